"""The sequential design: its stopping rule against its definition, its exact interval against
Clopper-Pearson (one look), its outcome distribution against simulation, and its coverage under
the stopping rule: exactly over every outcome for small designs, and by simulating the rule
with binomial draws (no physics) for the CLI's default shape (chunks of 1,024, target 0.01)."""

import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.stats import clopper_pearson_interval, wilson_interval
from openral_mjx.stats.sequential import SequentialDesign, sufficient_episodes


def simulate(design: SequentialDesign, rate: float, reps: int, seed: int) -> tuple[np.ndarray, ...]:
    """Run the stopping rule `reps` times on binomial chunks: (stop look, successes) per run."""
    rng = np.random.default_rng(seed)
    sizes = np.diff((0, *design.looks))
    counts = np.cumsum(rng.binomial(sizes, rate, size=(reps, len(sizes))), axis=1)
    stops = np.stack([design.stops(j, counts[:, j]) for j in range(len(sizes))], axis=1)
    look = np.argmax(stops, axis=1)  # the last look always stops
    return look, counts[np.arange(reps), look]


def test_one_look_is_clopper_pearson():
    design = SequentialDesign((60,), 0.1)
    for k in range(61):
        assert design.interval(0, k) == pytest.approx(clopper_pearson_interval(k, 60), abs=1e-9)


def test_stop_rule_is_its_definition():
    design = SequentialDesign.in_chunks(13, 0.07)
    for j, n in enumerate(design.looks):
        k = np.arange(n + 1)
        low, high = clopper_pearson_interval(k, n)
        met = (high - low) / 2 <= 0.07
        np.testing.assert_array_equal(
            design.stops(j, k), met if j < len(design.looks) - 1 else True
        )
    # Default cap: the fewest episodes at which every outcome meets the target (a partial
    # last chunk), whatever the chunk size.
    last = design.max_episodes
    assert last == sufficient_episodes(0.07) == SequentialDesign.in_chunks(50, 0.07).max_episodes
    assert all(design.meets_target(len(design.looks) - 1, k) for k in range(last + 1))
    low, high = clopper_pearson_interval((last - 1) // 2, last - 1)
    assert (high - low) / 2 > 0.07


def test_cap_and_partial_last_chunk():
    design = SequentialDesign.in_chunks(100, 0.01, max_episodes=250)
    assert design.looks == (100, 200, 250)
    assert design.stops(2, 125) and not design.meets_target(2, 125)
    with pytest.raises(ValueError, match="does not stop"):
        design.interval(0, 50)
    with pytest.raises(ConfigError, match="target_halfwidth must lie in"):
        SequentialDesign.in_chunks(100, 0.0)
    with pytest.raises(ConfigError, match="max_episodes must be a positive integer"):
        SequentialDesign.in_chunks(100, 0.1, max_episodes=0)


@pytest.mark.parametrize("rate", [0.07, 0.5, 0.83])
def test_outcome_distribution_matches_simulation(rate):
    design = SequentialDesign.in_chunks(25, 0.08)
    exact = design.stop_probabilities(rate)
    assert sum(p.sum() for _, p in exact) == pytest.approx(1.0, abs=1e-12)
    reps = 40_000
    look, _ = simulate(design, rate, reps, seed=3)
    for j, (_, p) in enumerate(exact):
        q = p.sum()
        assert abs(np.mean(look == j) - q) <= 4.5 * np.sqrt(q * (1 - q) / reps) + 1e-12


def _coverage(design, rates, interval) -> np.ndarray:
    """Exact P(interval covers rate) under the stopping rule, for each rate."""
    return np.array(
        [
            sum(
                p[(lo <= r) & (r <= hi)].sum()
                for j, (offset, p) in enumerate(design.stop_probabilities(r))
                for lo, hi in [interval(j, offset + np.arange(p.size))]
            )
            for r in rates
        ]
    )


@pytest.mark.parametrize("chunk,halfwidth", [(20, 0.1), (32, 0.08), (10, 0.15)])
def test_exact_coverage_holds_under_the_stopping_rule(chunk, halfwidth):
    """Every outcome's exact sequential interval, weighted by its exact probability: at least
    nominal at every rate. The fixed-n Clopper-Pearson interval, at least nominal for any fixed
    n, falls below it under the same rule: the reason the sequential interval exists."""
    design = SequentialDesign.in_chunks(chunk, halfwidth)
    rates = np.concatenate([np.linspace(0.002, 0.998, 300), [0.05, 0.5, 0.95]])
    reachable: set[tuple[int, int]] = set()
    for r in rates[::10]:
        for j, (offset, p) in enumerate(design.stop_probabilities(r)):
            reachable |= {(j, offset + i) for i in np.nonzero(p > 1e-15)[0]}
    cis = {o: design.interval(*o) for o in sorted(reachable)}

    def sequential(j, ks):
        pairs = [cis.get((j, int(k)), (2.0, -1.0)) for k in ks]  # unreachable: never covers
        return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])

    coverage = _coverage(design, rates, sequential)
    assert coverage.min() >= 0.95 - 1e-6  # slack for outcomes below 1e-15 left out
    naive = _coverage(design, rates, lambda j, ks: clopper_pearson_interval(ks, design.looks[j]))
    assert naive.min() < 0.947


@pytest.mark.parametrize(
    "rate", [pytest.param(0.9, id="0.9"), pytest.param(0.5, marks=pytest.mark.slow, id="0.5")]
)
def test_simulated_coverage_of_the_cli_default_design(rate):
    """The rule as `eval --target-halfwidth 0.01 --n-envs 1024` runs it, on binomial draws."""
    design = SequentialDesign.in_chunks(1024, 0.01)
    reps = 4000
    look, successes = simulate(design, rate, reps, seed=11)
    cis = {o: design.interval(*o) for o in set(zip(look.tolist(), successes.tolist(), strict=True))}
    covered = np.array([cis[o][0] <= rate <= cis[o][1] for o in zip(look, successes, strict=True)])
    assert covered.mean() >= 0.95 - 4.5 * np.sqrt(0.95 * 0.05 / reps)
    widths = np.array([cis[o][1] - cis[o][0] for o in zip(look, successes, strict=True)]) / 2
    assert np.median(widths) <= 0.0101  # the reported interval is about as narrow as asked


def test_sequential_interval_agrees_with_fixed_n_far_from_the_boundary():
    design = SequentialDesign.in_chunks(1024, 0.01)
    look, k = 3, 3700  # 90.3% of 4,096: stopping earlier was practically impossible
    assert design.stops(look, k)
    np.testing.assert_allclose(
        design.interval(look, k), clopper_pearson_interval(k, 4096), atol=1e-8
    )
    assert wilson_interval(k, 4096)[1] - wilson_interval(k, 4096)[0] < 2 * 0.01


def test_rule_takes_its_looks_from_the_runners_chunks():
    """The runner may run fewer envs than asked (memory) or more (a multiple of the devices):
    the design is fixed at the first look, from the chunk that actually ran."""
    from openral_mjx.evaluation import SequentialRule

    rule = SequentialRule(0.1, 100)
    assert not rule({"success": np.zeros(30, bool) | (np.arange(30) % 2 == 0)})
    assert rule.design.looks == (30, 60, 90, 100)
    assert rule({"success": np.zeros(60, bool)})  # 0 of 60: the half-width is 0.03
