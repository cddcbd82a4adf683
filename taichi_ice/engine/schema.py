"""The state of a batch of worlds, declared once: every field's name, type, shape and unit.

Everything else is derived from the tables below: the Taichi fields of ``state.Model``,
``state.Data`` and the broad phase's scratch (``state.allocate``), the NumPy arrays that
``assemble`` builds and ``World._start`` copies in (``HOST``; ``state.start_arrays``), the field table in
``docs/state.md`` (``markdown_table``; ``python -m taichi_ice.engine.schema`` writes it), and the
benchmark's traffic model (``stages.traffic``), which charges each stage for the fields it
declares it reads and writes (``stages.Stage``, in its own module with the check of those
declarations against the kernels' source).

Shapes are tuples of symbols that ``Layout.size`` resolves (MuJoCo Warp's convention). The
sizes are capacities (``assemble.capacity``: the scenes' counts rounded up to a few values),
so that scenes of other sizes run on kernels compiled for one of their kind; the kernels
loop over the bodies in use (``body_count``) and over every world (a world past the scenes'
has no bodies), and readers take the scenes' counts (``assemble.Batch.real``).

========== ===============================================================================
symbol     meaning
========== ===============================================================================
n_bodies   N, every body of every world, world-major
n_local_verts  vertices of the distinct unturned outlines (bodies of one shape share one)
n_worlds   W, worlds of the batch; ``world_edges`` = W + 1
n_probes   P, probe bodies (their contact force is recorded)
n_small    S, bodies in the spatial hash (the rest are large: walls, pushers)
n_large    G, large bodies, checked against every body of their world
slots      K, contact slots per body
hash_size  H, buckets of the spatial hash (a power of two)
scan_blocks H / SCAN, blocks of the hash's two-level prefix sum
nbr_len    C, entries of a body's neighbour list (candidate partners it owns)
grid_nodes nodes of the gridded current and wind together (1 where there is none)
========== ===============================================================================

plus the lengths of the code tables (``energy_terms``, ``body_energy_terms``,
``status_len``, from ``taichi_ice.codes``).

Pure Python: importing this module never starts Taichi.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..backend import DTYPES as BACKEND_DTYPES
from ..backend import numpy_dtype, taichi_dtype
from ..codes import BodyEnergy, EnergyTerm, Status

# Block length of the spatial hash's two-level prefix sum (broadphase.SpatialHash).
SCAN = 256

# Contact and body forces are gathered in 64-bit fixed point of this resolution (N, N m):
# integer addition is associative, so a body's total force does not depend on the order in
# which threads add to it and every run is bit-for-bit reproducible, alone or in a batch.
# 2^-24 N = 6e-8 N, with headroom to 2^39 N = 5e11 N. (The unit of ``body_force_q``.)
FORCE_QUANTUM = 2.0**-24

# Element types: "real" is the run's precision (f64 or f32); the rest are fixed. Energies and
# impulses accumulate over a whole run in f64 whatever the precision, and forces are gathered
# in 64-bit fixed point (FORCE_QUANTUM).
DTYPES = ("real", *BACKEND_DTYPES)  # "real": the run's precision

# Where a field's values come from at set-up: "host" (an array that assemble builds), or a
# constant fill.
HOST = "host"


@dataclass(frozen=True)
class Var:
    """One field of the state.

    Attributes:
        name: attribute name on its group (``model.body_pos``); prefix-first (body_, vert_,
            world_, contact_, ...).
        dtype: one of ``DTYPES``.
        shape: symbols (see the module table) or integers; ``()`` for a scalar.
        unit: SI unit, ``""`` for dimensionless, ``"id"`` for an index, ``"code"`` for a
            ``taichi_ice.codes`` member.
        doc: one line: what it holds.
        lanes: 1 for a scalar field, 2 for a 2-vector field (``ti.Vector.field(2, ...)``).
        role: ``"hot"`` (read or written by every step's stages), ``"cold"`` (set-up
            and bookkeeping, read rarely) or ``"diagnostic"`` (kept only for output: energy
            terms, overlap areas).
        when: a ``Layout`` switch that must be true for the field to exist (``"rate_state"``,
            ``"wind"``); otherwise a placeholder of one element keeps kernels uniform.
        init: ``HOST`` (built by ``assemble``, copied in by ``World._start``) or a fill value.
    """

    name: str
    dtype: str
    shape: tuple
    unit: str
    doc: str
    lanes: int = 1
    role: str = "hot"
    when: str | None = None
    init: Any = 0

    def __post_init__(self) -> None:
        if self.dtype not in DTYPES:
            raise ValueError(f"{self.name}: dtype {self.dtype!r} not in {DTYPES}")
        if self.role not in ("hot", "cold", "diagnostic"):
            raise ValueError(f"{self.name}: role {self.role!r}")

    def item_bytes(self, precision: str) -> int:
        """Bytes of one element (all lanes) in ``precision`` ('f64' or 'f32')."""
        dtype = precision if self.dtype == "real" else self.dtype
        return self.lanes * numpy_dtype(dtype).itemsize

    def np_dtype(self, precision: str) -> np.dtype:
        """NumPy dtype of the field's elements in ``precision``."""
        dtype = precision if self.dtype == "real" else self.dtype
        return numpy_dtype(dtype)


