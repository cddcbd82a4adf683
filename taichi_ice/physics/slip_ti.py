"""Friction at a DEM contact as a Taichi function: the twin of ``slip.contact_friction``.

The slip rate solved in the step, a new interface's start and the rule below ``v_star`` are
described in ``slip``, which holds the NumPy reference and the constants both share
(``NO_INTERFACE``, ``NEW_CONTACT``, Newton's tolerance and iterations); this module holds only
the functions the contact kernel calls, step for step as their twins (``sliding_steps_ti``:
``slip.sliding_steps``).
"""

# No ``from __future__ import annotations``: Taichi reads the annotations of its functions.

import taichi as ti

from ..codes import RestRule
from .contact_law_ti import tangential_force_ti
from .fmath_ti import exp_any, log_any
from .friction_ti import theta_advance_ti, theta_decay_ti
from .slip import (
    NEW_CONTACT_ABOVE,
    NEWTON_ITERATIONS,
    NO_INTERFACE,
    NO_INTERFACE_ABOVE,
    SLIDE_STEPS_MOST,
)

__all__ = ["contact_friction_ti", "sliding_steps_ti"]


@ti.func
def contact_friction_ti(
    theta,
    last_slip,
    slip,
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
    """Taichi twin of :func:`slip.contact_friction`; returns ``(mu, theta_new, V)``. ``tol`` is a
    compile-time constant, ``slip.NEWTON_TOLERANCE`` of the precision."""
    h = dt / t_c
    return _friction_ti(
        theta, last_slip, slip, f_trial, f_n, K, h, theta_decay_ti(h, method), A, B, mu0, v_star,
        memory, rule, method, tol,
    )  # fmt: skip


@ti.func
def _friction_ti(
    theta,
    last_slip,
    slip,
    f_trial,
    f_n,
    K,
    h,
    decay,
    A,
    B,
    mu0,
    v_star,
    memory,
    rule,
    method: ti.template(),
    tol: ti.template(),
):
    """``contact_friction_ti`` with the state's step ``h`` = dt / t_c and its
    ``friction_ti.theta_decay_ti`` given (``sliding_steps_ti``' sub-steps share them: the
    values of ``slip.contact_friction``, which computes them for each theta it advances)."""
    speed = ti.abs(slip)
    theta_in = theta
    if rule == RestRule.PAPER and last_slip * slip < 0.0:
        theta_in = NO_INTERFACE
    fresh = theta_in > NO_INTERFACE_ABOVE or memory == 0
    new = theta_in > NEW_CONTACT_ABOVE or memory == 0
    start = theta_in
    if fresh:
        start = 0.0
    mu_low = mu0
    theta_low = NO_INTERFACE
    if not fresh and (rule == RestRule.HEALING or rule == RestRule.RELAXING):
        theta_low = theta_advance_ti(theta_in, 0.0, 0.0, 0.0, h, decay, B, method)
        if rule == RestRule.HEALING:  # relaxing keeps the paper's mu0
            mu_low = ti.max(mu0 + theta_low, 0.0)
    elif not fresh and rule == RestRule.FROZEN:
        theta_low = theta_in
        mu_low = ti.max(mu0 + theta_in, 0.0)
    elif fresh and memory != 0 and rule != RestRule.PAPER:
        theta_low = 0.0
    a = 0.0
    b = -B
    if not new:
        a = theta_advance_ti(start, 0.0, 0.0, 0.0, h, decay, B, method)
        b = theta_advance_ti(start, 1.0, 1.0, 1.0, h, decay, B, method) - a
    c0 = mu0 + a
    c1 = A + b
    mu = mu_low
    theta_new = theta_low
    v = 0.0
    if speed <= v_star or K * v_star + f_n * ti.max(c0, 0.0) - f_trial >= 0.0:
        v = ti.min(ti.max(f_trial - mu_low * f_n, 0.0) / K, speed)
    else:
        y_s = log_any(speed / v_star)
        y = y_s
        capped = K * speed + f_n * ti.max(c0 + c1 * y_s, 0.0) - f_trial <= 0.0
        if not capped:
            mu_min = 0.0
            if c1 >= 0.0:
                mu_min = ti.max(c0, 0.0)
            y = ti.min(log_any((f_trial - f_n * mu_min) / (K * v_star)), y_s)
            for _ in range(NEWTON_ITERATIONS):
                e = K * v_star * exp_any(y)
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
        if not new:
            theta_new = theta_advance_ti(start, y, y, y, h, decay, B, method)
        mu = ti.max(mu0 + theta_new + A * y, 0.0)
        v = speed
        if not capped:
            v = v_star * exp_any(y)
    if slip < 0.0:
        v = -v
    return mu, theta_new, v


@ti.func
def sliding_steps_ti(
    theta,
    last_slip,
    slip,
    xi,
    f_n,
    k_t,
    c_t,
    dt,
    A,
    B,
    mu0,
    v_star,
    t_c,
    memory,
    rule,
    resolution,
    method: ti.template(),
    tol: ti.template(),
):
    """Taichi twin of :func:`slip.sliding_steps`; returns ``(mu, theta_new, V, f_t, xi_new,
    slip_work, damp_work)``."""
    n = 1
    # A contact's first step is taken whole (``slip.slide_steps``).
    if memory != 0 and resolution > 0.0 and theta < NEW_CONTACT_ABOVE:
        # Clamped before the cast: a tiny resolution must not overflow the integer.
        many = ti.min(ti.ceil(k_t * dt / (resolution * c_t)), SLIDE_STEPS_MOST)
        n = ti.max(ti.cast(many, ti.i32), 1)
    h = dt / n
    x = xi
    th = theta
    last = last_slip
    mu = 0.0 * f_n
    v = 0.0 * f_n
    f_sum = 0.0 * f_n
    slip_work = 0.0 * f_n
    damp_work = 0.0 * f_n
    held = 0.0 * f_n
    h_c = h / t_c  # the state's step and its decay, the same in every sub-step
    decay = theta_decay_ti(h_c, method)
    for _ in range(n):
        f_trial = ti.abs(k_t * (x + slip * h) + c_t * slip)
        mu, th, v = _friction_ti(
            th, last, slip, f_trial, f_n, k_t * h + c_t, h_c, decay, A, B, mu0, v_star, memory,
            rule, method, tol,
        )  # fmt: skip
        f, x_new, sw, dw = tangential_force_ti(x, slip, h, k_t, c_t, mu * f_n)
        f_sum += f
        slip_work += sw
        damp_work += dw
        held += 0.5 * k_t * (x_new - x) * (x_new - x)
        x = x_new
        last = v
    f_t = f_sum
    if n > 1:
        f_t = f_sum / n
        step = x - xi
        damp_work += held - 0.5 * k_t * step * step
    return mu, th, v, f_t, x, slip_work, damp_work
