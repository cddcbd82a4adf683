"""A contact's normal and tangent solved together over a step (the ``coupled`` integrator,
taichi_ice/physics/contact_coupled.py, issue 30): its exponential against SciPy's, the
joint solution's impulses against an ODE of the two coupled spring-dashpots solved by SciPy,
the pair's energy kept without dashpots, the two 1D solves of ``pair_impulses`` where nothing
couples them; and the Taichi twins against the NumPy ones on seeded random contacts."""

# No "from __future__ import annotations": Taichi reads kernel annotations as objects.

import math
from fractions import Fraction

import numpy as np
import pytest
import taichi as ti
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from taichi_ice.physics.contact_coupled import (
    SERIES_TOL,
    coupled_flow,
    coupled_impulses,
    flow_times,
    series_terms,
)
from taichi_ice.physics.contact_coupled_ti import coupled_impulses_ti, flow_times_ti
from taichi_ice.physics.contact_step import pair_impulses

RNG = np.random.default_rng(20261127)
NAMES = (
    "depth approach slip xi fresh approach_change slip_change last_force h "
    "k_n c_n k_t c_t inv_n inv_t"
).split()


def random_contact(rng, *, fresh=False, pushing=True):
    """``pair_impulses``' arguments, of the scenes' orders: a step of a fraction of a
    radian to a few; ``pushing``: deep and closing, so the normal force pushes throughout."""
    inv_n, inv_t = rng.uniform(2e-3, 2e-2, 2)
    k_n = rng.uniform(2e7, 1e8)
    k_t = rng.uniform(0.25, 1.0) * k_n
    c_n = rng.uniform(0.05, 0.3) * 2.0 * math.sqrt(k_n / inv_n)
    c_t = rng.uniform(0.05, 0.5) * 2.0 * math.sqrt(k_t / inv_t)
    h = rng.uniform(0.02, 0.15 if pushing else 1.5) / math.sqrt(k_n * inv_n)
    depth = rng.uniform(1e-4, 1e-3) if pushing else rng.uniform(1e-6, 1e-4)
    return dict(
        depth=depth,
        approach=rng.uniform(0.0, 0.5) if pushing else rng.uniform(-1.0, 1.0),
        slip=rng.uniform(-0.5, 0.5),
        xi=0.0 if fresh else rng.uniform(-1e-4, 1e-4),
        fresh=fresh,
        approach_change=rng.uniform(-1e-3, 1e-3),
        slip_change=rng.uniform(-1e-3, 1e-3),
        last_force=(0.0, 0.0) if fresh else (k_n * depth, rng.uniform(-1e3, 1e3)),
        h=h,
        k_n=k_n,
        c_n=c_n,
        k_t=k_t,
        c_t=c_t,
        inv_n=inv_n,
        inv_t=inv_t,
    )


def test_flow_times_is_scipys_exponential_times_the_state():
    """``exp(B) z`` by the Taylor series in pieces against SciPy's ``expm`` (Pade, scaling and
    squaring) times ``z``, for matrices of the flow's block form ``[[0, a I], [P, Q]]``: random
    ones from norms far below a piece's to ~15 pieces, and the flow's own (``W`` positive
    definite, springs and dashpots positive, steps to 3 radians of its fastest frequency)."""
    for _ in range(300):
        scale = RNG.uniform(0.01, 8.0)
        a = RNG.uniform(0.1, 1.0) * scale
        p, q = RNG.normal(size=(2, 2)) * scale, RNG.normal(size=(2, 2)) * scale
        b = np.block([[np.zeros((2, 2)), a * np.eye(2)], [p, q]])
        z = RNG.normal(size=4)
        e = expm(b)
        got = np.array(flow_times(a, *p.ravel(), *q.ravel(), z))
        assert np.max(np.abs(got - e @ z)) <= 1e-11 * np.max(np.abs(e)) * np.max(np.abs(z))
    for _ in range(300):
        root = RNG.normal(size=(2, 2))
        w = root @ root.T + 0.1 * np.eye(2)
        s, c = np.diag(RNG.uniform(0.1, 1.0, 2)), np.diag(RNG.uniform(0.0, 0.5, 2))
        omega = math.sqrt(max(w[0, 0] * s[0, 0], w[1, 1] * s[1, 1]))
        h = RNG.uniform(0.01, 3.0) / omega
        p, q = -w @ s * h / omega, -w @ c * h
        b = np.block([[np.zeros((2, 2)), omega * h * np.eye(2)], [p, q]])
        z = RNG.normal(size=4)
        want = expm(b) @ z
        got = np.array(flow_times(omega * h, *p.ravel(), *q.ravel(), z))
        assert np.max(np.abs(got - want)) <= 1e-12 * np.max(np.abs(want))


