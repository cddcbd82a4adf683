"""The friction law as Taichi functions: values in, values out, no field access.

The Taichi twins of ``friction``'s NumPy references, in the same order (``slip_log_ti``
beside ``friction.slip_log``, ...), which the batched driver ``batched.respond_batch_ti`` and
every DEM contact call inside their kernels; the tests hold each against its twin. The laws,
their parameters and the integrators' description are ``friction``'s.
"""

# No ``from __future__ import annotations``: Taichi reads the annotations of its functions
# and kernels (ti.template(), ti.types.ndarray) as objects, not strings.
import taichi as ti

from ..codes import ThetaMethod
from .fmath_ti import exp_any, log_any

__all__ = [
    "rate_state_mu_ti",
    "slip_log_ti",
    "theta_advance_ti",
    "theta_decay_ti",
    "theta_equilibrium_ti",
    "theta_step_ti",
]


@ti.func
def slip_log_ti(v, v_star):
    """Taichi twin of :func:`friction.slip_log`."""
    return log_any(ti.max(v, v_star) / v_star)


@ti.func
def rate_state_mu_ti(theta, x, A, mu0):
    """Taichi twin of :func:`friction.rate_state_mu`."""
    return ti.max(mu0 + theta + A * x, 0.0)


@ti.func
def theta_equilibrium_ti(x, B):
    """Taichi twin of :func:`friction.theta_equilibrium`."""
    return -B * x


@ti.func
def theta_step_ti(theta, x_start, x_mid, x_end, dt, B, t_c, method: ti.template()):
    """Taichi twin of :func:`friction.theta_step` (``method`` resolved at compile time)."""
    h = dt / t_c
    return theta_advance_ti(theta, x_start, x_mid, x_end, h, theta_decay_ti(h, method), B, method)


@ti.func
def theta_decay_ti(h, method: ti.template()):
    """``exp(-h)`` for the exponential method (``h`` = dt / t_c), which ``theta_step_ti`` takes:
    the same for every theta of a step, so a caller that advances several computes it once
    (an ``exp`` a call: a rate-and-state contact's law took three a sub-step)."""
    decay = 0.0 * h
    if ti.static(method == ThetaMethod.EXPONENTIAL):
        decay = exp_any(-h)
    return decay


@ti.func
def theta_advance_ti(theta, x_start, x_mid, x_end, h, decay, B, method: ti.template()):
    """``theta_step_ti`` with ``h`` = dt / t_c and its ``theta_decay_ti`` given."""
    new = theta
    if ti.static(method == ThetaMethod.EXPONENTIAL):
        steady = -B * x_mid
        new = steady + (theta - steady) * decay
    if ti.static(method == ThetaMethod.EULER):
        new = theta - h * (theta + B * x_start)
    if ti.static(method == ThetaMethod.IMPLICIT):
        # Increment form: in float32, (theta - h B x) / (1 + h) would lose the digits of h
        # that 1 + h rounds away when h is small.
        new = theta - h * (theta + B * x_end) / (1.0 + h)
    if ti.static(method == ThetaMethod.RK4):
        k1 = -(theta + B * x_start)
        k2 = -(theta + 0.5 * h * k1 + B * x_mid)
        k3 = -(theta + 0.5 * h * k2 + B * x_mid)
        k4 = -(theta + h * k3 + B * x_end)
        new = theta + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return new
