"""HDF5 run files: written as the run goes, readable while it runs and after it fails.

Layout (one file per world; DESIGN.md section 3):

- root attributes: ``taichi_ice_version``, ``scenario`` (the scene's TOML), ``source``,
  ``friction`` (law name), ``friction_params`` (JSON), ``arch``, ``precision``, ``dt`` (s),
  ``seed``, ``status`` (``running``, ``complete`` or ``failed``), ``failure`` (why, if
  failed), ``steps``, ``wall_time`` (s).
- ``/series/``: ``time`` (T,), ``probe_force`` (T, P, 2) mean contact force on each probe
  body over the sample interval (N), ``friction_energy``, ``viscous_energy``,
  ``drag_energy``, ``kinetic_energy``, ``elastic_energy``, ``crushing_energy``, ``work_in``
  (T,) in J, and ``n_contacts`` (T,).
- ``/frames/``: ``time`` (F,), ``position`` (F, N, 2), ``angle`` (F, N), ``velocity``
  (F, N, 2), ``omega`` (F, N); every body in scene order.
- ``/bodies/``: ``names``, ``kinds``, ``vertices`` (V, 2) centroid-relative outlines and
  ``vertex_offsets`` (N + 1,), ``mass`` (kg), ``inertia`` (kg m^2), ``probe_index`` (P,).

The file is opened in SWMR mode (single writer, multiple readers) and flushed after every
sample, so ``h5py.File(path, "r", swmr=True)`` reads a running file and a killed run leaves
a consistent file whose ``status`` still says ``running``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import h5py
import numpy as np

from . import budget
from ._version import __version__


class RunWriter:
    """Appends samples and frames of one world to an HDF5 file.

    Args:
        path: output file (its folder is created).
        scene: the world's Scene.
        attrs: extra root attributes (arch, precision, dt ...).
    """

    def __init__(self, path: str | Path, scene, attrs: Mapping[str, object]):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        n, p = scene.n_bodies, len(scene.probe_indices)
        f = h5py.File(self.path, "w", libver="latest")
        self.file = f
        law = scene.friction
        f.attrs["taichi_ice_version"] = __version__
        f.attrs["scenario"] = scene.text
        f.attrs["source"] = str(scene.source)
        f.attrs["friction"] = law.name
        f.attrs["friction_params"] = json.dumps(law.to_dict())
        f.attrs["seed"] = scene.simulation.seed
        for key, value in attrs.items():
            f.attrs[key] = value
        f.attrs["status"] = "running"
        f.attrs["failure"] = ""
        f.attrs["steps"] = 0

        b = f.create_group("bodies")
        b["names"] = np.array(scene.names, dtype=h5py.string_dtype())
        b["kinds"] = np.array([body.kind for body in scene.bodies], dtype=h5py.string_dtype())
        b["vertices"] = scene.vertices_flat
        b["vertex_offsets"] = scene.vertex_offsets
        b["mass"] = scene.masses
        b["inertia"] = scene.inertias
        b["probe_index"] = scene.probe_indices

        s = f.create_group("series")
        self.series = {
            "time": _growing(s, "time", ()),
            "probe_force": _growing(s, "probe_force", (p, 2)),
            "n_contacts": _growing(s, "n_contacts", (), dtype=np.int64),
        }
        for name in budget.SERIES:
            self.series[name] = _growing(s, name, ())
        fr = f.create_group("frames")
        self.frames = {
            "time": _growing(fr, "time", ()),
            "position": _growing(fr, "position", (n, 2)),
            "angle": _growing(fr, "angle", (n,)),
            "velocity": _growing(fr, "velocity", (n, 2)),
            "omega": _growing(fr, "omega", (n,)),
        }
        f.swmr_mode = True
        f.flush()

    def add_sample(self, time: float, probe_force, energies, n_contacts: int) -> None:
        """One time-series row: probe_force (P, 2) N, energies in budget.SERIES order (J)."""
        row = {"time": time, "probe_force": probe_force, "n_contacts": n_contacts}
        row.update(zip(budget.SERIES, energies))
        for name, value in row.items():
            _append(self.series[name], value)

    def add_frame(self, time: float, position, angle, velocity, omega) -> None:
        """One frame of every body's state."""
        row = {
            "time": time,
            "position": position,
            "angle": angle,
            "velocity": velocity,
            "omega": omega,
        }
        for name, value in row.items():
            _append(self.frames[name], value)

    def flush(self, steps: int) -> None:
        self.file.attrs["steps"] = steps
        self.file.flush()

    def close(self, status: str, failure: str = "", **attrs) -> None:
        """Mark the run ``complete`` or ``failed`` (with the reason) and close the file."""
        if not self.file.id.valid:
            return
        # Attributes cannot be created in SWMR mode, only overwritten: all exist already, or
        # are written before swmr_mode was set.
        self.file.attrs["status"] = status
        self.file.attrs["failure"] = failure
        for key, value in attrs.items():
            if key in self.file.attrs:
                self.file.attrs[key] = value
        self.file.flush()
        self.file.close()


def _growing(group, name: str, shape: tuple, dtype=np.float64):
    """A dataset of rows of ``shape`` that grows along its first axis."""
    # Small rows are chunked 64 at a time, frames one per chunk. HDF5 wants positive chunk
    # sizes, so an empty axis (no probes) is declared growable to allow a chunk of one.
    chunk_rows = 64 if np.prod(shape, dtype=np.int64) < 4096 else 1
    chunks = (chunk_rows, *(max(d, 1) for d in shape))
    maxshape = (None, *(d if d > 0 else None for d in shape))
    return group.create_dataset(
        name, shape=(0, *shape), maxshape=maxshape, dtype=dtype, chunks=chunks
    )


def _append(dataset, value) -> None:
    n = dataset.shape[0]
    dataset.resize(n + 1, axis=0)
    dataset[n] = value


def read_run(path: str | Path) -> dict:
    """Everything in a run file as NumPy arrays: ``{"attrs", "series", "frames", "bodies"}``.

    Works on a file that is still being written (SWMR) or whose run failed.
    """
    out: dict = {}
    with h5py.File(path, "r", swmr=True) as f:
        out["attrs"] = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
        for group in ("series", "frames", "bodies"):
            out[group] = {}
            for name, ds in f[group].items():
                data = ds[()]
                if ds.dtype.kind == "O":
                    data = np.array([x.decode() if isinstance(x, bytes) else x for x in data])
                out[group][name] = data
    return out
