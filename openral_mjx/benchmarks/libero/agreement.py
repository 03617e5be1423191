"""The LIBERO mirror against LIBERO itself.

- `libero_reference`: LIBERO's env for a task in a worker process, to replay actions from an
  initial state and to judge states by its own goal predicates (the tests' oracle).
- `replay_row`: `libero-expert`'s episode on the mirror, its actions replayed on LIBERO from
  the same initial state: how far the hand, the objects, the fixtures' joints and the arm
  part, worst over the episode (issue 37's "same actions, same trajectories", per task).
- `agreement_row`: `libero-expert` closed loop on the same seeds of each task, on the mirror
  (`libero_mjx`, any backend) and on LIBERO through the host adapter, as a user would run
  them, compared seed by seed (`compare_reports`): both rates with their intervals, per-seed
  agreement, exact McNemar, and the median difference in steps to success.

``python -m openral_mjx.benchmarks.libero.agreement --tasks libero_object/0 --seeds 200``
prints the table (markdown) and writes it as JSON with ``--out``; ``--protocol sampled`` runs
the mass-seed protocol's draws, ``--reports DIR`` keeps both reports of each task.
``--from-reports DIR/*.json`` runs nothing: the table of stored reports (`rows_from_reports`).
``--replay`` (with ``--tasks`` or ``--suite``) prints `replay_row`'s table instead, for the
tasks the expert covers.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.benchmarks.libero.assets import TIMEOUT_S, task_worker
from openral_mjx.benchmarks.libero.expert import coverage
from openral_mjx.benchmarks.libero.host_scene import SUITES
from openral_mjx.benchmarks.libero.mirror import LiberoMjx, LiberoMjxOptions
from openral_mjx.core.errors import ConfigError
from openral_mjx.core.files import write_text_atomic
from openral_mjx.evaluation import evaluate
from openral_mjx.host.pool import Worker
from openral_mjx.policies import make_policy
from openral_mjx.report import EvalReport, load_report, save_report
from openral_mjx.scenes import scene_suite, seed_cycles, seed_options
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


def expert_episode(scene: LiberoMjx, seed: int = 0) -> dict[str, Any]:
    """`libero-expert`'s episode of `seed` on `scene`, one env, until it ends or the task's
    step limit: its actions (T, 7), observations and joint positions at steps 0..T, and the
    control step it succeeded at (None if it did not)."""
    policy = make_policy("libero-expert", scene)
    _, pstate = policy.init(jax.random.PRNGKey(0), None)
    reset, step, act = jax.jit(scene.reset_with_seed), jax.jit(scene.step), jax.jit(policy.act)
    state = reset(jnp.int32(seed), jax.random.PRNGKey(seed))
    actions, obs = [], [np.asarray(state.obs)]
    qpos = [np.asarray(state.physics.quantities.qpos)]
    success = None
    for t in range(scene.max_steps):
        action, pstate = act(None, pstate, state.obs, jax.random.PRNGKey(t))
        state = step(state, action)
        actions.append(np.asarray(action))
        obs.append(np.asarray(state.obs))
        qpos.append(np.asarray(state.physics.quantities.qpos))
        if bool(state.done):
            success = t + 1 if bool(state.metrics["success"]) else None
            break
    return {
        "actions": np.stack(actions),
        "obs": np.stack(obs),
        "qpos": np.stack(qpos),
        "success_step": success,
    }


def joint_groups(scene: LiberoMjx) -> dict[str, Any]:
    """Where to read each kind of joint in the task's ``qpos``: the arm's joints, each free
    object's position (name -> its 3 indices) and the other fixtures' hinge and slide
    joints."""
    m = scene.mj_model
    meta = scene.export.meta
    robot = set(meta["arm_joints"]) | set(meta["gripper_joints"])
    arm = [int(m.joint(n).qposadr[0]) for n in meta["arm_joints"]]
    objects: dict[str, list[int]] = {}
    fixtures: list[int] = []
    for j in range(m.njnt):
        name, adr = m.joint(j).name, int(m.jnt_qposadr[j])
        if name in robot:
            continue
        if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            objects[m.body(int(m.jnt_bodyid[j])).name] = [adr, adr + 1, adr + 2]
        elif m.jnt_type[j] in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
            fixtures.append(adr)
    return {"arm": arm, "objects": objects, "fixtures": fixtures}


def replay_row(task: str, seed: int = 0, backend: str = "c") -> dict[str, Any]:
    """`libero-expert`'s episode of `seed` (LIBERO's initial state ``seed mod 50``) on the
    mirror, its actions replayed on LIBERO: the control step each side succeeded at, and
    the largest difference over the episode of the hand's position (m), of each free
    object's position (m; the worst object named), of the articulated fixtures' joints (m or
    rad) and of the arm's joints (rad). Open loop on LIBERO's side: a difference that grows
    is not corrected as closed loop would."""
    scene = LiberoMjx(LiberoMjxOptions(task=task), backend=backend)
    episode = expert_episode(scene, seed)
    with libero_reference(task) as libero:
        ref = libero.rollout(seed % scene.n_init_states, episode["actions"])
    groups = joint_groups(scene)
    mirror_q, libero_q = episode["qpos"], np.asarray(ref["qpos"])
    hand = np.abs(episode["obs"][:, :3] - np.asarray(ref["state"])[:, :3]).max()
    per_object = {
        name: float(np.linalg.norm(mirror_q[:, idx] - libero_q[:, idx], axis=1).max())
        for name, idx in groups["objects"].items()
    }
    worst = max(per_object, key=per_object.get) if per_object else None
    fixtures = groups["fixtures"]
    libero_success = np.flatnonzero(np.asarray(ref["success"]))
    return {
        "task": task,
        "coverage": coverage(task),
        "backend": backend,
        "seed": seed,
        "steps": len(episode["actions"]),
        "mirror_success_step": episode["success_step"],
        "libero_success_step": int(libero_success[0]) if libero_success.size else None,
        "hand_max_m": float(hand),
        "object_max_m": per_object[worst] if worst else None,
        "worst_object": worst,
        "fixture_joint_max": (
            float(np.abs(mirror_q[:, fixtures] - libero_q[:, fixtures]).max()) if fixtures else None
        ),
        "arm_joint_max_rad": float(
            np.abs(mirror_q[:, groups["arm"]] - libero_q[:, groups["arm"]]).max()
        ),
    }


def format_replay_table(rows: Sequence[dict[str, Any]]) -> str:
    """`replay_row`s in markdown."""
    lines = [
        "| task | expert | steps | success step, mirror / LIBERO | hand | worst object | "
        "fixture joints | arm joints (rad) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    g = lambda v: "-" if v is None else f"{v:.1e}"  # noqa: E731
    for r in rows:
        obj = "-" if r["worst_object"] is None else f"{g(r['object_max_m'])} ({r['worst_object']})"
        steps = f"{r['mirror_success_step'] or '-'} / {r['libero_success_step'] or '-'}"
        lines.append(
            f"| `{r['task']}` | {r['coverage']} | {r['steps']} | {steps} | {g(r['hand_max_m'])} "
            f"| {obj} | {g(r['fixture_joint_max'])} | {g(r['arm_joint_max_rad'])} |"
        )
    return "\n".join(lines)


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
        "protocol": mirror.options.get("protocol", "standard"),
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
    `libero_mjx` report against the latest `libero` report of its task and policy it pairs
    with, in the suites' order. A mirror report with no such LIBERO report is a
    `ConfigError`."""
    reports = [load_report(p) for p in paths]
    hosts = sorted((r for r in reports if r.scene == "libero"), key=lambda r: r.created_at)
    rows = []
    for mirror in (r for r in reports if r.scene == "libero_mjx"):
        row = None
        same = [h for h in hosts if (h.task, h.policy) == (mirror.task, mirror.policy)]
        for host in reversed(same):
            with contextlib.suppress(ConfigError):  # another protocol: not its pair
                row = comparison_row(host, mirror)
                break
        if row is None:
            raise ConfigError(
                f"no LIBERO report of task {mirror.task!r} among the reports pairs with the "
                f"mirror's on {mirror.backend} (same task, policy and protocol)"
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


def suite_tasks(suite: str) -> Iterator[str]:
    """The tasks of LIBERO suite `suite` (`scene_suite`'s names) the expert covers, wholly or
    partly, in order, each looked at (its export made) only when the one before has run."""
    return (t for t in scene_suite("libero_mjx", suite) if coverage(t) != "not covered")


def kept_rows(
    path: Path | None, seeds: int, backend: str, protocol: str
) -> tuple[list[dict[str, Any]], set[str]]:
    """`--resume`: the rows in `path` (an earlier run's `--out`), all kept, and the tasks
    whose row was made as this run would make it (the same seeds, backend and protocol),
    which are not run again."""
    if path is None or not path.exists():
        return [], set()
    try:
        rows = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise ConfigError(f"--resume: cannot read the rows in {path}: {e}") from None
    made = lambda r: (r.get("seeds"), r.get("backend"), r.get("protocol"))  # noqa: E731
    return rows, {r["task"] for r in rows if made(r) == (seeds, backend, protocol)}


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(
        prog="python -m openral_mjx.benchmarks.libero.agreement",
        description="libero-expert on the mirror and on LIBERO: closed loop seed by seed, or "
        "(--replay) its actions on the mirror replayed on LIBERO.",
    )
    what = ap.add_mutually_exclusive_group(required=True)
    what.add_argument("--tasks", nargs="+", help="SUITE/INDEX ...: run both scenes")
    what.add_argument(
        "--suite", help=f"the tasks the expert covers of one suite ({', '.join(SUITES)})"
    )
    what.add_argument(
        "--from-reports",
        nargs="+",
        type=Path,
        metavar="REPORT",
        help="no runs: the table of stored reports of both scenes (each mirror report against "
        "its task's latest LIBERO report)",
    )
    ap.add_argument(
        "--replay",
        action="store_true",
        help="per task, the expert's episode of --replay-seed on the mirror replayed action for "
        "action on LIBERO: how far hand, objects, fixtures and arm part (no closed loop)",
    )
    ap.add_argument("--replay-seed", type=int, default=0, help="the replayed episode's seed")
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
        "--resume",
        action="store_true",
        help="keep the rows --out already holds for these seeds, backend and protocol, and run "
        "only the other tasks (a run cut short goes on where it stopped)",
    )
    ap.add_argument(
        "--reports", type=Path, default=None, help="folder for both reports of each task"
    )
    a = ap.parse_args(argv)
    try:
        if a.from_reports is not None:
            rows = rows_from_reports(a.from_reports)
            if a.out is not None:
                write_text_atomic(a.out, json.dumps(rows, indent=1))
            print(format_table(rows))
            return
        if a.resume and (a.out is None or a.replay):
            raise ConfigError(
                "--resume keeps the closed-loop rows of --out: give --out, not --replay"
            )
        rows, done = kept_rows(a.out, a.seeds, a.backend, a.protocol) if a.resume else ([], set())
        _run_tasks(a, a.tasks or suite_tasks(a.suite), rows, done)
    except ConfigError as e:
        # a bad or unpaired report, an unknown suite, a task that cannot run (its export, its
        # draws; the rows before it are in --out): one line, exit 2
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None


