"""Evaluate a policy on a scene: roll out seeds with the runner and aggregate an `EvalReport`."""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import importlib.metadata
import platform
from collections.abc import Callable, Mapping
from typing import Any

import jax
import numpy as np

import openral_mjx
from openral_mjx.breakdown import breakdown
from openral_mjx.errors import ConfigError
from openral_mjx.options import to_dict
from openral_mjx.physics import PhysicsSettings
from openral_mjx.policies import Policy, make_policy
from openral_mjx.rollout import FACTOR_PREFIX, INFO_PREFIX, RunTiming, check_counts, run_seeds
from openral_mjx.scenes import Scene, make_scene
from openral_mjx.schema import EpisodeResult, EvalReport, SequentialInfo, TaskRow
from openral_mjx.sequential import RULE, SequentialDesign, sufficient_episodes
from openral_mjx.stats import wilson_interval

_PACKAGES = ("jax", "jaxlib", "mujoco", "mujoco-mjx", "flax", "numpy")


def package_versions() -> dict[str, str]:
    """Versions of Python and the packages that decide a result (source-tree runs included)."""
    out = {"python": platform.python_version(), "openral_mjx": openral_mjx.__version__}
    for name in _PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def device_description(scene: Scene) -> str:
    """What ran the physics: the JAX devices for `mjx`/`warp`, the CPU thread pool for `c`,
    worker processes for host scenes."""
    label = getattr(scene.backend, "device_label", None)
    if label is not None:
        return label()
    if scene.backend.name == "c":
        return f"cpu: MuJoCo C, {scene.backend.describe()['threads']} threads"
    devices = scene.backend.devices()
    return f"{devices[0].platform}: {devices[0].device_kind} x{len(devices)}"


def float32_values(values: np.ndarray) -> list[float]:
    """float32 values as the shortest decimals that read back to the same float32 (the JSON
    stays compact and loses nothing)."""
    return [float(str(v)) for v in np.asarray(values, np.float32)]


