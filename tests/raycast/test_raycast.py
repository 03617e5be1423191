"""Ray-cast sensors against MuJoCo C's `mj_multiRay` (float64) on the same states.

Random poses of `tabletop_push`, `so101_box` and a hand-made scene holding every primitive
type (plane, sphere, capsule, ellipsoid, cylinder, box) and a mobile base; our float32 casts
run under `jit` and `vmap` over the batch of poses. Measured worst case over these tests:
9.4e-7 m (bound 1e-4 m); 2.1e-6 m over 30 poses per scene with 64x48 images.

`mj_multiRay` culls bodies with a bounding sphere placed at the body's inertial position plus
its bounding box's centre unrotated, so it can miss a hit on a rotated body (here: 9 of the
so101_box wrist camera's rays through the moving finger, a few cm away) that `mj_ray`, which
tests every geom, finds. Where the two disagree, `mj_ray` is the reference, and the tests bound
how often that happens.
"""

from __future__ import annotations

import copy
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from openral_mjx import raycast
from openral_mjx.core.errors import ConfigError
from openral_mjx.raycast.geoms import subtree

TOL = 1e-4  # metres, float32 casts against float64 mj_multiRay
N_POSES = 6
MOBILE = Path(__file__).parents[1] / "data" / "mobile_base.xml"

SHAPES = """
<mujoco>
  <asset>
    <material name="m" rgba="0.6 0.6 0.6 1"/>
    <material name="clear" rgba="1 1 1 0"/>
  </asset>
  <worldbody>
    <geom name="floor" type="plane" size="3 3 0.1" material="m"/>
    <geom name="ghost" type="box" size="0.3 0.3 0.3" pos="0 0 0.5" material="clear"/>
    <geom name="hidden" type="box" size="0.2 0.2 0.2" pos="0 0 0.9" group="4" material="m"/>
    <camera name="top" pos="0 0 2.2" resolution="32 24" fovy="70"/>
    <body name="sphere" pos="0.5 0 0.3"><freejoint/>
      <geom type="sphere" size="0.12" material="m"/></body>
    <body name="capsule" pos="-0.5 0 0.3"><freejoint/>
      <geom type="capsule" size="0.06 0.15" material="m"/></body>
    <body name="ellipsoid" pos="0 0.5 0.3"><freejoint/>
      <geom type="ellipsoid" size="0.15 0.08 0.1" material="m"/></body>
    <body name="cylinder" pos="0 -0.5 0.3"><freejoint/>
      <geom type="cylinder" size="0.08 0.12" material="m"/></body>
    <body name="box" pos="0.5 0.5 0.3"><freejoint/>
      <geom type="box" size="0.1 0.05 0.08" material="m"/></body>
  </worldbody>
</mujoco>
"""


def with_mobile_base(xml: str) -> mujoco.MjModel:
    """`xml`'s world with the mobile base robot attached at the origin."""
    spec = mujoco.MjSpec.from_string(xml)
    robot = mujoco.MjSpec.from_file(str(MOBILE))
    frame = spec.worldbody.add_frame()
    frame.attach_body(robot.body("base_link"), "", "")
    return spec.compile()


