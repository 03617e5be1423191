"""PushT (gym-pusht) through the host adapter (the `gym-envs` worker environment). CI creates
that environment first; elsewhere these tests are skipped until
`python -m openral_mjx.host.envs create gym-envs` has run."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from worker_envs import require_worker_envs

from openral_mjx.benchmarks.pusht import host_scene as pt
from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation import evaluate
from openral_mjx.host import envs
from openral_mjx.host.batch import BatchConfig, EnvBatch
from openral_mjx.host.pool import Worker
from openral_mjx.policies.lerobot import key_map
from openral_mjx.runner.episode import seed_keys
from openral_mjx.scenes import make_scene, scene_options

ENV = "gym-envs"
require_worker_envs(ENV)
pytestmark = pytest.mark.worker

OBS = {"pixels": ((96, 96, 3), "uint8"), "agent_pos": ((2,), "float32")}


@pytest.fixture(scope="module")
def python():
    return envs.ensure_env(ENV)


def _initial(scene, seeds):
    """Reset `seeds` as the runner does (one batched host reset) -> obs and factors."""
    seeds = jnp.asarray(seeds, jnp.int32)
    state = jax.vmap(scene.reset_with_seed)(seeds, seed_keys(seeds)[0])
    return {k: np.asarray(v) for k, v in state.obs.items()}, np.asarray(state.info["factors"])


def test_seed_gives_the_same_initial_state_whatever_ran_before_and_wherever():
    """Seed s -> the same agent and block placement (image, agent position, factors) on a
    repeat after other steps, with another batch size and worker layout; seeds differ."""
    wide = make_scene("pusht", {"n_workers": 2}, backend="host")
    narrow = make_scene("pusht", {"n_workers": 1}, backend="host")
    rng = np.random.default_rng(0)
    try:
        first, factors = _initial(wide, [0, 1, 2, 3])
        wide.batch.step(rng.uniform(0, 512, (4, 2)), np.zeros(4, bool))
        again, factors_again = _initial(wide, [0, 1, 2, 3])
        late, late_factors = _initial(narrow, [3, 2])
    finally:
        wide.close()
        narrow.close()
    assert set(first) == {"pixels", "agent_pos"} and first["pixels"].shape == (4, 96, 96, 3)
    for key in first:
        np.testing.assert_array_equal(again[key], first[key])
        np.testing.assert_array_equal(late[key], first[key][[3, 2]])
    np.testing.assert_array_equal(factors_again, factors)
    np.testing.assert_array_equal(late_factors, factors[[3, 2]])
    assert len({tuple(f) for f in factors}) == 4  # four different placements
    np.testing.assert_allclose(first["agent_pos"], factors[:, 3:], rtol=1e-6)
    agent = factors[:, 3:]  # gym-pusht draws the agent's start from integers in [50, 450)
    assert ((agent >= 50) & (agent < 450) & (agent == np.round(agent))).all()
    assert ((factors[:, :2] > 0) & (factors[:, :2] < 512)).all()  # the block on the table


def test_random_policy_report_carries_the_resets_factors():
    """Random target positions through `evaluate`: a report with every episode's block pose
    and agent position as factors, equal to its reset's; the keypoint observation."""
    options = {"obs_type": "environment_state_agent_pos", "n_workers": 1}
    scene = make_scene("pusht", options, backend="host")
    try:
        (obs, first), (_, second) = _initial(scene, [0, 1]), _initial(scene, [2, 3])
        report = evaluate(scene, "random", n_envs=2, n_episodes=4, max_steps=10)
    finally:
        scene.close()
    want = np.concatenate([first, second])
    assert set(obs) == {"environment_state", "agent_pos"}
    assert obs["environment_state"].shape == (2, 16)
    assert report.backend == "host" and report.task == "PushT-v0" and report.n_episodes == 4
    assert all(e.metadata["error"] is None and e.steps == 10 for e in report.episodes)
    got = [[e.metadata["factors"][k] for k in pt.FACTORS] for e in report.episodes]
    np.testing.assert_array_equal(np.asarray(got, np.float32), want)
    assert 0 <= report.success_rate <= 1


def test_batch_matches_the_env_stepped_directly(python, tmp_path):
    """Two envs in one worker through the adapter against each env alone in a worker: the
    same images and agent positions after the reset and every step."""
    kwargs = {"task": "PushT-v0", "obs_type": "pixels_agent_pos", "image_size": 96}
    actions = np.random.default_rng(1).uniform(0, 512, (4, 2, 2)).astype(np.float32)
    batch = EnvBatch(BatchConfig(python, pt.FACTORY, kwargs, OBS, 2, n_workers=1))
    try:
        trace = [batch.reset(np.array([21, 22]), [{}, {}])]
        trace += [batch.step(a, np.zeros(2, bool)) for a in actions]
    finally:
        batch.close()
    assert all((t["error"] == 0).all() for t in trace)
    worker = Worker(python, {}, tmp_path / "direct.log", name="direct")
    try:
        worker.call({"op": "init", "factory": pt.FACTORY, "kwargs": kwargs}, 120)
        for i, seed in enumerate((21, 22)):
            reset = {"seed": seed, "options": {}}
            want = [worker.call({"op": "call", "method": "reset", "kwargs": reset}, 60)[0]]
            for a in actions[:, i]:
                step = {"op": "call", "method": "step", "kwargs": {"action": a}}
                want.append(worker.call(step, 60)[0])
            for t, w in enumerate(want):
                for key in OBS:
                    np.testing.assert_array_equal(trace[t]["obs"][key][i], w[key], f"{key} {t}")
    finally:
        worker.close()


def test_lerobot_features_map_onto_the_scene():
    """lerobot's PushT policy inputs find the scene's observations by name and shape."""
    scene = make_scene("pusht", {"image_size": 96}, backend="host")
    try:
        obs = {
            k: jax.ShapeDtypeStruct(s, np.dtype(d))
            for k, (s, d) in scene.host_spec.batch.observation.items()
        }
    finally:
        scene.close()
    features = {"observation.image": ("VISUAL", (3, 96, 96)), "observation.state": ("STATE", (2,))}
    assert key_map(features, obs) == {
        "observation.image": "pixels",
        "observation.state": "agent_pos",
    }
    assert scene.max_steps == 300 and scene.backend.control_dt == 0.1


def test_config_errors_are_one_line_and_list_the_valid_names():
    with pytest.raises(ConfigError) as e:
        scene_options("pusht", {"task": "PushT-v1"})
    assert str(e.value) == "unknown PushT task 'PushT-v1'; valid: PushT-v0"
    with pytest.raises(ConfigError) as e:
        scene_options("pusht", {"obs_type": "state"})
    valid = "pixels_agent_pos, environment_state_agent_pos"
    assert str(e.value) == f"unknown PushT obs_type 'state'; valid: {valid}"
    with pytest.raises(ConfigError, match="image_size=0"):
        scene_options("pusht", {"image_size": 0})
    with pytest.raises(ConfigError, match="requires robot 'pusht_agent', not 'so101'"):
        scene_options("pusht", {"robot": "so101"})


@pytest.mark.slow
def test_random_policy_full_episodes():
    """lerobot's protocol length: 300 steps, 10 seeds (random actions rarely succeed)."""
    report = evaluate("pusht", "random", n_envs=10, n_episodes=10)
    assert all(e.metadata["error"] is None for e in report.episodes)
    assert all(e.steps == 300 or e.success for e in report.episodes)
