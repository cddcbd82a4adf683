"""Run files: netCDF-4 (HDF5 with dimension scales), written as the run goes, readable while it
runs, after it fails and after it is killed. This module holds the layout and the writer.

Layout (one file per world; DESIGN.md section 3):

- root attributes: ``Conventions`` (CF), ``format_version``, ``taichi_ice_version``,
  ``taichi_version``, ``numpy_version``, ``h5py_version``, ``python_version``,
  ``git_revision``, ``command``, ``host``, ``started`` and ``finished`` (UTC), ``scenario``
  (the scene's TOML), ``source``, ``friction`` (law name), ``friction_params`` (JSON),
  ``arch`` (what ran: ``cpu``, ``cuda`` ...), ``arch_requested``, ``precision``,
  ``integrator`` (``euler`` or ``analytic``), ``dt`` (s),
  ``stable_dt`` (s), ``seed``, ``status`` (``running``, ``complete`` or ``failed``),
  ``failure`` (why, if failed), ``warning`` (e.g. a budget residual past its bound),
  ``steps``, ``wall_time`` (s), ``resumed`` (how many times the run was resumed).
- root coordinates (netCDF dimensions, shared by the groups): ``body`` (N,), ``probe``
  (P,: the body index of each probe), ``xy`` (2,: "x", "y"), ``vertex`` (V,), ``body_edge``
  (N + 1,), ``outline_node`` (V + N,: format 2.1 on).
- ``/series/``: ``time`` (T,), ``probe_force`` (T, P, 2) mean contact force on each probe
  body over the sample interval (N), ``friction_energy``, ``viscous_energy``,
  ``drag_energy``, ``kinetic_energy``, ``elastic_energy``, ``crushing_energy``,
  ``severed_energy``, ``work_in``, ``wind_work``, ``current_work``, ``tilt_work`` (T,) in J
  (the last three from format 2.2 on), and ``n_contacts`` (T,).
- ``/frames/``: ``time`` (F,), ``position`` (F, N, 2), ``angle`` (F, N), ``velocity``
  (F, N, 2), ``omega`` (F, N); every body in scene order.
- ``/bodies/``: ``names``, ``kinds``, ``vertices`` (V, 2) centroid-relative outlines and
  ``vertex_offsets`` (N + 1,), ``mass`` (kg), ``inertia`` (kg m^2), ``probe_index`` (P,);
  and the floes as CF-1.8 polygon geometries (CF section 7.5, "Geometries"; format 2.1 on):
  the container ``floe_outline`` (scalar: ``geometry_type = "polygon"``, ``node_count``,
  ``node_coordinates``), ``floe_outline_node_count`` (N,) and the nodes ``floe_outline_x``,
  ``floe_outline_y`` (V + N,: ``axis`` X and Y, m): every outline in the world as the scene
  places it at time 0 (``vertices`` turned by the scene's angle and moved to its position),
  anticlockwise (CF's right-hand rule for exterior rings), its first node again at its end
  (CF allows it; GDAL reads a ring left open as an open, invalid polygon).
  ``names``, ``kinds``, ``mass`` and ``inertia`` carry ``geometry = "floe_outline"``. Convex
  floes are single polygons without holes: no ``part_node_count`` or ``interior_ring``.
- ``/contacts/`` (only when asked: ``Simulation(contacts=True)``, ``run --contacts``): every
  contact at every frame, the frames' rows one after the other on the dimension ``contact``
  (a CF-1.8 contiguous ragged array, CF section 9.3.3 and appendix H.2.4: ``row_size`` (F,)
  on ``time`` counts each frame's rows, ``sample_dimension = "contact"``): ``time`` (F,),
  ``body_a`` and ``body_b``, ``point`` and ``normal`` (C, 2), ``width`` (m), ``overlap``
  (area, m^2), ``force_normal`` and ``force_tangential`` (N: on ``body_b``; ``body_a`` takes
  the opposite), ``slip_rate`` (m/s), ``theta``, ``mu`` and ``stuck`` (C,). A frame's rows
  are the contacts of the step that starts at its time (``taichi_ice.engine.contact_rows``).

Every variable has ``units`` (but the strings) and ``long_name``; each group's ``time`` is its
dimension. ``xarray.open_dataset(path, group="series")`` (and ``"frames"``, ``"bodies"``)
(and ``"contacts"``) reads a group with no other option; ``open_run(path)`` returns the whole
run as one Dataset.

Writing: rows are kept in memory and written every frame, each time in one short open of
the file that extends every series together, then closes it. Between writes the file is
closed and whole, so a reader (``h5py.File(path)``, xarray) sees series of one length, and a
run killed with SIGKILL leaves a file that opens with no special option (its ``status`` still
says ``running``). A reader that opens the file at the instant of a write may be refused;
``read_run`` and ``open_run`` try again.

Not here: reading a run file (``read_run``, ``open_run``, the checks of a file and of a
resume) is ``taichi_ice.run.runfile_read``; claiming an output path and its lock before a run
(``claim``, ``check_folder``) is ``taichi_ice.run.output``.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import uuid
from collections.abc import Mapping
from pathlib import Path

import h5py
import numpy as np

from .. import provenance
from ..errors import OutputError
from . import budget
from .runfile_contacts import CONTACT_DIMS, CONTACT_VARIABLES, append, create, cut
from .runfile_read import check_checkpoint_match, check_run_file

__all__ = [
    "CONVENTIONS",
    "DIMS",
    "DISK_RESERVE",
    "FORMAT_VERSION",
    "GEOMETRY",
    "VARIABLES",
    "DiskFullError",
    "RunWriter",
    "check_room",
]

# Version of this layout; a reader refuses a file with another major version. 2.1: the
# floes as CF geometries in /bodies (added only: every reader reads 2.0 files as before).
# /contacts, written only when asked, is an optional group of 2.1: its presence says it, and
# a file without it is the file of before, attribute for attribute.
# 2.2: the forcing's work series, wind_work, current_work and tilt_work (added only: a file
# without them had none, and the budget reads them as 0).
FORMAT_VERSION = "2.2"
CONVENTIONS = "CF-1.8"

# (units, long_name) of every variable; "" units for strings (CF gives them none).
_ENERGY_NAMES = {
    "friction_energy": "energy dissipated by frictional slip (cumulative)",
    "viscous_energy": "energy dissipated by the contact dashpots (cumulative)",
    "drag_energy": "energy dissipated by water drag (cumulative)",
    "work_in": "work done by kinematic bodies and external forces (cumulative)",
    "kinetic_energy": "kinetic energy, translational and rotational",
    "elastic_energy": "elastic energy in overlaps and tangential springs",
    "crushing_energy": "energy dissipated by crushing beyond the ice strength (cumulative)",
    "severed_energy": "work held by stick springs when their contacts ended (cumulative)",
    "wind_work": "work done by the wind's drag (cumulative)",
    "current_work": "work done by the ocean current through the water drag (cumulative)",
    "tilt_work": "work done by the sea-surface tilt of a geostrophic current (cumulative)",
}
VARIABLES: dict[str, dict[str, tuple[str, str]]] = {
    "": {
        "body": ("1", "body index, in scene order"),
        "probe": ("1", "body index of each probe body"),
        "xy": ("", "vector component"),
        "vertex": ("1", "vertex index in /bodies/vertices"),
        "body_edge": ("1", "index into /bodies/vertex_offsets"),
        "outline_node": ("1", "node index in /bodies/floe_outline_x and floe_outline_y"),
    },
    "series": {
        "time": ("s", "time of the sample"),
        "probe_force": ("N", "mean contact force on each probe body over the sample interval"),
        "n_contacts": ("1", "contacts in the world after the step"),
        **{name: ("J", _ENERGY_NAMES.get(name, name.replace("_", " "))) for name in budget.SERIES},
    },
    "frames": {
        "time": ("s", "time of the frame"),
        "position": ("m", "centroid position"),
        "angle": ("rad", "orientation, counter-clockwise"),
        "velocity": ("m s-1", "centroid velocity"),
        "omega": ("rad s-1", "angular velocity, counter-clockwise"),
    },
    "bodies": {
        "names": ("", "body name"),
        "kinds": ("", "body kind: dynamic, fixed or kinematic"),
        "vertices": ("m", "outline vertices relative to the centroid, unrotated"),
        "vertex_offsets": ("1", "first vertex of each body in vertices (and the end)"),
        "mass": ("kg", "mass"),
        "inertia": ("kg m2", "moment of inertia about the centroid"),
        "probe_index": ("1", "body index of each probe body"),
        "floe_outline": ("1", "floe outlines at time 0: CF geometry container"),
        "floe_outline_node_count": ("1", "number of outline nodes of each floe"),
        "floe_outline_x": ("m", "x of the floe outline nodes in the world at time 0"),
        "floe_outline_y": ("m", "y of the floe outline nodes in the world at time 0"),
    },
    "contacts": CONTACT_VARIABLES,
}
# The floes as CF-1.8 polygon geometries (CF section 7.5): the container's attributes, and
# the per-body variables (on the instance dimension, body) that it describes.
GEOMETRY = "floe_outline"
_GEOMETRY_ATTRS = {
    "geometry_type": "polygon",
    "node_count": "floe_outline_node_count",
    "node_coordinates": "floe_outline_x floe_outline_y",
    "comment": (
        "every floe's outline in the world as the scene places it at time 0 (/bodies/vertices "
        "turned by the body's initial angle and moved to its initial centroid), anticlockwise, "
        "the first node repeated at the end; a frame's outlines are vertices turned by "
        "/frames/angle and moved to /frames/position"
    ),
}
_GEOMETRY_OF = ("names", "kinds", "mass", "inertia")
# Dimensions of each variable (the first of a series or frame is its group's time).
DIMS: dict[str, dict[str, tuple[str, ...]]] = {
    "series": {"probe_force": ("time", "probe", "xy")},
    "frames": {
        "position": ("time", "body", "xy"),
        "angle": ("time", "body"),
        "velocity": ("time", "body", "xy"),
        "omega": ("time", "body"),
    },
    "bodies": {
        "names": ("body",),
        "kinds": ("body",),
        "vertices": ("vertex", "xy"),
        "vertex_offsets": ("body_edge",),
        "mass": ("body",),
        "inertia": ("body",),
        "probe_index": ("probe",),
        "floe_outline": (),
        "floe_outline_node_count": ("body",),
        "floe_outline_x": ("outline_node",),
        "floe_outline_y": ("outline_node",),
    },
    "contacts": CONTACT_DIMS,
}
# Attributes every run file has from its start (so a reader always finds them).
_PLACEHOLDERS = {
    "status": "running",
    "failure": "",
    "warning": "",
    "steps": 0,
    "wall_time": 0.0,
    "finished": "",
    "resumed": 0,
}


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------


# Bytes a run file's disk must keep free beyond what a write needs: HDF5 allocates chunks
# and metadata as it writes, and a write that meets a full disk leaves the whole file
# unreadable (h5py: "addr overflow"), not just its last rows. So a write that would not fit
# with this much to spare is not started: the run stops with the file whole.
DISK_RESERVE = 1 << 20


class DiskFullError(OutputError):
    """The disk of an output file has no room for the next write; nothing was written, and
    every file is as whole as after its last write."""


def check_room(path: Path, needed: int, what: str = "the next write", started: bool = True):
    """Raise DiskFullError unless the disk of ``path`` has ``needed`` bytes free and
    ``DISK_RESERVE`` to spare; ``started``: the run has written to it already."""
    try:
        free = shutil.disk_usage(Path(path).parent).free
    except OSError:  # no answer from the file system: let the write itself try
        return
    if free < needed + DISK_RESERVE:
        raise DiskFullError(
            f"{path}: the disk is full ({free / 1e6:.3g} MB free; {what} needs about "
            f"{(needed + DISK_RESERVE) / 1e6:.3g} MB with a margin): "
            + (
                "the run stopped with every row written so far intact; free some space or "
                "write elsewhere, and continue with --resume if it wrote checkpoints "
                "(--checkpoint-every)"
                if started
                else "nothing was written; free some space or write elsewhere"
            )
        )


def _open_for_write(path: Path) -> h5py.File:
    # File locking off: the lock file keeps writers apart, and a reader that holds the file
    # open (xarray keeps it) must not stop the run.
    return h5py.File(path, "r+", locking=False)


class RunWriter:
    """Appends samples and frames of one world to a run file.

    Args:
        path: output file (claimed with ``claim`` first; an existing file is replaced).
        scene: the world's Scene.
        attrs: extra root attributes (arch, precision, dt ...).
        resume: continue the file at ``path`` instead: its series and frames are cut to
            ``resume`` = ``(samples, frames)`` rows and it is marked running again.
        run_id: with ``resume``, the ``run_id`` the checkpoint recorded for this file (None:
            a checkpoint written before run ids, not checked). A file of another run, or one
            with fewer rows than the checkpoint counts, is refused before anything changes.
        contacts: write the ``/contacts`` group (``add_frame(..., contacts=rows)``); on
            ``resume`` the file must have it exactly when asked.

    Every new file gets a ``run_id`` attribute (random, 32 hex digits) that its checkpoints
    record, so that a resume never continues one run from another's checkpoint.
    """

    def __init__(
        self,
        path: str | Path,
        scene,
        attrs: Mapping[str, object],
        resume: tuple[int, int] | None = None,
        run_id: str | None = None,
        contacts: bool = False,
    ):
        self.path = Path(path)
        self.contacts: dict[str, list] | None = None
        if contacts:
            self.contacts = {k: [] for k in VARIABLES["contacts"] if k != "contact"}
        self.n_rows = 0  # contact rows written
        self.series: dict[str, list] = {k: [] for k in ("time", "probe_force", "n_contacts")}
        self.series.update({k: [] for k in budget.SERIES})
        self.frames: dict[str, list] = {
            k: [] for k in ("time", "position", "angle", "velocity", "omega")
        }
        self._buffered = 0
        if resume is not None:
            self.n_samples, self.n_frames = resume
            with _open_for_write(self.path) as f:
                check_run_file(f, self.path)
                check_checkpoint_match(
                    f, self.path, run_id, self.n_samples, self.n_frames, contacts=contacts
                )
                self.run_id = str(f.attrs.get("run_id", ""))
                for ds in f["series"].values():
                    ds.resize(self.n_samples, axis=0)
                for ds in f["frames"].values():
                    ds.resize(self.n_frames, axis=0)
                if contacts:
                    self.n_rows = cut(f["contacts"], self.n_frames)
                f.attrs["status"] = "running"
                f.attrs["failure"] = ""
                f.attrs["resumed"] = int(f.attrs.get("resumed", 0)) + 1
                for key, value in attrs.items():
                    if key not in ("started",):
                        f.attrs[key] = value
            return
        self.n_samples = self.n_frames = 0
        # Checked before the old file goes (counting the room it frees), so that a full disk
        # refuses the run with the old file still there.
        old = self.path.stat().st_size if self.path.is_file() else 0
        check_room(self.path, -old, "a new run file", started=False)
        with contextlib.suppress(FileNotFoundError):
            # Unlink, not truncate: a reader that holds the old file keeps it whole.
            self.path.unlink()
        self.run_id = uuid.uuid4().hex
        with h5py.File(self.path, "w", track_order=True) as f:
            self._create(f, scene, attrs)
            f.attrs["run_id"] = self.run_id

    def _create(self, f: h5py.File, scene, attrs: Mapping[str, object]) -> None:
        n, p = scene.n_bodies, len(scene.probe_indices)
        law = scene.friction
        f.attrs["Conventions"] = CONVENTIONS
        f.attrs["title"] = f"taichi-ice run of {scene.source}"
        f.attrs["format_version"] = FORMAT_VERSION
        for key, value in provenance.run_attributes().items():
            f.attrs[key] = value
        f.attrs["scenario"] = scene.text
        f.attrs["source"] = str(scene.source)
        f.attrs["friction"] = law.name
        f.attrs["friction_params"] = json.dumps(law.to_dict())
        f.attrs["seed"] = scene.simulation.seed
        for key, value in attrs.items():
            f.attrs[key] = value
        for key, value in _PLACEHOLDERS.items():
            f.attrs[key] = value

        scales = {
            "body": np.arange(n, dtype=np.int64),
            "probe": np.asarray(scene.probe_indices, dtype=np.int64),
            "xy": np.array(["x", "y"], dtype=h5py.string_dtype()),
            "vertex": np.arange(len(scene.vertices_flat), dtype=np.int64),
            "body_edge": np.arange(n + 1, dtype=np.int64),
            "outline_node": np.arange(len(scene.vertices_flat) + n, dtype=np.int64),
        }
        for name, values in scales.items():
            ds = f.create_dataset(name, data=values)
            ds.make_scale(name)
            _describe(ds, "", name)

        b = f.create_group("bodies", track_order=True)
        b["names"] = np.array(scene.names, dtype=h5py.string_dtype())
        b["kinds"] = np.array([body.kind for body in scene.bodies], dtype=h5py.string_dtype())
        b["vertices"] = np.asarray(scene.vertices_flat, dtype=np.float64).reshape(-1, 2)
        b["vertex_offsets"] = scene.vertex_offsets
        b["mass"] = scene.masses
        b["inertia"] = scene.inertias
        b["probe_index"] = np.asarray(scene.probe_indices, dtype=np.int64)
        _geometry(b, scene)
        for name, ds in b.items():
            _describe(ds, "bodies", name)
            _attach(f, ds, DIMS["bodies"][name])
        for name in _GEOMETRY_OF:
            b[name].attrs["geometry"] = GEOMETRY

        shapes = {
            "series": {
                "time": ((), np.float64),
                "probe_force": ((p, 2), np.float64),
                "n_contacts": ((), np.int64),
                **{k: ((), np.float64) for k in budget.SERIES},
            },
            "frames": {
                "time": ((), np.float64),
                "position": ((n, 2), np.float64),
                "angle": ((n,), np.float64),
                "velocity": ((n, 2), np.float64),
                "omega": ((n,), np.float64),
            },
        }
        for group, variables in shapes.items():
            g = f.create_group(group, track_order=True)
            time = _growing(g, "time", (), np.float64)
            time.make_scale("time")
            _describe(time, group, "time")
            for name, (shape, dtype) in variables.items():
                if name == "time":
                    continue
                ds = _growing(g, name, shape, dtype)
                _describe(ds, group, name)
                ds.dims[0].attach_scale(time)
                _attach(f, ds, DIMS.get(group, {}).get(name, ("time",)), skip=1)
        if self.contacts is not None:
            create(f)

    def add_sample(self, time: float, probe_force, energies, n_contacts: int) -> None:
        """One time-series row: probe_force (P, 2) N, energies in budget.SERIES order (J)."""
        row = {"time": time, "probe_force": probe_force, "n_contacts": n_contacts}
        row.update(zip(budget.SERIES, energies))
        for name, value in row.items():
            self.series[name].append(np.asarray(value))

    def add_frame(self, time: float, position, angle, velocity, omega, contacts=None) -> None:
        """One frame of every body's state, and with ``contacts`` (the writer's option) its
        contact rows: ``{name: array}`` of ``engine.contact_rows.ROW_NAMES``."""
        if self.contacts is not None:
            if contacts is None:
                raise ValueError(f"{self.path}: a frame of a run with /contacts needs its rows")
            self.contacts["time"].append(np.float64(time))
            self.contacts["row_size"].append(np.int64(len(contacts["body_a"])))
            for name, values in contacts.items():
                self.contacts[name].append(np.asarray(values))
                self._buffered += self.contacts[name][-1].nbytes
        row = {
            "time": time,
            "position": position,
            "angle": angle,
            "velocity": velocity,
            "omega": omega,
        }
        for name, value in row.items():
            self.frames[name].append(np.array(value, dtype=np.float64))
            self._buffered += self.frames[name][-1].nbytes

    @property
    def buffered_bytes(self) -> int:
        """Bytes of the frames kept in memory, not yet written (samples are a few % of it)."""
        return self._buffered

    def _needed(self) -> int:
        """Bytes the next write may take: the rows kept, twice (chunks, copies)."""
        series = sum(np.asarray(v[0]).nbytes * len(v) for v in self.series.values() if v)
        return 2 * (self._buffered + series)

    def flush(self, steps: int, **attrs) -> None:
        """Write the rows kept so far, and ``steps`` and ``attrs``, in one open of the file.

        Raises:
            DiskFullError: the disk has no room for them (``check_room``); nothing is
                written, and the rows stay kept.
        """
        check_room(self.path, self._needed())
        with _open_for_write(self.path) as f:
            self._write(f, steps, attrs)

    def _write(self, f: h5py.File, steps: int, attrs: Mapping[str, object]) -> None:
        for group, rows, count in (
            ("series", self.series, "n_samples"),
            ("frames", self.frames, "n_frames"),
        ):
            k = len(rows["time"])
            if not k:
                continue
            start = getattr(self, count)
            for name, values in rows.items():
                ds = f[group][name]
                ds.resize(start + k, axis=0)
                ds[start : start + k] = np.stack(values)
                values.clear()
            setattr(self, count, start + k)
        if self.contacts is not None and self.contacts["time"]:
            self.n_rows = append(f["contacts"], self.contacts, self.n_rows)
        self._buffered = 0
        f.attrs["steps"] = steps
        for key, value in attrs.items():
            f.attrs[key] = value

    def close(self, status: str, failure: str = "", **attrs) -> None:
        """Write what is left and mark the run ``complete`` or ``failed`` (with the reason).

        On a disk with no room for the rows kept (``check_room``) they are dropped, the run is
        marked ``failed`` with the reason, and the file keeps every row written before; a run
        that was to be marked ``complete`` then raises the DiskFullError once marked."""
        full = None
        try:
            check_room(self.path, self._needed(), "writing the last rows")
        except DiskFullError as exc:
            full = exc if status == "complete" else None
            kept = (self.contacts or {}).values()
            for rows in (*self.series.values(), *self.frames.values(), *kept):
                rows.clear()
            self._buffered = 0
            if "the disk is full" not in failure:
                failure = f"{failure}; {exc}" if failure else str(exc)
            status = "failed"
            attrs.pop("steps", None)  # the steps of the rows written
        with _open_for_write(self.path) as f:
            self._write(
                f,
                int(attrs.pop("steps", f.attrs.get("steps", 0))),
                {"status": status, "failure": failure, "finished": provenance.now(), **attrs},
            )
        if full is not None:
            raise full


def _geometry(b: h5py.Group, scene) -> None:
    """The floes at time 0 as a CF-1.8 polygon geometry (container, node count, nodes)."""
    from .export import floe_polygons

    offsets = np.asarray(scene.vertex_offsets, dtype=np.int64)
    vertices = np.asarray(scene.vertices_flat, dtype=np.float64).reshape(-1, 2)
    nodes = floe_polygons(vertices, offsets, scene.positions, scene.angles)
    b[GEOMETRY] = np.int32(0)  # a container of attributes; its value means nothing
    b[GEOMETRY].attrs.update(_GEOMETRY_ATTRS)
    # Each ring closed: its first node again after its last (CF allows the two to coincide;
    # GDAL's reader closes no ring itself).
    closed = np.insert(np.arange(len(nodes)), offsets[1:], offsets[:-1])
    nodes = nodes[closed]
    b["floe_outline_node_count"] = np.diff(offsets) + 1
    for axis, name in enumerate(("floe_outline_x", "floe_outline_y")):
        b[name] = nodes[:, axis]
        b[name].attrs["axis"] = "XY"[axis]


def _describe(ds, group: str, name: str) -> None:
    units, long_name = VARIABLES.get(group, {}).get(name, ("", name.replace("_", " ")))
    if units:
        ds.attrs["units"] = units
    ds.attrs["long_name"] = long_name


def _attach(f: h5py.File, ds, dims: tuple[str, ...], skip: int = 0) -> None:
    """Attach the root dimension scales ``dims`` to ``ds``'s axes (from axis ``skip``)."""
    for axis, name in enumerate(dims):
        if axis >= skip:
            ds.dims[axis].attach_scale(f[name])


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
