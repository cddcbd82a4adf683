"""The DEM-contact validation's second part: a block slides, stops, then holds or slides.

A block (4 m x 0.25 m: long and low, so that no load here tips it) pressed onto a fixed
floor slides with an initial speed until it stops; then a horizontal load ramps to 0.8 or
1.2 mu0 F and is held. Under the paper's rule (mu = mu0
below v_star) the first holds and the second slides with acceleration (1.2 - mu) F / m;
under ``healing`` and ``frozen`` the contact is left weak by the slide. ``dem_contact.run``
runs it and writes the results into ``dem_contact.json``.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from ...codes import RestRule
from ...physics.friction import RateState
from ...physics.slip import NO_INTERFACE

BLOCK = 1  # body index of the block (the floor is 0)
PRESS = 2707.56  # N: the block's weight (920 kg/m^3 x 0.3 m x 1 m^2 x 9.81 m/s^2)
# The block (m): 1 m^2 of ice, long and low. (A 1 m square pulled at its centroid by 1.2 mu0
# F, more than it is pressed with, tips over its leading corner once its friction rises with
# the slip rate, as it does when a contact starts from rest.)
WIDTH, HEIGHT = 4.0, 0.25
V0 = 0.05  # m/s: initial speed of the block
HOLD_AT = 0.5  # s: the horizontal load starts (the block stopped by ~0.02 s)
RAMP = 0.1  # s: the load ramps from 0 to its value over this time
OBSERVE = 0.5  # s: then holds its value this long
LOADS = (0.8, 1.2)  # horizontal load / (mu0 F)
SAMPLE_EVERY = 5  # steps between samples of the hold/slide runs
# The acceleration is averaged from this long after the ramp's end to the run's end (s).
SLIDE_SETTLE = 0.05

# ------------------------------------------------------------------------------------------------
# Hold and slide
# ------------------------------------------------------------------------------------------------


def block_scene(law: RateState, v0: float = V0, press: float = PRESS):
    """A block of ``scenarios/sliding_block.toml``'s mass, long and low, on a fixed floor,
    with ``law``."""
    from ...scene.parse import scene_from_dict

    return scene_from_dict(
        {
            "simulation": {"duration": HOLD_AT + RAMP + OBSERVE},
            "friction": law.to_dict(),
            "body": [
                {
                    "name": "floor",
                    "kind": "fixed",
                    "shape": "rectangle",
                    "width": 40.0,
                    "length": 0.5,
                    "position": [15.0, -0.25],  # top face at y = 0
                },
                {
                    "name": "block",
                    "shape": "rectangle",
                    "width": WIDTH,
                    "length": HEIGHT,
                    "position": [0.0, 0.5 * HEIGHT],
                    "velocity": [v0, 0.0],
                    "force": [0.0, -press],
                    "probe": True,
                },
            ],
        },
        source="dem_contact_hold_slide",
    )


def hold_slide(
    rules: tuple[str, ...] = tuple(RestRule.labels()),
    loads: tuple[float, ...] = LOADS,
    law: RateState | None = None,
) -> dict[str, Any]:
    """Slide to a stop, then a horizontal load of ``load x mu0 F``, per rule and load.

    Returns the JSON-ready summary: ``{"setup": ..., "cases": {rule: {load: {...}}}}``.
    Taichi must be running (``backend.init``).
    """
    from .contact_block import make_world

    base = law or RateState()
    params = {k: v for k, v in base.to_dict().items() if k not in ("law", "below_v_star")}
    cases = [(rule, load) for rule in rules for load in loads]
    laws = [RateState(**params, below_v_star=rule) for rule, _ in cases]
    scenes = [block_scene(law_) for law_ in laws]
    # At 0.2 of the limit (``contact_block.CHECK_SAFETY``), the step this check was made at.
    world = make_world(scenes)
    dt = world.dt
    mass = float(scenes[0].masses[BLOCK])
    ice = scenes[0].ice
    k_t = ice.tangential_stiffness * ice.contact_stiffness * WIDTH  # L: the block's base
    blocks = [s.start + BLOCK for s in world.world_slices()]
    n_hold, n_ramp, n_obs = (round(T / dt) for T in (HOLD_AT, RAMP, OBSERVE))
    n = n_hold + n_ramp + n_obs
    names = ("t", "x", "angle", "v", "omega", "force", "theta", "xi")
    rec: dict[str, list] = {k: [] for k in names}
    force_ext = world.model.body_force_ext
    start = time.perf_counter()
    for k in range(n):
        if n_hold <= k < n_hold + n_ramp:
            frac = (k - n_hold + 1) / n_ramp
            for b, (_, load) in zip(blocks, cases):
                force_ext[b] = (frac * load * base.mu0 * PRESS, -PRESS)
        world.step()
        if (k + 1) % SAMPLE_EVERY == 0:
            rec["t"].append((k + 1) * dt)
            pos, ang, vel, omega = world.motion()
            rec["x"].append(pos[blocks, 0])
            rec["angle"].append(ang[blocks])
            rec["v"].append(vel[blocks, 0])
            rec["omega"].append(omega[blocks])
            rec["force"].append(world.take_probe_impulses() / (SAMPLE_EVERY * dt))
            rec["theta"].append(world.data.contact_theta.to_numpy()[blocks, 0])
            rec["xi"].append(world.data.contact_xi.to_numpy()[blocks, 0])
    wall = time.perf_counter() - start
    world.check()
    r = {k: np.asarray(v) for k, v in rec.items()}
    t = r["t"]
    # The base (every point of it moves alike along x to first order in the tilt) and the
    # contact's slip: the base's displacement less what the stick spring took up (xi < 0
    # when the block moves +x over the floor, its only contact).
    base_x = r["x"] + 0.5 * HEIGHT * np.sin(r["angle"])
    base_v = r["v"] + 0.5 * HEIGHT * r["omega"] * np.cos(r["angle"])
    slipped = base_x + r["xi"]
    i0 = int(np.searchsorted(t, HOLD_AT - 1e-9 * dt)) - 1  # last sample before the load
    loaded = t > HOLD_AT
    window = np.nonzero(t > HOLD_AT + RAMP + SLIDE_SETTLE)[0]
    stretch = base.mu0 * PRESS / k_t
    creep = base.v_star * (RAMP + OBSERVE)
    out: dict[str, dict] = {}
    for j, (rule, load) in enumerate(cases):
        x, v, f, theta = base_x[:, j], base_v[:, j], r["force"][:, j], r["theta"][:, j]
        moving = np.nonzero(np.abs(v[: i0 + 1]) > 0.1 * V0)[0]
        theta_load = float(theta[i0])
        dx = np.max(np.abs(x[loaded] - x[i0]))
        slip = np.max(np.abs(slipped[loaded, j] - slipped[i0, j]))
        entry: dict[str, Any] = {
            "slid_before_load_m": float(x[i0] - scenes[j].positions[BLOCK, 0]),
            "slowed_below_v0_over_10_by_s": float(t[moving[-1] + 1]) if moving.size else 0.0,
            "base_speed_at_load_m_s": float(v[i0]),
            "theta_at_load": None if theta_load > 0.5 * NO_INTERFACE else theta_load,
            "mu_at_load": _mu_at_rest(base, rule, theta_load),
            "max_base_displacement_m": float(dx),
            "max_base_displacement_over_mu0F_kt": float(dx / stretch),
            "max_contact_slip_m": float(slip),
            "interface_under_load": bool(np.any(theta[loaded] < 0.5 * NO_INTERFACE)),
            "final_speed_m_s": float(v[-1]),
        }
        # Held: the contact slipped no more than a creep below v_star over the load's time.
        entry["held"] = bool(slip < creep)
        if not entry["held"]:
            a, b = window[0] - 1, window[-1]
            accel = (r["v"][b, j] - r["v"][a, j]) / (t[b] - t[a])
            mu_c = float(np.sum(-f[window, 0]) / np.sum(f[window, 1]))
            closed = (load * base.mu0 - mu_c) * PRESS / mass
            mu_law = _law_along(laws[j], t[a:], np.gradient(slipped[a:, j], t[a:]), theta[a])
            mu_dem = -f[a + 1 :, 0] / f[a + 1 :, 1]
            entry["slide"] = {
                "window_s": [float(t[a]), float(t[b])],
                "acceleration": float(accel),
                "mu_contact": mu_c,
                "closed_form_acceleration": float(closed),
                "rel_error": float(abs(accel - closed) / abs(closed)),
                "speed_range_m_s": [float(r["v"][a, j]), float(r["v"][b, j])],
                "mean_normal_force": float(np.mean(f[window, 1])),
                "max_abs_mu_contact_minus_law": float(np.max(np.abs(mu_dem - mu_law[1:]))),
            }
        out.setdefault(rule, {})[f"{load:g}"] = entry
    return {
        "setup": {
            "press_N": PRESS,
            "mass_kg": mass,
            "v0_m_s": V0,
            "load_starts_s": HOLD_AT,
            "ramp_s": RAMP,
            "observe_s": OBSERVE,
            "dt": dt,
            "k_t_N_per_m": k_t,
            "mu0F_over_kt_m": stretch,
            "held_if_contact_slips_less_than_m": creep,
            "theta_after_sliding_at_v0": -base.B * math.log(V0 / base.v_star),
            "wall_time_s": wall,
        },
        "cases": out,
    }


def _law_along(law: RateState, t: np.ndarray, v: np.ndarray, theta0: float) -> np.ndarray:
    """mu of the law along a sampled slip rate from ``theta0`` at ``t[0]`` (rates above
    v_star): theta relaxes exactly toward ``-B x`` with x held at the interval's mean rate,
    and ``mu = max(mu0 + theta + A x, 0)`` with x of the rate at each sample."""
    x = np.log(np.maximum(v, law.v_star) / law.v_star)
    theta = np.empty(t.size)
    theta[0] = theta0
    for k in range(t.size - 1):
        xm = 0.5 * (x[k] + x[k + 1])
        decay = math.exp(-(t[k + 1] - t[k]) / law.t_c)
        theta[k + 1] = -law.B * xm + (theta[k] + law.B * xm) * decay
    return np.maximum(law.mu0 + theta + law.A * x, 0.0)


def _mu_at_rest(law: RateState, rule: str, theta: float) -> float:
    """What a stuck contact under ``rule`` with state ``theta`` holds, over F_n, to ``K
    v_star`` (slip.contact_friction): mu0 with no interface; the law's mu at v_star,
    ``max(mu0 + theta, 0)``, with one (under ``relaxing`` too, whose mu0 below v_star
    applies only while the contact slides slower than v_star: the load here moves its
    surfaces faster)."""
    if rule == "paper" or theta > 0.5 * NO_INTERFACE:
        return law.mu0
    return max(law.mu0 + theta, 0.0)


__all__ = ["block_scene", "hold_slide"]
