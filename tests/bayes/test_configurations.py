"""One cell at several configurations: the robot's errors shared, each configuration's joints its own."""

from __future__ import annotations

import json
import math

import numpy as np
import pinocchio as pin
import pytest
import yaml

import bcad
from bcad.compiler import compile_problem
from bcad.kinematics import Samples
from bcad.model import load_problem

from conftest import REPO, document_made_once, run_bcad

DESIGN = REPO / "problems" / "studies" / "ur5_workcell_design.yaml"
UR5_URDF = REPO / "robots" / "ur5.urdf"
JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]
POINTS = np.array([[500.0, 0.0, 100.0], [700.0, 150.0, 50.0], [700.0, -150.0, 50.0]])  # p1..p3 on the table
#: log of the base placement's uniform prior's density: 600 mm x 600 mm x 2 * 3.14159 rad
BASE_LOG_PRIOR = -math.log(600 * 600 * 2 * 3.14159)


def design_source() -> dict:
    source = yaml.safe_load(DESIGN.read_text())
    source["robots"][0]["urdf"] = str(UR5_URDF)
    return source


@pytest.fixture(scope="module")
def solved(tmp_path_factory) -> dict:
    return document_made_once(
        tmp_path_factory, "ur5-workcell-seed-0", lambda: bcad.solve(design_source(), seed=0).document
    )


def test_the_graph_has_one_copy_of_the_arm_per_configuration_and_one_set_of_errors():
    compiled = compile_problem(load_problem(DESIGN))
    stats = compiled.stats
    assert (stats.cycles, stats.optimization_dim, stats.integration_dim) == (3, 21, 6)
    table = compiled.parameters
    # The base placement once, six joint angles per configuration, the six zero errors once.
    assert table.x_names[:3] == ["base_placement.tx", "base_placement.ty", "base_placement.rz"]
    assert table.x_names[3] == "ur5/shoulder_pan_joint@c1.rz" and table.x_names[-1] == "ur5/wrist_3_joint@c3.ry"
    assert table.l_names == [
        f"ur5/{joint}/zero.{axis}" for joint, axis in zip(JOINTS, ["rz", "ry", "ry", "ry", "rz", "ry"])
    ]
    assert [compiled.graph.links[k].name for k in compiled.graph.closing_links] == ["reach_p1", "reach_p2", "reach_p3"]
    assert [c.links for c in compiled.configurations] == [("reach_p1",), ("reach_p2",), ("reach_p3",)]
    assert "ur5/tool0" not in compiled.graph.frames and "ur5/tool0@c2" in compiled.graph.frames
    assert "ur5/world" in compiled.graph.frames  # the base is not downstream of any joint: one copy


