"""The stepped model's visual meshes reduced to a speck: the same physics as the full model."""

from __future__ import annotations

import mujoco
import numpy as np

from openral_mjx.physics.visual_meshes import collision_meshes_only, visual_only_meshes

# A box falling onto a floor with a mesh that collides (`hull`) and one that only cameras see
# (`skin`, a finer octahedron sharing the box's body); the last geom is a visual one of `hull`,
# which a colliding geom also uses, so `hull` stays.
_OCTA = "0.05 0 0  -0.05 0 0  0 0.05 0  0 -0.05 0  0 0 0.05  0 0 -0.05"
_TETRA = "0 0 0  0.04 0 0  0 0.04 0  0 0 0.04"
_XML = f"""
<mujoco>
  <asset>
    <mesh name="hull" vertex="{_TETRA}"/>
    <mesh name="skin" vertex="{_OCTA}" scale="1.5 1 1"/>
    <texture name="paint" type="2d" builtin="checker" width="64" height="64"/>
    <material name="paint" texture="paint"/>
  </asset>
  <worldbody>
    <geom type="plane" size="1 1 0.1"/>
    <body pos="0 0 0.3" euler="10 20 30">
      <freejoint/>
      <geom type="mesh" mesh="hull" density="500"/>
      <geom type="mesh" mesh="skin" contype="0" conaffinity="0" group="1" mass="0"
            material="paint"/>
      <geom type="mesh" mesh="hull" contype="0" conaffinity="0" group="1" mass="0" pos="0 0 0.1"/>
    </body>
  </worldbody>
</mujoco>
"""


def _models() -> tuple[mujoco.MjModel, mujoco.MjModel]:
    spec = mujoco.MjSpec.from_string(_XML)
    full = spec.compile()  # compiled in place, as a backend's spec may be
    return full, collision_meshes_only(spec, full)


def test_only_the_mesh_no_colliding_geom_uses_is_reduced() -> None:
    full, slim = _models()
    assert visual_only_meshes(full) == [full.mesh("skin").id]
    skin, hull = full.mesh("skin").id, full.mesh("hull").id
    assert slim is not full and int(slim.mesh_vertnum[skin]) == 4
    assert int(full.mesh_vertnum[skin]) == 6
    assert slim.ntexdata < full.ntexdata  # texels: the renderer's, not the physics'
    a, n = int(full.mesh_vertadr[hull]), int(full.mesh_vertnum[hull])
    b = int(slim.mesh_vertadr[hull])
    np.testing.assert_array_equal(slim.mesh_vert[b : b + n], full.mesh_vert[a : a + n])
    # the visual geom keeps the full mesh's frame and bounds: cameras place it there
    for name in (
        "geom_pos",
        "geom_quat",
        "geom_sameframe",
        "geom_aabb",
        "geom_rbound",
        "geom_size",
    ):
        np.testing.assert_array_equal(getattr(slim, name), getattr(full, name))


def test_the_reduced_model_steps_as_the_full_one_bit_for_bit() -> None:
    full, slim = _models()
    runs = []
    for m in (full, slim):
        d = mujoco.MjData(m)
        rows = []
        for _ in range(400):  # the box lands on its hull and settles
            mujoco.mj_step(m, d)
            rows.append(np.concatenate([d.qpos, d.qvel, d.geom_xpos.ravel()]))
        runs.append(np.stack(rows))
    assert runs[0][-1][2] < 0.1  # it fell
    np.testing.assert_array_equal(runs[1], runs[0])


def test_a_model_with_rangefinders_is_stepped_whole() -> None:
    spec = mujoco.MjSpec.from_string(
        _XML.replace(
            "</worldbody>",
            '<site name="eye" pos="0 0 1" zaxis="0 0 -1"/></worldbody>'
            '<sensor><rangefinder site="eye"/></sensor>',
        )
    )
    full = spec.compile()
    assert visual_only_meshes(full) == []
    assert collision_meshes_only(spec, full) is full
