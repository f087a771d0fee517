"""Problem schema -> kinematic graph, parameter table and compiled cycle chains."""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from bcad.arguments import Spelling
from bcad.compiler.calibration import CalibrationPrior, apply_calibrations
from bcad.compiler.configurations import ConfigurationCopy, check_shared_links, replicate_configurations
from bcad.compiler.dimensions import (
    TAKES_UNCERTAIN_RADIUS,
    add_uncertain_dimensions,
    add_uncertain_radii,
    edge_link,
    edge_transform,
    is_uncertain,
    nominal_position,
    position_frame,
    position_is_uncertain,
    position_link,
    with_dimensions,
)
from bcad.compiler.edges import check_edge, closing_x_message, edge_from_spec
from bcad.compiler.graph import DisconnectedGraph, GraphLink, KinematicGraph, build_graph
from bcad.compiler.parameters import ParameterTable, build_parameter_table
from bcad.compiler.robots import RobotFrames, robot_frames_and_links
from bcad.compiler.units import parameter_scales, pose_to_internal
from bcad.errors import InputError
from bcad.kinematics.chain import AffineParameter, BatchTransform, Chain, LinkTransform, Samples, compose
from bcad.kinematics.se3 import invert, pose_to_matrix, translation
from bcad.model.entities import Edge, Face
from bcad.model.pose import PARAMETERS
from bcad.model.problem import Problem
from bcad.model.source import Location, SourceDocument, file_trouble
from bcad.relations import RelationError, relation_kind
from bcad.relations.geometry import surface_coordinates


def relation_constraint(spec, parent, child, doc, loc):
    """The constraints of relation ``spec`` between entities ``parent`` and ``child``, with the
    terms by which their uncertain dimensions move it (named by L parameter: resolved to L
    columns once the table is built)."""
    kind = relation_kind(spec.type)
    if not kind.takes_uncertain_radius:
        for role, entity in (("parent", parent), ("child", child)):
            if is_uncertain(getattr(entity, "radius", 0.0)):
                raise doc.error(
                    loc + (role,),
                    f"{kind.name} needs the radius of '{entity.name}' exactly known; an uncertain radius (a "
                    f"distribution) is taken by {' and '.join(TAKES_UNCERTAIN_RADIUS)} and by measurements",
                )
    try:
        constraint = kind.build(parent, child)
    except RelationError as error:
        raise doc.error(loc + (error.role,), error.message) from None
    return with_dimensions(kind, parent, child, constraint)


@dataclass(frozen=True)
class ProblemStats:
    """Table 1 of the 2000 paper."""

    frames: int
    links: int
    cycles: int
    optimization_dim: int
    integration_dim: int
    inequality_constraints: int

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


