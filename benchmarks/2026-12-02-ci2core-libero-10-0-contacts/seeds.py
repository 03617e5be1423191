"""Seeds of libero_10/0 on warp (its CPU mode here) with CAP contacts per env.

    python seeds.py CAP SEED...

The 16 seeds that diverged on the H200 with 256 (2026-12-01): 5 22 24 32 48 63 64 69 74 84 89
160 173 176 187 194. Writes ``seeds_CAP_FIRST.json``: per seed success, first success step,
diverged, overflowed.
"""

import json
import sys
from pathlib import Path

import numpy as np

from openral_mjx.benchmarks.libero.mirror import LiberoMjx
from openral_mjx.policies import make_policy
from openral_mjx.runner import run_seeds
from openral_mjx.scenes import scene_options, scene_settings

cap, seeds = int(sys.argv[1]), [int(s) for s in sys.argv[2:]]
options = {"task": "libero_10/0", "protocol": "sampled", "sampled_states": 200}
settings = scene_settings("libero_mjx", cap, batch_size=len(seeds))
scene = LiberoMjx(scene_options("libero_mjx", options), backend="warp", settings=settings)
policy = make_policy("libero-expert", scene)
arrays, _ = run_seeds(scene, policy, None, seeds=np.array(seeds), n_envs=len(seeds), max_steps=270)
keys = ("success", "first_success_step", "diverged", "overflowed")
rows = {s: {k: np.asarray(arrays[k])[i].item() for k in keys} for i, s in enumerate(seeds)}
Path(f"seeds_{cap}_{seeds[0]}.json").write_text(json.dumps(rows, indent=1))
print(json.dumps(rows))
