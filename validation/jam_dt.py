"""Where the default step's rate-and-state peak force parts from a smaller step's: ``python
validation/jam_dt.py --out DIR``.

Over 256 layouts the Euler step at 0.2 stable_dt gives the pillar's rate-and-state peak force
+15 % [+8, +22] of what it gives at 0.05 (``docs/accuracy.md``; ``dem_ensemble``), and runs of
one layout at two steps are uncorrelated by 20 s, so a single run cannot say where the two
part. Four measurements that can:

1. **Mean force curves**: the probe force of ``--layouts`` layouts at each step (independent
   runs, ``run_ensemble``), its mean over the layouts in 1 s windows with the difference in
   standard errors, and when each layout's force first passes 10 kN, 100 kN, 0.5 MN and
   1 MN (the jam's onset and growth).
2. **Paired branches**: ``--branch-layouts`` layouts run at the default step to ``--t0``,
   and from that one state (``branch``: every field of the World copied but its dt)
   continued at each step to 19 s. The windows' paired shifts of the mean force against
   the default step's continuation have the chaos of the runs before ``--t0`` taken out.
3. **The stick spring's dashpot**: the smaller step with the scene's ``[ice]
   tangential_damping`` raised from 0.25 to ``--damping`` (the Euler step's stick spring
   takes its stretch at the step's end, a numerical dashpot ``k_t dt / 2``: up to 0.07 of
   critical at 0.2 stable_dt on the stiffest contact, 0.018 at 0.05;
   ``contact_law.contact_work``), against the same layouts at 0.25.

4. **The rule below v_star** (``--rule healing``, alone): the peak force of the same layouts
   at both steps with ``RateState(below_v_star=...)`` instead of the paper's rule (under
   which a contact whose slip falls below v_star takes mu0 and ends its interface), written
   to ``jam_dt_RULE.json``. About 10 minutes.
5. **The slide in sub-steps** (``--slide-resolution R``, alone): the same with ``[ice]
   slide_resolution = R`` (a sliding contact's stick spring relaxes over ``c_t / k_t``, no
   less than 2.5 default steps: in one step, the slip rate the law sees is that of the
   impedance ``k_t dt + c_t``; ``slip.sliding_steps``), written to
   ``jam_dt_slide_R.json`` (``jam_dt_slide_R_STEPS.json`` with ``--steps``, e.g. ``--steps
   0.0125`` for the finest step alone, ~35 minutes at ``--slide-resolution 0``). About 12
   minutes at 0.025. ``--first-seed N`` runs the layouts of seeds ``N, N + 1, ...`` instead
   (``..._seedsN.json``): a second sample that shares no layout with the first;
   ``--integrator NAME`` steps them (and those of 4.) with another integrator
   (``..._NAME.json``). Each record keeps every layout's peak force, frictional energy and
   whether its jam was released (``experiments.metrics``), and the ``git describe`` it ran.

Writes ``jam_dt.json`` and ``jam_dt.png`` and prints the tables (docs/accuracy.md quotes
them). About 25 minutes on 2 cores at the defaults; ``--layouts 8 --branch-layouts 4`` for a
look in two.
"""

from __future__ import annotations

import argparse
import copy
import json
import time
from pathlib import Path

import numpy as np

from taichi_ice.codes import RestRule
from taichi_ice.engine.options import INTEGRATORS

STEPS = (0.2, 0.05)  # dt / stable_dt: the default and its quarter
THRESHOLDS = (1e4, 1e5, 5e5, 1e6)  # N: the jam's onset and growth
UNTIL = 20.0  # s: the paper's run
BRANCH_END = 19.0  # s


