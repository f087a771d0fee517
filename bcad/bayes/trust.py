"""When a result cannot be trusted: the warnings of a result and their codes.

bcad never exits 0 on an answer it cannot stand behind. Each warning is
``{"code", "message"}``; the command line prints them and exits with code 3.

| code | when |
|---|---|
| ``log_value_not_finite`` | log p(X*) I(X*) is not finite: no sample scored above 0 |
| ``no_sample_satisfies`` | no posterior sample meets a closing link's relation |
| ``few_effective_samples`` | the estimate rests on fewer than MIN_EFFECTIVE effective samples, the posterior's figures (Table 2) on fewer than MIN_EFFECTIVE samples, or (importance) the estimate on fewer than MIN_RELATIVE_EFFECTIVE of its samples |
| ``pareto_k_high`` | the Pareto k̂ of the weights exceeds MAX_PARETO_K: the standard error cannot be trusted |
| ``nominal_better`` | the nominal backend's solution scores higher, by more than two standard errors |
| ``linear_moment_matched`` | the ``linear`` estimate replaced a non-normal L or score by a normal of its mean and variance: its value is not the objective's, and its standard error (0 without inequalities) is not its error |

A *design finding* is not a trust failure: the numbers are right, the design misses a goal.
:func:`design_findings` lists them (``{"code", "message"}``, printed, exit code 0):

| code | when |
|---|---|
| ``search_not_settled`` | the search's best value was reached by one of its independent runs only, on the stand-in and among the finalists' estimates of the exact objective (:func:`search_findings`): another seed may end at another X, better or worse |
| ``gimbal_lock`` | a closing link's mean ry is within GIMBAL_DEGREES of ±90 degrees while its rx or rz spreads: R = Rz(rz) Ry(ry) Rx(rx) turns rx and rz about nearly one axis there, so only rz - rx (ry near +90) or rz + rx (near -90) is well defined, and their separate means and stds are not (:func:`gimbal_findings`) |
| ``x_unused`` | an X enters no cycle and no relation (its link lies on a branch that closes nothing): its value changes nothing, and the solution's value of it means nothing (:func:`bound_findings`) |
| ``goal_missed`` | with every L at its mean, a scored parameter misses its distribution's mean by more than CLOSURE_TOLERANCE of its predictive spread sqrt(sigma_O^2 + J Sigma_L J^T) (the score's std and the propagated L; a curvilinear coordinate to second order, bcad.bayes.linear): a bound, a prior on X or another cycle pulls X away, or the cell cannot meet its goal |
"""

from __future__ import annotations

import math

import numpy as np

from bcad.errors import counted

MIN_EFFECTIVE = 100.0
#: below this share of the samples effective, an importance estimate's proposal missed the target
MIN_RELATIVE_EFFECTIVE = 0.005
MAX_PARETO_K = 0.7
#: two estimates of a log value that differ by less than this relative amount are one value
ROUNDING = 1e-9
#: a search value at or below this is its stand-in for -inf (bcad.bayes.search.PENALTY, -1e12: a
#: climb whose objective was nowhere finite), said as -inf (not imported: posterior needs no search)
NOT_FINITE = -1e11
#: the command a warning names for scoring the same X again with more samples
RESCORE = "`bcad posterior --at RESULT --samples N`"
CLOSURE_TOLERANCE = 3.0


