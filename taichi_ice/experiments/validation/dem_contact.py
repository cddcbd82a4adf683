"""The friction law through the DEM contact: Figure 3 on a block and floor, and hold/slide.

**1. Figure 3 through a contact.** A 1 m block rests on a kinematic floor (20 m x 1 m)
whose speed follows each of the paper's four Figure 3 profiles
(``single_interface.profiles()``: step, ramp, fast and slow sinusoid); the floor's velocity
is written from Python before every step (``world.data.body_vel``), piecewise constant:
over step ``(t_k, t_k + dt)`` it is ``V(t_k + dt / 2)``. The ratio ``F_t / F_n`` of the
contact force on the block (its probe impulse over the step) is the DEM's mu, compared
at the step's end ``t_k + dt`` with

- the exact solution of the profile (``Profile.exact``: ``exact.step``, ``exact.ramp``,
  ``exact.periodic``), which contains the sampling of V into steps;
- the exact solution of the applied piecewise-constant history (theta relaxes exponentially
  toward ``-B x`` at constant V: a closed form step by step), which leaves only what the
  contact itself adds: the stick spring's share of the displacement and the start-up.

How the interface's slip rate is made the floor speed (to ~1e-12 m/s here):

- *The block does not move.* A contact needs a dynamic body (a fixed or kinematic body never
  touches another), so the block is dynamic, with an ice density of 1e24 kg/m^3 in its scene
  (``[ice] density`` is per scene, and the floor is kinematic, so its mass plays no part).
  The contact force (~10 N) then moves the block by ~1e-20 m over the longest run, at
  ~1e-22 m/s (recorded as ``block_drift_speed``). No engine field is overwritten but the
  floor's velocity.
- *A stiff stick spring and a shallow overlap.* The block starts 1e-7 m into the floor (an
  overlap area of 1e-7 m^2, below the start-up check's 1e-6 of the block's area), so
  ``F_n = k_e A = 9.75 N`` and no normal motion; the stick spring ratio is 1e4
  (``[ice] tangential_stiffness``; ``k_t = ratio k_e L``). The sliding rate is the floor
  speed less the rate at which the spring's stretch ``mu F_n / k_t`` (7e-12 m) changes:
  ``V - V_slide = (F_n / k_t) dmu/dt``, ~1e-12 m/s, and 2e-10 m/s in the step that takes up
  a jump of mu. The first step matters most: the new contact's spring takes up
  ``mu F_n / k_t`` of the floor's ``V dt``, the interface starts in equilibrium at a rate
  that much lower and carries ``B ln(V / V_0)`` as a transient over t_c: ~1e-5 of V, 1e-6
  in mu, here. With the default ratio (0.5) the spring takes up 1.5e-7 m, a third of the
  first 5 ms step at 0.1 mm/s, and the step profile is 0.037 off at the start and still
  0.027 after 1 s (``default_stick_spring`` in the JSON); nor does that shrink with dt
  (``start_up_by_dt``): the first step that slides does so at a rate set by how far into
  it the spring reached its cap, and the new interface starts in equilibrium there.

Steps used: 5 ms for the step and the ramp (their knots fall on step boundaries), 1 ms for
the fast sinusoid, 20 ms for the slow one (``DT``; ``--quick`` takes ``QUICK_DT`` and a
shorter fast sinusoid). The sinusoids' gain and phase of mu against ln V are measured as in
``single_interface.gain_phase`` for the DEM, the exact solution and the applied history;
sampling V at mid-step and reading mu at the step's end delays the direct term by half a
step, ``H_sampled = A e^{-i w dt/2} - B / (1 + i w t_c)``, which the DEM follows.

**2. Hold and slide.** A 1 m block (276 kg) is pressed onto a fixed floor by an external
force F equal to its weight and slides from 5 cm/s until it stops; after ``HOLD_AT`` a
horizontal external force ramps over ``RAMP`` (a load applied at once would make the stick
spring and block overshoot to nearly twice it) to 0.8 or 1.2 mu0 F
(``model.body_force_ext``, written from Python), under each rule below v_star
(``paper``, ``healing``, ``frozen``): six worlds of one batch. Recorded per world: the
contact's theta when the load came (``-B ln(V / v_star)`` or so after sliding at V, healing
or frozen; none under the paper's rule); the contact's slip under the load (the base's
displacement less the stick spring's stretch): it *held* if that stayed below the creep
the rule allows below v_star, ``v_star x (RAMP + OBSERVE)``; how far the base moved,
against ``mu0 F / k_t``; and where it slides, the mean acceleration against
``(f - mu_contact) F / m``, mu_contact the contact's F_t / F_n over the same window, and
mu_contact against the law integrated along the block's slip from the contact's theta.

Writes ``dem_contact.json`` and ``fig3_dem_contact.png``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from ...physics.friction import RateState
from .hold_slide import hold_slide
from .single_interface import Profile, gain_phase, profiles, speed_axis

# ---- 1. The block on a moving floor -----------------------------------------------------------
FLOOR, BLOCK = 0, 1  # body indices of the floor scene
DEPTH = 1e-7  # m: overlap of the block into the floor
RATIO = 1e4  # [ice] tangential_stiffness: k_t = RATIO k_e L
DENSITY = 1e24  # kg/m^3: a block that the contact force cannot move
FLOOR_WIDTH = 20.0  # m
DT = {"step": 5e-3, "ramp": 5e-3, "fast_sinusoid": 1e-3, "slow_sinusoid": 2e-2}
QUICK_DT = {"step": 2e-2, "ramp": 2e-2, "fast_sinusoid": 4e-3, "slow_sinusoid": 1e-1}
# --quick: the fast sinusoid over 20 periods, measured on the last 5.
QUICK_FAST = {"duration": 20.0, "settle": 15.0}
# Steps of the start-up study with the default stick spring (s).
START_UP_DTS = (2e-2, 5e-3, 1e-3, 2e-4)
# The errors are also reported from this time on: the start-up is behind (s).
AFTER = 1.0


# ------------------------------------------------------------------------------------------------
# 1. Figure 3 through the contact
# ------------------------------------------------------------------------------------------------


def floor_scene(
    law: RateState,
    dt: float,
    duration: float,
    speed: float,
    *,
    depth: float = DEPTH,
    ratio: float = RATIO,
    density: float = DENSITY,
):
    """A 1 m block (probe) sunk ``depth`` into a kinematic floor moving at ``speed``."""
    from ...scene.parse import scene_from_dict

    return scene_from_dict(
        {
            "simulation": {
                "duration": duration,
                "dt": dt,
                "output_interval": duration,
                "series_interval": dt,
            },
            "ice": {"density": density, "tangential_stiffness": ratio},
            "friction": law.to_dict(),
            "body": [
                {
                    "name": "floor",
                    "kind": "kinematic",
                    "shape": "rectangle",
                    "width": FLOOR_WIDTH,
                    "length": 1.0,
                    "position": [0.0, -0.5],  # top face at y = 0
                    "velocity": [speed, 0.0],
                },
                {
                    "name": "block",
                    "shape": "rectangle",
                    "width": 1.0,
                    "length": 1.0,
                    "position": [0.0, 0.5 - depth],
                    "probe": True,
                },
            ],
        },
        source="dem_contact",
    )


def step_speeds(profile: Profile, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Step end times ``t_k + dt`` (s) and the floor speed over each step, ``V(t_k + dt/2)``."""
    n = round(profile.duration / dt)
    t_end = dt * np.arange(1, n + 1)
    return t_end, profile.rate(t_end - 0.5 * dt)


