"""The state's one declaration (taichi_ice.engine.schema) against what uses it.

- Every stage's kernels touch exactly the fields their ACCESS declares (parsed from the
  kernel source), so the traffic model and a reader see what the code does.
- The Taichi fields a World allocates have the declared shapes and types; host arrays of the
  wrong shape are refused; docs/state.md is the generated table.
- The traffic model against a hand count of one kernel.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import taichi as ti

from taichi_ice.engine import schema, stages
from taichi_ice.engine.assemble import assemble
from taichi_ice.engine.options import Options
from taichi_ice.engine.state import ti_dtype
from taichi_ice.engine.world import STAGES, World
from taichi_ice.scene.parse import load_scenario

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize(
    ("stage", "kernel"),
    [(name, kernel) for name, cls in STAGES.items() for kernel in cls.ACCESS],
)
def test_stage_declares_exactly_the_fields_its_kernel_touches(stage, kernel):
    """reads and writes of each kernel (and the methods it calls) equal its declaration."""
    cls = STAGES[stage]
    reads, writes = stages.fields_touched(cls, kernel)
    access = cls.ACCESS[kernel]
    assert reads == set(access.reads), (stage, kernel, reads ^ set(access.reads))
    assert writes == set(access.writes), (stage, kernel, writes ^ set(access.writes))
    assert set(access.per_contact) <= reads | writes


def test_fields_touched_tells_reads_from_writes():
    """A plain assignment writes, an augmented one and an atomic read and write, an index
    inside a target is read."""

    class Probe(stages.Stage):
        def kernel(self):
            d = self.data
            d.body_pos[0] = d.body_vel[1]
            d.body_angle[0] += 1.0
            d.sorted_ids[d.block_total[0] + ti.atomic_add(d.bucket_end[0], 1)] = 0
            self.helper()

        def helper(self):
            self.data.status[0] = self.data.time_step[None]

    reads, writes = stages.fields_touched(Probe, "kernel")
    assert writes == {"body_pos", "body_angle", "sorted_ids", "bucket_end", "status"}
    assert reads == {"body_vel", "body_angle", "block_total", "bucket_end", "time_step"}


@pytest.fixture(scope="module")
def world(taichi_runtime) -> World:
    return World([load_scenario(ROOT / "scenarios" / "pushed_field.toml")])


def test_allocated_fields_have_their_declared_shape_and_type(world):
    """Every declared field exists on its group with the declared shape, lanes and dtype."""
    holders = {
        "model": world.model,
        "data": world.data,
        "hash": world.hash,
        "nbr": world.neighbours,
    }
    for group, decls in schema.groups().items():
        for v in decls:
            field = getattr(holders[group], v.name)
            assert field.shape == schema.allocated_shape(world.layout, v), v.name
            assert field.dtype == ti_dtype(v, world.layout), v.name
            assert getattr(field, "n", 1) == v.lanes, v.name


def test_uploaded_host_arrays_read_back_unchanged(world):
    """A World starts with every host array in its field (``World._start``), cast to the
    field's type (f64: bit for bit)."""
    for v in schema.host_vars():
        if not world.layout.exists(v):
            continue
        holder = world.model if hasattr(world.model, v.name) else world.data
        got = getattr(holder, v.name).to_numpy()
        want = world.host[v.name]
        want = want.astype(got.dtype)  # the field's type: a float32 run's reals
        if want.ndim == 0:  # a scalar field
            np.testing.assert_array_equal(got, want, err_msg=v.name)
            continue
        np.testing.assert_array_equal(got[: len(want)], want, err_msg=v.name)


def test_host_arrays_of_the_wrong_shape_are_refused():
    """A host array that does not match its declaration is an error naming it."""
    batch = assemble([load_scenario(ROOT / "scenarios" / "two_squares.toml")])
    arrays = dict(batch.host)
    arrays["body_mass"] = np.zeros(5)
    with pytest.raises(ValueError, match="body_mass"):
        schema.HostArrays(batch.real, arrays)
    del arrays["body_mass"]
    with pytest.raises(ValueError, match=r"missing.*body_mass"):
        schema.HostArrays(batch.real, arrays)


def test_docs_state_table_is_generated_from_the_schema():
    """docs/state.md is exactly schema.markdown_table() (regenerate it when this fails)."""
    text = (ROOT / "docs" / "state.md").read_text()
    assert text == schema.markdown_table(), (
        "run: python -m taichi_ice.engine.schema > docs/state.md"
    )


def test_traffic_model_counts_the_integrator_by_hand():
    """The Euler step's integrator.advance moves, per body and f64: reads 12 scalars, 4
    vectors, the i64 force and torque, 6 energy terms and what the lists' staleness needs;
    writes back the same minus the model, plus the body's velocity change, rotation and
    path, the status and the stale flags."""
    batch = assemble(
        [load_scenario(ROOT / "scenarios" / "two_squares.toml")], Options(integrator="euler")
    )
    layout = batch.layout.replace(n_bodies=1000, n_worlds=1, n_probes=0)
    n = layout.n_bodies
    # reads: probe, kind (i32); force_ext (2 x f64); the water drag's two coefficients
    # (f64, zero without [water]: read to know); inv_mass, inv_inertia (f64); force_q
    # (2 x i64), torque_q (i64); vel (2 x f64), omega, pos (2 x f64), angle (f64); energy
    # (6 x f64, codes.BodyEnergy); time_step (f64); for the neighbour lists small, world
    # (i32), radius (f64), the position and angle at the last build (3 x f64), the path
    # since (f64). No probes: probe_impulse moves nothing. Once: time_step, the world's
    # runaway distance and the lists' skin (f64 each), and the bodies in use (i32).
    lists = 4 + 4 + 8 + 16 + 8 + 8
    body = 4 + 4 + 16 + 16 + 8 + 8 + 16 + 8 + 16 + 8 + 16 + 8 + 48 + lists
    reads = n * body + 8 + 8 + 8 + 4
    # writes: force_q, torque_q, vel, omega, pos, angle, energy; the velocity changes that
    # the contacts book their work with (dvel 2 x f64, domega); the rotation (cos, sin);
    # the path; status (4 x i32); the stale flags (one world, and the batch's).
    writes = n * (16 + 8 + 16 + 8 + 16 + 8 + 48 + 16 + 8 + 16 + 8) + 16 + 4 + 4
    got = stages.traffic({"integrator": STAGES["integrator"]}, layout, contacts=0)
    assert got["integrator.advance"] == reads + writes
