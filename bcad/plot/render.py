"""``bcad plot``: from a problem (and results) to the bytes of a picture."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from bcad.bayes.result import DesignResult
from bcad.errors import InputError
from bcad.model.pose import parameter_unit


def solution_of(compiled, path: Path) -> tuple[np.ndarray, int]:
    """X and the seed of a result file, checked as ``bcad posterior --at`` checks it."""
    from bcad.arguments import COMMAND_LINE
    from bcad.bayes.arguments import read_result, solution_at

    solution, seed, units, source = read_result(path)
    return solution_at(compiled, solution, {}, COMMAND_LINE, source, units), seed


def figure_bytes(figure, suffix: str) -> bytes:
    buffer = io.BytesIO()
    figure.savefig(buffer, format=suffix.lstrip("."), dpi=110, metadata={"Date": None} if suffix == ".svg" else None)
    import matplotlib.pyplot as plt

    plt.close(figure)
    return buffer.getvalue()


def arms_html(compiled, drawings, titles) -> bytes:
    """An interactive view of the arms drawing (plotly, offline: the library is embedded)."""
    from bcad.plot import require

    go = require("plotly.graph_objects", compiled.problem.source.path)
    figure = go.Figure()
    for title, drawing in zip(titles, drawings):
        for name, points in drawing.segments.items():
            figure.add_trace(
                go.Scatter3d(
                    x=points[:, 0], y=points[:, 1], z=points[:, 2], mode="lines+markers", name=f"{title}: {name}"
                )
            )
        for name, points in drawing.entities.items():
            figure.add_trace(go.Scatter3d(x=points[:, 0], y=points[:, 1], z=points[:, 2], mode="lines", name=name))
    figure.update_layout(scene={"aspectmode": "data"}, title=compiled.problem.name)
    return figure.to_html(include_plotlyjs=True, full_html=True).encode("utf-8")


def panel_title(name: str, result: DesignResult) -> str:
    """A panel's title: the result's name, the log objective with its standard error as this
    picture's own samples estimate it (they are drawn again at the result's X, so it differs from
    the file's value within their errors), and each closing link's scored parameters with Table 2's
    std (the prior's propagation: how far the cell misses) and w std (weighted by the scores)."""
    objective = result.objective
    lines = [name]
    if objective.log_value is not None:
        se = objective.log_value_se
        drawn = f" ({objective.samples:,} samples drawn here)" if objective.samples else ""
        lines.append(f"log p(X) I(X) = {objective.log_value:.2f}" + (f" ± {se:.2g}" if se is not None else "") + drawn)
    for link_name, link in result.posterior.links.items():
        scored = [(k, p) for k, p in enumerate(link.params) if p in link.constrained]
        weighted = link.weighted.std if link.weighted is not None else None
        if scored and weighted is not None and link.std is not None:
            figures = ", ".join(
                f"{p} {link.std[k]:.3g} / {weighted[k]:.3g} {parameter_unit(p, result.units)}" for k, p in scored
            )
            lines.append(f"{link_name}, std / w std (Table 2): {figures}")
    return "\n".join(lines)


def render(file: Path, what: str, *, at: list[Path], samples: int, seed: int, link: str | None, suffix: str) -> bytes:
    from bcad.plot import pyplot

    pyplot(file)  # the optional extra is there, or exit 2 before any work
    if what == "error":
        from bcad.compiler.units import angle_scale
        from bcad.model.clearance import load_chain_problem
        from bcad.numerics.seeding import stream
        from bcad.plot.figures import draw_error
        from bcad.worstcase.error_map import build_error_map
        from bcad.worstcase.result import MaxErrorResult
        from bcad.worstcase.run import maxerror_document
        from bcad.worstcase.statistics import error_samples

        problem = load_chain_problem(file)
        # the exact model's certified bound as `bcad maxerror --model exact` reports it (the sharp one where it applies)
        document = maxerror_document(problem, tol=1e-6, model="exact", seed=seed)
        error_map = build_error_map(problem)
        rotations, translations = error_samples(
            error_map, problem.name, problem.units.length, samples, stream(seed, "clearance")
        )
        result = MaxErrorResult.model_validate(document)
        figure, _ = draw_error(result, rotations / angle_scale(problem.units), translations, file)
        return figure_bytes(figure, suffix)

    from bcad.compiler import compile_problem
    from bcad.model import load_problem

    compiled = compile_problem(load_problem(file))
    if what == "graph":
        from bcad.plot.figures import draw_graph

        return figure_bytes(draw_graph(compiled, file)[0], suffix)
    if what == "relaxation":
        from bcad.plot.figures import draw_relaxation

        return figure_bytes(draw_relaxation(compiled, file)[0], suffix)
    if what == "residuals":
        from bcad.calibration.model import CalibrationModel
        from bcad.calibration.solve import calibrate
        from bcad.plot.figures import draw_residuals

        model = CalibrationModel(compiled)
        if not any(m.camera is not None for m in model.measurements):
            raise InputError(
                file, "--what residuals draws a camera's reprojection residuals; this problem measures no pixels"
            )
        calibration = calibrate(compiled, model, check_samples=0, seed=seed)
        return figure_bytes(draw_residuals(model, calibration.residuals_after, file)[0], suffix)

    from bcad.bayes.run import posterior_document

    if not at and what == "posterior":
        raise InputError(file, "a corner plot needs a solution: give --at RESULT.json")
    solutions = [solution_of(compiled, path) for path in at] or [
        (np.array(compiled.parameters.x_nominal, dtype=float), seed)
    ]
    titles = [path.name for path in at] or ["the nominal start (X at its pose)"]
    if what == "posterior":
        x, result_seed = solutions[0]
        kept: dict = {}
        document = posterior_document(compiled, x, samples=samples, seed=seed if seed else result_seed, kept=kept)
        from bcad.plot.figures import draw_posterior

        result = DesignResult.model_validate(document)
        if link is not None and link not in result.posterior.links:
            raise InputError(file, f"'{link}' is no closing link; closing links: {', '.join(result.posterior.links)}")
        return figure_bytes(draw_posterior(compiled, result, kept, link, file)[0], suffix)

    from bcad.bayes.model import BayesModel
    from bcad.plot.arms import draw_arms

    panels = []
    model = BayesModel(compiled) if compiled.graph.cycles else None
    for (x, result_seed), title in zip(solutions, titles):
        kept = {}
        if model is not None:
            document = posterior_document(
                compiled, x, samples=samples, seed=seed if seed else result_seed, kept=kept, model=model
            )
            title = panel_title(title, DesignResult.model_validate(document))
        panels.append((title, x, kept))
    figure, drawings = draw_arms(compiled, panels, file)
    if suffix == ".html":
        import matplotlib.pyplot as plt

        plt.close(figure)
        return arms_html(compiled, drawings, titles)
    return figure_bytes(figure, suffix)


def standard_figures(
    compiled, result: DesignResult, kept: dict, where, skipped: list[str] | None = None
) -> dict[str, bytes]:
    """``solve --plot DIR``: the cell at the solution, the corner plot of the first closing link
    (when the posterior samples were kept) and the graph, as PNG bytes by name. A corner plot its
    samples are too few for is left out, and why is added to ``skipped`` (the solve's result is
    not lost to a picture)."""
    from bcad.bayes.document import solution_from_dict
    from bcad.plot.arms import draw_arms
    from bcad.plot.figures import corner_refusal, draw_graph, draw_posterior

    x = solution_from_dict(compiled, result.solution)
    figures = {
        "arms": figure_bytes(draw_arms(compiled, [(f"{compiled.problem.name}: solution", x, kept)], where)[0], ".png"),
        "graph": figure_bytes(draw_graph(compiled, where)[0], ".png"),
    }
    if kept and result.posterior.links:
        name = next(iter(result.posterior.links))
        refusal = corner_refusal(name, kept[f"{name}/poses"], np.isfinite(kept[f"{name}/log_weights"]))
        if refusal is None:
            figures["posterior"] = figure_bytes(draw_posterior(compiled, result, kept, name, where)[0], ".png")
        elif skipped is not None:
            skipped.append(f"no posterior figure: {refusal}")
    return figures
