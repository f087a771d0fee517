"""The Bayesian family's arguments, checked once for ``bcad solve`` / ``bcad posterior`` and for
``bcad.solve`` / ``bcad.posterior``: the backend, the estimator, the seed, sample counts,
``--samples-out``, and the X a posterior is asked about (a result's solution and NAME=VALUE
values). Each check names the argument as its caller spells it (:class:`bcad.arguments.Spelling`).
"""

from __future__ import annotations

import difflib
import json
import math
import numbers
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from bcad.arguments import Spelling, choice, file_path, random_seed, sample_count
from bcad.errors import InputError, quoted

if TYPE_CHECKING:
    from bcad.compiler import CompiledProblem
    from bcad.model.source import JsonDocument

#: ``--backend``: the paper's method, or every L at its nominal value
BACKENDS = ("bayes", "nominal")
#: posterior samples that ``--samples-out`` may keep in memory and write at most
MAX_SAMPLES_OUT = 2_000_000


@dataclass(frozen=True)
class RunOptions:
    """A solve's or a posterior's options, checked."""

    seed: int
    samples: int | None  # None: the problem's solver.posterior_samples
    estimator: str | None  # None: the problem's solver.estimator
    backend: str = "bayes"


def run_options(*, seed, samples, estimator, spelling: Spelling, backend: str = "bayes") -> RunOptions:
    """The options of a solve or a posterior, each checked (``samples``: a whole number, or text
    such as "1e5" on the command line)."""
    from bcad.model.solver import ESTIMATORS

    return RunOptions(
        seed=random_seed(seed, spelling),
        samples=None if samples is None else sample_count(samples, "samples", spelling),
        estimator=None if estimator is None else choice(estimator, "estimator", spelling, ESTIMATORS),
        backend=choice(backend, "backend", spelling, BACKENDS),
    )


def samples_kept(
    samples_out: Path | None, count: int, spelling: Spelling, output: Path | None = None, protected=()
) -> dict | None:
    """The dict that collects the posterior samples for ``samples_out`` (None without it), once
    the path may be written (not an input, not ``output``'s file) and ``count`` samples fit."""
    if samples_out is None:
        return None
    from bcad.io import check_output

    if count > MAX_SAMPLES_OUT:
        raise InputError(
            spelling.where("samples_out"),
            f"keeps at most {MAX_SAMPLES_OUT:.0e} samples in memory; lower {spelling.name('samples')}",
        )
    if output is not None and Path(samples_out).resolve() == Path(output).resolve():
        raise InputError(spelling.where("samples_out"), "names the JSON result's file (-o); expected another file")
    check_output(Path(samples_out), list(protected))
    return {}


def read_result(path: Path) -> tuple[dict[str, float], int, dict | None, JsonDocument]:
    """A result file's ``solution`` (names to finite numbers), ``seed`` (0 when absent), ``units``
    (None when absent) and the file read (whose messages name a value's line)."""
    from bcad.model.pose import first_unnamed
    from bcad.model.source import read_json

    source = read_json(path, "a bcad result (JSON)", "a bcad result")
    document = source.data
    try:
        solution = document["solution"]
    except (KeyError, TypeError, IndexError):
        raise InputError(path, "not a bcad result: expected an object with a 'solution' mapping") from None
    if not isinstance(solution, dict):
        raise source.error(("solution",), "not a bcad result: its 'solution' is not a mapping of names to numbers")
    unnamed = first_unnamed(solution)
    if unnamed is not None:
        raise source.error(
            ("solution", list(solution)[unnamed - 1]),
            f"not a bcad result: entry {unnamed} of its 'solution' is not named "
            "LINK.PARAMETER (ur5/base.tx, arm/joint_1.rz)",
        )
    for name, value in solution.items():
        if not finite_number(value):
            raise source.error(
                ("solution", name),
                f"solution value of {quoted(name, 60)} is {json.dumps(value)[:40]}, expected a finite number",
            )
    seed = document.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise source.error(
            ("seed",), f"not a bcad result: its seed is {json.dumps(seed)[:40]}, expected a non-negative integer"
        )
    return {str(name): float(value) for name, value in solution.items()}, seed, result_units(document), source


