"""A contact's spring-dashpot integrated exactly over a step (the ``analytic`` integrator).

The contact forces are linear springs with dashpots between two bodies: along the normal
``f = max(k x + c x', 0)`` on the overlap depth ``x`` (no tension), along the tangent
``f = k_t xi + c_t xi'`` on the stick spring's stretch. An explicit step evaluates each at
the step's start and holds it for the step; that is first order, and its error at contact
onset (the dashpot's force jumps from 0 to ``c x'``) and at the end does not shrink faster.
Here each contact is instead solved as its own damped oscillator over the step,

    x'' = a - f / m,    x(0) = x0,  x'(0) = u0,

``m`` the pair's effective mass along the direction (``1/m = 1/m_i + (r_i x n)^2 / I_i +
...``), ``a`` the relative acceleration that the pair's other forces gave it over the last
step (held constant), the force switched off from the moment it would pull (normal) and the
rest of the step flown freely. The step hands the bodies what that force did: its impulse
``P = integral f dt`` and its "position impulse" ``Q = integral integral f dt dt``, so that
the body update ``v += P / m``, ``x += h v + Q / m`` moves an isolated pair exactly as the
ODE does, whatever the step (``tests/test_contact_step.py``: restitution and duration of
the clamped oscillator to round-off at 0.01 to 3 stability limits), and a body with several
contacts to second order.

A contact that began inside the last step (it overlaps now and did not then) is also given
what its force would have done since it began (``onset``): the time since is its depth over
its approach speed, and the missed impulse and displacement are added to this step's. This
removes the first-order error of the dashpot's jump at onset.

NumPy only; ``contact_step_ti`` holds the Taichi twins, operation for operation (the same
fdlibm ``exp``, ``cos`` and ``sin``, ``fmath`` and ``polygon.rotation``), so that the two
agree to round-off.
"""

from __future__ import annotations

import math

from . import fmath
from .polygon import rotation

__all__ = [
    "CRITICAL_BAND",
    "END_ITERATIONS",
    "MAX_LOOKS",
    "QUARTER_TURN",
    "onset",
    "oscillator_step",
    "pair_impulses",
    "sliding_impedance",
    "spring_dashpot",
    "stick_or_slide",
]

# |z - 1| below which the critically damped solution is used (the under- and overdamped ones
# divide by a frequency that vanishes at z = 1).
CRITICAL_BAND = 1e-6

# The end of an oscillating contact's force is looked for every quarter period of its
# oscillation inside a step (at most MAX_LOOKS times: a step of 16 quarter periods, 8 times
# the explicit step's stability limit, is far beyond any a scene takes).
QUARTER_TURN = 0.5 * math.pi
MAX_LOOKS = 16

# Safeguarded Newton iterations that locate the moment a clamped force reaches zero inside a
# step (bisection where Newton leaves the bracket): each halves the bracket at least, 60
# take it below the round-off of any step.
END_ITERATIONS = 60


def _exp(x: float) -> float:
    return float(fmath.exp(x)[0])


def _cos_sin(x: float) -> tuple[float, float]:
    c, s = rotation(x)
    return float(c), float(s)


def _solution(x0: float, u0: float, k: float, c: float, inv_m: float):
    """``(kind, sigma, freq, P, Q)`` of the homogeneous solution ``x'' + inv_m (c x' + k x) = 0``
    from ``(x0, u0)``: ``kind`` 0 underdamped ``e^{-sigma t}(P cos wt + Q sin wt)``, 1
    overdamped ``e^{-sigma t}(P cosh wt + Q sinh wt)``, 2 critical ``e^{-sigma t}(P + Q t)``."""
    w2 = k * inv_m
    sigma = 0.5 * c * inv_m
    disc = sigma * sigma - w2  # (z^2 - 1) w^2
    if abs(disc) <= CRITICAL_BAND * w2:
        return 2, sigma, 0.0, x0, u0 + sigma * x0
    if disc < 0.0:
        freq = math.sqrt(-disc)
        return 0, sigma, freq, x0, (u0 + sigma * x0) / freq
    freq = math.sqrt(disc)
    return 1, sigma, freq, x0, (u0 + sigma * x0) / freq


def _at(kind: int, sigma: float, freq: float, p: float, q: float, t: float):
    """``(x(t), x'(t))`` of the homogeneous solution (``_solution``)."""
    e = _exp(-sigma * t)
    if kind == 0:
        cw, sw = _cos_sin(freq * t)
        x = e * (p * cw + q * sw)
        v = e * ((freq * q - sigma * p) * cw - (sigma * q + freq * p) * sw)
        return x, v
    if kind == 1:
        g = _exp(freq * t)
        ch, sh = 0.5 * (g + 1.0 / g), 0.5 * (g - 1.0 / g)
        x = e * (p * ch + q * sh)
        v = e * ((freq * q - sigma * p) * ch + (freq * p - sigma * q) * sh)
        return x, v
    x = e * (p + q * t)
    v = e * (q - sigma * (p + q * t))
    return x, v


