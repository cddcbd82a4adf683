"""Scene files: validation messages, field lattices and jitter, centroids, mass properties.

References are independent of the code under test: shapely for areas and centroids, closed
forms for moments of inertia, explicit loops for the lattice.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from shapely import affinity
from shapely.geometry import Polygon

from taichi_ice.codes import BodyKind
from taichi_ice.errors import ScenarioError
from taichi_ice.physics import polygon
from taichi_ice.physics.friction import Coulomb, RateState
from taichi_ice.physics.timestep import DEFAULT_SAFETY, MIDSTEP_SAFETY, RATE_STATE_SAFETY
from taichi_ice.scene import parse as sc
from taichi_ice.scene import tables

ROOT = Path(__file__).resolve().parents[1]
# scenarios/ is a link to the scenes shipped in the package.
EXAMPLES = sorted((ROOT / "scenarios").glob("*.toml"))

# Positions are sums of a few float64 terms: equal to round-off.
POSITION_ATOL = 1e-12
# Mass properties from the shoelace sums against shapely and closed forms.
MASS_RTOL = 1e-12

BASE = textwrap.dedent(
    """\
    [simulation]
    duration = 2.0

    [[body]]
    name = "pillar"
    kind = "fixed"
    shape = "diamond"
    width = 1.0
    length = 1.0
    position = [0.0, 0.0]

    [[body]]
    name = "floe"
    shape = "rectangle"
    width = 1.0
    length = 0.5
    position = [3.0, 0.0]
    """
)


def base_dict() -> dict:
    """The BASE scene as a dict (a fresh copy)."""
    return {
        "simulation": {"duration": 2.0},
        "body": [
            {
                "name": "pillar",
                "kind": "fixed",
                "shape": "diamond",
                "width": 1.0,
                "length": 1.0,
                "position": [0.0, 0.0],
            },
            {
                "name": "floe",
                "shape": "rectangle",
                "width": 1.0,
                "length": 0.5,
                "position": [3.0, 0.0],
            },
        ],
    }


def field_dict(**field) -> dict:
    """A scene with one field (defaults overridden by ``field``) and nothing else."""
    spec = {
        "shape": "rectangle",
        "width": 0.5,
        "length": 0.4,
        "rows": 4,
        "columns": 5,
        "origin": [1.0, -2.0],
        "spacing": [0.7, 0.6],
        "stagger": 0.3,
    }
    spec.update(field)
    return {"simulation": {"duration": 1.0, "seed": 3}, "field": [spec]}


def error_of(text: str, source: str = "bad.toml") -> str:
    """The ScenarioError message for scene ``text``."""
    with pytest.raises(ScenarioError) as info:
        sc.parse_scenario(text, source=source)
    return str(info.value)


# ------------------------------------------------------------------------------------------
# Bad input: each class of mistake names the file, the table and the key, and says the fix.
# ------------------------------------------------------------------------------------------

BAD = [
    # (id, replace this, by this, substrings of the message)
    (
        "unknown-key",
        "width = 1.0\nlength = 0.5",
        "widht = 1.0\nlength = 0.5",
        ["[[body]] #1 'floe'", "unknown key 'widht'", "did you mean 'width'"],
    ),
    (
        "unknown-table",
        "[simulation]",
        "[watr]\n[simulation]",
        ["unknown table 'watr'", "did you mean 'water'"],
    ),
    (
        "string-number",
        "duration = 2.0",
        'duration = "2.0"',
        ["[simulation]", "key 'duration'", "remove the quotes"],
    ),
    (
        "zero-duration",
        "duration = 2.0",
        "duration = 0.0",
        ["[simulation]", "key 'duration'", "must be positive"],
    ),
    (
        "negative-size",
        "length = 0.5",
        "length = -0.5",
        ["[[body]] #1 'floe'", "key 'length'", "must be positive"],
    ),
    (
        "nan",
        "duration = 2.0",
        "duration = 2.0\n[ice]\ndensity = nan",
        ["[ice]", "key 'density'", "finite"],
    ),
    (
        "inf",
        "duration = 2.0",
        "duration = 2.0\n[ice]\nthickness = inf",
        ["[ice]", "key 'thickness'", "finite"],
    ),
    (
        "negative-viscosity",
        "duration = 2.0",
        "duration = 2.0\n[ice]\ncontact_viscosity = -1.0",
        ["[ice]", "key 'contact_viscosity'", "must not be negative"],
    ),
    (
        "negative-drag",
        "duration = 2.0",
        "duration = 2.0\n[water]\nskin_drag = -0.1",
        ["[water]", "key 'skin_drag'", "must not be negative"],
    ),
    (
        "unknown-shape",
        'shape = "rectangle"',
        'shape = "circle"',
        ["[[body]] #1 'floe'", "key 'shape'", '"circle"', '"rectangle" | "diamond" | "polygon"'],
    ),
    (
        "unknown-kind",
        'kind = "fixed"',
        'kind = "static"',
        ["[[body]] #0 'pillar'", "key 'kind'", '"dynamic" | "fixed" | "kinematic"'],
    ),
    (
        "duplicate-name",
        'name = "floe"',
        'name = "pillar"',
        ["[[body]] #1 'pillar'", "key 'name'", "already used by [[body]] #0 'pillar'", "unique"],
    ),
    (
        "overlap",
        "position = [3.0, 0.0]",
        "position = [0.8, 0.0]",
        ["[[body]] #0 'pillar' and [[body]] #1 'floe' overlap", "move them apart"],
    ),
    (
        "output-interval",
        "duration = 2.0",
        "duration = 2.0\noutput_interval = 3.0",
        ["[simulation]", "key 'output_interval'", "longer than the duration"],
    ),
    (
        "dt-word",
        "duration = 2.0",
        'duration = 2.0\ndt = "fast"',
        ["[simulation]", "key 'dt'", '"auto"'],
    ),
    (
        "seed-negative",
        "duration = 2.0",
        "duration = 2.0\nseed = -1",
        ["[simulation]", "key 'seed'", "at least 0"],
    ),
    (
        "dt-safety",
        "duration = 2.0",
        "duration = 2.0\ndt_safety = 1.5",
        ["[simulation]", "key 'dt_safety'", "(0, 1]"],
    ),
    (
        "integrator",
        "duration = 2.0",
        'duration = 2.0\nintegrator = "verlet"',
        ["[simulation]", "key 'integrator'", '"verlet"', '"auto" | "euler"', '"midstep"'],
    ),
    (
        "force-on-fixed",
        'kind = "fixed"',
        'kind = "fixed"\nforce = [1.0, 0.0]',
        ["[[body]] #0 'pillar'", "key 'force'", "only a dynamic body"],
    ),
    (
        "fixed-moving",
        'kind = "fixed"',
        'kind = "fixed"\nvelocity = [1.0, 0.0]',
        ["[[body]] #0 'pillar'", "key 'velocity'", 'kind = "kinematic"'],
    ),
    (
        "missing-key",
        "width = 1.0\nlength = 0.5",
        "length = 0.5",
        ["[[body]] #1 'floe'", "key 'width'", "required"],
    ),
    (
        "missing-simulation",
        "[simulation]\nduration = 2.0",
        "",
        ["missing table [simulation]", "duration"],
    ),
    (
        "bool-as-number",
        "duration = 2.0",
        "duration = 2.0\n[ice]\ndensity = true",
        ["[ice]", "key 'density'", "expected a number"],
    ),
    (
        "friction-negative",
        "duration = 2.0",
        'duration = 2.0\n[friction]\nlaw = "coulomb"\nmu = -0.1',
        ["[friction]", "key 'mu'", "mu must be >= 0"],
    ),
    (
        "friction-law",
        "duration = 2.0",
        'duration = 2.0\n[friction]\nlaw = "rate_state"',
        ["[friction]", "key 'law'", 'did you mean "rate-state"'],
    ),
    (
        "friction-wrong-law-key",
        "duration = 2.0",
        'duration = 2.0\n[friction]\nlaw = "rate-state"\nmu = 0.3',
        ["[friction]", "key 'mu'", 'belongs to law = "coulomb"'],
    ),
    (
        "friction-method",
        "duration = 2.0",
        'duration = 2.0\n[friction]\nlaw = "rate-state"\nmethod = "heun"',
        ["[friction]", "key 'method'", "heun"],
    ),
    (
        "friction-key-case",
        "duration = 2.0",
        'duration = 2.0\n[friction]\nlaw = "rate-state"\na = 0.1',
        ["[friction]", "unknown key 'a'", "did you mean 'A'"],
    ),
]


@pytest.mark.parametrize("old, new, expected", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_input_message(old: str, new: str, expected: list[str]) -> None:
    """Each class of bad input is refused with a message naming the file, table, key and fix."""
    assert old in BASE
    message = error_of(BASE.replace(old, new, 1))
    assert message.startswith("bad.toml: ")
    for part in expected:
        assert part in message, f"{part!r} not in {message!r}"


POLYGON_BODY = """
[[body]]
name = "odd"
shape = "polygon"
vertices = {vertices}
position = [10.0, 0.0]
"""


@pytest.mark.parametrize(
    "vertices, expected",
    [
        ("[[0, 0], [1, 0], [0.2, 0.2], [0, 1]]", "not strictly convex"),
        ("[[0, 0], [0, 1], [1, 0]]", "clockwise"),
        ("[[0, 0], [1, 0], [2, 0]]", "zero area"),
        ("[[0, 0], [1, 0]]", "at least 3 vertices"),
        ('[[0, 0], [1, "0"], [0, 1]]', "[x, y] number pairs"),
    ],
    ids=["concave", "clockwise", "degenerate", "too-few", "string-vertex"],
)
def test_bad_polygon_message(vertices: str, expected: str) -> None:
    """A bad polygon outline is refused with the body's table and key 'vertices' in the message."""
    message = error_of(BASE + POLYGON_BODY.format(vertices=vertices))
    assert message.startswith("bad.toml: [[body]] #2 'odd', key 'vertices': ")
    assert expected in message


