"""The floes of a run file as CF-1.8 polygon geometries (CF conventions section 7.5,
"Geometries"), read back by independent readers into shapely polygons held against
shapely's own: each body's scene outline turned by its angle about its centroid and moved to
its position (shapely.affinity). The readers: cf_xarray, and GDAL's netCDF driver (ogr2ogr,
where GDAL's command-line tools are installed: GDAL reads geometries in the root group only,
so from a copy of /bodies at the root). A run file of format 2.0 (before the geometries) is
still read by every reader of the package.

The run files are written with the package's RunWriter from a scene and made-up frames, so no
Taichi kernel runs here.
"""

from __future__ import annotations

import copy
import json
import shutil
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pytest
import shapely
import xarray as xr
from shapely import affinity

from taichi_ice import open_run
from taichi_ice.run.export import export_vtk
from taichi_ice.run.runfile import RunWriter
from taichi_ice.run.runfile_read import read_run
from taichi_ice.scene.parse import load_scenario, scene_from_dict

ROOT = Path(__file__).resolve().parents[1]
# Coordinates are a few metres: turning and moving them rounds at 1e-15 m.
ATOL = 1e-12  # m
# The per-body variables that the geometry describes (CF: "geometry" attribute).
PER_BODY = ("names", "kinds", "mass", "inertia")
NEW = ("floe_outline", "floe_outline_node_count", "floe_outline_x", "floe_outline_y")


def turned_floes():
    """Bodies of every kind and shape, each at its own angle: a fixed rectangle, a kinematic
    diamond, a dynamic pentagon and a dynamic triangle, apart from one another."""
    raw = copy.deepcopy(dict(load_scenario(ROOT / "scenarios" / "two_squares.toml").raw))
    raw["body"] = [
        {"name": "wall", "kind": "fixed", "shape": "rectangle", "width": 0.5, "length": 6.0,
         "position": [-4.0, 1.0], "angle": 0.3},
        {"name": "pusher", "kind": "kinematic", "shape": "diamond", "width": 0.8, "length": 1.4,
         "position": [3.0, -2.0], "angle": -1.1, "velocity": [0.1, 0.0]},
        {"name": "pentagon", "shape": "polygon",
         "vertices": [[0, 0], [1.2, -0.1], [1.6, 0.9], [0.7, 1.5], [-0.2, 0.8]],
         "position": [0.5, 3.0], "angle": 2.5, "probe": True},
        {"name": "triangle", "shape": "polygon", "vertices": [[0, 0], [1, 0], [0.2, 0.7]],
         "position": [0.0, -3.0], "angle": -2.9, "omega": 0.4},
    ]  # fmt: skip
    return scene_from_dict(raw)


@pytest.fixture(scope="module")
def floes(tmp_path_factory):
    """(scene, path) of a run file of ``turned_floes`` with three made-up frames."""
    scene = turned_floes()
    path = tmp_path_factory.mktemp("cf") / "floes.h5"
    writer = RunWriter(path, scene, {"dt": 1e-4, "arch": "cpu"})
    rng = np.random.default_rng(3)
    n = scene.n_bodies
    for f in range(3):
        writer.add_frame(
            0.1 * f,
            scene.positions + rng.normal(0.0, 0.2, (n, 2)),
            scene.angles + rng.uniform(-np.pi, np.pi, n),
            rng.normal(0.0, 1.0, (n, 2)),
            rng.normal(0.0, 1.0, n),
        )
    writer.close("complete")
    return scene, path


def scene_polygon(body) -> shapely.Polygon:
    """shapely's floe: the body's centroid-relative outline turned about the centroid by its
    angle, then moved to its position."""
    p = shapely.Polygon(body.vertices)
    p = affinity.rotate(p, body.angle, origin=(0.0, 0.0), use_radians=True)
    return affinity.translate(p, *body.position)


def test_cf_xarray_reads_every_floe_as_the_scenes_polygon(floes):
    # The test extra installs cf_xarray >= 0.11, which needs Python 3.11; below, this reader
    # cannot be had (the next tests check the same geometry against CF's rules and GDAL).
    cf_xarray = pytest.importorskip("cf_xarray")
    scene, path = floes
    with xr.open_dataset(path, group="bodies") as ds:
        assert ds.cf.geometries == {"polygon": ["floe_outline"]}
        geoms = cf_xarray.cf_to_shapely(ds, container="floe_outline")
        counts = ds["floe_outline_node_count"].values
    assert geoms.dims == ("body",) and geoms.size == scene.n_bodies == 4
    # Each ring closed: its first node again at its end.
    np.testing.assert_array_equal(counts, [len(b.vertices) + 1 for b in scene.bodies])
    for body, got in zip(scene.bodies, geoms.values):
        want = scene_polygon(body)
        assert isinstance(got, shapely.Polygon) and not got.interiors, body.name
        # CF 1.8, 7.5: exterior rings anticlockwise (the right-hand rule).
        assert got.is_valid and got.exterior.is_ccw, body.name
        coords = np.asarray(got.exterior.coords)
        assert len(coords) == len(body.vertices) + 1, body.name
        np.testing.assert_allclose(coords, want.exterior.coords, rtol=0, atol=ATOL)
        assert got.area == pytest.approx(shapely.Polygon(body.vertices).area, rel=1e-12)
        assert got.area == pytest.approx(want.area, rel=1e-12)
        assert got.centroid.distance(shapely.Point(body.position)) < ATOL, body.name
    # open_run's Dataset (every group in one) holds the same geometry.
    merged = cf_xarray.cf_to_shapely(open_run(path), container="floe_outline")
    assert merged.size == geoms.size
    assert all(a.equals_exact(b, 0.0) for a, b in zip(merged.values, geoms.values))


