"""Contributors: which uncertain parameters make a closing link imprecise.

Linearised (:mod:`bcad.bayes.linear`), a scored parameter c of a closing
link has the propagated variance Var(F_c) = sum_j J_cj^2 Var(L_j) where the
L are independent (across groups; a disc's two coordinates are uncorrelated),
so J_cj^2 Var(L_j) / Var(F_c) is the share of L_j: the contributor table of
tolerance analysis (root-sum-square stack-up). A calibration's posterior
correlates its L: then Var(F_c) = J_c Sigma_L J_c^T, and L_j's share is its
covariance contribution J_cj (Sigma_L J_c^T)_j / Var(F_c) (Euler's
allocation): the shares still sum to 1, and parameters whose errors offset
each other (a combination the calibration could not observe, whose sum it
knows) get shares of either sign, larger than 1 in size, that cancel.
Shares are summed per link and per robot (a robot's links are named
``ROBOT/...``).
"""

from __future__ import annotations

import numpy as np

from bcad.compiler import CompiledProblem

#: parameters listed individually per scored parameter (the rest are summed in the link and robot tables)
LISTED = 10


def variance_shares(compiled: CompiledProblem, linear, x: np.ndarray, parameter_scales) -> dict:
    """{closing link: {parameter: {"std", "by_parameter", "by_link", "by_robot"}}} at X.

    ``std`` is the linearised std of the parameter propagated from L (in the
    problem's units); shares are fractions that sum to 1 over all L.
    """
    table = compiled.parameters
    links = compiled.graph.links
    # an entity's dimension (link -1) counts under the entity's name
    link_names = [links[p.link].name if p.link >= 0 else p.name.rsplit(".", 1)[0] for p in table.l]
    robots = [r.name for r in compiled.problem.robots]  # a robot's configurations share its errors
    robot_of = [next((r for r in robots if name.startswith(r + "/")), "(not a robot)") for name in link_names]
    result: dict[str, dict] = {}
    for row, contributions in linear.contributors(x):
        link, parameter = row.name.rsplit(".", 1)
        total = float(contributions.sum())
        shares = contributions / total if total > 0 else np.zeros_like(contributions)
        order = np.argsort(-np.abs(shares), kind="stable")[:LISTED]
        by_link: dict[str, float] = {}
        by_robot: dict[str, float] = {}
        for share, name, robot in zip(shares, link_names, robot_of):
            by_link[name] = by_link.get(name, 0.0) + float(share)
            by_robot[robot] = by_robot.get(robot, 0.0) + float(share)
        scale = parameter_scales(compiled, [row.name])[0]
        result.setdefault(link, {})[parameter] = {
            "std": float(np.sqrt(total) * scale),
            "by_parameter": {table.l[j].name: float(shares[j]) for j in order if shares[j] != 0},
            "by_link": dict(sorted(by_link.items(), key=lambda item: -abs(item[1]))),
            "by_robot": dict(sorted(by_robot.items(), key=lambda item: -abs(item[1]))),
        }
    return result
