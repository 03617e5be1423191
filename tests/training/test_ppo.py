"""PPO's pieces against references: GAE (brax's `compute_gae` behind our adapter) against the
textbook recursion and against brax called directly, the Gaussian log density (brax's) against
scipy, the training envs' time limit and auto-reset, config validation."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from brax.training.agents.ppo.losses import compute_gae
from scipy.stats import norm

from openral_mjx.core.errors import ConfigError
from openral_mjx.training.env import BatchedEnv, EnvState
from openral_mjx.training.ppo import PPOConfig, gae, gaussian_logp


def _gae_reference(reward, value, next_value, terminal, done, gamma, lam):
    """Per env, backwards: delta_t = r_t + gamma V(s'_t) [not terminal] - V(s_t);
    A_t = delta_t + gamma lam A_{t+1} [episode continues]."""
    T, n = reward.shape
    adv = np.zeros((T, n))
    for i in range(n):
        running = 0.0
        for t in reversed(range(T)):
            bootstrap = 0.0 if terminal[t, i] else gamma * next_value[t, i]
            delta = reward[t, i] + bootstrap - value[t, i]
            running = delta + (0.0 if done[t, i] else gamma * lam * running)
            adv[t, i] = running
    return adv


def test_gae_matches_reference():
    rng = np.random.default_rng(0)
    T, n = 9, 5
    reward, value, next_value = (rng.normal(size=(T, n)) for _ in range(3))
    terminal = rng.random((T, n)) < 0.15
    done = terminal | (rng.random((T, n)) < 0.15)  # time limits end episodes too
    got = gae(
        *(jnp.asarray(x, jnp.float32) for x in (reward, value, next_value)),
        jnp.asarray(terminal, jnp.float32),
        jnp.asarray(done, jnp.float32),
        0.97,
        0.9,
    )
    ref = _gae_reference(reward, value, next_value, terminal, done, 0.97, 0.9)
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-5)


def test_gae_without_episode_ends_is_brax_unchanged():
    """Where no episode ends, our bootstrap (`next_value[t]`) is brax's (`value[t+1]`), so the
    adapter must return brax's own estimates: `vs - value` of `compute_gae`."""
    rng = np.random.default_rng(2)
    T, n = 7, 4
    reward, value = (jnp.asarray(rng.normal(size=(T, n)), jnp.float32) for _ in range(2))
    bootstrap = jnp.asarray(rng.normal(size=n), jnp.float32)
    next_value = jnp.concatenate([value[1:], bootstrap[None]])
    zeros = jnp.zeros((T, n), jnp.float32)
    got = gae(reward, value, next_value, zeros, zeros, 0.99, 0.95)
    vs, _ = compute_gae(zeros, zeros, reward, value, bootstrap, lambda_=0.95, discount=0.99)
    np.testing.assert_allclose(got, vs - value, rtol=1e-5, atol=1e-5)
    assert np.abs(np.asarray(got)).max() > 0.1  # not trivially zero


def test_gaussian_logp_matches_scipy():
    rng = np.random.default_rng(1)
    u, mean = rng.normal(size=(4, 3)), rng.normal(size=(4, 3))
    log_std = rng.normal(size=3) * 0.5
    ref = norm.logpdf(u, loc=mean, scale=np.exp(log_std)).sum(axis=-1)
    got = gaussian_logp(*(jnp.asarray(x, jnp.float32) for x in (u, mean, log_std)))
    np.testing.assert_allclose(got, ref, rtol=1e-5)


@pytest.mark.parametrize("backend", ["c", "warp"])
def test_time_limit_and_auto_reset(request, backend):
    """Envs end at the time limit (or on success), report the observation they ended on, and
    continue from the fresh states; their counters and returns restart. On warp, whose batch
    shares one contact buffer, the reset env then steps exactly as its fresh state does."""
    scene = request.getfixturevalue(f"push_{backend}")
    env = BatchedEnv(scene, n_envs=3, max_steps=2)
    start = env.reset_states(jax.random.PRNGKey(0))
    fresh = env.reset_states(jax.random.PRNGKey(1))
    state = EnvState(scene=start, t=jnp.array([0, 1, 0]), episode_return=jnp.zeros(3))
    step = jax.jit(env.step)
    action = start.obs[:, np.array(scene.action_obs_index())]  # hold the joints
    after, res = step(state, action, fresh)
    moved = jax.vmap(scene.step)(start, action)
    np.testing.assert_array_equal(res.done, [False, True, False])
    np.testing.assert_array_equal(res.terminal, [False, False, False])
    np.testing.assert_array_equal(res.next_obs, moved.obs)
    np.testing.assert_array_equal(after.t, [1, 0, 1])
    np.testing.assert_array_equal(after.scene.obs[1], fresh.obs[1])
    np.testing.assert_array_equal(after.scene.obs[np.array([0, 2])], moved.obs[np.array([0, 2])])
    np.testing.assert_allclose(res.episode_return, [0.0, moved.reward[1], 0.0])
    np.testing.assert_allclose(after.episode_return, [moved.reward[0], 0.0, moved.reward[2]])
    # Second step: envs 0 and 2 reach the limit; env 1 steps on from its fresh state.
    _, res2 = step(after, action, fresh)
    np.testing.assert_array_equal(res2.done, [True, False, True])
    from_fresh = jax.vmap(scene.step)(fresh, action)
    np.testing.assert_array_equal(res2.next_obs[1], from_fresh.obs[1])


def test_reset_spreads_episode_counters(push_c):
    env = BatchedEnv(push_c, n_envs=64, max_steps=200)
    t = np.asarray(jax.jit(env.reset)(jax.random.PRNGKey(0)).t)
    assert t.min() >= 0 and t.max() < 200 and len(np.unique(t)) > 30


@pytest.mark.parametrize(
    "kw,needle",
    [
        (dict(n_envs=6, unroll_length=5, n_minibatches=4), "does not split into 4"),
        (dict(n_envs=0), "n_envs must be a positive integer"),
        (dict(gamma=1.5), "gamma must lie in"),
        (dict(actor_lr=0.0), "actor_lr must be > 0"),
        (dict(success_bonus=-1.0), "success_bonus must be >= 0"),
    ],
)
def test_config_validation(kw, needle):
    with pytest.raises(ConfigError, match=needle):
        PPOConfig(**kw)