def result_units(document: dict) -> dict | None:
    """A result document's ``units`` mapping (None where it has none)."""
    units = document.get("units")
    return units if isinstance(units, dict) else None


def given_solution(at, spelling: Spelling) -> tuple[dict[str, float], JsonDocument | None, dict | None]:
    """The solution ``at`` gives (a result document, a mapping of X names to numbers, or a result
    file's path), the file it was read from (None for a mapping) and the result's units (None
    where it does not say: a mapping of X names)."""
    if at is None:
        return {}, None, None
    if isinstance(at, dict):
        if "kind" in at and "solution" not in at:
            raise InputError(
                spelling.where("at"),
                f"a result of kind {quoted(str(at['kind']), 30)}; expected a solve or posterior result "
                "(one with a solution)",
            )
        given = at.get("solution", at)
        if not isinstance(given, dict):
            raise spelling.error("at", at, "a result, its document, its file or a mapping of X names to numbers")
        return dict(given), None, result_units(at) if "solution" in at else None
    if not isinstance(at, (str, Path)):
        raise spelling.error("at", at, "a result, its document or its file (a path)")
    given, _, units, source = read_result(file_path(at, "at", spelling))
    return given, source, units


def finite_number(value) -> bool:
    """A real number (not a bool) that a float holds: a NaN, an infinity and an integer too large
    for a float (400 digits) are not (a value outside an X's bounds is refused with them named)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def solution_at(
    compiled: CompiledProblem,
    given: dict[str, float],
    values: dict[str, float],
    spelling: Spelling,
    source: JsonDocument | None,
    units: dict | None = None,
) -> np.ndarray:
    """X (internal units) from a result's solution ``given`` (read from ``source``: a file, or
    None) updated by ``values``: every name an X of this problem, every X given, within its bounds;
    the result's ``units`` (where it says them) this problem's, whose units its X are read in.

    On the command line ``values`` are ``--value NAME=VALUE``, in Python ``values=``; ``at``
    names the result either way."""
    from bcad.bayes.document import solution_from_dict

    names = compiled.parameters.x_names
    value_argument = "value" if spelling.call is None else "values"

    def refused(loc: tuple, message: str) -> InputError:
        """The error at the result file's value ``loc`` (the file's line), or at ``at``."""
        return source.error(loc, message) if source is not None else InputError(spelling.where("at"), message)

    def unknown(name: str) -> str:
        close = difflib.get_close_matches(name, names, n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        return f"{quoted(name, 60)} is not an X parameter of this problem{hint}"

    for name, value in values.items():
        if not isinstance(name, str) or not finite_number(value):
            raise spelling.error(value_argument, {name: value}, "X names (str) mapped to finite numbers")
        if name not in names:
            raise InputError(spelling.where(value_argument), unknown(name))
    for name, value in given.items():
        if not isinstance(name, str) or not finite_number(value):
            raise spelling.error("at", {name: value}, "a solution mapping X names (str) to finite numbers")
        if name not in names:
            raise refused(("solution", name), unknown(name) + ": is it another problem's result?")
    own = compiled.problem.units
    if units is not None and given and (units.get("length"), units.get("angle")) != (own.length, own.angle):
        raise refused(
            ("units",),
            f"a result in {units.get('length')} and {units.get('angle')}, and this problem is in {own.length} and "
            f"{own.angle}: its X would be read in the wrong units (solve this problem, or give its X by "
            f"{'--value' if spelling.call is None else 'values='})",
        )
    solution = {**given, **values}
    missing = [name for name in names if name not in solution]
    if missing:
        how = "--at RESULT.json or --value NAME=VALUE" if spelling.call is None else "at= or values="
        message = f"no value for X parameter(s) {', '.join(missing)}; give {how}"
        raise refused(("solution",), message) if source else InputError(compiled.problem.source.path, message)
    x = solution_from_dict(compiled, solution)
    compiled.check_unknowns(
        x,
        lambda name, message: (
            InputError(spelling.where(value_argument), message)
            if name in values
            else refused(("solution", name), message)
        ),
    )
    return x
