"""Convex polygons: construction, validation, mass properties, overlap and separation.

Every polygon is a ``(n, 2)`` float array of vertices in counter-clockwise order. Floes are
stored relative to their centroid (``vert_local``) and placed by a position and an angle.

NumPy only (importing it starts no Taichi): these functions are the references that the
Taichi kernels are tested against. Their Taichi twins are ``polygon_ti``'s, in the same
order (``rotation_ti`` beside ``rotation``, ``edge_normals_ti`` beside ``edge_normals``, ...).
``taichi_ice.geometry`` re-exports both modules under its old public name.
"""

from typing import NamedTuple

import numpy as np

from ..codes import OverlapKind
from ..errors import PolygonError

# Relative tolerance for convexity and degeneracy checks: a vertex whose turn is below this
# fraction of the polygon's size squared counts as collinear (it adds nothing but a
# zero-length normal to the separating-axis test, so it is refused).
CONVEXITY_RTOL = 1e-9


def rectangle(width: float, length: float) -> np.ndarray:
    """Axis-aligned rectangle centred at the origin: ``width`` across x, ``length`` along y (m)."""
    w, l = 0.5 * width, 0.5 * length
    return np.array([[-w, -l], [w, -l], [w, l], [-w, l]], dtype=np.float64)


def diamond(width: float, length: float) -> np.ndarray:
    """Rhombus centred at the origin with its corners on the axes.

    ``width`` is the diagonal across x, ``length`` the diagonal along y (m).
    """
    w, l = 0.5 * width, 0.5 * length
    return np.array([[w, 0.0], [0.0, l], [-w, 0.0], [0.0, -l]], dtype=np.float64)


