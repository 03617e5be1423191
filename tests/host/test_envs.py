"""Worker environments: created on first use from a recipe, reused, rebuilt when it changes."""

import subprocess
import sys

import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.host import envs

VERSION = f"{sys.version_info[0]}.{sys.version_info[1]}"


@pytest.fixture
def recipes(monkeypatch, tmp_path):
    monkeypatch.setenv("OPENRAL_MJX_ENVS", str(tmp_path))
    table = {"core": None, "tiny": envs.EnvRecipe(VERSION, (), "a bare venv")}
    monkeypatch.setattr(envs, "RECIPES", table)
    return table


def test_created_once_then_reused_and_rebuilt_on_a_new_recipe(recipes, tmp_path, capsys):
    python = envs.ensure_env("tiny")
    err = capsys.readouterr().err
    assert "creating worker environment 'tiny'" in err and "ready in" in err
    out = subprocess.run([python, "-c", "import sys; print(sys.prefix)"], capture_output=True)
    assert out.stdout.decode().strip() == str(tmp_path / "tiny")
    assert envs.ensure_env("tiny") == python and capsys.readouterr().err == ""
    recipes["tiny"] = envs.EnvRecipe(VERSION, (), "another note")
    assert not envs.is_ready("tiny")


def test_core_and_overrides(recipes, monkeypatch):
    assert envs.ensure_env("core") == sys.executable
    monkeypatch.setenv("OPENRAL_MJX_PYTHON_TINY", "/opt/my/python")
    assert envs.ensure_env("tiny") == "/opt/my/python"


def test_failures_name_the_command(recipes, monkeypatch):
    with pytest.raises(ConfigError, match="unknown worker environment 'nope'; valid: core, tiny"):
        envs.ensure_env("nope")
    recipes["tiny"] = envs.EnvRecipe("2.7", (), "old")
    with pytest.raises(ConfigError, match=r"need Python 2\.7"):
        envs.ensure_env("tiny")
    recipes["tiny"] = envs.EnvRecipe(VERSION, (("--no-index", "surely-not-a-package"),), "bad")
    with pytest.raises(ConfigError) as e:
        envs.ensure_env("tiny")
    assert "python -m openral_mjx.host.envs create tiny" in str(e.value)
    assert not envs.is_ready("tiny")
