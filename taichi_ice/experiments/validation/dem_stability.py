"""The largest time step each scene survives, against the computed limit ``stable_dt``.

``timestep.stable_time_step`` bounds the explicit contact integration by the stiffest contact
(a body's longest edge) at the lightest effective mass (two bodies hit at their farthest
corner, where rotation makes them feel lighter). Real contacts are rarely that bad, so a
scene survives some multiple of it; in a jam a block has 4-6 contacts and its highest
frequency rises, so the multiple falls. Here, by bisection on ``ratio = dt / stable_dt``
with short runs (``force_dt``), for

- ``free collision``: the offset collision of a square and a block (``dem_scenes``), 10 ms;
- ``dense field``: the pillar scene's 63 diamonds shut in a box at random velocities, 0.5 s;
- ``jam``: the pillar scene at mu = 0.9 until its jam carries its full load (17 s; ~3 MN);

"survives" means the run ends without ``DivergenceError`` (the engine's checks: a
non-finite or runaway velocity, or kinetic energy plus what was dissipated exceeding what
came in by half of it, ``budget.breached``) or ``CapacityError`` (more contacts than
slots: overlaps a resolved step never makes). Every trial also reports the budget residual
over the energy that came in (positive: missing; negative: created) and the energy the
bodies hold at the end over it (above 1: the step made energy). Near the limit the two
differ: at large steps the contacts' work is booked at the start-of-step velocity, which
books the dashpots' dissipation too high, so the residual goes negative before the bodies
gain energy (the free collision at 1.95 stable_dt holds 0.75 of the energy it was given,
and books 0.76 of it as dissipated).

From the limits, ``recommend`` picks the default ``dt_safety``: the largest candidate that
keeps ``MARGIN`` x in every scene (the jam's limit is the smallest) and whose errors in the
accuracy study (``dem_accuracy``) stay within ``ACCURACY``.
"""

from __future__ import annotations

import math
import time
from typing import Any

from . import dem_scenes

# Bisection stops when the bracket is this tight (hi / lo - 1).
TOLERANCE = 0.1
# First guesses; the bracket grows by GROW (or shrinks) until one end fails and one survives.
# A collision of faces has a heavier effective mass than the corner hit the limit assumes;
# a jam has more contacts per block than anything else.
START = {"free collision": 1.5, "dense field": 2.0, "jam": 1.2}
GROW = 1.25
MAX_RATIO = 16.0
# Run lengths (s) and sampling (s) of each scene.
SCENES = {
    "free collision": {"until": dem_scenes.COLLISION_END, "sample": dem_scenes.COLLISION_END},
    "dense field": {"until": 0.5, "sample": 0.01},
    "jam": {"until": 17.0, "sample": 0.01},
}

# The recommendation: the default keeps at least this factor below the smallest measured
# limit (a heavier jam, more blocks or a stiffer packing than ours may lower it), and its
# errors in the accuracy study stay within these (relative; the pillar measures against a
# run at a quarter of the step).
MARGIN = 2.0
CANDIDATES = (0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.6)


def scene_of(name: str):
    if name == "free collision":
        return dem_scenes.collision(dem_scenes.OFFSET, "coulomb")
    if name == "dense field":
        return dem_scenes.dense_box()
    if name == "jam":
        return dem_scenes.jam()
    raise ValueError(name)


def trial(
    scene, ratio: float, until: float, sample: float, integrator: str = "euler"
) -> dict[str, Any]:
    """One run at ``dt = ratio x stable_dt`` with ``integrator``: did it survive, and what
    did it create?"""
    from ...errors import TaichiIceError
    from ...run.budget import as_series, came_in, residual
    from ...run.simulation import Simulation

    dt = ratio * scene.stable_dt
    start = time.perf_counter()
    sim = Simulation(
        dem_scenes.with_step(scene, dt, sample, frames=10),
        dt=dt,
        force_dt=True,
        integrator=integrator,
    )
    out: dict[str, Any] = {"ratio": sim.dt / scene.stable_dt, "dt": sim.dt}
    try:
        sim.run(until=until)
        out["survived"] = True
    except TaichiIceError as exc:
        out.update(survived=False, failure=str(exc), failed_at=sim.time)
    now, start_e = as_series(sim.world.energies()[0]), as_series(sim.initial_energy[0])
    came = float(came_in(now, start_e))
    held = float(now["kinetic_energy"] + now["elastic_energy"])
    out["residual_over_energy_in"] = float(residual(now, start_e)) / came if came > 0 else None
    # What the bodies hold against what came in: above 1, the step itself made energy
    # (the residual can also go negative from dissipation booked too high at large steps).
    out["held_over_energy_in"] = held / came if came > 0 else None
    out["wall_s"] = time.perf_counter() - start
    return out


