"""Two floes colliding, as an ODE: the continuous-time limit of the DEM contact, by SciPy.

The reference that ``dem_accuracy`` holds the DEM's collisions against. It shares with the
engine only the contact geometry (``polygon.overlap``, the NumPy reference that the tests
hold against shapely) and the law's parameters; the time integration is SciPy's adaptive
``solve_ivp`` (DOP853) with event location, so what it measures in the DEM is the error of
the explicit step.

The contact law, in continuous time (Hopkins 1992; Cundall and Strack 1979), on two free
bodies (no water, no external force):

    F_n   = max(k_e A + k_v L v_n, 0)                     normal, no tension
    F_try = -k_t xi - c_t s                               the tangential force if stuck
    stuck:   |F_try| <= mu F_n:   F_t = F_try,             xi' = s
    sliding: F_t = sign(F_try) mu F_n,  xi' = (-F_t - k_t xi) / c_t

``k_t = r k_e L`` (``r`` the ice's ``tangential_stiffness``), ``c_t = 2 zeta sqrt(k_t m_t)``
(``zeta`` its ``tangential_damping``, ``m_t`` the pair's mass along the tangent at the
contact point: ``contact_law.tangential_damping``), ``s`` the tangential speed of the partner
at the contact point. The DEM's step (``contact_law.tangential_force``: a trial stretch, then a
backward-Euler relaxation to the cap) tends to exactly this as dt -> 0.

Rate and state with the paper's rule below ``v_star`` (``slip.contact_friction``, continuous):
the slip rate is the sliding rate, never faster than the surfaces,
``V = min(V_slide, |s|)``, ``V_slide`` solving ``c_t V + mu(V) F_n = |F_try|``; while the
contact slides ``mu = max(mu0 + theta + A ln(V / v_star), 0)`` and
``theta' = -(theta + B ln(V / v_star)) / t_c``. A contact that slides from its first touch
is a new interface in equilibrium at its rate, ``theta = -B ln(V0 / v_star)``; one at rest
holds at ``mu0`` until ``|F_try| > c_t v_star + mu0 F_n`` and then starts from rest, in
equilibrium at v_star (theta = 0); the interface ends when V falls below v_star (the
sliding rate, ``|F_try| <= c_t v_star + max(mu0 + theta, 0) F_n``, or the surfaces'
speed, ``|s| <= v_star``). Each switch is located as an event and the integration restarts
in the new mode. A contact's memory (``xi``, ``theta``) is dropped when the pair separates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...physics.polygon import min_penetration_axis, overlap, transform

# solve_ivp tolerances: the DEM errors measured against this are 1e-6 or more (relative).
RTOL = 1e-11
ATOL = 1e-13
# Free flight is searched for the next touch in steps of this (s), then bisected.
SEARCH_STEP = 2e-5
# Modes of a rate-and-state contact.
FRESH, SLIDING = 0, 1


@dataclass
class Pair:
    """Two dynamic bodies: outlines (centroid-relative, ``(n, 2)``), masses (kg), inertias
    (kg m^2), and the contact parameters: ``k_e``, ``k_v``, ``ratio``, ``zeta``; the law's
    parameters (``mu`` for Coulomb; ``A, B, mu0, v_star, t_c`` for rate and state)."""

    outlines: tuple[np.ndarray, np.ndarray]
    mass: np.ndarray
    inertia: np.ndarray
    k_e: float
    k_v: float
    ratio: float
    zeta: float
    law: Any

    @classmethod
    def from_scene(cls, scene) -> Pair:
        if scene.n_bodies != 2 or scene.water is not None or np.any(scene.forces != 0.0):
            raise ValueError("the collision ODE takes two free bodies with no water or force")
        law = scene.friction
        if law.name not in ("coulomb", "rate-state") or getattr(law, "below_v_star", "paper") != (
            "paper"
        ):
            raise ValueError(f"the collision ODE has Coulomb and the paper's rate-state: {law!r}")
        return cls(
            outlines=(np.asarray(scene.bodies[0].vertices), np.asarray(scene.bodies[1].vertices)),
            mass=np.asarray(scene.masses, dtype=float),
            inertia=np.asarray(scene.inertias, dtype=float),
            k_e=scene.ice.contact_stiffness,
            k_v=scene.ice.contact_viscosity,
            ratio=scene.ice.tangential_stiffness,
            zeta=scene.ice.tangential_damping,
            law=law,
        )

    @property
    def rate_state(self) -> bool:
        return self.law.name == "rate-state"

    def polygons(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World outlines of both bodies for the state ``y`` (x0, y0, a0, x1, y1, a1, ...)."""
        return (
            transform(self.outlines[0], y[0:2], y[2]),
            transform(self.outlines[1], y[3:5], y[5]),
        )

    def depth(self, y: np.ndarray) -> float:
        """Separating-axis depth (m): positive while the bodies overlap."""
        return min_penetration_axis(*self.polygons(y))[0]


