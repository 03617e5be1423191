"""Evaluate one policy on every task of a suite (e.g. LIBERO's `libero_spatial`): one report.

Each task runs as its own evaluation (its own scene and workers) over the same seeds, with the
policy built once and shared (built again per task where it is bound to one: `Policy.per_task`,
a task's scripted expert on a mirror). The report's `per_task` rows give each task's rate and Wilson
interval; its overall rate pools every episode, which is the average of the per-task rates
(every task runs the same number of episodes), with a Wilson interval over all of them.

`task_processes` > 1 runs that many tasks at once, one process each (each process builds the
policy once and keeps it for its next tasks, as a run in turn does), the tasks with the longest
episodes first (`scenes.longest_first`: four LIBERO suites at once otherwise leave `libero_10`'s
for last), reported in the suite's order. A task's episodes do not depend on which process ran
it, when or beside what. On one GPU this pays only under NVIDIA's MPS
daemon (`nvidia-cuda-mps-control -d`): without it the processes take turns on the GPU (8
MetaWorld tasks at 1,000 envs: 0.94x one at a time; with MPS 2.6x, 16 tasks 3.6x;
BENCHMARKS.md). A lerobot policy that samples per env from torch's global random state (not
from a key) draws what its process's earlier tasks left it, in turn or in processes.

`cluster` sends the tasks to a Ray cluster instead (`evaluation.cluster`), each through the
same per-task entry point as a task process (each building its policy), so per seed the report
is a local run's; it records where each task ran and how often one was started again after its
worker died.
A host scene's task runs its env workers as processes on the node its Ray task landed on, and
asks the cluster for one CPU per worker (`--opt n_workers=K`; else one CPU, `--threads`).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import multiprocessing
import multiprocessing.util
import os
import signal
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from openral_mjx.core.errors import ConfigError, RunFailed
from openral_mjx.core.interrupts import stop_signal
from openral_mjx.evaluation import cluster
from openral_mjx.evaluation.cluster import RayRun
from openral_mjx.evaluation.partial import Interrupted, add_by_key, partial_info
from openral_mjx.evaluation.run import build_spec_scene, evaluate_spec, policy_options, timed
from openral_mjx.evaluation.spec import RunSpec
from openral_mjx.policies import Policy, make_policy
from openral_mjx.report import EvalReport, PartialInfo, PartPlacement
from openral_mjx.runner.compile_cache import enable_compilation_cache
from openral_mjx.runner.cuda_wait import block_while_waiting
from openral_mjx.runner.memory import share_devices
from openral_mjx.scenes import longest_first, scene_suite, suite_names
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
    resume: EvalReport | None = None,
    cluster: str | None = None,
) -> EvalReport:
    """Run `policy` on every task of `suite` (or of several, comma-separated: their tasks in
    turn, one report) as `spec` says (`RunSpec.for_suite`: a setting a suite cannot honour is
    refused), on its backend (`host` for a host scene; `mjx`, `warp` or `c` for a mirror
    such as `metaworld_mjx`). One task at a time, `on_task(i, n, task)` before each; with
    `task_processes` > 1, that many at once, `on_task` as each ends (`compile_cache`: the
    directory each process caches compiled programs in).

    Stopped by a signal after its first tasks finished, raises `Interrupted` with the report
    of those (marked partial: the suite's first tasks, as far as every one finished; with
    several processes the running ones are ended). Given that report as `resume`, runs only
    the tasks after them (see `evaluation.partial`).

    With several processes the report's `run_s` is the wall time of all the tasks together
    (their builds and compiles overlap their runs, so they are in it) and `compile_s` the sum
    of the tasks' own compile times.

    With `cluster` (a Ray address, see `evaluation.cluster.check_address`) the tasks run on
    that cluster, all at once as its resources allow, timed as with several processes; the
    report's `cluster` says where each ran and counts the retries."""
    spec = spec.for_suite()
    suite = ",".join(suite_names(suite))  # "a, b" is "a,b": the report's task, resumed by it
    if task_processes < 1:
        raise ConfigError(f"task_processes must be >= 1, got {task_processes}")
    if cluster is not None and task_processes > 1:
        raise ConfigError("--cluster runs a suite's tasks on Ray workers: drop --task-processes")
    tasks = scene_suite(scene, suite)
    # a lerobot policy's cameras, unless options name them (as `evaluate_spec` does for a task)
    options = policy_options(scene, policy, options)
    earlier = _resumed(resume, suite, tasks)
    todo = tasks[len(earlier.partial.finished) if earlier and earlier.partial else 0 :]
    reports: list[EvalReport] = []
    ray_run = None if cluster is None else RayRun(cluster, earlier)
    try:
        if ray_run is not None:
            _suite_on_cluster(
                scene, policy, todo, options, spec, compile_cache, on_task, reports, ray_run
            )
        elif task_processes > 1:
            _suite_in_processes(
                scene, policy, todo, options, spec, task_processes, compile_cache, on_task, reports
            )
        else:
            _suite_in_turn(scene, policy, todo, options, spec, on_task, on_chunk, reports)
    except BaseException as e:
        stop = stop_signal(e)
        failed = isinstance(e, RunFailed)
        if (stop is None and not failed) or not (reports or earlier):
            raise
        # what finished, as a partial report: the suite's first tasks
        finished = tasks[: len(tasks) - len(todo) + len(reports)]
        if failed:
            partial = PartialInfo(str(e), "tasks", len(finished), len(tasks), finished)
        else:
            partial = partial_info(stop, "tasks", finished, len(tasks))
        blocks = [*([earlier] if earlier else []), *reports]
        merged = merge_reports(blocks, suite, policy, spec.command, partial)
        if ray_run is not None:
            merged = dataclasses.replace(merged, cluster=ray_run.info())
        if failed:
            raise RunFailed(str(e), merged) from e
        raise Interrupted(stop, merged) from e
    merged = merge_reports([*([earlier] if earlier else []), *reports], suite, policy, spec.command)
    return merged if ray_run is None else dataclasses.replace(merged, cluster=ray_run.info())


