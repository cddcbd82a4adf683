"""A sweep's results as one dataset: a row per world, written as netCDF-4 for xarray.

    from taichi_ice.experiments.sweep.dataset import open_sweep
    ds = open_sweep("out/sweep")                 # the folder, or its sweep.nc
    ds.peak_force.groupby("law").median()
    ds.where(ds.law == "rate-state", drop=True).released.mean()

Layout of ``sweep.nc``:

- dimension ``world`` (one row per world, in the sweep's order: law, override values, seed);
- coordinates ``world``, ``seed``, ``law`` (the law's label, e.g. ``mu0.5``), ``law_name``
  (its kind: coulomb, rate-state, steady-state, memory-only), every parameter of every law
  in the sweep (``mu``, ``A``, ``B``, ``mu0``, ``v_star``, ``t_c``: NaN where a world's law
  has no such parameter; choices such as ``below_v_star`` as strings, "" where absent) and
  every override (its dotted key, e.g. ``field.rubble.area_fraction``);
- variables: the metrics kept (``metrics.METRIC_INFO``: units and long names), ``status``
  (complete, failed, missing), ``failure``, ``steps``, ``dt``, and ``batch`` and ``worker``
  (which batch, on which process, ran the world);
- attributes: the sweep file's text, the scene's text and source, ``until``, ``window``,
  arch and precision, and the versions of taichi-ice, Taichi, NumPy, Python, Dask, xarray
  and netCDF4.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ...provenance import versions
from ..metrics import METRIC_INFO

__all__ = ["build_dataset", "open_sweep", "write_dataset"]

# xarray's netCDF engine for netCDF-4 files.
ENGINE = "netcdf4"


def build_dataset(sweep, worlds: Sequence, results: Mapping[str, dict], arch: str, precision: str):
    """The dataset of ``sweep``'s ``worlds`` from ``results`` (by world key; a world not in
    it gets NaN metrics and status 'missing').

    Returns:
        ``xarray.Dataset`` with dimension ``world`` (module docstring).
    """
    import xarray as xr

    from ...physics.friction import LAWS

    n = len(worlds)
    rows = [results.get(w.key) for w in worlds]
    coords: dict[str, tuple] = {
        "world": ("world", np.arange(n), {"long_name": "world index in the sweep"}),
        "seed": (
            "world",
            np.array([w.seed for w in worlds]),
            {"long_name": "field-jitter seed (layout)"},
        ),
        "law": (
            "world",
            np.array([w.label for w in worlds], dtype=str),
            {"long_name": "friction law label"},
        ),
        "law_name": (
            "world",
            np.array([w.law["law"] for w in worlds], dtype=str),
            {"long_name": "friction law kind"},
        ),
    }
    # Every parameter and choice of every law in the sweep, in declaration order.
    kinds = [LAWS[name] for name in dict.fromkeys(w.law["law"] for w in worlds)]
    for cls in kinds:
        for p in cls.parameters():
            if p.name in coords:
                continue
            values = np.array([float(w.law.get(p.name, math.nan)) for w in worlds])
            attrs = {
                "long_name": f"friction law parameter {p.name}: {p.doc}",
                "units": p.unit or "1",
            }
            coords[p.name] = ("world", values, attrs)
        for key in cls.choices:
            if key not in coords:
                values = np.array([str(w.law.get(key, "")) for w in worlds], dtype=str)
                coords[key] = ("world", values, {"long_name": f"friction law choice {key}"})
    for key in sweep.overrides:
        values = np.array([dict(w.overrides)[key] for w in worlds])
        coords[key] = ("world", values, {"long_name": f"scene override {key}"})

    data: dict[str, tuple] = {}
    for name in sweep.metrics:
        unit, long_name = METRIC_INFO[name]
        values = np.array([r["metrics"][name] if r else math.nan for r in rows], dtype=float)
        data[name] = ("world", values, {"units": unit, "long_name": long_name})

    def column(key, default, dtype, attrs):
        return (
            "world",
            np.array([r.get(key, default) if r else default for r in rows], dtype=dtype),
            attrs,
        )

    data["status"] = column("status", "missing", str, {"long_name": "complete, failed or missing"})
    data["failure"] = column("failure", "", str, {"long_name": "why the run failed, if it did"})
    data["steps"] = column("steps", 0, np.int64, {"long_name": "time steps taken", "units": "1"})
    data["dt"] = column("dt", math.nan, float, {"long_name": "time step", "units": "s"})
    data["batch"] = column("batch", "", str, {"long_name": "id of the batch that ran the world"})
    data["worker"] = column("worker", "", str, {"long_name": "host:pid of the process that ran it"})

    attrs = {
        "title": f"taichi-ice sweep of {sweep.scene.source}",
        "Conventions": "CF-1.8",
        "history": f"{time.strftime('%Y-%m-%dT%H:%M:%S')} taichi-ice sweep",
        "sweep_source": str(sweep.source),
        "sweep": sweep.text,
        "scene_source": str(sweep.scene.source),
        "scene": sweep.scene.text,
        "until_s": float(sweep.until),
        "window_s": float(sweep.window),
        "arch": arch,
        "precision": precision,
        **versions(("dask", "distributed", "xarray", "netCDF4")),
    }
    return xr.Dataset(data_vars=data, coords=coords, attrs=attrs)


def write_dataset(ds, path: str | Path) -> Path:
    """Write ``ds`` as netCDF-4 to ``path`` (whole: to a temporary name, then renamed)."""
    import os

    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    ds.to_netcdf(tmp, engine=ENGINE, format="NETCDF4")
    os.replace(tmp, path)
    return path


def open_sweep(path: str | Path):
    """A sweep's dataset as an ``xarray.Dataset``, read into memory (the file is closed).

    Args:
        path: the sweep's output folder or its ``sweep.nc``.
    """
    import xarray as xr

    path = Path(path)
    if path.is_dir():
        path = path / "sweep.nc"
    with xr.open_dataset(path, engine=ENGINE) as ds:
        return ds.load()
