"""Scene files: TOML in ``scenarios/`` to a validated, immutable :class:`Scene`.

A scene file has the tables ``[simulation]``, ``[ice]``, ``[water]`` (optional), ``[friction]``
(optional), and the arrays of tables ``[[body]]`` and ``[[field]]``; ``docs/scenarios.md`` is
the user's reference for every key. Everything a run needs is checked here, before Taichi
starts: every message names the file, the table (``[[body]] #3 'pillar'``) and the key, and
says how to fix it.

    scene = load_scenario("scenarios/pushed_field.toml")
    scene.bodies[0].position, scene.masses, scene.dt
    ensemble = [scene.reseeded(seed) for seed in range(100)]

Bodies are numbered from 0: the ``[[body]]`` tables in file order, then each ``[[field]]`` row
by row. Importing this module, and loading a scene, never starts Taichi.
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10: the tomli backport has the same API
    import tomli as tomllib

import numpy as np

from . import geometry
from .errors import PolygonError, ScenarioError
from .timestep import DEFAULT_SAFETY, stable_time_step

if TYPE_CHECKING:
    from .friction import Coulomb, RateState

__all__ = [
    "DYNAMIC",
    "FIXED",
    "KINDS",
    "KINEMATIC",
    "SHAPES",
    "Body",
    "FieldSpec",
    "IceProperties",
    "Scene",
    "SimulationSettings",
    "WaterProperties",
    "dump_toml",
    "find_overlaps",
    "load_scenario",
    "parse_scenario",
    "scene_from_dict",
]

# Body kinds; ``Scene.kinds`` holds these codes, ``KINDS[code]`` is the name.
KINDS = ("dynamic", "fixed", "kinematic")
DYNAMIC, FIXED, KINEMATIC = 0, 1, 2
SHAPES = ("rectangle", "diamond", "polygon")
FRICTION_LAWS = ("coulomb", "rate-state")

DEFAULT_OUTPUT_INTERVAL = 0.1  # s between frames
DEFAULT_SERIES_INTERVAL = 0.01  # s between time-series samples (capped at output_interval)

# Two bodies overlap at the start when their overlap area exceeds this fraction of the smaller
# one's area. Blocks laid edge to edge touch exactly, and round-off leaves them an overlap
# of order 1e-16 of their area; a real placement mistake is many orders above this.
OVERLAP_RTOL = 1e-6
# At most this many overlapping pairs are confirmed (and the first named) before giving up.
OVERLAP_REPORT = 5

_REQUIRED = object()

_SIMULATION_KEYS = (
    "duration",
    "dt",
    "output_interval",
    "series_interval",
    "seed",
    "dt_safety",
    "force_dt",
)
_ICE_KEYS = (
    "density",
    "thickness",
    "contact_stiffness",
    "contact_viscosity",
    "tangential_stiffness",
)
_WATER_KEYS = ("density", "form_drag", "skin_drag")
_FRICTION_KEYS = {
    "coulomb": ("law", "mu"),
    "rate-state": ("law", "A", "B", "mu0", "v_star", "t_c", "method"),
}
_BODY_KEYS = (
    "name",
    "kind",
    "shape",
    "width",
    "length",
    "vertices",
    "position",
    "angle",
    "velocity",
    "omega",
    "force",
    "probe",
)
_FIELD_KEYS = (
    "name",
    "shape",
    "width",
    "length",
    "vertices",
    "rows",
    "columns",
    "origin",
    "spacing",
    "stagger",
    "jitter",
    "angle",
    "velocity",
    "omega",
    "velocity_jitter",
)
_TOP_KEYS = ("simulation", "ice", "water", "friction", "body", "field")


# --------------------------------------------------------------------------------------------
# The scene
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SimulationSettings:
    """The ``[simulation]`` table.

    Attributes:
        duration: simulated time, s.
        dt: time step, s, or ``None`` for ``"auto"`` (``Scene.dt`` is the step chosen).
        output_interval: time between frames, s; frames at 0, interval, ..., duration.
        series_interval: time between time-series samples, s.
        seed: seed of the field jitter (``numpy.random.default_rng``).
        dt_safety: fraction of the stability limit that ``dt = "auto"`` takes, in (0, 1].
        force_dt: accept a ``dt`` above the stability limit (stability studies).
    """

    duration: float
    dt: float | None = None
    output_interval: float = DEFAULT_OUTPUT_INTERVAL
    series_interval: float = DEFAULT_SERIES_INTERVAL
    seed: int = 0
    dt_safety: float = DEFAULT_SAFETY
    force_dt: bool = False


@dataclass(frozen=True)
class IceProperties:
    """The ``[ice]`` table.

    Attributes:
        density: ice density, kg/m^3.
        thickness: floe thickness, m.
        contact_stiffness: ``k_e``, N/m per m of contact width.
        contact_viscosity: ``k_v``, Pa s per m of contact width.
        tangential_stiffness: ratio ``k_t / k_e`` of the tangential stick spring to the normal
            contact stiffness, dimensionless.
    """

    density: float = 920.0
    thickness: float = 0.3
    contact_stiffness: float = 9.75e7
    contact_viscosity: float = 3.16e4
    tangential_stiffness: float = 0.5


@dataclass(frozen=True)
class WaterProperties:
    """The ``[water]`` table (a scene without it has no water drag).

    Attributes:
        density: water density, kg/m^3.
        form_drag: form drag coefficient on the submerged frontal area, dimensionless.
        skin_drag: skin drag coefficient on the wetted plan (bottom) area, dimensionless.
    """

    density: float = 1010.0
    form_drag: float = 1.0
    skin_drag: float = 0.005


@dataclass(frozen=True, eq=False)
class Body:
    """One rigid floe, wall or pusher. Arrays are read-only.

    Attributes:
        name: unique name (``[[body]]`` name, or ``<field>_r<row>_c<column>``).
        kind: ``"dynamic"``, ``"fixed"`` or ``"kinematic"``.
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
    velocity: np.ndarray = dataclasses.field(default_factory=lambda: _frozen(np.zeros(2)))
    omega: float = 0.0
    force: np.ndarray = dataclasses.field(default_factory=lambda: _frozen(np.zeros(2)))
    probe: bool = False

    def world_vertices(self) -> np.ndarray:
        """``(n, 2)`` outline placed at ``position`` and rotated by ``angle``, m."""
        return geometry.transform(self.vertices, self.position, self.angle)


