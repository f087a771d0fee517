"""Benchmark of the search on fresh random cells: does every seed find the best X known?

    python bench/random_cells.py [--kinds KIND ...] [--cells 1] [--seeds 5] [--rescore 2e5] [--draw 0]
                                 [--skip-reference] [--poses {2,3}] [--keep DIR] [--efforts 1 2 ...]

Each run draws new cells (``--draw`` seeds the generator; by default the clock, so that nobody
tunes the search to them) of these kinds:

* ``ur5_poses``: one UR5 at two or three configurations (shared zero errors), each touching a
  random top face, side face, sphere or point of a part placed at random within its reach;
* ``ur5_placement``: the same with the UR5's base placement (tx, ty, rz) unknown as well;
* ``two_arms``: two UR5s on one table probing two faces of one part whose placement is uncertain
  and shared (no configurations: each arm's joints are a cycle's own X);
* ``peg``: a UR5 with its base placement unknown puts a peg in a hole, scored only by
  ``cylinder_in_cylinder``'s inequalities;
* ``dh_face``: a random 6R DH arm touching a face;
* ``rx90_non_gaussian``: the two-RX90 example with uniform and truncated-normal zero errors;
* ``linear_non_gaussian``: a placement X (priors N(0, 1)) aimed at a random target through
  uniform and truncated-normal L: judged on its closed form (quadrature), not on estimates.

For each cell, ``bcad solve FILE --seed S`` as a user runs it for seeds 0..N-1; each seed's X is
scored again by ``bcad posterior --at`` with ``--rescore`` importance samples on one fixed seed;
the best X known is the best of those and of a reference run with a search 10-40 times larger
(bench/global_search.py's REFERENCE, seed 99). Printed per kind: the share of seeds within 0.02
of the best known, the verdict's rates (the finding ``search_not_settled`` on seeds more than 0.02
below, its silence on the others), exits 3, and wall times. ``--efforts``: the seeds are solved
again at each ``solver: {search_effort: E}`` (a row each), to measure what time buys.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml
from global_search import REFERENCE, WITHIN, rescore, solve  # noqa: E402  (bench/ is on the path)
from user_environment import warm_bytecode  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
UR5 = str(REPO / "robots" / "ur5.urdf")
RX90_EXAMPLE = REPO / "problems" / "rx90_face_on_face.yaml"


def _normal(std: float) -> str:
    return f"normal(0, {std:g})"


def _target(rng: np.random.Generator, name: str, frame: str, index: int) -> tuple[list[dict], dict]:
    """A random touch target on the part (entities) and its relation to the probe tip."""
    kind = rng.choice(["top", "side", "sphere", "point"])
    x, y, z = rng.uniform(-60, 60), rng.uniform(-60, 60), rng.uniform(40, 160)
    score = {"tz": _normal(0.05)}
    if kind == "top":
        entity = {
            "name": f"t{index}",
            "type": "face",
            "frame": frame,
            "pose": [x, y, z, 0, 0, 0],
            "size": [float(rng.uniform(40, 120)), float(rng.uniform(40, 120))],
        }
        relation = {"type": "point_on_face", "status": "FFLFFF", "distributions": score}
    elif kind == "side":
        turn = float(rng.uniform(-math.pi, math.pi))
        entity = {
            "name": f"t{index}",
            "type": "face",
            "frame": frame,
            "pose": [x, y, z, 0, math.pi / 2, turn],
            "size": [float(rng.uniform(40, 100)), float(rng.uniform(40, 100))],
        }
        relation = {"type": "point_on_face", "status": "FFLFFF", "distributions": score}
    elif kind == "sphere":
        entity = {
            "name": f"t{index}",
            "type": "sphere",
            "frame": frame,
            "center": [x, y, z],
            "radius": float(rng.uniform(8, 25)),
        }
        relation = {"type": "point_on_sphere", "status": "FFLFFF", "distributions": score}
    else:
        entity = {"name": f"t{index}", "type": "point", "frame": frame, "at": [x, y, z]}
        relation = {
            "type": "point_on_point",
            "status": "LLLFFF",
            "distributions": {"tx": _normal(0.3), "ty": _normal(0.3), "tz": _normal(0.3)},
        }
    relation.update(name=f"touch_{index}", parent=f"t{index}", child=f"{name}_tip")
    return [entity], relation


def _ur5(
    name: str, pose: list[float], status: str | None = None, bounds: dict | None = None
) -> tuple[dict, dict, dict]:
    robot = {
        "name": name,
        "urdf": UR5,
        "parent": "table",
        "pose": pose,
        "joints": {"default": {"status": "X", "zero": _normal(0.001)}},
    }
    if status:
        robot["status"] = status
        robot["bounds"] = bounds
    probe = {
        "name": f"{name}_probe_mount",
        "parent": f"{name}/tool0",
        "child": f"{name}_probe",
        "pose": [0, 0, 120, 0, 0, 0],
        "status": "LLLFFF",
        "distributions": {"tx": _normal(0.05), "ty": _normal(0.05), "tz": _normal(0.05)},
    }
    tip = {"name": f"{name}_tip", "type": "point", "frame": f"{name}_probe", "at": [0, 0, 0]}
    return robot, probe, tip


def _part_pose(rng: np.random.Generator) -> list[float]:
    radius, angle = rng.uniform(380, 560), rng.uniform(-1.2, 1.2)
    return [
        float(radius * math.cos(angle)),
        float(radius * math.sin(angle)),
        0.0,
        0.0,
        0.0,
        float(rng.uniform(-math.pi, math.pi)),
    ]


def ur5_cell(rng: np.random.Generator, placement: bool, poses: int | None = None) -> dict:
    count = int(rng.integers(2, 4))
    count = poses or count  # drawn all the same: the cells drawn after are those of the same --draw
    if placement:
        robot, probe, tip = _ur5(
            "ur5", [0, 0, 0, 0, 0, 0], "XXFFFX", {"tx": [-150, 150], "ty": [-150, 150], "rz": [-3.14159, 3.14159]}
        )
    else:
        robot, probe, tip = _ur5("ur5", [0, 0, 0, 0, 0, 0])
    entities, relations = [tip], []
    for k in range(count):
        found, relation = _target(rng, "ur5", "part", k)
        entities += found
        relations.append(relation)
    return {
        "name": "ur5-placement" if placement else "ur5-poses",
        "units": {"length": "mm", "angle": "rad"},
        "frames": ["table", "part", "ur5_probe"],
        "robots": [robot],
        "links": [probe, {"name": "part_placement", "parent": "table", "child": "part", "pose": _part_pose(rng)}],
        "entities": entities,
        "relations": relations,
        "configurations": [
            {"name": f"c{k}", "joints": {"ur5": {}}, "relations": [r["name"]]} for k, r in enumerate(relations)
        ],
    }


def two_arms_cell(rng: np.random.Generator) -> dict:
    spacing = float(rng.uniform(700, 1000))
    left, left_probe, left_tip = _ur5("left", [0, 0, 0, 0, 0, 0])
    right, right_probe, right_tip = _ur5("right", [spacing, 0, 0, 0, 0, math.pi])
    part = [spacing / 2, float(rng.uniform(250, 450)), 0, 0, 0, float(rng.uniform(-0.5, 0.5))]
    faces = [
        {"name": "a", "type": "face", "frame": "part", "pose": [-40, 0, 60, 0, -math.pi / 2, 0], "size": [80, 80]},
        {"name": "b", "type": "face", "frame": "part", "pose": [40, 0, 60, 0, math.pi / 2, 0], "size": [80, 80]},
    ]
    if rng.random() < 0.5:
        faces[1]["pose"] = [0, 0, 120, 0, 0, 0]
    relations = [
        {
            "name": "touch_left",
            "type": "point_on_face",
            "parent": "a",
            "child": "left_tip",
            "status": "FFLFFF",
            "distributions": {"tz": _normal(0.05)},
        },
        {
            "name": "touch_right",
            "type": "point_on_face",
            "parent": "b",
            "child": "right_tip",
            "status": "FFLFFF",
            "distributions": {"tz": _normal(0.05)},
        },
    ]
    return {
        "name": "two-arms",
        "units": {"length": "mm", "angle": "rad"},
        "frames": ["table", "part", "left_probe", "right_probe"],
        "robots": [left, right],
        "links": [
            left_probe,
            right_probe,
            {
                "name": "part_placement",
                "parent": "table",
                "child": "part",
                "pose": part,
                "status": "LLFFFL",
                "distributions": {"tx": _normal(0.5), "ty": _normal(0.5), "rz": _normal(0.002)},
            },
        ],
        "entities": faces + [left_tip, right_tip],
        "relations": relations,
    }


def peg_cell(rng: np.random.Generator) -> dict:
    robot = {
        "name": "ur5",
        "urdf": UR5,
        "parent": "table",
        "pose": [0, 0, 0, 0, 0, 0],
        "status": "XXFFFX",
        "bounds": {"tx": [-150, 150], "ty": [-150, 150], "rz": [-3.14159, 3.14159]},
        "joints": {"default": {"status": "X", "zero": _normal(0.0005)}},
    }
    clearance = float(rng.uniform(0.05, 0.3))
    return {
        "name": "peg",
        "units": {"length": "mm", "angle": "rad"},
        "frames": ["table", "fixture", "gripper"],
        "robots": [robot],
        "links": [
            {"name": "gripper_mount", "parent": "ur5/tool0", "child": "gripper", "pose": [0, 0, 90, 0, 0, 0]},
            {
                "name": "fixture_placement",
                "parent": "table",
                "child": "fixture",
                "pose": _part_pose(rng)[:2] + [100, 0, 0, 0],
                "status": "LLFFFF",
                "distributions": {"tx": _normal(0.05), "ty": _normal(0.05)},
            },
        ],
        "entities": [
            {"name": "hole", "type": "cylinder", "frame": "fixture", "radius": 5.0, "length": 20.0},
            {
                "name": "peg",
                "type": "cylinder",
                "frame": "gripper",
                "pose": [0, 0, 60, math.pi, 0, 0],
                "radius": 5.0 - clearance,
                "length": 60.0,
            },
        ],
        "relations": [
            {"name": "insertion", "type": "cylinder_in_cylinder", "parent": "hole", "child": "peg", "close": True}
        ],
    }


def dh_face_cell(rng: np.random.Generator) -> dict:
    rows = []
    for _k in range(6):
        rows.append(
            {
                "a": float(rng.choice([0.0, rng.uniform(50, 400)])),
                "alpha": float(rng.choice([0.0, math.pi / 2, -math.pi / 2])),
                "d": float(rng.choice([0.0, rng.uniform(50, 300)])),
                "theta": 0.0,
            }
        )
    reach = sum(abs(r["a"]) + abs(r["d"]) for r in rows)
    robot = {
        "name": "arm",
        "dh": rows,
        "parent": "table",
        "joints": {"default": {"status": "X", "zero": _normal(0.001)}},
    }
    distance = float(rng.uniform(0.3, 0.6) * reach)
    return {
        "name": "dh-face",
        "units": {"length": "mm", "angle": "rad"},
        "frames": ["table", "part", "probe"],
        "robots": [robot],
        "links": [
            {
                "name": "probe_mount",
                "parent": "arm/link_6",
                "child": "probe",
                "pose": [0, 0, 100, 0, 0, 0],
                "status": "LLLFFF",
                "distributions": {"tx": _normal(0.05), "ty": _normal(0.05), "tz": _normal(0.05)},
            },
            {"name": "part_placement", "parent": "table", "child": "part", "pose": [distance, 0, 0, 0, 0, 0]},
        ],
        "entities": [
            {
                "name": "top",
                "type": "face",
                "frame": "part",
                "pose": [0, 0, float(rng.uniform(0, 200)), 0, 0, 0],
                "size": [100, 100],
            },
            {"name": "tip", "type": "point", "frame": "probe", "at": [0, 0, 0]},
        ],
        "relations": [
            {
                "name": "touch",
                "type": "point_on_face",
                "parent": "top",
                "child": "tip",
                "status": "FFLFFF",
                "distributions": {"tz": _normal(0.05)},
            }
        ],
    }


def rx90_non_gaussian_cell(rng: np.random.Generator) -> dict:
    document = yaml.safe_load(RX90_EXAMPLE.read_text())
    for robot in document["robots"]:
        robot["urdf"] = str((RX90_EXAMPLE.parent / robot["urdf"]).resolve())
        spread = float(rng.uniform(0.005, 0.02))
        zero = (
            f"uniform({-spread:g}, {spread:g})"
            if rng.random() < 0.5
            else f"truncnormal(0, {spread:g}, {-1.5 * spread:g}, {2 * spread:g})"
        )
        robot.setdefault("joints", {}).setdefault("default", {})["zero"] = zero
    document["name"] = "rx90-non-gaussian"
    return document


def linear_non_gaussian_cell(rng: np.random.Generator) -> dict:
    target = [float(v) for v in rng.uniform(1.5, 3.5, 2) * rng.choice([-1, 1], 2)]
    half = float(rng.uniform(0.3, 1.5))
    low, high = float(rng.uniform(-1.0, -0.2)), float(rng.uniform(0.5, 2.0))
    return {
        "name": "linear-non-gaussian",
        "frames": ["a", "m", "b"],
        "links": [
            {
                "name": "unknown",
                "parent": "a",
                "child": "m",
                "status": "XXFFFF",
                "bounds": {"tx": [-10, 10], "ty": [-10, 10]},
                "distributions": {"tx": "normal(0, 1)", "ty": "normal(0, 1)"},
            },
            {
                "name": "free",
                "parent": "m",
                "child": "b",
                "status": "LLFFFF",
                "distributions": {"tx": f"uniform({-half:g}, {half:g})", "ty": f"truncnormal(0, 1, {low:g}, {high:g})"},
            },
            {
                "name": "measured",
                "parent": "a",
                "child": "b",
                "pose": target + [0, 0, 0, 0],
                "status": "LLFFFF",
                "close": True,
                "distributions": {"tx": "normal(0, 0.05)", "ty": "normal(0, 0.05)"},
            },
        ],
    }


def linear_exact(document: dict) -> tuple[callable, float]:
    """The linear cell's log p(X) I(X) in closed form (quadrature) and its optimum."""
    from scipy import integrate, optimize, stats

    links = {link["name"]: link for link in document["links"]}
    target = links["measured"]["pose"][:2]
    half = float(links["free"]["distributions"]["tx"].split("(")[1].split(",")[1].rstrip(")"))
    low, high = (float(v) for v in links["free"]["distributions"]["ty"].rstrip(")").split(",")[2:4])
    truncated = stats.truncnorm(low, high)

    def convolution(miss, density, a, b):
        value, _ = integrate.quad(
            lambda e: density(e) * stats.norm.pdf(miss - e, 0.0, 0.05), a, b, points=[min(max(miss, a), b)], limit=400
        )
        return math.log(max(value, 1e-300))

    def log_value(x, y):
        return (
            stats.norm.logpdf(x)
            + convolution(target[0] - x, lambda e: 0.5 / half, -half, half)
            + stats.norm.logpdf(y)
            + convolution(target[1] - y, truncated.pdf, low, high)
        )

    best_x = optimize.minimize_scalar(
        lambda x: -log_value(x, 0.0), bounds=(-6, 6), method="bounded", options={"xatol": 1e-9}
    ).x
    best_y = optimize.minimize_scalar(
        lambda y: -log_value(best_x, y), bounds=(-6, 6), method="bounded", options={"xatol": 1e-9}
    ).x
    return log_value, log_value(best_x, best_y)


