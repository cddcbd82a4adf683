"""The pillar scene's statistics over layouts at other steps and integrators (issue 30).

One run of the pillar scene does not converge in dt past the time it parts from a run at
another step (``dem_accuracy``: 6-9 s of the paper's 20; a run differing in the last bit of
one x parts at 12-13 s), so its frictional energy at 20 s is one draw of a chaotic process;
what the paper's question rests on is that draw's distribution over layouts. Here, for
``LAYOUTS`` layouts of the pillar scene (the paper's and reseeded ones, as the study's), with
Coulomb friction (mu = 0.5) and the paper's rate-and-state law, the paper's 20 s at each
(integrator, dt / stable_dt) of ``CASES``, the measures of ``experiments.metrics``, held
against each other on the same layouts (``COMPARISONS``: 4x the Euler step's 0.2 stable_dt,
issue 30's baseline, and the analytic steps against it, it against a quarter of its step,
the two integrators at that quarter, and each law's default step, ``DEFAULTS``, against
the quarter step and the baseline):

- **the step's shift**: the mean of the paired differences (same layout), with its 95 %
  t interval, relative to the other's mean; the shift is "within the sampling error" where
  that interval holds 0 (past ~12 s the runs of one layout at two steps are as good as
  independent draws, so the interval is about sqrt(2) x 1.96 standard errors of one mean);
- **the sampling error**: the standard error of the other's mean over the layouts;
- the paired Wilcoxon signed-rank test (and, of the two distributions, the two-sample
  Kolmogorov-Smirnov test), SciPy; ``released`` (0 or 1): the counts and the exact McNemar
  test on the discordant pairs;
- **Holm's correction** over every test of the run (each comparison's measures and its
  released): a shift "differs" where its Wilcoxon (or McNemar) p, so adjusted, is below 0.05.
  With five comparisons of four measures for two laws, one uncorrected p below 0.05 is
  expected by chance alone.

Writes ``dem_ensemble.json`` (every layout's measures, per case and law, and the
comparisons) and ``dem_ensemble.png``. ``python -m taichi_ice.commands.validate dem_ensemble``
(also part of ``taichi-ice validate --dem``); ``--quick``: two layouts, 3 s, Euler only.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from ...physics import timestep
from ..inference import holm
from ..inference import mcnemar as _mcnemar_test
from .dem_charts import INTEGRATOR_COLORS

LAYOUTS = 32
UNTIL = 20.0  # s: the paper's run
LAWS = ("coulomb", "rate-state")
# Issue 30's "today's step", every law's default until 2026-12-02: the Euler step at 0.2.
BASELINE = ("euler", 0.2)
REFERENCE = ("euler", 0.05)  # a quarter of it
# Each law's default step now (``timestep.default_integrator`` at ``default_safety``):
# Coulomb's the midstep step at 0.6, rate and state's the Euler step at 0.05 (REFERENCE).
# Read from the code, so that the study holds whatever step a user gets by default.
DEFAULTS = {law: (timestep.default_integrator(law), timestep.default_safety(law)) for law in LAWS}
# (integrator, dt / stable_dt): 4x the baseline step with each integrator, the analytic and
# coupled steps at the baseline one, Euler and the analytic step at a quarter of it, and
# each law's default step (``DEFAULTS``) where it is none of those.
CASES = (
    BASELINE,
    ("euler", 0.8),
    ("analytic", 0.2),
    ("analytic", 0.8),
    ("coupled", 0.2),
    ("coupled", 0.8),
    REFERENCE,
    ("analytic", 0.05),
    ("midstep", 0.8),
)
CASES += tuple(sorted({d for d in DEFAULTS.values() if d not in CASES}))
# (case, against): what each comparison holds against what; a default step against the
# reference and the baseline.
COMPARISONS = (
    (("euler", 0.8), BASELINE),
    (("analytic", 0.2), BASELINE),
    (("analytic", 0.8), BASELINE),
    (("coupled", 0.2), BASELINE),
    (("coupled", 0.8), BASELINE),
    (("coupled", 0.8), ("coupled", 0.2)),
    (BASELINE, REFERENCE),
    (("analytic", 0.05), REFERENCE),
    (("midstep", 0.8), BASELINE),
)
COMPARISONS += tuple(
    (d, against)
    for d in sorted(set(DEFAULTS.values()))
    for against in (REFERENCE, BASELINE)
    if d != against and (d, against) not in COMPARISONS and (against, d) not in COMPARISONS
)
MEASURES = ("peak_force", "friction_energy", "concentration")
ALPHA = 0.05  # family-wise, Holm
# Quick: the rubble meets the pillar at 2.1 s.
QUICK = {
    "layouts": 2,
    "until": 3.0,
    "laws": ("coulomb",),
    "cases": (BASELINE, ("euler", 0.8)),
    "comparisons": ((("euler", 0.8), BASELINE),),
}


def paired(base, other) -> dict[str, Any]:
    """The shift of ``other`` from ``base`` (paired by layout) against the sampling error.

    Returns the mean shift, its 95 % t interval, the standard error of the baseline's mean,
    both relative to the baseline's mean, whether the interval holds 0, and the p-values of
    the Wilcoxon signed-rank and two-sample Kolmogorov-Smirnov tests. Layouts where either
    value is not finite (a concentration of no frictional energy) are left out; ``n``
    counts the rest.
    """
    from scipy import stats

    a, b = np.asarray(base, dtype=float), np.asarray(other, dtype=float)
    keep = np.isfinite(a) & np.isfinite(b)
    a, b = a[keep], b[keep]
    n = a.size
    if n == 0:
        return {"n": 0, "within_sampling_error": None}
    d = b - a
    shift = float(d.mean())
    half = float(stats.t.ppf(0.975, n - 1) * d.std(ddof=1) / math.sqrt(n)) if n > 1 else math.nan
    se = float(a.std(ddof=1) / math.sqrt(n)) if n > 1 else math.nan
    scale = (float(a.mean()) or 1.0) if n else math.nan
    out = {
        "n": int(n),
        "base_mean": float(a.mean()),
        "mean": float(b.mean()),
        "shift": shift,
        "shift_ci95": [shift - half, shift + half],
        "base_se": se,
        "shift_rel": shift / scale,
        "base_se_rel": se / scale,
        "within_sampling_error": bool(shift - half <= 0.0 <= shift + half) if n > 1 else None,
        "wilcoxon_p": None,
        "ks_p": float(stats.ks_2samp(a, b).pvalue) if n > 1 else None,
    }
    if n > 1 and np.any(d != 0.0):
        out["wilcoxon_p"] = float(stats.wilcoxon(a, b).pvalue)
    return out


def mcnemar(base, other) -> dict[str, Any]:
    """Released (0/1) in two cases on the same layouts: counts and the exact McNemar p
    (two-sided binomial test of the discordant pairs at 1/2)."""
    test = _mcnemar_test(base, other)
    return {
        "base": test["a"],
        "other": test["b"],
        "only_base": test["only_a"],
        "only_other": test["only_b"],
        "p": test["p"],
    }


def run_case(
    law: str, integrator: str, ratio: float, layouts: int, until: float, mu: float | None = None
) -> dict:
    """``layouts`` pillar layouts as one batch: each one's metrics (``metrics.run_metrics``);
    ``mu``: the Coulomb worlds' friction coefficient (None: the scene's)."""
    from ...engine.options import Options
    from ...physics.friction import Coulomb
    from ..ensemble import run_ensemble
    from . import dem_accuracy, dem_scenes

    scene = dem_scenes.pillar(law)
    if mu is not None and law == "coulomb":
        scene = scene.with_friction(Coulomb(mu=mu))
    dt = dem_accuracy.field_step(ratio, scene.stable_dt)
    own = scene.simulation.seed  # the paper's layout first, then reseeded ones
    seeds = [own, *[s for s in range(layouts + 1) if s != own][: layouts - 1]]
    start = time.perf_counter()
    ens = run_ensemble(
        scene,
        seeds,
        until=until,
        options=Options(dt=dt, force_dt=True, integrator=integrator),
    )
    values = {m: [float(x[m]) for x in ens.metrics] for m in (*MEASURES, "released")}
    # A batch stops whole when one of its worlds diverges: its measures are then of a
    # shorter run, and no layout of it is compared.
    completed = [ens.status == "complete"] * len(ens.seeds)
    return {
        "law": law,
        "integrator": integrator,
        "ratio": dt / scene.stable_dt,
        "dt": dt,
        "status": ens.status,
        "failure": ens.failure,
        "completed": completed,
        "seeds": list(ens.seeds),
        "wall_s": time.perf_counter() - start,
        **values,
    }


def _completed(run: dict) -> np.ndarray:
    """Which layouts of a case ran to the end (a run from before ``completed`` was kept:
    all of them if the batch did)."""
    done = run.get("completed")
    if done is None:
        done = [run["status"] == "complete"] * len(run["seeds"])
    return np.asarray(done, dtype=bool)


def compare(runs: list[dict], laws, comparisons) -> dict[str, Any]:
    """Each (case, against) of ``comparisons``, per law and measure, on the layouts both
    ran to the end (those of a batch that stopped are left out of both, and counted)."""
    out: dict[str, Any] = {}
    for law in laws:
        mine = {(r["integrator"], round(r["nominal"], 6)): r for r in runs if r["law"] == law}
        for (integ, ratio), (base_integ, base_ratio) in comparisons:
            other = mine[(integ, round(ratio, 6))]
            base = mine[(base_integ, round(base_ratio, 6))]
            ok = _completed(base) & _completed(other)
            entry: dict[str, Any] = {
                m: paired(np.asarray(base[m])[ok], np.asarray(other[m])[ok]) for m in MEASURES
            }
            entry["released"] = mcnemar(
                np.asarray(base["released"])[ok], np.asarray(other["released"])[ok]
            )
            entry["left_out"] = int((~ok).sum())
            key = f"{law}: {integ} {ratio:g} against {base_integ} {base_ratio:g}"
            out[key] = entry
    # Holm over every test of the run: each measure's Wilcoxon p and each released's McNemar p.
    tests = [
        (c[m], "wilcoxon_p" if m in MEASURES else "p")
        for c in out.values()
        for m in (*MEASURES, "released")
        if c[m].get("wilcoxon_p" if m in MEASURES else "p") is not None
    ]
    adjusted = holm([t[k] for t, k in tests])
    for (t, _), p in zip(tests, adjusted):
        t["holm_p"] = p
        t["differs"] = bool(p < ALPHA)
    for c in out.values():
        c["any_differs"] = any(c[m].get("differs", False) for m in (*MEASURES, "released"))
    return out


def _shift(c: dict[str, Any]) -> str:
    """``+25 % [+3, +47] (Holm p 0.3)``: a shift, its interval, relative to the other's mean."""
    b = c["base_mean"] or 1.0
    lo, hi = c["shift_ci95"]
    holm_p = c.get("holm_p")
    return f"{c['shift_rel'] * 100:+.0f} % [{lo / b * 100:+.0f}, {hi / b * 100:+.0f}]" + (
        f" (Holm p {holm_p:.2g})" if holm_p is not None else ""
    )


