"""SIGINT and SIGTERM as stops: which signal, its exit code, and handlers given back."""

import os
import signal

import pytest

from openral_mjx.core.interrupts import (
    EXIT_CODES,
    Terminated,
    signals_raise,
    stop_reason,
    stop_signal,
)


def test_sigterm_raises_terminated_and_handlers_come_back():
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(Terminated) as exc, signals_raise():
        os.kill(os.getpid(), signal.SIGTERM)
        signal.sigtimedwait([], 0)  # let the handler run
        raise AssertionError("not reached")
    assert stop_signal(exc.value) == "SIGTERM" and EXIT_CODES["SIGTERM"] == 143
    assert signal.getsignal(signal.SIGTERM) is before


def test_an_error_after_a_signal_leaves_as_that_stop_and_none_later():
    with pytest.raises(KeyboardInterrupt) as exc, signals_raise():
        try:
            os.kill(os.getpid(), signal.SIGINT)
            signal.sigtimedwait([], 0)
        except KeyboardInterrupt:
            raise RuntimeError("a JAX error around the interrupt") from None
    assert stop_signal(exc.value) == "SIGINT" and EXIT_CODES["SIGINT"] == 130
    assert isinstance(exc.value.__cause__, RuntimeError)
    assert stop_signal(RuntimeError("later, unrelated")) is None
    assert stop_reason("SIGINT") == "interrupted (SIGINT)"
    assert stop_reason("SIGTERM") == "terminated (SIGTERM)"
