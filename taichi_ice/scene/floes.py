"""Floe outlines from the geometry ecosystem: GeoJSON files (``[[field]] kind = "file"``) and
shapely or GeoPandas objects from Python (:func:`from_shapely`).

Coordinates are metres in a local projected frame (x east, y north, or any Cartesian frame),
not the longitude and latitude of RFC 7946 GeoJSON: project first (GeoPandas ``to_crs``,
``ogr2ogr -t_srs``). A file whose ``crs`` member names a geographic CRS is refused, and so is
one with no ``crs`` member whose coordinates all lie within +-180 and +-90 with floes below
``DEGREES_SIZE`` across (degrees read as metres); a file with a projected ``crs`` member is
trusted.

Each Polygon (and each part of a MultiPolygon) becomes one floe. The engine takes convex
floes of at most ``MAX_VERTICES`` vertices:

- repeated and collinear vertices are dropped (``tessellation.clean``); rings may be either
  way round, closed or not;
- a concave floe, or one with holes, is refused (``concave = "refuse"``, the default) or
  replaced by its convex hull (``concave = "hull"``, adding area). A decomposition into
  convex pieces glued together would need bonds between bodies, which the engine does not
  have: split such a floe yourself into separate floes if it must stay concave;
- a floe with more vertices is refused (``simplify = false``) or simplified
  (``tessellation.simplify``: the vertices whose removal takes the least area go first).

The largest area change is reported (the scene's ``notes``; :func:`convex_outlines` returns
it). Pure NumPy and ``json``: shapely is read through ``__geo_interface__`` and never imported.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..codes import BodyKind
from ..errors import PolygonError, ScenarioError
from ..physics import polygon
from ..readonly import frozen
from .model import MAX_VERTICES, Body
from .table import Table, is_number, type_name
from .tessellation import clean, convex_hull, is_convex, simplify

__all__ = [
    "CONCAVE",
    "DEGREES_SIZE",
    "FILE_KEYS",
    "FileField",
    "Outline",
    "convex_outlines",
    "from_geojson",
    "from_shapely",
    "parse_file_field",
    "read_geojson",
]

FILE_KEYS = (
    "name",
    "kind",
    "path",
    "concave",
    "simplify",
    "offset",
    "velocity",
    "omega",
    "velocity_jitter",
)
CONCAVE = ("refuse", "hull")
# Floes whose median equivalent diameter is below this (in the file's units), with every
# coordinate within +-180, +-90, are taken for longitude and latitude in degrees: a floe of
# 0.01 degrees is about a kilometre, one of 0.01 m is no sea-ice floe.
DEGREES_SIZE = 0.01
# The names of geographic CRSs (degrees) in a GeoJSON ``crs`` member.
_GEOGRAPHIC = ("CRS84", "CRS83", "CRS27", "EPSG::4326", "EPSG:4326", "EPSG::4269", "EPSG:4269")


@dataclass(frozen=True)
class Outline:
    """One floe: its convex outline and what was done to make it so.

    Attributes:
        vertices: ``(n, 2)`` counter-clockwise, at most ``MAX_VERTICES``, m.
        feature: index of the feature (or geometry) it came from; part: index of the polygon
            within a MultiPolygon (0 for a Polygon).
        hull_change: area the convex hull added, relative to the outline's (0 if convex).
        simplify_change: area simplification took off, relative to the convex outline's.
    """

    vertices: np.ndarray
    feature: int
    part: int = 0
    hull_change: float = 0.0
    simplify_change: float = 0.0


def _where(source: str, feature: int, part: int, multi: bool) -> str:
    return f"{source}: feature {feature}" + (f" part {part}" if multi else "")


def _polygons(data: Any, source: str):
    """``(feature, part, multi, rings)`` for each polygon of a GeoJSON object."""
    if hasattr(data, "__geo_interface__"):
        data = data.__geo_interface__
    if not isinstance(data, Mapping) or "type" not in data:
        raise ScenarioError(f"{source}: not a GeoJSON object (a table with a 'type')")
    kind = data["type"]
    if kind == "FeatureCollection":
        features = data.get("features")
        if not isinstance(features, (list, tuple)):
            raise ScenarioError(f"{source}: a FeatureCollection needs a list of features")
        items = [f.get("geometry") if isinstance(f, Mapping) else f for f in features]
    elif kind == "Feature":
        items = [data.get("geometry")]
    elif kind == "GeometryCollection":
        items = list(data.get("geometries", []))
    else:
        items = [data]
    for i, geometry in enumerate(items):
        if not isinstance(geometry, Mapping):
            raise ScenarioError(f"{source}: feature {i}: has no geometry")
        g = geometry.get("type")
        coords = geometry.get("coordinates")
        if g == "Polygon":
            yield i, 0, False, coords
        elif g == "MultiPolygon":
            if not isinstance(coords, (list, tuple)):
                raise ScenarioError(f"{source}: feature {i}: a MultiPolygon needs coordinates")
            for k, rings in enumerate(coords):
                yield i, k, True, rings
        else:
            raise ScenarioError(
                f"{source}: feature {i}: a {g} is not a floe; give Polygons or MultiPolygons"
            )


def _ring(ring: Any, where: str) -> np.ndarray:
    """A GeoJSON linear ring as ``(n, 2)`` counter-clockwise, not closed, cleaned."""
    if not isinstance(ring, (list, tuple)) or not all(
        isinstance(c, (list, tuple)) and len(c) >= 2 and is_number(c[0]) and is_number(c[1])
        for c in ring
    ):
        raise ScenarioError(f"{where}: its ring is not a list of [x, y] number pairs")
    v = np.array([[float(c[0]), float(c[1])] for c in ring], dtype=np.float64)
    if len(v) and np.array_equal(v[0], v[-1]):
        v = v[:-1]
    if len(v) < 3 or not np.all(np.isfinite(v)):
        raise ScenarioError(f"{where}: needs at least 3 finite vertices, got {len(v)}")
    extent = float(np.max(np.ptp(v, axis=0)))
    with np.errstate(all="ignore"):
        area = polygon.signed_area(v)
    if not (extent > 0.0 and abs(area) > 1e-9 * extent * extent and math.isfinite(area)):
        raise ScenarioError(
            f"{where}: has zero or non-finite area; give a ring that encloses a floe, in metres"
        )
    return clean(v[::-1] if area < 0.0 else v)


def convex_outlines(
    data: Any,
    *,
    concave: str = "refuse",
    simplify_outlines: bool = False,
    source: str = "<geometry>",
    crs: str | None = None,
) -> list[Outline]:
    """Convex floe outlines of the polygons in ``data`` (module docstring).

    Args:
        data: a GeoJSON mapping (FeatureCollection, Feature, GeometryCollection, Polygon,
            MultiPolygon), an object with ``__geo_interface__`` (a shapely geometry, a
            GeoPandas GeoSeries or GeoDataFrame), or a list of either: coordinates in m.
        concave: ``"refuse"`` or ``"hull"`` (concave floes and floes with holes).
        simplify_outlines: simplify floes of more than ``MAX_VERTICES`` vertices (else refuse).
        source: names the input in messages (the file, or ``feature <i>`` of it).
        crs: the coordinates' CRS when known (a file's ``crs`` member); a geographic one is
            refused, and a given one skips the check for degrees.

    Raises:
        ScenarioError: naming ``source``, the feature and the fix.
    """
    if concave not in CONCAVE:
        raise ScenarioError(f'{source}: concave must be "refuse" or "hull", got {concave!r}')
    if crs is not None and any(name in crs.upper() for name in _GEOGRAPHIC):
        raise ScenarioError(
            f"{source}: its crs is {crs}, longitude and latitude in degrees; floes need metres "
            "in a projected frame: reproject first (GeoPandas to_crs, ogr2ogr -t_srs), e.g. to "
            "EPSG:3413 (Arctic) or EPSG:3031 (Antarctic)"
        )
    if isinstance(data, (list, tuple)):
        found = []
        for i, item in enumerate(data):
            found += [
                (i, part, multi, rings)
                for _, part, multi, rings in _polygons(item, f"{source}: geometry {i}")
            ]
    else:
        found = list(_polygons(data, source))
    rings = []
    for feature, part, multi, coords in found:
        where = _where(source, feature, part, multi)
        if not isinstance(coords, (list, tuple)) or not coords:
            raise ScenarioError(f"{where}: has no rings")
        rings.append((feature, part, where, _ring(coords[0], where), len(coords) - 1))
    if not rings:
        raise ScenarioError(f"{source}: holds no polygons")
    if crs is None:
        _check_not_degrees([r[3] for r in rings], source)
    return [_convex(*ring, concave, simplify_outlines) for ring in rings]


def _convex(feature, part, where, v, holes, concave, simplify_outlines) -> Outline:
    """The floe of the cleaned outer ring ``v``: hulled or simplified as asked."""
    hull_change = 0.0
    if holes or not is_convex(v):
        area = polygon.signed_area(v)
        hull = clean(convex_hull(v))
        if concave == "refuse":
            what = f"has {holes} hole{'s' * (holes > 1)}" if holes else "is concave"
            raise ScenarioError(
                f'{where}: {what}; floes must be convex: set concave = "hull" to take its '
                f"convex hull (+{100 * (polygon.signed_area(hull) / area - 1):.3g} % area), or "
                "split it into convex floes (the engine has no bonds to glue pieces into one "
                "floe)"
            )
        v = hull
        hull_change = polygon.signed_area(v) / area - 1.0
    simplify_change = 0.0
    if len(v) > MAX_VERTICES:
        if not simplify_outlines:
            raise ScenarioError(
                f"{where}: {len(v)} vertices; a floe has at most {MAX_VERTICES} (the contact "
                "kernels' limit): set simplify = true to drop the vertices whose removal takes "
                "the least area (the change is reported), or simplify it yourself"
            )
        area = polygon.signed_area(v)
        v = simplify(v, MAX_VERTICES)
        simplify_change = 1.0 - polygon.signed_area(v) / area
    try:
        v = polygon.check_polygon(v, what=where)
    except PolygonError as exc:
        raise ScenarioError(str(exc)) from None
    return Outline(frozen(v), feature, part, hull_change, simplify_change)


def _check_not_degrees(rings: list[np.ndarray], source: str) -> None:
    every = np.concatenate(rings)
    if np.any(np.abs(every[:, 0]) > 180.0) or np.any(np.abs(every[:, 1]) > 90.0):
        return
    sizes = [2.0 * math.sqrt(polygon.signed_area(v) / math.pi) for v in rings]
    median = float(np.median(sizes))
    if median < DEGREES_SIZE:
        raise ScenarioError(
            f"{source}: every coordinate is within +-180, +-90 and the floes are "
            f"{median:.3g} across (median): these look like longitude and latitude in "
            "degrees; floes need metres in a projected frame: reproject first (GeoPandas "
            "to_crs, ogr2ogr -t_srs), or, if they really are metres, name the projected CRS "
            "in the file's crs member"
        )


def summary(outlines: list[Outline], where: str) -> tuple[str, ...]:
    """Notes on the hulls and simplifications made, for the scene's ``notes``."""
    notes = []
    hulled = [o for o in outlines if o.hull_change > 0.0]
    if hulled:
        worst = max(hulled, key=lambda o: o.hull_change)
        notes.append(
            f"{where}: {len(hulled)} concave floe{'s' * (len(hulled) > 1)} replaced by the "
            f"convex hull (largest area change +{100 * worst.hull_change:.3g} %, feature "
            f"{worst.feature})"
        )
    cut = [o for o in outlines if o.simplify_change > 0.0]
    if cut:
        worst = max(cut, key=lambda o: o.simplify_change)
        notes.append(
            f"{where}: {len(cut)} floe{'s' * (len(cut) > 1)} of more than {MAX_VERTICES} "
            f"vertices simplified (largest area change -{100 * worst.simplify_change:.3g} %, "
            f"feature {worst.feature})"
        )
    return tuple(notes)


