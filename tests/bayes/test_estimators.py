"""The linearised and importance estimators against closed forms and brute force."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from bcad.bayes.document import solution_from_dict
from bcad.bayes.estimators import estimate
from bcad.bayes.linear import LinearModel
from bcad.bayes.model import BayesModel
from bcad.bayes.objective import Objective
from bcad.bayes.run import solve_document as solve
from bcad.bayes.sampling import FreeParameterSampler
from bcad.compiler import compile_problem
from bcad.kinematics import Samples
from bcad.model import load_problem

from conftest import ONE_LINK_GRAPH, run_bcad

# Translations only, so the closing pose is X + L1 + L2 (linear), every L Gaussian and
# the closing link scored by Gaussians on tx, ty, tz: I(X) is a Gaussian in closed form.
SIGMA_1 = np.array([0.3, 0.2, 0.5])
SIGMA_2 = np.array([0.1, 0.4, 0.2])
SIGMA_O = np.array([0.25, 0.3, 0.15])
MEAN_1 = np.array([0.05, 0.0, -0.1])
MEAN_O = np.array([0.0, 0.02, 0.0])
NOMINAL = np.array([2.0, -1.0, 0.5])
LINEAR_GAUSSIAN = f"""
name: linear-gaussian
frames: [a, m, n, b]
links:
  - {{name: unknown, parent: a, child: m, status: XXXFFF, bounds: {{tx: [-5, 5], ty: [-5, 5], tz: [-5, 5]}}}}
  - name: first
    parent: m
    child: n
    status: LLLFFF
    distributions: {{tx: 'normal({MEAN_1[0]}, {SIGMA_1[0]})', ty: 'normal({MEAN_1[1]}, {SIGMA_1[1]})', tz: 'normal({MEAN_1[2]}, {SIGMA_1[2]})'}}
  - name: second
    parent: n
    child: b
    status: LLLFFF
    distributions: {{tx: 'normal(0, {SIGMA_2[0]})', ty: 'normal(0, {SIGMA_2[1]})', tz: 'normal(0, {SIGMA_2[2]})'}}
  - name: measured
    parent: a
    child: b
    pose: [{NOMINAL[0]}, {NOMINAL[1]}, {NOMINAL[2]}, 0, 0, 0]
    status: LLLFFF
    close: true
    distributions: {{tx: 'normal({MEAN_O[0]}, {SIGMA_O[0]})', ty: 'normal({MEAN_O[1]}, {SIGMA_O[1]})', tz: 'normal({MEAN_O[2]}, {SIGMA_O[2]})'}}
solver: {{posterior_samples: 20000, finalist_samples: 4096}}
"""
LOG_PRIOR = -3 * math.log(10.0)  # uniform on [-5, 5]^3
VARIANCE = SIGMA_1**2 + SIGMA_2**2 + SIGMA_O**2


def exact_log_integral(x: np.ndarray) -> float:
    """I(X) = prod_k N(mu_O; x + mu_1 - nominal, sigma_1^2 + sigma_2^2 + sigma_O^2)."""
    residual = MEAN_O - (x + MEAN_1 - NOMINAL)
    return float(np.sum(-0.5 * residual**2 / VARIANCE - 0.5 * np.log(2 * math.pi * VARIANCE)))


def exact_posterior(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std of the closing translation given its scores (precision-weighted)."""
    prior_mean, prior_variance = x + MEAN_1, SIGMA_1**2 + SIGMA_2**2
    precision = 1 / prior_variance + 1 / SIGMA_O**2
    mean = (prior_mean / prior_variance + (NOMINAL + MEAN_O) / SIGMA_O**2) / precision
    return mean, precision**-0.5


@pytest.fixture(scope="module")
def linear_gaussian(tmp_path_factory):
    path = tmp_path_factory.mktemp("lg") / "problem.yaml"
    path.write_text(LINEAR_GAUSSIAN, encoding="utf-8")
    return compile_problem(load_problem(path))


