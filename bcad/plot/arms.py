"""The cell at a solution (Fig. 5 of the 2000 paper): robots, entities, frames, and the 95 %
ellipsoids of the closing links' positions from the posterior samples."""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field

import numpy as np

from bcad.compiler import CompiledProblem
from bcad.compiler.calibration import nominal_samples
from bcad.compiler.dimensions import nominal_radius
from bcad.compiler.problem import entity_frame
from bcad.model.entities import nominal

#: sqrt of the chi-square 95 % quantile with 3 degrees of freedom: the ellipsoid's scale
CHI3_95 = 2.7954834829151074


@dataclass
class ArmsDrawing:
    """What an arms picture shows, in the problem's length unit (world = the first frame)."""

    segments: dict[str, np.ndarray] = field(default_factory=dict)  # robot -> (k, 3) joint positions, base to tip
    axes: dict[str, np.ndarray] = field(default_factory=dict)  # robot/joint -> (2, 3) axis arrow
    entities: dict[str, np.ndarray] = field(default_factory=dict)  # entity -> points drawn
    frames: dict[str, np.ndarray] = field(default_factory=dict)  # frame -> 4 x 4
    ellipsoids: dict[str, tuple[np.ndarray, np.ndarray, float]] = field(
        default_factory=dict
    )  # link -> (centre, covariance, magnification)
    meshes: dict[str, np.ndarray] = field(default_factory=dict)  # ROBOT/LINK:file -> triangles (k, 3, 3) in world
    labels: list[str] = field(default_factory=list)
    prior_ellipsoids: dict[str, tuple[np.ndarray, np.ndarray, float]] = field(
        default_factory=dict
    )  # the prior's propagation
    limits: np.ndarray | None = None  # (2, 3): the panel's lower and upper corner, the same for every panel
    inset: dict | None = None  # the contact inset: link, and each ellipse's outline in the parent frame
    #: link -> (2, 3) its parent and child frames' origins: the cell's links but the closing ones
    links: dict[str, np.ndarray] = field(default_factory=dict)