def random_states(model: mujoco.MjModel, n: int, box, seed: int = 0) -> list[mujoco.MjData]:
    """`n` states: joints uniform in their ranges, free bodies anywhere in `box` (lo, hi)
    with random orientations; kinematics evaluated."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        d = mujoco.MjData(model)
        for j in range(model.njnt):
            a, t = model.jnt_qposadr[j], model.jnt_type[j]
            if t == mujoco.mjtJoint.mjJNT_FREE:
                d.qpos[a : a + 3] = rng.uniform(*box)
                q = rng.normal(size=4)
                d.qpos[a + 3 : a + 7] = q / np.linalg.norm(q)
            elif model.jnt_limited[j]:
                d.qpos[a] = rng.uniform(*model.jnt_range[j])
            else:
                d.qpos[a] = rng.uniform(-np.pi, np.pi)
        mujoco.mj_kinematics(model, d)
        mujoco.mj_camlight(model, d)
        out.append(d)
    return out


MULTIRAY_MISSES: list[int] = []  # rays per call where mj_multiRay and mj_ray disagree


def multiray(model, data, origin, dirs, groups=raycast.VISIBLE_GROUPS, hidden_bodies=()):
    """mj_multiRay distances (inf: no hit) and geom ids, `mj_ray`'s where the two disagree
    (see module docstring); geoms of `hidden_bodies` made invisible (MuJoCo skips alpha-0
    geoms), which excludes several bodies at once."""
    if hidden_bodies:
        model = copy.copy(model)
        for g in range(model.ngeom):
            if int(model.geom_bodyid[g]) in hidden_bodies:
                model.geom_matid[g], model.geom_rgba[g, 3] = -1, 0.0
    mask = np.zeros(mujoco.mjNGROUP, np.uint8)
    mask[list(groups)] = 1
    dirs = np.ascontiguousarray(dirs, np.float64)
    geom = np.zeros(len(dirs), np.int32)
    dist = np.zeros(len(dirs))
    org = np.asarray(origin, np.float64)
    mujoco.mj_multiRay(
        model, data, org, dirs.reshape(-1), mask, 1, -1, geom, dist, None, len(dirs), 1e10
    )
    one = np.zeros(1, np.int32)
    misses = 0
    for i, v in enumerate(dirs):
        exact = mujoco.mj_ray(model, data, org, v, mask, 1, -1, one)
        if exact != dist[i]:
            misses += 1
            dist[i], geom[i] = exact, one[0]
    MULTIRAY_MISSES.append(misses)
    return np.where(dist < 0, np.inf, dist), geom


def poses(datas):
    xpos = jnp.asarray(np.stack([d.xpos for d in datas]), jnp.float32)
    xquat = jnp.asarray(np.stack([d.xquat for d in datas]), jnp.float32)
    return xpos, xquat


def check_camera(model, datas, spec: raycast.DepthSpec, hidden=()) -> tuple[float, set[int]]:
    """Depth image and point cloud against mj_multiRay through the same pixels; returns the
    worst error (m) and the geom types hit."""
    cam = spec.build(model)
    depth, valid = jax.jit(jax.vmap(lambda p, q: raycast.depth_image(cam, p, q)))(*poses(datas))
    points, pvalid = jax.jit(jax.vmap(lambda p, q: raycast.depth_pointcloud(cam, p, q)))(
        *poses(datas)
    )
    worst, kinds = 0.0, set()
    for i, d in enumerate(datas):
        rot = d.cam_xmat[cam.cam_id].reshape(3, 3)
        world = cam.dirs.astype(np.float64) @ rot.T
        t, geom = multiray(model, d, d.cam_xpos[cam.cam_id], world, spec.groups, hidden)
        z = t * cam.optical_dirs[:, 2]
        ok = (z >= spec.min_range_m) & (z <= spec.max_range_m)
        np.testing.assert_array_equal(np.asarray(valid[i]).reshape(-1), ok)
        np.testing.assert_array_equal(np.asarray(pvalid[i]), ok)
        expect = np.where(ok, z, spec.max_range_m).reshape(cam.shape)
        got = np.asarray(depth[i], np.float64)
        worst = max(worst, float(np.abs(got - expect).max()))
        ref_points = np.where(ok[:, None], t[:, None] * cam.optical_dirs, 0.0)
        worst = max(worst, float(np.abs(np.asarray(points[i]) - ref_points).max()))
        kinds |= {int(model.geom_type[g]) for g in geom[ok]}
    return worst, kinds


def check_laser(model, datas, spec: raycast.LaserSpec, hidden=()) -> tuple[float, int]:
    """Laser ranges against mj_multiRay from the same origin; returns the worst error (m)
    and how many beams hit something within range."""
    laser = spec.build(model)
    ranges = jax.jit(jax.vmap(lambda p, q: raycast.laser_scan(laser, p, q)))(*poses(datas))
    worst, hits = 0.0, 0
    for i, d in enumerate(datas):
        s = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, spec.frame)
        if s >= 0:
            pos, mat = d.site_xpos[s], d.site_xmat[s].reshape(3, 3)
        else:
            b = model.body(spec.frame).id
            pos, mat = d.xpos[b], d.xmat[b].reshape(3, 3)
        heading = np.arctan2(mat[1, 0], mat[0, 0])
        angles = heading + laser.angles.astype(np.float64)
        dirs = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
        origin = pos + np.array([0.0, 0.0, spec.height_m])
        t, _ = multiray(model, d, origin, dirs, spec.groups, hidden)
        expect = np.minimum(t, spec.max_range_m)
        got = np.asarray(ranges[i], np.float64)
        assert np.isfinite(got).all()
        worst = max(worst, float(np.abs(got - expect).max()))
        hits += int((t < spec.max_range_m).sum())
    return worst, hits


@pytest.fixture(scope="module")
def shapes():
    model = with_mobile_base(SHAPES)
    return model, random_states(model, N_POSES, ([-0.7, -0.7, 0.05], [0.7, 0.7, 0.6]))


def test_every_primitive_type_against_mj_multiray(shapes):
    model, datas = shapes
    worst, kinds = check_camera(model, datas, raycast.DepthSpec("top", max_range_m=5.0))
    assert worst < TOL
    primitives = {
        mujoco.mjtGeom.mjGEOM_PLANE,
        mujoco.mjtGeom.mjGEOM_SPHERE,
        mujoco.mjtGeom.mjGEOM_CAPSULE,
        mujoco.mjtGeom.mjGEOM_ELLIPSOID,
        mujoco.mjtGeom.mjGEOM_CYLINDER,
        mujoco.mjtGeom.mjGEOM_BOX,
    }
    assert kinds == {int(k) for k in primitives}


def test_laser_on_a_mobile_base_excludes_the_robot(shapes):
    """The default laser ignores the whole robot (base and mast), as if its geoms were
    invisible; the reference hides them from mj_multiRay."""
    model, datas = shapes
    spec = raycast.LaserSpec(frame="laser", height_m=0.05, max_range_m=2.0)
    robot = subtree(model, [model.body("base_link").id])
    worst, hits = check_laser(model, datas, spec, hidden=robot)
    assert worst < TOL and hits > N_POSES * 30


def test_self_exclusion_of_a_ray_that_would_hit_the_robot():
    """A beam from the base backwards, through the robot's own mast: excluded by default, it
    reaches the wall behind; with nothing excluded it stops at the mast's surface (closed
    form), where mj_multiRay stops too."""
    xml = """<mujoco><asset><material name="m" rgba="1 1 1 1"/></asset><worldbody>
      <geom name="wall" type="box" size="0.01 1 1" pos="-1 0 0" material="m"/>
    </worldbody></mujoco>"""
    model = with_mobile_base(xml)
    d = mujoco.MjData(model)  # base at the origin facing +x, mast down
    mujoco.mj_kinematics(model, d)
    xpos, xquat = jnp.asarray(d.xpos, jnp.float32), jnp.asarray(d.xquat, jnp.float32)
    # Beam 0 at bearing pi points along -x, 0.06 m up: above the chassis, through the mast.
    spec = dict(frame="laser", n_beams=4, height_m=0.03, angle_min=np.pi, max_range_m=5.0)
    own = raycast.laser_scan(raycast.LaserSpec(**spec).build(model), xpos, xquat)
    bare = raycast.laser_scan(raycast.LaserSpec(**spec, exclude=()).build(model), xpos, xquat)
    laser_x, mast_x, mast_r, wall_x = 0.05, -0.04, 0.015, -1.0 + 0.01
    assert float(own[0]) == pytest.approx(laser_x - wall_x, abs=TOL)
    assert float(bare[0]) == pytest.approx(laser_x - (mast_x + mast_r), abs=TOL)
    origin = d.site_xpos[model.site("laser").id] + np.array([0.0, 0.0, 0.03])
    t, geom = multiray(model, d, origin, np.array([[-1.0, 0.0, 0.0]]))
    assert model.geom(int(geom[0])).name == "mast"
    assert float(bare[0]) == pytest.approx(t[0], abs=TOL)


@pytest.mark.parametrize("scene_name", ["tabletop_push", "so101_box"])
def test_scene_cameras_and_lasers_against_mj_multiray(scene_name, push_c, box_c):
    scene = push_c if scene_name == "tabletop_push" else box_c
    model = scene.mj_model
    region = (
        ([-0.1, -0.35, 0.75], [0.5, 0.35, 1.0])
        if scene_name == "tabletop_push"
        else ([0.0, -0.4, 0.0], [0.5, 0.4, 0.3])
    )
    datas = random_states(model, N_POSES, region, seed=1)
    worst = 0.0
    for c in range(model.ncam):
        name = model.camera(c).name
        for groups in (raycast.VISIBLE_GROUPS, raycast.ALL_GROUPS):
            spec = raycast.DepthSpec(name, width=40, height=30, max_range_m=3.0, groups=groups)
            err, kinds = check_camera(model, datas, spec)
            worst = max(worst, err)
            assert mujoco.mjtGeom.mjGEOM_PLANE in kinds
    # A laser on the moving end-effector (the arm excluded), and one that sees the arm.
    arm = subtree(model, [model.body("base").id])
    err, hits = check_laser(model, datas, raycast.LaserSpec(frame="ee", height_m=0.0), arm)
    worst = max(worst, err)
    assert hits > 0
    err, _ = check_laser(model, datas, raycast.LaserSpec(frame="ee", height_m=0.0, exclude=()))
    assert max(worst, err) < TOL


def test_mj_multiray_is_the_reference_almost_everywhere():
    """The tests above compared with mj_multiRay itself on all but a handful of rays."""
    assert len(MULTIRAY_MISSES) > 50
    assert sum(MULTIRAY_MISSES) <= 0.001 * 14400 * 8


def test_rays_that_hit_nothing_read_exactly_max_range(shapes):
    model, datas = shapes
    # 3 m above everything, beams parallel to the floor: nothing to hit.
    laser = raycast.LaserSpec(frame="laser", height_m=3.0, max_range_m=7.5).build(model)
    ranges = jax.jit(jax.vmap(lambda p, q: raycast.laser_scan(laser, p, q)))(*poses(datas))
    assert ranges.dtype == jnp.float32 and ranges.shape == (N_POSES, 360)
    assert bool((ranges == jnp.float32(7.5)).all())
    # A depth camera whose range ends before the floor: all invalid, all max_range.
    cam = raycast.DepthSpec("top", max_range_m=0.5).build(model)
    depth, valid = jax.vmap(lambda p, q: raycast.depth_image(cam, p, q))(*poses(datas))
    assert not bool(valid.any()) and bool((depth == jnp.float32(0.5)).all())


def test_non_finite_poses_never_give_nan_or_inf(shapes):
    model, datas = shapes
    laser = raycast.LaserSpec(frame="laser").build(model)
    xpos, xquat = poses(datas[:1])
    ranges = raycast.laser_scan(laser, xpos[0].at[1].set(jnp.nan), xquat[0])
    assert bool(jnp.isfinite(ranges).all())


def test_optical_frame_conventions():
    """A camera 2 m above a floor, looking straight down with image up = world +x: depth is
    2 everywhere; a pixel right of centre has +x, below centre +y (optical frame), and the
    points sit on the floor."""
    xml = """<mujoco><asset><material name="m" rgba="1 1 1 1"/></asset><worldbody>
      <geom type="plane" size="5 5 0.1" material="m"/>
      <camera name="down" pos="0 0 2" xyaxes="0 -1 0 1 0 0" fovy="60"/>
    </worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(model)
    mujoco.mj_forward(model, d)
    cam = raycast.DepthSpec("down", width=8, height=6).build(model)
    xpos, xquat = jnp.asarray(d.xpos, jnp.float32), jnp.asarray(d.xquat, jnp.float32)
    depth, valid = raycast.depth_image(cam, xpos, xquat)
    points, _ = raycast.depth_pointcloud(cam, xpos, xquat)
    assert bool(valid.all())
    np.testing.assert_allclose(np.asarray(depth), 2.0, atol=1e-6)
    grid = np.asarray(points).reshape(6, 8, 3)
    assert (grid[:, 4:, 0] > 0).all() and (grid[:, :4, 0] < 0).all()  # +x right
    assert (grid[3:, :, 1] > 0).all() and (grid[:3, :, 1] < 0).all()  # +y down
    np.testing.assert_allclose(grid[..., 2], 2.0, atol=1e-6)
    # Image right is the camera's x axis (world -y), image down its -y axis (world -x).
    world = (np.asarray(cam.dirs) @ d.cam_xmat[0].reshape(3, 3).T).reshape(6, 8, 3)
    right, down = world[0, -1] - world[0, 0], world[-1, 0] - world[0, 0]
    assert right[1] < 0 and abs(right[0]) < 1e-6
    assert down[0] < 0 and abs(down[1]) < 1e-6