@dataclass
class CompiledProblem:
    problem: Problem
    graph: KinematicGraph
    parameters: ParameterTable
    transforms: list[LinkTransform]
    cycle_chains: list[Chain]
    robots: list[RobotFrames]
    #: what the problem's calibration results changed (:mod:`bcad.compiler.calibration`)
    calibration: CalibrationPrior = field(default_factory=CalibrationPrior)
    #: the cell's configurations (:mod:`bcad.compiler.configurations`), none for a single pose
    configurations: list[ConfigurationCopy] = field(default_factory=list)

    @property
    def stats(self) -> ProblemStats:
        graph = self.graph
        return ProblemStats(
            frames=len(graph.frames),
            links=len(graph.links),
            cycles=len(graph.cycles),
            optimization_dim=len(self.parameters.x),
            integration_dim=len(self.parameters.l),
            inequality_constraints=sum(
                link.relation.inequality_count for link in graph.links if link.relation is not None
            ),
        )

    def closing_poses(self, x: np.ndarray, samples: Samples) -> list[np.ndarray]:
        """For each cycle, the pose Q of its closing link, F_i(X, L) of Eq. 2, shape (N, 6)."""
        return [chain.evaluate(x, samples).poses() for chain in self.cycle_chains]

    def copies_of(self, frame: str) -> list[str]:
        """A frame's names in the graph: one per configuration that moves it, else itself."""
        return [c.frames[frame] for c in self.configurations if frame in c.frames] or [frame]

    def check_unknowns(self, x: np.ndarray, refused) -> None:
        """Raise ``refused(name, message)`` (an InputError where the X's value came from: a
        result file's line, --value) unless every X is within its bounds (a result of another
        problem, a hand-edited 1e308): what the problem's X may be."""
        scales = parameter_scales(self, self.parameters.x_names)
        for name, value, (low, high), scale in zip(self.parameters.x_names, x, self.parameters.x_bounds, scales):
            slack = 1e-9 * max(high - low, 1e-12)
            if not (low - slack <= value <= high + slack):
                raise refused(
                    name,
                    f"the value of X parameter {name} is {value * scale:.6g}, outside its bounds "
                    f"[{low * scale:.6g}, {high * scale:.6g}]",
                )

    def frame_transforms(
        self, x: np.ndarray, samples: Samples, frames: list[str] | None = None
    ) -> dict[str, BatchTransform]:
        """Each frame's transform (default: every frame) in the root frame, through the spanning tree.

        Each tree link is evaluated once and composed onto its parent frame's transform, so
        that all F frames of a long arm cost F link evaluations, not F² (a 500-joint robot)."""
        known: dict[str, BatchTransform] = {}

        def transform_of(frame: str) -> BatchTransform | None:
            # iterative: a chain of thousands of frames needs no recursion
            path = []
            while frame not in known and frame in self.graph.tree_parent:
                path.append(frame)
                index, forward = self.graph.tree_parent[frame]
                link = self.graph.links[index]
                frame = link.parent if forward else link.child
            above = known.get(frame)  # None: the root
            for child in reversed(path):
                index, forward = self.graph.tree_parent[child]
                step = Chain([(self.transforms[index], forward)]).evaluate(x, samples)
                above = step if above is None else compose(above, step)
                known[child] = above
            return above

        out = {}
        for frame in self.graph.frames if frames is None else frames:
            found = transform_of(frame)
            out[frame] = found if found is not None else Chain([]).evaluate(x, samples)
        return out


def _article(noun: str) -> str:
    """'an' before a vowel (an edge), else 'a' (a face)."""
    return "an" if noun[:1].lower() in "aeiou" else "a"


def _unknown(kind: str, name: str, known: list[str]) -> str:
    close = difflib.get_close_matches(name, known, n=1)
    hint = f" (did you mean '{close[0]}'?)" if close else ""
    return f"unknown {kind} '{name}'{hint}"


def _check_unique(doc: SourceDocument, kind: str, items: list[tuple[str, Location]]) -> None:
    """Each name given once, and none empty (an empty name is nothing another entry can refer to)."""
    seen: dict[str, Location] = {}
    for name, loc in items:
        if not name.strip():
            raise doc.error(loc, f"an empty {kind} name; expected a name")
        if name in seen:
            line = doc.mark(seen[name]).line
            raise doc.error(loc, f"duplicate {kind} name '{name}' (first declared on line {line})")
        seen[name] = loc


def entity_frame(entity, units) -> np.ndarray:
    """Constant transform from an entity's host frame to its entity frame."""
    if isinstance(entity, (Face,)) or entity.type in ("cylinder", "target"):
        return pose_to_matrix(pose_to_internal(entity.pose, units))
    if isinstance(entity, Edge):
        start, end = np.array(entity.nominal_start, float), np.array(entity.nominal_end, float)
        x_axis = (end - start) / np.linalg.norm(end - start)
        helper = np.eye(3)[int(np.argmin(np.abs(x_axis)))]
        z_axis = np.cross(x_axis, helper)
        z_axis /= np.linalg.norm(z_axis)
        T = translation(start)
        T[:3, :3] = np.column_stack([x_axis, np.cross(z_axis, x_axis), z_axis])
        return T
    return translation(nominal_position(entity))


