"""The worst-case family's run: the certified maxima of the clearance errors, the exact model's,
the statistics of uniform clearances and the tolerance allocation, as the result document
(:class:`bcad.worstcase.result.MaxErrorResult`), checked against its model before it leaves."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from bcad.arguments import COMMAND_LINE, Spelling, choice, file_path, random_seed, relative_gap, sample_count
from bcad.compiler.units import angle_scale
from bcad.errors import InputError
from bcad.numerics.seeding import stream

if TYPE_CHECKING:
    from bcad.model.clearance import ChainProblem

#: the exact bound's allowance for the rounding of the exact error's evaluation, in units of
#: (joints + 2) machine epsilons, relative
EXACT_ROUNDING = 64
#: clearance samples ``maxerror --samples`` draws at least: fewer leave no sample beyond the 99.7th
#: percentile, whose standard error (order statistics) then reads 0
MIN_CLEARANCE_SAMPLES = 1000
#: clearance samples times joints that ``maxerror --samples`` draws at most (7 joints: 2.9e6 samples)
MAX_CLEARANCE_SAMPLE_WORK = 20_000_000


#: the error models maxerror evaluates
MODELS = ("first-order", "exact")


@dataclass(frozen=True)
class MaxErrorOptions:
    """What a maxerror run is asked, checked (:func:`maxerror_options`)."""

    tol: float
    model: str
    samples: int | None
    spec: dict[str, float] | None
    allocate: dict[str, float] | None
    weights: list[float] | None
    seed: int = 0
    spelling: Spelling = COMMAND_LINE  # how the checks that need the chain name their option


def exact_gap_message(kind: str, bound: float, found: float, tol_name: str, tol: float) -> str:
    """The warning of an exact bound more than ``tol`` above the largest exact error found, the
    two printed with the digits that tell them apart (a gap of 2e-6: 9 digits)."""
    from bcad.worstcase.branch_and_bound import reached_gap

    gap = reached_gap(found, bound)
    digits = min(17, max(6, 3 - math.floor(math.log10(gap))))
    return (
        f"the exact {kind} bound {bound:.{digits}g} exceeds the largest exact error found, {found:.{digits}g}, "
        f"by {gap:.3g} of the bound, more than {tol_name} {tol:g}: both are certified (the error is between "
        "them), the bound is looser than asked"
    )


def maxerror_options(*, tol, model, samples, spec, allocate, weights, spelling: Spelling, seed=0) -> MaxErrorOptions:
    """The options of ``bcad maxerror`` and ``bcad.maxerror``, checked once for both: a relative
    gap ``tol``, a ``model``, a sample count, a ``spec`` and an ``allocate`` spec (text such as
    ``translation=0.0004,dx=0.09`` or a mapping), per-joint ``weights`` (only with ``allocate``);
    a spec without samples takes 1e5; a ``seed``. Errors name each option as ``spelling`` does."""
    from bcad.model.clearance import clearance_weights, spec_limits

    tol = relative_gap(tol, "tol", spelling)
    model = choice(model, "model", spelling, MODELS)
    samples = None if samples is None else sample_count(samples, "samples", spelling)
    if samples is not None and samples < MIN_CLEARANCE_SAMPLES:
        raise spelling.error(
            "samples",
            samples,
            f"a whole number of at least {MIN_CLEARANCE_SAMPLES} (the 99.7th percentile and its standard error "
            "need a few samples beyond it)",
        )
    limits = None if spec is None else spec_limits(spec, spelling.where("spec"))
    allocation = None if allocate is None else spec_limits(allocate, spelling.where("allocate"))
    factors = None if weights is None else clearance_weights(weights, spelling.where("weights"))
    if factors is not None and allocation is None:
        allocate_name = spelling.name("allocate")
        raise spelling.error(
            "weights", weights, f"it with {allocate_name}: weights scale the clearances of {allocate_name}"
        )
    if limits is not None and samples is None:
        samples = 100_000
    return MaxErrorOptions(tol, model, samples, limits, allocation, factors, random_seed(seed, spelling), spelling)


def chain_problem_of(problem, spelling: Spelling) -> ChainProblem:
    """A clearance problem from its path, its mapping (the keys of a file) or itself."""
    from bcad.model.clearance import ChainProblem, chain_problem_from_document, check_rotations, load_chain_problem
    from bcad.model.source import mapping_document

    if isinstance(problem, ChainProblem):
        check_rotations(problem)  # made in Python: not read through chain_problem_from_document
        return problem
    if isinstance(problem, dict):
        return chain_problem_from_document(mapping_document(problem))
    if problem is None:
        raise spelling.error("problem", problem, "a clearance problem's path, mapping or loaded model")
    return load_chain_problem(file_path(problem, "problem", spelling))


def maxerror_with(problem: ChainProblem, options: MaxErrorOptions) -> dict:
    """The result document of ``problem`` for checked ``options`` (:func:`maxerror_options`)."""
    return maxerror_document(
        problem,
        tol=options.tol,
        model=options.model,
        samples=options.samples,
        seed=options.seed,
        spec=options.spec,
        allocate=options.allocate,
        weights=options.weights,
        spelling=options.spelling,
    )


def maxerror_document(
    problem,
    *,
    tol: float,
    model: str,
    samples: int | None = None,
    seed: int = 0,
    spec: dict[str, float] | None = None,
    allocate: dict[str, float] | None = None,
    weights: list[float] | None = None,
    spelling: Spelling = COMMAND_LINE,
) -> dict:
    """The result of ``bcad maxerror``: certified first-order maxima, optionally the exact
    model's local maximum and the statistics of uniformly distributed clearances (``spelling``
    names the options the chain refuses: too many samples, weights of another length)."""
    from bcad.worstcase.branch_and_bound import certified_maximum, clearance_enters, reached_gap
    from bcad.worstcase.error_map import build_error_map

    error_map = build_error_map(problem)
    if samples and samples * error_map.joints > MAX_CLEARANCE_SAMPLE_WORK:
        # each sample is a chain of exact screws, kept for the percentiles: bounded in time and memory
        raise InputError(
            spelling.where("samples"),
            f"{samples:,} samples of a {error_map.joints}-joint chain; at most "
            f"{MAX_CLEARANCE_SAMPLE_WORK // error_map.joints:,} (samples x joints <= "
            f"{MAX_CLEARANCE_SAMPLE_WORK:.0e}: time and memory grow with both)",
        )
    per_angle = 1.0 / angle_scale(problem.units)
    # Screw units: dr in the problem's angle unit, dt in its length unit.
    screw_scale = np.array([per_angle] * 3 + [1.0] * 3)
    from bcad.model.results import SCHEMA_VERSION
    from bcad.version import __version__

    document = {
        "kind": "maxerror",
        "schema_version": SCHEMA_VERSION,
        "problem": problem.name,
        "bcad_version": __version__,
        "model": "first-order",
        "units": problem.units.model_dump(),
    }
    warnings: list[dict] = []
    for kind in ("rotation", "translation"):
        found = certified_maximum(error_map, kind, tol)
        scale = per_angle if kind == "rotation" else 1.0
        # A change of unit rounds: step the bounds outward so they stay bounds.
        entry = {
            "max": float(max(np.nextafter(found.max * scale, -np.inf), 0.0)) if scale != 1.0 else found.max,
            "upper_bound": float(np.nextafter(found.upper_bound * scale, np.inf))
            if scale != 1.0 and found.upper_bound > 0
            else found.upper_bound,
            "argmax": (found.argmax * screw_scale).tolist(),
            "seconds": round(found.seconds, 4),
            "gap": reached_gap(found.max, found.upper_bound),
            "converged": found.converged,
        }
        if not found.converged:
            warnings.append(
                {
                    "code": "gap_not_reached",
                    "message": f"the {kind} search stopped at a relative gap of {entry['gap']:.3g}, above "
                    f"{spelling.name('tol')} {tol:g}: the bound is certified but looser than asked (the tolerance "
                    "may be below what doubles resolve)",
                }
            )
        entry["model"] = "first-order"  # the linearised model's figures (Eq. 11): not a bound of the exact error
        if model == "exact":
            from bcad.worstcase.exact import EXACT_STARTS, ExactSearch, exact_maximum, exact_upper_bounds
            from bcad.worstcase.exact_bound import exact_bound

            sharp = None
            if not clearance_enters(error_map, kind):
                # the error set is {0} in the exact model too (rounding up a bound of 0 would say 5e-324)
                search, bound = ExactSearch(0.0, np.zeros((error_map.joints, 6)), 0.0), 0.0
            else:
                search = exact_maximum(error_map, found.argmax, kind, rng=stream(seed, f"exact-{kind}"))
                # Both bounds from the one first-order bound of this kind; only this kind's is kept.
                bound = exact_upper_bounds(error_map, found.upper_bound, found.upper_bound)[
                    0 if kind == "rotation" else 1
                ]
                # The sharp bound (bcad/worstcase/exact_bound.py), where its branch and bound applies.
                sharp = exact_bound(error_map, kind, search.max, search.argmax, tol, bound)
                if sharp is not None and sharp.bound < bound:
                    bound = sharp.bound
            # The exact error is evaluated in doubles, to about (n + 2) eps relative
            # (bcad.worstcase.exact.error_transforms): the bound covers that rounding too.
            bound *= 1.0 + EXACT_ROUNDING * (error_map.joints + 2) * np.finfo(float).eps
            if search.max > bound:  # never seen: a certificate that does not hold is said, not shown as one
                warnings.append(
                    {
                        "code": "exact_bound_below_max",
                        "message": f"the exact {kind} bound {bound:.17g} is below the error {search.max:.17g} "
                        "a feasible point reaches: the bound is not certified here",
                    }
                )
            if reached_gap(search.max, bound) > tol:
                warnings.append(
                    {
                        "code": "exact_gap_not_reached",
                        "message": exact_gap_message(
                            kind, bound * scale, search.max * scale, spelling.name("tol"), tol
                        ),
                    }
                )
            entry["exact"] = {
                "max": search.max * scale,
                "bound": float(np.nextafter(bound * scale, np.inf)) if scale != 1.0 and bound > 0 else bound,
                "gap": reached_gap(search.max, bound),
                "argmax": (search.argmax * screw_scale).tolist(),
                "at_first_order_argmax": search.start_value * scale,
                "relative_to_first_order": search.max / found.max - 1.0 if found.max > 0 else 0.0,
                "starts": 2 + EXACT_STARTS,
                "bound_cells": None if sharp is None else sharp.cells,
            }
        document[kind] = entry
    if model == "exact":
        document["model"] = "exact"
    if samples:
        from bcad.worstcase.statistics import error_statistics

        internal = (
            None
            if spec is None
            else {kind: value / per_angle if kind == "rotation" else value for kind, value in spec.items()}
        )
        statistics = error_statistics(
            error_map, problem.name, problem.units.length, samples, stream(seed, "clearance"), internal
        )
        for value in statistics["rotation"]:
            statistics["rotation"][value] *= per_angle
        if spec is not None:
            statistics["yield"]["spec"] = dict(spec)  # as given, in the problem's units
            # The exact model's certified bounds within the spec: no clearance can miss it.
            bounds = {kind: document.get(kind, {}).get("exact", {}).get("bound") for kind in spec}
            if all(bound is not None and bound <= spec[kind] for kind, bound in bounds.items()):
                statistics["yield"]["certain"] = True
        document["statistics"] = statistics
    if allocate is not None:
        allocation = document["allocation"] = allocation_to_dict(error_map, allocate, weights, per_angle, spelling)
        width = allocation["relative_width"]
        if width is None or width > ALLOCATION_WIDTH:
            side = (
                "no clearance was found beyond the spec (no unsafe side)"
                if allocation["lambda_high"] is None
                else f"its relative width is {width:.3g}"
            )
            warnings.append(
                {
                    "code": "allocation_width_not_reached",
                    "message": f"the tolerance bracket is wider than {ALLOCATION_WIDTH:g}: {side}; lambda_low "
                    f"{allocation['lambda_low']:.9g} is still proven safe (a limit the tool hardly reaches, "
                    "or one below what the bounds resolve)",
                }
            )
    document["warnings"] = warnings
    from bcad.model.results import checked
    from bcad.worstcase.result import MaxErrorResult

    return checked(document, MaxErrorResult)


#: the relative width of a tolerance bracket above which ``bcad maxerror --allocate`` warns
ALLOCATION_WIDTH = 1e-6


def allocation_to_dict(
    error_map, spec: dict[str, float], weights: list[float] | None, per_angle: float, spelling: Spelling = COMMAND_LINE
) -> dict:
    """Tolerance synthesis (:mod:`bcad.worstcase.allocate`) in the problem's units."""
    from bcad.worstcase.allocate import allocate as allocate_clearances

    if weights is not None and len(weights) != error_map.joints:
        raise InputError(
            spelling.where("weights"), f"gives {len(weights)} weights for a chain of {error_map.joints} joints"
        )
    internal = {kind: value / per_angle if kind == "rotation" else value for kind, value in spec.items()}
    found = allocate_clearances(error_map, internal, None if weights is None else np.array(weights, float))
    factors = np.ones(error_map.joints) if weights is None else np.array(weights, float)
    unit = np.array([per_angle, per_angle, 1.0, 1.0])
    clearances = error_map.clearance * (found.lambda_low * factors)[:, None] * unit[None, :]

    def in_units(values: dict[str, float]) -> dict[str, float]:
        return {kind: value * per_angle if kind == "rotation" else value for kind, value in values.items()}

    return {
        "spec": dict(spec),
        "weights": None if weights is None else list(weights),
        "lambda_low": found.lambda_low,
        "lambda_high": found.lambda_high if np.isfinite(found.lambda_high) else None,
        "relative_width": found.relative_width if np.isfinite(found.relative_width) else None,
        "exact_bound_at_lambda_low": in_units(found.bound_at_low),
        "witness_errors_at_lambda_high": in_units(found.witness_errors),
        "clearances_at_lambda_low": [
            dict(zip(("rot_xy", "rot_z", "trans_xy", "trans_z"), map(float, row))) for row in clearances
        ],
        "note": "lambda_low is proven safe (the exact model's certified bound is within the spec there); "
        "lambda_high is shown unsafe (a feasible clearance there exceeds the spec by more than 1e-9 relative)",
    }