def test_the_series_leaves_out_less_than_its_tolerance_and_takes_no_term_more():
    """``series_terms`` for piece norms ``nu`` from 1e-6 to a piece's full 2: what the Taylor
    series of ``exp(nu)`` leaves out after that many terms, summed in exact rationals (not the
    closed bound the code takes), times ``exp(nu)`` (the result is at least ``exp(-nu) |z|``),
    is at most ``SERIES_TOL``; with one term fewer it is more, at every norm."""

    def left_out(nu: float, m: int) -> float:
        x, term, total = Fraction(nu), Fraction(1), Fraction(0)
        for k in range(1, m + 80):
            term = term * x / k
            if k > m:
                total += term
        return float(total) * math.exp(nu)

    norms = np.concatenate([np.geomspace(1e-6, 2.0, 200), [2.0]])
    terms = [series_terms(nu) for nu in norms]
    assert terms[-1] == 24 and terms[0] == 2
    assert all(left_out(nu, m) <= SERIES_TOL for nu, m in zip(norms, terms))
    assert all(left_out(nu, m - 1) > SERIES_TOL for nu, m in zip(norms, terms))
    assert series_terms(float("nan")) == 1


def test_stuck_contact_impulses_match_the_coupled_ode():
    """A contact that stays stuck and pushes over the step, with the bodies' turning coupling
    its normal and tangent (``k_nt`` up to 0.9 of its bound): the returned mean normal force,
    the tangential impulse, both position impulses and the stretch are those of the ODE
    ``u' = a - W g`` with the integrals of ``g`` carried along, solved by SciPy's DOP853;
    ``a`` the other forces' acceleration, the last step's change less all of the contact's
    own forces (its cross term too)."""
    for _ in range(40):
        c = random_contact(RNG)
        k_nt = RNG.uniform(-0.9, 0.9) * math.sqrt(c["inv_n"] * c["inv_t"])
        w = np.array([[c["inv_n"], -k_nt], [-k_nt, c["inv_t"]]])
        s, d = np.diag([c["k_n"], c["k_t"]]), np.diag([c["c_n"], c["c_t"]])
        g_last = np.array([c["last_force"][0], -c["last_force"][1]])
        a = np.array([c["approach_change"], c["slip_change"]]) / c["h"] + w @ g_last

        def rhs(_t, y, w=w, s=s, d=d, a=a):
            g = s @ y[0:2] + d @ y[2:4]
            return np.concatenate([y[2:4], a - w @ g, g, y[4:6]])

        y0 = np.array([c["depth"], c["xi"], c["approach"], c["slip"], 0, 0, 0, 0], float)
        sol = solve_ivp(rhs, (0.0, c["h"]), y0, method="DOP853", rtol=1e-12, atol=1e-20)
        y = sol.y[:, -1]
        f_n, _f_el, q_n, p_t, q_t, xi1, a_n, a_t = coupled_impulses(*c.values(), k_nt, 1e9)
        assert (a_n, a_t) == pytest.approx(tuple(a), rel=1e-12)
        assert f_n * c["h"] == pytest.approx(y[4], rel=1e-8)
        assert p_t == pytest.approx(y[5], rel=1e-7, abs=1e-9 * abs(y[4]))
        assert q_n == pytest.approx(y[6], rel=1e-8)
        assert q_t == pytest.approx(y[7], rel=1e-7, abs=1e-9 * abs(y[6]))
        assert xi1 == pytest.approx(y[1], rel=1e-7, abs=1e-9 * abs(y[0]))


def test_without_cross_term_the_joint_solve_is_the_two_closed_forms():
    """k_nt = 0 decouples the system: the 4 x 4 exponential must give what ``pair_impulses``'
    two 1D solutions (fdlibm's exp, cos and sin) give, to round-off, on 200 seeded contacts
    that stay stuck, with and without an onset inside the last step."""
    for k in range(200):
        c = random_contact(RNG, fresh=k % 2 == 1)
        want = np.array(pair_impulses(*c.values()))
        got = np.array(coupled_impulses(*c.values(), 0.0, 1e9))
        assert np.all(np.abs(got - want) <= 1e-8 * np.maximum(np.abs(want), 1e-30))


