"""Read-only NumPy arrays: what the scene model hands out, so that no caller changes a scene.

Holds only :func:`frozen`, which the scene model (``taichi_ice.scene.model``) and the checked
reading of a scene file (``taichi_ice.scene.table``, ``taichi_ice.scene.parse``) share; it sits
below both so that neither imports the other for it. Plain NumPy: importing it never loads Taichi.
"""

from __future__ import annotations

import numpy as np

__all__ = ["frozen"]


def frozen(a: np.ndarray) -> np.ndarray:
    """A read-only float64 copy of ``a`` (integer arrays keep their dtype)."""
    a = np.array(a, dtype=a.dtype if a.dtype.kind in "iu" else np.float64)
    a.flags.writeable = False
    return a
