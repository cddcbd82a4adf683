"""Taichi twins of ``contact_coupled``: a contact's normal and tangent solved together over a
step (the ``coupled`` integrator).

Operation for operation the NumPy functions, in the kernel's precision (``real``, the type of
the arguments); the 4 x 4 products, the elimination and the sums run in the same index order,
unrolled. No field access: ``contact.ContactStage.pair`` reads the fields.
"""

# No "from __future__ import annotations": Taichi reads the annotations of its functions.

import taichi as ti

from .contact_coupled import MAX_SQUARINGS, PADE, SCALED_NORM
from .contact_step_ti import onset_ti, spring_dashpot_ti

__all__ = ["coupled_flow_ti", "coupled_impulses_ti", "expm4_ti"]


@ti.func
def _mul(a, b):
    out = a * 0.0
    for i in ti.static(range(4)):
        for j in ti.static(range(4)):
            s = a[i, 0] * b[0, j]
            for k in ti.static(range(1, 4)):
                s += a[i, k] * b[k, j]
            out[i, j] = s
    return out


@ti.func
def _solve(m, r):
    """Twin of ``contact_coupled._solve``: ``m^-1 r``, elimination without pivoting."""
    mm = m
    rr = r
    for k in ti.static(range(4)):
        for i in ti.static(range(k + 1, 4)):
            f = mm[i, k] / mm[k, k]
            for j in ti.static(range(k, 4)):
                mm[i, j] -= f * mm[k, j]
            for j in ti.static(range(4)):
                rr[i, j] -= f * rr[k, j]
    out = r * 0.0
    for i in ti.static(range(3, -1, -1)):
        for j in ti.static(range(4)):
            s = rr[i, j]
            for k in ti.static(range(i + 1, 4)):
                s -= mm[i, k] * out[k, j]
            out[i, j] = s / mm[i, i]
    return out


@ti.func
def expm4_ti(b):
    """Twin of :func:`contact_coupled.expm4` (``b`` a 4 x 4 ``ti.Matrix``)."""
    norm = ti.abs(b[0, 0]) * 0.0
    for i in ti.static(range(4)):
        row = ti.abs(b[i, 0])
        for j in ti.static(range(1, 4)):
            row += ti.abs(b[i, j])
        norm = ti.max(norm, row)
    s = 0
    scale = 1.0 + 0.0 * norm
    while norm > SCALED_NORM and s < MAX_SQUARINGS:
        norm *= 0.5
        scale *= 0.5
        s += 1
    x = b * scale
    x2 = _mul(x, x)
    x4 = _mul(x2, x2)
    x6 = _mul(x4, x2)
    eye = b * 0.0
    for i in ti.static(range(4)):
        eye[i, i] = 1.0
    odd = eye * PADE[1] + x2 * PADE[3] + x4 * PADE[5]
    u = _mul(x, odd)
    v = eye * PADE[0] + x2 * PADE[2] + x4 * PADE[4] + x6 * PADE[6]
    e = _solve(v - u, v + u)
    for _ in range(s):
        e = _mul(e, e)
    return e


@ti.func
def coupled_flow_ti(x_n, x_t, u_n, u_t, h, k_n, k_t, c_n, c_t, w_nn, w_nt, w_tt, a_n, a_t):
    """Twin of :func:`contact_coupled.coupled_flow`: ``(x_n, x_t, u_n, u_t)`` after ``h``."""
    det = w_nn * w_tt - w_nt * w_nt
    e_n = (w_tt * a_n - w_nt * a_t) / det / k_n
    e_t = (w_nn * a_t - w_nt * a_n) / det / k_t
    omega = ti.sqrt(ti.max(w_nn * k_n, w_tt * k_t))
    zero = 0.0 * h
    b = ti.Matrix(
        [
            [zero, zero, omega * h, zero],
            [zero, zero, zero, omega * h],
            [-w_nn * k_n * h / omega, -w_nt * k_t * h / omega, -w_nn * c_n * h, -w_nt * c_t * h],
            [-w_nt * k_n * h / omega, -w_tt * k_t * h / omega, -w_nt * c_n * h, -w_tt * c_t * h],
        ]
    )
    e = expm4_ti(b)
    z = ti.Vector([x_n - e_n, x_t - e_t, u_n / omega, u_t / omega])
    y = ti.Vector([zero, zero, zero, zero])
    for i in ti.static(range(4)):
        s = e[i, 0] * z[0]
        for j in ti.static(range(1, 4)):
            s += e[i, j] * z[j]
        y[i] = s
    return y[0] + e_n, y[1] + e_t, y[2] * omega, y[3] * omega


