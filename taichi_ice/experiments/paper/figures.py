"""The figures of the paper's reproduction: Figures 4-6 and the energy budget.

Each takes the models' ``EnsembleResult`` (or their run files) and writes one PNG; the
colours and titles are the models' (``models``). Figure 3 is ``validation.single_interface``'s
and the spread chart ``plots.plot_spread``; running the models is ``paper``'s.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..ensemble import EnsembleResult
from ..metrics import probe_force_magnitude
from ..models import MODEL_COLOURS, MODEL_TITLES, PAPER_FINDINGS

SNAPSHOT_EVERY = 4.0  # s between the bird's-eye views of Figure 4, as in the paper


def plot_positions(files: dict[str, Path], path: Path, every: float = SNAPSHOT_EVERY) -> Path:
    """Figure 4: bird's-eye views every ``every`` seconds, one row per model."""
    from ...run.plots import draw_bodies, outlines, save_figure, subplots
    from ...run.runfile_read import read_run

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
    fig, axes = subplots(
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
    return save_figure(fig, path)


def plot_pillar_force(results: dict[str, EnsembleResult], path: Path) -> Path:
    """Figure 5: magnitude of the force on the pillar against time, one panel per model."""
    from ...run.plots import save_figure, subplots

    fig, axes = subplots(2, 2, figsize=(9, 5.5), squeeze=False)
    for ax, (label, ens) in zip(axes.flat, results.items()):
        s = ens.series[0]
        ax.plot(s["time"], probe_force_magnitude(s) / 1e3, lw=0.7, color=MODEL_COLOURS.get(label))
        ax.set_title(MODEL_TITLES.get(label, label), fontsize=10)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("force on pillar (kN)")
        ax.set_xlim(0, s["time"][-1])
        ax.set_ylim(bottom=0)
    fig.suptitle("Force on the pillar (mean over each sample interval)", fontsize=10)
    return save_figure(fig, path)


def plot_friction_energy(results: dict[str, EnsembleResult], path: Path) -> Path:
    """Figure 6: cumulative frictional dissipation, every model on one axes (log scale).

    The single runs are the thick lines; the other layouts are the thin ones.
    """
    from ...run.plots import save_figure, subplots

    fig, ax = subplots(figsize=(7, 4.2))
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
    return save_figure(fig, path)


def plot_energy_budget(results: dict[str, EnsembleResult], path: Path) -> Path:
    """Every term of each single run's energy budget, with the residual on its own axis."""
    from ...run.budget import DISSIPATED, HELD, residual
    from ...run.plots import save_figure, subplots

    fig, axes = subplots(2, 2, figsize=(10, 6.5), squeeze=False)
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
    return save_figure(fig, path)
