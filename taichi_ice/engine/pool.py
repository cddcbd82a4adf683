"""The Worlds a process keeps, their kernels compiled: ``WorldPool`` and this process's ``POOL``.

    sim = Simulation(scene)            # a World from POOL: built, or one idle reloaded
    del sim                            # ... idle again once nothing holds it
    with POOL.lease() as make:         # a batch's Worlds, given back on leaving
        result = Simulation(scenes, worlds=make).run(until=10.0)

A World compiles its kernels for its layout (its capacities, precision, law kind,
integrator and stepping; values, dt and the counts below the capacities are data), and a
new World compiles them again even in a process that has compiled the same kernels before:
Taichi keys them by the fields they close over, and writes its offline cache only when the
process ends (measured on 2 cores with an empty cache: three ``Simulation`` of
``two_squares`` in one process took 13.0, 13.2 and 12.5 s to their first 0.01 s each with a
new World; 12.6, 0.9 and 0.01 s from the pool). So a World
is taken from the pool by every ``Simulation`` (``WorldPool.take``) and by the batches of
sweeps, ensembles and studies (``lease``); one no longer used is handed out again, reloaded
with the new scenes.

Engine-level: it builds and reloads ``world.World`` and knows nothing of sweeps, ensembles
or the command line (they lease from it). Which scenes make a batch is the caller's.
"""

from __future__ import annotations

import contextlib
import gc
import sys
import threading
import weakref
from collections.abc import Sequence
from typing import Any

from .options import Options
from .world import ENGINES

__all__ = ["POOL", "WorldPool"]


class _Entry:
    """A World the pool knows, and whether it is in use.

    In use while leased (``lease``), or while its owner (a ``Simulation``, held weakly)
    lives, or while anything but the pool and the World itself holds it: ``others`` is the
    number of references the World holds to itself (cycles through its stages), counted
    when it was built, and ``sys.getrefcount`` tells the rest. A World that a caller kept
    (``w = sim.world``) is never handed out under it.
    """

    __slots__ = ("asked", "generation", "leased", "others", "owner", "world")

    def __init__(self, world, asked: Options, others: int, generation: int):
        self.world = world
        self.asked = asked
        self.owner: weakref.ref | None = None
        self.leased = False
        self.others = others
        self.generation = generation

    def free(self) -> bool:
        if self.leased or (self.owner is not None and self.owner() is not None):
            return False
        # This entry's reference and getrefcount's argument, and the World's own.
        return sys.getrefcount(self.world) - 2 == self.others


