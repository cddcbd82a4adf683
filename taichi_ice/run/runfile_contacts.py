"""The ``/contacts`` group of a run file: every contact at every frame, when asked.

Layout (``CONTACT_VARIABLES``, units and long names; ``runfile`` takes them): the rows of every
frame one after the other on the dimension ``contact``, a CF-1.8 *contiguous ragged array*
(CF conventions section 9.3.3 and appendix H.2.4): ``row_size`` on the group's ``time`` (one
entry per frame, the frame's time) counts each frame's rows and names the dimension it
counts along (``sample_dimension = "contact"``), so frame ``f``'s rows are
``sum(row_size[:f])`` up to ``sum(row_size[:f + 1])``. The rows (``engine.contact_rows``):

========================= ========== =====================================================
variable                  unit       meaning
========================= ========== =====================================================
``body_a``, ``body_b``    index      the pair, once: ``body_a`` owns the contact
``point`` (contact, xy)   m          the overlap's centroid, in the world
``normal`` (contact, xy)  1          unit normal from ``body_a`` into ``body_b``
``width``                 m          the chord between the outlines' crossings
``overlap``               m^2        the overlap's area (an area, not a depth)
``force_normal``          N          on ``body_b`` along ``normal`` (``body_a``: minus it)
``force_tangential``      N          on ``body_b`` along ``(-normal_y, normal_x)``
``slip_rate``             m/s        the rate the surfaces slide at, signed; 0 while stuck
``theta``                 1          rate-and-state theta after the step; NaN if none
``mu``                    1          the friction coefficient of the step
``stuck``                 flag       1 stuck (``|F_t| < mu F_n``), 0 sliding (at the cap)
========================= ========== =====================================================

A frame's rows are the contacts of the step that starts at the frame's time: their forces
act over ``(t, t + dt]``. ``contact`` holds each row's index (a coordinate, so that netCDF
readers name the dimension); ``xarray.open_dataset(path, group="contacts")`` reads it.
Where a sliding rate-and-state contact takes its step in sub-steps (``[ice]
slide_resolution``), its force and ``mu`` are the step's means over them, and ``slip_rate``,
``theta`` and ``stuck`` the state its last sub-step leaves: a sliding row is at the cap
``|F_t| = mu F_n`` if it slid through the whole step, below it where its slide started
within the step. With the midstep step (the run's ``integrator`` attribute; Coulomb
friction's default) a contact is taken at the pose predicted for mid-step, every body in free
flight for dt / 2 from the frame: ``point``, ``normal``, ``width`` and ``overlap`` are that
pose's (the frame's where the outlines no longer overlap then), and a row's torque on a body
is about the body's centroid there, ``position + dt / 2 velocity``.

Written with the frames, in the same open of the file (``RunWriter``): a reader sees as many
frames in ``/contacts`` as in ``/frames``.
"""

from __future__ import annotations

import h5py
import numpy as np

__all__ = ["CONTACT_DIMS", "CONTACT_VARIABLES", "PER_FRAME", "append", "create", "cut"]

# (units, long_name) of each variable of the group (``runfile.VARIABLES["contacts"]``).
CONTACT_VARIABLES: dict[str, tuple[str, str]] = {
    "time": ("s", "time of the frame whose contacts the rows are"),
    "row_size": ("1", "contacts of each frame: its rows follow those of the frames before"),
    "contact": ("1", "row index over every frame's contacts"),
    "body_a": ("1", "body index of the body that owns the contact; it takes minus the force"),
    "body_b": ("1", "body index of the other body, on which the force acts"),
    "point": ("m", "contact point: the centroid of the overlap of the two outlines"),
    "normal": ("1", "unit normal from body_a into body_b"),
    "width": ("m", "contact width: the chord between the crossings of the outlines"),
    "overlap": ("m2", "overlap area of the two outlines, crushed area included"),
    "force_normal": ("N", "normal force on body_b along normal over the step from the frame"),
    "force_tangential": ("N", "tangential force on body_b along (-normal_y, normal_x)"),
    "slip_rate": ("m s-1", "rate the surfaces slide at along the tangent, 0 while stuck"),
    "theta": ("1", "rate-and-state variable theta after the step; NaN if none"),
    "mu": ("1", "friction coefficient of the step"),
    "stuck": ("1", "1 if the contact sticks (tangential force below mu F_n), 0 if it slides"),
}
# Dimensions of each (``runfile.DIMS["contacts"]``): the rest are on contact alone.
CONTACT_DIMS: dict[str, tuple[str, ...]] = {
    "row_size": ("time",),
    "point": ("contact", "xy"),
    "normal": ("contact", "xy"),
}
# The variables on the group's time (one entry a frame); the rest are on contact.
PER_FRAME = ("time", "row_size")
# Rows of a chunk of a variable on contact: a frame of a large field holds thousands.
CONTACT_CHUNK = 4096
PER_FRAME_CHUNK = 64


