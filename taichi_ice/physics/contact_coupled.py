"""A contact's normal and tangential spring-dashpots solved together over a step (the
``coupled`` integrator).

The analytic step (``contact_step.pair_impulses``) solves the normal and the stuck tangent as
two oscillators, each at the pair's inverse mass along its own direction, and takes what
moves one through the other, the bodies' turning, from the last step's forces: the cross
term of the pair's inverse mass, ``K_nt = (r_i x n)(r_i x t) / I_i + (r_j x n)(r_j x t) /
I_j``. Within a step of 0.8 stable_dt a contact's forces change by O(1), and an offset
collision's restitution is 2 % off there (``validation.contact_coupling``). Here the two are
one linear system over the step: ``x = (depth, stretch)``, ``u = x' = (approach, slip)``,

    u' = a - W (S x + C u),   W = [[K_nn, -K_nt], [-K_nt, K_tt]],

``S = diag(k_n, k_t)``, ``C = diag(c_n, c_t)``, ``S x + C u`` the normal force and the stuck
tangential force against the stretch, ``a`` the other forces' acceleration of the two (the
last step's change less all this contact's own, its cross term too). About its equilibrium
``x_eq = S^-1 W^-1 a`` it is ``z' = A z``, solved by the exponential of ``A h``
(:func:`expm4`: Pade [6/6], scaling and squaring, in balanced units). The bodies take the
impulse ``P = W^-1 (u0 + a h - u(h))`` and the position impulse ``Q = W^-1 (x0 + u0 h + a
h^2 / 2 - x(h))``, as in ``contact_step.spring_dashpot``; a contact that began inside the
last step is integrated from its onset. Sliding (the stuck impulse beyond ``mu`` times the
normal one), the tangential force is ``sign mu`` times the normal force, so the normal moves
alone at the inverse mass ``K_nn - sign mu K_nt`` (``contact_step.spring_dashpot``). Where the
normal force would pull at the step's start or end (its clamp binds inside the step), or
sliding leaves no positive inverse mass, the step is ``pair_impulses``' (whose 1D solve
locates the moment the force ends), computed here alike.

NumPy only; ``contact_coupled_ti`` holds the Taichi twins, operation for operation.
"""

from __future__ import annotations

import math

from .contact_step import onset, spring_dashpot

__all__ = ["MAX_SQUARINGS", "PADE", "SCALED_NORM", "coupled_flow", "coupled_impulses", "expm4"]

# Pade [6/6] of exp: c_k = (12 - k)! 6! / (12! k! (6 - k)!); its error at a norm of 1/2 is
# ~1e-17, below float64's round-off, so the matrix is halved until its norm is at most that.
PADE = (1.0, 0.5, 5.0 / 44.0, 1.0 / 66.0, 1.0 / 792.0, 1.0 / 15840.0, 1.0 / 665280.0)
SCALED_NORM = 0.5
MAX_SQUARINGS = 30  # a norm of 2^29: no step a scene takes comes near


def _mul(a, b):
    """4 x 4 product, summed in index order (as the Taichi twin)."""
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def _solve(m, r):
    """``m^-1 r`` (4 x 4) by Gaussian elimination without pivoting: ``m = V - U`` of the
    Pade approximant at a norm <= 1/2 is ``I - x / 2 + ...``, within 0.3 of the identity
    row by row, so it is diagonally dominant and stays so through the elimination, whose
    pivots keep away from zero."""
    m = [row[:] for row in m]
    r = [row[:] for row in r]
    for k in range(4):
        for i in range(k + 1, 4):
            f = m[i][k] / m[k][k]
            for j in range(k, 4):
                m[i][j] -= f * m[k][j]
            for j in range(4):
                r[i][j] -= f * r[k][j]
    out = [[0.0] * 4 for _ in range(4)]
    for i in range(3, -1, -1):
        for j in range(4):
            s = r[i][j]
            for k in range(i + 1, 4):
                s -= m[i][k] * out[k][j]
            out[i][j] = s / m[i][i]
    return out


