"""Where building a `lerobot:` policy for a LIBERO mirror task goes (issue 42): the scene built,
then `make_policy` and the policy's `init` under cProfile, the top entries by cumulative time.

    python3 benchmarks/profile_policy_build.py --policy lerobot:/tmp/act_libero
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time

import jax

from openral_mjx.evaluation.run import build_scene
from openral_mjx.policies import make_policy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--policy", required=True)
    parser.add_argument("--task", default="libero_object/0")
    parser.add_argument("--backend", default="warp")
    parser.add_argument("--top", type=int, default=45)
    args = parser.parse_args()
    t0 = time.perf_counter()
    scene = build_scene(
        "libero_mjx", {"task": args.task, "image_size": 128}, backend=args.backend, n_envs=50
    )
    print(f"scene {time.perf_counter() - t0:.1f} s")
    profile = cProfile.Profile()
    t0 = time.perf_counter()
    profile.enable()
    policy = make_policy(args.policy, scene)
    t1 = time.perf_counter()
    policy.init(jax.random.PRNGKey(0), scene.observation_spec)
    profile.disable()
    print(f"make_policy {t1 - t0:.1f} s, init {time.perf_counter() - t1:.1f} s")
    pstats.Stats(profile).sort_stats("cumulative").print_stats(args.top)


if __name__ == "__main__":
    main()
