"""The energy stage: every world's energy table, from the per-body and per-contact terms.

    work_in + wind + current + tilt
        = kinetic + elastic + friction + viscous + drag + crushing + severed + residual

(``budget``). ``work_in`` is the work of kinematic bodies and external forces; ``wind``,
``current`` and ``tilt`` that of the forcing (0 without it); ``friction`` the slip work
of contacts (the paper's Figure 6), ``viscous`` the contact dashpots, ``drag`` the water;
``crushing`` the work on overlap beyond the ice's strength; ``elastic`` what the contacts
hold now: the work of their elastic forces, normal (``integral k_e A v_n dt``) and
tangential (the spring's ``k_t xi^2 / 2`` at each step's stiffness), summed step by step.
The residual is the discretisation error of the explicit step and shrinks with dt. Each
world is summed by one thread in body order, so the sums are reproducible.

A sample of the time series (``sample``) is one row per world, ``SAMPLE_COLUMNS`` wide: the
energy table, the world's contact count and its status word, taken with the probes'
impulses since the last sample in the same pass, so that a run's sample costs one kernel
launch (``take``), or none when the worlds are stepped a thread each (the stepper samples
between its steps, ``WorldStepper.run``).
"""

# No "from __future__ import annotations": Taichi reads kernel annotations as objects.

from typing import ClassVar

import taichi as ti

from ..codes import BodyEnergy, BodyKind, EnergyTerm, Status
from .schema import Layout
from .stages import Access, Stage
from .state import Data, Model

# Columns of a sample row: the energy table (EnergyTerm), the contact count, the status word.
N_TERMS, N_STATUS = len(EnergyTerm), len(Status)
CONTACTS_COLUMN = N_TERMS
STATUS_COLUMN = CONTACTS_COLUMN + 1
SAMPLE_COLUMNS = STATUS_COLUMN + N_STATUS


@ti.data_oriented
class EnergyMeter(Stage):
    """Energy tables and time-series samples of every world, on demand (at output times,
    not every step)."""

    _TERMS = (
        "world_body_start",
        "body_kind",
        "body_mass",
        "body_inertia",
        "body_vel",
        "body_omega",
        "contact_count",
        "contact_elastic",
        "body_energy",
    )
    ACCESS: ClassVar[dict] = {
        "snapshot": Access(reads=_TERMS, writes=("world_energy",)),
        "take": Access(
            reads=(*_TERMS, "body_probe", "probe_impulse", "status"), writes=("probe_impulse",)
        ),
    }

    def __init__(self, layout: Layout, model: Model, data: Data):
        self.layout, self.model, self.data = layout, model, data

    @ti.func
    def terms(self, w):
        """World w's energy table (J), ``EnergyTerm`` order, and its contact count."""
        m, d = ti.static((self.model, self.data))
        row = ti.Vector.zero(ti.f64, N_TERMS)
        contacts = 0
        for i in range(m.world_body_start[w], m.world_body_start[w + 1]):
            if m.body_kind[i] == BodyKind.DYNAMIC:
                row[EnergyTerm.KINETIC] += 0.5 * ti.cast(
                    m.body_mass[i] * d.body_vel[i].norm_sqr()
                    + m.body_inertia[i] * d.body_omega[i] ** 2,
                    ti.f64,
                )
            n = d.contact_count[i]
            contacts += n
            if ti.static(self.layout.energy):
                for s in range(n):
                    row[EnergyTerm.ELASTIC] += ti.cast(d.contact_elastic[i, s], ti.f64)
                row[EnergyTerm.FRICTION] += d.body_energy[i, BodyEnergy.FRICTION]
                row[EnergyTerm.VISCOUS] += d.body_energy[i, BodyEnergy.VISCOUS]
                row[EnergyTerm.DRAG] += d.body_energy[i, BodyEnergy.DRAG]
                row[EnergyTerm.WORK_IN] += d.body_energy[i, BodyEnergy.WORK]
                row[EnergyTerm.CRUSHING] += d.body_energy[i, BodyEnergy.CRUSHING]
                row[EnergyTerm.SEVERED] += d.body_energy[i, BodyEnergy.SEVERED]
                if ti.static(self.layout.wind):
                    row[EnergyTerm.WIND] += d.body_energy[i, BodyEnergy.WIND]
                if ti.static(self.layout.current):
                    row[EnergyTerm.CURRENT] += d.body_energy[i, BodyEnergy.CURRENT]
                if ti.static(self.layout.tilt):
                    row[EnergyTerm.TILT] += d.body_energy[i, BodyEnergy.TILT]
        if ti.static(not self.layout.energy):  # no budget kept: only the kinetic term known
            for k in ti.static(range(N_TERMS)):
                if ti.static(k != EnergyTerm.KINETIC):
                    row[k] = ti.math.nan
        return row, contacts

    @ti.kernel
    def snapshot(self):
        """Energy terms of every world from the state after a step (``world_energy``)."""
        for w in range(self.layout.n_worlds):
            row, _n = self.terms(w)
            if ti.static(self.layout.energy):
                for k in ti.static(range(N_TERMS)):
                    self.data.world_energy[w, k] = row[k]

    @ti.func
    def sample(self, w, s, rows: ti.template(), impulses: ti.template(), record):
        """World w's sample into ``rows[s, w, :]`` (energy table, contact count, status) and
        its probes' impulses into ``impulses[s, p, :]``; ``record``: the impulses restart
        from zero (a sample of the series), else they go on adding up (a check only)."""
        m, d = ti.static((self.model, self.data))
        row, contacts = self.terms(w)
        for k in ti.static(range(N_TERMS)):
            rows[s, w, k] = row[k]
        rows[s, w, CONTACTS_COLUMN] = ti.cast(contacts, ti.f64)
        for k in ti.static(range(N_STATUS)):
            rows[s, w, STATUS_COLUMN + k] = ti.cast(d.status[w, k], ti.f64)
        for i in range(m.world_body_start[w], m.world_body_start[w + 1]):
            p = m.body_probe[i]
            if p >= 0:
                impulses[s, p, 0] = d.probe_impulse[p][0]
                impulses[s, p, 1] = d.probe_impulse[p][1]
                if record:
                    d.probe_impulse[p] = ti.Vector([0.0, 0.0], ti.f64)

    @ti.kernel
    def take(
        self,
        rows: ti.types.ndarray(dtype=ti.f64, ndim=3),
        impulses: ti.types.ndarray(dtype=ti.f64, ndim=3),
        s: ti.i32,
        record: ti.i32,
    ):
        """Sample ``s`` of every world now (see ``sample``)."""
        for w in range(self.layout.n_worlds):
            self.sample(w, s, rows, impulses, record)
