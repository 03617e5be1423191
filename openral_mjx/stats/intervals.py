"""Success-rate intervals and sample sizes for one policy: Wilson, Clopper-Pearson.

Closed forms where they exist (Wilson, Newcombe's square-and-add intervals for differences),
scipy for exact distributions (Clopper-Pearson through the beta quantile, the exact McNemar
test as a binomial test on the discordant pairs, Fisher's exact test). Interval and test
functions broadcast over numpy arrays, so the tests can compute coverage and level exactly over
every possible outcome instead of sampling.

References: Brown, Cai & DasGupta (2001), "Interval estimation for a binomial proportion";
Newcombe (1998), Statist. Med. 17: 873-890 (unpaired) and 2635-2650 (paired); Fagerland,
Lydersen & Laake (2017), "Statistical Analysis of Contingency Tables", ch. 4 and 8.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import stats as sps

from openral_mjx.core.errors import ConfigError, unknown

INTERVAL_METHODS = ("wilson", "clopper-pearson")


def scalar_or_array(x: np.ndarray) -> Any:
    return float(x) if np.ndim(x) == 0 else x


def check_confidence(confidence: float) -> None:
    if not 0 < confidence < 1:
        raise ConfigError(f"confidence must lie in (0, 1), got {confidence}")


def check_binomial_counts(successes: Any, n: Any) -> tuple[np.ndarray, np.ndarray]:
    k, n = np.asarray(successes), np.asarray(n)
    if np.any(n <= 0):
        raise ConfigError(f"n must be positive, got {n}")
    if np.any((k < 0) | (k > n)):
        raise ConfigError(f"successes must lie in [0, n], got {k} of {n}")
    return k.astype(np.float64), n.astype(np.float64)


def z_value(confidence: float) -> float:
    """The two-sided standard-normal quantile for `confidence` (1.96 at 0.95)."""
    check_confidence(confidence)
    return float(sps.norm.ppf(0.5 + confidence / 2))


def wilson_interval(successes: Any, n: Any, confidence: float = 0.95) -> tuple[Any, Any]:
    """Wilson score interval for a binomial proportion (no continuity correction).

    Coverage oscillates close to nominal for any n (Brown, Cai & DasGupta 2001), unlike the
    normal-approximation interval; exact at 0 and n successes. Broadcasts over arrays.
    """
    k, n = check_binomial_counts(successes, n)
    z = z_value(confidence)
    p = k / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # Clamp tiny float excursions; exact at the boundaries.
    low = np.where(k == 0, 0.0, np.maximum(0.0, centre - half))
    high = np.where(k == n, 1.0, np.minimum(1.0, centre + half))
    return scalar_or_array(low), scalar_or_array(high)


def clopper_pearson_interval(successes: Any, n: Any, confidence: float = 0.95) -> tuple[Any, Any]:
    """Clopper-Pearson ("exact") interval: inverts two one-sided binomial tests.

    Coverage is at least `confidence` for every rate and n (conservative; wider than Wilson).
    Broadcasts over arrays.
    """
    k, n = check_binomial_counts(successes, n)
    tail = (1 - confidence) / 2
    z_value(confidence)  # validates
    with np.errstate(invalid="ignore", divide="ignore"):
        low = np.where(k > 0, sps.beta.ppf(tail, np.maximum(k, 1), n - k + 1), 0.0)
        high = np.where(k < n, sps.beta.ppf(1 - tail, k + 1, np.maximum(n - k, 1)), 1.0)
    return scalar_or_array(low), scalar_or_array(high)


def binomial_interval(
    successes: Any, n: Any, confidence: float = 0.95, method: str = "wilson"
) -> tuple[Any, Any]:
    """The interval of `method` (`wilson` or `clopper-pearson`)."""
    if method == "wilson":
        return wilson_interval(successes, n, confidence)
    if method == "clopper-pearson":
        return clopper_pearson_interval(successes, n, confidence)
    raise unknown("interval method", method, INTERVAL_METHODS)


def episodes_for_halfwidth(
    halfwidth: float, rate: float = 0.5, confidence: float = 0.95, method: str = "wilson"
) -> int:
    """Fewest episodes whose interval half-width is at most `halfwidth` when the observed rate
    is `rate` (default 0.5, the worst case: enough whatever the rate turns out to be).

    Wilson: the smallest n solving the half-width quadratic (closed form). Clopper-Pearson:
    bisection on n with `rate * n` successes (the beta quantiles take fractional counts).
    """
    if not 0 < halfwidth < 0.5:
        raise ConfigError(f"halfwidth must lie in (0, 0.5), got {halfwidth}")
    if not 0 <= rate <= 1:
        raise ConfigError(f"rate must lie in [0, 1], got {rate}")
    z = z_value(confidence)
    if method == "wilson":
        # Half-width h = z sqrt(pq n + z^2/4) / (n + z^2); squaring gives a quadratic in n.
        pq, h2, z2 = rate * (1 - rate), halfwidth**2, z * z
        b = 2 * h2 * z2 - z2 * pq
        c = h2 * z2 * z2 - z2 * z2 / 4
        n = (-b + math.sqrt(b * b - 4 * h2 * c)) / (2 * h2)
        return max(1, math.ceil(n - 1e-9))
    if method != "clopper-pearson":
        raise unknown("interval method", method, INTERVAL_METHODS)
    tail = (1 - confidence) / 2

    def half(n: float) -> float:
        k = rate * n
        low = sps.beta.ppf(tail, k, n - k + 1) if k > 0 else 0.0
        high = sps.beta.ppf(1 - tail, k + 1, n - k) if k < n else 1.0
        return (high - low) / 2 - halfwidth

    lo, hi = 1, 2
    while half(hi) > 0:
        lo, hi = hi, hi * 2
    while hi - lo > 1:  # half(lo) > 0 >= half(hi); the half-width falls with n
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if half(mid) <= 0 else (mid, hi)
    return hi if half(lo) > 0 else lo
