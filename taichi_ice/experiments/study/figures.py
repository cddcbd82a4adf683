"""The study's figures, each from study.json's content (``report.study_summary``): a reader
with study.json alone can draw them again."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..models import MODEL_COLOURS

__all__ = ["plot_distributions", "plot_phase_map", "plot_release", "plot_step_bias"]

COLOURS = {**MODEL_COLOURS, "mu0.3": "C9", "mu0.7": "C6"}


def _arms(s: dict, kinds=("stratum", "control")) -> list[dict]:
    return [d for d in s["design"] if d["kind"] in kinds]


def plot_phase_map(s: dict, path: Path) -> Path:
    """P(jam) per model (rows) and stratum (columns, the control included), at the three
    thresholds side by side, with the counts and exact intervals written in."""
    from ...run.plots import save_figure, subplots

    arms = sorted(_arms(s), key=lambda d: d["area_fraction"])
    models = s["models"]
    names = (("jam_5kN", "5 kN"), ("jam", "10 kN"), ("jam_20kN", "20 kN"))
    fig, axes = subplots(1, 3, figsize=(13, 5), sharey=True)
    for ax, (name, said) in zip(axes, names):
        p = np.array([[s["described"][d["arm"]][m][name]["value"] for d in arms] for m in models])
        im = ax.imshow(p, vmin=0, vmax=1, cmap="viridis", aspect="auto")
        for i, m in enumerate(models):
            for j, d in enumerate(arms):
                e = s["described"][d["arm"]][m][name]
                ax.text(
                    j,
                    i,
                    f"{e['k']}/{e['n']}\n[{e['ci'][0]:.2f}, {e['ci'][1]:.2f}]",
                    ha="center",
                    va="center",
                    fontsize=7,
                    color="w" if e["value"] < 0.6 else "k",
                )
        ax.set_xticks(range(len(arms)), [f"{d['area_fraction']:g}" for d in arms])
        ax.set_yticks(range(len(models)), models)
        ax.set_xlabel("area fraction (stratum)")
        ax.set_title(f"P(peak pillar force > {said}), exact 95 % CI", fontsize=10)
    fig.colorbar(im, ax=axes[-1], label="share of layouts")
    return save_figure(fig, path)


def plot_release(s: dict, path: Path) -> Path:
    """Kaplan-Meier curves of the time from the peak to the largest jam's release, per model,
    one panel per jamming stratum (no strength); ticks mark censored runs' ends."""
    from ...run.plots import save_figure, subplots

    arms = _arms(s, ("stratum",))
    fig, axes = subplots(1, len(arms), figsize=(6 * len(arms), 4.2), sharey=True, squeeze=False)
    for ax, d in zip(axes[0], arms):
        for m in s["models"]:
            e = s["described"][d["arm"]][m]["release"]
            if not e["n"]:
                continue
            km = e["curve"]
            t = np.concatenate([[0.0], np.repeat(km["times"], 2)])
            v = np.concatenate([[1.0, 1.0], np.repeat(km["survival"], 2)[:-1]])
            if km["times"]:
                t = np.append(t, s["until"])
                v = np.append(v, km["survival"][-1])
            else:
                t, v = np.array([0.0, s["until"]]), np.array([1.0, 1.0])
            ax.plot(t, v, color=COLOURS.get(m, "k"), label=f"{m} ({e['events']}/{e['n']})")
        ax.set_title(f"area fraction {d['area_fraction']:g}: jams still held", fontsize=10)
        ax.set_xlabel("time since the peak force (s)")
        ax.set_ylim(-0.02, 1.02)
        if ax.get_lines():
            ax.legend(fontsize=7, title="released / jammed", title_fontsize=7)
        else:
            ax.text(0.5, 0.5, "no jams", ha="center", transform=ax.transAxes)
    axes[0][0].set_ylabel("share of the jams not yet released (Kaplan-Meier)")
    return save_figure(fig, path)


def plot_distributions(s: dict, path: Path) -> Path:
    """Every layout's peak force, frictional energy, share of time jammed and energy
    concentration per model, one row per stratum (the control included)."""
    from ...run.plots import save_figure, subplots

    arms = sorted(_arms(s), key=lambda d: -d["area_fraction"])
    measures = (
        ("peak_force", "peak pillar force (N)", True),
        ("friction_energy", "frictional energy (J)", True),
        ("jammed_fraction", "share of time above 10 kN", False),
        ("concentration", "largest 1-s share of the frictional energy", False),
    )
    fig, axes = subplots(len(arms), 4, figsize=(16, 3.4 * len(arms)), squeeze=False)
    rng = np.random.default_rng(0)
    for row, d in zip(axes, arms):
        worlds = [w for w in s["per_world"] if w["arm"] == d["arm"]]
        for ax, (name, said, log) in zip(row, measures):
            for i, m in enumerate(s["models"]):
                y = np.array([w[name] for w in worlds if w["model"] == m and w[name] is not None])
                if log:
                    y = np.maximum(y, 1e-3)
                x = i + rng.uniform(-0.25, 0.25, y.size)
                ax.plot(x, y, ".", ms=3, alpha=0.6, color=COLOURS.get(m, "k"))
                if y.size:
                    ax.plot([i - 0.35, i + 0.35], [np.median(y)] * 2, color="k", lw=1.5)
            if log:
                ax.set_yscale("log")
            ax.set_xticks(range(len(s["models"])), s["models"], rotation=60, fontsize=7)
            ax.set_title(f"{said}, area fraction {d['area_fraction']:g}", fontsize=9)
    return save_figure(fig, path)


def plot_step_bias(s: dict, path: Path) -> Path:
    """Each layout's measure at half the step against at the default step (the line: no
    shift), per measure, every model."""
    from ...run.plots import save_figure, subplots

    step = s["step_bias"][0]
    names = ("peak_force", "friction_energy", "jammed_fraction", "concentration")
    fig, axes = subplots(1, 4, figsize=(16, 4))
    by = {}
    for w in s["per_world"]:
        if w["arm"] in (step["arm"], step["against"]):
            by[(w["arm"], w["model"], w["seed"])] = w
    for ax, name in zip(axes, names):
        lo, hi = np.inf, -np.inf
        for m in s["models"]:
            pairs = [
                (by[(step["against"], m, seed)][name], w[name])
                for (arm, model, seed), w in by.items()
                if arm == step["arm"] and model == m and (step["against"], m, seed) in by
            ]
            pairs = [(a, b) for a, b in pairs if a is not None and b is not None]
            if not pairs:
                continue
            a, b = np.array(pairs).T
            ax.plot(a, b, ".", ms=4, alpha=0.7, color=COLOURS.get(m, "k"), label=m)
            lo, hi = min(lo, a.min(), b.min()), max(hi, a.max(), b.max())
        if np.isfinite(lo):
            ax.plot([lo, hi], [lo, hi], "k-", lw=0.8)
        if name in ("peak_force", "friction_energy") and lo > 0:
            ax.set_xscale("log")
            ax.set_yscale("log")
        ax.set_xlabel("default step")
        ax.set_ylabel("half step")
        ax.set_title(name.replace("_", " "), fontsize=10)
    axes[0].legend(fontsize=7)
    return save_figure(fig, path)
