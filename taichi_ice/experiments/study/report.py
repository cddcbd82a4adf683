"""The study's run and report: ``run_study`` (the sweep, then study.json, study.md and the
figures), ``study.report`` and ``study_markdown``, and the three figures.

The statistics and the claims they test are ``study``'s; the command line ``commands.study``'s.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from .stats import (
    AREA_FRACTIONS,
    BOOTSTRAP_RESAMPLES,
    BOOTSTRAP_SEED,
    CONFIDENCE,
    DEFAULT_LAYOUTS,
    JAM_FORCE,
    METRIC_ROWS,
    MODELS,
    RATE_STATE_ROLES,
    bootstrap_ci,
    carriers,
    claims,
    effective_mu,
    pooled,
    study_sweep,
    study_table,
    summarise,
)


def run_study(
    out,
    layouts: int = DEFAULT_LAYOUTS,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    until: float | None = None,
    arch: str = "cpu",
    precision: str = "f64",
    progress: bool = True,
) -> dict:
    """Run (or resume) the study into ``out`` and write its summary and figures.

    Returns:
        study.json's content.
    """
    from ..sweep.run import run_sweep

    out = Path(out)
    start = time.perf_counter()
    sweep = study_sweep(layouts, until)
    n = len(sweep.worlds())
    if progress:
        print(
            f"study: {layouts} layouts x {len(MODELS)} models x {len(AREA_FRACTIONS)} area "
            f"fractions = {n} worlds of {sweep.until:g} s",
            file=sys.stderr,
            flush=True,
        )
    result = run_sweep(
        sweep,
        out / "sweep",
        workers=workers,
        scheduler=scheduler,
        arch=arch,
        precision=precision,
        progress=progress,
    )
    log = json.loads((out / "sweep" / "sweep-log.json").read_text())
    summary = study_report(
        result.dataset(),
        out,
        scene=sweep.scene,
        layouts=layouts,
        until=sweep.until,
        runs=log,
        arch=arch,
        precision=precision,
    )
    summary["wall_time"] = time.perf_counter() - start
    (out / "study.json").write_text(json.dumps(summary, indent=1, allow_nan=True) + "\n")
    (out / "study.md").write_text(study_markdown(summary))
    if progress:
        print(
            f"study: done in {summary['wall_time']:.0f} s; wrote {out}/study.md, study.json, "
            "figures/",
            file=sys.stderr,
        )
    return summary


def per_world(table: dict) -> list[dict]:
    """Every world's values, so that a reader can recompute each verdict: its model, area
    fraction and seed, its metrics and its jam (``jam``, ``broken``, ``held``); NaN (a world
    that did not complete, or ``broken`` without a jam) written as None."""
    rows = []
    for model, cells in table.items():
        for fraction, cell in cells.items():
            names = [k for k in cell if k != "seed"]
            for i, seed in enumerate(cell["seed"]):
                row = {"model": model, "area_fraction": fraction, "seed": int(seed)}
                for k in names:
                    v = float(cell[k][i])
                    row[k] = v if math.isfinite(v) else None
                rows.append(row)
    return rows


def study_report(ds, out, *, scene, layouts, until, runs, arch, precision) -> dict:
    """The study's summary (study.json's content, but its wall time) and figures (into
    ``out/figures``) from the sweep's dataset ``ds``; ``runs`` is the sweep's log."""
    from ...physics.friction_parse import law_from_table

    out = Path(out)
    table = study_table(ds)
    claim_list = claims(table)
    speed = _pusher_speed(scene)
    summary = {
        "scene": str(scene.source),
        "layouts": layouts,
        "area_fractions": sorted(next(iter(table.values()))),
        "models": [label for label, _ in MODELS],
        "until": until,
        "arch": arch,
        "precision": precision,
        "jam_force_N": JAM_FORCE,
        "bootstrap": {
            "resamples": BOOTSTRAP_RESAMPLES,
            "confidence": CONFIDENCE,
            "seed": BOOTSTRAP_SEED,
        },
        "worlds": int(ds.sizes["world"]),
        "status": {
            s: int((ds["status"].values == s).sum()) for s in np.unique(ds["status"].values)
        },
        "runs": runs,
        "effective_mu": {
            label: effective_mu(law_from_table(t), speed)
            for label, t in MODELS
            if label in RATE_STATE_ROLES
        },
        "pusher_speed": speed,
        "summary": summarise(table),
        "claims": claim_list,
        "carriers": carriers(claim_list),
        "per_world": per_world(table),
    }
    figures = out / "figures"
    figures.mkdir(parents=True, exist_ok=True)
    plot_distributions(table, figures / "study_distributions.png")
    plot_jam_vs_mu(table, summary["effective_mu"], figures / "study_jam_vs_mu.png")
    plot_phase_map(table, figures / "study_phase_map.png")
    return summary


def _pusher_speed(scene) -> float:
    speeds = [float(np.hypot(*b.velocity)) for b in scene.bodies if b.kind == "kinematic"]
    return max(speeds) if speeds else math.nan


# --------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------


def _ci(e: dict, scale: float = 1.0, fmt: str = ".3g") -> str:
    if not e.get("n"):
        return "-"
    v, (lo, hi) = e["value"], e["ci"]
    return f"{v * scale:{fmt}} [{lo * scale:{fmt}}, {hi * scale:{fmt}}]"


def _where(run: dict) -> str:
    if run.get("scheduler"):
        return f"{run['workers']} workers at {run['scheduler']}"
    return f"{run['workers']} local workers" if run["workers"] else "one process"


def study_markdown(s: dict) -> str:
    """study.md: the tables of study.json, for people."""
    runs = s["runs"]
    ran = sum(r["world_steps"] for r in runs)
    wall = sum(r["wall_time"] for r in runs)
    lines = [
        "# The study: jams at a pillar over layouts, friction models and area fractions",
        "",
        f"Scene `{Path(s['scene']).name}`, {s['layouts']} layouts x {len(s['models'])} models x "
        f"{len(s['area_fractions'])} area fractions "
        f"({', '.join(f'{f:g}' for f in s['area_fractions'])}) "
        f"= {s['worlds']} worlds of {s['until']:g} s, {s['arch']}/{s['precision']}; "
        f"status: {', '.join(f'{k} {v}' for k, v in s['status'].items())}. "
        f"Sweep: {wall:.0f} s of wall time over {len(runs)} invocation(s), "
        f"{ran / max(wall, 1e-9):.0f} world-steps/s "
        f"({', '.join(_where(r) for r in runs)}); the study "
        f"{s['wall_time']:.0f} s in all.",
        "",
        f"A jam: peak pillar force above {s['jam_force_N'] / 1e3:g} kN. Broken: the force over "
        "the last second below a tenth of its peak. Values: mean [95 % percentile bootstrap "
        f"CI, {s['bootstrap']['resamples']} resamples] over every layout and area fraction.",
        "",
        "| model | " + " | ".join(label for _, label, _ in METRIC_ROWS) + " |",
        "|---|" + "---:|" * len(METRIC_ROWS),
    ]
    scale = {"N": (1e-3, " kN"), "J": (1e-3, " kJ"), "1": (1.0, "")}
    for model, entry in s["summary"].items():
        cells = []
        for name, _, unit in METRIC_ROWS:
            k, suffix = scale[unit]
            cells.append(_ci(entry["pooled"][name], k) + suffix)
        lines.append(f"| {model} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "P(jam) by area fraction (the phase map):",
        "",
        "| model | " + " | ".join(f"{f:g}" for f in s["area_fractions"]) + " |",
        "|---|" + "---:|" * len(s["area_fractions"]),
    ]
    for model, entry in s["summary"].items():
        cells = [
            _ci(entry["by_fraction"][f"{f:g}"]["jam"], 1.0, ".2f") for f in s["area_fractions"]
        ]
        lines.append(f"| {model} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "## The paper's claims, tested",
        "",
        "Each claim as a statement on the runs, its effect size with a 95 % CI and the number "
        "of layouts (or pairs: the same layout and area fraction under two models). Holds: "
        "the CI excludes no effect on the claimed side; contradicted: on the other side.",
        "",
        "| claim | statement | effect [95 % CI] | n | verdict |",
        "|---|---|---:|---:|---|",
    ]
    for c in s["claims"]:
        lo, hi = c["ci"]
        lines.append(
            f"| {c['claim']} | {c['statement']} | {c['effect']:+.3f} [{lo:+.3f}, {hi:+.3f}] "
            f"| {c['n']} | {c['verdict']} |"
        )
    lines += ["", "## Rate, memory or both", ""]
    lines += [
        "| claim | rate-state | steady-state (rate only) | memory-only | carried by |",
        "|---|---|---|---|---|",
    ]
    for c in s["carriers"]:
        v = c["verdicts"]
        lines.append(
            f"| {c['claim']} | {v['rate-state']} | {v['steady-state']} | {v['memory-only']} "
            f"| {c['carried_by']} |"
        )
    lines += [
        "",
        "Effective mu (steady-state friction at the pusher's speed, "
        f"{s['pusher_speed']:g} m/s): "
        + ", ".join(f"{k} {v:.3f}" for k, v in s["effective_mu"].items())
        + ".",
    ]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------


def plot_distributions(table: dict, path: Path) -> Path:
    """Peak force, frictional energy and its concentration per model (every layout and
    area fraction): ``plots.plot_spread``."""
    from ...run.plots import plot_spread
    from ..ensemble import EnsembleResult
    from ..models import MODEL_COLOURS, MODEL_TITLES

    results = {}
    for label, cells in table.items():
        names = ("peak_force", "friction_energy", "concentration")
        cols = {n: pooled(cells, n) for n in names}
        k = len(cols["peak_force"])
        results[label] = EnsembleResult(
            series=[],
            label=label,
            seeds=list(range(k)),
            metrics=[{n: float(cols[n][i]) for n in names} for i in range(k)],
        )
    colours = {**MODEL_COLOURS, "mu0.3": "C9", "mu0.7": "C6"}
    return plot_spread(results, path, titles=MODEL_TITLES, colours=colours)


def plot_jam_vs_mu(table: dict, eff_mu: dict, path: Path) -> Path:
    """P(jam) and P(jam held at the end) against mu; the rate-and-state variants at their
    effective mu; 95 % bootstrap CIs as bars."""
    from ...run.plots import pyplot, save_figure

    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    coulomb = [(label, float(label[2:])) for label, _ in MODELS if label.startswith("mu")]
    markers = {"rate-state": "*", "steady-state": "s", "memory-only": "D"}
    fractions = sorted(next(iter(table.values())))
    for ax, name, title in zip(
        axes, ("jam", "held"), ("a jam forms", "a jam still holds at the end")
    ):
        for k, f in enumerate([*fractions, None]):
            if f is None:
                pick = lambda c, name=name: pooled(c, name)  # noqa: E731
            else:
                pick = lambda c, f=f, name=name: c[f][name]  # noqa: E731
            colour = f"C{k}" if f is not None else "k"
            est = [bootstrap_ci(pick(table[label])) for label, _ in coulomb]
            mus = [mu for _, mu in coulomb]
            y = np.array([e[0] for e in est])
            err = np.array([[e[0] - e[1] for e in est], [e[2] - e[0] for e in est]])
            ax.errorbar(
                mus,
                y,
                yerr=err,
                color=colour,
                marker="o",
                capsize=3,
                lw=2 if f is None else 1,
                alpha=1 if f is None else 0.6,
                label="all area fractions" if f is None else f"area fraction {f:g}",
            )
            for model, mark in markers.items():
                e = bootstrap_ci(pick(table[model]))
                ax.errorbar(
                    [eff_mu[model]],
                    [e[0]],
                    yerr=[[e[0] - e[1]], [e[2] - e[0]]],
                    color=colour,
                    marker=mark,
                    ms=10 if f is None else 6,
                    ls="none",
                    capsize=3,
                    alpha=1 if f is None else 0.6,
                    label=f"{model} (at its effective mu)" if f is None else None,
                )
        ax.set_xlabel("mu (rate-and-state variants: steady-state mu at the pusher's speed)")
        ax.set_title(f"P({title})", fontsize=10)
        ax.set_ylim(-0.05, 1.05)
    axes[0].set_ylabel("probability over layouts (95 % CI)")
    axes[1].legend(fontsize=7, loc="best")
    return save_figure(fig, path)


def plot_phase_map(table: dict, path: Path) -> Path:
    """P(jam) for each model (rows) and area fraction (columns), with the layouts counted."""
    from ...run.plots import pyplot, save_figure

    plt = pyplot()
    models = list(table)
    fractions = sorted(next(iter(table.values())))
    p = np.array([[np.nanmean(table[m][f]["jam"]) for f in fractions] for m in models])
    n = np.array([[np.isfinite(table[m][f]["jam"]).sum() for f in fractions] for m in models])
    fig, ax = plt.subplots(figsize=(6, 5))
    im = ax.imshow(p, vmin=0, vmax=1, cmap="viridis", aspect="auto")
    for i in range(len(models)):
        for j in range(len(fractions)):
            ax.text(
                j,
                i,
                f"{p[i, j]:.2f}\n(n={n[i, j]})",
                ha="center",
                va="center",
                fontsize=8,
                color="w" if p[i, j] < 0.6 else "k",
            )
    ax.set_xticks(range(len(fractions)), [f"{f:g}" for f in fractions])
    ax.set_yticks(range(len(models)), models)
    ax.set_xlabel("area fraction of the rubble field")
    ax.set_title(f"P(jam: peak pillar force > {JAM_FORCE / 1e3:g} kN)", fontsize=10)
    fig.colorbar(im, ax=ax, label="probability over layouts")
    return save_figure(fig, path)
