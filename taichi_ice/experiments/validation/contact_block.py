"""One block on a floor: the first three checks of ``contact_convergence``.

A block (4 m x 0.25 m, 276 kg) pressed onto a floor by ``PRESS`` (``block_scene``), under
each rate-and-state law (``RATE_STATE_LAWS``), one world a law or case, one batch:

1. **The driven slider** (``slider``, ``slider_convergence``): pulled through a spring
   ``DRIVER_STIFFNESS`` whose end moves back and forth at ``0.1 sin(2 pi t / 4)`` m/s for
   ``SLIDER_UNTIL`` (the spring force is written from Python before every step, from the
   block's position and the driver's). Every reversal stops the block, so it sticks and
   starts again: the frictional work and the number of slip starts (a contact that gains a
   sliding interface) against dt over five halvings, the order of the work's convergence
   fitted against the finest run (``fit_order``).
2. **Hold and slide** (``pull``): the block slides at ``PULL_SPEEDS`` under a constant pull
   of ``PULL_LOADS`` x mu0 F_n against its motion: it stops, then must hold the pull if that
   is below mu0 F_n (the paper's rule: stuck, mu = mu0), whatever speed it slid at, and slide
   off above it. Held: the block moved less than ``HOLD_DISTANCE`` after it stopped.
3. **Steady sliding** (``steady``): the block rests against a fixed stop on a kinematic floor
   that speeds up to ``STEADY_SPEEDS`` under ``STEADY_PRESSES``: after ``STEADY_UNTIL``
   (5 t_c) the mean ``|F_t| / F_n`` over the last second against ``mu_ss(V)``.

The pillar checks, the sensitivity study, the report and the command are
``contact_convergence``'s.
"""

# No ``from __future__ import annotations``: Taichi reads the kernel's annotations as objects.

import math
import time
from typing import Any, Optional

import numpy as np
import taichi as ti

from ...physics.friction import MemoryOnly, RateState, SteadyState
from ...physics.slip import NO_INTERFACE

# ---- The block --------------------------------------------------------------------------------
FLOOR, BLOCK = 0, 1  # body indices
PRESS = 1.0e4  # N: the normal force the block is pressed onto the floor with
# The block (m): 276 kg of ice 0.3 m thick, long and low so that forces on its centroid do not
# turn it (a 1 m square under the memory-only law, whose friction rises above 0.9 as the
# slip speeds up, turned 0.16 rad about its leading corner instead of sliding).
BLOCK_WIDTH, BLOCK_HEIGHT = 4.0, 0.25
# ---- 1. The slider ----------------------------------------------------------------------------
DRIVER_STIFFNESS = 2.0e5  # N/m: the driver spring breaks the block free 4.4 cm after a reversal
DRIVER_SPEED = 0.1  # m/s: amplitude of the driver's speed
DRIVER_PERIOD = 4.0  # s
SLIDER_UNTIL = 12.0  # s: three periods, six reversals
# The driver's force is set from the block's position this often (s) and held in between: a
# sampled drive, the same at every step, so that the runs at different steps converge to one
# solution (and a run costs a kernel launch a millisecond, not two a step).
DRIVER_UPDATE = 1.0e-3
# The slider's steps: the coarsest at most this fraction of the stable step (twice the
# default), then SLIDER_HALVINGS halvings.
SLIDER_COARSEST = 0.4
SLIDER_HALVINGS = 5
# ---- 2. Hold and slide ------------------------------------------------------------------------
PULL_SPEEDS = (0.05, 0.5, 1.0)  # m/s: how fast the block slides before it stops
PULL_LOADS = (0.5, 0.8, 1.2)  # the pull, x mu0 F_n
PULL_UNTIL = 3.0  # s
# Held: the block's base moved less than this after it stopped (m). A stuck contact gives way
# by the stick spring's stretch, 2 mu0 F_n / k_t = 0.36 mm when the pull reverses it on the
# full base (0.7 mm measured: the tilted block stands on a narrower, softer contact); a
# block that slides off under 1.2 mu0 F_n covers metres.
HOLD_DISTANCE = 1.0e-3
# ---- 3. Steady sliding ------------------------------------------------------------------------
STEADY_SPEEDS = (1.0e-3, 1.0e-2, 1.0e-1)  # m/s: the floor's speed
STEADY_PRESSES = (1.0e4, 1.0e5)  # N
STEADY_UNTIL = 30.0  # s: ten t_c after the start (the slowest rigs slide only after ~7 s)
# The floor speeds up from rest over this (s). Started at once, the static-kinetic drop at
# the onset (mu0 to mu_ss) rings the block on its stop hard enough to reverse its slip at
# 1 cm/s, and the contact sticks and slips for ever after (a limit cycle of the paper's
# rule: stuck, mu0; sliding, mu_ss < mu0): steady sliding is stable but not reached.
STEADY_RAMP = 1.0
STEADY_RAMP_STEPS = 100
# The stop is this tall (m), at the block's foot: halfway up the block, the couple of the
# floor's friction and the stop's push rocked the block under 100 kN, its base's slip
# reversed with each rock, and the contact stuck and slipped (+97 % at 10 cm/s).
STOP_HEIGHT = 0.1
STEADY_WINDOW = 1.0  # s: mu is averaged over the last second

