"""Floe fields of many shapes: ``[[field]] kind = "voronoi"`` (a tessellated region, a
floe-size distribution) and ``kind = "file"`` (GeoJSON), and ``floes.from_shapely``.

References are independent of the code under test: shapely for areas, convexity,
intersections and containment, a maximum-likelihood fit (SciPy) for the size distribution's
exponent, the GeoJSON written by ``shapely.geometry.mapping``.
"""

from __future__ import annotations

import json
import math
import textwrap
from pathlib import Path

import numpy as np
import pytest
import shapely
from scipy.optimize import minimize_scalar
from shapely.geometry import MultiPolygon, Polygon, mapping

from taichi_ice.errors import ScenarioError
from taichi_ice.scene import floes
from taichi_ice.scene.model import MAX_VERTICES
from taichi_ice.scene.parse import load_scenario, parse_scenario, reseeded, scene_from_dict

ROOT = Path(__file__).resolve().parents[1]
# Areas are shoelace sums of float64 coordinates of order 100 m: round-off.
AREA_RTOL = 1e-10
# The floes cover concentration x region to this (relative): the cells tile the region and
# every floe is its cell shrunk by sqrt(concentration), so only round-off is left (7e-16
# measured over 20 fields); cleaning a near-degenerate corner could take 1e-7 of one outline.
CONCENTRATION_RTOL = 1e-9
# The fitted exponent of ~1,000 floes at exponent 2.5: over seeds 0-9 the fit had mean 2.51
# and standard deviation 0.08 (docs/scenarios.md); 0.25 is three of them.
EXPONENT_ATOL = 0.25
# The drawn sizes are scaled by one factor to meet the concentration; with ~1,000 floes it
# is within 1 % of 1 (the last floe's share of the ice area).
SIZE_RTOL = 0.02


def floe_polygons(scene) -> list[Polygon]:
    return [Polygon(b.world_vertices()) for b in scene.bodies]


def voronoi(**field) -> dict:
    """A scene of one Voronoi field (defaults overridden by ``field``)."""
    spec = {"kind": "voronoi", "name": "ice", "region": [0.0, 0.0, 120.0, 80.0]}
    spec.update(concentration=0.8, floes=60)
    spec.update(field)
    spec = {k: v for k, v in spec.items() if v is not None}  # floes=None: leave it out
    return {"simulation": {"duration": 1.0, "seed": 3}, "field": [spec]}


def assert_floe_field(scene, region: Polygon, concentration: float) -> None:
    """Convex floes of at most MAX_VERTICES, inside the region, none overlapping, with
    shapely's areas, covering ``concentration`` of the region."""
    polys = floe_polygons(scene)
    rho_d = scene.ice.density * scene.ice.thickness
    for b, p, mass in zip(scene.bodies, polys, scene.masses):
        assert 3 <= len(b.vertices) <= MAX_VERTICES, b.name
        assert p.is_valid and p.exterior.is_ccw, b.name
        assert p.convex_hull.area == pytest.approx(p.area, rel=AREA_RTOL), b.name
        assert mass == pytest.approx(rho_d * p.area, rel=AREA_RTOL), b.name
        assert region.buffer(1e-9).contains(p), b.name
        np.testing.assert_allclose(b.position, p.centroid.coords[0], atol=1e-9)
    tree = shapely.STRtree(polys)
    for i, p in enumerate(polys):
        for j in tree.query(p):
            if j > i:
                assert p.intersection(polys[j]).area <= 1e-12 * p.area, (i, j)
    total = sum(p.area for p in polys)
    assert total / region.area == pytest.approx(concentration, rel=CONCENTRATION_RTOL)


# --------------------------------------------------------------------------------------------
# kind = "voronoi"
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("concentration", [0.6, 0.9, 1.0])
def test_voronoi_floes_are_convex_disjoint_and_meet_the_concentration(concentration):
    """floes = N: N convex floes inside the region, none overlapping, at the concentration."""
    scene = scene_from_dict(voronoi(concentration=concentration))
    assert scene.n_bodies == 60 and scene.names[:2] == ("ice_0", "ice_1")
    assert_floe_field(scene, Polygon([(0, 0), (120, 0), (120, 80), (0, 80)]), concentration)


