"""The typical error beside the worst one: clearances as uniform distributions.

The errors are sampled on the exact model, P^-1 prod_j exp(dS_j) S_j (Eq. 10-11): each joint's
radial clearances uniform on their discs, its axial ones uniform on their intervals
(:func:`sample_screws`), in batches so that memory does not grow with the sample count. From
them: percentiles of the rotation and translation errors with their standard errors (the
binomial interval of the order statistic), the yield of a spec, P(error <= spec), with its
standard error (a plain Monte Carlo: every sample counts, the effective sample size is N), and
each joint's first-order share of the mean squared error.
"""

from __future__ import annotations

import numpy as np

from bcad.worstcase.error_map import ErrorMap

#: samples evaluated at once (screws of n joints: 48 n bytes each)
BATCH = 20_000
#: the percentiles reported (the median, 95 % and 3 sigma)
PERCENTILES = {"p50": 0.5, "p95": 0.95, "p99.7": 0.997}


def sample_screws(error_map: ErrorMap, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` error screws (count, n, 6) [dr; dt] per joint: uniform on each joint's clearance
    discs (rx, ry and tx, ty) and intervals (rz and tz)."""
    n = error_map.joints
    screws = np.zeros((count, n, 6))
    for slots, column in (((0, 1), 0), ((3, 4), 2)):
        radius = error_map.clearance[:, column]
        r = radius[None, :] * np.sqrt(rng.random((count, n)))
        phi = 2 * np.pi * rng.random((count, n))
        screws[:, :, slots[0]], screws[:, :, slots[1]] = r * np.cos(phi), r * np.sin(phi)
    for slot, column in ((2, 1), (5, 3)):
        half = error_map.clearance[:, column]
        screws[:, :, slot] = half[None, :] * rng.uniform(-1.0, 1.0, (count, n))
    return screws


def exact_error_vectors(error_map: ErrorMap, screws: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotation vectors (axis times angle) and translations of dP = P^-1 P' (Eq. 11) for
    error screws (B, n, 6): each (B, 3)."""
    from bcad.worstcase.exact import error_transforms, rotation_sine_cosine

    delta = error_transforms(error_map, screws)
    skew, cosine = rotation_sine_cosine(delta[:, :3, :3])
    sine = np.linalg.norm(skew, axis=-1)
    angle = np.arctan2(sine, cosine)
    factor = np.where(sine > 1e-300, angle / np.where(sine > 1e-300, sine, 1.0), 1.0)
    return skew * factor[:, None], delta[:, :3, 3].copy()


def error_samples(
    error_map: ErrorMap, name: str, length_unit: str, samples: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Sampled exact end-effector errors dP for uniformly distributed clearances: rotation vectors
    (axis times angle, rad) and translations, each (N, 3)."""
    rotations, translations = [], []
    for start in range(0, samples, BATCH):
        rotation, translation = exact_error_vectors(
            error_map, sample_screws(error_map, min(BATCH, samples - start), rng)
        )
        rotations.append(rotation)
        translations.append(translation)
    return np.vstack(rotations), np.vstack(translations)


def percentile_with_se(sorted_values: np.ndarray, q: float) -> tuple[float, float]:
    """The q-quantile of sorted samples and its standard error: half the spread between the order
    statistics one binomial standard deviation either side of N q."""
    n = len(sorted_values)
    spread = np.sqrt(n * q * (1.0 - q))
    low = int(np.clip(np.floor(n * q - spread), 0, n - 1))
    high = int(np.clip(np.ceil(n * q + spread), 0, n - 1))
    return float(np.quantile(sorted_values, q)), float(0.5 * (sorted_values[high] - sorted_values[low]))


def joint_shares(error_map: ErrorMap) -> list[dict[str, float]]:
    """Each joint's first-order share of the mean squared rotation and translation errors: the
    errors are sum over joints and blocks of M_j's block rows (transposed) times the block's
    variables (:data:`bcad.worstcase.branch_and_bound.BLOCKS`: dp_r = sum_j R_j^T dr_j and
    dp_t = sum_j (R_j^T dt_j + B_j dr_j), B_j = ([p_j]x R_j)^T, and for absolute angles a link's
    turn through rows 6-7), independent variables, a uniform disc of radius rho giving rho^2 / 4
    per axis and an interval of half-width zeta giving zeta^2 / 3."""
    from bcad.worstcase.branch_and_bound import BLOCKS

    shares = []
    totals = {"rotation": 0.0, "translation": 0.0}
    for j in range(error_map.joints):
        entry = {}
        for kind in totals:
            value = 0.0
            for rows, column, block in BLOCKS[kind]:
                radius = error_map.clearance[j, column]
                per_axis = radius**2 / 4 if block == "disc" else radius**2 / 3
                value += per_axis * float(np.sum(error_map.M_float[j, list(rows), :] ** 2))
            entry[kind] = value
            totals[kind] += value
        shares.append(entry)
    for entry in shares:
        for kind, total in totals.items():
            entry[kind] = entry[kind] / total if total > 0 else 0.0
    return shares


def error_statistics(
    error_map: ErrorMap,
    name: str,
    length_unit: str,
    samples: int,
    rng: np.random.Generator,
    spec: dict[str, float] | None = None,
) -> dict:
    """Rotation and translation errors of the exact dP for uniformly distributed clearances: mean,
    percentiles with standard errors, the largest sampled; each joint's share; and, with a
    ``spec`` ({"rotation": rad, "translation": length, "dx": length, ...}: norms, and
    displacements along the base frame's axes), its yield."""
    rotations, translations = error_samples(error_map, name, length_unit, samples, rng)
    rotation = np.linalg.norm(rotations, axis=1)
    translation = np.linalg.norm(translations, axis=1)

    def summary(values: np.ndarray) -> dict:
        ordered = np.sort(values)
        entry = {"mean": float(values.mean()), "mean_se": float(values.std() / np.sqrt(len(values)))}
        for key, q in PERCENTILES.items():
            entry[key], entry[f"{key}_se"] = percentile_with_se(ordered, q)
        entry.update(
            median=entry["p50"], p95=entry["p95"], p99=float(np.quantile(ordered, 0.99)), max_sampled=float(ordered[-1])
        )
        return entry

    document = {
        "samples": samples,
        "model": "exact",
        "rotation": summary(rotation),
        "translation": summary(translation),
        "joints": joint_shares(error_map),
    }
    if spec:
        within = np.ones(samples, dtype=bool)
        if "rotation" in spec:
            within &= rotation <= spec["rotation"]
        if "translation" in spec:
            within &= translation <= spec["translation"]
        from bcad.worstcase.directional import tool_direction

        for key in sorted(set(spec) - {"rotation", "translation"}):
            # a displacement along a base axis: u . t, u that axis in F_{n+1} (bcad.worstcase.directional)
            within &= translations @ tool_direction(error_map, key) <= spec[key]
        document["yield"] = yield_estimate(int(np.count_nonzero(within)), samples)
        document["yield"]["spec"] = dict(spec)
    return document


def yield_estimate(inside: int, samples: int) -> dict:
    """P(error <= spec) from ``inside`` of ``samples``: the share, its standard error and the exact
    (Clopper-Pearson) 95 % interval. The se is Agresti and Coull's, sqrt(p~(1 - p~) / N) with
    p~ = (k + 2) / (N + 4): where every sample met the spec the plain binomial se is 0, which
    says nothing; this one is about 1.4 / N there, and the interval's lower end (about 1 - 3.7 / N)
    says how far below 1 the yield may be."""
    from scipy.special import betaincinv  # the beta distribution's quantile (scipy.stats costs 0.3 s to import)

    share = inside / samples
    adjusted = (inside + 2.0) / (samples + 4.0)
    low = 0.0 if inside == 0 else float(betaincinv(inside, samples - inside + 1, 0.025))
    high = 1.0 if inside == samples else float(betaincinv(inside + 1, samples - inside, 0.975))
    return {
        "value": share,
        "se": float(np.sqrt(adjusted * (1.0 - adjusted) / samples)),
        "interval_95": [low, high],
        "effective_samples": samples,
    }
