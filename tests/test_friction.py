"""Friction laws on one interface: closed forms, convergence, stability, NumPy against Taichi."""

# No ``from __future__ import annotations``: Taichi reads kernel annotations as objects.
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import taichi as ti

from taichi_ice import StabilityError, backend
from taichi_ice.codes import ThetaMethod
from taichi_ice.physics import batched, exact, friction, friction_parse, friction_ti
from taichi_ice.physics.batched import respond_batch, respond_batch_ti
from taichi_ice.physics.friction import (
    EULER_STABILITY_LIMIT,
    RK4_STABILITY_LIMIT,
    Coulomb,
    RateState,
)

# NumPy and Taichi run the same operations in the same order; only the last bits of their
# log/exp differ, and the state equation damps them.
AGREE_F64 = 1e-12
# float32 against float64 over a few hundred steps: ~eps_f32 = 1.2e-7 per rounding, growing
# like eps / h with small steps.
AGREE_F32 = 1e-4
# The exponential method is exact for constant V; what is left is round-off and the 1 ps
# over which a sampled jump ramps (theta moves by ~B dx 1e-12 s / t_c ~ 1e-13 in it).
EXACT_CONSTANT_V = 2e-13
# The kink of x = ln(max(V, V*)/V*) where V crosses V* falls between samples: one local
# first-order error of ~(dt/t_c) B dx there, dt = t_c / 300.
CROSSING_TOL = 2e-5
# Measured convergence orders may differ from the theoretical ones by this much.
ORDER_TOL = 0.15

LAW = RateState()
A, B, MU0, V_STAR, T_C = LAW.params
ALL_METHODS = RateState.methods


def measured_order(errors, dts):
    """Least-squares slope of log(error) against log(dt)."""
    return np.polyfit(np.log(dts), np.log(errors), 1)[0]


def step_history(v1, v2, dt, duration, t_step=2.0):
    """Samples every dt; V jumps from v1 to v2 over 1 ps at t_step (a sample)."""
    before = np.append(np.arange(0.0, t_step - 0.5 * dt, dt), t_step)
    after = t_step + 1e-12 + np.arange(0.0, duration - t_step, dt)
    t = np.concatenate([before, after])
    return t, np.where(t > t_step, v2, v1)


# ---------------------------------------------------------------------------------------------
# Parameters and steady state
# ---------------------------------------------------------------------------------------------


def test_defaults_are_the_papers():
    """Defaults are Lishman et al. (2013) at -10 C: A, B, mu0, V*, t_c; exponential method."""
    assert LAW.params == (0.05, 0.112, 0.872, 1e-5, 3.0)
    assert LAW.method == "exponential"
    assert RateState.methods == ("exponential", "euler", "implicit", "rk4")
    assert LAW.to_dict() == {
        "law": "rate-state",
        "A": 0.05,
        "B": 0.112,
        "mu0": 0.872,
        "v_star": 1e-5,
        "t_c": 3.0,
        "method": "exponential",
        "below_v_star": "paper",
    }
    assert Coulomb().mu == 0.5 and Coulomb(0.3).to_dict() == {"law": "coulomb", "mu": 0.3}
    assert RateState(t_c=2.0, method="rk4").params[4] == 2.0
    assert RateState(method="rk4").method == "rk4"
    assert [friction.method_code(m) for m in RateState.methods] == [0, 1, 2, 3]
    assert ThetaMethod.RK4 == friction.method_code("rk4") == 3


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"t_c": 0.0}, "t_c"),
        ({"t_c": -3.0}, "t_c"),
        ({"v_star": 0.0}, "v_star"),
        ({"v_star": -1e-5}, "v_star"),
        ({"A": math.nan}, "A"),
        ({"B": math.inf}, "B"),
        ({"mu0": -0.1}, "mu0"),
        ({"mu0": "high"}, "mu0"),
        ({"method": "leapfrog"}, "method"),
    ],
)
def test_invalid_parameters_are_refused(kwargs, name):
    """NaN, infinite, negative or zero parameters (and unknown methods) are errors naming them."""
    with pytest.raises(ValueError, match=name):
        RateState(**kwargs)


