"""The progress bar of a run: the first stride compiles, and the rate and time left count
from its end (issue 30, item 4). A fake clock, no Taichi."""

from __future__ import annotations

from taichi_ice.run import progress
from taichi_ice.run.progress import Progress


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_the_time_left_counts_from_the_end_of_the_compiling_stride(monkeypatch, capsys):
    """100 steps: the first stride (10 steps) takes 20 s, most of it compiling; the next 10
    take 1 s. The bar said it compiles first, and at step 20 it reports 10 steps/s and 8 s
    left (80 steps at 10 steps/s), not the 1 step/s and 80 s a rate from the start gives."""
    clock = Clock()
    monkeypatch.setattr(progress._time, "perf_counter", clock)
    bar = Progress(100, dt=0.01)
    bar.every = 0.0  # a line at every update
    bar.compiling()
    clock.now += 20.0
    bar.update(10)
    clock.now += 1.0
    bar.update(20)
    lines = capsys.readouterr().err.splitlines()
    assert lines[0].startswith("starting: the first stride compiles the kernels")
    assert lines[1].startswith("first stride done in 20.0 s")
    assert "time left: after the next stride" in lines[2]  # no rate known yet
    assert "10 steps/s" in lines[3] and "8 s left" in lines[3]
    assert "t =   0.200 s" in lines[3]


def test_a_quiet_bar_writes_nothing(capsys):
    bar = Progress(10, dt=0.1, enabled=False)
    bar.compiling()
    bar.update(5)
    bar.close()
    assert capsys.readouterr().err == ""


def test_on_compiled_kernels_the_rate_counts_from_the_start(monkeypatch, capsys):
    """A run on a World whose kernels ran (``World.compiled``), resumed at step 40 of 100:
    nothing is said of compiling, and after 10 steps in 2 s the bar reports 5 steps/s and
    10 s left (50 steps), from the run's first stride on."""
    clock = Clock()
    monkeypatch.setattr(progress._time, "perf_counter", clock)
    bar = Progress(100, dt=0.01)
    bar.every = 0.0
    bar.compiling(compiled=True, step=40)
    clock.now += 2.0
    bar.update(50)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and "compil" not in lines[0]
    assert "5 steps/s" in lines[0] and "10 s left" in lines[0]
