"""The sharp certified bound on the exact clearance error (bcad/worstcase/exact_bound.py).

Checked against what it claims, independently: its Taylor remainder against the exact error at
random points of the clearance set; its bound against a 30-start search and 40,000 feasible
points on the examples and on random chains at 1, 10 and 100 times their clearances; and its
gap on the examples' own clearances against the 1e-6 the issue asks."""

from __future__ import annotations

import numpy as np
import pytest
from test_maxerror_exact import CHAINS, CLEARANCE, error_map_of, random_chain

from bcad.worstcase.branch_and_bound import BLOCKS, SCREW_SLOTS, certified_maximum
from bcad.worstcase.exact import ScaledVariables, error_transforms, exact_errors_batch, exact_maximum
from bcad.worstcase.exact_bound import (
    _error_vectors,
    _Geometry,
    error_vectors_and_gradients,
    exact_bound,
)
from bcad.worstcase.statistics import sample_screws

from conftest import run_bcad

KINDS = ("rotation", "translation")


def _rim(error_map, screws):
    """The screws pushed onto the boundary of every disc and interval (where maxima lie)."""
    rim = screws.copy()
    for slots, column in (((0, 1), 0), ((3, 4), 2)):
        norm = np.linalg.norm(rim[:, :, slots], axis=2, keepdims=True)
        rim[:, :, slots] *= np.where(norm > 0, error_map.clearance[None, :, [column]] / np.where(norm > 0, norm, 1), 0)
    for slot, column in ((2, 1), (5, 3)):
        rim[:, :, slot] = np.sign(rim[:, :, slot]) * error_map.clearance[None, :, column]
    return rim


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("scale", [1, 100])
def test_the_taylor_remainder_bounds_the_exact_error_between_any_two_points(kind, scale):
    """u . E(y) <= u . E(x) + grad(u . E)(x) . (y - x) + K(|y - x| per block) / 2 for random x, y in
    C and random u: the inequality every sharp bound rests on (the exact error from
    bcad.worstcase.exact's matrices, the gradient by central differences here)."""
    error_map = error_map_of(random_chain(7, 4, scale))
    geometry = _Geometry(error_map, kind)
    rng = np.random.default_rng(5)
    x = _rim(error_map, sample_screws(error_map, 300, rng))
    y = sample_screws(error_map, 300, rng)
    y[:150] = _rim(error_map, y[:150])
    u = rng.standard_normal((300, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    space = ScaledVariables(error_map, kind)
    joints, slots = space.joints, space.slots

    def ue(screws):
        return np.einsum("pc,pc->p", _error_vectors(error_transforms(error_map, screws), kind).real, u)

    h = 1e-7 * scale
    gradient = np.zeros((300, error_map.joints, 6))
    for j, slot in zip(joints, slots):
        step = np.zeros_like(x)
        step[:, j, slot] = h
        gradient[:, j, slot] = (ue(x + step) - ue(x - step)) / (2 * h)
    d = y - x
    steps = []
    for (_rows, _column, _kind), block in zip(BLOCKS[kind], SCREW_SLOTS[kind]):
        steps.append(np.linalg.norm(d[:, :, list(block)], axis=2))
    while len(steps) < 4:
        steps.append(np.zeros_like(steps[0]))
    predicted = ue(x) + np.einsum("pjs,pjs->p", gradient, d) + geometry.half_curvature(steps)
    actual = ue(y)
    slack = predicted - actual
    # the remainder's true size, for scale: the bound may not be below it (up to the
    # central differences' own error, far smaller)
    assert np.all(slack >= -1e-9 * np.abs(actual).max()), slack.min()
    # and it is a bound of the right order, not a huge constant: within 100 times the
    # largest actual second-order change
    second = np.abs(actual - ue(x) - np.einsum("pjs,pjs->p", gradient, d))
    assert np.max(geometry.half_curvature(steps)) < 100 * max(second.max(), 1e-300) + 1e-18


@pytest.mark.parametrize("kind", KINDS)
def test_the_chain_gradient_matches_central_differences_of_the_exact_error(kind):
    """E and its derivatives from one prefix and suffix sweep of the chain (what the sharp bound
    evaluates at x^) against E from bcad.worstcase.exact's matrices and its central differences."""
    error_map = error_map_of(random_chain(7, 4, 10))
    rng = np.random.default_rng(11)
    x = sample_screws(error_map, 20, rng)
    space = ScaledVariables(error_map, kind)
    joints, slots = space.joints, space.slots
    E, tangents = error_vectors_and_gradients(error_map, x, kind, joints, slots)
    assert np.allclose(E, _error_vectors(error_transforms(error_map, x), kind), rtol=0, atol=1e-15)
    h = 1e-6
    for k, (j, slot) in enumerate(zip(joints, slots)):
        step = np.zeros_like(x)
        step[:, j, slot] = h
        central = (
            _error_vectors(error_transforms(error_map, x + step), kind)
            - _error_vectors(error_transforms(error_map, x - step), kind)
        ) / (2 * h)
        assert np.allclose(tangents[:, k], central, rtol=0, atol=1e-8 * max(1.0, np.abs(central).max())), (j, slot)


# every chain of the scalar bound's test but the 20-joint ones at 10x and 100x (bench/maxerror_exact.py runs those)
SHARP_CHAINS = [(label, make) for label, make in CHAINS if label not in ("random 20 x10", "random 20 x100")]


@pytest.mark.parametrize("label, make", SHARP_CHAINS, ids=[label for label, _ in SHARP_CHAINS])
def test_the_sharp_bound_is_never_below_the_exact_error(label, make):
    """Against a 30-start search (+-x* and 28 random starts) and 40,000 feasible points, half on
    the set's boundary: the bound is never below any of them."""
    error_map = error_map_of(make())
    rng = np.random.default_rng(11)
    inside = sample_screws(error_map, 20_000, rng)
    sampled = np.maximum(
        exact_errors_batch(error_map, inside).max(axis=0),
        exact_errors_batch(error_map, _rim(error_map, sample_screws(error_map, 20_000, rng))).max(axis=0),
    )
    for index, kind in enumerate(KINDS):
        first = certified_maximum(error_map, kind, 1e-6)
        # 30 starts as the issue asks (8 at 20 joints here, to keep the suite short: bench/maxerror_exact.py runs 32)
        starts = 28 if error_map.joints <= 12 else 6
        search = exact_maximum(error_map, first.argmax, kind, starts=starts, rng=np.random.default_rng(2))
        found = search.max
        sharp = exact_bound(error_map, kind, found, search.argmax, 1e-6)
        if sharp is None:  # outside the module's range, or no better than the scalar bound
            assert not label.endswith("x1")
            continue
        assert sharp.bound >= found and sharp.bound >= sampled[index], (kind, found, sampled[index], sharp.bound)
        if label.endswith("x1"):
            assert (sharp.bound - found) / sharp.bound < 2e-6, (kind, (sharp.bound - found) / sharp.bound)


EXAMPLES = sorted(path.stem for path in CLEARANCE.glob("*.yaml") if "zhao" not in path.stem)


@pytest.mark.parametrize("name", EXAMPLES)
def test_the_examples_exact_gap_is_within_the_tolerance(name):
    """``bcad maxerror --model exact``: the bound encloses the exact error found, within 1e-6
    relative, on every example (the RX90 at the candle pose, whose base and wrist turn about
    axes through the flange, by splitting those free intervals), exit 0 with no warning."""
    import json

    result = run_bcad("maxerror", str(CLEARANCE / f"{name}.yaml"), "--model", "exact", "--json")
    document = json.loads(result.stdout)
    for kind in KINDS:
        exact = document[kind]["exact"]
        assert exact["bound"] >= exact["max"]
        assert exact["gap"] <= 1e-6, (kind, exact["gap"])
    assert document["warnings"] == [] and result.returncode == 0


def test_a_ring_of_maxima_at_20_joints_ends_in_seconds_on_the_scalar_bound(tmp_path):
    """A planar 20-joint arm's rotation maxima form a ring of directions: the sharp search would
    need some 26,000 vertices of 2,440 chain transforms each. Its work is capped (SHARP_WORK):
    the run ends with the scalar bound, certified, and says the gap is above --tol (exit 3)."""
    import json

    import yaml

    rows = [{"a": 0.1, "alpha": 0.0, "d": 0.0, "theta": 0.1 * (k + 1)} for k in range(20)]
    path = tmp_path / "planar20.yaml"
    path.write_text(
        yaml.safe_dump(
            {
                "name": "planar-20",
                "chain": {"dh": rows},
                "clearance": {"rot_xy": 1e-4, "rot_z": 5e-5, "trans_xy": 1e-5, "trans_z": 5e-6},
            }
        )
    )
    result = run_bcad("maxerror", str(path), "--model", "exact", "--json")
    assert result.returncode == 3, result.stderr
    document = json.loads(result.stdout)
    rotation = document["rotation"]["exact"]
    assert rotation["bound"] >= rotation["max"] and rotation["gap"] > 1e-6
    assert any(
        w["code"] == "exact_gap_not_reached" and "rotation" in w["message"] and "more than --tol" in w["message"]
        for w in document["warnings"]
    )
    assert document["translation"]["exact"]["bound"] >= document["translation"]["exact"]["max"]


def test_a_gap_warning_shows_the_two_figures_apart():
    """A bound 1.9e-6 above the largest error found (a planar 2R in mm at 0.5 deg clearances):
    printed with the digits that tell them apart, where six digits showed 4.60383 twice."""
    from bcad.worstcase.run import exact_gap_message

    message = exact_gap_message("translation", 4.60383409, 4.60382541, "--tol", 1e-6)
    assert "bound 4.60383409 exceeds the largest exact error found, 4.60382541, by 1.89e-06 of the bound" in message
    assert "0.5 exceeds the largest exact error found, 0.25, by 0.5 " in exact_gap_message(
        "rotation", 0.5, 0.25, "--tol", 1e-6
    )
