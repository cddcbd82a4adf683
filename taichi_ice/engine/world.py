"""A batch of independent worlds and its step: the algorithm, stage by stage.

Stepping in parallel over bodies (``stepping="bodies"``: large worlds), whatever the number
of worlds or bodies:

    step():  refresh_lists()       only when a body has moved half the skin (read back):
                                   hash.build(), contacts.build_lists()
             contacts.compute()    narrow phase from the neighbour lists, contact forces,
                                   contact memory
             integrator.advance()  forces -> velocities -> positions, work and drag
             contacts.settle_all() the analytic steps, with a budget: each contact's work
                                   booked again at the velocity change the bodies took

On a GPU each stage is a kernel launched every step. On the CPU a team of threads runs the
two stages for many steps in one launch, meeting at a barrier after each
(``stepper.BodyTeam``), until a step marks the lists stale: the launches and rounds of the
thread pool that a kernel per stage costs were a fifth of a step at 1e4 blocks.

Stepping in parallel over worlds (``stepping="worlds"``: small worlds, batches of them), one
launch for many steps (``advance(n)``; ``stepper.WorldStepper``): the thread of a world
rebuilds its neighbour lists when a body has moved half their skin, then runs the same
contact and integration code body by body. All three give bit-identical states.
"""

from __future__ import annotations

import dataclasses
import weakref
from collections.abc import Sequence

import numpy as np
import taichi as ti

from .. import backend
from ..codes import Status
from ..errors import CapacityError, DivergenceError, UsageError
from . import schema, state
from .assemble import LIST_SLOTS, assemble
from .broadphase import NeighbourList, SpatialHash
from .contact import ContactStage
from .energy import SAMPLE_COLUMNS, EnergyMeter
from .engines import ENGINES, Engines
from .integrate import Integrator
from .options import Options, options_of
from .stepper import NO_SAMPLE, BodyTeam, WorldStepper
from .transfer import Transfer

# The stages of a step, by the name their kernels are reported under (benchmarks, traffic).
STAGES = {
    "hash": SpatialHash,
    "contacts": ContactStage,
    "integrator": Integrator,
    "energy": EnergyMeter,
    "stepper": WorldStepper,
    "team": BodyTeam,
}

# "auto" on the CPU steps worlds of up to PER_WORLD_MAX_BODIES bodies one thread per world
# (many steps per launch), larger ones in parallel over bodies; and with fewer worlds than
# CPU threads, which would leave threads idle, only worlds of up to FEW_WORLDS_MAX_BODIES.
# Measured on the 2-core VM, random box of the paper's diamonds, no budget, with the
# parallel step on the CPU as a team of threads in one launch (``stepper.BodyTeam``), the
# mean of 60 alternating timings of 10 steps from the start: a lone world steps at 0.125 ms
# a step a thread per world against 0.43 in parallel at 1,000 blocks, 0.27 against 0.30 at
# 2,000, 0.45 against 0.37 at 3,000. The team is faster in most timings (1.3-1.5x the
# fastest at 300 to 3,000 blocks) but, spinning at two barriers a step, it stalls for a
# time slice whenever the VM's other load takes one of its cores (the slowest tenth of
# timings: 1.4 ms a step at 1,000 blocks); the fewer its steps per millisecond, the less
# that costs. Two worlds step 1.3x as fast a thread each as in parallel at 1,000 and 3,000
# blocks each, 2.1x at 5,000 and 1.2x at 10,000 (the fastest of 9 timings). (Before the
# team, with two launches and two rounds of the thread pool a step, a lone world crossed
# over at 3,000 to 4,000 blocks.)
PER_WORLD_MAX_BODIES = 10000
FEW_WORLDS_MAX_BODIES = 2000
# On a GPU a thread per world leaves the device idle unless there are thousands of worlds;
# "auto" steps them so only from this many worlds on (not measured: no GPU was lent yet).
GPU_MIN_WORLDS = 1024
# Trees of Taichi fields a World may add on the CPU and CUDA: 1 (``state.Fields``, its
# first launch), 2 with the team's words (measured); ~7 on SPIR-V, which has no limit.
TREES_PER_WORLD = 2

# What ``World.motion`` reads, in its order: positions, angles, velocities, omegas.
MOTION_FIELDS = ("body_pos", "body_angle", "body_vel", "body_omega")


