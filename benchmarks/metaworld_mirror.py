"""MetaWorld natively (`metaworld_mjx`) against MetaWorld itself on the CPU, and against the raw
physics ceiling (issue 20's speed figures).

    python benchmarks/metaworld_mirror.py mirror --tasks mt50 --backend warp --seeds 1000
    python benchmarks/metaworld_mirror.py host --tasks mt50 --seeds 32 --workers 16
    python benchmarks/metaworld_mirror.py raw --tasks reach-v3 push-v3 --backend warp --n 4096 65536
    python benchmarks/metaworld_mirror.py concurrent --tasks reach-v3 push-v3 --backend warp
    python benchmarks/metaworld_mirror.py save-mlp --out /tmp/mw_mlp
    JAX_PLATFORMS=cpu python benchmarks/metaworld_mirror.py mjx-check --tasks mt50 --seeds 2 \
        --max-steps 5

`mirror`: per task, `--seeds` episodes (seeds 0..) at once with a JAX MLP (3 x 256 SiLU, random
weights, fused in the episode's scan) on the mirror; episodes/s from the run time (compile
excluded, reported apart). `host`: the same number of tasks through the `metaworld` host scene
(MetaWorld's gymnasium env in `--workers` processes, uniform random actions: the policy's cost
is nothing beside MetaWorld's step), episodes/s over the whole run. Random weights and random
actions both fail almost always, so every episode runs MetaWorld's full 500 steps on both sides.
`host-direct`: MetaWorld alone, whole episodes inside the worker processes (no per-step
exchange), the simulator's own speed on those cores. `raw`: the evaluator (same MLP) against a
bare `vmap(scan(mjx.step))` on the task's model with each env's own fixed bodies, replaying the
evaluator's mocap targets and gripper controls from the same reset states. The evaluator is
timed as users run it, without a per-step trace; a first run records the actions to replay
(its rate is in the row too; before 2026-11-28, night, the recording run was the one timed).
`concurrent`: one process per task on the same GPU; each compiles and warms up, then runs its
`--seeds` episodes alone, one task after another, and then all at once: episodes/s of the
tasks one at a time against all together, measured by the same processes on the same
compiled programs.
`mjx-peak`: per task, the episode on one process's share of the GPU (`--share`): the batch
that fits, XLA's memory estimate, the allocator's peak, compile time.
`mjx-check`: per task, the mirror on `mjx` against `c` from the same reset vectors under the
same random actions (observation differences, MJX compile time): that every task builds,
compiles and steps on `mjx`. `mjx-forward`: one env's `mjx.forward` on the mjx model, its
contact slots and constraint rows (`--max-contact-points K`: MJX's cap on contacts). JSON
lines go to `--out` (appended), one per task.
`--warp-graph MODE` (`raw`): MuJoCo-Warp's CUDA graph capture mode (the graph-mode table).
`--layers-as-loop` (`raw`): the policy's fixed-order layers on the GPU as the elementwise loop
they were before 2026-11-28, not `batch_invariant.rows_matmul`: the A/B of the MLP's share.
`--poses-before-step` (`mirror`, `raw`): the mirror reads the poses `mj_step` leaves, one
physics step old, as before 2026-11-26: the A/B of what observing the state the step ends in
costs (one more kinematics pass per step).
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from gpu_trace import kernel_summary

from openral_mjx.benchmarks.metaworld.mirror import task as mw
from openral_mjx.core import fixed_order
from openral_mjx.evaluation import build_scene, run_evaluation
from openral_mjx.evaluation.suite import mps_running
from openral_mjx.policies.mlp import MlpConfig, init_params, mlp_policy, save_mlp
from openral_mjx.runner import run_seeds
from openral_mjx.runner.compile_cache import enable_compilation_cache
from openral_mjx.runner.device_layout import compiler_options
from openral_mjx.runner.episode import seed_keys
from openral_mjx.runner.memory import share_devices
from openral_mjx.scenes import scene_suite

HIDDEN = (256, 256, 256)


def tasks_of(names: list[str]) -> list[str]:
    out: list[str] = []
    for name in names:
        out += scene_suite("metaworld_mjx", name) if not name.endswith("-v3") else [name]
    return out


def mlp_config() -> MlpConfig:
    return MlpConfig(
        obs_size=39,
        action_size=4,
        action_offset=(0.0,) * 4,
        action_scale=(1.0,) * 4,
        hidden=HIDDEN,
    )


def mlp(scene):
    config = mlp_config()
    return mlp_policy(config, init_params(config, jax.random.PRNGKey(0)))


def save_random_mlp(args: argparse.Namespace) -> None:
    """The same random MLP as a checkpoint (`--out DIR`), for `eval --policy mlp:DIR`."""
    config = mlp_config()
    save_mlp(args.out, config, init_params(config, jax.random.PRNGKey(0)))
    print(f"saved {args.out}")


def observe_poses_before_step() -> None:
    """The mirror built from here on reads the poses `mj_step` leaves (see module doc)."""
    from openral_mjx.benchmarks.metaworld.mirror import scene
    from openral_mjx.physics import QuantitySpec

    def spec(*args, **kwargs) -> QuantitySpec:
        return QuantitySpec(*args, **{**kwargs, "poses_after_step": False})

    scene.QuantitySpec = spec
    POSES["after_step"] = False


POSES = {"after_step": True}
GRAPH = {"mode": "WARP"}
LAYERS = {"way": "tiles"}  # the policy's fixed-order layers on the GPU (`--layers-as-loop`)


def use_warp_graph_mode(mode: str) -> None:
    """The `warp` backend built from here on puts its model with MuJoCo-Warp graph capture
    `mode` (`mjx.put_model(graph_mode=...)`; MJX's default on a GPU is WARP): the A/B behind
    BENCHMARKS.md's graph-mode table."""
    import mujoco.mjx.warp as mjxw

    from openral_mjx.physics import warp_backend
    from openral_mjx.physics.mjx_backend import mjx

    graph = getattr(mjxw.types.GraphMode, mode)
    put = mjx.put_model

    class Patched:
        @staticmethod
        def put_model(*args, **kwargs):
            return put(*args, **kwargs, graph_mode=graph)

        def __getattr__(self, name):
            return getattr(mjx, name)

    warp_backend.mjx = Patched()
    GRAPH["mode"] = mode


def emit(out: Path | None, row: dict) -> None:
    print(json.dumps(row), flush=True)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        with out.open("a") as f:
            f.write(json.dumps(row) + "\n")


def mirror(args: argparse.Namespace) -> None:
    for task in tasks_of(args.tasks):
        t = time.perf_counter()
        scene = build_scene(
            "metaworld_mjx", {"task": task}, backend=args.backend, n_envs=args.seeds
        )
        built = time.perf_counter() - t
        with run_evaluation(
            scene, mlp(scene), n_envs=args.seeds, n_episodes=args.seeds, batching="chunks"
        ) as ev:
            r = ev.report
            emit(
                args.out,
                {
                    "kind": "mirror",
                    "poses_after_step": POSES["after_step"],
                    "task": task,
                    "backend": args.backend,
                    "device": str(jax.devices()[0].device_kind),
                    "episodes": r.n_episodes,
                    "success_rate": r.success_rate,
                    "diverged": r.diverged,
                    "episodes_per_s": r.episodes_per_s,
                    "env_steps_per_s": r.env_steps_per_s,
                    "run_s": r.run_s,
                    "compile_s": r.compile_s,
                    "build_s": built,
                    # what a user waits for this task: scene, compile and run
                    "wall_s": time.perf_counter() - t,
                },
            )
        scene.close()


def host(args: argparse.Namespace) -> None:
    for task in tasks_of(args.tasks):
        options = {"task": task, "expert": False, "n_workers": args.workers}
        scene = build_scene("metaworld", options, backend="host", n_envs=args.workers)
        t = time.perf_counter()
        with run_evaluation(
            scene, "random", n_envs=args.workers, n_episodes=args.seeds, batching="chunks"
        ) as ev:
            r = ev.report
        wall = time.perf_counter() - t
        emit(
            args.out,
            {
                "kind": "host",
                "task": task,
                "workers": args.workers,
                "episodes": r.n_episodes,
                "success_rate": r.success_rate,
                "episodes_per_s": r.episodes_per_s,
                "env_steps_per_s": r.env_steps_per_s,
                "wall_s": wall,
            },
        )
        scene.close()


def host_direct(args: argparse.Namespace) -> None:
    """MetaWorld alone: whole episodes inside `--workers` worker processes (no per-step
    exchange with the evaluator), random actions, 500 steps: the simulator's own speed."""
    from openral_mjx.benchmarks.metaworld.agreement import host_rollouts, host_workers

    rng = np.random.default_rng(0)
    for task in tasks_of(args.tasks):
        with host_workers(task, args.workers) as workers:
            calls = [
                {"rand_vec": None, "actions": rng.uniform(-1, 1, (500, 4)).astype(np.float32)}
                for _ in range(args.seeds)
            ]
            host_rollouts(workers, calls[: args.workers])  # warm: envs built, first reset
            t = time.perf_counter()
            results = host_rollouts(workers, calls)
            wall = time.perf_counter() - t
        steps = sum(len(r["actions"]) for r in results)
        emit(
            args.out,
            {
                "kind": "host-direct",
                "task": task,
                "workers": args.workers,
                "episodes": len(results),
                "episodes_per_s": len(results) / wall,
                "env_steps_per_s": steps / wall,
                "wall_s": wall,
            },
        )


def mirror_inputs(scene, actions: jax.Array) -> tuple[jax.Array, jax.Array]:
    """The mocap targets and gripper controls the scene derives from `actions` (T, 4), from
    its reset mocap position: what the raw ceiling replays."""
    low, high = scene._mocap_box
    start = scene._mocap_start[scene._mocap_id]

    def step(pos, a):
        a = jnp.clip(a, -1.0, 1.0)
        pos = jnp.clip(pos + a[:3] * mw.ACTION_SCALE, low, high)
        return pos, (pos, jnp.stack([a[3], -a[3]]))

    return jax.lax.scan(step, start, actions)[1]


def raw_start(scene, seeds: jax.Array) -> tuple[Any, Any]:
    """Each seed's reset physics as the evaluator resets it: (MJX data, per-env fields)."""
    from openral_mjx.runner.episode import seed_keys

    physics = jax.vmap(lambda s, k: scene.reset_with_seed(s, k).physics)
    data_fields = jax.jit(lambda s, k: (lambda p: (p.data, p.fields))(physics(s, k)))
    return data_fields(seeds, seed_keys(seeds)[0])


def raw_control_step(scene, mx) -> Callable[[Any, tuple[jax.Array, jax.Array]], Any]:
    """One control step of the bare loop on model `mx`: the mocap target and gripper control
    `(pos, ctrl)` (from `mirror_inputs`) set as the scene sets them, then `FRAME_SKIP` plain
    `mjx.step`s."""
    from openral_mjx.physics.mjx_backend import mjx

    mid = scene._mocap_id
    quat = np.asarray(mw.MOCAP_QUAT) / np.linalg.norm(mw.MOCAP_QUAT)
    q = jnp.asarray(quat, jnp.float32)

    def step(d, inputs):
        pos, c = inputs
        d = d.replace(
            ctrl=c,
            mocap_pos=d.mocap_pos.at[mid].set(pos),
            mocap_quat=d.mocap_quat.at[mid].set(q),
        )
        return jax.lax.fori_loop(0, mw.FRAME_SKIP, lambda _, x: mjx.step(mx, x), d)

    return step


def raw_ceiling(
    scene, actions: np.ndarray, max_steps: int
) -> tuple[float, float, float, Callable[[], Any]]:
    """(compile s, control steps/s, the same compiled as the runner compiles (`compiler_options`),
    a second run) of a bare `vmap(scan(mjx.step))` replaying the mocap targets and gripper
    controls of `actions` (n, T, 4) from the same reset states."""
    n = actions.shape[0]
    data, fields = raw_start(scene, jnp.arange(n))
    mocap, ctrl = jax.jit(jax.vmap(lambda a: mirror_inputs(scene, a)))(jnp.asarray(actions))

    def one(d, fields, mocap_seq, ctrl_seq):
        # this env's fixed bodies, as the evaluator has them
        step = raw_control_step(scene, scene.backend.model(fields))
        return jax.lax.scan(lambda d, x: (step(d, x), None), d, (mocap_seq, ctrl_seq))[0].qpos

    lowered = jax.jit(jax.vmap(one)).lower(data, fields, mocap, ctrl)
    t = time.perf_counter()
    compiled = lowered.compile()
    compile_s = time.perf_counter() - t
    again = lambda: jax.block_until_ready(compiled(data, fields, mocap, ctrl))  # noqa: E731
    t = time.perf_counter()
    again()
    rate = n * max_steps / (time.perf_counter() - t)
    # the same program as the runner compiles its own (without XLA's GPU autotuner), side by side
    untuned = lowered.compile(compiler_options=compiler_options(jax.devices()[0]))
    t = time.perf_counter()
    jax.block_until_ready(untuned(data, fields, mocap, ctrl))
    return compile_s, rate, n * max_steps / (time.perf_counter() - t), again


def raw(args: argparse.Namespace) -> None:
    for task in tasks_of(args.tasks):
        for n in args.n:
            scene = build_scene("metaworld_mjx", {"task": task}, backend=args.backend, n_envs=n)
            policy = mlp(scene)
            evaluate = functools.partial(
                run_seeds,
                scene,
                policy,
                policy.init(None, None)[0],
                seeds=np.arange(n),
                n_envs=n,
                max_steps=args.max_steps,
            )
            # the actions for the raw loop to replay, then the evaluator as users run it (no
            # per-step trace: recording the actions costs a write per step)
            arrays, recording = evaluate(record=("actions",))
            _, timing = evaluate()
            evaluator = n * args.max_steps / timing.run_s
            recorded = n * args.max_steps / recording.run_s
            raw_compile, ceiling, untuned, again = raw_ceiling(
                scene, arrays["actions"], args.max_steps
            )
            profile = {}
            if args.profile is not None:  # second runs, traced: kernel time by kind
                where = args.profile / f"{task}_{n}"
                with jax.profiler.trace(where / "evaluator", create_perfetto_trace=True):
                    evaluate()
                with jax.profiler.trace(where / "raw", create_perfetto_trace=True):
                    again()
                profile = {k: kernel_summary(where / k) for k in ("evaluator", "raw")}
            emit(
                args.out,
                {
                    "kind": "raw",
                    "poses_after_step": POSES["after_step"],
                    "warp_graph": GRAPH["mode"],
                    "policy_layers": LAYERS["way"],
                    "task": task,
                    "backend": args.backend,
                    "device": str(jax.devices()[0].device_kind),
                    "n": n,
                    "max_steps": args.max_steps,
                    "evaluator_steps_per_s": evaluator,
                    "raw_steps_per_s": ceiling,
                    "evaluator_over_raw": evaluator / ceiling,
                    "evaluator_recording_actions_steps_per_s": recorded,
                    "raw_runner_options_steps_per_s": untuned,
                    "evaluator_compile_s": timing.compile_s,
                    "raw_compile_s": raw_compile,
                    **({"profile": profile} if profile else {}),
                },
            )
            scene.close()


def mjx_peak(args: argparse.Namespace) -> None:
    """Per task: the episode compiled for `--seeds` envs on this process's share of the GPU
    (`--share` processes at once, as a suite's task processes plan), the batch that fits it,
    XLA's estimate of the episode's memory at that batch, the allocator's peak, and
    `--max-steps` steps of every seed run in batches of that size."""
    share_devices(args.share)
    for task in tasks_of(args.tasks):
        t = time.perf_counter()
        scene = build_scene("metaworld_mjx", {"task": task}, backend=args.backend)
        policy = mlp(scene)
        arrays, timing = run_seeds(
            scene,
            policy,
            policy.init(None, None)[0],
            seeds=np.arange(args.seeds),
            n_envs=args.seeds,
            max_steps=args.max_steps,
        )
        emit(
            args.out,
            {
                "kind": "mjx-peak",
                "task": task,
                "backend": args.backend,
                "device": str(jax.devices()[0].device_kind),
                "share": args.share,
                "requested_envs": args.seeds,
                "fitted_envs": timing.n_envs,
                "estimate_bytes": timing.bytes_per_device,
                "bytes_per_env": (timing.bytes_per_device or 0) / timing.n_envs,
                "peak_bytes_in_use": (jax.devices()[0].memory_stats() or {}).get(
                    "peak_bytes_in_use"
                ),
                "compile_s": timing.compile_s,
                "run_s": timing.run_s,
                "diverged": int(np.sum(arrays["diverged"])),
                "wall_s": time.perf_counter() - t,
            },
        )
        scene.close()


def mjx_check(args: argparse.Namespace) -> None:
    """Per task: the mirror built on `mjx` and on `c`, reset from the same random vectors of
    seeds 0..`--seeds`-1 and stepped `--max-steps` control steps with the same uniform random
    actions; the largest observation difference at reset and over the steps, and the compile
    times (MJX's collision of MetaWorld's meshes is the slow part)."""
    for task in tasks_of(args.tasks):
        seeds = np.arange(args.seeds)
        scenes = {b: build_scene("metaworld_mjx", {"task": task}, backend=b) for b in ("c", "mjx")}
        vecs = np.asarray(
            jax.jit(jax.vmap(scenes["c"].reset_with_seed))(seeds, seed_keys(seeds)[0]).info["vec"]
        )
        key = jax.random.PRNGKey(7)
        actions = jax.random.uniform(key, (args.max_steps, len(seeds), 4), minval=-1, maxval=1)
        obs, times, oks = {}, {}, {}
        for name, scene in scenes.items():
            t = time.perf_counter()
            reset = jax.jit(jax.vmap(scene.reset_from)).lower(vecs).compile()
            step = jax.jit(jax.vmap(scene.step)).lower(reset(vecs), actions[0]).compile()
            times[name] = time.perf_counter() - t
            state = reset(vecs)
            seq = [np.asarray(state.obs)]
            for a in actions:
                state = step(state, a)
                seq.append(np.asarray(state.obs))
            obs[name] = np.stack(seq, axis=1)  # (seeds, steps + 1, 39)
            oks[name] = float(np.mean(np.asarray(state.physics.quantities.ok)))
        diff = np.abs(obs["mjx"] - obs["c"])
        emit(
            args.out,
            {
                "kind": "mjx-check",
                "task": task,
                "seeds": len(seeds),
                "steps": args.max_steps,
                "reset_obs_max": float(diff[:, 0].max()),
                "steps_obs_max": float(diff[:, 1:].max()),
                # which of the 39 observation entries differs most, at reset and over the steps
                "reset_worst_index": int(diff[:, 0].max(axis=0).argmax()),
                "steps_worst_index": int(diff[:, 1:].max(axis=(0, 1)).argmax()),
                "hand_max_m": float(np.linalg.norm(diff[:, :, :3], axis=-1).max()),
                "finite": bool(np.isfinite(obs["mjx"]).all()),
                "mjx_ok": oks["mjx"],  # fraction not flagged (non-finite, contact cap)
                "mjx_compile_s": times["mjx"],
                "c_compile_s": times["c"],
                "mjx_changes": scenes["mjx"].mjx_changes,
            },
        )
        for scene in scenes.values():
            scene.close()


def mjx_forward(args: argparse.Namespace) -> None:
    """Per task, one `mjx.forward` of the mirror's mjx model (one env at its default state,
    jitted; the second call timed), with MJX's static contact slots and constraint rows; with
    `--max-contact-points K`, MJX's cap (the K deepest contacts per condim) set to K in place of
    the mirror's (-1: no cap)."""
    from mujoco import mjx

    for task in tasks_of(args.tasks):
        scene = build_scene("metaworld_mjx", {"task": task}, backend="mjx", n_envs=1)
        spec = scene.spec.copy()
        if args.max_contact_points is not None:
            (cap,) = [n for n in spec.numerics if n.name == "max_contact_points"]
            cap.data = [args.max_contact_points]
        m = spec.compile()
        mx, d = mjx.put_model(m, impl="jax"), mjx.make_data(m, impl="jax")
        d = jax.jit(mjx.kinematics)(mx, d)
        t = time.perf_counter()
        forward = jax.jit(mjx.forward).lower(mx, d).compile()
        compile_s = time.perf_counter() - t
        jax.block_until_ready(forward(mx, d))
        t = time.perf_counter()
        jax.block_until_ready(forward(mx, d))
        emit(
            args.out,
            {
                "kind": "mjx-forward",
                "task": task,
                "device": str(jax.devices()[0].device_kind),
                "max_contact_points": int(m.numeric_data[m.numeric("max_contact_points").id]),
                "contact_slots": int(d._impl.contact.dist.shape[0]),
                "constraint_rows": int(d._impl.efc_J.shape[0]),
                "compile_s": compile_s,
                "forward_ms": (time.perf_counter() - t) * 1000,
            },
        )
        scene.close()


def _wait_for(path: Path, timeout_s: float = 1800.0) -> None:
    end = time.monotonic() + timeout_s
    while not path.exists():
        if time.monotonic() > end:
            raise TimeoutError(f"no {path} after {timeout_s:.0f} s")
        time.sleep(0.005)


def child(args: argparse.Namespace) -> None:
    """One task of `concurrent`: compile and warm up, then a timed run when told to, alone
    (`go-solo-I`) and then with the others (`go-all`); (start, end) wall clocks to `DIR`."""
    from openral_mjx.runner.seeds import make_runner

    sync, i, task = args.sync, args.index, args.tasks[0]
    scene = build_scene("metaworld_mjx", {"task": task}, backend=args.backend, n_envs=args.seeds)
    policy = mlp(scene)
    runner = make_runner(scene, policy, n_envs=args.seeds, max_steps=args.max_steps)
    params, seeds = policy.init(None, None)[0], np.arange(args.seeds)
    runner.run(params, seeds)  # compile and one untimed run
    (sync / f"ready-{i}").touch()
    for phase in (f"solo-{i}", "all"):
        _wait_for(sync / f"go-{phase}")
        t0 = time.time()
        arrays, _ = runner.run(params, seeds)
        t1 = time.time()
        diverged = int(np.asarray(arrays["diverged"]).sum())
        device = str(jax.devices()[0].device_kind)
        row = {"task": task, "device": device, "t0": t0, "t1": t1, "diverged": diverged}
        (sync / f"{phase.split('-')[0]}-{i}.json").write_text(json.dumps(row))
    scene.close()


def concurrent(args: argparse.Namespace) -> None:
    import subprocess
    import tempfile

    tasks = tasks_of(args.tasks)
    with tempfile.TemporaryDirectory() as d:
        sync = Path(d)
        procs = [
            subprocess.Popen(
                [
                    sys.executable,
                    __file__,
                    "child",
                    "--tasks",
                    task,
                    "--backend",
                    args.backend,
                    "--seeds",
                    str(args.seeds),
                    "--max-steps",
                    str(args.max_steps),
                    "--sync",
                    d,
                    "--index",
                    str(i),
                ]
            )
            for i, task in enumerate(tasks)
        ]
        for i in range(len(tasks)):
            _wait_for(sync / f"ready-{i}")
        for i in range(len(tasks)):
            (sync / f"go-solo-{i}").touch()
            _wait_for(sync / f"solo-{i}.json")
        (sync / "go-all").touch()
        for i in range(len(tasks)):
            _wait_for(sync / f"all-{i}.json")
        codes = [p.wait() for p in procs]
        solo = [json.loads((sync / f"solo-{i}.json").read_text()) for i in range(len(tasks))]
        both = [json.loads((sync / f"all-{i}.json").read_text()) for i in range(len(tasks))]
    episodes = len(tasks) * args.seeds
    solo_s = sum(r["t1"] - r["t0"] for r in solo)
    all_s = max(r["t1"] for r in both) - min(r["t0"] for r in both)
    emit(
        args.out,
        {
            "kind": "concurrent",
            "backend": args.backend,
            "device": both[0]["device"],  # from a child: this process never touches the GPU
            "mps": mps_running(),
            "tasks": tasks,
            "seeds_per_task": args.seeds,
            "max_steps": args.max_steps,
            "one_at_a_time_episodes_per_s": episodes / solo_s,
            "all_at_once_episodes_per_s": episodes / all_s,
            "speedup": solo_s / all_s,
            "solo_run_s": [r["t1"] - r["t0"] for r in solo],
            "together_run_s": [r["t1"] - r["t0"] for r in both],
            "diverged": [r["diverged"] for r in both],
            "exit_codes": codes,
        },
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "what",
        choices=(
            "mirror",
            "host",
            "host-direct",
            "raw",
            "concurrent",
            "child",
            "save-mlp",
            "mjx-check",
            "mjx-forward",
            "mjx-peak",
        ),
    )
    parser.add_argument("--tasks", nargs="+", default=["mt10"])
    parser.add_argument("--backend", default="warp")
    parser.add_argument("--seeds", type=int, default=1000)
    parser.add_argument("--workers", type=int, default=16)
    parser.add_argument("--n", type=int, nargs="+", default=[4096, 65536])
    parser.add_argument("--max-steps", type=int, default=500)
    parser.add_argument("--out", type=Path)
    parser.add_argument("--no-cache", action="store_true", help="JAX's compilation cache off")
    parser.add_argument("--sync", type=Path, help=argparse.SUPPRESS)  # `child` only
    parser.add_argument("--index", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--poses-before-step", action="store_true", help="see module doc")
    parser.add_argument("--share", type=int, default=1, help="`mjx-peak`: processes at once")
    parser.add_argument(
        "--profile",
        type=Path,
        help="`raw`: trace a second run of each under jax.profiler into this folder and add "
        "GPU kernel time by kind (MuJoCo-Warp's, XLA's, copies) to the row",
    )
    parser.add_argument(
        "--max-contact-points", type=int, help="`mjx-forward`: MJX's cap instead of the mirror's"
    )
    parser.add_argument("--layers-as-loop", action="store_true", help="see module doc")
    parser.add_argument(
        "--warp-graph",
        choices=("WARP", "JAX", "NONE", "WARP_STAGED", "WARP_STAGED_EX"),
        help="MuJoCo-Warp's CUDA graph capture mode (`raw`; default: MJX's, WARP on a GPU)",
    )
    args = parser.parse_args()
    if args.poses_before_step:
        observe_poses_before_step()
    if args.warp_graph:
        use_warp_graph_mode(args.warp_graph)
    if args.layers_as_loop:
        fixed_order.rows_matmul = fixed_order.loop_rows
        LAYERS["way"] = "loop"
    if not args.no_cache:
        enable_compilation_cache()  # as the CLIs do: a repeated run loads its executables
    print(" ".join(["python", *sys.argv]), flush=True)
    modes = {"mirror": mirror, "host": host, "host-direct": host_direct, "raw": raw}
    modes |= {"concurrent": concurrent, "child": child, "save-mlp": save_random_mlp}
    modes |= {"mjx-check": mjx_check, "mjx-forward": mjx_forward, "mjx-peak": mjx_peak}
    modes[args.what](args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
