"""The study's statistics: every world's values, each stratum's description, the paper's
claims tested within each stratum, the step's bias and the power each claim had.

The paper ends: "the forces and energies calculated by the DEM are highly sensitive to
initial conditions. By running larger suites of experiments, across a wider range of
friction values, it may be possible to clarify the specific effects of incorporating rate
dependence, memory dependence, or both." The design is ``design``'s (strata by area
fraction with their own layouts, a control, a half step, two ice strengths); this module
analyses it, each method from ``experiments.inference`` (held against SciPy and statsmodels
in the tests):

- **Proportions** (a jam forms, a jam still holds at the end) with exact Clopper-Pearson
  intervals; a jam at three thresholds (5, 10, 20 kN: ``metrics.JAM_FORCES``).
- **Time to release** of the largest jam (``metrics.release``: from the peak to the first
  second whose mean force is below a tenth of it), Kaplan-Meier over the runs that jammed,
  censored at the run's end; the share of the run's time jammed; the frictional energy's
  concentration in time (the largest share lost in 1 s).
- **Claims within a stratum**, on the same layouts under two models (paired): the exact
  McNemar test for 0/1 outcomes (effect: the share of the discordant layouts on the claimed
  side, with its exact interval), the Wilcoxon signed-rank test for continuous ones (effect:
  the mean paired difference with a percentile bootstrap interval over layouts); claims on
  one model's proportion: the exact binomial test against 1/2. Holm's correction over every
  claim of a family (the strata without strength; each strength its own). A claim **holds**
  when its Holm-adjusted p is at most ``ALPHA`` and its effect lies on the claimed side, is
  **contradicted** when it lies on the other side, and is **undecided** otherwise.
- **Power**: per claim, the layouts that 80 % power at ``ALPHA`` needs at the observed effect
  (exact for the binomial and McNemar tests; Wilcoxon through the t test's normal
  approximation and the asymptotic relative efficiency 3/pi), beside the layouts run.
- **The step's bias**: the half-step arm against the same layouts at the default step, per
  model and measure: the mean paired shift with its interval, Wilcoxon, the exact two-sample
  Kolmogorov-Smirnov test, quantile shifts (10, 50, 90 %) with bootstrap intervals, and the
  shift over the standard error of the stratum's mean (below 1: smaller than the sampling
  error of the claims).
"""

from __future__ import annotations

import math

import numpy as np

from .. import inference
from ..metrics import JAM_FORCE, JAM_FORCES
from .design import MODELS

ALPHA = 0.05
POWER = 0.8
RATE_STATE_ROLES = {
    "rate-state": "rate and memory",
    "steady-state": "rate only",
    "memory-only": "memory only",
}
# The paper's bound for blocks that "slide easily past the pillar" (mu = 0.1).
FREE_FORCE = 1e3  # N
# The smallest force a run's peak is read at on a log scale (a run that never touches the
# pillar has a peak of 0).
FORCE_FLOOR = 1.0  # N
BOOTSTRAP_RESAMPLES = 4000
CONFIDENCE = 0.95
BOOTSTRAP_SEED = 20130301  # the resampling is seeded: the study's numbers are reproducible
# The step's bias, measure by measure.
STEP_MEASURES = ("peak_force", "friction_energy", "concentration", "jammed_fraction")


def bootstrap_ci(
    values,
    statistic=np.mean,
    *,
    n_resamples: int = BOOTSTRAP_RESAMPLES,
    confidence: float = CONFIDENCE,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float, float]:
    """``(estimate, low, high)``: ``statistic`` of ``values`` and its percentile bootstrap
    interval (Efron & Tibshirani 1993, ch. 13) over ``n_resamples`` resamples with
    replacement. NaNs are dropped; ``(nan, nan, nan)`` when nothing is left. For continuous
    values only: on 0/1 outcomes it gives zero-width intervals (use ``inference``)."""
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


def effective_mu(law, speed: float) -> float:
    """The constant mu a rate-and-state variant sits at: its steady-state friction at the
    pusher's speed (the slip rate the pusher imposes on the rubble it drives)."""
    return float(law.steady_state(np.array([speed]))[0])


