"""NumPy twin of a whole step: slow, plain loops, for tiny scenes.

The kernels (``contact.ContactStage``, ``integrate.Integrator``, ``energy.EnergyMeter``) are
held against this module in the tests. It writes the same algorithm one pair and one body at
a time, in float64, from the same equations:

- ``reference_contact.contact_force``: one pair, owner ``i`` and partner ``j`` (its own
  module, with what a contact carries from step to step, ``ContactMemory``).
- :func:`reference_step`: every owned pair of every world, forces gathered in the same
  fixed point as the kernels (``schema.FORCE_QUANTUM``, truncated toward zero), then
  semi-implicit Euler with water drag (``drag.water_drag``), external forces and the
  forcing (current, wind, Coriolis and tilt: ``forcing``); fixed bodies stay, kinematic ones
  move at their velocity. Contact memory (``xi``, last area,
  stored elastic energy, ``theta``) is a dict keyed by the ordered pair ``(owner, partner)``
  and dropped when the pair no longer overlaps.
- :func:`reference_energies`: the energy terms of each world, as ``World.energies``.

Pairs are found by testing every pair of a world (no spatial hash), so the cost is quadratic:
a few bodies and tens of steps. The model is read from the same assembled arrays the kernels
upload (``assemble.Batch``), so a parameter is derived once for both. NumPy only: importing
it starts no Taichi.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..codes import BodyEnergy, BodyKind, EnergyTerm, ThetaMethod
from ..physics.drag import water_drag
from ..physics.forcing import air_drag, coriolis_step, grid_sample, tilt_acceleration
from ..physics.friction import CONTACT_ROW
from ..physics.slip import NEWTON_TOLERANCE
from .assemble import Batch, assemble
from .reference_contact import ContactMemory, contact_force, settle
from .schema import FORCE_QUANTUM

__all__ = [
    "ReferenceModel",
    "ReferenceState",
    "outline",
    "owns",
    "reference_energies",
    "reference_step",
]


# --------------------------------------------------------------------------------------------
# A whole step
# --------------------------------------------------------------------------------------------


class _Row(dict):
    """A world's rate-and-state model columns, read back as ``contact_row`` gives them."""

    def contact_row(self) -> dict:
        return self


