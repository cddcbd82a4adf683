"""The DEM's speed against its accuracy, and its stability: ``taichi-ice validate --dem``.

For time steps from well below to beyond the computed stability limit (``dt`` as a multiple
``ratio`` of ``stable_dt``; ``force_dt`` past it), in float64 and float32, with Coulomb
friction (mu = 0.5) and the paper's rate-and-state law, and with each integrator
(``Options.integrator``: ``euler``, the default, and ``analytic``, each contact's
spring-dashpot solved over the step), the error against a reference and the wall time per
simulated second, on (scenes in ``dem_scenes``):

- **collisions** of a square and a block, face on and offset, against the ODE of the same
  contact law (``collision_ode``, SciPy; face on also its closed form): restitution, contact
  duration and, offset, the square's spin after the collision;
- the **pushed box** (``pushed_field`` compacted at 0.5 m/s): the energy budget's residual,
  ``max |residual| / work in``, which has no reference but zero;
- the **paper's scene** (``pillar``, 20 s): the peak pillar force (its 10 ms mean, as
  sampled), the frictional energy and the block positions against the float64 run at a
  quarter of the default step (``REFERENCE_RATIO``; each integrator its own, and the two
  references against each other), up to the time the default step's run parts from it (a
  block 1 cm from its twin: the scene is chaotic) or ``PILLAR_UNTIL``; when every run parts
  from the run at a quarter of its step (over the paper's 20 s for 0.8 against 0.2); and, at
  ``NUDGED_RATIOS``, when two runs part that differ only in the last bit of the x of the
  block that meets the pillar first (the 20 s runs: Euler only).

**Stability** (``dem_stability``): the largest ratio a free collision, a dense field and a
jam at full load survive, per integrator, and from them and the errors the recommended
``dt_safety`` of each integrator.

Cost: ``wall per simulated second = (wall per step) / dt``, the wall per step measured on a
world alone at the default ratio (per scene, law, integrator and precision), over
``TIMING_SPAN`` more seconds after its run, so that no kernel compilation is timed (the
work of a step does not depend on dt). The other ratios run each scene's laws batched (a
world's trajectory does not depend on its batch). Nothing compiled depends on dt, and each
Simulation takes the World of the last one of its layout from the process's pool
(``engine.pool``), so a new dt reloads a World instead of compiling one: the study compiles
once per layout and integrator.

Taichi holds one precision per process: each precision and integrator runs in its own
worker process (``python -m taichi_ice.commands.validate dem_accuracy --worker f32
--integrators euler ...``; ``--quick`` runs in this process when it already runs Taichi on
the CPU in float64), as many at a time as the cores (``run(workers=...)``): the jobs share no
kernel, and the timed runs are a world alone, a thread each. The workers write the runs
(``npz``) into ``DIR/dem_runs/<precision>/<integrator>/``, and the study merges their indexes
into ``DIR/dem_runs/<precision>/index.json``; the analysis (``dem_analysis``) and charts
(``dem_charts``) read them.

Writes ``dem_accuracy.json``, ``dem_accuracy.md`` (its numbers as tables),
``dem_accuracy.png`` (error against cost) and ``dem_stability.png`` (parting runs, limits).
"""

from __future__ import annotations

import json
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from . import dem_scenes
from .dem_workers import jsonable, spawned