def test_same_bits_at_any_batch_size(shapes):
    """The cast is elementwise with a fixed order: an env's image does not depend on its batch
    (so a depth observation keeps episodes batch-size independent)."""
    model, datas = shapes
    cam = raycast.DepthSpec("top", width=16, height=12).build(model)
    f = jax.jit(jax.vmap(lambda p, q: raycast.depth_image(cam, p, q)[0]))
    xpos, xquat = poses(datas)
    np.testing.assert_array_equal(f(xpos[:2], xquat[:2]), f(xpos, xquat)[:2])


def test_names_are_checked_at_build_time(shapes):
    model, _ = shapes
    with pytest.raises(ConfigError, match=r"unknown camera 'nope'; valid: top"):
        raycast.DepthSpec("nope").build(model)
    with pytest.raises(ConfigError, match=r"no body or site named 'nope'; bodies: world"):
        raycast.LaserSpec(frame="nope").build(model)
    with pytest.raises(ConfigError, match=r"unknown body 'nope'"):
        raycast.LaserSpec(frame="laser", exclude=("nope",)).build(model)
    with pytest.raises(ConfigError, match=r"geom groups \[7\] out of range"):
        raycast.LaserSpec(frame="laser", groups=(7,)).build(model)
    with pytest.raises(ConfigError, match="stride=0 must be >= 1"):
        raycast.DepthSpec("top", stride=0)
    tracking = mujoco.MjModel.from_xml_string(
        '<mujoco><worldbody><body name="b"><camera name="t" mode="track"/></body></worldbody>'
        "</mujoco>"
    )
    with pytest.raises(ConfigError, match="must have mode 'fixed'"):
        raycast.DepthSpec("t").build(tracking)


