"""Friction at a DEM contact: the sliding rate, and the law's rule below ``v_star``.

A contact's tangential force comes from a stick spring ``k_t`` and dashpot ``c_t`` on the
stretch ``xi``, capped at ``mu F_n`` (``contact.tangential_force``). The rate-and-state law
needs the contact's slip rate V, and that is not the tangential speed of the two surfaces:
part of that speed stretches the stick spring. Here V is the **sliding rate**, the part of
the displacement the spring does not take up, so a stuck contact has V = 0 exactly:

    F_trial = -k_t (xi + s dt) - c_t s                 the force if the contact stuck
    V       = max(|F_trial| - mu(V) F_n, 0) / K,       K = k_t dt + c_t

(the backward-Euler relaxation of the spring-dashpot toward the cap in
``tangential_force`` slides exactly ``V dt`` in the step). mu depends on V through
``x = ln(V / v_star)`` and through this step's update of theta, so V is solved per contact,
in the step, before the force is applied: with ``y = x`` the equation is

    g(y) = K v_star e^y + F_n max(c0 + c1 y, 0) - |F_trial| = 0,      y >= 0

where ``mu0 + theta_new(y) + A y = c0 + c1 y`` (every integrator's theta update is affine in
x when x is held over the step). g is convex, so Newton's method started above the root
(``V_hi``, the sliding rate at the smallest mu on the way) falls onto the largest root
monotonically, in a few iterations.

Below ``v_star`` (which includes sticking) the law does not apply, and ``RestRule`` says
what does:

- ``paper`` (default): mu = mu0 exactly, as the paper states; the interface ends, and a
  contact that slides again is a new interface with theta in equilibrium, ``-B x``, at its
  slip rate (the paper's "on initiation of a new sliding interface");
- ``healing``: theta keeps relaxing toward 0 over t_c and mu = max(mu0 + theta, 0): a
  contact that comes to rest after fast sliding is weak at first and heals;
- ``frozen``: theta is held and mu = max(mu0 + theta, 0) until the contact slides again.

A new contact has no interface yet (``NO_INTERFACE``). A law without memory (the
steady-state law) starts a new interface every step: mu = mu_ss(V) at once.

Twins (the package's convention): ``contact_friction`` (NumPy, scalars) and
``contact_friction_ti`` (Taichi, called by the contact kernel).
"""

# No ``from __future__ import annotations``: Taichi reads the annotations of its functions.

import math

import taichi as ti

from .codes import RestRule
from .friction import theta_step, theta_step_ti

# theta of a contact with no sliding interface (new, or ended below v_star under the paper's
# rule). theta itself is never positive (it starts at -B x <= 0 and relaxes toward -B x).
NO_INTERFACE = 1.0e30
_NO_INTERFACE_ABOVE = 0.5 * NO_INTERFACE
# Newton stops once a step moves y = ln(V / v_star) by less than this (relative to 1 + y),
# or after NEWTON_ITERATIONS; convergence is quadratic from above, so a handful suffice.
NEWTON_TOLERANCE = {"f64": 1e-13, "f32": 1e-6}
NEWTON_ITERATIONS = 30


def _newton_start(c0, c1, f_trial, f_n, K, v_star):
    # Sliding rate at the smallest mu over y >= 0: an upper bound of the root.
    mu_min = max(c0, 0.0) if c1 >= 0.0 else 0.0
    return math.log((f_trial - f_n * mu_min) / (K * v_star))


