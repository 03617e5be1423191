"""The mirror's camera images on `warp` against MuJoCo's own renderer, on the same states.

A pixel policy trained on MetaWorld's renders (MuJoCo's OpenGL renderer, which MetaWorld
draws through gymnasium) sees, on the mirror, MuJoCo-Warp's ray-traced images of the same
model. For each task the mirror (`metaworld_mjx` on `c`) plays a few seeds with MetaWorld's
scripted expert (or random actions); at chosen steps each state (joint positions and
velocities, mocap poses, the bodies the episode moved) is drawn by both renderers, from every
camera of MetaWorld's model:

- **warp**: the scene's observation path (`obs_rgb_cameras`, default style: textures, skybox,
  shadows), i.e. the images a reset at that joint state observes;
- **MuJoCo**: `mj_forward` on the same model and state, then MuJoCo's OpenGL renderer
  (`mjr_render` through `physics.gl.FrameRenderer`, headless EGL or OSMesa) with its default flags
  (shadows, reflections, the model's 4x multisampling: as `mujoco.Renderer` and MetaWorld
  draw); sites hidden, as MuJoCo-Warp draws none. The `sites` column draws them as
  MetaWorld's renders do (its goal marker at the episode's target, the arm's debug sites).

Per camera: the share of pixels whose every channel is within 8/255 (`within`), and the
mean absolute error over pixels and channels, in 1/255.

``python -m openral_mjx.benchmarks.metaworld.render --tasks push-v3 door-open-v3
pick-place-v3`` prints the table (markdown) and writes it as JSON with ``--out``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.benchmarks.metaworld.mirror import scene as mirror
from openral_mjx.benchmarks.metaworld.mirror.scene import _MOCAP_QUAT as MOCAP_QUAT
from openral_mjx.core.files import write_text_atomic
from openral_mjx.physics import PhysicsSettings
from openral_mjx.physics.gl import FrameRenderer, gl_backend
from openral_mjx.policies import make_policy
from openral_mjx.runner.episode import seed_keys
from openral_mjx.scenes import make_scene

TOL = 8  # per channel, in 1/255
SIZE = (480, 480)  # MetaWorld's default render size (width, height)
STEPS = (0, 50, 100)


def cameras(task: str) -> list[str]:
    """Every camera of the task's MetaWorld model, in model order."""
    m = make_scene("metaworld_mjx", {"task": task}, backend="c").mj_model
    return [m.camera(i).name for i in range(m.ncam)]


def drawn_state(scene: Any, state: Any) -> dict[str, np.ndarray]:
    """What drawing a batch of the mirror's states needs (float64, env-major): qpos, qvel,
    mocap_pos, mocap_quat, body_pos (the bodies the episode moved), target (where MetaWorld
    shows its goal site)."""
    m = scene.mj_model
    q = state.physics.quantities
    n = q.qpos.shape[0]
    rows = {
        "qpos": q.qpos,
        "qvel": q.qvel,
        "mocap_pos": state.info["mocap_pos"],
        "mocap_quat": np.broadcast_to(MOCAP_QUAT, (n, m.nmocap, 4)),
        "body_pos": state.physics.fields.get(
            "body_pos", np.broadcast_to(m.body_pos, (n, m.nbody, 3))
        ),
        "target": state.info["episode"]["target_pos"],
    }
    return {k: np.asarray(v, np.float64) for k, v in rows.items()}


def mirror_states(
    task: str, seeds: Sequence[int], steps: Sequence[int], policy: str = "expert"
) -> dict[str, np.ndarray]:
    """The mirror's states of `seeds` after each of `steps` control steps (0: the reset) on
    `c`, closed loop under MetaWorld's expert or uniform random actions, stacked seed-major
    within each step: `drawn_state`'s arrays and the step."""
    scene = make_scene("metaworld_mjx", {"task": task}, backend="c")
    seeds = np.asarray(seeds, np.int32)
    n = len(seeds)
    state = jax.jit(jax.vmap(scene.reset_with_seed))(seeds, seed_keys(seeds)[0])
    if policy == "expert":
        pol = make_policy("metaworld-expert", scene)
        params, pstate = pol.init(jax.random.PRNGKey(0), None)

        def act(s: Any, key: jax.Array) -> jax.Array:
            return jax.vmap(lambda o: pol.act(params, pstate, o, key)[0])(s.obs)
    else:
        pol = None

        def act(s: Any, key: jax.Array) -> jax.Array:
            return jax.random.uniform(key, (n, 4), minval=-1.0, maxval=1.0)

    step = jax.jit(lambda s, key: jax.vmap(scene.step)(s, act(s, key)))
    key = jax.random.PRNGKey(0)
    out: dict[str, list[np.ndarray]] = {}
    for t in range(max(steps) + 1):
        if t in steps:
            for k, v in {**drawn_state(scene, state), "step": np.full(n, t)}.items():
                out.setdefault(k, []).append(v)
        if t < max(steps):
            key, sub = jax.random.split(key)
            state = step(state, sub)
    if pol is not None and pol.close is not None:
        pol.close()
    scene.close()
    return {k: np.concatenate(v) for k, v in out.items()}


