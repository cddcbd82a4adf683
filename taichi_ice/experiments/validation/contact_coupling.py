"""Why the ``coupled`` integrator: a contact's normal and tangent solved apart or together.

The analytic step (``physics.contact_step``) solves each contact's normal spring-dashpot and
its stuck tangential one as two damped oscillators, each at the pair's inverse mass along its
own direction, and takes what moves one direction through the other (the bodies' turning:
the cross term ``K_nt`` of the pair's inverse mass) from the last step's forces. The
``coupled`` integrator (``physics.contact_coupled``) solves the two as one linear system over
the step. This study runs both in the NumPy twin of the step (``engine.reference``, float64):

- the two collisions of ``dem_accuracy`` and the offset one without friction, each law,
  against the ODE (``collision_ode``), from 0.0125 to 1.6 stable_dt: restitution, contact
  duration and the square's spin after. Without friction the two are one (no tangential
  spring); with it the offset collision's restitution is 2 % off apart at 0.8 stable_dt
  and 0.2 % together;
- a loaded ``stack`` of three turning blocks between a wall and a pusher (two contacts a
  block), each solve against itself at 0.05 stable_dt, to 2.0: together is no closer.

Both hold each contact's geometry (normal, point, lever arms) at the step's start while the
bodies turn: a first-order error of the spin and the duration even without friction. The
third solve, ``midstep`` (the coupled one linearised about the configuration predicted for
mid-step: the ``midstep`` integrator), is
second order on the offset collision without friction (order 2.1-2.4 in restitution,
duration and spin) and closer in the stack's velocities.

``python -m taichi_ice.commands.validate contact_coupling --out DIR [--quick]`` writes
``contact_coupling.json``, ``contact_coupling.md`` and ``contact_coupling.png``
(``docs/accuracy.md``).
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from ...physics.friction import Coulomb
from . import collision_ode, dem_scenes

__all__ = [
    "CASES",
    "RATIOS",
    "SOLVERS",
    "measure",
    "run",
    "run_stack",
    "simulate",
    "stack",
]

RATIOS = (0.0125, 0.05, 0.2, 0.4, 0.8, 1.6)  # dt / stable_dt
QUICK_RATIOS = (0.2, 0.8)
# (name, lateral offset of the block (m), law): the offset collision without friction shows
# that the decoupled solve's error is friction's (the tangent's spring and its cross term).
CASES = (
    ("face-on", 0.0, "coulomb"),
    ("offset", dem_scenes.OFFSET, "coulomb"),
    ("offset", dem_scenes.OFFSET, "rate-state"),
    ("offset", dem_scenes.OFFSET, "frictionless"),
)
# The analytic integrator's solve (``contact_step.pair_impulses``, apart), the coupled
# one's (``contact_coupled.coupled_impulses``, together), and the midstep one's (the coupled
# solve linearised about the configuration predicted for mid-step).
SOLVERS = ("decoupled", "coupled", "midstep")
MEASURES = ("restitution", "duration", "spin")
# The loaded stack: three squares between a wall and a pusher (``stack``), 0.25 s.
STACK_BLOCKS = 3
STACK_SPEED = 0.2  # m/s, the pusher's
STACK_DURATION = 0.25  # s: the pusher 5 cm in, the blocks squeezed and turning
STACK_REFERENCE = 0.05  # dt / stable_dt of each solve's own reference
STACK_RATIOS = (0.2, 0.4, 0.8, 1.2, 1.7, 2.0)
QUICK_STACK_RATIOS = (0.8,)
QUICK_STACK_DURATION = 0.05
# The face-on collision turns nothing (its spin is round-off): as ``dem_analysis.MEASURES``.
CASE_MEASURES = {"face-on": ("restitution", "duration"), "offset": MEASURES}


def _scene(offset: float, law: str):
    if law == "frictionless":
        return dem_scenes.collision(offset, "coulomb").with_friction(Coulomb(0.0))
    return dem_scenes.collision(offset, law)


def _model(scenes, solver: str):
    """The twin's model of ``scenes`` for ``solver`` (one of ``SOLVERS``), summing in float."""
    from ...engine.reference import ReferenceModel

    return dataclasses.replace(
        ReferenceModel.from_scenes(scenes),
        integrator={"decoupled": "analytic"}.get(solver, solver),
        quantum=None,
    )


def simulate(scene, dt: float, solver: str):
    """The collision in the NumPy twin of the analytic step, ``solver`` its pair solve;
    returns the final ``ReferenceState`` and the time it reached."""
    from ...engine.reference import ReferenceState, reference_step

    end = dem_scenes.COLLISION_END
    batch = [dem_scenes.with_step(scene, dt, end)]
    model = _model(batch, solver)
    state = ReferenceState.from_scenes(batch)
    steps = round(end / dt)
    for _ in range(steps):
        state = reference_step(state, model, dt)
    return state, steps * dt