@pytest.mark.parametrize("mu", [-0.5, math.nan, math.inf])
def test_invalid_coulomb_is_refused(mu):
    """A Coulomb coefficient must be a finite number >= 0."""
    with pytest.raises(ValueError, match="mu"):
        Coulomb(mu)


def test_steady_state_is_velocity_weakening_and_clamped():
    """mu_ss = mu0 + (A - B) ln(V/V*) above V*, mu0 below, 0 from V* e^{mu0/(B-A)} ~ 13 m/s."""
    v = np.array([0.0, 1e-7, V_STAR, 1e-4, 1e-2, 1.0])
    expected = MU0 + (A - B) * np.log(np.maximum(v, V_STAR) / V_STAR)
    assert np.allclose(LAW.steady_state(v), expected, rtol=0, atol=1e-15)
    v_zero = V_STAR * math.exp(MU0 / (B - A))
    assert 12.0 < v_zero < 14.0
    assert LAW.steady_state(0.99 * v_zero) > 0.0
    assert LAW.steady_state(1.01 * v_zero) == 0.0
    assert np.all(Coulomb(0.4).steady_state(v) == 0.4)


@pytest.mark.parametrize("method", ALL_METHODS)
def test_constant_rate_stays_in_equilibrium(method):
    """An interface that starts in equilibrium at constant V stays at mu_ss(V), any method."""
    t = np.cumsum(np.full(50, 0.7))
    for v0 in (3e-6, 1e-3, 0.2):
        mu = LAW.respond(t, np.full(t.shape, v0), method=method)
        assert np.allclose(mu, LAW.steady_state(v0), rtol=0, atol=1e-15)


# ---------------------------------------------------------------------------------------------
# Closed forms
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("v1, v2", [(1e-4, 1e-3), (1e-3, 2e-5)])
def test_exponential_is_exact_after_a_step(v1, v2):
    """For constant V the exponential update is the exact solution: a step to round-off."""
    t, v = step_history(v1, v2, dt=0.37, duration=30.0)
    mu = LAW.respond(t, v)
    ref = exact.step(t, v1, v2, LAW, t_step=2.0 + 0.5e-12)
    assert np.max(np.abs(mu - ref)) < EXACT_CONSTANT_V
    # Jump up by A ln(V2/V1), then decay to mu_ss(V2).
    after = np.argmax(t > 2.0)
    assert mu[after] - mu[after - 1] == pytest.approx(A * math.log(v2 / v1), abs=1e-12)


@pytest.mark.parametrize("method", ALL_METHODS)
def test_ramp_and_hold_converge_to_the_ei_closed_form(method):
    """Every method approaches the ramp's Ei closed form as dt -> 0 (1 mm/s mean error scale)."""
    knots_t, knots_v = [0.0, 4.0, 6.0, 20.0], [1e-4, 1e-4, 2e-3, 2e-3]
    t = np.linspace(0.0, 20.0, 2001)
    v = np.interp(t, knots_t, knots_v)
    mu = LAW.respond(t, v, method=method)
    error = np.max(np.abs(mu - exact.ramp(t, 1e-4, 2e-3, 2.0, LAW, t_start=4.0)))
    # dt = 0.01 s = t_c / 300: first-order methods ~1e-4, second ~1e-6, RK4 ~1e-10.
    bound = {"euler": 5e-4, "implicit": 5e-4, "exponential": 5e-6, "rk4": 1e-9}[method]
    assert error < bound