@dataclass(frozen=True, eq=False)
class FieldSpec:
    """A ``[[field]]`` as written, kept so that :meth:`Scene.reseeded` can lay it out again.

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
    velocity: np.ndarray = dataclasses.field(default_factory=lambda: _frozen(np.zeros(2)))
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
        zero = _frozen(np.zeros(2))
        bodies = []
        for i in range(self.size):
            row, col = divmod(i, self.columns)
            bodies.append(
                Body(
                    name=f"{self.name}_r{row}_c{col}",
                    kind="dynamic",
                    shape=self.shape,
                    vertices=self.vertices,  # one read-only array shared by every block
                    position=_frozen(positions[i]),
                    angle=self.angle,
                    velocity=_frozen(velocities[i]),
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
            ``friction`` a ``taichi_ice.friction.Coulomb`` or ``RateState``).
        bodies: every body: ``[[body]]`` tables in file order, then each field row by row.
        fields: the ``[[field]]`` specifications, in file order.
        raw: the input tables as given (defaults not filled); do not modify.
    """

    source: str
    text: str
    simulation: SimulationSettings
    ice: IceProperties
    water: WaterProperties | None
    friction: Coulomb | RateState
    bodies: tuple[Body, ...]
    fields: tuple[FieldSpec, ...] = ()
    raw: Mapping[str, Any] = dataclasses.field(default_factory=dict, repr=False)

    @property
    def n_bodies(self) -> int:
        """Number of bodies."""
        return len(self.bodies)

    @cached_property
    def names(self) -> tuple[str, ...]:
        """Body names in scene order."""
        return tuple(b.name for b in self.bodies)

    @cached_property
    def kinds(self) -> np.ndarray:
        """``(N,)`` int32 kind codes (``DYNAMIC``, ``FIXED``, ``KINEMATIC``; names in ``KINDS``)."""
        code = {k: i for i, k in enumerate(KINDS)}
        return _frozen(np.array([code[b.kind] for b in self.bodies], dtype=np.int32))

    @cached_property
    def probe_indices(self) -> np.ndarray:
        """``(P,)`` int32 indices of the probe bodies, in scene order."""
        idx = [i for i, b in enumerate(self.bodies) if b.probe]
        return _frozen(np.array(idx, dtype=np.int32))

    @cached_property
    def positions(self) -> np.ndarray:
        """``(N, 2)`` centroids, m."""
        return _frozen(_stack([b.position for b in self.bodies], (0, 2)))

    @cached_property
    def angles(self) -> np.ndarray:
        """``(N,)`` angles, rad."""
        return _frozen(np.array([b.angle for b in self.bodies], dtype=np.float64))

    @cached_property
    def velocities(self) -> np.ndarray:
        """``(N, 2)`` centroid velocities, m/s."""
        return _frozen(_stack([b.velocity for b in self.bodies], (0, 2)))

    @cached_property
    def omegas(self) -> np.ndarray:
        """``(N,)`` angular velocities, rad/s."""
        return _frozen(np.array([b.omega for b in self.bodies], dtype=np.float64))

    @cached_property
    def forces(self) -> np.ndarray:
        """``(N, 2)`` constant external forces, N."""
        return _frozen(_stack([b.force for b in self.bodies], (0, 2)))

    @cached_property
    def vertex_offsets(self) -> np.ndarray:
        """``(N + 1,)`` int64: body i's vertices are ``vertices_flat[off[i]:off[i + 1]]``."""
        counts = [len(b.vertices) for b in self.bodies]
        return _frozen(np.concatenate([[0], np.cumsum(counts, dtype=np.int64)]).astype(np.int64))

    @cached_property
    def vertices_flat(self) -> np.ndarray:
        """``(V, 2)`` every body's centroid-relative outline, concatenated, m."""
        return _frozen(_stack([b.vertices for b in self.bodies], (0, 2), concat=True))

    @cached_property
    def _mass_properties(self) -> tuple[np.ndarray, np.ndarray]:
        rho_d = self.ice.density * self.ice.thickness
        seen: dict[int, tuple[float, float]] = {}
        masses = np.empty(self.n_bodies)
        inertias = np.empty(self.n_bodies)
        for i, b in enumerate(self.bodies):
            key = id(b.vertices)  # a field shares one outline array between its blocks
            if key not in seen:
                area, _, polar = geometry.mass_properties(b.vertices)
                seen[key] = (rho_d * area, rho_d * polar)
            masses[i], inertias[i] = seen[key]
        return _frozen(masses), _frozen(inertias)

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
        ice = self.ice
        outlines = (b.vertices for b in self.bodies if b.kind == "dynamic")
        return stable_time_step(
            outlines, ice.density, ice.thickness, ice.contact_stiffness, ice.contact_viscosity
        )

    @cached_property
    def dt(self) -> float:
        """The time step, s: the file's, or for ``"auto"`` ``dt_safety * stable_dt``.

        ``"auto"`` never exceeds ``series_interval`` (which is what it is with no dynamic body).
        """
        sim = self.simulation
        if sim.dt is not None:
            return sim.dt
        return min(sim.dt_safety * self.stable_dt, sim.series_interval, sim.output_interval)

    def reseeded(self, seed: int) -> Scene:
        """The same scene with the field jitter drawn from ``seed``; nothing else changes.

        ``text`` is regenerated (without the file's comments) so that it rebuilds this scene.

        Raises:
            ScenarioError: the new jitter makes blocks overlap, or ``seed`` is not an integer >= 0.
        """
        if seed == self.simulation.seed:
            return self
        raw = copy.deepcopy(dict(self.raw))
        raw.setdefault("simulation", {})["seed"] = seed
        return scene_from_dict(raw, source=self.source)

    def with_friction(self, law: Coulomb | RateState) -> Scene:
        """The same scene with ``law`` at every contact (``text`` regenerated to match)."""
        from .friction import Coulomb, RateState

        if not isinstance(law, Coulomb | RateState):
            raise TypeError(f"law must be a Coulomb or RateState, got {type(law).__name__}")
        raw = copy.deepcopy(dict(self.raw))
        raw["friction"] = _friction_table(law)
        return dataclasses.replace(self, friction=law, raw=raw, text=dump_toml(raw))


