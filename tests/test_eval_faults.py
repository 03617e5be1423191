"""`eval` under faults: stopped by Ctrl-C or SIGTERM it keeps what finished, and `--resume`
finishes it; diverging physics leaves the terminal readable and the working directory clean.

The interrupt is made deterministic in-process: the progress callback that runs before the
second sweep point (or suite task) raises `KeyboardInterrupt`, or sends this process SIGTERM,
just as a signal arriving then would. Each resumed report is compared, per seed, with an
uninterrupted run of the same arguments on `c` (tabletop_push, 8 envs, short episodes).
"""

import concurrent.futures
import dataclasses
import multiprocessing
import os
import shutil
import signal
import sys
import time
from pathlib import Path

import pytest
from cli_runs import per_seed, run_cli, stop_at

from openral_mjx import eval as eval_cli
from openral_mjx.cli import eval_plan
from openral_mjx.evaluation import suite as suite_module
from openral_mjx.evaluation.run import build_scene
from openral_mjx.report import load_report, save_report
from openral_mjx.report.sweep import load_sweep, save_sweep

ARMS = Path(__file__).parent / "data" / "arms"

COMMON = ["--backend", "c", "--n-envs", "8", "--max-steps", "15", "--threads", "1"]
SWEEP = [*COMMON, "--no-compile-cache", "--sweep", "friction=0.2:0.6:2"]


@pytest.fixture(scope="module")
def whole_sweep(tmp_path_factory):
    """The uninterrupted sweep every resumed one must equal."""
    out = tmp_path_factory.mktemp("sweep") / "whole.json"
    with pytest.MonkeyPatch.context() as m:
        m.setattr(sys, "argv", ["openral_mjx.eval", *SWEEP, "--out", str(out)])
        with pytest.raises(SystemExit) as exc:
            eval_cli.main()
    assert exc.value.code == 0
    return out


@pytest.mark.heavy  # four episode programs compiled on c (~15 s each on 2 busy cores)
def test_interrupted_sweep_resumes_to_the_uninterrupted_result(
    monkeypatch, capsys, tmp_path, whole_sweep
):
    part = tmp_path / "part.json"
    with monkeypatch.context() as m:
        stop_at(m, "run_sweep", "on_point", 1, "SIGINT")
        code, _, err = run_cli(m, capsys, *SWEEP, "--out", str(part))
    assert code == 130
    line = err.strip().splitlines()[-1]
    assert line.startswith("interrupted (SIGINT): kept 1 of 2 points in ")
    assert str(part) in line and line.endswith("--resume")
    kept = load_sweep(part)
    assert kept.partial.finished == ["0.2"] and [p.value for p in kept.points] == [0.2]

    assert run_cli(monkeypatch, capsys, *SWEEP, "--out", str(part), "--resume")[0] == 0
    resumed, expected = load_sweep(part), load_sweep(whole_sweep)
    assert resumed.partial is None and len(resumed.points) == 2
    assert [(p.value, p.outcomes) for p in resumed.points] == [
        (p.value, p.outcomes) for p in expected.points
    ]
    assert [(s.p_value, s.difference) for s in resumed.steps] == [
        (s.p_value, s.difference) for s in expected.steps
    ]


def test_sigterm_keeps_the_finished_point_and_resume_checks_the_command(
    monkeypatch, capsys, tmp_path
):
    part = tmp_path / "part.json"
    with monkeypatch.context() as m:
        stop_at(m, "run_sweep", "on_point", 1, "SIGTERM")
        code, _, err = run_cli(m, capsys, *SWEEP, "--out", str(part))
    assert code == 143 and "terminated (SIGTERM): kept 1 of 2 points" in err
    assert load_sweep(part).partial.reason == "terminated (SIGTERM)"
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # the handlers are given back

    other = [a if a != SWEEP[-1] else "friction=0.2:0.8:2" for a in SWEEP]
    code, _, err = run_cli(monkeypatch, capsys, *other, "--out", str(part), "--resume")
    assert code == 2 and err.count("\n") == 1 and "written by another command" in err
    code, _, err = run_cli(monkeypatch, capsys, *SWEEP, "--resume")
    assert code == 2 and err == "error: --resume needs --out: the partial report to pick up from\n"
    code, _, err = run_cli(monkeypatch, capsys, *COMMON, "--out", str(part), "--resume")
    assert code == 2 and err.count("\n") == 1 and str(part) in err  # a sweep's, not a run's
    assert "schema 'openral_mjx.sweep/" in err and "valid: openral_mjx.eval_report/" in err
    complete = tmp_path / "complete.json"
    save_sweep(dataclasses.replace(load_sweep(part), partial=None), complete)
    code, _, err = run_cli(monkeypatch, capsys, *SWEEP, "--out", str(complete), "--resume")
    assert code == 2 and "is complete; nothing to resume" in err