LAWS = ("coulomb", "rate-state")
INTEGRATORS = ("euler", "analytic", "coupled", "midstep")  # engine.options.INTEGRATORS
COLLISIONS = dem_scenes.COLLISIONS
# dt / stable_dt of the collisions (batched: four worlds per dt; a new dt reloads the World
# of the last, compiling nothing). Float32, which only adds round-off, takes fewer.
COLLISION_RATIOS = {
    "f64": (0.0125, 0.05, 0.2, 0.8, 1.6),
    "f32": (0.2,),
}
# dt / stable_dt of the pillar scene and the pushed box, nominal: dt = SAMPLE / n with n a
# multiple of the coarsest's, so that a quarter of a step is exact and every run samples at
# the same times.
PILLAR_RATIOS = {"f64": (0.05, 0.1, 0.2, 0.4, 0.8, 1.6), "f32": (0.2, 0.8)}
BOX_RATIOS = {"f64": (0.05, 0.2, 0.8), "f32": (0.2,)}
SAMPLE = 0.01  # s between series samples (the pillar scene's own)
# Coulomb's default step (timestep.DEFAULT_SAFETY; rate and state's is 0.05 since
# 2026-11-28, from the ensembles, not from these single runs): its runs are one world
# alone, timed.
DEFAULT_RATIO = 0.2
REFERENCE_RATIO = 0.05  # a quarter of it: the float64 reference of the field scenes
# The pillar scene runs PILLAR_UNTIL (the rubble meets the pillar at 2.1 s), and the paper's
# whole 20 s at LONG_RATIOS (float64), where runs that differ by a step four times as long
# (0.8 against 0.2) or by the last bit of one x (NUDGED_RATIOS) can be seen to part. A run
# at 0.05 stable_dt costs ~6 s of wall time per simulated second once the rubble jams.
PILLAR_UNTIL = 6.0  # s
LONG_UNTIL = 20.0  # s: the paper's run
LONG_RATIOS = (0.2, 0.8)
NUDGED_RATIOS = (0.8,)
BOX_UNTIL = 2.5  # s: the pusher, at 0.5 m/s, compacts the box by 1.2 m
COLLISION_TIMING_UNTIL = 2.0  # s of the timing run of a collision (~12,700 steps)
# s more of a run at the default step, timed (~19,000 steps): from 6 s for the pillar scene
# (blocks at the pillar, before the jam; jammed, at 20 s, a step costs 2.5-3.5 times as much).
TIMING_SPAN = 2.0

# --quick (tests, smoke runs): float64 and Coulomb only, the collisions and the pushed box at
# one step each (so no orders), no pillar scene, no stability search: every Simulation at a
# new dt compiles for ~10 s on 2 cores, and this is two of them.
QUICK = {
    "precisions": ("f64",),
    "laws": ("coulomb",),
    "integrators": ("euler",),
    "collision_ratios": (0.1,),
    "pillar_ratios": (),
    "box_ratios": (0.8,),
    "reference_ratio": None,
    "pillar_until": 0.3,
    "box_until": 0.3,
    "long_ratios": (),
    "nudged_ratios": (),
    "stability": False,
}


def config(
    quick: bool = False, until: float | None = None, integrators: tuple[str, ...] | None = None
) -> dict[str, Any]:
    """The study's settings (``QUICK`` when quick); ``until`` (s) replaces ``PILLAR_UNTIL``,
    ``integrators`` the integrators compared (``INTEGRATORS``; quick: Euler alone)."""
    out = {
        "precisions": ("f64", "f32"),
        "laws": LAWS,
        "integrators": INTEGRATORS,
        "collision_ratios": None,  # per precision: COLLISION_RATIOS
        "pillar_ratios": None,  # per precision: PILLAR_RATIOS
        "box_ratios": None,  # per precision: BOX_RATIOS
        "reference_ratio": REFERENCE_RATIO,
        "pillar_until": PILLAR_UNTIL,
        "long_until": LONG_UNTIL,
        "box_until": BOX_UNTIL,
        "long_ratios": LONG_RATIOS,
        "nudged_ratios": NUDGED_RATIOS,
        "stability": True,
    }
    if quick:
        out.update(QUICK)
    if until is not None:
        out["pillar_until"] = float(until)
    if integrators is not None:
        from ...engine.options import INTEGRATORS as KNOWN

        unknown = [i for i in integrators if i not in KNOWN]
        if unknown or not integrators:
            raise ValueError(f"integrators must be some of {KNOWN}, got {integrators!r}")
        out["integrators"] = tuple(integrators)
    out["quick"] = quick
    return out


def ratios(cfg: dict[str, Any], kind: str, precision: str) -> tuple[float, ...]:
    """The ladder of ``kind`` ('collision', 'pillar', 'box') in ``precision``."""
    table = {"collision": COLLISION_RATIOS, "pillar": PILLAR_RATIOS, "box": BOX_RATIOS}[kind]
    mine = cfg[f"{kind}_ratios"]
    return table[precision] if mine is None else mine


def field_step(ratio: float, stable: float) -> float:
    """``SAMPLE / n``, n a whole multiple of the coarsest ladder step's count (ratio 1.6)."""
    coarsest = math.ceil(SAMPLE / (1.6 * stable) / 3.0) * 3  # whole at 1.6 / 1.2 (3/4)
    return SAMPLE / max(1, round(coarsest * 1.6 / ratio))


