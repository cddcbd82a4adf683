"""The Worlds a process keeps, their kernels compiled: ``WorldPool`` and this process's ``POOL``.

    from taichi_ice.engine.pool import POOL
    with POOL.lease() as make:
        result = Simulation(scenes, worlds=make).run(until=10.0)

A World compiles its kernels for its layout (its sizes, precision and stepping); a batch
that comes after another of the same layout takes that World, reloaded with its scenes,
instead of compiling again. A Dask worker of a sweep keeps its Worlds from one batch to the
next, and so does a resumable ensemble or paper run from one law to the next.

Engine-level: it builds and reloads ``world.World`` and knows nothing of sweeps, ensembles
or the command line (they lease from it). Which scenes make a batch is the caller's.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Sequence
from typing import Any

from .options import Options

__all__ = ["POOL", "WorldPool"]


class WorldPool:
    """The Worlds a process keeps between batches, their kernels compiled.

    A World's kernels specialise on its layout and close over its fields, so each new
    World compiles them all again (about 20 s for the pillar scene on 2 cores). The pool
    hands out an idle World of the same layout reloaded with the new scenes
    (``World.reload``: bit for bit what a new World gives) and builds one only when it has
    none. A World serves one batch at a time: ``lease()`` gives what makes the Worlds of a
    batch (``Simulation(worlds=...)``) and, on leaving, gives them back.

    Attributes:
        built, reloaded: Worlds built, and Worlds handed out again, so far.
    """

    def __init__(self):
        self._idle: list[tuple[Any, Options]] = []  # (World, the options asked for)
        self._lock = threading.Lock()
        self.built = 0
        self.reloaded = 0

    def get(self, scenes: Sequence, options: Options | None = None):
        """A World of ``scenes`` with ``options`` (as ``World(scenes, options)``): an idle
        one reloaded, or a new one. With ``options.slots`` None any idle World's slots are
        taken; precision None is the one Taichi runs."""
        from ..errors import UsageError
        from .world import World

        options = (Options() if options is None else options).resolved()
        scenes = list(scenes)
        n_bodies = sum(len(s.bodies) for s in scenes)
        with self._lock:
            candidates = [
                (w, asked)
                for w, asked in self._idle
                if asked.stepping == options.stepping
                and w.precision == options.precision
                and w.layout.energy == options.energy
                and w.layout.integrator == options.integrator
                and w.layout.n_worlds == len(scenes)
                and w.layout.n_bodies == n_bodies
                and options.slots in (None, w.layout.slots)
            ]
        for entry in candidates:
            with self._lock:
                if entry not in self._idle:
                    continue
                self._idle.remove(entry)
            try:
                entry[0].reload(scenes, dt=options.dt, force_dt=options.force_dt)
            except UsageError:  # another layout: the World is as it was
                self.put(*entry)
                continue
            except BaseException:
                self.put(*entry)
                raise
            self.reloaded += 1
            return entry[0]
        world = World(scenes, options)
        self.built += 1
        return world

    def put(self, world, asked: Options) -> None:
        """Give ``world`` back (built for ``asked``): the next batch may take it."""
        with self._lock:
            self._idle.append((world, asked))

    @contextlib.contextmanager
    def lease(self):
        """``with pool.lease() as make: Simulation(scenes, worlds=make)``: the Worlds
        ``make`` hands out go back to the pool on leaving."""
        out: list[tuple[Any, str]] = []

        def make(scenes, options: Options | None = None):
            options = Options() if options is None else options
            world = self.get(scenes, options)
            out.append((world, options))
            return world

        try:
            yield make
        finally:
            for world, asked in out:
                self.put(world, asked)


# This process's Worlds: a Dask worker keeps them from one batch to the next.
POOL = WorldPool()
