"""The contact laws as Taichi functions: the twins of ``contact_law``, for the contact kernel.

``normal_force_ti``, ``crush_ti``, ``tangential_damping_ti``, ``tangential_force_ti`` and
``contact_work_ti``, in the order of their NumPy twins in ``contact_law`` (where each law is
described), after the two vector helpers the kernel uses with them (``cross2``, ``perp``). No
field access: ``contact.ContactStage.pair`` reads the fields and calls these.
"""

# No "from __future__ import annotations": Taichi reads the annotations of its functions.

import taichi as ti

__all__ = [
    "contact_work_ti",
    "cross2",
    "crush_ti",
    "inverse_mass_along_ti",
    "normal_force_ti",
    "perp",
    "tangential_damping_ti",
    "tangential_force_ti",
]


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
    """Taichi twin of :func:`contact_law.normal_force`."""
    elastic = k_e * area
    return ti.max(elastic + k_v * width * approach_speed, 0.0), elastic


@ti.func
def crush_ti(area, crushed, width, k_e, force_per_width):
    """Taichi twin of :func:`contact_law.crush`."""
    cap = force_per_width * width
    crushed_new = crushed
    if k_e * (area - crushed) > cap:
        crushed_new = area - cap / k_e
    return cap, crushed_new


@ti.func
def inverse_mass_along_ti(inv_mass_i, inv_inertia_i, cross_i, inv_mass_j, inv_inertia_j, cross_j):
    """Taichi twin of :func:`contact_law.inverse_mass_along`."""
    return (
        inv_mass_i
        + inv_inertia_i * cross_i * cross_i
        + inv_mass_j
        + inv_inertia_j * cross_j * cross_j
    )


@ti.func
def tangential_damping_ti(k_t, zeta, inv_mass_i, inv_turn_i, inv_mass_j, inv_turn_j):
    """Taichi twin of :func:`contact_law.tangential_damping`."""
    inv_m = inv_mass_i + inv_turn_i + inv_mass_j + inv_turn_j
    return 2.0 * zeta * ti.sqrt(k_t / inv_m)


@ti.func
def tangential_force_ti(xi, slip_speed, dt, k_t, c_t, cap):
    """Taichi twin of :func:`contact_law.tangential_force`."""
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
    """Taichi twin of :func:`contact_law.contact_work`."""
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
