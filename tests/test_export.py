"""``taichi-ice export RUN --vtk DIR``: the floes of every frame as VTK PolyData for ParaView.

The files are read back here with two independent readers: our own (xml.etree, base64 and
NumPy, no VTK code of the package) and VTK's own vtkXMLPolyDataReader (the reader ParaView
uses; the ``vtk`` package, test-only), and each polygon is held against shapely's polygon of
the body's stored outline, turned to the frame's angle and moved to its centroid
(shapely.affinity). meshio reads no PolyData (.vtp), and VTK has no reader of ``.pvd``
collections (ParaView's own): the collection is read with xml.etree and each file it names
with VTK. The run file is written with the package's RunWriter from a landed scene and
made-up frames, so no Taichi is needed.
"""

from __future__ import annotations

import base64
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import shapely
from shapely import affinity

from taichi_ice.commands.cli import main
from taichi_ice.errors import OutputError
from taichi_ice.run.export import export_vtk
from taichi_ice.run.runfile import RunWriter
from taichi_ice.run.runfile_read import read_run
from taichi_ice.scene.parse import load_scenario

ROOT = Path(__file__).resolve().parents[1]
PILLAR = ROOT / "scenarios" / "pillar.toml"
N_FRAMES = 4
KIND_CODES = {"dynamic": 0, "fixed": 1, "kinematic": 2}


@pytest.fixture(scope="module")
def run_file(tmp_path_factory) -> Path:
    """A run file of the pillar scene (diamonds, walls, a pusher) with frames at random
    positions, angles and velocities."""
    scene = load_scenario(PILLAR)
    path = tmp_path_factory.mktemp("run") / "pillar.h5"
    writer = RunWriter(path, scene, {"dt": 1e-4, "arch": "cpu"})
    rng = np.random.default_rng(5)
    n = scene.n_bodies
    for f in range(N_FRAMES):
        writer.add_frame(
            0.1 * f,
            scene.positions + rng.normal(0.0, 0.3, (n, 2)),
            scene.angles + rng.uniform(-np.pi, np.pi, n),
            rng.normal(0.0, 1.0, (n, 2)),
            rng.normal(0.0, 1.0, n),
        )
    writer.close("complete")
    return path


def read_array(element: ET.Element) -> np.ndarray:
    """A VTK XML DataArray, inline ascii or binary (base64 of a UInt64 byte count and the
    little-endian values), shaped (tuples, components)."""
    dtype = {"Float64": "<f8", "Int64": "<i8", "Int32": "<i4"}[element.get("type")]
    components = int(element.get("NumberOfComponents", "1"))
    if element.get("format") == "binary":
        raw = base64.b64decode(element.text.strip())
        size = int(np.frombuffer(raw[:8], "<u8")[0])
        values = np.frombuffer(raw[8 : 8 + size], dtype)
        assert len(raw) == 8 + size
    else:
        assert element.get("format") == "ascii"
        values = np.array(element.text.split(), dtype=dtype)
    return values.reshape(-1, components)


def read_vtp(path: Path) -> dict:
    root = ET.parse(path).getroot()
    assert root.get("type") == "PolyData" and root.get("header_type") == "UInt64"
    piece = root.find("PolyData/Piece")
    out = {
        "n_points": int(piece.get("NumberOfPoints")),
        "n_polys": int(piece.get("NumberOfPolys")),
        "points": read_array(piece.find("Points/DataArray")),
        "time": float(read_array(root.find("PolyData/FieldData/DataArray"))[0, 0]),
    }
    # VTK reads a field array without its NumberOfTuples as empty.
    assert root.find("PolyData/FieldData/DataArray").get("NumberOfTuples") == "1"
    for a in piece.find("Polys"):
        out[a.get("Name")] = read_array(a).ravel()
    out["cells"] = {a.get("Name"): read_array(a) for a in piece.find("CellData")}
    return out


