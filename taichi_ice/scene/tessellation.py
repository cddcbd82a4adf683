"""Convex-polygon geometry for floe fields: power (weighted Voronoi) diagrams of a convex
region, the weights that give each cell the area asked for, random disks that seed them,
convex hulls, and the simplification of an outline to the engine's vertex count.

Pure NumPy (no SciPy, which the package does not depend on): a cell of the power diagram is
the region clipped by the half-planes of its neighbours,

    cell_i = { x in region : |x - p_i|^2 - w_i <= |x - p_j|^2 - w_j  for every j },

found by clipping with the most violated half-plane among the sites near ``p_i`` until none
is violated, over a search radius that provably holds every site that can cut the cell. With
every weight zero it is the Voronoi diagram. The weights that give the cells prescribed
areas maximise a concave function whose Hessian is the graph Laplacian of the cells with
edge weights ``l_ij / (2 |p_i - p_j|)`` (Aurenhammer, Hoffmann and Aronov 1998,
doi:10.1007/PL00009187); :func:`balance_weights` takes damped Newton steps on it, solved by
conjugate gradients (Kitagawa, Mérigot and Thibert 2019, doi:10.4171/JEMS/889).

Every polygon is an ``(n, 2)`` counter-clockwise array of vertices, m.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..physics.polygon import signed_area

__all__ = [
    "CLEAN_RTOL",
    "balance_weights",
    "clean",
    "convex_hull",
    "is_convex",
    "place_disks",
    "power_cells",
    "simplify",
]

# A vertex whose edges are shorter than this fraction of the outline's extent, or whose turn
# is below its square, is dropped by ``clean``: a hundred times the tolerance of
# ``physics.polygon.check_polygon`` (1e-9), so that a cleaned outline always passes it.
CLEAN_RTOL = 1e-7
# A site this far (relative to the region's extent) past a half-plane counts as inside it:
# round-off in coordinates of order 1e-16 of the extent.
_CLIP_RTOL = 1e-12


# --------------------------------------------------------------------------------------------
# One polygon
# --------------------------------------------------------------------------------------------


def _clip(v: np.ndarray, labels: list[int], s: np.ndarray, label: int):
    """``v`` cut to ``{s <= 0}``, ``s`` the half-plane's value at each vertex; ``labels[k]``
    names what edge ``k`` (from vertex ``k`` to ``k + 1``) lies on, the new edge ``label``."""
    out: list[np.ndarray] = []
    out_labels: list[int] = []
    n = len(v)
    for k in range(n):
        a, b = s[k], s[(k + 1) % n]
        if a <= 0.0:
            out.append(v[k])
            out_labels.append(labels[k])
            if b > 0.0:
                out.append(v[k] + (v[(k + 1) % n] - v[k]) * (a / (a - b)))
                out_labels.append(label)
        elif b <= 0.0:
            out.append(v[k] + (v[(k + 1) % n] - v[k]) * (a / (a - b)))
            out_labels.append(labels[k])
    if len(out) < 3:
        return np.zeros((0, 2)), []
    return np.array(out), out_labels


def _turns(v: np.ndarray) -> np.ndarray:
    """Cross product of the edges into and out of each vertex (positive: a left turn)."""
    before = v - np.roll(v, 1, axis=0)
    after = np.roll(v, -1, axis=0) - v
    return before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]


def is_convex(v: np.ndarray, rtol: float = CLEAN_RTOL) -> bool:
    """True when every turn of the counter-clockwise outline ``v`` is strictly to the left."""
    extent = float(np.max(np.ptp(v, axis=0)))
    return bool(np.all(_turns(v) > rtol * extent * extent))


def _ear_areas(v: np.ndarray) -> np.ndarray:
    """Area each vertex's removal takes off the outline (negative at a reflex vertex), m^2."""
    return 0.5 * _turns(v)


