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
  ``taichi_ice.ensemble``), the distribution over layouts, and whether the paper's
  findings hold across layouts.
- ``paper-state.json``: the options and the parts finished (``taichi_ice.ledger``), so that
  ``taichi-ice paper --out DIR --resume`` continues a reproduction that was stopped: Figure 3
  and the models finished are read back, the model that was running continues from its
  checkpoint (``RUN.h5.ckpt`` beside its first run file, every ``CHECKPOINT_EVERY`` of wall
  clock), the rest run.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import sys
import time
from importlib import resources
from pathlib import Path

import numpy as np

from .ensemble import EnsembleResult, probe_force_magnitude, run_ensemble
from .plots import plot_spread

# The bundled scene (package data), so that the command works from an installed wheel.
DEFAULT_SCENE = resources.files("taichi_ice").joinpath("scenarios").joinpath("pillar.toml")

MODEL_COLOURS = {
    "mu0.1": "C0",
    "mu0.5": "C1",
    "mu0.9": "C3",
    "rate-state": "C2",
    "rate-state_healing": "C4",
    "steady-state": "C7",
    "memory-only": "C5",
    "rate-state_strength1MPa": "C8",
    "rate-state_strength3MPa": "C9",
}
MODEL_TITLES = {
    "mu0.1": r"$\mu$ = 0.1",
    "mu0.5": r"$\mu$ = 0.5",
    "mu0.9": r"$\mu$ = 0.9",
    "rate-state": "rate and state",
    "rate-state_healing": "rate and state, healing below V*",
    "steady-state": "steady-state law (rate, no memory)",
    "memory-only": "memory only (B = A)",
    "rate-state_strength1MPa": "rate and state, ice strength 1 MPa",
    "rate-state_strength3MPa": "rate and state, ice strength 3 MPa",
}
# Ice strengths (Pa) of the extra single runs under rate-and-state (the paper gives none).
STRENGTHS = (1e6, 3e6)

# What the paper says of each model (its section "Variable friction within a simple DEM").
PAPER_FINDINGS = {
    "mu0.1": "blocks slide easily past the pillar; forces never higher than 1 kN",
    "mu0.5": "jams form and break; energy loss concentrated in two events (~14 s and ~19 s)",
    "mu0.9": "the blocks jam, the jam is never broken; force and energy loss rise dramatically",
    "rate-state": "jams form and break; frictional loss rises more steadily than for mu = 0.5",
}

SNAPSHOT_EVERY = 4.0  # s between the bird's-eye views of Figure 4, as in the paper

# Wall-clock seconds between checkpoints of a model's batch (``--checkpoint-every``): a kill
# loses at most this much of the model it stops.
CHECKPOINT_EVERY = 120.0


def models():
    """The paper's four friction models, ``(label, law)`` in its order."""
    from .friction import Coulomb, RateState

    return [
        ("mu0.1", Coulomb(0.1)),
        ("mu0.5", Coulomb(0.5)),
        ("mu0.9", Coulomb(0.9)),
        ("rate-state", RateState()),
    ]


