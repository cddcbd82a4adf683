"""Batched drivers: run a twin's Taichi function on many independent inputs in one launch.

They exist for the tests that hold each Taichi function against its NumPy twin on seeded
random inputs, for the benchmarks, and for studies that integrate thousands of interfaces:

- ``respond_batch_ti`` / ``respond_batch``: many sliding interfaces, each following its own
  slip-rate history under its own rate-and-state parameters (``friction``'s functions). They
  integrate the state equation with ``x = ln(max(V, v_star) / v_star)`` at every speed, which
  is ``RateState(below_v_star="healing").respond``; the paper's rule is a per-sample reset
  that ``RateState.respond`` applies;
- ``overlap_batch_ti``: the overlap and separating-axis functions of ``polygon`` on many
  polygon pairs (``polygon.overlap`` and friends are the NumPy twins);
- ``contact_friction_batch_ti``: the friction of many DEM contacts (``slip``);
- ``sliding_steps_batch_ti``: their tangential step, the slide in sub-steps (``slip``);
- ``rotation_batch_ti``: a body's rotation (``polygon_ti.rotation_ti``) of many angles.

The engine itself does not use them: its stages call the same ``_ti`` functions from their
own kernels.
"""

# No ``from __future__ import annotations``: Taichi reads the annotations of its kernels.

from typing import Any, NamedTuple, Union

import numpy as np
import taichi as ti

from .. import backend
from .friction import (
    Coulomb,
    RateState,
    check_rates,
    check_step_stability,
    check_times,
    method_code,
    rate_state_mu,
    slip_log,
    theta_equilibrium,
    theta_step,
)
from .friction_ti import rate_state_mu_ti, slip_log_ti, theta_equilibrium_ti, theta_step_ti
from .polygon_ti import (
    edge_normals_ti,
    facing_gap_ti,
    min_penetration_axis_ti,
    overlap_ti,
    rotation_ti,
    sat_separated_ti,
    separation_gap_ti,
)
from .slip import NEWTON_TOLERANCE
from .slip_ti import contact_friction_ti, sliding_steps_ti

# --------------------------------------------------------------------------------------------
# Many sliding interfaces at once
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
        x = slip_log_ti(v[iv, 0], v_star)
        theta = theta_equilibrium_ti(x, B)
        mu_out[i, 0] = rate_state_mu_ti(theta, x, A, mu0)
        if ti.static(with_theta):
            theta_out[i, 0] = theta
        for n in range(1, mu_out.shape[1]):
            v_start = v[iv, n - 1]
            v_end = v[iv, n]
            x_mid = slip_log_ti(0.5 * (v_start + v_end), v_star)
            x_end = slip_log_ti(v_end, v_star)
            theta = theta_step_ti(theta, x, x_mid, x_end, t[n] - t[n - 1], B, t_c, method)
            x = x_end
            mu_out[i, n] = rate_state_mu_ti(theta, x, A, mu0)
            if ti.static(with_theta):
                theta_out[i, n] = theta


def _batch_params(params: Any) -> np.ndarray:
    if params is None:
        params = RateState()
    if isinstance(params, RateState):
        return np.asarray([params.params], dtype=np.float64)
    if isinstance(params, Coulomb):
        raise ValueError("respond_batch_ti integrates rate-and-state laws; Coulomb mu is constant")
    p = np.asarray(params, dtype=np.float64)
    if p.ndim == 1:
        p = p[None, :]
    if p.ndim != 2 or p.shape[1] != 5:
        raise ValueError(
            f"params must be a RateState, a row (A, B, mu0, v_star, t_c) or an (N, 5) array; "
            f"got shape {np.shape(params)}"
        )
    for j, param in enumerate(RateState.parameters()):  # the law's declaration: A .. t_c
        col = p[:, j]
        bad = ~np.isfinite(col) | ((col <= 0.0) if param.positive else (col < 0.0))
        if np.any(bad):
            i = int(np.argmax(bad))
            rule = "> 0" if param.positive else ">= 0"
            raise ValueError(
                f"params[{i}, {j}] ({param.name}) must be finite and {rule}; got {col[i]}"
            )
    return p


