"""Why rate and state does not converge in dt in the pillar scene: ``python
validation/rest_rule_dt.py --out DIR``.

The pillar scene with the paper's rate-and-state law, once for each rule below v_star
(``RateState.below_v_star``: ``paper``, ``healing``, ``frozen``, ``relaxing``) and with
Coulomb mu = 0.9, at dt from 0.025 to 0.4 of the stable step; the frictional energy and the
block positions at a few times before the runs part (~5.5 s), against the run at 0.025.
Writes ``rest_rule_dt.json`` and ``rest_rule_dt.png`` and prints the table (docs/accuracy.md
quotes it). About 4 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from taichi_ice.codes import RestRule

RATIOS = (0.025, 0.05, 0.1, 0.2, 0.4)
TIMES = (2.5, 4.0, 5.5)
RULES = RestRule.labels()


def measure(scene, ratios=RATIOS, times=TIMES) -> dict:
    """Frictional energy (J) and positions (m) at ``times`` for each dt / stable_dt."""
    from taichi_ice.codes import EnergyTerm
    from taichi_ice.engine.world import World

    out = {}
    for ratio in ratios:
        # The Euler step, as the record was made (Coulomb's default is the midstep step
        # since 2026-12-02; rate and state's is still Euler).
        world = World([scene], dt=ratio * scene.stable_dt, force_dt=True, integrator="euler")
        energy, positions = [], []
        for t in times:
            world.advance(round((t - world.time) / world.dt))
            energy.append(float(world.energies()[0][EnergyTerm.FRICTION]))
            positions.append(world.positions())
        world.check()
        out[ratio] = {"friction": energy, "positions": positions}
    return out


def errors(runs: dict) -> dict:
    """Relative frictional-energy error and largest block displacement against the
    smallest step, per ratio and time."""
    ref = runs[min(runs)]
    table = {}
    for ratio, run in runs.items():
        table[ratio] = {
            "friction_j": run["friction"],
            "friction_rel": [abs(e - r) / abs(r) for e, r in zip(run["friction"], ref["friction"])],
            "displacement_m": [
                float(np.abs(p - q).max()) for p, q in zip(run["positions"], ref["positions"])
            ],
        }
    return table


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder for JSON and PNG")
    args = parser.parse_args(argv)
    from taichi_ice import backend, load_scenario
    from taichi_ice.physics.friction import Coulomb, RateState

    backend.init("cpu", "f64")
    base = load_scenario("pillar")
    laws = {f"rate-state, {rule}": RateState(below_v_star=rule) for rule in RULES}
    laws["coulomb 0.9"] = Coulomb(mu=0.9)
    results = {}
    for label, law in laws.items():
        table = errors(measure(base.with_friction(law)))
        results[label] = {str(k): v for k, v in table.items()}
        for ratio, row in table.items():
            cells = " | ".join(
                f"{t} s: {e:.3g} J, {rel:.2g}, {dx:.1e} m"
                for t, e, rel, dx in zip(
                    TIMES, row["friction_j"], row["friction_rel"], row["displacement_m"]
                )
            )
            print(f"{label:<22} {ratio:>6}: {cells}", flush=True)

    args.out.mkdir(parents=True, exist_ok=True)
    record = {"times_s": TIMES, "ratios": RATIOS, "reference_ratio": min(RATIOS), **results}
    (args.out / "rest_rule_dt.json").write_text(json.dumps(record, indent=1))
    _plot(results, args.out / "rest_rule_dt.png")
    print(f"wrote {args.out / 'rest_rule_dt.json'} and {args.out / 'rest_rule_dt.png'}")
    return 0


def _plot(results: dict, path: Path) -> None:
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(TIMES), figsize=(4 * len(TIMES), 3.6), sharey=True)
    for k, (ax, t) in enumerate(zip(axes, TIMES)):
        for label, table in results.items():
            ratios = [float(r) for r in table if float(r) != min(RATIOS)]
            rel = [max(table[str(r)]["friction_rel"][k], 1e-6) for r in ratios]
            ax.loglog(ratios, rel, "o-", label=label)
        ax.set_xticks(RATIOS[1:], [f"{r:g}" for r in RATIOS[1:]])
        ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
        ax.set_title(f"frictional energy at {t} s")
        ax.set_xlabel("dt / stable_dt")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel(f"relative error against dt = {min(RATIOS)} stable_dt")
    axes[0].legend(fontsize=7)
    fig.suptitle("pillar scene: the rule below v_star against the time step", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
