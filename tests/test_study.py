"""The study (issue 31): its design (strata with their own layouts, the half step, the
strengths), its statistics on a study whose answers are set, its report (study.json,
study.md, study.nc, figures), the docs' recompute script, and a short study run end to end."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.stats

from taichi_ice.experiments.study import design as study_design
from taichi_ice.experiments.study import report as study_report
from taichi_ice.experiments.study import stats as study
from taichi_ice.experiments.study.design import MODELS, Arm, design
from taichi_ice.experiments.study.stats import bootstrap_ci, verdict
from taichi_ice.physics.timestep import default_safety

# Two independent Monte Carlo resamplings of the same data agree on a 95 % quantile to about
# this fraction of the standard error (4,000 and 20,000 resamples).
MC_TOLERANCE = 0.08
LAYOUTS = 16


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
    """Holds or contradicted only when the adjusted p is at most alpha, by the effect's side."""
    assert verdict(0.01, 0.3, +1) == "holds"
    assert verdict(0.01, -0.3, +1) == "contradicted"
    assert verdict(0.01, -0.3, -1) == "holds"
    assert verdict(0.2, -0.3, -1) == "undecided"
    assert verdict(0.01, 0.0, -1) == "undecided"


def test_design_gives_each_stratum_its_own_layouts_and_pairs_the_half_step():
    """No seed is shared between strata; the half step and the strengths run the first
    layouts of their stratum (paired); every arm's sweep runs the eight models on its seeds
    with its own area fraction, step and strength; the issue's sizes at --layouts 64."""
    arms = {a.name: a for a in design(64)}
    strata = [a for a in arms.values() if a.kind in ("stratum", "control")]
    seen = [set(a.seeds) for a in strata]
    assert all(not (s & t) for i, s in enumerate(seen) for t in seen[i + 1 :])
    assert [a.layouts for a in strata] == [64, 64, 32]
    step = arms["half-step-af0.85"]
    assert step.seeds == arms["af0.85"].seeds[:32]
    assert step.dt_safety == pytest.approx(study_design.DEFAULT_SAFETY / 2)
    for s in study_design.STRENGTHS:
        for f in study_design.STRATA:
            arm = arms[f"strength-{s / 1e6:g}MPa-af{f:g}"]
            assert arm.strength == s and arm.seeds == arms[f"af{f:g}"].seeds[:32]
    for arm in (step, arms["strength-3MPa-af0.775"], arms["control-af0.7"]):
        sweep = arm.sweep(until=1.0)
        assert len(sweep.worlds()) == 8 * arm.layouts and sweep.until == 1.0
        scene = sweep.scene_for(sweep.worlds()[0])
        assert scene.ice.crushing_strength == arm.strength
        assert scene.dt_safety == (arm.dt_safety or default_safety(scene.friction.name))
    assert [a.name for a in design(2, 0, 0, 0)] == ["af0.85", "af0.775"]
    with pytest.raises(ValueError, match="not a stratum"):
        study_design.stratum_seeds(0.5, 3)


