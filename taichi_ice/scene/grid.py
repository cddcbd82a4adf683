"""A current or wind given on a grid: read from netCDF with xarray, checked, held read-only.

A scene names the file in the table of the field it gives (``[water] current = {file =
"currents.nc", u = "u", v = "v"}``, ``[wind] velocity = {file = ...}``). The file holds the
two components as variables (names ``u`` and ``v`` unless the table says others) on the
dimensions ``x`` and ``y`` and optionally ``t``, each with its coordinate variable: the node
positions in m (``x``, ``y``) and times in s from the run's start (``t``), evenly spaced and
increasing. Units, where the file gives them, must be those (``m``, ``s``, ``m/s`` or
``m s-1``). Every value must be finite (a land mask of NaN is refused: fill it).

The engine samples it at each floe's centroid (``physics.forcing.grid_sample``): bilinear in
x and y, linear in t, constant beyond the grid. Reading needs the ``xarray`` extra
(``pip install 'taichi-ice[xarray]'``); scenes without a grid never import it.

Plain NumPy (xarray when a grid is read): importing this module never starts Taichi.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from ..errors import ScenarioError
from ..readonly import frozen
from .table import printable

__all__ = ["MAX_GRID_NODES", "ForcingGrid", "read_grid"]

# Most nodes (x * y * t) of one grid: 2^24 nodes are 256 MiB of float64 pairs, uploaded whole
# to the device; a larger field is cropped or coarsened for the scene before it runs.
MAX_GRID_NODES = 2**24
# An axis is regular when no spacing differs from the mean by more than this fraction of it
# (coordinates written in float32 keep 1e-7).
REGULAR_RTOL = 1e-6
DIMS = ("t", "y", "x")
_UNITS = {
    "x": ("m", "meter", "meters", "metre", "metres"),
    "y": ("m", "meter", "meters", "metre", "metres"),
    "t": ("s", "second", "seconds"),
    "value": ("m/s", "m s-1", "m s^-1", "m s**-1", "m.s-1", "meter second-1", "m/sec"),
}
# Grids read in this process, by file, its size and modification time and the variables:
# an ensemble reseeds a scene a hundred times and reads its file once.
_CACHE: dict[tuple, ForcingGrid] = {}


@dataclass(frozen=True, eq=False)
class ForcingGrid:
    """A 2-vector field (m/s) on a regular grid, as read from a file.

    Attributes:
        path: the file read (resolved). variables: the names of the two components.
        values: ``(nt, ny, nx, 2)`` read-only float64, t major, x fastest.
        origin: ``(x0, y0, t0)`` of the first node (m, m, s). spacing: ``(dx, dy, dt)``
            (an axis of one node: 1.0).

    Two grids are equal when their nodes and values are (``digest``), wherever they came
    from: worlds of one batch must share one.
    """

    path: str
    variables: tuple[str, str]
    values: np.ndarray
    origin: tuple[float, float, float]
    spacing: tuple[float, float, float]

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(nt, ny, nx)``."""
        return tuple(int(n) for n in self.values.shape[:3])

    @cached_property
    def digest(self) -> str:
        """SHA-256 of the nodes and the values (once: batches compare their worlds' grids)."""
        h = hashlib.sha256(np.asarray(self.origin + self.spacing, dtype=np.float64).tobytes())
        h.update(np.asarray(self.shape, dtype=np.int64).tobytes())
        h.update(np.ascontiguousarray(self.values).tobytes())
        return h.hexdigest()

    def __eq__(self, other) -> bool:
        return isinstance(other, ForcingGrid) and self.digest == other.digest

    def __hash__(self) -> int:
        return hash(self.digest)

    def __repr__(self) -> str:
        nt, ny, nx = self.shape
        return (
            f"ForcingGrid({Path(self.path).name!r}, {self.variables}, {nx} x {ny} x {nt}, "
            f"sha256 {self.digest[:12]})"
        )


