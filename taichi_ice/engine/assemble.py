"""Scenes to the NumPy arrays of one batch: what every world needs, checked, in one place.

``assemble(scenes, options)`` concatenates the bodies of every scene world by world and derives
the per-body and per-world parameters (masses, drag coefficients, the tangential spring, the
friction law's columns), the sizes and compile-time switches of the batch (``Layout``) and
its time step. ``World`` uploads the result to Taichi fields; the NumPy reference
(``reference.ReferenceModel``) reads the same arrays, so the two never derive a parameter
twice.

NumPy only: importing it imports no Taichi (the polygon and drag modules it reads are the
NumPy halves of their ``_ti`` twins).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..codes import BodyKind, ThetaMethod
from ..errors import ScenarioError
from ..physics import polygon
from ..physics.drag import drag_coefficients
from ..physics.forcing import air_drag_coefficient
from ..scene.grid import ForcingGrid
from ..scene.model import MAX_VERTICES
from .options import BODY_FLOOR, DEFAULT_SMALL_SLOTS, LARGE_SLOTS, Options
from .schema import SCAN, HostArrays, Layout

# A dynamic body that moves more than this fraction of its thinnest dimension in one step
# has left the regime where contacts can be resolved (it would pass a quarter of the way
# through a neighbour before the contact is seen): the integration has blown up. This is a
# numerical bound, not a physical one: a jam that stores a megajoule and releases it can
# throw a block at tens of m/s, and that is the model's answer, not a divergence. (Energy
# created from nothing is caught by the energy budget, ``budget.breached``.)
RUNAWAY_STEP_FRACTION = 0.25

# The neighbour lists' skin, as a fraction of the hash cell (the largest small body's
# diameter), and their length in contact slots. A block drifting at 0.1 m/s keeps its list
# for ~0.25 s (2,000 steps of the pillar scene) with a 1 m cell. A list holds the pairs a
# body owns within the skin: its contacts (at most its slots) and near misses. Twice the
# slots: the most any body listed was 4 in the random and lattice boxes of 1e4 diamonds, 7 in
# the pillar scene's 17 layouts x 4 laws over 20 s (checked at every step), and more stops
# the run with a CapacityError that says what to pass.
SKIN_FRACTION = 0.05
LIST_SLOTS = 2

# Largest polygon the contact kernel compiles for (its clip buffers are 2 MAXV long); scenes
# are held to it when they are read (scene.MAX_VERTICES), batches built by hand here.
MAX_VERTS_LIMIT = MAX_VERTICES


# The sizes a layout compiles for are capacities: the scenes' counts rounded up to a few
# values (``capacity``), with a floor each, so that scenes of nearby sizes share a layout and
# its compiled kernels (a World reloaded with them, or Taichi's offline cache in another
# process that builds its fields in the same order: the cache's keys hold the fields' node
# ids, docs/architecture.md). Powers of two up to CAPACITY_POW2_MAX (memory is no concern
# there), then steps of an eighth to a sixteenth of the count (at most 12.5 % of rows unused
# at 1e4 bodies and up). The rows past the scenes' are never read: the kernels loop over
# ``body_count``.
# Worlds take a floor of 8: a world alone and a batch of up to 8 share one layout, and so
# one set of compiled kernels (a World of one and then of a batch in one process, as tests,
# ensembles and a user's first runs do, compiled twice with a floor of 1). A world past the
# scenes' has no bodies: its thread (thread-per-world stepping) and its rows of the
# per-world loops find nothing to do.
# Bodies take a floor of 256 (and the rest in proportion), so that every scene of up to 256
# bodies, a user's edits of one and a sweep over layouts of tens to hundreds of floes, is
# one layout: one compile (2026-12-02: the suite's workers built 107 layouts before, 69 with
# these floors and the small scenes' slots below; two squares' fields 10 kB -> 150 kB).
# Stepping is the same: the pillar (67 bodies), two squares and the pushed field took the
# same time a step at 256 rows as at their own capacities (128, 8 and 64; 256 over their
# own 0.96-1.00, one process, alternating), the pillar 7-9 % longer at 1024 rows (its ~100
# fields' first rows spread over more memory pages), so the floor stops at 256.
CAPACITY_POW2_MAX = 4096
CAPACITY_FLOORS = {
    "n_bodies": BODY_FLOOR,
    "n_local_verts": 8 * BODY_FLOOR,
    "n_worlds": 8,
    "n_probes": 8,
    "n_small": BODY_FLOOR,
    "n_large": 64,
    "grid_nodes": 4096,  # a forcing grid's nodes (64 kB at f64), allocated only for a grid
}
# Outline matrices the contact kernels unroll: a body of 3 vertices runs in the kernels of 4.
MAX_VERTS_STEPS = (4, 8, MAX_VERTICES)


def capacity(n: int, least: int = 1) -> int:
    """The size compiled for ``n`` items: at least ``least``, a power of two up to
    ``CAPACITY_POW2_MAX``, beyond it a multiple of the power of two 8-16 times below ``n``.

    >>> [capacity(n) for n in (1, 3, 5, 64, 65, 4096, 4097, 10_000, 100_000)]
    [1, 4, 8, 64, 128, 4096, 4608, 10240, 106496]
    """
    n = max(int(n), int(least))
    p = 1 << (n - 1).bit_length() if n > 1 else 1
    if p <= CAPACITY_POW2_MAX:
        return p
    step = 1 << (n.bit_length() - 4)
    return -(-n // step) * step


def capacities(sizes: dict) -> dict:
    """The layout's sizes for the scenes' counts ``sizes`` (``capacity`` of each, with its
    floor; ``max_verts`` to the next of ``MAX_VERTS_STEPS``)."""
    out = {k: capacity(v, CAPACITY_FLOORS[k]) for k, v in sizes.items() if k in CAPACITY_FLOORS}
    out["max_verts"] = next(m for m in MAX_VERTS_STEPS if m >= sizes["max_verts"])
    return out


@dataclass(frozen=True)
class Batch:
    """Everything a batch of worlds needs before its fields exist.

    Attributes:
        scenes: the worlds, in order.
        layout: sizes and compile-time switches (``schema.Layout``): the capacities the
            kernels compile for.
        real: the layout with the scenes' own counts (bodies, worlds, probes, ...): the
            shapes of ``host`` and of what readers return.
        host: the arrays of every ``HOST`` field (``schema.HostArrays``), of the scenes'
            counts (``state.start_arrays`` pads them to the capacities).
        dt: the time step (s). stable_dt: the contact stability limit (s), over every world.
        default_slots: the contact slots per body these scenes get when none are asked for
            (``layout.slots`` unless ``Options.slots`` set them).
    """

    scenes: tuple
    layout: Layout
    real: Layout
    host: HostArrays
    dt: float
    stable_dt: float
    default_slots: int

    @property
    def n_bodies(self) -> int:
        """Bodies of the scenes (``layout.n_bodies`` is the capacity)."""
        return self.real.n_bodies

    @property
    def n_probes(self) -> int:
        """Probes of the scenes."""
        return self.real.n_probes

    def world_slices(self) -> list[slice]:
        """Body index range of each world."""
        s = self.host.world_body_start
        return [slice(int(s[w]), int(s[w + 1])) for w in range(len(self.scenes))]

    def probe_slices(self) -> list[slice]:
        """Probe index range of each world."""
        counts = [len(sc.probe_indices) for sc in self.scenes]
        start = np.concatenate([[0], np.cumsum(counts)]).astype(int)
        return [slice(int(start[w]), int(start[w + 1])) for w in range(len(self.scenes))]


def assemble(scenes: Sequence, options: Options | None = None) -> Batch:
    """Check that ``scenes`` can run as one batch and build its arrays.

    Args:
        scenes: the worlds. They must share the water table (present or not; a uniform
            current may differ, its presence may not, a gridded one is one grid), the wind
            and Coriolis tables' presence (and a gridded wind's grid), whether the ice has a
            crushing strength, and the integrator of theta (laws that have one); the
            friction laws (Coulomb, rate-and-state and its variants), their parameters, the
            ice's values (stiffness, viscosity, strength, ...), a uniform current or wind,
            the air's density and drag, the Coriolis parameter and everything else may
            differ.
        options: the engine's settings (``options.Options``; default ``Options()``). Read
            here: ``dt`` and ``force_dt`` (``Options.time_step``), ``precision`` (None:
            'f64'), ``slots`` (None: ``DEFAULT_SMALL_SLOTS`` plus the most large bodies of
            any world, at most ``LARGE_SLOTS``; plus ``LARGE_SLOTS`` for scenes of up to
            ``BODY_FLOOR`` bodies), ``energy`` (``Layout.energy``; off, the
            step neither computes nor stores its terms: fields of ~270 B a block fewer at
            f64) and ``integrator`` (None: the scenes', ``Options.for_scenes``; the
            batch's scenes are those that step with it).

    Raises:
        ValueError: no scenes, or worlds that disagree on what a batch shares (the message
            names the first world that differs and what differs).
        ScenarioError: a polygon with more vertices than the kernels hold.
        StabilityError: a dt above the stability limit without ``force_dt``.
    """
    options = Options() if options is None else options
    scenes = tuple(scenes)
    if not scenes:
        raise ValueError("a batch needs at least one scene")
    options, scenes = options.for_scenes(scenes)
    _check_shared(scenes)
    dt, stable_dt = options.time_step(scenes)

    arrays, sizes = _bodies(scenes)
    first = scenes[0]
    coulomb = all(s.friction.name == "coulomb" for s in scenes)
    arrays.update(_worlds(scenes, coulomb))
    methods = {s.friction.method for s in scenes if hasattr(s.friction, "method")}
    large_per_world = sizes.pop("large_per_world")
    default_slots = DEFAULT_SMALL_SLOTS + min(int(large_per_world), LARGE_SLOTS)
    if sizes["n_bodies"] <= BODY_FLOOR:  # small scenes: one layout, walls or none
        default_slots = DEFAULT_SMALL_SLOTS + LARGE_SLOTS
    slots = options.slots if options.slots is not None else default_slots
    cell_size = sizes.pop("cell_size")
    skin = SKIN_FRACTION * cell_size
    arrays.update(_contact_values(scenes))
    forcing = _forcing(scenes, arrays, sizes)
    arrays["grid_inv_cell"] = np.array(1.0 / (cell_size + skin))
    arrays["list_skin"] = np.array(skin)
    arrays["body_count"] = np.array(sizes["n_bodies"], dtype=np.int32)
    real = Layout(
        **sizes,
        slots=slots,
        nbr_len=LIST_SLOTS * slots,
        hash_size=hash_size_for(sizes["n_small"]),
        coulomb=coulomb,
        rate_state=not coulomb,
        theta_method=int(ThetaMethod.from_label(methods.pop()))
        if methods
        else int(ThetaMethod.EXPONENTIAL),
        crushing=first.ice.crushing_strength is not None,
        precision=options.precision or "f64",
        energy=options.energy,
        integrator=options.integrator,
        **forcing,
    )
    caps = capacities(sizes)
    layout = real.replace(**caps, hash_size=hash_size_for(caps["n_small"]))
    if not layout.crushing:
        arrays.pop("world_crushing_force")
    if not layout.wind:
        arrays.pop("body_drag_air")
    host = HostArrays(real, arrays)
    return Batch(scenes, layout, real, host, dt, stable_dt, default_slots)


def hash_size_for(n_small: int) -> int:
    """Buckets of the spatial hash: the smallest power of two >= n_small (at least SCAN), a
    load factor between one half and one. (The hash is rebuilt only with the lists, every few
    hundred steps, so the fuller table's extra bucket collisions cost little.)"""
    return max(SCAN, 1 << int(np.ceil(np.log2(max(n_small, 2)))))


def _check_shared(scenes: tuple) -> None:
    """Every world agrees with the first on what one set of kernels compiles in."""
    first = scenes[0]
    for w, s in enumerate(scenes[1:], start=1):
        where = f"world {w} ({s.source}) differs from world 0 ({first.source}) in"
        if (s.ice.crushing_strength is None) != (first.ice.crushing_strength is None):
            raise ValueError(
                f"{where} whether the ice has a crushing_strength ([ice]); the kernels compile "
                "the cap in or not, so all worlds of a batch have one or none"
            )
        if _shared_water(s.water) != _shared_water(first.water):
            raise ValueError(
                f"{where} the [water] table; all worlds of a batch share it (but the value "
                "of a uniform current, which they may each have: not its presence)"
            )
        if _field_kind(s.wind, "velocity") != _field_kind(first.wind, "velocity"):
            raise ValueError(
                f"{where} its [wind] (present or not, uniform or on which grid); the kernels "
                "compile it in or not, so all worlds of a batch have one (uniform values, air "
                "density and drag may differ) or none"
            )
        if (s.coriolis is None) != (first.coriolis is None):
            raise ValueError(
                f"{where} whether it has a [coriolis] table; the kernels compile the force in "
                "or not, so all worlds of a batch have one (f may differ) or none"
            )
    # The laws may mix (Coulomb, rate-and-state and its variants, any parameters); the
    # integrator of theta is compiled in, so the laws that have one must agree on it.
    methods = [(w, s) for w, s in enumerate(scenes) if hasattr(s.friction, "method")]
    for w, s in methods[1:]:
        w0, s0 = methods[0]
        if s.friction.method != s0.friction.method:
            raise ValueError(
                f"world {w} ({s.source}) differs from world {w0} ({s0.source}) in the "
                f"rate-and-state integrator ({s.friction.method} against "
                f"{s0.friction.method}); the kernels compile one"
            )


def _field_kind(table, key: str):
    """What a batch shares of a current or wind: None, "uniform", or the grid itself."""
    value = None if table is None else getattr(table, key)
    if value is None or isinstance(value, ForcingGrid):
        return value
    return "uniform"


def _shared_water(water):
    """The [water] table as the worlds of a batch must share it."""
    if water is None:
        return None
    return dataclasses.replace(water, current=_field_kind(water, "current"))


def _forcing(scenes: tuple, arrays: dict, sizes: dict) -> dict:
    """The forcing's per-world arrays and grids into ``arrays``, ``grid_nodes`` into
    ``sizes``; returns the layout's switches (``Layout.current`` ...)."""
    first = scenes[0]
    current = _field_kind(first.water, "current")
    wind = _field_kind(first.wind, "velocity")
    switches = {
        "current": current is not None,
        "wind": wind is not None,
        "coriolis": first.coriolis is not None,
        "tilt": current is not None and first.water.geostrophic,
        "current_grid": isinstance(current, ForcingGrid),
        "wind_grid": isinstance(wind, ForcingGrid),
    }
    if current == "uniform":
        arrays["world_current"] = np.array([s.water.current for s in scenes], dtype=float)
    if wind == "uniform":
        arrays["world_wind"] = np.array([s.wind.velocity for s in scenes], dtype=float)
    if switches["coriolis"]:
        arrays["world_coriolis"] = np.array([s.coriolis.f for s in scenes], dtype=float)
    # Row 0 of the grid tables is the current's, row 1 the wind's (``forcing.Forcing``); a
    # row without a grid is never read.
    values, start = [], 0
    origin, spacing = np.zeros((2, 3)), np.ones((2, 3))
    size = np.array([[1, 1, 1, 0]] * 2, dtype=np.int32)
    for row, grid in enumerate((current, wind)):
        if isinstance(grid, ForcingGrid):
            nt, ny, nx = grid.shape
            values.append(grid.values.reshape(-1, 2))
            origin[row], spacing[row] = grid.origin, grid.spacing
            size[row] = (nx, ny, nt, start)
            start += nt * ny * nx
    sizes["grid_nodes"] = start
    switches["clock"] = bool(np.any(size[:, 2] > 1))
    if values:
        arrays.update(
            grid_values=np.concatenate(values),
            grid_origin=origin,
            grid_spacing=spacing,
            grid_size=size,
        )
    return switches


def _bodies(scenes: tuple) -> tuple[dict[str, np.ndarray], dict]:
    """Per-body arrays of every world, world-major, and the batch's sizes."""
    rows: dict[str, list] = {
        k: []
        for k in (
            "body_world",
            "body_kind",
            "body_mass",
            "body_inertia",
            "body_radius",
            "body_vert_count",
            "body_force_ext",
            "body_drag_linear",
            "body_drag_rotational",
            "body_drag_air",
            "body_probe",
            "body_pos",
            "body_angle",
            "body_vel",
            "body_omega",
        )
    }
    verts: list[np.ndarray] = []
    n_probe = 0
    for w, s in enumerate(scenes):
        masses, inertias = s.masses, s.inertias
        for i, b in enumerate(s.bodies):
            v = np.asarray(b.vertices, dtype=np.float64)
            if len(v) > MAX_VERTS_LIMIT:
                raise ScenarioError(
                    f"{s.source}: body '{b.name}' has {len(v)} vertices; the contact kernels "
                    f"hold at most {MAX_VERTS_LIMIT}: simplify its outline"
                )
            rows["body_world"].append(w)
            rows["body_kind"].append(BodyKind.from_label(b.kind))
            rows["body_mass"].append(masses[i])
            rows["body_inertia"].append(inertias[i])
            rows["body_radius"].append(float(np.max(np.hypot(v[:, 0], v[:, 1]))))
            rows["body_vert_count"].append(len(v))
            rows["body_force_ext"].append(b.force)
            c_lin, c_rot = (0.0, 0.0)
            if s.water is not None:
                area = masses[i] / (s.ice.density * s.ice.thickness)
                c_lin, c_rot = drag_coefficients(
                    area,
                    s.ice.thickness,
                    s.ice.density,
                    s.water.density,
                    s.water.form_drag,
                    s.water.skin_drag,
                )
            rows["body_drag_linear"].append(c_lin)
            rows["body_drag_rotational"].append(c_rot)
            c_air = 0.0
            if s.wind is not None:
                area = masses[i] / (s.ice.density * s.ice.thickness)
                c_air = air_drag_coefficient(area, s.wind.air_density, s.wind.drag)
            rows["body_drag_air"].append(c_air)
            rows["body_probe"].append(n_probe if b.probe else -1)
            n_probe += int(b.probe)
            rows["body_pos"].append(b.position)
            rows["body_angle"].append(b.angle)
            rows["body_vel"].append(b.velocity)
            rows["body_omega"].append(b.omega)
            verts.append(v)

    n = len(rows["body_kind"])
    out = {
        k: np.array(v, dtype=np.float64).reshape(n, 2)
        if k in ("body_force_ext", "body_pos", "body_vel")
        else np.array(v)
        for k, v in rows.items()
    }
    kind = out["body_kind"] = out["body_kind"].astype(np.int32)
    world = out["body_world"] = out["body_world"].astype(np.int32)
    count = out["body_vert_count"] = out["body_vert_count"].astype(np.int32)
    out["body_probe"] = out["body_probe"].astype(np.int32)
    dynamic = kind == BodyKind.DYNAMIC
    safe_mass = np.where(dynamic, out["body_mass"], 1.0)
    safe_inertia = np.where(dynamic, out["body_inertia"], 1.0)
    out["body_inv_mass"] = np.where(dynamic, 1.0 / safe_mass, 0.0)
    out["body_inv_inertia"] = np.where(dynamic, 1.0 / safe_inertia, 0.0)

    # Small bodies go into the spatial hash; larger ones (walls, pushers) are checked against
    # every body of their world.
    radius = out["body_radius"]
    r_small = radius[dynamic].max() if dynamic.any() else radius.max(initial=1.0)
    small = radius <= r_small * (1.0 + 1e-9)
    out["body_small"] = small.astype(np.int32)
    large_ids = np.flatnonzero(~small).astype(np.int32)
    n_worlds = len(scenes)
    out["large_ids"] = large_ids
    out["world_large_start"] = np.searchsorted(world[large_ids], np.arange(n_worlds + 1)).astype(
        np.int32
    )
    out["world_body_start"] = np.searchsorted(world, np.arange(n_worlds + 1)).astype(np.int32)
    # Bodies of one shape (a field's blocks) share their unturned outline: it is stored once.
    shapes: dict[bytes, int] = {}
    local_start = np.zeros(n, dtype=np.int32)
    distinct: list[np.ndarray] = []
    n_local = 0
    for i, v in enumerate(verts):
        key = v.tobytes()
        if key not in shapes:
            shapes[key] = n_local
            distinct.append(v)
            n_local += len(v)
        local_start[i] = shapes[key]
    out["body_local_start"] = local_start
    out["vert_local"] = np.concatenate(distinct) if distinct else np.zeros((0, 2))
    # Their edges' outward unit normals, which the contact stage turns with the body instead
    # of normalising its turned edges every step (a square root and a division each).
    out["vert_normal_local"] = (
        np.concatenate([polygon.edge_normals(v) for v in distinct])
        if distinct
        else np.zeros((0, 2))
    )
    sizes = {
        "n_bodies": n,
        "n_local_verts": n_local,
        "n_worlds": n_worlds,
        "n_probes": n_probe,
        "n_large": len(large_ids),
        "max_verts": int(count.max(initial=3)),
        "n_small": int(small.sum()),
        # A hash cell is the diameter of the largest small body: two small bodies can only
        # touch if their cells are neighbours.
        "cell_size": 2.0 * float(r_small),
        "large_per_world": int(np.diff(out["world_large_start"]).max(initial=0)),
    }
    return out, sizes


def _worlds(scenes: tuple, coulomb: bool) -> dict[str, np.ndarray]:
    """Per-world columns of the friction law: ``world_mu`` if every world is Coulomb, else
    every world's ``contact_row`` (``friction``), which any law gives."""
    if coulomb:
        return {"world_mu": np.array([s.friction.mu for s in scenes], dtype=float)}
    rows = [s.friction.contact_row() for s in scenes]
    out = {f"world_{k}": np.array([r[k] for r in rows], dtype=float) for k in rows[0]}
    for k in ("memory", "rest_rule"):
        out[f"world_{k}"] = out[f"world_{k}"].astype(np.int32)
    return out


def _contact_values(scenes: tuple) -> dict[str, np.ndarray]:
    """Per-world values of the contact law (``[ice]``) and the runaway distance: model data,
    not compiled in, so worlds of a batch may differ in them."""
    ice = [s.ice for s in scenes]
    return {
        "world_contact_stiffness": np.array([i.contact_stiffness for i in ice], dtype=float),
        "world_contact_viscosity": np.array([i.contact_viscosity for i in ice], dtype=float),
        "world_tangential_stiffness": np.array([i.tangential_stiffness for i in ice], dtype=float),
        "world_tangential_damping": np.array([i.tangential_damping for i in ice], dtype=float),
        "world_slide_resolution": np.array([i.slide_resolution for i in ice], dtype=float),
        "world_crushing_force": np.array(
            [(i.crushing_strength or 0.0) * i.thickness for i in ice], dtype=float
        ),
        "world_runaway_step": np.array([_runaway_step(s) for s in scenes], dtype=float),
    }


def _runaway_step(scene) -> float:
    """m: RUNAWAY_STEP_FRACTION of the scene's thinnest dynamic body's width, the most a
    dynamic body may move in one step (the kernel compares it with ``|v| dt``, dt read at
    run time); inf for a scene with no dynamic body."""
    thinnest = math.inf
    for b in scene.bodies:
        if b.kind == BodyKind.DYNAMIC.label:
            thinnest = min(thinnest, polygon.min_width(b.vertices))
    if not math.isfinite(thinnest):
        return math.inf
    return RUNAWAY_STEP_FRACTION * thinnest


__all__ = [
    "MAX_VERTS_LIMIT",
    "RUNAWAY_STEP_FRACTION",
    "Batch",
    "assemble",
    "hash_size_for",
]