# --------------------------------------------------------------------------------------------
# Entry points
# --------------------------------------------------------------------------------------------


def load_scenario(path: str | Path) -> Scene:
    """Read and validate a scene file.

    Args:
        path: a ``.toml`` scene file.

    Raises:
        ScenarioError: the file cannot be read, is not valid TOML, or is not a valid scene;
            the message names the file.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read the scene file ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"{path}: not a UTF-8 text file ({exc})") from None
    return parse_scenario(text, source=str(path))


def parse_scenario(text: str, source: str = "<string>") -> Scene:
    """Validate a scene given as TOML text; ``source`` names it in error messages.

    Raises:
        ScenarioError: a TOML syntax error (with its line and column) or an invalid scene.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{source}: TOML syntax error: {exc}") from None
    return scene_from_dict(data, source=source, text=text)


def scene_from_dict(
    data: Mapping[str, Any], source: str = "<dict>", text: str | None = None
) -> Scene:
    """Validate a scene given as nested dicts and lists (the TOML file's structure).

    NumPy arrays and scalars are accepted wherever the file has numbers and arrays.

    Args:
        data: ``{"simulation": {...}, "body": [{...}, ...], ...}``.
        source: names the scene in error messages.
        text: the TOML it came from; generated from ``data`` when ``None``.

    Raises:
        ScenarioError: the first problem found, naming the table, the key and the fix.
    """
    if not isinstance(data, Mapping):
        raise ScenarioError(f"{source}: a scene must be a table (dict), got {_type_name(data)}")
    _check_keys(source, "the top level", data, _TOP_KEYS, what="table")
    if "simulation" not in data:
        raise ScenarioError(
            f"{source}: missing table [simulation]; add it with at least duration = <seconds>"
        )
    simulation = _parse_simulation(source, data["simulation"])
    ice = _parse_ice(source, data.get("ice", {}))
    water = _parse_water(source, data["water"]) if "water" in data else None
    friction = _parse_friction(source, data.get("friction"))

    bodies: list[Body] = []
    labels: list[str] = []
    for i, table in enumerate(_array_of_tables(source, data, "body")):
        body = _parse_body(source, i, table)
        bodies.append(body)
        labels.append(f"[[body]] #{i} '{body.name}'")
    specs = [
        _parse_field(source, i, table)
        for i, table in enumerate(_array_of_tables(source, data, "field"))
    ]
    rng = np.random.default_rng(simulation.seed)
    for i, spec in enumerate(specs):
        for body in spec.layout(rng):
            bodies.append(body)
            labels.append(f"[[field]] #{i} block '{body.name}'")
    if not bodies:
        raise ScenarioError(f"{source}: the scene has no bodies; add a [[body]] or a [[field]]")
    _check_names(source, bodies, labels)

    raw = copy.deepcopy(dict(data))
    scene = Scene(
        source=source,
        text=dump_toml(raw) if text is None else text,
        simulation=simulation,
        ice=ice,
        water=water,
        friction=friction,
        bodies=tuple(bodies),
        fields=tuple(specs),
        raw=raw,
    )
    _check_time_step(scene)
    _check_overlaps(scene, labels)
    return scene


# --------------------------------------------------------------------------------------------
# Reading values
# --------------------------------------------------------------------------------------------


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=a.dtype if a.dtype.kind in "iu" else np.float64)
    a.flags.writeable = False
    return a


