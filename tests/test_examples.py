"""Every example of examples/ runs, in its short form, as a user runs it: a process of its own,
writing into a temporary folder; and the path of the docs' "Getting started" (the scene of
one's own, run and plotted from the command line, then looked at with xarray) runs too.

The docs site includes these files as they are (docs/examples.md, docs/getting-started.md),
so what the site shows is what ran here. Most of each test is Taichi compiling its kernels.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
# A figure with axes, lines and floes drawn in it is tens of kB; an empty or failed one is a
# few: below this the figure is not what the example says it draws.
MIN_FIGURE_BYTES = 10_000
# Seconds an example may take in its short form (they take 10-60 s on 2 busy cores,
# compiling included).
TIMEOUT = 900
# A float as the examples print it (%g-style, possibly negative, possibly a percentage).
NUMBER = r"-?\d+(?:\.\d+)?(?:e[+-]?\d+)?"


def run(*args: str | Path, cwd: Path = ROOT) -> str:
    """Run ``python ARGS`` with this checkout's package first on the path; its stdout."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    proc = subprocess.run(
        [sys.executable, *map(str, args)],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
    )
    assert proc.returncode == 0, f"exit {proc.returncode}\n{proc.stdout}\n{proc.stderr}"
    return proc.stdout


def figure(path: Path) -> None:
    """``path`` is a written figure of a plausible size."""
    assert path.is_file(), f"{path} was not written"
    assert path.stat().st_size > MIN_FIGURE_BYTES, f"{path}: {path.stat().st_size} bytes"


def row(out: str, label: str, columns: int) -> list[float]:
    """The numbers of the printed table row that starts with ``label``."""
    match = re.search(rf"^{re.escape(label)}\s+((?:{NUMBER}%?\s*){{{columns}}})$", out, re.M)
    assert match, f"no row {label!r} of {columns} numbers in:\n{out}"
    values = [float(v.rstrip("%")) for v in match.group(1).split()]
    assert all(math.isfinite(v) for v in values), values
    return values


def test_scene_from_python(tmp_path: Path) -> None:
    """A scene built from a dict runs with two laws as two worlds; their budgets close."""
    out = run(EXAMPLES / "scene_from_python.py", "--quick", "--out", tmp_path)
    for law in ("coulomb", "rate-state"):
        peak, friction, work_in, residual_percent = row(out, law, 4)
        assert peak >= 0 and friction >= 0
        assert work_in > 0, "the pusher meets the floes at 1 s: it must have done work by 1.5 s"
        assert abs(residual_percent) < 1.0
        assert (tmp_path / f"hexagons_{law}.h5").is_file()
    figure(tmp_path / "scene_from_python.png")


def test_sweep_with_xarray(tmp_path: Path) -> None:
    """A sweep of 2 layouts x 3 laws runs, its dataset opens in xarray, its figure is drawn."""
    xr = pytest.importorskip("xarray")
    out = run(EXAMPLES / "sweep_with_xarray.py", "--quick", "--out", tmp_path)
    for label in ("coulomb 0.1", "coulomb 0.9", "rate-state"):
        assert all(v >= 0 for v in row(out, label, 2))
    with xr.open_dataset(tmp_path / "sweep" / "sweep.nc") as ds:
        assert ds.sizes["world"] == 6
        assert (ds.status == "complete").all()
    figure(tmp_path / "sweep_with_xarray.png")
    # The same command again resumes: every world comes from the batch files.
    assert "0 worlds run, 6 reused" in run(
        EXAMPLES / "sweep_with_xarray.py", "--quick", "--out", tmp_path
    )


def test_animate_run(tmp_path: Path) -> None:
    """A bundled scene runs 1 s and becomes a GIF of one image per frame (0, 0.5, 1 s)."""
    pil = pytest.importorskip("PIL.Image")
    out = run(EXAMPLES / "animate_run.py", "--quick", "--out", tmp_path)
    assert "3 frames" in out
    gif = tmp_path / "animate_run.gif"
    figure(gif)
    with pil.open(gif) as image:
        assert image.format == "GIF" and image.n_frames == 3


def test_getting_started_scene_runs_and_plots(tmp_path: Path) -> None:
    """The scene of "Getting started" runs from the command line, plots and opens in xarray."""
    pytest.importorskip("xarray")
    run_file = tmp_path / "my_scene.h5"
    out = run(
        "-m", "taichi_ice", "run", EXAMPLES / "my_scene.toml",
        "--until", "0.5", "--out", run_file, "--quiet",
    )  # fmt: skip
    assert f"wrote {run_file}" in out
    run("-m", "taichi_ice", "plot", run_file)
    for name in ("probe_force", "energy", "positions"):
        figure(tmp_path / f"my_scene_{name}.png")
    out = run(EXAMPLES / "look_at_run.py", run_file)
    assert "status complete" in out
    assert re.search(rf"peak force on quay: {NUMBER} kN", out), out
    figure(tmp_path / "my_scene_look.png")
