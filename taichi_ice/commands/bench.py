"""``taichi-ice bench``: its options (also ``benchmarks/rubble_field.py``'s) and their types.

The benchmark itself, which runs what the options say, is ``bench.bench_command``; the
``bench`` package imports no command-line module.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from ..engine.options import INTEGRATORS
from ..experiments.bench import DEFAULT_STEPS, QUICK_STEPS, box2d
from ..experiments.bench.scenes import SCENES
from .args import nonnegative_int
from .help_text import ARCH_HELP, PRECISION_HELP


def _size(text: str) -> int:
    """``--sizes``: a whole number of blocks, 1 or more, also written as 1e5."""
    try:
        value = float(text)
    except ValueError:
        value = 0.0
    if not (value >= 1 and value == int(value)):
        raise argparse.ArgumentTypeError(f"{text!r}: use a whole number of blocks, e.g. 1e4")
    return int(value)


def _steps(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: use a whole number of steps, 1 or more")
    return value


def _safety(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0.0 < value <= 1.0:
        raise argparse.ArgumentTypeError(
            f"{text!r}: give a fraction of the stability limit in (0, 1], e.g. 0.8"
        )
    return value


def add_options(p: argparse.ArgumentParser) -> None:
    """The options of ``taichi-ice bench`` (and of ``benchmarks/rubble_field.py``)."""
    p.add_argument(
        "--sizes",
        type=_size,
        nargs="+",
        default=None,
        help="numbers of blocks, 1e3 to 1e6 (default 1e3 1e4 1e5), e.g. --sizes 1e4 1e5",
    )
    p.add_argument(
        "--precision",
        nargs="+",
        choices=("f64", "f32"),
        default=["f64", "f32"],
        help=PRECISION_HELP + "; one run per size in each type given (default both)",
    )
    p.add_argument(
        "--arch", default="cpu", choices=["cpu", "gpu", "cuda", "vulkan", "metal"], help=ARCH_HELP
    )
    p.add_argument(
        "--law",
        default="coulomb",
        choices=("coulomb", "rate-state"),
        help="friction law of every contact: coulomb (mu = 0.5, the default) or rate-state "
        "(with its default parameters)",
    )
    p.add_argument(
        "--water", action="store_true", help="add water drag on every block (default: none)"
    )
    p.add_argument(
        "--energy",
        action="store_true",
        help="keep the energy budget in the timed runs (default off: like Box2D, the "
        "benchmark asks for motion only; World(energy=False))",
    )
    p.add_argument(
        "--integrator",
        default=None,
        choices=list(INTEGRATORS),
        help="the DEM's integrator (run --integrator; default the law's: midstep with "
        "Coulomb friction, euler with a law with a memory)",
    )
    p.add_argument(
        "--dt-safety",
        type=_safety,
        default=None,
        metavar="FRACTION",
        help="the DEM's step as a fraction of the contact stability limit, in (0, 1] "
        "(default the scene's: 0.6 with Coulomb friction and the midstep step, 0.2 with "
        "Coulomb and the others, 0.05 with a law with a memory; docs/accuracy.md)",
    )
    p.add_argument(
        "--steps",
        type=_steps,
        default=None,
        help=f"timed steps per size, for each engine (default {DEFAULT_STEPS})",
    )
    p.add_argument(
        "--scene",
        default="random",
        choices=SCENES,
        help="random: diamonds at random angles, 55 %% of the box (default); lattice: "
        "zig-zag columns of touching diamonds, 54 %%",
    )
    p.add_argument(
        "--seed",
        type=nonnegative_int,
        default=0,
        help="seeds the placement and the velocities (>= 0)",
    )
    p.add_argument("--out", type=Path, default=Path("out/bench"), help="results folder")
    p.add_argument(
        "--name", default="bench", help="file name of the outputs in --out (default bench)"
    )
    p.add_argument(
        "--box2d",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also run the scene in Box2D v3 (pyb2d3) and report the ratio (default: on, "
        "when pyb2d3 is installed)",
    )
    p.add_argument(
        "--box2d-dt",
        type=float,
        default=box2d.DEFAULT_DT,
        metavar="SECONDS",
        help=f"Box2D's time step, in s (default {box2d.DEFAULT_DT:g})",
    )
    p.add_argument(
        "--box2d-substeps",
        type=_steps,
        default=box2d.DEFAULT_SUBSTEPS,
        help=f"Box2D's sub-steps per step (default {box2d.DEFAULT_SUBSTEPS})",
    )
    p.add_argument(
        "--box2d-threads",
        type=int,
        nargs="+",
        default=list(box2d.DEFAULT_THREADS),
        help="Box2D's worker threads, one run each; the fastest is compared (default "
        f"{' '.join(map(str, box2d.DEFAULT_THREADS))}; 0: no task system)",
    )
    p.add_argument(
        "--threads", type=int, default=None, help="CPU threads for Taichi (default: every core)"
    )
    p.add_argument(
        "--warm-cache",
        action="store_true",
        help="use Taichi's offline kernel cache (default: compile from scratch, so that "
        "first_step_s shows the compile time)",
    )
    p.add_argument(
        "--profile",
        action="store_true",
        help="also count Taichi's offloaded tasks (device launches) per step",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help=f"smoke run: 1e3 blocks, {QUICK_STEPS} steps, a smaller bandwidth copy",
    )
