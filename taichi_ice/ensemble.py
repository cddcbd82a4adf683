"""Ensembles: one scene over many seeds, run as the batched worlds of one Simulation.

    from taichi_ice.ensemble import run_ensemble
    scene = load_scenario("scenarios/pillar.toml")
    ens = run_ensemble(scene, seeds=range(16), friction=RateState())
    ens.metrics[3]["peak_force"], ens.summary()["concentration"]["median"]

One DEM run of rubble is very sensitive to its initial layout (the paper calls its own
comparison tentative for this reason), so the quantities worth reporting are distributions
over layouts. Each seed redraws the scene's field jitter (``Scene.reseeded``); all seeds run
together in one set of Taichi fields, and each world is bit-identical to the same seed run
alone (forces are summed in fixed point), so batching changes the cost, never the answer.

The metrics of one run (``run_metrics``), all from its ``/series``:

- ``peak_force``, ``mean_force`` (N): largest and time-mean magnitude of the total contact
  force on the probe bodies (the pillar), over the whole run.
- ``friction_energy`` (J): frictional dissipation at the end (the paper's Figure 6).
- ``concentration``: the largest share of ``friction_energy`` dissipated in any one window
  of ``window`` seconds (default 1 s). Steady dissipation over 20 s gives about 1/20 = 0.05;
  a run whose dissipation is one event gives close to 1. This is the measure behind the
  paper's remark that with mu = 0.5 "the energy loss seems to be concentrated in two
  individual events" while rate-and-state is "steadier".
- ``final_force`` (N): mean probe force over the last ``window`` seconds, and ``released``
  (1 or 0): whether it has fallen below a tenth of ``peak_force``, i.e. whether the largest
  jam against the probe had broken by the end.
- ``crushing_energy`` (J): work done crushing ice beyond its strength (0 without one).
- ``first_contact`` (s): first sample with a force on a probe (NaN if never).
- ``residual`` (J) and ``residual_rel``: the energy budget's residual at the end, absolute
  and relative to the energy that came in (initial kinetic + elastic, plus work in).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import budget
from .errors import Interrupted, RunFileError, TaichiIceError, UsageError
from .limits import check_size
from .simulation import RunResult

METRICS = (
    "peak_force",
    "mean_force",
    "friction_energy",
    "crushing_energy",
    "concentration",
    "final_force",
    "released",
    "first_contact",
    "residual",
    "residual_rel",
)

# Unit and long name of every metric (the dataset's attributes, the study's tables).
METRIC_INFO = {
    "peak_force": ("N", "largest magnitude of the total contact force on the probe bodies"),
    "mean_force": ("N", "time-mean magnitude of the total contact force on the probe bodies"),
    "friction_energy": ("J", "energy dissipated by friction at the end of the run"),
    "crushing_energy": ("J", "work done crushing ice beyond its strength at the end"),
    "concentration": ("1", "largest share of the frictional energy dissipated in one window"),
    "final_force": ("N", "mean probe force over the last window"),
    "released": ("1", "1 if the final probe force is below a tenth of its peak (jam broken)"),
    "first_contact": ("s", "first time with a force on a probe body"),
    "residual": ("J", "energy budget residual at the end: energy in minus energy accounted"),
    "residual_rel": ("1", "energy budget residual over the energy that came in"),
}

# A jam counts as released when the probe force over the last window is below this fraction
# of its peak.
RELEASED_FRACTION = 0.1


def probe_force_magnitude(series: dict) -> np.ndarray:
    """``(T,)`` magnitude of the total force on the probe bodies (N); zeros if none."""
    f = np.asarray(series["probe_force"])
    if f.ndim != 3 or f.shape[1] == 0:
        return np.zeros(len(series["time"]))
    return np.linalg.norm(f.sum(axis=1), axis=-1)


def concentration(time: np.ndarray, energy: np.ndarray, window: float = 1.0) -> float:
    """Largest share of the final ``energy`` gained in any window of ``window`` seconds.

    ``energy`` is cumulative (non-decreasing up to round-off), sampled at ``time``; windows
    start anywhere on the sample grid and the energy at their ends is interpolated linearly.
    Returns NaN when nothing was dissipated; 1.0 when the run is shorter than the window.
    """
    time, energy = np.asarray(time, dtype=float), np.asarray(energy, dtype=float)
    total = energy[-1] - energy[0]
    if not total > 0:
        return math.nan
    if time[-1] - time[0] <= window:
        return 1.0
    starts = time[time <= time[-1] - window]
    gained = np.interp(starts + window, time, energy) - np.interp(starts, time, energy)
    return float(np.max(gained) / total)


def run_metrics(series: dict, window: float = 1.0) -> dict[str, float]:
    """The metrics of one run (see the module docstring) from its ``/series`` arrays."""
    t = np.asarray(series["time"])
    force = probe_force_magnitude(series)
    touching = np.nonzero(force > 0)[0]
    residual = float(budget.residual(series)[-1])
    came_in = float(budget.came_in(series)[-1])
    peak = float(force.max()) if force.size else 0.0
    last = t >= t[-1] - window
    last[0] = False  # t = 0 carries no impulse
    final = float(force[last].mean()) if last.any() else 0.0
    return {
        "peak_force": peak,
        # Samples are equally spaced, so the time mean is the sample mean (t = 0 excluded:
        # it carries no impulse).
        "mean_force": float(force[1:].mean()) if force.size > 1 else 0.0,
        "friction_energy": float(series["friction_energy"][-1]),
        # 0 without an ice strength, and in files written before the term existed.
        "crushing_energy": float(np.asarray(series.get("crushing_energy", [0.0]))[-1]),
        "concentration": concentration(t, series["friction_energy"], window),
        "final_force": final,
        "released": float(peak > 0 and final < RELEASED_FRACTION * peak),
        "first_contact": float(t[touching[0]]) if touching.size else math.nan,
        "residual": residual,
        "residual_rel": residual / came_in if came_in > 0 else math.nan,
    }


@dataclass
class EnsembleResult(RunResult):
    """One law over many seeds: a RunResult (series, paths, steps, dt, wall time, status,
    failure: per world, in ``seeds`` order) with the law's label and each world's metrics.

    ``status`` is 'complete' or 'failed'; after a failure the series and metrics hold what
    every world had reached, and ``failure`` says why.
    """

    # Defaults only because RunResult's fields have them (kw_only= needs Python 3.10);
    # run_ensemble always passes all three.
    label: str = ""
    seeds: list[int] = field(default_factory=list)
    metrics: list[dict[str, float]] = field(default_factory=list)

    def values(self, name: str) -> np.ndarray:
        """``(n_seeds,)`` one metric over the seeds."""
        return np.array([m[name] for m in self.metrics], dtype=float)

    def summary(self) -> dict[str, dict[str, float]]:
        """Per metric: min, quartiles, median, max and mean over the seeds (NaNs ignored)."""
        out = {}
        for name in METRICS:
            v = self.values(name)
            v = v[np.isfinite(v)]
            if not v.size:
                out[name] = {"n": 0}
                continue
            q1, med, q3 = np.percentile(v, [25, 50, 75])
            out[name] = {
                "n": int(v.size),
                "min": float(v.min()),
                "q1": float(q1),
                "median": float(med),
                "q3": float(q3),
                "max": float(v.max()),
                "mean": float(v.mean()),
            }
        return out


def run_ensemble(
    scene,
    seeds: Iterable[int],
    friction=None,
    *,
    until: float | None = None,
    out: Sequence[str | Path] | str | Path | None = None,
    arch: str = "cpu",
    precision: str = "f64",
    dt: float | None = None,
    slots: int | None = None,
    window: float = 1.0,
    progress: bool = False,
    checkpoint_every: float | None = None,
    resume: bool = False,
    worlds=None,
) -> EnsembleResult:
    """Run ``scene`` reseeded with every seed, all seeds as worlds of one Simulation.

    Args:
        scene: the Scene (its own seed is one layout like any other).
        seeds: field-jitter seeds, one world each.
        friction: law replacing the scene's (a Coulomb or RateState); None keeps it.
        until: end time (s); default the scene's duration.
        out: a folder (files ``seed-XXXX.h5`` in it), one path per seed, or None (no files).
        arch, precision, dt, slots: as for ``Simulation``.
        window: the concentration window (s).
        progress: progress bar on stderr.
        checkpoint_every, resume: as for ``Simulation.run`` (they need ``out``): one
            checkpoint holds every world of the batch, beside the first world's file.
        worlds: what makes the World, as for ``Simulation`` (``sweep.WorldPool``: a World
            compiled for the same layout, reloaded).

    Returns:
        EnsembleResult. A run that diverges or overflows does not raise: its files are
        marked failed, and the result has ``status = 'failed'`` with what was reached.

    Raises:
        ScenarioError: a seed's jitter makes blocks overlap at the start.
        Interrupted, KeyboardInterrupt: the run was stopped (SIGINT, SIGTERM); its files are
            kept, and with checkpoints ``resume`` continues it.
    """
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("an ensemble needs at least one seed")
    check_size(
        len(seeds) * scene.n_bodies,
        f"ensemble of {len(seeds):,} seeds x {scene.n_bodies:,} bodies",
        "fewer seeds (taichi_ice.sweep runs many seeds in batches)",
    )
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds repeat: {seeds}")
    if friction is not None:
        scene = scene.with_friction(friction)
    if isinstance(out, (str, Path)):
        out = seed_paths(out, seeds)
    return run_worlds(
        [scene.reseeded(s) for s in seeds],
        label=scene.friction.label,
        until=until,
        out=out,
        arch=arch,
        precision=precision,
        dt=dt,
        slots=slots,
        window=window,
        progress=progress,
        checkpoint_every=checkpoint_every,
        resume=resume,
        worlds=worlds,
    )


def seed_paths(folder: str | Path, seeds: Sequence[int]) -> list[Path]:
    """The run file of each seed in ``folder``: ``seed-XXXX.h5`` (wider for large seeds)."""
    width = max(4, len(str(max(seeds))))
    return [Path(folder) / f"seed-{s:0{width}d}.h5" for s in seeds]


def run_worlds(
    scenes: Sequence,
    *,
    label: str = "",
    until: float | None = None,
    out: Sequence[str | Path] | None = None,
    arch: str = "cpu",
    precision: str = "f64",
    dt: float | None = None,
    slots: int | None = None,
    window: float = 1.0,
    progress: bool = False,
    worlds=None,
    checkpoint_every: float | None = None,
    resume: bool = False,
) -> EnsembleResult:
    """Run ``scenes`` (any layouts, laws and settings one batch can share, see
    ``assemble.assemble``) as the worlds of one Simulation and compute each one's metrics.

    ``run_ensemble`` is this over the seeds of one scene; a sweep runs its batches with it.
    Arguments and result as ``run_ensemble``'s (``out``: one path per scene, or None);
    ``worlds`` as ``Simulation``'s (what makes the World: a sweep reuses compiled ones);
    ``checkpoint_every`` and ``resume`` as ``Simulation.run``'s.

    A run stopped by SIGINT or SIGTERM raises (``Interrupted``): it has not failed, it is
    unfinished, and a resume (or a sweep run again) must run it.
    """
    from .simulation import Simulation

    scenes = list(scenes)
    sim = Simulation(scenes, arch=arch, precision=precision, dt=dt, slots=slots, worlds=worlds)
    try:
        result = sim.run(
            until=until,
            out=out,
            progress=progress,
            checkpoint_every=checkpoint_every,
            resume=resume,
        )
    except Interrupted:
        raise
    except TaichiIceError as exc:
        if not hasattr(exc, "result"):  # refused before any step (an output, a checkpoint)
            raise
        result = exc.result
    return EnsembleResult(
        **vars(result),
        label=label,
        seeds=[s.simulation.seed for s in scenes],
        metrics=[run_metrics(s, window) for s in result.series],
    )


def load_worlds(
    paths: Sequence[str | Path],
    record: dict,
    *,
    label: str = "",
    seeds: Sequence[int] = (),
    window: float = 1.0,
) -> EnsembleResult:
    """A batch that finished earlier, read back: the series from its run files (as written,
    so the metrics are those the run computed, bit for bit), and ``record`` (``status``,
    ``failure``, ``warning``, ``steps``, ``dt``, ``wall_time``: what a ledger kept of it)."""
    from .io import read_run

    series = [read_run(p)["series"] for p in paths]
    return EnsembleResult(
        series=series,
        paths=[Path(p) for p in paths],
        steps=int(record["steps"]),
        dt=float(record["dt"]),
        wall_time=float(record["wall_time"]),
        status=str(record["status"]),
        failure=str(record["failure"]),
        warning=str(record.get("warning", "")),
        label=label,
        seeds=[int(s) for s in seeds],
        metrics=[run_metrics(s, window) for s in series],
    )


def record_of(ens: EnsembleResult) -> dict:
    """What a ledger keeps of a finished batch, besides its run files (``load_worlds``)."""
    return {
        "status": ens.status,
        "failure": ens.failure,
        "warning": ens.warning,
        "steps": int(ens.steps),
        "dt": float(ens.dt),
        "wall_time": float(ens.wall_time),
    }


def run_part(ledger, part: str, paths: Sequence[Path], run, *, label="", seeds=()):
    """One batch of a resumable command (``ensemble``, ``paper``): read back if the ledger
    says it finished; else continued from its checkpoint if it was started and wrote one;
    else run from its start. ``run(checkpoint_every=, resume=, worlds=)`` runs it
    (``run_ensemble``); its World comes from this process's ``sweep.POOL``, so the batches of
    one layout (laws of one kind, a resumed batch) compile the kernels once.
    """
    from . import checkpoint
    from .sweep import POOL

    record = ledger.done(part)
    if record is not None:
        try:
            return load_worlds(paths, record, label=label, seeds=seeds)
        except RunFileError as exc:
            raise RunFileError(
                f"{part} finished earlier, but its run files cannot be read back ({exc}); "
                "start anew with --overwrite"
            ) from None
    ckpt = checkpoint.path_for(paths[0])
    resume = ledger.resumed and ledger.started(part) and ckpt.is_file()
    if not resume:
        checkpoint.remove(ckpt)  # another run's, or a part that never reached one
        ledger.start(part)
    try:
        with POOL.lease() as make:
            ens = run(checkpoint_every=ledger.checkpoint_every, resume=resume, worlds=make)
    except Interrupted as exc:
        if "--resume" in str(exc):  # it wrote a checkpoint, and says so
            raise
        raise Interrupted(
            f"{exc}; --resume keeps what finished and continues {part} from its last "
            "checkpoint (from its start if it wrote none)"
        ) from None
    ledger.finish(part, **record_of(ens))
    checkpoint.remove(ckpt)  # a finished part is read back, never continued
    return ens


def ensemble_command(
    scene_path,
    out,
    n_seeds: int,
    laws=(None,),
    until: float | None = None,
    arch: str = "cpu",
    precision: str = "f64",
    progress: bool = True,
    *,
    overwrite: bool = False,
    resume: bool = False,
    checkpoint_every: float | None = None,
) -> int:
    """The body of ``taichi-ice ensemble``: each law over ``n_seeds`` layouts.

    Writes ``out/<law>/seed-XXXX.h5`` (every world), ``out/ensemble.json`` (metrics per seed
    and their distribution per law), ``out/ensemble.csv`` (one row per law and seed) and
    ``out/ensemble.png`` (the spread chart).

    Resumable (``taichi_ice.ledger``): ``out/ensemble-state.json`` records the options and the
    laws finished. ``resume`` reads the laws finished back from their files, continues the
    interrupted one from its checkpoint (``checkpoint_every``: wall-clock seconds between
    checkpoints of a law's batch, None for none) and runs the rest: every file equals that of
    an ensemble never stopped (but the wall times). An earlier ensemble's output is refused
    unless ``resume`` or ``overwrite``.
    """
    import csv
    import json
    import sys

    from .io import check_folder
    from .ledger import Ledger, scene_digest
    from .plots import plot_spread
    from .scenario import load_scenario

    check_folder(out, make=False)  # before any work
    scene = load_scenario(scene_path)
    # Every seed is a world of one batch: refuse what cannot fit before any world is built
    # (1e7 seeds used to grow the process silently).
    check_size(
        n_seeds * scene.n_bodies,
        f"ensemble of {n_seeds:,} seeds x {scene.n_bodies:,} bodies of {scene_path}",
        "fewer --seeds (taichi-ice sweep runs many seeds in batches)",
    )
    out = check_folder(out)
    seeds = [scene.simulation.seed + k for k in range(n_seeds)]
    named: list[tuple[str, object]] = []  # (label, law or None: the scene's)
    for law in laws:
        label = (law if law is not None else scene.friction).label
        if label in (n for n, _ in named):
            raise UsageError(f"--friction {label} given twice: give each law once")
        named.append((label, law))
    options = {
        "scene": scene_digest(scene),
        "seeds": seeds,
        "laws": [
            [label, (law if law is not None else scene.friction).to_dict()] for label, law in named
        ],
        "until": scene.simulation.duration if until is None else float(until),
        "arch": arch,
        "precision": precision,
    }
    reports = [out / f"ensemble.{ext}" for ext in ("json", "csv", "png")]
    outputs = reports + [out / label for label, _ in named]
    results: dict[str, EnsembleResult] = {}
    with Ledger(
        out,
        "ensemble",
        options,
        resume=resume,
        overwrite=overwrite,
        outputs=outputs,
        checkpoint_every=checkpoint_every,
    ) as ledger:
        if not resume:
            for path in reports:  # an earlier ensemble's: reports say it finished
                path.unlink(missing_ok=True)
        for label, law in named:
            paths = seed_paths(out / label, seeds)
            finished = ledger.done(label) is not None
            if progress:
                print(
                    f"ensemble: {label}, {len(seeds)} layouts"
                    + (" (finished earlier: read back)" if finished else ""),
                    file=sys.stderr,
                    flush=True,
                )

            run = functools.partial(
                run_ensemble,
                scene,
                seeds,
                law,
                until=until,
                out=paths,
                arch=arch,
                precision=precision,
                progress=progress,
            )
            ens = run_part(ledger, label, paths, run, label=label, seeds=seeds)
            results[label] = ens
            summary = ens.summary()
            peak = summary["peak_force"].get("median", math.nan)
            energy = summary["friction_energy"].get("median", math.nan)
            print(
                f"{label}: {ens.status} in {ens.wall_time:.1f} s ({ens.steps} steps x "
                f"{len(seeds)} worlds); median peak force {peak / 1e3:.3g} kN, median friction "
                f"energy {energy:.4g} J"
                + (f"; FAILED: {ens.failure}" if ens.status != "complete" else "")
            )
        report = {
            "scene": str(scene.source),
            "seeds": seeds,
            "laws": {
                label: {
                    "status": ens.status,
                    "failure": ens.failure,
                    "steps": ens.steps,
                    "dt": ens.dt,
                    "wall_time": ens.wall_time,
                    "metrics": ens.metrics,
                    "summary": ens.summary(),
                }
                for label, ens in results.items()
            },
        }
        (out / "ensemble.json").write_text(json.dumps(report, indent=2) + "\n")
        with open(out / "ensemble.csv", "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(["law", "seed", *METRICS])
            for label, ens in results.items():
                for seed, m in zip(ens.seeds, ens.metrics):
                    writer.writerow([label, seed, *(m[k] for k in METRICS)])
        plot_spread(results, out / "ensemble.png")
    print(f"wrote {out}/ensemble.json, ensemble.csv, ensemble.png and the runs")
    return 0 if all(e.status == "complete" for e in results.values()) else 1
