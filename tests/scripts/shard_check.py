"""Run in a fresh process with XLA_FLAGS=--xla_force_host_platform_device_count=4 (see
tests/runner/test_sharding.py): shard envs over 4 CPU devices and compare with one device."""

import json
import sys

import jax
import numpy as np

from openral_mjx.physics import PhysicsSettings
from openral_mjx.policies import make_policy
from openral_mjx.runner import run_seeds, trace_seeds
from openral_mjx.scenes import TabletopPush

backend = sys.argv[1]
scene = TabletopPush(backend=backend, settings=PhysicsSettings(batch_size=8))
policy = make_policy("scripted", scene)
kw = dict(seeds=np.arange(10), max_steps=int(sys.argv[2]))
devices = jax.devices()
sharded, t4 = run_seeds(scene, policy, None, n_envs=8, devices=devices, record=("actions",), **kw)
single, t1 = run_seeds(
    scene, policy, None, n_envs=8, devices=devices[:1], record=("actions",), **kw
)
# Continuous batching over 4 devices: seeds interleave over the devices' slots.
refilled, t_refill = run_seeds(
    scene, policy, None, n_envs=8, devices=devices, batching="refill", **kw
)
# Videos re-run a few seeds with every step recorded: each device adds its envs' rows.
traced = {
    n: trace_seeds(
        scene, policy, None, seeds=[3, 6], max_steps=kw["max_steps"], devices=devices[:n]
    )
    for n in (4, 1)
}
trace_equal = jax.tree.leaves(
    jax.tree.map(lambda a, b: bool(np.array_equal(a, b)), traced[4][1], traced[1][1])
)
capped_scene = TabletopPush(
    backend=backend, settings=PhysicsSettings(batch_size=8, max_devices=2)
)  # the --devices cap: the first two devices
capped, t2 = run_seeds(capped_scene, make_policy("scripted", capped_scene), None, n_envs=8, **kw)
print(
    json.dumps(
        {
            "n_devices": [t4.n_devices, t1.n_devices, t2.n_devices],
            "n_envs": [t4.n_envs, t1.n_envs],
            "chunks": [len(t4.chunk_s), len(t1.chunk_s)],
            "equal": {k: bool(np.array_equal(sharded[k], single[k])) for k in sharded},
            "capped_equal": {k: bool(np.array_equal(capped[k], single[k])) for k in capped},
            "refill_equal": {k: bool(np.array_equal(refilled[k], single[k])) for k in refilled},
            "refill_devices": t_refill.n_devices,
            "trace_equal": all(trace_equal) and len(trace_equal) > 1,
            "traced_live_steps": int(traced[4][1]["live"].sum()),
            "success": sharded["success"].tolist(),
        }
    )
)