def _cross(a, b) -> float:
    return a[0] * b[1] - a[1] * b[0]


def _perp(omega: float, r: np.ndarray) -> np.ndarray:
    return np.array([-omega * r[1], omega * r[0]])


class ContactRHS:
    """Right-hand side and switch events of one contact phase.

    State: ``[pos0 (2), angle0, pos1 (2), angle1, vel0 (2), omega0, vel1 (2), omega1, xi,
    theta]``. ``mode`` is FRESH or SLIDING (rate and state only).
    """

    def __init__(self, pair: Pair, mode: int = FRESH):
        self.pair, self.mode = pair, mode

    def contact(self, y: np.ndarray) -> dict[str, Any] | None:
        """Forces and the quantities the events need, or None if the bodies do not overlap."""
        pair = self.pair
        p, q = pair.polygons(y)
        ov = overlap(p, q)
        if ov.area <= 0.0:
            return None
        r0, r1 = ov.centroid - y[0:2], ov.centroid - y[3:5]
        v_rel = (y[9:11] + _perp(y[11], r1)) - (y[6:8] + _perp(y[8], r0))
        n = ov.normal
        t = np.array([-n[1], n[0]])
        approach, slip = -float(v_rel @ n), float(v_rel @ t)
        f_n = max(pair.k_e * ov.area + pair.k_v * ov.width * approach, 0.0)
        k_t = pair.ratio * pair.k_e * ov.width
        inv_m = (
            1.0 / pair.mass[0]
            + _cross(r0, t) ** 2 / pair.inertia[0]
            + 1.0 / pair.mass[1]
            + _cross(r1, t) ** 2 / pair.inertia[1]
        )
        c_t = 2.0 * pair.zeta * math.sqrt(k_t / inv_m)
        xi, theta = y[12], y[13]
        f_try = -k_t * xi - c_t * slip
        out = {
            "r0": r0,
            "r1": r1,
            "n": n,
            "t": t,
            "f_n": f_n,
            "f_try": f_try,
            "c_t": c_t,
            "slip": slip,
        }
        law = pair.law
        if not pair.rate_state:
            mu, rate = law.mu, 0.0
        elif self.mode == FRESH:
            mu, rate = law.mu0, 0.0
        else:
            y_log = _sliding_log_rate(abs(f_try), f_n, c_t, theta, law)
            if abs(slip) > law.v_star:  # never faster than the surfaces
                y_log = min(y_log, math.log(abs(slip) / law.v_star))
            mu = max(law.mu0 + theta + law.A * y_log, 0.0)
            rate = -(theta + law.B * y_log) / law.t_c
        cap = mu * f_n
        if abs(f_try) <= cap or c_t <= 0.0:
            f_t, xi_rate = f_try, slip
        else:
            f_t = math.copysign(cap, f_try)
            xi_rate = (-f_t - k_t * xi) / c_t
        out.update(f_t=f_t, xi_rate=xi_rate, theta_rate=rate)
        return out

    def __call__(self, _t: float, y: np.ndarray) -> np.ndarray:
        pair = self.pair
        dy = np.zeros_like(y)
        dy[0:3], dy[3:6] = y[6:9], y[9:12]
        c = self.contact(y)
        if c is None:
            return dy
        force = c["f_n"] * c["n"] + c["f_t"] * c["t"]  # on body 1; -force on body 0
        dy[6:8] = -force / pair.mass[0]
        dy[8] = -_cross(c["r0"], force) / pair.inertia[0]
        dy[9:11] = force / pair.mass[1]
        dy[11] = _cross(c["r1"], force) / pair.inertia[1]
        dy[12], dy[13] = c["xi_rate"], c["theta_rate"]
        return dy

    def events(self) -> list:
        """Separation (terminal, downward) and, for rate and state, the mode switch."""

        def separate(_t, y):
            return self.pair.depth(y)

        separate.terminal, separate.direction = True, -1
        if not self.pair.rate_state:
            return [separate]
        law = self.pair.law

        def switch(_t, y):
            c = self.contact(y)
            if c is None:
                return -1.0
            held = law.mu0 if self.mode == FRESH else max(law.mu0 + y[13], 0.0)
            return abs(c["f_try"]) - c["c_t"] * law.v_star - held * c["f_n"]

        switch.terminal = True
        switch.direction = 1 if self.mode == FRESH else -1
        if self.mode == FRESH:
            return [separate, switch]

        def surfaces(_t, y):  # the surfaces slow below v_star (on the way to a reversal)
            c = self.contact(y)
            return -1.0 if c is None else abs(c["slip"]) - law.v_star

        surfaces.terminal, surfaces.direction = True, -1
        return [separate, switch, surfaces]


