"""Speed against accuracy of the state integrators: every method, float64 and float32,
NumPy and Taichi.

Accuracy: max |mu - exact| over two single-interface histories, at time steps halving
down to ~1e-3 t_c:

- ``ramp``: V piecewise linear with its knots on the grid (Figure 3b), so the integrators
  see the exact forcing: explicit and implicit Euler converge at order 1, the exponential
  method at order 2 (x at the half step), RK4 at order 4.
- ``sinusoid``: the fast sinusoid (Figure 3c) sampled at the steps and taken linear
  between samples, as a DEM provides it. The interpolation error of the half-step slip
  rate is O(dt^2), so RK4 drops to order 2 and the exponential method keeps 2.

Speed: nanoseconds per interface-step of the batched drivers (``respond_batch_ti`` in
Taichi, ``respond_batch`` in NumPy) on 1e6 interfaces with their own random slip-rate
histories. Error against wall time puts the two together: the cost of one history at step
dt is (steps) x (ns per interface-step).

Taichi holds one precision per process, so each precision runs in its own worker process
(``python -m taichi_ice.commands.validate speed_accuracy --worker f32 ...``); the caller's
Taichi runtime, if any, is left alone.

Writes ``speed_accuracy.png`` and ``speed_accuracy.json``.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from ...physics.friction import METHODS, RateState, method_code
from .single_interface import Profile, profiles
from .worker import study_worker

# Halvings of the step: ramp dt = 1 s ... 2^-10 s; sinusoid dt = P/4 ... P/4096.
RAMP_DTS = tuple(2.0**-k for k in range(11))
SINUSOID_DTS = tuple(2.0**-k for k in range(2, 13))
QUICK_LEVELS = 6
# Interface count and samples per history of the timing runs.
N_INTERFACES = 1_000_000
QUICK_N_INTERFACES = 10_000
BENCH_SAMPLES = 17
BENCH_DT = 0.05  # s
# Order fits use errors above this many float epsilons (below it round-off dominates) and
# steps at or below 0.1 t_c (the asymptotic range).
ORDER_FLOOR_EPS = 1e3
ORDER_MAX_H = 0.1


def study_profiles(quick: bool = False) -> dict[str, tuple[Profile, tuple[float, ...]]]:
    """The two accuracy histories and their steps (s)."""
    shapes = profiles()
    levels = QUICK_LEVELS if quick else None
    return {
        "ramp": (shapes["ramp"], RAMP_DTS[:levels]),
        "sinusoid": (_shorter(shapes["fast_sinusoid"], 10.0), SINUSOID_DTS[:levels]),
    }


def _shorter(profile: Profile, duration: float) -> Profile:
    from dataclasses import replace

    return replace(profile, duration=duration)


def measured_order(dts: list[float], errors: list[float], t_c: float, eps: float) -> float | None:
    """Least-squares slope of log(error) against log(dt) in the asymptotic range."""
    dts_a, err_a = np.asarray(dts), np.asarray(errors)
    use = (err_a > ORDER_FLOOR_EPS * eps) & (dts_a <= ORDER_MAX_H * t_c) & np.isfinite(err_a)
    if use.sum() < 2:
        return None
    slope = np.polyfit(np.log(dts_a[use]), np.log(err_a[use]), 1)[0]
    return float(slope)


# --------------------------------------------------------------------------------------------
# Worker: one precision, one process.
# --------------------------------------------------------------------------------------------


def _best_time(fn, repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def worker(precision: str, arch: str, n_interfaces: int, quick: bool) -> dict[str, Any]:
    """Errors and timings for one precision; starts Taichi in that precision."""
    from ... import backend
    from ...physics.batched import (
        respond_batch,
        respond_batch_ti,
        respond_batch_ti_unchecked,
        respond_batch_unchecked,
    )

    backend.init(arch, precision)
    dtype = backend.real_dtype(precision)
    law = RateState()
    runs = []
    for name, (profile, dts) in study_profiles(quick).items():
        for method in METHODS:
            for impl in ("taichi", "numpy"):
                errors, steps = [], []
                for dt in dts:
                    t, v = profile.grid(dt)
                    mu_exact = profile.exact(t, law)
                    if impl == "taichi":
                        mu = respond_batch_ti(t, v, law, method=method)[0]
                    else:
                        mu = respond_batch(t, v, law, method=method, dtype=dtype)[0]
                    errors.append(float(np.max(np.abs(mu.astype(np.float64) - mu_exact))))
                    steps.append(int(t.size - 1))
                runs.append(
                    {
                        "profile": name,
                        "method": method,
                        "precision": precision,
                        "backend": impl,
                        "dt": list(dts),
                        "steps": steps,
                        "max_error": errors,
                        "order": measured_order(
                            list(dts), errors, law.t_c, float(np.finfo(dtype).eps)
                        ),
                    }
                )
            print(
                f"speed/accuracy [{precision}] {name:8s} {method:11s} error at the finest step "
                f"{errors[-1]:.2e}",
                file=sys.stderr,
                flush=True,
            )
    rng = np.random.default_rng(20130301)
    # Slip rates log-uniform from v_star to 1 cm/s, a different history per interface; the
    # timed calls skip the input checks and copies so that they measure the integration.
    t = (np.arange(BENCH_SAMPLES) * BENCH_DT).astype(dtype)
    v = (10.0 ** rng.uniform(-5.0, -2.0, size=(n_interfaces, BENCH_SAMPLES))).astype(dtype)
    params = np.asarray([law.params], dtype=dtype)
    mu_out = np.empty_like(v)
    interface_steps = n_interfaces * (BENCH_SAMPLES - 1)
    timings = []
    for method in METHODS:
        code = method_code(method)
        respond_batch_ti_unchecked(t, v[:2], params, code, mu_out[:2])  # compile, untimed
        taichi_s = _best_time(lambda c=code: respond_batch_ti_unchecked(t, v, params, c, mu_out), 3)
        numpy_s = _best_time(lambda c=code: respond_batch_unchecked(t, v, params, c, dtype), 2)
        for impl, seconds in (("taichi", taichi_s), ("numpy", numpy_s)):
            timings.append(
                {
                    "method": method,
                    "precision": precision,
                    "backend": impl,
                    "n_interfaces": n_interfaces,
                    "steps": BENCH_SAMPLES - 1,
                    "seconds": seconds,
                    "ns_per_interface_step": seconds / interface_steps * 1e9,
                }
            )
        print(
            f"speed/accuracy [{precision}] {method:11s} at {n_interfaces:.0e} interfaces: "
            f"Taichi {taichi_s / interface_steps * 1e9:6.1f} ns, NumPy "
            f"{numpy_s / interface_steps * 1e9:6.1f} ns per interface-step",
            file=sys.stderr,
            flush=True,
        )
    # One interface through RateState.respond, the plain-Python reference loop.
    profile, dts = study_profiles(quick)["sinusoid"]
    t1, v1 = profile.grid(dts[-1])
    single_s = _best_time(lambda: law.respond(t1, v1), 1)
    return {
        "precision": precision,
        "arch": arch,
        "advanced_optimization": backend.optimized(),
        "optimize": backend.compile_level(),
        "threads": os.cpu_count(),
        "runs": runs,
        "timings": timings,
        "single_interface_numpy_us_per_step": single_s / (t1.size - 1) * 1e6,
    }


def _run_worker(
    precision: str, arch: str, n_interfaces: int, quick: bool, optimize: bool | str | None
) -> dict[str, Any]:
    from ... import backend

    with tempfile.TemporaryDirectory() as tmp:
        result = Path(tmp) / "result.json"
        cmd, env = study_worker(
            "speed_accuracy",
            precision,
            *("--arch", arch, "--interfaces", str(n_interfaces), "--result", str(result)),
            *(["--quick"] if quick else []),
        )
        if optimize is not None:
            env[backend.OPTIMIZE_ENV] = backend.optimize_level(optimize)
        proc = subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, check=False)
        if proc.returncode != 0:
            raise RuntimeError(f"speed/accuracy worker for {precision} failed: {' '.join(cmd)}")
        return json.loads(result.read_text())


# --------------------------------------------------------------------------------------------
# Study: both precisions, the chart, the summary.
# --------------------------------------------------------------------------------------------


def run(
    out_dir: str | Path,
    *,
    quick: bool = False,
    arch: str = "cpu",
    n_interfaces: int | None = None,
    precisions: tuple[str, ...] = ("f64", "f32"),
    optimize: bool | str | None = None,
) -> dict[str, Any]:
    """Measure error against step and against wall time; write the chart and the JSON.

    Args:
        out_dir: folder for ``speed_accuracy.png`` and ``speed_accuracy.json``.
        quick: fewer step halvings and 1e4 interfaces in the timings.
        arch: Taichi arch of the workers.
        n_interfaces: interfaces in the timing runs (default 1e6, or 1e4 when quick).
        precisions: the precisions to measure, each in its own process.
        optimize: the workers' compile setting, "off", "on" or "full" (or a bool; None: as
            ``TAICHI_ICE_OPTIMIZE`` says; ``validate`` passes the user's setting, since the
            other studies compile without Taichi's advanced passes: ``compile_for_studies``).

    Returns:
        The JSON summary as a dict.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    n = n_interfaces or (QUICK_N_INTERFACES if quick else N_INTERFACES)
    start = time.perf_counter()
    parts = []
    for precision in precisions:
        print(f"speed/accuracy: {precision} worker ({arch}, {n:.0e} interfaces) ...", flush=True)
        parts.append(_run_worker(precision, arch, n, quick, optimize))
    runs = [r for p in parts for r in p["runs"]]
    timings = [t for p in parts for t in p["timings"]]
    cost = {
        (t["method"], t["precision"], t["backend"]): t["ns_per_interface_step"] for t in timings
    }
    for r in runs:
        per_step = cost[(r["method"], r["precision"], r["backend"])]
        r["wall_s_per_interface"] = [s * per_step * 1e-9 for s in r["steps"]]
    orders = {
        f"{r['profile']}/{r['method']}": r["order"]
        for r in runs
        if r["precision"] == "f64" and r["backend"] == "taichi"
    }
    summary = {
        "law": RateState().to_dict(),
        "arch": arch,
        "n_interfaces": n,
        "convergence_order_f64": orders,
        "ns_per_interface_step": {
            f"{t['method']}/{t['precision']}/{t['backend']}": t["ns_per_interface_step"]
            for t in timings
        },
        "single_interface_numpy_us_per_step": parts[0]["single_interface_numpy_us_per_step"],
        "runs": runs,
        "timings": timings,
    }
    figure = out_dir / "speed_accuracy.png"
    plot_speed_accuracy(runs, figure)
    summary["figure"] = figure.name
    path = out_dir / "speed_accuracy.json"
    path.write_text(json.dumps(summary, indent=2) + "\n")
    print(
        f"speed/accuracy: wrote {figure} and {path} [{time.perf_counter() - start:.0f} s]",
        flush=True,
    )
    return summary


