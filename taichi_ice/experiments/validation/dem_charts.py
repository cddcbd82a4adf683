"""Charts of the DEM accuracy study: error against cost, and parting runs with the limits.

``plot_accuracy``: one panel per measure (``dem_analysis.MEASURES``), error against wall time
per simulated second; colour is the law and the integrator (circles Euler, squares the
analytic step), solid float64 and dashed float32, filled markers at or below the computed
stability limit and open ones beyond it, a ring at the default step (0.2 stable_dt); runs
that diverged are crosses on the top edge. Along a line the step grows from left to right
(the cost falls as 1 / dt); labels give dt / stable_dt.

``plot_stability``: (a) the largest distance between the same block in two runs of the
pillar scene over time: runs that differ in the last bit of one position, and runs at a step
and a quarter of it; (b) each stability trial at its dt / stable_dt, survived or diverged,
per scene and integrator, with the computed limit (1), the default and each integrator's
recommended dt_safety.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ...physics.timestep import DEFAULT_SAFETY, MIDSTEP_SAFETY
from .dem_analysis import MEASURES, PART, integrator_of, label

# Colour of each law with each integrator (``dem_analysis.label``), marker of each integrator.
COLORS = {
    "coulomb": "C0",
    "rate-state": "C3",
    "coulomb, analytic": "C2",
    "rate-state, analytic": "C1",
    "coulomb, coupled": "C4",
    "rate-state, coupled": "C5",
    "coulomb, midstep": "C6",
    "rate-state, midstep": "C8",
}
MARKERS = {"euler": "o", "analytic": "s", "coupled": "^", "midstep": "D"}
INTEGRATOR_COLORS = {"euler": "C0", "analytic": "C2", "coupled": "C4", "midstep": "C6"}
STYLES = {"f64": "-", "f32": "--"}
UNITS = {"positions": "largest block displacement (m)"}


def plot_accuracy(summary: dict[str, Any], path: Path) -> None:
    from matplotlib.lines import Line2D
    from matplotlib.ticker import NullFormatter

    from ...run.plots import subplots

    panels = [(s, m) for s, ms in MEASURES.items() for m in ms]
    fig, axes = subplots(3, 3, figsize=(14, 11.5), layout="constrained")
    points = summary["points"]
    for ax, (scene, measure) in zip(axes.flat, panels):
        mine = [p for p in points if p["scene"] == scene and p["measure"] == measure]
        top = max([p["error"] for p in mine if p["error"]] or [1.0]) * 3.0
        for name in COLORS:
            for prec in STYLES:
                line = sorted(
                    (
                        p
                        for p in mine
                        if label(p["law"], integrator_of(p)) == name
                        and p["precision"] == prec
                        and p["wall_per_simulated_s"]
                    ),
                    key=lambda p: p["ratio"],
                )
                ok = [p for p in line if p["error"] is not None and p["error"] > 0]
                if not line:
                    continue
                x = [p["wall_per_simulated_s"] for p in ok]
                y = [p["error"] for p in ok]
                color, ls = COLORS[name], STYLES[prec]
                marker = MARKERS[integrator_of(line[0])]
                ax.loglog(x, y, ls=ls, color=color, lw=1.0)
                for p in ok:
                    beyond = p["ratio"] > 1.0
                    ax.plot(
                        p["wall_per_simulated_s"],
                        p["error"],
                        marker,
                        ms=4,
                        color=color,
                        mfc="none" if beyond else color,
                    )
                    if abs(p["ratio"] / 0.2 - 1.0) < 0.05:
                        ax.plot(
                            p["wall_per_simulated_s"],
                            p["error"],
                            "o",
                            ms=9,
                            mfc="none",
                            color="k",
                            lw=0.8,
                        )
                for p in line:
                    if p["error"] is None:
                        ax.plot(p["wall_per_simulated_s"], top, "x", color=color, ms=6)
                if line[0]["law"] == "coulomb" and prec == "f64":
                    for p in ok:
                        ax.annotate(
                            f"{p['ratio']:.2g}",
                            (p["wall_per_simulated_s"], p["error"]),
                            textcoords="offset points",
                            xytext=(2, -9),
                            fontsize=6,
                            color="0.35",
                        )
        ax.set_title(f"{scene}: {measure}", fontsize=10)
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("wall time per simulated second (s), one world alone")
        ax.set_ylabel(UNITS.get(measure, "relative error"))
        ax.grid(True, which="major", alpha=0.3)
    handles = [
        Line2D([], [], color=c, marker=MARKERS[[*name.split(", "), "euler"][1]], label=name)
        for name, c in COLORS.items()
    ]
    handles += [Line2D([], [], color="k", ls=s, label=p) for p, s in STYLES.items()]
    handles += [
        Line2D([], [], color="k", marker="o", ls="none", label="dt <= stable_dt"),
        Line2D([], [], color="k", marker="o", mfc="none", ls="none", label="dt > stable_dt"),
        Line2D([], [], color="k", marker="o", ms=9, mfc="none", ls="none", label="dt = 0.2 stable"),
        Line2D([], [], color="k", marker="x", ls="none", label="diverged"),
    ]
    axes.flat[0].legend(handles=handles, fontsize=7, loc="lower left", ncol=2)
    windows = ", ".join(
        f"{label(v.get('law', key), integrator_of(v))} {v['window_s']:.3g} s"
        for key, v in summary.get("pillar_reference", {}).items()
    )
    fig.suptitle(
        "DEM accuracy against cost (labels: dt / stable_dt). Collisions against the ODE of the "
        "contact law; pushed box: energy budget residual;\npillar scene: against dt = 0.05 "
        "stable_dt (a quarter of the default step) of the same integrator, until the default "
        f"step's run parts:\n{windows}",
        fontsize=11,
    )
    fig.savefig(path, dpi=75)


def plot_stability(summary: dict[str, Any], path: Path) -> None:
    from ...run.plots import subplots

    fig, (ax, ax2) = subplots(1, 2, figsize=(13, 6.0), layout="constrained")
    for name, c in summary.get("chaos", {}).items():
        gap = np.maximum(np.asarray(c["largest_gap_m"]), 1e-17)
        ax.semilogy(
            c["time"],
            gap,
            color=COLORS.get(name, "k"),
            lw=1.4,
            label=f"{name}: last bit of one x (dt = {c['ratio']:.2g} stable)",
        )
    pairs = [
        p
        for p in summary.get("pillar_parting_at_a_quarter_step", [])
        if p["precision"] == "f64" and "time" in p
    ]
    named = set()  # one legend entry per law and integrator, for all its steps
    for pair in pairs:
        who = label(pair["law"], integrator_of(pair))
        steps = sorted({p["ratio"] for p in pairs if label(p["law"], integrator_of(p)) == who})
        ax.semilogy(
            pair["time"],
            np.maximum(pair["largest_gap_m"], 1e-17),
            ls="--",
            color=COLORS[who],
            alpha=0.5,
            lw=0.9,
            label=None
            if who in named
            else f"{who}: dt = {', '.join(f'{r:.2g}' for r in steps)} vs a quarter",
        )
        named.add(who)
    ax.axhline(PART, color="0.5", lw=0.8)
    ax.text(0.2, PART * 1.5, f"parted ({PART * 100:g} cm)", fontsize=8, color="0.3")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("largest distance between a block and its twin (m)")
    ax.set_title("(a) pillar scene: when do two runs part?")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, loc="lower right")
    rows = _stability_rows(summary)
    recs = summary.get("recommendation", {})
    for row, (integ, _, res) in enumerate(rows):
        for t in res["trials"]:
            ax2.plot(
                t["ratio"],
                row,
                MARKERS.get(integ, "o") if t["survived"] else "x",
                color="C2" if t["survived"] else "C3",
                ms=7,
            )
        lo = res["largest_surviving_ratio"]
        if lo:
            ax2.text(lo, row + 0.18, f"{lo:.2f}", fontsize=8, ha="center")
    ax2.set_yticks(range(len(rows)))
    ax2.set_yticklabels([name if i == "euler" else f"{name} ({i})" for i, name, _ in rows])
    ax2.set_ylim(-0.6, len(rows) - 0.4)
    largest = max((t["ratio"] for _, _, r in rows for t in r["trials"]), default=4.0)
    ax2.set_xlim(0.15, max(4.0, largest * 1.3))
    ax2.set_xscale("log")
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    ax2.xaxis.set_major_formatter(ScalarFormatter())
    ax2.xaxis.set_minor_formatter(NullFormatter())
    ax2.set_xticks([0.2, 0.5, 1.0, 2.0, 3.0])
    ax2.axvline(1.0, color="k", lw=0.8)
    ax2.text(1.02, -0.5, "computed limit", fontsize=8)
    ax2.axvline(DEFAULT_SAFETY, color="0.5", ls=":", lw=1.0)
    ax2.text(DEFAULT_SAFETY * 1.02, -0.5, f"Euler {DEFAULT_SAFETY:g}", fontsize=8, color="0.3")
    ax2.axvline(MIDSTEP_SAFETY, color="0.5", ls="--", lw=1.0)
    ax2.text(
        MIDSTEP_SAFETY * 1.02,
        -0.3,
        f"midstep {MIDSTEP_SAFETY:g} (Coulomb's default)",
        fontsize=8,
        color="0.3",
    )
    for k, (integ, rec) in enumerate(recs.items()):
        if rec.get("dt_safety"):
            color = INTEGRATOR_COLORS.get(integ, "k")
            ax2.axvline(rec["dt_safety"], color=color, ls="--", lw=1.0)
            ax2.text(
                rec["dt_safety"] * 1.02,
                len(rows) - 0.55 - 0.6 * k,
                f"recommended {rec['dt_safety']:g} ({integ})",
                fontsize=8,
                color=color,
            )
    ax2.set_xlabel(
        "dt / stable_dt (o, s, ^, D survived: Euler, analytic, coupled, midstep; x diverged)"
    )
    ax2.set_title("(b) the largest step each scene survives")
    fig.savefig(path, dpi=80)


def _stability_rows(summary: dict[str, Any]) -> list[tuple[str, str, dict[str, Any]]]:
    """(integrator, scene, limit) of every stability search in the summary."""
    return [
        (integ, name, res)
        for integ, limits in summary.get("stability", {}).items()
        for name, res in limits.items()
    ]


# Columns of the error table: the nominal steps (the field scenes' dt is SAMPLE / n, a few
# per cent below the nominal; the JSON has the exact ratios).
NOMINAL = (0.0125, 0.025, 0.05, 0.1, 0.2, 0.4, 0.8, 1.2, 1.6)


def _nominal(ratio: float) -> float:
    return min(NOMINAL, key=lambda n: abs(np.log(ratio / n)))


def _fmt(x, spec: str = ".2g") -> str:
    return "-" if x is None else format(x, spec)


def tables(summary: dict[str, Any]) -> str:
    """The study's numbers as Markdown: errors by step, orders, costs, parting, limits."""
    points = summary["points"]
    out = []
    ratios = sorted({_nominal(p["ratio"]) for p in points})
    rows = sorted(
        {(p["scene"], p["measure"], p["law"], integrator_of(p), p["precision"]) for p in points}
    )
    out.append(
        "Error (relative; positions in m) against dt / stable_dt, nominal (- : not run; "
        "stopped: the run diverged before the comparison's end):\n"
    )
    out.append(
        "| scene: measure | law | integrator | precision | "
        + " | ".join(f"{r:g}" for r in ratios)
        + " |"
    )
    out.append("|---|---|---|---|" + "---:|" * len(ratios))
    for scene, measure, law, integ, prec in rows:
        by = {
            _nominal(p["ratio"]): p
            for p in points
            if (p["scene"], p["measure"], p["law"], integrator_of(p), p["precision"])
            == (scene, measure, law, integ, prec)
        }
        cells = []
        for r in ratios:
            p = by.get(r)
            cells.append(
                "-" if p is None else ("stopped" if p["error"] is None else _fmt(p["error"]))
            )
        out.append(f"| {scene}: {measure} | {law} | {integ} | {prec} | " + " | ".join(cells) + " |")
    out.append("\nConvergence order (float64; scatter in decades; '(no)': not converging):\n")
    columns = [
        (law, integ)
        for integ in summary["settings"].get("integrators", ["euler"])
        for law in summary["settings"]["laws"]
    ]
    out.append("| scene: measure | " + " | ".join(label(*c) for c in columns) + " |")
    out.append("|---|" + "---:|" * len(columns))
    orders = summary["orders"]
    for scene, ms in MEASURES.items():
        for m in ms:
            cells = []
            for law, integ in columns:
                fit = orders.get(f"{scene}: {m}/{law}/{integ}/f64")
                cells.append(
                    "-"
                    if not fit
                    else f"{fit['order']:.2f} ({fit['scatter_decades']:.2f})"
                    + ("" if fit["converges"] else " (no)")
                )
            out.append(f"| {scene}: {m} | " + " | ".join(cells) + " |")
    # How the kernels were compiled (runs from before it was recorded: not said): the
    # setting (off, on, full) since it was recorded, before it the advanced passes' switch.
    how = {True: "with Taichi's advanced passes", False: "without Taichi's advanced passes"}
    compiled = {
        p: f"with TAICHI_ICE_OPTIMIZE={v}"
        for p, v in (summary.get("optimize") or {}).items()
        if v is not None
    } or {
        p: how[v] for p, v in (summary.get("advanced_optimization") or {}).items() if v is not None
    }
    if len(set(compiled.values())) == 1:
        setting = next(iter(compiled.values()))
    else:
        setting = ", ".join(f"{p} {v}" for p, v in sorted(compiled.items()))
    out.append(
        "\nCost: wall time per step of one world alone (us), and per simulated second "
        "at dt = 0.2 stable_dt (s)" + (f"; kernels compiled {setting}" if setting else "") + ":\n"
    )
    out.append("| scene | law | integrator | precision | us per step | s per simulated s at 0.2 |")
    out.append("|---|---|---|---|---:|---:|")
    stable = summary["settings"]["stable_dt"]
    for key, t in summary["timing"].items():
        scene, law, integ, prec = key.split("/")
        sdt = stable["collisions"] if scene == "collision" else stable["pillar, pushed box"]
        # A row without a run alone is a batch's wall per step, compiling included.
        batch = "" if t.get("alone", True) else " (batch, compiling included)"
        out.append(
            f"| {scene} | {law} | {integ} | {prec} | {t['wall_per_step_s'] * 1e6:.0f}{batch} | "
            f"{t['wall_per_step_s'] / (0.2 * sdt):.2f} |"
        )
    out.append("\nWhen two runs of the pillar scene part (a block 1 cm from its twin), s:\n")
    out.append("| runs | law | precision | parted at | compared until |")
    out.append("|---|---|---|---:|---:|")
    for p in summary["pillar_parting_at_a_quarter_step"]:
        out.append(
            f"| {p['ratio']:.2g} against {p['quarter']:.2g} stable_dt | "
            f"{label(p['law'], integrator_of(p))} | "
            f"{p['precision']} | {_fmt(p['parted_at'], '.1f')} | {p['until']:g} |"
        )
    for v in summary.get("pillar_reference", {}).values():
        a = v.get("against_euler")
        if a:
            out.append(
                f"| the references (0.05 stable_dt), {v['integrator']} against euler | "
                f"{v['law']} | f64 | {_fmt(a['parted_at'], '.1f')} | {a['until_s']:.3g} |"
            )
    for name, c in summary["chaos"].items():
        out.append(
            f"| the last bit of one x, at {c['ratio']:.2g} stable_dt | {name} | f64 | "
            f"{_fmt(c['parted_at'], '.1f')} (1e-9 m at {_fmt(c['departed_at'], '.1f')}) "
            f"| {c['until']:g} |"
        )
    rows = _stability_rows(summary)
    if rows:
        out.append(
            "\nThe largest dt / stable_dt each scene survives (bisection; the energy the "
            "bodies hold over what came in, at the last survivor):\n"
        )
        out.append("| scene | integrator | survives | stops | held / in at the survivor |")
        out.append("|---|---|---:|---:|---:|")
        for integ, name, res in rows:
            lo = res["largest_surviving_ratio"]
            held = next(
                (
                    t.get("held_over_energy_in")
                    for t in res["trials"]
                    if t["survived"] and t["ratio"] == lo
                ),
                None,
            )
            out.append(
                f"| {name} | {integ} | {_fmt(lo, '.3f')} | "
                f"{_fmt(res['smallest_failing_ratio'], '.3f')} | {_fmt(held, '.2f')} |"
            )
    for integ, rec in summary.get("recommendation", {}).items():
        out.append(
            f"\nRecommended `dt_safety` with the {integ} integrator: **{rec['dt_safety']}** "
            f"({rec['rule']}).\n"
        )
        by_law = summary.get("recommendation_by_law", {}).get(integ, {})
        for law, r in by_law.items():
            why = r["refused"].get(_next_candidate(r, r["dt_safety"]), "")
            out.append(
                f"- on {law}'s errors alone: **{r['dt_safety']}**, margin in the jam "
                f"{_fmt(r['jam_margin'], '.2f')}" + (f" (the next refused: {why})" if why else "")
            )
        if by_law:
            out.append("")
        names = list(next(iter(rec["candidates"].values()))["errors"])
        out.append("| dt_safety | margin in the jam | " + " | ".join(names) + " |")
        out.append("|---:|---:|" + "---:|" * len(names))
        for s, c in rec["candidates"].items():
            out.append(
                f"| {s} | {_fmt(c['margin'].get('jam'), '.1f')} | "
                + " | ".join(_fmt(c["errors"][n]) for n in names)
                + " |"
            )
    return "\n".join(out) + "\n"


def _next_candidate(rec: dict[str, Any], chosen) -> str | None:
    """The candidate after ``chosen`` in a recommendation's table (None past the last)."""
    keys = list(rec["candidates"])
    if chosen is None:
        return keys[0] if keys else None
    at = keys.index(f"{chosen:g}") if f"{chosen:g}" in keys else len(keys)
    return keys[at + 1] if at + 1 < len(keys) else None


__all__ = ["plot_accuracy", "plot_stability", "tables"]
