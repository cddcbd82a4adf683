"""Ocean current, wind and the Earth's rotation on a floe as Taichi functions: the twins of
``forcing`` (the laws, their coefficients and their references live there), in the same
order. The integrator's kernel calls them (``engine.forcing``, ``engine.integrate``).
"""

from __future__ import annotations

import taichi as ti


@ti.func
def air_drag_ti(vel, wind, c_air):
    """Taichi twin of :func:`forcing.air_drag` for one body (2-vectors)."""
    rel = wind - vel
    return c_air * rel.norm() * rel


@ti.func
def cross_k_ti(vec):
    """``k x vec``: ``(-y, x)``."""
    return ti.Vector([-vec[1], vec[0]])


@ti.func
def tilt_acceleration_ti(f, current):
    """Taichi twin of :func:`forcing.tilt_acceleration` (m/s^2)."""
    return f * cross_k_ti(current)


@ti.func
def coriolis_step_ti(v0, accel, f, dt):
    """Taichi twin of :func:`forcing.coriolis_step`: the velocity after a step with
    ``accel`` and Coriolis at the step's mean velocity (same operations, same order)."""
    b = 0.5 * f * dt
    w = v0 + dt * accel
    w = w + b * ti.Vector([v0[1], -v0[0]])
    return (w + b * ti.Vector([w[1], -w[0]])) / (1.0 + b * b)


@ti.func
def grid_cell_ti(s, n):
    """Taichi twin of :func:`forcing.grid_cell`: ``(i0, i1, w)`` at fractional index ``s``
    (f64) of an axis of ``n`` nodes."""
    s = ti.min(ti.max(s, 0.0), ti.cast(n, ti.f64) - 1.0)
    i0 = ti.min(ti.cast(ti.floor(s), ti.i32), ti.max(n - 2, 0))
    return i0, ti.min(i0 + 1, n - 1), s - ti.cast(i0, ti.f64)


@ti.func
def lerp_ti(a0, a1, w):
    """``a0 + w (a1 - a0)``: exactly ``a0`` where ``a1 == a0``."""
    return a0 + w * (a1 - a0)