def find_limit(name: str, log=print, integrator: str = "euler") -> dict[str, Any]:
    """Bisect the largest surviving ``dt / stable_dt`` of one scene with ``integrator``."""
    scene = scene_of(name)
    until, sample = SCENES[name]["until"], SCENES[name]["sample"]
    trials: list[dict[str, Any]] = []

    def run(ratio: float) -> bool:
        t = trial(scene, ratio, until, sample, integrator)
        trials.append(t)
        state = "survived" if t["survived"] else f"failed at t = {t['failed_at']:.3g} s"
        log(
            f"dem stability [{integrator}]: {name:14s} dt = {t['ratio']:.3f} x stable_dt: {state} "
            f"[{t['wall_s']:.1f} s]"
        )
        return t["survived"]

    lo = hi = None
    ratio = START[name]
    while lo is None or hi is None:
        if run(ratio):
            lo = ratio
            if hi is None:
                ratio *= GROW
                if ratio > MAX_RATIO:
                    break
        else:
            hi = ratio
            if lo is None:
                ratio /= GROW
                if ratio < 1e-3:
                    break
    while lo is not None and hi is not None and hi / lo - 1.0 > TOLERANCE:
        mid = math.sqrt(lo * hi)
        if run(mid):
            lo = mid
        else:
            hi = mid
    survivors = [t for t in trials if t["survived"]]
    failures = [t for t in trials if not t["survived"]]
    # Not monotone in dt: a survivor above a failure (kept visible, the bisection's bracket
    # is what is reported).
    non_monotone = bool(
        survivors
        and failures
        and max(t["ratio"] for t in survivors) > min(t["ratio"] for t in failures)
    )
    return {
        "scene": name,
        "integrator": integrator,
        "until_s": until,
        "stable_dt": scene.stable_dt,
        "largest_surviving_ratio": lo,
        "smallest_failing_ratio": hi,
        "non_monotone": non_monotone,
        "trials": sorted(trials, key=lambda t: t["ratio"]),
    }


def run_all(log=print, integrator: str = "euler") -> dict[str, Any]:
    """The limit of every scene with ``integrator`` (Taichi must run, float64)."""
    return {name: find_limit(name, log=log, integrator=integrator) for name in SCENES}


def recommend(limits: dict[str, Any], error_at: dict[str, Any], accuracy: dict[str, float]):
    """The default ``dt_safety`` from the limits and the accuracy study.

    Args:
        limits: ``run_all``'s result.
        error_at: ``{measure: callable(ratio) -> error}`` from the accuracy study
            (interpolated on its ladder; f64, Coulomb and rate-and-state).
        accuracy: ``{measure: largest error allowed}``.

    Returns:
        The recommendation, the margin it keeps in each scene, and why each candidate above
        it was refused.
    """
    found = {k: v["largest_surviving_ratio"] for k, v in limits.items()}
    known = [v for v in found.values() if v]
    smallest = min(known) if known else None
    refused: dict[str, str] = {}
    table: dict[str, Any] = {}
    chosen = None
    for s in CANDIDATES:
        table[f"{s:g}"] = {
            "margin": {k: (v / s if v else None) for k, v in found.items()},
            "errors": {m: error_at[m](s) for m in accuracy},
        }
        reasons = []
        if smallest is not None and smallest / s < MARGIN:
            reasons.append(f"margin {smallest / s:.2f} < {MARGIN:g} in the tightest scene")
        for measure, limit in accuracy.items():
            err = error_at[measure](s)
            if err is None or not err <= limit:
                shown = "n/a" if err is None else f"{err:.3g}"
                reasons.append(f"{measure} {shown} > {limit:g}")
        if reasons:
            refused[f"{s:g}"] = "; ".join(reasons)
        else:
            chosen = s
    margins = {k: (v / chosen if v and chosen else None) for k, v in found.items()}
    return {
        "dt_safety": chosen,
        "margin": margins,
        "jam_margin": margins.get("jam"),
        "rule": (
            f"the largest of {list(CANDIDATES)} that keeps at least {MARGIN:g} x below the "
            "smallest measured limit and whose errors stay within the accuracy limits"
        ),
        "accuracy_limits": accuracy,
        "refused": refused,
        "candidates": table,
    }


__all__ = ["find_limit", "recommend", "run_all", "trial"]
