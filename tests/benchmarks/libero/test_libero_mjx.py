"""`libero_mjx` against LIBERO itself (robosuite 1.4 on mujoco 3.8.1, in the `lerobot-libero`
worker environment) and its robot dynamics against MuJoCo C.

Tolerances: the mirror runs mujoco 4.0.0 and reads float32 quantities, LIBERO mujoco 3.8.1
in float64. With the arm in free space the two trajectories agree to a few 1e-7 over 20
random actions, objects and drawers included (measured); 1e-5 leaves room for float32
rounding growing over the steps, and is far below what the faults these tests caught made:
0.5 mm for one physics step of staleness in the observation, 3 cm of drawer for fixtures
left where the MJCF puts them rather than where LIBERO's reset does.
"""

from __future__ import annotations

import copy

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from worker_envs import require_worker_envs

from openral_mjx.benchmarks.libero import assets
from openral_mjx.benchmarks.libero.agreement import libero_reference
from openral_mjx.benchmarks.libero.assets import ENV, load_sampled, load_task, physics_spec
from openral_mjx.benchmarks.libero.mirror import LiberoMjx, LiberoMjxOptions
from openral_mjx.benchmarks.libero.mirror.controller import RobotDynamics
from openral_mjx.physics.base import reference_qpos

require_worker_envs(ENV)
pytestmark = pytest.mark.worker

TASK = "libero_goal/0"  # the open-drawer task: a joint predicate, the arm in free space


@pytest.fixture(scope="module")
def scene() -> LiberoMjx:
    return LiberoMjx(LiberoMjxOptions(task=TASK), backend="c")


def test_robot_dynamics_match_mujoco_c() -> None:
    """End-effector pose, Jacobian, the arm's mass matrix and bias forces, as robosuite reads
    them from MuJoCo, from the robot-only model in float32."""
    export = load_task(TASK)
    spec = physics_spec(export)
    m = spec.compile()
    dyn = RobotDynamics(spec, m, export.meta["arm_joints"], export.meta["eef_site"])
    robot_q = [m.joint(n).qposadr[0] for n in dyn.qpos_names]
    robot_v = [m.joint(n).dofadr[0] for n in dyn.qpos_names]
    arm = [m.joint(n).dofadr[0] for n in export.meta["arm_joints"]]
    site = m.site(export.meta["eef_site"]).id
    call = jax.jit(dyn)
    rng = np.random.default_rng(0)
    d = mujoco.MjData(m)
    for init in (0, 17, 33):
        state = export.init_states[init]
        d.qpos[:], d.qvel[:] = state[1 : 1 + m.nq], state[1 + m.nq :]
        d.qpos[robot_q] += rng.normal(0.0, 0.2, len(robot_q)) * (np.arange(len(robot_q)) < 7)
        d.qvel[robot_v] = rng.normal(0.0, 0.5, len(robot_v))
        mujoco.mj_forward(m, d)
        jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        mujoco.mj_jacSite(m, d, jacp, jacr, site)
        mass = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, mass)
        got = call(jnp.asarray(d.qpos[robot_q]), jnp.asarray(d.qvel[robot_v]))
        np.testing.assert_allclose(got.ee_pos, d.site_xpos[site], atol=1e-6)
        np.testing.assert_allclose(got.ee_mat.ravel(), d.site_xmat[site], atol=1e-6)
        np.testing.assert_allclose(got.jac, np.vstack([jacp, jacr])[:, arm], atol=1e-5)
        np.testing.assert_allclose(got.mass, mass[np.ix_(arm, arm)], atol=1e-5, rtol=1e-5)
        np.testing.assert_allclose(got.bias, d.qfrc_bias[arm], atol=1e-4, rtol=1e-5)