def stack(duration: float = STACK_DURATION):
    """``STACK_BLOCKS`` 1 m squares in a row between a fixed wall and a kinematic pusher that
    closes at ``STACK_SPEED``, each a quarter metre above or below the last, so that every
    contact is off the centroids and turns them: a block with two contacts, loaded."""
    import copy

    from ...scene.parse import load_scenario, scene_from_dict

    raw = copy.deepcopy(dict(load_scenario("two_squares").raw))
    wall = {"shape": "rectangle", "width": 0.5, "length": 3.0}
    bodies = [{"name": "wall", "kind": "fixed", "position": [-0.25, 0.0], **wall}]
    for k in range(STACK_BLOCKS):
        bodies.append(
            {
                "name": f"block{k}",
                "shape": "rectangle",
                "width": 1.0,
                "length": 1.0,
                "position": [0.5 + k, 0.25 * (-1) ** k],
            }
        )
    bodies.append(
        {
            "name": "pusher",
            "kind": "kinematic",
            "position": [STACK_BLOCKS + 0.25, 0.0],
            "velocity": [-STACK_SPEED, 0.0],
            **wall,
        }
    )
    raw["body"] = bodies
    raw["friction"] = Coulomb(0.5).to_dict()
    raw["simulation"].update(duration=duration, output_interval=duration, series_interval=duration)
    return scene_from_dict(raw, source="contact_coupling.stack")


def run_stack(ratios, duration: float = STACK_DURATION) -> list[dict[str, Any]]:
    """The stack at each step and solve, against the same solve at ``STACK_REFERENCE``:
    the largest error of a block's position (m) and velocity (m/s) at the end, or the time
    it diverged (a speed above 50 m/s or not finite)."""
    from ...engine.reference import ReferenceState, reference_step

    scene = stack(duration)

    def one(ratio: float, solver: str):
        dt = ratio * scene.stable_dt
        model = _model([scene], solver)
        state = ReferenceState.from_scenes([scene])
        for i in range(round(duration / dt)):
            state = reference_step(state, model, dt)
            if not np.all(np.isfinite(state.vel)) or np.abs(state.vel).max() > 50.0:
                return None, (i + 1) * dt
        return state, duration

    blocks = slice(1, 1 + STACK_BLOCKS)
    rows = []
    for solver in SOLVERS:
        ref, _ = one(STACK_REFERENCE, solver)
        for ratio in ratios:
            t0 = time.perf_counter()
            state, t = one(ratio, solver)
            row = {"case": "stack", "law": "coulomb", "ratio": ratio, "solver": solver}
            if state is None:
                row["diverged_at"] = t
            else:
                row["error"] = {
                    "position": float(np.abs(state.pos[blocks] - ref.pos[blocks]).max()),
                    "velocity": float(np.abs(state.vel[blocks] - ref.vel[blocks]).max()),
                }
            rows.append({**row, "wall_s": time.perf_counter() - t0})
    return rows


def measure(scene, state, t_end: float) -> dict[str, float]:
    """Restitution, contact duration and the square's spin after, as ``dem_analysis``."""
    v = np.asarray(state.vel)
    return {
        "restitution": float((v[1, 0] - v[0, 0]) / dem_scenes.CLOSING_SPEED),
        "duration": collision_ode.last_separation(
            scene, state.pos, state.angle, state.vel, state.omega, t_end, 0.0
        ),
        "spin": float(state.omega[0]),
    }


def _reference(scene) -> dict[str, float]:
    ode = collision_ode.solve_collision(scene, dem_scenes.COLLISION_END)
    touch, apart = ode["contacts"][0]
    v = np.asarray(ode["velocity"])
    return {
        "restitution": float((v[1, 0] - v[0, 0]) / dem_scenes.CLOSING_SPEED),
        "duration": apart - touch,
        "spin": float(ode["omega"][0]),
    }


