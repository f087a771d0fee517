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

Evaluation keeps the running transform as one array ``A`` of shape (4, 3, N):
``A[k] = R[:, k]`` for k < 3 and ``A[3]`` the translation. An axis rotation
mixes two columns in place (six operations on contiguous rows), a constant
(rotation and translation) is one 4 x 4 product ``C^T A``, and X-only steps
fold into constants for a given X; a joint's X angle joins the pending
constant (R(a + d) = R(d) R(a)), so a joint and its zero offset cost one
rotation by the offset's sines and cosines, which are computed once per
sample batch, since solvers evaluate many X on the same samples.
Batches larger than ``BLOCK`` are evaluated block by block, so that the working arrays stay
in a core's cache.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from bcad.kinematics.se3 import invert, rotation_about_axis, translation
from bcad.numerics.angles import cos_sin

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


Step = ConstantStep | AxisStep  # and, once planned, TranslationStep and SegmentStep


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


IDENTITY = np.eye(4)


def fold_steps(steps: Sequence[Step]) -> list[Step]:
    """Multiply runs of constants together and merge same-axis steps."""
    folded: list[Step] = []
    for step in steps:
        previous = folded[-1] if folded else None
        if isinstance(step, ConstantStep):
            if np.array_equal(step.matrix, IDENTITY):  # exactly the identity: nothing to apply
                continue
            if isinstance(previous, ConstantStep):
                folded[-1] = ConstantStep(previous.matrix @ step.matrix)
                continue
        elif isinstance(previous, AxisStep) and previous.kind == step.kind and previous.axis == step.axis:
            merged = AffineParameter(previous.value.offset + step.value.offset, previous.value.terms + step.value.terms)
            folded[-1] = AxisStep(step.kind, step.axis, merged)
            continue
        folded.append(step)
    return folded


