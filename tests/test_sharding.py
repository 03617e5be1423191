"""Envs shard over every device (a 1-D mesh over the env axis) with results identical to one
device. Runs in a subprocess because the device count is fixed when JAX starts."""

import json
import os
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).parent / "scripts" / "shard_check.py"


def test_warp_on_four_devices_equals_one_device():
    """10 seeds x 60 control steps of the scripted expert on MuJoCo-Warp (CPU mode): 4 devices
    x 2 envs against 1 device x 8 envs, chunked. Warp's per-env kernels and the fixed-order
    task logic make every seed's episode bit-identical whatever the layout; MJX's JAX
    implementation compiles its physics differently per layout (XLA's rewrites), so it is
    identical only at the same layout, and is not used here."""
    env = {
        **os.environ,
        "XLA_FLAGS": "--xla_force_host_platform_device_count=4",
        "JAX_PLATFORMS": "cpu",
    }
    proc = subprocess.run(
        [sys.executable, str(SCRIPT), "warp", "60"],
        capture_output=True,
        text=True,
        env=env,
        timeout=900,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["n_devices"] == [4, 1, 2]  # all, one, and the settings' cap of two
    assert result["n_envs"] == [8, 8] and result["chunks"] == [2, 2]
    assert all(result["equal"].values()), result["equal"]
    assert all(result["capped_equal"].values()), result["capped_equal"]
    assert any(result["success"])  # episodes long enough to differ if anything were off
