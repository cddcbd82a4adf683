"""Validation studies behind ``taichi-ice validate``: each writes figures (PNG) and a JSON summary.

- ``single_interface``: the paper's Figure 3 (step, ramp, fast and slow sinusoid) against
  the exact solutions, with the sinusoids' gain and phase against H(w).
- ``rest_rules``: mu of an interface that slides, stops and slides again under each rule
  below v_star (``paper``, ``healing``, ``frozen``) and the variants without memory or rate.
- ``dem_contact``: the same law through a DEM contact: Figure 3's profiles as the speed of a
  floor under a block, against the exact solutions; and a block that slides, stops, then
  holds or slides under a horizontal load, under each rule below v_star.
- ``stability``: explicit Euler and RK4 past their stability limits diverge; exponential
  and implicit stay bounded.
- ``speed_accuracy``: error against time step and against wall time for every method, in
  float64 and float32, NumPy and Taichi, with measured convergence orders.
- ``dem_accuracy`` (``--dem``): the DEM's error against cost over time steps from well below
  to beyond the stability limit, float64 and float32, Coulomb and rate-and-state (collisions
  against an ODE, the pushed box's energy budget, the pillar scene against a run at a quarter
  of the step, when chaotic runs part), and the largest step each scene survives
  (``dem_stability``), with the recommended ``dt_safety``; each with both integrators.
- ``dem_ensemble`` (``--dem``): the pillar scene over 32 layouts at 4x the Euler step's 0.2
  stable_dt and with the other integrators, against it on the same layouts, and each law's
  default step against a quarter of it: each measure's shift against its sampling error
  (paired t interval, Wilcoxon, KS; released: McNemar).
- ``contact_convergence`` (``--dem``): friction at a DEM contact against dt: a driven
  slider's frictional work and slip starts, a block that slid holding or sliding under a
  pull, steady sliding on a moving floor against mu_ss, every law in the pillar scene before
  runs part; and what the tangential stiffness and the steady-state law's t_c change.
- ``contact_coupling`` (``--dem``): why the coupled integrator: a contact's normal and
  tangent solved apart (analytic), together (coupled) and together at mid-step (midstep) in
  the NumPy twin, on the
  collisions against their ODE and on a loaded stack.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

__all__ = ["compile_for_studies", "validate_command"]


def compile_for_studies() -> str:
    """Let the accuracy studies compile without Taichi's advanced passes, unless the user
    set ``TAICHI_ICE_OPTIMIZE``; returns the setting the user asked for ("off", "on" or
    "full"; default: on, ``backend.optimize_level``).

    The studies build dozens of layouts (integrators, laws, batches, precisions) for runs of
    seconds: with the passes, compiling was most of ``validate --dem`` (issue 30: the coupled
    step's kernels 41.6 s against 2.6 s without). Their results are the same bit for bit
    (``tests/test_backend.py``); stepping is up to ~1.1x slower a world a thread, which the
    studies' wall-time axes (``dem_accuracy``) record (``advanced_optimization``). Child
    processes inherit the setting. The speed study times kernels: it asks for the user's.
    """
    from ... import backend

    wanted = backend.optimize_level()
    os.environ.setdefault(backend.OPTIMIZE_ENV, "0")
    return wanted


def validate_command(out: str, speed: bool = False, quick: bool = False, dem: bool = False) -> int:
    """Run the validation studies into ``out``; the body of ``taichi-ice validate``.

    Args:
        out: output folder (created if missing).
        speed: also run the speed/accuracy study (a few minutes at 1e6 interfaces).
        quick: smaller sizes, for tests and smoke runs.
        dem: also run the DEM accuracy and stability study and the contact convergence
            study (~20 minutes on 2 cores).

    Returns:
        Process exit code: 0.
    """
    from . import dem_contact, rest_rules, single_interface, stability

    out_dir = Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    optimize = compile_for_studies()
    start = time.perf_counter()
    single_interface.run(out_dir, quick=quick)
    rest_rules.run(out_dir)
    dem_contact.run(out_dir, quick=quick)
    stability.run(out_dir, quick=quick)
    if speed:
        from . import speed_accuracy

        speed_accuracy.run(out_dir, quick=quick, optimize=optimize)
    if dem:
        from . import contact_convergence, contact_coupling, dem_accuracy, dem_ensemble

        dem_accuracy.run(out_dir, quick=quick)
        dem_ensemble.run(out_dir, quick=quick)
        contact_convergence.run(out_dir, quick=quick)
        contact_coupling.run(out_dir, quick=quick)
    print(f"validate: done in {time.perf_counter() - start:.1f} s; results in {out_dir}/")
    return 0
