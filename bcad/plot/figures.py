"""The other pictures: the kinematic graph (Fig. 4 of the 2000 paper), a relation's relaxed
constraint (Fig. 2), a corner plot of the closing links' posterior, and the reachable error set
of a clearance chain with its certified bound."""

from __future__ import annotations

import math

import numpy as np

from bcad.compile import CompiledProblem
from bcad.model.pose import PARAMETERS
from bcad.tempering import relaxed_log_indicator


def draw_graph(compiled: CompiledProblem, where) -> tuple[object, dict]:
    """Frames on a circle, links as arrows: the spanning tree solid, closing links dashed red,
    each link's status at its middle (Fig. 4)."""
    from bcad.plot import pyplot

    plt = pyplot(where)
    graph = compiled.graph
    # Frames in depth-first order along the spanning tree: each chain's frames sit side by side.
    neighbours: dict[str, list[str]] = {name: [] for name in graph.frames}
    closing = set(graph.closing_links)
    for index, link in enumerate(graph.links):
        if index not in closing:
            neighbours[link.parent].append(link.child)
            neighbours[link.child].append(link.parent)
    frames, stack, seen = [], [graph.frames[0]], set()
    while stack:
        name = stack.pop()
        if name in seen:
            continue
        seen.add(name)
        frames.append(name)
        stack.extend(reversed([n for n in neighbours[name] if n not in seen]))
    frames += [name for name in graph.frames if name not in seen]
    angle = np.linspace(0, 2 * math.pi, len(frames), endpoint=False)
    position = {name: np.array([math.cos(a), math.sin(a)]) for name, a in zip(frames, angle)}
    figure, axes = plt.subplots(figsize=(9, 9))
    drawn = {"frames": frames, "links": {}}
    for index, link in enumerate(graph.links):
        start, end = position[link.parent], position[link.child]
        is_closing = index in closing
        style = {"color": "tab:red", "linestyle": "--"} if is_closing else {"color": "0.3", "linestyle": "-"}
        axes.annotate("", xy=end, xytext=start, arrowprops={"arrowstyle": "->", "linewidth": 1.2, **style})
        middle = (start + end) / 2
        axes.text(*middle, f"{link.name}\n{link.status}", fontsize=6, ha="center", color=style["color"])
        drawn["links"][link.name] = {"closing": is_closing, "status": link.status, "dashed": is_closing}
    for name, point in position.items():
        axes.plot(*point, "o", color="tab:blue")
        axes.text(*(point * 1.08), name, fontsize=7, ha="center", va="center")
    axes.set_title(f"{compiled.problem.name}: kinematic graph ({len(frames)} frames, {len(graph.links)} links, "
                   f"{len(graph.cycles)} cycle(s); closing links dashed)")
    axes.set_aspect("equal")
    axes.axis("off")
    return figure, drawn


def draw_relaxation(compiled: CompiledProblem, where, temperatures=(1.0, 0.3, 0.1, 0.03, 0.01)) -> tuple[object, dict]:
    """Fig. 2: the relaxed indicator exp(-(d/w)^2 / T) of an inequality (the first relation's
    first, of width w) against its signed distance d, at several temperatures, and T = 0."""
    from bcad.plot import pyplot

    plt = pyplot(where)
    relation = next((link for link in compiled.graph.links if link.relation is not None and link.relation.inequality_count), None)
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
    axes.set_title(f"{relation.name} ({relation.relation.kind}): relaxed constraint, width w = {width:.4g} {unit} (Sect. 4.2.1, Fig. 2)")
    axes.legend()
    return figure, {"distance": d, "curves": curves, "width": width}