def result_warnings(posterior, estimate, nominal_estimate=None) -> list[dict]:
    """The warnings of a result (module docstring), in a fixed order."""
    warnings: list[dict] = []

    def warn(code: str, message: str) -> None:
        warnings.append({"code": code, "message": message})

    if not math.isfinite(estimate.log_value):
        warn(
            "log_value_not_finite",
            f"log p(X) I(X) is {estimate.log_value}: no sample gave the closing links a non-zero score",
        )
    for link in posterior.links:
        if link.satisfied == 0:
            warn("no_sample_satisfies", f"no posterior sample meets the relation of closing link '{link.name}'")
    if estimate.effective_samples is not None and estimate.effective_samples < MIN_EFFECTIVE:
        warn(
            "few_effective_samples",
            f"the {estimate.estimator} estimate rests on {estimate.effective_samples:.1f} effective samples "
            f"(fewer than {MIN_EFFECTIVE:g}); its value and weighted posterior are noise-limited: "
            + ("--estimator importance adapts its samples to the scores, or " if estimate.estimator == "mc" else "")
            + f"{RESCORE} with more samples shows how far they move",
        )
    elif 0 < posterior.samples < MIN_EFFECTIVE:
        # (the linear estimate is exact, but Table 2's means and stds are still those of the samples)
        warn(
            "few_effective_samples",
            f"the posterior's figures rest on {counted(posterior.samples, 'sample')} (fewer than "
            f"{MIN_EFFECTIVE:g}): their means, stds and standard errors are noise-limited; {RESCORE} "
            "draws more (solve: --samples or solver.posterior_samples)",
        )
    elif (
        estimate.estimator == "importance"
        and estimate.effective_samples is not None
        and estimate.samples
        and estimate.effective_samples < MIN_RELATIVE_EFFECTIVE * estimate.samples
    ):
        warn(
            "few_effective_samples",
            f"the importance estimate rests on {100 * estimate.effective_samples / estimate.samples:.2f} % of "
            f"its samples (fewer than {100 * MIN_RELATIVE_EFFECTIVE:g} %): its proposal misses the integrand, "
            f"so its standard error is not reliable; {RESCORE} with more samples and "
            "another --seed shows how far the value moves",
        )
    if estimate.pareto_k is not None and estimate.pareto_k > MAX_PARETO_K:
        warn(
            "pareto_k_high",
            f"the weights' Pareto k = {estimate.pareto_k:.2f} exceeds {MAX_PARETO_K}: "
            "the standard errors cannot be trusted (the weights' tail is heavy, which more samples cure only "
            f"slowly); compare another --seed and {RESCORE} with ten times the "
            "samples: a value that moves by more than its standard error is not settled",
        )
    matched = estimate.moment_matched
    if estimate.estimator == "linear" and matched:
        warn(
            "linear_moment_matched",
            f"the linear estimate replaced the non-normal distribution of {counted(len(matched), 'parameter')} "
            f"({', '.join(matched[:3])}{', ...' if len(matched) > 3 else ''}) by a normal of the same mean and "
            "variance: its value is not the objective's, and its standard error is not its error; "
            "--estimator importance scores the distributions themselves",
        )
    if nominal_estimate is not None and math.isfinite(nominal_estimate.log_value):
        gap = nominal_estimate.log_value - estimate.log_value
        se = (
            math.hypot(estimate.log_value_se, nominal_estimate.log_value_se)
            if math.isfinite(estimate.log_value)
            else 0.0
        )
        # (beyond round-off too: where every weight is equal the standard errors are 0, and the two
        # estimates of one value differ in their last bits)
        if not math.isfinite(estimate.log_value) or gap > max(2.0 * se, ROUNDING * max(1.0, abs(estimate.log_value))):
            warn(
                "nominal_better",
                f"the nominal backend's solution scores higher (log objective {nominal_estimate.log_value:.3f} "
                f"against {estimate.log_value:.3f}, standard error of the difference {se:.3f})",
            )
    return warnings


def design_findings(compiled, linear, x: np.ndarray) -> list[dict]:
    """Goals the design misses at X (module docstring): each scored parameter's miss, with every
    L at its mean, against its predictive spread; what may pull X away is named."""
    findings = bound_findings(compiled, x, unused_unknowns(linear.chains, len(x)))
    if not len(linear.scored):
        return findings
    lin = linear.linearise(np.asarray(x, dtype=float)[None])
    # against the scores' Gaussian to second order: a touch of a sphere aims inside it by the bias
    # that lateral errors give its distance (bcad.bayes.linear), which is no miss
    covariance, residual = linear.scored_gaussian(lin)
    misses = -residual[0] / np.sqrt(np.diagonal(covariance[0]))
    pulls = []
    if any(finding["code"] == "x_at_bound" for finding in findings):
        pulls.append("a bound that holds X (x_at_bound)")
    if compiled.parameters.x_priors:
        pulls.append("a prior on X")
    if len(compiled.graph.cycles) > 1:
        pulls.append("another cycle's goal")
    why = (
        f"{' or '.join(pulls)} may pull X away from it, or the cell cannot meet it"
        if pulls
        else "nothing else in the problem pulls X away from it, so the cell cannot meet it at this X (is the goal "
        "within reach?)"
    )
    for row, miss in zip(linear.scored, misses):
        if not abs(miss) <= CLOSURE_TOLERANCE:
            findings.append(
                {
                    "code": "goal_missed",
                    "message": f"at the solution, with every L at its mean, {row.name} misses its scored value by "
                    f"{abs(miss):.3g} times its predictive spread (the score's std and the propagated L); {why}",
                }
            )
    return findings