def _dataset(arm: Arm, shift: float = 1.0):
    """A sweep dataset for ``arm`` whose answers are set: mu <= 0.3 never touches 1 kN;
    mu >= 0.5 jams and holds to the end; rate-state and the steady-state law jam and release
    2 s after the peak, jammed a tenth of the time; memory-only jams and holds as mu = 0.9;
    rate-state dissipates more steadily than mu = 0.5. ``shift`` scales rate-state's
    frictional energy (the step's bias)."""
    import xarray as xr

    rows = []
    for label, table in MODELS:
        for seed in arm.seeds:
            i = seed % study_design.SEED_BLOCK
            releases = label in ("rate-state", "steady-state")
            jams = label not in ("mu0.1", "mu0.3")
            peak = (5e5 if releases else 2e6) + 1e4 * i if jams else 500.0 + i
            energy = peak / 10 * (shift if label == "rate-state" else 1.0)
            conc = 0.3 + 0.001 * i if label == "rate-state" else 0.6
            rows.append(
                {
                    "law": label,
                    "seed": seed,
                    "mu": table.get("mu", np.nan),
                    "peak_force": peak,
                    "friction_energy": energy,
                    "concentration": conc,
                    "released": float(releases or not jams),
                    "release_time": 2.0 if releases else 15.0 - 0.1 * i,
                    "release_observed": float(releases),
                    "jammed_fraction": (0.1 if releases else 0.8) if jams else 0.0,
                    "crushing_energy": 0.0,
                }
            )
    cols = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    for name, force in (("jammed_fraction_5kN", 5e3), ("jammed_fraction_20kN", 2e4)):
        cols[name] = cols["jammed_fraction"] * (cols["peak_force"] > force)
    n = len(rows)
    data = {k: ("world", v) for k, v in cols.items() if k not in ("law", "seed", "mu")}
    data["status"] = ("world", np.full(n, "complete"))
    return xr.Dataset(
        data,
        coords={
            "world": np.arange(n),
            "seed": ("world", cols["seed"]),
            "law": ("world", cols["law"]),
            "mu": ("world", cols["mu"]),
        },
    )


def synthetic_results(layouts: int = LAYOUTS, shift: float = 1.1) -> dict:
    """``run.run_arms``' result for a study of ``layouts`` per stratum (no strengths)."""
    log = [{"workers": 2, "scheduler": None, "wall_time": 10.0, "world_steps": 1000}]
    return {
        a.name: (a, _dataset(a, shift if a.kind == "step" else 1.0), log)
        for a in design(layouts, strength_layouts=0)
    }


@pytest.fixture(scope="module")
def summary(tmp_path_factory):
    out = tmp_path_factory.mktemp("study")
    s = study_report.write_report(synthetic_results(), out, until=20.0)
    (out / "study.json").write_text(json.dumps(s, allow_nan=True))
    return out, s


def test_claims_and_carriers_on_a_study_with_known_answers(summary):
    """Every verdict is what the synthetic study was built to give, in both strata, after
    Holm's correction over the family; release and time jammed are carried by rate."""
    _, s = summary
    claims = s["claims"]["no strength"]
    assert {c["stratum"] for c in claims} == {"0.85", "0.775"}
    n_claims = len(claims)
    for c in claims:
        assert c["p_holm"] >= c["p"] and c["p_holm"] <= min(1.0, n_claims * c["p"]) + 1e-12
    by = {(c["stratum"], c["claim"], c.get("model")): c for c in claims}
    for f in ("0.85", "0.775"):
        slid = by[(f, "mu = 0.1: blocks slide easily past the pillar", None)]
        assert slid["counts"] == f"{LAYOUTS} of {LAYOUTS}" and slid["verdict"] == "holds"
        assert slid["p"] == pytest.approx(scipy.stats.binomtest(LAYOUTS, LAYOUTS).pvalue)
        assert by[(f, "mu = 0.9: the blocks jam", None)]["verdict"] == "holds"
        assert by[(f, "mu = 0.9: the jam is never broken", None)]["verdict"] == "holds"
        assert by[(f, "mu = 0.5: jams form and break", None)]["verdict"] == "contradicted"
        more = by[(f, "higher friction jams more", None)]
        assert more["effect"] == 0.5 and more["difference"] == 1.0
        assert more["verdict"] == "holds"
        assert more["p"] == pytest.approx(2.0 / 2**LAYOUTS)
        release = "rate-and-state releases jams more easily than mu = 0.9"
        assert by[(f, release, "rate-state")]["verdict"] == "holds"
        assert by[(f, release, "memory-only")]["verdict"] == "undecided"  # no difference
        assert by[(f, release, "memory-only")]["p"] == 1.0
        time = by[(f, "rate-and-state is jammed for less of the time than mu = 0.5", "rate-state")]
        assert time["effect"] == pytest.approx(-0.7) and time["verdict"] == "holds"
        # 16 equal differences: Wilcoxon's normal approximation with ties (SciPy's too).
        ref = scipy.stats.wilcoxon(np.full(LAYOUTS, -0.7), method="approx").pvalue
        assert time["p"] == pytest.approx(ref, rel=1e-9)
    carried = {(c["stratum"], c["claim"]): c["carried_by"] for c in s["carriers"]["no strength"]}
    assert carried[("0.85", release)].startswith("rate (")
    steadier = "rate-and-state dissipates more steadily than mu = 0.5"
    assert carried[("0.85", steadier)].startswith("rate and memory together")


