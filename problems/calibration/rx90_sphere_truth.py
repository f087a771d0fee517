"""The "true" cell of the sphere-touch calibration example and its data.

An RX90 with a 120 mm probe touches a 25.4 mm calibration sphere at 40
configurations. The truth: joint zero offsets, the probe's true length and
lateral offset, and the sphere's true centre, below. Each touch is found by
inverse kinematics on Pinocchio's model of robots/rx90.urdf (independent of
bcad): a random point of the sphere's upper half, approached with a random
tilt of the probe. A touch reads 0 mm from the surface, plus N(0, 0.01 mm).

    python problems/calibration/rx90_sphere_truth.py   # rewrites rx90_sphere_touches.csv (seed 11)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
ZEROS = np.array([0.0, -0.0006, 0.0005, 0.0, 0.0, 0.0])  # rad: the shoulder's and the elbow's
PROBE = np.array([0.15, -0.1, 120.3])  # mm in link_6, nominal (0, 0, 120)
CENTRE = np.array([600.4, 99.7, 300.5])  # mm, nominal (600, 100, 300)
RADIUS = 12.7
NOISE = 0.01
JOINTS = [f"arm/joint_{k}" for k in range(1, 7)]


def tip(model, data, q: np.ndarray) -> np.ndarray:
    import pinocchio as pin

    pin.framesForwardKinematics(model, data, q + ZEROS)
    M = data.oMf[model.getFrameId("link_6")].homogeneous
    return M[:3, :3] @ (PROBE / 1000.0) * 1000.0 + M[:3, 3] * 1000.0


def gauss_newton(residual, start: np.ndarray, iterations: int = 60) -> np.ndarray | None:
    """Damped Gauss-Newton from ``start`` with a central-difference Jacobian (plain numpy, so
    the path does not change with a library's version); None where it does not converge."""
    q = start.copy()
    for _ in range(iterations):
        r = residual(q)
        if np.linalg.norm(r) < 1e-12:
            return q
        step = 1e-7
        J = np.column_stack([(residual(q + step * e) - residual(q - step * e)) / (2 * step) for e in np.eye(len(q))])
        delta = np.linalg.lstsq(J, -r, rcond=None)[0]
        q = q + delta * min(1.0, 0.5 / max(np.max(np.abs(delta)), 1e-300))  # at most 0.5 rad a step
    return q if np.linalg.norm(residual(q)) < 1e-9 else None


def touches(count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Joint angles of ``count`` touches and the distances a perfect reading would give (0)."""
    import pinocchio as pin

    model = pin.buildModelFromUrdf(str(ROOT / "robots" / "rx90.urdf"))
    data = model.createData()
    rng = np.random.default_rng(seed)
    rows = []
    while len(rows) < count:
        u = rng.normal(size=3)
        u[2] = abs(u[2]) + 0.3
        u /= np.linalg.norm(u)
        target = CENTRE + RADIUS * u
        start = np.array([0.2, 0.6, 1.8, 0.0, 0.7, 0.0]) + rng.uniform(-0.3, 0.3, 6)
        start[5] = rng.uniform(-np.pi, np.pi)  # the probe's roll: varied, it shows the probe's lateral offset
        tilt = u + rng.normal(0.0, 0.4, 3)  # the probe's approach: about along the surface's normal, varied
        tilt /= np.linalg.norm(tilt)

        def residual(q):
            pin.framesForwardKinematics(model, data, q + ZEROS)
            axis = data.oMf[model.getFrameId("link_6")].homogeneous[:3, 2]
            # The tip on the target, the probe's axis along -tilt and joint 6 at its start: six
            # equations that fix the touch. (Tip and axis alone leave the roll about the probe
            # free, and which roll an optimiser settled on changed with scipy's version.)
            return np.concatenate([tip(model, data, q) - target, axis + tilt, [q[5] - start[5]]])

        q = gauss_newton(residual, start)
        # Only exact solutions near the start are kept: they are isolated and on the start's
        # branch (not a flipped wrist), so the rows do not depend on a library's solver.
        if q is not None and np.linalg.norm(residual(q)) < 1e-9 and np.max(np.abs(q - start)) < 1.0:
            rows.append(q)
    return np.array(rows), rng.normal(0.0, NOISE, count)


def write_csv(path: Path, count: int = 40, seed: int = 11) -> None:
    q, readings = touches(count, seed)
    lines = [",".join(JOINTS + ["tz"])] + [",".join(f"{v:.12f}" for v in [*q[r], readings[r]]) for r in range(count)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


if __name__ == "__main__":
    write_csv(Path(__file__).with_name("rx90_sphere_touches.csv"))
