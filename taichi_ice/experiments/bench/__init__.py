"""``taichi-ice bench``: DEM throughput, contacts, memory and the bandwidth bound, against Box2D.

A box of the paper's diamonds (``scenes``) at each size and precision, each in a fresh
process (``engine``): body-steps per second, simulated body-seconds per wall second,
contacts per block, Taichi field bytes per block, the process RSS, and how close the step
comes to the memory-bandwidth bound. With ``pyb2d3`` installed (``pip install
'taichi-ice[bench]'``), the same scene also runs in Box2D v3 (``box2d``) in the same worker,
and each row gets both engines' figures and their ratio. Outputs (``report``):
``<name>.csv``, ``<name>.json`` and ``<name>.png`` in ``--out``.

    taichi-ice bench --out out/bench                        # 1e3, 1e4, 1e5; f64 and f32
    taichi-ice bench --sizes 1e3 1e4 1e5 1e6 --precision f64 --steps 50
    taichi-ice bench --sizes 200 --steps 5 --no-box2d --out /tmp/bench   # smoke run
"""

from __future__ import annotations

import contextlib
import importlib.metadata
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

from ... import limits
from ...errors import TaichiIceError
from ...provenance import git_describe
from . import box2d, report
from .scenes import check_size

__all__ = ["bench_command"]

DEFAULT_SIZES = (1_000, 10_000, 100_000)
DEFAULT_STEPS = 100
QUICK_STEPS = 20
# Copy size for the bandwidth measurement (MB): well beyond the last-level cache.
BANDWIDTH_MB = 256
QUICK_BANDWIDTH_MB = 64


def _check_outputs(out: Path, name: str) -> None:
    """Refuse, before any benchmarking, a ``--name`` that is not a plain file name and an
    ``--out`` that cannot be written (the results would be lost at the end)."""
    if not name or name in (".", "..") or Path(name).name != name or "\\" in name:
        raise TaichiIceError(
            f"bench --name {name!r}: give a plain file name (no folders); --out says where"
        )
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=f".{name}-", suffix=".probe"):
            pass
    except OSError as exc:
        raise TaichiIceError(
            f"bench --out {out}: cannot write there ({exc.strerror or exc}); give a folder "
            "you can write to"
        ) from None


def bench_command(args) -> int:
    """Run the benchmark that ``args`` (the options of ``commands.bench.add_options``) describes;
    1 if a size failed."""
    sizes = args.sizes or ([1_000] if args.quick else list(DEFAULT_SIZES))
    steps = args.steps or (QUICK_STEPS if args.quick else DEFAULT_STEPS)
    precisions = list(dict.fromkeys(args.precision))
    for blocks in sizes:
        try:
            check_size(args.scene, blocks)
        except ValueError as exc:
            raise TaichiIceError(f"bench --sizes {blocks}: {exc}") from None
        # Before any worker starts: 1e12 used to fail in each worker with a traceback.
        limits.check_size(blocks, f"bench --sizes {blocks:g}", "give smaller --sizes")
    _check_outputs(Path(args.out), args.name)
    box2d_spec = None
    if args.box2d:
        if box2d.version() is None:
            print(
                "taichi-ice bench: pyb2d3 is not installed (pip install 'taichi-ice[bench]'): "
                "running without Box2D",
                file=sys.stderr,
            )
        else:
            box2d_spec = {
                "dt": args.box2d_dt,
                "substeps": args.box2d_substeps,
                "threads": args.box2d_threads,
            }
    common = {
        "scene": args.scene,
        "law": args.law,
        "water": args.water,
        "energy": args.energy,
        "seed": args.seed,
        "arch": args.arch,
        "steps": steps,
        "threads": args.threads,
        "integrator": getattr(args, "integrator", None),
        "dt_safety": getattr(args, "dt_safety", None),
    }
    stepped_by = common["integrator"] or "the law's integrator"
    print(
        f"bench: {args.scene} box, {args.arch} {'/'.join(precisions)}, {args.law}"
        f"{', water' if args.water else ''}{', energy budget' if args.energy else ''}, "
        f"{stepped_by} at "
        f"{common['dt_safety'] or 'the scene default'} of the stability limit, "
        f"{steps} steps per size" + (f", Box2D v3 {box2d.version()}" if box2d_spec else ""),
        file=sys.stderr,
    )
    print("  memory bandwidth ...", end="", file=sys.stderr, flush=True)
    copy_mb = QUICK_BANDWIDTH_MB if args.quick else BANDWIDTH_MB
    spec = {"task": "bandwidth", "arch": args.arch, "precision": precisions[0], "copy_mb": copy_mb}
    bandwidth = _worker(spec, args, cold_cache=True)
    if "error" in bandwidth:
        raise TaichiIceError(f"bench: the bandwidth measurement failed: {bandwidth['error']}")
    peak_bw = max(bandwidth["numpy_copy_gb_s"], bandwidth["taichi_copy_gb_s"]) * 1e9
    print(
        f" NumPy copy {bandwidth['numpy_copy_gb_s']:.3g} GB/s (one thread), "
        f"Taichi copy {bandwidth['taichi_copy_gb_s']:.3g} GB/s",
        file=sys.stderr,
    )

    # The workers of a size share one placement of the random box.
    with tempfile.TemporaryDirectory(prefix="taichi-ice-bench-") as placements:
        common["cache"] = placements
        rows, details, failed = _run_sizes(sizes, precisions, common, box2d_spec, args, peak_bw)

    meta = _meta(args, precisions, steps, bandwidth, failed)
    paths = report.write(args.out, args.name, rows, meta, details)
    if rows:
        report.print_table(rows)
    print(f"wrote {', '.join(str(p) for p in paths)}", file=sys.stderr)
    if failed:
        print(
            f"taichi-ice bench: {len(failed)} run(s) failed: "
            + "; ".join(f"{f['blocks']} {f['precision']}: {f['error']}" for f in failed),
            file=sys.stderr,
        )
        return 1
    return 0


