"""Which scene observation feeds which lerobot input feature (no torch needed)."""

import json
from pathlib import Path
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation import build_scene
from openral_mjx.policies.lerobot import (
    check_cameras,
    implied_camera_options,
    key_map,
    lerobot_policy,
    read_features,
    scene_arrays,
    split_flat,
)

SD = jax.ShapeDtypeStruct
LIBERO_OBS = {
    "image": SD((64, 64, 3), np.uint8),
    "wrist_image": SD((64, 64, 3), np.uint8),
    "state": SD((8,), np.float32),
}


def test_libero_defaults_and_lerobot_aliases():
    features = {
        "observation.images.image": ("VISUAL", (3, 64, 64)),
        "observation.images.image2": ("VISUAL", (3, 64, 64)),
        "observation.state": ("STATE", (8,)),
    }
    assert key_map(features, LIBERO_OBS) == {
        "observation.images.image": "image",
        "observation.images.image2": "wrist_image",
        "observation.state": "state",
    }


def test_flat_observations_feed_both_state_features():
    features = {
        "observation.state": ("STATE", (27,)),
        "observation.environment_state": ("ENV", (27,)),
    }
    obs = {"obs": SD((27,), np.float32)}
    assert key_map(features, obs) == {
        "observation.state": "obs",
        "observation.environment_state": "obs",
    }


def test_metaworld_keys_as_lerobots_metaworld_env_names_them():
    """lerobot's MetaWorld env observes `pixels` (-> observation.image) and a 4-D `agent_pos`
    (-> observation.state); the metaworld scene uses the same names."""
    features = {"observation.image": ("VISUAL", (3, 64, 64)), "observation.state": ("STATE", (4,))}
    obs = {
        "obs": SD((39,), np.float32),
        "agent_pos": SD((4,), np.float32),
        "pixels": SD((64, 64, 3), np.uint8),
        "expert_action": SD((4,), np.float32),
    }
    assert key_map(features, obs) == {
        "observation.image": "pixels",
        "observation.state": "agent_pos",
    }


def test_pusht_and_aloha_keys_as_lerobots_gym_envs_name_them():
    """lerobot's PushT policies read `observation.image` (<- `pixels`, 96 x 96) or
    `observation.environment_state` (<- the 16 keypoints) and `observation.state` (<- the 2-D
    `agent_pos`); its ALOHA policies read `observation.images.top` (<- `top`, 480 x 640) and
    the 14-D `agent_pos`. The pusht and aloha scenes observe exactly these names and shapes."""
    state = ("STATE", (2,))
    pixels = {"pixels": SD((96, 96, 3), np.uint8), "agent_pos": SD((2,), np.float32)}
    image = {"observation.image": ("VISUAL", (3, 96, 96)), "observation.state": state}
    assert key_map(image, pixels) == {
        "observation.image": "pixels",
        "observation.state": "agent_pos",
    }
    keypoints = {"environment_state": SD((16,), np.float32), "agent_pos": SD((2,), np.float32)}
    env_state = {"observation.environment_state": ("ENV", (16,)), "observation.state": state}
    assert key_map(env_state, keypoints) == {
        "observation.environment_state": "environment_state",
        "observation.state": "agent_pos",
    }
    aloha = {"top": SD((480, 640, 3), np.uint8), "agent_pos": SD((14,), np.float32)}
    act = {
        "observation.images.top": ("VISUAL", (3, 480, 640)),
        "observation.state": ("STATE", (14,)),
    }
    assert key_map(act, aloha) == {
        "observation.images.top": "top",
        "observation.state": "agent_pos",
    }


def test_explicit_map_and_mismatches():
    features = {"observation.images.front": ("VISUAL", (3, 64, 64))}
    with pytest.raises(ConfigError, match="has no observation: tried \\['front', 'rgb_front'\\]"):
        key_map(features, LIBERO_OBS)
    assert key_map(features, LIBERO_OBS, {"observation.images.front": "wrist_image"}) == {
        "observation.images.front": "wrist_image"
    }
    with pytest.raises(ConfigError, match="are not inputs of the policy"):
        key_map(features, LIBERO_OBS, {"observation.images.back": "image"})
    small = {"observation.images.image": ("VISUAL", (3, 32, 32))}
    with pytest.raises(ConfigError, match="shape \\[3, 32, 32\\] does not fit observation 'image'"):
        key_map(small, LIBERO_OBS)


