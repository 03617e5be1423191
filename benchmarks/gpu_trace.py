"""Where a traced run's GPU time goes: kernel time by kind from a `jax.profiler` trace.

    with jax.profiler.trace(DIR, create_perfetto_trace=True):
        ...
    summary = kernel_summary(DIR)

Kinds: `warp` (MuJoCo-Warp's physics kernels, compiled by Warp: `*_cuda_kernel_forward`),
`xla` (XLA's own kernels: fusions, reductions, copies inside the program) and `memcpy`. Busy
time is the union of the kernels' intervals on the device; span is first start to last end.
"""

from __future__ import annotations

import gzip
import json
from collections import defaultdict
from pathlib import Path
from typing import Any


def kind(name: str) -> str:
    """A GPU event's kind from its name."""
    if "cuda_kernel_forward" in name or "cuda_kernel_backward" in name:
        return "warp"
    if "memcpy" in name.lower() or "memset" in name.lower():
        return "memcpy"
    return "xla"


def _busy(intervals: list[tuple[float, float]]) -> float:
    total, end = 0.0, float("-inf")
    for a, b in sorted(intervals):
        if b > end:
            total += b - max(a, end)
            end = b
    return total


def kernel_summary(trace_dir: Path, top: int = 12) -> dict[str, Any]:
    """Kernel time (ms) and launches by kind, the `top` kernels of each kind, GPU busy time
    and span."""
    path = next(Path(trace_dir).glob("plugins/profile/*/perfetto_trace.json.gz"))
    with gzip.open(path) as f:
        data = json.load(f)
    events = data["traceEvents"] if isinstance(data, dict) else data
    gpu = {
        e["pid"]
        for e in events
        if e.get("ph") == "M"
        and e.get("name") == "process_name"
        and str(e["args"].get("name", "")).startswith("/device:GPU")
    }
    by_kind: dict[str, float] = defaultdict(float)
    by_name: dict[str, list[float]] = defaultdict(lambda: [0.0, 0])
    intervals = []
    for e in events:
        if e.get("ph") != "X" or e.get("pid") not in gpu or "dur" not in e:
            continue
        name, dur = e["name"], float(e["dur"]) / 1e3
        by_kind[kind(name)] += dur
        by_name[name][0] += dur
        by_name[name][1] += 1
        intervals.append((float(e["ts"]) / 1e3, float(e["ts"]) / 1e3 + dur))
    tops = {
        k: [
            {"name": n[:120], "ms": round(v[0], 2), "count": v[1]}
            for n, v in sorted(by_name.items(), key=lambda x: -x[1][0])
            if kind(n) == k
        ][:top]
        for k in by_kind
    }
    span = max(b for _, b in intervals) - min(a for a, _ in intervals) if intervals else 0.0
    return {
        "kernel_ms": {k: round(v, 1) for k, v in by_kind.items()},
        "launches": {k: sum(v[1] for n, v in by_name.items() if kind(n) == k) for k in by_kind},
        "busy_ms": round(_busy(intervals), 1),
        "span_ms": round(span, 1),
        "top": tops,
    }
