"""A process's clean stop (``edge.cli_args.stop_on_signals``): SIGTERM or SIGINT sets one event,
and a second signal never waits for the first's handler."""

from __future__ import annotations

import signal
import threading

import pytest

from superbody.edge.cli_args import stop_on_signals


@pytest.fixture
def handlers():
    old = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGINT)}
    yield
    for sig, h in old.items():
        signal.signal(sig, h)


@pytest.mark.parametrize("first", [signal.SIGTERM, signal.SIGINT])
def test_a_second_signal_does_not_wait_for_the_first_stop(handlers, first):
    stop = stop_on_signals()
    signal.getsignal(first)(first, None)  # type: ignore[operator]
    assert stop.is_set()
    second = signal.getsignal(signal.SIGTERM)
    # A signal handler runs in the main thread between any two of its steps, so a second signal
    # can arrive while the first handler's Event.set holds the event's lock. Held here, that lock
    # made the old handler (set the event again) wait forever; the second handler must not take it.
    done = threading.Event()
    with stop._cond:  # the lock Event.set holds
        t = threading.Thread(target=lambda: (second(signal.SIGTERM, None), done.set()), daemon=True)  # type: ignore[operator, func-returns-value]
        t.start()
        assert done.wait(2.0), "a second signal waited for the lock the first stop holds"
    t.join(2.0)

