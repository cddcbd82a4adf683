"""The summary of the paper's reproduction: summary.json's content and summary.md.

``build_summary`` gathers per model the single run's metrics, the distribution over the
other layouts and the paper's findings tested layout by layout (``findings``);
``summary_markdown`` writes its tables for people. Running the models (``paper``) and the
figures (``paper.figures``) live elsewhere.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..ensemble import EnsembleResult
from ..models import PAPER_FINDINGS


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
            verdict = "it holds" if f["holds"] else "it does not hold"
            extra = ""
            if "released_in" in f:
                counts = ", ".join(f"{k} {v}" for k, v in f["released_in"].items())
                extra = f" Released by the end, of {summary['seeds']} layouts: {counts}."
            lines.append(
                f"- **{f['claim']}** ({f['measure']}): true in {f['holds_in']} of "
                f"{f['of']} {f['unit']}, so {verdict} (true in more than half is the "
                f"rule).{extra}"
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