@dataclass(frozen=True)
class ReferenceModel:
    """Static data of a batch of worlds, read from its assembled arrays (bodies world-major).

    Attributes:
        kind: ``(N,)`` ``codes.BodyKind``. world: ``(N,)`` world index.
        mass: ``(N,)`` kg. inertia: ``(N,)`` kg m^2. vertices: N outlines ``(n, 2)``
            relative to the centroid, unrotated (m). force_ext: ``(N, 2)`` N.
        drag: ``(N, 2)`` water drag coefficients (kg/m, kg m^2), zeros without [water].
        laws: the friction of each world, rebuilt from its model columns: a Coulomb mu
            (float) when every world is Coulomb, else a world's rate-and-state columns.
        k_e (N/m^2), k_v (Pa s): normal contact parameters, ``(W,)`` one per world. ratio:
            tangential to normal stiffness, ``(W,)``. zeta: the tangential dashpot's
            fraction of critical damping, ``(W,)``. slide_resolution: ``(W,)`` the sub-steps
            of a sliding rate-and-state contact (``[ice] slide_resolution``), or None (0).
        method: ``codes.ThetaMethod`` for theta (one per batch).
        crushing_force: ``(W,)`` strength x thickness (N/m), or None.
        tol: Newton's tolerance of the sliding rate.
        quantum: force resolution of the gather (N); None sums in floating point.
        integrator: "euler", "analytic", "coupled" or "midstep" (``options.INTEGRATORS``).
        current, wind: ``(W, 2)`` uniform current and wind (m/s), or None.
        current_grid, wind_grid: ``(values, origin, spacing)`` of a gridded one
            (``forcing.grid_sample``), or None.
        c_air: ``(N,)`` wind drag coefficients (kg/m), or None without wind.
        coriolis: ``(W,)`` Coriolis parameters (1/s), or None. tilt: the current is
            geostrophic (its sea-surface tilt pushes the floes).
    """

    kind: np.ndarray
    world: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    vertices: tuple[np.ndarray, ...]
    force_ext: np.ndarray
    drag: np.ndarray
    laws: tuple
    k_e: np.ndarray
    k_v: np.ndarray
    ratio: np.ndarray
    zeta: np.ndarray
    slide_resolution: np.ndarray | None = None
    method: int = ThetaMethod.EXPONENTIAL
    quantum: float | None = FORCE_QUANTUM
    crushing_force: np.ndarray | None = None
    tol: float = NEWTON_TOLERANCE["f64"]
    integrator: str = "euler"
    current: np.ndarray | None = None
    current_grid: tuple | None = None
    wind: np.ndarray | None = None
    wind_grid: tuple | None = None
    c_air: np.ndarray | None = None
    coriolis: np.ndarray | None = None
    tilt: bool = False

    @property
    def n_bodies(self) -> int:
        return len(self.kind)

    @property
    def analytic(self) -> bool:
        """Contacts solved over the step, apart or together (``schema.Layout.analytic``)."""
        return self.integrator in ("analytic", "coupled", "midstep")

    @property
    def midstep(self) -> bool:
        """Each contact linearised about the configuration predicted for mid-step
        (``reference_contact.contact_force``'s ``mid``; ``schema.Layout.midstep``)."""
        return self.integrator == "midstep"

    def current_at(self, i: int, pos, t: float) -> np.ndarray:
        """The current at body i's centroid ``pos`` at time ``t`` (m/s)."""
        return _field_at(self.current, self.current_grid, int(self.world[i]), pos, t)

    def wind_at(self, i: int, pos, t: float) -> np.ndarray:
        """The wind at body i's centroid ``pos`` at time ``t`` (m/s)."""
        return _field_at(self.wind, self.wind_grid, int(self.world[i]), pos, t)

    def inv_mass(self, i: int) -> float:
        """``1 / m`` of body i (1/kg), 0 unless it is dynamic."""
        return 1.0 / float(self.mass[i]) if self.kind[i] == BodyKind.DYNAMIC else 0.0

    def inv_inertia(self, i: int) -> float:
        """``1 / I`` of body i (1/(kg m^2)), 0 unless it is dynamic."""
        return 1.0 / float(self.inertia[i]) if self.kind[i] == BodyKind.DYNAMIC else 0.0

    def pair(self, i: int, j: int) -> dict:
        """What ``reference_contact.contact_force`` takes from the model for the pair of
        owner ``i`` and partner ``j`` (the world's contact law and values, the two bodies'
        inverse mass and inertia, the integrator), as keywords."""
        w = int(self.world[i])
        return {
            "k_e": float(self.k_e[w]),
            "k_v": float(self.k_v[w]),
            "ratio": float(self.ratio[w]),
            "law": self.laws[w],
            "inv_mass": (self.inv_mass(i), self.inv_mass(j)),
            "inv_inertia": (self.inv_inertia(i), self.inv_inertia(j)),
            "zeta": float(self.zeta[w]),
            "slide_resolution": 0.0
            if self.slide_resolution is None
            else float(self.slide_resolution[w]),
            "method": self.method,
            "crushing_force": None
            if self.crushing_force is None
            else float(self.crushing_force[w]),
            "tol": self.tol,
            "analytic": self.analytic,
            "coupled": self.integrator in ("coupled", "midstep"),
        }

    @classmethod
    def from_batch(cls, batch: Batch, quantum: float | None = FORCE_QUANTUM):
        """The model of the batch a ``World`` uploads: the same arrays, nothing re-derived."""
        host, layout = batch.host, batch.real  # the scenes' counts, as host's arrays
        start, count = host.body_local_start, host.body_vert_count
        if layout.coulomb:
            laws = tuple(float(mu) for mu in host.world_mu)
        else:
            laws = tuple(
                _Row({k: host[f"world_{k}"][w].item() for k in CONTACT_ROW})
                for w in range(layout.n_worlds)
            )
        return cls(
            kind=host.body_kind,
            world=host.body_world,
            mass=host.body_mass,
            inertia=host.body_inertia,
            vertices=tuple(host.vert_local[a : a + n] for a, n in zip(start, count)),
            force_ext=host.body_force_ext,
            drag=np.stack([host.body_drag_linear, host.body_drag_rotational], axis=1),
            laws=laws,
            k_e=host.world_contact_stiffness,
            k_v=host.world_contact_viscosity,
            ratio=host.world_tangential_stiffness,
            zeta=host.world_tangential_damping,
            slide_resolution=host.world_slide_resolution,
            method=layout.theta_method,
            quantum=quantum,
            crushing_force=host.world_crushing_force if layout.crushing else None,
            tol=NEWTON_TOLERANCE[layout.precision],
            integrator=layout.integrator,
            current=host.world_current if layout.current_uniform else None,
            current_grid=_grid(host, 0) if layout.current_grid else None,
            wind=host.world_wind if layout.wind_uniform else None,
            wind_grid=_grid(host, 1) if layout.wind_grid else None,
            c_air=host.body_drag_air if layout.wind else None,
            coriolis=host.world_coriolis if layout.coriolis else None,
            tilt=layout.tilt,
        )

    @classmethod
    def from_scenes(cls, scenes: Sequence, quantum: float | None = FORCE_QUANTUM):
        """The model of ``World(scenes)`` (``assemble`` then :meth:`from_batch`)."""
        return cls.from_batch(assemble(scenes), quantum)


