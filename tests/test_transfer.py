"""``engine.transfer.Transfer`` against Taichi's own ``from_numpy`` and ``to_numpy``.

Fields of every supported type and shape (0-d, one and two axes, scalars and vectors),
seeded random values: what one launch writes is what ``to_numpy`` reads back, bit for bit,
and what it reads is what ``from_numpy`` put in. And a World's fields hold, before the first
step, what ``state.start_arrays`` says (read field by field with ``to_numpy``).
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
import taichi as ti

from taichi_ice import load_scenario
from taichi_ice.engine import schema
from taichi_ice.engine.state import start_arrays
from taichi_ice.engine.transfer import Transfer
from taichi_ice.engine.world import World
from taichi_ice.errors import UsageError
from taichi_ice.scene.parse import scene_from_dict

NUMPY = {ti.f64: np.float64, ti.f32: np.float32, ti.i32: np.int32, ti.i64: np.int64}
# (type, shape, lanes: 0 a scalar field): every case the kernel's loops distinguish.
SPECS = [
    (ti.f64, (7,), 0),
    (ti.f32, (5, 3), 0),
    (ti.i32, (9,), 0),
    (ti.i64, (4,), 2),
    (ti.f64, (), 0),
    (ti.i32, (), 0),
    (ti.f64, (6,), 2),
    (ti.f32, (3, 2), 12),
    (ti.f64, (), 2),
    (ti.i64, (2, 5), 0),
]


def make_fields() -> dict:
    return {
        f"f{k}": ti.Vector.field(lanes, dtype, shape=shape) if lanes else ti.field(dtype, shape)
        for k, (dtype, shape, lanes) in enumerate(SPECS * 2)
    }


def random_arrays(fields: dict, seed: int) -> dict:
    """Values that use each type's range: large and signed integers, floats of any exponent."""
    rng = np.random.default_rng(seed)
    out = {}
    for name, field in fields.items():
        shape = field.shape + ((field.n,) if isinstance(field, ti.MatrixField) else ())
        kind = NUMPY[field.dtype]
        if np.issubdtype(kind, np.integer):
            info = np.iinfo(kind)
            out[name] = rng.integers(info.min, info.max, size=shape, dtype=kind, endpoint=True)
        else:
            out[name] = (rng.normal(size=shape) * 10.0 ** rng.integers(-30, 30, size=shape)).astype(
                kind
            )
    return out


@pytest.mark.parametrize("seed", [0, 1])
def test_write_then_to_numpy_and_from_numpy_then_read_give_the_arrays_bit_for_bit(seed):
    fields = make_fields()
    transfer = Transfer(fields)
    arrays = random_arrays(fields, seed)
    transfer.write(arrays)
    for name, field in fields.items():
        got = field.to_numpy()
        assert got.dtype == arrays[name].dtype and got.shape == arrays[name].shape, name
        np.testing.assert_array_equal(got, arrays[name], err_msg=name)
    other = random_arrays(fields, seed + 100)
    for name, field in fields.items():
        if field.shape == ():  # Taichi's from_numpy takes no 0-d array
            value = other[name]
            field[None] = value.tolist() if value.ndim else value.item()
        else:
            field.from_numpy(other[name])
    read = transfer.read()
    assert set(read) == set(fields)
    for name in fields:
        assert read[name].dtype == other[name].dtype, name
        np.testing.assert_array_equal(read[name], other[name], err_msg=name)


def test_a_missing_or_misshapen_array_is_refused_naming_the_field():
    fields = make_fields()
    transfer = Transfer(fields)
    arrays = random_arrays(fields, 3)
    arrays["f1"] = arrays["f1"][:2]
    with pytest.raises(ValueError, match=r"f1 has shape \(2, 3\), its field \(5, 3\)"):
        transfer.write(arrays)
    del arrays["f1"]
    with pytest.raises(ValueError, match=r"no array for \['f1'\]"):
        transfer.write(arrays)