def plot(summary: dict[str, Any], path: Path) -> None:
    """Per law (rows) and measure (columns): each case's mean with its 95 % interval over
    the layouts; shaded, the mean +- 1.96 standard errors of the law's default step
    (``DEFAULTS``), or of ``BASELINE`` where the default was not run."""
    from matplotlib.figure import Figure

    laws = summary["settings"]["laws"]
    columns = (*MEASURES, "released")
    # Wide enough for every case's label (ten cases a law since the defaults joined them).
    most = max(sum(r["law"] == law for r in summary["runs"]) for law in laws)
    width = max(3.4, 0.5 * most)
    fig = Figure(figsize=(width * len(columns), 2.9 * len(laws)), constrained_layout=True)
    axes = fig.subplots(len(laws), len(columns), squeeze=False)
    for row, law in enumerate(laws):
        runs = [r for r in summary["runs"] if r["law"] == law]
        cases = [(r["integrator"], round(r["nominal"], 6)) for r in runs]
        integ, ratio = DEFAULTS.get(law, BASELINE)
        shaded = (integ, round(ratio, 6))
        if shaded not in cases:
            shaded = (BASELINE[0], round(BASELINE[1], 6))
        for col, m in enumerate(columns):
            ax = axes[row][col]
            for k, (r, case) in enumerate(zip(runs, cases)):
                v = np.asarray(r[m], dtype=float)
                half = 1.96 * v.std(ddof=1) / math.sqrt(v.size) if v.size > 1 else 0.0
                color = INTEGRATOR_COLORS.get(r["integrator"], "C7")
                ax.plot(np.full(v.size, k) + 0.08, v, ".", color=color, alpha=0.3, ms=4)
                ax.errorbar(k - 0.08, v.mean(), yerr=half, fmt="o", color=color, capsize=3)
                if case == shaded:
                    ax.axhspan(v.mean() - half, v.mean() + half, color="0.85", zorder=0)
            ax.set_xticks(range(len(runs)))
            ax.set_xticklabels(
                [
                    f"{r['integrator']}\n{r['nominal']:g}"
                    + ("" if r["status"] == "complete" else "\n(stopped)")
                    for r in runs
                ],
                fontsize=7,
            )
            ax.set_title(f"{law}: {m}", fontsize=9)
    mu = summary["settings"].get("mu")
    fig.suptitle(
        f"Pillar scene over {summary['settings']['layouts']} layouts, "
        + (f"Coulomb mu = {mu:g}, " if mu else "")
        + f"{summary['settings']['until_s']:g} s: "
        "each integrator and dt / stable_dt (mean, 95 % interval, layouts as dots);\nshaded: "
        "the law's default step's mean +- 1.96 standard errors ("
        + ", ".join(f"{law} {i} {r:g}" for law, (i, r) in DEFAULTS.items() if law in laws)
        + "; else euler 0.2)",
        fontsize=10,
    )
    fig.savefig(path, dpi=75)