def _grid(host, row: int) -> tuple:
    """``(values (nt, ny, nx, 2), origin, spacing)`` of row ``row`` of the batch's grids."""
    nx, ny, nt, start = (int(n) for n in host.grid_size[row])
    values = host.grid_values[start : start + nt * ny * nx].reshape(nt, ny, nx, 2)
    return values, host.grid_origin[row], host.grid_spacing[row]


def _field_at(uniform, grid, w: int, pos, t: float) -> np.ndarray:
    if grid is not None:
        return grid_sample(*grid, float(pos[0]), float(pos[1]), t)
    if uniform is not None:
        return np.asarray(uniform[w], dtype=np.float64)
    return np.zeros(2)


@dataclass
class ReferenceState:
    """Mutable state of a batch: bodies, contact memory and cumulative energy terms.

    Attributes:
        pos: ``(N, 2)`` m. angle: ``(N,)`` rad. vel: ``(N, 2)`` m/s. omega: ``(N,)`` rad/s.
        contacts: ``{(owner, partner): ContactMemory}`` of the contacts of the last step.
        dvel: ``(N, 2)`` m/s, domega: ``(N,)`` rad/s: each body's velocity change over its
            last step (zero before the first).
        body_energy: ``(N, len(BodyEnergy))`` cumulative terms per body (J),
            ``codes.BodyEnergy`` columns.
        time: s.
    """

    pos: np.ndarray
    angle: np.ndarray
    vel: np.ndarray
    omega: np.ndarray
    contacts: dict[tuple[int, int], ContactMemory] = field(default_factory=dict)
    body_energy: np.ndarray | None = None
    time: float = 0.0
    dvel: np.ndarray | None = None
    domega: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.angle)
        if self.body_energy is None:
            self.body_energy = np.zeros((n, len(BodyEnergy)))
        if self.dvel is None:
            self.dvel = np.zeros((n, 2))
        if self.domega is None:
            self.domega = np.zeros(n)

    @classmethod
    def from_batch(cls, batch: Batch) -> ReferenceState:
        """The initial state of the batch a ``World`` uploads."""
        host = batch.host
        return cls(
            pos=host.body_pos.copy(),
            angle=host.body_angle.copy(),
            vel=host.body_vel.copy(),
            omega=host.body_omega.copy(),
        )

    @classmethod
    def from_scenes(cls, scenes: Sequence) -> ReferenceState:
        """The initial state of ``World(scenes)``."""
        return cls.from_batch(assemble(scenes))

    def copy(self) -> ReferenceState:
        return replace(
            self,
            pos=self.pos.copy(),
            angle=self.angle.copy(),
            vel=self.vel.copy(),
            omega=self.omega.copy(),
            contacts=dict(self.contacts),
            body_energy=self.body_energy.copy(),
            dvel=self.dvel.copy(),
            domega=self.domega.copy(),
        )


