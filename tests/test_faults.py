"""Nothing lost, nothing silent (issue 27): a run that crashes says so in its file, a dt too
small to count is refused, a resume never continues one run from another's checkpoint, a
full disk stops a run with its file whole, blocks that would pass through each other are
refused, and hostile input is one line.

Each test reproduces a fault found by trying the landed code as a hostile user would: an
OverflowError from ``--dt 1e-300`` left a file marked ``complete`` with 0 steps; a stale
checkpoint left by a finished run was restored into the run that overwrote it, padding its
file with rows of zeros marked ``complete``; a checkpoint of another run was accepted; a
full disk segfaulted the run and left its file unreadable; two squares at 1,000 m/s passed
through each other "complete"; deep TOML, a NUL in a name and an empty run were tracebacks.
Each test fails on the code before its fix.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from taichi_ice import Simulation, load_scenario
from taichi_ice.commands.cli import main
from taichi_ice.engine.world import World
from taichi_ice.errors import DivergenceError, RunFileError
from taichi_ice.run import checkpoint as ckpt
from taichi_ice.run.runfile import DiskFullError
from taichi_ice.run.runfile_read import read_run

ROOT = Path(__file__).resolve().parents[1]
TWO_SQUARES = str(ROOT / "scenarios" / "two_squares.toml")


def one_line(err: str) -> str:
    """The one error line of a command's stderr (after its header line, if it printed one),
    and no traceback."""
    assert "Traceback" not in err, err
    lines = [x for x in err.strip().splitlines() if x.startswith("taichi-ice:")]
    assert len(lines) == 1, err
    return lines[0]


@pytest.fixture(scope="module")
def scene():
    return load_scenario(TWO_SQUARES)


def run(scene, path, until, **kw):
    return Simulation(scene).run(until=until, out=path, **kw)


def test_a_run_that_crashes_on_an_error_not_ours_is_marked_failed(scene, tmp_path, monkeypatch):
    """Any exception, not only the package's own, ends the file as ``failed`` with the
    exception's type and message, and keeps the rows written before it readable."""
    advance = World.advance_sampled
    calls = {"n": 0}

    def fail_on_the_third(self, plan):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError(28, "No space left on device")
        return advance(self, plan)

    monkeypatch.setattr(World, "advance_sampled", fail_on_the_third)
    path = tmp_path / "crash.h5"
    with pytest.raises(OSError):
        run(scene, path, 0.05, flush_every=0)
    monkeypatch.setattr(World, "advance_sampled", advance)
    got = read_run(path)
    assert got["attrs"]["status"] == "failed"
    assert got["attrs"]["failure"].startswith("OSError: ")
    assert "No space left" in got["attrs"]["failure"]
    assert len(got["frames"]["time"]) >= 1  # what was flushed before is there


def test_a_dt_too_small_to_count_is_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "tiny.h5"
    argv = ["run", TWO_SQUARES, "--dt", "1e-300", "--until", "0.01", "--out", str(out)]
    assert main([*argv, "--quiet"]) == 2
    line = one_line(capsys.readouterr().err)
    assert "steps per frame" in line and "larger dt" in line
    assert not out.exists()


def test_overwrite_removes_the_stale_checkpoint_so_resume_has_nothing_to_restore(tmp_path, capsys):
    """The reproduction: a finished run with checkpoints, then the same path overwritten
    without them, then ``--resume``: the old checkpoint used to be restored into the new
    file (rows of zeros, ``complete``). Now the overwrite removes it, and the resume says
    there is none."""
    out = tmp_path / "p.h5"
    base = ["run", TWO_SQUARES, "--out", str(out), "--quiet"]
    assert main([*base, "--until", "0.05", "--checkpoint-every", "0"]) == 0
    assert ckpt.path_for(out).exists()
    assert main([*base, "--until", "0.02", "--overwrite"]) == 0
    assert not ckpt.path_for(out).exists()
    before = read_run(out)
    capsys.readouterr()
    assert main([*base, "--until", "0.05", "--resume"]) == 2
    assert "no checkpoint" in one_line(capsys.readouterr().err)
    after = read_run(out)
    assert after["attrs"]["status"] == before["attrs"]["status"] == "complete"
    np.testing.assert_array_equal(after["series"]["time"], before["series"]["time"])