def test_linear_estimator_is_exact_on_a_linear_gaussian_problem(linear_gaussian):
    model = LinearModel(linear_gaussian)
    xs = np.random.default_rng(1).uniform(-3, 3, size=(6, 3))
    values, se = model.log_integral(xs)
    np.testing.assert_allclose(values, [exact_log_integral(x) for x in xs], rtol=0, atol=1e-9)
    assert np.all(se == 0)


def test_importance_estimate_agrees_with_the_closed_form_within_its_standard_errors(linear_gaussian):
    model = BayesModel(linear_gaussian)
    for seed, x in enumerate(np.array([[2.1, -0.9, 0.6], [1.0, 0.0, 1.5]])):
        found = estimate(model, x, "importance", 20000, np.random.default_rng(seed))
        exact = LOG_PRIOR + exact_log_integral(x)
        assert 0 < found.log_value_se < 0.05
        assert abs(found.log_value - exact) < 3 * found.log_value_se
        mean, std = exact_posterior(x)
        link = found.links[0]
        # 12 comparisons per X: at 4 standard errors a right estimator fails one in about 1300
        # runs (over 40 seeds the z-scores of these means and stds have sd 0.9-1.07)
        for k in range(3):
            assert abs(link["mean"][k] - mean[k]) < 4 * link["mean_se"][k]
            assert abs(link["std"][k] - std[k]) < 4 * link["std_se"][k]
        assert found.effective_samples > 0.5 * 20000


def test_an_importance_estimate_on_a_thread_pool_is_the_serial_one_bit_for_bit(linear_gaussian):
    """Each chunk has its own stream and chunks are summed in order: computed on two workers,
    the estimate and the weighted posterior are those of the serial run exactly, and still the
    closed form's within their standard errors."""
    from concurrent.futures import ThreadPoolExecutor

    model = BayesModel(linear_gaussian)
    x = np.array([2.1, -0.9, 0.6])
    samples = 3 * 16384 + 100  # four chunks, the last short
    serial = estimate(model, x, "importance", samples, np.random.default_rng(5))
    with ThreadPoolExecutor(max_workers=2) as pool:
        pooled = estimate(model, x, "importance", samples, np.random.default_rng(5), pool)
    assert (pooled.log_value, pooled.log_value_se, pooled.effective_samples) == (
        serial.log_value,
        serial.log_value_se,
        serial.effective_samples,
    )
    for key in ("mean", "std", "mean_se", "std_se"):
        np.testing.assert_array_equal(pooled.links[0][key], serial.links[0][key])
    assert abs(serial.log_value - (LOG_PRIOR + exact_log_integral(x))) < 3 * serial.log_value_se


def test_a_failing_chunk_stops_the_pooled_estimate_without_running_the_rest(linear_gaussian, monkeypatch):
    """An error in one chunk is the estimate's error, and the chunks not yet reached are not run:
    a few are submitted ahead, not all of them."""
    from concurrent.futures import ThreadPoolExecutor

    from bcad.bayes import importance

    model = BayesModel(linear_gaussian)
    original, calls = importance.ImportanceSampler.chunk, []

    def failing(self, *args):
        calls.append(1)
        if len(calls) == 2:
            raise FloatingPointError("chunk 2")
        return original(self, *args)

    monkeypatch.setattr(importance.ImportanceSampler, "chunk", failing)
    with ThreadPoolExecutor(max_workers=2) as pool, pytest.raises(FloatingPointError, match="chunk 2"):
        estimate(model, np.array([2.1, -0.9, 0.6]), "importance", 40 * 16384, np.random.default_rng(5), pool)
    assert len(calls) <= 2 + importance.AHEAD_CHUNKS + 1 < 40