def test_polygon_keys_are_exclusive() -> None:
    """A polygon given a width, or a rectangle given vertices, is told which keys it takes."""
    message = error_of(
        BASE + POLYGON_BODY.format(vertices="[[0, 0], [1, 0], [0, 1]]") + "width = 1.0"
    )
    assert "[[body]] #2 'odd', key 'width'" in message and '"vertices"' in message
    message = error_of(
        BASE.replace("length = 0.5", "length = 0.5\nvertices = [[0, 0], [1, 0], [0, 1]]")
    )
    assert "[[body]] #1 'floe', key 'vertices'" in message and 'shape = "polygon"' in message


def test_field_bad_input_message() -> None:
    """Field keys are checked too: rows must be a whole number, spacing positive, jitter >= 0."""
    cases = [
        ({"rows": 2.5}, "key 'rows'", "whole number"),
        ({"spacing": [0.7, 0.0]}, "key 'spacing'", "positive"),
        ({"jitter": -0.1}, "key 'jitter'", "must not be negative"),
        ({"colums": 3}, "unknown key 'colums'", "did you mean 'columns'"),
    ]
    for change, key, fix in cases:
        with pytest.raises(ScenarioError) as info:
            sc.scene_from_dict(field_dict(**change), source="ens")
        message = str(info.value)
        assert (
            message.startswith("ens: [[field]] #0 'field0'") and key in message and fix in message
        )


