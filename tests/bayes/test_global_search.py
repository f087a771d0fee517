"""The global search of X*: a space-filling design, batched closure, climbs in rounds,
basins and their coverage, checked against a brute-force search of the closure manifold."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from bcad.bayes.closure import CycleClosure
from bcad.bayes.document import solution_from_dict
from bcad.bayes.estimators import search_budget
from bcad.bayes.model import BayesModel
from bcad.bayes.nominal import CLOSED
from bcad.bayes.search import Basin, LocalMaximum, group_basins, unseen_mass
from bcad.compiler import compile_problem
from bcad.model import load_problem
from bcad.numerics.design import halton, radical_inverse

from conftest import REPO, run_bcad

PLANAR = REPO / "problems" / "studies" / "planar_2r.yaml"


def test_radical_inverse_is_van_der_corput():
    np.testing.assert_allclose(radical_inverse(np.arange(1, 8), 2), [0.5, 0.25, 0.75, 0.125, 0.625, 0.375, 0.875])
    np.testing.assert_allclose(radical_inverse(np.arange(1, 4), 3), [1 / 3, 2 / 3, 1 / 9])


def test_halton_fills_every_interval_evenly():
    """The first 3^4 points put exactly 3^3 in each third of the base-3 axis, and a shifted design
    stays in the cube with the same evenness (a shift modulo 1 moves every interval alike)."""
    points = halton(81, 3)
    counts = np.histogram(points[:, 1], bins=3, range=(0, 1))[0]
    assert list(counts) == [27, 27, 27]
    shifted = halton(64, 5, np.random.default_rng(0))
    assert shifted.shape == (64, 5) and np.all((shifted >= 0) & (shifted < 1))
    assert list(np.histogram(shifted[:, 0], bins=8, range=(0, 1))[0]) == [8] * 8


def test_batched_closure_closes_like_one_by_one():
    """The batched Levenberg-Marquardt never raises a start's cost, closes most starts (the
    planar 2R has stationary points where any LM stalls: one by one, 11 of these 16 close), and
    what it calls closed is closed (the tool on its line, by the closed form)."""
    compiled = compile_problem(load_problem(PLANAR))
    model = BayesModel(compiled)
    closure = CycleClosure(compiled, model.objective)
    starts = np.random.default_rng(1).uniform(-3.0, 3.0, size=(16, 2))
    closed, costs = closure.close_many(starts, 100)
    assert np.all(costs <= np.sum(closure.residuals_of(starts) ** 2, axis=1))
    assert np.sum(costs < CLOSED) >= 7
    for x, cost in zip(closed, costs):
        assert cost == pytest.approx(float(np.sum(closure.residuals(x) ** 2)), rel=1e-9, abs=1e-20)
        if cost < CLOSED:  # the tool on the line x = 1.2 m
            tool_x = math.cos(x[0]) + 0.8 * math.cos(x[0] + x[1])
            assert abs(tool_x - 1.2) < 1e-5


def test_basins_group_nearby_maxima_and_count_their_climbs():
    def separation(a, b):  # the unit box's max norm, broadcast over leading axes
        return np.max(np.abs(a - b), axis=-1)

    maxima = [
        LocalMaximum(np.array([0.5, 0.5]), -1.0, 0, 10),
        LocalMaximum(np.array([0.502, 0.5]), -1.001, 1, 10),
        LocalMaximum(np.array([0.1, 0.9]), -2.0, 2, 10),
    ]
    basins = group_basins(maxima, separation)
    assert [b.climbs for b in basins] == [2, 1] and basins[0].log_value == -1.0
    assert unseen_mass(basins) == pytest.approx(1 / 3)
    assert unseen_mass([Basin(np.zeros(2), 0.0, 5, 1, starts=5)]) == 0.0
    # Weighted by the screened starts each climb stands for: 1 + 4 starts in the best basin.
    weighted = group_basins(maxima, separation, weights=np.array([1, 4, 1]))
    assert [b.starts for b in weighted] == [5, 1] and unseen_mass(weighted) == pytest.approx(1 / 6)


def test_basins_and_distinct_maxima_are_those_of_pairwise_comparisons():
    """Grouping compares a maximum with every basin in one broadcast: the same basins, counts and
    distinct maxima as comparing pair by pair, on clustered random maxima."""
    from bcad.bayes.search import distinct_maxima

    rng = np.random.default_rng(5)

    def separation(a, b):
        return np.max(np.abs(a - b), axis=-1)

    centres = rng.uniform(0, 1, size=(6, 3))
    points = centres[rng.integers(0, 6, 200)] + rng.normal(0, 0.006, size=(200, 3))
    maxima = [LocalMaximum(x, float(v), k, 5) for k, (x, v) in enumerate(zip(points, rng.normal(size=200)))]
    weights = rng.integers(1, 5, 200)
    reference: list[list] = []  # [x, climbs, starts] per basin, pair by pair
    for m in sorted(maxima, key=lambda m: -m.log_value):
        match = next((b for b in reference if separation(m.x, b[0]) <= 0.01), None)
        if match is None:
            reference.append([m.x, 1, int(weights[m.start])])
        else:
            match[1] += 1
            match[2] += int(weights[m.start])
    basins = group_basins(maxima, separation, weights=weights)
    assert len(basins) == len(reference) > 6  # the noise splits some clusters
    assert [(b.climbs, b.starts) for b in basins] == [(r[1], r[2]) for r in reference]
    assert all(np.array_equal(b.x, r[0]) for b, r in zip(basins, reference))
    ordered = sorted(maxima, key=lambda m: -m.log_value)
    chosen = []
    for m in ordered:
        if all(separation(m.x, c.x) > 0.01 for c in chosen):
            chosen.append(m)
    assert distinct_maxima(ordered, 8, separation) == chosen[:8]


def _manifold_maximum(compiled, model) -> float:
    """Brute force, independent of the search: log p(X) I_lin(X) on the closure manifold of the
    planar 2R (tool on x = 1.2 m, both elbow branches), joint 1 on a grid of 20,001 points."""
    q1 = np.linspace(-3.1, 3.1, 20001)
    ratio = (1.2 - np.cos(q1)) / 0.8
    ok = np.abs(ratio) <= 1.0
    best = -np.inf
    for sign in (1.0, -1.0):
        q2 = sign * np.arccos(np.clip(ratio[ok], -1, 1)) - q1[ok]
        q2 = (q2 + np.pi) % (2 * np.pi) - np.pi
        inside = np.abs(q2) <= 3.1
        X = np.column_stack([q1[ok][inside], q2[inside]])
        value = model.objective.log_prior(X) + model.linear.log_integral(X)[0]
        best = max(best, float(np.max(value)))
    return best


def test_the_search_finds_the_manifold_maximum_on_every_seed():
    """Estimator linear (no Monte Carlo in the value): every seed's X* is within 0.02 of the
    brute-force maximum over the whole closure manifold, and the result records the search."""
    compiled = compile_problem(load_problem(PLANAR))
    reference = _manifold_maximum(compiled, BayesModel(compiled))
    starts, climbs = search_budget(compiled.problem.solver, 2, 2)
    assert (starts, climbs) == (960, 192)  # the default budget at n = 2, nL = 2: the cap of 192 climbs, 5 starts each
    values = []
    for seed in range(4):
        run = run_bcad("solve", PLANAR, "--estimator", "linear", "--seed", seed, "--quiet", cwd=REPO)
        assert run.returncode in (0, 3), run.stderr
        document = json.loads(run.stdout)
        values.append(document["objective"]["log_value"])
        search = document["diagnostics"]["search"]
        assert search["starts"] == 1 + starts and 2 <= search["climbs"] <= climbs
        assert sum(basin["climbs"] for basin in search["basins"]) == search["climbs"]
        assert (
            sum(basin["starts"] for basin in search["basins"]) == search["coverage"]["starts_in_basins"] <= 1 + starts
        )
        assert 0.0 <= search["coverage"]["unseen_mass"] <= 1.0
    assert max(values) <= reference + 0.02
    assert min(values) >= reference - 0.02, (values, reference)


def test_a_problem_whose_starts_all_close_to_one_point_is_settled(write_problem):
    """One X that every start closes to (the goal fixes it): one basin reached from every start,
    the verdict settled and no search finding; uniform L only: no pareto_k_high, exit 0."""
    path = write_problem("""
        name: uniform-only
        frames: [a, m, b]
        links:
          - {name: unknown, parent: a, child: m, status: XFFFFF, bounds: {tx: [-10, 10]}}
          - {name: free, parent: m, child: b, status: LFFFFF, distributions: {tx: 'uniform(-0.5, 0.5)'}}
          - {name: measured, parent: a, child: b, pose: [3, 0, 0, 0, 0, 0], status: LFFFFF, close: true,
             distributions: {tx: 'uniform(-0.4, 0.4)'}}
        """)
    run = run_bcad("solve", path, "--quiet")
    assert run.returncode == 0, run.stderr
    document = json.loads(run.stdout)
    search = document["diagnostics"]["search"]
    assert len(search["basins"]) == 1 and search["coverage"]["best_basin_starts"] >= 60
    assert search["verdict"]["settled"] and "search_not_settled" not in run.stderr
    assert all(finding["code"] != "search_not_settled" for finding in document["findings"])
    assert document["warnings"] == [] and document["solution"]["unknown.tx"] == pytest.approx(3.0, abs=1e-3)


def test_batched_closure_in_memory_bounded_chunks_gives_the_same(monkeypatch):
    """Many starts or many unknowns: the normal matrices are formed a chunk of starts at a time,
    with the same result as all at once; the search's budget shrinks with the dimension."""
    import bcad.bayes.closure as closure_module
    from bcad.bayes.estimators import search_budget
    from bcad.model.solver import SolverSettings

    compiled = compile_problem(load_problem(PLANAR))
    closure = CycleClosure(compiled, BayesModel(compiled).objective)
    starts = np.random.default_rng(2).uniform(-3.0, 3.0, size=(10, 2))
    whole = closure.close_many(starts, 30)
    monkeypatch.setattr(closure_module, "CLOSE_MEMORY", 8 * 4 * 3)  # three starts a chunk
    chunked = closure.close_many(starts, 30)
    np.testing.assert_array_equal(whole[0], chunked[0])
    np.testing.assert_array_equal(whole[1], chunked[1])
    settings = SolverSettings()
    assert search_budget(settings, 12, 48) == (120, 24)  # the RX90's: 84672 / (144 x 49) = 12, raised to 24
    assert search_budget(settings, 6, 15) == (735, 147)  # the UR5 face's: 84672 / (36 x 16)
    assert search_budget(settings, 2000, 10) == (1, 2)
    assert search_budget(settings, 18, 17, blocks=True) == (160, 32)  # a UR5 at three configurations
    assert search_budget(settings, 12, 17, blocks=True) == (165, 32)  # at two: the default's 33 climbs' starts
    assert search_budget(settings, 63, 17, blocks=True) == (160, 25)  # the climbs' cap: 1e5 / 63^2
    assert search_budget(settings.model_copy(update={"search_climbs": 5, "search_starts": 7}), 6, 15) == (7, 5)
    # search_effort multiplies the defaults and the caps, not a budget the file gives
    twice, half = settings.model_copy(update={"search_effort": 2.0}), settings.model_copy(update={"search_effort": 0.5})
    assert search_budget(twice, 12, 48) == (240, 48) and search_budget(half, 12, 48) == (60, 12)
    assert search_budget(twice, 6, 15) == (1470, 294)
    assert search_budget(twice, 18, 17, blocks=True) == (320, 64)
    assert search_budget(twice, 63, 17, blocks=True) == (320, 50)  # the cap doubled too
    assert search_budget(twice.model_copy(update={"search_climbs": 5, "search_starts": 7}), 6, 15) == (7, 5)
    given = {"search_climbs": 20, "search_starts": 200}  # given budgets keep the unscaled caps
    for effort in (0.5, 1.0, 2.0):
        settings_given = settings.model_copy(update={**given, "search_effort": effort})
        assert search_budget(settings_given, 63, 17, blocks=True) == (200, 20)
        assert search_budget(settings_given, 100, 17) == (100, 10)  # 1e8 / 100^3 starts, 1e5 / 100^2 climbs
    # the scaled defaults stay within the settings' own limits (1e4 starts, 1e3 climbs)
    assert search_budget(settings.model_copy(update={"search_effort": 50.0}), 6, 15) == (5000, 1000)