KINDS = {
    "ur5_poses": lambda rng, poses: ur5_cell(rng, placement=False, poses=poses),
    "ur5_placement": lambda rng, poses: ur5_cell(rng, placement=True, poses=poses),
    "two_arms": lambda rng, poses: two_arms_cell(rng),
    "peg": lambda rng, poses: peg_cell(rng),
    "dh_face": lambda rng, poses: dh_face_cell(rng),
    "rx90_non_gaussian": lambda rng, poses: rx90_non_gaussian_cell(rng),
    "linear_non_gaussian": lambda rng, poses: linear_non_gaussian_cell(rng),
}


def _finite(value: float | None) -> float:
    """A run's log p(X) I(X), -inf where it has none (no sample met the relations: exit 3)."""
    return -math.inf if value is None else float(value)


def reference_copy(document: dict, folder: Path, stem: str) -> Path:
    document = {**document, "solver": {**document.get("solver", {}), **REFERENCE}}
    path = folder / f"{stem}-reference.yaml"
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--kinds", nargs="+", default=list(KINDS), choices=list(KINDS))
    parser.add_argument("--cells", type=int, default=1, help="cells per kind")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--rescore", type=float, default=2e5)
    parser.add_argument("--draw", type=int, default=None, help="the generator's seed (default: the clock)")
    parser.add_argument("--skip-reference", action="store_true")
    parser.add_argument(
        "--poses", type=int, choices=(2, 3), help="poses of the UR5 kinds' cells (default: two or three, drawn)"
    )
    parser.add_argument(
        "--keep", type=Path, help="write the cells, results and each cell's summary here instead of a temporary folder"
    )
    parser.add_argument(
        "--efforts", type=float, nargs="+", default=[1.0], help="solve the seeds at each solver.search_effort"
    )
    args = parser.parse_args()
    draw = args.draw if args.draw is not None else int(time.time())
    print(f"cells drawn with --draw {draw}")
    warm_bytecode()
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        rng = np.random.default_rng(draw)
        print(
            f"{'kind':<20} {'cell':>4} {'effort':>6} {'within 0.02':>11} {'finding on worse':>16} {'silent on within':>16} "
            f"{'exit 3':>6} {'spread':>7} {'wall median (max), s':>21}"
        )
        for kind in args.kinds:
            for cell in range(args.cells):
                document = KINDS[kind](rng, args.poses)
                stem = f"{kind}-{cell}"
                path = folder / f"{stem}.yaml"
                path.write_text(yaml.safe_dump(document, sort_keys=False))
                by_effort = {}
                for effort in args.efforts:
                    solved = path
                    if effort != 1.0:
                        solved = folder / f"{stem}-effort{effort:g}.yaml"
                        settings = {**document.get("solver", {}), "search_effort": effort}
                        solved.write_text(yaml.safe_dump({**document, "solver": settings}, sort_keys=False))
                    runs = by_effort[effort] = []
                    for seed in range(args.seeds):
                        run = solve(solved, seed, folder)
                        findings = json.loads(Path(run["output"]).read_text()).get("findings", [])
                        run["finding"] = any(f["code"] == "search_not_settled" for f in findings)
                        runs.append(rescore(path, run, int(args.rescore)) if args.rescore else run)
                best = max(_finite(r["value"]) for runs in by_effort.values() for r in runs)
                if kind == "linear_non_gaussian":
                    exact, best = linear_exact(document)
                elif not args.skip_reference:
                    reference = solve(reference_copy(document, folder, stem), 99, folder)
                    if args.rescore:
                        reference = rescore(path, reference, int(args.rescore))
                    best = max(best, _finite(reference["value"]))
                if not math.isfinite(best):
                    print(
                        f"{kind:<20} {cell:>4} no X with I(X) > 0 found by any seed or the reference (every run exits "
                        "3): the cell's goal may be out of reach",
                        flush=True,
                    )
                    continue
                summary = {"best": best, "efforts": {}}
                for effort, runs in by_effort.items():
                    if kind == "linear_non_gaussian":
                        values = [exact(r["solution"]["unknown.tx"], r["solution"]["unknown.ty"]) for r in runs]
                    else:
                        values = [_finite(r["value"]) for r in runs]
                    within = [v >= best - (0.01 if kind == "linear_non_gaussian" else WITHIN) for v in values]
                    worse = [r for r, w in zip(runs, within) if not w]
                    good = [r for r, w in zip(runs, within) if w]
                    walls = [r["wall"] for r in runs]
                    summary["efforts"][effort] = {"values": values, "within": within, "runs": runs}
                    print(
                        f"{kind:<20} {cell:>4} {effort:>6g} {sum(within):>5} of {len(runs):<3} "
                        f"{sum(r['finding'] for r in worse):>8} of {len(worse):<5} {sum(not r['finding'] for r in good):>8} of {len(good):<5} "
                        f"{sum(r['exit'] == 3 for r in runs):>6} {best - min(values):>7.3f} "
                        f"{statistics.median(walls):>10.2f} ({max(walls):.2f})",
                        flush=True,
                    )
                (folder / f"{stem}-summary.json").write_text(json.dumps(summary, indent=1, default=str))


if __name__ == "__main__":
    main()
