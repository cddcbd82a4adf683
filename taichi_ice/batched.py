"""Public re-export: the batched kernels, at their home ``taichi_ice.physics.batched``.

``from taichi_ice.batched import respond_batch_ti`` keeps working; nothing inside the
package imports this module (tests/test_layers.py).
"""

from .physics.batched import (
    BatchOverlap,
    contact_friction_batch_ti,
    overlap_batch_ti,
    respond_batch,
    respond_batch_ti,
    respond_batch_ti_unchecked,
    respond_batch_unchecked,
    rotation_batch_ti,
)

__all__ = [
    "BatchOverlap",
    "contact_friction_batch_ti",
    "overlap_batch_ti",
    "respond_batch",
    "respond_batch_ti",
    "respond_batch_ti_unchecked",
    "respond_batch_unchecked",
    "rotation_batch_ti",
]