UNIFORM_PULL = REPO / "problems" / "studies" / "uniform_pull.yaml"


def _uniform_pull_exact(x: np.ndarray) -> np.ndarray:
    """log p(X) I(X) in closed form: N(x; 0, 1) times the uniform(-1, 1) L convolved with the
    closing N(0, 0.05): (Phi((4 - x) / 0.05) - Phi((2 - x) / 0.05)) / 2."""
    from scipy.stats import norm

    with np.errstate(divide="ignore"):
        return norm.logpdf(x) + np.log((norm.cdf((4.0 - x) / 0.05) - norm.cdf((2.0 - x) / 0.05)) / 2.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_non_gaussian_l_is_optimised_on_the_integrand_not_its_gaussian_surrogate(seed):
    """A prior pulls X towards 0, a uniform L lets it stop anywhere within 1 of 3: the integrand's
    optimum is at the plateau's near edge (2.083, log value -3.831 on a fine grid of the closed
    form), the moment-matched surrogate's at 2.25 (-4.14: 0.31 lower). Every seed ends within
    0.02 of the closed-form optimum, with the exact climb on record."""
    grid = np.linspace(1.5, 3.5, 200001)
    exact = _uniform_pull_exact(grid)
    best_x, best_value = grid[np.argmax(exact)], float(np.max(exact))
    assert best_x == pytest.approx(2.083, abs=0.002)
    run = run_bcad("solve", UNIFORM_PULL, "--seed", seed, "--quiet")
    assert run.returncode == 0, run.stderr
    document = json.loads(run.stdout)
    x = document["solution"]["unknown.tx"]
    assert float(_uniform_pull_exact(np.array([x]))[0]) >= best_value - 0.02, x
    assert document["objective"]["log_value"] == pytest.approx(
        best_value, abs=4 * document["objective"]["log_value_se"] + 0.02
    )
    climb = document["diagnostics"]["search"]["finalists"][0]["exact_climb"]
    assert climb["kept"] and climb["rounds"] >= 1


IIWA = REPO / "problems" / "studies" / "iiwa_probe_face.yaml"


def stand_in_value(model: BayesModel, x: np.ndarray) -> float:
    """log p(X) + log I_lin(X) at one X: the value the search's climbs and walks maximise."""
    log_integral, _ = model.search_linear.log_integral(x[None])
    return float(model.objective.log_prior(x[None])[0] + log_integral[0])


def test_a_bounded_step_holds_what_leaves_the_box_and_solves_the_rest_again():
    """A Newton step that would carry variables out of the box: held at the bound they reach, the
    others re-solved. On concave quadratic models it is never worse than clipping the plain step,
    and where one variable leaves (2-D) it is the model's maximum over the box (scipy's bounded
    minimiser, independent)."""
    from scipy.optimize import minimize

    from bcad.bayes.search import Climb, bounded_step

    rng = np.random.default_rng(4)
    compared = 0
    for n in (2,) * 40 + (5, 7, 7):
        a = rng.normal(size=(n, n))
        hessian = -(a @ a.T + 0.1 * np.eye(n))
        unit = rng.uniform(0.05, 0.95, n)
        unit[0] = 1.0 - 1e-5  # a joint just inside its limit, as in the redundant arm's climbs
        gradient = rng.normal(size=n) * 5
        climb = Climb(unit, 0.0, gradient, hessian, damping=0.0)

        def model(step):
            return float(gradient @ step + 0.5 * step @ hessian @ step)

        plain = np.linalg.solve(-hessian, gradient)
        step = bounded_step(climb, np.ones(n, dtype=bool), np.zeros(n, dtype=bool), plain)
        assert np.all(unit + step >= -1e-12) and np.all(unit + step <= 1 + 1e-12)
        clipped = np.clip(unit + plain, 0.0, 1.0) - unit
        assert model(step) >= model(clipped) - 1e-12
        if n == 2 and np.sum((unit + plain < 0) | (unit + plain > 1)) == 1:
            best = minimize(
                lambda s: -model(s),
                np.zeros(n),
                jac=lambda s: -(gradient + hessian @ s),
                bounds=list(zip(-unit, 1 - unit)),
                method="L-BFGS-B",
                options={"ftol": 1e-15, "gtol": 1e-12},
            )
            assert model(step) == pytest.approx(-best.fun, abs=1e-9)
            compared += 1
    assert compared >= 3


def _curved_ridge(unit: np.ndarray, with_residuals: bool = False):
    """A stiff score along a parabola, w = 1e4 (u2 - 0.5 - 2 (u1 - 0.5)^2), and a soft pull along it,
    -50 (u1 - 0.8)^2: the top is (0.8, 0.68), value 0."""
    unit = np.atleast_2d(unit)
    w = 1e4 * (unit[:, 1] - 0.5 - 2.0 * (unit[:, 0] - 0.5) ** 2)
    f = -0.5 * w**2 - 50.0 * (unit[:, 0] - 0.8) ** 2
    return (f, w[:, None]) if with_residuals else f


def test_the_climbs_second_order_correction_follows_a_curved_ridge(monkeypatch):
    """Along a curved ridge of a stiff score (a redundant arm's closure: curvatures 1e8-3e9 across, 1e2
    along), a Newton step leaves the ridge at second order; the value drops, the damping grows and
    the steps crawl (a UR5 at three poses: 111 steps to -41.782, where 36 with the correction
    reached -41.743). With the correction the climb reaches the top of this one in 27 steps
    (4 of them its convergence test); without it, it is not halfway after 40 (-3.06 after 80)."""
    from bcad.bayes import search
    from bcad.bayes.search import Climb, advance

    periodic = np.zeros(2, dtype=bool)
    start = np.array([0.3, 0.5 + 2.0 * 0.2**2])  # on the ridge, 0.5 from its top
    climb = Climb(start.copy())
    advance(_curved_ridge, [climb], 40, periodic)
    # at the top within the climbs' convergence (CONVERGED), stopped there by its own test
    assert climb.value > -1e-4 and np.allclose(climb.unit, [0.8, 0.68], atol=1e-3), (climb.value, climb.unit)
    assert climb.stopped and climb.iterations < 40
    monkeypatch.setattr(search, "second_order_correction", lambda climb, candidate, *rest: candidate)
    plain = Climb(start.copy())
    advance(_curved_ridge, [plain], 40, periodic)
    assert plain.value < -1.0 and plain.unit[0] < 0.5, plain  # crawling: not halfway in 40 steps


def test_no_climb_takes_more_newton_steps_than_the_iterations_allow():
    """``search_iterations`` caps every climb, the rounds of successive halving included (with
    fewer iterations than the rounds' 40 steps, the rounds stop there)."""
    from bcad.bayes.search import maximise_in_rounds

    model = BayesModel(compile_problem(load_problem(IIWA)))
    starts = model.objective.canonical(
        np.random.default_rng(5).uniform(*model.objective.bounds.T, size=(4, model.objective.dimension))
    )
    capped = maximise_in_rounds(model.search_linear, starts, 3)
    assert max(m.iterations for m in capped) == 3
    longer = maximise_in_rounds(model.search_linear, starts, 60)
    assert max(m.iterations for m in longer) > 3
    assert capped[0].log_value < longer[0].log_value - 0.1  # three steps do not reach the top


def test_a_redundant_arm_climbs_to_the_top_of_its_ridge():
    """problems/studies/iiwa_probe_face.yaml (7 joints, a 6-D closure manifold), from where a seed's
    search once ended (joint 4 at its limit, 2.09): the climb ends where scipy's L-BFGS-B (an
    independent optimiser, from its end point) gains no more than 3e-3. Before steps were solved
    again at the joint limits, this climb stopped at -11.687, 0.02 below the top (-11.667)."""
    from scipy.optimize import minimize

    from bcad.bayes.search import maximise_in_rounds

    model = BayesModel(compile_problem(load_problem(IIWA)))
    objective = model.objective
    start = np.array([1.3867517784, 0.8280547568, 2.3986217616, 2.09, 2.3284503457, 0.4138946768, -1.687496128])
    climbed = maximise_in_rounds(model.search_linear, start[None], 50, rounds=(50,))[0]

    def value(x):
        return stand_in_value(model, x)

    found = minimize(
        lambda x: -value(x),
        climbed.x,
        method="L-BFGS-B",
        bounds=list(objective.bounds),
        options={"maxiter": 400, "ftol": 1e-13, "gtol": 1e-10},
    )
    assert climbed.log_value > value(start) + 0.01
    assert -found.fun - climbed.log_value < 3e-3, (climbed.log_value, -found.fun)


def test_climbs_and_walks_on_a_peg_placement_reach_the_top_of_its_narrow_ridge():
    """problems/studies/ur5_peg_placement.yaml is scored by a peg's inequalities alone: its
    maxima lie on a ridge a few hundredths of a millimetre wide in a box of 300 mm and 2 pi, so
    the objective's curvature across it is 1e8-1e10 in the unit box and 1e2 along it. A climb
    from a point where a seed's search once stopped (-28.60) ends within 0.02 of where scipy's
    Nelder-Mead (derivative-free, an independent optimiser) climbs from the same point; with
    the finite-difference step of cells with scores (1e-5, whose second differences err by h
    times the third derivative) it gained 0.005 and stopped 0.22 below."""
    from scipy.optimize import minimize

    from bcad.bayes.search import maximise_in_rounds

    compiled = compile_problem(load_problem(REPO / "problems" / "studies" / "ur5_peg_placement.yaml"))
    model = BayesModel(compiled)
    start = solution_from_dict(
        compiled,
        {
            "ur5/base.tx": 150.0,
            "ur5/base.ty": 9.7397,
            "ur5/base.rz": -2.86472,
            "ur5/shoulder_pan_joint.rz": 0.194936,
            "ur5/shoulder_lift_joint.ry": 2.808257,
            "ur5/elbow_joint.ry": 1.890211,
            "ur5/wrist_1_joint.ry": -0.046543,
            "ur5/wrist_2_joint.rz": -1.402825,
            "ur5/wrist_3_joint.ry": 0.0,
        },
    )

    def value(x):
        return stand_in_value(model, x)

    climbed = maximise_in_rounds(model.search_linear, start[None], 60, rounds=(60,))[0]
    reference = minimize(
        lambda x: -value(x),
        start,
        method="Nelder-Mead",
        options={"maxiter": 2500, "xatol": 1e-8, "fatol": 1e-8, "adaptive": True},
    )
    assert -reference.fun > value(start) + 0.1  # the start is well below the ridge's top
    assert climbed.log_value > -reference.fun - 0.02, (value(start), climbed.log_value, -reference.fun)
    # The ridge walk from the same point (two seeds of its random moves) goes as far, on its own
    from bcad.bayes.search import LocalMaximum, walk_ridges

    for seed in (0, 1):
        (walked,) = walk_ridges(
            model.search_linear, [LocalMaximum(start, value(start), 1, 0)], np.random.default_rng(seed)
        )
        assert walked.log_value == pytest.approx(value(walked.x), abs=1e-9)
        assert walked.log_value > -reference.fun - 0.02, (seed, walked.log_value, -reference.fun)


@pytest.mark.parametrize(
    ("problem", "further"),
    [("studies/planar_2r.yaml", False), ("rx90_face_on_face.yaml", True)],
    ids=["first-climbs-replicate", "further-rounds-used"],
)
def test_the_further_climbs_give_the_same_answer_on_one_core_and_on_two(monkeypatch, forks, problem, further):
    """The further climbs' rounds run beside the first climbs in a forked child where two cores
    are there (bcad.parallel), and are stopped where the first climbs replicate the best basin
    (the planar arm) or used (the RX90s): the rounds used, and the answer, are those of one core.
    The linear estimator ends the solve at the search's best (the further rounds are the same)."""
    import bcad
    from bcad import parallel

    path = REPO / "problems" / problem
    documents = []
    for single in ("1", "0"):
        monkeypatch.setenv("BCAD_SINGLE_CORE", single)
        documents.append(bcad.solve(path, seed=3, samples=4096, estimator="linear").document)
    one, two = documents
    assert any(forks) == parallel.can_fork()
    search = one["diagnostics"]["search"]
    compiled = compile_problem(load_problem(path))
    first_starts = search_budget(compiled.problem.solver, len(compiled.parameters.x), len(compiled.parameters.l))[0]
    assert (search["starts"] > first_starts + 1) == further  # the further rounds' design joined the starts
    assert one["solution"] == two["solution"] and one["objective"] == two["objective"]
    assert search == two["diagnostics"]["search"]


def test_the_polish_gives_the_same_points_on_one_core_and_on_two(monkeypatch, forks):
    """The finalists' polish climbs each point on its own: half of them on a second core (a forked
    child) gives the same points bit for bit as one core."""
    from bcad import parallel
    from bcad.bayes.estimators import polish

    compiled = compile_problem(load_problem(REPO / "problems" / "ur5_probe_face.yaml"))
    model = BayesModel(compiled)
    x = np.array(compiled.parameters.x_nominal)
    points = x + np.random.default_rng(4).normal(0.0, 0.05, (3, len(x)))
    polished = []
    for single in ("1", "0"):
        monkeypatch.setenv("BCAD_SINGLE_CORE", single)
        polished.append(polish(model, points))
    assert any(forks) == parallel.can_fork()
    assert np.array_equal(polished[0], polished[1])
    assert not np.array_equal(polished[0], points)  # the polish moved them


def test_the_ridge_walk_goes_on_in_stages_along_a_long_ridge(tmp_path, monkeypatch):
    """The peg placement with its fixture moved to (440.31, -100.65) mm and a peg of radius 4.83 mm
    (a random cell): its ridge's top lies about 100 mm along the base's ty from where a seed's
    search once stopped (ty = 17.7 mm, 0.06 below the best seed exactly). One stage of the walk
    (WALK_STEPS steps) stops short of the top; the staged walk goes on while it gains and ends
    within 0.02 of a reference walk with twice the candidates per step and every one of 16
    stages walked (several times the default's evaluations)."""
    import yaml

    from bcad.bayes import search

    document = yaml.safe_load((REPO / "problems" / "studies" / "ur5_peg_placement.yaml").read_text())
    document["robots"][0]["urdf"] = str(REPO / "robots" / "ur5.urdf")
    document["links"][1]["pose"][:2] = [440.3083707651841, -100.64856854252665]
    document["entities"][1]["radius"] = 4.830212235033308
    problem = tmp_path / "peg.yaml"
    problem.write_text(yaml.safe_dump(document))
    compiled = compile_problem(load_problem(problem))
    model = BayesModel(compiled)
    start = solution_from_dict(
        compiled,
        {
            "ur5/base.tx": 149.999917,
            "ur5/base.ty": 17.735778,
            "ur5/base.rz": -2.42773,
            "ur5/shoulder_pan_joint.rz": 1.684917,
            "ur5/shoulder_lift_joint.ry": 0.195568,
            "ur5/elbow_joint.ry": -2.354571,
            "ur5/wrist_1_joint.ry": 0.588164,
            "ur5/wrist_2_joint.rz": -1.570817,
            "ur5/wrist_3_joint.ry": 2.691003,
        },
    )
    at_start = [LocalMaximum(start, stand_in_value(model, start), 1, 0)]
    (one_stage,) = search.walk_ridges(model.search_linear, at_start, np.random.default_rng(0), stages=1)
    (staged,) = search.walk_ridges(model.search_linear, at_start, np.random.default_rng(0))
    monkeypatch.setattr(search, "WALK_CANDIDATES", 2 * search.WALK_CANDIDATES)
    monkeypatch.setattr(search, "WALK_GAIN", -np.inf)
    (reference,) = search.walk_ridges(model.search_linear, at_start, np.random.default_rng(1), stages=16)
    assert reference.log_value > one_stage.log_value + 0.03, (one_stage.log_value, reference.log_value)
    assert staged.log_value > reference.log_value - 0.02, (staged.log_value, reference.log_value)
    assert staged.iterations > search.WALK_STEPS  # it went on past the first stage


def test_the_search_line_counts_in_singular_and_plural():
    """A search of one climb read '1 climbs from 2881 screened starts ended at 1 distinct maxima'."""
    from bcad.bayes.document import search_line

    one = {
        "climbs": 1,
        "starts": 2881,
        "basins": [{}],
        "verdict": {"method": "climbs", "agree": 0.02, "runs": 1, "reached_best": 1, "settled": True},
    }
    assert search_line(one).startswith(
        "search: 1 climb from 2881 screened starts ended at 1 distinct maximum; 1 of 1 climb reached the best value"
    )
    many = {**one, "climbs": 73, "starts": 1, "basins": [{}, {}], "verdict": {**one["verdict"], "runs": 73}}
    assert search_line(many).startswith("search: 73 climbs from 1 screened start ended at 2 distinct maxima; 1 of 73")