def test_resume_refuses_a_checkpoint_of_another_run_and_leaves_the_file_as_it_was(scene, tmp_path):
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    run(scene, a, 0.04, checkpoint_every=0)
    run(scene, b, 0.04, checkpoint_every=0)
    shutil.copyfile(ckpt.path_for(b), ckpt.path_for(a))  # same scene, another run
    before = read_run(a)
    with pytest.raises(RunFileError, match="belongs to another run"):
        run(scene, a, 0.08, resume=True)
    after = read_run(a)
    assert after["attrs"]["status"] == "complete"
    assert after["attrs"].get("resumed", 0) == before["attrs"].get("resumed", 0)
    np.testing.assert_array_equal(after["series"]["time"], before["series"]["time"])


def test_resume_refuses_a_checkpoint_that_counts_more_rows_than_the_file_holds(scene, tmp_path):
    """A checkpoint written before run ids (no ``run_ids`` attribute) is still checked
    against the rows its file holds: the file was replaced by a shorter run."""
    path = tmp_path / "r.h5"
    run(scene, path, 0.08, checkpoint_every=0)
    saved = tmp_path / "saved.ckpt"
    shutil.copyfile(ckpt.path_for(path), saved)
    run(scene, path, 0.02)  # a new, shorter run in its place
    shutil.copyfile(saved, ckpt.path_for(path))
    with h5py.File(ckpt.path_for(path), "a") as f:
        del f.attrs["run_ids"]
        resign(f)  # a whole checkpoint, only without ids: the rows must catch it
    with pytest.raises(RunFileError, match="fewer than"):
        run(scene, path, 0.1, resume=True)
    assert read_run(path)["attrs"]["status"] == "complete"


def resign(f: h5py.File) -> None:
    """Write the digest of a checkpoint changed on purpose (as its writer would have)."""
    groups = {g: {n: ds[()] for n, ds in f[g].items()} for g in ("data", "nbr", "host")}
    f.attrs["digest"] = ckpt.digest(groups, dict(f.attrs))


def test_a_checkpoint_whose_data_were_damaged_is_refused_not_restored(scene, tmp_path):
    """HDF5 keeps no checksum of its data: one flipped bit in a saved velocity used to be
    restored and run on, silently. The digest written with the checkpoint refuses it."""
    path = tmp_path / "v.h5"
    run(scene, path, 0.04, checkpoint_every=0)
    with h5py.File(ckpt.path_for(path), "a") as f:
        vel = f["data/body_vel"][()]
        vel.reshape(-1).view(np.uint8)[3] ^= 0x10  # a low bit of the first velocity
        f["data/body_vel"][...] = vel
    before = read_run(path)
    with pytest.raises(RunFileError, match=r"damaged checkpoint .* digest"):
        run(scene, path, 0.08, resume=True)
    np.testing.assert_array_equal(read_run(path)["series"]["time"], before["series"]["time"])


def test_a_checkpoint_with_a_damaged_attribute_is_one_clear_error(scene, tmp_path):
    path = tmp_path / "d.h5"
    run(scene, path, 0.04, checkpoint_every=0)
    with h5py.File(ckpt.path_for(path), "a") as f:
        f.attrs["n_samples"] = "[1, 2"
    with pytest.raises(RunFileError, match="damaged checkpoint"):
        ckpt.read(ckpt.path_for(path))


# --------------------------------------------------------------------------------------------
# A full disk
# --------------------------------------------------------------------------------------------


