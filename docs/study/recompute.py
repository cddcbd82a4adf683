"""Recompute a study's numbers from the values of its worlds, without running anything:

    python docs/study/recompute.py out/study/study.json
    python docs/study/recompute.py out/study/study.json --pair rate-state mu0.9 --measure held

Reads ``per_world`` of study.json (every world's model, area fraction, seed and metrics) and
prints, for each model and area fraction, how many layouts jammed with the exact
(Clopper-Pearson) 95 % interval, then for one pair of models the paired comparison of one
0/1 measure on the same layouts (the exact McNemar test), stratum by stratum. The statistics
are ``taichi_ice.experiments.inference``'s, held against SciPy and statsmodels in the tests.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict

from taichi_ice.experiments import inference


def strata(rows: list[dict]) -> dict:
    """``{(model, area fraction): {seed: row}}``."""
    out: dict = defaultdict(dict)
    for row in rows:
        out[(row["model"], row["area_fraction"])][row["seed"]] = row
    return out


def jam_table(cells: dict) -> list[tuple]:
    """``(model, fraction, jammed, n, low, high)`` for every cell, worlds that did not
    complete (no value) left out."""
    table = []
    for (model, fraction), by_seed in sorted(cells.items()):
        values = [r["jam"] for r in by_seed.values() if r["jam"] is not None]
        k, n = int(sum(values)), len(values)
        table.append((model, fraction, k, n, *inference.clopper_pearson(k, n)))
    return table


def paired(cells: dict, a: str, b: str, measure: str) -> list[tuple]:
    """``(fraction, n, only_a, only_b, p)``: ``measure`` (0/1) of models ``a`` and ``b`` on the
    layouts both have a value for, per area fraction, with the exact McNemar test."""
    out = []
    for fraction in sorted({f for _, f in cells}):
        ra, rb = cells.get((a, fraction), {}), cells.get((b, fraction), {})
        seeds = [
            s
            for s in sorted(set(ra) & set(rb))
            if ra[s][measure] is not None and rb[s][measure] is not None
        ]
        test = inference.mcnemar([ra[s][measure] for s in seeds], [rb[s][measure] for s in seeds])
        out.append((fraction, test["n"], test["only_a"], test["only_b"], test["p"]))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study_json", help="a study's study.json (taichi-ice study --out DIR)")
    ap.add_argument("--pair", nargs=2, default=("rate-state", "mu0.9"), metavar=("A", "B"))
    ap.add_argument("--measure", default="held", help="a 0/1 measure: jam, held, released")
    args = ap.parse_args(argv)
    summary = json.load(open(args.study_json))
    if "per_world" not in summary:
        raise SystemExit(f"{args.study_json}: no per_world values (written before issue 31)")
    cells = strata(summary["per_world"])
    print("model            fraction  jammed   n   95 % exact interval")
    for model, fraction, k, n, low, high in jam_table(cells):
        print(f"{model:<16} {fraction:8.3f} {k:7d} {n:4d}   [{low:.3f}, {high:.3f}]")
    a, b = args.pair
    print(f"\n{args.measure}: {a} against {b}, paired by layout (exact McNemar)")
    for fraction, n, only_a, only_b, p in paired(cells, a, b, args.measure):
        print(f"  {fraction:.3f}: n {n:3d}, only {a} {only_a:3d}, only {b} {only_b:3d}, p {p:.3g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
