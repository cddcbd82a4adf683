"""The start-up overlap search: which bodies of a scene overlap before anything moves.

The scene parser refuses a scene whose bodies overlap at the start (a placement mistake
that the contact law would turn into an explosion at the first step). ``find_overlaps``
screens every pair in NumPy, fast enough for 100,000 blocks, and confirms the pairs left
with the reference functions of ``taichi_ice.geometry``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..codes import BodyKind
from ..physics import polygon

if TYPE_CHECKING:
    from .model import Body

__all__ = ["OVERLAP_RTOL", "find_overlaps", "penetration_depth"]

# Two bodies overlap at the start when their overlap area exceeds this fraction of the smaller
# one's area. Blocks laid edge to edge touch exactly, and round-off leaves them an overlap
# of order 1e-16 of their area; a real placement mistake is many orders above this.
OVERLAP_RTOL = 1e-6


def find_overlaps(
    bodies: Sequence[Body], max_pairs: int | None = None, rtol: float = OVERLAP_RTOL
) -> list[tuple[int, int, float, float]]:
    """Pairs of bodies that overlap, at least one of them dynamic.

    A grid broad phase (cell = the largest dynamic body's diameter; bodies much larger than a
    cell, such as long walls, are tested against every dynamic body by bounding box), then a
    bounding-circle test and a batched separating-axis test over the edge normals, in NumPy;
    the pairs left go to ``polygon.sat_separated`` and ``polygon.overlap``.

    Args:
        bodies: the scene's bodies.
        max_pairs: stop after this many overlapping pairs.
        rtol: a pair overlaps when its overlap area exceeds ``rtol`` times the smaller area.

    Returns:
        ``[(i, j, overlap_area, smaller_area), ...]`` with ``i < j``, in order of ``i``, m^2.
    """
    n = len(bodies)
    dynamic = np.array([b.kind == BodyKind.DYNAMIC.label for b in bodies], dtype=bool)
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
    # really overlap reach the per-pair reference functions of ``physics.polygon``.
    depth = _sat_depth(groups, group_of, row_of, pos, a, b)
    keep = depth > 1e-9 * (radius[a] + radius[b])
    a, b = a[keep], b[keep]
    order = np.lexsort((b, a))
    found: list[tuple[int, int, float, float]] = []
    areas: dict[int, float] = {}
    for i, j in zip(a[order].tolist(), b[order].tolist()):
        pi, pj = bodies[i].world_vertices(), bodies[j].world_vertices()
        if polygon.sat_separated(pi, pj):
            continue
        area = float(polygon.overlap(pi, pj).area)
        for k in (i, j):
            if k not in areas:
                areas[k] = polygon.signed_area(bodies[k].vertices)
        smaller = min(areas[i], areas[j])
        if area > rtol * smaller:
            found.append((i, j, area, smaller))
            if max_pairs is not None and len(found) >= max_pairs:
                break
    return found


def _sat_depth(groups, group_of, row_of, pos, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Penetration depth (m) of each pair ``(a[p], b[p])`` over both bodies' edge normals.

    Positive when the pair overlaps, ``<= 0`` when an edge line separates it; the batched
    form of ``polygon.min_penetration_axis``, used only to screen candidate pairs.
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
                depth[chunk] = penetration_depth(p, q)
    return depth


def penetration_depth(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``(P,)`` depth (m) of each pair of convex outlines over both outlines' edge normals.

    Args:
        p, q: ``(P, n, 2)`` and ``(P, m, 2)`` counter-clockwise outlines in the world, m.

    Returns:
        Positive: the pair overlaps by that much along its least-penetration edge normal (the
        batched ``polygon.min_penetration_axis``). Zero or negative: an edge line separates
        the pair, and minus the value is the widest gap along an edge normal (a lower bound
        of the distance between them).
    """
    return np.minimum(_edge_depth(p, q), _edge_depth(q, p))


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
