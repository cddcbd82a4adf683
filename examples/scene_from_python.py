"""A scene built in Python and run with two friction laws side by side.

Hexagonal floes in a channel are pushed past a fixed pillar, once with constant (Coulomb)
friction and once with rate-and-state friction. The scene is a plain dict with the structure
of a scene file (docs/scenarios.md), checked by ``scene_from_dict`` as strictly as a file;
the two laws run as two worlds of one ``Simulation`` (one batch, one set of Taichi fields).

    python examples/scene_from_python.py --out out/examples          # 20 s of simulated time
    python examples/scene_from_python.py --out out/examples --quick  # 1.5 s: a smoke test

It writes a run file per law (``hexagons_<law>.h5``) and ``scene_from_python.png`` (the pillar
force of both laws, and the floes at the end), and prints each law's numbers.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from taichi_ice import Simulation
from taichi_ice.physics.friction import Coulomb, RateState
from taichi_ice.run.plots import draw_bodies
from taichi_ice.run.runfile_read import read_run
from taichi_ice.scene import scene_from_dict


def hexagon(radius: float) -> list[list[float]]:
    """A regular hexagon's vertices (m), counter-clockwise, corners on the x axis."""
    return [
        [radius * math.cos(k * math.pi / 3), radius * math.sin(k * math.pi / 3)] for k in range(6)
    ]


def channel_scene(duration: float) -> dict:
    """The scene as a dict: the tables of a scene file, in SI units."""
    wall = {"kind": "fixed", "shape": "rectangle", "width": 0.5, "length": 14.0}
    return {
        "simulation": {"duration": duration, "output_interval": 0.1, "seed": 1},
        "ice": {"thickness": 0.3},  # every other [ice] key at its default (Table 1's)
        "water": {},  # water drag, with its default coefficients
        "friction": {"law": "coulomb", "mu": 0.5},  # replaced per world below
        "body": [
            {"name": "left_wall", **wall, "position": [-0.25, 6.0]},  # inner face at x = 0
            {"name": "right_wall", **wall, "position": [5.25, 6.0]},  # inner face at x = 5
            {
                "name": "pillar",
                "kind": "fixed",
                "shape": "diamond",
                "width": 1.0,
                "length": 1.0,
                "position": [2.5, 5.5],
                "probe": True,  # its contact force goes to /series/probe_force
            },
            {
                "name": "pusher",
                "kind": "kinematic",  # moves at its velocity whatever pushes back
                "shape": "rectangle",
                "width": 4.9,
                "length": 0.4,
                "position": [2.5, 0.3],  # upper face at y = 0.5
                "velocity": [0.0, 0.2],  # m/s
            },
        ],
        "field": [
            {
                "name": "floes",
                "shape": "polygon",
                "vertices": hexagon(0.3),  # relative to each lattice point
                "rows": 6,
                "columns": 5,
                "origin": [0.6, 1.0],  # m: lowest faces 0.2 m above the pusher
                "spacing": [0.8, 0.7],
                "stagger": 0.4,  # odd rows shift right
                "jitter": 0.03,  # m, drawn from simulation.seed
                "angle": 0.1,
            }
        ],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/examples"), help="output folder")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="1.5 s (the pusher meets the floes at 1 s) instead of 20 s",
    )
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    scene = scene_from_dict(channel_scene(duration=1.5 if args.quick else 20.0), source="channel")
    laws = {"coulomb": Coulomb(mu=0.5), "rate-state": RateState()}  # the paper's parameters
    worlds = [scene.with_friction(law) for law in laws.values()]
    print(f"{scene.n_bodies} bodies a world, dt = {scene.dt:.3g} s, {len(worlds)} worlds")

    sim = Simulation(worlds, arch="cpu")  # arch="gpu" runs the same kernels on a GPU
    paths = [args.out / f"hexagons_{name}.h5" for name in laws]
    result = sim.run(out=paths)
    print(f"{result.steps} steps of {result.dt:.3g} s in {result.wall_time:.1f} s of wall time")

    header = ("peak force (kN)", 16), ("friction (kJ)", 15), ("work in (kJ)", 14), ("residual", 10)
    print(f"{'law':<12}" + "".join(f"{title:>{width}}" for title, width in header))
    for w, name in enumerate(laws):
        force = np.linalg.norm(result.series[w]["probe_force"][:, 0], axis=-1)
        budget = sim.energies(w)  # J, now: every term and what the budget misses
        share = budget["residual"] / max(budget["work_in"], 1e-30)
        print(
            f"{name:<12}{force.max() / 1e3:>16.4g}{budget['friction_energy'] / 1e3:>15.4g}"
            f"{budget['work_in'] / 1e3:>14.4g}{share:>10.2%}"
        )

    # The figure is drawn on a bare matplotlib Figure: no pyplot, no window, no global state.
    fig = Figure(figsize=(9, 4), layout="constrained")
    ax_force, *ax_floes = fig.subplots(1, 3, width_ratios=[2, 1, 1])
    for w, name in enumerate(laws):
        s = result.series[w]
        ax_force.plot(s["time"], np.linalg.norm(s["probe_force"][:, 0], axis=-1) / 1e3, label=name)
        run = read_run(paths[w])
        last = len(run["frames"]["time"]) - 1
        draw_bodies(ax_floes[w], run, last, view=(-0.5, 5.5, 3.5, 11.5))
        ax_floes[w].set_title(f"{name}, t = {run['frames']['time'][last]:.1f} s", fontsize=9)
        ax_floes[w].set_xticks([])
        ax_floes[w].set_yticks([])
    ax_force.set_xlabel("time (s)")
    ax_force.set_ylabel("force on the pillar (kN)")
    ax_force.legend()
    figure = args.out / "scene_from_python.png"
    fig.savefig(figure, dpi=80)
    print(f"wrote {figure} and {', '.join(str(p) for p in paths)}")


if __name__ == "__main__":
    main()
