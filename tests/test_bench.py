"""taichi-ice bench: its outputs, its random box of diamonds, and the Box2D comparison."""

from __future__ import annotations

import argparse
import csv
import json
import math

import numpy as np
import pytest
import shapely
from shapely.geometry import Polygon

from taichi_ice.codes import BodyEnergy, BodyKind, EnergyTerm
from taichi_ice.commands import bench as cli_bench
from taichi_ice.commands.cli import main
from taichi_ice.experiments import bench
from taichi_ice.experiments.bench import box2d, report
from taichi_ice.experiments.bench.scenes import (
    BLOCK_LENGTH,
    BLOCK_WIDTH,
    RANDOM_AREA_FRACTION,
    bench_scene,
    random_box,
    random_scene,
)
from taichi_ice.physics import polygon

# Shapely's intersection areas of polygons that only touch are round-off (m^2).
TOUCH_AREA = 1e-12
# pyb2d3 hands back float32 values.
FLOAT32_RTOL = 1e-6

# The columns docs/performance.md and benchmarks/README.md document, which every CSV has.
DOCUMENTED = (
    "blocks",
    "precision",
    "area_fraction",
    "dt_s",
    "body_steps_per_s",
    "body_s_per_s",
    "contacts_per_block",
    "field_bytes_per_block",
    "rss_mb",
    "bandwidth_fraction",
    "box2d_body_steps_per_s",
    "box2d_body_s_per_s",
    "steps_ratio",
    "sim_time_ratio",
)


def polygons(box) -> list[Polygon]:
    outline = polygon.diamond(BLOCK_WIDTH, BLOCK_LENGTH)
    return [Polygon(polygon.transform(outline, p, a)) for p, a in zip(box.positions, box.angles)]


