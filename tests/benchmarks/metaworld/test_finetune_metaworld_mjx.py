"""PPO on the `metaworld_mjx` mirror, on the CPU (`c`): the reward it trains on is MetaWorld's
on all 50 tasks (checked against MetaWorld itself, in its worker environment), a task whose
reward were not ported would be refused, and a small run improves reach-v3 on held-out seeds,
by the run's own paired comparison of the final policy against the initial one. The mirror
reads MetaWorld's model from the `metaworld` worker environment: without it these tests are
skipped (CI creates it)."""

from __future__ import annotations

import json
import sys
import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from worker_envs import require_worker_envs

from openral_mjx import finetune
from openral_mjx.benchmarks.metaworld import agreement
from openral_mjx.benchmarks.metaworld.mirror.tasks import TASKS, rewarded_tasks
from openral_mjx.physics import PhysicsSettings
from openral_mjx.scenes import make_scene

ENV = "metaworld"
require_worker_envs(ENV)
pytestmark = pytest.mark.worker

SCENE = ["--scene", "metaworld_mjx", "--backend", "c", "--threads", "2", "--no-compile-cache"]


def _finetune(monkeypatch, capsys, *argv):
    monkeypatch.setattr(sys, "argv", ["finetune", *argv])
    with pytest.raises(SystemExit) as exc:
        finetune.main()
    out, err = capsys.readouterr()
    return exc.value.code, out, err


def _host(worker, method, **kwargs):
    return worker.call({"op": "call", "method": method, "kwargs": kwargs}, agreement.TIMEOUT_S)


@pytest.mark.parametrize("task", [t for t in rewarded_tasks() if t.startswith("reach")])
def test_reward_is_metaworlds(task):
    """The reach tasks' reward against MetaWorld's `step` reward over random actions: exactly
    (to float32) on MetaWorld's own states, and closely on the mirror's (MuJoCo 4.0 against
    3.3). The other rewarded tasks: `test_reward_is_metaworlds_under_its_expert`."""
    scene = make_scene(
        "metaworld_mjx", {"task": task}, backend="c", settings=PhysicsSettings(threads=1)
    )
    seeds = np.arange(3)
    steps = 60
    rng = np.random.default_rng(0)
    # Random actions biased towards the goal (`goal - hand`), so both ends of the reward's
    # range (far from the goal, and inside its radius) are visited.
    state = agreement.mirror_resets(scene, seeds)
    step = jax.jit(jax.vmap(scene.step))
    logic = TASKS[task]
    host_r, mirror_r, formula_r = [], [], []
    with agreement.host_workers(task, 1) as (worker,):
        for i in range(len(seeds)):
            _host(worker, "reset", options={"rand_vec": np.asarray(state.info["vec"][i])})
            target = _host(worker, "state")["target_pos"]
            np.testing.assert_allclose(
                target, np.asarray(state.info["episode"]["target_pos"][i]), atol=1e-6
            )
        s = state
        actions = np.zeros((steps, len(seeds), 4), np.float32)
        for t in range(steps):
            to_goal = np.asarray(s.info["episode"]["target_pos"] - s.obs[:, :3])
            a = np.clip(60 * to_goal + rng.normal(0, 0.5, to_goal.shape), -1, 1)
            actions[t, :, :3] = a
            actions[t, :, 3] = rng.uniform(-1, 1, len(seeds))
            s = step(s, jnp.asarray(actions[t]))
            mirror_r.append(np.asarray(s.reward))
        mirror_r = np.stack(mirror_r, axis=1)
        for i in range(len(seeds)):
            _host(worker, "reset", options={"rand_vec": np.asarray(state.info["vec"][i])})
            episode = {"target_pos": jnp.asarray(state.info["episode"]["target_pos"][i])}
            rewards, formula = [], []
            for t in range(steps):
                _, reward, _, _, _ = _host(worker, "step", action=actions[t, i])
                tcp = _host(worker, "state")["tcp_center"]
                view = types.SimpleNamespace(tcp_center=jnp.asarray(tcp, jnp.float32))
                rewards.append(reward)
                formula.append(float(logic.reward(None, view, episode, jnp.asarray(actions[t, i]))))
            host_r.append(rewards)
            formula_r.append(formula)
    scene.close()
    host_r, formula_r = np.asarray(host_r), np.asarray(formula_r)
    # Both ends of the range were visited.
    assert host_r.min() < 3.0 and host_r.max() == pytest.approx(10.0)
    np.testing.assert_allclose(formula_r, host_r, rtol=1e-5, atol=1e-5)
    # The mirror's own trajectories stay within a few mm of MetaWorld's: the rewards agree closely.
    diff = np.abs(mirror_r - host_r)
    assert diff.max() < 0.5 and diff.mean() < 0.05, (diff.max(), diff.mean())