def drive_floor(
    law: RateState,
    speeds: np.ndarray,
    dt: float,
    *,
    depth: float = DEPTH,
    ratio: float = RATIO,
    density: float = DENSITY,
) -> dict[str, np.ndarray]:
    """Run the floor scene with the floor at ``speeds[k]`` over step k.

    Returns ``mu`` (F_t / F_n on the block over each step), ``f_n`` (N), ``slide_rate``
    (m/s: the floor speed less the stick spring's stretching rate, the slip the contact
    takes), ``block_drift_speed`` (m/s, the block's speed at the end) and ``wall_time``.
    Taichi must be running (``backend.init``), in float64.
    """
    from ...engine.world import World

    speeds = np.asarray(speeds, dtype=np.float64)
    n = speeds.size
    scene = floor_scene(
        law, dt, n * dt, float(speeds[0]), depth=depth, ratio=ratio, density=density
    )
    world = World([scene], dt=dt)
    vel, impulse, stretch = world.data.body_vel, world.data.probe_impulse, world.data.contact_xi
    cum = np.empty((n + 1, 2))
    xi = np.empty(n + 1)
    cum[0] = 0.0
    xi[0] = 0.0
    v_list = speeds.tolist()
    start = time.perf_counter()
    for k in range(n):
        if k == 0 or v_list[k] != v_list[k - 1]:
            vel[FLOOR] = (v_list[k], 0.0)
        world.step()
        # The probe's impulse accumulates (never reset): its increments are each step's.
        total = impulse[0]
        cum[k + 1, 0], cum[k + 1, 1] = total[0], total[1]
        xi[k + 1] = stretch[BLOCK, 0]
    wall = time.perf_counter() - start
    world.check()
    step_impulse = np.diff(cum, axis=0)
    return {
        "mu": step_impulse[:, 0] / step_impulse[:, 1],
        "f_n": step_impulse[:, 1] / dt,
        "slide_rate": speeds - np.diff(xi) / dt,
        "block_drift_speed": float(np.linalg.norm(world.velocities()[BLOCK])),
        "wall_time": wall,
    }


