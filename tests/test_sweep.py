"""Sweeps: the file is checked like a scene, the grid is what it says, a sweep's dataset does
not depend on the workers or batches, and a killed sweep resumes with only what is missing."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import shapely

from taichi_ice.commands.cli import main
from taichi_ice.experiments.sweep.run import run_sweep
from taichi_ice.experiments.sweep.spec import SweepError, apply_overrides, load_sweep
from taichi_ice.physics.friction import Coulomb, RateState
from taichi_ice.scene.parse import load_scenario

PILLAR = "scenarios/pillar.toml"

# A pillar scene cut to 3 rows of 7 blocks that start 0.035 m below the pillar and drift at
# 0.5 m/s, so that jams build within the 0.4 s the tests run.
SMALL = (
    open(PILLAR)
    .read()
    .replace("rows = 9\n", "rows = 3\n")
    .replace("origin = [0.411, 0.55]", "origin = [0.411, 3.945]")
    .replace("position = [2.8, -0.2]", "position = [2.8, 3.195]")
    .replace("velocity = [0.0, 0.1]     # m/s up", "velocity = [0.0, 0.5]     # m/s up")
    .replace("velocity = [0.0, 0.1]     # m/s: drifting", "velocity = [0.0, 0.5]     # m/s: drift")
)

SWEEP = """
[sweep]
scene = "small.toml"
seeds = { start = 0, count = 2 }
until = 0.4

[[law]]
law = "coulomb"
mu = [0.3, 0.9]