def expm4(b):
    """``exp(b)`` of a 4 x 4 matrix (nested lists or an array): Pade [6/6] of ``b / 2^s``,
    ``s`` the fewest halvings that bring its infinity norm to ``SCALED_NORM``, then squared
    ``s`` times. Returns nested lists."""
    norm = max(sum(abs(float(b[i][j])) for j in range(4)) for i in range(4))
    s = 0
    while norm > SCALED_NORM and s < MAX_SQUARINGS:
        norm *= 0.5
        s += 1
    scale = math.ldexp(1.0, -s)
    x = [[float(b[i][j]) * scale for j in range(4)] for i in range(4)]
    x2 = _mul(x, x)
    x4 = _mul(x2, x2)
    x6 = _mul(x4, x2)
    c = PADE
    odd = [
        [(c[1] if i == j else 0.0) + c[3] * x2[i][j] + c[5] * x4[i][j] for j in range(4)]
        for i in range(4)
    ]
    u = _mul(x, odd)
    v = [
        [
            (c[0] if i == j else 0.0) + c[2] * x2[i][j] + c[4] * x4[i][j] + c[6] * x6[i][j]
            for j in range(4)
        ]
        for i in range(4)
    ]
    e = _solve(
        [[v[i][j] - u[i][j] for j in range(4)] for i in range(4)],
        [[v[i][j] + u[i][j] for j in range(4)] for i in range(4)],
    )
    for _ in range(s):
        e = _mul(e, e)
    return e


def coupled_flow(x_n, x_t, u_n, u_t, h, k_n, k_t, c_n, c_t, w_nn, w_nt, w_tt, a_n, a_t):
    """``(x_n, x_t, u_n, u_t)`` after ``h`` of ``x' = u, u' = a - W (S x + C u)``, ``W =
    [[w_nn, w_nt], [w_nt, w_tt]]`` (positive definite), ``S = diag(k_n, k_t)``, ``C =
    diag(c_n, c_t)``: exactly, about the equilibrium ``S^-1 W^-1 a``, the rates in units of
    ``omega = sqrt(max(w_nn k_n, w_tt k_t))`` so that the matrix's entries are all of the
    order of ``omega h``."""
    det = w_nn * w_tt - w_nt * w_nt
    e_n = (w_tt * a_n - w_nt * a_t) / det / k_n
    e_t = (w_nn * a_t - w_nt * a_n) / det / k_t
    omega = math.sqrt(max(w_nn * k_n, w_tt * k_t))
    b = [
        [0.0, 0.0, omega * h, 0.0],
        [0.0, 0.0, 0.0, omega * h],
        [-w_nn * k_n * h / omega, -w_nt * k_t * h / omega, -w_nn * c_n * h, -w_nt * c_t * h],
        [-w_nt * k_n * h / omega, -w_tt * k_t * h / omega, -w_nt * c_n * h, -w_tt * c_t * h],
    ]
    e = expm4(b)
    z = (x_n - e_n, x_t - e_t, u_n / omega, u_t / omega)
    y = [sum(e[i][j] * z[j] for j in range(4)) for i in range(4)]
    return y[0] + e_n, y[1] + e_t, y[2] * omega, y[3] * omega