def test_solve_finds_the_linear_gaussian_optimum(linear_gaussian):
    result = solve(linear_gaussian, backend="bayes", seed=0)
    x = solution_from_dict(linear_gaussian, result["solution"])
    best = NOMINAL + MEAN_O - MEAN_1  # the residual vanishes
    assert LOG_PRIOR + exact_log_integral(x) > LOG_PRIOR + exact_log_integral(best) - 0.01
    objective = result["objective"]
    assert objective["estimator"] == "importance"
    assert abs(objective["log_value"] - (LOG_PRIOR + exact_log_integral(x))) < 3 * objective["log_value_se"]
    assert result["warnings"] == []
    # Contributors: the variance of tx splits as sigma_1^2 : sigma_2^2 between the two links.
    tx = result["contributors"]["measured"]["tx"]
    share = SIGMA_1[0] ** 2 / (SIGMA_1[0] ** 2 + SIGMA_2[0] ** 2)
    assert tx["by_link"]["first"] == pytest.approx(share, abs=1e-6)
    assert tx["by_parameter"]["second.tx"] == pytest.approx(1 - share, abs=1e-6)
    assert tx["std"] == pytest.approx(math.hypot(SIGMA_1[0], SIGMA_2[0]), rel=1e-6)


# A planar 2R arm with zero errors on both joints, closed on its end pose (tx, ty, rz).
PLANAR_2R = """
name: planar-2r
frames: [a, j1, e1, j2, e2, t]
links:
  - {name: zero1, parent: a, child: j1, status: FFFFFL, distributions: {rz: 'normal(0, 0.05)'}}
  - {name: joint1, parent: j1, child: e1, status: FFFFFX, bounds: {rz: [-3, 3]}}
  - {name: upper, parent: e1, child: j2, pose: [1, 0, 0, 0, 0, 0]}
  - {name: zero2, parent: j2, child: e2, status: FFFFFL, distributions: {rz: 'normal(0, 0.03)'}}
  - {name: joint2, parent: e2, child: t, pose: [0, 0, 0, 0, 0, 0], status: FFFFFX, bounds: {rz: [-3, 3]}}
  - name: target
    parent: a
    child: t
    pose: [0.8, 0.9, 0, 0, 0, 0]
    status: LLFFFF
    close: true
    distributions: {tx: 'normal(0, 0.02)', ty: 'normal(0, 0.02)'}
"""


def importance_z_scores(model: BayesModel, x: np.ndarray, reference: float, count: int = 50) -> np.ndarray:
    """(estimate - reference) / its standard error for ``count`` seeded importance estimates of N = 200."""
    z = []
    for seed in range(count):
        found = estimate(model, x, "importance", 200, np.random.default_rng(seed))
        z.append((found.log_value - reference) / found.log_value_se)
    return np.array(z)


def planar_2r_with_tool() -> str:
    """The planar 2R arm with a 0.6-long tool after joint 2 (so both zero errors move the
    closed point) and scores of 0.05: the nonlinear problem of the standard-error check."""
    text = PLANAR_2R.replace("frames: [a, j1, e1, j2, e2, t]", "frames: [a, j1, e1, j2, e2, t, t2]")
    text = text.replace("child: t\n    pose: [0.8, 0.9", "child: t2\n    pose: [0.8, 0.9")
    text += "  - {name: tool, parent: t, child: t2, pose: [0.6, 0, 0, 0, 0, 0]}\n"
    return text.replace("normal(0, 0.02)", "normal(0, 0.05)")


