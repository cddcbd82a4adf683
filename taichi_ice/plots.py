"""Figures of a run file: probe force, energy budget, bird's-eye snapshots, animation.

Matplotlib is imported inside the functions (Agg backend), never at module level.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .io import read_run

KIND_COLOURS = {"dynamic": "#9ecae1", "fixed": "#7f7f7f", "kinematic": "#fdae6b"}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def outlines(run: dict, frame: int) -> list[np.ndarray]:
    """World outlines ``(n_i, 2)`` of every body at one frame of a run (from ``read_run``)."""
    b, fr = run["bodies"], run["frames"]
    off, verts = b["vertex_offsets"], b["vertices"]
    pos, ang = fr["position"][frame], fr["angle"][frame]
    out = []
    for i in range(len(off) - 1):
        v = verts[off[i] : off[i + 1]]
        c, s = np.cos(ang[i]), np.sin(ang[i])
        out.append(v @ np.array([[c, s], [-s, c]]) + pos[i])
    return out


def draw_bodies(ax, run: dict, frame: int) -> None:
    """Filled outlines of every body at ``frame`` on ``ax``: walls grey, pushers orange."""
    from matplotlib.collections import PolyCollection

    kinds = run["bodies"]["kinds"]
    polys = outlines(run, frame)
    colours = [KIND_COLOURS.get(k, "#cccccc") for k in kinds]
    ax.add_collection(PolyCollection(polys, facecolors=colours, edgecolors="k", linewidths=0.4))
    pts = np.concatenate(polys)
    ax.set_xlim(pts[:, 0].min(), pts[:, 0].max())
    ax.set_ylim(pts[:, 1].min(), pts[:, 1].max())
    ax.set_aspect("equal")


def plot_run(
    path: str | Path, out_dir: str | Path | None = None, animate: bool = False, snapshots: int = 6
) -> list[Path]:
    """Write the figures of one run file; returns their paths.

    Figures: ``<stem>_probe_force.png`` (force magnitude on each probe body against time),
    ``<stem>_energy.png`` (every budget term and the residual), ``<stem>_positions.png``
    (bird's-eye snapshots), and with ``animate`` ``<stem>.gif`` (blocks beside the probe force).
    """
    from .simulation import energy_residual

    plt = _pyplot()
    path = Path(path)
    out = Path(out_dir) if out_dir else path.parent
    out.mkdir(parents=True, exist_ok=True)
    run = read_run(path)
    s, names = run["series"], run["bodies"]["names"]
    t = s["time"]
    written = []
    title = f"{path.stem}: {run['attrs'].get('friction', '')}, status {run['attrs']['status']}"

    fig, ax = plt.subplots(figsize=(7, 3.5))
    probes = run["bodies"]["probe_index"]
    for k, idx in enumerate(probes):
        ax.plot(t, np.linalg.norm(s["probe_force"][:, k], axis=-1) / 1e3, lw=0.8, label=names[idx])
    ax.set_xlabel("time (s)")
    ax.set_ylabel("contact force (kN)")
    ax.set_title(title, fontsize=9)
    if len(probes):
        ax.legend(fontsize=8)
    written.append(_save(fig, out / f"{path.stem}_probe_force.png"))

    fig, ax = plt.subplots(figsize=(7, 4))
    for name in (
        "work_in",
        "kinetic_energy",
        "elastic_energy",
        "friction_energy",
        "viscous_energy",
        "drag_energy",
    ):
        ax.plot(t, s[name], label=name.replace("_", " "))
    ax.plot(t, energy_residual(s), "k--", label="residual")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("energy (J)")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8, ncol=2)
    written.append(_save(fig, out / f"{path.stem}_energy.png"))

    n_frames = len(run["frames"]["time"])
    picks = np.unique(np.linspace(0, n_frames - 1, min(snapshots, n_frames)).round().astype(int))
    fig, axes = plt.subplots(1, len(picks), figsize=(2.4 * len(picks), 4), squeeze=False)
    for ax, f in zip(axes[0], picks, strict=True):
        draw_bodies(ax, run, f)
        ax.set_title(f"t = {run['frames']['time'][f]:.1f} s", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    written.append(_save(fig, out / f"{path.stem}_positions.png"))

    if animate:
        written.append(animate_run(run, out / f"{path.stem}.gif"))
    return written


def animate_run(run: dict, path: Path, fps: int = 10) -> Path:
    """GIF of the bodies beside the probe force, one image per frame."""
    plt = _pyplot()
    from matplotlib.animation import FuncAnimation, PillowWriter

    s, fr = run["series"], run["frames"]
    force = (
        np.linalg.norm(s["probe_force"], axis=-1).sum(axis=-1) / 1e3
        if s["probe_force"].size
        else np.zeros_like(s["time"])
    )
    fig, (ax_b, ax_f) = plt.subplots(1, 2, figsize=(8, 4), gridspec_kw={"width_ratios": [1, 1.4]})

    def draw(f):
        ax_b.clear()
        draw_bodies(ax_b, run, f)
        ax_b.set_title(f"t = {fr['time'][f]:.1f} s", fontsize=9)
        ax_f.clear()
        ax_f.plot(s["time"], force, lw=0.6, color="0.6")
        now = s["time"] <= fr["time"][f]
        ax_f.plot(s["time"][now], force[now], lw=0.9, color="C3")
        ax_f.set_xlabel("time (s)")
        ax_f.set_ylabel("probe force (kN)")

    anim = FuncAnimation(fig, draw, frames=len(fr["time"]))
    anim.save(path, writer=PillowWriter(fps=fps))
    plt.close(fig)
    return path


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path