def test_same_initial_state_and_actions_give_libero_s_observations(
    scene: LiberoMjx, libero
) -> None:
    """Seed s's reset (initial state s mod 50 and the settle) and then the same random
    actions: lerobot's state, the expert's entry and every joint (robot, objects, drawers)
    as LIBERO gives them, step by step."""
    actions = np.random.default_rng(1).uniform(-1.0, 1.0, (20, 7)).astype(np.float32)
    reset, step = jax.jit(scene.reset_with_seed), jax.jit(scene.step)
    for seed in (0, 57):  # 57: initial state 7
        ref = libero.rollout(seed % 50, actions)
        state = reset(jnp.int32(seed), jax.random.PRNGKey(seed))
        states, qpos = [np.asarray(state.obs)], [np.asarray(state.physics.quantities.qpos)]
        for a in actions:
            state = step(state, jnp.asarray(a))
            states.append(np.asarray(state.obs))
            qpos.append(np.asarray(state.physics.quantities.qpos))
        states = np.stack(states)
        np.testing.assert_allclose(states[:, :8], ref["state"], atol=1e-5)
        np.testing.assert_allclose(states[:, 8:], ref["expert"], atol=1e-5)
        np.testing.assert_allclose(np.stack(qpos), ref["qpos"], atol=1e-5)
        assert not np.asarray(state.metrics["diverged"])


def test_a_control_step_lasts_robosuite_s_control_period(scene: LiberoMjx) -> None:
    """20 Hz, as on the host scene: the period reports, latency budgets and videos use (the
    mirror said 2 ms, one physics step, until 2026-12-02)."""
    from openral_mjx.benchmarks.robosuite.host_scene import CONTROL_DT

    assert scene.control_dt == pytest.approx(CONTROL_DT)


def test_reference_pose_is_a_resting_state(scene: LiberoMjx) -> None:
    """Backends park a diverged env at the model's reference pose (and warp warms up from it).
    LIBERO's MJCF starts every object at the origin, a pile of hundreds of contacts (more than
    a warp env's contact capacity), so the mirror names its first initial state instead."""
    m = scene.mj_model
    np.testing.assert_array_equal(
        reference_qpos(m), scene.export.init_states[0][1 : 1 + m.nq].astype(np.float64)
    )
    d = mujoco.MjData(m)

    def contacts(qpos: np.ndarray) -> int:
        d.qpos[:] = qpos
        mujoco.mj_forward(m, d)
        return d.ncon

    resting, piled = contacts(reference_qpos(m)), contacts(m.qpos0)  # measured: 0 and 143
    assert resting < piled and resting <= 100, (resting, piled)


def test_seed_gives_the_same_bits_alone_and_in_a_batch(scene: LiberoMjx) -> None:
    """Seed 3 alone and first of [3, 7], reset and 12 random actions: every array of the state
    bit for bit. XLA's default CPU code (FMA contraction in some vector lanes only) made this
    seed differ by 1.2e-7 here; the package's CPU codegen pin (`core.cpu_codegen`) removes it."""
    actions = np.random.default_rng(0).uniform(-1.0, 1.0, (12, 7)).astype(np.float32)
    reset, step = jax.jit(jax.vmap(scene.reset_with_seed)), jax.jit(jax.vmap(scene.step))

    def run(seeds: list[int]):
        s = jnp.asarray(seeds, jnp.int32)
        state = reset(s, jax.vmap(jax.random.PRNGKey)(s))
        for a in actions:
            state = step(state, jnp.broadcast_to(a, (len(seeds), 7)))
        return jax.tree.map(np.asarray, state)

    alone, batched = run([3]), run([3, 7])
    for a, b in zip(jax.tree.leaves(alone), jax.tree.leaves(batched), strict=True):
        np.testing.assert_array_equal(a[0], b[0])


