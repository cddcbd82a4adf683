"""Run files are netCDF-4: xarray and the netCDF C library open them with no options, every
variable has units and a long name, and the file says where it came from."""

from __future__ import annotations

import platform
from importlib import metadata

import h5py
import numpy as np
import pytest

from taichi_ice import Simulation, backend, load_scenario, open_run

xr = pytest.importorskip("xarray")
netCDF4 = pytest.importorskip("netCDF4")

GROUPS = ("series", "frames", "bodies")


@pytest.fixture(scope="module")
def run_file(tmp_path_factory, taichi_runtime):
    arch, precision = taichi_runtime
    path = tmp_path_factory.mktemp("nc") / "squares.h5"
    Simulation(load_scenario("scenarios/two_squares.toml"), arch=arch, precision=precision).run(
        until=0.3, out=path
    )
    return path


def test_xarray_opens_every_group_with_no_options_and_reads_the_hdf5_values(run_file):
    root = xr.open_dataset(run_file)
    assert root.attrs["Conventions"].startswith("CF-")
    with h5py.File(run_file, "r") as f:
        for group in GROUPS:
            with xr.open_dataset(run_file, group=group) as ds:
                assert set(ds.variables) == set(f[group]), group
                for name in f[group]:
                    expected = f[group][name][()]
                    if expected.dtype.kind == "O":
                        expected = np.array([x.decode() for x in expected])
                    np.testing.assert_array_equal(ds[name].values, expected, err_msg=name)
        # Series on their time, frames on theirs; bodies on the root's dimensions.
        with xr.open_dataset(run_file, group="frames") as ds:
            assert ds["position"].dims == ("time", "body", "xy")
        with xr.open_dataset(run_file, group="series") as ds:
            assert ds["probe_force"].dims == ("time", "probe", "xy")
            assert ds.sizes["time"] == f["series/time"].shape[0]


def test_xarray_datatree_opens_every_group_of_the_file_at_once(run_file):
    """``xr.open_datatree`` with no options: the root's provenance and every group, each
    variable on its named dimensions."""
    tree = xr.open_datatree(run_file)
    assert set(GROUPS) <= set(tree.children)
    assert tree.attrs["Conventions"].startswith("CF-")
    assert tree["series"]["friction_energy"].dims == ("time",)
    assert tree["frames"]["position"].dims == ("time", "body", "xy")
    with h5py.File(run_file, "r") as f:
        np.testing.assert_array_equal(tree["series"]["time"].values, f["series/time"][()])


def test_the_netcdf_c_library_reads_units_and_long_names_of_every_variable(run_file):
    with netCDF4.Dataset(run_file) as nc:
        assert nc.data_model == "NETCDF4"
        for group in GROUPS:
            for name, var in nc.groups[group].variables.items():
                assert var.long_name, f"{group}/{name}"
                if var.dtype is not str:
                    assert isinstance(var.units, str) and var.units, f"{group}/{name}"
        assert nc.groups["frames"].variables["velocity"].units == "m s-1"
        assert nc.groups["series"].variables["friction_energy"].units == "J"


def test_open_run_returns_the_whole_run_as_one_dataset(run_file):
    ds = open_run(run_file)
    assert isinstance(ds, xr.Dataset)
    with h5py.File(run_file, "r") as f:
        np.testing.assert_array_equal(ds["time"].values, f["series/time"][()])
        np.testing.assert_array_equal(ds["frame_time"].values, f["frames/time"][()])
        np.testing.assert_array_equal(ds["position"].values, f["frames/position"][()])
        np.testing.assert_array_equal(ds["mass"].values, f["bodies/mass"][()])
    assert ds["position"].dims == ("frame_time", "body", "xy")
    assert ds.attrs["status"] == "complete"


def test_provenance_names_versions_command_host_times_and_the_arch_that_ran(run_file):
    a = xr.open_dataset(run_file).attrs
    assert a["taichi_version"] == metadata.version("taichi")
    assert a["numpy_version"] == np.__version__
    assert a["python_version"] == platform.python_version()
    assert a["format_version"] and a["command"] and a["host"]
    assert a["started"] <= a["finished"] and a["finished"].endswith("Z")
    assert "git_revision" in a
    assert a["arch"] == backend.actual_arch()


def test_cf_tools_read_the_floes_of_the_first_frame(run_file, taichi_runtime):
    """cf_xarray reads the CF-1.8 polygons of the file (tests/test_cf_geometry.py): the floes
    where the run's first frame has them, at time 0."""
    cf_xarray = pytest.importorskip("cf_xarray")
    shapely = pytest.importorskip("shapely")
    from shapely import affinity

    with (
        xr.open_dataset(run_file, group="bodies") as b,
        xr.open_dataset(run_file, group="frames") as fr,
    ):
        geoms = cf_xarray.cf_to_shapely(b, container=b["mass"].attrs["geometry"]).values
        off, vertices = b["vertex_offsets"].values, b["vertices"].values
        assert fr["time"].values[0] == 0.0
        position, angle = fr["position"].values[0], fr["angle"].values[0]
    # Frames hold the run's numbers: a float32 run rounded the scene's positions and angles.
    atol = 1e-12 if taichi_runtime[1] == "f64" else 1e-6
    assert len(geoms) == len(off) - 1 == 2
    for i, got in enumerate(geoms):
        want = shapely.Polygon(vertices[off[i] : off[i + 1]])
        want = affinity.rotate(want, angle[i], origin=(0.0, 0.0), use_radians=True)
        want = affinity.translate(want, *position[i])
        assert got.exterior.is_ccw
        np.testing.assert_allclose(got.exterior.coords, want.exterior.coords, rtol=0, atol=atol)