def _sliding_log_rate(f_try: float, f_n: float, c_t: float, theta: float, law) -> float:
    """``y = ln(V / v_star) >= 0`` solving ``c_t v_star e^y + max(mu0 + theta + A y, 0) F_n
    = |F_try|`` (0 if even y = 0 holds: the switch event is about to end the slide)."""

    def g(y):
        return c_t * law.v_star * math.exp(y) + max(law.mu0 + theta + law.A * y, 0.0) * f_n - f_try

    if c_t <= 0.0 or g(0.0) >= 0.0:
        return 0.0
    hi = math.log(f_try / (c_t * law.v_star))  # g(hi) >= 0: mu >= 0
    lo = 0.0
    # g is increasing (A > 0): bisect, then polish by secant steps.
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if g(mid) > 0.0:
            hi = mid
        else:
            lo = mid
        if hi - lo < 1e-14 * (1.0 + hi):
            break
    return 0.5 * (lo + hi)


def _new_interface_theta(pair: Pair, c: dict[str, Any] | None) -> float:
    """theta of a contact that slides from its first touch: ``-B y0``, ``y0 = ln(V0 /
    v_star)`` with V0 its slip rate, the largest root of ``c_t v_star e^y + max(mu0 + (A -
    B) y, 0) F_n = |F_try|`` capped at the surfaces' speed ``|s|``."""
    law = pair.law
    if c is None or c["c_t"] <= 0.0 or abs(c["slip"]) <= law.v_star:
        return 0.0
    f_try, f_n, c_t = abs(c["f_try"]), c["f_n"], c["c_t"]
    cap = math.log(abs(c["slip"]) / law.v_star)

    def h(y):
        return (
            c_t * law.v_star * math.exp(y) + max(law.mu0 + (law.A - law.B) * y, 0.0) * f_n - f_try
        )

    if h(cap) <= 0.0:
        return -law.B * cap
    # h is convex with h(0) < 0 < h(cap): one root between.
    lo, hi = 0.0, cap
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if h(mid) < 0.0:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-14 * (1.0 + hi):
            break
    return -law.B * 0.5 * (lo + hi)


def _free(pair: Pair, y: np.ndarray, dt: float) -> np.ndarray:
    """Rigid free flight over ``dt`` (no force acts between contacts)."""
    out = y.copy()
    out[0:3] += dt * y[6:9]
    out[3:6] += dt * y[9:12]
    return out


def next_touch(pair: Pair, y: np.ndarray, horizon: float) -> float | None:
    """Time (s) after which free flight from ``y`` first overlaps, or None within ``horizon``."""
    t = 0.0
    while t < horizon:
        t_next = min(t + SEARCH_STEP, horizon)
        if pair.depth(_free(pair, y, t_next)) > 0.0:
            lo, hi = t, t_next
            for _ in range(100):
                mid = 0.5 * (lo + hi)
                if pair.depth(_free(pair, y, mid)) > 0.0:
                    hi = mid
                else:
                    lo = mid
                if hi - lo < 1e-16:
                    break
            return hi
        t = t_next
    return None


