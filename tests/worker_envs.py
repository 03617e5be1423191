"""Guard for tests that need worker environments (`openral_mjx.host.envs`)."""

from __future__ import annotations

import os

import pytest

from openral_mjx.host import envs


def require_worker_envs(*names: str, module: bool = True) -> None:
    """Skip the calling test module (or, with `module=False`, the calling test) unless worker
    environments `names` exist. On CI, which creates them (`.ci/run`), a missing one is an
    error, so a broken creation cannot turn the tests into silent skips."""
    for name in names:
        if envs.is_ready(name):
            continue
        if os.environ.get("CI"):
            raise RuntimeError(
                f"CI must create the worker environment: {envs.create_command(name)}"
            )
        pytest.skip(
            f"worker environment not created ({envs.create_command(name)})",
            allow_module_level=module,
        )