def law_columns() -> tuple[str, ...]:
    """The model columns every law's parameters make (``world_mu``, ``world_A``, ...,
    ``world_t_c``, ``world_memory``, ``world_rest_rule``), read off the laws' declarations:
    what a stage that evaluates friction reads (its ``ACCESS``)."""
    return tuple(v.name for v in _law_params())


def contact_columns() -> tuple[str, ...]:
    """The model columns of the contact law's values (``[ice]``), one per world: what a stage
    that evaluates contact forces reads (its ``ACCESS``)."""
    return (
        "world_contact_stiffness",
        "world_contact_viscosity",
        "world_tangential_stiffness",
        "world_tangential_damping",
        "world_slide_resolution",
        "world_crushing_force",
    )


def _law_params():
    # The friction laws own their parameters (names, units, meaning): one model column per
    # parameter, so adding a parameter to a law adds its column here.
    from ..physics.friction import Coulomb, RateState

    coulomb = [
        Var(
            f"world_{p.name}",
            "real",
            ("n_worlds",),
            p.unit,
            f"Coulomb: {p.doc}",
            role="cold",
            when="coulomb",
            init=HOST,
        )
        for p in Coulomb.parameters()
    ]
    rate_state = [
        Var(
            f"world_{p.name}",
            "real",
            ("n_worlds",),
            p.unit,
            f"rate-and-state: {p.doc}",
            role="cold",
            when="rate_state",
            init=HOST,
        )
        for p in RateState.parameters()
    ] + [
        Var(
            "world_memory",
            "i32",
            ("n_worlds",),
            "",
            "rate-and-state: 1 if contacts carry theta, 0 (Coulomb) if not",
            role="cold",
            when="rate_state",
            init=HOST,
        ),
        Var(
            "world_rest_rule",
            "i32",
            ("n_worlds",),
            "code",
            "rate-and-state: codes.RestRule, the memory below v_star",
            role="cold",
            when="rate_state",
            init=HOST,
        ),
    ]
    return coulomb + rate_state


