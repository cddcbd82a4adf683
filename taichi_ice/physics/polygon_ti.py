"""Convex polygons as Taichi functions: a body's rotation, separation and overlap.

The Taichi twins of ``polygon``'s NumPy references, in the same order (``rotation_ti``
beside ``polygon.rotation``, ``edge_normals_ti`` beside ``polygon.edge_normals``, ...,
``_clip_ti`` beside ``polygon.intersection_polygon``, ``overlap_ti`` beside
``polygon.overlap``), which the contact kernel and ``batched`` call; the constants of the
rotation are ``polygon``'s. What each computes, and why, is said at its twin.
"""

import taichi as ti

from .. import backend
from ..codes import OverlapKind
from .polygon import (
    COS_COEFFS,
    INV_TWO_PI,
    PIO2_1,
    PIO2_2,
    PIO2_3,
    ROTATION_REDUCED_MAX,
    SIN_COEFFS,
    TWO_OVER_PI,
    TWO_PI,
)

# ---------------------------------------------------------------------------------------------
# A body's rotation: cos and sin of its angle, every step (the method: polygon.rotation)
# ---------------------------------------------------------------------------------------------


@ti.func
def rotation_ti(angle):
    """Taichi twin of :func:`polygon.rotation`: ``ti.Vector([cos, sin])`` of ``angle`` (rad).

    For a float64 runtime (``backend.init(precision="f64")``): its constants are literals of
    the default float type, which in a float32 runtime would round them (the float32 step
    uses ``ti.cos`` and ``ti.sin``, ``integrate.Integrator.turn``). Beyond
    ``ROTATION_REDUCED_MAX`` libm takes over, except on the backends that have no float64
    cos and sin (``backend.portable_f64``: Vulkan, Metal), where the angle is first brought
    within a turn of 0 (``polygon.rotation(..., portable=True)``).
    """
    out = ti.Vector([0.0, 0.0])
    if ti.static(backend.portable_f64()):
        x = angle
        if not ti.abs(x) <= ROTATION_REDUCED_MAX:
            x = x - TWO_PI * ti.floor(x * INV_TWO_PI + 0.5)
        out = _rotation_reduced_ti(x)
    else:
        if ti.abs(angle) <= ROTATION_REDUCED_MAX:
            out = _rotation_reduced_ti(angle)
        else:
            out = ti.Vector([ti.cos(angle), ti.sin(angle)])
    return out


@ti.func
def _rotation_reduced_ti(angle):
    """fdlibm's cos and sin of an angle within ``ROTATION_REDUCED_MAX`` of 0."""
    k = ti.floor(angle * TWO_OVER_PI + 0.5)
    r = ((angle - k * PIO2_1) - k * PIO2_2) - k * PIO2_3
    z = r * r
    s1, s2, s3, s4, s5, s6 = ti.static(SIN_COEFFS)
    c1, c2, c3, c4, c5, c6 = ti.static(COS_COEFFS)
    sin_r = r + r * z * (s1 + z * (s2 + z * (s3 + z * (s4 + z * (s5 + z * s6)))))
    tail = z * z * (c1 + z * (c2 + z * (c3 + z * (c4 + z * (c5 + z * c6)))))
    hz = 0.5 * z
    w = 1.0 - hz
    cos_r = w + (((1.0 - w) - hz) + tail)
    quadrant = ti.cast(k, ti.i64) & 3
    c = 0.0
    s = 0.0
    if quadrant == 0:
        c, s = cos_r, sin_r
    elif quadrant == 1:
        c, s = -sin_r, cos_r
    elif quadrant == 2:
        c, s = -cos_r, -sin_r
    else:
        c, s = sin_r, -cos_r
    return ti.Vector([c, s])


# ---------------------------------------------------------------------------------------------
# Taichi twins, for the contact kernel. Each takes the vertices of two bodies as local
# matrices ``p`` of static shape (P, 2) and ``q`` of static shape (Q, 2) in world
# coordinates, of which the first ``n_p`` and ``n_q`` rows are used; no field access, one
# return statement each (Taichi 1.7 inlines ti.func and allows no early return).
# ---------------------------------------------------------------------------------------------


@ti.func
def _row(m: ti.template(), k):
    """Row ``k`` (a dynamic index) of a local ``(n, 2)`` matrix as a 2-vector."""
    return ti.math.vec2(m[k, 0], m[k, 1])


