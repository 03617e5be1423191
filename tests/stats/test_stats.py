"""Intervals, sample sizes and comparisons against scipy, published values, exact coverage and
level computations over every outcome, and binomial simulation.

Coverage bands are those of the literature: Clopper-Pearson at or above nominal everywhere;
Wilson close to nominal on average, with the known dips near p = 0 and 1 (Brown, Cai &
DasGupta 2001, Statist. Sci. 16: 101-133, sec. 4.1); the exact McNemar test never above its
level; Newcombe's intervals close to nominal (Newcombe 1998; Fagerland et al. 2014).
"""

import numpy as np
import pytest
from scipy import stats as sps

from openral_mjx.core.errors import ConfigError
from openral_mjx.stats import (
    binomial_interval,
    clopper_pearson_interval,
    episodes_for_halfwidth,
    mcnemar_exact_pvalue,
    newcombe_interval,
    newcombe_paired_interval,
    paired_comparison,
    two_proportion_z_pvalue,
    unpaired_comparison,
    wilson_interval,
)

NS = (10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10000)
# A dense grid of rates across (0, 1), offset so no point sits on a special value.
RATES = np.linspace(0.0, 1.0, 20001)[1:-1] + 1.234e-6


@pytest.mark.parametrize(
    "k,n", [(0, 10), (1, 10), (5, 10), (10, 10), (37, 50), (900, 1024), (3, 10000)]
)
@pytest.mark.parametrize("conf", [0.9, 0.95, 0.99])
def test_intervals_match_scipy(k, n, conf):
    for method, ours in (("wilson", wilson_interval), ("exact", clopper_pearson_interval)):
        ref = sps.binomtest(k, n).proportion_ci(confidence_level=conf, method=method)
        low, high = ours(k, n, conf)
        assert low == pytest.approx(ref.low, abs=1e-12), method
        assert high == pytest.approx(ref.high, abs=1e-12), method


def test_intervals_broadcast_like_scalars():
    k = np.arange(31)
    for method in ("wilson", "clopper-pearson"):
        low, high = binomial_interval(k, 30, 0.9, method)
        scalar = [binomial_interval(int(i), 30, 0.9, method) for i in k]
        np.testing.assert_allclose(low, [s[0] for s in scalar], rtol=0, atol=1e-15)
        np.testing.assert_allclose(high, [s[1] for s in scalar], rtol=0, atol=1e-15)


def test_bad_input_is_a_config_error():
    for args in [(1, 0), (-1, 5), (6, 5)]:
        with pytest.raises(ConfigError):
            wilson_interval(*args)
    with pytest.raises(ConfigError, match="confidence must lie in"):
        clopper_pearson_interval(1, 5, 1.0)
    with pytest.raises(ConfigError, match="unknown interval method 'wald'"):
        binomial_interval(1, 5, method="wald")
    with pytest.raises(ConfigError, match="halfwidth"):
        episodes_for_halfwidth(0.0)


def _exact_coverage(n: int, interval) -> np.ndarray:
    """P(low(K) <= p <= high(K)), K ~ Bin(n, p), for every p in RATES, exactly.

    Both bounds increase with k, so the k whose interval holds p form one run
    [first k with high >= p, last k with low <= p]: two cdf values per rate.
    """
    low, high = interval(np.arange(n + 1), n)
    assert np.all(np.diff(low) > 0) and np.all(np.diff(high) > 0)
    k_first = np.searchsorted(high, RATES, side="left")
    k_last = np.searchsorted(low, RATES, side="right") - 1
    return sps.binom.cdf(k_last, n, RATES) - sps.binom.cdf(k_first - 1, n, RATES)


@pytest.mark.parametrize("n", NS)
def test_clopper_pearson_covers_at_least_nominal(n):
    coverage = _exact_coverage(n, clopper_pearson_interval)
    assert coverage.min() >= 0.95 - 1e-9
    assert coverage.mean() < 0.99  # conservative, not vacuous


@pytest.mark.parametrize("n", NS)
def test_wilson_covers_close_to_nominal(n):
    coverage = _exact_coverage(n, wilson_interval)
    # On average over the rate, within half a point of nominal (measured 0.9500-0.9541).
    assert 0.945 <= coverage.mean() <= 0.96
    # Where n p and n (1 - p) are both >= 5, never far below (measured minimum 0.927, n = 100).
    interior = np.minimum(RATES, 1 - RATES) * n >= 5
    assert n == 10 or coverage[interior].min() >= 0.92
    # The known dips next to p = 0 and 1 (n p or n (1 - p) below ~1; as low as ~0.84 at
    # any n) stay above 0.83.
    assert coverage.min() >= 0.83