def test_a_full_disk_stops_the_run_with_its_file_whole_and_resume_finishes_it(
    scene, tmp_path, monkeypatch
):
    """The disk fills during the run (simulated: the file system reports less and less free
    space): the run stops with a DiskFullError before the write that would not fit, the file
    says ``failed`` and why and holds every row written before, the checkpoint is kept, and
    once there is room ``resume`` finishes it equal to a run never stopped."""
    import shutil as real_shutil

    import taichi_ice.run.runfile as runio

    whole = run(scene, tmp_path / "whole.h5", 0.1)
    usage = real_shutil.disk_usage
    calls = {"n": 0}

    def filling(path):
        calls["n"] += 1
        free = 0 if calls["n"] > 12 else 1 << 40
        return usage(path)._replace(free=free)

    monkeypatch.setattr(runio.shutil, "disk_usage", filling)
    path = tmp_path / "full.h5"
    with pytest.raises(DiskFullError, match="the disk is full"):
        run(scene, path, 0.1, flush_every=0, checkpoint_every=0)
    monkeypatch.setattr(runio.shutil, "disk_usage", usage)
    stopped = read_run(path)
    assert stopped["attrs"]["status"] == "failed"
    assert "the disk is full" in stopped["attrs"]["failure"]
    assert 0 < len(stopped["frames"]["time"]) < len(whole.series[0]["time"])
    assert ckpt.path_for(path).exists()

    result = run(scene, path, 0.1, resume=True)
    assert result.status == "complete"
    done = read_run(path)
    for name, values in read_run(tmp_path / "whole.h5")["series"].items():
        np.testing.assert_array_equal(done["series"][name], values, err_msg=name)


def test_a_run_on_a_real_full_file_system_stops_cleanly(scene, tmp_path):
    """The same on a tmpfs of 1.5 MB (root only): the pillar's run file outgrows it. With
    the Euler step, whose checkpoint asks for 1.11 MB of room (twice its arrays, with a
    margin) and fits beside the first frames; the midstep step's (Coulomb's default) holds
    the analytic step's contact forces too and asks for 1.23 MB, more than the empty tmpfs
    has, so that run stops at its first checkpoint, before it could keep one."""
    import subprocess

    mnt = tmp_path / "small"
    mnt.mkdir()
    mounted = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=1500k", "tmpfs", str(mnt)], capture_output=True
    )
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode().strip()}")
    try:
        path = mnt / "p.h5"
        pillar = load_scenario("pillar")
        with pytest.raises(DiskFullError):
            Simulation(pillar, integrator="euler").run(
                until=20.0, out=path, flush_every=0, checkpoint_every=0
            )
        got = read_run(path)
        assert got["attrs"]["status"] == "failed"
        assert "the disk is full" in got["attrs"]["failure"]
        assert len(got["frames"]["time"]) > 1
        assert ckpt.read(ckpt.path_for(path))["attrs"]["steps"] > 0
    finally:
        subprocess.run(["umount", str(mnt)], capture_output=True)


# --------------------------------------------------------------------------------------------
# Bodies that would pass through each other
# --------------------------------------------------------------------------------------------


def head_on(speed: float):
    import copy

    from taichi_ice.scene.parse import scene_from_dict

    raw = copy.deepcopy(dict(load_scenario(TWO_SQUARES).raw))
    raw["body"][0]["velocity"] = [speed, 0.0]
    raw["body"][1]["velocity"] = [-speed, 0.0]
    return scene_from_dict(raw, source=f"head-on at {speed:g} m/s")


def test_blocks_fast_enough_to_pass_through_each_other_are_refused_up_front(monkeypatch):
    """Two 1 m squares head-on: at 1,000 m/s each they pass through each other (the run
    used to end "complete", each square on the other's side); now the scene is refused,
    naming the body and the speed the contact resolves. At 100 m/s they bounce back."""
    import taichi_ice.run.simulation as simulation
    from taichi_ice.errors import StabilityError

    with pytest.raises(StabilityError, match="pass through each other"):
        Simulation(head_on(1000.0))
    slow = Simulation(head_on(100.0))
    slow.run(until=0.02)
    x = slow.positions()[:, 0]
    assert x[0] < -1.0 and x[1] > 1.0  # bounced: each back on its own side
    # What the refusal prevents: the same collision, the check off, with the Euler step (at
    # the midstep step's 0.6 of the limit, Coulomb's default, the runaway check stops it
    # first: 1,000 m/s is more than a quarter of a block a step there).
    monkeypatch.setattr(simulation, "check_approach", lambda scene: None)
    with pytest.raises(DivergenceError, match="faster than 500 m/s"):
        Simulation(head_on(1000.0)).run(until=0.02)
    fast = Simulation(head_on(1000.0), integrator="euler")
    fast.run(until=0.02)
    x = fast.positions()[:, 0]
    assert x[0] > 1.0 and x[1] < -1.0  # passed through