def expected_polygons(run: dict, frame: int) -> list[shapely.Polygon]:
    """shapely's floes: each stored outline turned about its centroid, then moved there."""
    b, fr = run["bodies"], run["frames"]
    off = b["vertex_offsets"]
    polys = []
    for i in range(len(off) - 1):
        p = shapely.Polygon(b["vertices"][off[i] : off[i + 1]])
        p = affinity.rotate(p, fr["angle"][frame, i], origin=(0.0, 0.0), use_radians=True)
        polys.append(affinity.translate(p, *fr["position"][frame, i]))
    return polys


@pytest.mark.parametrize("binary", [True, False], ids=["binary", "ascii"])
def test_every_frame_is_the_floes_as_polygons_with_their_motion(run_file, tmp_path, binary):
    pvd = export_vtk(run_file, tmp_path / "vtk", binary=binary)
    run = read_run(run_file)
    times = run["frames"]["time"]
    kinds = [KIND_CODES[k] for k in run["bodies"]["kinds"]]
    counts = np.diff(run["bodies"]["vertex_offsets"])

    collection = ET.parse(pvd).getroot()
    assert collection.get("type") == "Collection"
    sets = collection.findall("Collection/DataSet")
    np.testing.assert_array_equal([float(s.get("timestep")) for s in sets], times)
    assert len(sets) == N_FRAMES
    for f, entry in enumerate(sets):
        vtp = read_vtp(pvd.parent / entry.get("file"))
        assert vtp["time"] == times[f]
        n = len(counts)
        assert vtp["n_polys"] == n and vtp["n_points"] == counts.sum()
        np.testing.assert_array_equal(np.diff(np.r_[0, vtp["offsets"]]), counts)
        assert np.all(vtp["points"][:, 2] == 0.0)
        xy = vtp["points"][:, :2]
        starts = np.r_[0, vtp["offsets"][:-1]]
        for want, start, end in zip(expected_polygons(run, f), starts, vtp["offsets"]):
            got = shapely.Polygon(xy[vtp["connectivity"][start:end]])
            assert got.is_valid and got.exterior.is_ccw
            assert got.area == pytest.approx(want.area, rel=1e-12)
            assert got.symmetric_difference(want).area < 1e-9 * want.area
        cells = vtp["cells"]
        np.testing.assert_array_equal(cells["velocity"][:, :2], run["frames"]["velocity"][f])
        assert np.all(cells["velocity"][:, 2] == 0.0)
        np.testing.assert_array_equal(cells["angular_velocity"][:, 0], run["frames"]["omega"][f])
        np.testing.assert_array_equal(cells["body"][:, 0], np.arange(n))
        np.testing.assert_array_equal(cells["kind"][:, 0], kinds)


def read_with_vtk(path: Path):
    """``path`` read by VTK's vtkXMLPolyDataReader: the vtkPolyData, and whatever VTK wrote
    to its output window (errors and warnings) while reading."""
    from vtkmodules.vtkCommonCore import vtkOutputWindow, vtkStringOutputWindow
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    before = vtkOutputWindow.GetInstance()
    window = vtkStringOutputWindow()
    vtkOutputWindow.SetInstance(window)
    try:
        reader = vtkXMLPolyDataReader()
        reader.SetFileName(str(path))
        reader.Update()
    finally:
        vtkOutputWindow.SetInstance(before)
    return reader.GetOutput(), window.GetOutput()


