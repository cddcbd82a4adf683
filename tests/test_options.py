"""The engine's settings are one validated value (``Options``), and nothing compiled into a
World depends on its time step: a World reloads at another dt and steps bit for bit as one
built for that dt (issue 29)."""

from __future__ import annotations

import numpy as np
import pytest

from taichi_ice import load_scenario
from taichi_ice.engine.options import MAX_SLOTS, Options
from taichi_ice.errors import StabilityError, UsageError


@pytest.mark.parametrize(
    "change, words",
    [
        ({"dt": 0.0}, "positive finite"),
        ({"dt": float("nan")}, "positive finite"),
        ({"dt": "1e-4"}, "number of seconds"),
        ({"dt": True}, "number of seconds"),
        ({"slots": 0}, f"1 to {MAX_SLOTS}"),
        ({"slots": MAX_SLOTS + 1}, f"1 to {MAX_SLOTS}"),
        ({"slots": 2.5}, "whole number"),
        ({"precision": "f16"}, "precision must be one of"),
        ({"stepping": "threads"}, "stepping must be one of"),
        ({"arch": "tpu"}, "arch = 'tpu'"),
        ({"energy": "yes"}, "energy must be True or False"),
        ({"timestep": 1e-4}, "unknown engine option(s) timestep"),
        ({"integrator": "verlet"}, "integrator must be one of"),
    ],
)
def test_a_bad_option_is_refused_when_made_naming_it(change, words):
    with pytest.raises(UsageError) as info:
        Options().replace(**change)
    assert words in str(info.value)


def test_a_simulation_without_its_energy_budget_is_refused_in_one_line():
    """A Simulation's series, run files and divergence check read the budget: energy=False
    is refused when it is made, naming the option and the World that steps without one
    (it used to fail inside the constructor asking for energy=True)."""
    from taichi_ice import Simulation, load_scenario

    with pytest.raises(UsageError, match=r"energy=False.*World\(scenes, energy=False\)"):
        Simulation(load_scenario("two_squares"), energy=False)


def test_the_time_step_is_decided_once_against_the_stability_limit():
    """dt None is the smallest of the scenes' dt; a dt above the smallest stability limit is
    refused, naming both, unless forced."""
    scene = load_scenario("two_squares")
    dt, limit = Options().time_step([scene])
    assert (dt, limit) == (scene.dt, scene.stable_dt) and dt < limit
    above = 1.5 * scene.stable_dt
    with pytest.raises(StabilityError, match=f"dt = {above:g} s is above the stability limit"):
        Options(dt=above).time_step([scene])
    assert Options(dt=above, force_dt=True).time_step([scene]) == (above, scene.stable_dt)


def test_the_integrator_is_the_options_else_the_files_else_the_laws():
    """Options.for_scenes decides a batch's integrator: the option's when given (every
    scene's dt = "auto" then follows it), else the one the scenes' files name, else the
    midstep step when every world has Coulomb friction and the Euler step when one has a law
    with a memory; files that name two are refused, naming both and the fix."""
    from taichi_ice.physics.friction import RateState

    coulomb = load_scenario("two_squares")
    assert coulomb.friction.name == "coulomb"
    memory = coulomb.with_friction(RateState())
    limit = coulomb.stable_dt

    def decided(scenes, **given):
        options, stepped = Options(**given).for_scenes(scenes)
        return options.integrator, [round(s.dt / limit, 12) for s in stepped]

    assert decided([coulomb]) == ("midstep", [0.6])
    assert decided([memory]) == ("euler", [0.05])
    assert decided([coulomb, memory]) == ("euler", [0.2, 0.05])
    assert decided([coulomb], integrator="coupled") == ("coupled", [0.2])
    assert decided([memory, coulomb], integrator="midstep") == ("midstep", [0.05, 0.6])
    euler = coulomb.with_integrator("euler")  # as a file with [simulation] integrator
    assert euler.simulation.integrator == "euler"
    assert decided([euler, coulomb]) == ("euler", [0.2, 0.2])
    assert decided([euler], integrator="midstep") == ("midstep", [0.6])
    assert Options(dt=1e-4).for_scenes([coulomb])[0].dt == 1e-4  # a given dt stays
    with pytest.raises(UsageError, match=r"different integrators \(coupled, euler") as info:
        Options().for_scenes([euler, coulomb.with_integrator("coupled")])
    assert "--integrator" in str(info.value)


def _fields(world) -> dict:
    """Every declared field of a World, as arrays (read in one launch: ``Transfer.read``,
    held to ``to_numpy`` by tests/test_transfer.py)."""
    return world.transfer.read()


def _stepped(world, steps: int) -> dict:
    """``world``'s fields after ``steps`` steps (checked)."""
    world.advance(steps)
    world.check()
    return _fields(world)


