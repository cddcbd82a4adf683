"""The study's report: study.json (every number, every world's values), study.md (the
tables, for people), study.nc (every world's values, for xarray) and the figures.

The statistics are ``stats``'s, the design ``design``'s, the running ``run``'s.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..metrics import JAM_FORCE, JAM_FORCES
from .design import MODELS
from .stats import (
    ALPHA,
    BOOTSTRAP_RESAMPLES,
    BOOTSTRAP_SEED,
    CONFIDENCE,
    POWER,
    RATE_STATE_ROLES,
    carriers,
    cells,
    describe,
    effective_mu,
    family,
    step_bias,
    stratum_claims,
    world_rows,
)

__all__ = ["study_markdown", "study_summary", "write_dataset", "write_report"]


def _strength_label(strength: float | None) -> str:
    return "no strength" if strength is None else f"{strength / 1e6:g} MPa"


def study_summary(results: dict, *, until: float, arch: str, precision: str) -> dict:
    """study.json's content (but its wall time) from ``run.run_arms``' ``results``."""
    from ...physics.friction_parse import law_from_table
    from ...scene.parse import load_scenario

    rows = world_rows(results)
    arms = {name: arm for name, (arm, _, _) in results.items()}
    described = {name: describe(cells(rows, name)) for name in arms}
    families = {}
    for strength in dict.fromkeys(a.strength for a in arms.values() if a.kind != "step"):
        strata = {
            f"{a.fraction:g}": stratum_claims(cells(rows, name))
            for name, a in arms.items()
            if a.kind in ("stratum", "strength") and a.strength == strength
        }
        if strata:
            families[_strength_label(strength)] = family(strata)
    steps = []
    for name, a in arms.items():
        if a.kind != "step":
            continue
        base = next(n for n, b in arms.items() if b.kind == "stratum" and b.fraction == a.fraction)
        default, half = cells(rows, base, a.seeds), cells(rows, name)
        steps.append(
            {
                "arm": name,
                "against": base,
                "area_fraction": a.fraction,
                "dt_safety": a.dt_safety,
                "rows": step_bias(default, half, cells(rows, base)),
                "claims": step_claims(default, half),
            }
        )
    scene = load_scenario("pillar")
    speed = max(float(np.hypot(*b.velocity)) for b in scene.bodies if b.kind == "kinematic")
    status: dict = {}
    for r in rows:
        status[r["status"]] = status.get(r["status"], 0) + 1
    return {
        "scene": "pillar",
        "until": until,
        "arch": arch,
        "precision": precision,
        "models": [label for label, _ in MODELS],
        "design": [
            {
                "arm": name,
                "kind": a.kind,
                "area_fraction": a.fraction,
                "layouts": a.layouts,
                "seeds": [a.seeds[0], a.seeds[-1]],
                "dt_safety": a.dt_safety,
                "strength": a.strength,
            }
            for name, a in arms.items()
        ],
        "jam_force_N": JAM_FORCE,
        "jam_forces_N": sorted(JAM_FORCES.values()),
        "alpha": ALPHA,
        "power": POWER,
        "confidence": CONFIDENCE,
        "bootstrap": {"resamples": BOOTSTRAP_RESAMPLES, "seed": BOOTSTRAP_SEED},
        "worlds": len(rows),
        "status": status,
        "runs": {name: log for name, (_, _, log) in results.items()},
        "pusher_speed": speed,
        "effective_mu": {
            label: effective_mu(law_from_table(t), speed)
            for label, t in MODELS
            if label in RATE_STATE_ROLES
        },
        "described": described,
        "claims": families,
        "carriers": {k: carriers(v) for k, v in families.items()},
        "step_bias": steps,
        "per_world": [
            {
                k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in r.items()
            }
            for r in rows
        ],
    }


def step_claims(default: dict, half: dict) -> list[dict]:
    """Every claim on the same layouts at the default step and at half of it: each one's
    effect, interval and unadjusted p at both, so a reader sees whether the step moves a
    verdict (Holm's adjustment is the main table's; these are on fewer layouts)."""
    out = []
    for d, h in zip(stratum_claims(default), stratum_claims(half)):
        out.append(
            {
                "claim": d["claim"],
                "model": d.get("model"),
                "direction": d["direction"],
                **{
                    key: {k: c[k] for k in ("n", "effect", "ci", "p")}
                    for key, c in (("default", d), ("half", h))
                },
            }
        )
    return out


def write_dataset(rows: list[dict], path: Path) -> Path:
    """study.nc: every world's values (``per_world``) on a dimension ``world``, with the
    metrics' units and long names (``metrics.METRIC_INFO``)."""
    import xarray as xr

    from ..metrics import METRIC_INFO

    keys = list(dict.fromkeys(k for r in rows for k in r))
    data = {}
    for k in keys:
        values = [r.get(k) for r in rows]
        if all(isinstance(v, str) for v in values):
            arr = np.array(values, dtype=str)
        elif all(isinstance(v, int) and not isinstance(v, bool) for v in values):
            arr = np.array(values, dtype=np.int64)
        else:
            arr = np.array([math.nan if v is None else float(v) for v in values])
        units, long_name = METRIC_INFO.get(k, ("1", k.replace("_", " ")))
        data[k] = ("world", arr, {"units": units, "long_name": long_name})
    ds = xr.Dataset(data, coords={"world": np.arange(len(rows))})
    ds.attrs.update(
        {
            "Conventions": "CF-1.8",
            "title": "taichi-ice study: every world's values",
            "source": "taichi-ice study",
        }
    )
    ds.to_netcdf(path)
    return path