def robot_chains(
    compiled: CompiledProblem, x: np.ndarray
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Per robot the positions of its base and of every actuated joint's frame (nominal L), the
    joints' axes in world, and every frame's transform (a calibrated L at its MAP)."""
    transforms = {name: t.matrices()[0] for name, t in compiled.frame_transforms(x, nominal_samples(compiled)).items()}
    chains, axes = {}, {}
    for robot in compiled.robots:
        names = [robot.base_frame] + list(robot.joint_frames)
        chains[robot.name] = np.array([transforms[name][:3, 3] for name in names])
        # A configured robot ROBOT@C has the motion links ROBOT/JOINT@C.
        base, _, configuration = robot.name.partition("@")
        for link in compiled.graph.links:
            if (
                link.joint is None
                or not link.joint[0].startswith(base + "/")
                or configuration
                and not link.joint[0].endswith("@" + configuration)
            ):
                continue
            R = transforms[link.child][:3, :3] @ link.tip[:3, :3].T
            k = link.joint_slot % 3
            origin = transforms[link.child][:3, 3]
            axes[link.name] = np.array([origin, R[:, k]])
    return chains, axes, transforms


def _sphere_points(centre, radius, n=16):
    u, v = np.meshgrid(np.linspace(0, 2 * math.pi, n), np.linspace(0, math.pi, n // 2))
    return centre + radius * np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], axis=-1)


def entity_outline(entity, T: np.ndarray, units) -> np.ndarray:
    """Points (k, 3) that outline an entity in world coordinates, given its host frame T."""
    E = T @ entity_frame(entity, units)
    if entity.type == "face":
        polygon = np.array(entity.polygon() + [entity.polygon()[0]])
        local = np.column_stack([polygon, np.zeros(len(polygon)), np.ones(len(polygon))])
    elif entity.type == "point":
        local = np.array([[0.0, 0.0, 0.0, 1.0]])
    elif entity.type == "edge":
        length = float(np.linalg.norm(np.subtract(entity.end, entity.start)))
        local = np.array([[0.0, 0.0, 0.0, 1.0], [length, 0.0, 0.0, 1.0]])
    elif entity.type == "sphere":
        return _sphere_points(E[:3, 3], nominal_radius(entity)).reshape(-1, 3)
    elif entity.type == "target":
        points = np.array(entity.corner_points())
        local = np.column_stack([points, np.ones(len(points))])
    else:  # cylinder: the two rims and four lines
        angles = np.linspace(0, 2 * math.pi, 25)
        radius = nominal_radius(entity)
        rim = np.column_stack([radius * np.cos(angles), radius * np.sin(angles)])
        bottom = np.column_stack([rim, np.zeros(len(rim)), np.ones(len(rim))])
        top = np.column_stack([rim, np.full(len(rim), entity.nominal_length), np.ones(len(rim))])
        local = np.vstack([bottom, top])
    return (local @ E.T)[:, :3]


def camera_frustum(compiled: CompiledProblem, camera, T: np.ndarray, depth: float) -> np.ndarray:
    """A polyline (k, 3) of a camera's field of view in world coordinates, given its optical
    frame T: the rays through the image's four corners out to ``depth`` along z (the intrinsics at
    their means, distortion left out), and the rectangle they end on."""
    from bcad.model.camera_info import read_camera_info

    info = None
    if camera.camera_info is not None:
        info = read_camera_info(compiled.problem.source.relative_path(camera.camera_info), camera.name)
    values = {name: nominal(value) for name, value in camera.values(info).items()}
    width, height = camera.size(info)
    corners = [(0.0, 0.0), (width, 0.0), (width, height), (0.0, height)]
    rays = [
        np.array([(u - values["cx"]) / values["fx"], (v - values["cy"]) / values["fy"], 1.0]) * depth
        for u, v in corners
    ]
    local = [
        np.zeros(3),
        rays[0],
        rays[1],
        np.zeros(3),
        rays[2],
        rays[3],
        np.zeros(3),
        rays[0],
        rays[3],
        rays[2],
        rays[1],
    ]
    return np.array(local) @ T[:3, :3].T + T[:3, 3]


def _moments(t: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mean = np.average(t, axis=0, weights=w)
    centred = t - mean
    return mean, (w[:, None] * centred).T @ centred / w.sum()


def closing_ellipsoids(compiled: CompiledProblem, kept: dict[str, np.ndarray], transforms) -> dict:
    """Per closing link, the position of its child frame from the posterior samples, as
    ``{"weighted": (centre, covariance), "prior": (centre, covariance), "local": {...}}``:
    weighted by the closing link's scores (the posterior) and unweighted (the prior's
    propagation), in world coordinates, and ``local`` the same in the link's parent frame."""
    out = {}
    for cycle in compiled.graph.cycles:
        link = compiled.graph.links[cycle.closing_link]
        key = f"{link.name}/poses"
        if key not in kept or getattr(link.relation, "spherical", False):
            continue
        poses = kept[key]
        log_weights = kept[f"{link.name}/log_weights"]
        finite = np.isfinite(log_weights)
        if not finite.any():
            continue
        weights = np.exp(log_weights[finite] - log_weights[finite].max())
        parent = transforms[link.parent] @ link.origin
        R = parent[:3, :3]
        entry = {"local": {}}
        # The prior's propagation is every sample (Table 2's mean and std), the posterior the
        # samples weighted by the scores (those a relation rules out weigh 0).
        for name, t, w in (("weighted", poses[finite, :3], weights), ("prior", poses[:, :3], np.ones(len(poses)))):
            mean, covariance = _moments(t, w)
            entry["local"][name] = (mean, covariance)
            entry[name] = ((parent @ np.append(mean, 1.0))[:3], R @ covariance @ R.T)
        out[link.name] = entry
    return out


def _ellipsoid_mesh(centre, covariance, magnification, n=20):
    values, vectors = np.linalg.eigh(covariance)
    radii = CHI3_95 * np.sqrt(np.maximum(values, 0.0)) * magnification
    sphere = _sphere_points(np.zeros(3), 1.0, n)
    return centre + (sphere * radii) @ vectors.T


def _ellipse_outline(mean: np.ndarray, covariance: np.ndarray, scale: float, n: int = 100) -> np.ndarray:
    """Points (n, 2) of the ellipse {mean + scale * L u, |u| = 1}, L L^T = covariance."""
    values, vectors = np.linalg.eigh(covariance)
    angles = np.linspace(0, 2 * math.pi, n)
    circle = np.column_stack([np.cos(angles), np.sin(angles)])
    return mean + (circle * scale * np.sqrt(np.maximum(values, 0.0))) @ vectors.T


#: sqrt of the chi-square 95 % quantile with 2 degrees of freedom: the inset's ellipses
CHI2_95 = 2.4477468306808166
WEIGHTED_COLOUR, PRIOR_COLOUR, LINK_COLOUR = "tab:red", "0.45", "0.6"


