"""Task instructions: every scene and task has one, reports record it, policies receive it."""

from __future__ import annotations

import dataclasses
import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from openral_mjx.benchmarks.aloha import host_scene as aloha
from openral_mjx.benchmarks.libero import host_scene as libero
from openral_mjx.benchmarks.libero.instructions import INSTRUCTIONS as LIBERO
from openral_mjx.benchmarks.metaworld import host_scene as mw
from openral_mjx.benchmarks.metaworld.mirror.tasks import TASKS as MIRROR_TASKS
from openral_mjx.benchmarks.pusht import host_scene as pusht
from openral_mjx.benchmarks.robosuite import host_scene as robosuite
from openral_mjx.evaluation.suite import merge_reports
from openral_mjx.host import envs
from openral_mjx.physics import PhysicsSettings
from openral_mjx.policies.lerobot import LerobotClient
from openral_mjx.report import EvalReport
from openral_mjx.scenes import SCENES, Scene, make_scene, scene_options


@pytest.fixture
def no_worker_envs(monkeypatch) -> set[str]:
    """Host scenes build with this interpreter for a worker environment not created here:
    nothing is created or started (workers start only in `prepare`). Returns the environments
    that were ready, read before the override (which makes every environment read as ready)."""
    ready = {name for name in envs.RECIPES if envs.is_ready(name)}
    for name in set(envs.RECIPES) - ready:
        variable = f"OPENRAL_MJX_PYTHON_{name.upper().replace('-', '_')}"
        monkeypatch.setenv(variable, sys.executable)
    return ready


def test_every_registered_scene_writes_an_instruction(no_worker_envs):
    """Known when the scene is built (host scenes start no worker for it), never the fallback;
    the mirrors say what their host scenes say."""
    said = {}
    for name in SCENES.names():
        if name == "metaworld_mjx" and "metaworld" not in no_worker_envs:  # its model's files
            said[name] = mw.instruction(scene_options(name).task)
            continue
        if name == "libero_mjx" and "lerobot-libero" not in no_worker_envs:  # its model's export
            said[name] = libero.instruction(scene_options(name).task)
            continue
        host = SCENES.get(name).backends == ("host",)
        scene = make_scene(
            name, backend="host" if host else "c", settings=PhysicsSettings(threads=1)
        )
        try:
            said[name] = text = scene.instruction
            assert isinstance(text, str) and text.strip(), name
            assert text != Scene.instruction.fget(scene), f"{name} uses the fallback"
        finally:
            scene.close()
    assert said["metaworld"] == said["metaworld_mjx"] == "Reach a goal position"
    assert said["libero"] == said["libero_mjx"]


def test_every_task_of_every_suite_has_one():
    by_scene = {
        "metaworld": mw.instruction,
        "metaworld_mjx": mw.instruction,
        "libero": libero.instruction,
        "libero_mjx": libero.instruction,
        "aloha": aloha.INSTRUCTIONS.__getitem__,
    }
    assert {n for n in SCENES.names() if SCENES.get(n).suites} == set(by_scene)
    for name, instruction in by_scene.items():
        suites = importlib.import_module(SCENES.get(name).suites.__module__).SUITES
        for suite in suites:
            for task in SCENES.get(name).suites(suite):
                assert instruction(task).strip(), (name, task)
    assert set(mw.INSTRUCTIONS) == set(mw.TASKS) == set(MIRROR_TASKS)
    assert [len(v) for v in LIBERO.values()] == [n for n, _ in libero.SUITES.values()]
    assert set(aloha.INSTRUCTIONS) == set(aloha.TASKS) and set(pusht.INSTRUCTIONS) == set(
        pusht.TASKS
    )
    assert set(robosuite.INSTRUCTIONS) == set(robosuite.OBJECT_SIZE)
    assert libero.instruction("libero_goal/7") == "turn on the stove"


def _site_packages(env: str):
    found = sorted(envs.env_dir(env).glob("lib/python*/site-packages"))
    if not envs.is_ready(env) or not found:
        pytest.skip(f"worker environment {env!r} not created ({envs.create_command(env)})")
    return found[0]


