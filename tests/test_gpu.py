"""The same worlds on a GPU backend as on the CPU (issue 28).

These tests compare the session's arch (``--arch vulkan``, ``--arch cuda``: the GPU lane,
``tests/gpu_lane.py``) against the CPU, which runs in a child process with the same
precision: every bundled scene with its own law and with the other, its trajectories and
its energy budget; a batch of layouts against each layout run alone; the thread-per-world
and kernel-per-stage steppings. On a CPU session they compare the CPU with itself and are
skipped (``test_engine.py`` holds the two steppings against each other there).

Where the two must agree and why:

- float32 and float64 Coulomb: the same operations in the same order on IEEE floats, so bit
  for bit where the backend's compiler neither fuses a multiply and an add nor reorders
  (Taichi asks for neither, ``fast_math=False``); the comparisons use a tolerance of a few
  ulps of the quantity (``RTOL``), and the bit-for-bit fraction is printed;
- rate-and-state in float64: Vulkan and Metal take fdlibm's exp and log (``fmath``), the
  CPU its libm's; the two differ by up to an ulp, which a contact's friction carries into
  its trajectory. Over these short runs that stays below ``RS_RTOL``.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from taichi_ice import Simulation, load_scenario
from taichi_ice.physics.friction import Coulomb, RateState
from taichi_ice.scene.parse import reseeded, scene_from_dict

ROOT = Path(__file__).resolve().parents[1]

# (scene, simulated seconds): each past its first contacts. pushed_field: the pusher reaches
# the field at 2.33 s (its Vulkan run used never to touch it).
SCENES = {
    "two_squares": 0.25,
    "sliding_block": 0.2,
    "free_field": 0.4,
    "pushed_field": 2.6,
    "pillar": 0.6,
}
LAWS = {"coulomb": Coulomb(mu=0.5), "rate-state": RateState(), "rate-state-one-step": RateState()}
# "rate-state" takes a sliding contact's step in sub-steps ([ice] slide_resolution, default
# 0.025: ``slip.sliding_steps_ti``); "rate-state-one-step" in one step, slide_resolution = SLIDE.
SLIDE = 0.0
RTOL = {"f64": 1e-12, "f32": 1e-5}  # of the quantity's scale (positions: the scene's size)
RS_RTOL = {"f64": 1e-9, "f32": 1e-5}

CHILD = """
import json, sys
import numpy as np
from taichi_ice import Simulation, backend, load_scenario
from taichi_ice.physics.friction import Coulomb, RateState
from taichi_ice.scene.parse import scene_from_dict
name, law, until, precision = sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4]
integrator, slide = sys.argv[5], float(sys.argv[6])
backend.init("cpu", precision)
friction = Coulomb(mu=0.5) if law == "coulomb" else RateState()
scene = load_scenario(name)
raw = {**scene.raw, "simulation": {**scene.raw["simulation"], "dt_safety": 0.2}}
if law == "rate-state-one-step":
    raw["ice"] = {**scene.raw.get("ice", {}), "slide_resolution": slide}
