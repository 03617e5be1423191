"""How long a LIBERO mirror task takes to build (`make_scene`) and to trace its first reset
with the render (`observation_spec`), in this process: run it once per tree to compare trees.

    PYTHONPATH=TREE python benchmarks/libero_build_time.py --task libero_object/0 --backend warp
"""

from __future__ import annotations

import argparse
import time

import openral_mjx
from openral_mjx.physics import PhysicsSettings
from openral_mjx.scenes import make_scene


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--task", default="libero_object/0")
    parser.add_argument("--backend", default="warp")
    parser.add_argument("--image-size", type=int, default=128, help="0: no cameras")
    parser.add_argument("--n-envs", type=int, default=50)
    args = parser.parse_args()
    options = {"task": args.task, **({"image_size": args.image_size} if args.image_size else {})}
    start = time.perf_counter()
    settings = PhysicsSettings(batch_size=args.n_envs)
    scene = make_scene("libero_mjx", options, backend=args.backend, settings=settings)
    built = time.perf_counter()
    scene.observation_spec  # noqa: B018 - the first trace of a reset with its render
    traced = time.perf_counter()
    print(
        f"{openral_mjx.__file__} {args.task} {args.backend}: build {built - start:.2f} s, "
        f"observation_spec {traced - built:.2f} s"
    )


if __name__ == "__main__":
    main()