def test_voronoi_in_a_polygon_region_with_a_size_distribution():
    """fsd in a convex hexagonal region: the same facts, and the sizes within their range."""
    hexagon = [[10.0, 0.0], [90.0, 5.0], [110.0, 50.0], [80.0, 95.0], [5.0, 90.0], [-8.0, 40.0]]
    fsd = {"exponent": 2.0, "min_size": 3.0, "max_size": 25.0}
    scene = scene_from_dict(voronoi(region=hexagon, concentration=0.75, floes=None, fsd=fsd))
    assert_floe_field(scene, Polygon(hexagon), 0.75)
    sizes = np.sqrt(4.0 * np.array([p.area for p in floe_polygons(scene)]) / np.pi)
    assert np.all(np.diff(sizes) <= 1e-9 * sizes[0])  # largest first
    assert sizes.min() >= 3.0 * (1 - SIZE_RTOL) and sizes.max() <= 25.0 * (1 + SIZE_RTOL)


def power_law_exponent(sizes: np.ndarray) -> float:
    """Maximum-likelihood exponent of p(d) ~ d^-a on [min, max] of the sizes."""
    lo, hi, logs = sizes.min(), sizes.max(), np.log(sizes).sum()

    def minus_log_likelihood(a):
        norm = (a - 1.0) / (lo ** (1.0 - a) - hi ** (1.0 - a))
        return -(len(sizes) * math.log(norm) - a * logs)

    return minimize_scalar(minus_log_likelihood, bounds=(1.01, 8.0), method="bounded").x


def test_size_distribution_exponent_recovered_by_a_fit():
    """The floes' equivalent diameters follow the power law asked for (MLE, ~1,000 floes)."""
    fsd = {"exponent": 2.5, "min_size": 4.0, "max_size": 40.0}
    data = voronoi(region=[0.0, 0.0, 400.0, 300.0], concentration=0.7, floes=None, fsd=fsd)
    data["field"][0]["seed"] = 4
    scene = scene_from_dict(data)
    sizes = np.sqrt(4.0 * np.array([p.area for p in floe_polygons(scene)]) / np.pi)
    assert 800 < len(sizes) < 1300
    assert power_law_exponent(sizes) == pytest.approx(2.5, abs=EXPONENT_ATOL)
    assert sizes.min() >= 4.0 * (1 - SIZE_RTOL) and sizes.max() <= 40.0 * (1 + SIZE_RTOL)
    # The fit tells exponents apart: the same region at 1.5 fits far from 2.5.
    data["field"][0]["fsd"] = dict(fsd, exponent=1.5)
    other = np.sqrt(4.0 * np.array([p.area for p in floe_polygons(scene_from_dict(data))]) / np.pi)
    assert power_law_exponent(other) < 2.5 - 3 * EXPONENT_ATOL


def test_voronoi_same_seed_same_field_other_seed_another():
    """The tessellation is a function of the seed: the field's own, or simulation.seed's."""
    a, b = scene_from_dict(voronoi()), scene_from_dict(voronoi())
    np.testing.assert_array_equal(a.vertices_flat, b.vertices_flat)
    np.testing.assert_array_equal(a.positions, b.positions)
    other = reseeded(a, 4)
    assert not np.array_equal(other.positions[:10], a.positions[:10])
    pinned = scene_from_dict(voronoi(seed=9))
    assert not np.array_equal(pinned.positions, a.positions)
    # The field's own seed is left alone by reseeded; the text rebuilds the scene.
    np.testing.assert_array_equal(reseeded(pinned, 4).positions, pinned.positions)
    again = parse_scenario(a.text)
    np.testing.assert_array_equal(again.vertices_flat, a.vertices_flat)


def test_voronoi_velocities_and_a_lattice_after_it():
    """Velocity and its jitter as for a lattice; a later lattice field is laid out as always."""
    data = voronoi(velocity=[0.5, -0.1], velocity_jitter=0.2, omega=0.3)
    scene = scene_from_dict(data)
    v = scene.velocities
    assert np.all(np.abs(v - [0.5, -0.1]) <= 0.2) and np.ptp(v[:, 0]) > 0.2
    assert np.all(scene.omegas == 0.3)
    lattice = {
        "shape": "rectangle",
        "width": 0.5,
        "length": 0.4,
        "rows": 2,
        "columns": 3,
        "origin": [200.0, 0.0],
        "spacing": [1.0, 1.0],
        "jitter": 0.1,
    }
    data["field"].append(lattice)
    with_lattice = scene_from_dict(data)
    data["field"][0]["seed"] = 12  # its own seed: the lattice's draws are unchanged
    assert np.array_equal(
        scene_from_dict(data).positions[-6:], with_lattice.positions[-6:]
    ) and not np.array_equal(scene_from_dict(data).positions[:60], with_lattice.positions[:60])


