"""Report plots (PNG, matplotlib without pyplot's global state).

`success_by_factor`: the report's breakdown, success rate with its interval per bin of each
episode factor, against the overall rate. `episode_lengths`: how long episodes ran, split by
outcome. `reward_curves`: the scene's per-step reward over the episode, by outcome, from the
per-step rewards that `run_evaluation(step_rewards=True)` keeps (the report stores only
totals). `sweep_curve`: a sweep report's success against the swept factor.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np

from openral_mjx.core.files import atomic_path
from openral_mjx.report import EvalReport
from openral_mjx.report.sweep import SweepReport

OUTCOME_COLORS = {"success": "#2a9d4b", "failure": "#c8553d", "diverged": "#6c5b7b"}
MIN_RUNNING = 10  # reward curves are drawn while at least this many episodes of a group run


def _figure(width: float, height: float) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _outcomes(report: EvalReport) -> np.ndarray:
    return np.array(
        [
            "success" if e.success else ("diverged" if e.metadata.get("diverged") else "failure")
            for e in report.episodes
        ]
    )


def _percent_axis(ax: Any) -> None:
    from matplotlib.ticker import PercentFormatter

    ax.yaxis.set_major_formatter(PercentFormatter(1.0))


def success_by_factor(report: EvalReport) -> Any:
    """One panel per episode factor: each equal-count bin's success rate (dot) with its
    interval (vertical bar) over the bin's range of factor values (horizontal bar), and the
    overall rate with its interval (dashed line, band)."""
    factors = list(dict.fromkeys(r.factor for r in report.breakdown))
    cols = min(max(len(factors), 1), 2)
    rows = max(-(-len(factors) // cols), 1)
    fig = _figure(4.2 * cols, 2.9 * rows)
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    level = round(100 * report.confidence)
    for ax, name in zip(axes, factors, strict=False):
        bins = [r for r in report.breakdown if r.factor == name]
        low = np.array([r.low for r in bins])
        high = np.array([r.high for r in bins])
        rate = np.array([r.rate for r in bins])
        err = np.array([[r.rate - r.ci_low for r in bins], [r.ci_high - r.rate for r in bins]])
        ax.axhspan(report.ci_low, report.ci_high, color="0.85", zorder=0)
        ax.axhline(report.success_rate, color="0.4", ls="--", lw=1, label="all episodes")
        ax.errorbar(
            (low + high) / 2,
            rate,
            xerr=(high - low) / 2,
            yerr=err,
            fmt="o",
            color="#1d5fa6",
            ms=4,
            capsize=3,
            label=f"bin ({level}% Wilson)",
        )
        for r, x in zip(bins, (low + high) / 2, strict=True):
            ax.annotate(
                f"n={r.n}",
                (x, r.ci_low),
                textcoords="offset points",
                xytext=(0, -11),
                ha="center",
                fontsize=7,
                color="0.3",
            )
        ax.set_title(name, fontsize=10)
        ax.set_ylim(max(0.0, min(report.ci_low, *(r.ci_low for r in bins)) - 0.08), 1.02)
        ax.set_xlabel(name, fontsize=8)
        ax.set_ylabel("success rate", fontsize=8)
        ax.tick_params(labelsize=7)
        _percent_axis(ax)
        ax.grid(alpha=0.3)
    if factors:
        axes[0].legend(fontsize=7, loc="lower left")
    else:
        axes[0].text(0.5, 0.5, "this scene declares no episode factors", ha="center")
        axes[0].set_axis_off()
    for ax in axes[len(factors) :]:
        ax.set_axis_off()
    fig.suptitle(
        f"{report.scene}/{report.policy} on {report.backend}: success by episode factor "
        f"({report.n_episodes:,} episodes, equal-count bins)",
        fontsize=10,
    )
    return fig


def episode_lengths(report: EvalReport) -> Any:
    """Histogram of episode lengths (control steps), stacked by outcome."""
    steps = np.array([e.steps for e in report.episodes])
    outcome = _outcomes(report)
    fig = _figure(6.4, 3.4)
    ax = fig.subplots()
    edges = np.linspace(0, report.max_steps + 1, min(report.max_steps + 1, 50) + 1)
    groups = [(k, steps[outcome == k]) for k in OUTCOME_COLORS if (outcome == k).any()]
    ax.hist(
        [g for _, g in groups],
        bins=edges,
        stacked=True,
        color=[OUTCOME_COLORS[k] for k, _ in groups],
        label=[f"{k} ({len(g):,})" for k, g in groups],
    )
    ax.set_xlabel(f"episode length, control steps ({1000 * report.control_dt_s:g} ms each)")
    ax.set_ylabel("episodes")
    ax.set_xlim(0, report.max_steps + 1)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax.set_title(
        f"{report.scene}/{report.policy}: episode length by outcome "
        f"(limit {report.max_steps} steps)",
        fontsize=10,
    )
    return fig


def reward_curves(report: EvalReport, rewards: np.ndarray) -> Any:
    """Per-step reward over the episode by outcome: median (line) and 25-75% (band) over the
    episodes of the group still running at that step, and how many are running (below). The
    median, not the mean: a success step's bonus would otherwise spike the curve wherever few
    episodes run.

    `rewards`: (n_episodes, max_steps), NaN after an episode's end (the runner's `rewards`).
    """
    rewards = np.asarray(rewards, np.float64)
    outcome = _outcomes(report)
    fig = _figure(6.4, 4.4)
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    t = np.arange(1, rewards.shape[1] + 1)
    for k, color in OUTCOME_COLORS.items():
        group = rewards[outcome == k]
        if not len(group):
            continue
        running = np.isfinite(group).sum(axis=0)
        shown = running >= MIN_RUNNING
        bottom.plot(t, running, color=color, lw=1.2)
        if not shown.any():
            continue
        g = group[:, shown]
        with np.errstate(all="ignore"):
            q25, median, q75 = np.nanpercentile(g, [25, 50, 75], axis=0)
        top.plot(t[shown], median, color=color, lw=1.4, label=f"{k} ({len(group):,} episodes)")
        top.fill_between(t[shown], q25, q75, color=color, alpha=0.2, lw=0)
    top.set_ylabel("reward per control step")
    top.set_title(
        f"{report.scene}/{report.policy}: the scene's per-step reward while episodes run\n"
        f"(median and 25-75% over running episodes; shown while >= {MIN_RUNNING} run)",
        fontsize=9,
    )
    if top.lines:
        top.legend(fontsize=8)
    else:
        note = f"fewer than {MIN_RUNNING} episodes of any outcome"
        top.text(0.5, 0.5, note, ha="center", transform=top.transAxes)
    top.grid(alpha=0.3)
    bottom.set_ylabel("running", fontsize=8)
    bottom.set_xlabel("control step")
    bottom.grid(alpha=0.3)
    bottom.tick_params(labelsize=7)
    return fig


def png_bytes(fig: Any) -> bytes:
    """`fig` as PNG bytes (to display, e.g. `IPython.display.Image(data=...)`)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def save_png(fig: Any, path: Path) -> Path:
    """Write `fig` as a PNG at `path`, atomically."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    return path


def write_plots(report: EvalReport, stem: Path, rewards: np.ndarray | None = None) -> list[Path]:
    """The report's plots as `STEM_success_by_factor.png`, `STEM_episode_length.png` and,
    given per-step rewards, `STEM_reward.png`; returns the paths written."""
    out = [
        save_png(success_by_factor(report), stem.with_name(f"{stem.name}_success_by_factor.png")),
        save_png(episode_lengths(report), stem.with_name(f"{stem.name}_episode_length.png")),
    ]
    if rewards is not None:
        path = stem.with_name(f"{stem.name}_reward.png")
        out.append(save_png(reward_curves(report, rewards), path))
    return out


def sweep_curve(report: SweepReport) -> Any:
    """Success rate (dot) with its interval (bar) at each value of the swept factor; a step
    between neighbours whose paired test is significant after the Holm correction is drawn
    red and marked with its adjusted p-value."""
    fig = _figure(5.2, 3.4)
    ax = fig.subplots()
    x = np.array([p.value for p in report.points])
    rate = np.array([p.success_rate for p in report.points])
    low = np.array([p.ci_low for p in report.points])
    high = np.array([p.ci_high for p in report.points])
    ax.errorbar(x, rate, yerr=[rate - low, high - rate], fmt="o", color="#264653", capsize=3)
    for i, s in enumerate(report.steps):
        color = "#c8553d" if s.significant else "#8d99ae"
        ax.plot(x[i : i + 2], rate[i : i + 2], color=color, lw=2 if s.significant else 1)
        if s.significant:
            ax.annotate(
                f"p={s.p_adjusted:.2g}",
                ((x[i] + x[i + 1]) / 2, (rate[i] + rate[i + 1]) / 2),
                fontsize=7,
                color=color,
                ha="center",
                va="bottom",
            )
    ax.set_xlabel(report.factor)
    ax.set_ylabel("success rate")
    ax.set_ylim(-0.02, 1.02)
    _percent_axis(ax)
    ax.set_title(
        f"{report.scene} / {report.policy}: {report.n_episodes} seeds per point "
        f"(95% Wilson; red: Holm p <= {report.alpha:g})",
        fontsize=8,
    )
    return fig
