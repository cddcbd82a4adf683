"""The engine: a batch of scenes on Taichi fields, and its step.

``options`` (the settings of a World, one validated value), ``schema`` (the state table:
every field with its unit and role), ``state`` (the fields), ``assemble`` (scenes to the
arrays of a batch), ``broadphase``, ``contact``, ``integrate``, ``energy`` and ``stepper``
(the stages of a step), ``world`` (``World``: build, step, read back), ``pool`` (Worlds kept
compiled between batches) and ``reference`` (the NumPy twin of a whole step).

Layer 3 of the package (docs/architecture.md): imports scene, physics and the base modules.
"""
