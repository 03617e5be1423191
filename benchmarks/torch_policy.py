"""Torch policies on the GPU path against a JAX MLP fused in the episode (issue 21).

    python benchmarks/torch_policy.py --backend warp --n 1024 4096 --act-n 1024 \\
        --out results/torch_policy.json

Side by side in one process, `tabletop_push`, env-steps/s at each N:
  (a) `jax`: a flax MLP (`policies.mlp`, 3 x 256 SiLU, random weights) traced into the episode;
  (b) `torch`: the same layer sizes in torch, in process (`--policy torch:...`: one
      `buffer_callback` per control step, JAX's buffers read and written by DLPack);
  (c) `server`: the same torch MLP (same seed, same weights) in a worker process behind the
      evaluator's worker pipe, one `pure_callback` per step: what `lerobot:` costs where
      lerobot cannot run in the evaluator's process.
With `--act-n`, a random-weight lerobot ACT at lerobot's default sizes (ResNet-18, 512-wide
transformer, chunks of 100) on two 128 x 128 RGB cameras (`overhead`, `front`, drawn by the
Warp renderer: `warp` only) and the joint state, `--policy lerobot:...` in process and through
the lerobot server (`OPENRAL_MJX_LEROBOT`), for `--act-steps` control steps.
Each measurement: one chunk of N seeds, one untimed run first (compilation), then the median
of `--repeats` timed runs. A self-check first: inside `jit`, the torch module must read JAX's
own buffer (same address) and write its actions back. Prints a table; JSON to `--out`.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import stat
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from openral_mjx.evaluation import build_scene, run_evaluation
from openral_mjx.host.pool import Worker, host_callback
from openral_mjx.policies.base import Policy, host_step_policy, pure_step_call
from openral_mjx.policies.mlp import MlpConfig, init_params, mlp_policy
from openral_mjx.policies.torch_policy import torch_policy

HIDDEN = (256, 256, 256)
HERE = Path(__file__).resolve().parent


def mlp(observation_spec, action_size, device):
    """The torch twin of the flax MLP: the same layer sizes and activation, random weights
    (seed 0, so the server builds the same module)."""
    import torch
    from torch import nn

    torch.manual_seed(0)
    (n,), _ = observation_spec["obs"]
    sizes = (n, *HIDDEN)
    layers: list = []
    for a, b in itertools.pairwise(sizes):
        layers += [nn.Linear(a, b), nn.SiLU()]
    return nn.Sequential(*layers, nn.Linear(sizes[-1], action_size)).to(device).eval()


class MlpServer:
    """`mlp` in a worker: numpy observations in, numpy actions out (runs in the worker)."""

    def __init__(self, obs_size: int, action_size: int, device: str) -> None:
        import torch

        self.torch, self.device = torch, device
        self.module = mlp({"obs": ((obs_size,), "float32")}, action_size, device)

    def act(self, obs: np.ndarray) -> np.ndarray:
        torch = self.torch
        with torch.inference_mode():
            x = torch.from_numpy(np.ascontiguousarray(obs)).to(self.device)
            return self.module(x).to("cpu", torch.float32).numpy()


def worker_python(tmp: Path) -> str:
    """An interpreter for workers: this one, with this script's folder and this process's
    PYTHONPATH before the worker's own (the evaluator's shim)."""
    path = os.pathsep.join([str(HERE), *filter(None, [os.environ.get("PYTHONPATH")])])
    script = tmp / "python"
    script.write_text(
        f'#!/bin/sh\nexport PYTHONPATH={path}:"$PYTHONPATH"\nexec {sys.executable} "$@"\n'
    )
    script.chmod(script.stat().st_mode | stat.S_IEXEC)
    return str(script)


def server_policy(scene, python: str, device: str, tmp: Path) -> Policy:
    """(c): the torch MLP behind the worker pipe, one batched `pure_callback` per step."""
    size, action_size = int(np.prod(scene.observation_spec.shape)), int(scene.action_size)
    worker = Worker(python, None, tmp / "mlp_server.log", name="torch mlp server")
    worker.call(
        {
            "op": "init",
            "factory": "torch_policy:MlpServer",
            "kwargs": {"obs_size": size, "action_size": action_size, "device": device},
        },
        300.0,
    )

    @host_callback
    def call(arrays, t):
        lead = np.shape(t)
        start = time.perf_counter()
        action = worker.call(
            {
                "op": "call",
                "method": "act",
                "kwargs": {"obs": np.asarray(arrays["obs"]).reshape(-1, size)},
            },
            300.0,
        )
        ms = 1000 * (time.perf_counter() - start)
        return (
            np.asarray(action, np.float32).reshape(*lead, action_size),
            np.full(lead, ms, np.float32),
        )

    return host_step_policy(
        "torch-mlp-server",
        pure_step_call(call, action_size),
        lambda obs: {"obs": obs},
        close=worker.close,
    )


def self_check(torch: Any) -> dict:
    """Inside `jit` on JAX's default device: the module's input is JAX's buffer (same
    address) and its actions come back."""
    from openral_mjx.policies.torch_bridge import TorchBridge, bridge_policy

    seen: dict[str, Any] = {}

    def run(inputs, steps):
        x = inputs["obs"]
        seen["ptr"], seen["device"] = x.data_ptr(), str(x.device)
        return x[:, :2] * 2

    bridge = TorchBridge(torch, run, {"obs": (4,)}, 2)
    policy = bridge_policy("check", bridge, lambda obs: {"obs": obs})
    obs = jnp.arange(4096 * 4, dtype=jnp.float32).reshape(4096, 4)
    params, pstate = policy.init(jax.random.PRNGKey(0), None)
    pstate = jax.tree.map(lambda x: jnp.broadcast_to(x, (4096, *x.shape)), pstate)
    act = jax.jit(jax.vmap(policy.act, in_axes=(None, 0, 0, None)))
    action, _ = act(params, pstate, obs, jax.random.PRNGKey(0))
    ok = bool(np.array_equal(np.asarray(action), 2 * np.asarray(obs)[:, :2]))
    shared = seen["ptr"] == obs.unsafe_buffer_pointer()
    return {"actions_equal": ok, "same_buffer": shared, "torch_device": seen["device"]}


def timed(scene, policy, n: int, repeats: int, max_steps: int | None = None) -> dict:
    runs, compile_s, latency = [], 0.0, []
    for i in range(repeats + 1):
        with run_evaluation(
            scene, policy, n_envs=n, n_episodes=n, batching="chunks", max_steps=max_steps
        ) as ev:
            if i:  # the first run compiles
                runs.append(ev.report.env_steps_per_s)
                latency.append(float(np.mean([e.mean_step_latency_ms for e in ev.report.episodes])))
            else:
                compile_s = ev.report.compile_s
    return {
        "env_steps_per_s": statistics.median(runs),
        "runs": runs,
        "compile_s": compile_s,
        "policy_ms_per_step": statistics.median(latency),
    }


def mlp_rows(args, torch, device: str, python: str, tmp: Path) -> list[dict]:
    rows = []
    for n in args.n:
        scene = build_scene("tabletop_push", None, backend=args.backend, n_envs=n)
        row: dict[str, Any] = {"n_envs": n}
        if "jax" in args.paths:
            config = MlpConfig(
                obs_size=int(np.prod(scene.observation_spec.shape)),
                action_size=scene.action_size,
                action_offset=(0.0,) * scene.action_size,
                action_scale=(1.0,) * scene.action_size,
                hidden=HIDDEN,
            )
            jax_mlp = mlp_policy(config, init_params(config, jax.random.PRNGKey(0)))
            row["jax"] = timed(scene, jax_mlp, n, args.repeats)
        if "torch" in args.paths:
            row["torch"] = timed(scene, torch_policy(scene, f"{__file__}:mlp"), n, args.repeats)
        if "server" in args.paths:
            policy = server_policy(scene, python, device, tmp)
            try:
                row["server"] = timed(scene, policy, n, args.repeats)
            finally:
                policy.close()
        for k in ("torch", "server"):
            if k in row and "jax" in row:
                row[k]["vs_jax"] = row[k]["env_steps_per_s"] / row["jax"]["env_steps_per_s"]
        print(
            f"N={n:,}: "
            + ", ".join(
                f"{k} {row[k]['env_steps_per_s']:,.0f} env-steps/s"
                for k in ("jax", "torch", "server")
                if k in row
            ),
            flush=True,
        )
        rows.append(row)
        scene.close()
    return rows


def act_rows(args, python: str, tmp: Path) -> dict:
    from openral_mjx.host.lerobot_server import build_random_policy

    options = {"obs_rgb_cameras": ["overhead", "front"], "obs_rgb_size": [128, 128]}
    scene = build_scene("tabletop_push", options, backend=args.backend, n_envs=args.act_n)
    from openral_mjx.policies.lerobot import scene_arrays

    state = int(scene_arrays(scene)["obs"].shape[0])
    path = tmp / "act"
    features = {
        "observation.images.overhead": [3, 128, 128],
        "observation.images.front": [3, 128, 128],
        "observation.state": [state],
    }
    build_random_policy("act", str(path), features, int(scene.action_size), size="default")
    out: dict[str, Any] = {"n_envs": args.act_n, "max_steps": args.act_steps}
    os.environ["OPENRAL_MJX_PYTHON_LEROBOT_LIBERO"] = python
    for mode in args.act_paths:
        os.environ["OPENRAL_MJX_LEROBOT"] = mode
        from openral_mjx.policies.lerobot import lerobot_policy

        policy = lerobot_policy(scene, str(path))
        try:
            out[mode] = timed(scene, policy, args.act_n, args.repeats, args.act_steps)
        finally:
            if policy.close is not None:
                policy.close()
        print(
            f"ACT N={args.act_n:,} {mode}: {out[mode]['env_steps_per_s']:,.0f} env-steps/s",
            flush=True,
        )
    if "process" in out and "server" in out:
        out["process_vs_server"] = (
            out["process"]["env_steps_per_s"] / out["server"]["env_steps_per_s"]
        )
    scene.close()
    return out


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--backend", default="warp")
    parser.add_argument("--n", type=int, nargs="*", default=[1024, 4096])
    parser.add_argument("--paths", nargs="+", default=["jax", "torch", "server"])
    parser.add_argument("--act-n", type=int, default=0)
    parser.add_argument("--act-steps", type=int, default=50)
    parser.add_argument("--act-paths", nargs="+", default=["process", "server"])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("results/torch_policy.json"))
    args = parser.parse_args()
    import torch

    device = "cuda" if torch.cuda.is_available() and jax.default_backend() == "gpu" else "cpu"
    check = self_check(torch)
    print(f"self-check: {check}", flush=True)
    result: dict[str, Any] = {
        "backend": args.backend,
        "device": str(jax.devices()[0].device_kind),
        "torch": torch.__version__,
        "jax": jax.__version__,
        "torch_device": device,
        "command": " ".join(["python", *sys.argv]),
        "self_check": check,
    }
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        python = worker_python(tmp)
        result["mlp"] = mlp_rows(args, torch, device, python, tmp)
        if args.act_n:
            result["act"] = act_rows(args, python, tmp)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
