"""The compile setting the suite runs under changes nothing a run computes.

The suite compiles without Taichi's advanced passes (``TAICHI_ICE_OPTIMIZE=0``,
``conftest.py``), as do the accuracy studies (``validate``); users' runs compile with them
but the control-flow-graph and whole-kernel common-subexpression passes ("on", the
default), or with every pass ("full"; the default before 2026-11-28, and on GPU archs).
This holds the three against each other bit for bit, in fresh processes (Taichi's settings
are per process), on both ways of stepping: a world a thread (the pillar scene with
rate-and-state friction through its jam, with the default step and the coupled one) and
bodies in parallel (a box of 300 diamonds at random angles and velocities), the latter both
by a team of threads in one launch (of two threads, and in the "on" process of one too) and
by a kernel per stage and step. The "full" process
leaves out the coupled step, whose kernels take that setting ~2 minutes to compile on 2
cores (the same bits were checked here with it while "full" was the default).
"""

from __future__ import annotations

import inspect
import os
import subprocess
import sys
from pathlib import Path

import pytest
import taichi as ti

from taichi_ice import backend, frontend
from taichi_ice.engine import state
from taichi_ice.errors import BackendError

_RUN = """
import hashlib, sys
from taichi.lang import impl
from taichi_ice import backend, load_scenario
from taichi_ice.experiments.bench.scenes import bench_scene
from taichi_ice.physics.friction_parse import parse_law
from taichi_ice.engine.world import World

backend.init("cpu", "f64")
cfg = impl.current_cfg()
print("ADVANCED", cfg.advanced_optimization, cfg.cfg_optimization, cfg.opt_level)
parts = sys.argv[1:]
def digest(w):
    return hashlib.sha1(
        w.positions().tobytes() + w.velocities().tobytes() + w.angles().tobytes()
    ).hexdigest()
# 140,000 steps of 0.2 stable_dt (rate and state's "auto" is 0.05): 15 s, the blocks jammed
# at the pillar (~70 contacts; the 3,000 this was first written with ended at 0.3 s, before
# the first contact, at 5 s).
pillar = load_scenario("pillar").with_friction(parse_law("rate-state"))
w = World([pillar], dt=0.2 * pillar.stable_dt)
w.advance(140000)
w.check()
print("PILLAR", digest(w), int(w.contact_counts().sum()))
# The coupled step (issue 30): the analytic step's closed forms and the 4 x 4 flow, whose
# kernels take the advanced passes longest (16x); the accuracy studies compile without them.
if "coupled" in parts:
    c = World([pillar], dt=0.2 * pillar.stable_dt, integrator="coupled")
    c.advance(140000)
    c.check()
    print("COUPLED", digest(c), int(c.contact_counts().sum()))
scene, _ = bench_scene("random", 300, "rate-state", False, 0)
w = World([scene], stepping="bodies")
w.advance(300)
w.check()
print("BOX", digest(w), int(w.contact_counts().sum()))
k = World([scene], stepping="bodies")
k.team = None  # the parallel step's kernels launched every step, as on a GPU
k.advance(300)
k.check()
print("KERNELS", digest(k))
if "team1" in parts:
    # A team of one thread (TI_CPU_MAX_NUM_THREADS=1, or a one-core machine): its barriers
    # once hung in the first step where Taichi's advanced passes run (stepper.BodyTeam.launch).
    backend.cpu_threads = lambda: 1
    t = World([scene], stepping="bodies")
    assert t.team.threads == 1
    t.advance(300)
    t.check()
    print("TEAM1", digest(t))
"""


