"""The paper's experiment from one command: ``taichi-ice paper --out DIR``.

Rubble pushed past a pillar (``scenarios/pillar.toml``) with constant friction mu = 0.1,
0.5, 0.9 and with rate-and-state friction, as in Figures 4-6 of Lishman, Sammonds &
Feltham; and, what one run cannot show, the same four models over ``seeds`` other jittered
layouts. Each model is one Simulation whose worlds are the scene's own layout (the "single
run" the paper's figures show) and the reseeded ones.

Writes into DIR:

- ``runs/mu0.1.h5``, ``mu0.5.h5``, ``mu0.9.h5``, ``rate-state.h5``: the single runs;
  ``runs/spread/<model>/seed-XXXX.h5``: the other layouts.
- ``figures/``: ``fig3_single_interface.png`` (the friction law against its exact
  solution), ``fig4_positions.png``, ``fig5_pillar_force.png``, ``fig6_friction_energy.png``,
  ``energy_budget.png``, ``fig_spread.png``.
- ``summary.json`` and ``summary.md``: per model the single run's metrics (see
  ``taichi_ice.experiments.ensemble``), the distribution over layouts, and whether the paper's
  findings hold across layouts.
- ``paper-state.json``: the options and the parts finished (``taichi_ice.experiments.ledger``),
  so that ``taichi-ice paper --out DIR --resume`` continues a reproduction that was stopped:
  Figure 3 and the models finished are read back, the model that was running continues from its
  checkpoint (``RUN.h5.ckpt`` beside its first run file, every ``CHECKPOINT_EVERY`` of wall
  clock), the rest run.

The run lives here; summary.json and summary.md are ``paper_summary``'s, the figures
``paper_figures``', the models and what the paper says of them ``models``'.
"""

from __future__ import annotations

import functools
import json
import sys
import time
from pathlib import Path

from ...run.plots import plot_spread
from ..ensemble import EnsembleResult, run_ensemble
from ..models import DEFAULT_SCENE, MODEL_COLOURS, MODEL_TITLES, models, variants
from .figures import plot_energy_budget, plot_friction_energy, plot_pillar_force, plot_positions
from .summary import build_summary, summary_markdown

# Ice strengths (Pa) of the extra single runs under rate-and-state (the paper gives none).
STRENGTHS = (1e6, 3e6)

# Wall-clock seconds between checkpoints of a model's batch (``--checkpoint-every``): a kill
# loses at most this much of the model it stops.
CHECKPOINT_EVERY = 120.0


def reproduce(
    out: str | Path,
    seeds: int = 16,
    scene_path: str | Path = DEFAULT_SCENE,
    until: float | None = None,
    arch: str = "cpu",
    precision: str = "f64",
    progress: bool = True,
    quick: bool = False,
    extras: bool = True,
    *,
    resume: bool = False,
    overwrite: bool = False,
    checkpoint_every: float | None = CHECKPOINT_EVERY,
) -> dict:
    """Run the whole reproduction into ``out``; returns the summary written to summary.json.

    Args:
        out: output folder.
        seeds: layouts besides the scene's own, per model (0: the single runs only).
        scene_path: the scene (default ``scenarios/pillar.toml``).
        until: end time (s); default the scene's duration (20 s).
        arch, precision: as for ``Simulation``.
        progress: progress bars and a line per model on stderr.
        quick: small sizes for Figure 3 (tests).
        extras: also run the ``variants`` over the same layouts and rate-and-state with an
            ice strength of each of ``STRENGTHS`` (the scene's own layout).
        resume: continue an earlier reproduction in ``out`` that was stopped: Figure 3 and
            the models it finished are read back, the model it was running continues from
            its checkpoint, the rest run (``taichi_ice.experiments.ledger``; the options must be the
            same). Without it, an earlier reproduction's output is refused unless
            ``overwrite``.
        checkpoint_every: wall-clock seconds between checkpoints of a model's Simulation
            (default ``CHECKPOINT_EVERY``); None for none (a resume then reruns the model
            that was stopped from its start).
    """
    from ...run.output import check_folder
    from ...scene.parse import load_scenario
    from ..ledger import Ledger, scene_digest

    if seeds < 0:
        raise ValueError(f"--seeds {seeds}: must be 0 or more")
    out = check_folder(out)  # before any work
    runs, figures = out / "runs", out / "figures"
    start = time.perf_counter()
    scene = load_scenario(scene_path)
    until = scene.simulation.duration if until is None else float(until)
    options = {
        "scene": scene_digest(scene),
        "seeds": seeds,
        "until": until,
        "arch": arch,
        "precision": precision,
        "quick": quick,
        "extras": extras,
    }
    reports = [out / "summary.json", out / "summary.md"]
    with Ledger(
        out,
        "paper",
        options,
        resume=resume,
        overwrite=overwrite,
        outputs=[*reports, runs, figures],
        checkpoint_every=checkpoint_every,
    ) as ledger:
        # Wall time of the parts an earlier, stopped reproduction finished: the summary's
        # wall time is the whole reproduction's, not this process's.
        done = [ledger.done(part) for part in ledger.parts]
        earlier = sum(float(d.get("wall_time", 0.0)) for d in done if d)
        if not resume:
            for path in reports:  # an earlier reproduction's: a summary says it finished
                path.unlink(missing_ok=True)
        figures.mkdir(parents=True, exist_ok=True)
        results = _reproduce(
            ledger, scene, runs, figures, seeds, until, arch, precision, progress, quick, extras
        )

        _say(progress, "paper: figures")
        paper_models = {label: results[label] for label, _ in models()}
        files = {label: ens.paths[0] for label, ens in paper_models.items()}
        plot_positions(files, figures / "fig4_positions.png")
        plot_pillar_force(paper_models, figures / "fig5_pillar_force.png")
        plot_friction_energy(results, figures / "fig6_friction_energy.png")
        plot_energy_budget(paper_models, figures / "energy_budget.png")
        if seeds:
            plot_spread(
                {k: e for k, e in results.items() if len(e.seeds) > 1},
                figures / "fig_spread.png",
                single=True,
                titles=MODEL_TITLES,
                colours=MODEL_COLOURS,
            )

        summary = build_summary(results, scene, until, arch, precision, seeds)
        summary["wall_time"] = time.perf_counter() - start + earlier
        (out / "summary.json").write_text(json.dumps(summary, indent=2, allow_nan=True) + "\n")
        (out / "summary.md").write_text(summary_markdown(summary))
    _say(progress, f"paper: done in {summary['wall_time']:.0f} s; results in {out}/")
    return summary


