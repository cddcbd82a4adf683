"""How often a loaded jam's rate-and-state contacts end and start their sliding interfaces, per
contact-second, at several steps from one state: ``python validation/interface_events.py
--out DIR``.

The paper's rule below v_star: a contact whose slip rate falls below ``v_star`` in a step
takes mu0 and ends its interface; when it slides again it starts a new one at theta = 0
(strong), and a slip that changes sign ends it too (``slip.contact_friction``). The step
decides both on its own slip rate, once a step. This script counts, contact by contact and
step by step, what the rule decides in a jam:

- ``ends``: an interface ended while its contact held (theta from a value to ``NO_INTERFACE``);
- ``births``: a held contact started an interface (the reverse; not a contact's first
  touch, whose slot held ``NEW_CONTACT``);
- ``reversals``: a live interface whose slip changed sign (under the paper's rule, ended and
  started again in one step; under the others it goes on);
- ``theta_erased``: what the ends take, -theta of each interface where it ended (and, under
  the paper's rule, where its slip reversed), per contact-second: the ends' effect on the
  force, which converges where their count does not (``docs/accuracy.md``);
- ``stuck``: the share of contact-steps with no interface (slip at or below ``v_star``);
- ``mu_live``: the mean friction coefficient of the contacts with an interface, ``mu_all``
  of every held contact (mu0 without one);
- the slip rate an interface starts at, over ``v_star`` (quantiles);
- how long the interfaces born in the span lived, in steps and seconds: an interface that
  lives a step or two at every dt is chatter at the step's own scale, one that lives a
  fixed time is a physical event the step resolves or not.

``--layouts`` pillar layouts (the paper's and reseeded ones) run at the default step to
``--t0`` (a jam carrying load), and from that one state (``jam_dt.branch``) each step of
``--steps`` runs ``--span`` seconds, its contacts read after every step. A contact lives in
one slot (its owner body's), so the rates are per contact; each step's fields are read
through NumPy, so the finest step takes minutes. Writes ``interface_events.json`` and prints
the table (docs/accuracy.md quotes it). ``--rule healing`` (``frozen``, ``relaxing``) runs the same
under that rule below v_star, from its own jam (the run to ``--t0`` under it too).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import time
from pathlib import Path

import numpy as np

from taichi_ice.codes import RestRule

STEPS = (0.2, 0.1, 0.05, 0.025, 0.0125)  # dt / stable_dt


def _jam_dt():
    """``validation/jam_dt.py`` as a module (its scene and ``branch``)."""
    spec = importlib.util.spec_from_file_location("jam_dt", Path(__file__).with_name("jam_dt.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _states(before: dict, after: dict) -> dict:
    """Each slot's state either side of a step: ``held`` (the same partner before and
    after), ``live0``/``live1`` (an interface), ``none0``/``none1`` (touching, no
    interface: ``NO_INTERFACE``; a slot at ``NEW_CONTACT`` is neither)."""
    from taichi_ice.physics.slip import NEW_CONTACT_ABOVE, NO_INTERFACE_ABOVE

    def none(theta):
        return (theta > NO_INTERFACE_ABOVE) & (theta < NEW_CONTACT_ABOVE)

    return {
        "held": (after["partner"] >= 0) & (after["partner"] == before["partner"]),
        "live0": before["theta"] < NO_INTERFACE_ABOVE,
        "live1": after["theta"] < NO_INTERFACE_ABOVE,
        "none0": none(before["theta"]),
        "none1": none(after["theta"]),
    }


def births(before: dict, after: dict) -> np.ndarray:
    """Where a held contact started an interface in the step (from ``NO_INTERFACE``: not a
    contact's first touch)."""
    m = _states(before, after)
    return m["held"] & m["none0"] & m["live1"]


def count_step(before: dict, after: dict, v_star: float) -> dict:
    """What the rule decided in one step, over every slot whose contact held through it
    (the same partner before and after). ``before`` and ``after``: ``partner``, ``theta`` and
    ``slip`` arrays of equal shape (the World's ``contact_*`` fields)."""
    m = _states(before, after)
    held, live0, live1 = m["held"], m["live0"], m["live1"]
    ends = held & live0 & m["none1"]
    reversals = held & live0 & live1 & (before["slip"] * after["slip"] < 0)
    return {
        "contact_steps": int(held.sum()),
        "stuck_steps": int((held & m["none1"]).sum()),
        "below_steps": int((held & (np.abs(after["slip"]) <= v_star)).sum()),
        "ends": int(ends.sum()),
        "births": int(births(before, after).sum()),
        "reversals": int(reversals.sum()),
        # How much memory the ends erase: -theta of each interface where it ended (the
        # strength it gave back, in units of mu), and of each live interface whose slip
        # reversed (erased under the paper's rule, kept under the others).
        "theta_ended": float(-before["theta"][ends].sum()),
        "theta_reversed": float(-before["theta"][reversals].sum()),
    }


def episodes(
    before: dict, after: dict, born: np.ndarray, k: int, reversal_ends: bool = True
) -> list[int]:
    """The lengths (steps) of the interfaces that ended in step ``k`` (counted from 0) of a
    contact that held since their birth in the span (under the paper's rule,
    ``reversal_ends``, a slip that changed sign ends one and starts the next), and ``born``
    brought up to date: the step of each slot's birth, -1 where none was seen (a slot whose
    partner changed, or an interface older than the span)."""
    m = _states(before, after)
    held, live0, live1, none1 = m["held"], m["live0"], m["live1"], m["none1"]
    reversed_ = held & live0 & live1 & (before["slip"] * after["slip"] < 0) & reversal_ends
    ended = held & live0 & (none1 | reversed_) & (born >= 0)
    out = (k - born[ended]).tolist()
    born[~held | (live0 & none1)] = -1
    born[held & ((m["none0"] & live1) | reversed_)] = k  # a reversal ends one and starts one
    return out


def episode_summary(lengths: list[int], dt: float) -> dict:
    """How long the interfaces born and ended in the span lived: in steps (the share that
    lived one step, two, at most four) and in seconds (median)."""
    x = np.asarray(lengths)
    if not x.size:
        return {"episodes": 0}
    return {
        "episodes": int(x.size),
        "episode_1_step": float(np.mean(x == 1)),
        "episode_2_steps": float(np.mean(x == 2)),
        "episode_at_most_4_steps": float(np.mean(x <= 4)),
        "episode_median_steps": float(np.median(x)),
        "episode_median_s": float(np.median(x) * dt),
        "episode_mean_s": float(np.mean(x) * dt),
    }


def live_mu(theta: np.ndarray, slip: np.ndarray, law) -> np.ndarray:
    """The friction coefficient of contacts with an interface (``rate_state_mu`` at their
    slip rate, held at ``v_star`` from below, as the law takes it; under ``relaxing``, mu0
    below v_star, where the interface is kept)."""
    y = np.log(np.maximum(np.abs(slip), law.v_star) / law.v_star)
    mu = np.maximum(law.mu0 + theta + law.A * y, 0.0)
    if law.below_v_star == "relaxing":
        mu = np.where(np.abs(slip) < law.v_star, law.mu0, mu)
    return mu


def _fields(world) -> dict:
    d = world.data
    return {
        "partner": d.contact_partner.to_numpy(),
        "theta": d.contact_theta.to_numpy(),
        "slip": d.contact_slip.to_numpy(),
    }


def run(layouts: int, t0: float, span: float, steps=STEPS, first_seed: int = 1, rule=None) -> dict:
    """The counts at each step of ``steps`` over ``span`` s from the state at ``t0``, under
    the rule below v_star ``rule`` (None: the paper's, the scene's own)."""
    from taichi_ice.physics.slip import NEW_CONTACT_ABOVE, NO_INTERFACE_ABOVE
    from taichi_ice.run.simulation import Simulation
    from taichi_ice.scene.parse import reseeded

    jam_dt = _jam_dt()
    base = jam_dt._scene(rule=rule)
    scenes = [base] + [reseeded(base, s) for s in range(first_seed, first_seed + layouts - 1)]
    law = base.friction
    source = Simulation(scenes)
    start = time.perf_counter()
    source.step(round(t0 / source.world.dt))
    out = {
        "t0_s": source.time,
        "span_s": span,
        "layouts": layouts,
        "seeds": [s.simulation.seed for s in scenes],
        "source_dt_over_stable": source.world.dt / base.stable_dt,
        "source_wall_s": time.perf_counter() - start,
        "v_star": law.v_star,
        "rule": law.below_v_star,
        "steps": {},
    }
    for ratio in steps:
        sim = jam_dt.branch(source, scenes, ratio * base.stable_dt)
        world = sim.world
        n = round(span / world.dt)
        before = _fields(world)
        totals: dict = {}
        mu_sum, mu_n = 0.0, 0
        all_sum, all_n = 0.0, 0
        born = np.full(before["partner"].shape, -1)  # the step each slot's interface began
        lengths = []  # steps each interface born in the span lived to its end
        birth_slips = []  # |slip| / v_star of each interface started, in its first step
        start = time.perf_counter()
        for k in range(n):
            world.advance(1)
            after = _fields(world)
            for key, value in count_step(before, after, law.v_star).items():
                totals[key] = totals.get(key, 0) + value
            lengths += episodes(before, after, born, k, law.below_v_star == "paper")
            birth_slips.append(np.abs(after["slip"][births(before, after)]) / law.v_star)
            live = (after["partner"] >= 0) & (after["theta"] < NO_INTERFACE_ABOVE)
            mu = live_mu(after["theta"][live], after["slip"][live], law)
            mu_sum, mu_n = mu_sum + float(mu.sum()), mu_n + mu.size
            none = (after["partner"] >= 0) & ~live & (after["theta"] < NEW_CONTACT_ABOVE)
            all_sum += float(mu.sum()) + law.mu0 * int(none.sum())  # no interface: mu0
            all_n += mu.size + int(none.sum())
            before = after
        world.check()
        seconds = totals["contact_steps"] * world.dt
        out["steps"][str(ratio)] = {
            **totals,
            "dt_s": world.dt,
            "n_steps": n,
            "contact_seconds": seconds,
            "ends_per_s": totals["ends"] / seconds,
            "births_per_s": totals["births"] / seconds,
            "reversals_per_s": totals["reversals"] / seconds,
            # -theta erased per contact-second (units of mu per s): what the ends do to the
            # force, where their count is a count of events however small
            "theta_ended_per_s": totals["theta_ended"] / seconds,
            "theta_erased_per_s": (
                totals["theta_ended"]
                + (totals["theta_reversed"] if law.below_v_star == "paper" else 0.0)
            )
            / seconds,
            "mean_theta_at_end": totals["theta_ended"] / max(totals["ends"], 1),
            "stuck_share": totals["stuck_steps"] / totals["contact_steps"],
            "below_share": totals["below_steps"] / totals["contact_steps"],
            "mu_live": mu_sum / max(mu_n, 1),
            "mu_all": all_sum / max(all_n, 1),
            **episode_summary(lengths, world.dt),
            "birth_slip_over_v_star_q10_q50_q90": np.quantile(
                np.concatenate(birth_slips), [0.1, 0.5, 0.9]
            ).tolist()
            if totals["births"]
            else None,
            "wall_s": time.perf_counter() - start,
        }
        del sim, world
    return out


def table(result: dict) -> str:
    rows = [
        "| step (stable_dt) | steps | contact-s | ends /s | births /s | reversals /s "
        "| -theta erased /s | stuck | mean mu, live | mean mu, all | interfaces born and ended "
        "| of 1 step | of <= 4 | median life |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for ratio, r in result["steps"].items():
        lived = "| 0 | - | - | - |"
        if r["episodes"]:
            lived = (
                f"| {r['episodes']} | {r['episode_1_step']:.2f} | "
                f"{r['episode_at_most_4_steps']:.2f} | {r['episode_median_s'] * 1e3:.3g} ms |"
            )
        rows.append(
            f"| {ratio} | {r['n_steps']} | {r['contact_seconds']:.0f} | {r['ends_per_s']:.2f} | "
            f"{r['births_per_s']:.2f} | {r['reversals_per_s']:.2f} | "
            f"{r['theta_erased_per_s']:.4f} | {r['stuck_share']:.3f} | "
            f"{r['mu_live']:.4f} | {r['mu_all']:.4f} " + lived
        )
    return "\n".join(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder for the JSON")
    parser.add_argument("--layouts", type=int, default=4, help="pillar layouts, one batch")
    parser.add_argument("--first-seed", type=int, default=1, help="seed of the 2nd layout on")
    parser.add_argument("--t0", type=float, default=15.0, help="s: where the branches start")
    parser.add_argument("--span", type=float, default=0.5, help="s each step runs")
    parser.add_argument("--rule", choices=RestRule.labels(), help="the rule below v_star")
    parser.add_argument(
        "--steps", default=",".join(map(str, STEPS)), help="dt / stable_dt, comma-separated"
    )
    args = parser.parse_args(argv)
    steps = [float(s) for s in args.steps.split(",")]
    result = run(args.layouts, args.t0, args.span, steps, args.first_seed, args.rule)
    args.out.mkdir(parents=True, exist_ok=True)
    rule = f"_{args.rule}" if args.rule else ""
    name = f"interface_events_t{args.t0:g}_seed{args.first_seed}{rule}.json"
    (args.out / name).write_text(json.dumps(result, indent=1))
    print(table(result))
    print(f"wrote {args.out / name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
