"""Scene options from YAML and `--opt`: numbers in every notation Python's `float()` takes,
finite only; YAML errors in one line."""

from __future__ import annotations

import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.options import load_yaml, parse_overrides, yaml_value
from openral_mjx.scenes import scene_options


@pytest.mark.parametrize(
    "text, number",
    [("5e-2", 5e-2), ("1e6", 1e6), ("-1E+3", -1e3), (".5e1", 5.0), ("2.5", 2.5), ("3", 3)],
)
def test_every_float_notation_reads_as_a_number(text, number):
    """YAML 1.1 (PyYAML) would keep `5e-2` and `1e6` as strings."""
    assert yaml_value(text) == number and type(yaml_value(text)) is type(number)
    assert parse_overrides([f"cube_mass={text}"]) == {"cube_mass": number}


@pytest.mark.parametrize("text", ["1e", "e5", "abc", "1e-2x"])
def test_what_is_not_a_number_stays_a_string(text):
    assert yaml_value(text) == text


def test_options_take_exponent_notation_from_opt_and_config(tmp_path):
    options = scene_options("tabletop_push", parse_overrides(["cube_mass=5e-2"]))
    assert options.cube_mass == 0.05
    config = tmp_path / "c.yaml"
    config.write_text("cube_mass: 4e-2\ngoal_distance: [5e-2, 1e-1]\n")
    options = scene_options("tabletop_push", load_yaml(config))
    assert options.cube_mass == 0.04 and options.goal_distance == (0.05, 0.1)


@pytest.mark.parametrize("value", [".inf", "-.inf", ".nan"])
def test_non_finite_options_are_refused(value):
    with pytest.raises(ConfigError, match="expected a finite number"):
        scene_options("tabletop_push", parse_overrides([f"cube_mass={value}"]))


def test_yaml_errors_are_one_line(tmp_path):
    config = tmp_path / "c.yaml"
    config.write_text("cube_mass: [0.1\ncube_size: 0.03\n")
    with pytest.raises(ConfigError, match=r"line 2, column \d+$") as exc:
        load_yaml(config)
    assert "\n" not in str(exc.value)


def test_an_option_that_may_be_unset_says_so_and_takes_null():
    needle = r"option image_size='none': expected an integer or null$"
    with pytest.raises(ConfigError, match=needle):
        scene_options("libero_mjx", parse_overrides(["image_size=none"]))
    assert scene_options("libero_mjx", parse_overrides(["image_size=null"])).image_size is None
    assert scene_options("libero_mjx", parse_overrides(["image_size=64"])).image_size == 64