def test_undamped_coupled_flow_keeps_the_pairs_energy():
    """No dashpots, no other forces: ``1/2 u^T W^-1 u + 1/2 x^T S x`` is constant along the
    exact flow, whatever the cross term (W positive definite) and the step."""
    for _ in range(50):
        k_nn, k_tt = RNG.uniform(2e-3, 2e-2, 2)
        k_nt = RNG.uniform(-0.9, 0.9) * math.sqrt(k_nn * k_tt)
        w = np.array([[k_nn, -k_nt], [-k_nt, k_tt]])
        s = np.diag(RNG.uniform(1e7, 1e8, 2))
        x, u = RNG.normal(0, 1e-3, 2), RNG.normal(0, 0.5, 2)
        h = RNG.uniform(1e-5, 3e-3)
        y = np.array(
            coupled_flow(*x, *u, h, s[0, 0], s[1, 1], 0.0, 0.0, k_nn, -k_nt, k_tt, 0.0, 0.0)
        )
        before = 0.5 * u @ np.linalg.solve(w, u) + 0.5 * x @ s @ x
        after = 0.5 * y[2:] @ np.linalg.solve(w, y[2:]) + 0.5 * y[:2] @ s @ y[:2]
        assert after == pytest.approx(before, rel=1e-10)


def test_sliding_moves_the_normal_at_the_reduced_inverse_mass():
    """Sliding (mu small), the tangential impulse the cap gives is mu times the normal one,
    and the normal is the 1D solution at ``K_nn - sign mu K_nt``: with ``k_nt`` = 0 it is
    ``pair_impulses``' normal exactly."""
    c = random_contact(np.random.default_rng(3))
    c["slip"] = 0.4
    got = coupled_impulses(*c.values(), 0.0, 1e-3)
    want = pair_impulses(*c.values())
    assert abs(got[3]) > 1e-3 * got[0] * c["h"]  # it slides
    assert got[0:3] == want[0:3]


@pytest.fixture(scope="module")
def kernel(taichi_runtime):
    n = 400
    real = ti.f64 if taichi_runtime[1] == "f64" else ti.f32
    ins = ti.field(real, shape=(n, 18))
    flags = ti.field(ti.i32, shape=n)
    outs = ti.field(real, shape=(n, 8))

    @ti.kernel
    def run():
        for i in range(n):
            r = ti.Vector([ins[i, k] for k in ti.static(range(18))])
            out = coupled_impulses_ti(
                r[0], r[1], r[2], r[3], flags[i] == 1, r[4], r[5], ti.Vector([r[6], r[7]]),
                r[8], r[9], r[10], r[11], r[12], r[13], r[14], r[15], r[16],
            )  # fmt: skip
            for k in ti.static(range(8)):
                outs[i, k] = out[k]

    return ins, flags, outs, run, taichi_runtime[1]