def write_report(
    results: dict, out, *, until: float = 20.0, arch: str = "cpu", precision: str = "f64"
) -> dict:
    """study.md, study.nc and the figures into ``out``; returns study.json's content (the
    caller writes it, with its wall time)."""
    from .figures import plot_distributions, plot_phase_map, plot_release, plot_step_bias

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary = study_summary(results, until=until, arch=arch, precision=precision)
    write_dataset(summary["per_world"], out / "study.nc")
    figures = out / "figures"
    figures.mkdir(parents=True, exist_ok=True)
    plot_phase_map(summary, figures / "study_phase_map.png")
    plot_release(summary, figures / "study_release.png")
    plot_distributions(summary, figures / "study_distributions.png")
    if summary["step_bias"]:
        plot_step_bias(summary, figures / "study_step_bias.png")
    (out / "study.md").write_text(study_markdown(summary))
    return summary


# --------------------------------------------------------------------------------------------
# study.md
# --------------------------------------------------------------------------------------------


def _p(x: float) -> str:
    return f"{x:.2g}" if x >= 1e-3 else f"{x:.1e}"


def _prop(e: dict) -> str:
    if not e["n"]:
        return "-"
    lo, hi = e["ci"]
    return f"{e['k']}/{e['n']} [{lo:.2f}, {hi:.2f}]"


def _quart(e: dict, scale: float = 1.0, fmt: str = ".3g") -> str:
    if not e.get("n"):
        return "-"
    return f"{e['median'] * scale:{fmt}} [{e['q25'] * scale:{fmt}}, {e['q75'] * scale:{fmt}}]"


def _release(e: dict) -> str:
    if not e["n"]:
        return "-"
    median = "not reached" if e["median"] is None else f"{e['median']:.1f} s"
    said = f"{median} ({e['events']} of {e['n']} released"
    if e["censored_followup_median"] is not None:
        said += f"; the others followed {e['censored_followup_median']:.1f} s"
    return said + ")"