def test_simplified_cells_are_reported():
    """A large floe among small ones has more than 16 neighbours: simplified, and said so."""
    fsd = {"exponent": 3.5, "min_size": 3.0, "max_size": 60.0}
    for seed in range(8):
        data = voronoi(region=[0.0, 0.0, 200.0, 200.0], concentration=0.8, floes=None, fsd=fsd)
        data["field"][0]["seed"] = seed
        scene = scene_from_dict(data)
        if scene.notes:
            break
    (note,) = [n for n in scene.notes if "simplified" in n]
    assert note.startswith("<dict>: [[field]] #0 'ice': ") and "largest cell area change" in note
    assert_floe_field(scene, Polygon([(0, 0), (200, 0), (200, 200), (0, 200)]), 0.8)


BAD_VORONOI = [
    ({"colour": 1}, "colour", "known keys"),
    ({"kind": "voronoy"}, "kind", "allowed"),
    ({"concentration": 1.5}, "concentration", "(0, 1]"),
    ({"concentration": 0.0}, "concentration", "(0, 1]"),
    ({"floes": None}, "floes", "give floes"),
    ({"fsd": {"exponent": 2, "min_size": 1, "max_size": 5}}, "floes", "not both"),
    ({"floes": 0}, "floes", "at least 1"),
    ({"floes": 10**6}, "floes", "at most 20,000"),
    ({"floes": 2.5}, "floes", "whole number"),
    ({"region": [0, 0, -1, 5]}, "region", "x1 > x0"),
    ({"region": "big"}, "region", "[x0, y0, x1, y1]"),
    ({"region": [[0, 0], [0, 9], [9, 9], [9, 0]]}, "region", "reverse the list"),
    ({"region": [[0, 0], [9, 0], [2, 2], [0, 9]]}, "region", "the region must be convex"),
    ({"region": [0, 0, 1e8, 1]}, "region", "near the origin"),
    ({"seed": -1}, "seed", "at least 0"),
    ({"velocity_jitter": -1.0}, "velocity_jitter", "must not be negative"),
]
BAD_FSD = [
    ({"exponent": 11}, "exponent", "[0, 10]"),
    ({"exponent": "2"}, "exponent", "remove the quotes"),
    ({"max_size": 2.0}, "max_size", "above min_size"),
    ({"min_size": 0.0}, "min_size", "must be positive"),
    ({"max_size": 500.0}, "max_size", "more than the"),
    ({"min_size": 0.01, "exponent": 3.5}, "min_size", "at most 20,000"),
    ({"size": 3}, "size", "known keys"),
]


@pytest.mark.parametrize(("change", "key", "fix"), BAD_VORONOI, ids=[b[1] for b in BAD_VORONOI])
def test_voronoi_bad_keys_refused_in_one_line(change, key, fix):
    """Each mistake: one line naming the file, the field, the key and the fix."""
    data = voronoi()
    data["field"][0].update(change)
    data["field"][0] = {k: v for k, v in data["field"][0].items() if v is not None}  # removed
    with pytest.raises(ScenarioError) as info:
        scene_from_dict(data, source="sea.toml")
    message = str(info.value)
    assert message.startswith("sea.toml: [[field]] #0 'ice'") and "\n" not in message
    assert f"'{key}'" in message and fix in message, message


@pytest.mark.parametrize(("change", "key", "fix"), BAD_FSD, ids=[b[1] for b in BAD_FSD])
def test_fsd_bad_keys_refused_in_one_line(change, key, fix):
    """A mistake in the fsd table names the table and the key."""
    fsd = {"exponent": 2.5, "min_size": 4.0, "max_size": 40.0}
    fsd.update(change)
    data = voronoi(floes=None, fsd=fsd)
    with pytest.raises(ScenarioError) as info:
        scene_from_dict(data, source="sea.toml")
    message = str(info.value)
    assert message.startswith("sea.toml: [[field]] #0 'ice', table 'fsd'") and "\n" not in message
    assert f"'{key}'" in message and fix in message, message


# --------------------------------------------------------------------------------------------
# kind = "file" and from_shapely
# --------------------------------------------------------------------------------------------


def shapes() -> list[Polygon]:
    """Three convex floes, one of them given clockwise, apart from each other (m)."""
    return [
        Polygon([(0, 0), (20, 0), (22, 14), (3, 18)]),
        Polygon([(30, 0), (45, 2), (40, 15)]),
        Polygon([(60, 0), (60, 12), (75, 12), (75, 0)]),  # clockwise
    ]