def test_recorded_controls_replay_the_episode_in_mujoco_c(scene: LiberoMjx) -> None:
    """`reset_controls` and `step_controls` (what a benchmark replays as raw physics) leave
    the episode as `reset_from` and `step` do, and their controls, applied one physics step
    at a time by MuJoCo C from `initial_physics`' state and fixtures, give its joint
    positions: the same trajectory (to 1.2e-7 over 325 physics steps, measured; a trajectory
    that parts from it moves objects by millimetres)."""
    init, actions = 5, np.random.default_rng(1).uniform(-1.0, 1.0, (3, 7)).astype(np.float32)
    state, settle = jax.jit(scene.reset_controls)(jnp.int32(init))
    plain = jax.jit(scene.reset_from)(jnp.int32(init))
    step, step_controls = jax.jit(scene.step), jax.jit(scene.step_controls)
    controls = [settle]
    for a in actions:
        plain = step(plain, a)
        state, u = step_controls(state, a)
        controls.append(u[None])
    for a, b in zip(jax.tree.leaves(state), jax.tree.leaves(plain), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    u = np.concatenate(controls)
    assert u.shape == (scene.export.meta["settle_steps"] + 3, scene.n_substeps, scene.mj_model.nu)
    m = copy.deepcopy(scene.mj_model)
    for k, v in scene.model_fields(jnp.int32(init)).items():
        getattr(m, k)[:] = np.asarray(v)
    d = mujoco.MjData(m)
    start = scene.initial_physics(jnp.int32(init)).quantities
    d.qpos[:], d.qvel[:] = np.asarray(start.qpos), np.asarray(start.qvel)
    mujoco.mj_forward(m, d)
    for ctrl in u.reshape(-1, m.nu):
        d.ctrl[:] = ctrl
        mujoco.mj_step(m, d)
    np.testing.assert_allclose(
        d.qpos.astype(np.float32), np.asarray(state.physics.quantities.qpos), rtol=0, atol=1e-6
    )


@pytest.fixture(scope="module")
def libero():
    with libero_reference(TASK) as reference:
        yield reference


def test_fixtures_sit_where_libero_s_reset_puts_them(scene: LiberoMjx, libero) -> None:
    """LIBERO's reset draws its fixtures' poses (this task's cabinet, stove and wine rack)
    from numpy's RNG, seeded with the initial state's index: the mirror's reset to the same
    state puts every body where LIBERO's full reset does."""
    names = [str(n) for n in scene.export.meta["body_names"]]
    ids = np.array([scene.mj_model.body(n).id for n in names])
    reset = jax.jit(scene.reset_from)
    refs = {}
    for init in (1, 17, 42):
        refs[init] = ref = libero.body_poses(init)
        fields = reset(jnp.int32(init)).physics.fields
        for name in ("body_pos", "body_quat"):
            np.testing.assert_allclose(np.asarray(fields[name])[ids], ref[name], atol=1e-6)
    # the fixtures do move between initial states (by ~1 cm), so one pose for all would fail
    assert np.abs(refs[1]["body_pos"] - refs[17]["body_pos"]).max() > 1e-3


def test_sampled_protocol_starts_from_libero_s_own_draw(scene: LiberoMjx, libero) -> None:
    """The mass-seed protocol (``protocol=sampled``): seed s is LIBERO's own reset draw with
    numpy seeded by s (objects in their BDDL regions, the fixtures, the drawers' joints). The
    mirror reads the draw the export kept (`load_sampled`); LIBERO's full reset draws it live:
    the same state, bit for bit, and every body where LIBERO puts it. Draws 1 and 2 (the
    mirror's seeds 4 and 2: with 3 states, seed s is draw s mod 3) start apart, and apart
    from the standard protocol's state 1."""
    options = LiberoMjxOptions(task=TASK, protocol="sampled", sampled_states=3)
    sampled = LiberoMjx(options, backend="c")
    assert sampled.n_init_states == 3
    kept = load_sampled(TASK, 3)["states"]
    names = [str(n) for n in scene.export.meta["body_names"]]
    ids = np.array([scene.mj_model.body(n).id for n in names])
    reset = jax.jit(sampled.reset_from)
    nq = sampled.mj_model.nq
    for seed, mirror_seed in ((1, 4), (2, 2)):
        live = libero.drawn_state(seed)
        np.testing.assert_array_equal(kept[seed], live["state"])
        init = mirror_seed % sampled.n_init_states
        np.testing.assert_allclose(sampled._init_qpos[init], live["state"][1 : 1 + nq], atol=1e-7)
        fields = reset(jnp.int32(init)).physics.fields
        for name in ("body_pos", "body_quat"):
            got = np.asarray(fields.get(name, getattr(sampled.mj_model, name)))
            np.testing.assert_allclose(got[ids], live[name], atol=1e-6)
    standard = scene.export.init_states[1][1 : 1 + nq]
    assert np.abs(kept[1][1 : 1 + nq] - kept[2][1 : 1 + nq]).max() > 1e-3
    assert np.abs(kept[1][1 : 1 + nq] - standard).max() > 1e-3


def test_an_object_on_a_fixture_is_drawn_where_libero_puts_it(monkeypatch) -> None:
    """``libero_spatial/3`` sets its second bowl on the cabinet, a fixture LIBERO's reset
    places too. The kept draws (each LIBERO's full reset, blocks drawn by one worker per core
    and kept in seed order) are LIBERO's live draws, bit for bit, in the first block and in
    later ones. Re-running the placement on the live simulation, as the export once did, put
    that bowl 0.9 m higher, where it fell onto the scene after the settle."""
    task = "libero_spatial/3"
    monkeypatch.setattr(assets, "SAMPLED_BLOCK", 2)  # where the cache holds fewer draws
    kept = load_sampled(task, 5)["states"]
    with libero_reference(task) as libero:
        for seed in (0, 3, 4):
            np.testing.assert_array_equal(kept[seed], libero.drawn_state(seed)["state"])


def goal_states(scene: LiberoMjx, n: int, seed: int) -> np.ndarray:
    """States around the goal: initial state 0 with each atom's joints near their thresholds,
    then each atom's object moved near its target (into, onto and through it), wherever
    those joints put the target."""
    m, goal = scene.mj_model, scene.goal
    base = np.asarray(scene.export.init_states[0], np.float64)
    rng = np.random.default_rng(seed)
    states = np.repeat(base[None], n, axis=0)
    for atom in goal.atoms:
        for joint, threshold in zip(atom.get("joints", ()), atom.get("threshold", ()), strict=True):
            j = m.joint(joint)
            low, high = m.jnt_range[j.id]
            states[:, 1 + j.qposadr[0]] = np.clip(
                threshold + rng.uniform(-0.05, 0.05, n), low, high
            )
    init = jax.jit(jax.vmap(scene.backend.init))
    q = init(jnp.asarray(states[:, 1 : 1 + m.nq]), jnp.asarray(states[:, 1 + m.nq :]))
    q = q.quantities
    for atom in goal.atoms:
        if "obj" not in atom:
            continue
        if "site_body" in atom:
            centre = jax.vmap(lambda q, atom=atom: goal._site(q, 1, atom)[0])(q)
        else:
            centre = q.body_pos[:, 1 + goal.bodies.index(atom["target"])]
        body = m.body(atom["obj"]).id
        while m.body_jntnum[body] == 0:  # the object's free joint may sit above its body
            body = m.body_parentid[body]
        adr = 1 + m.jnt_qposadr[m.body_jntadr[body]]
        # where the object's body is, from where its free joint puts it
        offset = np.asarray(q.body_pos[:, 1 + goal.bodies.index(atom["obj"])], np.float64)
        offset = offset - states[:, adr : adr + 3]
        spread = rng.uniform([-0.05, -0.05, -0.03], [0.05, 0.05, 0.08], (n, 3))
        states[:, adr : adr + 3] = np.asarray(centre, np.float64) + spread - offset
    return states


def check_goal(scene: LiberoMjx, libero, seed: int = 2) -> None:
    states = goal_states(scene, 96, seed)
    m = scene.mj_model
    expected = libero.check_success(states)
    physics = jax.jit(jax.vmap(scene.backend.init))(
        jnp.asarray(states[:, 1 : 1 + m.nq]), jnp.asarray(states[:, 1 + m.nq :])
    )
    got = np.asarray(jax.vmap(lambda q: scene.goal(q, body_offset=1))(physics.quantities))
    assert 0 < expected.sum() < len(expected), "the states must hold both outcomes"
    np.testing.assert_array_equal(got, expected)


def test_goal_agrees_with_libero_s_predicates(scene: LiberoMjx, libero) -> None:
    """LIBERO's own `_check_success` and the mirror's goal on the same states (see
    `goal_states`): Open(drawer), a joint threshold."""
    check_goal(scene, libero)


@pytest.mark.slow
@pytest.mark.parametrize(
    "task",
    [
        "libero_spatial/0",  # On(bowl, plate): heights, contact, 3 cm
        "libero_object/0",  # In(can, basket region)
        "libero_goal/1",  # On(bowl, stove region): its under test and contact
        "libero_10/3",  # Close(drawer) and In(bowl, drawer region)
    ],
)
def test_goal_agrees_with_libero_s_predicates_on_every_kind(task: str) -> None:
    """As above, on a task of each other predicate."""
    with libero_reference(task) as reference:
        check_goal(LiberoMjx(LiberoMjxOptions(task=task), backend="c"), reference)
