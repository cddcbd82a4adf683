"""Narrow phase and contact forces (Hopkins 1992), with per-contact memory.

For each candidate pair its owner's thread clips the outlines (``polygon_ti.overlap_ti``), then:

- normal force  ``F_n = k_e A + k_v L v_n``, no tension (``F_n >= 0``); ``A`` the overlap
  area, ``L`` the contact width (chord), ``v_n`` the approach speed along the normal. With an
  ice strength (``[ice] crushing_strength``) the elastic force is capped at strength x
  thickness x L: the overlap beyond the cap is crushed (``crush``), not recovered, and its
  work is booked as crushing;
- tangential force from a stick spring ``k_t = ratio k_e L`` (proportional to the contact
  width, like the normal one) and a dashpot ``c_t`` that damps it to a fraction of critical
  at the pair's mass along the tangent (``tangential_damping``) on the tangential stretch
  ``xi``, capped at ``mu F_n`` (Cundall and Strack 1979): beyond the cap the contact slips,
  the spring-dashpot relaxes toward the cap and the slip distance times the cap is
  frictional work;
- ``mu`` from the world's law: Coulomb, or rate-and-state (and its variants) through
  ``slip_ti.contact_friction_ti``: the slip rate solved in the step (the sliding rate, never
  faster than the surfaces), ``theta`` and the slip rate carried by the contact while it
  slides, and the rule below ``v_star`` (Lishman et al. 2013).

Ownership: each pair is handled once, by a dynamic body if exactly one is dynamic, else by
the lower id; small-large pairs by the small body. The owner keeps the contact's memory
(partner, ``xi``, ``theta``, slip rate, stored elastic energy, crushed area) in one of its K
slots; a pair that no longer overlaps is not written again, so its memory is dropped. The
slots are single-buffered: only the owner's thread touches them, and it copies the last
step's memory out (``remember``) before writing this step's over it. More than K contacts
raise the overflow status, which the simulation turns into an error.

Forces are gathered in 64-bit fixed point (``schema.FORCE_QUANTUM``), so a run is bit-for-bit
reproducible on any number of threads and in any batch (where a device's integer atomics
fail inside loops, whole quanta summed in float64, exact below 2^53: ``backend.float_gather``;
its overflow reports are plain stores of a count above the limit, ``raise_status``).

The contact laws are pure functions, each twice (``taichi_ice``'s twin convention: the plain
name is the NumPy reference in ``contact_law``, ``_ti`` the Taichi function in
``contact_law_ti``): ``normal_force``, ``crush``, ``tangential_damping``, ``tangential_force``
and ``contact_work``. The NumPy reference of a whole pair is ``reference_contact.contact_force``.
This module holds the forces of a step (``ContactStage``); finding the candidate pairs (the
outlines, ownership, the neighbour lists) is its base's, ``contact_lists.ContactLists``.

Energy (``contact_work``): the work of a contact's forces, at the velocity the bodies move
with over the step, goes to the owner's ``body_energy`` row as friction (slip) and viscous
(dashpots) and to the contact as the elastic energy it holds: the work its elastic force
``k_e A`` has done on the approach, ``integral k_e A v_n dt`` (``integral k_e A dA / L`` for
translation along the normal), and its stick spring's. When the contact ends, what it still
holds goes to the owner's ``SEVERED`` term: the normal force follows the overlap's area
and the spring's stiffness the contact width, neither a potential, so floes that slide
apart take work the contact never gives back (``codes.BodyEnergy.SEVERED``).
"""

# No "from __future__ import annotations": Taichi reads kernel annotations as objects.

from typing import ClassVar

import taichi as ti

from ..codes import BodyEnergy, Status
from ..physics.contact_coupled_ti import coupled_impulses_ti
from ..physics.contact_law_ti import (
    contact_work_ti,
    cross2,
    crush_ti,
    inverse_mass_along_ti,
    normal_force_ti,
    tangential_damping_ti,
    tangential_force_ti,
)
from ..physics.contact_step_ti import pair_impulses_ti, sliding_impedance_ti, stick_or_slide_ti
from ..physics.polygon_ti import facing_gap_ti, separation_gap_ti
from ..physics.slip import NEW_CONTACT, NEWTON_TOLERANCE
from ..physics.slip_ti import contact_friction_ti, sliding_steps_ti
from .contact_lists import SETTLE_ACCESS, ContactLists
from .schema import Layout, contact_columns, law_columns
from .stages import Access
from .state import Data, Model


