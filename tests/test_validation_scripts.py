"""The validation scripts' own tools (``validation/*.py``, not a package: loaded by path).

``jam_dt.branch`` continues a Simulation's state at another step: at the same step it must
step bit for bit as the Simulation it copied (else its paired branches would measure the
copy, not the step). Its window statistics are held against direct sums, and
``interface_events``' counts against a step whose events are known.
"""

import importlib.util
import json
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


def test_integrator_reaches_every_run_and_names_the_record(tmp_path, monkeypatch):
    """``--integrator`` steps every layout of every step with that integrator and writes
    ``..._INTEGRATOR.json`` saying so; without ``--rule`` or ``--slide-resolution`` it is
    refused. (The ensemble is replaced by one that records its options: the runs are not the
    subject.)"""
    import types

    from taichi_ice.experiments import ensemble, metrics

    jam_dt = _script("jam_dt")
    asked = []

    def fake_run_ensemble(scene, seeds, until, options):
        asked.append((options.integrator, options.dt, len(seeds)))
        row = {"peak_force": 1.0, "friction_energy": 2.0, "released": False}
        series = [{"time": np.array([0.0, 1.0])} for _ in seeds]
        return types.SimpleNamespace(series=series, metrics=[row] * len(seeds), status="ok")

    monkeypatch.setattr(ensemble, "run_ensemble", fake_run_ensemble)
    monkeypatch.setattr(metrics, "probe_force_magnitude", lambda s: np.zeros(2))
    argv = ["--out", str(tmp_path), "--slide-resolution", "0.025", "--steps", "0.4,0.2"]
    assert jam_dt.main([*argv, "--layouts", "3", "--integrator", "midstep"]) == 0
    assert [(a[0], a[2]) for a in asked] == [("midstep", 3), ("midstep", 3)]
    assert asked[0][1] == pytest.approx(2 * asked[1][1])  # 0.4 and 0.2 of one limit
    record = json.loads((tmp_path / "jam_dt_slide_0.025_0.4_0.2_midstep.json").read_text())
    assert record["integrator"] == "midstep" and record["steps"] == [0.4, 0.2]
    assert "git" in record  # the revision that ran it (None outside a git checkout)
    with pytest.raises(SystemExit):  # argparse's error: the option needs the variant
        jam_dt.main(["--out", "unused", "--integrator", "midstep"])


def test_the_interface_events_are_counted_slot_by_slot():
    """``interface_events.count_step`` on seven slots whose step is known: a contact that held
    and ended its interface, one that started one, one whose slip reversed, one that stayed
    stuck, one whose partner changed, an empty slot and a first touch; ``live_mu`` is the law's
    ``mu0 + theta + A ln(V / v_star)``, with V held at v_star from below (mu0 below it under
    ``relaxing``)."""
    from taichi_ice.physics.friction import RateState
    from taichi_ice.physics.slip import NEW_CONTACT, NO_INTERFACE

    events = _script("interface_events")
    law = RateState()
    v = law.v_star
    before = {
        "partner": np.array([[3, 4, 5, 6, 7, -1, 9]]),
        "theta": np.array(
            [[-0.1, NO_INTERFACE, -0.2, NO_INTERFACE, -0.1, NEW_CONTACT, NEW_CONTACT]]
        ),
        "slip": np.array([[2e-3, 0.0, 1e-3, 0.0, 1e-3, 0.0, 0.0]]),
    }
    after = {
        "partner": np.array([[3, 4, 5, 6, 8, -1, 9]]),
        "theta": np.array([[NO_INTERFACE, -0.05, -0.15, NO_INTERFACE, -0.1, NEW_CONTACT, -0.1]]),
        "slip": np.array([[0.5 * v, 3e-3, -1e-3, 0.2 * v, 1e-3, 0.0, 2e-3]]),
    }
    got = events.count_step(before, after, v)
    assert events.births(before, after).tolist() == [[0, 1, 0, 0, 0, 0, 0]]
    assert got == {
        # the partner that changed and the empty slot are not held; the last slot's first
        # touch (it held NEW_CONTACT) starts a contact, not a held contact's new interface
        "contact_steps": 5,
        "stuck_steps": 2,
        "below_steps": 2,
        "ends": 1,
        "births": 1,
        "reversals": 1,
        "theta_ended": 0.1,  # the first slot's -theta where it ended
        "theta_reversed": 0.2,  # the third's, where its slip changed sign
    }
    theta, slip = np.array([-0.1, -0.1, 0.0]), np.array([0.1 * v, -10.0 * v, 1.0])
    want = [law.mu0 - 0.1, law.mu0 - 0.1 + law.A * np.log(10.0), law.mu0 + law.A * np.log(1 / v)]
    assert np.allclose(events.live_mu(theta, slip, law), want, rtol=1e-14, atol=0)
    # Under relaxing the interface is kept below v_star and mu is the paper's mu0 there.
    relaxing = RateState(below_v_star="relaxing")
    want[0] = law.mu0
    assert np.allclose(events.live_mu(theta, slip, relaxing), want, rtol=1e-14, atol=0)


def test_an_interface_s_life_is_counted_from_its_birth_to_its_end():
    """``interface_events.episodes`` on one slot stepped by hand: born in step 0, a reversal
    in step 2 (an end after 2 steps and a birth), ended in step 5 (after 3); a slot whose
    partner changes forgets its birth, and an interface born before the span is not
    counted."""
    from taichi_ice.physics.slip import NO_INTERFACE

    events = _script("interface_events")
    live, none = -0.1, NO_INTERFACE
    # theta, slip and partner of two slots after each step; slot 1 was live before the span
    states = [
        ((none, live), (0.0, 1e-3), (4, 5)),  # before the span
        ((live, live), (1e-3, 1e-3), (4, 5)),  # step 0: slot 0 born
        ((live, none), (2e-3, 0.0), (4, 5)),  # step 1: slot 1 ends (born before: uncounted)
        ((live, live), (-1e-3, 1e-3), (4, 5)),  # step 2: slot 0 reverses; slot 1 born
        ((live, live), (-1e-3, 1e-3), (4, 6)),  # step 3: slot 1's partner changes
        ((live, none), (-1e-3, 0.0), (4, 6)),  # step 4
        ((none, none), (0.0, 0.0), (4, 6)),  # step 5: slot 0 ends
    ]

    def fields(state):
        theta, slip, partner = state
        return {"theta": np.array(theta), "slip": np.array(slip), "partner": np.array(partner)}

    born = np.full(2, -1)
    lengths = [
        events.episodes(fields(a), fields(b), born, k)
        for k, (a, b) in enumerate(zip(states[:-1], states[1:]))
    ]
    assert lengths == [[], [], [2], [], [], [3]]
    born = np.full(2, -1)  # under the other rules a reversal does not end the interface
    kept = [
        events.episodes(fields(a), fields(b), born, k, reversal_ends=False)
        for k, (a, b) in enumerate(zip(states[:-1], states[1:]))
    ]
    assert kept == [[], [], [], [], [], [5]]
    summary = events.episode_summary([2, 3], dt=1e-3)
    assert summary["episodes"] == 2 and summary["episode_median_s"] == pytest.approx(2.5e-3)
    assert summary["episode_1_step"] == 0.0 and summary["episode_at_most_4_steps"] == 1.0
