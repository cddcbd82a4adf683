"""The ``taichi-ice`` command (also ``python -m taichi_ice``).

A user's mistake (a bad scene file, an unstable dt, a run that diverged, an output that
exists or is taken, an arch this machine lacks) ends with one line on stderr naming what to
fix and exit status 2, never a traceback. SIGTERM (``timeout``, batch schedulers) stops a run
as Ctrl-C does: its file is closed, marked failed with the reason, and kept.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
from pathlib import Path

from .._version import __version__
from ..engine.options import INTEGRATORS
from ..errors import Interrupted, TaichiIceError
from ..scene.table import printable
from .args import (
    nonnegative_int,
    parse_dt,
    parse_duration,
    parse_friction,
    positive_float,
    positive_int,
    slots_per_body,
)
from .help_text import ARCH_HELP, OPTIMIZE_HELP, PRECISION_HELP, SLOTS_HELP, scene_help

EXAMPLES = {
    "run": """examples:
  taichi-ice run scenarios/pushed_field.toml --out runs/pushed.h5
  taichi-ice run scenarios/pushed_field.toml --friction rate-state --until 5
  taichi-ice run scenarios/two_squares.toml --friction coulomb:0.3 --dt 5e-5 --precision f32
  taichi-ice run scenarios/pillar.toml --out runs/p.h5 --checkpoint-every 10min
  taichi-ice run scenarios/pillar.toml --out runs/p.h5 --resume     # after a kill or failure
  taichi-ice run scenarios/pushed_field.toml --contacts   # + every contact at every frame

--contacts adds the group /contacts to the run file: at every frame, one row per contact
(body_a, body_b, point, normal, width, overlap area, force_normal and force_tangential on
body_b, slip_rate, theta, mu, stuck), the forces of the step that starts at the frame; open
it with xarray.open_dataset(FILE, group="contacts"), see its force chains with taichi-ice
plot and export. The run itself is the same bit for bit; the rows cost about 0.2 ms of host
time per contact per frame.""",
    "validate": """examples:
  taichi-ice validate --out out/validation          # Figure 3, exact solutions, stability
  taichi-ice validate --out out/validation --speed  # + speed against accuracy (minutes)
  taichi-ice validate --out out/validation --dem    # + the DEM's accuracy against cost, its
                                                    #   stability limits and the contacts'
                                                    #   convergence in dt (~20 minutes)""",
    "paper": """examples:
  taichi-ice paper --out out/paper                  # Figures 3-6, budget, spread over 16 layouts,
                                                    # variants of the law, ice strength
  taichi-ice paper --out out/paper --seeds 0        # the four single runs only
  taichi-ice paper --out /tmp/short --until 2 --seeds 2   # a smoke run
  taichi-ice paper --out out/paper --resume         # after a kill: finished models are kept

With --out, each model's batch writes a checkpoint every 2 minutes of wall clock
(--checkpoint-every); --resume skips Figure 3 and the models finished and continues the
model that was stopped from its checkpoint (same options).""",
    "ensemble": """examples:
  taichi-ice ensemble scenarios/pillar.toml --seeds 32 --out out/ens
  taichi-ice ensemble scenarios/pillar.toml --seeds 8 --friction coulomb:0.3 \\
      --friction rate-state:t_c=5 --until 10 --out out/ens
  taichi-ice ensemble scenarios/pillar.toml --seeds 32 --out out/ens --checkpoint-every 10min
  taichi-ice ensemble scenarios/pillar.toml --seeds 32 --out out/ens --resume   # after a kill

--resume skips the laws finished (read back from their files) and continues the law that
was stopped from its checkpoint (same scene and options): the files equal those of an
ensemble never stopped.""",
    "bench": """examples:
  taichi-ice bench --out out/bench                  # 1e3, 1e4, 1e5 blocks; f64 and f32; Box2D
  taichi-ice bench --sizes 1e5 1e6 --precision f32 --arch gpu --no-box2d
  taichi-ice bench --sizes 200 --steps 5 --no-box2d --out /tmp/bench   # a smoke run""",
    "export": """examples:
  taichi-ice export runs/pillar.h5 --vtk out/pillar_vtk    # then open pillar.pvd in ParaView
  taichi-ice export runs/pillar.h5 --vtk out/v --every 10 --overwrite

Each frame is a VTK PolyData file (.vtp): every floe a polygon, with cell data velocity,
angular_velocity, body (index) and kind (0 dynamic, 1 fixed, 2 kinematic); the .pvd file
collects them with their times. A run with per-contact rows (run --contacts) also gets its
force chains, RUN_contacts_000000.vtp ... and RUN_contacts.pvd: a line per contact from one
body's centroid through the contact point to the other's, with cell data force_normal,
force_tangential, slip_rate, theta, mu, stuck, body_a and body_b.""",
    "plot": """examples:
  taichi-ice plot runs/pushed.h5                    # figures beside the file
  taichi-ice plot runs/pushed.h5 --out figs/ --animate""",
}


