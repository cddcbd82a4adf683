"""Scene files: TOML to a validated, immutable :class:`~taichi_ice.scene.model.Scene`.

A scene file has the tables ``[simulation]``, ``[ice]``, ``[water]``, ``[wind]`` and
``[coriolis]`` (optional), ``[friction]`` (optional), and the arrays of tables ``[[body]]`` and
``[[field]]``; ``docs/scenarios.md`` is
the user's reference for every key. Everything a run needs is checked here, before Taichi
starts: every message names the file, the table (``[[body]] #3 'pillar'``) and the key, and
says how to fix it.

    scene = load_scenario("scenarios/pushed_field.toml")
    scene = load_scenario("pillar")          # a scene shipped with the package
    scene.bodies[0].position, scene.masses, scene.dt
    ensemble = [reseeded(scene, seed) for seed in range(100)]

The job is split by module: the scene model is ``taichi_ice.scene.model``, the checked reading of
one table ``taichi_ice.scene.table``, each table of the file to its part of the model
``taichi_ice.scene.tables``, the start-up overlap search ``taichi_ice.scene.overlaps``, TOML text
in and out ``taichi_ice.tomlio``. This module loads a file, lays the fields out, checks the
scene whole (names, masses, extent, time step, overlaps) and draws another seed's jitter
(:func:`reseeded`); it re-exports the public names of the others so that
``taichi_ice.scene.parse`` is the one import a caller needs. Importing it, and loading a scene,
never starts Taichi.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from ..codes import BodyKind
from ..errors import ScenarioError
from ..limits import check_size
from ..physics.timestep import body_contact_limit, contact_damping
from ..tomlio import TOMLDecodeError, dump_toml, loads
from .model import (
    DEFAULT_OUTPUT_INTERVAL,
    DEFAULT_SERIES_INTERVAL,
    MAX_COORDINATE,
    MAX_STEPS,
    SHAPES,
    Body,
    CoriolisProperties,
    FieldSpec,
    IceProperties,
    Scene,
    SimulationSettings,
    WaterProperties,
    WindProperties,
)
from .overlaps import OVERLAP_RTOL, find_overlaps
from .table import array_of_tables, check_keys, type_name
from .tables import (
    parse_body,
    parse_coriolis,
    parse_field,
    parse_friction,
    parse_ice,
    parse_simulation,
    parse_water,
    parse_wind,
)

__all__ = [
    "DEFAULT_OUTPUT_INTERVAL",
    "DEFAULT_SERIES_INTERVAL",
    "OVERLAP_RTOL",
    "SHAPES",
    "Body",
    "CoriolisProperties",
    "FieldSpec",
    "IceProperties",
    "Scene",
    "SimulationSettings",
    "WaterProperties",
    "WindProperties",
    "bundled_scenes",
    "dump_toml",
    "find_overlaps",
    "load_scenario",
    "parse_scenario",
    "reseeded",
    "scene_from_dict",
]

# At most this many overlapping pairs are confirmed (and the first named) before giving up.
OVERLAP_REPORT = 5

# The scenes shipped inside the package (taichi_ice/scenarios/*.toml; the repository's
# scenarios/ folder links there), loadable by name from any directory.
_BUNDLED = "scenarios"

_TOP_KEYS = ("simulation", "ice", "water", "wind", "coriolis", "friction", "body", "field")


# --------------------------------------------------------------------------------------------
# Entry points
# --------------------------------------------------------------------------------------------


def load_scenario(path: str | Path) -> Scene:
    """Read and validate a scene file, or a scene shipped with the package.

    Args:
        path: a ``.toml`` scene file. When there is no such file and ``path`` is a bare name
            (``"pillar"`` or ``"pillar.toml"``, no folder), the bundled scene of that name
            (see :func:`bundled_scenes`): the examples load from any directory.

    Raises:
        ScenarioError: the file cannot be read, is not valid TOML, or is not a valid scene;
            the message names the file (and, for a missing one, lists the bundled scenes).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError as exc:
        bundled = _bundled_scene(path)
        if bundled is None:
            raise ScenarioError(
                f"{path}: cannot read the scene file ({exc.strerror or exc}), and no scene "
                f"shipped with taichi-ice has that name; those are {', '.join(bundled_scenes())} "
                "(load one by its name alone, e.g. 'pillar')"
            ) from None
        return parse_scenario(bundled.read_text(encoding="utf-8"), source=str(bundled))
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read the scene file ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"{path}: not a UTF-8 text file ({exc})") from None
    return parse_scenario(text, source=str(path))


def bundled_scenes() -> tuple[str, ...]:
    """Names of the scenes shipped with the package, sorted; ``load_scenario(name)`` loads one."""
    folder = resources.files("taichi_ice").joinpath(_BUNDLED)
    names = (f.name for f in folder.iterdir() if f.name.endswith(".toml"))
    return tuple(sorted(name[: -len(".toml")] for name in names))


