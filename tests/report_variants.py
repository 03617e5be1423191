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


def suite_variant(report: EvalReport, outcomes: dict, suite: str = "mt3", **fields) -> EvalReport:
    """A suite run's report (as `eval --suite` writes one): `outcomes[task]` the successes of
    that task's seeds 0..n-1, one `per_task` row each, episodes naming their task."""
    rows, episodes = [], []
    for task, ok in outcomes.items():
        one = variant(report, ok, task=task)
        rows.append(dataclasses.replace(one.per_task[0], task=task))
        episodes += [
            dataclasses.replace(e, metadata={**e.metadata, "task": task}) for e in one.episodes
        ]
    k = sum(e.success for e in episodes)
    return dataclasses.replace(
        report,
        task=suite,
        episodes=episodes,
        per_task=rows,
        successes=k,
        n_episodes=len(episodes),
        success_rate=k / len(episodes),
        breakdown=[],
        **fields,
    )
