"""The model MJX steps: the meshes that only cameras see reduced to a speck.

MJX keeps a model's NumPy fields as static pytree metadata, and its Warp implementation hands
every mesh array to each compiled step as an XLA constant. A LIBERO task with its cameras holds
1.03 M mesh vertices, 1.02 M of them in visual meshes that no colliding geom uses: every step
in a compiled episode carried them (a 54 MB cache entry for one CPU episode, with the model
checksummed on every trace). The physics never reads a mesh that no colliding geom uses, so
the model it steps has each such mesh replaced by a tiny tetrahedron; cameras draw from the full
model. Everything else the physics reads is checked equal to the full model's, field by field,
and the full model is stepped wherever it is not.
"""

from __future__ import annotations

import mujoco
import numpy as np

# A mesh's stand-in: a tetrahedron 1 mm across, as an in-memory OBJ file (a compiled spec keeps
# a mesh's loaded data until its file changes, so editing its vertices alone does not take).
_SPECK_FILE = "openral_mjx_speck.obj"
_SPECK = b"v 0 0 0\nv 0.001 0 0\nv 0 0.001 0\nv 0 0 0.001\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
# Geom fields MuJoCo derives from the mesh at compile time: its frame (and whether that is the
# body's) and bounds. They are kept from the full model: cameras place visual geoms by them,
# and collision never meets them.
_GEOM_FIELDS = ("geom_pos", "geom_quat", "geom_sameframe", "geom_aabb", "geom_rbound", "geom_size")
# Arrays allowed to differ: the meshes themselves (the colliding ones are compared apart), the
# bounding volume hierarchy built over them (MuJoCo's ray casts; MJX's step does not read it),
# the textures (1 x 1 in the stepped model: decoding them again took longer than the rest),
# and the sizes.
_MESH_DERIVED = ("mesh_", "bvh_", "tex_", "_sizes")


def visual_only_meshes(model: mujoco.MjModel) -> list[int]:
    """Ids of the meshes that no colliding geom uses (none where the model has rangefinders,
    which MuJoCo ray casts against every geom)."""
    if np.any(model.sensor_type == mujoco.mjtSensor.mjSENS_RANGEFINDER):
        return []
    mesh = model.geom_type == mujoco.mjtGeom.mjGEOM_MESH
    colliding = (model.geom_contype | model.geom_conaffinity) > 0
    collided = set(model.geom_dataid[mesh & colliding].tolist())
    return [i for i in range(model.nmesh) if i not in collided]


def collision_meshes_only(spec: mujoco.MjSpec, model: mujoco.MjModel) -> mujoco.MjModel:
    """`model` (`spec` compiled) with its visual-only meshes reduced to a speck and its
    textures to a texel, or `model` itself where it has no such mesh, where MuJoCo will not
    compile the reduced spec, or where the reduced model would differ in anything else."""
    visual = visual_only_meshes(model)
    if not visual:
        return model
    reduced = spec.copy()
    reduced.assets = {**reduced.assets, _SPECK_FILE: _SPECK}
    for i in visual:
        mesh = reduced.meshes[i]
        mesh.file, mesh.scale = _SPECK_FILE, [1.0, 1.0, 1.0]
        for data in ("vert", "face", "normal", "texcoord", "facenormal", "facetexcoord"):
            setattr(mesh, f"user{data}", [])  # a mesh given inline rather than by file
    for texture in reduced.textures:
        texture.file, texture.builtin = "", mujoco.mjtBuiltin.mjBUILTIN_FLAT
        texture.width = texture.height = 1
    try:
        slim = reduced.compile()
    except ValueError:  # a mesh MuJoCo cannot replace (say, one another asset refers to)
        return model
    geoms = np.flatnonzero(
        (model.geom_type == mujoco.mjtGeom.mjGEOM_MESH) & np.isin(model.geom_dataid, visual)
    )
    for name in _GEOM_FIELDS:
        getattr(slim, name)[geoms] = getattr(model, name)[geoms]
    slim.dof_length[:] = model.dof_length  # from the bodies' geoms (MuJoCo-Warp's sleeping)
    return slim if _same_physics(model, slim, visual) else model


def _same_physics(full: mujoco.MjModel, slim: mujoco.MjModel, visual: list[int]) -> bool:
    """Whether `slim` equals `full` in every array outside `_MESH_DERIVED`, and in the
    meshes outside `visual` (those that collide)."""
    for name in dir(full):
        a = getattr(full, name)
        if not isinstance(a, np.ndarray) or name.startswith(_MESH_DERIVED):
            continue
        if not np.array_equal(a, getattr(slim, name), equal_nan=True):
            return False
    kept = sorted(set(range(full.nmesh)) - set(visual))
    for i in kept:
        a, n = int(full.mesh_vertadr[i]), int(full.mesh_vertnum[i])
        b = int(slim.mesh_vertadr[i])
        if int(slim.mesh_vertnum[i]) != n or not np.array_equal(
            full.mesh_vert[a : a + n], slim.mesh_vert[b : b + n]
        ):
            return False
    return True