@pytest.mark.parametrize("binary", [True, False], ids=["binary", "ascii"])
def test_vtk_reads_every_frame_as_the_floes_with_their_motion_and_time(run_file, tmp_path, binary):
    pytest.importorskip("vtkmodules.vtkIOXML")
    from vtkmodules.util.numpy_support import vtk_to_numpy

    pvd = export_vtk(run_file, tmp_path / "vtk", binary=binary)
    run = read_run(run_file)
    frames, times = run["frames"], run["frames"]["time"]
    kinds = [KIND_CODES[k] for k in run["bodies"]["kinds"]]
    counts = np.diff(run["bodies"]["vertex_offsets"])
    n = len(counts)
    sets = ET.parse(pvd).getroot().findall("Collection/DataSet")
    assert len(sets) == N_FRAMES
    for f, entry in enumerate(sets):
        assert float(entry.get("timestep")) == times[f]
        data, errors = read_with_vtk(pvd.parent / entry.get("file"))
        assert errors == "", errors
        assert data.GetNumberOfPoints() == counts.sum()
        assert data.GetNumberOfCells() == data.GetNumberOfPolys() == n
        assert data.GetNumberOfVerts() == data.GetNumberOfLines() == data.GetNumberOfStrips() == 0
        points = vtk_to_numpy(data.GetPoints().GetData())
        assert points.shape == (counts.sum(), 3) and np.all(points[:, 2] == 0.0)
        for i, want in enumerate(expected_polygons(run, f)):
            ids = data.GetCell(i).GetPointIds()
            xy = points[[ids.GetId(k) for k in range(ids.GetNumberOfIds())], :2]
            assert len(xy) == counts[i]
            np.testing.assert_allclose(xy, np.asarray(want.exterior.coords)[:-1], atol=1e-12)
            assert shapely.Polygon(xy).exterior.is_ccw
        cells = data.GetCellData()
        names = {cells.GetArrayName(k) for k in range(cells.GetNumberOfArrays())}
        assert names == {"velocity", "angular_velocity", "body", "kind"}
        assert cells.GetVectors().GetName() == "velocity"
        assert cells.GetScalars().GetName() == "angular_velocity"
        velocity = vtk_to_numpy(cells.GetArray("velocity"))
        np.testing.assert_array_equal(velocity[:, :2], frames["velocity"][f])
        assert np.all(velocity[:, 2] == 0.0)
        got = {k: vtk_to_numpy(cells.GetArray(k)) for k in ("angular_velocity", "body", "kind")}
        np.testing.assert_array_equal(got["angular_velocity"], frames["omega"][f])
        np.testing.assert_array_equal(got["body"], np.arange(n))
        np.testing.assert_array_equal(got["kind"], kinds)
        assert data.GetPointData().GetNumberOfArrays() == 0
        # The frame's time as the field data ParaView reads (VTK reads a field array that
        # does not say its NumberOfTuples as empty).
        time = data.GetFieldData().GetArray("TimeValue")
        assert time is not None and time.GetNumberOfTuples() == 1
        assert vtk_to_numpy(time)[0] == times[f]


def test_the_command_writes_the_collection_and_never_clobbers_an_export(run_file, tmp_path, capsys):
    out = tmp_path / "vtk"
    assert main(["export", str(run_file), "--vtk", str(out), "--every", "2"]) == 0
    printed = capsys.readouterr().out
    assert str(out / "pillar.pvd") in printed
    files = sorted(p.name for p in out.iterdir())
    assert files == ["pillar.pvd", "pillar_000000.vtp", "pillar_000002.vtp"]
    before = (out / "pillar_000000.vtp").read_bytes()

    assert main(["export", str(run_file), "--vtk", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "exists" in err[0] and "--overwrite" in err[0]
    assert (out / "pillar_000000.vtp").read_bytes() == before
    with pytest.raises(OutputError, match="exists"):
        export_vtk(run_file, out)

    assert main(["export", str(run_file), "--vtk", str(out), "--overwrite"]) == 0
    assert len(list(out.glob("pillar_*.vtp"))) == N_FRAMES


@pytest.mark.parametrize("case", ["not a run", "folder is a file"])
def test_bad_input_is_one_line(run_file, tmp_path, capsys, case):
    if case == "not a run":
        bad = tmp_path / "x.h5"
        bad.write_text("not a run")
        args, expect = [str(bad), "--vtk", str(tmp_path / "v")], "not an HDF5 file"
    else:
        (tmp_path / "f").write_text("kept")
        args, expect = [str(run_file), "--vtk", str(tmp_path / "f")], "is a file"
    assert main(["export", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expect in err[0] and "Traceback" not in err[0]


def test_help_says_what_is_and_is_not_exported(capsys):
    with pytest.raises(SystemExit):
        main(["export", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "ParaView" in text and "per-contact" in text