def entity_anchor(entity, units) -> tuple[str, np.ndarray]:
    """The graph frame an entity hangs on and its constant transform from there: its host frame
    and :func:`entity_frame`, or, where its position is uncertain, the frame of its position
    link (:func:`bcad.compiler.dimensions.position_link`) and the identity."""
    if position_is_uncertain(entity):
        return position_frame(entity), np.eye(4)
    return entity.frame, entity_frame(entity, units)


def compile_problem(problem: Problem) -> CompiledProblem:
    """Check a validated problem's references and build its kinematic graph."""
    doc, units = problem.source, problem.units
    _check_unique(doc, "frame", [(name, ("frames", i)) for i, name in enumerate(problem.frames)])
    _check_unique(doc, "robot", [(r.name, ("robots", i, "name")) for i, r in enumerate(problem.robots)])
    _check_unique(doc, "entity", [(e.name, ("entities", i, "name")) for i, e in enumerate(problem.entities)])
    _check_unique(
        doc,
        "link or relation",
        [(l.name, ("links", i, "name")) for i, l in enumerate(problem.links)]
        + [(r.name, ("relations", i, "name")) for i, r in enumerate(problem.relations)],
    )

    frames = list(problem.frames)
    frame_locs: dict[str, Location] = {name: ("frames", i) for i, name in enumerate(frames)}
    links: list[GraphLink] = []
    robots: list[RobotFrames] = []

    def require_frame(name: str, loc: Location) -> None:
        if name in frame_locs:
            return
        robot = name.split("/", 1)[0] if "/" in name else None
        if robot in {r.name for r in problem.robots}:
            # A robot's frames come from its URDF: a misspelt link, not a missing declaration.
            links = [frame.split("/", 1)[1] for frame in frame_locs if frame.startswith(robot + "/")]
            raise doc.error(
                loc, _unknown("frame", name, list(frame_locs)) + f"; robot '{robot}' has the links {', '.join(links)}"
            )
        raise doc.error(loc, _unknown("frame", name, list(frame_locs)) + "; declare it under frames")

    for i, robot in enumerate(problem.robots):
        if "/" in robot.name:
            raise doc.error(("robots", i, "name"), f"robot name '{robot.name}' may not contain '/'")
        robot_frames, robot_links, placement = robot_frames_and_links(robot, i, units, doc)
        robots.append(placement)
        for frame in robot_frames:
            if frame in frame_locs:
                raise doc.error(
                    ("robots", i, "name"),
                    f"robot frame '{frame}' clashes with the frame declared at line {doc.mark(frame_locs[frame]).line}",
                )
            frame_locs[frame] = ("robots", i)
        frames.extend(robot_frames)
        links.extend(robot_links)
    for i, robot in enumerate(problem.robots):
        require_frame(robot.parent, ("robots", i, "parent"))

    for i, spec in enumerate(problem.links):
        loc = ("links", i)
        require_frame(spec.parent, loc + ("parent",))
        require_frame(spec.child, loc + ("child",))
        if spec.parent == spec.child:
            raise doc.error(loc + ("child",), f"link '{spec.name}' joins frame '{spec.parent}' to itself")
        check_edge(spec, loc, doc)
        rank = "closing" if spec.close else "link"
        links.append(edge_from_spec(spec.name, spec.parent, spec.child, spec, loc, units, rank))

    entities = {}
    for i, entity in enumerate(problem.entities):
        require_frame(entity.frame, ("entities", i, "frame"))
        entities[entity.name] = entity
        if position_is_uncertain(entity):
            frame = position_frame(entity)
            link = (
                edge_link(entity, i, entity_frame(entity, units))
                if entity.type == "edge"
                else position_link(entity, i, doc)
            )
            if frame in frame_locs or link.name in {l.name for l in problem.links} | {
                r.name for r in problem.relations
            }:
                raise doc.error(
                    ("entities", i, "name"),
                    f"the frame '{frame}' or link '{link.name}' of the uncertain "
                    f"position of '{entity.name}' clashes with a declared frame or link",
                )
            frames.append(frame)
            frame_locs[frame] = ("entities", i)
            links.append(link)

    for i, spec in enumerate(problem.relations):
        loc = ("relations", i)
        ends = []
        kind = relation_kind(spec.type)
        for role, expected in (("parent", kind.parent), ("child", kind.child)):
            entity = entities.get(getattr(spec, role))
            if entity is None:
                raise doc.error(
                    loc + (role,),
                    _unknown("entity", getattr(spec, role), list(entities)) + "; declare it under entities",
                )
            if entity.type != expected:
                raise doc.error(
                    loc + (role,),
                    f"{spec.type} needs {_article(expected)} {expected} as {role}; "
                    f"'{entity.name}' is {_article(entity.type)} {entity.type}",
                )
            ends.append(entity)
        parent, child = ends
        check_edge(spec, loc, doc)
        constraint = relation_constraint(spec, parent, child, doc, loc)
        for parameter in constraint.constrained:
            value = spec.pose[PARAMETERS.index(parameter)]
            if value != 0.0:
                raise doc.error(
                    loc + ("pose",),
                    f"{spec.type} constrains {parameter} to 0, but the nominal pose has {parameter} = {value:g}",
                )
        if parent.frame == child.frame:
            raise doc.error(
                loc + ("child",), f"relation '{spec.name}' joins two entities of the same frame '{parent.frame}'"
            )
        child_host, child_frame = entity_anchor(child, units)
        parent_host, parent_frame = entity_anchor(parent, units)
        parent_frame, child_frame = kind.frames(parent, child, parent_frame, child_frame)
        rank = {True: "closing", False: "link", None: "relation"}[spec.close]
        link = edge_from_spec(spec.name, parent_host, child_host, spec, loc, units, rank)
        link.origin = parent_frame
        link.tip = invert(child_frame)
        link.relation = constraint
        links.append(link)

    frames, links, configurations = replicate_configurations(problem, frames, links)
    robots = [configured for robot in robots for configured in configured_robots(robot, configurations)]
    try:
        graph = build_graph(frames, links)
    except DisconnectedGraph as exc:
        first = exc.unreached[0]
        raise doc.error(
            frame_locs.get(first.split("@")[0], ()),
            f"the graph is disconnected: frame '{first}'"
            + (f" and {len(exc.unreached) - 1} other(s)" if len(exc.unreached) > 1 else "")
            + f" cannot be reached from '{frames[0]}' through any link",
        ) from None

    closing = set(graph.closing_links)
    for index, link in enumerate(graph.links):
        if link.rank == "closing" and index not in closing:
            raise doc.error(link.loc + ("close",), f"'{link.name}' asks to close a cycle, but it lies on no cycle")
        if link.relation is not None and link.relation.curvilinear and index not in closing:
            raise doc.error(
                link.loc + ("close",),
                f"'{link.name}' ({link.relation.kind}) must close a cycle: its pose is in "
                "curvilinear (spherical or cylindrical) coordinates, which only a closing link's computed pose "
                "can take; set close: true",
            )
        if index in closing and "X" in link.status:
            raise doc.error(link.loc + ("status",), closing_x_message(link.name, link.status))

    _check_unique(doc, "camera", [(c.name, ("cameras", i, "name")) for i, c in enumerate(problem.cameras)])
    _check_unique(
        doc, "measurement", [(m.name, ("measurements", i, "name")) for i, m in enumerate(problem.measurements)]
    )
    for i, camera in enumerate(problem.cameras):
        if camera.frame not in graph.frames:
            raise doc.error(
                ("cameras", i, "frame"),
                f"unknown frame '{camera.frame}'; a camera's frame is its optical "
                "frame (x right, y down, z forward), a frame of the problem reached by the camera's mount link",
            )
    mismatch = check_shared_links(graph.links, closing)
    if mismatch is not None:
        raise doc.error(("configurations",), mismatch)
    table, transforms = build_parameter_table(graph)
    radius_columns = add_uncertain_radii(table, problem)
    dimension_columns = add_uncertain_dimensions(table, problem)
    for entity in problem.entities:
        if entity.type == "edge" and position_is_uncertain(entity):
            # The edge's position link: its ends' deviations as L terms (first order)
            index = next(k for k, link in enumerate(graph.links) if link.name == f"{entity.name}.start")
            transforms[index] = edge_transform(entity, entity_frame(entity, units), dimension_columns)
    for link in graph.links:
        if link.relation is not None and link.relation.uncertain:
            link.relation = replace(
                link.relation,
                uncertain=tuple(
                    (attribute, dimension_columns[name], coefficients)
                    for attribute, name, coefficients in link.relation.uncertain
                ),
            )
    l_nominal = np.array([graph.links[p.link].nominal[p.slot] if p.link >= 0 else 0.0 for p in table.l])
    calibration = apply_calibrations(table, problem, l_nominal)
    chains = []
    for cycle in graph.cycles:
        closing_link = graph.links[cycle.closing_link]
        # T(Q) = origin^-1 · T_parent,child · tip^-1 for the closing link's own pose Q.
        constant = tuple(AffineParameter() for _ in range(6))
        steps = [(LinkTransform(constant, invert(closing_link.origin)), True)]
        steps += [(transforms[index], forward) for index, forward in cycle.path]
        steps += [(LinkTransform(constant, np.eye(4), invert(closing_link.tip)), True)]
        relation = closing_link.relation
        coordinates = None
        if relation is not None and relation.curvilinear:
            coordinates = surface_coordinates(relation, radius_columns.get(relation.surface))
        chains.append(Chain(steps, coordinates))
    return CompiledProblem(problem, graph, table, transforms, chains, robots, calibration, configurations)