# The laws of the checks: the paper's law and the two variants that separate rate and memory.
RATE_STATE_LAWS = {
    "rate-state": RateState(),
    "steady-state": SteadyState(),
    "memory-only": MemoryOnly(),
}


def block_scene(
    law,
    *,
    velocity: float = 0.0,
    force_x: float = 0.0,
    press: float = PRESS,
    floor_speed: float = 0.0,
    stop: bool = False,
    dt: Optional[float] = None,
    tangential_stiffness: Optional[float] = None,
    duration: float = 1.0,
    ice: Optional[dict] = None,
):
    """A block (probe) pressed onto a floor by ``press`` (N) with a force ``force_x``
    along the floor; the floor fixed, or kinematic at ``floor_speed`` (m/s); with ``stop``,
    a fixed block touching its left face (what holds it on a moving floor). ``dt`` (s) is
    forced past the stable limit if asked; None takes the default step."""
    from ...scene.parse import scene_from_dict

    sim: dict[str, Any] = {"duration": duration, "output_interval": duration}
    if dt is not None:
        sim.update(dt=dt, force_dt=True, series_interval=min(dt * 100, duration))
    ice = dict(ice or {})
    if tangential_stiffness is not None:
        ice["tangential_stiffness"] = tangential_stiffness
    floor: dict[str, Any] = {
        "name": "floor",
        "kind": "kinematic" if floor_speed else "fixed",
        "shape": "rectangle",
        "width": 400.0,
        "length": 0.5,
        "position": [0.0, -0.25],  # top face at y = 0
        "probe": True,
    }
    if floor_speed:
        floor["velocity"] = [floor_speed, 0.0]
    bodies = [
        floor,
        {
            "name": "block",
            "shape": "rectangle",
            "width": BLOCK_WIDTH,
            "length": BLOCK_HEIGHT,
            "position": [0.0, 0.5 * BLOCK_HEIGHT],  # resting on the floor, not overlapping it
            "velocity": [velocity, 0.0],
            "force": [force_x, -press],
            "probe": True,
        },
    ]
    if stop:
        bodies.append(
            {
                "name": "stop",
                "kind": "fixed",
                "shape": "rectangle",
                "width": 0.5,
                "length": STOP_HEIGHT,
                # Its right face touches the foot of the block's left face, so that the stop
                # and the floor's friction, both near the floor, hardly tilt the block.
                "position": [-0.5 * BLOCK_WIDTH - 0.25, 0.5 * STOP_HEIGHT],
            }
        )
    return scene_from_dict(
        {"simulation": sim, "ice": ice, "friction": law.to_dict(), "body": bodies},
        source="contact_convergence",
    )


