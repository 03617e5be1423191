"""The 16 seeds of libero_10/0 that diverged on warp (H200, 256 contacts per env, 2026-12-01),
again on warp's CPU mode with 512 contacts per env."""
import json, sys
import numpy as np
from openral_mjx.benchmarks.libero.mirror import LiberoMjx
from openral_mjx.policies import make_policy
from openral_mjx.runner import run_seeds
from openral_mjx.scenes import scene_options, scene_settings

SEEDS = [int(s) for s in sys.argv[2:]]
cap = int(sys.argv[1])
opts = scene_options("libero_mjx", {"task": "libero_10/0", "protocol": "sampled", "sampled_states": 200})
scene = LiberoMjx(opts, backend="warp", settings=scene_settings("libero_mjx", cap, batch_size=len(SEEDS)))
policy = make_policy("libero-expert", scene)
arrays, timing = run_seeds(scene, policy, None, seeds=np.array(SEEDS), n_envs=len(SEEDS), max_steps=270)
rows = {s: {k: np.asarray(arrays[k])[i].item() for k in ("success", "first_success_step", "diverged", "overflowed")} for i, s in enumerate(SEEDS)}
json.dump(rows, open(f"/tmp/div/seeds_{cap}_{SEEDS[0]}.json", "w"), indent=1)
print(json.dumps(rows))
