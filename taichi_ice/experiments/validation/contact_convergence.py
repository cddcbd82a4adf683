"""Friction at a DEM contact that converges as the step shrinks: ``taichi-ice validate --dem``.

Four checks of the rate-and-state contact (``slip``, ``contact``), each a scene small enough
to run at many steps, and the sensitivity of the paper's scene to what the contact model
leaves open:

1. **The driven slider.** A block (4 m x 0.25 m, 276 kg) pressed onto a fixed floor by ``PRESS`` and
   pulled through a spring ``DRIVER_STIFFNESS`` whose end moves back and forth at
   ``0.1 sin(2 pi t / 4)`` m/s for ``SLIDER_UNTIL`` (the spring force is written from Python
   before every step, from the block's position and the driver's). Every reversal stops the
   block, so it sticks and starts again: the frictional work and the number of slip starts
   (a contact that gains a sliding interface) against dt over five halvings, the order of
   the work's convergence fitted against the finest run.
2. **Hold and slide.** The same block slides at ``PULL_SPEEDS`` under a constant pull of
   ``PULL_LOADS`` x mu0 F_n against its motion: it stops, then must hold the pull if that is
   below mu0 F_n (the paper's rule: stuck, mu = mu0), whatever speed it slid at, and slide
   off above it. Held: the block moved less than ``HOLD_DISTANCE`` after it stopped.
3. **Steady sliding.** The block rests against a fixed stop on a kinematic floor that speeds
   up to ``STEADY_SPEEDS`` under ``STEADY_PRESSES``: after ``STEADY_UNTIL`` (5 t_c) the mean
   ``|F_t| / F_n`` over the last second against ``mu_ss(V)``.
4. **The pillar before runs part.** ``pillar`` under every law (Coulomb 0.1, 0.5, 0.9,
   rate-and-state, steady-state, memory-only) at ``PILLAR_RATIOS`` of the stable step: the
   frictional energy at ``PILLAR_TIMES`` against the run at the smallest.
5. **Sensitivity** (``sensitivity``): the tangential stiffness ratio (``RATIOS_T``) on the
   slider and on ``LAYOUTS`` pillar layouts (20 s): how much each moves the peak pillar
   force and the frictional energy.

``run`` writes ``contact_convergence.json`` and ``contact_convergence.png``; ``--quick`` runs
fewer steps and layouts. Run alone:
``python -m taichi_ice.commands.validate contact_convergence --out DIR``.

Checks 1-3, on one block, are ``contact_block``'s; the pillar, the sensitivity, the report
and the command are here.
"""

import json
import time
from pathlib import Path
from typing import Any, Union

import numpy as np

from ...physics.friction import Coulomb, RateState, SteadyState
from .contact_block import (
    RATE_STATE_LAWS,
    SLIDER_HALVINGS,
    SLIDER_UNTIL,
    fit_order,
    make_world,
    pull,
    slider,
    slider_convergence,
    slider_steps,
    steady,
)

# ---- 4. The pillar ----------------------------------------------------------------------------
PILLAR_RATIOS = (0.025, 0.05, 0.1, 0.2, 0.4)
PILLAR_TIMES = (2.5, 4.0, 5.5)  # s: before runs at different steps part (~6 s)
# ---- 5. Sensitivity ---------------------------------------------------------------------------
RATIOS_T = (0.25, 0.5, 1.0)  # [ice] tangential_stiffness
STEADY_T_C = (1.0, 0.3, 0.1, 0.03)  # s: the steady-state law's t_c
LAYOUTS = 16  # pillar layouts: the paper's and 15 reseeded
SENSITIVITY_UNTIL = 20.0  # s: the paper's run

# The pillar's laws: the checks' rate-and-state laws and the paper's constant ones.
PILLAR_LAWS = {
    "coulomb 0.1": Coulomb(0.1),
    "coulomb 0.5": Coulomb(0.5),
    "coulomb 0.9": Coulomb(0.9),
    **RATE_STATE_LAWS,
}


# ------------------------------------------------------------------------------------------------
# 4. The pillar before runs part
# ------------------------------------------------------------------------------------------------


def pillar(laws=None, ratios=PILLAR_RATIOS, times=PILLAR_TIMES, *, default: float = 0.2) -> dict:
    """Every law's frictional energy in the pillar scene at ``times``, per ratio (a batch of
    the laws per ratio), and the error of each against the smallest ratio."""
    from ...codes import EnergyTerm
    from ...scene.parse import load_scenario

    laws = laws or PILLAR_LAWS
    base = load_scenario("pillar")
    scenes = [base.with_friction(law) for law in laws.values()]
    energy = {}
    for ratio in ratios:
        world = make_world(scenes, ratio * base.stable_dt)
        rows = []
        for t in times:
            world.advance(round((t - world.time) / world.dt))
            rows.append(world.energies()[:, EnergyTerm.FRICTION].copy())
        world.check()
        energy[ratio] = np.asarray(rows)  # (times, laws)
        del world  # gone before the next is built, whose kernels are its (engines.Engines)
    ref = energy[min(ratios)]
    out: dict[str, Any] = {"ratios": list(ratios), "times_s": list(times), "laws": {}}
    for k, name in enumerate(laws):
        errors = {r: np.abs(energy[r][:, k] / ref[:, k] - 1.0) for r in ratios}
        hs = [r for r in ratios if r != min(ratios)]
        out["laws"][name] = {
            "friction_J": {str(r): energy[r][:, k].tolist() for r in ratios},
            "rel_error": {str(r): errors[r].tolist() for r in ratios},
            "max_rel_error_at_default": float(np.max(errors[default]))
            if default in errors
            else None,
            "order": fit_order(hs, [float(np.max(errors[r])) for r in hs]),
        }
    return out


