"""A lerobot policy served to the evaluator (runs in a worker of the ``lerobot-libero`` env).

`LerobotRunner` loads a policy directory (``config.json``, ``model.safetensors`` and the
processor files lerobot writes next to them) with lerobot's own `from_pretrained`, from a
local path only, and acts for a batch of envs per control step: the batch's observations,
already renamed to the policy's input features, go through the saved pre-processor, the
policy (action chunks replayed per env, see `LerobotRunner`) and the saved post-processor.
Images arrive as (n, H, W, C), uint8 or float in [0, 1], and become float (n, C, H, W) in
[0, 1], lerobot's convention; the task's instruction goes in as ``task``, one string per env
(what VLA policies read; lerobot's evaluation passes it to every policy). It runs in the
evaluator's process where lerobot imports there, else in a worker as `LerobotServer`, which
answers one batched `act` per control step over the pipe. `build_random_policy`
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


class LerobotRunner:
    """One lerobot policy on `device` (None: CUDA if torch sees a GPU, else the CPU), acting
    for a batch of envs on torch tensors; the evaluator runs it in process where lerobot
    imports (`policies.lerobot`), else `LerobotServer` runs it in a worker.

    Action chunks are kept per env, as lerobot's `select_action` keeps them for one env: an
    env whose episode starts (step 0) or whose chunk is used up gets a new chunk from
    `predict_action_chunk` on its own observation, and its next `n_action_steps` actions come
    from it; the others go on with theirs. So envs that start their episodes at different
    steps (continuous batching) each see the episode lerobot would give them alone; with every
    env starting together, the actions are those of `select_action` on the batch. Policies
    that keep an observation history (Diffusion's `n_obs_steps` > 1) or blend chunks
    (temporal ensembling) run `select_action` on the whole batch instead, reset when every env
    starts: `per_env` is False and the evaluator runs them in aligned chunks.

    Args:
        path: local policy directory.
        device: torch device.
        seed: torch's RNG seed when the policy is built and, for whole-batch policies, at
            every episode start (diffusion sampling draws noise).
    """

    def __init__(self, path: str, device: str | None = None, seed: int = 0) -> None:
        _offline()
        import torch
        from lerobot.configs.policies import PreTrainedConfig
        from lerobot.policies.factory import get_policy_class, make_pre_post_processors

        self.torch = torch
        self.device = _device(device)
        self.seed = seed
        torch.manual_seed(seed)
        config = PreTrainedConfig.from_pretrained(path, local_files_only=True)
        config.device = self.device
        cls = get_policy_class(config.type)
        self.policy = cls.from_pretrained(path, config=config, local_files_only=True)
        self.policy.to(self.device).eval()
        on_device = {"device_processor": {"device": self.device}}
        self.pre, self.post = make_pre_post_processors(
            config,
            pretrained_path=path,
            preprocessor_overrides=on_device,
            postprocessor_overrides=on_device,  # actions stay where the evaluator reads them
        )
        self.visual = {k for k, f in config.input_features.items() if f.type.value == "VISUAL"}
        self.n_action_steps = int(getattr(config, "n_action_steps", 1) or 1)
        self.per_env = (
            hasattr(self.policy, "predict_action_chunk")
            and int(getattr(config, "n_obs_steps", 1) or 1) == 1
            and getattr(config, "temporal_ensemble_coeff", None) is None
        )
        self.chunk: Any = None  # (n, n_action_steps, action_dim): each env's current chunk
        self.index: Any = None  # (n,) int64: each env's next action in it

    def describe(self) -> dict[str, Any]:
        return {"device": self.device, "type": self.policy.config.type, "per_env": self.per_env}

    def batch(self, obs: dict[str, Any], task: str | None) -> dict[str, Any]:
        """lerobot's batch: images (n, H, W, C), uint8 or float in [0, 1], become float
        (n, C, H, W) in [0, 1]; the rest float; `task` one string per row."""
        out: dict[str, Any] = {}
        n = 0
        for name, t in obs.items():
            t = t.to(self.device)
            if name in self.visual:
                t = t.permute(0, 3, 1, 2)
                t = t.float().div_(255.0) if t.dtype == self.torch.uint8 else t.float()
            out[name] = t.float()
            n = t.shape[0]
        if task is not None:
            out["task"] = [task] * n  # lerobot's language key: one string per batch row
        return out

    def __call__(self, obs: dict[str, Any], steps: Any, task: str | None = None) -> Any:
        """Actions (n, action_dim) on the policy's device for a batch of observations keyed
        by input feature; `steps`: each env's control step in its episode (0: it starts)."""
        torch = self.torch
        steps = steps.to(self.device).reshape(-1)
        if not self.per_env:
            if bool((steps == 0).all()):
                self.policy.reset()
                self.pre.reset()
                self.post.reset()
                torch.manual_seed(self.seed)
            return self.post(self.policy.select_action(self.pre(self.batch(obs, task))))
        n, size = steps.shape[0], self.n_action_steps
        if self.index is None or self.index.shape[0] != n:
            self.index = torch.full((n,), size, dtype=torch.int64, device=self.device)
            self.chunk = None
        index = torch.where(steps == 0, size, self.index)
        rows = torch.nonzero(index >= size).reshape(-1)
        if rows.numel():
            sub = {k: v[rows.to(v.device)] for k, v in obs.items()}
            chunk = self.policy.predict_action_chunk(self.pre(self.batch(sub, task)))[:, :size]
            if self.chunk is None:
                self.chunk = torch.zeros(
                    (n, *chunk.shape[1:]), dtype=chunk.dtype, device=chunk.device
                )
            self.chunk[rows] = chunk
            index[rows] = 0
        action = self.chunk[torch.arange(n, device=self.device), index]
        self.index = index + 1
        return self.post(action)


class LerobotServer:
    """`LerobotRunner` behind the worker pipe: numpy in, numpy out (see the module doc)."""

    def __init__(self, path: str, device: str | None = None, seed: int = 0) -> None:
        self.runner = LerobotRunner(path, device, seed)
        self.torch = self.runner.torch

    def describe(self) -> dict[str, Any]:
        return self.runner.describe()

    def act(
        self, obs: dict[str, np.ndarray], steps: list[int], task: str | None = None
    ) -> dict[str, Any]:
        """Actions (n, action_dim) for a batch of observations keyed by input feature;
        `steps`: each env's control step in its episode (0: it starts); `task` is the
        instruction every env's batch row carries. `ms` is the inference time here
        (pre-processing, model, post-processing)."""
        torch = self.torch
        start = time.perf_counter()
        tensors = {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in obs.items()}
        with torch.inference_mode():
            action = self.runner(tensors, torch.as_tensor(np.asarray(steps)), task)
        out = action.detach().to("cpu", torch.float32).numpy()
        return {"action": out, "ms": 1000 * (time.perf_counter() - start)}


def build_random_policy(
    kind: str,
    path: str,
    features: dict[str, list[int]],
    action_dim: int,
    seed: int = 0,
    size: str = "small",
) -> None:
    """Save a small `kind` ("act" or "diffusion") policy with random weights at `path`.

    `features` maps input feature names to shapes (``observation.images.*`` and PushT's
    ``observation.image``: (3, H, W); ``observation.state`` / ``observation.environment_state``:
    (d,)). Normalisation statistics
    are unit ones (mean 0 / std 1, min -1 / max 1), saved in the processor files as lerobot
    saves a trained policy's. `size`: "small" (a few thousand weights, for tests) or
    "default" (lerobot's own sizes for `kind`, e.g. ACT's ResNet-18 and 512-wide transformer;
    the backbone random too, nothing downloaded).
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
    small = {
        "act": dict(
            chunk_size=8,
            n_action_steps=8,
            dim_model=32,
            n_heads=2,
            dim_feedforward=64,
            n_encoder_layers=1,
            n_decoder_layers=1,
            use_vae=False,
        ),
        "diffusion": dict(
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
            use_group_norm=True,
        ),
    }
    if size not in ("small", "default"):
        raise ValueError(f"unknown policy size {size!r}; valid: small, default")
    if kind in small:
        sizes = small[kind] if size == "small" else {}
        config = make_policy_config(kind, **common, **sizes, pretrained_backbone_weights=None)
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
