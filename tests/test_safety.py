"""Never lose or clobber a file, and every mistake a one-line message (issue 12).

Each test here reproduces a fault found by trying the landed code as a new user would: an
output that replaced the scene, a second writer that broke the first one's file, SIGTERM
that left no message, a GPU arch that crashed, a star-shaped floe that passed, a field too
large to fit that ran until the machine killed it, API edges that gave bare exceptions.
"""

from __future__ import annotations

import copy
import json
import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import shapely

from taichi_ice import Simulation, load_scenario
from taichi_ice.commands.args import parse_duration
from taichi_ice.commands.cli import main
from taichi_ice.errors import (
    PolygonError,
    ScenarioError,
    SizeError,
    StabilityError,
    UsageError,
)
from taichi_ice.physics.polygon import check_polygon
from taichi_ice.run.runfile_read import read_run
from taichi_ice.scene.model import MAX_VERTICES
from taichi_ice.scene.parse import scene_from_dict

ROOT = Path(__file__).resolve().parents[1]
TWO_SQUARES = str(ROOT / "scenarios" / "two_squares.toml")


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def run_args(out, *more):
    return ["run", TWO_SQUARES, "--out", str(out), "--until", "0.02", "--quiet", *more]


# --------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------


def test_an_existing_output_is_refused_unless_overwrite(tmp_path, capsys):
    out = tmp_path / "sq.h5"
    assert main(run_args(out)) == 0
    before = out.read_bytes()
    capsys.readouterr()
    assert main(run_args(out)) == 2
    line = one_line(capsys.readouterr().err)
    assert "exists" in line and "--overwrite" in line
    assert out.read_bytes() == before
    assert main(run_args(out, "--overwrite")) == 0
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "complete"
    assert not Path(f"{out}.lock").exists()


