"""Friction laws for one sliding interface: Coulomb and rate-and-state with memory.

The rate-and-state law of Lishman et al. (2013), doi:10.1016/j.coldregions.2013.03.004:

    mu(t)     = mu0 + theta + A x,                x = ln(max(V, V*) / V*)
    dtheta/dt = -(theta + B x) / t_c

with V the slip rate (m/s) and theta the dimensionless state. A new interface starts in
equilibrium, ``theta = -B x``; mu is clamped at 0.

The law lives here twice, and the two are held against each other in the tests:

- as Taichi functions (``slip_log``, ``rate_state_mu``, ``theta_equilibrium``,
  ``theta_step``) with no field access, which the batched driver ``respond_batch`` and every
  DEM contact call inside their kernels;
- as NumPy twins (same names with ``_np``) that ``Coulomb.respond`` and ``RateState.respond``
  use for one interface.

Time integrators of the state equation over a step ``dt`` (``h = dt / t_c``), each written
with the slip rate taken linear between samples:

- ``exponential`` (default): ``theta <- theta_ss + (theta - theta_ss) exp(-h)`` with
  ``theta_ss = -B x`` at the half step. Exact for constant V, second order otherwise, and
  stable at any step (the state equation is linear in theta).
- ``euler``: explicit, x at the step start; first order, unstable for ``dt > 2 t_c``.
- ``implicit``: backward Euler, x at the step end; first order, stable at any step.
- ``rk4``: classic Runge-Kutta with x at start, middle (twice) and end; fourth order for a
  smooth x(t), unstable for ``dt > 2.785293563... t_c``.
"""

# No ``from __future__ import annotations``: Taichi reads the annotations of its functions
# and kernels (ti.template(), ti.types.ndarray) as objects, not strings.
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import taichi as ti

from . import backend
from .errors import StabilityError

__all__ = [
    "EULER_STABILITY_LIMIT",
    "METHODS",
    "METHOD_CODES",
    "METHOD_EULER",
    "METHOD_EXPONENTIAL",
    "METHOD_IMPLICIT",
    "METHOD_RK4",
    "RK4_STABILITY_LIMIT",
    "Coulomb",
    "RateState",
    "method_code",
    "rate_state_mu",
    "rate_state_mu_np",
    "respond_batch",
    "respond_batch_np",
    "respond_batch_np_unchecked",
    "respond_batch_unchecked",
    "slip_log",
    "slip_log_np",
    "stability_limit",
    "theta_equilibrium",
    "theta_equilibrium_np",
    "theta_step",
    "theta_step_np",
]

# Integrator codes, compile-time constants for ``theta_step`` (dispatched with ti.static).
METHOD_EXPONENTIAL = 0
METHOD_EULER = 1
METHOD_IMPLICIT = 2
METHOD_RK4 = 3
METHODS = ("exponential", "euler", "implicit", "rk4")
METHOD_CODES = {name: code for code, name in enumerate(METHODS)}

# Stability limits on h = dt / t_c for d theta/dt = -theta / t_c. Explicit Euler amplifies by
# 1 - h, so |1 - h| <= 1 needs h <= 2. RK4 amplifies by R(-h) = 1 - h + h^2/2 - h^3/6 + h^4/24;
# R(-h) = 1 again at the real root of h^3 - 4 h^2 + 12 h - 24 = 0, h = 2.785293563405...
EULER_STABILITY_LIMIT = 2.0
RK4_STABILITY_LIMIT = 2.785293563405282

# Paper defaults at -10 C (Lishman et al. 2013).
DEFAULT_A = 0.05
DEFAULT_B = 0.112
DEFAULT_MU0 = 0.872
DEFAULT_V_STAR = 1e-5  # m/s
DEFAULT_T_C = 3.0  # s
DEFAULT_COULOMB_MU = 0.5


# --------------------------------------------------------------------------------------------
# The law as Taichi functions: values in, values out, no field access.
# --------------------------------------------------------------------------------------------


@ti.func
def slip_log(v, v_star):
    """x = ln(max(v, v_star) / v_star): the law's rate variable, 0 at and below v_star."""
    return ti.log(ti.max(v, v_star) / v_star)


