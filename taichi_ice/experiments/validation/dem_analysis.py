"""Errors, costs, convergence orders and parting times of the DEM accuracy study's runs.

Reads what the workers of ``dem_accuracy`` wrote (``dem_runs/<precision>/index.json`` and the
arrays beside it) and returns the study's JSON summary; NumPy and SciPy (the collision ODE),
no Taichi runtime.

Errors (relative unless said):

- collisions, against ``collision_ode``: restitution ``e = (u1 - u0) / 1 m/s`` (the
  centroids' x velocities after the contact), contact duration (from t = 0, when they touch,
  to the last overlap of the free flight traced back from the end), the square's spin after;
- pushed box: ``max_t |budget residual| / work in`` (no reference: zero is exact);
- pillar: peak pillar force, frictional energy and the largest block displacement (m)
  against the float64 reference run (a quarter of the default step) of the same integrator,
  up to the time ``T`` when the run at the default step parts from it (a block ``PART`` from
  its twin, at the 0.1 s frames; each law and integrator its own ``T``); positions at ``T``.
  The references of the two integrators are also held against each other.

Every record and point names its friction law (``law``) and its ``integrator`` (records
from before the integrators were compared have none: Euler).

Orders: ``error = C (h^p - h_ref^p)`` (``h = dt / stable_dt``; ``h_ref`` that of the
reference run, 0 for the ODE) fitted in log space over the steps at or below
``ORDER_MAX_RATIO`` whose errors are above round-off; ``scatter`` is the fit's RMS residual
in decades (a large one: not in the asymptotic range, or an erratic error).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Callable

import numpy as np

from . import collision_ode, dem_scenes, dem_stability

PART = 0.01  # m: two runs have parted once a block is this far from its twin (1 % of it)
DEPART = 1e-9  # m: ... and have started to depart at this distance
ORDER_MAX_RATIO = 0.4
# The pushed box has no run between 0.2 and 0.8 stable_dt (each dt is a kernel compilation).
ORDER_MAX_RATIO_OF = {"pushed box": 0.8}
ORDER_FLOOR = {"f64": 1e-12, "f32": 1e-5}  # errors below this are round-off
# A fit "converges" above this order with less scatter than this (decades): otherwise the
# error is not in its asymptotic range, or does not shrink with dt.
CONVERGING_ORDER = 0.5
CONVERGING_SCATTER = 0.15
# The recommended dt_safety keeps these errors (float64, at dt = dt_safety x stable_dt,
# interpolated on the ladder; the largest over both laws) within:
# A contact's energy loss (restitution) and duration are what the contact model is built to
# give; the pillar force and frictional energy are the paper's measures; the budget must
# close (DESIGN: "up to a residual that shrinks with dt"). Keys: "scene: measure" (the
# largest error over both laws) or "scene: measure/law". (Until issue 30 the rate-and-state
# pillar measures were left out: before issue 26 they did not converge; now they do, at
# order 0.85 and 2.4 with the Euler step.)
ACCURACY = {
    "face-on collision: restitution": 0.02,
    "face-on collision: duration": 0.02,
    "offset collision: spin": 0.05,
    "pushed box: budget residual": 0.01,
    "pillar: peak force": 0.02,
    "pillar: friction energy": 0.02,
}
MEASURES = {
    "face-on collision": ("restitution", "duration"),
    "offset collision": ("restitution", "duration", "spin"),
    "pushed box": ("budget residual",),
    "pillar": ("peak force", "friction energy", "positions"),
}


def _load(parts: dict[str, Any], runs_dir: Path) -> list[dict[str, Any]]:
    records = []
    for precision, index in parts.items():
        for r in index["records"]:
            r = dict(r)
            if "arrays" in r:
                with np.load(runs_dir / precision / r["arrays"]) as z:
                    r["data"] = {k: z[k] for k in z.files}
            records.append(r)
    return records


def integrator_of(r: dict[str, Any]) -> str:
    """A record's or point's integrator (Euler where none is named)."""
    return r.get("integrator") or "euler"


def label(law: str, integrator: str) -> str:
    """How the charts and tables name a law run with an integrator."""
    return law if integrator == "euler" else f"{law}, {integrator}"


def _timing(records: list[dict[str, Any]]) -> dict[tuple[str, ...], dict[str, Any]]:
    """Wall per step of one world alone (its kernels compiled), per (scene, law, integrator,
    precision); from a batch (its wall per step, compilation included) where no such run
    exists."""
    out: dict[tuple[str, ...], dict[str, Any]] = {}
    for r in records:
        scene = "collision" if r.get("kind") == "timing" else r.get("scene")
        if scene not in ("collision", "pillar", "pushed box") or r.get("nudged"):
            continue
        key = (scene, r["law"], integrator_of(r), r["precision"])
        if r.get("wall_per_step_s"):
            out[key] = {
                "wall_per_step_s": r["wall_per_step_s"],
                "alone": True,
                "steps": r["timed_steps"],
                "dt": r["dt"],
            }
        elif key not in out and r.get("steps") and r.get("wall_s"):
            out[key] = {
                "wall_per_step_s": r["wall_s"] / r["steps"],
                "alone": False,
                "steps": r["steps"],
                "dt": r["dt"],
            }
    return out


def _collisions(records, timing, log) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    refs: dict[tuple[str, str], dict[str, Any]] = {}
    points = []
    for r in records:
        if r.get("scene") not in MEASURES or "collision" not in r["scene"]:
            continue
        key = (r["scene"], r["law"])
        scene = dem_scenes.collision(dem_scenes.COLLISIONS[r["scene"]], r["law"])
        if key not in refs:
            ode = collision_ode.solve_collision(scene, dem_scenes.COLLISION_END)
            touch, apart = ode["contacts"][0]
            refs[key] = {
                "restitution": _restitution(ode["velocity"]),
                "duration": apart - touch,
                "spin": float(ode["omega"][0]),
                "contacts": len(ode["contacts"]),
                "rhs_calls": ode["rhs_calls"],
            }
            if r["scene"] == "face-on collision":
                m0, m1 = scene.masses
                width = dem_scenes.BLOCK_LENGTH
                dur, rest = collision_ode.clamped_oscillator(
                    scene.ice.contact_stiffness * width,
                    scene.ice.contact_viscosity * width,
                    m0 * m1 / (m0 + m1),
                    dem_scenes.CLOSING_SPEED,
                )
                refs[key]["closed_form"] = {"restitution": rest, "duration": dur}
            log(
                f"dem accuracy: ODE of the {r['scene']} ({r['law']}): restitution "
                f"{refs[key]['restitution']:.6f}, duration {refs[key]['duration'] * 1e3:.4f} ms, "
                f"spin {refs[key]['spin']:.5f} rad/s"
            )
        ref = refs[key]
        got: dict[str, float] = {}
        if r["status"] == "complete":
            d = r["data"]
            got["restitution"] = _restitution(d["velocity"])
            got["duration"] = collision_ode.last_separation(
                scene, d["position"], d["angle"], d["velocity"], d["omega"], r["t_end"], 0.0
            )
            got["spin"] = float(d["omega"][0])
        for m in MEASURES[r["scene"]]:
            err = abs(got[m] / ref[m] - 1.0) if m in got else None
            points.append(_point(r, m, err, timing, "collision", value=got.get(m)))
    reference = {f"{s}/{law}": v for (s, law), v in refs.items()}
    return reference, points


def _restitution(velocity) -> float:
    v = np.asarray(velocity)
    return float((v[1, 0] - v[0, 0]) / dem_scenes.CLOSING_SPEED)


def _point(r, measure, err, timing, cost_scene, value=None, **extra) -> dict[str, Any]:
    t = timing.get((cost_scene, r["law"], integrator_of(r), r["precision"]))
    cost = t["wall_per_step_s"] / r["dt"] if t else None
    out = {
        "scene": r["scene"],
        "measure": measure,
        "law": r["law"],
        "integrator": integrator_of(r),
        "precision": r["precision"],
        "ratio": r["ratio"],
        "dt": r["dt"],
        "error": err,
        "value": value,
        "wall_per_simulated_s": cost,
        "status": r["status"],
    }
    out.update(extra)
    if r["status"] != "complete":
        out["failure"] = r.get("failure")
    return out


def _pushed(records, timing) -> list[dict[str, Any]]:
    from ...run.budget import residual

    points = []
    for r in records:
        if r.get("scene") != "pushed box":
            continue
        err = None
        if r["status"] == "complete":
            d = r["data"]
            res = np.abs(residual(d))
            err = float(res.max() / d["work_in"][-1])
        points.append(_point(r, "budget residual", err, timing, "pushed box"))
    return points


def separation(a: dict[str, np.ndarray], b: dict[str, np.ndarray], dynamic) -> tuple:
    """Frame times and the largest distance (m) between the same block in two runs."""
    n = min(a["frame_time"].size, b["frame_time"].size)
    gap = np.linalg.norm(a["position"][:n, dynamic] - b["position"][:n, dynamic], axis=-1)
    return a["frame_time"][:n], gap.max(axis=1)


def first_time(t: np.ndarray, gap: np.ndarray, threshold: float) -> float | None:
    hit = np.flatnonzero(gap > threshold)
    return float(t[hit[0]]) if hit.size else None


def _pillar(records, timing, cfg, dynamic) -> tuple[list, list, dict]:
    """Errors of every pillar run against the float64 reference of its integrator, over each
    (law, integrator)'s window; when the runs at a step and at a quarter of it part; and the
    two integrators' references against each other."""
    records = [
        r
        for r in records
        if r.get("scene") == "pillar" and not r.get("nudged") and not r.get("timing_only")
    ]
    ref_ratio = _ratio_of(records, cfg)
    refs = {
        (r["law"], integrator_of(r)): r
        for r in records
        if r["precision"] == "f64" and math.isclose(r["ratio"], ref_ratio) and "data" in r
    }
    by = {
        (r["law"], integrator_of(r), r["precision"], round(r["ratio"], 6)): r
        for r in records
        if "data" in r
    }
    pairs = []
    for (law, integ, prec, _), r in sorted(by.items()):
        fine = next(
            (
                v
                for (lw, i, p, _), v in by.items()
                if (lw, i, p) == (law, integ, prec)
                and math.isclose(v["ratio"] * 4, r["ratio"], rel_tol=1e-9)
            ),
            None,
        )
        if fine is None:
            continue
        t, gap = separation(r["data"], fine["data"], dynamic)
        pairs.append(
            {
                "law": law,
                "integrator": integ,
                "precision": prec,
                "ratio": r["ratio"],
                "quarter": fine["ratio"],
                "until": float(t[-1]),
                "parted_at": first_time(t, gap, PART),
                "departed_at": first_time(t, gap, DEPART),
                "time": t.tolist(),
                "largest_gap_m": gap.tolist(),
            }
        )
    # Each (law, integrator)'s window: until the run at the default step parts from the
    # reference (a quarter of its step), or the whole run.
    windows = {}
    for (law, integ), ref in refs.items():
        pair = next(
            (
                p
                for p in pairs
                if (p["law"], p["integrator"], p["precision"]) == (law, integ, "f64")
                and math.isclose(p["quarter"], ref["ratio"])
            ),
            None,
        )
        whole = float(ref["data"]["time"][-1])
        windows[law, integ] = pair["parted_at"] if pair and pair["parted_at"] is not None else whole
    points = []
    for r in records:
        key = (r["law"], integrator_of(r))
        if key not in refs or r is refs[key] or "data" not in r:
            continue
        d, rd = r["data"], refs[key]["data"]
        end = windows[key]
        t, gap = separation(d, rd, dynamic)
        extra = {"parted_at": first_time(t, gap, PART), "compared_to": end}
        if r["status"] != "complete" and float(d["time"][-1]) < end - 1e-9:
            for m in MEASURES["pillar"]:
                points.append(_point(r, m, None, timing, "pillar", **extra))
            continue
        values = {"got": _pillar_values(d, end), "ref": _pillar_values(rd, end)}
        errors = {
            m: abs(values["got"][m] / values["ref"][m] - 1.0) if values["ref"][m] else None
            for m in ("peak force", "friction energy")
        }
        errors["positions"] = float(gap[int(np.searchsorted(t, end + 1e-9)) - 1])
        for m in MEASURES["pillar"]:
            points.append(
                _point(r, m, errors[m], timing, "pillar", value=values["got"].get(m), **extra)
            )
    reference = {
        f"{law}/{integ}": {
            "law": law,
            "integrator": integ,
            "ratio": r["ratio"],
            "dt": r["dt"],
            "status": r["status"],
            "window_s": windows[law, integ],
            "peak_force_N": float(np.linalg.norm(r["data"]["probe_force"][:, 0, :], axis=-1).max()),
            "friction_energy_J": float(r["data"]["friction_energy"][-1]),
        }
        for (law, integ), r in refs.items()
    }
    # The references of two integrators converge to one solution: held against each other
    # over the shorter of their windows.
    for (law, integ), r in refs.items():
        base = refs.get((law, "euler"))
        if integ == "euler" or base is None:
            continue
        end = min(windows[law, integ], windows[law, "euler"])
        t, gap = separation(r["data"], base["data"], dynamic)
        mine, theirs = _pillar_values(r["data"], end), _pillar_values(base["data"], end)
        reference[f"{law}/{integ}"]["against_euler"] = {
            "until_s": end,
            "parted_at": first_time(t, gap, PART),
            "positions": float(gap[int(np.searchsorted(t, end + 1e-9)) - 1]),
            **{m: abs(mine[m] / theirs[m] - 1.0) if theirs[m] else None for m in mine},
        }
    return points, pairs, reference


