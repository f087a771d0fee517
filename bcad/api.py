"""bcad's Python API: a facade over the three families.

Each family owns its run and its result: :mod:`bcad.bayes.run` (``solve``, ``posterior``),
:mod:`bcad.worstcase.run` (``maxerror``), :mod:`bcad.calibration.run` (``calibrate``). This
module checks the API's arguments, loads and compiles problems, composes the families where one
question needs two (``calibrate --for PLAN.yaml`` directs proposals at a plan's configuration,
which the Bayesian family solves), and wraps each document in a :class:`Result`. The ``bcad``
command and ``bcad batch`` are thin layers over it. In a notebook::

    import bcad

    problem = bcad.load("problems/rx90_face_on_face.yaml")
    result = bcad.solve(problem, seed=0)
    result.table()                      # Table 2 of the 2000 paper (rich; HTML in notebooks)
    result.links["contact"].std         # the posterior std of the closing link's pose, Eq. 2
    result.objective.log_value          # the document's fields are the result's
    result.to_json()

Errors raise :class:`bcad.InputError` (with the file and line); nothing here exits.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from bcad.arguments import Spelling, choice, whole_number
from bcad.bayes.run import MAX_SAMPLES_OUT, posterior_document, solve_document, write_samples
from bcad.calibration import run as calibration_family
from bcad.errors import InputError, quoted, shown
from bcad.model.source import SourceDocument

# The Bayesian family, the graph compiler and the graph language's schemas are loaded by the
# functions that use them: ``bcad maxerror`` and ``bcad validate`` start without them.
if TYPE_CHECKING:
    from bcad.compiler import CompiledProblem
    from bcad.model.problem import Problem

__all__ = ["load", "compile", "solve", "posterior", "maxerror", "calibrate", "Result", "ClosingLink", "InputError"]


def result_model(kind: str):
    """The typed model of a result document of this kind (the command that wrote it)."""
    if kind in ("solve", "posterior"):
        from bcad.bayes.result import DesignResult

        return DesignResult
    if kind == "maxerror":
        from bcad.worstcase.result import MaxErrorResult

        return MaxErrorResult
    from bcad.calibration.result import CalibrationResult

    return CalibrationResult


def results_json_schema() -> dict:
    """The JSON Schema of every result document (``bcad schema --results``): one of the
    families' models, told apart by ``kind``."""
    from bcad.bayes.result import DesignResult
    from bcad.calibration.result import CalibrationResult
    from bcad.model.results import SCHEMA_VERSION
    from bcad.model.schema import json_schema_of
    from bcad.worstcase.result import MaxErrorResult

    return json_schema_of(
        [DesignResult, MaxErrorResult, CalibrationResult],
        "serialization",
        "results.schema.json",
        f"bcad result (schema_version {SCHEMA_VERSION})",
        "The JSON document that bcad solve, posterior, maxerror or calibrate writes; its 'kind' names the command. "
        "Keys not listed may be added by later versions: readers ignore them.",
    )


def checked(document: dict) -> dict:
    """The document, once the model of its kind has checked it (:func:`bcad.model.results.checked`)."""
    from bcad.model.results import checked as checked_by

    return checked_by(document, result_model(document["kind"]))


def maxerror_document(problem, **options) -> dict:
    """The result of ``bcad maxerror`` (:func:`bcad.worstcase.run.maxerror_document`)."""
    from bcad.worstcase.run import maxerror_document as run

    return run(problem, **options)


def nominal_configuration(plan: CompiledProblem) -> np.ndarray:
    """A plan's X with its cycles closed at nominal L (the nominal backend, seed 0: deterministic),
    the configuration ``calibrate --for PLAN.yaml`` directs its proposals at."""
    from bcad.bayes.model import BayesModel
    from bcad.bayes.nominal import solve_nominal

    return solve_nominal(BayesModel(plan), np.random.default_rng(0)).x


def calibration_run(compiled: CompiledProblem, **options) -> tuple[dict, dict[str, str]]:
    """The result of ``bcad calibrate`` and the calibrated URDF texts
    (:func:`bcad.calibration.run.calibration_run`; a plan's configuration, for ``task``, from the
    Bayesian family's nominal backend)."""
    return calibration_family.calibration_run(compiled, plan_configuration=nominal_configuration, **options)