def test_cli_writes_csv_json_and_chart(tmp_path):
    """`taichi-ice bench` at a tiny size writes the three files with the documented columns."""
    out = tmp_path / "bench"
    argv = ["bench", "--sizes", "200", "--steps", "5", "--precision", "f64", "--no-box2d"]
    assert main([*argv, "--warm-cache", "--quick", "--out", str(out)]) == 0

    with open(out / "bench.csv", newline="") as fh:
        reader = csv.DictReader(fh)
        assert tuple(reader.fieldnames[: len(report.CSV_COLUMNS)]) == report.CSV_COLUMNS
        rows = list(reader)
    assert set(DOCUMENTED) <= set(report.CSV_COLUMNS)
    assert len(rows) == 1
    row = rows[0]
    assert (row["scene"], row["blocks"], row["bodies"], row["precision"]) == (
        "random",
        "200",
        "204",
        "f64",
    )
    assert float(row["area_fraction"]) == pytest.approx(RANDOM_AREA_FRACTION)
    for column in ("body_steps_per_s", "field_bytes_per_block", "rss_mb", "bandwidth_fraction"):
        assert float(row[column]) > 0, column
    # Throughput and simulated time per wall second are the same figure, a step apart.
    assert float(row["body_s_per_s"]) == pytest.approx(
        float(row["body_steps_per_s"]) * float(row["dt_s"]), rel=1e-4
    )
    assert row["box2d_body_steps_per_s"] == "" and row["steps_ratio"] == ""
    # The DEM at its law's default: Coulomb friction, the midstep step at 0.6 of the limit.
    assert row["integrator"] == "midstep"

    record = json.loads((out / "bench.json").read_text())
    assert record["scene"] == "random" and record["failed"] == []
    assert record["runs"][0]["blocks"] == 200
    assert record["runs"][0]["box"]["area_fraction"] == pytest.approx(RANDOM_AREA_FRACTION)
    assert (out / "bench.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    # Like Box2D, the timed runs keep no energy budget unless asked: with it, each body also
    # holds its budget columns, its last velocity change (three reals: the contacts book their
    # work at the mid-step velocity) and a real per contact slot (f64), for every row the
    # fields allocate (the layout's capacity: 256 rows for 204 bodies).
    # Counted by hand for the Euler step (the analytic steps book each contact's work again
    # once the bodies have moved, and keep what that needs).
    assert row["energy"] == "0"
    rows = {}
    for name, extra_args in (("plain", []), ("kept", ["--energy"])):
        folder = tmp_path / name
        more = [*extra_args, "--integrator", "euler", "--warm-cache", "--quick"]
        assert main([*argv, *more, "--out", str(folder)]) == 0
        with open(folder / "bench.csv", newline="") as fh:
            rows[name] = next(csv.DictReader(fh))
    row, kept_row = rows["plain"], rows["kept"]
    assert (row["energy"], kept_row["energy"], row["integrator"]) == ("0", "1", "euler")
    slots = record["runs"][0]["layout"]["slots"]
    rows_allocated = record["runs"][0]["layout"]["n_bodies"]
    assert rows_allocated >= int(row["bodies"])
    extra = float(kept_row["field_bytes_per_block"]) - float(row["field_bytes_per_block"])
    bodies_per_block = rows_allocated / int(row["blocks"])
    # The budget's columns but the forcing's (a scene without current or wind allocates
    # none of those: codes.BodyEnergy.WIND onwards).
    per_body = (int(BodyEnergy.WIND) + slots + 3) * 8
    # And each world's energy table (float64, a column per codes.EnergyTerm), for every world
    # the fields allocate (8 at least), where without the budget it is one unused element.
    worlds = record["runs"][0]["layout"]["n_worlds"]
    per_block_tables = (worlds * len(EnergyTerm) - 1) * 8 / int(row["blocks"])
    assert extra == pytest.approx(bodies_per_block * per_body + per_block_tables, rel=0.01)


def test_random_box_is_as_dense_as_asked_and_nothing_overlaps():
    """The random box covers 55 % of its interior, no two blocks overlap (shapely), none
    crosses a wall, most touch a neighbour, and the angles are uniform."""
    box = random_box(600, seed=3)
    polys = polygons(box)
    interior = Polygon([(0, 0), (box.width, 0), (box.width, box.height), (0, box.height)])
    covered = shapely.union_all(polys).area
    assert covered / interior.area == pytest.approx(RANDOM_AREA_FRACTION, rel=1e-9)
    assert all(interior.contains(p) for p in polys)

    tree = shapely.STRtree(polys)
    left, right = tree.query(polys, predicate="intersects")
    pairs = [(i, j) for i, j in zip(left.tolist(), right.tolist()) if i < j]
    overlaps = [polys[i].intersection(polys[j]).area for i, j in pairs]
    assert max(overlaps, default=0.0) < TOUCH_AREA

    # Gaps closed to about the placement clearance: most blocks start next to another.
    near_left, near_right = tree.query(polys, predicate="dwithin", distance=1e-3)
    touching = {i for i, j in zip(near_left.tolist(), near_right.tolist()) if i != j}
    assert len(touching) > 0.8 * len(polys)

    counts, _ = np.histogram(np.mod(box.angles, 2 * math.pi), bins=4, range=(0, 2 * math.pi))
    assert counts.min() > 0.8 * len(polys) / 4


def test_random_box_depends_only_on_its_seed():
    """The same seed gives the same box; another seed another."""
    a, b, c = random_box(100, seed=1), random_box(100, seed=1), random_box(100, seed=2)
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.angles, b.angles)
    assert np.array_equal(a.velocities, b.velocities)
    assert not np.array_equal(a.angles, c.angles)


def test_box2d_gets_the_same_scene_and_runs():
    """Box2D receives the same masses, positions, angles and velocities, and steps them."""
    pytest.importorskip("pyb2d3")
    scene, _ = random_scene(100, "coulomb", False, seed=0)
    world, batch, masses = box2d.build(scene, threads=2)
    dynamic = scene.kinds == int(BodyKind.DYNAMIC)
    np.testing.assert_allclose(masses, scene.masses[dynamic], rtol=FLOAT32_RTOL)
    np.testing.assert_allclose(
        np.array(batch.get_positions()), scene.positions[dynamic], rtol=FLOAT32_RTOL, atol=1e-5
    )
    np.testing.assert_allclose(
        np.array(batch.get_linear_velocities()), scene.velocities[dynamic], atol=1e-6
    )
    rotations = np.array(batch.get_rotations())  # (cos, sin) of each angle
    np.testing.assert_allclose(
        rotations, np.stack([np.cos(scene.angles), np.sin(scene.angles)], 1)[dynamic], atol=1e-6
    )
    del world

    result = box2d.run_box2d(scene, steps=5)
    assert result["box2d_threads"] == 2 and result["box2d_substeps"] == 4
    assert result["box2d_body_steps_per_s"] > 0
    assert result["box2d_body_s_per_s"] == pytest.approx(result["box2d_body_steps_per_s"] * 1e-3)
    # Six steps of 1 ms at up to 1.4 m/s: blocks move, by millimetres.
    moved = np.hypot(*(result["positions"] - scene.positions[dynamic]).T)
    assert np.isfinite(moved).all() and 0 < moved.max() < 0.02