@pytest.mark.parametrize(
    "profile, expected",
    [
        ("ramp", {"exponential": 2, "euler": 1, "implicit": 1, "rk4": 4}),
        ("sinusoid", {"exponential": 2, "euler": 1, "implicit": 1, "rk4": 2}),
    ],
)
def test_convergence_orders(profile, expected):
    """Orders: Euler 1, implicit 1, exponential 2; RK4 4 when V is linear on each step (a ramp
    with knots on the grid) but 2 when a smooth V is sampled and taken linear between samples,
    since its half-step rate is then off by O(dt^2)."""
    if profile == "ramp":
        dts = [2.0**-k for k in range(3, 8)]
        knots_t, knots_v = [0.0, 4.0, 6.0, 20.0], [1e-4, 1e-4, 2e-3, 2e-3]

        def history(dt):
            t = np.arange(round(20.0 / dt) + 1) * dt
            return t, np.interp(t, knots_t, knots_v)

        def reference(t):
            return exact.ramp(t, 1e-4, 2e-3, 2.0, LAW, t_start=4.0)
    else:
        period = 2.0
        dts = [period / n for n in (32, 64, 128, 256, 512)]

        def v_of_t(s):
            return 1e-3 * (1.0 + 0.5 * np.sin(2 * np.pi * s / period))

        def history(dt):
            t = np.arange(round(8.0 / dt) + 1) * dt
            return t, v_of_t(t)

        def reference(t):
            return exact.periodic(t, v_of_t, period, LAW)

    for method, order in expected.items():
        errors = []
        for dt in dts:
            t, v = history(dt)
            errors.append(np.max(np.abs(LAW.respond(t, v, method=method) - reference(t))))
        assert measured_order(errors, dts) == pytest.approx(order, abs=ORDER_TOL), method


# ---------------------------------------------------------------------------------------------
# Below v_star, and the clamp
# ---------------------------------------------------------------------------------------------


def test_below_v_star_mu_is_mu0():
    """An interface that starts and stays below V* has mu = mu0 exactly under every rule:
    no interface (theta NaN) under the paper's, theta = 0 under the others."""
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.01, 1.0, 200))
    v = rng.uniform(0.0, V_STAR, 200)
    for method in ALL_METHODS:
        mu, theta = LAW.respond(t, v, method=method, return_theta=True)
        assert np.all(mu == MU0) and np.all(np.isnan(theta))
        for rule in ("healing", "frozen", "relaxing"):
            law = RateState(below_v_star=rule)
            mu, theta = law.respond(t, v, method=method, return_theta=True)
            assert np.all(mu == MU0) and np.all(theta == 0.0)


def test_slide_stop_slide_under_each_rule():
    """Slide at 1 mm/s, stop (below V*) for 5 s, slide again: the paper's rule gives mu0 while
    stopped and mu_ss again at once (a new interface); frozen holds mu_ss while stopped and
    resumes where it was; healing weakens to mu0 + theta at the stop and heals with t_c,
    then the direct effect A x on top of the healed state at the restart."""
    t = np.linspace(0.0, 30.0, 30001)
    v = np.where((t > 10.0) & (t < 15.0), 0.0, 1e-3)
    x = math.log(1e-3 / V_STAR)
    mu_ss = MU0 + (A - B) * x
    stopped, again = (t > 10.5) & (t < 14.9), np.searchsorted(t, 15.0)
    paper = RateState().respond(t, v)
    assert np.all(paper[stopped] == MU0) and paper[again] == pytest.approx(mu_ss, abs=1e-12)
    frozen = RateState(below_v_star="frozen").respond(t, v)
    assert np.allclose(frozen[stopped], MU0 - B * x, atol=1e-12)  # theta held, no A x
    assert frozen[again] == pytest.approx(mu_ss, abs=1e-3)  # the same interface resumes
    healing = RateState(below_v_star="healing").respond(t, v)
    theta_stop = -B * x
    expected = MU0 + theta_stop * np.exp(-(t[stopped] - 10.0) / T_C)
    assert np.allclose(healing[stopped], expected, atol=2e-3)  # decays from the stop
    peak = MU0 + theta_stop * math.exp(-5.0 / T_C) + A * x
    assert healing[again] == pytest.approx(peak, abs=2e-3)  # the aging law's peak


