"""Checkpoint and resume: a run killed after a checkpoint and resumed equals, bit for bit, the
run that was never stopped; with rate-and-state contacts jammed between a pusher and a wall.
So does an ensemble (every world of a batch in one checkpoint, the laws finished read back),
and a paper run resumed skips what it finished."""

from __future__ import annotations

import copy
import dataclasses
import json

import h5py
import numpy as np
import pytest
from jam_bodies import jam_bodies

from taichi_ice import Simulation, load_scenario
from taichi_ice.commands.cli import main
from taichi_ice.errors import RunFileError
from taichi_ice.physics.friction import Coulomb, RateState
from taichi_ice.physics.slip import NO_INTERFACE
from taichi_ice.run import checkpoint as ckpt
from taichi_ice.run.runfile import RunWriter
from taichi_ice.run.runfile_read import read_run
from taichi_ice.scene.parse import scene_from_dict
from taichi_ice.tomlio import dump_toml

UNTIL = 0.3  # s
STOP_AT_FLUSH = 5  # the run is killed at its 5th frame write, last checkpointed at t = 0.2 s,
# when the blocks slide on the floor with a rate-and-state interface (at 0.15 s they are stuck)


def jam():
    """Three 1 m squares pressed onto a floor (an external force of 200 kN each), pushed
    along it by a kinematic pusher at 2 cm/s against a wall, with rate-and-state friction:
    they jam between the pusher and the wall while sliding on the floor."""
    raw = copy.deepcopy(dict(load_scenario("scenarios/two_squares.toml").raw))
    # dt_safety 0.2: the step this jam was written at (rate and state's "auto" is 0.05).
    raw["simulation"].update(
        duration=UNTIL, output_interval=0.05, series_interval=0.01, dt_safety=0.2
    )
    raw["friction"] = {"law": "rate-state"}
    raw["body"] = jam_bodies(push=0.02)
    return scene_from_dict(raw, source="jam")


def fields(sim) -> dict:
    world = sim.world
    out = {f"data/{n}": getattr(world.data, n).to_numpy() for n in world.data.names}
    out.update(
        {f"nbr/{n}": getattr(world.neighbours, n).to_numpy() for n in world.neighbours.names}
    )
    return out


@pytest.mark.parametrize("integrator", ["euler", "coupled", "midstep"])
def test_resumed_run_equals_the_uninterrupted_run_bit_for_bit(tmp_path, monkeypatch, integrator):
    """Killed between two checkpoints and resumed, a run's file and state equal the run's
    that was never stopped, with the default step and with the coupled one (whose contacts
    also carry their last mean forces)."""
    scene = jam()
    whole = Simulation(scene, integrator=integrator)
    whole.run(until=UNTIL, out=tmp_path / "whole.h5")
    whole_fields = fields(whole)
    del whole  # its World (kernels compiled) serves the next Simulation

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
        Simulation(scene, integrator=integrator).run(until=UNTIL, out=path, checkpoint_every=0)
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

    resumed = Simulation(scene, integrator=integrator)
    result = resumed.run(until=UNTIL, out=path, resume=True)
    assert result.status == "complete"
    # The checkpoint held the scene's bodies' rows, not the capacity's (the resumed fields'
    # rows past them are a new World's, as the uninterrupted run's are), and every world's.
    layout = resumed.world.layout
    assert saved["data"]["body_pos"].shape[0] == scene.n_bodies < layout.n_bodies
    assert saved["nbr"]["world_nbr_stale"].shape[0] == layout.n_worlds

    a, b = read_run(tmp_path / "whole.h5"), read_run(path)
    assert b["attrs"]["resumed"] == 1
    for group in ("series", "frames"):
        for name, values in a[group].items():
            np.testing.assert_array_equal(b[group][name], values, err_msg=f"{group}/{name}")
    assert np.max(np.abs(a["series"]["probe_force"])) > 0.0  # the jam pushes on its probes
    for name, values in whole_fields.items():
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
    # The same text whose [ice] resolved otherwise (a default that changed, as slide_resolution
    # did from 0 to 0.025): another run, though its text is the same.
    resolved = dataclasses.replace(scene, ice=dataclasses.replace(scene.ice, slide_resolution=0.0))
    assert resolved.text == scene.text and resolved.ice != scene.ice
    with pytest.raises(RunFileError, match="its scene differs"):
        Simulation(resolved).run(until=UNTIL, out=path, resume=True)
    # Another integrator steps another state (the analytic step's position impulses).
    # The message names the checkpoint's integrator and how to resume with it.
    made_with = Simulation(scene).options.integrator
    with pytest.raises(RunFileError, match="its integrator differs") as info:
        Simulation(scene, integrator="analytic").run(until=UNTIL, out=path, resume=True)
    assert f"--integrator {made_with}" in str(info.value)
    # A checkpoint of another state layout (format 1 had two contact buffers) is refused.
    with h5py.File(ckpt.path_for(path), "r+") as f:
        f.attrs["format_version"] = "1"
    with pytest.raises(RunFileError, match="format 1"):
        Simulation(scene).run(until=UNTIL, out=path, resume=True)
    ckpt.remove(ckpt.path_for(path))
    with pytest.raises(RunFileError, match="no checkpoint"):
        Simulation(scene).run(until=UNTIL, out=path, resume=True)


