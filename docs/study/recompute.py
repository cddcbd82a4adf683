"""Recompute a study's numbers from the values of its worlds, without running anything:

    python docs/study/recompute.py out/study/study.json
    python docs/study/recompute.py out/study/study.json --pair rate-state mu0.9 --measure held
    python docs/study/recompute.py out/study/study.json --measure jammed_fraction
    python docs/study/recompute.py out/study/study.json --against docs/study/study.json

Reads ``per_world`` of study.json (every world's arm, area fraction, model, seed and
metrics) and prints, for each arm (a stratum at one step and strength) and model, how many
layouts jammed with the exact (Clopper-Pearson) 95 % interval, then for one pair of models
the paired comparison of one measure on the same layouts, arm by arm: the exact McNemar test
for a 0/1 measure (jam, held, released), the Wilcoxon signed-rank test for any other. The
statistics are ``taichi_ice.experiments.inference``'s, held against SciPy and statsmodels in
the tests; study.md's p-values are these before Holm's adjustment.

``--against OLD``: the study against another run of it (another step, another version), the
same layouts paired by seed: which models give every value the same, each other model's
shift per measure (the study's own step-bias statistics, ``stats.step_bias``: the mean paired
shift with its bootstrap interval, the Wilcoxon p with Holm's adjustment over the arm's rows,
McNemar on jam and held), and every claim whose verdict moved.
"""

from __future__ import annotations

import argparse
import json
import math
from collections import defaultdict

import numpy as np

from taichi_ice.experiments import inference
from taichi_ice.experiments.study import stats

BINARY = ("jam", "jam_5kN", "jam_20kN", "held", "slid", "released", "release_observed")


def strata(rows: list[dict]) -> dict:
    """``{(arm, model): {seed: row}}``."""
    out: dict = defaultdict(dict)
    for row in rows:
        out[(row["arm"], row["model"])][row["seed"]] = row
    return out


def jam_table(cells: dict) -> list[tuple]:
    """``(arm, model, jammed, n, low, high)`` for every cell, worlds that did not complete
    (no value) left out."""
    table = []
    for (arm, model), by_seed in sorted(cells.items()):
        values = [r["jam"] for r in by_seed.values() if r["jam"] is not None]
        k, n = int(sum(values)), len(values)
        table.append((arm, model, k, n, *inference.clopper_pearson(k, n)))
    return table


def paired(cells: dict, a: str, b: str, measure: str) -> list[tuple]:
    """``(arm, n, said, p)``: ``measure`` of models ``a`` and ``b`` on the layouts both have
    a value for, per arm: the exact McNemar test of a 0/1 measure (``said``: the discordant
    counts), else the Wilcoxon signed-rank test (``said``: the mean difference a - b)."""
    out = []
    for arm in sorted({arm for arm, _ in cells}):
        ra, rb = cells.get((arm, a), {}), cells.get((arm, b), {})
        seeds = [
            s
            for s in sorted(set(ra) & set(rb))
            if ra[s][measure] is not None and rb[s][measure] is not None
        ]
        x, y = [ra[s][measure] for s in seeds], [rb[s][measure] for s in seeds]
        if measure in BINARY:
            test = inference.mcnemar(x, y)
            said = f"only {a} {test['only_a']}, only {b} {test['only_b']}"
        else:
            d = [u - v for u, v in zip(x, y) if u != v]
            test = inference.wilcoxon(d) if d else {"p": 1.0}
            said = f"mean {a} - {b} {sum(d) / max(len(seeds), 1):+.4g}"
        out.append((arm, len(seeds), said, test["p"]))
    return out


def _same(a: dict, b: dict) -> bool:
    """Every metric of two rows equal (NaN equal to NaN); bookkeeping keys aside."""
    for key, x in a.items():
        if key in ("arm", "status", "dt_safety") or key not in b:
            continue
        y = b[key]
        both_nan = isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y)
        if x != y and not both_nan:
            return False
    return True


def _columns(rows: dict, seeds: list) -> dict:
    """``{measure: values of rows[seed] over seeds}``, None as NaN: what ``step_bias`` takes."""
    names = (*stats.STEP_MEASURES, "jam", "held")
    return {
        k: np.array([np.nan if rows[s][k] is None else rows[s][k] for s in seeds], float)
        for k in names
    }