def test_policy_directory_checks(tmp_path, push_c):
    with pytest.raises(ConfigError, match="needs a directory"):
        lerobot_policy(push_c, None)
    with pytest.raises(ConfigError, match="does not exist"):
        lerobot_policy(push_c, str(tmp_path / "missing"))
    with pytest.raises(ConfigError, match=r"no config\.json"):
        lerobot_policy(push_c, str(tmp_path))
    (tmp_path / "config.json").write_text(
        json.dumps(
            {
                "input_features": {"observation.state": {"type": "STATE", "shape": [27]}},
                "output_features": {"action": {"type": "ACTION", "shape": [7]}},
            }
        )
    )
    assert read_features(tmp_path) == ({"observation.state": ("STATE", (27,))}, 7)
    with pytest.raises(ConfigError, match="outputs 7 action values; scene 'tabletop_push' takes 6"):
        lerobot_policy(push_c, str(tmp_path))


def test_sensor_slices_of_a_flat_observation_are_their_own_arrays():
    """Images in a flat observation reach the policy as images: `split_flat` cuts the vector
    by the scene's layout (the state first, then each sensor: put back together, it is the
    observation), and the state features take the state part."""
    options = {"obs_depth_cameras": ["front"], "obs_depth_size": [8, 6]}
    scene = build_scene("tabletop_push", options, backend="c")
    try:
        arrays = scene_arrays(scene)
        assert set(arrays) == {"obs", "depth_front"} and arrays["depth_front"].shape == (6, 8)
        obs = jax.random.normal(jax.random.PRNGKey(0), scene.observation_spec.shape)
        views = split_flat(scene, obs)
        assert views["obs"].shape == arrays["obs"].shape
        rebuilt = jnp.concatenate([views["obs"], views["depth_front"].reshape(-1)])
        np.testing.assert_array_equal(np.asarray(rebuilt), np.asarray(obs))
        state = {"observation.state": ("STATE", arrays["obs"].shape)}
        assert key_map(state, arrays) == {"observation.state": "obs"}
    finally:
        scene.close()


def _config(path, features):
    path.mkdir()
    inputs = {k: {"type": t, "shape": list(s)} for k, (t, s) in features.items()}
    config = {"input_features": inputs, "output_features": {"action": {"shape": [6]}}}
    (path / "config.json").write_text(json.dumps(config))
    return f"lerobot:{path}"


def test_a_policys_cameras_set_the_scenes_rgb_options(tmp_path):
    """The cameras and size a lerobot policy's config asks for become the scene's
    `obs_rgb_cameras`/`obs_rgb_size`, unless the user set them or the scene has no such
    options."""
    from openral_mjx.scenes import SCENES

    push = SCENES.get("tabletop_push").options_cls
    spec = _config(
        tmp_path / "act",
        {
            "observation.images.overhead": ("VISUAL", (3, 32, 48)),
            "observation.images.front": ("VISUAL", (3, 32, 48)),
            "observation.state": ("STATE", (24,)),
        },
    )
    want = {"obs_rgb_cameras": ["front", "overhead"], "obs_rgb_size": [48, 32]}
    assert implied_camera_options(spec, push, None) == want
    assert implied_camera_options(spec, push, {"obs_rgb_cameras": ["front"]}) == {}
    assert implied_camera_options(spec, SCENES.get("libero").options_cls, None) == {}
    assert implied_camera_options("scripted", push, None) == {}
    mixed = _config(
        tmp_path / "mixed",
        {
            "observation.images.overhead": ("VISUAL", (3, 32, 48)),
            "observation.images.front": ("VISUAL", (3, 64, 64)),
        },
    )
    assert implied_camera_options(mixed, push, None) == {}  # no one size fits both