@pytest.mark.heavy  # four episode programs compiled on c
def test_interrupted_suite_resumes_to_the_uninterrupted_result(monkeypatch, capsys, tmp_path):
    """Two stand-in tasks on a cheap MuJoCo scene (the suite machinery is under test), each
    on its own seeds' episodes: `--opt`-free tabletop_push with the task's friction."""
    frictions = {"a": 0.2, "b": 1.0}
    monkeypatch.setattr(suite_module, "scene_suite", lambda scene, suite: list(frictions))
    monkeypatch.setattr(eval_plan, "scene_suite", lambda scene, suite: list(frictions))

    def stand_in(name, options, spec, randomize=()):
        friction = f"friction={frictions[options['task']]}"
        return build_scene("tabletop_push", backend="c", n_envs=8, threads=1, randomize=[friction])

    monkeypatch.setattr(suite_module, "build_spec_scene", stand_in)
    argv = [*COMMON, "--scene", "metaworld_mjx", "--suite", "abc", "--policy", "zero"]
    whole, part = tmp_path / "whole.json", tmp_path / "part.json"
    code, _, err = run_cli(monkeypatch, capsys, *argv, "--out", str(whole))
    assert code == 0, err

    with monkeypatch.context() as m:
        stop_at(m, "evaluate_suite", "on_task", 1, "SIGINT")
        code, _, err = run_cli(m, capsys, *argv, "--out", str(part))
    assert code == 130 and "kept 1 of 2 tasks" in err.strip().splitlines()[-1]
    kept = load_report(part)
    assert kept.partial.finished == ["a"] and kept.n_episodes == 8

    assert run_cli(monkeypatch, capsys, *argv, "--out", str(part), "--resume")[0] == 0
    resumed, expected = load_report(part), load_report(whole)
    assert resumed.partial is None
    assert per_seed(resumed) == per_seed(expected) and len(per_seed(expected)) == 16
    assert [(r.n_episodes, r.successes) for r in resumed.per_task] == [
        (r.n_episodes, r.successes) for r in expected.per_task
    ]


@pytest.mark.heavy  # three episode programs compiled on c
def test_interrupted_sequential_run_keeps_a_prefix_and_resumes(monkeypatch, capsys, tmp_path):
    """Zero policy, chunks of 4 seeds, target half-width 0.2: the uninterrupted run stops
    after 8 episodes. Stopped as the second chunk ends (before its look), the partial report
    keeps the first chunk only; resumed, the run looks after 8 episodes and stops there."""
    argv = ["--backend", "c", "--n-envs", "4", "--max-steps", "3", "--threads", "1"]
    argv += ["--policy", "zero", "--batching", "chunks"]
    argv += ["--target-halfwidth", "0.2", "--max-episodes", "12"]
    whole, part = tmp_path / "whole.json", tmp_path / "part.json"
    assert run_cli(monkeypatch, capsys, *argv, "--out", str(whole))[0] == 0

    with monkeypatch.context() as m:
        stop_at(m, "evaluate_spec", "on_chunk", 8, "SIGINT")
        code, _, err = run_cli(m, capsys, *argv, "--out", str(part))
    assert code == 130 and "kept 4 of 12 episodes" in err.strip().splitlines()[-1]
    kept = load_report(part)
    assert kept.n_episodes == 4 and [e.metadata["seed"] for e in kept.episodes] == [0, 1, 2, 3]
    assert kept.sequential.stopped == "interrupted" and kept.partial.unit == "episodes"

    assert run_cli(monkeypatch, capsys, *argv, "--out", str(part), "--resume")[0] == 0
    resumed, expected = load_report(part), load_report(whole)
    assert resumed.partial is None and resumed.n_episodes == expected.n_episodes == 8
    assert per_seed(resumed) == per_seed(expected)
    assert (resumed.ci_low, resumed.ci_high, resumed.sequential.looks) == (
        expected.ci_low,
        expected.ci_high,
        expected.sequential.looks,
    )


