"""A batch of independent worlds and its step: the algorithm, stage by stage.

    step():  hash.build()          broad phase: bucket every small body by its cell
             contacts.compute()    narrow phase, contact forces, contact memory
             integrator.advance()  forces -> velocities -> positions, work and drag

Three kernel launches per step, whatever the number of worlds or bodies.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from . import backend, geometry
from .broadphase import SpatialHash, hash_size_for
from .contact import ContactStage
from .drag import drag_coefficients
from .energy import EnergyMeter
from .errors import CapacityError, DivergenceError, StabilityError
from .integrate import Integrator
from .state import (
    KIND_DYNAMIC,
    KIND_NAMES,
    STATUS_NONFINITE,
    STATUS_RUNAWAY,
    STATUS_SLOT_OVERFLOW,
    Data,
    HostArrays,
    Layout,
    Model,
    upload,
)

# Contact slots per body beyond the large bodies of its world. A convex block in a dense
# packing touches at most about eight others and owns at most all of them.
DEFAULT_SMALL_SLOTS = 10

# A dynamic body that moves more than this fraction of its thinnest dimension in one step
# has left the regime where contacts can be resolved (it would pass a quarter of the way
# through a neighbour before the contact is seen): the integration has blown up. This is a
# numerical bound, not a physical one: a jam that stores a megajoule and releases it can
# throw a block at tens of m/s, and that is the model's answer, not a divergence. (Energy
# created from nothing is caught by the energy budget in Simulation.run.)
RUNAWAY_STEP_FRACTION = 0.25

# Largest polygon the contact kernel compiles for (its clip buffers are 2 MAXV long).
MAX_VERTS_LIMIT = 16


def _law_kind(law) -> str:
    from .friction import Coulomb, RateState

    if isinstance(law, RateState):
        return "rate-state"
    if isinstance(law, Coulomb):
        return "coulomb"
    raise TypeError(f"friction must be a Coulomb or RateState, got {type(law).__name__}")


class World:
    """Many independent scenes stepped together on one set of Taichi fields.

    Args:
        scenes: the worlds; they must agree on ice properties, water (present or not), and the
            kind of friction law (Coulomb or rate-and-state; parameters may differ).
        dt: time step (s); default the smallest ``scene.dt``.
        precision: 'f64' or 'f32' (Taichi must be started with the same, see backend.init).
        slots: contact slots per body; default sized from the scenes.
        force_dt: accept a dt above the stability limit.
    """

    def __init__(
        self,
        scenes: Sequence,
        dt: float | None = None,
        precision: str = "f64",
        slots: int | None = None,
        force_dt: bool = False,
    ):
        import taichi as ti

        if not scenes:
            raise ValueError("World needs at least one scene")
        self.scenes = list(scenes)
        first = self.scenes[0]
        for s in self.scenes[1:]:
            if s.ice != first.ice:
                raise ValueError("all worlds of a batch must share the [ice] properties")
            if (s.water is None) != (first.water is None) or s.water != first.water:
                raise ValueError("all worlds of a batch must share the [water] table")
            if _law_kind(s.friction) != _law_kind(first.friction):
                raise ValueError("all worlds of a batch must use the same kind of friction law")
        self.precision = precision
        self.real_np = backend.real_dtype(precision)
        self.stable_dt = min(s.stable_dt for s in self.scenes)
        self.dt = float(dt) if dt is not None else min(s.dt for s in self.scenes)
        if not (self.dt > 0 and math.isfinite(self.dt)):
            raise ValueError(f"dt must be a positive number of seconds, got {self.dt}")
        forced = force_dt or all(s.simulation.force_dt for s in self.scenes)
        if self.dt > self.stable_dt and not forced:
            raise StabilityError(
                f"dt = {self.dt:.3g} s is above the contact stability limit "
                f"{self.stable_dt:.3g} s of this scene; use dt = 'auto' "
                f"({first.simulation.dt_safety} x the limit) or force it (force_dt)"
            )

        host, layout_args = self._assemble(slots)
        real = ti.f64 if precision == "f64" else ti.f32
        self.layout = Layout(real=real, **layout_args)
        self.host = host
        self.model = Model(self.layout)
        self.data = Data(self.layout)
        upload(self.model, self.data, host, self.real_np)
        self.data.time_step[None] = self.dt

        ice = first.ice
        # Tangential spring (N/m) and dashpot (N s/m) of each world (see _assemble).
        self.k_t, self.c_t = host.world_tangential[:, 0], host.world_tangential[:, 1]
        params = {
            "k_e": ice.contact_stiffness,
            "k_v": ice.contact_viscosity,
            "method": self._theta_method(),
        }
        self.hash = SpatialHash(self.layout, self.model, self.data)
        self.contacts = ContactStage(self.layout, self.model, self.data, self.hash, params)
        self.integrator = Integrator(self.layout, self.model, self.data, self._runaway_speed())
        self.energy = EnergyMeter(self.layout, self.model, self.data)
        self.cur = 0  # contact buffer holding the memory of the last step
        self.steps = 0
        self.time = 0.0

    # ----------------------------------------------------------------------------------------
    # The step
    # ----------------------------------------------------------------------------------------

    def step(self) -> None:
        """Advance every world by one time step."""
        self.hash.build()
        self.contacts.compute(self.cur)
        self.integrator.advance()
        self.cur = 1 - self.cur
        self.steps += 1
        self.time = self.steps * self.dt

    def check(self) -> None:
        """Raise if a step overflowed the contact slots or diverged (reads back 3 integers)."""
        status = self.data.status.to_numpy()
        if status[STATUS_SLOT_OVERFLOW] > self.layout.slots:
            raise CapacityError(
                f"a body had {status[STATUS_SLOT_OVERFLOW]} contacts at t = {self.time:.4g} s, "
                f"more than its {self.layout.slots} contact slots; pass slots="
                f"{int(status[STATUS_SLOT_OVERFLOW]) + 4} (Simulation/World) to allow more"
            )
        if status[STATUS_NONFINITE]:
            raise DivergenceError(
                f"a body's velocity became non-finite at t = {self.time:.4g} s "
                f"(dt = {self.dt:.3g} s, stability limit {self.stable_dt:.3g} s); the run "
                "diverged: lower dt (or the scene's dt_safety)"
            )
        if status[STATUS_RUNAWAY]:
            raise DivergenceError(
                f"a body moved faster than {self.integrator.runaway_speed:.3g} m/s (a quarter "
                f"of the thinnest block per step) at t = {self.time:.4g} s (dt = {self.dt:.3g} s, "
                f"stability limit {self.stable_dt:.3g} s); the run diverged: lower dt (or the "
                "scene's dt_safety)"
            )

    # ----------------------------------------------------------------------------------------
    # Reading the state
    # ----------------------------------------------------------------------------------------

    def energies(self) -> np.ndarray:
        """``(W, ENERGY_COUNT)`` energy terms of every world now (J); see state.ENERGY_*."""
        self.energy.snapshot(self.cur)
        return self.data.world_energy.to_numpy()[: len(self.scenes)]

    def positions(self) -> np.ndarray:
        """``(N, 2)`` centroids of every body of every world (m)."""
        return self.data.body_pos.to_numpy()[: self.layout.n_bodies].astype(np.float64)

    def angles(self) -> np.ndarray:
        """``(N,)`` angles (rad)."""
        return self.data.body_angle.to_numpy()[: self.layout.n_bodies].astype(np.float64)

    def velocities(self) -> np.ndarray:
        """``(N, 2)`` centroid velocities (m/s)."""
        return self.data.body_vel.to_numpy()[: self.layout.n_bodies].astype(np.float64)

    def omegas(self) -> np.ndarray:
        """``(N,)`` angular velocities (rad/s)."""
        return self.data.body_omega.to_numpy()[: self.layout.n_bodies].astype(np.float64)

    def take_probe_impulses(self) -> np.ndarray:
        """``(P, 2)`` contact impulse on each probe since the last call (N s); resets them."""
        impulse = self.data.probe_impulse.to_numpy()[: self.layout.n_probes]
        self.data.probe_impulse.fill(0.0)
        return impulse

    def contact_counts(self) -> np.ndarray:
        """``(W,)`` number of contacts in each world after the last step."""
        counts = self.data.contact_count.to_numpy()[self.cur, : self.layout.n_bodies]
        return np.bincount(self.host.body_world, weights=counts, minlength=len(self.scenes)).astype(
            np.int64
        )

    def world_slices(self) -> list[slice]:
        """Body index range of each world."""
        s = self.host.world_body_start
        return [slice(int(s[w]), int(s[w + 1])) for w in range(len(self.scenes))]

    def probe_slices(self) -> list[slice]:
        """Probe index range of each world."""
        counts = [len(sc.probe_indices) for sc in self.scenes]
        start = np.concatenate([[0], np.cumsum(counts)])
        return [slice(int(start[w]), int(start[w + 1])) for w in range(len(self.scenes))]

    # ----------------------------------------------------------------------------------------
    # Set-up
    # ----------------------------------------------------------------------------------------

    def _theta_method(self) -> int:
        from .friction import METHOD_EXPONENTIAL, RateState, method_code

        law = self.scenes[0].friction
        return method_code(law.method) if isinstance(law, RateState) else METHOD_EXPONENTIAL

    @staticmethod
    def _characteristic_width(scene) -> float:
        """Longest edge of any dynamic body of a scene (m): the widest contact, which sets the
        tangential stiffness. Per world, so that a world runs the same alone or in a batch."""
        width = 0.0
        for b in scene.bodies:
            if b.kind == "dynamic":
                width = max(width, geometry.longest_edge(b.vertices))
        return width if width > 0 else 1.0

    def _runaway_speed(self) -> float:
        """m/s: RUNAWAY_STEP_FRACTION of the thinnest dynamic body's width per step."""
        thinnest = math.inf
        for s in self.scenes:
            for b in s.bodies:
                if b.kind == "dynamic":
                    thinnest = min(thinnest, geometry.min_width(b.vertices))
        if not math.isfinite(thinnest):
            return math.inf
        return RUNAWAY_STEP_FRACTION * thinnest / self.dt

    def _assemble(self, slots: int | None) -> tuple[HostArrays, dict]:
        """Concatenate every world's bodies (world-major) into the NumPy side of the batch."""
        from .friction import RateState

        cols: dict[str, list] = {
            k: []
            for k in (
                "world",
                "kind",
                "mass",
                "inertia",
                "radius",
                "count",
                "force",
                "drag",
                "probe",
                "pos",
                "angle",
                "vel",
                "omega",
            )
        }
        verts: list[np.ndarray] = []
        mu = np.zeros(len(self.scenes))
        rate_state = np.zeros((len(self.scenes), 5))
        tangential = np.zeros((len(self.scenes), 2))
        n_probe = 0
        for w, s in enumerate(self.scenes):
            if isinstance(s.friction, RateState):
                rate_state[w] = s.friction.params
            else:
                mu[w] = s.friction.mu
            width = self._characteristic_width(s)
            ratio = s.ice.tangential_stiffness
            tangential[w] = (
                ratio * s.ice.contact_stiffness * width,
                ratio * s.ice.contact_viscosity * width,
            )
            masses, inertias = s.masses, s.inertias
            for i, b in enumerate(s.bodies):
                v = np.asarray(b.vertices, dtype=np.float64)
                cols["world"].append(w)
                cols["kind"].append(KIND_NAMES[b.kind])
                cols["mass"].append(masses[i])
                cols["inertia"].append(inertias[i])
                cols["radius"].append(float(np.max(np.hypot(v[:, 0], v[:, 1]))))
                cols["count"].append(len(v))
                cols["force"].append(b.force)
                if s.water is not None:
                    area = masses[i] / (s.ice.density * s.ice.thickness)
                    cols["drag"].append(
                        drag_coefficients(
                            area,
                            s.ice.thickness,
                            s.ice.density,
                            s.water.density,
                            s.water.form_drag,
                            s.water.skin_drag,
                        )
                    )
                else:
                    cols["drag"].append((0.0, 0.0))
                cols["probe"].append(n_probe if b.probe else -1)
                n_probe += int(b.probe)
                cols["pos"].append(b.position)
                cols["angle"].append(b.angle)
                cols["vel"].append(b.velocity)
                cols["omega"].append(b.omega)
                verts.append(v)

        kind = np.array(cols["kind"], dtype=np.int32)
        world = np.array(cols["world"], dtype=np.int32)
        radius = np.array(cols["radius"])
        count = np.array(cols["count"], dtype=np.int32)
        n = len(kind)
        if count.max(initial=0) > MAX_VERTS_LIMIT:
            raise ValueError(f"polygons have at most {MAX_VERTS_LIMIT} vertices in the kernels")
        dynamic = kind == KIND_DYNAMIC
        r_small = radius[dynamic].max() if dynamic.any() else radius.max(initial=1.0)
        small = radius <= r_small * (1.0 + 1e-9)
        large_ids = np.flatnonzero(~small).astype(np.int32)
        n_worlds = len(self.scenes)
        world_large_start = np.searchsorted(world[large_ids], np.arange(n_worlds + 1)).astype(
            np.int32
        )
        world_body_start = np.searchsorted(world, np.arange(n_worlds + 1)).astype(np.int32)
        large_per_world = np.diff(world_large_start).max(initial=0)
        vert_start = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int32) if n else count

        host = HostArrays(
            body_world=world,
            body_kind=kind,
            body_small=small.astype(np.int32),
            body_mass=np.array(cols["mass"]),
            body_inertia=np.array(cols["inertia"]),
            body_radius=radius,
            body_vert_start=vert_start,
            body_vert_count=count,
            body_force_ext=np.array(cols["force"]).reshape(n, 2),
            body_drag=np.array(cols["drag"]).reshape(n, 2),
            body_probe=np.array(cols["probe"], dtype=np.int32),
            vert_local=np.concatenate(verts) if verts else np.zeros((0, 2)),
            world_mu=mu,
            world_rate_state=rate_state,
            world_tangential=tangential,
            world_body_start=world_body_start,
            large_ids=large_ids,
            world_large_start=world_large_start,
            body_pos=np.array(cols["pos"]).reshape(n, 2),
            body_angle=np.array(cols["angle"]),
            body_vel=np.array(cols["vel"]).reshape(n, 2),
            body_omega=np.array(cols["omega"]),
        )
        n_small = int(small.sum())
        layout = dict(
            n_bodies=n,
            n_verts=int(count.sum()),
            n_worlds=n_worlds,
            n_probes=n_probe,
            slots=int(slots) if slots else DEFAULT_SMALL_SLOTS + int(large_per_world),
            max_verts=int(count.max(initial=3)),
            hash_size=hash_size_for(n_small),
            cell_size=2.0 * float(r_small),
            n_small=n_small,
            n_large=len(large_ids),
            rate_state=_law_kind(self.scenes[0].friction) == "rate-state",
            water=self.scenes[0].water is not None,
        )
        return host, layout


__all__ = ["World"]