# --------------------------------------------------------------------------------------------
# Every world's values
# --------------------------------------------------------------------------------------------


def derived(m: dict) -> dict:
    """A world's 0/1 outcomes from its metrics (NaN where they are NaN): ``jam`` (peak above
    ``JAM_FORCE``), ``jam_5kN``, ``jam_20kN``, ``held`` (a jam not released by the end),
    ``slid`` (peak at most ``FREE_FORCE``)."""
    peak, released = m.get("peak_force", math.nan), m.get("released", math.nan)
    if not math.isfinite(peak):
        return dict.fromkeys(("jam", "jam_5kN", "jam_20kN", "held", "slid"), math.nan)
    out = {
        f"jam{'' if name == 'jammed_fraction' else name[len('jammed_fraction') :]}": float(
            peak > force
        )
        for name, force in JAM_FORCES.items()
    }
    out["held"] = float(peak > JAM_FORCE and released == 0)
    out["slid"] = float(peak <= FREE_FORCE)
    return out


def world_rows(results: dict) -> list[dict]:
    """One row per world of every arm (``run.run_arms``' result): its arm, kind, stratum
    (area fraction), step fraction, strength, model, law and parameters, seed, status, dt,
    metrics and ``derived`` outcomes."""
    rows = []
    for name, (arm, ds, _log) in results.items():
        params = [
            c
            for c in ds.coords
            if ds[c].dims == ("world",) and c not in ("world", "seed", "law") and "." not in c
        ]
        metrics = [v for v in ds.data_vars if ds[v].dtype.kind == "f" and v != "dt"]
        for i in range(int(ds.sizes["world"])):
            row = {
                "arm": name,
                "kind": arm.kind,
                "area_fraction": arm.fraction,
                "dt_safety": arm.dt_safety,
                "strength": arm.strength,
                "model": str(ds["law"].values[i]),
                "seed": int(ds["seed"].values[i]),
                "status": str(ds["status"].values[i]),
            }
            for c in params:
                v = ds[c].values[i]
                row[c] = str(v) if ds[c].dtype.kind in "US" else float(v)
            if "dt" in ds:
                row["dt"] = float(ds["dt"].values[i])
            m = {v: float(ds[v].values[i]) for v in metrics}
            row.update(m)
            row.update(derived(m))
            rows.append(row)
    return rows


def cells(rows: list[dict], arm: str, seeds=None) -> dict[str, dict[str, np.ndarray]]:
    """``{model: {value: (layouts,) in seed order}}`` of one arm (its worlds that did not
    complete: NaN); with ``seeds``, those layouts only."""
    out = {}
    for label, _ in MODELS:
        mine = [r for r in rows if r["arm"] == arm and r["model"] == label]
        if seeds is not None:
            mine = [r for r in mine if r["seed"] in set(seeds)]
        mine.sort(key=lambda r: r["seed"])
        if not mine:
            continue
        names = [k for k, v in mine[0].items() if isinstance(v, float) or v is None]
        cell = {"seed": np.array([r["seed"] for r in mine])}
        done = np.array([r["status"] == "complete" for r in mine])
        for k in names:
            v = np.array([math.nan if r[k] is None else r[k] for r in mine], dtype=float)
            cell[k] = np.where(done, v, math.nan)  # a world that failed counts nowhere
        out[label] = cell
    return out


# --------------------------------------------------------------------------------------------
# Description of an arm
# --------------------------------------------------------------------------------------------


def proportion(values) -> dict:
    """``{"k", "n", "value", "ci"}``: successes of the finite 0/1 ``values``, with the exact
    (Clopper-Pearson) interval."""
    x = np.asarray(values, dtype=float)
    x = x[np.isfinite(x)]
    k, n = int(x.sum()), int(x.size)
    low, high = inference.clopper_pearson(k, n, CONFIDENCE)
    return {"k": k, "n": n, "value": k / n if n else math.nan, "ci": [low, high]}


def quartiles(values) -> dict:
    """``{"n", "median", "q25", "q75"}`` of the finite values (NaN if none)."""
    x = np.asarray(values, dtype=float)
    x = x[np.isfinite(x)]
    if not x.size:
        return {"n": 0, "median": math.nan, "q25": math.nan, "q75": math.nan}
    q25, med, q75 = np.quantile(x, [0.25, 0.5, 0.75])
    return {"n": int(x.size), "median": float(med), "q25": float(q25), "q75": float(q75)}


