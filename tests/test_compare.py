"""The compare CLI: paired by seed, unpaired, partial overlap, and every non-comparable pair of
reports -> one line, exit 2."""

import dataclasses
import json
import sys

import numpy as np
import pytest
from report_variants import variant, with_steps
from scipy import stats as sps

from openral_mjx import compare as compare_cli
from openral_mjx.evaluation import evaluate
from openral_mjx.report import EvalReport, save_report
from openral_mjx.stats import paired_comparison, unpaired_comparison


@pytest.fixture(scope="module")
def base() -> EvalReport:
    return evaluate("tabletop_push", "zero", n_envs=8, max_steps=2, backend="c", threads=1)


def run_compare(monkeypatch, capsys, tmp_path, a: EvalReport, b: EvalReport, *flags):
    paths = []
    for name, r in (("a.json", a), ("b.json", b)):
        save_report(r, tmp_path / name)
        paths.append(str(tmp_path / name))
    monkeypatch.setattr(sys, "argv", ["openral_mjx.compare", *paths, *flags])
    with pytest.raises(SystemExit) as exc:
        compare_cli.main()
    out, err = capsys.readouterr()
    return exc.value.code, out, err


A = [1, 0, 0, 1, 0, 0, 1, 0, 0, 0]
B = [1, 1, 1, 1, 0, 1, 1, 1, 0, 1]


def test_paired_on_common_seeds(monkeypatch, capsys, tmp_path, base):
    a = variant(base, A)
    b = variant(base, B, policy="scripted")
    code, out, _ = run_compare(monkeypatch, capsys, tmp_path, a, b)
    assert code == 0
    ref = paired_comparison(np.array(A, bool), np.array(B, bool))
    assert "paired on 10 common seeds: both succeed 3, only A 0, only B 5, neither 2" in out
    assert f"B - A = +{100 * ref.difference:.1f} points" in out
    assert f"[{100 * ref.ci_low:+.1f}, {100 * ref.ci_high:+.1f}]" in out
    assert f"exact McNemar p = {ref.p_value:.2g}" in out  # 2 / 2**5 = 0.0625
    assert "no difference detected at the 5% level" in out


def test_pairing_follows_seeds_not_order(monkeypatch, capsys, tmp_path, base):
    a = variant(base, A)
    order = np.random.default_rng(0).permutation(10)
    b = variant(base, [B[i] for i in order], seeds=order)
    _, out, _ = run_compare(monkeypatch, capsys, tmp_path, a, b)
    assert "both succeed 3, only A 0, only B 5, neither 2" in out


def test_partial_overlap_and_forced_unpaired(monkeypatch, capsys, tmp_path, base):
    a = variant(base, A)
    b = variant(base, B, seeds=range(5, 15))
    _, out, _ = run_compare(monkeypatch, capsys, tmp_path, a, b)
    assert "paired on 5 common seeds" in out
    assert "note: 5 episodes of A and 5 of B have no partner and are left out" in out
    _, out, _ = run_compare(monkeypatch, capsys, tmp_path, a, b, "--unpaired")
    ref = unpaired_comparison(3, 10, 8, 10)
    assert "unpaired: 10 episodes of A, 10 of B" in out and ref.test == "fisher-exact"
    assert f"Fisher's exact p = {ref.p_value:.2g}" in out
    assert "share 5 seeds: the unpaired test ignores their correlation" in out


def test_disjoint_seeds_are_unpaired(monkeypatch, capsys, tmp_path, base):
    a = variant(base, [1] * 40 + [0] * 60, seeds=range(100))
    b = variant(base, [1] * 60 + [0] * 40, seeds=range(100, 200), max_steps=5)
    _, out, _ = run_compare(monkeypatch, capsys, tmp_path, a, b)
    ref = unpaired_comparison(40, 100, 60, 100)
    assert "unpaired: 100 episodes of A, 100 of B" in out
    assert f"two-proportion z p = {ref.p_value:.2g}" in out
    assert "B's success rate is higher than A's at the 5% level" in out
    assert "note: the runs differ in max_steps" in out
    assert "t interval" not in out  # means of paired differences need common seeds


