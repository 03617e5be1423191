"""Which episodes to show, and their step-by-step record, by re-simulating their seeds.

The evaluation itself records nothing per step (it must not slow down for videos nobody asked
for); an episode is a function of its seed, so the chosen seeds are run again with the
runner's tracing variant. Where the backend's episodes do not depend on the batch layout
(`c`), a chosen seed runs alone with the other chosen ones; elsewhere (`mjx`, `warp`) it runs
inside the very batch it ran in during the evaluation (same seeds, same padding, same
devices). Each re-simulated episode is compared with the evaluated one (success, steps,
divergence, total reward bit for bit), and the video says whether they agree: on a GPU even
the same batch can come out differently (see the determinism table in docs/cli.md).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from openral_mjx.evaluation.run import Evaluation
from openral_mjx.runner import seed_chunks, trace_seeds

_COMPARED = ("success", "steps", "diverged", "total_reward")


@dataclasses.dataclass
class EpisodeTrace:
    """One episode, step by step (step 0 is the reset state; `steps + 1` entries each).

    `frame`: the scene's `frame_record` per step; `images`: the policy's image observations;
    `sensors`: the scene's sensor readings (`Scene.sensor_frames`); `action`: the action that
    led to each step (zero at step 0); `reward` per step.
    `outcome` is "success", "failure" or "diverged". `resimulated` says how the episode was
    re-run and `reproduced` whether it matched the evaluated episode exactly.
    """

    seed: int
    outcome: str
    steps: int
    reproduced: bool
    resimulated: str
    frame: dict[str, np.ndarray]
    images: dict[str, np.ndarray]
    sensors: dict[str, np.ndarray]
    action: np.ndarray
    reward: np.ndarray

    def provenance(self) -> str:
        """One phrase on how this episode was obtained, for titles and metadata."""
        agree = "same episode as evaluated" if self.reproduced else "DIFFERS from the evaluated"
        return f"{self.resimulated}: {agree}"


def outcome_of(success: bool, diverged: bool) -> str:
    return "success" if success else ("diverged" if diverged else "failure")


def choose_seeds(evaluation: Evaluation, first: int = 0, failures: int = 0) -> list[int]:
    """Seeds of the first `first` episodes, then of the first `failures` failed ones (a
    diverged episode is a failure), without repeats, in that order."""
    seeds = evaluation.seeds[: len(evaluation.arrays["success"])]
    failed = seeds[~evaluation.arrays["success"]]
    chosen = [int(s) for s in seeds[: max(first, 0)]]
    chosen += [int(s) for s in failed[: max(failures, 0)] if int(s) not in chosen]
    return chosen


def trace_episodes(evaluation: Evaluation, seeds: Sequence[int]) -> list[EpisodeTrace]:
    """Re-simulate `seeds` of `evaluation` (see the module docstring) and return each episode,
    cut at its last step (finished envs keep simulating in lock-step; that is not shown)."""
    if not seeds:
        return []
    ev, backend = evaluation, evaluation.scene.backend
    index = {int(s): i for i, s in enumerate(ev.seeds)}
    unknown = [s for s in seeds if s not in index or index[s] >= len(ev.arrays["success"])]
    if unknown:
        raise ValueError(f"seeds {unknown} were not evaluated")
    batch_of = None
    how = f"re-simulated alone on {backend.name} (episodes do not depend on the batch)"
    if not backend.layout_invariant:
        chunks = seed_chunks(ev.seeds, ev.timing.n_envs)
        batch_of = lambda s: chunks[index[s] // ev.timing.n_envs]  # noqa: E731
        how = f"re-simulated on {backend.name} in its evaluation batch of {ev.timing.n_envs}"
        if ev.timing.batch_steps is not None:  # continuous batching: no fixed batch to re-run
            how = f"re-simulated on {backend.name} in a batch of {ev.timing.n_envs} seeds"
    arrays, trace = trace_seeds(
        ev.scene,
        ev.policy,
        ev.params,
        seeds=list(seeds),
        max_steps=ev.report.max_steps,
        batch_of=batch_of,
    )
    out = []
    for k, seed in enumerate(seeds):
        i = index[seed]
        same = all(_identical(arrays[f][k], ev.arrays[f][i]) for f in _COMPARED)
        n = int(arrays["steps"][k]) + 1

        def cut(tree: Any, k: int = k, n: int = n) -> Any:
            return {name: np.asarray(v[k, :n]) for name, v in tree.items()}

        out.append(
            EpisodeTrace(
                seed=int(seed),
                outcome=outcome_of(bool(arrays["success"][k]), bool(arrays["diverged"][k])),
                steps=n - 1,
                reproduced=same,
                resimulated=how,
                frame=cut(trace["frame"]),
                images=cut(trace["images"]),
                sensors=cut(trace["sensors"]),
                action=np.asarray(trace["action"][k, :n]),
                reward=np.asarray(trace["reward"][k, :n]),
            )
        )
    return out


def _identical(a: Any, b: Any) -> bool:
    """Equal values, and for floats equal bits (a reward off in the last bit is another run)."""
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.kind == "f":
        return a.dtype == b.dtype and a.tobytes() == b.tobytes()
    return bool(np.array_equal(a, b))