def variants():
    """The choices that separate rate from memory, run over the same layouts as the paper's
    models: the law with today's earlier rule below V* (healing), the steady-state law and
    memory only. ``(label, law)``."""
    from .friction import MemoryOnly, RateState, SteadyState

    return [
        ("rate-state_healing", RateState(below_v_star="healing")),
        ("steady-state", SteadyState()),
        ("memory-only", MemoryOnly()),
    ]


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
            its checkpoint, the rest run (``taichi_ice.ledger``; the options must be the
            same). Without it, an earlier reproduction's output is refused unless
            ``overwrite``.
        checkpoint_every: wall-clock seconds between checkpoints of a model's Simulation
            (default ``CHECKPOINT_EVERY``); None for none (a resume then reruns the model
            that was stopped from its start).
    """
    from .io import check_folder
    from .ledger import Ledger, scene_digest
    from .scenario import load_scenario

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
    from .ensemble import run_part
    from .studies import single_interface

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
        from .friction import RateState
        from .scenario import scene_from_dict

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


# --------------------------------------------------------------------------------------------
# Summary
# --------------------------------------------------------------------------------------------


def build_summary(results: dict[str, EnsembleResult], scene, until, arch, precision, seeds):
    """summary.json's content: the single runs, the spread and the findings across seeds."""
    out = {
        "scene": str(scene.source),
        "duration": until,
        "arch": arch,
        "precision": precision,
        "n_bodies": scene.n_bodies,
        "seeds": seeds,
        "models": {},
    }
    for label, ens in results.items():
        single = dict(ens.metrics[0])
        single.update(
            seed=ens.seeds[0],
            file=str(ens.paths[0]),
            steps=ens.steps,
            dt=ens.dt,
            # One Simulation steps every layout together: the batch's wall time.
            wall_time=ens.wall_time,
            status=ens.status,
            failure=ens.failure,
        )
        entry = {"paper": PAPER_FINDINGS.get(label, ""), "single": single}
        if seeds and len(ens.seeds) > 1:
            spread = dataclasses.replace(
                ens, seeds=ens.seeds[1:], series=ens.series[1:], metrics=ens.metrics[1:]
            )
            entry["spread"] = spread.summary()
            entry["seeds"] = {
                name: spread.values(name).tolist()
                for name in ("peak_force", "friction_energy", "concentration", "residual_rel")
            }
            entry["seed_list"] = spread.seeds
        out["models"][label] = entry
    if seeds:
        out["findings"] = findings(results)
        # Which findings survive which choice: each variant in the role of rate-and-state.
        out["findings_by_choice"] = {
            label: findings(results, rs=label)
            for label, ens in results.items()
            if label not in ("mu0.1", "mu0.5", "mu0.9") and len(ens.seeds) > 1
        }
    return out


def findings(results: dict[str, EnsembleResult], rs: str = "rate-state") -> list[dict]:
    """The paper's claims tested seed by seed (the same layouts run under every model), with
    the model labelled ``rs`` (a variant's label) in the role of rate-and-state."""
    if rs != "rate-state":
        results = {k: e for k, e in results.items() if k != "rate-state"}
        if rs in results:
            results["rate-state"] = results[rs]

    def v(label, name):
        return results[label].values(name)[1:] if label in results else np.array([])

    claims = []

    def add(claim, measure, passed: np.ndarray, details: dict, unit: str = "layouts"):
        n = int(passed.size)
        k = int(np.count_nonzero(passed))
        claims.append(
            {
                "claim": claim,
                "measure": measure,
                "holds_in": k,
                "of": n,
                "unit": unit,
                "holds": bool(n and k > n / 2),
                **details,
            }
        )

    if "mu0.1" in results:
        peak = v("mu0.1", "peak_force")
        add(
            "mu = 0.1: pillar force stays below about 1 kN",
            "peak pillar force < 1 kN",
            peak < 1e3,
            {"median_peak_kN": _median(peak) / 1e3},
        )
    if {"mu0.9", "mu0.5", "mu0.1"} <= results.keys():
        p1, p5, p9 = v("mu0.1", "peak_force"), v("mu0.5", "peak_force"), v("mu0.9", "peak_force")
        add(
            "mu = 0.9 jams: the force rises far above the lower frictions'",
            "peak pillar force: mu 0.9 > mu 0.5 > mu 0.1, same layout",
            (p9 > p5) & (p5 > p1),
            {
                "median_peak_kN": {
                    k: _median(x) / 1e3 for k, x in zip(("mu0.1", "mu0.5", "mu0.9"), (p1, p5, p9))
                }
            },
        )
    if {"rate-state", "mu0.9"} <= results.keys():
        rs, p9 = v("rate-state", "peak_force"), v("mu0.9", "peak_force")
        add(
            "rate-and-state releases jams more easily than constant friction at its "
            "low-speed level (mu = 0.9)",
            "peak pillar force: rate-state < mu 0.9, same layout",
            rs < p9,
            {"median_peak_kN": {"rate-state": _median(rs) / 1e3, "mu0.9": _median(p9) / 1e3}},
        )
    if {"rate-state", "mu0.5", "mu0.9"} <= results.keys():
        released = {k: v(k, "released") for k in ("mu0.5", "mu0.9", "rate-state")}
        counts = {k: int(np.nansum(x)) for k, x in released.items()}
        add(
            "rate-and-state releases jams more easily than constant mu = 0.5 and 0.9",
            "the largest jam has broken by the end (force over the last second below a tenth "
            "of its peak): rate-state released, the constant-friction run of the same layout "
            "not, counted over both constant frictions",
            np.concatenate(
                [
                    (released["rate-state"] > released[k])[released["rate-state"] != released[k]]
                    for k in ("mu0.5", "mu0.9")
                ]
            ),
            {"released_in": counts},
            unit="layouts where the two differ",
        )
    if {"rate-state", "mu0.5"} <= results.keys():
        rs, c5 = v("rate-state", "concentration"), v("mu0.5", "concentration")
        add(
            "rate-and-state dissipates more steadily than mu = 0.5 (less in single events)",
            "largest share of the total frictional energy lost in any 1 s: rate-state < mu 0.5, "
            "same layout",
            rs < c5,
            {"median_concentration": {"rate-state": _median(rs), "mu0.5": _median(c5)}},
        )
    return claims


