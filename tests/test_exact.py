"""The exact solutions in ``taichi_ice.physics.exact`` against independent references.

SciPy (a test-only dependency) supplies them: ``scipy.special.expi`` for Ei and
``scipy.integrate.solve_ivp`` at tight tolerances for the state equation itself.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.special import expi

from taichi_ice.physics import exact
from taichi_ice.physics.friction import RateState

# Ei by series / asymptotic series / continued fraction: a few ulps, up to the ~1e-14
# relative accuracy of expi(z) e^{-z} itself for z in the hundreds.
EI_REL_TOL = 1e-13
# solve_ivp (DOP853, rtol 1e-12) is the looser of the two sides.
ODE_TOL = 1e-10
ODE_OPTIONS = {"method": "DOP853", "rtol": 1e-12, "atol": 1e-14}

LAW = RateState()
A, B, MU0, V_STAR, T_C = LAW.params


def x_of(v):
    return np.log(np.maximum(v, V_STAR) / V_STAR)


def ode_mu(v_of_t, knots, t_eval, theta0=None):
    """mu(t) by integrating dtheta/dt = -(theta + B x)/t_c piece by piece between knots."""
    t_eval = np.asarray(t_eval, dtype=float)
    bounds = sorted({0.0, *knots, float(t_eval.max())})
    theta = -B * x_of(v_of_t(0.0)) if theta0 is None else theta0
    out = np.empty_like(t_eval)
    # A knot is where V has a kink; integrate each smooth piece on its own.
    for lo, hi in itertools.pairwise(bounds):
        inside = (t_eval >= lo) & (t_eval <= hi)
        sol = solve_ivp(
            lambda t, th: -(th + B * x_of(v_of_t(t))) / T_C,
            (lo, hi),
            [theta],
            t_eval=t_eval[inside],
            **ODE_OPTIONS,
        )
        out[inside] = sol.y[0]
        theta = solve_ivp(
            lambda t, th: -(th + B * x_of(v_of_t(t))) / T_C, (lo, hi), [theta], **ODE_OPTIONS
        ).y[0, -1]
    return np.maximum(MU0 + out + A * x_of(v_of_t(t_eval)), 0.0)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_ei_matches_scipy_expi(sign):
    """Ei(z) e^{-z} matches scipy's expi on both sides of 0, over 14 decades of |z|."""
    z = sign * np.logspace(-10, math.log10(600.0), 3000)
    ref = np.exp(-z) * expi(z)
    got = exact.ei_scaled(z)
    # Near Ei's zero at z = 0.3725 relative error is meaningless: compare to |g| + 1e-3.
    scale = np.maximum(np.abs(ref), 1e-3)
    assert np.max(np.abs(got - ref) / scale) < EI_REL_TOL
    assert np.allclose(exact.ei(z[np.abs(z) < 50]), expi(z[np.abs(z) < 50]), rtol=EI_REL_TOL)


def test_ei_scaled_tends_to_one_over_z():
    """e^{-z} Ei(z) = 1/z + 1/z^2 + 2/z^3 + ... where Ei itself overflows (|z| up to 1e8)."""
    z = np.array([1e3, 1e5, 1e8, -1e3, -1e5, -1e8])
    series = sum(math.factorial(k) / z ** (k + 1) for k in range(10))
    assert np.allclose(exact.ei_scaled(z), series, rtol=1e-14, atol=0)


def test_ei_rejects_zero_and_nan():
    """Ei has a logarithmic singularity at 0: asking for it is an error."""
    for bad in (0.0, np.nan):
        with pytest.raises(ValueError, match="z != 0"):
            exact.ei_scaled([1.0, bad])


@pytest.mark.parametrize("v1, v2", [(1e-4, 1e-3), (1e-3, 1e-4), (2e-3, 5e-6)])
def test_step_closed_form_matches_ode(v1, v2):
    """A step V1 -> V2: mu jumps by A ln(V2/V1) and relaxes to mu_ss(V2) with t_c."""
    t = np.linspace(0.0, 25.0, 251)
    got = exact.step(t, v1, v2, LAW, t_step=5.0)
    ref = ode_mu(lambda s: np.where(np.asarray(s) < 5.0, v1, v2), [5.0], t)
    assert np.max(np.abs(got - ref)) < ODE_TOL
    # Just after the step: the direct effect A ln(V2/V1) on top of mu_ss(V1).
    jump = exact.step(5.0, v1, v2, LAW, t_step=5.0) - exact.step(4.999, v1, v2, LAW, t_step=5.0)
    assert jump == pytest.approx(A * (x_of(v2) - x_of(v1)), abs=1e-15)


def test_step_after_fast_deceleration_is_clamped_at_zero():
    """Stopping from 0.1 m/s (above v* e^{mu0/B} = 2.4 cm/s): mu(0+) would be < 0; it is 0."""
    t = np.linspace(0.0, 30.0, 301)
    got = exact.step(t, 0.1, 1e-4, LAW)
    unclamped_start = MU0 + (A - B) * x_of(1e-4) + B * (x_of(1e-4) - x_of(0.1))
    assert unclamped_start < 0.0
    assert got[0] == 0.0 and np.all(got >= 0.0) and got[-1] > 0.5
    ref = ode_mu(lambda s: 1e-4 + 0.0 * np.asarray(s), [], t, theta0=-B * x_of(0.1))
    assert np.max(np.abs(got - ref)) < ODE_TOL


