"""Evaluate a policy on a scene: roll out seeds with the runner and aggregate an `EvalReport`."""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import functools
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

import jax
import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.interrupts import stop_reason, stop_signal
from openral_mjx.core.options import to_dict
from openral_mjx.evaluation.episodes import episode_results
from openral_mjx.evaluation.partial import Interrupted, add_by_key
from openral_mjx.evaluation.provenance import device_description, package_versions
from openral_mjx.evaluation.sequential import PairedRule, SequentialRule
from openral_mjx.evaluation.spec import RunSpec
from openral_mjx.physics import release_warp_graphs
from openral_mjx.physics.mj_warnings import count_warnings
from openral_mjx.policies import Policy, make_policy
from openral_mjx.policies.lerobot import implied_camera_options
from openral_mjx.report import EpisodeResult, EvalReport, PartialInfo, SequentialInfo, TaskRow
from openral_mjx.runner import (
    RunTiming,
    check_batching,
    check_counts,
    resolve_batching,
    run_seeds,
)
from openral_mjx.scenes import SCENES, Scene, make_scene, randomization, scene_settings
from openral_mjx.stats.breakdown import breakdown
from openral_mjx.stats.intervals import wilson_interval
from openral_mjx.stats.sequential import RULE


def _worker_versions(scene: Scene) -> dict[str, str]:
    """A host scene's simulator versions (its workers' environment), else nothing."""
    versions = getattr(scene.backend, "worker_versions", None)
    return versions() if versions is not None else {}


def build_scene(
    name: str,
    options: Mapping[str, Any] | None = None,
    *,
    backend: str = "auto",
    n_envs: int = 1024,
    threads: int | None = None,
    contacts_per_env: int | None = None,
    ccd_contacts_per_env: int | None = None,
    warp_graphs: str | None = None,
    devices: int | None = None,
    randomize: Sequence[str] = (),
) -> Scene:
    """Scene `name` on `backend`, its buffers sized for batches of `n_envs` (`warp`'s contact
    buffers and graph mode as `PhysicsSettings` takes them), on at most `devices` devices
    (default: all the backend can use), with the `randomize` factors (``NAME=LOW:HIGH``, see
    `scenes.randomization`) drawn per seed."""
    check_counts(n_envs, 1, 1)
    if devices is not None and devices < 1:
        raise ConfigError(f"devices must be >= 1, got {devices}")
    settings = scene_settings(
        name,
        contacts_per_env,
        threads=threads,
        batch_size=n_envs,
        max_devices=devices,
        ccd_contacts_per_env=ccd_contacts_per_env,
        warp_graphs=warp_graphs,
    )
    scene = make_scene(name, options, backend=backend, settings=settings)
    return randomization.randomize(scene, randomize)


def policy_options(scene: str, policy: str, options: Mapping[str, Any] | None) -> dict[str, Any]:
    """`options` with the camera options a `lerobot:PATH` policy implies for `scene` beneath
    them (`implied_camera_options`: its image features set the cameras unless `options` do),
    as every run that builds a scene by name for a policy by name takes them."""
    implied = implied_camera_options(policy, SCENES.get(scene).options_cls, options)
    return {**implied, **(options or {})}


def build_spec_scene(
    name: str, options: Mapping[str, Any] | None, spec: RunSpec, randomize: Sequence[str] = ()
) -> Scene:
    """`build_scene` with the spec's backend, batch size, threads, contacts and devices."""
    return build_scene(
        name,
        options,
        backend=spec.backend,
        n_envs=spec.n_envs,
        threads=spec.threads,
        contacts_per_env=spec.contacts_per_env,
        ccd_contacts_per_env=spec.ccd_contacts_per_env,
        warp_graphs=spec.warp_graphs,
        devices=spec.devices,
        randomize=randomize,
    )


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
        """Release what the run built, and the CUDA graphs Warp captured for its programs
        (`physics.release_warp_graphs`: device memory a next run in this process needs)."""
        try:
            self.resources.close()
        finally:
            release_warp_graphs()

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
    is then exact for that stopping rule (see `openral_mjx.stats.sequential`). Raises `ConfigError`
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
    ccd_contacts_per_env: int | None = None,
    warp_graphs: str | None = None,
    devices: int | None = None,
    options: Mapping[str, Any] | None = None,
    command: str = "",
    on_chunk: Callable[[int, int, int], None] | None = None,
    step_rewards: bool = False,
    batching: str = "auto",
    refill_every: int = 1,
    randomize: Sequence[str] = (),
) -> Evaluation:
    """`evaluate`, returning the report with the scene, policy and per-seed arrays that made
    it; `step_rewards` also keeps every step's reward (`arrays["rewards"]`, for plots).
    `batching` is `chunks` (fixed batches of `n_envs` seeds), `refill` (continuous batching:
    a slot whose episode ended takes the next seed, resets batched every `refill_every`
    control steps) or `auto` (`refill` where it applies: see `resolve_batching`); per seed
    the episodes are the same. `randomize` draws factors per seed (``NAME=LOW:HIGH``, see
    `scenes.randomization`) on the scene, built here or given. `contacts_per_env`,
    `ccd_contacts_per_env` and `warp_graphs` size and replay `warp`'s buffers as
    `PhysicsSettings` takes them (for a scene built here)."""
    spec = RunSpec(
        n_envs=n_envs,
        n_episodes=n_episodes,
        target_halfwidth=target_halfwidth,
        max_episodes=max_episodes,
        max_steps=max_steps,
        seed=seed,
        factor_bins=factor_bins,
        batching=batching,
        refill_every=refill_every,
        step_rewards=step_rewards,
        backend=backend,
        threads=threads,
        contacts_per_env=contacts_per_env,
        ccd_contacts_per_env=ccd_contacts_per_env,
        warp_graphs=warp_graphs,
        devices=devices,
        command=command,
    )
    return evaluate_spec(
        scene, policy, spec, options=options, on_chunk=on_chunk, randomize=randomize
    )