# --------------------------------------------------------------------------------------------
# Files and Python objects
# --------------------------------------------------------------------------------------------


def read_geojson(path: str | Path, where: str = "") -> Mapping:
    """The parsed GeoJSON file at ``path``; errors name ``where`` (the scene's table)."""
    prefix = f"{where}: " if where else ""
    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
    except OSError as exc:
        raise ScenarioError(
            f"{prefix}cannot read {path} ({exc.strerror or exc}); paths are relative to the "
            "scene file"
        ) from None
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise ScenarioError(f"{prefix}{path} is not a GeoJSON (JSON) file: {exc}") from None
    if not isinstance(data, Mapping):
        raise ScenarioError(f"{prefix}{path}: not a GeoJSON object, got {type_name(data)}")
    return data


def _crs_name(data: Mapping) -> str | None:
    crs = data.get("crs")
    if isinstance(crs, Mapping):
        properties = crs.get("properties")
        if isinstance(properties, Mapping) and isinstance(properties.get("name"), str):
            return properties["name"]
    return None


def _bodies(
    outlines: Sequence[Outline], name: str, velocity=(0.0, 0.0), omega: float = 0.0
) -> list[dict]:
    multi = {o.feature for o in outlines if o.part > 0}
    bodies = []
    for o in outlines:
        _, centroid, _ = polygon.mass_properties(o.vertices)
        bodies.append(
            {
                "name": f"{name}_f{o.feature}" + (f"_p{o.part}" if o.feature in multi else ""),
                "shape": "polygon",
                "vertices": (o.vertices - centroid).tolist(),
                "position": centroid.tolist(),
                "velocity": [float(velocity[0]), float(velocity[1])],
                "omega": float(omega),
            }
        )
    return bodies


