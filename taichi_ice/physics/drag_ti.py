"""Water drag on a floe as a Taichi function: the twin of ``drag.water_drag``.

The drag law, its coefficients (``drag.drag_coefficients``) and its NumPy reference live in
``drag``; this module holds only the function the integrator's kernel calls.
"""

from __future__ import annotations

import taichi as ti


@ti.func
def water_drag_ti(vel, omega, c_lin, c_rot):
    """Taichi twin of :func:`drag.water_drag` for one body (2-vector ``vel``)."""
    return -c_lin * vel.norm() * vel, -c_rot * ti.abs(omega) * omega