def read_result(path: Path) -> tuple[dict[str, float], int]:
    """A result file's ``solution`` (names to finite numbers) and ``seed`` (0 when absent)."""
    import math

    from bcad.model.pose import is_parameter_name
    from bcad.model.source import read_json

    document = read_json(path, "a bcad result (JSON)", "a bcad result")
    try:
        solution = document["solution"]
    except (KeyError, TypeError, IndexError):
        raise InputError(path, "not a bcad result: expected an object with a 'solution' mapping") from None
    if not isinstance(solution, dict):
        raise InputError(path, "not a bcad result: its 'solution' is not a mapping of names to numbers")
    named = [is_parameter_name(name) for name in solution]
    if not all(named):
        raise InputError(
            path,
            f"not a bcad result: entry {named.index(False) + 1} of its 'solution' is not named "
            "LINK.PARAMETER (ur5/base.tx, arm/joint_1.rz)",
        )
    for name, value in solution.items():
        try:  # an integer too large for a float (400 digits) is not finite either
            finite = not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(float(value))
        except OverflowError:
            finite = False
        if not finite:
            raise InputError(
                path, f"solution value of {quoted(name, 60)} is {json.dumps(value)[:40]}, expected a finite number"
            )
    seed = document.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise InputError(
            path, f"not a bcad result: its seed is {json.dumps(seed)[:40]}, expected a non-negative integer"
        )
    return {str(name): float(value) for name, value in solution.items()}, seed


# --- the Python API ------------------------------------------------------------------------


#: the most samples an API call may ask for (the schema's bound on posterior_samples)
MAX_API_SAMPLES = 1_000_000_000


def _finite_values(values: dict) -> bool:
    """Whether every entry maps a name to a real number of at most 1e9 in size (a NaN, an
    infinity and a 5000-digit integer are not; the comparison is exact for any integer)."""
    return all(
        isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool) and abs(v) <= 1e9
        for k, v in values.items()
    )


def _check_count(value, name: str, low: int, high: int, call: str, optional: bool = False) -> int | None:
    """A whole number in [low, high] (:func:`bcad.arguments.whole_number`), else InputError."""
    if optional and value is None:
        return None
    return whole_number(value, name, Spelling(call), low, high)


def _check_choice(value, name: str, choices: tuple[str, ...], call: str, optional: bool = False) -> str | None:
    if optional and value is None:
        return None
    return choice(value, name, Spelling(call), choices)


def _check_path(value, name: str, call: str) -> Path | None:
    if value is None:
        return None
    if not isinstance(value, (str, Path)) or not str(value).strip():
        raise InputError(f"bcad.{call}", f"{name} is {shown(value)}; expected a file's path (str or pathlib.Path)")
    return Path(value)


def load(source: str | Path | dict) -> Problem:
    """A problem from a YAML file (path) or from a mapping of the same keys (``dict``).

    Paths in a mapping (``urdf``, ``data``) are relative to the current folder. Raises
    :class:`InputError` naming the file and line of anything wrong.
    """
    from bcad.model.problem import load as load_any

    return load_any(source)


def compile(problem: Problem | str | Path | dict) -> CompiledProblem:  # noqa: A001 (bcad.compile)
    """The probabilistic kinematic graph of a problem (Sect. 3.1 of the 2000 paper)."""
    from bcad.compiler.problem import compile_any

    return compile_any(problem)


def compile_with_calibrations(problem, calibration=(), call: str = "bcad") -> CompiledProblem:
    """The compiled problem, with ``calibration`` results (paths) added to its ``calibration:``,
    as ``--calibration`` adds them (the command and the API both come here)."""
    if isinstance(calibration, (str, Path)) or not isinstance(calibration, (list, tuple)):
        raise InputError(f"bcad.{call}", f"calibration is {shown(calibration)}; expected a list of result paths")
    paths = [_check_path(path, "calibration", call) for path in calibration]
    if not paths:
        return compile(problem)
    for path in paths:
        if not path.exists():
            raise InputError(path, "no such file (a bcad calibrate result)")
    loaded = load(problem)
    # model_copy keeps the source document (error positions, relative paths)
    return compile(
        loaded.model_copy(update={"calibration": [*loaded.calibration, *(str(p.absolute()) for p in paths)]})
    )