def test_relaxing_keeps_mu0_below_v_star_and_the_interface_through_the_stop():
    """``relaxing``: while stopped mu = mu0 exactly (the paper's constant friction) and theta
    decays from the stop as exp(-t / t_c) (eq. 2b at V = V*); at the restart the interface
    goes on from that theta: mu0 + theta_stop e^{-5 / t_c} + A x, the healing rule's peak,
    not the paper's new interface at mu_ss. Above V* it is the healing rule's law."""
    t = np.linspace(0.0, 30.0, 30001)
    v = np.where((t > 10.0) & (t < 15.0), 0.0, 1e-3)
    x = math.log(1e-3 / V_STAR)
    stopped, again = (t > 10.0) & (t < 15.0), np.searchsorted(t, 15.0)
    # The samples are 1 ms apart and the stop and restart fall within one (V linear between
    # samples): theta's decay may start a sample off, a relative dt / t_c (measured 3.1e-4,
    # every integrator), and the restart's first sample carries up to a sample's relaxation
    # toward -B x, B x dt / t_c each way (measured 2.0e-4 on mu).
    one_sample = (t[1] - t[0]) / T_C
    for method in ALL_METHODS:
        relaxing = RateState(below_v_star="relaxing")
        mu, theta = relaxing.respond(t, v, method=method, return_theta=True)
        assert np.all(mu[stopped] == MU0)
        late = stopped & (t > 10.5)
        expected = -B * x * np.exp(-(t[late] - 10.0) / T_C)
        assert np.allclose(theta[late], expected, rtol=one_sample, atol=0)
        peak = MU0 - B * x * math.exp(-5.0 / T_C) + A * x
        assert mu[again] == pytest.approx(peak, abs=2.0 * B * x * one_sample)
        assert mu[again] > MU0 + (A - B) * x + 0.05  # healed: stronger than the steady state
        healing = RateState(below_v_star="healing").respond(t, v, method=method)
        sliding = v > V_STAR
        assert np.array_equal(mu[sliding], healing[sliding])


def test_after_slowing_below_v_star_theta_relaxes_to_zero():
    """Healing: slide at 1 mm/s, stop below V*: theta decays to 0 with t_c, mu returns to
    mu0 without a jump at the crossing (the exact piecewise-linear solution's convention)."""
    knots_t, knots_v = [0.0, 10.0, 13.0, 60.0], [1e-3, 1e-3, 1e-7, 1e-7]
    t = np.linspace(0.0, 60.0, 6001)
    v = np.interp(t, knots_t, knots_v)
    law = RateState(below_v_star="healing")  # the rule exact.piecewise_linear solves
    mu, theta = law.respond(t, v, return_theta=True)
    ref_mu = exact.piecewise_linear(knots_t, knots_v, t, law)
    assert np.max(np.abs(mu - ref_mu)) < CROSSING_TOL
    below = t > 13.0
    assert np.allclose(mu[below], MU0 + theta[below], rtol=0, atol=1e-15)
    decay = theta[below] / theta[below][0]
    assert np.allclose(decay, np.exp(-(t[below] - t[below][0]) / T_C), rtol=1e-6)
    assert abs(mu[-1] - MU0) < 1e-7
    # Continuous in V at V*, at the theta the interface carries there.
    theta_at = theta[below][0]
    above, under = (
        friction.rate_state_mu(theta_at, LAW.slip_log(V_STAR * f), A, MU0)
        for f in (1 + 1e-9, 1 - 1e-9)
    )
    assert abs(above - under) < 1e-10


def test_fast_deceleration_is_clamped_at_zero():
    """Stopping from 5 cm/s (above V* e^{mu0/B} ~ 2.4 cm/s): mu would go negative; it is 0."""
    v_threshold = V_STAR * math.exp(MU0 / B)
    assert 0.023 < v_threshold < 0.025
    for v1, clamped in ((0.05, True), (0.02, False)):
        t, v = step_history(v1, 1e-5, dt=0.05, duration=20.0)
        mu, theta = LAW.respond(t, v, return_theta=True)
        after = np.argmax(t > 2.0)
        assert (mu[after] == 0.0) == clamped
        assert np.all(mu >= 0.0)
        assert np.allclose(mu, np.maximum(MU0 + theta + A * LAW.slip_log(v), 0.0), atol=1e-15)
        assert mu[-1] > 0.8  # recovered toward mu0 after ~6 t_c