def test_an_angle_past_a_full_turn_is_refused_as_degrees() -> None:
    """angle = 10 meant as degrees (issue 32): refused with the radians of 10 degrees, for a
    body and a field; a full turn either way (2 pi) is still an angle."""
    import math

    message = error_of(BASE.replace("length = 0.5", "length = 0.5\nangle = 10"))
    assert "[[body]] #1 'floe', key 'angle'" in message and "more than a full turn" in message
    assert f"{math.radians(10):.6g}" in message
    with pytest.raises(ScenarioError, match=r"key 'angle'.*write -0\.785398"):
        sc.scene_from_dict(field_dict(angle=-45.0), source="ens")
    turned = sc.scene_from_dict(field_dict(angle=-2 * math.pi))
    assert np.allclose(turned.angles, -2 * math.pi)


def test_field_overlap_names_blocks() -> None:
    """Blocks packed closer than their size are refused, naming both blocks and the fix."""
    with pytest.raises(ScenarioError) as info:
        sc.scene_from_dict(field_dict(spacing=[0.45, 0.6], stagger=0.0))
    message = str(info.value)
    assert (
        "[[field]] #0 block 'field0_r0_c0' and [[field]] #0 block 'field0_r0_c1' overlap" in message
    )
    assert "raise spacing or lower jitter" in message


def test_single_bracket_body_refused() -> None:
    """[body] (one table) instead of [[body]] (an array of tables) says to double the brackets."""
    text = '[simulation]\nduration = 1.0\n[body]\nshape = "rectangle"\n'
    message = error_of(text)
    assert message.startswith("bad.toml: 'body'") and "write [[body]] (double brackets)" in message


def test_toml_syntax_error_names_file_and_line() -> None:
    """A TOML syntax error becomes a ScenarioError with the file and the line."""
    message = error_of(BASE.replace("duration = 2.0", "duration = = 2.0"))
    assert message.startswith("bad.toml: TOML syntax error") and "line 2" in message


def test_missing_file_is_named(tmp_path: Path) -> None:
    """Loading a file that does not exist names it."""
    path = tmp_path / "nowhere.toml"
    with pytest.raises(ScenarioError, match=r"nowhere\.toml: cannot read"):
        sc.load_scenario(path)


def test_no_bodies_refused() -> None:
    """A scene with no body and no field is refused."""
    assert "no bodies" in error_of("[simulation]\nduration = 1.0\n")


# ------------------------------------------------------------------------------------------
# The time step
# ------------------------------------------------------------------------------------------


def test_dt_above_limit_refused_unless_forced() -> None:
    """dt above the stable limit is refused with the limit and both fixes; force_dt accepts it."""
    limit = sc.parse_scenario(BASE).stable_dt
    unstable = BASE.replace("duration = 2.0", f"duration = 2.0\ndt = {1.5 * limit!r}")
    message = error_of(unstable)
    assert "[simulation], key 'dt'" in message and f"{limit:.4g} s" in message
    assert 'dt = "auto"' in message and "force_dt = true" in message
    forced = sc.parse_scenario(unstable.replace("dt =", "force_dt = true\ndt ="))
    assert forced.dt == pytest.approx(1.5 * limit)
    assert (
        sc.parse_scenario(
            BASE.replace("duration = 2.0", f"duration = 2.0\ndt = {0.9 * limit!r}")
        ).dt
        == 0.9 * limit
    )


def test_auto_dt_and_limit_follow_dynamic_bodies() -> None:
    """dt = "auto" is dt_safety x the limit; the limit depends on the dynamic bodies only."""
    scene = sc.parse_scenario(BASE)
    assert math.isfinite(scene.stable_dt)
    assert scene.dt == pytest.approx(MIDSTEP_SAFETY * scene.stable_dt, rel=1e-15)
    # A much smaller fixed body changes nothing; the same as a dynamic body lowers the limit.
    tiny = (
        '\n[[body]]\nname = "chip"\nkind = "{kind}"\nshape = "rectangle"\n'
        "width = 0.1\nlength = 0.1\nposition = [9.0, 9.0]\n"
    )
    assert sc.parse_scenario(BASE + tiny.format(kind="fixed")).stable_dt == scene.stable_dt
    assert sc.parse_scenario(BASE + tiny.format(kind="dynamic")).stable_dt < 0.5 * scene.stable_dt
    half = sc.parse_scenario(BASE.replace("duration = 2.0", "duration = 2.0\ndt_safety = 0.1"))
    assert half.dt == pytest.approx(0.1 * scene.stable_dt, rel=1e-15)