def plot_speed_accuracy(runs: list[dict[str, Any]], path: Path) -> None:
    """2 x 2: error against dt / t_c (top) and against wall time (bottom), ramp and sinusoid."""
    from matplotlib.lines import Line2D

    from ...run.plots import subplots

    colors = {"exponential": "C0", "euler": "C3", "implicit": "C2", "rk4": "C1"}
    styles = {"f64": "-", "f32": "--"}
    markers = {"taichi": "o", "numpy": "x"}
    t_c = RateState().t_c
    fig, axes = subplots(2, 2, figsize=(11, 8.2), layout="constrained")
    titles = {
        "ramp": "ramp, knots on the grid",
        "sinusoid": "fast sinusoid, sampled",
    }
    for col, name in enumerate(("ramp", "sinusoid")):
        for r in (r for r in runs if r["profile"] == name):
            kwargs = {
                "color": colors[r["method"]],
                "ls": styles[r["precision"]],
                "marker": markers[r["backend"]],
                "ms": 4,
                "mfc": "none",
                "lw": 1.0,
            }
            h = np.asarray(r["dt"]) / t_c
            axes[0, col].loglog(h, r["max_error"], **kwargs)
            axes[1, col].loglog(r["wall_s_per_interface"], r["max_error"], **kwargs)
        axes[0, col].set_title(f"({'ab'[col]}) {titles[name]}: error against step")
        axes[0, col].set_xlabel("dt / t_c")
        axes[1, col].set_title(f"({'cd'[col]}) {name}: error against wall time")
        axes[1, col].set_xlabel("wall time per interface for the whole history (s), batch of 1e6")
        for row in (0, 1):
            axes[row, col].set_ylabel("max |mu - exact|")
            axes[row, col].grid(True, which="major", alpha=0.3)
    # Reference slopes on the step axes, from the lower left of each panel's data.
    for col, name in enumerate(("ramp", "sinusoid")):
        mine = [r for r in runs if r["profile"] == name]
        h0 = 2.0 * min(min(r["dt"]) for r in mine) / t_c
        e0 = 3.0 * min(min(r["max_error"]) for r in mine)
        h = np.array([h0, 10.0 * h0])
        for order in (1, 2, 4):
            axes[0, col].loglog(h, e0 * (h / h0) ** order, color="0.6", lw=0.8)
            axes[0, col].text(
                h[1], e0 * 10.0**order, f" slope {order}", color="0.4", fontsize=7, va="center"
            )
    handles = [Line2D([], [], color=c, label=m) for m, c in colors.items()]
    handles += [Line2D([], [], color="k", ls=s, label=p) for p, s in styles.items()]
    handles += [
        Line2D([], [], color="k", marker=mk, ls="none", mfc="none", label=b)
        for b, mk in markers.items()
    ]
    axes[0, 0].legend(handles=handles, fontsize=8, loc="lower right", ncol=2)
    fig.suptitle("Rate-and-state integrators: accuracy against step and against cost")
    fig.savefig(path, dpi=80)
