"""The other pictures: the kinematic graph (Fig. 4 of the 2000 paper), a relation's relaxed
constraint (Fig. 2), a corner plot of the closing links' posterior, and the reachable error set
of a clearance chain with its certified bound."""

from __future__ import annotations

import math
import textwrap
from typing import TYPE_CHECKING

import numpy as np

from bcad.compiler import CompiledProblem
from bcad.compiler.units import pose_scales
from bcad.model.pose import PARAMETERS, parameter_unit
from bcad.tempering import relaxed_log_indicator

if TYPE_CHECKING:
    from bcad.bayes.result import DesignResult
    from bcad.worstcase.result import MaxErrorResult


def circle_order(compiled: CompiledProblem) -> list[str]:
    """The frames in the order they sit on the circle of Fig. 4: along the spanning tree, depth
    first, starting at the first cycle's closing-link parent, walking the tree path of that cycle
    last at each of its frames and ending at its child, so that the closing link joins
    neighbours."""
    graph = compiled.graph
    closing = set(graph.closing_links)
    neighbours: dict[str, list[str]] = {name: [] for name in graph.frames}
    for index, link in enumerate(graph.links):
        if index not in closing:
            neighbours[link.parent].append(link.child)
            neighbours[link.child].append(link.parent)
    if graph.cycles:
        cycle = graph.cycles[0]
        link = graph.links[cycle.closing_link]
        path = [link.parent]
        for index, forward in cycle.path:
            step = graph.links[index]
            path.append(step.child if forward else step.parent)
    else:
        path = [graph.frames[0]]
    order: list[str] = []
    seen: set[str] = set(path)

    def subtree(name: str) -> None:
        """Every frame hanging off ``name`` away from the path, depth first (an explicit stack:
        a long chain would exceed Python's recursion limit)."""
        stack = [iter(neighbours[name])]
        while stack:
            for other in stack[-1]:
                if other not in seen:
                    seen.add(other)
                    order.append(other)
                    stack.append(iter(neighbours[other]))
                    break
            else:
                stack.pop()

    for k, name in enumerate(path):
        if k < len(path) - 1:
            order.append(name)
            subtree(name)
        else:  # the last frame of the path ends the circle: its subtrees come before it
            subtree(name)
            order.append(name)
    order += [name for name in graph.frames if name not in seen]
    return order


def _radial(angle: float) -> tuple[float, str]:
    """A text rotation along the radius at ``angle`` that reads left to right, and the
    horizontal alignment of text that starts at the circle and grows outwards."""
    degrees = math.degrees(angle) % 360.0
    return (degrees, "left") if degrees <= 90.0 or degrees >= 270.0 else (degrees - 180.0, "right")


def draw_graph(compiled: CompiledProblem, where) -> tuple[object, dict]:
    """Frames on a circle, links as arrows: the spanning tree solid, closing links dashed red,
    each link's name and status along the radius beside it (Fig. 4). The frames sit in
    :func:`circle_order`, so a cycle's closing link joins neighbours; frame names point
    outwards, link names inwards, so no two labels overlap."""
    from bcad.plot import pyplot

    plt = pyplot(where)
    graph = compiled.graph
    closing = set(graph.closing_links)
    frames = circle_order(compiled)
    count = len(frames)
    angle = {name: 2 * math.pi * k / count for k, name in enumerate(frames)}
    position = {name: np.array([math.cos(a), math.sin(a)]) for name, a in angle.items()}
    slot = {name: k for k, name in enumerate(frames)}
    figure, axes = plt.subplots(figsize=(11, 11))
    drawn = {"frames": frames, "links": {}, "texts": []}
    fontsize = 7 if count <= 40 else 5
    for index, link in enumerate(graph.links):
        start, end = position[link.parent], position[link.child]
        is_closing = index in closing
        style = {"color": "tab:red", "linestyle": "--"} if is_closing else {"color": "0.3", "linestyle": "-"}
        axes.annotate("", xy=end, xytext=start, arrowprops={"arrowstyle": "->", "linewidth": 1.2, **style})
        gap = (slot[link.child] - slot[link.parent]) % count
        label = f"{link.name} {link.status}"
        if gap in (1, count - 1):
            # between neighbours: along the radius, inside the circle, at the middle angle
            middle = angle[link.parent] + (math.pi / count if gap == 1 else -math.pi / count)
            rotation, align = _radial(middle)
            text = axes.text(
                0.93 * math.cos(middle),
                0.93 * math.sin(middle),
                label,
                fontsize=fontsize,
                rotation=rotation,
                rotation_mode="anchor",
                ha="right" if align == "left" else "left",
                va="center",
                color=style["color"],
            )
        else:
            text = axes.text(
                *(0.5 * start + 0.5 * end),
                label,
                fontsize=fontsize,
                ha="center",
                va="center",
                color=style["color"],
                bbox={"facecolor": "white", "edgecolor": "none", "pad": 0.5},
            )
        drawn["texts"].append(text)
        drawn["links"][link.name] = {"closing": is_closing, "status": link.status, "dashed": is_closing, "gap": gap}
    for name, point in position.items():
        axes.plot(*point, "o", color="tab:blue")
        rotation, align = _radial(angle[name])
        drawn["texts"].append(
            axes.text(
                *(point * 1.04),
                name,
                fontsize=fontsize + 1,
                rotation=rotation,
                rotation_mode="anchor",
                ha=align,
                va="center",
            )
        )
    axes.set_title(
        f"{compiled.problem.name}: kinematic graph ({len(frames)} frames, {len(graph.links)} links, "
        f"{len(graph.cycles)} cycle(s); closing links dashed red)"
    )
    axes.set_xlim(-1.5, 1.5)
    axes.set_ylim(-1.5, 1.5)
    axes.set_aspect("equal")
    axes.axis("off")
    return figure, drawn


