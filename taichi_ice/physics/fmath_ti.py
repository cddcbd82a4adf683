"""float64 ``exp`` and ``log`` as Taichi functions, for backends whose shading language has none.

The Taichi twins of ``fmath`` (fdlibm's ``e_exp.c`` and ``e_log.c``; the method, its accuracy
and its special cases are described there), in the same order: ``log_ti`` beside
``fmath.log``, ``exp_ti`` beside ``fmath.exp``. Kernels call ``exp_any``/``log_any``: the
backend's own ``ti.exp``/``ti.log`` wherever it has them (CPU and CUDA: the results there
stay bit for bit what they were; float32 everywhere), these for a float64 argument where it
does not (Vulkan, Metal). The constants are ``fmath``'s; this module holds no NumPy twin.
"""

from __future__ import annotations

import taichi as ti

from .. import backend
from .fmath import (
    EXP_COEFFS,
    INV_LN2,
    LN2_HI,
    LN2_LO,
    LOG_COEFFS,
    O_THRESHOLD,
    TWO54,
    TWO_M1000,
    U_THRESHOLD,
)

# Every constant of the Taichi functions is a float64 as written: a bare Python number in a
# kernel takes the run's default float, float32 in a float32 run, where these functions
# still compute in float64 (the twins of float64 data, on Vulkan).
F64 = ti.f64


@ti.func
def log_ti(x_in):
    """Natural logarithm of a float64 by fdlibm's method (twin: :func:`fmath.log`)."""
    x = ti.cast(x_in, ti.f64)
    k = ti.cast(0, ti.i64)
    if x > 0.0 and x < F64(2.2250738585072014e-308):
        x = x * F64(TWO54)
        k = -54
    bits = ti.bit_cast(x, ti.i64)
    hx = bits >> 32
    k += (hx >> 20) - 1023
    hx = hx & 0x000FFFFF
    i = (hx + 0x95F64) & 0x100000
    xn = ti.bit_cast(((hx | (i ^ 0x3FF00000)) << 32) | (bits & ti.i64(0xFFFFFFFF)), ti.f64)
    k += i >> 20
    f = xn - F64(1.0)
    s = f / (F64(2.0) + f)
    z = s * s
    w = z * z
    c1, c2, c3, c4, c5, c6, c7 = ti.static(LOG_COEFFS)
    g1, g2, g3, g4, g5, g6, g7 = F64(c1), F64(c2), F64(c3), F64(c4), F64(c5), F64(c6), F64(c7)
    t1 = w * (g2 + w * (g4 + w * g6))
    t2 = z * (g1 + w * (g3 + w * (g5 + w * g7)))
    r = t2 + t1
    dk = ti.cast(k, ti.f64)
    y = F64(0.0)
    if ((hx - 0x6147A) | (0x6B851 - hx)) > 0:
        hfsq = F64(0.5) * f * f
        y = dk * F64(LN2_HI) - ((hfsq - (s * (hfsq + r) + dk * F64(LN2_LO))) - f)
    else:
        y = dk * F64(LN2_HI) - ((s * (f - r) - dk * F64(LN2_LO)) - f)
    if x == 0.0:
        y = -ti.math.inf
    elif not x >= 0.0:  # negative or NaN
        y = ti.math.nan
    elif x > F64(1.7976931348623157e308):
        y = ti.math.inf
    return y


@ti.func
def exp_ti(x_in):
    """Exponential of a float64 by fdlibm's method (twin: :func:`fmath.exp`)."""
    x = ti.cast(x_in, ti.f64)
    half = F64(0.5)
    if x < 0.0:
        half = F64(-0.5)
    xs = x
    if not ti.abs(x) < F64(1e4):  # huge or NaN: decided below, keep k finite
        xs = F64(0.0)
    k = ti.cast(F64(INV_LN2) * xs + half, ti.i64)  # truncation, as C's (int)
    dk = ti.cast(k, ti.f64)
    hi = x - dk * F64(LN2_HI)
    lo = dk * F64(LN2_LO)
    r = hi - lo
    t = r * r
    c1, c2, c3, c4, c5 = ti.static(EXP_COEFFS)
    p1, p2, p3, p4, p5 = F64(c1), F64(c2), F64(c3), F64(c4), F64(c5)
    c = r - t * (p1 + t * (p2 + t * (p3 + t * (p4 + t * p5))))
    y = F64(1.0) - ((lo - (r * c) / (F64(2.0) - c)) - hi)
    out = F64(0.0)
    if k >= -1021:
        out = ti.bit_cast(ti.bit_cast(y, ti.i64) + (k << 52), ti.f64)
    else:
        out = ti.bit_cast(ti.bit_cast(y, ti.i64) + ((k + 1000) << 52), ti.f64) * F64(TWO_M1000)
    if x > F64(O_THRESHOLD):
        out = ti.math.inf
    elif x < F64(U_THRESHOLD):
        out = F64(0.0)
    elif not x == x:
        out = ti.math.nan
    return out


@ti.func
def exp_any(x):
    """``exp(x)`` on any backend: its own where it has one (CPU, CUDA, and float32
    everywhere: bit for bit what it was), :func:`exp_ti` for a float64 ``x`` on Vulkan and
    Metal, which have no float64 exp (decided by ``x``'s type, not the run's precision: a
    float32 run computes some things in float64)."""
    y = x
    if ti.static(_portable(x)):
        y = exp_ti(x)
    else:
        y = ti.exp(x)
    return y


@ti.func
def log_any(x):
    """``log(x)`` on any backend, as :func:`exp_any`."""
    y = x
    if ti.static(_portable(x)):
        y = log_ti(x)
    else:
        y = ti.log(x)
    return y


def _portable(x) -> bool:
    """Whether the Taichi expression ``x`` is float64 on a backend without float64 exp and
    log (``backend.SPIRV_ARCHES``): read when a kernel compiles."""
    if backend.actual_arch() not in backend.SPIRV_ARCHES:
        return False
    ptr = getattr(x, "ptr", None)  # a Python number takes the run's precision
    return backend.portable_f64() if ptr is None else ptr.get_rvalue_type() == ti.f64


__all__ = ["exp_any", "exp_ti", "log_any", "log_ti"]