def test_auto_dt_follows_the_law_unless_the_file_sets_dt_safety() -> None:
    """dt = "auto" takes 0.6 of the limit with Coulomb friction, stepped by its default
    integrator (midstep), 0.2 with Coulomb and the other integrators, and 0.05 with a law
    that has a memory, whatever its integrator (its pillar statistics are not converged at
    0.2 or 0.1: docs/accuracy.md); a file's dt_safety wins for either."""
    from taichi_ice.physics.friction import Coulomb, MemoryOnly, RateState, SteadyState

    scene = sc.parse_scenario(BASE)
    limit = scene.stable_dt
    assert (MIDSTEP_SAFETY, DEFAULT_SAFETY, RATE_STATE_SAFETY) == (0.6, 0.2, 0.05)
    for law, integrator, safety in (
        (Coulomb(mu=0.5), "midstep", MIDSTEP_SAFETY),
        (RateState(), "euler", RATE_STATE_SAFETY),
        (SteadyState(), "euler", RATE_STATE_SAFETY),
        (MemoryOnly(), "euler", RATE_STATE_SAFETY),
    ):
        other = scene.with_friction(law)
        assert (other.integrator, other.dt_safety) == (integrator, safety)
        assert other.dt == pytest.approx(safety * limit, rel=1e-15)
    # Another integrator, given to the scene (the engine's option does this), moves the step
    # with it where the law's step depends on it: Coulomb's.
    for integrator in ("euler", "analytic", "coupled"):
        assert scene.with_integrator(integrator).dt == pytest.approx(0.2 * limit, rel=1e-15)
        rs = scene.with_friction(RateState()).with_integrator(integrator)
        assert rs.dt == pytest.approx(0.05 * limit, rel=1e-15)
    assert scene.with_integrator("euler").with_integrator("midstep").dt == scene.dt
    own = sc.parse_scenario(BASE.replace("duration = 2.0", "duration = 2.0\ndt_safety = 0.3"))
    for law in (Coulomb(mu=0.5), RateState()):
        assert own.with_friction(law).dt == pytest.approx(0.3 * limit, rel=1e-15)
        assert own.with_friction(law).with_integrator("euler").dt == own.with_friction(law).dt
    # A file that names its integrator steps with it, and "auto" is the law's.
    for named, integrator, safety in (('"euler"', "euler", 0.2), ('"auto"', "midstep", 0.6)):
        filed = sc.parse_scenario(
            BASE.replace("duration = 2.0", f"duration = 2.0\nintegrator = {named}")
        )
        assert (filed.integrator, filed.dt) == (integrator, pytest.approx(safety * limit))
    # The message for a dt above the limit names the step "auto" would take with the law.
    rs = BASE.replace("duration = 2.0", f"duration = 2.0\ndt = {2 * limit!r}")
    rs += '\n[friction]\nlaw = "rate-state"\n'
    with pytest.raises(ScenarioError, match=r'dt = "auto" \(takes 0.05 x the limit'):
        sc.parse_scenario(rs)


# ------------------------------------------------------------------------------------------
# Defaults and the parsed values
# ------------------------------------------------------------------------------------------


def test_defaults() -> None:
    """Absent keys and tables take their documented defaults."""
    scene = sc.parse_scenario(BASE)
    sim = scene.simulation
    assert (sim.duration, sim.dt, sim.output_interval, sim.series_interval) == (
        2.0,
        None,
        0.1,
        0.01,
    )
    assert (sim.seed, sim.dt_safety, sim.force_dt, sim.integrator) == (0, None, False, None)
    assert (scene.integrator, scene.dt_safety) == ("midstep", MIDSTEP_SAFETY)  # Coulomb's
    assert scene.ice == sc.IceProperties(920.0, 0.3, 9.75e7, 3.16e4, 0.5)
    assert scene.water is None
    assert scene.friction == Coulomb(mu=0.5)
    assert scene.names == ("pillar", "floe")
    assert scene.kinds.tolist() == [BodyKind.FIXED, BodyKind.DYNAMIC]
    assert scene.probe_indices.tolist() == []
    water = sc.parse_scenario(BASE + "\n[water]\n")
    assert water.water == sc.WaterProperties(1010.0, 1.0, 0.005)
    coarse = sc.parse_scenario(
        BASE.replace("duration = 2.0", "duration = 2.0\noutput_interval = 0.005")
    )
    assert coarse.simulation.series_interval == 0.005


def test_body_values_and_friction_parsed() -> None:
    """Every body key and the rate-state table reach the Scene unchanged."""
    text = (
        BASE.replace(
            "position = [3.0, 0.0]",
            "position = [3.0, 0.0]\nangle = 0.3\nvelocity = [0.1, -0.2]\nomega = 0.5\n"
            "force = [10.0, 20.0]\nprobe = true",
        )
        + '\n[friction]\nlaw = "rate-state"\nA = 0.04\nt_c = 2.0\nmethod = "rk4"\n'
    )
    scene = sc.parse_scenario(text)
    floe = scene.bodies[1]
    assert (floe.name, floe.kind, floe.shape, floe.angle, floe.omega, floe.probe) == (
        "floe",
        "dynamic",
        "rectangle",
        0.3,
        0.5,
        True,
    )
    assert floe.position.tolist() == [3.0, 0.0]
    assert floe.velocity.tolist() == [0.1, -0.2] and floe.force.tolist() == [10.0, 20.0]
    assert scene.probe_indices.tolist() == [1]
    assert scene.friction == RateState(A=0.04, t_c=2.0, method="rk4")
    assert scene.bodies[0].force.tolist() == [0.0, 0.0]


