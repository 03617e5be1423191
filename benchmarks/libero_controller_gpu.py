"""What the LIBERO mirror's controller costs on its own, per control step, on one device.

The mirror recomputes robosuite's OSC at each of a control step's 25 physics steps: the arm's
pose, Jacobian, mass matrix and bias forces from a robot-only model (`RobotDynamics`), then
`arm_torques`. On the GPU its evaluator ran at 0.32 of raw physics on `libero_object/0`
(2026-11-27), where the contacts are cheap, and the controller was thought to be why; on one
H200 (2026-12-01, BENCHMARKS.md) it took 6.7 ms of the 52.7 ms per control step by which the
evaluator (then at 0.60) trailed raw physics at 4,096 envs. This times it alone, batched as
the runner batches it (``vmap`` over N envs, 25 calls in a loop, as in one control step), and
counts the kernels XLA compiles it into, for two arithmetic forms:

- ``fixed``: as the scene runs it, every product unrolled in a fixed order
  (`core.fixed_order`: a seed's torques do not depend on its batch);
- ``library``: the same functions with `jnp.matmul`, `jnp.sum` and `jnp.linalg.inv` in
  place of the fixed-order helpers (swapped in while tracing), as a bound on what the order
  costs; not batch-invariant, so not a drop-in change.

Usage (after ``source benchmarks/gpu_setup.sh``, task exports in ``OPENRAL_MJX_LIBERO_MODELS``):

    python3 benchmarks/libero_controller_gpu.py --tasks libero_object/0 --ns 4096 16384
"""

from __future__ import annotations

import argparse
import contextlib
import json
import re
import statistics
import time
from collections.abc import Iterator

import jax
import jax.numpy as jnp
import numpy as np

from openral_mjx.benchmarks.libero.mirror import controller
from openral_mjx.core import fixed_order
from openral_mjx.scenes import make_scene

SUBSTEPS = 25

LIBRARY = {
    "dot": lambda a, b: jnp.sum(a * b, axis=-1),
    "mm": jnp.matmul,
    "mv": lambda a, x: jnp.einsum("...ij,...j->...i", a, x),
    "total": lambda x: jnp.sum(x, axis=0),
    "inv_spd": jnp.linalg.inv,
    "norm": lambda x: jnp.linalg.norm(x, axis=-1),
}


@contextlib.contextmanager
def arithmetic(form: str) -> Iterator[None]:
    """Trace with the fixed-order helpers (``fixed``) or the library's (``library``)."""
    saved = {k: getattr(fixed_order, k) for k in LIBRARY}
    if form == "library":
        for k, f in LIBRARY.items():
            setattr(fixed_order, k, f)
    try:
        yield
    finally:
        for k, f in saved.items():
            setattr(fixed_order, k, f)


def kernels(hlo: str) -> int:
    """Kernel launches in compiled GPU HLO, roughly: fusions and custom calls outside the
    fused computations (instructions of the entry and loop-body computations)."""
    count, fused = 0, False
    for line in hlo.splitlines():
        if re.match(r"^\s*(%?fused_|%?[a-z_.0-9]*fused)", line) and "{" in line:
            fused = True
        elif line.startswith("}"):
            fused = False
        elif not fused and re.search(r"= \S+ (fusion|custom-call)\(", line):
            count += 1
    return count


def measure(scene, task: str, n: int, form: str, repeats: int) -> dict:
    """One row: the controller of `scene` (task `task`) at `n` envs in arithmetic `form`."""
    dyn_fn, gains = scene.dynamics, scene.gains
    q0 = np.asarray(scene.mj_model.qpos0, np.float32)
    rq, rv = scene._robot_qpos, scene._robot_dofs
    arm_q, arm_v = scene._arm_q, scene._arm_v
    rng = np.random.default_rng(0)
    qpos = jnp.asarray(q0 + rng.normal(0, 0.02, (n, q0.size)).astype(np.float32))
    qvel = jnp.asarray(rng.normal(0, 0.1, (n, scene.mj_model.nv)).astype(np.float32))
    state = controller.ControllerState(
        goal_pos=jnp.zeros((n, 3)),
        goal_ori=jnp.tile(jnp.eye(3), (n, 1, 1)),
        gripper=jnp.zeros((n, 2)),
    )

    def one(qp, qv, c):
        def sub(i, acc):
            q = qp + 1e-4 * i.astype(jnp.float32)
            dyn = dyn_fn(q[rq], qv[rv])
            return acc + controller.arm_torques(gains, c, dyn, q[arm_q], qv[arm_v])

        return jax.lax.fori_loop(0, SUBSTEPS, sub, jnp.zeros(len(arm_q), jnp.float32))

    with arithmetic(form):
        fn = jax.jit(jax.vmap(one))
        t = time.perf_counter()
        compiled = fn.lower(qpos, qvel, state).compile()
        compile_s = time.perf_counter() - t
    jax.block_until_ready(compiled(qpos, qvel, state))
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = jax.block_until_ready(compiled(qpos, qvel, state))
        times.append(time.perf_counter() - t)
    return {
        "task": task,
        "n": n,
        "form": form,
        "compile_s": round(compile_s, 2),
        "control_step_ms": round(1e3 * statistics.median(times), 3),
        "kernels": kernels(compiled.as_text()),
        "finite": bool(np.isfinite(np.asarray(out)).all()),
        "torque_abs_sum": float(np.abs(np.asarray(out, np.float64)).sum()),  # the forms agree
        "device": str(jax.devices()[0]),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tasks", nargs="+", default=["libero_object/0"])
    ap.add_argument("--ns", nargs="+", type=int, default=[4096])
    ap.add_argument(
        "--forms", nargs="+", choices=("fixed", "library"), default=["fixed", "library"]
    )
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    rows = []
    for task in a.tasks:
        # `c`: only the scene's controller and its constants are used, on JAX's device
        scene = make_scene("libero_mjx", {"task": task, "expert": False}, backend="c")
        for n in a.ns:
            for form in a.forms:
                row = measure(scene, task, n, form, a.repeats)
                rows.append(row)
                print(json.dumps(row), flush=True)
    if a.out:
        with open(a.out, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
