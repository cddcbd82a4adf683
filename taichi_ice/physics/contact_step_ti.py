"""Taichi twins of ``contact_step``: a contact's spring-dashpot integrated exactly over a step.

Operation for operation the NumPy functions, in the kernel's precision (``real``, the type
of the arguments): in float64 fdlibm's ``exp`` (``fmath_ti.exp_ti``) and ``cos``/``sin``
(``polygon_ti.rotation_ti``), which the NumPy twins use too (and which every backend has), in
float32 Taichi's own. No field access: ``contact.ContactStage.pair`` reads the fields.
"""

# No "from __future__ import annotations": Taichi reads the annotations of its functions.

import taichi as ti

from .contact_step import CRITICAL_BAND, END_ITERATIONS, MAX_LOOKS, QUARTER_TURN
from .fmath_ti import exp_ti
from .polygon_ti import rotation_ti

__all__ = [
    "onset_ti",
    "oscillator_step_ti",
    "pair_impulses_ti",
    "sliding_impedance_ti",
    "spring_dashpot_ti",
    "stick_or_slide_ti",
]

EPS64 = 2.220446049250313e-16


@ti.func
def _exp(x):
    y = x
    if ti.static(x.ptr.get_rvalue_type() == ti.f64):
        y = exp_ti(x)
    else:
        y = ti.exp(x)
    return y


@ti.func
def _cos_sin(x):
    cs = ti.Vector([x, x])
    if ti.static(x.ptr.get_rvalue_type() == ti.f64):
        cs = rotation_ti(x)
    else:
        cs = ti.Vector([ti.cos(x), ti.sin(x)])
    return cs[0], cs[1]


@ti.func
def _solution(x0, u0, k, c, inv_m):
    """Twin of ``contact_step._solution``."""
    w2 = k * inv_m
    sigma = 0.5 * c * inv_m
    disc = sigma * sigma - w2
    kind = 2
    freq = 0.0 * sigma
    p = x0
    q = u0 + sigma * x0
    if ti.abs(disc) <= CRITICAL_BAND * w2:
        pass
    elif disc < 0.0:
        kind = 0
        freq = ti.sqrt(-disc)
        q = (u0 + sigma * x0) / freq
    else:
        kind = 1
        freq = ti.sqrt(disc)
        q = (u0 + sigma * x0) / freq
    return kind, sigma, freq, p, q


@ti.func
def _at(kind, sigma, freq, p, q, t):
    """Twin of ``contact_step._at``."""
    e = _exp(-sigma * t)
    x = p
    v = q
    if kind == 0:
        cw, sw = _cos_sin(freq * t)
        x = e * (p * cw + q * sw)
        v = e * ((freq * q - sigma * p) * cw - (sigma * q + freq * p) * sw)
    elif kind == 1:
        g = _exp(freq * t)
        ch = 0.5 * (g + 1.0 / g)
        sh = 0.5 * (g - 1.0 / g)
        x = e * (p * ch + q * sh)
        v = e * ((freq * q - sigma * p) * ch + (freq * p - sigma * q) * sh)
    else:
        x = e * (p + q * t)
        v = e * (q - sigma * (p + q * t))
    return x, v


@ti.func
def oscillator_step_ti(x0, u0, h, k, c, inv_m, a, clamp: ti.template()):
    """Twin of :func:`contact_step.oscillator_step`: ``(x1, u1, x_end)``.

    Where ``clamp``, every look at the solution (at ``h``, at the quarter periods, at the
    root search's guesses and at the root) is one call of ``_at`` in one loop, ``phase``
    saying which: a kernel inlines a function once per call, and ``_at`` (an exponential
    and a cosine and sine, fdlibm's in float64) was called at four places. The same values
    in the same order as the twin's.
    """
    f0 = k * x0 + c * u0
    x1 = x0 + u0 * h + 0.5 * a * h * h
    u1 = u0 + a * h
    x_end = x0
    if ti.static(not clamp):
        shift = a / (inv_m * k)
        kind, sigma, freq, p, q = _solution(x0 - shift, u0, k, c, inv_m)
        xh, uh = _at(kind, sigma, freq, p, q, h)
        xh += shift
        x1, u1, x_end = xh, uh, xh
    elif not f0 < 0.0:  # pushing (as the twin: a NaN goes on)
        shift = a / (inv_m * k)
        kind, sigma, freq, p, q = _solution(x0 - shift, u0, k, c, inv_m)
        looks = 1
        if kind == 0:
            looks = ti.min(ti.cast(freq * h / QUARTER_TURN, ti.i32) + 1, MAX_LOOKS)
        lo = 0.0 * h
        f_lo = f0
        hi = h
        f_hi = f0
        look = 1
        searched = 0
        # 0: at h; 1: the looks (a force that oscillates, every quarter period: it cannot
        # turn twice between two); 2: the search for the moment the force ends, between lo
        # (pushing) and hi (pulling); 3: at that moment, then free flight to h; 4: done.
        phase = 0
        t = h
        for _ in range(MAX_LOOKS + END_ITERATIONS + 1):
            x, v = _at(kind, sigma, freq, p, q, t)
            f = k * (x + shift) + c * v
            if phase == 0:
                x1, u1, x_end = x + shift, v, x + shift
                f_hi = f
                phase = 1
            elif phase == 1:
                if f < 0.0:
                    hi = t
                    f_hi = f
                    look = looks
                else:
                    lo = t
                    f_lo = f
                    look += 1
            elif phase == 2:
                if f > 0.0:
                    lo = t
                else:
                    hi = t
                slope = k * v + c * (a - inv_m * f)  # f' along the solution
                nxt = 0.5 * (lo + hi)
                if slope < 0.0:
                    nxt = t - f / slope
                t = nxt
                if not (lo < nxt < hi):
                    t = 0.5 * (lo + hi)
                searched += 1
                if hi - lo <= 4.0 * EPS64 * h or searched == END_ITERATIONS:
                    phase = 3
                    t = lo
            else:
                x_end = x + shift
                rest = h - lo
                x1 = x_end + v * rest + 0.5 * a * rest * rest
                u1 = v + a * rest
                phase = 4
            if phase == 1:
                if look < looks:
                    t = h * look / looks
                elif f_hi < 0.0:
                    phase = 2
                    t = lo + (hi - lo) * f_lo / (f_lo - f_hi)  # the secant's zero
                else:
                    phase = 4
            if phase == 4:
                break
    return x1, u1, x_end