scene = scene_from_dict(raw, source=name)
sim = Simulation(
    scene, friction=friction, arch="cpu", precision=precision, integrator=integrator
)
result = sim.run(until=until)
w = sim.world
s = result.series[0]
print(json.dumps({
    "pos": w.positions().tolist(), "ang": w.angles().tolist(),
    "vel": w.velocities().tolist(), "steps": int(sim.steps),
    "series": {k: np.asarray(v, dtype=float).tolist() for k, v in s.items()},
}))
"""


@pytest.fixture(scope="module")
def gpu(taichi_runtime):
    arch, precision = taichi_runtime
    if arch == "cpu":
        pytest.skip("compares a GPU backend with the CPU: run in the GPU lane (make test-vulkan)")
    return arch, precision


def on_cpu(name: str, law: str, until: float, precision: str, integrator: str) -> dict:
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, name, law, repr(until), precision, integrator, repr(SLIDE)],
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def on_here(name: str, law: str, until: float, arch: str, precision: str, integrator: str) -> dict:
    scene = load_scenario(name)
    # Every law at 0.2 of the limit (rate and state's "auto" is 0.05): the step these
    # comparisons were written at; on and off the GPU the same step either way.
    raw = {**scene.raw, "simulation": {**scene.raw["simulation"], "dt_safety": 0.2}}
    if law == "rate-state-one-step":
        raw["ice"] = {**scene.raw.get("ice", {}), "slide_resolution": SLIDE}
    scene = scene_from_dict(raw, source=name)
    sim = Simulation(
        scene,
        friction=LAWS[law],
        arch=arch,
        precision=precision,
        integrator=integrator,
    )
    result = sim.run(until=until)
    w = sim.world
    return {
        "pos": w.positions(),
        "ang": w.angles(),
        "vel": w.velocities(),
        "steps": sim.steps,
        "series": result.series[0],
    }


@pytest.mark.parametrize("law", sorted(LAWS))
@pytest.mark.parametrize("name", sorted(SCENES))
def test_a_scene_on_the_gpu_equals_the_cpu(name, law, gpu):
    assert_same_on_both(name, law, "euler", gpu)


@pytest.mark.parametrize("integrator", ["coupled", "midstep"])
@pytest.mark.parametrize("law", ["coulomb", "rate-state"])  # these steps take no sub-steps
@pytest.mark.parametrize("name", ["two_squares", "pillar"])
def test_the_coupled_step_on_the_gpu_equals_the_cpu(name, law, integrator, gpu):
    """The coupled step's 4 x 4 exponential (plain arithmetic and a square root) and its 1D
    solves (fdlibm's exp on every backend in float64) give the CPU's trajectories; and the
    midstep one's, which also turns each pair of outlines to mid-step and clips them again."""
    assert_same_on_both(name, law, integrator, gpu)


def assert_same_on_both(name, law, integrator, gpu):
    arch, precision = gpu
    until = SCENES[name]
    want = on_cpu(name, law, until, precision, integrator)
    got = on_here(name, law, until, arch, precision, integrator)
    assert got["steps"] == want["steps"]
    rtol = (RTOL if law == "coulomb" else RS_RTOL)[precision]
    pos, want_pos = np.asarray(got["pos"]), np.asarray(want["pos"])
    scale = max(1.0, float(np.max(np.abs(want_pos))))
    same = np.mean(pos == want_pos)
    err = float(np.max(np.abs(pos - want_pos))) / scale
    print(f"{name} {law} {integrator} {arch}/{precision}: positions {100 * same:.0f} % bit "
          f"for bit, largest difference {err:.2e} of the scene's size")  # fmt: skip
    assert err <= rtol, err
    np.testing.assert_allclose(got["ang"], want["ang"], rtol=0, atol=rtol * 10)
    s, t = got["series"], want["series"]
    came = max(1.0, abs(t["work_in"][-1]) + abs(t["kinetic_energy"][0]))
    for key in ("kinetic_energy", "friction_energy", "work_in", "elastic_energy"):
        np.testing.assert_allclose(s[key], t[key], rtol=0, atol=rtol * came * 100, err_msg=key)
    contacts = np.asarray(s["n_contacts"])
    np.testing.assert_array_equal(contacts > 0, np.asarray(t["n_contacts"]) > 0)


def test_pushed_field_touches_the_field_on_the_gpu(gpu):
    """The reproduction of issue 28: on Vulkan in float32 the pusher never reached the
    field (no contact, 0 J in, the file marked complete)."""
    arch, precision = gpu
    got = on_here("pushed_field", "coulomb", SCENES["pushed_field"], arch, precision, "euler")
    assert np.max(got["series"]["n_contacts"]) > 0
    assert got["series"]["work_in"][-1] > 0.0


@pytest.mark.parametrize("stepping", ["worlds", "bodies"])
def test_a_batch_on_the_gpu_equals_each_layout_alone(stepping, gpu):
    """Three layouts of the pillar as one batch, against each run alone, by each stepping:
    worlds do not touch each other, whichever way the GPU steps them."""
    arch, precision = gpu
    base = load_scenario("pillar")
    scenes = [reseeded(base, base.simulation.seed + k) for k in range(3)]
    batch = Simulation(scenes, arch=arch, precision=precision, stepping=stepping)
    batch.run(until=0.3)
    pos = batch.world.positions()
    for k, (scene, sl) in enumerate(zip(scenes, batch.world.world_slices())):
        alone = Simulation(scene, arch=arch, precision=precision, stepping=stepping)
        alone.run(until=0.3)
        np.testing.assert_allclose(
            pos[sl], alone.world.positions(), rtol=0, atol=RTOL[precision] * 100, err_msg=k
        )


THREE_BODIES = {  # a block on a moving floor against a stop (test_engine's steady state)
    "simulation": {"duration": 0.1},
    "body": [
        {"name": "floor", "kind": "kinematic", "shape": "rectangle", "width": 6.0,
         "length": 0.5, "position": [0.0, -0.25], "velocity": [0.1, 0.0], "probe": True},
        {"name": "block", "shape": "rectangle", "width": 1.0, "length": 1.0,
         "position": [0.0, 0.5]},
        {"name": "stop", "kind": "fixed", "shape": "rectangle", "width": 0.5, "length": 1.0,
         "position": [0.75, 0.6]},
    ],
}  # fmt: skip


@pytest.mark.parametrize("name", [*sorted(SCENES), "three_bodies"])
def test_every_field_of_a_world_holds_its_own_values(name, taichi_runtime):
    """Each field of a World filled with its own number reads back as that number, on any
    arch: Taichi 1.7.4's SPIR-V backend overlapped a 32-bit field of an odd length with the
    64-bit field beside it (4 of a World's 33 fields on Vulkan, before ``state.Fields`` laid
    them out 64-bit first with pads; with 3 bodies in float32, 4 fields still did, until
    64-bit and 32-bit fields had trees of their own there).

    The numbers go in as the World starts its fields, all in one launch
    (``transfer.Transfer.write``: Taichi's ``fill`` compiles a kernel per field, ~110 a World,
    which took most of this test's time); each is read back by Taichi's own ``to_numpy``."""
    from taichi_ice.engine.world import World

    arch, precision = taichi_runtime
    scene = scene_from_dict(THREE_BODIES) if name == "three_bodies" else load_scenario(name)
    world = World([scene], precision=precision, stepping="bodies")
    groups = (world.model, world.data, world.neighbours, world.hash)
    fields = [(g.__class__.__name__, n, getattr(g, n)) for g in groups for n in g.names]
    assert sorted(n for _, n, _ in fields) == sorted(world.transfer.names)
    shapes = world.transfer.shapes()
    world.transfer.write({n: np.full(shapes[n], k + 1) for k, (_, n, _) in enumerate(fields)})
    lost = [
        f"{group}.{n}"
        for k, (group, n, field) in enumerate(fields)
        if not np.all(field.to_numpy() == k + 1)
    ]
    assert not lost, f"on {arch}/{precision}"