def from_shapely(
    geometries: Any,
    *,
    concave: str = "refuse",
    simplify: bool = False,
    name: str = "floe",
    velocity=(0.0, 0.0),
    omega: float = 0.0,
    crs: str | None = None,
) -> list[dict]:
    """``[[body]]`` tables of floes from shapely polygons, for ``scene_from_dict``.

        from shapely.geometry import Polygon
        from taichi_ice.scene.floes import from_shapely
        bodies = from_shapely([Polygon([(0, 0), (20, 0), (18, 15)]), ...], concave="hull")
        scene = scene_from_dict({"simulation": {"duration": 10.0}, "body": bodies})

    Args:
        geometries: a shapely Polygon or MultiPolygon, a GeoPandas GeoSeries or
            GeoDataFrame, a GeoJSON mapping, or a list of these; coordinates in metres in a
            projected frame (reproject a GeoDataFrame with ``to_crs`` first).
        concave, simplify: as the keys of ``[[field]] kind = "file"`` (module docstring); the
            area changes are in :func:`convex_outlines`'s answer.
        name: the floes are named ``<name>_f<i>`` (``_p<k>`` for the parts of a MultiPolygon).
        velocity: ``[vx, vy]`` of every floe, m/s. omega: rad/s.
        crs: the CRS of the coordinates, when known (``GeoDataFrame.crs.to_string()``): a
            geographic one is refused; given, it skips the check for degrees.

    Returns:
        One dict per floe: ``name``, ``shape = "polygon"``, ``vertices`` about its centroid,
        ``position`` (the centroid), ``velocity``, ``omega``; the scene is self-contained.

    Raises:
        ScenarioError: a concave floe (``concave = "refuse"``), too many vertices
            (``simplify = False``), degrees for metres, not polygons.
    """
    outlines = convex_outlines(
        geometries, concave=concave, simplify_outlines=simplify, source="<shapely>", crs=crs
    )
    return _bodies(outlines, name, velocity, omega)


