"""Drawing the mass-seed protocol's initial states in several workers (`assets._draw`), with a
stand-in for LIBERO's worker: blocks kept in seed order whatever order they finish in, a
prefix kept when a worker fails, and draws of an older format drawn again."""

from __future__ import annotations

import contextlib
import random
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from openral_mjx.benchmarks.libero import assets
from openral_mjx.core.errors import ConfigError
from openral_mjx.host.pool import WorkerFailure


class _Worker:
    """Draws seed s as the state ``[s, s, s]`` after a random delay; fails at `fail_at`."""

    def __init__(self, fail_at: int | None) -> None:
        self.fail_at = fail_at
        self.rng = random.Random(threading.get_ident())

    def call(self, msg: dict, timeout: float) -> dict[str, np.ndarray]:
        start, stop = msg["kwargs"]["start"], msg["kwargs"]["stop"]
        time.sleep(self.rng.uniform(0.0, 0.05))
        if self.fail_at is not None and start <= self.fail_at < stop:
            raise WorkerFailure("worker died")
        seeds = np.arange(start, stop, dtype=np.float64)
        return {
            "states": np.repeat(seeds[:, None], 3, axis=1),
            "fixture_ids": np.array([4]),
            "fixture_pos": seeds[:, None, None] * np.ones((1, 1, 3)),
            "fixture_quat": np.ones((stop - start, 1, 4)),
        }


def _stand_in(monkeypatch, fail_at: int | None = None, cores: int = 3) -> None:
    @contextlib.contextmanager
    def task_worker(task: str) -> Iterator[tuple[_Worker, Path]]:
        yield _Worker(fail_at), Path("worker.log")

    monkeypatch.setattr(assets, "task_worker", task_worker)
    monkeypatch.setattr(assets, "SAMPLED_BLOCK", 2)
    monkeypatch.setattr(assets.os, "cpu_count", lambda: cores)


def test_blocks_are_kept_in_seed_order(monkeypatch, tmp_path) -> None:
    _stand_in(monkeypatch)
    path = tmp_path / "sampled.npz"
    have = assets._draw("libero_spatial/3", path, None, 0, 11)
    np.testing.assert_array_equal(have["states"][:, 0], np.arange(11))
    np.testing.assert_array_equal(have["fixture_pos"][:, 0, 0], np.arange(11))
    kept = assets._read_sampled(path)
    assert kept is not None and len(kept["states"]) == 11
    more = assets._draw("libero_spatial/3", path, kept, 11, 14)  # extended from where it was
    np.testing.assert_array_equal(more["states"][:, 0], np.arange(14))


def test_a_failed_worker_keeps_the_prefix_drawn_before_it(monkeypatch, tmp_path) -> None:
    _stand_in(monkeypatch, fail_at=6, cores=1)  # one worker: blocks 0-1, 2-3, 4-5, then fails
    path = tmp_path / "sampled.npz"
    with pytest.raises(ConfigError, match="initial states failed: worker died"):
        assets._draw("libero_spatial/3", path, None, 0, 11)
    kept = assets._read_sampled(path)
    assert kept is not None
    np.testing.assert_array_equal(kept["states"][:, 0], np.arange(6))


def test_draws_of_an_older_format_are_not_read(monkeypatch, tmp_path) -> None:
    _stand_in(monkeypatch)
    path = tmp_path / "sampled.npz"
    have = assets._draw("libero_spatial/3", path, None, 0, 2)
    old = {k: v for k, v in have.items() if k != "sampled_format"}  # as format 1 wrote them
    assets._write_npz(path, old)
    assert assets._read_sampled(path) is None
    assets._write_npz(path, have)
    assert assets._read_sampled(path) is not None
