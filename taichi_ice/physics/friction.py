"""Friction laws for one sliding interface: Coulomb and rate-and-state with memory.

The rate-and-state law of Lishman et al. (2013), doi:10.1016/j.coldregions.2013.03.004:

    mu(t)     = mu0 + theta + A x,                x = ln(max(V, V*) / V*)
    dtheta/dt = -(theta + B x) / t_c

with V the slip rate (m/s) and theta the dimensionless state. A new interface starts in
equilibrium, ``theta = -B x``; mu is clamped at 0.

A law is a frozen dataclass whose fields are its parameters, each declared once with its
default, unit and meaning (``Law.parameters``): the scene table ``[friction]``, the command
line's ``--friction coulomb:0.5``, the model columns of a batch (``schema``), the label of
its files and its HDF5 attributes are all derived from that declaration.
``friction_parse.parse_law`` and ``friction_parse.law_from_table`` are the one parser of both
written forms.

The law lives here twice, and the two are held against each other in the tests
(``taichi_ice``'s convention for every twin: the plain name is the NumPy reference, the
``_ti`` suffix its Taichi function):

- NumPy: ``slip_log``, ``rate_state_mu``, ``theta_equilibrium``, ``theta_step``, which
  ``Coulomb.respond`` and ``RateState.respond`` use for one interface;
- Taichi: the same names with ``_ti``, with no field access, in ``friction_ti`` (this module
  imports no Taichi), which the batched driver ``batched.respond_batch_ti`` and every DEM
  contact call inside their kernels.

Time integrators of the state equation over a step ``dt`` (``h = dt / t_c``; codes in
``codes.ThetaMethod``), each written with the slip rate taken linear between samples:

- ``exponential`` (default): ``theta <- theta_ss + (theta - theta_ss) exp(-h)`` with
  ``theta_ss = -B x`` at the half step. Exact for constant V, second order otherwise, and
  stable at any step (the state equation is linear in theta).
- ``euler``: explicit, x at the step start; first order, unstable for ``dt > 2 t_c``.
- ``implicit``: backward Euler, x at the step end; first order, stable at any step.
- ``rk4``: classic Runge-Kutta with x at start, middle (twice) and end; fourth order for a
  smooth x(t), unstable for ``dt > 2.785293563... t_c``.
"""

import dataclasses
import math
from collections.abc import Sequence
from typing import Any, ClassVar, Union

import numpy as np

from ..codes import RestRule, ThetaMethod
from ..errors import StabilityError

__all__ = [
    "CONTACT_ROW",
    "EULER_STABILITY_LIMIT",
    "LAWS",
    "METHODS",
    "RK4_STABILITY_LIMIT",
    "Coulomb",
    "Law",
    "LawError",
    "Parameter",
    "RateState",
    "method_code",
    "rate_state_mu",
    "slip_log",
    "stability_limit",
    "theta_equilibrium",
    "theta_step",
]

METHODS = ThetaMethod.labels()

# Stability limits on h = dt / t_c for d theta/dt = -theta / t_c. Explicit Euler amplifies by
# 1 - h, so |1 - h| <= 1 needs h <= 2. RK4 amplifies by R(-h) = 1 - h + h^2/2 - h^3/6 + h^4/24;
# R(-h) = 1 again at the real root of h^3 - 4 h^2 + 12 h - 24 = 0, h = 2.785293563405...
EULER_STABILITY_LIMIT = 2.0
RK4_STABILITY_LIMIT = 2.785293563405282


# --------------------------------------------------------------------------------------------
# The NumPy references (same operations in the same order as the Taichi twins, which are
# friction_ti's, in this order).
# --------------------------------------------------------------------------------------------


def slip_log(v, v_star):
    """x = ln(max(v, v_star) / v_star): the law's rate variable, 0 at and below v_star."""
    return np.log(np.maximum(v, v_star) / v_star)


def rate_state_mu(theta, x, A, mu0):
    """Friction coefficient mu = max(mu0 + theta + A x, 0)."""
    return np.maximum(mu0 + theta + A * x, 0.0)


def theta_equilibrium(x, B):
    """Steady-state theta = -B x, the state of a new interface sliding at x."""
    return -B * x


