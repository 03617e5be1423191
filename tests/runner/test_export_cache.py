"""The traced-episode cache: keyed by everything that decides the program, reused across runs."""

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from openral_mjx.policies import make_policy
from openral_mjx.runner import EpisodeRunner, compile_cache, export_cache
from openral_mjx.scenes import make_scene


def test_key_depends_on_every_part():
    base = dict(scene="s", options={"a": 1}, policy="scripted", max_steps=10)
    key = export_cache.cache_key(**base)
    assert export_cache.cache_key(**base) == key
    for part, value in (("options", {"a": 2}), ("policy", "zero"), ("max_steps", 11)):
        assert export_cache.cache_key(**{**base, part: value}) != key, part


def test_model_digest_follows_the_scene(push_c):
    other = make_scene("tabletop_push", {"cube_size": 0.031}, backend="c")
    same = make_scene("tabletop_push", {}, backend="c")
    digest = export_cache.model_digest(push_c.mj_model)
    assert export_cache.model_digest(same.mj_model) == digest
    assert export_cache.model_digest(other.mj_model) != digest


class _Stop(Exception):
    pass


def _keys(lower: Callable[[], Any], monkeypatch: pytest.MonkeyPatch) -> list[str | None]:
    """The export-cache keys `lower` asks for (stopped at the first, before any tracing)."""
    keys: list[str | None] = []

    def spy(fn, args, key, directory):
        keys.append(key)
        raise _Stop

    monkeypatch.setattr(export_cache, "lower", spy)
    with pytest.raises(_Stop):
        lower()
    monkeypatch.undo()
    return keys


def test_uncacheable_runs_have_no_key(push_c, push_mjx, monkeypatch):
    host_callbacks = EpisodeRunner(push_c, make_policy("zero", push_c), n_envs=2, max_steps=2)
    assert _keys(lambda: host_callbacks._lower_compile(None), monkeypatch) == [None]
    assert _keys(host_callbacks._compile_factors, monkeypatch) == [None]
    no_key = dataclasses.replace(make_policy("zero", push_mjx), cache_key=None)
    runner = EpisodeRunner(push_mjx, no_key, n_envs=2, max_steps=2)
    assert _keys(lambda: runner._lower_compile(None), monkeypatch) == [None]
    (factor_key,) = _keys(runner._compile_factors, monkeypatch)  # policy-independent
    assert factor_key is not None


@pytest.mark.heavy
@pytest.mark.usefixtures("xla_optimised")  # MJX's physics (tests/xla_level.py)
def test_second_run_reuses_the_traced_programs(push_mjx, tmp_path, monkeypatch):
    monkeypatch.setattr(compile_cache, "_EXPORT_DIR", tmp_path)
    policy = make_policy("zero", push_mjx)
    kw = dict(n_envs=2, max_steps=3)
    first, _ = EpisodeRunner(push_mjx, policy, **kw).run(None, np.arange(2))
    entries = sorted(tmp_path.iterdir())
    assert len(entries) == 3  # the episode and the two factor stages

    def no_tracing(*args, **kwargs):
        raise AssertionError("traced again despite a cached export")

    monkeypatch.setattr(export_cache.export, "export", no_tracing)
    second, _ = EpisodeRunner(push_mjx, policy, **kw).run(None, np.arange(2))
    for k in first:
        np.testing.assert_array_equal(first[k], second[k], err_msg=k)
    for entry in entries:  # a corrupt entry is rebuilt, not an error
        entry.write_bytes(b"garbage")
    monkeypatch.undo()
    monkeypatch.setattr(compile_cache, "_EXPORT_DIR", tmp_path)
    third, _ = EpisodeRunner(push_mjx, policy, **kw).run(None, np.arange(2))
    for k in first:
        np.testing.assert_array_equal(first[k], third[k], err_msg=k)
    assert all(entry.read_bytes() != b"garbage" for entry in entries)


@pytest.mark.parametrize("name", ["zero", "random", "scripted"])
def test_builtin_policies_declare_cache_keys(push_c, name):
    assert make_policy(name, push_c).cache_key == name