def _cmd_run(args) -> int:
    from ..run import output
    from ..scene.parse import load_scenario

    out = args.out or str(Path("runs") / (Path(args.scene).stem + ".h5"))
    folder = Path(out).parent
    made = not folder.exists()
    # The output is claimed (checked, locked) before the scene is read or Taichi starts.
    output.claim(out, overwrite=args.overwrite, resume=args.resume, inputs=[args.scene])
    try:
        return _run_scene(args, load_scenario(args.scene), out)
    finally:
        output.release(out)
        if made:  # a folder the claim made and nothing was written to: not left behind
            with contextlib.suppress(OSError):
                folder.rmdir()


def _run_scene(args, scene, out: str) -> int:
    import numpy as np

    from ..run.simulation import Simulation

    sim = Simulation(
        scene,
        friction=args.friction,
        arch=args.arch,
        precision=args.precision,
        dt=args.dt,
        force_dt=args.force_dt,
        slots=args.slots,
        integrator=args.integrator,
        contacts=args.contacts,
    )
    law = sim.scenes[0].friction
    ran = sim.arch_used if sim.arch_used == args.arch else f"{sim.arch_used} (--arch {args.arch})"
    print(
        f"{args.scene}: {scene.n_bodies} bodies, {law!r}, {sim.options.integrator} step, "
        f"dt = {sim.dt:.3g} s (limit {sim.world.stable_dt:.3g} s), {ran}/{args.precision}"
        + (f"; {sim.dt_note}" if sim.dt_note else "")
        + (f"; WARNING: {sim.forced_note}" if sim.forced_note else ""),
        file=sys.stderr,
    )
    for note in scene.notes:  # outlines a tessellation or a file had simplified or hulled
        print(f"note: {note}", file=sys.stderr)
    result = sim.run(
        until=args.until,
        out=out,
        progress=not args.quiet,
        overwrite=True,  # claimed above, with --overwrite or not
        resume=args.resume,
        checkpoint_every=args.checkpoint_every,
    )
    e = sim.energies()
    probe = result.series[0]["probe_force"]
    peak = float(np.max(np.linalg.norm(probe, axis=-1))) if probe.size else 0.0
    from ..run.budget import WORK

    work = sum(e[k] for k in WORK)  # of kinematic bodies, external forces and the forcing
    scale = max(abs(work), e["kinetic_energy"] + e["friction_energy"], 1e-300)
    print(
        f"wrote {out}: {result.steps} steps in {result.wall_time:.1f} s "
        f"({result.steps / max(result.wall_time, 1e-9):.0f} steps/s); "
        f"peak probe force {peak / 1e3:.3g} kN; friction {e['friction_energy']:.4g} J; "
        f"work in {work:.4g} J; budget residual {e['residual']:.3g} J "
        f"({100 * e['residual'] / scale:.2f} %)"
        + (f"; WARNING: {result.warning}" if result.warning else "")
    )
    return 0


def _cmd_validate(args) -> int:
    from ..experiments.validation import validate_command

    return validate_command(args.out, speed=args.speed, quick=args.quick, dem=args.dem)


def _cmd_paper(args) -> int:
    from ..experiments.models import DEFAULT_SCENE
    from ..experiments.paper.reproduce import reproduce

    reproduce(
        args.out,
        seeds=args.seeds,
        scene_path=args.scene or DEFAULT_SCENE,
        until=args.until,
        arch=args.arch,
        precision=args.precision,
        progress=not args.quiet,
        quick=args.quick,
        extras=not args.paper_only,
        resume=args.resume,
        overwrite=args.overwrite,
        checkpoint_every=args.checkpoint_every,
    )
    return 0


