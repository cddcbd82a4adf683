"""One place that starts Taichi: arch and precision are run options, never code forks.

Taichi holds one runtime per process. ``init`` starts it on first use and afterwards only
checks that later callers ask for the same arch and precision; a different request is an
error rather than a silent re-initialisation, which would free every field already built.

``ti.init`` prints "[Taichi] Starting on arch=..." on every start; ``init`` drops that line
unless the environment variable ``ENABLE_TAICHI_HEADER_PRINT`` asks for Taichi's messages (the
variable that also governs Taichi's import banner; ``taichi_ice/__init__.py`` sets it to "0"
unless the user set it).

Compile time: Taichi compiles each kernel for its batch's layout on first use (cached on
disk afterwards), in one of three settings (``TAICHI_ICE_OPTIMIZE`` in the environment, or
``init(optimize=...)``):

- ``on`` (the default on the CPU): Taichi's advanced IR passes (algebraic simplification,
  constant folding, loop invariants, dead code) without the two that scale worst with a
  kernel's size: the control-flow-graph pass (``cfg_optimization``: store-to-load forwarding
  and dead stores over the whole kernel; left out since 2026-11-28) and the whole-kernel
  common-subexpression pass (``opt_level`` 0; left out since 2026-11-29). Measured on 2
  cores, one sitting, each case a fresh process on an empty cache: the pillar scene's first
  step took 22.2-24.0 s with every pass (three runs), 5.1-5.4 s without the CFG pass,
  3.8-4.5 s with no advanced pass; with the coupled integrator 117 s, 17.8 s and 8.5 s. The
  CSE pass then took most of what was left (2026-11-29, Taichi's scoped profiler: 8.9 s of
  the midstep step's 15.5 s of compiling, 9,553 IR rewrites each scanning the kernel);
  without it the pillar's first step with the coupled step took 7.2-9.2 s against 20.6-21.8
  s, with the Euler step 3.4-4.8 s against 4.7-5.9 s (``benchmarks/README.md``). What it
  costs a step (``benchmarks/compile_settings.py``, 2026-11-29: the settings' Worlds in one
  process, stepped in alternating chunks, medians of 30 rounds' ratios;
  ``results/cpu-2core-compile_settings*``): "on" steps as "off" does or a few per cent
  faster, and every pass ("full") steps 4-10 % faster: on/full 1.10 and 1.08 (two runs) for
  the pillar with rate and state before its jam, 1.09 and 1.10 with the coupled step, 1.08
  and 1.04 for a box of 1e4 blocks stepped by the team; off/full 1.10 and 1.11, 1.11 and
  1.15, 1.08 and 1.06; first steps from an empty cache 4.9-5.5 s (on and off) against
  27.0-29.5 s (full), 8.2-9.1 against 110-116 s, 6.7-7.3 against 21-23 s. The CSE pass alone
  moves no step beyond the VM's noise (pairs without it over with it: 0.98-1.08). So "on"
  pays for runs of minutes: a run that steps one layout for more than about 5 minutes (the
  pillar's extra 22 s of compiling over 8 % of its steps) is faster with
  ``TAICHI_ICE_OPTIMIZE=full``, once per layout (the offline cache keeps it). Trajectories
  are the same bit for bit in all settings (``tests/test_backend.py``; the paired Worlds
  too).
- ``full``: every advanced pass, the CFG and CSE ones included (the default before
  2026-11-28 on the CPU; on GPU archs it stays the default, where runs are long and the
  CPU's steps are 4-10 % faster with it; a GPU's not measured). Taichi's passes run on the
  host whatever the arch: on Vulkan (lavapipe, Mesa's software driver; 2026-11-29, one run
  each, fresh processes, empty caches) the pillar's first step took 37.6 s with it and 7.9 s
  with "on" (Euler, a thread per world), 16.0 and 5.5 s (a kernel per stage), 124.7 and 18.2
  s (the coupled step). ``benchmarks/compile_settings.py --arch cuda`` measures both sides
  on a GPU.
- ``off`` (``0``): no advanced pass (Taichi's basic simplification and dead-code passes
  only; neither the control-flow-graph nor the CSE pass, which Taichi 1.7.4 runs only among
  the advanced ones). The test suite and the accuracy studies (``taichi-ice
  validate``, but its speed study) compile this way.
"""

from __future__ import annotations

import contextlib
import io
import os
import signal
import subprocess
import sys

from . import frontend