def contact_friction(
    theta, f_trial, f_n, K, dt, A, B, mu0, v_star, t_c, memory, rule, method, tol=1e-13
):
    """mu of a contact this step and its new theta (NumPy twin of ``contact_friction_ti``).

    Args:
        theta: the contact's theta from the last step, ``NO_INTERFACE`` if none.
        f_trial: ``|F_trial|`` (N), the tangential force if the contact stuck this step.
        f_n: normal force (N, >= 0). K: ``k_t dt + c_t`` (N s/m). dt: step (s).
        A, B, mu0, v_star, t_c: the law's parameters.
        memory: 1 if theta is carried, 0 for the steady-state law.
        rule: ``codes.RestRule`` below v_star. method: ``codes.ThetaMethod``.
        tol: Newton's tolerance on ``y = ln(V / v_star)``.

    Returns:
        ``(mu, theta_new, V)``: mu for the cap ``mu F_n``, theta to carry (``NO_INTERFACE``
        when the contact has no interface), and the sliding rate (m/s).
    """
    fresh = theta > _NO_INTERFACE_ABOVE or memory == 0
    # Below v_star.
    mu_low, theta_low = mu0, NO_INTERFACE
    if not fresh and rule == RestRule.HEALING:
        theta_low = float(theta_step(theta, 0.0, 0.0, 0.0, dt, B, t_c, method))
        mu_low = max(mu0 + theta_low, 0.0)
    elif not fresh and rule == RestRule.FROZEN:
        theta_low = theta
        mu_low = max(mu0 + theta, 0.0)
    elif fresh and memory != 0 and rule != RestRule.PAPER:
        theta_low = 0.0  # an interface at rest: in equilibrium at v_star
    # At or above v_star: mu(y) = max(c0 + c1 y, 0).
    a, b = 0.0, -B
    if not fresh:
        a = float(theta_step(theta, 0.0, 0.0, 0.0, dt, B, t_c, method))
        b = float(theta_step(theta, 1.0, 1.0, 1.0, dt, B, t_c, method)) - a
    c0, c1 = mu0 + a, A + b
    if K * v_star + f_n * max(c0, 0.0) - f_trial >= 0.0:
        v = max(f_trial - mu_low * f_n, 0.0) / K if K > 0.0 else 0.0
        return mu_low, theta_low, v
    y = _newton_start(c0, c1, f_trial, f_n, K, v_star)
    for _ in range(NEWTON_ITERATIONS):
        e = K * v_star * math.exp(y)
        m = c0 + c1 * y
        g = e + f_n * max(m, 0.0) - f_trial
        gp = e + (f_n * c1 if m > 0.0 else 0.0)
        dy = g / gp
        y -= dy
        if dy <= tol * (1.0 + y):
            break
    theta_new = -B * y if fresh else float(theta_step(theta, y, y, y, dt, B, t_c, method))
    return max(mu0 + theta_new + A * y, 0.0), theta_new, v_star * math.exp(y)


@ti.func
def contact_friction_ti(
    theta,
    f_trial,
    f_n,
    K,
    dt,
    A,
    B,
    mu0,
    v_star,
    t_c,
    memory,
    rule,
    method: ti.template(),
    tol: ti.template(),
):
    """Taichi twin of :func:`contact_friction`; returns ``(mu, theta_new, V)``. ``tol`` is a
    compile-time constant, ``NEWTON_TOLERANCE`` of the precision."""
    fresh = theta > _NO_INTERFACE_ABOVE or memory == 0
    mu_low = mu0
    theta_low = NO_INTERFACE
    if not fresh and rule == RestRule.HEALING:
        theta_low = theta_step_ti(theta, 0.0, 0.0, 0.0, dt, B, t_c, method)
        mu_low = ti.max(mu0 + theta_low, 0.0)
    elif not fresh and rule == RestRule.FROZEN:
        theta_low = theta
        mu_low = ti.max(mu0 + theta, 0.0)
    elif fresh and memory != 0 and rule != RestRule.PAPER:
        theta_low = 0.0
    a = 0.0
    b = -B
    if not fresh:
        a = theta_step_ti(theta, 0.0, 0.0, 0.0, dt, B, t_c, method)
        b = theta_step_ti(theta, 1.0, 1.0, 1.0, dt, B, t_c, method) - a
    c0 = mu0 + a
    c1 = A + b
    mu = mu_low
    theta_new = theta_low
    v = 0.0
    if K * v_star + f_n * ti.max(c0, 0.0) - f_trial >= 0.0:
        if K > 0.0:
            v = ti.max(f_trial - mu_low * f_n, 0.0) / K
    else:
        mu_min = 0.0
        if c1 >= 0.0:
            mu_min = ti.max(c0, 0.0)
        y = ti.log((f_trial - f_n * mu_min) / (K * v_star))
        for _ in range(NEWTON_ITERATIONS):
            e = K * v_star * ti.exp(y)
            m = c0 + c1 * y
            g = e + f_n * ti.max(m, 0.0) - f_trial
            gp = e
            if m > 0.0:
                gp += f_n * c1
            dy = g / gp
            y -= dy
            if dy <= tol * (1.0 + y):
                break
        theta_new = -B * y
        if not fresh:
            theta_new = theta_step_ti(theta, y, y, y, dt, B, t_c, method)
        mu = ti.max(mu0 + theta_new + A * y, 0.0)
        v = v_star * ti.exp(y)
    return mu, theta_new, v


__all__ = ["NO_INTERFACE", "contact_friction", "contact_friction_ti"]
