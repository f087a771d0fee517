"""Human-readable renderings of compiled problems: rich tables and trees, DOT."""

from __future__ import annotations

from typing import TYPE_CHECKING

from rich.table import Table
from rich.text import Text
from rich.tree import Tree

from bcad.errors import printable
from bcad.model.pose import LENGTH_NAMES, parameter_unit
from bcad.tables import WholeTable

if TYPE_CHECKING:
    from bcad.bayes.result import DesignResult
    from bcad.compiler import CompiledProblem
    from bcad.worstcase.result import MaxErrorResult


def _text(text: str, style: str = "") -> Text:
    """A table's text: a name from a file with the characters a terminal acts on as escapes
    (:func:`bcad.errors.printable`)."""
    return Text(printable(text), style=style)


STAT_LABELS = {
    "integration_dim": "Integration space dimension",
    "optimization_dim": "Optimization space dimension",
    "cycles": "Number of cycles",
    "frames": "Number of frames",
    "links": "Number of links",
    "inequality_constraints": "Number of inequality constraints",
}


def _quantities_table(title: str, rows: list[tuple[str, int]]) -> WholeTable:
    """A table of quantities and their values under ``title``, as wide as its title (not wrapped
    in two)."""
    shown = _text(title)
    table = Table(title=shown, min_width=min(len(shown), 100))
    table.add_column("Quantity")
    table.add_column("Value", justify="right")
    for label, value in rows:
        table.add_row(label, str(value))
    return WholeTable(table)


def stats_table(compiled: CompiledProblem) -> WholeTable:
    """Table 1 of the 2000 paper for this problem."""
    stats = compiled.stats.as_dict()
    rows = [(label, stats[key]) for key, label in STAT_LABELS.items()]
    cameras = compiled.problem.cameras
    if cameras:
        # a camera's intrinsics and distortion given as distributions: L that calibrate identifies
        identified = sum(
            not isinstance(value, (int, float)) for camera in cameras for value in camera.values().values()
        )
        rows += [("Number of cameras", len(cameras)), ("Camera parameters with a distribution (L)", identified)]
    return _quantities_table(f"{compiled.problem.name}: problem statistics (Table 1)", rows)


def chain_stats_table(name: str, stats: dict) -> WholeTable:
    """A clearance problem's statistics: its chain's joints and the clearances it gives them."""
    rows = [("Number of joints", stats["joints"]), ("Clearance bounds (nonzero)", stats["clearances"])]
    return _quantities_table(f"{name}: clearance problem statistics", rows)


def _link_label(compiled: CompiledProblem, index: int, forward: bool = True) -> Text:
    """A link's name (bold), status, relation and direction; user text is never read as markup."""
    link = compiled.graph.links[index]
    arrow = "" if forward else " (used backward)"
    relation = f" [{link.relation.kind}]" if link.relation is not None else ""
    return Text.assemble((printable(link.name), "bold"), f" {link.status}{relation}{arrow}")


def graph_tree(compiled: CompiledProblem) -> Tree:
    """The spanning tree from the root frame, then each cycle with its closing link."""
    graph = compiled.graph
    children: dict[str, list[tuple[str, int, bool]]] = {frame: [] for frame in graph.frames}
    for frame, (index, forward) in graph.tree_parent.items():
        link = graph.links[index]
        parent = link.parent if forward else link.child
        children[parent].append((frame, index, forward))

    root = Tree(_text(compiled.problem.name, style="bold"))
    tree = root.add(Text.assemble("spanning tree from frame ", (printable(graph.root), "cyan")))

    # grown from a stack, not by recursion: a serial chain of thousands of links is as deep
    growing = [(tree, graph.root)]
    while growing:
        node, frame = growing.pop()
        added = []
        for child, index, forward in children[frame]:
            label = Text.assemble((printable(child), "cyan"), " via ", _link_label(compiled, index, forward))
            added.append((node.add(label), child))
        growing.extend(reversed(added))
    cycles = root.add(f"{len(graph.cycles)} cycle(s)")
    for number, cycle in enumerate(graph.cycles, start=1):
        link = graph.links[cycle.closing_link]
        node = cycles.add(
            Text.assemble(
                f"cycle {number}: closing link ",
                _link_label(compiled, cycle.closing_link),
                " from ",
                (printable(link.parent), "cyan"),
                " to ",
                (printable(link.child), "cyan"),
            )
        )
        for index, forward in cycle.path:
            node.add(_link_label(compiled, index, forward))
    return root


