"""Overlap throughput: pairs per second of the NumPy reference and of the Taichi kernel.

Seeded random convex pairs (3 to 8 vertices, about a third overlapping, the rest rejected by
the SAT) go through ``polygon.overlap`` one by one and through ``batched.overlap_batch_ti``
(``overlap_ti`` in one parallel kernel; it also writes the SAT outputs that the tests check)
in batches of growing size. The Taichi timings exclude the first call, which compiles
the kernel, and include the host-to-kernel copies of the ndarrays. Results go to
``<out>/overlap.csv`` and ``<out>/overlap.json``.

    python benchmarks/overlap.py --out out/bench
    python benchmarks/overlap.py --arch gpu --precision f32 --sizes 10000 1000000
"""

import argparse
import csv
import json
import platform
import time
from pathlib import Path

import numpy as np

from taichi_ice import backend
from taichi_ice.physics.batched import overlap_batch_ti
from taichi_ice.physics.polygon import overlap, transform

MAXV = 8  # padded vertex count, as in the DEM's local matrices


def random_pairs(count: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``count`` random convex pairs, zero-padded to ``(count, MAXV, 2)``, and their counts."""
    rng = np.random.default_rng(seed)
    verts = np.zeros((2, count, MAXV, 2))
    counts = rng.integers(3, MAXV + 1, size=(2, count))
    for side in range(2):
        for b in range(count):
            n = counts[side, b]
            # Evenly spaced angles, jittered by less than half a gap, stay strictly convex.
            angles = (np.arange(n) + rng.uniform(-0.3, 0.3, n)) * (2.0 * np.pi / n)
            semi = rng.uniform(0.3, 1.5, 2)
            local = np.stack([semi[0] * np.cos(angles), semi[1] * np.sin(angles)], axis=1)
            centre = rng.uniform(0.0, 2.5, 2) if side else np.zeros(2)
            verts[side, b, :n] = transform(local, centre, rng.uniform(0.0, 2.0 * np.pi))
    return verts[0], counts[0], verts[1], counts[1]


def time_numpy(p, n_p, q, n_q, budget_s: float) -> tuple[int, float]:
    """Pairs done and seconds spent by the NumPy reference within about ``budget_s``."""
    start = time.perf_counter()
    done = 0
    while done < len(p) and time.perf_counter() - start < budget_s:
        overlap(p[done, : n_p[done]], q[done, : n_q[done]])
        done += 1
    return done, time.perf_counter() - start


def time_taichi(p, n_p, q, n_q, repeats: int) -> float:
    """Best wall time (s) of ``repeats`` calls of overlap_batch_ti on the whole batch."""
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        overlap_batch_ti(p, n_p, q, n_q)
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/bench"), help="results folder")
    parser.add_argument("--arch", default="cpu", help="Taichi arch: cpu (default) or gpu")
    parser.add_argument("--precision", default="f64", help="f64 (default) or f32")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1_000, 10_000, 100_000])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    backend.init(args.arch, args.precision)
    p, n_p, q, n_q = random_pairs(max(args.sizes), args.seed)
    start = time.perf_counter()
    overlap_batch_ti(p[:1], n_p[:1], q[:1], n_q[:1])
    compile_s = time.perf_counter() - start

    done, seconds = time_numpy(p, n_p, q, n_q, budget_s=2.0)
    rows = [{"method": "numpy", "pairs": done, "seconds": seconds, "pairs_per_s": done / seconds}]
    for size in sorted(args.sizes):
        seconds = time_taichi(p[:size], n_p[:size], q[:size], n_q[:size], repeats=5)
        rows.append(
            {"method": "taichi", "pairs": size, "seconds": seconds, "pairs_per_s": size / seconds}
        )
    for row in rows:
        print(f"{row['method']:>7} {row['pairs']:>9} pairs  {row['pairs_per_s']:12.4g} pairs/s")

    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "overlap.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    meta = {
        "arch": args.arch,
        "precision": args.precision,
        "machine": platform.node(),
        "processor": platform.processor(),
        "taichi_compile_s": compile_s,
        "overlapping_fraction": float(np.mean(overlap_batch_ti(p, n_p, q, n_q).area > 0)),
        "rows": rows,
    }
    (args.out / "overlap.json").write_text(json.dumps(meta, indent=2) + "\n")


if __name__ == "__main__":
    main()
