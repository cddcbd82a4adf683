"""Time integration: semi-implicit (symplectic) Euler for dynamic bodies.

    v(t+dt) = v(t) + dt F(x(t), v(t)) / m,     x(t+dt) = x(t) + dt v(t+dt)

and likewise for the angle. Fixed bodies never move; kinematic bodies move at their own
velocity and do work on whatever they push. Work and dissipation of the step are evaluated
with the mid-step velocity, which is the exact power of a force held constant over the step,
so kinetic energy and work agree to round-off and the energy residual measures only the
time discretisation of the contact forces.

The stage also reads the contact forces gathered in fixed point, clears them for the next
step, accumulates probe impulses, and raises the non-finite and runaway flags.
"""

from __future__ import annotations

import taichi as ti

from .drag import water_drag
from .state import (
    BODY_DRAG,
    BODY_WORK,
    FORCE_QUANTUM,
    KIND_DYNAMIC,
    KIND_KINEMATIC,
    STATUS_NONFINITE,
    STATUS_RUNAWAY,
    Data,
    Layout,
    Model,
)


@ti.data_oriented
class Integrator:
    """Advances every body by one step."""

    def __init__(self, layout: Layout, model: Model, data: Data, runaway_speed: float):
        """
        Args:
            runaway_speed: a dynamic body faster than this (m/s) flags the run as divergent.
        """
        self.layout, self.model, self.data = layout, model, data
        self.runaway_speed = float(runaway_speed)

    @ti.kernel
    def advance(self):
        m, d = ti.static((self.model, self.data))
        dt = d.time_step[None]
        for i in range(self.layout.n_bodies):
            f = ti.cast(d.body_force_q[i], self.layout.real) * FORCE_QUANTUM
            tau = ti.cast(d.body_torque_q[i], self.layout.real) * FORCE_QUANTUM
            d.body_force_q[i] = ti.Vector([0, 0], ti.i64)
            d.body_torque_q[i] = 0
            p = m.body_probe[i]
            if p >= 0:
                d.probe_impulse[p, 0] += ti.cast(f[0] * dt, ti.f64)
                d.probe_impulse[p, 1] += ti.cast(f[1] * dt, ti.f64)
            kind = m.body_kind[i]
            if kind == KIND_DYNAMIC:
                v0, w0 = d.body_vel[i], d.body_omega[i]
                f_ext = m.body_force_ext[i]
                f_drag = ti.Vector([0.0, 0.0], self.layout.real)
                t_drag = ti.cast(0.0, self.layout.real)
                if ti.static(self.layout.water):
                    f_drag, t_drag = water_drag(v0, w0, m.body_drag[i, 0], m.body_drag[i, 1])
                v1 = v0 + dt * m.body_inv_mass[i] * (f + f_ext + f_drag)
                w1 = w0 + dt * m.body_inv_inertia[i] * (tau + t_drag)
                vm, wm = 0.5 * (v0 + v1), 0.5 * (w0 + w1)
                d.body_energy[i, BODY_DRAG] += ti.cast(-(f_drag.dot(vm) + t_drag * wm) * dt, ti.f64)
                d.body_energy[i, BODY_WORK] += ti.cast(f_ext.dot(vm) * dt, ti.f64)
                d.body_vel[i] = v1
                d.body_omega[i] = w1
                d.body_pos[i] += dt * v1
                d.body_angle[i] += dt * w1
                speed2 = v1.norm_sqr()
                if not (speed2 < ti.math.inf and ti.abs(w1) < ti.math.inf):
                    d.status[STATUS_NONFINITE] = 1
                elif speed2 > self.runaway_speed * self.runaway_speed:
                    d.status[STATUS_RUNAWAY] = 1
            elif kind == KIND_KINEMATIC:
                # The contact force f acts on the pusher; the pusher does -f.v on the rest.
                v, w = d.body_vel[i], d.body_omega[i]
                d.body_energy[i, BODY_WORK] += ti.cast(-(f.dot(v) + tau * w) * dt, ti.f64)
                d.body_pos[i] += dt * v
                d.body_angle[i] += dt * w