def test_jacobian_matches_the_analytic_one_of_a_planar_arm(write_problem):
    compiled = compile_problem(load_problem(write_problem(PLANAR_2R)))
    model = LinearModel(compiled)
    for q1, q2 in [(0.3, 0.7), (-1.2, 2.0), (2.5, -0.4)]:
        lin = model.linearise(np.array([[q1, q2]]))
        J = lin.jacobians[0][:6]
        # End of a 1-long upper arm: (cos q1, sin q1); the second joint sits there, at the end.
        tx, ty = math.cos(q1), math.sin(q1)
        expected_l1 = [-ty, tx, 0, 0, 0, 1]
        expected_l2 = [0, 0, 0, 0, 0, 1]
        np.testing.assert_allclose(J[:, 0], expected_l1, rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(J[:, 1], expected_l2, rtol=1e-7, atol=1e-9)


def test_importance_standard_errors_are_honest_on_a_nonlinear_problem(write_problem):
    """z-scores of 50 independent importance estimates against a 2e6-sample Monte Carlo reference
    (its standard error, 0.0005, is a tenth of theirs)."""
    compiled = compile_problem(load_problem(write_problem(planar_2r_with_tool())))
    objective = Objective(compiled)
    x = np.array([0.4, 1.3])
    samples = Samples(FreeParameterSampler(compiled).draw(np.random.default_rng(123), 2_000_000))
    reference = float(objective.log_value(x[None], samples, 0.0)[0])
    z = importance_z_scores(BayesModel(compiled), x, reference)
    assert abs(z.mean()) < 0.5
    assert 0.8 < z.std() < 1.25


def test_every_estimator_runs_from_the_command_line(write_problem):
    path = write_problem(
        ONE_LINK_GRAPH
        + "solver: {population: 12, max_samples: 256, selection_samples: 1024, posterior_samples: 20000}\n"
    )
    for estimator in ("importance", "linear", "mc"):
        run = run_bcad("solve", path, "--estimator", estimator, "--quiet", "--seed", "1")
        assert run.returncode in (0, 3), run.stderr
        result = json.loads(run.stdout)
        assert result["objective"]["estimator"] == estimator
        # I(X) = N(X; 3, 0.5^2) with the prior N(1, 2^2): log p(X*) I(X*) in closed form.
        x = result["solution"]["unknown.tx"]
        exact = (
            -0.5 * ((x - 1) / 2) ** 2 - math.log(2) - 0.5 * ((x - 3) / 0.5) ** 2 - math.log(0.5) - math.log(2 * math.pi)
        )
        tolerance = 1e-9 if estimator == "linear" else 4 * result["objective"]["log_value_se"]
        assert abs(result["objective"]["log_value"] - exact) <= tolerance
    bad = run_bcad("solve", path, "--estimator", "magic")
    assert bad.returncode == 2 and "magic" in bad.stderr


def test_untrusted_results_warn_and_exit_3(write_problem):
    path = write_problem(ONE_LINK_GRAPH)
    # X far from closing the cycle (6 standard deviations of its score), and a sample
    # count too small for 100 effective samples.
    run = run_bcad("posterior", path, "--value", "unknown.tx=9", "--samples", "50", "--json")
    assert run.returncode == 3, run.stderr
    document = json.loads(run.stdout)
    assert "few_effective_samples" in [warning["code"] for warning in document["warnings"]]
    # a warning says what to do next: more samples at the same X
    assert all("bcad posterior --at RESULT --samples N" in warning["message"] for warning in document["warnings"])
    # Missing the goal is a design finding, not a trust failure: listed and printed.
    assert [finding["code"] for finding in document["findings"]] == ["goal_missed"]
    assert "finding [goal_missed]" in run.stderr
    ok = run_bcad("posterior", path, "--value", "unknown.tx=2.8", "--json")
    assert ok.returncode == 0, ok.stderr
    assert json.loads(ok.stdout)["warnings"] == []


def test_a_linear_estimate_on_few_posterior_samples_warns_and_exits_3(write_problem):
    """The linear estimate of log p(X) I(X) is exact, but Table 2's means and stds are those of the
    posterior samples: on 2 samples they are noise with a standard error that reads 0."""
    path = write_problem(ONE_LINK_GRAPH)
    few = run_bcad("posterior", path, "--value", "unknown.tx=2.8", "--estimator", "linear", "--samples", "2", "--json")
    assert few.returncode == 3, few.stderr
    warnings = json.loads(few.stdout)["warnings"]
    assert [w["code"] for w in warnings] == ["few_effective_samples"]
    assert "rest on 2 samples" in warnings[0]["message"]
    assert "bcad posterior --at RESULT --samples N" in warnings[0]["message"]
    enough = run_bcad("posterior", path, "--value", "unknown.tx=2.8", "--estimator", "linear", "--samples", "100")
    assert enough.returncode == 0, enough.stderr


def test_a_linear_estimate_of_a_non_normal_l_warns_and_exits_3(write_problem):
    """A uniform L of width 2 seen through a narrow score: I(X) = 1/2 where the cycle closes within
    it, which the importance estimate finds; the linear estimate's moment-matched normal gives
    N(0; 0, sqrt(1/3 + 0.01^2)) instead, 0.32 higher, with a standard error of 0: a warning says so."""
    text = ONE_LINK_GRAPH.replace("normal(0, 0.3)", "uniform(-1, 1)").replace("normal(0, 0.4)", "normal(0, 0.01)")
    path = write_problem(text)
    log_prior = -0.5 - math.log(2) - 0.5 * math.log(2 * math.pi)  # N(3; 1, 2)
    linear = run_bcad("posterior", path, "--value", "unknown.tx=3", "--estimator", "linear", "--json")
    assert linear.returncode == 3, linear.stderr
    document = json.loads(linear.stdout)
    assert [w["code"] for w in document["warnings"]] == ["linear_moment_matched"]
    assert "free.tx" in document["warnings"][0]["message"]
    moment_matched = log_prior - 0.5 * math.log(2 * math.pi * (1 / 3 + 0.01**2))
    assert document["objective"]["log_value"] == pytest.approx(moment_matched, abs=1e-9)
    exact = run_bcad("posterior", path, "--value", "unknown.tx=3", "--json", "--samples", "20000")
    assert exact.returncode == 0, exact.stderr
    objective = json.loads(exact.stdout)["objective"]
    assert abs(objective["log_value"] - (log_prior + math.log(0.5))) < 4 * objective["log_value_se"] + 1e-6
    # a normal L: the linear estimate is exact, and says nothing
    plain = run_bcad("posterior", write_problem(ONE_LINK_GRAPH), "--value", "unknown.tx=3", "--estimator", "linear")
    assert plain.returncode == 0 and "linear_moment_matched" not in plain.stderr, plain.stderr


def test_a_missed_goal_is_a_finding_with_exit_0(write_problem):
    """X held 6 score-stds from closing, with enough samples: the numbers are trusted (exit 0),
    and the miss, measured against the predictive spread sqrt(sigma_O^2 + J Sigma_L J^T), is a
    finding. Near the goal there is none."""
    path = write_problem(ONE_LINK_GRAPH)
    far = run_bcad("posterior", path, "--value", "unknown.tx=9", "--samples", "2e4", "--json")
    document = json.loads(far.stdout)
    assert far.returncode == 0 and document["warnings"] == [], far.stderr
    assert [finding["code"] for finding in document["findings"]] == ["goal_missed"]
    assert "finding [goal_missed]" in far.stderr
    assert document["findings"][0]["message"].endswith(
        "a prior on X may pull X away from it, or the cell cannot meet it"
    ), document["findings"][0]["message"]
    # without a prior on X nor another cycle, nothing pulls X: the goal is out of reach at this X
    alone = write_problem(ONE_LINK_GRAPH.replace(", distributions: {tx: 'normal(1, 2)'}", ""))
    document = json.loads(run_bcad("posterior", alone, "--value", "unknown.tx=9", "--samples", "2e4", "--json").stdout)
    assert (
        "nothing else in the problem pulls X away from it, so the cell cannot meet it at this X"
        in (document["findings"][0]["message"])
    )
    near = run_bcad("posterior", path, "--value", "unknown.tx=2.8", "--json")
    assert json.loads(near.stdout)["findings"] == []


PEG_CENTRED = """
name: peg-centred
units: {length: mm, angle: rad}
frames: [world, fixture, gripper, peg_frame]
links:
  - {name: fixture_placement, parent: world, child: fixture, pose: [0, 0, 0, 0, 0, 0]}
  - name: gripper_placement
    parent: world
    child: gripper
    pose: [0, 0, 50, 0, 0, 0]
    status: XXFFFF
    bounds: {tx: [-1, 1], ty: [-1, 1]}
  - name: gripper_error
    parent: gripper
    child: peg_frame
    status: LLFFFF
    distributions: {tx: "normal(0, {sigma})", ty: "normal(0, {sigma})"}
entities:
  - {name: hole, type: cylinder, frame: fixture, radius: 5.0, length: 20.0}
  - {name: peg, type: cylinder, frame: peg_frame, pose: [0, 0, -40, 0, 0, 0], radius: {peg}, length: 60.0}
relations:
  - {name: insertion, type: cylinder_in_cylinder, parent: hole, child: peg, close: true}
"""


@pytest.mark.parametrize("ratio", [0.8, 1.5, 2.5])
def test_the_surrogate_of_a_centred_peg_sees_its_lateral_error(write_problem, ratio):
    """A vertical peg centred over its hole with a lateral error tx, ty ~ N(0, sigma): it goes in
    when |(tx, ty)| <= c, the radial clearance, so I = P(Rayleigh <= c) = 1 - exp(-c^2 / (2
    sigma^2)) in closed form. The peg's radial distance |r| - c has no gradient at r = 0, so a
    surrogate that linearises the distances there sees no lateral error at all (log I_lin = 0);
    the surrogate evaluates them at drawn poses. Its kernels widen each distance by 0.3 (the
    sharper surrogate) or 0.6 (the search's) of its spread, an effective sigma sqrt(1 + 0.3^2)
    and sqrt(1 + 0.6^2) times the true one: the closed form at that sigma, within the draws' noise."""
    sigma, clearance = 0.1, 0.1 * ratio
    text = PEG_CENTRED.replace("{sigma}", f"{sigma:g}").replace("{peg}", f"{5.0 - clearance:g}")
    model = BayesModel(compile_problem(load_problem(write_problem(text, "peg.yaml"))))
    x = np.zeros((1, 2))
    for linear, widening in ((model.polish_linear, 0.3), (model.search_linear, 0.6)):
        effective = sigma * math.sqrt(1.0 + widening**2)
        expected = math.log1p(-math.exp(-(clearance**2) / (2.0 * effective**2)))
        value, se = linear.log_integral(x)  # log P(H): no score besides the inequalities
        assert abs(value[0] - expected) < max(0.03, 4 * se[0]), (widening, value[0], expected, se[0])


def test_the_surrogate_drawn_in_l_space_is_the_one_drawn_in_pose_space():
    """Where the relations' pose rows outnumber the L, the conditional Gaussian is drawn in L's
    space (rank nL, no r x r Cholesky): the same distribution, so the same P_lin(H) to the
    quadrature's noise. The RX90 example (6 rows, 48 L) both ways, 4096 fixed points each, at
    the nominal backend's X and at points of a line through it."""
    from bcad.bayes.linear import fixed_normal_points

    from conftest import RX90_EXAMPLE

    compiled = compile_problem(load_problem(RX90_EXAMPLE))
    rows_model = LinearModel(compiled, draws=4096)
    l_model = LinearModel(compiled, draws=4096)
    assert not rows_model.in_l_space
    l_model.in_l_space = True
    l_model.draws = fixed_normal_points(4096, len(l_model.mean_l))
    from bcad.bayes.nominal import solve_nominal

    x0 = solve_nominal(BayesModel(compiled), np.random.default_rng(0)).x  # the cycle closed nominally
    direction = np.random.default_rng(3).standard_normal(len(x0))
    population = x0 + np.outer(np.linspace(-2e-3, 2e-3, 5), direction)
    by_rows, se_rows = rows_model.log_integral(population)
    by_l, se_l = l_model.log_integral(population)
    assert np.all(np.isfinite(by_rows)) and np.ptp(by_rows) > 0.1  # the line crosses the landscape
    assert np.all(np.abs(by_l - by_rows) < 4 * np.hypot(se_rows, se_l) + 1e-3), (by_rows, by_l, se_rows)


def test_many_relations_are_drawn_in_l_space_and_solve_quickly(write_problem):
    """40 points on 40 faces, one X: 240 relation rows, no L. The search drew a 240-dimensional
    Gaussian per point (16 s); in L's space it is exact and takes well under a second."""
    import time

    faces = "".join(
        f"  - {{name: f{k}, type: face, frame: a, pose: [0, 0, 0, 0, 0, 0], size: [10, 10]}}\n"
        f"  - {{name: p{k}, type: point, frame: b, at: [0, 0, 0]}}\n"
        for k in range(40)
    )
    touches = "".join(
        f"  - {{name: r{k}, type: point_on_face, parent: f{k}, child: p{k}, status: FFLFFF, "
        "distributions: {tz: 'normal(0, 0.1)'}}\n"
        for k in range(40)
    )
    problem = write_problem(
        "name: many\nframes: [a, b]\nlinks:\n  - {name: x, parent: a, child: b, status: FFXFFF, "
        "bounds: {tz: [-1, 1]}}\nentities:\n" + faces + "relations:\n" + touches + "solver: {posterior_samples: 2000}\n"
    )
    model = BayesModel(compile_problem(load_problem(problem)))
    assert model.search_linear.in_l_space and len(model.search_linear.relation_rows) == 240
    started = time.perf_counter()
    values, _ = model.search_linear.log_integral(np.linspace(-0.5, 0.5, 11)[:, None])
    assert time.perf_counter() - started < 2.0
    # 40 independent N(0, 0.1) scores of tz = x: log p = 40 log N(x; 0, 0.1), the faces' indicators 1
    expected = 40 * (-0.5 * (np.linspace(-0.5, 0.5, 11) / 0.1) ** 2 - math.log(0.1 * math.sqrt(2 * math.pi)))
    assert np.allclose(values, expected, atol=1e-6)


def test_the_search_line_of_an_untrusted_result_says_its_estimates_are_doubted():
    from bcad.bayes.document import search_line

    search = {
        "climbs": 3,
        "starts": 64,
        "basins": [{}, {}],
        "verdict": {"method": "climbs", "agree": 0.02, "runs": 3, "reached_best": 2, "settled": True},
        "choice": {"margin": 5.0, "margin_se": 1.0},
    }
    trusted = search_line(search)
    assert "settled" in trusted and "doubt" not in trusted
    assert search_line(search, trusted=False) == trusted + (
        " (the finalists' estimates behind this are of the kind the warnings below doubt)"
    )


def test_the_nominal_is_better_only_beyond_two_standard_errors_and_round_off():
    """Where every importance weight is equal, the standard errors are 0 and the nominal's estimate
    of the same value differed in its last bits (-8.504181555478729 against -8.50418155547873):
    nominal_better, exit 3, on a sound result. Round-off is one value; 0.01 above at se 0 is not."""
    from bcad.bayes.estimators import ObjectiveEstimate
    from bcad.bayes.trust import result_warnings

    posterior = type("Posterior", (), {"links": [], "samples": 100_000})()

    def at(value: float, se: float = 0.0) -> ObjectiveEstimate:
        return ObjectiveEstimate("importance", value, se, 2000, 2000.0, None, [])

    def codes(nominal: ObjectiveEstimate) -> list[str]:
        return [w["code"] for w in result_warnings(posterior, at(-8.50418155547873), nominal)]

    assert codes(at(-8.504181555478729)) == []
    assert codes(at(-8.494)) == ["nominal_better"]
    assert codes(at(-8.494, se=0.006)) == []
