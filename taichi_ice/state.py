"""Data-oriented state of many independent worlds: Taichi fields, structure of arrays.

One set of fields holds every body of every world of a batch; a single scene is the batch of
one. Bodies are stored world by world (``world_body_start``), so an ensemble of small scenes
fills a GPU exactly as one large scene does, and the broad phase never pairs bodies of
different worlds.

Every field is declared once, in ``taichi_ice.schema`` (name, type, shape, unit, meaning;
``docs/state.md`` is its table); this module only turns those declarations into Taichi fields
(``Model``: static after set-up; ``Data``: mutable; ``Fields`` for a stage's scratch) and
copies the assembled NumPy arrays in (``upload``).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import taichi as ti

from . import schema
from .schema import HostArrays, Layout, Var

# Contact and body forces are gathered in 64-bit fixed point of this resolution (N, N m):
# integer addition is associative, so a body's total force does not depend on the order in
# which threads add to it and every run is bit-for-bit reproducible, alone or in a batch.
# 2^-24 N = 6e-8 N, with headroom to 2^39 N = 5e11 N.
FORCE_QUANTUM = 2.0**-24

_TI_DTYPES = {"f64": ti.f64, "f32": ti.f32, "i32": ti.i32, "i64": ti.i64}


def ti_dtype(v: Var, layout: Layout):
    """The Taichi element type of a declared field in this layout's precision."""
    return _TI_DTYPES[layout.precision if v.dtype == "real" else v.dtype]


def make_field(v: Var, layout: Layout):
    """One Taichi field as declared (a switched-off or empty field gets one element), not
    yet filled with its ``init`` value (``Fields`` fills a group once it is declared)."""
    shape = schema.allocated_shape(layout, v)
    dtype = ti_dtype(v, layout)
    if v.lanes > 1:
        return ti.Vector.field(v.lanes, dtype, shape=shape)
    return ti.field(dtype, shape=shape)


class Fields:
    """A group of declared fields as attributes (``fields.body_pos``).

    Every field is declared before any is filled: Taichi places the fields declared since
    its last kernel launch in one tree of memory, a fill is a launch, and a process holds at
    most 512 trees (Taichi's LLVM backends). Filled as declared, a World took 5 trees, and a
    process (the test suite) could build no more than ~100 Worlds; filled afterwards, 2.
    """

    def __init__(self, layout: Layout, decls: Iterable[Var]):
        self.layout = layout
        self.names = tuple(v.name for v in decls)
        for v in decls:
            setattr(self, v.name, make_field(v, layout))
        for v in decls:
            if v.init not in (0, schema.HOST):
                getattr(self, v.name).fill(v.init)


class Model(Fields):
    """Static per-body and per-world data of a batch (``schema.groups()["model"]``)."""

    def __init__(self, layout: Layout):
        super().__init__(layout, schema.groups()["model"])


class Data(Fields):
    """Mutable state of a batch (``schema.groups()["data"]``)."""

    def __init__(self, layout: Layout):
        super().__init__(layout, schema.groups()["data"])


def upload(model: Model, data: Data, host: HostArrays) -> None:
    """Copy every assembled array into its field, cast to the field's type."""
    layout = model.layout
    for v in schema.host_vars():
        if not layout.exists(v):
            continue
        group = model if hasattr(model, v.name) else data
        array = np.ascontiguousarray(host[v.name], dtype=v.np_dtype(layout.precision))
        if array.size:
            getattr(group, v.name).from_numpy(array)


__all__ = ["FORCE_QUANTUM", "Data", "Fields", "Model", "make_field", "ti_dtype", "upload"]