def warp_images(
    task: str, states: dict[str, np.ndarray], cams: Sequence[str], size: tuple[int, int], **style
) -> dict[str, np.ndarray]:
    """Each camera's images (n, H, W, 3) uint8 of `states` through the mirror's observation
    on `warp` (a reset at each state's joint positions, with its episode's bodies); `style`:
    `obs_rgb_*` options (textures, shadows, samples) beside the scene's defaults."""
    options = {
        "task": task,
        "obs_rgb_cameras": list(cams),
        "obs_rgb_size": list(size),
        **{f"obs_rgb_{k}": v for k, v in style.items()},
    }
    n = len(states["qpos"])
    scene = make_scene(
        "metaworld_mjx", options, backend="warp", settings=PhysicsSettings(batch_size=n)
    )
    # Per-env bodies only where the episodes moved some (as the scene's reset passes them).
    moved = not np.array_equal(
        states["body_pos"], np.broadcast_to(scene.mj_model.body_pos, states["body_pos"].shape)
    )
    fields = {"body_pos": jnp.asarray(states["body_pos"], jnp.float32)} if moved else {}
    images = jax.jit(jax.vmap(lambda q, v, f: scene.backend.init(q, v, f).quantities.sensors))(
        jnp.asarray(states["qpos"], jnp.float32), jnp.asarray(states["qvel"], jnp.float32), fields
    )
    return {c: np.round(np.asarray(images[f"rgb_{c}"]) * 255).astype(np.uint8) for c in cams}


def mujoco_images(
    task: str,
    states: dict[str, np.ndarray],
    cams: Sequence[str],
    size: tuple[int, int],
    sites: bool,
) -> dict[str, np.ndarray]:
    """Each camera's images (n, H, W, 3) uint8 of `states` from MuJoCo's OpenGL renderer
    with its default flags, after `mj_forward` (and, with `sites`, the goal site moved to the
    episode's target after it, as MetaWorld does before rendering)."""
    m = make_scene("metaworld_mjx", {"task": task}, backend="c").mj_model
    d = mujoco.MjData(m)
    goal = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "goal")
    w, h = size
    out: dict[str, list[np.ndarray]] = {c: [] for c in cams}
    with FrameRenderer(m, w, h, gl_backend(), shadows=True, reflections=True, sites=sites) as r:
        for i in range(len(states["qpos"])):
            m.body_pos[:] = states["body_pos"][i]
            d.qpos[:], d.qvel[:] = states["qpos"][i], states["qvel"][i]
            d.mocap_pos[:], d.mocap_quat[:] = states["mocap_pos"][i], states["mocap_quat"][i]
            mujoco.mj_forward(m, d)
            if sites and goal >= 0:
                d.site_xpos[goal] = states["target"][i]
            for c in cams:
                out[c].append(r.render(d, m.camera(c).id))
    return {c: np.stack(v) for c, v in out.items()}


def agreement(ours: np.ndarray, ref: np.ndarray, tol: int = TOL) -> tuple[float, float]:
    """(share of pixels with every channel within `tol`/255, mean absolute error in 1/255)."""
    err = np.abs(ours.astype(np.int32) - ref.astype(np.int32))
    return float(np.mean(np.all(err <= tol, axis=-1))), float(err.mean())


