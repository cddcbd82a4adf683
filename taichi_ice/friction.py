"""Public re-export: the friction laws, at their homes ``taichi_ice.physics.friction`` (the
laws, NumPy) and ``taichi_ice.physics.friction_parse`` (``law_from_table``, ``parse_law``).

``from taichi_ice.friction import RateState`` keeps working; nothing inside the package
imports this module (tests/test_layers.py).
"""

from .physics.friction import *  # noqa: F403
from .physics.friction import __all__ as _laws
from .physics.friction_parse import law_from_table, parse_law

__all__ = [*_laws, "law_from_table", "parse_law"]
