"""Sweep plans: a sweep's worlds cut into batches that can share one World, and what a
worker needs to run each (plain data: it travels to other machines).

    from taichi_ice.experiments.sweep.plan import batch_spec, contact_slots, plan_batches
    batches = plan_batches(sweep, sweep.worlds(), workers=4)
    specs = [batch_spec(sweep, b, None, "cpu", "f64", contact_slots(sweep)) for b in batches]

Worlds that can share one ``World`` (the same law kind and theta integrator, ice, water and
time step) go into the same batches. Kernels compile for capacities (``assemble.capacity``),
so a batch shorter than the largest of its kind runs on that batch's World as it is when its
layout is the same, and otherwise may be padded with copies of its last world up to the
fewest worlds that have that layout, where running them costs less than compiling the
kernels again (``COMPILE_SECONDS``). Every world is bit-identical alone and in any batch,
so the plan changes the cost, never a result.

Reading the sweep is ``sweep.spec``'s; running the batches ``sweep.run``'s.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ...codes import ThetaMethod
from .spec import Case, Sweep, apply_overrides

__all__ = ["PlannedBatch", "batch_id", "batch_spec", "contact_slots", "plan_batches"]

# Worlds per batch at most: on a CPU a batch is stepped a thread per world, and more worlds
# than threads only lengthen the batch; on a GPU a batch should fill the device.
MAX_BATCH = {"cpu": 64, "gpu": 4096}
# A worker compiles the kernels once per layout (pool.WorldPool); a batch shorter than the
# others of its kind is padded to their size when running the copies costs less than a compile.
# Measured on the 2-core VM (pillar scene, 3 worlds): a World built in 4 s and its kernels
# compiled in 15.5 s; a thread steps small worlds at 1.2-1.4 M body-steps/s (world.py).
COMPILE_SECONDS = 20.0
BODY_STEPS_PER_SECOND = 1.2e6


def _override_scene(sweep: Sweep, overrides, scenes: dict):
    """The sweep's scene with ``overrides`` applied (memoised in ``scenes``)."""
    scene = scenes.get(overrides)
    if scene is None:
        scene = apply_overrides(sweep.scene, overrides) if overrides else sweep.scene
        scenes[overrides] = scene
    return scene


def _share_key(sweep: Sweep, case: Case, scenes: dict, law_kind: bool = False) -> str:
    """Worlds with equal keys can share one World: same law kind and integrator, ice, water,
    simulation settings (time step, intervals) and whether their runs are written.

    With ``law_kind``, the key of the compiled kernels instead: the law's name becomes
    "coulomb" or "rate-state" (every other law runs on the rate-and-state kernels), so
    batches of rate-state, steady-state and memory-only worlds of one size share a layout.
    """
    scene = _override_scene(sweep, case.overrides, scenes)
    settings = dataclasses.replace(scene.simulation, seed=0)
    law, method = case.law["law"], case.law.get("method")
    if law_kind:
        # A law without a theta integrator runs on the default one (assemble).
        law = "coulomb" if law == "coulomb" else "rate-state"
        method = method or (None if law == "coulomb" else ThetaMethod.EXPONENTIAL.label)
    return repr(
        (
            law,
            method,
            scene.dt,
            settings,
            scene.ice,
            scene.water,
            case.index in sweep.runs,
        )
    )


@dataclass(frozen=True)
class PlannedBatch:
    """A batch of a sweep's plan: its worlds, and ``pad`` copies of its last world run
    with them (not recorded) so that it has the size of the other batches of its layout."""

    worlds: tuple[Case, ...]
    pad: int = 0


def plan_batches(
    sweep: Sweep,
    worlds: Sequence[Case],
    workers: int,
    arch: str = "cpu",
    slots: int | None = None,
) -> list[PlannedBatch]:
    """Cut ``worlds`` into batches of worlds that can share one World.

    The batch size is the sweep's, or else each group's worlds split evenly over the
    workers (so every worker gets work), at most ``MAX_BATCH`` worlds, the group cut into
    batches whose sizes differ by one at most. The batches come longest first
    (``batch_seconds``), the order in which ``run_sweep`` submits them.

    A worker compiles the kernels once per layout (``pool.WorldPool``), and a batch's layout
    depends on its size through the capacities: where a kind of batch (the law's kernels,
    the same scene settings) has more batches than there are workers, a batch shorter than
    the largest of its kind whose layout is not the largest's is padded with copies of its
    last world, to the fewest worlds with that layout, when running them costs less than
    compiling (``COMPILE_SECONDS``, ``BODY_STEPS_PER_SECOND``). Each world is bit-identical
    in any batch, so padding changes the cost, never a result.

    ``slots``: the contact slots every batch gets (``contact_slots``, computed if None).
    """
    groups: dict[str, list[Case]] = {}
    scenes: dict = {}
    for w in worlds:
        groups.setdefault(_share_key(sweep, w, scenes), []).append(w)
    cap = MAX_BATCH["cpu" if arch == "cpu" else "gpu"]
    chunks: list[list[Case]] = []
    for group in groups.values():
        if sweep.batch_size:
            size = sweep.batch_size
        else:
            size = min(cap, max(1, math.ceil(len(group) / max(workers, 1))))
            # As even as the number of batches allows: 7 worlds in 4 + 3, not 6 + 1.
            size = math.ceil(len(group) / math.ceil(len(group) / size))
        chunks += [group[i : i + size] for i in range(0, len(group), size)]

    kinds = [_share_key(sweep, c[0], scenes, law_kind=True) for c in chunks]
    largest: dict[str, int] = {}
    for kind, chunk in zip(kinds, chunks):
        largest[kind] = max(largest.get(kind, 0), len(chunk))
    layouts = _Layouts(sweep, slots)
    batches = []
    for kind, chunk in zip(kinds, chunks):
        pad = 0
        # Only where a worker runs more than one batch of the kind; never a batch whose
        # runs are written (its files are its worlds').
        shared = kinds.count(kind) > max(workers, 1)
        written = chunk[-1].index in sweep.runs
        if shared and not written and len(chunk) < largest[kind]:
            pad = layouts.fewest_alike(chunk[-1], len(chunk), largest[kind]) - len(chunk)
            if _pad_seconds(sweep, chunk, pad) > COMPILE_SECONDS:
                pad = 0
        batches.append(PlannedBatch(tuple(chunk), pad))
    # Longest first (stable): a worker that finishes early then takes a short batch, so the
    # sweep does not end waiting on one long batch that started last (a study's models with
    # memory take four times the steps of its Coulomb ones).
    batches.sort(key=lambda b: -batch_seconds(sweep, b))
    return batches


