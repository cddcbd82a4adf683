"""Run files: the layout of DESIGN.md section 3, the frame grid, the probe forces, and a file
that another process reads while the run is still writing it, with series of one length."""

from __future__ import annotations

import copy
import json
import math
import subprocess
import sys

import h5py
import numpy as np
import pytest

from taichi_ice import Simulation, __version__, load_scenario
from taichi_ice.run import simulation
from taichi_ice.run.runfile import RunWriter
from taichi_ice.run.runfile_read import read_run
from taichi_ice.scene.parse import scene_from_dict

SERIES = {
    "time",
    "probe_force",
    "friction_energy",
    "viscous_energy",
    "drag_energy",
    "kinetic_energy",
    "elastic_energy",
    "crushing_energy",
    "severed_energy",
    "work_in",
    "wind_work",
    "current_work",
    "tilt_work",
    "n_contacts",
}
FRAMES = {"time", "position", "angle", "velocity", "omega"}
BODIES = {
    "names",
    "kinds",
    "vertices",
    "vertex_offsets",
    "mass",
    "inertia",
    "probe_index",
    # The floes at time 0 as a CF-1.8 polygon geometry (tests/test_cf_geometry.py).
    "floe_outline",
    "floe_outline_node_count",
    "floe_outline_x",
    "floe_outline_y",
}
ROOT_ATTRS = {
    "taichi_ice_version",
    "scenario",
    "friction",
    "friction_params",
    "arch",
    "precision",
    "dt",
    "seed",
    "status",
    "failure",
}

DURATION = 0.2  # s
OUTPUT_INTERVAL = 0.02  # s
SERIES_INTERVAL = 0.005  # s
# Times are multiples of dt accumulated as steps * dt: round-off of the product only.
TIME_ATOL = 1e-12  # s
# The probe impulse and the momentum change add the same fixed-point forces, times dt, in a
# different order (and the velocities round at the run's precision).
IMPULSE_RTOL = {"f64": 1e-9, "f32": 1e-5}
# Frames hold the run's numbers; a float32 run rounds the scene's.
STATE_RTOL = {"f64": 0.0, "f32": 1e-7}


@pytest.fixture(scope="module")
def run_opts(taichi_runtime: tuple[str, str]) -> dict:
    arch, precision = taichi_runtime
    return {"arch": arch, "precision": precision}


def colliding_squares():
    """scenarios/two_squares.toml shortened, 1 mm apart, both squares probes."""
    base = load_scenario("scenarios/two_squares.toml")
    raw = copy.deepcopy(dict(base.raw))
    raw["simulation"].update(
        duration=DURATION, output_interval=OUTPUT_INTERVAL, series_interval=SERIES_INTERVAL
    )
    raw["body"][0].update(position=[-0.5005, 0.02], probe=True)
    raw["body"][1].update(position=[0.5005, -0.02])
    return scene_from_dict(raw)


@pytest.fixture(scope="module")
def finished(tmp_path_factory: pytest.TempPathFactory, run_opts: dict):
    """(scene, simulation, path) of a complete run of two colliding squares."""
    scene = colliding_squares()
    path = tmp_path_factory.mktemp("io") / "squares.h5"
    sim = Simulation(scene, **run_opts)
    sim.run(out=path)
    return scene, sim, path


def test_run_file_has_the_design_layout(finished, run_opts):
    """Root attributes, /series, /frames and /bodies are those of DESIGN.md section 3."""
    scene, sim, path = finished
    n, p = scene.n_bodies, len(scene.probe_indices)
    assert p == 2
    with h5py.File(path, "r") as f:
        assert ROOT_ATTRS <= set(f.attrs)
        # The groups, and the root's netCDF dimensions (tests/test_netcdf.py).
        assert set(f) == {
            "series",
            "frames",
            "bodies",
            "body",
            "probe",
            "xy",
            "vertex",
            "body_edge",
            "outline_node",
        }
        attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
        assert attrs["taichi_ice_version"] == __version__
        assert attrs["scenario"] == scene.text
        assert attrs["friction"] == "coulomb"
        assert json.loads(attrs["friction_params"]) == scene.friction.to_dict()
        assert attrs["arch"] == run_opts["arch"]
        assert attrs["precision"] == run_opts["precision"]
        assert attrs["dt"] == sim.dt
        assert attrs["seed"] == scene.simulation.seed
        assert attrs["status"] == "complete"
        assert attrs["failure"] == ""

        series = f["series"]
        assert set(series) == SERIES
        t = round(DURATION / SERIES_INTERVAL) + 1
        for name in SERIES - {"probe_force"}:
            assert series[name].shape == (t,), name
        assert series["probe_force"].shape == (t, p, 2)

        frames = f["frames"]
        assert set(frames) == FRAMES
        fr = round(DURATION / OUTPUT_INTERVAL) + 1
        assert frames["time"].shape == (fr,)
        assert frames["position"].shape == (fr, n, 2)
        assert frames["angle"].shape == (fr, n)
        assert frames["velocity"].shape == (fr, n, 2)
        assert frames["omega"].shape == (fr, n)

        bodies = f["bodies"]
        assert set(bodies) == BODIES
        assert [x.decode() for x in bodies["names"][()]] == list(scene.names)
        assert [x.decode() for x in bodies["kinds"][()]] == [b.kind for b in scene.bodies]
        np.testing.assert_array_equal(bodies["vertices"][()], scene.vertices_flat)
        np.testing.assert_array_equal(bodies["vertex_offsets"][()], scene.vertex_offsets)
        np.testing.assert_array_equal(bodies["mass"][()], scene.masses)
        np.testing.assert_array_equal(bodies["inertia"][()], scene.inertias)
        np.testing.assert_array_equal(bodies["probe_index"][()], scene.probe_indices)

        # The last frame is the state the run ended in; the first the scene's.
        np.testing.assert_array_equal(frames["position"][-1], sim.positions())
        np.testing.assert_array_equal(frames["omega"][-1], sim.omegas())
        rtol = STATE_RTOL[run_opts["precision"]]
        np.testing.assert_allclose(frames["position"][0], scene.positions, rtol=rtol)
        np.testing.assert_allclose(frames["velocity"][0], scene.velocities, rtol=rtol)