def coupled_impulses(
    depth,
    approach,
    slip,
    xi,
    fresh,
    approach_change,
    slip_change,
    last_force,
    h,
    k_n,
    c_n,
    k_t,
    c_t,
    inv_n,
    inv_t,
    k_nt,
    mu,
):
    """``contact_step.pair_impulses`` with the normal and the stuck tangent solved as one
    system (module docstring): the same arguments and returns, with ``k_nt``, the cross
    term of the pair's inverse mass (1/kg), and ``mu``, the friction the step would slide
    at (Coulomb's, or rate and state's ``mu0``: its mu is solved after the impulses). The
    returned accelerations are the other forces', all of the contact's own out (its cross
    term too, also where it hands over: the work is booked with its own change, cross term
    included, ``reference_contact.contact_force``).

    Written as its Taichi twin runs it, each solution once in the code: the joint flow in a
    loop of two stages (since the onset, then the step), then at most one 1D normal solve
    (sliding, or handed over) and one tangential (handed over)."""
    w_nt = -k_nt
    det = inv_n * inv_t - w_nt * w_nt
    a_n = approach_change / h
    a_t = slip_change / h
    tau = 0.0
    a_n_pair, a_t_pair = a_n, a_t  # pair_impulses' (its own normal and tangent out)
    if fresh:
        tau = onset(depth, approach, h)
    else:  # all of this contact's own forces of the last step out of the change
        g_n, g_t = last_force[0], -last_force[1]
        a_n_pair = a_n + inv_n * g_n
        a_t_pair = a_t + inv_t * g_t
        a_n = a_n_pair + w_nt * g_t
        a_t = a_t_pair + w_nt * g_n
    x_n, x_t, u_n, u_t = depth, xi, approach, slip
    y_n, y_t, v_n, v_t = x_n, x_t, u_n, u_t
    p0_n = p0_t = q0_n = q0_t = v0 = 0.0
    for stage in range(2):
        # The step's flow is skipped where the force pulls at its start: handed over anyway.
        if (stage == 1 and k_n * x_n + c_n * u_n >= 0.0) or (stage == 0 and tau > 0.0):
            # Stage 0, since onset: from no depth or stretch at the rates it had then; the
            # difference from the free flight to now is what the forces did. 1: the step.
            span, i_n, i_t, j_n, j_t = h, x_n, x_t, u_n, u_t
            if stage == 0:
                span, i_n, i_t, j_n, j_t = tau, 0.0, 0.0, u_n - a_n * tau, u_t - a_t * tau
            o_n, o_t, r_n, r_t = coupled_flow(
                i_n, i_t, j_n, j_t, span, k_n, k_t, c_n, c_t, inv_n, w_nt, inv_t, a_n, a_t
            )
            if stage == 0:
                dn, dt_ = u_n - r_n, u_t - r_t
                p0_n = (inv_t * dn - w_nt * dt_) / det
                p0_t = (inv_n * dt_ - w_nt * dn) / det
                dn, dt_ = x_n - o_n, x_t - o_t
                q0_n = (inv_t * dn - w_nt * dt_) / det
                q0_t = (inv_n * dt_ - w_nt * dn) / det
                v0 = c_n * o_n
                x_n, x_t, u_n, u_t = o_n, o_t, r_n, r_t
            else:
                y_n, y_t, v_n, v_t = o_n, o_t, r_n, r_t
    fallback = k_n * x_n + c_n * u_n < 0.0 or k_n * y_n + c_n * v_n < 0.0
    dn, dt_ = u_n + a_n * h - v_n, u_t + a_t * h - v_t
    p_n = p0_n + (inv_t * dn - w_nt * dt_) / det
    p_t = p0_t + (inv_n * dt_ - w_nt * dn) / det
    dn = x_n + u_n * h + 0.5 * a_n * h * h - y_n
    dt_ = x_t + u_t * h + 0.5 * a_t * h * h - y_t
    q_n = q0_n + h * p0_n + (inv_t * dn - w_nt * dt_) / det
    q_t = q0_t + h * p0_t + (inv_n * dt_ - w_nt * dn) / det
    p_v = v0 + c_n * (y_n - x_n)
    xi1 = y_t
    # Sliding: the tangential force is sign mu times the normal one, so the normal moves
    # alone at K_nn - sign mu K_nt; the stuck p_t stays (the cap, ``stick_or_slide``, takes
    # mu times this normal impulse). Handed over: pair_impulses' two 1D solves.
    sliding = not fallback and abs(p_t) > mu * p_n
    sign = -1.0 if p_t < 0.0 else 1.0
    inv_slide = inv_n - sign * mu * k_nt
    if sliding and not inv_slide > 0.0:
        fallback = True
    if fallback or sliding:
        inv_m, a_m = (inv_n, a_n_pair) if fallback else (inv_slide, a_n)
        p_n, q_n, p_v, _, _ = spring_dashpot(depth, approach, h, k_n, c_n, inv_m, a_m, True, tau)
    if fallback:
        p_t, q_t, _, xi1, _ = spring_dashpot(xi, slip, h, k_t, c_t, inv_t, a_t_pair, False, tau)
    return p_n / h, (p_n - p_v) / h, q_n, p_t, q_t, xi1, a_n, a_t