def write_geojson(path: Path, polys, crs: str | None = None) -> Path:
    collection = {
        "type": "FeatureCollection",
        "features": [{"type": "Feature", "properties": {}, "geometry": mapping(p)} for p in polys],
    }
    if crs is not None:
        collection["crs"] = {"type": "name", "properties": {"name": crs}}
    path.write_text(json.dumps(collection))
    return path


def file_scene(folder: Path, polys, crs=None, **field) -> Path:
    """A scene file beside its GeoJSON file, with one file field."""
    write_geojson(folder / "floes.geojson", polys, crs)
    options = "".join(f"{k} = {json.dumps(v)}\n" for k, v in field.items())
    text = textwrap.dedent(
        """\
        [simulation]
        duration = 1.0

        [[field]]
        name = "ice"
        kind = "file"
        path = "floes.geojson"
        """
    )
    scene = folder / "sea.toml"
    scene.write_text(text + options)
    return scene


def same_vertices(got: np.ndarray, polygon: Polygon) -> bool:
    return {tuple(np.round(p, 9)) for p in got} == {
        tuple(np.round(p, 9)) for p in polygon.exterior.coords[:-1]
    }


def test_geojson_round_trip(tmp_path):
    """Polygons written by shapely come back as floes with their areas and vertices."""
    polys = shapes()
    scene = load_scenario(file_scene(tmp_path, polys, offset=[0.0, 0.0]))
    assert scene.names == ("ice_f0", "ice_f1", "ice_f2") and not scene.notes
    rho_d = scene.ice.density * scene.ice.thickness
    for body, poly, mass in zip(scene.bodies, polys, scene.masses):
        assert mass == pytest.approx(rho_d * poly.area, rel=AREA_RTOL)
        assert same_vertices(body.world_vertices(), poly)
        np.testing.assert_allclose(body.position, poly.centroid.coords[0], atol=1e-9)
    moved = load_scenario(file_scene(tmp_path, polys, offset=[100.0, -5.0]))
    np.testing.assert_allclose(moved.positions - scene.positions, [[100.0, -5.0]] * 3)


def test_concave_floe_refused_naming_the_feature_or_hulled(tmp_path):
    """A concave floe is refused (file, feature, fix), or replaced by shapely's hull."""
    dart = Polygon([(100, 0), (120, 0), (110, 4), (110, 15)])
    polys = [*shapes(), dart]
    path = file_scene(tmp_path, polys)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    message = str(info.value)
    assert message.startswith(f"{path}: [[field]] #0 'ice': ") and "\n" not in message
    assert "floes.geojson: feature 3: is concave" in message
    assert 'concave = "hull"' in message and "no bonds" in message
    hull = Polygon(dart.convex_hull)
    assert f"+{100 * (hull.area / dart.area - 1):.3g} % area" in message
    scene = load_scenario(file_scene(tmp_path, polys, concave="hull"))
    assert same_vertices(scene.bodies[3].world_vertices(), hull)
    (note,) = scene.notes
    assert f"+{100 * (hull.area / dart.area - 1):.3g} %" in note and "feature 3" in note


def test_twenty_vertex_floe_simplified_with_the_area_change_reported(tmp_path):
    """20 vertices: refused, or simplified to 16 inside the original, the loss reported."""
    t = np.linspace(0.0, 2.0 * np.pi, 20, endpoint=False)
    round_floe = Polygon(np.stack([200 + 10 * np.cos(t), 10 * np.sin(t)], axis=1))
    polys = [*shapes(), round_floe]
    with pytest.raises(ScenarioError) as info:
        load_scenario(file_scene(tmp_path, polys))
    message = str(info.value)
    assert "feature 3: 20 vertices" in message and "simplify = true" in message
    scene = load_scenario(file_scene(tmp_path, polys, simplify=True))
    floe = Polygon(scene.bodies[3].world_vertices())
    assert len(scene.bodies[3].vertices) == MAX_VERTICES
    assert floe.convex_hull.area == pytest.approx(floe.area, rel=AREA_RTOL)
    assert round_floe.buffer(1e-9).contains(floe)
    (note,) = scene.notes
    assert f"-{100 * (1 - floe.area / round_floe.area):.3g} %" in note and "feature 3" in note


