"""Where one `eval` run's time and CPU go (issue 42: sixteen LIBERO task processes keep the
CPU busy, so every process-second of CPU counts): the run in this process under cProfile,
with JAX's compile events (trace, lowering, cache retrieval, XLA) summed by function, the
process's CPU time against its wall time, and the CPU time of each of its threads by name
(XLA's, torch's and Warp's pools next to the Python thread).

    python3 benchmarks/profile_eval.py --prof-out /tmp/p.pstats -- --scene libero_mjx \\
        --task libero_object/0 --backend warp --n-envs 50 --policy lerobot:/tmp/act_libero
"""

from __future__ import annotations

import argparse
import collections
import cProfile
import os
import pstats
import runpy
import sys
import time
from pathlib import Path

import jax

CLOCK = os.sysconf("SC_CLK_TCK")


def thread_cpu() -> dict[str, float]:
    """CPU seconds (user + system) of this process's live threads, summed by thread name."""
    out: dict[str, float] = collections.defaultdict(float)
    for task in Path("/proc/self/task").iterdir():
        try:
            stat = (task / "stat").read_text()
        except OSError:  # ended meanwhile
            continue
        name = stat[stat.index("(") + 1 : stat.rindex(")")]
        fields = stat[stat.rindex(")") + 2 :].split()
        out[name] += (int(fields[11]) + int(fields[12])) / CLOCK  # utime, stime
    return dict(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--prof-out", type=Path, required=True, help="pstats file to write")
    parser.add_argument("--top", type=int, default=40)
    parser.add_argument("eval_args", nargs=argparse.REMAINDER, help="after --: eval's flags")
    args = parser.parse_args()
    eval_args = args.eval_args[1:] if args.eval_args[:1] == ["--"] else args.eval_args

    events: dict[tuple[str, str], float] = collections.defaultdict(float)

    def on_event(event: str, seconds: float, **kw: object) -> None:
        events[(event.rsplit("/", 1)[-1], str(kw.get("fun_name", "")))] += seconds

    jax.monitoring.register_event_duration_secs_listener(on_event)
    sys.argv = ["openral_mjx.eval", *eval_args]
    profile = cProfile.Profile()
    wall0, cpu0 = time.perf_counter(), time.process_time()
    profile.enable()
    try:
        runpy.run_module("openral_mjx.eval", run_name="__main__")
    except SystemExit as e:
        print(f"eval exited with {e.code}")
    finally:
        profile.disable()
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        profile.dump_stats(args.prof_out)
        print(f"\nwall {wall:.1f} s, process CPU {cpu:.1f} s ({cpu / wall:.2f} cores)")
        print("CPU by thread name (s):")
        for name, seconds in sorted(thread_cpu().items(), key=lambda kv: -kv[1])[:12]:
            print(f"  {seconds:8.1f}  {name}")
        print("JAX compile events (s), by function:")
        for (event, fun), seconds in sorted(events.items(), key=lambda kv: -kv[1])[:20]:
            print(f"  {seconds:8.2f}  {event}  {fun}")
        stats = pstats.Stats(profile)
        stats.sort_stats("tottime").print_stats(args.top)
        stats.sort_stats("cumulative").print_stats(args.top)


if __name__ == "__main__":
    main()