def release_curve(cell: dict) -> dict:
    """Kaplan-Meier of the time from the peak to the largest jam's release, over the
    layouts that jammed (censored where the run ended first); ``held_to_end``: the
    estimated share still held at the longest time observed."""
    jam = cell["jam"] == 1
    t, seen = cell["release_time"][jam], cell["release_observed"][jam] == 1
    keep = np.isfinite(t)
    if not keep.any():
        return {
            "n": 0,
            "events": 0,
            "median": None,
            "censored_followup_median": None,
            "curve": None,
        }
    km = inference.kaplan_meier(t[keep], seen[keep])
    censored = t[keep][~seen[keep]]
    return {
        "n": int(keep.sum()),
        "events": int(seen[keep].sum()),
        "median": km["median"],
        # How long the runs still held were followed after their peak: 0 where the peak is
        # the run's last sample (a jam still building when the run ends).
        "censored_followup_median": float(np.median(censored)) if censored.size else None,
        "curve": km,
    }


DESCRIBED = ("peak_force", "friction_energy", "concentration", "jammed_fraction")


def describe(arm_cells: dict) -> dict:
    """Per model: the 0/1 outcomes' proportions, quartiles of the continuous measures, the
    release curve."""
    out = {}
    for label, cell in arm_cells.items():
        entry = {
            name: proportion(cell[name]) for name in ("jam_5kN", "jam", "jam_20kN", "held", "slid")
        }
        for name in (*DESCRIBED, "crushing_energy"):
            if name in cell:
                entry[name] = quartiles(cell[name])
        entry["release"] = release_curve(cell)
        out[label] = entry
    return out


# --------------------------------------------------------------------------------------------
# Claims
# --------------------------------------------------------------------------------------------


def _log10_force(f: np.ndarray) -> np.ndarray:
    return np.log10(np.maximum(f, FORCE_FLOOR))


def one_proportion(values, direction: int) -> dict:
    """A claim on one model's proportion against 1/2: the exact binomial test, the
    proportion with its exact interval (effect: the proportion minus 1/2), the layouts that
    80 % power would need at the observed proportion."""
    p = proportion(values)
    test = inference.binomial_test(p["k"], p["n"], 0.5) if p["n"] else 1.0
    return {
        "test": "exact binomial, against 1/2",
        "n": p["n"],
        "effect": p["value"] - 0.5 if p["n"] else math.nan,
        "ci": [p["ci"][0] - 0.5, p["ci"][1] - 0.5],
        "counts": f"{p['k']} of {p['n']}",
        "p": test,
        "n_needed": inference.binomial_n(p["value"], 0.5, ALPHA, POWER) if p["n"] else None,
        "direction": direction,
    }


def paired_binary(a, b, direction: int) -> dict:
    """A claim that model A's 0/1 outcome is more (``direction`` +1) or less (-1) frequent
    than B's on the same layouts: the exact McNemar test. Effect: the share of the
    discordant layouts (those where one model alone has it) where it is A's, minus 1/2, with
    its exact interval (the conditional odds ratio's, read on the share's scale); the counts
    give each model's proportion (their difference is the discordant counts' over n)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    keep = np.isfinite(a) & np.isfinite(b)
    test = inference.mcnemar(a[keep] == 1, b[keep] == 1)
    n, only_a, only_b = test["n"], test["only_a"], test["only_b"]
    discordant = only_a + only_b
    low, high = inference.clopper_pearson(only_a, discordant, CONFIDENCE)
    return {
        "test": "exact McNemar",
        "n": n,
        "effect": only_a / discordant - 0.5 if discordant else math.nan,
        "ci": [low - 0.5, high - 0.5],
        "difference": (only_a - only_b) / n if n else math.nan,
        "counts": f"{test['a']} vs {test['b']} of {n}; discordant {only_a} vs {only_b}",
        "p": test["p"],
        "n_needed": inference.mcnemar_pairs(only_a / n, only_b / n, ALPHA, POWER)
        if n and only_a != only_b
        else None,
        "direction": direction,
    }


def paired_continuous(a, b, direction: int, transform=None) -> dict:
    """A claim that model A's measure is larger (+1) or smaller (-1) than B's on the same
    layouts: the Wilcoxon signed-rank test; effect: the mean paired difference (of
    ``transform``ed values) with its percentile bootstrap interval over layouts."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if transform is not None:
        a, b = transform(a), transform(b)
    d = a - b
    d = d[np.isfinite(d)]
    est, low, high = bootstrap_ci(d)
    nonzero = d[d != 0]
    test = inference.wilcoxon(nonzero) if nonzero.size else {"p": 1.0}
    sd = float(np.std(d, ddof=1)) if d.size > 1 else math.nan
    return {
        "test": "Wilcoxon signed-rank",
        "n": int(d.size),
        "effect": est,
        "ci": [low, high],
        "median": float(np.median(d)) if d.size else math.nan,
        "p": float(test["p"]),
        "n_needed": inference.paired_pairs(est, sd, ALPHA, POWER)
        if d.size > 1 and sd > 0 and est != 0
        else None,
        "direction": direction,
    }