@contextlib.contextmanager
def lights_scaled(scale: float) -> Iterator[None]:
    """A diagnostic: MetaWorld's models (both renderers' copies) with every light's and the
    headlight's ambient, diffuse and specular colours times `scale`.

    MuJoCo's OpenGL renderer clamps a vertex's lit colour to 1 before it multiplies the
    texture, MuJoCo-Warp does not clamp before the final pixel; MetaWorld's lights add up to
    about 1.36 on a surface facing up and the camera, so its textured table, floor and walls
    come out brighter on warp. Scaled down so that nothing saturates, the two agree there.
    """
    if scale == 1.0:
        yield
        return
    load_spec = mirror.load_spec

    def dimmed(xml: str) -> mujoco.MjSpec:
        spec = load_spec(xml)
        for light in spec.lights:
            for name in ("ambient", "diffuse", "specular"):
                setattr(light, name, np.asarray(getattr(light, name)) * scale)
        head = spec.visual.headlight
        for name in ("ambient", "diffuse", "specular"):
            setattr(head, name, np.asarray(getattr(head, name)) * scale)
        return spec

    mirror.load_spec = dimmed
    try:
        yield
    finally:
        mirror.load_spec = load_spec


def task_rows(
    task: str,
    seeds: Sequence[int],
    steps: Sequence[int],
    size: tuple[int, int],
    policy: str = "expert",
    light_scale: float = 1.0,
    images: Path | None = None,
    **style: Any,
) -> list[dict[str, Any]]:
    """One row per camera of `task`: agreement over every state, without and with sites
    (and both renderers' images in `images`/TASK.npz, if given)."""
    cams = cameras(task)
    states = mirror_states(task, seeds, steps, policy)
    with lights_scaled(light_scale):
        t0 = time.perf_counter()
        ours = warp_images(task, states, cams, size, **style)
        warp_s = time.perf_counter() - t0
        plain = mujoco_images(task, states, cams, size, sites=False)
        marked = mujoco_images(task, states, cams, size, sites=True)
    if images is not None:
        images.mkdir(parents=True, exist_ok=True)
        arrays = {f"warp_{c}": ours[c] for c in cams} | {f"mujoco_{c}": plain[c] for c in cams}
        np.savez_compressed(images / f"{task}.npz", **arrays)
    rows = []
    for c in cams:
        within, mae = agreement(ours[c], plain[c])
        per_state = [
            agreement(ours[c][i : i + 1], plain[c][i : i + 1])[0] for i in range(len(ours[c]))
        ]
        rows.append(
            {
                "task": task,
                "camera": c,
                "within": within,
                "mae": mae,
                "worst_state": min(per_state),
                "within_sites": agreement(ours[c], marked[c])[0],
                "n_states": len(ours[c]),
                "steps": list(steps),
                "size": list(size),
                "policy": policy,
                "style": style,
                "light_scale": light_scale,
                "warp_render_s": warp_s,
            }
        )
    return rows


def markdown(rows: Sequence[dict[str, Any]]) -> str:
    """Per camera over all tasks (and per task): share within 8/255 and MAE."""
    tasks = list(dict.fromkeys(r["task"] for r in rows))
    cams = list(dict.fromkeys(r["camera"] for r in rows))
    head = (
        "| camera | within 8/255 | MAE (1/255) | worst state | "
        + " | ".join(tasks)
        + " | with sites |\n|---"
        + "|---" * (len(tasks) + 4)
        + "|"
    )
    lines = [head]
    for c in cams:
        mine = [r for r in rows if r["camera"] == c]
        within = np.mean([r["within"] for r in mine])
        mae = np.mean([r["mae"] for r in mine])
        worst = min(r["worst_state"] for r in mine)
        sites = np.mean([r["within_sites"] for r in mine])
        per = " | ".join(f"{100 * r['within']:.1f}%" for r in mine)
        lines.append(
            f"| `{c}` | {100 * within:.1f}% | {mae:.1f} | {100 * worst:.1f}% | {per} | "
            f"{100 * sites:.1f}% |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", default=["push-v3", "door-open-v3", "pick-place-v3"])
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--steps", type=int, nargs="+", default=list(STEPS))
    parser.add_argument("--size", type=int, nargs=2, default=list(SIZE), metavar=("W", "H"))
    parser.add_argument("--policy", choices=("expert", "random"), default="expert")
    parser.add_argument("--samples", type=int, default=1, help="warp sub-pixel samples per axis")
    parser.add_argument(
        "--light-scale", type=float, default=1.0, help="diagnostic: scale every light by this"
    )
    parser.add_argument("--images", type=Path, help="save both renderers' images here")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    rows = []
    size = (args.size[0], args.size[1])
    for task in args.tasks:
        rows += task_rows(
            task,
            range(args.seeds),
            args.steps,
            size,
            args.policy,
            args.light_scale,
            args.images,
            samples=args.samples,
        )
        print(markdown([r for r in rows if r["task"] == task]), file=sys.stderr, flush=True)
    print(markdown(rows))
    if args.out:
        write_text_atomic(args.out, json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
