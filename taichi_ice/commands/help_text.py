"""Help texts that several commands' options share: where the kernels run, the precision,
the contact slots, and a scene given as a file or a bundled name.

Kept apart from ``cli`` so that ``commands.bench`` and ``commands.sweep``, whose options
``cli`` builds, take the same words without importing ``cli``.
"""

from __future__ import annotations

from ..engine.options import BODY_FLOOR, DEFAULT_SMALL_SLOTS, LARGE_SLOTS, MAX_SLOTS

__all__ = ["ARCH_HELP", "PRECISION_HELP", "SLOTS_HELP", "scene_help"]

ARCH_HELP = (
    "where the kernels run: cpu (the default, every core), gpu (the GPU backend Taichi finds: "
    "CUDA, Vulkan or Metal), or one of cuda, vulkan, metal by name; one this machine lacks "
    "is refused before the run starts"
)
OPTIMIZE_HELP = (
    "how much of Taichi's optimisation the kernels get: on (the default on the CPU: a first "
    "run compiles in ~5-9 s on 2 cores), full (every pass, the default on GPUs: 21-116 s to "
    "compile, then 4-10 %% faster a step on the CPU: for runs that step one scene for more "
    "than ~5 min; the cache keeps the kernels for the next run) or off; the same results bit "
    "for bit. Sets TAICHI_ICE_OPTIMIZE for this command and its workers"
)
PRECISION_HELP = (
    "floating-point type of the simulation state: f64 (64-bit) or f32 (32-bit: less memory "
    "and often faster on a GPU, with rounding near 1e-7 of each value, so the energy budget "
    "closes less tightly)"
)
SLOTS_HELP = (
    f"the most contacts one body can hold at once (1-{MAX_SLOTS}; default "
    f"{DEFAULT_SMALL_SLOTS}, plus one per wall or pusher in the scene, up to {LARGE_SLOTS} "
    f"more; {DEFAULT_SMALL_SLOTS + LARGE_SLOTS} in a scene of up to {BODY_FLOOR} bodies). A "
    "body that touches more in a step stops the run with an error that names the number to "
    "pass; raise it for dense packs, or a body among much smaller ones. Each slot costs "
    "about 20 bytes per body"
)


def scene_help(what: str) -> str:
    """The help of an option or argument that takes a scene: a file, or a bundled name."""
    from ..scene.parse import bundled_scenes

    return (
        f"{what}: a scene file (TOML), e.g. scenarios/pillar.toml, or the name of a scene "
        f"bundled with taichi-ice, from any directory: {', '.join(bundled_scenes())}"
    )