@ti.func
def _next_row(m: ti.template(), k: ti.template(), n):
    """Row ``k + 1`` of a local ``(N, 2)`` matrix holding an ``n``-gon, or row 0 after the last
    vertex, for a compile-time ``k``: both indices are constants."""
    nxt = ti.math.vec2(m[0, 0], m[0, 1])
    if ti.static(k + 1 < m.n):
        if k + 1 < n:
            nxt = ti.math.vec2(m[k + 1, 0], m[k + 1, 1])
    return nxt


@ti.func
def _cross_ti(a, b):
    """z component of the 2D cross product of two 2-vectors."""
    return a[0] * b[1] - a[1] * b[0]


@ti.func
def edge_normals_ti(p: ti.template(), n_p):
    """Outward unit normals of the edges of ``p`` (rows ``0 .. n_p - 1`` of a matrix shaped
    like ``p``; edge k runs from vertex k to vertex k + 1), for :func:`overlap_normals_ti`:
    a body's normals computed once serve all its candidate pairs."""
    normals = ti.Matrix.zero(float, p.n, 2)
    for k in ti.static(range(p.n)):
        if k < n_p:
            e = _next_row(p, k, n_p) - ti.math.vec2(p[k, 0], p[k, 1])
            n = ti.math.vec2(e[1], -e[0]).normalized()
            normals[k, 0] = n[0]
            normals[k, 1] = n[1]
    return normals


@ti.func
def min_penetration_axis_ti(p: ti.template(), n_p, q: ti.template(), n_q):
    """Taichi twin of :func:`polygon.min_penetration_axis`.

    Args:
        p: ``ti.Matrix`` of static shape ``(P, 2)``; rows ``0 .. n_p - 1`` are a
            counter-clockwise convex polygon (m).
        n_p: number of vertices of ``p`` (3 <= n_p <= P).
        q: ``ti.Matrix`` of static shape ``(Q, 2)``, likewise (m).
        n_q: number of vertices of ``q`` (3 <= n_q <= Q).

    Returns:
        ``(depth, axis)`` as :func:`polygon.min_penetration_axis`: depth (m), the smallest
        penetration when overlapping, the gap along the first separating edge (``<= 0``)
        when separated; axis a unit 2-vector from ``p`` toward ``q``.
    """
    return _min_penetration_axis_ti(
        p, edge_normals_ti(p, n_p), n_p, q, edge_normals_ti(q, n_q), n_q
    )


@ti.func
def _min_penetration_axis_ti(
    p: ti.template(), p_normals: ti.template(), n_p, q: ti.template(), q_normals: ti.template(), n_q
):
    """:func:`min_penetration_axis_ti` with the edge normals of both polygons given (the
    engine's are its bodies' shapes' normals turned, ``ContactLists.normals``: normalising
    q's edges here cost 7-14 % of a jammed pillar step, ``benchmarks/jam_step.py``)."""
    # Stops at the first separating axis: most candidate pairs of a dense field are near
    # misses, and the depth of a separated pair only matters by its sign. The loops are
    # unrolled over the matrices' static size (rows past the count skipped), so every index
    # is a constant and the outlines stay in registers: a third fewer instructions a step
    # than loops over the counts, which kept them in memory (random box of 1e4 diamonds,
    # with the outline and normals unrolled likewise).
    depth = 0.0
    axis = ti.math.vec2(0.0, 0.0)
    separated = False
    for k in ti.static(range(p.n)):
        if k < n_p and not separated:
            d, n = _normal_penetration_ti(p, p_normals, k, q, n_q)
            if ti.static(k == 0):
                depth, axis = d, n
            elif d < depth:
                depth, axis = d, n
            if depth <= 0.0:
                separated = True
    if not separated:
        for k in ti.static(range(q.n)):
            if k < n_q and not separated:
                d, n = _normal_penetration_ti(q, q_normals, k, p, n_p)
                if d < depth:
                    depth, axis = d, -n
                if depth <= 0.0:
                    separated = True
    return depth, axis


@ti.func
def _after(k, n):
    """The vertex after ``k`` of an ``n``-gon (an integer modulo costs tens of cycles)."""
    k1 = k + 1
    if k1 == n:
        k1 = 0
    return k1


