"""Camera images from MuJoCo-Warp's batch renderer (`mjx.create_render_context`,
`mjx.refit_bvh`, `mjx.render`), for the `warp` backend's single-env readout under `vmap`.

A render context fixes the number of worlds it renders, so it cannot be built before the
batch is known: `WarpCameras.render` is a `jax.custom_batching.custom_vmap` function whose
batching rule sees the batch size at trace time and renders the whole batch through a context
built for that size (cached per size; a per-device batch on several devices). Unbatched (e.g.
shape evaluation), it renders a batch of one.

Depth is planar (along the optical axis) like the ray-cast depth camera, `max_range_m` where
the renderer saw nothing or a surface outside the camera's range; RGB is float32 in [0, 1].

RGB is lit by the model's lights and the headlight. The renderer reads each world's own light
colours (`RENDER_FIELDS`: an env's fields of those names reach it as a batched model, so the
`light` factor varies them per env); the headlight is baked into its kernel, the same in
every world. Lights are placed in the data by MuJoCo's `mj_camlight`, which `mjx.step` runs and
kinematics alone does not: `WarpCameras.place` puts them (and the cameras, fixed to their body
or tracking it) for the first frame. How RGB is drawn (textures and skybox, shadows,
anti-aliasing) is the specs' `RgbStyle`, one per render context. sRGB textures are decoded
to linear values first, as MuJoCo's renderer samples them (`render_model`), and textured
materials' specular is handed over as OpenGL applies it (`gl_material_terms`).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.core.errors import ConfigError, unknown
from openral_mjx.core.rotations import quat_to_mat
from openral_mjx.physics.base import camera_local
from openral_mjx.physics.cameras import RgbSpec, RgbStyle
from openral_mjx.physics.mjx_backend import mjx
from openral_mjx.raycast import DepthSpec
from openral_mjx.raycast.geoms import mat_vec
from openral_mjx.raycast.mount import Mount, camera, moved

# Per-env model fields the renderer reads (from `PhysicsState.fields`); the others it reads
# from the shared model.
RENDER_FIELDS = ("light_diffuse",)


@dataclasses.dataclass(frozen=True)
class _Camera:
    cam_id: int
    width: int
    height: int
    rgb: tuple[str, ...]  # keys of RGB images of this camera
    depth: tuple[DepthSpec, ...]


def renderable(specs: list[DepthSpec | RgbSpec]) -> list[DepthSpec | RgbSpec]:
    """The specs one render context can serve: RGB images, and depth images at the camera's
    own intrinsics, full resolution (stride 1) and with no excluded bodies; one size per
    camera, one set of geom groups (the first spec's) and one `RgbStyle` (the first RGB
    image's), RGB images first. Depth images left out are ray cast."""
    sizes: dict[str, tuple[int | None, int | None]] = {}
    groups = None
    out = []
    ordered = [s for s in specs if isinstance(s, RgbSpec)]
    style = ordered[0].style if ordered else None
    for s in ordered + [s for s in specs if not isinstance(s, RgbSpec)]:
        if isinstance(s, DepthSpec) and (s.intrinsics is not None or s.exclude or s.stride != 1):
            continue
        if isinstance(s, RgbSpec) and s.style != style:
            continue
        size = (s.width, s.height)
        if sizes.setdefault(s.camera, size) != size or (groups or s.groups) != s.groups:
            continue
        groups = groups or s.groups
        out.append(s)
    return out


def style_options(model: mujoco.MjModel, style: RgbStyle) -> dict[str, Any]:
    """MuJoCo-Warp render-context settings drawing `style`: textures (and the skybox, where
    the model has one), shadows that block their light entirely (MuJoCo's renderer keeps
    none of a shadowed light; MuJoCo-Warp keeps 0.3 by default), sub-pixel samples."""
    skybox = int(mujoco.mjtTexture.mjTEXTURE_SKYBOX)
    return {
        "use_textures": style.textures,
        "render_skybox": style.textures and bool(np.any(model.tex_type == skybox)),
        "use_shadows": style.shadows,
        "shadow_light_fraction": 0.0,
        "samples_per_pixel": style.samples,
    }


def _srgb_table() -> np.ndarray:
    """The linear value (uint8) of each uint8 sRGB-encoded one (IEC 61966-2-1)."""
    c = np.arange(256, dtype=np.float64) / 255.0
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return np.round(lin * 255.0).astype(np.uint8)


_SRGB_LINEAR = _srgb_table()


def srgb_to_linear(texels: np.ndarray) -> np.ndarray:
    """uint8 sRGB-encoded values decoded to linear ones (IEC 61966-2-1), uint8: looked up,
    not computed per texel (a LIBERO task's textures hold ~150 M)."""
    return _SRGB_LINEAR[np.asarray(texels, np.uint8)]


def area_resampled(texels: np.ndarray, height: int, width: int) -> np.ndarray:
    """`texels` (H, W, C) uint8 resampled to (`height`, `width`, C): each new texel the mean
    of the old ones its area covers, weighted by how much of each it covers (a mipmap
    level's box filter, at any ratio).

    Where whole blocks of 2^n x 2^m texels (to 2^16 a block) make each new texel, their
    exact means, rounded: what the weights give there too (float32 holds every partial sum
    exactly), in a twentieth of the time (a 4,096-texel texture to 64: 14 ms)."""
    h, w, c = texels.shape
    ky, kx = h // height, w // width
    whole = (ky * height, kx * width) == (h, w) and ky * kx <= 1 << 16
    if whole and _power_of_two(ky) and _power_of_two(kx):
        rows = texels.reshape(height, ky, w * c).sum(axis=1, dtype=np.uint32)
        block = rows.reshape(height, width, kx, c).sum(axis=2)
        return np.round(block / (ky * kx)).astype(np.uint8)
    return weighted_resampled(texels, height, width)


def weighted_resampled(texels: np.ndarray, height: int, width: int) -> np.ndarray:
    """`area_resampled` at any ratio: each new texel weights the old ones by the share of
    its area they cover (float32)."""

    def weights(n_in: int, n_out: int) -> np.ndarray:  # (n_out, n_in), rows summing to 1
        edges = np.arange(n_out + 1) * (n_in / n_out)
        cells = np.arange(n_in)[None, :]
        cover = np.minimum(edges[1:, None], cells + 1) - np.maximum(edges[:-1, None], cells)
        return (np.clip(cover, 0.0, None) * (n_out / n_in)).astype(np.float32)

    h, w, c = texels.shape
    rows = weights(h, height) @ texels.reshape(h, w * c).astype(np.float32)
    out = np.einsum("jw,iwc->ijc", weights(w, width), rows.reshape(height, w, c))
    return np.clip(np.round(out), 0, 255).astype(np.uint8)


def _power_of_two(n: int) -> bool:
    return n > 0 and n & (n - 1) == 0


def render_model(model: mujoco.MjModel, texels: int = 0) -> mujoco.MjModel:
    """The model MuJoCo-Warp's renderer draws: `model`, or a copy whose textures are changed
    to be drawn as MuJoCo's renderer draws them.

    - sRGB-encoded textures (`tex_colorspace`) hold their linear values. MuJoCo's renderer
      decodes those when it samples them (OpenGL's sRGB texture formats) and writes the result
      unencoded; MuJoCo-Warp reads every texel as stored, which drew LIBERO's sRGB floor
      ~30/255 brighter.
    - `texels` > 0: each texture wider than that is replaced by its mipmap level `texels`
      wide (`area_resampled` in linear values; a cube or skybox texture face by face).
      MuJoCo's renderer samples a minified texture from its mipmaps; MuJoCo-Warp samples the
      one level it is given, so a wood grain seen from afar aliases into noise at full size.
      The level is also what the renderer uploads: LIBERO's 4,096-texel basket took 268 MB
      of GPU memory per process as full-size float RGBA, and its conversion seconds of start-up.
      Only the copy's `tex_width`/`tex_height` shrink (the level sits at the texture's old
      address), so it is for the renderer, never to be compiled or saved.
    """
    srgb = model.tex_colorspace == int(mujoco.mjtColorSpace.mjCOLORSPACE_SRGB)
    wide = (model.tex_width > texels) if texels > 0 else np.zeros(model.ntex, bool)
    changed = [t for t in np.flatnonzero(srgb | wide) if model.tex_adr[t] >= 0]
    if not changed:
        return model
    out = copy.copy(model)  # the arrays too: the physics' model keeps its textures
    faced = {int(mujoco.mjtTexture.mjTEXTURE_CUBE), int(mujoco.mjtTexture.mjTEXTURE_SKYBOX)}
    for t in map(int, changed):
        a, nch = int(out.tex_adr[t]), int(out.tex_nchannel[t])
        w, h = int(out.tex_width[t]), int(out.tex_height[t])
        image = out.tex_data[a : a + w * h * nch].reshape(h, w, nch)  # a view into the copy
        rgb = min(3, nch)  # alpha stays linear
        if srgb[t]:
            image[..., :rgb] = srgb_to_linear(image[..., :rgb])
            out.tex_colorspace[t] = int(mujoco.mjtColorSpace.mjCOLORSPACE_LINEAR)
        if wide[t]:
            faces = h // w if int(out.tex_type[t]) in faced and h % w == 0 else 1
            rows = h // faces  # a cube's faces are stacked and must not blend into each other
            w2 = texels
            h2 = max(1, round(rows * texels / w))
            image = np.concatenate(
                [area_resampled(image[f * rows : (f + 1) * rows], h2, w2) for f in range(faces)]
            )
            out.tex_width[t], out.tex_height[t] = image.shape[1], image.shape[0]
        out.tex_data[a : a + image.size] = image.reshape(-1)
    return out


def _spot_factor(model: mujoco.MjModel, data: mujoco.MjData, light: int, at: np.ndarray) -> float:
    """How much of light `light` reaches point `at` in MuJoCo's renderer: its distance
    attenuation and, for a spot, its cone (OpenGL's cutoff and exponent)."""
    kind = int(model.light_type[light])
    if kind == int(mujoco.mjtLightType.mjLIGHT_DIRECTIONAL):
        return 1.0
    to_point = at - data.light_xpos[light]
    dist = float(np.linalg.norm(to_point))
    a0, a1, a2 = (float(x) for x in model.light_attenuation[light])
    factor = 1.0 / max(a0 + a1 * dist + a2 * dist * dist, mujoco.mjMINVAL)
    if kind == int(mujoco.mjtLightType.mjLIGHT_SPOT):
        cos = float(np.dot(to_point / max(dist, mujoco.mjMINVAL), data.light_xdir[light]))
        if cos < np.cos(np.deg2rad(float(model.light_cutoff[light]))):
            return 0.0
        factor *= max(cos, 0.0) ** float(model.light_exponent[light])
    return factor


def gl_material_terms(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """(mat_emission, mat_specular) that make MuJoCo-Warp's lighting of textured materials
    come out as MuJoCo's renderer's.

    MuJoCo's renderer (OpenGL's fixed-function lighting, the texture modulating the lit
    colour) multiplies the specular term by the texture; MuJoCo-Warp adds it unmodulated,
    and skips it where the shininess is 0. There OpenGL's term does not depend on the view
    (exponent 0): specular x each light's specular colour x how much of the light reaches
    the surface, times the texture, which is what MuJoCo-Warp's emission term draws. So a
    textured material with shininess 0 gets that much emission, evaluated where the first
    geom with the material sits in the model's initial pose (LIBERO's tables: specular 0.2,
    shininess 0, drawn 22/255 darker without it). Elsewhere a textured material's specular
    is scaled by its texture's mean colour, the average of OpenGL's modulation. Untextured
    materials are unchanged. Light colours are averaged over the channels."""
    emission = np.array(model.mat_emission, np.float32)
    specular = np.array(model.mat_specular, np.float32)
    textures = model.mat_texid[:, int(mujoco.mjtTextureRole.mjTEXROLE_RGB)]
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)  # light and geom poses (mj_camlight)
    lights = [i for i in range(model.nlight) if model.light_active[i]]
    head = float(np.mean(model.vis.headlight.specular)) if model.vis.headlight.active else 0.0
    for mat in np.flatnonzero((textures >= 0) & (specular > 0)):
        tex = int(textures[mat])
        if model.mat_shininess[mat] > 0:
            specular[mat] *= _mean_texel(model, tex)
            continue
        geoms = np.flatnonzero(model.geom_matid == mat)
        at = data.geom_xpos[geoms[0]] if len(geoms) else np.zeros(3)
        reach = sum(
            float(np.mean(model.light_specular[i])) * _spot_factor(model, data, i, at)
            for i in lights
        )
        emission[mat] += specular[mat] * (head + reach)
    return emission, specular


def _mean_texel(model: mujoco.MjModel, tex: int) -> float:
    """Texture `tex`'s mean colour (its RGB channels averaged, in [0, 1], linear values)."""
    a, nch = int(model.tex_adr[tex]), int(model.tex_nchannel[tex])
    w, h = int(model.tex_width[tex]), int(model.tex_height[tex])
    texels = model.tex_data[a : a + w * h * nch].reshape(-1, nch)[:, : min(3, nch)]
    if model.tex_colorspace[tex] == int(mujoco.mjtColorSpace.mjCOLORSPACE_SRGB):
        texels = srgb_to_linear(texels)
    return float(np.mean(texels)) / 255.0


# MuJoCo's `mjtCamLight` modes, as the ints `MjModel.light_mode` holds.
_FIXED, _TRACK, _TRACKCOM, _TARGET, _TARGETCOM = range(5)


def _subtree_com(model: mujoco.MjModel, xipos: jax.Array) -> jax.Array:
    """Each body's subtree centre of mass (nbody, 3), as MuJoCo's `mj_comPos` computes it
    from the model's masses."""
    inside = np.zeros((model.nbody, model.nbody), np.float32)  # [a, b]: b in a's subtree
    for b in range(model.nbody):
        a = b
        inside[a, b] = 1.0
        while a:
            a = int(model.body_parentid[a])
            inside[a, b] = 1.0
    weighted = jnp.asarray(model.body_mass, jnp.float32)[:, None] * xipos
    total = model.body_subtreemass
    scale = jnp.asarray(1.0 / np.maximum(total, mujoco.mjMINVAL), jnp.float32)[:, None]
    com = (jnp.asarray(inside) @ weighted) * scale
    return jnp.where(jnp.asarray(total < mujoco.mjMINVAL)[:, None], xipos, com)


def light_poses(
    model: mujoco.MjModel, xpos: jax.Array, xquat: jax.Array, xipos: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """Every light's world position and unit direction, (nlight, 3) each, from one env's body
    poses (`xpos`, `xquat`) and inertial-frame positions (`xipos`), as MuJoCo's `mj_camlight`
    places them in each mode (one tracking a subtree's centre of mass follows the model's
    masses)."""
    modes = [int(k) for k in model.light_mode]
    com = _subtree_com(model, xipos) if {_TRACKCOM, _TARGETCOM} & set(modes) else None
    positions, directions = [], []
    for i, kind in enumerate(modes):
        b, target = int(model.light_bodyid[i]), int(model.light_targetbodyid[i])
        rot = quat_to_mat(xquat[b])
        pos = xpos[b] + mat_vec(rot, jnp.asarray(model.light_pos[i], jnp.float32))
        direction = mat_vec(rot, jnp.asarray(model.light_dir[i], jnp.float32))
        if kind in (_TRACK, _TRACKCOM):
            origin = xpos[b] if kind == _TRACK else com[b]  # type: ignore[index]
            offset = model.light_pos0[i] if kind == _TRACK else model.light_poscom0[i]
            pos = origin + jnp.asarray(offset, jnp.float32)
            direction = jnp.asarray(model.light_dir0[i], jnp.float32)
        elif kind in (_TARGET, _TARGETCOM) and target >= 0:
            direction = (xpos[target] if kind == _TARGET else com[target]) - pos  # type: ignore[index]
        positions.append(pos)
        directions.append(direction / jnp.maximum(jnp.linalg.norm(direction), mujoco.mjMINVAL))
    return jnp.stack(positions), jnp.stack(directions)


def camera_id(model: mujoco.MjModel, name: str) -> int:
    """The id of camera `name`, which MuJoCo-Warp's renderer can place each frame here: a
    perspective camera fixed to its body or tracking it (`mj_camlight`'s `fixed`, `track`,
    `trackcom` modes); a typed error naming the valid cameras otherwise."""
    c = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, name)
    if c < 0:
        raise unknown("camera", name, [model.camera(i).name for i in range(model.ncam)])
    if int(model.cam_mode[c]) not in (_FIXED, _TRACK, _TRACKCOM):
        raise ConfigError(
            f"rendered camera {name!r}: mode {mujoco.mjtCamLight(int(model.cam_mode[c])).name} "
            "is not supported; valid: fixed, track, trackcom"
        )
    if int(model.cam_projection[c]) != int(mujoco.mjtProjection.mjPROJ_PERSPECTIVE):
        raise ConfigError(f"rendered camera {name!r} must be a perspective camera")
    return c


def tracked_camera_pose(
    model: mujoco.MjModel, cam: int, xpos: jax.Array, com: jax.Array | None
) -> tuple[jax.Array, jax.Array]:
    """World position (3,) and rotation (3, 3) of a `track`/`trackcom` camera, as MuJoCo's
    `mj_camlight` puts it: its body's position (`track`) or subtree centre of mass
    (`trackcom`, `com` from `_subtree_com`) plus the offset it had at `qpos0`, with the world
    orientation it had there (it follows the body, never turns with it)."""
    b = int(model.cam_bodyid[cam])
    if int(model.cam_mode[cam]) == _TRACK:
        pos = xpos[b] + jnp.asarray(model.cam_pos0[cam], jnp.float32)
    else:
        assert com is not None
        pos = com[b] + jnp.asarray(model.cam_poscom0[cam], jnp.float32)
    return pos, jnp.asarray(model.cam_mat0[cam].reshape(3, 3), jnp.float32)


class WarpCameras:
    """Renders the images of `specs` (all servable by one context, see `renderable`)."""

    def __init__(
        self,
        mj_model: mujoco.MjModel,
        mx: mjx.Model,
        specs: list[DepthSpec | RgbSpec],
        devices: list[str] | None,
    ) -> None:
        self.mj_model, self.mx, self.devices = mj_model, mx, devices
        self.groups = specs[0].groups
        rgb = [s for s in specs if isinstance(s, RgbSpec)]
        self.style = rgb[0].style if rgb else RgbStyle()
        if self.style.textures and mj_model.nmat:  # the renderer reads materials from `mx`
            emission, specular = gl_material_terms(mj_model)
            self.mx = mx.replace(
                mat_emission=jnp.asarray(emission), mat_specular=jnp.asarray(specular)
            )
        cams: dict[int, _Camera] = {}
        for s in specs:
            cid = camera_id(mj_model, s.camera)
            res = mj_model.cam_resolution[cid]
            w, h = int(s.width or res[0]), int(s.height or res[1])
            c = cams.get(cid, _Camera(cid, w, h, (), ()))
            if isinstance(s, RgbSpec):
                c = dataclasses.replace(c, rgb=(*c.rgb, s.key))
            else:
                c = dataclasses.replace(c, depth=(*c.depth, s))
            cams[cid] = c
        self.cameras = list(cams.values())
        # Fixed cameras hang from their body (`Mount`); tracking ones are placed per frame.
        self._mounts: dict[int, Mount | None] = {
            c.cam_id: (
                camera(mj_model, mj_model.camera(c.cam_id).name, "rendered camera")[1]
                if int(mj_model.cam_mode[c.cam_id]) == _FIXED
                else None
            )
            for c in self.cameras
        }
        self._contexts: dict[int, Any] = {}
        self._ones: dict[tuple[int, Any], Any] = {}  # `_one`'s jitted renders
        self.render = self._make_render()

    @functools.cached_property
    def drawn_model(self) -> mujoco.MjModel:
        """`render_model` of the physics' model, built once for every batch size's context:
        its textures' levels take seconds."""
        return render_model(self.mj_model, self.style.texels)

    def context(self, nworld: int) -> Any:
        """The render context for batches of `nworld` (built on first use)."""
        if nworld not in self._contexts:
            self._contexts[nworld] = mjx.create_render_context(
                self.drawn_model,
                nworld=nworld,
                devices=self.devices,
                cam_active=[c.cam_id for c in self.cameras],
                cam_res=[(c.width, c.height) for c in self.cameras],
                render_rgb=[bool(c.rgb) for c in self.cameras],
                render_depth=[bool(c.depth) for c in self.cameras],
                enabled_geom_groups=list(self.groups),
                **style_options(self.mj_model, self.style),
            )
        return self._contexts[nworld]

    def place(self, d: mjx.Data, fields: dict[str, jax.Array] | None = None) -> mjx.Data:
        """`d` with the rendered cameras' poses and the lights' computed from its body poses
        (what MuJoCo's `mj_camlight` does; kinematics alone leaves them unset, and a light left
        at the origin with no direction lights nothing), the cameras where this env's
        `cam_pos`/`cam_quat` fields put them."""
        ids = jnp.asarray(list(self._mounts), jnp.int32)
        poses = []
        com = None
        if any(int(self.mj_model.cam_mode[c]) == _TRACKCOM for c in self._mounts):
            com = _subtree_com(self.mj_model, d.xipos)
        for cam, mount in self._mounts.items():
            if mount is not None:
                pos, rot = mount.pose(d.xpos, d.xquat)
            else:
                pos, rot = tracked_camera_pose(self.mj_model, cam, d.xpos, com)
            local = camera_local(fields, cam, self.mj_model)
            if local is not None:
                nominal = (self.mj_model.cam_pos[cam], self.mj_model.cam_quat[cam])
                pos, rot = moved(pos, rot, nominal, local)
            poses.append((pos, rot))
        cam_xpos = d.cam_xpos.at[ids].set(jnp.stack([p for p, _ in poses]))
        cam_xmat = d.cam_xmat.at[ids].set(jnp.stack([r for _, r in poses]))
        d = d.replace(cam_xpos=cam_xpos, cam_xmat=cam_xmat)
        if not self.mj_model.nlight:
            return d
        pos, direction = light_poses(self.mj_model, d.xpos, d.xquat, d.xipos)
        return d.tree_replace({"_impl.light_xpos": pos, "_impl.light_xdir": direction})

    def _render(
        self, d: mjx.Data, model: dict[str, jax.Array], axis_size: int, batched: list[bool]
    ) -> tuple[dict, jax.Array]:
        """Render a batch of `axis_size` envs (`batched`: which leaves of (`d`, `model`)),
        re-entering `vmap` so that MJX's own batching rules marshal the data, and the model
        with the envs' own `model` fields, for MuJoCo-Warp. Returns the images and the envs'
        execution tokens after rendering (the only part of the data rendering changes)."""
        from mujoco.mjx._src import render_util
        from mujoco.mjx.warp import render_context

        rc = self.context(axis_size).pytree()
        leaves, treedef = jax.tree.flatten((d, model))
        in_axes = [0 if b else None for b in batched]
        one = self._one(axis_size, treedef)
        rgb, depth, token = jax.vmap(one, in_axes=(in_axes,), axis_size=axis_size)(leaves)
        # One row per env (an unbatched batch of one comes back with an extra axis).
        rgb, depth = rgb.reshape(axis_size, -1), depth.reshape(axis_size, -1)
        token = token.reshape(axis_size)
        adr = render_context.get(rc).depth_adr.numpy()
        out: dict[str, jax.Array] = {}
        for i, c in enumerate(self.cameras):
            if c.rgb:
                image = render_util.get_rgb(rc, i, rgb)
                out.update({key: image for key in c.rgb})
            for s in c.depth:
                a = int(adr[i])
                raw = depth[:, a : a + c.width * c.height].reshape(-1, c.height, c.width)
                valid = (raw > 0) & (raw >= s.min_range_m) & (raw <= s.max_range_m)
                out[s.key] = jnp.where(valid, raw, jnp.float32(s.max_range_m))
        return out, token

    def _one(self, axis_size: int, treedef: Any) -> Any:
        """One env's refit and render through the context for `axis_size`, as a `jit` kept
        per batch size and data layout: JAX then traces MuJoCo-Warp's render once per input
        shapes, where every trace of a step (the episode's scan, the observation probe, the
        warm-up) used to trace it again (~1 s each on the 2-core machine)."""
        key = (axis_size, treedef)
        if key not in self._ones:
            rc = self.context(axis_size).pytree()

            def one(leaves: list[jax.Array]) -> tuple[jax.Array, jax.Array, jax.Array]:
                d, model = jax.tree.unflatten(treedef, leaves)
                d = mjx.refit_bvh(self.mx, d, rc)
                rgb, depth, d = mjx.render(self.mx.replace(**model), d, rc)
                return rgb, depth, d._impl._jax_token

            self._ones[key] = jax.jit(one)
        return self._ones[key]

    def _make_render(self):
        @jax.custom_batching.custom_vmap
        def render_token(
            d: mjx.Data, model: dict[str, jax.Array]
        ) -> tuple[dict[str, jax.Array], jax.Array]:
            out = self._render(d, model, 1, [False] * len(jax.tree.leaves((d, model))))
            return jax.tree.map(lambda x: x[0], out)

        @render_token.def_vmap
        def _batched(axis_size: int, in_batched: Any, d: mjx.Data, model: dict[str, jax.Array]):
            out = self._render(d, model, axis_size, jax.tree.leaves(tuple(in_batched)))
            return out, jax.tree.map(lambda _: True, out)

        def render(
            d: mjx.Data, fields: dict[str, jax.Array] | None = None
        ) -> tuple[dict[str, jax.Array], mjx.Data]:
            """One env's images, drawn with its `fields` of the model's `RENDER_FIELDS`, and
            its data carrying the post-render execution token (so the next physics step is
            ordered after the render)."""
            model = {k: v for k, v in (fields or {}).items() if k in RENDER_FIELDS}
            images, token = render_token(d, model)
            return images, d.tree_replace({"_impl._jax_token": token})

        return render
