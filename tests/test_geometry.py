"""Polygon geometry: overlap, clipping, SAT and mass properties against shapely and symmetry.

Shapely (GEOS) is the independent reference: it shares no code with ``taichi_ice.physics.polygon``.
The Taichi functions are held against the NumPy reference on the same seeded random pairs.
"""

import numpy as np
import pytest
import shapely
from shapely.geometry import MultiPoint, Point, Polygon

from taichi_ice.codes import OverlapKind
from taichi_ice.errors import PolygonError
from taichi_ice.physics.batched import overlap_batch_ti, rotation_batch_ti
from taichi_ice.physics.polygon import (
    check_polygon,
    diamond,
    facing_gap,
    facing_separated,
    intersection_polygon,
    mass_properties,
    min_penetration_axis,
    min_width,
    overlap,
    rectangle,
    rotation,
    sat_separated,
    separation_gap,
    transform,
)

N_PAIRS = 3000  # seeded random pairs; about two thirds overlap
MAXV = 8  # largest random polygon, and the padded size handed to the Taichi kernel
SEED = 20240611

# Shapely works with its own vertex order and arithmetic, so the two agree to round-off
# relative to the polygon size (areas ~1 m^2, coordinates ~5 m): 1e-10 leaves two orders of
# magnitude over the largest error seen (~1e-13), while any real mistake is O(1).
SHAPELY_RTOL = 1e-10
# Identical formulas evaluated in a different order (Taichi/LLVM vs NumPy): a few ulps of the
# coordinates, amplified by at most the conditioning of a chord crossing.
TI_RTOL_F64 = 1e-12
# float32 inputs are rounded before both computations; what is left is f32 round-off in the
# clip and the fan sums, relative to coordinates ~5 m.
TI_RTOL_F32 = 2e-4
# A pair whose SAT depth is this close to zero (relative to its size) is touching within
# round-off: shapely may call it intersecting with zero area; SAT need not agree there.
TOUCH_RTOL = 1e-12


def random_convex(rng: np.random.Generator, centre: np.ndarray) -> np.ndarray:
    """A strictly convex CCW polygon of 3..MAXV vertices on a random rotated ellipse (m)."""
    n = int(rng.integers(3, MAXV + 1))
    while True:
        angles = np.sort(rng.uniform(0.0, 2.0 * np.pi, n))
        gaps = np.diff(np.append(angles, angles[0] + 2.0 * np.pi))
        # Gaps wide enough that no vertex is nearly collinear (check_polygon would refuse it).
        if gaps.min() > 0.2:
            break
    semi = rng.uniform(0.3, 1.5, 2)
    local = np.stack([semi[0] * np.cos(angles), semi[1] * np.sin(angles)], axis=1)
    return check_polygon(transform(local, centre, rng.uniform(0.0, 2.0 * np.pi)))


