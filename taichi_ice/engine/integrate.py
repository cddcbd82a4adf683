"""Time integration of dynamic bodies: semi-implicit (symplectic) Euler (``integrator =
"euler"``, the default),

    v(t+dt) = v(t) + dt F(x(t), v(t)) / m,     x(t+dt) = x(t) + dt v(t+dt),

or the analytic step (``"analytic"``), whose contacts hand over their mean force over the
step F and their position impulse as a force G = 2 Q / dt^2 (``physics.contact_step``),

    v(t+dt) = v(t) + dt (F + F_other) / m,     x(t+dt) = x(t) + dt v(t) + dt^2 (G + F_other) / 2m,

F_other the external force and the water drag (taken at the step's middle); likewise for the
angle. Fixed bodies never move; kinematic bodies move at their own
velocity and do work on whatever they push.

Where a scene has them (``physics.forcing``, compiled in only then): the water drag acts on
the velocity relative to the current, the wind's drag joins the other forces (both taken
where the water drag is), the sea-surface tilt of a geostrophic current adds ``f k x u``, and
Coriolis turns the velocity by the trapezoidal rule (``forcing.coriolis_step``: at the step's
mean velocity, so that it does no work). Work and dissipation of the step are evaluated
with the mid-step velocity, which is the exact power of a force held constant over the step,
so kinetic energy and work agree to round-off and the energy residual measures only the
time discretisation of the contact forces.

The stage also reads the contact forces gathered in fixed point, clears them for the next
step, accumulates probe impulses, raises the non-finite and runaway flags, and marks a
world's neighbour lists stale when one of its bodies has moved half their skin.
"""

from __future__ import annotations

from typing import ClassVar

import taichi as ti

from ..codes import BodyEnergy, BodyKind, Status
from ..physics.drag_ti import water_drag_ti
from ..physics.forcing_ti import air_drag_ti, coriolis_step_ti, tilt_acceleration_ti
from ..physics.polygon_ti import rotation_ti
from .forcing import Forcing
from .schema import FORCE_QUANTUM, Layout
from .stages import Access, Stage
from .state import Data, Model, quantum_dtype

# What the step reads of the forcing: its values, its grids and the body's clock.
FORCING_READS = (
    "body_drag_air",
    "body_time",
    "world_current",
    "world_wind",
    "world_coriolis",
    "grid_values",
    "grid_origin",
    "grid_spacing",
    "grid_size",
)