# ---------------------------------------------------------------------------------------------
# Stability
# ---------------------------------------------------------------------------------------------


def test_stability_limits_are_the_amplification_roots():
    """Explicit Euler's 1 - h and RK4's 1 - h + h^2/2 - h^3/6 + h^4/24 reach -1 and 1 there."""
    h = RK4_STABILITY_LIMIT
    assert 1 - h + h**2 / 2 - h**3 / 6 + h**4 / 24 == pytest.approx(1.0, abs=1e-14)
    assert h == pytest.approx(2.785293563405282, abs=1e-14)
    assert 1 - EULER_STABILITY_LIMIT == -1.0


@pytest.mark.parametrize(
    "method, ok_h, bad_h, text",
    [("euler", 2.0, 2.001, "2 t_c = 6 s"), ("rk4", 2.785, 2.786, "2.785293563 t_c")],
)
def test_unstable_steps_are_refused(method, ok_h, bad_h, text):
    """A step past the stability limit raises StabilityError naming the limit, up front."""
    t_ok = np.arange(0, 20) * ok_h * T_C
    v = np.full(t_ok.shape, 1e-3)
    LAW.respond(t_ok, v, method=method)
    t_bad = np.arange(0, 20) * bad_h * T_C
    for call in (
        lambda: LAW.respond(t_bad, v, method=method),
        lambda: respond_batch_ti(t_bad, v, LAW, method=method),
        lambda: respond_batch(t_bad, v, LAW, method=method),
    ):
        with pytest.raises(StabilityError, match=text) as info:
            call()
        assert isinstance(info.value, ValueError)
        assert "check_stability=False" in str(info.value)


@pytest.mark.parametrize("method, h", [("euler", 2.2), ("rk4", 3.0)])
def test_unstable_steps_diverge_when_forced(method, h):
    """Past the limit the deviation from steady state grows by |R(h)| > 1 per step."""
    t, v = step_history(1e-4, 1e-3, dt=h * T_C, duration=40 * h * T_C)
    _, theta = LAW.respond(t, v, method=method, check_stability=False, return_theta=True)
    deviation = np.abs(theta + B * LAW.slip_log(1e-3))
    assert deviation[-1] > 100 * deviation[2]


@pytest.mark.parametrize("method", ["exponential", "implicit"])
def test_exponential_and_implicit_are_stable_at_any_step(method):
    """At dt = 50 t_c the exponential and implicit methods still settle to mu_ss(V2)."""
    t, v = step_history(1e-4, 1e-3, dt=50 * T_C, duration=2000 * T_C)
    mu = LAW.respond(t, v, method=method)
    assert np.all(np.isfinite(mu)) and np.all(mu <= mu.max())
    assert abs(mu[-1] - LAW.steady_state(1e-3)) < 1e-12


# ---------------------------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "t, v, message",
    [
        ([0.0, 1.0, 2.0], [1e-3, -1e-3, 1e-3], r"v is a slip rate and must be >= 0.*\[1\]"),
        ([0.0, 1.0, 2.0], [1e-3, math.nan, 1e-3], r"NaN.*\[1\]"),
        ([0.0, 1.0, 2.0], [1e-3, math.inf, 1e-3], "finite"),
        ([0.0, 1.0, 1.0], [1e-3, 1e-3, 1e-3], r"strictly increasing; t\[2\]"),
        ([0.0, 2.0, 1.0], [1e-3, 1e-3, 1e-3], "strictly increasing"),
        ([0.0, math.nan, 1.0], [1e-3, 1e-3, 1e-3], "t must be finite"),
        ([0.0, 1.0, 2.0], [1e-3, 1e-3], r"shape \(T,\).*T = len\(t\) = 3.*\(2,\)"),
        ([0.0, 1.0, 2.0], [[1e-3] * 3] * 2, "shape"),
        ([], [], "non-empty"),
    ],
)
def test_bad_histories_are_refused(t, v, message):
    """Negative, NaN or infinite rates, non-increasing times and shape mismatches are errors."""
    with pytest.raises(ValueError, match=message):
        LAW.respond(t, v)
    if np.ndim(v) == 1:
        with pytest.raises(ValueError):
            Coulomb().respond(t, v)