@ti.data_oriented
class ContactStage(ContactLists):
    """Finds overlapping pairs, applies contact forces and keeps contact memory."""

    ACCESS: ClassVar[dict[str, Access]] = {
        "compute": Access(
            reads=(
                # Model
                "body_count",
                "body_world",
                "body_radius",
                "body_local_start",
                "body_vert_count",
                "vert_local",
                "vert_normal_local",
                *law_columns(),
                *contact_columns(),
                "body_inv_mass",
                "body_inv_inertia",
                # Neighbour lists
                "nbr_count",
                "nbr_ids",
                "nbr_path",
                "nbr_gap",
                # Data in
                "time_step",
                "body_pos",
                "body_rot",
                "body_angle",  # the midstep integrator's predicted turn
                "body_vel",
                "body_omega",
                "contact_count",
                "contact_partner",
                "contact_xi",
                "contact_elastic",
                "contact_theta",
                "contact_slip",
                "contact_crushed",
                "contact_force",
                "body_force_q",
                "body_torque_q",
                "body_shift_q",
                "body_turn_q",
                "body_energy",
                "body_dvel",
                "body_domega",
                "status",
            ),
            writes=(
                "contact_count",
                "contact_partner",
                "contact_xi",
                "contact_elastic",
                "contact_theta",
                "contact_slip",
                "contact_crushed",
                "contact_force",
                "contact_booking",
                "body_force_q",
                "body_torque_q",
                "body_shift_q",
                "body_turn_q",
                "body_energy",
                "status",
                "nbr_gap",
            ),
            per_contact=(
                "body_vel",
                "body_omega",
                "body_inv_mass",
                "body_inv_inertia",
                "contact_partner",
                "contact_xi",
                "contact_elastic",
                "contact_theta",
                "contact_slip",
                "contact_crushed",
                "contact_force",
                "contact_booking",
                "body_force_q",
                "body_torque_q",
                "body_shift_q",
                "body_turn_q",
                "body_energy",
                "body_dvel",
                "body_domega",
            ),
        ),
        "settle_all": SETTLE_ACCESS,
        "build_lists": Access(
            reads=(
                "body_count",
                "list_skin",
                "body_world",
                "body_kind",
                "body_small",
                "body_radius",
                "body_local_start",
                "body_vert_count",
                "vert_local",
                "world_large_start",
                "large_ids",
                "bucket_end",
                "bucket_count",
                "sorted_ids",
                "body_pos",
                "body_angle",
                "body_rot",
                "nbr_ids",
                "world_nbr_stale",
                "status",
            ),
            writes=(
                "nbr_ids",
                "nbr_count",
                "nbr_ref_pos",
                "nbr_ref_angle",
                "world_nbr_stale",
                "nbr_rebuild",
                "status",
                "nbr_path",
                "nbr_gap",
            ),
        ),
    }

    def __init__(self, layout: Layout, model: Model, data: Data, spatial_hash, neighbours):
        self.layout, self.model, self.data = layout, model, data
        self.hash, self.neighbours = spatial_hash, neighbours
        self.tol = NEWTON_TOLERANCE[layout.precision]
        self.method = int(layout.theta_method)
        self.maxv = layout.max_verts

    @ti.func
    def pair(
        self,
        i,
        j,
        p: ti.template(),
        p_normals: ti.template(),
        n_p,
        xi,
        elastic,
        theta,
        last_slip,
        crushed,
        fresh,
        last_force,
        used,
        dt,
        serial: ti.template(),
    ):
        """Contact between owner i, whose outline relative to its centroid is ``p`` (its
        edges' outward normals ``p_normals``), and
        partner j, with the pair's memory of the last step (``xi``, ``elastic``, ``theta``,
        ``last_slip``, ``crushed``, and for the analytic step its mean forces ``last_force``:
        zero and ``NEW_CONTACT`` if it was not in contact, which ``fresh`` says). Returns the
        owner's new slot count, and the gap (m) by which an edge proved the pair apart
        (negative if none did)."""
        m, d = ti.static((self.model, self.data))
        xi_, xj_ = d.body_pos[i], d.body_pos[j]
        q, n_q = self.outline(j, xi_)
        # Most candidates (bounding circles that meet) do not touch, and one of the two
        # edges that face each other separates 99 % of those in a random box of 1e4 diamonds
        # (-14 % of a step's CPU time there), 60-75 % in the pillar's rows: for a pair
        # not in contact last step, every edge then, for a gap that skips it for steps to come.
        toward = ti.cast(xj_ - xi_, self.layout.real)
        gap = facing_gap_ti(p, p_normals, n_p, q, n_q, toward)
        q_normals = self.normals(j)  # turned, not normalised: the SAT's too (-7-14 % in a jam)
        if gap < 0.0:
            gap = facing_gap_ti(q, q_normals, n_q, p, n_p, -toward)
        if gap < 0.0 and fresh:
            gap = separation_gap_ti(p, p_normals, n_p, q, q_normals, n_q)
        separated = gap >= 0.0
        # With the midstep step, the overlap at the pose predicted for mid-step too.
        area, point, normal, width, a_m, p_m, n_m, w_m, c_i, c_j = self.step_overlaps(
            i, j, p, p_normals, n_p, q, q_normals, n_q, separated, xi_, dt
        )
        if area > 0.0:
            # The world's contact law (model data: worlds of a batch may differ in it).
            w = m.body_world[i]
            k_e, k_v = m.world_contact_stiffness[w], m.world_contact_viscosity[w]
            # point is relative to body i
            r_i, r_j = point, point + ti.cast(xi_ - xj_, self.layout.real)
            v_rel = self.relative(i, j, r_i, r_j, d.body_vel, d.body_omega)
            tangent = ti.Vector([-normal[1], normal[0]])
            approach = -v_rel.dot(normal)
            slip = v_rel.dot(tangent)
            depth_area, shift_back = area, 0.0 * area
            if ti.static(self.layout.midstep):  # linearised at mid-step (``reference_contact``)
                if a_m > 0.0:
                    normal, width, r_i, r_j = n_m, w_m, p_m - c_i, p_m - c_j
                    v_rel = self.relative(i, j, r_i, r_j, d.body_vel, d.body_omega)
                    tangent = ti.Vector([-normal[1], normal[0]])
                    approach, slip = -v_rel.dot(normal), v_rel.dot(tangent)
                    depth_area, shift_back = a_m, 0.5 * dt * approach

            # Normal: elastic on the overlap not crushed; with a strength, the overlap beyond
            # the cap is crushed (kept, not recovered) and its work is booked.
            cap_n = 0.0
            crushed_new = crushed
            if ti.static(self.layout.crushing):
                cap_n, crushed_new = crush_ti(area, crushed, width, k_e, m.world_crushing_force[w])
            f_n, f_el = normal_force_ti(ti.max(area - crushed_new, 0.0), width, approach, k_e, k_v)
            crush_work = 0.0
            if ti.static(self.layout.crushing):
                f_n = ti.min(f_n, cap_n)
                if crushed_new > crushed and width > 0.0:
                    crush_work = cap_n * (crushed_new - crushed) / width

            # Tangential: a stick spring ~ the contact width, damped by ``tangential_damping_ti``.
            k_t = m.world_tangential_stiffness[w] * k_e * width
            c_t = tangential_damping_ti(
                k_t,
                m.world_tangential_damping[w],
                m.body_inv_mass[i],
                m.body_inv_inertia[i] * cross2(r_i, tangent) ** 2,
                m.body_inv_mass[j],
                m.body_inv_inertia[j] * cross2(r_j, tangent) ** 2,
            )
            # The last step's change of the pair's relative velocity at the contact point:
            # the energy's booking velocity, and the analytic step's other forces.
            rel_change = ti.Vector([0.0, 0.0], self.layout.real)
            if ti.static(self.layout.velocity_changes):
                rel_change = self.relative(i, j, r_i, r_j, d.body_dvel, d.body_domega)
            # The analytic step: the normal and the stuck tangential spring-dashpot solved
            # over the step, apart (``contact_step_ti``) or together (``coupled``,
            # ``contact_coupled_ti``), the mean forces f and the position impulses g (2 Q /
            # dt^2) gathered; Euler's f (and g = f) where it cannot be (a pair of bodies
            # that do not move, a contact of no width).
            exact = False
            inv_n, inv_t, a_n, a_t, k_nt = 0.0 * k_e, 0.0 * k_e, 0.0 * k_e, 0.0 * k_e, 0.0 * k_e
            q_n, p_t, q_t = 0.0 * k_e, 0.0 * k_e, 0.0 * k_e
            xi1 = xi
            if ti.static(self.layout.analytic):
                mi, ii = m.body_inv_mass[i], m.body_inv_inertia[i]
                mj, ij = m.body_inv_mass[j], m.body_inv_inertia[j]
                inv_n = inverse_mass_along_ti(
                    mi, ii, cross2(r_i, normal), mj, ij, cross2(r_j, normal)
                )
                inv_t = inverse_mass_along_ti(
                    mi, ii, cross2(r_i, tangent), mj, ij, cross2(r_j, tangent)
                )
                exact = width > 0.0 and inv_n > 0.0 and inv_t > 0.0
                if exact:
                    depth = ti.max(area - crushed_new, 0.0) / width
                    if ti.static(self.layout.midstep):
                        depth = ti.max(depth_area - crushed_new, 0.0) / width - shift_back
                    args = (
                        depth, approach, slip, xi, fresh,
                        -rel_change.dot(normal), rel_change.dot(tangent), last_force, dt,
                        k_e * width, k_v * width, k_t, c_t, inv_n, inv_t,
                    )  # fmt: skip
                    if ti.static(self.layout.coupled):
                        k_nt = ii * cross2(r_i, normal) * cross2(r_i, tangent)
                        k_nt = k_nt + ij * cross2(r_j, normal) * cross2(r_j, tangent)
                        mu_slide = 0.0 * k_e  # the mu it would slide at (rate and state's: mu0)
                        if ti.static(self.layout.rate_state):
                            mu_slide = m.world_mu0[w]
                        else:
                            mu_slide = m.world_mu[w]
                        f_n, f_el, q_n, p_t, q_t, xi1, a_n, a_t = coupled_impulses_ti(
                            *args, k_nt, mu_slide
                        )
                    else:
                        f_n, f_el, q_n, p_t, q_t, xi1, a_n, a_t = pair_impulses_ti(*args)
                    if ti.static(self.layout.crushing):
                        if f_n > cap_n:  # the strength caps the step's mean force
                            scale = cap_n / f_n
                            f_n, f_el, q_n = cap_n, f_el * scale, q_n * scale
            mu = 0.0
            theta_new = 0.0
            slip_rate = 0.0
            # Rate and state: the Euler step solves the law with the tangential step
            # (``sliding_steps_ti``, below); the analytic step first, from its impulses.
            if ti.static(self.layout.rate_state and self.layout.analytic):
                f_trial = ti.abs(k_t * (xi + slip * dt) + c_t * slip)
                impedance = k_t * dt + c_t
                if exact:  # the stuck spring-dashpot's mean force over the step
                    f_trial = ti.abs(p_t) / dt
                    impedance = sliding_impedance_ti(k_t, c_t, dt)
                mu, theta_new, slip_rate = contact_friction_ti(
                    theta,
                    last_slip,
                    slip,
                    f_trial,
                    f_n,
                    impedance,
                    dt,
                    m.world_A[w],
                    m.world_B[w],
                    m.world_mu0[w],
                    m.world_v_star[w],
                    m.world_t_c[w],
                    m.world_memory[w],
                    m.world_rest_rule[w],
                    ti.static(self.method),
                    ti.static(self.tol),
                )
            elif ti.static(not self.layout.rate_state):
                mu = m.world_mu[w]

            f_t = 0.0 * k_e
            g_t = 0.0 * k_e
            xi_new = xi
            slip_work = 0.0 * k_e
            damp_work = 0.0 * k_e
            if ti.static(self.layout.analytic):
                if exact:
                    f_t, g_t, xi_new, slip_work, damp_work = stick_or_slide_ti(
                        p_t, q_t, xi, xi1, slip, dt, k_t, c_t, mu * f_n * dt, mu * q_n
                    )
                else:
                    f_t, xi_new, slip_work, damp_work = tangential_force_ti(
                        xi, slip, dt, k_t, c_t, mu * f_n
                    )
            elif ti.static(self.layout.rate_state):
                # The law and the capped spring-dashpot together, in sub-steps that resolve
                # the slide as ``[ice] slide_resolution`` asks (0.025 by default; 0: one step).
                mu, theta_new, slip_rate, f_t, xi_new, slip_work, damp_work = sliding_steps_ti(
                    theta,
                    last_slip,
                    slip,
                    xi,
                    f_n,
                    k_t,
                    c_t,
                    dt,
                    m.world_A[w],
                    m.world_B[w],
                    m.world_mu0[w],
                    m.world_v_star[w],
                    m.world_t_c[w],
                    m.world_memory[w],
                    m.world_rest_rule[w],
                    m.world_slide_resolution[w],
                    ti.static(self.method),
                    ti.static(self.tol),
                )
            else:
                f_t, xi_new, slip_work, damp_work = tangential_force_ti(
                    xi, slip, dt, k_t, c_t, mu * f_n
                )
            force = f_n * normal + f_t * tangent  # on j; -force on i
            self.add_force(j, force, cross2(r_j, force), serial)
            self.add_force(i, -force, -cross2(r_i, force), serial)
            if ti.static(self.layout.analytic):
                g = force  # Euler's: the mean force held over the step
                if exact:
                    g = (2.0 * q_n / (dt * dt)) * normal + g_t * tangent
                self.add_shift(j, g, cross2(r_j, g), serial)
                self.add_shift(i, -g, -cross2(r_i, g), serial)

            # The work of the contact's forces, booked at the velocity the bodies move with
            # over the step (``contact_work_ti``): the elastic part is what the contact holds
            # (normal, on the approach, less what crushed; tangential, the stick spring's
            # energy at this step's stiffness, which follows the width), the rest is
            # dissipated. (Without a budget, ``Layout.energy`` off, none of it is computed.)
            if ti.static(self.layout.energy):
                # The booking velocity's change: the last step's (Euler); the analytic step
                # knows this step's, its other forces' and its own (``contact_step``).
                approach_change = -rel_change.dot(normal)
                slip_change = rel_change.dot(tangent)
                if ti.static(self.layout.analytic):
                    if exact:
                        approach_change = (a_n - inv_n * f_n) * dt
                        slip_change = (a_t + inv_t * f_t) * dt
                        if ti.static(self.layout.coupled):  # and its cross term
                            approach_change -= k_nt * f_t * dt
                            slip_change += k_nt * f_n * dt
                held, viscous, friction = contact_work_ti(
                    f_n,
                    f_el,
                    f_t,
                    approach,
                    approach_change,
                    slip_change,
                    dt,
                    slip_work,
                    damp_work,
                    k_t,
                    xi,
                    xi_new,
                    crush_work,
                )
                elastic += held
                if ti.static(self.layout.settles):  # what ``settle`` books again
                    b = ti.Vector.zero(self.layout.real, 12)
                    if exact:
                        slid = ti.select(slip_work > 0.0, 1.0, 0.0)
                        b = ti.Vector([approach_change, slip_change, 0.5 * dt * f_el,
                                       0.5 * dt * (f_n - f_el), -0.5 * dt * f_t, slid,
                                       normal[0], normal[1], cross2(r_i, normal),
                                       cross2(r_j, normal), cross2(r_i, tangent),
                                       cross2(r_j, tangent)], self.layout.real)  # fmt: skip
                    if used < self.layout.slots:
                        d.contact_booking[i, used] = b
                # The owner's rows: plain stores (an augmented assignment would be an atomic).
                e_f = d.body_energy[i, BodyEnergy.FRICTION]
                d.body_energy[i, BodyEnergy.FRICTION] = e_f + friction
                e_v = d.body_energy[i, BodyEnergy.VISCOUS]
                d.body_energy[i, BodyEnergy.VISCOUS] = e_v + viscous
                if ti.static(self.layout.crushing):
                    e_c = d.body_energy[i, BodyEnergy.CRUSHING]
                    d.body_energy[i, BodyEnergy.CRUSHING] = e_c + crush_work

            if used < self.layout.slots:
                d.contact_partner[i, used] = j
                d.contact_xi[i, used] = xi_new
                if ti.static(self.layout.energy):
                    d.contact_elastic[i, used] = elastic
                if ti.static(self.layout.rate_state):
                    d.contact_theta[i, used] = theta_new
                    d.contact_slip[i, used] = slip_rate
                if ti.static(self.layout.crushing):
                    d.contact_crushed[i, used] = crushed_new
                if ti.static(self.layout.analytic):
                    d.contact_force[i, used] = ti.Vector([f_n, f_t])
            used += 1
        return used, gap

    @ti.func
    def body(self, i, dt, serial: ti.template()):
        """Every contact of owner i with the partners of its neighbour list whose bounding
        circles meet its own (ascending ids: a body's sums do not depend on how the list was
        built); the last step's memory is read from its slots and this step's written over it."""
        m, d, nb = ti.static((self.model, self.data, self.neighbours))
        old, n_old = self.remember(i)
        used = 0
        # The owner's outline and its edges' normals, turned for the first candidate that
        # needs them (n_p 0 before): most bodies, most steps, have none (-8 % a free step).
        p = ti.Matrix.zero(self.layout.real, self.maxv, 2)
        p_normals, n_p = p, 0
        # What the last step's contacts held, less what carries on: the elastic energy of
        # the contacts that ended (``BodyEnergy.SEVERED``).
        severed = ti.cast(0.0, ti.f64)
        if ti.static(self.layout.energy):
            for s in range(n_old):
                severed += ti.cast(old.elastic[s], ti.f64)
        path_i = nb.nbr_path[i]
        for k in range(nb.nbr_count[i]):
            j = nb.nbr_ids[i, k]
            # Found apart by a gap that the two bodies' paths since cannot have closed: the
            # test would find them apart again (most candidates, most steps). Gaps are kept
            # for the first ``slots`` entries, more than any list measured held.
            if k < self.layout.slots:
                if path_i + nb.nbr_path[j] < nb.nbr_gap[i, k]:
                    continue
            if not self.near(i, j):
                if k < self.layout.slots:
                    reach = m.body_radius[i] + m.body_radius[j]
                    apart = (d.body_pos[j] - d.body_pos[i]).norm() - reach
                    nb.nbr_gap[i, k] = self.gap_bound(i, j, apart, path_i)
                continue
            if n_p == 0:
                p, n_p = self.outline(i, d.body_pos[i])
                p_normals = self.normals(i)
            # The pair's memory from the last step, if it was in contact then.
            xi = ti.cast(0.0, self.layout.real)
            elastic = ti.cast(0.0, self.layout.real)
            theta = ti.cast(NEW_CONTACT, self.layout.real)
            last_slip = ti.cast(0.0, self.layout.real)
            crushed = ti.cast(0.0, self.layout.real)
            fresh = True
            last_force = ti.Vector([0.0, 0.0], self.layout.real)
            for s in range(n_old):
                if old.partner[s] == j:
                    fresh = False
                    if ti.static(self.layout.analytic):
                        last_force = ti.Vector([old.force[s, 0], old.force[s, 1]])
                    xi = old.xi[s]
                    if ti.static(self.layout.energy):
                        elastic = old.elastic[s]
                    if ti.static(self.layout.rate_state):
                        theta = old.theta[s]
                        last_slip = old.slip[s]
                    if ti.static(self.layout.crushing):
                        crushed = old.crushed[s]
            carried, gap = self.pair(
                i,
                j,
                p,
                p_normals,
                n_p,
                xi,
                elastic,
                theta,
                last_slip,
                crushed,
                fresh,
                last_force,
                used,
                dt,
                serial,
            )
            if k < self.layout.slots:
                nb.nbr_gap[i, k] = self.gap_bound(i, j, ti.cast(gap, ti.f64), path_i)
            if ti.static(self.layout.energy):
                if carried > used:  # in contact: its memory carries on
                    severed -= ti.cast(elastic, ti.f64)
            used = carried
        if ti.static(self.layout.energy):
            if severed != 0.0:  # most bodies, most steps: no contact ended, no row touched
                e = d.body_energy[i, BodyEnergy.SEVERED]
                d.body_energy[i, BodyEnergy.SEVERED] = e + severed
        d.contact_count[i] = ti.min(used, self.layout.slots)
        # More contacts than slots is reported (never silently dropped): the caller turns it
        # into CapacityError. (The list's own overflow is reported when it is built.)
        if used > self.layout.slots:
            self.raise_status(self.model.body_world[i], Status.SLOT_OVERFLOW, used)

    @ti.func
    def listed(self, i, dt, serial: ti.template()):
        """Body i's contacts, its candidates from its neighbour list (read in place: a copy
        cost 2 % of a step); ``serial``: one thread steps the world, forces need no atomics."""
        self.body(i, dt, serial)

    @ti.kernel
    def compute(self):
        """Every contact's force and memory this step, in parallel over the bodies in use."""
        for i in range(self.layout.n_bodies):
            if i < self.model.body_count[None]:
                self.listed(i, self.data.time_step[None], False)