def test_ratios_and_the_box2d_run_shared_by_both_precisions(tmp_path, monkeypatch, capsys):
    """Box2D runs once per size (with the first precision); each row gets both engines'
    figures and their ratios. Without pyb2d3 the bench says so in one line."""
    specs = []

    def worker(spec, args, cold_cache):
        specs.append(spec)
        if spec["task"] == "bandwidth":
            return {"numpy_copy_gb_s": 10.0, "taichi_copy_gb_s": 20.0}
        fast = spec["precision"] == "f32"
        row = {
            "blocks": spec["blocks"],
            "bodies": spec["blocks"] + 4,
            "precision": spec["precision"],
            "dt_s": 1e-4,
            "step_ms": 1.0 if fast else 2.0,
            "body_steps_per_s": 2e6 if fast else 1e6,
            "body_s_per_s": 200.0 if fast else 100.0,
            "bytes_per_step_mb": 1.0,
            "contacts_per_block": 0.3,
            "field_bytes_per_block": 1000.0,
            "rss_mb": 100.0,
        }
        if spec["box2d"]:
            row.update(box2d_body_steps_per_s=5e5, box2d_body_s_per_s=500.0, box2d_threads=2)
        details = {"traffic": {"bytes_per_kernel": {}}}
        return {"row": row, "details": details}

    monkeypatch.setattr(bench, "_worker", worker)
    monkeypatch.setattr(report, "plot", lambda rows, meta, path: path.write_bytes(b""))
    parser = argparse.ArgumentParser()
    cli_bench.add_options(parser)
    args = parser.parse_args(["--sizes", "1e3", "--out", str(tmp_path)])

    monkeypatch.setattr(box2d, "version", lambda: "0.11.1")
    assert bench.bench_command(args) == 0
    with_box2d = [s["box2d"] is not None for s in specs if s["task"] == "size"]
    assert with_box2d == [True, False]
    with open(tmp_path / "bench.csv", newline="") as fh:
        f64, f32 = csv.DictReader(fh)
    assert float(f64["steps_ratio"]) == pytest.approx(2.0)
    assert float(f32["steps_ratio"]) == pytest.approx(4.0)
    assert float(f32["sim_time_ratio"]) == pytest.approx(0.4)
    assert f32["box2d_threads"] == "2"
    # 1 MB a step at 20 GB/s against a 2 ms step.
    assert float(f64["bandwidth_fraction"]) == pytest.approx(2**20 / 20e9 / 2e-3)

    specs.clear()
    monkeypatch.setattr(box2d, "version", lambda: None)
    capsys.readouterr()
    assert bench.bench_command(args) == 0
    said = capsys.readouterr().err
    assert said.count("pyb2d3 is not installed") == 1
    assert all(s.get("box2d") is None for s in specs)


def test_a_size_the_scene_cannot_hold_is_refused(capsys):
    """Too few blocks for the random box end in one line naming the size, exit status 2."""
    assert main(["bench", "--sizes", "50", "--no-box2d"]) == 2
    said = capsys.readouterr().err
    assert "--sizes 50" in said and "at least 100 blocks" in said


def test_integrator_and_step_are_options(tmp_path, capsys):
    """`--integrator coupled --dt-safety 0.8` runs the DEM with that integrator at four
    times the default step: the row says so, and its simulated time per wall second is its
    throughput times that step. A step fraction outside (0, 1] is refused in one line."""
    out = tmp_path / "bench"
    argv = ["bench", "--sizes", "200", "--steps", "5", "--precision", "f64", "--no-box2d"]
    argv += ["--warm-cache", "--quick", "--out", str(out)]
    assert main([*argv, "--integrator", "coupled", "--dt-safety", "0.8"]) == 0
    with open(out / "bench.csv", newline="") as fh:
        row = next(csv.DictReader(fh))
    record = json.loads((out / "bench.json").read_text())
    layout = record["runs"][0]["layout"]
    assert row["integrator"] == "coupled" and layout["integrator"] == "coupled"
    scene, _ = bench_scene("random", 200, "coulomb", False, 0)
    # (the CSV keeps six digits)
    assert float(row["dt_s"]) == pytest.approx(0.8 * scene.stable_dt, rel=1e-5)
    assert float(row["body_s_per_s"]) == pytest.approx(
        float(row["body_steps_per_s"]) * float(row["dt_s"]), rel=1e-4
    )
    for bad in ("0", "1.5", "fast"):
        with pytest.raises(SystemExit) as stop:
            main(["bench", "--dt-safety", bad])
        assert stop.value.code == 2
        said = capsys.readouterr().err
        assert f"{bad!r}: give a fraction of the stability limit in (0, 1]" in said


