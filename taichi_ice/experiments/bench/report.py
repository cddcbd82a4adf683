"""The benchmark's outputs: CSV (one row per size and precision), JSON, PNG chart, table."""

from __future__ import annotations

import csv
import json
from pathlib import Path

__all__ = ["BOX2D_COLUMNS", "CSV_COLUMNS", "plot", "print_table", "write"]

# Box2D's figures (``box2d.run_box2d``), of its fastest run when several thread counts ran.
BOX2D_COLUMNS = (
    "box2d_version",
    "box2d_threads",
    "box2d_dt_s",
    "box2d_substeps",
    "box2d_steps",
    "box2d_build_s",
    "box2d_step_ms",
    "box2d_body_steps_per_s",
    "box2d_body_s_per_s",
    "box2d_rss_mb",
)
# Every CSV has these columns, in this order (empty where not measured: the box2d_* columns
# without Box2D); the time of each Taichi kernel of a step follows as "<stage>.<kernel>_ms".
CSV_COLUMNS = (
    "scene",
    "blocks",
    "bodies",
    "area_fraction",
    "steps",
    "dt_s",
    "integrator",
    "law",
    "water",
    "energy",
    "arch",
    "precision",
    "stepping",
    "threads",
    "scene_s",
    "world_s",
    "first_step_s",
    "compile_s",
    "step_ms",
    "body_steps_per_s",
    "body_s_per_s",
    "contacts_per_step",
    "contacts_per_block",
    "launches_per_step",
    "field_mb",
    "field_bytes_per_block",
    "rss_mb",
    "peak_rss_mb",
    "bytes_per_step_mb",
    "bandwidth_gb_s",
    "bandwidth_bound_ms",
    "bandwidth_fraction",
    *BOX2D_COLUMNS,
    "steps_ratio",
    "sim_time_ratio",
)


def write(out: Path, name: str, rows: list[dict], meta: dict, details: list[dict]) -> list[Path]:
    """Write ``<name>.csv``, ``<name>.json`` and (with rows) ``<name>.png`` into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    kernels = sorted({k for row in rows for k in row if k.endswith("_ms") and k not in CSV_COLUMNS})
    paths = [out / f"{name}.csv", out / f"{name}.json"]
    with open(paths[0], "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=(*CSV_COLUMNS, *kernels), extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: f"{v:.6g}" if isinstance(v, float) else v for k, v in row.items()})
    runs = [{**row, **d} for row, d in zip(rows, details)]
    paths[1].write_text(json.dumps({**meta, "runs": runs}, indent=2, default=float) + "\n")
    if rows:
        paths.append(out / f"{name}.png")
        plot(rows, meta, paths[2])
    return paths


def print_table(rows: list[dict]) -> None:
    """One line per size and precision, on stdout."""
    header = (
        f"{'blocks':>7} {'prec':>4} {'ms/step':>8} {'body-steps/s':>12} {'body-s/s':>8} "
        f"{'contacts/blk':>12} {'B/block':>7} {'RSS MB':>6} {'bw bound':>8} "
        f"{'Box2D b-steps/s':>15} {'ratio':>5} {'sim ratio':>9}"
    )
    print(header)
    print("-" * len(header))
    for r in rows:
        box2d = r.get("box2d_body_steps_per_s")
        print(
            f"{r['blocks']:>7} {r['precision']:>4} {r['step_ms']:>8.3g} "
            f"{r['body_steps_per_s']:>12.4g} {r['body_s_per_s']:>8.3g} "
            f"{r['contacts_per_block']:>12.3f} {r['field_bytes_per_block']:>7.0f} "
            f"{r['rss_mb']:>6.0f} {r['bandwidth_fraction']:>8.1%} "
            + (
                f"{box2d:>15.4g} {r['steps_ratio']:>5.2f} {r['sim_time_ratio']:>9.3f}"
                if box2d
                else f"{'-':>15} {'-':>5} {'-':>9}"
            )
        )


def plot(rows: list[dict], meta: dict, path: Path) -> None:
    """Throughput, simulated time per wall second, contacts and memory against size."""
    from ...run.plots import subplots

    fig, axes = subplots(2, 2, figsize=(11, 8))
    (ax_steps, ax_sim), (ax_contacts, ax_memory) = axes
    precisions = list(dict.fromkeys(r["precision"] for r in rows))
    for k, precision in enumerate(precisions):
        mine = [r for r in rows if r["precision"] == precision]
        blocks = [r["blocks"] for r in mine]
        style = {"color": f"C{k}", "marker": "o"}
        label = f"taichi-ice {precision}"
        ax_steps.plot(blocks, [r["body_steps_per_s"] for r in mine], **style, label=label)
        ax_sim.plot(blocks, [r["body_s_per_s"] for r in mine], **style, label=label)
        ax_contacts.plot(blocks, [r["contacts_per_block"] for r in mine], **style, label=label)
        ax_memory.plot(
            blocks,
            [r["field_bytes_per_block"] for r in mine],
            **style,
            label=f"fields, {precision}",
        )
        ax_memory.plot(
            blocks,
            [r["rss_mb"] * 2**20 / r["blocks"] for r in mine],
            **style,
            linestyle=":",
            label=f"process RSS, {precision}",
        )
    first = [r for r in rows if r["precision"] == precisions[0]]
    blocks = [r["blocks"] for r in first]
    ax_steps.plot(
        blocks,
        [r["bodies"] / (r["bandwidth_bound_ms"] * 1e-3) for r in first],
        "k--",
        label=f"memory-bandwidth bound ({first[0]['bandwidth_gb_s']:.3g} GB/s, {precisions[0]})",
    )
    box2d = [r for r in first if r.get("box2d_body_steps_per_s")]
    if box2d:
        threads = "/".join(str(t) for t in dict.fromkeys(r["box2d_threads"] for r in box2d))
        label = f"Box2D v3 (dt {box2d[0]['box2d_dt_s']:g} s, {threads} threads)"
        x = [r["blocks"] for r in box2d]
        ax_steps.plot(x, [r["box2d_body_steps_per_s"] for r in box2d], "D-", c="C3", label=label)
        ax_sim.plot(x, [r["box2d_body_s_per_s"] for r in box2d], "D-", c="C3", label=label)
        ax_steps.margins(y=0.2)  # room for the ratios
        for r in box2d:
            # Above our point, between it and the bound, where no legend goes.
            ax_steps.annotate(
                f"{r['precision']}/Box2D {r['steps_ratio']:.2f}",
                (r["blocks"], r["body_steps_per_s"]),
                textcoords="offset points",
                xytext=(0, 8),
                ha="center",
                fontsize=7,
                color="C3",
            )
    ax_steps.set(ylabel="body-steps per second")
    ax_sim.set(ylabel="simulated body-seconds per wall second")
    ax_contacts.set(ylabel="contacts per block (mean over the timed steps)", ylim=(0, None))
    ax_memory.set(ylabel="bytes per block")
    for ax in axes.flat:
        ax.set_xscale("log")
        if ax is not ax_contacts:
            ax.set_yscale("log")
        ax.set_xlabel("blocks")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    dt = first[0]["dt_s"]
    fig.suptitle(
        f"{meta['scene']} box of diamonds at {first[0]['area_fraction']:.0%}, {meta['law']}"
        f"{', water' if meta['water'] else ''}"
        f"{', energy budget' if meta.get('energy') else ''}, dt {dt:.3g} s: "
        f"{meta['arch']}, {meta['cpu']} x {meta['threads']} threads",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
