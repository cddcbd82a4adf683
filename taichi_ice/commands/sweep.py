"""The ``taichi-ice sweep`` subcommand: its options, the Sweep they name, and its body.

    taichi-ice sweep sweeps/pillar.toml --out out/sweep
    taichi-ice sweep --scene pillar --seeds 0-15 --friction coulomb:0.5 --out out/sweep

Everything argparse of a sweep is here (``add_options``; ``add_cluster_options`` is shared
with the study); the sweep file's format and checks are ``sweep.spec``'s, and running it
``sweep.run``'s. ``cli`` wires this in as the ``sweep`` subcommand.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..experiments.sweep.run import MAX_WORKERS, run_sweep
from ..experiments.sweep.spec import Sweep, SweepError, not_utf8, sweep_from_dict
from .args import nonnegative_int, parse_friction, positive_int
from .help_text import scene_help

__all__ = ["EXAMPLES", "add_cluster_options", "add_options", "sweep_command", "sweep_from_args"]

EXAMPLES = """examples:
  taichi-ice sweep sweeps/pillar.toml --out out/sweep              # local cluster, worker per core
  taichi-ice sweep sweeps/pillar.toml --out out/sweep --workers 0  # in this process, no Dask
  taichi-ice sweep --scene pillar --seeds 0-15 --friction coulomb:0.5 --friction rate-state \\
      --override field.rubble.area_fraction=0.7,0.85 --until 10 --out out/sweep
  taichi-ice sweep sweeps/pillar.toml --out out/sweep --scheduler tcp://10.0.0.1:8786
Run it again with the same --out to resume: only the worlds no batch file holds run."""


def add_options(p) -> None:
    """The options of ``taichi-ice sweep`` (beside the engine options the CLI adds)."""
    p.epilog = EXAMPLES
    p.add_argument("sweep", nargs="?", help="sweep file (TOML); or give --scene and the axes")
    p.add_argument("--out", required=True, help="output folder (an existing one is resumed)")
    p.add_argument("--scene", help=scene_help("the scene to sweep, without a sweep file"))
    p.add_argument(
        "--seeds",
        help="layouts: a count from the scene's seed (8), a range (0-15) or a list (0,3,7)",
    )
    p.add_argument(
        "--friction",
        type=parse_friction,
        action="append",
        help="a law (repeatable): coulomb[:MU], rate-state[:..], steady-state, memory-only",
    )
    p.add_argument(
        "--override",
        action="append",
        metavar="KEY=V1,V2",
        help="a scene key and its values (repeatable), e.g. ice.thickness=0.2,0.3",
    )
    p.add_argument("--metrics", help="metrics to keep, comma-separated (default all)")
    add_cluster_options(p)
    p.add_argument(
        "--batch-size", type=_batch_size, default=None, help="worlds per batch (default: auto)"
    )
    p.add_argument("--runs", help='worlds whose HDF5 run is written: "all", "none" or 0,5,9')


def add_cluster_options(p) -> None:
    """``--workers`` and ``--scheduler``: where the batches run (sweep and study)."""
    p.add_argument(
        "--workers",
        type=_workers,
        default=None,
        help="Dask workers of an embedded local cluster (default: one per core; 0: no Dask)",
    )
    p.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://host:8786")


def _workers(text: str) -> int:
    value = nonnegative_int(text)
    if value > MAX_WORKERS:
        raise argparse.ArgumentTypeError(
            f"{text!r}: at most {MAX_WORKERS} local workers (a process each); for more, "
            "start a Dask cluster and give --scheduler"
        )
    return value


def _batch_size(text: str) -> int:
    return positive_int(text)


def _seed_option(text: str, scene_seed: int):
    try:
        if "-" in text:
            a, b = (int(x) for x in text.split("-", 1))
            return {"start": a, "count": b - a + 1}
        if "," in text:
            return [int(x) for x in text.split(",") if x.strip()]
        return {"start": scene_seed, "count": int(text)}
    except ValueError:
        raise SweepError(
            f"--seeds {text!r}: use a count (8), a range (0-15) or a list (0,3,7)"
        ) from None


def _number_list(key: str, text: str) -> list:
    values = []
    for item in text.split(","):
        try:
            values.append(int(item) if item.strip().lstrip("-").isdigit() else float(item))
        except ValueError:
            raise SweepError(f"--override {key}={text}: {item!r} is not a number") from None
    return values


def sweep_from_args(args) -> Sweep:
    """The Sweep the command line names: a sweep file (with ``--until``, ``--metrics``,
    ``--batch-size`` and ``--runs`` replacing its values) or ``--scene`` and the axes."""
    from ..tomlio import TOMLDecodeError, loads

    axes = {"--scene": args.scene, "--seeds": args.seeds, "--friction": args.friction}
    axes["--override"] = args.override
    if args.sweep:
        given = [k for k, v in axes.items() if v]
        if given:
            raise SweepError(
                f"{args.sweep}: {', '.join(given)} cannot be combined with a sweep file; "
                "write them in its [sweep], [[law]] and [overrides] tables"
            )
        path = Path(args.sweep)
        try:
            text = path.read_text(encoding="utf-8")
            data = loads(text)
        except OSError as exc:
            raise SweepError(
                f"{path}: cannot read the sweep file ({exc.strerror or exc})"
            ) from None
        except UnicodeDecodeError as exc:
            raise SweepError(not_utf8(path, exc)) from None
        except TOMLDecodeError as exc:
            raise SweepError(f"{path}: TOML syntax error: {exc}") from None
        source, base_dir = str(path), path.parent
    else:
        if not args.scene:
            raise SweepError("give a sweep file, or --scene SCENE with --seeds, --friction ...")
        from ..scene.parse import load_scenario

        seed = load_scenario(args.scene).simulation.seed
        data = {"sweep": {"scene": str(args.scene)}}
        if args.seeds:
            data["sweep"]["seeds"] = _seed_option(args.seeds, seed)
        if args.friction:
            data["law"] = [law.to_dict() for law in args.friction]
        overrides = {}
        for item in args.override or []:
            key, eq, values = item.partition("=")
            if not eq:
                raise SweepError(
                    f"--override {item!r}: write KEY=V1,V2 (e.g. ice.thickness=0.2,0.3)"
                )
            overrides[key.strip()] = _number_list(key, values)
        if overrides:
            data["overrides"] = overrides
        source, base_dir, text = "<command line>", ".", None
    original = dict(data.get("sweep", {}))
    table = dict(original)
    if args.until is not None:
        table["until"] = args.until
    if args.batch_size is not None:
        table["batch_size"] = args.batch_size
    if args.metrics:
        table["metrics"] = [m.strip() for m in args.metrics.split(",")]
    if args.runs:
        runs = args.runs.strip()
        table["runs"] = runs if runs in ("all", "none") else _number_list("runs", runs)
    data = {**data, "sweep": table}
    # The file's own text when the command line changed nothing in it; else the tables.
    text = text if table == original else None
    return sweep_from_dict(data, source=source, base_dir=base_dir, text=text)


def sweep_command(args) -> int:
    """The body of ``taichi-ice sweep``."""
    sweep = sweep_from_args(args)
    result = run_sweep(
        sweep,
        args.out,
        workers=args.workers,
        scheduler=args.scheduler,
        arch=args.arch,
        precision=args.precision,
        progress=not args.quiet,
    )
    print(
        f"wrote {result.path}: {len(result.ran)} worlds run, {len(result.reused)} reused, "
        f"{result.wall_time:.0f} s, {result.world_steps / max(result.wall_time, 1e-9):.0f} "
        "world-steps/s"
    )
    return 1 if result.failed_batches else 0
