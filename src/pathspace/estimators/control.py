"""The clock and the brakes of a render: elapsed time without pauses, pausing, a deadline, stopping.

Estimators call :meth:`RenderControl.check` between wavefront steps (a
bounce, a subpath vertex, a batch of connections).  It returns at once while
the render runs, waits while it is paused (the render loop pauses it while
``on_checkpoint`` looks at the film, so that the time spent developing
snapshots is not render time, and the work done meanwhile is small), and
raises :class:`Interrupted` once the render has been cancelled (another
worker failed, or the user stopped it) or -- with a time budget -- its
deadline has passed: a running item checks the clock, so a budget is met
however long the paths are (the unfinished work is dropped; the film holds
whole passes only, possibly none: the render then says so).

:meth:`RenderControl.stop` asks for the same clean stop from anywhere,
including a signal handler: it only sets a flag, which the workers see at
their next check, so no exception is ever raised in the middle of NumPy or
the C extension.  :meth:`RenderControl.stop_on_signals` turns SIGINT
(Ctrl-C) and SIGTERM into such stops for the duration of a render.
"""
from __future__ import annotations

import signal
import threading
import time
from contextlib import contextmanager
from typing import Iterator

__all__ = ["Interrupted", "RenderControl", "STOP_SIGNALS"]

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)  # what stop_on_signals turns into a clean stop


class Interrupted(Exception):
    """Raised inside a worker when its render has been cancelled."""


class RenderControl:
    """Elapsed render time (wall time minus pauses), pause/resume, and cancellation."""

    def __init__(self) -> None:
        self._start: float | None = None
        self._paused_since: float | None = None
        self._paused_total = 0.0
        self._running = threading.Event()
        self._running.set()
        self.reason = ""  # why the render was cancelled or stopped; empty while it runs
        self.deadline: float | None = None  # render seconds after which check() stops the workers

    def start(self, offset: float = 0.0) -> None:
        """Start the clock at ``offset`` seconds: the render time of earlier sessions of a resumed render."""
        self._start = time.perf_counter() - offset

    def elapsed(self) -> float:
        """Seconds of rendering since :meth:`start`, pauses excluded."""
        if self._start is None:
            return 0.0
        now = self._paused_since if self._paused_since is not None else time.perf_counter()
        return now - self._start - self._paused_total

    def pause(self) -> None:
        """Stop the clock; workers wait at their next :meth:`check`."""
        if self._paused_since is None:
            self._paused_since = time.perf_counter()
            self._running.clear()

    def resume(self) -> None:
        """Restart the clock and the workers."""
        if self._paused_since is not None:
            self._paused_total += time.perf_counter() - self._paused_since
            self._paused_since = None
            self._running.set()

    def cancel(self, reason: str = "cancelled") -> None:
        """Stop the render: workers raise :class:`Interrupted` at their next :meth:`check`."""
        self.reason = reason or "cancelled"
        self._running.set()

    def stop(self, reason: str = "stopped") -> None:
        """Ask the render to stop at the workers' next :meth:`check`, keeping the passes it completed.

        Safe in a signal handler: it sets a flag and takes no lock (paused
        workers see it when the render resumes them).
        """
        self.reason = reason or "stopped"

    @contextmanager
    def stop_on_signals(self) -> Iterator[None]:
        """While in this block, SIGINT and SIGTERM :meth:`stop` the render (the reason is the signal's name,
        e.g. "SIGINT"); the first such signal restores the previous handlers, so a second one acts as it
        would have without this block.  Outside the main thread (where Python runs signal handlers) this
        does nothing."""
        if threading.current_thread() is not threading.main_thread():
            yield
            return
        # getsignal gives None for a handler installed from C: nothing Python can reinstall, so the default.
        previous = {number: signal.getsignal(number) or signal.SIG_DFL for number in STOP_SIGNALS}

        def restore() -> None:
            for number, handler in previous.items():
                signal.signal(number, handler)

        def handler(number: int, frame) -> None:
            restore()
            self.stop(signal.Signals(number).name)

        for number in STOP_SIGNALS:
            signal.signal(number, handler)
        try:
            yield
        finally:
            restore()

    @property
    def cancelled(self) -> bool:
        """Whether :meth:`cancel` or :meth:`stop` was called."""
        return bool(self.reason)

    def check(self) -> None:
        """Called by workers between steps: wait while paused, raise :class:`Interrupted` if cancelled."""
        if self._paused_since is not None:
            self._running.wait()
        if self.reason:
            raise Interrupted(self.reason)
        if self.deadline is not None and self.elapsed() >= self.deadline:
            raise Interrupted("the time budget is spent")
