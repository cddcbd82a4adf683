"""``taichi-ice study``: its options and its body (the study itself is ``study`` and
``study.report``)."""

from __future__ import annotations

from ..experiments.study.stats import DEFAULT_LAYOUTS

EXAMPLES = """examples:
  taichi-ice study --out out/study                       # the default size (~10 min on 2 cores)
  taichi-ice study --out out/study --layouts 32 --workers 16
  taichi-ice study --out out/study --scheduler tcp://10.0.0.1:8786 --layouts 200
  taichi-ice study --out /tmp/smoke --layouts 2 --until 0.5   # a smoke run
Run it again with the same --out to resume, or with more --layouts to grow it."""


def add_options(p) -> None:
    """The options of ``taichi-ice study`` (beside the engine options the CLI adds)."""
    p.epilog = EXAMPLES
    p.add_argument("--out", default="out/study", help="output folder (default out/study)")
    p.add_argument(
        "--layouts",
        type=int,
        default=DEFAULT_LAYOUTS,
        help=f"jittered layouts per model and area fraction (default {DEFAULT_LAYOUTS})",
    )
    from .sweep import add_cluster_options

    add_cluster_options(p)


def study_command(args) -> int:
    """The body of ``taichi-ice study``."""
    from ..experiments.study.report import run_study
    from ..experiments.sweep.spec import SweepError

    if args.layouts < 2:
        raise SweepError(f"--layouts {args.layouts}: a confidence interval needs 2 or more")
    run_study(
        args.out,
        args.layouts,
        workers=args.workers,
        scheduler=args.scheduler,
        until=args.until,
        arch=args.arch,
        precision=args.precision,
        progress=not args.quiet,
    )
    print(f"wrote {args.out}/study.md, study.json and figures/")
    return 0
