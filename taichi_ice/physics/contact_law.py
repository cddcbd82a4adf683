"""The contact laws (Hopkins 1992; Cundall and Strack 1979) as NumPy functions.

Pure functions of one contact, values in, values out: ``normal_force`` (elastic on the overlap
area, viscous on the contact width), ``crush`` (the ice's strength caps the elastic force),
``tangential_damping`` (the stick spring's dashpot), ``tangential_force`` (the stick
spring-dashpot capped at mu F_n) and ``contact_work`` (the work of a contact's forces, held and
dissipated). They are the references that ``reference_contact.contact_force`` composes into a whole
pair; their Taichi twins, which the contact kernel (``contact.ContactStage.pair``) calls, are
``contact_law_ti``'s, in the same order. NumPy only: importing it starts no Taichi. What the
contact stage does with them is told in ``contact``.
"""

import math

__all__ = [
    "contact_work",
    "crush",
    "inverse_mass_along",
    "normal_force",
    "tangential_damping",
    "tangential_force",
]


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


def inverse_mass_along(inv_mass_i, inv_inertia_i, cross_i, inv_mass_j, inv_inertia_j, cross_j):
    """1/kg: the inverse of the mass two bodies move with at their contact point along a
    direction ``d``, ``1/m_i + (r_i x d)^2 / I_i + 1/m_j + (r_j x d)^2 / I_j`` (``cross_i``,
    ``cross_j``: ``r x d`` of each; 0 terms for a fixed or kinematic body)."""
    return (
        inv_mass_i
        + inv_inertia_i * cross_i * cross_i
        + inv_mass_j
        + inv_inertia_j * cross_j * cross_j
    )


def tangential_damping(k_t, zeta, inv_mass_i, inv_turn_i, inv_mass_j, inv_turn_j):
    """Dashpot ``c_t`` (N s/m) that damps the stick spring ``k_t`` to ``zeta`` of critical.

    The spring holds the two bodies' contact points together along the tangent ``t``, where
    they move as one mass ``m_t``: ``1 / m_t = 1/m_i + (r_i x t)^2 / I_i + 1/m_j +
    (r_j x t)^2 / I_j`` (0 for a fixed or kinematic body), so ``c_t = 2 zeta sqrt(k_t m_t)``:
    the same damping ratio whatever the floes' size. The default ``[ice] tangential_damping``
    is 0.25: the contact checks of ``validation.contact_convergence`` give the same results from
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