def test_frames_and_samples_fall_on_their_intervals(finished):
    """Frames at 0, interval, 2 interval, ..., duration; samples likewise."""
    _, _, path = finished
    with h5py.File(path, "r") as f:
        frames = f["frames/time"][()]
        samples = f["series/time"][()]
    np.testing.assert_allclose(frames, OUTPUT_INTERVAL * np.arange(len(frames)), atol=TIME_ATOL)
    np.testing.assert_allclose(samples, SERIES_INTERVAL * np.arange(len(samples)), atol=TIME_ATOL)
    assert frames[-1] == pytest.approx(DURATION, abs=TIME_ATOL)
    assert samples[-1] == pytest.approx(DURATION, abs=TIME_ATOL)


def test_probe_force_is_the_contact_force_on_the_probe(finished, run_opts):
    """The probe force, summed over its sample intervals, is each square's momentum change."""
    scene, sim, path = finished
    with h5py.File(path, "r") as f:
        time = f["series/time"][()]
        force = f["series/probe_force"][()]
    assert sim.velocities()[0, 0] < 0.0 < sim.velocities()[1, 0]  # the squares rebounded
    impulse = np.sum(force[1:] * np.diff(time)[:, None, None], axis=0)  # (P, 2), N s
    change = scene.masses[:, None] * (sim.velocities() - scene.velocities)
    rtol = IMPULSE_RTOL[run_opts["precision"]]
    np.testing.assert_allclose(
        impulse, change[scene.probe_indices], rtol=rtol, atol=rtol * np.abs(change).max()
    )
    # Equal and opposite: the two probes feel the one contact.
    np.testing.assert_allclose(impulse[0], -impulse[1], rtol=rtol)


READER = """
import json, sys
from taichi_ice.run.runfile_read import read_run
run = read_run(sys.argv[1])
print(json.dumps({"status": run["attrs"]["status"], "frames": len(run["frames"]["time"]),
                  "samples": len(run["series"]["time"]),
                  "lengths": sorted({len(v) for v in run["series"].values()})}))
"""


def test_another_process_reads_the_file_while_the_run_writes_it(tmp_path, monkeypatch, run_opts):
    """A second process opens the file mid-run and sees the frames written so far, every
    series of one length."""
    scene = colliding_squares()
    path = tmp_path / "running.h5"
    seen: list[dict] = []
    flush = RunWriter.flush

    def flush_then_read(self, steps, **attrs):
        flush(self, steps, **attrs)
        if len(seen) < 1 and self.n_frames == 4:
            out = subprocess.run(
                [sys.executable, "-c", READER, str(self.path)],
                capture_output=True,
                text=True,
                timeout=60,
                check=True,
            )
            seen.append(json.loads(out.stdout.strip().splitlines()[-1]))

    monkeypatch.setattr(RunWriter, "flush", flush_then_read)
    Simulation(scene, **run_opts).run(out=path, flush_every=0)
    assert seen == [
        {
            "status": "running",
            "frames": 4,
            "samples": round(3 * OUTPUT_INTERVAL / SERIES_INTERVAL) + 1,
            "lengths": [round(3 * OUTPUT_INTERVAL / SERIES_INTERVAL) + 1],
        }
    ]
    with h5py.File(path, "r") as f:  # a finished file needs no SWMR
        assert f.attrs["status"] == "complete"
        assert f["frames/time"].shape == (round(DURATION / OUTPUT_INTERVAL) + 1,)


def test_rows_kept_in_memory_are_written_as_if_at_every_frame(tmp_path, monkeypatch, run_opts):
    """flush_every=0 writes the file at every frame, inf only at the end, and a bound on the
    bytes kept writes it as soon as a frame is kept: the three files hold the same rows,
    value for value."""
    written: list[int] = []
    flush = RunWriter.flush

    def counted(self, steps, **attrs):
        flush(self, steps, **attrs)
        written.append(self.n_frames)

    monkeypatch.setattr(RunWriter, "flush", counted)
    scene = colliding_squares()
    cases = {
        "each": (0.0, simulation.FLUSH_BYTES),
        "end": (math.inf, simulation.FLUSH_BYTES),
        "bytes": (math.inf, 1),
    }
    runs = {}
    for name, (every, bound) in cases.items():
        monkeypatch.setattr(simulation, "FLUSH_BYTES", bound)
        written.clear()
        Simulation(scene, **run_opts).run(out=tmp_path / f"{name}.h5", flush_every=every)
        runs[name] = (list(written), read_run(tmp_path / f"{name}.h5"))
    n_frames = round(DURATION / OUTPUT_INTERVAL) + 1
    # The frame at t = 0 waits for the next; every later frame is written as it comes.
    assert runs["each"][0] == list(range(2, n_frames + 1))
    assert runs["end"][0] == []  # the rows kept are written by close, not flush
    assert runs["bytes"][0] == runs["each"][0]
    for name in ("end", "bytes"):
        for group in ("series", "frames"):
            a, b = runs["each"][1][group], runs[name][1][group]
            assert a.keys() == b.keys() and len(a["time"]) > 1
            for key in a:
                np.testing.assert_array_equal(b[key], a[key], err_msg=f"{name}: {group}/{key}")
    assert len(runs["end"][1]["frames"]["time"]) == n_frames