#: a closing link's ry this close to +-90 degrees is a gimbal lock of its rpy angles (module docstring)
GIMBAL_DEGREES = 6.0
#: rx's or rz's std (rad) above which they spread: below, a rotation fixed but for rounding
GIMBAL_SPREAD = 1e-9


def gimbal_findings(posterior) -> list[dict]:
    """``gimbal_lock`` (module docstring) for each closing link whose mean ry lies within
    GIMBAL_DEGREES of +-90 degrees while its rx or rz spreads (by more than GIMBAL_SPREAD). There
    Ry(+-pi/2) Rx(rx) = Rz(-+rx) Ry(+-pi/2): rx turns about the axis rz turns about, and a
    rotation a few thousandths of a radian wide spreads rx and rz over ranges up to 1 / cos(ry)
    times its width, together (ry near +90: rz - rx holds) or in opposite directions (near -90:
    rz + rx holds)."""
    findings = []
    for link in posterior.links:
        ry = float(link.mean[4])
        spread = float(max(link.std[3], link.std[5]))
        if abs(90.0 - abs(math.degrees(ry))) < GIMBAL_DEGREES and spread > GIMBAL_SPREAD:
            defined = "rz - rx" if ry > 0 else "rz + rx"
            findings.append(
                {
                    "code": "gimbal_lock",
                    "message": f"closing link '{link.name}': its ry is {math.degrees(ry):.1f} degrees, within "
                    f"{GIMBAL_DEGREES:g} of {'+' if ry > 0 else '-'}90, where rx and rz (R = Rz Ry Rx) turn about "
                    f"nearly one axis: their separate means and stds are not meaningful, only {defined} is; "
                    "frames turned so that the link's ry is near 0 (its entities' or frames' poses) read plainly",
                }
            )
    return findings


#: an X this close to a bound, relative to the bounds' width, sits on it
AT_BOUND = 1e-6
#: an angular X's bounds spanning more turns than this, in radians, were likely written in
#: degrees (+-180 read as radians is 57 turns; a robot joint's own +-2 pi, 2)
MANY_TURNS = 4
#: an angle's bounds this close to a whole turn, relative to it, were meant as one (+-3.14159 rad
#: falls 5.3e-6 rad short, +-179.9 deg 0.2 deg): its finding says so instead of "widen them"
NEAR_TURN = 1e-3


def unused_unknowns(chains, count: int) -> np.ndarray:
    """Per X (``count`` of them), whether it enters none of ``chains`` (the cycles' and the tree
    relations' chains, :class:`bcad.bayes.linear.LinearModel`'s): p(X) I(X) does not depend on it."""
    used = np.zeros(count, dtype=bool)
    for chain in chains:
        for step in chain.folded_steps:
            for term in getattr(getattr(step, "value", None), "terms", ()):
                if term.source == "x":
                    used[term.index] = True
    return ~used