@ti.func
def spring_dashpot_ti(x, u, h, k, c, inv_m, a, clamp: ti.template(), tau):
    """Twin of :func:`contact_step.spring_dashpot`: ``(P, Q, P_viscous, x1, u1)``."""
    m = 1.0 / inv_m
    p0 = 0.0 * x
    q0 = 0.0 * x
    v0 = 0.0 * x
    xs = x
    us = u
    x1, u1, x_end = x, u, x
    # The stretch since onset (stage 0, if tau > 0) and the step (stage 1) through one call
    # of the oscillator, in a loop: inlined twice, its solution, clamp and root search made
    # the pillar's midstep kernel compile in 11.5-11.8 s against 8.6-9.1 s, the analytic one
    # 6.7 against 4.1-5.2 s (empty cache, 2 cores; the same operations in the same order).
    for stage in range(0 if tau > 0.0 else 1, 2):
        x_in, u_in, span = xs, us, h
        if stage == 0:
            x_in, u_in, span = 0.0 * x, u - a * tau, tau
        xo, uo, x_e = oscillator_step_ti(x_in, u_in, span, k, c, inv_m, a, clamp)
        if stage == 0:
            p0 = (u - uo) * m
            q0 = (x - xo) * m
            v0 = c * x_e
            xs, us = xo, uo
        else:
            x1, u1, x_end = xo, uo, x_e
    p = (us + a * h - u1) * m
    q = (xs + us * h + 0.5 * a * h * h - x1) * m
    return p0 + p, q0 + h * p0 + q, v0 + c * (x_end - xs), x1, u1


@ti.func
def stick_or_slide_ti(p_t, q_t, xi, xi1, slip, h, k_t, c_t, cap_p, cap_q):
    """Twin of :func:`contact_step.stick_or_slide`: ``(f_t, g_t, xi_new, slip_work, damp_work)``."""
    f_t = -p_t / h
    g_t = -2.0 * q_t / (h * h)
    xi_new = xi1
    slip_work = 0.0 * xi
    if ti.abs(p_t) > cap_p:
        sign = 1.0
        if p_t < 0.0:
            sign = -1.0
        f_t = -sign * cap_p / h
        g_t = -sign * 2.0 * cap_q / (h * h)
        xi_new = (c_t * xi - f_t * h) / (k_t * h + c_t)
        slip_work = (cap_p / h) * ti.abs(xi + slip * h - xi_new)
    damp_work = -f_t * slip * h - k_t * xi_new * (xi_new - xi) - slip_work
    return f_t, g_t, xi_new, slip_work, damp_work


@ti.func
def onset_ti(x, u, h):
    """Twin of :func:`contact_step.onset`."""
    tau = 0.0 * x
    if u > 0.0 and x > 0.0:
        tau = ti.min(x / u, h)
    return tau


@ti.func
def sliding_impedance_ti(k_t, c_t, h):
    """Twin of :func:`contact_step.sliding_impedance`."""
    return k_t * h + c_t


@ti.func
def pair_impulses_ti(
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
):
    """Twin of :func:`contact_step.pair_impulses`."""
    a_n = approach_change / h
    a_t = slip_change / h
    tau = 0.0 * h
    if fresh:
        tau = onset_ti(depth, approach, h)
    else:
        a_n += inv_n * last_force[0]
        a_t -= inv_t * last_force[1]
    p_n, q_n, p_v, _x, _u = spring_dashpot_ti(depth, approach, h, k_n, c_n, inv_n, a_n, True, tau)
    p_t, q_t, _v, xi1, _s = spring_dashpot_ti(xi, slip, h, k_t, c_t, inv_t, a_t, False, tau)
    return p_n / h, (p_n - p_v) / h, q_n, p_t, q_t, xi1, a_n, a_t