@ti.func
def rate_state_mu(theta, x, A, mu0):
    """Friction coefficient mu = max(mu0 + theta + A x, 0)."""
    return ti.max(mu0 + theta + A * x, 0.0)


@ti.func
def theta_equilibrium(x, B):
    """Steady-state theta = -B x, the state of a new interface sliding at x."""
    return -B * x


@ti.func
def theta_step(theta, x_start, x_mid, x_end, dt, B, t_c, method: ti.template()):
    """Advance theta over one step of ``dt`` seconds.

    Args:
        theta: state at the step start.
        x_start, x_mid, x_end: ``slip_log`` of the slip rate at the start, the half step and
            the end of the step (the slip rate taken linear over the step).
        dt: step (s). B: state coefficient. t_c: critical slip time (s).
        method: ``METHOD_EXPONENTIAL``, ``METHOD_EULER``, ``METHOD_IMPLICIT`` or
            ``METHOD_RK4`` (a Python int, resolved at compile time).
    """
    h = dt / t_c
    new = theta
    if ti.static(method == METHOD_EXPONENTIAL):
        steady = -B * x_mid
        new = steady + (theta - steady) * ti.exp(-h)
    if ti.static(method == METHOD_EULER):
        new = theta - h * (theta + B * x_start)
    if ti.static(method == METHOD_IMPLICIT):
        # Increment form: in float32, (theta - h B x) / (1 + h) would lose the digits of h
        # that 1 + h rounds away when h is small.
        new = theta - h * (theta + B * x_end) / (1.0 + h)
    if ti.static(method == METHOD_RK4):
        k1 = -(theta + B * x_start)
        k2 = -(theta + 0.5 * h * k1 + B * x_mid)
        k3 = -(theta + 0.5 * h * k2 + B * x_mid)
        k4 = -(theta + h * k3 + B * x_end)
        new = theta + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return new


# --------------------------------------------------------------------------------------------
# NumPy twins of the Taichi functions (same operations in the same order).
# --------------------------------------------------------------------------------------------


def slip_log_np(v, v_star):
    """NumPy twin of ``slip_log``: x = ln(max(v, v_star) / v_star)."""
    return np.log(np.maximum(v, v_star) / v_star)


def rate_state_mu_np(theta, x, A, mu0):
    """NumPy twin of ``rate_state_mu``: max(mu0 + theta + A x, 0)."""
    return np.maximum(mu0 + theta + A * x, 0.0)


def theta_equilibrium_np(x, B):
    """NumPy twin of ``theta_equilibrium``: -B x."""
    return -B * x


def theta_step_np(theta, x_start, x_mid, x_end, dt, B, t_c, method: int):
    """NumPy twin of ``theta_step`` (scalars or broadcastable arrays; method an int code)."""
    h = dt / t_c
    if method == METHOD_EXPONENTIAL:
        steady = -B * x_mid
        return steady + (theta - steady) * np.exp(-h)
    if method == METHOD_EULER:
        return theta - h * (theta + B * x_start)
    if method == METHOD_IMPLICIT:
        return theta - h * (theta + B * x_end) / (1.0 + h)
    if method == METHOD_RK4:
        k1 = -(theta + B * x_start)
        k2 = -(theta + 0.5 * h * k1 + B * x_mid)
        k3 = -(theta + 0.5 * h * k2 + B * x_mid)
        k4 = -(theta + h * k3 + B * x_end)
        return theta + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    raise ValueError(f"unknown method code {method!r}; expected 0..{len(METHODS) - 1}")


# --------------------------------------------------------------------------------------------
# Input checks shared by the NumPy and Taichi paths.
# --------------------------------------------------------------------------------------------


def _method_code(method: str | int) -> int:
    if isinstance(method, str) and method in METHOD_CODES:
        return METHOD_CODES[method]
    if isinstance(method, int) and not isinstance(method, bool) and 0 <= method < len(METHODS):
        return method
    raise ValueError(f"unknown method {method!r}; choose one of {METHODS}")


def method_code(method: str | int) -> int:
    """The ``METHOD_*`` code of a method name (a valid code passes through).

    Raises:
        ValueError: an unknown method, with the list of known ones.
    """
    return _method_code(method)