def applied_exact(speeds: np.ndarray, dt: float, law: RateState) -> np.ndarray:
    """Exact mu at the end of each step of a piecewise-constant slip rate (all >= v_star),
    starting in equilibrium at ``speeds[0]``: at constant x, theta relaxes toward ``-B x`` as
    ``exp(-dt / t_c)``, and mu = mu0 + theta + A x."""
    x = np.log(np.maximum(speeds, law.v_star) / law.v_star)
    decay = math.exp(-dt / law.t_c)
    theta = np.empty(x.size)
    th = -law.B * float(x[0])
    for k, xk in enumerate(x.tolist()):
        th = -law.B * xk + (th + law.B * xk) * decay
        theta[k] = th
    return np.maximum(law.mu0 + theta + law.A * x, 0.0)


def _errors(t: np.ndarray, mu: np.ndarray, ref: np.ndarray) -> dict[str, float]:
    err = np.abs(mu - ref)
    late = t > AFTER
    return {
        "max": float(err.max()),
        "max_after_1s": float(err[late].max()),
        "rms_after_1s": float(np.sqrt(np.mean(err[late] ** 2))),
        "at": float(t[int(np.argmax(err))]),
    }


def run_profile(profile: Profile, dt: float, law: RateState, **scene_kw: Any) -> dict[str, Any]:
    """One profile through the DEM contact: errors, sliding rate, and for a sinusoid gain and
    phase. Returns ``{"entry": JSON-ready dict, "curves": (t, v, mu_dem, mu_exact)}``."""
    t, v = step_speeds(profile, dt)
    run = drive_floor(law, v, dt, **scene_kw)
    mu = run["mu"]
    mu_exact = profile.exact(t, law)
    mu_applied = applied_exact(v, dt, law)
    slide_error = np.abs(run["slide_rate"] - v)
    entry: dict[str, Any] = {
        "dt": dt,
        "duration": profile.duration,
        "steps": int(t.size),
        "wall_time_s": run["wall_time"],
        "floor_speed": "V(t_k + dt/2) over step k; mu compared at t_k + dt",
        "error_vs_exact": _errors(t, mu, mu_exact),
        "error_vs_applied_history": _errors(t, mu, mu_applied),
        "error_of_sampling": _errors(t, mu_applied, mu_exact),
        "max_slide_rate_error": float(slide_error.max()),
        "max_slide_rate_error_after_1s": float(slide_error[t > AFTER].max()),
        "normal_force": [float(run["f_n"].min()), float(run["f_n"].max())],
        "block_drift_speed": run["block_drift_speed"],
        "mu_range": [float(mu.min()), float(mu.max())],
    }
    if profile.periodic:
        x_v = profile.rate(t)
        dem = gain_phase(profile, t, x_v, mu, law)
        ex = gain_phase(profile, t, x_v, mu_exact, law)
        app = gain_phase(profile, t, x_v, mu_applied, law)
        entry["period"] = profile.period
        entry["omega_t_c"] = dem["omega_t_c"]
        # Gain and phase of mu against ln V(t) at the step ends: the DEM, the exact solution
        # of the profile and that of the applied (sampled) history. Sampling V at the step's
        # middle and reading mu at its end delays the direct term A x by half a step (theta,
        # driven by the midpoint values, is second order): H_sampled = A e^{-i w dt/2} -
        # B / (1 + i w t_c). The contact itself adds nothing measurable.
        h_sampled = law.A * np.exp(-0.5j * profile.omega * dt) - law.B / (
            1.0 + 1j * profile.omega * law.t_c
        )
        entry["gain"] = {
            "dem": dem["gain_measured"],
            "exact": ex["gain_measured"],
            "applied_history": app["gain_measured"],
            "theory": dem["gain_theory"],
            "theory_sampled": float(abs(h_sampled)),
            "dem_rel_error_vs_exact": abs(dem["gain_measured"] - ex["gain_measured"])
            / ex["gain_measured"],
        }
        entry["phase_deg"] = {
            "dem": dem["phase_measured_deg"],
            "exact": ex["phase_measured_deg"],
            "applied_history": app["phase_measured_deg"],
            "theory": dem["phase_theory_deg"],
            "dem_minus_exact": _wrap(dem["phase_measured_deg"] - ex["phase_measured_deg"]),
            "dem_minus_applied_history": _wrap(
                dem["phase_measured_deg"] - app["phase_measured_deg"]
            ),
            "theory_sampled": math.degrees(math.atan2(h_sampled.imag, h_sampled.real)),
        }
    return {"entry": entry, "curves": (t, v, mu, mu_exact)}