class _Layouts:
    """The layout of a batch of ``n`` copies of a sweep's world (memoised), as a worker
    assembles it."""

    def __init__(self, sweep: Sweep, slots: int | None):
        self.sweep, self.slots, self.memo = sweep, slots, {}

    def of(self, case: Case, n: int):
        from ...engine.assemble import assemble
        from ...engine.options import Options
        from .spec import world_scene

        if self.slots is None:
            self.slots = contact_slots(self.sweep)
        key = (case.overrides, repr(sorted(case.law.items())), n)
        if key not in self.memo:
            scene = world_scene(self.sweep.scene, case.overrides, case.seed, case.law)
            options = Options(slots=self.slots, force_dt=True)
            self.memo[key] = assemble([scene] * n, options).layout
        return self.memo[key]

    def fewest_alike(self, case: Case, n: int, largest: int) -> int:
        """The fewest worlds from ``n`` to ``largest`` whose batch has the layout of
        ``largest`` (capacities grow with the count: a bisection)."""
        target = self.of(case, largest)
        lo, hi = n, largest
        while lo < hi:
            mid = (lo + hi) // 2
            if self.of(case, mid) == target:
                hi = mid
            else:
                lo = mid + 1
        return lo


def _pad_seconds(sweep: Sweep, chunk: Sequence[Case], pad: int) -> float:
    """Estimated seconds (one thread) to run ``pad`` more copies of a world of ``chunk``, at
    its law's step (a law with memory steps at a smaller ``dt_safety``)."""
    from ...physics.friction_parse import law_from_table

    scene = _override_scene(sweep, chunk[-1].overrides, {})
    steps = math.ceil(sweep.until / scene.with_friction(law_from_table(chunk[-1].law)).dt)
    return pad * len(scene.bodies) * steps / BODY_STEPS_PER_SECOND


def batch_seconds(sweep: Sweep, batch: PlannedBatch) -> float:
    """Estimated seconds (one thread) to run ``batch``, its padding included."""
    return _pad_seconds(sweep, batch.worlds, len(batch.worlds) + batch.pad)


def contact_slots(sweep: Sweep) -> int:
    """Contact slots per body that every batch of ``sweep`` gets: the most that any world
    needs (``assemble``'s default). Batches of equal slots and size share a layout, so a
    worker compiles once for all of them."""
    from ...engine.assemble import assemble
    from ...engine.options import Options

    keys = list(sweep.overrides)
    slots = 1
    for combo in itertools.product(*(sweep.overrides[k] for k in keys)):
        pairs = tuple(zip(keys, combo))
        scene = apply_overrides(sweep.scene, pairs) if pairs else sweep.scene
        # Seeds move blocks, never change their shapes: the slots are the scene's.
        slots = max(slots, assemble([scene], Options(force_dt=True)).layout.slots)
    return slots


def batch_id(worlds: Sequence[Case]) -> str:
    """A batch's name: a hash of its worlds' keys (the same worlds, the same name)."""
    h = hashlib.sha1("\n".join(w.key for w in worlds).encode()).hexdigest()
    return h[:12]


def batch_spec(
    sweep: Sweep,
    batch: PlannedBatch | Sequence[Case],
    run_dir: Path | None,
    arch,
    precision,
    slots: int | None = None,
):
    """What a worker needs to run a batch: plain data (it travels to other machines)."""
    if not isinstance(batch, PlannedBatch):
        batch = PlannedBatch(tuple(batch))
    worlds = batch.worlds
    return {
        "id": batch_id(worlds),
        "scene_text": sweep.scene.text,
        "scene_source": sweep.scene.source,
        "until": sweep.until,
        "window": sweep.window,
        "arch": arch,
        "precision": precision,
        "slots": slots,
        "pad": batch.pad,
        "worlds": [
            {
                "index": w.index,
                "key": w.key,
                "seed": w.seed,
                "law": dict(w.law),
                "overrides": list(w.overrides),
                "run": str(run_dir / w.run_name) if run_dir and w.index in sweep.runs else None,
            }
            for w in worlds
        ],
    }
