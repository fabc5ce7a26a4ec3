"""The statistics the checks use: autocorrelation times, goodness-of-fit tests, pooled bins."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import stats


def integrated_time(x: Sequence[float]) -> float:
    """Integrated autocorrelation time 1 + 2 sum_t rho_t of a series (Geyer's initial
    monotone sequence estimator); 1 for independent draws and for a constant series."""
    x = np.asarray(x, dtype=float)
    n = len(x)
    if n < 4:
        return 1.0
    x = x - x.mean()
    if not np.any(x):
        return 1.0
    f = np.fft.rfft(x, 2 * n)
    acov = np.fft.irfft(f * np.conj(f))[:n]
    rho = acov / acov[0]
    m = (n - 1) // 2
    pairs = rho[0 : 2 * m : 2] + rho[1 : 2 * m : 2]
    stop = np.flatnonzero(pairs <= 0.0)
    pairs = pairs[: stop[0] if len(stop) else len(pairs)]
    pairs = np.minimum.accumulate(pairs)
    return max(1.0, float(-1.0 + 2.0 * pairs.sum()))


def pool_bins(expected: Sequence[float], minimum: float = 5.0) -> list[list[int]]:
    """Groups of adjacent bins whose expected counts each add up to at least ``minimum``
    (the last group takes any remainder), so that the chi-square approximation holds."""
    groups: list[list[int]] = []
    current: list[int] = []
    total = 0.0
    for i, e in enumerate(expected):
        current.append(i)
        total += e
        if total >= minimum:
            groups.append(current)
            current, total = [], 0.0
    if current:
        if groups:
            groups[-1].extend(current)
        else:
            groups.append(current)
    return groups


def chisquare_gof(observed: Sequence[float], probs: Sequence[float]) -> tuple[float, float]:
    """Chi-square goodness of fit of bin counts to bin probabilities (which sum to one),
    adjacent bins pooled to expected counts of at least 5. Returns (statistic, p)."""
    observed = np.asarray(observed, dtype=float)
    probs = np.asarray(probs, dtype=float)
    n = observed.sum()
    groups = pool_bins(n * probs)
    if n == 0 or len(groups) < 2:
        return 0.0, 1.0
    o = np.array([observed[g].sum() for g in groups])
    e = np.array([n * probs[g].sum() for g in groups])
    e *= o.sum() / e.sum()  # rounding only
    stat, p = stats.chisquare(o, e)
    return float(stat), float(p)


def chisquare_two_sample(a: Sequence[Any], b: Sequence[Any]) -> tuple[float, float]:
    """Chi-square test that two samples of a discrete quantity have the same distribution
    (a 2 x k contingency table, adjacent values pooled to expected cells of at least 5)."""
    values = sorted(set(a) | set(b), key=lambda v: (isinstance(v, str), v))
    index = {v: i for i, v in enumerate(values)}
    table = np.zeros((2, len(values)))
    for row, sample in enumerate((a, b)):
        for v in sample:
            table[row, index[v]] += 1
    n = table.sum()
    if n == 0 or min(len(a), len(b)) == 0:
        return 0.0, 1.0
    share = table.sum(axis=1).min() / n
    groups = pool_bins(table.sum(axis=0) * share)
    if len(groups) < 2:
        return 0.0, 1.0
    pooled = np.stack([table[:, g].sum(axis=1) for g in groups], axis=1)
    stat, p, _, _ = stats.chi2_contingency(pooled, correction=False)
    return float(stat), float(p)


def poisson_gof(draws: Sequence[int], rate: float) -> tuple[float, float]:
    draws = np.asarray(draws, dtype=int)
    top = int(draws.max()) + 1 if len(draws) else 1
    observed = np.bincount(draws, minlength=top + 1)[: top + 1].astype(float)
    probs = stats.poisson.pmf(np.arange(top + 1), rate)
    probs[-1] = stats.poisson.sf(top - 1, rate)  # the last bin is the tail, N >= top
    return chisquare_gof(observed, probs)


def mean_sd(x) -> str:
    x = np.asarray(x, dtype=float)
    if len(x) == 0:
        return "no draws"
    return f"mean {x.mean():.3f}, sd {x.std():.3f}"


def shares(values, labels) -> str:
    n = max(len(values), 1)
    return " ".join(f"{v} {sum(1 for x in values if x == v) / n:.2f}" for v in labels)


def seed_sequence(seed) -> np.random.SeedSequence:
    return seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
