"""``taichi-ice study``: its options and its body (the study itself is
``experiments.study``: its design, run, statistics and report)."""

from __future__ import annotations

from ..experiments.study.design import DEFAULT_LAYOUTS

EXAMPLES = """examples:
  taichi-ice study --out out/study               # 2 layouts a stratum: 128 worlds, minutes
  taichi-ice study --out out/study --layouts 64  # issue 31's: 2,560 worlds, ~1 h on 2 cores
  taichi-ice study --out out/study --layouts 200 --scheduler tcp://10.0.0.1:8786
  taichi-ice study --out /tmp/smoke --until 0.5  # a smoke run
Run it again with the same --out to resume, or with more --layouts to grow it. The arms:
the strata 0.85 and 0.775 (--layouts each), the control 0.70, the half step on 0.85 and
the ice strengths 1 and 3 MPa on both strata (each --layouts / 2 unless given; 0 drops an
arm)."""


def add_options(p) -> None:
    """The options of ``taichi-ice study`` (beside the engine options the CLI adds)."""
    p.epilog = EXAMPLES
    p.add_argument("--out", default="out/study", help="output folder (default out/study)")
    p.add_argument(
        "--layouts",
        type=int,
        default=DEFAULT_LAYOUTS,
        help="layouts (jittered fields) per jamming stratum, each run under all eight models "
        f"(default {DEFAULT_LAYOUTS}; issue 31's study: 64)",
    )
    for name, what in (
        ("control", "of the control stratum (area fraction 0.70)"),
        ("step", "run again at half the default step (stratum 0.85)"),
        ("strength", "per stratum with each ice strength (1 and 3 MPa)"),
    ):
        p.add_argument(
            f"--{name}-layouts",
            type=int,
            default=None,
            metavar="N",
            help=f"layouts {what} (default --layouts / 2, at least 2; 0: not run)",
        )
    from .sweep import add_cluster_options

    add_cluster_options(p)


def study_command(args) -> int:
    """The body of ``taichi-ice study``."""
    from ..experiments.study.run import run_study
    from ..experiments.sweep.spec import SweepError

    if args.layouts < 2:
        raise SweepError(f"--layouts {args.layouts}: a confidence interval needs 2 or more")
    for name in ("control", "step", "strength"):
        n = getattr(args, f"{name}_layouts")
        if n is not None and n not in (0,) and n < 2:
            raise SweepError(f"--{name}-layouts {n}: give 0 (no such arm) or 2 or more")
    run_study(
        args.out,
        args.layouts,
        control_layouts=args.control_layouts,
        step_layouts=args.step_layouts,
        strength_layouts=args.strength_layouts,
        workers=args.workers,
        scheduler=args.scheduler,
        until=args.until,
        arch=args.arch,
        precision=args.precision,
        progress=not args.quiet,
    )
    print(f"wrote {args.out}/study.md, study.json, study.nc and figures/")
    return 0
