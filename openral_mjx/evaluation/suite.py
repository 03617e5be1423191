"""Evaluate one policy on every task of a suite (e.g. LIBERO's `libero_spatial`): one report.

Each task runs as its own evaluation (its own scene and workers) over the same seeds, with the
policy built once and shared. The report's `per_task` rows give each task's rate and Wilson
interval; its overall rate pools every episode, which is the average of the per-task rates
(every task runs the same number of episodes), with a Wilson interval over all of them.
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

from openral_mjx.evaluation.run import evaluate
from openral_mjx.policies import make_policy
from openral_mjx.report import EvalReport, TaskRow
from openral_mjx.scenes import make_scene, scene_suite
from openral_mjx.stats import wilson_interval


def evaluate_suite(
    scene: str,
    suite: str,
    policy: str,
    *,
    n_envs: int,
    n_episodes: int | None = None,
    seed: int = 0,
    max_steps: int | None = None,
    options: Mapping[str, Any] | None = None,
    command: str = "",
    on_task: Callable[[int, int, str], None] | None = None,
    on_chunk: Callable[[int, int, int], None] | None = None,
) -> EvalReport:
    """Run `policy` on every task of `suite`; `on_task(i, n, task)` before each task."""
    tasks = scene_suite(scene, suite)
    reports: list[EvalReport] = []
    with contextlib.ExitStack() as owned:
        pol = None
        for i, task in enumerate(tasks):
            if on_task is not None:
                on_task(i, len(tasks), task)
            built = make_scene(scene, {**(options or {}), "task": task}, backend="host")
            with contextlib.closing(built):
                if pol is None:
                    pol = make_policy(policy, built)
                    if pol.close is not None:
                        owned.callback(pol.close)
                reports.append(
                    evaluate(
                        built,
                        pol,
                        n_envs=n_envs,
                        n_episodes=n_episodes,
                        seed=seed,
                        max_steps=max_steps,
                        command=command,
                        on_chunk=on_chunk,
                    )
                )
    return merge_reports(reports, suite, policy, command)


def merge_reports(reports: list[EvalReport], suite: str, policy: str, command: str) -> EvalReport:
    """One report over several tasks' reports (see module docstring)."""
    first = reports[0]
    n = sum(r.n_episodes for r in reports)
    successes = sum(r.successes for r in reports)
    low, high = wilson_interval(successes, n)
    run_s = sum(r.run_s for r in reports)
    steps = sum(r.env_steps_per_s * r.run_s for r in reports)
    rows = [
        TaskRow(
            r.task,
            r.n_episodes,
            r.successes,
            r.success_rate,
            r.ci_low,
            r.ci_high,
            instruction=r.instruction,
        )
        for r in reports
    ]
    return dataclasses.replace(
        first,
        task=suite,
        instruction=None,  # one per task, in `per_task`
        policy=policy,
        n_episodes=n,
        successes=successes,
        success_rate=successes / n,
        ci_low=low,
        ci_high=high,
        diverged=sum(r.diverged for r in reports),
        per_task=rows,
        breakdown=[],
        env_steps_per_s=steps / run_s,
        episodes_per_s=n / run_s,
        compile_s=sum(r.compile_s for r in reports),
        run_s=run_s,
        options={**first.options, "task": suite},
        command=command,
        episodes=[e for r in reports for e in r.episodes],
    )


def format_tasks(report: EvalReport) -> str:
    """Per-task rates with intervals, then the average."""
    lines = [f"per task ({report.confidence:.0%} Wilson):"]
    for r in report.per_task:
        lines.append(
            f"  {r.task:22s} {r.successes:4d}/{r.n_episodes:<4d} {100 * r.success_rate:5.1f}% "
            f"[{100 * r.ci_low:.1f}, {100 * r.ci_high:.1f}]"
        )
    rates = [r.success_rate for r in report.per_task]
    lines.append(f"  average of {len(rates)} tasks: {100 * sum(rates) / len(rates):.1f}%")
    return "\n".join(lines)