def _stack(arrays: list[np.ndarray], empty_shape: tuple[int, ...], concat: bool = False):
    if not arrays:
        return np.zeros(empty_shape)
    return np.concatenate(arrays) if concat else np.stack(arrays)


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float | np.integer | np.floating) and not isinstance(
        v, bool | np.bool_
    )


def _type_name(v: Any) -> str:
    if isinstance(v, bool | np.bool_):
        return f"a boolean ({str(bool(v)).lower()})"
    if isinstance(v, str):
        return f'a string ("{v}")'
    if _is_number(v):
        return f"a number ({v})"
    if isinstance(v, Mapping):
        return "a table"
    if isinstance(v, list | tuple | np.ndarray):
        return "an array"
    return f"a {type(v).__name__}"


def _suggest(key: str, known: Sequence[str]) -> str:
    lower = {k.lower(): k for k in known}
    close = difflib.get_close_matches(key.lower(), list(lower), n=1, cutoff=0.6)
    hint = f"did you mean '{lower[close[0]]}'? " if close else ""
    return f"{hint}known keys: {', '.join(known)}"


def _check_keys(source: str, label: str, data: Mapping, known: Sequence[str], what="key") -> None:
    for key in data:
        if key not in known:
            raise ScenarioError(
                f"{source}: {label}: unknown {what} '{key}'; {_suggest(key, known)}"
            )


class _Table:
    """Typed, checked access to one table; every error names the file, table and key."""

    def __init__(self, source: str, label: str, data: Any, known: Sequence[str]):
        self.source, self.label = source, label
        if not isinstance(data, Mapping):
            raise ScenarioError(f"{source}: {label} must be a table, got {_type_name(data)}")
        self.data = data
        _check_keys(source, label, data, known)

    def error(self, key: str, message: str) -> ScenarioError:
        return ScenarioError(f"{self.source}: {self.label}, key '{key}': {message}")

    def __contains__(self, key: str) -> bool:
        return key in self.data

    def _get(self, key: str, default: Any) -> Any:
        if key in self.data:
            return self.data[key]
        if default is _REQUIRED:
            raise self.error(key, "missing; this key is required")
        return default

    def _as_number(self, key: str, v: Any, what: str = "a number") -> float:
        if not _is_number(v):
            fix = ""
            if isinstance(v, str):
                try:
                    float(v)
                    fix = "; remove the quotes"
                except ValueError:
                    pass
            raise self.error(key, f"expected {what}, got {_type_name(v)}{fix}")
        x = float(v)
        if not math.isfinite(x):
            raise self.error(key, f"must be a finite number, got {x}")
        return x

    def number(
        self,
        key: str,
        default: Any = _REQUIRED,
        *,
        positive: bool = False,
        nonnegative: bool = False,
        unit: str = "",
    ) -> float:
        v = self._get(key, default)
        if v is default and key not in self.data:
            return v
        x = self._as_number(key, v)
        if positive and x <= 0.0:
            raise self.error(key, f"must be positive, got {x:g}{unit}")
        if nonnegative and x < 0.0:
            raise self.error(key, f"must not be negative, got {x:g}{unit}")
        return x

    def integer(self, key: str, default: Any = _REQUIRED, *, minimum: int | None = None) -> int:
        v = self._get(key, default)
        if v is default and key not in self.data:
            return v
        if not isinstance(v, int | np.integer) or isinstance(v, bool | np.bool_):
            raise self.error(
                key, f"expected a whole number (like 3, no decimal point), got {_type_name(v)}"
            )
        if minimum is not None and v < minimum:
            raise self.error(key, f"must be at least {minimum}, got {v}")
        return int(v)

    def boolean(self, key: str, default: bool) -> bool:
        v = self._get(key, default)
        if not isinstance(v, bool | np.bool_):
            raise self.error(key, f"expected true or false, got {_type_name(v)}")
        return bool(v)

    def string(
        self, key: str, default: Any = _REQUIRED, choices: Sequence[str] | None = None
    ) -> str:
        v = self._get(key, default)
        if not isinstance(v, str):
            raise self.error(key, f"expected a string, got {_type_name(v)}")
        if choices is not None and v not in choices:
            allowed = " | ".join(f'"{c}"' for c in choices)
            raise self.error(key, f'unknown value "{v}"; allowed: {allowed}')
        return v

    def vector(self, key: str, default: Any = _REQUIRED, *, positive: bool = False) -> np.ndarray:
        v = self._get(key, default)
        if not isinstance(v, list | tuple | np.ndarray) or len(v) != 2:
            raise self.error(key, f"expected an array of two numbers [x, y], got {_type_name(v)}")
        xy = np.array([self._as_number(key, c, "two numbers [x, y]") for c in v])
        if positive and np.any(xy <= 0.0):
            raise self.error(key, f"both components must be positive, got {xy.tolist()}")
        return _frozen(xy)

    def polygon(self, key: str) -> np.ndarray:
        v = self._get(key, _REQUIRED)
        if not isinstance(v, list | tuple | np.ndarray) or not all(
            isinstance(p, list | tuple | np.ndarray) and len(p) == 2 and all(map(_is_number, p))
            for p in v
        ):
            raise self.error(
                key, "expected an array of [x, y] number pairs, like [[0, 0], [1, 0], [0, 1]]"
            )
        try:
            return geometry.check_polygon(v, what=f"{self.source}: {self.label}, key '{key}'")
        except PolygonError as exc:
            raise ScenarioError(str(exc)) from None


