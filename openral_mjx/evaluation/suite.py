"""Evaluate one policy on every task of a suite (e.g. LIBERO's `libero_spatial`): one report.

Each task runs as its own evaluation (its own scene and workers) over the same seeds, with the
policy built once and shared (built again per task where it is bound to one: `Policy.per_task`,
a task's scripted expert on a mirror). The report's `per_task` rows give each task's rate and Wilson
interval; its overall rate pools every episode, which is the average of the per-task rates
(every task runs the same number of episodes), with a Wilson interval over all of them.

`task_processes` > 1 runs that many tasks at once, one process each (the policy built in each
process). A task's episodes do not depend on which process ran it or beside what. On one GPU
this pays only under NVIDIA's MPS daemon (`nvidia-cuda-mps-control -d`): without it the
processes take turns on the GPU (8 MetaWorld tasks at 1,000 envs: 0.94x one at a time; with
MPS 2.6x, 16 tasks 3.6x; BENCHMARKS.md).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import multiprocessing
import os
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation.run import build_spec_scene, evaluate_spec
from openral_mjx.evaluation.spec import RunSpec
from openral_mjx.policies import Policy, make_policy
from openral_mjx.report import EvalReport, TaskRow
from openral_mjx.runner.compile_cache import enable_compilation_cache
from openral_mjx.scenes import scene_suite
from openral_mjx.stats import wilson_interval

MPS_PIPE_DEFAULT = "/tmp/nvidia-mps"


def mps_running() -> bool:
    """Whether an NVIDIA MPS control daemon appears to serve this user's processes (its
    control pipe exists): what lets processes on one GPU run their kernels side by side."""
    pipe = os.environ.get("CUDA_MPS_PIPE_DIRECTORY", MPS_PIPE_DEFAULT)
    return (Path(pipe) / "control").exists()


def evaluate_suite(
    scene: str,
    suite: str,
    policy: str,
    spec: RunSpec,
    *,
    options: Mapping[str, Any] | None = None,
    task_processes: int = 1,
    compile_cache: Path | None = None,
    on_task: Callable[[int, int, str], None] | None = None,
    on_chunk: Callable[[int, int, int], None] | None = None,
) -> EvalReport:
    """Run `policy` on every task of `suite` as `spec` says (`RunSpec.for_suite`: a setting a
    suite cannot honour is refused), on its backend (`host` for a host scene; `mjx`, `warp`
    or `c` for a mirror such as `metaworld_mjx`). One task at a time, `on_task(i, n, task)`
    before each; with `task_processes` > 1, that many at once, `on_task` as each ends
    (`compile_cache`: the directory each process caches compiled programs in).

    With several processes the report's `run_s` is the wall time of all the tasks together
    (their builds and compiles overlap their runs, so they are in it) and `compile_s` the sum
    of the tasks' own compile times."""
    spec = spec.for_suite()
    if task_processes < 1:
        raise ConfigError(f"task_processes must be >= 1, got {task_processes}")
    tasks = scene_suite(scene, suite)
    if task_processes > 1:
        return _suite_in_processes(
            scene, suite, policy, tasks, options, spec, task_processes, compile_cache, on_task
        )
    reports: list[EvalReport] = []
    pol: Policy | None = None
    try:
        for i, task in enumerate(tasks):
            if on_task is not None:
                on_task(i, len(tasks), task)
            built = build_spec_scene(scene, {**(options or {}), "task": task}, spec)
            with contextlib.closing(built):
                if pol is None or pol.per_task:
                    _close(pol)
                    pol = None
                    pol = make_policy(policy, built)
                with evaluate_spec(built, pol, spec, on_chunk=on_chunk) as evaluation:
                    reports.append(evaluation.report)
    finally:
        _close(pol)
    return merge_reports(reports, suite, policy, spec.command)


def _close(policy: Policy | None) -> None:
    if policy is not None and policy.close is not None:
        policy.close()


def _start_task_process(compile_cache: Path | None) -> None:
    """A task process: allocate GPU memory as needed (several share the GPU), not 75% of it
    up front, and cache compiled programs where the parent does."""
    os.environ["XLA_PYTHON_CLIENT_PREALLOCATE"] = "false"
    if compile_cache is not None:
        enable_compilation_cache(compile_cache)


def _task_report(
    scene: str,
    task: str,
    policy: str,
    options: Mapping[str, Any],
    spec: RunSpec,
) -> EvalReport:
    """One task's report, its scene and policy built (and closed) in this process."""
    built = build_spec_scene(scene, {**options, "task": task}, spec)
    with contextlib.closing(built):
        pol = make_policy(policy, built)
        try:
            with evaluate_spec(built, pol, spec) as evaluation:
                return evaluation.report
        finally:
            _close(pol)


def _suite_in_processes(
    scene: str,
    suite: str,
    policy: str,
    tasks: list[str],
    options: Mapping[str, Any] | None,
    spec: RunSpec,
    task_processes: int,
    compile_cache: Path | None,
    on_task: Callable[[int, int, str], None] | None,
) -> EvalReport:
    """`evaluate_suite` with `task_processes` tasks at once (fresh `spawn`ed processes: no
    JAX or GPU state is inherited); the report's tasks in the suite's order."""
    start = time.perf_counter()
    with concurrent.futures.ProcessPoolExecutor(
        max_workers=min(task_processes, len(tasks)),
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_start_task_process,
        initargs=(compile_cache,),
    ) as pool:
        futures = {
            pool.submit(_task_report, scene, task, policy, options or {}, spec): i
            for i, task in enumerate(tasks)
        }
        reports: dict[int, EvalReport] = {}
        try:
            for future in concurrent.futures.as_completed(futures):
                i = futures[future]
                reports[i] = future.result()
                if on_task is not None:
                    on_task(len(reports), len(tasks), tasks[i])
        except BaseException:
            for future in futures:
                future.cancel()
            raise
    wall = time.perf_counter() - start
    merged = merge_reports([reports[i] for i in range(len(tasks))], suite, policy, spec.command)
    n = merged.n_episodes
    steps = merged.env_steps_per_s * merged.run_s
    return dataclasses.replace(
        merged, run_s=wall, episodes_per_s=n / wall, env_steps_per_s=steps / wall
    )


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
