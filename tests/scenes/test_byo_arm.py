"""Bring your own arm: published-style MJCF arms run `tabletop_push` as they are.

The arms under tests/data/arms/ are written here in the style of published models (mesh
visuals, capsule/cylinder collision geoms, `general` servos with gainprm/biasprm, a `home`
keyframe, a 3-4 cm flange): a small 6-DOF (~0.5 m reach), an industrial 6-DOF (~0.9 m,
stretched out at qpos0, implicitfast, kv/kp = 0.2 s) and a 7-DOF with a tendon-driven hand.
Only the end-effector site is named. Every bad input is a one-line `ConfigError`.
"""

from __future__ import annotations

import re
import shutil
import sys
from pathlib import Path

import jax
import mujoco
import numpy as np
import pytest

from openral_mjx import eval as eval_cli
from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation import run_evaluation
from openral_mjx.physics import PhysicsSettings
from openral_mjx.policies import make_policy
from openral_mjx.scenes import TabletopPushOptions, make_scene, scene_options
from openral_mjx.scenes.tabletop_push.arm import prepare, span, workspace

ARMS = Path(__file__).parents[1] / "data" / "arms"
SITES = {"small6": "tool0", "industrial6": "attachment_site", "seven": "tcp"}
MOBILE = Path(__file__).parents[1] / "data" / "mobile_base.xml"


def arm(name: str, **extra: object) -> dict[str, object]:
    """Options for a test arm, as a user gives them: the MJCF and its end-effector site."""
    return {"robot_mjcf": str(ARMS / f"{name}.xml"), "ee_site": SITES[name], **extra}


def push_c(options: dict[str, object]):
    return make_scene("tabletop_push", options, backend="c", settings=PhysicsSettings(threads=2))


def variant(tmp_path: Path, name: str, old: str, new: str) -> str:
    """A copy of arm `name` (with its mesh assets) with `old` replaced by `new` in its XML."""
    text = (ARMS / f"{name}.xml").read_text()
    assert old in text
    shutil.copytree(ARMS / "assets", tmp_path / "assets", dirs_exist_ok=True)
    path = tmp_path / f"{name}_variant.xml"
    path.write_text(text.replace(old, new))
    return str(path)


def one_line_error(options: dict[str, object]) -> str:
    with pytest.raises(ConfigError) as exc:
        push_c(options)
    message = str(exc.value)
    assert "\n" not in message
    return message


# ---- initial configuration ----------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(SITES))
def test_arm_starts_at_its_home_keyframe(name):
    scene = push_c(arm(name))
    own = mujoco.MjModel.from_xml_path(str(ARMS / f"{name}.xml"))
    home = own.key_qpos[own.key("home").id]
    qpos = np.asarray(scene.reset(jax.random.PRNGKey(0)).physics.quantities.qpos)
    np.testing.assert_allclose(qpos[scene.robot_qpos_adr], home, atol=1e-6)
    assert scene.arm.start == "keyframe 'home'"


def test_so101_keeps_its_home_qpos(push_c):
    qpos = np.asarray(push_c.reset(jax.random.PRNGKey(0)).physics.quantities.qpos)
    for joint, value in push_c.robot.home_qpos.items():
        assert qpos[push_c.mj_model.joint(joint).qposadr[0]] == pytest.approx(value)
    assert push_c.arm.start == "home_qpos"


def test_robot_keyframe_option(tmp_path):
    # A second keyframe, named: the arm starts there.
    path = variant(
        tmp_path, "small6", "</keyframe>", '<key name="low" qpos="0.3 0.6 1.8 0 0.7 0"/></keyframe>'
    )
    scene = push_c({"robot_mjcf": path, "ee_site": "tool0", "robot_keyframe": "low"})
    qpos = np.asarray(scene.reset(jax.random.PRNGKey(0)).physics.quantities.qpos)
    np.testing.assert_allclose(qpos[scene.robot_qpos_adr], [0.3, 0.6, 1.8, 0, 0.7, 0], atol=1e-6)
    message = one_line_error(arm("small6", robot_keyframe="nope"))
    assert "robot_keyframe='nope'" in message and "valid: 'home'" in message
    assert "valid: (none)" in one_line_error({"robot_keyframe": "home"})  # so101 has none


