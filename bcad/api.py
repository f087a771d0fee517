"""bcad's Python API: a facade over the three families.

Each family owns its run, its arguments' checks and its result: :mod:`bcad.bayes.run`
(``solve``, ``posterior``), :mod:`bcad.worstcase.run` (``maxerror``), :mod:`bcad.calibration.run`
(``calibrate``). This module calls them, composes them where one question needs two, and wraps
each document in a :class:`bcad.result.Result`. In a notebook::

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

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from bcad.arguments import Spelling, file_path
from bcad.errors import InputError
from bcad.result import ClosingLink, Result
from bcad.worker_env import one_blas_thread

# The Bayesian family, the graph compiler and the graph language's schemas are loaded by the
# functions that use them: ``bcad maxerror`` and ``bcad validate`` start without them.
if TYPE_CHECKING:
    from bcad.compiler import CompiledProblem
    from bcad.model.problem import Problem

__all__ = ["load", "compile", "solve", "posterior", "maxerror", "calibrate", "Result", "ClosingLink", "InputError"]


def load(source: str | Path | dict):
    """A problem from a YAML file (path) or from a mapping of the same keys (``dict``): a
    :class:`Problem`, or a clearance problem (one with a ``chain``) as the model :func:`maxerror`
    takes (:class:`bcad.model.clearance.ChainProblem`).

    Paths in a mapping (``urdf``, ``data``) are relative to the current folder. Raises
    :class:`InputError` naming the file and line of anything wrong.
    """
    from bcad.model.clearance import load_problem_or_chain

    return load_problem_or_chain(source)


def compile(problem: Problem | str | Path | dict) -> CompiledProblem:  # noqa: A001 (bcad.compile)
    """The probabilistic kinematic graph of a problem (Sect. 3.1 of the 2000 paper)."""
    from bcad.compiler.problem import compile_any

    return compile_any(problem)


def nominal_configuration(plan: CompiledProblem) -> np.ndarray:
    """A plan's X with its cycles closed at nominal L (the nominal backend, seed 0: deterministic),
    the configuration ``calibrate --for PLAN.yaml`` directs its proposals at: the calibration
    family asks the Bayesian one through here, as the families never import each other."""
    from bcad.bayes.model import BayesModel
    from bcad.bayes.nominal import solve_nominal

    return solve_nominal(BayesModel(plan), np.random.default_rng(0)).x


@one_blas_thread()
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
    """X* = argmax p(X) I(X) and the closing links' posterior there, as ``bcad solve``.
    ``calibration``: results of ``bcad calibrate`` whose posterior replaces the L they name;
    ``samples_out``: also write the posterior samples there (.npz, as ``--samples-out``);
    ``progress(phase, temperature, samples, best)``: called as the run goes, with ``phase`` one of
    the genetic algorithm's phases, ``"search"``, or ``"posterior"`` (``samples``: drawn so far)."""
    from bcad.bayes.arguments import run_options
    from bcad.bayes.run import solve_run
    from bcad.compiler.problem import compile_with_calibrations, input_files

    spelling = Spelling("solve")
    options = run_options(seed=seed, samples=samples, estimator=estimator, backend=backend, spelling=spelling)
    if progress is not None and not callable(progress):
        raise spelling.error("progress", progress, "a callable or None")
    samples_out = file_path(samples_out, "samples_out", spelling)
    compiled = compile_with_calibrations(problem, calibration, spelling)
    inputs = input_files(problem, compiled)
    document, _ = solve_run(compiled, options, spelling, progress=progress, samples_out=samples_out, inputs=inputs)
    return Result("solve", document)


@one_blas_thread()
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
    """The closing links' posterior and the objective's estimate at a given X, as
    ``bcad posterior``: X from ``at`` (a result, its document or its file) and/or ``values``;
    ``samples`` (default: the problem's ``solver.posterior_samples``, as :func:`solve`'s posterior),
    ``calibration`` and ``samples_out`` as :func:`solve`'s."""
    from bcad.bayes.arguments import given_solution, run_options, solution_at
    from bcad.bayes.run import posterior_run
    from bcad.bayes.solvable import check_solvable
    from bcad.compiler.problem import compile_with_calibrations, input_files

    spelling = Spelling("posterior")
    options = run_options(seed=seed, samples=samples, estimator=estimator, spelling=spelling)
    if values is not None and not isinstance(values, dict):
        raise spelling.error("values", values, "a mapping of X names to numbers")
    samples_out = file_path(samples_out, "samples_out", spelling)
    given, source, units = given_solution(at.document if isinstance(at, Result) else at, spelling)
    compiled = compile_with_calibrations(problem, calibration, spelling)
    check_solvable(compiled, needs_unknowns=False)
    x = solution_at(compiled, given, dict(values or {}), spelling, source, units)
    inputs = input_files(problem, compiled) + ([source.path] if source is not None else [])
    return Result("posterior", posterior_run(compiled, x, options, spelling, samples_out=samples_out, inputs=inputs))


@one_blas_thread()
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
    from bcad.worstcase.run import chain_problem_of, maxerror_options, maxerror_with

    spelling = Spelling("maxerror")
    given = dict(tol=tol, model=model, samples=samples, spec=spec, allocate=allocate, weights=weights, seed=seed)
    options = maxerror_options(**given, spelling=spelling)
    return Result("maxerror", maxerror_with(chain_problem_of(problem, spelling), options))


@one_blas_thread()
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
    ``result.cameras`` (``bcad.model.camera_info.camera_info_text`` writes one as ROS
    camera_info YAML, as ``--camera-info`` does). ``check_samples`` None: the default check,
    fewer samples for a large file."""
    from dataclasses import asdict

    from bcad.calibration.run import calibrate_options, calibration_run

    options = calibrate_options(
        robust=robust,
        check_samples=check_samples,
        seed=seed,
        propose=propose,
        candidates=candidates,
        predict=predict,
        task=task,
        spelling=Spelling("calibrate"),
    )
    compiled = compile(problem)
    document, texts = calibration_run(
        compiled, urdf=bool(compiled.problem.robots), plan_configuration=nominal_configuration, **asdict(options)
    )
    return Result("calibrate", document, texts)