# ------------------------------------------------------------------------------------------------
# 5. Sensitivity
# ------------------------------------------------------------------------------------------------


def pillar_layouts(law, layouts: int, *, until=SENSITIVITY_UNTIL, tangential_stiffness=None):
    """Peak pillar force (N, the 10 ms mean as sampled) and frictional energy (J) at
    ``until`` of ``layouts`` pillar layouts (the paper's and reseeded ones), one batch."""
    import dataclasses

    from ...codes import EnergyTerm
    from ...scene.parse import load_scenario, reseeded

    base = load_scenario("pillar").with_friction(law)
    scenes = [base] + [reseeded(base, s) for s in range(1, layouts)]
    if tangential_stiffness is not None:
        ice = dataclasses.replace(base.ice, tangential_stiffness=tangential_stiffness)
        scenes = [dataclasses.replace(s, ice=ice) for s in scenes]
    world = make_world(scenes)
    every = round(0.01 / world.dt)
    pillar_probe = [s.start for s in world.probe_slices()]
    peak = np.zeros(len(scenes))
    for _ in range(round(until / (every * world.dt))):
        world.advance(every)
        f = world.take_probe_impulses()[pillar_probe] / (every * world.dt)
        peak = np.maximum(peak, np.hypot(f[:, 0], f[:, 1]))
    world.check()
    return {
        "peak_force_N": peak.tolist(),
        "friction_J": world.energies()[:, EnergyTerm.FRICTION].tolist(),
    }


def _against(runs: dict, reference) -> dict:
    """Each run with the geometric mean, over layouts, of its peak force and frictional
    energy over the reference run's."""
    ref = runs[reference]
    return {
        str(key): {
            **run_,
            "peak_ratio_geomean": _geomean(run_["peak_force_N"], ref["peak_force_N"]),
            "friction_ratio_geomean": _geomean(run_["friction_J"], ref["friction_J"]),
        }
        for key, run_ in runs.items()
    }


def sensitivity(layouts: int = LAYOUTS, until=SENSITIVITY_UNTIL, halvings: int = 0) -> dict:
    """What the contact model leaves open, on the slider (its work and slip starts) and on
    ``layouts`` pillar layouts (the geometric mean of the peak force and frictional energy
    over those of the default):

    - the tangential stiffness ratio (``RATIOS_T``), under rate-and-state and Coulomb 0.5;
    - the steady-state law's ``t_c`` (``STEADY_T_C``): how short its memory must be before
      the pillar's outcome stops depending on it.
    """
    out: dict[str, Any] = {"tangential_stiffness": {}, "steady_state_t_c": {}}
    dt = slider_steps(halvings)[-1]
    rs = {"rate-state": RateState()}
    out["tangential_stiffness"]["slider"] = {
        str(t): slider(rs, dt, tangential_stiffness=t)["rate-state"] for t in RATIOS_T
    }
    for name in ("rate-state", "coulomb 0.5"):
        law = PILLAR_LAWS[name]
        runs = {
            t: pillar_layouts(law, layouts, until=until, tangential_stiffness=t) for t in RATIOS_T
        }
        out["tangential_stiffness"][name] = _against(runs, 0.5)
    laws = {f"t_c {t_c:g}": SteadyState(t_c=t_c) for t_c in STEADY_T_C}
    out["steady_state_t_c"]["slider"] = slider(laws, dt)
    runs = {t_c: pillar_layouts(SteadyState(t_c=t_c), layouts, until=until) for t_c in STEADY_T_C}
    out["steady_state_t_c"]["pillar"] = _against(runs, SteadyState().t_c)
    return out


def _geomean(values, reference) -> float:
    a, b = np.asarray(values, dtype=float), np.asarray(reference, dtype=float)
    keep = (a > 0) & (b > 0)
    return float(np.exp(np.mean(np.log(a[keep] / b[keep])))) if np.any(keep) else float("nan")


# ------------------------------------------------------------------------------------------------
# The study
# ------------------------------------------------------------------------------------------------


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    return x


