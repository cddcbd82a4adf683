"""Run metrics: what one run's ``/series`` says about the rubble against the probe bodies.

    from taichi_ice.run.runfile_read import read_run
    from taichi_ice.experiments.metrics import METRICS, METRIC_INFO, run_metrics
    m = run_metrics(read_run("runs/pillar.h5")["series"], window=1.0)

Pure NumPy definitions (no Taichi, no runs): ``ensemble`` computes them for every world of a
batch, a sweep keeps the ones its file names (``sweep.spec``), its dataset takes their units
and long names (``dataset``), the study and the paper read them. Running worlds is not here
(``ensemble.run_worlds``).

The metrics of one run (``run_metrics``), all from its ``/series``:

- ``peak_force``, ``mean_force`` (N): largest and time-mean magnitude of the total contact
  force on the probe bodies (the pillar), over the whole run.
- ``friction_energy`` (J): frictional dissipation at the end (the paper's Figure 6).
- ``concentration``: the largest share of ``friction_energy`` dissipated in any one window
  of ``window`` seconds (default 1 s). Steady dissipation over 20 s gives about 1/20 = 0.05;
  a run whose dissipation is one event gives close to 1. This is the measure behind the
  paper's remark that with mu = 0.5 "the energy loss seems to be concentrated in two
  individual events" while rate-and-state is "steadier".
- ``final_force`` (N): mean probe force over the last ``window`` seconds, and ``released``
  (1 or 0): whether it has fallen below a tenth of ``peak_force``, i.e. whether the largest
  jam against the probe had broken by the end.
- ``release_time`` (s) and ``release_observed`` (1 or 0): from the peak force to the first
  sample at which the mean force over the ``window`` before it is below a tenth of the peak
  (the largest jam broken; ``released``'s rule applied at every sample); where that never
  happens, the time from the peak to the end of the run, censored (``release_observed`` 0:
  Kaplan-Meier takes it so, ``inference.kaplan_meier``). NaN and 0 without a force.
- ``jammed_fraction`` and ``jammed_fraction_5kN``, ``_20kN``: the share of the run's time
  during which the probe force exceeds 10 kN (the study's jam, ten times the paper's "never
  higher than 1 kN"), 5 kN and 20 kN (the threshold's sensitivity).
- ``crushing_energy`` (J): work done crushing ice beyond its strength (0 without one).
- ``first_contact`` (s): first sample with a force on a probe (NaN if never).
- ``residual`` (J) and ``residual_rel``: the energy budget's residual at the end, absolute
  and relative to the energy that came in (initial kinetic + elastic, plus work in).
"""

from __future__ import annotations

import math

import numpy as np

from ..run import budget

METRICS = (
    "peak_force",
    "mean_force",
    "friction_energy",
    "crushing_energy",
    "concentration",
    "final_force",
    "released",
    "release_time",
    "release_observed",
    "jammed_fraction",
    "jammed_fraction_5kN",
    "jammed_fraction_20kN",
    "first_contact",
    "residual",
    "residual_rel",
)

# Unit and long name of every metric (the dataset's attributes, the study's tables).
METRIC_INFO = {
    "peak_force": ("N", "largest magnitude of the total contact force on the probe bodies"),
    "mean_force": ("N", "time-mean magnitude of the total contact force on the probe bodies"),
    "friction_energy": ("J", "energy dissipated by friction at the end of the run"),
    "crushing_energy": ("J", "work done crushing ice beyond its strength at the end"),
    "concentration": ("1", "largest share of the frictional energy dissipated in one window"),
    "final_force": ("N", "mean probe force over the last window"),
    "released": ("1", "1 if the final probe force is below a tenth of its peak (jam broken)"),
    "release_time": ("s", "from the peak force to the largest jam's release, or to the end"),
    "release_observed": ("1", "1 if the largest jam was released before the end (else censored)"),
    "jammed_fraction": ("1", "share of the run's time with a probe force above 10 kN"),
    "jammed_fraction_5kN": ("1", "share of the run's time with a probe force above 5 kN"),
    "jammed_fraction_20kN": ("1", "share of the run's time with a probe force above 20 kN"),
    "first_contact": ("s", "first time with a force on a probe body"),
    "residual": ("J", "energy budget residual at the end: energy in minus energy accounted"),
    "residual_rel": ("1", "energy budget residual over the energy that came in"),
}