@pytest.mark.parametrize("p,n", [(0.03, 200), (0.5, 40), (0.9, 1000), (0.995, 10000)])
def test_simulated_coverage_matches_exact(p, n):
    """Many binomial experiments: the fraction of intervals that cover p agrees with the exact
    coverage within Monte-Carlo error, and lies in the band."""
    rng = np.random.default_rng(1234)
    reps = 40_000
    k = rng.binomial(n, p, size=reps)
    for interval, floor in ((wilson_interval, 0.92), (clopper_pearson_interval, 0.95)):
        low, high = interval(k, n)
        simulated = np.mean((low <= p) & (p <= high))
        lo_all, hi_all = interval(np.arange(n + 1), n)
        pmf = sps.binom.pmf(np.arange(n + 1), n, p)
        exact = pmf[(lo_all <= p) & (p <= hi_all)].sum()
        se = np.sqrt(exact * (1 - exact) / reps)
        assert abs(simulated - exact) <= 4.5 * se
        assert simulated >= floor - 4.5 * se


@pytest.mark.parametrize("rate", [0.0, 0.02, 0.3, 0.5, 0.91, 1.0])
@pytest.mark.parametrize("halfwidth", [0.005, 0.01, 0.05])
@pytest.mark.parametrize("method", ["wilson", "clopper-pearson"])
def test_episodes_for_halfwidth_is_the_smallest_enough(rate, halfwidth, method):
    n = episodes_for_halfwidth(halfwidth, rate, 0.95, method)

    def half(m):
        low, high = binomial_interval(rate * m, m, 0.95, method)
        return (high - low) / 2

    assert half(n) <= halfwidth + 1e-12
    assert n == 1 or half(n - 1) > halfwidth


def test_episodes_for_halfwidth_normal_approximation():
    # Far from 0 and 1 the Wilson count approaches z^2 p (1 - p) / h^2.
    z2 = sps.norm.ppf(0.975) ** 2
    assert episodes_for_halfwidth(0.01, 0.5) == pytest.approx(z2 / 4 / 1e-4, rel=1e-3)
    assert episodes_for_halfwidth(0.01, 0.9) == pytest.approx(z2 * 0.09 / 1e-4, rel=2e-3)


# --- comparisons -------------------------------------------------------------------------


def test_mcnemar_matches_scipy_binomial_test():
    for only_a, only_b in [(0, 0), (0, 5), (3, 9), (12, 12), (40, 61), (500, 430)]:
        ref = sps.binomtest(only_b, only_a + only_b, 0.5).pvalue if only_a + only_b else 1.0
        assert mcnemar_exact_pvalue(only_a, only_b) == pytest.approx(ref, rel=1e-10)


def _rejection_given_discordant(m_values: np.ndarray, alpha: float) -> np.ndarray:
    """P(exact McNemar p <= alpha | m discordant pairs) under the null, for each m."""
    out = np.zeros(len(m_values))
    for i, m in enumerate(m_values):
        b = np.arange(m + 1)
        reject = mcnemar_exact_pvalue(b, m - b) <= alpha
        out[i] = sps.binom.pmf(b, m, 0.5)[reject].sum()
    return out


@pytest.mark.parametrize("n", [10, 30, 100, 1000, 10000])
@pytest.mark.parametrize("discordance", [0.02, 0.1, 0.3, 0.6, 1.0])
def test_mcnemar_holds_its_level(n, discordance):
    """Exact size under the null (equal marginals): the discordant count is
    Bin(n, discordance) and, given it, `only_b` is Bin(m, 1/2)."""
    alpha = 0.05
    mean, sd = n * discordance, np.sqrt(n * discordance * (1 - discordance))
    m = np.arange(max(0, int(mean - 12 * sd) - 20), min(n, int(mean + 12 * sd) + 20) + 1)
    weights = sps.binom.pmf(m, n, discordance)
    assert weights.sum() > 1 - 1e-12  # the window holds all but a negligible mass
    size = float(weights @ _rejection_given_discordant(m, alpha))
    assert size <= alpha + 1e-12
    if mean >= 100:  # and not needlessly conservative once there are discordant pairs
        assert size >= 0.03


def test_mcnemar_level_by_simulation():
    """Paired outcomes with equal marginals (P both 0.5, only A 0.1, only B 0.1, neither 0.3)."""
    rng = np.random.default_rng(7)
    n, reps = 200, 20_000
    cells = rng.multinomial(n, [0.5, 0.1, 0.1, 0.3], size=reps)
    rejected = np.mean(mcnemar_exact_pvalue(cells[:, 1], cells[:, 2]) <= 0.05)
    assert rejected <= 0.05 + 4.5 * np.sqrt(0.05 * 0.95 / reps)


def _paired_tables(n: int) -> tuple[np.ndarray, ...]:
    both, only_a, only_b = np.meshgrid(*(np.arange(n + 1),) * 3, indexing="ij")
    keep = both + only_a + only_b <= n
    both, only_a, only_b = both[keep], only_a[keep], only_b[keep]
    return both, only_a, only_b, n - both - only_a - only_b