def _run_tasks(
    a: argparse.Namespace, tasks: Iterable[str], rows: list[dict[str, Any]], done: set[str]
) -> None:
    """Each task's row (both scenes run, or the replay), printed and written to `a.out` as it
    ends, after `rows` (kept by `--resume`; the tasks in `done` are not run again); then the
    table."""
    table = format_replay_table if a.replay else format_table
    if done:
        print(f"kept {len(done)} rows of {a.out}: {', '.join(sorted(done))}", flush=True)
    for task in tasks:
        if task in done:
            continue
        if a.replay:
            row = replay_row(task, a.replay_seed, a.backend)
        else:
            row, host, mirror = agreement_row(
                task, a.seeds, a.backend, a.host_envs, a.protocol, a.mirror_envs, a.contacts_per_env
            )
            if a.reports is not None:
                name = task.replace("/", "_")
                save_report(host, a.reports / f"{name}_libero.json")
                save_report(mirror, a.reports / f"{name}_mirror_{a.backend}.json")
        rows.append(row)
        print(table([row]).splitlines()[-1], flush=True)
        if a.out is not None:  # after every task: an interrupted run keeps its rows
            write_text_atomic(a.out, json.dumps(rows, indent=1))
    print(table(rows))


if __name__ == "__main__":
    main()
