"""The traced-episode cache: keyed by everything that decides the program, reused across runs."""

import dataclasses

import numpy as np
import pytest

from openral_mjx import compile_cache, export_cache
from openral_mjx.policies import make_policy
from openral_mjx.rollout import EpisodeRunner
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


def test_uncacheable_runs_have_no_key(push_c, push_mjx):
    host_callbacks = EpisodeRunner(push_c, make_policy("zero", push_c), n_envs=2, max_steps=2)
    assert host_callbacks._export_key(()) is None
    no_key = dataclasses.replace(make_policy("zero", push_mjx), cache_key=None)
    assert EpisodeRunner(push_mjx, no_key, n_envs=2, max_steps=2)._export_key(()) is None


def test_second_run_reuses_the_traced_episode(push_mjx, tmp_path, monkeypatch):
    monkeypatch.setattr(compile_cache, "_EXPORT_DIR", tmp_path)
    policy = make_policy("zero", push_mjx)
    kw = dict(n_envs=2, max_steps=3)
    first, _ = EpisodeRunner(push_mjx, policy, **kw).run(None, np.arange(2))
    (entry,) = tmp_path.iterdir()

    def no_tracing(*args, **kwargs):
        raise AssertionError("traced again despite a cached export")

    monkeypatch.setattr(export_cache.export, "export", no_tracing)
    second, _ = EpisodeRunner(push_mjx, policy, **kw).run(None, np.arange(2))
    for k in first:
        np.testing.assert_array_equal(first[k], second[k], err_msg=k)
    entry.write_bytes(b"garbage")  # a corrupt entry is rebuilt, not an error
    monkeypatch.undo()
    monkeypatch.setattr(compile_cache, "_EXPORT_DIR", tmp_path)
    third, _ = EpisodeRunner(push_mjx, policy, **kw).run(None, np.arange(2))
    np.testing.assert_array_equal(first["total_reward"], third["total_reward"])
    assert entry.read_bytes() != b"garbage"


@pytest.mark.parametrize("name", ["zero", "random", "scripted"])
def test_builtin_policies_declare_cache_keys(push_c, name):
    assert make_policy(name, push_c).cache_key == name