def _run_sizes(sizes, precisions, common, box2d_spec, args, peak_bw):
    """Every size in every precision, each in a worker: ``(rows, details, failed)``."""
    rows: list[dict] = []
    details: list[dict] = []
    failed: list[dict] = []
    for blocks in sizes:
        first_row: dict | None = None
        for precision in precisions:
            # Box2D runs once per size, in the worker of the first precision that completes.
            spec = {**common, "task": "size", "blocks": blocks, "precision": precision}
            spec["box2d"] = box2d_spec if first_row is None else None
            result = _worker(spec, args, cold_cache=not args.warm_cache)
            if "error" in result:
                print(f"  {blocks} blocks, {precision} FAILED: {result['error']}", file=sys.stderr)
                failed.append({"blocks": blocks, "precision": precision, **result})
                continue
            row = result["row"]
            _bound(row, result["details"], peak_bw)
            if first_row is None:
                first_row = row
            elif box2d_spec:
                row.update({k: v for k, v in first_row.items() if k.startswith("box2d_")})
            if row.get("box2d_body_steps_per_s"):
                row["steps_ratio"] = row["body_steps_per_s"] / row["box2d_body_steps_per_s"]
                row["sim_time_ratio"] = row["body_s_per_s"] / row["box2d_body_s_per_s"]
            rows.append(row)
            details.append(result["details"])
    return rows, details, failed


def _bound(row: dict, details: dict, peak_bw: float) -> None:
    """Add the memory-bandwidth bound of the step and of each kernel (``peak_bw`` B/s)."""
    bound_s = row["bytes_per_step_mb"] * 2**20 / peak_bw
    row["bandwidth_gb_s"] = peak_bw / 1e9
    row["bandwidth_bound_ms"] = bound_s * 1e3
    row["bandwidth_fraction"] = bound_s / (row["step_ms"] * 1e-3)
    moved = details["traffic"]["bytes_per_kernel"]
    details["kernel_bandwidth_fraction"] = {
        name: moved[name] / peak_bw / (row[f"{name}_ms"] * 1e-3)
        for name in moved
        if row.get(f"{name}_ms")
    }


def _worker(spec: dict, args, cold_cache: bool) -> dict:
    """Run ``spec`` in a fresh interpreter (``engine.main``); its progress goes to stderr."""
    env = dict(os.environ)
    if args.threads:
        env["TI_CPU_MAX_NUM_THREADS"] = str(args.threads)
    if args.profile:
        env["TI_KERNEL_PROFILER"] = "1"
    with tempfile.TemporaryDirectory(prefix="ti-cache-") as cache:
        if cold_cache:
            env["TI_OFFLINE_CACHE_FILE_PATH"] = cache
        cmd = [sys.executable, "-m", "taichi_ice.experiments.bench.engine", json.dumps(spec)]
        done = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, text=True, check=False)
    lines = done.stdout.strip().splitlines()
    if done.returncode or not lines:
        return {"error": f"the worker exited with status {done.returncode} (see above)"}
    return json.loads(lines[-1])


def _meta(args, precisions: list[str], steps: int, bandwidth: dict, failed: list) -> dict:
    """What the JSON records about the run besides its rows."""
    from .scenes import BLOCK_LENGTH, BLOCK_WIDTH

    return {
        "scene": args.scene,
        "arch": args.arch,
        "precisions": precisions,
        "law": args.law,
        "water": args.water,
        "energy": args.energy,
        "steps": steps,
        "seed": args.seed,
        "threads": args.threads or os.cpu_count(),
        "cold_cache": not args.warm_cache,
        # The compile setting the workers inherit (TAICHI_ICE_OPTIMIZE; backend.optimize_level).
        "optimize": _optimize_setting(args.arch),
        "machine": platform.node(),
        "cpu": _cpu_model(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "taichi": importlib.metadata.version("taichi"),
        "numpy": importlib.metadata.version("numpy"),
        "pyb2d3": box2d.version() if args.box2d else None,
        "git": git_describe(),
        "block": {"shape": "diamond", "width": BLOCK_WIDTH, "length": BLOCK_LENGTH},
        "bandwidth": bandwidth,
        "failed": failed,
    }


def _optimize_setting(arch: str) -> str:
    from ... import backend

    return backend.optimize_level(None, "cpu" if arch == "cpu" else "gpu")


def _cpu_model() -> str:
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor()
