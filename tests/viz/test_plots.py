"""Report plots: what they draw is the report's numbers; files are written next to the stem."""

import numpy as np
from PIL import Image

from openral_mjx.viz import plots
from openral_mjx.viz.plots import episode_lengths, success_by_factor, write_plots


def test_per_step_rewards_add_up_to_the_episode_totals(scripted_eval):
    """The runner's per-step rewards: finite for exactly `steps` steps, NaN after, and their
    float32 running sum is the episode's total reward, bit for bit."""
    rewards, arrays = scripted_eval.arrays["rewards"], scripted_eval.arrays
    assert rewards.shape == (8, 100)
    for r, steps, total in zip(rewards, arrays["steps"], arrays["total_reward"], strict=True):
        assert np.isfinite(r[:steps]).all() and np.isnan(r[steps:]).all()
        acc = np.float32(0)
        for v in r[:steps]:
            acc = np.float32(acc + v)
        assert acc == total


def test_success_by_factor_draws_the_breakdown(scripted_eval):
    report = scripted_eval.report
    fig = success_by_factor(report)
    factors = list(dict.fromkeys(r.factor for r in report.breakdown))
    axes = [ax for ax in fig.axes if ax.get_title()]
    assert [ax.get_title() for ax in axes] == factors
    for ax, name in zip(axes, factors, strict=True):
        rows = [r for r in report.breakdown if r.factor == name]
        points = ax.containers[0].lines[0]  # the errorbar's markers
        np.testing.assert_allclose(points.get_ydata(), [r.rate for r in rows])
        np.testing.assert_allclose(points.get_xdata(), [(r.low + r.high) / 2 for r in rows])


def test_episode_lengths_histogram_counts_each_outcome(scripted_eval):
    report = scripted_eval.report
    fig = episode_lengths(report)
    bars = fig.axes[0].containers
    steps = np.array([e.steps for e in report.episodes])
    success = np.array([e.success for e in report.episodes])
    assert [len(steps[success]), len(steps[~success])] == [
        int(sum(p.get_height() for p in c)) for c in bars
    ]


def test_reward_curves_are_medians_of_running_episodes(scripted_eval, monkeypatch):
    monkeypatch.setattr(plots, "MIN_RUNNING", 1)  # 8 episodes here: draw every step
    report, rewards = scripted_eval.report, scripted_eval.arrays["rewards"]
    success = scripted_eval.arrays["success"]
    assert 0 < success.sum() < len(success)
    fig = plots.reward_curves(report, rewards)
    top, bottom = fig.axes[:2]
    failure = next(ln for ln in top.lines if ln.get_label().startswith("failure"))
    # Failures run to the step limit: the curve is their median reward at each step.
    np.testing.assert_allclose(failure.get_ydata(), np.median(rewards[~success], axis=0))
    # Successes end early: the lower panel counts those still running.
    running = bottom.lines[0].get_ydata()
    counts = [(scripted_eval.arrays["steps"][success] >= t).sum() for t in range(1, 101)]
    np.testing.assert_array_equal(running, counts)


def test_write_plots_writes_pngs_next_to_the_stem(scripted_eval, tmp_path):
    stem = tmp_path / "run"
    paths = write_plots(scripted_eval.report, stem, scripted_eval.arrays["rewards"])
    assert [p.name for p in paths] == [
        "run_success_by_factor.png",
        "run_episode_length.png",
        "run_reward.png",
    ]
    for p in paths:
        with Image.open(p) as im:
            assert im.format == "PNG" and min(im.size) > 200
    assert len(write_plots(scripted_eval.report, tmp_path / "again")) == 2
    assert not list(tmp_path.glob(".*.tmp"))