def draw_relaxation(compiled: CompiledProblem, where, temperatures=(1.0, 0.3, 0.1, 0.03, 0.01)) -> tuple[object, dict]:
    """Fig. 2: the relaxed indicator exp(-(d/w)^2 / T) of an inequality (the first relation's
    first, of width w) against its signed distance d, at several temperatures, and T = 0."""
    from bcad.plot import pyplot

    plt = pyplot(where)
    relation = next(
        (link for link in compiled.graph.links if link.relation is not None and link.relation.inequality_count), None
    )
    if relation is None:
        from bcad.errors import InputError

        raise InputError(where, "no relation with inequalities to draw (relaxation needs one)")
    width = float(relation.relation.widths[0])
    d = np.linspace(-0.5 * width, 1.5 * width, 801)
    figure, axes = plt.subplots(figsize=(7, 4.5))
    curves = {}
    for temperature in temperatures:
        value = np.exp(relaxed_log_indicator(d, width, temperature))
        axes.plot(d, value, label=f"T = {temperature:g}")
        curves[temperature] = value
    exact = np.exp(relaxed_log_indicator(d, width, 0.0))
    axes.plot(d, exact, "k--", label="T = 0 (the indicator)")
    curves[0.0] = exact
    unit = compiled.problem.units.length
    axes.set_xlabel(f"signed distance d ({unit}; <= 0 satisfied)")
    axes.set_ylabel("f^T(d)")
    axes.set_title(
        f"{relation.name} ({relation.relation.kind}): relaxed constraint, width w = {width:.4g} {unit} (Sect. "
        "4.2.1, Fig. 2)"
    )
    axes.legend()
    return figure, {"distance": d, "curves": curves, "width": width}


def corner_refusal(name: str, poses: np.ndarray, finite: np.ndarray) -> str | None:
    """Why a corner plot of closing link ``name``'s samples ``poses`` (N, 6) cannot be drawn, or
    None: corner draws the samples and, in red, those the scores weigh (``finite`` log-weights),
    and each set needs more samples than the parameters that move."""
    moving = np.ptp(poses, axis=0) > 0
    if not moving.any():
        return (
            f"the pose of '{name}' is the same in all {len(poses)} samples: a corner plot needs "
            "spread; give more --samples (the default is 2e4)"
        )
    fewest = min(len(poses), int(finite.sum())) if finite.any() else len(poses)
    if fewest <= int(moving.sum()):
        return (
            f"a corner plot of {int(moving.sum())} parameters needs more samples than that, weighted "
            f"ones too ({len(poses)} given, {int(finite.sum())} of them weighted); give more --samples "
            "(the default is 2e4)"
        )
    return None