@pytest.mark.heavy  # two episode programs compiled on c
def test_interrupted_fixed_run_keeps_its_finished_chunks_and_resumes(monkeypatch, capsys, tmp_path):
    """A plain run of 12 seeds in chunks of 4, stopped as its second chunk ends (before it is
    kept): the partial report keeps the first chunk's seeds (a prefix), and --resume runs the
    rest to the uninterrupted run's episodes, seed by seed, and its interval."""
    argv = ["--backend", "c", "--n-envs", "4", "--max-steps", "4", "--threads", "1"]
    argv += ["--policy", "random", "--batching", "chunks", "--n-episodes", "12"]
    whole, part = tmp_path / "whole.json", tmp_path / "part.json"
    assert run_cli(monkeypatch, capsys, *argv, "--out", str(whole))[0] == 0

    with monkeypatch.context() as m:
        stop_at(m, "evaluate_spec", "on_chunk", 8, "SIGINT")
        code, _, err = run_cli(m, capsys, *argv, "--out", str(part))
    line = err.strip().splitlines()[-1]
    assert code == 130 and line.startswith("interrupted (SIGINT): kept 4 of 12 episodes"), err
    assert "Traceback" not in err
    kept = load_report(part)
    assert [e.metadata["seed"] for e in kept.episodes] == [0, 1, 2, 3]
    assert kept.partial.unit == "episodes" and kept.sequential is None

    assert run_cli(monkeypatch, capsys, *argv, "--out", str(part), "--resume")[0] == 0
    resumed, expected = load_report(part), load_report(whole)
    assert resumed.partial is None and resumed.n_episodes == expected.n_episodes == 12
    assert per_seed(resumed) == per_seed(expected)
    assert (resumed.ci_low, resumed.ci_high) == (expected.ci_low, expected.ci_high)


def test_stop_pool_ends_running_task_processes():
    """An interrupted `--task-processes` suite ends its processes, not waits for them."""
    pool = concurrent.futures.ProcessPoolExecutor(
        1, mp_context=multiprocessing.get_context("spawn")
    )
    worker = pool.submit(os.getpid).result(timeout=60)  # the process is up and taking work
    pool.submit(time.sleep, 120)
    processes = list(pool._processes.values())
    assert [p.pid for p in processes] == [worker]
    start = time.monotonic()
    suite_module.stop_pool(pool)
    assert time.monotonic() - start < 10
    assert not any(p.is_alive() for p in processes)


class _ReapedLate:
    """A pool process whose exit code the pool's own thread has not stored yet: `exitcode`
    reads None until a few `join`s have passed (the race a CI run lost once)."""

    def __init__(self, code: int, joins_before: int) -> None:
        self.code, self.joins_left = code, joins_before

    @property
    def exitcode(self) -> int | None:
        return None if self.joins_left else self.code

    def join(self, timeout: float | None = None) -> None:
        self.joins_left = max(0, self.joins_left - 1)


def test_a_dead_task_process_is_named_by_its_signal_even_when_reaped_late():
    """The one-line error names the signal although the exit code arrives late; the pool's
    SIGTERM to the other processes is not the cause; no code at all reads 'ended abruptly'."""
    late = [_ReapedLate(-signal.SIGKILL, 3), _ReapedLate(-signal.SIGTERM, 1)]
    assert suite_module._death(late).startswith("was killed by SIGKILL")
    assert suite_module._death([_ReapedLate(3, 2)]) == "exited with code 3"
    assert suite_module._death([_ReapedLate(1, 10**9)], wait_s=0.2) == "ended abruptly"