# ---- actuators ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "old,new,needle",
    [
        (
            '<general class="small6" name="act2" joint="joint2" ctrlrange="-2.6 2.6"/>',
            '<motor name="act2" joint="joint2" ctrlrange="-30 30"/>',
            "actuator 'act2' is a motor",
        ),
        (
            '<general class="small6" name="act2" joint="joint2" ctrlrange="-2.6 2.6"/>',
            '<velocity name="act2" joint="joint2" kv="20" ctrlrange="-2 2"/>',
            "actuator 'act2' is a velocity servo",
        ),
        (
            '<general class="small6" name="act2" joint="joint2" ctrlrange="-2.6 2.6"/>',
            '<intvelocity name="act2" joint="joint2" kp="400" actrange="-2.6 2.6"/>',
            "actuator 'act2' is an integrated-velocity servo",
        ),
        (
            'gainprm="400 0 0" biasprm="0 -400 -30"',
            'gainprm="400 0 0" biasprm="0 -200 -30"',
            "actuator 'act1' is a position servo with biasprm[1]=-200 != -gainprm[0]=-400",
        ),
    ],
)
def test_non_position_actuators_are_refused(tmp_path, old, new, needle):
    path = variant(tmp_path, "small6", old, new)
    message = one_line_error({"robot_mjcf": path, "ee_site": "tool0"})
    assert needle in message and "position servos" in message


def test_a_mix_names_only_the_bad_actuators(tmp_path):
    path = variant(
        tmp_path,
        "small6",
        '<general class="small6_wrist" name="act5" joint="joint5" ctrlrange="-2.1 2.1"/>',
        '<motor name="act5" joint="joint5"/><velocity name="extra" joint="joint6" kv="1"/>',
    )
    message = one_line_error({"robot_mjcf": path, "ee_site": "tool0"})
    assert "'act5' is a motor" in message and "'extra' is a velocity servo" in message
    assert "'act4'" not in message and "'act6'" not in message


def test_position_and_general_servos_are_the_same(tmp_path):
    """`<position kp kv>` compiles to the `general` servo written out: both are accepted and
    give the same actuator parameters."""
    general = push_c(arm("small6"))
    path = variant(
        tmp_path,
        "small6",
        '<general class="small6" name="act2" joint="joint2" ctrlrange="-2.6 2.6"/>',
        '<position name="act2" joint="joint2" kp="400" kv="30" ctrlrange="-2.6 2.6" '
        'forcerange="-30 30"/>',
    )
    position = push_c({"robot_mjcf": path, "ee_site": "tool0"})
    for field in ("actuator_gainprm", "actuator_biasprm", "actuator_gaintype", "actuator_biastype"):
        np.testing.assert_array_equal(
            getattr(position.mj_model, field), getattr(general.mj_model, field), field
        )


def test_tendon_actuator_is_held_at_its_keyframe_ctrl():
    """The 7-DOF's hand (a `general` servo on a fixed tendon, ctrl 0-255) drives no arm joint:
    the expert holds it at the keyframe's ctrl and learned policies get no joint base."""
    scene = push_c(arm("seven"))
    own = mujoco.MjModel.from_xml_path(str(ARMS / "seven.xml"))
    fingers = own.actuator("fingers").id
    assert scene.arm.held == {fingers: own.key_ctrl[own.key("home").id][fingers]}
    assert scene.action_obs_index() is None
    policy = scene.scripted_policy()
    params, pstate = policy.init(jax.random.PRNGKey(0), None)
    state = scene.reset(jax.random.PRNGKey(1))
    for t in range(3):
        action, pstate = policy.act(params, pstate, state.obs, jax.random.PRNGKey(t))
        assert float(action[fingers]) == scene.arm.held[fingers]
        state = scene.step(state, action)


# ---- tool, integrator, collisions -----------------------------------------------------------


@pytest.mark.parametrize(
    "name,radius",
    [
        ("small6", 0.03),  # its flange cylinder
        ("industrial6", 0.04),  # its flange cylinder
        ("seven", float(np.hypot(0.009, 0.008 + 0.006))),  # the closed finger pads' corners
    ],
)
def test_tool_radius_comes_from_the_end_effector_geoms(name, radius):
    o = TabletopPushOptions(**arm(name))
    setup = prepare(o, o.robot_spec())
    assert setup.tool_radius == pytest.approx(radius, abs=1e-6)
    assert setup.push_height == pytest.approx(0.9 * o.cube_size / 2)  # nothing below the site


def test_so101_tool_radius_is_fixed():
    o = TabletopPushOptions()
    setup = prepare(o, o.robot_spec())
    assert (setup.tool_radius, setup.push_height, setup.hover_clearance) == (0.01, 0.0135, 0.04)
    assert setup.base_x == 0.0


