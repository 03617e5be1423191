"""The `metaworld_mjx` mirror against MetaWorld itself (run in the `metaworld` worker
environment, on the mirror's random vectors): initial states, open-loop physics, and per-seed
outcomes of MetaWorld's scripted expert, on `c`, for a CPU-sized subset of tasks and seeds
(BENCHMARKS.md has the full table). CI creates the worker environment first; elsewhere these
tests are skipped until `python -m openral_mjx.host.envs create metaworld` has run."""

from __future__ import annotations

import contextlib

import jax
import numpy as np
import pytest
from worker_envs import require_worker_envs

from openral_mjx.benchmarks.metaworld import agreement
from openral_mjx.benchmarks.metaworld.host_scene import TASKS as METAWORLD_TASKS
from openral_mjx.benchmarks.metaworld.mirror.tasks import TASKS
from openral_mjx.core.errors import ConfigError
from openral_mjx.physics import PhysicsSettings
from openral_mjx.scenes import make_scene, scene_suite

ENV = "metaworld"
require_worker_envs(ENV)
pytestmark = pytest.mark.worker

# One task per kind of reset: a free object (push), a fixed body moved per episode with a
# target read from the placed model (button-press-topdown, if ported), the hand alone (reach).
CHECKED = [t for t in ("push-v3", "button-press-topdown-v3", "reach-v3") if t in TASKS]
# Tolerances (metres): MuJoCo 4.0 here, 3.3 in MetaWorld's environment. Resting contacts
# settle up to ~0.6 mm apart (the puck's rest height: 19.97 mm here, 19.44 mm there), and
# 100 random steps from the same joint state stay within a few millimetres.
RESET_TOL = 2e-3
TRAJECTORY_TOL = 1e-2


@pytest.fixture(scope="module", params=CHECKED)
def mirror(request):
    scene = make_scene(
        "metaworld_mjx", {"task": request.param}, backend="c", settings=PhysicsSettings(threads=2)
    )
    with agreement.host_workers(request.param, 2) as workers:
        yield scene, workers
    scene.close()


def test_tasks_are_metaworlds():
    assert set(TASKS) <= set(METAWORLD_TASKS)
    assert scene_suite("metaworld_mjx", "mt10")[:3] == ["reach-v3", "push-v3", "pick-place-v3"]
    with pytest.raises(ConfigError, match="unknown MetaWorld mirror task 'nope'"):
        make_scene("metaworld_mjx", {"task": "nope"}, backend="c")


def test_same_initial_state_and_physics(mirror):
    scene, workers = mirror
    err = agreement.trajectory_agreement(scene, workers, np.arange(3), steps=100)
    assert err["reset"].max() < RESET_TOL, err
    assert err["hand"].max() < TRAJECTORY_TOL, err
    assert err["object"].max() < TRAJECTORY_TOL, err


def test_same_outcomes_under_the_expert(mirror):
    scene, workers = mirror
    out = agreement.outcome_agreement(scene, workers, np.arange(24), n_envs=24)
    assert out["agreement"] >= 0.95, out
    assert out["mcnemar_p"] > 0.01, out


def test_seed_reproduces_its_episode_in_any_batch():
    scene = make_scene("metaworld_mjx", {"task": "push-v3"}, backend="c")
    a = agreement.mirror_resets(scene, np.arange(5))
    b = agreement.mirror_resets(scene, np.array([3]))
    np.testing.assert_array_equal(np.asarray(a.info["vec"][3]), np.asarray(b.info["vec"][0]))
    np.testing.assert_array_equal(np.asarray(a.obs[3]), np.asarray(b.obs[0]))
    vec = np.asarray(a.info["vec"])
    assert np.all(np.linalg.norm(vec[:, :2] - vec[:, 3:5], axis=1) >= 0.15)  # MetaWorld's redraw


