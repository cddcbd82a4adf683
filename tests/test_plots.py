"""The figures of a run (``taichi_ice.run.plots``): one view for every snapshot and every
frame of the animation, figures drawn without pyplot or a switch of the user's backend, and a
run with nothing to draw refused in one line.

The runs are written by ``RunWriter`` with positions chosen here (no simulation), so the
bodies' true extents are known from the scene's geometry: 1 m squares.
"""

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from taichi_ice.commands.cli import main
from taichi_ice.run.budget import SERIES
from taichi_ice.run.plots import animation_frames, positions_figure
from taichi_ice.run.runfile import RunWriter
from taichi_ice.run.runfile_read import read_run
from taichi_ice.scene.parse import load_scenario

ROOT = Path(__file__).resolve().parents[1]
TWO_SQUARES = str(ROOT / "scenarios" / "two_squares.toml")
HALF = 0.5  # m: half the side of each square of two_squares.toml
STILL_X = -0.6  # m: where the right square is held in the written run
DRIFT_X = np.linspace(1.0, 2.9, 7)  # m: the left square's centre, frame by frame


def write_drift(path: Path) -> Path:
    """A complete run file of two_squares.toml in which the left square drifts from x = 1.0
    to 2.9 m and the other stays at x = -0.6 m, both at y = 0, unrotated."""
    scene = load_scenario(TWO_SQUARES)
    n = scene.n_bodies
    assert n == 2 and [b.name for b in scene.bodies] == ["left", "right"]
    writer = RunWriter(path, scene, {})
    for k, x in enumerate(DRIFT_X):
        pos = np.array([[x, 0.0], [STILL_X, 0.0]])
        writer.add_frame(0.1 * k, pos, np.zeros(n), np.zeros((n, 2)), np.zeros(n))
        writer.add_sample(0.1 * k, np.zeros((1, 2)), np.zeros(len(SERIES)), 0)
    writer.close("complete", steps=len(DRIFT_X))
    return path


def assert_one_view_holding(axes, xs) -> None:
    """Every axes has the same limits, and they hold both squares with the left one's centre
    at each of ``xs`` (their extents from the scene's geometry)."""
    views = {(ax.get_xlim(), ax.get_ylim()) for ax in axes}
    assert len(views) == 1, views
    (x0, x1), (y0, y1) = views.pop()
    assert x0 <= STILL_X - HALF and x1 >= max(xs) + HALF
    assert x0 <= min(xs) - HALF
    assert y0 <= -HALF and y1 >= HALF
    # One view, not a window far larger than the scene: within 10 % of its extent.
    assert x1 - x0 <= 1.1 * (max(xs) + HALF - (STILL_X - HALF))


def test_every_snapshot_panel_shares_one_view_that_holds_every_frame(tmp_path):
    """A square that drifts 1.9 m is seen to move: the panels' limits are one, and each
    panel's bodies lie inside it."""
    run = read_run(write_drift(tmp_path / "drift.h5"))
    fig = positions_figure(run, snapshots=4)
    axes = [ax for ax in fig.axes if ax.collections]
    assert len(axes) == 4
    assert_one_view_holding(axes, DRIFT_X)
    # The square's outline in each panel is where the run put it (drawn, not only framed).
    for ax in axes:
        t = float(re.search(r"t = ([0-9.]+) s", ax.get_title()).group(1))
        x = DRIFT_X[round(t / 0.1)]
        left = ax.collections[0].get_paths()[0].vertices
        assert np.isclose(left[:, 0].min(), x - HALF) and np.isclose(left[:, 0].max(), x + HALF)


def test_every_frame_of_the_animation_shares_one_view(tmp_path):
    """The GIF's bodies panel keeps one view from the first frame to the last."""
    run = read_run(write_drift(tmp_path / "drift.h5"))
    fig, draw, n_frames = animation_frames(run)
    assert n_frames == len(DRIFT_X)
    limits = []
    for f in range(n_frames):
        draw(f)
        ax = fig.axes[0]
        limits.append((ax.get_xlim(), ax.get_ylim()))
        assert_one_view_holding([ax], DRIFT_X)
    assert len(set(limits)) == 1


# Draws a run's figures and its GIF in a fresh interpreter whose backend is set to one that
# is not Agg, with matplotlib.use replaced by a function that fails.
DRAW_IN_A_FRESH_PROCESS = """
import sys
import matplotlib
matplotlib.use("pdf")
before = matplotlib.get_backend()
def refuse(*args, **kwargs):
    raise AssertionError(f"matplotlib.use{args} called by the package")
matplotlib.use = refuse
from taichi_ice.run.plots import plot_run
written = plot_run(sys.argv[1], sys.argv[2], animate=True)
assert matplotlib.get_backend() == before, (before, matplotlib.get_backend())
print(len(written), "matplotlib.pyplot" in sys.modules)
"""