def _median(x: np.ndarray) -> float:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(np.median(x)) if x.size else math.nan


def summary_markdown(summary: dict) -> str:
    """summary.md: the tables of summary.json, for people."""
    lines = [
        "# Rubble pushed past a pillar: four friction models",
        "",
        f"Scene `{summary['scene']}`, {summary['n_bodies']} bodies, {summary['duration']:g} s, "
        f"{summary['arch']}/{summary['precision']}; whole reproduction "
        f"{summary.get('wall_time', math.nan):.0f} s of wall time.",
        "",
        "## The single runs (the scene's own layout)",
        "",
        "| model | peak force (kN) | mean force (kN) | friction energy (J) | crushing energy (J) "
        "| largest 1-s share | budget residual | steps | dt (s) | wall time (s) | status |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for label, entry in summary["models"].items():
        s = entry["single"]
        lines.append(
            f"| {label} | {s['peak_force'] / 1e3:.3g} | {s['mean_force'] / 1e3:.3g} | "
            f"{s['friction_energy']:.4g} | {s.get('crushing_energy', 0.0):.4g} | "
            f"{s['concentration']:.2f} | "
            f"{s['residual']:.3g} J ({100 * s['residual_rel']:.2g} %) | {s['steps']} | "
            f"{s['dt']:.3g} | {s['wall_time']:.0f} | {s['status']} |"
        )
    lines += [
        "",
        "The wall time of a model is that of its one Simulation, which steps the single run "
        "and every other layout together.",
    ]
    if summary.get("seeds"):
        lines += [
            "",
            f"## Over {summary['seeds']} other layouts (median [quartiles])",
            "",
            "| model | peak force (kN) | friction energy (J) | largest 1-s share "
            "| worst budget residual |",
            "|---|---:|---:|---:|---:|",
        ]
        for label, entry in summary["models"].items():
            sp = entry.get("spread")
            if not sp:
                continue
            worst = max((abs(x) for x in entry["seeds"]["residual_rel"]), default=math.nan)
            lines.append(
                f"| {label} | {_q(sp['peak_force'], 1e-3)} | {_q(sp['friction_energy'])} | "
                f"{_q(sp['concentration'])} | {100 * worst:.2g} % |"
            )
        lines += ["", "## The paper's findings, layout by layout", ""]
        for f in summary["findings"]:
            verdict = "holds" if f["holds"] else "does not hold"
            extra = ""
            if "released_in" in f:
                counts = ", ".join(f"{k} {v}" for k, v in f["released_in"].items())
                extra = f" Released by the end, of {summary['seeds']} layouts: {counts}."
            lines.append(
                f"- **{f['claim']}** ({f['measure']}): {verdict} in {f['holds_in']} of "
                f"{f['of']} {f['unit']}.{extra}"
            )
    by_choice = summary.get("findings_by_choice") or {}
    if by_choice:
        choices = list(by_choice)
        lines += [
            "",
            "## Which findings survive which choice",
            "",
            "Each rate-and-state claim with the model of the column in the role of "
            "rate-and-state: layouts (or pairs) where it holds, of those compared.",
            "",
            "| claim | " + " | ".join(choices) + " |",
            "|---|" + "---:|" * len(choices),
        ]
        claims = [f["claim"] for f in by_choice[choices[0]] if "rate-and-state" in f["claim"]]
        for claim in claims:
            cells = []
            for c in choices:
                f = next((f for f in by_choice[c] if f["claim"] == claim), None)
                cells.append(f"{f['holds_in']}/{f['of']}" if f else "-")
            lines.append(f"| {claim} | " + " | ".join(cells) + " |")
    lines += ["", "## What the paper reports", ""]
    for label, entry in summary["models"].items():
        if entry["paper"]:
            lines.append(f"- {label}: {entry['paper']}")
    return "\n".join(lines) + "\n"


def _q(stats: dict, scale: float = 1.0) -> str:
    if not stats.get("n"):
        return "-"
    return f"{stats['median'] * scale:.3g} [{stats['q1'] * scale:.3g}, {stats['q3'] * scale:.3g}]"


# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------


def plot_positions(files: dict[str, Path], path: Path, every: float = SNAPSHOT_EVERY) -> Path:
    """Figure 4: bird's-eye views every ``every`` seconds, one row per model."""
    from .io import read_run
    from .plots import _pyplot, _save, draw_bodies, outlines

    plt = _pyplot()
    runs = {label: read_run(p) for label, p in files.items()}
    first = next(iter(runs.values()))
    t_end = min(r["frames"]["time"][-1] for r in runs.values())
    times = np.arange(0.0, t_end + 1e-9, every)
    # One view for every panel: the channel from below the pusher to a little past the
    # highest block shown (the walls run much further).
    kinds = first["bodies"]["kinds"]
    fixed = [p for k, p in zip(kinds, outlines(first, 0)) if k == "fixed"]
    left = min(p[:, 0].min() for p in fixed)
    right = max(p[:, 0].max() for p in fixed)
    # The view's top follows most of the rubble (95 % of the blocks), not a block thrown far
    # downstream, and never passes the walls' ends.
    top, bottom = -math.inf, math.inf
    for r in runs.values():
        for t in times:
            f = int(np.argmin(np.abs(r["frames"]["time"] - t)))
            moving = [p for k, p in zip(kinds, outlines(r, f)) if k != "fixed"]
            top = max(top, float(np.percentile([p[:, 1].max() for p in moving], 95)))
            bottom = min(bottom, min(p[:, 1].min() for p in moving))
    top = min(top + 0.5, max(p[:, 1].max() for p in fixed))
    view = (left, right, bottom - 0.2, top)
    fig, axes = plt.subplots(
        len(runs),
        len(times),
        figsize=(
            1.3 * len(times) + 0.6,
            0.25 + 1.25 * len(runs) * (view[3] - view[2]) / (right - left),
        ),
        squeeze=False,
    )
    for row, (label, r) in enumerate(runs.items()):
        for col, t in enumerate(times):
            ax = axes[row, col]
            f = int(np.argmin(np.abs(r["frames"]["time"] - t)))
            draw_bodies(ax, r, f, view=view)
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0:
                ax.set_title(f"t = {r['frames']['time'][f]:.0f} s", fontsize=9)
            if col == 0:
                ax.set_ylabel(MODEL_TITLES.get(label, label), fontsize=9)
    fig.suptitle(
        "Block positions every 4 s (walls and pillar fixed, grey; pusher orange)", fontsize=9
    )
    return _save(fig, path)


def plot_pillar_force(results: dict[str, EnsembleResult], path: Path) -> Path:
    """Figure 5: magnitude of the force on the pillar against time, one panel per model."""
    from .plots import _pyplot, _save

    plt = _pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(9, 5.5), squeeze=False)
    for ax, (label, ens) in zip(axes.flat, results.items()):
        s = ens.series[0]
        ax.plot(s["time"], probe_force_magnitude(s) / 1e3, lw=0.7, color=MODEL_COLOURS.get(label))
        ax.set_title(MODEL_TITLES.get(label, label), fontsize=10)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("force on pillar (kN)")
        ax.set_xlim(0, s["time"][-1])
        ax.set_ylim(bottom=0)
    fig.suptitle("Force on the pillar (mean over each sample interval)", fontsize=10)
    return _save(fig, path)


