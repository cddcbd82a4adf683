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

``fmath_ti.exp_ti``/``fmath_ti.log_ti`` are the Taichi functions; ``exp``/``log`` here
their NumPy twins, step for step, so the two agree bit for bit (on the CPU and CUDA; a SPIR-V
driver may fuse their multiply-adds, which moves log by an ulp in 2 % of arguments on
lavapipe). Kernels call ``fmath_ti.exp_any``/``fmath_ti.log_any``: the backend's own
``ti.exp``/``ti.log`` wherever it has them (CPU and CUDA: the results there stay bit for bit
what they were; float32 everywhere), these for a float64 argument where it does not (Vulkan,
Metal). The rotation's ``cos`` and ``sin`` are fdlibm's already (``polygon_ti.rotation_ti``).

Special cases as the laws meet them: ``log`` of 0 is ``-inf``, of a negative number or NaN
NaN, of ``inf`` ``inf``; ``exp`` overflows to ``inf`` above 709.78 and underflows to 0 below
-745.13. Subnormal arguments of ``log`` are scaled by 2^54 first.

This module is NumPy only (the constants and the twins); it imports no Taichi.
"""

from __future__ import annotations

import numpy as np

# e_log.c
LN2_HI = 6.93147180369123816490e-01
LN2_LO = 1.90821492927058770002e-10
LOG_COEFFS = (
    6.666666666666735130e-01,
    3.999999999940941908e-01,
    2.857142874366239149e-01,
    2.222219843214978396e-01,
    1.818357216161805012e-01,
    1.531383769920937332e-01,
    1.479819860511658591e-01,
)
TWO54 = 1.80143985094819840000e16
# e_exp.c
O_THRESHOLD = 7.09782712893383973096e02
U_THRESHOLD = -7.45133219101941108420e02
INV_LN2 = 1.44269504088896338700e00
EXP_COEFFS = (
    1.66666666666666019037e-01,
    -2.77777777770155933842e-03,
    6.61375632143793436117e-05,
    -1.65339022054652515390e-06,
    4.13813679705723846039e-08,
)
TWO_M1000 = 9.33263618503218878990e-302  # 2^-1000


# ---------------------------------------------------------------------------------------------
# NumPy twins (the Taichi functions, in the same order, are fmath_ti's)
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
    x = np.where(sub, x * TWO54, x)
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
    g1, g2, g3, g4, g5, g6, g7 = LOG_COEFFS
    t1 = w * (g2 + w * (g4 + w * g6))
    t2 = z * (g1 + w * (g3 + w * (g5 + w * g7)))
    r = t2 + t1
    dk = k.astype(np.float64)
    hfsq = 0.5 * f * f
    big = ((hx - 0x6147A) | (0x6B851 - hx)) > 0
    y = np.where(
        big,
        dk * LN2_HI - ((hfsq - (s * (hfsq + r) + dk * LN2_LO)) - f),
        dk * LN2_HI - ((s * (f - r) - dk * LN2_LO) - f),
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
    k = np.trunc(INV_LN2 * xs + half)  # as C's (int)
    hi = x - k * LN2_HI
    lo = k * LN2_LO
    r = hi - lo
    t = r * r
    p1, p2, p3, p4, p5 = EXP_COEFFS
    c = r - t * (p1 + t * (p2 + t * (p3 + t * (p4 + t * p5))))
    y = 1.0 - ((lo - (r * c) / (2.0 - c)) - hi)
    ki = k.astype(np.int64)
    normal = ki >= -1021
    scaled = _float(_bits(y) + (np.where(normal, ki, ki + 1000) << 52))
    out = np.where(normal, scaled, scaled * TWO_M1000)
    out = np.where(x > O_THRESHOLD, np.inf, out)
    out = np.where(x < U_THRESHOLD, 0.0, out)
    return np.where(np.isnan(x), np.nan, out)


__all__ = [
    "EXP_COEFFS",
    "INV_LN2",
    "LN2_HI",
    "LN2_LO",
    "LOG_COEFFS",
    "O_THRESHOLD",
    "TWO54",
    "TWO_M1000",
    "U_THRESHOLD",
    "exp",
    "log",
]
