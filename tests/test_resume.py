"""Checkpoint and resume: a run killed after a checkpoint and resumed equals, bit for bit, the
run that was never stopped; with rate-and-state contacts jammed between a pusher and a wall."""

from __future__ import annotations

import copy

import h5py
import numpy as np
import pytest

from taichi_ice import Simulation, load_scenario
from taichi_ice import checkpoint as ckpt
from taichi_ice.errors import RunFileError
from taichi_ice.io import RunWriter, read_run
from taichi_ice.scenario import scene_from_dict
from taichi_ice.slip import NO_INTERFACE

UNTIL = 0.3  # s
STOP_AT_FLUSH = 4  # the run is killed at its 4th frame write, after 3 checkpoints


def jam():
    """Three 1 m squares pressed onto a floor (an external force of 200 kN each), pushed
    along it by a kinematic pusher at 2 cm/s against a wall, with rate-and-state friction:
    they jam between the pusher and the wall while sliding on the floor."""
    raw = copy.deepcopy(dict(load_scenario("scenarios/two_squares.toml").raw))
    raw["simulation"].update(duration=UNTIL, output_interval=0.05, series_interval=0.01)
    raw["friction"] = {"law": "rate-state"}
    square = {"shape": "rectangle", "width": 1.0, "length": 1.0}
    raw["body"] = [
        {
            "name": "floor",
            "kind": "fixed",
            "shape": "rectangle",
            "width": 6.0,
            "length": 0.5,
            "position": [1.0, -0.25],
            "probe": True,
        },
        {
            "name": "wall",
            "kind": "fixed",
            "shape": "rectangle",
            "width": 0.5,
            "length": 2.0,
            "position": [1.752, 1.0],
            "probe": True,
        },
        {
            "name": "pusher",
            "kind": "kinematic",
            "shape": "rectangle",
            "width": 0.5,
            "length": 0.9,
            "position": [-1.752, 0.5],
            "velocity": [0.02, 0.0],
        },
    ] + [
        {"name": f"block{i}", **square, "position": [i * 1.001, 0.501], "force": [0.0, -2e5]}
        for i in range(-1, 2)
    ]
    return scene_from_dict(raw, source="jam")


def fields(sim) -> dict:
    world = sim.world
    out = {f"data/{n}": getattr(world.data, n).to_numpy() for n in world.data.names}
    out.update(
        {f"nbr/{n}": getattr(world.neighbours, n).to_numpy() for n in world.neighbours.names}
    )
    return out


def test_resumed_run_equals_the_uninterrupted_run_bit_for_bit(tmp_path, monkeypatch):
    scene = jam()
    whole = Simulation(scene)
    whole.run(until=UNTIL, out=tmp_path / "whole.h5")

    path = tmp_path / "killed.h5"
    flush = RunWriter.flush
    calls = {"n": 0}

    def flush_then_die(self, steps, **attrs):
        calls["n"] += 1
        if calls["n"] == STOP_AT_FLUSH:
            raise KeyboardInterrupt  # a kill between the checkpoint and the next one
        flush(self, steps, **attrs)

    monkeypatch.setattr(RunWriter, "flush", flush_then_die)
    with pytest.raises(KeyboardInterrupt):
        Simulation(scene).run(until=UNTIL, out=path, checkpoint_every=0)
    monkeypatch.setattr(RunWriter, "flush", flush)

    saved = ckpt.read(ckpt.path_for(path))
    killed = read_run(path)
    assert killed["attrs"]["status"] == "failed"
    # The failed file holds rows past the checkpoint: the resume must cut them.
    assert len(killed["frames"]["time"]) > saved["attrs"]["n_frames"][0]
    # At the checkpoint the blocks are in contact and carry rate-and-state memory.
    theta = saved["data"]["contact_theta"]
    assert saved["data"]["contact_count"].sum() > 0
    assert np.any((theta != NO_INTERFACE) & (theta != 0.0))
    assert saved["attrs"]["steps"] > 0

    resumed = Simulation(scene)
    result = resumed.run(until=UNTIL, out=path, resume=True)
    assert result.status == "complete"

    a, b = read_run(tmp_path / "whole.h5"), read_run(path)
    assert b["attrs"]["resumed"] == 1
    for group in ("series", "frames"):
        for name, values in a[group].items():
            np.testing.assert_array_equal(b[group][name], values, err_msg=f"{group}/{name}")
    assert np.max(np.abs(a["series"]["probe_force"])) > 0.0  # the jam pushes on its probes
    for name, values in fields(whole).items():
        np.testing.assert_array_equal(fields(resumed)[name], values, err_msg=name)
    # The run's own result carries the whole series, the part before the checkpoint too.
    np.testing.assert_array_equal(result.series[0]["time"], a["series"]["time"])


def test_resume_refuses_another_scene_an_old_format_and_a_missing_checkpoint(tmp_path):
    scene = jam()
    path = tmp_path / "r.h5"
    Simulation(scene).run(until=0.05, out=path, checkpoint_every=0)
    other = copy.deepcopy(dict(scene.raw))
    other["simulation"]["seed"] = 1
    with pytest.raises(RunFileError, match="another run"):
        Simulation(scene_from_dict(other)).run(until=UNTIL, out=path, resume=True)
    # A checkpoint of another state layout (format 1 had two contact buffers) is refused.
    with h5py.File(ckpt.path_for(path), "r+") as f:
        f.attrs["format_version"] = "1"
    with pytest.raises(RunFileError, match="format 1"):
        Simulation(scene).run(until=UNTIL, out=path, resume=True)
    ckpt.remove(ckpt.path_for(path))
    with pytest.raises(RunFileError, match="no checkpoint"):
        Simulation(scene).run(until=UNTIL, out=path, resume=True)
