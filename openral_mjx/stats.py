"""Success-rate statistics: binomial intervals, sample sizes, and comparisons of two policies.

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

import dataclasses
import math
from typing import Any

import numpy as np
from scipy import stats as sps

from openral_mjx.errors import ConfigError, unknown

INTERVAL_METHODS = ("wilson", "clopper-pearson")
UNPAIRED_TESTS = ("auto", "two-proportion-z", "fisher-exact")


def _scalar_or_array(x: np.ndarray) -> Any:
    return float(x) if np.ndim(x) == 0 else x


def check_confidence(confidence: float) -> None:
    if not 0 < confidence < 1:
        raise ConfigError(f"confidence must lie in (0, 1), got {confidence}")


def _check_counts(successes: Any, n: Any) -> tuple[np.ndarray, np.ndarray]:
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
    k, n = _check_counts(successes, n)
    z = z_value(confidence)
    p = k / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # Clamp tiny float excursions; exact at the boundaries.
    low = np.where(k == 0, 0.0, np.maximum(0.0, centre - half))
    high = np.where(k == n, 1.0, np.minimum(1.0, centre + half))
    return _scalar_or_array(low), _scalar_or_array(high)


def clopper_pearson_interval(successes: Any, n: Any, confidence: float = 0.95) -> tuple[Any, Any]:
    """Clopper-Pearson ("exact") interval: inverts two one-sided binomial tests.

    Coverage is at least `confidence` for every rate and n (conservative; wider than Wilson).
    Broadcasts over arrays.
    """
    k, n = _check_counts(successes, n)
    tail = (1 - confidence) / 2
    z_value(confidence)  # validates
    with np.errstate(invalid="ignore", divide="ignore"):
        low = np.where(k > 0, sps.beta.ppf(tail, np.maximum(k, 1), n - k + 1), 0.0)
        high = np.where(k < n, sps.beta.ppf(1 - tail, k + 1, np.maximum(n - k, 1)), 1.0)
    return _scalar_or_array(low), _scalar_or_array(high)


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


# --- two policies -----------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Comparison:
    """Policy B against policy A: the difference of success rates B - A, an interval for it,
    and the p-value of a test of equal rates.

    Paired comparisons (same seeds) carry the 2x2 table of outcomes per seed: `both`,
    `only_a`, `only_b` (the discordant pairs the McNemar test uses) and `neither`.
    """

    paired: bool
    test: str
    interval_method: str
    confidence: float
    n_a: int
    successes_a: int
    n_b: int
    successes_b: int
    difference: float
    ci_low: float
    ci_high: float
    p_value: float
    both: int | None = None
    only_a: int | None = None
    only_b: int | None = None
    neither: int | None = None

    @property
    def rate_a(self) -> float:
        return self.successes_a / self.n_a

    @property
    def rate_b(self) -> float:
        return self.successes_b / self.n_b


def mcnemar_exact_pvalue(only_a: Any, only_b: Any) -> Any:
    """Exact (conditional) McNemar test: two-sided binomial test of `only_b` out of the
    discordant pairs at 1/2. Its level is at most alpha for every n and discordance rate."""
    b, c = np.asarray(only_a), np.asarray(only_b)
    m = b + c
    p = np.minimum(1.0, 2 * sps.binom.cdf(np.minimum(b, c), m, 0.5))
    return _scalar_or_array(np.where(m == 0, 1.0, p))


def newcombe_paired_interval(
    both: Any, only_a: Any, only_b: Any, neither: Any, confidence: float = 0.95
) -> tuple[Any, Any]:
    """Interval for the paired difference rate_b - rate_a: Newcombe's square-and-add of the two
    marginal Wilson intervals, with the correlation estimate phi corrected as in Fagerland,
    Lydersen & Laake (2017, ch. 8). Broadcasts over arrays."""
    a, c, b, d = (np.asarray(x, np.float64) for x in (both, only_a, only_b, neither))
    n = a + b + c + d
    # Group 1 = B (successes a + b), group 2 = A (successes a + c): delta = (b - c) / n.
    p1, p2 = (a + b) / n, (a + c) / n
    l1, u1 = (np.asarray(x) for x in wilson_interval(a + b, n, confidence))
    l2, u2 = (np.asarray(x) for x in wilson_interval(a + c, n, confidence))
    prod = (a + b) * (c + d) * (a + c) * (b + d)
    cross = a * d - b * c
    corrected = np.where(cross > n / 2, cross - n / 2, np.where(cross >= 0, 0.0, cross))
    with np.errstate(invalid="ignore", divide="ignore"):
        phi = np.where(prod > 0, corrected / np.sqrt(np.where(prod > 0, prod, 1.0)), 0.0)
    delta = p1 - p2
    low = delta - np.sqrt(
        np.maximum(0.0, (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2)
    )
    high = delta + np.sqrt(
        np.maximum(0.0, (u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2)
    )
    return _scalar_or_array(np.maximum(-1.0, low)), _scalar_or_array(np.minimum(1.0, high))


def newcombe_interval(
    successes_a: Any, n_a: Any, successes_b: Any, n_b: Any, confidence: float = 0.95
) -> tuple[Any, Any]:
    """Interval for rate_b - rate_a from independent samples: Newcombe's hybrid score
    (square-and-add of the two Wilson intervals; his method 10). Broadcasts over arrays."""
    la, ua = (np.asarray(x) for x in wilson_interval(successes_a, n_a, confidence))
    lb, ub = (np.asarray(x) for x in wilson_interval(successes_b, n_b, confidence))
    pa = np.asarray(successes_a, np.float64) / np.asarray(n_a)
    pb = np.asarray(successes_b, np.float64) / np.asarray(n_b)
    delta = pb - pa
    low = delta - np.sqrt((pb - lb) ** 2 + (ua - pa) ** 2)
    high = delta + np.sqrt((ub - pb) ** 2 + (pa - la) ** 2)
    return _scalar_or_array(low), _scalar_or_array(high)


def two_proportion_z_pvalue(successes_a: Any, n_a: Any, successes_b: Any, n_b: Any) -> Any:
    """Two-sided pooled two-proportion z test (the score test); 1 when no variance."""
    ka, na, kb, nb = (np.asarray(x, np.float64) for x in (successes_a, n_a, successes_b, n_b))
    pooled = (ka + kb) / (na + nb)
    var = pooled * (1 - pooled) * (1 / na + 1 / nb)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = (kb / nb - ka / na) / np.sqrt(np.where(var > 0, var, 1.0))
    return _scalar_or_array(np.where(var > 0, 2 * sps.norm.sf(np.abs(z)), 1.0))


def _unpaired_test(ka: int, na: int, kb: int, nb: int, test: str) -> str:
    if test not in UNPAIRED_TESTS:
        raise unknown("unpaired test", test, UNPAIRED_TESTS)
    if test != "auto":
        return test
    # The z test's normal approximation wants every expected cell count >= 5 (Cochran).
    pooled = (ka + kb) / (na + nb)
    expected = min(n * r for n in (na, nb) for r in (pooled, 1 - pooled))
    return "two-proportion-z" if expected >= 5 else "fisher-exact"


def paired_comparison(success_a: Any, success_b: Any, confidence: float = 0.95) -> Comparison:
    """Compare per-seed outcomes on common seeds (element i of both arrays = the same seed):
    exact McNemar test, Newcombe paired interval for rate_b - rate_a."""
    a, b = np.asarray(success_a, bool), np.asarray(success_b, bool)
    if a.shape != b.shape or a.ndim != 1 or a.size == 0:
        raise ConfigError(
            f"paired outcomes need two equal, non-empty 1-D arrays, got {a.shape}, {b.shape}"
        )
    check_confidence(confidence)
    both, only_a = int((a & b).sum()), int((a & ~b).sum())
    only_b, neither = int((~a & b).sum()), int((~a & ~b).sum())
    low, high = newcombe_paired_interval(both, only_a, only_b, neither, confidence)
    n = a.size
    return Comparison(
        paired=True,
        test="mcnemar-exact",
        interval_method="newcombe-paired",
        confidence=confidence,
        n_a=n,
        successes_a=both + only_a,
        n_b=n,
        successes_b=both + only_b,
        difference=(only_b - only_a) / n,
        ci_low=low,
        ci_high=high,
        p_value=mcnemar_exact_pvalue(only_a, only_b),
        both=both,
        only_a=only_a,
        only_b=only_b,
        neither=neither,
    )


def unpaired_comparison(
    successes_a: int,
    n_a: int,
    successes_b: int,
    n_b: int,
    confidence: float = 0.95,
    test: str = "auto",
) -> Comparison:
    """Compare two independent samples: Newcombe hybrid-score interval for rate_b - rate_a and
    a two-proportion z test, or Fisher's exact test (`auto`: Fisher when an expected cell
    count is below 5, where the z test's normal approximation is poor)."""
    _check_counts(successes_a, n_a)
    _check_counts(successes_b, n_b)
    check_confidence(confidence)
    chosen = _unpaired_test(successes_a, n_a, successes_b, n_b, test)
    if chosen == "fisher-exact":
        table = [[successes_b, n_b - successes_b], [successes_a, n_a - successes_a]]
        p = float(sps.fisher_exact(table).pvalue)
    else:
        p = two_proportion_z_pvalue(successes_a, n_a, successes_b, n_b)
    low, high = newcombe_interval(successes_a, n_a, successes_b, n_b, confidence)
    return Comparison(
        paired=False,
        test=chosen,
        interval_method="newcombe",
        confidence=confidence,
        n_a=int(n_a),
        successes_a=int(successes_a),
        n_b=int(n_b),
        successes_b=int(successes_b),
        difference=successes_b / n_b - successes_a / n_a,
        ci_low=low,
        ci_high=high,
        p_value=p,
    )


__all__ = [
    "INTERVAL_METHODS",
    "UNPAIRED_TESTS",
    "Comparison",
    "binomial_interval",
    "clopper_pearson_interval",
    "episodes_for_halfwidth",
    "mcnemar_exact_pvalue",
    "newcombe_interval",
    "newcombe_paired_interval",
    "paired_comparison",
    "two_proportion_z_pvalue",
    "unpaired_comparison",
    "wilson_interval",
]