def against(old: dict, new: dict) -> dict:
    """The study ``new`` against ``old`` (both ``strata`` cells), arm by arm on the seeds both
    hold: ``{arm: {"same": [models equal in every value], "n": {model: seeds},
    "shifts": stats.step_bias rows (new against old)}}``."""
    out = {}
    for arm in sorted({arm for arm, _ in new} & {arm for arm, _ in old}):
        models = sorted({m for a, m in new if a == arm} & {m for a, m in old if a == arm})
        same, n, base, other, whole = [], {}, {}, {}, {}
        for model in models:
            ro, rn = old[(arm, model)], new[(arm, model)]
            seeds = sorted(set(ro) & set(rn))
            n[model] = len(seeds)
            if seeds and all(_same(ro[s], rn[s]) for s in seeds):
                same.append(model)
                continue
            base[model], other[model] = _columns(ro, seeds), _columns(rn, seeds)
            whole[model] = _columns(ro, sorted(ro))
        out[arm] = {"same": same, "n": n, "shifts": stats.step_bias(base, other, whole)}
    return out


def verdicts_moved(old: dict, new: dict) -> list[tuple]:
    """``(family, stratum, claim, model, old verdict, new verdict)`` for every claim both
    studies test whose verdict differs; a claim is keyed by family, stratum, claim and model."""

    def by(summary):
        return {
            (family, c["stratum"], c["claim"], c.get("model")): c["verdict"]
            for family, claims in summary["claims"].items()
            for c in claims
        }

    a, b = by(old), by(new)
    return [(*k, a[k], b[k]) for k in sorted(set(a) & set(b), key=str) if a[k] != b[k]]


def _print_against(old_path: str, old: dict, new: dict) -> None:
    print(f"\nagainst {old_path}: the same layouts, paired by seed")
    for arm, result in against(strata(old["per_world"]), strata(new["per_world"])).items():
        print(f"  {arm}: equal in every value: {', '.join(result['same']) or 'none'}")
        for r in result["shifts"]:
            if "mcnemar" in r:
                t = r["mcnemar"]
                print(
                    f"    {r['model']:<14} {r['measure']:<16} only before {t['only_a']}, only "
                    f"now {t['only_b']}, p {t['p']:.3g}"
                )
                continue
            low, high = r["ci"]
            mean = r["default_mean"]
            if mean:  # relative to the old mean
                shift, low, high = (100 * x / mean for x in (r["shift"], low, high))
                said = f"{shift:+.1f} % [{low:+.1f}, {high:+.1f}]"
            else:  # a measure that was 0 on every layout: the shift itself
                said = f"{r['shift']:+.4g} [{low:+.4g}, {high:+.4g}] (was 0)"
            print(
                f"    {r['model']:<14} {r['measure']:<16} n {r['n']:3d} shift {said}"
                f" p {r['wilcoxon_p']:.2g} (Holm {r['wilcoxon_p_holm']:.2g})"
            )
    moved = verdicts_moved(old, new)
    print(f"  verdicts moved: {len(moved)}")
    for family, stratum, claim, model, was, now in moved:
        print(f"    {family} | {stratum} | {claim} | {model or '-'}: {was} -> {now}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study_json", help="a study's study.json (taichi-ice study --out DIR)")
    ap.add_argument("--pair", nargs=2, default=("rate-state", "mu0.9"), metavar=("A", "B"))
    ap.add_argument(
        "--measure", default="held", help="a 0/1 measure (jam, held) or any metric (peak_force)"
    )
    ap.add_argument(
        "--against", metavar="OLD", help="another run's study.json: shifts and verdicts moved"
    )
    args = ap.parse_args(argv)
    summary = _load(args.study_json)
    cells = strata(summary["per_world"])
    print("arm                    model          jammed   n   95 % exact interval")
    for arm, model, k, n, low, high in jam_table(cells):
        print(f"{arm:<22} {model:<14} {k:6d} {n:4d}   [{low:.3f}, {high:.3f}]")
    a, b = args.pair
    test = "exact McNemar" if args.measure in BINARY else "Wilcoxon signed-rank"
    print(f"\n{args.measure}: {a} against {b}, paired by layout ({test})")
    for arm, n, said, p in paired(cells, a, b, args.measure):
        print(f"  {arm:<22} n {n:3d}, {said}, p {p:.3g}")
    if args.against:
        _print_against(args.against, _load(args.against), summary)
    return 0


def _load(path: str) -> dict:
    summary = json.load(open(path))
    if "per_world" not in summary:
        raise SystemExit(f"{path}: no per_world values (written before issue 31)")
    return summary


if __name__ == "__main__":
    raise SystemExit(main())
