"""The LIBERO mirror against LIBERO itself.

- `libero_reference`: LIBERO's env for a task in a worker process, to replay actions from an
  initial state and to judge states by its own goal predicates (the tests' oracle).
- `agreement_table`: `libero-expert` closed loop on the same seeds of each task, on the mirror
  (`libero_mjx`, any backend) and on LIBERO through the host adapter, as a user would run
  them, compared seed by seed (`compare_reports`): both rates with their intervals, per-seed
  agreement, exact McNemar, and the median difference in steps to success.

``python -m openral_mjx.benchmarks.libero.agreement --tasks libero_object/0 --seeds 200``
prints the table (markdown) and writes it as JSON with ``--out``; ``--protocol sampled`` runs
the mass-seed protocol's draws, ``--reports DIR`` keeps both reports of each task.
``--from-reports DIR/*.json`` runs nothing: the table of stored reports (`rows_from_reports`).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from openral_mjx.benchmarks.libero.assets import TIMEOUT_S, task_worker
from openral_mjx.benchmarks.libero.expert import coverage
from openral_mjx.benchmarks.libero.host_scene import SUITES
from openral_mjx.core.errors import ConfigError
from openral_mjx.core.files import write_text_atomic
from openral_mjx.evaluation import evaluate
from openral_mjx.host.pool import Worker
from openral_mjx.report import EvalReport, load_report, save_report
from openral_mjx.scenes import seed_cycles, seed_options
from openral_mjx.stats import compare_reports


class LiberoReference:
    """LIBERO's env for one task, in a worker (`openral_mjx.benchmarks.libero.export`)."""

    def __init__(self, worker: Worker) -> None:
        self.worker = worker

    def _call(self, method: str, **kwargs: Any) -> Any:
        return self.worker.call({"op": "call", "method": method, "kwargs": kwargs}, TIMEOUT_S)

    def rollout(
        self, init: int, actions: np.ndarray, sampled: bool = False
    ) -> dict[str, np.ndarray]:
        """Initial state `init` (`sampled`: the mass-seed protocol's draw for seed `init`),
        LIBERO's settle, then `actions`: per step 0..T the joint positions and velocities,
        lerobot's state and the goal."""
        actions = np.asarray(actions, np.float64)
        return self._call("rollout", init=int(init), actions=actions, sampled=sampled)

    def drawn_state(self, seed: int) -> dict[str, np.ndarray]:
        """LIBERO's full reset for seed `seed` of the mass-seed protocol, before the settle:
        the flattened state and every body's pose (`TaskExport.drawn_state`)."""
        return self._call("drawn_state", seed=int(seed))

    def body_poses(self, init: int, sampled: bool = False) -> dict[str, np.ndarray]:
        """Every body's `body_pos` and `body_quat` after LIBERO's reset to initial state
        `init` (`sampled`: the mass-seed protocol's draw for seed `init`; LIBERO's body
        order)."""
        return self._call("body_poses", init=int(init), sampled=sampled)

    def check_success(self, states: np.ndarray) -> np.ndarray:
        """LIBERO's goal at each flattened ``[time, qpos, qvel]`` state."""
        return np.asarray(self._call("check_success", states=np.asarray(states, np.float64)))


@contextlib.contextmanager
def libero_reference(task: str) -> Iterator[LiberoReference]:
    """LIBERO's env for `task` (``suite/index``) in a worker, closed on exit."""
    with task_worker(task) as (worker, _):
        yield LiberoReference(worker)


def agreement_row(
    task: str,
    seeds: int,
    backend: str = "c",
    host_envs: int = 8,
    protocol: str = "standard",
    mirror_envs: int | None = None,
    contacts_per_env: int | None = None,
) -> tuple[dict[str, Any], EvalReport, EvalReport]:
    """`libero-expert` on seeds 0..seeds-1 of `task` on the mirror and on LIBERO: the table's
    row, and the two reports (LIBERO's first).

    `protocol` ``sampled`` starts seed s from LIBERO's own draw for seed s on both scenes,
    with as many draws as seeds (``sampled_states``: seed s < seeds is the same state under
    any larger count, and `compare` pairs these reports with runs of more draws on their first
    `seeds` seeds). LIBERO runs
    without its renderer: the expert reads the state, and the episodes are the same."""
    scene_options: dict[str, Any] = {"task": task, "protocol": protocol}
    if protocol == "sampled":
        scene_options["sampled_states"] = seeds
    mirror = evaluate(
        "libero_mjx",
        "libero-expert",
        n_envs=min(mirror_envs or seeds, seeds),
        contacts_per_env=contacts_per_env,
        n_episodes=seeds,
        backend=backend,
        options=scene_options,
    )
    host = evaluate(
        "libero",
        "libero-expert",
        n_envs=min(host_envs, seeds),
        n_episodes=seeds,
        options={**scene_options, "image_size": None},
    )
    return comparison_row(host, mirror), host, mirror


