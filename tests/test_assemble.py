"""Batch assembly (taichi_ice.engine.assemble) and the energy budget (taichi_ice.run.budget),
no kernels.

- A batch refuses worlds that disagree on what one set of kernels compiles in (ice, water,
  the state integrator: a batch mixing integrators once ran every world with the first
  world's), naming the world and what differs; the laws themselves may mix.
- Per-world parameters are the world's own: a world's columns are the same alone and in any
  batch (which is why a batched world equals the world alone).
- The budget's residual and breach test against hand-made terms.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from taichi_ice.codes import EnergyTerm, RestRule
from taichi_ice.engine.assemble import MAX_VERTS_LIMIT, assemble
from taichi_ice.errors import ScenarioError
from taichi_ice.physics.friction import Coulomb, MemoryOnly, RateState, SteadyState
from taichi_ice.run import budget
from taichi_ice.scene.parse import load_scenario, reseeded, scene_from_dict

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def pushed():
    return load_scenario(ROOT / "scenarios" / "pushed_field.toml")


def test_worlds_that_cannot_share_kernels_are_refused(pushed):
    """Mixing the state integrator is an error naming the world (Coulomb has none)."""
    base = pushed.with_friction(RateState())
    other = [base.with_friction(Coulomb(0.3)), base.with_friction(RateState(method="rk4"))]
    with pytest.raises(ValueError, match=r"world 2 .*integrator"):
        assemble([base, *other])


def test_laws_mix_in_one_batch_each_with_its_own_row(pushed):
    """Coulomb, rate-and-state and its variants share a batch; each world's columns are its
    law's: Coulomb as A = B = 0 with mu0 = mu and no memory, the steady-state law with its
    short t_c, memory-only with B = A, the rest rule as its code."""
    laws = [
        Coulomb(0.3),
        RateState(below_v_star="healing"),
        SteadyState(B=0.2),
        MemoryOnly(A=0.07),
    ]
    host = assemble([pushed.with_friction(law) for law in laws]).host
    assert host["world_mu0"].tolist() == [0.3, 0.872, 0.872, 0.872]
    assert host["world_A"].tolist() == [0.0, 0.05, 0.05, 0.07]
    assert host["world_B"].tolist() == [0.0, 0.112, 0.2, 0.07]
    assert host["world_memory"].tolist() == [0, 1, 1, 1]
    assert host["world_t_c"].tolist() == [1.0, 3.0, 0.1, 3.0]
    assert host["world_rest_rule"].tolist() == [
        RestRule.PAPER,
        RestRule.HEALING,
        RestRule.PAPER,
        RestRule.PAPER,
    ]
    only_coulomb = assemble([pushed.with_friction(Coulomb(0.3))])
    assert only_coulomb.layout.coulomb and "world_A" not in only_coulomb.host


def test_worlds_with_other_ice_values_share_a_layout(pushed):
    """The [ice] table's values are model data: worlds that differ in them make one batch,
    of the layout each has alone (one set of kernels), with each world's own columns; only
    the crushing strength's presence, which compiles its cap in or out, must agree."""
    raw = dict(pushed.raw)
    ice = {"thickness": 0.5, "contact_stiffness": 2e8, "contact_viscosity": 1e4}
    raw["ice"] = {**raw.get("ice", {}), **ice, "tangential_stiffness": 0.3}
    other = scene_from_dict(raw)
    batch = assemble([pushed, other])
    alone = assemble([other])
    assert batch.layout == alone.layout.replace(
        n_bodies=batch.layout.n_bodies,
        n_probes=batch.layout.n_probes,
        n_small=batch.layout.n_small,
        n_large=batch.layout.n_large,
        n_local_verts=batch.layout.n_local_verts,
    )
    host = batch.host
    assert host["world_contact_stiffness"].tolist() == [pushed.ice.contact_stiffness, 2e8]
    assert host["world_contact_viscosity"].tolist() == [pushed.ice.contact_viscosity, 1e4]
    assert host["world_tangential_stiffness"].tolist() == [pushed.ice.tangential_stiffness, 0.3]
    # The thicker world's floes are heavier: masses are per body.
    start = host["world_body_start"]
    heavier = host["body_mass"][start[1] : start[2]]
    np.testing.assert_allclose(heavier, alone.host["body_mass"])
    raw["ice"] = {**raw["ice"], "crushing_strength": 1e6}
    with pytest.raises(ValueError, match=r"world 1 .*crushing_strength"):
        assemble([pushed, scene_from_dict(raw)])


