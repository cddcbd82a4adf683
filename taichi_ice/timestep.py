"""The stable time step of the explicit contact integration.

A contact is a spring ``k = k_e L`` (``k_e`` the contact stiffness per metre of contact
width, ``L`` the contact width) with a dashpot ``c = k_v L`` between two bodies. Semi-implicit
(symplectic) Euler integrates a damped oscillator ``m x'' + c x' + k x = 0`` stably for

    dt < (2 / w) (sqrt(1 + z^2) - z),   w = sqrt(k / m_eff),   z = c / (2 sqrt(k m_eff)),

(the undamped limit 2/w, lowered by the explicit dashpot). The stiffest contact is the widest
one a body's edge allows (``L`` = its longest edge) and the lightest effective mass is that
of two such bodies hit at their farthest corner, where rotation makes them feel lighter:
``1 / m_eff = 2 (1 / m + R^2 / I)``, ``R`` the circumradius about the centroid.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from .geometry import longest_edge, mass_properties

# dt = "auto" takes this fraction of the stability limit: a contact oscillation then spans
# at least ~30 steps, so overlaps, contact widths and the friction memory are resolved. A jam
# at full load survives 1.42 x the limit, so this keeps 7.1 x; accuracy, not stability, sets
# it (docs/accuracy.md, "Decision").
DEFAULT_SAFETY = 0.2


def body_contact_limit(
    vertices: np.ndarray, density: float, thickness: float, stiffness: float, viscosity: float
) -> float:
    """Stability limit (s) of the stiffest contact between two copies of one dynamic body.

    Args:
        vertices: ``(n, 2)`` counter-clockwise outline, relative to any origin (m).
        density: ice density (kg/m^3). thickness: ice thickness (m).
        stiffness: contact stiffness ``k_e`` (N/m per m of contact width).
        viscosity: contact viscosity ``k_v`` (Pa s per m of contact width).
    """
    area, centroid, polar = mass_properties(vertices)
    mass = density * thickness * area
    inertia = density * thickness * polar
    rel = np.asarray(vertices, dtype=np.float64) - centroid
    radius = float(np.max(np.hypot(rel[:, 0], rel[:, 1])))
    width = longest_edge(rel)
    m_eff = 1.0 / (2.0 * (1.0 / mass + radius * radius / inertia))
    k = stiffness * width
    c = viscosity * width
    w = math.sqrt(k / m_eff)
    z = c / (2.0 * math.sqrt(k * m_eff))
    return (2.0 / w) * (math.sqrt(1.0 + z * z) - z)


def stable_time_step(
    outlines: Iterable[np.ndarray],
    density: float,
    thickness: float,
    stiffness: float,
    viscosity: float,
) -> float:
    """Largest stable dt (s) over the outlines of a scene's dynamic bodies.

    Returns ``inf`` when there is no dynamic body (nothing to integrate).
    """
    limit = math.inf
    seen: set[bytes] = set()
    for v in outlines:
        v = np.asarray(v, dtype=np.float64)
        key = v.tobytes()
        if key in seen:  # a lattice repeats one outline thousands of times
            continue
        seen.add(key)
        limit = min(limit, body_contact_limit(v, density, thickness, stiffness, viscosity))
    return limit