def run(out: Path, quick: bool = False) -> dict[str, Any]:
    """Every case, step and solver against the ODE; writes the JSON, table and chart."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ratios = QUICK_RATIOS if quick else RATIOS
    rows, references = [], {}
    start = time.perf_counter()
    for name, offset, law in CASES:
        scene = _scene(offset, law)
        ref = references[f"{name}/{law}"] = _reference(scene)
        for ratio in ratios:
            for solver in SOLVERS:
                t0 = time.perf_counter()
                state, t_end = simulate(scene, ratio * scene.stable_dt, solver)
                got = measure(scene, state, t_end)
                err = {m: abs(got[m] / ref[m] - 1.0) for m in CASE_MEASURES[name]}
                rows.append(
                    {
                        "case": name,
                        "law": law,
                        "ratio": ratio,
                        "solver": solver,
                        "value": got,
                        "error": err,
                        "wall_s": time.perf_counter() - t0,
                    }
                )
        print(
            f"contact coupling: {name} collision ({law}) at {len(ratios)} steps "
            f"[{time.perf_counter() - start:.0f} s]",
            flush=True,
        )
    stack_ratios = QUICK_STACK_RATIOS if quick else STACK_RATIOS
    stack_rows = run_stack(stack_ratios, QUICK_STACK_DURATION if quick else STACK_DURATION)
    print(
        f"contact coupling: the stack at {len(stack_ratios)} steps "
        f"[{time.perf_counter() - start:.0f} s]",
        flush=True,
    )
    result = {
        "references": references,
        "rows": rows,
        "ratios": list(ratios),
        "stack": stack_rows,
        "stack_ratios": list(stack_ratios),
    }
    (out / "contact_coupling.json").write_text(json.dumps(result, indent=1))
    (out / "contact_coupling.md").write_text(table(result))
    chart(result, out / "contact_coupling.png")
    return result


def error_of(result: dict, case: str, law: str, solver: str, measure_: str, ratio: float):
    """One error of a ``run`` result (None if that run is not in it)."""
    for r in result["rows"]:
        if (r["case"], r["law"], r["solver"], r["ratio"]) == (case, law, solver, ratio):
            return r["error"].get(measure_)
    return None


def table(result: dict) -> str:
    """Markdown: each case, measure and solver's relative error at every step."""
    ratios = result["ratios"]
    head = "| collision | law | measure | solve | " + " | ".join(f"{r:g}" for r in ratios) + " |"
    lines = [
        "# The contact's two directions solved together, against apart (issue 30)",
        "",
        "Relative error against the ODE (`collision_ode`) at dt / stable_dt, in the NumPy "
        "twin of the analytic step, float64 (`validation.contact_coupling`).",
        "",
        head,
        "|---|---|---|---|" + "---:|" * len(ratios),
    ]
    for name, _, law in CASES:
        for m in CASE_MEASURES[name]:
            for solver in SOLVERS:
                cells = []
                for ratio in ratios:
                    e = error_of(result, name, law, solver, m, ratio)
                    cells.append("" if e is None or not math.isfinite(e) else f"{e:.2g}")
                lines.append(f"| {name} | {law} | {m} | {solver} | " + " | ".join(cells) + " |")
    ratios = result["stack_ratios"]
    lines += [
        "",
        "The loaded stack (`stack`): the largest error of a block's position (m) and velocity "
        f"(m/s) against the same solve at {STACK_REFERENCE} stable_dt, or when it diverged.",
        "",
        "| measure | solve | " + " | ".join(f"{r:g}" for r in ratios) + " |",
        "|---|---|" + "---:|" * len(ratios),
    ]
    for m in ("position", "velocity"):
        for solver in SOLVERS:
            cells = []
            for ratio in ratios:
                row = next(
                    r for r in result["stack"] if (r["solver"], r["ratio"]) == (solver, ratio)
                )
                if "error" in row:
                    cells.append(f"{row['error'][m]:.2g}")
                else:
                    cells.append(f"diverged at {row['diverged_at']:.3f} s")
            lines.append(f"| {m} | {solver} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def chart(result: dict, path: Path) -> Path:
    """Restitution, duration and spin error against the step, each case; solid coupled,
    dashed decoupled (the analytic step's), dotted the midstep one."""
    from matplotlib.ticker import NullFormatter

    from ...run.plots import save_figure, subplots

    ratios = np.array(result["ratios"])
    fig, axes = subplots(1, 4, figsize=(18, 4.4), layout="constrained")
    colours = dict(zip([f"{n}/{law}" for n, _, law in CASES], ("C0", "C1", "C2", "C3")))
    for ax, m in zip(axes[:3], MEASURES):
        for name, _, law in CASES:
            for solver, style in zip(SOLVERS, ("--", "-", ":")):
                e = [error_of(result, name, law, solver, m, r) for r in ratios]
                e = np.array([np.nan if v is None else max(v, 1e-12) for v in e])
                ax.loglog(
                    ratios,
                    e,
                    style,
                    marker="o",
                    color=colours[f"{name}/{law}"],
                    label=f"{name}, {law}, {solver}",
                )
        ax.axvline(0.8, color="grey", lw=0.8)
        ax.axhline(0.015, color="grey", lw=0.8, ls=":")
        ax.set_title(f"{m} error")
        ax.set_xlabel("dt / stable_dt")
    axes[0].set_ylabel("relative error against the ODE")
    axes[0].legend(fontsize=7)
    ax = axes[3]
    for solver, style in zip(SOLVERS, ("--", "-", ":")):
        rows = [r for r in result["stack"] if r["solver"] == solver and "error" in r]
        ax.loglog(
            [r["ratio"] for r in rows],
            [max(r["error"]["velocity"], 1e-12) for r in rows],
            style,
            marker="s",
            color="k",
            label=f"stack, {solver}",
        )
        for r in result["stack"]:
            if r["solver"] == solver and "error" not in r:
                ax.axvline(r["ratio"], color="r", ls=style, lw=0.8)
    ax.axvline(0.8, color="grey", lw=0.8)
    ax.set_title("loaded stack: block velocity error (m/s)")
    ax.xaxis.set_minor_formatter(NullFormatter())  # the ladder's minor ticks overlapped
    ax.set_xlabel("dt / stable_dt (red: diverged)")
    ax.legend(fontsize=7)
    return save_figure(fig, path)