[overrides]
"field.rubble.area_fraction" = [0.75, 0.85]
"""


@pytest.fixture
def sweep_dir(tmp_path):
    (tmp_path / "small.toml").write_text(SMALL)
    (tmp_path / "sweep.toml").write_text(SWEEP)
    return tmp_path


def _bad(tmp_path, text: str) -> str:
    (tmp_path / "small.toml").write_text(SMALL)
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(SweepError) as info:
        load_sweep(path)
    message = str(info.value)
    assert message.startswith(str(path)), message
    return message


BASE = '[sweep]\nscene = "small.toml"\n'


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (BASE + "seed = [0, 1]\n", ["[sweep]", "'seed'", "did you mean 'seeds'"]),
        (BASE + "seeds = [0, 1, 1]\n", ["'seeds'", "repeat"]),
        (BASE + 'seeds = "3"\n', ["'seeds'", "{ start = 0, count = 8 }"]),
        (BASE + "metrics = ['peak_forces']\n", ["'metrics'", "did you mean 'peak_force'"]),
        (BASE + "runs = [7]\n", ["'runs'", "world 7 does not exist"]),
        (BASE + '[[law]]\nlaw = "coulomb"\nmu = [0.5, -1.0]\n', ["[[law]] #0", "'mu'"]),
        (BASE + '[[law]]\nlaw = "rate-state"\nmu = 0.5\n', ["[[law]] #0", "'mu'", "coulomb"]),
        (BASE + '[[law]]\nlaw = "rate_state"\n', ["[[law]] #0", 'did you mean "rate-state"']),
        (
            BASE + '[[law]]\nlaw = "coulomb"\nmu = [0.5]\n[[law]]\nlaw = "coulomb"\n',
            ["[[law]] #1", "mu0.5 is already in [[law]] #0"],
        ),
        (BASE + "[overrides]\nice.thicknes = [0.2]\n", ["[overrides]", "did you mean 'thickness'"]),
        (BASE + '[overrides]\n"body.pushr.speed" = [0.1]\n', ["no body named 'pushr'", "pusher"]),
        (BASE + '[overrides]\n"body.pusher.velocity" = [[0, 1]]\n', ["a number or a list"]),
        (BASE + '[overrides]\n"simulation.seed" = [1]\n', ["[sweep] seeds"]),
        # A value the scene refuses, with the scene's own message: the blocks would overlap.
        (
            BASE + '[overrides]\n"field.rubble.area_fraction" = [0.99]\n',
            ["area_fraction = 0.99", "overlap"],
        ),
    ],
)
def test_bad_sweep_files_are_refused_with_file_table_and_key(tmp_path, text, expected):
    """Each mistake in a sweep file is refused before anything runs, naming file and key."""
    message = _bad(tmp_path, text)
    for part in expected:
        assert part in message, message


def test_bad_sweep_on_the_command_line_is_one_line(tmp_path, capsys):
    """`taichi-ice sweep` with a bad file: exit status 2 and one line on stderr."""
    (tmp_path / "small.toml").write_text(SMALL)
    (tmp_path / "bad.toml").write_text(BASE + "[overrides]\nice.thicknes = [0.2]\n")
    status = main(["sweep", str(tmp_path / "bad.toml"), "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1 and "thicknes" in err[0], err


def test_the_worlds_are_every_law_value_and_seed(sweep_dir):
    """2 laws x 2 area fractions x 2 seeds = 8 worlds, in that nesting, each key unique."""
    sweep = load_sweep(sweep_dir / "sweep.toml")
    worlds = sweep.worlds()
    got = [(w.label, w.overrides[0][1], w.seed) for w in worlds]
    assert got == [(mu, af, s) for mu in ("mu0.3", "mu0.9") for af in (0.75, 0.85) for s in (0, 1)]
    assert len({w.key for w in worlds}) == 8
    assert [w.index for w in worlds] == list(range(8))


def test_area_fraction_and_speed_overrides_set_what_they_name():
    """area_fraction: block area over the lattice cell (shapely) equals the value asked for;
    the last row stays, the first row and the pusher move together; speed keeps direction."""
    scene = load_scenario(PILLAR)
    raw = dict(scene.raw)
    raw["field"] = [{**raw["field"][0], "jitter": 0.0}]
    from taichi_ice.scene.parse import scene_from_dict

    still = scene_from_dict(raw, source="still")
    new = apply_overrides(still, [("field.rubble.area_fraction", 0.7), ("body.pusher.speed", 0.25)])

    def y(s, name):
        return {b.name: b for b in s.bodies}[name].position[1]

    block = {b.name: b for b in new.bodies}["rubble_r0_c0"]
    area = shapely.Polygon(block.world_vertices()).area
    spacing_x = new.bodies[-1].position[0] - new.bodies[-2].position[0]  # neighbours in a row
    spacing_y = y(new, "rubble_r1_c0") - y(new, "rubble_r0_c0")
    assert area / (spacing_x * spacing_y) == pytest.approx(0.7, rel=1e-12)
    assert y(new, "rubble_r8_c0") == pytest.approx(y(still, "rubble_r8_c0"), abs=1e-12)
    shift = y(new, "rubble_r0_c0") - y(still, "rubble_r0_c0")
    pusher = {b.name: b for b in new.bodies}["pusher"]
    pusher0 = {b.name: b for b in still.bodies}["pusher"]
    assert pusher.position[1] - pusher0.position[1] == pytest.approx(shift, abs=1e-12)
    assert shift < -0.5  # a looser field reaches further back
    assert pusher.velocity == pytest.approx([0.0, 0.25])


# The sweep that is killed: in one process (no Dask), batches of 4.
KILLED = ["--workers", "0", "--batch-size", "4", "--quiet"]


def _equal(a, b, names):
    for name in names:
        x, y = a[name].values, b[name].values
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), (name, x, y)


def test_two_workers_equal_one_process_and_a_killed_sweep_resumes(sweep_dir, taichi_runtime):
    """The dataset of a sweep killed after its first batch and resumed on a 2-worker local
    cluster (batches of 4, then 2) equals the single-process run (batches of 7 and 1, the
    latter with its HDF5 run), value for value, and the resume runs only what was missing;
    the dataset opens in xarray with its coordinates, units and provenance."""
    from taichi_ice.experiments.sweep.dataset import open_sweep
    from taichi_ice.run.runfile_read import read_run

    if taichi_runtime != ("cpu", "f64"):
        pytest.skip("the worker processes run on the CPU in float64")
    sweep = load_sweep(sweep_dir / "sweep.toml")
    n = len(sweep.worlds())

    # Reference: this process, no Dask; world 0 alone (its run is written), the rest together.
    ref = run_sweep(
        dataclasses.replace(sweep, runs=frozenset({0})),
        sweep_dir / "ref",
        workers=0,
        progress=False,
    )
    assert ref.ran == list(range(n)) and not ref.failed_batches
    expected = open_sweep(ref.path)
    assert (expected.status.values == "complete").all()
    assert expected.peak_force.values.min() > 0  # the jams built: the test compares forces
    assert len(set(expected.batch.values)) == 2
    # Self-describing: coordinates, units, long names, the sweep file and versions.
    for coord in ("seed", "law", "law_name", "mu", "field.rubble.area_fraction"):
        assert coord in expected.coords
    assert expected.peak_force.attrs["units"] == "N"
    assert expected.friction_energy.attrs["units"] == "J"
    assert "long_name" in expected.concentration.attrs
    assert expected.attrs["sweep"] == sweep.text and expected.attrs["xarray_version"]
    files = sorted((sweep_dir / "ref" / "runs").iterdir())
    assert [f.name for f in files] == ["mu0.3_area_fraction0.75_seed-0000.h5"]
    run = read_run(files[0])
    assert run["series"]["friction_energy"][-1] == expected.friction_energy.values[0]

    # A sweep in another process, batches of 4, killed once its first batch is written.
    out = sweep_dir / "killed"
    proc = subprocess.Popen(
        [sys.executable, "-m", "taichi_ice", "sweep", "sweep.toml", "--out", str(out), *KILLED],
        cwd=sweep_dir,
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    deadline = time.monotonic() + 300
    while not list((out / "batches").glob("batch-*.json")):
        assert proc.poll() is None, proc.stderr.read().decode()
        assert time.monotonic() < deadline, "no batch finished in 300 s"
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done = {
        w["index"]
        for f in (out / "batches").glob("batch-*.json")
        for w in json.loads(f.read_text())["worlds"]
    }
    assert 0 < len(done) < n and not (out / "sweep.nc").exists()

    resumed = run_sweep(dataclasses.replace(sweep, batch_size=2), out, workers=2, progress=False)
    assert sorted(resumed.reused) == sorted(done)
    assert resumed.ran == sorted(set(range(n)) - done)
    got = open_sweep(out)
    _equal(got, expected, [*sweep.metrics, "steps", "dt", "seed", "mu", "status"])
    assert len(set(got.batch.values)) == len(done) // 4 + (n - len(done)) // 2

    # Run again: nothing is missing, nothing runs.
    again = run_sweep(sweep, out, workers=2, progress=False)
    assert again.ran == [] and len(again.reused) == n


def test_the_example_sweep_is_valid():
    """sweeps/pillar.toml (docs/sweeps.md's example): 7 laws x 2 area fractions x 8 layouts."""
    sweep = load_sweep("sweeps/pillar.toml")
    assert len(sweep.worlds()) == 112 and sweep.runs == {0}


def _fields(world) -> dict:
    """Every declared field of a World, as arrays (read in one launch: ``Transfer.read``,
    held to ``to_numpy`` by tests/test_transfer.py)."""
    return world.transfer.read()


def test_a_reloaded_world_steps_bit_for_bit_as_a_new_one():
    """A World that has run other worlds (a block sliding on the floor under rate-and-state
    friction: its contact holds xi and theta) and is reloaded with new ones holds, 300 steps
    later, exactly the fields of a World built for the new ones (positions, velocities,
    energies, contact memory, neighbour lists), even with the new blocks placed where the
    old contacts are, so that memory left behind would be found. Worlds of another layout
    are refused, naming what differs."""
    from taichi_ice.engine.world import World
    from taichi_ice.errors import UsageError
    from taichi_ice.physics.friction_parse import law_from_table

    scene = load_scenario("sliding_block")

    def worlds(*laws):
        return [scene.with_friction(law_from_table({"law": law, **extra})) for law, extra in laws]

    first = worlds(("rate-state", {}), ("memory-only", {}))
    second = worlds(("rate-state", {"below_v_star": "healing"}), ("steady-state", {}))
    reused = World(first)
    reused.advance(301)
    reused.check()
    assert reused.contact_counts().tolist() == [1, 1]  # sliding: memory to forget
    on_the_floor = reused.positions(), reused.angles()

    # Nine worlds take a capacity of 16, past the floor of 8 (assemble.capacity): another
    # layout.
    with pytest.raises(UsageError, match="n_worlds 8 here, 16 for the scenes"):
        reused.reload([*second * 4, *first[:1]])
    reused.reload(second)
    assert reused.steps == 0 and reused.time == 0.0
    fresh = World(second)
    for world in (reused, fresh):
        world.place(*on_the_floor)
        world.advance(300)
        world.check()
    got, expected = _fields(reused), _fields(fresh)
    assert got.keys() == expected.keys()
    for name in expected:
        assert np.array_equal(got[name], expected[name]), name
    assert np.array_equal(reused.energies(), fresh.energies())
    theta = got["contact_theta"][got["contact_partner"] >= 0]
    assert theta.size and np.all(theta != 0.0)  # rate-and-state memory was compared


def test_the_batches_of_a_layout_share_one_world_in_a_process(sweep_dir, monkeypatch):
    """A sweep run in one process builds one World (one compilation of the kernels) for
    all its batches of one layout: batches of 3, 3 and 2 (padded to 3) build one World and
    reload it twice; the same sweep in batches of 4, within the capacity of that World (8
    worlds, 256 bodies: ``assemble.capacity``), reloads it twice more and gives the same
    dataset, value for value."""
    from taichi_ice.engine import pool as pool_module
    from taichi_ice.engine.world import World
    from taichi_ice.experiments.sweep.dataset import open_sweep

    pool = pool_module.WorldPool()
    monkeypatch.setattr(pool_module, "POOL", pool)
    built = []
    build = World.__init__

    def counted(self, *args, **kwargs):
        built.append(len(args[0]))
        build(self, *args, **kwargs)

    monkeypatch.setattr(World, "__init__", counted)
    sweep = load_sweep(sweep_dir / "sweep.toml")
    n = len(sweep.worlds())

    by3 = run_sweep(
        dataclasses.replace(sweep, batch_size=3), sweep_dir / "by3", workers=0, progress=False
    )
    assert by3.ran == list(range(n)) and not by3.failed_batches
    got = open_sweep(by3.path)
    assert len(set(got.batch.values)) == 3
    assert built == [3] and (pool.built, pool.reloaded) == (1, 2)

    by4 = run_sweep(
        dataclasses.replace(sweep, batch_size=4), sweep_dir / "by4", workers=0, progress=False
    )
    assert by4.ran == list(range(n)) and not by4.failed_batches
    assert built == [3] and (pool.built, pool.reloaded) == (1, 4)
    expected = open_sweep(by4.path)
    assert (expected.status.values == "complete").all()
    _equal(got, expected, [*sweep.metrics, "steps", "dt", "seed", "mu", "status"])


def test_a_damaged_batch_file_is_set_aside_and_its_worlds_run_again(sweep_dir, capsys):
    """A truncated batch file and a garbled log (damage from outside: both are written whole
    or not at all) used to stop the sweep with a JSONDecodeError naming no file. Now the
    batch file is moved aside with a line naming it, only its worlds run again, and the
    dataset equals the undamaged one, value for value; a garbled settings file is one
    SweepError naming it."""
    from taichi_ice.experiments.sweep.dataset import open_sweep

    sweep = dataclasses.replace(load_sweep(sweep_dir / "sweep.toml"), batch_size=4)
    out = sweep_dir / "out"
    first = run_sweep(sweep, out, workers=0, progress=False)
    expected = open_sweep(first.path)
    batches = sorted((out / "batches").glob("batch-*.json"))
    assert len(batches) == 2
    damaged = batches[0]
    damaged.write_text(damaged.read_text()[:40])  # truncated
    (out / "sweep-log.json").write_bytes(b"\xff\xfe not json")
    capsys.readouterr()
    again = run_sweep(sweep, out, workers=0, progress=False)
    err = capsys.readouterr().err
    assert str(damaged) in err and "run again" in err
    assert len(again.ran) == 4 and not again.failed_batches
    assert damaged.with_name(damaged.name + ".damaged").exists()
    _equal(open_sweep(again.path), expected, [*sweep.metrics, "steps", "dt", "seed", "mu"])

    # Damage that still parses: one value changed (as a flipped bit in a digit would), the
    # digest left as written. It used to be read as a result; now it is set aside and rerun.
    other = batches[1]
    data = json.loads(other.read_text())
    assert "digest" in data
    data["wall_time"] = data["wall_time"] + 1.0
    other.write_text(json.dumps(data))
    capsys.readouterr()
    third = run_sweep(sweep, out, workers=0, progress=False)
    assert str(other) in capsys.readouterr().err
    assert len(third.ran) == 4 and not third.failed_batches
    _equal(open_sweep(third.path), expected, [*sweep.metrics, "steps", "dt", "seed", "mu"])

    (out / "sweep-state.json").write_text("{")
    with pytest.raises(SweepError, match=r"sweep-state\.json: damaged"):
        run_sweep(sweep, out, workers=0, progress=False)


def test_a_second_sweep_on_a_folder_in_use_is_refused_and_a_stale_lock_is_taken_over(
    sweep_dir,
):
    """Two sweeps on one --out both ran the missing worlds and raced on the dataset; now the
    folder is locked by the sweep running in it (``out/sweep.lock``: pid, host, command),
    a second is one SweepError naming the first, and the lock of a process that is gone is
    taken over."""
    import json as _json
    import socket
    import subprocess
    import sys

    sweep = load_sweep(sweep_dir / "sweep.toml")
    out = sweep_dir / "out"
    out.mkdir()
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock = {"pid": holder.pid, "host": socket.gethostname(), "since": "now"}
        (out / "sweep.lock").write_text(_json.dumps(lock))
        with pytest.raises(SweepError, match=f"another sweep is running.*pid {holder.pid}"):
            run_sweep(sweep, out, workers=0, progress=False)
    finally:
        holder.kill()
        holder.wait()
    result = run_sweep(sweep, out, workers=0, progress=False)  # its holder is gone now
    assert not result.failed_batches
    assert not (out / "sweep.lock").exists()


def test_a_short_batch_is_padded_only_to_the_capacity_of_the_largest(tmp_path):
    """Kernels compile for capacities: a batch shorter than the largest of its kind runs as
    it is where its layout is the largest's (5 pillar worlds of 67 bodies in 3 + 2: both
    take 8 worlds and 256 bodies), and else is padded to the fewest worlds that have that
    layout (8 worlds in 7 + 1: the 1, 256 bodies, to 4, past 256, fewer than 7)."""
    from taichi_ice.engine.assemble import assemble
    from taichi_ice.engine.options import Options
    from taichi_ice.experiments.sweep.plan import contact_slots, plan_batches
    from taichi_ice.experiments.sweep.spec import world_scene

    (tmp_path / "pillar.toml").write_text(open(PILLAR).read())
    (tmp_path / "sweep.toml").write_text(SWEEP.replace('"small.toml"', '"pillar.toml"'))
    sweep = load_sweep(tmp_path / "sweep.toml")
    worlds = sweep.worlds()
    slots = contact_slots(sweep)

    def layout(case, n):
        scene = world_scene(sweep.scene, case.overrides, case.seed, case.law)
        return assemble([scene] * n, Options(slots=slots, force_dt=True)).layout

    by3 = plan_batches(dataclasses.replace(sweep, batch_size=3), worlds[:5], workers=1)
    assert [(len(b.worlds), b.pad) for b in by3] == [(3, 0), (2, 0)]
    assert layout(worlds[4], 2) == layout(worlds[0], 3)
    by7 = plan_batches(dataclasses.replace(sweep, batch_size=7), worlds, workers=1)
    assert [len(b.worlds) for b in by7] == [7, 1]
    last, pad = by7[1].worlds[-1], by7[1].pad
    assert 0 < pad < 6
    assert layout(last, 1 + pad) == layout(last, 7) != layout(last, pad)


MIXED = """
[sweep]
scene = "small.toml"
seeds = { start = 0, count = 4 }
until = 0.4

[[law]]
law = "coulomb"
mu = 0.9

[[law]]
law = "rate-state"
"""


def test_each_model_is_split_over_the_workers_and_the_longest_batches_go_first(tmp_path):
    """With two workers each model's worlds are cut in two batches, and the batches come
    longest first: rate and state's, at a quarter of Coulomb's step (``dt_safety``), before
    Coulomb's, so no worker is left running a long batch alone at the end."""
    from taichi_ice.experiments.sweep.plan import batch_seconds, plan_batches

    (tmp_path / "small.toml").write_text(SMALL)
    (tmp_path / "sweep.toml").write_text(MIXED)
    sweep = load_sweep(tmp_path / "sweep.toml")
    base = sweep.scene
    coulomb_dt, memory_dt = (base.with_friction(law).dt for law in (Coulomb(0.9), RateState()))
    assert memory_dt < coulomb_dt  # the premise: a law with memory steps smaller
    batches = plan_batches(sweep, sweep.worlds(), workers=2)
    laws = [b.worlds[0].law["law"] for b in batches]
    assert laws == ["rate-state", "rate-state", "coulomb", "coulomb"]
    assert [len(b.worlds) for b in batches] == [2, 2, 2, 2]
    seconds = [batch_seconds(sweep, b) for b in batches]
    assert seconds[0] / seconds[-1] == pytest.approx(
        math.ceil(0.4 / memory_dt) / math.ceil(0.4 / coulomb_dt)
    )


def test_a_sweep_on_a_scheduler_plans_for_the_workers_it_has(sweep_dir, monkeypatch):
    """On a running Dask cluster (``--scheduler``, and the study's arms) the batches are
    planned for its workers, as on the embedded cluster: two workers, two batches. (Planned
    for one, a study's arm ran one batch per model, and on two workers took twice its
    longest model's batch.)"""
    from dask.distributed import LocalCluster

    from taichi_ice.experiments.sweep import run as run_module

    planned = []

    def recorded(specs, *_):
        planned.extend(specs)
        return iter(())  # nothing runs: the plan is what is checked

    monkeypatch.setattr(run_module, "_execute", recorded)
    sweep = load_sweep(sweep_dir / "sweep.toml")
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0"
    ) as cluster:
        run_sweep(sweep, sweep_dir / "out", scheduler=cluster.scheduler_address, progress=False)
    # Every world of this sweep can share one World: one batch on one worker, two on two.
    assert [len(spec["worlds"]) for spec in planned] == [4, 4]


