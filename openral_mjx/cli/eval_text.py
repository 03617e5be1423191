"""`eval`'s text: the lines printed for a sequential run, a `--decide` verdict, `--list`
and MuJoCo's counted warnings."""

from __future__ import annotations

import dataclasses

from openral_mjx.physics import BACKEND_NAMES
from openral_mjx.physics.mj_warnings import format_warnings
from openral_mjx.policies import POLICIES
from openral_mjx.report import EvalReport
from openral_mjx.robots import ROBOTS
from openral_mjx.scenes import SCENES


def sequential_summary(report: EvalReport) -> str:
    """One line on how a sequential run stopped."""
    s = report.sequential
    assert s is not None
    why = (
        f"half-width {s.halfwidth:.4f} (target {s.target_halfwidth:g})"
        if s.stopped == "target"
        else f"reached --max-episodes before the target {s.target_halfwidth:g}: half-width "
        f"{s.halfwidth:.4f}"
    )
    return (
        f"sequential: stopped after {s.looks} chunk(s) of {s.chunk:,}, {report.n_episodes:,} "
        f"of at most {s.max_episodes:,} episodes; {why}; interval exact under this stopping rule"
    )


DECIDED = {
    "better": "B's success rate is higher than A's",
    "worse": "B's success rate is lower than A's",
    "equivalent": "B's success rate is within +-{margin} points of A's",
    "inconclusive": "no decision by the cap",
}


def decision_summary(report: EvalReport, baseline: EvalReport | None) -> str:
    """The lines of `--decide`: the verdict, the looks and the interval valid under the rule."""
    d = report.decision
    assert d is not None
    margin = "" if d.margin is None else f"{100 * d.margin:g}"
    verdict = DECIDED[d.decision].format(margin=margin)
    a = f"A: {d.baseline} ({d.baseline_policy})" + (
        f", {baseline.success_rate:.1%} over its {baseline.n_episodes:,} seeds"
        if baseline is not None
        else ""
    )
    lines = [
        a,
        f"decide: {verdict}; stopped at look {len(d.looks)} of {-(-d.cap // d.chunk)}, "
        f"{report.n_episodes:,} of at most {d.cap:,} seeds",
        "  look  seeds  only A  only B  stop if only B <=  or >=",
    ]
    for i, look in enumerate(d.looks, 1):
        lines.append(
            f"  {i:>4}  {look.n:>5,}  {look.only_a:>6}  {look.only_b:>6}  {look.lower:>16}  "
            f"{look.upper:>5}"
        )
    level = f"{100 * (1 - d.alpha):g}%"
    lines.append(
        f"B - A = {100 * d.difference:+.1f} points, {level} repeated CI [{100 * d.ci_low:+.1f}, "
        f"{100 * d.ci_high:+.1f}] (valid under the stopping rule)"
    )
    lines.append(f"design: {d.rule}")
    return "\n".join(lines)


def _scene_listing(name: str) -> list[str]:
    """Scene `name`'s lines in --list, from its registration: backends, robot, tasks, suites."""
    entry = SCENES.get(name)
    backends = entry.backends or tuple(b for b in BACKEND_NAMES if b != "auto")
    robot_field = {f.name: f for f in dataclasses.fields(entry.options_cls)}.get("robot")
    if entry.fixed_robot is not None:
        robot = entry.fixed_robot
    elif robot_field is not None:
        robot = f"--robot or --robot-mjcf (default {robot_field.default})"
    else:
        robot = "none"
    lines = [f"  {name}: backends {', '.join(backends)}; robot {robot}"]
    if entry.tasks:
        lines.append(f"    --task  {entry.tasks}")
    if entry.suite_names:
        lines.append(f"    --suite {', '.join(entry.suite_names)}")
    return lines


def listing() -> str:
    return "\n".join(
        [
            f"scenes:   {', '.join(SCENES.names())}",
            f"policies: {', '.join(POLICIES.names())}",
            f"robots:   {', '.join(ROBOTS.names())}",
            f"backends: {', '.join(BACKEND_NAMES)} (MuJoCo scenes), host (host scenes)",
            "",
            "scenes, as registered (tasks: --task; suites: --suite):",
            *(line for name in SCENES.names() for line in _scene_listing(name)),
        ]
    )


def warnings_line(counts: dict[str, int]) -> str:
    """The one line that stands for MuJoCo's warnings (counted during the run, not shown)."""
    return (
        f"mujoco warnings: {format_warnings(counts)} (counted, not printed; by kind in the "
        "report's mujoco_warnings)"
    )
