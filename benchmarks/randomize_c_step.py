"""The `c` backend's cost of per-env model fields, one batched control step at a time.

Steps the same `tabletop_push` states with the model's own values and with every physics field
`--randomize` writes given per env (equal to the model's, so both step the same physics): the
difference is what per-env model copies cost MuJoCo C (the rollout over distinct models, and
the check for changed rows). Interleaved, best of `--repeats`, on one process.

    python benchmarks/randomize_c_step.py --n 256 --steps 20 --repeats 5
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

from openral_mjx.evaluation import build_scene

FIELDS = (
    "actuator_biasprm",
    "actuator_gainprm",
    "body_inertia",
    "body_mass",
    "dof_M0",
    "dof_armature",
    "dof_damping",
    "geom_friction",
)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=256)
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args()
    scene = build_scene("tabletop_push", backend="c", n_envs=args.n)
    b = scene.backend
    keys = jax.vmap(lambda s: jax.random.split(jax.random.PRNGKey(s), 2)[0])(jnp.arange(args.n))
    bits = np.asarray(jax.jit(jax.vmap(scene.reset))(keys).physics.data)
    m = b.host_model
    ctrl = np.tile(np.asarray(m.qpos0[: b.nu], np.float32), (args.n, 1))
    values = [np.repeat(getattr(m, k)[None], args.n, 0).astype(np.float32) for k in FIELDS]
    best = {"nominal": np.inf, "per-env fields": np.inf}
    for _ in range(args.repeats):
        for label, names, vals in (("nominal", (), ()), ("per-env fields", FIELDS, values)):
            b._host_step(names, False, bits, ctrl, *vals)  # warm: copies made, fields written
            t = time.perf_counter()
            for _ in range(args.steps):
                b._host_step(names, False, bits, ctrl, *vals)
            best[label] = min(best[label], (time.perf_counter() - t) / args.steps)
    for label, s in best.items():
        print(f"{label:15s} {1e3 * s:6.2f} ms per control step of {args.n} envs")
    print(f"ratio {best['per-env fields'] / best['nominal']:.2f} (threads {b.threads})")


if __name__ == "__main__":
    main()