def evaluate_spec(
    scene: str | Scene,
    policy: str | Policy,
    spec: RunSpec,
    *,
    options: Mapping[str, Any] | None = None,
    on_chunk: Callable[[int, int, int], None] | None = None,
    randomize: Sequence[str] = (),
    resume: EvalReport | None = None,
    decide: PairedRule | None = None,
    keep_finished: bool = False,
    build_s: Mapping[str, float] | None = None,
) -> Evaluation:
    """`run_evaluation` for a checked `RunSpec`: `scene` (a name: built from `options` as the
    spec says, and closed with the `Evaluation`) run under `policy`.

    A sequential run (`target_halfwidth`) stopped by a signal after its first look raises
    `Interrupted` with the report of the chunks of seeds every one of which finished (a
    prefix), marked partial; given that report as `resume`, the run goes on from the seed
    after them, its looks where the uninterrupted run's fall, and returns the whole run's
    report (its `arrays` and `timing` are those of the seeds run here).

    `decide` (a `PairedRule` over the spec's `n_episodes` seeds) stops the run at the first
    look that decides B against an earlier report; the report's `decision` says how. Stopped
    by a signal after a look, it raises `Interrupted` as a sequential run does (its `decision`
    "undecided", with the looks so far), and resumes the same way: the resumed run takes the
    same looks and reaches the same decision as an uninterrupted one.

    `keep_finished`: a fixed-size run does the same, keeping its seeds up to the last chunk
    of `n_envs` that finished, and resumes from there to the uninterrupted run's episodes.

    `build_s`: seconds the caller spent building the `scene` or `policy` it passes built
    (the report's `build_s`, beside what is built here)."""
    rule, n_episodes = spec.stopping_rule(), spec.episodes
    if decide is not None and (rule is not None or n_episodes != decide.cap):
        raise ConfigError(
            "a paired decision runs its own looks over its cap of seeds: give n_episodes = its "
            "cap, and no target_halfwidth"
        )
    seed, step_rewards = spec.seed, spec.step_rewards
    earlier = _resumed(resume, rule, decide, keep_finished)
    owned = contextlib.ExitStack()
    with owned, count_warnings() as warned:  # on an error, close what this call built
        building = dict(build_s or {})
        scene, pol = _scene_and_policy(scene, policy, spec, options, randomize, owned, building)
        policy = policy if isinstance(policy, str) else pol.name  # the report names it
        steps = scene.max_steps if spec.max_steps is None else spec.max_steps
        aligned = pol.aligned_episodes
        refill_every = spec.refill_every
        check_batching(spec.batching, scene.backend.name, refill_every, step_rewards, aligned)
        batching = resolve_batching(
            spec.batching, scene.backend.name, n_episodes, spec.n_envs, step_rewards, aligned
        )
        requested = np.arange(seed, seed + n_episodes, dtype=np.int64)
        before = np.array([e.success for e in earlier], bool)
        seen: dict[str, Any] = {}

        def until(arrays: dict[str, Any]) -> bool:
            """The stopping rule over every seed so far (a resumed run's earlier ones first),
            keeping the finished prefix for a partial report (a fixed-size run: only that)."""
            seen["arrays"] = arrays
            so_far = {"success": np.concatenate([before, arrays["success"]])}
            if decide is not None:
                return decide(so_far)
            return rule is not None and rule(so_far)

        stops = rule is not None or decide is not None

        with timed(building, "policy"):
            params, _ = pol.init(jax.random.PRNGKey(seed), scene.observation_spec)
        assemble = functools.partial(
            _report, scene, policy, spec, rule, batching, refill_every, steps, resume, warned
        )
        meta = {
            "scene": scene.name,
            "task": scene.task,
            "robot": scene.robot_name,
            "policy": policy,
            "backend": scene.backend.name,
        }
        episodes_of = functools.partial(
            episode_results,
            control_dt=scene.control_dt,
            metadata=meta,
            policy_latency=pol.latency_ms is not None,
            describe=scene.describe_episode,
        )
        start = time.perf_counter()
        try:
            arrays, timing = run_seeds(
                scene,
                pol,
                params,
                seeds=requested[len(earlier) :],
                n_envs=spec.n_envs,
                max_steps=steps,
                on_chunk=on_chunk,
                until=until if stops or keep_finished else None,
                record=("rewards",) if step_rewards else (),
                batching=batching,
                refill_every=refill_every,
            )
        except BaseException as e:
            signal = stop_signal(e)
            if signal is None or not (stops or keep_finished) or not (seen or earlier):
                raise
            # the seeds every chunk of which finished (a prefix), as a partial report
            arrays = seen.get("arrays", {"success": np.zeros(0, bool)})
            n = len(arrays["success"])
            stopper = rule if rule is not None else decide
            chunk = spec.n_envs if stopper is None else stopper.design.looks[0]
            timing = _stopped_timing(n, chunk, time.perf_counter() - start, steps)
            seeds = requested[len(earlier) : len(earlier) + n]
            episodes = episodes_of(arrays, seeds, timing) if n else []
            total = len(requested)
            partial = PartialInfo(stop_reason(signal), "episodes", len(earlier) + n, total)
            kept = assemble(episodes, timing, partial, build_s=building)
            if decide is not None:
                kept.decision = decide.info()
            raise Interrupted(signal, kept) from e
        n_new = len(arrays["success"])
        episodes = episodes_of(arrays, requested[len(earlier) : len(earlier) + n_new], timing)
        report = assemble(episodes, timing, build_s=building)
        if decide is not None:
            report.decision = decide.info()
        resources = owned.pop_all()  # handed to the Evaluation
    return Evaluation(report, scene, pol, params, requested, arrays, timing, resources)


