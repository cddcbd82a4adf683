"""What a long run says while it steps and how it stops: a progress line on stderr
(``Progress``) and SIGINT / SIGTERM noted and acted on at the end of a stride
(``StopRequest``), so that a run stopped by a signal closes its files at a consistent state.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
import time as _time


class StopRequest:
    """SIGINT and SIGTERM while a run steps: noted, and acted on at the end of the stride.

    The run then stops at a consistent state: its files closed with the reason and, when it
    takes checkpoints, a last checkpoint to resume from. Only the main thread can catch
    signals; elsewhere the handlers are left as they are.
    """

    SIGNALS = ("SIGINT", "SIGTERM")

    def __init__(self):
        self.signal: str | None = None

    def _note(self, signum, frame) -> None:
        self.signal = signal.Signals(signum).name

    @contextlib.contextmanager
    def deferring(self):
        if threading.current_thread() is not threading.main_thread():
            yield
            return
        previous = {}
        for name in self.SIGNALS:
            sig = getattr(signal, name)
            previous[sig] = signal.signal(sig, self._note)
        try:
            yield
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, signal.SIG_DFL if handler is None else handler)


class Progress:
    """A one-line progress bar on stderr: simulated time, steps per second, time left."""

    def __init__(self, total: int, dt: float, enabled: bool = True, width: int = 30):
        self.total, self.dt, self.enabled, self.width = max(total, 1), dt, enabled, width
        self.start = _time.perf_counter()
        self.last = 0.0
        # On a terminal the bar redraws in place; in a log file it is a line every 15 s.
        self.tty = sys.stderr.isatty()
        self.every = 0.2 if self.tty else 15.0

    def update(self, k: int) -> None:
        if not self.enabled:
            return
        now = _time.perf_counter()
        if now - self.last < self.every and k < self.total:
            return
        self.last = now
        frac = k / self.total
        rate = k / max(now - self.start, 1e-9)
        eta = (self.total - k) / max(rate, 1e-9)
        filled = int(self.width * frac)
        start, end = ("\r", " ") if self.tty else ("", "\n")
        sys.stderr.write(
            f"{start}[{'#' * filled}{'.' * (self.width - filled)}] {100 * frac:5.1f}%  "
            f"t = {k * self.dt:7.3f} s  {rate:8.0f} steps/s  {eta:5.0f} s left{end}"
        )
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled and self.tty:
            sys.stderr.write("\n")
            sys.stderr.flush()