def _largest_radius(covariance: np.ndarray) -> float:
    return CHI3_95 * math.sqrt(max(float(np.linalg.eigvalsh(covariance).max()), 1e-300))


def _legend_handles(robots: bool) -> list:
    from matplotlib.lines import Line2D

    robot = Line2D(
        [], [], color="tab:blue", marker="o", linewidth=3, markersize=4, label="robot: base and joint frames"
    )
    return [robot] * robots + [
        Line2D([], [], color=LINK_COLOUR, linewidth=1.5, label="links: parent to child frame (closing links aside)"),
        Line2D([], [], color="tab:orange", linewidth=1.5, label="joint axes"),
        Line2D([], [], color="tab:green", linewidth=1, label="entities (faces, points, ...)"),
        Line2D([], [], color="k", linewidth=1, label="frames (x red, y green, z blue)"),
        Line2D([], [], color=WEIGHTED_COLOUR, linewidth=1, label="closing link, weighted posterior: 95 % ellipsoid"),
        Line2D(
            [],
            [],
            color=PRIOR_COLOUR,
            linewidth=1,
            linestyle=":",
            label="closing link, prior propagation: 95 % ellipsoid",
        ),
    ]


def draw_arms(
    compiled: CompiledProblem, solutions: list[tuple[str, np.ndarray, dict]], where
) -> tuple[object, list[ArmsDrawing]]:
    """One 3-D panel per (title, X, kept samples): the cell as the solution places it (Fig. 5).

    Every panel has the same limits and the same ellipsoid magnification, so that two solutions
    compare at a glance; each closing link's position is drawn twice, weighted by its scores
    (the posterior, red) and unweighted (the prior's propagation, grey), and an inset shows both
    at true scale in the link's parent frame (the contact)."""
    from bcad.plot import pyplot

    plt = pyplot(where)
    units = compiled.problem.units
    figure = plt.figure(figsize=(6.5 * len(solutions), 7.0))
    drawings = []
    meshes = robot_meshes(compiled)  # read once, placed in each panel
    # The panels' common frame: one cube holding every panel's scene, one magnification.
    placed = []
    for title, x, kept in solutions:
        chains, joint_axes, transforms = robot_chains(compiled, x)
        scene = np.vstack(list(chains.values()) + [T[:3, 3][None] for T in transforms.values()])
        placed.append((chains, joint_axes, transforms, scene, closing_ellipsoids(compiled, kept, transforms)))
    everything = np.vstack([entry[3] for entry in placed])
    low, high = everything.min(axis=0), everything.max(axis=0)
    size = float(np.max(high - low)) or 1.0
    middle = (low + high) / 2
    largest = max(
        [_largest_radius(e[kind][1]) for entry in placed for e in entry[4].values() for kind in ("weighted", "prior")]
        or [1e-300]
    )
    magnification = max(1.0, 0.05 * size / largest)
    for index, ((title, x, kept), (chains, joint_axes, transforms, scene, ellipsoids)) in enumerate(
        zip(solutions, placed)
    ):
        axes3d = figure.add_subplot(1, len(solutions), index + 1, projection="3d")
        drawing = ArmsDrawing()
        # Every link but the closing ones, its parent frame's origin to its child's: a cell of
        # plain links (no robot) is drawn as the chain it is, not as scattered frames.
        closing = {cycle.closing_link for cycle in compiled.graph.cycles}
        for index, link in enumerate(compiled.graph.links):
            if index in closing or link.parent not in transforms or link.child not in transforms:
                continue
            points = np.array([transforms[link.parent][:3, 3], transforms[link.child][:3, 3]])
            axes3d.plot(*points.T, color=LINK_COLOUR, linewidth=1.5)
            drawing.links[link.name] = points
        for name, points in chains.items():
            axes3d.plot(*points.T, "-o", color="tab:blue", linewidth=3, markersize=4)
            axes3d.text(*points[0], name, color="tab:blue")
            drawing.segments[name] = points
            drawing.labels.append(name)
        for name, (frame, local) in meshes.items():
            if frame not in transforms:
                continue
            from mpl_toolkits.mplot3d.art3d import Poly3DCollection

            T = transforms[frame]
            triangles = local @ T[:3, :3].T + T[:3, 3]
            axes3d.add_collection3d(Poly3DCollection(triangles, facecolor="0.75", edgecolor="none", alpha=0.35))
            drawing.meshes[name] = triangles
        for name, (origin, direction) in joint_axes.items():
            tip = origin + 0.06 * size * direction
            axes3d.plot(*np.array([origin, tip]).T, color="tab:orange", linewidth=1.5)
            drawing.axes[name] = np.array([origin, tip])
        for entity, host in ((e, frame) for e in compiled.problem.entities for frame in compiled.copies_of(e.frame)):
            points = entity_outline(entity, transforms[host], units)
            style = {"point": "o", "sphere": ".", "target": "."}.get(entity.type, "-")
            axes3d.plot(*points.T, style, color="tab:green", markersize=3, linewidth=1)
            label = entity.name + host[len(entity.frame) :]  # a configuration's copy: NAME@C
            axes3d.text(*points[0], label, color="tab:green", fontsize=7)
            drawing.entities[label] = points
            drawing.labels.append(label)
        for camera in compiled.problem.cameras:
            points = camera_frustum(compiled, camera, transforms[camera.frame], 0.15 * size)
            label = f"{camera.name} (camera)"
            axes3d.plot(*points.T, "-", color="tab:purple", linewidth=1)
            axes3d.text(*points[0], label, color="tab:purple", fontsize=7)
            drawing.entities[label] = points
            drawing.labels.append(label)
        # Each frame's axes, one collection per colour (thousands of frames draw in one call
        # each); names only where they can be read (MAX_FRAME_LABELS frames at most).
        from mpl_toolkits.mplot3d.art3d import Line3DCollection

        frames = compiled.problem.frames
        triads = {k: [] for k in range(3)}
        for name in frames:
            T = transforms[name]
            for k in range(3):
                triads[k].append([T[:3, 3], T[:3, 3] + 0.04 * size * T[:3, k]])
            if len(frames) <= MAX_FRAME_LABELS:
                axes3d.text(*T[:3, 3], name, fontsize=6, color="0.25")
                drawing.labels.append(name)
            drawing.frames[name] = T
        for k, colour in enumerate(("r", "g", "b")):
            if triads[k]:
                axes3d.add_collection3d(Line3DCollection(np.array(triads[k]), colors=colour, linewidths=1))
        for link_name, entry in ellipsoids.items():
            for kind, colour, style in (("prior", PRIOR_COLOUR, ":"), ("weighted", WEIGHTED_COLOUR, "-")):
                centre, covariance = entry[kind]
                mesh = _ellipsoid_mesh(centre, covariance, magnification)
                axes3d.plot_wireframe(
                    mesh[..., 0], mesh[..., 1], mesh[..., 2], color=colour, linewidth=0.5, linestyle=style
                )
            centre, covariance = entry["weighted"]
            label = f"{link_name}: 95 % ellipsoid x{magnification:.3g}"
            axes3d.text(*centre, label, color=WEIGHTED_COLOUR, fontsize=7)
            drawing.ellipsoids[link_name] = (centre, covariance, magnification)
            drawing.prior_ellipsoids[link_name] = (entry["prior"][0], entry["prior"][1], magnification)
            drawing.labels.append(label)
        for setter, k in ((axes3d.set_xlim, 0), (axes3d.set_ylim, 1), (axes3d.set_zlim, 2)):
            setter(middle[k] - size / 2, middle[k] + size / 2)
        drawing.limits = np.array([middle - size / 2, middle + size / 2])
        axes3d.set_xlabel(f"x ({units.length})")
        axes3d.set_ylabel(f"y ({units.length})")
        axes3d.set_zlabel(f"z ({units.length})")
        axes3d.set_title(title, fontsize=8)
        if ellipsoids:
            drawing.inset = _contact_inset(axes3d, ellipsoids, units)
        drawings.append(drawing)
    # three columns of legend fit two panels' width; one panel's takes two (three rows)
    single = len(solutions) == 1
    handles = _legend_handles(bool(compiled.robots))
    figure.legend(handles=handles, loc="lower center", ncol=2 if single else 3, fontsize=7, frameon=False)
    # (tight_layout does not see 3-D axes' titles: room for three title lines and the legend)
    figure.subplots_adjust(left=0.0, right=0.97, top=0.86, bottom=0.13 if single else 0.1, wspace=0.05)
    return figure, drawings


