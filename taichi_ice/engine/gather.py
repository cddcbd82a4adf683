"""The fixed-point gather of a step's contact forces (``state.GATHERED``): what makes a run
bit-for-bit the same on any number of threads and in any batch."""

# No "from __future__ import annotations": Taichi reads the annotations of its functions.

import taichi as ti

from .schema import FORCE_QUANTUM
from .state import quantum_dtype

__all__ = ["gather"]


@ti.func
def gather(sums: ti.template(), torques: ti.template(), i, force, torque, serial: ti.template()):
    """Add a force and its torque to body i's fixed-point sums (``GATHERED``): truncated to
    whole ``FORCE_QUANTUM`` as 64-bit integers, then held as the sums' type (the same
    integers in float64 where integer atomics fail, ``backend.float_gather``); atomically
    when bodies are stepped in parallel, plainly when a thread steps the whole world
    (``serial``). Integer sums are the same in any order either way."""
    q, qt = ti.static((1.0 / FORCE_QUANTUM, quantum_dtype()))
    fx = ti.cast(ti.cast(force[0] * q, ti.i64), qt)
    fy = ti.cast(ti.cast(force[1] * q, ti.i64), qt)
    tq = ti.cast(ti.cast(torque * q, ti.i64), qt)
    if ti.static(serial):
        sums[i] = sums[i] + ti.Vector([fx, fy], qt)
        torques[i] = torques[i] + tq
    else:
        ti.atomic_add(sums[i][0], fx)
        ti.atomic_add(sums[i][1], fy)
        ti.atomic_add(torques[i], tq)
