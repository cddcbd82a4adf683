"""The study the paper asked for: ``taichi-ice study --out DIR``.

The paper ends: "the forces and energies calculated by the DEM are highly sensitive to
initial conditions. By running larger suites of experiments, across a wider range of
friction values, it may be possible to clarify the specific effects of incorporating rate
dependence, memory dependence, or both." This is that suite: the pillar scene
(``scenarios/pillar.toml``) over ``layouts`` jittered layouts x eight friction models
(mu = 0.1, 0.3, 0.5, 0.7, 0.9; rate-and-state; its steady-state law, rate without memory;
its memory-only variant, B = A) x the field's area fraction (``AREA_FRACTIONS``), run as one
sweep (``taichi_ice.experiments.sweep.run``) on Dask.

Per model (over every layout and area fraction, and per area fraction), with percentile
bootstrap confidence intervals over layouts (``bootstrap_ci``):

- the probability that a jam forms (the peak pillar force exceeds ``JAM_FORCE``) and that a
  jam breaks by the end (``metrics.RELEASED_FRACTION``: the force over the last second has
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

This module holds the study's design (its models, area fractions, sweep) and statistics:
the bootstrap, the table of runs, the summary, the claims and their carriers. Running it and
writing its report and figures is ``study.report``'s; the command line ``commands.study``'s.
"""

from __future__ import annotations

import math

import numpy as np

from ..metrics import JAM_FORCE

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
# past the pillar" (mu = 0.1: "forces never higher than 1 kN"): metrics.JAM_FORCE, 10 kN.
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
    from ..models import DEFAULT_SCENE
    from ..sweep.spec import sweep_from_dict

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


def study_table(ds) -> dict[str, dict[float, dict[str, np.ndarray]]]:
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


def pooled(cells: dict, name: str) -> np.ndarray:
    return np.concatenate([c[name] for c in cells.values()])


def summarise(table: dict) -> dict:
    """Per model: every METRIC_ROWS quantity with its bootstrap CI, pooled and per fraction."""
    out = {}
    for label, cells in table.items():
        entry = {"pooled": {}, "by_fraction": {}}
        for name, _, _ in METRIC_ROWS:
            entry["pooled"][name] = _estimate(pooled(cells, name))
            entry["pooled"][name]["median"] = (
                float(np.nanmedian(pooled(cells, name)))
                if np.isfinite(pooled(cells, name)).any()
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

    p01 = pooled(table["mu0.1"], "peak_force")
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
        pooled(table["mu0.9"], "jam") - 0.5,
        +1,
        "probability",
    )
    add(
        "mu = 0.9: the jam is never broken",
        "the jam is never broken",
        "P(jam broken by the end, given a jam) at mu = 0.9, minus 1/2 (< 0: most hold)",
        pooled(table["mu0.9"], "broken") - 0.5,
        -1,
        "probability",
    )
    add(
        "mu = 0.5: jams form and break",
        "jams form and break",
        "P(jam broken by the end, given a jam) at mu = 0.5, minus 1/2 (> 0: most break)",
        pooled(table["mu0.5"], "broken") - 0.5,
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
