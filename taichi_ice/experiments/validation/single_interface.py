"""The paper's Figure 3: friction of one interface under four slip-rate profiles.

Step, ramp, fast sinusoid and slow sinusoid (Lishman et al. 2013,
doi:10.1016/j.coldregions.2013.03.004), each integrated by every method of ``RateState`` and
compared with its exact solution (``taichi_ice.physics.exact``). For the sinusoids the gain and
phase of mu relative to ln V are measured from the fundamental harmonic over whole periods
after the start-up transient has died out, and compared with the transfer function
``H(w) = A - B / (1 + i w t_c)``: in phase when fast, 180 degrees out of phase when slow.

Writes ``fig3_single_interface.png`` and ``single_interface.json``.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...physics import exact
from ...physics.friction import RateState

# The sampled histories take a slip-rate jump over this interval (s): t must increase
# strictly and V is linear between samples. Over it theta moves by ~B dx JUMP / t_c ~ 1e-13.
JUMP = 1e-12


@dataclass(frozen=True)
class Profile:
    """A slip-rate history V(t): piecewise linear through knots, or a sinusoid.

    Attributes:
        name: key in the JSON summary. title: panel title.
        duration: simulated time (s). dt: time step of Figure 3 (s).
        knots_t, knots_v: knot times (s, non-decreasing; a repeated time is a jump) and
            slip rates (m/s) of a piecewise-linear profile.
        v_mean, rel_amplitude, period: V = v_mean (1 + rel_amplitude sin(2 pi t / period))
            for a sinusoid (m/s, -, s).
        shown: time range drawn in Figure 3 (s).
        settle: the sinusoid's gain and phase are measured on whole periods after this (s).
    """

    name: str
    title: str
    duration: float
    dt: float
    knots_t: tuple[float, ...] = ()
    knots_v: tuple[float, ...] = ()
    v_mean: float = 0.0
    rel_amplitude: float = 0.0
    period: float = 0.0
    shown: float = 0.0
    settle: float = 0.0

    @property
    def periodic(self) -> bool:
        return self.period > 0.0

    @property
    def omega(self) -> float:
        """Angular frequency (rad/s) of a sinusoid."""
        return 2.0 * math.pi / self.period

    def _sample_knots(self) -> tuple[np.ndarray, np.ndarray]:
        # The second knot of a jump moves JUMP later, so that V is a function of t.
        kt = np.array(self.knots_t, dtype=np.float64)
        for i in range(1, kt.size):
            if kt[i] <= kt[i - 1]:
                kt[i] = kt[i - 1] + JUMP
        return kt, np.array(self.knots_v, dtype=np.float64)

    def rate(self, t: np.ndarray) -> np.ndarray:
        """V(t) (m/s) as the sampled history sees it."""
        t = np.asarray(t, dtype=np.float64)
        if self.periodic:
            return self.v_mean * (1.0 + self.rel_amplitude * np.sin(self.omega * t))
        kt, kv = self._sample_knots()
        return np.interp(t, kt, kv)

    def grid(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Times ``(T,)`` (s) every ``dt`` from 0 to ``duration``, plus every knot; and V there."""
        n = max(1, round(self.duration / dt))
        t = np.arange(n + 1) * (self.duration / n)
        if not self.periodic:
            kt, _ = self._sample_knots()
            # Knots replace grid points closer than a millionth of a step to them.
            near = np.min(np.abs(t[:, None] - kt[None, :]), axis=1) < 1e-6 * dt
            t = np.union1d(t[~near], kt)
        return t, self.rate(t)

    def exact(self, t: np.ndarray, law: RateState) -> np.ndarray:
        """Exact mu(t): step closed form, ramp (Ei) closed form, or periodic harmonics."""
        if self.periodic:
            return exact.periodic(t, self.rate, self.period, law)
        kt, kv = self.knots_t, self.knots_v
        jumps = [i for i in range(1, len(kt)) if kt[i] == kt[i - 1]]
        if jumps:
            (i,) = jumps
            # The sampled history jumps between kt[i] and kt[i] + JUMP.
            return exact.step(t, kv[i - 1], kv[i], law, t_step=kt[i] + 0.5 * JUMP)
        (start, end) = (kt[1], kt[2])
        return exact.ramp(t, kv[1], kv[2], end - start, law, t_start=start)


