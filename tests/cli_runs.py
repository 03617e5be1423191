"""Run `python -m openral_mjx.eval` in this process, as the tests of the CLI do."""

from __future__ import annotations

import sys

import pytest

from openral_mjx import eval as eval_module


def run_cli(monkeypatch: pytest.MonkeyPatch, capsys, *argv: str) -> tuple[int, str, str]:
    """The exit code, stdout and stderr of ``eval ARGV``."""
    monkeypatch.setattr(sys, "argv", ["openral_mjx.eval", *argv])
    with pytest.raises(SystemExit) as exc:
        eval_module.main()
    out, err = capsys.readouterr()
    return exc.value.code, out, err
