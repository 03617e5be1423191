"""Plots of `compare`'s families (PNG): two suites' per-task differences, k policies' rates and
pairwise differences. Drawn with `plots`' figure helpers (matplotlib without pyplot)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from openral_mjx.stats.intervals import wilson_interval
from openral_mjx.stats.report_families import ManyReportComparison, SuiteReportComparison
from openral_mjx.viz.plots import _figure, save_png

SIGNIFICANT, PLAIN = "#c8553d", "#264653"


def suite_differences(sc: SuiteReportComparison) -> Any:
    """Forest plot: each task's B - A with its interval (red where Holm-significant), and the
    suite mean with its stratified interval at the bottom."""
    r = sc.result
    alpha = 1 - r.confidence
    rows = len(r.tasks) + 1
    fig = _figure(6.4, 1.2 + 0.32 * rows)
    ax = fig.subplots()
    y = np.arange(rows)[::-1]
    for yi, c, adj in zip(y[:-1], r.per_task, r.adjusted, strict=True):
        color = SIGNIFICANT if adj <= alpha else PLAIN
        ax.errorbar(
            c.difference,
            yi,
            xerr=[[c.difference - c.ci_low], [c.ci_high - c.difference]],
            fmt="o",
            color=color,
            ms=4,
            capsize=3,
        )
    ax.errorbar(
        r.mean_difference,
        y[-1],
        xerr=[[r.mean_difference - r.ci_low], [r.ci_high - r.mean_difference]],
        fmt="D",
        color="black",
        ms=5,
        capsize=3,
    )
    ax.axvline(0, color="0.5", lw=1, ls="--")
    ax.axhline(y[-1] + 0.5, color="0.8", lw=1)
    ax.set_yticks(y, [*r.tasks, "suite mean"], fontsize=7)
    ax.set_xlabel(f"B - A, success rate ({round(100 * r.confidence)}% interval)")
    ax.xaxis.set_major_formatter(_percent_formatter())
    ax.grid(alpha=0.3, axis="x")
    ax.set_title(
        f"B: {sc.labels[1]}  vs  A: {sc.labels[0]}\n(red: Holm-adjusted p <= {alpha:g})",
        fontsize=8,
    )
    return fig


def _percent_formatter() -> Any:
    from matplotlib.ticker import PercentFormatter

    return PercentFormatter(1.0)


def policy_comparison(mc: ManyReportComparison) -> Any:
    """Left: policies ranked by success rate with Wilson intervals (filled: not significantly
    worse than the best). Right: the pairwise matrix of row - column differences in points,
    marked where Holm-significant."""
    r = mc.result
    k, n = len(r.names), mc.n_seeds
    order = list(np.argsort([-x for x in r.rates], kind="stable"))
    names = [r.names[i] for i in order]
    fig = _figure(4.0 + 0.55 * k + 3.4, 1.6 + 0.45 * k)
    left, right = fig.subplots(1, 2, width_ratios=(3.4, 1.2 + 0.55 * k))
    for y, i in enumerate(order[::-1]):
        rate = r.rates[i]
        low, high = wilson_interval(round(rate * n), n, 1 - r.alpha)
        keep = r.names[i] in r.not_worse
        left.errorbar(
            rate,
            y,
            xerr=[[rate - low], [high - rate]],
            fmt="o",
            color=PLAIN if keep else "0.6",
            mfc=PLAIN if keep else "white",
            ms=5,
            capsize=3,
        )
    left.set_yticks(range(k), names[::-1], fontsize=7)
    left.set_xlabel(f"success rate ({round(100 * (1 - r.alpha))}% Wilson)")
    left.xaxis.set_major_formatter(_percent_formatter())
    left.grid(alpha=0.3, axis="x")
    left.set_title(f"filled: not worse than the best ({r.best})", fontsize=8)
    diff = np.full((k, k), np.nan)
    for (a, b), c in r.pairs.items():
        i, j = names.index(b), names.index(a)
        diff[i, j], diff[j, i] = c.difference, -c.difference
    lim = max(float(np.nanmax(np.abs(diff))) if k > 1 else 0.0, 1e-3)
    right.imshow(100 * diff, cmap="RdBu", vmin=-100 * lim, vmax=100 * lim)
    for (a, b), adj in r.adjusted.items():
        i, j = names.index(b), names.index(a)
        for y, x, sign in ((i, j, 1), (j, i, -1)):
            text = f"{100 * sign * diff[i, j]:+.0f}" + ("*" if adj <= r.alpha else "")
            color = "white" if abs(diff[i, j]) > 0.6 * lim else "black"
            right.text(x, y, text, ha="center", va="center", fontsize=7, color=color)
    right.set_xticks(range(k), names, rotation=45, ha="right", fontsize=7)
    right.set_yticks(range(k), names, fontsize=7)
    right.set_title(f"row - column, points (*: Holm p <= {r.alpha:g})", fontsize=8)
    fig.suptitle(f"{k} policies on {n:,} common seeds", fontsize=9)
    return fig


def write_comparison_plots(
    comparison: SuiteReportComparison | ManyReportComparison, folder: Path
) -> list[Path]:
    """`folder/compare_suite.png` or `folder/compare_policies.png`; returns the paths."""
    if isinstance(comparison, SuiteReportComparison):
        return [save_png(suite_differences(comparison), folder / "compare_suite.png")]
    return [save_png(policy_comparison(comparison), folder / "compare_policies.png")]