def describe_table(entry: dict) -> list[str]:
    """One arm's description: a row per model."""
    lines = [
        "| model | jam > 5 kN | jam > 10 kN | jam > 20 kN | held at the end | median time to "
        "release (KM) | share of time above 10 kN | peak force (kN) | frictional energy (kJ) "
        "| largest 1-s share |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for model, e in entry.items():
        lines.append(
            f"| {model} | {_prop(e['jam_5kN'])} | {_prop(e['jam'])} | {_prop(e['jam_20kN'])} "
            f"| {_prop(e['held'])} | {_release(e['release'])} "
            f"| {_quart(e['jammed_fraction'], 1.0, '.2f')} | {_quart(e['peak_force'], 1e-3)} "
            f"| {_quart(e['friction_energy'], 1e-3)} | {_quart(e['concentration'], 1.0, '.2f')} |"
        )
    return lines


def claims_table(claims: list[dict]) -> list[str]:
    lines = [
        "| stratum | claim | model | statement | test | effect [95 % CI] | p | p (Holm) "
        "| layouts run / for 80 % power | verdict |",
        "|---|---|---|---|---|---:|---:|---:|---:|---|",
    ]
    for c in claims:
        lo, hi = c["ci"]
        effect = f"{c['effect']:+.3g} [{lo:+.3g}, {hi:+.3g}]"
        if "counts" in c:
            effect += f" ({c['counts']})"
        need = c["n_needed"] if c["n_needed"] is not None else "-"
        lines.append(
            f"| {c['stratum']} | {c['claim']} | {c.get('model', '')} | {c['statement']} "
            f"| {c['test']} | {effect} | {_p(c['p'])} | {_p(c['p_holm'])} "
            f"| {c['n']} / {need} | **{c['verdict']}** |"
        )
    return lines


def step_table(step: dict) -> list[str]:
    lines = [
        "| model | measure | n | mean at the default step | shift [95 % CI] | relative "
        "| Wilcoxon p (Holm) | KS D (p) | median shift [95 % CI] | shift / SE of a stratum "
        "mean |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in step["rows"]:
        if "mcnemar" in r:
            continue
        lo, hi = r["ci"]
        q = next(x for x in r["quantiles"] if x["q"] == 0.5)
        lines.append(
            f"| {r['model']} | {r['measure']} | {r['n']} | {r['default_mean']:.3g} "
            f"| {r['shift']:+.3g} [{lo:+.3g}, {hi:+.3g}] | {r['relative']:+.0%} "
            f"| {_p(r['wilcoxon_p'])} ({_p(r['wilcoxon_p_holm'])}) "
            f"| {r['ks']['statistic']:.2f} ({_p(r['ks']['p'])}) "
            f"| {q['shift']:+.3g} [{q['low']:+.3g}, {q['high']:+.3g}] "
            f"| {r['shift_over_se']:.2f} |"
        )
    lines += [
        "",
        "Each claim on these layouts at both steps (effect [95 % CI], unadjusted p):",
        "",
        "| claim | model | default step | half step |",
        "|---|---|---:|---:|",
    ]
    for c in step["claims"]:
        cells = []
        for key in ("default", "half"):
            e = c[key]
            lo, hi = e["ci"]
            cells.append(f"{e['effect']:+.3g} [{lo:+.3g}, {hi:+.3g}], p {_p(e['p'])}")
        lines.append(f"| {c['claim']} | {c['model'] or ''} | {cells[0]} | {cells[1]} |")
    binary = [r for r in step["rows"] if "mcnemar" in r]
    lines += ["", "| model | outcome | default step | half step | discordant | McNemar p |"]
    lines += ["|---|---|---:|---:|---:|---:|"]
    for r in binary:
        m = r["mcnemar"]
        lines.append(
            f"| {r['model']} | {r['measure']} | {m['a']}/{m['n']} | {m['b']}/{m['n']} "
            f"| {m['only_a']} vs {m['only_b']} | {_p(m['p'])} |"
        )
    return lines


def study_markdown(s: dict) -> str:
    """study.md: the tables of study.json, for people."""
    lines = [
        "# The study: jams at a pillar, by stratum, friction model, step and ice strength",
        "",
        f"Scene `pillar`, {s['worlds']} worlds of {s['until']:g} s, {s['arch']}/"
        f"{s['precision']}; status: {', '.join(f'{k} {v}' for k, v in s['status'].items())}. "
        "Each arm is a stratum (area fraction) at one step and strength, every model on the "
        "same layouts (paired); the strata draw their own layouts (independent).",
        "",
        "| arm | kind | area fraction | layouts (seeds) | step (x stable limit) | strength "
        "| wall time (s) | world-steps/s |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for d in s["design"]:
        runs = s["runs"][d["arm"]]
        wall = sum(r["wall_time"] for r in runs)
        steps = sum(r["world_steps"] for r in runs)
        lines.append(
            f"| {d['arm']} | {d['kind']} | {d['area_fraction']:g} | {d['layouts']} "
            f"({d['seeds'][0]}-{d['seeds'][1]}) | {d['dt_safety'] or 'default'} "
            f"| {_strength_label(d['strength'])} | {wall:.0f} | {steps / max(wall, 1e-9):.0f} |"
        )
    lines += [
        "",
        f"A jam: peak pillar force above {s['jam_force_N'] / 1e3:g} kN (also 5 and 20 kN). "
        "Held at the end: a jam whose force over the last second is not below a tenth of its "
        "peak. Time to release: from the peak to the first second whose mean force is below "
        "a tenth of it, over the layouts that jammed, Kaplan-Meier with the run's end as "
        "censoring; the runs not released were followed (from their peak to the end) the "
        "median time given: 0 s where the peak is the last sample, a jam still building. "
        "Proportions: k/n [exact 95 % CI]; measures: median [quartiles].",
        "",
    ]
    for d in s["design"]:
        lines += [f"## {d['arm']}", "", *describe_table(s["described"][d["arm"]]), ""]
    for label, claims in s["claims"].items():
        lines += [
            f"## The paper's claims, tested ({label})",
            "",
            "Within each stratum, on the same layouts (paired). Holds: Holm-adjusted p <= "
            f"{s['alpha']:g} over the {len(claims)} claims of this table, and the effect on the "
            "claimed side; contradicted: on the other side; else undecided. Effects: "
            "one-proportion claims, the proportion - 1/2 [exact CI]; paired 0/1 outcomes, the "
            "share of the discordant layouts (one model alone has it) that are the first "
            "model's - 1/2 [exact CI]; measures, the mean paired difference [bootstrap CI]. "
            "The last numeric column: layouts run, and layouts for "
            f"{s['power']:.0%} power at the observed effect.",
            "",
        ]
        lines += [*claims_table(claims), ""]
        lines += ["| stratum | claim | rate-state | steady-state | memory-only | carried by |"]
        lines += ["|---|---|---|---|---|---|"]
        for c in s["carriers"][label]:
            v = c["verdicts"]
            lines.append(
                f"| {c['stratum']} | {c['claim']} | {v['rate-state']} | {v['steady-state']} "
                f"| {v['memory-only']} | {c['carried_by']} |"
            )
        lines.append("")
    for step in s["step_bias"]:
        lines += [
            f"## The step's bias: {step['arm']} against {step['against']}",
            "",
            f"The same layouts at {step['dt_safety']:g} x the stable limit (half the Euler "
            "step's 0.2, Coulomb's default until 2026-12-02, since then the midstep step at "
            "0.6; the laws with a memory default to 0.05 since 2026-11-28, a study run before "
            "ran them at 0.2). "
            "Shift: this step minus default, mean over layouts [bootstrap CI]; shift / SE: its "
            "size against the standard error of the stratum's mean at the default step (the "
            "claims' sampling error; below 1: smaller).",
            "",
        ]
        lines += [*step_table(step), ""]
    lines += [
        "Effective mu (steady-state friction at the pusher's speed, "
        f"{s['pusher_speed']:g} m/s): "
        + ", ".join(f"{k} {v:.3f}" for k, v in s["effective_mu"].items())
        + ".",
    ]
    return "\n".join(lines) + "\n"
