"""NumPy twin of one contact: the forces, work and memory of a pair, as the contact kernel.

:func:`contact_force` is the reference of ``contact.ContactStage.pair``, one pair at a time
in float64: the Hopkins (1992) overlap of the two outlines (``polygon.overlap``: area ``A``,
contact point, normal from ``i`` into ``j``, width ``L``); the velocity of ``j`` relative to
``i`` at the contact point, split into the approach speed ``v_n`` and the slip ``v_t``; the
normal force ``F_n = max(k_e (A - A_c) + k_v L v_n, 0)``, with ``A_c`` the crushed area when
the ice has a strength (``contact_law.crush``); the tangential stick spring
``k_t = ratio k_e L`` and its dashpot on the stretch ``xi``, capped at ``mu F_n`` (Cundall and
Strack 1979); ``mu`` from Coulomb, or from the rate-and-state row of the world through
``slip.contact_friction`` (the sliding rate solved in the step, the rule below v_star); the
stored elastic energy grows by the elastic forces' work. ``ContactMemory`` is what a contact
carries from one step to the next. The whole step, which gathers these over every owned pair,
is ``reference.reference_step``. NumPy only: importing it starts no Taichi.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..physics.contact_coupled import coupled_impulses
from ..physics.contact_law import (
    contact_work,
    crush,
    inverse_mass_along,
    normal_force,
    tangential_damping,
    tangential_force,
)
from ..physics.contact_step import pair_impulses, sliding_impedance, stick_or_slide
from ..physics.friction import method_code
from ..physics.polygon import overlap
from ..physics.slip import (
    NEW_CONTACT,
    NEWTON_TOLERANCE,
    NO_INTERFACE,
    contact_friction,
    slide_steps,
    sliding_steps,
)

__all__ = ["ContactForce", "ContactMemory", "contact_force", "settle"]


@dataclass(frozen=True)
class ContactMemory:
    """What a contact carries from one step to the next (one kernel contact slot).

    Attributes:
        xi: tangential spring stretch along the tangent (m).
        area: overlap area at the last step (m^2).
        elastic: elastic energy the contact holds (J), normal and tangential: booked as
            severed (``BodyEnergy.SEVERED``) when the contact ends.
        theta: rate-and-state variable; ``slip.NO_INTERFACE`` when the contact has no
            sliding interface (and for Coulomb), ``slip.NEW_CONTACT`` before its first step.
        slip: the law's slip rate along the tangent (m/s, signed; 0 for Coulomb).
        crushed: overlap area crushed so far (m^2).
        force: the analytic step's mean normal and tangential force on the partner over the
            last step (N).
    """

    xi: float = 0.0
    area: float = 0.0
    elastic: float = 0.0
    theta: float = NEW_CONTACT
    slip: float = 0.0
    crushed: float = 0.0
    force: tuple[float, float] = (0.0, 0.0)


class ContactForce(NamedTuple):
    """One contact of one step, as the kernel evaluates it.

    Attributes:
        area: overlap area (m^2). point: ``(2,)`` contact point (m). normal: ``(2,)`` unit
            normal from the owner into the partner. width: contact width ``L`` (m).
            kind: ``codes.OverlapKind``.
        approach: approach speed along the normal (m/s), positive when closing.
        slip: tangential velocity of the partner relative to the owner (m/s), along
            ``tangent = (-normal_y, normal_x)``.
        mu: friction coefficient of the step (the mean over its sub-steps where the slide
            took them, ``slip.sliding_steps``). normal_force: ``F_n`` (N), clamped at 0.
        elastic_force: ``k_e A`` (N). tangential_force: along the tangent, on the partner (N).
        force: ``(2,)`` total force on the partner (N); the owner gets ``-force``.
        torque_owner, torque_partner: about each centroid (N m).
        memory: the contact's new memory (stretch, area, stored elastic energy, theta).
        slip_work: frictional work of the step (J). viscous_work: dashpot work (J).
        crushing_work: work on the crushed overlap (J). sliding_rate: V of the law (m/s,
            signed along the tangent; 0 for Coulomb; the last sub-step's where the slide
            took sub-steps).
        shift, shift_torque_owner, shift_torque_partner: the analytic step's position
            impulse on the partner as a force, ``2 Q / dt^2`` (N), and its torques (None and
            0 for the Euler step).
        booking: the analytic step's ``SETTLE_LANES`` values (``settle``), None where the
            step is not solved over (Euler's, or a pair it cannot solve).
        step_area: the overlap area (m^2) at the pose the step takes the contact at, whose
            point, normal and width are those above: the mid-step pose's with ``mid`` where
            the outlines overlap there, else ``area``.
    """

    area: float
    point: np.ndarray
    normal: np.ndarray
    width: float
    kind: int
    approach: float
    slip: float
    mu: float
    normal_force: float
    elastic_force: float
    tangential_force: float
    force: np.ndarray
    torque_owner: float
    torque_partner: float
    memory: ContactMemory
    slip_work: float
    viscous_work: float
    crushing_work: float = 0.0
    sliding_rate: float = 0.0
    shift: np.ndarray | None = None
    shift_torque_owner: float = 0.0
    shift_torque_partner: float = 0.0
    sliding: bool = False
    booking: tuple | None = None
    step_area: float | None = None


def _cross(a, b) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _spin(omega: float, r) -> np.ndarray:
    """omega (z) x r: velocity of a point at ``r`` on a body spinning at ``omega``."""
    return np.array([-omega * r[1], omega * r[0]])


def contact_force(
    p: np.ndarray,
    q: np.ndarray,
    pos_owner,
    vel_owner,
    omega_owner: float,
    pos_partner,
    vel_partner,
    omega_partner: float,
    *,
    dt: float,
    k_e: float,
    k_v: float,
    ratio: float,
    law,
    inv_mass: tuple[float, float],
    inv_inertia: tuple[float, float],
    zeta: float = 0.25,
    slide_resolution: float = 0.0,
    dvel: tuple = ((0.0, 0.0), (0.0, 0.0)),
    domega: tuple[float, float] = (0.0, 0.0),
    memory: ContactMemory | None = None,
    method: int | None = None,
    crushing_force: float | None = None,
    tol: float = NEWTON_TOLERANCE["f64"],
    analytic: bool = False,
    coupled: bool = False,
    mid: tuple | None = None,
) -> ContactForce | None:
    """NumPy reference of ``ContactStage.pair``: the contact between an owner and a partner.

    The outlines and centroids may be given in any frame, the same for all four; the
    kernel takes the owner's centroid as the origin (``outline``), which keeps float32
    accurate far from the world origin.

    Args:
        p: ``(n, 2)`` outline of the owner (m), counter-clockwise.
        q: ``(m, 2)`` outline of the partner (m), in the frame of ``p``.
        pos_owner, vel_owner, omega_owner: centroid (m) in that frame, velocity (m/s), spin
            (rad/s).
        pos_partner, vel_partner, omega_partner: likewise for the partner.
        dt: time step (s). k_e: N/m^2. k_v: Pa s.
        ratio: ``k_t / (k_e L)`` (``[ice] tangential_stiffness``).
        law: the world's friction: a Coulomb mu (float), or a law whose ``contact_row`` the
            rate-and-state contact runs (any law: Coulomb is A = B = 0).
        inv_mass, inv_inertia: ``1 / m`` (1/kg) and ``1 / I`` (1/(kg m^2)) of owner and
            partner, 0 for a fixed or kinematic body.
        zeta: the tangential dashpot's fraction of critical damping
            (``[ice] tangential_damping``; ``contact_law.tangential_damping``).
        slide_resolution: a rate-and-state contact's sub-steps in the Euler step
            (``[ice] slide_resolution``; ``slip.sliding_steps``), 0 for one step.
        dvel, domega: the velocity (m/s) and spin (rad/s) changes of the owner's and the
            partner's last steps, with which the contact books its work
            (``contact_law.contact_work``).
        memory: the contact's memory from the last step, or None for a new contact.
        method: ``codes.ThetaMethod`` for theta; default the law's own method.
        crushing_force: strength x thickness (N/m), or None for no strength.
        tol: Newton's tolerance of the sliding rate (``slip.NEWTON_TOLERANCE``).
        analytic: the analytic step (``physics.contact_step``): the normal and the stuck
            tangential spring-dashpot solved over the step, the pair's other forces told
            from ``dvel``, ``domega`` and the memory's ``force``.
        coupled: with ``analytic``, the pair's normal and stuck tangent solved together
            (``contact_coupled.coupled_impulses``, the ``coupled`` integrator), told the
            cross term of the pair's inverse mass and the friction it would slide at (the
            Coulomb mu, or rate and state's mu0: its mu is solved after the impulses).
        mid: with ``analytic``, ``(p, q, pos_owner, pos_partner)`` at the configuration
            predicted for mid-step (``reference_step`` with ``ReferenceModel.midstep``: each
            body in free flight for h/2), in the frame of ``p``. Where the outlines overlap
            there too, the contact is linearised about that configuration: its normal,
            point, width and lever arms, hence the force's direction, its torques and the
            pair's inverse masses, are the mid-step's, and the flow starts from the
            approach and slip of the step's velocities at the mid-step point and from the
            mid-step overlap's depth less h/2 of that approach. Held at the step's start
            instead, they are a first-order error of the spin and the contact's duration
            even without friction (docs/accuracy.md, issue 30; the ``midstep`` integrator).

    Returns:
        A :class:`ContactForce` (its ``point`` in the frame of ``p``), or None if the
        outlines do not overlap.
    """
    ov = overlap(p, q)
    if not ov.area > 0.0:
        return None
    area, point, normal, width = ov.area, ov.centroid, ov.normal, ov.width
    r_i = point - np.asarray(pos_owner, dtype=np.float64)
    r_j = point - np.asarray(pos_partner, dtype=np.float64)
    v_rel = (np.asarray(vel_partner, dtype=np.float64) + _spin(omega_partner, r_j)) - (
        np.asarray(vel_owner, dtype=np.float64) + _spin(omega_owner, r_i)
    )
    tangent = np.array([-normal[1], normal[0]])
    approach = -float(v_rel @ normal)
    slip = float(v_rel @ tangent)
    # The mid-step linearisation (``mid``): where the outlines still overlap at mid-step.
    depth_area, shift_back = area, 0.0
    if analytic and mid is not None:
        om = overlap(mid[0], mid[1])
        if om.area > 0.0:
            point, normal, width = om.centroid, om.normal, om.width
            r_i = point - np.asarray(mid[2], dtype=np.float64)
            r_j = point - np.asarray(mid[3], dtype=np.float64)
            v_rel = (np.asarray(vel_partner, dtype=np.float64) + _spin(omega_partner, r_j)) - (
                np.asarray(vel_owner, dtype=np.float64) + _spin(omega_owner, r_i)
            )
            tangent = np.array([-normal[1], normal[0]])
            approach = -float(v_rel @ normal)
            slip = float(v_rel @ tangent)
            depth_area, shift_back = om.area, 0.5 * dt * approach
    old = memory if memory is not None else ContactMemory()
    cap_n, crushed = math.inf, old.crushed
    if crushing_force is not None:
        cap_n, crushed = crush(area, old.crushed, width, k_e, crushing_force)
    f_n, f_el = normal_force(max(area - crushed, 0.0), width, approach, k_e, k_v)
    crushing_work = 0.0
    if crushing_force is not None:
        f_n = min(f_n, cap_n)
        if crushed > old.crushed and width > 0.0:
            crushing_work = cap_n * (crushed - old.crushed) / width

    k_t = ratio * k_e * width
    c_t = tangential_damping(
        k_t,
        zeta,
        inv_mass[0],
        inv_inertia[0] * _cross(r_i, tangent) ** 2,
        inv_mass[1],
        inv_inertia[1] * _cross(r_j, tangent) ** 2,
    )
    change = (np.asarray(dvel[1], dtype=np.float64) + _spin(domega[1], r_j)) - (
        np.asarray(dvel[0], dtype=np.float64) + _spin(domega[0], r_i)
    )
    exact = False
    q_n = p_t = q_t = 0.0
    xi1 = old.xi
    if analytic:
        ci_n, cj_n = _cross(r_i, normal), _cross(r_j, normal)
        ci_t, cj_t = _cross(r_i, tangent), _cross(r_j, tangent)
        inv_n = inverse_mass_along(
            inv_mass[0], inv_inertia[0], ci_n, inv_mass[1], inv_inertia[1], cj_n
        )
        inv_t = inverse_mass_along(
            inv_mass[0], inv_inertia[0], ci_t, inv_mass[1], inv_inertia[1], cj_t
        )
        exact = width > 0.0 and inv_n > 0.0 and inv_t > 0.0
    if exact:
        solve, extra = pair_impulses, ()
        if coupled:
            solve = coupled_impulses
            extra = (
                inv_inertia[0] * ci_n * ci_t + inv_inertia[1] * cj_n * cj_t,
                float(law) if isinstance(law, (int, float)) else law.contact_row()["mu0"],
            )
        f_n, f_el, q_n, p_t, q_t, xi1, a_n, a_t = solve(
            max(depth_area - crushed, 0.0) / width - shift_back,
            approach,
            slip,
            old.xi,
            memory is None,
            -float(change @ normal),
            float(change @ tangent),
            old.force,
            dt,
            k_e * width,
            k_v * width,
            k_t,
            c_t,
            inv_n,
            inv_t,
            *extra,
        )
        if crushing_force is not None and f_n > cap_n:
            scale = cap_n / f_n
            f_n, f_el, q_n = cap_n, f_el * scale, q_n * scale
    theta_new, v = NO_INTERFACE, 0.0
    mu_step = None  # the step's mean mu, where sub-steps took it
    steps = None  # the Euler step's rate-and-state contact: the law with its tangential step
    if isinstance(law, (int, float)):
        mu, theta_new = float(law), 0.0  # no theta is kept
    else:
        row = law.contact_row()
        code = method_code(getattr(law, "method", "exponential")) if method is None else method
        rate = [row[k] for k in ("A", "B", "mu0", "v_star", "t_c", "memory", "rest_rule")]
        if not analytic:
            steps = sliding_steps(
                old.theta, old.slip, slip, old.xi, f_n, k_t, c_t, dt, *rate, code, tol,
                slide_resolution,
            )  # fmt: skip
            mu, theta_new, v = steps[:3]
        else:
            f_trial = abs(k_t * (old.xi + slip * dt) + c_t * slip)
            impedance = k_t * dt + c_t
            if exact:
                f_trial = abs(p_t) / dt
                impedance = sliding_impedance(k_t, c_t, dt)
            mu, theta_new, v = contact_friction(
                old.theta, old.slip, slip, f_trial, f_n, impedance, dt, *rate, code, tol
            )

    shift = None
    # Whether the cap binds, by the very test of ``stick_or_slide`` and ``tangential_force``
    # (the same operations in the same order, so the same answer to the last bit).
    if exact:
        sliding = abs(p_t) > mu * f_n * dt
        f_t, g_t, xi_new, slip_work, damp_work = stick_or_slide(
            p_t, q_t, old.xi, xi1, slip, dt, k_t, c_t, mu * f_n * dt, mu * q_n
        )
    elif steps is not None:
        f_t, xi_new, slip_work, damp_work = steps[3:7]
        sliding = abs(-k_t * (old.xi + slip * dt) - c_t * slip) > mu * f_n
        if slide_steps(k_t, c_t, dt, row["memory"], slide_resolution, old.theta) > 1:
            # in sub-steps: the step's mean mu, and sliding if its last sub-step slid (the
            # state it leaves, as theta and the slip rate)
            mu_step, sliding = steps[7:]
    else:
        sliding = abs(-k_t * (old.xi + slip * dt) - c_t * slip) > mu * f_n
        f_t, xi_new, slip_work, damp_work = tangential_force(old.xi, slip, dt, k_t, c_t, mu * f_n)
    force = f_n * normal + f_t * tangent
    if analytic:
        shift = force.copy()  # Euler's: the mean force held over the step
        if exact:
            shift = (2.0 * q_n / (dt * dt)) * normal + g_t * tangent
    # The work of its forces at the bodies' mid-step velocity (``contact_law.contact_work``).
    approach_change, slip_change = -float(change @ normal), float(change @ tangent)
    if exact:  # this step's change, its other forces' and its own
        approach_change = (a_n - inv_n * f_n) * dt
        slip_change = (a_t + inv_t * f_t) * dt
        if coupled:  # and its cross term
            approach_change -= extra[0] * f_t * dt
            slip_change += extra[0] * f_n * dt
    held, viscous, friction = contact_work(
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
        old.xi,
        xi_new,
        crushing_work,
    )
    booking = None
    if exact:  # what ``settle`` books again once the bodies have moved
        booking = (
            approach_change,
            slip_change,
            0.5 * dt * f_el,
            0.5 * dt * (f_n - f_el),
            -0.5 * dt * f_t,
            1.0 if slip_work > 0.0 else 0.0,
            float(normal[0]),
            float(normal[1]),
            ci_n,
            cj_n,
            ci_t,
            cj_t,
        )
    return ContactForce(
        area=area,
        step_area=depth_area,
        point=point,
        normal=normal,
        width=width,
        kind=ov.kind,
        approach=approach,
        slip=slip,
        mu=mu if mu_step is None else mu_step,
        normal_force=f_n,
        elastic_force=f_el,
        tangential_force=f_t,
        force=force,
        torque_owner=-_cross(r_i, force),
        torque_partner=_cross(r_j, force),
        memory=ContactMemory(
            xi=xi_new,
            area=area,
            elastic=old.elastic + held,
            theta=theta_new,
            slip=v,
            crushed=crushed,
            force=(f_n, f_t),
        ),
        slip_work=friction,
        viscous_work=viscous,
        crushing_work=crushing_work,
        sliding_rate=v,
        shift=shift,
        shift_torque_owner=0.0 if shift is None else -_cross(r_i, shift),
        shift_torque_partner=0.0 if shift is None else _cross(r_j, shift),
        sliding=bool(sliding),
        booking=booking,
    )


def settle(booking: tuple, dvel: tuple, domega: tuple[float, float]) -> tuple[float, float, float]:
    """The analytic step's contact work booked again once the bodies have moved: the
    reference of ``ContactLists.settle``.

    ``contact_force`` books a contact's work at the pair's velocity change estimated before
    the bodies move: its other forces' of the last step and its own of this one
    (``pair_impulses``' ``a_n``, ``a_t``), exact for a lone pair. Where every force of a
    jam grows together, the estimate is off by the others' growth, every step, the same
    way: the loaded stack's budget was left open by 0.1 of the work done at 0.8 stable_dt
    (docs/accuracy.md). With the change the bodies took (the integrator's), the work is the
    one their kinetic energy took, to round-off.

    Args:
        booking: ``ContactForce.booking`` (the kernel's ``contact_booking`` lanes).
        dvel: the owner's and the partner's velocity change of the step (m/s).
        domega: the same of their spin (rad/s).

    Returns:
        ``(held, viscous, friction)`` to add to the contact's held energy and the owner's
        viscous and frictional terms (J).
    """
    b = booking
    dv = np.asarray(dvel[1], dtype=np.float64) - np.asarray(dvel[0], dtype=np.float64)
    n = np.array([b[6], b[7]])
    t = np.array([-b[7], b[6]])
    d_n = -float(dv @ n) - domega[1] * b[9] + domega[0] * b[8] - b[0]
    d_t = float(dv @ t) + domega[1] * b[11] - domega[0] * b[10] - b[1]
    held, tangential = b[2] * d_n, b[4] * d_t
    friction = 0.0
    if b[5] > 0.0:
        friction = tangential
    else:
        held += tangential
    return held, b[3] * d_n, friction