def _inputs_of(problem, compiled: CompiledProblem) -> list[Path]:
    """The files a call read that no output may replace: the problem's and its calibrations'."""
    return ([Path(problem)] if isinstance(problem, (str, Path)) else []) + [Path(p) for p in compiled.calibration.files]


def _samples_kept(samples_out, count: int, call: str) -> tuple[Path | None, dict | None]:
    """``samples_out``'s path and the dict that collects the samples (None, None without it)."""
    if samples_out is None:
        return None, None
    path = _check_path(samples_out, "samples_out", call)
    if count > MAX_SAMPLES_OUT:
        raise InputError(
            f"bcad.{call}", f"samples_out keeps at most {MAX_SAMPLES_OUT:.0e} samples in memory; lower samples"
        )
    from bcad.io import check_output

    check_output(path)
    return path, {}


@dataclass(frozen=True)
class ClosingLink:
    """The posterior of one closing link's pose Q (Eq. 1), in the problem's units (Table 2)."""

    name: str
    parent: str
    child: str
    parameters: tuple[str, ...]
    mean: np.ndarray  # the prior's propagation: Q under L ~ p(L)
    std: np.ndarray
    weighted_mean: np.ndarray  # the posterior: weighted by the closing link's distributions and relation
    weighted_std: np.ndarray
    effective_samples: float | None
    satisfied: float | None  # fraction of prior samples meeting the relation's inequalities


@dataclass
class Result:
    """A result of :func:`solve`, :func:`posterior`, :func:`maxerror` or :func:`calibrate`: the JSON
    document of the matching command, with typed views of its parts."""

    kind: str
    document: dict
    #: calibrate: the calibrated robots' URDF texts, by robot name
    urdf: dict[str, str] = field(default_factory=dict)

    @property
    def typed(self):
        """The document as its family's typed model (:class:`bcad.bayes.result.DesignResult`,
        :class:`bcad.worstcase.result.MaxErrorResult`, :class:`bcad.calibration.result.CalibrationResult`):
        ``result.typed.rotation.upper_bound``. Its fields are also the result's own:
        ``worst.rotation.upper_bound``, ``cal.check``."""
        try:
            return self.__dict__["_typed"]
        except KeyError:
            typed = self.__dict__["_typed"] = result_model(self.document["kind"]).model_validate(self.document)
            return typed

    def __getattr__(self, name: str):
        if name.startswith("_") or name in ("kind", "document", "urdf"):
            raise AttributeError(name)
        typed = self.typed
        if name in type(typed).model_fields or name in (typed.model_extra or {}):
            return getattr(typed, name)
        raise AttributeError(f"a {self.kind} result has no {name!r}")

    def to_json(self) -> str:
        """The document as the command writes it (indented JSON, no NaN)."""
        from bcad.io import json_text

        return json_text(self.document)

    @property
    def warnings(self) -> list[dict]:
        return list(self.document.get("warnings", []))

    @property
    def trusted(self) -> bool:
        """No warning: the command would exit 0."""
        return not self.warnings

    @property
    def solution(self) -> dict[str, float]:
        """X by name (solve and posterior)."""
        return dict(self.document.get("solution", {}))

    @property
    def log_objective(self) -> tuple[float | None, float | None]:
        """log p(X) I(X) and its standard error (Eq. 2)."""
        objective = self.document.get("objective", {})
        return objective.get("log_value"), objective.get("log_value_se")

    @property
    def links(self) -> dict[str, ClosingLink]:
        """Each closing link's posterior (solve and posterior)."""
        out = {}
        for name, link in self.document.get("posterior", {}).get("links", {}).items():
            weighted = link.get("weighted") or {}
            out[name] = ClosingLink(
                name,
                link["parent"],
                link["child"],
                tuple(link["params"]),
                np.array(link["mean"], dtype=float),
                np.array(link["std"], dtype=float),
                np.array(weighted.get("mean", link["mean"]), dtype=float),
                np.array(weighted.get("std", link["std"]), dtype=float),
                link.get("effective_samples"),
                link.get("satisfied"),
            )
        return out

    @property
    def parameters(self) -> dict[str, dict]:
        """Calibrated parameters by name (calibrate)."""
        return dict(self.document.get("parameters", {}))

    def table(self):
        """The command's table (a rich renderable; shown as HTML in notebooks)."""
        from bcad import report

        if self.kind == "maxerror":
            return report.maxerror_table(self.typed)
        if self.kind == "calibrate":
            from bcad.calibration.report import calibration_table

            return calibration_table(self.document)
        return report.posterior_table(self.typed)

    def _repr_html_(self) -> str:
        import io

        from rich.console import Console

        console = Console(file=io.StringIO(), record=True, width=120, markup=False, emoji=False)
        console.print(self.table())
        return console.export_html(inline_styles=True)