class WorldPool:
    """The Worlds a process keeps, their kernels compiled, handed out again when idle.

    A World's kernels specialise on its layout and close over its fields, so each new
    World compiles them all again (13 s for two squares, about 20 s for the pillar scene on
    2 cores, where Taichi's offline cache does not yet hold them). The pool hands out an
    idle World of the same layout reloaded with the new scenes (``World.reload``: bit for
    bit what a new World gives) and builds one only when it has none. A World serves one
    batch at a time. Worlds of an earlier Taichi runtime (``backend.init(...,
    reinit=True)`` frees every field) are dropped.

    Attributes:
        built, reloaded: Worlds built, and Worlds handed out again, so far.
    """

    def __init__(self):
        self._entries: list[_Entry] = []
        self._lock = threading.Lock()
        self.built = 0
        self.reloaded = 0

    def __len__(self) -> int:
        return len(self._entries)

    def idle(self) -> int:
        """How many of the pool's Worlds could be handed out now."""
        with self._lock:
            return sum(e.free() for e in self._entries)

    def get(self, scenes: Sequence, options: Options | None = None):
        """A World of ``scenes`` with ``options`` (as ``World(scenes, options)``), leased
        until ``put`` gives it back: an idle one reloaded, or a new one. A World is handed
        out again only as a new one would be built: of the same layout, and with
        ``options.slots`` None, with the slots these scenes get by default; precision None
        is the one Taichi runs."""
        entry = self._acquire(scenes, options)
        return entry.world

    def take(self, scenes: Sequence, options: Options | None, owner):
        """A World for ``owner`` (a ``Simulation``), as ``get``: it is idle again once the
        owner is gone and nothing else holds the World."""
        entry = self._acquire(scenes, options)
        with self._lock:
            entry.owner = weakref.ref(owner)
            entry.leased = False
        return entry.world

    def _acquire(self, scenes: Sequence, options: Options | None) -> _Entry:
        from .. import backend
        from ..errors import UsageError
        from .world import World

        options, scenes = (Options() if options is None else options).resolved().for_scenes(scenes)
        scenes = list(scenes)
        n_bodies = sum(len(s.bodies) for s in scenes)
        generation = backend.generation()

        def fits(e: _Entry) -> bool:
            w = e.world
            return (
                e.asked.stepping == options.stepping
                and w.precision == options.precision
                and w.layout.energy == options.energy
                and w.layout.integrator == options.integrator
                and w.layout.n_worlds >= len(scenes)
                and w.layout.n_bodies >= n_bodies
                and options.slots in (None, w.layout.slots)
            )

        refused: list[_Entry] = []  # of another layout (sizes the checks above do not see)
        collected = False
        while True:
            with self._lock:
                self._entries = [e for e in self._entries if e.generation == generation]
                entry = next(
                    (e for e in self._entries if e not in refused and fits(e) and e.free()),
                    None,
                )
                if entry is not None:
                    entry.leased, entry.owner = True, None  # ours while it reloads
                else:
                    held = any(e not in refused and fits(e) and not e.leased for e in self._entries)
            if entry is None:
                if held and not collected:
                    # A World held only by a reference cycle (a failed run's traceback holds
                    # its Simulation) is idle once Python's collector runs: before compiling.
                    gc.collect()
                    collected = True
                    continue
                break
            try:
                entry.world.reload(scenes, dt=options.dt, force_dt=options.force_dt)
                batch = entry.world.batch
                if options.slots is None and batch.default_slots != batch.layout.slots:
                    # A new World would have other slots: the reloaded one could stop where
                    # a new one runs, and would not be the same run bit for bit.
                    raise UsageError("other contact slots")
            except UsageError:  # another layout: the World is idle, its content stale
                entry.leased = False
                refused.append(entry)
                continue
            except BaseException:
                entry.leased = False
                raise
            entry.asked = options
            self.reloaded += 1
            return entry
        world = World(scenes, options)
        # The World's references to itself: all that holds it but this name and the argument.
        others = sys.getrefcount(world) - 2
        entry = _Entry(world, options, others, generation)
        entry.leased = True
        del world
        with self._lock:
            self._entries.append(entry)
        self.built += 1
        return entry

    def release(self, key: tuple) -> bool:
        """Let go of one idle World whose kernels are ``key`` (``World.engine_key``), so that
        its fields and kernels pass to a World being built outside the pool
        (``engines.Engines``) instead of it compiling its own; False if there is none."""
        with self._lock:
            for e in self._entries:
                if e.world.engine_key == key and e.free():
                    self._entries.remove(e)
                    return True
        return False

    def put(self, world, asked: Options | None = None) -> None:
        """Give back a World that ``get`` or ``lease`` handed out: the next batch may take
        it (``asked``: the options it was built for, kept for the record)."""
        with self._lock:
            for e in self._entries:
                if e.world is world:
                    e.leased = False
                    e.owner = None
                    if asked is not None:
                        e.asked = asked
                    return
        raise ValueError("WorldPool.put: this World did not come from this pool")

    @contextlib.contextmanager
    def lease(self):
        """``with pool.lease() as make: Simulation(scenes, worlds=make)``: the Worlds
        ``make`` hands out go back to the pool on leaving."""
        out: list[Any] = []

        def make(scenes, options: Options | None = None):
            world = self.get(scenes, Options() if options is None else options)
            out.append(world)
            return world

        try:
            yield make
        finally:
            for world in out:
                self.put(world)


# This process's Worlds: a Dask worker keeps them from one batch to the next.
POOL = WorldPool()


def _release_idle(key: tuple) -> bool:
    """``engines.Engines``'s ask before it builds a World anew: the process's pool (as it is
    now: tests put a pool of their own in its place) lets go of an idle World of ``key``."""
    return POOL.release(key)


ENGINES.holders.append(_release_idle)