def stratum_claims(c: dict) -> list[dict]:
    """The paper's claims on one stratum's cells ``c`` (``cells``), each with its test."""
    out = []

    def add(claim, paper, statement, result, model=None):
        role = RATE_STATE_ROLES.get(model)
        out.append(
            {
                "claim": claim,
                "paper": paper,
                "statement": statement,
                **result,
                **({"model": model, "role": role} if model else {}),
            }
        )

    def jammed(model, name):
        cell = c[model]
        return np.where(cell["jam"] == 1, cell[name], np.nan)

    add(
        "mu = 0.1: blocks slide easily past the pillar",
        "forces never higher than 1 kN",
        "share of layouts with a peak force <= 1 kN at mu = 0.1 (> 1/2: most)",
        one_proportion(c["mu0.1"]["slid"], +1),
    )
    add(
        "mu = 0.9: the blocks jam",
        "the blocks jam",
        "share of layouts that jam (peak > 10 kN) at mu = 0.9 (> 1/2: most)",
        one_proportion(c["mu0.9"]["jam"], +1),
    )
    add(
        "mu = 0.9: the jam is never broken",
        "the jam is never broken",
        "share of the jams at mu = 0.9 released before the end (< 1/2: most hold)",
        one_proportion(jammed("mu0.9", "release_observed"), -1),
    )
    add(
        "mu = 0.5: jams form and break",
        "jams form and break",
        "share of the jams at mu = 0.5 released before the end (> 1/2: most break)",
        one_proportion(jammed("mu0.5", "release_observed"), +1),
    )
    add(
        "higher friction jams more",
        "mu = 0.9 jams where mu = 0.1 slides",
        "jam at mu = 0.9 against at mu = 0.1, paired by layout",
        paired_binary(c["mu0.9"]["jam"], c["mu0.1"]["jam"], +1),
    )
    for model in RATE_STATE_ROLES:
        for other in ("mu0.9", "mu0.5"):
            name = "0.9" if other == "mu0.9" else "0.5"
            add(
                f"rate-and-state releases jams more easily than mu = {name}",
                "jams form and break" + (" (mu = 0.9: never broken)" if name == "0.9" else ""),
                f"a jam still held at the end, {model} against mu = {name}, paired by layout",
                paired_binary(c[model]["held"], c[other]["held"], -1),
                model,
            )
            add(
                f"rate-and-state is jammed for less of the time than mu = {name}",
                "jams form and break",
                f"share of the 20 s above 10 kN, {model} minus mu = {name}, paired by layout",
                paired_continuous(c[model]["jammed_fraction"], c[other]["jammed_fraction"], -1),
                model,
            )
        add(
            "rate-and-state gives lower peak forces than mu = 0.9",
            "force and energy loss rise dramatically at mu = 0.9",
            f"log10(peak force, {model} / mu = 0.9), paired by layout",
            paired_continuous(c[model]["peak_force"], c["mu0.9"]["peak_force"], -1, _log10_force),
            model,
        )
        add(
            "rate-and-state dissipates more steadily than mu = 0.5",
            "frictional loss rises more steadily than for mu = 0.5 (two events)",
            f"largest 1-s share of the frictional energy, {model} minus mu = 0.5, paired",
            paired_continuous(c[model]["concentration"], c["mu0.5"]["concentration"], -1),
            model,
        )
    return out