def read_grid(
    path: Path, u: str, v: str, error: Callable[[str, str], ScenarioError]
) -> ForcingGrid:
    """Read and check the grid of variables ``u`` and ``v`` in the netCDF file ``path``.

    Args:
        path: the file (already resolved against the scene's folder).
        u, v: the variables' names.
        error: ``error(key, message)`` makes the scene's error for a key of the table that
            names the file (``file``, ``u`` or ``v``), so that every message names the scene
            file, the table and the key as well as the netCDF file and the variable.

    Raises:
        ScenarioError: no xarray, an unreadable file, a missing variable or coordinate,
            other dimensions, an irregular or decreasing axis, units other than SI, a
            non-finite value, or more than ``MAX_GRID_NODES`` nodes.
    """
    try:
        stat = path.stat()
    except OSError as exc:
        raise error("file", f"cannot read {path} ({exc.strerror or exc})") from None
    key = (str(path.resolve()), stat.st_size, stat.st_mtime_ns, u, v)
    if key in _CACHE:
        return _CACHE[key]
    try:
        import xarray as xr
    except ImportError:
        raise error(
            "file",
            f"reading the grid {path} needs xarray and netCDF4: pip install 'taichi-ice[xarray]'",
        ) from None
    try:
        ds = xr.open_dataset(path, decode_times=False, decode_timedelta=False)
    except Exception as exc:  # xarray raises what its backend raises
        why = printable(str(exc).strip().splitlines()[0] if str(exc).strip() else "")
        raise error("file", f"cannot read {path} as netCDF ({type(exc).__name__}: {why})") from None
    with ds:
        grid = _grid(ds, path, u, v, error)
    _CACHE[key] = grid
    return grid


def _grid(ds, path: Path, u: str, v: str, error) -> ForcingGrid:
    arrays = []
    dims: tuple[str, ...] | None = None
    for k, name in (("u", u), ("v", v)):
        if name not in ds.data_vars:
            listed = ", ".join(map(str, ds.data_vars)) or "none"
            raise error(k, f"{path} has no variable '{name}'; its variables: {listed}")
        da = ds[name]
        if set(da.dims) not in ({"x", "y"}, {"x", "y", "t"}):
            raise error(
                k,
                f"{path}: variable '{name}' has the dimensions {tuple(da.dims)}; give it "
                "(y, x) or (t, y, x), named x and y (m) and t (s)",
            )
        if dims is not None and set(da.dims) != set(dims):
            raise error(k, f"{path}: variable '{name}' has other dimensions than '{u}'")
        dims = tuple(da.dims)
        _units(ds[name].attrs, "value", f"{path}: variable '{name}'", k, error)
        arrays.append(da)
    assert dims is not None
    nodes = 1
    origin, spacing = [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]
    for axis, dim in ((0, "x"), (1, "y"), (2, "t")):
        if dim not in dims:
            continue
        if dim not in ds.coords or ds[dim].ndim != 1:
            raise error(
                "file",
                f"{path}: dimension '{dim}' has no coordinate variable; "
                f"add one with the node {'times in s' if dim == 't' else 'positions in m'}",
            )
        _units(ds[dim].attrs, dim, f"{path}: coordinate '{dim}'", "file", error)
        c = np.asarray(ds[dim].values, dtype=np.float64)
        origin[axis], spacing[axis] = _regular(c, dim, path, error)
        nodes *= len(c)
    if nodes > MAX_GRID_NODES:
        raise error(
            "file",
            f"{path}: the grid has {nodes} nodes, more than {MAX_GRID_NODES}; crop or "
            "coarsen it to the scene",
        )
    order = [d for d in DIMS if d in dims]
    values = []
    for (k, name), da in zip((("u", u), ("v", v)), arrays):
        a = np.asarray(da.transpose(*order).values, dtype=np.float64)
        if "t" not in dims:
            a = a[None]
        bad = int(np.count_nonzero(~np.isfinite(a)))
        if bad:
            raise error(
                k,
                f"{path}: variable '{name}' has {bad} missing or non-finite values (a land "
                "mask?); fill them",
            )
        values.append(a)
    return ForcingGrid(
        path=str(path),
        variables=(u, v),
        values=frozen(np.stack(values, axis=-1)),
        origin=(origin[0], origin[1], origin[2]),
        spacing=(spacing[0], spacing[1], spacing[2]),
    )


def _units(attrs, kind: str, what: str, key: str, error) -> None:
    units = attrs.get("units")
    if units is not None and str(units).strip() not in _UNITS[kind]:
        raise error(
            key,
            f"{what} is in '{units}'; give it in {_UNITS[kind][0]} (or leave its units out)",
        )


def _regular(c: np.ndarray, dim: str, path: Path, error) -> tuple[float, float]:
    """(first node, spacing) of a coordinate that must be finite, increasing and regular."""
    if c.size == 0 or not np.all(np.isfinite(c)):
        raise error("file", f"{path}: coordinate '{dim}' is empty or not finite")
    if c.size == 1:
        return float(c[0]), 1.0
    step = np.diff(c)
    mean = float(c[-1] - c[0]) / (c.size - 1)
    if np.any(step <= 0.0):
        raise error("file", f"{path}: coordinate '{dim}' is not increasing; sort the grid")
    if np.max(np.abs(step - mean)) > REGULAR_RTOL * mean:
        raise error(
            "file",
            f"{path}: coordinate '{dim}' is not evenly spaced (steps {step.min():.6g} to "
            f"{step.max():.6g}); interpolate the field to a regular grid",
        )
    return float(c[0]), mean