def _same(got: dict, expected: dict, *where) -> dict:
    """``got`` is, field for field, ``expected`` (and is returned); a failure names
    ``where`` and the field."""
    for name in expected:
        assert np.array_equal(got[name], expected[name]), (*where, name)
    return got


def test_water_and_a_constant_force_are_values_not_another_layout():
    """Water drag and a body's constant force are data (zero coefficients, a zero force for
    a body without them): two squares with water and a push share the layout of the dry,
    unpushed pair, and a World reloaded with them after a dry run steps, field for field, as
    it did when it was built for them; the drag and the push act (the floes end elsewhere
    than dry), and a dry run on it after them is the dry run again."""
    import copy

    from taichi_ice.codes import BodyEnergy
    from taichi_ice.engine.assemble import assemble
    from taichi_ice.engine.world import World
    from taichi_ice.scene.parse import scene_from_dict

    dry = load_scenario("two_squares")
    raw = copy.deepcopy(dry.raw)
    raw["water"] = {}
    raw["body"][0]["force"] = [40.0, 5.0]  # N
    wet = scene_from_dict(raw, source=dry.source)
    assert wet.water is not None and assemble([wet]).layout == assemble([dry]).layout

    world = World([wet], dt=dry.dt)
    expected = _stepped(world, 3000)
    world.reload([dry], dt=dry.dt)
    dry_run = _stepped(world, 3000)
    assert not np.array_equal(dry_run["body_pos"], expected["body_pos"])
    # The drag dissipated and the push worked on the wet run only (the budget's columns).
    wet_e, dry_e = expected["body_energy"][:2], dry_run["body_energy"][:2]
    assert np.all(wet_e[:, BodyEnergy.DRAG] > 0.0) and wet_e[0, BodyEnergy.WORK] != 0.0
    assert not np.any(dry_e[:, [BodyEnergy.DRAG, BodyEnergy.WORK]])
    world.reload([wet], dt=dry.dt)
    _same(_stepped(world, 3000), expected)
    world.reload([dry], dt=dry.dt)
    _same(_stepped(world, 3000), dry_run)


def test_a_world_reloaded_at_another_dt_steps_as_one_built_for_it():
    """The layout a World compiles for holds no dt (the runaway bound is a distance per step,
    compared with |v| dt at run time): the same scenes assembled at dt and dt / 3 give equal
    layouts, and a World reloaded at dt / 3 holds, 400 steps later, exactly the fields of a
    World built at dt / 3, with a rate-and-state contact sliding (its memory integrates dt).

    One World, so one compile: its first 400 steps, on new fields built at dt / 3, are the
    reference; a run at dt then leaves its fields full before the reload at dt / 3."""
    from taichi_ice.engine.assemble import assemble
    from taichi_ice.engine.world import World

    scene = load_scenario("sliding_block")
    small = scene.dt / 3
    assert assemble([scene]).layout == assemble([scene], Options(dt=small)).layout

    world = World([scene], dt=small)
    world.advance(400)
    world.check()
    expected = _fields(world)
    world.reload([scene])
    assert world.dt == scene.dt
    world.advance(400)
    coarse = world.positions()
    world.reload([scene], dt=small)
    assert world.dt == small and world.options.dt == small
    world.advance(400)
    world.check()
    assert world.contact_counts().tolist() == [1]
    _same(_fields(world), expected)
    # And the step at dt / 3 is not the step at dt: the reload took the new dt.
    assert not np.array_equal(coarse, world.positions())


@pytest.fixture
def pool(monkeypatch):
    """A pool of this test's own, as ``Simulation`` finds it (``pool.POOL``)."""
    from taichi_ice.engine import pool as pool_module

    mine = pool_module.WorldPool()
    monkeypatch.setattr(pool_module, "POOL", mine)
    return mine


def test_a_simulation_reuses_a_world_no_one_holds_and_steps_as_a_new_one(pool):
    """A Simulation takes its World from the process's pool: once the first Simulation is
    gone its World is reloaded for the next scenes of that layout (built once, then
    reloaded), and the run is, field for field, that of the World when it was built for it,
    here with the analytic step and a rate-and-state contact (contact memory, the
    remembered contact force) after another run left the World's fields full."""
    from taichi_ice.experiments.validation import dem_scenes
    from taichi_ice.run.simulation import Simulation

    scene = dem_scenes.collision(dem_scenes.OFFSET, "rate-state")
    # The reference first, on the new fields of the pool's one World (one compile).
    fresh = Simulation(scene, integrator="analytic")
    expected = {}
    for until in (0.002, 0.01):  # in the contact (touching at t = 0, 4.9 ms), and after
        fresh.run(until=until)
        expected[until] = _fields(fresh.world)
    del fresh
    assert (pool.built, pool.reloaded, pool.idle()) == (1, 0, 1)
    # The face-on collision (the same layout: the law's kind is compiled in) fills it.
    sim = Simulation(dem_scenes.collision(0.0, "rate-state"), integrator="analytic")
    assert (pool.built, pool.reloaded) == (1, 1)
    sim.run(until=0.01)
    first = sim.world
    del sim
    assert pool.idle() == 0  # still held, by `first`
    del first
    assert (pool.built, pool.reloaded, pool.idle()) == (1, 1, 1)

    reused = Simulation(scene, integrator="analytic")
    assert (pool.built, pool.reloaded) == (1, 2)
    # Its kernels ran: a run on it compiles nothing, and its progress bar says so.
    assert reused.world.compiled("sampled")
    for until in (0.002, 0.01):
        reused.run(until=until)
        got = _same(_fields(reused.world), expected[until], until)
        if until < 0.005:
            assert np.any(got["contact_force"] != 0.0)  # the contact was met


