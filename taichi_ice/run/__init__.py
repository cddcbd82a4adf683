"""A run: a Simulation stepping one World to a run file, with its checkpoints, energy
budget, plots and exports.

``simulation`` (``Simulation``), ``runfile`` (the netCDF-4 run file: writing and
``open_run``), ``checkpoint`` (kill and resume, bit for bit), ``budget`` (the energy budget
and its closure), ``plots`` and ``export``.

Layer 4 of the package (docs/architecture.md): imports engine, scene, physics and the base
modules.
"""
