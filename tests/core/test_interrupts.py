"""SIGINT and SIGTERM as stops: which signal, its exit code, and handlers given back."""

import logging
import os
import signal

import jax
import jax.numpy as jnp
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


def _call_back(fn) -> None:
    """Run `fn` as a JAX host callback inside a jitted function, as a host scene's step does."""
    out = jax.ShapeDtypeStruct((), jnp.float32)
    jax.jit(lambda x: jax.pure_callback(fn, out, x))(jnp.float32(0)).block_until_ready()


def test_a_host_callback_ended_by_a_stop_logs_no_traceback(caplog):
    """JAX logs an exception raised in a host callback with its traceback; a stop's is dropped
    (the run prints one line for it), any other exception's is still logged."""

    def stopped(x):
        raise KeyboardInterrupt

    def buggy(x):
        raise ValueError("a bug in the callback")

    with caplog.at_level(logging.ERROR), signals_raise():
        with pytest.raises(BaseException):  # noqa: B017 (whatever JAX wraps the stop in)
            _call_back(stopped)
        with pytest.raises(Exception, match="a bug in the callback"):
            _call_back(buggy)
    logged = [r.exc_info[1] for r in caplog.records if r.exc_info]
    assert [type(e) for e in logged] == [ValueError]
