"""Small scenes: wall time per simulated second of the paper's pillar scene (63 blocks).

A scene of tens of blocks is dominated by what a step costs beyond its physics (kernel
launches, offloaded tasks, read-backs). This script times ``Simulation.run`` of the pillar
scene, one world and a batch of layouts, Coulomb and rate-and-state, and writes what it
measured:

    python benchmarks/small_scene.py --out out/small --until 2
    python benchmarks/small_scene.py --batch 1 17 --laws coulomb:0.9 rate-state

For each case: wall seconds per simulated second (of one world, and per world of a batch),
steps per second, world-steps per second, body-steps per second. The first ``--warmup``
simulated seconds of each case are run first (untimed) so compilation is not counted.
Writes ``small_scene.csv`` and ``small_scene.json`` into ``--out``.
"""

from __future__ import annotations

import argparse
import csv
import json
import platform
import time
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/small_scene"))
    ap.add_argument("--until", type=float, default=2.0, help="simulated seconds timed")
    ap.add_argument("--warmup", type=float, default=0.05, help="simulated seconds untimed")
    ap.add_argument("--batch", type=int, nargs="+", default=[1, 17])
    ap.add_argument("--laws", nargs="+", default=["coulomb:0.9", "rate-state"])
    ap.add_argument("--precision", default="f64")
    ap.add_argument("--arch", default="cpu")
    args = ap.parse_args(argv)

    from taichi_ice import Simulation, backend, load_scenario
    from taichi_ice.physics.friction_parse import parse_law
    from taichi_ice.scene.parse import reseeded

    backend.init(args.arch, args.precision)
    base = load_scenario("pillar")
    rows = []
    for law in args.laws:
        for n in args.batch:
            scenes = [reseeded(base, base.simulation.seed + k) for k in range(n)]
            sim = Simulation(
                scenes, friction=parse_law(law), arch=args.arch, precision=args.precision
            )
            sim.run(until=args.warmup)
            steps0 = sim.steps
            start = time.perf_counter()
            sim.run(until=args.warmup + args.until)
            wall = time.perf_counter() - start
            steps = sim.steps - steps0
            bodies = sum(len(s.bodies) for s in scenes)
            row = {
                "law": law,
                "worlds": n,
                "bodies": bodies,
                "dt": sim.dt,
                "simulated_s": args.until,
                "wall_s": wall,
                "wall_per_sim_s": wall / args.until,
                "wall_per_world_sim_s": wall / args.until / n,
                "steps_per_s": steps / wall,
                "world_steps_per_s": steps * n / wall,
                "body_steps_per_s": steps * bodies / wall,
                "us_per_step": 1e6 * wall / steps,
            }
            rows.append(row)
            print(
                f"{law:>12} x{n:<3d} {row['wall_per_sim_s']:8.3f} s per simulated s "
                f"({row['wall_per_world_sim_s']:.3f} per world), {row['us_per_step']:8.1f} us/step,"
                f" {row['body_steps_per_s'] / 1e6:6.2f} M body-steps/s",
                flush=True,
            )
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "small_scene.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    meta = {"machine": platform.platform(), "processor": platform.processor(), **vars(args)}
    meta["out"] = str(meta["out"])
    (args.out / "small_scene.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
