"""Friction at a DEM contact: the slip rate, a new interface's start, the rule below ``v_star``.

A contact's tangential force comes from a stick spring ``k_t`` and dashpot ``c_t`` on the
stretch ``xi``, capped at ``mu F_n`` (``contact_law.tangential_force``). The rate-and-state law
needs the contact's slip rate V: how fast its two surfaces slide over each other. Two
speeds bound it:

- the **sliding rate**, the part of the step's displacement the stick spring does not take
  up: zero while the contact sticks, and exactly what the backward-Euler relaxation of the
  spring-dashpot toward the cap slides (``V dt``):

      F_trial = -k_t (xi + s dt) - c_t s               the force if the contact stuck
      V_slide = max(|F_trial| - mu(V) F_n, 0) / K,     K = k_t dt + c_t

- the **surface speed** ``|s|``, the tangential speed of the two surfaces past each other at
  the contact point, set by the motion of the blocks.

**V is the sliding rate, never faster than the surfaces**: ``V = min(V_slide, |s|)``. The
cap matters where the sliding rate is not the blocks' doing: when a loaded contact breaks
free, its spring gives up ``(mu0 - mu) F_n / k_t`` of stretch at a rate set by ``c_t`` and
dt (8 m/s at 100 kN, more as dt shrinks), and an interface started in equilibrium there had
mu near 0 for seconds.

**A new interface starts in equilibrium at its slip rate** (the paper's "on initiation of a
new sliding interface"), which is that of its first sliding step only for a contact that
slides from its first touch (``NEW_CONTACT``): its surfaces meet already moving. A contact
that touched and stuck (``NO_INTERFACE``) starts from rest: its slip rate grows from zero,
and the law takes over where it passes ``v_star``, in equilibrium there (theta = 0); the
step then carries theta to its end at the step's rate, as for any interface. (Started in
equilibrium at its first step's rate instead, even capped at the surfaces' speed, an
interface starts at the creep rate of the stuck spring, which is set by k_t: the driven
slider's frictional work then scattered by 2e-3 over the steps, with no order.)

mu depends on V through ``y = ln(V / v_star)`` and through this step's update of theta, so V
is solved per contact, in the step, before the force is applied: with
``mu0 + theta_new(y) + A y = c0 + c1 y`` (every integrator's theta update is affine in y when
y is held over the step), the sliding rate solves

    g(y) = K v_star e^y + F_n max(c0 + c1 y, 0) - |F_trial| = 0,      0 <= y <= y_s,

``y_s = ln(|s| / v_star)``. g is convex; if ``g(y_s) <= 0`` the contact would slide faster
than its surfaces and V = |s|; otherwise g has one root in (0, y_s) (g(0) < 0 there), which
Newton's method started at the smaller of y_s and ``y_hi`` (the sliding rate at the smallest
mu on the way) reaches monotonically from above in a few iterations.

Below ``v_star`` (which includes sticking) the law does not apply, and ``RestRule`` says
what does:

- ``paper`` (default): mu = mu0 exactly, as the paper states; the interface ends, and a
  contact that slides again is a new interface. A slip that reverses its direction between
  two steps passed through zero on the way: the interface ended there
  (``last_slip * slip < 0``), however fast both steps slid, and the contact starts again
  from rest. (A block stopped by its friction would otherwise carry the weak state of its
  fast slide through the reversal, and slide off under a load mu0 holds.)
- ``healing``: theta keeps relaxing toward 0 over t_c and mu = max(mu0 + theta, 0): a
  contact that comes to rest after fast sliding is weak at first and heals;
- ``frozen``: theta is held and mu = max(mu0 + theta, 0) until the contact slides again;
- ``relaxing``: mu = mu0 exactly, as under ``paper``, but the interface does not end (not
  below v_star, not at a reversal): theta relaxes toward 0 over t_c as under ``healing``, and
  when the contact slides faster than v_star again the law goes on from that theta. The
  paper's rule decides the end of an interface on one step's slip, and a held contact's slip
  hovers at v_star, so how often its interfaces end grows as the step shrinks
  (``validation/interface_events.py``); this rule keeps the paper's mu and has no such event.
  In force it is close to ``healing``: mu0 is taken only where the surfaces move slower
  than v_star or the law at theta would not slide past it (the branch ``contact_friction``
  takes), so a stopped contact with a weak theta, loaded fast enough to move its surfaces
  past v_star, holds (mu0 + theta) F_n, not mu0 F_n: the paper's stopped contacts are
  strong by the end.

A Coulomb world in a rate-and-state batch (``memory`` 0, A = B = 0) gets mu0 exactly.

Twins (the package's convention): ``contact_friction`` here (NumPy, scalars; this module
imports no Taichi) and ``slip_ti.contact_friction_ti`` (Taichi, called by the contact kernel).
"""