def test_the_scene_file_is_never_an_output(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    text = Path(TWO_SQUARES).read_text()
    scene.write_text(text)
    assert main(["run", str(scene), "--out", str(scene), "--overwrite", "--quiet"]) == 2
    assert "scene file" in one_line(capsys.readouterr().err)
    assert scene.read_text() == text


@pytest.mark.parametrize("case", ["folder", "below a file", "unwritable"])
def test_bad_output_paths_are_refused_before_any_work(tmp_path, capsys, monkeypatch, case):
    def never(*args, **kwargs):
        raise AssertionError("the scene was read before the output was checked")

    monkeypatch.setattr("taichi_ice.scene.parse.load_scenario", never)
    if case == "folder":
        out, expect = tmp_path, "is a folder"
    elif case == "below a file":
        (tmp_path / "f").write_text("")
        out, expect = tmp_path / "f" / "run.h5", "is a file"
    else:
        if os.geteuid() == 0:
            pytest.skip("root writes in any folder")
        locked = tmp_path / "ro"
        locked.mkdir(mode=0o500)
        out, expect = locked / "run.h5", "not writable"
    assert main(run_args(out)) == 2
    assert expect in one_line(capsys.readouterr().err)


@pytest.mark.parametrize("command", ["ensemble", "paper"])
@pytest.mark.parametrize("case", ["a file", "below a file"])
def test_an_output_folder_that_is_a_file_is_one_line_before_any_work(
    tmp_path, capsys, monkeypatch, command, case
):
    def never(*args, **kwargs):
        raise AssertionError("the scene was read before the output folder was checked")

    monkeypatch.setattr("taichi_ice.scene.parse.load_scenario", never)
    (tmp_path / "f").write_text("kept")
    out = tmp_path / "f" if case == "a file" else tmp_path / "f" / "results"
    args = [command, TWO_SQUARES] if command == "ensemble" else [command]
    assert main([*args, "--out", str(out), "--quiet"]) == 2
    assert "is a file" in one_line(capsys.readouterr().err)
    assert (tmp_path / "f").read_text() == "kept"


def test_a_second_writer_is_refused_naming_the_first(tmp_path, capsys):
    out = tmp_path / "sq.h5"
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
    lock = Path(f"{out}.lock")
    record = {
        "pid": other.pid,
        "host": socket.gethostname(),
        "command": "taichi-ice run other.toml",
        "since": "2025-01-01T00:00:00Z",
    }
    try:
        lock.write_text(json.dumps(record))
        assert main(run_args(out)) == 2
        line = one_line(capsys.readouterr().err)
        assert str(other.pid) in line and "taichi-ice run other.toml" in line
        assert not out.exists()
    finally:
        other.kill()
        other.wait()
    # The other writer is gone: its lock is stale, and taken over.
    assert main(run_args(out)) == 0
    assert not lock.exists()


CHILD_UNTIL = "1e5"  # s of simulated time: the children are stopped long before (60 s
# of two squares ran to the end in a few seconds once small worlds stepped fast)


def test_sigterm_and_sigkill_leave_files_that_open_with_no_options(tmp_path):
    """SIGTERM stops a run as Ctrl-C does (a message, status failed, exit 143); after
    SIGTERM or SIGKILL the file opens with plain h5py and its series have one length."""
    path = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
    env = {**os.environ, "PYTHONPATH": path}
    paths = {sig: tmp_path / f"{sig.name}.h5" for sig in (signal.SIGTERM, signal.SIGKILL)}
    procs = {
        sig: subprocess.Popen(
            [sys.executable, "-m", "taichi_ice", *run_args(path, "--until", CHILD_UNTIL)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        for sig, path in paths.items()
    }
    try:
        deadline = time.monotonic() + 240
        for path in paths.values():
            while True:
                assert time.monotonic() < deadline, "the runs did not start writing"
                try:
                    if len(read_run(path)["frames"]["time"]) >= 3:
                        break
                except Exception:
                    pass
                time.sleep(0.5)
        for sig, proc in procs.items():
            proc.send_signal(sig)
        outs = {sig: proc.communicate(timeout=120) for sig, proc in procs.items()}
    finally:
        for proc in procs.values():
            proc.kill()
    assert procs[signal.SIGTERM].returncode == 143
    err = outs[signal.SIGTERM][1]  # the run's header line, then the message
    assert "Traceback" not in err and "SIGTERM" in err.strip().splitlines()[-1]
    assert procs[signal.SIGKILL].returncode == -signal.SIGKILL
    for sig, path in paths.items():
        with h5py.File(path, "r") as f:  # no swmr=True, no h5clear
            status = f.attrs["status"]
            lengths = {f["series"][name].shape[0] for name in f["series"]}
            frames = {f["frames"][name].shape[0] for name in f["frames"]}
        assert len(lengths) == 1 and len(frames) == 1, (sig, lengths, frames)
        assert status == ("failed" if sig == signal.SIGTERM else "running")
    assert "SIGTERM" in read_run(paths[signal.SIGTERM])["attrs"]["failure"]


def test_a_gpu_arch_this_machine_lacks_is_one_line_and_writes_nothing(tmp_path, capsys):
    if Path("/dev/nvidia0").exists() or Path("/dev/dri").exists():
        pytest.skip("this machine may have a GPU")
    out = tmp_path / "g.h5"
    assert main(run_args(out, "--arch", "cuda")) == 2
    line = one_line(capsys.readouterr().err)
    assert "--arch cuda" in line and "--arch cpu" in line
    assert not out.exists()


def test_checkpoint_durations_parse_and_refuse_nonsense():
    assert parse_duration("30s") == 30.0
    assert parse_duration("10min") == 600.0
    assert parse_duration("1h") == 3600.0
    assert parse_duration("90") == 90.0
    with pytest.raises(Exception, match="30s, 10min or 1h"):
        parse_duration("soon")


# --------------------------------------------------------------------------------------------
# Scenes
# --------------------------------------------------------------------------------------------


def pentagram():
    a = np.pi / 2 + 4 * np.pi * np.arange(5) / 5
    return np.stack([np.cos(a), np.sin(a)], axis=1)


def hexagon_twice():
    a = 2 * np.pi * np.arange(12) / 6
    return np.stack([np.cos(a), np.sin(a)], axis=1)


def is_floe(v) -> bool:
    """Independent reference (shapely): a simple, counter-clockwise, convex outline."""
    p = shapely.Polygon(v)
    return bool(
        p.is_valid
        and p.exterior.is_ccw
        and abs(p.convex_hull.area - p.area) <= 1e-9 * p.convex_hull.area
    )


def test_self_intersecting_outlines_are_refused_as_shapely_says():
    for v in (pentagram(), hexagon_twice()):
        assert not is_floe(v)
        with pytest.raises(PolygonError, match="crosses itself"):
            check_polygon(v)
    rng = np.random.default_rng(12)
    verdicts = {True: 0, False: 0}
    for _ in range(400):
        n = int(rng.integers(3, 9))
        a = np.sort(rng.uniform(0, 2 * np.pi, n))
        if np.min(np.diff(np.r_[a, a[0] + 2 * np.pi])) < 0.05:
            continue  # near-duplicate corners: a different rule refuses those
        if rng.random() < 0.7:
            a = rng.permutation(a)
        v = np.stack([np.cos(a), np.sin(a)], axis=1)
        try:
            check_polygon(v)
            accepted = True
        except PolygonError:
            accepted = False
        assert accepted == is_floe(v), v
        verdicts[accepted] += 1
    assert min(verdicts.values()) > 20  # both verdicts were tested


def squares_raw():
    return copy.deepcopy(dict(load_scenario(TWO_SQUARES).raw))


def test_the_vertex_limit_is_checked_when_the_scene_is_read_and_documented():
    raw = squares_raw()
    a = 2 * np.pi * np.arange(MAX_VERTICES + 1) / (MAX_VERTICES + 1)
    body = raw["body"][0]
    for key in ("width", "length"):
        body.pop(key)
    body.update(shape="polygon", vertices=(0.4 * np.stack([np.cos(a), np.sin(a)], 1)).tolist())
    with pytest.raises(ScenarioError, match=f"at most {MAX_VERTICES}"):
        scene_from_dict(raw, source="s.toml")
    docs = (ROOT / "docs" / "scenarios.md").read_text()
    assert f"at most {MAX_VERTICES} vertices" in docs


@pytest.mark.parametrize(
    ("change", "error", "words"),
    [
        (lambda r: r["body"][0].update(width=1e-150), ScenarioError, "steps"),
        (lambda r: r["body"][0].update(width=1e-150, length=1e-150), ScenarioError, "mass"),
        (lambda r: r["body"][0].update(position=[1e12, 0.0]), ScenarioError, "origin"),
        (
            lambda r: r.update(
                field=[{"shape": "diamond", "width": 0.7, "length": 1.0, "rows": 2**63 - 1,
                        "columns": 7, "origin": [10.0, 10.0], "spacing": [0.8, 1.05]}]
            ),
            SizeError,
            "32-bit",
        ),
    ],
    ids=["width 1e-150", "both 1e-150", "1e12 m away", "2^63 rows"],
)  # fmt: skip
def test_extreme_values_are_one_clear_error(change, error, words):
    raw = squares_raw()
    change(raw)
    with pytest.raises(error, match=words) as info:
        scene_from_dict(raw, source="s.toml")
    assert "s.toml" in str(info.value) and "\n" not in str(info.value)


def test_a_scene_too_large_for_the_memory_is_refused_before_it_is_built(monkeypatch):
    monkeypatch.setattr(
        "taichi_ice.limits.memory_limit", lambda: (10**9, "this machine has available")
    )
    raw = squares_raw()
    raw["field"] = [
        {"shape": "diamond", "width": 0.7, "length": 1.0, "rows": 1000, "columns": 1000,
         "origin": [10.0, 10.0], "spacing": [0.8, 1.05]}
    ]  # fmt: skip
    start = time.perf_counter()
    with pytest.raises(SizeError, match=r"need about 4.1 GB .* has available 1 GB"):
        scene_from_dict(raw, source="s.toml")
    assert time.perf_counter() - start < 1.0  # refused from the count, nothing built


# --------------------------------------------------------------------------------------------
# API edges
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def sim(taichi_runtime):
    arch, precision = taichi_runtime
    return Simulation(TWO_SQUARES, arch=arch, precision=precision)  # a path is a scene too


@pytest.mark.parametrize("until", [-1.0, 0.0, math.nan, math.inf, "soon"])
def test_run_refuses_an_end_time_that_is_not_a_positive_finite_time(sim, until):
    with pytest.raises(UsageError, match="until"):
        sim.run(until=until)


def test_a_second_run_goes_on_to_an_absolute_end_time(sim):
    sim.run(until=0.01)
    result = sim.run(until=0.02)
    assert sim.time == pytest.approx(0.02)
    assert result.series[0]["time"][-1] == pytest.approx(0.02)
    with pytest.raises(UsageError, match="before"):
        sim.run(until=0.015)


@pytest.mark.parametrize("dt", [0.0, -1e-4, math.nan, math.inf])
def test_a_dt_that_is_not_a_positive_time_is_refused(dt):
    with pytest.raises(UsageError, match="dt"):
        Simulation(TWO_SQUARES, dt=dt)


def test_dt_errors_quote_the_dt_passed_and_a_shortened_dt_is_said(sim):
    limit = sim.world.stable_dt
    with pytest.raises(StabilityError, match=r"dt = 0\.00095 s"):
        Simulation(TWO_SQUARES, dt=0.00095)
    assert limit < 0.00095
    shortened = Simulation(TWO_SQUARES, dt=0.005, force_dt=True)
    assert "0.005" in shortened.dt_note and f"{shortened.dt:.4g}" in shortened.dt_note


def test_simulation_refuses_an_empty_batch_and_things_that_are_not_scenes():
    with pytest.raises(UsageError, match="at least one scene"):
        Simulation([])
    with pytest.raises(UsageError, match="Scenes"):
        Simulation([42])


@pytest.mark.parametrize("kind", ["text", "foreign hdf5", "missing"])
def test_plot_of_a_file_that_is_not_a_run_is_one_line(tmp_path, capsys, kind):
    path = tmp_path / "x.h5"
    if kind == "text":
        path.write_text("not a run")
    elif kind == "foreign hdf5":
        with h5py.File(path, "w") as f:
            f["data"] = np.arange(3)
    assert main(["plot", str(path)]) == 2
    line = one_line(capsys.readouterr().err)
    assert str(path) in line and "run file" in line