@pytest.mark.parametrize("n", [20, 50])
def test_newcombe_paired_interval_coverage(n):
    """Exact coverage over every 2x2 table, for 200 random joint distributions of the pair."""
    cells = _paired_tables(n)
    low, high = newcombe_paired_interval(*cells)
    rng = np.random.default_rng(n)
    coverage = []
    for _ in range(200):
        p = rng.dirichlet(np.ones(4))
        pmf = np.exp(sps.multinomial.logpmf(np.stack(cells, 1), n, p))
        delta = p[2] - p[1]  # rate_b - rate_a
        coverage.append(pmf[(low <= delta) & (delta <= high)].sum())
    coverage = np.array(coverage)
    # Measured: mean 0.954 / 0.952, minimum 0.928 / 0.933 (n = 20 / 50).
    assert 0.945 <= coverage.mean() <= 0.965
    assert coverage.min() >= 0.92


@pytest.mark.parametrize("n", [20, 50, 200])
def test_newcombe_unpaired_interval_coverage(n):
    ka, kb = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    low, high = newcombe_interval(ka, n, kb, n)
    rng = np.random.default_rng(n)
    coverage = []
    for pa, pb in rng.uniform(size=(200, 2)):
        pmf = sps.binom.pmf(ka, n, pa) * sps.binom.pmf(kb, n, pb)
        coverage.append(pmf[(low <= pb - pa) & (pb - pa <= high)].sum())
    coverage = np.array(coverage)
    # Measured: mean 0.950-0.953; minimum 0.900 at n = 20 (rates near 0 or 1), 0.94 at 200.
    assert 0.945 <= coverage.mean() <= 0.96
    assert coverage.min() >= (0.89 if n < 100 else 0.93)


def test_newcombe_published_example():
    # Newcombe (1998), Statist. Med. 17: 873, example (a): 56/70 - 48/80, method 10.
    low, high = newcombe_interval(48, 80, 56, 70)
    assert (round(low, 4), round(high, 4)) == (0.0524, 0.3339)


def test_paired_interval_without_correlation_is_the_unpaired_one():
    # With phi = 0 (here ad - bc = 0) square-and-add reduces to the independent case.
    low, high = newcombe_paired_interval(both=10, only_a=20, only_b=5, neither=10)
    ref = newcombe_interval(30, 45, 15, 45)
    assert (low, high) == pytest.approx(ref, abs=1e-15)


def test_unpaired_tests_hold_their_level():
    """Exact size over every outcome pair under a common rate: Fisher's test never exceeds
    alpha; the z test stays near it when the expected counts are not small."""
    alpha = 0.05
    n = 40
    ka, kb = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    fisher = np.array(
        [
            [sps.fisher_exact([[b, n - b], [a, n - a]]).pvalue for b in range(n + 1)]
            for a in ka[:, 0]
        ]
    )
    for rate in (0.1, 0.3, 0.5, 0.8):
        pmf = sps.binom.pmf(ka, n, rate) * sps.binom.pmf(kb, n, rate)
        assert pmf[fisher <= alpha].sum() <= alpha + 1e-12
    n = 300
    ka, kb = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    z = two_proportion_z_pvalue(ka, n, kb, n)
    for rate in (0.1, 0.3, 0.5, 0.8):
        pmf = sps.binom.pmf(ka, n, rate) * sps.binom.pmf(kb, n, rate)
        assert 0.04 <= pmf[z <= alpha].sum() <= 0.06


def test_paired_comparison_counts_and_direction():
    a = np.array([1, 1, 0, 0, 1, 0, 0, 0], bool)
    b = np.array([1, 0, 1, 1, 1, 1, 0, 1], bool)
    c = paired_comparison(a, b)
    assert (c.both, c.only_a, c.only_b, c.neither) == (2, 1, 4, 1)
    assert c.difference == pytest.approx(3 / 8) and c.rate_b - c.rate_a == pytest.approx(3 / 8)
    assert c.p_value == pytest.approx(sps.binomtest(4, 5, 0.5).pvalue)
    assert c.ci_low < c.difference < c.ci_high
    with pytest.raises(ConfigError, match="equal"):
        paired_comparison(a, b[:5])


def test_unpaired_comparison_picks_its_test():
    small = unpaired_comparison(1, 10, 6, 10)
    assert small.test == "fisher-exact"
    assert small.p_value == pytest.approx(sps.fisher_exact([[6, 4], [1, 9]]).pvalue)
    large = unpaired_comparison(300, 1000, 350, 1000)
    assert large.test == "two-proportion-z"
    # The pooled z test is the chi-square test without continuity correction.
    chi2 = sps.chi2_contingency([[350, 650], [300, 700]], correction=False)
    assert large.p_value == pytest.approx(chi2.pvalue, rel=1e-10)
    with pytest.raises(ConfigError, match="unknown unpaired test 't'"):
        unpaired_comparison(1, 10, 6, 10, test="t")