def branch(source, scenes, dt: float):
    """A Simulation of ``scenes`` at ``dt`` (the source's integrator) that continues
    ``source``'s state: its fields as a checkpoint holds them (``checkpoint.state``) but its
    own step ``time_step``, the step count set to ``source.time / dt``. With the same dt it
    steps bit for bit as ``source`` would (``tests/test_validation_scripts.py``)."""
    from taichi_ice.run import checkpoint
    from taichi_ice.run.simulation import Simulation

    sim = Simulation(scenes, dt=dt, force_dt=True, integrator=source.options.integrator)
    arrays = checkpoint.state(source.world)
    arrays["data"]["time_step"] = sim.world.data.time_step.to_numpy()
    steps = round(source.time / dt)
    checkpoint.put_state(sim, arrays, steps, source.initial_energy, "the branched run")
    return sim


def window_means(time: np.ndarray, force: np.ndarray, edges) -> np.ndarray:
    """``(layouts, len(edges) - 1)``: each layout's mean force in ``(edges[k], edges[k+1]]``."""
    out = np.full((force.shape[0], len(edges) - 1), np.nan)
    for k, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        w = (time > lo) & (time <= hi)
        if w.any():
            out[:, k] = force[:, w].mean(axis=1)
    return out


def first_above(time: np.ndarray, force: np.ndarray, threshold: float) -> np.ndarray:
    """``(layouts,)``: when each layout's force first exceeds ``threshold`` (NaN if never)."""
    hit = force > threshold
    return np.where(hit.any(axis=1), time[np.argmax(hit, axis=1)], np.nan)


