"""Does LIBERO's reset for seed s depend on what the env drew before it? (issue 37)

Seed s of the `libero` host scene and of the `libero_mjx` mirror must start from one state.
Both take LIBERO's reset with numpy seeded with s (`worker_env.LiberoEnv.start`), but in
different histories: the mirror's draws are made in blocks, seed after seed, in one worker
(`assets.load_sampled`), and each host env resets its own run of seeds. This resets seed
`--seed` in a fresh env and again right after seed 0 in another, and prints per task the
largest difference of the state (qpos, and the bodies' model poses, where LIBERO places the
fixtures) as one JSON line. Any non-zero difference means the reset carries hidden state.

Run in the lerobot-libero worker environment from the project root:

    PYTHONPATH=. ~/.cache/openral_mjx/envs/lerobot-libero/bin/python \
        benchmarks/libero_draw_history.py --tasks libero_90/0 libero_90/5 libero_10/1
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from openral_mjx.benchmarks.libero.worker_env import LiberoEnv


def reset_state(env: LiberoEnv, seed: int, sampled: bool) -> np.ndarray:
    """qpos and every body's model position after LIBERO's reset for `seed`."""
    env.start(seed, sampled=sampled)
    inner = env.env.env
    return np.concatenate([inner.sim.data._data.qpos, inner.sim.model._model.body_pos.ravel()])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", required=True, help="suite/index, e.g. libero_90/5")
    parser.add_argument("--seed", type=int, default=1, help="the seed reset in both histories")
    args = parser.parse_args()
    for task in args.tasks:
        row: dict[str, object] = {"task": task, "seed": args.seed}
        for protocol, sampled in (("sampled", True), ("standard", False)):
            fresh = reset_state(LiberoEnv(task, image_size=None), args.seed, sampled)
            after = LiberoEnv(task, image_size=None)
            reset_state(after, 0, sampled)
            row[f"{protocol}_max_abs_diff"] = float(
                np.abs(fresh - reset_state(after, args.seed, sampled)).max()
            )
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