def test_the_file_follows_the_cf_geometry_rules(floes):
    """What CF 1.8 section 7.5 asks of a polygon geometry that cf_xarray does not check: a
    scalar container naming the node count and the node coordinates, nodes with an axis on
    one dimension, and data variables on the instance dimension naming the container."""
    _, path = floes
    with xr.open_dataset(path, group="bodies") as ds:
        container = ds["floe_outline"]
        assert container.dims == ()
        assert container.attrs["geometry_type"] == "polygon"
        assert "part_node_count" not in container.attrs  # single parts, no holes
        assert "interior_ring" not in container.attrs
        x, y = container.attrs["node_coordinates"].split()
        assert (ds[x].attrs["axis"], ds[y].attrs["axis"]) == ("X", "Y")
        assert ds[x].dims == ds[y].dims == ("outline_node",)
        assert ds[x].attrs["units"] == ds[y].attrs["units"] == "m"
        node_count = ds[container.attrs["node_count"]]
        assert node_count.dims == ("body",)
        assert int(node_count.sum()) == ds.sizes["outline_node"]
        # The nodes of each geometry in turn, each ring's first node again at its end.
        ends = np.cumsum(node_count.values)
        for axis in (x, y):
            v = ds[axis].values
            np.testing.assert_array_equal(v[ends - node_count.values], v[ends - 1])
        for name in PER_BODY:
            assert ds[name].attrs["geometry"] == "floe_outline", name
            assert ds[name].dims == ("body",), name
        for name in ds.data_vars:
            if name not in PER_BODY:
                assert "geometry" not in ds[name].attrs, name
    with h5py.File(path, "r") as f:
        assert f.attrs["Conventions"] == "CF-1.8"
        assert f.attrs["format_version"] == "2.2"


def as_format_2_0(path: Path, old: Path) -> None:
    """``old``: a copy of run file ``path`` as format 2.0 wrote it (no geometries)."""
    old.write_bytes(path.read_bytes())
    with h5py.File(old, "r+") as f:
        for name in NEW:
            del f["bodies"][name]
        del f["outline_node"]
        for name in PER_BODY:
            del f["bodies"][name].attrs["geometry"]
        f.attrs["format_version"] = "2.0"


def test_a_format_2_0_file_is_still_read_by_every_reader(floes, tmp_path):
    _, path = floes
    old = tmp_path / "floes.h5"
    as_format_2_0(path, old)
    new_run, old_run = read_run(path), read_run(old)
    assert set(new_run["bodies"]) - set(old_run["bodies"]) == set(NEW)
    for group in ("series", "frames", "bodies"):
        for name, values in old_run[group].items():
            np.testing.assert_array_equal(values, new_run[group][name], err_msg=name)
    ds = open_run(old)
    assert "floe_outline" not in ds and ds["mass"].dims == ("body",)
    np.testing.assert_array_equal(ds["position"].values, new_run["frames"]["position"])
    # The VTK export of the old file is the export of the new one, byte for byte.
    a = export_vtk(path, tmp_path / "new")
    b = export_vtk(old, tmp_path / "old")
    names = sorted(p.name for p in a.parent.iterdir())
    assert names == sorted(p.name for p in b.parent.iterdir()) and len(names) == 4
    for name in names:
        assert (a.parent / name).read_bytes() == (b.parent / name).read_bytes(), name


@pytest.mark.skipif(shutil.which("ogr2ogr") is None, reason="GDAL's ogr2ogr is not installed")
def test_gdal_reads_the_floes_as_valid_polygons_with_their_fields(floes, tmp_path):
    """GDAL's netCDF driver (what QGIS opens netCDF with) turns the geometry into a layer of
    polygons, the variables that name the container into its fields. GDAL closes no ring
    itself: a ring left open came out open, an invalid polygon."""
    scene, path = floes
    flat = tmp_path / "bodies.nc"
    with xr.open_dataset(path, group="bodies") as ds:
        ds.attrs["Conventions"] = "CF-1.8"  # the root's: GDAL reads CF geometry by it
        ds.to_netcdf(flat)
    out = tmp_path / "floes.geojson"
    subprocess.run(["ogr2ogr", "-f", "GeoJSON", str(out), str(flat)], check=True, timeout=60)
    layer = json.loads(out.read_text())
    assert layer["name"] == "floe_outline"
    features = layer["features"]
    assert len(features) == scene.n_bodies
    for body, feature in zip(scene.bodies, features):
        assert feature["properties"]["names"] == body.name
        assert feature["properties"]["kinds"] == body.kind
        got = shapely.geometry.shape(feature["geometry"])
        assert isinstance(got, shapely.Polygon) and got.is_valid, body.name
        ring = feature["geometry"]["coordinates"][0]
        assert ring[0] == ring[-1] and len(ring) == len(body.vertices) + 1, body.name
        want = scene_polygon(body)
        np.testing.assert_allclose(got.exterior.coords, want.exterior.coords, atol=ATOL)
    # GeoJSON holds 15 significant digits.
    masses = [f["properties"]["mass"] for f in features]
    np.testing.assert_allclose(masses, scene.masses, rtol=1e-14)