@pytest.mark.parametrize(
    "name,integrator",
    [
        ("so101", mujoco.mjtIntegrator.mjINT_EULER),
        ("small6", mujoco.mjtIntegrator.mjINT_EULER),
        ("industrial6", mujoco.mjtIntegrator.mjINT_IMPLICITFAST),  # its MJCF asks
        ("seven", mujoco.mjtIntegrator.mjINT_IMPLICITFAST),  # kv dt / M > 1 at the wrist
    ],
)
def test_integrator(name, integrator):
    o = TabletopPushOptions(**(arm(name) if name in SITES else {}))
    assert prepare(o, o.robot_spec()).integrator == integrator


def test_seven_rings_under_euler():
    """Why the 7-DOF needs implicitfast: held at home under Euler at 2 ms its wrist servos
    (kv 150) ring at the force limit; under implicitfast it holds still."""
    peak = {}
    for integrator in (mujoco.mjtIntegrator.mjINT_EULER, mujoco.mjtIntegrator.mjINT_IMPLICITFAST):
        model = mujoco.MjModel.from_xml_path(str(ARMS / "seven.xml"))
        model.opt.timestep, model.opt.integrator = 0.002, integrator
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, 0)
        for _ in range(250):
            mujoco.mj_step(model, data)
        peak[integrator] = np.abs(data.qvel[:7]).max()
    assert peak[mujoco.mjtIntegrator.mjINT_EULER] > 0.1
    assert peak[mujoco.mjtIntegrator.mjINT_IMPLICITFAST] < 0.01


def test_cylinders_collide_as_prisms_that_mjx_takes():
    from mujoco import mjx

    scene = push_c(arm("industrial6"))
    m = scene.mj_model
    own = mujoco.MjModel.from_xml_path(str(ARMS / "industrial6.xml"))
    cylinders = [
        g
        for g in range(own.ngeom)
        if own.geom_type[g] == mujoco.mjtGeom.mjGEOM_CYLINDER and own.geom_contype[g]
    ]
    colliding = (m.geom_contype | m.geom_conaffinity) != 0
    assert not np.any(colliding & (m.geom_type == mujoco.mjtGeom.mjGEOM_CYLINDER))
    # Each prism (the same geom of the same body) has its cylinder's length, and vertices at
    # the radius that keeps its cross-section area.
    for g in cylinders:
        body = own.geom_bodyid[g]
        mine = m.body_geomadr[m.body(own.body(body).name).id] + g - own.body_geomadr[body]
        assert m.geom_type[mine] == mujoco.mjtGeom.mjGEOM_MESH
        mesh = m.geom_dataid[mine]
        vert = m.mesh_vert[m.mesh_vertadr[mesh] : m.mesh_vertadr[mesh] + m.mesh_vertnum[mesh]]
        r, half = own.geom_size[g, :2]
        axis = int(np.argmin(np.abs(vert.max(axis=0) - vert.min(axis=0) - 2 * half)))
        assert vert[:, axis].max() - vert[:, axis].min() == pytest.approx(2 * half, abs=1e-6)
        radius = np.linalg.norm(np.delete(vert, axis, axis=1), axis=1)
        assert radius.max() - radius.min() < 1e-6  # every vertex on one circle
        area = 8 * np.sin(2 * np.pi / 16) * radius.max() ** 2  # 16 triangles
        assert area == pytest.approx(np.pi * r**2, rel=1e-5)
    mjx.put_model(m)  # no "cylinder-box collisions not implemented"


# ---- options on the table, reach -----------------------------------------------------------


@pytest.mark.parametrize(
    "override,needle",
    [
        ({"cube_spawn_x": [5, 6]}, "option cube_spawn_x=[5.0, 6.0] leaves the table"),
        ({"cube_spawn_y": [-0.4, 0.0]}, "option cube_spawn_y=[-0.4, 0.0] leaves the table"),
        ({"goal_region_x": [0.1, 0.6]}, "option goal_region_x=[0.1, 0.6] leaves the table"),
        ({"goal_region_y": [0.2, 0.4]}, "option goal_region_y=[0.2, 0.4] leaves the table"),
        ({"goal_distance": [-0.1, 0.1]}, "option goal_distance=[-0.1, 0.1]: must be >= 0"),
        ({"cube_size": 0.8}, "option cube_size=0.8: must be smaller than the table"),
    ],
)
def test_spawn_and_goal_must_be_on_the_table(override, needle):
    with pytest.raises(ConfigError) as exc:
        scene_options("tabletop_push", override)
    assert needle in str(exc.value)


