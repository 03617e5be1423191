"""The `mlp` policy: normaliser against numpy, checkpoints round trip through orbax, the runner
acts exactly as training does, episodes do not depend on the batch size, bad checkpoints are
one-line errors."""

import json
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.policies import make_policy
from openral_mjx.policies.mlp import (
    CONFIG_FILE,
    MlpConfig,
    distribution,
    init_params,
    load_mlp,
    save_mlp,
    to_action,
)
from openral_mjx.policies.normalizer import init_stats, normalize, update_stats
from openral_mjx.runner import EpisodeRunner


def test_running_stats_match_numpy():
    rng = np.random.default_rng(0)
    batches = [rng.normal(loc=3.0, scale=s, size=(n, 4)) for s, n in ((0.5, 7), (2.0, 100), (1, 1))]
    stats = init_stats(4)
    for b in batches:
        stats = update_stats(stats, jnp.asarray(b, jnp.float32))
    data = np.concatenate(batches)
    np.testing.assert_allclose(stats.mean, data.mean(0), rtol=1e-5)
    np.testing.assert_allclose(stats.var, data.var(0), rtol=1e-4)
    assert float(stats.count) == len(data)
    z = normalize(stats, jnp.asarray(data[:3], jnp.float32), std_min=0.01, clip=10.0)
    np.testing.assert_allclose(z, (data[:3] - data.mean(0)) / data.std(0), rtol=1e-4, atol=1e-5)


@pytest.fixture(scope="module")
def policy(push_c):
    """A small random policy with a non-trivial normaliser (statistics of reset observations,
    with joint velocities made to vary), built for `tabletop_push`."""
    scene = push_c
    config = MlpConfig(
        obs_size=scene.observation_size,
        action_size=scene.action_size,
        action_offset=(0.01,) * scene.action_size,
        action_scale=(0.1,) * scene.action_size,
        action_base_index=scene.action_obs_index(),
        hidden=(32, 32),
        metadata={"scene": scene.name},
    )
    obs = jax.vmap(scene.reset)(jax.random.split(jax.random.PRNGKey(1), 64)).obs
    obs = obs + 0.3 * jax.random.normal(jax.random.PRNGKey(2), obs.shape)
    params = init_params(config, jax.random.PRNGKey(0), update_stats(init_stats(obs.shape[1]), obs))
    # Make the last layer matter (it is initialised near zero).
    last = params["actor"]["params"]["_Dense_2"]
    last["kernel"] = jax.random.normal(jax.random.PRNGKey(3), last["kernel"].shape)
    return config, params


@pytest.fixture(scope="module")
def saved(policy, tmp_path_factory):
    path = tmp_path_factory.mktemp("mlp") / "ckpt"
    save_mlp(path, *policy)
    return path


def test_checkpoint_round_trip(policy, saved):
    config, params = policy
    loaded_config, loaded = load_mlp(saved)
    assert loaded_config == config and loaded_config.metadata == config.metadata
    jax.tree.map(np.testing.assert_array_equal, loaded, params)
    assert sorted(p.name for p in saved.parent.iterdir()) == ["ckpt"]  # no temp dirs left


def test_runner_acts_as_training_does(push_c, policy, saved):
    """The checkpoint evaluated through the runner (fixed-order products) gives the training-
    time actions (XLA products, in-memory params) on the same observations."""
    config, params = policy
    pol = make_policy(f"mlp:{saved}", push_c)
    loaded, _ = pol.init(None, None)
    runner = EpisodeRunner(push_c, pol, n_envs=3, max_steps=12, record=("obs", "actions"))
    arrays, _ = runner.run(loaded, np.arange(3))
    obs, actions = arrays["obs"].reshape(-1, config.obs_size), arrays["actions"].reshape(-1, 6)
    mean, _ = distribution(config, params, jnp.asarray(obs))
    expected = np.asarray(to_action(config, jnp.asarray(obs), mean))
    # Float32 products summed in another order: agreement to a few ulps of ~1 rad.
    np.testing.assert_allclose(actions, expected, rtol=0, atol=2e-6)
    # The normalisation matters at this tolerance: without it the actions differ.
    raw = {**params, "normalizer": init_stats(config.obs_size)}
    mean_raw, _ = distribution(config, raw, jnp.asarray(obs))
    assert np.abs(np.asarray(to_action(config, jnp.asarray(obs), mean_raw)) - actions).max() > 1e-2


