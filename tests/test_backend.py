"""The compile setting the suite runs under changes nothing a run computes.

The suite compiles without Taichi's advanced passes (``conftest.py``), which is about 3x
faster, as do the accuracy studies (``validate``); users' runs compile with them. This
holds the two against each other bit for bit,
in two fresh processes (Taichi's settings are per process), on both ways of stepping: a
world a thread (the pillar scene with rate-and-state friction through its jam, with the
default step and the coupled one) and bodies in
parallel (a box of 300 diamonds at random angles and velocities), the latter both by a team
of threads in one launch and by a kernel per stage and step.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
import taichi as ti

from taichi_ice import backend
from taichi_ice.engine import state

_RUN = """
import hashlib, sys
from taichi.lang import impl
from taichi_ice import backend, load_scenario
from taichi_ice.experiments.bench.scenes import bench_scene
from taichi_ice.physics.friction_parse import parse_law
from taichi_ice.engine.world import World

backend.init("cpu", "f64")
print("ADVANCED", impl.current_cfg().advanced_optimization)
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
"""


def _start(optimize: str) -> subprocess.Popen:
    env = dict(os.environ, TAICHI_ICE_OPTIMIZE=optimize)
    return subprocess.Popen(
        [sys.executable, "-c", _RUN],
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
    # The two processes side by side: compiling is most of their time, on a core each.
    procs = _start("0"), _start("1")
    fast, full = (_result(p) for p in procs)
    assert fast["ADVANCED"] == "False" and full["ADVANCED"] == "True"
    contacts = int(full["BOX"].split()[1])
    assert contacts > 20  # blocks are colliding: the narrow phase worked on many pairs
    assert int(full["PILLAR"].split()[1]) > 20  # blocks pressed on the pillar and each other
    assert fast["PILLAR"] == full["PILLAR"]
    assert int(full["COUPLED"].split()[1]) > 20  # the coupled solve ran on many contacts
    assert fast["COUPLED"] == full["COUPLED"]
    assert fast["BOX"] == full["BOX"]
    # The team's threads meet at barriers inside one launch (stepper.BodyTeam): compiled
    # with every pass, they still see each other's stores as the kernels per stage do.
    assert full["BOX"].split()[0] == full["KERNELS"] == fast["KERNELS"]


@pytest.mark.parametrize(
    ("value", "expected"),
    [(None, True), ("1", True), ("yes", True), ("0", False), ("False", False), (" off ", False)],
)
def test_optimize_default_reads_the_environment(monkeypatch, value, expected):
    if value is None:
        monkeypatch.delenv(backend.OPTIMIZE_ENV, raising=False)
    else:
        monkeypatch.setenv(backend.OPTIMIZE_ENV, value)
    assert backend.optimize_default() is expected


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
