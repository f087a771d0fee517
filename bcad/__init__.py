"""bcad: a Bayesian robotic CAD system.

Data flows one way: problem file -> schema (:mod:`bcad.model`) -> kinematic graph
(:mod:`bcad.compile`) -> a family (:mod:`bcad.bayes`, :mod:`bcad.worstcase`, :mod:`bcad.calibrate`,
on :mod:`bcad.numerics` and :mod:`bcad.kinematics`) -> JSON result (:mod:`bcad.results`).

The Python API (:mod:`bcad.api`) is reached from here, loaded on first use so that
``import bcad`` (and the ``bcad`` command's start-up) stays light::

    import bcad
    problem = bcad.load("problems/rx90_face_on_face.yaml")
    result = bcad.solve(problem, seed=0)
"""

import sys
import types

from bcad.version import __version__

#: the API's names, resolved lazily from :mod:`bcad.api` (PEP 562)
_API = {"load", "solve", "posterior", "maxerror", "Result", "ClosingLink"}


def __getattr__(name: str):
    if name in _API:
        from bcad import api

        return getattr(api, name)
    if name == "InputError":
        from bcad.errors import InputError

        return InputError
    if name == "confined":
        from bcad.model.source import confined

        return confined
    if name == "compile":
        # The package bcad.compile is callable: bcad.compile(problem) compiles (see its __init__).
        import importlib

        return importlib.import_module("bcad.compile")
    raise AttributeError(f"module 'bcad' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted((set(globals()) - {"sys", "types"}) | _API | {"InputError", "compile", "confined"})


class _CalibrateEntry:
    """``bcad.calibrate``: the API function when called, the subpackage :mod:`bcad.calibrate` for
    its attributes (``bcad.calibrate.model``, ``import bcad.calibrate.check as check``, which the
    import system resolves through this attribute)."""

    def __call__(self, *args, **kwargs):
        from bcad.api import calibrate

        return calibrate(*args, **kwargs)

    @property
    def __wrapped__(self):  # inspect.signature and help() show the API function's
        from bcad.api import calibrate

        return calibrate

    @property
    def __doc__(self):  # noqa: D105
        from bcad.api import calibrate

        return calibrate.__doc__

    def __getattr__(self, name: str):
        import importlib

        return getattr(importlib.import_module("bcad.calibrate"), name)

    def __repr__(self) -> str:
        return "<bcad.calibrate: the API function, and the subpackage's attributes>"


calibrate = _CalibrateEntry()


class _Package(types.ModuleType):
    """The package ``bcad``. Loading a subpackage binds it as an attribute of its parent, which
    for ``bcad.calibrate`` would replace the API entry of that name by the subpackage the
    function itself imports (a second ``bcad.calibrate(...)`` then raised 'module is not
    callable'). That binding is skipped: ``bcad.calibrate`` stays the entry above,
    callable, and it hands the subpackage's attributes through. ``bcad.compile`` needs no such
    care: its package is callable itself."""

    def __setattr__(self, name: str, value) -> None:
        if name == "calibrate" and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
