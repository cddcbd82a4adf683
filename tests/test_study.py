"""The study's statistics: the bootstrap CI against SciPy and the normal closed form; the
claims and their carriers on a dataset whose answers are known; the report it writes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.stats

from taichi_ice.experiments.study import report as study_report
from taichi_ice.experiments.study import stats as study
from taichi_ice.experiments.study.stats import MODELS, bootstrap_ci, verdict

# Two independent Monte Carlo resamplings of the same data agree on a 95 % quantile to about
# this fraction of the standard error (4,000 and 20,000 resamples).
MC_TOLERANCE = 0.08


def test_bootstrap_ci_matches_scipy_and_the_normal_closed_form():
    """Percentile bootstrap CI of a mean: as scipy.stats.bootstrap's, and for n = 400 normal
    values within a few per cent of mean +- 1.96 s / sqrt(n)."""
    rng = np.random.default_rng(3)
    x = rng.normal(2.0, 1.5, 400)
    est, low, high = bootstrap_ci(x)
    se = x.std(ddof=1) / np.sqrt(x.size)
    ref = scipy.stats.bootstrap(
        (x,), np.mean, method="percentile", n_resamples=20000, random_state=1
    ).confidence_interval
    assert est == pytest.approx(x.mean(), rel=1e-12)
    assert abs(low - ref.low) < MC_TOLERANCE * se and abs(high - ref.high) < MC_TOLERANCE * se
    z = scipy.stats.norm.ppf(0.975)
    assert low == pytest.approx(x.mean() - z * se, abs=0.05 * se * z)
    assert high == pytest.approx(x.mean() + z * se, abs=0.05 * se * z)


def test_bootstrap_of_a_constant_and_of_nothing():
    """A constant has a zero-width interval; all-NaN values give NaN, not an error."""
    assert bootstrap_ci(np.full(7, 0.25)) == (0.25, 0.25, 0.25)
    assert all(np.isnan(bootstrap_ci([np.nan, np.nan])))


def test_verdicts():
    """Holds, contradicted or undecided by where the interval lies against zero."""
    assert verdict(0.1, 0.3, +1) == "holds"
    assert verdict(-0.3, -0.1, +1) == "contradicted"
    assert verdict(-0.3, -0.1, -1) == "holds"
    assert verdict(-0.1, 0.2, -1) == "undecided"


def synthetic(layouts: int = 12, fractions=(0.7, 0.85)):
    """A study dataset whose answers are set: mu >= 0.5 jams and holds, mu < 0.5 never jams;
    rate-state and the steady-state law jam and break, memory-only jams and holds (so the
    release is carried by rate); concentration lower under rate-state than mu = 0.5 only."""
    import xarray as xr

    rows = []
    for label, _ in MODELS:
        for f in fractions:
            for seed in range(layouts):
                jam = label in ("mu0.5", "mu0.7", "mu0.9") or label in (
                    "rate-state",
                    "steady-state",
                    "memory-only",
                )
                broken = label in ("rate-state", "steady-state")
                peak = 2e6 + 1e4 * seed if jam else 500.0 + seed
                if label in ("rate-state", "steady-state"):
                    peak = 5e5 + 1e4 * seed
                conc = 0.3 if label == "rate-state" else 0.6
                rows.append((label, f, seed, peak, float(broken or not jam), conc))
    label, f, seed, peak, released, conc = map(np.array, zip(*rows))
    n = len(rows)
    return xr.Dataset(
        {
            "peak_force": ("world", peak),
            "mean_force": ("world", peak / 3),
            "friction_energy": ("world", peak / 10),
            "concentration": ("world", conc),
            "final_force": ("world", np.where(released == 1, 0.0, peak)),
            "released": ("world", released),
            "status": ("world", np.full(n, "complete")),
        },
        coords={
            "world": np.arange(n),
            "seed": ("world", seed),
            "law": ("world", label),
            f"field.{study.FIELD}.area_fraction": ("world", f),
        },
    )


def test_claims_and_carriers_on_a_dataset_with_known_answers():
    """Every claim's verdict and effect is what the synthetic dataset was built to give, and
    the release is carried by rate, the steadier dissipation by rate and memory together."""
    table = study.study_table(synthetic())
    by = {(c["claim"], c.get("model")): c for c in study.claims(table)}
    assert by[("mu = 0.1: blocks slide easily past the pillar", None)]["verdict"] == "holds"
    assert by[("mu = 0.9: the blocks jam", None)]["verdict"] == "holds"
    assert by[("mu = 0.9: the jam is never broken", None)]["verdict"] == "holds"
    assert by[("mu = 0.5: jams form and break", None)]["verdict"] == "contradicted"
    jams = by[("higher friction jams more", None)]
    assert jams["effect"] == 1.0 and jams["n"] == 24
    release = "rate-and-state releases jams more easily than mu = 0.9"
    assert by[(release, "rate-state")]["effect"] == -1.0
    assert by[(release, "memory-only")]["verdict"] == "undecided"  # no difference at all
    carried = {c["claim"]: c["carried_by"] for c in study.carriers(study.claims(table))}
    assert carried[release].startswith("rate (")
    steadier = "rate-and-state dissipates more steadily than mu = 0.5"
    assert carried[steadier].startswith("rate and memory together")
    p = study.summarise(table)["mu0.9"]["pooled"]["jam"]
    assert p["value"] == 1.0 and p["n"] == 24


def _report(out, layouts: int, runs=()) -> dict:
    """The report of the synthetic study of ``layouts`` layouts, into ``out``."""
    from taichi_ice.scene.parse import load_scenario

    return study_report.study_report(
        synthetic(layouts=layouts),
        out,
        scene=load_scenario("pillar"),
        layouts=layouts,
        until=20.0,
        runs=list(runs),
        arch="cpu",
        precision="f64",
    )


def test_report_writes_figures_json_and_markdown(tmp_path):
    """The report of a study: three figures, study.json with every model, study.md tables."""
    runs = [{"workers": 2, "scheduler": None, "wall_time": 10.0, "world_steps": 1000}]
    summary = _report(tmp_path, 4, runs)
    summary["wall_time"] = 11.0
    for name in ("study_distributions", "study_jam_vs_mu", "study_phase_map"):
        assert (tmp_path / "figures" / f"{name}.png").stat().st_size > 20_000
    assert set(summary["summary"]) == {label for label, _ in MODELS}
    assert summary["effective_mu"]["memory-only"] == pytest.approx(0.872)
    # Steady state at the pusher's 0.1 m/s: mu0 + (A - B) ln(0.1 / v_star).
    assert summary["effective_mu"]["rate-state"] == pytest.approx(
        0.872 + (0.05 - 0.112) * np.log(0.1 / 1e-5)
    )
    json.dumps(summary)  # serialisable
    # Every world's values, as in the dataset, with its model, area fraction and seed.
    ds = synthetic(layouts=4)
    rows = summary["per_world"]
    assert len(rows) == ds.sizes["world"]
    key = study.FIELD
    for w in range(ds.sizes["world"]):
        law, seed = str(ds["law"].values[w]), int(ds["seed"].values[w])
        fraction = float(ds[f"field.{key}.area_fraction"].values[w])
        (row,) = [
            r for r in rows if (r["model"], r["seed"], r["area_fraction"]) == (law, seed, fraction)
        ]
        assert row["peak_force"] == ds["peak_force"].values[w]
        assert row["released"] == ds["released"].values[w]
        assert row["jam"] == float(ds["peak_force"].values[w] > study.JAM_FORCE)
    md = study_report.study_markdown(summary)
    assert "| mu0.9 |" in md and "carried by" in md and "100 world-steps/s" in md


def test_the_docs_script_recomputes_the_jams_from_study_json(tmp_path, capsys):
    """docs/study/recompute.py reads per_world alone: its jam counts are the summary's, with
    the exact interval (12 of 12: [0.735, 1]); mu = 0.9 holds every jam that rate-and-state
    releases, on 12 layouts of each area fraction (McNemar p = 2 / 2^12)."""
    import importlib.util

    summary = _report(tmp_path, 12)
    path = tmp_path / "study.json"
    path.write_text(json.dumps(summary))
    spec = importlib.util.spec_from_file_location(
        "recompute", Path(__file__).resolve().parents[1] / "docs" / "study" / "recompute.py"
    )
    recompute = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(recompute)
    cells = recompute.strata(summary["per_world"])
    for model, fraction, k, n, low, high in recompute.jam_table(cells):
        want = summary["summary"][model]["by_fraction"][f"{fraction:g}"]["jam"]["value"]
        assert (k / n, n) == (want, 12)
        if k == n:
            assert (round(low, 3), high) == (0.735, 1.0)
    pairs = recompute.paired(cells, "mu0.9", "rate-state", "held")
    assert [f for f, *_ in pairs] == [0.7, 0.85]
    for _, n, only_a, only_b, p in pairs:
        assert (n, only_a, only_b) == (12, 12, 0) and p == pytest.approx(2.0 / 2**12)
    assert recompute.main([str(path)]) == 0
    assert "rate-state against mu0.9" in capsys.readouterr().out