def test_a_world_has_the_same_columns_alone_and_in_a_batch(pushed):
    """The law columns of a world do not depend on its batch."""
    a = pushed.with_friction(RateState(t_c=2.0))
    b = reseeded(pushed, 7).with_friction(RateState(B=0.2))
    alone = assemble([b]).host
    batch = assemble([a, b]).host
    for name in ("world_B", "world_t_c", "world_memory", "world_rest_rule"):
        assert batch[name][1] == alone[name][0], name
    assert batch["world_t_c"].tolist() == [2.0, 3.0]
    start = batch["world_body_start"]
    np.testing.assert_array_equal(batch["body_pos"][start[1] : start[2]], alone["body_pos"])


def test_too_many_vertices_is_a_scene_error_naming_the_body():
    """A polygon beyond the kernels' vertex limit is refused when the scene is read, and by
    assemble when a scene is built by hand, before any field exists."""
    n = MAX_VERTS_LIMIT + 1

    def ring(count):
        angles = np.linspace(0.0, 2.0 * np.pi, count, endpoint=False)
        return np.stack([np.cos(angles), np.sin(angles)], 1)

    def tables(vertices):
        body = {"name": "round", "shape": "polygon", "position": [0.0, 0.0]}
        return {"simulation": {"duration": 1.0}, "body": [{**body, "vertices": vertices}]}

    with pytest.raises(ScenarioError, match=f"'round'.*{n} vertices"):
        scene_from_dict(tables(ring(n).tolist()))
    scene = scene_from_dict(tables(ring(n - 1).tolist()))
    body = dataclasses.replace(scene.bodies[0], vertices=ring(n))
    with pytest.raises(ScenarioError, match=f"'round' has {n} vertices"):
        assemble([dataclasses.replace(scene, bodies=(body,))])


def test_budget_residual_and_breach_on_hand_made_terms():
    """residual = (kinetic + elastic)(0) + work in - held - dissipated; a breach is energy
    created beyond half of what came in."""
    start = np.zeros((2, len(EnergyTerm)))
    start[:, EnergyTerm.KINETIC] = 10.0
    now = np.zeros((2, len(EnergyTerm)))
    now[:, EnergyTerm.WORK_IN] = 5.0
    now[:, EnergyTerm.FRICTION] = 6.0
    now[0, EnergyTerm.KINETIC] = 8.0  # 15 in, 14 accounted: 1 J went missing
    now[1, EnergyTerm.KINETIC] = 17.0  # 15 in, 23 accounted: 8 J created (> 7.5)
    terms, initial = budget.as_series(now), budget.as_series(start)
    np.testing.assert_allclose(budget.residual(terms, initial), [1.0, -8.0])
    np.testing.assert_allclose(budget.came_in(terms, initial), [15.0, 15.0])
    assert budget.breached(now, start).tolist() == [1]
    assert budget.SERIES[EnergyTerm.WORK_IN] == "work_in"
    assert budget.SERIES[EnergyTerm.FRICTION] == "friction_energy"


SIZES = ("n_bodies", "n_local_verts", "n_probes", "n_small", "n_large", "slots", "nbr_len",
         "hash_size")  # fmt: skip


