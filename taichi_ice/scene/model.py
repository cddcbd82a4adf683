"""The scene model: a validated, immutable :class:`Scene` of bodies, fields and settings.

What the engine, the recorders and the ensemble runner read; ``taichi_ice.scene.parse`` builds
it from a TOML file (and checks every value first), so the classes here trust their inputs.
This module holds the model only: it never parses, and never imports the parser. What needs
a scene checked whole again, such as another seed's field jitter, is the parser's
(``taichi_ice.scene.parse.reseeded``).

    scene.bodies[0].position, scene.masses, scene.kinds, scene.dt

Bodies are numbered from 0: the ``[[body]]`` tables in file order, then each ``[[field]]`` row
by row. Plain Python and NumPy: importing this module never starts Taichi.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from ..codes import BodyKind
from ..physics import polygon
from ..physics.forcing import AIR_DENSITY, AIR_DRAG
from ..physics.timestep import default_integrator, default_safety, stable_time_step
from ..readonly import frozen
from ..tomlio import dump_toml

if TYPE_CHECKING:
    from ..physics.friction import Coulomb, RateState
    from .grid import ForcingGrid

__all__ = [
    "DEFAULT_OUTPUT_INTERVAL",
    "DEFAULT_SERIES_INTERVAL",
    "SHAPES",
    "Body",
    "CoriolisProperties",
    "FieldSpec",
    "IceProperties",
    "Scene",
    "SimulationSettings",
    "WaterProperties",
    "WindProperties",
]

SHAPES = ("rectangle", "diamond", "polygon")

DEFAULT_OUTPUT_INTERVAL = 0.1  # s between frames
DEFAULT_SERIES_INTERVAL = 0.01  # s between time-series samples (capped at output_interval)
# Most vertices of one outline: the contact kernels hold an outline in a fixed-size local
# matrix (assemble.MAX_VERTS_LIMIT is this); checked here when a scene is read.
MAX_VERTICES = 16
# Most steps a run may need (duration / dt): beyond this a scene's smallest block is so small
# (or light) that the run would never end; it is refused with the block's name.
MAX_STEPS = 10**12
# Farthest a body may start from the origin, m (10,000 km: any sea). Positions are float64,
# so even here they resolve to 2 nm, far below any contact overlap.
MAX_COORDINATE = 1e7

# Body.kind is a BodyKind label; Scene.kinds turns it into the code the kernels compare with.
_DYNAMIC = BodyKind.DYNAMIC.label
_KIND_CODES = {kind.label: int(kind) for kind in BodyKind}


@dataclass(frozen=True)
class SimulationSettings:
    """The ``[simulation]`` table.

    Attributes:
        duration: simulated time, s.
        dt: time step, s, or ``None`` for ``"auto"`` (``Scene.dt`` is the step chosen).
        output_interval: time between frames, s; frames at 0, interval, ..., duration.
        series_interval: time between time-series samples, s.
        seed: seed of the field jitter (``numpy.random.default_rng``).
        dt_safety: fraction of the stability limit that ``dt = "auto"`` takes, in (0, 1];
            ``None`` for the law's and integrator's (``Scene.dt_safety``: 0.6 with Coulomb
            friction and the midstep step, 0.2 with Coulomb and another step, 0.05 with a
            law that has a memory; ``timestep.default_safety``).
        force_dt: accept a ``dt`` above the stability limit (stability studies).
        integrator: how a step moves the bodies, one of ``options.INTEGRATORS``, or ``None``
            for ``"auto"``: the law's (``Scene.integrator``: "midstep" with Coulomb
            friction, "euler" with a law that has a memory; ``timestep.default_integrator``).
            The engine's ``Options.integrator`` (``--integrator``), when given, wins.
    """

    duration: float
    dt: float | None = None
    output_interval: float = DEFAULT_OUTPUT_INTERVAL
    series_interval: float = DEFAULT_SERIES_INTERVAL
    seed: int = 0
    dt_safety: float | None = None
    force_dt: bool = False
    integrator: str | None = None


@dataclass(frozen=True)
class IceProperties:
    """The ``[ice]`` table.

    Attributes:
        density: ice density, kg/m^3.
        thickness: floe thickness, m.
        contact_stiffness: ``k_e``, N/m per m of contact width.
        contact_viscosity: ``k_v``, Pa s per m of contact width.
        tangential_stiffness: ratio ``k_t / k_e`` of the tangential stick spring to the normal
            one, dimensionless; a contact of width L has ``k_t = ratio k_e L``.
        tangential_damping: the tangential dashpot as a fraction of critical damping of the
            stick spring at the pair's mass along the tangent (``contact_law.tangential_damping``),
            dimensionless.
        slide_resolution: a sliding rate-and-state contact's step is taken in sub-steps of
            at most this fraction of its stick spring's relaxation time ``c_t / k_t``
            (``slip.sliding_steps``; the Euler step), so that the slip rate the law sees does
            not depend on dt through the spring's backward-Euler relaxation (a contact's first
            step is taken whole). Default 0.025: over 128 pillar layouts the default step and a
            quarter of it then give rate and state's peak force +7.3 % [-1.7, +16.3] apart and
            each within 3.6 % of a sixteenth step, where in one step they differ by +18.1 %
            [+8.2, +27.9] (docs/accuracy.md); 0: one step (the default before 2026-11-27).
            Dimensionless, >= 0.
        crushing_strength: the ice's strength (Pa), or None (default: no limit). A contact's
            normal elastic force is capped at strength x thickness x contact width; overlap
            beyond the cap is crushed, not recovered, and its work is the budget's
            ``crushing`` term.
    """

    density: float = 920.0
    thickness: float = 0.3
    contact_stiffness: float = 9.75e7
    contact_viscosity: float = 3.16e4
    tangential_stiffness: float = 0.5
    tangential_damping: float = 0.25
    slide_resolution: float = 0.025
    crushing_strength: float | None = None


@dataclass(frozen=True)
class WaterProperties:
    """The ``[water]`` table (a scene without it has no water drag).

    Attributes:
        density: water density, kg/m^3.
        form_drag: form drag coefficient on the submerged frontal area, dimensionless.
        skin_drag: skin drag coefficient on the wetted plan (bottom) area, dimensionless.
        current: the ocean current, m/s: ``(u, v)`` everywhere, a ``grid.ForcingGrid``, or
            None (still water). The drag acts on the floe's velocity relative to it.
        geostrophic: the current is geostrophic: the sea surface tilts to balance its
            Coriolis force, and pushes every floe with ``m f k x u`` (needs ``current`` and
            a ``[coriolis]`` table).
    """

    density: float = 1010.0
    form_drag: float = 1.0
    skin_drag: float = 0.005
    current: tuple[float, float] | ForcingGrid | None = None
    geostrophic: bool = False


@dataclass(frozen=True)
class WindProperties:
    """The ``[wind]`` table: air drag ``rho_a C_a S |U - v| (U - v)`` on every dynamic floe
    (``physics.forcing``).

    Attributes:
        velocity: the wind, m/s: ``(u, v)`` everywhere or a ``grid.ForcingGrid``.
        air_density: kg/m^3 (default the standard atmosphere at sea level).
        drag: the air-ice drag coefficient ``C_a`` on the plan area, dimensionless
            (default Hibler's 1979 value, ``physics.forcing.AIR_DRAG``).
    """

    velocity: tuple[float, float] | ForcingGrid
    air_density: float = AIR_DENSITY
    drag: float = AIR_DRAG


@dataclass(frozen=True)
class CoriolisProperties:
    """The ``[coriolis]`` table: the Coriolis force ``-m f k x v`` on every dynamic floe.

    Attributes:
        latitude: degrees north (negative south), or None where ``f`` was given.
        f: the Coriolis parameter ``2 Omega sin(latitude)``, 1/s.
    """

    latitude: float | None = None
    f: float = 0.0


@dataclass(frozen=True, eq=False)
class Body:
    """One rigid floe, wall or pusher. Arrays are read-only.

    Attributes:
        name: unique name (``[[body]]`` name, or ``<field>_r<row>_c<column>``).
        kind: a :class:`~taichi_ice.codes.BodyKind` label: ``"dynamic"``, ``"fixed"`` or
            ``"kinematic"``.
        shape: ``"rectangle"``, ``"diamond"`` or ``"polygon"``.
        vertices: ``(n, 2)`` counter-clockwise outline relative to the centroid, before the
            rotation by ``angle``, m.
        position: ``(2,)`` centroid in the world, m.
        angle: rotation, rad, counter-clockwise.
        velocity: ``(2,)`` velocity of the centroid, m/s.
        omega: angular velocity, rad/s.
        force: ``(2,)`` constant external force (dynamic bodies; zero otherwise), N.
        probe: record the contact force on this body in ``/series/probe_force``.
    """

    name: str
    kind: str
    shape: str
    vertices: np.ndarray
    position: np.ndarray
    angle: float = 0.0
    velocity: np.ndarray = dataclasses.field(default_factory=lambda: frozen(np.zeros(2)))
    omega: float = 0.0
    force: np.ndarray = dataclasses.field(default_factory=lambda: frozen(np.zeros(2)))
    probe: bool = False

    def world_vertices(self) -> np.ndarray:
        """``(n, 2)`` outline placed at ``position`` and rotated by ``angle``, m."""
        return polygon.transform(self.vertices, self.position, self.angle)


@dataclass(frozen=True, eq=False)
class FieldSpec:
    """A ``[[field]]`` as written, kept so that ``scene.reseeded`` can lay it out again.

    Attributes:
        name: prefix of the block names (default ``field<i>``).
        shape: block shape; ``vertices`` its outline relative to the block centroid, m.
        centroid_offset: ``(2,)`` centroid of the outline as written, relative to a lattice
            point, before rotation, m (zero for rectangles and diamonds).
        rows, columns: lattice size; blocks are numbered row by row.
        origin: ``(2,)`` lattice point of the first block, m. spacing: ``(2,)`` between
            lattice points in x and y, m. stagger: x shift of odd rows, m.
        jitter: each block moves by U(-jitter, jitter) in x and y, m.
        angle: rotation of every block, rad. velocity: ``(2,)`` m/s. omega: rad/s.
        velocity_jitter: each block's velocity changes by U(-v, v) in x and y, m/s.
    """

    name: str
    shape: str
    vertices: np.ndarray
    centroid_offset: np.ndarray
    rows: int
    columns: int
    origin: np.ndarray
    spacing: np.ndarray
    stagger: float = 0.0
    jitter: float = 0.0
    angle: float = 0.0
    velocity: np.ndarray = dataclasses.field(default_factory=lambda: frozen(np.zeros(2)))
    omega: float = 0.0
    velocity_jitter: float = 0.0

    @property
    def size(self) -> int:
        """Number of blocks."""
        return self.rows * self.columns

    def lattice(self) -> np.ndarray:
        """``(rows * columns, 2)`` lattice points row by row, before jitter, m."""
        rows, cols = np.divmod(np.arange(self.size), self.columns)
        x = self.origin[0] + cols * self.spacing[0] + (rows % 2) * self.stagger
        y = self.origin[1] + rows * self.spacing[1]
        return np.stack([x, y], axis=1)

    def layout(self, rng: np.random.Generator) -> list[Body]:
        """The blocks, drawing their jitter from ``rng``.

        Draws ``2 * size`` position offsets, then ``2 * size`` velocity offsets, both
        U(-1, 1) row by row (x then y), whatever ``jitter`` and ``velocity_jitter`` are: a
        field's layout depends only on the seed and the fields before it.
        """
        shape = (self.size, 2)
        position_draws = rng.uniform(-1.0, 1.0, shape)
        velocity_draws = rng.uniform(-1.0, 1.0, shape)
        c, s = math.cos(self.angle), math.sin(self.angle)
        shift = np.array(
            [
                c * self.centroid_offset[0] - s * self.centroid_offset[1],
                s * self.centroid_offset[0] + c * self.centroid_offset[1],
            ]
        )
        positions = self.lattice() + self.jitter * position_draws + shift
        velocities = self.velocity + self.velocity_jitter * velocity_draws
        zero = frozen(np.zeros(2))
        bodies = []
        for i in range(self.size):
            row, col = divmod(i, self.columns)
            bodies.append(
                Body(
                    name=f"{self.name}_r{row}_c{col}",
                    kind=_DYNAMIC,
                    shape=self.shape,
                    vertices=self.vertices,  # one read-only array shared by every block
                    position=frozen(positions[i]),
                    angle=self.angle,
                    velocity=frozen(velocities[i]),
                    omega=self.omega,
                    force=zero,
                    probe=False,
                )
            )
        return bodies


@dataclass(frozen=True, eq=False)
class Scene:
    """A validated scene: what the engine, the recorders and the ensemble runner read.

    Attributes:
        source: where it came from (a file path, ``"<string>"`` or ``"<dict>"``); errors name it.
        text: the scene as TOML (the file's text, or generated for a dict); stored in HDF5 and
            enough to rebuild this exact scene.
        simulation, ice, water, friction: the tables (``water`` is ``None`` for no drag;
            ``friction`` a ``taichi_ice.physics.friction.Coulomb`` or ``RateState``).
        wind, coriolis: the ``[wind]`` and ``[coriolis]`` tables, or None (none).
        bodies: every body: ``[[body]]`` tables in file order, then each field row by row.
        fields: the ``[[field]]`` specifications, in file order: ``FieldSpec`` (a lattice),
            ``voronoi.VoronoiField`` or ``floes.FileField``.
        raw: the input tables as given (defaults not filled); do not modify.
        notes: what was changed to make the floes of a tessellation or a file (outlines
            simplified or hulled, with the largest area change); ``taichi-ice run`` prints them.
    """

    source: str
    text: str
    simulation: SimulationSettings
    ice: IceProperties
    water: WaterProperties | None
    friction: Coulomb | RateState
    bodies: tuple[Body, ...]
    # FieldSpec, voronoi.VoronoiField or floes.FileField (which import this module).
    fields: tuple[Any, ...] = ()
    raw: Mapping[str, Any] = dataclasses.field(default_factory=dict, repr=False)
    notes: tuple[str, ...] = ()
    wind: WindProperties | None = None
    coriolis: CoriolisProperties | None = None

    @property
    def n_bodies(self) -> int:
        """Number of bodies."""
        return len(self.bodies)

    @cached_property
    def identity(self) -> str:
        """The scene's text and the ``[ice]`` values and ``dt_safety`` it resolved to, defaults
        included: what a resumed run, ensemble or sweep must share with the one it continues.
        A default that changed (``slide_resolution``, 0 -> 0.025 on 2026-11-27; rate and
        state's ``dt_safety``, 0.2 -> 0.05 on 2026-11-28) makes the same text another run."""
        ice = json.dumps(dataclasses.asdict(self.ice), sort_keys=True)
        return (
            f"{self.text}\n# [ice] as resolved: {ice}\n"
            f"# [simulation] dt_safety as resolved: {self.dt_safety!r}\n"
        )

    @cached_property
    def names(self) -> tuple[str, ...]:
        """Body names in scene order."""
        return tuple(b.name for b in self.bodies)

    @cached_property
    def kinds(self) -> np.ndarray:
        """``(N,)`` int32 :class:`~taichi_ice.codes.BodyKind` codes, in scene order."""
        return frozen(np.array([_KIND_CODES[b.kind] for b in self.bodies], dtype=np.int32))

    @cached_property
    def probe_indices(self) -> np.ndarray:
        """``(P,)`` int32 indices of the probe bodies, in scene order."""
        idx = [i for i, b in enumerate(self.bodies) if b.probe]
        return frozen(np.array(idx, dtype=np.int32))

    @cached_property
    def positions(self) -> np.ndarray:
        """``(N, 2)`` centroids, m."""
        return frozen(_stack([b.position for b in self.bodies], (0, 2)))

    @cached_property
    def angles(self) -> np.ndarray:
        """``(N,)`` angles, rad."""
        return frozen(np.array([b.angle for b in self.bodies], dtype=np.float64))

    @cached_property
    def velocities(self) -> np.ndarray:
        """``(N, 2)`` centroid velocities, m/s."""
        return frozen(_stack([b.velocity for b in self.bodies], (0, 2)))

    @cached_property
    def omegas(self) -> np.ndarray:
        """``(N,)`` angular velocities, rad/s."""
        return frozen(np.array([b.omega for b in self.bodies], dtype=np.float64))

    @cached_property
    def forces(self) -> np.ndarray:
        """``(N, 2)`` constant external forces, N."""
        return frozen(_stack([b.force for b in self.bodies], (0, 2)))

    @cached_property
    def vertex_offsets(self) -> np.ndarray:
        """``(N + 1,)`` int64: body i's vertices are ``vertices_flat[off[i]:off[i + 1]]``."""
        counts = [len(b.vertices) for b in self.bodies]
        return frozen(np.concatenate([[0], np.cumsum(counts, dtype=np.int64)]).astype(np.int64))

    @cached_property
    def vertices_flat(self) -> np.ndarray:
        """``(V, 2)`` every body's centroid-relative outline, concatenated, m."""
        return frozen(_stack([b.vertices for b in self.bodies], (0, 2), concat=True))

    @cached_property
    def _mass_properties(self) -> tuple[np.ndarray, np.ndarray]:
        rho_d = self.ice.density * self.ice.thickness
        seen: dict[int, tuple[float, float]] = {}
        masses = np.empty(self.n_bodies)
        inertias = np.empty(self.n_bodies)
        for i, b in enumerate(self.bodies):
            key = id(b.vertices)  # a field shares one outline array between its blocks
            if key not in seen:
                area, _, polar = polygon.mass_properties(b.vertices)
                seen[key] = (rho_d * area, rho_d * polar)
            masses[i], inertias[i] = seen[key]
        return frozen(masses), frozen(inertias)

    @property
    def masses(self) -> np.ndarray:
        """``(N,)`` masses ``rho_i d area``, kg (also for fixed and kinematic bodies)."""
        return self._mass_properties[0]

    @property
    def inertias(self) -> np.ndarray:
        """``(N,)`` moments of inertia about the centroid ``rho_i d J``, kg m^2."""
        return self._mass_properties[1]

    @cached_property
    def stable_dt(self) -> float:
        """Stability limit of the contact integration over the dynamic bodies, s (inf if none)."""
        outlines = (b.vertices for b in self.bodies if b.kind == _DYNAMIC)
        return stable_time_step(outlines, *self.limit_args)

    @property
    def limit_args(self) -> tuple[float, ...]:
        """The ice properties ``timestep.body_contact_limit`` takes after an outline."""
        ice = self.ice
        return (
            ice.density,
            ice.thickness,
            ice.contact_stiffness,
            ice.contact_viscosity,
            ice.tangential_stiffness,
            ice.tangential_damping,
        )

    @property
    def integrator(self) -> str:
        """How a step moves the bodies: the file's ``[simulation] integrator``, or the law's
        (``timestep.default_integrator``: "midstep" with Coulomb friction, "euler" with a law
        that has a memory; docs/accuracy.md, "So the default step")."""
        named = self.simulation.integrator
        return named if named is not None else default_integrator(self.friction.name)

    @property
    def dt_safety(self) -> float:
        """The fraction of the stability limit ``dt = "auto"`` takes: the file's
        ``[simulation] dt_safety``, or the law's with its integrator
        (``timestep.default_safety``: 0.6 with Coulomb friction and the midstep step, 0.2
        with Coulomb and the others, 0.05 with rate and state, whose pillar statistics are
        not converged at 0.2 or 0.1; docs/accuracy.md)."""
        sim = self.simulation
        if sim.dt_safety is not None:
            return sim.dt_safety
        return default_safety(self.friction.name, self.integrator)

    def with_integrator(self, integrator: str) -> Scene:
        """The same scene stepped by ``integrator`` (``options.INTEGRATORS``), its
        ``dt = "auto"`` the fraction of the limit the law takes with it; the engine's
        ``Options.integrator`` applied to a scene. ``text`` is unchanged: a run records its
        integrator beside it (run files, checkpoints)."""
        if integrator == self.integrator:
            return self
        sim = dataclasses.replace(self.simulation, integrator=integrator)
        return dataclasses.replace(self, simulation=sim)

    @cached_property
    def dt(self) -> float:
        """The time step, s: the file's, or for ``"auto"`` ``dt_safety * stable_dt``.

        ``"auto"`` never exceeds ``series_interval`` (which is what it is with no dynamic body).
        """
        sim = self.simulation
        if sim.dt is not None:
            return sim.dt
        return min(self.dt_safety * self.stable_dt, sim.series_interval, sim.output_interval)

    def with_friction(self, law: Coulomb | RateState) -> Scene:
        """The same scene with ``law`` at every contact (``text`` regenerated to match)."""
        # friction imports Taichi, which loading a scene does not need.
        from ..physics.friction import Law

        if not isinstance(law, Law):
            raise TypeError(f"law must be a friction law (Coulomb, RateState), got {law!r}")
        raw = copy.deepcopy(dict(self.raw))
        raw["friction"] = law.to_dict()
        return dataclasses.replace(self, friction=law, raw=raw, text=dump_toml(raw))


def _stack(arrays: list[np.ndarray], empty_shape: tuple[int, ...], concat: bool = False):
    if not arrays:
        return np.zeros(empty_shape)
    return np.concatenate(arrays) if concat else np.stack(arrays)