# The step of the checks when none is given: 0.2 of the stable limit, the default with
# Coulomb friction and until 2026-11-28 with rate and state, whose default is now 0.05
# (``timestep.RATE_STATE_SAFETY``: its pillar statistics over layouts move down to that).
# The checks were written, and their records and pages made, at 0.2; their errors shrink
# with the step (``contact_convergence``'s orders), so what holds here holds at 0.05.
CHECK_SAFETY = 0.2


def make_world(scenes, dt: Optional[float] = None):
    """A World of ``scenes`` at ``CHECK_SAFETY`` of their stable limit, or at ``dt`` (s)
    forced past the limit if asked."""
    from ...engine.world import World

    if dt is None:
        return World(scenes, dt=CHECK_SAFETY * min(s.stable_dt for s in scenes))
    return World(scenes, dt=dt, force_dt=True)


# ------------------------------------------------------------------------------------------------
# 1. The slider
# ------------------------------------------------------------------------------------------------


def driver_position(t: float) -> float:
    """Where the driver spring's end is at ``t`` (m): its speed is
    ``DRIVER_SPEED sin(2 pi t / DRIVER_PERIOD)``."""
    w = 2.0 * math.pi / DRIVER_PERIOD
    return DRIVER_SPEED / w * (1.0 - math.cos(w * t))


@ti.kernel
def _drive(
    body_pos: ti.template(),
    body_force_ext: ti.template(),
    contact_count: ti.template(),
    contact_theta: ti.template(),
    sliding: ti.template(),
    starts: ti.template(),
    blocks: ti.types.ndarray(),
    origin: ti.types.ndarray(),
    reach: ti.f64,
    stiffness: ti.f64,
    press: ti.f64,
):
    """Each block's driver force ``k_d (x_d - x)`` from its position; and the slip starts
    since the last call (the contact has a sliding interface now and had none then)."""
    for w in range(blocks.shape[0]):
        b = blocks[w]
        x = body_pos[b][0] - origin[w]
        body_force_ext[b] = ti.Vector([stiffness * (reach - x), -press])
        now = 0
        if contact_count[b] > 0 and contact_theta[b, 0] < 0.5 * NO_INTERFACE:
            now = 1
        if now == 1 and sliding[w] == 0:
            starts[w] += 1
        sliding[w] = now


def slider_steps(halvings: int, *, tangential_stiffness=None) -> list[float]:
    """The slider's steps (s): ``DRIVER_UPDATE / (n0 2^k)``, k = 0..halvings, n0 the fewest
    steps an update that keep the first at most ``SLIDER_COARSEST`` stable_dt."""
    probe = block_scene(RateState(), tangential_stiffness=tangential_stiffness)
    n0 = math.ceil(DRIVER_UPDATE / (SLIDER_COARSEST * probe.stable_dt))
    return [DRIVER_UPDATE / (n0 * 2**k) for k in range(halvings + 1)]