def test_ensembles_and_sweeps_tell_a_changed_default_from_the_same_scene():
    """What an ensemble's or paper's ledger and a sweep compare on resume: the same text whose
    [ice] resolved otherwise (slide_resolution's default went from 0 to 0.025) is another
    scene to each, and the same scene is the same."""
    from types import SimpleNamespace

    from taichi_ice.experiments.ledger import scene_digest
    from taichi_ice.experiments.sweep.run import _identity

    scene = jam()
    again = scene_from_dict(copy.deepcopy(dict(scene.raw)))
    resolved = dataclasses.replace(scene, ice=dataclasses.replace(scene.ice, slide_resolution=0.0))
    assert resolved.text == scene.text == again.text
    assert scene_digest(again) == scene_digest(scene) != scene_digest(resolved)

    def sweep_of(s):
        return _identity(
            SimpleNamespace(scene=s, until=1.0, window=None, laws=(s.friction,)), "cpu", "f64"
        )

    assert sweep_of(again) == sweep_of(scene) != sweep_of(resolved)

    # The same for a step that resolved otherwise: rate and state's dt_safety, 0.2 until
    # 2026-11-28, 0.05 since (the text leaves it to the law).
    raw = copy.deepcopy(dict(scene.raw))
    del raw["simulation"]["dt_safety"]
    unset = scene_from_dict(raw)
    old = dataclasses.replace(
        unset, simulation=dataclasses.replace(unset.simulation, dt_safety=0.2)
    )
    assert old.text == unset.text and (old.dt_safety, unset.dt_safety) == (0.2, 0.05)
    assert scene_digest(old) != scene_digest(unset)
    assert sweep_of(old) != sweep_of(unset)
    # A sweep's laws resolve their own steps: a Coulomb scene swept with rate and state.
    coulomb = unset.with_friction(Coulomb(mu=0.5))
    laws = {"coulomb": (Coulomb(mu=0.5),), "both": (Coulomb(mu=0.5), RateState())}
    both = {
        k: _identity(SimpleNamespace(scene=coulomb, until=1.0, window=None, laws=v), "cpu", "f64")
        for k, v in laws.items()
    }
    assert both["coulomb"]["dt_safety"] == {Coulomb(mu=0.5).label: 0.6}
    assert both["both"]["dt_safety"] == {Coulomb(mu=0.5).label: 0.6, RateState().label: 0.05}
    # And Coulomb's, 0.2 with the Euler step until 2026-12-02, 0.6 with the midstep step
    # since (its default integrator): another scene to each.
    euler = dataclasses.replace(
        coulomb, simulation=dataclasses.replace(coulomb.simulation, dt_safety=0.2)
    )
    assert euler.text == coulomb.text and (euler.dt_safety, coulomb.dt_safety) == (0.2, 0.6)
    assert scene_digest(euler) != scene_digest(coulomb)
    assert sweep_of(euler) != sweep_of(coulomb)