# A jam counts as released when the probe force over the last window is below this fraction
# of its peak.
RELEASED_FRACTION = 0.1
# A jam: a probe force above this (N); the other two are the threshold's sensitivity.
JAM_FORCE = 10e3
JAM_FORCES = {
    "jammed_fraction_5kN": 5e3,
    "jammed_fraction": JAM_FORCE,
    "jammed_fraction_20kN": 20e3,
}


def probe_force_magnitude(series: dict) -> np.ndarray:
    """``(T,)`` magnitude of the total force on the probe bodies (N); zeros if none."""
    f = np.asarray(series["probe_force"])
    if f.ndim != 3 or f.shape[1] == 0:
        return np.zeros(len(series["time"]))
    return np.linalg.norm(f.sum(axis=1), axis=-1)


def concentration(time: np.ndarray, energy: np.ndarray, window: float = 1.0) -> float:
    """Largest share of the final ``energy`` gained in any window of ``window`` seconds.

    ``energy`` is cumulative (non-decreasing up to round-off), sampled at ``time``; windows
    start anywhere on the sample grid and the energy at their ends is interpolated linearly.
    Returns NaN when nothing was dissipated; 1.0 when the run is shorter than the window.
    """
    time, energy = np.asarray(time, dtype=float), np.asarray(energy, dtype=float)
    total = energy[-1] - energy[0]
    if not total > 0:
        return math.nan
    if time[-1] - time[0] <= window:
        return 1.0
    starts = time[time <= time[-1] - window]
    gained = np.interp(starts + window, time, energy) - np.interp(starts, time, energy)
    return float(np.max(gained) / total)


def trailing_mean(time: np.ndarray, values: np.ndarray, window: float) -> np.ndarray:
    """``(T,)`` mean of ``values`` over the samples within ``window`` before each one (it
    included; the sample at t = 0, which carries no impulse, left out)."""
    time, values = np.asarray(time, dtype=float), np.asarray(values, dtype=float)
    total = np.concatenate([[0.0], np.cumsum(values)])
    first = np.maximum(np.searchsorted(time, time - window, side="left"), 1)
    last = np.arange(time.size) + 1
    count = np.maximum(last - first, 1)
    return np.where(last > first, (total[last] - total[first]) / count, values)


def release(time: np.ndarray, force: np.ndarray, window: float = 1.0) -> tuple[float, bool]:
    """``(seconds, observed)``: from the peak of ``force`` to the first sample whose
    trailing mean over ``window`` is below ``RELEASED_FRACTION`` of the peak, or, censored
    (``observed`` False), to the end; ``(nan, False)`` without a force."""
    time, force = np.asarray(time, dtype=float), np.asarray(force, dtype=float)
    if not force.size or not force.max() > 0.0:
        return math.nan, False
    at = int(np.argmax(force))
    below = np.nonzero(trailing_mean(time, force, window)[at:] < RELEASED_FRACTION * force[at])
    if below[0].size:
        return float(time[at + below[0][0]] - time[at]), True
    return float(time[-1] - time[at]), False


def run_metrics(series: dict, window: float = 1.0) -> dict[str, float]:
    """The metrics of one run (see the module docstring) from its ``/series`` arrays."""
    t = np.asarray(series["time"])
    force = probe_force_magnitude(series)
    touching = np.nonzero(force > 0)[0]
    residual = float(budget.residual(series)[-1])
    came_in = float(budget.came_in(series)[-1])
    peak = float(force.max()) if force.size else 0.0
    last = t >= t[-1] - window
    last[0] = False  # t = 0 carries no impulse
    final = float(force[last].mean()) if last.any() else 0.0
    release_time, observed = release(t, force, window)
    return {
        "peak_force": peak,
        # Samples are equally spaced, so the time mean is the sample mean (t = 0 excluded:
        # it carries no impulse).
        "mean_force": float(force[1:].mean()) if force.size > 1 else 0.0,
        "friction_energy": float(series["friction_energy"][-1]),
        # 0 without an ice strength, and in files written before the term existed.
        "crushing_energy": float(np.asarray(series.get("crushing_energy", [0.0]))[-1]),
        "concentration": concentration(t, series["friction_energy"], window),
        "final_force": final,
        "released": float(peak > 0 and final < RELEASED_FRACTION * peak),
        "release_time": release_time,
        "release_observed": float(observed),
        # Samples are equally spaced: a share of the samples after t = 0 is a share of time.
        **{
            name: float(np.mean(force[1:] > threshold)) if force.size > 1 else 0.0
            for name, threshold in JAM_FORCES.items()
        },
        "first_contact": float(t[touching[0]]) if touching.size else math.nan,
        "residual": residual,
        "residual_rel": residual / came_in if came_in > 0 else math.nan,
    }
