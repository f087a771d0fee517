"""bcad: a Bayesian robotic CAD system.

Data flows one way: problem file -> schema (:mod:`bcad.model`) -> kinematic graph
(:mod:`bcad.compiler`) -> a family (:mod:`bcad.bayes`, :mod:`bcad.worstcase`,
:mod:`bcad.calibration`, on :mod:`bcad.numerics` and :mod:`bcad.kinematics`) -> JSON result
(:mod:`bcad.bayes.document`).

The Python API (:mod:`bcad.api`) is reached from here, loaded on first use so that
``import bcad`` (and the ``bcad`` command's start-up) stays light::

    import bcad
    problem = bcad.load("problems/rx90_face_on_face.yaml")
    result = bcad.solve(problem, seed=0)
"""

from bcad.version import __version__

#: the API's names, resolved lazily from :mod:`bcad.api` (PEP 562)
_API = {"load", "compile", "solve", "posterior", "maxerror", "calibrate", "Result", "ClosingLink"}


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
    raise AttributeError(f"module 'bcad' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | _API | {"InputError", "confined"})