LIBERO_FEATURES = {
    "observation.images.image": ("VISUAL", (3, 32, 32)),
    "observation.images.image2": ("VISUAL", (3, 32, 32)),
    "observation.state": ("STATE", (8,)),
}


def test_a_libero_policys_image_side_sets_image_size(tmp_path):
    """A policy saved for LIBERO (lerobot's `observation.images.image`/`image2`, square)
    sets `image_size` on the mirror and on the host scene, unless given; images of two sizes
    or not square imply nothing (`check_cameras` then says why)."""
    from openral_mjx.scenes import SCENES

    spec = _config(tmp_path / "act", LIBERO_FEATURES)
    for scene in ("libero_mjx", "libero"):
        options = SCENES.get(scene).options_cls
        assert implied_camera_options(spec, options, None) == {"image_size": 32}
        assert implied_camera_options(spec, options, {"image_size": 64}) == {}
    mirror = SCENES.get("libero_mjx").options_cls
    state_only = _config(tmp_path / "state", {"observation.state": ("STATE", (8,))})
    assert implied_camera_options(state_only, mirror, None) == {}
    wide = _config(tmp_path / "wide", {"observation.images.image": ("VISUAL", (3, 32, 48))})
    assert implied_camera_options(wide, mirror, None) == {}


def test_cameras_a_scene_cannot_serve_are_one_line_errors(tmp_path):
    """On a scene whose cameras follow option `image_size`: none rendered, or another size,
    is a one-line ConfigError naming the option's value to give."""
    path = Path(_config(tmp_path / "act", LIBERO_FEATURES).removeprefix("lerobot:"))
    flat = {"obs": SD((18,), np.float32)}
    none = SimpleNamespace(name="libero_mjx", options=SimpleNamespace(image_size=None))
    with pytest.raises(
        ConfigError, match="renders none without option image_size: --opt image_size=32"
    ) as e:
        check_cameras(none, "act", path, flat)
    assert "\n" not in str(e.value)
    big = SimpleNamespace(name="libero_mjx", options=SimpleNamespace(image_size=64))
    images = {
        "image": SD((64, 64, 3), np.uint8),
        "wrist_image": SD((64, 64, 3), np.uint8),
        "state": SD((8,), np.float32),
    }
    with pytest.raises(ConfigError, match="image_size=64: --opt image_size=32"):
        check_cameras(big, "act", path, images)
    right = SimpleNamespace(name="libero_mjx", options=SimpleNamespace(image_size=32))
    check_cameras(right, "act", path, images)  # the size the policy reads: no error
    wide = Path(
        _config(
            tmp_path / "wide", {"observation.images.image": ("VISUAL", (3, 32, 48))}
        ).removeprefix("lerobot:")
    )
    with pytest.raises(ConfigError, match="a policy whose images are square"):
        check_cameras(none, "wide", wide, flat)


def test_a_suite_takes_the_policys_image_size_too(tmp_path, monkeypatch):
    """`eval --suite` builds each task with the options a lerobot policy implies, as a single
    task does (a LIBERO policy's suite on the mirror ran without cameras before: one-line
    error "renders none without option image_size"); a given option still wins."""
    from openral_mjx.evaluation import RunSpec
    from openral_mjx.evaluation import suite as suite_module

    seen = []

    def build(scene, options, spec):
        seen.append(dict(options))
        raise ConfigError("stop here")

    monkeypatch.setattr(suite_module, "build_spec_scene", build)
    policy = _config(tmp_path / "act", LIBERO_FEATURES)
    spec = RunSpec(backend="c", n_envs=2, max_steps=2)
    for given, side in ((None, 32), ({"image_size": 64}, 64)):
        with pytest.raises(ConfigError, match="stop here"):
            suite_module.evaluate_suite("libero_mjx", "libero_object", policy, spec, options=given)
        assert seen[-1] == {"image_size": side, "task": "libero_object/0"}, seen[-1]