def test_bad_batches_are_refused():
    """The batch drivers refuse mismatched rows, bad parameter rows and Coulomb laws."""
    t = np.arange(5.0)
    with pytest.raises(ValueError, match=r"3 interfaces.*params has 2"):
        respond_batch_ti(t, np.full((3, 5), 1e-3), np.tile(LAW.params, (2, 1)))
    bad = np.tile(LAW.params, (4, 1))
    bad[2, 4] = 0.0
    with pytest.raises(ValueError, match=r"params\[2, 4\] \(t_c\)"):
        respond_batch_ti(t, np.full(5, 1e-3), bad)
    with pytest.raises(ValueError, match="Coulomb"):
        respond_batch_ti(t, np.full(5, 1e-3), Coulomb())
    with pytest.raises(ValueError, match="unknown method"):
        respond_batch_ti(t, np.full(5, 1e-3), method="leapfrog")


def test_coulomb_is_constant():
    """Coulomb friction has no memory: mu is the same at every time and rate."""
    t = np.linspace(0.0, 10.0, 11)
    v = np.linspace(0.0, 2.0, 11)
    assert np.all(Coulomb(0.1).respond(t, v) == 0.1)
    assert Coulomb(0.1).params == (0.1,) and Coulomb(0.1).name == "coulomb"


# ---------------------------------------------------------------------------------------------
# NumPy against Taichi
# ---------------------------------------------------------------------------------------------