def _bundled_scene(path: Path) -> Any:
    """The bundled scene file (an ``importlib.resources`` Traversable) named by ``path``, or None.

    Only a bare name qualifies: a path with a folder names a file of the user's, and a typo
    in it must be an error rather than a silent switch to the shipped scene.
    """
    if len(path.parts) != 1:
        return None
    name = path.name if path.suffix == ".toml" else f"{path.name}.toml"
    scene = resources.files("taichi_ice").joinpath(_BUNDLED).joinpath(name)
    return scene if scene.is_file() else None


def parse_scenario(text: str, source: str = "<string>") -> Scene:
    """Validate a scene given as TOML text; ``source`` names it in error messages.

    Raises:
        ScenarioError: a TOML syntax error (with its line and column) or an invalid scene.
    """
    try:
        data = loads(text)
    except TOMLDecodeError as exc:
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
        raise ScenarioError(f"{source}: a scene must be a table (dict), got {type_name(data)}")
    check_keys(source, "the top level", data, _TOP_KEYS, what="table")
    if "simulation" not in data:
        raise ScenarioError(
            f"{source}: missing table [simulation]; add it with at least duration = <seconds>"
        )
    simulation = parse_simulation(source, data["simulation"])
    ice = parse_ice(source, data.get("ice", {}))
    water = parse_water(source, data["water"]) if "water" in data else None
    wind = parse_wind(source, data["wind"]) if "wind" in data else None
    coriolis = parse_coriolis(source, data["coriolis"]) if "coriolis" in data else None
    if water is not None and water.geostrophic and coriolis is None:
        raise ScenarioError(
            f"{source}: [water], key 'geostrophic': the tilt that holds a geostrophic current "
            "is f k x u: add a [coriolis] table (latitude or f), or remove geostrophic"
        )
    friction = parse_friction(source, data.get("friction"))

    bodies: list[Body] = []
    labels: list[str] = []
    for i, table in enumerate(array_of_tables(source, data, "body")):
        body = parse_body(source, i, table)
        bodies.append(body)
        labels.append(f"[[body]] #{i} '{body.name}'")
    specs = [
        parse_field(source, i, table)
        for i, table in enumerate(array_of_tables(source, data, "field"))
    ]
    # Before any block is made: a field of 1e7 rows would otherwise fill the memory first.
    check_size(
        len(bodies) + sum(spec.size for spec in specs),
        f"{source}: [[field]] rows x columns",
        fix="lower rows or columns (or run on a machine with more memory)",
    )
    rng = np.random.default_rng(simulation.seed)
    notes: list[str] = []
    for i, spec in enumerate(specs):
        made = spec.layout(rng)
        if isinstance(made, tuple):  # a tessellation or a file: the floes and notes on them
            made, said = made
            notes.extend(said)
        for body in made:
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
        notes=tuple(notes),
        wind=wind,
        coriolis=coriolis,
    )
    _check_mass(scene, labels)
    _check_extent(scene, labels)
    _check_time_step(scene, labels)
    _check_overlaps(scene, labels)
    return scene


def reseeded(scene: Scene, seed: int) -> Scene:
    """``scene`` with the field jitter drawn from ``seed``, and the tessellation of each
    Voronoi field that has no ``seed`` of its own; nothing else changes.

    ``text`` is regenerated (without the file's comments) so that it rebuilds this scene.
    The scene is parsed and checked whole again (the new jitter may make blocks overlap),
    which is why this is the parser's and not a method of the model.

        ensemble = [reseeded(scene, seed) for seed in range(100)]

    Raises:
        ScenarioError: the new jitter makes blocks overlap, or ``seed`` is not an integer >= 0.
    """
    if seed == scene.simulation.seed:
        return scene
    raw = copy.deepcopy(dict(scene.raw))
    raw.setdefault("simulation", {})["seed"] = seed
    return scene_from_dict(raw, source=scene.source)


# --------------------------------------------------------------------------------------------
# Whole-scene checks
# --------------------------------------------------------------------------------------------


def _check_names(source: str, bodies: list[Body], labels: list[str]) -> None:
    first: dict[str, int] = {}
    for i, b in enumerate(bodies):
        bad = next((c for c in b.name if not c.isprintable()), None)
        if bad is not None:
            # A NUL cannot be stored in the run file's names (HDF5 strings end at it), and
            # the other control characters garble every table and message that shows it.
            raise ScenarioError(
                f"{source}: {labels[i].encode('unicode_escape').decode()}, key 'name': "
                f"{b.name!r} holds the control character "
                f"{bad!r}; use printable characters"
            )
        if b.name in first:
            raise ScenarioError(
                f"{source}: {labels[i]}, key 'name': the name '{b.name}' is already used by "
                f"{labels[first[b.name]]}; body names must be unique: rename one"
            )
        first[b.name] = i