def theta_step(theta, x_start, x_mid, x_end, dt, B, t_c, method: int):
    """Advance theta over one step of ``dt`` seconds (scalars or broadcastable arrays).

    Args:
        theta: state at the step start.
        x_start, x_mid, x_end: ``slip_log`` of the slip rate at the start, the half step and
            the end of the step (the slip rate taken linear over the step).
        dt: step (s). B: state coefficient. t_c: critical slip time (s).
        method: a ``codes.ThetaMethod``.
    """
    h = dt / t_c
    if method == ThetaMethod.EXPONENTIAL:
        steady = -B * x_mid
        return steady + (theta - steady) * np.exp(-h)
    if method == ThetaMethod.EULER:
        return theta - h * (theta + B * x_start)
    if method == ThetaMethod.IMPLICIT:
        return theta - h * (theta + B * x_end) / (1.0 + h)
    if method == ThetaMethod.RK4:
        k1 = -(theta + B * x_start)
        k2 = -(theta + 0.5 * h * k1 + B * x_mid)
        k3 = -(theta + 0.5 * h * k2 + B * x_mid)
        k4 = -(theta + h * k3 + B * x_end)
        return theta + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    raise ValueError(f"unknown method code {method!r}; expected 0..{len(METHODS) - 1}")


# --------------------------------------------------------------------------------------------
# Input checks shared by the NumPy and Taichi paths.
# --------------------------------------------------------------------------------------------


def method_code(method: Union[str, int]) -> ThetaMethod:
    """The ``codes.ThetaMethod`` of a method name (a valid code passes through).

    Raises:
        ValueError: an unknown method, with the list of known ones.
    """
    if isinstance(method, str) and method in METHODS:
        return ThetaMethod.from_label(method)
    if isinstance(method, int) and not isinstance(method, bool) and 0 <= method < len(METHODS):
        return ThetaMethod(method)
    raise ValueError(f"unknown method {method!r}; choose one of {METHODS}")


def stability_limit(method: Union[str, int]) -> float:
    """Largest stable ``dt / t_c`` of a method (``inf`` for exponential and implicit)."""
    code = method_code(method)
    if code == ThetaMethod.EULER:
        return EULER_STABILITY_LIMIT
    if code == ThetaMethod.RK4:
        return RK4_STABILITY_LIMIT
    return math.inf


def check_step_stability(method: int, dt_max: float, t_c_min: float) -> None:
    """Refuse (``StabilityError``) a largest step ``dt_max`` beyond ``method``'s stability
    limit at the shortest ``t_c_min`` (``respond`` here and in ``batched``)."""
    limit = stability_limit(method)
    if dt_max > limit * t_c_min:
        name = {ThetaMethod.EULER: "explicit Euler", ThetaMethod.RK4: "RK4"}[method]
        raise StabilityError(
            f"{name} is unstable for a time step above {limit:.10g} t_c = "
            f"{limit * t_c_min:.6g} s (t_c = {t_c_min:g} s); the largest step here is "
            f"{dt_max:.6g} s. Use smaller steps, method='exponential' or 'implicit' (stable "
            "at any step), or check_stability=False to integrate it anyway."
        )


def _check_param(name: str, value: Any, *, positive: bool = False) -> float:
    if isinstance(value, bool):
        raise ValueError(f"{name} must be a number, got {value!r}")
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


def check_times(t: Any) -> np.ndarray:
    """``t`` as a float64 ``(T,)`` array of finite, strictly increasing times, or ValueError."""
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


def check_rates(v: Any, t: np.ndarray, ndims: Sequence[int]) -> np.ndarray:
    """``v`` as float64 slip rates of ``ndims`` dimensions over the times ``t``: finite and
    >= 0, or ValueError."""
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


@dataclasses.dataclass(frozen=True)
class Parameter:
    """One numeric parameter of a law, as its dataclass field declares it.

    Attributes:
        name: keyword, scene-table key and model column suffix (``world_<name>``).
        default: the paper's value.
        unit: SI unit, ``""`` if dimensionless.
        doc: one line: what it is.
        positive: must be > 0 (otherwise >= 0).
    """

    name: str
    default: float
    unit: str
    doc: str
    positive: bool = False


def _param(default: float, unit: str, doc: str, positive: bool = False) -> Any:
    """A law's numeric parameter: a dataclass field that carries its declaration."""
    return dataclasses.field(
        default=default, metadata={"unit": unit, "doc": doc, "positive": positive}
    )


class LawError(ValueError):
    """A friction law written wrongly; ``key`` names the offending key (or None)."""

    def __init__(self, message: str, key: Union[str, None] = None):
        super().__init__(message)
        self.key = key


