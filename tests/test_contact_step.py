"""A contact's spring-dashpot integrated exactly over a step (taichi_ice/physics/contact_step.py,
issue 30): against the ODE solved by SciPy and the clamped oscillator's collision
(``collision_ode.clamped_oscillator``: independent of the engine), at any step; and the Taichi
twins against the NumPy ones on seeded random contacts."""

# No "from __future__ import annotations": Taichi reads kernel annotations as objects.

import math

import numpy as np
import pytest
import taichi as ti
from scipy.integrate import solve_ivp

from taichi_ice.experiments.validation.collision_ode import clamped_oscillator
from taichi_ice.physics.contact_step import onset, oscillator_step, spring_dashpot
from taichi_ice.physics.contact_step_ti import spring_dashpot_ti

RNG = np.random.default_rng(20261126)

# The face-on collision of the validation study: a 1 m square and a 1 m x 0.8 m block of the
# paper's ice, touching on the block's 0.8 m face.
M_EFF = 276.0 * 220.8 / (276.0 + 220.8)
K = 9.75e7 * 0.8
C = 3.16e4 * 0.8


def collide(h: float, k: float, c: float) -> tuple[float, float]:
    """(duration, restitution) of two bodies closing at 1 m/s, stepped by ``spring_dashpot``
    as the engine steps a contact (``v += P / m``, ``x += h v + Q / m``), the contact found at
    the first step it overlaps and started from its onset inside that step."""
    depth, rate, touching, t = -0.3 * h, 1.0, False, 0.0  # they touch 0.3 steps in
    while True:
        p = q = 0.0
        if depth > 0.0:
            tau = 0.0 if touching else onset(depth, rate, h)
            p, q, _, _, _ = spring_dashpot(depth, rate, h, k, c, 1.0 / M_EFF, 0.0, True, tau)
            touching = True
        else:
            touching = False
        depth += h * rate - q / M_EFF
        rate -= p / M_EFF
        t += h
        if rate < 0.0 and depth < 0.0:
            # Flying apart: when the overlap ended, from the free flight back.
            return t - depth / rate - 0.3 * h, -rate


@pytest.mark.parametrize(
    "damping", [0.0, 1.0, 7.7, 30.0], ids=["elastic", "paper", "critical", "overdamped"]
)
def test_an_isolated_collision_is_exact_at_any_step(damping):
    """The clamped damped oscillator's duration and restitution, to round-off, from a tenth
    of the explicit step's stability limit (2 / w) to three times it, undamped to
    overdamped (z = 0, 0.13, 1.0, 3.9)."""
    c = C * damping
    want_t, want_e = clamped_oscillator(K, c, M_EFF, 1.0)
    limit = 2.0 / math.sqrt(K / M_EFF)
    for ratio in (0.1, 0.37, 1.0, 3.0):
        got_t, got_e = collide(ratio * limit, K, c)
        assert got_e == pytest.approx(want_e, rel=1e-9, abs=1e-12), ratio
        assert got_t == pytest.approx(want_t, rel=1e-9), ratio


def test_a_step_of_the_forced_oscillator_matches_the_ode():
    """``oscillator_step`` from random states, with the pair's other forces (a constant
    acceleration), against SciPy's solution of the same ODE; with the clamp the force stops
    where it would pull and the rest of the step is free flight."""
    compared = 0
    for _ in range(60):
        k = 10.0 ** RNG.uniform(5.0, 9.0)
        inv_m = 10.0 ** RNG.uniform(-4.0, -1.0)
        z = RNG.choice([0.0, 0.05, 0.5, 1.0, 2.5])
        c = 2.0 * z * math.sqrt(k / inv_m)
        w = math.sqrt(k * inv_m)
        h = RNG.uniform(0.05, 2.0) / w
        x0 = RNG.uniform(0.0, 1e-3)
        u0 = RNG.uniform(-1.0, 1.0)
        a = RNG.uniform(-50.0, 50.0)
        clamp = bool(RNG.integers(2))

        def rhs(_t, y, clamp=clamp, k=k, c=c, inv_m=inv_m, a=a):
            f = k * y[0] + c * y[1]
            if clamp:
                f = max(f, 0.0)
            return [y[1], a - inv_m * f]

        if clamp and k * x0 + c * u0 < 0.0:
            continue  # pulling from the start: free flight (the ODE would engage later)
        ref = solve_ivp(rhs, (0.0, h), [x0, u0], method="DOP853", rtol=1e-12, atol=1e-18)
        x1, u1, _ = oscillator_step(x0, u0, h, k, c, inv_m, a, clamp)
        scale_x = abs(x0) + abs(u0) * h + abs(a) * h * h
        scale_u = abs(u0) + abs(a) * h + w * abs(x0)
        if clamp:
            # The step releases for good; the ODE engages again if the force turns back.
            forces = [k * x + c * u for x, u in zip(ref.y[0], ref.y[1], strict=True)]
            if min(forces) < 0.0 < forces[-1]:
                continue
        assert x1 == pytest.approx(ref.y[0, -1], abs=1e-7 * scale_x)
        assert u1 == pytest.approx(ref.y[1, -1], abs=1e-7 * scale_u)
        compared += 1
    assert compared >= 30  # most draws are compared, not passed over