def profiles(quick: bool = False) -> dict[str, Profile]:
    """The four profiles of Figure 3 (coarser steps when ``quick``)."""
    coarse = 4.0 if quick else 1.0
    return {
        "step": Profile(
            name="step",
            title="(a) step",
            duration=30.0,
            dt=0.01 * coarse,
            knots_t=(0.0, 5.0, 5.0, 30.0),
            knots_v=(1e-4, 1e-4, 1e-3, 1e-3),
            shown=30.0,
        ),
        "ramp": Profile(
            name="ramp",
            title="(b) ramp",
            duration=30.0,
            dt=0.01 * coarse,
            knots_t=(0.0, 5.0, 7.0, 30.0),
            knots_v=(1e-4, 1e-4, 1e-3, 1e-3),
            shown=30.0,
        ),
        "fast_sinusoid": Profile(
            name="fast_sinusoid",
            title="(c) fast sinusoid",
            duration=60.0,
            dt=0.005 * coarse,
            v_mean=1e-3,
            rel_amplitude=0.5,
            period=1.0,
            shown=10.0,
            settle=50.0,
        ),
        "slow_sinusoid": Profile(
            name="slow_sinusoid",
            title="(d) slow sinusoid",
            duration=600.0,
            dt=0.1 * coarse,
            v_mean=1e-3,
            rel_amplitude=0.5,
            period=300.0,
            shown=600.0,
            settle=300.0,
        ),
    }


def fundamental(t: np.ndarray, y: np.ndarray, omega: float, start: float) -> complex:
    """Complex amplitude of ``y`` at ``omega`` over the whole periods of ``t >= start``.

    ``y ~ Re(c e^{i omega t})``; exact for a uniformly sampled periodic signal whose
    harmonics lie below the Nyquist frequency.
    """
    period = 2.0 * math.pi / omega
    dt = t[1] - t[0]
    per_period = round(period / dt)
    first = int(np.searchsorted(t, start - 1e-9 * dt))
    n_periods = (t.size - 1 - first) // per_period
    if n_periods < 1:
        raise ValueError("no whole period after the settling time")
    window = slice(first, first + n_periods * per_period)
    return complex(2.0 * np.mean(y[window] * np.exp(-1j * omega * t[window])))


def gain_phase(
    profile: Profile, t: np.ndarray, v: np.ndarray, mu: np.ndarray, law: RateState
) -> dict[str, float]:
    """Measured and theoretical gain |H| and phase arg H (degrees) of mu against ln V."""
    x = law.slip_log(v)
    measured = fundamental(t, mu, profile.omega, profile.settle) / fundamental(
        t, x, profile.omega, profile.settle
    )
    theory = complex(exact.transfer_function(profile.omega, law))
    # Wrapped to (-180, 180] degrees: near 180 degrees a small error can cross the branch cut.
    phase_error = (_deg(measured) - _deg(theory) + 180.0) % 360.0 - 180.0
    return {
        "omega_t_c": profile.omega * law.t_c,
        "gain_measured": abs(measured),
        "gain_theory": abs(theory),
        "gain_rel_error": abs(abs(measured) - abs(theory)) / abs(theory),
        "phase_measured_deg": _deg(measured),
        "phase_theory_deg": _deg(theory),
        "phase_error_deg": phase_error,
        "mu_amplitude": abs(fundamental(t, mu, profile.omega, profile.settle)),
    }


def _deg(z: complex) -> float:
    return math.degrees(math.atan2(z.imag, z.real))


