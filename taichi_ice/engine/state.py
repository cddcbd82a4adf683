"""Data-oriented state of many independent worlds: Taichi fields, structure of arrays.

One set of fields holds every body of every world of a batch; a single scene is the batch of
one. Bodies are stored world by world (``world_body_start``), so an ensemble of small scenes
fills a GPU exactly as one large scene does, and the broad phase never pairs bodies of
different worlds.

Every field is declared once, in ``taichi_ice.engine.schema`` (name, type, shape, unit, meaning;
``docs/state.md`` is its table); this module only turns those declarations into Taichi fields
(``Model``: static after set-up; ``Data``: mutable; ``Fields`` for a stage's scratch) and
lists what each holds before the first step (``start_arrays``).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import taichi as ti

from .. import backend
from . import schema
from .schema import HostArrays, Layout, Var

# The fixed-point force sums: float64 holding whole quanta where the device's integer
# atomics fail inside loops (``backend.float_gather``), else 64-bit integers.
GATHERED = ("body_force_q", "body_torque_q", "body_shift_q", "body_turn_q")


def quantum_dtype():
    """The Taichi type of the fixed-point force sums (``GATHERED``) on this device."""
    return ti.f64 if backend.float_gather() else ti.i64


def ti_dtype(v: Var, layout: Layout):
    """The Taichi element type of a declared field in this layout's precision."""
    if v.name in GATHERED:
        return quantum_dtype()
    return backend.taichi_dtype(layout.precision if v.dtype == "real" else v.dtype)


def make_field(v: Var, layout: Layout):
    """One Taichi field as declared (a switched-off or empty field gets one element); its
    ``init`` value is written with every other field's start (``start_arrays``)."""
    shape = schema.allocated_shape(layout, v)
    dtype = ti_dtype(v, layout)
    if v.lanes > 1:
        return ti.Vector.field(v.lanes, dtype, shape=shape)
    return ti.field(dtype, shape=shape)


def _scalar_bytes(v: Var, layout: Layout) -> int:
    return 8 if ti_dtype(v, layout) in (ti.f64, ti.i64) else 4


# The width (bytes) of the fields waiting in Taichi's open tree, on SPIR-V (``Fields``).
_open_width: int | None = None


def _join_tree(width: int) -> None:
    """Before a field of ``width`` bytes on SPIR-V: put the fields declared since the last
    tree in a tree of their own if they have the other width (what Taichi does at the next
    kernel launch), so that no tree mixes 32-bit and 64-bit fields."""
    global _open_width
    from taichi.lang import impl

    if impl._root_fb.empty:  # a launch closed the last tree
        _open_width = None
    if _open_width is not None and _open_width != width:
        impl.get_runtime().materialize()
    _open_width = width


class Fields:
    """A group of declared fields as attributes (``fields.body_pos``).

    Declared only: nothing is launched here. Taichi places the fields declared since its
    last kernel launch in one tree of memory, and a process holds at most 512 trees (Taichi's
    LLVM backends): filled as declared, a World took 5 trees, and a process (the test suite)
    could build no more than ~100 Worlds. The fields get their values, ``init`` or the
    scenes', all at once in the World's first launch (``World._start``: ``start_arrays``
    through ``transfer.Transfer``), so a World's groups share one tree. (Filling the four
    fields whose ``init`` is not 0 here, as before, compiled Taichi's fill kernel once per
    field and World, ~60 ms each on 2 cores, for values the first launch wrote again.)
    """

    def __init__(self, layout: Layout, decls: Iterable[Var]):
        self.layout = layout
        decls = tuple(decls)
        self.names = tuple(v.name for v in decls)
        # Taichi 1.7's SPIR-V backend (Vulkan, Metal) lays out a tree of fields wrongly
        # when a 32-bit field's size is not a multiple of 8 bytes in a tree that holds
        # 64-bit fields: the two overlap (measured on Mesa's lavapipe: [i64 (2,), f32 (3,)]
        # and [f32 (3,), f64 (2,)] each lose values to the other, [i64 (2,), f32 (2,)] and
        # [i64 (2,), i32 (), f32 ()] do not). In a World 4 of 33 fields lost values: a
        # contact was missed for a step, and pushed_field never met its pusher. So the
        # 64-bit fields come first, and a 32-bit field of an odd number of elements is
        # followed by a 4-byte pad. That was not enough: a 3-body World in float32 still
        # lost 4 fields (body_pos, body_vel, probe_impulse, nbr_ref_angle) on lavapipe. So
        # there no tree holds fields of both widths (``_join_tree``): a World's fields take
        # 6-7 trees instead of 1. The CPU and CUDA compute the same either way.
        self._pads = []
        split = backend.actual_arch() in backend.SPIRV_ARCHES
        for v in sorted(decls, key=lambda v: -_scalar_bytes(v, layout)):
            if split:
                _join_tree(_scalar_bytes(v, layout))
            field = make_field(v, layout)
            setattr(self, v.name, field)
            size = int(np.prod(schema.allocated_shape(layout, v), dtype=np.int64)) * v.lanes
            if _scalar_bytes(v, layout) == 4 and size % 2:
                self._pads.append(ti.field(ti.i32, shape=()))


class Model(Fields):
    """Static per-body and per-world data of a batch (``schema.groups()["model"]``)."""

    def __init__(self, layout: Layout):
        super().__init__(layout, schema.groups()["model"])


class Data(Fields):
    """Mutable state of a batch (``schema.groups()["data"]``)."""

    def __init__(self, layout: Layout):
        super().__init__(layout, schema.groups()["data"])


def padded(array: np.ndarray, v: Var, layout: Layout) -> np.ndarray:
    """An assembled array of the scenes' counts, padded to the field's capacity: with zeros,
    and a ``world_edges`` array with its last value (the worlds past the scenes' are empty)."""
    shape = schema.allocated_shape(layout, v) + ((v.lanes,) if v.lanes > 1 else ())
    if array.shape == shape:
        return array
    if array.ndim != len(shape) or any(a > b for a, b in zip(array.shape, shape)):
        raise ValueError(f"host array {v.name}: shape {array.shape} exceeds its field's {shape}")
    widths = [(0, b - a) for a, b in zip(array.shape, shape)]
    if v.shape and v.shape[0] == "world_edges":
        return np.pad(array, widths, mode="edge")
    return np.pad(array, widths)


def start_arrays(layout: Layout, host: HostArrays) -> dict[str, np.ndarray]:
    """What every declared field (``schema.groups()``) holds before the first step, by name:
    the assembled array of a ``HOST`` field, cast to the field's type and padded to its
    capacity (``padded``); the declared ``init`` value everywhere else (and in a switched-off
    ``HOST`` field, which no kernel reads). ``transfer.Transfer.write`` puts them in at once."""
    out = {}
    for group in schema.groups().values():
        for v in group:
            shape = schema.allocated_shape(layout, v) + ((v.lanes,) if v.lanes > 1 else ())
            if v.init == schema.HOST and layout.exists(v):
                array = np.asarray(host[v.name], dtype=v.np_dtype(layout.precision))
                out[v.name] = array if not v.shape else padded(array, v, layout)
            else:
                out[v.name] = np.full(shape, 0 if v.init == schema.HOST else v.init)
    return out


__all__ = ["Data", "Fields", "Model", "make_field", "padded", "start_arrays", "ti_dtype"]