def from_geojson(path: str | Path, **options) -> list[dict]:
    """``[[body]]`` tables of the floes of a GeoJSON file (the options of
    :func:`from_shapely`; the file's ``crs`` member is read): a scene that keeps its
    outlines in its own text instead of naming the file."""
    data = read_geojson(path)
    options.setdefault("crs", _crs_name(data))
    outlines = convex_outlines(
        data,
        concave=options.pop("concave", "refuse"),
        simplify_outlines=options.pop("simplify", False),
        source=str(path),
        crs=options.pop("crs"),
    )
    return _bodies(outlines, options.pop("name", "floe"), **options)


# --------------------------------------------------------------------------------------------
# The [[field]] table
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class FileField:
    """A ``[[field]] kind = "file"``: the floes of a GeoJSON file, read when the scene is.

    Attributes:
        name: prefix of the floe names (``<name>_f<feature>``, ``_p<part>`` for the parts of
            a MultiPolygon).
        path: the file as written; resolved: where it was read (relative paths are relative
            to the scene file's folder).
        concave: ``"refuse"`` or ``"hull"``. simplify: simplify floes of more than
            ``MAX_VERTICES`` vertices.
        offset: ``(2,)`` added to every coordinate, m.
        outlines: the floes as read (``Outline``), before ``offset``.
        velocity: ``(2,)`` m/s. omega: rad/s. velocity_jitter: m/s, as for a lattice.
        where: the file and table, for messages.
    """

    name: str
    path: str
    resolved: str
    concave: str
    simplify: bool
    offset: np.ndarray
    outlines: tuple[Outline, ...]
    velocity: np.ndarray = dataclasses.field(default_factory=lambda: frozen(np.zeros(2)))
    omega: float = 0.0
    velocity_jitter: float = 0.0
    where: str = ""

    kind = "file"

    @property
    def size(self) -> int:
        """Number of floes."""
        return len(self.outlines)

    def layout(self, rng: np.random.Generator) -> tuple[list[Body], tuple[str, ...]]:
        """The floes and the notes on what was hulled or simplified. Draws one integer from
        ``rng`` (as a Voronoi field does), which seeds the ``2 x floes`` velocity numbers."""
        own = np.random.default_rng(int(rng.integers(2**63)))
        jitter = self.velocity_jitter * own.uniform(-1.0, 1.0, (self.size, 2))
        tables = _bodies(self.outlines, self.name, self.velocity, self.omega)
        bodies = []
        for k, table in enumerate(tables):
            bodies.append(
                Body(
                    name=table["name"],
                    kind=BodyKind.DYNAMIC.label,
                    shape="polygon",
                    vertices=frozen(np.array(table["vertices"])),
                    position=frozen(np.array(table["position"]) + self.offset),
                    velocity=frozen(self.velocity + jitter[k]),
                    omega=self.omega,
                )
            )
        return bodies, summary(list(self.outlines), self.where)


