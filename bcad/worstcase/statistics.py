"""The typical error beside the worst one: clearances as uniform distributions.

The chain is written in bcad's general problem language: per joint, an error
link F_j -> F'_j whose L parameters are uniform on the clearance bounds
(``rx,ry: disc(rot_xy)``, ``rz: uniform(-rot_z, rot_z)``, ``tx,ty:
disc(trans_xy)``, ``tz: uniform(-trans_z, trans_z)``), then the fixed link
S_j; a fixed link gives the nominal end-effector frame, and a link from it to
the shifted end effector closes the one cycle. Its closing pose is dP
(Eq. 11), evaluated by the batched kinematics for N samples.

The error link's pose vector uses bcad's rpy rotation, which agrees with the
paper's exp(dS_j) to first order (they differ by terms of the order of the
clearance squared).
"""

from __future__ import annotations

import numpy as np

from bcad.compile import compile_problem
from bcad.worstcase.error_map import ErrorMap
from bcad.kinematics import Samples
from bcad.kinematics.se3 import matrix_to_pose
from bcad.model.problem import Problem
from bcad.numerics.sampling import FreeParameterSampler


def statistical_problem(error_map: ErrorMap, name: str, length_unit: str) -> dict:
    """The chain and its clearances as a bcad problem document (internal units)."""
    n = error_map.joints
    frames = ["F1"]
    links = []
    P = np.eye(4)
    for j in range(n):
        rot_xy, rot_z, trans_xy, trans_z = (float(v) for v in error_map.clearance[j])
        status = ["F"] * 6
        distributions = {}
        # A radial clearance is a uniform disc across the axis, an axial one a uniform interval.
        for slots, key, size in (((0, 1), "tx,ty", trans_xy), ((2,), "tz", trans_z),
                                 ((3, 4), "rx,ry", rot_xy), ((5,), "rz", rot_z)):
            if size > 0:
                for slot in slots:
                    status[slot] = "L"
                distributions[key] = f"disc({size!r})" if len(slots) == 2 else f"uniform({-size!r}, {size!r})"
        frames += [f"E{j + 1}", f"F{j + 2}"]
        links.append({"name": f"clearance{j + 1}", "parent": f"F{j + 1}", "child": f"E{j + 1}",
                      "status": "".join(status), "distributions": distributions})
        links.append({"name": f"S{j + 1}", "parent": f"E{j + 1}", "child": f"F{j + 2}",
                      "pose": [float(v) for v in matrix_to_pose(error_map.S[j])]})
        P = P @ error_map.S[j]
    frames.append("nominal")
    links.append({"name": "P", "parent": "F1", "child": "nominal", "pose": [float(v) for v in matrix_to_pose(P)]})
    links.append({"name": "dP", "parent": "nominal", "child": f"F{n + 1}", "close": True})
    return {"name": f"{name}-statistics", "units": {"length": length_unit, "angle": "rad"}, "frames": frames, "links": links}


def error_samples(error_map: ErrorMap, name: str, length_unit: str, samples: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Sampled end-effector errors dP for uniformly distributed clearances: rotation vectors
    (axis times angle, rad) and translations, each (N, 3)."""
    compiled = compile_problem(Problem.model_validate(statistical_problem(error_map, name, length_unit)))
    draws = Samples(FreeParameterSampler(compiled).draw(rng, samples))
    transform = compiled.cycle_chains[0].evaluate(np.zeros(0), draws)
    M = transform.columns  # M[j][i] = R[i, j]
    skew = 0.5 * np.stack([M[1, 2] - M[2, 1], M[2, 0] - M[0, 2], M[0, 1] - M[1, 0]], axis=-1)
    sine = np.linalg.norm(skew, axis=-1)
    angle = np.arctan2(sine, 0.5 * (M[0, 0] + M[1, 1] + M[2, 2] - 1.0))
    factor = np.where(sine > 1e-300, angle / np.where(sine > 1e-300, sine, 1.0), 1.0)
    return skew * factor[:, None], transform.translations.T.copy()


def error_statistics(error_map: ErrorMap, name: str, length_unit: str, samples: int, rng: np.random.Generator) -> dict:
    """Rotation and translation error of dP for uniformly distributed clearances."""
    rotations, translations = error_samples(error_map, name, length_unit, samples, rng)
    rotation = np.linalg.norm(rotations, axis=1)
    translation = np.linalg.norm(translations, axis=1)

    def summary(values: np.ndarray) -> dict:
        return {
            "mean": float(values.mean()),
            "median": float(np.median(values)),
            "p95": float(np.quantile(values, 0.95)),
            "p99": float(np.quantile(values, 0.99)),
            "max_sampled": float(values.max()),
        }

    return {"samples": samples, "rotation": summary(rotation), "translation": summary(translation)}