def _resumed(resume: EvalReport | None, suite: str, tasks: list[str]) -> EvalReport | None:
    """A partial suite report to resume from, checked to hold this suite's first tasks."""
    if resume is None:
        return None
    done = resume.partial.finished if resume.partial is not None else []
    if resume.partial is None or resume.task != suite or done != tasks[: len(done)]:
        raise ConfigError(
            f"cannot resume suite {suite!r} from a report of {resume.task!r} "
            f"(finished tasks: {', '.join(done) or 'none'})"
        )
    return resume


def _suite_in_turn(
    scene: str,
    policy: str,
    tasks: list[str],
    options: Mapping[str, Any] | None,
    spec: RunSpec,
    on_task: Callable[[int, int, str], None] | None,
    on_chunk: Callable[[int, int, int], None] | None,
    reports: list[EvalReport],
) -> None:
    """The `tasks` one after another, each one's report appended to `reports` as it ends."""
    kept: dict[str, Policy] = {}
    try:
        for i, task in enumerate(tasks):
            if on_task is not None:
                on_task(i, len(tasks), task)
            reports.append(_task_report(scene, task, policy, options or {}, spec, kept, on_chunk))
    finally:
        _close_kept(kept)


def _close(policy: Policy | None) -> None:
    if policy is not None and policy.close is not None:
        policy.close()


def _close_kept(kept: dict[str, Policy]) -> None:
    """Close the policies `kept` for a next task that did not come."""
    while kept:
        _close(kept.popitem()[1])


# a task process's policy, kept from one of its tasks to the next (see `_pooled_task_report`)
_PROCESS_POLICIES: dict[str, Policy] = {}


def _start_task_process(compile_cache: Path | None, processes: int = 1) -> None:
    """A task process, one of `processes` at once: allocate GPU memory as needed (they share
    the GPU), not 75% of it up front, size batches for its share of the memory, wait for the
    GPU without spinning a core the others need (`runner.cuda_wait`), and cache compiled
    programs where the parent does. The policy it keeps is closed as it ends."""
    os.environ["XLA_PYTHON_CLIENT_PREALLOCATE"] = "false"
    share_devices(processes)
    if processes > 1:
        block_while_waiting()
    if compile_cache is not None:
        enable_compilation_cache(compile_cache)
    multiprocessing.util.Finalize(None, _close_kept, (_PROCESS_POLICIES,), exitpriority=10)