ARCHES = ("cpu", "gpu", "cuda", "vulkan", "metal")
PRECISIONS = ("f64", "f32")

_current: tuple[str, str] | None = None
# The arch Taichi actually runs on ("cpu", "cuda", "vulkan", "metal"), read back after start.
_actual: str | None = None
_generation = 0  # Taichi starts in this process (``generation``)
_level: str | None = None  # the running Taichi's compile setting (``compile_level``)
# Taichi's names of CPU archs: a GPU arch that fell back runs on one of these.
_CPU_ARCHES = ("x64", "arm64", "cpu")
# Seconds a child process may take to start Taichi on a GPU arch (import + driver start).
PROBE_TIMEOUT = 180.0
# Bytes of compiled kernels Taichi keeps on disk between processes (see ``init``).
OFFLINE_CACHE_BYTES = 1 << 30

# Environment variable: the compile setting, "off" (or "0"), "on" (or "1") or "full"
# (``optimize_level``; module docstring).
OPTIMIZE_ENV = "TAICHI_ICE_OPTIMIZE"
_OPTIMIZE_NAMES = {
    "off": ("0", "false", "no", "off"),
    "on": ("1", "true", "yes", "on"),
    "full": ("full",),
}
# Taichi's compile options of each setting (module docstring), passed to ``ti.init``.
# ``advanced_optimization``: the advanced IR passes. ``cfg_optimization``: their
# control-flow-graph pass, run in the first round of their loop; Taichi 1.7.4 calls it
# nowhere else (``simplify.cpp``), so "off" never runs it, and keeps the flag as it was
# (the cache's keys of kernels compiled before). ``opt_level``: 0 leaves out their
# whole-kernel common-subexpression pass (and the CFG one; Taichi's passes read the level
# nowhere else). Taichi's offline cache keys kernels by all three (checked), so kernels
# compiled one way are never loaded for another. They are fields of Taichi's config, read
# when a kernel compiles (``benchmarks/compile_settings.py`` sets them per World).
COMPILE_OPTIONS = {
    "off": {"advanced_optimization": False, "cfg_optimization": True, "opt_level": 1},
    "on": {"advanced_optimization": True, "cfg_optimization": False, "opt_level": 0},
    "full": {"advanced_optimization": True, "cfg_optimization": True, "opt_level": 1},
}

# The line ti.init prints unconditionally (taichi/lang/misc.py, a plain print to stdout).
_START_LINE = "[Taichi] Starting on arch="


# The element types of the engine's fields, by the names the state table (``schema``) and
# ``precision`` use: one mapping to NumPy's and Taichi's types, here.
_NUMPY_TYPES = {"f64": "float64", "f32": "float32", "i32": "int32", "i64": "int64"}
DTYPES = tuple(_NUMPY_TYPES)


def numpy_dtype(name: str):
    """The NumPy dtype of a type name of ``DTYPES`` ('f64', 'f32', 'i32', 'i64')."""
    import numpy as np

    return np.dtype(_NUMPY_TYPES[name])


def taichi_dtype(name: str):
    """The Taichi type of a type name of ``DTYPES`` (imports Taichi)."""
    import taichi as ti

    return {"f64": ti.f64, "f32": ti.f32, "i32": ti.i32, "i64": ti.i64}[name]


def real_dtype(precision: str):
    """NumPy scalar type that matches a precision name ('f64' or 'f32')."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    return numpy_dtype(precision).type


def current_arch():
    """The arch Taichi was started on by ``init`` ('cpu', 'gpu', ...), or None."""
    return None if _current is None else _current[0]


def actual_arch() -> str | None:
    """The arch Taichi really runs on ('cpu', 'cuda', 'vulkan', 'metal'), or None before
    ``init``: 'gpu' resolves to a backend, and a backend that fell back reads 'cpu'."""
    return _actual


# Backends whose shading language has no float64 exp, log, sin or cos (SPIR-V's
# GLSL.std.450, Metal's): the kernels take fdlibm's (``fmath``, ``polygon_ti.rotation_ti``).
SPIRV_ARCHES = ("vulkan", "metal", "opengl", "gles", "dx11")

# Whether integer atomics inside a loop run right on the device: False on Mesa 22's
# lavapipe (Debian 12's software Vulkan), where a loop that holds one, executed or not,
# stops after 2-3 iterations (``_integer_atomics_in_loops_work``). None before ``init``.
_int_atomics_ok: bool | None = None
# Whether the device lets one GPU thread loop as long as it likes: False on Mesa 22's
# lavapipe, whose shaders stop every loop once a thread has taken 65,535 turns of loops in
# all (llvmpipe's loop limiter; ``_loops_uncapped``). None before ``init``.
_loops_ok: bool | None = None
# Turns of a loop the probe asks one thread for: past lavapipe 22's 65,535.
_PROBE_TURNS = 70_000


def loops_capped() -> bool:
    """Whether a GPU thread's loops stop after a fixed number of turns on this device
    (``_loops_uncapped``): the thread-per-world stepper then takes a step per launch
    (``world.World``), and every launch checks that its threads ran to the end."""
    return _loops_ok is False


def float_gather() -> bool:
    """Whether contact forces are gathered in float64 holding whole quanta instead of
    64-bit integers (``schema.FORCE_QUANTUM``): only on a device whose integer atomics fail
    inside loops (``_integer_atomics_in_loops_work``). The sums are the same integers
    while a body's force stays below 2^53 quanta (5.4e8 N); read when a kernel compiles."""
    return _int_atomics_ok is False