def _wrap(degrees: float) -> float:
    """An angle difference wrapped to [-180, 180) degrees."""
    return (degrees + 180.0) % 360.0 - 180.0


def dem_profiles(quick: bool = False) -> dict[str, tuple[Profile, float]]:
    """The four Figure 3 profiles and the DEM step of each."""
    steps = QUICK_DT if quick else DT
    out = {}
    for name, profile in profiles().items():
        if quick and name == "fast_sinusoid":
            profile = dataclasses.replace(profile, **QUICK_FAST)
        out[name] = (profile, steps[name])
    return out


# ------------------------------------------------------------------------------------------------
# Study
# ------------------------------------------------------------------------------------------------


def _start_up_by_dt(law: RateState, ratio: float) -> list[dict[str, float]]:
    """The first 2 s of the step profile (0.1 mm/s) at several steps: the start-up's error."""
    profile = dataclasses.replace(profiles()["step"], duration=2.0)
    out = []
    for dt in START_UP_DTS:
        t, _, mu, mu_exact = run_profile(profile, dt, law, ratio=ratio)["curves"]
        err = np.abs(mu - mu_exact)
        out.append(
            {"dt": dt, "max": float(err.max()), "at_1s": float(err[np.searchsorted(t, 1.0)])}
        )
    return out


def _runtime() -> tuple[str, str] | None:
    """Start Taichi on the CPU in float64 unless it runs; None if it runs in float32."""
    from ... import backend

    current = backend.current()
    if current is None:
        backend.init("cpu", "f64")
        return ("cpu", "f64")
    return current if current[1] == "f64" else None