@pytest.mark.parametrize(
    "v_start, v_end",
    [(1e-4, 1e-2), (1e-2, 1e-4), (1e-3, 1e-6), (5e-6, 3e-3), (1e-3, 1.0001e-3)],
    ids=["up", "down", "down-through-v_star", "up-from-below-v_star", "nearly-flat"],
)
def test_ramp_closed_form_matches_ode(v_start, v_end):
    """A ramp of either sign, then a hold: the Ei closed form and its continuation."""
    t = np.linspace(0.0, 25.0, 501)
    got = exact.ramp(t, v_start, v_end, 4.0, LAW, t_start=3.0)
    ref = ode_mu(lambda s: np.interp(s, [3.0, 7.0], [v_start, v_end]), [3.0, 7.0], t)
    assert np.max(np.abs(got - ref)) < ODE_TOL


def test_ramp_formula_as_in_the_design():
    """theta(t) = -B x(t) + B [g(z(t)) - e^{-t/t_c} g(z(0))], z = V/(b t_c), V = a + b t."""
    a, b = 2e-4, 3e-4
    t = np.linspace(0.0, 6.0, 61)
    z = (a + b * t) / (b * T_C)
    theta = -B * x_of(a + b * t) + B * (
        np.exp(-z) * expi(z) - np.exp(-t / T_C) * np.exp(-z[0]) * expi(z[0])
    )
    got = exact.ramp(t, a, a + b * 6.0, 6.0, LAW)
    assert np.max(np.abs(got - (MU0 + theta + A * x_of(a + b * t)))) < 1e-13


def test_piecewise_linear_matches_ode_on_a_random_history():
    """Any piecewise-linear history: a chain of ramp closed forms, jumps included."""
    rng = np.random.default_rng(7)
    knots_t = np.sort(rng.uniform(0.0, 20.0, 8))
    knots_t[3] = knots_t[2]  # a jump
    knots_v = 10 ** rng.uniform(-6.0, -2.5, 8)
    t = np.linspace(0.0, 25.0, 400)

    def v_of_t(s):
        s = np.asarray(s, dtype=float)
        # Right-continuous at the jump, as piecewise_linear is.
        return np.where(
            s < knots_t[2],
            np.interp(s, knots_t[:3], knots_v[:3]),
            np.interp(s, knots_t[3:], knots_v[3:]),
        )

    got = exact.piecewise_linear(knots_t, knots_v, t, LAW)
    ref = ode_mu(v_of_t, list(knots_t), t)
    assert np.max(np.abs(got - ref)) < ODE_TOL


def test_piecewise_linear_jump_is_the_step():
    """Two knots at one time are a jump: the same mu as the step closed form."""
    t = np.linspace(0.0, 30.0, 301)
    got = exact.piecewise_linear([5.0, 5.0], [1e-4, 3e-3], t, LAW)
    assert np.max(np.abs(got - exact.step(t, 1e-4, 3e-3, LAW, t_step=5.0))) < 1e-15


@pytest.mark.parametrize("period", [1.0, 40.0])
def test_periodic_matches_ode_including_the_transient(period):
    """Periodic V from equilibrium: harmonics times H(k w), plus the e^{-t/t_c} transient."""

    def v_of_t(s):
        return 1e-3 * (1.0 + 0.6 * np.sin(2 * np.pi * np.asarray(s) / period + 0.3))

    t = np.linspace(0.0, 3.0 * period + 5.0, 600)
    got = exact.periodic(t, v_of_t, period, LAW)
    assert np.max(np.abs(got - ode_mu(v_of_t, [], t))) < ODE_TOL


def test_transfer_function_limits_and_measured_gain():
    """H = A - B/(1 + i w t_c): A in phase when fast, A - B (180 degrees) when slow; the
    periodic solution's fundamental is exactly H times that of ln V."""
    assert exact.transfer_function(1e9, LAW) == pytest.approx(A, abs=1e-9)
    assert exact.transfer_function(0.0, LAW) == pytest.approx(A - B, abs=1e-15)
    assert np.degrees(np.angle(exact.transfer_function(1e3 / T_C, LAW))) < 1.0
    assert np.degrees(np.angle(exact.transfer_function(1e-3 / T_C, LAW))) > 179.0
    period = 7.0
    w = 2 * np.pi / period

    def v_of_t(s):
        return 2e-3 * np.exp(0.4 * np.sin(w * np.asarray(s)))

    t = 20.0 * period + np.arange(1000) * period / 1000  # one period, transient gone
    mu = exact.periodic(t, v_of_t, period, LAW)
    gain = np.mean(mu * np.exp(-1j * w * t)) / np.mean(x_of(v_of_t(t)) * np.exp(-1j * w * t))
    assert abs(gain - exact.transfer_function(w, LAW)) < 1e-12