@ti.func
def _normal_penetration_ti(
    own: ti.template(), normals: ti.template(), k: ti.template(), other: ti.template(), n_other
):
    """How far ``other`` reaches past edge ``k`` (a compile-time index) of ``own`` along its
    outward unit normal ``normals[k]`` (m; <= 0: that edge's line separates them), and the
    normal."""
    a = ti.math.vec2(own[k, 0], own[k, 1])
    n = ti.math.vec2(normals[k, 0], normals[k, 1])
    return _reach_past_ti(a, n, other, n_other), n


@ti.func
def _reach_past_ti(a, n, other: ti.template(), n_other):
    """How far ``other`` reaches past the line through ``a`` with outward unit normal ``n``
    (m; <= 0: the line separates them)."""
    lowest = ti.math.dot(n, ti.math.vec2(other[0, 0], other[0, 1]) - a)
    for j in ti.static(range(1, other.n)):
        if j < n_other:
            lowest = ti.min(lowest, ti.math.dot(n, ti.math.vec2(other[j, 0], other[j, 1]) - a))
    return -lowest


@ti.func
def sat_separated_ti(p: ti.template(), n_p, q: ti.template(), n_q):
    """Taichi twin of :func:`polygon.sat_separated`: True (1) when an edge line separates p and q.

    Same arguments as :func:`min_penetration_axis_ti`. :func:`overlap_ti` does not run it
    first: most pairs that reach an overlap touch, where the test runs every axis to find
    none; a separated pair has no crossing and its clip no area.
    """
    depth, _axis = min_penetration_axis_ti(p, n_p, q, n_q)
    return depth <= 0.0


@ti.func
def separation_gap_ti(
    p: ti.template(), p_normals: ti.template(), n_p, q: ti.template(), q_normals: ti.template(), n_q
):
    """Taichi twin of :func:`polygon.separation_gap`, the outward unit normals of both
    polygons' edges given: the widest gap along any edge normal of either (m; >= 0: apart
    by at least that much). Every axis, unrolled over the matrices' static size (rows past
    the count skipped), as ``_min_penetration_axis_ti``."""
    gap = -_reach_past_ti(_row(p, 0), _row(p_normals, 0), q, n_q)
    for k in ti.static(range(1, p.n)):
        if k < n_p:
            gap = ti.max(gap, -_reach_past_ti(_row(p, k), _row(p_normals, k), q, n_q))
    for k in ti.static(range(q.n)):
        if k < n_q:
            gap = ti.max(gap, -_reach_past_ti(_row(q, k), _row(q_normals, k), p, n_p))
    return gap


@ti.func
def facing_gap_ti(p: ti.template(), p_normals: ti.template(), n_p, q: ti.template(), n_q, toward):
    """Taichi twin of :func:`polygon.facing_gap`, the outward unit normals of ``p``'s edges given
    (``edge_normals_ti``, or a body's turned ``vert_normal_local``)."""
    best = ti.math.dot(ti.math.vec2(p_normals[0, 0], p_normals[0, 1]), toward)
    a = ti.math.vec2(p[0, 0], p[0, 1])
    n = ti.math.vec2(p_normals[0, 0], p_normals[0, 1])
    for k in ti.static(range(1, p.n)):
        if k < n_p:
            nk = ti.math.vec2(p_normals[k, 0], p_normals[k, 1])
            along = ti.math.dot(nk, toward)
            if along > best:
                best = along
                a = ti.math.vec2(p[k, 0], p[k, 1])
                n = nk
    return -_reach_past_ti(a, n, q, n_q)


