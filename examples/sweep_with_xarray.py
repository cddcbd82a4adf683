"""A small sweep, analysed with xarray into a figure.

The paper's pillar scene (rubble pushed past a fixed pillar) over a few layouts x Coulomb
friction from mu = 0.1 to 0.9 x rate-and-state friction. The sweep is given as the tables of
a sweep file (docs/sweeps.md), run batch by batch, and its results come back as an
``xarray.Dataset`` with one row per world: the analysis is a ``groupby``.

    python examples/sweep_with_xarray.py --out out/examples              # 4 layouts, 20 s
    python examples/sweep_with_xarray.py --out out/examples --workers 2  # on 2 Dask workers
    python examples/sweep_with_xarray.py --out out/examples --quick      # a smoke test

Run it again with the same --out and only the worlds not yet done run (a sweep resumes).
It writes ``OUT/sweep/sweep.nc`` and ``OUT/sweep_with_xarray.png``, and prints the medians.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from taichi_ice.experiments.sweep.run import run_sweep
from taichi_ice.experiments.sweep.spec import sweep_from_dict


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/examples"), help="output folder")
    parser.add_argument("--quick", action="store_true", help="2 layouts, 3 laws, 1 s")
    parser.add_argument(
        "--workers", type=int, default=0, help="Dask workers (default 0: this process, no Dask)"
    )
    args = parser.parse_args()

    mus = [0.1, 0.9] if args.quick else [0.1, 0.3, 0.5, 0.7, 0.9]
    sweep = sweep_from_dict(
        {
            "sweep": {
                "scene": "pillar",  # a bundled scene, or the path of a scene file
                "seeds": {"start": 0, "count": 2 if args.quick else 4},
                "until": 1.0 if args.quick else 20.0,  # s
                "window": 0.5 if args.quick else 1.0,  # s: "released" reads the last window
                "metrics": ["peak_force", "mean_force", "friction_energy", "released"],
                "runs": "none",  # no HDF5 run file per world: the metrics are the result
            },
            "law": [{"law": "coulomb", "mu": mus}, {"law": "rate-state"}],  # a list: an axis
        },
        source="sweep_with_xarray",
    )
    result = run_sweep(sweep, args.out / "sweep", workers=args.workers, progress=False)
    print(f"{len(result.ran)} worlds run, {len(result.reused)} reused, in {result.wall_time:.1f} s")

    ds = result.dataset()  # an xarray.Dataset on dimension "world"
    assert (ds.status == "complete").all(), ds.failure.values

    # Medians over layouts: Coulomb by mu, rate-and-state on its own.
    coulomb = ds.where(ds.law_name == "coulomb", drop=True)
    by_mu = coulomb[["peak_force", "friction_energy"]].groupby("mu").median()
    rate_state = ds.where(ds.law_name == "rate-state", drop=True)
    print(f"{'law':<16}{'median peak force (kN)':>24}{'median friction (kJ)':>22}")
    for mu in by_mu.mu.values:
        row = by_mu.sel(mu=mu)
        print(
            f"{f'coulomb {mu:.1f}':<16}{float(row.peak_force) / 1e3:>24.4g}"
            f"{float(row.friction_energy) / 1e3:>22.4g}"
        )
    print(
        f"{'rate-state':<16}{float(rate_state.peak_force.median()) / 1e3:>24.4g}"
        f"{float(rate_state.friction_energy.median()) / 1e3:>22.4g}"
    )

    # The figure, on a bare matplotlib Figure (no pyplot): every layout a dot, the median a line.
    fig = Figure(figsize=(9, 3.6), layout="constrained")
    axes = fig.subplots(1, 2)
    panels = {"peak_force": "peak force on the pillar (kN)", "friction_energy": "friction (kJ)"}
    for ax, (name, label) in zip(axes, panels.items()):
        scale = 1e-3  # N to kN, J to kJ
        ax.plot(coulomb.mu, coulomb[name] * scale, "o", color="C0", alpha=0.5, label="Coulomb")
        ax.plot(by_mu.mu, by_mu[name] * scale, "-", color="C0", label="Coulomb, median")
        rs = rate_state[name].values * scale
        ax.plot(np.full(rs.shape, 1.0), rs, "s", color="C3", alpha=0.6, label="rate-and-state")
        ax.axhline(float(np.median(rs)), color="C3", lw=0.8, ls="--")
        ax.set_xticks([*by_mu.mu.values, 1.0], [*(f"{m:.1f}" for m in by_mu.mu.values), "RS"])
        ax.set_xlabel("friction coefficient mu (RS: rate-and-state)")
        ax.set_ylabel(label)
        ax.set_yscale("symlog", linthresh=1.0)  # logarithmic above 1, linear down to 0
        ax.set_ylim(bottom=0.0)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"pillar scene, {ds.seed.to_series().nunique()} layouts, {sweep.until:g} s")
    figure = args.out / "sweep_with_xarray.png"
    fig.savefig(figure, dpi=80)
    print(f"wrote {figure} and {result.path}")


if __name__ == "__main__":
    main()
