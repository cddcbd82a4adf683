"""Every contact at every frame (``run --contacts``, ``/contacts``) against the engine that
applied it, an independent clip, and independent readers.

A frame's rows are the contacts of the step that starts at the frame's time. They are held
against what the engine itself computes in that step: each body's net contact force and
torque as the contact kernel gathers them (``body_force_q``, ``body_torque_q``, read after
the contact stage of the step taken from the frame's state), the probe force of that step
(the run file's ``probe_force`` sampled every step: its sample one step after a frame is the
mean over that one step), and theta and the slip rate the step leaves in the contact slots.
The geometry (overlap area, contact point, width, normal) is held against shapely's clip of
the two floes at the frame; the stuck and sliding rows against Coulomb's cap; the files
against xarray, the netCDF C library and VTK's own reader. A run without ``--contacts`` has
no group and is otherwise the same file, variable for variable; a run killed and resumed
writes the rows of the run never stopped.

The scene: three 1 m squares pressed onto a floor (200 kN each), pushed along it at 0.2 m/s
against a wall by a kinematic pusher: contacts that stick (squares on squares) and slide (on
the floor), with rate-and-state interfaces under that law.
"""

from __future__ import annotations

import copy
import types
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest
import shapely
from jam_bodies import jam_bodies

from taichi_ice import Simulation, load_scenario
from taichi_ice.commands.cli import main
from taichi_ice.engine.schema import FORCE_QUANTUM
from taichi_ice.errors import RunFileError
from taichi_ice.physics.slip import NO_INTERFACE_ABOVE
from taichi_ice.run import checkpoint as ckpt
from taichi_ice.run.export import export_vtk
from taichi_ice.run.plots import positions_figure
from taichi_ice.run.runfile import VARIABLES, RunWriter
from taichi_ice.run.runfile_read import open_run, read_run
from taichi_ice.scene.parse import scene_from_dict
from taichi_ice.tomlio import dump_toml

UNTIL = 0.1  # s
DT = 1e-4  # s, below the scene's stability limit (1.8e-4 s at its safety factor)
OUTPUT_INTERVAL = 0.01  # s: 100 steps a frame
MU = 0.5  # the Coulomb runs' friction coefficient
ROWS = {
    "body_a",
    "body_b",
    "point",
    "normal",
    "width",
    "overlap",
    "force_normal",
    "force_tangential",
    "slip_rate",
    "theta",
    "mu",
    "stuck",
}
CONTACTS = ROWS | {"time", "row_size", "contact"}
# The twin does the kernel's float64 operations in the same order; what differs is the
# kernel's gather: each contact's force truncated to a whole 2^-24 N (schema.FORCE_QUANTUM)
# per component before it is summed. A body's sum is off by at most one quantum a contact.
FORCE_RTOL = 1e-12
# Equal operations: the theta and slip rate the kernel leaves equal the twin's to round-off.
STATE_RTOL = 1e-12
# shapely clips with other operations in another order (GEOS): its overlap of a 0.1-1 mm deep
# contact of 1 m squares differs by round-off of the 1 m coordinates.
AREA_RTOL = 1e-9
POINT_ATOL = 1e-12  # m
# The probe force is the impulse of the step (the fixed-point force times dt, summed in
# float64) over dt: round-off of that product and quotient.
PROBE_RTOL = 1e-12


def jam_dict(law: str, push: float = 0.2) -> dict:
    """Three squares pressed onto a floor, pushed at ``push`` m/s against a wall (module
    doc)."""
    raw = copy.deepcopy(dict(load_scenario("scenarios/two_squares.toml").raw))
    raw["simulation"].update(
        duration=UNTIL, dt=DT, output_interval=OUTPUT_INTERVAL, series_interval=DT
    )
    raw["friction"] = {"law": law, **({"mu": MU} if law == "coulomb" else {})}
    raw["body"] = jam_bodies(push=push, tilt=0.001, probe_pusher=True)
    return raw


def jam(law: str, push: float = 0.2):
    return scene_from_dict(jam_dict(law, push), source=f"jam {law}")


@pytest.fixture(scope="module")
def f64(taichi_runtime: tuple[str, str]) -> None:
    """Skip comparisons with the engine that only a float64 run meets (the rows are
    computed in float64; a float32 kernel's forces differ by its round-off)."""
    if taichi_runtime[1] != "f64":
        pytest.skip("needs float64 (tolerances near round-off)")


