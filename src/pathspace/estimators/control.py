"""The clock and the brakes of a render: elapsed time without pauses, pausing, a deadline, cancelling.

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
"""
from __future__ import annotations

import threading
import time

__all__ = ["Interrupted", "RenderControl"]


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
        self.reason = ""  # why the render was cancelled; empty while it runs
        self.deadline: float | None = None  # render seconds after which check() stops the workers

    def start(self) -> None:
        """Start the clock."""
        self._start = time.perf_counter()

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

    @property
    def cancelled(self) -> bool:
        """Whether :meth:`cancel` was called."""
        return bool(self.reason)

    def check(self) -> None:
        """Called by workers between steps: wait while paused, raise :class:`Interrupted` if cancelled."""
        if self._paused_since is not None:
            self._running.wait()
        if self.reason:
            raise Interrupted(self.reason)
        if self.deadline is not None and self.elapsed() >= self.deadline:
            raise Interrupted("the time budget is spent")
