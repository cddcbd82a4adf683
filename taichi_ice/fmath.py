"""float64 ``exp`` and ``log`` for backends whose shading language has none (Vulkan, Metal).

SPIR-V's extended instruction set (GLSL.std.450) defines ``Exp``, ``Log``, ``Sin``, ``Cos``
and the rest for 16- and 32-bit floats only, so Taichi's SPIR-V code generator stops at the
first ``ti.exp`` of a float64 value ("Instruction Exp does not 64bits operation"). The
rate-and-state law needs both (``friction.steady_theta``, ``friction.evolve_theta``,
``slip.sliding_rate``). These are fdlibm's ``e_exp.c`` and ``e_log.c`` (Sun Microsystems
1993, as in glibc and musl): the argument split by its exponent bits (integer operations,
which SPIR-V has for 64 bits), a rational or polynomial kernel on the rest, and the exponent
put back. Within 1 ulp of NumPy's (``tests/test_fmath.py``: 2e5 seeded arguments over the
ranges the laws use and beyond).

``exp_ti``/``log_ti`` are the Taichi functions; ``exp``/``log`` their NumPy twins, step for
step, so the two agree bit for bit (on the CPU and CUDA; a SPIR-V driver may fuse their
multiply-adds, which moves log by an ulp in 2 % of arguments on lavapipe). Kernels call
``exp_any``/``log_any``: the backend's own ``ti.exp``/``ti.log`` wherever it has them (CPU
and CUDA: the results there stay bit for bit what they were; float32 everywhere), these
for a float64 argument where it does not (Vulkan, Metal). The
rotation's ``cos`` and ``sin`` are fdlibm's already (``geometry.rotation_ti``).

Special cases as the laws meet them: ``log`` of 0 is ``-inf``, of a negative number or NaN
NaN, of ``inf`` ``inf``; ``exp`` overflows to ``inf`` above 709.78 and underflows to 0 below
-745.13. Subnormal arguments of ``log`` are scaled by 2^54 first.
"""

from __future__ import annotations

import numpy as np
import taichi as ti

from . import backend

# e_log.c
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_LG = (
    6.666666666666735130e-01,
    3.999999999940941908e-01,
    2.857142874366239149e-01,
    2.222219843214978396e-01,
    1.818357216161805012e-01,
    1.531383769920937332e-01,
    1.479819860511658591e-01,
)
_TWO54 = 1.80143985094819840000e16
# e_exp.c
_O_THRESHOLD = 7.09782712893383973096e02
_U_THRESHOLD = -7.45133219101941108420e02
_INV_LN2 = 1.44269504088896338700e00
_P = (
    1.66666666666666019037e-01,
    -2.77777777770155933842e-03,
    6.61375632143793436117e-05,
    -1.65339022054652515390e-06,
    4.13813679705723846039e-08,
)
_TWO_M1000 = 9.33263618503218878990e-302  # 2^-1000


# ---------------------------------------------------------------------------------------------
# NumPy twins
# ---------------------------------------------------------------------------------------------


def _bits(x: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=np.float64).view(np.int64)