def auto_stepping(largest: int, n_worlds: int, arch: str | None, threads: int) -> str:
    """What ``stepping="auto"`` picks: ``"worlds"`` (a thread per world) or ``"bodies"``.

    Args:
        largest: bodies of the largest world.
        n_worlds: worlds of the batch.
        arch: the arch Taichi was started on (``backend.current_arch()``; None: not yet).
        threads: CPU threads Taichi runs on.
    """
    if largest > PER_WORLD_MAX_BODIES:
        return "bodies"
    if arch not in (None, "cpu"):
        return "worlds" if n_worlds >= GPU_MIN_WORLDS else "bodies"
    if n_worlds < threads and largest > FEW_WORLDS_MAX_BODIES:
        return "bodies"
    return "worlds"


class World:
    """Many independent scenes stepped together on one set of Taichi fields.

    Args:
        scenes: the worlds; what they must share is checked by ``assemble.assemble``.
        options: the engine's settings (``options.Options``: dt, precision, slots, force_dt,
            stepping, energy; arch is Taichi's, started before); default ``Options()``.
            ``precision`` None is the precision Taichi runs (``backend.init``), else 'f64'.
            ``energy`` off: the step neither computes nor stores its terms
            (``schema.Layout.energy``; about 270 fewer bytes a block at f64 and less work per
            contact); trajectories are the same bit for bit, ``energies`` raises and the
            samples' energy columns, but the kinetic one, are NaN. For runs that ask for no
            energy (benchmarks, fields where only the motion is wanted). ``stepping``:
            "worlds" (one thread per world, many steps per launch: small worlds), "bodies"
            (parallel over bodies: large worlds; on the CPU by a team of threads, ``team``,
            many steps per launch) or "auto" (``auto_stepping``: worlds if no world has more
            than ``PER_WORLD_MAX_BODIES`` bodies, ``FEW_WORLDS_MAX_BODIES`` when there are
            fewer worlds than CPU threads, and on a GPU only for ``GPU_MIN_WORLDS`` worlds or
            more).
        **changes: options by name, for short (``World(scenes, dt=1e-4)``): they replace
            those of ``options``.

    Attributes:
        options: the settings it was built with, arch and precision resolved, ``stepping`` the one
            chosen.
        team: the ``stepper.BodyTeam`` that steps bodies in parallel on the CPU, or None
            (worlds stepping, or a GPU: a kernel per stage and step). Setting it to None
            steps with the kernels per stage instead, to compare (same state bit for bit).

    A World that is collected leaves its fields and compiled kernels to the next World of
    its layout in the process (``Engines``; every field back to its start, bit for bit a
    World on new fields): building one is seconds of compiling the first time, milliseconds
    after.

    Raises:
        UsageError: an option out of range (``Options``); or the process holds too many of
            Taichi's trees of fields for another World (``backend.field_tree_limit``; Taichi
            never frees them).
    """

    def __init__(self, scenes: Sequence, options: Options | None = None, **changes):
        options = options_of(options, changes).resolved()
        self.batch = assemble(scenes, options)
        self.scenes = list(self.batch.scenes)
        self.layout, self.host = self.batch.layout, self.batch.host
        self.dt, self.stable_dt = self.batch.dt, self.batch.stable_dt
        self.precision = options.precision
        stepping = options.stepping
        if stepping == "auto":
            stepping = auto_stepping(
                int(np.diff(self.host.world_body_start).max(initial=0)),
                len(self.scenes),
                backend.current_arch(),
                backend.cpu_threads(),
            )
        self.stepping = stepping
        self.options = options.replace(
            stepping=stepping, slots=self.layout.slots, integrator=self.layout.integrator
        )
        # The parallel step on the CPU: one launch for many steps (``BodyTeam``); None
        # launches the two stages' kernels every step (GPU, or set to None to compare).
        threads = None
        if stepping == "bodies" and backend.actual_arch() in (None, "cpu"):
            threads = min(backend.cpu_threads(), backend.usable_cores())
        key = (self.layout, stepping, threads, backend.generation())
        self.engine_key = key
        parts = ENGINES.take(key)
        if parts is None:
            parts = self._build(threads)
        for name, part in parts.items():
            setattr(self, name, part)
        # Every field to its start, these scenes in: new fields, or those of a World gone.
        self._start()
        # When this World is gone, its fields and compiled kernels serve the next World of
        # its layout (``Engines``).
        weakref.finalize(self, ENGINES.give_back, key, parts)
        # What WorldStepper.run is handed when it takes no sample (it writes nothing there).
        self._no_samples = (np.zeros((1, 1, SAMPLE_COLUMNS)), np.zeros((1, 1, 2)))
        self.steps = 0
        self.time = 0.0
        # Let the device finish building the fields: on Vulkan (lavapipe, Mesa 22.3) the
        # first kernel after a new World's last tree of fields read its velocities as zeros
        # (the energies before the first step) unless the device had finished; a sync here
        # made every later read right (tests/test_engine.py, sampled against stepped).
        ti.sync()

    def _build(self, threads: int | None) -> dict:
        """New fields for this World's layout and the stages whose kernels close over them
        (compiled at their first launch); ``_start`` puts the scenes in."""
        limit = backend.field_tree_limit()
        if limit is not None and backend.field_trees() + TREES_PER_WORLD > limit:
            raise UsageError(
                f"this process holds {backend.field_trees()} trees of Taichi fields, the most "
                f"it can ({limit}: about {limit // TREES_PER_WORLD}-{limit} "
                "Worlds; Taichi never frees them): step other scenes of the same layout on a "
                "World built before (World.reload), or build the rest in a new process"
            )
        layout = self.layout
        model, data = state.Model(layout), state.Data(layout)
        hash_ = SpatialHash(layout, model, data)
        neighbours = NeighbourList(layout)
        # Every declared field, written at once (``World._start``).
        declared = {n: getattr(g, n) for g in (model, data, hash_, neighbours) for n in g.names}
        unheld = {v.name for g in schema.groups().values() for v in g} - set(declared)
        if unheld:
            raise RuntimeError(
                f"World: fields {sorted(unheld)} are declared in taichi_ice.engine.schema but "
                "held by no group of the World; it cannot start them"
            )
        contacts = ContactStage(layout, model, data, hash_, neighbours)
        integrator = Integrator(layout, model, data, neighbours)
        energy = EnergyMeter(layout, model, data)
        stepper = WorldStepper(layout, model, data, neighbours, contacts, integrator, energy)
        team = None
        if threads is not None:
            team = BodyTeam(layout, data, neighbours, contacts, integrator, threads)
        return {
            "model": model,
            "data": data,
            "hash": hash_,
            "neighbours": neighbours,
            "contacts": contacts,
            "integrator": integrator,
            "energy": energy,
            "stepper": stepper,
            "team": team,
            "transfer": Transfer(declared),
            # ``read``'s Transfers, one per set of fields read, kept with the fields.
            "readers": {},
            # What this World's kernels ran ("advance", "sampled"): those are compiled, for
            # the next World on these fields too (``compiled``).
            "launched": set(),
        }

    # ----------------------------------------------------------------------------------------
    # Reuse: other scenes on the same fields and compiled kernels
    # ----------------------------------------------------------------------------------------

    def reload(self, scenes: Sequence, dt: float | None = None, force_dt: bool = False) -> None:
        """Put ``scenes`` on this World's fields, as ``World(scenes, dt, ...)`` would start
        them, without compiling anything again.

        The kernels of a World specialise on its ``layout`` and close over its fields, so a
        new World compiles every kernel anew (seconds to a minute); a World reloaded with
        scenes of the same layout keeps them. The scenes are assembled with this World's
        precision and contact slots (its capacities), every field is reset to its declared
        start (``schema.groups()``: a fill with ``Var.init``, then the assembled ``HOST``
        arrays), the outlines turned, the neighbour lists marked stale and the clock set to
        0: stepping it gives, bit for bit, what a new ``World(scenes, self.options.replace(dt=dt,
        force_dt=force_dt))`` gives. ``stepping`` stays as built; dt may differ from the
        World's (nothing compiled depends on it).

        Args:
            scenes: the new worlds.
            dt, force_dt: as for ``World`` (dt defaults to the smallest ``scene.dt``).

        Raises:
            UsageError: the scenes' layout is not this World's (other sizes or switches; the
                message names what differs); the World is left as it was.
            ValueError, ScenarioError, StabilityError: as ``assemble`` raises them.
        """
        batch = assemble(scenes, self.options.replace(dt=dt, force_dt=force_dt))
        if batch.layout != self.layout:
            raise UsageError(
                "World.reload: the scenes need another layout than this World was compiled "
                f"for ({_layout_difference(self.layout, batch.layout)}); build a new World "
                "for them"
            )
        self.batch = batch
        self.options = self.options.replace(dt=dt, force_dt=force_dt)
        self.scenes = list(batch.scenes)
        self.host = batch.host
        self.dt, self.stable_dt = batch.dt, batch.stable_dt
        self._start()
        self.steps = 0
        self.time = 0.0

    def _start(self) -> None:
        """Every field to its declared start (``state.start_arrays``: ``Var.init``, the
        assembled ``HOST`` arrays; among them the neighbour lists marked stale) in one launch
        (``transfer.Transfer``), dt set, the outlines turned: the fields of a new World of
        these scenes, whether the fields are new or a World's gone."""
        arrays = state.start_arrays(self.layout, self.host)
        arrays["time_step"] = np.asarray(self.dt)
        self.transfer.write(arrays)
        self.integrator.orient()

    # ----------------------------------------------------------------------------------------
    # The step
    # ----------------------------------------------------------------------------------------

    def step(self) -> None:
        """Advance every world by one time step."""
        self.advance(1)

    def compiled(self, entry: str = "sampled") -> bool:
        """Whether ``entry``'s kernels ran on these fields already in this process
        (``"advance"``, or ``"sampled"``: ``advance_sampled``, a Simulation's), so that
        running it compiles nothing: a World on the fields of one gone, or reloaded."""
        return entry in self.launched

    def advance(self, n: int) -> None:
        """Advance every world by ``n`` time steps (no read-back: call ``check`` after)."""
        if n <= 0:
            return
        self.launched.add("advance")
        if self.stepping == "worlds":
            plan = np.array([[n, NO_SAMPLE]], dtype=np.int32)
            self.stepper.launch(plan, *self._no_samples)
        elif self.team is not None:
            left = n
            while left > 0:
                self.refresh_lists()
                left -= self.team.launch(min(left, self.team.MAX_STEPS))
        else:
            for _ in range(n):
                self.refresh_lists()
                self.contacts.compute()
                self.integrator.advance()
                if self.layout.settles:
                    self.contacts.settle_all()
        self.steps += n
        self.time = self.steps * self.dt

    def refresh_lists(self) -> None:
        """Rebuild the neighbour lists of the worlds that need it, through the spatial hash
        (the parallel step's broad phase; one read-back of ``nbr_rebuild``)."""
        if self.neighbours.nbr_rebuild[None]:
            self.hash.build()
            self.contacts.build_lists()

    def check(self) -> None:
        """Raise if a step overflowed the contact slots or diverged (reads back the status
        words)."""
        self.raise_for(self.data.status.to_numpy()[: len(self.scenes)], self.time)

    def tripped(self, status: np.ndarray) -> np.ndarray:
        """Which status words ``(..., len(Status))`` ``raise_for`` raises for (a bool array
        over the leading axes: the samples of a launch, their worlds)."""
        status = np.asarray(status).astype(np.int64)
        return (
            (status[..., Status.SLOT_OVERFLOW] > self.layout.slots)
            | (status[..., Status.LIST_OVERFLOW] > self.layout.nbr_len)
            | (status[..., Status.NONFINITE] != 0)
            | (status[..., Status.RUNAWAY] != 0)
        )

    def raise_for(self, status: np.ndarray, time: float) -> None:
        """Raise CapacityError or DivergenceError for ``(W, len(Status))`` status words (one
        per world, as ``check`` reads them or a sample holds them) read at ``time`` (s)."""
        status = np.asarray(status).astype(np.int64).reshape(-1, len(Status))
        where = ""
        bad = np.flatnonzero(self.tripped(status))
        if not bad.size:
            return
        w = int(bad[0])
        if len(status) > 1:
            where = f" in world {w}"
        word = status[w]
        if word[Status.SLOT_OVERFLOW] > self.layout.slots:
            raise CapacityError(
                f"a body had {word[Status.SLOT_OVERFLOW]} contacts{where} at t = {time:.4g} s, "
                f"more than its {self.layout.slots} contact slots; pass slots="
                f"{int(word[Status.SLOT_OVERFLOW]) + 4} (Simulation/World; --slots on the "
                "command line) to allow more"
            )
        listed = int(word[Status.LIST_OVERFLOW])
        if listed > self.layout.nbr_len:
            raise CapacityError(
                f"a body had {listed} neighbours within the skin{where} at t = {time:.4g} s, "
                f"more than its list of {self.layout.nbr_len}; pass slots="
                f"{-(-listed // LIST_SLOTS) + 2} (Simulation/World; --slots on the command "
                "line) to allow more"
            )
        if word[Status.NONFINITE]:
            raise DivergenceError(
                f"a body's velocity became non-finite{where} at t = {time:.4g} s "
                f"(dt = {self.dt:.3g} s, stability limit {self.stable_dt:.3g} s); the run "
                "diverged: lower dt (or the scene's dt_safety)"
            )
        raise DivergenceError(
            f"a body moved faster than {self.host.world_runaway_step[w] / self.dt:.3g} m/s "
            "(a quarter "
            f"of the thinnest block per step){where} at t = {time:.4g} s (dt = {self.dt:.3g} "
            f"s, stability limit {self.stable_dt:.3g} s); the run diverged: lower dt (or the "
            "scene's dt_safety)"
        )

    def advance_sampled(self, plan) -> tuple[np.ndarray, np.ndarray]:
        """Advance through ``plan``, rows ``(steps, record)``: that many steps, then a sample
        of every world (``EnergyMeter.sample``); ``record`` restarts the probes' impulses
        from zero (a sample of the series), else they go on adding up. Stepping a thread per
        world, the whole plan is one launch. No status is checked: the samples hold it
        (``raise_for``).

        Returns:
            ``rows`` ``(S, W, energy.SAMPLE_COLUMNS)``: each world's energy table
            (``codes.EnergyTerm`` columns), contact count and status word after each row of
            the plan; ``impulses`` ``(S, P, 2)``: each probe's contact impulse (N s) since
            the last recorded sample.
        """
        plan = np.ascontiguousarray(np.asarray(plan, dtype=np.int32).reshape(-1, 2))
        if np.any(plan[:, 0] < 0):
            raise ValueError(f"advance_sampled: negative step counts in {plan[:, 0]}")
        rows = np.zeros((len(plan), self.layout.n_worlds, SAMPLE_COLUMNS))
        impulses = np.zeros((len(plan), max(self.layout.n_probes, 1), 2))
        if len(plan):
            self.launched.add("sampled")
            if self.stepping == "worlds":
                self.stepper.launch(plan, rows, impulses)
                self.steps += int(plan[:, 0].sum())
                self.time = self.steps * self.dt
            else:
                for s, (n, record) in enumerate(plan):
                    self.advance(int(n))
                    self.energy.take(rows, impulses, s, int(record))
        return rows[:, : len(self.scenes)], impulses[:, : self.batch.n_probes]

    def place(self, positions: np.ndarray, angles: np.ndarray) -> None:
        """Move every body to ``(N, 2)`` positions (m) and ``(N,)`` angles (rad): their
        outlines are turned and the neighbour lists rebuilt before the next step."""
        real = backend.real_dtype(self.precision)
        n = self.batch.n_bodies
        pos = self.data.body_pos.to_numpy()
        ang = self.data.body_angle.to_numpy()
        pos[:n] = np.asarray(positions, dtype=np.float64).reshape(n, 2)
        ang[:n] = np.asarray(angles, dtype=real).reshape(n)
        self.data.body_pos.from_numpy(pos)
        self.data.body_angle.from_numpy(ang)
        self.integrator.orient()
        self.neighbours.world_nbr_stale.fill(1)
        self.neighbours.nbr_rebuild[None] = 1

    # ----------------------------------------------------------------------------------------
    # Reading the state
    # ----------------------------------------------------------------------------------------

    def energies(self) -> np.ndarray:
        """``(W, E)`` energy table of every world now (J), ``codes.EnergyTerm`` columns.

        Raises:
            UsageError: the World keeps no energy budget (built with ``energy=False``).
        """
        if not self.layout.energy:
            raise UsageError(
                "World.energies: this World keeps no energy budget (built with "
                "energy=False); build it with energy=True to read the energy table"
            )
        self.energy.snapshot()
        return self.data.world_energy.to_numpy()[: len(self.scenes)]

    def motion(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(N, 2)`` positions (m), ``(N,)`` angles (rad), ``(N, 2)`` velocities (m/s) and
        ``(N,)`` spins (rad/s) of every body of every world, float64, read in one launch (a
        run's frame). One kernel for the four fields (``read``), compiled once for the
        World's fields, where Taichi's ``to_numpy`` compiles a kernel for each field (about
        0.1 s each on 2 cores with an empty cache, for every new World)."""
        got = self.read(MOTION_FIELDS)
        n = self.batch.n_bodies
        return tuple(got[name][:n].astype(np.float64) for name in MOTION_FIELDS)

    def read(self, names: Sequence[str]) -> dict[str, np.ndarray]:
        """Fields by name (any of ``schema.groups()``), ``{name: array}`` as ``to_numpy``
        gives each (the whole capacity), in one launch: a ``transfer.Transfer`` of these
        names, compiled at its first read and kept with the fields for every later read, by
        this World and by the next one on its fields. What a run reads again and again (its
        frames, its contacts) reads so; Taichi's ``to_numpy`` compiles a kernel for every
        field that a new World reads.

        Raises:
            UsageError: a name that is no field of the World (``schema.groups()``).
        """
        key = tuple(names)
        reader = self.readers.get(key)
        if reader is None:
            groups = (self.model, self.data, self.hash, self.neighbours)
            fields = {}
            for name in key:
                holder = next((g for g in groups if name in g.names), None)
                if holder is None:
                    raise UsageError(
                        f"World.read: no field {name!r}; the fields are those of "
                        "taichi_ice.engine.schema.groups()"
                    )
                fields[name] = getattr(holder, name)
            reader = self.readers[key] = Transfer(fields)
        return reader.read()

    # One field each (Taichi's ``to_numpy``: a kernel per field and World, the cheapest
    # call); a caller that wants all four takes ``motion``'s one launch.

    def positions(self) -> np.ndarray:
        """``(N, 2)`` centroids of every body of every world (m)."""
        return self.data.body_pos.to_numpy()[: self.batch.n_bodies].astype(np.float64)

    def angles(self) -> np.ndarray:
        """``(N,)`` angles (rad)."""
        return self.data.body_angle.to_numpy()[: self.batch.n_bodies].astype(np.float64)

    def velocities(self) -> np.ndarray:
        """``(N, 2)`` centroid velocities (m/s)."""
        return self.data.body_vel.to_numpy()[: self.batch.n_bodies].astype(np.float64)

    def omegas(self) -> np.ndarray:
        """``(N,)`` angular velocities (rad/s)."""
        return self.data.body_omega.to_numpy()[: self.batch.n_bodies].astype(np.float64)

    def take_probe_impulses(self) -> np.ndarray:
        """``(P, 2)`` contact impulse on each probe since the last call (N s); resets them."""
        impulse = self.data.probe_impulse.to_numpy()[: self.batch.n_probes]
        self.data.probe_impulse.fill(0.0)
        return impulse

    def contact_counts(self) -> np.ndarray:
        """``(W,)`` number of contacts in each world after the last step."""
        counts = self.data.contact_count.to_numpy()[: self.batch.n_bodies]
        return np.bincount(self.host.body_world, weights=counts, minlength=len(self.scenes)).astype(
            np.int64
        )

    def world_slices(self) -> list[slice]:
        """Body index range of each world."""
        return self.batch.world_slices()

    def probe_slices(self) -> list[slice]:
        """Probe index range of each world."""
        return self.batch.probe_slices()


def _layout_difference(have, want) -> str:
    """``"n_worlds 3 here, 2 for the scenes, ..."``: the fields of two layouts that differ."""
    diff = [
        f"{f.name} {getattr(have, f.name)!r} here, {getattr(want, f.name)!r} for the scenes"
        for f in dataclasses.fields(have)
        if getattr(have, f.name) != getattr(want, f.name)
    ]
    return ", ".join(diff)


__all__ = ["ENGINES", "STAGES", "Engines", "World", "auto_stepping"]
