"""Every registered scene on every backend it runs on: built, reset and stepped under `jit` and
`vmap` at a tiny batch, its observation the shape the scene declares and finite throughout.

A scene is smoke-tested here the day it is registered. Tiers (see README, Tests): MuJoCo
scenes on `c` run in the default tier; `mjx` and `warp` (a compile of minutes on a CPU) in
`heavy`; scenes that need a worker environment in `worker`; the cases that cost a minute or
more and are covered elsewhere (SLOW_CASES) in `slow`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from worker_envs import require_worker_envs
from xla_level import for_backend

from openral_mjx.physics import BACKEND_NAMES
from openral_mjx.scenes import SCENES, make_scene, scene_settings

N_ENVS = 2
STEPS = 3
# Smallest settings that still build the scene as users get it: one worker process for host
# scenes (both envs in it), two C threads, a warp buffer sized for this batch.
HOST_OPTIONS = {"n_workers": 1}
# (with the scene's own contact capacity, as `eval` builds it).
SETTINGS = {"c": {"threads": 2}, "warp": {"batch_size": 8}}
# Cases in `slow` (run by hand or on a GPU machine): MJX compiles the MetaWorld mirror's mesh
# collisions for ~2.5 minutes on 2 cores, the largest single test of CI's heavy tier. Its MJX
# model is still built and checked in the heavy tier (tests/benchmarks/metaworld), and
# `gpu_runs.sh mw-mjx-check` steps all 50 tasks on MJX on a GPU. LIBERO's host scene starts
# its robosuite workers for ~45 s; the worker tier builds and steps it twice already
# (tests/host/test_worker_env_scenes.py: the acceptance command, and its batch against the env
# stepped directly).
SLOW_CASES = {("metaworld_mjx", "mjx"), ("libero", "host")}


def _cases() -> list:
    cases = []
    for name in SCENES.names():
        entry = SCENES.get(name)
        backends = entry.backends or tuple(b for b in BACKEND_NAMES if b != "auto")
        for backend in backends:
            marks = []
            if entry.worker_env is not None:
                marks.append(pytest.mark.worker)
            if backend in ("mjx", "warp"):
                marks.append(pytest.mark.heavy)
            if (name, backend) in SLOW_CASES:
                marks.append(pytest.mark.slow)
            cases.append(pytest.param(name, backend, marks=marks, id=f"{name}-{backend}"))
    return cases


@pytest.mark.parametrize(("name", "backend"), _cases())
def test_scene_resets_and_steps(name, backend):
    entry = SCENES.get(name)
    if entry.worker_env is not None:
        require_worker_envs(entry.worker_env, module=False)
    if backend == "warp":
        pytest.importorskip("warp")
    overrides = HOST_OPTIONS if backend == "host" else {}
    settings = scene_settings(name, **SETTINGS.get(backend, {}))
    scene = make_scene(name, overrides, backend=backend, settings=settings)
    try:
        scene.prepare(N_ENVS)
        seeds = jnp.arange(N_ENVS, dtype=jnp.int32)
        keys = jax.vmap(jax.random.PRNGKey)(seeds)
        options = for_backend(backend)  # MJX's physics compiled optimised (xla_level)
        state = jax.jit(jax.vmap(scene.reset_with_seed), compiler_options=options)(seeds, keys)
        low, high = scene.action_bounds()
        assert low.shape == high.shape == (scene.action_size,)
        action = jnp.broadcast_to((low + high) / 2, (N_ENVS, scene.action_size))
        step = jax.jit(jax.vmap(scene.step), compiler_options=options)
        spec = scene.observation_spec
        states = [state]
        for _ in range(STEPS):
            states.append(step(states[-1], action))
        for t, s in enumerate(states):
            shapes = jax.tree.map(lambda a: a.shape, s.obs)
            assert shapes == jax.tree.map(lambda d: (N_ENVS, *d.shape), spec), (t, shapes)
            for leaf in jax.tree.leaves(s.obs):
                assert np.isfinite(np.asarray(leaf, np.float64)).all(), f"step {t}: non-finite"
            assert np.isfinite(np.asarray(s.reward)).all(), f"step {t}: non-finite reward"
            assert not np.asarray(s.metrics["diverged"]).any(), f"step {t}: diverged"
        if isinstance(spec, jax.ShapeDtypeStruct):  # a flat vector: its declared layout
            assert spec.shape == (scene.observation_size,)
            assert sum(size for _, size in scene.obs_layout.values()) == scene.observation_size
    finally:
        scene.close()


def test_lazy_entries_resolve_on_first_get():
    """A benchmark folder's scene is registered by reference ("module:attribute"): listed at
    once, imported on its first `get`, and a second registration of its name is refused."""
    from openral_mjx.core.errors import ConfigError
    from openral_mjx.core.registry import Registry

    reg: Registry[object] = Registry("thing")
    reg.register_lazy("sqrt", "math:sqrt")
    assert reg.names() == ["sqrt"] and "sqrt" in reg
    assert reg.get("sqrt")(4.0) == 2.0
    with pytest.raises(KeyError, match="registered twice"):
        reg.register("sqrt")(abs)
    with pytest.raises(ValueError, match="not 'module:attribute'"):
        reg.register_lazy("cos", "math.cos")
    with pytest.raises(ConfigError, match="unknown thing 'nope'"):
        reg.get("nope")
    assert SCENES.get("metaworld_mjx").worker_env == "metaworld"  # a lazy entry, resolved


def test_registered_suites_are_the_scenes_suites():
    """Each entry's `suite_names` (what --list and --help show) are suites its `suites` takes,
    every one non-empty; an entry with suites but no names, or names but no suites, is refused."""
    from openral_mjx.scenes import SceneEntry, scene_suite

    for name in SCENES.names():
        for suite in SCENES.get(name).suite_names:
            assert scene_suite(name, suite), (name, suite)
    with pytest.raises(ValueError, match="suite_names"):
        SceneEntry(object, make_scene, suites=lambda s: [s])
    with pytest.raises(ValueError, match="suite_names"):
        SceneEntry(object, make_scene, suite_names=("all",))


def test_several_suites_run_as_one_in_the_order_named():
    """`--suite a,b` (lerobot's LIBERO convention) is the tasks of a, then of b; a suite named
    twice, suites sharing tasks, an empty name or an unknown suite among them is one error."""
    from openral_mjx.core.errors import ConfigError
    from openral_mjx.scenes import scene_suite

    four = "libero_spatial, libero_object,libero_goal,libero_10"
    tasks = scene_suite("libero_mjx", four)
    assert len(tasks) == 40 and tasks[0] == "libero_spatial/0" and tasks[-1] == "libero_10/9"
    assert tasks[10:20] == scene_suite("libero_mjx", "libero_object")
    with pytest.raises(ConfigError, match="suite 'libero_10' is named twice"):
        scene_suite("libero", "libero_10,libero_goal,libero_10")
    with pytest.raises(ConfigError, match="suites in 'mt10,mt50' share tasks"):
        scene_suite("metaworld_mjx", "mt10,mt50")
    with pytest.raises(ConfigError, match="has an empty suite name"):
        scene_suite("libero", "libero_10,")
    with pytest.raises(ConfigError, match=r"unknown LIBERO suite 'libero_100'.*libero_10"):
        scene_suite("libero", "libero_10,libero_100")


def test_a_pool_starts_the_longest_episodes_first():
    """Four LIBERO suites in one pool of task processes, in the order named, left
    `libero_10`'s 520-step episodes for last while most processes idled. `longest_first`
    orders them by each task's episode limit (lerobot's per suite), the named order among
    equals; a cap on every episode (`--max-steps`) or a scene whose tasks do not say keeps
    the named order. The episode limits are the ones the scenes run."""
    from openral_mjx.benchmarks.libero.mirror.options import LiberoMjxOptions
    from openral_mjx.scenes import longest_first, scene_suite

    tasks = scene_suite("libero_mjx", "libero_spatial,libero_goal,libero_10")
    order = [tasks[i] for i in longest_first("libero_mjx", tasks)]
    assert order == tasks[20:] + tasks[10:20] + tasks[:10]
    assert [LiberoMjxOptions(task=t).episode_limit for t in order] == [520] * 10 + [300] * 10 + [
        280
    ] * 10
    assert longest_first("libero_mjx", tasks, max_steps=280) == list(range(30))
    assert longest_first("libero_mjx", tasks, max_steps=290) == [*range(10, 30), *range(10)]
    mt = scene_suite("metaworld_mjx", "mt10")
    assert longest_first("metaworld_mjx", mt) == list(range(len(mt)))
