"""Exchanging the joint values of two arms of one model: a hop between the roles they play.

Where a cycle runs through two arms of the same model (the same URDF file, or the same DH rows)
whose joints are X, the best configurations often come in pairs whose arms have exchanged what
they do: on the two RX90s holding parts face to face, one arm's wrist against its limit while
the other leans in, or the other way round. A climb that found one member of a pair sits far
(several radians) from the other, whose basin the space-filling starts reach rarely. So the
search also climbs from its best maximum with the two arms' joint values exchanged, moved back
onto closure (:func:`arm_swaps` gives the permutations of X that do it). On a two-RX90 cell with
uniform and truncated-normal zero errors, 36 climbs reached the best basin on 4 of 12 seeds, and
with that one further climb on 7 of 12.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from bcad.compiler import CompiledProblem


def _model_of(robot) -> tuple:
    """What makes two robots one model: the same URDF file (and xacro arguments), or the same DH
    rows and convention."""
    if robot.urdf is not None:
        return ("urdf", str(robot.urdf), tuple(sorted((robot.xacro_args or {}).items())))
    return ("dh", robot.convention, repr(robot.dh))


def arm_swaps(compiled: CompiledProblem) -> list[np.ndarray]:
    """For each pair of robots of one model whose joints are X with the same bounds, the
    permutation of X's columns that exchanges their joint values (each joint with the joint of
    the same name), the other X unchanged. Nothing where no two robots qualify."""
    robots = compiled.problem.robots
    links = compiled.graph.links
    joints: dict[int, dict[str, int]] = {}  # robot index -> joint name within the robot -> X column
    for column, parameter in enumerate(compiled.parameters.x):
        link = links[parameter.link] if parameter.link >= 0 else None
        if link is None or link.joint is None or not link.loc or link.loc[0] != "robots":
            continue
        robot = link.loc[1]
        own = link.name.split("/", 1)[-1] + "." + parameter.name.rsplit(".", 1)[-1]
        joints.setdefault(robot, {})[own] = column
    bounds = compiled.parameters.x_bounds
    swaps = []
    for a, b in combinations(sorted(joints), 2):
        if _model_of(robots[a]) != _model_of(robots[b]) or set(joints[a]) != set(joints[b]):
            continue
        pairs = [(joints[a][name], joints[b][name]) for name in sorted(joints[a])]
        if any(tuple(bounds[i]) != tuple(bounds[j]) for i, j in pairs):
            continue
        permutation = np.arange(len(compiled.parameters.x))
        for i, j in pairs:
            permutation[i], permutation[j] = j, i
        swaps.append(permutation)
    return swaps
