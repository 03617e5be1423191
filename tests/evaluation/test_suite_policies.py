"""A suite's policy across its tasks: a task process keeps the one it built for its next task
(a lerobot checkpoint takes seconds to load), builds one bound to a task again, and its report
times what it built (`build_s`)."""

import dataclasses

import pytest
from cli_runs import per_seed

from openral_mjx.evaluation import RunSpec
from openral_mjx.evaluation import suite as suite_module
from openral_mjx.evaluation.run import build_scene
from openral_mjx.policies import make_policy

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
