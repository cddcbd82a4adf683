"""The fields and compiled stages of Worlds that are gone, kept for the next World of their
layout in this process: ``Engines`` and this process's ``ENGINES``.

``world.World`` gives its parts back here when it is collected and takes them from here
before building new ones; ``pool.WorldPool`` registers itself as a holder of idle Worlds.
No Taichi: the parts are opaque here.
"""

from __future__ import annotations

import gc
import threading


class Engines:
    """The fields and compiled stages of Worlds that are gone, by layout, for the next World
    of that layout in this process.

    A World's kernels close over its fields, so a new World compiles every kernel anew even
    where the process compiled the same ones before (Taichi keys them by the fields, and its
    offline cache by the fields' ids: it serves a new process that builds its fields in the
    same order, docs/architecture.md), and Taichi frees no field before the process ends.
    So when a World is collected its parts (fields and stages, ``World._build``) come here,
    and a World built later for the same layout, stepping and team takes them, every field
    back to its start (``World._start``, as ``World.reload``): no new fields,
    nothing compiled, and, bit for bit, the run of a World on new fields
    (``tests/test_options.py``). Parts of an earlier Taichi start are dropped.

    Attributes:
        built, reused: Worlds built on new fields, and on fields of a World gone, so far.
        holders: callables ``release(key) -> bool`` of what keeps idle Worlds, asked to let
            go of one of ``key`` before a World is built anew (``engine.pool`` adds its own).
    """

    def __init__(self):
        self._idle: dict[tuple, list[dict]] = {}
        self._lock = threading.Lock()
        self.built = 0
        self.reused = 0
        self.holders: list = []

    def take(self, key: tuple) -> dict | None:
        """The parts of a World gone for ``key`` (layout, stepping, team, generation), or
        None (the caller builds them: counted as built).

        Before answering None (and the caller compiling a set anew: seconds), it asks
        whoever keeps idle Worlds (``holders``: the process's pool, ``pool.WorldPool.release``,
        where a ``Simulation`` gone leaves its World) to let go of one of ``key``, and runs
        Python's collector, since a World gone in a reference cycle gives its parts back
        only then."""
        parts = self._pop(key)
        if parts is None:
            for release in list(self.holders):
                if release(key):
                    break
            gc.collect()  # outside the lock: the finalizers it runs call give_back
            parts = self._pop(key)
        with self._lock:
            if parts is None:
                self.built += 1
            else:
                self.reused += 1
        return parts

    def _pop(self, key: tuple) -> dict | None:
        with self._lock:
            generation = key[-1]
            self._idle = {k: v for k, v in self._idle.items() if k[-1] == generation and v}
            idle = self._idle.get(key)
            return idle.pop() if idle else None

    def give_back(self, key: tuple, parts: dict) -> None:
        """``parts`` of a World gone, for the next World of ``key``."""
        with self._lock:
            self._idle.setdefault(key, []).append(parts)

    def clear(self) -> None:
        """Forget every idle part (their fields stay allocated until the process ends)."""
        with self._lock:
            self._idle.clear()

    def idle(self) -> int:
        """Parts waiting for a World."""
        with self._lock:
            return sum(len(v) for v in self._idle.values())


# This process's idle parts of Worlds.
ENGINES = Engines()


__all__ = ["ENGINES", "Engines"]