def test_every_configuration_draws_the_same_errors_and_matches_pinocchio():
    """At equal joint values the three flanges coincide for every draw of L (the errors are one
    set), and each is Pinocchio's forward kinematics at q + the zero errors."""
    compiled = compile_problem(load_problem(DESIGN))
    rng = np.random.default_rng(5)
    q = rng.uniform(-2.0, 2.0, 6)
    base = np.array([120.0, -40.0, 0.3])
    x = np.concatenate([base, q, q, q])
    zeros = rng.normal(0.0, 0.01, size=(64, 6))
    frames = compiled.frame_transforms(x, Samples(zeros), ["ur5/tool0@c1", "ur5/tool0@c2", "ur5/tool0@c3"])
    c1 = frames["ur5/tool0@c1"].matrices()
    np.testing.assert_allclose(frames["ur5/tool0@c2"].matrices(), c1, atol=1e-9)
    np.testing.assert_allclose(frames["ur5/tool0@c3"].matrices(), c1, atol=1e-9)
    model = pin.buildModelFromUrdf(str(UR5_URDF))
    data = model.createData()
    tool = model.getFrameId("tool0")
    c, s = math.cos(base[2]), math.sin(base[2])
    placement = np.array([[c, -s, 0, base[0]], [s, c, 0, base[1]], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    for n in range(len(zeros)):
        pin.framesForwardKinematics(model, data, q + zeros[n])
        expected = data.oMf[tool].homogeneous.copy()
        expected[:3, 3] *= 1000.0  # the problem is in mm
        np.testing.assert_allclose(c1[n], placement @ expected, atol=1e-8)


def independent_log_value(document: dict, samples: int, shared: bool, seed: int = 1) -> tuple[float, float]:
    """log p(X) I(X) at the document's solution by plain Monte Carlo with Pinocchio: the zero
    errors drawn once per sample and shared by the three configurations (or, ``shared=False``,
    drawn for each, as three independent robot copies would)."""
    model = pin.buildModelFromUrdf(str(UR5_URDF))
    data = model.createData()
    tool = model.getFrameId("tool0")
    solution = document["solution"]
    tx, ty, rz = (solution[f"base_placement.{p}"] for p in ("tx", "ty", "rz"))
    R = np.array([[math.cos(rz), -math.sin(rz), 0], [math.sin(rz), math.cos(rz), 0], [0, 0, 1]])
    rng = np.random.default_rng(seed)
    zeros = rng.normal(0.0, 0.001, (samples, 6))
    log_scores = np.zeros(samples)
    for name, point in zip(("c1", "c2", "c3"), POINTS):
        q = np.array([document["configurations"][name]["joints"][f"ur5/{joint}"] for joint in JOINTS])
        errors = zeros if shared else rng.normal(0.0, 0.001, (samples, 6))
        flange = np.empty((samples, 3))
        for n in range(samples):
            pin.framesForwardKinematics(model, data, q + errors[n])
            flange[n] = data.oMf[tool].translation * 1000.0
        miss = flange @ R.T + [tx, ty, 0.0] - point
        log_scores += -0.5 * np.sum(miss**2, axis=1) / 0.25 - 1.5 * math.log(2 * math.pi * 0.25)
    top = log_scores.max()
    weights = np.exp(log_scores - top)
    log_i = top + math.log(weights.mean())
    se = weights.std() / weights.mean() / math.sqrt(samples)
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    log_prior = BASE_LOG_PRIOR - 3 * float(np.sum(np.log(upper - lower)))
    return log_prior + log_i, se


def test_the_objective_shares_the_errors_as_an_independent_monte_carlo_does(solved):
    value, se = independent_log_value(solved, 40_000, shared=True)
    bcad_value = solved["objective"]["log_value"]
    bcad_se = solved["objective"]["log_value_se"]
    assert abs(bcad_value - value) < 3 * math.hypot(se, bcad_se)
    # Three independent copies of the arm (the old way) give another, lower value: the test can tell.
    copies, copies_se = independent_log_value(solved, 40_000, shared=False)
    assert bcad_value - copies > 10 * math.hypot(copies_se, bcad_se)


def test_each_configuration_reports_its_joints_and_closes_on_its_point(solved):
    configurations = solved["configurations"]
    assert list(configurations) == ["c1", "c2", "c3"]
    for k, name in enumerate(("c1", "c2", "c3")):
        entry = configurations[name]
        assert entry["closing_links"] == [f"reach_p{k + 1}"]
        assert sorted(entry["joints"]) == sorted(f"ur5/{joint}" for joint in JOINTS)
        for joint, value in entry["joints"].items():
            axis = "rz" if joint.endswith(("pan_joint", "wrist_2_joint")) else "ry"
            assert value == pytest.approx(solved["solution"][f"{joint}@{name}.{axis}"])
        # The flange reaches its point: the closing link's mean miss is well inside its 0.5 mm score.
        mean = solved["posterior"]["links"][f"reach_p{k + 1}"]["weighted"]["mean"][:3]
        assert max(abs(v) for v in mean) < 0.05


def test_the_design_is_at_least_as_good_as_a_fixed_base_placement(solved):
    """A design over a larger set cannot be worse: the same cell with the base held at a
    placement (each solved as its own problem) is not better, less the base prior's density,
    beyond the search's tolerance of 0.02 in log value."""
    for placement in ([300.0, 0.0, 0.0], [150.0, 100.0, 1.57]):
        source = design_source()
        base = source["links"][0]
        base.update(status="FFFFFF", pose=[placement[0], placement[1], 0, 0, 0, placement[2]])
        del base["bounds"]
        fixed = bcad.solve(source, seed=0).document["objective"]["log_value"] + BASE_LOG_PRIOR
        assert solved["objective"]["log_value"] > fixed - 0.02, placement


def test_a_configuration_sets_its_own_joint_status_and_value(write_problem, tmp_path):
    source = design_source()
    source["configurations"][0]["joints"] = {"ur5": {"wrist_3_joint": {"status": "F", "value": 0.5}}}
    compiled = compile_problem(bcad.load(source))
    assert "ur5/wrist_3_joint@c1.ry" not in compiled.parameters.x_names
    assert compiled.stats.optimization_dim == 20
    from bcad.bayes.document import configurations_to_dict

    x = np.array(compiled.parameters.x_nominal)
    assert configurations_to_dict(compiled, x)["c1"]["joints"]["ur5/wrist_3_joint"] == pytest.approx(0.5)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda s: s["configurations"][0].update(joints={"ur6": {}}), "unknown robot 'ur6' (did you mean 'ur5'?)"),
        (lambda s: s["configurations"][0].update(joints={"ur5": {"elbow": {"status": "X"}}}), "unknown joint 'elbow'"),
        (
            lambda s: s["configurations"][1].update(relations=["reach_p1"]),
            "'reach_p1' is listed by configuration 'c1' already",
        ),
        (lambda s: s["configurations"][1].update(relations=["reach_p9"]), "unknown link or relation 'reach_p9'"),
        (lambda s: s["configurations"][1].update(name="c1"), "duplicate configuration name 'c1'"),
        (lambda s: s["configurations"][1].update(name="c 2"), "should match pattern"),
        (
            lambda s: s["configurations"][0]["joints"]["ur5"].update(default={"status": "X", "bounds": [1, 1]}),
            "need low < high",
        ),
    ],
)
def test_a_bad_configuration_is_refused_with_its_line(tmp_path, mutate, message):
    source = design_source()
    mutate(source)
    path = tmp_path / "cell.yaml"
    path.write_text(yaml.safe_dump(source, sort_keys=False))
    result = run_bcad("validate", path)
    assert result.returncode == 2, result.stderr
    assert message in result.stderr and "cell.yaml:" in result.stderr
    assert "Traceback" not in result.stderr


