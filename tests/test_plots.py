"""The figures of a run (``taichi_ice.run.plots``): one view for every snapshot and every
frame of the animation, figures drawn without pyplot or a switch of the user's backend, and a
run with nothing to draw refused in one line.

The runs are written by ``RunWriter`` with positions chosen here (no simulation), so the
bodies' true extents are known from the scene's geometry: 1 m squares.
"""

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from taichi_ice.run.budget import SERIES
from taichi_ice.run.runfile import RunWriter
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
from taichi_ice.run.budget import SERIES
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
