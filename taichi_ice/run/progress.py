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
    """A one-line progress bar on stderr: simulated time, steps per second, time left.

    The first stride of a run compiles the kernels of a new layout (seconds to a minute on
    2 cores; Taichi's offline cache makes it quicker the next time). The bar says so while it
    waits (``compiling``) and counts its rate and time left from the end of that first
    stride, so that the compile time does not make the estimate of the rest wrong. On a
    World whose kernels ran already (``World.compiled``) it says nothing of compiling and
    counts from the start.
    """

    def __init__(self, total: int, dt: float, enabled: bool = True, width: int = 30):
        self.total, self.dt, self.enabled, self.width = max(total, 1), dt, enabled, width
        self.start = _time.perf_counter()
        self.last = 0.0
        # Steps and clock when the first stride (and its compiling) ended; None before.
        self.k0: int | None = None
        self.t0 = 0.0
        # On a terminal the bar redraws in place; in a log file it is a line every 15 s.
        self.tty = sys.stderr.isatty()
        self.every = 0.2 if self.tty else 15.0

    def compiling(self, compiled: bool = False, step: int = 0) -> None:
        """Say, before the first stride, that the kernels compile first; or, ``compiled``,
        that nothing compiles: the rate counts from now and ``step`` (where the run starts)."""
        if compiled:
            self.k0, self.t0 = step, _time.perf_counter()
            return
        if self.enabled:
            sys.stderr.write(
                "starting: the first stride compiles the kernels of a new layout "
                "(once per layout) ...\n"
            )
            sys.stderr.flush()

    def update(self, k: int) -> None:
        if not self.enabled:
            return
        now = _time.perf_counter()
        if self.k0 is None:  # the first stride is done: what took long was compiling
            self.k0, self.t0 = k, now
            sys.stderr.write(
                f"first stride done in {now - self.start:.1f} s (compiling included); "
                "the rate counts from here\n"
            )
        if now - self.last < self.every and k < self.total:
            return
        self.last = now
        frac = k / self.total
        if k > self.k0 and now > self.t0:
            rate = (k - self.k0) / (now - self.t0)
            speed, eta = f"{rate:8.0f} steps/s", f"{(self.total - k) / rate:5.0f} s left"
        else:
            speed, eta = "      -- steps/s", "time left: after the next stride"
        filled = int(self.width * frac)
        start, end = ("\r", " ") if self.tty else ("", "\n")
        sys.stderr.write(
            f"{start}[{'#' * filled}{'.' * (self.width - filled)}] {100 * frac:5.1f}%  "
            f"t = {k * self.dt:7.3f} s  {speed}  {eta}{end}"
        )
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled and self.tty:
            sys.stderr.write("\n")
            sys.stderr.flush()
