"""Exact solutions of the rate-and-state law on one interface (NumPy only).

They are the references that the integrators in ``friction`` are measured against. The
state equation (Lishman et al. 2013, doi:10.1016/j.coldregions.2013.03.004)

    dtheta/dt = -(theta + B x(t)) / t_c,      x = ln(max(V, v_star) / v_star)

is linear in theta, so

    theta(t) = theta(0) e^{-t/t_c} - (B / t_c) int_0^t e^{-(t-s)/t_c} x(s) ds,

and the friction follows as ``mu = max(mu0 + theta + A x, 0)``. Three forcings integrate
in closed form:

- A step V1 -> V2 (theta continuous across it):
  ``mu(t) = mu_ss(V2) + B ln(V2 / V1) exp(-t / t_c)``.
- A ramp V = a + b t (V > v_star, b of either sign). Integrating by parts, with
  ``x' = b / V`` and the substitution ``z = V / (b t_c)`` (so that ``s / t_c = z - z0``):

      theta(t) = -B x(t) + (theta(0) + B x(0)) e^{-t/t_c} + B [g(z(t)) - e^{-t/t_c} g(z(0))],
      g(z) = e^{-z} Ei(z),

  with Ei the exponential integral (principal value); z keeps the sign of b along the
  ramp, and for b < 0, ``Ei(z) = -E1(-z)``. Any piecewise-linear history is a chain of
  such ramps and jumps (``piecewise_linear``).
- A periodic V (period P, w = 2 pi / P): in the periodic steady state each harmonic
  ``X_k e^{i k w t}`` of x gives ``mu_k = H(k w) X_k`` with the transfer function
  ``H(w) = A - B / (1 + i w t_c)``; an interface that starts in equilibrium at t = 0 adds
  the transient ``(theta(0) - theta_p(0)) e^{-t/t_c}`` (``periodic``).

The package never imports SciPy; ``g`` is evaluated here by a power series, an asymptotic
series and a continued fraction, and the tests hold it against ``scipy.special.expi``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = [
    "ei",
    "ei_scaled",
    "periodic",
    "piecewise_linear",
    "ramp",
    "step",
    "transfer_function",
]

EULER_GAMMA = 0.57721566490153286061
_EPS = 1e-17
# Above this z > 0 the asymptotic series of e^{-z} Ei(z) is accurate to its smallest term,
# about sqrt(2 pi / z) e^{-z} relative, i.e. below 1e-16 here.
_ASYMPTOTIC_FROM = 40.0
# Below this |z| (z < 0) the alternating power series of E1 loses no digits; above it the
# continued fraction converges in a few tens of terms.
_CONTINUED_FRACTION_FROM = 1.0


def _law_params(law: Any) -> tuple[float, float, float, float, float]:
    if law is None:
        from .friction import RateState

        law = RateState()
    params = law.params if hasattr(law, "params") else law
    A, B, mu0, v_star, t_c = (float(p) for p in params)
    return A, B, mu0, v_star, t_c


# --------------------------------------------------------------------------------------------
# The exponential integral, scaled: g(z) = e^{-z} Ei(z).
# --------------------------------------------------------------------------------------------


def _ei_series_scaled(z: np.ndarray) -> np.ndarray:
    # Ei(z) = gamma + ln z + sum_k z^k / (k k!), 0 < z <= 40: positive terms, no cancellation.
    term = z.copy()
    total = z.copy()
    for k in range(2, 400):
        term = term * z * (k - 1) / (k * k)
        total += term
        if np.all(term <= _EPS * total):
            break
    return np.exp(-z) * (EULER_GAMMA + np.log(z) + total)


def _ei_asymptotic_scaled(z: np.ndarray) -> np.ndarray:
    # e^{-z} Ei(z) ~ sum_k k! / z^{k+1}; for z > 40 the terms fall until k ~ z, far past the
    # point where they drop below 1e-17 of the sum.
    term = 1.0 / z
    total = term.copy()
    for k in range(1, int(_ASYMPTOTIC_FROM)):
        term = term * k / z
        total += term
        if np.all(term <= _EPS * total):
            break
    return total


def _e1_series(y: np.ndarray) -> np.ndarray:
    # E1(y) = -gamma - ln y - sum_k (-y)^k / (k k!), 0 < y <= 1.
    term = -y.copy()
    total = term.copy()
    for k in range(2, 60):
        term = -term * y * (k - 1) / (k * k)
        total += term
        if np.all(np.abs(term) <= _EPS * np.abs(total)):
            break
    return -EULER_GAMMA - np.log(y) - total


def _e1_continued_fraction_scaled(y: np.ndarray) -> np.ndarray:
    # e^{y} E1(y) = 1/(y + 1 - 1/(y + 3 - 4/(y + 5 - ...))), y >= 1, by the modified Lentz
    # method (Press et al., Numerical Recipes, section 6.3).
    tiny = 1e-300
    b = y + 1.0
    c = np.full_like(y, 1.0 / tiny)
    d = 1.0 / b
    h = d.copy()
    for i in range(1, 1000):
        an = -float(i * i)
        b = b + 2.0
        d = 1.0 / (an * d + b)
        c = b + an / c
        delta = c * d
        h *= delta
        if np.all(np.abs(delta - 1.0) <= 1e-16):
            break
    return h


def ei_scaled(z: Any) -> np.ndarray:
    """g(z) = e^{-z} Ei(z) for real z != 0 (any shape), to about 1e-15 relative.

    Ei is the exponential integral (principal value for z > 0); for z < 0,
    ``Ei(z) = -E1(-z)``. The scaling keeps g finite where Ei overflows (g ~ 1/z as
    |z| -> inf).

    Raises:
        ValueError: z == 0 (where Ei has its logarithmic singularity) or z NaN.
    """
    z = np.asarray(z, dtype=np.float64)
    if np.any(z == 0.0) or np.any(np.isnan(z)):
        raise ValueError("ei_scaled needs real z != 0 (Ei is singular at 0)")
    flat = z.reshape(-1)
    out = np.empty_like(flat)
    parts = (
        ((flat > 0) & (flat <= _ASYMPTOTIC_FROM), _ei_series_scaled),
        (flat > _ASYMPTOTIC_FROM, _ei_asymptotic_scaled),
        ((flat < 0) & (flat > -_CONTINUED_FRACTION_FROM), lambda s: -np.exp(-s) * _e1_series(-s)),
        (flat <= -_CONTINUED_FRACTION_FROM, lambda s: -_e1_continued_fraction_scaled(-s)),
    )
    for mask, fn in parts:
        if np.any(mask):
            out[mask] = fn(flat[mask])
    return out.reshape(z.shape)


def ei(z: Any) -> np.ndarray:
    """Exponential integral Ei(z) for real z != 0 (overflows to inf above z ~ 709)."""
    z = np.asarray(z, dtype=np.float64)
    with np.errstate(over="ignore"):
        return np.exp(z) * ei_scaled(z)


# --------------------------------------------------------------------------------------------
# Closed forms.
# --------------------------------------------------------------------------------------------


def _x(v: Any, v_star: float) -> np.ndarray:
    return np.log(np.maximum(v, v_star) / v_star)


def transfer_function(omega: Any, law: Any = None) -> np.ndarray:
    """H(w) = A - B / (1 + i w t_c): complex gain from x = ln(V/v_star) to mu at w (rad/s).

    |H| -> A with phase 0 (mu in phase with ln V) for w t_c >> 1, and H -> A - B < 0
    (180 degrees out of phase) for w t_c << 1.
    """
    A, B, _, _, t_c = _law_params(law)
    return A - B / (1.0 + 1j * np.asarray(omega, dtype=np.float64) * t_c)


def step(t: Any, v1: float, v2: float, law: Any = None, t_step: float = 0.0) -> np.ndarray:
    """Friction of an interface in equilibrium at ``v1`` whose slip rate jumps to ``v2``.

        mu(t) = mu_ss(V1)                                       for t < t_step
        mu(t) = mu_ss(V2) + B ln(V2 / V1) exp(-(t - t_step) / t_c)    for t >= t_step

    with ``ln(V / v_star)`` read as ``x = ln(max(V, v_star) / v_star)`` and mu clamped at 0,
    as in ``RateState``.

    Args:
        t: times (s), any shape. v1, v2: slip rates before and after (m/s).
        law: a ``RateState`` or a tuple (A, B, mu0, v_star, t_c); default the paper's.
        t_step: time of the jump (s).
    """
    A, B, mu0, v_star, t_c = _law_params(law)
    t = np.asarray(t, dtype=np.float64)
    x1, x2 = float(_x(v1, v_star)), float(_x(v2, v_star))
    tau = np.maximum(t - t_step, 0.0)
    after = mu0 + (A - B) * x2 + B * (x2 - x1) * np.exp(-tau / t_c)
    return np.maximum(np.where(t < t_step, mu0 + (A - B) * x1, after), 0.0)


def _split_at_v_star(tk: np.ndarray, vk: np.ndarray, v_star: float):
    # Insert a knot wherever V crosses v_star inside a segment, so that every segment lies
    # entirely at or above v_star (x = ln V / v_star, smooth) or at or below it (x = 0).
    t_out, v_out = [tk[0]], [vk[0]]
    for k in range(len(tk) - 1):
        va, vb = vk[k], vk[k + 1]
        if (va - v_star) * (vb - v_star) < 0.0 and tk[k + 1] > tk[k]:
            t_out.append(tk[k] + (tk[k + 1] - tk[k]) * (v_star - va) / (vb - va))
            v_out.append(v_star)
        t_out.append(tk[k + 1])
        v_out.append(vb)
    return np.asarray(t_out), np.asarray(v_out)


def _segment_theta(theta0, va, vb, length, tau, B, v_star, t_c):
    # theta at time tau into segments from va to vb over `length` seconds (arrays, broadcast);
    # each segment lies wholly on one side of v_star (see _split_at_v_star).
    theta0, va, vb, length, tau = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (theta0, va, vb, length, tau))
    )
    decay = np.exp(-tau / t_c)
    out = np.empty(theta0.shape)
    below = np.maximum(va, vb) <= v_star
    flat = ~below & ((va == vb) | (length == 0.0))
    ramp_ = ~below & ~flat
    # Below v_star x = 0: theta relaxes toward 0.
    out[below] = theta0[below] * decay[below]
    # Constant V: exponential relaxation toward -B x.
    xs = _x(va[flat], v_star)
    out[flat] = -B * xs + (theta0[flat] + B * xs) * decay[flat]
    if np.any(ramp_):
        a, b_len, L, s, th0, dec = (
            va[ramp_],
            vb[ramp_],
            length[ramp_],
            tau[ramp_],
            theta0[ramp_],
            decay[ramp_],
        )
        slope = (b_len - a) / L
        v_now = a + slope * s
        x0, x_now = _x(a, v_star), _x(v_now, v_star)
        z0 = a / (slope * t_c)
        z = v_now / (slope * t_c)
        out[ramp_] = -B * x_now + (th0 + B * x0) * dec + B * (ei_scaled(z) - dec * ei_scaled(z0))
    return out


def piecewise_linear(
    t_knots: Any, v_knots: Any, t: Any, law: Any = None, *, return_theta: bool = False
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Exact friction for a slip rate linear between knots, starting in equilibrium.

    Before the first knot the interface rests in equilibrium at ``v_knots[0]``; after the
    last one the slip rate stays at ``v_knots[-1]``. Two knots at the same time make a jump
    (theta is continuous across it; mu jumps by ``A`` times the jump in x). Each segment is
    the ramp closed form (module docstring); segments that cross ``v_star`` are split there.

    Args:
        t_knots: ``(K,)`` non-decreasing knot times (s).
        v_knots: ``(K,)`` slip rates at the knots (m/s), >= 0.
        t: times to evaluate (s), any shape; at a jump, the value just after it.
        law: a ``RateState`` or a tuple (A, B, mu0, v_star, t_c); default the paper's.
        return_theta: also return theta.

    Returns:
        mu at ``t`` (same shape), or ``(mu, theta)``.
    """
    A, B, mu0, v_star, t_c = _law_params(law)
    tk = np.asarray(t_knots, dtype=np.float64)
    vk = np.asarray(v_knots, dtype=np.float64)
    if tk.ndim != 1 or tk.shape != vk.shape or tk.size == 0:
        raise ValueError("t_knots and v_knots must be 1-D arrays of the same non-zero length")
    if np.any(np.diff(tk) < 0.0) or np.any(vk < 0.0) or not np.all(np.isfinite(vk)):
        raise ValueError("knot times must be non-decreasing and knot rates finite and >= 0")
    tk, vk = _split_at_v_star(tk, vk, v_star)
    lengths = np.diff(tk)
    theta_k = np.empty(tk.size)
    theta_k[0] = -B * _x(vk[0], v_star)
    for k in range(tk.size - 1):
        theta_k[k + 1] = _segment_theta(
            theta_k[k], vk[k], vk[k + 1], lengths[k], lengths[k], B, v_star, t_c
        )[()]
    t = np.asarray(t, dtype=np.float64)
    flat_t = t.reshape(-1)
    # Segment k runs from knot k to knot k+1; a final open segment holds v_knots[-1].
    seg = np.clip(np.searchsorted(tk, flat_t, side="right") - 1, 0, tk.size - 1)
    va = vk[seg]
    vb = np.where(seg < tk.size - 1, vk[np.minimum(seg + 1, tk.size - 1)], va)
    length = np.where(seg < tk.size - 1, np.append(lengths, 0.0)[seg], 0.0)
    tau = np.maximum(flat_t - tk[seg], 0.0)
    theta = _segment_theta(theta_k[seg], va, vb, length, tau, B, v_star, t_c)
    v_now = np.where(
        length > 0.0,
        va + (vb - va) * np.divide(tau, length, where=length > 0, out=np.zeros_like(tau)),
        va,
    )
    v_now = np.where(flat_t < tk[0], vk[0], v_now)
    mu = np.maximum(mu0 + theta + A * _x(v_now, v_star), 0.0)
    mu, theta = mu.reshape(t.shape), theta.reshape(t.shape)
    return (mu, theta) if return_theta else mu


