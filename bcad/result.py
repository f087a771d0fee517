"""What the Python API returns: :class:`Result`, a result document with its family's typed model,
and :class:`ClosingLink`, one closing link's posterior read from it.

Each family owns the model of its document (:class:`bcad.bayes.result.DesignResult`,
:class:`bcad.worstcase.result.MaxErrorResult`, :class:`bcad.calibration.result.CalibrationResult`);
:func:`result_model` names the one of a kind and :func:`results_json_schema` publishes them all.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def result_model(kind: str):
    """The typed model of a result document of this kind (the command that wrote it)."""
    if kind in ("solve", "posterior"):
        from bcad.bayes.result import DesignResult

        return DesignResult
    if kind == "maxerror":
        from bcad.worstcase.result import MaxErrorResult

        return MaxErrorResult
    from bcad.calibration.result import CalibrationResult

    return CalibrationResult


def results_json_schema() -> dict:
    """The JSON Schema of every result document (``bcad schema --results``): one of the
    families' models, told apart by ``kind``."""
    from bcad.bayes.result import DesignResult
    from bcad.calibration.result import CalibrationResult
    from bcad.model.results import SCHEMA_VERSION
    from bcad.model.schema import json_schema_of
    from bcad.worstcase.result import MaxErrorResult

    return json_schema_of(
        [DesignResult, MaxErrorResult, CalibrationResult],
        "serialization",
        "results.schema.json",
        f"bcad result (schema_version {SCHEMA_VERSION})",
        "The JSON document that bcad solve, posterior, maxerror or calibrate writes; its 'kind' names the command. "
        "Keys not listed may be added by later versions: readers ignore them.",
    )


def checked(document: dict) -> dict:
    """The document, once the model of its kind has checked it (:func:`bcad.model.results.checked`)."""
    from bcad.model.results import checked as checked_by

    return checked_by(document, result_model(document["kind"]))


@dataclass(frozen=True)
class ClosingLink:
    """The posterior of one closing link's pose Q, in the problem's units (the paper's Table 2:
    a row per closing link)."""

    name: str
    parent: str
    child: str
    parameters: tuple[str, ...]
    mean: np.ndarray  # the prior's propagation: Q under L ~ p(L)
    std: np.ndarray
    weighted_mean: np.ndarray  # the posterior: weighted by the closing link's distributions and relation
    weighted_std: np.ndarray
    effective_samples: float | None
    satisfied: float | None  # fraction of prior samples meeting the relation's inequalities
    satisfied_se: float | None = None  # its standard error, sqrt(p (1 - p) / N)


@dataclass
class Result:
    """A result of :func:`bcad.solve`, :func:`bcad.posterior`, :func:`bcad.maxerror` or
    :func:`bcad.calibrate`: the JSON document of the matching command, with typed views of its parts."""

    kind: str
    document: dict
    #: calibrate: the calibrated robots' URDF texts, by robot name
    urdf: dict[str, str] = field(default_factory=dict)

    @property
    def typed(self):
        """The document as its family's typed model (:class:`bcad.bayes.result.DesignResult`,
        :class:`bcad.worstcase.result.MaxErrorResult`, :class:`bcad.calibration.result.CalibrationResult`):
        ``result.typed.rotation.upper_bound``. Its fields are also the result's own:
        ``worst.rotation.upper_bound``, ``cal.check``. Read from ``document`` at each access, so
        that it follows what was changed there."""
        return result_model(self.document["kind"]).model_validate(self.document)

    def __getattr__(self, name: str):
        if name.startswith("_") or name in ("kind", "document", "urdf"):
            raise AttributeError(name)
        typed = self.typed
        if name in type(typed).model_fields or name in (typed.model_extra or {}):
            return getattr(typed, name)
        raise AttributeError(f"a {self.kind} result has no {name!r}")

    def to_json(self) -> str:
        """The document as the command writes it (indented JSON, no NaN)."""
        from bcad.io import json_text

        return json_text(self.document)

    @property
    def warnings(self) -> list[dict]:
        """The result's warnings (``code`` and ``message``): why it may not be trusted."""
        return [warning.model_dump() for warning in self.typed.warnings]

    @property
    def trusted(self) -> bool:
        """No warning: the command would exit 0."""
        return not self.typed.warnings

    @property
    def solution(self) -> dict[str, float]:
        """X by name (solve and posterior; empty for the other kinds)."""
        return dict(getattr(self.typed, "solution", None) or {})

    @property
    def log_objective(self) -> tuple[float | None, float | None]:
        """log p(X) I(X) and its standard error (solve and posterior)."""
        objective = getattr(self.typed, "objective", None)
        return (None, None) if objective is None else (objective.log_value, objective.log_value_se)

    @property
    def links(self) -> dict[str, ClosingLink]:
        """Each closing link's posterior (solve and posterior; empty for the other kinds)."""
        posterior = getattr(self.typed, "posterior", None)
        out = {}
        for name, link in (posterior.links if posterior is not None else {}).items():
            weighted = link.weighted
            mean = weighted.mean if weighted is not None and weighted.mean is not None else link.mean
            std = weighted.std if weighted is not None and weighted.std is not None else link.std
            out[name] = ClosingLink(
                name,
                link.parent,
                link.child,
                tuple(link.params),
                np.array(link.mean, dtype=float),
                np.array(link.std, dtype=float),
                np.array(mean, dtype=float),
                np.array(std, dtype=float),
                link.effective_samples,
                link.satisfied,
                link.satisfied_se,
            )
        return out

    @property
    def parameters(self) -> dict[str, dict]:
        """Calibrated parameters by name, each as its document entry (calibrate; empty otherwise)."""
        parameters = getattr(self.typed, "parameters", None) or {}
        return {name: entry.model_dump() for name, entry in parameters.items()}

    def table(self):
        """The command's table (a rich renderable; shown as HTML in notebooks)."""
        from bcad import report

        if self.kind == "maxerror":
            return report.maxerror_table(self.typed)
        if self.kind == "calibrate":
            from bcad.calibration.report import calibration_table

            return calibration_table(self.document)
        return report.posterior_table(self.typed)

    def _repr_html_(self) -> str:
        import io

        from rich.console import Console

        console = Console(file=io.StringIO(), record=True, width=120, markup=False, emoji=False)
        console.print(self.table())
        return console.export_html(inline_styles=True)