def _task_report(
    scene: str,
    task: str,
    policy: str,
    options: Mapping[str, Any],
    spec: RunSpec,
    kept: dict[str, Policy] | None = None,
    on_chunk: Callable[[int, int, int], None] | None = None,
) -> EvalReport:
    """One task's report, its scene built (and closed) in this process, its policy too or
    taken from `kept`. A policy not bound to one task (`Policy.per_task`) is left in `kept`
    for the next task, as loading one (a lerobot checkpoint) takes seconds; else closed."""
    build_s: dict[str, float] = {}
    with timed(build_s, "scene"):
        built = build_spec_scene(scene, {**options, "task": task}, spec)
    with contextlib.closing(built):
        pol = (kept or {}).pop(policy, None)
        if pol is None:
            with timed(build_s, "policy"):
                pol = make_policy(policy, built)
        keep_in = None if pol.per_task else kept  # where it waits for the next task
        try:
            with evaluate_spec(built, pol, spec, on_chunk=on_chunk, build_s=build_s) as done:
                return done.report
        finally:
            if keep_in is not None:
                keep_in[policy] = pol
            else:
                _close(pol)


def _pooled_task_report(
    scene: str, task: str, policy: str, options: Mapping[str, Any], spec: RunSpec
) -> EvalReport:
    """`_task_report` in a pool's task process, which keeps its policy for its next task
    (as a suite run in turn does): per seed the episodes are a fresh policy's."""
    return _task_report(scene, task, policy, options, spec, _PROCESS_POLICIES)


def cluster_task_report(
    scene: str,
    task: str,
    policy: str,
    options: Mapping[str, Any],
    spec: RunSpec,
    compile_cache: bool,
) -> EvalReport:
    """A Ray worker's part of a suite: one task's report, as a task process makes it (with
    the node's own default compilation cache, if `compile_cache`)."""
    if compile_cache:
        enable_compilation_cache()
    return _task_report(scene, task, policy, options, spec)


def _suite_on_cluster(
    scene: str,
    policy: str,
    tasks: list[str],
    options: Mapping[str, Any] | None,
    spec: RunSpec,
    compile_cache: Path | None,
    on_task: Callable[[int, int, str], None] | None,
    reports: list[EvalReport],
    ray_run: RayRun,
) -> None:
    """The `tasks` as Ray tasks on the cluster at `ray_run.address`, as many at once as it
    has room for; `reports` (and `ray_run.placements`) get the first tasks' in the suite's
    order as every one before has ended, as with processes; timed as with processes."""
    start = time.perf_counter()
    with cluster.connected(ray_run.address) as ray:
        ray_run.nodes = cluster.live_nodes(ray)
        cpus = spec.threads
        if spec.backend == "host":  # a host task's env workers are processes on its node
            cpus = (options or {}).get("n_workers") or cpus
        resources = cluster.part_resources(ray, spec.backend, cpus)
        cache = compile_cache is not None
        parts = [(t, (scene, t, policy, dict(options or {}), spec, cache)) for t in tasks]
        ended: dict[int, tuple[EvalReport, PartPlacement]] = {}
        order = longest_first(scene, tasks, spec.max_steps)  # as a pool of processes
        runs = cluster.fan_out(ray, cluster_task_report, parts, resources, order=order)
        with contextlib.closing(runs):  # an interrupt cancels the running tasks
            for i, report, placement in runs:
                ended[i] = (report, placement)
                while len(reports) in ended:
                    done, where = ended.pop(len(reports))
                    reports.append(done)
                    ray_run.placements.append(where)
                if on_task is not None:
                    on_task(len(ended) + len(reports), len(tasks), tasks[i])
    _spread_wall_time(reports, time.perf_counter() - start, policy)


