"""Run `python -m openral_mjx.eval ARGS` and print each device's peak memory afterwards.

    python benchmarks/peak_memory.py --backend warp --n-envs 65536 --n-episodes 1000000

Peak memory is the allocator's `peak_bytes_in_use` for the whole process (GPU backends only),
so it includes compilation scratch, the model and every chunk's buffers.
"""

from __future__ import annotations

import sys

import jax

from openral_mjx import eval as eval_cli


def main() -> None:
    sys.argv[0] = "python -m openral_mjx.eval"
    try:
        eval_cli.main()
    finally:
        for device in jax.local_devices():
            stats = device.memory_stats() or {}
            peak = stats.get("peak_bytes_in_use")
            shown = "n/a" if peak is None else f"{peak / 2**30:.2f} GiB"
            print(f"peak memory {device}: {shown}", flush=True)


if __name__ == "__main__":
    main()