def test_meshes_are_refused_unless_filtered_out():
    xml = """<mujoco><asset><mesh name="tet" vertex="0 0 0 1 0 0 0 1 0 0 0 1"/>
      <material name="m" rgba="1 1 1 1"/></asset><worldbody>
      <camera name="c" pos="0 0 3"/><geom name="rock" type="mesh" mesh="tet" material="m"/>
      <geom name="ghost_rock" type="mesh" mesh="tet" group="3" material="m"/>
    </worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    with pytest.raises(ConfigError, match=r"primitive geoms only; geoms \['rock'\]"):
        raycast.DepthSpec("c", width=4, height=4).build(model)
    cam = raycast.DepthSpec("c", width=4, height=4, groups=(3,), exclude=()).build
    with pytest.raises(ConfigError, match="ghost_rock"):
        cam(model)
    assert raycast.DepthSpec("c", width=4, height=4, groups=(5,)).build(model).geoms.groups == ()


def test_invisible_and_out_of_group_geoms_are_not_seen(shapes):
    model, _ = shapes
    cam = raycast.DepthSpec("top").build(model)
    names = {model.geom(int(g)).name for g in cam.geoms.geom_ids}
    assert "ghost" not in names and "hidden" not in names and "floor" in names
    every = raycast.DepthSpec("top", groups=raycast.ALL_GROUPS).build(model)
    assert "hidden" in {model.geom(int(g)).name for g in every.geoms.geom_ids}


def test_static_camera_culls_geoms_it_cannot_see():
    """Static geoms outside a static camera's frustum are dropped at build time (moving ones
    never are), and the image is unchanged."""
    xml = """<mujoco><asset><material name="m" rgba="1 1 1 1"/></asset><worldbody>
      <geom name="floor" type="plane" size="5 5 0.1" material="m"/>
      <geom name="behind" type="box" size="0.1 0.1 0.1" pos="0 0 3" material="m"/>
      <geom name="aside" type="sphere" size="0.1" pos="4 0 0.5" material="m"/>
      <geom name="far" type="sphere" size="0.1" pos="0 0 -20" material="m"/>
      <geom name="seen" type="box" size="0.1 0.1 0.1" pos="0.2 0 0.1" material="m"/>
      <body name="mover" pos="4 4 1"><freejoint/>
        <geom type="sphere" size="0.1" material="m"/></body>
      <camera name="c" pos="0 0 2" fovy="60"/>
    </worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    kept = raycast.DepthSpec("c", width=8, height=8, max_range_m=5.0).build(model)
    names = {model.geom(int(g)).name or "mover" for g in kept.geoms.geom_ids}
    assert names == {"floor", "seen", "mover"}
    (d,) = random_states(model, 1, ([3, 3, 1], [3, 3, 1]))
    worst, _ = check_camera(model, [d], kept.spec)
    assert worst < TOL
