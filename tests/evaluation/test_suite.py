"""Suites: a task process keeps the policy it built for its next task (a lerobot checkpoint
takes seconds to load), builds one bound to a task again, and its report times what it built
(`build_s`); a pool of task processes starts the longest tasks first and reports in the
suite's order; a run over several suites prints each suite's average."""

import concurrent.futures
import dataclasses

import pytest
from cli_runs import per_seed

from openral_mjx.evaluation import RunSpec, evaluate
from openral_mjx.evaluation import suite as suite_module
from openral_mjx.evaluation.run import build_scene
from openral_mjx.policies import make_policy
from openral_mjx.report import TaskRow
from openral_mjx.scenes import scene_suite

FRICTIONS = {"a": 0.2, "b": 1.0}
SPEC = RunSpec(backend="c", n_envs=4, n_episodes=4, max_steps=5, threads=1)


@pytest.fixture
def tasks(monkeypatch):
    """Two stand-in tasks on a cheap scene (tabletop_push with the task's friction), and the
    policies made for them, each a `random` policy (bound to its task where `bound` says),
    whose closes are counted."""
    made: list[str] = []
    closed: list[str] = []
    bound = {"per_task": False}

    def stand_in(name, options, spec, randomize=()):
        friction = f"friction={FRICTIONS[options['task']]}"
        return build_scene("tabletop_push", backend="c", n_envs=4, threads=1, randomize=[friction])

    def counted(name, scene):
        made.append(scene.describe())
        policy = make_policy(name, scene)
        return dataclasses.replace(
            policy, per_task=bound["per_task"], close=lambda: closed.append(name)
        )

    monkeypatch.setattr(suite_module, "build_spec_scene", stand_in)
    monkeypatch.setattr(suite_module, "make_policy", counted)
    return made, closed, bound


def report(task: str, kept: dict | None):
    return suite_module._task_report("tabletop_push", task, "random", {}, SPEC, kept)


def test_a_policy_is_kept_for_the_next_task_and_runs_the_same_episodes(tasks):
    made, closed, _ = tasks
    kept: dict = {}
    first = report("a", kept)
    second = report("b", kept)
    assert len(made) == 1 and list(kept) == ["random"] and closed == []
    # both timed their scene and policy (the second: only the kept policy's parameters)
    assert set(first.build_s) == set(second.build_s) == {"scene", "policy"}
    fresh = report("b", None)
    assert len(made) == 2 and closed == ["random"]  # built for it and closed after it
    assert per_seed(second) == per_seed(fresh) and len(per_seed(fresh)) == 4
    suite_module._close_kept(kept)
    assert kept == {} and closed == ["random", "random"]


def test_a_policy_bound_to_its_task_is_built_for_each_and_never_kept(tasks):
    made, closed, bound = tasks
    bound["per_task"] = True
    kept: dict = {}
    report("a", kept)
    report("b", kept)
    assert len(made) == 2 and made[0] != made[1]  # one per task's scene
    assert kept == {} and closed == ["random", "random"]


def test_several_suites_print_each_suites_average_and_the_whole_one():
    """Over `libero_spatial,libero_10` (half of spatial's tasks and all but one of libero_10's
    succeed), each suite's average over its rows, then the average over all of them; a
    partial report (libero_10's last task missing) averages what it holds."""
    one = evaluate("tabletop_push", "zero", n_envs=2, n_episodes=2, max_steps=1, backend="c")
    tasks = scene_suite("libero_mjx", "libero_spatial,libero_10")[:-1]
    won = {t: int(t.startswith("libero_10") or int(t[-1]) % 2 == 0) for t in tasks}
    rows = [TaskRow(t, 1, won[t], float(won[t]), 0.0, 1.0) for t in tasks]
    report = dataclasses.replace(
        one, scene="libero_mjx", task="libero_spatial,libero_10", per_task=rows
    )
    lines = suite_module.format_tasks(report).splitlines()
    assert lines[-3:] == [
        "  libero_spatial: average of 10 tasks: 50.0%",
        "  libero_10: average of 9 tasks: 100.0%",
        "  average of 19 tasks: 73.7%",
    ]
    single = dataclasses.replace(report, task="libero_spatial", per_task=rows[:10])
    assert suite_module.format_tasks(single).splitlines()[-1] == "  average of 10 tasks: 50.0%"


class _OneThread(concurrent.futures.ThreadPoolExecutor):
    """A pool of one thread in place of the task processes (a process's initializer would set
    this test process's memory share): it runs tasks in the order they are submitted."""

    def __init__(self, max_workers, mp_context, initializer, initargs):
        super().__init__(max_workers=1)


def test_a_pool_starts_the_longest_tasks_first_and_reports_in_suite_order(monkeypatch):
    """`libero_spatial,libero_10` in a pool: libero_10's tasks (520 steps) start before
    libero_spatial's (280), while the report keeps the suite's order."""
    one = evaluate("tabletop_push", "zero", n_envs=2, n_episodes=2, max_steps=1, backend="c")
    tasks = scene_suite("libero_mjx", "libero_spatial,libero_10")
    started: list[str] = []

    def run_task(scene, task, policy, options, spec):
        started.append(task)
        return dataclasses.replace(one, task=task)

    monkeypatch.setattr(suite_module.concurrent.futures, "ProcessPoolExecutor", _OneThread)
    reports: list = []
    spec = RunSpec(backend="c", n_envs=2, n_episodes=2)
    suite_module._suite_in_processes(
        "libero_mjx", "zero", tasks, {}, spec, 2, None, None, reports, run_task
    )
    assert started == tasks[10:] + tasks[:10]
    assert [r.task for r in reports] == tasks