def _pad(polys: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Stack polygons into a zero-padded ``(B, MAXV, 2)`` array and their ``(B,)`` counts."""
    out = np.zeros((len(polys), MAXV, 2))
    for b, v in enumerate(polys):
        out[b, : len(v)] = v
    return out, np.array([len(v) for v in polys])


@pytest.fixture(scope="module")
def pairs() -> list[tuple[np.ndarray, np.ndarray]]:
    """Seeded random convex pairs around (3, -2) m, overlapping or not."""
    rng = np.random.default_rng(SEED)
    out = []
    for _ in range(N_PAIRS):
        c = np.array([3.0, -2.0]) + rng.uniform(-1.0, 1.0, 2)
        offset = rng.uniform(0.0, 2.5) * np.array([np.cos(a := rng.uniform(0, 7)), np.sin(a)])
        out.append((random_convex(rng, c), random_convex(rng, c + offset)))
    return out


@pytest.fixture(scope="module")
def reference(pairs):
    """NumPy overlap and shapely's intersection for every pair."""
    ours = [overlap(p, q) for p, q in pairs]
    theirs = [Polygon(p).intersection(Polygon(q)) for p, q in pairs]
    return ours, theirs


@pytest.fixture(scope="module")
def batch(pairs, taichi_runtime):
    """Taichi overlap_batch_ti on every pair, and the inputs rounded to its precision."""
    real = np.float64 if taichi_runtime[1] == "f64" else np.float32
    p, n_p = _pad([p for p, _ in pairs])
    q, n_q = _pad([q for _, q in pairs])
    p, q = p.astype(real), q.astype(real)
    rounded = [(p[b, : n_p[b]].astype(float), q[b, : n_q[b]].astype(float)) for b in range(len(p))]
    return overlap_batch_ti(p, n_p, q, n_q), rounded


def _ti_rtol(taichi_runtime) -> float:
    return TI_RTOL_F64 if taichi_runtime[1] == "f64" else TI_RTOL_F32


def _assert_area_centroid(label, areas, centroids, pairs, shapes, rtol):
    """Area and first moment (area * centroid) against shapely, relative to the pair's size."""
    worst_area = worst_moment = 0.0
    for area, centroid, (p, q), ref in zip(areas, centroids, pairs, shapes):
        scale = min(mass_properties(p)[0], mass_properties(q)[0])
        err_area = abs(area - ref.area) / scale
        # The centroid of a sliver is ill-conditioned; its first moment is not.
        ref_c = np.array(ref.centroid.coords[0]) if ref.area > 0 else np.zeros(2)
        err_moment = np.max(np.abs(area * np.asarray(centroid) - ref.area * ref_c))
        err_moment /= scale * np.sqrt(scale)
        worst_area, worst_moment = max(worst_area, err_area), max(worst_moment, err_moment)
    print(f"{label}: max area error {worst_area:.2e}, max moment error {worst_moment:.2e} (rel)")
    assert worst_area < rtol
    assert worst_moment < rtol


def test_numpy_overlap_area_and_centroid_match_shapely(pairs, reference):
    """The clipped area and contact point equal shapely's intersection on random pairs."""
    ours, theirs = reference
    assert sum(o.area > 0 for o in ours) > N_PAIRS // 2
    _assert_area_centroid(
        "numpy",
        [o.area for o in ours],
        [o.centroid for o in ours],
        pairs,
        theirs,
        SHAPELY_RTOL,
    )


def test_intersection_polygon_matches_shapely(pairs, reference):
    """The clipped polygon covers exactly shapely's intersection (symmetric difference ~ 0)."""
    worst = 0.0
    for (p, q), ref in zip(pairs[:500], reference[1][:500]):
        clipped = intersection_polygon(p, q)
        if len(clipped) < 3 or ref.area == 0.0:
            continue
        ours = Polygon(clipped)
        worst = max(worst, ours.symmetric_difference(ref).area / ref.area)
    print(f"intersection_polygon: max symmetric difference {worst:.2e} of the area")
    assert worst < 1e-8


def test_taichi_overlap_area_and_centroid_match_shapely(batch, taichi_runtime):
    """overlap_ti's area and contact point equal shapely's intersection on random pairs."""
    result, rounded = batch
    shapes = [Polygon(p).intersection(Polygon(q)) for p, q in rounded]
    rtol = max(SHAPELY_RTOL, _ti_rtol(taichi_runtime))
    _assert_area_centroid("taichi", result.area, result.centroid, rounded, shapes, rtol)


def _shapely_crossings(p: np.ndarray, q: np.ndarray) -> np.ndarray | None:
    """Points where the boundaries cross, from shapely; None if they share a segment."""
    hit = Polygon(p).exterior.intersection(Polygon(q).exterior)
    if hit.is_empty:
        return np.zeros((0, 2))
    if isinstance(hit, Point):
        return np.array(hit.coords)
    if isinstance(hit, MultiPoint):
        return np.array([g.coords[0] for g in hit.geoms])
    return None


def test_chord_endpoints_match_shapely_boundary_crossings(pairs, reference):
    """A chord contact's width and normal come from the two points where the boundaries cross."""
    ours = reference[0]
    n_chord = 0
    for (p, q), ov in zip(pairs, ours):
        if ov.area == 0.0:
            continue
        ref = _shapely_crossings(p, q)
        assert ref is not None  # random pairs share no edge segment
        if len(ref) != 2:
            assert ov.kind == OverlapKind.FALLBACK
            continue
        assert ov.kind == OverlapKind.CHORD
        n_chord += 1
        size = np.sqrt(min(mass_properties(p)[0], mass_properties(q)[0]))
        chord = ref[1] - ref[0]
        assert ov.width == pytest.approx(np.hypot(*chord), abs=SHAPELY_RTOL * size)
        assert abs(ov.normal @ chord) < SHAPELY_RTOL * size
        assert np.hypot(*ov.normal) == pytest.approx(1.0, abs=1e-14)
        # Out of p into q: p's boundary inside q lies ahead of the chord, q's behind it.
        mid = 0.5 * (ref[0] + ref[1])
        for v in p:
            if Polygon(q).contains(Point(v)):
                assert (v - mid) @ ov.normal > -SHAPELY_RTOL * size
        for v in q:
            if Polygon(p).contains(Point(v)):
                assert (v - mid) @ ov.normal < SHAPELY_RTOL * size
    assert n_chord > N_PAIRS // 3


def test_sat_agrees_with_shapely_on_random_pairs(pairs, reference):
    """SAT separates a pair exactly when shapely's intersection has no area (off exact touching)."""
    for (p, q), shape in zip(pairs, reference[1]):
        depth, axis = min_penetration_axis(p, q)
        size = np.sqrt(min(mass_properties(p)[0], mass_properties(q)[0]))
        if abs(depth) < TOUCH_RTOL * size:
            continue
        assert sat_separated(p, q) == (shape.area == 0.0)
        assert sat_separated(p, q) == (not Polygon(p).intersects(Polygon(q)))
        assert np.hypot(*axis) == pytest.approx(1.0, abs=1e-14)
        if depth <= 0.0:
            # Moving q along the axis by the gap (a no-op or an approach) keeps them apart.
            assert shapely.distance(Polygon(p), Polygon(q)) >= -depth * (1 - 1e-9)
        else:
            # Moving q by the depth along the axis leaves them just touching.
            moved = Polygon(q + (depth * (1 + 1e-9)) * axis)
            assert Polygon(p).intersection(moved).area < 1e-9 * size**2


def _toward(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """q's vertex mean seen from p's (the direction overlap_batch_ti hands the facing test)."""
    return q.mean(axis=0) - p.mean(axis=0)


def test_facing_edge_never_separates_a_touching_pair(pairs, reference):
    """A facing edge said to separate proves the pair apart (shapely: no intersection), and
    with both polygons' facing edges it settles most of the pairs that shapely finds apart."""
    settled = apart = 0
    for (p, q), shape in zip(pairs, reference[1]):
        size = np.sqrt(min(mass_properties(p)[0], mass_properties(q)[0]))
        if abs(min_penetration_axis(p, q)[0]) < TOUCH_RTOL * size:
            continue
        either = facing_separated(p, q, _toward(p, q)) or facing_separated(q, p, _toward(q, p))
        if either:
            assert shape.area == 0.0 and not Polygon(p).intersects(Polygon(q))
            # The gap it proves is a lower bound of the distance between the polygons (what
            # the contact step relies on to skip the pair while both move less than it).
            gap = max(facing_gap(p, q, _toward(p, q)), facing_gap(q, p, _toward(q, p)))
            assert 0.0 <= gap <= Polygon(p).distance(Polygon(q)) * (1 + SHAPELY_RTOL) + 1e-12
        if shape.area == 0.0:
            apart += 1
            settled += either
    print(f"facing edges settle {settled} of {apart} separated pairs")
    # Random polygons of 3 to 8 vertices, 0 to 2.5 m apart: a sufficient test, not a complete
    # one, that still decides most (99 % of the random box's near misses of diamonds).
    assert apart > N_PAIRS // 10
    assert settled > 0.8 * apart


def test_taichi_facing_edge_equals_its_numpy_twin(batch, taichi_runtime):
    """facing_gap_ti gives facing_gap's gap, and so facing_separated's verdict, on random
    pairs (the verdict off touching)."""
    result, rounded = batch
    rtol = _ti_rtol(taichi_runtime)
    checked = 0
    for b, (p, q) in enumerate(rounded):
        size = np.sqrt(min(mass_properties(p)[0], mass_properties(q)[0]))
        normals = np.array([[e[1], -e[0]] for e in np.roll(p, -1, axis=0) - p])
        normals /= np.hypot(normals[:, 0], normals[:, 1])[:, None]
        k = int(np.argmax(normals @ _toward(p, q)))
        reach = -np.min((q - p[k]) @ normals[k])
        if abs(reach) < rtol * size:
            continue
        assert result.facing[b] == facing_separated(p, q, _toward(p, q))
        assert result.facing_gap[b] == pytest.approx(reach * -1.0, abs=rtol * size)
        assert facing_gap(p, q, _toward(p, q)) == pytest.approx(-reach, abs=1e-12 * size)
        checked += 1
    assert checked > 0.9 * N_PAIRS


def test_separation_gap_bounds_the_distance_and_its_sign_is_the_sat_verdict(pairs, reference):
    """Every edge normal of both polygons tried: a gap >= 0 proves the pair apart (shapely: no
    intersection) and is at most their distance, which the contact step relies on to skip a
    pair while both move less; a negative one is minus the smallest penetration; and it
    settles every separated pair, where the facing edges settle most."""
    apart = beyond_facing = 0
    for (p, q), shape in zip(pairs, reference[1]):
        size = np.sqrt(min(mass_properties(p)[0], mass_properties(q)[0]))
        depth = min_penetration_axis(p, q)[0]
        if abs(depth) < TOUCH_RTOL * size:
            continue
        gap = separation_gap(p, q)
        assert (gap >= 0.0) == (shape.area == 0.0) == (not Polygon(p).intersects(Polygon(q)))
        if gap >= 0.0:
            apart += 1
            distance = Polygon(p).distance(Polygon(q))
            assert gap <= distance * (1 + SHAPELY_RTOL) + 1e-12
            facing = max(facing_gap(p, q, _toward(p, q)), facing_gap(q, p, _toward(q, p)))
            assert gap >= facing
            beyond_facing += facing < 0.0
        else:
            assert gap == pytest.approx(-depth, rel=1e-12)
    print(f"{beyond_facing} of {apart} separated pairs are settled only past the facing edges")
    assert apart > N_PAIRS // 10
    assert beyond_facing > 0


def test_taichi_separation_gap_equals_its_numpy_twin(batch, taichi_runtime):
    """separation_gap_ti gives separation_gap's gap on random pairs, to round-off."""
    result, rounded = batch
    rtol = _ti_rtol(taichi_runtime)
    for b, (p, q) in enumerate(rounded):
        size = np.sqrt(min(mass_properties(p)[0], mass_properties(q)[0]))
        assert result.separation_gap[b] == pytest.approx(separation_gap(p, q), abs=rtol * size)


def test_taichi_matches_numpy_on_random_pairs(batch, taichi_runtime):
    """overlap_ti and its SAT twins give the NumPy reference's fields on random pairs."""
    result, rounded = batch
    rtol = _ti_rtol(taichi_runtime)
    worst = {"area": 0.0, "centroid": 0.0, "normal": 0.0, "width": 0.0}
    n_kind_differs = 0
    for b, (p, q) in enumerate(rounded):
        ov = overlap(p, q)
        depth, _axis = min_penetration_axis(p, q)
        size = np.sqrt(min(mass_properties(p)[0], mass_properties(q)[0]))
        if abs(depth) > rtol * size:
            assert result.separated[b] == (depth <= 0.0)
            assert result.depth[b] == pytest.approx(depth, abs=rtol * size)
        if result.kind[b] != ov.kind:
            # Only a pair at a classification edge (touching, or a crossing at a vertex) may
            # flip, and only in float32.
            n_kind_differs += 1
            continue
        if ov.kind == OverlapKind.NONE:
            continue
        worst["area"] = max(worst["area"], abs(result.area[b] - ov.area) / size**2)
        worst["centroid"] = max(
            worst["centroid"], np.max(np.abs(result.centroid[b] - ov.centroid)) * ov.area / size**3
        )
        if ov.kind == OverlapKind.CHORD:
            # The normal of a short chord turns by (endpoint error / width): compare the
            # endpoint displacement this implies.
            turn = np.max(np.abs(result.normal[b] - ov.normal)) * ov.width / size
            worst["normal"] = max(worst["normal"], turn)
            worst["width"] = max(worst["width"], abs(result.width[b] - ov.width) / size)
    print(f"taichi vs numpy ({taichi_runtime[1]}): {worst}, kinds differ on {n_kind_differs}")
    assert n_kind_differs <= (0 if taichi_runtime[1] == "f64" else N_PAIRS // 100)
    for name, err in worst.items():
        assert err < rtol, name


def _square_into_face():
    """A 1 m square pressed 0.1 m face-on into the top face of a 4 m square."""
    return rectangle(4.0, 4.0), transform(rectangle(1.0, 1.0), [0.3, 2.4], 0.0)


HAND_CASES = {
    # name: (p, q, area, centroid, normal, width, kind)
    "square face-on": (
        *_square_into_face(),
        0.1,
        [0.3, 1.95],
        [0.0, 1.0],
        1.0,
        OverlapKind.CHORD,
    ),
    "diamond corner into a face": (
        rectangle(4.0, 4.0),
        transform(diamond(1.0, 1.0), [-0.5, 2.4], 0.0),
        # A right isosceles triangle of height 0.1 m: base 0.2 m, area 0.01 m^2.
        0.01,
        [-0.5, 2.0 - 0.1 / 3.0],
        [0.0, 1.0],
        0.2,
        OverlapKind.CHORD,
    ),
    "containment": (
        rectangle(4.0, 4.0),
        transform(rectangle(1.0, 0.5), [1.0, 0.2], 0.0),
        # Shortest way out of the big square: 1.5 m to the right, across which q is 0.5 m.
        0.5,
        [1.0, 0.2],
        [1.0, 0.0],
        0.5,
        OverlapKind.FALLBACK,
    ),
    "touching edges": (
        rectangle(2.0, 2.0),
        transform(rectangle(2.0, 2.0), [2.0, 0.5], 0.0),
        0.0,
        [0.0, 0.0],
        [0.0, 0.0],
        0.0,
        OverlapKind.NONE,
    ),
    "collinear faces, overlapping": (
        rectangle(2.0, 2.0),
        transform(rectangle(2.0, 2.0), [1.9, 0.0], 0.0),
        # Top and bottom edges coincide: no clean crossing, the SAT axis gives the face normal.
        0.2,
        [0.95, 0.0],
        [1.0, 0.0],
        2.0,
        OverlapKind.FALLBACK,
    ),
    "eight crossings": (
        rectangle(2.0, 2.0),
        diamond(2.4, 2.4),
        # The diamond's corners poke 0.2 m out of each face: the square loses four corner
        # triangles of legs 0.8 m. Least penetration: 2.2 m across p's first (bottom) edge.
        4.0 - 4 * 0.32,
        [0.0, 0.0],
        [0.0, -1.0],
        2.0,
        OverlapKind.FALLBACK,
    ),
    "identical": (
        diamond(2.0, 1.0),
        diamond(2.0, 1.0),
        # Every edge is a tie; the first edge of p wins: normal of edge (1,0)->(0,0.5).
        1.0,
        [0.0, 0.0],
        [1.0 / np.sqrt(1.25) * 0.5, 1.0 / np.sqrt(1.25)],
        # Extent of the diamond across that normal, between the x corners: 2 / sqrt(1.25).
        2.0 / np.sqrt(1.25),
        OverlapKind.FALLBACK,
    ),
}


@pytest.mark.parametrize("name", list(HAND_CASES))
def test_overlap_hand_cases(name, taichi_runtime):
    """Face-on, corner, containment, touching, collinear, multi-crossing, identical: as by hand."""
    p, q, area, centroid, normal, width, kind = HAND_CASES[name]
    ov = overlap(p, q)
    assert ov.kind == kind
    assert ov.area == pytest.approx(area, abs=1e-12)
    np.testing.assert_allclose(ov.centroid, centroid, atol=1e-12)
    np.testing.assert_allclose(ov.normal, normal, atol=1e-12)
    assert ov.width == pytest.approx(width, abs=1e-12)
    # Same answers from the Taichi twin (float32 rounds the inputs and the answer).
    tol = 1e-12 if taichi_runtime[1] == "f64" else 1e-5
    pp, n_p = _pad([p])
    qq, n_q = _pad([q])
    ti_ov = overlap_batch_ti(pp, n_p, qq, n_q)
    assert ti_ov.kind[0] == kind
    assert ti_ov.area[0] == pytest.approx(area, abs=tol)
    np.testing.assert_allclose(ti_ov.centroid[0], centroid, atol=tol)
    np.testing.assert_allclose(ti_ov.normal[0], normal, atol=tol)
    assert ti_ov.width[0] == pytest.approx(width, abs=tol)


def _lattice_pairs(count: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Seeded convex polygons with integer vertices, offset by integers: their vertices meet,
    lie on each other's edges and their edges overlap exactly, in float64 and float32."""
    rng = np.random.default_rng(SEED + 2)

    def lattice_polygon():
        while True:
            hull = MultiPoint(rng.integers(0, 5, size=(MAXV, 2)).astype(float)).convex_hull
            if hull.geom_type == "Polygon":
                # GEOS drops collinear points; orient counter-clockwise.
                ring = shapely.geometry.polygon.orient(hull, 1.0).exterior.coords
                return check_polygon(np.array(ring)[:-1])

    return [
        (lattice_polygon(), lattice_polygon() + rng.integers(-4, 5, size=2)) for _ in range(count)
    ]


def test_overlap_of_lattice_polygons_matches_shapely_and_its_twin(taichi_runtime):
    """Where vertices meet and edges touch or lie on one another, the chord's walk and the
    clip give shapely's area and centroid, and the Taichi twin the same kind and numbers."""
    pairs = _lattice_pairs(1500)
    ours = [overlap(p, q) for p, q in pairs]
    kinds = [sum(o.kind == k for o in ours) for k in OverlapKind]
    print(f"lattice pairs: {dict(zip([k.name for k in OverlapKind], kinds))}")
    assert min(kinds) > 100  # every case met, chords through vertices among them
    shapes = [Polygon(p).intersection(Polygon(q)) for p, q in pairs]
    _assert_area_centroid(
        "numpy", [o.area for o in ours], [o.centroid for o in ours], pairs, shapes, SHAPELY_RTOL
    )
    # Integers are exact in float32 too: every side test, hence every kind, is the same.
    pp, n_p = _pad([p for p, _ in pairs])
    qq, n_q = _pad([q for _, q in pairs])
    result = overlap_batch_ti(pp, n_p, qq, n_q)
    np.testing.assert_array_equal(result.kind, [o.kind for o in ours])
    rtol = max(SHAPELY_RTOL, _ti_rtol(taichi_runtime))
    _assert_area_centroid("taichi", result.area, result.centroid, pairs, shapes, rtol)
    chord = result.kind == OverlapKind.CHORD
    np.testing.assert_allclose(
        result.width[chord], [o.width for o, c in zip(ours, chord) if c], rtol=rtol
    )


def test_face_on_width_and_area_follow_the_depth():
    """A square pressed face-on by depth d overlaps side * d, width = side, face normal."""
    side = 0.7
    for depth in (1e-6, 1e-3, 0.05, 0.3):
        q = transform(rectangle(side, side), [0.2, 2.0 + 0.5 * side - depth], 0.0)
        ov = overlap(rectangle(4.0, 4.0), q)
        assert ov.kind == OverlapKind.CHORD
        assert ov.area == pytest.approx(side * depth, rel=1e-9)
        assert ov.width == pytest.approx(side, rel=1e-12)
        np.testing.assert_allclose(ov.normal, [0.0, 1.0], atol=1e-12)


def test_chord_tends_to_the_fallback_at_collinear_faces():
    """Near-collinear faces give a chord within depth/width rad of the fallback's face normal."""
    side, depth = 2.0, 0.01
    p = rectangle(side, side)
    collinear = overlap(p, transform(p, [side - depth, 0.0], 0.0))
    assert collinear.kind == OverlapKind.FALLBACK
    for shift in (1e-3, 1e-6, 1e-9):
        near = overlap(p, transform(p, [side - depth, shift], 0.0))
        assert near.kind == OverlapKind.CHORD
        assert near.area == pytest.approx(collinear.area, abs=depth * shift * 1.01)
        assert np.max(np.abs(near.normal - collinear.normal)) < 1.01 * depth / side
        # The overlap itself is shorter by the shift; the chord adds (d / w)^2 / 2.
        assert near.width == pytest.approx(collinear.width, rel=(depth / side) ** 2 + shift)


def test_overlap_is_antisymmetric_in_its_arguments(pairs, reference):
    """overlap(q, p) has the same area, centroid and width as overlap(p, q), opposite normal."""
    for (p, q), ov in zip(pairs[:1000], reference[0][:1000]):
        vo = overlap(q, p)
        size = np.sqrt(min(mass_properties(p)[0], mass_properties(q)[0]))
        assert vo.kind == ov.kind
        assert vo.area == pytest.approx(ov.area, abs=SHAPELY_RTOL * size**2)
        assert ov.area * np.max(np.abs(vo.centroid - ov.centroid)) < SHAPELY_RTOL * size**3
        if ov.kind == OverlapKind.CHORD:
            assert vo.width == pytest.approx(ov.width, abs=SHAPELY_RTOL * size)
            np.testing.assert_allclose(vo.normal, -ov.normal, atol=SHAPELY_RTOL)


def test_overlap_follows_a_rigid_motion_of_both_polygons(pairs, reference):
    """Rotating and translating both polygons rotates and translates the contact, nothing else."""
    rng = np.random.default_rng(SEED + 1)
    for (p, q), ov in zip(pairs[:1000], reference[0][:1000]):
        angle, shift = rng.uniform(0.0, 2.0 * np.pi), rng.uniform(-20.0, 20.0, 2)
        rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        moved = overlap(transform(p, shift, angle), transform(q, shift, angle))
        size = np.sqrt(min(mass_properties(p)[0], mass_properties(q)[0]))
        # Coordinates grow to ~25 m, so round-off grows with them.
        tol = 100 * SHAPELY_RTOL
        assert moved.kind == ov.kind
        assert moved.area == pytest.approx(ov.area, abs=tol * size**2)
        if ov.kind == OverlapKind.NONE:
            continue
        assert (
            ov.area * np.max(np.abs(moved.centroid - (rot @ ov.centroid + shift))) < tol * size**3
        )
        if ov.kind == OverlapKind.CHORD:
            assert moved.width == pytest.approx(ov.width, abs=tol * size)
            np.testing.assert_allclose(moved.normal, rot @ ov.normal, atol=tol)


def test_mass_properties_match_shapely(pairs):
    """Polygon area and centroid equal shapely's; the polar moment equals a fine quadrature."""
    for p, _ in pairs[:300]:
        area, centroid, _polar = mass_properties(p)
        shape = Polygon(p)
        assert area == pytest.approx(shape.area, rel=1e-12)
        np.testing.assert_allclose(centroid, shape.centroid.coords[0], atol=1e-12)
    # A w x l rectangle has J = A (w^2 + l^2) / 12 about its centroid, wherever it is.
    area, centroid, polar = mass_properties(transform(rectangle(2.0, 0.5), [3.0, -1.0], 0.7))
    assert polar == pytest.approx(1.0 * (4.0 + 0.25) / 12.0, rel=1e-12)
    np.testing.assert_allclose(centroid, [3.0, -1.0], atol=1e-12)


@pytest.mark.parametrize(
    ("vertices", "message"),
    [
        ([[0, 0], [0, 1], [1, 1], [1, 0]], "clockwise"),
        ([[0, 0], [2, 0], [2, 2], [1, 1], [0, 2]], "reflex"),
        ([[0, 0], [1, 0], [2, 0], [2, 2], [0, 2]], "collinear"),
        ([[0, 0], [1, 0]], "at least 3 vertices"),
        ([[0, 0], [1, 0], [np.nan, 1]], "finite"),
        ([[0, 0], [1, 1], [2, 2]], "zero area"),
        ([[0, 0], [1, 0], [1, 0], [1, 1]], "repeated"),
        ("square", "list of [x, y]"),
    ],
)
def test_check_polygon_names_the_problem(vertices, message):
    """check_polygon refuses a bad outline with a message that says what is wrong."""
    with pytest.raises(PolygonError, match=message.replace("[", r"\[").replace("]", r"\]")):
        check_polygon(vertices, what="body 'floe'")
    with pytest.raises(PolygonError, match="body 'floe'"):
        check_polygon(vertices, what="body 'floe'")


def test_check_polygon_accepts_the_library_shapes():
    """Rectangles and diamonds from this module are valid floes."""
    for v in (rectangle(2.0, 1.0), diamond(0.7, 1.0), transform(diamond(1.0, 2.0), [5, 5], 1.0)):
        np.testing.assert_array_equal(check_polygon(v), v)


def test_min_width_is_the_least_caliper_width(pairs):
    """min_width equals the smallest extent over a dense sweep of directions (a brute-force
    caliper that does not know the width is attained across an edge), and is exact for the
    paper's diamond: twice the distance from its centre to a face."""
    theta = np.linspace(0.0, np.pi, 200_001)
    u = np.stack([np.cos(theta), np.sin(theta)])
    for p, _ in pairs[:50]:
        proj = p @ u
        caliper = float(np.min(proj.max(axis=0) - proj.min(axis=0)))
        # The width has a kink at its minimum (an edge's normal), so a sweep that misses that
        # direction by up to dtheta = pi / 2e5 overestimates by up to ~diameter * dtheta.
        diameter = np.max(np.linalg.norm(p[:, None] - p[None], axis=-1))
        assert caliper - diameter * np.pi / 2e5 <= min_width(p) <= caliper + 1e-12
    assert min_width(diamond(0.7, 1.0)) == pytest.approx(0.7 * 1.0 / np.hypot(0.7, 1.0), rel=1e-14)
    assert min_width(rectangle(5.5, 0.4)) == pytest.approx(0.4, rel=1e-14)


# libm's cos and sin are within half an ulp; the rotation's reduction and polynomials add at
# most as much again: one ulp of 1 (2.2e-16) in absolute terms, where |cos|, |sin| <= 1.
ROTATION_ATOL = 2.3e-16


def _angles() -> np.ndarray:
    """Seeded angles (rad): one turn, spinning bodies' thousands of turns, past the exact
    reduction (the libm fallback), and the multiples of pi/4 where the quadrants meet."""
    rng = np.random.default_rng(SEED)
    return np.concatenate(
        [
            rng.uniform(-4.0, 4.0, 20000),
            rng.uniform(-1e5, 1e5, 20000),
            rng.uniform(-1e7, 1e7, 200),
            np.arange(-40, 41) * (np.pi / 4),
            [0.0, -0.0, 1e-300, -1e-300],
        ]
    )


def test_rotation_matches_libm_cos_and_sin():
    """The step's cos and sin (fdlibm's reduction and polynomials) are libm's to an ulp of 1."""
    x = _angles()
    c, s = rotation(x)
    np.testing.assert_allclose(c, np.cos(x), rtol=0, atol=ROTATION_ATOL)
    np.testing.assert_allclose(s, np.sin(x), rtol=0, atol=ROTATION_ATOL)
    # A rotation: unit length to round-off.
    np.testing.assert_allclose(np.hypot(c, s), 1.0, rtol=0, atol=4 * ROTATION_ATOL)


def test_taichi_rotation_equals_its_numpy_twin_bit_for_bit(taichi_runtime):
    """rotation_ti evaluates the same operations as rotation: the same bits."""
    if taichi_runtime[1] != "f64":
        pytest.skip("rotation_ti is the float64 step's (float32 uses ti.cos and ti.sin)")
    from taichi_ice import backend

    x = _angles()
    got = rotation_batch_ti(x)
    # On Vulkan and Metal an angle past ROTATION_REDUCED_MAX is reduced by whole turns
    # instead of handed to libm (they have no float64 cos): the twin does the same.
    c, s = rotation(x, portable=backend.portable_f64())
    if backend.actual_arch() in (*backend.SPIRV_ARCHES, "cuda"):
        # SPIR-V lets the driver fuse a multiply and an add (Taichi marks no NoContraction),
        # and Mesa's lavapipe does: 13 % of these angles differ from the twin by an ulp of 1.
        # LLVM's NVPTX contracts them too, with Taichi's fast math off: on an H100 (driver
        # 580.159, 2026-11-26) cos differed by an ulp in 377 of 40,285 angles. Within an ulp
        # there; bit for bit is a strict expected failure (as test_fmath's).
        np.testing.assert_allclose(got[:, 0], c, rtol=0, atol=2.3e-16)
        np.testing.assert_allclose(got[:, 1], s, rtol=0, atol=2.3e-16)
        equal = np.array_equal(got[:, 0], c) and np.array_equal(got[:, 1], s)
        assert not equal, f"bit for bit on {backend.actual_arch()} now: drop this xfail"
        pytest.xfail("the device's compiler fused multiply-adds (within an ulp, checked above)")
    np.testing.assert_array_equal(got[:, 0], c)
    np.testing.assert_array_equal(got[:, 1], s)


def test_the_portable_rotation_of_far_angles_is_within_their_own_round_off():
    """On Vulkan and Metal an angle beyond ROTATION_REDUCED_MAX is reduced by whole turns in
    float64 (no libm there): the result is within the angle's own round-off (|x| eps) of
    NumPy's cos and sin, which reduce exactly."""
    x = _angles()
    c, s = rotation(x, portable=True)
    bound = 2.3e-16 + 2.0 * np.abs(x) * np.finfo(np.float64).eps
    assert np.all(np.abs(c - np.cos(x)) <= bound)
    assert np.all(np.abs(s - np.sin(x)) <= bound)


def test_geometry_still_names_the_polygon_functions_and_their_twins():
    """``taichi_ice.geometry`` (README's public name) re-exports ``polygon`` and ``polygon_ti``."""
    from taichi_ice import geometry
    from taichi_ice.physics import polygon, polygon_ti

    assert geometry.overlap is polygon.overlap
    assert geometry.check_polygon is polygon.check_polygon
    assert geometry.overlap_ti is polygon_ti.overlap_ti
    assert geometry.rotation_ti is polygon_ti.rotation_ti
