"""Batched evaluation of a chain of probabilistic links, vectorised over samples.

A link's transform is ``T = origin · T(Q) · tip`` (constants around the pose
6-vector Q), and ``T(Q) = Tx(tx) Ty(ty) Tz(tz) Rz(rz) Ry(ry) Rx(rx)``. Each
parameter of Q is an affine function of the inputs: a constant (F) or an
offset plus unknowns X and free parameters L. A path through the graph (Eq. 1
of the 2000 paper: a cycle minus its closing link, edges used forward or
backward) is compiled once into a short list of *steps*:

* :class:`ConstantStep`: a rigid transform, the fold of every run of fixed
  parameters and constant link geometry;
* :class:`AxisStep`: a rotation about, or translation along, one coordinate
  axis by an affine function of X and L. Consecutive steps about the same axis
  merge (a joint's zero offset and its angle become one rotation).

Evaluation keeps the running rotation as three column arrays ``M[k] = R[:, k]``
of shape (3, N) and the translation as (3, N): an axis rotation mixes two
columns (four multiply-adds on contiguous arrays), a constant is one small
matrix product, and X-only steps fold into constants for a given X. Sines and
cosines of L samples are computed once per sample batch and reused across
every X (angle addition), since solvers evaluate many X on the same samples.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, Sequence

import numpy as np

from bcad.kinematics.se3 import invert, rotation_about_axis, translation

Source = Literal["x", "l"]


@dataclass(frozen=True)
class Term:
    """``coefficient * input`` where the input is X[index] or L[index]."""

    source: Source
    index: int
    coefficient: float = 1.0


@dataclass(frozen=True)
class AffineParameter:
    """A pose parameter's value: ``offset + sum of terms``."""

    offset: float = 0.0
    terms: tuple[Term, ...] = ()

    @property
    def is_constant(self) -> bool:
        return not self.terms


@dataclass(frozen=True)
class LinkTransform:
    """``origin · T(Q) · tip`` with each of the six parameters of Q affine in X and L."""

    parameters: tuple[AffineParameter, ...]
    origin: np.ndarray = field(default_factory=lambda: np.eye(4))
    tip: np.ndarray = field(default_factory=lambda: np.eye(4))


@dataclass(frozen=True)
class ConstantStep:
    matrix: np.ndarray


@dataclass(frozen=True)
class AxisStep:
    kind: Literal["rotation", "translation"]
    axis: int
    value: AffineParameter


Step = ConstantStep | AxisStep

# T(Q) = Tx Ty Tz Rz Ry Rx: (kind, axis, index of the parameter in Q).
_FACTORS = (
    ("translation", 0, 0),
    ("translation", 1, 1),
    ("translation", 2, 2),
    ("rotation", 2, 5),
    ("rotation", 1, 4),
    ("rotation", 0, 3),
)


def _axis_matrix(kind: str, axis: int, value: float) -> np.ndarray:
    if kind == "translation":
        vector = np.zeros(3)
        vector[axis] = value
        return translation(vector)
    T = np.eye(4)
    T[:3, :3] = rotation_about_axis(axis, value)
    return T


def _negated(value: AffineParameter) -> AffineParameter:
    return AffineParameter(-value.offset, tuple(Term(t.source, t.index, -t.coefficient) for t in value.terms))


def link_steps(link: LinkTransform, forward: bool = True) -> list[Step]:
    """The steps of one link, used forward (T) or backward (T^-1)."""
    steps: list[Step] = [ConstantStep(np.asarray(link.origin, dtype=float))]
    for kind, axis, index in _FACTORS:
        value = link.parameters[index]
        if value.is_constant:
            steps.append(ConstantStep(_axis_matrix(kind, axis, value.offset)))
        else:
            steps.append(AxisStep(kind, axis, value))
    steps.append(ConstantStep(np.asarray(link.tip, dtype=float)))
    if forward:
        return steps
    inverted: list[Step] = []
    for step in reversed(steps):
        if isinstance(step, ConstantStep):
            inverted.append(ConstantStep(invert(step.matrix)))
        else:
            inverted.append(AxisStep(step.kind, step.axis, _negated(step.value)))
    return inverted


def fold_steps(steps: Sequence[Step]) -> list[Step]:
    """Multiply runs of constants together and merge same-axis steps."""
    folded: list[Step] = []
    for step in steps:
        previous = folded[-1] if folded else None
        if isinstance(step, ConstantStep):
            if np.allclose(step.matrix, np.eye(4), rtol=0.0, atol=0.0):
                continue
            if isinstance(previous, ConstantStep):
                folded[-1] = ConstantStep(previous.matrix @ step.matrix)
                continue
        elif (
            isinstance(previous, AxisStep)
            and previous.kind == step.kind
            and previous.axis == step.axis
        ):
            merged = AffineParameter(
                previous.value.offset + step.value.offset, previous.value.terms + step.value.terms
            )
            folded[-1] = AxisStep(step.kind, step.axis, merged)
            continue
        folded.append(step)
    return folded