class Law:
    """Base of the friction laws: identity (``name``, ``label``) and declared parameters."""

    name: ClassVar[str] = ""
    # Keys that are not numeric parameters (a choice), with their allowed values.
    choices: ClassVar[dict[str, tuple[str, ...]]] = {}

    @classmethod
    def parameters(cls) -> tuple[Parameter, ...]:
        """The law's numeric parameters, in declaration order."""
        return tuple(
            Parameter(
                f.name, f.default, f.metadata["unit"], f.metadata["doc"], f.metadata["positive"]
            )
            for f in dataclasses.fields(cls)
            if "unit" in f.metadata
        )

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """Every key of the law's scene table after ``law``: parameters, then choices."""
        return tuple(p.name for p in cls.parameters()) + tuple(cls.choices)

    def __post_init__(self) -> None:
        for p in self.parameters():
            object.__setattr__(
                self, p.name, _check_param(p.name, getattr(self, p.name), positive=p.positive)
            )
        for key, allowed in self.choices.items():
            value = getattr(self, key)
            if not isinstance(value, str) or value not in allowed:
                raise ValueError(f"{key} must be one of {allowed}, got {value!r}")

    @property
    def params(self) -> tuple[float, ...]:
        """The numeric parameters' values, in declaration order."""
        return tuple(getattr(self, p.name) for p in self.parameters())

    def to_dict(self) -> dict[str, Any]:
        """``{"law": name, parameter: value, ..., choice: value}``: the scene table, HDF5
        attributes and JSON all use this form; ``friction_parse.law_from_table`` reads it back."""
        out: dict[str, Any] = {"law": self.name}
        out.update((k, getattr(self, k)) for k in self.keys())
        return out

    @property
    def label(self) -> str:
        """Short name for files and legends: the law's name, then every numeric parameter
        that differs from its default and every choice but the integrator that does
        (``rate-state``, ``rate-state_t_c5``, ``rate-state_healing``)."""
        changed = [
            f"{p.name}{getattr(self, p.name):g}"
            for p in self.parameters()
            if getattr(self, p.name) != p.default
        ]
        defaults = {f.name: f.default for f in dataclasses.fields(self)}
        changed += [
            getattr(self, k)
            for k in self.choices
            if k != "method" and getattr(self, k) != defaults.get(k)
        ]
        return "_".join([self.name, *changed])


@dataclasses.dataclass(frozen=True)
class Coulomb(Law):
    """Amontons-Coulomb friction: mu constant, no memory.

    Args:
        mu: friction coefficient (dimensionless, >= 0).
    """

    name: ClassVar[str] = "coulomb"
    mu: float = _param(0.5, "", "friction coefficient")

    @property
    def label(self) -> str:
        """``mu0.5``: the coefficient, as the paper names its constant-friction models."""
        return f"mu{self.mu:g}"

    def contact_row(self) -> dict[str, float]:
        """Coulomb as a rate-and-state row (A = B = 0, mu0 = mu, no memory), so that a
        Coulomb world can share a batch with rate-and-state worlds: its mu is exactly mu."""
        return {
            "A": 0.0,
            "B": 0.0,
            "mu0": self.mu,
            "v_star": 1.0,
            "t_c": 1.0,
            "memory": 0,
            "rest_rule": int(RestRule.PAPER),
        }

    def steady_state(self, v: Any) -> np.ndarray:
        """mu at slip rates ``v`` (m/s, any shape): the constant mu."""
        v = np.asarray(v, dtype=np.float64)
        if np.any(np.isnan(v)) or np.any(v < 0.0):
            raise ValueError("v is a slip rate and must be >= 0 (m/s) and not NaN")
        return np.full(v.shape, self.mu)

    def respond(self, t: Any, v: Any, method: Union[str, None] = None, **_: Any) -> np.ndarray:
        """mu at every time of a slip-rate history (constant); checks the input like RateState."""
        t = check_times(t)
        check_rates(v, t, (1,))
        if method is not None:
            method_code(method)
        return np.full(t.shape, self.mu)