def select(cases, comparisons, wanted) -> tuple[tuple, tuple]:
    """The cases ``wanted`` (``(integrator, ratio)`` pairs, in their order) and the
    comparisons of ``comparisons`` whose two cases are both among them; a wanted case the
    study does not list (another step, say) is held against ``BASELINE`` and ``REFERENCE``,
    those of them wanted too. ``wanted`` None keeps everything.

    Raises:
        UsageError: a wanted case that no comparison of the study holds against another
            run case (it would be run and compared with nothing).
    """
    from ...errors import UsageError

    if wanted is None:
        return tuple(cases), tuple(comparisons)
    wanted = tuple((i, float(r)) for i, r in wanted)
    every = {c for pair in comparisons for c in pair}
    kept = tuple((a, b) for a, b in comparisons if a in wanted and b in wanted)
    for against in (BASELINE, REFERENCE):  # a case of the user's own: against these
        if against in wanted:
            kept += tuple((c, against) for c in wanted if c not in every and c != against)
    compared = {c for pair in kept for c in pair}
    alone = [f"{i}:{r:g}" for i, r in wanted if (i, r) not in compared]
    if alone:
        known = ", ".join(f"{i}:{r:g}" for i, r in sorted(every))
        raise UsageError(
            f"dem_ensemble --cases: {', '.join(alone)} would be compared with no other case "
            f"run; the comparisons hold these against each other: {known} (e.g. --cases "
            "euler:0.2,coupled:0.8)"
        )
    return wanted, kept


