"""The learning-curve PNG of a run, drawn from its metrics log (matplotlib, Agg: no display)."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path
from typing import Any

import numpy as np


def can_plot() -> bool:
    """Whether matplotlib is installed (the `train` extra)."""
    return importlib.util.find_spec("matplotlib") is not None


def _series(
    rows: list[dict[str, Any]], kind: str, key: str, after: int = -1
) -> tuple[np.ndarray, np.ndarray]:
    """(env steps in millions, values) of `key` over rows of `kind` past `after` env steps."""
    sel = [
        r for r in rows if r["kind"] == kind and r.get(key) is not None and r["env_steps"] > after
    ]
    return np.array([r["env_steps"] / 1e6 for r in sel]), np.array([r[key] for r in sel], float)


def plot_learning_curve(
    rows: list[dict[str, Any]], path: Path, title: str, warmup_steps: int = 0
) -> None:
    """Validation success (95% Wilson band) and training success over env steps, with the
    training episode return beneath; written atomically to `path`.

    Training statistics start after `warmup_steps`: until every env has run one full episode,
    the episodes that end are the ones cut short by the spread-out initial step counters.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True, height_ratios=(2, 1))
    x, y = _series(rows, "eval", "success_rate")
    _, lo = _series(rows, "eval", "ci_low")
    _, hi = _series(rows, "eval", "ci_high")
    n = next((r["n_episodes"] for r in rows if r.get("kind") == "eval"), 0)
    ax1.fill_between(x, 100 * lo, 100 * hi, alpha=0.25, color="C0", linewidth=0)
    ax1.plot(x, 100 * y, "o-", color="C0", label=f"validation ({n} held-out seeds, mean action)")
    xt, yt = _series(rows, "train", "train_success_rate", warmup_steps)
    ax1.plot(xt, 100 * yt, color="C1", alpha=0.7, label="training episodes (sampled actions)")
    ax1.set_ylabel("success rate (%)")
    ax1.set_ylim(0, 100)
    ax1.grid(alpha=0.3)
    ax1.legend(loc="lower right")
    ax1.set_title(title)
    xr, yr = _series(rows, "train", "episode_return", warmup_steps)
    ax2.plot(xr, yr, color="C2")
    ax2.set_ylabel("training episode return")
    ax2.set_xlabel("environment steps (millions)")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    os.replace(tmp, path)