def solve(
    problem,
    *,
    seed: int = 0,
    backend: str = "bayes",
    samples: int | None = None,
    estimator: str | None = None,
    progress: Callable | None = None,
    calibration: list[str | Path] = (),
    samples_out: str | Path | None = None,
) -> Result:
    """X* = argmax p(X) I(X) (Eq. 2) and the closing links' posterior there, as ``bcad solve``.
    ``calibration``: results of ``bcad calibrate`` whose posterior replaces the L they name;
    ``samples_out``: also write the posterior samples there (.npz, as ``--samples-out``);
    ``progress(phase, temperature, samples, best)``: called as the run goes, with ``phase`` one of
    the genetic algorithm's phases, ``"search"``, or ``"posterior"`` (``samples``: drawn so far)."""
    from bcad.model.solver import ESTIMATORS

    _check_choice(backend, "backend", ("bayes", "nominal"), "solve")
    seed = _check_count(seed, "seed", 0, 2**63 - 1, "solve")
    samples = _check_count(samples, "samples", 1, MAX_API_SAMPLES, "solve", optional=True)
    _check_choice(estimator, "estimator", ESTIMATORS, "solve", optional=True)
    if progress is not None and not callable(progress):
        raise InputError("bcad.solve", f"progress is {shown(progress)}; expected a callable or None")
    compiled = compile_with_calibrations(problem, calibration, "solve")
    path, kept = _samples_kept(samples_out, samples or compiled.problem.solver.posterior_samples, "solve")
    result = Result(
        "solve",
        solve_document(
            compiled,
            backend=backend,
            seed=seed,
            posterior_samples=samples,
            estimator=estimator,
            progress=progress,
            kept=kept,
            samples_option="bcad.solve: samples",
        ),
    )
    if path is not None:
        write_samples(compiled, kept, path, _inputs_of(problem, compiled))
    return result


def posterior(
    problem,
    *,
    at: Result | dict | str | Path | None = None,
    values: dict[str, float] | None = None,
    samples: int | None = None,
    seed: int = 0,
    estimator: str | None = None,
    calibration: list[str | Path] = (),
    samples_out: str | Path | None = None,
) -> Result:
    """The closing links' posterior (Table 2) and the objective's estimate at a given X, as
    ``bcad posterior``: X from ``at`` (a result, its document or its file) and/or ``values``;
    ``samples`` (default: the problem's ``solver.posterior_samples``, as :func:`solve`'s posterior),
    ``calibration`` and ``samples_out`` as :func:`solve`'s."""
    from bcad.model.solver import ESTIMATORS

    samples = _check_count(samples, "samples", 1, MAX_API_SAMPLES, "posterior", optional=True)
    seed = _check_count(seed, "seed", 0, 2**63 - 1, "posterior")
    _check_choice(estimator, "estimator", ESTIMATORS, "posterior", optional=True)
    if at is not None and not isinstance(at, (Result, dict)):
        at = _check_path(at, "at (a result, its document or its file)", "posterior")
    if values is not None and (not isinstance(values, dict) or not _finite_values(values)):
        raise InputError("bcad.posterior", "values must map X names (str) to finite numbers of at most 1e9")
    from bcad.bayes.document import solution_from_dict
    from bcad.bayes.model import check_solvable

    compiled = compile_with_calibrations(problem, calibration, "posterior")
    check_solvable(compiled, needs_unknowns=False)
    solution: dict[str, float] = {}
    if isinstance(at, Result):
        solution = at.solution
    elif isinstance(at, dict):
        solution = at.get("solution", at)
        if not isinstance(solution, dict) or not _finite_values(solution):
            raise InputError(
                "bcad.posterior", "at: its solution must map X names (str) to finite numbers of at most 1e9"
            )
        solution = dict(solution)
    elif at is not None:
        solution, _ = read_result(Path(at))
    solution.update(values or {})
    names = compiled.parameters.x_names
    unknown = [name for name in solution if name not in names]
    missing = [name for name in names if name not in solution]
    if unknown or missing:
        problem_text = (
            f"unknown X parameter(s) {', '.join(quoted(name, 60) for name in unknown[:5])}"
            if unknown
            else f"no value for X parameter(s) {', '.join(missing)}"
        )
        raise InputError(compiled.problem.source.path, problem_text)
    x = solution_from_dict(compiled, solution)
    compiled.check_unknowns(x, at if isinstance(at, (str, Path)) else "bcad.posterior")
    path, kept = _samples_kept(samples_out, samples or compiled.problem.solver.posterior_samples, "posterior")
    result = Result(
        "posterior",
        posterior_document(
            compiled,
            x,
            samples=samples,
            seed=seed,
            estimator=estimator,
            kept=kept,
            samples_option="bcad.posterior: samples",
        ),
    )
    if path is not None:
        write_samples(compiled, kept, path, _inputs_of(problem, compiled))
    return result