def _contact_inset(axes3d, ellipsoids: dict, units) -> dict:
    """The first closing link's position in its parent frame (x, y: the contact plane of a face
    on a face), both 95 % ellipses at true scale: what the magnified ellipsoids stand for."""
    link_name, entry = next(iter(ellipsoids.items()))
    inset = axes3d.inset_axes([0.02, 0.02, 0.3, 0.3], zorder=10)
    drawn = {"link": link_name}
    for kind, colour, style in (("prior", PRIOR_COLOUR, ":"), ("weighted", WEIGHTED_COLOUR, "-")):
        mean, covariance = entry["local"][kind]
        outline = _ellipse_outline(mean[:2], covariance[:2, :2], CHI2_95)
        inset.plot(outline[:, 0], outline[:, 1], color=colour, linestyle=style, linewidth=1)
        inset.plot(*mean[:2], "+", color=colour)
        drawn[kind] = outline
    inset.set_aspect("equal", adjustable="datalim")
    inset.tick_params(labelsize=5)
    inset.set_title(f"{link_name} in its parent frame, true scale ({units.length})", fontsize=6)
    inset.set_facecolor("white")
    return drawn


#: frames whose names are written in the picture, at most (beyond, only their axes are drawn)
MAX_FRAME_LABELS = 200
#: faces of one mesh drawn at most (every k-th face beyond: a picture, not a render)
MAX_MESH_FACES = 3000
#: the largest mesh file read for a picture (larger ones are drawn as segments)
MAX_MESH_BYTES = 50_000_000
#: mesh formats read for a picture, each whole in its file: no archive (a zip of a few MB can hold
#: an OBJ of gigabytes) and no XML (Collada's .dae), and no file besides it (an OBJ's materials
#: and textures are not read); other meshes are drawn as segments
MESH_TYPES = (".stl", ".obj", ".ply", ".off", ".glb")