@pytest.mark.parametrize(
    "edit,flags,needle",
    [
        ({"scene": "so101_box"}, [], "reports are not comparable: scene 'tabletop_push' (A)"),
        ({"task": "other"}, [], "reports are not comparable: task"),
        ({"schema_version": "openral_mjx.eval_report/1"}, [], "schema 'openral_mjx.eval_report/1'"),
        ({}, ["--test", "t"], "unknown unpaired test 't'; valid: auto"),
        ({}, ["--confidence", "95"], "confidence must lie in (0, 1), got 95.0"),
    ],
)
def test_not_comparable_is_exit_2(monkeypatch, capsys, tmp_path, base, edit, flags, needle):
    b = dataclasses.replace(base, **{k: v for k, v in edit.items() if k != "schema_version"})
    if "schema_version" in edit:
        b = dataclasses.replace(b, schema_version=edit["schema_version"])
    code, out, err = run_compare(monkeypatch, capsys, tmp_path, base, b, *flags)
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], err


def test_missing_and_broken_files(monkeypatch, capsys, tmp_path, base):
    save_report(base, tmp_path / "a.json")
    (tmp_path / "b.json").write_text(json.dumps({"schema_version": "x"}))
    for b in ("missing.json", str(tmp_path / "b.json")):
        monkeypatch.setattr(sys, "argv", ["c", str(tmp_path / "a.json"), b])
        with pytest.raises(SystemExit) as exc:
            compare_cli.main()
        assert exc.value.code == 2 and capsys.readouterr().err.startswith("error: report ")


@pytest.mark.parametrize(
    ("original", "mirror", "task"),
    [("libero", "libero_mjx", "libero_object/0"), ("metaworld", "metaworld_mjx", "push-v3")],
)
def test_a_mirror_pairs_with_its_original_and_reports_steps_to_success(
    monkeypatch, capsys, tmp_path, base, original, mirror, task
):
    """A mirror scene mirrors its original: seed s is one initial state, so their reports pair
    by seed; over the seeds both succeed on (0, 3, 6), B's steps minus A's are 2, 1, 5."""
    a = with_steps(variant(base, A, scene=original, task=task), [10, 0, 0, 20, 0, 0, 30, 0, 0, 0])
    b = with_steps(variant(base, B, scene=mirror, task=task), [12, 5, 5, 21, 0, 5, 35, 5, 0, 5])
    b = dataclasses.replace(b, options={**b.options, "mirror_only": 1})  # not in A
    code, out, _ = run_compare(monkeypatch, capsys, tmp_path, a, b)
    assert code == 0
    assert "paired on 10 common seeds: both succeed 3, only A 0, only B 5, neither 2" in out
    assert "per-seed agreement 50.0%" in out
    assert "steps to success where both succeed (3 seeds): median B - A = +2" in out
    assert "one mirrors the other" in out
    assert "mirror_only" not in out  # an option only one scene has is no difference


def test_reports_of_different_initial_state_protocols_are_not_comparable(
    monkeypatch, capsys, tmp_path, base
):
    """LIBERO's seeds mean the 50 shipped initial states or LIBERO's own draws (option
    protocol): reports that ran different protocols do not pair; a report that records no
    protocol ran the standard one."""
    steps = [10, 0, 0, 20, 0, 0, 30, 0, 0, 0]
    a = with_steps(variant(base, A, scene="libero", task="libero_object/0"), steps)
    b = with_steps(variant(base, B, scene="libero_mjx", task="libero_object/0"), steps)
    sampled = {"protocol": "sampled", "sampled_states": 1024}
    b2 = dataclasses.replace(b, options={**b.options, **sampled})
    code, _, err = run_compare(monkeypatch, capsys, tmp_path, a, b2)
    assert code == 2, err
    assert "not comparable: option protocol 'standard' (A) vs 'sampled' (B)" in err
    a2 = dataclasses.replace(a, options={**a.options, **sampled})
    code, out, _ = run_compare(monkeypatch, capsys, tmp_path, a2, b2)
    assert code == 0 and "paired on 10 common seeds" in out