def comparison_row(host: EvalReport, mirror: EvalReport) -> dict[str, Any]:
    """The agreement table's row of a LIBERO report against a mirror report of one task,
    paired seed by seed (`compare_reports`; seeds below both draw counts where those differ)."""
    rc = compare_reports(
        host,
        mirror,
        mirrored=True,
        seed_options=seed_options(host.scene, mirror.scene),
        seed_cycles=seed_cycles(host.scene, mirror.scene),
    )
    c = rc.comparison
    return {
        "task": mirror.task,
        "coverage": coverage(mirror.task),
        "backend": mirror.backend,
        "mujoco": mirror.versions.get("mujoco"),
        "seeds": rc.common_seeds,
        "libero_rate": host.success_rate,
        "libero_ci": [host.ci_low, host.ci_high],
        "mirror_rate": mirror.success_rate,
        "mirror_ci": [mirror.ci_low, mirror.ci_high],
        "agreement": (c.both + c.neither) / rc.common_seeds,
        "only_libero": c.only_a,
        "only_mirror": c.only_b,
        "mcnemar_p": c.p_value,
        "both_succeeded": rc.both_succeeded,
        "steps_median_difference": rc.steps_median_difference,
        "mirror_diverged": mirror.diverged,
    }


def rows_from_reports(paths: Sequence[Path]) -> list[dict[str, Any]]:
    """The table's rows from stored reports (`--reports` folders, `eval --out` files): each
    `libero_mjx` report against the latest `libero` report of its task it pairs with, in the
    suites' order. A mirror report with no such LIBERO report is a `ConfigError`."""
    reports = [load_report(p) for p in paths]
    hosts = sorted((r for r in reports if r.scene == "libero"), key=lambda r: r.created_at)
    rows = []
    for mirror in (r for r in reports if r.scene == "libero_mjx"):
        row = None
        for host in reversed([h for h in hosts if h.task == mirror.task]):
            with contextlib.suppress(ConfigError):  # another protocol: not its pair
                row = comparison_row(host, mirror)
                break
        if row is None:
            raise ConfigError(
                f"no LIBERO report of task {mirror.task!r} among the reports pairs with the "
                f"mirror's on {mirror.backend} (same task and protocol)"
            )
        rows.append(row)
    return sorted(rows, key=_order)


def _order(row: dict[str, Any]) -> tuple[int, int, str, str]:
    suite, index = row["task"].split("/")
    suites = list(SUITES)
    key = suites.index(suite) if suite in suites else len(suites)
    return key, int(index), row["backend"], str(row.get("mujoco"))


def format_table(rows: Sequence[dict[str, Any]]) -> str:
    """The agreement table in markdown."""
    lines = [
        "| task | backend (MuJoCo) | seeds | LIBERO | mirror (diverged) | per-seed agreement | "
        "McNemar p | steps to success, mirror - LIBERO (median) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    pct = lambda r, ci: f"{100 * r:.1f}% [{100 * ci[0]:.1f}, {100 * ci[1]:.1f}]"  # noqa: E731
    for r in rows:
        steps = r["steps_median_difference"]
        diverged = f" ({r['mirror_diverged']})" if r["mirror_diverged"] else ""
        lines.append(
            f"| `{r['task']}` | {r['backend']} ({r.get('mujoco') or '?'}) | {r['seeds']} | "
            f"{pct(r['libero_rate'], r['libero_ci'])} | "
            f"{pct(r['mirror_rate'], r['mirror_ci'])}{diverged} | {100 * r['agreement']:.1f}% | "
            f"{r['mcnemar_p']:.2g} | {'-' if steps is None else f'{steps:+g}'} |"
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(
        prog="python -m openral_mjx.benchmarks.libero.agreement",
        description="libero-expert closed loop on the mirror and on LIBERO, seed by seed.",
    )
    what = ap.add_mutually_exclusive_group(required=True)
    what.add_argument("--tasks", nargs="+", help="SUITE/INDEX ...: run both scenes")
    what.add_argument(
        "--from-reports",
        nargs="+",
        type=Path,
        metavar="REPORT",
        help="no runs: the table of stored reports of both scenes (each mirror report against "
        "its task's latest LIBERO report)",
    )
    ap.add_argument("--seeds", type=int, default=200)
    ap.add_argument("--backend", default="c", help="the mirror's backend")
    ap.add_argument("--host-envs", type=int, default=8, help="LIBERO worker processes")
    ap.add_argument("--mirror-envs", type=int, default=None, help="the mirror's batch")
    ap.add_argument(
        "--contacts-per-env",
        type=int,
        default=None,
        help="the mirror's warp contact buffer per env (libero_10/0 needs 512)",
    )
    ap.add_argument("--protocol", choices=("standard", "sampled"), default="standard")
    ap.add_argument("--out", type=Path, default=None, help="JSON file for the rows")
    ap.add_argument(
        "--reports", type=Path, default=None, help="folder for both reports of each task"
    )
    a = ap.parse_args(argv)
    if a.from_reports is not None:
        try:
            rows = rows_from_reports(a.from_reports)
        except ConfigError as e:  # a bad or unpaired report: one line, exit 2
            print(f"error: {e}", file=sys.stderr)
            raise SystemExit(2) from None
        if a.out is not None:
            write_text_atomic(a.out, json.dumps(rows, indent=1))
        print(format_table(rows))
        return
    rows = []
    for task in a.tasks:
        row, host, mirror = agreement_row(
            task, a.seeds, a.backend, a.host_envs, a.protocol, a.mirror_envs, a.contacts_per_env
        )
        rows.append(row)
        if a.reports is not None:
            name = task.replace("/", "_")
            save_report(host, a.reports / f"{name}_libero.json")
            save_report(mirror, a.reports / f"{name}_mirror_{a.backend}.json")
        print(format_table([row]).splitlines()[-1], flush=True)
        if a.out is not None:
            write_text_atomic(a.out, json.dumps(rows, indent=1))
    print(format_table(rows))


if __name__ == "__main__":
    main()
