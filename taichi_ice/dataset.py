"""Public re-export: a sweep's dataset, at its home ``taichi_ice.experiments.sweep.dataset``.

``from taichi_ice.dataset import open_sweep`` keeps working; nothing inside the package
imports this module (tests/test_layers.py).
"""

from .experiments.sweep.dataset import build_dataset, open_sweep, write_dataset

__all__ = ["build_dataset", "open_sweep", "write_dataset"]