def test_reports_of_different_draw_counts_pair_on_the_seeds_below_both(
    monkeypatch, capsys, tmp_path, base
):
    """Seed s of the sampled protocol starts from draw s mod sampled_states: runs of 1,024
    draws and of 4 start seeds 0-3 from the same states, and pair on those only."""
    steps = [10, 0, 0, 20, 0, 0, 30, 0, 0, 0]
    a = with_steps(variant(base, A, scene="libero", task="libero_object/0"), steps)
    b = with_steps(variant(base, B, scene="libero_mjx", task="libero_object/0"), steps)
    a = dataclasses.replace(a, options={**a.options, "protocol": "sampled", "sampled_states": 4})
    b = dataclasses.replace(b, options={**b.options, "protocol": "sampled", "sampled_states": 1024})
    code, out, _ = run_compare(monkeypatch, capsys, tmp_path, a, b)
    assert code == 0
    # seeds 0-3: A 1 0 0 1, B 1 1 1 1
    assert "paired on 4 common seeds: both succeed 2, only A 0, only B 2, neither 0" in out
    assert "option sampled_states differs: seeds below 4 start from the same" in out
    assert "6 episodes of A and 6 of B have no partner" in out


def test_a_mirror_without_the_original_s_reward_gets_no_reward_line(
    monkeypatch, capsys, tmp_path, base
):
    """A mirror task whose reward is not ported collects 0 everywhere: a paired reward
    difference against the original would be the original's reward, so it is left out, with a
    note; with rewards on both sides the line is there."""
    steps = [10, 0, 0, 20, 0, 0, 30, 0, 0, 0]
    a = with_steps(variant(base, A, scene="metaworld", task="box-close-v3"), steps, [3.0] * 10)
    b = variant(base, A, scene="metaworld_mjx", task="box-close-v3")
    for rewards, shown in (([0.0] * 10, False), ([2.0] * 10, True)):
        _, out, _ = run_compare(monkeypatch, capsys, tmp_path, a, with_steps(b, steps, rewards))
        assert ("total reward over 10 common seeds: mean B - A" in out) == shown, out
        assert ("no total reward compared: B collected 0 in every episode" in out) != shown


def test_scenes_that_mirror_nothing_of_each_other_are_not_comparable(
    monkeypatch, capsys, tmp_path, base
):
    a = variant(base, A, scene="libero", task="libero_object/0")
    b = variant(base, B, scene="metaworld_mjx", task="libero_object/0")
    code, _, err = run_compare(monkeypatch, capsys, tmp_path, a, b)
    assert code == 2
    assert "not comparable: scene 'libero' (A) vs 'metaworld_mjx' (B)" in err


def test_paired_reports_compare_mean_steps_and_reward_with_a_t_interval(
    monkeypatch, capsys, tmp_path, base
):
    """Steps to success over the seeds both succeed on (0, 3, 6: B - A = 2, 1, 5) and total
    reward over all ten, each a mean of paired differences with scipy's paired t interval."""
    rng = np.random.default_rng(2)
    reward_a, reward_b = rng.normal(0, 1, 10), rng.normal(0.5, 1, 10)
    steps_a, steps_b = [10, 0, 0, 20, 0, 0, 30, 0, 0, 0], [12, 5, 5, 21, 0, 5, 35, 5, 0, 5]
    a = with_steps(variant(base, A), steps_a, reward_a)
    b = with_steps(variant(base, B, policy="scripted"), steps_b, reward_b)
    code, out, _ = run_compare(monkeypatch, capsys, tmp_path, a, b, "--confidence", "0.9")
    assert code == 0
    ci = sps.ttest_rel([12, 21, 35], [10, 20, 30]).confidence_interval(0.9)
    assert (
        "steps to success where both succeed (3 seeds): median B - A = +2, mean +2.667, "
        f"90% t interval [{ci.low:+.4g}, {ci.high:+.4g}]"
    ) in out
    ci = sps.ttest_rel(reward_b, reward_a).confidence_interval(0.9)
    assert (
        f"total reward over 10 common seeds: mean B - A = {np.mean(reward_b - reward_a):+.4g}, "
        f"90% t interval [{ci.low:+.4g}, {ci.high:+.4g}]"
    ) in out