def _scene_and_policy(
    scene: str | Scene,
    policy: str | Policy,
    spec: RunSpec,
    options: Mapping[str, Any] | None,
    randomize: Sequence[str],
    owned: contextlib.ExitStack,
    build_s: dict[str, float],
) -> tuple[Scene, Policy]:
    """The run's scene (built from its name as `spec` says, with the cameras a lerobot
    policy's features imply) with `randomize`'s factors, and its policy told the scene's
    instruction; what is built here is closed by `owned`, its seconds added to `build_s`."""
    if isinstance(scene, str):
        if isinstance(policy, str):  # a lerobot policy's cameras, unless options name them
            options = policy_options(scene, policy, options)
        with timed(build_s, "scene"):
            scene = build_spec_scene(scene, options, spec)
        owned.callback(scene.close)
    scene = randomization.randomize(scene, randomize)
    if isinstance(policy, str):
        with timed(build_s, "policy"):
            pol = make_policy(policy, scene)
        if pol.close is not None:
            owned.callback(pol.close)
    else:
        pol = policy
    if pol.instruct is not None:  # this task's (a suite shares one policy over its tasks)
        pol.instruct(scene.instruction)
    return scene, pol


@contextlib.contextmanager
def timed(seconds: dict[str, float], what: str) -> Iterator[None]:
    """Add the seconds the block takes to `seconds[what]` (a report's `build_s`)."""
    start = time.perf_counter()
    try:
        yield
    finally:
        seconds[what] = seconds.get(what, 0.0) + time.perf_counter() - start