# --------------------------------------------------------------------------------------------
# Worker: the runs of one precision (Taichi started in it).
# --------------------------------------------------------------------------------------------


class Store:
    """Run records of one precision: arrays in ``<dir>/<key>.npz``, the rest in a list."""

    def __init__(self, folder: Path):
        self.folder = folder
        folder.mkdir(parents=True, exist_ok=True)
        self.records: list[dict[str, Any]] = []

    def add(self, record: dict[str, Any], arrays: dict[str, np.ndarray] | None = None) -> None:
        if arrays:
            key = f"run{len(self.records):03d}"
            np.savez_compressed(self.folder / f"{key}.npz", **arrays)
            record["arrays"] = f"{key}.npz"
        self.records.append(record)


def _run(sim, until: float, out=None) -> tuple[dict[str, Any], Any]:
    """Run a Simulation; returns ``({status, failure, wall_s, steps}, result or None)``."""
    from ...errors import TaichiIceError

    before = sim.steps
    try:
        result = sim.run(until=until, out=out)
        steps = result.steps - before
        return {"status": "complete", "wall_s": result.wall_time, "steps": steps}, result
    except TaichiIceError as exc:
        res = getattr(exc, "result", None)
        return {
            "status": "failed",
            "failure": str(exc),
            "failed_at": sim.time,
            "wall_s": res.wall_time if res else None,
            "steps": sim.steps - before,
        }, None


def run_collisions(
    store: Store, precision: str, cfg: dict[str, Any], log, integrator: str = "euler"
) -> None:
    """Every collision ratio as one batch of (face on, offset) x laws; then the timing runs."""
    from ...run.simulation import Simulation

    keys = [(kind, law) for kind in COLLISIONS for law in cfg["laws"]]
    scenes = {k: dem_scenes.collision(COLLISIONS[k[0]], k[1]) for k in keys}
    stable = scenes[keys[0]].stable_dt
    end = dem_scenes.COLLISION_END
    for ratio in ratios(cfg, "collision", precision):
        dt = ratio * stable
        batch = [dem_scenes.with_step(scenes[k], dt, end) for k in keys]
        start = time.perf_counter()
        sim = Simulation(batch, dt=dt, force_dt=True, precision=precision, integrator=integrator)
        info, _ = _run(sim, until=batch[0].simulation.series_interval)
        for w, (kind, law) in enumerate(keys):
            state = {
                "position": sim.positions(w),
                "angle": sim.angles(w),
                "velocity": sim.velocities(w),
                "omega": sim.omegas(w),
            }
            store.add(
                {
                    "scene": kind,
                    "law": law,
                    "integrator": integrator,
                    "precision": precision,
                    "ratio": sim.dt / stable,
                    "dt": sim.dt,
                    "t_end": sim.time,
                    **info,
                },
                state,
            )
        log(
            f"dem accuracy [{precision}, {integrator}] collisions at dt = "
            f"{sim.dt / stable:.4f} x stable_dt: "
            f"{info['status']} [{time.perf_counter() - start:.1f} s]"
        )
        del sim  # its World idle: the next dt reloads it (pool.POOL), compiling nothing
    for law in cfg["laws"]:
        # The offset collision alone at the default step: run once (compiling), then timed.
        scene = dem_scenes.collision(dem_scenes.OFFSET, law)
        dt = DEFAULT_RATIO * stable
        sim = Simulation(
            dem_scenes.with_step(scene, dt, SAMPLE),
            dt=dt,
            precision=precision,
            integrator=integrator,
        )
        info, _ = _run(sim, until=end)
        store.add(
            {
                "kind": "timing",
                "scene": "collision",
                "law": law,
                "integrator": integrator,
                "precision": precision,
                "dt": sim.dt,
                **_timed(sim, COLLISION_TIMING_UNTIL - sim.time),
            }
        )
        del sim


def _read(path: Path) -> dict[str, np.ndarray]:
    """The series and frames of one run file that the analysis uses."""
    from ...run.runfile_read import read_run

    run = read_run(path)
    s, f = run["series"], run["frames"]
    keys = (
        "time",
        "friction_energy",
        "work_in",
        "kinetic_energy",
        "elastic_energy",
        "viscous_energy",
        "drag_energy",
        "crushing_energy",
        "severed_energy",
    )
    out = {k: np.asarray(s[k]) for k in keys if k in s}
    out["probe_force"] = np.asarray(s["probe_force"])
    out["frame_time"], out["position"] = np.asarray(f["time"]), np.asarray(f["position"])
    return out