# fmt: off
# Static after set-up (MuJoCo Warp's Model).
MODEL: tuple[Var, ...] = (
    Var("body_world", "i32", ("n_bodies",), "id", "world of the body", init=HOST),
    Var("body_kind", "i32", ("n_bodies",), "code", "codes.BodyKind", init=HOST),
    Var("body_small", "i32", ("n_bodies",), "", "1 if the body is in the spatial hash, 0 if large", init=HOST),
    Var("body_inv_mass", "real", ("n_bodies",), "1/kg", "1 / mass; 0 for fixed and kinematic bodies", init=HOST),
    Var("body_inv_inertia", "real", ("n_bodies",), "1/(kg m^2)", "1 / moment of inertia; 0 likewise", init=HOST),
    Var("body_mass", "real", ("n_bodies",), "kg", "mass, for the kinetic energy", role="diagnostic", init=HOST),
    Var("body_inertia", "real", ("n_bodies",), "kg m^2", "moment of inertia about the centroid", role="diagnostic", init=HOST),
    Var("body_radius", "real", ("n_bodies",), "m", "circumradius about the centroid", init=HOST),
    Var("body_local_start", "i32", ("n_bodies",), "id", "first vertex of the body's unturned outline in vert_local (shared by bodies of one shape)", init=HOST),
    Var("body_vert_count", "i32", ("n_bodies",), "", "vertices of the body (<= max_verts)", init=HOST),
    Var("body_force_ext", "real", ("n_bodies",), "N", "constant external force on a dynamic body", lanes=2, init=HOST),
    Var("body_drag_linear", "real", ("n_bodies",), "kg/m", "quadratic water drag on translation (0: no [water])", init=HOST),
    Var("body_drag_rotational", "real", ("n_bodies",), "kg m^2", "quadratic water drag on rotation (0: no [water])", init=HOST),
    # The forcing (physics.forcing): uniform per world, or sampled from the batch's grids.
    Var("body_drag_air", "real", ("n_bodies",), "kg/m", "quadratic wind drag rho_a C_a S ([wind])", when="wind", init=HOST),
    Var("world_current", "real", ("n_worlds",), "m/s", "uniform ocean current ([water] current)", lanes=2, when="current_uniform", init=HOST),
    Var("world_wind", "real", ("n_worlds",), "m/s", "uniform wind ([wind] velocity)", lanes=2, when="wind_uniform", init=HOST),
    Var("world_coriolis", "real", ("n_worlds",), "1/s", "Coriolis parameter f ([coriolis])", when="coriolis", init=HOST),
    Var("grid_values", "real", ("grid_nodes",), "m/s", "the gridded current's nodes, then the wind's: t major, x fastest", lanes=2, when="gridded", init=HOST),
    Var("grid_origin", "f64", (2, 3), "m, m, s", "x, y and t of the first node of the current's grid (row 0) and the wind's (row 1)", when="gridded", init=HOST),
    Var("grid_spacing", "f64", (2, 3), "m, m, s", "node spacing along x, y and t of each grid", when="gridded", init=HOST),
    Var("grid_size", "i32", (2, 4), "", "nodes along x, y and t of each grid, and its first node in grid_values", when="gridded", init=HOST),
    Var("body_probe", "i32", ("n_bodies",), "id", "probe index of the body, -1 if none", init=HOST),
    Var("vert_local", "real", ("n_local_verts",), "m", "distinct outlines relative to the centroid, unrotated", lanes=2, init=HOST),
    Var("vert_normal_local", "real", ("n_local_verts",), "", "outward unit normal of the edge from each vertex of vert_local to the next, unrotated", lanes=2, init=HOST),
    Var("world_body_start", "i32", ("world_edges",), "id", "first body of each world (bodies are world-major)", role="cold", init=HOST),
    Var("large_ids", "i32", ("n_large",), "id", "large bodies, world by world", role="cold", init=HOST),
    Var("world_large_start", "i32", ("world_edges",), "id", "first large body of each world in large_ids", role="cold", init=HOST),
    # The contact law's values, data not code: worlds of one batch may differ in them, and a
    # scene of another stiffness runs on kernels compiled for one of its kind.
    Var("world_contact_stiffness", "real", ("n_worlds",), "N/m^2", "k_e, N/m per m of contact width ([ice] contact_stiffness)", role="cold", init=HOST),
    Var("world_contact_viscosity", "real", ("n_worlds",), "Pa s", "k_v, Pa s per m of contact width ([ice] contact_viscosity)", role="cold", init=HOST),
    Var("world_tangential_stiffness", "real", ("n_worlds",), "", "k_t / (k_e L): the stick spring's ratio to the normal one ([ice] tangential_stiffness)", role="cold", init=HOST),
    Var("world_tangential_damping", "real", ("n_worlds",), "", "the stick spring's dashpot as a fraction of critical ([ice] tangential_damping)", role="cold", init=HOST),
    Var("world_slide_resolution", "real", ("n_worlds",), "", "a sliding rate-and-state contact's sub-steps: at most this fraction of c_t / k_t each, 0 for one step ([ice] slide_resolution; Euler step)", role="cold", init=HOST),
    Var("world_crushing_force", "real", ("n_worlds",), "N/m", "strength x thickness: the elastic normal force's cap per m of contact width", role="cold", when="crushing", init=HOST),
    Var("world_runaway_step", "real", ("n_worlds",), "m", "a dynamic body that moves farther in one step flags its world as diverged (RUNAWAY_STEP_FRACTION of its thinnest dynamic body; inf if none)", role="cold", init=HOST),
    Var("grid_inv_cell", "f64", (), "1/m", "1 / the spatial hash's cell edge (the largest small body's diameter plus the skin)", role="cold", init=HOST),
    Var("body_count", "i32", (), "", "bodies of the batch: rows of the n_bodies fields in use (the rest is capacity, never read)", role="cold", init=HOST),
    Var("list_skin", "real", (), "m", "margin of the neighbour lists: a pair is listed when its bounding circles come within it, a world's lists rebuilt when a body has moved half of it", role="cold", init=HOST),
)