import math

from ..codes import RestRule
from .contact_law import tangential_force
from .friction import theta_step

# theta of a contact with no sliding interface: one that touched last step and stuck (or whose
# interface ended below v_star under the paper's rule), and one that touches for the first
# time (NEW_CONTACT). theta itself is never positive (it starts at -B y <= 0 and relaxes
# toward -B y).
NO_INTERFACE = 1.0e30
NEW_CONTACT = 3.0e30
NO_INTERFACE_ABOVE = 0.5 * NO_INTERFACE
NEW_CONTACT_ABOVE = 2.0e30
# Newton stops once a step moves y = ln(V / v_star) by less than this (relative to 1 + y),
# or after NEWTON_ITERATIONS; convergence is quadratic from above, so a handful suffice.
NEWTON_TOLERANCE = {"f64": 1e-13, "f32": 1e-6}
NEWTON_ITERATIONS = 30
# ``sliding_steps`` takes at most this many sub-steps, whatever ``[ice] slide_resolution``.
SLIDE_STEPS_MOST = 64


def contact_friction(
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
    method,
    tol=1e-13,
):
    """mu of a contact this step, its new theta and its slip rate (NumPy twin of
    ``slip_ti.contact_friction_ti``).

    Args:
        theta: the contact's theta from the last step: ``NO_INTERFACE`` if it touched and
            had no interface, ``NEW_CONTACT`` if it did not touch.
        last_slip: the slip rate of the last step along the tangent (m/s, signed; 0 if none).
        slip: ``s``, the tangential speed of the partner's surface past the owner's at the
            contact point this step (m/s, signed along the same tangent).
        f_trial: ``|F_trial|`` (N), the tangential force if the contact stuck this step.
        f_n: normal force (N, >= 0). K: ``k_t dt + c_t`` (N s/m, > 0). dt: step (s).
        A, B, mu0, v_star, t_c: the law's parameters.
        memory: 1 if theta is carried, 0 for a Coulomb world of a rate-and-state batch
            (A = B = 0: mu is exactly mu0).
        rule: ``codes.RestRule`` below v_star. method: ``codes.ThetaMethod``.
        tol: Newton's tolerance on ``y = ln(V / v_star)``.

    Returns:
        ``(mu, theta_new, V)``: mu for the cap ``mu F_n``, theta to carry (``NO_INTERFACE``
        when the contact has no interface), and the slip rate ``V = min(V_slide, |s|)``
        with the sign of ``slip`` (m/s).
    """
    speed = abs(slip)
    if rule == RestRule.PAPER and last_slip * slip < 0.0:
        theta = NO_INTERFACE  # the slip reversed: it passed through zero, below v_star
    fresh = theta > NO_INTERFACE_ABOVE or memory == 0
    # A new interface starts in equilibrium at its slip rate: a contact's first step at the
    # surfaces' (capped) rate; a contact that was at rest at v_star, which its slip passed
    # on the way up (theta = 0), whatever rate this step reaches.
    new = theta > NEW_CONTACT_ABOVE or memory == 0
    start = 0.0 if fresh else theta
    # Below v_star.
    mu_low, theta_low = mu0, NO_INTERFACE
    if not fresh and (rule == RestRule.HEALING or rule == RestRule.RELAXING):
        theta_low = float(theta_step(theta, 0.0, 0.0, 0.0, dt, B, t_c, method))
        if rule == RestRule.HEALING:  # relaxing keeps the paper's mu0
            mu_low = max(mu0 + theta_low, 0.0)
    elif not fresh and rule == RestRule.FROZEN:
        theta_low = theta
        mu_low = max(mu0 + theta, 0.0)
    elif fresh and memory != 0 and rule != RestRule.PAPER:
        theta_low = 0.0  # an interface at rest: in equilibrium at v_star
    # At or above v_star: mu(y) = max(c0 + c1 y, 0).
    a, b = 0.0, -B
    if not new:
        a = float(theta_step(start, 0.0, 0.0, 0.0, dt, B, t_c, method))
        b = float(theta_step(start, 1.0, 1.0, 1.0, dt, B, t_c, method)) - a
    c0, c1 = mu0 + a, A + b
    if speed <= v_star or K * v_star + f_n * max(c0, 0.0) - f_trial >= 0.0:
        v = min(max(f_trial - mu_low * f_n, 0.0) / K, speed)
        return mu_low, theta_low, -v if slip < 0.0 else v
    y_s = math.log(speed / v_star)
    capped = K * speed + f_n * max(c0 + c1 * y_s, 0.0) - f_trial <= 0.0
    if capped:
        y = y_s  # it would slide faster than its surfaces move: V = |s|
    else:
        # The sliding rate at the smallest mu on the way bounds the root from above.
        mu_min = max(c0, 0.0) if c1 >= 0.0 else 0.0
        y = min(math.log((f_trial - f_n * mu_min) / (K * v_star)), y_s)
        for _ in range(NEWTON_ITERATIONS):
            e = K * v_star * math.exp(y)
            m = c0 + c1 * y
            g = e + f_n * max(m, 0.0) - f_trial
            gp = e + (f_n * c1 if m > 0.0 else 0.0)
            dy = g / gp
            y -= dy
            if dy <= tol * (1.0 + y):
                break
    theta_new = -B * y if new else float(theta_step(start, y, y, y, dt, B, t_c, method))
    mu = max(mu0 + theta_new + A * y, 0.0)
    v = speed if capped else v_star * math.exp(y)
    return mu, theta_new, -v if slip < 0.0 else v


