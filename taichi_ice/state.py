"""Data-oriented state of many independent worlds: Taichi fields, structure of arrays.

One set of fields holds every body of every world of a batch; a single scene is the batch of
one. Bodies are stored world by world (``world_body_start``), so an ensemble of small scenes
fills a GPU exactly as one large scene does, and the broad phase never pairs bodies of
different worlds.

Shapes below use N bodies, V vertices, W worlds, K contact slots per body, P probes, H hash
buckets, S small bodies (those in the spatial hash), G large bodies (walls, pushers: checked
against every body of their world instead).

Model (static after set-up)

==================== ======== =========== ==================================================
field                dtype    shape       meaning (unit)
==================== ======== =========== ==================================================
body_world           i32      N           world index of the body
body_kind            i32      N           KIND_DYNAMIC, KIND_FIXED or KIND_KINEMATIC
body_small           i32      N           1 if the body is in the spatial hash, 0 if large
body_inv_mass        real     N           1 / mass (1/kg); 0 for fixed and kinematic bodies
body_inv_inertia     real     N           1 / moment of inertia (1/(kg m^2)); 0 likewise
body_mass            real     N           mass (kg), for kinetic energy
body_inertia         real     N           moment of inertia about the centroid (kg m^2)
body_radius          real     N           circumradius about the centroid (m)
body_vert_start      i32      N           first vertex of the body in ``vert_local``
body_vert_count      i32      N           number of vertices (<= MAXV)
body_force_ext       vec2     N           constant external force on a dynamic body (N)
body_drag            real     N x 2       water drag: translational (kg/m), rotational (kg m^2)
body_probe           i32      N           probe index of the body, or -1
vert_local           vec2     V           outline relative to the centroid, unrotated (m)
world_mu             real     W           Coulomb friction coefficient of each world
world_rate_state     real     W x 5       rate-and-state (A, B, mu0, v_star, t_c) per world
world_tangential     real     W x 2       tangential spring k_t (N/m), dashpot c_t (N s/m)
world_body_start     i32      W + 1       first body of each world (bodies are world-major)
large_ids            i32      G           large bodies, world by world
world_large_start    i32      W + 1       first large body of each world in ``large_ids``
==================== ======== =========== ==================================================

Data (mutable)

==================== ======== =========== ==================================================
body_pos             vec2     N           centroid position (m)
body_angle           real     N           orientation (rad, counter-clockwise)
body_vel             vec2     N           centroid velocity (m/s)
body_omega           real     N           angular velocity (rad/s)
body_force_q         i64 x 2  N           contact force gathered this step, fixed point
body_torque_q        i64      N           contact torque gathered this step, fixed point
body_energy          f64      N x 4       cumulative per-body terms (J), see BODY_* indices
contact_partner      i32      2 x N x K   partner body of each slot, -1 if empty; two buffers
contact_count        i32      2 x N       used slots per body, per buffer
contact_xi           real     2 x N x K   tangential spring stretch along the tangent (m)
contact_area         real     2 x N x K   overlap area of the contact this step (m^2), output only
contact_elastic      real     2 x N x K   normal elastic energy stored in the contact (J)
contact_theta        real     2 x N x K   rate-and-state state variable (rate-state only)
world_energy         f64      W x E       running energy terms (J), see ENERGY_* indices
probe_impulse        f64      P x 2       contact impulse on each probe since last sample (N s)
status               i32      STATUS_LEN  overflow and divergence flags
time_step            real     ()          dt of the run (s)
==================== ======== =========== ==================================================

The two contact buffers alternate each step: the contact stage reads last step's memory
from one and writes this step's into the other, so no slot is read after it is overwritten.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import taichi as ti

KIND_DYNAMIC = 0
KIND_FIXED = 1
KIND_KINEMATIC = 2
KIND_NAMES = {"dynamic": KIND_DYNAMIC, "fixed": KIND_FIXED, "kinematic": KIND_KINEMATIC}

# Indices into world_energy. Cumulative terms grow over a run; KINETIC and ELASTIC are
# snapshots written by energy.snapshot().
ENERGY_FRICTION = 0  # dissipated by frictional slip (J)
ENERGY_VISCOUS = 1  # dissipated by the normal and tangential contact dashpots (J)
ENERGY_DRAG = 2  # dissipated by water drag (J)
ENERGY_WORK_IN = 3  # work done by kinematic bodies and external forces (J)
ENERGY_KINETIC = 4  # kinetic energy, translational + rotational (J)
ENERGY_ELASTIC = 5  # elastic energy in overlaps and tangential springs (J)
ENERGY_COUNT = 6

# Indices into body_energy: cumulative terms that one thread owns per body, so they need no
# atomics; energy.snapshot sums them per world in a fixed order.
BODY_FRICTION = 0  # frictional slip work of contacts this body owns (J)
BODY_VISCOUS = 1  # dashpot work of contacts this body owns (J)
BODY_DRAG = 2  # water drag dissipation on this body (J)
BODY_WORK = 3  # work done by this body (kinematic) or on it by its external force (J)
BODY_ENERGY_COUNT = 4

# Contact and body forces are gathered in 64-bit fixed point of this resolution (N, N m):
# integer addition is associative, so a body's total force does not depend on the order in
# which threads add to it and every run is bit-for-bit reproducible, alone or in a batch.
# 2^-24 N = 6e-8 N, with headroom to 2^39 N = 5e11 N.
FORCE_QUANTUM = 2.0**-24

# Indices into status.
STATUS_SLOT_OVERFLOW = 0  # most contacts any body needed this step (compare with K)
STATUS_NONFINITE = 1  # 1 if any body's velocity or position became non-finite
STATUS_RUNAWAY = 2  # 1 if any body moved faster than the runaway speed
STATUS_LEN = 3


@dataclass(frozen=True)
class Layout:
    """Sizes and compile-time switches of a batch (all plain Python numbers)."""

    n_bodies: int
    n_verts: int
    n_worlds: int
    n_probes: int
    slots: int  # K, contact slots per body
    max_verts: int  # MAXV, largest vertex count of any body
    hash_size: int  # H, a power of two
    cell_size: float  # m, hash cell edge = diameter of the largest small body
    n_small: int
    n_large: int
    rate_state: bool  # theta is carried only by rate-and-state worlds
    water: bool  # drag is compiled in only with water
    real: object  # ti.f32 or ti.f64


def _field(dtype, shape):
    # Taichi fields cannot be empty; size-zero buffers get one unused element.
    if isinstance(shape, int):
        shape = max(shape, 1)
    else:
        shape = tuple(max(s, 1) for s in shape)
    return ti.field(dtype, shape=shape)


def _vec_field(dtype, shape):
    return ti.Vector.field(2, dtype, shape=max(shape, 1))


class Model:
    """Static per-body and per-world data of a batch (see the module table)."""

    def __init__(self, layout: Layout):
        real, n, w = layout.real, layout.n_bodies, layout.n_worlds
        self.body_world = _field(ti.i32, n)
        self.body_kind = _field(ti.i32, n)
        self.body_small = _field(ti.i32, n)
        self.body_inv_mass = _field(real, n)
        self.body_inv_inertia = _field(real, n)
        self.body_mass = _field(real, n)
        self.body_inertia = _field(real, n)
        self.body_radius = _field(real, n)
        self.body_vert_start = _field(ti.i32, n)
        self.body_vert_count = _field(ti.i32, n)
        self.body_force_ext = _vec_field(real, n)
        self.body_drag = _field(real, (n, 2))
        self.body_probe = _field(ti.i32, n)
        self.vert_local = _vec_field(real, layout.n_verts)
        self.world_mu = _field(real, w)
        self.world_rate_state = _field(real, (w, 5))
        self.world_tangential = _field(real, (w, 2))
        self.world_body_start = _field(ti.i32, w + 1)
        self.large_ids = _field(ti.i32, layout.n_large)
        self.world_large_start = _field(ti.i32, w + 1)


class Data:
    """Mutable state of a batch (see the module table)."""

    def __init__(self, layout: Layout):
        real, n, k = layout.real, layout.n_bodies, layout.slots
        self.body_pos = _vec_field(real, n)
        self.body_angle = _field(real, n)
        self.body_vel = _vec_field(real, n)
        self.body_omega = _field(real, n)
        self.body_force_q = ti.Vector.field(2, ti.i64, shape=max(n, 1))
        self.body_torque_q = _field(ti.i64, n)
        self.body_energy = _field(ti.f64, (n, BODY_ENERGY_COUNT))
        self.contact_partner = _field(ti.i32, (2, n, k))
        self.contact_count = _field(ti.i32, (2, n))
        self.contact_xi = _field(real, (2, n, k))
        self.contact_area = _field(real, (2, n, k))
        self.contact_elastic = _field(real, (2, n, k))
        # Coulomb batches carry no state variable: one unused element keeps kernels uniform.
        self.contact_theta = _field(real, (2, n, k) if layout.rate_state else 1)
        self.world_energy = _field(ti.f64, (layout.n_worlds, ENERGY_COUNT))
        self.probe_impulse = _field(ti.f64, (layout.n_probes, 2))
        self.status = _field(ti.i32, STATUS_LEN)
        self.time_step = ti.field(real, shape=())
        self.contact_partner.fill(-1)


@dataclass
class HostArrays:
    """The NumPy side of a batch before upload: what ``world.build`` assembles from scenes."""

    body_world: np.ndarray
    body_kind: np.ndarray
    body_small: np.ndarray
    body_mass: np.ndarray
    body_inertia: np.ndarray
    body_radius: np.ndarray
    body_vert_start: np.ndarray
    body_vert_count: np.ndarray
    body_force_ext: np.ndarray
    body_drag: np.ndarray
    body_probe: np.ndarray
    vert_local: np.ndarray
    world_mu: np.ndarray
    world_rate_state: np.ndarray
    world_tangential: np.ndarray
    world_body_start: np.ndarray
    large_ids: np.ndarray
    world_large_start: np.ndarray
    body_pos: np.ndarray
    body_angle: np.ndarray
    body_vel: np.ndarray
    body_omega: np.ndarray


def upload(model: Model, data: Data, host: HostArrays, real_np) -> None:
    """Copy the assembled NumPy arrays into the Taichi fields."""

    def put(field, array, dtype):
        array = np.ascontiguousarray(array, dtype=dtype)
        if array.shape[0] == 0:
            return
        field.from_numpy(array)

    n_dyn = host.body_kind == KIND_DYNAMIC
    inv_mass = np.where(n_dyn, 1.0 / np.where(n_dyn, host.body_mass, 1.0), 0.0)
    inv_inertia = np.where(n_dyn, 1.0 / np.where(n_dyn, host.body_inertia, 1.0), 0.0)
    put(model.body_world, host.body_world, np.int32)
    put(model.body_kind, host.body_kind, np.int32)
    put(model.body_small, host.body_small, np.int32)
    put(model.body_inv_mass, inv_mass, real_np)
    put(model.body_inv_inertia, inv_inertia, real_np)
    put(model.body_mass, host.body_mass, real_np)
    put(model.body_inertia, host.body_inertia, real_np)
    put(model.body_radius, host.body_radius, real_np)
    put(model.body_vert_start, host.body_vert_start, np.int32)
    put(model.body_vert_count, host.body_vert_count, np.int32)
    put(model.body_force_ext, host.body_force_ext, real_np)
    put(model.body_drag, host.body_drag, real_np)
    put(model.body_probe, host.body_probe, np.int32)
    put(model.vert_local, host.vert_local, real_np)
    put(model.world_mu, host.world_mu, real_np)
    put(model.world_rate_state, host.world_rate_state, real_np)
    put(model.world_tangential, host.world_tangential, real_np)
    put(model.world_body_start, host.world_body_start, np.int32)
    put(model.large_ids, host.large_ids, np.int32)
    put(model.world_large_start, host.world_large_start, np.int32)
    put(data.body_pos, host.body_pos, real_np)
    put(data.body_angle, host.body_angle, real_np)
    put(data.body_vel, host.body_vel, real_np)
    put(data.body_omega, host.body_omega, real_np)
