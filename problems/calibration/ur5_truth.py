"""The "true" UR5 of the calibration example and its tracker data.

The truth is the UR5's nominal classic DH table (Universal Robots' published
values, in mm) plus the factory calibration deltas that a UR5's controller
reported (``calibration.conf``, published at
https://github.com/ros-industrial/universal_robot/issues/357:
delta_theta, delta_a, delta_d, delta_alpha, in m and rad). The d deltas are
hundreds of metres and cancel: axes 2, 3 and 4 are nearly parallel, and DH
puts the common normal of two nearly parallel axes far away. The forward
kinematics here are the plain DH product, written independently of bcad.

    python problems/calibration/ur5_truth.py   # rewrites ur5_tracker.csv (seed 357)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

NOMINAL = {  # mm and rad: a, alpha, d, theta per row
    "a": [0.0, -425.0, -392.25, 0.0, 0.0, 0.0],
    "alpha": [np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0],
    "d": [89.159, 0.0, 0.0, 109.15, 94.65, 82.3],
    "theta": [0.0] * 6,
}
CONTROLLER_DELTAS = {  # m and rad, as the controller wrote them
    "theta": [
        2.07750978653505926e-05,
        0.96821571555565844,
        -1.85685385014877657,
        0.888647901450376643,
        5.66106814887767484e-05,
        -7.46310764096455082e-05,
    ],
    "a": [
        0.000393621049984383038,
        0.184093300397451837,
        0.14493953300732923,
        -6.43297403642304399e-05,
        7.76709040084077299e-06,
        0.0,
    ],
    "d": [
        4.00263097760228392e-05,
        278.244144925623573,
        -183.695513914913732,
        -94.5471513669751289,
        0.000304782681775556119,
        0.000123737941387466743,
    ],
    "alpha": [
        -0.000271624944216508624,
        0.00125856505456124258,
        -0.00322052070697146503,
        0.00065153016530383745,
        -0.00058700465721117645,
        0.0,
    ],
}
TRUE = {
    key: np.array(NOMINAL[key]) + np.array(CONTROLLER_DELTAS[key]) * (1000.0 if key in ("a", "d") else 1.0)
    for key in NOMINAL
}
#: where the robot's base stands in the tracker's frame (tx, ty, tz in mm, rx, ry, rz), nominal and true
BASE_NOMINAL = np.array([2000.0, -500.0, -800.0, 0.0, 0.0, 2.5])
BASE_TRUE = BASE_NOMINAL + np.array([1.2, -0.8, 2.0, 0.002, -0.001, 0.003])
#: the tracker's reflector on the flange (link_6), nominal and true, mm
SMR_NOMINAL = np.array([20.0, 40.0, 120.0])
SMR_TRUE = SMR_NOMINAL + np.array([0.3, -0.2, 0.5])
NOISE = 0.05  # mm
JOINTS = [f"ur5/joint_{k}" for k in range(1, 7)]


def _rz(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _rx(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def _ry(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def _translation(x, y, z):
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def flange(q: np.ndarray, dh: dict = TRUE) -> np.ndarray:
    """link_6 in the base frame: prod_i Rz(theta_i + q_i) Tz(d_i) Tx(a_i) Ry(beta_i) Rx(alpha_i)
    (beta: Hayati's tilt, 0 unless ``dh`` has it)."""
    T = np.eye(4)
    beta = dh.get("beta", np.zeros(6))
    for i in range(6):
        T = (
            T
            @ _rz(dh["theta"][i] + q[i])
            @ _translation(0, 0, dh["d"][i])
            @ _translation(dh["a"][i], 0, 0)
            @ _ry(beta[i])
            @ _rx(dh["alpha"][i])
        )
    return T


def reflector_in_tracker(
    q: np.ndarray, dh: dict = TRUE, base: np.ndarray = BASE_TRUE, smr: np.ndarray = SMR_TRUE
) -> np.ndarray:
    """The reflector's position in the tracker frame, mm (default: the true robot's)."""
    tx, ty, tz, rx, ry, rz = base
    placement = _translation(tx, ty, tz) @ _rz(rz) @ _ry(ry) @ _rx(rx)
    return (placement @ flange(q, dh) @ np.append(smr, 1.0))[:3]


def configurations(rng: np.random.Generator, count: int) -> np.ndarray:
    """Joint angles spread over the workspace, away from the wrist singularity (|q5| > 0.3)."""
    q = rng.uniform(-np.pi, np.pi, size=(count, 6))
    q[:, 1] = rng.uniform(-2.6, -0.5, size=count)
    q[:, 2] = rng.uniform(-2.4, 2.4, size=count)
    q[:, 4] = np.where(rng.uniform(size=count) < 0.5, 1, -1) * rng.uniform(0.3, 2.8, size=count)
    return q


def write_csv(path: Path, count: int = 30, seed: int = 357) -> None:
    rng = np.random.default_rng(seed)
    q = configurations(rng, count)
    measured = np.array([reflector_in_tracker(row) for row in q]) + rng.normal(0.0, NOISE, (count, 3))
    lines = [",".join(JOINTS + ["tx", "ty", "tz"])]
    lines += [",".join(f"{v:.10f}" for v in [*q[r], *measured[r]]) for r in range(count)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


if __name__ == "__main__":
    write_csv(Path(__file__).with_name("ur5_tracker.csv"))