def paired_shift(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """``(mean, standard error)`` of ``b - a`` layout by layout."""
    d = np.asarray(b, dtype=float) - np.asarray(a, dtype=float)
    return float(d.mean()), float(d.std(ddof=1) / np.sqrt(d.size))


def _scene(damping: float | None = None, rule: str | None = None, slide: float | None = None):
    from taichi_ice.experiments.validation import dem_scenes
    from taichi_ice.physics.friction import RateState
    from taichi_ice.scene.parse import load_scenario, scene_from_dict

    scene = dem_scenes.pillar("rate-state")
    if rule is not None:
        return scene.with_friction(RateState(below_v_star=rule))
    if damping is None and slide is None:
        return scene
    raw = copy.deepcopy(dict(load_scenario("pillar").raw))
    if damping is not None:
        raw.setdefault("ice", {})["tangential_damping"] = damping
    if slide is not None:
        raw.setdefault("ice", {})["slide_resolution"] = slide
    return scene_from_dict(raw, source="pillar").with_friction(scene.friction)


def _seeds(scene, n: int, first: int | None = None) -> list[int]:
    """The paper's layout and ``n - 1`` reseeded ones (dem_ensemble's), or with ``first``
    the seeds ``first, ..., first + n - 1`` (layouts none of the others share)."""
    if first is not None:
        return list(range(first, first + n))
    own = scene.simulation.seed  # the paper's layout first, as dem_ensemble's
    return [own, *[s for s in range(n + 1) if s != own][: n - 1]]


def _curves(
    scene, layouts: int, ratio: float, first: int | None = None, integrator: str = "euler"
) -> dict:
    from taichi_ice.engine.options import Options
    from taichi_ice.experiments.ensemble import run_ensemble
    from taichi_ice.experiments.metrics import probe_force_magnitude
    from taichi_ice.experiments.validation import dem_accuracy

    dt = dem_accuracy.field_step(ratio, scene.stable_dt)
    start = time.perf_counter()
    seeds = _seeds(scene, layouts, first)
    options = Options(dt=dt, force_dt=True, integrator=integrator)
    ens = run_ensemble(scene, seeds, until=UNTIL, options=options)
    return {
        "seeds": seeds,
        "time": np.asarray(ens.series[0]["time"]),
        "force": np.array([probe_force_magnitude(s) for s in ens.series]),
        "peak": np.array([m["peak_force"] for m in ens.metrics]),
        "friction_energy": np.array([m["friction_energy"] for m in ens.metrics]),
        "released": np.array([m["released"] for m in ens.metrics]),
        "status": ens.status,
        "wall_s": time.perf_counter() - start,
    }


def _branches(layouts: int, t0: float) -> dict:
    from taichi_ice.experiments.ensemble import reseeded
    from taichi_ice.experiments.metrics import probe_force_magnitude
    from taichi_ice.experiments.validation import dem_accuracy
    from taichi_ice.run.simulation import Simulation

    scene = _scene()
    scenes = [reseeded(scene, s) for s in _seeds(scene, layouts)]
    source = Simulation(
        scenes, dt=dem_accuracy.field_step(STEPS[0], scene.stable_dt), force_dt=True
    )
    source.run(until=t0)
    out = {}
    for ratio in STEPS:
        start = time.perf_counter()
        sim = branch(source, scenes, dem_accuracy.field_step(ratio, scene.stable_dt))
        result = sim.run(until=BRANCH_END)
        out[ratio] = {
            "time": np.asarray(result.series[0]["time"]),
            "force": np.array([probe_force_magnitude(s) for s in result.series]),
            "wall_s": time.perf_counter() - start,
        }
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder for JSON and PNG")
    parser.add_argument("--layouts", type=int, default=128, help="layouts of the curves")
    parser.add_argument("--branch-layouts", type=int, default=64, help="layouts branched")
    parser.add_argument("--t0", type=float, default=8.0, help="s: where the branches start")
    parser.add_argument("--damping", type=float, default=0.35, help="raised [ice] damping")
    parser.add_argument(
        "--rule",
        choices=RestRule.labels(),
        help="only the peak force at both steps with this rule below v_star (4.)",
    )
    parser.add_argument(
        "--steps",
        type=lambda text: tuple(float(x) for x in text.split(",")),
        default=STEPS,
        help="dt / stable_dt of --rule and --slide-resolution, comma-separated (default "
        f"{','.join(map(str, STEPS))}); the first is the one the others are held against",
    )
    parser.add_argument(
        "--slide-resolution",
        type=float,
        help="only the peak force at both steps with this [ice] slide_resolution (5.)",
    )
    parser.add_argument(
        "--first-seed",
        type=int,
        help="with --rule or --slide-resolution: the layouts' seeds from this one on, "
        "instead of the paper's layout and seeds 1, 2, ... (written to ..._seedsN.json)",
    )
    parser.add_argument(
        "--integrator",
        choices=INTEGRATORS,
        default="euler",
        help="with --rule or --slide-resolution: the runs' integrator (run --integrator; "
        "default euler), written to ..._INTEGRATOR.json when not euler",
    )
    args = parser.parse_args(argv)
    variant = args.rule is not None or args.slide_resolution is not None
    for option, given in (("--first-seed", args.first_seed is not None),
                          ("--integrator", args.integrator != "euler")):  # fmt: skip
        if given and not variant:
            parser.error(f"{option} goes with --rule or --slide-resolution")
    from taichi_ice import backend

    backend.init("cpu", "f64")
    if args.rule is not None:
        return _variant(args, _scene(rule=args.rule), "rule", args.rule, args.rule)
    if args.slide_resolution is not None:
        r = args.slide_resolution
        tag = f"slide_{r:g}" + ("" if args.steps == STEPS else "_" + "_".join(map(str, args.steps)))
        return _variant(args, _scene(slide=r), "slide_resolution", r, tag)
    record: dict = {
        "steps": list(STEPS),
        "layouts": args.layouts,
        "until_s": UNTIL,
        "slide_resolution": _scene().ice.slide_resolution,
    }

    # 1. Mean force curves.
    runs = {ratio: _curves(_scene(), args.layouts, ratio) for ratio in STEPS}
    t = runs[STEPS[0]]["time"]
    edges = np.arange(0.0, UNTIL + 0.5, 1.0)
    means = {r: window_means(t, runs[r]["force"], edges) for r in STEPS}
    rows = []
    for k in range(len(edges) - 1):
        a, b = means[STEPS[0]][:, k], means[STEPS[1]][:, k]
        se = float(np.hypot(a.std(ddof=1), b.std(ddof=1)) / np.sqrt(a.size))
        rows.append(
            {
                "window_s": [edges[k], edges[k + 1]],
                "mean_n": [float(a.mean()), float(b.mean())],
                "difference_in_se": float((a.mean() - b.mean()) / se) if se > 0 else 0.0,
            }
        )
    onsets = {
        f"{thr:g}": [float(np.nanmedian(first_above(t, runs[r]["force"], thr))) for r in STEPS]
        for thr in THRESHOLDS
    }
    record["curves"] = {
        "windows": rows,
        "median_first_above_s": onsets,
        "peak_mean_n": [float(runs[r]["peak"].mean()) for r in STEPS],
        "peak_n": [runs[r]["peak"].tolist() for r in STEPS],
        "wall_s": [runs[r]["wall_s"] for r in STEPS],
        "status": [runs[r]["status"] for r in STEPS],
    }
    print(f"mean probe force over {args.layouts} layouts (kN), at {STEPS[0]} and {STEPS[1]}:")
    for row in rows:
        lo, hi = row["window_s"]
        a, b = (m / 1e3 for m in row["mean_n"])
        print(
            f"  ({lo:4.1f}, {hi:4.1f}] s: {a:8.1f} {b:8.1f}"
            f"  ({row['difference_in_se']:+.1f} standard errors)"
        )
    for thr, (a, b) in onsets.items():
        print(f"  median first above {float(thr) / 1e3:g} kN: {a:.2f} s and {b:.2f} s")

    # 2. Paired branches.
    br = _branches(args.branch_layouts, args.t0)
    bt = br[STEPS[0]]["time"]
    bedges = np.arange(args.t0, BRANCH_END + 1e-9, 0.5)
    bmeans = {r: window_means(bt, br[r]["force"], bedges) for r in STEPS}
    brows = []
    print(f"paired branches of {args.branch_layouts} layouts from {args.t0:g} s (kN):")
    for k in range(len(bedges) - 1):
        base = bmeans[STEPS[0]][:, k]
        shift, se = paired_shift(base, bmeans[STEPS[1]][:, k])
        brows.append(
            {
                "window_s": [bedges[k], bedges[k + 1]],
                "mean_n": float(base.mean()),
                "paired_shift_n": shift,
                "standard_error_n": se,
            }
        )
        print(
            f"  ({bedges[k]:4.1f}, {bedges[k + 1]:4.1f}] s: {base.mean() / 1e3:8.1f} at "
            f"{STEPS[0]}, {STEPS[1]} {shift / 1e3:+7.1f} +- {se / 1e3:.1f}"
        )
    record["branches"] = {
        "layouts": args.branch_layouts,
        "t0_s": args.t0,
        "windows": brows,
        "wall_s": [br[r]["wall_s"] for r in STEPS],
    }

    # 3. The stick spring's dashpot.
    damped = _curves(_scene(args.damping), args.layouts, STEPS[1])
    shift, se = paired_shift(runs[STEPS[1]]["peak"], damped["peak"])
    record["damping"] = {
        "tangential_damping": [0.25, args.damping],
        "ratio": STEPS[1],
        "peak_mean_n": [float(runs[STEPS[1]]["peak"].mean()), float(damped["peak"].mean())],
        "peak_shift_n": shift,
        "peak_shift_standard_error_n": se,
        "wall_s": damped["wall_s"],
    }
    print(
        f"peak force at {STEPS[1]} stable_dt, tangential damping 0.25 -> {args.damping:g}: "
        f"{runs[STEPS[1]]['peak'].mean() / 1e6:.3f} -> {damped['peak'].mean() / 1e6:.3f} MN "
        f"({shift / 1e6:+.3f} +- {se / 1e6:.3f}); at {STEPS[0]}: "
        f"{runs[STEPS[0]]['peak'].mean() / 1e6:.3f} MN"
    )

    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "jam_dt.json").write_text(json.dumps(record, indent=1))
    _plot(t, means, edges, bedges, brows, record, args.out / "jam_dt.png")
    print(f"wrote {args.out / 'jam_dt.json'} and {args.out / 'jam_dt.png'}")
    return 0