def run(
    out_dir: str | Path,
    quick: bool = False,
    reuse: bool = False,
    log=print,
    layouts: int | None = None,
    cases=None,
    laws=None,
    mu: float | None = None,
) -> dict[str, Any]:
    """Every case of every law, the comparisons, ``dem_ensemble.json`` and ``.png``.

    ``reuse``: keep the runs of an earlier ``dem_ensemble.json`` in ``out_dir`` made with the
    same layouts and length, and run only the cases it lacks. ``layouts``: how many (default
    ``LAYOUTS``; quick 2): the paired intervals narrow as 1/sqrt(layouts). ``cases``: run only
    these ``(integrator, dt / stable_dt)`` and the comparisons among them (``select``).
    ``laws``: run only these of ``LAWS``. ``mu``: the Coulomb worlds' friction coefficient
    (None: the pillar scene's, 0.5); recorded, and a record of another is not reused.
    """
    from ... import backend

    if backend.current() is None:
        backend.init("cpu", "f64")
    cfg = (
        dict(QUICK)
        if quick
        else {
            "layouts": LAYOUTS,
            "until": UNTIL,
            "laws": LAWS,
            "cases": CASES,
            "comparisons": COMPARISONS,
        }
    )
    if layouts is not None:
        if layouts < 2:
            from ...errors import UsageError

            raise UsageError(
                f"dem_ensemble --layouts: at least 2 (a paired interval), got {layouts}"
            )
        cfg["layouts"] = int(layouts)
    cfg["cases"], cfg["comparisons"] = select(cfg["cases"], cfg["comparisons"], cases)
    if laws is not None:
        unknown = [law for law in laws if law not in LAWS]
        if unknown or not laws:
            from ...errors import UsageError

            raise UsageError(
                f"dem_ensemble --laws: {', '.join(unknown) or 'none given'}: choose from "
                f"{', '.join(LAWS)}"
            )
        cfg["laws"] = tuple(laws)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "dem_ensemble.json"
    start = time.perf_counter()
    from . import dem_scenes

    # Records made before [ice] slide_resolution became 0.025 (2026-11-27) took the slide in
    # one step and do not name it: their runs are not reused under another resolution.
    slide = dem_scenes.pillar("rate-state").ice.slide_resolution
    kept = {}
    if reuse and path.is_file():
        old = json.loads(path.read_text())
        was = old["settings"].get("slide_resolution", 0.0)
        same = (
            old["settings"]["layouts"],
            old["settings"]["until_s"],
            was,
            old["settings"].get("mu"),
        ) == (cfg["layouts"], cfg["until"], slide, mu)
        if same:
            kept = {(r["law"], r["integrator"], round(r["nominal"], 6)): r for r in old["runs"]}
    runs = []
    for law in cfg["laws"]:
        for integ, ratio in cfg["cases"]:
            r = kept.get((law, integ, round(ratio, 6)))
            if r is None:
                r = run_case(law, integ, ratio, cfg["layouts"], cfg["until"], mu)
                r["nominal"] = ratio
            runs.append(r)
            log(
                f"dem ensemble: {law}, {integ} at {ratio:g} stable_dt, {cfg['layouts']} layouts "
                f"to {cfg['until']:g} s: {r['status']} [{r['wall_s']:.1f} s]"
                + (f" ({r['failure']})" if r.get("failure") else "")
            )
    summary = {
        "settings": {
            "layouts": cfg["layouts"],
            "until_s": cfg["until"],
            "slide_resolution": slide,
            "mu": mu,
            "laws": list(cfg["laws"]),
            "cases": [list(c) for c in cfg["cases"]],
            "comparisons": [[list(a), list(b)] for a, b in cfg["comparisons"]],
            "within": "the paired shift's 95 % t interval holds 0",
            "differs": f"Holm-adjusted Wilcoxon (McNemar) p < {ALPHA} over every test of the run",
        },
        "runs": runs,
        "comparisons": compare(runs, cfg["laws"], cfg["comparisons"]),
    }
    summary["wall_s"] = time.perf_counter() - start
    for key, c in summary["comparisons"].items():
        if not c["peak_force"]["n"]:
            log(f"dem ensemble: {key}: no layout to compare (a batch stopped)")
            continue
        shifts = ", ".join(f"{m} {_shift(c[m])}" for m in MEASURES)
        rel = c["released"]
        log(
            f"dem ensemble: {key}: {shifts}; released {rel['base']} -> {rel['other']} "
            f"(McNemar p {rel['p']:.2g}); "
            + ("DIFFERS (Holm)" if c["any_differs"] else "no shift beyond the sampling error")
        )
    path.write_text(json.dumps(summary, indent=1) + "\n")
    plot(summary, out_dir / "dem_ensemble.png")
    log(f"dem ensemble: wrote {path} and dem_ensemble.png [{summary['wall_s']:.0f} s]")
    return summary


__all__ = ["compare", "holm", "mcnemar", "paired", "run", "run_case"]