def test_a_pusher_too_fast_for_the_contacts_is_refused_in_one_line(tmp_path, capsys):
    scene = tmp_path / "fast_pusher.toml"
    text = (ROOT / "scenarios" / "pushed_field.toml").read_text()
    assert "velocity = [0.0, -0.1]" in text
    scene.write_text(text.replace("velocity = [0.0, -0.1]", "velocity = [0.0, -1000.0]", 1))
    out = tmp_path / "p.h5"
    assert main(["run", str(scene), "--until", "0.01", "--out", str(out), "--quiet"]) == 2
    line = one_line(capsys.readouterr().err)
    assert "pusher" in line and "1000 m/s" in line and "pass through" in line
    assert not out.exists()


def test_a_disk_that_fills_before_the_last_write_fails_the_run_it_does_not_pass(
    scene, tmp_path, monkeypatch
):
    """No room for the rows kept at the end of a run that otherwise completed: the file is
    marked failed (not complete) and whole, and the run raises, not returns."""
    import shutil as real_shutil

    import taichi_ice.run.runfile as runio

    usage = real_shutil.disk_usage
    calls = {"n": 0}

    def full_after_the_first_call(path):
        calls["n"] += 1
        return usage(path)._replace(free=0 if calls["n"] > 1 else 1 << 40)

    monkeypatch.setattr(runio.shutil, "disk_usage", full_after_the_first_call)
    path = tmp_path / "last.h5"
    with pytest.raises(DiskFullError, match="writing the last rows"):
        run(scene, path, 0.03, flush_every=3600)
    monkeypatch.setattr(runio.shutil, "disk_usage", usage)
    got = read_run(path)
    assert got["attrs"]["status"] == "failed"
    assert "the disk is full" in got["attrs"]["failure"]


def test_resume_and_overwrite_together_are_refused(tmp_path, capsys):
    out = tmp_path / "both.h5"
    with pytest.raises(SystemExit) as info:
        main(["run", TWO_SQUARES, "--out", str(out), "--resume", "--overwrite"])
    assert info.value.code == 2
    assert "not allowed with argument" in capsys.readouterr().err
    assert not out.exists()


# --------------------------------------------------------------------------------------------
# Hostile input: one line, no traceback
# --------------------------------------------------------------------------------------------


def test_toml_nested_too_deeply_is_one_line_for_scenes_and_sweeps(tmp_path, capsys):
    """tomllib recurses once a level: 1e5 nested arrays were a RecursionError traceback."""
    deep = tmp_path / "deep.toml"
    deep.write_text("a = " + "[" * 100_000 + "\n")
    for argv in (
        ["run", str(deep), "--out", str(tmp_path / "d.h5")],
        ["sweep", str(deep), "--out", str(tmp_path / "sweep"), "--workers", "0"],
    ):
        assert main(argv) == 2
        assert "nested too deeply" in one_line(capsys.readouterr().err)
    assert not (tmp_path / "d.h5").exists()


def test_a_sweep_file_that_is_not_utf8_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_bytes(b"\xff\xfe[sweep]\n")
    assert main(["sweep", str(bad), "--out", str(tmp_path / "sweep"), "--workers", "0"]) == 2
    line = one_line(capsys.readouterr().err)
    assert str(bad) in line and "UTF-8" in line and "0xff" in line


def test_a_body_name_with_a_nul_is_refused_before_a_file_is_made(tmp_path, capsys):
    """h5py cannot store a NUL in a string: the run used to fail after creating its file,
    which stayed 'running' forever."""
    scene = tmp_path / "nul.toml"
    text = Path(TWO_SQUARES).read_text()
    assert 'name = "left"' in text
    scene.write_text(text.replace('name = "left"', 'name = "le\\u0000ft"', 1))
    out = tmp_path / "nul.h5"
    assert main(["run", str(scene), "--out", str(out), "--until", "0.01"]) == 2
    line = one_line(capsys.readouterr().err)
    assert "key 'name'" in line and "control character" in line and "\x00" not in line
    assert not out.exists()