def test_calibrate_refuses_configurations(tmp_path):
    source = yaml.safe_load((REPO / "problems" / "calibration" / "ur5_tracker.yaml").read_text())
    source["measurements"][0]["data"] = str(REPO / "problems" / "calibration" / "ur5_tracker.csv")
    source["configurations"] = [{"name": "a", "joints": {"ur5": {}}}]
    path = tmp_path / "cal.yaml"
    path.write_text(yaml.safe_dump(source, sort_keys=False))
    result = run_bcad("calibrate", path)
    assert result.returncode == 2 and "remove configurations:" in result.stderr, result.stderr


def test_solve_prints_the_configurations_table(tmp_path):
    out = tmp_path / "design.json"
    source = design_source()
    source["solver"] = {"search_climbs": 8, "search_starts": 64}
    path = tmp_path / "design.yaml"
    path.write_text(yaml.safe_dump(source, sort_keys=False))
    result = run_bcad("solve", path, "-o", out)
    assert result.returncode == 0, result.stderr
    assert "joint values per configuration" in result.stdout and "reach_p3" in result.stdout
    assert json.loads(out.read_text())["configurations"]["c2"]["closing_links"] == ["reach_p2"]


def test_arms_on_one_base_are_searched_arm_by_arm_like_configurations():
    """Without configurations, X that enter one cycle only form that cycle's block (three arms on
    one base, each reaching its own point: each arm's six joints), while the base's X, in every
    cycle, are held when a block is redrawn. A cell whose X all share one cycle (the RX90's two
    arms closing one face on face) has no blocks."""
    from bcad.bayes.configurations import configuration_blocks

    placement = compile_problem(load_problem(REPO / "problems" / "studies" / "ur5_base_placement.yaml"))
    blocks = configuration_blocks(placement)
    names = [p.name for p in placement.parameters.x]
    assert [sorted(names[k].split("/")[0] for k in np.flatnonzero(mask)) for mask in blocks] == [
        ["a"] * 6,
        ["b"] * 6,
        ["c"] * 6,
    ]
    shared = ~np.any(blocks, axis=0)
    assert sorted(names[k] for k in np.flatnonzero(shared)) == [
        "base_placement.rz",
        "base_placement.tx",
        "base_placement.ty",
    ]
    assert configuration_blocks(compile_problem(load_problem(REPO / "problems" / "rx90_face_on_face.yaml"))) == []


