"""The study the paper asked for: ``taichi-ice study --out DIR``.

The paper ends: "the forces and energies calculated by the DEM are highly sensitive to
initial conditions. By running larger suites of experiments, across a wider range of
friction values, it may be possible to clarify the specific effects of incorporating rate
dependence, memory dependence, or both." This is that suite: the pillar scene
(``scenarios/pillar.toml``) over ``layouts`` jittered layouts x eight friction models
(mu = 0.1, 0.3, 0.5, 0.7, 0.9; rate-and-state; its steady-state law, rate without memory;
its memory-only variant, B = A) x the field's area fraction (``AREA_FRACTIONS``), run as one
sweep (``taichi_ice.sweep``) on Dask.

Per model (over every layout and area fraction, and per area fraction), with percentile
bootstrap confidence intervals over layouts (``bootstrap_ci``):

- the probability that a jam forms (the peak pillar force exceeds ``JAM_FORCE``) and that a
  jam breaks by the end (``ensemble.RELEASED_FRACTION``: the force over the last second has
  fallen below a tenth of its peak), and that a jam still holds at the end;
- the mean of the peak and mean pillar force, the frictional energy and its concentration
  in time (the largest share lost in any 1 s).

The paper's claims are tested as statements on paired differences (the same layout and
area fraction under two models), each with its effect size, confidence interval and the
number of pairs; a claim holds when its interval excludes no effect on the claimed side,
is contradicted when it excludes it on the other, and is undecided otherwise. Each
rate-and-state claim is tested again with the steady-state law and with memory only in
rate-and-state's place, which says whether rate, memory or both carry the effect.

Writes into DIR: ``sweep/`` (the sweep: batch files, ``sweep.nc``), ``study.json``,
``study.md`` and ``figures/``: ``study_distributions.png`` (each metric per model),
``study_jam_vs_mu.png`` (jam probability against mu, the rate-and-state variants at their
effective mu) and ``study_phase_map.png`` (jam probability against area fraction and model).
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

# The models of the study, in the order of its tables: (label, [[law]] table).
MODELS = [
    ("mu0.1", {"law": "coulomb", "mu": 0.1}),
    ("mu0.3", {"law": "coulomb", "mu": 0.3}),
    ("mu0.5", {"law": "coulomb", "mu": 0.5}),
    ("mu0.7", {"law": "coulomb", "mu": 0.7}),
    ("mu0.9", {"law": "coulomb", "mu": 0.9}),
    ("rate-state", {"law": "rate-state"}),
    ("steady-state", {"law": "steady-state"}),
    ("memory-only", {"law": "memory-only"}),
]
RATE_STATE_ROLES = {
    "rate-state": "rate and memory",
    "steady-state": "rate only",
    "memory-only": "memory only",
}
# Share of the rubble field's lattice that is ice: the scene's own 0.85 and two looser
# fields (row spacing 0.61 m and 0.68 m instead of 0.56 m; their first rows and the pusher
# start lower, so the field is compacted against the pillar later).
AREA_FRACTIONS = (0.70, 0.775, 0.85)
FIELD = "rubble"
# A jam: the pillar force exceeds ten times the paper's bound for blocks that "slide easily
# past the pillar" (mu = 0.1: "forces never higher than 1 kN").
JAM_FORCE = 10e3  # N
FREE_FORCE = 1e3  # N: the paper's "never higher than 1 kN"
# Layouts of the default study: what a 2-core machine runs in about 10 minutes (measured,
# see README: about 24 worlds x 20 s per layout).
DEFAULT_LAYOUTS = 2
BOOTSTRAP_RESAMPLES = 4000
CONFIDENCE = 0.95
BOOTSTRAP_SEED = 20130301  # the resampling is seeded: the study's numbers are reproducible


# --------------------------------------------------------------------------------------------
# Statistics
# --------------------------------------------------------------------------------------------


def bootstrap_ci(
    values,
    statistic=np.mean,
    *,
    n_resamples: int = BOOTSTRAP_RESAMPLES,
    confidence: float = CONFIDENCE,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float, float]:
    """``(estimate, low, high)``: ``statistic`` of ``values`` and its percentile bootstrap
    confidence interval (Efron & Tibshirani 1993, ch. 13): resample the values with
    replacement ``n_resamples`` times, take the statistic of each, and read the
    ``(1 - confidence) / 2`` and ``(1 + confidence) / 2`` quantiles. NaNs are dropped;
    ``(nan, nan, nan)`` when nothing is left.

    Args:
        values: ``(n,)`` one value per independent unit (a layout, or a pair of runs of it).
        statistic: reduces an ``(..., n)`` array along its last axis (``np.mean``).
    """
    x = np.asarray(values, dtype=float)
    x = x[np.isfinite(x)]
    if not x.size:
        return math.nan, math.nan, math.nan
    rng = np.random.default_rng(seed)
    resampled = x[rng.integers(0, x.size, size=(n_resamples, x.size))]
    stats = statistic(resampled, axis=-1)
    alpha = (1.0 - confidence) / 2.0
    low, high = np.quantile(stats, [alpha, 1.0 - alpha])
    return float(statistic(x)), float(low), float(high)


def _estimate(values, statistic=np.mean) -> dict:
    est, low, high = bootstrap_ci(values, statistic)
    n = int(np.isfinite(np.asarray(values, dtype=float)).sum())
    return {"value": est, "ci": [low, high], "n": n}


def verdict(low: float, high: float, direction: int) -> str:
    """'holds' if the interval lies wholly on the claimed side of 0 (``direction`` +1 or
    -1), 'contradicted' if wholly on the other, else 'undecided'."""
    if not (math.isfinite(low) and math.isfinite(high)):
        return "undecided"
    if direction * low > 0 and direction * high > 0:
        return "holds"
    if direction * low < 0 and direction * high < 0:
        return "contradicted"
    return "undecided"


# --------------------------------------------------------------------------------------------
# The sweep
# --------------------------------------------------------------------------------------------


def study_sweep(layouts: int, until: float | None = None, fractions=AREA_FRACTIONS):
    """The study as a Sweep: the pillar scene, ``layouts`` seeds, the eight models, the
    area fractions."""
    from .paper import DEFAULT_SCENE
    from .sweep import sweep_from_dict

    data = {
        "sweep": {
            "scene": str(DEFAULT_SCENE),
            "seeds": {"start": 0, "count": int(layouts)},
            "metrics": [
                "peak_force",
                "mean_force",
                "friction_energy",
                "concentration",
                "final_force",
                "released",
                "residual_rel",
            ],
        },
        "law": [table for _, table in MODELS],
        "overrides": {f"field.{FIELD}.area_fraction": list(fractions)},
    }
    if until is not None:
        data["sweep"]["until"] = float(until)
    return sweep_from_dict(data, source="<taichi-ice study>")


def effective_mu(law, speed: float) -> float:
    """The constant mu a rate-and-state variant sits at on the jam-probability axis: its
    steady-state friction at the pusher's speed (the slip rate the pusher imposes on the
    rubble it drives)."""
    return float(law.steady_state(np.array([speed]))[0])


# --------------------------------------------------------------------------------------------
# Analysis
# --------------------------------------------------------------------------------------------


def _table(ds) -> dict[str, dict[float, dict[str, np.ndarray]]]:
    """``{model: {area fraction: {metric: (layouts,) in seed order, "seed": ...}}}``."""
    key = f"field.{FIELD}.area_fraction"
    out: dict = {}
    laws = ds["law"].values
    fractions = ds[key].values
    seeds = ds["seed"].values
    for label, _ in MODELS:
        out[label] = {}
        for f in np.unique(fractions):
            rows = np.nonzero((laws == label) & (fractions == f))[0]
            rows = rows[np.argsort(seeds[rows])]
            cell = {
                name: ds[name].values[rows].astype(float)
                for name in ds.data_vars
                if ds[name].dtype.kind == "f"
            }
            cell["seed"] = seeds[rows]
            peak = cell["peak_force"]
            cell["jam"] = np.where(np.isfinite(peak), peak > JAM_FORCE, np.nan)
            jam = cell["jam"] == 1
            cell["broken"] = np.where(jam, cell["released"], np.nan)  # given a jam
            cell["held"] = np.where(np.isfinite(peak), jam & (cell["released"] == 0), np.nan)
            out[label][float(f)] = cell
    return out


METRIC_ROWS = (
    ("jam", "P(jam forms)", "1"),
    ("broken", "P(jam broken by the end, given a jam)", "1"),
    ("held", "P(jam still held at the end)", "1"),
    ("peak_force", "peak pillar force", "N"),
    ("mean_force", "mean pillar force", "N"),
    ("friction_energy", "frictional energy", "J"),
    ("concentration", "largest 1-s share of the frictional energy", "1"),
)


def _pooled(cells: dict, name: str) -> np.ndarray:
    return np.concatenate([c[name] for c in cells.values()])


def summarise(table: dict) -> dict:
    """Per model: every METRIC_ROWS quantity with its bootstrap CI, pooled and per fraction."""
    out = {}
    for label, cells in table.items():
        entry = {"pooled": {}, "by_fraction": {}}
        for name, _, _ in METRIC_ROWS:
            entry["pooled"][name] = _estimate(_pooled(cells, name))
            entry["pooled"][name]["median"] = (
                float(np.nanmedian(_pooled(cells, name)))
                if np.isfinite(_pooled(cells, name)).any()
                else math.nan
            )
        for f, cell in cells.items():
            entry["by_fraction"][f"{f:g}"] = {
                name: _estimate(cell[name]) for name, _, _ in METRIC_ROWS
            }
        out[label] = entry
    return out


def _paired(table: dict, a: str, b: str, name: str, transform=None) -> np.ndarray:
    """Per layout and fraction, ``name`` under model ``a`` minus under ``b`` (transformed)."""
    diffs = []
    for f in table[a]:
        x, y = table[a][f][name], table[b][f][name]
        if transform is not None:
            x, y = transform(x), transform(y)
        diffs.append(x - y)
    return np.concatenate(diffs)


def _log10_force(f: np.ndarray) -> np.ndarray:
    # 1 N floor: a run that never touches the pillar has a peak of 0.
    return np.log10(np.maximum(f, 1.0))


def claims(table: dict) -> list[dict]:
    """The paper's claims as statements on the study's runs (module docstring)."""
    out = []

    def add(claim, paper, statement, values, direction, unit, role=None, model=None):
        est = _estimate(values)
        low, high = est["ci"]
        out.append(
            {
                "claim": claim,
                "paper": paper,
                "statement": statement,
                "effect": est["value"],
                "ci": [low, high],
                "n": est["n"],
                "unit": unit,
                "verdict": verdict(low, high, direction),
                **({"model": model, "role": role} if model else {}),
            }
        )

    p01 = _pooled(table["mu0.1"], "peak_force")
    add(
        "mu = 0.1: blocks slide easily past the pillar",
        "forces never higher than 1 kN",
        "P(peak force <= 1 kN) at mu = 0.1, minus 1/2 (> 0: in most layouts)",
        np.where(np.isfinite(p01), (p01 <= FREE_FORCE).astype(float), np.nan) - 0.5,
        +1,
        "probability",
    )
    add(
        "mu = 0.9: the blocks jam",
        "the blocks jam",
        "P(jam) at mu = 0.9, minus 1/2 (> 0: in most layouts)",
        _pooled(table["mu0.9"], "jam") - 0.5,
        +1,
        "probability",
    )
    add(
        "mu = 0.9: the jam is never broken",
        "the jam is never broken",
        "P(jam broken by the end, given a jam) at mu = 0.9, minus 1/2 (< 0: most hold)",
        _pooled(table["mu0.9"], "broken") - 0.5,
        -1,
        "probability",
    )
    add(
        "mu = 0.5: jams form and break",
        "jams form and break",
        "P(jam broken by the end, given a jam) at mu = 0.5, minus 1/2 (> 0: most break)",
        _pooled(table["mu0.5"], "broken") - 0.5,
        +1,
        "probability",
    )
    add(
        "higher friction jams more",
        "mu = 0.9 jams where mu = 0.1 slides",
        "P(jam) at mu = 0.9 minus at mu = 0.1, paired by layout",
        _paired(table, "mu0.9", "mu0.1", "jam"),
        +1,
        "probability",
    )
    for model, role in RATE_STATE_ROLES.items():
        add(
            "rate-and-state releases jams more easily than mu = 0.9",
            "jams form and break (mu = 0.9: never broken)",
            f"P(jam held at the end), {model} minus mu = 0.9, paired by layout",
            _paired(table, model, "mu0.9", "held"),
            -1,
            "probability",
            role,
            model,
        )
        add(
            "rate-and-state releases jams more easily than mu = 0.5",
            "jams form and break",
            f"P(jam held at the end), {model} minus mu = 0.5, paired by layout",
            _paired(table, model, "mu0.5", "held"),
            -1,
            "probability",
            role,
            model,
        )
        add(
            "rate-and-state gives lower peak forces than mu = 0.9",
            "force and energy loss rise dramatically at mu = 0.9",
            f"mean log10(peak force {model} / peak force mu = 0.9), paired by layout",
            _paired(table, model, "mu0.9", "peak_force", _log10_force),
            -1,
            "log10 ratio",
            role,
            model,
        )
        add(
            "rate-and-state dissipates more steadily than mu = 0.5",
            "frictional loss rises more steadily than for mu = 0.5 (two events)",
            f"largest 1-s share of frictional energy, {model} minus mu = 0.5, paired by layout",
            _paired(table, model, "mu0.5", "concentration"),
            -1,
            "share",
            role,
            model,
        )
    return out


def carriers(claim_list: list[dict]) -> list[dict]:
    """For each rate-and-state claim: which of rate, memory or both carries its effect."""
    out = []
    for claim in dict.fromkeys(c["claim"] for c in claim_list if "model" in c):
        v = {c["model"]: c["verdict"] for c in claim_list if c["claim"] == claim}
        rs, rate, memory = v["rate-state"], v["steady-state"], v["memory-only"]
        if rs != "holds":
            carrier = f"no effect to carry (rate-and-state: {rs})"
        elif rate == "holds" and memory == "holds":
            carrier = "either alone (rate only and memory only both show it)"
        elif rate == "holds":
            carrier = "rate (the steady-state law shows it, memory only does not)"
        elif memory == "holds":
            carrier = "memory (memory only shows it, the steady-state law does not)"
        else:
            carrier = "rate and memory together (neither alone shows it)"
        out.append({"claim": claim, "verdicts": v, "carried_by": carrier})
    return out


# --------------------------------------------------------------------------------------------
# The command
# --------------------------------------------------------------------------------------------


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
    from .sweep import run_sweep

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


def study_report(ds, out, *, scene, layouts, until, runs, arch, precision) -> dict:
    """The study's summary (study.json's content, but its wall time) and figures (into
    ``out/figures``) from the sweep's dataset ``ds``; ``runs`` is the sweep's log."""
    from .friction import law_from_table

    out = Path(out)
    table = _table(ds)
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
    from .ensemble import EnsembleResult
    from .paper import MODEL_COLOURS, MODEL_TITLES
    from .plots import plot_spread

    results = {}
    for label, cells in table.items():
        names = ("peak_force", "friction_energy", "concentration")
        cols = {n: _pooled(cells, n) for n in names}
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
    from .plots import _pyplot, _save

    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    coulomb = [(label, float(label[2:])) for label, _ in MODELS if label.startswith("mu")]
    markers = {"rate-state": "*", "steady-state": "s", "memory-only": "D"}
    fractions = sorted(next(iter(table.values())))
    for ax, name, title in zip(
        axes, ("jam", "held"), ("a jam forms", "a jam still holds at the end")
    ):
        for k, f in enumerate([*fractions, None]):
            if f is None:
                pick = lambda c, name=name: _pooled(c, name)  # noqa: E731
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
    return _save(fig, path)


def plot_phase_map(table: dict, path: Path) -> Path:
    """P(jam) for each model (rows) and area fraction (columns), with the layouts counted."""
    from .plots import _pyplot, _save

    plt = _pyplot()
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
    return _save(fig, path)


# --------------------------------------------------------------------------------------------
# Command line: taichi-ice study
# --------------------------------------------------------------------------------------------

EXAMPLES = """examples:
  taichi-ice study --out out/study                       # the default size (~10 min on 2 cores)
  taichi-ice study --out out/study --layouts 32 --workers 16
  taichi-ice study --out out/study --scheduler tcp://10.0.0.1:8786 --layouts 200
  taichi-ice study --out /tmp/smoke --layouts 2 --until 0.5   # a smoke run
Run it again with the same --out to resume, or with more --layouts to grow it."""


def add_options(p) -> None:
    """The options of ``taichi-ice study`` (beside the engine options the CLI adds)."""
    p.epilog = EXAMPLES
    p.add_argument("--out", default="out/study", help="output folder (default out/study)")
    p.add_argument(
        "--layouts",
        type=int,
        default=DEFAULT_LAYOUTS,
        help=f"jittered layouts per model and area fraction (default {DEFAULT_LAYOUTS})",
    )
    from .sweep import add_cluster_options

    add_cluster_options(p)


def study_command(args) -> int:
    """The body of ``taichi-ice study``."""
    from .sweep import SweepError

    if args.layouts < 2:
        raise SweepError(f"--layouts {args.layouts}: a confidence interval needs 2 or more")
    run_study(
        args.out,
        args.layouts,
        workers=args.workers,
        scheduler=args.scheduler,
        until=args.until,
        arch=args.arch,
        precision=args.precision,
        progress=not args.quiet,
    )
    print(f"wrote {args.out}/study.md, study.json and figures/")
    return 0
