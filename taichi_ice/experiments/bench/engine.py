"""The benchmark's worker: one scene size in one precision, in a process of its own.

A fresh process per size and precision gives a clean Taichi runtime (Taichi's precision is
per process), clean memory figures, and with an empty offline kernel cache the real compile
time. The worker:

1. builds the scene (``scenes.bench_scene``) and the World;
2. takes one warm-up step, which compiles the step's kernels (``first_step_s``);
3. times ``steps`` steps (``World.advance`` where the World has it), read back in up to
   ``SAMPLES`` chunks to sample the contact count;
4. counts the Taichi kernel launches of ``PROBE_STEPS`` more steps and times each kernel
   (synchronising after each, so they are not part of the throughput);
5. reads the Taichi field bytes of the World and the process RSS;
6. with ``box2d``, runs the same scene in Box2D v3 (``box2d.run_box2d``), after everything
   above, so that its memory is not counted as ours.

``measure_bandwidth`` measures the copy bandwidth in a process of its own.

    python -m taichi_ice.experiments.bench.engine '{"task": "size", "blocks": 1000, ...}'

prints the result as JSON on its last line of stdout; progress goes to stderr.
"""

# No "from __future__ import annotations": Taichi reads kernel annotations as objects.

import contextlib
import dataclasses
import json
import math
import os
import sys
import time
from typing import Optional

import numpy as np

from ...codes import BodyKind
from .memory import field_bytes, rss_bytes, traffic
from .report import BOX2D_COLUMNS
from .scenes import bench_scene

__all__ = ["PROBE_STEPS", "SAMPLES", "kernel_probe", "measure_bandwidth", "measure_size"]

# Contact-count read-backs during the timed steps; each costs one synchronisation.
SAMPLES = 10
# Instrumented steps (launch count, per-kernel time) after the timed ones.
PROBE_STEPS = 5


def progress(text: str, end: str = "\n") -> None:
    print(text, end=end, file=sys.stderr, flush=True)


def advance(world, n: int) -> None:
    """``n`` steps: in one call where the World can (``World.advance``), else one by one."""
    if hasattr(world, "advance"):
        world.advance(n)
    else:
        for _ in range(n):
            world.step()


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


def device_tasks(steps: int) -> Optional[dict]:
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


