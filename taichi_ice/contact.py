"""Narrow phase and contact forces (Hopkins 1992), with per-contact memory.

For every candidate pair the owner body's thread clips the two outlines
(``geometry.overlap_ti``) and applies:

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
  ``slip.contact_friction_ti``: the slip rate solved in the step (the sliding rate, never
  faster than the surfaces), ``theta`` and the slip rate carried by the contact while it
  slides, and the rule below ``v_star`` (Lishman et al. 2013).

Ownership: each pair is handled once, by a dynamic body if exactly one is dynamic, else by
the lower id; small-large pairs by the small body. The owner keeps the contact's memory
(partner, ``xi``, ``theta``, slip rate, stored elastic energy, crushed area) in one of its K slots;
a pair that no longer overlaps is not written again, so its memory is dropped. The slots
are single-buffered: only the owner's thread touches them, and it copies the last step's
memory out (``remember``) before writing this step's over it. More than K contacts raise
the overflow status, which the simulation turns into an error.

Forces are gathered in 64-bit fixed point (``state.FORCE_QUANTUM``), so a run is bit-for-bit
reproducible on any number of threads and in any batch. (On a device whose integer atomics
fail inside loops the whole quanta are summed in float64, exact below 2^53 of them:
``backend.float_gather``.) Overflow reports there are plain stores of a count above the
limit (``raise_status``), not the largest such count.

The contact laws are pure functions, each twice (``taichi_ice``'s twin convention: the plain
name is the NumPy reference, ``_ti`` the Taichi function): ``normal_force``,
``tangential_damping``, ``tangential_force`` and ``contact_work``. The NumPy reference of a
whole pair is ``reference.contact_force``.

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

import math
from typing import ClassVar

import taichi as ti

from . import backend
from .broadphase import bucket_of
from .codes import BodyEnergy, BodyKind, Status
from .geometry import facing_gap_ti, overlap_normals_ti
from .schema import Access, Layout, Stage
from .slip import NEW_CONTACT, NEWTON_TOLERANCE, contact_friction_ti
from .state import FORCE_QUANTUM, Data, Model, quantum_dtype

# Round-off allowance of a gap that lets a pair be skipped (``ContactStage.gap_bound``), as
# a fraction of the two circumradii: 1e-5 m for two of the paper's diamonds, against ~1e-7 m
# of error in a float32 outline a metre across, turned and shifted relative to the pair.
GAP_MARGIN = 1e-5


@ti.func
def cross2(a, b):
    """z-component of the cross product of two 2-vectors."""
    return a[0] * b[1] - a[1] * b[0]


@ti.func
def perp(omega, r):
    """omega (z) x r: the velocity of a point at r on a body spinning at omega."""
    return ti.Vector([-omega * r[1], omega * r[0]])


@ti.func
def normal_force_ti(area, width, approach_speed, k_e, k_v):
    """Taichi twin of :func:`normal_force`."""
    elastic = k_e * area
    return ti.max(elastic + k_v * width * approach_speed, 0.0), elastic


def normal_force(area, width, approach_speed, k_e, k_v):
    """Hopkins normal force (N): elastic on the overlap area, viscous on the contact width.

    Args:
        area: overlap area ``A`` (m^2). width: contact width ``L`` (m).
        approach_speed: ``v_n``, positive when closing (m/s).
        k_e: N/m per m of contact width. k_v: Pa s per m of contact width.

    Returns:
        ``(max(k_e A + k_v L v_n, 0), k_e A)``: the force, clamped at zero (no tension), and
        its elastic part.
    """
    elastic = k_e * area
    return max(elastic + k_v * width * approach_speed, 0.0), elastic


@ti.func
def crush_ti(area, crushed, width, k_e, force_per_width):
    """Taichi twin of :func:`crush`."""
    cap = force_per_width * width
    crushed_new = crushed
    if k_e * (area - crushed) > cap:
        crushed_new = area - cap / k_e
    return cap, crushed_new


def crush(area, crushed, width, k_e, force_per_width):
    """The ice's strength: the normal elastic force ``k_e (A - A_c)`` is capped at
    ``cap = strength x thickness x L``; overlap beyond it is crushed and not recovered.

    Args:
        area: overlap area ``A`` (m^2). crushed: area crushed so far, ``A_c`` (m^2).
        width: contact width ``L`` (m). k_e: N/m per m of contact width.
        force_per_width: strength x thickness (N/m).

    Returns:
        ``(cap, A_c')``: the cap (N) and the crushed area after this step (m^2): ``A - cap /
        k_e`` if the elastic force would exceed the cap, else unchanged. The crushing work of
        the step is ``cap (A_c' - A_c) / L``.
    """
    cap = force_per_width * width
    if k_e * (area - crushed) > cap:
        crushed = area - cap / k_e
    return cap, crushed


@ti.func
def tangential_damping_ti(k_t, zeta, inv_mass_i, inv_turn_i, inv_mass_j, inv_turn_j):
    """Taichi twin of :func:`tangential_damping`."""
    inv_m = inv_mass_i + inv_turn_i + inv_mass_j + inv_turn_j
    return 2.0 * zeta * ti.sqrt(k_t / inv_m)


def tangential_damping(k_t, zeta, inv_mass_i, inv_turn_i, inv_mass_j, inv_turn_j):
    """Dashpot ``c_t`` (N s/m) that damps the stick spring ``k_t`` to ``zeta`` of critical.

    The spring holds the two bodies' contact points together along the tangent ``t``, where
    they move as one mass ``m_t``: ``1 / m_t = 1/m_i + (r_i x t)^2 / I_i + 1/m_j +
    (r_j x t)^2 / I_j`` (0 for a fixed or kinematic body), so ``c_t = 2 zeta sqrt(k_t m_t)``:
    the same damping ratio whatever the floes' size. The default ``[ice] tangential_damping``
    is 0.25: the contact checks of ``studies.contact_convergence`` give the same results from
    0.25 to 1 (the slider's work to 1e-4), while explicit dashpots add up in a block with
    several stuck contacts, so a jam at full load ran to 1.2 x the computed stable step at
    0.25 and diverged below it at 0.5 (0.8-1.0 x) and 1 (0.6-0.8 x; ``docs/friction.md``).
    (Proportional to ``k_v L`` as before, the ratio fell with the floes' mass: ~0.16 for the
    paper's diamonds.)

    Args:
        k_t: stick spring (N/m). zeta: fraction of critical damping.
        inv_mass_i, inv_mass_j: ``1 / m`` of the two bodies (1/kg).
        inv_turn_i, inv_turn_j: ``(r x t)^2 / I`` of the two bodies (1/kg), ``r`` from the
            centroid to the contact point.
    """
    inv_m = inv_mass_i + inv_turn_i + inv_mass_j + inv_turn_j
    return 2.0 * zeta * math.sqrt(k_t / inv_m)


@ti.func
def tangential_force_ti(xi, slip_speed, dt, k_t, c_t, cap):
    """Taichi twin of :func:`tangential_force`."""
    trial = xi + slip_speed * dt
    force = -k_t * trial - c_t * slip_speed
    slip_work = 0.0
    damp_work = c_t * slip_speed * slip_speed * dt
    new_xi = trial
    if ti.abs(force) > cap:
        force = ti.math.sign(force) * cap
        new_xi = (c_t * xi - force * dt) / (k_t * dt + c_t)
        slip_work = cap * ti.abs(trial - new_xi)
        damp_work = c_t * (new_xi - xi) * (new_xi - xi) / dt
    return force, new_xi, slip_work, damp_work


def tangential_force(xi, slip_speed, dt, k_t, c_t, cap):
    """Stick spring-dashpot capped at ``cap`` = mu F_n (Cundall and Strack 1979).

    Args:
        xi: tangential stretch carried from the last step (m).
        slip_speed: tangential velocity of the partner relative to the owner (m/s).
        dt: time step (s). k_t: spring (N/m). c_t: dashpot (N s/m). cap: mu F_n (N).

    Returns:
        (force on the partner along the tangent (N), new stretch (m),
         frictional work of this step (J), dashpot work of this step (J)).
    """
    trial = xi + slip_speed * dt
    force = -k_t * trial - c_t * slip_speed
    slip_work = 0.0
    damp_work = c_t * slip_speed * slip_speed * dt
    new_xi = trial
    if abs(force) > cap:
        # Slip: the force is the cap and the spring-dashpot relaxes toward it over the step,
        # -k_t new_xi - c_t (new_xi - xi) / dt = force (backward Euler), the rest of the
        # displacement is sliding. (Setting new_xi = -force / k_t instead lets the dashpot's
        # share of the trial force flip or over-stretch the spring by 2 mu F_n / k_t in one
        # step, booking slip work that no force did: an energy error that dt does not shrink.)
        force = math.copysign(cap, force)
        new_xi = (c_t * xi - force * dt) / (k_t * dt + c_t)
        slip_work = cap * abs(trial - new_xi)
        damp_work = c_t * (new_xi - xi) * (new_xi - xi) / dt
    return force, new_xi, slip_work, damp_work


@ti.func
def contact_work_ti(
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
):
    """Taichi twin of :func:`contact_work`."""
    approach_mid = approach + 0.5 * approach_change
    extra = -f_t * 0.5 * slip_change * dt
    step = xi_new - xi
    held = f_el * approach_mid * dt - crush_work + 0.5 * k_t * (xi_new * xi_new - xi * xi)
    viscous = (f_n - f_el) * approach_mid * dt + damp_work + 0.5 * k_t * step * step
    friction = slip_work
    if slip_work > 0.0:
        friction += extra
    else:
        held += extra
    return held, viscous, friction


def contact_work(
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
):
    """The work a contact's forces do on it over a step, split into what it holds and what
    it dissipates (J), booked at the velocity the two bodies move with over the step.

    Symplectic Euler changes a body's kinetic energy by ``F . (v0 + v1) / 2 dt``: a force's
    work at the mid-step velocity, not the start-of-step one the contact's forces were
    evaluated with (which overstated a colliding contact's elastic energy by (pi / 2) w dt
    of it, and left a residual of 1.6 % of what a free field lost). The mid-step velocity is
    not known when the contacts are evaluated, so each body's last velocity change stands in
    for this step's (``body_dvel``, ``body_domega``): ``v_mid = v0 + dv_last / 2``, second
    order where the motion is smooth. The tangential force's extra work over the step's
    extra slip goes to friction if the contact slides, to its spring if it sticks.

    The stick spring's step is backward Euler (its force takes the stretch at the step's
    end, ``tangential_force``), which dissipates ``k_t (xi' - xi)^2 / 2`` a step on top of
    what the spring then holds: a dashpot of ``k_t dt / 2`` that vanishes with dt, booked as
    viscous (left out, it was the residual's largest part: 1.9 % of what a free field lost
    at the default step, halving with dt).

    Args:
        f_n: normal force (N). f_el: its elastic part ``k_e A`` (N). f_t: tangential force
            on the partner along the tangent (N).
        approach: the normal approach speed at the step's start (m/s). approach_change,
            slip_change: the change of the approach and of the tangential slip speed over
            the last step (m/s).
        dt: step (s). slip_work, damp_work: the step's frictional and tangential dashpot work
            (``tangential_force``, J). k_t: stick spring (N/m). xi, xi_new: its stretch
            before and after the step (m). crush_work: the work on the crushed overlap (J).

    Returns:
        ``(held, viscous, friction)``: the change of the energy the contact holds, and the
        step's viscous and frictional dissipation (J).
    """
    approach_mid = approach + 0.5 * approach_change
    extra = -f_t * 0.5 * slip_change * dt
    step = xi_new - xi
    held = f_el * approach_mid * dt - crush_work + 0.5 * k_t * (xi_new * xi_new - xi * xi)
    viscous = (f_n - f_el) * approach_mid * dt + damp_work + 0.5 * k_t * step * step
    friction = slip_work
    if slip_work > 0.0:
        friction += extra
    else:
        held += extra
    return held, viscous, friction


@ti.data_oriented
class ContactStage(Stage):
    """Finds overlapping pairs, applies contact forces and keeps contact memory."""

    ACCESS: ClassVar[dict[str, Access]] = {
        "compute": Access(
            reads=(
                # Model
                "body_world",
                "body_radius",
                "body_local_start",
                "body_vert_count",
                "vert_local",
                "vert_normal_local",
                "world_mu",
                "world_A",
                "world_B",
                "world_mu0",
                "world_v_star",
                "world_t_c",
                "world_memory",
                "world_rest_rule",
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
                "body_vel",
                "body_omega",
                "contact_count",
                "contact_partner",
                "contact_xi",
                "contact_elastic",
                "contact_theta",
                "contact_slip",
                "contact_crushed",
                "body_force_q",
                "body_torque_q",
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
                "body_force_q",
                "body_torque_q",
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
                "body_force_q",
                "body_torque_q",
                "body_energy",
                "body_dvel",
                "body_domega",
            ),
        ),
        "build_lists": Access(
            reads=(
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
        self.k_e = float(layout.contact_stiffness)
        self.k_v = float(layout.contact_viscosity)
        self.ratio = float(layout.tangential_stiffness)
        self.zeta = float(layout.tangential_damping)
        self.crush = float(layout.crushing_force)
        self.tol = NEWTON_TOLERANCE[layout.precision]
        self.method = int(layout.theta_method)
        self.maxv = layout.max_verts

    @ti.func
    def outline(self, i, origin):
        """Body i's outline relative to ``origin`` in a (MAXV, 2) matrix, and its count.

        Positions are float64 in either precision and only their difference is cast to
        the run's precision: clipping near the pair keeps float32 accurate in large fields,
        its resolution scaling with the bodies' size, not the domain's.
        The outline is the body's shape (``vert_local``, shared by bodies of one shape, so
        it stays in cache) turned by its rotation (``body_rot``, the integrator's cos and
        sin): four multiply-adds a vertex instead of a turned outline stored per body.
        """
        m, d = ti.static((self.model, self.data))
        x = ti.cast(d.body_pos[i] - origin, self.layout.real)  # positions are f64
        return self.turned(i, m.vert_local, x, True), m.body_vert_count[i]

    @ti.func
    def normals(self, i):
        """Outward unit normals of body i's edges in a (MAXV, 2) matrix: its shape's
        (``vert_normal_local``) turned by its rotation, as ``outline`` turns the vertices
        (``geometry.edge_normals_ti`` of the outline, without a square root an edge)."""
        zero = ti.Vector([0.0, 0.0], self.layout.real)
        return self.turned(i, self.model.vert_normal_local, zero, False)

    @ti.func
    def turned(self, i, local: ti.template(), shift, shifted: ti.template()):
        """Rows of body i's shape in ``local`` (a field of 2-vectors indexed like
        ``vert_local``) turned by the body's rotation, plus ``shift`` if ``shifted``, in a
        (MAXV, 2) matrix. Unrolled to the largest outline, so that the matrix's indices are
        constants (``geometry._min_penetration_axis_ti`` says why)."""
        m, d = ti.static((self.model, self.data))
        out = ti.Matrix.zero(self.layout.real, self.maxv, 2)
        rot = d.body_rot[i]
        c, s = rot[0], rot[1]
        start, count = m.body_local_start[i], m.body_vert_count[i]
        for k in ti.static(range(self.maxv)):
            if k < count:
                v = local[start + k]
                if ti.static(shifted):
                    out[k, 0] = shift[0] + (c * v[0] - s * v[1])
                    out[k, 1] = shift[1] + (s * v[0] + c * v[1])
                else:
                    out[k, 0] = c * v[0] - s * v[1]
                    out[k, 1] = s * v[0] + c * v[1]
        return out

    @ti.func
    def add_force(self, i, force, torque, serial: ti.template()):
        """Add a contact's force and torque to body i, in fixed point: atomically when
        bodies are stepped in parallel, plainly when a thread steps the whole world
        (``serial``); integer sums are the same in any order either way."""
        d, q, qt = ti.static((self.data, 1.0 / FORCE_QUANTUM, quantum_dtype()))
        # Truncated to whole quanta as 64-bit integers, then held as the sums' type (the
        # same integers in float64, ``backend.float_gather``).
        fx = ti.cast(ti.cast(force[0] * q, ti.i64), qt)
        fy = ti.cast(ti.cast(force[1] * q, ti.i64), qt)
        tq = ti.cast(ti.cast(torque * q, ti.i64), qt)
        if ti.static(serial):
            d.body_force_q[i] = d.body_force_q[i] + ti.Vector([fx, fy], qt)
            d.body_torque_q[i] = d.body_torque_q[i] + tq
        else:
            ti.atomic_add(d.body_force_q[i][0], fx)
            ti.atomic_add(d.body_force_q[i][1], fy)
            ti.atomic_add(d.body_torque_q[i], tq)

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
        used,
        dt,
        serial: ti.template(),
    ):
        """Contact between owner i, whose outline relative to its centroid is ``p`` (its
        edges' outward normals ``p_normals``), and
        partner j, with the pair's memory of the last step (``xi``, ``elastic``, ``theta``,
        ``last_slip``, ``crushed``: zero and ``NEW_CONTACT`` if it was not in contact).
        Returns
        the owner's new slot count, and the gap (m) by which a facing edge proved the pair
        apart (negative if none did)."""
        m, d = ti.static((self.model, self.data))
        xi_, xj_ = d.body_pos[i], d.body_pos[j]
        q, n_q = self.outline(j, xi_)
        # Most candidates (bounding circles that meet) do not touch, and one of the two
        # edges that face each other separates 99 % of those (random box of 1e4 diamonds):
        # try them before the full separating-axis test and the clip. (-14 % of a step's
        # CPU time there; the jammed pillar scene's step the same.)
        toward = ti.cast(xj_ - xi_, self.layout.real)
        gap = facing_gap_ti(p, p_normals, n_p, q, n_q, toward)
        if gap < 0.0:
            gap = facing_gap_ti(q, self.normals(j), n_q, p, n_p, -toward)
        separated = gap >= 0.0
        area = 0.0
        point = ti.math.vec2(0.0, 0.0)
        normal = ti.math.vec2(0.0, 0.0)
        width = 0.0
        if not separated:
            area, point, normal, width, _kind = overlap_normals_ti(p, p_normals, n_p, q, n_q)
        if area > 0.0:
            # point is relative to body i
            r_i, r_j = point, point + ti.cast(xi_ - xj_, self.layout.real)
            v_rel = (d.body_vel[j] + perp(d.body_omega[j], r_j)) - (
                d.body_vel[i] + perp(d.body_omega[i], r_i)
            )
            tangent = ti.Vector([-normal[1], normal[0]])
            approach = -v_rel.dot(normal)
            slip = v_rel.dot(tangent)

            # Normal: elastic on the overlap not crushed; with a strength, the overlap beyond
            # the cap is crushed (kept, not recovered) and its work is booked.
            cap_n = 0.0
            crushed_new = crushed
            if ti.static(self.layout.crushing):
                cap_n, crushed_new = crush_ti(area, crushed, width, self.k_e, self.crush)
            f_n, f_el = normal_force_ti(
                ti.max(area - crushed_new, 0.0), width, approach, self.k_e, self.k_v
            )
            crush_work = 0.0
            if ti.static(self.layout.crushing):
                f_n = ti.min(f_n, cap_n)
                if crushed_new > crushed and width > 0.0:
                    crush_work = cap_n * (crushed_new - crushed) / width

            # Tangential: a stick spring proportional to the contact width and a dashpot
            # that damps it to a fraction of critical, ``tangential_damping_ti``.
            k_t = self.ratio * self.k_e * width
            c_t = tangential_damping_ti(
                k_t,
                self.zeta,
                m.body_inv_mass[i],
                m.body_inv_inertia[i] * cross2(r_i, tangent) ** 2,
                m.body_inv_mass[j],
                m.body_inv_inertia[j] * cross2(r_j, tangent) ** 2,
            )
            mu = 0.0
            theta_new = 0.0
            slip_rate = 0.0
            w = m.body_world[i]
            if ti.static(self.layout.rate_state):
                f_trial = ti.abs(k_t * (xi + slip * dt) + c_t * slip)
                mu, theta_new, slip_rate = contact_friction_ti(
                    theta,
                    last_slip,
                    slip,
                    f_trial,
                    f_n,
                    k_t * dt + c_t,
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
            else:
                mu = m.world_mu[w]

            f_t, xi_new, slip_work, damp_work = tangential_force_ti(
                xi, slip, dt, k_t, c_t, mu * f_n
            )
            force = f_n * normal + f_t * tangent  # on j; -force on i
            self.add_force(j, force, cross2(r_j, force), serial)
            self.add_force(i, -force, -cross2(r_i, force), serial)

            # The work of the contact's forces, booked at the velocity the bodies move with
            # over the step (``contact_work_ti``): the elastic part is what the contact holds
            # (normal, on the approach, less what crushed; tangential, the stick spring's
            # energy at this step's stiffness, which follows the width), the rest is
            # dissipated. (Without a budget, ``Layout.energy`` off, none of it is computed.)
            if ti.static(self.layout.energy):
                rel_change = (d.body_dvel[j] + perp(d.body_domega[j], r_j)) - (
                    d.body_dvel[i] + perp(d.body_domega[i], r_i)
                )
                held, viscous, friction = contact_work_ti(
                    f_n,
                    f_el,
                    f_t,
                    approach,
                    -rel_change.dot(normal),
                    rel_change.dot(tangent),
                    dt,
                    slip_work,
                    damp_work,
                    k_t,
                    xi,
                    xi_new,
                    crush_work,
                )
                elastic += held
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
            used += 1
        return used, gap

    @ti.func
    def owns(self, i, j):
        """True if body i handles the pair (i, j) of two small bodies (see ``wants``)."""
        kind = ti.static(self.model.body_kind)
        dyn_i, dyn_j = kind[i] == BodyKind.DYNAMIC, kind[j] == BodyKind.DYNAMIC
        return (dyn_i and not dyn_j) or (dyn_i == dyn_j and dyn_i and i < j)

    @ti.func
    def near(self, i, j):
        """Bounding circles of bodies i and j overlap."""
        m, d = ti.static((self.model, self.data))
        reach = m.body_radius[i] + m.body_radius[j]
        return (d.body_pos[j] - d.body_pos[i]).norm_sqr() < reach * reach

    @ti.func
    def beyond_a_face(self, i, j, margin):
        """Body i's bounding circle, grown by ``margin``, lies wholly outside one face of
        body j (so they cannot overlap): a cheap rejection for large bodies, whose bounding
        circles (a wall's is half its length) meet nearly every small body of the world."""
        m, d = ti.static((self.model, self.data))
        q, n_q = self.outline(j, d.body_pos[i])  # relative to i's centroid
        r = m.body_radius[i] + margin
        outside = False
        for k in range(n_q):
            a = ti.Vector([q[k, 0], q[k, 1]])
            k1 = (k + 1) % n_q
            e = ti.Vector([q[k1, 0], q[k1, 1]]) - a
            # Outward normal of a counter-clockwise outline; i's centroid is the origin.
            if -a.dot(ti.Vector([e[1], -e[0]])) > r * e.norm():
                outside = True
        return outside

    @ti.func
    def wants(self, i, j):
        """True if body i handles the pair (i, j), j != i, of its world.

        Small dynamic bodies own their contacts with small bodies that are not dynamic and,
        among dynamic ones, those of higher id; small bodies own their contacts with large
        ones if either is dynamic (a small fixed or kinematic body, a pillar, those with
        large dynamic bodies); large bodies among themselves the lower id, if either moves.
        """
        m, _d = ti.static((self.model, self.data))
        dyn_i = m.body_kind[i] == BodyKind.DYNAMIC
        dyn_j = m.body_kind[j] == BodyKind.DYNAMIC
        keep = False
        if m.body_small[j]:
            keep = m.body_small[i] != 0 and self.owns(i, j)
        elif m.body_small[i]:
            keep = dyn_i or dyn_j
        else:
            keep = j > i and (dyn_i or dyn_j)
        return keep

    @ti.func
    def remember(self, i):
        """Body i's contact memory of the last step, copied out of its slots (which this
        step overwrites: only the owner's thread touches them, so one buffer suffices), and
        its count."""
        d, k = ti.static((self.data, self.layout.slots))
        # (Slot count, not the contact stiffness: one element when no budget is kept.)
        k_budget = ti.static(k if self.layout.energy else 1)
        old = ti.Struct(
            partner=ti.Vector.zero(ti.i32, k),
            xi=ti.Vector.zero(self.layout.real, k),
            elastic=ti.Vector.zero(self.layout.real, k_budget),
            theta=ti.Vector.zero(self.layout.real, k if self.layout.rate_state else 1),
            slip=ti.Vector.zero(self.layout.real, k if self.layout.rate_state else 1),
            crushed=ti.Vector.zero(self.layout.real, k if self.layout.crushing else 1),
        )
        n_old = d.contact_count[i]
        for s in range(n_old):
            old.partner[s] = d.contact_partner[i, s]
            old.xi[s] = d.contact_xi[i, s]
            if ti.static(self.layout.energy):
                old.elastic[s] = d.contact_elastic[i, s]
            if ti.static(self.layout.rate_state):
                old.theta[s] = d.contact_theta[i, s]
                old.slip[s] = d.contact_slip[i, s]
            if ti.static(self.layout.crushing):
                old.crushed[s] = d.contact_crushed[i, s]
        return old, n_old

    @ti.func
    def body(self, i, dt, serial: ti.template()):
        """Every contact of owner i with the partners of its neighbour list whose bounding
        circles meet its own (ascending ids, so the sums of a body do not depend on how the
        list was built); the memory of the last step is read from its slots and this step's
        written over it."""
        m, d, nb = ti.static((self.model, self.data, self.neighbours))
        old, n_old = self.remember(i)
        used = 0
        # The owner's outline and its edges' normals once for all its candidates.
        p, n_p = self.outline(i, d.body_pos[i])
        p_normals = self.normals(i)
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
            # The pair's memory from the last step, if it was in contact then.
            xi = ti.cast(0.0, self.layout.real)
            elastic = ti.cast(0.0, self.layout.real)
            theta = ti.cast(NEW_CONTACT, self.layout.real)
            last_slip = ti.cast(0.0, self.layout.real)
            crushed = ti.cast(0.0, self.layout.real)
            for s in range(n_old):
                if old.partner[s] == j:
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
    def gap_bound(self, i, j, gap, path_i):
        """What ``nbr_gap`` keeps of a pair found ``gap`` apart (m; negative: not proven
        apart, -1 kept): the gap less a margin for round-off (``GAP_MARGIN`` of the two
        circumradii, far above the error of outlines turned and shifted in float32), plus
        both bodies' paths now, rounded down to float32. While the paths sum to less, no
        point of either body can have moved into the other."""
        m, nb = ti.static((self.model, self.neighbours))
        bound = ti.cast(-1.0, ti.f32)
        margin = GAP_MARGIN * ti.cast(m.body_radius[i] + m.body_radius[j], ti.f64)
        if gap > margin:
            total = gap - margin + path_i + nb.nbr_path[j]
            bound = ti.cast(total * (1.0 - 1e-6), ti.f32)  # f32 rounds to nearest: below
        return bound

    @ti.func
    def list_add(self, i, j, n):
        """Append j to body i's list (``n`` entries so far) if i owns the pair and their
        bounding circles come within the skin (for a large partner, also if i's circle does
        not lie wholly beyond one of its faces); returns the new count, which may pass the
        list's length (reported by ``end_list``)."""
        m, d, nb = ti.static((self.model, self.data, self.neighbours))
        skin = ti.static(self.layout.skin)
        if j != i and self.wants(i, j):
            reach = m.body_radius[i] + m.body_radius[j] + skin
            if (d.body_pos[j] - d.body_pos[i]).norm_sqr() < reach * reach:
                if m.body_small[j] or not self.beyond_a_face(i, j, skin):
                    if n < self.layout.nbr_len:
                        nb.nbr_ids[i, n] = j
                    n += 1
        return n

    @ti.func
    def end_list(self, i, n):
        """Close body i's list of ``n`` entries: its count, where body i stands now, and the
        overflow report."""
        d, nb = ti.static((self.data, self.neighbours))
        nb.nbr_count[i] = ti.min(n, self.layout.nbr_len)
        nb.nbr_ref_pos[i] = d.body_pos[i]
        nb.nbr_ref_angle[i] = d.body_angle[i]
        # No entry proven apart yet; paths count from here (the world's lists are rebuilt
        # together, so a partner's path restarts too).
        nb.nbr_path[i] = 0.0
        for k in range(ti.min(n, self.layout.slots)):
            nb.nbr_gap[i, k] = ti.cast(-1.0, ti.f32)
        if n > self.layout.nbr_len:
            self.raise_status(self.model.body_world[i], Status.LIST_OVERFLOW, n)

    @ti.func
    def raise_status(self, w, code: ti.template(), value):
        """Raise world w's status word ``code`` to ``value``: atomically, or where integer
        atomics fail inside loops (``backend.float_gather``) by a plain store when it is
        higher, which another body of the world may overwrite with its own count above
        the limit (the overflow is still reported; the count may not be the largest)."""
        if ti.static(backend.float_gather()):
            if value > self.data.status[w, code]:
                self.data.status[w, code] = value
        else:
            ti.atomic_max(self.data.status[w, code], value)

    @ti.func
    def build_list(self, i):
        """Body i's neighbour list from every body of its world (one thread per world):
        ascending by construction."""
        m, _d = ti.static((self.model, self.data))
        w = m.body_world[i]
        n = 0
        for j in range(m.world_body_start[w], m.world_body_start[w + 1]):
            n = self.list_add(i, j, n)
        self.end_list(i, n)

    @ti.func
    def build_list_hashed(self, i):
        """Body i's neighbour list from the 3 x 3 cells of the spatial hash around it and the
        large bodies of its world, sorted ascending: the same list as ``build_list``."""
        m, d, h, nb = ti.static((self.model, self.data, self.hash, self.neighbours))
        w = m.body_world[i]
        n = 0
        if m.body_small[i]:
            c = h.cell_of(d.body_pos[i])
            for k in range(9):
                cell = c + ti.Vector([k % 3 - 1, k // 3 - 1])
                b = bucket_of(cell, w, h.mask)
                for e in range(h.bucket_end[b] - h.bucket_count[b], h.bucket_end[b]):
                    j = h.sorted_ids[e]
                    # A bucket may hold other cells or worlds: keep only this cell's bodies.
                    if m.body_world[j] == w:
                        cj = h.cell_of(d.body_pos[j])
                        if cj[0] == cell[0] and cj[1] == cell[1]:
                            n = self.list_add(i, j, n)
        for g in range(m.world_large_start[w], m.world_large_start[w + 1]):
            n = self.list_add(i, m.large_ids[g], n)
        # Ascending ids (insertion sort of a few entries).
        for k in range(1, ti.min(n, self.layout.nbr_len)):
            v = nb.nbr_ids[i, k]
            s = k
            while s > 0 and nb.nbr_ids[i, s - 1] > v:
                nb.nbr_ids[i, s] = nb.nbr_ids[i, s - 1]
                s -= 1
            nb.nbr_ids[i, s] = v
        self.end_list(i, n)

    @ti.kernel
    def build_lists(self):
        """Rebuild the neighbour lists of every stale world from the spatial hash (built
        from the current positions first, ``SpatialHash.build``)."""
        m, nb = ti.static((self.model, self.neighbours))
        for i in range(self.layout.n_bodies):
            if nb.world_nbr_stale[m.body_world[i]]:
                self.build_list_hashed(i)
        for w in range(self.layout.n_worlds):
            nb.world_nbr_stale[w] = 0
            if w == 0:
                nb.nbr_rebuild[None] = 0

    @ti.func
    def listed(self, i, dt, serial: ti.template()):
        """Body i's contacts, its candidates taken from its neighbour list; ``serial``: one
        thread steps the whole world (``WorldStepper``), so forces need no atomics. (The
        list is read in place: a copy of its near entries cost 2 % of a step.)"""
        self.body(i, dt, serial)

    @ti.kernel
    def compute(self):
        """Forces of every contact of the step in parallel over bodies, candidates from the
        neighbour lists, and the contacts' memory."""
        for i in range(self.layout.n_bodies):
            self.listed(i, self.data.time_step[None], False)