def test_the_time_left_is_counted_by_the_batches_cost_not_their_worlds(monkeypatch, capsys):
    """A sweep's progress lines: the first estimates the wall time from the plan (its longest
    batch, where that is longer than its share of the work); after a batch estimated at three
    times the other's cost, finished in 30 s, 10 s are left (counted by worlds, 2 of 4 done,
    it would say 30 s)."""
    from taichi_ice.experiments.sweep import run as run_module

    clock = iter([100.0, 130.0, 140.0])  # the reporter made, each batch done
    monkeypatch.setattr(run_module.time, "perf_counter", lambda: next(clock))
    say = run_module._Reporter(True, {"long": 3.0, "short": 1.0}, 4, 0)
    say.start("2 Dask workers", 2)  # 4 s of work on two workers, its longest batch 3 s
    assert "in 2 batches on 2 Dask workers; about 3 s at 1.2 M body-steps/s" in (
        capsys.readouterr().err
    )
    result = {"worlds": [{"status": "complete"}] * 2, "world_steps": 1, "wall_time": 30.0}
    law = {"law": "rate-state"}
    say.done({"id": "long", "worlds": [{"law": law}] * 2}, {**result, "worker": "w"})
    assert capsys.readouterr().err.rstrip().endswith("2/4 worlds, ~10 s left")
    say.done({"id": "short", "worlds": [{"law": law}] * 2}, {**result, "worker": "w"})
    assert capsys.readouterr().err.rstrip().endswith("4/4 worlds, ~0 s left")
    assert [run_module._duration(s) for s in (40, 720, 12600)] == ["40 s", "12 min", "3.5 h"]