def test_overlapping_file_floes_refused_naming_both(tmp_path):
    """Two floes of a file that overlap: the message names both."""
    polys = [*shapes(), Polygon([(10, 5), (25, 5), (25, 20)])]
    with pytest.raises(ScenarioError) as info:
        load_scenario(file_scene(tmp_path, polys))
    message = str(info.value)
    assert "block 'ice_f0'" in message and "block 'ice_f3'" in message and "overlap" in message
    assert "correct their outlines" in message


def test_degrees_refused_and_a_projected_crs_trusted(tmp_path):
    """Longitude and latitude are refused (crs member, or their look); a projected crs not."""
    lonlat = [Polygon([(-150.0, 72.0), (-149.999, 72.0), (-149.999, 72.0005)])]
    with pytest.raises(ScenarioError, match="look like longitude and latitude"):
        load_scenario(file_scene(tmp_path, lonlat))
    with pytest.raises(ScenarioError, match="reproject first"):
        load_scenario(file_scene(tmp_path, shapes(), crs="urn:ogc:def:crs:OGC:1.3:CRS84"))
    tiny = [Polygon([(0.0, 0.0), (0.001, 0.0), (0.0, 0.001)])]
    scene = load_scenario(file_scene(tmp_path, tiny, crs="urn:ogc:def:crs:EPSG::3413"))
    assert scene.n_bodies == 1


@pytest.mark.parametrize(
    ("content", "fix"),
    [
        ("{", "not a GeoJSON (JSON) file"),
        ('{"type": "FeatureCollection"}', "needs a list of features"),
        ('{"type": "Point", "coordinates": [0, 0]}', "a Point is not a floe"),
        (
            '{"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [2, 0]]]}',
            "zero or non-finite area",
        ),
        ('{"type": "Polygon", "coordinates": [[[0, 0], ["a", 0], [0, 1]]]}', "number pairs"),
    ],
)
def test_bad_geojson_refused_in_one_line(tmp_path, content, fix):
    """A file that is not GeoJSON floes: one line naming the scene, the field and the fix."""
    path = file_scene(tmp_path, shapes())
    (tmp_path / "floes.geojson").write_text(content)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    message = str(info.value)
    assert message.startswith(f"{path}: [[field]] #0 'ice'") and "\n" not in message
    assert fix in message, message


def test_file_field_bad_keys(tmp_path):
    """A missing file, an unknown key or a bad concave value: named, with the fix."""
    path = file_scene(tmp_path, shapes())
    text = path.read_text()
    cases = [
        (text.replace("floes.geojson", "gone.geojson"), "key 'path': cannot read"),
        (text + "colour = 1\n", "unknown key 'colour'"),
        (text + 'concave = "split"\n', 'allowed: "refuse" | "hull"'),
        (text + 'simplify = "yes"\n', "expected true or false"),
    ]
    for case, fix in cases:
        path.write_text(case)
        with pytest.raises(ScenarioError) as info:
            load_scenario(path)
        assert str(info.value).startswith(f"{path}: [[field]] #0 'ice'") and fix in str(info.value)


def test_from_shapely_builds_self_contained_bodies():
    """shapely polygons (and a MultiPolygon's parts) to [[body]] tables of the same floes."""
    polys = shapes()
    multi = MultiPolygon(
        [Polygon([(0, 40), (8, 40), (4, 47)]), Polygon([(20, 40), (28, 40), (24, 47)])]
    )
    bodies = floes.from_shapely([*polys, multi], name="floe", velocity=(0.0, 0.1))
    scene = scene_from_dict({"simulation": {"duration": 1.0}, "body": bodies})
    assert scene.names == ("floe_f0", "floe_f1", "floe_f2", "floe_f3_p0", "floe_f3_p1")
    for body, poly in zip(scene.bodies, [*polys, *multi.geoms]):
        assert same_vertices(body.world_vertices(), poly)
    np.testing.assert_array_equal(scene.velocities[:, 1], 0.1)
    # The text holds the outlines: it rebuilds the scene with no file.
    np.testing.assert_array_equal(parse_scenario(scene.text).vertices_flat, scene.vertices_flat)
    with pytest.raises(ScenarioError, match=r"<shapely>: feature 0: is concave"):
        floes.from_shapely(Polygon([(0, 0), (20, 0), (10, 4), (10, 15)]))
    (outline,) = floes.convex_outlines(
        Polygon([(0, 0), (20, 0), (10, 4), (10, 15)]), concave="hull"
    )
    assert outline.hull_change == pytest.approx(
        Polygon([(0, 0), (20, 0), (10, 15)]).area
        / Polygon([(0, 0), (20, 0), (10, 4), (10, 15)]).area
        - 1.0,
        rel=AREA_RTOL,
    )


