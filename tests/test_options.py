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
    ],
)
def test_a_bad_option_is_refused_when_made_naming_it(change, words):
    with pytest.raises(UsageError) as info:
        Options().replace(**change)
    assert words in str(info.value)


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


def _fields(world) -> dict:
    holders = (world.model, world.data, world.hash, world.neighbours)
    return {name: getattr(h, name).to_numpy() for h in holders for name in h.names}


def test_a_world_reloaded_at_another_dt_steps_as_one_built_for_it():
    """The layout a World compiles for holds no dt (the runaway bound is a distance per step,
    compared with |v| dt at run time): the same scenes assembled at dt and dt / 3 give equal
    layouts, and a World reloaded at dt / 3 holds, 400 steps later, exactly the fields of a
    World built at dt / 3, with a rate-and-state contact sliding (its memory integrates dt)."""
    from taichi_ice.engine.assemble import assemble
    from taichi_ice.engine.world import World

    scene = load_scenario("sliding_block")
    small = scene.dt / 3
    assert assemble([scene]).layout == assemble([scene], Options(dt=small)).layout

    reused = World([scene])
    reused.advance(50)
    reused.reload([scene], dt=small)
    assert reused.dt == small and reused.options.dt == small
    fresh = World([scene], dt=small)
    for world in (reused, fresh):
        world.advance(400)
        world.check()
    assert reused.contact_counts().tolist() == [1]
    got, expected = _fields(reused), _fields(fresh)
    for name in expected:
        assert np.array_equal(got[name], expected[name]), name
    # And the step at dt / 3 is not the step at dt: the reload took the new dt.
    coarse = World([scene])
    coarse.advance(400)
    assert not np.array_equal(coarse.positions(), fresh.positions())