def test_drawing_a_run_leaves_the_backend_and_pyplot_alone(tmp_path):
    """The figures and the GIF are drawn without pyplot and without matplotlib.use (which
    switched a notebook's inline backend to Agg)."""
    run = write_drift(tmp_path / "drift.h5")
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    proc = subprocess.run(
        [sys.executable, "-c", DRAW_IN_A_FRESH_PROCESS, str(run), str(tmp_path / "figs")],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["4", "False"]
    assert (tmp_path / "figs" / "drift.gif").stat().st_size > 1_000


def test_no_module_of_the_package_switches_the_backend_or_imports_pyplot():
    """Every figure of the package (paper, study, validate, bench) is a bare Figure: no
    module calls matplotlib.use or imports pyplot."""
    offenders = []
    for path in sorted((ROOT / "taichi_ice").rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        code = "\n".join(line.split("#")[0] for line in text.splitlines())
        if re.search(
            r"matplotlib\.use\(|import matplotlib\.pyplot|from matplotlib import pyplot", code
        ):
            offenders.append(str(path.relative_to(ROOT)))
    assert offenders == []


def test_outlines_turn_each_body_about_its_centre():
    """A 1 m square turned by 30 degrees about (2, 1), beside a triangle: each corner is the
    body's own corner turned anticlockwise by the angle and moved to its centre; the view
    holds both with the margin."""
    from taichi_ice.run.plots import VIEW_MARGIN, outlines, shared_view

    square = np.array([[-HALF, -HALF], [HALF, -HALF], [HALF, HALF], [-HALF, HALF]])
    triangle = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    angle = np.radians(30.0)
    run = {
        "bodies": {
            "vertex_offsets": np.array([0, 4, 7]),
            "vertices": np.vstack([square, triangle]),
        },
        "frames": {
            "position": np.array([[[2.0, 1.0], [-3.0, 0.0]]]),
            "angle": np.array([[angle, 0.0]]),
        },
    }
    turned, still = outlines(run, 0)
    c, s = np.cos(angle), np.sin(angle)
    for (x, y), (tx, ty) in zip(square, turned):
        assert np.allclose([tx, ty], [2.0 + c * x - s * y, 1.0 + s * x + c * y])
    assert np.allclose(still, triangle + np.array([-3.0, 0.0]))
    reach = HALF * (c + s)  # half the extent of the turned square
    lo_x, hi_x, lo_y, hi_y = -3.0, 2.0 + reach, min(0.0, 1.0 - reach), 1.0 + reach
    pad = VIEW_MARGIN * max(hi_x - lo_x, hi_y - lo_y)
    assert np.allclose(shared_view(run, [0]), (lo_x - pad, hi_x + pad, lo_y - pad, hi_y + pad))


# Starts `taichi-ice run` and kills it (SIGKILL) at the instant of the run file's first write,
# after the file was made: the file holds the bodies, no sample and no frame, status running.
KILL_AT_FIRST_WRITE = """
import os, signal, sys
from taichi_ice.commands.cli import main
from taichi_ice.run.runfile import RunWriter
RunWriter._write = lambda self, *a, **k: os.kill(os.getpid(), signal.SIGKILL)
main(["run", sys.argv[1], "--out", sys.argv[2], "--quiet"])
"""


def test_plot_of_a_run_killed_before_its_first_sample_is_one_line(tmp_path, capsys):
    """`taichi-ice plot` of a run killed before it wrote a sample: exit 2, one line that says
    the run has nothing yet and why, no traceback, no figure folder."""
    path = tmp_path / "killed.h5"
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    proc = subprocess.run(
        [sys.executable, "-c", KILL_AT_FIRST_WRITE, TWO_SQUARES, str(path)],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    run = read_run(path)
    assert run["attrs"]["status"] == "running"
    assert len(run["series"]["time"]) == 0 and len(run["frames"]["time"]) == 0
    out = tmp_path / "figs"
    assert main(["plot", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"taichi-ice: error: {path}: ")
    assert "no sample or frame yet" in lines[0] and "killed before its first sample" in lines[0]
    assert f"run it again (taichi-ice run {TWO_SQUARES} --out {path} --overwrite)" in lines[0]
    assert not out.exists()


@pytest.mark.parametrize("status", ["failed", "complete"])
def test_plot_of_an_empty_run_says_its_status(tmp_path, capsys, status):
    """A run that failed before its first sample says so, with its reason."""
    path = tmp_path / "empty.h5"
    failure = "diverged at t = 0" if status == "failed" else ""
    RunWriter(path, load_scenario(TWO_SQUARES), {}).close(status, failure=failure)
    assert main(["plot", str(path)]) == 2
    line = capsys.readouterr().err.strip()
    assert "\n" not in line and "no sample or frame yet" in line
    if status == "failed":
        assert "failed before its first sample (diverged at t = 0)" in line
    else:
        assert "status complete" in line