def test_scene_is_immutable() -> None:
    """Scene and Body are frozen and their arrays read-only."""
    scene = sc.parse_scenario(BASE)
    with pytest.raises(AttributeError):
        scene.bodies = ()
    with pytest.raises(ValueError):
        scene.bodies[0].position[0] = 1.0
    with pytest.raises(ValueError):
        scene.masses[0] = 1.0


def test_touching_and_non_dynamic_overlaps_allowed() -> None:
    """Edge-to-edge contact is not an overlap, and fixed/kinematic bodies may overlap each other."""
    touching = BASE.replace("position = [3.0, 0.0]", "position = [1.0, 0.0]")  # corner on face
    assert sc.parse_scenario(touching).n_bodies == 2
    walls = BASE.replace('name = "floe"', 'name = "floe"\nkind = "kinematic"').replace(
        "position = [3.0, 0.0]", "position = [0.5, 0.0]"
    )
    assert sc.parse_scenario(walls).n_bodies == 2
    assert "overlap" in error_of(walls.replace('kind = "kinematic"', 'kind = "dynamic"'))


def test_find_overlaps_matches_brute_force() -> None:
    """The overlap screen finds exactly the pairs a brute-force shapely search finds."""
    rng = np.random.default_rng(7)
    bodies = []
    for i in range(300):
        w, l = rng.uniform(0.2, 1.0, 2)
        outline = polygon.rectangle(w, l) if i % 2 else polygon.diamond(w, l)
        bodies.append(
            sc.Body(
                name=f"b{i}",
                kind=("dynamic", "fixed", "kinematic")[i % 3],
                shape="rectangle",
                vertices=outline,
                position=rng.uniform(0.0, 12.0, 2),
                angle=rng.uniform(0, np.pi),
            )
        )
    wall = polygon.rectangle(40.0, 0.3)
    bodies.append(
        sc.Body(
            name="wall",
            kind="fixed",
            shape="rectangle",
            vertices=wall,
            position=np.array([6.0, 6.0]),
            angle=0.1,
        )
    )
    polys = [Polygon(b.world_vertices()) for b in bodies]
    expected = set()
    for i in range(len(bodies)):
        for j in range(i + 1, len(bodies)):
            if bodies[i].kind != "dynamic" and bodies[j].kind != "dynamic":
                continue
            area = polys[i].intersection(polys[j]).area
            if area > sc.OVERLAP_RTOL * min(polys[i].area, polys[j].area):
                expected.add((i, j))
    found = sc.find_overlaps(bodies)
    assert len(expected) > 20
    assert {(i, j) for i, j, _, _ in found} == expected
    for i, j, area, _ in found:
        assert area == pytest.approx(polys[i].intersection(polys[j]).area, rel=1e-9)


# ------------------------------------------------------------------------------------------
# Fields
# ------------------------------------------------------------------------------------------


def test_field_lattice_exact() -> None:
    """Without jitter, block (r, c) sits at origin + (c sx + stagger if r odd, r sy), row by row."""
    scene = sc.scene_from_dict(field_dict())
    expected_names, expected_pos = [], []
    for r in range(4):
        for c in range(5):
            expected_names.append(f"field0_r{r}_c{c}")
            expected_pos.append([1.0 + c * 0.7 + (0.3 if r % 2 == 1 else 0.0), -2.0 + r * 0.6])
    assert list(scene.names) == expected_names
    np.testing.assert_allclose(scene.positions, expected_pos, rtol=0, atol=POSITION_ATOL)
    assert set(scene.kinds.tolist()) == {BodyKind.DYNAMIC}
    assert all(b.shape == "rectangle" for b in scene.bodies)


def test_field_after_bodies_and_named() -> None:
    """Field blocks follow the [[body]] tables and take the field's name as prefix."""
    data = base_dict()
    data["field"] = [field_dict(name="rubble", origin=[10.0, 10.0])["field"][0]]
    scene = sc.scene_from_dict(data)
    assert scene.names[:2] == ("pillar", "floe")
    assert scene.names[2] == "rubble_r0_c0" and scene.names[-1] == "rubble_r3_c4"
    assert scene.n_bodies == 2 + 20


def test_field_jitter_seeded_and_bounded() -> None:
    """Jitter is U(-jitter, jitter) per axis: same seed same layout, another seed another."""
    jitter = 0.04
    lattice = sc.scene_from_dict(field_dict(rows=20, columns=20, spacing=[0.7, 0.6])).positions
    a = sc.scene_from_dict(field_dict(rows=20, columns=20, jitter=jitter)).positions
    b = sc.scene_from_dict(field_dict(rows=20, columns=20, jitter=jitter)).positions
    data = field_dict(rows=20, columns=20, jitter=jitter)
    data["simulation"]["seed"] = 4
    c = sc.scene_from_dict(data).positions
    np.testing.assert_array_equal(a, b)
    assert np.all(np.abs(a - c) > 0.0)
    offset = a - lattice
    assert np.all(np.abs(offset) <= jitter)
    # 800 uniform draws reach within 5 % of the bound on both sides, and average near zero.
    assert offset.max() > 0.95 * jitter and offset.min() < -0.95 * jitter
    assert abs(offset.mean()) < 0.1 * jitter