# Mutable (MuJoCo Warp's Data).
DATA: tuple[Var, ...] = (
    Var("body_pos", "f64", ("n_bodies",), "m", "centroid position (f64 in either precision: a block far from the origin keeps its resolution; contacts work in the run's precision relative to the owner)", lanes=2, init=HOST),
    Var("body_angle", "real", ("n_bodies",), "rad", "orientation, counter-clockwise", init=HOST),
    Var("body_vel", "real", ("n_bodies",), "m/s", "centroid velocity", lanes=2, init=HOST),
    Var("body_omega", "real", ("n_bodies",), "rad/s", "angular velocity", init=HOST),
    Var("body_rot", "real", ("n_bodies",), "", "cos and sin of body_angle, updated as the body turns: its outline is vert_local turned by them (16 B a body at f64, where the turned outline took 16 B a vertex)", lanes=2),
    Var("body_force_q", "i64", ("n_bodies",), "N / FORCE_QUANTUM", "contact force gathered this step, fixed point (float64 whole quanta where integer atomics fail in loops: backend.float_gather)", lanes=2),
    Var("body_torque_q", "i64", ("n_bodies",), "N m / FORCE_QUANTUM", "contact torque gathered this step, fixed point (as body_force_q)"),
    Var("body_energy", "f64", ("n_bodies", "body_energy_terms"), "J", "cumulative per-body terms, codes.BodyEnergy columns", role="diagnostic", when="energy"),
    Var("body_dvel", "real", ("n_bodies",), "m/s", "velocity change of the body's last step: the contacts book their work at v + dv / 2 (contact_law.contact_work); the analytic step estimates a pair's other forces from it", lanes=2, when="velocity_changes"),
    Var("body_domega", "real", ("n_bodies",), "rad/s", "angular velocity change of the body's last step", when="velocity_changes"),
    Var("body_shift_q", "i64", ("n_bodies",), "N / FORCE_QUANTUM", "analytic step: the contacts' position impulses 2 Q / dt^2 gathered this step, fixed point (as body_force_q)", lanes=2, when="analytic"),
    Var("body_turn_q", "i64", ("n_bodies",), "N m / FORCE_QUANTUM", "analytic step: their torque, fixed point", when="analytic"),
    Var("body_time", "f64", ("n_bodies",), "s", "time of a dynamic body's next step: the clock of a grid with a t axis", when="clock"),
    Var("contact_partner", "i32", ("n_bodies", "slots"), "id", "partner body of each slot, -1 if empty", init=-1),
    Var("contact_count", "i32", ("n_bodies",), "", "used slots of each body"),
    Var("contact_xi", "real", ("n_bodies", "slots"), "m", "tangential spring stretch along the tangent"),
    Var("contact_elastic", "real", ("n_bodies", "slots"), "J", "elastic energy the contact holds: work of its normal and tangential springs (booked as severed when the contact ends)", role="diagnostic", when="energy"),
    Var("contact_theta", "real", ("n_bodies", "slots"), "", "rate-and-state variable theta; slip.NO_INTERFACE if none", when="rate_state"),
    Var("contact_slip", "real", ("n_bodies", "slots"), "m/s", "slip rate of the law along the tangent (signed: a change of sign ends the interface); 0 if stuck", when="rate_state"),
    Var("contact_force", "real", ("n_bodies", "slots"), "N", "analytic step: the contact's mean normal and tangential force on the partner over its last step (what its pair's other forces are told from)", lanes=2, when="analytic"),
    Var("contact_booking", "real", ("n_bodies", "slots"), "", "analytic step: what its work was booked with (the pair's estimated velocity change along the normal and tangent, m/s), the work's weights (0.5 dt f_el, 0.5 dt (f_n - f_el), -0.5 dt f_t, J s/m), whether it slid, the normal and the lever arms' cross products (m): ``settle`` books the work again at the velocity change the bodies took", lanes=12, when="settles"),
    Var("contact_crushed", "real", ("n_bodies", "slots"), "m^2", "overlap area crushed (beyond the strength), not recovered", when="crushing"),
    Var("world_energy", "f64", ("n_worlds", "energy_terms"), "J", "energy table of each world, codes.EnergyTerm columns", role="diagnostic", when="energy"),
    Var("probe_impulse", "f64", ("n_probes",), "N s", "contact impulse on each probe since the last sample", lanes=2, role="diagnostic"),
    Var("status", "i32", ("n_worlds", "status_len"), "code", "overflow and divergence flags of each world, codes.Status entries", role="cold"),
    Var("time_step", "real", (), "s", "dt of the run", role="cold"),
)