@pytest.fixture(scope="module")
def expert_worker():
    """One MetaWorld worker on the mirror's MuJoCo (engine ``ours``), re-initialised for each
    task: starting a worker took ~2.5 s of a task's ~6 s check."""
    with agreement.host_workers("reach-v3", 1, engine="ours") as (worker,):
        yield worker


# The seed each task's check starts from: 0, except where MetaWorld's reward does not get
# through its stages in the expert's first 150 steps there (disassemble-v3: 0 for all 500
# steps of seed 0; push-back-v3: below 0.15 for 300 steps of seeds 0, 1 and 3).
SEEDS = {"disassemble-v3": 1, "push-back-v3": 2}
EXPERT_STEPS = 150  # one seed's 150 expert steps take the reward through its stages


@pytest.mark.parametrize("task", [t for t in rewarded_tasks() if not t.startswith("reach")])
def test_reward_is_metaworlds_under_its_expert(task, expert_worker):
    """MetaWorld's scripted expert drives MetaWorld's own code on the mirror's MuJoCo (engine
    ``ours``). The mirror's reward formula on MetaWorld's own states (its joint positions put
    into the mirror's physics) gives MetaWorld's reward to float32; the mirror replaying the
    expert's actions from the same reset gives it too while the two stay together (its
    trajectory can part by centimetres where the open-loop replay pushes an object, and a
    reward threshold can fall between two states a fraction of a millimetre apart)."""
    scene = make_scene(
        "metaworld_mjx", {"task": task}, backend="c", settings=PhysicsSettings(threads=1)
    )
    seed = SEEDS.get(task, 0)
    state = agreement.mirror_resets(scene, np.arange(seed, seed + 1))
    logic = TASKS[task]
    moved = bool(logic.moved_bodies)
    episode = jax.tree.map(lambda x: x[0], state.info["episode"])

    @jax.jit
    @jax.vmap  # over the trace's steps (the backends run batches)
    def formula(qpos, qvel, body_pos, obs, action):
        fields = {"body_pos": body_pos} if moved else None
        view = scene._view(scene.backend.init(qpos, qvel, fields=fields))
        return logic.reward(obs, view, episode, action)

    init = {"op": "init", "factory": agreement.FACTORY, "kwargs": {"task": task}}
    expert_worker.call(init, agreement.TIMEOUT_S)
    vec = np.asarray(state.info["vec"][0])
    trace = _host(expert_worker, "expert_trace", rand_vec=vec, steps=EXPERT_STEPS)
    args = [trace[k] for k in ("qpos", "qvel", "body_pos", "obs", "action")]
    formula_r = np.asarray(formula(*(jnp.asarray(a, jnp.float32) for a in args)))
    host_r, actions = trace["reward"], trace["action"]
    step = jax.jit(jax.vmap(scene.step))
    mirror_r, mirror_obs = [], []
    for t in range(EXPERT_STEPS):
        state = step(state, jnp.asarray(actions[t])[None])
        mirror_r.append(float(state.reward[0]))
        mirror_obs.append(np.asarray(state.obs[0, :18]))
    scene.close()
    assert host_r.max() - host_r.min() > 0.5, (host_r.min(), host_r.max())  # not constant
    np.testing.assert_allclose(formula_r, host_r, rtol=1e-4, atol=1e-3)
    together = np.abs(np.stack(mirror_obs) - trace["obs"][:, :18]).max(axis=-1) < 1e-3
    assert together[:10].all()  # the replay starts where MetaWorld does
    diff = np.abs(np.asarray(mirror_r) - host_r)[together]
    # within 0.1 (push: 0.018 at 1 mm apart) but where a threshold of the reward falls
    # between the two states: 1% of the steps, or one (stick-pull: one step in 93)
    assert np.sum(diff >= 0.1) <= max(1, 0.01 * diff.size), np.sort(diff)[-5:]


# MetaWorld takes bin-picking's in-place margin at the first step, the mirror at the reset:
# where the first step moves the cube (7.7 mm on seed 3) the rewards part by up to 5.9e-3.
FIRST_STEP_MARGIN = {"bin-picking-v3": 1e-2}