def _integer_atomics_in_loops_work() -> bool:
    """Run the smallest kernel that Mesa 22's lavapipe gets wrong: one thread loops 64
    times, writing each index, past an integer atomic it never executes. A correct device
    writes all 64; lavapipe 22.3 writes 3. (Float atomics in the same loop run right.)"""
    import numpy as np
    import taichi as ti

    builder = ti.FieldsBuilder()
    out, flag = ti.field(ti.i32), ti.field(ti.i32)
    builder.dense(ti.i, 64).place(out)
    builder.place(flag)
    tree = builder.finalize()

    @ti.kernel
    def probe():
        for _ in range(1):
            for i in range(64):
                out[i] = i + 1
                if i > 1000:
                    ti.atomic_max(flag[None], i)

    probe()
    works = bool(np.array_equal(out.to_numpy(), np.arange(1, 65)))
    tree.destroy()
    return works


def _loops_uncapped() -> bool:
    """Whether one thread counts to ``_PROBE_TURNS`` in a loop (lavapipe 22 stops at
    65,535: llvmpipe counts a thread's turns of all its loops against one limit)."""
    import taichi as ti

    builder = ti.FieldsBuilder()
    out, asked = ti.field(ti.i32), ti.field(ti.i32)
    builder.place(out, asked)
    tree = builder.finalize()

    @ti.kernel
    def probe():
        for _ in range(1):
            turns = 0
            for _i in range(asked[None]):  # read at run time: no compiler can count it
                turns += 1
            out[None] = turns

    asked[None] = _PROBE_TURNS
    probe()
    works = int(out[None]) == _PROBE_TURNS
    tree.destroy()
    return works


def portable_f64() -> bool:
    """Whether the running Taichi computes in float64 on a backend without float64 exp,
    log, sin and cos (Vulkan, Metal): read when a kernel compiles (``ti.static``)."""
    return _current is not None and _current[1] == "f64" and _actual in SPIRV_ARCHES


def resolve(arch: str | None = None, precision: str | None = None) -> tuple[str, str]:
    """``(arch, precision)`` with None read as what this process's Taichi already runs on,
    or ``"cpu"`` and ``"f64"`` before it started: a Simulation or a command run inside a
    process that started Taichi on a GPU (a notebook, the GPU test lane) uses that GPU."""
    if arch is None:
        arch = _current[0] if _current is not None else "cpu"
    if precision is None:
        precision = _current[1] if _current is not None else "f64"
    return arch, precision


def cpu_threads() -> int:
    """The CPU threads Taichi runs its parallel loops on (every core unless told; the
    machine's count before ``init``)."""
    if _current is not None:
        from taichi.lang import impl

        threads = impl.current_cfg().cpu_max_num_threads
        if threads:
            return int(threads)
    return os.cpu_count() or 1


# Trees of fields a process can hold on Taichi's CPU and CUDA backends (its LLVM runtime's
# kMaxNumSnodeTreesLlvm); one more crashes the process.
MAX_FIELD_TREES = 512


def field_tree_limit() -> int | None:
    """The most trees of fields this process's backend holds: ``MAX_FIELD_TREES`` on the
    CPU and CUDA, None (no limit of Taichi's) on SPIR-V backends, where a process held 700
    in a check on lavapipe and a World takes ~7 (``state.Fields``)."""
    return None if _actual in SPIRV_ARCHES else MAX_FIELD_TREES


