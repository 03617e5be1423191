"""Run `python -m openral_mjx.eval` in this process, as the tests of the CLI do, and stop it
where a signal would."""

from __future__ import annotations

import os
import signal
import sys
import time

import pytest

from openral_mjx import eval as eval_module


def run_cli(monkeypatch: pytest.MonkeyPatch, capsys, *argv: str) -> tuple[int, str, str]:
    """The exit code, stdout and stderr of ``eval ARGV``."""
    monkeypatch.setattr(sys, "argv", ["openral_mjx.eval", *argv])
    with pytest.raises(SystemExit) as exc:
        eval_module.main()
    out, err = capsys.readouterr()
    return exc.value.code, out, err


def stop_at(monkeypatch, name, keyword, at, how):
    """Wrap `eval_module.<name>` so that its `keyword` callback stops the run (`how`: raise
    KeyboardInterrupt, or send this process SIGTERM) when called with first argument `at`."""
    real = getattr(eval_module, name)

    def wrapped(*args, **kwargs):
        inner = kwargs[keyword]

        def hook(i, *rest):
            if i == at:
                if how == "SIGTERM":
                    os.kill(os.getpid(), signal.SIGTERM)
                    time.sleep(5)  # the handler raises before this ends
                raise KeyboardInterrupt
            inner(i, *rest)

        return real(*args, **{**kwargs, keyword: hook})

    monkeypatch.setattr(eval_module, name, wrapped)


def per_seed(report) -> list[tuple]:
    """Each episode's seed, outcome, length and return: what a resumed run must give again."""
    return [(e.metadata["seed"], e.success, e.steps, e.total_reward) for e in report.episodes]