def run(
    out_dir: str | Path, *, quick: bool = False, law: RateState | None = None
) -> dict[str, Any]:
    """Integrate the four profiles with every method, compare with exact, write the results.

    Args:
        out_dir: folder for ``fig3_single_interface.png`` and ``single_interface.json``.
        quick: 4x coarser steps.
        law: the rate-and-state law; default the paper's.

    Returns:
        The JSON summary as a dict.
    """
    law = law or RateState()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    summary: dict[str, Any] = {
        "law": law.to_dict(),
        "figure_method": law.method,
        "reference": "Lishman et al. 2013, doi:10.1016/j.coldregions.2013.03.004, Figure 3",
        "profiles": {},
    }
    curves = {}
    for name, profile in profiles(quick).items():
        start = time.perf_counter()
        t, v = profile.grid(profile.dt)
        mu_exact = profile.exact(t, law)
        entry: dict[str, Any] = {
            "dt": profile.dt,
            "duration": profile.duration,
            "steps": int(t.size - 1),
            "reference": {
                "step": "step closed form",
                "ramp": "ramp closed form (exponential integral Ei)",
            }.get(name, "periodic steady state, harmonic by harmonic, plus transient"),
            "max_error": {},
        }
        for method in law.methods:
            mu = law.respond(t, v, method=method)
            entry["max_error"][method] = float(np.max(np.abs(mu - mu_exact)))
            if method == law.method:
                curves[name] = (t, v, mu, mu_exact)
        mu = curves[name][2]
        entry["mu_range"] = [float(mu.min()), float(mu.max())]
        if profile.periodic:
            entry["period"] = profile.period
            entry.update(gain_phase(profile, t, v, mu, law))
        summary["profiles"][name] = entry
        print(
            f"single interface: {name:14s} {t.size - 1:6d} steps, max |mu - exact| "
            f"({law.method}) = {entry['max_error'][law.method]:.2e} "
            f"[{time.perf_counter() - start:.1f} s]"
        )
    figure = out_dir / "fig3_single_interface.png"
    plot_figure3(curves, profiles(quick), law, figure)
    summary["figure"] = figure.name
    path = out_dir / "single_interface.json"
    path.write_text(json.dumps(summary, indent=2) + "\n")
    print(f"single interface: wrote {figure} and {path}")
    return summary


def plot_figure3(
    curves: dict[str, tuple[np.ndarray, ...]],
    profile_set: dict[str, Profile],
    law: RateState,
    path: Path,
) -> None:
    """Four panels as in the paper: slip rate dashed (right axis), friction solid (left)."""
    from ...run.plots import subplots

    fig, axes = subplots(2, 2, figsize=(10, 6.4), layout="constrained")
    for ax, (name, (t, v, mu, mu_exact)) in zip(axes.flat, curves.items()):
        profile = profile_set[name]
        shown = t <= profile.shown + 1e-9
        every = max(1, int(shown.sum()) // 40)
        ax.plot(t[shown], mu[shown], "-", color="C0", lw=1.6, label=f"mu ({law.method})")
        ax.plot(
            t[shown][::every],
            mu_exact[shown][::every],
            "o",
            ms=3.5,
            mfc="none",
            color="k",
            label="mu exact",
        )
        ax.set_title(profile.title)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("friction coefficient mu")
        ax.set_xlim(0.0, profile.shown)
        speed_axis(ax, t[shown], v[shown], "slip rate", legend=name == "step")
    fig.suptitle(
        "Friction on one interface (rate and state, Lishman et al. 2013): "
        "slip rate dashed, friction solid"
    )
    fig.savefig(path, dpi=90)


def speed_axis(ax, t, v, label: str, legend: bool = False) -> None:
    """The speed ``v`` (m/s, shown in mm/s) dashed on a right-hand axis of ``ax``; with
    ``legend``, one legend for both axes."""
    ax2 = ax.twinx()
    ax2.plot(t, v * 1e3, "--", color="C3", lw=1.2, label=label)
    ax2.set_ylabel(f"{label} V (mm/s)", color="C3")
    ax2.tick_params(axis="y", colors="C3")
    ax2.set_ylim(0.0, 1.2 * float(v.max()) * 1e3)
    if legend:
        lines = ax.get_lines() + ax2.get_lines()
        ax.legend(lines, [ln.get_label() for ln in lines], loc="center right", fontsize=8)
