"""A rate-and-state contact's slide in sub-steps (``slip.sliding_steps``, ``[ice]
slide_resolution``).

References that do not share the code: the closed form of a stick spring-dashpot relaxing
toward a fixed cap (``xi(t) = cap / k + (xi0 - cap / k) e^(-t k / c)``), the work of the
contact's force against what it holds and dissipates (the step's energy balance), the
same slide taken over one step and over two half steps, and the Taichi twin against the
NumPy one on seeded random contacts.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from taichi_ice.codes import RestRule, ThetaMethod
from taichi_ice.physics.batched import sliding_steps_batch_ti
from taichi_ice.physics.contact_law import tangential_force
from taichi_ice.physics.slip import (
    NEW_CONTACT,
    NO_INTERFACE,
    SLIDE_STEPS_MOST,
    contact_friction,
    slide_steps,
    sliding_steps,
)

PAPER = (0.05, 0.112, 0.872, 1e-5, 3.0)  # A, B, mu0, v_star, t_c
# A stick spring of a 1 m contact of the paper's ice (0.5 k_e L) on a pair of 1e4 kg, damped
# to 0.25 of critical: relaxation time c / k = 7 ms.
K_T = 0.5 * 9.75e7
C_T = 2.0 * 0.25 * math.sqrt(K_T * 1.0e4)
TAU = C_T / K_T
DT = 0.4 * TAU  # k_t dt / c_t = 0.4: the paper's pillar's stiffest contact at 0.2 stable_dt
F_N = 1.0e5


def step(xi, slip, dt, resolution, law=PAPER, theta=NO_INTERFACE, last=0.0, memory=1):
    return sliding_steps(
        theta, last, slip, xi, F_N, K_T, C_T, dt, *law, memory, RestRule.PAPER,
        ThetaMethod.EXPONENTIAL, 1e-13, resolution,
    )  # fmt: skip


def test_slide_relaxes_as_the_closed_form_at_first_order_in_the_resolution():
    """Sliding against a fixed cap (A = B = 0: mu = mu0), the stretch relaxes toward cap / k_t
    over c_t / k_t and the slip rate is s - xi'; the sub-steps reach both closed forms at
    first order in the resolution, where one backward-Euler step at k_t dt / c_t = 0.4
    misses the stretch's change by 13 % and the slip's lag behind s by 6.6 %."""
    coulomb = (0.0, 0.0, PAPER[2], PAPER[3], PAPER[4])
    cap = PAPER[2] * F_N
    slip, xi0 = 0.1, 1.5e-3  # under-stretched (k xi0 < cap) but sliding: V < s
    assert K_T * xi0 < cap < K_T * xi0 + C_T * slip
    xi_exact = cap / K_T + (xi0 - cap / K_T) * math.exp(-DT / TAU)
    v_exact = slip - (cap - K_T * xi_exact) / C_T
    errors = {}
    for r in (0.0, 0.04, 0.02, 0.01):  # 1, 10, 20 and 40 sub-steps
        mu, _, v, f_t, xi, slip_work, _, _, _ = step(xi0, slip, DT, r, law=coulomb)
        assert mu == PAPER[2] and f_t == -cap and slip_work > 0.0
        # Each relative to what the step changes: the stretch's change, the slip's lag.
        errors[r] = (abs(xi - xi_exact) / (xi_exact - xi0), abs(v - v_exact) / (slip - v_exact))
    assert errors[0.0][0] > 0.1 and errors[0.0][1] > 0.05  # measured 13 % and 6.6 %
    for k in (0, 1):
        order = math.log2(errors[0.02][k] / errors[0.01][k])
        assert 0.9 < order < 1.1, (k, errors)
        assert errors[0.01][k] < 0.05 * errors[0.0][k]


def test_one_step_or_two_half_steps_give_the_same_slide():
    """The law's theta and slip rate, and the stretch, after a step taken whole or as two
    half steps: taken in one step each (resolution 0) they part by dt's share of the
    relaxation; in sub-steps of other sizes (27 whole, 14 in each half) by ten times less:
    the sub-steps, not dt, set the slide."""
    slip = 0.02
    for xi0, theta in ((0.9 * PAPER[2] * F_N / K_T, NO_INTERFACE), (1.2e-3, -0.3)):
        gap = {}
        for r in (0.0, 0.015):  # 27 sub-steps whole, 14 + 14 in halves
            whole = step(xi0, slip, DT, r, theta=theta)
            half = step(xi0, slip, DT / 2, r, theta=theta)
            halves = step(half[4], slip, DT / 2, r, theta=half[1], last=half[2])
            assert whole[5] > 0.0 and halves[5] > 0.0  # both slid
            gap[r] = [abs(whole[k] - halves[k]) / abs(whole[k]) for k in (1, 2, 4)]
        for k in range(3):
            assert gap[0.015][k] < gap[0.0][k] / 10, (xi0, gap)


def test_the_step_books_the_work_of_its_mean_force():
    """On seeded random contacts, over sub-steps: the mean force's work on the slip is what
    friction, the dashpots and the spring take, ``-f_t s dt = slip_work + damp_work + k_t
    xi' (xi' - xi)`` (the identity ``contact_law.contact_work`` books the step with)."""
    rng = np.random.default_rng(20261127)
    many = 0
    for _ in range(400):
        xi = rng.normal(0.0, 2e-3)
        slip = rng.choice([-1.0, 1.0]) * 10.0 ** rng.uniform(-4, 0)
        theta = rng.choice([NO_INTERFACE, NEW_CONTACT, -rng.uniform(0.0, 0.8)])
        r = rng.choice([0.0, 0.1, 0.02])
        _, _, _, f_t, xi_new, slip_work, damp_work, _, _ = step(xi, slip, DT, r, theta=theta)
        many += slide_steps(K_T, C_T, DT, 1, r) > 1
        work = -f_t * slip * DT
        parts = slip_work + damp_work + K_T * xi_new * (xi_new - xi)
        scale = abs(f_t * slip * DT) + slip_work + abs(damp_work) + K_T * xi_new**2
        assert work == pytest.approx(parts, rel=0, abs=1e-11 * scale)
        step_ = xi_new - xi  # what the budget books as viscous: none of it negative
        assert slip_work >= 0.0 and damp_work + 0.5 * K_T * step_**2 >= -1e-11 * scale
    assert many > 200


def test_without_resolution_it_is_the_one_step_contact_bit_for_bit():
    """Resolution 0 and a Coulomb world of a rate-and-state batch (memory 0)
    take one step: the law then the capped spring-dashpot, as the contact took them before."""
    rng = np.random.default_rng(7)
    for _ in range(200):
        xi, slip = rng.normal(0.0, 2e-3), rng.normal(0.0, 0.05)
        theta = rng.choice([NO_INTERFACE, NEW_CONTACT, -rng.uniform(0.0, 0.8)])
        memory, r = (1, 0.0) if rng.random() < 0.5 else (0, 0.05)
        got = step(xi, slip, DT, r, theta=theta, memory=memory)
        f_trial = abs(K_T * (xi + slip * DT) + C_T * slip)
        mu, th, v = contact_friction(
            theta, 0.0, slip, f_trial, F_N, K_T * DT + C_T, DT, *PAPER, memory,
            RestRule.PAPER, ThetaMethod.EXPONENTIAL, 1e-13,
        )  # fmt: skip
        force = tangential_force(xi, slip, DT, K_T, C_T, mu * F_N)
        assert got == (mu, th, v, *force, mu, force[2] > 0.0)


def test_sub_steps_are_counted_from_the_relaxation_time():
    assert slide_steps(K_T, C_T, DT, 1, 0.1) == 4  # 0.4 / 0.1
    assert slide_steps(K_T, C_T, DT, 1, 0.0) == 1
    # A contact's first step is taken whole: its normal force is the whole step's overlap's.
    assert slide_steps(K_T, C_T, DT, 1, 0.1, NEW_CONTACT) == 1
    birth = step(0.0, 0.05, DT, 0.01, theta=NEW_CONTACT)
    assert birth == step(0.0, 0.05, DT, 0.0, theta=NEW_CONTACT)
    assert slide_steps(K_T, C_T, DT, 0, 0.1) == 1
    assert slide_steps(K_T, C_T, DT, 1, 1e-6) == SLIDE_STEPS_MOST
    assert slide_steps(K_T, C_T, DT, 1, 1e-300) == SLIDE_STEPS_MOST  # no integer overflow


def test_taichi_twin_matches_numpy_on_random_contacts(taichi_runtime):
    """sliding_steps_ti against sliding_steps on seeded random contacts: every rule, new,
    resting and carried interfaces, stuck and sliding, one step and many."""
    if taichi_runtime[1] != "f64":
        pytest.skip("the 1e-10 agreement is a float64 property")
    rng = np.random.default_rng(20261127)
    n = 400
    kind = rng.random(n)
    theta = np.where(
        kind < 0.2, NEW_CONTACT, np.where(kind < 0.4, NO_INTERFACE, -rng.uniform(0.0, 1.5, n))
    )
    f_n = 10.0 ** rng.uniform(2, 6, n)
    k_t = 10.0 ** rng.uniform(5, 8, n)
    c_t = 2.0 * 0.25 * np.sqrt(k_t * 10.0 ** rng.uniform(2, 5, n))
    rows = np.column_stack(
        [
            theta,
            rng.choice([-1.0, 0.0, 1.0], n) * 10.0 ** rng.uniform(-5, 0, n),
            rng.choice([-1.0, 1.0], n) * 10.0 ** rng.uniform(-6, 0, n),
            rng.uniform(-1.0, 1.0, n) * f_n / k_t,
            f_n,
            k_t,
            c_t,
            rng.uniform(0.05, 0.5, n) * c_t / k_t,
            rng.uniform(0.0, 0.1, n),
            rng.uniform(0.0, 0.2, n),
            rng.uniform(0.2, 1.0, n),
            10.0 ** rng.uniform(-6, -4, n),
            rng.uniform(0.5, 5.0, n),
            rng.choice([0.0, 0.1, 0.02, 1e-300], n),  # the last: capped at SLIDE_STEPS_MOST
        ]
    )
    codes = np.column_stack([rng.integers(0, 2, n), rng.integers(0, len(RestRule), n)])
    steps = [slide_steps(r[5], r[6], r[7], c[0], r[13]) for r, c in zip(rows, codes)]
    assert sum(s > 1 for s in steps) > n // 4
    for method in ThetaMethod:
        got = sliding_steps_batch_ti(rows, codes, int(method))
        want = np.array(
            [
                sliding_steps(*r[:13], int(c[0]), int(c[1]), int(method), 1e-13, r[13])
                for r, c in zip(rows, codes)
            ]
        )
        force = rows[:, 4]  # f_n: the scale of forces, stretches (f_n / k_t) and works
        stretch = force / rows[:, 5]
        atol = (1e-13, 1e-13, 1e-15, 1e-10 * force, 1e-10 * stretch, 1e-9 * force * stretch,
                1e-9 * force * stretch)  # fmt: skip
        rtol = (1e-11, 1e-11, 1e-9, 1e-9, 1e-9, 1e-9, 1e-9)  # mu, theta, V as contact_friction's
        for k in range(7):
            bound = rtol[k] * np.abs(want[:, k]) + atol[k]
            assert np.all(np.abs(got[:, k] - want[:, k]) <= bound), k
        sliding = want[:, 5] > 0
        assert 0.2 * n < np.count_nonzero(sliding) < 0.9 * n
