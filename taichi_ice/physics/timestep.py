"""The stable time step of the explicit contact integration.

A contact is a spring ``k = k_e L`` (``k_e`` the contact stiffness per metre of contact
width, ``L`` the contact width) with a dashpot ``c = k_v L`` between two bodies, and along
the tangent a stick spring ``k_t = r k_e L`` with a dashpot that damps it to ``zeta`` of
critical (``contact_law.tangential_damping``). Semi-implicit (symplectic) Euler integrates a
damped oscillator ``m x'' + c x' + k x = 0`` stably for

    dt < (2 / w) (sqrt(1 + z^2) - z),   w = sqrt(k / m_eff),   z = c / (2 sqrt(k m_eff)),

(the undamped limit 2/w, lowered by the explicit dashpot; the tangential step, whose trial
stretch takes the start-of-step slip, has the same limit). The stiffest contact is the
widest one a body's edge allows (``L`` = its longest edge) and the lightest effective mass
is that of two such bodies hit at their farthest corner, where rotation makes them feel
lighter: ``1 / m_eff = 2 (1 / m + R^2 / I)``, ``R`` the circumradius about the centroid. The
limit is the smaller of the normal and the tangential oscillator's: at the defaults
(``r = 0.5``, ``zeta = 0.25``) the normal one (the tangential one is ``1.53 / w_t`` with
``w_t = sqrt(r) w``; a critically damped spring's, ``0.83 / w_t``, would bind).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from ..codes import BodyKind
from ..errors import StabilityError
from .polygon import longest_edge, mass_properties, min_width

# How a step moves the bodies (``Options.integrator``): "euler", semi-implicit Euler with the
# contact forces of the step's start (first order); "analytic", each contact's spring-dashpot
# integrated exactly over the step (``physics.contact_step``; second order); "coupled", the
# analytic step with each contact's normal and tangent solved together over the step
# (``physics.contact_coupled``: the bodies' turning couples them); "midstep", the coupled
# step with each contact linearised about the configuration predicted for mid-step (its
# normal, point and lever arms: held at the step's start they are a first-order error of the
# bodies' turn; ``reference_contact.contact_force``'s ``mid``).
INTEGRATORS = ("euler", "analytic", "coupled", "midstep")

# dt = "auto" takes this fraction of the stability limit with Coulomb friction and the Euler
# step (and the analytic and coupled steps): a contact oscillation then spans at least ~30
# steps, so overlaps, contact widths and the friction memory are resolved. A jam at full
# load survives 1.27-1.42 x the limit, so this keeps over 6 x; accuracy, not stability, sets
# it (docs/accuracy.md, "So the default step"): over 256 pillar layouts Coulomb's statistics
# at 0.2 and 0.05 agree (peak force -0.6 % [-4.7, +3.5]).
DEFAULT_SAFETY = 0.2
# ... and with Coulomb friction and the midstep step, Coulomb's default integrator since
# 2026-12-02 (``default_integrator``): the largest of ``dem_stability.CANDIDATES`` that keeps
# 2 x below the jam's limit (1.42 x: 2.37 x) with every error of Coulomb's within
# ``dem_analysis.ACCURACY`` (the pillar's frictional energy 1.5 %, the offset collision's
# spin 0.7 %; ``dem_accuracy``'s ``recommendation_by_law``), whose pillar statistics over 256
# layouts agree with the Euler step's at 0.05 within 1.6 % (docs/accuracy.md, "So the
# default step").
MIDSTEP_SAFETY = 0.6
# ... and with a law that has a memory (rate-and-state, steady-state, memory-only), with
# every integrator: over 256 pillar layouts the Euler step's peak force at 0.2 and at 0.1
# stands +9.8 % and +9.5 % above a sixteenth of the default step (both p < 0.01), at 0.05
# +0.4 % [-5.6, +6.4]; the midstep step's at 0.4 +10.5 % (docs/accuracy.md).
RATE_STATE_SAFETY = 0.05


def default_integrator(law: str) -> str:
    """The integrator a scene of the friction law named ``law`` (``Law.name``) steps with
    unless its file or the engine's options name one: "midstep" for ``"coulomb"`` (second
    order in a collision, and at three times the Euler step's default it holds the pillar's
    statistics; docs/accuracy.md), "euler" for every law with a memory (the midstep step
    does not take their pillar statistics past the Euler step's 0.05)."""
    return "midstep" if law == "coulomb" else "euler"


def default_safety(law: str, integrator: str | None = None) -> float:
    """The fraction of the stability limit ``dt = "auto"`` takes for the friction law named
    ``law`` stepped by ``integrator`` (None: the law's, ``default_integrator``):
    ``MIDSTEP_SAFETY`` for Coulomb with the midstep step, ``DEFAULT_SAFETY`` for Coulomb
    with the others, ``RATE_STATE_SAFETY`` for every law with a memory."""
    if law != "coulomb":
        return RATE_STATE_SAFETY
    integrator = default_integrator(law) if integrator is None else integrator
    return MIDSTEP_SAFETY if integrator == "midstep" else DEFAULT_SAFETY


def oscillator_limit(k: float, c: float, m_eff: float) -> float:
    """Largest stable step (s) of symplectic Euler on ``m_eff x'' + c x' + k x = 0``."""
    w = math.sqrt(k / m_eff)
    z = c / (2.0 * math.sqrt(k * m_eff))
    if z <= 1.0:
        return (2.0 / w) * (math.sqrt(1.0 + z * z) - z)
    # The same limit as (2 / w) / (sqrt(1 + z^2) + z): the difference above cancels to 0 for
    # a heavily damped contact (z > 1e8, where the limit is ~ 2 m_eff / c); hypot and the
    # division in two stay finite where z or w are huge. (Below z = 1 the difference loses
    # nothing, and keeps every existing scene's dt to the last bit.)
    return (2.0 / w) / (math.hypot(1.0, z) + z)


def _stiffest_contact(vertices: np.ndarray, density: float, thickness: float):
    """``(m_eff, L)`` of the stiffest contact between two copies of one body: the effective
    mass of two such bodies hit at their farthest corner (kg) and the widest contact its
    edges allow (its longest edge, m)."""
    area, centroid, polar = mass_properties(vertices)
    mass = density * thickness * area
    inertia = density * thickness * polar
    rel = np.asarray(vertices, dtype=np.float64) - centroid
    radius = float(np.max(np.hypot(rel[:, 0], rel[:, 1])))
    m_eff = 1.0 / (2.0 * (1.0 / mass + radius * radius / inertia))
    return m_eff, longest_edge(rel)


def body_contact_limit(
    vertices: np.ndarray,
    density: float,
    thickness: float,
    stiffness: float,
    viscosity: float,
    tangential_stiffness: float = 0.5,
    tangential_damping: float = 0.25,
) -> float:
    """Stability limit (s) of the stiffest contact between two copies of one dynamic body.

    Args:
        vertices: ``(n, 2)`` counter-clockwise outline, relative to any origin (m).
        density: ice density (kg/m^3). thickness: ice thickness (m).
        stiffness: contact stiffness ``k_e`` (N/m per m of contact width).
        viscosity: contact viscosity ``k_v`` (Pa s per m of contact width).
        tangential_stiffness: ``k_t / (k_e L)``. tangential_damping: the tangential dashpot's
            fraction of critical damping.
    """
    m_eff, width = _stiffest_contact(vertices, density, thickness)
    normal = oscillator_limit(stiffness * width, viscosity * width, m_eff)
    k_t = tangential_stiffness * stiffness * width
    tangential = oscillator_limit(k_t, 2.0 * tangential_damping * math.sqrt(k_t * m_eff), m_eff)
    return min(normal, tangential)


def contact_damping(
    vertices: np.ndarray, density: float, thickness: float, stiffness: float, viscosity: float
) -> tuple[float, float]:
    """``(m_eff, z)`` of the stiffest contact between two copies of one dynamic body (the
    effective mass, kg, and the normal dashpot's fraction of critical damping that
    ``body_contact_limit`` uses): what an error message says sets the limit."""
    m_eff, width = _stiffest_contact(vertices, density, thickness)
    k, c = stiffness * width, viscosity * width
    return m_eff, c / (2.0 * math.sqrt(k) * math.sqrt(m_eff))


def stable_time_step(
    outlines: Iterable[np.ndarray],
    density: float,
    thickness: float,
    stiffness: float,
    viscosity: float,
    tangential_stiffness: float = 0.5,
    tangential_damping: float = 0.25,
) -> float:
    """Largest stable dt (s) over the outlines of a scene's dynamic bodies (the arguments
    of ``body_contact_limit``).

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
        limit = min(
            limit,
            body_contact_limit(
                v,
                density,
                thickness,
                stiffness,
                viscosity,
                tangential_stiffness,
                tangential_damping,
            ),
        )
    return limit


# The largest overlap a collision may reach, as a fraction of the thinnest dynamic body: the
# contact is a spring on the overlap area, and two blocks that close faster than the spring
# can stop them within this depth pass through each other (two 1 m squares head-on at
# +-1,000 m/s ended on each other's side, the run "complete").
PENETRATION_FRACTION = 0.25


def check_approach(scene) -> None:
    """Refuse a scene whose bodies start fast enough to pass through each other: two bodies
    closing at twice the fastest start speed (a dynamic or kinematic body's centroid speed
    plus its spin at its farthest corner) overlap by ``v / w``, ``w = 2 / stable_dt`` the
    fastest contact oscillation; more than ``PENETRATION_FRACTION`` of the thinnest dynamic
    body is refused. Speeds a jam gives later are watched by the runaway check.

    Two 1 m squares head-on (``two_squares``, bound 275 m/s): at 100, 250 and 400 m/s each
    they bounce back; at 700 and 1,000 m/s they pass through each other."""
    dynamic = [b for b in scene.bodies if b.kind == BodyKind.DYNAMIC.label]
    if not dynamic:
        return
    thinnest = min(min_width(b.vertices) for b in dynamic)
    w = 2.0 / scene.stable_dt
    allowed = PENETRATION_FRACTION * thinnest * w / 2.0  # per body, two closing head-on
    for b in scene.bodies:
        if b.kind == BodyKind.FIXED.label:
            continue
        reach = float(np.max(np.linalg.norm(np.asarray(b.vertices), axis=1)))
        speed = float(np.linalg.norm(b.velocity)) + abs(float(b.omega)) * reach
        if speed > allowed:
            raise StabilityError(
                f"{scene.source}: body {b.name} starts at {speed:.4g} m/s; colliding at that "
                f"speed, blocks would overlap by more than {PENETRATION_FRACTION:g} of the "
                f"thinnest block ({thinnest:.3g} m) and could pass through each other: the "
                f"contact stiffness resolves at most {allowed:.4g} m/s; lower the speed, or "
                "raise [ice] contact_stiffness"
            )
