"""Sweeps: the same seeds at each value of one factor, and where success changes.

Each grid value is a run of `Randomized(scene, [*randomize, factor fixed at the value])`, so
every point sees the same initial states, the same draws of the other factors and the same
policy key streams: neighbouring points are paired seed by seed. The steps between neighbours
are tested with the exact McNemar test and Holm-adjusted over all steps, so the sweep as a
whole says "success drops here" with a family-wise error of at most `alpha`.

Every point is compiled anew (its value is a constant of its episode program); on a GPU that is
most of a small sweep's time, on `c` a few seconds per point.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import functools
import itertools
from collections.abc import Callable, Sequence

import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.interrupts import stop_signal
from openral_mjx.evaluation.partial import Interrupted, add_warnings, partial_info
from openral_mjx.evaluation.provenance import device_description, package_versions
from openral_mjx.evaluation.run import evaluate_spec
from openral_mjx.evaluation.spec import RunSpec
from openral_mjx.policies import Policy, make_policy
from openral_mjx.report import EvalReport, PartialInfo
from openral_mjx.report.sweep import SweepPoint, SweepReport, SweepStep
from openral_mjx.scenes import Scene
from openral_mjx.scenes.factor_ranges import (
    FactorRange,
    available_factors,
    grid_values,
    parse_factor,
)
from openral_mjx.scenes.randomization import Randomized
from openral_mjx.stats import holm_adjusted, paired_comparison


def parse_sweep(text: str, randomize: Sequence[FactorRange] = ()) -> tuple[FactorRange, int]:
    """``NAME=LOW:HIGH:N`` -> (range, N), refusing a factor `randomize` also draws."""
    factor, points = parse_factor(text, grid=True)
    if factor.name in {f.name for f in randomize}:
        raise ConfigError(f"--sweep {factor.name} is also in --randomize: give it once")
    return factor, points


def sweep_steps(outcomes: Sequence[np.ndarray], values: Sequence[float], alpha: float) -> list:
    """Paired comparisons of neighbouring points, Holm-adjusted over all of them."""
    pairs = [paired_comparison(a, b) for a, b in itertools.pairwise(outcomes)]
    adjusted = holm_adjusted([c.p_value for c in pairs]) if pairs else np.zeros(0)
    return [
        SweepStep(
            from_value=values[i],
            to_value=values[i + 1],
            difference=float(c.difference),
            ci_low=float(c.ci_low),
            ci_high=float(c.ci_high),
            p_value=float(c.p_value),
            p_adjusted=float(adjusted[i]),
            significant=bool(adjusted[i] <= alpha),
        )
        for i, c in enumerate(pairs)
    ]


def run_sweep(
    scene: Scene,
    policy: str | Policy,
    sweep: str,
    spec: RunSpec,
    *,
    randomize: Sequence[FactorRange] = (),
    alpha: float = 0.05,
    on_point: Callable[[int, int, float], None] | None = None,
    on_chunk: Callable[[int, int, int], None] | None = None,
    resume: SweepReport | None = None,
) -> SweepReport:
    """Run `policy` on the same seeds at each value of `sweep` (``NAME=LOW:HIGH:N``), each
    point as `spec` says, except a sequential target: every point runs the same seeds.
    `on_point(i, n, value)` is called before each point. Stopped by a signal after some
    points finished, raises `Interrupted` with the report of those (marked partial); given
    that report as `resume`, runs only the points after them (see `evaluation.partial`).
    """
    if spec.target_halfwidth is not None:
        raise ConfigError("--sweep runs the same seeds at every point: drop --target-halfwidth")
    if not 0 < alpha < 1:
        raise ConfigError(f"alpha must be in (0, 1), got {alpha}")
    factor, n_points = parse_sweep(sweep, randomize)
    if factor.name not in available_factors(scene):
        raise ConfigError(
            f"scene {scene.name!r} cannot sweep {factor.name!r}; "
            f"valid: {', '.join(available_factors(scene)) or '(none)'}"
        )
    values = grid_values(factor, n_points)
    sweep_report = functools.partial(
        _sweep_report,
        scene=scene,
        sweep=sweep,
        factor=factor,
        randomize=randomize,
        alpha=alpha,
        values=values,
        command=spec.command,
    )
    points = _resumed_points(resume, sweep, values)
    reports: list[EvalReport] = []
    with contextlib.ExitStack() as owned:
        pol = policy
        if isinstance(policy, str):
            pol = make_policy(policy, scene)
            if pol.close is not None:
                owned.callback(pol.close)
        assert isinstance(pol, Policy)
        name = policy if isinstance(policy, str) else pol.name
        try:
            for i, value in enumerate(values[len(points) :], start=len(points)):
                if on_point is not None:
                    on_point(i, len(values), value)
                fixed = dataclasses.replace(factor, low=value, high=value)
                point_scene = Randomized(scene, [*randomize, fixed])
                with evaluate_spec(point_scene, pol, spec, on_chunk=on_chunk) as ev:
                    success = np.asarray(ev.arrays["success"], bool)
                    r = ev.report
                reports.append(r)
                points.append(_point(value, r, success))
        except BaseException as e:
            signal = stop_signal(e)
            if signal is None or not points:
                raise
            finished = [f"{p.value:g}" for p in points]
            partial = partial_info(signal, "points", finished, len(values))
            raise Interrupted(signal, sweep_report(name, points, reports, resume, partial)) from e
    return sweep_report(name, points, reports, resume)


def _point(value: float, r: EvalReport, success: np.ndarray) -> SweepPoint:
    """A grid value's row from its run's report and per-seed outcomes."""
    return SweepPoint(
        value=value,
        n_episodes=r.n_episodes,
        successes=r.successes,
        success_rate=r.success_rate,
        ci_low=r.ci_low,
        ci_high=r.ci_high,
        diverged=r.diverged,
        episodes_per_s=r.episodes_per_s,
        outcomes="".join("1" if s else "0" for s in success),
    )


def _resumed_points(resume: SweepReport | None, sweep: str, values: Sequence[float]) -> list:
    """The finished points of a partial sweep report, checked to be this sweep's first ones."""
    if resume is None:
        return []
    done = [p.value for p in resume.points]
    if resume.sweep != sweep or done != list(values[: len(done)]):
        raise ConfigError(
            f"cannot resume sweep {sweep!r} from a report of sweep {resume.sweep!r} "
            f"(points {', '.join(f'{v:g}' for v in done)})"
        )
    return list(resume.points)


