"""One place that starts Taichi: arch and precision are run options, never code forks.

Taichi holds one runtime per process. ``init`` starts it on first use and afterwards only
checks that later callers ask for the same arch and precision; a different request is an
error rather than a silent re-initialisation, which would free every field already built.

``ti.init`` prints "[Taichi] Starting on arch=..." on every start; ``init`` drops that line
unless the environment variable ``ENABLE_TAICHI_HEADER_PRINT`` asks for Taichi's messages (the
variable that also governs Taichi's import banner; ``taichi_ice/__init__.py`` sets it to "0"
unless the user set it).
"""

from __future__ import annotations

import contextlib
import io
import os
import sys

ARCHES = ("cpu", "gpu", "cuda", "vulkan", "metal")
PRECISIONS = ("f64", "f32")

_current: tuple[str, str] | None = None

# The line ti.init prints unconditionally (taichi/lang/misc.py, a plain print to stdout).
_START_LINE = "[Taichi] Starting on arch="


def real_dtype(precision: str):
    """NumPy dtype that matches a precision name ('f64' or 'f32')."""
    import numpy as np

    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    return np.float64 if precision == "f64" else np.float32


def current_arch():
    """The arch Taichi was started on by ``init`` ('cpu', 'gpu', ...), or None."""
    return None if _current is None else _current[0]


def init(arch: str = "cpu", precision: str = "f64", *, reinit: bool = False) -> None:
    """Start Taichi on ``arch`` with ``precision`` as its default float type.

    Args:
        arch: 'cpu', or 'gpu' (Taichi picks CUDA, Vulkan or Metal), or a backend by name.
        precision: 'f64' (default on the CPU) or 'f32'.
        reinit: allow switching arch or precision; every existing field becomes invalid.

    Raises:
        ValueError: unknown arch or precision, or a different arch/precision than the
            running one without ``reinit``.
    """
    global _current
    if arch not in ARCHES:
        raise ValueError(f"arch must be one of {ARCHES}, got {arch!r}")
    real_dtype(precision)
    wanted = (arch, precision)
    if _current == wanted:
        return
    if _current is not None and not reinit:
        raise ValueError(
            f"Taichi already runs with arch={_current[0]}, precision={_current[1]}; "
            f"this process cannot also use arch={arch}, precision={precision}. "
            "Start a new process (or pass reinit=True, which frees every existing field)."
        )
    import taichi as ti

    with _quiet_start():
        ti.init(
            arch=getattr(ti, arch),
            default_fp=ti.f64 if precision == "f64" else ti.f32,
            default_ip=ti.i32,
            log_level=ti.WARN,
            offline_cache=True,
        )
    _current = wanted


@contextlib.contextmanager
def _quiet_start():
    """Drop ti.init's start-up line from stdout, and pass everything else printed through.

    Only Python's ``sys.stdout`` is captured: Taichi's warnings (an arch falling back to the
    CPU) come from its C++ logger and still reach the terminal.
    """
    if _taichi_messages_wanted():
        yield
        return
    captured = io.StringIO()
    try:
        with contextlib.redirect_stdout(captured):
            yield
    finally:
        kept = [
            line
            for line in captured.getvalue().splitlines(keepends=True)
            if not line.startswith(_START_LINE)
        ]
        sys.stdout.write("".join(kept))


def _taichi_messages_wanted() -> bool:
    """True when ENABLE_TAICHI_HEADER_PRINT is set and not false, read as Taichi reads it."""
    return os.environ.get("ENABLE_TAICHI_HEADER_PRINT", "0").lower() not in ("false", "0", "f")


def current() -> tuple[str, str] | None:
    """(arch, precision) of the running Taichi runtime, or None before ``init``."""
    return _current
