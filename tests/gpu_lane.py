"""The GPU lane: the tests that cover every kernel, run on a GPU backend in both precisions.

    python tests/gpu_lane.py --check          # exit 0 if a Vulkan device answers, else 1
    python tests/gpu_lane.py --run vulkan     # the lane on Vulkan (make test-vulkan)
    python tests/gpu_lane.py --run vulkan --full   # and the long runs (below)
    python tests/gpu_lane.py --run cuda       # the same on CUDA, where there is one (all of it)

Each precision runs in its own pytest session (Taichi holds one runtime per process) with
``--arch`` and ``--precision`` (tests/conftest.py), and a line gives its pass count and time.
On Vulkan without a GPU (Mesa's lavapipe) the kernels run on the CPU through SPIR-V, slowly
but by the GPU code paths: a kernel per stage and step, and a thread per world. There a
session takes a pytest worker per core (at most 4: ``--workers``), and leaves out the tests
marked ``long_run`` unless ``--full``: the pillar's 20 s budgets and the convergence studies,
half the float64 lane's time there (docs/performance.md has the measurements). What the GPU
answer of such a test rests on: ``test_gpu.py`` holds the same scenes and integrators equal
to the CPU's to round-off, the kernels' twins hold on the lane, and the CPU suite runs the
long tests whole.

What the lane holds and why (the CPU suite runs all of it too):

- ``test_gpu.py``: worlds on the lane's arch against the same worlds on the CPU (a child
  process), a batch against each world alone, and the two ways of stepping;
- ``test_fmath.py``: the float64 exp and log that SPIR-V lacks;
- ``test_geometry.py``, ``test_contact.py``: the overlap and contact kernels against their
  NumPy twins and shapely;
- ``test_contact_coupled.py``: the coupled step's 4 x 4 solve against its NumPy twin;
- ``test_contact_step.py``: the analytic step's spring-dashpot against its NumPy twin (to
  float32's round-off in a float32 run) and the clamped oscillator;
- ``test_friction.py``, ``test_slip.py``, ``test_slide_steps.py``: the laws' kernels and a
  contact's slide in sub-steps against their twins and closed forms;
- ``test_engine.py``, ``test_budget.py``: stepping, conservation, the energy budget;
- ``test_resume.py`` (float64): checkpoints and resume, bit for bit on the same arch;
- ``test_forcing.py``: current, wind, Coriolis and tilt in the step against closed forms, a
  root finder and their NumPy twins, gridded against uniform bit for bit;
- ``test_transfer.py``: the kernels that start, checkpoint and resume a World's fields in
  one launch against Taichi's own ``from_numpy`` and ``to_numpy``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

LANE = {
    "f64": [
        "tests/test_gpu.py",
        "tests/test_fmath.py",
        "tests/test_geometry.py",
        "tests/test_contact.py",
        "tests/test_contact_step.py",
        "tests/test_contact_coupled.py",
        "tests/test_friction.py",
        "tests/test_slip.py",
        "tests/test_slide_steps.py",
        "tests/test_engine.py",
        "tests/test_budget.py",
        "tests/test_resume.py",
        "tests/test_forcing.py",
        "tests/test_transfer.py",
    ],
    "f32": [
        "tests/test_gpu.py",
        "tests/test_fmath.py",
        "tests/test_contact.py",
        "tests/test_contact_step.py",
        "tests/test_contact_coupled.py",
        "tests/test_friction.py",
        "tests/test_engine.py",
        "tests/test_forcing.py",
        "tests/test_transfer.py",
    ],
}


def device_answers(arch: str) -> bool:
    """Whether Taichi starts on ``arch`` here (in a child process, so a crash of the driver
    does not touch this one)."""
    from taichi_ice.backend import probe
    from taichi_ice.errors import BackendError

    try:
        probe(arch)
    except BackendError:
        return False
    return True


def describe(arch: str) -> str:
    """One line on the device's force gather (``backend.float_gather``), from a child."""
    code = (
        f"from taichi_ice import backend; backend.init({arch!r}, 'f64'); "
        "print('float64 sums of whole quanta (integer atomics fail inside loops here)' "
        "if backend.float_gather() else '64-bit integer atomics')"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=False
    )
    said = proc.stdout.strip().splitlines()
    return said[-1] if proc.returncode == 0 and said else f"unknown (exit {proc.returncode})"


def lane_options(arch: str, full: bool, workers: int | None) -> list[str]:
    """pytest's options for the lane on ``arch``: on Vulkan (software, CPU-bound) a worker
    per core and no long runs unless ``full``; on CUDA one process and everything."""
    if arch != "vulkan":
        return []
    if workers is None:  # the cores this process may run on, as make test's nproc counts them
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
        workers = max(1, min(cores or 1, 4))
    options = [] if full else ["-m", "not long_run"]
    if workers > 1:
        options += ["-n", str(workers), "--dist", "load"]
    return options


def run_lane(arch: str, extra: list[str], full: bool = False, workers: int | None = None) -> int:
    failed = 0
    options = lane_options(arch, full, workers)
    print(f"{arch} lane: forces gathered by {describe(arch)}", flush=True)
    if arch == "vulkan" and not full:
        print(f"{arch} lane: long runs left to the CPU suite (--full runs them here)", flush=True)
    for precision, files in LANE.items():
        start = time.perf_counter()
        cmd = [
            sys.executable,
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            "--arch",
            arch,
            "--precision",
            precision,
            *options,
            *files,
            *extra,
        ]
        proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
        summary = [ln for ln in proc.stdout.splitlines() if " in " in ln and "passed" in ln]
        took = time.perf_counter() - start
        if proc.returncode != 0:
            sys.stdout.write(proc.stdout[-20000:])
            sys.stderr.write(proc.stderr[-5000:])
            failed += 1
        line = summary[-1].strip("= ") if summary else f"exit {proc.returncode}"
        print(f"{arch} lane, {precision}: {line} ({took:.0f} s in all)", flush=True)
    return 1 if failed else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    group = ap.add_mutually_exclusive_group(required=True)
    group.add_argument("--check", action="store_true", help="exit 0 if Vulkan answers")
    group.add_argument("--run", metavar="ARCH", help="run the lane on ARCH (vulkan, cuda)")
    ap.add_argument("--full", action="store_true", help="on Vulkan, the long runs too")
    ap.add_argument(
        "--workers", type=int, default=None, help="on Vulkan, pytest workers (default: cores, <= 4)"
    )
    args, extra = ap.parse_known_args(argv)
    if args.workers is not None and args.workers < 1:
        ap.error(f"--workers {args.workers}: give 1 or more")
    sys.path.insert(0, str(ROOT))
    if args.check:
        return 0 if device_answers("vulkan") else 1
    if not device_answers(args.run):
        print(f"{args.run} lane: Taichi finds no {args.run} device here", file=sys.stderr)
        return 1
    return run_lane(args.run, extra, full=args.full, workers=args.workers)


if __name__ == "__main__":
    sys.exit(main())