def _pillar_values(run: dict[str, np.ndarray], end: float) -> dict[str, float]:
    """The pillar measures of one run up to ``end`` (s)."""
    use = run["time"] <= end + 1e-9
    force = np.linalg.norm(run["probe_force"][use, 0, :], axis=-1)
    return {
        "peak force": float(force.max()),
        "friction energy": float(run["friction_energy"][use][-1]),
    }


def _ratio_of(records, cfg) -> float:
    """Actual ratio of the float64 reference run (nominal ``reference_ratio``)."""
    ratios = sorted(
        {r["ratio"] for r in records if r.get("scene") == "pillar" and r["precision"] == "f64"}
    )
    if not ratios or cfg["reference_ratio"] is None:
        return math.nan
    return min(ratios, key=lambda x: abs(x / cfg["reference_ratio"] - 1.0))


def _chaos(records, dynamic) -> dict[str, Any]:
    """Each nudged pillar run against its twin: when they depart and part."""
    out = {}
    runs = [r for r in records if r.get("scene") == "pillar" and "data" in r]
    for twin in (r for r in runs if r.get("nudged")):
        law = twin["law"]
        base = next(
            r
            for r in runs
            if r["law"] == law
            and integrator_of(r) == integrator_of(twin)
            and not r.get("nudged")
            and not r.get("timing_only")
            and r["precision"] == twin["precision"]
            and r["dt"] == twin["dt"]
        )
        t, gap = separation(base["data"], twin["data"], dynamic)
        out[label(law, integrator_of(twin))] = {
            "law": law,
            "integrator": integrator_of(twin),
            "ratio": base["ratio"],
            "dt": base["dt"],
            "nudged_body": twin["nudged_body"],
            "until": float(t[-1]),
            "status": base["status"],
            "departed_at": first_time(t, gap, DEPART),
            "parted_at": first_time(t, gap, PART),
            "time": t.tolist(),
            "largest_gap_m": gap.tolist(),
        }
    return out


