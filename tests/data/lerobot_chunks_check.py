"""Run in the lerobot environment by tests/policies/test_lerobot_chunks.py: `LerobotRunner`'s
per-env action chunks against lerobot's own `select_action`.

1. Every env starting together: the runner's actions are `select_action`'s on the batch.
2. Envs starting their episodes at different steps (one of them twice), as under continuous
   batching: each episode's actions are those `select_action` gives that env alone, from a
   reset, on the same observations.
Prints the largest differences; exits non-zero (an AssertionError) where they are not small.
"""

from __future__ import annotations

import sys
import tempfile

import torch

from openral_mjx.host.lerobot_server import LerobotRunner, build_random_policy

FEATURES = {"observation.images.top": [3, 12, 16], "observation.state": [5]}
N_ACTION_STEPS = 4  # of a chunk of 8: chunks are cut as lerobot cuts them
T = 14


def observations(n: int, seed: int) -> list[dict[str, torch.Tensor]]:
    g = torch.Generator().manual_seed(seed)
    return [
        {
            "observation.images.top": torch.rand(n, 12, 16, 3, generator=g),  # (n, H, W, C)
            "observation.state": torch.randn(n, 5, generator=g),
        }
        for _ in range(T)
    ]


def reference(runner: LerobotRunner, obs: list[dict[str, torch.Tensor]]) -> torch.Tensor:
    """lerobot's own loop for one batch from a reset: `select_action` step by step."""
    runner.policy.reset()
    out = []
    for o in obs:
        batch = runner.pre(runner.batch(o, "push the cube"))
        out.append(runner.post(runner.policy.select_action(batch)))
    return torch.stack(out)


def main(path: str) -> None:
    build_random_policy("act", path, FEATURES, 3, seed=1)
    with open(f"{path}/config.json") as f:
        text = f.read().replace('"n_action_steps": 8', f'"n_action_steps": {N_ACTION_STEPS}')
    with open(f"{path}/config.json", "w") as f:
        f.write(text)
    runner, ref = LerobotRunner(path, "cpu"), LerobotRunner(path, "cpu")
    assert runner.per_env and runner.n_action_steps == N_ACTION_STEPS
    torch.set_grad_enabled(False)

    # 1. together
    obs = observations(3, 0)
    got = torch.stack([runner(o, torch.full((3,), t), "push the cube") for t, o in enumerate(obs)])
    want = reference(ref, obs)
    together = float((got - want).abs().max())
    print(f"together: max |runner - select_action| = {together:.3g}")
    assert together <= 1e-6, together

    # 2. staggered: env 0 starts at 0, env 1 at 3, env 2 at 5 and again at 10
    starts = {0: [0], 1: [3], 2: [5, 10]}
    steps = torch.zeros(T, 3, dtype=torch.int64)
    for env, begins in starts.items():
        for i, b in enumerate(begins):
            end = begins[i + 1] if i + 1 < len(begins) else T
            steps[b:end, env] = torch.arange(end - b)
    obs = observations(3, 1)
    runner = LerobotRunner(path, "cpu")
    got = torch.stack([runner(o, steps[t], "push the cube") for t, o in enumerate(obs)])
    worst = 0.0
    for env, begins in starts.items():
        for i, b in enumerate(begins):
            end = begins[i + 1] if i + 1 < len(begins) else T
            alone = [{k: v[env : env + 1] for k, v in o.items()} for o in obs[b:end]]
            want = reference(ref, alone)[:, 0]
            worst = max(worst, float((got[b:end, env] - want).abs().max()))
    print(f"staggered: max |runner - select_action alone| = {worst:.3g}")
    assert worst <= 1e-5, worst
    print("OK")


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as d:
        main(sys.argv[1] if len(sys.argv) > 1 else d)