# The spatial hash of the parallel step, rebuilt with its neighbour lists (broadphase.SpatialHash).
HASH: tuple[Var, ...] = (
    Var("bucket_count", "i32", ("hash_size",), "", "bodies in each bucket this step"),
    Var("bucket_end", "i32", ("hash_size",), "id", "one past the last entry of each bucket in sorted_ids (its start while filling)"),
    Var("block_total", "i32", ("scan_blocks",), "", "per-block totals of the two-level scan"),
    Var("sorted_ids", "i32", ("n_small",), "id", "small body ids, grouped by bucket"),
    Var("strip_ids", "i32", ("n_bodies",), "id", "a thread per world's list build (ContactLists.build_world): each world's small bodies, strip by strip"),
    Var("strip_end", "i32", ("n_bodies",), "id", "the same: where each strip's entries end in strip_ids"),
)

# Neighbour lists with a skin (broadphase.NeighbourList), rebuilt when a body has moved half
# the skin since the last build.
NEIGHBOURS: tuple[Var, ...] = (
    Var("nbr_ids", "i32", ("n_bodies", "nbr_len"), "id", "partners a body owns whose bounding circles come within the skin, ascending"),
    Var("nbr_count", "i32", ("n_bodies",), "", "entries of each body's list"),
    Var("nbr_ref_pos", "f64", ("n_bodies",), "m", "centroid when the list was built", lanes=2),
    Var("nbr_ref_angle", "real", ("n_bodies",), "rad", "angle when the list was built"),
    Var("nbr_path", "f64", ("n_bodies",), "m", "how far any point of the body can have moved since its list was built: the sum over the steps of dt (|v| + radius |omega|)"),
    Var("nbr_gap", "f32", ("n_bodies", "slots"), "m", "of each of the first slots entries of the list found apart: that gap, less a margin, plus both bodies' nbr_path then; the pair cannot touch while their nbr_path sum to less (-1: test it; later entries are tested every step)", init=-1),
    Var("world_nbr_stale", "i32", ("n_worlds",), "", "1 if the world's lists must be rebuilt before its next step", init=1),
    Var("nbr_rebuild", "i32", (), "", "1 if some world's lists are stale (the parallel step reads it back before each step)", role="cold", init=1),
)
# fmt: on