def verdict(p_adjusted: float, effect: float, direction: int) -> str:
    """'holds' when the adjusted p is at most ALPHA and the effect lies on the claimed side
    (``direction`` +1 or -1), 'contradicted' on the other side, else 'undecided'."""
    if not (math.isfinite(p_adjusted) and math.isfinite(effect)) or p_adjusted > ALPHA:
        return "undecided"
    if direction * effect > 0:
        return "holds"
    if direction * effect < 0:
        return "contradicted"
    return "undecided"


def family(claim_lists: dict[str, list[dict]]) -> list[dict]:
    """The claims of several strata (``{stratum label: claims}``) as one family: Holm's
    adjustment over all of them, and each one's verdict."""
    flat = [{**c, "stratum": s} for s, cs in claim_lists.items() for c in cs]
    adjusted = inference.holm([c["p"] for c in flat]) if flat else []
    for c, p in zip(flat, adjusted):
        c["p_holm"] = p
        c["verdict"] = verdict(p, c["effect"], c["direction"])
    return flat


def carriers(claim_list: list[dict]) -> list[dict]:
    """For each rate-and-state claim in each stratum: which of rate, memory or both carries
    its effect (the verdicts of rate-and-state, the steady-state law and memory only)."""
    out = []
    keys = dict.fromkeys((c["stratum"], c["claim"]) for c in claim_list if "model" in c)
    for stratum, claim in keys:
        v = {
            c["model"]: c["verdict"]
            for c in claim_list
            if c["claim"] == claim and c["stratum"] == stratum
        }
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
        out.append({"stratum": stratum, "claim": claim, "verdicts": v, "carried_by": carrier})
    return out


# --------------------------------------------------------------------------------------------
# The step's bias
# --------------------------------------------------------------------------------------------


def step_bias(default: dict, half: dict, stratum: dict) -> list[dict]:
    """The half step against the default on the same layouts, per model and measure (module
    docstring). ``default`` and ``half``: cells on the same seeds; ``stratum``: the default
    step's cells on all the stratum's layouts (their standard error is the claims' sampling
    error). Holm's adjustment over the Wilcoxon tests of every row."""
    rows = []
    for label in half:
        a, b = default[label], half[label]
        for name in STEP_MEASURES:
            x, y = a[name], b[name]
            keep = np.isfinite(x) & np.isfinite(y)
            x, y = x[keep], y[keep]
            if x.size < 2:
                continue
            d = y - x
            mean = float(np.mean(x))
            est, low, high = bootstrap_ci(d)
            nonzero = d[d != 0]
            full = stratum[label][name]
            full = full[np.isfinite(full)]
            se = float(np.std(full, ddof=1) / np.sqrt(full.size)) if full.size > 1 else math.nan
            rows.append(
                {
                    "model": label,
                    "measure": name,
                    "n": int(x.size),
                    "default_mean": mean,
                    "shift": est,
                    "ci": [low, high],
                    "relative": est / mean if mean else math.nan,
                    "wilcoxon_p": float(inference.wilcoxon(nonzero)["p"]) if nonzero.size else 1.0,
                    "ks": inference.ks_2samp(x, y),
                    "quantiles": inference.quantile_shift(x, y, seed=BOOTSTRAP_SEED),
                    "stratum_n": int(full.size),
                    "stratum_se": se,
                    "shift_over_se": abs(est) / se if se > 0 else math.nan,
                }
            )
        for name in ("jam", "held"):
            test = inference.mcnemar(a[name] == 1, b[name] == 1)
            rows.append({"model": label, "measure": name, "mcnemar": test})
    tested = [r for r in rows if "wilcoxon_p" in r]
    for r, p in zip(tested, inference.holm([r["wilcoxon_p"] for r in tested])):
        r["wilcoxon_p_holm"] = p
    return rows
