"""The solver against brute force, tempering's limit, Monte Carlo's convergence rate, errors."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import TypeAdapter
from typer.testing import CliRunner

from bcad.bayes.objective import Objective
from bcad.bayes.run import solve_document as solve
from bcad.bayes.sampling import FreeParameterSampler
from bcad.cli import app
from bcad.compiler import compile_problem
from bcad.kinematics import Samples
from bcad.model import load_problem
from bcad.model.distributions import Distribution
from bcad.tempering import relaxed_log_indicator

runner = CliRunner()

# A planar 2R arm (links 1.0 and 0.8) with uncertain zero offsets must put its
# tool on the line x = 1.2 (only tx of the closing link is scored), so one
# degree of freedom is left to choose the configuration that propagates the
# zero-offset errors least.
PLANAR_2R = """
name: planar-2r
frames: [base, f1, g1, f2, h2, g2, tool, target]
links:
  - {name: joint1, parent: base, child: f1, status: FFFFFX, bounds: {rz: [-3.1, 3.1]}}
  - {name: zero1, parent: f1, child: g1, status: FFFFFL, distributions: {rz: 'normal(0, 0.02)'}}
  - {name: arm1, parent: g1, child: f2, pose: [1.0, 0, 0, 0, 0, 0]}
  - {name: joint2, parent: f2, child: h2, status: FFFFFX, bounds: {rz: [-3.1, 3.1]}}
  - {name: zero2, parent: h2, child: g2, status: FFFFFL, distributions: {rz: 'normal(0, 0.05)'}}
  - {name: arm2, parent: g2, child: tool, pose: [0.8, 0, 0, 0, 0, 0]}
  - {name: line, parent: base, child: target, pose: [1.2, 0, 0, 0, 0, 0]}
  - {name: reach, parent: target, child: tool, close: true, status: LFFFFF, distributions: {tx: 'normal(0, 0.005)'}}