def test_field_velocity_jitter() -> None:
    """Field velocities are the field's velocity plus a bounded, seeded random part."""
    scene = sc.scene_from_dict(field_dict(velocity=[0.5, -0.1], velocity_jitter=0.2, omega=0.3))
    dv = scene.velocities - [0.5, -0.1]
    assert np.all(np.abs(dv) <= 0.2) and dv.std() > 0.05
    assert np.all(scene.omegas == 0.3)


def test_reseeded_changes_only_jitter() -> None:
    """reseeded moves field blocks within their jitter and leaves everything else as it was."""
    data = base_dict()
    data["water"] = {"form_drag": 0.8}
    data["field"] = [field_dict(origin=[10.0, 10.0], jitter=0.05, velocity_jitter=0.1)["field"][0]]
    scene = sc.scene_from_dict(data)
    other = sc.reseeded(scene, 11)
    assert other.simulation == dataclasses_replace(scene.simulation, seed=11)
    assert (other.ice, other.water, other.friction, other.names) == (
        scene.ice,
        scene.water,
        scene.friction,
        scene.names,
    )
    for b0, b1 in zip(scene.bodies[:2], other.bodies[:2]):
        np.testing.assert_array_equal(b0.position, b1.position)
        np.testing.assert_array_equal(b0.vertices, b1.vertices)
    moved = other.positions[2:] - scene.positions[2:]
    assert np.all(np.abs(moved) <= 2 * 0.05) and np.all(moved != 0.0)
    lattice = scene.fields[0].lattice()
    assert np.all(np.abs(other.positions[2:] - lattice) <= 0.05)
    np.testing.assert_array_equal(other.masses, scene.masses)
    np.testing.assert_array_equal(other.inertias, scene.inertias)
    assert sc.reseeded(scene, scene.simulation.seed) is scene
    # Its text rebuilds it exactly.
    again = sc.parse_scenario(other.text)
    np.testing.assert_array_equal(again.positions, other.positions)
    np.testing.assert_array_equal(again.velocities, other.velocities)


def dataclasses_replace(obj, **changes):
    """dataclasses.replace (kept local so the test reads as one comparison)."""
    import dataclasses

    return dataclasses.replace(obj, **changes)


def test_with_friction() -> None:
    """with_friction swaps the law and keeps the bodies; its text carries the new law."""
    scene = sc.parse_scenario(BASE)
    law = RateState(B=0.1, method="implicit")
    other = scene.with_friction(law)
    assert other.friction == law and scene.friction == Coulomb()
    assert other.bodies is scene.bodies
    assert sc.parse_scenario(other.text).friction == law


def test_dict_text_round_trip() -> None:
    """A scene built in code gets TOML text that parses back to the same scene."""
    data = base_dict()
    data["body"][1]["velocity"] = np.array([0.25, 0.0])
    data["simulation"]["dt"] = "auto"
    scene = sc.scene_from_dict(data)
    again = sc.parse_scenario(scene.text)
    np.testing.assert_array_equal(again.positions, scene.positions)
    np.testing.assert_array_equal(again.velocities, scene.velocities)
    assert again.simulation == scene.simulation and again.names == scene.names
    assert data["simulation"] == {"duration": 2.0, "dt": "auto"}  # defaults not written into it


def assert_same_scene(a: sc.Scene, b: sc.Scene) -> None:
    """Two scenes have the same settings, law, bodies and fields (values compared exactly)."""
    assert (a.simulation, a.ice, a.water, a.friction) == (b.simulation, b.ice, b.water, b.friction)
    assert a.names == b.names and a.dt == b.dt
    assert [x.kind for x in a.bodies] == [x.kind for x in b.bodies]
    assert [x.shape for x in a.bodies] == [x.shape for x in b.bodies]
    assert [x.probe for x in a.bodies] == [x.probe for x in b.bodies]
    for name in (
        "kinds",
        "probe_indices",
        "positions",
        "angles",
        "velocities",
        "omegas",
        "forces",
        "vertex_offsets",
        "vertices_flat",
        "masses",
        "inertias",
    ):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert len(a.fields) == len(b.fields)
    for fa, fb in zip(a.fields, b.fields):
        for f in dataclasses.fields(fa):
            np.testing.assert_array_equal(getattr(fa, f.name), getattr(fb, f.name), f.name)