# --------------------------------------------------------------------------------------------
# Commands made of batches: `taichi-ice ensemble` and `taichi-ice paper`
# --------------------------------------------------------------------------------------------


def jam_file(tmp_path):
    """The jam as a scene file, with two loose squares drifting at jittered speeds beside it:
    every seed is another world (``scene.reseeded``), the jam in each."""
    raw = copy.deepcopy(dict(jam().raw))
    raw["field"] = [
        {
            "name": "drift",
            "shape": "rectangle",
            "width": 0.5,
            "length": 0.5,
            "rows": 1,
            "columns": 2,
            "origin": [0.0, 3.0],
            "spacing": [0.52, 1.0],
            "jitter": 0.003,
            "velocity_jitter": 0.1,
        }
    ]
    path = tmp_path / "jam.toml"
    path.write_text(dump_toml(raw))
    return path


def die_at(monkeypatch, path, n):
    """Raise KeyboardInterrupt (a kill) at the ``n``-th flush of run file ``path``."""
    flush = RunWriter.flush
    calls = {"n": 0}

    def flush_then_die(self, steps, **attrs):
        if self.path == path:
            calls["n"] += 1
            if calls["n"] == n:
                raise KeyboardInterrupt
        flush(self, steps, **attrs)

    monkeypatch.setattr(RunWriter, "flush", flush_then_die)
    return flush


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def assert_same_runs(a, b):
    for group in ("series", "frames", "bodies"):
        assert a[group].keys() == b[group].keys()
        for name, values in a[group].items():
            np.testing.assert_array_equal(b[group][name], values, err_msg=f"{group}/{name}")


def test_a_resumed_ensemble_equals_the_uninterrupted_one_value_for_value(
    tmp_path, monkeypatch, capsys
):
    """Two rate-and-state laws over 3 seeds; killed in the second law after 3 checkpoints of
    its batch, refused when resumed with other options, then resumed: the first law is read
    back (its files untouched), the second continues from its checkpoint, and every CSV row,
    JSON value (but wall times) and run file equals the ensemble that was never stopped."""
    scene = jam_file(tmp_path)
    argv = ["ensemble", str(scene), "--seeds", "3", "--until", str(UNTIL), "--quiet"]
    argv += ["--friction", "rate-state", "--friction", "rate-state:t_c=0.5"]
    whole, out = tmp_path / "whole", tmp_path / "killed"
    assert main([*argv, "--out", str(whole)]) == 0

    second = out / "rate-state_t_c0.5"
    flush = die_at(monkeypatch, second / "seed-0000.h5", STOP_AT_FLUSH)
    assert main([*argv, "--out", str(out), "--checkpoint-every", "0"]) == 130
    monkeypatch.setattr(RunWriter, "flush", flush)
    saved = ckpt.read(ckpt.path_for(second / "seed-0000.h5"))
    assert saved["attrs"]["n_frames"] == [STOP_AT_FLUSH] * 3  # t = 0, ..., 0.15 s
    # Every world of the batch is in the checkpoint, in rate-and-state contact.
    assert len(saved["attrs"]["scenarios"]) == 3
    theta = saved["data"]["contact_theta"]
    assert np.any((theta != NO_INTERFACE) & (theta != 0.0))
    assert not (out / "ensemble.csv").exists()
    first = sorted((out / "rate-state").glob("seed-*.h5"))
    assert len(first) == 3 and not list((out / "rate-state").glob("*.ckpt"))
    stamps = [p.stat().st_mtime_ns for p in first]
    capsys.readouterr()

    # Without --resume the folder is refused; with other options the resume is.
    assert main([*argv, "--out", str(out)]) == 2
    assert "pass --resume" in one_line(capsys.readouterr().err)
    other = [a if a != str(UNTIL) else "0.25" for a in argv]
    assert main([*other, "--out", str(out), "--resume"]) == 2
    assert "until: 0.3 there, 0.25 now" in one_line(capsys.readouterr().err)
    assert main([*argv, "--out", str(tmp_path / "none"), "--resume"]) == 2
    assert "no ensemble to resume" in one_line(capsys.readouterr().err)

    assert main([*argv, "--out", str(out), "--resume"]) == 0
    assert [p.stat().st_mtime_ns for p in first] == stamps  # read back, not run again
    assert (out / "ensemble.csv").read_text() == (whole / "ensemble.csv").read_text()
    a, b = (json.loads((d / "ensemble.json").read_text()) for d in (whole, out))
    for report in (a, b):
        for law in report["laws"].values():
            law.pop("wall_time")
    assert a == b
    assert np.isfinite(a["laws"]["rate-state"]["metrics"][0]["peak_force"])
    for path in sorted(whole.glob("*/seed-*.h5")):
        run = read_run(out / path.relative_to(whole))
        assert run["attrs"]["status"] == "complete"
        assert run["attrs"]["resumed"] == (1 if path.parent.name == second.name else 0)
        assert_same_runs(read_run(path), run)
    # The worlds differ (the seeds drew other drifts), and the jam pushed on its probes.
    runs = [read_run(p) for p in sorted((whole / "rate-state").glob("seed-*.h5"))]
    assert not np.array_equal(runs[0]["frames"]["position"], runs[1]["frames"]["position"])
    assert np.max(np.abs(runs[0]["series"]["probe_force"])) > 0.0
    assert not list(out.glob("*/*.ckpt"))  # finished batches keep no checkpoint


