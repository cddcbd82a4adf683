"""How big a scene may be: estimated before anything is allocated, refused with the estimate.

A field of 1e7 blocks used to run for minutes, growing to 16 GB, before the machine killed
it. ``check_size`` is called when a scene is read (``scene.parse``) and before a batch is
allocated (``Simulation``), from the body count alone.
"""

from __future__ import annotations

import contextlib
import os

from .errors import SizeError

# Bytes per body of a run, scene and engine together. Measured with /proc/self/statm on the
# 2-core VM, a field of 50,000 diamonds, float64: 0.8 kB per body for the scene (Body objects
# and their arrays), 2.4 kB more once Simulation has assembled the host arrays and allocated
# the Taichi fields (1.35 kB of them, measured then); rounded up for the copies made on the way.
BYTES_PER_BODY = 4096
# Body ids are 32-bit integers in the kernels.
MAX_BODIES = 2**31 - 1


def memory_limit() -> tuple[int, str] | None:
    """``(bytes, what)``: the memory a new allocation of this process can have now, the
    least of the machine's (Linux ``MemAvailable``, else the physical memory), the job's
    cgroup (v2 ``memory.max`` less ``memory.current``, or v1's limit less usage: a
    container's or a batch scheduler's limit) and the address space ``ulimit -v`` leaves
    (``RLIMIT_AS`` less this process's ``VmSize``); ``what`` names the one that binds.
    None when none can be read."""
    found: list[tuple[int, str]] = []
    with contextlib.suppress(OSError, ValueError, IndexError):
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    found.append((int(line.split()[1]) * 1024, "this machine has available"))
                    break
    if not found:
        with contextlib.suppress(OSError, ValueError, AttributeError):
            phys = int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
            found.append((phys, "this machine has"))
    for limit_file, usage_file in (
        ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
        (
            "/sys/fs/cgroup/memory/memory.limit_in_bytes",
            "/sys/fs/cgroup/memory/memory.usage_in_bytes",
        ),
    ):
        with contextlib.suppress(OSError, ValueError):
            with open(limit_file, encoding="ascii") as fh:
                text = fh.read().strip()
            if text != "max" and int(text) < 1 << 60:  # v1 writes a huge number for none
                with open(usage_file, encoding="ascii") as fh:
                    used = int(fh.read().strip())
                found.append((max(int(text) - used, 0), "this job's cgroup leaves"))
            break
    with contextlib.suppress(ImportError, OSError, ValueError):
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            found.append((max(soft - _vm_size(), 0), "ulimit -v leaves this process"))
    return min(found) if found else None


def _vm_size() -> int:
    with open("/proc/self/status", encoding="ascii") as fh:
        for line in fh:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    return 0


def available_memory() -> int | None:
    """Bytes of memory a new allocation can have now (``memory_limit``), or None."""
    limit = memory_limit()
    return None if limit is None else limit[0]


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
    limit = memory_limit()
    if limit is not None and need > limit[0]:
        have, what = limit
        raise SizeError(
            f"{where}: {n:,} bodies need about {need / 1e9:.3g} GB of memory "
            f"({BYTES_PER_BODY} bytes each) and {what} {have / 1e9:.3g} GB: {fix}"
        )


__all__ = [
    "BYTES_PER_BODY",
    "MAX_BODIES",
    "available_memory",
    "check_size",
    "estimate_bytes",
    "memory_limit",
]