def _reproduce(
    ledger, scene, runs, figures, seeds, until, arch, precision, progress, quick, extras
) -> dict[str, EnsembleResult]:
    """The parts of ``reproduce``: Figure 3 and a batch per model, each skipped when the
    ledger says it finished (``ensemble.run_part``)."""
    from ..ensemble import run_part
    from ..validation import single_interface

    if ledger.done("fig3"):
        _say(progress, "paper: Figure 3: finished earlier")
    else:
        _say(
            progress,
            "paper: Figure 3, the friction law on one interface against its exact solution",
        )
        t0 = time.perf_counter()
        ledger.start("fig3")
        single_interface.run(figures, quick=quick)
        ledger.finish("fig3", wall_time=time.perf_counter() - t0)

    base = scene.simulation.seed
    layout_seeds = [base] + [base + k for k in range(1, seeds + 1)]
    batches = [
        (
            label,
            scene,
            law,
            layout_seeds,
            [runs / f"{label}.h5"]
            + [runs / "spread" / label / f"seed-{s:04d}.h5" for s in layout_seeds[1:]],
        )
        for label, law in models() + (variants() if extras else [])
    ]
    if extras:
        from ...physics.friction import RateState
        from ...scene.parse import scene_from_dict

        for strength in STRENGTHS:
            label = f"rate-state_strength{strength / 1e6:g}MPa"
            raw = dict(scene.raw)
            raw["ice"] = {**raw.get("ice", {}), "crushing_strength": strength}
            strong = scene_from_dict(raw, source=scene.source)
            batches.append((label, strong, RateState(), [base], [runs / f"{label}.h5"]))

    results: dict[str, EnsembleResult] = {}
    for label, batch_scene, law, batch_seeds, paths in batches:
        finished = ledger.done(label) is not None
        _say(
            progress,
            f"paper: {label}: {len(batch_seeds)} layout(s) x {batch_scene.n_bodies} bodies, "
            f"{until:g} s, {arch}/{precision}"
            + (": finished earlier, read back" if finished else ""),
        )

        run = functools.partial(
            run_ensemble,
            batch_scene,
            batch_seeds,
            law,
            until=until,
            out=paths,
            arch=arch,
            precision=precision,
            progress=progress,
        )
        ens = run_part(ledger, label, paths, run, label=law.label, seeds=batch_seeds)
        results[label] = ens
        m = ens.metrics[0]
        _say(
            progress,
            f"paper: {label}: {ens.status} in {ens.wall_time:.0f} s; single run: peak "
            f"{m['peak_force'] / 1e3:.3g} kN, friction {m['friction_energy']:.4g} J, "
            f"budget residual {100 * m['residual_rel']:.2g} %"
            + (f"; FAILED: {ens.failure}" if ens.status != "complete" else ""),
        )
    return results


def _say(enabled: bool, text: str) -> None:
    if enabled:
        print(text, file=sys.stderr, flush=True)