def test_a_resumed_paper_run_skips_the_parts_finished(tmp_path, monkeypatch, capsys):
    """`taichi-ice paper` (a small scene, 0.1 s, the four models) killed in its third model:
    the resume neither redraws Figure 3 nor reruns the two models finished, continues the
    third from its checkpoint and runs the fourth; the summary holds all four."""
    from taichi_ice.experiments.validation import single_interface

    scene = jam_file(tmp_path)
    out = tmp_path / "paper"
    argv = ["paper", "--scene", str(scene), "--out", str(out), "--until", "0.1", "--seeds", "2"]
    argv += ["--paper-only", "--quick", "--quiet", "--checkpoint-every", "0"]
    flush = die_at(monkeypatch, out / "runs" / "mu0.9.h5", 2)
    assert main(argv) == 130
    monkeypatch.setattr(RunWriter, "flush", flush)
    assert ckpt.path_for(out / "runs" / "mu0.9.h5").is_file()
    assert not (out / "summary.json").exists()
    assert not (out / "runs" / "rate-state.h5").exists()
    finished = [out / "runs" / f"{m}.h5" for m in ("mu0.1", "mu0.5")]
    stamps = [p.stat().st_mtime_ns for p in finished]
    capsys.readouterr()
    assert main(argv) == 2  # the folder holds a paper run: --resume or --overwrite
    assert "pass --resume" in one_line(capsys.readouterr().err)

    drawn, ran = [], []
    monkeypatch.setattr(single_interface, "run", lambda *a, **k: drawn.append(a))
    simulate = Simulation.run

    def run(self, *args, **kwargs):
        ran.append((self.scenes[0].friction.label, kwargs.get("resume")))
        return simulate(self, *args, **kwargs)

    monkeypatch.setattr(Simulation, "run", run)
    assert main([*argv, "--resume"]) == 0
    assert drawn == []
    assert ran == [("mu0.9", True), ("rate-state", False)]
    assert [p.stat().st_mtime_ns for p in finished] == stamps
    assert read_run(out / "runs" / "mu0.9.h5")["attrs"]["resumed"] == 1
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary["models"]) == ["mu0.1", "mu0.5", "mu0.9", "rate-state"]
    for entry in summary["models"].values():
        assert entry["single"]["status"] == "complete"
        assert entry["single"]["steps"] == round(0.1 / entry["single"]["dt"])
        assert entry["spread"]["peak_force"]["n"] == 2
    assert (out / "figures" / "fig3_single_interface.png").is_file()