def _with_squares(scene, n: int):
    """``scene`` with ``n`` more copies of its last square, 3 m apart above it, falling in
    at 0.5 m/s along y (no gravity: they drift, and the first meets the pair's right square
    at about 4 s)."""
    import copy

    from taichi_ice.scene.parse import scene_from_dict

    raw = copy.deepcopy(scene.raw)
    last = raw["body"][-1]
    for k in range(1, n + 1):
        extra = {key: value for key, value in last.items() if key != "probe"}
        extra.update(name=f"extra{k}", position=[last["position"][0], 3.0 * k])
        extra["velocity"] = [0.0, -0.5]
        raw["body"].append(extra)
    return scene_from_dict(raw, source=scene.source)


def test_a_scene_of_other_counts_within_the_capacities_reuses_the_world(pool):
    """The sizes a World compiles for are capacities (``assemble.capacity``: 256 bodies at
    least): two squares, then the same scene with three more, run on one World (built once,
    reloaded), and the second run of five is, field for field (the unused rows too), that of
    the World when it was built for five; 260 more (262 bodies) need another layout."""
    from taichi_ice.engine.assemble import assemble
    from taichi_ice.run.simulation import Simulation

    base = load_scenario("two_squares")
    five = _with_squares(base, 3)
    assert assemble([five]).layout == assemble([base]).layout
    assert assemble([_with_squares(base, 10)]).layout == assemble([base]).layout
    assert assemble([_with_squares(base, 260)]).layout.n_bodies == 512
    fresh = Simulation(five)  # the reference, on the pool's one World as built (one compile)
    expected = {}
    for until in (0.25, 1.0):  # in the pair's collision, and after
        fresh.run(until=until)
        expected[until] = _fields(fresh.world)
    del fresh
    first = Simulation(base)
    first.run(until=0.3)  # past the collision: the fields hold a contact's leftovers
    del first
    reused = Simulation(five)
    assert (pool.built, pool.reloaded) == (1, 2)
    for until in (0.25, 1.0):
        reused.run(until=until)
        _same(_fields(reused.world), expected[until], until)
    assert len(reused.positions(0)) == 5
    assert reused.positions(0)[2:, 1].tolist() == pytest.approx([2.5, 5.5, 8.5])


def test_a_world_on_the_fields_of_one_gone_steps_as_one_on_new_fields(monkeypatch):
    """A World that is collected gives its fields and compiled stages to the next World of
    its layout (``engines.Engines``): that World runs, field for field, as the first World
    did on new fields, here the rate-and-state sliding block after a run of it with other
    coefficients left its fields full (one set of fields, so one compile)."""
    from taichi_ice.engine import world as world_module
    from taichi_ice.engine.world import World
    from taichi_ice.physics.friction import RateState

    engines = world_module.Engines()
    monkeypatch.setattr(world_module, "ENGINES", engines)
    block = load_scenario("sliding_block").with_friction(RateState())
    other = load_scenario("sliding_block").with_friction(RateState(A=0.02, B=0.03, t_c=1.0))
    new = World([block], stepping="worlds")
    assert engines.built == 1
    expected = _stepped(new, 3000)
    data = new.data
    del new
    used = World([other], stepping="worlds")
    assert used.data is data and (engines.built, engines.reused) == (1, 1)
    used.advance(4000)
    used.check()
    del used
    assert engines.idle() == 1
    again = World([block], stepping="worlds")
    assert again.data is data and (engines.built, engines.reused) == (1, 2)
    got = _same(_stepped(again, 3000), expected)
    theta = got["contact_theta"][got["contact_partner"] >= 0]
    assert theta.size and np.all(theta != 0.0)  # rate-and-state memory was compared


