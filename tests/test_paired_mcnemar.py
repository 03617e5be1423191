"""The paired comparison script: discordant counts on common seeds, the exact McNemar p-value
against its closed form (twice the binomial tail of the smaller count)."""

import importlib.util
import math
from pathlib import Path

import pytest

_path = Path(__file__).parent.parent / "benchmarks" / "paired_mcnemar.py"
_spec = importlib.util.spec_from_file_location("paired_mcnemar", _path)
paired = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(paired)


def test_counts_and_exact_p_value():
    # 20 common seeds: 3 before-only, 10 after-only, 5 both, 2 neither; seed 99 not common.
    outcomes = [(1, 0)] * 3 + [(0, 1)] * 10 + [(1, 1)] * 5 + [(0, 0)] * 2
    before = {s: bool(a) for s, (a, _) in enumerate(outcomes)} | {99: True}
    after = {s: bool(b) for s, (_, b) in enumerate(outcomes)}
    r = paired.compare(before, after)
    assert (r["n_common_seeds"], r["before_only"], r["after_only"]) == (20, 3, 10)
    assert r["before"]["successes"] == 8 and r["after"]["successes"] == 15
    tail = sum(math.comb(13, k) for k in range(4)) / 2**13
    assert r["p_value"] == pytest.approx(2 * tail, rel=1e-12)
    assert r["log10_p_value"] == pytest.approx(math.log10(2 * tail), rel=1e-9)


def test_no_discordant_pairs_is_p_one():
    same = {s: s % 2 == 0 for s in range(10)}
    assert paired.compare(same, same)["p_value"] == 1.0