def stop_pool(pool: concurrent.futures.ProcessPoolExecutor) -> None:
    """End `pool` now: cancel what has not started and terminate its running processes, so
    none outlives an interrupted parent (`shutdown` alone waits for running tasks)."""
    processes = list(getattr(pool, "_processes", {}).values())  # no public handle before 3.14
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(timeout=5)
        if process.is_alive():  # a task that handles SIGTERM itself and goes on
            process.kill()
            process.join(timeout=5)


def _suite_in_processes(
    scene: str,
    policy: str,
    tasks: list[str],
    options: Mapping[str, Any] | None,
    spec: RunSpec,
    task_processes: int,
    compile_cache: Path | None,
    on_task: Callable[[int, int, str], None] | None,
    reports: list[EvalReport],
    run_task: Callable[..., EvalReport] = _pooled_task_report,
) -> None:
    """The `tasks` with `task_processes` at once (fresh `spawn`ed processes: no JAX or GPU
    state is inherited); `reports` gets the first tasks' reports in the suite's order as soon
    as every one before has ended, so an interrupt keeps a prefix. Its timings are made the
    wall time's (see `evaluate_suite`).

    A task process that dies (killed for memory by the system, most often, with many tasks
    at once on one machine) breaks the pool: the tasks that had not ended start again in a
    new pool of half as many processes, with a warning. One that dies running alone raises
    `RunFailed`. A task's episodes do not depend on its process, so a restart changes none."""
    start = time.perf_counter()
    pool = _TaskPool(scene, policy, tasks, options or {}, spec, compile_cache, on_task, run_task)
    ended: dict[int, EvalReport] = {}
    processes = min(task_processes, len(tasks))

    def unfinished() -> list[int]:
        return [i for i in range(len(reports), len(tasks)) if i not in ended]

    while todo := unfinished():
        processes = min(processes, len(todo))
        died = pool.run(todo, processes, reports, ended)
        if died is None:
            break
        left = [tasks[i] for i in unfinished()]
        if processes == 1:
            raise RunFailed(f"task {left[0]}'s process {died}")
        processes //= 2
        print(
            f"warning: a task process {died}; the {len(left)} unfinished tasks start again, "
            f"{processes} at a time",
            file=sys.stderr,
        )
    _spread_wall_time(reports, time.perf_counter() - start, policy)


@dataclasses.dataclass(frozen=True)
class _TaskPool:
    """What every pool of a suite's task processes runs: `run_task(scene, task, policy,
    options, spec)` per task, the longest first (`longest_first`), in processes that cache
    compiled programs in `compile_cache`; `on_task(done, total, task)` as each ends."""

    scene: str
    policy: str
    tasks: list[str]
    options: Mapping[str, Any]
    spec: RunSpec
    compile_cache: Path | None
    on_task: Callable[[int, int, str], None] | None
    run_task: Callable[..., EvalReport]

    def run(
        self,
        todo: list[int],
        processes: int,
        reports: list[EvalReport],
        ended: dict[int, EvalReport],
    ) -> str | None:
        """Tasks `todo` in a pool of `processes`: each report into `ended`, then into
        `reports` once the tasks before it have theirs. None, or how a process died (the
        pool then ends)."""
        pool = concurrent.futures.ProcessPoolExecutor(
            max_workers=processes,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_start_task_process,
            initargs=(self.compile_cache, processes),
        )
        order = longest_first(self.scene, self.tasks, self.spec.max_steps)
        rank = {i: r for r, i in enumerate(order)}
        try:
            futures = {
                pool.submit(
                    self.run_task, self.scene, self.tasks[i], self.policy, self.options, self.spec
                ): i
                for i in sorted(todo, key=rank.__getitem__)
            }
            workers = list(getattr(pool, "_processes", {}).values())  # all started by now
            for future in concurrent.futures.as_completed(futures):
                i = futures[future]
                try:
                    ended[i] = future.result()
                except concurrent.futures.process.BrokenProcessPool:
                    stop_pool(pool)
                    return _death(workers)
                while len(reports) in ended:
                    reports.append(ended.pop(len(reports)))
                if self.on_task is not None:
                    self.on_task(len(ended) + len(reports), len(self.tasks), self.tasks[i])
        except BaseException:
            stop_pool(pool)
            raise
        pool.shutdown()
        return None


