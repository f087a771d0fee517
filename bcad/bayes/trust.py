"""When a result cannot be trusted: the warnings of a result and their codes.

bcad never exits 0 on an answer it cannot stand behind. Each warning is
``{"code", "message"}``; the command line prints them and exits with code 3.

| code | when |
|---|---|
| ``log_value_not_finite`` | log p(X*) I(X*) is not finite: no sample scored above 0 |
| ``no_sample_satisfies`` | no posterior sample meets a closing link's relation |
| ``few_effective_samples`` | the estimate rests on fewer than MIN_EFFECTIVE effective samples |
| ``pareto_k_high`` | the Pareto k̂ of the weights exceeds MAX_PARETO_K: the standard error cannot be trusted |
| ``nominal_better`` | the nominal backend's solution scores higher, by more than two standard errors |
| ``cycle_not_closed`` | with every L at its mean, a cycle misses its closing link's scored value by more than CLOSURE_TOLERANCE of the score's std |
"""

from __future__ import annotations

import math

import numpy as np

MIN_EFFECTIVE = 100.0
MAX_PARETO_K = 0.7
CLOSURE_TOLERANCE = 3.0


def result_warnings(compiled, linear, x: np.ndarray, posterior, estimate, nominal_estimate=None) -> list[dict]:
    """The warnings of a result at X (module docstring), in a fixed order."""
    warnings: list[dict] = []

    def warn(code: str, message: str) -> None:
        warnings.append({"code": code, "message": message})

    if not math.isfinite(estimate.log_value):
        warn("log_value_not_finite", f"log p(X) I(X) is {estimate.log_value}: no sample gave the closing links a non-zero score")
    for link in posterior.links:
        if link.satisfied == 0:
            warn("no_sample_satisfies", f"no posterior sample meets the relation of closing link '{link.name}'")
    if estimate.effective_samples is not None and estimate.effective_samples < MIN_EFFECTIVE:
        warn(
            "few_effective_samples",
            f"the {estimate.estimator} estimate rests on {estimate.effective_samples:.1f} effective samples "
            f"(fewer than {MIN_EFFECTIVE:g}); its value and weighted posterior are noise-limited",
        )
    if estimate.pareto_k is not None and estimate.pareto_k > MAX_PARETO_K:
        warn("pareto_k_high", f"the weights' Pareto k = {estimate.pareto_k:.2f} exceeds {MAX_PARETO_K}: "
             "the standard errors cannot be trusted")
    if nominal_estimate is not None and math.isfinite(nominal_estimate.log_value):
        gap = nominal_estimate.log_value - estimate.log_value
        se = math.hypot(estimate.log_value_se, nominal_estimate.log_value_se) if math.isfinite(estimate.log_value) else 0.0
        if not math.isfinite(estimate.log_value) or gap > 2.0 * se:
            warn("nominal_better", f"the nominal backend's solution scores higher (log objective {nominal_estimate.log_value:.3f} "
                 f"against {estimate.log_value:.3f}, standard error of the difference {se:.3f})")
    lin = linear.linearise(np.asarray(x, dtype=float)[None])
    misses = (linear.scored_deviation(lin.poses)[0] - linear.scored_mean) / np.sqrt(linear.scored_variance)
    for row, miss in zip(linear.scored, misses):
        if not abs(miss) <= CLOSURE_TOLERANCE:
            warn("cycle_not_closed", f"at the solution, with every L at its mean, {row.name} misses its scored value by "
                 f"{abs(miss):.3g} standard deviations of its distribution")
    return warnings
