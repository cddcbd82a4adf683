"""Which slip rate a rate-and-state contact should use: five definitions side by side on one
block (``python validation/slip_definitions.py``).

A one-dimensional block (276 kg) pressed onto a fixed floor by F_n, its contact a stick
spring ``k_t = 0.5 k_e L`` (L = 1 m) and dashpot capped at mu F_n, stepped as the engine steps
(``contact_law.tangential_force`` for the spring and its cap, then symplectic Euler). Only the
friction law's slip rate and a new interface's start differ:

- ``sliding``: the sliding rate ``V = (|F_trial| - mu(V) F_n) / K``, every new interface in
  equilibrium there, with the dashpot ``c_t = 0.5 k_v L`` (the landed code before issue 26);
- ``sliding, critical``: the same with the critically damped dashpot;
- ``surface``: the surfaces' speed ``|s|`` while the contact slides;
- ``capped``: the sliding rate capped at ``|s|``, every new interface at its capped rate;
- ``regularised``: a law continuous through V = 0, ``mu = A asinh(V / (2 v_star) e^((mu0 +
  theta) / A))``, theta relaxing toward ``-B ln(max(V, v_star) / v_star)``, no rule below
  v_star, V the capped sliding rate;
- ``chosen``: ``slip.contact_friction``: capped, a contact at rest starts at v_star, a
  reversed slip ends the interface (the engine's).

Every definition but the first runs with the critically damped dashpot and ends an
interface whose slip reverses. Checks (the engine's, ``validation.contact_convergence``, in
one dimension): the driven slider's frictional work and slip starts over five halvings of
dt; a block stopped by its friction under a pull of 0.5, 0.8 and 1.2 mu0 F_n; steady
sliding against a stop on a floor at 1 mm/s to 10 cm/s. Prints a table and writes
``slip_definitions.json`` with ``--out``. About 3 minutes.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from taichi_ice.codes import RestRule, ThetaMethod
from taichi_ice.physics.contact_law import tangential_damping, tangential_force
from taichi_ice.physics.slip import NEW_CONTACT, NO_INTERFACE, contact_friction

A, B, MU0, V_STAR, T_C = 0.05, 0.112, 0.872, 1e-5, 3.0
K_E, K_V, RATIO, WIDTH = 9.75e7, 3.16e4, 0.5, 1.0
MASS, PRESS = 276.0, 1.0e4
K_T = RATIO * K_E * WIDTH
DEFINITIONS = ("sliding", "sliding, critical", "surface", "capped", "regularised", "chosen")


def _affine(theta, dt, fresh):
    """theta_new(y) = a + b y over a step (exponential integrator; fresh: -B y)."""
    if fresh:
        return 0.0, -B
    e = math.exp(-dt / T_C)
    return theta * e, -B * (1.0 - e)


def _root(g, lo, hi):
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if g(mid) < 0.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def friction(definition, theta, last, s, f_trial, f_n, K, dt):
    """``(mu, theta_new, V signed)`` of one contact step under ``definition``."""
    if definition == "chosen":
        return contact_friction(
            theta,
            last,
            s,
            f_trial,
            f_n,
            K,
            dt,
            A,
            B,
            MU0,
            V_STAR,
            T_C,
            1,
            RestRule.PAPER,
            ThetaMethod.EXPONENTIAL,
        )
    speed = abs(s)
    if definition != "sliding" and last * s < 0.0:
        theta = NO_INTERFACE  # a reversed slip passed through zero
    fresh = theta > 0.5 * NO_INTERFACE
    sign = -1.0 if s < 0.0 else 1.0
    if definition == "regularised":
        th0 = 0.0 if fresh else theta
        e = math.exp(-dt / T_C)

        def parts(v):
            x = math.log(max(v, V_STAR) / V_STAR)
            th = -B * x + (th0 + B * x) * e
            return A * math.asinh(v / (2 * V_STAR) * math.exp((MU0 + th) / A)), th

        v = speed
        if K * speed + f_n * parts(speed)[0] - f_trial > 0.0:
            v = _root(lambda u: K * u + f_n * parts(u)[0] - f_trial, 0.0, speed)
        mu, th = parts(v)
        return mu, th, sign * v
    a, b = _affine(theta, dt, fresh)
    c0, c1 = MU0 + a, A + b
    if K * V_STAR + f_n * max(c0, 0.0) - f_trial >= 0.0 or (
        definition != "sliding" and definition != "sliding, critical" and speed <= V_STAR
    ):
        return MU0, NO_INTERFACE, 0.0
    if definition == "surface":
        y = math.log(max(speed, V_STAR) / V_STAR)
    else:
        hi = math.log(f_trial / (K * V_STAR))
        y = _root(
            lambda u: K * V_STAR * math.exp(u) + f_n * max(c0 + c1 * u, 0.0) - f_trial, 0.0, hi
        )
        if definition == "capped" and speed > V_STAR:
            y = min(y, math.log(speed / V_STAR))
    th = a + b * y
    return max(MU0 + th + A * y, 0.0), th, sign * V_STAR * math.exp(y)


def simulate(
    definition,
    dt,
    until,
    *,
    v0=0.0,
    pull=0.0,
    driver=None,
    floor=0.0,
    stop=False,
    ramp=0.0,
    sample=None,
):
    """One block: its frictional work, slip starts, path, and the mean friction force over
    the last second."""
    critical = definition != "sliding"
    c_t = tangential_damping(K_T, 1.0, 1.0 / MASS, 0.0, 0.0, 0.0) if critical else RATIO * K_V
    x, u, xi, theta, last = 0.0, v0, 0.0, NEW_CONTACT, 0.0
    work, starts, sliding = 0.0, 0, False
    f_driver = 0.0
    every = round(driver[2] / dt) if driver else 1
    n = round(until / dt)
    window = []
    for k in range(n):
        t = k * dt
        v_floor = floor * min(1.0, t / ramp) if ramp else floor
        s = u - v_floor
        K = K_T * dt + c_t
        f_trial = abs(K_T * (xi + s * dt) + c_t * s)
        mu, theta, last = friction(definition, theta, last, s, f_trial, PRESS, K, dt)
        f_t, xi, slip_work, _ = tangential_force(xi, s, dt, K_T, c_t, mu * PRESS)
        now = theta < 0.5 * NO_INTERFACE
        starts += now and not sliding
        sliding = now
        work += slip_work
        if driver and k % every == 0:
            f_driver = driver[0] * (driver[1](t) - x)
        force = f_t + pull + f_driver
        if stop and x < 0.0:
            force += -K_E * 0.1 * x - K_V * 0.1 * u
        if t > until - 1.0:
            window.append(f_t)
        u += dt * force / MASS
        x += dt * u
    return {"work": work, "starts": starts, "x": x, "mu_mean": abs(np.mean(window)) / PRESS}


def driver_position(t):
    w = 2.0 * math.pi / 4.0
    return 0.1 / w * (1.0 - math.cos(w * t))


def checks(definition) -> dict:
    out = {}
    runs = [
        simulate(definition, 4e-4 / 2**k, 12.0, driver=(2e5, driver_position, 1e-3))
        for k in range(6)
    ]
    works = [r["work"] for r in runs]
    errors = [abs(w / works[-1] - 1.0) for w in works[:-1]]
    hs = [4e-4 / 2**k for k in range(5)]
    keep = [(h, e) for h, e in zip(hs, errors) if e > 0]
    order = float(np.polyfit(*np.log(np.array(keep)).T, 1)[0]) if len(keep) > 1 else None
    out["slider"] = {"work_J": works, "starts": [r["starts"] for r in runs], "order": order}
    hold = {}
    for v0 in (0.05, 0.5, 1.0):
        for load in (0.5, 0.8, 1.2):
            r = simulate(definition, 2e-5, 3.0, v0=v0, pull=-load * MU0 * PRESS)
            hold[f"{v0:g} m/s, {load:g}"] = "held" if abs(r["x"]) < 0.05 else "slid"
    out["hold"] = hold
    steady = {}
    for v in (1e-3, 1e-2, 1e-1):
        r = simulate(definition, 5e-5, 30.0, floor=-v, stop=True, ramp=1.0)
        mu_ss = MU0 + (A - B) * math.log(v / V_STAR)
        steady[f"{v:g} m/s"] = r["mu_mean"] / mu_ss - 1.0
    out["steady"] = steady
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="folder for slip_definitions.json")
    args = parser.parse_args(argv)
    results = {}
    for definition in DEFINITIONS:
        r = checks(definition)
        results[definition] = r
        s = r["slider"]
        held = sum(v == "held" for k, v in r["hold"].items() if not k.endswith("1.2"))
        slid = sum(v == "slid" for k, v in r["hold"].items() if k.endswith("1.2"))
        steady = ", ".join(f"{e:+.1%}" for e in r["steady"].values())
        order = "none" if s["order"] is None else f"{s['order']:.2f}"
        print(
            f"{definition:18s} slider work {s['work_J'][0]:.1f} -> {s['work_J'][-1]:.1f} J, "
            f"order {order}, starts {sorted(set(s['starts']))}; held {held}/6 below mu0, "
            f"slid {slid}/3 above; steady sliding {steady}",
            flush=True,
        )
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "slip_definitions.json").write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