def stability_limit(method: str | int) -> float:
    """Largest stable ``dt / t_c`` of a method (``inf`` for exponential and implicit)."""
    code = _method_code(method)
    if code == METHOD_EULER:
        return EULER_STABILITY_LIMIT
    if code == METHOD_RK4:
        return RK4_STABILITY_LIMIT
    return math.inf


def _check_stability(method: int, dt_max: float, t_c_min: float) -> None:
    limit = stability_limit(method)
    if dt_max > limit * t_c_min:
        name = {METHOD_EULER: "explicit Euler", METHOD_RK4: "RK4"}[method]
        raise StabilityError(
            f"{name} is unstable for a time step above {limit:.10g} t_c = "
            f"{limit * t_c_min:.6g} s (t_c = {t_c_min:g} s); the largest step here is "
            f"{dt_max:.6g} s. Use smaller steps, method='exponential' or 'implicit' (stable "
            "at any step), or check_stability=False to integrate it anyway."
        )


def _check_param(name: str, value: Any, *, positive: bool = False) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value}")
    if positive and value <= 0.0:
        raise ValueError(f"{name} must be > 0, got {value}")
    if not positive and value < 0.0:
        raise ValueError(f"{name} must be >= 0, got {value}")
    return value


def _first_bad(mask: np.ndarray) -> tuple[int, ...]:
    return tuple(int(i) for i in np.argwhere(mask)[0])