def configured_robots(robot: RobotFrames, configurations: list[ConfigurationCopy]) -> list[RobotFrames]:
    """A robot's frames in each configuration that moves it, named ``ROBOT@CONFIGURATION``
    (the robot itself where none does)."""
    moved = [c for c in configurations if any(frame in c.frames for frame in robot.joint_frames)]
    return [
        RobotFrames(f"{robot.name}@{c.name}", c.frame(robot.base_frame), tuple(c.frame(f) for f in robot.joint_frames))
        for c in moved
    ] or [robot]


def compile_with_calibrations(problem, calibration, spelling: Spelling) -> CompiledProblem:
    """The compiled problem (:func:`compile_any`), with ``calibration`` (paths of ``bcad calibrate``
    results) added to its ``calibration:``, as ``--calibration`` adds them."""
    from bcad.model.problem import load

    calibration = () if calibration is None else calibration  # None: none, as the other arguments take it
    if isinstance(calibration, (str, Path)) or not isinstance(calibration, (list, tuple)):
        raise spelling.error("calibration", calibration, "a list of result paths")
    for path in calibration:
        if not isinstance(path, (str, Path)) or not str(path).strip():
            raise spelling.error("calibration", path, "a bcad calibrate result's path")
        trouble = file_trouble(Path(path))
        if trouble == "not found":
            raise InputError(Path(path), "no such file (a bcad calibrate result)")
        if trouble is not None:
            raise InputError(Path(path), f"{trouble}; expected a bcad calibrate result")
    if not calibration:
        return compile_any(problem)
    loaded = load(problem)
    # model_copy keeps the source document (error positions, relative paths)
    added = [str(Path(path).absolute()) for path in calibration]
    return compile_problem(loaded.model_copy(update={"calibration": [*loaded.calibration, *added]}))


def input_files(problem, compiled: CompiledProblem) -> list[Path]:
    """The files a run read that no output may replace: the problem's (where ``problem`` is its
    path) and its calibration results'."""
    given = [Path(problem)] if isinstance(problem, (str, Path)) else []
    return given + [Path(name) for name in compiled.calibration.files]


def compile_any(problem) -> CompiledProblem:
    """The probabilistic kinematic graph (Sect. 3.1 of the 2000 paper) of a compiled problem (as
    it is), a :class:`Problem`, a path or a mapping (:func:`bcad.model.problem.load`)."""
    from bcad.model.problem import load

    if isinstance(problem, CompiledProblem):
        return problem
    return compile_problem(load(problem))