def slide_steps(k_t, c_t, dt, memory, resolution, theta=NO_INTERFACE):
    """How many sub-steps ``sliding_steps`` takes: enough that each is at most ``resolution``
    of the stick spring's relaxation time ``c_t / k_t``, at most ``SLIDE_STEPS_MOST``; 1 where
    ``resolution`` is 0 (the one-step contact), for a Coulomb world of a rate-and-state batch
    (``memory`` 0), whose mu does not depend on the slip rate, and for a contact's first
    step (``theta`` ``NEW_CONTACT``). That step is taken whole because its normal force is
    that of an overlap grown over the whole step: in a sub-step, the stick spring's trial
    force against it is that of a sub-step's stretch, so an interface that the blocks set
    sliding (one step, and a step 16 times finer, start it at the surfaces' rate) would be
    born at rest and stick at mu0 (a brief collision in the paper's pillar at 4.56 s)."""
    if memory == 0 or not resolution > 0.0 or theta > NEW_CONTACT_ABOVE:
        return 1
    many = min(k_t * dt / (resolution * c_t), SLIDE_STEPS_MOST)  # before ceil: no overflow
    return max(math.ceil(many), 1)


def sliding_steps(
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
    method,
    tol=1e-13,
    resolution=0.0,
):
    """A rate-and-state contact's tangential step, its slide resolved in time (NumPy twin of
    ``slip_ti.sliding_steps_ti``).

    A sliding contact's stick spring-dashpot relaxes toward the cap with the time ``c_t /
    k_t = 2 zeta / sqrt(k_t / m_t)``, not much longer than the step (``k_t dt / c_t`` up to 0.4
    in the paper's pillar at 0.2 stable_dt), and the law's slip rate follows that relaxation:
    taken in one step, the rate the law sees is that of the impedance ``k_t dt + c_t``, set
    by dt as much as by the dashpot, and so is the contact's memory. The step is taken in
    ``n = slide_steps(...)`` sub-steps ``h = dt / n`` with the surfaces' speed ``slip`` held:
    each solves the law (``contact_friction``, impedance ``k_t h + c_t``) and the capped
    spring-dashpot (``contact_law.tangential_force``) and carries theta, the slip rate and
    the stretch to the next. With ``n`` 1 it is the one-step contact, bit for bit.

    Args:
        theta, last_slip, slip, f_n, A, B, mu0, v_star, t_c, memory, rule, method, tol: as
            ``contact_friction``. xi: the stretch from the last step (m). k_t, c_t: stick
            spring (N/m) and dashpot (N s/m). dt: the step (s).
        resolution: the sub-steps' largest fraction of ``c_t / k_t`` (``[ice]
            slide_resolution``; ``slide_steps``), 0 for one step.

    Returns:
        ``(mu, theta_new, V, f_t, xi_new, slip_work, damp_work, mu_step, slid)``: the last
        sub-step's mu, theta and slip rate (the memory the next step starts from); the mean
        tangential force over the step on the partner (N: the impulse the bodies take, over
        dt); the stretch at its end; the frictional work and the dashpot's, plus (for ``n`` >
        1) what the sub-steps' backward Euler dissipates beyond the one
        ``contact_law.contact_work`` books for the whole step, so that the budget closes:
        ``-f_t slip dt = slip_work + damp_work + k_t xi_new (xi_new - xi)``; and, for a
        contact row, the step's mean mu over its sub-steps (the mean force is ``mu_step f_n``
        where the contact slid through the whole step) and whether its last sub-step slid
        (at the cap: the state the step leaves, as theta and V are). With ``n`` 1,
        ``mu_step`` is ``mu``. (The Taichi twin returns the first seven: the kernel writes
        no rows.)
    """
    n = slide_steps(k_t, c_t, dt, memory, resolution, theta)
    h = dt / n
    x, th, last = xi, theta, last_slip
    mu = v = 0.0
    f_sum = slip_work = damp_work = held = mu_sum = 0.0
    slid = False
    for _ in range(n):
        f_trial = abs(k_t * (x + slip * h) + c_t * slip)
        mu, th, v = contact_friction(
            th, last, slip, f_trial, f_n, k_t * h + c_t, h, A, B, mu0, v_star, t_c, memory,
            rule, method, tol,
        )  # fmt: skip
        f, x_new, sw, dw = tangential_force(x, slip, h, k_t, c_t, mu * f_n)
        f_sum += f
        mu_sum += mu
        slid = sw > 0.0
        slip_work += sw
        damp_work += dw
        held += 0.5 * k_t * (x_new - x) * (x_new - x)
        x, last = x_new, v
    f_t, mu_step = f_sum, mu
    if n > 1:
        f_t, mu_step = f_sum / n, mu_sum / n
        step = x - xi
        damp_work += held - 0.5 * k_t * step * step
    return mu, th, v, f_t, x, slip_work, damp_work, mu_step, slid


__all__ = [
    "NEWTON_ITERATIONS",
    "NEWTON_TOLERANCE",
    "NEW_CONTACT",
    "NEW_CONTACT_ABOVE",
    "NO_INTERFACE",
    "NO_INTERFACE_ABOVE",
    "SLIDE_STEPS_MOST",
    "contact_friction",
    "slide_steps",
    "sliding_steps",
]