def fit_order(
    ratios, errors, h_ref: float, precision: str, max_ratio: float = ORDER_MAX_RATIO
) -> dict[str, Any] | None:
    """``p`` of ``error = C (h^p - h_ref^p)`` over the asymptotic range, and its scatter."""
    h = np.asarray(ratios, dtype=float)
    e = np.asarray([np.nan if x is None else x for x in errors], dtype=float)
    use = (h <= max_ratio * 1.01) & (h > h_ref * 1.01) & np.isfinite(e)
    use &= e > ORDER_FLOOR[precision]
    if use.sum() < 3:
        return None
    h, e = h[use], np.log(e[use])
    best = None
    # Against the ODE (h_ref = 0) the model is C h^p, and a negative order (the error grows
    # as dt shrinks) may show; against a reference run it needs p > 0.
    for p in np.arange(-1.0 if h_ref == 0 else 0.05, 4.0001, 0.005):
        g = p * np.log(h) if h_ref == 0 else np.log(h**p - h_ref**p)
        c = np.mean(e - g)
        rms = float(np.sqrt(np.mean((e - g - c) ** 2)))
        if best is None or rms < best[1]:
            best = (float(p), rms)
    scatter = best[1] / math.log(10.0)
    return {
        "order": round(best[0], 3),
        "scatter_decades": scatter,
        "converges": bool(best[0] > CONVERGING_ORDER and scatter < CONVERGING_SCATTER),
        "ratios": h.tolist(),
    }