def slider(laws: dict, dt: float, *, until: float = SLIDER_UNTIL, tangential_stiffness=None):
    """The slider under each law (one world a law, one batch) at the step ``dt`` (which
    divides ``DRIVER_UPDATE``): frictional work (J) and slip starts per law.

    The driver's force ``k_d (x_d(t) - x)`` is set every ``DRIVER_UPDATE`` from the block's
    position and held in between (the same sampled drive at every dt, so that the runs
    converge to one solution), by a kernel that also counts the slip starts: samples at
    which the contact has a sliding interface after one at which it had none.
    """
    from ...codes import EnergyTerm

    scenes = [
        block_scene(law, dt=dt, tangential_stiffness=tangential_stiffness, duration=until)
        for law in laws.values()
    ]
    world = make_world(scenes, dt)
    every = round(DRIVER_UPDATE / dt)
    updates = round(until / DRIVER_UPDATE)
    blocks = np.array([s.start + BLOCK for s in world.world_slices()], dtype=np.int32)
    origin = world.positions()[blocks, 0].astype(np.float64)
    sliding = ti.field(ti.i32, len(blocks))
    starts = ti.field(ti.i32, len(blocks))
    d, m = world.data, world.model
    start = time.perf_counter()
    for k in range(updates + 1):
        t = k * DRIVER_UPDATE
        _drive(
            d.body_pos,
            m.body_force_ext,
            d.contact_count,
            d.contact_theta,
            sliding,
            starts,
            blocks,
            origin,
            driver_position(t),
            DRIVER_STIFFNESS,
            PRESS,
        )
        if k < updates:
            world.advance(every)
    wall = time.perf_counter() - start
    world.check()
    work = world.energies()[:, EnergyTerm.FRICTION]
    counts = starts.to_numpy()
    return {
        name: {
            "dt": dt,
            "ratio": dt / scenes[0].stable_dt,
            "friction_work_J": float(work[k]),
            "slip_starts": int(counts[k]),
            "wall_s": wall,
        }
        for k, name in enumerate(laws)
    }


def fit_order(hs, errors) -> Optional[float]:
    """Least-squares slope of log(error) against log(h) over the positive errors."""
    pts = [(math.log(h), math.log(e)) for h, e in zip(hs, errors) if e > 0.0]
    if len(pts) < 2:
        return None
    x, y = np.array(pts).T
    return float(np.polyfit(x, y, 1)[0])


def slider_convergence(laws: dict, halvings: int = SLIDER_HALVINGS, *, until=SLIDER_UNTIL) -> dict:
    """The slider at ``halvings + 1`` steps, per law: work, starts, the error against the
    finest run and the order of convergence (the slope of the error against dt)."""
    steps = slider_steps(halvings)
    by_dt = {dt: slider(laws, dt, until=until) for dt in steps}
    out = {}
    for name in laws:
        runs = [by_dt[dt][name] for dt in steps]
        finest = runs[-1]
        for r in runs:
            r["work_error_rel"] = abs(r["friction_work_J"] / finest["friction_work_J"] - 1.0)
        coarse = runs[:-1]
        out[name] = {
            "runs": runs,
            "order": fit_order([r["dt"] for r in coarse], [r["work_error_rel"] for r in coarse]),
            "starts": sorted({r["slip_starts"] for r in runs}),
        }
    return out


# ------------------------------------------------------------------------------------------------
# 2. Hold and slide under a constant pull
# ------------------------------------------------------------------------------------------------


def pull(laws: dict, speeds=PULL_SPEEDS, loads=PULL_LOADS, *, until: float = PULL_UNTIL) -> dict:
    """The block slides at each speed under a pull of each load x mu0 F_n against its
    motion, under each law (one world a case, one batch): where its base stopped, how far it
    moved after, and whether it held. (The base, not the centroid: the pull at the centroid
    and the friction at the base tilt the block a little, which moves its centroid.)"""
    cases = [(name, v, f) for name in laws for v in speeds for f in loads]
    scenes = [
        block_scene(laws[name], velocity=v, force_x=-f * laws[name].mu0 * PRESS)
        for name, v, f in cases
    ]
    world = make_world(scenes)
    dt = world.dt
    blocks = [s.start + BLOCK for s in world.world_slices()]
    n = round(until / dt)
    every = max(1, round(1e-3 / dt))

    def base():  # the middle of the block's base, where it touches the floor (m)
        return world.positions()[blocks, 0] + 0.5 * BLOCK_HEIGHT * np.sin(world.angles()[blocks])

    x, t = [base()], [0.0]
    for _ in range(0, n, every):
        world.advance(every)
        x.append(base())
        t.append(world.time)
    world.check()
    x, t = np.asarray(x), np.asarray(t)
    out: dict[str, list] = {name: [] for name in laws}
    for k, (name, v, f) in enumerate(cases):
        path = x[:, k] - x[0, k]
        turn = int(np.argmax(path))  # where the block stopped (the farthest it got)
        after = float(np.max(np.abs(path[turn:] - path[turn])))
        out[name].append(
            {
                "speed_m_s": v,
                "load": f,
                "slid_m": float(path[turn]),
                "stopped_at_s": float(t[turn]),
                "moved_after_stop_m": after,
                "held": after < HOLD_DISTANCE,
            }
        )
    return {"dt": dt, "hold_distance_m": HOLD_DISTANCE, "laws": out}


