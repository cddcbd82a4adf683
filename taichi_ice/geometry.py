"""Convex polygons: construction, validation, mass properties, overlap and separation.

Every polygon is a ``(n, 2)`` float array of vertices in counter-clockwise order. Floes are
stored relative to their centroid (``vert_local``) and placed by a position and an angle.

NumPy functions here are the references that the Taichi kernels are tested against.
"""

from __future__ import annotations

import numpy as np

from .errors import PolygonError

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
        raise PolygonError(f"{what}: has zero area; give at least 3 vertices that are not collinear")
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
        kind = "collinear with its neighbours" if abs(turns[bad - 1]) <= CONVEXITY_RTOL * extent * extent else "a reflex (inward) corner"
        raise PolygonError(
            f"{what}: not strictly convex: vertex {bad} {v[bad].tolist()} is {kind}; "
            "floes must be convex polygons (split a concave floe into convex pieces)"
        )
    return v


def transform(vertices: np.ndarray, position, angle: float) -> np.ndarray:
    """Rotate ``vertices`` by ``angle`` (rad, counter-clockwise) and translate by ``position``."""
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    return np.asarray(vertices, dtype=np.float64) @ rot.T + np.asarray(position, dtype=np.float64)