def test_a_world_starts_with_the_declared_values_in_every_field(taichi_runtime):
    """Every declared field of a new World, read with ``to_numpy``, holds ``start_arrays``
    (the host arrays padded, the declared init elsewhere), but the time step, which is dt,
    and the bodies' rotations, which ``Integrator.orient`` computes from their angles."""
    raw = copy.deepcopy(dict(load_scenario("scenarios/two_squares.toml").raw))
    for body, angle in zip(raw["body"], (0.3, -1.1)):  # turned: the rotations are not (1, 0)
        body["angle"] = angle
    scene = scene_from_dict(raw)
    world = World([scene, scene])
    want = start_arrays(world.layout, world.host)
    holders = (world.model, world.data, world.hash, world.neighbours)
    got = {name: getattr(h, name).to_numpy() for h in holders for name in h.names}
    declared = {v.name for g in schema.groups().values() for v in g}
    assert set(got) == declared == set(want)
    for name, values in got.items():
        if name == "time_step":
            assert values == np.asarray(world.dt, dtype=values.dtype)  # float32 in a f32 run
            continue
        if name == "body_rot":  # (cos, sin) of the angles, the rows past the bodies' 0
            angles = want["body_angle"]
            turned = np.where(np.arange(len(angles))[:, None] < world.batch.n_bodies, 1.0, 0.0)
            # libm's cos and sin against the kernel's, to one unit of round-off of the
            # field's type (measured: 0 in float64, half a unit in float32 on the CPU)
            atol = float(np.finfo(values.dtype).eps)
            want_rot = turned * np.stack([np.cos(angles), np.sin(angles)], axis=1)
            np.testing.assert_allclose(values, want_rot, rtol=0, atol=atol)
            continue
        np.testing.assert_array_equal(values, want[name].astype(values.dtype), err_msg=name)
    assert got["world_nbr_stale"].tolist() == [1] * world.layout.n_worlds  # lists stale


def test_a_worlds_motion_is_its_four_fields_read_in_one_launch(taichi_runtime):
    """``World.motion`` (one Transfer launch: a run's frames) gives what Taichi's
    ``to_numpy`` reads from the four fields, and what the four readers give, bit for bit,
    after steps that moved and turned the bodies; and only the scenes' bodies, not the
    capacity's."""
    raw = copy.deepcopy(dict(load_scenario("scenarios/two_squares.toml").raw))
    raw["body"][0]["angle"] = 0.3  # a corner first: the collision turns both squares
    scene = scene_from_dict(raw)
    world = World([scene, scene, scene])
    world.advance(round(0.4 / world.dt))
    world.check()
    got = world.motion()
    d = world.data
    fields = (d.body_pos, d.body_angle, d.body_vel, d.body_omega)
    want = [f.to_numpy()[:6].astype(np.float64) for f in fields]
    assert world.batch.n_bodies == 6 < world.layout.n_bodies
    for name, g, w in zip(("positions", "angles", "velocities", "omegas"), got, want):
        assert g.shape == w.shape and g.dtype == np.float64, name
        np.testing.assert_array_equal(g, w, err_msg=name)
    readers = (world.positions(), world.angles(), world.velocities(), world.omegas())
    for g, r in zip(got, readers):
        np.testing.assert_array_equal(r, g)
    assert np.all(got[3] != 0.0)  # the squares spin: the check compares moving values


def test_world_read_gives_what_to_numpy_gives_for_fields_of_every_group(taichi_runtime):
    """``World.read`` (the contact rows' reads): fields of the model, the state, the hash and
    the lists, of every type, equal Taichi's ``to_numpy`` of each, bit for bit, after steps;
    the same set read again takes the same reader; an unknown name is refused by name."""
    world = World([load_scenario("scenarios/two_squares.toml")] * 2)
    world.advance(round(0.3 / world.dt))
    world.check()
    names = ["body_mass", "body_vel", "contact_count", "contact_xi", "nbr_ids", "sorted_ids"]
    names.append("grid_inv_cell")  # 0-d
    holders = (world.model, world.data, world.hash, world.neighbours)
    got = world.read(names)
    assert list(got) == names
    for name in names:
        holder = next(h for h in holders if name in h.names)
        want = getattr(holder, name).to_numpy()
        assert got[name].dtype == want.dtype, name
        np.testing.assert_array_equal(got[name], want, err_msg=name)
    assert np.any(got["body_vel"] != 0.0)  # moving values
    # (a World on the fields of one gone, as here after the test above, keeps its readers)
    readers = dict(world.readers)
    assert readers[tuple(names)] is not None
    world.read(names)
    assert world.readers == readers
    with pytest.raises(UsageError, match="no field 'body_size'"):
        world.read(["body_pos", "body_size"])
