"""The validation scripts' own tools (``validation/*.py``, not a package: loaded by path).

``jam_dt.branch`` continues a Simulation's state at another step: at the same step it must
step bit for bit as the Simulation it copied (else its paired branches would measure the
copy, not the step). Its window statistics are held against direct sums.
"""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from taichi_ice import load_scenario

ROOT = Path(__file__).resolve().parents[1]


def _script(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "validation" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_branch_at_the_same_step_continues_bit_for_bit():
    from taichi_ice.run.simulation import Simulation

    jam_dt = _script("jam_dt")
    scene = load_scenario("two_squares")
    source = Simulation(scene)
    source.run(until=0.2015)  # the squares meet at 0.2 s and touch for a few ms
    assert source.world.contact_counts().sum() > 0  # a contact's memory is copied
    again = jam_dt.branch(source, [scene], source.dt)
    assert again.time == source.time and again.steps == source.steps
    halved = jam_dt.branch(source, [scene], source.dt / 2)
    assert abs(halved.time - source.time) < 1e-12 and halved.dt == source.dt / 2
    assert np.array_equal(halved.positions(0), source.positions(0))
    for sim in (source, again):
        sim.run(until=0.25)
    for read in ("positions", "velocities", "angles", "omegas"):
        assert np.array_equal(getattr(again, read)(0), getattr(source, read)(0)), read
    assert again.energies(0) == source.energies(0)
    # The squares separated: the same step's rebound, and the half step's within Euler's
    # first-order error of it (it is not a copy of the source: its step is its own).
    halved.run(until=0.25)
    v, w = source.velocities(0)[:, 0], halved.velocities(0)[:, 0]
    assert v[0] < 0.0 < v[1] and 0.0 < np.abs(w - v).max() < 0.01 * np.abs(v).max()


def test_the_window_statistics_against_direct_sums():
    jam_dt = _script("jam_dt")
    rng = np.random.default_rng(7)
    time = np.arange(0.0, 2.0001, 0.01)
    force = rng.uniform(0.0, 5.0, size=(3, time.size))
    force[1, time > 1.234] += 100.0
    means = jam_dt.window_means(time, force, [0.0, 1.0, 2.0])
    for k, (lo, hi) in enumerate(((0.0, 1.0), (1.0, 2.0))):
        for row in range(3):
            picked = [f for t, f in zip(time, force[row]) if lo < t <= hi]
            assert np.isclose(means[row, k], sum(picked) / len(picked))
    first = jam_dt.first_above(time, force, 50.0)
    assert np.isnan(first[0]) and np.isnan(first[2]) and np.isclose(first[1], 1.24)
    a, b = rng.normal(size=40), rng.normal(size=40) + 0.5
    shift, se = jam_dt.paired_shift(a, b)
    assert np.isclose(shift, np.mean(b - a))
    assert np.isclose(se, np.std(b - a, ddof=1) / np.sqrt(40))


def test_the_scene_variants_change_only_what_they_name():
    jam_dt = _script("jam_dt")
    paper = jam_dt._scene()
    damped = jam_dt._scene(damping=0.35)
    healing = jam_dt._scene(rule="healing")
    slid = jam_dt._scene(slide=0.1)
    assert paper.friction.below_v_star == "paper" and healing.friction.below_v_star == "healing"
    assert damped.ice.tangential_damping == 0.35 and paper.ice.tangential_damping == 0.25
    assert slid.ice.slide_resolution == 0.1 and paper.ice.slide_resolution == 0.025
    assert slid.ice.tangential_damping == 0.25 and damped.ice.slide_resolution == 0.025
    assert damped.friction == paper.friction == slid.friction and healing.ice == paper.ice
    for variant in (damped, slid):
        assert [b.name for b in variant.bodies] == [b.name for b in paper.bodies]


def test_first_seed_gives_layouts_the_default_ones_do_not_share():
    jam_dt = _script("jam_dt")
    paper = jam_dt._scene()
    default = jam_dt._seeds(paper, 128)
    assert default[0] == paper.simulation.seed and len(set(default)) == 128
    fresh = jam_dt._seeds(paper, 128, first=1000)
    assert fresh == list(range(1000, 1128)) and not set(fresh) & set(default)
    with pytest.raises(SystemExit):  # argparse's error: the option needs a variant
        jam_dt.main(["--out", "unused", "--first-seed", "1000"])