def draw_posterior(compiled: CompiledProblem, document: dict, kept: dict, link_name: str | None, where) -> tuple[object, dict]:
    """A corner plot of a closing link's six parameters from the posterior samples: unweighted
    (the prior's propagation) and weighted by the closing link's distributions, overlaid, with
    Table 2's numbers in the title."""
    from bcad.plot import pyplot, require

    pyplot(where)
    corner = require("corner", where)
    links = document["posterior"]["links"]
    name = link_name or next(iter(links))
    poses = kept[f"{name}/poses"]
    log_weights = kept[f"{name}/log_weights"]
    finite = np.isfinite(log_weights)
    weights = np.zeros(len(poses))
    weights[finite] = np.exp(log_weights[finite] - log_weights[finite].max())
    moving = np.ptp(poses, axis=0) > 0
    labels = [p for p, m in zip(PARAMETERS, moving) if m]
    data = poses[:, moving]
    import logging

    logging.disable(logging.WARNING)  # corner logs "too few points to create valid contours" for tight posteriors
    try:
        figure = corner.corner(data, labels=labels, color="0.5", hist_kwargs={"density": True}, plot_datapoints=False)
        if weights[finite].sum() > 0:
            corner.corner(data[finite], weights=weights[finite], fig=figure, color="tab:red", hist_kwargs={"density": True},
                          plot_datapoints=False)
    finally:
        logging.disable(logging.NOTSET)
    entry = links[name]
    table = ", ".join(f"{p} {entry['weighted']['mean'][k]:.3g}±{entry['weighted']['std'][k]:.2g}" for k, p in enumerate(PARAMETERS) if moving[k])
    title = f"{name}: grey prior propagation, red weighted posterior (Table 2: {table})"
    figure.suptitle(title, fontsize=8)
    return figure, {"link": name, "title": title, "labels": labels}


def draw_error(document: dict, rotation_vectors: np.ndarray, translations: np.ndarray, where) -> tuple[object, dict]:
    """The reachable error set of a clearance chain: sampled end-effector errors projected on the
    plane of the worst sample and the direction of their largest other spread, with the certified
    first-order maximum and bound as circles (rotation and translation side by side)."""
    from bcad.plot import pyplot

    plt = pyplot(where)
    figure, panels = plt.subplots(1, 2, figsize=(11, 5))
    drawn = {}
    units = document["units"]
    for axes, kind, vectors, unit in ((panels[0], "rotation", rotation_vectors, units["angle"]),
                                      (panels[1], "translation", translations, units["length"])):
        norms = np.linalg.norm(vectors, axis=1)
        worst = vectors[int(np.argmax(norms))]
        e1 = worst / (np.linalg.norm(worst) or 1.0)
        rest = vectors - np.outer(vectors @ e1, e1)
        _, _, vt = np.linalg.svd(rest - rest.mean(axis=0), full_matrices=False)
        e2 = vt[0] - (vt[0] @ e1) * e1
        e2 /= np.linalg.norm(e2) or 1.0
        projected = np.column_stack([vectors @ e1, vectors @ e2])
        axes.plot(projected[:, 0], projected[:, 1], ".", markersize=1, color="0.4", label=f"{len(vectors)} sampled clearances")
        entry = document[kind]
        circle = np.linspace(0, 2 * math.pi, 400)
        for value, style, label in ((entry["max"], "tab:blue", "certified maximum"), (entry["upper_bound"], "tab:red", "certified bound")):
            axes.plot(value * np.cos(circle), value * np.sin(circle), color=style, linewidth=1, label=f"{label} {value:.4g} {unit}")
        axes.set_aspect("equal")
        axes.tick_params(axis="x", labelrotation=30)
        axes.set_title(f"{kind} error: worst sample {norms.max():.4g} {unit}")
        axes.set_xlabel(f"along the worst sample ({unit})")
        axes.set_ylabel(f"across ({unit})")
        axes.legend(fontsize=7, loc="lower right")
        drawn[kind] = {"sampled_max": float(norms.max()), "bound": entry["upper_bound"], "max": entry["max"]}
    figure.suptitle(f"{document['problem']}: reachable end-effector errors and the certified bounds (Berger et al. 2010)")
    figure.tight_layout()
    return figure, drawn