GROUPS: dict[str, tuple[Var, ...]] = {}


def groups() -> dict[str, tuple[Var, ...]]:
    """``{"model": ..., "data": ..., "hash": ..., "nbr": ...}``: every declared field by group."""
    if not GROUPS:
        GROUPS.update(model=MODEL + tuple(_law_params()), data=DATA, hash=HASH, nbr=NEIGHBOURS)
    return GROUPS


def var(name: str) -> Var:
    """The declaration of field ``name`` (in any group)."""
    for group in groups().values():
        for v in group:
            if v.name == name:
                return v
    raise KeyError(f"no field {name!r} is declared in taichi_ice.engine.schema")


def host_vars() -> tuple[Var, ...]:
    """Fields whose values ``assemble`` builds (``init == HOST``), in declaration order."""
    return tuple(v for g in groups().values() for v in g if v.init == HOST)


# --------------------------------------------------------------------------------------------
# Layout: the sizes and compile-time switches of a batch
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Layout:
    """Sizes and compile-time switches of a batch (plain Python values; MuJoCo's Option).

    Kernels specialise on everything here (``ti.static``): two batches with the same layout
    share compiled kernels. Values are not here: the contact law's stiffnesses, dashpots and
    strength, the runaway distance, the hash's cell and the lists' skin are model fields
    (``world_contact_stiffness``, ..., ``grid_inv_cell``, ``list_skin``), and dt is
    ``time_step``, so a scene of another stiffness or floe size, or a run at another dt,
    takes the kernels compiled for the first of its kind. Nor are the scenes' counts: the
    sizes are capacities (``assemble.capacity``), and the bodies in use are ``body_count``,
    so a scene of 5 bodies and one of 8 share kernels too. Nor are the water's drag and the
    bodies' constant forces: a body without them has zero coefficients (``body_drag_linear``,
    ``body_drag_rotational``) and a zero ``body_force_ext``, so a scene with water or a
    pushed body takes the kernels of one without (2026-12-03: the suite's workers compiled
    the step for 39 layouts before, 26 since; the forces add exact zeros: the same bits).

    Attributes:
        n_bodies, n_local_verts, n_worlds, n_probes, n_small, n_large, slots, hash_size:
            capacities (see the module table).
        max_verts: most vertices a body may have, 4, 8 or 16 (the kernels' local outline
            matrices).
        coulomb, rate_state: the batch's friction: every world Coulomb (``world_mu``), or
            rate-and-state columns for every world (``friction.contact_row``: the
            rate-and-state laws, and Coulomb worlds as A = B = 0).
        theta_method: ``codes.ThetaMethod`` of the state variable (one per batch).
        crushing: the ice's strength caps the normal force (``[ice] crushing_strength``; its
            value per world is ``world_crushing_force``).
        precision: ``"f64"`` or ``"f32"``, the type of every ``real`` field.
        energy: the energy budget is kept (``body_energy``, the contacts' stored elastic
            energy, ``world_energy``); off, no kernel computes or stores a term of it, and
            the samples' energy columns are NaN.
        nbr_len: entries of a body's neighbour list.
        integrator: how the step moves the bodies, "euler", "analytic", "coupled" or "midstep"
            (``options.INTEGRATORS``).
        current, wind, coriolis: an ocean current (``[water] current``), the wind's drag
            (``[wind]``), the Coriolis force (``[coriolis]``) are compiled in; without them
            the step is what it was before they existed, bit for bit.
        tilt: the sea-surface tilt of a geostrophic current (``[water] geostrophic``).
        current_grid, wind_grid: the current or the wind is sampled from a grid
            (``grid_values``), not uniform per world (``world_current``, ``world_wind``).
        clock: a grid has a t axis: each dynamic body keeps its time (``body_time``).
        grid_nodes: capacity of ``grid_values``, both grids' nodes together.
    """

    n_bodies: int
    n_local_verts: int
    n_worlds: int
    n_probes: int
    n_small: int
    n_large: int
    slots: int
    hash_size: int
    max_verts: int
    coulomb: bool
    rate_state: bool
    theta_method: int
    crushing: bool
    precision: str = "f64"
    energy: bool = True
    nbr_len: int = 1
    integrator: str = "euler"
    current: bool = False
    wind: bool = False
    coriolis: bool = False
    tilt: bool = False
    current_grid: bool = False
    wind_grid: bool = False
    clock: bool = False
    grid_nodes: int = 1

    @property
    def current_uniform(self) -> bool:
        """A current of one value per world (``world_current``)."""
        return self.current and not self.current_grid

    @property
    def wind_uniform(self) -> bool:
        """A wind of one value per world (``world_wind``)."""
        return self.wind and not self.wind_grid

    @property
    def gridded(self) -> bool:
        """The current or the wind comes from a grid (``grid_values``)."""
        return self.current_grid or self.wind_grid

    @property
    def forced(self) -> bool:
        """The forcing does work that the budget books (``codes.BodyEnergy.WIND`` ...):
        a current (and its tilt) or wind. Coriolis does none."""
        return self.current or self.wind

    @property
    def analytic(self) -> bool:
        """Each contact's spring-dashpot is integrated exactly over the step
        (``integrator`` "analytic", "coupled" or "midstep"): its position impulses are
        gathered too."""
        return self.integrator in ("analytic", "coupled", "midstep")

    @property
    def coupled(self) -> bool:
        """The analytic step with a contact's normal and tangent solved together
        (``integrator`` "coupled" or "midstep", ``physics.contact_coupled``)."""
        return self.integrator in ("coupled", "midstep")

    @property
    def midstep(self) -> bool:
        """The coupled step with each contact linearised about the configuration predicted
        for mid-step (``integrator = "midstep"``; ``ContactLists.midstep_outlines``)."""
        return self.integrator == "midstep"

    @property
    def settles(self) -> bool:
        """The analytic steps book each contact's work again once the bodies have moved, at
        the velocity change they took (``ContactLists.settle``): where the budget is kept."""
        return self.analytic and self.energy

    @property
    def velocity_changes(self) -> bool:
        """Each body's last velocity change is kept (``body_dvel``): for the energy budget's
        booking, and for the analytic step's estimate of what a pair's other forces do."""
        return self.energy or self.analytic

    @property
    def real(self):
        """The Taichi type of ``real`` fields (for kernels; imports Taichi when asked)."""
        return taichi_dtype(self.precision)

    def size(self, symbol) -> int:
        """The value of a shape symbol (an int passes through)."""
        if isinstance(symbol, int):
            return symbol
        derived = {
            "world_edges": self.n_worlds + 1,
            "scan_blocks": (self.hash_size + SCAN - 1) // SCAN,
            "energy_terms": len(EnergyTerm),
            # The forcing's columns only where it does work.
            "body_energy_terms": len(BodyEnergy) if self.forced else int(BodyEnergy.WIND),
            "status_len": len(Status),
        }
        if symbol in derived:
            return derived[symbol]
        value = getattr(self, symbol, None)
        if not isinstance(value, int) or isinstance(value, bool):
            raise KeyError(f"unknown shape symbol {symbol!r}")
        return value

    def shape(self, v: Var) -> tuple[int, ...]:
        """The field's shape in this layout (before the one-element floor of empty fields)."""
        return tuple(self.size(s) for s in v.shape)

    def exists(self, v: Var) -> bool:
        """Whether the field is allocated at its declared shape (its ``when`` switch holds)."""
        return v.when is None or bool(getattr(self, v.when))

    def replace(self, **changes) -> Layout:
        return dataclasses.replace(self, **changes)


