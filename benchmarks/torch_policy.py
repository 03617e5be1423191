"""A JAX MLP fused in the jitted loop against the same MLP in torch, in process (issue 21).

    python benchmarks/torch_policy.py --backend mjx --n 1024 4096 --out results/torch.json

Per N, side by side in one process: env-steps/s of `tabletop_push` with (a) a flax MLP
(`policies.mlp`, 3 x 256 SiLU, random weights) traced into the episode, and (b) a torch MLP of
the same sizes through `--policy torch:...` on each torch device asked for (`cuda`: the
default on a GPU; `cpu`: torch on the host inside the callback). Each run is one chunk of N
seeds for the scene's episode length; one untimed run first (compilation), then the median of
`--repeats` timed runs. Prints a table and the ratio (b) / (a); JSON to `--out`.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import statistics
import sys
from pathlib import Path

import jax
import numpy as np

from openral_mjx.evaluation import build_scene, run_evaluation
from openral_mjx.policies.mlp import MlpConfig, init_params, mlp_policy
from openral_mjx.policies.torch_policy import torch_policy

HIDDEN = (256, 256, 256)


def mlp(observation_spec, action_size, device):
    """The torch twin of the flax MLP: the same layer sizes and activation, random weights."""
    from torch import nn

    (n,), _ = observation_spec["obs"]
    sizes = (n, *HIDDEN)
    layers: list = []
    for a, b in itertools.pairwise(sizes):
        layers += [nn.Linear(a, b), nn.SiLU()]
    return nn.Sequential(*layers, nn.Linear(sizes[-1], action_size)).to(device)


def timed(scene, policy, n: int, repeats: int) -> dict:
    runs, compile_s = [], 0.0
    for i in range(repeats + 1):
        with run_evaluation(scene, policy, n_envs=n, n_episodes=n, batching="chunks") as ev:
            if i:  # the first run compiles
                runs.append(ev.report.env_steps_per_s)
            else:
                compile_s = ev.report.compile_s
    return {"env_steps_per_s": statistics.median(runs), "runs": runs, "compile_s": compile_s}


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--backend", default="mjx")
    parser.add_argument("--n", type=int, nargs="+", default=[1024, 4096])
    parser.add_argument("--torch-devices", nargs="+", default=None)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("results/torch_policy.json"))
    args = parser.parse_args()
    import torch

    devices = args.torch_devices or (["cuda", "cpu"] if torch.cuda.is_available() else ["cpu"])
    rows = []
    for n in args.n:
        scene = build_scene("tabletop_push", None, backend=args.backend, n_envs=n)
        config = MlpConfig(
            obs_size=int(np.prod(scene.observation_spec.shape)),
            action_size=scene.action_size,
            action_offset=(0.0,) * scene.action_size,
            action_scale=(1.0,) * scene.action_size,
            hidden=HIDDEN,
        )
        jax_mlp = mlp_policy(config, init_params(config, jax.random.PRNGKey(0)))
        row = {"n_envs": n, "jax_mlp": timed(scene, jax_mlp, n, args.repeats)}
        print(f"N={n:,} jax mlp: {row['jax_mlp']['env_steps_per_s']:,.0f} env-steps/s", flush=True)
        for device in devices:
            os.environ["OPENRAL_MJX_TORCH_DEVICE"] = device
            policy = torch_policy(scene, f"{Path(__file__).resolve()}:mlp")
            row[f"torch_{device}"] = timed(scene, policy, n, args.repeats)
            ratio = row[f"torch_{device}"]["env_steps_per_s"] / row["jax_mlp"]["env_steps_per_s"]
            row[f"torch_{device}"]["vs_jax"] = ratio
            print(
                f"N={n:,} torch mlp on {device}: "
                f"{row[f'torch_{device}']['env_steps_per_s']:,.0f} env-steps/s ({ratio:.2f}x jax)",
                flush=True,
            )
        rows.append(row)
        scene.close()
    result = {
        "backend": args.backend,
        "device": str(jax.devices()[0].device_kind),
        "torch": torch.__version__,
        "jax": jax.__version__,
        "command": " ".join(["python", *sys.argv]),
        "rows": rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
