"""Each table of a scene file to its part of the model: ``[simulation]``, ``[ice]``,
``[water]``, ``[friction]``, one ``[[body]]``, one ``[[field]]``.

Every value is read through a :class:`~taichi_ice.scene.table.Table`, so each error names the file,
the table (``[[body]] #3 'pillar'``) and the key, and says how to fix it. The keys each table
takes are here too (``BODY_KEYS`` ...; those of the settings tables are their dataclasses'
fields). What it does not do: load a file, lay fields out, or check the scene whole (bodies
that overlap, a time step too small to run); that is ``taichi_ice.scene.parse``, which calls
these. Importing it never starts Taichi (a ``[friction]`` table is read by
``taichi_ice.physics.friction``, imported when one is parsed).
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..codes import BodyKind
from ..errors import ScenarioError
from ..physics import polygon
from ..physics.forcing import coriolis_parameter
from ..physics.timestep import INTEGRATORS
from ..readonly import frozen
from .floes import FILE_KEYS, FileField, parse_file_field
from .grid import ForcingGrid, read_grid
from .model import (
    DEFAULT_OUTPUT_INTERVAL,
    DEFAULT_SERIES_INTERVAL,
    MAX_VERTICES,
    SHAPES,
    Body,
    CoriolisProperties,
    FieldSpec,
    IceProperties,
    SimulationSettings,
    WaterProperties,
    WindProperties,
)
from .table import REQUIRED, Table, type_name
from .voronoi import VORONOI_KEYS, VoronoiField, parse_voronoi

if TYPE_CHECKING:
    from ..physics.friction import Law

__all__ = [
    "BODY_KEYS",
    "CORIOLIS_KEYS",
    "FIELD_KEYS",
    "FIELD_KINDS",
    "ICE_KEYS",
    "SIMULATION_KEYS",
    "WATER_KEYS",
    "WIND_KEYS",
    "parse_body",
    "parse_coriolis",
    "parse_field",
    "parse_friction",
    "parse_ice",
    "parse_simulation",
    "parse_water",
    "parse_wind",
]

# The keys of each table. The settings tables' keys are their dataclasses' fields, in order
# (one owner: a new setting is a new field); a body or field is written with shape keys
# (width, length, vertices) that the model turns into an outline, so its keys are listed.
SIMULATION_KEYS = tuple(f.name for f in dataclasses.fields(SimulationSettings))
ICE_KEYS = tuple(f.name for f in dataclasses.fields(IceProperties))
WATER_KEYS = tuple(f.name for f in dataclasses.fields(WaterProperties))
WIND_KEYS = tuple(f.name for f in dataclasses.fields(WindProperties))
CORIOLIS_KEYS = tuple(f.name for f in dataclasses.fields(CoriolisProperties))
# The keys of a table that gives a current or wind on a grid (``grid``).
GRID_KEYS = ("file", "u", "v")
BODY_KEYS = (
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
FIELD_KEYS = (
    "name",
    "kind",
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
# What a [[field]] lays out: a lattice of one outline (the keys above), a tessellation of a
# region (voronoi.VORONOI_KEYS) or the floes of a GeoJSON file (floes.FILE_KEYS).
FIELD_KINDS = ("lattice", "voronoi", "file")


# --------------------------------------------------------------------------------------------
# Tables
# --------------------------------------------------------------------------------------------


def parse_simulation(source: str, data: Any) -> SimulationSettings:
    """The ``[simulation]`` table; ``dt = "auto"`` is ``dt = None``."""
    t = Table(source, "[simulation]", data, SIMULATION_KEYS)
    duration = t.number("duration", positive=True, unit=" s")
    dt: float | None = None
    raw_dt = t.get("dt", "auto")
    if isinstance(raw_dt, str):
        if raw_dt != "auto":
            raise t.error("dt", f'expected "auto" or a time step in seconds, got "{raw_dt}"')
    else:
        dt = t.as_number("dt", raw_dt, 'a time step in seconds or "auto"')
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
    dt_safety = t.number("dt_safety", None)  # None: the law's (Scene.dt_safety)
    if dt_safety is not None and not 0.0 < dt_safety <= 1.0:
        raise t.error("dt_safety", f"must be in (0, 1], got {dt_safety:g}")
    force_dt = t.boolean("force_dt", False)
    integrator = t.string("integrator", "auto", choices=("auto", *INTEGRATORS))
    integrator = None if integrator == "auto" else integrator  # None: the law's
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
        duration, dt, output_interval, series_interval, seed, dt_safety, force_dt, integrator
    )


def parse_ice(source: str, data: Any) -> IceProperties:
    """The ``[ice]`` table, its defaults filled."""
    t = Table(source, "[ice]", data, ICE_KEYS)
    d = IceProperties()
    return IceProperties(
        density=t.number("density", d.density, positive=True, unit=" kg/m^3"),
        thickness=t.number("thickness", d.thickness, positive=True, unit=" m"),
        contact_stiffness=t.number("contact_stiffness", d.contact_stiffness, positive=True),
        contact_viscosity=t.number("contact_viscosity", d.contact_viscosity, nonnegative=True),
        tangential_stiffness=t.number(
            "tangential_stiffness", d.tangential_stiffness, positive=True
        ),
        tangential_damping=t.number("tangential_damping", d.tangential_damping, positive=True),
        slide_resolution=t.number("slide_resolution", d.slide_resolution, nonnegative=True),
        crushing_strength=t.number("crushing_strength", None, positive=True, unit=" Pa"),
    )


def parse_water(source: str, data: Any) -> WaterProperties:
    """The ``[water]`` table, its defaults filled (a grid file of its current read)."""
    t = Table(source, "[water]", data, WATER_KEYS)
    d = WaterProperties()
    current = _velocity_field(t, "current", None)
    geostrophic = t.boolean("geostrophic", False)
    if geostrophic and current is None:
        raise t.error(
            "geostrophic",
            "a geostrophic current needs a current: add current = [u, v] (m/s) or a grid "
            "file, or remove geostrophic",
        )
    return WaterProperties(
        density=t.number("density", d.density, positive=True, unit=" kg/m^3"),
        form_drag=t.number("form_drag", d.form_drag, nonnegative=True),
        skin_drag=t.number("skin_drag", d.skin_drag, nonnegative=True),
        current=current,
        geostrophic=geostrophic,
    )


def parse_wind(source: str, data: Any) -> WindProperties:
    """The ``[wind]`` table, its defaults filled (a grid file of its velocity read)."""
    t = Table(source, "[wind]", data, WIND_KEYS)
    return WindProperties(
        velocity=_velocity_field(t, "velocity", REQUIRED),
        air_density=t.number(
            "air_density", WindProperties.air_density, positive=True, unit=" kg/m^3"
        ),
        drag=t.number("drag", WindProperties.drag, nonnegative=True),
    )


def parse_coriolis(source: str, data: Any) -> CoriolisProperties:
    """The ``[coriolis]`` table: ``latitude`` (degrees) or ``f`` (1/s), one of the two."""
    t = Table(source, "[coriolis]", data, CORIOLIS_KEYS)
    if ("latitude" in t) == ("f" in t):
        raise ScenarioError(
            f"{source}: [coriolis]: give latitude (degrees north, e.g. 75.0) or f (the "
            "Coriolis parameter in 1/s, e.g. 1.4e-4), one of the two"
        )
    if "f" in t:
        return CoriolisProperties(f=t.number("f"))
    latitude = t.number("latitude")
    if not -90.0 <= latitude <= 90.0:
        raise t.error(
            "latitude", f"must be in [-90, 90] degrees (north positive), got {latitude:g}"
        )
    return CoriolisProperties(latitude=latitude, f=coriolis_parameter(latitude))


def _velocity_field(t: Table, key: str, default: Any) -> tuple[float, float] | ForcingGrid | None:
    """A current or wind: ``[u, v]`` (m/s) everywhere, or a table ``{file, u, v}`` naming a
    netCDF grid (``grid.read_grid``; a relative path is read from the scene file's folder)."""
    v = t.get(key, default)
    if v is None:
        return None
    if isinstance(v, Mapping):
        sub = Table(t.source, f"{t.label} {key}", v, GRID_KEYS)
        name = sub.string("file")
        path = Path(name).expanduser()
        if not path.is_absolute():
            here = Path(t.source)
            path = (here.parent if here.is_file() else Path.cwd()) / path
        return read_grid(path, sub.string("u", "u"), sub.string("v", "v"), sub.error)
    if not isinstance(v, (list, tuple, np.ndarray)):
        raise t.error(
            key,
            f'expected [u, v] in m/s or a grid file {{file = "{key}.nc", u = "u", v = "v"}}, '
            f"got {type_name(v)}",
        )
    u, w = t.vector(key)
    return (float(u), float(w))


# --------------------------------------------------------------------------------------------
# Friction: the [friction] table to a law, and a law back to a table
# --------------------------------------------------------------------------------------------


def parse_friction(source: str, data: Any) -> Law:
    """The law of the ``[friction]`` table (``friction.law_from_table`` owns the rules); its
    errors are placed in the file and table here."""
    from ..physics.friction import LawError
    from ..physics.friction_parse import law_from_table

    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise ScenarioError(f"{source}: [friction] must be a table, got {type_name(data)}")
    try:
        return law_from_table(data)
    except LawError as exc:
        law = data.get("law", "coulomb")
        where = f'[friction] (law = "{law}")' if exc.key not in (None, "law") else "[friction]"
        key = f", key '{exc.key}'" if exc.key else ""
        raise ScenarioError(f"{source}: {where}{key}: {exc}") from None


# --------------------------------------------------------------------------------------------
# Bodies and fields
# --------------------------------------------------------------------------------------------


def _outline(t: Table, shape: str) -> np.ndarray:
    """Outline as written, relative to the body's position (m)."""
    if shape == "polygon":
        for key in ("width", "length"):
            if key in t:
                raise t.error(key, 'is for rectangle and diamond; a polygon takes only "vertices"')
        vertices = t.polygon("vertices")
        if len(vertices) > MAX_VERTICES:
            raise t.error(
                "vertices",
                f"{len(vertices)} vertices; a floe has at most {MAX_VERTICES} (the contact "
                "kernels' limit): simplify its outline",
            )
        return vertices
    if "vertices" in t:
        raise t.error("vertices", f'is for shape = "polygon"; a {shape} takes width and length')
    width = t.number("width", positive=True, unit=" m")
    length = t.number("length", positive=True, unit=" m")
    return (
        polygon.rectangle(width, length) if shape == "rectangle" else polygon.diamond(width, length)
    )


def _centred(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(outline relative to its centroid, centroid relative to the original origin)."""
    _, centroid, _ = polygon.mass_properties(vertices)
    return frozen(vertices - centroid), centroid


def _rotate(v: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def parse_body(source: str, index: int, data: Any) -> Body:
    """The ``[[body]]`` table number ``index``, placed at its centroid."""
    label = f"[[body]] #{index}"
    name = f"body{index}"
    if isinstance(data, Mapping) and "name" in data:
        name = Table(source, label, {"name": data["name"]}, ("name",)).string("name")
        if not name.strip():
            raise ScenarioError(f"{source}: {label}, key 'name': must not be empty")
    if isinstance(data, Mapping):
        label = f"{label} '{name}'"
    t = Table(source, label, data, BODY_KEYS)
    kind = t.string("kind", BodyKind.DYNAMIC.label, BodyKind.labels())
    shape = t.string("shape", REQUIRED, SHAPES)
    vertices, centroid = _centred(_outline(t, shape))
    position = t.vector("position")
    angle = t.angle("angle", 0.0)
    velocity = t.vector("velocity", frozen(np.zeros(2)))
    omega = t.number("omega", 0.0)
    if "force" in t and kind != BodyKind.DYNAMIC.label:
        raise t.error(
            "force", f'only a dynamic body takes an external force; this one is "{kind}": remove it'
        )
    force = t.vector("force", frozen(np.zeros(2)))
    if kind == BodyKind.FIXED.label:
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
        position=frozen(position + _rotate(centroid, angle)),
        angle=angle,
        velocity=velocity,
        omega=omega,
        force=force,
        probe=probe,
    )


def parse_field(source: str, index: int, data: Any) -> FieldSpec | VoronoiField | FileField:
    """The ``[[field]]`` table number ``index``, as written (its ``layout`` lays it out):
    a lattice (``kind = "lattice"``, the default), a tessellation (``"voronoi"``,
    ``taichi_ice.scene.voronoi``) or the floes of a GeoJSON file (``"file"``,
    ``taichi_ice.scene.floes``)."""
    label = f"[[field]] #{index}"
    name = f"field{index}"
    if isinstance(data, Mapping) and "name" in data:
        name = Table(source, label, {"name": data["name"]}, ("name",)).string("name")
        if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
            raise ScenarioError(
                f"{source}: {label}, key 'name': use letters, digits, '_', '-' or '.', "
                f'got "{name}"'
            )
    if isinstance(data, Mapping):
        label = f"{label} '{name}'"
        kind = Table(source, label, {"kind": data.get("kind", "lattice")}, ("kind",)).string(
            "kind", choices=FIELD_KINDS
        )
        if kind == "voronoi":
            return parse_voronoi(Table(source, label, data, VORONOI_KEYS), name)
        if kind == "file":
            return parse_file_field(Table(source, label, data, FILE_KEYS), name)
    t = Table(source, label, data, FIELD_KEYS)
    shape = t.string("shape", REQUIRED, SHAPES)
    vertices, centroid = _centred(_outline(t, shape))
    return FieldSpec(
        name=name,
        shape=shape,
        vertices=vertices,
        centroid_offset=frozen(centroid),
        rows=t.integer("rows", minimum=1),
        columns=t.integer("columns", minimum=1),
        origin=t.vector("origin"),
        spacing=t.vector("spacing", positive=True),
        stagger=t.number("stagger", 0.0),
        jitter=t.number("jitter", 0.0, nonnegative=True, unit=" m"),
        angle=t.angle("angle", 0.0),
        velocity=t.vector("velocity", frozen(np.zeros(2))),
        omega=t.number("omega", 0.0),
        velocity_jitter=t.number("velocity_jitter", 0.0, nonnegative=True, unit=" m/s"),
    )