def _planar_cell(count: int) -> dict:
    """A 2-joint DH arm touching ``count`` points round it, one configuration each."""
    rows = [{"a": 300.0, "alpha": 0.0, "d": 0.0, "theta": 0.0}, {"a": 250.0, "alpha": 0.0, "d": 0.0, "theta": 0.0}]
    entities = [{"name": "tip", "type": "point", "frame": "probe", "at": [0, 0, 0]}]
    relations, configurations = [], []
    for k in range(count):
        angle = 2 * math.pi * k / count
        entities.append(
            {
                "name": f"p{k}",
                "type": "point",
                "frame": "table",
                "at": [400 * math.cos(angle), 400 * math.sin(angle), 0.0],
            }
        )
        relations.append(
            {
                "name": f"r{k}",
                "type": "point_on_point",
                "parent": f"p{k}",
                "child": "tip",
                "status": "LLFFFF",
                "distributions": {"tx": "normal(0, 0.1)", "ty": "normal(0, 0.1)"},
            }
        )
        configurations.append({"name": f"c{k}", "joints": {"arm": {}}, "relations": [f"r{k}"]})
    return {
        "name": "ring",
        "units": {"length": "mm", "angle": "rad"},
        "frames": ["table", "probe"],
        "robots": [
            {
                "name": "arm",
                "dh": rows,
                "parent": "table",
                "joints": {"default": {"status": "X", "zero": "normal(0, 0.001)"}},
            }
        ],
        "links": [{"name": "mount", "parent": "arm/link_2", "child": "probe", "pose": [0, 0, 0, 0, 0, 0]}],
        "entities": entities,
        "relations": relations,
        "configurations": configurations,
    }


def test_configurations_are_bounded_by_what_the_search_finishes_within_a_minute(tmp_path):
    """17 configurations: the schema's limit; a 6-joint arm at 16 (96 X x 16 cycles): past the
    search's X x cycles bound, refused before any search; 2 joints at 16 (32 x 16) pass."""
    path = tmp_path / "ring.yaml"
    path.write_text(yaml.safe_dump(_planar_cell(17)))
    run = run_bcad("validate", path)
    assert run.returncode == 2 and "configurations" in run.stderr and "at most 16" in run.stderr, run.stderr
    from bcad.bayes.solvable import check_solvable

    cell = _planar_cell(16)
    check_solvable(compile_problem(bcad.load(cell)))
    cell["robots"][0]["dh"] = cell["robots"][0]["dh"] * 3
    cell["links"][0]["parent"] = "arm/link_6"
    with pytest.raises(bcad.InputError, match=r"96 X in 16 cycles; the search takes X x cycles <= 512"):
        check_solvable(compile_problem(bcad.load(cell)))


def test_a_pydantic_union_member_is_never_named_in_a_message(tmp_path):
    path = tmp_path / "chain.yaml"
    text = (REPO / "problems" / "clearance" / "3r.yaml").read_text().replace("rot_xy: 2.0e-4", "rot_xy: 1.0e-13")
    path.write_text(text)
    run = run_bcad("maxerror", path)
    assert run.returncode == 2 and "clearance: rot_xy = 1e-13: a clearance is 0 or at least 1e-12" in run.stderr, (
        run.stderr
    )
    assert "function-after" not in run.stderr


@pytest.mark.parametrize(
    "gains, rounds",
    [
        ([0.0] * 9, 2),  # nothing gained: the two rounds every lineage takes
        ([0.5, 0.3, 0.1, 0.005, 1.0], 4),  # on while a round gains more than AGREE
        ([0.5, 0.3, 0.02, 1.0], 3),  # a gain of AGREE exactly is not more
        ([1.0] * 9, 5),  # MAX_BRANCH_ROUNDS (5) at most
    ],
)
def test_a_lineage_of_the_branch_search_goes_on_while_its_rounds_gain(monkeypatch, gains, rounds):
    """A lineage's full climbs can move the shared X (a base placement) where the blocks' branches
    were not searched: it takes more rounds while the last one gained more than AGREE, each round
    on its own random stream, the blocks' branches pooled across its rounds."""
    from types import SimpleNamespace

    from bcad.bayes import estimators
    from bcad.bayes.search import LocalMaximum

    assert estimators.BRANCH_ROUNDS == 2 and estimators.MAX_BRANCH_ROUNDS == 5 and estimators.AGREE == 0.02
    schedule, anchors, draws, pools = iter(gains), [], [], []

    def combinations(model, closure, anchor, rng, iterations, pool, effort, alone):
        assert alone == ["alone"]  # the lineage's branches on each configuration alone, every round
        anchors.append(float(anchor[0, 0]))
        draws.append(float(rng.random()))
        pools.append(pool)
        # a start whose value (its first X) is the anchor's plus the next gain, exact in binary
        return np.array([[anchors[-1] + next(schedule), 0.0]])

    def climbs(linear, starts, iterations):
        return [LocalMaximum(start, float(start[0]), k, 1) for k, start in enumerate(starts)]

    monkeypatch.setattr(estimators, "branch_combinations", combinations)
    monkeypatch.setattr(estimators, "alone_branches", lambda *args: ["alone"])
    monkeypatch.setattr(estimators, "maximise_in_rounds", climbs)
    model = SimpleNamespace(closure=None, search_linear=None)
    origin = LocalMaximum(np.zeros(2), 0.0, 0, 1)
    settings = SimpleNamespace(search_iterations=10, search_effort=1.0)
    best, done = estimators.branch_lineage(model, settings, 0, 0, origin)
    assert len(done) == len(anchors) == rounds
    assert best.log_value == pytest.approx(sum(gains[:rounds]))
    # each round starts from the best point so far, on a stream of its own, with the lineage's pool
    assert anchors == pytest.approx(np.cumsum([0.0, *gains[: rounds - 1]]))
    assert len(set(draws)) == rounds
    assert all(pool is pools[0] for pool in pools)