@ti.func
def _clip_ti(p: ti.template(), n_p, q: ti.template(), n_q):
    """Sutherland-Hodgman clipping of ``p`` by ``q`` (see :func:`polygon.intersection_polygon`).

    Returns:
        ``(buf, start, count)``: ``buf`` is a ``(2 (P + Q), 2)`` local matrix holding the
        intersection in rows ``start .. start + count - 1``. Clipping a convex polygon by a
        half-plane adds at most one vertex, so ``P + Q`` rows suffice; the two halves of
        ``buf`` are the ping-pong buffers of successive clips. Writes past ``P + Q`` (only
        possible through round-off on near-degenerate input) are dropped.
    """
    cap = ti.static(p.n + q.n)
    buf = ti.Matrix.zero(float, 2 * cap, 2)
    for k in range(n_p):
        buf[k, 0] = p[k, 0]
        buf[k, 1] = p[k, 1]
    src = 0
    count = n_p
    for e in range(n_q):
        c = _row(q, e)
        edge = _row(q, _after(e, n_q)) - c
        dst = cap - src
        out = 0
        # Edge (a, b) of the current polygon for k = 0 .. count - 1, b wrapping to the first
        # vertex; each vertex's side of the clip line is computed once.
        first = _row(buf, src)
        s_first = _cross_ti(edge, first - c)
        a = first
        sa = s_first
        for k in range(count):
            b = first
            sb = s_first
            if k + 1 < count:
                b = _row(buf, src + k + 1)
                sb = _cross_ti(edge, b - c)
            if (sa >= 0.0) != (sb >= 0.0):
                x = a + (sa / (sa - sb)) * (b - a)
                if out < cap:
                    buf[dst + out, 0] = x[0]
                    buf[dst + out, 1] = x[1]
                out += 1
            if sb >= 0.0:
                if out < cap:
                    buf[dst + out, 0] = b[0]
                    buf[dst + out, 1] = b[1]
                out += 1
            a = b
            sa = sb
        src = dst
        count = ti.min(out, cap)
    return buf, src, count


@ti.func
def _fan_step_ti(u, w, twice_area, moment):
    """A fan's triangle (its origin, ``u``, ``w``, relative to the origin) added to the sums of
    twice the area and of the first moment (times 6), as polygon._area_centroid sums them."""
    cr = _cross_ti(u, w)
    return twice_area + cr, moment + (u + w) * cr


@ti.func
def _fan_along_ti(poly: ti.template(), start, stop, n, origin, u, twice_area, moment):
    """The fan's triangles over ``poly``'s vertices after edge ``start`` up to the one that
    starts edge ``stop`` (``n`` vertices; none when they are equal), ``u`` the last vertex
    so far (relative to ``origin``); returns the last vertex and the sums."""
    last, area2, first = u, twice_area, moment
    k = start
    while k != stop:
        k = _after(k, n)
        w = _row(poly, k) - origin
        area2, first = _fan_step_ti(last, w, area2, first)
        last = w
    return last, area2, first


@ti.func
def overlap_ti(p: ti.template(), n_p, q: ti.template(), n_q):
    """Taichi twin of :func:`polygon.overlap`: :func:`overlap_normals_ti` with the polygons'
    edge normals computed here."""
    return overlap_normals_ti(p, edge_normals_ti(p, n_p), n_p, q, edge_normals_ti(q, n_q), n_q)