def allocated_shape(layout: Layout, v: Var) -> tuple[int, ...]:
    """Shape of the Taichi field: a switched-off field has one element; Taichi fields cannot
    be empty, so a zero-size axis gets one unused element."""
    if not layout.exists(v):
        return (1,)
    return tuple(max(n, 1) for n in layout.shape(v))


def field_bytes(layout: Layout) -> dict[str, int]:
    """Bytes of every allocated field, ``{name: bytes}``."""
    return {
        v.name: int(np.prod(allocated_shape(layout, v), dtype=np.int64))
        * v.item_bytes(layout.precision)
        for g in groups().values()
        for v in g
    }


# --------------------------------------------------------------------------------------------
# Host arrays
# --------------------------------------------------------------------------------------------


class HostArrays(Mapping):
    """The NumPy side of a batch before upload: one array per ``HOST`` field, checked.

    Built by ``assemble``; read by ``state.start_arrays`` and by the NumPy reference
    (``reference.ReferenceModel``), so both start from the same numbers. Access by name as a
    mapping or an attribute (``host.body_mass``).

    Raises:
        ValueError: a field missing, unknown, or not of its declared shape and type.
    """

    def __init__(self, layout: Layout, arrays: Mapping[str, np.ndarray]):
        wanted = {v.name: v for v in host_vars() if layout.exists(v)}
        unknown = set(arrays) - {v.name for v in host_vars()}
        missing = set(wanted) - set(arrays)
        if unknown or missing:
            raise ValueError(f"host arrays: unknown {sorted(unknown)}, missing {sorted(missing)}")
        self._arrays: dict[str, np.ndarray] = {}
        for name, v in wanted.items():
            shape = layout.shape(v) + ((v.lanes,) if v.lanes > 1 else ())
            dtype = v.np_dtype("f64")  # assembled in float64; upload casts reals
            a = np.asarray(arrays[name], dtype=dtype, order="C")  # (0-d stays 0-d)
            if a.shape != shape:
                raise ValueError(f"host array {name}: shape {a.shape}, declared {shape}")
            a.flags.writeable = False
            self._arrays[name] = a

    def __getitem__(self, name: str) -> np.ndarray:
        return self._arrays[name]

    def __getattr__(self, name: str) -> np.ndarray:
        try:
            return self.__dict__["_arrays"][name]
        except KeyError:
            raise AttributeError(name) from None

    def __iter__(self):
        return iter(self._arrays)

    def __len__(self) -> int:
        return len(self._arrays)