def test_the_lineages_give_the_same_answer_on_one_core_and_on_two(monkeypatch, forks):
    """The branch search's next lineage runs ahead in a forked child where two cores are there
    (bcad.parallel); each lineage has its own streams, so the answer is the one-core answer."""
    from bcad import parallel

    cell = _planar_cell(3)
    cell["solver"] = {"finalist_samples": 4096}
    answers = []
    for single in ("1", "0"):
        monkeypatch.setenv("BCAD_SINGLE_CORE", single)
        result = bcad.solve(cell, seed=2, samples=4096)
        answers.append(result.document)
    one, two = answers
    assert any(forks) == parallel.can_fork()  # the second run's lineages ran ahead in children
    assert one["diagnostics"]["search"]["verdict"]["method"] == "lineages"
    assert one["diagnostics"]["search"]["verdict"]["runs"] >= 2
    assert one["solution"] == two["solution"]
    assert one["objective"] == two["objective"]
    assert one["diagnostics"]["search"]["verdict"] == two["diagnostics"]["search"]["verdict"]


def test_the_nominal_takes_each_configuration_from_the_restart_that_closes_it_best():
    """Each configuration's own joints enter its cycles alone, so the nominal least squares is a
    sum of one term per configuration: the point assembled from each block's best restart is the
    best of every combination of the restarts' blocks (checked against all 4^3 of them), and a
    cell whose restarts rarely close every configuration at once is closed. A point out of
    the arm's reach leaves its configuration open: the others are closed, the nominal is no
    further from closing than scipy's fallback from the best restart alone, and a block redrawn
    with the others held leaves them where they were."""
    import itertools

    from bcad.bayes.model import BayesModel
    from bcad.bayes.nominal import RESTARTS, blockwise_best, separable_blocks, solve_nominal
    from bcad.numerics.seeding import stream

    model = BayesModel(compile_problem(bcad.load(_planar_cell(3))))
    blocks = separable_blocks(model)
    assert blocks is not None and blocks.masks.shape[0] == 3
    assert np.array_equal(blocks.cycles, np.eye(3, dtype=bool))  # each configuration's point, its own cycle
    closure = model.closure
    points = np.random.default_rng(5).uniform(closure.low, closure.high, size=(4, len(closure.low)))
    assembled = blockwise_best(closure, points, blocks)
    cost = np.sum(closure.residuals(assembled) ** 2)
    combined = []
    for choice in itertools.product(range(4), repeat=3):
        x = np.zeros(len(closure.low))
        for mask, row in zip(blocks.masks, choice):
            x[mask] = points[row, mask]
        combined.append(np.sum(closure.residuals(x) ** 2))
    assert cost == pytest.approx(min(combined), rel=1e-12)
    assert cost < np.min(np.sum(closure.residuals_of(points) ** 2, axis=1))
    placement = compile_problem(load_problem(REPO / "problems" / "studies" / "ur5_base_placement.yaml"))
    assert separable_blocks(BayesModel(placement)) is None  # the base's X are in every cycle
    # twelve points round the arm: a random restart closes one with probability p, all twelve p^12
    model = BayesModel(compile_problem(bcad.load(_planar_cell(12))))
    for seed in range(3):
        assert solve_nominal(model, stream(seed, "nominal")).closed
    # one point beyond the arm's reach (550 mm)
    cell = _planar_cell(6)
    cell["entities"][1]["at"] = [700.0, 0.0, 0.0]
    model = BayesModel(compile_problem(bcad.load(cell)))
    closure = model.closure
    blocks = separable_blocks(model)
    held = closure.low + 0.3 * (closure.high - closure.low)
    rows = np.repeat(held[None], 8, axis=0)
    mask = blocks.masks[2]
    rows[:, mask] = np.random.default_rng(1).uniform(closure.low[mask], closure.high[mask], (8, int(mask.sum())))
    found, _ = closure.close_many(rows, 50, fixed=~mask)
    assert np.array_equal(found[:, ~mask], rows[:, ~mask])
    nominal = solve_nominal(model, stream(0, "nominal"))
    terms = blocks.terms(closure, nominal.x[None])[0]
    assert not nominal.closed and terms[0] > 1.0 and np.all(terms[1:] < 1e-8), terms
    assert nominal.starts > 1 + RESTARTS
    rng = stream(0, "nominal")
    start = np.clip(np.array(model.compiled.parameters.x_nominal, dtype=float), closure.low, closure.high)
    restarts, costs = closure.close_many(rng.uniform(closure.low, closure.high, (RESTARTS, len(start))), 200)
    alone = closure.close(restarts[int(np.argmin(costs))])[1]
    assert nominal.cost <= alone


