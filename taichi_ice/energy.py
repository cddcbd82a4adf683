"""Energy budget of every world: snapshots of kinetic and elastic energy, sums of the rest.

    work_in = kinetic + elastic + friction + viscous + drag + residual

``work_in`` is the work of kinematic bodies and external forces; ``friction`` the slip work
of contacts (the paper's Figure 6), ``viscous`` the contact dashpots, ``drag`` the water;
``elastic`` what the overlaps (``integral k_e A v_n dt``) and the tangential springs
(``k_t xi^2 / 2``) hold now. The residual is the discretisation error of the explicit step
and shrinks with dt. Each world is summed by one thread in body order, so the sums are
reproducible.
"""

# No "from __future__ import annotations": Taichi reads kernel annotations as objects.

import taichi as ti

from .state import (
    BODY_DRAG,
    BODY_FRICTION,
    BODY_VISCOUS,
    BODY_WORK,
    ENERGY_DRAG,
    ENERGY_ELASTIC,
    ENERGY_FRICTION,
    ENERGY_KINETIC,
    ENERGY_VISCOUS,
    ENERGY_WORK_IN,
    KIND_DYNAMIC,
    Data,
    Layout,
    Model,
)


@ti.data_oriented
class EnergyMeter:
    """Fills ``data.world_energy`` on demand (at output times, not every step)."""

    def __init__(self, layout: Layout, model: Model, data: Data):
        self.layout, self.model, self.data = layout, model, data

    @ti.kernel
    def snapshot(self, cur: ti.i32):
        """Energy terms of every world from the state after a step (contact buffer cur)."""
        m, d = ti.static((self.model, self.data))
        for w in range(self.layout.n_worlds):
            kinetic = ti.cast(0.0, ti.f64)
            elastic = ti.cast(0.0, ti.f64)
            friction = ti.cast(0.0, ti.f64)
            viscous = ti.cast(0.0, ti.f64)
            drag = ti.cast(0.0, ti.f64)
            work = ti.cast(0.0, ti.f64)
            k_t = ti.cast(m.world_tangential[w, 0], ti.f64)
            for i in range(m.world_body_start[w], m.world_body_start[w + 1]):
                if m.body_kind[i] == KIND_DYNAMIC:
                    kinetic += 0.5 * ti.cast(
                        m.body_mass[i] * d.body_vel[i].norm_sqr()
                        + m.body_inertia[i] * d.body_omega[i] ** 2,
                        ti.f64,
                    )
                for s in range(d.contact_count[cur, i]):
                    xi = ti.cast(d.contact_xi[cur, i, s], ti.f64)
                    elastic += ti.cast(d.contact_elastic[cur, i, s], ti.f64) + 0.5 * k_t * xi * xi
                friction += d.body_energy[i, BODY_FRICTION]
                viscous += d.body_energy[i, BODY_VISCOUS]
                drag += d.body_energy[i, BODY_DRAG]
                work += d.body_energy[i, BODY_WORK]
            d.world_energy[w, ENERGY_KINETIC] = kinetic
            d.world_energy[w, ENERGY_ELASTIC] = elastic
            d.world_energy[w, ENERGY_FRICTION] = friction
            d.world_energy[w, ENERGY_VISCOUS] = viscous
            d.world_energy[w, ENERGY_DRAG] = drag
            d.world_energy[w, ENERGY_WORK_IN] = work