def _variant(args, scene, key: str, value, tag: str) -> int:
    """4. and 5.: the peak force at ``args.steps`` of a variant of the scene (``key`` =
    ``value``), written to ``jam_dt_TAG.json``."""
    from taichi_ice.provenance import git_describe

    steps = args.steps
    tag += "" if args.first_seed is None else f"_seeds{args.first_seed}"
    integrator = args.integrator
    tag += "" if integrator == "euler" else f"_{integrator}"
    runs = {r: _curves(scene, args.layouts, r, args.first_seed, integrator) for r in steps}
    peaks = [runs[r]["peak"] for r in steps]
    record = {
        key: value,
        "slide_resolution": scene.ice.slide_resolution,
        "integrator": integrator,
        "steps": list(steps),
        "layouts": args.layouts,
        "seeds": runs[steps[0]]["seeds"],
        "until_s": UNTIL,
        "peak_mean_n": [float(p.mean()) for p in peaks],
        "peak_n": [p.tolist() for p in peaks],
        "friction_energy_j": [runs[r]["friction_energy"].tolist() for r in steps],
        "released": [runs[r]["released"].tolist() for r in steps],
        "wall_s": [runs[r]["wall_s"] for r in steps],
        "status": [runs[r]["status"] for r in steps],
        "git": git_describe(),
    }
    print(f"peak force with {key} {value} over {args.layouts} layouts:")
    for r, p in zip(steps, peaks):
        print(
            f"  {r:g} stable_dt: {p.mean() / 1e6:.3f} MN, {int(runs[r]['released'].sum())} "
            f"released ({runs[r]['wall_s']:.0f} s)"
        )
    if len(steps) > 1:  # the first against the others
        shifts = [paired_shift(p, peaks[0]) for p in peaks[1:]]
        record["peak_shift_n"] = [s for s, _ in shifts]
        record["peak_shift_standard_error_n"] = [e for _, e in shifts]
        for r, (shift, se) in zip(steps[1:], shifts):
            print(f"  {steps[0]:g} minus {r:g}: {shift / 1e6:+.3f} +- {se / 1e6:.3f} MN")
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"jam_dt_{tag}.json"
    path.write_text(json.dumps(record, indent=1))
    print(f"wrote {path}")
    return 0


