"""Ensembles: one scene over many seeds, run as the batched worlds of one Simulation.

    from taichi_ice.experiments.ensemble import run_ensemble
    scene = load_scenario("scenarios/pillar.toml")
    ens = run_ensemble(scene, seeds=range(16), friction=RateState())
    ens.metrics[3]["peak_force"], ens.summary()["concentration"]["median"]

One DEM run of rubble is very sensitive to its initial layout (the paper calls its own
comparison tentative for this reason), so the quantities worth reporting are distributions
over layouts. Each seed redraws the scene's field jitter (``scenario.reseeded``); all seeds run
together in one set of Taichi fields, and each world is bit-identical to the same seed run
alone (forces are summed in fixed point), so batching changes the cost, never the answer.

Each world's metrics are ``metrics.run_metrics``'s (probe forces, friction energy and its
concentration, whether the jam released, the budget's residual): ``metrics`` defines them,
this module runs the worlds they are computed from.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..engine.options import Options, options_of
from ..errors import Interrupted, RunFileError, TaichiIceError, UsageError
from ..limits import check_size
from ..run.simulation import RunResult
from ..scene.parse import reseeded
from .metrics import METRICS, run_metrics


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
    options: Options | None = None,
    window: float = 1.0,
    progress: bool = False,
    checkpoint_every: float | None = None,
    resume: bool = False,
    worlds=None,
    **changes,
) -> EnsembleResult:
    """Run ``scene`` reseeded with every seed, all seeds as worlds of one Simulation.

    Args:
        scene: the Scene (its own seed is one layout like any other).
        seeds: field-jitter seeds, one world each.
        friction: law replacing the scene's (a Coulomb or RateState); None keeps it.
        until: end time (s); default the scene's duration.
        out: a folder (files ``seed-XXXX.h5`` in it), one path per seed, or None (no files).
        options, **changes: the engine's settings, as for ``Simulation``
            (``engine.options.Options``; ``arch="gpu"`` and the like for short).
        window: the concentration window (s).
        progress: progress bar on stderr.
        checkpoint_every, resume: as for ``Simulation.run`` (they need ``out``): one
            checkpoint holds every world of the batch, beside the first world's file.
        worlds: what makes the World, as for ``Simulation`` (``pool.WorldPool``: a World
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
        "fewer seeds (taichi_ice.experiments.sweep.run runs many seeds in batches)",
    )
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds repeat: {seeds}")
    if friction is not None:
        scene = scene.with_friction(friction)
    if isinstance(out, (str, Path)):
        out = seed_paths(out, seeds)
    return run_worlds(
        [reseeded(scene, s) for s in seeds],
        label=scene.friction.label,
        until=until,
        out=out,
        options=options_of(options, changes),
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
    options: Options | None = None,
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
    from ..run.simulation import Simulation

    scenes = list(scenes)
    sim = Simulation(scenes, options=options, worlds=worlds)
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
    from ..run.runfile_read import read_run

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
    (``run_ensemble``); its World comes from this process's ``pool.POOL``, so the batches of
    one layout (laws of one kind, a resumed batch) compile the kernels once.
    """
    from ..engine.pool import POOL
    from ..run import checkpoint

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

    Resumable (``taichi_ice.experiments.ledger``): ``out/ensemble-state.json`` records the options
    and the laws finished. ``resume`` reads the laws finished back from their files, continues the
    interrupted one from its checkpoint (``checkpoint_every``: wall-clock seconds between
    checkpoints of a law's batch, None for none) and runs the rest: every file equals that of an
    ensemble never stopped (but the wall times). An earlier ensemble's output is refused unless
    ``resume`` or ``overwrite``.
    """
    import csv
    import json
    import sys

    from ..run.output import check_folder
    from ..run.plots import plot_spread
    from ..scene.parse import load_scenario
    from .ledger import Ledger, scene_digest

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
