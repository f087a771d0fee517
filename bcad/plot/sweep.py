"""``bcad batch --plot DIR``: for each problem swept over a key, its key figure against the swept
value (the log objective with its standard error, or the certified errors of a clearance chain),
a line for each combination of the other keys' values (a slice of the grid)."""

from __future__ import annotations

from collections import defaultdict

#: a slice of a sweep: the other keys' values it holds, and its points (swept value, summary line)
Slice = tuple[tuple[tuple[str, str], ...], list[tuple[float, dict]]]


def sweep_series(summaries: list[dict]) -> dict[tuple[str, str], list[Slice]]:
    """(file, swept key) -> its slices, each of the lines whose other keys are equal, for numeric
    sweeps: the slices with at least two done points, in the order of the held values."""
    series: dict[tuple[str, str, tuple], list[tuple[float, dict]]] = defaultdict(list)
    for line in summaries:
        if line.get("status") == "error":
            continue
        for key, value in line.get("point", {}).items():
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                continue
            others = tuple(sorted((k, str(v)) for k, v in line["point"].items() if k != key))
            series[(line["file"], key, others)].append((float(value), line))
    out: dict[tuple[str, str], list[Slice]] = defaultdict(list)
    for (file, key, others), points in series.items():
        if len(points) >= 2:
            out[(file, key)].append((others, sorted(points, key=lambda point: point[0])))
    return {where: sorted(slices, key=lambda s: [_order(value) for _, value in s[0]]) for where, slices in out.items()}


def _order(text: str) -> tuple:
    """A held value's place among its key's values: numbers by their value (2 before 10), then text."""
    try:
        number = float(text)
    except ValueError:
        return (1, 0.0, text)
    return (0, number, "") if number == number else (1, 0.0, text)  # (nan among the words)


def _held(others: tuple[tuple[str, str], ...]) -> str:
    """The other keys' values a slice holds, as a legend reads them (nothing for a one-key sweep)."""
    return ", ".join(f"{key}={value}" for key, value in others)


def draw_sweep(file: str, key: str, slices: list[Slice], where) -> tuple[object, dict]:
    """The sweep's figure, a line per slice (labelled with the values it holds), and what was drawn:
    per slice (in ``slices``' order) its ``values`` and figures."""
    from bcad.plot import pyplot

    plt = pyplot(where)
    figure, axes = plt.subplots(figsize=(7, 4.5))
    first = slices[0][1][0][1]  # the first slice's first summary line: the kind and units of all
    drawn: dict = {"slices": []}
    if first.get("kind") == "maxerror":
        # a length and an angle: each on an axis of its own, in its unit
        units = first.get("units") or {}  # (a summary written without them: no unit said)
        drawn["axes"] = {}
        sides = (
            ("translation", axes, "o-", units.get("length")),
            ("rotation", axes.twinx(), "s--", units.get("angle")),
        )
        for name, side, _, unit in sides:
            side.set_ylabel(f"{name} error, certified maximum" + (f" ({unit})" if unit else ""))
            drawn["axes"][name] = side.get_ylabel()
        for k, (others, points) in enumerate(slices):
            values = [value for value, _ in points]
            entry = {"held": dict(others), "values": values}
            for name, side, style, _ in sides:
                maxima = [line[name]["max"] for _, line in points]
                label = f"{name} (certified maximum)" + (f", {_held(others)}" if others else "")
                side.plot(values, maxima, style, color=f"C{(2 * k + (side is not axes)) % 10}", label=label)
                entry[name] = maxima
            drawn["slices"].append(entry)
        figure.legend(loc="upper left", bbox_to_anchor=(0.12, 0.88), fontsize="small")
    else:
        for others, points in slices:
            values = [value for value, _ in points]
            figures = [line.get("log_objective") for _, line in points]
            errors = [line.get("log_objective_se") or 0.0 for _, line in points]
            kept = [(v, f, e) for v, f, e in zip(values, figures, errors) if f is not None]
            axes.errorbar(
                [v for v, _, _ in kept],
                [f for _, f, _ in kept],
                yerr=[2 * e for _, _, e in kept],
                fmt="o-",
                capsize=3,
                label="log p(X*) I(X*) ± 2 se" + (f", {_held(others)}" if others else ""),
            )
            drawn["slices"].append(
                {"held": dict(others), "values": [v for v, _, _ in kept], "log_objective": [f for _, f, _ in kept]}
            )
        axes.set_ylabel("log objective at the solution (Eq. 2)")
        axes.legend(fontsize="small")
    axes.set_xlabel(f"{key} (as the problem file writes it, in its units)")
    axes.set_title(f"{file}: swept over {key}")
    return figure, drawn
