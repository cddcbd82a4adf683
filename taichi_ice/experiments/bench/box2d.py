"""The benchmark scene in Box2D v3 (``pyb2d3``, the optional ``bench`` extra), for comparison.

The same bodies as the DEM scene: each polygon (centroid-relative, as ``Scene.bodies`` holds
it) at the same position, angle, velocity and angular velocity, with the same areal density
``rho_i d`` (kg/m^2, so the same masses), Coulomb friction ``mu`` (``mu0`` for a
rate-and-state scene: Box2D has no rate and state), no restitution, zero gravity; fixed
bodies become static bodies. What Box2D does differently is its own: a soft-step solver with
``substeps`` sub-steps per step, a contact stiffness of its own (``contact_hertz``), and no
water. Sleeping is off (the DEM never sleeps a block) and contact events are off (nothing reads
them); everything else is Box2D's default.

Importing this module never imports ``pyb2d3``; ``version()`` says whether it is there.
"""

from __future__ import annotations

import importlib.metadata
import time
from typing import TYPE_CHECKING

import numpy as np

from ...codes import BodyKind
from .memory import rss_bytes

if TYPE_CHECKING:
    from ...scene.model import Scene

__all__ = ["DEFAULT_DT", "DEFAULT_SUBSTEPS", "DEFAULT_THREADS", "run_box2d", "version"]

# Box2D's own time step for the comparison (s). Box2D samples run at 1/60 s; 1e-3 s keeps a
# block's travel per step (1 mm at 1 m/s) far below its size, so the comparison is not won
# by taking steps the DEM could not take, and still ten times the DEM's step.
DEFAULT_DT = 1e-3
# Box2D v3's recommended sub-steps per step (b2World_Step's documentation).
DEFAULT_SUBSTEPS = 4
# Worker threads of Box2D's task system (pyb2d3.ThreadPool), one run each, the fastest of
# which the bench compares with; 0 runs Box2D without a task system. On the 2-vCPU machine
# neither is reliably the faster (at 1e5 blocks: 94 against 138 ms a step in one run, 153
# against 139 in the next), so both run.
DEFAULT_THREADS = (2, 0)


def version() -> str | None:
    """The installed ``pyb2d3`` version, or None when it is not installed."""
    try:
        return importlib.metadata.version("pyb2d3")
    except importlib.metadata.PackageNotFoundError:
        return None


def friction_coefficient(law) -> float:
    """Box2D's friction coefficient for a DEM law: ``mu`` (Coulomb) or ``mu0`` (rate and state)."""
    for name in ("mu", "mu0"):
        if hasattr(law, name):
            return float(getattr(law, name))
    raise ValueError(f"no friction coefficient for Box2D in {law!r}")


def build(scene: Scene, threads: int = 2):
    """A ``pyb2d3.World`` holding ``scene``'s bodies, and its dynamic bodies as a batch.

    Returns:
        ``(world, bodies, masses)``: the world, a ``pyb2d3.Bodies`` of the dynamic bodies in
        scene order, and their masses (kg) as Box2D computed them, ``(D,)``.
    """
    import pyb2d3 as b2

    pool = b2.ThreadPool(threads) if threads > 0 else None
    world = b2.World(gravity=(0.0, 0.0), thread_pool=pool)
    world.sleeping_enabled = False
    material = b2.surface_material(friction=friction_coefficient(scene.friction), restitution=0.0)
    shape_def = b2.shape_def(
        density=scene.ice.density * scene.ice.thickness,
        material=material,
        enable_contact_events=False,
    )
    shapes: dict[int, object] = {}  # one Box2D polygon per distinct outline array
    batch = b2.Bodies()
    masses = []
    for body in scene.bodies:
        key = id(body.vertices)
        if key not in shapes:
            shapes[key] = b2.polygon(points=np.asarray(body.vertices))
        common = {"position": tuple(body.position), "rotation": float(body.angle)}
        if body.kind == BodyKind.DYNAMIC.label:
            handle = world.create_dynamic_body(
                **common,
                linear_velocity=tuple(body.velocity),
                angular_velocity=float(body.omega),
            )
        elif body.kind == BodyKind.FIXED.label:
            handle = world.create_static_body(**common)
        else:
            raise ValueError(f"Box2D comparison: body '{body.name}' is {body.kind}; not supported")
        handle.create_shape(shape_def, shapes[key])
        if body.kind == BodyKind.DYNAMIC.label:
            batch.append(handle)
            masses.append(handle.mass)
    return world, batch, np.array(masses)


def run_box2d(
    scene: Scene,
    steps: int,
    dt: float = DEFAULT_DT,
    substeps: int = DEFAULT_SUBSTEPS,
    threads: int = 2,
) -> dict:
    """Time ``steps`` Box2D steps of ``scene`` after one warm-up step.

    Returns:
        A dict: ``box2d_version``, ``box2d_threads``, ``box2d_dt_s``, ``box2d_substeps``,
        ``box2d_steps``, ``box2d_build_s`` (creating the world), ``box2d_step_ms``,
        ``box2d_body_steps_per_s`` and ``box2d_body_s_per_s`` (bodies, walls included, as for
        the DEM), ``box2d_rss_mb`` (resident memory the world added), and for checks
        ``masses`` (kg), ``positions`` and ``velocities`` of the dynamic bodies at the end.
    """
    rss_before, _ = rss_bytes()
    start = time.perf_counter()
    world, batch, masses = build(scene, threads)
    build_s = time.perf_counter() - start
    world.step(dt, substeps)  # the first step finds every pair: not timed
    start = time.perf_counter()
    for _ in range(steps):
        world.step(dt, substeps)
    step_s = (time.perf_counter() - start) / steps
    rss_after, _ = rss_bytes()
    positions = np.array(batch.get_positions(), dtype=np.float64)
    velocities = np.array(batch.get_linear_velocities(), dtype=np.float64)
    n = scene.n_bodies
    return {
        "box2d_version": version(),
        "box2d_threads": threads,
        "box2d_dt_s": dt,
        "box2d_substeps": substeps,
        "box2d_steps": steps,
        "box2d_build_s": build_s,
        "box2d_step_ms": step_s * 1e3,
        "box2d_body_steps_per_s": n / step_s,
        "box2d_body_s_per_s": n * dt / step_s,
        "box2d_rss_mb": (rss_after - rss_before) / 2**20,
        "masses": masses,
        "positions": positions,
        "velocities": velocities,
    }
