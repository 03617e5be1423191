"""`eval` stopped by Ctrl-C or SIGTERM keeps what finished, and `--resume` finishes it.

The interrupt is made deterministic in-process: the progress callback that runs before the
second sweep point (or suite task) raises `KeyboardInterrupt`, or sends this process SIGTERM,
just as a signal arriving then would. Each resumed report is compared, per seed, with an
uninterrupted run of the same arguments on `c` (tabletop_push, 8 envs, short episodes).
"""

import concurrent.futures
import multiprocessing
import os
import signal
import sys
import time

import pytest

from openral_mjx import eval as eval_cli
from openral_mjx.evaluation import suite as suite_module
from openral_mjx.evaluation.run import build_scene
from openral_mjx.report import load_report
from openral_mjx.report.sweep import load_sweep

COMMON = ["--backend", "c", "--n-envs", "8", "--max-steps", "15", "--threads", "1"]
SWEEP = [*COMMON, "--sweep", "friction=0.2:0.6:3", "--no-compile-cache"]


def run_cli(monkeypatch, capsys, *argv):
    monkeypatch.setattr(sys, "argv", ["openral_mjx.eval", *argv])
    with pytest.raises(SystemExit) as exc:
        eval_cli.main()
    out, err = capsys.readouterr()
    return exc.value.code, out, err


def stop_at(monkeypatch, name, keyword, at, how):
    """Wrap `eval_cli.<name>` so that its `keyword` callback stops the run (`how`: raise
    KeyboardInterrupt, or send this process SIGTERM) when called with first argument `at`."""
    real = getattr(eval_cli, name)

    def wrapped(*args, **kwargs):
        inner = kwargs[keyword]

        def hook(i, *rest):
            if i == at:
                if how == "SIGTERM":
                    os.kill(os.getpid(), signal.SIGTERM)
                    time.sleep(5)  # the handler raises before this ends
                raise KeyboardInterrupt
            inner(i, *rest)

        return real(*args, **{**kwargs, keyword: hook})

    monkeypatch.setattr(eval_cli, name, wrapped)


@pytest.mark.parametrize("how, code", [("SIGINT", 130), ("SIGTERM", 143)])
def test_interrupted_sweep_resumes_to_the_uninterrupted_result(
    monkeypatch, capsys, tmp_path, how, code
):
    whole, part = tmp_path / "whole.json", tmp_path / "part.json"
    assert run_cli(monkeypatch, capsys, *SWEEP, "--out", str(whole))[0] == 0

    with monkeypatch.context() as m:
        stop_at(m, "run_sweep", "on_point", 1, how)
        got, _, err = run_cli(m, capsys, *SWEEP, "--out", str(part))
    assert got == code
    line = err.strip().splitlines()[-1]
    assert line.startswith(f"{'terminated' if how == 'SIGTERM' else 'interrupted'} ({how}):")
    assert f"kept 1 of 3 points in {part}" in line and line.endswith("--resume")
    kept = load_sweep(part)
    assert kept.partial is not None and kept.partial.reason.endswith(f"({how})")
    assert kept.partial.finished == ["0.2"] and [p.value for p in kept.points] == [0.2]
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # handlers given back

    assert run_cli(monkeypatch, capsys, *SWEEP, "--out", str(part), "--resume")[0] == 0
    resumed, expected = load_sweep(part), load_sweep(whole)
    assert resumed.partial is None
    assert [(p.value, p.outcomes) for p in resumed.points] == [
        (p.value, p.outcomes) for p in expected.points
    ]
    assert [(s.p_value, s.difference) for s in resumed.steps] == [
        (s.p_value, s.difference) for s in expected.steps
    ]


def test_resume_refuses_another_command_or_a_complete_report(monkeypatch, capsys, tmp_path):
    part = tmp_path / "part.json"
    with monkeypatch.context() as m:
        stop_at(m, "run_sweep", "on_point", 1, "SIGINT")
        assert run_cli(m, capsys, *SWEEP, "--out", str(part))[0] == 130
    other = [a if a != "friction=0.2:0.6:3" else "friction=0.2:0.8:3" for a in SWEEP]
    code, _, err = run_cli(monkeypatch, capsys, *other, "--out", str(part), "--resume")
    assert code == 2 and err.count("\n") == 1 and "written by another command" in err
    code, _, err = run_cli(monkeypatch, capsys, *SWEEP, "--resume")
    assert code == 2 and err.strip() == "error: --resume needs --out: the partial report to pick up from"
    code, _, err = run_cli(monkeypatch, capsys, *COMMON, "--out", str(part), "--resume")
    assert code == 2 and "--resume finishes an interrupted --sweep or --suite" in err
    assert run_cli(monkeypatch, capsys, *SWEEP, "--out", str(part), "--resume")[0] == 0
    code, _, err = run_cli(monkeypatch, capsys, *SWEEP, "--out", str(part), "--resume")
    assert code == 2 and "is complete; nothing to resume" in err


def test_interrupted_suite_resumes_to_the_uninterrupted_result(monkeypatch, capsys, tmp_path):
    """Three stand-in tasks on a cheap MuJoCo scene (the suite machinery is under test), each
    on its own seeds' episodes: `--opt`-free tabletop_push with the task's friction."""
    frictions = {"a": 0.2, "b": 0.6, "c": 1.0}
    monkeypatch.setattr(suite_module, "scene_suite", lambda scene, suite: list(frictions))
    monkeypatch.setattr(eval_cli, "scene_suite", lambda scene, suite: list(frictions))

    def stand_in(name, options, spec, randomize=()):
        friction = f"friction={frictions[options['task']]}"
        return build_scene("tabletop_push", backend="c", n_envs=8, threads=1, randomize=[friction])

    monkeypatch.setattr(suite_module, "build_spec_scene", stand_in)
    argv = [*COMMON, "--scene", "metaworld_mjx", "--suite", "abc", "--policy", "scripted"]
    whole, part = tmp_path / "whole.json", tmp_path / "part.json"
    assert run_cli(monkeypatch, capsys, *argv, "--out", str(whole))[0] == 0

    with monkeypatch.context() as m:
        stop_at(m, "evaluate_suite", "on_task", 2, "SIGINT")
        code, _, err = run_cli(m, capsys, *argv, "--out", str(part))
    assert code == 130 and "kept 2 of 3 tasks" in err.strip().splitlines()[-1]
    kept = load_report(part)
    assert kept.partial.finished == ["a", "b"] and kept.n_episodes == 16

    assert run_cli(monkeypatch, capsys, *argv, "--out", str(part), "--resume")[0] == 0
    resumed, expected = load_report(part), load_report(whole)
    assert resumed.partial is None
    per_seed = [
        [(e.metadata["seed"], e.success, e.steps, e.total_reward) for e in r.episodes]
        for r in (resumed, expected)
    ]
    assert per_seed[0] == per_seed[1] and len(per_seed[0]) == 24
    assert [(r.n_episodes, r.successes) for r in resumed.per_task] == [
        (r.n_episodes, r.successes) for r in expected.per_task
    ]


def test_stop_pool_ends_running_task_processes():
    """An interrupted `--task-processes` suite ends its processes, not waits for them."""
    pool = concurrent.futures.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"))
    future = pool.submit(time.sleep, 120)
    deadline = time.monotonic() + 60
    while not future.running() and time.monotonic() < deadline:
        time.sleep(0.05)
    processes = list(pool._processes.values())
    assert future.running() and processes
    start = time.monotonic()
    suite_module.stop_pool(pool)
    assert time.monotonic() - start < 10
    assert not any(p.is_alive() for p in processes)
