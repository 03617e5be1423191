"""Torch policies for tests/policies/test_torch_policy.py
(`torch:tests/data/torch_policies.py:NAME`).

Each factory builds a small module from the observation spec and action size the evaluator
passes (by keyword, whichever its signature names); `tabletop_push` observes one flat vector,
so the modules take a (batch, n) tensor."""

from __future__ import annotations

import torch
from torch import nn


class Tail(nn.Module):
    """Action = the last `action_size` observation values (tabletop_push: cube pose and goal,
    which differ per env; the scene clips them to the servo ranges), copied with no arithmetic,
    so the batch's row order shows and a JAX twin gives the same bits."""

    def __init__(self, action_size: int) -> None:
        super().__init__()
        self.action_size = action_size

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return obs[:, -self.action_size :].clone()


def tail(action_size: int) -> nn.Module:
    return Tail(action_size)


def linear(observation_spec, action_size: int, device: str) -> nn.Module:
    """A fixed-weight linear layer (weights from a seeded generator), for comparison with the
    same map computed in numpy."""
    (size,), _ = observation_spec["obs"]
    layer = nn.Linear(size, action_size)
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        layer.weight.copy_(0.01 * torch.randn(action_size, size, generator=g))
        layer.bias.copy_(0.1 * torch.randn(action_size, generator=g))
    return layer.to(device)


class CountSteps(nn.Module):
    """Counts each env's steps since its last reset and returns the count in every action
    dimension: with resets per episode, step t of every episode acts t."""

    def __init__(self, action_size: int) -> None:
        super().__init__()
        self.action_size = action_size
        self.count: torch.Tensor | None = None
        self.resets: list[list[int]] = []

    def reset(self, envs: torch.Tensor) -> None:
        self.resets.append(envs.tolist())
        if self.count is None or self.count.shape[0] <= int(envs.max()):
            self.count = None  # a new batch size: forward starts every env at 0
        else:
            self.count[envs] = 0

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        n = obs.shape[0]
        if self.count is None or self.count.shape[0] != n:
            self.count = torch.zeros(n)
        out = self.count[:, None].repeat(1, self.action_size) * 1e-3
        self.count += 1
        return out


def count_steps(action_size: int) -> nn.Module:
    return CountSteps(action_size)


def wrong_size(action_size: int) -> nn.Module:
    """Returns one action value too many."""
    return Tail(action_size + 1)


NOT_A_FACTORY = 3
