"""Friction at a DEM contact (taichi_ice.physics.slip): the slip rate, a new interface's start and
the rule below v_star.

References that do not share the code: the closed forms of the law at the solved rate (the
equation V = (|F_trial| - mu(V) F_n) / K must hold with mu written out by hand), scipy's
bracketing root finder for the same equation, and the Taichi twin against the NumPy one on
seeded random contacts.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from taichi_ice.codes import RestRule, ThetaMethod
from taichi_ice.physics.batched import contact_friction_batch_ti
from taichi_ice.physics.slip import NEW_CONTACT, NO_INTERFACE, contact_friction

A, B, MU0, V_STAR, T_C = 0.05, 0.112, 0.872, 1e-5, 3.0
DT = 1e-4
# The Newton root against the equation written out by hand: relative to the forces involved.
EQUATION_RTOL = 1e-10
FAST = 1.0  # m/s: surfaces moving fast enough that the cap at |s| does not bind


def solve(
    theta,
    f_trial,
    f_n,
    K,
    *,
    slip=FAST,
    last_slip=0.0,
    memory=1,
    rule=RestRule.PAPER,
    method=0,
    law=None,
):
    a, b, mu0, v_star, t_c = law or (A, B, MU0, V_STAR, T_C)
    return contact_friction(
        theta,
        last_slip,
        slip,
        f_trial,
        f_n,
        K,
        DT,
        a,
        b,
        mu0,
        v_star,
        t_c,
        memory,
        rule,
        method,
    )


def test_stuck_contact_has_no_sliding_rate_and_the_paper_mu0():
    """A stuck contact (no interface under the paper's rule) with |F_trial| <= mu0 F_n: V = 0
    and mu = mu0; a still-sliding interface with low theta keeps sliding at that load."""
    for theta in (NO_INTERFACE, NEW_CONTACT):
        mu, theta_new, v = solve(theta, 0.8 * MU0 * 1e4, 1e4, 2e4)
        assert v == 0.0 and mu == MU0 and theta_new == NO_INTERFACE
    mu, theta_new, v = solve(-0.5, 0.8 * MU0 * 1e4, 1e4, 2e4, last_slip=FAST)
    assert v > V_STAR and mu < 0.8 * MU0  # the cap is below the load: it slides


def test_new_contact_slides_at_steady_state_friction_of_its_own_rate():
    """A contact sliding at its first touch solves V K = |F_trial| - mu_ss(V) F_n with mu_ss
    written by hand, below the surfaces' speed, and starts at theta = -B ln(V / v_star);
    scipy's brentq finds the same V."""
    f_n, K, f_trial = 1e4, 2e4, 1.2 * MU0 * 1e4
    mu, theta, v = solve(NEW_CONTACT, f_trial, f_n, K, slip=100.0)
    x = math.log(v / V_STAR)
    assert mu == pytest.approx(MU0 + (A - B) * x, abs=1e-14)
    assert theta == pytest.approx(-B * x, abs=1e-14)
    assert v * K == pytest.approx(f_trial - mu * f_n, rel=EQUATION_RTOL)

    def g(y):
        return K * V_STAR * math.exp(y) + f_n * max(MU0 + (A - B) * y, 0.0) - f_trial

    y = brentq(g, 0.0, math.log(f_trial / (K * V_STAR)), xtol=1e-15, rtol=1e-15)
    assert v == pytest.approx(V_STAR * math.exp(y), rel=1e-10)
    assert V_STAR < v < 100.0 and mu < MU0  # the static-kinetic drop, at its sliding rate


def test_slip_rate_is_never_faster_than_the_surfaces():
    """The sliding rate of a new contact that would outrun its surfaces is capped at |s|:
    V = |s| with its sign, theta in equilibrium there, mu = mu_ss(|s|)."""
    f_n, K, f_trial = 1e4, 2e4, 1.2 * MU0 * 1e4  # the sliding rate alone: ~0.9 m/s
    for s in (0.1, -0.1, 1e-3):
        mu, theta, v = solve(NEW_CONTACT, f_trial, f_n, K, slip=s)
        x = math.log(abs(s) / V_STAR)
        assert v == s
        assert theta == pytest.approx(-B * x, abs=1e-14)
        assert mu == pytest.approx(MU0 + (A - B) * x, abs=1e-14)
    # Slower than v_star: below the law, mu0, whatever the load.
    mu, theta, v = solve(NEW_CONTACT, 5.0 * MU0 * f_n, f_n, K, slip=0.5 * V_STAR)
    assert (mu, theta) == (MU0, NO_INTERFACE) and abs(v) <= 0.5 * V_STAR


def test_a_contact_at_rest_starts_its_interface_at_v_star():
    """A contact that stuck starts from rest: its interface is born in equilibrium at v_star
    (theta = 0) and carried over the step at the solved rate,
    theta_new = -B x (1 - e^{-dt/t_c}); mu = mu0 + theta_new + A x and V K = |F_trial| - mu
    F_n, so mu rises above mu0 with the rate (the direct effect) instead of dropping."""
    f_n, K, f_trial = 1e4, 2e4, 1.2 * MU0 * 1e4
    mu, theta, v = solve(NO_INTERFACE, f_trial, f_n, K)
    x = math.log(v / V_STAR)
    assert theta == pytest.approx(-B * x * (1.0 - math.exp(-DT / T_C)), abs=1e-15)
    assert mu == pytest.approx(MU0 + theta + A * x, abs=1e-13)
    assert v * K == pytest.approx(f_trial - mu * f_n, rel=EQUATION_RTOL)
    assert mu > MU0


def test_carried_interface_updates_theta_exponentially_at_the_solved_rate():
    """A sliding interface: theta_new = -B x + (theta + B x) e^{-dt/t_c} with x of the solved
    V, mu = mu0 + theta_new + A x, and V K = |F_trial| - mu F_n."""
    f_n, K = 1e4, 2e4
    for theta in (-0.1, -0.6, -1.2):
        f_trial = 0.9 * f_n
        mu, theta_new, v = solve(theta, f_trial, f_n, K, last_slip=0.3)
        x = math.log(v / V_STAR)
        h = math.exp(-DT / T_C)
        assert theta_new == pytest.approx(-B * x + (theta + B * x) * h, abs=1e-13)
        assert mu == pytest.approx(max(MU0 + theta_new + A * x, 0.0), abs=1e-13)
        assert v * K == pytest.approx(f_trial - mu * f_n, rel=EQUATION_RTOL)


def test_a_slip_that_reverses_ends_the_interface_under_the_paper_rule():
    """Between two steps of opposite slip the slip passed through zero: under the paper's
    rule the interface ended there (a weak theta is forgotten and mu0 holds the load);
    healing, frozen and relaxing keep their theta through the reversal."""
    f_n, K, theta = 1e4, 2e4, -1.2  # theta after a fast slide: mu near 0 at low speed
    load = 0.8 * MU0 * f_n
    same = solve(theta, load, f_n, K, slip=-1e-3, last_slip=-1e-3)
    assert abs(same[2]) > V_STAR  # no reversal: the weak interface slides on
    mu, th, v = solve(theta, load, f_n, K, slip=-1e-3, last_slip=1e-3)
    assert (mu, th, v) == (MU0, NO_INTERFACE, 0.0)  # reversed: at rest, mu0 holds
    for rule in (RestRule.HEALING, RestRule.FROZEN, RestRule.RELAXING):
        kept = solve(theta, load, f_n, K, slip=-1e-3, last_slip=1e-3, rule=rule)
        assert kept[1] < 0.0 and abs(kept[2]) > V_STAR


def test_rules_below_v_star():
    """Slower than v_star: paper mu0 and no interface; healing steps theta with x = 0;
    frozen holds it; both with mu = max(mu0 + theta, 0); relaxing steps theta as healing
    does and takes mu0."""
    f_n, K, theta = 1e4, 2e4, -0.5
    f_trial = 0.2 * f_n  # below mu(v_star) F_n = 0.372 F_n: no root at or above v_star
    mu, th, v = solve(theta, f_trial, f_n, K, rule=RestRule.PAPER)
    assert (mu, th, v) == (MU0, NO_INTERFACE, 0.0)
    mu, th, v = solve(theta, f_trial, f_n, K, rule=RestRule.HEALING)
    assert th == pytest.approx(theta * math.exp(-DT / T_C), abs=1e-15)
    assert mu == pytest.approx(MU0 + th, abs=1e-15) and v == 0.0
    mu, th, v = solve(theta, f_trial, f_n, K, rule=RestRule.FROZEN)
    assert th == theta and mu == pytest.approx(MU0 + theta, abs=1e-15) and v == 0.0
    mu, th, v = solve(theta, f_trial, f_n, K, rule=RestRule.RELAXING)
    assert th == pytest.approx(theta * math.exp(-DT / T_C), abs=1e-15)
    assert mu == MU0 and v == 0.0  # the paper's mu0, the interface kept
    # A contact stuck after sliding: under the paper's rule it has no interface and holds
    # 0.6 F_n; frozen, it kept theta = -0.5 and slides.
    f_trial = 0.6 * f_n
    assert solve(NO_INTERFACE, f_trial, f_n, K, rule=RestRule.PAPER)[2] == 0.0
    assert solve(theta, f_trial, f_n, K, rule=RestRule.FROZEN)[2] > V_STAR
    # Relaxing: while its surfaces move slower than v_star, mu0 holds the stuck contact
    # though it kept theta = -0.5 (0.6 F_n < mu0 F_n); moving faster, the weak law slides it.
    assert solve(theta, f_trial, f_n, K, slip=1e-6, rule=RestRule.RELAXING)[:3:2] == (MU0, 0.0)
    assert solve(theta, f_trial, f_n, K, rule=RestRule.RELAXING)[2] > V_STAR


def test_coulomb_row_slides_at_exactly_mu():
    """A = B = 0, no memory: mu is exactly mu0 at any load (Coulomb in a mixed batch)."""
    for f_trial in (0.3e4, 0.5e4, 5e4):
        mu, _, v = solve(NO_INTERFACE, f_trial, 1e4, 2e4, memory=0, law=(0, 0, 0.5, 1.0, 1.0))
        assert mu == 0.5
        want = min(max(f_trial - 0.5e4, 0.0) / 2e4, FAST)
        assert v == pytest.approx(want, rel=1e-12, abs=1e-300)


def test_taichi_twin_matches_numpy_on_random_contacts(taichi_runtime):
    """contact_friction_ti against contact_friction on seeded random contacts: every rule,
    new, resting and carried interfaces, reversals, stuck and sliding, capped and not,
    every integrator."""
    if taichi_runtime[1] != "f64":
        pytest.skip("the 1e-11 agreement is a float64 property")
    rng = np.random.default_rng(20261123)
    n = 600
    f_n = 10.0 ** rng.uniform(0, 6, n)
    kind = rng.random(n)
    theta = np.where(
        kind < 0.2, NEW_CONTACT, np.where(kind < 0.4, NO_INTERFACE, -rng.uniform(0.0, 1.5, n))
    )
    slip = rng.choice([-1.0, 1.0], n) * 10.0 ** rng.uniform(-6, 1, n)
    last = rng.choice([-1.0, 0.0, 1.0], n) * 10.0 ** rng.uniform(-5, 0, n)
    rows = np.column_stack(
        [
            theta,
            last,
            slip,
            f_n * rng.uniform(0.0, 2.0, n),
            f_n,
            10.0 ** rng.uniform(1, 5, n),
            np.full(n, DT),
            rng.uniform(0.0, 0.1, n),
            rng.uniform(0.0, 0.2, n),
            rng.uniform(0.2, 1.0, n),
            10.0 ** rng.uniform(-6, -4, n),
            rng.uniform(0.5, 5.0, n),
        ]
    )
    codes = np.column_stack([rng.integers(0, 2, n), rng.integers(0, len(RestRule), n)])
    for method in ThetaMethod:
        got = contact_friction_batch_ti(rows, codes, int(method))
        want = np.array(
            [contact_friction(*r, int(c[0]), int(c[1]), int(method)) for r, c in zip(rows, codes)]
        )
        assert np.allclose(got[:, 0], want[:, 0], rtol=1e-11, atol=1e-13)
        assert np.allclose(got[:, 1], want[:, 1], rtol=1e-11, atol=1e-13)
        assert np.allclose(got[:, 2], want[:, 2], rtol=1e-9, atol=1e-15)
        sliding = np.abs(want[:, 2]) > 0
        capped = want[:, 2] == rows[:, 2]
        assert 0.2 * n < np.count_nonzero(sliding) < 0.9 * n  # both branches exercised
        assert 0.05 * n < np.count_nonzero(capped & sliding) < 0.8 * n
