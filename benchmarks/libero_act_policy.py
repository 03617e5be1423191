"""Save a random-weight lerobot ACT for LIBERO's input features, as a trained one is saved.

    python benchmarks/libero_act_policy.py --out /tmp/act_libero --size 128

The features are those lerobot's LIBERO env hands a policy (``observation.images.image``:
agentview, ``observation.images.image2``: the wrist camera, both (3, SIZE, SIZE); the 8-D
``observation.state``) and the 7-D action; the sizes lerobot's defaults for ACT (ResNet-18
backbone, random too, nothing downloaded; a 512-wide transformer; chunks of 100), or a few
thousand weights with ``--small``. The folder then runs unchanged on the host scene and on
the mirror, its image size implied by its config:

    python -m openral_mjx.eval --scene libero_mjx --task libero_spatial/0 --backend c \\
        --policy lerobot:/tmp/act_libero --n-envs 16

Needs lerobot where it runs: the evaluator's own environment (the GPU machine's lerobot 0.6)
or the ``lerobot-libero`` worker environment's interpreter (with this checkout on
``PYTHONPATH``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from openral_mjx.host.lerobot_server import build_random_policy

STATE_SIZE = 8  # end-effector position, axis-angle, two finger positions
ACTION_SIZE = 7  # OSC pose delta and the gripper


def libero_features(size: int) -> dict[str, list[int]]:
    """lerobot's LIBERO input features with square cameras of side `size`."""
    return {
        "observation.images.image": [3, size, size],
        "observation.images.image2": [3, size, size],
        "observation.state": [STATE_SIZE],
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="the policy folder to write")
    parser.add_argument("--size", type=int, default=128, help="the cameras' side (pixels)")
    parser.add_argument("--small", action="store_true", help="a tiny ACT (tests), not lerobot's")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    size = "small" if args.small else "default"
    build_random_policy(
        "act", str(args.out), libero_features(args.size), ACTION_SIZE, args.seed, size
    )
    print(f"ACT ({size}) for LIBERO at {args.size} x {args.size}: {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