def run(out_dir: Union[str, Path], quick: bool = False, log=print) -> dict:
    """Every check, into ``out_dir/contact_convergence.json`` and ``.png`` (``quick``: fewer
    halvings, shorter runs, two pillar layouts)."""
    from ... import backend

    if backend.current() is None:
        backend.init("cpu", "f64")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    summary: dict[str, Any] = {}
    halvings, until = (2, 4.0) if quick else (SLIDER_HALVINGS, SLIDER_UNTIL)
    summary["slider"] = slider_convergence(RATE_STATE_LAWS, halvings, until=until)
    for name, s in summary["slider"].items():
        log(
            f"slider, {name}: work "
            + ", ".join(f"{r['friction_work_J']:.2f}" for r in s["runs"])
            + f" J; order {s['order']:.2f}; slip starts {s['starts']}"
        )
    summary["pull"] = pull(RATE_STATE_LAWS)
    for name, cases in summary["pull"]["laws"].items():
        held = ", ".join(
            f"{c['speed_m_s']:g} m/s {c['load']:g}: {'held' if c['held'] else 'slid'}"
            for c in cases
        )
        log(f"hold and slide, {name}: {held}")
    summary["steady"] = steady(RATE_STATE_LAWS)
    for name, cases in summary["steady"]["laws"].items():
        errs = ", ".join(
            f"{c['speed_m_s']:g} m/s {c['press_N'] / 1e3:g} kN {c['rel_error'] * 100:+.2f} %"
            for c in cases
        )
        log(f"steady sliding, {name}: {errs}")
    summary["pillar"] = pillar(ratios=(0.05, 0.2) if quick else PILLAR_RATIOS)
    for name, e in summary["pillar"]["laws"].items():
        log(
            f"pillar, {name}: largest error at the default step {e['max_rel_error_at_default']:.2%}"
        )
    summary["sensitivity"] = sensitivity(
        layouts=2 if quick else LAYOUTS,
        until=6.0 if quick else SENSITIVITY_UNTIL,
        halvings=1 if quick else 2,
    )
    summary["wall_s"] = time.perf_counter() - start
    path = out_dir / "contact_convergence.json"
    path.write_text(json.dumps(_jsonable(summary), indent=1))
    plot(summary, out_dir / "contact_convergence.png")
    log(f"contact convergence: {summary['wall_s']:.0f} s; {path}")
    return summary


def plot(summary: dict, path: Path) -> None:
    """Four panels: the slider's work error against dt, the pillar's frictional-energy error
    against dt, steady sliding against mu_ss, and the sensitivity to the tangential stiffness
    and to the steady-state law's t_c."""
    from ...run.plots import subplots

    fig, axes = subplots(2, 2, figsize=(12, 9))
    ax = axes[0, 0]
    for name, s in summary["slider"].items():
        runs = [r for r in s["runs"] if r["work_error_rel"] > 0]
        ax.loglog(
            [r["dt"] for r in runs],
            [r["work_error_rel"] for r in runs],
            "o-",
            label=f"{name}: order {s['order']:.2f}, slip starts {s['starts']}",
        )
    ax.set(
        xlabel="dt (s)",
        ylabel="|W_f / W_f(finest) - 1|",
        title="driven slider: frictional work against dt",
    )
    ax.legend(fontsize=8)
    ax = axes[0, 1]
    p = summary["pillar"]
    for name, e in p["laws"].items():
        rs = [r for r in p["ratios"] if r != min(p["ratios"])]
        ax.loglog(rs, [max(e["rel_error"][str(r)]) for r in rs], "o-", label=name)
    ax.axhline(0.03, color="grey", ls=":", label="3 %")
    ax.axvline(0.2, color="0.8", ls="--")
    ax.set(
        xlabel="dt / stable_dt",
        ylabel="largest |E_f / E_f(0.025) - 1| at 2.5, 4, 5.5 s",
        title="pillar before runs part: frictional energy",
    )
    ax.legend(fontsize=8)
    ax = axes[1, 0]
    for name, cases in summary["steady"]["laws"].items():
        for press in sorted({c["press_N"] for c in cases}):
            cs = [c for c in cases if c["press_N"] == press]
            ax.semilogx(
                [c["speed_m_s"] for c in cs],
                [100 * c["rel_error"] for c in cs],
                "o-",
                label=f"{name}, {press / 1e3:g} kN",
            )
    ax.axhspan(-2, 2, color="0.9", zorder=0)
    ax.set(
        xlabel="floor speed (m/s)",
        ylabel="mean |F_t| / F_n over mu_ss(V) - 1 (%)",
        title="steady sliding on a moving floor (t = 30 s)",
    )
    ax.legend(fontsize=7)
    ax = axes[1, 1]
    sens = summary["sensitivity"]
    for name in ("rate-state", "coulomb 0.5"):
        runs = sens["tangential_stiffness"][name]
        keys = sorted(runs, key=float)
        for what, marker in (("peak_ratio_geomean", "o-"), ("friction_ratio_geomean", "s--")):
            ax.plot(
                [float(k) for k in keys],
                [runs[k][what] for k in keys],
                marker,
                label=f"{name}, {what.split('_')[0]}",
            )
    ax.axhline(1.0, color="grey", lw=0.8)
    ax.set(
        xscale="log",
        xlabel="tangential stiffness ratio k_t / (k_e L)",
        ylabel="geometric mean over layouts, / default",
        title="pillar layouts: peak force and frictional energy",
    )
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
