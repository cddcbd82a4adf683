"""The study's design: which worlds it runs, in arms of one stratum and setting each.

Issue 31's referee found that area fraction acts as a switch (at 0.70 nothing jams, at
0.775 and 0.85 every model but mu = 0.1 jams), so pooling the fractions measures the
design, and that the three fractions reused one set of seeds (clustered units). So:

- **Strata by area fraction**, analysed apart: the jamming strata ``STRATA`` (0.85, the
  scene's own, and 0.775) with ``layouts`` layouts each, and the control ``CONTROL`` (0.70),
  reported beside them, never pooled.
- **Independent layouts per stratum**: each stratum draws its seeds from its own block
  (``stratum_seeds``: 0.85 from 0, 0.775 from 100,000, 0.70 from 200,000), so no layout
  is shared between strata; within a stratum the eight models run on the same layouts
  (paired units).
- **The step's bias**: the first ``step_layouts`` layouts of the 0.85 stratum again at 0.1
  of the limit (``STEP_SAFETY``), every model (the same seeds: paired): half the default
  step with Coulomb friction, twice it with the laws that have a memory (their default is
  0.05 since 2026-11-28; the committed study ran every model at 0.2 and this arm at 0.1).
- **An ice strength** (``STRENGTHS``, 1 and 3 MPa: ``[ice] crushing_strength``) on the first
  ``strength_layouts`` layouts of each jamming stratum, every model.

Each arm is one sweep (``Arm.sweep``), run into its own folder (``arms/NAME``), so a stratum,
a step and a strength never share a batch (the kernels compile the strength in, and a batch
has one dt) and each arm resumes on its own.
"""

from __future__ import annotations

from dataclasses import dataclass

from ...physics.timestep import DEFAULT_SAFETY
from ..metrics import METRICS as RUN_METRICS

__all__ = ["Arm", "design", "stratum_seeds"]

# The models of the study, in the order of its tables: (label, [[law]] table).
MODELS = [
    ("mu0.1", {"law": "coulomb", "mu": 0.1}),
    ("mu0.3", {"law": "coulomb", "mu": 0.3}),
    ("mu0.5", {"law": "coulomb", "mu": 0.5}),
    ("mu0.7", {"law": "coulomb", "mu": 0.7}),
    ("mu0.9", {"law": "coulomb", "mu": 0.9}),
    ("rate-state", {"law": "rate-state"}),
    ("steady-state", {"law": "steady-state"}),
    ("memory-only", {"law": "memory-only"}),
]
FIELD = "rubble"
# Share of the rubble field's lattice that is ice: the scene's own 0.85 and a looser field
# (row spacing 0.61 m instead of 0.56 m) jam; at 0.70 (0.68 m) nothing jammed in the 2024
# study: the control.
STRATA = (0.85, 0.775)
CONTROL = 0.70
# Each stratum's seeds start at its index in (0.85, 0.775, 0.70) x SEED_BLOCK.
SEED_BLOCK = 100_000
# The step arm: every model at 0.1 of the limit, half the Euler step's 0.2 (Coulomb's default
# until 2026-12-02, and the step of the committed study; since then Coulomb's default is the
# midstep step at 0.6, which the arm then runs at a sixth of it); the laws with a memory
# default to 0.05 (timestep.RATE_STATE_SAFETY) since 2026-11-28, so for them the arm is
# twice their default step: the step at which their peak force reads high.
STEP_SAFETY = DEFAULT_SAFETY / 2.0
STRENGTHS = (1e6, 3e6)  # Pa: [ice] crushing_strength
# What each world keeps: every run metric (experiments.metrics.METRICS) but the time of
# first contact and the budget's absolute residual (its relative one is kept).
METRICS = tuple(m for m in RUN_METRICS if m not in ("first_contact", "residual"))


def stratum_seeds(fraction: float, n: int) -> list[int]:
    """The first ``n`` layouts of the stratum at ``fraction`` (its own block of seeds)."""
    order = (*STRATA, CONTROL)
    if fraction not in order:
        raise ValueError(f"area fraction {fraction} is not a stratum of the study: {order}")
    start = SEED_BLOCK * order.index(fraction)
    return list(range(start, start + int(n)))


@dataclass(frozen=True)
class Arm:
    """One arm of the study: a stratum at one step and strength, every model.

    Attributes:
        name: its folder under ``arms/`` ("af0.85", "control-af0.7", "half-step-af0.85",
            "strength-1MPa-af0.775").
        kind: "stratum", "control", "step" or "strength".
        fraction: the area fraction (the stratum). layouts: layouts run.
        dt_safety: the step's fraction of the stable limit (None: the scene's default).
        strength: ``[ice] crushing_strength`` (Pa), or None (no strength).
    """

    name: str
    kind: str
    fraction: float
    layouts: int
    dt_safety: float | None = None
    strength: float | None = None

    @property
    def seeds(self) -> list[int]:
        return stratum_seeds(self.fraction, self.layouts)

    def sweep(self, until: float | None = None):
        """The arm as a ``Sweep``: the pillar scene, its seeds, the eight models."""
        from ..models import DEFAULT_SCENE
        from ..sweep.spec import sweep_from_dict

        overrides: dict = {f"field.{FIELD}.area_fraction": [self.fraction]}
        if self.dt_safety is not None:
            overrides["simulation.dt_safety"] = [self.dt_safety]
        if self.strength is not None:
            overrides["ice.crushing_strength"] = [self.strength]
        data = {
            "sweep": {
                "scene": str(DEFAULT_SCENE),
                "seeds": self.seeds,
                "metrics": list(METRICS),
            },
            "law": [table for _, table in MODELS],
            "overrides": overrides,
        }
        if until is not None:
            data["sweep"]["until"] = float(until)
        return sweep_from_dict(data, source=f"<taichi-ice study, arm {self.name}>")


def design(
    layouts: int,
    control_layouts: int | None = None,
    step_layouts: int | None = None,
    strength_layouts: int | None = None,
) -> list[Arm]:
    """The study's arms: ``layouts`` per jamming stratum; the control, the half step and
    the strengths on ``max(2, layouts // 2)`` layouts each unless given (0 leaves an arm
    out)."""
    half = max(2, layouts // 2)
    control = half if control_layouts is None else control_layouts
    step = half if step_layouts is None else step_layouts
    strength = half if strength_layouts is None else strength_layouts
    arms = [Arm(f"af{f:g}", "stratum", f, layouts) for f in STRATA]
    if control:
        arms.append(Arm(f"control-af{CONTROL:g}", "control", CONTROL, control))
    if step:
        f = STRATA[0]
        step = min(step, layouts)  # the same layouts as the stratum's: paired
        arms.append(Arm(f"half-step-af{f:g}", "step", f, step, dt_safety=STEP_SAFETY))
    if strength:
        strength = min(strength, layouts)
        for s in STRENGTHS:
            for f in STRATA:
                arms.append(
                    Arm(f"strength-{s / 1e6:g}MPa-af{f:g}", "strength", f, strength, strength=s)
                )
    return arms


# Layouts per jamming stratum of ``taichi-ice study`` without --layouts: a smoke-sized run
# (128 worlds, a few minutes on 2 cores); issue 31's study is --layouts 64.
DEFAULT_LAYOUTS = 2
