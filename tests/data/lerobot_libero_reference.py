"""Run in the lerobot environment by tests/benchmarks/libero/test_libero_mjx_lerobot.py: what
lerobot's own LIBERO env hands a policy, as the reference for `libero_mjx`'s.

``python lerobot_libero_reference.py IN.npz OUT.npz``: IN holds ``task`` (``suite/index``),
``size`` (the cameras' side), ``seeds`` (n,) and ``actions`` (n, T, 7). For each seed, one
lerobot `LiberoEnv` (episode index and reset seed the seed: LIBERO's initial state ``seed mod
50``, its fixtures placed as `libero_mjx` places them) resets and plays that seed's actions;
after the reset and every step its observation goes through lerobot's
`preprocess_observation` and `LiberoProcessorStep`, as lerobot's evaluation feeds a policy.
OUT holds each policy input feature as (n, T + 1, ...) and ``task`` (the env's
``task_description``, what lerobot hands VLA policies).
"""

from __future__ import annotations

import sys

import numpy as np


def main(src: str, dst: str) -> None:
    from openral_mjx.benchmarks.libero.worker_env import configure

    assets = configure()  # LIBERO's config and assets, as the host scene's workers find them
    import libero.libero as libero_pkg

    libero_pkg._assets_path_cache = str(assets)
    from lerobot.envs.libero import LiberoEnv, _get_suite
    from lerobot.envs.utils import preprocess_observation
    from lerobot.processor.env_processor import LiberoProcessorStep

    inputs = np.load(src)
    suite_name, _, index = str(inputs["task"]).partition("/")
    size = int(inputs["size"])
    suite = _get_suite(suite_name)
    step = LiberoProcessorStep()
    frames: dict[str, list[list[np.ndarray]]] = {}

    def record(obs: dict, row: int) -> None:
        batched = _batch(obs)
        processed = step.observation(preprocess_observation(batched))
        for key, value in processed.items():
            frames.setdefault(key, [[] for _ in inputs["seeds"]])[row].append(value[0].numpy())

    env = LiberoEnv(
        suite,
        int(index),
        suite_name,
        observation_width=size,
        observation_height=size,
        obs_type="pixels_agent_pos",
    )
    for row, seed in enumerate(inputs["seeds"].tolist()):
        env.init_state_id = int(seed)  # the episode index lerobot's vector env gives env `seed`
        obs, _ = env.reset(seed=int(seed))
        record(obs, row)
        for action in inputs["actions"][row]:
            obs, *_ = env.step(np.asarray(action, np.float64))
            record(obs, row)
    task = env.task_description
    env.close()
    out = {key: np.stack([np.stack(f) for f in rows]) for key, rows in frames.items()}
    np.savez(dst, task=np.array(task), **out)


def _batch(obs: dict) -> dict:
    """One env's observation as a batch of one (lerobot's vector envs hand batches over)."""
    if isinstance(obs, dict):
        return {k: _batch(v) for k, v in obs.items()}
    return np.asarray(obs)[None]


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
