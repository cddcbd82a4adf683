"""Many steps per kernel launch: each thread steps one world, body by body.

A scene of tens of blocks does less work per step than a kernel launch costs: stepping it
with ``World.step`` (two launches and a dozen offloaded tasks per step) spends most of its
time starting threads. ``WorldStepper.run(plan, ...)`` instead launches once for many steps
(and the samples of the run between them, ``World.advance_sampled``);
its one parallel loop runs over the worlds of the batch, and the thread of a world takes it
through the ``n`` steps in turn:

    for each step:   rebuild the world's neighbour lists if a body moved half the skin
                     contacts of every body, candidates from its list   (ContactStage)
                     advance every body                                 (Integrator)

The contact and integration code is the very code of the parallel step (the same Taichi
functions), and a body's candidates come in the same order (ascending ids) however they
were found, so the two ways of stepping give bit-identical states (tests/test_engine.py).
A batch of small worlds fills the cores with worlds; a single large world should be stepped
in parallel over its bodies (``World.step``): ``World`` chooses (``stepping``).
"""

# No "from __future__ import annotations": Taichi reads kernel annotations as objects.

from typing import ClassVar

import taichi as ti

from . import backend
from .broadphase import NeighbourList
from .contact import ContactStage
from .energy import EnergyMeter
from .integrate import Integrator
from .schema import Access, Layout, Stage
from .state import Data, Model

# ``take`` of a plan row that takes no sample (``WorldStepper.run``).
NO_SAMPLE = -1


@ti.data_oriented
class WorldStepper(Stage):
    """Steps every world ``n`` times in one launch, one thread per world."""

    # Per step (``n`` = 1): the contact stage's and the integrator's traffic; the lists are
    # read every step and rebuilt rarely.
    ACCESS: ClassVar[dict[str, Access]] = {
        "run": Access(
            reads=(
                "body_angle",
                "body_drag_linear",
                "body_drag_rotational",
                "body_energy",
                "body_force_ext",
                "body_force_q",
                "body_inv_inertia",
                "body_inv_mass",
                "body_kind",
                "body_local_start",
                "body_omega",
                "body_pos",
                "body_probe",
                "body_radius",
                "body_rot",
                "body_small",
                "body_torque_q",
                "body_vel",
                "body_vert_count",
                "body_world",
                "contact_count",
                "contact_crushed",
                "contact_elastic",
                "contact_partner",
                "contact_spring",
                "contact_theta",
                "contact_xi",
                "nbr_count",
                "nbr_ids",
                "nbr_ref_angle",
                "nbr_ref_pos",
                "probe_impulse",
                "status",
                "time_step",
                "vert_local",
                "vert_normal_local",
                "world_A",
                "world_B",
                "world_body_start",
                "world_memory",
                "world_mu",
                "world_mu0",
                "world_nbr_stale",
                "world_rest_rule",
                "world_t_c",
                "world_v_star",
            ),
            writes=(
                "body_angle",
                "body_energy",
                "body_force_q",
                "body_omega",
                "body_pos",
                "body_rot",
                "body_torque_q",
                "body_vel",
                "contact_count",
                "contact_crushed",
                "contact_elastic",
                "contact_partner",
                "contact_spring",
                "contact_theta",
                "contact_xi",
                "nbr_count",
                "nbr_ids",
                "nbr_ref_angle",
                "nbr_ref_pos",
                "probe_impulse",
                "status",
                "world_nbr_stale",
                "nbr_rebuild",
            ),
            per_contact=ContactStage.ACCESS["compute"].per_contact,
        )
    }
    # With the samples between the steps (EnergyMeter.take): a step that takes none reads
    # none of their fields, but the kernel may.
    ACCESS["run"] = Access(
        reads=tuple(sorted({*ACCESS["run"].reads, *EnergyMeter.ACCESS["take"].reads})),
        writes=tuple(sorted({*ACCESS["run"].writes, *EnergyMeter.ACCESS["take"].writes})),
        per_contact=ACCESS["run"].per_contact,
    )
    PARTS: ClassVar[dict[str, type]] = {
        "contacts": ContactStage,
        "integrator": Integrator,
        "energy": EnergyMeter,
    }

    def __init__(
        self,
        layout: Layout,
        model: Model,
        data: Data,
        neighbours: NeighbourList,
        contacts: ContactStage,
        integrator: Integrator,
        energy: EnergyMeter,
    ):
        self.layout, self.model, self.data = layout, model, data
        self.neighbours, self.contacts, self.integrator = neighbours, contacts, integrator
        self.energy = energy
        # Worlds per task (CPU) or per block (GPU): a world's steps are long, so on the CPU
        # each world is a task of the thread pool, which balances worlds of unequal cost.
        self.world_block = 1 if backend.actual_arch() in (None, "cpu") else 128

    @ti.func
    def steps(self, w, n, dt):
        """``n`` steps of world w."""
        m, nb = ti.static((self.model, self.neighbours))
        lo, hi = m.world_body_start[w], m.world_body_start[w + 1]
        for _s in range(n):
            if nb.world_nbr_stale[w]:
                for i in range(lo, hi):
                    self.contacts.build_list(i)
                nb.world_nbr_stale[w] = 0
            for i in range(lo, hi):
                self.contacts.listed(i, dt, True)
            for i in range(lo, hi):
                self.integrator.body(i, dt)  # marks the lists stale

    @ti.kernel
    def run(
        self,
        plan: ti.types.ndarray(dtype=ti.i32, ndim=2),
        rows: ti.types.ndarray(dtype=ti.f64, ndim=3),
        impulses: ti.types.ndarray(dtype=ti.f64, ndim=3),
    ):
        """Steps and samples in one launch: for each row s of ``plan`` (steps, take), its
        steps of every world, then the world's sample ``s`` (``EnergyMeter.sample``) unless
        ``take`` is ``NO_SAMPLE``; ``take`` 1 restarts the probes' impulses (a recorded
        sample), 0 lets them add up. One kernel for stepping with and without samples: a
        layout compiles it once."""
        ti.loop_config(block_dim=self.world_block)
        for w in range(self.layout.n_worlds):
            dt = self.data.time_step[None]
            for s in range(plan.shape[0]):
                self.steps(w, plan[s, 0], dt)
                if plan[s, 1] != NO_SAMPLE:
                    self.energy.sample(w, s, rows, impulses, plan[s, 1])
