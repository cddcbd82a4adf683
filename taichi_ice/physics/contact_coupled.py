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
``x_eq = S^-1 W^-1 a`` it is ``z' = A z``, solved by the exponential of ``A h`` times ``z``
(:func:`flow_times`: its Taylor series in pieces, in balanced units). The bodies take the
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

__all__ = [
    "MAX_PIECES",
    "MAX_TERMS",
    "PIECE_NORM",
    "REACH",
    "SERIES_TOL",
    "coupled_flow",
    "coupled_impulses",
    "flow_times",
    "series_terms",
]

# exp(B) z by its Taylor series, B cut into pieces of infinity norm at most PIECE_NORM: at a
# piece's full norm 24 terms leave out less than 2^-53 of the result (``series_terms``); its
# largest term is at most twice |z|, so little is lost to cancellation.
PIECE_NORM = 2.0
MAX_TERMS = 30
# A norm of 131072, a step some 65,000 times the stability limit: no step a scene comes near
# (about 1 at the default); past it one piece, whose overflow the runaway check stops.
MAX_PIECES = 1 << 16
SERIES_TOL = 2.0**-53  # what the terms left out may add, against the result


def _reach(m: int) -> float:
    """The largest norm ``nu`` of a piece whose series' first ``m`` terms (after the 1) leave
    out at most ``SERIES_TOL`` of the result: what they leave out is at most ``|z| nu^(m+1) /
    (m+1)! / (1 - nu / (m+2))`` and the result is at least ``|z| exp(-nu)`` (infinity
    norms: ``z = exp(-B) exp(B) z``)."""

    def enough(nu: float) -> bool:
        rest = nu ** (m + 1) / math.factorial(m + 1) / (1.0 - nu / (m + 2))
        return rest * math.exp(nu) <= SERIES_TOL

    lo, hi = 0.0, PIECE_NORM
    if enough(hi):
        return hi
    for _ in range(100):  # bisection to the last bit
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if enough(mid) else (lo, mid)
    return lo


# REACH[m - 1]: the largest piece norm that m terms serve (m = 1 .. MAX_TERMS; 24 serve a
# piece's full norm, 18 a norm of 1, 14 of 0.5).
REACH = tuple(_reach(m) for m in range(1, MAX_TERMS + 1))


def series_terms(nu: float) -> int:
    """Terms of the series for a piece of norm ``nu``: the fewest that ``REACH`` allows
    (one where ``nu`` is not a number: the run has failed)."""
    terms = 1
    for reach in REACH:
        if reach < PIECE_NORM and nu > reach:
            terms += 1
    return terms


def _times(a, p00, p01, p10, p11, q00, q01, q10, q11, v0, v1, v2, v3):
    """``B v`` for ``B = [[0, a I], [P, Q]]``, in the Taichi twin's order."""
    return (
        a * v2,
        a * v3,
        p00 * v0 + p01 * v1 + q00 * v2 + q01 * v3,
        p10 * v0 + p11 * v1 + q10 * v2 + q11 * v3,
    )


def flow_times(a, p00, p01, p10, p11, q00, q01, q10, q11, z):
    """``exp(B) z`` for the flow's matrix ``B = [[0, a I], [P, Q]]`` (``P = [[p00, p01],
    [p10, p11]]``, ``Q`` alike; ``z`` four numbers): ``B`` cut into the fewest equal pieces of
    infinity norm at most ``PIECE_NORM``, each applied by the first terms of its Taylor series
    that the piece's norm says leave out at most ``SERIES_TOL`` of the result
    (``series_terms``; Al-Mohy and Higham's ``expm_multiply``, which SciPy has, chooses its
    terms from the norm alike). Only products of ``B`` with a vector, and those of its
    block form (10 multiplications), in a loop: the Pade exponential of the whole matrix it
    replaced (4 x 4 products, a solve, squarings, unrolled) took about 2.3x its time in
    the pillar's jam (docs/performance.md). The loop tests nothing as it goes: a test of
    each term against the sum cost as much as the term (docs/performance.md)."""
    norm = max(
        abs(a),
        abs(p00) + abs(p01) + abs(q00) + abs(q01),
        abs(p10) + abs(p11) + abs(q10) + abs(q11),
    )
    pieces = 1  # also where the norm is past MAX_PIECES' or not a number: the run has failed
    if PIECE_NORM < norm <= PIECE_NORM * MAX_PIECES:
        pieces = math.ceil(norm / PIECE_NORM)
    s = 1.0 / pieces
    b = (a * s, p00 * s, p01 * s, p10 * s, p11 * s, q00 * s, q01 * s, q10 * s, q11 * s)
    terms = series_terms(norm * s)
    y = tuple(z)
    for _ in range(pieces):
        t = y
        for k in range(1, terms + 1):
            r = 1.0 / k
            t = _times(*b, *t)
            t = (t[0] * r, t[1] * r, t[2] * r, t[3] * r)
            y = (y[0] + t[0], y[1] + t[1], y[2] + t[2], y[3] + t[3])
    return y


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
    z = (x_n - e_n, x_t - e_t, u_n / omega, u_t / omega)
    y = flow_times(
        omega * h,
        -w_nn * k_n * h / omega,
        -w_nt * k_t * h / omega,
        -w_nt * k_n * h / omega,
        -w_tt * k_t * h / omega,
        -w_nn * c_n * h,
        -w_nt * c_t * h,
        -w_nt * c_n * h,
        -w_tt * c_t * h,
        z,
    )
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
