"""float64 exp and log of our own, for the backends whose shading language has none
(taichi_ice/physics/fmath.py, issue 28): the Taichi functions equal their NumPy twins bit for bit on
seeded arguments, and the twins are within 1 ulp of NumPy's own exp and log (an independent
libm) over the ranges the friction laws use and beyond, special values included."""

from __future__ import annotations

import numpy as np
import pytest
import taichi as ti

from taichi_ice import backend
from taichi_ice.physics import fmath, fmath_ti

RNG = np.random.default_rng(20261126)
ARGS = np.concatenate(
    [
        RNG.uniform(-800.0, 800.0, 20_000),  # exp: both thresholds and past them
        np.exp(RNG.uniform(-745.0, 709.0, 20_000)),  # log: subnormal to huge
        RNG.uniform(0.0, 3.0, 20_000),  # near 1, where log's kernels switch
        RNG.uniform(-1e-6, 1e-6, 2_000),  # exp near 0
        [0.0, -0.0, -1.0, np.inf, -np.inf, np.nan, 5e-324, 1e-310, 2.2250738585072014e-308],
        [1.0, 2.0, 0.5, 709.78, 709.79, -745.13, -745.14, -708.4, -708.3, 1e-20, -1e-20],
    ]
)

SPECIALS = {  # argument: (exp, log)
    0.0: (1.0, -np.inf),
    -1.0: (np.exp(-1.0), np.nan),
    np.inf: (np.inf, np.inf),
    -np.inf: (0.0, np.nan),
    1.0: (np.e, 0.0),
}


@pytest.fixture(scope="module")
def on_taichi(taichi_runtime):
    """The Taichi functions on float64 fields, in a run of either precision: a float32 run
    takes them for float64 data on Vulkan (their constants stay float64 there)."""
    n = ARGS.size
    x, e, lg = (ti.field(ti.f64, n) for _ in range(3))
    x.from_numpy(ARGS)

    @ti.kernel
    def run():
        for i in range(n):
            e[i] = fmath_ti.exp_ti(x[i])
            lg[i] = fmath_ti.log_ti(x[i])

    run()
    return e.to_numpy(), lg.to_numpy()


def same(a, b) -> np.ndarray:
    return (a == b) | (np.isnan(a) & np.isnan(b))


def test_the_taichi_functions_equal_their_numpy_twins_bit_for_bit(on_taichi):
    e, lg = on_taichi
    with np.errstate(all="ignore"):
        equal = np.all(same(e, fmath.exp(ARGS))) and np.all(same(lg, fmath.log(ARGS)))
    if backend.actual_arch() in (*backend.SPIRV_ARCHES, "cuda"):
        # A strict expected failure: measured on lavapipe (Mesa 22.3.6), exp bit for bit and
        # log 1 ulp off the twin in 1,197 of 62,020 arguments; on CUDA (an H100, driver
        # 580.159, 2026-11-26), exp in 479 and log in 195, 1 ulp each, in runs of either
        # precision. Taichi's SPIR-V marks no product NoContraction, so the driver may fuse
        # a * b + c into one rounding, and LLVM's NVPTX contracts them even with Taichi's
        # fast math off; the CPU compiles IEEE as written (backend.init: fast_math=False).
        # The engine calls these only where the device has no float64 exp and log (SPIR-V;
        # CUDA's are libdevice's). The next test holds the device to NumPy.
        assert not equal, f"bit for bit on {backend.actual_arch()} now: drop this xfail"
        pytest.xfail("the device's compiler fused multiply-adds (see the next test)")
    assert equal


def test_the_taichi_functions_are_within_one_ulp_of_numpy_on_the_device(on_taichi):
    """What the kernels rely on, on any arch: the device's exp and log within an ulp of
    NumPy's (and as NumPy at overflow, underflow and the values that are not numbers)."""
    for got, ref in zip(on_taichi, (np.exp, np.log)):
        with np.errstate(all="ignore"):
            want = ref(ARGS)
        normal = np.isfinite(want) & (np.abs(want) >= np.finfo(np.float64).tiny)
        ulps = np.abs(got[normal] - want[normal]) / np.abs(want[normal]) / np.finfo(float).eps
        assert ulps.max() <= 1.0, (ref.__name__, ARGS[normal][np.argmax(ulps)])
        rest = ~normal
        assert np.all(same(got[rest], want[rest]) | (np.abs(got[rest] - want[rest]) < 1e-320))


@pytest.mark.parametrize("name", ["exp", "log"])
def test_the_twins_are_within_one_ulp_of_numpy(name):
    ours, ref = getattr(fmath, name), getattr(np, name)
    with np.errstate(all="ignore"):
        got, want = ours(ARGS), ref(ARGS)
    normal = np.isfinite(want) & (np.abs(want) >= np.finfo(np.float64).tiny)
    # Relative to want, in units of eps (an ulp is at most eps |want|): np.spacing of a
    # value below 1e-292 is subnormal, and Taichi starts a process with subnormals flushed
    # to zero, so the ulp itself cannot be computed there.
    rel = np.abs(got[normal] - want[normal]) / np.abs(want[normal])
    ulps = rel / np.finfo(np.float64).eps
    assert ulps.max() <= 1.0, ARGS[normal][np.argmax(ulps)]
    # Overflow, underflow and the values that are not numbers, as NumPy gives them.
    rest = ~normal
    assert np.all(same(got[rest], want[rest]) | (np.abs(got[rest] - want[rest]) < 1e-320))


@pytest.mark.parametrize(("x", "want"), SPECIALS.items())
def test_special_values(x, want):
    with np.errstate(all="ignore"):
        got = (fmath.exp(x)[0], fmath.log(x)[0])
    for g, w in zip(got, want):
        assert same(np.float64(g), np.float64(w)) or g == pytest.approx(w, rel=1e-16)