def random_batch(seed, n=48, samples=300):
    """Seeded random histories crossing V* and the clamp region, random parameters, uneven dt."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.001, 1.5, samples))
    v = 10 ** rng.uniform(-7.0, -0.5, (n, samples))
    v[:, ::7] = 0.0
    params = np.column_stack(
        [
            rng.uniform(0.0, 0.1, n),
            rng.uniform(0.0, 0.2, n),
            rng.uniform(0.3, 1.0, n),
            10 ** rng.uniform(-6, -4, n),
            rng.uniform(1.0, 5.0, n),
        ]
    )
    return t, v, params


@pytest.mark.parametrize("method", ALL_METHODS)
def test_taichi_batch_matches_numpy(method, taichi_runtime):
    """The Taichi batch, the NumPy batch and RateState.respond agree on random histories."""
    if taichi_runtime[1] != "f64":
        pytest.skip("the 1e-12 agreement is a float64 property")
    t, v, params = random_batch(11)
    mu, theta = respond_batch_ti(t, v, params, method=method, return_theta=True)
    mu_np, theta_np = respond_batch(t, v, params, method=method, return_theta=True)
    assert mu.shape == (48, 300) and mu.dtype == np.float64
    assert np.max(np.abs(mu - mu_np)) < AGREE_F64
    assert np.max(np.abs(theta - theta_np)) < AGREE_F64
    for i in (0, 17, 47):
        law = RateState(*params[i], below_v_star="healing")  # the batch's reading
        assert np.max(np.abs(law.respond(t, v[i], method=method) - mu[i])) < AGREE_F64
    assert np.any(mu == 0.0) and np.any(mu == params[:, 2:3])  # clamp and below-V* exercised


def test_batch_broadcasts_one_history_or_one_law(taichi_runtime):
    """A (T,) history is shared by every parameter row; a single law by every history row.
    (In a float32 run the kernel computes in float32: held to the float32 twin.)"""
    real = backend.real_dtype(taichi_runtime[1])
    t, v, params = random_batch(5, n=6, samples=40)
    shared_v = respond_batch_ti(t, v[0], params)
    assert shared_v.shape == (6, 40)
    for i in range(6):
        law = RateState(*params[i], below_v_star="healing")
        if real is np.float64:
            assert np.allclose(shared_v[i], law.respond(t, v[0]), atol=1e-12)
        else:
            want = respond_batch(t, v[0], params[i : i + 1], dtype=real)[0]
            assert np.allclose(shared_v[i], want, atol=AGREE_F32)
    shared_law = respond_batch_ti(t, v, LAW)
    atol = 1e-12 if real is np.float64 else AGREE_F32
    assert np.allclose(shared_law, respond_batch(t, v, LAW, dtype=real), atol=atol)


def test_batch_kernel_compiles_once_per_method(taichi_runtime):
    """New shapes reuse the compiled kernel (ndarray arguments); only a new method compiles."""
    compiled = batched._respond_kernel._primal.compiled_kernels  # Taichi 1.7 internals
    respond_batch_ti(np.arange(4.0), np.full((2, 4), 1e-3), method="implicit")
    count = len(compiled)
    respond_batch_ti(np.arange(9.0), np.full((5, 9), 1e-3), method="implicit")
    respond_batch_ti(
        np.arange(3.0), np.full(3, 1e-3), np.tile(LAW.params, (7, 1)), method="implicit"
    )
    assert len(compiled) == count


@ti.kernel
def _step_each(
    inputs: ti.types.ndarray(ndim=2), out: ti.types.ndarray(ndim=2), method: ti.template()
):
    for i in range(inputs.shape[0]):
        x_start = friction_ti.slip_log_ti(inputs[i, 1], inputs[i, 7])
        x_mid = friction_ti.slip_log_ti(inputs[i, 2], inputs[i, 7])
        x_end = friction_ti.slip_log_ti(inputs[i, 3], inputs[i, 7])
        theta = friction_ti.theta_step_ti(
            inputs[i, 0], x_start, x_mid, x_end, inputs[i, 4], inputs[i, 5], inputs[i, 6], method
        )
        out[i, 0] = theta
        out[i, 1] = friction_ti.rate_state_mu_ti(theta, x_end, inputs[i, 8], inputs[i, 9])
        out[i, 2] = friction_ti.theta_equilibrium_ti(x_end, inputs[i, 5])


@pytest.mark.parametrize("method", ALL_METHODS)
def test_taichi_functions_match_their_numpy_twins(method, taichi_runtime):
    """Each ti.func, called from a user kernel as a DEM contact calls it, equals its NumPy twin."""
    rng = np.random.default_rng(19)
    n = 1000
    # theta, v_start, v_mid, v_end, dt, B, t_c, v_star, A, mu0
    inputs = np.column_stack(
        [
            rng.uniform(-1.5, 0.5, n),
            10 ** rng.uniform(-7, 0, (n, 3)),
            rng.uniform(1e-5, 5.0, n),
            rng.uniform(0.0, 0.2, n),
            rng.uniform(2.6, 5.0, n),
            10 ** rng.uniform(-6, -4, n),
            rng.uniform(0.0, 0.1, n),
            rng.uniform(0.3, 1.0, n),
        ]
    )
    out = np.empty((n, 3))
    _step_each(inputs, out, friction.method_code(method))
    theta0, vs, vm, ve, dt, b, t_c, v_star, a, mu0 = inputs.T
    xs, xm, xe = (friction.slip_log(v, v_star) for v in (vs, vm, ve))
    theta = friction.theta_step(theta0, xs, xm, xe, dt, b, t_c, friction.method_code(method))
    assert np.max(np.abs(out[:, 0] - theta)) < AGREE_F64
    assert np.max(np.abs(out[:, 1] - friction.rate_state_mu(theta, xe, a, mu0))) < AGREE_F64
    assert np.max(np.abs(out[:, 2] - friction.theta_equilibrium(xe, b))) < AGREE_F64


F32_SCRIPT = textwrap.dedent(
    """
    import numpy as np
    from taichi_ice import backend
    from taichi_ice.physics.batched import respond_batch, respond_batch_ti
    from taichi_ice.physics.friction import RateState

    rng = np.random.default_rng(2)
    t = np.cumsum(rng.uniform(0.01, 1.0, 200))
    v = 10 ** rng.uniform(-6.0, -2.0, (16, 200))
    mu64 = respond_batch_ti(t, v)  # starts Taichi itself: CPU, float64
    assert backend.current() == ("cpu", "f64"), backend.current()
    backend.init("cpu", "f32", reinit=True)
    for method in RateState.methods:
        mu32 = respond_batch_ti(t, v, method=method)
        assert mu32.dtype == np.float32
        ref = respond_batch(t, v, method=method)
        print(method, float(np.max(np.abs(mu32 - ref))))
    print("f64", float(np.max(np.abs(mu64 - respond_batch(t, v)))))
    """
)


def test_float32_batch_in_its_own_process():
    """Taichi started in float32 integrates to float32 accuracy; respond_batch_ti starts Taichi
    (CPU, float64) by itself when nobody has."""
    root = Path(__file__).resolve().parent.parent
    proc = subprocess.run(
        [sys.executable, "-c", F32_SCRIPT],
        capture_output=True,
        text=True,
        cwd=root,
        # The package first, and whatever else the parent imports from (its site folders).
        env={
            **os.environ,
            "PYTHONPATH": os.pathsep.join(filter(None, [str(root), os.environ.get("PYTHONPATH")])),
        },
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    errors = dict(line.split() for line in proc.stdout.splitlines() if line[:1].isalpha())
    assert float(errors.pop("f64")) < AGREE_F64
    assert set(errors) == set(ALL_METHODS)
    for method, error in errors.items():
        assert 0.0 < float(error) < AGREE_F32, method


# ---------------------------------------------------------------------------------------------
# A law's identity: one declaration of its parameters, one parser, one label
# ---------------------------------------------------------------------------------------------

SOME_LAWS = [
    Coulomb(),
    Coulomb(0.3),
    RateState(),
    RateState(A=0.04, t_c=2.0, method="rk4"),
    RateState(B=0.2, mu0=0.6, v_star=2e-5),
]


@pytest.mark.parametrize("law", SOME_LAWS, ids=repr)
def test_every_written_form_reads_back_the_same_law(law):
    """to_dict -> law_from_table and the command-line form -> parse_law give the law back."""
    assert friction_parse.law_from_table(law.to_dict()) == law
    text = f"{law.name}:" + ",".join(f"{k}={v}" for k, v in law.to_dict().items() if k != "law")
    assert friction_parse.parse_law(text) == law


def test_parameters_are_declared_once_with_units():
    """Each law lists its parameters with the paper's defaults, units and meaning; the batch
    model has one column per parameter."""
    from taichi_ice.engine import schema

    names = {p.name: p for p in RateState.parameters()}
    assert list(names) == ["A", "B", "mu0", "v_star", "t_c"]
    assert names["v_star"].unit == "m/s" and names["t_c"].unit == "s" and names["t_c"].positive
    assert [p.default for p in names.values()] == list(RateState().params)
    for law in friction.LAWS.values():
        for p in law.parameters():
            assert schema.var(f"world_{p.name}").unit == p.unit


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        ("viscous", "law", "unknown law"),
        ("rate-state:a=0.1", "a", "did you mean 'A'"),
        ("rate-state:mu=0.3", "mu", 'belongs to law = "coulomb"'),
        ("coulomb:-0.1", "mu", "mu must be >= 0"),
        ("rate-state:t_c=abc", "t_c", "must be a number"),
        ("rate-state:method=heun", "method", "method must be one of"),
    ],
)
def test_bad_law_text_names_the_key(text, key, message):
    """A mistake in a law's text names the key and says what is wrong."""
    with pytest.raises(friction.LawError, match=message) as info:
        friction_parse.parse_law(text)
    assert info.value.key == key


def test_scene_tables_are_strict_where_the_command_line_is_lenient():
    """The command line takes 'rs' and 'RATE-STATE'; a scene file must spell the name."""
    assert friction_parse.parse_law("RS:t_c=2") == RateState(t_c=2.0)
    with pytest.raises(friction.LawError, match='did you mean "rate-state"'):
        friction_parse.law_from_table({"law": "rate_state"})
    with pytest.raises(friction.LawError, match="remove the quotes"):
        friction_parse.law_from_table({"law": "coulomb", "mu": "0.3"})