def _series_key(p: dict[str, Any]) -> tuple[str, str, str, str, str]:
    """What a point's error series is: (scene, measure, law, integrator, precision)."""
    return (p["scene"], p["measure"], p["law"], integrator_of(p), p["precision"])


def _orders(points, h_refs) -> dict[str, Any]:
    """Each series' fitted order, keyed ``"scene: measure/law/integrator/precision"``."""
    out = {}
    for key in sorted({_series_key(p) for p in points}):
        scene, measure, law, integ, prec = key
        mine = sorted(
            (p for p in points if _series_key(p) == key),
            key=lambda p: p["ratio"],
        )
        fit = fit_order(
            [p["ratio"] for p in mine],
            [p["error"] for p in mine],
            h_refs.get(scene, 0.0),
            prec,
            ORDER_MAX_RATIO_OF.get(scene, ORDER_MAX_RATIO),
        )
        out[f"{scene}: {measure}/{law}/{integ}/{prec}"] = fit
    return out


def error_at(points, key: str, integrator: str = "euler") -> Callable[[float], float | None]:
    """The float64 error of ``key`` ("scene: measure", the largest over the laws, or "scene:
    measure/law") with ``integrator`` at a ratio, log-log interpolated on the ladder (None
    beyond it)."""
    scene, measure = key.split(": ")
    measure, _, only = measure.partition("/")
    points = [p for p in points if integrator_of(p) == integrator]
    curves = []
    for law in sorted({p["law"] for p in points if not only or p["law"] == only}):
        mine = sorted(
            (
                p
                for p in points
                if p["scene"] == scene
                and p["measure"] == measure
                and p["law"] == law
                and p["precision"] == "f64"
                and p["error"] is not None
                and p["error"] > 0
            ),
            key=lambda p: p["ratio"],
        )
        if mine:
            curves.append((np.log([p["ratio"] for p in mine]), np.log([p["error"] for p in mine])))

    def at(ratio: float) -> float | None:
        if not curves:
            return None
        worst = 0.0
        for x, y in curves:
            if np.log(ratio) > x[-1] + 1e-9:
                return None  # beyond the ladder
            worst = max(worst, float(np.exp(np.interp(np.log(ratio), x, y))))
        return worst

    return at


