"""taichi_ice.scene.tessellation: power and Voronoi diagrams, weights for prescribed areas,
seed disks, hulls and simplification, held against shapely and brute force.

References are independent of the code under test: shapely's Voronoi diagram, convex hull,
areas and predicates, and the power distance minimised point by point.
"""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from shapely.geometry import MultiPoint, Polygon

from taichi_ice.scene import tessellation as tess

REGION = np.array([[0.0, 0.0], [120.0, 0.0], [120.0, 80.0], [0.0, 80.0]])
# A convex hexagonal region, not axis-aligned.
HEXAGON = np.array([[10.0, 0.0], [90.0, 5.0], [110.0, 50.0], [80.0, 95.0], [5.0, 90.0], [-8, 40]])
# Areas and coordinates are sums of a few float64 products of numbers of order 100: round-off.
AREA_RTOL = 1e-10
# Newton stops below this relative area error (tessellation.balance_weights' default).
BALANCE_RTOL = 1e-9


def random_sites(rng, region, n):
    """``n`` sites uniform in the convex ``region``."""
    shape = Polygon(region)
    lo, hi = region.min(axis=0), region.max(axis=0)
    out = []
    while len(out) < n:
        p = lo + (hi - lo) * rng.random(2)
        if shape.contains(shapely.Point(p)):
            out.append(p)
    return np.array(out)


def assert_tiles(cells, region) -> None:
    """The cells are convex, do not overlap, and cover the region (shapely)."""
    polys = [Polygon(c) for c in cells if len(c)]
    for p in polys:
        assert p.is_valid and p.exterior.is_ccw
        assert p.convex_hull.area == pytest.approx(p.area, rel=AREA_RTOL)
    total = Polygon(region).area
    assert sum(p.area for p in polys) == pytest.approx(total, rel=AREA_RTOL)
    assert shapely.union_all(polys).area == pytest.approx(total, rel=AREA_RTOL)


@pytest.mark.parametrize("region", [REGION, HEXAGON], ids=["rectangle", "hexagon"])
def test_voronoi_cells_are_shapelys(region):
    """With zero weights the cells are shapely's Voronoi diagram clipped to the region."""
    rng = np.random.default_rng(5)
    sites = random_sites(rng, region, 150)
    cells, labels = tess.power_cells(sites, np.zeros(len(sites)), region)
    assert_tiles(cells, region)
    box = Polygon(region)
    reference = shapely.voronoi_polygons(MultiPoint(sites), extend_to=box.buffer(200.0))
    for part in reference.geoms:
        clipped = part.intersection(box)
        (inside,) = [i for i, s in enumerate(sites) if part.contains(shapely.Point(s))]
        got = Polygon(cells[inside])
        assert got.symmetric_difference(clipped).area <= AREA_RTOL * clipped.area
    # Each edge names the site across it, or -1 on the region's boundary.
    for i, (cell, names) in enumerate(zip(cells, labels)):
        for k, j in enumerate(names):
            mid = 0.5 * (cell[k] + cell[(k + 1) % len(cell)])
            if j < 0:
                assert box.exterior.distance(shapely.Point(mid)) < 1e-9
            else:
                d_i, d_j = np.hypot(*(mid - sites[i])), np.hypot(*(mid - sites[j]))
                assert d_i == pytest.approx(d_j, rel=1e-9)


def test_power_cells_hold_the_points_of_least_power_distance():
    """Each random point lies in the cell of the site minimising |x - p|^2 - w (brute force)."""
    rng = np.random.default_rng(11)
    sites = random_sites(rng, HEXAGON, 120)
    weights = rng.uniform(0.0, 60.0, len(sites))
    cells, _ = tess.power_cells(sites, weights, HEXAGON)
    assert_tiles(cells, HEXAGON)
    points = random_sites(rng, HEXAGON, 4000)
    power = ((points[:, None, :] - sites[None]) ** 2).sum(-1) - weights[None]
    nearest = power.argmin(axis=1)
    for i, cell in enumerate(cells):
        if not len(cell):
            assert not np.any(nearest == i)
            continue
        inside = shapely.contains_xy(Polygon(cell), points[:, 0], points[:, 1])
        np.testing.assert_array_equal(inside, nearest == i, err_msg=f"cell {i}")


