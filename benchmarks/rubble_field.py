"""Rubble-field throughput: body-steps per second of the whole DEM step at 1e3 to 1e5 blocks.

The scene is the paper's rubble: diamond blocks 0.7 m across x and 1.0 m along y, in a closed
box of four fixed walls, covering 54 % of the box interior. The blocks start in zig-zag
columns whose neighbours touch edge to edge (and tip to tip), with random velocities of up to
``VELOCITY_JITTER`` in x and y, so about half of the touching pairs close and form contacts
from the second step on (see ``box_for``). Spread evenly instead, the blocks would sit about
0.2 m apart and need some 2 s (18,000 steps of dt = 1.1e-4 s) to meet. Friction is Coulomb
(mu = 0.5) or rate-and-state (the paper's defaults); water drag is optional.

Each size runs in its own process (a clean Taichi runtime, clean memory figures, and by
default an empty offline kernel cache, so the first step includes the real compile time):

1. build the scene and the World;
2. one warm-up step, which compiles the three kernels (``first_step_s``);
3. ``--steps`` timed steps, read back in up to ``SAMPLES`` chunks to sample the contact count;
4. a few instrumented steps that count the Taichi kernel launches of ``World.step`` and time
   each kernel (synchronising after each, so they are not part of the throughput figure);
5. memory: the bytes of every Taichi field the World holds, and the process RSS.

A separate process measures the memory bandwidth (a NumPy copy on one thread and a Taichi
copy kernel on every thread); ``TRAFFIC`` estimates the bytes each kernel must move per step,
and ``bandwidth_fraction`` is how close the measured step comes to that bound.

    python benchmarks/rubble_field.py --out out/bench
    python benchmarks/rubble_field.py --sizes 1000 10000 100000 --steps 100 --law rate-state
    python benchmarks/rubble_field.py --quick --out /tmp/bench     # 1e3 blocks, 20 steps
    python benchmarks/rubble_field.py --arch gpu --sizes 100000 1000000 --profile

Writes ``rubble_field.csv``, ``rubble_field.json`` and ``rubble_field.png`` into ``--out``.
"""

# No "from __future__ import annotations": Taichi reads kernel annotations as objects.

import argparse
import contextlib
import csv
import dataclasses
import importlib.metadata
import json
import math
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# The paper's blocks (m): the diamond's diagonals across x and along y.
BLOCK_WIDTH = 0.7
BLOCK_LENGTH = 1.0
# Blocks over box interior, in plan view.
AREA_FRACTION = 0.54
# Clearance between the outermost blocks and the walls (m), and wall thickness (m).
WALL_GAP = 0.05
WALL_THICKNESS = 1.0
# Each velocity component of each block is U(-v, v) (m/s): enough to close the touching pairs
# within a step, small against the 10 m/s runaway floor.
VELOCITY_JITTER = 0.1

DEFAULT_SIZES = (1_000, 10_000, 100_000)
DEFAULT_STEPS = 100
QUICK_STEPS = 20
# Contact-count read-backs during the timed steps; each costs one synchronisation.
SAMPLES = 10
# Instrumented steps (launch count, per-kernel time) after the timed ones.
PROBE_STEPS = 5
# Copy size for the bandwidth measurement: well beyond the last-level cache.
BANDWIDTH_MB = 256
QUICK_BANDWIDTH_MB = 128

CSV_COLUMNS = (
    "blocks",
    "bodies",
    "steps",
    "dt_s",
    "law",
    "water",
    "arch",
    "precision",
    "threads",
    "scene_s",
    "world_s",
    "first_step_s",
    "compile_s",
    "step_ms",
    "body_steps_per_s",
    "contacts_per_step",
    "contacts_per_block",
    "launches_per_step",
    "hash.build_ms",
    "contacts.compute_ms",
    "integrator.advance_ms",
    "field_mb",
    "rss_mb",
    "peak_rss_mb",
    "bytes_per_step_mb",
    "bandwidth_gb_s",
    "bandwidth_bound_ms",
    "bandwidth_fraction",
)


# --------------------------------------------------------------------------------------------
# The scene
# --------------------------------------------------------------------------------------------