@ti.func
def coupled_impulses_ti(
    depth,
    approach,
    slip,
    xi,
    fresh,
    approach_change,
    slip_change,
    last_force,
    h,
    k_n,
    c_n,
    k_t,
    c_t,
    inv_n,
    inv_t,
    k_nt,
    mu,
):
    """Twin of :func:`contact_coupled.coupled_impulses` (each solution inlined once)."""
    w_nt = -k_nt
    det = inv_n * inv_t - w_nt * w_nt
    a_n = approach_change / h
    a_t = slip_change / h
    tau = 0.0 * h
    a_n_pair = a_n
    a_t_pair = a_t
    if fresh:
        tau = onset_ti(depth, approach, h)
    else:
        g_n = last_force[0]
        g_t = -last_force[1]
        a_n_pair = a_n + inv_n * g_n
        a_t_pair = a_t + inv_t * g_t
        a_n = a_n_pair + w_nt * g_t
        a_t = a_t_pair + w_nt * g_n
    x_n, x_t, u_n, u_t = depth, xi, approach, slip
    y_n, y_t, v_n, v_t = x_n, x_t, u_n, u_t
    zero = 0.0 * h
    p0_n, p0_t, q0_n, q0_t, v0 = zero, zero, zero, zero, zero
    for stage in range(2):
        if (stage == 1 and k_n * x_n + c_n * u_n >= 0.0) or (stage == 0 and tau > 0.0):
            span, i_n, i_t, j_n, j_t = h, x_n, x_t, u_n, u_t
            if stage == 0:
                span, i_n, i_t, j_n, j_t = tau, zero, zero, u_n - a_n * tau, u_t - a_t * tau
            o_n, o_t, r_n, r_t = coupled_flow_ti(
                i_n, i_t, j_n, j_t, span, k_n, k_t, c_n, c_t, inv_n, w_nt, inv_t, a_n, a_t
            )
            if stage == 0:
                dn = u_n - r_n
                dt_ = u_t - r_t
                p0_n = (inv_t * dn - w_nt * dt_) / det
                p0_t = (inv_n * dt_ - w_nt * dn) / det
                dn = x_n - o_n
                dt_ = x_t - o_t
                q0_n = (inv_t * dn - w_nt * dt_) / det
                q0_t = (inv_n * dt_ - w_nt * dn) / det
                v0 = c_n * o_n
                x_n, x_t, u_n, u_t = o_n, o_t, r_n, r_t
            else:
                y_n, y_t, v_n, v_t = o_n, o_t, r_n, r_t
    fallback = k_n * x_n + c_n * u_n < 0.0 or k_n * y_n + c_n * v_n < 0.0
    dn = u_n + a_n * h - v_n
    dt_ = u_t + a_t * h - v_t
    p_n = p0_n + (inv_t * dn - w_nt * dt_) / det
    p_t = p0_t + (inv_n * dt_ - w_nt * dn) / det
    dn = x_n + u_n * h + 0.5 * a_n * h * h - y_n
    dt_ = x_t + u_t * h + 0.5 * a_t * h * h - y_t
    q_n = q0_n + h * p0_n + (inv_t * dn - w_nt * dt_) / det
    q_t = q0_t + h * p0_t + (inv_n * dt_ - w_nt * dn) / det
    p_v = v0 + c_n * (y_n - x_n)
    xi1 = y_t
    sliding = not fallback and ti.abs(p_t) > mu * p_n
    sign = 1.0
    if p_t < 0.0:
        sign = -1.0
    inv_slide = inv_n - sign * mu * k_nt
    if sliding and not inv_slide > 0.0:
        fallback = True
    if fallback or sliding:
        inv_m = inv_slide
        a_m = a_n
        if fallback:
            inv_m = inv_n
            a_m = a_n_pair
        p_n, q_n, p_v, _x, _u = spring_dashpot_ti(
            depth, approach, h, k_n, c_n, inv_m, a_m, True, tau
        )
    if fallback:
        p_t, q_t, _v, xi1, _s = spring_dashpot_ti(
            xi, slip, h, k_t, c_t, inv_t, a_t_pair, False, tau
        )
    return p_n / h, (p_n - p_v) / h, q_n, p_t, q_t, xi1, a_n, a_t
