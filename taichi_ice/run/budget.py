"""The energy budget of a world: its terms, the energy that came in, and the residual.

    came_in  = (kinetic + elastic)(0) + work_in + wind_work + current_work + tilt_work
    residual = came_in - (kinetic + elastic + friction + viscous + drag + crushing + severed)

``work_in`` is the work of kinematic bodies and external forces; ``wind_work``,
``current_work`` and ``tilt_work`` that of the forcing (``physics.forcing``: the wind's
drag, the current through the water drag, ``F_water . u``, and the sea-surface tilt of a
geostrophic current; 0 in a scene without them, and in files written before them; Coriolis
does no work); ``friction`` the slip work of contacts (the paper's Figure 6), ``viscous``
the contact dashpots (and the stick spring's backward-Euler step, a dashpot of
``k_t dt / 2``: ``contact_law.contact_work``), ``drag`` the water (the drag's power on the
floe's velocity relative to the current), ``crushing`` the overlap beyond the ice's
strength (0 unless ``[ice] crushing_strength``), ``severed`` the elastic energy contacts
still held when they ended (the normal force follows the overlap's area and the stick
spring's stiffness the contact width, neither a potential, so floes that slide apart take
work along that no force gives back; it can be negative; ``codes.BodyEnergy.SEVERED``);
``kinetic`` and ``elastic`` are what the world holds now (the overlaps and the tangential
springs). The contacts book their work at the velocity the bodies move with over the step,
so the residual is the time discretisation error of the explicit step alone: it shrinks
with dt, faster than first order (docs/accuracy.md). A divergence is judged without the
elastic term (``created``, ``breached``), and the whole residual at the end of a run.

The terms are ``codes.EnergyTerm`` columns in the kernels' energy table and named series
(``SERIES``) in run files and results. Plain NumPy: the engine, the plots, the ensemble
metrics and the paper's figures all use this module.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..codes import EnergyTerm

# The forcing's terms: work done on the floes (``<label>_work``).
_FORCING = (EnergyTerm.WIND, EnergyTerm.CURRENT, EnergyTerm.TILT)
# Series name of each term, in EnergyTerm order (the /series datasets of a run file).
SERIES: tuple[str, ...] = tuple(
    "work_in"
    if t == EnergyTerm.WORK_IN
    else f"{t.label}_work"
    if t in _FORCING
    else f"{t.label}_energy"
    for t in EnergyTerm
)
# The work done on a world: by kinematic bodies and external forces, and by the forcing.
WORK = ("work_in", "wind_work", "current_work", "tilt_work")
# The terms that hold energy now and the ones that accumulate its losses.
HELD = ("kinetic_energy", "elastic_energy")
DISSIPATED = (
    "friction_energy",
    "viscous_energy",
    "drag_energy",
    "crushing_energy",
    "severed_energy",
)

# The run is stopped as diverged once a world's kinetic energy and what it has dissipated
# exceed what came in by this fraction of it (``breached``): an explicit step past its
# stability limit creates energy from nothing, and it shows in the bodies' velocities or, in a
# jam that rattles, in what the contacts dissipate. The elastic term is left out: past the
# limit the contacts' booking of their work (at a mid-step velocity estimated from each
# body's last step) is no better than the step, and what a contact books as held leaves
# with it (docs/accuracy.md, "The divergence guard").
BREACH = 0.5
# Energy (J) below which a budget is not judged: round-off of an idle world.
BREACH_FLOOR = 1e-6


def series_name(term: EnergyTerm) -> str:
    """The series name of a term (``friction_energy``, ``work_in``)."""
    return SERIES[term]


def as_series(table: np.ndarray) -> dict[str, np.ndarray]:
    """``{series name: column}`` of an energy table whose last axis is the EnergyTerm
    columns (one world's row ``(E,)``, a world's history ``(T, E)``, ...)."""
    table = np.asarray(table)
    return {name: table[..., t] for t, name in enumerate(SERIES)}


def _initial(terms: Mapping[str, Any]) -> dict[str, Any]:
    # The first sample of each series: a run's budget starts at t = 0.
    # (Files written before the crushing, severed or forcing terms have none: they were 0.)
    return {k: np.asarray(terms.get(k, 0.0)).reshape(-1)[0] for k in SERIES}


def came_in(terms: Mapping[str, Any], initial: Mapping[str, Any] | None = None):
    """Energy that came into a world (J): what it held at t = 0 plus the work done on it.

    Args:
        terms: the terms now (floats, or arrays over time as in ``/series``).
        initial: the terms at t = 0; default the first entry of each array in ``terms``.
    """
    initial = _initial(terms) if initial is None else initial
    out = initial["kinetic_energy"] + initial["elastic_energy"] + np.asarray(terms["work_in"])
    for name in WORK[1:]:  # the forcing's: 0 without it, absent from files before it
        out = out + np.asarray(terms.get(name, 0.0))
    return out


def residual(terms: Mapping[str, Any], initial: Mapping[str, Any] | None = None):
    """Budget residual (J): what came in minus what is held and what was dissipated.

    Args and default as :func:`came_in`. Positive when energy went missing, negative when
    the step created it.
    """
    initial = _initial(terms) if initial is None else initial
    out = came_in(terms, initial)
    for name in HELD + DISSIPATED:
        out = out - np.asarray(terms.get(name, 0.0))
    return out


def relative_residual(terms: Mapping[str, Any], initial: Mapping[str, Any] | None = None):
    """Residual over the energy that came in (NaN where nothing came in)."""
    came = np.asarray(came_in(terms, initial), dtype=float)
    res = np.asarray(residual(terms, initial), dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(came > 0, res / np.where(came > 0, came, 1.0), np.nan)


def created(terms: Mapping[str, Any], initial: Mapping[str, Any] | None = None):
    """Energy created (J; negative when none): kinetic energy plus everything dissipated,
    less what came in. What ``breached`` judges; the elastic energy held in contacts is left
    out (``BREACH``). Args and default as :func:`came_in`."""
    initial = _initial(terms) if initial is None else initial
    out = np.asarray(terms["kinetic_energy"]) - came_in(terms, initial)
    for name in DISSIPATED:
        out = out + np.asarray(terms.get(name, 0.0))
    return out


def breached(table: np.ndarray, initial: np.ndarray) -> np.ndarray:
    """Indices of the worlds whose budget shows energy created from nothing.

    Args:
        table: ``(W, E)`` energy table of every world now (EnergyTerm columns).
        initial: ``(W, E)`` the same at t = 0.

    Returns:
        The worlds whose kinetic energy plus what they dissipated exceeds what came in by
        more than ``BREACH`` times it, plus ``BREACH_FLOOR`` (``created``).
    """
    return np.nonzero(breaches(table, initial))[0]


def breaches(table: np.ndarray, initial: np.ndarray) -> np.ndarray:
    """``breached`` as a bool array over the leading axes of ``table`` (``(..., W, E)``: the
    samples of a launch at once), ``initial`` ``(W, E)``."""
    now, start = as_series(table), as_series(initial)
    came = np.maximum(came_in(now, start), 0.0)
    return created(now, start) > BREACH * came + BREACH_FLOOR


# A run whose energy budget misses by more than this fraction of the energy that came in is
# marked with a warning (file attribute ``warning``, ``RunResult.warning``, the summary line).
# The landed scenes closed within 8 % when this was set; a body 1e12 m out missed by 33 %.
RESIDUAL_WARNING = 0.1


def residual_warning(table: np.ndarray, initial: np.ndarray) -> str:
    """The warning for the world of the energy ``table`` (a row per world, ``EnergyTerm``
    columns; ``initial`` the same at t = 0) whose budget misses most, if by more than
    ``RESIDUAL_WARNING`` of the energy that came in; "" if none does."""
    worst, where = 0.0, 0
    for w in range(len(table)):
        rel = float(relative_residual(as_series(table[w]), as_series(initial[w])))
        if abs(rel) > abs(worst):  # NaN (nothing came in) never counts
            worst, where = rel, w
    if abs(worst) <= RESIDUAL_WARNING:
        return ""
    label = f"world {where}" if len(table) > 1 else "the run"
    return (
        f"{label}'s energy budget misses by {100 * worst:.3g} % of the energy in (bound "
        f"{100 * RESIDUAL_WARNING:g} %): the result is suspect; lower dt, or check the "
        "scene (a body far from the others, a tiny block)"
    )


__all__ = [
    "BREACH",
    "BREACH_FLOOR",
    "DISSIPATED",
    "HELD",
    "RESIDUAL_WARNING",
    "SERIES",
    "WORK",
    "as_series",
    "breached",
    "breaches",
    "came_in",
    "created",
    "relative_residual",
    "residual",
    "residual_warning",
    "series_name",
]