def solve_collision(scene, t_end: float) -> dict[str, Any]:
    """The collision of the scene's two bodies from t = 0 to ``t_end``, by ``solve_ivp``.

    Returns ``{"contacts": [(t_touch, t_separate), ...], "position", "angle", "velocity",
    "omega"`` at ``t_end`` (arrays over the two bodies), ``"mode_switches"`` (rate and state:
    how many times an interface started or ended), ``"rhs_calls"``}.
    """
    from scipy.integrate import solve_ivp

    pair = Pair.from_scene(scene)
    y = np.zeros(14)
    y[0:2], y[2] = scene.bodies[0].position, scene.bodies[0].angle
    y[3:5], y[5] = scene.bodies[1].position, scene.bodies[1].angle
    y[6:8], y[8] = scene.bodies[0].velocity, scene.bodies[0].omega
    y[9:11], y[11] = scene.bodies[1].velocity, scene.bodies[1].omega
    t = 0.0
    contacts: list[tuple[float, float]] = []
    switches = calls = 0
    while t < t_end:
        wait = next_touch(pair, y, t_end - t)
        if wait is None:
            break
        y = _free(pair, y, wait)
        t += wait
        touch = t
        y[12], y[13] = 0.0, 0.0  # a new contact: no stretch, no interface
        mode = FRESH
        if pair.rate_state:
            # Sliding from its first touch (no normal force yet, the dashpot's |F_try| above
            # c_t v_star): a new interface in equilibrium at its rate.
            first = ContactRHS(pair, FRESH).contact(_free(pair, y, 1e-12))
            if first is not None and abs(first["slip"]) > pair.law.v_star:
                y[13] = _new_interface_theta(pair, first)
                mode = SLIDING
                switches += 1
        while True:
            rhs = ContactRHS(pair, mode)
            sol = solve_ivp(
                rhs,
                (t, t_end),
                y,
                method="DOP853",
                rtol=RTOL,
                atol=ATOL,
                events=rhs.events(),
                max_step=1e-4,
            )
            calls += sol.nfev
            if sol.status == -1:
                raise RuntimeError(f"collision ODE failed: {sol.message}")
            t, y = float(sol.t[-1]), sol.y[:, -1].copy()
            if sol.status == 0:  # reached t_end in contact
                contacts.append((touch, math.nan))
                break
            if sol.t_events[0].size:  # separated
                contacts.append((touch, t))
                break
            # The interface started from rest (in equilibrium at v_star: theta = 0) or ended.
            y[13] = 0.0
            mode = SLIDING if mode == FRESH else FRESH
            switches += 1
        if sol.status == 0:
            break
    y = _free(pair, y, t_end - t) if t < t_end else y
    return {
        "contacts": contacts,
        "position": np.stack([y[0:2], y[3:5]]),
        "angle": np.array([y[2], y[5]]),
        "velocity": np.stack([y[6:8], y[9:11]]),
        "omega": np.array([y[8], y[11]]),
        "mode_switches": switches,
        "rhs_calls": calls,
    }


def clamped_oscillator(k: float, c: float, m_eff: float, v0: float) -> tuple[float, float]:
    """``(duration (s), restitution)`` of a face-on collision, ``m d'' = -max(k d + c d', 0)``
    from ``d = 0, d' = v0`` until ``d`` returns to 0, solved by scipy (DOP853, rtol 1e-12).

    Without the no-tension clamp this is the linear oscillator, ``pi / w_d`` and
    ``exp(-z pi / sqrt(1 - z^2))``; with it the dashpot stops pulling when ``k d + c d' = 0``,
    so the pair leaves a little faster (restitution up by O(z)). Independent of the engine:
    the tests use it as their reference too.
    """
    from scipy.integrate import solve_ivp

    def rhs(_t, y):
        return [y[1], -max(k * y[0] + c * y[1], 0.0) / m_eff]

    def apart(_t, y):
        return y[0]

    apart.terminal, apart.direction = True, -1
    sol = solve_ivp(
        rhs,
        (0.0, 1.0),
        [0.0, v0],
        events=apart,
        method="DOP853",
        rtol=1e-12,
        atol=1e-16,
        first_step=1e-9,
    )
    return float(sol.t_events[0][0]), float(-sol.y_events[0][0][1] / v0)


def last_separation(scene, position, angle, velocity, omega, t_end: float, t_from: float) -> float:
    """When two bodies that fly apart rigidly at ``t_end`` (state given) last overlapped:
    the latest time in ``[t_from, t_end]`` where their backward free flight overlaps (s)."""
    pair = Pair.from_scene(scene)
    y = np.zeros(14)
    y[0:2], y[2], y[3:5], y[5] = position[0], angle[0], position[1], angle[1]
    y[6:8], y[8], y[9:11], y[11] = velocity[0], omega[0], velocity[1], omega[1]
    back = -y.copy()
    back[0:6] = y[0:6]  # reversed velocities: free flight backwards in time
    wait = next_touch(pair, back, t_end - t_from)
    return math.nan if wait is None else t_end - wait


__all__ = ["Pair", "clamped_oscillator", "last_separation", "next_touch", "solve_collision"]