def forces_on_bodies(rows: dict, position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(N, 2)`` net force (N) and ``(N,)`` torque (N m) on each body from a frame's rows:
    the row's force on ``body_b``, its opposite on ``body_a``, at the contact point."""
    normal = rows["normal"]
    tangent = np.stack([-normal[:, 1], normal[:, 0]], axis=1)
    f = rows["force_normal"][:, None] * normal + rows["force_tangential"][:, None] * tangent
    force, torque = np.zeros_like(position), np.zeros(len(position))
    for sign, body in ((1.0, rows["body_b"]), (-1.0, rows["body_a"])):
        r = rows["point"] - position[body]
        np.add.at(force, body, sign * f)
        np.add.at(torque, body, sign * (r[:, 0] * f[:, 1] - r[:, 1] * f[:, 0]))
    return force, torque


def pose(run: dict, frame: int) -> tuple[np.ndarray, np.ndarray]:
    """``(position, angle)`` of the bodies at the pose the step from ``frame`` takes its
    contacts at: the frame's, or with the midstep step each body in free flight for dt / 2
    from it (the run file's ``integrator`` and ``dt``)."""
    frames = run["frames"]
    position, angle = frames["position"][frame], frames["angle"][frame]
    if run["attrs"]["integrator"] == "midstep":
        half = 0.5 * float(run["attrs"]["dt"])
        position = position + half * frames["velocity"][frame]
        angle = angle + half * frames["omega"][frame]
    return position, angle


def frame_rows(run: dict, frame: int) -> dict:
    """Frame ``frame``'s rows, cut by the ragged array's counts (CF H.2.4)."""
    c = run["contacts"]
    start = int(np.sum(c["row_size"][:frame]))
    rows = slice(start, start + int(c["row_size"][frame]))
    return {name: c[name][rows] for name in ROWS}


# Each law at its default integrator (Coulomb: midstep; rate and state: Euler), and Coulomb
# with the Euler step.
RUNS = {"coulomb": ("coulomb", None), "rate-state": ("rate-state", None)}
RUNS["coulomb-euler"] = ("coulomb", "euler")


@pytest.fixture(scope="module", params=list(RUNS))
def ran(request, tmp_path_factory):
    """A run with contacts, and after it the engine's step from its last frame, split at its
    stages: what the contact kernel gathered on each body, then the probes' impulses and
    the contact slots the whole step left. Of the Simulation it keeps what the tests read
    (its dt, series_every and options), not the Simulation: its World goes back to the
    pool for the tests' own runs of this layout, which compile nothing then."""
    law, integrator = RUNS[request.param]
    path = tmp_path_factory.mktemp("contacts") / f"{request.param}.h5"
    sim = Simulation(jam(law), contacts=True, integrator=integrator)
    sim.run(out=path)
    world = sim.world
    n = world.batch.n_bodies
    world.refresh_lists()
    world.contacts.compute()
    engine = {
        "force": world.data.body_force_q.to_numpy()[:n] * FORCE_QUANTUM,
        "torque": world.data.body_torque_q.to_numpy()[:n] * FORCE_QUANTUM,
    }
    world.integrator.advance()
    engine["impulse"] = world.data.probe_impulse.to_numpy()[: world.batch.n_probes]
    d = world.data
    counts, partners = d.contact_count.to_numpy(), d.contact_partner.to_numpy()
    theta = d.contact_theta.to_numpy() if world.layout.rate_state else None
    slip = d.contact_slip.to_numpy() if world.layout.rate_state else None
    engine["slots"] = {
        (i, int(partners[i, s])): {}
        if theta is None
        else {"theta": float(theta[i, s]), "slip": float(slip[i, s])}
        for i in range(n)
        for s in range(counts[i])
    }
    kept = types.SimpleNamespace(dt=sim.dt, series_every=sim.series_every, options=sim.options)
    del sim, world, d
    return law, kept, path, read_run(path), engine


def test_rows_are_the_forces_the_engine_applies_in_the_step_from_the_frame(ran, f64):
    """Summed over each body, the last frame's rows are the body's net contact force and
    torque that the contact kernel gathers in the step from that frame; over the probes,
    the probe impulse of the step over dt; each pair is one contact slot of the engine,
    once, and under rate-and-state its theta and slip rate are what the step leaves there."""
    law, sim, _path, run, engine = ran
    last = len(run["frames"]["time"]) - 1
    rows = frame_rows(run, last)
    position, _ = pose(run, last)
    force, torque = forces_on_bodies(rows, position)
    n_rows = len(rows["body_a"])
    assert n_rows >= 5  # the floor, the wall, the pusher and the squares between them
    touches = np.bincount(np.r_[rows["body_a"], rows["body_b"]], minlength=len(position))
    bound = (touches[:, None] + 1) * FORCE_QUANTUM + FORCE_RTOL * np.abs(force).max()
    assert np.all(np.abs(force - engine["force"]) <= bound), force - engine["force"]
    np.testing.assert_array_less(
        np.abs(torque - engine["torque"]), (touches + 1) * FORCE_QUANTUM * 2.0
    )
    # Each pair once, as the one slot of the body that owns it: Newton's third law is the
    # row's force on body_b and its opposite on body_a, both matched above.
    pairs = list(zip(rows["body_a"].tolist(), rows["body_b"].tolist()))
    assert len({frozenset(p) for p in pairs}) == n_rows
    assert set(pairs) == set(engine["slots"])
    probes = run["bodies"]["probe_index"]
    np.testing.assert_allclose(
        engine["impulse"] / sim.dt, force[probes], rtol=PROBE_RTOL, atol=n_rows * FORCE_QUANTUM
    )
    if law == "rate-state":
        sliding = 0
        for k, pair in enumerate(pairs):
            slot = engine["slots"][pair]
            theta = slot["theta"] if slot["theta"] < NO_INTERFACE_ABOVE else np.nan
            np.testing.assert_allclose(rows["theta"][k], theta, rtol=STATE_RTOL)
            np.testing.assert_allclose(rows["slip_rate"][k], slot["slip"], rtol=STATE_RTOL)
            sliding += np.isfinite(theta)
        assert sliding >= 1  # a square slides on the floor with an interface
    else:
        assert np.all(np.isnan(rows["theta"]))


def test_probe_force_of_the_step_after_each_frame_is_the_sum_of_its_rows(ran, f64):
    """Sampled every step, the run file's probe force one step after a frame is the force of
    the step that starts at the frame: the sum of the frame's rows on each probe body."""
    _law, sim, _path, run, _engine = ran
    series, frames = run["series"], run["frames"]
    assert sim.series_every == 1 and np.isclose(series["time"][1], sim.dt, rtol=1e-12)
    probes = run["bodies"]["probe_index"]
    checked = 0
    for f, t in enumerate(frames["time"][:-1]):
        after = int(np.argmin(np.abs(series["time"] - (t + sim.dt))))
        assert series["time"][after] == pytest.approx(t + sim.dt, rel=1e-12)
        rows = frame_rows(run, f)
        force, _ = forces_on_bodies(rows, pose(run, f)[0])
        np.testing.assert_allclose(
            series["probe_force"][after],
            force[probes],
            rtol=PROBE_RTOL,
            atol=(len(rows["body_a"]) + 1) * FORCE_QUANTUM,
            err_msg=f"frame {f}",
        )
        checked += bool(np.any(force[probes] != 0.0))
    assert checked >= 5  # the floor carries the squares from the first frames on


def test_stuck_rows_are_below_the_cap_and_sliding_rows_at_it(ran):
    """A stuck contact's tangential force is below mu F_n (Coulomb: the scene's 0.5) and it
    does not slip; a sliding one's is mu F_n to round-off and it slips. Both occur. Under
    rate and state the slide takes sub-steps (``[ice] slide_resolution``): a row's force and
    mu are the step's means, at the cap where the contact slid through the step (a row
    whose slide started within the step would be below it: none is at this scene's frames,
    10 sliding rows of 10 at the cap; in one step,
    ``test_in_one_step_every_sliding_row_is_at_the_cap``)."""
    law, _sim, _path, run, _engine = ran
    c = run["contacts"]
    assert_rows_hold_the_cap(c)
    if law == "coulomb":
        np.testing.assert_array_equal(c["mu"], MU)
    if law == "rate-state":
        # theta where the law acts (a sliding interface), never positive (DESIGN: it starts
        # at -B ln(V/V*) <= 0 and relaxes toward it); none on a stuck contact.
        stuck, sliding = c["stuck"] == 1, c["stuck"] == 0
        assert np.all(np.isnan(c["theta"][stuck]))
        theta = c["theta"][sliding]
        assert np.isfinite(theta).sum() >= 3 and np.all(theta[np.isfinite(theta)] <= 0.0)


def assert_rows_hold_the_cap(c: dict) -> None:
    """Stuck rows below ``mu F_n`` and not slipping; sliding rows slipping against their
    force, at the cap to round-off."""
    cap = c["mu"] * c["force_normal"]
    stuck, sliding = c["stuck"] == 1, c["stuck"] == 0
    assert set(np.unique(c["stuck"])) == {0, 1}
    assert stuck.sum() >= 10 and sliding.sum() >= 5
    force = np.abs(c["force_tangential"])
    assert np.all(force[stuck] <= cap[stuck] * (1.0 + 1e-12))
    np.testing.assert_array_equal(c["slip_rate"][stuck], 0.0)
    at_cap = np.isclose(force[sliding], cap[sliding], rtol=1e-12, atol=0.0)
    print(f"{at_cap.sum()} of {sliding.sum()} sliding rows at the cap, {stuck.sum()} stuck")
    assert np.all(at_cap), (at_cap.sum(), sliding.sum())
    assert np.all(c["slip_rate"][sliding] != 0.0)
    # The slip is against the force: friction opposes the sliding.
    assert np.all(c["slip_rate"][sliding] * c["force_tangential"][sliding] < 0.0)


def test_in_one_step_every_sliding_row_is_at_the_cap(tmp_path):
    """Rate and state with its slide in one step (``slide_resolution = 0``): every sliding
    row's force is its mu F_n to round-off, as a Coulomb row's."""
    raw = jam_dict("rate-state")
    raw["ice"] = {**raw.get("ice", {}), "slide_resolution": 0.0}
    path = tmp_path / "one_step.h5"
    Simulation(scene_from_dict(raw, source="jam one step"), contacts=True).run(out=path)
    assert_rows_hold_the_cap(read_run(path)["contacts"])


def test_geometry_is_the_overlap_of_the_two_floes_at_the_frame(ran, f64):
    """Each row's overlap area and point are shapely's intersection of the two floes placed
    at the frame (its area and centroid; with the midstep step, placed at the pose it
    predicts for mid-step), its width the chord between the outlines' crossings, its normal
    a unit vector across that chord from body_a toward body_b."""
    _law, _sim, _path, run, _engine = ran
    b, frames = run["bodies"], run["frames"]
    off = b["vertex_offsets"]
    checked = 0
    for f in range(len(frames["time"])):
        rows = frame_rows(run, f)
        position, angle = pose(run, f)
        c, s = np.cos(angle), np.sin(angle)
        floes = []
        for i in range(len(off) - 1):
            v = b["vertices"][off[i] : off[i + 1]]
            turned = np.stack([c[i] * v[:, 0] - s[i] * v[:, 1], s[i] * v[:, 0] + c[i] * v[:, 1]])
            floes.append(shapely.Polygon(turned.T + position[i]))
        for k in range(len(rows["body_a"])):
            a, bb = floes[rows["body_a"][k]], floes[rows["body_b"][k]]
            both = a.intersection(bb)
            assert rows["overlap"][k] == pytest.approx(both.area, rel=AREA_RTOL)
            np.testing.assert_allclose(
                rows["point"][k], np.asarray(both.centroid.coords)[0], atol=POINT_ATOL
            )
            crossings = np.asarray(
                [p.coords[0] for p in a.exterior.intersection(bb.exterior).geoms]
            )
            assert len(crossings) == 2
            chord = crossings[1] - crossings[0]
            assert rows["width"][k] == pytest.approx(np.hypot(*chord), rel=1e-9)
            normal = rows["normal"][k]
            assert np.hypot(*normal) == pytest.approx(1.0, rel=1e-12)
            assert abs(normal @ chord) <= 1e-9 * np.hypot(*chord)
            centre_a = np.asarray(a.centroid.coords)[0]
            assert normal @ (np.asarray(bb.centroid.coords)[0] - centre_a) > 0.0
            checked += 1
    assert checked >= 30


def test_xarray_and_the_netcdf_library_read_the_group(ran):
    """``xr.open_dataset(path, group="contacts")`` with no options: the rows on ``contact``,
    counted per frame by ``row_size`` (a CF contiguous ragged array), every variable with
    units and a long name; ``open_run`` holds them beside the frames."""
    xr = pytest.importorskip("xarray")
    netCDF4 = pytest.importorskip("netCDF4")
    _law, _sim, path, run, _engine = ran
    with xr.open_dataset(path, group="contacts") as ds:
        assert set(ds.variables) == CONTACTS
        assert ds["row_size"].dims == ("time",)
        assert ds["row_size"].attrs["sample_dimension"] == "contact"
        assert int(ds["row_size"].sum()) == ds.sizes["contact"] == len(run["contacts"]["mu"])
        np.testing.assert_array_equal(ds["time"].values, run["frames"]["time"])
        assert ds["point"].dims == ("contact", "xy") and ds["mu"].dims == ("contact",)
        for name in ROWS:
            np.testing.assert_array_equal(ds[name].values, run["contacts"][name], err_msg=name)
    assert set(VARIABLES["contacts"]) == CONTACTS
    with netCDF4.Dataset(path) as nc:
        for name, var in nc.groups["contacts"].variables.items():
            assert var.long_name and var.units, name
        assert nc.groups["contacts"].variables["overlap"].units == "m2"
    ds = open_run(path)
    assert ds["force_normal"].dims == ("contact",)
    np.testing.assert_array_equal(ds["row_size"].values, run["contacts"]["row_size"])
    assert ds["row_size"].dims == ("frame_time",)


def test_a_run_without_contacts_is_the_same_file_without_the_group(ran, tmp_path):
    """The same scene run without ``contacts`` writes no ``/contacts`` and, variable for
    variable, the same file: asking for the rows changes nothing the run computes."""
    law, sim, path, _run, _engine = ran
    plain = tmp_path / "plain.h5"
    Simulation(jam(law), integrator=sim.options.integrator).run(out=plain)
    with h5py.File(path, "r") as f, h5py.File(plain, "r") as g:
        assert "contacts" in f and "contacts" not in g
        assert set(f) - {"contacts"} == set(g)
        compared = 0

        def same(name, obj):
            nonlocal compared
            if isinstance(obj, h5py.Dataset):
                np.testing.assert_array_equal(f[name][()], obj[()], err_msg=name)
                assert dict(f[name].attrs).keys() == dict(obj.attrs).keys(), name
                compared += 1

        g.visititems(same)
        assert compared >= 30
        own = {"run_id", "started", "finished", "wall_time", "command", "title", "source"}
        for key, value in g.attrs.items():
            if key not in own:
                np.testing.assert_array_equal(f.attrs[key], value, err_msg=key)


@pytest.mark.parametrize("binary", [True, False], ids=["binary", "ascii"])
def test_vtk_reads_the_force_chains_as_lines_with_the_rows(ran, tmp_path, binary):
    """``export`` writes each frame's contacts as lines (body_a's centroid, the contact
    point, body_b's centroid) that VTK's own reader opens with the rows as cell data."""
    pytest.importorskip("vtkmodules.vtkIOXML")
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkCommonCore import vtkOutputWindow, vtkStringOutputWindow
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    _law, _sim, path, run, _engine = ran
    pvd = export_vtk(path, tmp_path / "vtk", binary=binary)
    chains = pvd.with_name(f"{path.stem}_contacts.pvd")
    entries = ET.parse(chains).getroot().findall("Collection/DataSet")
    frames = run["frames"]
    assert len(entries) == len(frames["time"])
    window = vtkStringOutputWindow()
    before = vtkOutputWindow.GetInstance()
    vtkOutputWindow.SetInstance(window)
    try:
        for f, entry in enumerate(entries):
            assert float(entry.get("timestep")) == frames["time"][f]
            reader = vtkXMLPolyDataReader()
            reader.SetFileName(str(chains.parent / entry.get("file")))
            reader.Update()
            data = reader.GetOutput()
            rows = frame_rows(run, f)
            n = len(rows["body_a"])
            assert data.GetNumberOfLines() == data.GetNumberOfCells() == n
            assert data.GetNumberOfPolys() == 0
            if n == 0:
                continue
            points = vtk_to_numpy(data.GetPoints().GetData()).reshape(n, 3, 3)
            np.testing.assert_array_equal(points[:, 0, :2], frames["position"][f][rows["body_a"]])
            np.testing.assert_array_equal(points[:, 1, :2], rows["point"])
            np.testing.assert_array_equal(points[:, 2, :2], frames["position"][f][rows["body_b"]])
            cells = data.GetCellData()
            assert cells.GetScalars().GetName() == "force_normal"
            for name in ("force_normal", "force_tangential", "slip_rate", "theta", "mu"):
                got = vtk_to_numpy(cells.GetArray(name))
                np.testing.assert_array_equal(got, rows[name], err_msg=name)
            for name in ("stuck", "body_a", "body_b"):
                np.testing.assert_array_equal(vtk_to_numpy(cells.GetArray(name)), rows[name])
            force = vtk_to_numpy(cells.GetArray("force"))
            on_b, _ = forces_on_bodies({k: v[:1] for k, v in rows.items()}, frames["position"][f])
            np.testing.assert_allclose(force[0, :2], on_b[rows["body_b"][0]], rtol=1e-15)
    finally:
        vtkOutputWindow.SetInstance(before)
    assert window.GetOutput() == ""


def test_the_snapshots_draw_the_force_chains(ran):
    """``taichi-ice plot``'s snapshots draw a line per contact, widest where the normal
    force is largest."""
    from matplotlib.collections import LineCollection

    _law, _sim, _path, run, _engine = ran
    fig = positions_figure(run, snapshots=3)
    picks = [0, 5, 10]  # frames the three panels show
    for ax, f in zip(fig.axes, picks):
        lines = [c for c in ax.collections if isinstance(c, LineCollection)]
        rows = frame_rows(run, f)
        if not len(rows["body_a"]):
            assert not lines
            continue
        (chains,) = lines
        assert len(chains.get_segments()) == len(rows["body_a"])
        widths = chains.get_linewidths()
        assert np.argmax(widths) == np.argmax(rows["force_normal"])


def test_a_world_of_a_batch_writes_the_rows_it_writes_alone(ran, tmp_path):
    """Batched with another world (pushed faster), a world's file holds the rows of its run
    alone, bit for bit, its bodies numbered within it; the other world has rows of its own."""
    law, sim, _path, run, _engine = ran
    paths = [tmp_path / "a.h5", tmp_path / "b.h5"]
    batch = Simulation(
        [jam(law), jam(law, push=0.3)], contacts=True, integrator=sim.options.integrator
    )
    batch.run(out=paths)
    alone, batched, other = run["contacts"], read_run(paths[0]), read_run(paths[1])
    for name, values in alone.items():
        np.testing.assert_array_equal(batched["contacts"][name], values, err_msg=name)
    n = len(other["bodies"]["names"])
    c = other["contacts"]
    assert len(c["mu"]) > 0 and 0 <= c["body_a"].min() and c["body_b"].max() < n
    assert not np.array_equal(c["force_normal"][: len(alone["mu"])], alone["force_normal"])


def test_a_resumed_run_keeps_writing_the_rows_of_the_run_never_stopped(tmp_path, monkeypatch):
    """Killed after a checkpoint and resumed with contacts, the run file's ``/contacts`` is
    that of the run never stopped, bit for bit; resuming it without them is refused."""
    scene = jam("rate-state")
    whole = tmp_path / "whole.h5"
    Simulation(scene, contacts=True).run(out=whole)
    path = tmp_path / "killed.h5"
    flush = RunWriter.flush
    calls = {"n": 0}

    def flush_then_die(self, steps, **attrs):
        calls["n"] += 1
        if calls["n"] == 6:
            raise KeyboardInterrupt  # a kill between two checkpoints
        flush(self, steps, **attrs)

    monkeypatch.setattr(RunWriter, "flush", flush_then_die)
    with pytest.raises(KeyboardInterrupt):
        Simulation(scene, contacts=True).run(out=path, checkpoint_every=0)
    monkeypatch.setattr(RunWriter, "flush", flush)
    saved = ckpt.read(ckpt.path_for(path))
    killed = read_run(path)
    assert len(killed["contacts"]["row_size"]) > saved["attrs"]["n_frames"][0]
    with pytest.raises(RunFileError, match="with --contacts"):
        Simulation(scene).run(out=path, resume=True)
    Simulation(scene, contacts=True).run(out=path, resume=True)
    a, b = read_run(whole), read_run(path)
    assert b["attrs"]["resumed"] == 1
    assert set(a["contacts"]) == set(b["contacts"]) == CONTACTS
    for name, values in a["contacts"].items():
        np.testing.assert_array_equal(b["contacts"][name], values, err_msg=name)
    assert len(a["contacts"]["row_size"]) == len(a["frames"]["time"])


def test_the_command_line_writes_the_group_when_asked(tmp_path, capsys):
    """``taichi-ice run --contacts`` writes ``/contacts``; ``--help`` says what it holds."""
    scene_file = tmp_path / "jam.toml"
    scene_file.write_text(dump_toml(jam_dict("coulomb")))
    out = tmp_path / "jam.h5"
    assert main(["run", str(scene_file), "--out", str(out), "--contacts", "--quiet"]) == 0
    run = read_run(out)
    assert set(run["contacts"]) == CONTACTS
    assert len(run["contacts"]["row_size"]) == len(run["frames"]["time"])
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--contacts" in text and "/contacts" in text and "theta" in text
