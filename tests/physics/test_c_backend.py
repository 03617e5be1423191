"""The C backend: thread-count invariance, faults in the host callback, pool lifecycle."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from openral_mjx.physics import PhysicsSettings
from openral_mjx.policies import make_policy
from openral_mjx.runner import run_seeds
from openral_mjx.scenes import TabletopPush


def test_same_episodes_whatever_the_thread_count(push_c):
    one_thread = TabletopPush(backend="c", settings=PhysicsSettings(threads=1))
    seeds = np.arange(6)
    runs = [
        run_seeds(s, make_policy("scripted", s), None, seeds=seeds, n_envs=6, max_steps=60)[0]
        for s in (push_c, one_thread)
    ]
    assert "factor/goal_distance" in runs[0]  # factors come along and must agree too
    for k in runs[0]:
        np.testing.assert_array_equal(runs[0][k], runs[1][k], err_msg=k)


def test_callback_exception_is_a_clear_error_not_a_hang(push_c):
    state = jax.vmap(push_c.reset)(jax.vmap(jax.random.PRNGKey)(jnp.arange(2)))
    original = push_c.backend._host_step

    def broken(*args):
        raise RuntimeError("simulated worker failure")

    push_c.backend._host_step = broken
    try:
        with pytest.raises(Exception, match="simulated worker failure"):
            jax.block_until_ready(jax.jit(jax.vmap(push_c.step))(state, jnp.zeros((2, 6))))
    finally:
        push_c.backend._host_step = original
    # The backend still works afterwards.
    out = jax.jit(jax.vmap(push_c.step))(state, jnp.zeros((2, 6)))
    assert bool(out.physics.quantities.ok.all())


def test_pool_can_close_and_reopen():
    scene = TabletopPush(backend="c", settings=PhysicsSettings(threads=1))
    step = jax.jit(scene.step)
    s = scene.reset(jax.random.PRNGKey(0))
    a = step(s, jnp.zeros(6)).obs
    scene.backend.close()
    b = step(s, jnp.zeros(6)).obs
    np.testing.assert_array_equal(a, b)
