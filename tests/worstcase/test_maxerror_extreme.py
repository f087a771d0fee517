"""The exact clearance error at the schema's extremes (links of 5.5e5 m, clearances of 1e-12),
checked in 60-digit arithmetic (mpmath, written here independently of bcad): ``exact.max`` is
the error its own ``argmax`` reaches, and ``exact.bound`` is above it. Computed as P^-1 P' in
doubles, the error lost 1e-5 of itself to rounding: max above bound, negative gaps."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from conftest import run_bcad

mp = pytest.importorskip("mpmath")


def _transform(rotation, translation):
    T = mp.eye(4)
    for r in range(3):
        for c in range(3):
            T[r, c] = rotation[r, c]
        T[r, 3] = translation[r]
    return T


def _rot(axis: int, angle):
    c, s = mp.cos(angle), mp.sin(angle)
    R = mp.eye(3)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    R[i, i], R[j, j], R[j, i], R[i, j] = c, c, s, -s
    return R


def _exact_error(rows, screws, kind):
    """|t| or the rotation angle of P^-1 prod_j exp(ds_j) S_j, in 60 digits (Eq. 10-11)."""
    chain = [
        _transform(_rot(2, mp.mpf(r["theta"])), [0, 0, 0])
        * _transform(mp.eye(3), [mp.mpf(r["a"]), 0, mp.mpf(r["d"])])
        * _transform(_rot(0, mp.mpf(r["alpha"])), [0, 0, 0])
        for r in rows
    ]
    nominal, moved = mp.eye(4), mp.eye(4)
    for S, screw in zip(chain, screws):
        w, v = [mp.mpf(x) for x in screw[:3]], [mp.mpf(x) for x in screw[3:]]
        twist = mp.matrix([[0, -w[2], w[1], v[0]], [w[2], 0, -w[0], v[1]], [-w[1], w[0], 0, v[2]], [0, 0, 0, 0]])
        nominal, moved = nominal * S, moved * mp.expm(twist) * S
    R = nominal[:3, :3].T
    inverse = _transform(R, -(R * nominal[:3, 3]))
    delta = inverse * moved
    if kind == "translation":
        return mp.sqrt(delta[0, 3] ** 2 + delta[1, 3] ** 2 + delta[2, 3] ** 2)
    skew = [(delta[2, 1] - delta[1, 2]) / 2, (delta[0, 2] - delta[2, 0]) / 2, (delta[1, 0] - delta[0, 1]) / 2]
    return mp.atan2(mp.sqrt(sum(x**2 for x in skew)), (delta[0, 0] + delta[1, 1] + delta[2, 2] - 1) / 2)


@pytest.mark.parametrize("seed", [5, 6, 7])
def test_the_exact_error_at_the_schemas_extremes_is_its_argmaxs_and_below_its_bound(tmp_path, seed):
    mp.mp.dps = 60
    rng = np.random.default_rng(seed)
    rows = [
        {
            "a": float(rng.uniform(-5.5e5, 5.5e5)),
            "alpha": float(rng.uniform(-3, 3)),
            "d": float(rng.uniform(-5.5e5, 5.5e5)),
            "theta": float(rng.uniform(-3, 3)),
        }
        for _ in range(int(rng.integers(2, 5)))
    ]
    problem = tmp_path / "extreme.yaml"
    problem.write_text(
        yaml.safe_dump(
            {
                "name": "extreme",
                "chain": {"dh": rows},
                "clearance": {"rot_xy": 1e-12, "rot_z": 1e-12, "trans_xy": 1e-12, "trans_z": 1e-12},
            }
        )
    )
    run = run_bcad("maxerror", problem, "--model", "exact", "--json")
    assert run.returncode in (0, 3), run.stderr
    document = json.loads(run.stdout)
    assert not any(w["code"] == "exact_bound_below_max" for w in document["warnings"])
    for kind in ("rotation", "translation"):
        exact = document[kind]["exact"]
        true = _exact_error(rows, exact["argmax"], kind)
        assert abs(float(mp.mpf(exact["max"]) / true - 1)) < 1e-12, (kind, exact["max"], true)
        assert mp.mpf(exact["bound"]) >= true and exact["gap"] > 0, (kind, exact["bound"], true)
