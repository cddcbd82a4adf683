"""A batch of independent worlds and its step: the algorithm, stage by stage.

    step():  hash.build()          broad phase: bucket every small body by its cell
             contacts.compute()    narrow phase, contact forces, contact memory
             integrator.advance()  forces -> velocities -> positions, work and drag

Three kernel launches per step, whatever the number of worlds or bodies.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from . import backend, state
from .assemble import assemble
from .broadphase import SpatialHash
from .codes import Status
from .contact import ContactStage
from .energy import EnergyMeter
from .errors import CapacityError, DivergenceError
from .integrate import Integrator

# The stages of a step, by the name their kernels are reported under (benchmarks, traffic).
STAGES = {
    "hash": SpatialHash,
    "contacts": ContactStage,
    "integrator": Integrator,
    "energy": EnergyMeter,
}


class World:
    """Many independent scenes stepped together on one set of Taichi fields.

    Args:
        scenes: the worlds; what they must share is checked by ``assemble.assemble``.
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
        backend.real_dtype(precision)
        self.batch = assemble(scenes, dt=dt, precision=precision, slots=slots, force_dt=force_dt)
        self.scenes = list(self.batch.scenes)
        self.layout, self.host = self.batch.layout, self.batch.host
        self.dt, self.stable_dt = self.batch.dt, self.batch.stable_dt
        self.precision = precision
        self.model = state.Model(self.layout)
        self.data = state.Data(self.layout)
        state.upload(self.model, self.data, self.host)
        self.data.time_step[None] = self.dt

        self.hash = SpatialHash(self.layout, self.model, self.data)
        self.contacts = ContactStage(self.layout, self.model, self.data, self.hash)
        self.integrator = Integrator(self.layout, self.model, self.data)
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
        if status[Status.SLOT_OVERFLOW] > self.layout.slots:
            raise CapacityError(
                f"a body had {status[Status.SLOT_OVERFLOW]} contacts at t = {self.time:.4g} s, "
                f"more than its {self.layout.slots} contact slots; pass slots="
                f"{int(status[Status.SLOT_OVERFLOW]) + 4} (Simulation/World) to allow more"
            )
        if status[Status.NONFINITE]:
            raise DivergenceError(
                f"a body's velocity became non-finite at t = {self.time:.4g} s "
                f"(dt = {self.dt:.3g} s, stability limit {self.stable_dt:.3g} s); the run "
                "diverged: lower dt (or the scene's dt_safety)"
            )
        if status[Status.RUNAWAY]:
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
        """``(W, E)`` energy table of every world now (J), ``codes.EnergyTerm`` columns."""
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
        return self.batch.world_slices()

    def probe_slices(self) -> list[slice]:
        """Probe index range of each world."""
        return self.batch.probe_slices()


__all__ = ["STAGES", "World"]