def box_for(rows: int, columns: int) -> dict:
    """Box interior (m) and lattice of a ``rows`` x ``columns`` field at ``AREA_FRACTION``.

    Rows are half a block length apart and odd rows shift by half a block width, so each block
    shares an edge with the block up-right (even rows) or up-left (odd rows) of it and touches
    the block two rows up tip to tip: zig-zag columns of touching blocks. The column spacing
    then sets the area fraction, counted over the whole interior, wall gaps included.
    """
    blocks = rows * columns
    row_spacing = BLOCK_LENGTH / 2.0
    stagger = BLOCK_WIDTH / 2.0
    height = (rows - 1) * row_spacing + BLOCK_LENGTH + 2.0 * WALL_GAP
    # A diamond covers half its bounding box.
    width = blocks * 0.5 * BLOCK_WIDTH * BLOCK_LENGTH / (AREA_FRACTION * height)
    column_spacing = (width - 2.0 * WALL_GAP - BLOCK_WIDTH - stagger) / max(columns - 1, 1)
    return {
        "rows": rows,
        "columns": columns,
        "width": width,
        "height": height,
        "spacing": [column_spacing, row_spacing],
        "stagger": stagger,
        "origin": [WALL_GAP + BLOCK_WIDTH / 2.0, WALL_GAP + BLOCK_LENGTH / 2.0],
    }


