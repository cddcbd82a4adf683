"""Stability of the state integrators at large steps (h = dt / t_c).

An interface in equilibrium at V1 steps to V2 and then slides at V2; the exact theta relaxes
to -B ln(V2 / v_star) with e^{-t/t_c}. Each method multiplies the deviation by its
amplification factor R(h) per step:

    exponential e^{-h};  explicit Euler 1 - h;  implicit 1 / (1 + h);
    RK4 1 - h + h^2/2 - h^3/6 + h^4/24.

|R| > 1 (divergence) for explicit Euler past h = 2 and RK4 past h = 2.785293563...; the
exponential and implicit methods stay bounded at any step. ``RateState.respond`` refuses
the unstable steps (``StabilityError``) unless ``check_stability=False``, which this study
passes to show what the refusal prevents.

Writes ``stability.png`` and ``stability.json``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import StabilityError
from ...physics.friction import EULER_STABILITY_LIMIT, RK4_STABILITY_LIMIT, RateState

V_BEFORE = 1e-4  # m/s
V_AFTER = 1e-3  # m/s
# Steps (h = dt / t_c) on either side of each limit, and far past them.
CASES = (
    ("euler", 1.9),
    ("euler", 2.1),
    ("rk4", 2.7),
    ("rk4", 2.9),
    ("implicit", 2.9),
    ("implicit", 20.0),
    ("exponential", 2.9),
    ("exponential", 20.0),
)


def amplification(method: str, h: np.ndarray | float) -> np.ndarray:
    """Per-step amplification factor R(h) of a method on d theta/dt = -theta / t_c."""
    h = np.asarray(h, dtype=np.float64)
    if method == "exponential":
        return np.exp(-h)
    if method == "euler":
        return 1.0 - h
    if method == "implicit":
        return 1.0 / (1.0 + h)
    if method == "rk4":
        return 1.0 - h + h**2 / 2.0 - h**3 / 6.0 + h**4 / 24.0
    raise ValueError(f"unknown method {method!r}")


def run(
    out_dir: str | Path, *, quick: bool = False, law: RateState | None = None
) -> dict[str, Any]:
    """Integrate the step response at the ``CASES`` steps; write the chart and the JSON.

    Args:
        out_dir: folder for ``stability.png`` and ``stability.json``.
        quick: a shorter run.
        law: the rate-and-state law; default the paper's.
    """
    law = law or RateState()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    duration = (60.0 if quick else 200.0) * law.t_c
    x1, x2 = law.slip_log(V_BEFORE), law.slip_log(V_AFTER)
    offset = law.B * (x2 - x1)  # theta(0+) minus its final value
    results = []
    curves = []
    for method, h in CASES:
        dt = h * law.t_c
        # The jump takes 1 ps; every later step is dt.
        t = np.concatenate([[0.0], 1e-12 + dt * np.arange(int(duration / dt) + 1)])
        v = np.where(t > 0.0, V_AFTER, V_BEFORE)
        refused = None
        try:
            law.respond(t, v, method=method)
        except StabilityError as err:
            refused = str(err)
        _, theta = law.respond(t, v, method=method, check_stability=False, return_theta=True)
        exact_theta = -law.B * x2 + offset * np.exp(-t / law.t_c)
        deviation = np.abs(theta - exact_theta) / offset
        # Deviation from the final steady state shrinks or grows by |R| each step.
        # Measured over the first steps, before it reaches round-off or overflows.
        from_final = np.abs(theta + law.B * x2)[1:21]
        stop = np.flatnonzero(~np.isfinite(from_final) | (from_final <= 1e-12 * offset))
        usable = from_final[: stop[0] if stop.size else from_final.size]
        growth = float(np.exp(np.mean(np.diff(np.log(usable))))) if usable.size > 1 else math.nan
        theory = float(abs(amplification(method, h)))
        finite = np.isfinite(deviation)
        results.append(
            {
                "method": method,
                "h": h,
                "dt": dt,
                "steps": int(t.size - 1),
                "amplification_theory": theory,
                "amplification_measured": growth if math.isfinite(growth) else None,
                "diverges": bool(theory > 1.0),
                "max_deviation_over_offset": float(np.max(deviation[finite])),
                "final_deviation_over_offset": float(deviation[finite][-1]),
                "refused": refused is not None,
                "refusal": refused,
            }
        )
        curves.append((method, h, t / law.t_c, deviation))
        print(
            f"stability: {method:11s} h = {h:5.2f}  |R| = {theory:8.4f}  "
            f"deviation after {t[-1] / law.t_c:.0f} t_c = {deviation[finite][-1]:.2e} x offset"
            f"{'  (refused by default)' if refused else ''}"
        )
    summary = {
        "law": law.to_dict(),
        "limits_h": {"euler": EULER_STABILITY_LIMIT, "rk4": RK4_STABILITY_LIMIT},
        "v_before": V_BEFORE,
        "v_after": V_AFTER,
        "cases": results,
    }
    figure = out_dir / "stability.png"
    plot_stability(curves, figure)
    summary["figure"] = figure.name
    path = out_dir / "stability.json"
    path.write_text(json.dumps(summary, indent=2) + "\n")
    print(f"stability: wrote {figure} and {path}")
    return summary


def plot_stability(curves: list[tuple[str, float, np.ndarray, np.ndarray]], path: Path) -> None:
    """Left: |theta - exact| over time; right: |R(h)| of each method with the limits."""
    from ...run.plots import subplots

    colors = {"exponential": "C0", "euler": "C3", "implicit": "C2", "rk4": "C1"}
    fig, (ax, ax2) = subplots(1, 2, figsize=(11, 4.3), layout="constrained")
    floor = 1e-17
    for method, h, t_over_tc, deviation in curves:
        unstable = abs(float(amplification(method, h))) > 1.0
        ax.semilogy(
            t_over_tc,
            np.clip(deviation, floor, None),
            "-" if unstable else "--",
            marker="." if unstable else None,
            color=colors[method],
            alpha=1.0 if unstable or h < 10 else 0.6,
            label=f"{method}, dt = {h:g} t_c" + (" (refused)" if unstable else ""),
        )
    ax.axhline(1.0, color="0.5", lw=0.8)
    ax.set_ylim(floor, 1e8)
    ax.set_xlabel("time / t_c")
    ax.set_ylabel("|theta - exact| / initial offset")
    ax.set_title("(a) step response at large steps")
    ax.legend(fontsize=7, loc="upper left", ncol=2)
    h = np.linspace(0.0, 6.0, 601)
    for method, color in colors.items():
        ax2.plot(h, np.abs(amplification(method, h)), color=color, label=method)
    ax2.axhline(1.0, color="0.5", lw=0.8)
    for limit, name in ((EULER_STABILITY_LIMIT, "2"), (RK4_STABILITY_LIMIT, "2.785")):
        ax2.axvline(limit, color="0.5", ls=":", lw=0.8)
        ax2.text(limit, 2.7, f" h = {name}", fontsize=8, color="0.3")
    ax2.set_ylim(0.0, 3.0)
    ax2.set_xlabel("h = dt / t_c")
    ax2.set_ylabel("|amplification per step|")
    ax2.set_title("(b) |R(h)|: above 1 the method diverges")
    ax2.legend(fontsize=8)
    fig.savefig(path, dpi=90)
