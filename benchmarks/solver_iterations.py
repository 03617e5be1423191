"""Which program spends MuJoCo-Warp's solver iterations: the evaluator against raw physics.

    python benchmarks/solver_iterations.py --task door-open-v3 --n 65536 --max-steps 200 \
        [--profile DIR]

The evaluator (`run_seeds`, the random MLP of `metaworld_mirror.py`) records its actions and
observations; the bare episode function (`make_episode_fn` under one `jit`, with and without
XLA's autotuner) runs the same seeds. Printed: how far their observations and actions are from
the evaluator's, then each run's actions replayed through the scene's step and through a bare
`mjx.step` loop, with the solver's iterations per env and step (`solver_niter` of each control
step's last physics step: the batch's largest sets how often the solver's loop runs). With
`--profile`, second runs of the four programs are traced and their launches of the solver's
kernels counted (`gpu_trace.kernel_summary`). Issue 38: BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import functools
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from gpu_trace import kernel_summary
from metaworld_mirror import mirror_inputs, mlp, raw_control_step, raw_start

from openral_mjx.evaluation import build_scene
from openral_mjx.runner import run_seeds
from openral_mjx.runner.device_layout import compiler_options
from openral_mjx.runner.episode import make_episode_fn, seed_keys

KERNELS = ("linesearch", "JTDAJ", "kinematics_branch", "set_conditional")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="door-open-v3")
    parser.add_argument("--n", type=int, default=65536)
    parser.add_argument("--max-steps", type=int, default=200)
    parser.add_argument("--backend", default="warp")
    parser.add_argument("--profile", type=Path)
    args = parser.parse_args()
    n, steps = args.n, args.max_steps
    scene = build_scene("metaworld_mjx", {"task": args.task}, backend=args.backend, n_envs=n)
    policy = mlp(scene)
    params = policy.init(None, None)[0]
    seeds = jnp.arange(n, dtype=jnp.int32)
    evaluate = functools.partial(
        run_seeds, scene, policy, params, seeds=np.arange(n), n_envs=n, max_steps=steps
    )
    arrays, _ = evaluate(record=("actions", "obs"))
    runs = {"evaluator": (np.asarray(arrays["obs"]), np.asarray(arrays["actions"]))}
    lowered = jax.jit(make_episode_fn(scene, policy, steps, record=("actions", "obs")))
    lowered = lowered.lower(params, seeds)
    for name, options in (("bare", {}), ("bare, no autotuner", compiler_options(seeds.device))):
        _, out = lowered.compile(compiler_options=options)(params, seeds)
        runs[name] = tuple(np.swapaxes(np.asarray(out[k]), 0, 1) for k in ("obs", "actions"))
    obs0, act0 = runs["evaluator"]
    for name, (obs, act) in list(runs.items())[1:]:
        print(
            f"{name} against the evaluator: largest |obs difference| "
            f"{np.abs(obs - obs0).max():.3g}, |action difference| {np.abs(act - act0).max():.3g}"
        )

    reset_keys = seed_keys(seeds)[0]
    data, fields = raw_start(scene, seeds)

    def scene_replay(seed, key, actions):
        def body(state, action):
            state = scene.traced.step(state, action)
            return state, jnp.max(state.physics.data._impl.solver_niter)

        return jax.lax.scan(body, scene.traced.reset_with_seed(seed, key), actions)[1]

    def raw_replay(d, fields, actions):
        step = raw_control_step(scene, scene.backend.model(fields))

        def body(d, inputs):
            d = step(d, inputs)
            return d, jnp.max(d._impl.solver_niter)

        return jax.lax.scan(body, d, mirror_inputs(scene, actions))[1]

    programs = {
        "scene step": (jax.jit(jax.vmap(scene_replay)), (seeds, reset_keys)),
        "raw mjx.step": (jax.jit(jax.vmap(raw_replay)), (data, fields)),
    }
    for name, (_, actions) in runs.items():
        for replay, (fn, inputs) in programs.items():
            niter = np.asarray(fn(*inputs, jnp.asarray(actions)))
            print(
                f"{name}'s actions through the {replay}: batch-largest iterations summed over "
                f"steps {int(niter.max(0).sum())}, env-steps with 2 or more "
                f"{int((niter >= 2).sum())} of {niter.size}",
                flush=True,
            )
    if args.profile is None:
        return
    episode = lowered.compile(compiler_options=compiler_options(seeds.device))
    traced = {
        "evaluator": lambda: evaluate(),
        "bare episode": lambda: jax.block_until_ready(episode(params, seeds)),
        **{
            replay: functools.partial(
                lambda f, a: jax.block_until_ready(f(*a, jnp.asarray(act0))), fn, inputs
            )
            for replay, (fn, inputs) in programs.items()
        },
    }
    for name, run in traced.items():
        run()  # compiled and warm
        where = args.profile / name.replace(" ", "_").replace(".", "_")
        start = time.perf_counter()
        with jax.profiler.trace(where, create_perfetto_trace=True):
            run()
        wall = time.perf_counter() - start
        summary = kernel_summary(where, top=400)
        counts = {
            k: sum(e["count"] for v in summary["top"].values() for e in v if k in e["name"])
            for k in KERNELS
        }
        print(f"{name}: traced {wall:.2f} s, GPU busy {summary['busy_ms']} ms, launches {counts}")


if __name__ == "__main__":
    main()
