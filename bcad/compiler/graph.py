"""The probabilistic kinematic graph: frames, links, spanning tree and cycles.

Sect. 3.1 of the 2000 paper: frames are vertices, links are directed edges. A
connected graph with n frames and m links has p = m - n + 1 independent
cycles; each is closed by one *closing link* whose pose is computed from the
rest of its cycle (Eq. 1) rather than sampled. bcad picks a spanning tree
(Kruskal, preferring robots and plain links in the tree, relations out of it),
and every link left out of the tree closes its fundamental cycle.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bcad.model.source import Location
from bcad.relations.geometry import RelationConstraint

# Lower ranks go into the spanning tree first.
TREE_RANK = {"robot": 0, "link": 1, "relation": 2, "closing": 3}


@dataclass
class GraphLink:
    """One edge: ``T = origin · T(Q) · tip`` from ``parent`` to ``child``.

    Lengths are in the problem's length unit, angles in radians.
    ``distributions`` maps a parameter group (``("rz",)`` or ``("tx", "ty")``)
    to its distribution (of the deviation from ``nominal`` for L parameters,
    a prior on the value for X parameters).
    """

    name: str
    parent: str
    child: str
    nominal: np.ndarray
    status: str
    origin: np.ndarray = field(default_factory=lambda: np.eye(4))
    tip: np.ndarray = field(default_factory=lambda: np.eye(4))
    distributions: dict[tuple[str, ...], object] = field(default_factory=dict)  # Distribution models
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    relation: RelationConstraint | None = None
    rank: str = "link"
    loc: Location = ()
    #: parameters that follow another link's (URDF <mimic>): slot -> (link name, its slot, factor, offset),
    #: the value being factor x that parameter + offset; such a slot has status F here
    coupled: dict[int, tuple[str, int, float, float]] = field(default_factory=dict)
    #: a robot joint's motion link: (ROBOT/JOINT, sign, factor) with parameter = sign x factor x the
    #: joint's value in the problem's units (factor: the angle unit in rad, or 1 for lengths)
    joint: tuple[str, float, float] | None = None
    #: a motion link's joint variable: which of (tx ... rz) it is (its axis: slot mod 3)
    joint_slot: int | None = None
    #: a motion link's limits [low, high] of the joint's value (internal units), before the sign
    joint_limits: tuple[float, float] | None = None
    #: the joint's own travel (a URDF's <limit>, a DH row's limits; internal units): no bounds or
    #: value, the robot's or a configuration's, may reach past it; None where it has none
    hard_limits: tuple[float, float] | None = None
    #: whether the problem gave this link's bounds (False: a robot joint's limits, its model's)
    bounds_given: bool = True
    #: a configuration's copy of a link whose parameters it shares: the name of the
    #: link that holds them; the copy's pose is that link's, draw for draw
    shared: str | None = None
    #: the configuration a link belongs to, None where it belongs to the whole cell
    configuration: str | None = None
    #: names of its parameters other than LINK.PARAM (an entity's position: ENTITY.at[0]), by slot
    parameter_names: dict[int, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Cycle:
    """A fundamental cycle: its closing link and the tree path that closes it.

    ``path`` runs from the closing link's parent frame to its child frame as
    (link index, used forward) pairs, so ``T_parent,child`` is their product.
    """

    closing_link: int
    path: tuple[tuple[int, bool], ...]


@dataclass
class KinematicGraph:
    frames: list[str]
    links: list[GraphLink]
    tree_links: list[int]
    cycles: list[Cycle]
    #: frame -> (link to its tree parent, link used forward from parent to frame)
    tree_parent: dict[str, tuple[int, bool]]

    @property
    def root(self) -> str:
        return self.frames[0]

    @property
    def closing_links(self) -> list[int]:
        return [cycle.closing_link for cycle in self.cycles]

    def path_from_root(self, frame: str) -> list[tuple[int, bool]]:
        """Tree links from the root to ``frame``, each with its direction of use."""
        path: list[tuple[int, bool]] = []
        while frame in self.tree_parent:
            index, forward = self.tree_parent[frame]
            path.append((index, forward))
            link = self.links[index]
            frame = link.parent if forward else link.child
        return path[::-1]

    def tree_path(self, start: str, end: str) -> list[tuple[int, bool]]:
        """Tree links from ``start`` to ``end`` (up to their common ancestor, then down)."""
        up = self.path_from_root(start)
        down = self.path_from_root(end)
        common = 0
        while common < min(len(up), len(down)) and up[common] == down[common]:
            common += 1
        return [(index, not forward) for index, forward in reversed(up[common:])] + down[common:]


class DisconnectedGraph(Exception):
    """Raised with the frames that the spanning tree cannot reach from the root."""

    def __init__(self, unreached: list[str]):
        super().__init__(unreached)
        self.unreached = unreached


def build_graph(frames: list[str], links: list[GraphLink]) -> KinematicGraph:
    """Spanning tree, fundamental cycles and closing links of a frame/link set."""
    parent = {frame: frame for frame in frames}

    def find(frame: str) -> str:
        while parent[frame] != frame:
            parent[frame] = parent[parent[frame]]
            frame = parent[frame]
        return frame

    order = sorted(range(len(links)), key=lambda k: (TREE_RANK[links[k].rank], k))
    tree: list[int] = []
    closing: list[int] = []
    for index in order:
        a, b = find(links[index].parent), find(links[index].child)
        if a == b:
            closing.append(index)
        else:
            parent[a] = b
            tree.append(index)

    root = frames[0]
    unreached = [frame for frame in frames if find(frame) != find(root)]
    if unreached:
        raise DisconnectedGraph(unreached)

    adjacency: dict[str, list[tuple[int, str, bool]]] = {frame: [] for frame in frames}
    for index in sorted(tree):
        link = links[index]
        adjacency[link.parent].append((index, link.child, True))
        adjacency[link.child].append((index, link.parent, False))
    tree_parent: dict[str, tuple[int, bool]] = {}
    queue, seen = [root], {root}
    while queue:
        frame = queue.pop(0)
        for index, other, forward in adjacency[frame]:
            if other not in seen:
                seen.add(other)
                tree_parent[other] = (index, forward)
                queue.append(other)

    graph = KinematicGraph(frames, links, sorted(tree), [], tree_parent)
    graph.cycles = [
        Cycle(index, tuple(graph.tree_path(links[index].parent, links[index].child))) for index in sorted(closing)
    ]
    return graph