def test_balanced_weights_give_the_target_areas():
    """balance_weights finds weights whose cells have areas spanning two decades."""
    rng = np.random.default_rng(3)
    total = Polygon(REGION).area
    shares = rng.uniform(1.0, 10.0, 200) ** 2
    targets = np.sort(total * shares / shares.sum())[::-1]
    radii = np.sqrt(0.35 * targets / np.pi)
    sites = tess.place_disks(radii, REGION, rng)
    _, cells, _, areas = tess.balance_weights(sites, radii**2, targets, REGION)
    assert_tiles(cells, REGION)
    shapely_areas = np.array([Polygon(c).area for c in cells])
    np.testing.assert_allclose(shapely_areas, areas, rtol=AREA_RTOL)
    np.testing.assert_allclose(shapely_areas, targets, rtol=BALANCE_RTOL)


def test_place_disks_are_disjoint_and_inside():
    """Random sequential addition: no two disks overlap, every centre is in the region."""
    rng = np.random.default_rng(8)
    radii = np.sort(rng.uniform(0.5, 5.0, 100))[::-1]  # 28 % of the region
    centres = tess.place_disks(radii, HEXAGON, rng)
    assert shapely.contains_xy(Polygon(HEXAGON), centres[:, 0], centres[:, 1]).all()
    d = np.hypot(*(centres[:, None, :] - centres[None]).transpose(2, 0, 1))
    gap = d - (radii[:, None] + radii[None])
    np.fill_diagonal(gap, 0.0)
    assert gap.min() >= 0.0


def test_convex_hull_is_shapelys():
    """The hull has shapely's area and vertices, counter-clockwise, with none collinear."""
    rng = np.random.default_rng(2)
    for _ in range(20):
        points = rng.normal(size=(40, 2)) * [3.0, 1.0]
        hull = tess.convex_hull(points)
        reference = MultiPoint(points).convex_hull
        assert Polygon(hull).area == pytest.approx(reference.area, rel=AREA_RTOL)
        assert Polygon(hull).exterior.is_ccw
        assert {tuple(p) for p in hull} == set(reference.exterior.coords[:-1])
        assert tess.is_convex(hull)


def circle_ish(n: int, seed: int) -> np.ndarray:
    """A strictly convex ``n``-gon: points on an ellipse at random angles."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0.0, 2.0 * np.pi, n))
    return np.stack([5.0 * np.cos(t), 3.0 * np.sin(t)], axis=1)


def test_simplify_keeps_a_convex_outline_inside_losing_least_area():
    """Simplified to 16: convex, inside the original; one removal is the best of all (brute)."""
    for seed in range(10):
        v = circle_ish(30, seed)
        out = tess.simplify(v, 16)
        assert len(out) == 16 and tess.is_convex(out)
        original, simple = Polygon(v), Polygon(out)
        assert original.buffer(1e-9).contains(simple)
        # One vertex too many: the vertex removed is the one whose removal loses least.
        v17 = v[:17]
        best = max(Polygon(np.delete(v17, k, axis=0)).area for k in range(17))
        assert Polygon(tess.simplify(v17, 16)).area == pytest.approx(best, rel=AREA_RTOL)


def test_clean_drops_repeated_and_collinear_vertices():
    """A repeated vertex and one in the middle of an edge go; the area stays (shapely)."""
    square = [[0.0, 0.0], [2.0, 0.0], [2.0, 0.0], [2.0, 1.0], [2.0, 2.0], [0.0, 2.0]]
    out = tess.clean(np.array(square))
    assert {tuple(p) for p in out} == {(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)}
    assert Polygon(out).area == pytest.approx(Polygon(square).area, rel=AREA_RTOL)
    assert tess.is_convex(out)
