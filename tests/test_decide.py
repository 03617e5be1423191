"""`eval --compare-with A.json --decide`: B runs on A's seeds in looks of --n-envs and stops at
the first look that decides; the report's `decision` block is the design's own verdict on the
seeds it ran (recomputed here from the report's episodes), over a contiguous prefix of seeds."""

import numpy as np
import pytest
from cli_runs import per_seed, run_cli, stop_at
from report_variants import variant

from openral_mjx.core.errors import ConfigError
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


def test_rule_resumes_to_the_uninterrupted_looks():
    """A rule stopped after two looks writes an "undecided" block (with the repeated interval
    at its last look); a fresh rule resumed from it and B's outcomes so far replays those
    looks and takes the rest as the uninterrupted rule does. A changed design or changed
    baseline outcomes are refused."""
    rng = np.random.default_rng(0)
    a, b = rng.random(64) < 0.35, np.zeros(64, bool)
    whole = PairedRule(a, "a.json", "zero")
    n = 8
    while not whole({"success": b[:n]}):
        n += 8
    assert whole.looks[-1].decision == "worse" and n == 32

    first = PairedRule(a, "a.json", "zero")
    assert not first({"success": b[:8]}) and not first({"success": b[:16]})
    kept = first.info()
    low, high = first.design.interval([x.only_a + x.only_b for x in first.looks], 0)
    assert kept.decision == "undecided" and (kept.ci_low, kept.ci_high) == (low, high)

    again = PairedRule(a, "a.json", "zero")
    again.resume(kept, b[:16])
    assert not again({"success": b[:24]}) and again({"success": b[:32]})
    assert again.looks == whole.looks and again.info() == whole.info()

    with pytest.raises(ConfigError, match="margin None, spending obrien-fleming; this run"):
        PairedRule(a, "a.json", "zero", margin=0.1).resume(kept, b[:16])
    with pytest.raises(ConfigError, match=r"not those its episodes give against 'a\.json'"):
        PairedRule(~a, "a.json", "zero").resume(kept, b[:16])
    with pytest.raises(ConfigError, match="not an undecided --decide run stopped at a look"):
        PairedRule(a, "a.json", "zero").resume(kept, b[:12])


@pytest.mark.heavy  # three episode programs compiled on c (~17 s each on 2 busy cores)
def test_interrupted_decide_resumes_to_the_uninterrupted_decision(
    monkeypatch, capsys, tmp_path, base
):
    """B (zero) against A succeeding on ~35% of seeds, looks of 8: uninterrupted, B is worse
    at 32 seeds. Stopped as the third chunk ends (before its look), the partial report keeps
    the first 16 seeds and their two looks, "undecided"; resumed, the run takes looks 3 and 4
    and ends as the uninterrupted one: same episodes per seed, looks, decision, interval."""
    rng = np.random.default_rng(0)
    save_report(variant(base, (rng.random(64) < 0.35).tolist()), tmp_path / "a.json")
    argv = [*TINY, "--n-envs", "8", "--batching", "chunks", "--compare-with"]
    argv += [str(tmp_path / "a.json"), "--decide"]
    whole, part = tmp_path / "whole.json", tmp_path / "part.json"
    assert run_cli(monkeypatch, capsys, *argv, "--out", str(whole))[0] == 0

    with monkeypatch.context() as m:
        stop_at(m, "evaluate_spec", "on_chunk", 24, "SIGINT")
        code, _, err = run_cli(m, capsys, *argv, "--out", str(part))
    assert code == 130 and "kept 16 of 64 episodes" in err.strip().splitlines()[-1]
    kept = load_report(part)
    assert [e.metadata["seed"] for e in kept.episodes] == list(range(16))
    assert kept.decision is not None and kept.decision.decision == "undecided"
    assert [x.n for x in kept.decision.looks] == [8, 16]

    code, out, err = run_cli(monkeypatch, capsys, *argv, "--out", str(part), "--resume")
    assert code == 0, err
    resumed, expected = load_report(part), load_report(whole)
    assert resumed.partial is None and resumed.n_episodes == expected.n_episodes == 32
    assert per_seed(resumed) == per_seed(expected)
    assert resumed.decision is not None and expected.decision is not None
    assert resumed.decision.decision == "worse"
    assert resumed.decision == expected.decision
    assert "stopped at look 4 of 8, 32 of at most 64 seeds" in out