def test_search_effort_multiplies_each_configurations_branch_search(monkeypatch):
    """The setting that trades time for coverage reaches the branch search: each block's climbs and
    redraws are the default's times search_effort, and the answer is the same on a cell whose
    branches (elbow up or down at each of three points) every budget finds."""
    import bcad.bayes.branches as branches

    budgets = []
    default_budget = branches.block_budget

    def recorded(model, mask, effort=1.0):
        budgets.append((effort, default_budget(model, mask, effort), default_budget(model, mask)))
        return budgets[-1][1]

    monkeypatch.setattr(branches, "block_budget", recorded)
    values, climbs_made, starts_screened = {}, {}, {}
    for effort in (0.5, 2.0):
        cell = _planar_cell(3)
        cell["solver"] = {"search_effort": effort, "estimator": "linear"}
        document = bcad.solve(bcad.load(cell), seed=0).document
        values[effort] = document["objective"]["log_value"]
        climbs_made[effort] = document["diagnostics"]["search"]["climbs"]
        starts_screened[effort] = document["diagnostics"]["search"]["starts"]
    assert {effort for effort, _, _ in budgets} == {0.5, 2.0}  # each block's search was given the effort
    for effort, (draws, climbs), (_, default_climbs) in budgets:
        assert climbs == max(2, math.floor(effort * default_climbs + 0.5))
        assert draws == branches.STARTS_PER_CLIMB * climbs
    # the whole-X climbs and the combinations climbed in full grow with it, the screened design too
    assert climbs_made[2.0] > 2 * climbs_made[0.5] and starts_screened[2.0] > 3 * starts_screened[0.5]
    assert abs(values[0.5] - values[2.0]) < 1e-6


def _planar_tip(joints: np.ndarray) -> np.ndarray:
    """The 2-joint arm's tip (mm) for joint values (..., 2), by its closed form."""
    first, both = joints[..., 0], joints[..., 0] + joints[..., 1]
    return np.stack([300.0 * np.cos(first) + 250.0 * np.cos(both), 300.0 * np.sin(first) + 250.0 * np.sin(both)], -1)


def test_each_configuration_alone_keeps_its_relations_and_every_error():
    from bcad.bayes.alone import configuration_alone
    from bcad.bayes.configurations import configuration_blocks

    compiled = compile_problem(bcad.load(_planar_cell(3)))
    names = [p.name for p in compiled.parameters.x]
    cells = configuration_alone(compiled)
    assert len(cells) == len(configuration_blocks(compiled)) == 3
    for k, ((alone, columns), mask) in enumerate(zip(cells, configuration_blocks(compiled))):
        assert [c.name for c in alone.configurations] == [f"c{k}"]
        assert [r.name for r in alone.problem.relations] == [f"r{k}"]
        assert len(alone.graph.cycles) == 1
        assert alone.parameters.l_names == compiled.parameters.l_names  # one robot's errors, all of them
        assert [names[c] for c in columns] == [p.name for p in alone.parameters.x]
        assert sorted(columns) == sorted(np.flatnonzero(mask))


