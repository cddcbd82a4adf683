"""An animation of a run: rubble in a box, compacted by a pusher, as a GIF.

Runs the bundled scene ``pushed_field`` (diamond floes between three walls, pushed down at
0.1 m/s, with water drag) with rate-and-state friction, then draws every frame of its run
file beside the force on its probes (the pusher and the bottom wall) with
``taichi_ice.run.plots.animate_run``, the function behind ``taichi-ice plot RUN --animate``.

    python examples/animate_run.py --out out/examples          # 10 s, a frame every 0.5 s
    python examples/animate_run.py --out out/examples --quick  # 1 s: a smoke test

It writes ``OUT/pushed_field_rs.h5`` and ``OUT/animate_run.gif``.
"""

from __future__ import annotations

import argparse
import copy
from pathlib import Path

import matplotlib

from taichi_ice import Simulation, load_scenario
from taichi_ice.physics.friction import RateState
from taichi_ice.run.plots import animate_run
from taichi_ice.run.runfile_read import read_run
from taichi_ice.scene import scene_from_dict


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/examples"), help="output folder")
    parser.add_argument("--quick", action="store_true", help="1 s instead of 10 s")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    # A bundled scene by name; its tables (scene.raw) are a dict to change and check again:
    # here a frame every 0.5 s instead of 0.1 s, so that the GIF stays small.
    bundled = load_scenario("pushed_field")
    tables = copy.deepcopy(dict(bundled.raw))
    tables["simulation"]["output_interval"] = 0.5
    scene = scene_from_dict(tables, source="pushed_field, a frame every 0.5 s")

    sim = Simulation(scene, friction=RateState(), arch="cpu")
    path = args.out / "pushed_field_rs.h5"
    result = sim.run(until=1.0 if args.quick else 10.0, out=path)
    print(f"{result.steps} steps, {result.wall_time:.1f} s of wall time: {path}")

    run = read_run(path)  # the run file as NumPy arrays: attrs, series, frames, bodies
    # Drawn at 70 dots per inch rather than matplotlib's 100, inside this block only: a GIF
    # half the size, small enough for a web page.
    with matplotlib.rc_context({"figure.dpi": 70}):
        gif = animate_run(run, args.out / "animate_run.gif", fps=5)
    print(f"{len(run['frames']['time'])} frames: {gif}")


if __name__ == "__main__":
    main()
