"""Reports with chosen per-seed outcomes, for the tests of the CLIs that read two reports
(`compare`, `plan compare --from`)."""

from __future__ import annotations

import dataclasses

from openral_mjx.report import EvalReport


def variant(report: EvalReport, outcomes, seeds=None, **fields) -> EvalReport:
    """`report` with the given per-episode successes (and seeds), totals kept consistent."""
    seeds = list(range(len(outcomes))) if seeds is None else list(seeds)
    template = report.episodes[0]
    episodes = [
        dataclasses.replace(
            template, success=bool(ok), metadata={**template.metadata, "seed": int(s)}
        )
        for ok, s in zip(outcomes, seeds, strict=True)
    ]
    k, n = int(sum(outcomes)), len(outcomes)
    row = dataclasses.replace(report.per_task[0], n_episodes=n, successes=k, success_rate=k / n)
    return dataclasses.replace(
        report,
        episodes=episodes,
        successes=k,
        n_episodes=n,
        success_rate=k / n,
        per_task=[row],
        **fields,
    )


def with_steps(report: EvalReport, steps: list[int], rewards: list[float] | None = None):
    """`report` whose episode i reached success at control step ``steps[i]`` (and, given
    `rewards`, collected ``rewards[i]``)."""
    rewards = [e.total_reward for e in report.episodes] if rewards is None else rewards
    episodes = [
        dataclasses.replace(
            e,
            steps=int(s),
            total_reward=float(r),
            metadata={**e.metadata, "first_success_step": int(s) if e.success else -1},
        )
        for e, s, r in zip(report.episodes, steps, rewards, strict=True)
    ]
    return dataclasses.replace(report, episodes=episodes)
