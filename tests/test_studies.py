"""The validation studies (``taichi-ice validate --quick --speed``): files and physical facts."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from taichi_ice.experiments.validation import validate_command

# Quick Figure 3 steps are t_c / 75 (t_c / 150 for the fast sinusoid): second-order errors
# of ~1e-5 in the sinusoids' fundamental.
GAIN_REL_TOL = 1e-3
PHASE_TOL_DEG = 0.05
# What the exponential method leaves after a step: round-off and the 1 ps sampled jump.
STEP_EXACT_TOL = 1e-12
ORDER_TOL = 0.2

FILES = (
    "fig3_single_interface.png",
    "single_interface.json",
    "stability.png",
    "stability.json",
    "speed_accuracy.png",
    "speed_accuracy.json",
)


@pytest.fixture(scope="module")
def validated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("validate")
    assert validate_command(str(out), speed=True, quick=True) == 0
    return out


def load(out: Path, name: str) -> dict:
    return json.loads((out / name).read_text())


def test_validate_writes_every_file(validated):
    """validate --speed writes the three charts (non-trivial PNGs) and their JSON summaries."""
    for name in FILES:
        path = validated / name
        assert path.is_file(), name
        if name.endswith(".png"):
            assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
            assert 10_000 < path.stat().st_size < 300_000, name


def test_figure3_summary_errors_against_exact(validated):
    """Every profile reports each method's max error; exponential is exact after a step."""
    summary = load(validated, "single_interface.json")
    assert summary["law"]["law"] == "rate-state"
    profiles = summary["profiles"]
    assert set(profiles) == {"step", "ramp", "fast_sinusoid", "slow_sinusoid"}
    for name, entry in profiles.items():
        assert set(entry["max_error"]) == {"exponential", "euler", "implicit", "rk4"}, name
        assert all(0.0 <= e < 1e-2 for e in entry["max_error"].values()), name
    assert profiles["step"]["max_error"]["exponential"] < STEP_EXACT_TOL
    # First-order methods are the least accurate at the same step.
    for entry in profiles.values():
        errors = entry["max_error"]
        assert errors["exponential"] < errors["euler"] and errors["rk4"] < errors["implicit"]


def test_sinusoids_follow_the_transfer_function(validated):
    """Fast slip: mu in phase with ln V (gain ~A); slow: 180 degrees out (gain ~B - A)."""
    profiles = load(validated, "single_interface.json")["profiles"]
    fast, slow = profiles["fast_sinusoid"], profiles["slow_sinusoid"]
    for entry in (fast, slow):
        assert entry["gain_rel_error"] < GAIN_REL_TOL
        assert abs(entry["phase_error_deg"]) < PHASE_TOL_DEG
        assert abs(entry["phase_measured_deg"] - entry["phase_theory_deg"]) < PHASE_TOL_DEG
    assert fast["omega_t_c"] > 10 and abs(fast["phase_measured_deg"]) < 10.0
    assert slow["omega_t_c"] < 0.1 and abs(slow["phase_measured_deg"]) > 170.0
    assert fast["gain_measured"] == pytest.approx(0.05, rel=0.01)  # ~A
    assert slow["gain_measured"] == pytest.approx(0.062, rel=0.01)  # ~B - A


def test_stability_summary(validated):
    """Explicit Euler past 2 t_c and RK4 past 2.785 t_c diverge and are refused by default;
    exponential and implicit decay at any step."""
    cases = load(validated, "stability.json")["cases"]
    for case in cases:
        assert case["diverges"] == case["refused"], case
        if case["diverges"]:
            assert case["final_deviation_over_offset"] > 1.0
            assert case["amplification_measured"] == pytest.approx(
                case["amplification_theory"], rel=1e-6
            )
            assert "t_c" in case["refusal"]
        else:
            assert case["final_deviation_over_offset"] < 1.0
    assert {c["method"] for c in cases if c["diverges"]} == {"euler", "rk4"}


def test_speed_accuracy_summary(validated):
    """Both precisions and both back ends are measured; float64 orders are the methods' own."""
    summary = load(validated, "speed_accuracy.json")
    orders = summary["convergence_order_f64"]
    expected = {
        "ramp/exponential": 2,
        "ramp/euler": 1,
        "ramp/implicit": 1,
        "ramp/rk4": 4,
        "sinusoid/exponential": 2,
        "sinusoid/rk4": 2,
    }
    for key, order in expected.items():
        assert orders[key] == pytest.approx(order, abs=ORDER_TOL), key
    cost = summary["ns_per_interface_step"]
    assert len(cost) == 16 and all(ns > 0 for ns in cost.values())
    combos = {(r["precision"], r["backend"]) for r in summary["runs"]}
    assert combos == {("f64", "taichi"), ("f64", "numpy"), ("f32", "taichi"), ("f32", "numpy")}
    for run in summary["runs"]:
        assert len(run["wall_s_per_interface"]) == len(run["dt"]) == len(run["max_error"])


def test_the_studies_compile_without_the_advanced_passes_unless_the_user_asks(monkeypatch):
    """``validate`` compiles its studies as the suite does (same bits, test_backend) unless
    ``TAICHI_ICE_OPTIMIZE`` is set, and hands the speed study's workers the user's setting."""
    import os
    import subprocess
    from types import SimpleNamespace

    from taichi_ice.backend import OPTIMIZE_ENV
    from taichi_ice.experiments.validation import compile_for_studies, speed_accuracy

    monkeypatch.delenv(OPTIMIZE_ENV, raising=False)
    assert compile_for_studies() == "on"  # what the user asked for: the default
    assert os.environ[OPTIMIZE_ENV] == "0"  # what the studies (and their workers) get
    monkeypatch.setenv(OPTIMIZE_ENV, "1")
    assert compile_for_studies() == "on" and os.environ[OPTIMIZE_ENV] == "1"
    monkeypatch.setenv(OPTIMIZE_ENV, "full")
    assert compile_for_studies() == "full" and os.environ[OPTIMIZE_ENV] == "full"
    monkeypatch.setenv(OPTIMIZE_ENV, "off")
    assert compile_for_studies() == "off" and os.environ[OPTIMIZE_ENV] == "off"

    seen = []

    def fake_run(cmd, env, **kwargs):
        seen.append(env.get(OPTIMIZE_ENV))
        Path(cmd[cmd.index("--result") + 1]).write_text("{}")
        return SimpleNamespace(returncode=0)

    monkeypatch.setattr(subprocess, "run", fake_run)
    for optimize in (True, False, "full", None):
        speed_accuracy._run_worker("f64", "cpu", 10, True, optimize)
    assert seen == ["on", "off", "full", "off"]  # None: the environment's, inherited