def _plot(t, means, edges, bedges, brows, record, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    mid = 0.5 * (edges[:-1] + edges[1:])
    for ratio, m in means.items():
        se = m.std(axis=0, ddof=1) / np.sqrt(m.shape[0])
        axes[0].errorbar(
            mid,
            m.mean(axis=0) / 1e6,
            yerr=1.96 * se / 1e6,
            marker="o",
            ms=3,
            capsize=2,
            label=f"euler {ratio:g} stable_dt",
        )
    axes[0].set_xlabel("time (s)")
    axes[0].set_ylabel("mean probe force over the layouts (MN)")
    axes[0].set_title(f"independent runs, {record['layouts']} layouts, 1 s windows", fontsize=9)
    axes[0].legend(fontsize=8)
    bmid = 0.5 * (bedges[:-1] + bedges[1:])
    shift = np.array([r["paired_shift_n"] for r in brows]) / 1e3
    se = np.array([r["standard_error_n"] for r in brows]) / 1e3
    axes[1].errorbar(bmid, shift, yerr=1.96 * se, marker="o", ms=3, capsize=2)
    axes[1].axhline(0.0, color="k", lw=0.8)
    axes[1].set_xlabel("time (s)")
    axes[1].set_ylabel(f"mean force at {STEPS[1]} minus at {STEPS[0]} (kN)")
    axes[1].set_title(
        f"paired branches of {record['branches']['layouts']} layouts from "
        f"{record['branches']['t0_s']:g} s (95 % intervals)",
        fontsize=9,
    )
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.suptitle(
        "pillar, rate and state: where the Euler step's peak force parts with dt", fontsize=9
    )
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