def _quote(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def graph_dot(compiled: CompiledProblem) -> str:
    """Graphviz DOT: frames as nodes, tree links solid, closing links dashed red."""
    graph = compiled.graph
    closing = set(graph.closing_links)
    lines = [f"digraph {_quote(compiled.problem.name)} {{", "  rankdir=LR;", "  node [shape=box];"]
    for frame in graph.frames:
        lines.append(f"  {_quote(frame)};")
    for index, link in enumerate(graph.links):
        style = " style=dashed color=red" if index in closing else ""
        # Graphviz's line break is the two characters \n inside the quoted label.
        label = _quote(link.name)[:-1] + "\\n" + link.status + '"'
        lines.append(f"  {_quote(link.parent)} -> {_quote(link.child)} [label={label}{style}];")
    lines.append("}")
    return "\n".join(lines) + "\n"


#: a figure below this share of the largest of its kind in its table (lengths, angles) is round-off
#: (3e-17 beside 0.7): shown as 0
ROUND_OFF = 1e-9
#: ... and a figure below this, in the table's unit, whatever the other figures of its kind: a
#: rotation-only closure's lengths are all round-off (1e-17 m), with nothing of their kind beside
#: them to show it (double precision leaves about 1e-13 of a 1000 mm coordinate)
ROUND_OFF_FLOOR = 1e-12


def _figure(value: float | None, digits: int = 4, round_off: float = 0.0) -> str:
    """A figure with ``digits`` decimals; one whose decimals would keep a single significant digit
    or none (a 0.12 mm or a 10 um std in metres) with two significant digits instead (0.00012,
    1.2e-5: the exponent without its padding, as wide as four decimals), unless it is below
    ``round_off``, the table's noise."""
    if value is None:
        return "-"
    if abs(value) <= round_off:
        value = 0.0  # (no sign: -3e-13 is no more negative than it is anything)
    if round_off < abs(value) and abs(round(value, digits)) < 10.0 ** (1 - digits):
        mantissa, _, exponent = f"{value:#.2g}".partition("e")
        return f"{mantissa}e{int(exponent)}" if exponent else mantissa
    return f"{value:.{digits}f}"


def _round_off(links) -> dict[bool, float]:
    """The round-offs of a Table 2, of its lengths (key True) and of its angles (False): ROUND_OFF
    times the largest figure of each kind, at least ROUND_OFF_FLOOR. One for both read a 1e-6 rad
    standard error beside a 1565 mm mean as round-off."""
    largest = {True: 0.0, False: 0.0}
    for link in links:
        for _, values in _statistics(link):
            for param, value in zip(link.params, values or ()):
                if value is not None:
                    largest[param in LENGTH_NAMES] = max(largest[param in LENGTH_NAMES], abs(value))
    return {kind: max(ROUND_OFF * value, ROUND_OFF_FLOOR) for kind, value in largest.items()}


def posterior_table(result: DesignResult) -> WholeTable:
    """The closing links' posterior in the style of Table 2 of the 2000 paper, with standard errors;
    where its six parameter columns do not fit whole, a row per parameter instead."""
    units, posterior, objective = result.units, result.posterior, result.objective
    caption = (
        f"log p(X) I(X) = {_figure(objective.log_value)} ± {_figure(objective.log_value_se)} ({objective.estimator}"
    )
    if objective.effective_samples is not None:
        caption += f", {objective.effective_samples:.0f} effective samples"
    if objective.pareto_k is not None:
        caption += f", Pareto k {objective.pareto_k:.2f}"
    # the constrained parameters named, not only set in bold: a redirected output has no bold
    constrained = "; ".join(
        f"{name} {', '.join(link.constrained)}" if len(posterior.links) > 1 else ", ".join(link.constrained)
        for name, link in posterior.links.items()
        if link.constrained
    )
    caption += (
        "); w: weighted by the closing link's scores (the posterior); ± se: the Monte Carlo standard error "
        "of the figure above; bold: constrained parameters" + (f" ({constrained})" if constrained else "")
    )
    for name, link in posterior.links.items():
        if link.satisfied is not None:
            se = "" if link.satisfied_se is None else f" ± {100 * link.satisfied_se:.2f}"
            caption += f"; {name}: inequalities met by {100 * link.satisfied:.2f}{se} % of the samples"
    title = _text(f"{result.problem}: posterior of the closing links ({posterior.samples} samples, Table 2)")
    table = Table(title=title, caption=_text(caption))
    table.add_column("link")
    table.add_column("")
    for name in ("tx", "ty", "tz"):
        table.add_column(f"{name} ({units.length})", justify="right")
    for name in ("rx", "ry", "rz"):
        table.add_column(f"{name} ({units.angle})", justify="right")
    round_off = _round_off(posterior.links.values())
    for link_name, link in posterior.links.items():
        for label, values in _statistics(link):
            if values is None:
                continue
            cells = []
            for param, value in zip(link.params, values):
                cells.append(
                    _text(
                        _figure(value, round_off=round_off[param in LENGTH_NAMES]),
                        style="bold" if param in link.constrained else "",
                    )
                )
            table.add_row(_text(link_name if label == "mean" else ""), label, *cells)
    return WholeTable(table, _posterior_by_parameter(result, title, caption, round_off), keys=2)


def _statistics(link) -> list[tuple[str, list | None]]:
    """A closing link's Table 2 statistics, each followed by its Monte Carlo standard error."""
    weighted = link.weighted
    return [
        ("mean", link.mean),
        ("± se", link.mean_se),
        ("std", link.std),
        ("± se", link.std_se),
        ("w mean", None if weighted is None else weighted.mean),
        ("± se", None if weighted is None else getattr(weighted, "mean_se", None)),
        ("w std", None if weighted is None else weighted.std),
        ("± se", None if weighted is None else getattr(weighted, "std_se", None)),
    ]


def _posterior_by_parameter(result: DesignResult, title: Text, caption: str, round_off: dict[bool, float]) -> Table:
    """Table 2 transposed: a row per closing link and parameter, the statistics as columns, and
    under it a row of their standard errors (``round_off``: :func:`_round_off`'s, the same table's)."""
    table = Table(title=title, caption=_text(caption))
    for column in ("link", "parameter", "mean", "std", "w mean", "w std"):
        table.add_column(column, justify="left" if column in ("link", "parameter") else "right")
    for link_name, link in result.posterior.links.items():
        statistics = [values for _, values in _statistics(link)]
        for k, param in enumerate(link.params):
            unit = parameter_unit(param, result.units)
            style = "bold" if param in link.constrained else ""
            noise = round_off[param in LENGTH_NAMES]
            figures = [None if values is None else values[k] for values in statistics]
            table.add_row(
                _text(link_name if k == 0 else ""),
                _text(f"{param} ({unit})", style=style),
                *(_text(_figure(value, round_off=noise), style=style) for value in figures[0::2]),
            )
            table.add_row(
                Text(""),
                _text("± se"),
                *(_text(_figure(value, round_off=noise)) for value in figures[1::2]),
            )
    return table


def configurations_table(result: DesignResult) -> WholeTable:
    """Each configuration's joint values, a column per configuration."""
    configurations = result.configurations or {}
    units = result.units
    table = Table(title=_text(f"{result.problem}: joint values per configuration ({units.angle} or {units.length})"))
    table.add_column("joint")
    for name in configurations:
        table.add_column(_text(name), justify="right")
    joints = list(dict.fromkeys(joint for entry in configurations.values() for joint in entry.joints))
    for joint in joints:
        table.add_row(
            _text(joint),
            *(
                _text(_figure(entry.joints.get(joint))) if joint in entry.joints else Text("")
                for entry in configurations.values()
            ),
        )
    table.add_row(_text("closing links"), *(_text(", ".join(entry.closing_links)) for entry in configurations.values()))
    return WholeTable(table)


def contributors_table(result: DesignResult) -> WholeTable:
    """Shares of each scored parameter's linearised variance, per robot, link and parameter."""
    table = Table(title=_text(f"{result.problem}: contributors to the closing links' variance (linearised)"))
    for column in ("scored", "std", "by", "largest shares"):
        table.add_column(column)
    for link_name, parameters in (result.contributors or {}).items():
        for parameter, entry in parameters.items():
            groups = (("robot", entry.by_robot), ("link", entry.by_link), ("parameter", entry.by_parameter))
            for k, (group, shares) in enumerate(groups):
                text = ", ".join(f"{name} {100 * share:.0f}%" for name, share in list(shares.items())[:3])
                table.add_row(
                    _text(f"{link_name}.{parameter}" if k == 0 else ""),
                    f"{entry.std:.4g} {parameter_unit(parameter, result.units)}"
                    if k == 0 and entry.std is not None
                    else "",
                    group,
                    _text(text),
                )
    return WholeTable(table)


def maxerror_table(result: MaxErrorResult) -> WholeTable:
    """Worst-case pose errors (certified) beside the typical ones, if sampled."""
    units, statistics, allocation = result.units, result.statistics, result.allocation
    table = Table(title=_text(f"{result.problem}: maximal end-effector error from joint clearances ({result.model})"))
    table.add_column("error")
    table.add_column("first-order max (feasible point)", justify="right")
    table.add_column("first-order bound", justify="right")
    table.add_column("relative gap", justify="right")
    exact_shown = result.rotation.exact is not None
    if exact_shown:
        table.add_column("exact model: max found / certified bound (gap)", justify="right")
    if statistics is not None:
        table.add_column("uniform clearances: p50 / p95 / p99.7", justify="right")
    table.add_column("time (s)", justify="right")
    for kind, unit in (("rotation", units.angle), ("translation", units.length)):
        entry = getattr(result, kind)
        cells = [f"{kind} ({unit})", f"{entry.max:.9g}", f"{entry.upper_bound:.9g}", f"{entry.gap:.1e}"]
        if exact_shown:
            exact = entry.exact
            cells.append(f"{exact.max:.9g} / {exact.bound:.9g} ({exact.gap:.1e})")
        if statistics is not None:
            summary = getattr(statistics, kind)
            cells.append(f"{summary.p50:.4g} / {summary.p95:.4g} / {summary.p99_7:.4g}")
        cells.append(f"{entry.seconds:.4f}")
        table.add_row(*cells)
    notes = []
    if statistics is not None and statistics.yield_ is not None:
        found = statistics.yield_
        spec = ", ".join(
            f"{kind} <= {value:g} {units.angle if kind == 'rotation' else units.length}"
            for kind, value in found.spec.items()
        )
        low, high = found.interval_95
        certain = "; certain: the exact model's certified bound is within the spec" if found.certain else ""
        notes.append(
            f"yield of the spec ({spec}): {found.value:.4f} ± {found.se:.4f}, 95 % interval "
            f"[{low:.4f}, {high:.4f}] ({found.effective_samples} samples){certain}"
        )
    if statistics is not None:
        notes.append(
            "each joint's share of the mean squared error (first order), rotation / translation: "
            + ", ".join(f"{k + 1}: {j.rotation:.2f} / {j.translation:.2f}" for k, j in enumerate(statistics.joints))
        )
    if allocation is not None:
        safe = f"tolerance synthesis: the clearances x {allocation.lambda_low:.9g} are proven to meet the spec"
        if allocation.lambda_high is None:  # no scale was found beyond the spec: no bracket to give a width of
            notes.append(f"{safe}, and no larger scale was shown not to")
        else:
            notes.append(
                f"{safe}, x {allocation.lambda_high:.9g} shown not to (relative width {allocation.relative_width:.1e})"
            )
    if notes:
        table.caption = _text("; ".join(notes))
    return WholeTable(table)
