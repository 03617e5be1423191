"""Success by episode factor: equal-count bins against direct counts, Wilson per bin."""

import itertools

import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.stats import wilson_interval
from openral_mjx.stats.breakdown import breakdown, format_breakdown, quantile_edges


def test_bins_partition_the_episodes_with_equal_counts():
    rng = np.random.default_rng(0)
    values = rng.uniform(0.06, 0.1, size=1000)
    success = rng.uniform(size=1000) < 0.2 + 5 * (values - 0.06)  # better further away
    rows = breakdown({"goal_distance": values}, success, n_bins=5)
    assert [r.n for r in rows] == [200] * 5
    for i, r in enumerate(rows):
        last = i == len(rows) - 1
        inside = (values >= r.low) & ((values <= r.high) if last else (values < r.high))
        assert r.n == inside.sum() and r.successes == success[inside].sum()
        assert r.rate == r.successes / r.n
        assert (r.ci_low, r.ci_high) == wilson_interval(r.successes, r.n)
    assert rows[0].low == values.min() and rows[-1].high == values.max()
    assert all(a.high == b.low for a, b in itertools.pairwise(rows))
    assert rows[-1].rate > rows[0].rate  # the trend shows


def test_ties_constant_factors_and_several_factors():
    success = np.array([1, 0, 1, 1, 0, 0, 1, 0], bool)
    rows = breakdown(
        {"flag": np.array([0, 0, 0, 0, 0, 1, 1, 1.0]), "same": np.full(8, 0.5)}, success, 4
    )
    flag = [r for r in rows if r.factor == "flag"]
    same = [r for r in rows if r.factor == "same"]
    assert [(r.low, r.high, r.n, r.successes) for r in flag] == [(0, 1, 5, 3), (1, 1, 3, 1)]
    assert [(r.low, r.high, r.n) for r in same] == [(0.5, 0.5, 8)]
    assert rows.index(flag[0]) < rows.index(same[0])  # factors keep their order


def test_fewer_episodes_than_bins():
    rows = breakdown({"x": np.array([0.3, 0.1, 0.2])}, np.array([1, 0, 1], bool), n_bins=5)
    assert [(r.low, r.high, r.n, r.successes) for r in rows] == [
        (0.1, 0.2, 1, 0),
        (0.2, 0.3, 1, 1),
        (0.3, 0.3, 1, 1),
    ]


def test_edges_and_bad_bins():
    np.testing.assert_array_equal(quantile_edges(np.arange(10.0), 2), [0.0, 5.0, 9.0])
    np.testing.assert_array_equal(quantile_edges(np.arange(7.0)[::-1], 2), [0.0, 4.0, 6.0])
    with pytest.raises(ConfigError, match="factor_bins must be a positive integer, got 0"):
        quantile_edges(np.arange(3.0), 0)


def test_table_text():
    rows = breakdown({"x": np.arange(4.0)}, np.array([1, 1, 0, 0], bool), n_bins=2)
    text = format_breakdown(rows)
    lines = text.splitlines()
    assert len(lines) == 3 and "95% Wilson" in lines[0]
    assert lines[1].split()[:3] == ["x", "[0,", "2)"] and lines[2].split()[:2] == ["[2,", "3]"]
    assert "100.0%" in lines[1] and "0.0%" in lines[2]