def clean(v: np.ndarray, rtol: float = CLEAN_RTOL) -> np.ndarray:
    """``v`` without repeated and collinear vertices: while an edge is shorter than ``rtol``
    of the extent or a turn smaller than ``rtol`` of its square, the vertex of the smallest
    ear among those is removed (a convex outline only loses area, of that order)."""
    v = np.asarray(v, dtype=np.float64)
    while len(v) > 3:
        extent = float(np.max(np.ptp(v, axis=0)))
        edges = np.roll(v, -1, axis=0) - v
        length = np.hypot(edges[:, 0], edges[:, 1])
        short = (length <= rtol * extent) | (np.roll(length, 1) <= rtol * extent)
        flat = np.abs(_turns(v)) <= rtol * extent * extent
        bad = np.flatnonzero(short | flat)
        if bad.size == 0:
            break
        ears = np.abs(_ear_areas(v))
        v = np.delete(v, bad[np.argmin(ears[bad])], axis=0)
    return v


def simplify(v: np.ndarray, max_vertices: int) -> np.ndarray:
    """The convex outline ``v`` cut to at most ``max_vertices`` vertices by removing, one at
    a time, the vertex whose removal takes the least area (the result is convex and inside
    ``v``)."""
    v = np.asarray(v, dtype=np.float64)
    while len(v) > max_vertices:
        v = np.delete(v, int(np.argmin(_ear_areas(v))), axis=0)
    return v


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull of ``points`` with no collinear vertex (Andrew's
    monotone chain), starting at the lowest-leftmost point."""
    p = np.unique(np.asarray(points, dtype=np.float64), axis=0)  # sorted by x, then y
    if len(p) < 3:
        return p

    def half(points):
        chain: list[np.ndarray] = []
        for q in points:
            while len(chain) >= 2:
                a, b = chain[-2], chain[-1]
                if (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]) > 0.0:
                    break
                chain.pop()
            chain.append(q)
        return chain

    lower, upper = half(p), half(p[::-1])
    return np.array(lower[:-1] + upper[:-1])


# --------------------------------------------------------------------------------------------
# Power diagram
# --------------------------------------------------------------------------------------------


class _Grid:
    """The sites bucketed in square cells, for the sites within a box."""

    def __init__(self, points: np.ndarray, cell: float):
        self.points, self.cell = points, cell
        self.lo = points.min(axis=0)
        ij = np.floor((points - self.lo) / cell).astype(np.int64)
        self.shape = ij.max(axis=0) + 1
        key = ij[:, 0] * self.shape[1] + ij[:, 1]
        self.order = np.argsort(key, kind="stable")
        self.keys = key[self.order]

    def near(self, centre: np.ndarray, radius: float) -> np.ndarray:
        """Indices of the sites in the cells that the box ``centre +- radius`` touches."""
        a = np.floor((centre - radius - self.lo) / self.cell).astype(np.int64)
        b = np.floor((centre + radius - self.lo) / self.cell).astype(np.int64)
        a, b = np.maximum(a, 0), np.minimum(b, self.shape - 1)
        if np.any(a > b):
            return np.zeros(0, dtype=np.int64)
        columns = np.arange(a[0], b[0] + 1) * self.shape[1]
        start = np.searchsorted(self.keys, columns + a[1], "left")
        stop = np.searchsorted(self.keys, columns + b[1], "right")
        return np.concatenate([self.order[s:e] for s, e in zip(start, stop)])


def power_cells(
    sites: np.ndarray, weights: np.ndarray, region: np.ndarray
) -> tuple[list[np.ndarray], list[list[int]]]:
    """The power diagram of ``sites`` with ``weights`` (m^2) restricted to ``region``.

    Args:
        sites: ``(N, 2)`` distinct points, m. weights: ``(N,)``; all zero: the Voronoi diagram.
        region: a convex counter-clockwise polygon, m.

    Returns:
        ``(cells, neighbours)``: cell ``i`` as a counter-clockwise polygon (empty ``(0, 2)``
        when the weights leave it no room), and what each of its edges lies on (a site's
        index, or -1 for the region's boundary).
    """
    sites = np.asarray(sites, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    region = np.asarray(region, dtype=np.float64)
    n = len(sites)
    extent = float(np.max(np.ptp(region, axis=0)))
    area = signed_area(region)
    grid = _Grid(sites, 2.0 * math.sqrt(area / n))
    w_max = float(weights.max())
    tol = _CLIP_RTOL * extent
    cells: list[np.ndarray] = []
    neighbours: list[list[int]] = []
    for i in range(n):
        p, w = sites[i], weights[i]
        v, labels = region - p, [-1] * len(region)
        done = np.zeros(0, dtype=np.int64)
        radius = 2.0 * grid.cell
        while len(v):
            near = grid.near(p, radius)
            near = np.setdiff1d(near[near != i], done, assume_unique=False)
            done = np.union1d(done, near)
            q = sites[near] - p
            # Cell i is 2 y.q <= |q|^2 + w_i - w_j in y = x - p_i: one row per site j.
            beta = np.einsum("ij,ij->i", q, q) + w - weights[near]
            norm = 2.0 * np.hypot(q[:, 0], q[:, 1])
            while len(v) and len(near):
                past = ((2.0 * v @ q.T) - beta).max(axis=0) / norm
                j = int(np.argmax(past))
                if past[j] <= tol:
                    break
                v, labels = _clip(v, labels, 2.0 * v @ q[j] - beta[j], int(near[j]))
            if not len(v):
                break
            reach = float(np.sqrt((v**2).sum(axis=1).max()))
            # A site j at distance d >= reach cuts nothing when (d - reach)^2 - w_max >=
            # reach^2 - w_i, which bounds |x - p_j|^2 - w_j and |x - p_i|^2 - w_i in the cell.
            needed = reach + math.sqrt(max(reach * reach - w + w_max, 0.0))
            if radius >= needed:
                break
            radius = max(needed, 1.5 * radius)
        cells.append(v + p if len(v) else np.zeros((0, 2)))
        neighbours.append(labels)
    return cells, neighbours


def _laplacian(sites, cells, neighbours):
    """``(rows, columns, values)`` of the off-diagonal of d(area)/d(weight), with ``values``
    ``l_ij / (2 |p_i - p_j|)`` for each shared edge, each pair once in each direction."""
    rows, cols, vals = [], [], []
    for i, (v, labels) in enumerate(zip(cells, neighbours)):
        if not len(v):
            continue
        edges = np.roll(v, -1, axis=0) - v
        length = np.hypot(edges[:, 0], edges[:, 1])
        for k, j in enumerate(labels):
            if j >= 0:
                rows.append(i)
                cols.append(j)
                vals.append(length[k] / (2.0 * float(np.hypot(*(sites[j] - sites[i])))))
    rows, cols, vals = np.array(rows, int), np.array(cols, int), np.array(vals)
    # Each edge is seen from both cells: the mean of the two is symmetric to round-off.
    n = len(sites)
    key = np.minimum(rows, cols) * n + np.maximum(rows, cols)
    uniq, inverse = np.unique(key, return_inverse=True)
    mean = np.bincount(inverse, vals) / np.bincount(inverse)
    a, b = np.divmod(uniq, n)
    return np.concatenate([a, b]), np.concatenate([b, a]), np.concatenate([mean, mean])


def _solve_laplacian(n, rows, cols, vals, rhs, rtol=1e-12, max_iter=None):
    """``x`` of ``L x = rhs`` (``L`` the graph Laplacian; ``rhs`` made to sum to zero, ``x``
    to mean zero), by conjugate gradients."""
    degree = np.bincount(rows, vals, minlength=n)

    def apply(x):
        return degree * x - np.bincount(rows, vals * x[cols], minlength=n)

    b = rhs - rhs.mean()
    x = np.zeros(n)
    r = b.copy()
    d = r.copy()
    rr = float(r @ r)
    stop = (rtol * float(np.linalg.norm(b))) ** 2
    for _ in range(max_iter or 10 * n + 100):
        if rr <= stop:
            break
        ad = apply(d)
        alpha = rr / float(d @ ad)
        x += alpha * d
        r -= alpha * ad
        rr, rr_old = float(r @ r), rr
        d = r + (rr / rr_old) * d
    return x - x.mean()


class BalanceError(ValueError):
    """The weights could not give the cells their areas (a target too small for its site)."""


def balance_weights(
    sites: np.ndarray,
    weights: np.ndarray,
    targets: np.ndarray,
    region: np.ndarray,
    rtol: float = 1e-9,
    max_iter: int = 60,
):
    """Weights whose power cells have the areas ``targets`` (m^2, summing to the region's).

    Damped Newton on the weights (module docstring), from ``weights``: a step is halved
    until every cell keeps at least half the area of the smallest cell or target and the
    largest error ``|area_i - target_i| / target_i`` falls by at least a quarter of the step.

    Returns:
        ``(weights, cells, neighbours, areas)``; the largest relative area error is below
        ``rtol``.

    Raises:
        BalanceError: no step improves the areas, or ``max_iter`` steps were not enough.
    """
    n = len(sites)
    targets = np.asarray(targets, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64).copy()

    def state(w):
        cells, labels = power_cells(sites, w, region)
        areas = np.array([signed_area(c) if len(c) else 0.0 for c in cells])
        return cells, labels, areas, float(np.max(np.abs(areas - targets) / targets))

    cells, labels, areas, error = state(w)
    for _ in range(max_iter):
        if error <= rtol:
            return w, cells, labels, areas
        if np.any(areas <= 0.0):
            raise BalanceError("a cell is empty")
        rows, cols, vals = _laplacian(sites, cells, labels)
        step = _solve_laplacian(n, rows, cols, vals, targets - areas)
        floor = 0.5 * min(float(areas.min()), float(targets.min()))
        t = 1.0
        while True:
            trial = state(w + t * step)
            if trial[2].min() >= floor and trial[3] <= (1.0 - 0.25 * t) * error:
                break
            t *= 0.5
            if t < 1e-6:
                raise BalanceError(f"no Newton step improves the areas (error {error:.3g})")
        w = w + t * step
        cells, labels, areas, error = trial
    if error <= rtol:
        return w, cells, labels, areas
    raise BalanceError(f"{max_iter} Newton steps left an area error of {error:.3g}")


# --------------------------------------------------------------------------------------------
# Seeds
# --------------------------------------------------------------------------------------------


def _inside(region: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``(P,)`` distance of each point inside the convex ``region`` from its boundary
    (negative outside), m."""
    edges = np.roll(region, -1, axis=0) - region
    normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)
    normals /= np.hypot(normals[:, 0], normals[:, 1])[:, None]
    # Outward normals of a counter-clockwise outline: inside, every n.(x - v) is negative.
    return -(points @ normals.T - np.einsum("kd,kd->k", normals, region)).max(axis=1)


def place_disks(
    radii: Sequence[float], region: np.ndarray, rng: np.random.Generator, batch: int = 32
) -> np.ndarray | None:
    """Centres of disjoint disks of ``radii`` in ``region``, placed in the order given
    (random sequential addition: each centre uniform over the places left), m.

    A centre keeps half its radius from the boundary where the region allows. Returns
    ``None`` when a disk finds no place in 200 batches of ``batch`` tries (the caller
    shrinks the disks). Draws from ``rng`` only.
    """
    radii = np.asarray(radii, dtype=np.float64)
    lo, hi = region.min(axis=0), region.max(axis=0)
    cell = 2.0 * float(radii.max())
    buckets: dict[tuple[int, int], list[int]] = {}
    centres = np.empty((len(radii), 2))
    for i, r in enumerate(radii):
        for attempt in range(200):
            tries = lo + (hi - lo) * rng.random((batch, 2))
            margin = 0.5 * r if attempt < 100 else 0.0
            tries = tries[_inside(region, tries) >= margin]
            if not len(tries):
                continue
            placed = None
            # A disk of radius <= r_max whose centre is more than one cell away in x or y
            # cannot reach one of radius r <= r_max: each try is held against 3 x 3 cells.
            for c in tries:
                gx, gy = np.floor((c - lo) / cell).astype(np.int64).tolist()
                near = [
                    k
                    for x in (gx - 1, gx, gx + 1)
                    for y in (gy - 1, gy, gy + 1)
                    for k in buckets.get((x, y), ())
                ]
                if near:
                    d = np.hypot(*(centres[near] - c).T)
                    if np.any(d < r + radii[near]):
                        continue
                placed = (c, (gx, gy))
                break
            if placed is not None:
                centres[i] = placed[0]
                buckets.setdefault(placed[1], []).append(i)
                break
        else:
            return None
    return centres