def test_a_simulation_gone_in_a_reference_cycle_leaves_its_world_to_the_next(pool):
    """A Simulation unreachable but in a reference cycle (as a failed run's traceback holds
    one) is freed only by Python's collector; the pool runs it before building, so the next
    Simulation of the layout is handed that World, even with automatic collection off."""
    import gc

    from taichi_ice.run.simulation import Simulation

    scene = load_scenario("two_squares")
    gc.disable()
    try:
        first = Simulation(scene)
        first.me = first  # a cycle: only the collector frees it
        del first
        assert pool.idle() == 0  # not freed yet
        second = Simulation(scene)
    finally:
        gc.enable()
    assert (pool.built, pool.reloaded) == (1, 1)
    del second


def test_a_world_still_held_is_never_handed_out(pool):
    """A World that a live Simulation or a name still holds stays as it is: the next
    Simulation of its layout builds its own."""
    from taichi_ice.run.simulation import Simulation

    scene = load_scenario("two_squares")
    first = Simulation(scene)
    first.run(until=0.02)
    kept = first.positions(0).copy()
    world = first.world
    del first
    second = Simulation(scene)
    assert second.world is not world and (pool.built, pool.reloaded) == (2, 0)
    second.run(until=0.05)
    assert np.array_equal(world.positions()[: len(kept)], kept)


def test_a_world_with_other_slots_than_a_new_one_is_not_reused(pool):
    """A Simulation that asks for no slots gets the scenes' default, as a new World would: an
    idle World built with other slots is passed over (a reused one could stop for want of
    slots where a new one runs)."""
    from taichi_ice.engine.assemble import assemble
    from taichi_ice.run.simulation import Simulation

    scene = load_scenario("two_squares")
    default = assemble([scene]).layout.slots
    Simulation(scene, slots=default + 1)
    assert pool.idle() == 1
    sim = Simulation(scene)
    assert sim.world.layout.slots == default and (pool.built, pool.reloaded) == (2, 0)
    del sim
    again = Simulation(scene)
    assert again.world.layout.slots == default and (pool.built, pool.reloaded) == (2, 1)


def test_worlds_of_an_earlier_taichi_start_are_dropped(pool, monkeypatch):
    """``backend.init(..., reinit=True)`` frees every field: the pool forgets the Worlds of
    an earlier start instead of handing one out."""
    from taichi_ice import backend
    from taichi_ice.run.simulation import Simulation

    scene = load_scenario("two_squares")
    Simulation(scene)
    assert len(pool) == 1 and pool.idle() == 1
    monkeypatch.setattr(backend, "generation", lambda: -1)
    Simulation(scene)
    assert len(pool) == 1 and (pool.built, pool.reloaded) == (2, 0)


def test_a_world_built_after_a_simulation_takes_the_kernels_of_its_idle_world(pool):
    """A Simulation gone leaves its World idle in the pool, for the next Simulation; a World
    built directly for the same layout (as the tests and the validation studies build
    theirs) takes that World's fields and compiled stages (``Engines.take`` asks the pool to
    let go of it, ``WorldPool.release``) instead of compiling its own, and steps, field for
    field, as a World on new fields."""
    from taichi_ice.engine import world as world_module
    from taichi_ice.engine.world import World
    from taichi_ice.run.simulation import Simulation

    scene = load_scenario("two_squares")
    sim = Simulation(scene)
    sim.run(until=0.3)  # past the collision: the fields hold a contact's leftovers
    options, key, data = sim.world.options, sim.world.engine_key, sim.world.data
    del sim
    assert pool.idle() == 1
    engines = world_module.ENGINES
    built, reused = engines.built, engines.reused
    again = World([scene], options)
    assert again.engine_key == key and again.data is data
    assert (engines.built, engines.reused, len(pool)) == (built, reused + 1, 0)
    new = World([scene], options)  # `again` holds those fields: new ones
    assert new.data is not data and engines.built == built + 1
    _same(_stepped(again, 3000), _stepped(new, 3000))


def test_a_world_gone_in_a_reference_cycle_still_gives_its_kernels_to_the_next(monkeypatch):
    """A World that is unreachable but in a reference cycle is freed only by Python's
    collector; ``Engines.take`` runs it before building, so the next World of the layout
    takes the cycle's fields even with automatic collection off."""
    import gc

    from taichi_ice.engine import world as world_module
    from taichi_ice.engine.world import World

    engines = world_module.Engines()
    monkeypatch.setattr(world_module, "ENGINES", engines)
    scene = load_scenario("two_squares")
    gc.disable()
    try:
        first = World([scene], stepping="worlds")
        first.me = first  # a cycle: only the collector frees it
        data = first.data
        del first
        assert engines.idle() == 0  # not freed yet
        again = World([scene], stepping="worlds")
    finally:
        gc.enable()
    assert again.data is data and (engines.built, engines.reused) == (1, 1)
