"""``bcad batch --plot DIR``: for each problem swept over a key, its key figure against the swept
value (the log objective with its standard error, or the certified errors of a clearance chain)."""

from __future__ import annotations

from collections import defaultdict


def sweep_series(summaries: list[dict]) -> dict[tuple[str, str], list[tuple[float, dict]]]:
    """(file, swept key) -> [(value, summary line)] over the lines whose other keys are equal,
    for numeric sweeps with at least two done points."""
    series: dict[tuple[str, str, tuple], list[tuple[float, dict]]] = defaultdict(list)
    for line in summaries:
        if line.get("status") == "error":
            continue
        for key, value in line.get("point", {}).items():
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                continue
            others = tuple(sorted((k, str(v)) for k, v in line["point"].items() if k != key))
            series[(line["file"], key, others)].append((float(value), line))
    out: dict[tuple[str, str], list[tuple[float, dict]]] = {}
    for (file, key, others), points in series.items():
        if len(points) >= 2 and (file, key) not in out:
            out[(file, key)] = sorted(points, key=lambda point: point[0])
    return out


def draw_sweep(file: str, key: str, points: list[tuple[float, dict]], where) -> tuple[object, dict]:
    from bcad.plot import pyplot

    plt = pyplot(where)
    figure, axes = plt.subplots(figsize=(7, 4.5))
    values = [value for value, _ in points]
    kind = points[0][1].get("kind")
    drawn: dict = {"values": values}
    if kind == "maxerror":
        # a length and an angle: each on an axis of its own, in its unit
        units = points[0][1].get("units") or {}  # (a summary written without them: no unit said)
        drawn["axes"] = {}
        for name, side, style, unit in (
            ("translation", axes, "o-", units.get("length")),
            ("rotation", axes.twinx(), "s--", units.get("angle")),
        ):
            maxima = [line[name]["max"] for _, line in points]
            side.plot(values, maxima, style, color="C0" if side is axes else "C1", label=f"{name} (certified maximum)")
            side.set_ylabel(f"{name} error, certified maximum" + (f" ({unit})" if unit else ""))
            drawn[name] = maxima
            drawn["axes"][name] = side.get_ylabel()
        figure.legend(loc="upper left", bbox_to_anchor=(0.12, 0.88))
    else:
        figures = [line.get("log_objective") for _, line in points]
        errors = [line.get("log_objective_se") or 0.0 for _, line in points]
        kept = [(v, f, e) for v, f, e in zip(values, figures, errors) if f is not None]
        axes.errorbar(
            [v for v, _, _ in kept],
            [f for _, f, _ in kept],
            yerr=[2 * e for _, _, e in kept],
            fmt="o-",
            capsize=3,
            label="log p(X*) I(X*) ± 2 se",
        )
        drawn["log_objective"] = [f for _, f, _ in kept]
        axes.set_ylabel("log objective at the solution (Eq. 2)")
        axes.legend()
    axes.set_xlabel(f"{key} (as the problem file writes it, in its units)")
    axes.set_title(f"{file}: swept over {key}")
    return figure, drawn
