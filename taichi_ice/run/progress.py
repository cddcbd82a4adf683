"""What a long run says while it steps and how it stops: its progress on stderr (``Progress``:
compiling kernels, then a bar, drawn by rich) and SIGINT / SIGTERM noted and acted on at the
end of a stride (``StopRequest``), so that a run stopped by a signal closes its files at a
consistent state.
"""

from __future__ import annotations

import contextlib
import math
import signal
import sys
import threading
import time as _time
from typing import TextIO

# Outside a terminal and a notebook (a log file, CI), a plain line at most this often (s),
# as the hand-written bar wrote there before: sparse enough for the log of a long run.
LINE_EVERY = 15.0
# Redraws a second of the live bar (terminal, notebook): enough for a spinner to look alive,
# few enough for a notebook's output widget, which each redraw clears and fills again.
REFRESH_PER_SECOND = 4


def _now() -> float:
    # Looked up at each call, so that the tests' fake clock (progress._time) reaches it.
    return _time.perf_counter()


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
    """The progress of a run on stderr: compiling kernels, then simulated time, steps per
    second and the time left.

    Taichi compiles the kernels of a new layout at their first launch: seconds to minutes on
    2 cores (a scene of 16-vertex floes: 300 s), once per layout (Taichi's offline cache keeps
    them for the next run). Until the first stride is done the bar says ``compiling
    kernels`` and gives no rate; the rate and the time left count from the end of that
    stride, the steps on compiled kernels only, never from the run's start (compiling
    counted in had a 20 s run say "80 s left", issue 33). On a World whose kernels ran already
    (``World.compiled``) nothing compiles: no such phase, and the rate counts from the start.

    Where it shows (``mode``):

    - ``"live"``: a terminal, or a Jupyter notebook with ipywidgets (its output widget, through
      rich's Jupyter support): a rich progress bar redrawn in place, a few times a second.
    - ``"lines"``: anywhere else (a log file, CI, a pipe; a notebook without ipywidgets):
      plain lines, never a bar: one when compiling starts, one when the first stride is
      done, then at most one every ``LINE_EVERY`` s and one at the end: about 240 lines an
      hour, a short run 3.
    - ``"off"``: ``enabled=False`` (``--quiet``): nothing.

    Args:
        total: the step the run ends at.
        dt: the time step (s).
        enabled: show anything at all.
        stream: where to write; stderr (as it is when the Progress is made) by default.
    """

    def __init__(self, total: int, dt: float, enabled: bool = True, stream: TextIO | None = None):
        self.total, self.dt, self.enabled = max(total, 1), dt, enabled
        self.stream = sys.stderr if stream is None else stream
        self.mode, self._console = _where(self.stream) if enabled else ("off", None)
        self.start = _now()
        # Steps and clock where the steps on compiled kernels start counting; None while the
        # first stride (its compiling) is on.
        self.k0: int | None = None
        self.t0 = 0.0
        self.k = 0
        self.rate: float | None = None  # steps per second on compiled kernels
        self.left: float | None = None  # wall seconds left at that rate
        self._last_line: float | None = None  # the clock at the last plain line
        self._shown = -1  # the step of the last plain line
        self._bar = self._task = None
        decimals = max(0, 2 - math.floor(math.log10(max(self.total * dt, 1e-12))))
        self._decimals = min(decimals, 9)

    # ----------------------------------------------------------------------------------------
    # What the run says
    # ----------------------------------------------------------------------------------------

    def compiling(self, compiled: bool = False, step: int = 0) -> None:
        """Say, before the first stride, that the kernels compile first; or, ``compiled``,
        that nothing compiles: the rate counts from now and ``step`` (where the run starts)."""
        self.k = step
        if compiled:
            self.k0, self.t0 = step, _now()
        if self.mode == "live":
            self._open()
        elif self.mode == "lines" and not compiled:
            self._write(
                "compiling kernels (once per layout; Taichi keeps them for the next run) ..."
            )

    def update(self, k: int) -> None:
        """The run has stepped to step ``k`` (the end of a stride)."""
        now = _now()
        self.k = k
        first = self.k0 is None
        if first:  # the first stride is done: what took long was compiling
            self.k0, self.t0 = k, now
        if k > self.k0 and now > self.t0:
            self.rate = (k - self.k0) / (now - self.t0)
            self.left = (self.total - k) / self.rate
        if self.mode == "live":
            self._show(refresh=first)
        elif self.mode == "lines":
            if first:
                self._write(
                    f"kernels compiled: first stride done in {now - self.start:.1f} s "
                    f"(compiling included); the rate counts from here: {self.status()}"
                )
            elif self._last_line is None or now - self._last_line >= LINE_EVERY:
                self._write(self.status())

    def close(self) -> None:
        """The run has ended (or failed): the bar's last state stays, a plain line says it."""
        if self._bar is not None:
            self._show(refresh=True)  # in a notebook, stop() draws no last state
            self._bar.stop()
            self._bar = None
        elif self.mode == "lines" and self.k0 is not None and self._shown != self.k:
            self._write(self.status())

    # ----------------------------------------------------------------------------------------
    # Its words
    # ----------------------------------------------------------------------------------------

    def simulated(self) -> str:
        """``"0.20/1.00 s simulated"``: simulated time now and at the end."""
        d = self._decimals
        return f"{self.k * self.dt:.{d}f}/{self.total * self.dt:.{d}f} s simulated"

    def speed(self) -> str:
        return "-- steps/s" if self.rate is None else f"{self.rate:,.0f} steps/s"

    def time_left(self) -> str:
        if self.k >= self.total:  # a run done in its first stride has no rate, nor time left
            return "0 s left"
        if self.rate is None:
            return "time left: after the next stride"
        return f"{duration(self.left)} left"

    def status(self) -> str:
        """One line: how far, how fast, how long still."""
        return (
            f"{100 * self.k / self.total:3.0f}%  {self.simulated()}  {self.speed()}  "
            f"{self.time_left()}"
        )

    # ----------------------------------------------------------------------------------------
    # The live bar (rich)
    # ----------------------------------------------------------------------------------------

    def _open(self) -> None:
        from rich.progress import BarColumn, SpinnerColumn, TaskProgressColumn, TextColumn
        from rich.progress import Progress as Bar

        self._bar = Bar(
            SpinnerColumn(),
            TextColumn("{task.description}"),
            BarColumn(),
            TaskProgressColumn(),
            TextColumn("{task.fields[simulated]}"),
            TextColumn("{task.fields[speed]}"),
            TextColumn("{task.fields[left]}"),
            console=self._console,
            refresh_per_second=REFRESH_PER_SECOND,
            get_time=_now,
        )
        # Of unknown length (a pulsing bar) while the kernels compile: rich's update sets
        # no total back to None.
        total = None if self.k0 is None else self.total
        self._task = self._bar.add_task("", total=total, simulated="", speed="", left="")
        self._show()
        self._bar.start()

    def _show(self, refresh: bool = False) -> None:
        if self._bar is None:  # an update with no compiling() before it
            self._open()
        if self.k0 is None:
            fields = dict(description="compiling kernels", simulated="(once per layout)")
        else:
            fields = dict(
                description="stepping",
                total=self.total,
                simulated=self.simulated(),
                speed=self.speed(),
                left=self.time_left(),
            )
        self._bar.update(self._task, completed=self.k, refresh=refresh, **fields)

    def _write(self, text: str) -> None:
        self.stream.write(text + "\n")
        self.stream.flush()
        self._last_line, self._shown = _now(), self.k


def _where(stream: TextIO):
    """``("live", console)`` on a terminal or in a notebook that can show widgets, else
    ``("lines", None)``: plain lines."""
    from rich.console import Console

    console = Console(file=stream)
    if console.is_jupyter:  # an IPython kernel: stderr is no terminal, yet a bar shows
        try:
            import ipywidgets  # noqa: F401  (rich draws into its Output widget)
        except ImportError:
            return "lines", None
        return "live", console
    isatty = getattr(stream, "isatty", None)
    if isatty is not None and isatty() and console.is_interactive:  # not TERM=dumb
        return "live", console
    return "lines", None


def duration(seconds: float) -> str:
    """``"8 s"``, ``"2 min 05 s"``, ``"1 h 03 min"``."""
    s = round(seconds)
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"