@ti.func
def overlap_normals_ti(
    p: ti.template(), p_normals: ti.template(), n_p, q: ti.template(), q_normals: ti.template(), n_q
):
    """Contact geometry of two convex polygons (the Taichi twin of :func:`polygon.overlap`), the
    outward unit normals of both polygons' edges given (``edge_normals_ti``, or a body's
    shape's normals turned).

    The contact kernel gathers the world-coordinate vertices of bodies i and j into local
    matrices (e.g. ``ti.Matrix.zero(float, MAXV, 2)`` filled row by row) and calls this.
    Shift both by a common nearby origin (e.g. body i's position) before the call when
    running in float32: the clip and the area lose digits in proportion to the size of the
    coordinates, not of the overlap.

    Args:
        p: ``ti.Matrix`` of static shape ``(P, 2)``; rows ``0 .. n_p - 1`` are a
            counter-clockwise convex polygon (m).
        p_normals: ``edge_normals_ti(p, n_p)``.
        n_p: number of vertices of ``p`` (3 <= n_p <= P).
        q: ``ti.Matrix`` of static shape ``(Q, 2)``, likewise (m).
        q_normals: ``edge_normals_ti(q, n_q)``.
        n_q: number of vertices of ``q`` (3 <= n_q <= Q).

    Returns:
        ``(area, centroid, normal, width, kind)``: area (m^2), centroid (2-vector, m),
        unit normal from ``p`` into ``q`` (2-vector), contact width (m) and kind
        (``OverlapKind.NONE``, ``CHORD`` or ``FALLBACK``), as in :class:`Overlap`;
        all zero for a separated pair.
    """
    area = 0.0
    centroid = ti.math.vec2(0.0, 0.0)
    normal = ti.math.vec2(0.0, 0.0)
    width = 0.0
    kind = OverlapKind.NONE
    # Where the two boundaries cross exactly twice, once where p's enters q (E) and once where
    # it leaves (X), the overlap is E, p's vertices after E's edge up to X's, X, and q's
    # vertices after X's edge up to E's: its area and centroid need no clip. The clip (and
    # the separating-axis test, for the fallback's axis) serve every other case, separated
    # pairs included (they do not cross): most of the engine's pairs here touch, as they
    # reached here past the test of the two edges that face each other.
    crossings = 0
    entering_count = 0
    enter = ti.math.vec2(0.0, 0.0)
    leave = ti.math.vec2(0.0, 0.0)
    enter_p, enter_q, leave_p, leave_q = 0, 0, 0, 0
    # Boundary crossings, by the rule of polygon.boundary_crossings().
    for j in range(n_q):
        c = _row(q, j)
        d = _row(q, _after(j, n_q))
        cd = d - c
        # Each vertex's side of q's edge line j once: the next edge's start is this
        # one's end (the twin's sa and sb).
        a = _row(p, 0)
        sa = _cross_ti(cd, a - c)
        first_side = sa
        for i in range(n_p):
            b = _row(p, _after(i, n_p))
            sb = first_side
            if i + 1 < n_p:
                sb = _cross_ti(cd, b - c)
            # Most edge pairs do not straddle each other's lines: test one first.
            if (sa > 0.0) != (sb > 0.0):
                ab = b - a
                tc = _cross_ti(ab, c - a)
                td = _cross_ti(ab, d - a)
                if (tc > 0.0) != (td > 0.0):
                    x = a + (sa / (sa - sb)) * ab
                    if sb > 0.0:
                        entering_count += 1
                        enter = x
                        enter_p, enter_q = i, j
                    else:
                        leave = x
                        leave_p, leave_q = i, j
                    crossings += 1
            a = b
            sa = sb
    chord = enter - leave
    chord_length = chord.norm()
    if crossings == 2 and entering_count == 1 and chord_length > 0.0:
        # Fan from E, as polygon._area_centroid fans from its first vertex.
        u, twice_area, moment = _fan_along_ti(
            p, enter_p, leave_p, n_p, enter, ti.math.vec2(0.0, 0.0), 0.0, ti.math.vec2(0.0, 0.0)
        )
        twice_area, moment = _fan_step_ti(u, leave - enter, twice_area, moment)
        u, twice_area, moment = _fan_along_ti(
            q, leave_q, enter_q, n_q, enter, leave - enter, twice_area, moment
        )
        if twice_area > 0.0:
            area = 0.5 * twice_area
            centroid = enter + moment / (3.0 * twice_area)
            kind = OverlapKind.CHORD
            width = chord_length
            normal = ti.math.vec2(-chord[1], chord[0]) / chord_length
    else:
        buf, start, count = _clip_ti(p, n_p, q, n_q)
        # Fan from the first vertex, as polygon._area_centroid does.
        origin = _row(buf, start)
        twice_area = 0.0
        moment = ti.math.vec2(0.0, 0.0)
        for k in range(1, count - 1):
            u = _row(buf, start + k) - origin
            w = _row(buf, start + k + 1) - origin
            cr = _cross_ti(u, w)
            twice_area += cr
            moment += (u + w) * cr
        if twice_area > 0.0:
            area = 0.5 * twice_area
            centroid = origin + moment / (3.0 * twice_area)
            kind = OverlapKind.FALLBACK
            _depth, axis = _min_penetration_axis_ti(p, p_normals, n_p, q, q_normals, n_q)
            normal = axis
            tangent = ti.math.vec2(-axis[1], axis[0])
            lo = ti.math.dot(tangent, origin)
            hi = lo
            for k in range(1, count):
                s = ti.math.dot(tangent, _row(buf, start + k))
                lo = ti.min(lo, s)
                hi = ti.max(hi, s)
            width = hi - lo
    return area, centroid, normal, width, kind


__all__ = [
    "edge_normals_ti",
    "facing_gap_ti",
    "min_penetration_axis_ti",
    "overlap_normals_ti",
    "overlap_ti",
    "rotation_ti",
    "sat_separated_ti",
    "separation_gap_ti",
]
