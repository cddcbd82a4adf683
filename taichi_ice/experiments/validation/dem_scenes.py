"""The scenes of the DEM accuracy and stability studies (``dem_accuracy``, ``dem_stability``).

- ``collision(offset)``: a 1 m square and a 1 m x 0.8 m block (``scenarios/two_squares.toml``
  with the right square shortened along y) touching at t = 0 and closing at 1 m/s along x;
  face on (``offset = 0``: the block's 0.8 m face lies inside the square's, so the contact is
  that face, its normal x, and nothing turns) or with the block shifted up by ``offset`` (the
  contact is off both centroids: it turns them and slides). The block is shorter so that no
  two edges are collinear (a degenerate case of the chord, which round-off can tilt);
- ``pushed_box``: ``scenarios/pushed_field.toml`` with the pusher 5 cm above the rubble at
  0.5 m/s down: 36 diamonds compacted against the bottom wall, with water;
- ``pillar``: the paper's scene, ``scenarios/pillar.toml``, as shipped;
- ``dense_box``: the pillar scene's 63 diamonds (85 % of their lattice is ice) shut in a box
  at random velocities of up to 0.5 m/s, no pusher, no pillar: every block meets its
  neighbours within ~0.1 s;
- ``jam``: the pillar scene at mu = 0.9, whose jam against the pillar carries ~3 MN by 17 s.

``with_step`` sets a scene's sampling so that a chosen dt is exact (``Simulation`` shortens
dt to fit whole steps into the output interval); ``nudge`` moves one body by the last bit of
one coordinate. Plain NumPy: no Taichi until a Simulation is built.
"""

from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np

from ...codes import BodyKind
from ...physics.friction import Coulomb, RateState
from ...scene.parse import load_scenario, scene_from_dict

# The squares touch at t = 0, so that the contact starts on a step boundary at every dt (a
# gap would put the touch at a different phase of the step for each dt, and the error would
# jump about by O(dt) rather than shrink smoothly).
GAP = 0.0  # m between the squares' faces at t = 0
CLOSING_SPEED = 1.0  # m/s
BLOCK_LENGTH = 0.8  # m: the right block along y
OFFSET = 0.3  # m: the offset collision's lateral shift (the contact is 0.6 m of a face)
COLLISION_END = 0.01  # s: the contact lasts ~3.8-4.4 ms; then they fly apart
PUSHER_SPEED = 0.5  # m/s, the pushed box's pusher
DENSE_SPEED = 0.5  # m/s, the dense box's velocity jitter
JAM_MU = 0.9
# The two collisions by name, and the block's offset in each (m).
COLLISIONS = {"face-on collision": 0.0, "offset collision": OFFSET}


def law_named(name: str) -> Coulomb | RateState:
    """The study's two laws: ``coulomb`` (mu = 0.5, the pillar scene's) and ``rate-state``
    (the paper's parameters and rule)."""
    return Coulomb(0.5) if name == "coulomb" else RateState()


def collision(offset: float = 0.0, law: str = "coulomb"):
    """A 1 m square and a 1 m x ``BLOCK_LENGTH`` block ``GAP`` apart (touching), closing at
    ``CLOSING_SPEED``; the block ``offset`` (m) higher. No water, no force: the ODE's setting
    (``collision_ode``)."""
    base = load_scenario("two_squares")
    raw = copy.deepcopy(dict(base.raw))
    raw["simulation"].update(
        duration=COLLISION_END, output_interval=COLLISION_END, series_interval=COLLISION_END
    )
    raw["friction"] = law_named(law).to_dict()
    half = 0.5 * CLOSING_SPEED
    raw["body"][0].update(position=[-0.5 - GAP / 2, 0.0], velocity=[half, 0.0])
    raw["body"][1].update(
        length=BLOCK_LENGTH, position=[0.5 + GAP / 2, float(offset)], velocity=[-half, 0.0]
    )
    return scene_from_dict(raw, source=f"collision(offset={offset:g})")


def pushed_box(law: str = "coulomb"):
    """``pushed_field`` with its pusher 5 cm above the rubble, moving down at 0.5 m/s."""
    base = load_scenario("pushed_field")
    raw = copy.deepcopy(dict(base.raw))
    raw["friction"] = law_named(law).to_dict()
    pusher = next(b for b in raw["body"] if b["name"] == "pusher")
    pusher.update(position=[3.0, 7.0], velocity=[0.0, -PUSHER_SPEED])
    return scene_from_dict(raw, source="pushed_box")


def pillar(law: str = "coulomb"):
    """The paper's scene as shipped, with ``law`` at every contact."""
    return load_scenario("pillar").with_friction(law_named(law))


def jam():
    """The pillar scene at mu = 0.9: a jam that carries MN against the pillar by ~17 s."""
    return load_scenario("pillar").with_friction(Coulomb(JAM_MU))


def dense_box():
    """The pillar scene's rubble shut in a 5.6 m x 5.6 m box at random velocities."""
    base = load_scenario("pillar")
    raw = copy.deepcopy(dict(base.raw))
    walls = [b for b in raw["body"] if b["name"] in ("left_wall", "right_wall")]
    for b in walls:
        b.update(length=6.6, position=[b["position"][0], 2.8])
    walls += [
        {
            "name": "bottom",
            "kind": "fixed",
            "shape": "rectangle",
            "width": 6.6,
            "length": 0.5,
            "position": [2.8, -0.25],
        },
        {
            "name": "top",
            "kind": "fixed",
            "shape": "rectangle",
            "width": 6.6,
            "length": 0.5,
            "position": [2.8, 5.85],
        },
    ]
    raw["body"] = walls
    field = raw["field"][0]
    field.update(velocity=[0.0, 0.0], velocity_jitter=DENSE_SPEED)
    raw["simulation"]["duration"] = 1.0
    return scene_from_dict(raw, source="dense_box")


def with_step(scene, dt: float, sample: float, frames: int = 1):
    """The scene with series every ``round(sample / dt)`` steps of ``dt`` and frames every
    ``frames`` samples, so that ``Simulation(scene, dt=dt)`` keeps ``dt`` (to round-off)."""
    every = max(1, round(sample / dt))
    sim = dataclasses.replace(
        scene.simulation,
        series_interval=every * dt,
        output_interval=frames * every * dt,
        duration=max(scene.simulation.duration, frames * every * dt),
    )
    return dataclasses.replace(scene, simulation=sim)


def nudge(scene, body: int):
    """The same scene with body ``body``'s x moved up by one unit in the last place."""
    bodies = list(scene.bodies)
    pos = np.array(bodies[body].position)
    pos[0] = np.nextafter(pos[0], math.inf)
    pos.flags.writeable = False
    bodies[body] = dataclasses.replace(bodies[body], position=pos)
    return dataclasses.replace(scene, bodies=tuple(bodies))


def first_at_pillar(scene) -> int:
    """Index of the rubble block nearest the pillar at t = 0 (the first to meet it)."""
    names = scene.names
    pillar_pos = scene.positions[names.index("pillar")]
    dynamic = np.flatnonzero(scene.kinds == int(BodyKind.DYNAMIC))
    dist = np.linalg.norm(scene.positions[dynamic] - pillar_pos, axis=1)
    return int(dynamic[np.argmin(dist)])


__all__ = [
    "collision",
    "dense_box",
    "first_at_pillar",
    "jam",
    "law_named",
    "nudge",
    "pillar",
    "pushed_box",
    "with_step",
]