class Samples:
    """A batch of N samples of the free parameters L, with per-batch caches.

    ``values`` has shape (N, nL). Sines and cosines of L columns, and the
    transforms of chain segments that depend on L only, are computed the first
    time they are needed and reused for every X evaluated on this batch (the
    solvers compare individuals on common samples).
    """

    def __init__(self, values: np.ndarray):
        values = np.asarray(values, dtype=float)
        if values.ndim != 2:
            raise ValueError(f"L samples must have shape (N, nL), got {values.shape}")
        self.values = values
        self.columns = np.ascontiguousarray(values.T)
        self._trig: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._segments: dict[int, tuple[object, BatchTransform]] = {}
        self._cached_bytes = 0

    @classmethod
    def from_columns(cls, columns: np.ndarray) -> Samples:
        """A batch from its (nL, N) column array (taken as is, without a copy)."""
        batch = cls.__new__(cls)
        batch.columns = np.ascontiguousarray(columns, dtype=float)
        batch.values = batch.columns.T
        batch._trig, batch._segments = {}, {}
        batch._cached_bytes = 0
        return batch

    @property
    def count(self) -> int:
        return self.values.shape[0]

    def room_for(self, values: int) -> bool:
        """Whether ``values`` more doubles fit in this batch's caches (CACHE_BYTES in all)."""
        return self._cached_bytes + 8 * values <= CACHE_BYTES

    def trig(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        found = self.cached_trig(index)
        if found is None:
            column = self.columns[index]
            found = cos_sin(column)  # polynomials where the L are small errors
            if self.room_for(2 * column.size):
                self._trig[index] = found
                self._cached_bytes += 16 * column.size
        return found

    def cached_trig(self, index: int) -> tuple[np.ndarray, np.ndarray] | None:
        return self._trig.get(index)

    def cached_segment(self, segment: SegmentStep) -> BatchTransform | None:
        cached = self._segments.get(id(segment))
        return cached[1] if cached is not None and cached[0] is segment else None

    def segment(self, segment: SegmentStep) -> BatchTransform:
        """The transform of an L-only chain segment on this batch (computed once, while the
        caches have room)."""
        found = self.cached_segment(segment)
        if found is None:
            found = _evaluate_steps(segment.steps, np.zeros(0), self, "single")
            if self.room_for(12 * self.count):
                self._segments[id(segment)] = (segment, found)
                self._cached_bytes += 96 * self.count
        return found


#: the most that a batch's caches (sines, cosines, L-only segments) hold: past it, they
#: are computed where used (a 500-joint arm at 1e5 samples would cache gigabytes)
CACHE_BYTES = 256 << 20


#: samples per block of :meth:`Chain.evaluate` (about 1 MB of working arrays: a core's L2)
BLOCK = 1 << 14


class _SampleBlock:
    """A contiguous block of a :class:`Samples` batch, sharing (slicing) its per-batch caches."""

    def __init__(self, samples: Samples, block: slice):
        self.samples = samples
        self.block = block
        self.columns = samples.columns[:, block]
        self.count = self.columns.shape[1]

    def trig(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        whole = self.samples.cached_trig(index)
        if whole is None and self.samples.room_for(2 * self.samples.count):
            whole = self.samples.trig(index)
        if whole is None:  # the batch's caches are full: this block's own, not the batch's
            return cos_sin(self.columns[index])
        return whole[0][self.block], whole[1][self.block]

    def segment(self, segment: SegmentStep) -> BatchTransform:
        whole = self.samples.cached_segment(segment)
        if whole is None and self.samples.room_for(12 * self.samples.count):
            whole = self.samples.segment(segment)
        if whole is None:
            return _evaluate_steps(segment.steps, np.zeros(0), self, "single")
        return BatchTransform(whole.columns[..., self.block], whole.translations[..., self.block])


@dataclass(frozen=True)
class TranslationStep:
    """Consecutive translations along coordinate axes: ``(axis, value)`` pairs."""

    moves: tuple[tuple[int, AffineParameter], ...]


@dataclass(frozen=True, eq=False)
class SegmentStep:
    """A run of steps that depends on L only, cached per sample batch."""

    steps: tuple[Step, ...]


def _depends_on_x(step: Step) -> bool:
    if isinstance(step, AxisStep):
        return any(term.source == "x" for term in step.value.terms)
    if isinstance(step, TranslationStep):
        return any(term.source == "x" for _, value in step.moves for term in value.terms)
    return False


def _group_translations(steps: Sequence[Step]) -> list[Step]:
    grouped: list[Step] = []
    for step in steps:
        if isinstance(step, AxisStep) and step.kind == "translation":
            move = (step.axis, step.value)
            if grouped and isinstance(grouped[-1], TranslationStep):
                grouped[-1] = TranslationStep(grouped[-1].moves + (move,))
            else:
                grouped.append(TranslationStep((move,)))
        else:
            grouped.append(step)
    return grouped


def _cache_l_segments(steps: Sequence[Step]) -> list[Step]:
    """Replace every run of two or more L-only varying steps by a cached segment."""
    planned: list[Step] = []
    run: list[Step] = []

    def close_run() -> None:
        # Constants at either end of a run stay outside, where they fold for free.
        trailing: list[Step] = []
        while run and isinstance(run[-1], ConstantStep):
            trailing.insert(0, run.pop())
        if sum(not isinstance(step, ConstantStep) for step in run) >= 2:
            planned.append(SegmentStep(tuple(run)))
        else:
            planned.extend(run)
        planned.extend(trailing)
        run.clear()

    for step in steps:
        if _depends_on_x(step):
            close_run()
            planned.append(step)
        elif isinstance(step, ConstantStep) and not run:
            planned.append(step)
        else:
            run.append(step)
    close_run()
    return planned


IDENTITY = np.eye(4)
IDENTITY.setflags(write=False)


class _State:
    """The running product as one array ``A`` of shape (4, 3, *batch): ``A[k]`` (k < 3) is column k
    of the rotations, ``A[3]`` the translations, so that right-multiplying by a constant
    homogeneous C is the single product ``C^T A`` (rotation and translation together). A
    constant is held pending and folded in only when a varying step needs it."""

    def __init__(self, batch: tuple[int, ...]):
        self.batch = batch
        self.pending = IDENTITY
        self.stacked: np.ndarray | None = None

    @property
    def columns(self) -> np.ndarray:
        return self.stacked[:3]

    @property
    def translations(self) -> np.ndarray:
        return self.stacked[3]

    def _materialise(self, columns: np.ndarray, translations: np.ndarray) -> None:
        """Start from (3, 3, ...) and (3, ...) arrays that broadcast to the batch."""
        self.stacked = np.empty((4, 3) + self.batch)
        self.stacked[:3] = columns
        self.stacked[3] = translations

    def flush(self) -> None:
        if self.pending is IDENTITY and self.stacked is not None:
            return
        C = self.pending
        if self.stacked is None:
            ones = (1,) * len(self.batch)
            self._materialise(C[:3, :3].T.reshape((3, 3) + ones), C[:3, 3].reshape((3,) + ones))
        else:
            # new A[k] = sum_j A[j] C[j, k]; C's last row is (0, 0, 0, 1)
            self.stacked = (C.T @ self.stacked.reshape(4, -1)).reshape(self.stacked.shape)
        self.pending = IDENTITY

    def apply_transform(self, G: BatchTransform) -> None:
        """Right-multiply by per-sample transforms (shape (3, 3, N), broadcast over the batch)."""
        if self.stacked is None:
            # First varying factor: pending · G, a constant times a batch.
            R, t = self.pending[:3, :3], self.pending[:3, 3]
            middle = (1,) * (len(self.batch) - 1)  # population axes before the sample axis
            columns = np.matmul(R, G.columns)
            translations = R @ G.translations + t[:, None]
            self._materialise(
                columns.reshape((3, 3) + middle + columns.shape[-1:]),
                translations.reshape((3,) + middle + translations.shape[-1:]),
            )
            self.pending = IDENTITY
            return
        self.flush()
        M = self.stacked
        new = np.empty_like(M)
        for k in range(3):
            g = G.columns[k]
            np.multiply(M[0], g[0], out=new[k])
            new[k] += M[1] * g[1]
            new[k] += M[2] * g[2]
        t = G.translations
        np.multiply(M[0], t[0], out=new[3])
        new[3] += M[1] * t[1]
        new[3] += M[2] * t[2]
        new[3] += M[3]
        self.stacked = new

    def rotate(self, axis: int, c: np.ndarray, s: np.ndarray, sign: float = 1.0) -> None:
        """Right-multiply by rotations about a coordinate axis by angles whose cosines are c and
        sines sign * s (sign -1: the inverse rotations, without negating s)."""
        i, j = (axis + 1) % 3, (axis + 2) % 3
        column_i, column_j = self.stacked[i], self.stacked[j]
        # In place, six operations: new_i = c_i c + c_j s, new_j = c_j c - c_i s (sign +1).
        scratch = column_i * s
        column_i *= c
        moved = column_j * s
        if sign > 0:
            column_i += moved
        else:
            column_i -= moved
        column_j *= c
        if sign > 0:
            column_j -= scratch
        else:
            column_j += scratch


def _x_part(value: AffineParameter, x: np.ndarray, mode: str) -> tuple[float | np.ndarray, list[Term]]:
    """The X-dependent part of a parameter and its L terms.

    The X part is a scalar (one X), (N,) (one X per sample) or (P, 1) (a
    population of P individuals, each evaluated on every sample).
    """
    base: float | np.ndarray = value.offset
    l_terms = []
    for term in value.terms:
        if term.source == "x":
            if mode == "single":
                component = x[term.index]
            elif mode == "per_sample":
                component = x[:, term.index]
            else:
                component = x[:, term.index, None]
            base = base + term.coefficient * component
        else:
            l_terms.append(term)
    return base, l_terms


def _evaluate_steps(steps: Sequence[Step], x: np.ndarray, samples: Samples, mode: str = "single") -> BatchTransform:
    batch = (x.shape[0], samples.count) if mode == "population" else (samples.count,)
    state = _State(batch)
    for step in steps:
        if isinstance(step, ConstantStep):
            state.pending = state.pending @ step.matrix
        elif isinstance(step, SegmentStep):
            state.apply_transform(samples.segment(step))
        elif isinstance(step, TranslationStep):
            amounts = []
            for axis, value in step.moves:
                base, l_terms = _x_part(value, x, mode)
                for term in l_terms:
                    base = base + term.coefficient * samples.columns[term.index]
                amounts.append((axis, base))
            if all(np.ndim(amount) == 0 for _, amount in amounts):
                for axis, amount in amounts:
                    state.pending = state.pending @ _axis_matrix("translation", axis, float(amount))
                continue
            state.flush()
            for axis, amount in amounts:
                state.stacked[3] += state.stacked[axis] * amount
        else:
            base, l_terms = _x_part(step.value, x, mode)
            if not l_terms and np.ndim(base) == 0:
                state.pending = state.pending @ _axis_matrix(step.kind, step.axis, float(base))
                continue
            if len(l_terms) == 1 and abs(l_terms[0].coefficient) == 1.0:
                cos_d, sin_d = samples.trig(l_terms[0].index)
                sign = l_terms[0].coefficient
                if np.ndim(base) == 0:
                    # R(a ± d) = R(± d) R(a) about one axis: rotate by the L sample d with its
                    # cached trig, and hold R(a), a constant for this X, pending with the next
                    # constants (a joint angle and its zero offset cost one rotation).
                    state.flush()
                    state.rotate(step.axis, cos_d, sin_d, sign)
                    if base != 0.0:
                        state.pending = _axis_matrix("rotation", step.axis, float(base))
                    continue
                # cos(a ± d) and sin(a ± d) per sample (a varies with the sample's X).
                ca, sa = np.cos(base), np.sin(base)
                c = ca * cos_d - (sign * sa) * sin_d
                s = sa * cos_d + (sign * ca) * sin_d
            else:
                angle = base
                for term in l_terms:
                    angle = angle + term.coefficient * samples.columns[term.index]
                c, s = np.cos(angle), np.sin(angle)
            state.flush()
            state.rotate(step.axis, c, s)
    state.flush()
    return BatchTransform(state.columns, state.translations)


@dataclass
class BatchTransform:
    """N rigid transforms: ``columns[k]`` is column k of the rotations, shape (3, 3, N).

    ``coordinates``, when set, maps the translations (3, *batch) to the translation part of
    :meth:`poses` (a relation whose pose is not Cartesian: a point on a sphere)."""

    columns: np.ndarray
    translations: np.ndarray
    coordinates: object = None

    def matrices(self) -> np.ndarray:
        """The transforms as (*batch, 4, 4) homogeneous matrices."""
        batch = self.translations.shape[1:]
        T = np.zeros(batch + (4, 4))
        T[..., :3, :3] = np.moveaxis(self.columns, (0, 1), (-1, -2))
        T[..., :3, 3] = np.moveaxis(self.translations, 0, -1)
        T[..., 3, 3] = 1.0
        return T

    def poses(self) -> np.ndarray:
        """The transforms as (*batch, 6) pose vectors (rpy as in :mod:`bcad.kinematics.se3`)."""
        M = self.columns
        rx = np.arctan2(M[1, 2], M[2, 2])
        ry = np.arctan2(-M[0, 2], np.hypot(M[0, 0], M[0, 1]))
        rz = np.arctan2(M[0, 1], M[0, 0])
        t = self.translations if self.coordinates is None else self.coordinates(self.translations)
        return np.stack([t[0], t[1], t[2], rx, ry, rz], axis=-1)


def compose(first: BatchTransform, second: BatchTransform) -> BatchTransform:
    """The transforms ``first · second`` (R = R1 R2, t = R1 t2 + t1), batch by batch
    (a batch of one broadcasts against N)."""
    # columns[k, i] = R[i, k]: column k of R1 R2 is R1 applied to column k of R2.
    columns = np.einsum("ji...,kj...->ki...", first.columns, second.columns)
    translations = np.einsum("ji...,j...->i...", first.columns, second.translations) + first.translations
    return BatchTransform(columns, translations)


def _bound(coordinates, samples):
    """A chain's coordinates for one batch: those that read the samples (an uncertain radius)
    are bound to them."""
    return coordinates.bind(samples) if hasattr(coordinates, "bind") else coordinates


class Chain:
    """A compiled path of links, evaluated for N samples at once."""

    def __init__(self, links: Sequence[tuple[LinkTransform, bool]], coordinates=None):
        #: the map of :attr:`BatchTransform.coordinates` for this chain's transforms (None: Cartesian)
        self.coordinates = coordinates
        #: the links it was built from, each with whether it is used forward
        self.links: tuple[tuple[LinkTransform, bool], ...] = tuple(links)
        steps: list[Step] = []
        for link, forward in links:
            steps.extend(link_steps(link, forward))
        #: the constants and axis steps, before they are planned for batches (analytic derivatives
        #: in L walk these: :mod:`bcad.kinematics.jacobian`)
        self.folded_steps: list[Step] = fold_steps(steps)
        self.steps: list[Step] = _cache_l_segments(_group_translations(self.folded_steps))

    def evaluate(self, x: np.ndarray, samples: Samples) -> BatchTransform:
        """The chain's transform for unknowns ``x`` (shape (nX,) or (N, nX)) and L samples.

        Large batches are evaluated in blocks of :data:`BLOCK` samples: a block's working
        arrays stay in the core's cache, where the whole batch's would stream through memory
        once per step (measured on the RX90 example: see ``bench/kinematics.py``)."""
        x = np.asarray(x, dtype=float)
        mode = "per_sample" if x.ndim == 2 else "single"
        n = samples.count
        if n <= BLOCK:
            result = _evaluate_steps(self.steps, x, samples, mode)
        else:
            columns = np.empty((3, 3, n))
            translations = np.empty((3, n))
            for start in range(0, n, BLOCK):
                block = slice(start, min(start + BLOCK, n))
                part = _evaluate_steps(
                    self.steps, x[block] if mode == "per_sample" else x, _SampleBlock(samples, block), mode
                )
                columns[:, :, block] = part.columns
                translations[:, block] = part.translations
            result = BatchTransform(columns, translations)
        result.coordinates = _bound(self.coordinates, samples)
        return result

    def evaluate_population(self, population: np.ndarray, samples: Samples) -> BatchTransform:
        """Every individual of a population (P, nX) on every sample: batch shape (P, N)."""
        result = _evaluate_steps(self.steps, np.asarray(population, dtype=float), samples, "population")
        result.coordinates = _bound(self.coordinates, samples)
        return result