def maxerror(
    problem,
    *,
    tol: float = 1e-6,
    model: str = "first-order",
    samples: int | None = None,
    seed: int = 0,
    spec: str | dict[str, float] | None = None,
    allocate: str | dict[str, float] | None = None,
    weights: str | list[float] | None = None,
) -> Result:
    """The certified largest end-effector errors that joint clearances can cause, as ``bcad maxerror``
    (``problem``: a clearance problem's path, mapping or loaded model). ``spec``: the yield of a
    spec (``{"translation": 0.0004}`` or ``"rotation=R,dx=D"``, problem units; 1e5 samples unless
    ``samples`` says); ``allocate``: the largest clearance scale whose exact errors meet a spec,
    with per-joint ``weights``."""
    from bcad.model.clearance import ChainProblem, chain_problem_from_document, load_chain_problem
    from bcad.worstcase.run import maxerror_options, maxerror_with

    options = maxerror_options(
        tol=tol,
        model=model,
        samples=samples,
        spec=spec,
        allocate=allocate,
        weights=weights,
        spelling=Spelling("maxerror"),
    )
    seed = _check_count(seed, "seed", 0, 2**63 - 1, "maxerror")
    if isinstance(problem, dict):
        problem = chain_problem_from_document(SourceDocument(path=Path("<dict>"), data=problem))
    elif not isinstance(problem, ChainProblem):
        if problem is None:
            raise InputError(
                "bcad.maxerror", "problem is None; expected a clearance problem's path, mapping or loaded model"
            )
        problem = load_chain_problem(_check_path(problem, "problem", "maxerror"))
    return Result(
        "maxerror",
        maxerror_with(problem, options, seed),
    )


def calibrate(
    problem,
    *,
    robust: bool = False,
    check_samples: int | None = None,
    seed: int = 0,
    propose: int = 0,
    candidates: str | Path | None = None,
    predict: str | Path | None = None,
    task: str | Path | None = None,
) -> Result:
    """Identify a cell's parameters from its measurements, as ``bcad calibrate``. The
    calibrated robots' URDF texts are in ``result.urdf`` by robot name, the calibrated cameras in
    ``result.document["cameras"]`` (``bcad.model.camera_info.camera_info_text`` writes one as
    ROS camera_info YAML, as ``--camera-info`` does)."""
    if not isinstance(robust, bool):
        raise InputError("bcad.calibrate", f"robust is {shown(robust)}; expected True or False")
    # None: the family's default check size, fewer for a large file (bcad.calibration.run.check_sample_count)
    check_samples = _check_count(check_samples, "check_samples", 0, MAX_API_SAMPLES, "calibrate", optional=True)
    seed = _check_count(seed, "seed", 0, 2**63 - 1, "calibrate")
    propose = _check_count(propose, "propose", 0, 100_000, "calibrate")
    candidates, predict, task = (
        _check_path(v, n, "calibrate") for v, n in ((candidates, "candidates"), (predict, "predict"), (task, "task"))
    )
    if propose and candidates is None:
        raise InputError("bcad.calibrate", "propose needs candidates (a CSV file of configurations)")
    compiled = compile(problem)
    document, texts = calibration_run(
        compiled,
        robust=robust,
        check_samples=check_samples,
        seed=seed,
        propose=propose,
        candidates=candidates,
        urdf=bool(compiled.problem.robots),
        predict=None if predict is None else Path(predict),
        task=None if task is None else Path(task),
    )
    return Result("calibrate", document, texts)