def draw_posterior(
    compiled: CompiledProblem, result: DesignResult, kept: dict, link_name: str | None, where
) -> tuple[object, dict]:
    """A corner plot of a closing link's six parameters from the posterior samples: unweighted
    (the prior's propagation) and weighted by the closing link's distributions, overlaid, with
    Table 2's numbers in the title."""
    from bcad.plot import pyplot, require

    pyplot(where)
    corner = require("corner", where)
    links = result.posterior.links
    name = link_name or next(iter(links))
    # the samples in the problem's units, as the labels and Table 2 (kept in internal units: rad)
    poses = kept[f"{name}/poses"] * pose_scales(compiled)
    log_weights = kept[f"{name}/log_weights"]
    finite = np.isfinite(log_weights)
    weights = np.zeros(len(poses))
    if finite.any():
        weights[finite] = np.exp(log_weights[finite] - log_weights[finite].max())
    moving = np.ptp(poses, axis=0) > 0
    refusal = corner_refusal(name, poses, finite)
    if refusal is not None:
        from bcad.errors import InputError

        raise InputError(where, refusal)
    unit_of = {p: parameter_unit(p, result.units) for p in PARAMETERS}
    names = [p for p, m in zip(PARAMETERS, moving) if m]
    labels = [f"{p} ({unit_of[p]})" for p in names]
    data = poses[:, moving]
    entry = links[name]
    weighted = weights[finite].sum() > 0
    # The weighted posterior is much narrower than the prior's propagation: its histograms get
    # bins of their own over its own range (weighted mean ± 4 weighted std, within the data).
    weighted_range = None
    if weighted:
        w = weights[finite] / weights[finite].sum()
        mean = w @ data[finite]
        std = np.sqrt(np.maximum(w @ (data[finite] - mean) ** 2, 0.0))
        low, high = data.min(axis=0), data.max(axis=0)
        weighted_range = [
            (max(lo, m - 4 * s), min(hi, m + 4 * s)) if s > 0 else (lo, hi)
            for lo, hi, m, s in zip(low, high, mean, std)
        ]
    import logging

    logging.disable(logging.WARNING)  # corner logs "too few points to create valid contours" for tight posteriors
    try:
        # The weighted layer first, the prior's second: the axes keep the prior's (wider) limits.
        figure = None
        if weighted:
            figure = corner.corner(
                data[finite],
                weights=weights[finite],
                range=weighted_range,
                bins=25,
                color="tab:red",
                hist_kwargs={"density": True},
                plot_datapoints=False,
                labels=labels,
            )
        figure = corner.corner(
            data, labels=labels, color="0.5", hist_kwargs={"density": True}, plot_datapoints=False, fig=figure
        )
    finally:
        logging.disable(logging.NOTSET)
    weighted_mean, weighted_std = entry.weighted.mean, entry.weighted.std
    if weighted_mean is None:  # no sample has a non-zero score (the result's warnings say so): grey alone
        title = (
            f"{name} ({result.posterior.samples} samples): grey, the prior's propagation (Table 2 mean, std); "
            "no sample has a non-zero score, so there is no weighted posterior to draw"
        )
    else:
        table = ", ".join(
            f"{p} {weighted_mean[k]:.3g}±{weighted_std[k]:.2g}" for k, p in enumerate(PARAMETERS) if moving[k]
        )
        effective = f", {entry.effective_samples:.0f} effective" if entry.effective_samples is not None else ""
        title = (
            f"{name} ({result.posterior.samples} samples{effective}): grey, the prior's propagation (Table 2 mean, "
            f"std); red, weighted by the scores (Table 2 w mean, w std)\nTable 2 w mean ± w std: {table}"
        )
    # A corner of one or two parameters is drawn at least MIN_CORNER_INCHES wide (its cells grow;
    # the text keeps its size); the title is wrapped to the figure's width, and the grid's top
    # leaves room for its lines and the diagonal's two-line titles (points: 1.25 lines per size)
    if figure.get_figwidth() < MIN_CORNER_INCHES:
        figure.set_size_inches(MIN_CORNER_INCHES, MIN_CORNER_INCHES)
    per_line = int(figure.get_figwidth() * 72 / (9 * 0.6))  # characters of 9 pt, about 0.6 em wide
    lines = [wrapped for part in title.split("\n") for wrapped in textwrap.wrap(part, per_line)]
    height = 72 * figure.get_figheight()
    above = 0.015 * height + len(lines) * 9 * 1.25 + 2 * 7 * 1.25 + 12  # offset, title, diagonal's titles, gap
    top = min(0.9, 1 - above / height)
    figure.subplots_adjust(top=top)
    figure.suptitle("\n".join(lines), fontsize=9, y=0.985)
    grid = np.array(figure.axes).reshape(len(names), len(names))
    for k, p in enumerate(names):
        j = PARAMETERS.index(p)
        prior = f"prior: {entry.mean[j]:.3g} ± {entry.std[j]:.2g}"
        grid[k, k].set_title(
            prior + f" {unit_of[p]}"
            if weighted_mean is None
            else f"w: {weighted_mean[j]:.3g} ± {weighted_std[j]:.2g} {unit_of[p]}\n{prior}",
            fontsize=7,
        )
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color="0.5", label="prior propagation (Table 2 mean, std)")]
    if weighted_mean is not None:
        handles.append(Line2D([], [], color="tab:red", label="weighted posterior (Table 2 w mean, w std)"))
    if len(names) == 1:  # no empty cell above the diagonal: the legend goes on the histogram
        grid[0, 0].legend(handles=handles, loc="upper right", fontsize=8, frameon=False)
    else:
        figure.legend(
            handles=handles,
            loc="upper right",
            bbox_to_anchor=(0.98, min(0.88, top)),
            fontsize=10 if len(names) > 2 else 8,  # two parameters: the empty cell is half the width
            frameon=False,
        )
    return figure, {"link": name, "title": title, "labels": labels, "weighted_range": weighted_range}