def bound_findings(compiled, x: np.ndarray, unused: np.ndarray | None = None) -> list[dict]:
    """``x_at_bound`` for each X the solution puts on one of the bounds the problem gives it (not a
    robot joint's own limits, the end of its travel, and not a periodic angle, whose bounds are
    the same angle): the most robust configuration may lie beyond the range the problem allows,
    and the user should know it is their bound, not the cell, that decides. Also ``angle_in_turns``
    for an angle's bounds (the problem's, in radians) of more than MANY_TURNS turns, and
    ``x_unused`` for each X that ``unused`` marks (:func:`unused_unknowns`) instead of a bound's
    finding: no value of it is better than another."""
    from bcad.bayes.objective import periodic_unknowns, turning_unknowns
    from bcad.compiler.units import parameter_scales

    table = compiled.parameters
    periodic = np.isfinite(periodic_unknowns(compiled))
    turning = turning_unknowns(compiled)
    scales = parameter_scales(compiled, table.x_names)
    findings = []
    for k, (name, value, (low, high)) in enumerate(zip(table.x_names, np.asarray(x, dtype=float), table.x_bounds)):
        width = high - low
        link = table.x[k].link  # -1: an entity's dimension, whose bounds the problem gives
        given = link < 0 or compiled.graph.links[link].bounds_given  # not a robot joint's own limits
        turns = width / (2.0 * math.pi)
        # (a periodic angle too: +-90 meant in degrees, read as radians, bounds nothing)
        if given and table.x[k].slot >= 3 and compiled.problem.units.angle == "rad" and turns > MANY_TURNS:
            findings.append(
                {
                    "code": "angle_in_turns",
                    "message": f"{name}'s bounds [{low:.6g}, {high:.6g}] rad span {turns:.3g} turns: degrees "
                    "written as radians? (units: {angle: deg} reads every angle of the file in degrees)",
                }
            )
        if unused is not None and unused[k]:
            findings.append(
                {
                    "code": "x_unused",
                    "message": f"{name} enters no cycle and no relation: its value changes nothing, and the "
                    "solution's value of it means nothing; fix it (status F), or close a cycle through its link",
                }
            )
            continue
        if periodic[k] or not width > 0 or not given:
            continue
        short = 2.0 * math.pi - width  # an angle's bounds just short of a whole turn, as written
        near_turn = turning[k] and 0.0 < short <= NEAR_TURN * 2.0 * math.pi
        for side, bound in (("lower", low), ("upper", high)):
            if abs(value - bound) <= AT_BOUND * width:
                at = f"{name} is at its {side} bound ({bound * scales[k]:.6g})"
                if near_turn:
                    message = (
                        f"{at}, and its bounds fall {short * scales[k]:.2g} {compiled.problem.units.angle} short of "
                        "a whole turn: the search stops there as at a wall, where the angle goes on round; bounds "
                        "spanning a whole turn (+-3.1415927 rad, +-180 deg) let it wrap"
                    )
                else:
                    message = (
                        f"{at}: the most robust value may lie beyond the bounds the problem gives it; widen them to "
                        "look there, or keep them if they are the cell's real limits"
                    )
                findings.append({"code": "x_at_bound", "message": message})
    return findings


def search_findings(verdict: dict | None) -> list[dict]:
    """``search_not_settled`` where the search's verdict (:func:`bcad.bayes.estimators.solve`) says
    its best value was not reached twice: by two lineages of the branch search (a cell at several
    configurations) or by two climbs, each within AGREE (0.02) of the best value
    (:data:`bcad.bayes.estimators.AGREE`), nor by two finalists' estimates of the exact objective."""
    if not verdict or verdict.get("settled", True):
        return []
    run, runs = (
        ("lineage of the branch search", "lineages of the branch search")
        if verdict["method"] == "lineages"
        else ("climb", "climbs")
    )
    values = ", ".join(f"{v:.3f}" if v > NOT_FINITE else "-inf" for v in verdict["values"][:4] if v is not None)
    finalists = (
        f", and no finalist of another {run} came within {verdict.get('agree', 0.02):g} of the answer's estimate of "
        "log p(X) I(X)"
        if verdict.get("finalists_scored", 0) >= 2
        and verdict.get("runs_reached_best", verdict.get("finalists_reached_best")) == 1
        else ""
    )
    return [
        {
            "code": "search_not_settled",
            "message": f"only {verdict['reached_best']} of {counted(verdict['runs'], run, runs)} reached the best value of the "
            f"search's linearised stand-in log p(X) I_lin(X) (their best values: {values}; the result's "
            f"log p(X) I(X) is the exact objective's estimate){finalists}: another seed may end at another X, "
            "better or worse; run again with another --seed and keep the best, or raise solver.search_effort (2 searches about twice as long)",
        }
    ]