class Samples:
    """A batch of N samples of the free parameters L, with cached sines and cosines.

    ``values`` has shape (N, nL). The trigonometric cache is filled lazily per
    column, the first time a rotation needs it.
    """

    def __init__(self, values: np.ndarray):
        values = np.asarray(values, dtype=float)
        if values.ndim != 2:
            raise ValueError(f"L samples must have shape (N, nL), got {values.shape}")
        self.values = values
        self.columns = np.ascontiguousarray(values.T)
        self._trig: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    @property
    def count(self) -> int:
        return self.values.shape[0]

    def trig(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        if index not in self._trig:
            column = self.columns[index]
            self._trig[index] = (np.cos(column), np.sin(column))
        return self._trig[index]


@dataclass
class BatchTransform:
    """N rigid transforms: ``columns[k]`` is column k of the rotations, shape (3, 3, N)."""

    columns: np.ndarray
    translations: np.ndarray

    def matrices(self) -> np.ndarray:
        """The transforms as (N, 4, 4) homogeneous matrices."""
        n = self.translations.shape[1]
        T = np.zeros((n, 4, 4))
        T[:, :3, :3] = np.transpose(self.columns, (2, 1, 0))
        T[:, :3, 3] = self.translations.T
        T[:, 3, 3] = 1.0
        return T

    def poses(self) -> np.ndarray:
        """The transforms as (N, 6) pose vectors (rpy as in :mod:`bcad.kinematics.se3`)."""
        M = self.columns
        rx = np.arctan2(M[1, 2], M[2, 2])
        ry = np.arctan2(-M[0, 2], np.hypot(M[0, 0], M[0, 1]))
        rz = np.arctan2(M[0, 1], M[0, 0])
        return np.column_stack([self.translations[0], self.translations[1], self.translations[2], rx, ry, rz])


class Chain:
    """A compiled path of links, evaluated for N samples at once."""

    def __init__(self, links: Sequence[tuple[LinkTransform, bool]]):
        steps: list[Step] = []
        for link, forward in links:
            steps.extend(link_steps(link, forward))
        self.steps: list[Step] = fold_steps(steps)

    def evaluate(self, x: np.ndarray, samples: Samples) -> BatchTransform:
        """The chain's transform for unknowns ``x`` (shape (nX,) or (N, nX)) and L samples."""
        x = np.asarray(x, dtype=float)
        n = samples.count
        per_sample_x = x.ndim == 2
        pending = np.eye(4)
        columns: np.ndarray | None = None
        translations: np.ndarray | None = None

        def flush() -> None:
            nonlocal pending, columns, translations
            R, t = pending[:3, :3], pending[:3, 3]
            if columns is None:
                columns = np.repeat(R.T[:, :, None], n, axis=2)
                translations = np.repeat(t[:, None], n, axis=1)
            elif not np.array_equal(pending, np.eye(4)):
                translations = translations + np.tensordot(t, columns, axes=(0, 0))
                columns = (R.T @ columns.reshape(3, -1)).reshape(3, 3, n)
            pending = np.eye(4)

        for step in self.steps:
            if isinstance(step, ConstantStep):
                pending = pending @ step.matrix
                continue
            value = step.value
            base: float | np.ndarray = value.offset
            l_terms = []
            for term in value.terms:
                if term.source == "x":
                    base = base + term.coefficient * (x[:, term.index] if per_sample_x else x[term.index])
                else:
                    l_terms.append(term)
            if not l_terms and np.ndim(base) == 0:
                pending = pending @ _axis_matrix(step.kind, step.axis, float(base))
                continue
            flush()
            if step.kind == "translation":
                amount = base
                for term in l_terms:
                    amount = amount + term.coefficient * samples.columns[term.index]
                translations += columns[step.axis] * amount
                continue
            if len(l_terms) == 1 and abs(l_terms[0].coefficient) == 1.0 and np.ndim(base) == 0:
                # cos(a ± d) and sin(a ± d) from the cached trig of the L sample d.
                cos_d, sin_d = samples.trig(l_terms[0].index)
                ca, sa = np.cos(base), np.sin(base)
                sign = l_terms[0].coefficient
                c = ca * cos_d - (sign * sa) * sin_d
                s = sa * cos_d + (sign * ca) * sin_d
            else:
                angle = base
                for term in l_terms:
                    angle = angle + term.coefficient * samples.columns[term.index]
                angle = np.broadcast_to(angle, (n,))
                c, s = np.cos(angle), np.sin(angle)
            i, j = (step.axis + 1) % 3, (step.axis + 2) % 3
            column_i, column_j = columns[i], columns[j]
            new_i = column_i * c
            new_i += column_j * s
            column_j *= c
            column_j -= column_i * s
            columns[i] = new_i
        flush()
        return BatchTransform(columns, translations)