def owns(kind: np.ndarray, i: int, j: int) -> bool:
    """True if body i handles the pair (i, j): the dynamic one, or the lower id of two."""
    dyn_i, dyn_j = kind[i] == BodyKind.DYNAMIC, kind[j] == BodyKind.DYNAMIC
    return bool((dyn_i and not dyn_j) or (dyn_i and dyn_j and i < j))


def outline(model: ReferenceModel, state: ReferenceState, i: int, origin=(0.0, 0.0)):
    """``(n, 2)`` outline of body i relative to ``origin`` (m), as ``ContactStage.outline``.

    Same operations in the same order as the kernel: ``(x - origin) + R v``.
    """
    c, s = math.cos(state.angle[i]), math.sin(state.angle[i])
    x = state.pos[i] - np.asarray(origin, dtype=np.float64)
    v = model.vertices[i]
    return np.stack([x[0] + c * v[:, 0] - s * v[:, 1], x[1] + s * v[:, 0] + c * v[:, 1]], axis=1)


def reference_step(state: ReferenceState, model: ReferenceModel, dt: float) -> ReferenceState:
    """One step of every world, as ``World.step`` takes it; returns the new state.

    Contacts: every ordered pair (owner, partner) of a world, in body order, through
    :func:`contact_force`; forces and torques are gathered in fixed point of
    ``model.quantum`` (each contribution truncated toward zero, as the kernel's cast does),
    or in floating point if ``model.quantum`` is None. Then semi-implicit Euler:
    ``v += dt (F + F_ext + F_drag(v)) / m``, ``x += dt v`` (and the angle likewise).
    """
    n = model.n_bodies
    new = state.copy()
    exact = model.quantum is None
    analytic = model.analytic
    force_sum = np.zeros((n, 2)) if exact else [[0, 0] for _ in range(n)]
    torque_sum = np.zeros(n) if exact else [0] * n
    shift_sum = np.zeros((n, 2)) if exact else [[0, 0] for _ in range(n)]
    turn_sum = np.zeros(n) if exact else [0] * n
    scale = None if exact else 1.0 / model.quantum

    def gather(k: int, f: np.ndarray, tau: float, forces=force_sum, torques=torque_sum) -> None:
        if exact:
            forces[k] += f
            torques[k] += tau
        else:
            # float -> int truncates toward zero, like ti.cast(x, ti.i64).
            forces[k][0] += int(f[0] * scale)
            forces[k][1] += int(f[1] * scale)
            torques[k] += int(tau * scale)

    def summed(forces, torques, i: int) -> tuple[np.ndarray, float]:
        if exact:
            return forces[i], float(torques[i])
        f = np.array([float(forces[i][0]), float(forces[i][1])]) * model.quantum
        return f, float(torques[i]) * model.quantum

    contacts: dict[tuple[int, int], ContactMemory] = {}
    bookings: dict[tuple[int, int], tuple] = {}
    # The configuration predicted for mid-step (``model.midstep``): free flight for h/2.
    mid = None
    if analytic and model.midstep:
        mid = state.copy()
        mid.pos = state.pos + 0.5 * dt * state.vel
        mid.angle = state.angle + 0.5 * dt * state.omega
    for i in range(n):
        for j in range(n):
            if i == j or model.world[i] != model.world[j] or not owns(model.kind, i, j):
                continue
            # In the owner's frame, as the kernel clips.
            origin = state.pos[i]
            c = contact_force(
                outline(model, state, i, origin),
                outline(model, state, j, origin),
                np.zeros(2),
                state.vel[i],
                state.omega[i],
                state.pos[j] - origin,
                state.vel[j],
                state.omega[j],
                dt=dt,
                dvel=(state.dvel[i], state.dvel[j]),
                domega=(float(state.domega[i]), float(state.domega[j])),
                memory=state.contacts.get((i, j)),
                mid=None
                if mid is None
                else (
                    outline(model, mid, i, origin),
                    outline(model, mid, j, origin),
                    mid.pos[i] - origin,
                    mid.pos[j] - origin,
                ),
                **model.pair(i, j),
            )
            if c is None:
                continue  # no overlap: the pair's memory is dropped
            gather(j, c.force, c.torque_partner)
            gather(i, -c.force, c.torque_owner)
            if analytic:
                gather(j, c.shift, c.shift_torque_partner, shift_sum, turn_sum)
                gather(i, -c.shift, c.shift_torque_owner, shift_sum, turn_sum)
            new.body_energy[i, BodyEnergy.FRICTION] += c.slip_work
            new.body_energy[i, BodyEnergy.VISCOUS] += c.viscous_work
            new.body_energy[i, BodyEnergy.CRUSHING] += c.crushing_work
            contacts[(i, j)] = c.memory
            if c.booking is not None:
                bookings[(i, j)] = c.booking
    # A contact that ended takes the energy it still held with it.
    for (i, j), mem in state.contacts.items():
        if (i, j) not in contacts:
            new.body_energy[i, BodyEnergy.SEVERED] += mem.elastic
    new.contacts = contacts

    for i in range(n):
        f, tau = summed(force_sum, torque_sum, i)
        if model.kind[i] == BodyKind.DYNAMIC:
            v0, w0 = state.vel[i], float(state.omega[i])
            f_ext = model.force_ext[i]
            f_drag, t_drag = np.zeros(2), 0.0
            vd, wd = v0, w0  # analytic: mid-step, as the others leave it
            if analytic:
                vd = v0 + 0.5 * dt * (1.0 / model.mass[i]) * (f + f_ext)
                wd = w0 + 0.5 * dt * (1.0 / model.inertia[i]) * tau
            u_w = model.current_at(i, state.pos[i], state.time)
            if np.any(model.drag[i] != 0.0):  # a body in [water] (the kernel's test too)
                fd, td = water_drag(
                    (vd - u_w)[None, :], np.array([wd]), model.drag[i, 0:1], model.drag[i, 1:2]
                )
                f_drag, t_drag = fd[0], float(td[0])
            f_all = f + f_ext + f_drag
            f_air = np.zeros(2)
            if model.c_air is not None:
                f_air = air_drag(vd, model.wind_at(i, state.pos[i], state.time), model.c_air[i])
                f_all = f_all + f_air
            v1 = v0 + dt * (1.0 / model.mass[i]) * f_all
            a_tilt, a_cor = np.zeros(2), np.zeros(2)
            if model.coriolis is not None:
                cor = float(model.coriolis[model.world[i]])
                if model.tilt:
                    a_tilt = tilt_acceleration(cor, u_w)
                v1 = coriolis_step(v0, (1.0 / model.mass[i]) * f_all + a_tilt, cor, dt)
                vc = 0.5 * (v0 + v1)
                a_cor = cor * np.array([vc[1], -vc[0]])
            w1 = w0 + dt * (1.0 / model.inertia[i]) * (tau + t_drag)
            shift, turn = dt * v1, dt * w1
            if analytic:
                g, gam = summed(shift_sum, turn_sum, i)
                f_pos = g + f_ext + f_drag + f_air
                shift = dt * v0 + 0.5 * dt * dt * (1.0 / model.mass[i]) * f_pos
                shift = shift + 0.5 * dt * dt * (a_tilt + a_cor)
                turn = dt * w0 + 0.5 * dt * dt * (1.0 / model.inertia[i]) * (gam + t_drag)
            vm, wm = 0.5 * (v0 + v1), 0.5 * (w0 + w1)
            # The drag dissipates on the velocity relative to the water; its power on the
            # current is the current's work (``integrate.Integrator.body``).
            new.body_energy[i, BodyEnergy.DRAG] += -(float(f_drag @ (vm - u_w)) + t_drag * wm) * dt
            new.body_energy[i, BodyEnergy.WORK] += float(f_ext @ vm) * dt
            new.body_energy[i, BodyEnergy.CURRENT] += float(f_drag @ u_w) * dt
            new.body_energy[i, BodyEnergy.WIND] += float(f_air @ vm) * dt
            new.body_energy[i, BodyEnergy.TILT] += float(a_tilt @ vm) * dt / model.inv_mass(i)
            new.dvel[i] = v1 - v0
            new.domega[i] = w1 - w0
            new.vel[i] = v1
            new.omega[i] = w1
            new.pos[i] = state.pos[i] + shift
            new.angle[i] = state.angle[i] + turn
        elif model.kind[i] == BodyKind.KINEMATIC:
            v, w = state.vel[i], float(state.omega[i])
            new.body_energy[i, BodyEnergy.WORK] += -(float(f @ v) + tau * w) * dt
            new.pos[i] = state.pos[i] + dt * v
            new.angle[i] = state.angle[i] + dt * w
    # The analytic steps book their contacts' work again at the change the bodies took
    # (``reference_contact.settle``; the kernel's ``ContactLists.settle``).
    for (i, j), booking in bookings.items():
        held, viscous, friction = settle(
            booking, (new.dvel[i], new.dvel[j]), (float(new.domega[i]), float(new.domega[j]))
        )
        mem = new.contacts[(i, j)]
        new.contacts[(i, j)] = replace(mem, elastic=mem.elastic + held)
        new.body_energy[i, BodyEnergy.FRICTION] += friction
        new.body_energy[i, BodyEnergy.VISCOUS] += viscous
    new.time = state.time + dt
    return new