def lattice_for(blocks: int) -> dict:
    """The most nearly square box of ``box_for`` that holds ``blocks`` blocks.

    Without a factorisation of ``blocks`` into a box of aspect ratio within 1:3, the lattice
    is rounded to the nearest near-square one and holds ``rows * columns`` blocks instead.

    Raises:
        ValueError: too few blocks for the wall gaps to leave room at ``AREA_FRACTION``.
    """

    def aspect(box: dict) -> float:
        return abs(math.log(box["width"] / box["height"]))

    # Column spacing width / AREA_FRACTION and rows length / 2 apart make a square box for
    # rows / columns = 2 width / (AREA_FRACTION length).
    ratio = 2.0 * BLOCK_WIDTH / (AREA_FRACTION * BLOCK_LENGTH)
    columns = max(2, round(math.sqrt(blocks / ratio)))
    boxes = [box_for(blocks // c, c) for c in range(2, blocks // 2 + 1) if blocks % c == 0]
    boxes.append(box_for(max(2, round(blocks / columns)), columns))
    # Neighbouring columns must not touch: their spacing exceeds a block width.
    fits = [b for b in boxes if b["spacing"][0] > BLOCK_WIDTH and aspect(b) < math.log(3.0)]
    if not fits:
        raise ValueError(f"{blocks} blocks are too few for a box at this area fraction")
    exact = [b for b in fits if b["rows"] * b["columns"] == blocks]
    return min(exact or fits, key=aspect)


def rubble_scene(blocks: int, law: str, water: bool, seed: int) -> dict:
    """Scene tables (as for ``scenario.scene_from_dict``) of the rubble field in its box."""
    box = lattice_for(blocks)
    w, h, t = box["width"], box["height"], WALL_THICKNESS
    # The walls overlap at the corners, which fixed bodies may.
    walls = [
        ("left", [t, h + 2 * t], [-t / 2, h / 2]),
        ("right", [t, h + 2 * t], [w + t / 2, h / 2]),
        ("bottom", [w + 2 * t, t], [w / 2, -t / 2]),
        ("top", [w + 2 * t, t], [w / 2, h + t / 2]),
    ]
    scene = {
        "simulation": {"duration": 1.0, "dt": "auto", "seed": seed},
        "friction": {"law": "coulomb", "mu": 0.5} if law == "coulomb" else {"law": "rate-state"},
        "body": [
            {
                "name": f"{name}_wall",
                "kind": "fixed",
                "shape": "rectangle",
                "width": size[0],
                "length": size[1],
                "position": pos,
            }
            for name, size, pos in walls
        ],
        "field": [
            {
                "name": "rubble",
                "shape": "diamond",
                "width": BLOCK_WIDTH,
                "length": BLOCK_LENGTH,
                "rows": box["rows"],
                "columns": box["columns"],
                "origin": box["origin"],
                "spacing": box["spacing"],
                "stagger": box["stagger"],
                "velocity_jitter": VELOCITY_JITTER,
            }
        ],
    }
    if water:
        scene["water"] = {}
    return scene


# --------------------------------------------------------------------------------------------
# Memory and traffic
# --------------------------------------------------------------------------------------------

# The kernels of one step, by the name their times are reported under. The traffic of each
# comes from the fields its stage declares it reads and writes (taichi_ice.schema): compulsory
# traffic, each element counted once per launch (a body's data gathered again by each of its
# neighbours is taken to hit the cache), so the bound is optimistic.
STEP_STAGES = ("hash", "contacts", "integrator")


def field_bytes(world) -> dict[str, int]:
    """Bytes of the World's Taichi fields, per group (model, data, hash), from the schema."""
    from taichi_ice import schema

    sizes = schema.field_bytes(world.layout)
    return {group: sum(sizes[v.name] for v in decls) for group, decls in schema.groups().items()}


def traffic(world, contacts: float) -> dict:
    """Bytes per step each kernel of the step must move with ``contacts`` contacts per step,
    and the split into bytes per body and per contact."""
    from taichi_ice import schema
    from taichi_ice.world import STAGES

    stages = {name: STAGES[name] for name in STEP_STAGES}
    per_kernel = schema.traffic(stages, world.layout, contacts)
    total = per_kernel.pop("total")
    no_contacts = schema.traffic(stages, world.layout, 0.0)["total"]
    one_contact = schema.traffic(stages, world.layout, 1.0)["total"]
    return {
        "bytes_per_step": total,
        "bytes_per_kernel": per_kernel,
        "bytes_per_body": no_contacts / world.layout.n_bodies,
        "bytes_per_contact": one_contact - no_contacts,
    }


def rss_bytes() -> tuple[int, int]:
    """Current and peak resident set size of this process (bytes)."""
    current = 0
    with contextlib.suppress(OSError):
        with open("/proc/self/statm") as fh:
            current = int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    # ru_maxrss is in KiB on Linux (bytes on macOS).
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    peak *= 1 if sys.platform == "darwin" else 1024
    return current, peak


# --------------------------------------------------------------------------------------------
# Workers (one process each)
# --------------------------------------------------------------------------------------------


def progress(text: str, end: str = "\n") -> None:
    print(text, end=end, file=sys.stderr, flush=True)


@contextlib.contextmanager
def kernel_probe(world):
    """Record ``(stage.kernel, seconds)`` of every Taichi kernel launched inside the block.

    Wraps Taichi's ``Kernel.__call__`` and synchronises after each launch, so the times are
    per kernel; names are the World attribute that owns the kernel (``hash.build``).
    """
    import taichi as ti
    from taichi.lang.kernel_impl import Kernel

    owners = {id(value): key for key, value in vars(world).items()}
    calls: list[tuple[str, float]] = []
    original = Kernel.__call__

    def timed(kernel, *args, **kwargs):
        start = time.perf_counter()
        result = original(kernel, *args, **kwargs)
        ti.sync()
        owner = owners.get(id(args[0]), type(args[0]).__name__) if args else "?"
        calls.append((f"{owner}.{kernel.func.__name__}", time.perf_counter() - start))
        return result

    Kernel.__call__ = timed
    try:
        yield calls
    finally:
        Kernel.__call__ = original


def device_tasks(steps: int) -> dict | None:
    """Offloaded tasks per step (one device launch each on a GPU) from Taichi's profiler.

    Only with ``TI_KERNEL_PROFILER=1`` (``--profile``); reads Taichi 1.7's profiler records.
    """
    import taichi as ti

    if not ti.cfg.kernel_profiler:
        return None
    records = ti.lang.impl.get_runtime().prog.get_kernel_profiler_records()
    tasks: dict[str, list[float]] = {}
    for rec in records:
        tasks.setdefault(rec.name, []).append(rec.kernel_time)
    return {
        "tasks_per_step": len(records) / steps,
        "task_ms": {name: float(np.mean(t)) for name, t in tasks.items()},
    }


def run_size(blocks: int, args: argparse.Namespace) -> dict:
    """Build, warm up, time and measure one rubble field; returns a result row and details."""
    from taichi_ice import backend

    backend.init(args.arch, args.precision)
    import taichi as ti

    from taichi_ice.scenario import scene_from_dict
    from taichi_ice.world import World

    rss_base, _ = rss_bytes()
    start = time.perf_counter()
    scene = scene_from_dict(rubble_scene(blocks, args.law, args.water, args.seed))
    scene_s = time.perf_counter() - start
    n_blocks = sum(b.kind == "dynamic" for b in scene.bodies)
    box = lattice_for(blocks)
    dynamic = np.array([b.kind == "dynamic" for b in scene.bodies])
    area = scene.masses[dynamic].sum() / (scene.ice.density * scene.ice.thickness)
    progress(f"  {n_blocks} blocks: scene {scene_s:.2f} s", end="")

    start = time.perf_counter()
    world = World([scene], precision=args.precision)
    ti.sync()
    world_s = time.perf_counter() - start
    progress(f", world {world_s:.2f} s", end="")

    start = time.perf_counter()
    world.step()
    ti.sync()
    first_step_s = time.perf_counter() - start
    progress(f", first step {first_step_s:.2f} s, {args.steps} steps ", end="")

    # Timed steps in chunks; the contact count is read between chunks, off the clock.
    chunks = np.array_split(np.arange(args.steps), min(SAMPLES, args.steps))
    seconds = 0.0
    contacts = []
    for chunk in chunks:
        start = time.perf_counter()
        for _ in chunk:
            world.step()
        ti.sync()
        seconds += time.perf_counter() - start
        contacts.append(int(world.contact_counts()[0]))
        progress(".", end="")
    world.check()
    step_s = seconds / args.steps
    progress(f" {step_s * 1e3:.3g} ms/step")

    if args.profile:
        ti.profiler.clear_kernel_profiler_info()
    with kernel_probe(world) as calls:
        for _ in range(PROBE_STEPS):
            world.step()
    tasks = device_tasks(PROBE_STEPS)  # before check(), whose read-back is a task too
    world.check()
    kernel_ms: dict[str, float] = {}
    for name, t in calls:
        kernel_ms[name] = kernel_ms.get(name, 0.0) + t * 1e3 / PROBE_STEPS

    fields = field_bytes(world)
    rss, peak = rss_bytes()
    contacts_per_step = float(np.mean(contacts))
    moved = traffic(world, contacts_per_step)
    row = {
        "blocks": n_blocks,
        "bodies": world.layout.n_bodies,
        "steps": args.steps,
        "dt_s": world.dt,
        "law": args.law,
        "water": int(args.water),
        "arch": args.arch,
        "precision": args.precision,
        "threads": args.threads or os.cpu_count(),
        "scene_s": scene_s,
        "world_s": world_s,
        "first_step_s": first_step_s,
        "compile_s": max(first_step_s - step_s, 0.0),
        "step_ms": step_s * 1e3,
        "body_steps_per_s": world.layout.n_bodies / step_s,
        "contacts_per_step": contacts_per_step,
        "contacts_per_block": contacts_per_step / n_blocks,
        "launches_per_step": len(calls) / PROBE_STEPS,
        **{f"{name}_ms": ms for name, ms in kernel_ms.items()},
        "field_mb": sum(fields.values()) / 2**20,
        "rss_mb": rss / 2**20,
        "peak_rss_mb": peak / 2**20,
        "bytes_per_step_mb": moved["bytes_per_step"] / 2**20,
    }
    details = {
        "lattice": {**box, "area_fraction": area / (box["width"] * box["height"])},
        "field_bytes": fields,
        "rss_base_mb": rss_base / 2**20,
        "contacts_sampled": contacts,
        "kernels_per_step": [name for name, _ in calls[: len(calls) // PROBE_STEPS]],
        "traffic": moved,
        "device_tasks": tasks,
        "layout": dataclasses.asdict(world.layout),
    }
    return {"row": row, "details": details}


def measure_bandwidth(args: argparse.Namespace) -> dict:
    """Copy bandwidth (GB/s, read + write) of a NumPy copy and of a Taichi copy kernel."""
    from taichi_ice import backend

    backend.init(args.arch, args.precision)
    import taichi as ti

    real = ti.f64 if args.precision == "f64" else ti.f32
    dtype = np.float64 if args.precision == "f64" else np.float32
    size = (QUICK_BANDWIDTH_MB if args.quick else BANDWIDTH_MB) * 2**20
    n = size // np.dtype(dtype).itemsize

    src = np.ones(n, dtype)
    dst = np.zeros(n, dtype)
    best_np = math.inf
    for _ in range(5):
        start = time.perf_counter()
        np.copyto(dst, src)
        best_np = min(best_np, time.perf_counter() - start)

    a = ti.field(real, shape=n)
    b = ti.field(real, shape=n)
    a.fill(1.0)

    @ti.kernel
    def copy(src: ti.template(), dst: ti.template()):
        for i in src:
            dst[i] = src[i]

    copy(a, b)
    ti.sync()
    best_ti = math.inf
    for _ in range(5):
        start = time.perf_counter()
        copy(a, b)
        ti.sync()
        best_ti = min(best_ti, time.perf_counter() - start)
    return {
        "copy_mb": size / 2**20,
        "numpy_copy_gb_s": 2 * size / best_np / 1e9,
        "taichi_copy_gb_s": 2 * size / best_ti / 1e9,
    }


# --------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------


def worker_env(args: argparse.Namespace, cache: str | None) -> dict:
    env = dict(os.environ)
    if cache is not None:
        env["TI_OFFLINE_CACHE_FILE_PATH"] = cache
    if args.threads:
        env["TI_CPU_MAX_NUM_THREADS"] = str(args.threads)
    if args.profile:
        env["TI_KERNEL_PROFILER"] = "1"
    return env


def run_worker(task: str, argv: list[str], env: dict) -> dict:
    """Run ``task`` in a fresh interpreter; its progress goes to stderr, its JSON to stdout."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", task, *argv]
    done = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, text=True, check=False)
    if done.returncode:
        raise SystemExit(f"the {task} worker failed (exit status {done.returncode})")
    return json.loads(done.stdout.strip().splitlines()[-1])


def cpu_model() -> str:
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor()


def print_table(rows: list[dict]) -> None:
    header = (
        f"{'blocks':>7} {'steps':>5} {'first s':>7} {'ms/step':>8} {'body-steps/s':>12} "
        f"{'contacts':>9} {'launch':>6} {'fields MB':>9} {'RSS MB':>7} {'MB/step':>7} "
        f"{'bw bound':>8}"
    )
    print(header)
    print("-" * len(header))
    for r in rows:
        print(
            f"{r['blocks']:>7} {r['steps']:>5} {r['first_step_s']:>7.2f} {r['step_ms']:>8.3g} "
            f"{r['body_steps_per_s']:>12.4g} {r['contacts_per_step']:>9.0f} "
            f"{r['launches_per_step']:>6.0f} {r['field_mb']:>9.1f} {r['rss_mb']:>7.0f} "
            f"{r['bytes_per_step_mb']:>7.2f} {r['bandwidth_fraction']:>8.1%}"
        )


def plot(rows: list[dict], meta: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    blocks = [r["blocks"] for r in rows]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    ax1.plot(blocks, [r["body_steps_per_s"] for r in rows], "o-", label="measured")
    ax1.plot(
        blocks,
        [r["bodies"] / (r["bandwidth_bound_ms"] * 1e-3) for r in rows],
        "k--",
        label=f"memory-bandwidth bound ({rows[0]['bandwidth_gb_s']:.3g} GB/s)",
    )
    ax1.set(xscale="log", yscale="log", xlabel="blocks", ylabel="body-steps per second")
    ax1.legend(fontsize=8, loc="center right")
    ax2.plot(blocks, [r["contacts_per_step"] for r in rows], "o-")
    for r in rows:
        ax2.annotate(
            f"{r['contacts_per_block']:.2f} per block",
            (r["blocks"], r["contacts_per_step"]),
            textcoords="offset points",
            xytext=(0, -14),
            ha="center",
            fontsize=8,
        )
    ax2.set(xscale="log", yscale="log", xlabel="blocks", ylabel="contacts per step (mean)")
    ax2.margins(0.15)  # room for the labels
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(
        f"rubble field, {meta['arch']} {meta['precision']}, {meta['law']}"
        f"{', water' if meta['water'] else ''}: {meta['cpu']} x {meta['threads']} threads",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--sizes",
        type=int,
        nargs="+",
        default=list(DEFAULT_SIZES),
        help="numbers of blocks (default 1000 10000 100000)",
    )
    parser.add_argument(
        "--steps",
        type=int,
        default=None,
        help=f"timed steps per size (default {DEFAULT_STEPS}, quick {QUICK_STEPS})",
    )
    parser.add_argument("--arch", default="cpu", help="Taichi arch: cpu (default) or gpu")
    parser.add_argument("--precision", default="f64", choices=("f64", "f32"))
    parser.add_argument("--law", default="coulomb", choices=("coulomb", "rate-state"))
    parser.add_argument("--water", action="store_true", help="add water drag")
    parser.add_argument("--seed", type=int, default=0, help="seeds the velocity jitter")
    parser.add_argument(
        "--threads", type=int, default=None, help="CPU threads for Taichi (default: every core)"
    )
    parser.add_argument(
        "--warm-cache",
        action="store_true",
        help="use Taichi's offline kernel cache (default: compile from scratch)",
    )
    parser.add_argument(
        "--profile",
        action="store_true",
        help="also count Taichi's offloaded tasks (device launches) per step",
    )
    parser.add_argument(
        "--quick", action="store_true", help=f"smoke run: 1000 blocks, {QUICK_STEPS} steps"
    )
    parser.add_argument("--out", type=Path, default=Path("out/bench"), help="results folder")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.quick:
        args.sizes = [1_000]
    if args.steps is None:
        args.steps = QUICK_STEPS if args.quick else DEFAULT_STEPS
    if args.steps < 1:
        parser.error("--steps must be >= 1")
    for blocks in args.sizes:
        try:
            lattice_for(blocks)
        except ValueError as exc:
            parser.error(f"--sizes: {exc}")
    return args


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv)
    if args.worker:
        from taichi_ice.errors import CapacityError, DivergenceError

        try:
            if args.worker == "bandwidth":
                result = measure_bandwidth(args)
            else:
                result = run_size(int(args.worker), args)
        except (CapacityError, DivergenceError) as exc:
            progress("")
            result = {"error": f"{type(exc).__name__}: {exc}"}
        print(json.dumps(result))
        return

    forwarded = [a for a in argv if a != "--worker"]
    print(
        f"rubble field: {args.arch} {args.precision}, {args.law}"
        f"{', water' if args.water else ''}, {args.steps} steps per size",
        file=sys.stderr,
    )
    progress("  memory bandwidth ...", end="")
    with tempfile.TemporaryDirectory(prefix="ti-cache-") as tmp:
        bandwidth = run_worker("bandwidth", forwarded, worker_env(args, tmp))
    progress(
        f" NumPy copy {bandwidth['numpy_copy_gb_s']:.3g} GB/s (one thread), "
        f"Taichi copy {bandwidth['taichi_copy_gb_s']:.3g} GB/s"
    )
    peak_bw = max(bandwidth["numpy_copy_gb_s"], bandwidth["taichi_copy_gb_s"]) * 1e9

    rows, details, failed = [], [], []
    for blocks in args.sizes:
        with tempfile.TemporaryDirectory(prefix="ti-cache-") as tmp:
            env = worker_env(args, None if args.warm_cache else tmp)
            result = run_worker(str(blocks), forwarded, env)
        if "error" in result:
            progress(f"  {blocks} blocks FAILED: {result['error']}")
            failed.append({"blocks": blocks, "error": result["error"]})
            continue
        row = result["row"]
        bound_s = row["bytes_per_step_mb"] * 2**20 / peak_bw
        row["bandwidth_gb_s"] = peak_bw / 1e9
        row["bandwidth_bound_ms"] = bound_s * 1e3
        row["bandwidth_fraction"] = bound_s / (row["step_ms"] * 1e-3)
        # Each kernel's own bound, against its time in the instrumented steps.
        moved = result["details"]["traffic"]["bytes_per_kernel"]
        result["details"]["kernel_bandwidth_fraction"] = {
            name: moved[name] / peak_bw / (row[f"{name}_ms"] * 1e-3)
            for name in moved
            if row.get(f"{name}_ms")
        }
        rows.append(row)
        details.append(result["details"])

    meta = {
        "arch": args.arch,
        "precision": args.precision,
        "law": args.law,
        "water": args.water,
        "steps": args.steps,
        "seed": args.seed,
        "threads": args.threads or os.cpu_count(),
        "cold_cache": not args.warm_cache,
        "machine": platform.node(),
        "cpu": cpu_model(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "taichi": importlib.metadata.version("taichi"),
        "numpy": np.__version__,
        "block": {"shape": "diamond", "width": BLOCK_WIDTH, "length": BLOCK_LENGTH},
        "area_fraction": AREA_FRACTION,
        "velocity_jitter": VELOCITY_JITTER,
        "bandwidth": bandwidth,
        "failed": failed,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "rubble_field.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=CSV_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: f"{v:.6g}" if isinstance(v, float) else v for k, v in row.items()})
    runs = [{**row, **d} for row, d in zip(rows, details)]
    (args.out / "rubble_field.json").write_text(json.dumps({**meta, "runs": runs}, indent=2))
    if rows:
        plot(rows, meta, args.out / "rubble_field.png")
        print_table(rows)
    print(f"wrote {args.out}/rubble_field.csv, .json, .png", file=sys.stderr)
    if failed:
        raise SystemExit(f"{len(failed)} size(s) failed: " + "; ".join(f["error"] for f in failed))


if __name__ == "__main__":
    main()
