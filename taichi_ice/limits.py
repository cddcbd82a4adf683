"""How big a scene may be: estimated before anything is allocated, refused with the estimate.

A field of 1e7 blocks used to run for minutes, growing to 16 GB, before the machine killed
it. ``check_size`` is called when a scene is read (``scenario``) and before a batch is
allocated (``Simulation``), from the body count alone.
"""

from __future__ import annotations

import os

from .errors import SizeError

# Bytes per body of a run, scene and engine together. Measured with /proc/self/statm on the
# 2-core VM, a field of 50,000 diamonds, float64: 0.8 kB per body for the scene (Body objects
# and their arrays), 2.4 kB more once Simulation has assembled the host arrays and allocated
# the Taichi fields (README: 1.35 kB of them); rounded up for the copies made on the way.
BYTES_PER_BODY = 4096
# Body ids are 32-bit integers in the kernels.
MAX_BODIES = 2**31 - 1


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation now (Linux ``MemAvailable``), else the
    physical memory, else None when neither can be read."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (OSError, ValueError, AttributeError):
        return None


def estimate_bytes(n_bodies: int) -> int:
    """Memory a run of ``n_bodies`` bodies needs, about (bytes)."""
    return int(n_bodies) * BYTES_PER_BODY


def check_size(n_bodies: int, where: str, fix: str = "make the scene smaller") -> None:
    """Refuse ``n_bodies`` bodies if the run cannot fit in memory or in 32-bit ids.

    Raises:
        SizeError: naming ``where``, the estimate, what is available, and ``fix``.
    """
    n = int(n_bodies)
    if n > MAX_BODIES:
        raise SizeError(
            f"{where}: {n:,} bodies; the kernels number bodies with 32-bit integers, at most "
            f"{MAX_BODIES:,}: {fix}"
        )
    need = estimate_bytes(n)
    have = available_memory()
    if have is not None and need > have:
        raise SizeError(
            f"{where}: {n:,} bodies need about {need / 1e9:.3g} GB of memory "
            f"({BYTES_PER_BODY} bytes each) and this machine has {have / 1e9:.3g} GB "
            f"available: {fix}"
        )


__all__ = ["BYTES_PER_BODY", "MAX_BODIES", "available_memory", "check_size", "estimate_bytes"]