def reference_energies(state: ReferenceState, model: ReferenceModel) -> np.ndarray:
    """``(W, E)`` energy table of each world (J), ``codes.EnergyTerm`` columns."""
    n_worlds = int(model.world.max()) + 1 if model.n_bodies else 0
    out = np.zeros((n_worlds, len(EnergyTerm)))
    for i in range(model.n_bodies):
        w = model.world[i]
        if model.kind[i] == BodyKind.DYNAMIC:
            out[w, EnergyTerm.KINETIC] += 0.5 * (
                model.mass[i] * float(state.vel[i] @ state.vel[i])
                + model.inertia[i] * state.omega[i] ** 2
            )
        out[w, EnergyTerm.FRICTION] += state.body_energy[i, BodyEnergy.FRICTION]
        out[w, EnergyTerm.VISCOUS] += state.body_energy[i, BodyEnergy.VISCOUS]
        out[w, EnergyTerm.DRAG] += state.body_energy[i, BodyEnergy.DRAG]
        out[w, EnergyTerm.WORK_IN] += state.body_energy[i, BodyEnergy.WORK]
        out[w, EnergyTerm.CRUSHING] += state.body_energy[i, BodyEnergy.CRUSHING]
        out[w, EnergyTerm.SEVERED] += state.body_energy[i, BodyEnergy.SEVERED]
        out[w, EnergyTerm.WIND] += state.body_energy[i, BodyEnergy.WIND]
        out[w, EnergyTerm.CURRENT] += state.body_energy[i, BodyEnergy.CURRENT]
        out[w, EnergyTerm.TILT] += state.body_energy[i, BodyEnergy.TILT]
    for (i, _j), mem in state.contacts.items():
        out[model.world[i], EnergyTerm.ELASTIC] += mem.elastic
    return out