def _check_mass(scene: Scene, labels: list[str]) -> None:
    """Every body's mass and moment of inertia are positive finite numbers (a width of 1e-150
    m makes the inertia underflow to 0, and the stable time step with it)."""
    with np.errstate(all="ignore"):
        m, j = scene.masses, scene.inertias
        good = (m > 0.0) & np.isfinite(m) & (j > 0.0) & np.isfinite(j)
    if np.all(good):
        return
    i = int(np.argmin(good))
    size = float(np.max(np.ptp(scene.bodies[i].vertices, axis=0)))
    raise ScenarioError(
        f"{scene.source}: {labels[i]}: its mass ({m[i]:.3g} kg) or moment of inertia "
        f"({j[i]:.3g} kg m^2) is not a positive finite number (outline {size:.3g} m across): "
        "give it the width and length (or vertices) of a real floe"
    )


def _check_extent(scene: Scene, labels: list[str]) -> None:
    """Every body within ``MAX_COORDINATE`` of the origin (positions are float64: a block
    1e12 m out is resolved to 0.1 mm, coarser than its contact overlaps)."""
    far = np.max(np.abs(scene.positions), axis=1) if scene.n_bodies else np.zeros(0)
    bad = np.flatnonzero(~(far <= MAX_COORDINATE))
    if bad.size:
        i = int(bad[0])
        raise ScenarioError(
            f"{scene.source}: {labels[i]}, key 'position': {scene.positions[i].tolist()} m is "
            f"more than {MAX_COORDINATE:.0e} m from the origin; place the scene near the "
            "origin (contacts resolve to 1e-16 of the coordinates)"
        )


def _check_time_step(scene: Scene, labels: list[str]) -> None:
    sim = scene.simulation
    limit = scene.stable_dt
    dt = sim.dt if sim.dt is not None else scene.dt
    if not dt > 0.0 or sim.duration / dt > MAX_STEPS:
        raise ScenarioError(
            f"{scene.source}: [simulation]: duration = {sim.duration:g} s at dt = {dt:.3g} s "
            f"(stable limit {limit:.3g} s) is {sim.duration / max(dt, 1e-300):.3g} steps, more "
            f"than {MAX_STEPS:.0e}: {_what_sets_the_limit(scene, labels)}"
        )
    if sim.dt is None:
        return
    if sim.dt > limit and not sim.force_dt:
        raise ScenarioError(
            f"{scene.source}: [simulation], key 'dt': {sim.dt:g} s is above the stable limit "
            f"{limit:.4g} s of the contact integration (stiffest contact of the lightest "
            f'dynamic body); use dt = "auto" (takes {scene.dt_safety:g} x the limit, '
            f"{scene.dt_safety * limit:.3g} s), a dt below the limit, or force_dt = true for a "
            "stability study"
        )


def _what_sets_the_limit(scene: Scene, labels: list[str]) -> str:
    """The fix for a stable dt too small to run: the block and the [ice] keys that set it."""
    ice = scene.ice
    limits: dict[bytes, float] = {}  # by outline: a field repeats one thousands of times

    def limit(i: int) -> float:
        v = scene.bodies[i].vertices
        if v.tobytes() not in limits:
            limits[v.tobytes()] = body_contact_limit(v, *scene.limit_args)
        return limits[v.tobytes()]

    dynamic = [i for i, b in enumerate(scene.bodies) if b.kind == BodyKind.DYNAMIC.label]
    if not dynamic:
        return "shorten the duration"
    worst = min(dynamic, key=limit)
    _, z = contact_damping(scene.bodies[worst].vertices, *scene.limit_args[:4])
    block = (
        f"{labels[worst]} weighs {scene.masses[worst]:.3g} kg ([ice] thickness = "
        f"{ice.thickness:.3g} m, density = {ice.density:.3g} kg/m^3)"
    )
    if z > 1.0:
        return (
            f"{block}, and [ice] contact_viscosity = {ice.contact_viscosity:.3g} damps its "
            f"stiffest contact at {z:.3g} x critical, where an explicit dashpot is stable only "
            "below 2 m_eff / c; lower contact_viscosity (Table 1: 3.16e4) or give the blocks "
            "a real thickness and size"
        )
    return (
        f"the lightest dynamic block, {block}, against [ice] contact_stiffness = "
        f"{ice.contact_stiffness:.3g}: give the blocks real floe sizes and thickness, lower "
        "contact_stiffness, or shorten the duration"
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
        "apart (or, in a field, raise spacing or lower jitter; floes read from a file: "
        "correct their outlines)"
    )