def measure_size(spec: dict) -> dict:
    """Build, warm up, time and measure one scene; returns ``{"row": ..., "details": ...}``.

    ``spec`` holds ``scene``, ``blocks``, ``law``, ``water``, ``energy`` (keep the budget;
    default off), ``seed``, ``cache`` (a folder for the placement, shared by the runs of a
    size, or None), ``arch``, ``precision``, ``steps``, ``threads``, ``integrator`` (default
    None: the law's, ``timestep.default_integrator``) and ``dt_safety`` (the step as a
    fraction of the stability limit; None: the scene's), and ``box2d`` (None, or the ``dt``,
    ``substeps`` and list of ``threads`` of ``compare_box2d``).
    """
    from ... import backend

    backend.init(spec["arch"], spec["precision"])
    import taichi as ti

    from ...engine.world import World

    steps = spec["steps"]
    rss_base, _ = rss_bytes()
    start = time.perf_counter()
    scene, facts = bench_scene(
        spec["scene"], spec["blocks"], spec["law"], spec["water"], spec["seed"], spec["cache"]
    )
    scene_s = time.perf_counter() - start
    dynamic = scene.kinds == int(BodyKind.DYNAMIC)
    n_blocks = int(dynamic.sum())
    progress(f"  {n_blocks} blocks, {spec['precision']}: scene {scene_s:.2f} s", end="")

    start = time.perf_counter()
    safety = spec.get("dt_safety")
    world = World(
        [scene],
        precision=spec["precision"],
        energy=spec.get("energy", False),
        integrator=spec.get("integrator"),
        dt=None if safety is None else safety * scene.stable_dt,
    )
    ti.sync()
    world_s = time.perf_counter() - start
    progress(f", world {world_s:.2f} s", end="")

    start = time.perf_counter()
    advance(world, 1)
    ti.sync()
    first_step_s = time.perf_counter() - start
    progress(f", first step {first_step_s:.2f} s, {steps} steps ", end="")

    # Timed steps in chunks; the contact count is read between chunks, off the clock.
    seconds = 0.0
    contacts = []
    for chunk in np.array_split(np.arange(steps), min(SAMPLES, steps)):
        start = time.perf_counter()
        advance(world, len(chunk))
        ti.sync()
        seconds += time.perf_counter() - start
        contacts.append(int(world.contact_counts()[0]))
        progress(".", end="")
    world.check()
    step_s = seconds / steps
    progress(f" {step_s * 1e3:.3g} ms/step")

    if os.environ.get("TI_KERNEL_PROFILER") == "1":
        ti.profiler.clear_kernel_profiler_info()
    with kernel_probe(world) as calls:
        advance(world, PROBE_STEPS)
    tasks = device_tasks(PROBE_STEPS)  # before check(), whose read-back is a task too
    world.check()
    kernel_ms: dict[str, float] = {}
    for name, t in calls:
        kernel_ms[name] = kernel_ms.get(name, 0.0) + t * 1e3 / PROBE_STEPS

    fields = field_bytes(world)
    rss, peak = rss_bytes()
    contacts_per_step = float(np.mean(contacts))
    moved = traffic(world, contacts_per_step)
    bodies = world.batch.n_bodies
    row = {
        "scene": spec["scene"],
        "blocks": n_blocks,
        "bodies": bodies,
        "area_fraction": facts["area_fraction"],
        "steps": steps,
        "dt_s": world.dt,
        "integrator": world.options.integrator,
        "law": spec["law"],
        "water": int(spec["water"]),
        "energy": int(spec.get("energy", False)),
        "arch": spec["arch"],
        "precision": spec["precision"],
        "stepping": getattr(world, "stepping", "bodies"),
        "threads": spec["threads"] or os.cpu_count(),
        "scene_s": scene_s,
        "world_s": world_s,
        "first_step_s": first_step_s,
        "compile_s": max(first_step_s - step_s, 0.0),
        "step_ms": step_s * 1e3,
        "body_steps_per_s": bodies / step_s,
        "body_s_per_s": bodies * world.dt / step_s,
        "contacts_per_step": contacts_per_step,
        "contacts_per_block": contacts_per_step / n_blocks,
        "launches_per_step": len(calls) / PROBE_STEPS,
        "field_mb": sum(fields.values()) / 2**20,
        "field_bytes_per_block": sum(fields.values()) / n_blocks,
        "rss_mb": rss / 2**20,
        "peak_rss_mb": peak / 2**20,
        "bytes_per_step_mb": moved["bytes_per_step"] / 2**20,
        **{f"{name}_ms": ms for name, ms in kernel_ms.items()},
    }
    details = {
        "box": facts,
        "field_bytes": fields,
        "rss_base_mb": rss_base / 2**20,
        "contacts_sampled": contacts,
        "kernels_per_step": [name for name, _ in calls[: max(len(calls) // PROBE_STEPS, 1)]],
        "kernel_ms": kernel_ms,
        "traffic": moved,
        "device_tasks": tasks,
        "layout": dataclasses.asdict(world.layout),
    }
    if spec.get("box2d"):
        row_box2d, details["box2d"] = compare_box2d(scene, steps, spec["box2d"])
        row.update(row_box2d)
    return {"row": row, "details": details}


def compare_box2d(scene, steps: int, options: dict) -> tuple[dict, list[dict]]:
    """Box2D on ``scene`` with each thread count of ``options["threads"]``.

    Returns:
        The fastest run's ``box2d_*`` figures (``box2d_rss_mb``: the largest of the runs),
        and every run's, with the largest relative difference of Box2D's masses from the
        scene's and whether its positions stayed finite.
    """
    from .box2d import run_box2d

    runs = []
    for threads in options["threads"]:
        progress(f"  {scene.n_bodies} bodies, Box2D v3, {threads} threads: ", end="")
        result = run_box2d(scene, steps, options["dt"], options["substeps"], threads)
        masses, positions = result.pop("masses"), result.pop("positions")
        result.pop("velocities")
        dynamic = scene.kinds == int(BodyKind.DYNAMIC)
        result["box2d_mass_rel_error"] = float(
            np.max(np.abs(masses / scene.masses[dynamic] - 1.0), initial=0.0)
        )
        result["box2d_finite"] = bool(np.isfinite(positions).all())
        runs.append(result)
        progress(f"{result['box2d_step_ms']:.3g} ms/step")
    fastest = min(runs, key=lambda r: r["box2d_step_ms"])
    row = {k: v for k, v in fastest.items() if k in BOX2D_COLUMNS}
    # A later world may reuse the memory an earlier one freed: the first run shows the most.
    row["box2d_rss_mb"] = max(r["box2d_rss_mb"] for r in runs)
    return row, runs


# Threads a SPIR-V dispatch may have on lavapipe: 65,535 workgroups of Taichi's 128.
SPIRV_MAX_THREADS = 65_535 * 128


def measure_bandwidth(spec: dict) -> dict:
    """Copy bandwidth (GB/s, read + write) of a NumPy copy and of a Taichi copy kernel.

    ``spec`` holds ``arch``, ``precision`` and ``copy_mb`` (well beyond the last-level cache).
    """
    from ... import backend

    backend.init(spec["arch"], spec["precision"])
    import taichi as ti

    real = ti.f64 if spec["precision"] == "f64" else ti.f32
    dtype = np.float64 if spec["precision"] == "f64" else np.float32
    n = spec["copy_mb"] * 2**20 // np.dtype(dtype).itemsize
    if backend.actual_arch() in backend.SPIRV_ARCHES:
        # Taichi launches one thread an element there, in workgroups of 128, and lavapipe
        # takes at most 65,535 workgroups: a copy of more elements is refused
        # ("Dispatch error: not_supported"; 8,000,000 float64 copied, 8,388,608 refused).
        n = min(n, SPIRV_MAX_THREADS)
    size = n * np.dtype(dtype).itemsize

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


def main(argv: Optional[list] = None) -> None:
    """Run the task of the JSON spec in ``argv[0]``; print its result as JSON."""
    from ...errors import CapacityError, DivergenceError

    spec = json.loads((sys.argv[1:] if argv is None else argv)[0])
    try:
        if spec["task"] == "bandwidth":
            result = measure_bandwidth(spec)
        else:
            result = measure_size(spec)
    except (CapacityError, DivergenceError) as exc:
        progress("")
        result = {"error": f"{type(exc).__name__}: {exc}"}
    print(json.dumps(result, default=float))


if __name__ == "__main__":
    main()