def parse_file_field(t: Table, name: str) -> FileField:
    """The ``[[field]] kind = "file"`` table ``t``: its GeoJSON file read and checked."""
    path = t.string("path")
    if not path.strip():
        raise t.error("path", 'must not be empty; give the GeoJSON file, e.g. "floes.geojson"')
    folder = Path(t.source).parent if Path(t.source).is_file() else Path.cwd()
    resolved = Path(path) if Path(path).is_absolute() else folder / path
    concave = t.string("concave", "refuse", CONCAVE)
    simplify_outlines = t.boolean("simplify", False)
    where = f"{t.source}: {t.label}"
    data = read_geojson(resolved, f"{where}, key 'path'")
    outlines = convex_outlines(
        data,
        concave=concave,
        simplify_outlines=simplify_outlines,
        source=f"{where}: {resolved}",
        crs=_crs_name(data),
    )
    return FileField(
        name=name,
        path=path,
        resolved=str(resolved),
        concave=concave,
        simplify=simplify_outlines,
        offset=t.vector("offset", frozen(np.zeros(2))),
        outlines=tuple(outlines),
        velocity=t.vector("velocity", frozen(np.zeros(2))),
        omega=t.number("omega", 0.0),
        velocity_jitter=t.number("velocity_jitter", 0.0, nonnegative=True, unit=" m/s"),
        where=where,
    )