@ti.data_oriented
class Integrator(Stage):
    """Advances every body by one step."""

    ACCESS: ClassVar[dict[str, Access]] = {
        "advance": Access(
            reads=(
                # Model
                "body_count",
                "body_probe",
                "body_kind",
                "body_force_ext",
                "body_drag_linear",
                "body_drag_rotational",
                "body_inv_mass",
                "body_inv_inertia",
                # The forcing (``forcing.Forcing``)
                *FORCING_READS,
                # Data in
                "time_step",
                "body_force_q",
                "body_torque_q",
                "body_shift_q",
                "body_turn_q",
                "probe_impulse",
                "body_vel",
                "body_omega",
                "body_pos",
                "body_angle",
                "body_energy",
                # Per world: how far a step may move a body
                "world_runaway_step",
                # Neighbour lists: has the body moved half the skin?
                "list_skin",
                "body_small",
                "body_radius",
                "body_world",
                "nbr_ref_pos",
                "nbr_ref_angle",
                "nbr_path",
            ),
            writes=(
                "body_force_q",
                "body_torque_q",
                "body_shift_q",
                "body_turn_q",
                "probe_impulse",
                "body_vel",
                "body_omega",
                "body_pos",
                "body_angle",
                "body_energy",
                "body_dvel",
                "body_domega",
                "status",
                "body_rot",
                "world_nbr_stale",
                "nbr_rebuild",
                "nbr_path",
                "body_time",
            ),
        ),
        "orient": Access(reads=("body_count", "body_angle"), writes=("body_rot",)),
    }
    PARTS: ClassVar[dict[str, type]] = {"forcing": Forcing}

    def __init__(self, layout: Layout, model: Model, data: Data, neighbours):
        self.layout, self.model, self.data = layout, model, data
        self.neighbours = neighbours
        self.forcing = Forcing(layout, model, data)

    @ti.kernel
    def orient(self):
        """Turn every body to its angle (``body_rot``): once at set-up; the step turns the
        bodies that move."""
        for i in range(self.layout.n_bodies):  # the capacity: a launch of known size
            if i < self.model.body_count[None]:
                self.turn(i)

    @ti.func
    def turn(self, i):
        """Body i's rotation (cos, sin of its angle), from which the contact stage turns its
        outline: two numbers a body, not two a vertex. In float64 by ``rotation_ti`` (libm's
        cos and sin were 12 % of a step), in float32 by ``ti.cos`` and ``ti.sin``."""
        angle = self.data.body_angle[i]
        if ti.static(self.layout.precision == "f64"):
            self.data.body_rot[i] = rotation_ti(angle)
        else:
            self.data.body_rot[i] = ti.Vector([ti.cos(angle), ti.sin(angle)])

    @ti.kernel
    def advance(self):
        for i in range(self.layout.n_bodies):
            if i < self.model.body_count[None]:
                self.body(i, self.data.time_step[None])

    @ti.func
    def moved(self, i):
        """How far any point of body i that its neighbour list relies on has moved since the
        list was built (m): its centroid for a small body (the bounding circle turns with
        it); for a large one, whose faces are tested, also its circumradius times the turn."""
        m, d, nb = ti.static((self.model, self.data, self.neighbours))
        dist = (d.body_pos[i] - nb.nbr_ref_pos[i]).norm()
        if not m.body_small[i]:
            dist += m.body_radius[i] * ti.abs(d.body_angle[i] - nb.nbr_ref_angle[i])
        return dist

    @ti.func
    def displace(self, i, shift, turn):
        """Shift body i's centroid by ``shift`` (m, f64) and turn it by ``turn`` (rad), and add
        to its ``nbr_path`` how far any point of it moved: the centroid's step plus its
        circumradius times the turn (an arc is longer than its chord), both as stored, so
        rounding of the angle is counted too. The contact stage skips a pair found apart by
        a gap while their paths since add up to less (``ContactStage.body``)."""
        m, d, nb = ti.static((self.model, self.data, self.neighbours))
        pos, angle = d.body_pos[i], d.body_angle[i]
        d.body_pos[i] = pos + shift
        d.body_angle[i] = angle + turn
        moved = (d.body_pos[i] - pos).norm() + m.body_radius[i] * ti.abs(
            ti.cast(d.body_angle[i] - angle, ti.f64)
        )
        nb.nbr_path[i] = nb.nbr_path[i] + moved

    @ti.func
    def moving(self, i):
        """Mark body i's world's lists stale if it has moved half their skin. Its path since
        (``nbr_path``) bounds how far it moved: below half the skin, as most steps are, no
        square root is taken (about 2 % of a step of the pillar before its jam)."""
        m, nb = ti.static((self.model, self.neighbours))
        half = 0.5 * ti.cast(m.list_skin[None], ti.f64)
        if nb.nbr_path[i] > half:
            if self.moved(i) > half:
                nb.world_nbr_stale[m.body_world[i]] = 1
                nb.nbr_rebuild[None] = 1

    @ti.func
    def body(self, i, dt):
        """Advance body i by one step of dt.

        Only body i's thread writes its rows (state, energy, probe), so they are updated
        with plain stores: an augmented assignment to a field is an atomic in Taichi (a
        compare-and-swap loop for a float), which the step does not need."""
        m, d, qt = ti.static((self.model, self.data, quantum_dtype()))
        f = ti.cast(d.body_force_q[i], self.layout.real) * FORCE_QUANTUM
        tau = ti.cast(d.body_torque_q[i], self.layout.real) * FORCE_QUANTUM
        d.body_force_q[i] = ti.Vector([0, 0], qt)
        d.body_torque_q[i] = 0
        # The analytic step's position impulses, as forces (2 Q / dt^2): a contact's force
        # over the step moves the body by dt^2 / 2 of them over its mass, not by dt^2 of its
        # mean as the Euler step has it (``contact_step``).
        g = ti.Vector([0.0, 0.0], self.layout.real)
        gam = ti.cast(0.0, self.layout.real)
        if ti.static(self.layout.analytic):
            g = ti.cast(d.body_shift_q[i], self.layout.real) * FORCE_QUANTUM
            gam = ti.cast(d.body_turn_q[i], self.layout.real) * FORCE_QUANTUM
            d.body_shift_q[i] = ti.Vector([0, 0], qt)
            d.body_turn_q[i] = 0
        p = m.body_probe[i]
        if p >= 0:
            d.probe_impulse[p] = d.probe_impulse[p] + ti.cast(f * dt, ti.f64)
        kind = m.body_kind[i]
        if kind == BodyKind.DYNAMIC:
            v0, w0 = d.body_vel[i], d.body_omega[i]
            f_ext = m.body_force_ext[i]  # zero for most bodies: the same bits as none
            f_drag = ti.Vector([0.0, 0.0], self.layout.real)
            t_drag = ti.cast(0.0, self.layout.real)
            # Euler: at the step's start; analytic: at the middle of the step the other
            # forces make (second order).
            vd, wd = v0, w0
            if ti.static(self.layout.analytic):
                vd = v0 + 0.5 * dt * m.body_inv_mass[i] * (f + f_ext)
                wd = w0 + 0.5 * dt * m.body_inv_inertia[i] * tau
            # The water's velocity relative to which the floe feels its drag: the current.
            u_w = ti.Vector([0.0, 0.0], self.layout.real)
            if ti.static(self.layout.current):
                u_w = self.forcing.current(i)
            c_lin, c_rot = m.body_drag_linear[i], m.body_drag_rotational[i]
            if c_lin != 0.0 or c_rot != 0.0:  # in [water]: a value, not a compiled switch
                vr = vd
                if ti.static(self.layout.current):
                    vr = vd - u_w
                f_drag, t_drag = water_drag_ti(vr, wd, c_lin, c_rot)
            f_all = f + f_ext + f_drag
            f_air = ti.Vector([0.0, 0.0], self.layout.real)
            if ti.static(self.layout.wind):
                f_air = air_drag_ti(vd, self.forcing.wind(i), m.body_drag_air[i])
                f_all = f_all + f_air
            v1 = v0 + dt * m.body_inv_mass[i] * f_all
            a_tilt = ti.Vector([0.0, 0.0], self.layout.real)
            if ti.static(self.layout.coriolis):
                cor = m.world_coriolis[m.body_world[i]]
                if ti.static(self.layout.tilt):
                    a_tilt = tilt_acceleration_ti(cor, u_w)
                v1 = coriolis_step_ti(v0, m.body_inv_mass[i] * f_all + a_tilt, cor, dt)
            w1 = w0 + dt * m.body_inv_inertia[i] * (tau + t_drag)
            shift = dt * v1
            turn = dt * w1
            if ti.static(self.layout.analytic):
                # x(t + dt) = x + dt v + dt^2 / (2 m) (2 Q / dt^2 + the other forces)
                f_pos = g + f_ext + f_drag
                if ti.static(self.layout.wind):
                    f_pos = f_pos + f_air
                shift = dt * v0 + 0.5 * dt * dt * m.body_inv_mass[i] * f_pos
                if ti.static(self.layout.coriolis):
                    # The tilt, and Coriolis at the step's mean velocity, as v1 had them.
                    vc = 0.5 * (v0 + v1)
                    a_cor = m.world_coriolis[m.body_world[i]] * ti.Vector([vc[1], -vc[0]])
                    shift = shift + 0.5 * dt * dt * (a_tilt + a_cor)
                turn = dt * w0 + 0.5 * dt * dt * m.body_inv_inertia[i] * (gam + t_drag)
            vm, wm = 0.5 * (v0 + v1), 0.5 * (w0 + w1)
            if ti.static(self.layout.energy):
                # The drag dissipates its power on the velocity relative to the water; the
                # rest of its power on the floe, F.u, is the current's work. Coriolis does
                # none (perpendicular to vm); the wind and the tilt do F.vm.
                vr = vm
                if ti.static(self.layout.current):
                    vr = vm - u_w
                e_d = d.body_energy[i, BodyEnergy.DRAG]
                d.body_energy[i, BodyEnergy.DRAG] = e_d + ti.cast(
                    -(f_drag.dot(vr) + t_drag * wm) * dt, ti.f64
                )
                e_w = d.body_energy[i, BodyEnergy.WORK]
                d.body_energy[i, BodyEnergy.WORK] = e_w + ti.cast(f_ext.dot(vm) * dt, ti.f64)
                if ti.static(self.layout.current):
                    e_c = d.body_energy[i, BodyEnergy.CURRENT]
                    d.body_energy[i, BodyEnergy.CURRENT] = e_c + ti.cast(
                        f_drag.dot(u_w) * dt, ti.f64
                    )
                if ti.static(self.layout.wind):
                    e_a = d.body_energy[i, BodyEnergy.WIND]
                    d.body_energy[i, BodyEnergy.WIND] = e_a + ti.cast(f_air.dot(vm) * dt, ti.f64)
                if ti.static(self.layout.tilt):  # m f (k x u).vm
                    e_t = d.body_energy[i, BodyEnergy.TILT]
                    d.body_energy[i, BodyEnergy.TILT] = e_t + ti.cast(
                        a_tilt.dot(vm) * dt / m.body_inv_mass[i], ti.f64
                    )
            if ti.static(self.layout.clock):
                d.body_time[i] = d.body_time[i] + ti.cast(dt, ti.f64)
            if ti.static(self.layout.velocity_changes):  # what the contacts use next step
                d.body_dvel[i] = v1 - v0
                d.body_domega[i] = w1 - w0
            d.body_vel[i] = v1
            d.body_omega[i] = w1
            self.displace(i, ti.cast(shift, ti.f64), turn)
            self.turn(i)
            self.moving(i)
            speed2 = v1.norm_sqr()
            w = m.body_world[i]
            moved = speed2 * dt * dt
            if ti.static(self.layout.analytic):
                moved = shift.norm_sqr()
            if not (speed2 < ti.math.inf and ti.abs(w1) < ti.math.inf):
                d.status[w, Status.NONFINITE] = 1
            elif moved > m.world_runaway_step[w] * m.world_runaway_step[w]:
                d.status[w, Status.RUNAWAY] = 1
        elif kind == BodyKind.KINEMATIC:
            # The contact force f acts on the pusher; the pusher does -f.v on the rest.
            v, w = d.body_vel[i], d.body_omega[i]
            if ti.static(self.layout.energy):
                e_w = d.body_energy[i, BodyEnergy.WORK]
                d.body_energy[i, BodyEnergy.WORK] = e_w + ti.cast(
                    -(f.dot(v) + tau * w) * dt, ti.f64
                )
            self.displace(i, ti.cast(dt * v, ti.f64), dt * w)
            if w != 0.0:
                self.turn(i)
            self.moving(i)
