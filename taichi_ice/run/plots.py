"""Figures of a run file: probe force, energy budget, bird's-eye snapshots, animation.

Every figure of the package is a bare ``matplotlib.figure.Figure`` (:func:`new_figure`,
:func:`subplots`) written by ``Figure.savefig`` (:func:`save_figure`): neither ``pyplot`` nor
``matplotlib.use`` is touched, so drawing a figure leaves the caller's backend (a notebook's
inline figures, a GUI) and pyplot's figures as they were. Matplotlib is imported inside the
functions, never at module level; the other figures of the package (``paper``, ``study``,
``validate``, ``bench``) are drawn through :func:`subplots` and :func:`save_figure` here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..codes import BodyKind
from ..errors import UsageError
from .runfile_read import frame_contacts, read_run

KIND_COLOURS = {
    BodyKind.DYNAMIC.label: "#9ecae1",
    BodyKind.FIXED.label: "#7f7f7f",
    BodyKind.KINEMATIC.label: "#fdae6b",
}
# Room around the bodies in a shared view, as a share of its longer side: an outline on the
# view's edge keeps its line.
VIEW_MARGIN = 0.02
# What ``subplots`` hands to the Figure itself; every other keyword goes to Figure.subplots.
_FIGURE_KEYWORDS = ("figsize", "dpi", "layout", "facecolor")


def new_figure(**kwargs):
    """A ``matplotlib.figure.Figure(**kwargs)``, attached to no backend and unknown to pyplot:
    ``save_figure`` (or ``fig.savefig``) writes it and the garbage collector frees it."""
    from matplotlib.figure import Figure

    return Figure(**kwargs)


def subplots(nrows: int = 1, ncols: int = 1, **kwargs):
    """``(fig, axes)`` as ``pyplot.subplots`` returns them, on a :func:`new_figure`.

    ``figsize``, ``dpi``, ``layout`` and ``facecolor`` go to the Figure; the rest (``squeeze``,
    ``sharey``, ``gridspec_kw`` ...) to ``Figure.subplots``.
    """
    fig = new_figure(**{k: kwargs.pop(k) for k in _FIGURE_KEYWORDS if k in kwargs})
    return fig, fig.subplots(nrows, ncols, **kwargs)


def world_vertices(run: dict, frame: int) -> np.ndarray:
    """Every body's outline at one frame, in world coordinates (m), stacked ``(V, 2)`` in the
    order of ``bodies/vertices`` (body ``i`` is rows ``vertex_offsets[i]:[i + 1]``)."""
    b, fr = run["bodies"], run["frames"]
    off, verts = b["vertex_offsets"], b["vertices"]
    owner = np.repeat(np.arange(len(off) - 1), np.diff(off))
    ang = fr["angle"][frame][owner]
    c, s = np.cos(ang), np.sin(ang)
    x = c * verts[:, 0] - s * verts[:, 1]
    y = s * verts[:, 0] + c * verts[:, 1]
    return np.stack([x, y], axis=-1) + fr["position"][frame][owner]


def outlines(run: dict, frame: int) -> list[np.ndarray]:
    """World outlines ``(n_i, 2)`` of every body at one frame of a run (from ``read_run``)."""
    return np.split(world_vertices(run, frame), run["bodies"]["vertex_offsets"][1:-1])


def shared_view(run: dict, frames) -> tuple[float, float, float, float]:
    """One view ``(xmin, xmax, ymin, ymax)`` in m for every panel that shows ``frames``.

    The union of every body's outline over those frames, walls and pushers included, plus
    ``VIEW_MARGIN``: a floe that drifts is seen to move against a frame that stays put, and
    it stays in view at each frame. The run's bodies are what frames a scene (its walls and
    channel are fixed bodies in every frame), so no scene-specific box is needed; a view of
    part of a scene (Figure 4's channel) is passed to :func:`draw_bodies` by its caller.
    """
    lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
    for f in frames:
        pts = world_vertices(run, f)
        lo, hi = np.minimum(lo, pts.min(axis=0)), np.maximum(hi, pts.max(axis=0))
    pad = VIEW_MARGIN * max(float(np.max(hi - lo)), 1e-9)
    return (lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad)


def draw_bodies(ax, run: dict, frame: int, view: tuple | None = None) -> None:
    """Filled outlines of every body at ``frame`` on ``ax``: walls grey, pushers orange.

    ``view`` is ``(xmin, xmax, ymin, ymax)`` in m; default every body of this frame in full.
    Panels that show one run at several frames take one view (:func:`shared_view`), or a
    body that moved looks still.
    """
    from matplotlib.collections import PolyCollection

    kinds = run["bodies"]["kinds"]
    polys = outlines(run, frame)
    colours = [KIND_COLOURS.get(k, "#cccccc") for k in kinds]
    ax.add_collection(PolyCollection(polys, facecolors=colours, edgecolors="k", linewidths=0.4))
    if view is None:
        view = shared_view(run, [frame])
    ax.set_xlim(view[0], view[1])
    ax.set_ylim(view[2], view[3])
    ax.set_aspect("equal")


# Force chains on the snapshots (a run with contacts): the line of a contact carrying the most
# normal force of the frames shown is this wide (points); the others in proportion, down to
# the thinnest.
CHAIN_WIDTH = 3.0
CHAIN_THINNEST = 0.2
CHAIN_COLOUR = "#b2182b"


def chain_scale(run: dict, frames) -> float:
    """The largest normal force of any contact at ``frames`` (N; 0 if none): the force
    chains of panels that share a view share it, so their widths compare."""
    if "contacts" not in run:
        return 0.0
    return max(
        (float(np.max(frame_contacts(run, f)["force_normal"], initial=0.0)) for f in frames),
        default=0.0,
    )


def draw_force_chains(ax, run: dict, frame: int, scale: float | None = None) -> int:
    """The contacts of ``frame`` as force chains on ``ax``: a line from one body's centroid
    through the contact point to the other's, as wide as its normal force over ``scale``
    (N; default this frame's largest, :func:`chain_scale`). A wall's or a pusher's end
    stops at the contact point: a chain grounds there, and lines to a long wall's centroid
    would cross the view. Returns the lines drawn (none for a run without contacts)."""
    from matplotlib.collections import LineCollection

    rows = frame_contacts(run, frame)
    if not rows or not len(rows["body_a"]):
        return 0
    position = run["frames"]["position"][frame]
    moves = np.asarray(run["bodies"]["kinds"]) == BodyKind.DYNAMIC.label
    point = rows["point"]
    ends = [
        np.where(moves[rows[name]][:, None], position[rows[name]], point)
        for name in ("body_a", "body_b")
    ]
    lines = np.stack([ends[0], point, ends[1]], axis=1)
    scale = chain_scale(run, [frame]) if scale is None else scale
    share = rows["force_normal"] / scale if scale > 0.0 else np.zeros(len(lines))
    widths = np.maximum(CHAIN_WIDTH * share, CHAIN_THINNEST)
    ax.add_collection(LineCollection(lines, linewidths=widths, colors=CHAIN_COLOUR, zorder=3))
    return len(lines)


def check_plottable(run: dict, path) -> None:
    """Raise UsageError (one line) unless the run holds a sample and a frame to draw."""
    if len(run["series"]["time"]) and len(run["frames"]["time"]):
        return
    status = run["attrs"].get("status", "")
    if status == "failed":
        why = f"it failed before its first sample ({run['attrs'].get('failure') or 'no reason'})"
    elif status == "running":
        why = "it was killed before its first sample, or is still starting"
    else:
        why = f"status {status}"
    scene = run["attrs"].get("source") or "SCENE"
    raise UsageError(
        f"{path}: the run has no sample or frame yet ({why}); nothing to plot: wait for its "
        f"first frame, or run it again (taichi-ice run {scene} --out {path} --overwrite)"
    )


def positions_figure(run: dict, snapshots: int = 6):
    """Bird's-eye snapshots at ``snapshots`` frames spread over the run, one panel each, all
    on one view (:func:`shared_view` of the frames shown), with the force chains of a run
    that wrote its contacts (:func:`draw_force_chains`, one width scale for every panel);
    returns the Figure."""
    n_frames = len(run["frames"]["time"])
    picks = np.unique(np.linspace(0, n_frames - 1, min(snapshots, n_frames)).round().astype(int))
    view = shared_view(run, picks)
    scale = chain_scale(run, picks)
    fig, axes = subplots(1, len(picks), figsize=(2.4 * len(picks), 4), squeeze=False)
    for ax, f in zip(axes[0], picks):
        draw_bodies(ax, run, f, view=view)
        draw_force_chains(ax, run, f, scale)
        ax.set_title(f"t = {run['frames']['time'][f]:.1f} s", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    return fig


def plot_run(
    path: str | Path, out_dir: str | Path | None = None, animate: bool = False, snapshots: int = 6
) -> list[Path]:
    """Write the figures of one run file; returns their paths.

    Figures: ``<stem>_probe_force.png`` (force magnitude on each probe body against time),
    ``<stem>_energy.png`` (every budget term and the residual), ``<stem>_positions.png``
    (bird's-eye snapshots on one view, with force chains if the run wrote its contacts),
    and with ``animate`` ``<stem>.gif`` (blocks beside the probe force, every frame on one
    view).

    Raises:
        UsageError: the run holds no sample or frame yet (killed or failed before its first).
    """
    from .budget import DISSIPATED, HELD, WORK, residual

    path = Path(path)
    out = Path(out_dir) if out_dir else path.parent
    run = read_run(path)
    check_plottable(run, path)
    out.mkdir(parents=True, exist_ok=True)
    s, names = run["series"], run["bodies"]["names"]
    t = s["time"]
    written = []
    title = f"{path.stem}: {run['attrs'].get('friction', '')}, status {run['attrs']['status']}"

    fig, ax = subplots(figsize=(7, 3.5))
    probes = run["bodies"]["probe_index"]
    for k, idx in enumerate(probes):
        ax.plot(t, np.linalg.norm(s["probe_force"][:, k], axis=-1) / 1e3, lw=0.8, label=names[idx])
    ax.set_xlabel("time (s)")
    ax.set_ylabel("contact force (kN)")
    ax.set_title(title, fontsize=9)
    if len(probes):
        ax.legend(fontsize=8)
    written.append(save_figure(fig, out / f"{path.stem}_probe_force.png"))

    fig, ax = subplots(figsize=(7, 4))
    sometimes = ("crushing_energy", *WORK[1:])  # crushing and the forcing's work: if any
    for name in (*WORK, *HELD, *DISSIPATED):
        if name in s and (name not in sometimes or np.any(s[name])):
            ax.plot(t, s[name], label=name.replace("_", " "))
    ax.plot(t, residual(s), "k--", label="residual")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("energy (J)")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8, ncol=2)
    written.append(save_figure(fig, out / f"{path.stem}_energy.png"))

    written.append(
        save_figure(positions_figure(run, snapshots), out / f"{path.stem}_positions.png")
    )

    if animate:
        written.append(animate_run(run, out / f"{path.stem}.gif"))
    return written


def animation_frames(run: dict):
    """The animation's Figure and ``draw(f)``, which draws frame ``f`` on it: the bodies on
    one view for every frame (:func:`shared_view` of them all) beside the summed probe force,
    drawn up to the frame's time. Returns ``(fig, draw, n_frames)``."""
    s, fr = run["series"], run["frames"]
    force = (
        np.linalg.norm(s["probe_force"], axis=-1).sum(axis=-1) / 1e3
        if s["probe_force"].size
        else np.zeros_like(s["time"])
    )
    n_frames = len(fr["time"])
    view = shared_view(run, range(n_frames))
    scale = chain_scale(run, range(n_frames))
    fig, (ax_b, ax_f) = subplots(
        1, 2, figsize=(8, 4), gridspec_kw={"width_ratios": [1, 1.4]}, layout="constrained"
    )

    def draw(f):
        ax_b.clear()
        draw_bodies(ax_b, run, f, view=view)
        draw_force_chains(ax_b, run, f, scale)
        ax_b.set_title(f"t = {fr['time'][f]:.1f} s", fontsize=9)
        ax_b.set_xlabel("x (m)")
        ax_b.set_ylabel("y (m)")
        ax_f.clear()
        ax_f.plot(s["time"], force, lw=0.6, color="0.6")
        now = s["time"] <= fr["time"][f]
        ax_f.plot(s["time"][now], force[now], lw=0.9, color="C3")
        ax_f.set_xlabel("time (s)")
        ax_f.set_ylabel("probe force (kN)")

    return fig, draw, n_frames


def animate_run(run: dict, path: Path, fps: int = 10) -> Path:
    """GIF of the bodies beside the probe force, one image per frame (``animation_frames``)."""
    from matplotlib.animation import FuncAnimation, PillowWriter

    fig, draw, n_frames = animation_frames(run)
    anim = FuncAnimation(fig, draw, frames=n_frames)
    anim.save(path, writer=PillowWriter(fps=fps))
    return path


def plot_spread(results: dict, path: Path, single: bool = False, titles=None, colours=None) -> Path:
    """Each ensemble metric over the layouts, per law (box and dots).

    Args:
        results: ``{label: EnsembleResult}``.
        single: world 0 of each result is the reference run: starred, not in the box.
        titles, colours: per label (default the label, matplotlib's cycle).
    """
    titles, colours = titles or {}, colours or {}
    panels = (
        ("peak_force", "peak force on probe (kN)", 1e-3, True),
        ("friction_energy", "total frictional energy (J)", 1.0, True),
        ("concentration", "largest share of frictional\nenergy lost in any 1 s", 1.0, False),
    )
    fig, axes = subplots(1, len(panels), figsize=(12, 4))
    labels = list(results)
    first = 1 if single else 0
    rng = np.random.default_rng(0)  # horizontal scatter of the dots, for legibility only
    for ax, (name, ylabel, scale, log) in zip(axes, panels):
        for x, label in enumerate(labels):
            values = results[label].values(name) * scale
            d = values[first:][np.isfinite(values[first:])]
            colour = colours.get(label, f"C{x}")
            if d.size:
                ax.boxplot([d], positions=[x], widths=0.5, showfliers=False)
                ax.scatter(x + rng.uniform(-0.15, 0.15, d.size), d, s=12, color=colour, zorder=3)
            if single:
                ax.scatter(
                    [x],
                    [values[0]],
                    marker="*",
                    s=140,
                    color="red",
                    edgecolor="k",
                    zorder=4,
                    label="single run" if x == 0 else None,
                )
        ax.set_xticks(range(len(labels)), [titles.get(k, k) for k in labels], fontsize=8)
        ax.set_xlim(-0.6, len(labels) - 0.4)
        ax.set_ylabel(ylabel)
        if log and any(np.nanmax(r.values(name), initial=0) > 0 for r in results.values()):
            ax.set_yscale("log")
    n = len(results[labels[0]].seeds) - first
    if single:
        axes[0].legend(fontsize=8)
    fig.suptitle(
        f"Spread over {n} jittered layouts (dots)" + (", single runs starred" if single else ""),
        fontsize=10,
    )
    return save_figure(fig, path)


def save_figure(fig, path: Path) -> Path:
    """Lay ``fig`` out (``tight_layout``, unless it has a layout of its own), write it to
    ``path`` (PNG at 120 dpi); return ``path``. A bare Figure needs no closing."""
    if fig.get_layout_engine() is None:
        fig.tight_layout()
    fig.savefig(path, dpi=120)
    return path