def test_mlp_episode_does_not_depend_on_batch_size(push_c, saved):
    pol = make_policy(f"mlp:{saved}", push_c)
    params, _ = pol.init(None, None)
    record = ("actions",)
    six, _ = EpisodeRunner(push_c, pol, n_envs=6, max_steps=15, record=record).run(
        params, np.arange(6)
    )
    one, _ = EpisodeRunner(push_c, pol, n_envs=1, max_steps=15, record=record).run(
        params, np.array([4])
    )
    for k in one:
        np.testing.assert_array_equal(one[k][0], six[k][4], err_msg=k)


def test_sampling_variant_is_seeded_and_differs_from_mean(push_c, saved):
    sample = make_policy(f"mlp-sample:{saved}", push_c)
    mean = make_policy(f"mlp:{saved}", push_c)
    params, _ = mean.init(None, None)
    obs = push_c.reset(jax.random.PRNGKey(0)).obs
    key = jax.random.PRNGKey(7)
    a1, a2 = (sample.act(params, None, obs, key)[0] for _ in range(2))
    np.testing.assert_array_equal(a1, a2)
    assert not np.allclose(a1, mean.act(params, None, obs, key)[0])


def _corrupt_data(path):
    """Overwrite bytes in the middle of the largest array data file."""
    target = max(
        (p for p in (path / "params").rglob("*") if p.is_file()), key=lambda p: p.stat().st_size
    )
    data = bytearray(target.read_bytes())
    data[len(data) // 2 : len(data) // 2 + 8] = b"\xff" * 8
    target.write_bytes(bytes(data))


@pytest.mark.parametrize(
    "name,damage,needle",
    [
        ("missing", lambda p: shutil.rmtree(p), "does not exist"),
        ("no config", lambda p: (p / CONFIG_FILE).unlink(), "is not an mlp checkpoint"),
        ("bad json", lambda p: (p / CONFIG_FILE).write_text("{"), "is not JSON"),
        ("no params", lambda p: shutil.rmtree(p / "params"), "params"),
        ("corrupt data", _corrupt_data, "is corrupt: 1/"),
        ("deleted file", lambda p: (p / "params" / "manifest.ocdbt").unlink(), "is corrupt"),
    ],
)
def test_damaged_checkpoint_is_config_error(saved, tmp_path, name, damage, needle):
    path = tmp_path / "ckpt"
    shutil.copytree(saved, path)
    damage(path)
    with pytest.raises(ConfigError, match=needle) as exc:
        load_mlp(path)
    assert "\n" not in str(exc.value), name


def test_checkpoint_for_another_scene_is_rejected(push_c, tmp_path):
    config = MlpConfig(
        obs_size=30,
        action_size=6,
        action_offset=(0.0,) * 6,
        action_scale=(1.0,) * 6,
        hidden=(8,),
        metadata={"scene": "so101_box"},
    )
    save_mlp(tmp_path / "other", config, init_params(config, jax.random.PRNGKey(0)))
    with pytest.raises(ConfigError, match=r"observation size 30 .*so101_box.*has 24 and 6"):
        make_policy(f"mlp:{tmp_path / 'other'}", push_c)
    # A config that claims other sizes than its arrays: the stored shapes are checked first.
    data = json.loads((tmp_path / "other" / CONFIG_FILE).read_text())
    data["hidden"] = [16]
    (tmp_path / "other" / CONFIG_FILE).write_text(json.dumps(data))
    with pytest.raises(
        ConfigError, match=r"other arrays than expected .*: \(8,\) stored, \(16,\) expected"
    ):
        load_mlp(tmp_path / "other")


def test_run_directory_hint(saved, tmp_path):
    shutil.copytree(saved, tmp_path / "best")
    with pytest.raises(ConfigError, match=r"did you mean .*best"):
        load_mlp(tmp_path)