def _check_times(t: Any) -> np.ndarray:
    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1 or t.size == 0:
        raise ValueError(f"t must be a non-empty 1-D array of times (s), got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        (i,) = _first_bad(~np.isfinite(t))
        raise ValueError(f"t must be finite; t[{i}] = {t[i]}")
    steps = np.diff(t)
    if np.any(steps <= 0.0):
        i = int(np.argmax(steps <= 0.0))
        raise ValueError(
            f"t must be strictly increasing; t[{i + 1}] = {t[i + 1]!r} does not come after "
            f"t[{i}] = {t[i]!r}"
        )
    return t


def _check_rates(v: Any, t: np.ndarray, ndims: Sequence[int]) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    if v.ndim not in ndims or v.shape[-1] != t.shape[0]:
        want = " or ".join({1: "(T,)", 2: "(N, T)"}[d] for d in ndims)
        raise ValueError(
            f"v must have shape {want} with T = len(t) = {t.shape[0]}; got shape {v.shape}"
        )
    if np.any(np.isnan(v)):
        raise ValueError(f"v must not be NaN; v{list(_first_bad(np.isnan(v)))} is NaN")
    if np.any(~np.isfinite(v)):
        raise ValueError(f"v must be finite; v{list(_first_bad(~np.isfinite(v)))} is infinite")
    if np.any(v < 0.0):
        idx = _first_bad(v < 0.0)
        raise ValueError(f"v is a slip rate and must be >= 0 (m/s); v{list(idx)} = {v[idx]!r}")
    return v


# --------------------------------------------------------------------------------------------
# The laws.
# --------------------------------------------------------------------------------------------


class Coulomb:
    """Amontons-Coulomb friction: mu constant, no memory.

    Args:
        mu: friction coefficient (dimensionless, >= 0).
    """

    name = "coulomb"

    def __init__(self, mu: float = DEFAULT_COULOMB_MU) -> None:
        self.mu = _check_param("mu", mu)

    @property
    def params(self) -> tuple[float]:
        """(mu,)."""
        return (self.mu,)

    def to_dict(self) -> dict[str, Any]:
        """Law name and parameters, flat, for HDF5 attributes and JSON."""
        return {"law": self.name, "mu": self.mu}

    def steady_state(self, v: Any) -> np.ndarray:
        """mu at slip rates ``v`` (m/s, any shape): the constant mu."""
        v = np.asarray(v, dtype=np.float64)
        if np.any(np.isnan(v)) or np.any(v < 0.0):
            raise ValueError("v is a slip rate and must be >= 0 (m/s) and not NaN")
        return np.full(v.shape, self.mu)

    def respond(self, t: Any, v: Any, method: str | None = None, **_: Any) -> np.ndarray:
        """mu at every time of a slip-rate history (constant); checks the input like RateState."""
        t = _check_times(t)
        v = _check_rates(v, t, (1,))
        if method is not None:
            _method_code(method)
        return np.full(t.shape, self.mu)

    def __repr__(self) -> str:
        return f"Coulomb(mu={self.mu!r})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Coulomb) and other.mu == self.mu

    def __hash__(self) -> int:
        return hash((self.name, self.mu))


class RateState:
    """Rate-and-state friction with memory (Lishman et al. 2013, eqs. 2a-b).

        mu        = max(mu0 + theta + A x, 0),      x = ln(max(V, v_star) / v_star)
        dtheta/dt = -(theta + B x) / t_c

    A new sliding interface starts in equilibrium, ``theta = -B x``, so at constant V the
    friction is ``mu_ss = mu0 + (A - B) x`` (velocity weakening since A < B).

    Below ``v_star`` the paper uses ``mu = mu0``. Here ``x`` is taken as
    ``ln(max(V, v_star) / v_star)`` in both equations, so below ``v_star`` the rate term is
    0 and theta relaxes toward 0 (the equilibrium at ``v_star``) with time constant ``t_c``.
    Hence an interface that starts or rests below ``v_star`` has ``theta = 0`` and exactly
    ``mu = mu0``; after sliding slows below ``v_star``, mu returns to ``mu0`` as theta
    decays; and mu is a continuous function of (V, theta) everywhere.

    mu is clamped at 0: right after a fast deceleration from above ``v_star exp(mu0 / B)``
    (about 2.4 cm/s) the unclamped law would be negative.

    Args:
        A: direct (rate) coefficient, >= 0.
        B: state coefficient, >= 0.
        mu0: reference friction at ``v_star``, >= 0.
        v_star: reference slip rate (m/s), > 0.
        t_c: critical slip time (s), > 0.
        method: default integrator of ``respond``, one of ``RateState.methods``.

    Raises:
        ValueError: a parameter that is NaN, infinite, negative, or zero where it must be
            positive (``v_star``, ``t_c``), or an unknown method.
    """

    name = "rate-state"
    methods = METHODS

    def __init__(
        self,
        A: float = DEFAULT_A,
        B: float = DEFAULT_B,
        mu0: float = DEFAULT_MU0,
        v_star: float = DEFAULT_V_STAR,
        t_c: float = DEFAULT_T_C,
        method: str = "exponential",
    ) -> None:
        self.A = _check_param("A", A)
        self.B = _check_param("B", B)
        self.mu0 = _check_param("mu0", mu0)
        self.v_star = _check_param("v_star", v_star, positive=True)
        self.t_c = _check_param("t_c", t_c, positive=True)
        _method_code(method)
        if not isinstance(method, str):
            raise ValueError(f"method must be a name, one of {METHODS}; got {method!r}")
        self.method = method

    @property
    def params(self) -> tuple[float, float, float, float, float]:
        """(A, B, mu0, v_star, t_c): the order of a row of ``respond_batch`` parameters."""
        return (self.A, self.B, self.mu0, self.v_star, self.t_c)

    def to_dict(self) -> dict[str, Any]:
        """Law name, parameters and default method, flat, for HDF5 attributes and JSON."""
        return {
            "law": self.name,
            "A": self.A,
            "B": self.B,
            "mu0": self.mu0,
            "v_star": self.v_star,
            "t_c": self.t_c,
            "method": self.method,
        }

    def slip_log(self, v: Any) -> np.ndarray:
        """x = ln(max(v, v_star) / v_star) for slip rates ``v`` (m/s, any shape)."""
        return slip_log_np(np.asarray(v, dtype=np.float64), self.v_star)

    def steady_state(self, v: Any) -> np.ndarray:
        """Steady-state friction ``max(mu0 + (A - B) x, 0)`` at slip rates ``v`` (m/s).

        Args:
            v: slip rates (m/s), any shape, >= 0.

        Returns:
            mu_ss, same shape as ``v``.
        """
        v = np.asarray(v, dtype=np.float64)
        if np.any(np.isnan(v)):
            raise ValueError("v must not be NaN")
        if np.any(v < 0.0):
            raise ValueError(f"v is a slip rate and must be >= 0 (m/s); min(v) = {v.min()!r}")
        x = slip_log_np(v, self.v_star)
        return rate_state_mu_np(theta_equilibrium_np(x, self.B), x, self.A, self.mu0)

    def respond(
        self,
        t: Any,
        v: Any,
        method: str | None = None,
        *,
        check_stability: bool = True,
        return_theta: bool = False,
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Friction of one interface under a slip-rate history (NumPy reference path).

        The slip rate is taken linear between samples; the interface starts in equilibrium
        at ``v[0]``.

        Args:
            t: ``(T,)`` strictly increasing times (s); steps may vary.
            v: ``(T,)`` slip rates (m/s) at those times, >= 0.
            method: integrator, one of ``RateState.methods``; default ``self.method``.
            check_stability: refuse (``StabilityError``) a step above the method's stability
                limit (explicit Euler: 2 t_c; RK4: 2.785... t_c). Pass False to integrate
                it anyway, e.g. for a stability chart.
            return_theta: also return the state.

        Returns:
            ``(T,)`` mu at every time; with ``return_theta``, ``(mu, theta)``.

        Raises:
            ValueError: t not strictly increasing or not finite, v negative or NaN, shapes
                that differ, unknown method.
            StabilityError: a step above the stability limit (with ``check_stability``).
        """
        code = _method_code(self.method if method is None else method)
        t = _check_times(t)
        v = _check_rates(v, t, (1,))
        if check_stability and t.size > 1:
            _check_stability(code, float(np.max(np.diff(t))), self.t_c)
        A, B, mu0, v_star, t_c = self.params
        x = slip_log_np(v, v_star)
        x_mid = slip_log_np(0.5 * (v[:-1] + v[1:]), v_star)
        dt = np.diff(t)
        theta = np.empty_like(x)
        theta[0] = theta_equilibrium_np(x[0], B)
        # Plain floats: one interface is a sequential loop, and NumPy scalars cost more.
        xs, xm, dts = x.tolist(), x_mid.tolist(), dt.tolist()
        th = float(theta[0])
        with np.errstate(over="ignore", invalid="ignore"):
            for n in range(t.size - 1):
                th = float(theta_step_np(th, xs[n], xm[n], xs[n + 1], dts[n], B, t_c, code))
                theta[n + 1] = th
            mu = rate_state_mu_np(theta, x, A, mu0)
        return (mu, theta) if return_theta else mu

    def __repr__(self) -> str:
        return (
            f"RateState(A={self.A!r}, B={self.B!r}, mu0={self.mu0!r}, v_star={self.v_star!r}, "
            f"t_c={self.t_c!r}, method={self.method!r})"
        )

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, RateState)
            and other.params == self.params
            and other.method == self.method
        )

    def __hash__(self) -> int:
        return hash((self.name, *self.params, self.method))


# --------------------------------------------------------------------------------------------
# Batched Taichi driver: many independent interfaces at once.
# --------------------------------------------------------------------------------------------


@ti.kernel
def _respond_kernel(
    t: ti.types.ndarray(ndim=1),
    v: ti.types.ndarray(ndim=2),
    params: ti.types.ndarray(ndim=2),
    mu_out: ti.types.ndarray(ndim=2),
    theta_out: ti.types.ndarray(ndim=2),
    method: ti.template(),
    with_theta: ti.template(),
):
    # Model: params (N or 1, 5) rows (A, B, mu0, v_star, t_c); t (T,) times, s.
    # Data in: v (N or 1, T) slip rates, m/s; a single row is shared by every interface.
    # Data out: mu_out (N, T); theta_out (N, T) when with_theta, else unused.
    for i in range(mu_out.shape[0]):  # parallel over interfaces, sequential in time
        iv = i % v.shape[0]
        ip = i % params.shape[0]
        A = params[ip, 0]
        B = params[ip, 1]
        mu0 = params[ip, 2]
        v_star = params[ip, 3]
        t_c = params[ip, 4]
        x = slip_log(v[iv, 0], v_star)
        theta = theta_equilibrium(x, B)
        mu_out[i, 0] = rate_state_mu(theta, x, A, mu0)
        if ti.static(with_theta):
            theta_out[i, 0] = theta
        for n in range(1, mu_out.shape[1]):
            v_start = v[iv, n - 1]
            v_end = v[iv, n]
            x_mid = slip_log(0.5 * (v_start + v_end), v_star)
            x_end = slip_log(v_end, v_star)
            theta = theta_step(theta, x, x_mid, x_end, t[n] - t[n - 1], B, t_c, method)
            x = x_end
            mu_out[i, n] = rate_state_mu(theta, x, A, mu0)
            if ti.static(with_theta):
                theta_out[i, n] = theta


def _batch_params(params: Any) -> np.ndarray:
    if params is None:
        params = RateState()
    if isinstance(params, RateState):
        return np.asarray([params.params], dtype=np.float64)
    if isinstance(params, Coulomb):
        raise ValueError("respond_batch integrates rate-and-state laws; Coulomb mu is constant")
    p = np.asarray(params, dtype=np.float64)
    if p.ndim == 1:
        p = p[None, :]
    if p.ndim != 2 or p.shape[1] != 5:
        raise ValueError(
            f"params must be a RateState, a row (A, B, mu0, v_star, t_c) or an (N, 5) array; "
            f"got shape {np.shape(params)}"
        )
    names = ("A", "B", "mu0", "v_star", "t_c")
    for j, name in enumerate(names):
        col = p[:, j]
        bad = ~np.isfinite(col) | ((col <= 0.0) if name in ("v_star", "t_c") else (col < 0.0))
        if np.any(bad):
            i = int(np.argmax(bad))
            rule = "> 0" if name in ("v_star", "t_c") else ">= 0"
            raise ValueError(f"params[{i}, {j}] ({name}) must be finite and {rule}; got {col[i]}")
    return p


def _prepare_batch(
    t: Any, v: Any, params: Any, method: str | int, check_stability: bool
) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    code = _method_code(method)
    t = _check_times(t)
    v = _check_rates(v, t, (1, 2))
    v = v[None, :] if v.ndim == 1 else v
    p = _batch_params(params)
    if v.shape[0] != p.shape[0] and 1 not in (v.shape[0], p.shape[0]):
        raise ValueError(
            f"v has {v.shape[0]} interfaces (rows) but params has {p.shape[0]}; "
            "they must match, or one of them must be a single row"
        )
    if check_stability and t.size > 1:
        _check_stability(code, float(np.max(np.diff(t))), float(np.min(p[:, 4])))
    return code, t, v, p


def respond_batch(
    t: Any,
    v: Any,
    params: Any = None,
    method: str = "exponential",
    *,
    check_stability: bool = True,
    return_theta: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Friction of many independent interfaces at once, in one Taichi kernel.

    Each interface follows its own slip-rate history (or a shared one) with its own
    rate-and-state parameters (or shared ones), exactly as ``RateState.respond`` does for
    one: slip rate linear between samples, equilibrium start at ``v[:, 0]``. The kernel is
    parallel over interfaces and sequential in time; it compiles once per method and
    precision and not per call or shape.

    Starts Taichi (CPU, float64) if it is not running; otherwise runs on the running arch
    and in its precision (inputs are cast to it, outputs come back in it). Output memory is
    ``N T`` reals (8 bytes each in float64), twice that with ``return_theta``.

    Args:
        t: ``(T,)`` strictly increasing times (s), shared by every interface.
        v: ``(N, T)`` slip rates (m/s, >= 0), or ``(T,)`` shared by every interface.
        params: a ``RateState`` (default: the paper's), a row ``(A, B, mu0, v_star, t_c)``,
            or an ``(N, 5)`` array of such rows, one per interface.
        method: integrator, one of ``RateState.methods``.
        check_stability: refuse a step above the method's stability limit for the
            smallest ``t_c`` (``StabilityError``); False integrates it anyway.
        return_theta: also return the state.

    Returns:
        ``(N, T)`` mu (``N`` from ``v`` or ``params``, whichever has more rows); with
        ``return_theta``, ``(mu, theta)``.

    Raises:
        ValueError: bad times, rates or parameters, or ``v`` and ``params`` row counts that
            differ (other than 1).
        StabilityError: a step above the stability limit (with ``check_stability``).
    """
    code, t, v, p = _prepare_batch(t, v, params, method, check_stability)
    if backend.current() is None:
        backend.init("cpu", "f64")
    dtype = backend.real_dtype(backend.current()[1])
    n = max(v.shape[0], p.shape[0])
    mu = np.empty((n, t.size), dtype=dtype)
    theta = np.empty((n, t.size), dtype=dtype) if return_theta else None
    respond_batch_unchecked(
        np.ascontiguousarray(t, dtype=dtype),
        np.ascontiguousarray(v, dtype=dtype),
        np.ascontiguousarray(p, dtype=dtype),
        code,
        mu,
        theta,
    )
    return (mu, theta) if return_theta else mu


def respond_batch_unchecked(
    t: np.ndarray,
    v: np.ndarray,
    params: np.ndarray,
    method: int,
    mu_out: np.ndarray,
    theta_out: np.ndarray | None = None,
) -> None:
    """Run the batch kernel on prepared arrays: no checks, no copies, no allocation.

    For benchmarks and callers that reuse buffers; ``respond_batch`` is the checked entry.
    Taichi must be running, and every array must be C-contiguous in its precision.

    Args:
        t: ``(T,)`` times (s). v: ``(N or 1, T)`` slip rates (m/s).
        params: ``(N or 1, 5)`` rows (A, B, mu0, v_star, t_c).
        method: an integer ``METHOD_*`` code.
        mu_out: ``(N, T)`` written with mu. theta_out: ``(N, T)`` written with theta, or None.
    """
    with_theta = theta_out is not None
    theta = theta_out if with_theta else np.empty((1, 1), dtype=mu_out.dtype)
    _respond_kernel(t, v, params, mu_out, theta, method, with_theta)
    ti.sync()


def respond_batch_np(
    t: Any,
    v: Any,
    params: Any = None,
    method: str = "exponential",
    *,
    check_stability: bool = True,
    return_theta: bool = False,
    dtype: Any = np.float64,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """NumPy twin of ``respond_batch``: vectorised over interfaces, a Python loop in time.

    Same arguments, checks and results as ``respond_batch``, plus ``dtype`` (``np.float64``
    or ``np.float32``), the precision of the arithmetic. It is the reference the Taichi
    batch is held against and the NumPy entry of the speed/accuracy study.
    """
    code, t, v, p = _prepare_batch(t, v, params, method, check_stability)
    dtype = np.dtype(dtype)
    if dtype not in (np.float32, np.float64):
        raise ValueError(f"dtype must be float64 or float32, got {dtype}")
    mu, theta = respond_batch_np_unchecked(t, v, p, code, dtype)
    return (mu, theta) if return_theta else mu


def respond_batch_np_unchecked(
    t: np.ndarray, v: np.ndarray, params: np.ndarray, method: int, dtype: Any = np.float64
) -> tuple[np.ndarray, np.ndarray]:
    """The loop of ``respond_batch_np`` without its checks; returns ``(mu, theta)``, (N, T).

    Args as ``respond_batch_unchecked`` (any float arrays; computed in ``dtype``).
    """
    dtype = np.dtype(dtype)
    n = max(v.shape[0], params.shape[0])
    A, B, mu0, v_star, t_c = (np.ascontiguousarray(col, dtype=dtype) for col in params.T)
    # Time-major copies so that every step reads and writes contiguous rows of interfaces.
    v_t = np.ascontiguousarray(v.T, dtype=dtype)
    x = slip_log_np(v_t, v_star)
    x_mid = slip_log_np(dtype.type(0.5) * (v_t[:-1] + v_t[1:]), v_star)
    dt = np.diff(np.asarray(t, dtype=dtype))
    theta = np.empty((t.size, n), dtype=dtype)
    theta[0] = theta_equilibrium_np(x[0], B)
    with np.errstate(over="ignore", invalid="ignore"):
        for i in range(t.size - 1):
            theta[i + 1] = theta_step_np(theta[i], x[i], x_mid[i], x[i + 1], dt[i], B, t_c, method)
        mu = rate_state_mu_np(theta, x, A, mu0)
    mu = np.ascontiguousarray(np.broadcast_to(mu, (t.size, n)).T)
    return mu, np.ascontiguousarray(theta.T)
