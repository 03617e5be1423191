"""Looking at rollouts: episode videos (`video`), report plots (`plots`); headless GL is
`physics.gl`.

Everything here runs after the batched rollout, on the host, and needs the optional `viz`
extra (matplotlib, PyAV): `pip install 'openral_mjx[viz]'`.
"""

from __future__ import annotations

import importlib.util

from openral_mjx.core.errors import ConfigError

INSTALL_HINT = "pip install 'openral_mjx[viz]'"
_MODULES = {"matplotlib": "matplotlib", "av": "PyAV"}


def require_viz() -> None:
    """Raise a `ConfigError` naming the install command if the `viz` extra is missing."""
    missing = [name for mod, name in _MODULES.items() if importlib.util.find_spec(mod) is None]
    if missing:
        raise ConfigError(
            f"videos and plots need {' and '.join(missing)}; install them with {INSTALL_HINT}"
        )