def episode_results(
    arrays: Mapping[str, Any],
    seeds: np.ndarray,
    timing: RunTiming,
    control_dt: float,
    metadata: Mapping[str, Any],
    *,
    policy_latency: bool = False,
    describe: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
) -> list[EpisodeResult]:
    """Turn the runner's per-env arrays into `EpisodeResult`s.

    Latency: with `policy_latency`, the policy's own per-step latency as the runner
    accumulated it (mean and max over the episode's steps, steps over the control period);
    otherwise the batch's per-step time from chunk timings. `describe` turns a seed's
    `info/...` values into metadata entries (the scene's `describe_episode`).
    """
    budget_ms = 1000 * control_dt
    chunk_ms = [round(1000 * s / timing.scan_steps, 4) for s in timing.chunk_s]
    max_ms = max(chunk_ms)
    factors = {
        k.removeprefix(FACTOR_PREFIX): float32_values(v)
        for k, v in arrays.items()
        if k.startswith(FACTOR_PREFIX)
    }
    info = {
        k.removeprefix(INFO_PREFIX): v.tolist()
        for k, v in arrays.items()
        if k.startswith(INFO_PREFIX)
    }
    if policy_latency:
        lat_sum = arrays["latency_sum_ms"].tolist()
        lat_max = arrays["latency_max_ms"].tolist()
        lat_over = arrays["latency_violations"].tolist()
    rewards = float32_values(arrays["total_reward"])
    steps = arrays["steps"].tolist()
    success = arrays["success"].tolist()
    diverged = arrays["diverged"].tolist()
    first = arrays["first_success_step"].tolist()
    results = []
    for i, seed in enumerate(seeds.tolist()):
        if policy_latency:
            mean_ms = round(lat_sum[i] / max(steps[i], 1), 4)
            ep_max_ms, violations = round(lat_max[i], 4), lat_over[i]
        else:
            mean_ms = chunk_ms[i // timing.n_envs]
            ep_max_ms, violations = max_ms, steps[i] if mean_ms > budget_ms else 0
        extra = {} if not info else (describe or dict)({k: v[i] for k, v in info.items()})
        results.append(
            EpisodeResult(
                success=success[i],
                steps=steps[i],
                total_reward=rewards[i],
                mean_step_latency_ms=mean_ms,
                max_step_latency_ms=ep_max_ms,
                latency_budget_ms=budget_ms,
                budget_violations=violations,
                metadata={
                    **metadata,
                    "seed": seed,
                    "diverged": diverged[i],
                    "first_success_step": first[i],
                    "factors": {k: v[i] for k, v in factors.items()},
                    **extra,
                },
            )
        )
    return results


def build_scene(
    name: str,
    options: Mapping[str, Any] | None = None,
    *,
    backend: str = "auto",
    n_envs: int = 1024,
    threads: int | None = None,
    contacts_per_env: int | None = None,
    devices: int | None = None,
) -> Scene:
    """Scene `name` on `backend`, its buffers sized for batches of `n_envs`, on at most
    `devices` devices (default: all the backend can use)."""
    check_counts(n_envs, 1, 1)
    if devices is not None and devices < 1:
        raise ConfigError(f"devices must be >= 1, got {devices}")
    settings = PhysicsSettings(threads=threads, batch_size=n_envs, max_devices=devices)
    if contacts_per_env is not None:
        settings = dataclasses.replace(settings, contacts_per_env=contacts_per_env)
    return make_scene(name, options, backend=backend, settings=settings)


@dataclasses.dataclass
class Evaluation:
    """A finished evaluation with what produced it, for looking at it afterwards (videos).

    `seeds` are the seeds the run was given (a sequential run may have stopped before the last
    ones); `arrays` the runner's per-seed arrays of the episodes that ran (`rewards`, per step,
    only when asked for); `timing` its batch layout and timings. `close()` (or leaving a `with`
    block) releases what `run_evaluation` built for it (a host scene's worker processes, a
    policy server); a scene or policy passed in built stays the caller's.
    """

    report: EvalReport
    scene: Scene
    policy: Policy
    params: Any
    seeds: np.ndarray
    arrays: dict[str, np.ndarray]
    timing: RunTiming
    resources: contextlib.ExitStack = dataclasses.field(
        default_factory=contextlib.ExitStack, repr=False
    )

    def close(self) -> None:
        self.resources.close()

    def __enter__(self) -> Evaluation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def evaluate(
    scene: str | Scene = "tabletop_push",
    policy: str | Policy = "scripted",
    **kwargs: Any,
) -> EvalReport:
    """Evaluate `policy` on seeds `seed .. seed + n_episodes - 1` and return the report.

    Keyword arguments are `run_evaluation`'s. With `target_halfwidth`, run sequentially
    instead: chunks of `n_envs` seeds until the success-rate interval's half-width is at most
    the target, or `max_episodes` (default: the worst case, rate 1/2); the report's interval
    is then exact for that stopping rule (see `openral_mjx.sequential`). Raises `ConfigError`
    for unknown names, bad options and non-positive counts. `scene` and `policy` are registry
    names (built here and closed afterwards) or built objects (left open for the caller, e.g.
    one policy over every task of a suite).
    """
    with run_evaluation(scene, policy, **kwargs) as evaluation:
        return evaluation.report


def run_evaluation(
    scene: str | Scene = "tabletop_push",
    policy: str | Policy = "scripted",
    *,
    n_envs: int = 1024,
    n_episodes: int | None = None,
    target_halfwidth: float | None = None,
    max_episodes: int | None = None,
    factor_bins: int = 5,
    seed: int = 0,
    max_steps: int | None = None,
    backend: str = "auto",
    threads: int | None = None,
    contacts_per_env: int | None = None,
    devices: int | None = None,
    options: Mapping[str, Any] | None = None,
    command: str = "",
    on_chunk: Callable[[int, int], None] | None = None,
    step_rewards: bool = False,
) -> Evaluation:
    """`evaluate`, returning the report with the scene, policy and per-seed arrays that made
    it; `step_rewards` also keeps every step's reward (`arrays["rewards"]`, for plots)."""
    rule = _sequential_rule(n_envs, n_episodes, target_halfwidth, max_episodes)
    if rule is not None:
        n_episodes = rule.max_episodes
    n_episodes = n_envs if n_episodes is None else n_episodes
    check_counts(n_envs, n_episodes, 1 if max_steps is None else max_steps)
    if seed < 0:
        raise ConfigError(f"seed must be >= 0, got {seed}")
    if factor_bins < 1:
        raise ConfigError(f"factor_bins must be a positive integer, got {factor_bins}")
    owned = contextlib.ExitStack()
    with owned:  # on an error, close what this call built (worker processes)
        if isinstance(scene, str):
            scene = build_scene(
                scene,
                options,
                backend=backend,
                n_envs=n_envs,
                threads=threads,
                contacts_per_env=contacts_per_env,
                devices=devices,
            )
            owned.callback(scene.close)
        if isinstance(policy, str):
            pol = make_policy(policy, scene)
            if pol.close is not None:
                owned.callback(pol.close)
        else:
            pol, policy = policy, policy.name
        steps = scene.max_steps if max_steps is None else max_steps
        requested = np.arange(seed, seed + n_episodes, dtype=np.int64)
        params, _ = pol.init(jax.random.PRNGKey(seed), scene.observation_spec)
        arrays, timing = run_seeds(
            scene,
            pol,
            params,
            seeds=requested,
            n_envs=n_envs,
            max_steps=steps,
            on_chunk=on_chunk,
            until=rule,
            record=("rewards",) if step_rewards else (),
        )
        n_episodes = len(arrays["success"])
        seeds = requested[:n_episodes]
        meta = {
            "scene": scene.name,
            "task": scene.task,
            "robot": scene.robot_name,
            "policy": policy,
            "backend": scene.backend.name,
        }
        episodes = episode_results(
            arrays,
            seeds,
            timing,
            scene.control_dt,
            meta,
            policy_latency=pol.latency_ms is not None,
            describe=scene.describe_episode,
        )
        resources = owned.pop_all()  # handed to the Evaluation
    successes = int(arrays["success"].sum())
    low, high = wilson_interval(successes, n_episodes)
    sequential = None
    if rule is not None:
        design = rule.design
        look = design.looks.index(n_episodes)
        low, high = design.interval(look, successes)
        sequential = SequentialInfo(
            target_halfwidth=design.halfwidth,
            max_episodes=design.max_episodes,
            chunk=timing.n_envs,
            looks=look + 1,
            stopped="target" if design.meets_target(look, successes) else "max_episodes",
            halfwidth=(high - low) / 2,
            rule=RULE,
        )
    names = episodes[0].metadata["factors"] if episodes else {}
    factors = {k: [e.metadata["factors"][k] for e in episodes] for k in names}
    simulated = len(timing.chunk_s) * timing.n_envs * timing.scan_steps
    report = EvalReport(
        scene=scene.name,
        task=scene.task,
        robot=scene.robot_name,
        policy=policy,
        backend=scene.backend.name,
        device=device_description(scene),
        n_episodes=n_episodes,
        n_envs=timing.n_envs,
        seed=seed,
        max_steps=steps,
        successes=successes,
        success_rate=successes / n_episodes,
        ci_low=low,
        ci_high=high,
        confidence=0.95,
        ci_method="wilson" if rule is None else "sequential-exact",
        diverged=int(arrays["diverged"].sum()),
        per_task=[TaskRow(scene.task, n_episodes, successes, successes / n_episodes, low, high)],
        breakdown=breakdown(factors, arrays["success"], factor_bins),
        env_steps_per_s=simulated / timing.run_s,
        episodes_per_s=n_episodes / timing.run_s,
        compile_s=timing.compile_s,
        run_s=timing.run_s,
        control_dt_s=scene.control_dt,
        options={**to_dict(scene.options), "backend": scene.backend.describe()},
        versions=package_versions(),
        command=command,
        created_at=dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        episodes=episodes,
        sequential=sequential,
    )
    return Evaluation(report, scene, pol, params, requested, arrays, timing, resources)


class SequentialRule:
    """The runner's `until` for a sequential run: stop once the design says so.

    The design's looks fall after each of the runner's chunks. The runner fixes the chunk
    size (devices, memory) before any episode runs, and the first look reveals it, so the
    design is built then: it still depends on no outcome.
    """

    def __init__(self, halfwidth: float, max_episodes: int) -> None:
        self.halfwidth, self.max_episodes = halfwidth, max_episodes
        self._design: SequentialDesign | None = None

    @property
    def design(self) -> SequentialDesign:
        if self._design is None:
            raise RuntimeError("the sequential design is fixed at the first look")
        return self._design

    def __call__(self, arrays: Mapping[str, Any]) -> bool:
        n = len(arrays["success"])
        if self._design is None:
            self._design = SequentialDesign.in_chunks(n, self.halfwidth, self.max_episodes)
        return self._design.stops(self._design.looks.index(n), int(arrays["success"].sum()))


def _sequential_rule(
    n_envs: int, n_episodes: int | None, target: float | None, max_episodes: int | None
) -> SequentialRule | None:
    """The stopping rule for `target_halfwidth`, or None for a fixed episode count."""
    if target is None:
        if max_episodes is not None:
            raise ConfigError(
                "max_episodes caps a sequential run: give target_halfwidth too "
                "(or n_episodes for a fixed count)"
            )
        return None
    if n_episodes is not None:
        raise ConfigError(
            "n_episodes and target_halfwidth exclude each other: a sequential run decides "
            "how many episodes it needs (cap it with max_episodes)"
        )
    if not 0 < target < 0.5:
        raise ConfigError(f"target_halfwidth must lie in (0, 0.5), got {target}")
    if max_episodes is not None and max_episodes < 1:
        raise ConfigError(f"max_episodes must be a positive integer, got {max_episodes}")
    check_counts(n_envs, 1, 1)
    return SequentialRule(target, max_episodes or sufficient_episodes(target))


__all__ = ["Evaluation", "build_scene", "evaluate", "package_versions", "run_evaluation"]
