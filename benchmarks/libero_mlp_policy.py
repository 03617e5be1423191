"""Save a random-weight JAX MLP on LIBERO's 8-D state, as `finetune` saves a trained one.

    python benchmarks/libero_mlp_policy.py --out /tmp/mlp_libero

Issue 42's second policy for speed: a flax Gaussian MLP (three layers of 256, acting with its
mean) on the state lerobot's LIBERO env hands a policy (end-effector position, axis-angle, two
finger positions) and LIBERO's 7-D action in [-1, 1]. It runs on the mirror with the
observation reduced to that state (``--opt expert=false``, no cameras):

    python -m openral_mjx.eval --scene libero_mjx --task libero_object/0 --backend warp \\
        --n-envs 1024 --policy mlp:/tmp/mlp_libero --opt expert=false
"""

from __future__ import annotations

import argparse
from pathlib import Path

import jax

from openral_mjx.benchmarks.libero.mirror.scene import STATE_SIZE
from openral_mjx.policies.mlp import MlpConfig, init_params, save_mlp

ACTION_SIZE = 7  # OSC pose delta and the gripper, each in [-1, 1]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="the checkpoint folder to write")
    parser.add_argument("--seed", type=int, default=0, help="the weights' PRNG seed")
    args = parser.parse_args()
    config = MlpConfig(
        obs_size=STATE_SIZE,
        action_size=ACTION_SIZE,
        action_offset=(0.0,) * ACTION_SIZE,
        action_scale=(1.0,) * ACTION_SIZE,
        metadata={"scene": "libero_mjx with --opt expert=false"},
    )
    save_mlp(args.out, config, init_params(config, jax.random.PRNGKey(args.seed)))
    print(f"random-weight MLP on LIBERO's state: {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
