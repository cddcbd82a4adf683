"""Many steps per kernel launch: a thread per world (``WorldStepper``), or a team of threads
over the bodies of large worlds on the CPU (``BodyTeam``).

A scene of tens of blocks does less work per step than a kernel launch costs: stepping it
in parallel over its bodies spends most of its time starting threads and waiting at
barriers. ``WorldStepper.run(plan, ...)`` instead launches once for many steps
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

import numpy as np
import taichi as ti

from .. import backend
from ..errors import BackendError
from .broadphase import NeighbourList
from .contact import ContactStage
from .contact_lists import SETTLE_ACCESS
from .energy import EnergyMeter
from .integrate import FORCING_READS, Integrator
from .schema import Layout, contact_columns, law_columns
from .stages import Access, Stage
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
                "body_domega",
                "body_drag_linear",
                "body_drag_rotational",
                *FORCING_READS,
                "body_dvel",
                "body_energy",
                "body_force_ext",
                "body_force_q",
                "body_shift_q",
                "body_turn_q",
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
                "contact_force",
                "contact_booking",
                "contact_elastic",
                "contact_partner",
                "contact_slip",
                "contact_theta",
                "contact_xi",
                "nbr_count",
                "nbr_gap",
                "nbr_ids",
                "nbr_path",
                "nbr_ref_angle",
                "nbr_ref_pos",
                "probe_impulse",
                "status",
                "time_step",
                "grid_inv_cell",
                "large_ids",
                "strip_ids",
                "strip_end",
                "world_large_start",
                "vert_local",
                "vert_normal_local",
                "world_body_start",
                "world_nbr_stale",
                *law_columns(),
                *contact_columns(),
                "world_runaway_step",
                "list_skin",
            ),
            writes=(
                "body_angle",
                "body_domega",
                "body_dvel",
                "body_energy",
                "body_force_q",
                "body_shift_q",
                "body_turn_q",
                "body_omega",
                "body_pos",
                "body_rot",
                "body_torque_q",
                "body_vel",
                "contact_count",
                "contact_crushed",
                "contact_force",
                "contact_booking",
                "contact_elastic",
                "contact_partner",
                "contact_slip",
                "contact_theta",
                "contact_xi",
                "nbr_count",
                "nbr_gap",
                "nbr_ids",
                "nbr_path",
                "nbr_ref_angle",
                "nbr_ref_pos",
                "probe_impulse",
                "status",
                "world_nbr_stale",
                "nbr_rebuild",
                "body_time",
                "strip_ids",
                "strip_end",
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
                self.contacts.build_world(w)
                nb.world_nbr_stale[w] = 0
            for i in range(lo, hi):
                self.contacts.listed(i, dt, True)
            for i in range(lo, hi):
                self.integrator.body(i, dt)  # marks the lists stale
            if ti.static(self.layout.settles):
                for i in range(lo, hi):
                    self.contacts.settle(i)

    def launch(self, plan: np.ndarray, rows: np.ndarray, impulses: np.ndarray) -> None:
        """``run`` the plan, rows ``(steps, take)``, and check that every world's thread ran
        to its end. Where the device caps a thread's loops (``backend.loops_capped``: Mesa
        22's lavapipe stops them after 65,535 turns in all) a launch takes one step, and a
        step that alone goes past the cap is an error, never a shortened step."""
        if not backend.loops_capped():
            self._checked(plan, rows, impulses)
            return
        for s, (n, take) in enumerate(np.asarray(plan, dtype=np.int32).reshape(-1, 2)):
            for k in range(max(int(n), 1)):
                last = k == max(int(n), 1) - 1
                one = np.array([[min(int(n), 1), take if last else NO_SAMPLE]], dtype=np.int32)
                self._checked(one, rows[s : s + 1], impulses[s : s + 1])

    def _checked(self, plan: np.ndarray, rows: np.ndarray, impulses: np.ndarray) -> None:
        turns = np.full(self.layout.n_worlds, self.CANARY_TURNS, dtype=np.int32)
        self.run(plan, rows, impulses, turns)
        if np.any(turns != self.CANARY_TURNS):
            raise BackendError(
                f"the {backend.actual_arch()} device stopped a world's thread part-way through "
                f"its loops (world {int(np.flatnonzero(turns != self.CANARY_TURNS)[0])}): its "
                "driver caps the turns a GPU thread may take (Mesa 22's lavapipe: 65,535), and "
                "one step of this world takes more; step it a kernel per stage "
                "(stepping='bodies') or use another driver (Mesa 25 has no such cap)"
            )

    # Turns of the loop each world's thread takes last (``run``): a device that cut the
    # thread's loops short takes one.
    CANARY_TURNS = 2

    @ti.kernel
    def run(
        self,
        plan: ti.types.ndarray(dtype=ti.i32, ndim=2),
        rows: ti.types.ndarray(dtype=ti.f64, ndim=3),
        impulses: ti.types.ndarray(dtype=ti.f64, ndim=3),
        turns: ti.types.ndarray(dtype=ti.i32, ndim=1),
    ):
        """Steps and samples in one launch: for each row s of ``plan`` (steps, take), its
        steps of every world, then the world's sample ``s`` (``EnergyMeter.sample``) unless
        ``take`` is ``NO_SAMPLE``; ``take`` 1 restarts the probes' impulses (a recorded
        sample), 0 lets them add up. One kernel for stepping with and without samples: a
        layout compiles it once. Last, each world's thread loops ``turns[w]`` times and
        writes back how many turns it took (``launch`` checks them)."""
        ti.loop_config(block_dim=self.world_block)
        for w in range(self.layout.n_worlds):
            dt = self.data.time_step[None]
            for s in range(plan.shape[0]):
                self.steps(w, plan[s, 0], dt)
                if plan[s, 1] != NO_SAMPLE:
                    self.energy.sample(w, s, rows, impulses, plan[s, 1])
            took = 0
            for _k in range(turns[w]):  # read at run time: no compiler can count it
                took += 1
            turns[w] = took


@ti.data_oriented
class BodyTeam(Stage):
    """The parallel step on the CPU, many steps per launch: a team of threads, one task each.

    Stepping in parallel over bodies with a kernel per stage (``contacts.compute``, then
    ``integrator.advance``) pays, every step, two launches from Python and two rounds of
    Taichi's thread pool, whose workers sleep on a condition variable between tasks: about
    60 us a round on the 2-core VM, a fifth of a step at 1e4 blocks when it was measured.
    ``run(n)`` launches once for ``n`` steps (at most ``MAX_STEPS``: the barriers count
    arrivals in 32 bits). Its parallel loop has one iteration per thread of the team; each takes
    the steps in turn:

        for each step:   contacts of bodies in chunks claimed from a shared counter
                         barrier
                         advance bodies in chunks claimed from the second counter
                         barrier
                         (analytic steps with a budget: settle the contacts' work in
                          chunks claimed from the third, ``ContactLists.settle``; barrier)
                         stop if a body moved half the skin (lists to rebuild)

    The barriers spin on an atomic counter (``barrier``) instead of sleeping: the team must
    have a core for each of its threads (``threads``: Taichi's threads, at most the cores this
    process may use, ``backend.usable_cores``), or a thread waits out the time slice of the
    one it waits for; and when other load on the machine takes one of its cores, the rest
    spin until that thread runs again (a time slice: milliseconds, a stall that small worlds,
    with many steps a millisecond, feel most; ``world.auto_stepping`` keeps them a thread
    per world). Every one of the team's iterations runs at once on its own worker: the
    pool wakes as many workers as the loop's ``parallelize`` and a worker cannot take a second
    iteration while its first waits at a barrier. The bodies, the contact and integration
    code and the order of a body's candidates are those of the kernels per stage, and forces
    are summed in fixed point, so the two give the same state bit for bit
    (``tests/test_engine.py``). The launch returns after the step that marked lists stale;
    ``World.advance`` rebuilds them (``refresh_lists``) and launches for the steps left.
    """

    ACCESS: ClassVar[dict[str, Access]] = {
        "run": Access(
            reads=tuple(
                sorted(
                    {
                        *ContactStage.ACCESS["compute"].reads,
                        *Integrator.ACCESS["advance"].reads,
                        *SETTLE_ACCESS.reads,
                        "nbr_rebuild",
                    }
                )
            ),
            writes=tuple(
                sorted(
                    {
                        *ContactStage.ACCESS["compute"].writes,
                        *Integrator.ACCESS["advance"].writes,
                        *SETTLE_ACCESS.writes,
                    }
                )
            ),
            per_contact=ContactStage.ACCESS["compute"].per_contact,
        )
    }
    PARTS: ClassVar[dict[str, type]] = {"contacts": ContactStage, "integrator": Integrator}
    # Bodies a thread claims at a time: enough that claims are rare, few enough that the
    # threads finish a stage together (1e4 bodies: 157 chunks for 2 threads).
    CHUNK = 64
    # Steps a launch may take: the (at most) 3 n threads arrivals of its barriers stay in an
    # i32 for teams of up to 1,000 threads.
    MAX_STEPS = 1 << 19

    def __init__(
        self,
        layout: Layout,
        data: Data,
        neighbours: NeighbourList,
        contacts: ContactStage,
        integrator: Integrator,
        threads: int,
    ):
        self.layout, self.data, self.neighbours = layout, data, neighbours
        self.contacts, self.integrator = contacts, integrator
        self.threads = int(threads)
        # The team's synchronisation words, reset at the start of every launch (scratch of
        # one launch, no state of the batch: not in the schema). ``arrived``: arrivals at
        # the barriers so far; ``claimed``: chunks claimed in each stage of the step;
        # ``done``: steps taken when the launch stops early.
        self.arrived = ti.field(ti.i32, ())
        self.claimed = ti.field(ti.i32, 3)
        self.done = ti.field(ti.i32, ())
        self._compiled = False

    def launch(self, n: int) -> int:
        """``run(n)``: the steps taken. Its first call compiles it without Taichi's
        ``cache_loop_invariant_global_vars`` pass (an advanced pass, on in the "on" and
        "full" settings), and puts the setting back for the kernels compiled after.

        That pass keeps a global that a loop reads and adds to in a local copy for the
        loop's length, written back at its end: right for a loop no other thread touches,
        wrong for a barrier, whose spin reads must see every arrival. Taichi 1.7.4 applied
        it to the barriers of a team of one thread (its loop runs over a range of one; the
        arrival's add and the spin's read each got a copy of their own, so the read never
        saw the add: the IR of a minimal kernel shows it) and, with every pass ("full"),
        to the midstep team's of two: the team then waited for ever in its first step
        (found 2026-12-03: ``TI_CPU_MAX_NUM_THREADS=1``, or a one-core machine, stepping a
        world of 1e4 blocks). Taichi's offline cache does not key kernels by this setting:
        a kernel of the same code cached by a run with the pass on may still be loaded (a
        team of two in "on", which ran), but a run that hung never wrote one."""
        if self._compiled:
            return self.run(n)
        from taichi.lang import impl

        cfg = impl.current_cfg()
        kept = cfg.cache_loop_invariant_global_vars
        cfg.cache_loop_invariant_global_vars = False
        try:
            steps = self.run(n)
        finally:
            cfg.cache_loop_invariant_global_vars = kept
        self._compiled = True
        return steps

    @ti.func
    def barrier(self, k):
        """The ``k``-th barrier of the launch: wait until every thread has arrived at it.
        (An atomic add of 0 reads the counter: a plain load could be hoisted out of the
        loop, and the atomics order the stage's stores before the arrival.)"""
        ti.atomic_add(self.arrived[None], 1)
        while ti.atomic_add(self.arrived[None], 0) < k * self.threads:
            pass

    @ti.func
    def chunk(self, stage):
        """The first body of the next unclaimed chunk of ``stage`` (0: contacts, 1: the
        integrator, 2: ``settle``), ``body_count`` or more when all are claimed."""
        return ti.atomic_add(self.claimed[stage], 1) * self.CHUNK

    @ti.kernel
    def run(self, n: ti.i32) -> ti.i32:
        """``n`` steps of every body, fewer if a step marks the neighbour lists stale: then
        it stops after that step. Returns the steps taken."""
        self.arrived[None] = 0
        self.claimed[0] = 0
        self.claimed[1] = 0
        self.claimed[2] = 0
        self.done[None] = n
        nb, m = ti.static((self.neighbours, self.contacts.model))
        ti.loop_config(parallelize=self.threads, block_dim=1)
        for t in range(self.threads):
            count = m.body_count[None]
            dt = self.data.time_step[None]
            k = 0
            for s in range(n):
                first = self.chunk(0)
                while first < count:
                    for i in range(first, ti.min(first + self.CHUNK, count)):
                        self.contacts.listed(i, dt, False)
                    first = self.chunk(0)
                if t == 0:
                    self.claimed[1] = 0  # last used before the previous barrier
                    self.claimed[2] = 0
                k += 1
                self.barrier(k)
                first = self.chunk(1)
                while first < count:
                    for i in range(first, ti.min(first + self.CHUNK, count)):
                        self.integrator.body(i, dt)
                    first = self.chunk(1)
                if t == 0:
                    self.claimed[0] = 0
                k += 1
                self.barrier(k)
                if ti.static(self.layout.settles):  # the contacts' work booked again
                    first = self.chunk(2)
                    while first < count:
                        for i in range(first, ti.min(first + self.CHUNK, count)):
                            self.contacts.settle(i)
                        first = self.chunk(2)
                    k += 1
                    self.barrier(k)
                # Every thread reads the same word: it is written in the integrator's stage
                # only, which no thread enters again before the next barrier.
                if ti.atomic_add(nb.nbr_rebuild[None], 0):
                    if t == 0:
                        self.done[None] = s + 1
                    break
        return self.done[None]