def _timed(sim, span: float) -> dict[str, Any]:
    """Wall per step of ``span`` more seconds on a Simulation whose kernels have run (so no
    compilation is timed): the cost of one step of this choice. (``Simulation.run`` takes
    the time to run until, not a duration.)"""
    info, _ = _run(sim, until=sim.time + span)
    steps = info.get("steps") or 0
    return {
        "wall_per_step_s": info["wall_s"] / steps if steps and info["wall_s"] else None,
        "timed_steps": steps,
    }


def _field_run(store, precision, sim_worlds, labels, dt, until, stable, alone, tmp, log):
    """One Simulation of field worlds (of one integrator, ``labels[0]["integrator"]``); each
    world's series and frames into the store."""
    from ...run.simulation import Simulation

    start = time.perf_counter()
    integrator = labels[0]["integrator"]
    sim = Simulation(sim_worlds, dt=dt, force_dt=True, precision=precision, integrator=integrator)
    paths = [tmp / f"{precision}-{i}.h5" for i in range(len(labels))]
    info, _ = _run(sim, until=until, out=paths)
    timing = _timed(sim, TIMING_SPAN) if alone and info["status"] == "complete" else {}
    for label, path in zip(labels, paths):
        store.add(
            {
                **label,
                "precision": precision,
                "ratio": sim.dt / stable,
                "dt": sim.dt,
                "until": until,
                "alone": alone,
                **info,
                **timing,
            },
            _read(path),
        )
        path.unlink()
    names = ", ".join(
        f"{x['scene']} {x['law']}{' (nudged)' if x['nudged'] else ''}" for x in labels
    )
    log(
        f"dem accuracy [{precision}, {integrator}] {names} at dt = {sim.dt / stable:.4f} x "
        f"stable_dt to "
        f"{until:g} s: {info['status']} [{time.perf_counter() - start:.1f} s]"
    )


def run_fields(
    store: Store, precision: str, cfg: dict[str, Any], tmp: Path, log, integrator: str = "euler"
) -> None:
    """The pillar scene and the pushed box at every ratio of their ladders.

    Each law's worlds of a scene run batched; at ``DEFAULT_RATIO`` each world runs alone
    (then timed, ``_timed``); at ``long_ratios`` the pillar scene runs ``long_until``, at
    ``nudged_ratios`` beside its twins nudged by the last bit of one x (float64 and Euler
    only; a world is bit-identical batched and alone, so the runs alone at a long ratio are
    for timing).
    """
    makers = {"pillar": dem_scenes.pillar, "pushed box": dem_scenes.pushed_box}
    laws = cfg["laws"]
    base = makers["pillar"](laws[0])
    stable = base.stable_dt
    block = dem_scenes.first_at_pillar(base)
    for scene, kind, until in (
        ("pillar", "pillar", cfg["pillar_until"]),
        ("pushed box", "box", cfg["box_until"]),
    ):
        for ratio in ratios(cfg, kind, precision):
            dt = field_step(ratio, stable)
            f64_pillar = scene == "pillar" and precision == "f64" and integrator == "euler"
            alone = math.isclose(ratio, DEFAULT_RATIO) and not cfg["quick"]
            long = f64_pillar and any(math.isclose(ratio, r) for r in cfg["long_ratios"])
            nudged = f64_pillar and any(math.isclose(ratio, r) for r in cfg["nudged_ratios"])
            batch = [(law, n) for law in laws for n in ((False, True) if nudged else (False,))]
            runs = []  # (worlds as (law, nudged), until, alone, timing only)
            if alone:
                runs += [([(law, False)], until, True, long) for law in laws]
            if long:
                runs.append((batch, cfg["long_until"], False, False))
            elif not alone:
                runs.append((batch, until, False, False))
            for group, span, single, timing_only in runs:
                worlds = [makers[scene](law) for law, _ in group]
                worlds = [
                    dem_scenes.nudge(w, block) if n else w for w, (_, n) in zip(worlds, group)
                ]
                labels = [
                    {
                        "scene": scene,
                        "law": law,
                        "integrator": integrator,
                        "nudged": n,
                        "nudged_body": block if n else None,
                        "timing_only": timing_only,
                    }
                    for law, n in group
                ]
                _field_run(store, precision, worlds, labels, dt, span, stable, single, tmp, log)