def _respond_rate_state(t, v, A, B, mu0, v_star, t_c, code, rule):
    """mu and theta of one interface (see ``RateState.respond``); theta is NaN where the
    interface has ended (below v_star under the paper's rule)."""
    x = slip_log(v, v_star)
    x_mid = slip_log(0.5 * (v[:-1] + v[1:]), v_star)
    dt = np.diff(t)
    below = (v < v_star).tolist()
    theta = np.empty_like(x)
    # Plain floats: one interface is a sequential loop, and NumPy scalars cost more.
    xs, xm, dts = x.tolist(), x_mid.tolist(), dt.tolist()
    none = math.nan
    if below[0]:
        th = none if rule == RestRule.PAPER else 0.0
    else:
        th = float(theta_equilibrium(xs[0], B))
    theta[0] = th
    with np.errstate(over="ignore", invalid="ignore"):
        for n in range(t.size - 1):
            if below[n + 1] and rule == RestRule.PAPER:
                th = none  # the interface ends
            elif below[n + 1] and rule == RestRule.FROZEN and not math.isnan(th):
                pass  # held while slower than v_star
            elif math.isnan(th):
                # A new interface: in equilibrium at its slip rate (0 at or below v_star).
                th = float(theta_equilibrium(xs[n + 1], B))
            else:
                th = float(theta_step(th, xs[n], xm[n], xs[n + 1], dts[n], B, t_c, code))
            theta[n + 1] = th
        ended = np.isnan(theta)
        if rule == RestRule.RELAXING:
            ended = ended | np.asarray(below)  # mu0 below v_star; theta carried on
        mu = np.where(ended, mu0, rate_state_mu(np.where(ended, 0.0, theta), x, A, mu0))
    return mu, theta


class _RateStateFamily(Law):
    """The laws a rate-and-state contact runs: each gives its row of the batch's model
    (``contact_row``), so that worlds of a batch may mix them."""

    def contact_row(self) -> dict[str, float]:
        """The model columns of a world under this law: ``A, B, mu0, v_star, t_c`` and the
        codes ``memory`` (1 if theta is carried) and ``rest_rule`` (``codes.RestRule``)."""
        raise NotImplementedError

    def slip_log(self, v: Any) -> np.ndarray:
        """x = ln(max(v, v_star) / v_star) for slip rates ``v`` (m/s, any shape)."""
        return slip_log(np.asarray(v, dtype=np.float64), self.v_star)

    def steady_state(self, v: Any) -> np.ndarray:
        """Steady-state friction ``max(mu0 + (A - B) x, 0)`` at slip rates ``v`` (m/s, any
        shape, >= 0); mu0 at or below v_star."""
        v = np.asarray(v, dtype=np.float64)
        if np.any(np.isnan(v)):
            raise ValueError("v must not be NaN")
        if np.any(v < 0.0):
            raise ValueError(f"v is a slip rate and must be >= 0 (m/s); min(v) = {v.min()!r}")
        row = self.contact_row()
        x = slip_log(v, row["v_star"])
        return rate_state_mu(theta_equilibrium(x, row["B"]), x, row["A"], row["mu0"])


