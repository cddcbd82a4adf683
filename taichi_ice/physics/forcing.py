"""Ocean current, wind and the Earth's rotation on a floe: the laws, in NumPy.

A dynamic floe of mass ``m``, plan area ``S``, moving at ``v`` through water that moves at
``u`` (the current) under air that moves at ``U`` (the wind), feels

    F_water = -c_lin |v - u| (v - u)            (``drag.water_drag`` of the relative velocity)
    F_air   =  c_air |U - v| (U - v),    c_air = rho_a C_a S
    F_cor   = -m f k x v                        (Coriolis; k the vertical unit vector)
    F_tilt  =  m f k x u                        (sea-surface tilt, where u is geostrophic)

``k x (x, y) = (-y, x)``: with ``f > 0`` (northern hemisphere) Coriolis turns a floe to the
right of its motion. A geostrophic current is one the pressure gradient of the tilted sea
surface holds against Coriolis, ``f k x u = -g grad(eta)``, so the tilt pushes a floe with
``m f k x u``: a floe at the current's velocity feels no net force from the two.

The air drag is the bulk formula of the wind stress on sea ice (rho_a C_a |U| U on the plan
area; Hibler 1979, doi:10.1175/1520-0485(1979)009<0815:ADTSIM>2.0.CO;2, took C_a = 1.2e-3;
Leppäranta 2011, *The Drift of Sea Ice*, gives 1.2e-3 to 2e-3 over sea ice), applied to the
wind relative to the floe. The water drag keeps the form and skin law of ``drag``, on the
velocity relative to the current.

Coriolis is integrated with the trapezoidal rule (``coriolis_step``): the velocity update
solves ``v1 = v0 + dt a - f dt k x (v0 + v1) / 2``, a rotation of the velocity that keeps its
length, so Coriolis does no work over a step, and stays stable at any ``f dt`` (an explicit
Euler step would add ``(f dt)^2 / 2`` of the kinetic energy every step).

Gridded fields are sampled by ``grid_sample``: bilinear in x and y, linear in t, constant
beyond the grid's ends, written as ``a0 + w (a1 - a0)`` so that a field equal at both nodes
comes back exactly (a uniform field given on a grid runs bit for bit as the uniform one).

NumPy only: the Taichi twins are ``forcing_ti``.
"""

from __future__ import annotations

import math

import numpy as np

# The Earth's rotation rate (sidereal day), rad/s: f = 2 OMEGA sin(latitude).
EARTH_ROTATION = 7.2921e-5
# Defaults of the [wind] table: the International Standard Atmosphere at sea level, and
# Hibler's (1979) air-ice drag coefficient (see the module docstring).
AIR_DENSITY = 1.225  # kg/m^3
AIR_DRAG = 1.2e-3  # C_a, dimensionless


def coriolis_parameter(latitude: float) -> float:
    """f = 2 Omega sin(latitude) (1/s) for a ``latitude`` in degrees (north positive)."""
    return 2.0 * EARTH_ROTATION * math.sin(math.radians(latitude))


def air_drag_coefficient(area: float, air_density: float, drag: float) -> float:
    """``c_air = rho_a C_a S`` (kg/m) of a floe of plan area ``area`` (m^2)."""
    return air_density * drag * area


def air_drag(vel, wind, c_air):
    """Wind drag (N) on floes moving at ``vel`` under air moving at ``wind`` (m/s).

    Args:
        vel, wind: ``(..., 2)``. c_air: ``(...)`` kg/m (``air_drag_coefficient``).
    """
    rel = np.asarray(wind, dtype=np.float64) - np.asarray(vel, dtype=np.float64)
    speed = np.linalg.norm(rel, axis=-1, keepdims=True)
    return np.asarray(c_air)[..., None] * speed * rel


def cross_k(vec):
    """``k x vec`` for 2-vectors ``(..., 2)``: ``(-y, x)``."""
    vec = np.asarray(vec, dtype=np.float64)
    return np.stack([-vec[..., 1], vec[..., 0]], axis=-1)


def tilt_acceleration(f, current):
    """Sea-surface tilt per unit mass (m/s^2), ``f k x u``, of a geostrophic ``current``."""
    return np.asarray(f)[..., None] * cross_k(current)


def coriolis_step(v0, accel, f, dt):
    """Velocity after a step of ``dt`` with the acceleration ``accel`` and Coriolis taken at
    the step's mean velocity (trapezoidal rule, see the module docstring).

    Solves ``v1 = v0 + dt accel - b k x (v0 + v1)``, ``b = f dt / 2``, with
    ``(I + b K)^-1 = (I - b K) / (1 + b^2)`` (``K`` the matrix of ``k x``, ``K^2 = -I``). The
    operations are those of ``forcing_ti.coriolis_step_ti``, in the same order.

    Args:
        v0, accel: ``(2,)`` m/s and m/s^2. f: 1/s. dt: s.
    """
    v0 = np.asarray(v0, dtype=np.float64)
    b = 0.5 * f * dt
    w = v0 + dt * np.asarray(accel, dtype=np.float64)
    w = w + b * np.array([v0[1], -v0[0]])
    return (w + b * np.array([w[1], -w[0]])) / (1.0 + b * b)


def coriolis_force(mass, f, v_mean):
    """Coriolis force (N), ``-m f k x v``, at the step's mean velocity ``v_mean``: what
    ``coriolis_step`` applies; it is perpendicular to ``v_mean``, so it does no work."""
    return -mass * f * cross_k(v_mean)


def grid_cell(s: float, n: int) -> tuple[int, int, float]:
    """Lower and upper node and the weight of the upper one at fractional index ``s`` of an
    axis of ``n`` nodes, ``s`` clamped to ``[0, n - 1]`` (constant beyond the ends)."""
    s = min(max(s, 0.0), n - 1.0)
    i0 = min(math.floor(s), max(n - 2, 0))
    return i0, min(i0 + 1, n - 1), s - i0


def _lerp(a0, a1, w):
    return a0 + w * (a1 - a0)


def grid_sample(values, origin, spacing, x: float, y: float, t: float = 0.0):
    """A 2-vector field on a regular grid at the point ``(x, y)`` and time ``t``.

    Args:
        values: ``(nt, ny, nx, 2)`` the field at the nodes (t major, x fastest).
        origin: ``(x0, y0, t0)`` of the first node (m, m, s). spacing: ``(dx, dy, dt)`` between
            nodes (an axis of one node: any positive value).
        x, y: m. t: s.

    Returns:
        ``(2,)``: bilinear in x and y, linear in t, constant beyond the grid's ends, in the
        order of ``Forcing.sample`` (x, then y, then t).
    """
    values = np.asarray(values, dtype=np.float64)
    nt, ny, nx = values.shape[:3]
    ix = grid_cell((x - origin[0]) / spacing[0], nx)
    iy = grid_cell((y - origin[1]) / spacing[1], ny)
    it = grid_cell((t - origin[2]) / spacing[2], nt)

    def plane(k):
        lo = _lerp(values[k, iy[0], ix[0]], values[k, iy[0], ix[1]], ix[2])
        hi = _lerp(values[k, iy[1], ix[0]], values[k, iy[1], ix[1]], ix[2])
        return _lerp(lo, hi, iy[2])

    return _lerp(plane(it[0]), plane(it[1]), it[2])


__all__ = [
    "AIR_DENSITY",
    "AIR_DRAG",
    "EARTH_ROTATION",
    "air_drag",
    "air_drag_coefficient",
    "coriolis_force",
    "coriolis_parameter",
    "coriolis_step",
    "cross_k",
    "grid_cell",
    "grid_sample",
    "tilt_acceleration",
]