def test_impulses_account_for_the_motion():
    """``P`` and ``Q`` are what the force did: the bodies' motion under the other forces
    alone, less ``P / m`` and ``Q / m``, is the contact's own (exact) motion; and the
    dashpot's part of ``P`` is ``c`` times the depth gained while the force acted."""
    k, inv_m, c, h, a = K, 1.0 / M_EFF, C, 1e-4, 3.0
    x, u = 2e-4, 0.4
    p, q, viscous, x1, u1 = spring_dashpot(x, u, h, k, c, inv_m, a, True)
    assert x + u * h + 0.5 * a * h * h - q * inv_m == pytest.approx(x1, rel=1e-12)
    assert u + a * h - p * inv_m == pytest.approx(u1, rel=1e-12)
    assert viscous == pytest.approx(c * (x1 - x), rel=1e-12)  # the force acted throughout


@pytest.fixture(scope="module")
def kernel(taichi_runtime):
    n = 400
    # The run's float type, as the engine calls it (SPIR-V has no float64 cos and sin: a
    # float32 run on Vulkan computes them in float32).
    real = ti.f64 if taichi_runtime[1] == "f64" else ti.f32
    ins = ti.field(real, shape=(n, 8))
    outs = ti.field(real, shape=(n, 5))

    @ti.kernel
    def run(clamp: ti.template()):
        for i in range(n):
            p, q, v, x1, u1 = spring_dashpot_ti(
                ins[i, 0],
                ins[i, 1],
                ins[i, 2],
                ins[i, 3],
                ins[i, 4],
                ins[i, 5],
                ins[i, 6],
                clamp,
                ins[i, 7],
            )
            outs[i, 0], outs[i, 1], outs[i, 2], outs[i, 3], outs[i, 4] = p, q, v, x1, u1

    return ins, outs, run, taichi_runtime[1]


@pytest.mark.parametrize("clamp", [True, False], ids=["normal", "tangential"])
def test_the_taichi_twin_equals_numpy_on_random_contacts(kernel, clamp):
    """Seeded random contacts, from stuck to flying apart inside the step, onset or not, and
    every damping regime: the kernel's ``(P, Q, P_viscous, x1, u1)`` are the NumPy twin's to
    round-off: in float64 on the CPU bit for bit but where the compiler fuses a multiply-add,
    on Vulkan within 1e-9 of the terms they are differences of. A float32 run computes in
    float32 (the NumPy twin in float64 on the same, rounded, inputs): measured over 4,000
    draws, 99.5-99.98 % of them within 1e-6 of the terms (median 5e-8), all within 3.1e-5
    (CPU and Vulkan); the bounds below are 99 % and 1e-4."""
    ins, outs, run, precision = kernel
    n = ins.shape[0]
    rows = np.empty((n, 8))
    for i in range(n):
        k = 10.0 ** RNG.uniform(5.0, 9.0)
        inv_m = 10.0 ** RNG.uniform(-4.0, -1.0)
        z = RNG.choice([0.0, 0.1, 0.25, 1.0, 3.0])
        h = RNG.uniform(0.05, 3.0) / math.sqrt(k * inv_m)
        x, u = RNG.uniform(-1e-4, 1e-3), RNG.uniform(-1.0, 1.0)
        tau = RNG.choice([0.0, RNG.uniform(0.0, h)])
        rows[i] = (x, u, h, k, 2.0 * z * math.sqrt(k / inv_m), inv_m, RNG.uniform(-20, 20), tau)
    ins.from_numpy(rows)
    rows = ins.to_numpy().astype(np.float64)  # as the kernel got them
    run(clamp)
    got = outs.to_numpy()
    want = np.array([spring_dashpot(*r[:7], clamp, r[7]) for r in rows])
    # Round-off is measured against the size of what each output is a difference of (P is
    # m times a change of speed, near 0 for a contact that flies; Q m times one of place).
    x, u, h, _k, c, inv_m, a = (rows[:, i] for i in range(7))
    place = np.abs(x) + np.abs(u) * h + np.abs(a) * h * h
    speed = np.abs(u) + np.abs(a) * h + place / h
    scale = np.stack([speed / inv_m, place / inv_m, c * place, place, speed], axis=1)
    off = np.abs(got - want) <= {"f64": 1e-9, "f32": 1e-6}[precision] * scale
    if precision == "f64":
        assert np.all(off)
    else:
        assert off.all(axis=1).mean() >= 0.99
        assert np.all(np.abs(got - want) <= 1e-4 * scale)
