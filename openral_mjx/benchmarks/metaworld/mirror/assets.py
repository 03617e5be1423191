"""MetaWorld's MuJoCo models, read from its installed package and compiled with our mujoco.

MetaWorld 3.1.1 pins mujoco 3.3.0, so it lives in its own worker environment (``metaworld``,
see `openral_mjx.host.envs`), created from the package registry on first use; its XML and
meshes are read from there (or from this interpreter's site-packages where MetaWorld is
installed beside us). Nothing is downloaded at run time beyond that environment's packages.
"""

from __future__ import annotations

import functools
import importlib.util
import subprocess
from pathlib import Path

import mujoco
import numpy as np

from openral_mjx.benchmarks.metaworld.worker_env import WELD_DATA
from openral_mjx.core.errors import ConfigError
from openral_mjx.host.envs import ensure_env

ENV = "metaworld"


@functools.cache
def package_dir() -> Path:
    """The installed ``metaworld`` package's directory."""
    spec = importlib.util.find_spec("metaworld")
    if spec is not None and spec.origin:
        return Path(spec.origin).parent
    python = ensure_env(ENV)
    out = subprocess.run(
        [python, "-c", "import metaworld, os; print(os.path.dirname(metaworld.__file__))"],
        capture_output=True,
        text=True,
    )
    if out.returncode != 0:
        raise ConfigError(
            f"cannot import metaworld in the {ENV!r} worker environment: {out.stderr}"
        )
    return Path(out.stdout.strip())


def load_spec(xml: str) -> mujoco.MjSpec:
    """The task's model as MetaWorld sets it up before its first reset (mocap welds reset)."""
    path = package_dir() / "assets" / xml
    if not path.is_file():
        raise ConfigError(f"MetaWorld asset {xml!r} not found under {path.parent}")
    spec = mujoco.MjSpec.from_file(str(path))
    for eq in spec.equalities:
        if eq.type == mujoco.mjtEq.mjEQ_WELD:
            data = np.array(eq.data, np.float64)  # mujoco >= 4 has a 12th entry: kept
            data[: len(WELD_DATA)] = WELD_DATA
            eq.data = data
    return spec
