"""Memory and traffic of a World: field bytes, process RSS, bytes a step must move.

The traffic model is the stages' own declarations (``taichi_ice.engine.schema``): every field a
kernel reads or writes, counted once per launch, so the bound it gives is optimistic.
"""

from __future__ import annotations

import contextlib
import os
import resource
import sys

__all__ = ["STEP_KERNELS", "field_bytes", "rss_bytes", "traffic"]

# The kernels of a step by the World's stepping. (The parallel step's hash and list rebuilds
# run once in hundreds of steps and are left out. On the CPU its two stages run in one
# launch, ``team.run``, but each step still moves what each of them reads and writes.)
STEP_KERNELS = {
    "bodies": ("contacts.compute", "integrator.advance"),
    "worlds": ("stepper.run",),
}


def field_bytes(world) -> dict[str, int]:
    """Bytes of the World's Taichi fields, per group (model, data, hash), from the schema."""
    from ...engine import schema

    sizes = schema.field_bytes(world.layout)
    return {group: sum(sizes[v.name] for v in decls) for group, decls in schema.groups().items()}


def traffic(world, contacts: float) -> dict:
    """Bytes per step the kernels of a step must move with ``contacts`` contacts per step.

    Returns:
        ``bytes_per_step``, ``bytes_per_kernel`` (``{"stage.kernel": bytes}``), and the split
        into ``bytes_per_body`` and ``bytes_per_contact``.
    """
    from ...engine import stages
    from ...engine.world import STAGES

    kernels = STEP_KERNELS[getattr(world, "stepping", "bodies")]
    if kernels == STEP_KERNELS["bodies"] and world.layout.settles:
        kernels = (*kernels, "contacts.settle_all")  # the analytic steps' third stage
    # The kernels touch the scenes' bodies, not the capacity past them; the hash's buckets
    # are cleared whole.
    layout = world.batch.real.replace(hash_size=world.layout.hash_size)
    per_kernel = stages.traffic(STAGES, layout, contacts, kernels)
    total = per_kernel.pop("total")
    no_contacts = stages.traffic(STAGES, layout, 0.0, kernels)["total"]
    one_contact = stages.traffic(STAGES, layout, 1.0, kernels)["total"]
    return {
        "bytes_per_step": total,
        "bytes_per_kernel": per_kernel,
        "bytes_per_body": no_contacts / layout.n_bodies,
        "bytes_per_contact": one_contact - no_contacts,
    }


def rss_bytes() -> tuple[int, int]:
    """Current and peak resident set size of this process (bytes)."""
    current = 0
    with contextlib.suppress(OSError):
        with open("/proc/self/statm") as fh:
            current = int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    # ru_maxrss is in KiB on Linux (bytes on macOS).
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    peak *= 1 if sys.platform == "darwin" else 1024
    return current, peak
