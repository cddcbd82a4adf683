"""Recompute a study's numbers from the values of its worlds, without running anything:

    python docs/study/recompute.py out/study/study.json
    python docs/study/recompute.py out/study/study.json --pair rate-state mu0.9 --measure held
    python docs/study/recompute.py out/study/study.json --measure jammed_fraction

Reads ``per_world`` of study.json (every world's arm, area fraction, model, seed and
metrics) and prints, for each arm (a stratum at one step and strength) and model, how many
layouts jammed with the exact (Clopper-Pearson) 95 % interval, then for one pair of models
the paired comparison of one measure on the same layouts, arm by arm: the exact McNemar test
for a 0/1 measure (jam, held, released), the Wilcoxon signed-rank test for any other. The
statistics are ``taichi_ice.experiments.inference``'s, held against SciPy and statsmodels in
the tests; study.md's p-values are these before Holm's adjustment.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict

from taichi_ice.experiments import inference

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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study_json", help="a study's study.json (taichi-ice study --out DIR)")
    ap.add_argument("--pair", nargs=2, default=("rate-state", "mu0.9"), metavar=("A", "B"))
    ap.add_argument(
        "--measure", default="held", help="a 0/1 measure (jam, held) or any metric (peak_force)"
    )
    args = ap.parse_args(argv)
    summary = json.load(open(args.study_json))
    if "per_world" not in summary:
        raise SystemExit(f"{args.study_json}: no per_world values (written before issue 31)")
    cells = strata(summary["per_world"])
    print("arm                    model          jammed   n   95 % exact interval")
    for arm, model, k, n, low, high in jam_table(cells):
        print(f"{arm:<22} {model:<14} {k:6d} {n:4d}   [{low:.3f}, {high:.3f}]")
    a, b = args.pair
    test = "exact McNemar" if args.measure in BINARY else "Wilcoxon signed-rank"
    print(f"\n{args.measure}: {a} against {b}, paired by layout ({test})")
    for arm, n, said, p in paired(cells, a, b, args.measure):
        print(f"  {arm:<22} n {n:3d}, {said}, p {p:.3g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