def test_box_close_reset_steps_after_moving_the_box():
    """box-close's reset as MetaWorld 3.1.1 writes it, in MuJoCo C: the hand reset (50 x 5
    steps) with the box moved, `frame_skip` more physics steps, then the lid's xyz set and its
    velocity zeroed, its orientation kept. The mirror's reset state matches it."""
    import mujoco

    from openral_mjx.benchmarks.metaworld.mirror import task as mw

    scene = make_scene("metaworld_mjx", {"task": "box-close-v3"}, backend="c")
    assert TASKS["box-close-v3"].settle_steps == 1
    assert all(t.hand_reset_per_episode for t in TASKS.values() if t.settle_steps)
    state = agreement.mirror_resets(scene, np.arange(2))
    m = scene.mj_model
    mocap = m.body_mocapid[m.body("mocap").id]
    box = m.body("boxbody").id
    for i, vec in enumerate(np.asarray(state.info["vec"], np.float64)):
        d = mujoco.MjData(m)
        m.body_pos[box, :2] = vec[3:5]
        for _ in range(mw.HAND_RESET_STEPS + 1):  # the hand reset, then frame_skip steps
            d.mocap_pos[mocap] = TASKS["box-close-v3"].hand_init_pos
            d.mocap_quat[mocap] = mw.MOCAP_QUAT
            d.ctrl[:] = (-1.0, 1.0)
            mujoco.mj_step(m, d, nstep=mw.FRAME_SKIP)
        d.qpos[9:12] = (vec[0], vec[1], np.float32(0.02))
        d.qvel[9:15] = 0.0
        qpos = np.asarray(state.physics.quantities.qpos[i])
        np.testing.assert_allclose(qpos, d.qpos, atol=1e-4)
    scene.close()


def test_window_close_reset_observation_is_metaworlds():
    """MetaWorld reads window-close's reset observation before recomputing positions: it shows
    the handle 0.2 m from where the window starts. The mirror observes the same; the physics
    from the placed state agrees as for any task."""
    scene = make_scene("metaworld_mjx", {"task": "window-close-v3"}, backend="c")
    with agreement.host_workers("window-close-v3", 1) as workers:
        err = agreement.trajectory_agreement(scene, workers, np.arange(2), steps=3)
    scene.close()
    assert err["reset"].max() < RESET_TOL, err
    assert err["object"].max() < TRAJECTORY_TOL, err


# MetaWorld's own code on the mirror's MuJoCo: what remains is float32 rounding of the
# observations and of the actions (the mirror's JAX) in a float64 simulation.
SAME_ENGINE_TOL = 1e-5


@pytest.mark.parametrize("task", ["box-close-v3", "plate-slide-v3"])
def test_mirror_is_metaworld_on_the_same_mujoco(task):
    """With MetaWorld's code put on this process's mujoco (`engine="ours"`), the mirror's task
    logic leaves nothing to the engine version: the same state to rounding over 100 random
    steps, and every expert episode with the same outcome at the same step. box-close: a hand
    reset per episode that meets the moved box, settle steps, a lid carried to the box (its
    outcomes part from MetaWorld on its pinned 3.3 on 5-9% of seeds). plate-slide: a plate
    resting on its channel at distance 0, whose push the float32-rounded channel position
    slowed (the expert succeeded 37 steps later, until per-env model fields kept MuJoCo's
    float64 values)."""
    import mujoco

    with pytest.raises(ConfigError, match="unknown MetaWorld engine 'mj5'; valid: metaworld, ours"):
        agreement.host_workers(task, 1, engine="mj5").__enter__()
    scene = make_scene(
        "metaworld_mjx", {"task": task}, backend="c", settings=PhysicsSettings(threads=2)
    )
    try:
        with agreement.host_workers(task, 2, engine="ours") as workers:
            assert agreement.host_versions(workers)["mujoco"] == mujoco.__version__
            err = agreement.trajectory_agreement(scene, workers, np.arange(2), steps=100)
            out = agreement.outcome_agreement(scene, workers, np.arange(12), n_envs=12)
    finally:
        scene.close()
    for what in ("reset", "hand", "object"):
        assert err[what].max() < SAME_ENGINE_TOL, err
    assert out["agreement"] == 1.0, out
    both = out["mirror"] & out["host"]
    assert both.sum() >= 8, out
    np.testing.assert_array_equal(out["mirror_steps"][both], out["host_steps"][both])


