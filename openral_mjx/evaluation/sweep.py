"""Sweeps: the same seeds at each value of one factor, and where success changes.

Each grid value is a run of `Randomized(scene, [*randomize, factor fixed at the value])`, so
every point sees the same initial states, the same draws of the other factors and the same
policy key streams: neighbouring points are paired seed by seed. The steps between neighbours
are tested with the exact McNemar test and Holm-adjusted over all steps, so the sweep as a
whole says "success drops here" with a family-wise error of at most `alpha`.

Every point is compiled anew (its value is a constant of its episode program); on a GPU that is
most of a small sweep's time, on `c` a few seconds per point.

With `cluster` (a Ray address, see `evaluation.cluster`) the points run at once on the cluster's
workers, each building the scene and policy from their names as the driver does, so per seed a
point's outcomes are a local run's; the report records where each point ran and the retries.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import functools
import itertools
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.interrupts import stop_signal
from openral_mjx.evaluation import cluster as ray_cluster
from openral_mjx.evaluation.cluster import RayRun
from openral_mjx.evaluation.partial import Interrupted, add_by_key, partial_info
from openral_mjx.evaluation.provenance import device_description, package_versions
from openral_mjx.evaluation.run import build_spec_scene, evaluate_spec
from openral_mjx.evaluation.spec import RunSpec
from openral_mjx.policies import Policy, make_policy
from openral_mjx.report import EvalReport, PartialInfo, PartPlacement
from openral_mjx.report.sweep import SweepPoint, SweepReport, SweepStep
from openral_mjx.runner.compile_cache import enable_compilation_cache
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


@dataclasses.dataclass(frozen=True)
class SweepCluster:
    """Where and how a sweep's points run on a Ray cluster: its `address`, and the `scene`'s
    registered name and `options` that each worker builds the scene from (`compile_cache`:
    each worker caches compiled programs in its node's default cache)."""

    address: str
    scene: str
    options: Mapping[str, Any]
    compile_cache: bool = False


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
    cluster: SweepCluster | None = None,
) -> SweepReport:
    """Run `policy` on the same seeds at each value of `sweep` (``NAME=LOW:HIGH:N``), each
    point as `spec` says, except a sequential target: every point runs the same seeds.
    `on_point(i, n, value)` is called before each point (with `cluster`: as each ends, `i`
    of `n` done). Stopped by a signal after some points finished, raises `Interrupted` with
    the report of those (marked partial: the grid's first points, as far as every one
    finished); given that report as `resume`, runs only the points after them (see
    `evaluation.partial`). With `cluster` the points run on that Ray cluster (see module doc;
    `policy` must then be a name) and the report's `run_s` is their wall time.
    """
    if spec.target_halfwidth is not None:
        raise ConfigError("--sweep runs the same seeds at every point: drop --target-halfwidth")
    if not 0 < alpha < 1:
        raise ConfigError(f"alpha must be in (0, 1), got {alpha}")
    if cluster is not None and not isinstance(policy, str):
        raise ConfigError("a sweep on Ray builds its policy on each worker: pass its name")
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
    todo = values[len(points) :]
    reports: list[EvalReport] = []
    ray_run = None if cluster is None else RayRun(cluster.address, resume)
    with contextlib.ExitStack() as owned:
        pol = policy
        if isinstance(policy, str) and cluster is None:
            pol = make_policy(policy, scene)
            if pol.close is not None:
                owned.callback(pol.close)
        name = policy if isinstance(policy, str) else policy.name
        try:
            if cluster is not None and ray_run is not None:
                assert isinstance(policy, str)
                point_args = (policy, spec, tuple(randomize), factor)
                _points_on_cluster(
                    cluster, point_args, todo, len(values), on_point, reports, points, ray_run
                )
            else:
                assert isinstance(pol, Policy)
                for i, value in enumerate(todo, start=len(points)):
                    if on_point is not None:
                        on_point(i, len(values), value)
                    r, success = _run_point(scene, pol, spec, randomize, factor, value, on_chunk)
                    reports.append(r)
                    points.append(_point(value, r, success))
        except BaseException as e:
            signal = stop_signal(e)
            if signal is None or not points:
                raise
            finished = [f"{p.value:g}" for p in points]
            partial = partial_info(signal, "points", finished, len(values))
            kept = sweep_report(name, points, reports, resume, partial)
            if ray_run is not None:
                kept = dataclasses.replace(kept, cluster=ray_run.info())
            raise Interrupted(signal, kept) from e
    done = sweep_report(name, points, reports, resume)
    return done if ray_run is None else dataclasses.replace(done, cluster=ray_run.info())