def _start(optimize: str, *parts: str) -> subprocess.Popen:
    env = dict(os.environ, TAICHI_ICE_OPTIMIZE=optimize)
    return subprocess.Popen(
        [sys.executable, "-c", _RUN, *parts],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _result(proc: subprocess.Popen) -> dict[str, str]:
    out, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err[-2000:]
    lines = [ln.split(" ", 1) for ln in out.splitlines() if ln[:1].isupper()]
    return {k: v for k, v in lines}


def test_optimised_and_fast_compiled_kernels_step_the_same():
    # The processes side by side: compiling is most of their time.
    procs = _start("0", "coupled"), _start("1", "coupled", "team1"), _start("full")
    fast, on, full = (_result(p) for p in procs)
    assert fast["ADVANCED"] == "False True 1"
    assert on["ADVANCED"] == "True False 0" and full["ADVANCED"] == "True True 1"
    contacts = int(on["BOX"].split()[1])
    assert contacts > 20  # blocks are colliding: the narrow phase worked on many pairs
    assert int(on["PILLAR"].split()[1]) > 20  # blocks pressed on the pillar and each other
    assert fast["PILLAR"] == on["PILLAR"] == full["PILLAR"]
    assert int(on["COUPLED"].split()[1]) > 20  # the coupled solve ran on many contacts
    assert fast["COUPLED"] == on["COUPLED"]
    assert fast["BOX"] == on["BOX"] == full["BOX"]
    # The team's threads meet at barriers inside one launch (stepper.BodyTeam): compiled
    # with every pass, they still see each other's stores as the kernels per stage do.
    assert on["BOX"].split()[0] == on["KERNELS"] == fast["KERNELS"] == full["KERNELS"]
    # And so does a team of one, which has no one to wait for.
    assert on["TEAM1"] == on["KERNELS"]


@pytest.mark.parametrize(
    ("value", "arch", "expected"),
    [
        (None, "cpu", "on"),
        (None, "cuda", "full"),
        (None, "vulkan", "full"),
        ("", "cpu", "on"),
        ("1", "cpu", "on"),
        ("yes", "cuda", "on"),
        ("0", "cpu", "off"),
        ("False", "cpu", "off"),
        (" off ", "cpu", "off"),
        ("FULL", "cpu", "full"),
    ],
)
def test_optimize_level_reads_the_environment(monkeypatch, value, arch, expected):
    if value is None:
        monkeypatch.delenv(backend.OPTIMIZE_ENV, raising=False)
    else:
        monkeypatch.setenv(backend.OPTIMIZE_ENV, value)
    assert backend.optimize_level(None, arch) == expected


def test_optimize_level_takes_bools_and_refuses_what_names_no_setting(monkeypatch):
    assert backend.optimize_level(True) == "on" and backend.optimize_level(False) == "off"
    assert backend.optimize_level("full", "cpu") == "full"
    monkeypatch.setenv(backend.OPTIMIZE_ENV, "fast")
    with pytest.raises(BackendError, match=r"TAICHI_ICE_OPTIMIZE .* is 'fast': .*off .*on .*full"):
        backend.optimize_level()


def test_usable_cores_honours_a_cgroup_quota(monkeypatch):
    """A container's CPU quota (cgroup v2 ``cpu.max``) caps the cores a team of spinning
    threads may count on; "max" (no quota) leaves the affinity's count."""
    import builtins
    import io

    real_open = builtins.open
    quota = {"text": "150000 100000\n"}

    def fake_open(path, *args, **kwargs):
        if str(path) == "/sys/fs/cgroup/cpu.max":
            return io.StringIO(quota["text"])
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", fake_open)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2, 3}, raising=False)
    assert backend.usable_cores() == 1
    quota["text"] = "400000 100000\n"
    assert backend.usable_cores() == 4
    quota["text"] = "max 100000\n"
    assert backend.usable_cores() == 4
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {3}, raising=False)
    assert backend.usable_cores() == 1


def test_the_integer_atomics_probe_passes_on_a_correct_device(taichi_runtime):
    """The probe that sends forces through float64 on Mesa 22's lavapipe must pass on a
    device that loops right: on the CPU (and CUDA) forces stay 64-bit integers. On the lane's
    arch it reports what that device does; the scenes against the CPU (test_gpu) hold either
    way of gathering."""
    arch, _ = taichi_runtime
    works = backend._integer_atomics_in_loops_work()
    assert works == backend._int_atomics_ok
    if arch in ("cpu", "cuda"):
        assert works and not backend.float_gather()
        assert state.quantum_dtype() == ti.i64
    assert state.quantum_dtype() == (ti.f64 if backend.float_gather() else ti.i64)


def test_a_kernel_error_still_names_its_file_line_and_column(taichi_runtime):
    """Taichi's source positions come from ``frontend.source_position`` (no line wrapping:
    a third of a cached start), and an error in a kernel still says where, held against this
    file's own text."""
    from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext

    assert ASTTransformerContext.get_pos_info is frontend.source_position

    out = ti.field(ti.i32, shape=())

    @ti.kernel
    def broken():
        total = 1
        total += undefined_on_purpose  # noqa: F821
        out[None] = total

    with pytest.raises(ti.TaichiNameError, match="undefined_on_purpose") as info:
        broken()
    text = open(__file__).read().splitlines()
    lineno = next(i for i, ln in enumerate(text, 1) if "undefined_on_purpose  # noqa" in ln)
    column = text[lineno - 1].index("undefined_on_purpose")
    lines = str(info.value).splitlines()
    at = lines.index(f'File "{__file__}", line {lineno}, in broken:')
    assert lines[at + 1] == text[lineno - 1]
    assert lines[at + 2] == " " * column + "^" * len("undefined_on_purpose")


_SOURCES = """
import sys
from taichi_ice import backend, frontend, load_scenario
from taichi_ice.engine.world import World

if sys.argv[1] == "taichi":  # Taichi reading every source at every call site, as it ships
    frontend.use_cached_sources = lambda: False
backend.init("cpu", "f64")
w = World([load_scenario("two_squares")])
w.advance(2)
"""


def _sources_run(reader: str, cache: Path) -> list[str]:
    env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=str(cache))
    out = subprocess.run(
        [sys.executable, "-c", _SOURCES, reader],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return sorted(p.name for p in cache.glob("*.tic"))  # written as the process ends


def test_sources_read_once_give_the_ir_taichi_reads(tmp_path):
    """``frontend.use_cached_sources`` (each function's source read once a process) builds
    the IR Taichi builds reading every source at every call site: a process with it finds
    every kernel in the offline cache that a process without it wrote there (Taichi's keys
    are hashes of the IR), and adds none."""
    from taichi.lang import kernel_impl

    assert frontend.use_cached_sources()  # in effect in this process (and idempotent)
    assert isinstance(kernel_impl.textwrap, frontend._KeptTextwrap)
    lines, _ = kernel_impl.getsourcelines(_sources_run)
    lines.append("changed by a caller")
    assert kernel_impl.getsourcelines(_sources_run) == inspect.getsourcelines(_sources_run)

    written = _sources_run("taichi", tmp_path)
    assert len(written) >= 3  # the stepping kernel and the World's others
    assert _sources_run("kept", tmp_path) == written
