"""One validation study from the command line, and the worker processes two of them start:
``python -m taichi_ice.commands.validate STUDY --out DIR [--quick]``.

``taichi-ice validate`` runs them together (``experiments.validation.validate_command``);
this runs one: ``stability``, ``single_interface``, ``dem_contact``, ``dem_accuracy``,
``dem_ensemble``, ``contact_convergence``, ``contact_coupling`` or ``speed_accuracy`` (which
writes the stability chart first). The studies' code is in
``taichi_ice.experiments.validation``; their options are here, where argparse lives.
``dem_accuracy`` and ``speed_accuracy`` run each precision in a child process started through
this module (``--worker``, hidden).
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
from pathlib import Path

STUDIES = (
    "stability",
    "single_interface",
    "dem_contact",
    "dem_accuracy",
    "dem_ensemble",
    "contact_convergence",
    "contact_coupling",
    "speed_accuracy",
)
# What --quick makes shorter, by study.
QUICK = {
    "stability": "shorter runs",
    "single_interface": "coarser steps",
    "dem_contact": "coarser steps",
    "dem_accuracy": "small sizes (tests)",
    "dem_ensemble": "two layouts, 3 s, Euler only",
    "contact_convergence": "fewer steps and layouts",
    "contact_coupling": "two steps (0.2 and 0.8 stable_dt)",
    "speed_accuracy": "fewer steps, 1e4 interfaces",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m taichi_ice.commands.validate",
        description=__doc__.splitlines()[0],
    )
    studies = parser.add_subparsers(dest="study", required=True, metavar="STUDY")
    for name in STUDIES:
        module = importlib.import_module(f"taichi_ice.experiments.validation.{name}")
        p = studies.add_parser(name, help=(module.__doc__ or name).splitlines()[0])
        p.add_argument("--out", type=Path, default=Path("out/validation"), help="output folder")
        p.add_argument("--quick", action="store_true", help=QUICK[name])
        if name == "dem_accuracy":
            p.add_argument(
                "--until", type=float, default=None, help="seconds of the pillar runs (default 20)"
            )
            p.add_argument(
                "--reuse",
                action="store_true",
                help="analyse the runs already in --out, run nothing",
            )
            p.add_argument(
                "--integrators",
                type=_integrators,
                default=None,
                metavar="LIST",
                help="integrators compared, comma-separated, e.g. 'euler' or 'euler,analytic' "
                "(default: both; --quick: euler)",
            )
        if name == "dem_ensemble":
            p.add_argument(
                "--reuse",
                action="store_true",
                help="keep the cases already in --out/dem_ensemble.json, run only the others",
            )
            p.add_argument(
                "--layouts",
                type=int,
                default=None,
                metavar="N",
                help="layouts of the pillar scene per case (default 32; --quick 2): the "
                "intervals narrow as 1/sqrt(N), the runs take N/32 as long",
            )
            p.add_argument(
                "--cases",
                type=_cases,
                default=None,
                metavar="LIST",
                help="only these cases, INTEGRATOR:RATIO comma-separated (dt / stable_dt), "
                "and the comparisons among them, e.g. 'euler:0.2,coupled:0.8' (default: all); "
                "a case the study does not list is compared with euler:0.2 and euler:0.05, "
                "those of them that run too",
            )
            p.add_argument(
                "--laws",
                type=_laws,
                default=None,
                metavar="LIST",
                help="only these friction laws, comma-separated: coulomb, rate-state "
                "(default: both; --quick: coulomb)",
            )
            p.add_argument(
                "--mu",
                type=_mu,
                default=None,
                metavar="MU",
                help="the Coulomb worlds' friction coefficient (default the pillar scene's, "
                "0.5), e.g. 0.9, the paper's jamming model",
            )
        if name == "speed_accuracy":
            p.add_argument("--arch", default="cpu", help="Taichi arch (cpu or gpu)")
            p.add_argument("--interfaces", type=int, default=None, help="interfaces timed")
            p.add_argument("--result", help=argparse.SUPPRESS)
        if name in ("dem_accuracy", "speed_accuracy"):
            p.add_argument("--worker", choices=("f64", "f32"), help=argparse.SUPPRESS)
    return parser


def _listed(text: str, known, what: str) -> tuple[str, ...]:
    """Comma-separated names, each one of ``known``; else one line naming the choices."""
    names = tuple(x.strip() for x in text.split(",") if x.strip())
    unknown = [x for x in names if x not in known]
    if unknown or not names:
        raise argparse.ArgumentTypeError(
            f"unknown {what}(s) {', '.join(unknown) or repr(text)}: choose from "
            f"{', '.join(known)}, comma-separated"
        )
    return names


def _mu(text: str) -> float:
    """A friction coefficient: a number > 0; else one line saying so."""
    try:
        mu = float(text)
    except ValueError:
        mu = float("nan")
    if not mu > 0.0 or mu == float("inf"):
        raise argparse.ArgumentTypeError(f"{text!r}: a friction coefficient is a number > 0")
    return mu


def _integrators(text: str) -> tuple[str, ...]:
    from ..engine.options import INTEGRATORS

    return _listed(text, INTEGRATORS, "integrator")


def _cases(text: str) -> tuple[tuple[str, float], ...]:
    from ..engine.options import INTEGRATORS

    out = []
    for item in (x.strip() for x in text.split(",") if x.strip()):
        name, _, ratio = item.partition(":")
        try:
            value = float(ratio)
        except ValueError:
            value = math.nan
        if name not in INTEGRATORS or not value > 0.0:
            raise argparse.ArgumentTypeError(
                f"case {item!r}: write INTEGRATOR:RATIO, the integrator one of "
                f"{', '.join(INTEGRATORS)} and RATIO = dt / stable_dt > 0, e.g. coupled:0.8"
            )
        out.append((name, value))
    if not out:
        raise argparse.ArgumentTypeError("no case given: e.g. --cases euler:0.2,coupled:0.8")
    return tuple(out)


def _laws(text: str) -> tuple[str, ...]:
    from ..experiments.validation.dem_ensemble import LAWS

    return _listed(text, LAWS, "law")


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.study != "speed_accuracy":  # it times kernels: compiled as the user says
        from ..experiments.validation import compile_for_studies

        compile_for_studies()
    study = importlib.import_module(f"taichi_ice.experiments.validation.{args.study}")
    if args.study == "dem_accuracy":
        if args.worker:
            cfg = study.config(args.quick, args.until, args.integrators)
            study.worker(args.worker, args.out, cfg, log=study.log)
        else:
            study.run(
                args.out,
                quick=args.quick,
                until=args.until,
                reuse=args.reuse,
                integrators=args.integrators,
            )
    elif args.study == "dem_ensemble":
        from ..errors import UsageError

        try:  # a case compared with nothing: one line, before anything runs
            table = (
                study.QUICK
                if args.quick
                else {"cases": study.CASES, "comparisons": study.COMPARISONS}
            )
            study.select(table["cases"], table["comparisons"], args.cases)
            if args.layouts is not None and args.layouts < 2:
                raise UsageError(f"--layouts: at least 2 (a paired interval), got {args.layouts}")
        except UsageError as exc:
            parser.error(str(exc))
        study.run(
            args.out,
            quick=args.quick,
            reuse=args.reuse,
            layouts=args.layouts,
            cases=args.cases,
            laws=args.laws,
            mu=args.mu,
        )
    elif args.study == "speed_accuracy":
        if args.worker:
            n = args.interfaces or (study.QUICK_N_INTERFACES if args.quick else study.N_INTERFACES)
            data = study.worker(args.worker, args.arch, n, args.quick)
            Path(args.result).write_text(json.dumps(data))
            return 0
        from ..experiments.validation import stability

        stability.run(args.out, quick=args.quick)
        study.run(args.out, quick=args.quick, arch=args.arch, n_interfaces=args.interfaces)
    else:
        study.run(args.out, quick=args.quick)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
