"""Warp-rendered depth against the ray-cast depth camera on the same states, on this device.

`tests/physics/test_camera_render.py` checks this in MuJoCo-Warp's CPU mode; this script repeats it
where the renderer runs on a GPU: so101_box on `warp` with the overhead and wrist depth
cameras (rendered by MuJoCo-Warp's batch renderer), N envs reset and stepped with random
actions, every pixel compared with `raycast.depth_image` cast from the same states' body
poses. Prints the worst error (m) and the share of pixels within 1e-4 m.

    python3 benchmarks/depth_agreement.py --n 1024 --steps 20
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jnp
import numpy as np

from openral_mjx import raycast
from openral_mjx.physics import PhysicsSettings
from openral_mjx.runner import seed_keys
from openral_mjx.scenes import make_scene

SIZE = (64, 40)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1024)
    parser.add_argument("--steps", type=int, default=20)
    args = parser.parse_args()
    cams = ("overhead", "wrist")
    options = {"obs_depth_cameras": list(cams), "obs_depth_size": list(SIZE)}
    scene = make_scene(
        "so101_box", options, backend="warp", settings=PhysicsSettings(batch_size=args.n)
    )
    assert scene.backend.rendered == {f"depth_{c}" for c in cams}, scene.backend.rendered
    model = scene.mj_model
    casts = {
        c: raycast.DepthSpec(c, width=SIZE[0], height=SIZE[1], max_range_m=1.0).build(model)
        for c in cams
    }

    @jax.jit
    def errors(state):
        d = state.physics.data
        out = {}
        for c, cam in casts.items():
            cast = jax.vmap(lambda p, q, cam=cam: raycast.depth_image(cam, p, q)[0])(
                d.xpos, d.xquat
            )
            out[c] = jnp.abs(state.physics.quantities.sensors[f"depth_{c}"] - cast)
        return out

    low, high = (np.asarray(x) for x in scene.action_bounds())
    rng = np.random.default_rng(0)
    state = jax.jit(jax.vmap(scene.reset))(seed_keys(jnp.arange(args.n))[0])
    step = jax.jit(jax.vmap(scene.step))
    worst = {c: 0.0 for c in cams}
    within = {c: [] for c in cams}
    for t in range(args.steps + 1):
        for c, err in errors(state).items():
            err = np.asarray(err)
            worst[c] = max(worst[c], float(err.max()))
            within[c].append(float((err <= 1e-4).mean()))
        if t < args.steps:
            action = rng.uniform(low, high, (args.n, scene.action_size)).astype(np.float32)
            state = step(state, jnp.asarray(action))
    device = jax.devices()[0]
    print(f"{device.platform}: {device.device_kind}; {args.n} envs x {args.steps + 1} states")
    for c in cams:
        print(
            f"depth_{c} {SIZE[0]}x{SIZE[1]}: worst |warp - ray cast| {worst[c]:.2e} m, "
            f"pixels within 1e-4 m {100 * min(within[c]):.3f}% (worst state)"
        )


if __name__ == "__main__":
    main()
