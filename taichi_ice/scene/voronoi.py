"""``[[field]] kind = "voronoi"``: a region tessellated into convex floes.

Seeds are placed by random sequential addition of disks (each uniform over the room the
disks before it left), the cells are the Voronoi diagram of the seeds, or, for a floe-size
distribution, the power diagram whose weights give each cell the area of a floe drawn from
it (``tessellation.balance_weights``), and each cell is shrunk about its centroid by
``sqrt(concentration)``: the cells tile the region, so the floes cover exactly
``concentration`` of it, and a shrunk convex cell lies inside its cell, so no two floes touch.

- ``floes = N``: N disks of one radius at packing fraction ``PACKING``: the seeds keep a
  spacing of at least ``0.67 sqrt(area / N)`` (a hard-core process), so no cell is a sliver.
- ``fsd = {exponent, min_size, max_size}``: floe sizes (the diameter of the circle of the
  floe's area, m) drawn from ``p(d) ~ d^-exponent`` on ``[min_size, max_size]`` until their
  area reaches ``concentration x area``; all are then scaled by one factor so that it is
  exact, and placed largest first, each disk's area ``PACKING`` of its floe's cell.

A cell with more vertices than the engine takes (``MAX_VERTICES``) is simplified
(``tessellation.simplify``) and shrunk less, so that its floe keeps its area where the gap
allows; what changed is the scene's ``notes``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..codes import BodyKind
from ..errors import PolygonError, ScenarioError
from ..physics import polygon
from ..readonly import frozen
from .model import MAX_COORDINATE, MAX_VERTICES, Body
from .table import REQUIRED, Table, is_number
from .tessellation import BalanceError, balance_weights, clean, place_disks, power_cells, simplify

__all__ = [
    "FSD_KEYS",
    "MAX_FLOES",
    "MIN_FLOE_SIZE",
    "PACKING",
    "VORONOI_KEYS",
    "Tessellation",
    "VoronoiField",
    "draw_sizes",
    "parse_voronoi",
    "tessellate",
]

VORONOI_KEYS = (
    "name",
    "kind",
    "region",
    "concentration",
    "floes",
    "fsd",
    "seed",
    "velocity",
    "omega",
    "velocity_jitter",
)
FSD_KEYS = ("exponent", "min_size", "max_size")
# Most floes one field may have: the tessellation is Python over the cells, about 0.3 ms a
# cell per power diagram and eight diagrams to balance the weights (measured on the 2-core VM
# under load: 5,114 floes of a size distribution in 14 s, 5,000 Voronoi floes in 2 s; so
# 20,000 floes of a distribution take about a minute).
MAX_FLOES = 20_000
# The smallest floe a field makes, m: below it the weights and areas approach round-off.
MIN_FLOE_SIZE = 1e-3
# The disks that seed the cells cover this fraction of the region: far below where random
# sequential addition jams (0.547 for equal disks), so each finds room at once.
PACKING = 0.35
# Largest exponent of the size distribution (observed floe-size exponents are 1.5 to 4).
MAX_EXPONENT = 10.0
# Newton stops when every cell's area is within this fraction of its target.
AREA_RTOL = 1e-9


@dataclass(frozen=True)
class Tessellation:
    """The floes of a tessellation and what was changed to make them.

    Attributes:
        outlines: counter-clockwise floe outlines in the world, m, largest target first.
        simplified: how many cells had more than ``MAX_VERTICES`` vertices.
        cell_change: largest area a simplified cell lost, relative to its cell.
        floe_error: largest relative area error left in a floe once shrunk less (nonzero
            only where the gap was too small to make it up: concentration near 1).
        scale: the factor the drawn sizes were scaled by to meet the concentration (1 for
            ``floes = N``).
    """

    outlines: tuple[np.ndarray, ...]
    simplified: int = 0
    cell_change: float = 0.0
    floe_error: float = 0.0
    scale: float = 1.0


def _power_law(rng: np.random.Generator, n: int, exponent: float, lo: float, hi: float):
    """``n`` draws from ``p(d) ~ d^-exponent`` on ``[lo, hi]`` (inverse transform), m."""
    u = rng.random(n)
    ratio = hi / lo
    if abs(exponent - 1.0) < 1e-12:
        return lo * ratio**u
    k = 1.0 - exponent
    return lo * (1.0 + u * (ratio**k - 1.0)) ** (1.0 / k)


def _moment(k: float, exponent: float, lo: float, hi: float) -> float:
    """``E[d^k]`` of the truncated power law, m^k."""

    def integral(power):  # of x^power over [1, hi / lo]
        ratio = hi / lo
        return (
            math.log(ratio)
            if abs(power + 1.0) < 1e-12
            else (ratio ** (power + 1) - 1) / (power + 1)
        )

    return lo**k * integral(k - exponent) / integral(-exponent)


def expected_count(exponent: float, lo: float, hi: float, ice_area: float) -> float:
    """How many floes of the truncated power law cover ``ice_area`` (m^2), on average."""
    return ice_area / (0.25 * math.pi * _moment(2.0, exponent, lo, hi))


def draw_sizes(
    rng: np.random.Generator, exponent: float, lo: float, hi: float, ice_area: float
) -> tuple[np.ndarray, float]:
    """Sizes (m), largest first, drawn until their area is closest to ``ice_area`` and
    scaled to cover it exactly; and the scale factor."""
    batch = max(16, int(1.2 * expected_count(exponent, lo, hi, ice_area)) + 16)
    drawn = np.zeros(0)
    while True:
        drawn = np.concatenate([drawn, _power_law(rng, batch, exponent, lo, hi)])
        area = np.cumsum(0.25 * math.pi * drawn**2)
        if area[-1] >= ice_area:
            break
    n = int(np.searchsorted(area, ice_area)) + 1  # the first n reach ice_area
    if n > 1 and ice_area - area[n - 2] < area[n - 1] - ice_area:
        n -= 1
    scale = math.sqrt(ice_area / area[n - 1])
    return np.sort(drawn[:n])[::-1] * scale, scale


def tessellate(
    region: np.ndarray,
    rng: np.random.Generator,
    concentration: float,
    floes: int | None = None,
    fsd: tuple[float, float, float] | None = None,
    max_vertices: int = MAX_VERTICES,
) -> Tessellation:
    """Convex floes covering ``concentration`` of the convex ``region`` (module docstring).

    Args:
        region: counter-clockwise convex polygon, m.
        rng: the only source of randomness.
        concentration: ice area over region area, in (0, 1].
        floes: the number of floes (a Voronoi diagram), or
        fsd: ``(exponent, min_size, max_size)`` of the floe-size distribution (a power
            diagram).
        max_vertices: the most vertices of a floe.

    Raises:
        BalanceError: the weights could not give the cells their areas.
        RuntimeError: the seed disks found no room (not seen at ``PACKING``).
    """
    region = np.asarray(region, dtype=np.float64)
    area = polygon.signed_area(region)
    if fsd is not None:
        sizes, scale = draw_sizes(rng, *fsd, concentration * area)
        targets = area * sizes**2 / np.sum(sizes**2)
    else:
        scale = 1.0
        targets = np.full(int(floes or 1), area / int(floes or 1))
    radii = np.sqrt(PACKING * targets / math.pi)
    for _ in range(20):
        centres = place_disks(radii, region, rng)
        if centres is not None:
            break
        radii = 0.9 * radii
    else:
        raise RuntimeError("the seed disks found no room in the region")
    if len(targets) == 1:
        cells = [region]
    elif fsd is not None:
        _, cells, _, _ = balance_weights(centres, radii**2, targets, region, rtol=AREA_RTOL)
    else:
        cells, _ = power_cells(centres, np.zeros(len(centres)), region)
    outlines = []
    simplified, cell_change, floe_error = 0, 0.0, 0.0
    for cell in cells:
        before = polygon.signed_area(cell)
        v = clean(cell)
        if len(v) > max_vertices:
            simplified += 1
            v = simplify(v, max_vertices)
        after = polygon.signed_area(v)
        cell_change = max(cell_change, 1.0 - after / before)
        # Shrunk about its centroid by at most 1, the floe stays inside its cell.
        factor = min(1.0, math.sqrt(concentration * before / after))
        _, centroid, _ = polygon.mass_properties(v)
        outlines.append(centroid + factor * (v - centroid))
        floe_error = max(floe_error, 1.0 - factor * factor * after / (concentration * before))
    return Tessellation(tuple(outlines), simplified, cell_change, floe_error, scale)


# --------------------------------------------------------------------------------------------
# The [[field]] table
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class VoronoiField:
    """A ``[[field]] kind = "voronoi"`` as written (``layout`` tessellates it).

    Attributes:
        name: prefix of the floe names (``<name>_<k>``).
        region: ``(n, 2)`` counter-clockwise convex polygon tessellated, m.
        concentration: floe area over region area, in (0, 1].
        floes: number of floes (Voronoi), or ``None`` for a size distribution.
        exponent, min_size, max_size: ``p(d) ~ d^-exponent`` on ``[min_size, max_size]``
            (m, equivalent diameter), or ``None``.
        seed: this field's own seed, or ``None`` to draw one from ``simulation.seed``.
        velocity: ``(2,)`` m/s. omega: rad/s. velocity_jitter: each floe's velocity changes by
            U(-v, v) in x and y, m/s.
        where: the file and table, for messages.
    """

    name: str
    region: np.ndarray
    concentration: float
    floes: int | None = None
    exponent: float | None = None
    min_size: float | None = None
    max_size: float | None = None
    seed: int | None = None
    velocity: np.ndarray = dataclasses.field(default_factory=lambda: frozen(np.zeros(2)))
    omega: float = 0.0
    velocity_jitter: float = 0.0
    where: str = ""

    kind = "voronoi"

    @property
    def area(self) -> float:
        """Area of the region, m^2."""
        return polygon.signed_area(self.region)

    @property
    def size(self) -> int:
        """Number of floes (for a size distribution, the expected number), for memory checks."""
        if self.floes is not None:
            return self.floes
        count = expected_count(
            self.exponent, self.min_size, self.max_size, self.concentration * self.area
        )
        return int(min(math.ceil(count), 2**62))

    def layout(self, rng: np.random.Generator) -> tuple[list[Body], tuple[str, ...]]:
        """The floes and the notes on what was simplified.

        Draws one integer from ``rng`` whether ``seed`` is given or not (the fields after
        this one depend only on the scene's seed and the fields before them); the
        tessellation, then ``2 x floes`` velocity numbers, come from ``seed`` or that draw.
        """
        drawn = int(rng.integers(2**63))
        own = np.random.default_rng(self.seed if self.seed is not None else drawn)
        fsd = None
        if self.floes is None:
            fsd = (self.exponent, self.min_size, self.max_size)
        try:
            made = tessellate(self.region, own, self.concentration, self.floes, fsd)
        except (BalanceError, RuntimeError) as exc:
            raise ScenarioError(
                f"{self.where}: could not tessellate the region ({exc}); narrow the size "
                "range (max_size / min_size), or enlarge the region"
            ) from None
        jitter = self.velocity_jitter * own.uniform(-1.0, 1.0, (len(made.outlines), 2))
        bodies = []
        for k, outline in enumerate(made.outlines):
            try:
                v = polygon.check_polygon(outline, what=f"{self.where}: floe {k}")
            except PolygonError as exc:  # not seen: cleaned outlines pass
                raise ScenarioError(str(exc)) from None
            _, centroid, _ = polygon.mass_properties(v)
            bodies.append(
                Body(
                    name=f"{self.name}_{k}",
                    kind=BodyKind.DYNAMIC.label,
                    shape="polygon",
                    vertices=frozen(v - centroid),
                    position=frozen(centroid),
                    velocity=frozen(self.velocity + jitter[k]),
                    omega=self.omega,
                )
            )
        notes = []
        if made.simplified:
            kept = (
                f"largest floe area error {100 * made.floe_error:.3g} % where the gap was too "
                "small to make it up"
                if made.floe_error > 1e-9
                else "their floes were shrunk less and kept their areas"
            )
            notes.append(
                f"{self.where}: {made.simplified} of {len(bodies)} cells had more than "
                f"{MAX_VERTICES} vertices and were simplified (largest cell area change "
                f"-{100 * made.cell_change:.3g} %; {kept})"
            )
        if abs(made.scale - 1.0) > 0.01:
            notes.append(
                f"{self.where}: {len(bodies)} floes; their drawn sizes were scaled by "
                f"{made.scale:.4g} to cover concentration = {self.concentration:g} of the region"
            )
        return bodies, tuple(notes)


def _region(t: Table) -> np.ndarray:
    """``region``: ``[x0, y0, x1, y1]`` (a rectangle) or a convex polygon ``[[x, y], ...]``."""
    v = t.get("region", REQUIRED)
    if isinstance(v, (list, tuple, np.ndarray)) and len(v) == 4 and all(map(is_number, v)):
        x0, y0, x1, y1 = (t.as_number("region", c) for c in v)
        if not (x1 > x0 and y1 > y0):
            raise t.error(
                "region", f"[x0, y0, x1, y1] needs x1 > x0 and y1 > y0, got {[x0, y0, x1, y1]}"
            )
        region = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    else:
        try:
            region = t.polygon("region")
        except ScenarioError as exc:
            message = str(exc)
            if "expected an array" in message:
                raise t.error(
                    "region",
                    "expected [x0, y0, x1, y1] (a rectangle, m) or a convex polygon [[x, y], ...]",
                ) from None
            raise ScenarioError(
                message.replace(
                    "floes must be convex polygons (split a concave floe into convex pieces)",
                    "the region must be convex (tessellate each convex part as a field)",
                )
            ) from None
    far = float(np.max(np.abs(region)))
    if not far <= MAX_COORDINATE:
        raise t.error(
            "region",
            f"reaches {far:.3g} m from the origin, more than {MAX_COORDINATE:.0e} m; place the "
            "scene near the origin",
        )
    return region


def parse_voronoi(t: Table, name: str) -> VoronoiField:
    """The ``[[field]] kind = "voronoi"`` table ``t``, checked."""
    region = _region(t)
    area = polygon.signed_area(region)
    concentration = t.number("concentration")
    if not 0.0 < concentration <= 1.0:
        raise t.error(
            "concentration", f"must be in (0, 1] (ice area / region area), got {concentration:g}"
        )
    if ("floes" in t) == ("fsd" in t):
        raise t.error(
            "floes",
            "give either floes = <number of floes> (a Voronoi tessellation) or fsd = "
            "{ exponent, min_size, max_size } (a floe-size distribution), not both"
            if "floes" in t
            else "missing; give floes = <number of floes> or fsd = { exponent = ..., "
            "min_size = ..., max_size = ... }",
        )
    floes = exponent = lo = hi = None
    if "floes" in t:
        floes = t.integer("floes", minimum=1)
        if floes > MAX_FLOES:
            raise t.error(
                "floes", f"{floes:,} floes; a field tessellates at most {MAX_FLOES:,}: lower it"
            )
        size = math.sqrt(area / floes)
        if size < MIN_FLOE_SIZE:
            raise t.error(
                "floes",
                f"{floes} floes in {area:.3g} m^2 are {size:.3g} m across, below "
                f"{MIN_FLOE_SIZE:g} m: lower floes or enlarge the region",
            )
    else:
        d = Table(t.source, f"{t.label}, table 'fsd'", t.get("fsd", REQUIRED), FSD_KEYS)
        exponent = d.number("exponent")
        if not 0.0 <= exponent <= MAX_EXPONENT:
            raise d.error(
                "exponent",
                f"must be in [0, {MAX_EXPONENT:g}] (p(d) ~ d^-exponent), got {exponent:g}",
            )
        lo = d.number("min_size", positive=True, unit=" m")
        hi = d.number("max_size", positive=True, unit=" m")
        if lo < MIN_FLOE_SIZE:
            raise d.error("min_size", f"must be at least {MIN_FLOE_SIZE:g} m, got {lo:g} m")
        if not hi > lo:
            raise d.error("max_size", f"must be above min_size = {lo:g} m, got {hi:g} m")
        ice = concentration * area
        if 0.25 * math.pi * hi * hi > ice:
            raise d.error(
                "max_size",
                f"a floe of {hi:g} m covers {0.25 * math.pi * hi * hi:.3g} m^2, more than the "
                f"{ice:.3g} m^2 of ice the region holds at this concentration: lower max_size "
                "or enlarge the region",
            )
        count = expected_count(exponent, lo, hi, ice)
        if count > MAX_FLOES:
            raise d.error(
                "min_size",
                f"the distribution makes about {count:,.0f} floes in this region; a field "
                f"tessellates at most {MAX_FLOES:,}: raise min_size or the exponent's "
                "bound, or shrink the region",
            )
    seed = t.integer("seed", None, minimum=0) if "seed" in t else None
    if seed is not None and seed >= 2**63:
        raise t.error("seed", f"must be below 2^63, got {seed}")
    return VoronoiField(
        name=name,
        region=frozen(region),
        concentration=concentration,
        floes=floes,
        exponent=exponent,
        min_size=lo,
        max_size=hi,
        seed=seed,
        velocity=t.vector("velocity", frozen(np.zeros(2))),
        omega=t.number("omega", 0.0),
        velocity_jitter=t.number("velocity_jitter", 0.0, nonnegative=True, unit=" m/s"),
        where=f"{t.source}: {t.label}",
    )