def _stopped_timing(n: int, chunk: int, run_s: float, steps: int) -> RunTiming:
    """Timings of a run stopped by a signal after `n` seeds in looks of `chunk`: its wall time
    `run_s` (compiling included) spread evenly, as no chunk timings came back."""
    looks = -(-n // chunk)
    return RunTiming(0.0, run_s, (run_s / max(looks, 1),) * looks, steps, chunk)


def _resumed(
    resume: EvalReport | None,
    rule: SequentialRule | None,
    decide: PairedRule | None,
    keep_finished: bool = False,
) -> list[EpisodeResult]:
    """The episodes of the partial sequential, paired-decision or (`keep_finished`) fixed-size
    report a run resumes (none without one); a sequential design is fixed at the chunk that
    report's looks came after."""
    if resume is None:
        return []
    fixed = resume.sequential is None and resume.decision is None
    if rule is None and decide is None and keep_finished and fixed and resume.partial:
        return list(resume.episodes)
    if decide is not None and resume.decision is not None and resume.partial is not None:
        success = np.array([e.success for e in resume.episodes], bool)
        decide.resume(resume.decision, success)
        return list(resume.episodes)
    if rule is None or resume.sequential is None or resume.partial is None:
        raise ConfigError(
            "only a partial report of a sequential run (target_halfwidth), of a paired "
            "decision (its report's `decision`) or of a fixed-size run of the same kind resumes"
        )
    rule.fix(resume.sequential.chunk)
    return list(resume.episodes)


def _sequential_info(
    rule: SequentialRule,
    n_episodes: int,
    successes: int,
    interval: tuple[float, float],
    partial: PartialInfo | None,
) -> SequentialInfo:
    """The report's `sequential` block: the design, the looks taken and why the run stopped."""
    design = rule.design
    look = design.looks.index(n_episodes)
    stopped = "target" if design.meets_target(look, successes) else "max_episodes"
    return SequentialInfo(
        target_halfwidth=design.halfwidth,
        max_episodes=design.max_episodes,
        chunk=design.looks[0],
        looks=look + 1,
        stopped="interrupted" if partial is not None else stopped,
        halfwidth=(interval[1] - interval[0]) / 2,
        rule=RULE,
    )


def _report(
    scene: Scene,
    policy: str,
    spec: RunSpec,
    rule: SequentialRule | None,
    batching: str,
    refill_every: int,
    steps: int,
    resume: EvalReport | None,
    warned: Mapping[str, int],
    episodes: list[EpisodeResult],
    timing: RunTiming,
    partial: PartialInfo | None = None,
    *,
    build_s: Mapping[str, float] | None = None,
) -> EvalReport:
    """The report over `episodes` (after those of `resume`, whose timings add to `timing`'s)."""
    earlier = [] if resume is None else resume.episodes
    episodes = [*earlier, *episodes]
    n_episodes = len(episodes)
    success = np.array([e.success for e in episodes], bool)
    successes = int(success.sum())
    low, high = wilson_interval(successes, n_episodes)
    exact = rule is not None and partial is None
    if exact:  # a partial run did not stop by the design: Wilson's interval, not its own
        low, high = rule.design.interval(rule.design.looks.index(n_episodes), successes)
    sequential = None
    if rule is not None:
        sequential = _sequential_info(rule, n_episodes, successes, (low, high), partial)
    names = episodes[0].metadata["factors"] if episodes else {}
    factors = {k: [e.metadata["factors"][k] for e in episodes] for k in names}
    compile_s, run_s = timing.compile_s, timing.run_s
    env_steps, live_steps = timing.env_steps, float(sum(e.steps for e in episodes))
    if resume is not None:
        compile_s, run_s = compile_s + resume.compile_s, run_s + resume.run_s
        env_steps += resume.env_steps_per_s * resume.run_s
    run_s = max(run_s, 1e-9)
    return EvalReport(
        scene=scene.name,
        task=scene.task,
        robot=scene.robot_name,
        policy=policy,
        backend=scene.backend.name,
        device=device_description(scene),
        n_episodes=n_episodes,
        n_envs=timing.n_envs,
        seed=spec.seed,
        max_steps=steps,
        successes=successes,
        success_rate=successes / max(n_episodes, 1),
        ci_low=low,
        ci_high=high,
        confidence=0.95,
        ci_method="sequential-exact" if exact else "wilson",
        diverged=sum(bool(e.metadata.get("diverged")) for e in episodes),
        overflowed=sum(bool(e.metadata.get("overflowed")) for e in episodes),
        per_task=[
            TaskRow(
                scene.task,
                n_episodes,
                successes,
                successes / max(n_episodes, 1),
                low,
                high,
                instruction=scene.instruction,
            )
        ],
        breakdown=breakdown(factors, success, spec.factor_bins),
        env_steps_per_s=env_steps / run_s,
        episodes_per_s=n_episodes / run_s,
        live_env_steps_per_s=live_steps / run_s,
        compile_s=compile_s,
        run_s=run_s,
        control_dt_s=scene.control_dt,
        options={
            **to_dict(scene.options),
            "backend": scene.backend.describe(),
            "batching": batching if batching == "chunks" else f"refill every {refill_every}",
            **(
                {"randomize": scene.describe()}
                if isinstance(scene, randomization.Randomized)
                else {}
            ),
        },
        versions={**package_versions(), **_worker_versions(scene)},
        command=spec.command,
        created_at=dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        episodes=episodes,
        sequential=sequential,
        instruction=scene.instruction,
        partial=partial,
        mujoco_warnings=add_by_key([warned, {} if resume is None else resume.mujoco_warnings]),
        build_s=add_by_key([build_s or {}, {} if resume is None else resume.build_s]),
    )
