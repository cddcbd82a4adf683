"""The DEM accuracy and stability study (``taichi-ice validate --dem``) and its references.

- The collision ODE (``collision_ode``: SciPy on the polygon overlap) agrees with the closed
  form of a face-on collision, a damped oscillator with no tension.
- A free collision forced just beyond the stability limit that the study measured stops with
  a one-line DivergenceError from ``taichi-ice run`` (no traceback), and completes just below.
- The study runs end to end at a tiny size (``--quick``), and its DEM collisions are within
  1 % of the ODE at a tenth of the stability limit.
"""

from __future__ import annotations

import copy
import json
import math

import pytest

from taichi_ice import backend
from taichi_ice.commands.cli import main
from taichi_ice.experiments.validation import collision_ode, dem_accuracy, dem_scenes, dem_workers
from taichi_ice.tomlio import dump_toml

# DOP853 at rtol 1e-11 on the overlap geometry against the scalar ODE of the same oscillator:
# they agree to the solver's tolerance, far below the DEM errors measured (>= 1e-4).
ODE_RTOL = 1e-7
# The clamp releases the contact when k d + c d' = 0: the restitution exceeds the linear one
# by O(zeta) (3.6 % here), the duration barely moves.
CLAMP_RESTITUTION_RTOL = 0.05
CLAMP_DURATION_RTOL = 5e-3

# The largest dt / stable_dt the free collision (the offset collision, Coulomb) survived, and
# the smallest at which it diverged: the engine stops a run whose budget shows half the
# energy that came in created, which this collision's does between the two (scans from 0.9
# to 2.5 by 0.1 and from 1.40 to 1.50 by 0.02: every step up to 1.42 runs, every one from
# 1.44 stops; `taichi-ice validate --dem`, docs/accuracy.md). (1.875 and 1.983 with the
# tangential dashpot at 0.5 k_v L, a damping ratio of ~0.13 here against 0.25 now: an
# explicit dashpot lowers the limit; 1.64 and 1.66 of a 21 % smaller limit with it critical.)
FREE_COLLISION_SURVIVES = 1.42
FREE_COLLISION_DIVERGES = 1.44
# Just beyond and just below: 5 % past each end of the bracket.
MARGIN = 0.05

# At dt = 0.1 stable_dt the collisions are within 1 % of the ODE (restitution, duration, spin).
COLLISION_RTOL_AT_0_1 = 0.01
# The pushed box's energy budget closes to well under 1 % of the work in.
BUDGET_RTOL = 0.01


def test_collision_ode_matches_the_closed_form_of_a_face_on_collision():
    """Face on, the polygon ODE is the damped oscillator m d'' = -max(k d + c d', 0)."""
    scene = dem_scenes.collision(0.0, "coulomb")
    ode = collision_ode.solve_collision(scene, dem_scenes.COLLISION_END)
    ((touch, apart),) = ode["contacts"]
    v = ode["velocity"]
    restitution = (v[1, 0] - v[0, 0]) / dem_scenes.CLOSING_SPEED
    m0, m1 = scene.masses
    m_eff = m0 * m1 / (m0 + m1)
    width = dem_scenes.BLOCK_LENGTH
    k, c = scene.ice.contact_stiffness * width, scene.ice.contact_viscosity * width
    duration, clamped = collision_ode.clamped_oscillator(k, c, m_eff, dem_scenes.CLOSING_SPEED)
    assert apart - touch == pytest.approx(duration, rel=ODE_RTOL)
    assert restitution == pytest.approx(clamped, rel=ODE_RTOL)
    assert abs(ode["omega"]).max() < 1e-9  # face on: nothing turns
    # The clamped oscillator against the linear closed form.
    zeta = c / (2.0 * math.sqrt(k * m_eff))
    omega_d = math.sqrt(k / m_eff) * math.sqrt(1.0 - zeta * zeta)
    linear = math.exp(-zeta * math.pi / math.sqrt(1.0 - zeta * zeta))
    assert duration == pytest.approx(math.pi / omega_d, rel=CLAMP_DURATION_RTOL)
    assert linear < clamped < linear * (1.0 + CLAMP_RESTITUTION_RTOL)