def analyse(parts: dict[str, Any], runs_dir: Path, cfg: dict[str, Any], log=print) -> dict:
    """The JSON summary of the study from the workers' runs."""
    from ...codes import BodyKind

    records = _load(parts, runs_dir)
    timing = _timing(records)
    pillar_scene = dem_scenes.pillar("coulomb")
    dynamic = np.flatnonzero(pillar_scene.kinds == int(BodyKind.DYNAMIC))
    ode, collision_points = _collisions(records, timing, log)
    pillar_points, pairs, pillar_ref = _pillar(records, timing, cfg, dynamic)
    points = collision_points + _pushed(records, timing) + pillar_points
    orders = _orders(points, {"pillar": _ratio_of(records, cfg)})
    summary: dict[str, Any] = {
        "settings": {
            "quick": cfg["quick"],
            "laws": list(cfg["laws"]),
            "integrators": list(cfg.get("integrators", ("euler",))),
            "precisions": list(cfg["precisions"]),
            "pillar_until_s": cfg["pillar_until"],
            "box_until_s": cfg["box_until"],
            "long_until_s": cfg.get("long_until"),
            "collision_end_s": dem_scenes.COLLISION_END,
            "part_m": PART,
            "depart_m": DEPART,
            "stable_dt": {
                "collisions": dem_scenes.collision().stable_dt,
                "pillar, pushed box": pillar_scene.stable_dt,
            },
            "cost": "wall per step of one world alone at dt = 0.2 stable_dt, over dt",
        },
        "collision_reference": ode,
        "pillar_reference": pillar_ref,
        "timing": {"/".join(k): v for k, v in sorted(timing.items())},  # scene/law/integ/prec
        "orders": orders,
        "pillar_parting_at_a_quarter_step": pairs,
        "chaos": _chaos(records, dynamic),
        "points": points,
    }
    stability = parts.get("f64", {}).get("stability")
    if stability:
        if "jam" in stability:  # runs from before the integrators were compared: Euler's
            stability = {"euler": stability}
        # Per integrator: {scene: its limit}, and the dt_safety each would recommend.
        summary["stability"] = stability
        summary["stability_ratio"] = {
            integ: {k: v["largest_surviving_ratio"] for k, v in limits.items()}
            for integ, limits in stability.items()
        }
        summary["recommendation"] = {
            integ: _recommend(points, limits, integ) for integ, limits in stability.items()
        }
        # The same rule on one law's errors alone: a default step may follow the law
        # (timestep.default_safety).
        laws = sorted({p["law"] for p in points})
        summary["recommendation_by_law"] = {
            integ: {law: _recommend(points, limits, integ, law) for law in laws}
            for integ, limits in stability.items()
        }
    _report(summary, log)
    return summary


