"""Reference for the host adapter's overhead: N envs stepped from a plain Python loop.

Run with a worker environment's interpreter (``PYTHONPATH`` holding this package), e.g. by
`benchmarks/host_overhead.py`. Builds N envs (untimed), then times resetting all N and
stepping each `steps` times with uniform random actions (in `--bounds`), one env after
another, exactly the work one adapter worker does for N envs. Prints JSON. With `--barrier DIR
--procs K` (K such loops run side by side, as K adapter workers), each starts its clock only
once all K have built their envs; `--seed0` offsets its seeds.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import time
from pathlib import Path

import numpy as np


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--factory", required=True)
    p.add_argument("--kwargs", default="{}")
    p.add_argument("--n", type=int, default=4)
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--action-size", type=int, default=7)
    p.add_argument("--resets", type=int, default=1, help="resets of every env (the adapter's)")
    p.add_argument("--bounds", default=None, help="JSON [low, high] of the actions (default +-1)")
    p.add_argument("--seed0", type=int, default=0, help="first seed (env i gets seed0 + i)")
    p.add_argument("--barrier", type=Path, help="folder where K side-by-side loops meet")
    p.add_argument("--procs", type=int, default=1, help="loops meeting at --barrier")
    a = p.parse_args()
    module, _, attr = a.factory.partition(":")
    make = getattr(importlib.import_module(module), attr)
    envs = [make(**json.loads(a.kwargs)) for _ in range(a.n)]
    rng = np.random.default_rng(0)
    low, high = (
        json.loads(a.bounds) if a.bounds else ([-1.0] * a.action_size, [1.0] * a.action_size)
    )
    if a.barrier:  # start together with the other loops, once all have built their envs
        (a.barrier / f"ready.{os.getpid()}").touch()
        while len(list(a.barrier.glob("ready.*"))) < a.procs:
            time.sleep(0.01)
    start = time.perf_counter()
    for i, env in enumerate(envs, a.seed0):
        env.reset(seed=i, options={"init_state": i})
    reset_s = time.perf_counter() - start
    for _ in range(a.steps):
        for env in envs:
            env.step(rng.uniform(low, high).astype(np.float32))
    for _ in range(a.resets - 1):  # e.g. the reset that reads a scene's episode factors
        for i, env in enumerate(envs, a.seed0):
            env.reset(seed=i, options={"init_state": i})
    total_s = time.perf_counter() - start
    print(json.dumps({"n": a.n, "steps": a.steps, "reset_s": reset_s, "total_s": total_s}))


if __name__ == "__main__":
    main()
