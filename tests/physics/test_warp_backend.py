"""The `warp` backend in MuJoCo-Warp's CPU mode: buffer overflows, freezing, the full runner."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.physics import PhysicsSettings
from openral_mjx.policies import make_policy
from openral_mjx.runner import run_seeds
from openral_mjx.scenes import TabletopPush


def test_contact_overflow_marks_env_diverged():
    """A resting cube makes 4 box-box contacts; a 1-contact buffer cannot hold them, and the
    env must report untrustworthy physics rather than run on with dropped contacts."""
    settings = PhysicsSettings(batch_size=2, contacts_per_env=1)
    tiny = TabletopPush(backend="warp", settings=settings)
    keys = jax.vmap(jax.random.PRNGKey)(jnp.arange(2))
    state = jax.jit(jax.vmap(tiny.reset))(keys)
    assert not state.metrics["diverged"].any()  # no collision pass has run yet
    state = jax.jit(jax.vmap(tiny.step))(state, jnp.zeros((2, tiny.action_size)))
    assert state.metrics["diverged"].all()
    assert not state.metrics["success"].any()
    assert state.physics.quantities.overflowed.all()  # a capacity, not physics gone wrong


def test_an_overflow_is_reported_as_such():
    """Through the evaluator, episodes that overflowed are diverged and say so: per episode
    (``overflowed``), counted in the report, and in its summary with the flag to raise."""
    from openral_mjx.evaluation import evaluate

    kw = {"n_envs": 2, "n_episodes": 2, "max_steps": 2, "backend": "warp", "threads": 1}
    report = evaluate("tabletop_push", "zero", contacts_per_env=1, **kw)
    assert report.diverged == report.overflowed == 2
    assert all(e.metadata["overflowed"] for e in report.episodes)
    assert "2 diverged (2 from full physics buffers: raise --contacts-per-env" in report.summary()
    fine = evaluate("tabletop_push", "zero", **kw)
    assert fine.diverged == fine.overflowed == 0
    assert not any("overflowed" in e.metadata for e in fine.episodes)


def test_batch_larger_than_buffers_is_rejected(push_warp):
    pol = make_policy("zero", push_warp)
    with pytest.raises(ConfigError, match="batch_size=8"):
        run_seeds(push_warp, pol, None, seeds=np.arange(16), n_envs=16, max_steps=2)


def test_diverged_env_is_parked_and_spares_its_neighbours(push_warp):
    """A NaN env stays diverged, is parked at the reference pose (finite again, so it cannot
    flood the batch's shared contact buffer) and leaves the other env's physics untouched."""
    scene, n = push_warp, 2
    state = jax.vmap(scene.reset)(jax.vmap(jax.random.PRNGKey)(jnp.arange(n)))
    q = state.physics.quantities
    bad_qvel = q.qvel.at[0].set(jnp.nan)
    poisoned = state.replace(physics=jax.vmap(scene.backend.init)(q.qpos, bad_qvel))
    healthy = state.replace(physics=jax.vmap(scene.backend.init)(q.qpos, q.qvel))
    step = jax.jit(jax.vmap(scene.step))
    action = jnp.zeros((n, scene.action_size))
    a, b = step(poisoned, action), step(healthy, action)
    assert a.metrics["diverged"].tolist() == [True, False]
    assert not a.physics.quantities.overflowed.any()  # non-finite: no buffer ran out
    assert bool(jnp.isfinite(a.physics.quantities.qpos).all())
    np.testing.assert_array_equal(a.physics.quantities.qpos[1], b.physics.quantities.qpos[1])


def test_convex_contact_capacity_is_part_of_the_contact_capacity():
    """`ccd_contacts_per_env` bounds the GJK/EPA share of the contact buffer, so it can be
    neither above `contacts_per_env` nor below 1."""
    assert PhysicsSettings(contacts_per_env=8, ccd_contacts_per_env=8).ccd_contacts_per_env == 8
    with pytest.raises(ConfigError, match=r"<= contacts_per_env \(8\), got 9"):
        PhysicsSettings(contacts_per_env=8, ccd_contacts_per_env=9)
    with pytest.raises(ConfigError, match="ccd_contacts_per_env must be >= 1, got 0"):
        PhysicsSettings(ccd_contacts_per_env=0)


def test_a_finished_run_frees_warps_captured_graphs(push_warp, monkeypatch):
    """Warp keeps a CUDA graph, with its device temporaries, per buffer set each callable
    meets; a closed evaluation drops them so the next run in the process has the memory
    (here on the CPU, where Warp captures none, a stand-in entry in each callable's cache)."""
    from warp._src.jax import ffi

    from openral_mjx.evaluation import run as run_module
    from openral_mjx.physics import release_warp_graphs

    state = jax.jit(jax.vmap(push_warp.reset))(jax.vmap(jax.random.PRNGKey)(jnp.arange(2)))
    jax.jit(jax.vmap(push_warp.step))(state, jnp.zeros((2, push_warp.action_size)))
    callables = list(ffi._FFI_CALLABLE_REGISTRY.values())
    assert callables  # the step went through Warp's JAX callables
    for c in callables:
        c.captures["stand-in"] = object()
    release_warp_graphs()
    assert all(not c.captures for c in callables)

    released = []
    monkeypatch.setattr(run_module, "release_warp_graphs", lambda: released.append(1))
    ev = run_module.run_evaluation(
        "tabletop_push", "zero", n_envs=2, n_episodes=2, max_steps=2, backend="c", threads=1
    )
    with ev:
        assert not released  # the run's programs may still be used (videos) until closed
    assert released == [1]


def test_warp_graphs_reach_the_model_and_bad_ones_are_refused():
    """`PhysicsSettings.warp_graphs` picks Warp's graph mode of the model MJX puts (the CLI's
    `--warp-graphs`), unset keeps MJX's own choice, and a name outside `WARP_GRAPHS` is a
    one-line ConfigError naming the valid ones, in the settings and in a run spec."""
    import warp

    from openral_mjx.evaluation.spec import RunSpec

    staged = TabletopPush(
        backend="warp", settings=PhysicsSettings(batch_size=1, warp_graphs="staged")
    )
    assert staged.backend.mx.opt._impl.graph_mode == warp.JaxCallableGraphMode.WARP_STAGED
    assert staged.backend.describe()["warp_graphs"] == "staged"  # the report says which ran
    default = TabletopPush(backend="warp", settings=PhysicsSettings(batch_size=1))
    assert default.backend.mx.opt._impl.graph_mode == warp.JaxCallableGraphMode.JAX  # CPU's
    assert "warp_graphs" not in default.backend.describe()
    for make in (lambda: PhysicsSettings(warp_graphs="cuda"), lambda: RunSpec(warp_graphs="cuda")):
        with pytest.raises(
            ConfigError, match="unknown warp_graphs 'cuda'; valid: warp, staged, none"
        ):
            make()
    with pytest.raises(ConfigError, match="ccd_contacts_per_env must be at most 65,536"):
        RunSpec(ccd_contacts_per_env=10**6)