def _sweep_report(
    policy: str,
    points: list[SweepPoint],
    reports: list[EvalReport],
    resume: SweepReport | None,
    partial: PartialInfo | None = None,
    *,
    scene: Scene,
    sweep: str,
    factor: FactorRange,
    randomize: Sequence[FactorRange],
    alpha: float,
    values: Sequence[float],
    command: str,
) -> SweepReport:
    """The sweep report over `points` (those of `resume`, then those of `reports`)."""
    first = reports[0] if reports else resume
    assert first is not None
    earlier = [] if resume is None else [resume]
    outcomes = [np.array([c == "1" for c in p.outcomes], bool) for p in points]
    return SweepReport(
        scene=first.scene,
        task=first.task,
        policy=policy,
        backend=first.backend,
        device=device_description(scene),
        factor=factor.label,
        sweep=sweep,
        relative=factor.relative,
        randomize=[f.text() for f in randomize],
        seed=first.seed,
        n_episodes=first.n_episodes,
        alpha=alpha,
        correction="holm",
        points=points,
        steps=sweep_steps(outcomes, [p.value for p in points], alpha),
        compile_s=sum(r.compile_s for r in [*earlier, *reports]),
        run_s=sum(r.run_s for r in [*earlier, *reports]),
        command=command,
        created_at=dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        versions=package_versions(),
        partial=partial,
        mujoco_warnings=add_warnings(r.mujoco_warnings for r in [*earlier, *reports]),
    )