def field_trees() -> int:
    """Trees of fields Taichi holds in this process (each batch of fields declared between
    two kernel launches is one; they are never freed), 0 before ``init``."""
    if _current is None:
        return 0
    from taichi.lang import impl

    return int(impl.get_runtime().prog.get_snode_tree_size())


def usable_cores() -> int:
    """Cores this process may run on: its CPU affinity, capped by a cgroup (v2) CPU quota
    when one is set (a container's ``--cpus``); ``os.cpu_count()`` where neither is known."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 0
    cores = cores or os.cpu_count() or 1
    with contextlib.suppress(OSError, ValueError):
        with open("/sys/fs/cgroup/cpu.max") as fh:
            quota, period = fh.read().split()[:2]
        if quota != "max":
            cores = min(cores, max(1, int(int(quota) // int(period))))
    return cores


def _running_arch() -> str:
    from taichi.lang import impl

    name = impl.current_cfg().arch.name
    return "cpu" if name in _CPU_ARCHES else name


_PROBE = """
import os, sys
os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "0")
import taichi as ti
ti.init(arch=getattr(ti, sys.argv[1]), log_level=ti.ERROR, offline_cache=False)
from taichi.lang import impl
print("ARCH=" + impl.current_cfg().arch.name)
"""


def probe(arch: str) -> str:
    """Start Taichi on ``arch`` in a child process and return the arch it ran on.

    A missing GPU or driver can crash ``ti.init`` (a segfault on some machines) or make it
    fall back to the CPU; in a child neither touches this process.

    Raises:
        BackendError: the child crashed, hung, or fell back to the CPU; the message says
            what happened and to use ``--arch cpu``.
    """
    from .errors import BackendError

    if arch == "cpu":
        return "cpu"
    try:
        proc = subprocess.run(
            [sys.executable, "-c", _PROBE, arch],
            capture_output=True,
            text=True,
            timeout=PROBE_TIMEOUT,
            check=False,
        )
    except subprocess.TimeoutExpired:
        raise BackendError(
            f"--arch {arch}: starting Taichi on it took over {PROBE_TIMEOUT:.0f} s in a test "
            "process; its driver does not answer: use --arch cpu"
        ) from None
    found = [ln[5:] for ln in proc.stdout.splitlines() if ln.startswith("ARCH=")]
    if proc.returncode != 0 or not found:
        if proc.returncode < 0:
            how = f"crashed with {signal.Signals(-proc.returncode).name}"
        else:
            tail = (proc.stderr.strip().splitlines() or ["no message"])[-1]
            how = f"failed ({tail[:200]})"
        raise BackendError(
            f"--arch {arch}: Taichi cannot start on it here: a test process {how}; "
            "this machine has no usable GPU or driver for it: use --arch cpu"
        )
    ran = "cpu" if found[-1] in _CPU_ARCHES else found[-1]
    if ran == "cpu":
        raise BackendError(
            f"--arch {arch}: Taichi finds no {arch} device here and would fall back to the "
            "CPU; use --arch cpu (or run where there is a GPU)"
        )
    return ran


def optimize_level(value=None, arch: str = "cpu") -> str:
    """The compile setting ``value`` names ("off", "on" or "full"; module docstring).

    ``value`` may be a bool (True "on", False "off") or a string: "0", "false", "no" and
    "off" are "off"; "1", "true", "yes" and "on" are "on"; "full" is "full". None reads
    ``TAICHI_ICE_OPTIMIZE``, and unset (or empty) is "on" on the CPU, "full" on a GPU arch.

    Raises:
        BackendError: a value that names none of them (the environment variable's included).
    """
    if value is None:
        value = os.environ.get(OPTIMIZE_ENV, "").strip()
        if not value:
            return "on" if arch == "cpu" else "full"
    if isinstance(value, bool):
        return "on" if value else "off"
    text = str(value).strip().lower()
    for level, names in _OPTIMIZE_NAMES.items():
        if text in names:
            return level
    from .errors import BackendError

    raise BackendError(
        f"{OPTIMIZE_ENV} (or optimize=) is {value!r}: it must be off (or 0), on (or 1) or "
        "full; unset it for the default (on)"
    )


def ask_optimize(value) -> str:
    """Have this process's Taichi, and the processes it starts (a sweep's workers), compile
    in the setting ``value`` names (``optimize_level``): sets ``TAICHI_ICE_OPTIMIZE``, which
    ``init`` reads when it starts Taichi and child processes inherit. Returns the setting.

    Raises:
        BackendError: Taichi already runs in this process in another setting (fixed when it
            starts), or ``value`` names none.
    """
    from .errors import BackendError

    level = optimize_level(value)
    running = compile_level()
    if running is not None and running != level:
        raise BackendError(
            f"--optimize {level}: Taichi already runs in this process and compiles with "
            f"'{running}' (fixed when it starts); run the command in a new process, or set "
            f"{OPTIMIZE_ENV}={level} before Taichi starts"
        )
    os.environ[OPTIMIZE_ENV] = level
    return level


def init(
    arch: str = "cpu",
    precision: str = "f64",
    *,
    reinit: bool = False,
    optimize: bool | str | None = None,
) -> None:
    """Start Taichi on ``arch`` with ``precision`` as its default float type.

    Args:
        arch: 'cpu', or 'gpu' (Taichi picks CUDA, Vulkan or Metal), or a backend by name.
        precision: 'f64' (default on the CPU) or 'f32'.
        reinit: allow switching arch or precision; every existing field becomes invalid.
        optimize: the compile setting, "off", "on" or "full" (or a bool: on or off; default:
            ``TAICHI_ICE_OPTIMIZE``, else "on" on the CPU and "full" on a GPU arch;
            ``optimize_level`` and the module docstring). Applies when this call starts
            Taichi; a running Taichi keeps its setting.

    Raises:
        ValueError: unknown arch or precision, or a different arch/precision than the
            running one without ``reinit``.
    """
    global _current, _actual, _int_atomics_ok, _loops_ok, _generation, _level
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

    level = optimize_level(optimize, arch)
    frontend.use_fast_positions()
    frontend.use_cached_sources()
    with _quiet_start():
        ti.init(
            arch=getattr(ti, arch),
            default_fp=taichi_dtype(precision),
            default_ip=ti.i32,
            log_level=ti.WARN,
            **COMPILE_OPTIONS[level],
            offline_cache=True,
            # Taichi's default cache holds 100 MB and, past it, drops the least recently used
            # quarter when a process ends. Kernels specialise on their batch's layout, and
            # the test suite alone compiles ~150 MB of them, so at 100 MB every run evicted
            # what the next one needed and compiled it again (the suite took 16-26 min
            # instead of ~7). 1 GiB holds the suite and a user's scenes with room to spare.
            offline_cache_max_size_of_files=OFFLINE_CACHE_BYTES,
            # On the CPU Taichi otherwise cuts an outermost loop into one chunk per thread of
            # at least 512 iterations, ignoring loop_config: a batch of 17 worlds, stepped a
            # thread each, ran on one core (measured: 2 worlds took twice as long as 1). Off,
            # a loop is cut into tasks of its block_dim (adaptive when not set: 512-1024
            # iterations), and the world loops ask for a world per task. (Taichi's offline
            # cache does not key kernels by this option: a kernel compiled with it on before
            # keeps its old threading until its code changes. The stepper's changed with it.)
            make_cpu_multithreading_loop=False,
            # IEEE arithmetic, as written: fast math lets LLVM fuse and reorder operations
            # differently in each kernel a function is inlined into, so the two ways of
            # stepping (``world.World.stepping``) would part by round-off, and it may drop
            # the non-finite checks. Measured on 2 cores (random box, 1e4 blocks): the same
            # speed within the VM's noise.
            fast_math=False,
        )
    _current = wanted
    _level = level
    _generation += 1
    _actual = _running_arch()
    spirv = _actual in SPIRV_ARCHES
    _int_atomics_ok = _integer_atomics_in_loops_work() if spirv else True
    _loops_ok = _loops_uncapped() if spirv else True


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


def generation() -> int:
    """How many times this process has started Taichi: the fields (and Worlds) of an
    earlier start are freed (``init(..., reinit=True)``)."""
    return _generation


def optimized() -> bool | None:
    """Whether the running Taichi compiles with its advanced passes (``init``'s
    ``optimize`` on or full), or None before ``init``."""
    return None if _level is None else _level != "off"


def compile_level() -> str | None:
    """The running Taichi's compile setting, "off", "on" or "full" (``init``'s
    ``optimize``), or None before ``init``."""
    return _level


def current() -> tuple[str, str] | None:
    """(arch, precision) of the running Taichi runtime, or None before ``init``."""
    return _current