def _death(workers: list[multiprocessing.process.BaseProcess], wait_s: float = 10.0) -> str:
    """How the pool's process died, from its exit code ("was killed by SIGKILL ...").

    The pool's own thread reaps its processes too: a `waitpid` that loses that race reads
    no code for a moment, so this waits (up to `wait_s`) until every code is known."""
    deadline = time.monotonic() + wait_s
    while any(w.exitcode is None for w in workers) and time.monotonic() < deadline:
        for w in workers:
            w.join(timeout=0.05)
    codes = sorted({w.exitcode for w in workers if w.exitcode not in (None, 0)})
    # the pool ends the others with SIGTERM once one is gone: that one's code tells
    told = [c for c in codes if c != -signal.SIGTERM] or codes
    if not told:
        return "ended abruptly"
    code = told[0]
    if code < 0:
        name = signal.Signals(-code).name
        why = " (the system's out-of-memory killer, most often)" if name == "SIGKILL" else ""
        return f"was killed by {name}{why}"
    return f"exited with code {code}"


def _spread_wall_time(reports: list[EvalReport], wall: float, policy: str) -> None:
    """Make `reports` (tasks run at once) share `wall` seconds, each by its share of their
    summed run time, so their merge's throughput is the wall time's."""
    if not reports:
        return
    merged = merge_reports(reports, "", policy, "")
    steps = merged.env_steps_per_s * merged.run_s
    for j, r in enumerate(reports):  # one wall time for all: spread over the tasks by share
        share = r.run_s / (merged.run_s or 1.0)
        reports[j] = dataclasses.replace(
            r,
            run_s=wall * share,
            episodes_per_s=merged.n_episodes / wall,
            env_steps_per_s=steps / wall,
        )


def merge_reports(
    reports: list[EvalReport],
    suite: str,
    policy: str,
    command: str,
    partial: PartialInfo | None = None,
) -> EvalReport:
    """One report over several tasks' reports (see module docstring): their `per_task` rows in
    order (a report may itself be a merged one, as a partial suite's is), marked `partial`
    where given."""
    first = reports[0]
    n = sum(r.n_episodes for r in reports)
    successes = sum(r.successes for r in reports)
    low, high = wilson_interval(successes, n)
    run_s = sum(r.run_s for r in reports)
    steps = sum(r.env_steps_per_s * r.run_s for r in reports)
    rows = [row for r in reports for row in r.per_task]
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
        overflowed=sum(r.overflowed for r in reports),
        per_task=rows,
        breakdown=[],
        env_steps_per_s=steps / run_s,
        episodes_per_s=n / run_s,
        compile_s=sum(r.compile_s for r in reports),
        run_s=run_s,
        options={**first.options, "task": suite},
        command=command,
        episodes=[e for r in reports for e in r.episodes],
        partial=partial,
        mujoco_warnings=add_by_key(r.mujoco_warnings for r in reports),
        build_s=add_by_key(r.build_s for r in reports),
    )


def format_tasks(report: EvalReport) -> str:
    """Per-task rates with intervals, then the average (and, over several suites, each
    suite's: how LIBERO's results are given)."""
    lines = [f"per task ({report.confidence:.0%} Wilson):"]
    for r in report.per_task:
        lines.append(
            f"  {r.task:22s} {r.successes:4d}/{r.n_episodes:<4d} {100 * r.success_rate:5.1f}% "
            f"[{100 * r.ci_low:.1f}, {100 * r.ci_high:.1f}]"
        )
    rates = {r.task: r.success_rate for r in report.per_task}
    names = suite_names(report.task)
    several = len(names) > 1
    groups = [(f"{n}: average", scene_suite(report.scene, n)) for n in names] if several else []
    for label, tasks in [*groups, ("average", list(rates))]:
        mine = [rates[t] for t in tasks if t in rates]  # a partial report lacks the last ones
        if mine:
            lines.append(f"  {label} of {len(mine)} tasks: {100 * sum(mine) / len(mine):.1f}%")
    return "\n".join(lines)