def test_generated_text_round_trip_every_table() -> None:
    """tomli-w text of a scene using every table (NumPy values, an empty [water]) rebuilds it."""
    data = base_dict()
    data["simulation"].update(seed=np.int64(5), output_interval=0.05, force_dt=False)
    data["ice"] = {"density": np.float64(900.0), "thickness": 0.5}
    data["water"] = {}  # present but empty: drag with the default coefficients
    data["friction"] = {"law": "rate-state", "A": 0.04, "t_c": 2.0, "method": "rk4"}
    data["body"][1].update(velocity=np.array([0.25, -0.1]), angle=0.3, probe=np.bool_(True))
    data["body"].append(
        {
            "name": 'odd "quoted" floe',
            "shape": "polygon",
            "vertices": np.array([[0.0, 0.0], [2.0, 0.0], [2.5, 1.0], [0.5, 1.5]]),
            "position": [10.0, 0.0],
            "force": (1.0e3, 0.0),
        }
    )
    polygon_field = _polygon_field([[0.0, 0.0], [0.6, 0.0], [0.0, 0.45]])["field"][0]
    data["field"] = [
        field_dict(origin=[20.0, 0.0], jitter=0.05, velocity_jitter=0.1)["field"][0],
        dict(polygon_field, name="shards", origin=[20.0, 10.0]),
    ]
    scene = sc.scene_from_dict(data)
    assert scene.water == sc.WaterProperties() and isinstance(scene.friction, RateState)
    again = sc.parse_scenario(scene.text)
    assert_same_scene(again, scene)
    assert again.text == scene.text == sc.dump_toml(again.raw)
    # Reseeding and a new law regenerate the text; it rebuilds those scenes too.
    for other in (sc.reseeded(scene, 9), scene.with_friction(Coulomb(0.3))):
        assert_same_scene(sc.parse_scenario(other.text), other)


def test_example_text_is_the_file() -> None:
    """A scene loaded from a file keeps the file's text, and tomli-w text of it is equivalent."""
    path = ROOT / "scenarios" / "pillar.toml"
    scene = sc.load_scenario(path)
    assert scene.text == path.read_text(encoding="utf-8")
    assert_same_scene(sc.parse_scenario(sc.dump_toml(scene.raw)), scene)


@pytest.mark.parametrize("kind", BodyKind.labels())
def test_every_body_kind_label_accepted(kind: str) -> None:
    """Every BodyKind label is a [[body]] kind; Body.kind keeps it, Scene.kinds has its code."""
    scene = sc.parse_scenario(BASE.replace('kind = "fixed"', f'kind = "{kind}"'))
    assert scene.bodies[0].kind == kind
    assert scene.kinds.dtype == np.int32
    assert scene.kinds.tolist() == [BodyKind.from_label(kind), BodyKind.DYNAMIC]


# ------------------------------------------------------------------------------------------
# Scenes shipped with the package
# ------------------------------------------------------------------------------------------


def test_bundled_scenes_are_the_examples() -> None:
    """scenarios/ links to the package's scenes, and bundled_scenes() names each of them."""
    assert (ROOT / "scenarios").resolve() == (ROOT / "taichi_ice" / "scenarios").resolve()
    assert sc.bundled_scenes() == tuple(p.stem for p in EXAMPLES)


@pytest.mark.parametrize("name", ["pillar", "pillar.toml"])
def test_bundled_scene_by_name(name: str, tmp_path: Path, monkeypatch) -> None:
    """From any directory, a bare scene name with no such file loads the bundled scene."""
    monkeypatch.chdir(tmp_path)
    scene = sc.load_scenario(name)
    bundled = ROOT / "taichi_ice" / "scenarios" / "pillar.toml"
    assert Path(scene.source).resolve() == bundled.resolve()
    assert scene.text == bundled.read_text(encoding="utf-8")


def test_local_file_wins_over_bundled(tmp_path: Path, monkeypatch) -> None:
    """A file in the working directory is loaded even when a bundled scene has its name."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "pillar.toml").write_text(BASE, encoding="utf-8")
    scene = sc.load_scenario("pillar.toml")
    assert scene.source == "pillar.toml" and scene.names == ("pillar", "floe")


@pytest.mark.parametrize("path", ["nope", "nope.toml", "elsewhere/pillar.toml"])
def test_missing_scene_lists_bundled(path: str, tmp_path: Path, monkeypatch) -> None:
    """A missing file that is no bundled name is named, with the bundled scenes listed."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ScenarioError) as info:
        sc.load_scenario(path)
    message = str(info.value)
    assert message.startswith(f"{Path(path)}: cannot read the scene file")
    assert all(name in message for name in sc.bundled_scenes())


# ------------------------------------------------------------------------------------------
# Polygons, centroids and mass properties
# ------------------------------------------------------------------------------------------


def test_polygon_body_centroid() -> None:
    """A polygon body sits at its (shapely) centroid, its outline exactly where it was written."""
    vertices = [[0.0, 0.0], [2.0, 0.0], [2.5, 1.0], [0.5, 1.5]]
    angle, position = 0.4, np.array([5.0, -1.0])
    text = BASE + POLYGON_BODY.format(vertices=vertices).replace(
        "position = [10.0, 0.0]", f"position = {position.tolist()}\nangle = {angle}"
    )
    body = sc.parse_scenario(text).bodies[2]
    written = affinity.translate(
        affinity.rotate(Polygon(vertices), angle, origin=(0.0, 0.0), use_radians=True), *position
    )
    centroid = written.centroid
    np.testing.assert_allclose(body.position, [centroid.x, centroid.y], atol=POSITION_ATOL)
    # The stored outline is centred on its own centroid ...
    local = Polygon(body.vertices).centroid
    assert abs(local.x) < POSITION_ATOL and abs(local.y) < POSITION_ATOL
    # ... and placed in the world it is the outline as written.
    np.testing.assert_allclose(
        body.world_vertices(), np.asarray(written.exterior.coords)[:-1], atol=POSITION_ATOL
    )


