"""The energy stage: every world's energy table, from the per-body and per-contact terms.

    work_in = kinetic + elastic + friction + viscous + drag + crushing + residual   (``budget``)

``work_in`` is the work of kinematic bodies and external forces; ``friction`` the slip work
of contacts (the paper's Figure 6), ``viscous`` the contact dashpots, ``drag`` the water;
``crushing`` the work on overlap beyond the ice's strength; ``elastic`` what the contacts
hold now: the work of their elastic forces, normal (``integral k_e A v_n dt``) and
tangential (the spring's ``k_t xi^2 / 2`` at each step's stiffness), summed step by step.
The residual is the discretisation error of the explicit step and shrinks with dt. Each
world is summed by one thread in body order, so the sums are reproducible.
"""

# No "from __future__ import annotations": Taichi reads kernel annotations as objects.

from typing import ClassVar

import taichi as ti

from .codes import BodyEnergy, BodyKind, EnergyTerm
from .schema import Access, Layout, Stage
from .state import Data, Model


@ti.data_oriented
class EnergyMeter(Stage):
    """Fills ``data.world_energy`` on demand (at output times, not every step)."""

    ACCESS: ClassVar[dict] = {
        "snapshot": Access(
            reads=(
                "world_body_start",
                "body_kind",
                "body_mass",
                "body_inertia",
                "body_vel",
                "body_omega",
                "contact_count",
                "contact_elastic",
                "body_energy",
            ),
            writes=("world_energy",),
        )
    }

    def __init__(self, layout: Layout, model: Model, data: Data):
        self.layout, self.model, self.data = layout, model, data

    @ti.kernel
    def snapshot(self):
        """Energy terms of every world from the state after a step."""
        m, d = ti.static((self.model, self.data))
        for w in range(self.layout.n_worlds):
            kinetic = ti.cast(0.0, ti.f64)
            elastic = ti.cast(0.0, ti.f64)
            friction = ti.cast(0.0, ti.f64)
            viscous = ti.cast(0.0, ti.f64)
            drag = ti.cast(0.0, ti.f64)
            work = ti.cast(0.0, ti.f64)
            crushing = ti.cast(0.0, ti.f64)
            for i in range(m.world_body_start[w], m.world_body_start[w + 1]):
                if m.body_kind[i] == BodyKind.DYNAMIC:
                    kinetic += 0.5 * ti.cast(
                        m.body_mass[i] * d.body_vel[i].norm_sqr()
                        + m.body_inertia[i] * d.body_omega[i] ** 2,
                        ti.f64,
                    )
                for s in range(d.contact_count[i]):
                    elastic += ti.cast(d.contact_elastic[i, s], ti.f64)
                friction += d.body_energy[i, BodyEnergy.FRICTION]
                viscous += d.body_energy[i, BodyEnergy.VISCOUS]
                drag += d.body_energy[i, BodyEnergy.DRAG]
                work += d.body_energy[i, BodyEnergy.WORK]
                crushing += d.body_energy[i, BodyEnergy.CRUSHING]
            d.world_energy[w, EnergyTerm.KINETIC] = kinetic
            d.world_energy[w, EnergyTerm.ELASTIC] = elastic
            d.world_energy[w, EnergyTerm.FRICTION] = friction
            d.world_energy[w, EnergyTerm.VISCOUS] = viscous
            d.world_energy[w, EnergyTerm.DRAG] = drag
            d.world_energy[w, EnergyTerm.WORK_IN] = work
            d.world_energy[w, EnergyTerm.CRUSHING] = crushing
