"""Water drag on a floe: quadratic form and skin drag, translational and rotational.

A floe of plan area ``S`` and thickness ``d`` floats with draft ``h = rho_i d / rho_w``. Its
outline is taken as the disc of equal area, radius ``R = sqrt(S / pi)``, diameter ``D = 2R``:

    F = -c_lin |v| v,       c_lin = rho_w / 2 (C_form h D + C_skin S)
    T = -c_rot |w| w,       c_rot = rho_w / 2 (C_form h 2 pi R^4 + C_skin 2 pi R^5 / 5)

The form term acts on the submerged frontal area ``h D``; the skin term on the wetted base.
For rotation each element of the rim (``2 pi R`` of it, lever ``R``, speed ``w R``) and of the
base (``integral r^3 dA = 2 pi R^5 / 5``) adds the same quadratic law. Still water; the
coefficients are the scene's ``[water] form_drag`` and ``skin_drag``.

NumPy only: the Taichi twin of ``water_drag`` is ``drag_ti.water_drag_ti``.
"""

from __future__ import annotations

import math

import numpy as np


def drag_coefficients(
    area: float,
    thickness: float,
    ice_density: float,
    water_density: float,
    form: float,
    skin: float,
) -> tuple[float, float]:
    """(c_lin in kg/m, c_rot in kg m^2) of one floe; see the module docstring."""
    draft = ice_density * thickness / water_density
    radius = math.sqrt(area / math.pi)
    c_lin = 0.5 * water_density * (form * draft * 2.0 * radius + skin * area)
    c_rot = (
        0.5
        * water_density
        * (form * draft * 2.0 * math.pi * radius**4 + skin * 2.0 * math.pi * radius**5 / 5.0)
    )
    return c_lin, c_rot


def water_drag(vel, omega, c_lin, c_rot):
    """Drag force (N) and torque (N m) on floes moving at ``vel`` (m/s), ``omega`` (rad/s).

    Args:
        vel: ``(N, 2)`` velocities. omega: ``(N,)`` angular velocities.
        c_lin: ``(N,)`` kg/m. c_rot: ``(N,)`` kg m^2 (``drag_coefficients``).

    Returns:
        ``(force (N, 2), torque (N,))``.
    """
    vel = np.asarray(vel, dtype=np.float64)
    speed = np.linalg.norm(vel, axis=-1, keepdims=True)
    return -np.asarray(c_lin)[..., None] * speed * vel, -np.asarray(c_rot) * np.abs(omega) * omega