@dataclasses.dataclass(frozen=True)
class RateState(_RateStateFamily):
    """Rate-and-state friction with memory (Lishman et al. 2013, eqs. 2a-b).

        mu        = max(mu0 + theta + A x, 0),      x = ln(V / v_star)
        dtheta/dt = -(theta + B x) / t_c

    A new sliding interface starts in equilibrium, ``theta = -B x``, so at constant V the
    friction is ``mu_ss = mu0 + (A - B) x`` (velocity weakening since A < B).

    Below ``v_star`` the paper uses ``mu = mu0``. ``below_v_star`` chooses what the memory
    does there (``codes.RestRule``): ``paper`` (default): mu = mu0 exactly, the interface
    ends, and one that slides again is a new interface in equilibrium; ``healing``: x = 0,
    theta relaxes toward 0 over t_c and mu = max(mu0 + theta, 0) (the aging law's healing;
    the state equation read with ``x = ln(max(V, v_star) / v_star)`` everywhere);
    ``frozen``: theta is held while slower than v_star, mu = max(mu0 + theta, 0);
    ``relaxing``: mu = mu0 exactly, as under ``paper``, but the interface does not end: theta
    relaxes toward 0 over t_c as under ``healing`` and the interface slides on from there
    (the paper's words read in continuous time: a per-step end of the interface makes how
    often it ends depend on the step, ``docs/accuracy.md``). At a DEM contact mu0 applies
    only while the contact slides slower than v_star (its surfaces do, or the law at its
    theta would), so a stopped contact loaded past that holds (mu0 + theta) F_n, as under
    ``healing``: its jams carry as little.

    mu is clamped at 0: right after a fast deceleration from above ``v_star exp(mu0 / B)``
    (about 2.4 cm/s) the unclamped law would be negative.

    Args:
        A: direct (rate) coefficient, >= 0.
        B: state coefficient, >= 0.
        mu0: reference friction at ``v_star``, >= 0.
        v_star: reference slip rate (m/s), > 0.
        t_c: critical slip time (s), > 0.
        method: default integrator of ``respond``, one of ``RateState.methods``.
        below_v_star: ``paper``, ``healing``, ``frozen`` or ``relaxing``.

    Raises:
        ValueError: a parameter that is NaN, infinite, negative, or zero where it must be
            positive (``v_star``, ``t_c``), or an unknown method or rule.
    """

    name: ClassVar[str] = "rate-state"
    methods: ClassVar[tuple[str, ...]] = METHODS
    choices: ClassVar[dict[str, tuple[str, ...]]] = {
        "method": METHODS,
        "below_v_star": RestRule.labels(),
    }

    # Paper defaults at -10 C (Lishman et al. 2013).
    A: float = _param(0.05, "", "direct (rate) coefficient")
    B: float = _param(0.112, "", "state coefficient")
    mu0: float = _param(0.872, "", "friction at the reference slip rate v_star")
    v_star: float = _param(1e-5, "m/s", "reference slip rate", positive=True)
    t_c: float = _param(3.0, "s", "critical slip time of the state's relaxation", positive=True)
    method: str = "exponential"
    below_v_star: str = "paper"

    def contact_row(self) -> dict[str, float]:
        return {
            **{p.name: getattr(self, p.name) for p in RateState.parameters()},
            "memory": 1,
            "rest_rule": int(RestRule.from_label(self.below_v_star)),
        }

    def respond(
        self,
        t: Any,
        v: Any,
        method: Union[str, None] = None,
        *,
        check_stability: bool = True,
        return_theta: bool = False,
    ) -> Union[np.ndarray, tuple[np.ndarray, np.ndarray]]:
        """Friction of one interface under a slip-rate history (NumPy reference path).

        The slip rate is taken linear between samples; the interface starts in equilibrium
        at ``v[0]``. The rule below v_star is applied sample by sample: a sample below
        v_star ends the interface (``paper``; theta NaN there), holds theta (``frozen``) or
        steps it with x = 0 (``healing``); the first sample at or above v_star after an end
        starts a new interface in equilibrium.

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
        code = method_code(self.method if method is None else method)
        t = check_times(t)
        v = check_rates(v, t, (1,))
        row = self.contact_row()
        if check_stability and t.size > 1:
            check_step_stability(code, float(np.max(np.diff(t))), row["t_c"])
        mu, theta = _respond_rate_state(
            t,
            v,
            row["A"],
            row["B"],
            row["mu0"],
            row["v_star"],
            row["t_c"],
            code,
            row["rest_rule"],
        )
        return (mu, theta) if return_theta else mu


# The model columns of a world under any law (``Law.contact_row``): the rate-and-state
# parameters as declared, then the two codes (theta carried or not; the rule below v_star).
# A Coulomb world fills them so that it shares a batch with rate-and-state worlds.
CONTACT_ROW = (*(p.name for p in RateState.parameters()), "memory", "rest_rule")


@dataclasses.dataclass(frozen=True)
class MemoryOnly(RateState):
    """Rate-and-state friction with B = A: mu_ss = mu0 at every speed, so only the
    transients of the memory remain (a speed step gives a jump of ``A dx`` that decays over
    t_c back to mu0). Parameters and rules as ``RateState``; ``B`` is ``A``."""

    name: ClassVar[str] = "memory-only"
    B: float = dataclasses.field(default=0.05, init=False, repr=False)

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "B", self.A)

    @classmethod
    def parameters(cls) -> tuple[Parameter, ...]:
        return tuple(p for p in super().parameters() if p.name != "B")


@dataclasses.dataclass(frozen=True)
class SteadyState(RateState):
    """Rate without lasting memory: the rate-and-state law with a short critical slip time,
    so that mu follows its steady state ``mu_ss = max(mu0 + (A - B) x, 0)`` within ``t_c``
    (0.1 s by default, against the paper's 3 s) of any change of the slip rate.

    The law without any memory (mu = mu_ss(V) at once, every step a new interface) is not
    well posed at a contact: velocity weakening with no direct effect has no unique slip
    rate, the static threshold is tested every step, and the contact chattered between
    stick and slip at a rate set by dt (its slider's frictional work moved by 166 % over
    the steps, its pillar budget missed by 9 %). Through ``t_c`` the direct effect ``A``
    keeps the slip rate unique and the runs converge in dt, as long as the step resolves
    ``t_c`` (``docs/friction.md`` measures t_c = 0.03 to 1 s). Parameters and rules as
    ``RateState``.
    """

    name: ClassVar[str] = "steady-state"

    t_c: float = _param(
        0.1, "s", "critical slip time, short: mu reaches mu_ss within it", positive=True
    )


# The laws by name, in the order the documentation lists them.
LAWS: dict[str, type] = {law.name: law for law in (Coulomb, RateState, SteadyState, MemoryOnly)}