def oscillator_step(x0, u0, h, k, c, inv_m, a, clamp):
    """Exact motion over ``h`` of ``x'' = a - inv_m f``, ``f = k x + c x'`` (``clamp``: ``f =
    max(., 0)``, and once it reaches 0 the rest of the step is free flight).

    Args:
        x0, u0: the coordinate (m) and its rate (m/s) at the step's start.
        h: the step (s). k (N/m), c (N s/m): spring and dashpot (k > 0).
        inv_m: ``1 / m``, the pair's effective inverse mass along the direction (1/kg).
        a: the acceleration of the coordinate by the pair's other forces (m/s^2), constant.
        clamp: the force pushes only (the normal contact).

    Returns:
        ``(x1, u1, x_end)``: the coordinate and its rate after ``h``, and the coordinate
        where the force stopped acting (at ``h`` if it acted throughout; ``x0`` if not at all).
    """
    f0 = k * x0 + c * u0
    if clamp and f0 < 0.0:  # pulling: no force; fly
        return x0 + u0 * h + 0.5 * a * h * h, u0 + a * h, x0
    shift = a / (inv_m * k)  # the equilibrium the other forces move the spring to
    kind, sigma, freq, p, q = _solution(x0 - shift, u0, k, c, inv_m)
    x1, u1 = _at(kind, sigma, freq, p, q, h)
    x1 += shift
    if not clamp:
        return x1, u1, x1
    # Does the force reach zero inside the step? An oscillating one is looked at every
    # quarter period (it cannot turn twice between two looks); the last look is at h.
    looks = 1 if kind != 0 else min(int(freq * h / QUARTER_TURN) + 1, MAX_LOOKS)
    lo, f_lo, hi, f_hi = 0.0, f0, h, k * x1 + c * u1
    for i in range(1, looks):
        t = h * i / looks
        x, v = _at(kind, sigma, freq, p, q, t)
        f = k * (x + shift) + c * v
        if f < 0.0:
            hi, f_hi = t, f
            break
        lo, f_lo = t, f
    if f_hi >= 0.0:
        return x1, u1, x1
    # It does, between lo (positive) and hi (negative): find when.
    t = lo + (hi - lo) * f_lo / (f_lo - f_hi)  # the secant's zero as the first guess
    for _ in range(END_ITERATIONS):
        x, v = _at(kind, sigma, freq, p, q, t)
        f = k * (x + shift) + c * v
        if f > 0.0:
            lo = t
        else:
            hi = t
        # f' = k v + c (a - inv_m f) along the solution
        slope = k * v + c * (a - inv_m * f)
        step = t - f / slope if slope < 0.0 else 0.5 * (lo + hi)
        t = step if lo < step < hi else 0.5 * (lo + hi)
        if hi - lo <= 4.0 * 2.220446049250313e-16 * h:
            break
    x, v = _at(kind, sigma, freq, p, q, lo)
    x_end = x + shift
    rest = h - lo
    return x_end + v * rest + 0.5 * a * rest * rest, v + a * rest, x_end


def onset(x, u, h):
    """The time (s) since a contact that overlaps now and did not at the last step began:
    its depth over its approach speed (both as free flight left them), at most a step; 0 for
    one that is not closing (it began by turning, say: no dashpot jump to make up)."""
    if not (u > 0.0 and x > 0.0):
        return 0.0
    return min(x / u, h)


def spring_dashpot(x, u, h, k, c, inv_m, a, clamp, tau=0.0):
    """What a contact's spring-dashpot does over a step, for the body update.

    Args:
        x, u: the coordinate and its rate at the step's start (m, m/s), as the bodies are.
        h, k, c, inv_m, a, clamp: as ``oscillator_step``.
        tau: for a contact that began inside the last step, the time since it began (s;
            ``onset``): the force is integrated from then, not from now, and what it did
            before now is added (0: a contact that was there at the last step).

    Returns:
        ``(P, Q, P_viscous, x1, u1)``: the impulse of the force along the direction over the
        step (N s, positive: against ``x``), its position impulse (N s^2: the bodies end
        ``Q / m`` short of where they would have flown), the dashpot's part of ``P``, and
        the coordinate and rate after the step.
    """
    m = 1.0 / inv_m
    p0 = q0 = v0 = 0.0
    if tau > 0.0:
        # Since onset: from 0 at the approach it had then, to where the force has it now.
        xs, us, x_end0 = oscillator_step(0.0, u - a * tau, tau, k, c, inv_m, a, clamp)
        p0, q0 = (u - us) * m, (x - xs) * m
        v0 = c * x_end0
        x, u = xs, us
    x1, u1, x_end = oscillator_step(x, u, h, k, c, inv_m, a, clamp)
    p = (u + a * h - u1) * m
    q = (x + u * h + 0.5 * a * h * h - x1) * m
    return p0 + p, q0 + h * p0 + q, v0 + c * (x_end - x), x1, u1


