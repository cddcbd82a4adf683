"""What a step of the jammed pillar costs, and a 20 s pillar run's stepping, for one engine or
several side by side (the paper's scene, one world, a thread, float64; the law's default
integrator, or ``--integrator``).

    python benchmarks/jam_step.py --out out/jam_step
    git worktree add /tmp/before <rev>
    python benchmarks/jam_step.py --out out/jam_step --trees /tmp/before . --rounds 4

Each tree (a checkout holding ``taichi_ice``) runs in fresh processes, the trees one after
the other in every round, so that the machine's load falls on both alike. A process, for each
law: runs the pillar to ``--at`` seconds (the jam carries load from about 10 s), saves that
state (``World.transfer``), and steps ``--steps`` steps from it ``--windows`` times (the
same steps each time: the fastest and the median window per step); then times a whole run
from 0 to 20 s after a first step that compiled, and hashes its positions and angles at 20 s
(equal hashes: the trees' trajectories are the same bit for bit). A change that moves the
trajectory gives each tree another jam at ``--at``; ``--same-state`` steps every tree from the
first tree's (saved in ``--out`` by its first process, loaded by the others).

Writes ``jam_step.json`` (every window and run, the trees' git revisions, the machine) and
``jam_step.png`` into ``--out``, and prints a line per run.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def worker(
    law_text: str,
    at: float,
    steps: int,
    windows: int,
    state_file: str = "",
    until: float = 20.0,
    integrator: str | None = None,
) -> dict:
    import hashlib

    import numpy as np

    from taichi_ice import Simulation, backend, load_scenario
    from taichi_ice.physics.friction_parse import parse_law

    backend.init("cpu", "f64")
    law = parse_law(law_text)
    kw = {"arch": "cpu", "precision": "f64", "integrator": integrator}
    sim = Simulation([load_scenario("pillar")], friction=law, **kw)
    world = sim.world
    if state_file and Path(state_file).is_file():  # the first tree's jam (--same-state)
        sim.run(until=sim.dt)  # compiled (or loaded)
        # The fields this tree has and the first lacks (scratch added since) keep their own.
        state = world.transfer.read()
        with np.load(state_file) as saved:
            state.update({name: saved[name] for name in saved.files if name in state})
            done = int(saved["_steps"])
        origin = "loaded"
    else:
        sim.run(until=at)
        state, done = world.transfer.read(), world.steps
        origin = "own"
        if state_file:
            np.savez(state_file, _steps=done, **state)
            origin = "saved"
    per_step = []
    for _ in range(windows):
        world.transfer.write(state)
        world.steps, world.time = done, done * world.dt
        start = time.perf_counter()
        world.advance(steps)
        world.check()
        per_step.append((time.perf_counter() - start) / steps)
    contacts = int(world.contact_counts().sum())

    run = Simulation([load_scenario("pillar")], friction=law, **kw)
    run.run(until=run.dt)  # compiled (or loaded) and stepped once
    start = time.perf_counter()
    run.run(until=until)
    stepping = time.perf_counter() - start
    end = run.world
    digest = hashlib.sha1(end.positions().tobytes() + end.angles().tobytes()).hexdigest()
    return {
        "jam_us": [1e6 * s for s in per_step],
        "jam_fastest_us": 1e6 * min(per_step),
        "jam_median_us": 1e6 * float(np.median(per_step)),
        "jam_contacts": contacts,
        "jam_state": origin,  # its own jam, or saved for the other trees, or loaded
        "run_steps": int(run.world.steps),
        "run_stepping_s": stepping,
        "run_hash": digest[:12],
    }


def _git(tree: Path) -> str:
    out = subprocess.run(
        ["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    )
    dirty = subprocess.run(
        ["git", "-C", str(tree), "status", "--porcelain", "--untracked-files=no"],
        capture_output=True,
        text=True,
    ).stdout.strip()
    return out.stdout.strip() + ("+changes" if dirty else "")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/jam_step"))
    ap.add_argument("--trees", nargs="+", type=Path, default=[ROOT], help="checkouts to compare")
    ap.add_argument("--laws", default="coulomb:0.9,rate-state", help="comma-separated laws")
    ap.add_argument("--rounds", type=int, default=3, help="fresh processes per tree and law")
    ap.add_argument("--at", type=float, default=15.0, help="the jam's state: seconds run first")
    ap.add_argument("--steps", type=int, default=2000, help="steps a timed window")
    ap.add_argument("--until", type=float, default=20.0, help="the whole run's end (s)")
    ap.add_argument("--windows", type=int, default=9, help="timed windows from that state")
    # The names the engine takes. Appended, not put first: a worker must import the package
    # of the tree it times (its PYTHONPATH), not this checkout's.
    sys.path.append(str(ROOT))
    from taichi_ice.physics.timestep import INTEGRATORS

    ap.add_argument("--integrator", choices=INTEGRATORS, help="the step (default: the law's)")
    ap.add_argument(
        "--same-state",
        action="store_true",
        help="step every tree from the first tree's jam (saved in --out), not its own: for "
        "changes that move the trajectory (their jams at --at differ)",
    )
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--state-file", default="", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        row = worker(
            args.worker,
            args.at,
            args.steps,
            args.windows,
            args.state_file,
            args.until,
            args.integrator,
        )
        print(json.dumps(row))
        return 0

    trees = [t.resolve() for t in args.trees]
    for tree in trees:
        if not (tree / "taichi_ice" / "__init__.py").is_file():
            print(f"--trees: {tree} holds no taichi_ice package (a checkout of the repository)")
            return 2
    args.out.mkdir(parents=True, exist_ok=True)
    for stale in args.out.glob("state-*.npz"):  # an earlier run's jam: the first tree saves anew
        stale.unlink()
    runs = []
    for law in args.laws.split(","):
        for r in range(args.rounds):
            for tree in trees:
                env = {**os.environ, "PYTHONPATH": str(tree)}
                cmd = [sys.executable, __file__, "--at", str(args.at), "--steps", str(args.steps)]
                cmd += ["--windows", str(args.windows), "--until", str(args.until)]
                cmd += ["--worker", law]
                if args.integrator:
                    cmd += ["--integrator", args.integrator]
                if args.same_state:
                    name = "state-" + "".join(c if c.isalnum() else "_" for c in law) + ".npz"
                    cmd += ["--state-file", str((args.out / name).resolve())]
                proc = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=tree)
                if proc.returncode != 0:
                    print(proc.stderr[-2000:], file=sys.stderr)
                    return 1
                row = {"law": law, "round": r, "tree": str(tree), "git": _git(tree)}
                row.update(json.loads(proc.stdout.splitlines()[-1]))
                runs.append(row)
                print(
                    f"{law:12s} {row['git']:>16s}  jam {row['jam_fastest_us']:5.1f} us a step "
                    f"(median {row['jam_median_us']:5.1f}; {row['jam_contacts']} contacts)  "
                    f"run to {args.until:g} s: {row['run_stepping_s']:5.2f} s stepping, "
                    f"{row['run_hash']}",
                    flush=True,
                )
    (args.out / "jam_step.json").write_text(
        json.dumps(
            {"machine": platform.platform(), "cpus": os.cpu_count(), "at": args.at,
             "steps": args.steps, "windows": args.windows, "until": args.until,
             "same_state": args.same_state, "integrator": args.integrator,
             "runs": runs},
            indent=1,
        )
    )  # fmt: skip
    _chart(runs, args.out / "jam_step.png", args.integrator)
    return 0


def _chart(runs, path: Path, integrator: str | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    laws = list(dict.fromkeys(r["law"] for r in runs))
    trees = list(dict.fromkeys((r["tree"], r["git"]) for r in runs))
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.2), layout="constrained")
    for ax, key, label in (
        (axes[0], "jam_fastest_us", "jammed step, fastest window (us)"),
        (axes[1], "run_stepping_s", "20 s run, stepping (s)"),
    ):
        for k, (tree, git) in enumerate(trees):
            for j, law in enumerate(laws):
                ys = [r[key] for r in runs if r["tree"] == tree and r["law"] == law]
                xs = [j + 0.25 * (k - (len(trees) - 1) / 2)] * len(ys)
                ax.plot(xs, ys, "o", color=f"C{k}", label=git if j == 0 else None)
        ax.set_xticks(range(len(laws)), laws)
        ax.set_xlim(-0.5, len(laws) - 0.5)
        ax.set_ylabel(label)
        ax.set_ylim(0, 1.15 * max(r[key] for r in runs))
        ax.grid(alpha=0.3)
    axes[0].legend(title="engine", fontsize=8)
    step = f"{integrator} step" if integrator else "the law's default step"
    fig.suptitle(
        f"pillar scene, one world, a thread, {step} (each point a fresh process)", fontsize=10
    )
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    sys.exit(main())
