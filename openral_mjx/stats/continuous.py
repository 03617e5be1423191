"""A continuous per-episode value compared on common seeds: the mean of B - A with a Student t
interval (steps to success, total reward).

Pairing by seed removes the between-seed variation, as for success, so the differences of the
shared seeds are one sample and the interval is the one-sample t interval of their mean. It is
exact for normal differences; for others it leans on the central limit theorem, which is slow
for skewed ones: simulated at n = 30, the 95% interval covers 95.0% for normal differences,
about 92.5% for exponential ones and 88% for log-normal ones (sigma 1)
(`tests/stats/test_continuous.py`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from scipy import stats as sps

from openral_mjx.core.errors import ConfigError
from openral_mjx.stats.intervals import check_confidence, scalar_or_array


def t_interval(values: Any, confidence: float = 0.95) -> tuple[Any, Any]:
    """Student t interval for the mean of `values` (a sample along the last axis, at least 2
    values; leading axes are independent samples): mean +- t_{n-1} s / sqrt(n)."""
    check_confidence(confidence)
    x = np.asarray(values, np.float64)
    n = x.shape[-1]
    if n < 2:
        raise ConfigError(f"a t interval needs at least 2 values, got {n}")
    mean = x.mean(axis=-1)
    half = sps.t.ppf(0.5 + confidence / 2, n - 1) * x.std(axis=-1, ddof=1) / np.sqrt(n)
    return scalar_or_array(mean - half), scalar_or_array(mean + half)


@dataclasses.dataclass(frozen=True)
class PairedMean:
    """The mean of B - A of a per-episode value over `n` paired seeds, with its t interval
    (None for fewer than 2 seeds)."""

    metric: str
    n: int
    mean: float
    confidence: float
    ci_low: float | None
    ci_high: float | None


def paired_mean_difference(
    a: Any, b: Any, metric: str, confidence: float = 0.95
) -> PairedMean | None:
    """B - A of a value per common seed (element i of both = one seed): its mean and t
    interval; None when no seed is shared."""
    check_confidence(confidence)
    va, vb = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if va.shape != vb.shape or va.ndim != 1:
        raise ConfigError(f"paired values need two equal 1-D arrays, got {va.shape}, {vb.shape}")
    if va.size == 0:
        return None
    diff = vb - va
    low, high = t_interval(diff, confidence) if diff.size >= 2 else (None, None)
    return PairedMean(metric, int(diff.size), float(diff.mean()), confidence, low, high)


def format_paired_mean(pm: PairedMean, where: str) -> str:
    """One line: the mean of B - A `where` it was taken, and its t interval."""
    text = f"{pm.metric} {where}: mean B - A = {pm.mean:+.4g}"
    if pm.ci_low is None:
        return text + " (one seed: no interval)"
    level = round(100 * pm.confidence)
    return text + f", {level}% t interval [{pm.ci_low:+.4g}, {pm.ci_high:+.4g}]"
