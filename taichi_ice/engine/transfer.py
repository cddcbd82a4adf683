"""Every field of a World to or from NumPy in one kernel launch: ``Transfer``.

    transfer = Transfer({"body_pos": data.body_pos, ...})
    arrays = transfer.read()           # {name: array}, as field.to_numpy() gives each
    transfer.write(arrays)             # as field.from_numpy(array) for each

Taichi's ``field.from_numpy``, ``to_numpy`` and ``fill`` compile a kernel of their own for
each field they touch (the field is the kernel's template argument), and a World has ~80
fields: on a new set of fields (a new World, ``engines.Engines``) the per-field kernels were
more of the compile time than the step's kernels (the test suite from an empty Taichi cache on
2 cores: ~10,500 of them, 670 s of its 1,470 s of compiling, against 555 s for its 108
thread-per-world steppers). ``Transfer`` copies every field of a set in one kernel, to or
from one flat buffer per element type, a loop per distinct shape that copies element i of
every field of that shape (each loop is a task, and each task costs ~30 ms of compiling):
measured on 2 cores, 54 fields of every type and shape took 1.0-1.1 s to compile and run each
way, against 3.7-4.0 s field by field with ``from_numpy`` or ``to_numpy``. The values are
copied, not converted: each buffer holds its fields' own type, so a write then a read gives
back the arrays bit for bit (``tests/test_transfer.py`` holds the kernels against
``from_numpy``/``to_numpy`` on seeded random fields of every type).

Engine-level: it knows Taichi fields and NumPy arrays, nothing of what the fields mean.
"""

# No ``from __future__ import annotations``: Taichi reads its functions' annotations.
import warnings

import numpy as np
import taichi as ti

__all__ = ["Transfer"]

# The element types a field may have, and the buffer (kernel argument) that carries each.
_KINDS = (
    (ti.f64, np.float64),
    (ti.f32, np.float32),
    (ti.i32, np.int32),
    (ti.i64, np.int64),
)


def _kind(dtype) -> int:
    for k, (t, _) in enumerate(_KINDS):
        if dtype == t:
            return k
    raise TypeError(f"Transfer: fields of type {dtype} are not supported (f64, f32, i32, i64)")


def _launch(kernel, buffers) -> None:
    """Run a transfer kernel. Its first call compiles it, unrolling a loop over the fields
    (Python's, at compile time: ``ti.static``), of which Taichi warns past 32 turns: the
    turns are the fields, each a few statements, not a long unrolled computation."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*unrolling more than", category=SyntaxWarning)
        kernel(*buffers)


class _Slot:
    """Where one field lives in its kind's flat buffer."""

    __slots__ = ("field", "kind", "lanes", "name", "offset", "shape", "size")

    def __init__(self, name: str, field, offset: int):
        self.name = name
        self.field = field
        self.shape = tuple(int(n) for n in field.shape)
        self.lanes = int(field.n) if isinstance(field, ti.MatrixField) else 0
        if self.lanes and int(field.m) != 1:
            raise TypeError(f"Transfer: {name} is a matrix field; only vectors are supported")
        if len(self.shape) > 2:
            raise TypeError(f"Transfer: {name} has {len(self.shape)} axes; at most 2")
        self.kind = _kind(field.dtype)
        self.offset = offset
        self.size = int(np.prod(self.array_shape, dtype=np.int64))

    @property
    def array_shape(self) -> tuple[int, ...]:
        """The shape ``field.to_numpy()`` gives: the field's, then its lanes."""
        return self.shape + ((self.lanes,) if self.lanes else ())