def signed_area(vertices: np.ndarray) -> float:
    """Shoelace area (m^2), positive for counter-clockwise vertex order."""
    v = np.asarray(vertices, dtype=np.float64)
    x, y = v[:, 0], v[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def mass_properties(vertices: np.ndarray) -> tuple[float, np.ndarray, float]:
    """Area, centroid and polar second moment of area of a simple polygon.

    Args:
        vertices: ``(n, 2)`` counter-clockwise vertices (m).

    Returns:
        ``(area, centroid, polar_moment)``: area in m^2, centroid ``(2,)`` in m, and
        ``J = integral of |r - centroid|^2 dA`` in m^4 (multiply by density and thickness
        for the moment of inertia, kg m^2).
    """
    v = np.asarray(vertices, dtype=np.float64)
    x0, y0 = v[:, 0], v[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    cross = x0 * y1 - x1 * y0
    area = 0.5 * float(np.sum(cross))
    cx = float(np.sum((x0 + x1) * cross)) / (6.0 * area)
    cy = float(np.sum((y0 + y1) * cross)) / (6.0 * area)
    # Second moments about the origin (standard triangle-fan formulas), then shifted to the
    # centroid with the parallel-axis theorem.
    ixx = float(np.sum((y0 * y0 + y0 * y1 + y1 * y1) * cross)) / 12.0
    iyy = float(np.sum((x0 * x0 + x0 * x1 + x1 * x1) * cross)) / 12.0
    polar = ixx + iyy - area * (cx * cx + cy * cy)
    return area, np.array([cx, cy]), polar


def check_polygon(vertices, what: str = "polygon") -> np.ndarray:
    """Validate a floe outline and return it as a float64 ``(n, 2)`` array.

    Args:
        vertices: sequence of ``[x, y]`` pairs (m).
        what: how to name the polygon in error messages (e.g. ``"body 'pillar' vertices"``).

    Raises:
        PolygonError: fewer than three vertices, not finite, zero area, clockwise order,
            repeated or collinear vertices, or not convex; the message says which and how
            to fix it.
    """
    try:
        v = np.asarray(vertices, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise PolygonError(f"{what}: must be a list of [x, y] number pairs ({exc})") from None
    if v.ndim != 2 or v.shape[1] != 2:
        raise PolygonError(f"{what}: must be a list of [x, y] pairs, got shape {v.shape}")
    if len(v) < 3:
        raise PolygonError(f"{what}: needs at least 3 vertices, got {len(v)}")
    if not np.all(np.isfinite(v)):
        raise PolygonError(f"{what}: vertices must be finite numbers (found NaN or inf)")
    extent = float(np.max(np.ptp(v, axis=0)))
    area = signed_area(v)
    if extent <= 0.0 or abs(area) <= CONVEXITY_RTOL * extent * extent:
        raise PolygonError(
            f"{what}: has zero area; give at least 3 vertices that are not collinear"
        )
    if area < 0.0:
        raise PolygonError(
            f"{what}: vertices are clockwise; list them counter-clockwise (reverse the list)"
        )
    edges = np.roll(v, -1, axis=0) - v
    if np.any(np.hypot(edges[:, 0], edges[:, 1]) <= CONVEXITY_RTOL * extent):
        raise PolygonError(f"{what}: has repeated consecutive vertices; remove the duplicates")
    turns = edges[:, 0] * np.roll(edges[:, 1], -1) - edges[:, 1] * np.roll(edges[:, 0], -1)
    if np.any(turns <= CONVEXITY_RTOL * extent * extent):
        bad = int(np.argmin(turns) + 1) % len(v)
        kind = (
            "collinear with its neighbours"
            if abs(turns[bad - 1]) <= CONVEXITY_RTOL * extent * extent
            else "a reflex (inward) corner"
        )
        raise PolygonError(
            f"{what}: not strictly convex: vertex {bad} {v[bad].tolist()} is {kind}; "
            "floes must be convex polygons (split a concave floe into convex pieces)"
        )
    # Every turn is to the left, yet the outline may wind round more than once (a pentagram,
    # a hexagon traced twice): the turning angles of a simple convex polygon sum to 2 pi.
    turning = float(np.sum(np.arctan2(turns, np.sum(edges * np.roll(edges, -1, axis=0), axis=1))))
    if turning > 3.0 * np.pi:
        raise PolygonError(
            f"{what}: crosses itself: its outline winds {turning / (2.0 * np.pi):.0f} times "
            "around its inside (a star, or a polygon traced twice); list each corner once, in "
            "counter-clockwise order"
        )
    return v


def transform(vertices: np.ndarray, position, angle: float) -> np.ndarray:
    """Rotate ``vertices`` by ``angle`` (rad, counter-clockwise) and translate by ``position``."""
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    return np.asarray(vertices, dtype=np.float64) @ rot.T + np.asarray(position, dtype=np.float64)


# ---------------------------------------------------------------------------------------------
# A body's rotation: cos and sin of its angle, every step
# ---------------------------------------------------------------------------------------------

# The step turns every moving body, and libm's general sin and cos took 12 % of a step of the
# random box at 1e4 blocks (sampled with perf on the 2-core VM). fdlibm's method (Sun
# Microsystems 1993, as in glibc and musl) at a fraction of the cost: reduce x by the nearest
# multiple k of pi/2 with pi/2 split in three 33-bit parts (Cody and Waite 1980: k pi/2 is
# exact for |k| < 2^20), then evaluate the kernels __kernel_sin and __kernel_cos on
# |r| <= pi/4 and pick the quadrant from k. Within 1.2e-16 of NumPy's cos and sin (half an
# ulp of 1; tests/test_geometry.py). Beyond ROTATION_REDUCED_MAX rad (a body that has turned
# 160,000 times) the reduction is no longer exact and libm takes over.
PIO2_1 = 1.57079632673412561417e00  # first 33 bits of pi/2
PIO2_2 = 6.07710050630396597660e-11  # next 33 bits
PIO2_3 = 2.02226624871116645580e-21  # next 33 bits
TWO_OVER_PI = 6.36619772367581382433e-01
SIN_COEFFS = (
    -1.66666666666666324348e-01,
    8.33333333332248946124e-03,
    -1.98412698298579493134e-04,
    2.75573137070700676789e-06,
    -2.50507602534068634195e-08,
    1.58969099521155010221e-10,
)
COS_COEFFS = (
    4.16666666666666019037e-02,
    -1.38888888888741095749e-03,
    2.48015872894767294178e-05,
    -2.75573143513906633035e-07,
    2.08757232129817482790e-09,
    -1.13596475577881948265e-11,
)
ROTATION_REDUCED_MAX = 1.0e6
TWO_PI = 6.28318530717958647693e00
INV_TWO_PI = 1.59154943091895335769e-01


def rotation(angle, portable: bool = False):
    """``(cos(angle), sin(angle))`` by fdlibm's method (see above), as float64 arrays.

    The NumPy twin of :func:`rotation_ti`, step for step, so the two agree bit for bit; both
    are within 1.2e-16 of ``np.cos`` and ``np.sin``.

    Args:
        angle: angle(s) in rad, any shape.
        portable: as on a backend without float64 cos and sin (Vulkan, Metal): an angle
            beyond ``ROTATION_REDUCED_MAX`` is brought within a turn of 0 (losing what its
            own round-off holds, ~1e-16 of it) instead of handed to libm.
    """
    x = np.asarray(angle, dtype=np.float64)
    if portable:
        with np.errstate(invalid="ignore"):
            far = ~(np.abs(x) <= ROTATION_REDUCED_MAX)
        x = np.where(far, x - TWO_PI * np.floor(x * INV_TWO_PI + 0.5), x)
    k = np.floor(x * TWO_OVER_PI + 0.5)
    r = ((x - k * PIO2_1) - k * PIO2_2) - k * PIO2_3
    z = r * r
    s1, s2, s3, s4, s5, s6 = SIN_COEFFS
    c1, c2, c3, c4, c5, c6 = COS_COEFFS
    sin_r = r + r * z * (s1 + z * (s2 + z * (s3 + z * (s4 + z * (s5 + z * s6)))))
    tail = z * z * (c1 + z * (c2 + z * (c3 + z * (c4 + z * (c5 + z * c6)))))
    hz = 0.5 * z
    w = 1.0 - hz
    cos_r = w + (((1.0 - w) - hz) + tail)
    quadrant = np.mod(k, 4.0)
    c = np.select([quadrant == 0, quadrant == 1, quadrant == 2], [cos_r, -sin_r, -cos_r], sin_r)
    s = np.select([quadrant == 0, quadrant == 1, quadrant == 2], [sin_r, cos_r, -sin_r], -cos_r)
    far = ~(np.abs(x) <= ROTATION_REDUCED_MAX)
    if not portable and np.any(far):
        c = np.where(far, np.cos(x), c)
        s = np.where(far, np.sin(x), s)
    return c, s


# ---------------------------------------------------------------------------------------------
# Overlap of two convex polygons (Hopkins 1992 contact geometry)
# ---------------------------------------------------------------------------------------------

# ``Overlap.kind`` is a ``codes.OverlapKind``: NONE, CHORD or FALLBACK.


class Overlap(NamedTuple):
    """Contact geometry of two overlapping convex polygons ``p`` and ``q``.

    Attributes:
        area: area of the intersection polygon ``A_ov`` (m^2).
        centroid: ``(2,)`` centroid of the intersection polygon, the contact point (m).
        normal: ``(2,)`` unit contact normal, pointing out of ``p`` into ``q``.
        width: contact width ``L``, the length of the chord between the two points where
            the boundaries cross (m); see :func:`overlap` for the fallback.
        kind: ``OverlapKind.NONE``, ``CHORD`` or ``FALLBACK``.

    :func:`batched.overlap_batch_ti` returns the same fields as arrays with a leading batch axis.
    """

    area: float
    centroid: np.ndarray
    normal: np.ndarray
    width: float
    kind: int


def _cross(ax, ay, bx, by):
    """z component of the 2D cross product (works on scalars and arrays)."""
    return ax * by - ay * bx


def edge_normals(p: np.ndarray) -> np.ndarray:
    """``(n, 2)`` outward unit normals of the edges of a counter-clockwise polygon ``p``; edge
    k runs from vertex k to vertex k + 1 (the NumPy twin of :func:`edge_normals_ti`)."""
    p = np.asarray(p, dtype=np.float64)
    edges = np.roll(p, -1, axis=0) - p
    # Outward normal of a counter-clockwise edge (ex, ey) is (ey, -ex).
    normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)
    return normals / np.hypot(normals[:, 0], normals[:, 1])[:, None]


def min_penetration_axis(p: np.ndarray, q: np.ndarray) -> tuple[float, np.ndarray]:
    """Separating-axis query over the edge normals of both convex polygons.

    For an outward unit edge normal ``n`` of ``p`` through vertex ``p_k`` the penetration of
    ``q`` is ``n . p_k - min_j n . q_j``: how far ``q`` must move along ``n`` to clear that
    edge's line (likewise for the edges of ``q``, whose normals point from ``q`` to ``p``,
    so they are negated). The smallest one is the cheapest way to separate the pair.

    Args:
        p: ``(n, 2)`` counter-clockwise convex polygon (m).
        q: ``(m, 2)`` counter-clockwise convex polygon (m).

    Returns:
        ``(depth, axis)``: depth (m) is positive when the polygons overlap, the smallest
        penetration, and ``<= 0`` when an edge line separates them: then ``-depth`` is the
        gap along the first separating edge normal (edges of ``p`` in order, then of ``q``;
        the search stops there), a lower bound on their distance. ``axis`` is the ``(2,)``
        unit normal of that edge, oriented from ``p`` toward ``q``. Ties go to the first
        edge of ``p``, then of ``q``.
    """
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    best_depth = np.inf
    best_axis = np.zeros(2)
    for own, other, sign in ((p, q, 1.0), (q, p, -1.0)):
        normals = edge_normals(own)
        # rel[k, j] = n_k . (other_j - own_k)
        rel = np.einsum("kd,kjd->kj", normals, other[None, :, :] - own[:, None, :])
        depths = -rel.min(axis=1)
        separating = np.flatnonzero(depths <= 0.0)
        if separating.size:
            k = int(separating[0])
            return float(depths[k]), sign * normals[k]
        k = int(np.argmin(depths))
        if depths[k] < best_depth:
            best_depth = float(depths[k])
            best_axis = sign * normals[k]
    return best_depth, best_axis


def longest_edge(p: np.ndarray) -> float:
    """Length of a polygon's longest edge (m): the widest contact it can make."""
    p = np.asarray(p, dtype=np.float64)
    e = np.roll(p, -1, axis=0) - p
    return float(np.max(np.hypot(e[:, 0], e[:, 1])))


def min_width(p: np.ndarray) -> float:
    """Thinnest width of a convex polygon (m): the least distance between two parallel
    supporting lines, which for a convex polygon lies across one of its edges."""
    p = np.asarray(p, dtype=np.float64)
    e = np.roll(p, -1, axis=0) - p
    n = np.stack([e[:, 1], -e[:, 0]], axis=1) / np.hypot(e[:, 0], e[:, 1])[:, None]
    # Distance of every vertex from every edge's line; the farthest vertex gives the width
    # across that edge.
    d = np.abs(np.einsum("ekd,ed->ek", p[None, :, :] - p[:, None, :], n))
    return float(np.min(np.max(d, axis=1)))


def sat_separated(p: np.ndarray, q: np.ndarray) -> bool:
    """True when an edge line of ``p`` or ``q`` separates them (touching counts as separated).

    Args:
        p: ``(n, 2)`` counter-clockwise convex polygon (m).
        q: ``(m, 2)`` counter-clockwise convex polygon (m).
    """
    return min_penetration_axis(p, q)[0] <= 0.0


def facing_gap(p: np.ndarray, q: np.ndarray, toward) -> float:
    """How far ``q`` lies beyond the edge of ``p`` that faces ``toward`` (m; negative: it
    reaches past that edge's line).

    The facing edge is the one whose outward normal has the largest component along
    ``toward`` (the first of equals), typically the direction from ``p``'s centroid to
    ``q``'s. A gap >= 0 proves the pair apart (any separating line does) by at least that
    much: the distance between the polygons is never less. A negative one proves nothing.

    Args:
        p: ``(n, 2)`` counter-clockwise convex polygon (m).
        q: ``(m, 2)`` counter-clockwise convex polygon (m).
        toward: ``(2,)`` direction (any length).
    """
    p = np.asarray(p, dtype=np.float64)
    normals = edge_normals(p)
    k = int(np.argmax(normals @ np.asarray(toward, dtype=np.float64)))
    return float(np.min((np.asarray(q, dtype=np.float64) - p[k]) @ normals[k]))


def separation_gap(p: np.ndarray, q: np.ndarray) -> float:
    """The widest gap along any edge normal of ``p`` or ``q`` (m): >= 0 proves the pair
    apart by at least that much (touching counts as apart), < 0 is minus their smallest
    penetration (``min_penetration_axis``' depth). The separating-axis test run over every
    axis, for the gap: the contact step tries it on a pair that was not in contact, when
    neither facing edge (``facing_gap``) separates it, so that the pair is skipped while
    the gap holds (``ContactStage.gap_bound``).

    Args:
        p: ``(n, 2)`` counter-clockwise convex polygon (m).
        q: ``(m, 2)`` counter-clockwise convex polygon (m).
    """
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    gap = -np.inf
    for own, other in ((p, q), (q, p)):
        for a, n in zip(own, edge_normals(own)):  # as facing_gap computes one edge's
            gap = max(gap, float(np.min((other - a) @ n)))
    return gap


def facing_separated(p: np.ndarray, q: np.ndarray, toward) -> bool:
    """True when the edge of ``p`` that faces ``toward`` separates ``p`` from ``q``
    (``facing_gap`` >= 0). A sufficient test, not a complete one: the contact step tries it
    for both polygons before the full separating-axis test: in the random box of 1e4
    diamonds it settles 99 % of the candidate pairs whose bounding circles meet but which do
    not touch.
    """
    return facing_gap(p, q, toward) >= 0.0


def intersection_polygon(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Intersection of two convex polygons by Sutherland-Hodgman clipping of ``p`` by ``q``.

    A point on an edge line of ``q`` counts as inside, so touching polygons give a
    degenerate (zero-area) result rather than nothing.

    Args:
        p: ``(n, 2)`` counter-clockwise convex polygon (m).
        q: ``(m, 2)`` counter-clockwise convex polygon (m).

    Returns:
        ``(k, 2)`` counter-clockwise vertices of the intersection, ``k <= n + m``; ``k`` is
        0 when they do not meet, and fewer than three vertices mean zero area.
    """
    poly = [tuple(v) for v in np.asarray(p, dtype=np.float64)]
    q = np.asarray(q, dtype=np.float64)
    for e in range(len(q)):
        if not poly:
            break
        cx, cy = q[e]
        ex, ey = q[(e + 1) % len(q)] - q[e]
        clipped = []
        for k in range(len(poly)):
            ax, ay = poly[k]
            bx, by = poly[(k + 1) % len(poly)]
            # Signed distances (times |edge|) of a and b to the left of the clipping edge.
            sa = _cross(ex, ey, ax - cx, ay - cy)
            sb = _cross(ex, ey, bx - cx, by - cy)
            if (sa >= 0.0) != (sb >= 0.0):
                t = sa / (sa - sb)
                clipped.append((ax + t * (bx - ax), ay + t * (by - ay)))
            if sb >= 0.0:
                clipped.append((bx, by))
        poly = clipped
    return np.array(poly, dtype=np.float64).reshape(-1, 2)


def _area_centroid(poly: np.ndarray) -> tuple[float, np.ndarray]:
    """Shoelace area and centroid, as a fan from the first vertex.

    Taking the first vertex as origin keeps the cross products small for a small overlap far
    from the world origin (the cancellation that matters most in float32).
    """
    if len(poly) < 3:
        return 0.0, np.zeros(2)
    rel = poly[1:] - poly[0]
    u, w = rel[:-1], rel[1:]
    cross = _cross(u[:, 0], u[:, 1], w[:, 0], w[:, 1])
    twice_area = float(np.sum(cross))
    if twice_area <= 0.0:
        return 0.0, np.zeros(2)
    centroid = poly[0] + np.sum((u + w) * cross[:, None], axis=0) / (3.0 * twice_area)
    return 0.5 * twice_area, centroid


def boundary_crossings(p: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points where the boundary of ``p`` crosses the boundary of ``q``.

    Edge ``a -> b`` of ``p`` crosses edge ``c -> d`` of ``q`` when ``a`` and ``b`` lie on
    different sides of line ``cd`` and ``c`` and ``d`` on different sides of line ``ab``,
    where a point on a line counts as outside (to the right). That rule never divides by
    zero and counts a crossing through a vertex once; touching and collinear edges are
    usually not crossings, which sends those cases to the fallback of :func:`overlap`.

    Args:
        p: ``(n, 2)`` counter-clockwise convex polygon (m).
        q: ``(m, 2)`` counter-clockwise convex polygon (m).

    Returns:
        ``(points, entering)``: ``(c, 2)`` crossing points (m), ordered by edge of ``p``
        then edge of ``q``, and ``(c,)`` bools, True where the boundary of ``p``, walked
        counter-clockwise, enters ``q``.
    """
    points, entering, _edge_p, _edge_q = _crossings(p, q, _sides(p, q), _sides(q, p))
    return points, entering


def _sides(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``(n, m)`` sides of ``p``'s vertices to ``q``'s edge lines (times the edge's length;
    > 0 inside), as the clip and the crossings compute them."""
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    a, c = p[:, None, :], q[None, :, :]
    cd = np.roll(q, -1, axis=0)[None, :, :] - c
    return _cross(cd[..., 0], cd[..., 1], (a - c)[..., 0], (a - c)[..., 1])


def _crossings(p: np.ndarray, q: np.ndarray, sides: np.ndarray, sides_qp: np.ndarray):
    """:func:`boundary_crossings` with the edge of ``p`` and of ``q`` each point lies on
    (``(c,)`` indices; edge k runs from vertex k to k + 1), given ``_sides(p, q)`` and
    ``_sides(q, p)``: edge ``a -> b`` of ``p`` and ``c -> d`` of ``q`` cross where ``a`` and
    ``b`` lie on two sides of line ``cd`` (``sa``, ``sb``) and ``c`` and ``d`` on two sides
    of line ``ab`` (``tc``, ``td``)."""
    p = np.asarray(p, dtype=np.float64)
    sa, sb = sides, np.roll(sides, -1, axis=0)  # b's side is the next vertex's
    tc = sides_qp.T
    td = np.roll(tc, -1, axis=1)  # d's side is the next vertex's
    hit = ((sa > 0.0) != (sb > 0.0)) & ((tc > 0.0) != (td > 0.0))
    i, j = np.nonzero(hit)
    t = sa[i, j] / (sa[i, j] - sb[i, j])
    points = p[i] + t[:, None] * (np.roll(p, -1, axis=0)[i] - p[i])
    return points, sb[i, j] > 0.0, i, j


def _chord_polygon(p, q, enter, leave, enter_edges, leave_edges) -> np.ndarray:
    """The intersection of ``p`` and ``q`` whose boundaries cross exactly twice: ``enter``
    (on edge ``enter_edges[0]`` of ``p`` and ``enter_edges[1]`` of ``q``), ``p``'s vertices
    after that edge up to the start of ``leave``'s edge, ``leave``, and ``q``'s vertices
    after ``leave``'s edge of ``q`` up to the start of ``enter``'s (counter-clockwise)."""

    def after(poly, start, stop):
        # The vertices after edge ``start`` up to the one that starts edge ``stop``.
        k, out = int(start), []
        while k != int(stop):
            k = (k + 1) % len(poly)
            out.append(poly[k])
        return out

    walk = [enter, *after(p, enter_edges[0], leave_edges[0])]
    walk += [leave, *after(q, leave_edges[1], enter_edges[1])]
    return np.array(walk, dtype=np.float64)


def overlap(p: np.ndarray, q: np.ndarray) -> Overlap:
    """Contact geometry of two convex polygons in the Hopkins (1992) overlap model.

    The intersection polygon gives the area ``A_ov`` and the contact point (its centroid).
    When the two boundaries cross exactly twice, once where the boundary of ``p`` enters
    ``q`` (``E``) and once where it leaves (``X``), the chord ``X -> E`` is the contact
    line: the width is its length and the normal its left perpendicular, which points to the
    side where the boundary of ``p`` lies inside ``q``, i.e. out of ``p`` into ``q``.

    Fallback (``kind == OverlapKind.FALLBACK``) when there are not exactly one entry and one
    exit: the normal is the separating-axis minimum-penetration axis over both polygons'
    edge normals (:func:`min_penetration_axis`, oriented ``p -> q``) and the width is the
    extent of the intersection polygon across that normal. Why this is continuous enough for
    a DEM force: the area, hence the elastic force ``k_e A_ov``, is continuous through every
    case; only the direction and the width (which scales the dashpot) can jump when the kind
    changes, and they jump little where it matters. Touching and collinear edges (measure
    zero, but met in lattices of equal blocks) are limits of chord contacts whose chord runs
    corner to corner across a thin overlap of depth ``d`` and width ``w``: its normal differs
    from the minimum-penetration axis (the face normal) by about ``d / w`` rad and its length
    from the extent by a fraction ``(d / w)^2 / 2``, both small in the small-overlap regime
    that a resolved time step keeps. Containment and more than two crossings need overlaps
    comparable to a block's size or a corner poking through; there the minimum-penetration
    axis is the direction that separates the pair soonest, the usual choice of polygon DEM
    and rigid-body codes, and the extent is the width of the overlap that pushes along it.

    Args:
        p: ``(n, 2)`` counter-clockwise convex polygon in world coordinates (m).
        q: ``(m, 2)`` counter-clockwise convex polygon in world coordinates (m).

    Returns:
        An :class:`Overlap`. Separated or touching polygons (zero area: an edge line
        separates them, round-off aside) give ``kind == OverlapKind.NONE`` with zero area,
        centroid, normal and width. A chord contact's polygon is walked from its two
        crossings (:func:`_chord_polygon`); the clip (:func:`intersection_polygon`) and the
        separating-axis test serve the fallback (a pair that overlaps has no separating
        axis to stop that test early, and most pairs that reach here overlap).
    """
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    none = Overlap(0.0, np.zeros(2), np.zeros(2), 0.0, OverlapKind.NONE)
    sides, sides_qp = _sides(p, q), _sides(q, p)
    if np.any(np.all(sides < 0.0, axis=0)) or np.any(np.all(sides_qp < 0.0, axis=0)):
        # One outline strictly outside an edge line of the other: no crossing, and no area
        # to clip (but for a sliver of round-off when its vertices lie within it of that
        # line). Most pairs the reference engine tries are apart: 5x faster than the clip.
        return none
    points, entering, edge_p, edge_q = _crossings(p, q, sides, sides_qp)
    if len(points) == 2 and entering[0] != entering[1]:
        e, x = (0, 1) if entering[0] else (1, 0)
        chord = points[e] - points[x]
        width = float(np.hypot(chord[0], chord[1]))
        if width > 0.0:
            poly = _chord_polygon(
                p, q, points[e], points[x], (edge_p[e], edge_q[e]), (edge_p[x], edge_q[x])
            )
            area, centroid = _area_centroid(poly)
            if area <= 0.0:
                return none
            normal = np.array([-chord[1], chord[0]]) / width
            return Overlap(area, centroid, normal, width, OverlapKind.CHORD)
    poly = intersection_polygon(p, q)
    area, centroid = _area_centroid(poly)
    if area <= 0.0:
        return none
    _depth, axis = min_penetration_axis(p, q)
    tangent = np.array([-axis[1], axis[0]])
    along = poly @ tangent
    return Overlap(area, centroid, axis, float(along.max() - along.min()), OverlapKind.FALLBACK)


__all__ = [
    "CONVEXITY_RTOL",
    "COS_COEFFS",
    "INV_TWO_PI",
    "PIO2_1",
    "PIO2_2",
    "PIO2_3",
    "ROTATION_REDUCED_MAX",
    "SIN_COEFFS",
    "TWO_OVER_PI",
    "TWO_PI",
    "Overlap",
    "boundary_crossings",
    "check_polygon",
    "diamond",
    "edge_normals",
    "facing_gap",
    "facing_separated",
    "intersection_polygon",
    "longest_edge",
    "mass_properties",
    "min_penetration_axis",
    "min_width",
    "overlap",
    "rectangle",
    "rotation",
    "sat_separated",
    "separation_gap",
    "signed_area",
    "transform",
]