def test_alone_branches_are_each_configurations_other_elbow():
    """A 2-joint arm reaching a point has two branches, elbow up and down: searched on its own point
    alone, each configuration's branches include the one the anchor does not take, and each reaches
    its point (the arm's closed form, not bcad's chain)."""
    from bcad.bayes.branches import alone_branches
    from bcad.bayes.configurations import configuration_blocks
    from bcad.bayes.model import BayesModel
    from bcad.bayes.nominal import solve_nominal
    from bcad.numerics.seeding import stream

    model = BayesModel(compile_problem(bcad.load(_planar_cell(3))))
    anchor = solve_nominal(model, stream(0, "nominal")).x
    found = alone_branches(model, anchor, np.random.default_rng(1), 40)
    for k, (mask, branches) in enumerate(zip(configuration_blocks(model.compiled), found)):
        point = 400.0 * np.array([math.cos(2 * math.pi * k / 3), math.sin(2 * math.pi * k / 3)])
        assert len(branches) >= 1
        np.testing.assert_allclose(_planar_tip(branches), np.broadcast_to(point, (len(branches), 2)), atol=1e-2)
        elbow = np.sign(np.sin(anchor[mask][1]))
        assert any(np.sign(np.sin(branch[1])) == -elbow for branch in branches)


def test_a_configuration_alone_where_relations_are_listed_as_links_or_joints_differ():
    """A configuration may list its relations under ``links:``: each cell alone still keeps its own
    relation only. Where configurations name different joints, the full cell replicates every joint
    any of them names and a cell alone only its own: its X are not the full cell's, and it has no
    cell alone (the branch search ranks its branches beside the others' only), without an error."""
    from bcad.bayes.alone import configuration_alone

    cell = _planar_cell(3)
    for configuration in cell["configurations"]:
        configuration["links"], configuration["relations"] = configuration["relations"], []
    cells = configuration_alone(compile_problem(bcad.load(cell)))
    assert [[r.name for r in alone.problem.relations] for alone, _ in cells] == [["r0"], ["r1"], ["r2"]]

    cell = _planar_cell(3)
    cell["configurations"][0]["joints"] = {"arm": {"joint_2": {}}}
    compiled = compile_problem(bcad.load(cell))
    cells = configuration_alone(compiled)
    assert len(cells) == 3 and cells[0] is None
    names = [p.name for p in compiled.parameters.x]
    for found in cells[1:]:
        if found is not None:
            alone, columns = found
            assert [names[c] for c in columns] == [p.name for p in alone.parameters.x]


def test_a_configuration_whose_blocks_find_no_other_branch_is_solved(tmp_path):
    """A UR5 touching one face at two configurations, the first naming no joints: where a
    configuration's search on its cell alone found no branch beyond its anchor's, the combinations
    were scored on an empty batch of points (exit 1, "cannot reshape array of size 0"). It solves,
    and the stand-in of no points is no points."""
    from bcad.bayes.model import BayesModel

    path = tmp_path / "touch.yaml"
    path.write_text(
        f"""
name: two-touches
frames: [w, tool, part]
robots:
  - {{name: r, parent: w, urdf: {REPO / "robots" / "ur5.urdf"}}}
links:
  - {{name: tool_mount, parent: r/tool0, child: tool}}
  - {{name: part_place, parent: w, child: part}}
entities:
  - {{name: top, type: face, frame: part, size: [0.2, 0.1]}}
  - {{name: tip, type: point, frame: tool}}
relations:
  - {{name: touch, type: point_on_face, parent: top, child: tip, status: FFLFFF, distributions: {{tz: 'normal(0, 0.001)'}}}}
configurations:
  - {{name: c0}}
  - {{name: c1, joints: {{r: {{}}}}}}
"""
    )
    model = BayesModel(compile_problem(load_problem(path)))
    value, se, whitened = model.search_linear.log_integral_parts(np.empty((0, model.objective.dimension)))
    assert value.shape == se.shape == (0,) and whitened.shape == (0, 2)  # touch@c0, touch@c1
    run = run_bcad("solve", path, "--samples", "2000", "--quiet")
    assert run.returncode in (0, 3) and "internal error" not in run.stderr, run.stderr
    document = json.loads(run.stdout)
    assert np.isfinite(document["objective"]["log_value"])