def _run_point(
    scene: Scene,
    policy: Policy,
    spec: RunSpec,
    randomize: Sequence[FactorRange],
    factor: FactorRange,
    value: float,
    on_chunk: Callable[[int, int, int], None] | None = None,
) -> tuple[EvalReport, np.ndarray]:
    """One grid value's run: its report and per-seed successes."""
    fixed = dataclasses.replace(factor, low=value, high=value)
    point_scene = Randomized(scene, [*randomize, fixed])
    with evaluate_spec(point_scene, policy, spec, on_chunk=on_chunk) as ev:
        return ev.report, np.asarray(ev.arrays["success"], bool)


def cluster_point(
    scene: str,
    options: Mapping[str, Any],
    policy: str,
    spec: RunSpec,
    randomize: Sequence[FactorRange],
    factor: FactorRange,
    value: float,
    compile_cache: bool,
) -> tuple[EvalReport, np.ndarray]:
    """A Ray worker's part of a sweep: one grid value's run, its scene and policy built (and
    closed) here as the driver builds them (with the node's default compilation cache, if
    `compile_cache`)."""
    if compile_cache:
        enable_compilation_cache()
    built = build_spec_scene(scene, options, spec)
    with contextlib.closing(built):
        pol = make_policy(policy, built)
        try:
            return _run_point(built, pol, spec, randomize, factor, value)
        finally:
            if pol.close is not None:
                pol.close()


def _points_on_cluster(
    cluster: SweepCluster,
    point_args: tuple[str, RunSpec, tuple[FactorRange, ...], FactorRange],
    values: Sequence[float],
    n_values: int,
    on_point: Callable[[int, int, float], None] | None,
    reports: list[EvalReport],
    points: list[SweepPoint],
    ray_run: RayRun,
) -> None:
    """The grid `values` as Ray tasks, as many at once as the cluster has room for; `points`
    (with `reports` and `ray_run.placements`) get the first values' rows in the grid's order as
    every one before has ended, so an interrupt keeps a prefix (`point_args`: the policy, spec,
    other factors and swept factor of `cluster_point`). The points' run times are made shares
    of the wall time."""
    start = time.perf_counter()
    spec = point_args[1]
    built = (cluster.scene, dict(cluster.options))
    with ray_cluster.connected(cluster.address) as ray:
        ray_run.nodes = ray_cluster.live_nodes(ray)
        resources = ray_cluster.part_resources(ray, spec.backend, spec.threads)
        parts = [(f"{v:g}", (*built, *point_args, v, cluster.compile_cache)) for v in values]
        ended: dict[int, tuple[EvalReport, np.ndarray, PartPlacement]] = {}
        first = len(points)
        runs = ray_cluster.fan_out(ray, cluster_point, parts, resources)
        with contextlib.closing(runs):  # an interrupt cancels the running points
            for i, (report, success), placement in runs:
                ended[i] = (report, success, placement)
                while len(reports) in ended:
                    r, ok, where = ended.pop(len(reports))
                    reports.append(r)
                    points.append(_point(values[len(reports) - 1], r, ok))
                    ray_run.placements.append(where)
                if on_point is not None:
                    on_point(first + len(ended) + len(reports), n_values, values[i])
    wall = time.perf_counter() - start
    total = sum(r.run_s for r in reports) or 1.0
    reports[:] = [dataclasses.replace(r, run_s=wall * r.run_s / total) for r in reports]


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
        overflowed=r.overflowed,
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
        mujoco_warnings=add_by_key(r.mujoco_warnings for r in [*earlier, *reports]),
    )