def plot_friction_energy(results: dict[str, EnsembleResult], path: Path) -> Path:
    """Figure 6: cumulative frictional dissipation, every model on one axes (log scale).

    The single runs are the thick lines; the other layouts are the thin ones.
    """
    from .plots import _pyplot, _save

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for label, ens in results.items():
        colour = MODEL_COLOURS.get(label)
        paper_model = label in PAPER_FINDINGS
        if paper_model:  # the other layouts of the paper's models only, to stay readable
            for s in ens.series[1:]:
                ax.plot(s["time"], s["friction_energy"], lw=0.4, alpha=0.35, color=colour)
        s = ens.series[0]
        ax.plot(
            s["time"],
            s["friction_energy"],
            "-" if paper_model else "--",
            lw=2 if paper_model else 1.2,
            color=colour,
            label=MODEL_TITLES.get(label, label),
        )
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("cumulative frictional energy (J)")
    n = max(len(e.series) for e in results.values()) - 1
    ax.set_title(
        "Frictional energy dissipation" + (f" (thin: {n} other layouts)" if n else ""), fontsize=10
    )
    ax.legend(fontsize=9)
    return _save(fig, path)


def plot_energy_budget(results: dict[str, EnsembleResult], path: Path) -> Path:
    """Every term of each single run's energy budget, with the residual on its own axis."""
    from .budget import DISSIPATED, HELD, residual
    from .plots import _pyplot, _save

    plt = _pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(10, 6.5), squeeze=False)
    # What came in first, then where it went.
    terms = ("work_in", *DISSIPATED, *HELD)
    for ax, (label, ens) in zip(axes.flat, results.items()):
        s = ens.series[0]
        for name in terms:
            if name in s and (name != "crushing_energy" or np.any(s[name])):
                ax.plot(
                    s["time"], s[name], lw=1, label=name.replace("_energy", "").replace("_", " ")
                )
        ax.set_title(MODEL_TITLES.get(label, label), fontsize=10)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("energy (J)")
        ax.set_yscale("symlog", linthresh=1.0)
        twin = ax.twinx()
        twin.plot(s["time"], residual(s), "k--", lw=0.8, label="residual (right)")
        twin.set_ylabel("residual (J)", fontsize=8)
        twin.tick_params(labelsize=7)
        if ax is axes[0, 0]:
            h1, l1 = ax.get_legend_handles_labels()
            h2, l2 = twin.get_legend_handles_labels()
            ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="upper left")
    fig.suptitle(
        "Energy budget: work in = kinetic + elastic + friction + viscous + drag (+ residual)",
        fontsize=10,
    )
    return _save(fig, path)