def test_peg_unplug_reset_spin_comes_from_the_episodes_hand_reset():
    """MetaWorld's last hand reset in peg-unplug-side runs with the box already moved and the
    plug inside it; the plug keeps the angular velocity that leaves (0 to 3 rad/s by episode).
    The mirror simulates that hand reset per episode: on the same mujoco, its reset spin is
    MetaWorld's to 1e-5 on all but the seeds where the 250-step tumble is chaotic."""
    scene = make_scene("metaworld_mjx", {"task": "peg-unplug-side-v3"}, backend="c")
    state = agreement.mirror_resets(scene, np.arange(6))
    scene.close()
    mirror = np.asarray(state.physics.quantities.qvel)[:, 12:15]
    theirs = []
    with agreement.host_workers("peg-unplug-side-v3", 1, engine="ours") as (worker,):
        for vec in np.asarray(state.info["vec"], np.float64):
            options = {"options": {"rand_vec": vec}}
            worker.call({"op": "call", "method": "reset", "kwargs": options}, 60)
            theirs.append(worker.call({"op": "call", "method": "state", "kwargs": {}}, 60)["qvel"])
    spin = np.asarray(theirs)[:, 12:15]
    norms = np.linalg.norm(spin, axis=1)
    assert norms.max() > 100 * norms.min(), norms  # it depends on the episode
    assert np.sum(np.abs(spin - mirror).max(axis=1) < SAME_ENGINE_TOL) >= 4, (spin, mirror)


def test_mjx_model_observes_metaworlds_frames():
    """A geom made a prism for mjx is observed in its cylinder's frame. reach-wall's puck is
    flatter than it is wide, so MuJoCo makes the prism's axis its x: with the same tilted puck,
    MuJoCo C's orientation of the prism, turned by the scene's offset, is the cylinder's."""
    import mujoco

    from openral_mjx.benchmarks.metaworld.mirror.assets import load_spec
    from openral_mjx.core.rotations import quat_mul

    scene = make_scene("metaworld_mjx", {"task": "reach-wall-v3"}, backend="mjx")
    assert scene.mjx_changes == {
        "cylinders_as_prisms": 1,
        "margins_zeroed": 4,
        "contacts_per_condim": 64,
    }
    m = scene.mj_model
    original = load_spec(TASKS["reach-wall-v3"].xml).compile()
    quats = []
    for model in (original, m):
        d = mujoco.MjData(model)
        adr = model.jnt_qposadr[model.joint("objjoint").id]
        d.qpos[adr + 3 : adr + 7] = (0.9, 0.3, -0.2, 0.25)  # normalised by kinematics
        mujoco.mj_kinematics(model, d)
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, d.geom_xmat[model.geom("objGeom").id])
        quats.append(quat)
    assert np.abs(np.abs(quats[0] @ quats[1]) - 1) > 0.1  # the prism's own frame is turned
    turned = np.asarray(quat_mul(jax.numpy.asarray(quats[1]), scene._geom_frames[0]))
    np.testing.assert_allclose(np.abs(turned @ quats[0]), 1.0, atol=1e-6)


def test_mjx_copy_caps_contact_slots_and_the_backend_checks_the_cap():
    """box-close's mjx copy keeps 64 contacts per condim of MJX's 780 slots, and the `mjx`
    backend watches each capped group (tests/physics/test_mjx_backend.py: what the check does)."""
    from mujoco.mjx._src import collision_driver

    from openral_mjx.physics.mjx_backend import capped_contact_groups

    scene = make_scene("metaworld_mjx", {"task": "box-close-v3"}, backend="mjx")
    m = scene.mj_model
    groups = capped_contact_groups(m)
    slots = collision_driver.make_condim(m)
    assert len(slots) == 64 * len(np.unique(slots)) == 128, len(slots)
    assert groups == [(0, 64), (64, 64)]  # both condims (3 and 4) truncated, 780 slots before
    assert scene.backend._capped == groups


@pytest.mark.slow  # MJX compiles MetaWorld's mesh collisions for minutes on a CPU
def test_mjx_starts_where_c_does():
    """The same random vectors give the same reset observation on mjx (float32 kinematics;
    MJX collides the puck through a 16-gon prism: resting contacts, hence the tolerance), the
    flat puck's orientation included."""
    c = make_scene("metaworld_mjx", {"task": "reach-wall-v3"}, backend="c")
    m = make_scene("metaworld_mjx", {"task": "reach-wall-v3"}, backend="mjx")
    vecs = np.asarray(agreement.mirror_resets(c, np.arange(3)).info["vec"])
    obs_c = jax.jit(jax.vmap(c.reset_from))(vecs).obs
    obs_m = jax.jit(jax.vmap(m.reset_from))(vecs).obs
    np.testing.assert_allclose(np.asarray(obs_m), np.asarray(obs_c), atol=RESET_TOL)