def _dataset(g: h5py.Group, name: str, template: np.ndarray, chunk: int):
    """A variable of ``g`` that grows along its first axis, of ``template``'s row shape and
    type, with its units and long name (as ``runfile`` describes its variables)."""
    shape = template.shape[1:]
    ds = g.create_dataset(
        name,
        shape=(0, *shape),
        maxshape=(None, *shape),
        dtype=template.dtype,
        chunks=(chunk, *shape),
    )
    units, long_name = CONTACT_VARIABLES[name]
    ds.attrs["units"] = units
    ds.attrs["long_name"] = long_name
    return ds


def create(f: h5py.File) -> h5py.Group:
    """The empty ``/contacts`` group of run file ``f`` (whose root holds the scale ``xy``)."""
    from ..engine.contact_rows import empty_rows

    g = f.create_group("contacts", track_order=True)
    time = _dataset(g, "time", np.zeros(0), PER_FRAME_CHUNK)
    row = _dataset(g, "contact", np.zeros(0, dtype=np.int64), CONTACT_CHUNK)
    for scale in (time, row):
        scale.make_scale(scale.name.rsplit("/", 1)[-1])
    size = _dataset(g, "row_size", np.zeros(0, dtype=np.int64), PER_FRAME_CHUNK)
    size.attrs["sample_dimension"] = "contact"
    size.dims[0].attach_scale(time)
    for name, empty in empty_rows().items():
        ds = _dataset(g, name, empty, CONTACT_CHUNK)
        ds.dims[0].attach_scale(row)
        for axis, dim in enumerate(CONTACT_DIMS.get(name, ())[1:], start=1):
            ds.dims[axis].attach_scale(f[dim])
    g["stuck"].attrs["flag_values"] = np.array([0, 1], dtype=np.int8)
    g["stuck"].attrs["flag_meanings"] = "sliding stuck"
    return g


def append(g: h5py.Group, kept: dict[str, list], n_rows: int) -> int:
    """Append the frames ``kept`` (``{name: [one entry a frame]}``: ``time``, ``row_size`` and
    each frame's rows) to ``g``, which holds ``n_rows`` rows; empty ``kept``'s lists and
    return the rows ``g`` holds now."""
    frames = len(g["time"])
    n = int(np.sum(kept["row_size"]))
    for name, values in kept.items():
        per_frame = name in PER_FRAME
        start = frames if per_frame else n_rows
        data = np.stack(values) if per_frame else np.concatenate(values)
        ds = g[name]
        ds.resize(start + len(data), axis=0)
        if len(data):
            ds[start:] = data
        values.clear()
    g["contact"].resize(n_rows + n, axis=0)
    if n:
        g["contact"][n_rows:] = np.arange(n_rows, n_rows + n)
    return n_rows + n


def cut(g: h5py.Group, n_frames: int) -> int:
    """Cut ``g`` to its first ``n_frames`` frames (a resume); return the rows they hold."""
    n_rows = int(np.sum(g["row_size"][:n_frames]))
    for name, ds in g.items():
        ds.resize(n_frames if name in PER_FRAME else n_rows, axis=0)
    return n_rows