solver: {posterior_samples: 20000}
"""


def test_planar_2r_optimum_matches_a_brute_force_grid(write_problem):
    compiled = compile_problem(load_problem(write_problem(PLANAR_2R)))
    result = solve(compiled, backend="bayes", seed=1)
    x = np.array([result["solution"]["joint1.rz"], result["solution"]["joint2.rz"]])

    objective = Objective(compiled)
    samples = Samples(FreeParameterSampler(compiled).draw(np.random.default_rng(42), 1500))
    grid = np.linspace(-3.1, 3.1, 125)
    population = np.array(np.meshgrid(grid, grid, indexing="ij")).reshape(2, -1).T
    values = objective.log_value(population, samples, 0.0)
    brute = population[int(np.argmax(values))]
    # The solver's X is as good as the grid's best on the same samples, up to the
    # grid's resolution (0.05 rad), ...
    ours = objective.log_value(x, samples, 0.0)[0]
    assert ours >= values.max() - 0.05

    # ... and it propagates the zero-offset errors about as little: tool x is
    # 1.0 cos(q1 + d1) + 0.8 cos(q1 + d1 + q2 + d2).
    def spread(q):
        d = samples.values
        angle1 = q[0] + d[:, 0]
        return np.std(1.0 * np.cos(angle1) + 0.8 * np.cos(angle1 + q[1] + d[:, 1]))

    assert spread(x) <= 1.05 * spread(brute)
    assert spread(x) < 0.5 * np.median([spread(q) for q in population[values > values.max() - 8]])


@pytest.mark.parametrize(
    "text, x",
    [
        ("normal(0.2, 0.1)", 0.5),
        ("uniform(-1, 1)", 1.3),
        ("truncnormal(0, 1, -0.5, 0.5)", -0.7),
        ("disc(0.5)", [0.3, 0.6]),
    ],
)
def test_tempered_densities_tend_to_the_original_as_t_goes_to_zero(text, x):
    distribution = TypeAdapter(Distribution).validate_python(text)
    x = np.asarray(x, dtype=float)
    inside = x * 0.5
    for point in (x, inside):
        original = distribution.logpdf(point)
        values = [distribution.tempered_logpdf(point, t) for t in (1.0, 0.1, 1e-3, 1e-6)]
        assert distribution.tempered_logpdf(point, 0.0) == original
        if np.isfinite(original):
            assert abs(values[-1] - original) < 1e-4
        else:
            assert values[1] > values[2] > values[3]  # the relaxed tail closes
            assert values[-1] < -1e4
    # Heated, the support widens: a point outside gets a finite value.
    assert np.isfinite(distribution.tempered_logpdf(x, 50.0))


def test_relaxed_indicator_is_the_paper_interval_limit():
    distance = np.array([-0.5, 0.0, 0.1, 1.0])
    assert list(relaxed_log_indicator(distance, 2.0, 0.0)) == [0.0, 0.0, -np.inf, -np.inf]
    np.testing.assert_allclose(relaxed_log_indicator(distance, 2.0, 1.0), [0, 0, -0.0025, -0.25])


def test_estimator_standard_error_shrinks_like_one_over_sqrt_n(write_problem):
    compiled = compile_problem(load_problem(write_problem(PLANAR_2R)))
    objective = Objective(compiled)
    sampler = FreeParameterSampler(compiled)
    from scipy.optimize import brentq

    # A configuration on the line x = 1.2, where the integrand is not negligible.
    q2 = -1.2
    q1 = brentq(lambda q: np.cos(q) + 0.8 * np.cos(q + q2) - 1.2, 0.0, 1.5)
    x = np.array([[q1, q2]])
    rng = np.random.default_rng(0)

    def spread(n: int) -> float:
        estimates = [np.exp(objective.log_value(x, Samples(sampler.draw(rng, n)), 0.0)[0]) for _ in range(200)]
        return float(np.std(estimates))

    ratio = spread(250) / spread(4000)
    assert ratio == pytest.approx(4.0, rel=0.25)  # sqrt(4000 / 250) = 4


def test_tempering_widens_the_objective_support(write_problem):
    compiled = compile_problem(load_problem(write_problem(PLANAR_2R)))
    objective = Objective(compiled)
    samples = Samples(FreeParameterSampler(compiled).draw(np.random.default_rng(1), 500))
    far = np.array([[0.0, 0.0]])  # tool at x = 1.8, 0.6 from the line: 120 sigma
    cold = objective.log_value(far, samples, 0.0)[0]
    warm = objective.log_value(far, samples, 100.0)[0]
    assert cold < -5000 and warm > -10


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda t: t.replace("status: FFFFFX, bounds: {rz: [-3.1, 3.1]}", "status: FFFFFF"), "no X"),
        (
            lambda t: t.replace(
                "  - {name: reach, parent: target, child: tool, close: true, status: LFFFFF, distributions: {tx: 'normal(0, 0.005)'}}\n",
                "",
            ),
            "no cycle",
        ),
        (
            lambda t: t.replace("close: true, status: LFFFFF, distributions: {tx: 'normal(0, 0.005)'}", "close: true"),
            "no distribution",
        ),
    ],
)
def test_unsolvable_problems_exit_2(write_problem, edit, message):
    path = write_problem(edit(PLANAR_2R))
    result = runner.invoke(app, ["solve", str(path), "--quiet"])
    assert result.exit_code == 2, result.output
    assert message in result.stderr
    assert result.stderr.startswith(str(path))
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize("samples", ["abc", "0", "1.5", "-3"])
def test_sample_counts_are_checked(write_problem, samples):
    result = runner.invoke(app, ["solve", str(write_problem(PLANAR_2R)), "--samples", samples])
    assert result.exit_code == 2


def test_result_file_never_replaces_the_problem(write_problem):
    path = write_problem(PLANAR_2R)
    before = path.read_text()
    result = runner.invoke(app, ["solve", str(path), "-o", str(path), "--quiet", "--samples", "1e3"])
    assert result.exit_code == 2
    assert path.read_text() == before


def test_posterior_set_checks_names(write_problem):
    path = write_problem(PLANAR_2R)
    result = runner.invoke(app, ["posterior", str(path), "--value", "joint1.rx=1", "--value", "joint2.rz=0"])
    assert result.exit_code == 2
    assert "did you mean 'joint1.rz'" in result.stderr
    missing = runner.invoke(app, ["posterior", str(path), "--value", "joint1.rz=1"])
    assert missing.exit_code == 2 and "joint2.rz" in missing.stderr


def test_point_on_face_relaxation_as_in_figure_2():
    from bcad.relations.point_on_face import constraint as point_on_face

    relation = point_on_face([(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)])
    points = np.array([[0.5, 0.5, 0.0], [1.5, 0.0, 0.0], [3.0, 3.0, 0.0]]).T  # (3, N)
    columns = np.broadcast_to(np.eye(3)[:, :, None], (3, 3, 3))  # identity rotations
    cold = relation.log_satisfaction(columns, points, 0.0)
    assert list(cold) == [0.0, -np.inf, -np.inf]
    t50, t100 = relation.log_satisfaction(columns, points, 50.0), relation.log_satisfaction(columns, points, 100.0)
    assert t50[0] == t100[0] == 0.0
    # (d / w)^2 / T with w = 2: 0.5 outside one edge; 2 outside two edges.
    np.testing.assert_allclose(t50[1:], [-(0.25**2) / 50, -2 * (1.0**2) / 50])
    assert np.all(t100[1:] > t50[1:])


def test_quasi_monte_carlo_samples_have_the_prior_moments(write_problem):
    compiled = compile_problem(load_problem(write_problem(PLANAR_2R)))
    draws = FreeParameterSampler(compiled, qmc=True).draw(np.random.default_rng(0), 4096)
    np.testing.assert_allclose(draws.mean(axis=0), [0, 0], atol=2e-4)
    np.testing.assert_allclose(draws.std(axis=0), [0.02, 0.05], rtol=0.01)
    again = FreeParameterSampler(compiled, qmc=True).draw(np.random.default_rng(0), 4096)
    np.testing.assert_array_equal(draws, again)


#: a foot uniform on [-2, 2] x normal(0, 1) standing on a face of width WIDTH and depth 2 (a tree
#: relation: its draws are kept where the foot is on the face); tests/bayes/test_uncertain_sizes.py gives
#: the width a distribution
STANDING_FOOT = """
name: local
frames: [table, block]
entities:
  - {name: top, type: face, frame: table, size: [WIDTH, 2]}
  - {name: foot, type: point, frame: block}
relations:
  - name: standing
    type: point_on_face
    parent: top
    child: foot
    close: false
    status: LLFFFF
    distributions: {tx: 'uniform(-2, 2)', ty: 'normal(0, 1)'}
"""


def test_tree_relations_are_sampled_by_exact_rejection(write_problem):
    compiled = compile_problem(load_problem(write_problem(STANDING_FOOT.replace("WIDTH", "2"))))
    draws = FreeParameterSampler(compiled).draw(np.random.default_rng(3), 20000)
    assert np.all(np.abs(draws) <= 1.0)  # the point stays on the 2 x 2 face
    # The prior restricted to the face: tx uniform on [-1, 1], ty a normal truncated to [-1, 1].
    assert np.mean(draws[:, 0] < 0.0) == pytest.approx(0.5, abs=0.02)
    assert np.std(draws[:, 0]) == pytest.approx(2 / np.sqrt(12), rel=0.03)
    from scipy import stats

    truncated = stats.truncnorm(-1, 1)
    assert np.std(draws[:, 1]) == pytest.approx(truncated.std(), rel=0.03)