def _float(bits: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(bits, dtype=np.int64).view(np.float64)


def log(x) -> np.ndarray:
    """Natural logarithm by fdlibm's method (the NumPy twin of :func:`log_ti`)."""
    x = np.array(x, dtype=np.float64, copy=True).reshape(-1)
    shape = np.shape(x)
    k = np.zeros(shape, dtype=np.int64)
    sub = (x > 0.0) & (x < 2.2250738585072014e-308)
    x = np.where(sub, x * _TWO54, x)
    k = np.where(sub, -54, k)
    hx = (_bits(x) >> 32).astype(np.int64)
    k = k + ((hx >> 20) - 1023)
    hx = hx & 0x000FFFFF
    i = (hx + 0x95F64) & 0x100000
    low = _bits(x) & 0xFFFFFFFF
    xn = _float(((hx | (i ^ 0x3FF00000)) << 32) | low)
    k = k + (i >> 20)
    f = xn - 1.0
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    g1, g2, g3, g4, g5, g6, g7 = _LG
    t1 = w * (g2 + w * (g4 + w * g6))
    t2 = z * (g1 + w * (g3 + w * (g5 + w * g7)))
    r = t2 + t1
    dk = k.astype(np.float64)
    hfsq = 0.5 * f * f
    big = ((hx - 0x6147A) | (0x6B851 - hx)) > 0
    y = np.where(
        big,
        dk * _LN2_HI - ((hfsq - (s * (hfsq + r) + dk * _LN2_LO)) - f),
        dk * _LN2_HI - ((s * (f - r) - dk * _LN2_LO) - f),
    )
    with np.errstate(divide="ignore", invalid="ignore"):
        y = np.where(x == 0.0, -np.inf, y)
        y = np.where((x < 0.0) | np.isnan(x), np.nan, y)
        y = np.where(np.isposinf(x), np.inf, y)
    return y


def exp(x) -> np.ndarray:
    """Exponential by fdlibm's method (the NumPy twin of :func:`exp_ti`)."""
    x = np.array(x, dtype=np.float64, copy=True).reshape(-1)
    half = np.where(x < 0.0, -0.5, 0.5)
    with np.errstate(invalid="ignore"):
        xs = np.where(np.abs(x) < 1e4, x, 0.0)  # huge or NaN: decided below, keep k finite
    k = np.trunc(_INV_LN2 * xs + half)  # as C's (int)
    hi = x - k * _LN2_HI
    lo = k * _LN2_LO
    r = hi - lo
    t = r * r
    p1, p2, p3, p4, p5 = _P
    c = r - t * (p1 + t * (p2 + t * (p3 + t * (p4 + t * p5))))
    y = 1.0 - ((lo - (r * c) / (2.0 - c)) - hi)
    ki = k.astype(np.int64)
    normal = ki >= -1021
    scaled = _float(_bits(y) + (np.where(normal, ki, ki + 1000) << 52))
    out = np.where(normal, scaled, scaled * _TWO_M1000)
    out = np.where(x > _O_THRESHOLD, np.inf, out)
    out = np.where(x < _U_THRESHOLD, 0.0, out)
    return np.where(np.isnan(x), np.nan, out)


# ---------------------------------------------------------------------------------------------
# Taichi
# ---------------------------------------------------------------------------------------------


# Every constant of the Taichi functions is a float64 as written: a bare Python number in a
# kernel takes the run's default float, float32 in a float32 run, where these functions
# still compute in float64 (the twins of float64 data, on Vulkan).
F64 = ti.f64


@ti.func
def log_ti(x_in):
    """Natural logarithm of a float64 by fdlibm's method (twin: :func:`log`)."""
    x = ti.cast(x_in, ti.f64)
    k = ti.cast(0, ti.i64)
    if x > 0.0 and x < F64(2.2250738585072014e-308):
        x = x * F64(_TWO54)
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
    c1, c2, c3, c4, c5, c6, c7 = ti.static(_LG)
    g1, g2, g3, g4, g5, g6, g7 = F64(c1), F64(c2), F64(c3), F64(c4), F64(c5), F64(c6), F64(c7)
    t1 = w * (g2 + w * (g4 + w * g6))
    t2 = z * (g1 + w * (g3 + w * (g5 + w * g7)))
    r = t2 + t1
    dk = ti.cast(k, ti.f64)
    y = F64(0.0)
    if ((hx - 0x6147A) | (0x6B851 - hx)) > 0:
        hfsq = F64(0.5) * f * f
        y = dk * F64(_LN2_HI) - ((hfsq - (s * (hfsq + r) + dk * F64(_LN2_LO))) - f)
    else:
        y = dk * F64(_LN2_HI) - ((s * (f - r) - dk * F64(_LN2_LO)) - f)
    if x == 0.0:
        y = -ti.math.inf
    elif not x >= 0.0:  # negative or NaN
        y = ti.math.nan
    elif x > F64(1.7976931348623157e308):
        y = ti.math.inf
    return y


@ti.func
def exp_ti(x_in):
    """Exponential of a float64 by fdlibm's method (twin: :func:`exp`)."""
    x = ti.cast(x_in, ti.f64)
    half = F64(0.5)
    if x < 0.0:
        half = F64(-0.5)
    xs = x
    if not ti.abs(x) < F64(1e4):  # huge or NaN: decided below, keep k finite
        xs = F64(0.0)
    k = ti.cast(F64(_INV_LN2) * xs + half, ti.i64)  # truncation, as C's (int)
    dk = ti.cast(k, ti.f64)
    hi = x - dk * F64(_LN2_HI)
    lo = dk * F64(_LN2_LO)
    r = hi - lo
    t = r * r
    c1, c2, c3, c4, c5 = ti.static(_P)
    p1, p2, p3, p4, p5 = F64(c1), F64(c2), F64(c3), F64(c4), F64(c5)
    c = r - t * (p1 + t * (p2 + t * (p3 + t * (p4 + t * p5))))
    y = F64(1.0) - ((lo - (r * c) / (F64(2.0) - c)) - hi)
    out = F64(0.0)
    if k >= -1021:
        out = ti.bit_cast(ti.bit_cast(y, ti.i64) + (k << 52), ti.f64)
    else:
        out = ti.bit_cast(ti.bit_cast(y, ti.i64) + ((k + 1000) << 52), ti.f64) * F64(_TWO_M1000)
    if x > F64(_O_THRESHOLD):
        out = ti.math.inf
    elif x < F64(_U_THRESHOLD):
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


__all__ = ["exp", "exp_any", "exp_ti", "log", "log_any", "log_ti"]