def _recommend(
    points, limits: dict[str, Any], integrator: str, law: str | None = None
) -> dict[str, Any]:
    """``dem_stability.recommend`` for one integrator, with its errors there and at 0.2: on
    the largest error over the laws, or on ``law``'s alone."""
    only = f"/{law}" if law else ""
    funcs = {m: error_at(points, m + only, integrator) for m in ACCURACY}
    # Only the measures this run has float64 errors of (--quick has fewer).
    accuracy = {m: a for m, a in ACCURACY.items() if funcs[m](0.1) is not None}
    rec = dem_stability.recommend(limits, funcs, accuracy)
    rec["errors_at_recommended"] = (
        {m: f(rec["dt_safety"]) for m, f in funcs.items()} if rec["dt_safety"] else None
    )
    rec["errors_at_0.2"] = {m: f(0.2) for m, f in funcs.items()}
    return rec


def _report(summary: dict[str, Any], log) -> None:
    for key, fit in summary["orders"].items():
        if fit:
            log(
                f"dem accuracy: order {fit['order']:.2f} (scatter {fit['scatter_decades']:.2f} "
                f"decades) {key}"
            )
    for law, c in summary["chaos"].items():
        log(
            f"dem accuracy: {law}: runs that differ in the last bit depart at "
            f"{c['departed_at']} s and part at {c['parted_at']} s (of {c['until']:g} s)"
        )
    for integ, rec in summary.get("recommendation", {}).items():
        by_law = summary.get("recommendation_by_law", {}).get(integ, {})
        log(
            f"dem accuracy [{integ}]: stable ratios {summary['stability_ratio'][integ]}; "
            f"recommended dt_safety {rec['dt_safety']}, margin in the jam {rec['jam_margin']}"
            + "".join(f"; {law} alone {r['dt_safety']}" for law, r in by_law.items())
        )


def load_summary(path: str | Path) -> dict[str, Any]:
    return json.loads(Path(path).read_text())


__all__ = ["analyse", "error_at", "first_time", "fit_order", "separation"]