def _array_of_tables(source: str, data: Mapping, key: str) -> list:
    v = data.get(key, [])
    if isinstance(v, Mapping):
        raise ScenarioError(
            f"{source}: '{key}' must be an array of tables: write [[{key}]] (double brackets), "
            f"not [{key}]"
        )
    if not isinstance(v, list | tuple):
        raise ScenarioError(
            f"{source}: '{key}' must be an array of tables [[{key}]], got {_type_name(v)}"
        )
    return list(v)


# --------------------------------------------------------------------------------------------
# Tables
# --------------------------------------------------------------------------------------------


def _parse_simulation(source: str, data: Any) -> SimulationSettings:
    t = _Table(source, "[simulation]", data, _SIMULATION_KEYS)
    duration = t.number("duration", positive=True, unit=" s")
    dt: float | None = None
    raw_dt = t._get("dt", "auto")
    if isinstance(raw_dt, str):
        if raw_dt != "auto":
            raise t.error("dt", f'expected "auto" or a time step in seconds, got "{raw_dt}"')
    else:
        dt = t._as_number("dt", raw_dt, 'a time step in seconds or "auto"')
        if dt <= 0.0:
            raise t.error("dt", f'must be positive, got {dt:g} s; or use dt = "auto"')
    output_interval = t.number("output_interval", DEFAULT_OUTPUT_INTERVAL, positive=True, unit=" s")
    if output_interval > duration:
        raise t.error(
            "output_interval",
            f"{output_interval:g} s is longer than the duration {duration:g} s; "
            "lower it (or raise duration)",
        )
    series_interval = t.number(
        "series_interval", min(DEFAULT_SERIES_INTERVAL, output_interval), positive=True, unit=" s"
    )
    if series_interval > duration:
        raise t.error(
            "series_interval",
            f"{series_interval:g} s is longer than the duration {duration:g} s; lower it",
        )
    seed = t.integer("seed", 0, minimum=0)
    dt_safety = t.number("dt_safety", DEFAULT_SAFETY)
    if not 0.0 < dt_safety <= 1.0:
        raise t.error("dt_safety", f"must be in (0, 1], got {dt_safety:g}")
    force_dt = t.boolean("force_dt", False)
    if dt is not None:
        for name, interval in (
            ("output_interval", output_interval),
            ("series_interval", series_interval),
        ):
            if dt > interval:
                raise t.error(
                    "dt",
                    f"{dt:g} s is longer than {name} = {interval:g} s; lower dt (or use "
                    f'dt = "auto"), or raise {name}',
                )
    return SimulationSettings(
        duration, dt, output_interval, series_interval, seed, dt_safety, force_dt
    )


def _parse_ice(source: str, data: Any) -> IceProperties:
    t = _Table(source, "[ice]", data, _ICE_KEYS)
    d = IceProperties()
    return IceProperties(
        density=t.number("density", d.density, positive=True, unit=" kg/m^3"),
        thickness=t.number("thickness", d.thickness, positive=True, unit=" m"),
        contact_stiffness=t.number("contact_stiffness", d.contact_stiffness, positive=True),
        contact_viscosity=t.number("contact_viscosity", d.contact_viscosity, nonnegative=True),
        tangential_stiffness=t.number(
            "tangential_stiffness", d.tangential_stiffness, positive=True
        ),
    )


def _parse_water(source: str, data: Any) -> WaterProperties:
    t = _Table(source, "[water]", data, _WATER_KEYS)
    d = WaterProperties()
    return WaterProperties(
        density=t.number("density", d.density, positive=True, unit=" kg/m^3"),
        form_drag=t.number("form_drag", d.form_drag, nonnegative=True),
        skin_drag=t.number("skin_drag", d.skin_drag, nonnegative=True),
    )


def _parse_friction(source: str, data: Any) -> Coulomb | RateState:
    from .friction import Coulomb, RateState

    if data is None:
        return Coulomb()
    if not isinstance(data, Mapping):
        raise ScenarioError(f"{source}: [friction] must be a table, got {_type_name(data)}")
    every_key = tuple(dict.fromkeys(k for keys in _FRICTION_KEYS.values() for k in keys))
    probe = _Table(source, "[friction]", data, every_key)
    law = probe.string("law", "coulomb")
    if law not in FRICTION_LAWS:
        close = difflib.get_close_matches(law.lower().replace("_", "-"), FRICTION_LAWS, n=1)
        hint = f'did you mean "{close[0]}"? ' if close else ""
        raise probe.error("law", f'unknown law "{law}"; {hint}allowed: "coulomb" | "rate-state"')
    for key in data:
        if key not in _FRICTION_KEYS[law]:
            other = next(k for k, keys in _FRICTION_KEYS.items() if key in keys)
            raise probe.error(
                key, f'belongs to law = "{other}", not law = "{law}"; remove it or change law'
            )
    keys = [k for k in _FRICTION_KEYS[law] if k != "law"]
    kwargs: dict[str, Any] = {}
    for key in keys:
        if key in data:
            kwargs[key] = probe.string(key) if key == "method" else probe.number(key)
    try:
        return Coulomb(**kwargs) if law == "coulomb" else RateState(**kwargs)
    except (TypeError, ValueError) as exc:
        # The law's own check names the bad parameter; say which file and table it came from.
        message = str(exc)
        bad = next((k for k in keys if message.startswith(k + " ")), None)
        if bad is None and "method" in message:
            bad = "method"
        where = f", key '{bad}'" if bad else ""
        raise ScenarioError(f'{source}: [friction] (law = "{law}"){where}: {exc}') from None


