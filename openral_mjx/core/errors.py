"""Typed errors: every user mistake is a `ConfigError` naming the bad value and the valid ones."""

from __future__ import annotations

from collections.abc import Iterable


class ConfigError(ValueError):
    """A user-facing configuration mistake (unknown name, bad value, missing file).

    The CLI prints its message on one line and exits with code 2; library callers catch it
    like any `ValueError`.
    """


def unknown(kind: str, value: object, valid: Iterable[object]) -> ConfigError:
    """Build the canonical "unknown X 'v'; valid: a, b, c" error."""
    choices = ", ".join(str(v) for v in valid) or "(none)"
    return ConfigError(f"unknown {kind} {value!r}; valid: {choices}")


class RunFailed(RuntimeError):
    """A run that could not finish for a reason outside the user's input (a task process
    killed by the system, e.g. for memory). The CLI prints its message on one line and exits
    with code 1; `report`, where set, holds what finished, marked partial, to resume from."""

    def __init__(self, message: str, report: object | None = None) -> None:
        super().__init__(message)
        self.report = report