def ramp(
    t: Any,
    v_start: float,
    v_end: float,
    duration: float,
    law: Any = None,
    t_start: float = 0.0,
) -> np.ndarray:
    """Exact friction for a ramp from ``v_start`` to ``v_end`` that then holds ``v_end``.

    The interface rests in equilibrium at ``v_start`` until ``t_start``; the slip rate then
    changes linearly over ``duration`` seconds (the Ei closed form) and stays at ``v_end``
    (exponential relaxation to ``mu_ss(v_end)``).
    """
    if not duration > 0.0:
        raise ValueError(f"duration must be > 0, got {duration}")
    knots_t = [t_start, t_start + duration]
    return piecewise_linear(knots_t, [v_start, v_end], t, law)


def periodic(
    t: Any,
    v_of_t: Callable[[np.ndarray], np.ndarray],
    period: float,
    law: Any = None,
    *,
    n_samples: int = 4096,
    return_theta: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Exact friction for a periodic slip rate, from an equilibrium start at t = 0.

    x = ln(max(V, v_star)/v_star) is sampled at ``n_samples`` points over one period and
    Fourier transformed; harmonic k of theta is ``-B / (1 + i k w t_c)`` times harmonic k of
    x (so that harmonic k of mu is ``H(k w)`` times it), and the transient
    ``(theta(0) - theta_p(0)) e^{-t/t_c}`` takes the periodic solution ``theta_p`` from the
    equilibrium start ``theta(0) = -B x(0)``. Exact up to the truncation of the Fourier
    series, which converges geometrically for a smooth x (V above v_star throughout).

    Args:
        t: times >= 0 (s), any shape.
        v_of_t: the slip rate (m/s) as a vectorised function of time, periodic in ``period``.
        period: P (s).
        law: a ``RateState`` or a tuple (A, B, mu0, v_star, t_c); default the paper's.
        n_samples: samples per period for the Fourier transform.
        return_theta: also return theta.
    """
    A, B, mu0, v_star, t_c = _law_params(law)
    omega = 2.0 * math.pi / period
    samples = np.arange(n_samples) * (period / n_samples)
    x_hat = np.fft.rfft(_x(v_of_t(samples), v_star)) / n_samples
    # Keep the harmonics above the transform's round-off (~1e-16 of the largest, times a
    # margin); the Nyquist one is dropped (it has no phase).
    mags = np.abs(x_hat[1 : n_samples // 2])
    keep = np.nonzero(mags > 1e-14 * max(float(mags.max(initial=0.0)), 1e-300))[0]
    n_harm = int(keep[-1]) + 1 if keep.size else 0
    k = np.arange(1, n_harm + 1)
    gain = -B / (1.0 + 1j * k * omega * t_c) * x_hat[1 : n_harm + 1]
    theta_mean = -B * x_hat[0].real

    def theta_periodic(times: np.ndarray) -> np.ndarray:
        out = np.full(times.shape, theta_mean)
        for lo in range(0, times.size, 4096):
            chunk = times[lo : lo + 4096]
            phase = np.exp(1j * omega * np.outer(chunk, k))
            out[lo : lo + 4096] += 2.0 * (phase @ gain).real
        return out

    t = np.asarray(t, dtype=np.float64)
    flat_t = t.reshape(-1)
    theta0 = -B * float(_x(v_of_t(np.zeros(1)), v_star)[0])
    transient = (theta0 - theta_periodic(np.zeros(1))[0]) * np.exp(-flat_t / t_c)
    theta = theta_periodic(flat_t) + transient
    mu = np.maximum(mu0 + theta + A * _x(v_of_t(flat_t), v_star), 0.0)
    mu, theta = mu.reshape(t.shape), theta.reshape(t.shape)
    return (mu, theta) if return_theta else mu
