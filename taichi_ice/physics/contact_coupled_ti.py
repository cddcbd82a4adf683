"""Taichi twins of ``contact_coupled``: a contact's normal and tangent solved together over a
step (the ``coupled`` integrator).

Operation for operation the NumPy functions, in the kernel's precision (``real``, the type of
the arguments); the products and sums in the same order. No field access:
``contact.ContactStage.pair`` reads the fields.
"""

# No "from __future__ import annotations": Taichi reads the annotations of its functions.

import taichi as ti

from .contact_coupled import MAX_PIECES, MAX_TERMS, PIECE_NORM, REACH
from .contact_step_ti import onset_ti, spring_dashpot_ti

__all__ = ["coupled_flow_ti", "coupled_impulses_ti", "flow_times_ti"]


@ti.func
def _times(a, p00, p01, p10, p11, q00, q01, q10, q11, v0, v1, v2, v3):
    """Twin of ``contact_coupled._times``: ``B v``, ``B = [[0, a I], [P, Q]]``."""
    return (
        a * v2,
        a * v3,
        p00 * v0 + p01 * v1 + q00 * v2 + q01 * v3,
        p10 * v0 + p11 * v1 + q10 * v2 + q11 * v3,
    )


@ti.func
def flow_times_ti(a, p00, p01, p10, p11, q00, q01, q10, q11, z0, z1, z2, z3):
    """Twin of :func:`contact_coupled.flow_times`: ``exp(B) z``, four numbers."""
    norm = ti.max(
        ti.max(ti.abs(a), ti.abs(p00) + ti.abs(p01) + ti.abs(q00) + ti.abs(q01)),
        ti.abs(p10) + ti.abs(p11) + ti.abs(q10) + ti.abs(q11),
    )
    pieces = 1
    if PIECE_NORM < norm <= PIECE_NORM * MAX_PIECES:
        pieces = ti.cast(ti.ceil(norm / PIECE_NORM), ti.i32)
    s = 1.0 / (pieces + 0.0 * a)
    b0, b1, b2, b3, b4 = a * s, p00 * s, p01 * s, p10 * s, p11 * s
    b5, b6, b7, b8 = q00 * s, q01 * s, q10 * s, q11 * s
    nu = norm * s  # the terms: ``contact_coupled.series_terms``
    terms = 1
    for m in ti.static(range(MAX_TERMS)):
        if ti.static(REACH[m] < PIECE_NORM):
            if nu > REACH[m]:
                terms += 1
    y0, y1, y2, y3 = z0, z1, z2, z3
    for _ in range(pieces):
        t0, t1, t2, t3 = y0, y1, y2, y3
        for k in range(1, terms + 1):
            r = 1.0 / (k + 0.0 * a)
            t0, t1, t2, t3 = _times(b0, b1, b2, b3, b4, b5, b6, b7, b8, t0, t1, t2, t3)
            t0, t1, t2, t3 = t0 * r, t1 * r, t2 * r, t3 * r
            y0, y1, y2, y3 = y0 + t0, y1 + t1, y2 + t2, y3 + t3
    return y0, y1, y2, y3


@ti.func
def coupled_flow_ti(x_n, x_t, u_n, u_t, h, k_n, k_t, c_n, c_t, w_nn, w_nt, w_tt, a_n, a_t):
    """Twin of :func:`contact_coupled.coupled_flow`: ``(x_n, x_t, u_n, u_t)`` after ``h``."""
    det = w_nn * w_tt - w_nt * w_nt
    e_n = (w_tt * a_n - w_nt * a_t) / det / k_n
    e_t = (w_nn * a_t - w_nt * a_n) / det / k_t
    omega = ti.sqrt(ti.max(w_nn * k_n, w_tt * k_t))
    y0, y1, y2, y3 = flow_times_ti(
        omega * h,
        -w_nn * k_n * h / omega,
        -w_nt * k_t * h / omega,
        -w_nt * k_n * h / omega,
        -w_tt * k_t * h / omega,
        -w_nn * c_n * h,
        -w_nt * c_t * h,
        -w_nt * c_n * h,
        -w_tt * c_t * h,
        x_n - e_n,
        x_t - e_t,
        u_n / omega,
        u_t / omega,
    )
    return y0 + e_n, y1 + e_t, y2 * omega, y3 * omega


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