def _prepare_batch(
    t: Any, v: Any, params: Any, method: Union[str, int], check_stability: bool
) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    code = method_code(method)
    t = check_times(t)
    v = check_rates(v, t, (1, 2))
    v = v[None, :] if v.ndim == 1 else v
    p = _batch_params(params)
    if v.shape[0] != p.shape[0] and 1 not in (v.shape[0], p.shape[0]):
        raise ValueError(
            f"v has {v.shape[0]} interfaces (rows) but params has {p.shape[0]}; "
            "they must match, or one of them must be a single row"
        )
    if check_stability and t.size > 1:
        check_step_stability(code, float(np.max(np.diff(t))), float(np.min(p[:, 4])))
    return code, t, v, p


def respond_batch_ti(
    t: Any,
    v: Any,
    params: Any = None,
    method: str = "exponential",
    *,
    check_stability: bool = True,
    return_theta: bool = False,
) -> Union[np.ndarray, tuple[np.ndarray, np.ndarray]]:
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
    respond_batch_ti_unchecked(
        np.ascontiguousarray(t, dtype=dtype),
        np.ascontiguousarray(v, dtype=dtype),
        np.ascontiguousarray(p, dtype=dtype),
        code,
        mu,
        theta,
    )
    return (mu, theta) if return_theta else mu