def _collision_file(tmp_path, ratio: float):
    """The free collision of the stability study as a scene file whose sampling makes
    ``dt = ratio x stable_dt`` exact, stepped by the Euler step, whose limit the study
    measured (``FREE_COLLISION_*``; the midstep step, Coulomb's default, survives 14 x);
    returns (path, dt)."""
    scene = dem_scenes.collision(dem_scenes.OFFSET, "coulomb")
    dt = ratio * scene.stable_dt
    every = round(dem_scenes.COLLISION_END / dt)
    raw = copy.deepcopy(dict(scene.raw))
    raw["simulation"].update(
        duration=every * dt,
        output_interval=every * dt,
        series_interval=every * dt,
        integrator="euler",
    )
    path = tmp_path / f"collision_{ratio:g}.toml"
    path.write_text(dump_toml(raw))
    return path, dt


@pytest.mark.parametrize(
    ("ratio", "diverges"),
    [
        (FREE_COLLISION_DIVERGES * (1.0 + MARGIN), True),
        (FREE_COLLISION_SURVIVES * (1.0 - MARGIN), False),
    ],
)
def test_free_collision_beyond_its_measured_limit_stops_with_a_clear_error(
    tmp_path, capsys, ratio, diverges
):
    """Past the measured limit the run ends in one line naming the divergence and the fix."""
    path, dt = _collision_file(tmp_path, ratio)
    out = tmp_path / "run.h5"
    code = main(["run", str(path), "--dt", repr(dt), "--force-dt", "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if diverges:
        assert code == 2
        (line,) = [ln for ln in err.splitlines() if ln.startswith("taichi-ice: error:")]
        assert "diverged" in line and "lower dt" in line
    else:
        assert code == 0
        assert "error" not in err


# Layout 93 of the pillar ensemble (Coulomb, mu = 0.5, seed 93; ``dem_ensemble``): with the
# coupled step at 0.8 stable_dt (nominal, 0.768 actual) its jam goes unstable at 14.5 s,
# bodies spinning up to 10-11 rad/s (2026-11-27 and again 2026-12-02). From its state at 14 s
# the coupled step runs on at 0.6 (|omega| <= 3.2 rad/s) and diverges at 0.7 and above; at
# 0.6 the whole run completes, as all 128 layouts did (docs/accuracy.md, "Over 128 layouts").
HARD_JAM_SEED = 93
HARD_JAM_DIVERGES_AT = (14.0, 15.0)  # s


@pytest.mark.parametrize(("ratio", "diverges"), [(0.8, True), (0.6, False)])
def test_the_coupled_step_loses_a_hard_jam_at_0_8_stable_dt_and_holds_it_at_0_6(ratio, diverges):
    """Where the coupled step fails: a jam harder than the stability study's (which holds to
    1.42 stable_dt) is lost at 0.8 and kept at 0.6, the whole 20 s."""
    import re

    from taichi_ice.engine.options import Options
    from taichi_ice.errors import DivergenceError
    from taichi_ice.run.simulation import Simulation
    from taichi_ice.scene.parse import reseeded

    scene = reseeded(dem_scenes.pillar("coulomb"), HARD_JAM_SEED)
    dt = dem_accuracy.field_step(ratio, scene.stable_dt)
    sim = Simulation([scene], options=Options(dt=dt, force_dt=True, integrator="coupled"))
    if diverges:
        with pytest.raises(DivergenceError, match="created") as exc:
            sim.run(until=20.0)
        at = float(re.search(r"at t = (\S+) s", str(exc.value)).group(1))
        assert HARD_JAM_DIVERGES_AT[0] < at < HARD_JAM_DIVERGES_AT[1], str(exc.value)
    else:
        result = sim.run(until=20.0)
        assert result.status == "complete"


def test_quick_study_runs_and_its_collisions_match_the_ode(tmp_path):
    """--quick end to end: its files, and collisions within 1 % of the ODE at 0.1 stable_dt."""
    summary = dem_accuracy.run(tmp_path, quick=True)
    for name in ("dem_accuracy.json", "dem_accuracy.png", "dem_stability.png"):
        assert (tmp_path / name).stat().st_size > 0
    on_disk = json.loads((tmp_path / "dem_accuracy.json").read_text())
    assert set(on_disk) >= {"points", "orders", "timing", "collision_reference"}
    # The wall times' kernels: compiled as this process's Taichi was (the suite: without
    # the advanced passes, conftest).
    assert on_disk["advanced_optimization"] == {"f64": backend.optimized()}
    points = summary["points"]
    checked = 0
    for p in points:
        if "collision" in p["scene"]:
            assert p["ratio"] == pytest.approx(0.1)
            assert p["error"] < COLLISION_RTOL_AT_0_1, p
            assert p["wall_per_simulated_s"] > 0
            checked += 1
    assert checked == 5  # face on: restitution, duration; offset: those and the spin
    residuals = [p["error"] for p in points if p["measure"] == "budget residual"]
    assert len(residuals) == 1 and residuals[0] < BUDGET_RTOL


def test_worker_processes_give_the_runs_of_this_process_bit_for_bit(tmp_path):
    """The study's worker processes (a process per precision and integrator, their indexes
    merged into one per precision) run what this process runs, to the last bit: every
    state, series and error of ``--quick``, run here and in a worker; ``reuse`` reads the
    merged index."""
    import numpy as np

    here = dem_accuracy.run(tmp_path / "here", quick=True)
    cfg = dem_accuracy.config(quick=True)
    parts = dem_workers.spawned(tmp_path / "spawned", cfg, ["f64"], None, 1, lambda _m: None)
    ours = json.loads((tmp_path / "here" / "dem_runs" / "f64" / "index.json").read_text())
    theirs = parts["f64"]
    assert [w["integrator"] for w in theirs["workers"]] == ["euler"]
    assert len(theirs["records"]) == len(ours["records"]) > 0
    timing = {"wall_s", "wall_per_step_s", "wall_per_simulated_s"}
    for mine, spawned in zip(ours["records"], theirs["records"]):
        assert {k: v for k, v in mine.items() if k not in timing | {"arrays"}} == {
            k: v for k, v in spawned.items() if k not in timing | {"arrays"}
        }
        if "arrays" in mine:
            assert spawned["arrays"] == f"euler/{mine['arrays']}"
            with np.load(tmp_path / "here" / "dem_runs" / "f64" / mine["arrays"]) as a:
                path = tmp_path / "spawned" / "dem_runs" / "f64" / spawned["arrays"]
                with np.load(path) as b:
                    assert sorted(a.files) == sorted(b.files)
                    for name in a.files:
                        assert np.array_equal(a[name], b[name], equal_nan=True), name
    again = dem_accuracy.run(tmp_path / "spawned", quick=True, reuse=True)
    assert [(p["scene"], p["measure"], p["error"]) for p in again["points"]] == [
        (p["scene"], p["measure"], p["error"]) for p in here["points"]
    ]


def test_a_failed_worker_stops_the_others_and_names_its_command(tmp_path):
    """``dem_workers.run_workers``: a worker that exits non-zero raises with its exit code
    and command, and the worker still running is stopped, not waited for (it would sleep
    60 s)."""
    import os
    import sys
    import time

    sleeper = [sys.executable, "-c", "import time; time.sleep(60)"]
    failing = [sys.executable, "-c", "import sys; sys.exit(3)"]
    env = dict(os.environ)
    jobs = [("f64", "euler", sleeper, env), ("f64", "coupled", failing, env)]
    start = time.perf_counter()
    with pytest.raises(RuntimeError, match=r"exit 3\).*sys\.exit\(3\)"):
        dem_workers.run_workers(jobs, 2, lambda _m: None)
    assert time.perf_counter() - start < 30


def test_timing_runs_the_span_beyond_where_the_run_stopped():
    """``_timed`` times ``span`` more seconds: a run already past the span still steps
    (``Simulation.run`` takes the time to reach, not a duration)."""
    from taichi_ice.run.simulation import Simulation

    scene = dem_scenes.collision(dem_scenes.OFFSET, "coulomb")
    dt = dem_accuracy.DEFAULT_RATIO * scene.stable_dt
    sim = Simulation([dem_scenes.with_step(scene, dt, dem_accuracy.SAMPLE)], dt=dt)
    sim.run(until=0.05)
    timing = dem_accuracy._timed(sim, 0.02)
    assert timing["timed_steps"] == pytest.approx(0.02 / dt, abs=1)
    assert timing["wall_per_step_s"] > 0
    assert sim.time == pytest.approx(0.07, abs=dt)


def test_the_analysis_keeps_each_integrator_its_own_series_order_and_default_step():
    """Errors of 0.05 (h / 0.2) (Euler) and 0.05 (h / 0.4)^2 (analytic) over one ladder: each
    integrator gets its
    own fitted order (1 and 2, the exponents put in), its own interpolated error and its own
    recommended step; the tables name both. No Taichi: the analysis of made-up points."""
    from taichi_ice.experiments.validation import dem_analysis, dem_charts, dem_stability

    ladder = (0.0125, 0.05, 0.2, 0.8)
    points = []
    for integ, power, h0 in (("euler", 1.0, 0.2), ("analytic", 2.0, 0.4)):
        for law in ("coulomb", "rate-state"):
            for h in ladder:
                points.append(
                    {
                        "scene": "face-on collision",
                        "measure": "restitution",
                        "law": law,
                        "integrator": integ,
                        "precision": "f64",
                        "ratio": h,
                        "dt": h * 1e-4,
                        "error": 0.05 * (h / h0) ** power,
                        "value": None,
                        "wall_per_simulated_s": 1e-3 / h,
                        "status": "complete",
                    }
                )
    orders = dem_analysis._orders(points, {})
    for law in ("coulomb", "rate-state"):
        euler = orders[f"face-on collision: restitution/{law}/euler/f64"]
        analytic = orders[f"face-on collision: restitution/{law}/analytic/f64"]
        assert euler["order"] == pytest.approx(1.0, abs=0.01)
        assert analytic["order"] == pytest.approx(2.0, abs=0.01)
    key = "face-on collision: restitution"
    at_euler = dem_analysis.error_at(points, key, "euler")
    at_analytic = dem_analysis.error_at(points, key, "analytic")
    # Interpolated log-log between 0.2 and 0.8: exact for a power law.
    assert at_euler(0.4) == pytest.approx(0.1, rel=1e-9)
    assert at_analytic(0.4) == pytest.approx(0.05, rel=1e-9)
    assert at_analytic(1.6) is None  # beyond the ladder
    limits = {"jam": {"largest_surviving_ratio": 2.0}}
    picked = {
        integ: dem_stability.recommend(
            limits, {key: dem_analysis.error_at(points, key, integ)}, {key: 0.06}
        )["dt_safety"]
        for integ in ("euler", "analytic")
    }
    # Euler: 0.05 (s / 0.2) <= 0.06 up to s = 0.24; analytic: 0.05 (s / 0.4)^2 up to 0.438
    # (the candidates: 0.2 and 0.4).
    assert picked == {"euler": 0.2, "analytic": 0.4}
    summary = {
        "points": points,
        "orders": orders,
        "timing": {"collision/coulomb/analytic/f64": {"wall_per_step_s": 4e-6}},
        "settings": {
            "laws": ["coulomb", "rate-state"],
            "integrators": ["euler", "analytic"],
            "stable_dt": {"collisions": 1e-4, "pillar, pushed box": 1e-4},
        },
        "pillar_parting_at_a_quarter_step": [],
        "chaos": {},
    }
    text = dem_charts.tables(summary)
    assert "| face-on collision: restitution | coulomb | analytic | f64 |" in text
    assert "coulomb, analytic" in text  # the orders' column
    assert "| 2.00 (0.00) |" in text


def test_a_law_alone_gets_the_step_its_own_errors_allow():
    """The recommendation on one law's errors alone (``recommendation_by_law``, what a
    default step per law rests on): face-on restitution 0.05 (h / 0.4)^2 with Coulomb and
    four times that with rate and state, against the 0.02 bound of ``ACCURACY``: Coulomb
    alone allows h <= 0.253 (the candidate 0.25), rate and state h <= 0.126 (0.1), the
    largest over both laws as rate and state; a jam's limit of 0.45 caps every one at 0.2
    (2 x below it). The tables say each, and why the next candidate was refused."""
    from taichi_ice.experiments.validation import dem_analysis, dem_charts

    points = [
        {
            "scene": "face-on collision",
            "measure": "restitution",
            "law": law,
            "integrator": "analytic",
            "precision": "f64",
            "ratio": h,
            "error": scale * 0.05 * (h / 0.4) ** 2,
        }
        for law, scale in (("coulomb", 1.0), ("rate-state", 4.0))
        for h in (0.0125, 0.05, 0.2, 0.8)
    ]
    wide = {"jam": {"largest_surviving_ratio": 2.0}}
    picked = {
        law: dem_analysis._recommend(points, wide, "analytic", law)["dt_safety"]
        for law in ("coulomb", "rate-state", None)
    }
    assert picked == {"coulomb": 0.25, "rate-state": 0.1, None: 0.1}
    tight = {"jam": {"largest_surviving_ratio": 0.45}}
    coulomb = dem_analysis._recommend(points, tight, "analytic", "coulomb")
    assert coulomb["dt_safety"] == 0.2 and coulomb["jam_margin"] == pytest.approx(2.25)
    assert "margin 1.80 < 2" in coulomb["refused"]["0.25"]
    summary = {
        "points": points,
        "orders": {},
        "timing": {},
        "settings": {
            "laws": ["coulomb", "rate-state"],
            "integrators": ["analytic"],
            "stable_dt": {"collisions": 1e-4, "pillar, pushed box": 1e-4},
        },
        "pillar_parting_at_a_quarter_step": [],
        "chaos": {},
        "recommendation": {"analytic": dem_analysis._recommend(points, wide, "analytic")},
        "recommendation_by_law": {
            "analytic": {
                law: dem_analysis._recommend(points, wide, "analytic", law)
                for law in ("coulomb", "rate-state")
            }
        },
    }
    text = dem_charts.tables(summary)
    assert (
        "- on coulomb's errors alone: **0.25**, margin in the jam 8.00 (the next refused: " in text
    )
    assert "face-on collision: restitution 0.0281 > 0.02" in text
    assert "- on rate-state's errors alone: **0.1**" in text


def test_coulombs_default_step_is_the_one_the_committed_records_chose():
    """Coulomb friction's default (the midstep step at ``MIDSTEP_SAFETY``) is what the
    committed study recommends on Coulomb's errors alone, and the committed 256-layout
    ensemble ran it: every layout through its 20 s, no measure moved beyond the sampling
    error against the Euler step at a quarter of its old default. A default changed without
    records that back it fails here."""
    import re
    from pathlib import Path

    from taichi_ice.physics import timestep

    assert timestep.default_integrator("coulomb") == "midstep"
    assert timestep.default_integrator("rate-state") == "euler"
    validation = Path(__file__).resolve().parents[1] / "docs" / "validation"
    text = (validation / "dem_accuracy.md").read_text()
    section = text.split("Recommended `dt_safety` with the midstep integrator")[1]
    chosen = re.search(r"on coulomb's errors alone: \*\*([0-9.]+)\*\*", section)
    assert float(chosen.group(1)) == timestep.MIDSTEP_SAFETY
    record = json.loads((validation / "dem_ensemble_256_coulomb.json").read_text())
    (run,) = [
        r
        for r in record["runs"]
        if (r["integrator"], r["nominal"]) == ("midstep", timestep.MIDSTEP_SAFETY)
    ]
    assert run["status"] == "complete" and len(run["seeds"]) == 256
    against = record["comparisons"][
        f"coulomb: midstep {timestep.MIDSTEP_SAFETY:g} against euler 0.05"
    ]
    for measure in ("peak_force", "friction_energy", "concentration"):
        assert against[measure]["n"] == 256 and against[measure]["within_sampling_error"]
        assert not against[measure]["differs"]
    assert not against["released"]["differs"]


def test_validate_refuses_an_unknown_integrator_in_one_line(capsys):
    from taichi_ice.commands import validate

    with pytest.raises(SystemExit) as exc:
        validate.main(["dem_accuracy", "--integrators", "euler,verlet", "--out", "unused"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "unknown integrator(s) verlet" in err and "euler, analytic" in err
    assert "Traceback" not in err


def test_the_step_shift_is_held_against_the_sampling_error_in_closed_form():
    """``dem_ensemble.paired`` on four layouts whose values shift by 1, 2, 3, 4: mean 2.5,
    its 95 % t interval 2.5 -+ t(0.975, 3) 1.2910 / 2 (t = 3.18245, from tables), the
    baseline mean's standard error 2.5820 / 2; the exact Wilcoxon p of four positive
    differences 2 / 2^4. ``holm``: p = 0.01, 0.04, 0.03 of three tests adjust to 0.03, 0.06,
    0.06 (3 x 0.01, then max(0.03, 2 x 0.03), then max(0.06, 1 x 0.04)). ``mcnemar``: 5
    released only in the baseline and none only in the other, p = 2 / 2^5; as many each
    way, p = 1."""
    from taichi_ice.experiments.validation import dem_ensemble

    base = [10.0, 12.0, 14.0, 16.0]
    got = dem_ensemble.paired(base, [11.0, 14.0, 17.0, 20.0])
    half = 3.182446305 * 1.2909944487 / 2.0
    assert got["shift"] == pytest.approx(2.5)
    assert got["shift_ci95"] == pytest.approx([2.5 - half, 2.5 + half], rel=1e-8)
    assert got["base_se"] == pytest.approx(2.5819888975 / 2.0, rel=1e-9)
    assert got["shift_rel"] == pytest.approx(2.5 / 13.0)
    assert got["within_sampling_error"] is False  # the interval [0.45, 4.55] misses 0
    assert got["wilcoxon_p"] == pytest.approx(0.125)
    assert 0.0 < got["ks_p"] <= 1.0
    # Shifts of +3, -1, +1, -3 (mean 0): the interval holds 0.
    assert dem_ensemble.paired(base, [13.0, 11.0, 15.0, 13.0])["within_sampling_error"] is True
    # A layout whose value is not finite is left out of both.
    assert dem_ensemble.paired([1.0, float("nan"), 3.0], [1.0, 2.0, 3.0])["n"] == 2

    assert dem_ensemble.holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06])
    assert dem_ensemble.holm([0.5, 0.9]) == pytest.approx([1.0, 1.0])

    released = dem_ensemble.mcnemar([1] * 5 + [0] * 3, [0] * 8)
    assert (released["only_base"], released["only_other"]) == (5, 0)
    assert released["p"] == pytest.approx(2.0 / 2**5)
    assert dem_ensemble.mcnemar([1, 0, 1, 0], [0, 1, 0, 1])["p"] == pytest.approx(1.0)


def test_the_ensemble_holds_each_laws_default_step_against_the_quarter_step():
    """``validate --dem``'s ensemble runs the step a user gets by default for each law
    (``timestep.default_integrator`` at ``default_safety``: Coulomb's midstep step at 0.6
    stable_dt, rate and state's Euler step at 0.05) and holds it against the Euler step at
    0.05 and at 0.2 (issue 30's baseline), each pair of cases compared once."""
    from taichi_ice.experiments.validation import dem_ensemble
    from taichi_ice.physics import timestep

    pairs = {frozenset(pair) for pair in dem_ensemble.COMPARISONS}
    assert len(pairs) == len(dem_ensemble.COMPARISONS)  # no pair twice, in either order
    for law in dem_ensemble.LAWS:
        default = (timestep.default_integrator(law), timestep.default_safety(law))
        assert default in dem_ensemble.CASES
        for against in (("euler", 0.05), ("euler", 0.2)):
            if default != against:
                assert frozenset((default, against)) in pairs, (law, default, against)
    assert ("midstep", timestep.MIDSTEP_SAFETY) in dem_ensemble.CASES


def test_quick_ensemble_runs_and_compares_on_the_same_layouts(tmp_path):
    """``dem_ensemble --quick``: two layouts of the pillar scene at 0.2 and 0.8 stable_dt
    until the rubble has met the pillar; its files, every layout's measures, and the
    comparison's verdict."""
    from taichi_ice.experiments.validation import dem_ensemble

    summary = dem_ensemble.run(tmp_path, quick=True, log=lambda _: None)
    assert (tmp_path / "dem_ensemble.png").stat().st_size > 0
    on_disk = json.loads((tmp_path / "dem_ensemble.json").read_text())
    runs = on_disk["runs"]
    ((key, c),) = on_disk["comparisons"].items()
    assert len(runs) == 2 and all(r["status"] == "complete" for r in runs)
    assert runs[0]["seeds"] == runs[1]["seeds"] and len(runs[0]["seeds"]) == 2
    assert all(min(r["peak_force"]) > 0 for r in runs)  # the rubble met the pillar
    assert key == "coulomb: euler 0.8 against euler 0.2"
    assert c["peak_force"]["n"] == 2 and isinstance(c["any_differs"], bool)
    assert summary["comparisons"][key]["any_differs"] == c["any_differs"]


def test_the_ensemble_runs_the_cases_and_layouts_asked_for(tmp_path, capsys):
    """``--cases`` keeps the comparisons among the cases run and refuses, in one line, a
    case compared with nothing; ``--layouts`` sets how many layouts each case runs;
    ``--laws`` which friction laws."""
    from taichi_ice.commands import validate
    from taichi_ice.errors import UsageError
    from taichi_ice.experiments.validation import dem_ensemble

    cases, comparisons = dem_ensemble.select(
        dem_ensemble.CASES, dem_ensemble.COMPARISONS, [("euler", 0.2), ("coupled", 0.8)]
    )
    assert cases == (("euler", 0.2), ("coupled", 0.8))
    assert comparisons == ((("coupled", 0.8), ("euler", 0.2)),)
    _, three = dem_ensemble.select(
        dem_ensemble.CASES,
        dem_ensemble.COMPARISONS,
        [("euler", 0.2), ("coupled", 0.2), ("coupled", 0.8)],
    )
    assert set(three) == {
        (("coupled", 0.2), ("euler", 0.2)),
        (("coupled", 0.8), ("euler", 0.2)),
        (("coupled", 0.8), ("coupled", 0.2)),
    }
    with pytest.raises(UsageError, match=r"coupled:0\.8 would be compared with no other"):
        dem_ensemble.select(dem_ensemble.CASES, dem_ensemble.COMPARISONS, [("coupled", 0.8)])
    # A step the study does not list (0.4) is held against the baseline and the reference,
    # those of them that run too.
    assert ("midstep", 0.4) not in dem_ensemble.CASES
    _, own = dem_ensemble.select(
        dem_ensemble.CASES, dem_ensemble.COMPARISONS, [("euler", 0.2), ("midstep", 0.4)]
    )
    assert own == ((("midstep", 0.4), ("euler", 0.2)),)
    _, both = dem_ensemble.select(
        dem_ensemble.CASES,
        dem_ensemble.COMPARISONS,
        [("euler", 0.2), ("euler", 0.05), ("midstep", 0.4)],
    )
    assert set(both) == {
        (("euler", 0.2), ("euler", 0.05)),
        (("midstep", 0.4), ("euler", 0.2)),
        (("midstep", 0.4), ("euler", 0.05)),
    }
    with pytest.raises(UsageError, match=r"midstep:0\.4 would be compared with no other"):
        dem_ensemble.select(dem_ensemble.CASES, dem_ensemble.COMPARISONS, [("midstep", 0.4)])
    for argv, said in (
        (["--cases", "coupled:0.8"], "coupled:0.8 would be compared with no other case run"),
        (["--cases", "verlet:0.2,euler:0.2"], "case 'verlet:0.2': write INTEGRATOR:RATIO"),
        (["--layouts", "1"], "--layouts: at least 2"),
        (["--laws", "rate-state,stick"], "unknown law(s) stick: choose from coulomb, rate-state"),
    ):
        with pytest.raises(SystemExit) as exc:
            validate.main(["dem_ensemble", "--out", str(tmp_path / "unused"), *argv])
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert said in err and "Traceback" not in err
    assert not (tmp_path / "unused").exists()  # refused before anything ran

    summary = dem_ensemble.run(
        tmp_path,
        quick=True,
        layouts=3,
        cases=[("euler", 0.2), ("euler", 0.8)],
        laws=["rate-state"],
        log=lambda _: None,
    )
    assert summary["settings"]["layouts"] == 3
    assert summary["settings"]["laws"] == ["rate-state"]
    runs = summary["runs"]
    assert len(runs) == 2 and all(len(r["seeds"]) == 3 for r in runs)
    assert all(r["law"] == "rate-state" for r in runs)
    assert runs[0]["seeds"] == runs[1]["seeds"]
    ((key, c),) = summary["comparisons"].items()
    assert key == "rate-state: euler 0.8 against euler 0.2" and c["peak_force"]["n"] == 3


def test_dem_ensemble_runs_the_coulomb_worlds_at_the_mu_asked_and_refuses_a_bad_one(
    monkeypatch, capsys
):
    """``--mu 0.9`` runs the pillar's Coulomb worlds at mu = 0.9 (rate and state's are left
    alone), and a coefficient that is not a positive number is refused in one line."""
    from taichi_ice.commands import validate
    from taichi_ice.experiments import ensemble
    from taichi_ice.experiments.validation import dem_ensemble

    seen = []

    class Stop(Exception):
        pass

    def capture(scene, seeds, until, options):
        seen.append((scene.friction, len(seeds), options.integrator))
        raise Stop

    monkeypatch.setattr(ensemble, "run_ensemble", capture)
    for law in ("coulomb", "rate-state"):
        with pytest.raises(Stop):
            dem_ensemble.run_case(law, "midstep", 0.6, 3, 1.0, mu=0.9)
    (coulomb, n, integrator), (memory, _, _) = seen
    assert (coulomb.name, coulomb.mu, n, integrator) == ("coulomb", 0.9, 3, "midstep")
    assert memory.name == "rate-state"
    for bad in ("-1", "nan", "x"):
        with pytest.raises(SystemExit) as exc:
            validate.main(["dem_ensemble", "--mu", bad, "--out", "unused"])
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert "a friction coefficient is a number > 0" in err and "Traceback" not in err