def worker(precision: str, folder: Path, cfg: dict[str, Any], log) -> dict[str, Any]:
    """Every run of one precision into ``folder``; returns the index (also written there)."""
    from ... import backend
    from . import dem_stability

    backend.init("cpu", precision)
    store = Store(folder)
    start = time.perf_counter()
    for integrator in cfg["integrators"]:
        run_collisions(store, precision, cfg, log, integrator)
        with tempfile.TemporaryDirectory(dir=folder) as tmp:
            run_fields(store, precision, cfg, Path(tmp), log, integrator)
    index: dict[str, Any] = {
        "precision": precision,
        # The wall times were taken with kernels compiled this way (``compile_for_studies``).
        "advanced_optimization": backend.optimized(),
        "optimize": backend.compile_level(),
        "records": store.records,
    }
    if precision == "f64" and cfg["stability"]:
        index["stability"] = {
            i: dem_stability.run_all(log=log, integrator=i) for i in cfg["integrators"]
        }
    index["wall_s"] = time.perf_counter() - start
    (folder / "index.json").write_text(json.dumps(index, default=jsonable))
    return index


# --------------------------------------------------------------------------------------------
# Study
# --------------------------------------------------------------------------------------------


def run(
    out_dir: str | Path,
    *,
    quick: bool = False,
    until: float | None = None,
    reuse: bool = False,
    integrators: tuple[str, ...] | None = None,
    workers: int | None = None,
) -> dict:
    """Every run, then the analysis, chart and JSON; returns the JSON summary as a dict.

    Args:
        out_dir: output folder (``dem_accuracy.json``, the PNGs, ``dem_runs/``).
        quick: float64 and Coulomb only, two steps per scene, short runs (``QUICK``).
        until: seconds of the pillar scene's runs (default ``PILLAR_UNTIL``).
        integrators: those compared (default ``INTEGRATORS``; quick: Euler alone).
        reuse: analyse the runs already in ``out_dir/dem_runs`` (from an earlier call with
            the same settings) instead of running them again.
        workers: worker processes at a time, one per precision and integrator (default: the
            cores this process may use, ``backend.usable_cores``).
    """
    from ... import backend
    from ...errors import TaichiIceError
    from . import dem_analysis, dem_charts

    try:
        import scipy  # noqa: F401  (the collision ODE's solver)
    except ImportError:
        raise TaichiIceError(
            "validate --dem solves its collision references with SciPy, which is not "
            "installed: pip install scipy (or the test extra, pip install 'taichi-ice[test]')"
        ) from None
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cfg = config(quick, until, integrators)
    start = time.perf_counter()
    parts = {}
    spawn = []
    for precision in cfg["precisions"]:
        folder = out_dir / "dem_runs" / precision
        if reuse:
            parts[precision] = json.loads((folder / "index.json").read_text())
        elif quick and backend.current() == ("cpu", precision):
            parts[precision] = worker(precision, folder, cfg, log=log)  # two runs: here
        else:
            spawn.append(precision)
    if spawn:
        parts.update(spawned(out_dir, cfg, spawn, until, workers or backend.usable_cores(), log))
    summary = dem_analysis.analyse(parts, out_dir / "dem_runs", cfg, log=log)
    summary["wall_s"] = time.perf_counter() - start
    summary["advanced_optimization"] = {
        p: part.get("advanced_optimization") for p, part in parts.items()
    }
    summary["optimize"] = {p: part.get("optimize") for p, part in parts.items()}
    figure = out_dir / "dem_accuracy.png"
    dem_charts.plot_accuracy(summary, figure)
    stability_figure = out_dir / "dem_stability.png"
    dem_charts.plot_stability(summary, stability_figure)
    summary["figures"] = [figure.name, stability_figure.name]
    (out_dir / "dem_accuracy.md").write_text(dem_charts.tables(summary))
    path = out_dir / "dem_accuracy.json"
    path.write_text(json.dumps(summary, indent=1, default=jsonable) + "\n")
    log(f"dem accuracy: wrote {figure}, {stability_figure} and {path} [{summary['wall_s']:.0f} s]")
    return summary


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


__all__ = ["config", "field_step", "run", "worker"]