def run(
    out_dir: str | Path, *, quick: bool = False, law: RateState | None = None
) -> dict[str, Any]:
    """Both studies; writes ``dem_contact.json`` and ``fig3_dem_contact.png`` into ``out_dir``.

    Args:
        out_dir: output folder (created if missing).
        quick: coarser steps (``QUICK_DT``) and a shorter fast sinusoid.
        law: the rate-and-state law of Figure 3 (paper rule); default the paper's.

    Returns:
        The JSON summary as a dict (``{"skipped": reason}`` in a float32 runtime: a 1e-7 m
        overlap needs float64).
    """
    law = law or RateState()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "dem_contact.json"
    runtime = _runtime()
    if runtime is None:
        summary: dict[str, Any] = {"skipped": "Taichi runs in float32; this study needs float64"}
        path.write_text(json.dumps(summary, indent=2) + "\n")
        print("dem contact: skipped (needs float64)")
        return summary
    summary = {
        "law": law.to_dict(),
        "arch": runtime[0],
        "precision": runtime[1],
        "setup": {
            "block": "1 m x 1 m, dynamic, density 1e24 kg/m^3, probe",
            "floor": f"{FLOOR_WIDTH:g} m x 1 m, kinematic, speed written before every step",
            "overlap_depth_m": DEPTH,
            "tangential_stiffness_ratio": RATIO,
            "errors_after_s": AFTER,
        },
        "profiles": {},
    }
    curves = {}
    shown = {}
    for name, (profile, dt) in dem_profiles(quick).items():
        res = run_profile(profile, dt, law)
        entry = res["entry"]
        summary["profiles"][name] = entry
        curves[name] = res["curves"]
        shown[name] = profile
        err = entry["error_vs_exact"]
        line = (
            f"dem contact: {name:14s} {entry['steps']:6d} steps of {dt:g} s, max |mu - exact| "
            f"{err['max']:.2e} ({err['max_after_1s']:.2e} after 1 s), vs applied history "
            f"{entry['error_vs_applied_history']['max']:.2e}"
        )
        if profile.periodic:
            gain, phase = entry["gain"], entry["phase_deg"]
            line += (
                f"; gain {gain['dem']:.5f} (exact {gain['exact']:.5f}), "
                f"phase {phase['dem']:.3f} deg (exact {phase['exact']:.3f})"
            )
        print(f"{line} [{entry['wall_time_s']:.1f} s]")
    # The step again with the default stick spring: what the start-up costs there.
    from ...scene.model import IceProperties

    profile, dt = dem_profiles(quick)["step"]
    default_ratio = IceProperties().tangential_stiffness
    entry = run_profile(profile, dt, law, ratio=default_ratio)["entry"]
    summary["default_stick_spring"] = {
        "profile": "step",
        "tangential_stiffness_ratio": default_ratio,
        "dt": dt,
        **{k: entry[k] for k in ("error_vs_exact", "error_vs_applied_history")},
        "max_slide_rate_error": entry["max_slide_rate_error"],
        "max_slide_rate_error_after_1s": entry["max_slide_rate_error_after_1s"],
    }
    if not quick:
        # How a new interface starts depends on the step with this spring: the first step
        # that slides does so at a rate set by how far into it the spring reached its cap.
        summary["default_stick_spring"]["start_up_by_dt"] = _start_up_by_dt(law, default_ratio)
    print(
        f"dem contact: step with the default stick spring (ratio {default_ratio:g}): max |mu - "
        f"exact| {entry['error_vs_exact']['max']:.2e} "
        f"({entry['error_vs_exact']['max_after_1s']:.2e} after 1 s)"
    )
    summary["hold_slide"] = hold_slide(law=law)
    for rule, per_load in summary["hold_slide"]["cases"].items():
        for load, e in per_load.items():
            what = "holds" if e["held"] else "slides"
            extra = ""
            if "slide" in e:
                s = e["slide"]
                extra = (
                    f", a = {s['acceleration']:.4f} m/s^2 vs (f - mu) F / m = "
                    f"{s['closed_form_acceleration']:.4f} (mu {s['mu_contact']:.4f})"
                )
            theta = e["theta_at_load"]
            theta = "none" if theta is None else f"{theta:.3f}"
            print(
                f"dem contact: {rule:8s} {load} mu0 F {what}: contact slipped "
                f"{e['max_contact_slip_m']:.3g} m, theta at load {theta}{extra}"
            )
    figure = out_dir / "fig3_dem_contact.png"
    plot(curves, shown, summary["profiles"], figure)
    summary["figure"] = figure.name
    path.write_text(json.dumps(summary, indent=2) + "\n")
    print(f"dem contact: wrote {figure} and {path}")
    return summary


def plot(
    curves: dict[str, tuple[np.ndarray, ...]],
    profile_set: dict[str, Profile],
    entries: dict[str, dict],
    path: Path,
) -> None:
    """Four panels in the style of ``single_interface.plot_figure3``: the DEM's F_t / F_n
    solid, the exact solution as circles, the floor speed dashed (right axis)."""
    from ...run.plots import subplots

    fig, axes = subplots(2, 2, figsize=(10, 6.4), layout="constrained")
    for ax, (name, (t, v, mu, mu_exact)) in zip(axes.flat, curves.items()):
        profile = profile_set[name]
        shown = t <= profile.shown + 1e-9
        every = max(1, int(shown.sum()) // 40)
        ax.plot(t[shown], mu[shown], "-", color="C0", lw=1.6, label="mu = F_t / F_n (DEM)")
        ax.plot(
            t[shown][::every],
            mu_exact[shown][::every],
            "o",
            ms=3.5,
            mfc="none",
            color="k",
            label="mu exact",
        )
        err = entries[name]["error_vs_exact"]["max_after_1s"]
        ax.set_title(
            f"{profile.title}: dt {entries[name]['dt']:g} s, |mu - exact| <= {err:.1e} (t > 1 s)",
            fontsize=10,
        )
        ax.set_xlabel("time (s)")
        ax.set_ylabel("friction coefficient mu")
        ax.set_xlim(0.0, profile.shown)
        speed_axis(ax, t[shown], v[shown], "floor speed", legend=name == "step")
    fig.suptitle(
        "Friction through a DEM contact: a block on a floor moving at V(t) "
        "(rate and state, Lishman et al. 2013)"
    )
    fig.savefig(path, dpi=90)


__all__ = [
    "applied_exact",
    "dem_profiles",
    "drive_floor",
    "floor_scene",
    "hold_slide",
    "run",
    "run_profile",
    "step_speeds",
]