def test_polygon_field_centroid() -> None:
    """Polygon field blocks sit at their centroid, the outline placed at the lattice point."""
    vertices = [[0.0, 0.0], [0.6, 0.0], [0.0, 0.45]]
    scene = sc.scene_from_dict(_polygon_field(vertices))
    lattice = scene.fields[0].lattice()
    assert len(scene.bodies) == len(lattice)
    for body, point in zip(scene.bodies, lattice):
        c = affinity.translate(Polygon(vertices), *point).centroid
        np.testing.assert_allclose(body.position, [c.x, c.y], atol=POSITION_ATOL)


def _polygon_field(vertices) -> dict:
    """A field of polygon blocks (no width and length)."""
    data = field_dict(shape="polygon", vertices=vertices)
    del data["field"][0]["width"], data["field"][0]["length"]
    return data


def test_masses_and_inertias() -> None:
    """Mass = rho d area (shapely); I = m (w^2 + l^2) / 12 for a rectangle, / 24 for a rhombus."""
    ice = "\n[ice]\ndensity = 900.0\nthickness = 0.5\n"
    polygon = [[0.0, 0.0], [2.0, 0.0], [2.5, 1.0], [0.5, 1.5]]
    scene = sc.parse_scenario(BASE + ice + POLYGON_BODY.format(vertices=polygon))
    rho_d = 900.0 * 0.5
    m_diamond, m_rect = rho_d * 1.0 * 1.0 / 2, rho_d * 1.0 * 0.5
    np.testing.assert_allclose(scene.masses[:2], [m_diamond, m_rect], rtol=MASS_RTOL)
    np.testing.assert_allclose(
        scene.inertias[:2],
        [m_diamond * (1.0 + 1.0) / 24, m_rect * (1.0 + 0.25) / 12],
        rtol=MASS_RTOL,
    )
    assert scene.masses[2] == pytest.approx(rho_d * Polygon(polygon).area, rel=MASS_RTOL)
    # Polygon inertia by the independent triangle decomposition about the centroid.
    c = np.asarray(Polygon(polygon).centroid.coords[0])
    p = np.asarray(polygon) - c
    j = 0.0
    for k in range(len(p)):
        a, b = p[k], p[(k + 1) % len(p)]
        area = 0.5 * (a[0] * b[1] - a[1] * b[0])
        j += area * (a @ a + a @ b + b @ b) / 6.0
    assert scene.inertias[2] == pytest.approx(rho_d * j, rel=MASS_RTOL)


def test_flat_vertices() -> None:
    """vertices_flat with vertex_offsets gives back each body's outline."""
    scene = sc.scene_from_dict(field_dict())
    off = scene.vertex_offsets
    assert off[-1] == len(scene.vertices_flat)
    for i, b in enumerate(scene.bodies):
        np.testing.assert_array_equal(scene.vertices_flat[off[i] : off[i + 1]], b.vertices)


# ------------------------------------------------------------------------------------------
# Examples and start-up
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_loads(path: Path) -> None:
    """Every example scene loads, with a stable time step and at least one dynamic body."""
    scene = sc.load_scenario(path)
    assert scene.source == str(path) and scene.text == path.read_text()
    assert np.any(scene.kinds == BodyKind.DYNAMIC)
    assert 0.0 < scene.dt <= scene.stable_dt


def test_examples_present() -> None:
    """The four documented examples exist."""
    names = {p.name for p in EXAMPLES}
    assert {
        "two_squares.toml",
        "sliding_block.toml",
        "free_field.toml",
        "pushed_field.toml",
    } <= names


def test_loading_does_not_start_taichi() -> None:
    """Importing taichi_ice.scene.parse and loading a scene leave Taichi unstarted."""
    code = textwrap.dedent(
        f"""
        from taichi_ice.scene.parse import load_scenario, reseeded
        scene = load_scenario({str(ROOT / "scenarios" / "pushed_field.toml")!r})
        scene.masses, scene.dt, reseeded(scene, 5)
        from taichi.lang import impl
        from taichi_ice import backend
        assert impl.get_runtime().prog is None, "Taichi was started"
        assert backend.current() is None
        print("ok")
        """
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().endswith("ok")


def test_documented_example_loads() -> None:
    """The complete example in docs/scenarios.md is a valid scene using every key."""
    doc = (ROOT / "docs" / "scenarios.md").read_text()
    text = doc.split("```toml\n", 1)[1].split("```", 1)[0]
    scene = sc.parse_scenario(text, source="docs/scenarios.md")
    assert scene.n_bodies == 3 + 9 * 7
    assert isinstance(scene.friction, RateState) and scene.water is not None
    for table, keys in [
        ("simulation", tables.SIMULATION_KEYS),
        ("ice", tables.ICE_KEYS),
        ("water", tables.WATER_KEYS),
        ("friction", ("law", *RateState.keys())),
    ]:
        assert set(scene.raw[table]) == set(keys), table
    assert set().union(*scene.raw["body"]) == set(tables.BODY_KEYS)
    # A field takes vertices (polygon) or width and length, not both.
    assert set(scene.raw["field"][0]) == set(tables.FIELD_KEYS) - {"vertices"}