def test_plotting_a_run_with_no_rows_yet_is_one_line_and_makes_nothing(scene, tmp_path, capsys):
    """A run killed before its first write: plot used to raise IndexError."""
    from taichi_ice.run.runfile import RunWriter

    path = tmp_path / "empty.h5"
    RunWriter(path, scene, {})  # created, never written to
    out = tmp_path / "figures"
    assert main(["plot", str(path), "--out", str(out)]) == 2
    assert "no sample or frame yet" in one_line(capsys.readouterr().err)
    assert not out.exists()


def test_a_bad_scene_run_without_out_leaves_no_runs_folder(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.toml").write_text("[simulation]\nduration = -1\n")
    assert main(["run", "bad.toml"]) == 2
    assert "duration" in one_line(capsys.readouterr().err)
    assert not (tmp_path / "runs").exists()


def test_bench_checks_its_outputs_and_seed_before_benchmarking(tmp_path, capsys):
    """bench found an unwritable --out only after benchmarking (the results lost), wrote
    --name ../../x outside --out, and took --seed -1 into a traceback."""
    afile = tmp_path / "afile"
    afile.write_text("")
    for argv, words in (
        (["--name", "../../x"], "plain file name"),
        (["--out", str(afile / "sub")], "cannot write there"),
    ):
        assert main(["bench", "--quick", "--no-box2d", *argv]) == 2
        assert words in one_line(capsys.readouterr().err)
    with pytest.raises(SystemExit) as info:
        main(["bench", "--quick", "--seed", "-1"])
    assert info.value.code == 2
    assert "0 or more" in capsys.readouterr().err
    assert not list(tmp_path.parent.glob("x*"))


def test_a_full_disk_refuses_an_overwrite_with_the_old_file_still_whole(
    scene, tmp_path, monkeypatch
):
    import shutil as real_shutil

    import taichi_ice.run.runfile as runio

    path = tmp_path / "old.h5"
    run(scene, path, 0.02)
    before = read_run(path)
    usage = real_shutil.disk_usage
    monkeypatch.setattr(runio.shutil, "disk_usage", lambda p: usage(p)._replace(free=0))
    with pytest.raises(DiskFullError, match="nothing was written"):
        run(scene, path, 0.02)
    monkeypatch.setattr(runio.shutil, "disk_usage", usage)
    after = read_run(path)
    assert after["attrs"]["run_id"] == before["attrs"]["run_id"]
    np.testing.assert_array_equal(after["series"]["time"], before["series"]["time"])


def test_resuming_with_another_friction_law_names_the_law(scene, tmp_path):
    """A checkpoint of a Coulomb run resumed with rate-and-state used to be reported as
    "its scene differs"."""
    from taichi_ice.physics.friction import RateState

    path = tmp_path / "law.h5"
    run(scene, path, 0.04, checkpoint_every=0)
    with pytest.raises(RunFileError, match="its friction law differs"):
        Simulation(scene, friction=RateState()).run(until=0.08, out=path, resume=True)
    assert read_run(path)["attrs"]["status"] == "complete"


# --------------------------------------------------------------------------------------------
# Limits (item 7): refused in one line before anything is built, compiled or written
# --------------------------------------------------------------------------------------------

BIG_FIELD = """
[simulation]
duration = 1.0
[ice]
density = 920.0
thickness = 0.3
contact_stiffness = 9.75e7
contact_viscosity = 3.16e4
[friction]
law = "coulomb"
mu = 0.5
[[field]]
shape = "diamond"
width = 0.7
length = 1.0
rows = 1000
columns = 1000
origin = [0.0, 0.0]
spacing = [0.8, 1.05]
"""


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["run", TWO_SQUARES, "--slots", "-3"], "use 1 to 64 contact slots"),
        (["run", TWO_SQUARES, "--slots", "0"], "use 1 to 64 contact slots"),
        (["run", TWO_SQUARES, "--slots", "1000000000"], "use 1 to 64 contact slots"),
        (["study", "--workers", "-2"], "0 or more"),
        (["sweep", "--scene", "two_squares", "--seeds", "4", "--workers", "5000"], "--scheduler"),
        (["sweep", "--scene", "two_squares", "--seeds", "4", "--batch-size", "0"], "1 or more"),
    ],
    ids=["slots -3", "slots 0", "slots 1e9", "study workers -2", "workers 5000", "batch 0"],
)
def test_counts_out_of_range_are_refused_by_the_command_line(argv, words, tmp_path, capsys):
    """--slots -3 used to compile and then fail; 1e9 reached Taichi's allocator (a 40 GB
    request and a traceback); study --workers -2 hung."""
    with pytest.raises(SystemExit) as exit_:
        main([*argv, "--out", str(tmp_path / "o")])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and words in err.strip().splitlines()[-1]
    assert not (tmp_path / "o").exists()