def _friction_table(law: Any) -> dict[str, Any]:
    return {k: (v if isinstance(v, str) else float(v)) for k, v in law.to_dict().items()}


def _outline(t: _Table, shape: str) -> np.ndarray:
    """Outline as written, relative to the body's position (m)."""
    if shape == "polygon":
        for key in ("width", "length"):
            if key in t:
                raise t.error(key, 'is for rectangle and diamond; a polygon takes only "vertices"')
        return t.polygon("vertices")
    if "vertices" in t:
        raise t.error("vertices", f'is for shape = "polygon"; a {shape} takes width and length')
    width = t.number("width", positive=True, unit=" m")
    length = t.number("length", positive=True, unit=" m")
    return (
        geometry.rectangle(width, length)
        if shape == "rectangle"
        else geometry.diamond(width, length)
    )


def _centred(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(outline relative to its centroid, centroid relative to the original origin)."""
    _, centroid, _ = geometry.mass_properties(vertices)
    return _frozen(vertices - centroid), centroid


def _rotate(v: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def _parse_body(source: str, index: int, data: Any) -> Body:
    label = f"[[body]] #{index}"
    name = f"body{index}"
    if isinstance(data, Mapping) and "name" in data:
        name = _Table(source, label, {"name": data["name"]}, ("name",)).string("name")
        if not name.strip():
            raise ScenarioError(f"{source}: {label}, key 'name': must not be empty")
    if isinstance(data, Mapping):
        label = f"{label} '{name}'"
    t = _Table(source, label, data, _BODY_KEYS)
    kind = t.string("kind", "dynamic", KINDS)
    shape = t.string("shape", _REQUIRED, SHAPES)
    vertices, centroid = _centred(_outline(t, shape))
    position = t.vector("position")
    angle = t.number("angle", 0.0)
    velocity = t.vector("velocity", _frozen(np.zeros(2)))
    omega = t.number("omega", 0.0)
    if "force" in t and kind != "dynamic":
        raise t.error(
            "force", f'only a dynamic body takes an external force; this one is "{kind}": remove it'
        )
    force = t.vector("force", _frozen(np.zeros(2)))
    if kind == "fixed":
        for key, moving in (("velocity", np.any(velocity != 0.0)), ("omega", omega != 0.0)):
            if moving:
                raise t.error(
                    key,
                    'a fixed body does not move; remove it, or use kind = "kinematic" for a body '
                    "that moves at a prescribed velocity",
                )
    probe = t.boolean("probe", False)
    return Body(
        name=name,
        kind=kind,
        shape=shape,
        vertices=vertices,
        # The position names the origin of the outline as written; the body lives at its
        # centroid, which the rotation carries along.
        position=_frozen(position + _rotate(centroid, angle)),
        angle=angle,
        velocity=velocity,
        omega=omega,
        force=force,
        probe=probe,
    )


def _parse_field(source: str, index: int, data: Any) -> FieldSpec:
    label = f"[[field]] #{index}"
    name = f"field{index}"
    if isinstance(data, Mapping) and "name" in data:
        name = _Table(source, label, {"name": data["name"]}, ("name",)).string("name")
        if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
            raise ScenarioError(
                f"{source}: {label}, key 'name': use letters, digits, '_', '-' or '.', "
                f'got "{name}"'
            )
    if isinstance(data, Mapping):
        label = f"{label} '{name}'"
    t = _Table(source, label, data, _FIELD_KEYS)
    shape = t.string("shape", _REQUIRED, SHAPES)
    vertices, centroid = _centred(_outline(t, shape))
    return FieldSpec(
        name=name,
        shape=shape,
        vertices=vertices,
        centroid_offset=_frozen(centroid),
        rows=t.integer("rows", minimum=1),
        columns=t.integer("columns", minimum=1),
        origin=t.vector("origin"),
        spacing=t.vector("spacing", positive=True),
        stagger=t.number("stagger", 0.0),
        jitter=t.number("jitter", 0.0, nonnegative=True, unit=" m"),
        angle=t.number("angle", 0.0),
        velocity=t.vector("velocity", _frozen(np.zeros(2))),
        omega=t.number("omega", 0.0),
        velocity_jitter=t.number("velocity_jitter", 0.0, nonnegative=True, unit=" m/s"),
    )


# --------------------------------------------------------------------------------------------
# Whole-scene checks
# --------------------------------------------------------------------------------------------


def _check_names(source: str, bodies: list[Body], labels: list[str]) -> None:
    first: dict[str, int] = {}
    for i, b in enumerate(bodies):
        if b.name in first:
            raise ScenarioError(
                f"{source}: {labels[i]}, key 'name': the name '{b.name}' is already used by "
                f"{labels[first[b.name]]}; body names must be unique: rename one"
            )
        first[b.name] = i


def _check_time_step(scene: Scene) -> None:
    sim = scene.simulation
    if sim.dt is None:
        return
    limit = scene.stable_dt
    if sim.dt > limit and not sim.force_dt:
        raise ScenarioError(
            f"{scene.source}: [simulation], key 'dt': {sim.dt:g} s is above the stable limit "
            f"{limit:.4g} s of the contact integration (stiffest contact of the lightest "
            f'dynamic body); use dt = "auto" (takes {sim.dt_safety:g} x the limit, '
            f"{sim.dt_safety * limit:.3g} s), a dt below the limit, or force_dt = true for a "
            "stability study"
        )


def _check_overlaps(scene: Scene, labels: list[str]) -> None:
    found = find_overlaps(scene.bodies, max_pairs=OVERLAP_REPORT)
    if not found:
        return
    i, j, area, smaller = found[0]
    a, b = scene.bodies[i], scene.bodies[j]
    more = (
        f" (and at least {len(found) - 1} more pair{'s' if len(found) > 2 else ''})"
        if len(found) > 1
        else ""
    )
    raise ScenarioError(
        f"{scene.source}: {labels[i]} and {labels[j]} overlap at the start by {area:.3g} m^2 "
        f"({100.0 * area / smaller:.3g}% of the smaller){more}; centroids at "
        f"{np.round(a.position, 6).tolist()} and {np.round(b.position, 6).tolist()}: move them "
        "apart (or, in a field, raise spacing or lower jitter)"
    )


def find_overlaps(
    bodies: Sequence[Body], max_pairs: int | None = None, rtol: float = OVERLAP_RTOL
) -> list[tuple[int, int, float, float]]:
    """Pairs of bodies that overlap, at least one of them dynamic.

    A grid broad phase (cell = the largest dynamic body's diameter; bodies much larger than a
    cell, such as long walls, are tested against every dynamic body by bounding box), then a
    bounding-circle test and a batched separating-axis test over the edge normals, in NumPy;
    the pairs left go to ``geometry.sat_separated`` and ``geometry.overlap``.

    Args:
        bodies: the scene's bodies.
        max_pairs: stop after this many overlapping pairs.
        rtol: a pair overlaps when its overlap area exceeds ``rtol`` times the smaller area.

    Returns:
        ``[(i, j, overlap_area, smaller_area), ...]`` with ``i < j``, in order of ``i``, m^2.
    """
    n = len(bodies)
    dynamic = np.array([b.kind == "dynamic" for b in bodies], dtype=bool)
    if n < 2 or not dynamic.any():
        return []
    pos = np.stack([b.position for b in bodies])
    # Outlines rotated into the world (relative to the centroid), grouped by vertex count so
    # that each group is one (members, n, 2) array.
    by_count: dict[int, list[int]] = {}
    for i, b in enumerate(bodies):
        by_count.setdefault(len(b.vertices), []).append(i)
    groups: list[np.ndarray] = []
    group_of = np.empty(n, dtype=np.int64)
    row_of = np.empty(n, dtype=np.int64)
    lo = np.empty((n, 2))
    hi = np.empty((n, 2))
    radius = np.empty(n)
    for g, members in enumerate(by_count.values()):
        idx = np.array(members)
        local = np.stack([bodies[i].vertices for i in members])
        ang = np.array([bodies[i].angle for i in members])
        c, s = np.cos(ang)[:, None], np.sin(ang)[:, None]
        rot = np.stack(
            [c * local[..., 0] - s * local[..., 1], s * local[..., 0] + c * local[..., 1]], -1
        )
        groups.append(rot)
        group_of[idx], row_of[idx] = g, np.arange(len(members))
        lo[idx] = pos[idx] + rot.min(axis=1)
        hi[idx] = pos[idx] + rot.max(axis=1)
        radius[idx] = np.sqrt((rot**2).sum(-1)).max(axis=1)

    pairs = _candidate_pairs(lo, hi, dynamic, cell=2.0 * float(radius[dynamic].max()))
    if len(pairs) == 0:
        return []
    a, b = pairs[:, 0], pairs[:, 1]
    d = pos[b] - pos[a]
    dist = np.hypot(d[:, 0], d[:, 1])
    keep = dist < radius[a] + radius[b]
    a, b = a[keep], b[keep]
    # Batched separating-axis test: it clears touching lattice neighbours, so only pairs that
    # really overlap reach the per-pair reference functions of ``geometry``.
    depth = _sat_depth(groups, group_of, row_of, pos, a, b)
    keep = depth > 1e-9 * (radius[a] + radius[b])
    a, b = a[keep], b[keep]
    order = np.lexsort((b, a))
    found: list[tuple[int, int, float, float]] = []
    areas: dict[int, float] = {}
    for i, j in zip(a[order].tolist(), b[order].tolist(), strict=True):
        pi, pj = bodies[i].world_vertices(), bodies[j].world_vertices()
        if geometry.sat_separated(pi, pj):
            continue
        area = float(geometry.overlap(pi, pj).area)
        for k in (i, j):
            if k not in areas:
                areas[k] = geometry.signed_area(bodies[k].vertices)
        smaller = min(areas[i], areas[j])
        if area > rtol * smaller:
            found.append((i, j, area, smaller))
            if max_pairs is not None and len(found) >= max_pairs:
                break
    return found


def _sat_depth(groups, group_of, row_of, pos, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Penetration depth (m) of each pair ``(a[p], b[p])`` over both bodies' edge normals.

    Positive when the pair overlaps, ``<= 0`` when an edge line separates it; the batched
    form of ``geometry.min_penetration_axis``, used only to screen candidate pairs.
    """
    depth = np.empty(len(a))
    ga, gb = group_of[a], group_of[b]
    for g in range(len(groups)):
        for h in range(len(groups)):
            m = np.flatnonzero((ga == g) & (gb == h))
            for chunk in np.array_split(m, max(1, len(m) // 50_000)):
                if len(chunk) == 0:
                    continue
                p = groups[g][row_of[a[chunk]]] + pos[a[chunk]][:, None, :]
                q = groups[h][row_of[b[chunk]]] + pos[b[chunk]][:, None, :]
                depth[chunk] = np.minimum(_edge_depth(p, q), _edge_depth(q, p))
    return depth


def _edge_depth(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``(P,)`` smallest penetration of ``q`` past the edge lines of ``p``, m."""
    edges = np.roll(p, -1, axis=1) - p
    normals = np.stack([edges[..., 1], -edges[..., 0]], axis=-1)
    normals /= np.hypot(normals[..., 0], normals[..., 1])[..., None]
    # rel[p, k, j] = n_k . (q_j - p_k): how far vertex j of q lies outside edge k of p.
    rel = np.einsum("pkd,pjd->pkj", normals, q) - np.einsum("pkd,pkd->pk", normals, p)[..., None]
    return (-rel.min(axis=2)).min(axis=1)


# A body whose bounding box spans more grid cells than this per axis is tested by brute force.
_LARGE_CELLS = 4


def _candidate_pairs(
    lo: np.ndarray, hi: np.ndarray, dynamic: np.ndarray, cell: float
) -> np.ndarray:
    """``(P, 2)`` pairs ``i < j`` whose bounding boxes overlap, at least one dynamic."""
    n = len(lo)
    ilo = np.floor(lo / cell).astype(np.int64)
    ihi = np.floor(hi / cell).astype(np.int64)
    span = ihi - ilo + 1
    large = np.any(span > _LARGE_CELLS, axis=1)
    chunks = []

    small = np.flatnonzero(~large)
    if len(small) > 1:
        dx, dy = np.meshgrid(np.arange(_LARGE_CELLS), np.arange(_LARGE_CELLS), indexing="ij")
        dx, dy = dx.ravel(), dy.ravel()
        cx = ilo[small, 0][:, None] + dx
        cy = ilo[small, 1][:, None] + dy
        inside = (cx <= ihi[small, 0][:, None]) & (cy <= ihi[small, 1][:, None])
        ids = np.broadcast_to(small[:, None], cx.shape)[inside]
        cx, cy = cx[inside], cy[inside]
        cx -= cx.min()
        cy -= cy.min()
        key = cx * (int(cy.max()) + 1) + cy
        order = np.argsort(key, kind="stable")
        key, ids = key[order], ids[order]
        # Every ordered pair (p, q), p < q, of entries sharing a cell.
        starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
        ends = np.r_[starts[1:], len(key)]
        group_end = np.repeat(ends, ends - starts)
        count = group_end - np.arange(len(key)) - 1
        p = np.repeat(np.arange(len(key)), count)
        offset = np.arange(len(p)) - np.repeat(np.cumsum(count) - count, count)
        q = p + 1 + offset
        chunks.append(np.stack([ids[p], ids[q]], axis=1))
    for i in np.flatnonzero(large):
        j = np.flatnonzero(dynamic)
        j = j[j != i]
        chunks.append(np.stack([np.full(len(j), i), j], axis=1))
    if not chunks:
        return np.zeros((0, 2), dtype=np.int64)
    pairs = np.concatenate(chunks)
    pairs = np.sort(pairs, axis=1)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    pairs = np.unique(pairs[:, 0] * n + pairs[:, 1])
    pairs = np.stack(np.divmod(pairs, n), axis=1)
    i, j = pairs[:, 0], pairs[:, 1]
    keep = (
        (dynamic[i] | dynamic[j]) & np.all(lo[i] <= hi[j], axis=1) & np.all(lo[j] <= hi[i], axis=1)
    )
    return pairs[keep]


# --------------------------------------------------------------------------------------------
# TOML output
# --------------------------------------------------------------------------------------------

_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _toml_key(key: str) -> str:
    return key if _BARE_KEY.fullmatch(key) else json.dumps(key)


def _toml_value(v: Any) -> str:
    if isinstance(v, np.ndarray):
        v = v.tolist()
    elif isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # JSON string escapes are valid TOML basic-string escapes
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} as TOML")


def dump_toml(data: Mapping[str, Any]) -> str:
    """Write scene data (tables, arrays of tables, numbers, strings, arrays) as TOML text."""
    lines: list[str] = []
    scalars = {k: v for k, v in data.items() if not _is_table(v) and not _is_table_array(v)}
    for k, v in scalars.items():
        lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
    for k, v in data.items():
        if _is_table(v):
            lines += ["", f"[{_toml_key(k)}]"]
            lines += [f"{_toml_key(kk)} = {_toml_value(vv)}" for kk, vv in v.items()]
        elif _is_table_array(v):
            for table in v:
                lines += ["", f"[[{_toml_key(k)}]]"]
                lines += [f"{_toml_key(kk)} = {_toml_value(vv)}" for kk, vv in table.items()]
    return "\n".join(lines).lstrip("\n") + "\n"


def _is_table(v: Any) -> bool:
    return isinstance(v, Mapping)


def _is_table_array(v: Any) -> bool:
    return isinstance(v, list | tuple) and len(v) > 0 and all(isinstance(x, Mapping) for x in v)