def _cmd_ensemble(args) -> int:
    from ..experiments.ensemble import ensemble_command

    return ensemble_command(
        args.scene,
        args.out,
        n_seeds=args.seeds,
        laws=args.friction or [None],
        until=args.until,
        arch=args.arch,
        precision=args.precision,
        progress=not args.quiet,
        overwrite=args.overwrite,
        resume=args.resume,
        checkpoint_every=args.checkpoint_every,
    )


def _cmd_sweep(args) -> int:
    from .sweep import sweep_command

    return sweep_command(args)


def _cmd_study(args) -> int:
    from .study import study_command

    return study_command(args)


def _cmd_bench(args) -> int:
    from ..experiments.bench import bench_command

    return bench_command(args)


def _cmd_plot(args) -> int:
    from ..run.plots import plot_run

    written = plot_run(args.run, out_dir=args.out, animate=args.animate)
    for path in written:
        print(f"wrote {path}")
    return 0


def _cmd_export(args) -> int:
    from ..run.export import export_vtk

    pvd = export_vtk(
        args.run, args.vtk, overwrite=args.overwrite, binary=not args.ascii, every=args.every
    )
    print(f"wrote {pvd} (open it in ParaView)")
    return 0


def _engine_options(p: argparse.ArgumentParser) -> None:
    """The options every command that runs scenes shares: arch, precision, end, progress."""
    p.add_argument(
        "--arch",
        default=None,
        choices=["cpu", "gpu", "cuda", "vulkan", "metal"],
        help=ARCH_HELP,
    )
    p.add_argument(
        "--precision", default=None, choices=["f64", "f32"], help=PRECISION_HELP + "; default f64"
    )
    p.add_argument("--optimize", default=None, choices=["off", "on", "full"], help=OPTIMIZE_HELP)
    p.add_argument(
        "--until",
        type=positive_float,
        default=None,
        metavar="SECONDS",
        help="simulated time to stop at, in s (default: the scene's duration), e.g. --until 5",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar on stderr")


def _folder_resume_options(p: argparse.ArgumentParser, every: str | None = None) -> None:
    """--overwrite, --resume and --checkpoint-every of a command that writes a folder of runs
    (``taichi_ice.experiments.ledger``); ``every``: the default interval."""
    p.add_argument(
        "--checkpoint-every",
        type=parse_duration,
        default=parse_duration(every) if every else None,
        metavar="DURATION",
        help="write the whole state of the batch that runs to a checkpoint every DURATION of "
        "wall clock (30s, 10min, 1h), and when stopped by Ctrl-C or SIGTERM"
        + (f" (default {every})" if every else ""),
    )
    again = p.add_mutually_exclusive_group()
    again.add_argument(
        "--resume",
        action="store_true",
        help="continue the run in --out that was stopped: what finished is kept, the part that "
        "was running continues from its checkpoint (same options)",
    )
    again.add_argument(
        "--overwrite", action="store_true", help="start anew over an earlier run in --out"
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="taichi-ice",
        description="Sea-ice rubble DEM with rate-and-state friction (Taichi, CPU and GPU).",
    )
    parser.add_argument("--version", action="version", version=f"taichi-ice {__version__}")
    sub = parser.add_subparsers(
        dest="command",
        required=True,
        metavar="COMMAND",
        help="one of those below; taichi-ice COMMAND --help gives its options and examples",
    )

    def add(name, help_, func):
        p = sub.add_parser(
            name,
            help=help_,
            description=help_,
            epilog=EXAMPLES.get(name),
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        p.set_defaults(func=func)
        return p

    p = add("run", "run one scene and write its HDF5 file", _cmd_run)
    p.add_argument("scene", help=scene_help("the scene to run"))
    p.add_argument("--out", help="HDF5 run file to write (default runs/<scene>.h5)")
    p.add_argument(
        "--friction",
        type=parse_friction,
        default=None,
        help="override the scene's law: coulomb[:MU] or rate-state[:A=..,B=..,...]",
    )
    _engine_options(p)
    p.add_argument(
        "--dt",
        type=parse_dt,
        default=None,
        metavar="SECONDS",
        help="time step in s, e.g. --dt 5e-5, or 'auto' (the default: the scene's dt, a "
        "share of the contact stability limit)",
    )
    p.add_argument(
        "--force-dt",
        action="store_true",
        help="accept a dt above the stability limit (for stability studies)",
    )
    p.add_argument(
        "--slots",
        type=slots_per_body,
        default=None,
        metavar="N",
        help=SLOTS_HELP,
    )
    p.add_argument(
        "--integrator",
        default=None,
        choices=list(INTEGRATORS),
        help="how a step moves the bodies (default the scene's [simulation] integrator, else "
        "the law's: midstep with Coulomb friction, at 0.6 of the stability limit; euler with a "
        "law with a memory, at 0.05; docs/accuracy.md, 'So the default step'). euler: contact "
        "forces of the step's start (first order; Coulomb at 0.2 of the limit); analytic: each "
        "contact's spring-dashpot solved over the step; coupled: the analytic step with each "
        "contact's normal and tangent solved together; midstep: the coupled step with each "
        "contact linearised at mid-step (second order where a collision is smooth). With "
        'dt = "auto" the step follows the integrator given here',
    )
    p.add_argument(
        "--contacts",
        action="store_true",
        help="also write every contact at every frame to the group /contacts (pair, point, "
        "normal, width, overlap, normal and tangential force, slip rate, theta, mu, stuck; "
        "the step that starts at the frame); the run steps the same, bit for bit",
    )
    p.add_argument(
        "--checkpoint-every",
        type=parse_duration,
        default=None,
        metavar="DURATION",
        help="write the whole state to OUT.ckpt every DURATION of wall clock (30s, 10min, 1h), "
        "at a frame, and when stopped by Ctrl-C or SIGTERM",
    )
    again = p.add_mutually_exclusive_group()
    again.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the output file if it exists (and remove its checkpoint)",
    )
    again.add_argument(
        "--resume",
        action="store_true",
        help="continue the run in --out from its last checkpoint (same scene and options)",
    )

    p = add(
        "validate", "check the friction law against its exact solutions (Figure 3)", _cmd_validate
    )
    p.add_argument("--out", default="out/validation", help="output folder (default out/validation)")
    p.add_argument("--speed", action="store_true", help="also chart speed against accuracy")
    p.add_argument(
        "--dem",
        action="store_true",
        help="also chart the DEM's error against cost (collisions, pushed box, pillar scene), "
        "find the largest stable dt of each scene, and check that friction at a contact "
        "converges in dt (slider, hold and slide, steady sliding, every law in the pillar scene)",
    )
    p.add_argument("--quick", action="store_true", help="small sizes (for tests)")

    p = add(
        "paper",
        "the paper's experiment: rubble past a pillar, four friction models, spread over layouts",
        _cmd_paper,
    )
    p.add_argument("--out", default="out/paper", help="output folder (default out/paper)")
    p.add_argument(
        "--seeds",
        type=nonnegative_int,
        default=16,
        help="other jittered layouts per model, run as batched worlds (default 16; 0 skips)",
    )
    p.add_argument(
        "--scene",
        default=None,
        help=scene_help("the scene of the four models' runs (default: pillar)"),
    )
    _engine_options(p)
    p.add_argument("--quick", action="store_true", help="small sizes for Figure 3 (for tests)")
    p.add_argument(
        "--paper-only",
        action="store_true",
        help="only the paper's four models: skip the variants (healing below v_star, "
        "steady-state, memory-only) over the same layouts and the two runs with an ice "
        "strength",
    )
    _folder_resume_options(p, every="2min")

    p = add(
        "ensemble",
        "one scene over many seeds (and laws) as batched worlds: metrics, spread chart",
        _cmd_ensemble,
    )
    p.add_argument("scene", help=scene_help("the scene whose layouts are run"))
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument(
        "--seeds",
        type=positive_int,
        default=16,
        help="layouts: jittered fields from the scene's seed on, one world each (default 16)",
    )
    p.add_argument(
        "--friction",
        type=parse_friction,
        action="append",
        help="a law to run (repeatable; default the scene's): coulomb[:MU], rate-state[:..]",
    )
    _engine_options(p)
    _folder_resume_options(p)

    from .study import add_options as study_options
    from .sweep import add_options as sweep_options

    p = add(
        "sweep",
        "layouts x friction laws x scene overrides in batches on Dask (resumable): a netCDF file",
        _cmd_sweep,
    )
    sweep_options(p)
    _engine_options(p)
    p = add(
        "study",
        "the pillar scene over layouts x 8 friction models x area fractions: claims with CIs",
        _cmd_study,
    )
    study_options(p)
    _engine_options(p)

    p = add(
        "bench",
        "throughput, contacts and memory on a box of diamonds, 1e3 to 1e6 blocks, against Box2D v3",
        _cmd_bench,
    )
    from .bench import add_options

    add_options(p)

    p = add("plot", "figures (and an animation) of a run file", _cmd_plot)
    p.add_argument("run", help="HDF5 run file that taichi-ice run wrote (also while it runs)")
    p.add_argument("--out", default=None, help="folder for the figures (default: beside the file)")
    p.add_argument(
        "--animate",
        action="store_true",
        help="also write RUN.gif: every frame of the run beside the probe force, 10 images "
        "a second",
    )

    p = add(
        "export",
        "a run file's frames for ParaView: floes as polygons with their velocity, and force "
        "chains if the run wrote its contacts (VTK files)",
        _cmd_export,
    )
    p.add_argument("run", help="HDF5 run file that taichi-ice run wrote")
    p.add_argument(
        "--vtk",
        required=True,
        metavar="DIR",
        help="folder for RUN_000000.vtp ... and RUN.pvd (made if missing)",
    )
    p.add_argument(
        "--every", type=positive_int, default=1, metavar="N", help="every N-th frame (default 1)"
    )
    p.add_argument("--ascii", action="store_true", help="arrays as text, not base64")
    p.add_argument("--overwrite", action="store_true", help="replace an earlier export in DIR")
    return parser


def _terminate(signum, frame) -> None:
    # SIGTERM outside a run's steps (a run notes it and stops at the end of its stride).
    raise Interrupted(f"stopped by {signal.Signals(signum).name}")


# What Taichi's Vulkan runtime says when the driver refuses a launch (too many workgroups).
DISPATCH_REFUSED = "Dispatch error"


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    previous = None
    try:
        previous = signal.signal(signal.SIGTERM, _terminate)
    except ValueError:  # not the main thread (a test's, an embedding's): leave it
        pass
    try:
        if hasattr(args, "arch") and hasattr(args, "precision"):
            from .. import backend

            # Unset: cpu and f64, or what Taichi already runs on when main is called in a
            # process that started it (a notebook, the GPU test lane).
            args.arch, args.precision = backend.resolve(args.arch, args.precision)
            if getattr(args, "optimize", None):
                backend.ask_optimize(args.optimize)
            running = backend.current()
            if args.arch != "cpu" and (running is None or running[0] != args.arch):
                # In a child process: a GPU that crashes ti.init stays there.
                backend.probe(args.arch)
        return int(args.func(args) or 0)
    except Interrupted as exc:
        print(f"taichi-ice: {exc} (files written so far are kept)", file=sys.stderr)
        return 143 if "SIGTERM" in str(exc) else 130
    except TaichiIceError as exc:
        # One line whatever the message quotes (a key or a name with a newline in it).
        print(f"taichi-ice: error: {printable(exc)}", file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(f"taichi-ice: error: {exc.filename or exc}: no such file", file=sys.stderr)
        return 2
    except RuntimeError as exc:
        if DISPATCH_REFUSED not in str(exc):
            raise
        # Taichi launches a thread an element; Vulkan promises 65,535 workgroups a launch
        # and lavapipe gives no more (docs/performance.md, On GPUs).
        print(
            "taichi-ice: error: the GPU driver refused a kernel launch (Taichi: "
            f"{printable(str(exc).strip().splitlines()[-1])}): some drivers (lavapipe) take at "
            "most 65,535 workgroups of 128 threads, which a field of more than 8,388,480 "
            "elements (a World past ~5e5 blocks) needs; run it with --arch cpu or on another "
            "GPU (files written so far are kept)",
            file=sys.stderr,
        )
        return 2
    except KeyboardInterrupt:
        print("taichi-ice: interrupted (files written so far are kept)", file=sys.stderr)
        return 130
    except OSError as exc:
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"taichi-ice: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    raise SystemExit(main())