def test_randomized_mirror_varies_the_object_only():
    """`--randomize` on the mirror: the free object's mass (and MuJoCo C's `dof_M0` for it)
    and its friction with the table per env, noise on the objects' observed poses only, and a
    delayed hand that stands still; the initial state stays MetaWorld's."""
    from openral_mjx.scenes.randomization import INFO_KEY, randomize

    base = make_scene("metaworld_mjx", {"task": "push-v3"}, backend="c")
    scene = randomize(base, ["mass=0.5x:2x", "friction=0.2:1.0", "object_noise=0.01", "delay=2"])
    seeds = jax.numpy.array([1, 2, 3])
    keys = jax.vmap(lambda s: jax.random.split(jax.random.PRNGKey(s), 2)[0])(seeds)
    state = jax.jit(jax.vmap(scene.reset))(keys)
    nominal = jax.jit(jax.vmap(base.reset))(keys)
    np.testing.assert_array_equal(state.physics.quantities.qpos, nominal.physics.quantities.qpos)
    m = base.mj_model
    obj = m.body("obj").id
    values = state.info[INFO_KEY]["values"]
    fields = state.physics.fields
    np.testing.assert_allclose(
        fields["body_mass"][:, obj], m.body_mass[obj] * values["mass"], rtol=1e-6
    )
    dofs = np.flatnonzero(m.dof_bodyid == obj)
    np.testing.assert_allclose(
        fields["dof_M0"][:, dofs[0]], m.dof_M0[dofs[0]] * values["mass"], rtol=1e-6
    )
    noise = np.asarray(state.obs - nominal.obs)
    start, size = base.obs_layout["objects"]
    assert np.abs(noise[:, start : start + 3]).max() > 0
    np.testing.assert_array_equal(np.delete(noise, np.arange(start, start + size), 1), 0.0)
    # Two steps of delay: the hand holds still whatever the policy commands.
    step = jax.jit(jax.vmap(scene.step))
    hand = np.asarray(state.info[INFO_KEY]["obs"][:, :3])
    for _ in range(2):
        state = step(state, jax.numpy.ones((3, 4)))
    np.testing.assert_allclose(state.info[INFO_KEY]["obs"][:, :3], hand, atol=2e-3)


def test_suite_plays_each_tasks_own_expert_alone_or_in_processes(monkeypatch):
    """A suite on the mirror builds MetaWorld's expert for each task (it is bound to one: the
    pick-place expert, not reach's), and `task_processes` runs the same episodes: each task's
    seeds equal a run of that task alone."""
    from openral_mjx.evaluation import RunSpec, build_scene, evaluate
    from openral_mjx.evaluation import suite as suite_module

    tasks = ["reach-v3", "pick-place-v3"]  # reach's expert fails pick-place on these seeds
    monkeypatch.setattr(suite_module, "scene_suite", lambda scene, suite: tasks)
    run = {"n_envs": 2, "n_episodes": 2, "max_steps": 60}

    def outcomes(report):
        return [
            (e["metadata"]["task"], e["success"], e["steps"]) for e in report.to_dict()["episodes"]
        ]

    args = ("metaworld_mjx", "mt10", "metaworld-expert")
    in_turn = suite_module.evaluate_suite(*args, RunSpec(backend="c", threads=2, **run))
    together = suite_module.evaluate_suite(
        *args, RunSpec(backend="c", threads=1, **run), task_processes=2
    )
    scene = build_scene("metaworld_mjx", {"task": "pick-place-v3"}, backend="c", n_envs=2)
    with contextlib.closing(scene):
        alone = evaluate(scene, "metaworld-expert", **run)
    assert outcomes(in_turn) == outcomes(together)
    assert outcomes(in_turn)[2:] == outcomes(alone)
    assert [r.task for r in in_turn.per_task] == tasks
    assert in_turn.per_task[1].successes == alone.successes
