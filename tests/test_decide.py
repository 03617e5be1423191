"""`eval --compare-with A.json --decide`: B runs on A's seeds in looks of --n-envs and stops at
the first look that decides; the report's `decision` block is the design's own verdict on the
seeds it ran (recomputed here from the report's episodes), over a contiguous prefix of seeds."""

import numpy as np
import pytest
from cli_runs import run_cli
from report_variants import variant

from openral_mjx.evaluation import evaluate
from openral_mjx.evaluation.sequential import PairedRule
from openral_mjx.report import EvalReport, load_report, save_report
from openral_mjx.stats.paired_sequential import PairedDecisionDesign

TINY = ["--policy", "zero", "--backend", "c", "--threads", "1", "--max-steps", "2"]


@pytest.fixture(scope="module")
def base() -> EvalReport:
    return evaluate("tabletop_push", "zero", n_envs=8, max_steps=2, backend="c", threads=1)


def decide(monkeypatch, capsys, tmp_path, a: EvalReport, *flags: str):
    save_report(a, tmp_path / "a.json")
    out = tmp_path / "b.json"
    argv = [*TINY, "--n-envs", "8", "--compare-with", str(tmp_path / "a.json"), "--decide"]
    code, stdout, err = run_cli(monkeypatch, capsys, *argv, "--out", str(out), *flags)
    assert code == 0, err
    return load_report(out), stdout


def test_worse_stops_early_and_records_its_looks(monkeypatch, capsys, tmp_path, base):
    """A succeeds on every seed, B (zero, 2 steps) on none: B is worse, decided before the
    cap; the looks are the first 8, 16, ... seeds and their counts are those of the prefix."""
    a_outcomes = [1] * 64
    report, out = decide(monkeypatch, capsys, tmp_path, variant(base, a_outcomes))
    d = report.decision
    assert d is not None and d.decision == "worse" and d.cap == 64 and d.chunk == 8
    assert report.n_episodes < 64 and report.n_episodes == d.looks[-1].n
    seeds = [int(e.metadata["seed"]) for e in report.episodes]
    assert seeds == list(range(report.n_episodes))  # a contiguous prefix
    assert [x.n for x in d.looks] == list(range(8, report.n_episodes + 1, 8))
    assert all(x.only_a == x.n and x.only_b == 0 for x in d.looks)
    # the design's own verdict on the same outcomes
    b = np.array([e.success for e in report.episodes])
    ref = PairedDecisionDesign.in_chunks(8, 64).run(np.ones(64, bool), np.r_[b, np.zeros(64, bool)])
    assert ref[-1].decision == "worse" and len(ref) == len(d.looks)
    assert (d.ci_low, d.ci_high) == pytest.approx((ref[-1].ci_low, ref[-1].ci_high))
    assert d.ci_high < 0 and d.difference == -1.0
    assert "decide: B's success rate is lower than A's; stopped at look" in out
    assert "valid under the stopping rule" in out


def test_agreement_is_equivalence_within_margin(monkeypatch, capsys, tmp_path, base):
    """A fails on every seed, as B does: no discordant seed, so once the discordance's
    interval is below the margin the policies are equivalent."""
    report, out = decide(monkeypatch, capsys, tmp_path, variant(base, [0] * 96), "--margin", "0.2")
    d = report.decision
    assert d is not None and d.decision == "equivalent" and d.margin == 0.2
    assert -0.2 < d.ci_low <= 0 <= d.ci_high < 0.2
    assert report.n_episodes < 96
    assert "within +-20 points of A's" in out
    assert "--decide" in report.command and "--margin 0.2" in report.command


def test_cap_defaults_to_a_s_seeds_and_can_be_lower(monkeypatch, capsys, tmp_path, base):
    """Without a margin, agreement never decides: the run goes to the cap, --n-episodes."""
    report, _ = decide(monkeypatch, capsys, tmp_path, variant(base, [0] * 40), "--n-episodes", "24")
    d = report.decision
    assert d is not None and d.decision == "inconclusive" and d.cap == 24
    assert report.n_episodes == 24 and len(d.looks) == 3


def test_rule_reads_only_the_prefix_it_is_given():
    """The runner hands the rule the first n seeds, all finished; its look equals the
    design's on those seeds alone (later outcomes cannot change it)."""
    rng = np.random.default_rng(5)
    a, b = rng.random(120) < 0.3, rng.random(120) < 0.7
    rule = PairedRule(a, "a.json", "zero", margin=0.1)
    for n in (20, 40, 60):
        stop = rule({"success": b[:n]})
        if stop:
            break
    looks = PairedDecisionDesign.in_chunks(20, 120, margin=0.1).run(a, b)
    assert [x.n for x in rule.looks] == [x.n for x in looks[: len(rule.looks)]]
    assert rule.looks[-1].decision == looks[len(rule.looks) - 1].decision