def test_the_taichi_twin_equals_numpy_on_random_contacts(kernel):
    """Seeded random contacts: pushing or flying apart inside the step (handed to the 1D
    solves), new or not, stuck or sliding, the cross term up to 0.9 of its bound: the
    kernel's outputs are the NumPy twin's to round-off (in float64 within 1e-9 of the terms
    they are made of; a float32 run computes in float32: 99 % within 1e-5, all within
    1e-3)."""
    ins, flags, outs, run, precision = kernel
    n = ins.shape[0]
    rows, fresh = np.empty((n, 18)), np.zeros(n, dtype=np.int32)
    for i in range(n):
        c = random_contact(RNG, fresh=i % 3 == 0, pushing=i % 4 != 0)
        k_nt = RNG.uniform(-0.9, 0.9) * math.sqrt(c["inv_n"] * c["inv_t"])
        mu = RNG.choice([1e-3, 0.5, 1e9])
        fresh[i] = c["fresh"]
        f = c["last_force"]
        v = [c[k] for k in NAMES if k not in ("fresh", "last_force")]
        # depth approach slip xi | changes | last force | h k_n c_n k_t c_t inv_n inv_t
        rows[i] = (*v[0:4], *v[4:6], f[0], f[1], *v[6:], k_nt, mu, 0.0)
    ins.from_numpy(rows)
    flags.from_numpy(fresh)
    rows = ins.to_numpy().astype(np.float64)  # as the kernel got them
    run()
    got = outs.to_numpy()
    want = np.array(
        [
            coupled_impulses(*r[0:4], bool(fl), *r[4:6], (r[6], r[7]), *r[8:15], r[15], r[16])
            for r, fl in zip(rows, fresh)
        ]
    )
    # Each output against the size of the terms it is made of (as test_contact_step's): the
    # other forces' acceleration, the speeds and places of the step, and the impulses m
    # times a change of speed (P, mean forces P / h) or of place (Q).
    depth, appr, slip, xi, h = rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3], rows[:, 8]
    inv = np.minimum(rows[:, 13], rows[:, 14])
    big = np.maximum(rows[:, 13], rows[:, 14])
    acc = (np.abs(rows[:, 4]) + np.abs(rows[:, 5])) / h + big * (
        np.abs(rows[:, 6]) + np.abs(rows[:, 7])
    )
    place = np.abs(depth) + np.abs(xi) + (np.abs(appr) + np.abs(slip)) * h + acc * h * h
    speed = np.abs(appr) + np.abs(slip) + acc * h + place / h
    scale = np.stack(
        [speed / (h * inv), speed / (h * inv), place / inv, speed / inv, place / inv, place,
         acc, acc],
        axis=1,
    )  # fmt: skip
    off = np.abs(got - want) <= {"f64": 1e-9, "f32": 1e-5}[precision] * scale
    if precision == "f64":
        assert np.all(off), np.argwhere(~off)[:5]
    else:
        assert off.all(axis=1).mean() >= 0.99
        assert np.all(np.abs(got - want) <= 1e-3 * scale)


def test_the_taichi_flow_equals_numpy_over_many_pieces(taichi_runtime):
    """``flow_times_ti`` against its NumPy twin on seeded random matrices of the flow's block
    form with norms from far below a piece's (2) to tens of pieces (the contacts above reach two
    pieces only now and then): the loop over pieces and the series' stop, where a step far
    past the default one takes them. Float64: within 1e-12 of ``max|exp(B)| max|z|``; a
    float32 run computes in float32: within 1e-4 of it."""
    n = 200
    real = ti.f64 if taichi_runtime[1] == "f64" else ti.f32
    ins = ti.field(real, shape=(n, 13))
    outs = ti.field(real, shape=(n, 4))

    @ti.kernel
    def run():
        for i in range(n):
            r = ti.Vector([ins[i, k] for k in ti.static(range(13))])
            y = flow_times_ti(
                r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8], r[9], r[10], r[11], r[12]
            )
            for k in ti.static(range(4)):
                outs[i, k] = y[k]

    rng = np.random.default_rng(20261202)
    scale = np.exp(rng.uniform(np.log(0.01), np.log(30.0), n))
    rows = np.concatenate(
        [rng.uniform(0.1, 1.0, (n, 1)), rng.normal(size=(n, 8)), rng.normal(size=(n, 4))], axis=1
    )
    rows[:, :9] *= scale[:, None]
    ins.from_numpy(rows)
    rows = ins.to_numpy().astype(np.float64)  # as the kernel got them
    run()
    got = outs.to_numpy().astype(np.float64)
    want = np.array([flow_times(*r[:9], r[9:]) for r in rows])
    size = np.array(
        [np.max(np.abs(expm(np.block([[np.zeros((2, 2)), r[0] * np.eye(2)],
                                      [r[1:5].reshape(2, 2), r[5:9].reshape(2, 2)]]))))
         for r in rows]
    ) * np.max(np.abs(rows[:, 9:]), axis=1)  # fmt: skip
    norms = np.max(
        [rows[:, 0], np.abs(rows[:, [1, 2, 5, 6]]).sum(1), np.abs(rows[:, [3, 4, 7, 8]]).sum(1)],
        axis=0,
    )
    assert np.sum(norms > 2.0) >= n // 3 and norms.max() > 40.0  # the inputs take many pieces
    tol = {"f64": 1e-12, "f32": 1e-4}[taichi_runtime[1]]
    assert np.all(np.abs(got - want) <= tol * size[:, None])
