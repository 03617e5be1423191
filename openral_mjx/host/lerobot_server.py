"""A lerobot policy served to the evaluator (runs in a worker of the ``lerobot-libero`` env).

`LerobotServer` loads a policy directory (``config.json``, ``model.safetensors`` and the
processor files lerobot writes next to them) with lerobot's own `from_pretrained`, from a
local path only, and answers one batched `act` per control step: the batch's observations,
already renamed to the policy's input features, go through the saved pre-processor,
`select_action` (which replays the policy's action chunk step by step) and the saved
post-processor. Images arrive as uint8 (n, H, W, C) and become float (n, C, H, W) in [0, 1],
lerobot's convention; the task's instruction goes in as ``task``, one string per env (what
VLA policies read; lerobot's evaluation passes it to every policy). `build_random_policy`
writes a small ACT or Diffusion policy with random weights the same way a trained one is
saved (for tests and for trying the pipeline).
"""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np


def _offline() -> None:
    for var in ("HF_HUB_OFFLINE", "HF_DATASETS_OFFLINE", "TRANSFORMERS_OFFLINE"):
        os.environ.setdefault(var, "1")


def _device(device: str | None) -> str:
    import torch

    if device:
        return device
    return "cuda" if torch.cuda.is_available() else "cpu"


class LerobotServer:
    """One lerobot policy on `device` (None: CUDA if torch sees a GPU, else the CPU).

    Args:
        path: local policy directory.
        device: torch device.
        seed: torch's RNG seed at every episode start (diffusion sampling draws noise).
    """

    def __init__(self, path: str, device: str | None = None, seed: int = 0) -> None:
        _offline()
        import torch
        from lerobot.configs.policies import PreTrainedConfig
        from lerobot.policies.factory import get_policy_class, make_pre_post_processors

        self.torch = torch
        self.device = _device(device)
        self.seed = seed
        config = PreTrainedConfig.from_pretrained(path, local_files_only=True)
        config.device = self.device
        cls = get_policy_class(config.type)
        self.policy = cls.from_pretrained(path, config=config, local_files_only=True)
        self.policy.to(self.device).eval()
        self.pre, self.post = make_pre_post_processors(
            config,
            pretrained_path=path,
            preprocessor_overrides={"device_processor": {"device": self.device}},
        )
        self.visual = {k for k, f in config.input_features.items() if f.type.value == "VISUAL"}

    def describe(self) -> dict[str, Any]:
        return {"device": self.device, "type": self.policy.config.type}

    def _batch(self, obs: dict[str, np.ndarray], task: str | None = None) -> dict[str, Any]:
        torch = self.torch
        batch: dict[str, Any] = {}
        n = 0
        for name, value in obs.items():
            t = torch.from_numpy(np.ascontiguousarray(value))
            if name in self.visual:
                t = t.permute(0, 3, 1, 2).float().div_(255.0)
            batch[name] = t.float()
            n = len(t)
        if task is not None:
            batch["task"] = [task] * n  # lerobot's language key: one string per batch row
        return batch

    def act(
        self, obs: dict[str, np.ndarray], reset: bool, task: str | None = None
    ) -> dict[str, Any]:
        """Actions (n, action_dim) for a batch of observations keyed by input feature; `reset`
        starts new episodes (clears the action queue, reseeds torch); `task` is the
        instruction every env's batch row carries. `ms` is the inference time here
        (pre-processing, model, post-processing)."""
        start = time.perf_counter()
        if reset:
            self.policy.reset()
            self.pre.reset()
            self.post.reset()
            self.torch.manual_seed(self.seed)
        with self.torch.inference_mode():
            action = self.post(self.policy.select_action(self.pre(self._batch(obs, task))))
        out = action.detach().to("cpu", self.torch.float32).numpy()
        return {"action": out, "ms": 1000 * (time.perf_counter() - start)}


def build_random_policy(
    kind: str, path: str, features: dict[str, list[int]], action_dim: int, seed: int = 0
) -> None:
    """Save a small `kind` ("act" or "diffusion") policy with random weights at `path`.

    `features` maps input feature names to shapes (``observation.images.*`` and PushT's
    ``observation.image``: (3, H, W); ``observation.state`` / ``observation.environment_state``:
    (d,)). Normalisation statistics
    are unit ones (mean 0 / std 1, min -1 / max 1), saved in the processor files as lerobot
    saves a trained policy's.
    """
    _offline()
    import torch
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies.factory import make_policy_config, make_pre_post_processors

    torch.manual_seed(seed)

    def kind_of(name: str) -> FeatureType:
        if name == "observation.image" or name.startswith("observation.images."):
            return FeatureType.VISUAL
        if name == "observation.environment_state":
            return FeatureType.ENV
        return FeatureType.STATE

    inputs = {k: PolicyFeature(type=kind_of(k), shape=tuple(s)) for k, s in features.items()}
    outputs = {"action": PolicyFeature(type=FeatureType.ACTION, shape=(action_dim,))}
    common = {"input_features": inputs, "output_features": outputs, "device": "cpu"}
    if kind == "act":
        config = make_policy_config(
            "act",
            **common,
            chunk_size=8,
            n_action_steps=8,
            dim_model=32,
            n_heads=2,
            dim_feedforward=64,
            n_encoder_layers=1,
            n_decoder_layers=1,
            use_vae=False,
            pretrained_backbone_weights=None,
        )
    elif kind == "diffusion":
        config = make_policy_config(
            "diffusion",
            **common,
            n_obs_steps=2,
            horizon=8,
            n_action_steps=4,
            down_dims=(16, 32),
            kernel_size=3,
            n_groups=4,
            diffusion_step_embed_dim=16,
            num_inference_steps=3,
            spatial_softmax_num_keypoints=8,
            crop_shape=None,
            pretrained_backbone_weights=None,
            use_group_norm=True,
        )
    else:
        raise ValueError(f"unknown policy kind {kind!r}; valid: act, diffusion")
    from lerobot.policies.factory import get_policy_class

    policy = get_policy_class(kind)(config)
    stats: dict[str, dict[str, Any]] = {}
    for name, feature in {**inputs, **outputs}.items():
        shape = (feature.shape[0], 1, 1) if feature.type is FeatureType.VISUAL else feature.shape
        stats[name] = {
            "mean": torch.zeros(shape),
            "std": torch.ones(shape),
            "min": -torch.ones(shape),
            "max": torch.ones(shape),
        }
    pre, post = make_pre_post_processors(config, dataset_stats=stats)
    policy.save_pretrained(path)
    pre.save_pretrained(path)
    post.save_pretrained(path)