def stick_or_slide(p_t, q_t, xi, xi1, slip, h, k_t, c_t, cap_p, cap_q):
    """The tangential impulse of a step, capped by friction (Cundall and Strack 1979).

    Args:
        p_t, q_t: the stick spring-dashpot's impulse and position impulse over the step had
            the contact stuck (``spring_dashpot``, unclamped: positive against the stretch).
        xi, xi1: the stretch at the step's start and, stuck, at its end (m).
        slip: the tangential velocity of the partner relative to the owner (m/s).
        h: the step (s). k_t, c_t: stick spring (N/m) and dashpot (N s/m).
        cap_p, cap_q: ``mu P_n`` and ``mu Q_n``: the most friction can give over the step.

    Returns:
        ``(f_t, g_t, xi_new, slip_work, damp_work)``: the step's mean force on the partner
        along the tangent (N, ``-P / h``), its position impulse as a force (N, ``-2 Q / h^2``:
        what the body update takes), the stretch after the step, and the frictional and
        dashpot work (J): stuck, none is frictional; sliding, the force is the cap, the
        spring-dashpot relaxes toward it over the step by backward Euler, as
        ``contact_law.tangential_force``'s (``k_t xi' + c_t (xi' - xi) / h = cap``, the slip
        rate's impedance ``k_t h + c_t``, ``sliding_impedance``) and the cap's work on the
        slip is frictional. The two with the spring's change add
        up to the work on the start-of-step slip, ``-f_t slip h = slip_work + damp_work +
        k_t xi_new (xi_new - xi)`` (``contact_law.contact_work`` books the rest at the
        mid-step velocity).
    """
    f_t = -p_t / h
    g_t = -2.0 * q_t / (h * h)
    xi_new = xi1
    slip_work = 0.0
    if abs(p_t) > cap_p:
        sign = math.copysign(1.0, p_t)
        f_t = -sign * cap_p / h
        g_t = -sign * 2.0 * cap_q / (h * h)
        xi_new = (c_t * xi - f_t * h) / (k_t * h + c_t)
        slip_work = (cap_p / h) * abs(xi + slip * h - xi_new)
    damp_work = -f_t * slip * h - k_t * xi_new * (xi_new - xi) - slip_work
    return f_t, g_t, xi_new, slip_work, damp_work


def sliding_impedance(k_t, c_t, h):
    """N s/m: how much the sliding tangential force falls per m/s of sliding, ``k_t h +
    c_t``: the stretch a slide at V takes off over the step, ``V h``, is taken at the step's
    end (``stick_or_slide``'s backward Euler, as the Euler step's
    ``contact_law.tangential_force``); what the rate-and-state law's sliding rate is solved
    with in the analytic step (``slip.contact_friction``'s ``K``)."""
    return k_t * h + c_t


def pair_impulses(
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
    """A pair's normal and stuck tangential spring-dashpots over the step (the analytic
    step's contact, ``contact.ContactStage.pair`` and ``reference_contact.contact_force``).

    Args:
        depth: ``A / L``, the overlap's mean depth (m). approach, slip: the normal approach
            speed (m/s, positive closing) and the tangential slip of the partner (m/s).
        xi: the stick spring's stretch (m). fresh: the pair did not touch at the last step.
        approach_change, slip_change: the last step's change of the two (m/s).
        last_force: the contact's mean normal and tangential force on the partner over the
            last step (N): what it did to the change, taken out to leave its other forces'.
        h: the step (s). k_n, c_n: normal spring and dashpot; k_t, c_t: the stick spring's.
        inv_n, inv_t: the pair's inverse mass along the normal and the tangent (1/kg).

    Returns:
        ``(f_n, f_el, q_n, p_t, q_t, xi1, a_n, a_t)``: the step's mean normal force and its
        elastic part (N), the normal position impulse (N s^2), the stuck tangential impulse
        and position impulse (against the stretch), the stuck stretch after the step, and
        the other forces' accelerations of the approach and the slip (m/s^2).
    """
    a_n = approach_change / h
    a_t = slip_change / h
    tau = 0.0
    if fresh:
        tau = onset(depth, approach, h)
    else:
        a_n += inv_n * last_force[0]
        a_t -= inv_t * last_force[1]
    p_n, q_n, p_v, _, _ = spring_dashpot(depth, approach, h, k_n, c_n, inv_n, a_n, True, tau)
    p_t, q_t, _, xi1, _ = spring_dashpot(xi, slip, h, k_t, c_t, inv_t, a_t, False, tau)
    return p_n / h, (p_n - p_v) / h, q_n, p_t, q_t, xi1, a_n, a_t