def test_descriptions_release_curves_and_power(summary):
    """Proportions with exact intervals, the Kaplan-Meier median of release (2 s for
    rate-and-state, not reached for mu = 0.9: every jam censored), the power table."""
    _, s = summary
    d = s["described"]["af0.85"]
    assert d["mu0.9"]["jam"]["k"] == LAYOUTS and d["mu0.9"]["jam"]["ci"][0] == pytest.approx(
        scipy.stats.binomtest(LAYOUTS, LAYOUTS).proportion_ci(method="exact").low
    )
    assert d["rate-state"]["release"]["median"] == 2.0
    assert d["mu0.9"]["release"]["median"] is None and d["mu0.9"]["release"]["events"] == 0
    # mu = 0.9's runs followed 15 - 0.1 i s after their peak (i = 0..15): median 14.25 s.
    assert d["mu0.9"]["release"]["censored_followup_median"] == pytest.approx(14.25)
    assert d["rate-state"]["release"]["censored_followup_median"] is None
    assert d["mu0.1"]["jam"]["k"] == 0
    claims = s["claims"]["no strength"]
    more = next(c for c in claims if c["claim"] == "higher friction jams more")
    assert more["n_needed"] is not None and more["n_needed"] <= LAYOUTS


def test_step_bias_finds_a_set_shift_and_no_other(summary):
    """The half-step arm differs only in rate-state's frictional energy (x 1.1): that row's
    relative shift is +10 % (every layout +10 %: Wilcoxon's exact p 2 / 2^8); every other
    row has no shift."""
    _, s = summary
    (step,) = s["step_bias"]
    assert step["against"] == "af0.85"
    rows = {(r["model"], r["measure"]): r for r in step["rows"]}
    moved = rows[("rate-state", "friction_energy")]
    assert moved["relative"] == pytest.approx(0.1) and moved["n"] == LAYOUTS // 2
    assert moved["wilcoxon_p"] == pytest.approx(2.0 / 2 ** (LAYOUTS // 2))
    assert moved["shift_over_se"] > 0
    for key, r in rows.items():
        if key != ("rate-state", "friction_energy") and "shift" in r:
            assert r["shift"] == 0.0 and r["wilcoxon_p"] == 1.0
        if "mcnemar" in r:
            assert r["mcnemar"]["only_a"] == r["mcnemar"]["only_b"] == 0
    # No claim reads the frictional energy: every claim is the same at both steps.
    assert len(step["claims"]) == 23
    for c in step["claims"]:
        assert c["default"]["n"] == c["half"]["n"] == LAYOUTS // 2
        assert c["default"]["p"] == c["half"]["p"]
        assert c["default"]["effect"] == c["half"]["effect"] or (
            np.isnan(c["default"]["effect"]) and np.isnan(c["half"]["effect"])
        )


def test_report_writes_json_markdown_netcdf_and_figures(summary):
    """study.json carries every world (its arm, stratum, model, seed, law parameter and
    metrics, as in the sweep datasets); study.nc holds the same values; four figures."""
    import xarray as xr

    out, s = summary
    results = synthetic_results()
    assert all(set(d) == {label for label, _ in MODELS} for d in s["described"].values())
    # Steady state at the pusher's 0.1 m/s: mu0 + (A - B) ln(0.1 / v_star); memory only
    # (B = A) stays at mu0.
    assert s["effective_mu"]["memory-only"] == pytest.approx(0.872)
    assert s["effective_mu"]["rate-state"] == pytest.approx(
        0.872 + (0.05 - 0.112) * np.log(0.1 / 1e-5)
    )
    rows = s["per_world"]
    assert len(rows) == sum(int(ds.sizes["world"]) for _, ds, _ in results.values())
    for name, (arm, ds, _) in results.items():
        mine = {(r["model"], r["seed"]): r for r in rows if r["arm"] == name}
        for w in range(ds.sizes["world"]):
            row = mine[(str(ds["law"].values[w]), int(ds["seed"].values[w]))]
            assert row["area_fraction"] == arm.fraction
            assert row["peak_force"] == ds["peak_force"].values[w]
            assert row["jam"] == float(ds["peak_force"].values[w] > study.JAM_FORCE)
            mu = ds["mu"].values[w]
            assert row["mu"] is None if np.isnan(mu) else row["mu"] == mu
    nc = xr.open_dataset(out / "study.nc")
    assert nc.sizes["world"] == len(rows)
    assert list(nc["arm"].values) == [r["arm"] for r in rows]
    assert np.array_equal(nc["seed"].values, [r["seed"] for r in rows])
    assert np.array_equal(nc["peak_force"].values, [r["peak_force"] for r in rows])
    assert nc["peak_force"].attrs["units"] == "N"
    nc.close()
    for name in ("study_phase_map", "study_release", "study_distributions", "study_step_bias"):
        assert (out / "figures" / f"{name}.png").stat().st_size > 20_000
    md = (out / "study.md").read_text()
    # Each arm's throughput from its sweep log: 1,000 world-steps in 10 s.
    assert "| af0.85 | stratum | 0.85 | 16 (0-15) | default | no strength | 10 | 100 |" in md
    assert "## The paper's claims, tested (no strength)" in md and "carried by" in md
    assert "## The step's bias: half-step-af0.85 against af0.85" in md
    json.dumps(s, allow_nan=True)


def _recompute():
    """docs/study/recompute.py as a module (a script beside the docs, not in the package)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "recompute", Path(__file__).resolve().parents[1] / "docs" / "study" / "recompute.py"
    )
    recompute = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(recompute)
    return recompute


def test_the_docs_script_recomputes_the_study_from_study_json(summary, capsys):
    """docs/study/recompute.py reads per_world alone: its jam counts are the report's, with
    the exact interval; mu = 0.9 holds every jam rate-and-state releases (McNemar p 2/2^16)
    and its share of time jammed is the report's Wilcoxon p."""
    out, s = summary
    recompute = _recompute()
    cells = recompute.strata(s["per_world"])
    for arm, model, k, n, low, high in recompute.jam_table(cells):
        want = s["described"][arm][model]["jam"]
        assert (k, n) == (want["k"], want["n"]) and [low, high] == want["ci"]
    pairs = {arm: rest for arm, *rest in recompute.paired(cells, "mu0.9", "rate-state", "held")}
    n, said, p = pairs["af0.85"]
    assert n == LAYOUTS and said == f"only mu0.9 {LAYOUTS}, only rate-state 0"
    assert p == pytest.approx(2.0 / 2**LAYOUTS)
    claim = next(
        c
        for c in s["claims"]["no strength"]
        if c["stratum"] == "0.775"
        and c["claim"] == "rate-and-state is jammed for less of the time than mu = 0.9"
        and c["model"] == "steady-state"
    )
    pairs = {
        arm: rest
        for arm, *rest in recompute.paired(cells, "steady-state", "mu0.9", "jammed_fraction")
    }
    assert pairs["af0.775"][2] == pytest.approx(claim["p"], rel=1e-12)
    assert recompute.main([str(out / "study.json")]) == 0
    assert "rate-state against mu0.9" in capsys.readouterr().out


def test_the_docs_script_sets_a_study_against_another_run_of_it(summary, tmp_path, capsys):
    """``recompute.py --against OLD``: a study against itself is equal in every value and
    moves no verdict; with rate and state's peak force 0.1 MN higher on every layout, its shift
    is 0.1 MN with a zero-width interval, the other models stay equal, and a verdict changed in
    the other run is listed."""
    import copy

    _, s = summary
    recompute = _recompute()
    cells = recompute.strata(s["per_world"])
    itself = recompute.against(cells, cells)
    assert set(itself) == {arm for arm, _ in cells}
    for arm, result in itself.items():
        assert result["same"] == sorted(m for a, m in cells if a == arm)
        assert result["shifts"] == []
    assert recompute.verdicts_moved(s, s) == []

    other = copy.deepcopy(s)
    for row in other["per_world"]:
        if row["model"] == "rate-state":
            row["peak_force"] += 1.0e5
    claim = other["claims"]["no strength"][0]
    claim["verdict"] = "undecided" if claim["verdict"] != "undecided" else "holds"
    moved = recompute.against(cells, recompute.strata(other["per_world"]))
    for arm, result in moved.items():
        assert result["same"] == sorted(m for a, m in cells if a == arm and m != "rate-state")
        peak = next(r for r in result["shifts"] if r["measure"] == "peak_force")
        assert peak["model"] == "rate-state"
        assert peak["shift"] == pytest.approx(1.0e5, rel=1e-9)
        assert peak["ci"] == pytest.approx([1.0e5, 1.0e5], rel=1e-9)
        assert peak["relative"] == pytest.approx(1.0e5 / peak["default_mean"], rel=1e-9)
        friction = next(r for r in result["shifts"] if r["measure"] == "friction_energy")
        assert friction["shift"] == 0.0 and friction["wilcoxon_p"] == 1.0
    assert recompute.verdicts_moved(s, other) == [
        (
            "no strength",
            claim["stratum"],
            claim["claim"],
            claim.get("model"),
            s["claims"]["no strength"][0]["verdict"],
            claim["verdict"],
        )
    ]
    # A measure that was 0 on every layout before is printed as a shift, not a ratio.
    before = copy.deepcopy(s)
    for summary_ in (before, other):
        for row in summary_["per_world"]:
            if row["model"] == "rate-state":
                row["jammed_fraction"] = 0.0 if summary_ is before else 0.01
    (tmp_path / "before.json").write_text(json.dumps(before, allow_nan=True))
    (tmp_path / "other.json").write_text(json.dumps(other, allow_nan=True))
    assert (
        recompute.main([str(tmp_path / "other.json"), "--against", str(tmp_path / "before.json")])
        == 0
    )
    said = capsys.readouterr().out
    assert "verdicts moved: 1" in said and "rate-state     peak_force" in said
    assert "rate-state     jammed_fraction  n" in said and "+0.01 [+0.01, +0.01] (was 0)" in said


def test_a_short_study_runs_end_to_end(tmp_path):
    """`run_study` of two layouts per stratum and the half step, 0.3 s each, in this process:
    every arm's sweep runs, and study.json, study.md, study.nc and the figures are written;
    a second call resumes (runs nothing)."""
    from taichi_ice.experiments.study.run import run_study

    kw = dict(control_layouts=0, strength_layouts=0, until=0.3, workers=0, progress=False)
    s = run_study(tmp_path, 2, **kw)
    assert s["worlds"] == 3 * 2 * 8 and s["status"] == {"complete": 48}
    assert {d["arm"] for d in s["design"]} == {"af0.85", "af0.775", "half-step-af0.85"}
    for name in ("study.json", "study.md", "study.nc"):
        assert (tmp_path / name).stat().st_size > 0
    again = run_study(tmp_path, 2, **kw)
    assert all(log[-1]["worlds_run"] == 0 for log in again["runs"].values())
    assert again["per_world"] == s["per_world"]