def _squares(n: int, walls: bool = False):
    """``n`` unit squares on a 2 m grid, at rest; four walls around them if ``walls``."""
    side = int(np.ceil(np.sqrt(n)))
    body = [
        {"name": f"s{k}", "shape": "rectangle", "width": 1.0, "length": 1.0,
         "position": [2.0 * (k % side), 2.0 * (k // side)]}
        for k in range(n)
    ]  # fmt: skip
    if walls:
        far = 2.0 * side + 1.0
        for name, (x, y, w, h) in {
            "south": (far / 2 - 1, -2, far + 2, 1), "north": (far / 2 - 1, far, far + 2, 1),
            "west": (-2, far / 2 - 1, 1, far + 2), "east": (far, far / 2 - 1, 1, far + 2),
        }.items():  # fmt: skip
            body.append({"name": name, "shape": "rectangle", "width": w, "length": h,
                         "position": [x, y], "kind": "fixed"})  # fmt: skip
    raw = {"simulation": {"duration": 1.0}, "ice": {"density": 920.0, "thickness": 0.3},
           "friction": {"law": "coulomb", "mu": 0.5}, "body": body}  # fmt: skip
    return scene_from_dict(raw)


def test_every_scene_of_up_to_256_bodies_compiles_for_the_same_sizes():
    """Every scene of up to 256 bodies (``options.BODY_FLOOR``) compiles for the same sizes
    (``assemble.CAPACITY_FLOORS``) and contact slots, walls or none, so that a user's edits
    and a sweep over layouts of up to 256 floes compile once (per largest outline, 4, 8 or 16
    vertices: a switch of the kernels): every bundled scene (2 to 67 bodies), and 1, 252
    (with four walls) and 256 squares; past 256 bodies the next power of two, and the slots
    the walls ask (6 without, 8 with four)."""
    from taichi_ice.engine.options import BODY_FLOOR, DEFAULT_SMALL_SLOTS, LARGE_SLOTS

    scenes = [load_scenario(p) for p in sorted((ROOT / "scenarios").glob("*.toml"))]
    scenes += [_squares(1), _squares(BODY_FLOOR - 4, walls=True), _squares(BODY_FLOOR)]
    sizes = {tuple(getattr(assemble([s]).layout, k) for k in SIZES) for s in scenes}
    assert len(sizes) == 1, sizes
    (first,) = sizes
    assert dict(zip(SIZES, first))["n_bodies"] == BODY_FLOOR
    assert dict(zip(SIZES, first))["slots"] == DEFAULT_SMALL_SLOTS + LARGE_SLOTS
    bare, walled = assemble([_squares(300)]).layout, assemble([_squares(300, walls=True)]).layout
    assert (bare.n_bodies, walled.n_bodies) == (512, 512)
    assert (bare.slots, walled.slots) == (DEFAULT_SMALL_SLOTS, DEFAULT_SMALL_SLOTS + LARGE_SLOTS)


def test_the_sizes_compiled_are_capacities_and_the_host_arrays_the_scenes_counts():
    """A layout's sizes are capacities: powers of two (with a floor) up to 4096, then
    multiples of a power of two 8-16 times below the count, never below it and never more
    than twice it (an eighth above 4096); the host arrays keep the scenes' counts, and
    ``state.padded`` fills the rest of a field with zeros (a world past the scenes' starts
    and ends at the last body)."""
    from taichi_ice.engine.assemble import CAPACITY_POW2_MAX, capacity
    from taichi_ice.engine.schema import var
    from taichi_ice.engine.state import padded

    for n in [*range(1, 300), 4095, 4096, 4097, 10_000, 99_999, 100_000, 1_000_000]:
        c = capacity(n)
        assert n <= c <= (2 * n if n <= CAPACITY_POW2_MAX else n * 1.125), n
        assert capacity(c) == c  # a capacity is its own
    assert [capacity(n, 8) for n in (1, 8, 9)] == [8, 8, 16]
    assert capacity(10_000) == 10_240 and capacity(1_000_000) == 1_048_576

    scene = load_scenario(ROOT / "scenarios" / "two_squares.toml")
    batch = assemble([scene, scene, scene])
    assert (batch.n_bodies, batch.real.n_worlds, batch.n_probes) == (6, 3, 3)
    assert (batch.layout.n_bodies, batch.layout.n_worlds, batch.layout.n_probes) == (256, 8, 8)
    assert batch.layout.max_verts == 4 and batch.host.body_mass.shape == (6,)
    edges = padded(batch.host.world_body_start, var("world_body_start"), batch.layout)
    assert edges.tolist() == [0, 2, 4, 6, 6, 6, 6, 6, 6]
    mass = padded(batch.host.body_mass, var("body_mass"), batch.layout)
    assert mass.tolist() == [*batch.host.body_mass.tolist(), *[0.0] * 250]
