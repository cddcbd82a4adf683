"""The physics of one contact, NumPy beside Taichi: no fields, no scenes, no state.

Polygons and their overlap (``polygon``), friction laws and their memory (``friction``), the
slip solve of a contact (``slip``), water drag (``drag``), the stable time step
(``timestep``), exact solutions to test against (``exact``) and the batched kernels that
evaluate a law or an overlap for many inputs at once (``batched``). Each ``x.py`` is NumPy
and imports no Taichi; its Taichi twin ``x_ti.py`` keeps the same functions in the same
order, so that the two read side by side and the tests hold one against the other.

Layer 1 of the package (docs/architecture.md): imports only the base modules.
"""
