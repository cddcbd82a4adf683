"""The progress of a run: the first stride compiles, and the rate and time left count from
its end (issue 30, item 4); rich draws it on a terminal and in a notebook, plain lines at most
every 15 s elsewhere, nothing with --quiet (issue 33, item 4). A fake clock, no Taichi but in
the last test, a real run in a subprocess."""

from __future__ import annotations

import builtins
import io
import re
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from taichi_ice.run import progress
from taichi_ice.run.progress import Progress, duration

ROOT = Path(__file__).resolve().parents[1]
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|\x1b\][^\x07]*\x07")


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


class Terminal(io.StringIO):
    """What rich takes for a terminal: a stream that says it is a tty."""

    def isatty(self) -> bool:
        return True


@pytest.fixture
def clock(monkeypatch):
    clock = Clock()
    monkeypatch.setattr(progress._time, "perf_counter", clock)
    return clock


@pytest.fixture
def wide_terminal(monkeypatch):
    """A terminal wide enough for the whole bar, whatever the one running the tests."""
    monkeypatch.setenv("COLUMNS", "200")
    monkeypatch.setenv("TERM", "xterm-256color")
    for name in ("TTY_INTERACTIVE", "TTY_COMPATIBLE", "NO_COLOR", "FORCE_COLOR"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.delattr(builtins, "get_ipython", raising=False)


def test_the_time_left_counts_from_the_end_of_the_compiling_stride(monkeypatch, clock, capsys):
    """100 steps: the first stride (10 steps) takes 20 s, most of it compiling; the next 10
    take 1 s. The lines said it compiles first, and at step 20 they report 10 steps/s and 8 s
    left (80 steps at 10 steps/s), not the 1 step/s and 80 s a rate from the start gives."""
    monkeypatch.setattr(progress, "LINE_EVERY", 0.0)  # a line at every update
    bar = Progress(100, dt=0.01)
    assert bar.mode == "lines"  # capsys's stderr is no terminal
    bar.compiling()
    clock.now += 20.0
    bar.update(10)
    clock.now += 1.0
    bar.update(20)
    lines = capsys.readouterr().err.splitlines()
    assert lines[0].startswith("compiling kernels")
    assert lines[1].startswith("kernels compiled: first stride done in 20.0 s")
    assert "time left: after the next stride" in lines[1]  # no rate known yet
    assert "10 steps/s" in lines[2] and "8 s left" in lines[2]
    assert "0.20/1.00 s simulated" in lines[2]


def test_a_quiet_bar_writes_nothing(capsys):
    bar = Progress(10, dt=0.1, enabled=False)
    assert bar.mode == "off"
    bar.compiling()
    bar.update(5)
    bar.close()
    assert capsys.readouterr().err == ""


def test_a_quiet_bar_writes_nothing_on_a_terminal(wide_terminal):
    """--quiet (enabled=False) silences the live bar too."""
    term = Terminal()
    bar = Progress(10, dt=0.1, enabled=False, stream=term)
    bar.compiling()
    bar.update(5)
    bar.close()
    assert term.getvalue() == ""


def test_on_compiled_kernels_the_rate_counts_from_the_start(monkeypatch, clock, capsys):
    """A run on a World whose kernels ran (``World.compiled``), resumed at step 40 of 100:
    nothing is said of compiling, and after 10 steps in 2 s the bar reports 5 steps/s and
    10 s left (50 steps), from the run's first stride on."""
    monkeypatch.setattr(progress, "LINE_EVERY", 0.0)
    bar = Progress(100, dt=0.01)
    bar.compiling(compiled=True, step=40)
    clock.now += 2.0
    bar.update(50)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and "compil" not in lines[0]
    assert "5 steps/s" in lines[0] and "10 s left" in lines[0]


def test_a_run_done_in_its_first_stride_has_no_time_left(clock, capsys):
    """The whole run in one stride: no rate is known, and the line says 0 s left, not
    'after the next stride'."""
    bar = Progress(10, dt=0.1)
    bar.compiling()
    clock.now += 5.0
    bar.update(10)
    bar.close()
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 2 and lines[1].endswith(
        "100%  1.00/1.00 s simulated  -- steps/s  0 s left"
    )


def stride_run(bar: Progress, clock: Clock, compile_s: float, strides: int, steps: int, s: float):
    """A fake run: compiling and a first stride of ``steps`` in ``compile_s``, then
    ``strides`` more of ``steps`` steps in ``s`` each."""
    bar.compiling()
    clock.now += compile_s
    bar.update(steps)
    for i in range(strides):
        clock.now += s
        bar.update(steps * (i + 2))


def test_the_eta_after_compiling_is_the_stepping_rate_s(clock):
    """1000 steps; the first advance takes 10 s (compiling), then strides of 10 steps take
    0.1 s: after 10 of them the bar says 100 steps/s and 8.9 s left (890 steps), where the
    wall time since the start (11 s for 110 steps) would say 10 steps/s and 89 s."""
    bar = Progress(1000, dt=0.02, stream=io.StringIO())
    stride_run(bar, clock, compile_s=10.0, strides=10, steps=10, s=0.1)
    assert bar.rate == pytest.approx(100.0)
    assert bar.left == pytest.approx(8.9)
    assert bar.status() == " 11%  2.2/20.0 s simulated  100 steps/s  9 s left"


def strip(text: str) -> str:
    return ANSI.sub("", text)


def test_a_terminal_shows_compiling_then_a_bar_with_the_stepping_eta(wide_terminal, clock):
    """On a terminal (rich, redrawn in place): 'compiling kernels' from the start, before any
    rate; after the first stride 'stepping', and at the end the rate and time left of the
    steps on compiled kernels only (10 steps/s, 8 s left), with the simulated time."""
    term = Terminal()
    bar = Progress(100, dt=0.01, stream=term)
    assert bar.mode == "live"
    bar.compiling()
    compiling = strip(term.getvalue())
    assert "compiling kernels" in compiling
    assert "steps/s" not in compiling and "%" not in compiling  # no rate, no share yet
    clock.now += 20.0
    bar.update(10)
    assert "stepping" in strip(term.getvalue())[len(compiling) :]
    clock.now += 1.0
    bar.update(20)
    bar.close()
    out = strip(term.getvalue())
    last = out[out.rindex("stepping") :]
    assert "10 steps/s" in last and "8 s left" in last
    assert "0.20/1.00 s simulated" in last and "20%" in last
    assert bar.rate == pytest.approx(10.0) and bar.left == pytest.approx(8.0)


def test_outside_a_terminal_the_lines_stay_sparse(clock):
    """A 1 h run (36,000 strides of 0.1 s) in a log writes one line when compiling starts,
    one when it is done, one at most every 15 s and one at the end: no more than 243, and
    it does keep the log informed (200 lines at least)."""
    log = io.StringIO()
    bar = Progress(36_001 * 10, dt=1e-3, stream=log)
    assert bar.mode == "lines"
    stride_run(bar, clock, compile_s=30.0, strides=36_000, steps=10, s=0.1)
    bar.close()
    lines = log.getvalue().splitlines()
    assert 200 <= len(lines) <= 243  # 3600 s / 15 s + 3
    assert lines[-1].startswith("100%") and "0 s left" in lines[-1]
    assert "\r" not in log.getvalue()  # no bar redrawn in place in a log


class ZMQInteractiveShell:
    """What IPython's get_ipython() returns in a Jupyter kernel (the class name rich reads)."""


def test_in_a_notebook_with_widgets_the_bar_is_rich_s_jupyter_one(monkeypatch):
    """An IPython kernel with ipywidgets: the live bar, drawn by a console that knows it is in
    Jupyter (rich renders into an Output widget), though stderr is no terminal."""
    monkeypatch.setattr(builtins, "get_ipython", ZMQInteractiveShell, raising=False)
    monkeypatch.setitem(sys.modules, "ipywidgets", types.ModuleType("ipywidgets"))
    bar = Progress(100, dt=0.01, stream=io.StringIO())
    assert bar.mode == "live" and bar._console.is_jupyter


def test_in_a_notebook_without_widgets_plain_lines(monkeypatch):
    """An IPython kernel without ipywidgets, where rich can show no bar: plain lines."""
    monkeypatch.setattr(builtins, "get_ipython", ZMQInteractiveShell, raising=False)
    monkeypatch.setitem(sys.modules, "ipywidgets", None)  # import fails
    assert Progress(100, dt=0.01, stream=io.StringIO()).mode == "lines"


def test_durations_read_as_such():
    assert [duration(s) for s in (0.4, 8, 59.6, 125, 3599, 3780)] == [
        "0 s",
        "8 s",
        "1 min 00 s",
        "2 min 05 s",
        "59 min 59 s",
        "1 h 03 min",
    ]


def test_a_real_run_outside_a_terminal_says_a_few_lines(tmp_path):
    """`taichi-ice run` with stderr a pipe: it completes, its progress is at most 4 lines
    (compiling, compiled, maybe one 15 s line, the end), --quiet has none, and the run files
    of both hold the same series and frames."""
    from taichi_ice.run.runfile_read import read_run

    def run(name: str, *extra: str) -> list[str]:
        command = [sys.executable, "-m", "taichi_ice", "run", "scenarios/two_squares.toml"]
        done = subprocess.run(
            [*command, "--until", "0.05", "--out", str(tmp_path / name), *extra],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert done.returncode == 0, done.stderr
        assert "\r" not in done.stderr
        return [
            line
            for line in done.stderr.splitlines()
            if line.startswith(("compiling kernels", "kernels compiled")) or "% " in line
        ]

    said = run("loud.h5")
    assert 2 <= len(said) <= 4, said
    assert said[0].startswith("compiling kernels") and "kernels compiled" in said[1]
    assert run("quiet.h5", "--quiet") == []
    loud, quiet = read_run(tmp_path / "loud.h5"), read_run(tmp_path / "quiet.h5")
    for group in ("series", "frames"):
        assert loud[group].keys() == quiet[group].keys()
        for key in loud[group]:
            np.testing.assert_array_equal(loud[group][key], quiet[group][key])