def respond_batch_ti_unchecked(
    t: np.ndarray,
    v: np.ndarray,
    params: np.ndarray,
    method: int,
    mu_out: np.ndarray,
    theta_out: Union[np.ndarray, None] = None,
) -> None:
    """Run the batch kernel on prepared arrays: no checks, no copies, no allocation.

    For benchmarks and callers that reuse buffers; ``respond_batch_ti`` is the checked entry.
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


def respond_batch(
    t: Any,
    v: Any,
    params: Any = None,
    method: str = "exponential",
    *,
    check_stability: bool = True,
    return_theta: bool = False,
    dtype: Any = np.float64,
) -> Union[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """NumPy reference of ``respond_batch_ti``: vectorised over interfaces, a loop in time.

    Same arguments, checks and results as ``respond_batch_ti``, plus ``dtype`` (``np.float64``
    or ``np.float32``), the precision of the arithmetic. It is the reference the Taichi
    batch is held against and the NumPy entry of the speed/accuracy study.
    """
    code, t, v, p = _prepare_batch(t, v, params, method, check_stability)
    dtype = np.dtype(dtype)
    if dtype not in (np.float32, np.float64):
        raise ValueError(f"dtype must be float64 or float32, got {dtype}")
    mu, theta = respond_batch_unchecked(t, v, p, code, dtype)
    return (mu, theta) if return_theta else mu


def respond_batch_unchecked(
    t: np.ndarray, v: np.ndarray, params: np.ndarray, method: int, dtype: Any = np.float64
) -> tuple[np.ndarray, np.ndarray]:
    """The loop of ``respond_batch`` without its checks; returns ``(mu, theta)``, (N, T).

    Args as ``respond_batch_ti_unchecked`` (any float arrays; computed in ``dtype``).
    """
    dtype = np.dtype(dtype)
    n = max(v.shape[0], params.shape[0])
    A, B, mu0, v_star, t_c = (np.ascontiguousarray(col, dtype=dtype) for col in params.T)
    # Time-major copies so that every step reads and writes contiguous rows of interfaces.
    v_t = np.ascontiguousarray(v.T, dtype=dtype)
    x = slip_log(v_t, v_star)
    x_mid = slip_log(dtype.type(0.5) * (v_t[:-1] + v_t[1:]), v_star)
    dt = np.diff(np.asarray(t, dtype=dtype))
    theta = np.empty((t.size, n), dtype=dtype)
    theta[0] = theta_equilibrium(x[0], B)
    with np.errstate(over="ignore", invalid="ignore"):
        for i in range(t.size - 1):
            theta[i + 1] = theta_step(theta[i], x[i], x_mid[i], x[i + 1], dt[i], B, t_c, method)
        mu = rate_state_mu(theta, x, A, mu0)
    mu = np.ascontiguousarray(np.broadcast_to(mu, (t.size, n)).T)
    return mu, np.ascontiguousarray(theta.T)


# --------------------------------------------------------------------------------------------
# Many polygon pairs at once
# --------------------------------------------------------------------------------------------


@ti.kernel
def _overlap_batch_kernel(
    # In:
    p_in: ti.types.ndarray(ndim=3),
    n_p_in: ti.types.ndarray(ndim=1),
    q_in: ti.types.ndarray(ndim=3),
    n_q_in: ti.types.ndarray(ndim=1),
    maxv_p: ti.template(),
    maxv_q: ti.template(),
    # Out:
    area_out: ti.types.ndarray(ndim=1),
    centroid_out: ti.types.ndarray(ndim=2),
    normal_out: ti.types.ndarray(ndim=2),
    width_out: ti.types.ndarray(ndim=1),
    kind_out: ti.types.ndarray(ndim=1),
    depth_out: ti.types.ndarray(ndim=1),
    axis_out: ti.types.ndarray(ndim=2),
    separated_out: ti.types.ndarray(ndim=1),
    gap_out: ti.types.ndarray(ndim=1),
    separation_out: ti.types.ndarray(ndim=1),
):
    for b in range(area_out.shape[0]):
        # The gather the contact kernel does: vertices into fixed-size local matrices.
        p = ti.Matrix.zero(float, maxv_p, 2)
        q = ti.Matrix.zero(float, maxv_q, 2)
        for k in range(n_p_in[b]):
            p[k, 0] = p_in[b, k, 0]
            p[k, 1] = p_in[b, k, 1]
        for k in range(n_q_in[b]):
            q[k, 0] = q_in[b, k, 0]
            q[k, 1] = q_in[b, k, 1]
        area, centroid, normal, width, kind = overlap_ti(p, n_p_in[b], q, n_q_in[b])
        depth, axis = min_penetration_axis_ti(p, n_p_in[b], q, n_q_in[b])
        area_out[b] = area
        width_out[b] = width
        kind_out[b] = kind
        depth_out[b] = depth
        separated_out[b] = ti.cast(sat_separated_ti(p, n_p_in[b], q, n_q_in[b]), ti.i32)
        # The facing edge of p toward q, q's vertex mean seen from p's.
        toward = ti.math.vec2(0.0, 0.0)
        for k in range(n_q_in[b]):
            toward += ti.math.vec2(q[k, 0], q[k, 1]) / n_q_in[b]
        for k in range(n_p_in[b]):
            toward -= ti.math.vec2(p[k, 0], p[k, 1]) / n_p_in[b]
        p_normals, q_normals = edge_normals_ti(p, n_p_in[b]), edge_normals_ti(q, n_q_in[b])
        gap_out[b] = facing_gap_ti(p, p_normals, n_p_in[b], q, n_q_in[b], toward)
        separation_out[b] = separation_gap_ti(p, p_normals, n_p_in[b], q, q_normals, n_q_in[b])
        for d in ti.static(range(2)):
            centroid_out[b, d] = centroid[d]
            normal_out[b, d] = normal[d]
            axis_out[b, d] = axis[d]


class BatchOverlap(NamedTuple):
    """Results of :func:`overlap_batch_ti` for B pairs: the :class:`Overlap` fields, batched.

    Attributes:
        area: ``(B,)`` m^2. centroid: ``(B, 2)`` m. normal: ``(B, 2)``. width: ``(B,)`` m.
        kind: ``(B,)`` int32. depth: ``(B,)`` SAT minimum penetration (m). axis: ``(B, 2)``
        its unit axis, ``p -> q``. separated: ``(B,)`` bool, the SAT verdict. facing_gap:
        ``(B,)`` m, :func:`polygon_ti.facing_gap_ti` toward ``q``'s vertex mean from ``p``'s.
        separation_gap: ``(B,)`` m, :func:`polygon_ti.separation_gap_ti`, every axis.
        facing: ``(B,)`` bool, that gap >= 0 (the facing edge separates the pair).
    """

    area: np.ndarray
    centroid: np.ndarray
    normal: np.ndarray
    width: np.ndarray
    kind: np.ndarray
    depth: np.ndarray
    axis: np.ndarray
    separated: np.ndarray
    facing_gap: np.ndarray
    separation_gap: np.ndarray
    facing: np.ndarray


def overlap_batch_ti(p, n_p, q, n_q) -> BatchOverlap:
    """Run :func:`overlap_ti` (and the SAT functions) on B pairs at once, for tests and benchmarks.

    Starts Taichi on the CPU in float64 if nothing has started it yet; otherwise runs on the
    arch and precision already chosen, with inputs cast to that precision.

    Args:
        p: ``(B, P, 2)`` vertices of the first polygons (m), rows past ``n_p[b]`` ignored.
        n_p: ``(B,)`` vertex counts of ``p`` (3 <= n_p <= P).
        q: ``(B, Q, 2)`` vertices of the second polygons (m).
        n_q: ``(B,)`` vertex counts of ``q`` (3 <= n_q <= Q).

    Returns:
        A :class:`BatchOverlap` of NumPy arrays.
    """
    if backend.current() is None:
        backend.init()
    real = backend.real_dtype(backend.current()[1])
    p = np.ascontiguousarray(p, dtype=real)
    q = np.ascontiguousarray(q, dtype=real)
    n_p = np.ascontiguousarray(n_p, dtype=np.int32)
    n_q = np.ascontiguousarray(n_q, dtype=np.int32)
    batch = p.shape[0]
    if p.ndim != 3 or q.ndim != 3 or p.shape[2] != 2 or q.shape[2] != 2:
        raise ValueError(f"p and q must be (B, MAXV, 2) arrays, got {p.shape} and {q.shape}")
    if q.shape[0] != batch or n_p.shape != (batch,) or n_q.shape != (batch,):
        raise ValueError("p, n_p, q and n_q must have the same batch length B")
    if np.any(n_p < 3) or np.any(n_p > p.shape[1]) or np.any(n_q < 3) or np.any(n_q > q.shape[1]):
        raise ValueError("vertex counts must lie between 3 and the padded size of p and q")
    out = BatchOverlap(
        area=np.zeros(batch, real),
        centroid=np.zeros((batch, 2), real),
        normal=np.zeros((batch, 2), real),
        width=np.zeros(batch, real),
        kind=np.zeros(batch, np.int32),
        depth=np.zeros(batch, real),
        axis=np.zeros((batch, 2), real),
        separated=np.zeros(batch, np.int32),
        facing_gap=np.zeros(batch, real),
        separation_gap=np.zeros(batch, real),
        facing=np.zeros(batch, bool),
    )
    if batch:
        _overlap_batch_kernel(p, n_p, q, n_q, p.shape[1], q.shape[1], *out[:-1])
    return out._replace(separated=out.separated.astype(bool), facing=out.facing_gap >= 0.0)


# --------------------------------------------------------------------------------------------
# Friction at many contacts at once
# --------------------------------------------------------------------------------------------


@ti.kernel
def _contact_friction_kernel(
    inputs: ti.types.ndarray(ndim=2),
    codes: ti.types.ndarray(ndim=2),
    out: ti.types.ndarray(ndim=2),
    method: ti.template(),
    tol: ti.template(),
):
    # inputs (N, 12): theta, last_slip, slip, f_trial, f_n, K, dt, A, B, mu0, v_star, t_c;
    # codes (N, 2): memory, rest rule; out (N, 3): mu, theta_new, V.
    for i in range(inputs.shape[0]):
        mu, theta, v = contact_friction_ti(
            inputs[i, 0],
            inputs[i, 1],
            inputs[i, 2],
            inputs[i, 3],
            inputs[i, 4],
            inputs[i, 5],
            inputs[i, 6],
            inputs[i, 7],
            inputs[i, 8],
            inputs[i, 9],
            inputs[i, 10],
            inputs[i, 11],
            codes[i, 0],
            codes[i, 1],
            method,
            tol,
        )
        out[i, 0] = mu
        out[i, 1] = theta
        out[i, 2] = v


def contact_friction_batch_ti(inputs: Any, codes: Any, method: int = 0) -> np.ndarray:
    """``slip_ti.contact_friction_ti`` on N contacts at once (for the twin tests).

    Args:
        inputs: ``(N, 12)`` rows (theta, last_slip, slip, f_trial, f_n, K, dt, A, B, mu0,
            v_star, t_c).
        codes: ``(N, 2)`` int rows (memory, rest rule).
        method: ``codes.ThetaMethod`` (compile-time).

    Returns:
        ``(N, 3)`` rows (mu, theta_new, V) in the running precision.
    """
    return _contact_batch(_contact_friction_kernel, inputs, codes, method, 12, 3)


def _contact_batch(kernel, inputs, codes, method: int, columns: int, outputs: int):
    """Run a contact twin's batch ``kernel`` on ``(N, columns)`` real inputs and ``(N, 2)``
    codes in the running precision (started on the CPU in float64 if none runs); returns
    its ``(N, outputs)`` rows."""
    if backend.current() is None:
        backend.init("cpu", "f64")
    precision = backend.current()[1]
    real = backend.real_dtype(precision)
    inputs = np.ascontiguousarray(inputs, dtype=real)
    codes = np.ascontiguousarray(codes, dtype=np.int32)
    if inputs.ndim != 2 or inputs.shape[1] != columns or codes.shape != (inputs.shape[0], 2):
        raise ValueError(
            f"inputs must be (N, {columns}) and codes (N, 2); got {inputs.shape}, {codes.shape}"
        )
    out = np.zeros((inputs.shape[0], outputs), dtype=real)
    if inputs.shape[0]:
        kernel(inputs, codes, out, int(method), NEWTON_TOLERANCE[precision])
    return out


@ti.kernel
def _sliding_steps_kernel(
    inputs: ti.types.ndarray(ndim=2),
    codes: ti.types.ndarray(ndim=2),
    out: ti.types.ndarray(ndim=2),
    method: ti.template(),
    tol: ti.template(),
):
    # inputs (N, 14): theta, last_slip, slip, xi, f_n, k_t, c_t, dt, A, B, mu0, v_star, t_c,
    # resolution; codes (N, 2): memory, rest rule; out (N, 7).
    for i in range(inputs.shape[0]):
        r = sliding_steps_ti(
            inputs[i, 0], inputs[i, 1], inputs[i, 2], inputs[i, 3], inputs[i, 4], inputs[i, 5],
            inputs[i, 6], inputs[i, 7], inputs[i, 8], inputs[i, 9], inputs[i, 10],
            inputs[i, 11], inputs[i, 12], codes[i, 0], codes[i, 1], inputs[i, 13], method, tol,
        )  # fmt: skip
        for k in ti.static(range(7)):
            out[i, k] = r[k]


def sliding_steps_batch_ti(inputs: Any, codes: Any, method: int = 0) -> np.ndarray:
    """``slip_ti.sliding_steps_ti`` on N contacts at once (for the twin tests).

    Args:
        inputs: ``(N, 14)`` rows (theta, last_slip, slip, xi, f_n, k_t, c_t, dt, A, B, mu0,
            v_star, t_c, resolution).
        codes: ``(N, 2)`` int rows (memory, rest rule).
        method: ``codes.ThetaMethod`` (compile-time).

    Returns:
        ``(N, 7)`` rows (mu, theta_new, V, f_t, xi_new, slip_work, damp_work) in the running
        precision.
    """
    return _contact_batch(_sliding_steps_kernel, inputs, codes, method, 14, 7)


# --------------------------------------------------------------------------------------------
# Rotations of many angles
# --------------------------------------------------------------------------------------------


@ti.kernel
def _rotation_kernel(angle: ti.types.ndarray(ndim=1), out: ti.types.ndarray(ndim=2)):
    for i in range(angle.shape[0]):
        r = rotation_ti(angle[i])
        out[i, 0] = r[0]
        out[i, 1] = r[1]


def rotation_batch_ti(angle: Any) -> np.ndarray:
    """``polygon_ti.rotation_ti`` of N angles (rad) at once: ``(N, 2)`` rows (cos, sin).

    Raises:
        ValueError: Taichi runs in float32 (``rotation_ti`` is the float64 step's).
    """
    if backend.current() is None:
        backend.init("cpu", "f64")
    if backend.current()[1] != "f64":
        raise ValueError("rotation_ti is for a float64 runtime; this one runs float32")
    angle = np.ascontiguousarray(np.ravel(angle), dtype=np.float64)
    out = np.zeros((angle.shape[0], 2))
    if angle.shape[0]:
        _rotation_kernel(angle, out)
    return out