# --------------------------------------------------------------------------------------------
# The documentation table
# --------------------------------------------------------------------------------------------


def markdown_table() -> str:
    """docs/state.md: every field, grouped, with type, shape, unit, role and meaning."""
    lines = [
        "# The state of a batch",
        "",
        "Generated from `taichi_ice/engine/schema.py` by `python -m taichi_ice.engine.schema > docs/state.md`;",
        "a test keeps the two equal. `real` is the run's precision (f64 or f32). A field whose",
        "`when` switch is off is allocated with one unused element.",
        "",
    ]
    titles = {
        "model": "Model: static after set-up",
        "data": "Data: mutable",
        "hash": "Spatial hash and strips: scratch of the list rebuilds (the hash the parallel step's, the strips a thread per world's)",
        "nbr": "Neighbour lists: rebuilt when a body has moved half the skin",
    }
    for group, fields in groups().items():
        lines += [
            f"## {titles[group]}",
            "",
            "| field | type | shape | unit | role | meaning |",
            "|---|---|---|---|---|---|",
        ]
        for v in fields:
            dtype = v.dtype if v.lanes == 1 else f"{v.dtype} x {v.lanes}"
            shape = " x ".join(str(s) for s in v.shape) or "scalar"
            role = v.role + (f", if {v.when}" if v.when else "")
            lines.append(f"| `{v.name}` | {dtype} | {shape} | {v.unit} | {role} | {v.doc} |")
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    print(markdown_table(), end="")