# ------------------------------------------------------------------------------------------------
# 3. Steady sliding on a moving floor
# ------------------------------------------------------------------------------------------------


def critical_stiffness(law, speed: float, press: float) -> float:
    """The stiffness (N/m) below which steady sliding of a spring-held block at ``speed``
    under ``press`` is unstable under ``law`` (quasi-static; Ruina 1983, Rice and Ruina
    1983): ``F_n (B - A) / (V t_c)``, with ``V t_c`` the law's slip distance of memory."""
    return press * (law.B - law.A) / (speed * law.t_c)


def stop_stiffness() -> float:
    """The stiffness (N/m) of the stop that holds the block: its contact is the stop's
    height wide."""
    from ...scene.model import IceProperties

    return IceProperties().contact_stiffness * STOP_HEIGHT


def steady(laws: dict, speeds=STEADY_SPEEDS, presses=STEADY_PRESSES, *, until=STEADY_UNTIL):
    """The block held by a stop on a floor that speeds up to each speed, under each press
    and law (one batch): the mean ``|F_t| / F_n`` on the floor over the last
    ``STEADY_WINDOW`` against ``mu_ss(V)``, and the stop's stiffness over the critical one
    (``critical_stiffness``: below 1, steady sliding is unstable and the block sticks and
    slips)."""
    cases = [(name, v, p) for name in laws for p in presses for v in speeds]
    scenes = [
        block_scene(laws[name], press=p, floor_speed=-v, stop=True, duration=until)
        for name, v, p in cases
    ]
    world = make_world(scenes)
    dt = world.dt
    probes = [s.start for s in world.probe_slices()]  # the floor is each world's first probe
    floors = [s.start + FLOOR for s in world.world_slices()]
    # The floor speeds up from rest over STEADY_RAMP, in STEADY_RAMP_STEPS even increments.
    every = max(1, round(STEADY_RAMP / STEADY_RAMP_STEPS / dt))
    for k in range(1, STEADY_RAMP_STEPS + 1):
        for b, (_, v, _) in zip(floors, cases):
            world.data.body_vel[b] = (-v * k / STEADY_RAMP_STEPS, 0.0)
        world.advance(every)
    world.advance(round((until - STEADY_WINDOW) / dt) - every * STEADY_RAMP_STEPS)
    world.take_probe_impulses()
    world.advance(round(STEADY_WINDOW / dt))
    impulse = world.take_probe_impulses()[probes]
    world.check()
    out: dict[str, list] = {name: [] for name in laws}
    for k, (name, v, p) in enumerate(cases):
        law = laws[name]
        mu = abs(impulse[k, 0]) / abs(impulse[k, 1])
        mu_ss = float(law.steady_state(v))
        k_c = critical_stiffness(law, v, p)
        out[name].append(
            {
                "speed_m_s": v,
                "press_N": p,
                "mu": float(mu),
                "mu_ss": mu_ss,
                "rel_error": float(mu / mu_ss - 1.0),
                # None where steady sliding is stable at any stiffness (B <= A).
                "stiffness_over_critical": stop_stiffness() / k_c if k_c > 0.0 else None,
            }
        )
    return {"dt": dt, "laws": out}