#: the least width and height of a corner plot, inches: one of one or two parameters would be
#: narrower than its title and legend
MIN_CORNER_INCHES = 7.0


#: SI prefixes for readable error figures: (power of ten, prefix) from the largest down
PREFIXES = ((0, ""), (-3, "m"), (-6, "µ"), (-9, "n"))
#: a unit's power of ten in metres or radians, for rescaling small errors
UNIT_POWER = {"m": 0, "cm": -2, "mm": -3, "rad": 0}


def readable_unit(largest: float, unit: str) -> tuple[float, str]:
    """(factor, label): values times factor are in the label's unit, the largest in [1, 1000)
    where a prefix allows it (4.8e-4 rad: 480 µrad; 2.9e-4 m: 290 µm). Degrees stay degrees."""
    if unit not in UNIT_POWER or not largest > 0:
        return 1.0, unit
    base = "rad" if unit == "rad" else "m"
    size = largest * 10.0 ** UNIT_POWER[unit]
    for power, prefix in PREFIXES:
        if size >= 10.0**power or power == PREFIXES[-1][0]:
            return 10.0 ** (UNIT_POWER[unit] - power), prefix + base
    return 1.0, unit


def draw_error(
    result: MaxErrorResult, rotation_vectors: np.ndarray, translations: np.ndarray, where
) -> tuple[object, dict]:
    """The reachable error set of a clearance chain: sampled end-effector errors projected on the
    plane of the worst sample and the direction of their largest other spread, with the certified
    first-order maximum (a feasible error: a star on the first axis, where its direction is
    unknown to the picture, and a circle) and the certified bound (dashed), in units that read
    (µrad, µm); with the exact model's certified bound where the result has it."""
    from bcad.plot import pyplot

    plt = pyplot(where)
    figure, grid = plt.subplots(2, 2, figsize=(11, 9.6), gridspec_kw={"height_ratios": [1.3, 1.0]})
    panels, histograms = grid[0], grid[1]
    drawn = {}
    for axes, histogram, kind, vectors, unit in (
        (panels[0], histograms[0], "rotation", rotation_vectors, result.units.angle),
        (panels[1], histograms[1], "translation", translations, result.units.length),
    ):
        entry = getattr(result, kind)
        factor, shown = readable_unit(max(float(entry.upper_bound), float(np.abs(vectors).max(initial=0.0))), unit)
        vectors = vectors * factor
        norms = np.linalg.norm(vectors, axis=1)
        worst = vectors[int(np.argmax(norms))]
        e1 = worst / (np.linalg.norm(worst) or 1.0)
        rest = vectors - np.outer(vectors @ e1, e1)
        _, _, vt = np.linalg.svd(rest - rest.mean(axis=0), full_matrices=False)
        e2 = vt[0] - (vt[0] @ e1) * e1
        e2 /= np.linalg.norm(e2) or 1.0
        projected = np.column_stack([vectors @ e1, vectors @ e2])
        axes.plot(
            projected[:, 0], projected[:, 1], ".", markersize=1, color="0.4", label=f"{len(vectors)} sampled clearances"
        )
        maximum, bound = float(entry.max) * factor, float(entry.upper_bound) * factor
        circle = np.linspace(0, 2 * math.pi, 400)
        axes.plot(
            maximum * np.cos(circle),
            maximum * np.sin(circle),
            color="tab:blue",
            linewidth=2.5,
            label=f"certified maximum {maximum:.4g} {shown}",
        )
        axes.plot(
            bound * np.cos(circle),
            bound * np.sin(circle),
            color="tab:red",
            linewidth=1,
            linestyle="--",
            label=f"first-order certified bound {bound:.4g} {shown} "
            f"(gap {(bound - maximum) / bound if bound else 0.0:.1e})",
        )
        axes.plot([maximum], [0.0], "*", color="tab:blue", markersize=12)
        axes.annotate(
            f"max {maximum:.4g}",
            (maximum, 0.0),
            xytext=(-10, 12),
            textcoords="offset points",
            ha="right",
            color="tab:blue",
            fontsize=8,
        )
        axes.set_aspect("equal")
        axes.tick_params(axis="x", labelrotation=30)
        axes.set_title(
            f"{kind} error: worst sample {norms.max():.4g} {shown}, certified max {maximum:.4g} {shown}", fontsize=9
        )
        axes.set_xlabel(f"along the worst sample ({shown})")
        axes.set_ylabel(f"across ({shown})")
        axes.legend(fontsize=7, loc="lower right")
        drawn[kind] = {
            "sampled_max": float(norms.max()) / factor,
            "bound": entry.upper_bound,
            "max": entry.max,
            "unit": shown,
            "factor": factor,
        }
        # The typical beside the worst: the sampled errors' histogram, their percentiles,
        # the first-order maximum and the certified bound of the exact model.
        histogram.hist(norms, bins=80, color="0.55")
        percentiles = {key: float(np.quantile(norms, q)) for key, q in (("p50", 0.5), ("p95", 0.95), ("p99.7", 0.997))}
        for (key, value), colour in zip(percentiles.items(), ("tab:green", "tab:orange", "tab:purple")):
            histogram.axvline(value, color=colour, linewidth=1.5, label=f"{key} {value:.4g} {shown}")
        histogram.axvline(maximum, color="tab:blue", linewidth=2.5, label=f"first-order maximum {maximum:.4g} {shown}")
        if entry.exact is not None and entry.exact.bound is not None:
            exact = float(entry.exact.bound) * factor
            histogram.axvline(
                exact,
                color="tab:red",
                linestyle="--",
                linewidth=1,
                label=f"certified bound, exact model {exact:.4g} {shown}",
            )
            drawn[kind]["exact_bound"] = entry.exact.bound
        histogram.set_xlabel(f"{kind} error ({shown})")
        histogram.set_ylabel("samples")
        histogram.legend(fontsize=7, loc="upper right")
        drawn[kind]["percentiles"] = {key: value / factor for key, value in percentiles.items()}
    figure.suptitle(f"{result.problem}: reachable end-effector errors and the certified bounds (Berger et al. 2010)")
    figure.tight_layout()
    return figure, drawn


