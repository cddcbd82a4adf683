"""The engine's settings, one validated value: how a batch of scenes is stepped.

``Options`` holds what the scenes do not say and every layer above the engine passes down
unchanged: the arch and precision Taichi runs, the time step and whether it may exceed the
stability limit, the contact slots per body, how the worlds are stepped and whether the
energy budget is kept. It is checked once, when it is made (``UsageError`` naming the option
and the fix), and the time step is decided and held to the stability limit in one place,
``Options.time_step`` (``StabilityError``). A ``World`` is built from scenes and an
``Options``; ``Simulation``, the World pool of sweeps and the commands make one and hand it
on, as MuJoCo Warp's ``Option`` or Box2D's step context travel with their model.

Nothing here is compiled into a kernel: ``World.reload`` may take another dt.
NumPy and the standard library only: importing this module starts no Taichi.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..backend import ARCHES, PRECISIONS
from ..errors import StabilityError, UsageError
from ..physics.timestep import INTEGRATORS, default_integrator

STEPPINGS = ("auto", "worlds", "bodies")
# Contact slots per body: DEFAULT_SMALL_SLOTS, plus one for each large body of its world (a
# wall, a pusher) up to LARGE_SLOTS. A body owns its contacts with small bodies of higher id
# and with large bodies. Measured with 6 slots, checked at every step (the overflow status):
# the pillar scene's 17 layouts for 20 s under each of the four friction models, the jams at
# full load included, never had a body own more than 6 contacts (5 in the 200 samples of
# each run), nor list more than 7 neighbours; the random and lattice boxes of 1e4 blocks, 3
# and 2 contacts. A scene that needs more stops with a CapacityError that says what to
# pass (``slots``, ``--slots``). At 1e5 blocks each slot costs 12 B a block (f64 Coulomb:
# partner and stretch) and 8 more in the neighbour lists; 14 slots had taken 280 B.
# A scene of up to BODY_FLOOR bodies (the smallest capacity a layout compiles for,
# ``assemble.CAPACITY_FLOORS``) takes the LARGE_SLOTS whatever its walls: one layout, one
# compile, for every small scene (2 slots cost ~10 kB there).
DEFAULT_SMALL_SLOTS = 6
LARGE_SLOTS = 2
BODY_FLOOR = 256
# Most slots a body may be given (``slots``): a convex block among blocks of its size touches
# at most a dozen; 64 (~1.3 kB a block of slots and lists) leaves room for a block among
# small ones. 1e9 used to reach Taichi's allocator (a 40 GB request and a traceback).
MAX_SLOTS = 64


@dataclass(frozen=True)
class Options:
    """How the engine steps a batch: checked when made; ``replace`` gives a changed copy.

    Attributes:
        arch: 'cpu', 'gpu' (Taichi picks CUDA, Vulkan or Metal) or a backend by name; None:
            the arch Taichi already runs on in this process, else 'cpu' (``resolved``).
        precision: 'f64' or 'f32', the type of every ``real`` field; None: the running one,
            else 'f64'.
        dt: time step (s); None: the smallest of the scenes' ``dt`` (``time_step``).
        force_dt: accept a dt above the contact stability limit (stability studies).
        slots: contact slots per body, 1 to ``MAX_SLOTS``; None: sized from the scenes
            (``assemble``).
        stepping: "worlds" (a thread per world, many steps a launch: small worlds), "bodies"
            (parallel over bodies: large worlds) or "auto" (``world.auto_stepping``).
        energy: keep the energy budget; off, trajectories are the same bit for bit and the
            step neither computes nor stores its terms (``schema.Layout.energy``).
        integrator: "euler", "analytic", "coupled" or "midstep" (``INTEGRATORS``): compiled in
            (``schema.Layout.integrator``); None: the scenes' (``for_scenes``: the one their
            files name, else the law's, "midstep" for Coulomb friction and "euler" for a
            law with a memory). Given, it wins over the scenes', and their ``dt = "auto"``
            follows it (``Scene.with_integrator``).
    """

    arch: str | None = None
    precision: str | None = None
    dt: float | None = None
    force_dt: bool = False
    slots: int | None = None
    stepping: str = "auto"
    energy: bool = True
    integrator: str | None = None

    def __post_init__(self):
        if self.arch is not None and self.arch not in ARCHES:
            raise UsageError(f"arch = {self.arch!r}: use one of {', '.join(ARCHES)}")
        if self.precision is not None and self.precision not in PRECISIONS:
            raise UsageError(f"precision must be one of {PRECISIONS}, got {self.precision!r}")
        if self.dt is not None:
            if isinstance(self.dt, bool) or not isinstance(self.dt, (int, float, np.floating)):
                raise UsageError(f"dt must be a number of seconds, got {self.dt!r}")
            if not (0.0 < self.dt < math.inf):
                raise UsageError(f"dt = {self.dt!r}: use a positive finite time step in seconds")
            object.__setattr__(self, "dt", float(self.dt))
        if self.slots is not None:
            if isinstance(self.slots, bool) or not isinstance(self.slots, (int, np.integer)):
                raise UsageError(
                    f"slots = {self.slots!r}: give a whole number of contact slots per body"
                )
            if not 1 <= self.slots <= MAX_SLOTS:
                raise UsageError(
                    f"slots = {self.slots}: contact slots per body must be 1 to {MAX_SLOTS} "
                    f"(default {DEFAULT_SMALL_SLOTS} plus one per wall or pusher, up to "
                    f"{LARGE_SLOTS}, and {DEFAULT_SMALL_SLOTS + LARGE_SLOTS} for up to "
                    f"{BODY_FLOOR} bodies); a run that needs more stops and says how many"
                )
            object.__setattr__(self, "slots", int(self.slots))
        if self.stepping not in STEPPINGS:
            raise UsageError(f"stepping must be one of {STEPPINGS}, got {self.stepping!r}")
        if self.integrator is not None and self.integrator not in INTEGRATORS:
            raise UsageError(
                f"integrator must be one of {INTEGRATORS} (or None: the scenes'), got "
                f"{self.integrator!r}"
            )
        for name in ("force_dt", "energy"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise UsageError(f"{name} must be True or False, got {getattr(self, name)!r}")
            object.__setattr__(self, name, bool(getattr(self, name)))

    def replace(self, **changes) -> Options:
        """A copy with ``changes`` (option names), checked again."""
        unknown = sorted(set(changes) - {f.name for f in dataclasses.fields(self)})
        if unknown:
            raise UsageError(
                f"unknown engine option(s) {', '.join(unknown)}: the options are "
                f"{', '.join(f.name for f in dataclasses.fields(self))}"
            )
        return dataclasses.replace(self, **changes)

    def resolved(self) -> Options:
        """``arch`` and ``precision`` filled in: what this process's Taichi already runs on,
        else 'cpu' and 'f64' (``backend.resolve``)."""
        from ..backend import resolve

        arch, precision = resolve(self.arch, self.precision)
        return dataclasses.replace(self, arch=arch, precision=precision)

    def for_scenes(self, scenes: Sequence) -> tuple[Options, tuple]:
        """This Options with ``integrator`` decided for ``scenes``, and the scenes as they step
        with it (``Scene.with_integrator``: their ``dt = "auto"`` the fraction of the limit
        their law takes with it). Unless given here, the integrator is the one the scenes'
        files name (``[simulation] integrator``), else that of the batch's laws
        (``timestep.default_integrator``: "midstep" when every world has Coulomb friction,
        "euler" when one has a law with a memory, whose kernels the batch then runs).

        Raises:
            UsageError: scenes whose files name different integrators, none given here.
        """
        scenes = tuple(scenes)
        integrator = self.integrator
        if integrator is None:
            named = {s.simulation.integrator for s in scenes} - {None}
            if len(named) > 1:
                names = ", ".join(sorted(named))
                raise UsageError(
                    f"the scenes of one batch name different integrators ({names}, "
                    "[simulation] integrator): a batch steps with one; give them the same, or "
                    "choose one for all (integrator=..., --integrator)"
                )
            coulomb = all(s.friction.name == "coulomb" for s in scenes)
            integrator = (
                named.pop() if named else default_integrator("coulomb" if coulomb else "rate-state")
            )
        chosen = self if integrator == self.integrator else self.replace(integrator=integrator)
        return chosen, tuple(s.with_integrator(integrator) for s in scenes)

    def time_step(self, scenes: Sequence) -> tuple[float, float]:
        """``(dt, stable_dt)`` for ``scenes``: this dt or the smallest ``scene.dt``, and the
        contact stability limit over every scene.

        Raises:
            StabilityError: dt above the limit, unless ``force_dt`` or every scene forces it.
        """
        stable_dt = min(s.stable_dt for s in scenes)
        dt = self.dt if self.dt is not None else min(s.dt for s in scenes)
        forced = self.force_dt or all(s.simulation.force_dt for s in scenes)
        if dt > stable_dt and not forced:
            raise StabilityError(
                f"dt = {dt:g} s is above the stability limit {stable_dt:.4g} s of the contact "
                f"integration (stiffest contact of the lightest dynamic body); use a dt "
                "below it, dt = None for the scene's, or force_dt (--force-dt) for a "
                "stability study"
            )
        return float(dt), float(stable_dt)


def options_of(options: Options | None, changes: dict) -> Options:
    """``options`` (default ``Options()``) with ``changes``: what a constructor that takes an
    ``Options`` and, for convenience, options by name (``World(scenes, dt=...)``) does."""
    base = Options() if options is None else options
    if not isinstance(base, Options):
        raise UsageError(f"options must be an Options, got {type(base).__name__}")
    return base.replace(**changes) if changes else base


__all__ = ["INTEGRATORS", "MAX_SLOTS", "STEPPINGS", "Options", "options_of"]