def test_on_table_bounds_are_the_table_minus_half_a_cube():
    o = TabletopPushOptions()
    edge = o.table_center[0] + o.table_size[0] / 2 - o.cube_size / 2
    scene_options("tabletop_push", {"cube_spawn_x": [0.2, edge]})
    with pytest.raises(ConfigError, match=rf"must lie in \[-0.085, {edge:g}\]"):
        scene_options("tabletop_push", {"cube_spawn_x": [0.2, edge + 0.001]})


def test_base_is_placed_from_the_reach():
    """Unset, the industrial arm's base moves back until the workspace lies inside its reach,
    which the composed model shows; the SO-101 stays at 0."""
    scene = push_c(arm("industrial6"))
    setup, o = scene.arm, scene.options
    assert setup.base_x < -0.3
    root = scene.mj_model.body("base").id
    np.testing.assert_allclose(scene.mj_model.body_pos[root], [setup.base_x, 0.0, o.table_height])
    box = workspace(o, o.cube_size / 2 + setup.tool_radius + 0.008)
    near, far = span(*box, np.array([setup.base_x, 0.0]))
    assert setup.reach.near <= near and far <= setup.reach.far


def test_workspace_out_of_reach_names_the_option_and_a_value_that_works():
    message = one_line_error(arm("industrial6", robot_base_x=0.0))
    assert message.startswith("option robot_base_x=0: mjcf:industrial6.xml reaches")
    value = float(re.search(r"set robot_base_x=(-?[0-9.]+)", message).group(1))
    assert push_c(arm("industrial6", robot_base_x=value)).arm.base_x == value
    message = one_line_error({"robot_mjcf": str(MOBILE), "robot_base_x": 0.0})
    assert "cannot bring its site 'ee'" in message and "no robot_base_x" in message


def test_expert_refuses_an_arm_that_cannot_reach():
    """Unset, a robot that reaches the table nowhere (a mobile base with a mast) still builds
    for other policies; the scripted expert says why it cannot push."""
    scene = push_c({"robot_mjcf": str(MOBILE)})
    with pytest.raises(ConfigError, match=r"the scripted expert cannot push: .*cannot bring"):
        make_policy("scripted", scene)


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["--opt", "cube_spawn_x=[5,6]"], "option cube_spawn_x=[5.0, 6.0] leaves the table"),
        (
            [
                *("--robot-mjcf", str(ARMS / "industrial6.xml")),
                *("--opt", "ee_site=attachment_site", "robot_base_x=-0.25"),
            ],
            "option robot_base_x=-0.25: mjcf:industrial6.xml reaches",
        ),
        (
            ["--robot-mjcf", str(ARMS / "seven.xml"), "--opt", "ee_site=tcp", "robot_keyframe=x"],
            "option robot_keyframe='x': no such keyframe in mjcf:seven.xml; valid: 'home'",
        ),
    ],
)
def test_cli_one_line_exit_2(monkeypatch, capsys, tmp_path, argv, needle):
    out_path = tmp_path / "rep.json"
    monkeypatch.setattr(
        sys, "argv", ["openral_mjx.eval", *argv, "--out", str(out_path), "--backend", "c"]
    )
    with pytest.raises(SystemExit) as exc:
        eval_cli.main()
    _, err = capsys.readouterr()
    assert exc.value.code == 2
    assert needle in err and len(err.strip().splitlines()) == 1
    assert not out_path.exists()


# ---- the expert on each arm -----------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(SITES))
def test_expert_pushes_with_every_arm_on_c(name):
    """>= 60% over 256 seeds (measured: small6 100%, industrial6 100%, seven 91%; 12-15 s
    each from a cold compilation cache on 2 cores)."""
    evaluation = run_evaluation(push_c(arm(name)), "scripted", n_envs=256)
    rate = float(np.mean(evaluation.arrays["success"]))
    assert rate >= 0.6, f"{name}: {rate:.1%}"


@pytest.mark.slow
def test_expert_pushes_on_mjx():
    """The industrial arm on MJX (its cylinders as prisms, implicitfast), 8 seeds: ~3 min on
    2 cores (measured 8/8 here; 256/256 over 256 seeds on an H100)."""
    scene = make_scene("tabletop_push", arm("industrial6"), backend="mjx")
    evaluation = run_evaluation(scene, "scripted", n_envs=8)
    assert float(np.mean(evaluation.arrays["success"])) >= 0.6
