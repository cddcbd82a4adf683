"""scenarios/pillar.toml against the paper's scene (Lishman et al., "Memory in sea ice
friction", section "Variable friction within a simple DEM", Table 1).

Loads the scene only (no Taichi run); geometry is checked on the bodies' world vertices.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from taichi_ice import load_scenario
from taichi_ice.scene.parse import Scene, reseeded

PATH = Path(__file__).resolve().parents[1] / "scenarios" / "pillar.toml"

# Extents are differences of a few float64 sums and products of sin/cos at angle 0.
ATOL = 1e-9


@pytest.fixture(scope="module")
def scene() -> Scene:
    """The pillar scene as loaded from its file."""
    return load_scenario(PATH)


def _by_kind(scene: Scene, kind: str) -> list:
    return [b for b in scene.bodies if b.kind == kind]


def _extent(vertices: np.ndarray) -> np.ndarray:
    """(width across x, length along y) of an outline."""
    return vertices.max(axis=0) - vertices.min(axis=0)


def test_rubble_is_63_diamonds_of_0_7_by_1_m(scene: Scene) -> None:
    """63 free diamond rubble blocks: short axis 0.7 m across, long axis 1 m along the channel."""
    blocks = _by_kind(scene, "dynamic")
    assert len(blocks) == 63
    for b in blocks:
        assert b.shape == "diamond" and len(b.vertices) == 4
        np.testing.assert_allclose(_extent(b.world_vertices()), [0.7, 1.0], atol=ATOL)


def test_channel_is_5_6_m_wide(scene: Scene) -> None:
    """Two fixed walls whose inner faces are 5.6 m apart and contain every block and the pillar."""
    walls = [b for b in _by_kind(scene, "fixed") if b.shape == "rectangle"]
    assert len(walls) == 2
    verts = [w.world_vertices() for w in walls]
    left, right = sorted(verts, key=lambda v: v[:, 0].mean())
    inner_left, inner_right = left[:, 0].max(), right[:, 0].min()
    assert inner_right - inner_left == pytest.approx(5.6, abs=ATOL)
    others = np.concatenate([b.world_vertices() for b in scene.bodies if b.shape == "diamond"])
    assert others[:, 0].min() >= inner_left - ATOL and others[:, 0].max() <= inner_right + ATOL
    # long enough to reach from below the pusher to well past the pillar
    pillar = next(b for b in scene.bodies if b.name == "pillar")
    for v in verts:
        assert v[:, 1].max() - pillar.position[1] >= 15.0


def test_pillar_is_a_1_m_diamond_2_7_m_across(scene: Scene) -> None:
    """A fixed diamond pillar, both axes 1 m, 2.7 m across the channel, whose force is probed."""
    pillars = [b for b in _by_kind(scene, "fixed") if b.shape == "diamond"]
    assert len(pillars) == 1
    pillar = pillars[0]
    v = pillar.world_vertices()
    np.testing.assert_allclose(_extent(v), [1.0, 1.0], atol=ATOL)
    walls = [b.world_vertices() for b in _by_kind(scene, "fixed") if b.shape == "rectangle"]
    inner_left = min(walls, key=lambda w: w[:, 0].mean())[:, 0].max()
    assert (v[:, 0].max() + v[:, 0].min()) / 2 - inner_left == pytest.approx(2.7, abs=ATOL)
    assert pillar.probe
    assert list(scene.probe_indices) == [scene.names.index(pillar.name)]


def test_pusher_is_a_rectangle_at_0_1_m_per_s_below_the_rubble(scene: Scene) -> None:
    """One kinematic rectangle moving up the channel at 0.1 m/s, below every rubble block."""
    pushers = _by_kind(scene, "kinematic")
    assert len(pushers) == 1
    pusher = pushers[0]
    assert pusher.shape == "rectangle" and pusher.omega == 0.0
    np.testing.assert_array_equal(pusher.velocity, [0.0, 0.1])
    top = pusher.world_vertices()[:, 1].max()
    lowest = min(b.world_vertices()[:, 1].min() for b in _by_kind(scene, "dynamic"))
    assert top <= lowest


def test_ice_and_water_are_table_1(scene: Scene) -> None:
    """Table 1: ice 920 kg/m^3, 0.3 m, k_e 9.75e7 N/m, k_v 3.16e4 Pa s; water 1010 kg/m^3."""
    assert scene.ice.density == 920.0
    assert scene.ice.thickness == 0.3
    assert scene.ice.contact_stiffness == 9.75e7
    assert scene.ice.contact_viscosity == 3.16e4
    assert scene.water is not None and scene.water.density == 1010.0


def test_runs_for_20_s(scene: Scene) -> None:
    """The simulation lasts 20 s, as in the paper's Figures 4-6."""
    assert scene.simulation.duration == 20.0


def test_other_seeds_load(scene: Scene) -> None:
    """Reseeded jitter (the paper: results depend on initial conditions) still loads."""
    for seed in (1, 2, 3):
        other = reseeded(scene, seed)
        assert other.n_bodies == scene.n_bodies