def test_diverging_run_counts_mujoco_warnings(monkeypatch, capfd, tmp_path):
    """An arm whose joints have negative damping diverges in every env: the episodes count as
    diverged, MuJoCo's per-occurrence warnings become one summary line and report counts, and
    nothing (no MUJOCO_LOG.TXT) lands in the working directory."""
    arm = tmp_path / "arm"
    shutil.copytree(ARMS, arm)
    xml = arm / "small6.xml"
    text = xml.read_text()
    assert 'damping="0.3"' in text
    xml.write_text(text.replace('damping="0.3"', 'damping="-50"'))
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    out = tmp_path / "r.json"
    argv = [*COMMON, "--robot-mjcf", str(xml), "--opt", "ee_site=tool0", "--no-breakdown"]
    monkeypatch.setattr(sys, "argv", ["openral_mjx.eval", *argv, "--out", str(out)])
    with pytest.raises(SystemExit) as exc:
        eval_cli.main()
    stdout, stderr = capfd.readouterr()
    assert exc.value.code == 0
    report = load_report(out)
    assert report.diverged == 8 and report.mujoco_warnings.get("BADQACC", 0) > 0
    assert "Nan, Inf or huge value" not in stdout + stderr
    lines = [line for line in stderr.splitlines() if line.startswith("mujoco warnings:")]
    assert lines == [
        f"mujoco warnings: BADQACC {report.mujoco_warnings['BADQACC']:,} (counted, not "
        "printed; by kind in the report's mujoco_warnings)"
    ]
    assert list(cwd.iterdir()) == []


def _dying_suite(monkeypatch, tmp_path, tasks: list[str]):
    """A suite of `tasks` whose task processes run `task_faults.run_task` (saved reports, and
    SIGKILL where a marker says): the process pool's handling is what is under test."""
    import functools

    import task_faults

    from openral_mjx.evaluation import evaluate

    base = evaluate("tabletop_push", "zero", n_envs=2, max_steps=2, backend="c", threads=1)
    for task in tasks:
        row = dataclasses.replace(base.per_task[0], task=task)
        save_report(dataclasses.replace(base, task=task, per_task=[row]), tmp_path / f"{task}.json")
    monkeypatch.setattr(suite_module, "scene_suite", lambda scene, suite: list(tasks))
    monkeypatch.setattr(eval_plan, "scene_suite", lambda scene, suite: list(tasks))
    in_processes = functools.partial(
        suite_module._suite_in_processes, run_task=task_faults.run_task
    )
    monkeypatch.setattr(suite_module, "_suite_in_processes", in_processes)
    monkeypatch.setenv(task_faults.FOLDER, str(tmp_path))
    return [
        *COMMON,
        "--scene",
        "metaworld_mjx",
        "--suite",
        "abc",
        "--policy",
        "zero",
        "--task-processes",
        "2",
    ]


@pytest.mark.heavy  # ~8 task processes started (spawn, ~3 s each on 2 busy cores)
def test_a_killed_task_process_restarts_its_tasks_and_one_that_dies_alone_keeps_the_rest(
    monkeypatch, capsys, tmp_path
):
    """A task process killed by SIGKILL (the out-of-memory killer's signal) broke the pool and
    the whole suite with a traceback (four LIBERO suites at once on one H200). Now the
    unfinished tasks start again with half the processes, after a one-line warning; a task
    whose process dies even alone ends the run with one line, exit code 1, and the finished
    tasks kept as a partial report that --resume finishes."""
    tasks = ["a", "b", "c", "d"]
    argv = _dying_suite(monkeypatch, tmp_path, tasks)
    out = tmp_path / "suite.json"
    (tmp_path / "b.die-once").touch()
    code, _, err = run_cli(monkeypatch, capsys, *argv, "--out", str(out))
    assert code == 0, err
    warning = [line for line in err.splitlines() if line.startswith("warning: a task process")]
    assert len(warning) == 1 and "was killed by SIGKILL" in warning[0], err
    assert "1 at a time" in warning[0] and "Traceback" not in err
    report = load_report(out)
    assert [r.task for r in report.per_task] == tasks and report.partial is None

    (tmp_path / "c.die").touch()
    code, _, err = run_cli(monkeypatch, capsys, *argv, "--out", str(out))
    line = err.strip().splitlines()[-1]
    assert code == 1 and "Traceback" not in err, err
    assert line.startswith("error: task c's process was killed by SIGKILL"), line
    assert "kept 2 of 4 tasks" in line and line.endswith("--resume"), line
    kept = load_report(out)
    assert kept.partial.finished == ["a", "b"]

    (tmp_path / "c.die").unlink()
    assert run_cli(monkeypatch, capsys, *argv, "--out", str(out), "--resume")[0] == 0
    resumed = load_report(out)
    assert resumed.partial is None and [r.task for r in resumed.per_task] == tasks