def test_jam_step_steps_every_tree_from_the_first_trees_jam(tmp_path):
    """benchmarks/jam_step.py --same-state runs end to end: the first process saves its jam
    (at --at), the second loads it instead of running there, and both write their rows."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    cmd = [sys.executable, str(root / "benchmarks" / "jam_step.py"), "--out", str(tmp_path)]
    cmd += ["--trees", str(root), str(root), "--laws", "coulomb:0.9", "--rounds", "1"]
    cmd += ["--at", "0.05", "--steps", "50", "--windows", "2", "--until", "0.1", "--same-state"]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=root, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    record = json.loads((tmp_path / "jam_step.json").read_text())
    assert record["same_state"] and record["until"] == 0.1
    first, second = record["runs"]
    assert (first["jam_state"], second["jam_state"]) == ("saved", "loaded")
    assert first["run_steps"] == second["run_steps"] > 0
    assert first["run_hash"] == second["run_hash"]  # one engine
    assert first["jam_contacts"] == second["jam_contacts"]
    with np.load(tmp_path / "state-coulomb_0_9.npz") as saved:
        assert 0 < int(saved["_steps"]) < first["run_steps"]  # at 0.05 s of the run's 0.1
    assert (tmp_path / "jam_step.png").is_file()


def test_suite_compile_sums_the_compiles_by_file_and_finds_the_repeats():
    """``benchmarks/suite_compile.py``'s summary of its rows, by hand: one kernel of one
    layout compiled by both workers (2 s and 3 s: the cheaper, 2 s, was spent twice), another
    compiled twice in one worker (1 s, then 1.5 s again), one more once (0.5 s), and two of
    no layout (0.5 s each), which are not told apart."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "suite_compile.py"
    spec = importlib.util.spec_from_file_location("suite_compile", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)

    def row(worker, test, kernel, layout, front, launch):
        return {
            "worker": worker,
            "test": test,
            "kernel": kernel,
            "owner": "WorldStepper",
            "layout": layout,
            "front_s": front,
            "launch_s": launch,
        }

    rows = [
        row("gw0", "tests/test_a.py::t1", "run", "L1", 0.5, 1.5),
        row("gw1", "tests/test_b.py::t2", "run", "L1", 1.0, 2.0),
        row("gw0", "tests/test_a.py::t3", "run", "L2", 0.25, 0.75),
        row("gw0", "tests/test_c.py::t4", "run", "L2", 0.5, 1.0),
        row("gw1", "tests/test_b.py::t5", "advance", "L1", 0.125, 0.375),
        # No layout (Taichi's to_numpy of two fields, say): not told apart, never a repeat.
        row("gw0", "tests/test_c.py::t6", "tensor_to_ext_arr", "", 0.25, 0.25),
        row("gw0", "tests/test_c.py::t6", "tensor_to_ext_arr", "", 0.25, 0.25),
    ]
    got = module.summarise(rows)
    assert got["kernels"] == 7
    assert got["compile_s"] == pytest.approx(2.0 + 3.0 + 1.0 + 1.5 + 0.5 + 1.0)
    assert got["front_s"] == pytest.approx(0.5 + 1.0 + 0.25 + 0.5 + 0.125 + 0.5)
    assert got["by_file"] == pytest.approx(
        {"tests/test_b.py": 3.5, "tests/test_a.py": 3.0, "tests/test_c.py": 2.5}
    )
    assert list(got["by_file"]) == ["tests/test_b.py", "tests/test_a.py", "tests/test_c.py"]
    assert got["by_worker"] == pytest.approx({"gw0": 5.5, "gw1": 3.5})
    assert got["by_kernel"] == pytest.approx(
        {
            "WorldStepper.run": 7.5,
            "WorldStepper.tensor_to_ext_arr": 1.0,
            "WorldStepper.advance": 0.5,
        }
    )
    assert got["both_workers_s"] == pytest.approx(2.0)
    assert got["again_in_a_worker_s"] == pytest.approx(1.5)
