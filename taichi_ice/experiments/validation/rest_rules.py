"""What a rate-and-state interface remembers when it stops: the ``below_v_star`` rules.

One interface slides at 1 mm/s for 10 s, stops (V = 0 < v_star) for 5 s and slides again at
1 mm/s; mu(t) under ``paper`` (default), ``healing``, ``frozen`` and ``relaxing``
(``codes.RestRule``), and the steady-state and memory-only variants, from
``RateState.respond`` (NumPy). Writes ``fig_rest_rules.png`` and ``rest_rules.json`` (mu
just before the stop, while stopped, and just after the restart, per rule).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ...codes import RestRule
from ...physics.friction import MemoryOnly, RateState, SteadyState

STOP, RESTART, END = 10.0, 15.0, 30.0
SPEED = 1e-3  # m/s


def history(dt: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) and slip rates (m/s) of slide, stop, slide."""
    t = np.arange(0.0, END + 0.5 * dt, dt)
    return t, np.where((t > STOP) & (t < RESTART), 0.0, SPEED)


def curves(law: RateState | None = None) -> dict[str, np.ndarray]:
    """mu(t) of every rule and variant over :func:`history`."""
    law = law or RateState()
    t, v = history()
    out = {"time": t, "slip_rate": v}
    for rule in RestRule.labels():
        params = {k: v_ for k, v_ in law.to_dict().items() if k != "law"}
        out[rule] = RateState(**{**params, "below_v_star": rule}).respond(t, v)
    kw = {k: getattr(law, k) for k in ("A", "B", "mu0", "v_star")}
    out["steady-state"] = SteadyState(**kw).respond(t, v)
    out["memory-only (paper)"] = MemoryOnly(
        A=law.A, mu0=law.mu0, v_star=law.v_star, t_c=law.t_c
    ).respond(t, v)
    return out


def run(out_dir: str | Path, law: RateState | None = None) -> dict[str, Any]:
    """Write the figure and the JSON into ``out_dir``; returns the summary."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    c = curves(law)
    t = c["time"]
    before, during, after = (
        int(np.searchsorted(t, STOP)) - 1,
        int(np.searchsorted(t, 0.5 * (STOP + RESTART))),
        int(np.searchsorted(t, RESTART)),
    )
    summary = {
        name: {
            "mu_sliding_before_stop": float(mu[before]),
            "mu_mid_stop": float(mu[during]),
            "mu_at_restart": float(mu[after]),
        }
        for name, mu in c.items()
        if name not in ("time", "slip_rate")
    }
    (out_dir / "rest_rules.json").write_text(json.dumps(summary, indent=2) + "\n")
    plot(c, out_dir / "fig_rest_rules.png")
    print(f"rest rules: wrote {out_dir / 'fig_rest_rules.png'}")
    return summary


def plot(c: dict[str, np.ndarray], path: Path) -> None:
    from ...run.plots import subplots

    fig, ax = subplots(figsize=(8, 4.2), layout="constrained")
    styles = {
        "paper": ("C0", "-", 2.2),
        "healing": ("C1", "-", 1.4),
        "frozen": ("C2", "--", 1.4),
        "relaxing": ("C3", ":", 2.2),
        "steady-state": ("C7", ":", 1.4),
        "memory-only (paper)": ("C4", "-.", 1.2),
    }
    for name, (colour, ls, lw) in styles.items():
        label = f"rate-state, below_v_star = {name}" if name in RestRule.labels() else name
        ax.plot(c["time"], c[name], ls, color=colour, lw=lw, label=label)
    ax.axvspan(STOP, RESTART, color="0.9", zorder=0, label="stopped (V = 0)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("friction coefficient mu")
    ax.set_title("Slide at 1 mm/s, stop for 5 s, slide again")
    ax.legend(fontsize=8, loc="lower right")
    fig.savefig(path, dpi=90)


__all__ = ["curves", "history", "run"]