@pytest.mark.slow  # 48 tasks x 5 seeds
@pytest.mark.parametrize("task", [t for t in rewarded_tasks() if not t.startswith("reach")])
def test_reward_formula_is_metaworlds_on_five_seeds(task, expert_worker):
    """The formula half of `test_reward_is_metaworlds_under_its_expert` on seeds 0-4: the
    mirror's reward on MetaWorld's own states under its expert is MetaWorld's `step` reward."""
    scene = make_scene(
        "metaworld_mjx", {"task": task}, backend="c", settings=PhysicsSettings(threads=1)
    )
    seeds = np.arange(5)
    state = agreement.mirror_resets(scene, seeds)
    logic = TASKS[task]
    moved = bool(logic.moved_bodies)

    @jax.jit
    @jax.vmap  # over the trace's steps
    def formula(qpos, qvel, body_pos, obs, action, episode):
        fields = {"body_pos": body_pos} if moved else None
        view = scene._view(scene.backend.init(qpos, qvel, fields=fields))
        return logic.reward(obs, view, episode, action)

    init = {"op": "init", "factory": agreement.FACTORY, "kwargs": {"task": task}}
    expert_worker.call(init, agreement.TIMEOUT_S)
    for i in seeds:
        vec = np.asarray(state.info["vec"][i])
        trace = _host(expert_worker, "expert_trace", rand_vec=vec, steps=EXPERT_STEPS)
        episode = jax.tree.map(
            lambda x, i=i: jnp.broadcast_to(x[i], (EXPERT_STEPS, *x.shape[1:])),
            state.info["episode"],
        )
        args = [trace[k] for k in ("qpos", "qvel", "body_pos", "obs", "action")]
        formula_r = np.asarray(formula(*(jnp.asarray(a, jnp.float32) for a in args), episode))
        atol = FIRST_STEP_MARGIN.get(task, 1e-3)
        np.testing.assert_allclose(
            formula_r, trace["reward"], rtol=1e-4, atol=atol, err_msg=f"seed {i}"
        )
    scene.close()


def test_ppo_refuses_a_task_without_reward(monkeypatch, capsys, tmp_path):
    """Every task ports MetaWorld's reward; one that did not (`has_reward` False) would be
    refused with a one-line error rather than trained on 0."""
    no_reward = "soccer-v3"
    monkeypatch.setattr(type(TASKS[no_reward]), "has_reward", False)
    out = tmp_path / "run"
    code, _, err = _finetune(
        monkeypatch, capsys, "ppo", *SCENE, "--task", no_reward, "--out", str(out)
    )
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: "), err
    assert f"task {no_reward!r} has no reward" in lines[0]
    assert ", ".join(rewarded_tasks()) in lines[0] and "reach-v3" in lines[0]
    assert not out.exists()


# PPO from scratch on reach-v3, CPU-sized (~50k env steps, about a minute of training and
# compilation on 2 cores). `--reward-scale 0.01`: success ends a mirror episode, so the
# success bonus (10) must be worth at least staying at the goal, 10 x 0.01 / (1 - 0.99) = 10,
# or PPO learns to hover just outside the goal radius. `--action-scale 0.5`: one unit of the
# network's output moves the hand half its full speed (0.05, made for position servos, barely
# moves it).
PPO = ["--task", "reach-v3", "--n-envs", "64", "--unroll-length", "16", "--minibatches", "4"]
PPO += ["--epochs", "4", "--max-steps", "100", "--hidden", "64", "64", "--action-scale", "0.5"]
PPO += ["--reward-scale", "0.01", "--num-timesteps", "49152", "--eval-every", "48"]
PPO += ["--checkpoint-every", "48", "--eval-episodes", "64", "--eval-n-envs", "64"]


@pytest.mark.slow
def test_ppo_improves_reach_on_held_out_seeds(monkeypatch, capsys, tmp_path):
    """The run's own paired comparison of its final policy against its initial one on the same
    64 validation seeds (neither chosen on them): measured 0% -> 95.3%, McNemar p = 9e-19."""
    out = tmp_path / "run"
    code, stdout, err = _finetune(monkeypatch, capsys, "ppo", *SCENE, *PPO, "--out", str(out))
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    vs = summary["final_vs_init"]
    assert vs["n_episodes"] == 64 and vs["test"] == "mcnemar-exact"
    assert vs["difference"] >= 0.5 and vs["ci_low"] > 0.25 and vs["p_value"] < 1e-6, vs
    assert summary["init"]["success_rate"] <= 0.1 <= 0.6 <= summary["final_success_rate"]
    assert "McNemar p = " in stdout and "--task reach-v3 --max-steps 100" in stdout
    # The start is kept for a before/after evaluation on test seeds.
    assert (out / "init" / "mlp_policy.json").is_file()