def robot_meshes(compiled: CompiledProblem) -> dict[str, tuple[str, np.ndarray]]:
    """The visual meshes of the URDF robots, where the URDF names them and the files are found
    (and trimesh is installed), read once: by ROBOT/LINK:FILE, the link's frame and the
    triangles (k, 3, 3) in that frame (the visual's origin and scale applied)."""
    try:
        import trimesh
    except ImportError:
        return {}
    from bcad.compiler.units import urdf_length_scale
    from bcad.compiler.urdf import UrdfText, attribute_floats, urdf_text
    from bcad.io import record_input
    from bcad.kinematics.se3 import pose_to_matrix
    from bcad.model.source import check_confined

    length = urdf_length_scale(compiled.problem.units)
    doc = compiled.problem.source
    out = {}
    for robot in compiled.problem.robots:
        if robot.urdf is None:
            continue
        path = doc.relative_path(robot.urdf)
        source = UrdfText(path, urdf_text(path, robot.xacro_args))
        root = source.parse()
        for link in root.iter("link"):
            frame = f"{robot.name}/{link.get('name')}"
            for visual in link.findall("visual"):
                mesh = visual.find("geometry/mesh")
                if mesh is None:
                    continue
                filename = mesh.get("filename", "")
                if filename.startswith("file://"):
                    filename = filename[len("file://") :]
                if "://" in filename:
                    continue  # package:// and the like: not resolvable without ROS
                file = (path.parent / filename) if not filename.startswith("/") else type(path)(filename)
                kind = file.suffix.lower()
                if kind not in MESH_TYPES or not file.is_file() or file.stat().st_size > MAX_MESH_BYTES:
                    continue  # missing, too large or of another kind: the segments stay the picture
                check_confined(file, "a mesh")
                record_input(file)  # an input: no picture may replace it
                try:
                    # from its bytes, of the kind its name says: trimesh finds no other file to read
                    with open(file, "rb") as stream:  # (the limit read, not more, should it have grown)
                        data = stream.read(MAX_MESH_BYTES + 1)
                    if len(data) > MAX_MESH_BYTES:
                        continue
                    loaded = trimesh.load(io.BytesIO(data), file_type=kind[1:], force="mesh")
                except Exception:  # an unreadable mesh: the segments stay the picture
                    continue
                origin = visual.find("origin")
                xyz = attribute_floats(origin, "xyz", "0 0 0", source)
                rpy = attribute_floats(origin, "rpy", "0 0 0", source)
                scale = attribute_floats(mesh, "scale", "1 1 1", source)
                T = pose_to_matrix(np.array([c * length for c in xyz] + rpy))
                vertices = np.asarray(loaded.vertices, dtype=float) * np.asarray(scale) * length
                faces = np.asarray(loaded.faces)
                step = max(1, len(faces) // MAX_MESH_FACES)
                out[f"{frame}:{file.name}"] = (frame, vertices[faces[::step]] @ T[:3, :3].T + T[:3, 3])
    return out