class Transfer:
    """Read or write a fixed set of Taichi fields in one kernel launch each way.

    Args:
        fields: ``{name: field}``: scalar or vector fields (``ti.field``, ``ti.Vector.field``)
            of type f64, f32, i32 or i64, of any shape (0-d included).

    The two kernels close over the fields and are compiled at their first call, once for the
    life of the fields. ``write`` takes every field's array at its ``to_numpy`` shape; the
    values are cast to the field's type with NumPy (``np.asarray(..., dtype)``), as
    ``from_numpy`` does.
    """

    def __init__(self, fields: dict):
        offsets = [0] * len(_KINDS)
        self._slots: list[_Slot] = []
        for name, field in fields.items():
            kind = _kind(field.dtype)
            slot = _Slot(name, field, offsets[kind])
            offsets[kind] += slot.size
            self._slots.append(slot)
        if max(offsets) >= 2**31:
            raise ValueError("Transfer: more than 2^31 elements of one type in one set of fields")
        # A buffer of no field still needs one element to be an argument.
        self._sizes = [max(n, 1) for n in offsets]
        self._read = None
        self._write = None

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self._slots)

    def shapes(self) -> dict[str, tuple[int, ...]]:
        """``{name: shape}`` of the arrays ``read`` gives and ``write`` takes."""
        return {s.name: s.array_shape for s in self._slots}

    def read(self) -> dict[str, np.ndarray]:
        """Every field's values, ``{name: array}``: what ``field.to_numpy()`` gives."""
        if self._read is None:
            self._read = self._kernel(to_fields=False)
        buffers = [np.zeros(n, dtype=np_type) for n, (_, np_type) in zip(self._sizes, _KINDS)]
        _launch(self._read, buffers)
        return {
            s.name: buffers[s.kind][s.offset : s.offset + s.size].reshape(s.array_shape).copy()
            for s in self._slots
        }

    def write(self, arrays: dict) -> None:
        """Every field set from ``arrays`` (``{name: array}`` of each field's ``to_numpy``
        shape), as ``field.from_numpy`` sets each.

        Raises:
            ValueError: a field's array is missing, or of another shape.
        """
        missing = [s.name for s in self._slots if s.name not in arrays]
        if missing:
            raise ValueError(f"Transfer.write: no array for {missing}")
        buffers = [np.zeros(n, dtype=np_type) for n, (_, np_type) in zip(self._sizes, _KINDS)]
        for s in self._slots:
            array = np.asarray(arrays[s.name], dtype=_KINDS[s.kind][1])
            if array.shape != s.array_shape:
                raise ValueError(
                    f"Transfer.write: {s.name} has shape {array.shape}, its field {s.array_shape}"
                )
            buffers[s.kind][s.offset : s.offset + s.size] = array.reshape(-1)
        if self._write is None:
            self._write = self._kernel(to_fields=True)
        _launch(self._write, buffers)

    def _kernel(self, to_fields: bool):
        """The kernel that copies every slot between its field and its kind's buffer, a
        loop per shape (row-major, lanes last: ``to_numpy``'s order)."""
        slots = self._slots
        n = len(slots)
        fields = [s.field for s in slots]
        shapes = [s.shape for s in slots]
        lanes = [s.lanes for s in slots]
        kinds = [s.kind for s in slots]
        offsets = [s.offset for s in slots]
        steps = [max(s.lanes, 1) for s in slots]
        sizes = [int(np.prod(s.shape, dtype=np.int64)) for s in slots]
        buffer = ti.types.ndarray(ndim=1)

        @ti.func
        def unravel(i, k: ti.template()):
            """The index of element i (row-major) of slot k's field: one or two axes."""
            if ti.static(len(shapes[k]) == 1):
                return i
            else:
                return ti.Vector([i // shapes[k][1], i % shapes[k][1]])

        # One loop per shape, copying element i of every field of that shape: a task per
        # shape, not per field (each task costs ~30 ms of compiling).
        groups: dict = {}
        for k in range(n):
            groups.setdefault(shapes[k], []).append(k)
        group_list = list(groups.values())
        group_shapes = list(groups)

        @ti.kernel
        def run(b0: buffer, b1: buffer, b2: buffer, b3: buffer):
            for g in ti.static(range(len(group_list))):
                if ti.static(len(group_shapes[g]) == 0):
                    for k in ti.static(group_list[g]):
                        b = ti.static((b0, b1, b2, b3)[kinds[k]])
                        for lane in ti.static(range(steps[k])):
                            if ti.static(lanes[k] == 0):
                                if ti.static(to_fields):
                                    fields[k][None] = b[offsets[k]]
                                else:
                                    b[offsets[k]] = fields[k][None]
                            elif ti.static(to_fields):
                                fields[k][None][lane] = b[offsets[k] + lane]
                            else:
                                b[offsets[k] + lane] = fields[k][None][lane]
                else:
                    for i in range(sizes[group_list[g][0]]):
                        for k in ti.static(group_list[g]):
                            b = ti.static((b0, b1, b2, b3)[kinds[k]])
                            I = unravel(i, k)
                            at = offsets[k] + i * steps[k]
                            if ti.static(lanes[k] == 0):
                                if ti.static(to_fields):
                                    fields[k][I] = b[at]
                                else:
                                    b[at] = fields[k][I]
                            else:
                                for lane in ti.static(range(lanes[k])):
                                    if ti.static(to_fields):
                                        fields[k][I][lane] = b[at + lane]
                                    else:
                                        b[at + lane] = fields[k][I][lane]

        return run
