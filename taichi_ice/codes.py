"""Integer codes shared by the host and the kernels, each defined once.

Every code that crosses from Python into a Taichi field or kernel (a body's kind, the
integrator of the state variable, a column of the energy table, a status flag) is an
``IntEnum`` here. The kernels compare field values against these members (resolved at
compile time); files and messages use their ``label``.

Plain Python, no Taichi: the scene parser and the NumPy references import it too.
"""

from __future__ import annotations

from enum import IntEnum


class _Labelled(IntEnum):
    """An IntEnum whose members have a lower-case, hyphenated name for files and messages."""

    @property
    def label(self) -> str:
        return self.name.lower().replace("_", "-")

    @classmethod
    def labels(cls) -> tuple[str, ...]:
        """Every member's label, in code order."""
        return tuple(m.label for m in cls)

    @classmethod
    def from_label(cls, label: str):
        """The member whose ``label`` is ``label``.

        Raises:
            ValueError: no such member; the message lists the labels.
        """
        for m in cls:
            if m.label == label:
                return m
        raise ValueError(f"unknown {cls.__name__} {label!r}; choose one of {cls.labels()}")


class BodyKind(_Labelled):
    """How a body moves (``[[body]] kind``; ``/bodies/kinds`` in the output)."""

    DYNAMIC = 0  # integrated from the forces on it
    FIXED = 1  # never moves (walls, a pillar); infinite mass
    KINEMATIC = 2  # moves at its prescribed velocity (a pusher) and does work on the rest


class ThetaMethod(_Labelled):
    """Integrator of the rate-and-state variable over a step (``friction.theta_step``)."""

    EXPONENTIAL = 0  # exact for constant slip rate; second order with V at the half step
    EULER = 1  # explicit; first order; unstable for dt > 2 t_c
    IMPLICIT = 2  # backward Euler; first order; stable at any step
    RK4 = 3  # classic Runge-Kutta; unstable for dt > 2.785 t_c


class EnergyTerm(_Labelled):
    """Columns of a world's energy table (J); see ``taichi_ice.run.budget``.

    ``KINETIC`` and ``ELASTIC`` are what the world holds now; every other term accumulates
    over a run.
    """

    FRICTION = 0  # dissipated by frictional slip (the paper's Figure 6)
    VISCOUS = 1  # dissipated by the normal and tangential contact dashpots
    DRAG = 2  # dissipated by water drag
    WORK_IN = 3  # work done by kinematic bodies and external forces
    KINETIC = 4  # kinetic energy, translational + rotational
    ELASTIC = 5  # elastic energy in overlaps and tangential springs
    CRUSHING = 6  # dissipated by crushing: overlap beyond the ice's strength, not recovered
    SEVERED = 7  # held by contacts (overlap and stick spring) when they ended (see BodyEnergy)
    # Work done on the floes by the forcing (see BodyEnergy): 0 in a scene without it.
    WIND = 8  # by the wind's drag
    CURRENT = 9  # by the current, through the water drag (the drag's power on the current)
    TILT = 10  # by the sea-surface tilt of a geostrophic current


class BodyEnergy(_Labelled):
    """Columns of the per-body energy accumulators (J): each body's thread owns its row,
    so no atomics; the energy stage sums them per world in a fixed order."""

    FRICTION = 0  # slip work of the contacts this body owns
    VISCOUS = 1  # dashpot work of the contacts this body owns
    DRAG = 2  # water drag dissipation on this body
    WORK = 3  # work done by this body (kinematic) or on it by its external force
    CRUSHING = 4  # crushing work of the contacts this body owns
    # Elastic energy this body's contacts still held when they ended: the work done on
    # their overlaps and stick springs that no force gave back. The normal force follows the
    # overlap's area and the spring's stiffness the contact width, neither a potential, so
    # floes that slide apart (a crushed overlap above all) take energy along that the step
    # size does not change; a spring that stiffened while stretched gives back more than it
    # took (negative).
    SEVERED = 5
    # The forcing's work on this body (kept only where a scene has a current or wind:
    # ``schema.Layout.forced``). The water drag on a floe at v in a current u does F.v =
    # F.u + F.(v - u): the current's work F.u, and -F.(v - u) >= 0 dissipated (DRAG).
    WIND = 6  # F_air.v, the wind's drag
    CURRENT = 7  # F_water.u
    TILT = 8  # m f (k x u).v, the sea-surface tilt of a geostrophic current


class RestRule(_Labelled):
    """What a rate-and-state contact's memory does while it slides slower than ``v_star``
    (``below_v_star`` of the laws; ``slip.contact_friction``)."""

    PAPER = 0  # the paper: mu = mu0 exactly; the interface ends, and one that slides again
    #            is a new interface, its theta in equilibrium at its slip rate
    HEALING = 1  # theta keeps relaxing toward 0 (the equilibrium at v_star) over t_c, and
    #              mu = max(mu0 + theta, 0): the aging law's healing
    FROZEN = 2  # theta is held, mu = max(mu0 + theta, 0), until the contact slides again
    RELAXING = 3  # the paper's mu = mu0 exactly, but the interface is kept: theta relaxes
    #               toward 0 over t_c as under HEALING, and slides on from there


class Status(_Labelled):
    """Entries of the status word the kernels raise and ``World.check`` reads."""

    SLOT_OVERFLOW = 0  # most contacts any body needed this step (compare with the slots)
    NONFINITE = 1  # 1 if a body's velocity became non-finite
    RUNAWAY = 2  # 1 if a body moved more than the runaway distance in one step
    LIST_OVERFLOW = 3  # most neighbour-list entries any body needed (compare with nbr_len)


class OverlapKind(_Labelled):
    """How the contact geometry of two polygons was found (``polygon.overlap``)."""

    NONE = 0  # separated or touching: no contact, every other field is zero
    CHORD = 1  # the boundaries cross exactly twice: normal and width from that chord
    FALLBACK = 2  # containment, collinear edges or more than two crossings: SAT axis


__all__ = [
    "BodyEnergy",
    "BodyKind",
    "EnergyTerm",
    "OverlapKind",
    "RestRule",
    "Status",
    "ThetaMethod",
]