def draw_residuals(model, whitened: np.ndarray, where) -> tuple[object, dict]:
    """A calibration's reprojection residuals: one panel per camera measurement, the image's
    outline, each detected point at its pixel and its residual (measured - predicted) drawn as
    an arrow magnified to be seen, one colour per view. Returns the figure and, per measurement,
    its pixels (rows, 2), residuals (rows, 2, px) and views (rows,)."""
    from bcad.plot import pyplot

    plt = pyplot(where)
    cameras = [(k, m) for k, m in enumerate(model.measurements) if m.camera is not None]
    figure, axes = plt.subplots(1, len(cameras), figsize=(6.5 * len(cameras), 5.5), squeeze=False)
    blocks = model.residual_blocks(whitened)
    drawn = {}
    for panel, (k, m) in zip(axes[0], cameras):
        residuals = blocks[k]
        _, views = np.unique(m.x_rows, axis=0, return_inverse=True)
        width, height = model.cameras[m.camera].image_size
        largest = float(np.max(np.abs(residuals))) or 1.0
        magnification = max(1.0, 0.04 * max(width, height) / largest)
        panel.plot([0, width, width, 0, 0], [0, 0, height, height, 0], color="0.3", linewidth=1)
        colours = plt.get_cmap("tab20")(views.ravel() % 20)
        panel.quiver(
            m.measured[:, 0],
            m.measured[:, 1],
            residuals[:, 0] * magnification,
            residuals[:, 1] * magnification,
            color=colours,
            angles="xy",
            scale_units="xy",
            scale=1,
            width=0.002,
        )
        panel.scatter(m.measured[:, 0], m.measured[:, 1], s=2, color=colours)
        panel.set_xlim(-0.02 * width, 1.02 * width)
        panel.set_ylim(1.02 * height, -0.02 * height)  # v grows downwards, as in the image
        panel.set_aspect("equal")
        rms = float(np.sqrt(np.mean(residuals**2)))
        panel.set_title(
            f"{m.name}: reprojection residuals x{magnification:.3g} (RMS {rms:.3g} px, {len(np.unique(views))} views)",
            fontsize=9,
        )
        panel.set_xlabel("u (px)")
        panel.set_ylabel("v (px)")
        drawn[m.name] = {"pixels": m.measured, "residuals": residuals, "views": views.ravel()}
    figure.tight_layout()
    return figure, drawn