def test_from_geojson_reads_the_file(tmp_path):
    """from_geojson gives the [[body]] tables of a file's floes."""
    polys = shapes()
    bodies = floes.from_geojson(write_geojson(tmp_path / "f.geojson", polys))
    for table, poly in zip(bodies, polys):
        outline = np.array(table["vertices"]) + table["position"]
        assert same_vertices(outline, poly)


# --------------------------------------------------------------------------------------------
# Documentation and the engine
# --------------------------------------------------------------------------------------------


def test_documented_field_examples_load(tmp_path):
    """The voronoi and file examples of docs/scenarios.md are valid fields."""
    doc = (ROOT / "docs" / "scenarios.md").read_text()
    section = doc.split("## Floe fields from a tessellation or a file", 1)[1]
    blocks = [b.split("```", 1)[0] for b in section.split("```toml\n")[1:3]]
    head = "[simulation]\nduration = 1.0\n\n"
    scene = parse_scenario(head + blocks[0], source="doc")
    assert scene.fields[0].kind == "voronoi" and scene.n_bodies > 50
    polys = [Polygon([(5e5, 7e6), (5e5 + 30, 7e6), (5e5 + 10, 7e6 + 20)])]
    write_geojson(tmp_path / "floes.geojson", polys)
    (tmp_path / "sea.toml").write_text(head + blocks[1])
    scene = load_scenario(tmp_path / "sea.toml")
    assert scene.fields[0].kind == "file" and scene.n_bodies == 1


def test_voronoi_scene_steps_in_the_engine(taichi_runtime):
    """A tessellated field assembles and runs: floes collide, momentum stays (no water)."""
    from taichi_ice import Simulation

    arch, precision = taichi_runtime
    data = voronoi(region=[0.0, 0.0, 8.0, 6.0], floes=16, concentration=0.95)
    data["field"][0]["velocity_jitter"] = 0.4
    scene = scene_from_dict(data)
    sim = Simulation(scene, arch=arch, precision=precision)
    m = scene.masses
    p0 = (m[:, None] * sim.velocities()).sum(axis=0)
    sim.run(until=0.15)
    sim.check()
    p = (m[:, None] * sim.velocities()).sum(axis=0)
    scale = float(np.sum(m * np.linalg.norm(scene.velocities, axis=1)))
    energies = sim.energies()
    assert energies["viscous_energy"] + energies["friction_energy"] > 0.0  # they collided
    assert np.max(np.abs(p - p0)) <= (1e-12 if precision == "f64" else 1e-5) * scale


def test_sweep_takes_a_voronoi_fields_own_keys(tmp_path):
    """A sweep may vary a Voronoi field's concentration; area_fraction is a lattice's."""
    from taichi_ice.experiments.sweep.spec import SweepError, load_sweep
    from taichi_ice.tomlio import dump_toml

    (tmp_path / "sea.toml").write_text(dump_toml(voronoi()))
    head = '[sweep]\nscene = "sea.toml"\nseeds = [0, 1]\n[overrides]\n'
    (tmp_path / "ok.toml").write_text(head + '"field.ice.concentration" = [0.6, 0.7]\n')
    worlds = load_sweep(tmp_path / "ok.toml").worlds()
    assert [w.overrides[0][1] for w in worlds] == [0.6, 0.6, 0.7, 0.7]
    (tmp_path / "bad.toml").write_text(head + '"field.ice.area_fraction" = [0.7]\n')
    with pytest.raises(SweepError) as info:
        load_sweep(tmp_path / "bad.toml")
    assert "unknown key 'area_fraction'" in str(info.value)
    assert "concentration" in str(info.value)


def test_run_prints_the_notes(tmp_path, capsys):
    """`taichi-ice run` says which outlines were simplified, and by how much."""
    from taichi_ice.commands.cli import main

    t = np.linspace(0.0, 2.0 * np.pi, 20, endpoint=False)
    round_floe = Polygon(np.stack([200 + 10 * np.cos(t), 10 * np.sin(t)], axis=1))
    path = file_scene(tmp_path, [*shapes(), round_floe], simplify=True)
    out = tmp_path / "run.h5"
    assert main(["run", str(path), "--out", str(out), "--until", "0.002", "--quiet"]) == 0
    err = capsys.readouterr().err
    (note,) = [line for line in err.splitlines() if line.startswith("note: ")]
    assert "feature 3" in note and "simplified" in note