def test_slots_out_of_range_are_refused_by_the_api(scene):
    from taichi_ice.errors import UsageError

    for slots in (0, -3, 10**9, 2.5):
        with pytest.raises(UsageError, match="slots"):
            Simulation(scene, slots=slots)


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["bench", "--sizes", "1e12", "--no-box2d"], "32-bit integers"),
        (["ensemble", TWO_SQUARES, "--seeds", "10000000000"], "fewer --seeds"),
        (["sweep", "--scene", "two_squares", "--seeds", "100000000"], "at most 1,000,000 worlds"),
    ],
    ids=["bench 1e12", "ensemble 1e10 seeds", "sweep 1e8 seeds"],
)
def test_work_too_large_for_the_machine_is_refused_before_it_starts(argv, words, tmp_path, capsys):
    """bench --sizes 1e12 was a traceback in each worker; an ensemble of 1e7 seeds grew the
    process silently; a sweep of 1e8 seeds ended in a MemoryError. Refused in one line,
    nothing made."""
    out = tmp_path / "o"
    quiet = [] if argv[0] == "bench" else ["--quiet"]
    assert main([*argv, "--out", str(out), *quiet]) == 2
    assert words in one_line(capsys.readouterr().err)
    assert not out.exists()


def test_the_memory_guard_reads_the_jobs_address_space_limit(tmp_path):
    """Under ``ulimit -v`` (3 GB) a field of 1e6 blocks (about 4 GB) is refused in one line
    naming the limit. It used to be judged against the machine's free memory and crash in
    Taichi after a minute."""
    import resource
    import subprocess
    import sys

    scene = tmp_path / "big.toml"
    scene.write_text(BIG_FIELD)

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))

    proc = subprocess.run(
        [sys.executable, "-m", "taichi_ice", "run", str(scene), "--out", str(tmp_path / "b.h5")],
        capture_output=True,
        text=True,
        timeout=120,
        preexec_fn=limit,
    )
    assert proc.returncode == 2
    line = one_line(proc.stderr)
    assert "ulimit -v" in line and "1,000,000 bodies" in line and str(scene) in line
    assert not (tmp_path / "b.h5").exists()


def test_a_ledger_damaged_so_that_it_still_parses_is_refused(tmp_path, capsys, taichi_runtime):
    """A byte of ``ensemble-state.json`` changed inside a status ("comp&ete") used to be
    believed: the resume reported the finished part FAILED and exited 1. The ledger's digest
    refuses it in one line, and the run files stay as they were."""
    arch, precision = taichi_runtime
    out = tmp_path / "ens"
    argv = ["ensemble", TWO_SQUARES, "--seeds", "2", "--until", "0.02", "--out", str(out)]
    opts = ["--quiet", "--arch", arch, "--precision", precision]
    assert main([*argv, *opts]) == 0
    ledger = out / "ensemble-state.json"
    text = ledger.read_text()
    assert '"complete"' in text
    ledger.write_text(text.replace('"complete"', '"comp&ete"', 1))
    runs = sorted(out.rglob("*.h5"))
    before = [read_run(p)["series"]["time"] for p in runs]
    capsys.readouterr()
    assert main([*argv, "--resume", *opts]) == 2
    assert "damaged ledger" in one_line(capsys.readouterr().err)
    for p, time in zip(runs, before):
        np.testing.assert_array_equal(read_run(p)["series"]["time"], time)