def test_written_down_text_is_the_installed_packages():
    """MetaWorld's is lerobot's data file; LIBERO's names each task's BDDL file (its task map,
    a data module), whose name ends with the instruction's words."""
    site = _site_packages("lerobot-libero")
    data = json.loads((site / "lerobot/envs/metaworld_config.json").read_text())
    assert data["TASK_DESCRIPTIONS"] == mw.INSTRUCTIONS
    task_map: dict = {}
    exec((site / "libero/libero/benchmark/libero_suite_task_map.py").read_text(), task_map)
    for suite, names in task_map["libero_task_map"].items():
        if suite in LIBERO:
            assert len(names) == len(LIBERO[suite]), suite
            for file_name, text in zip(names, LIBERO[suite], strict=True):
                assert file_name.endswith(text.replace(" ", "_")), (file_name, text)


@pytest.mark.slow
def test_libero_text_is_libero_tasks_language():
    """Strictly: LIBERO's own `task.language` for every task (imports LIBERO: slow)."""
    python = envs.env_python("lerobot-libero")
    _site_packages("lerobot-libero")
    script = (
        "import json; from openral_mjx.benchmarks.libero.worker_env import configure; configure(); "
        "from libero.libero import benchmark; d = benchmark.get_benchmark_dict(); "
        "print(json.dumps({s: [d[s]().get_task(i).language for i in range(d[s]().n_tasks)] "
        f"for s in {list(LIBERO)!r}}}))"
    )
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[2])}
    proc = subprocess.run([str(python), "-c", script], env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == {
        k: list(v) for k, v in LIBERO.items()
    }


SAVED = Path(__file__).parents[2] / "benchmarks/2026-11-23-ci2core/rays/box_c_nodepth.json"


def test_reports_before_5_read_without_it_and_suites_keep_each_tasks():
    """(A run's report records its scene's: `test_schema.test_report_records_the_instruction`.)"""
    old = EvalReport.from_dict(json.loads(SAVED.read_text()))  # a /2 report
    assert old.instruction is None and old.per_task[0].instruction is None
    a = dataclasses.replace(old, instruction="do a")
    a.per_task = [dataclasses.replace(old.per_task[0], instruction="do a")]
    b = dataclasses.replace(a, task="b", instruction="do b")
    b.per_task = [dataclasses.replace(old.per_task[0], task="b", instruction="do b")]
    merged = merge_reports([a, b], "suite", "scripted", "")
    assert merged.instruction is None  # one per task, in the rows
    assert [r.instruction for r in merged.per_task] == ["do a", "do b"]
    again = EvalReport.from_dict(merged.to_dict())
    assert again.per_task == merged.per_task and again.schema_version == old.schema_version


FACTORY = """
import torch

seen = {}


class Module(torch.nn.Module):
    def __init__(self, action_size):
        super().__init__()
        self.action_size = action_size

    def forward(self, obs, task):
        seen["step"] = list(task)
        return torch.zeros(obs.shape[0], self.action_size)


def make(action_size, task, instruction):
    seen["factory"] = (task, instruction)
    return Module(action_size)
"""


def test_torch_policy_receives_it(push_c, tmp_path):
    pytest.importorskip("torch")
    from openral_mjx.policies.torch_policy import torch_policy

    path = tmp_path / "vla.py"
    path.write_text(FACTORY)
    policy = torch_policy(push_c, f"{path}:make")
    seen = sys.modules["openral_mjx_torch_vla"].seen
    text = push_c.instruction
    assert seen["factory"] == (text, text)
    assert seen["step"] == [text, text]  # the dry run: one string per env
    policy.instruct("push it harder")
    params, pstate = policy.init(None, None)
    obs = jnp.zeros(push_c.observation_size, jnp.float32)
    action, _ = policy.act(params, pstate, obs, None)
    assert np.shape(action) == (push_c.action_size,)
    assert seen["step"] == ["push it harder"]


class _Worker:
    alive = True

    def __init__(self) -> None:
        self.sent: list[dict] = []

    def call(self, message: dict, timeout: float) -> dict:
        self.sent.append(message)
        n = len(next(iter(message["kwargs"]["obs"].values())))
        return {"action": np.zeros((n, 2), np.float32)}


def test_lerobot_client_sends_it_as_task(tmp_path):
    client = LerobotClient(tmp_path, {"observation.state": "state"}, 2, "open the drawer")
    client.worker = worker = _Worker()  # type: ignore[assignment]
    obs = {"state": np.zeros((3, 4), np.float32)}
    client(obs, np.zeros(3, np.int32))
    client.instruct("close the drawer")
    client(obs, np.ones(3, np.int32))
    assert [m["kwargs"]["task"] for m in worker.sent] == ["open the drawer", "close the drawer"]
