"""Sweeps: layouts x friction laws x scene overrides, run as batches on Dask.

``spec`` (sweep files, checked: ``Sweep``, ``Case``), ``plan`` (cases into batches of one
layout), ``run`` (the batches on Dask, resume) and ``dataset`` (the sweep's netCDF-4
dataset, ``open_sweep``). NumPy and the standard library until ``run``."""
