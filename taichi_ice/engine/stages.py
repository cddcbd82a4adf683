"""The step's stages declared: what each kernel reads and writes, checked and costed.

A stage (``broadphase.SpatialHash``, ``contact.ContactStage``, ``integrate.Integrator``, ...)
subclasses ``Stage`` and maps each of its kernels to an ``Access``: the fields of
``schema``'s tables it reads and writes. ``fields_touched`` reads a kernel's source (and that
of the methods it calls) to find the fields it really touches, which ``tests/test_schema.py``
holds against the declaration; ``traffic`` charges each kernel for the bytes its declared
fields move, the benchmark's memory model. The fields themselves, their shapes and the
``Layout`` that sizes them are ``schema``'s.

Pure Python: importing this module never starts Taichi.
"""

from __future__ import annotations

import ast
import inspect
import textwrap
from collections.abc import Collection, Mapping
from dataclasses import dataclass

import numpy as np

from .schema import Layout, groups, var

__all__ = ["Access", "Stage", "fields_touched", "traffic"]


@dataclass(frozen=True)
class Access:
    """What one kernel of a stage reads and writes, and how many elements of each.

    Attributes:
        reads, writes: field names (a field both read and written is in both).
        per_contact: fields whose traffic scales with the contacts of the step rather than
            with their declared shape (contact slots: only used slots are touched; the
            bodies of a contact, gathered by the owner's thread).
    """

    reads: tuple[str, ...]
    writes: tuple[str, ...]
    per_contact: tuple[str, ...] = ()


class Stage:
    """Base of the step's stages: ``ACCESS`` maps each kernel to what it reads and writes.

    ``tests/test_schema.py`` parses every kernel (and the methods it calls) and checks that
    the fields it touches are exactly those declared, so the declaration cannot drift.
    """

    ACCESS: Mapping[str, Access] = {}


# Module functions that add to the fields passed as their first n arguments (read and
# written, as an atomic): ``fields_touched`` counts those arguments as written.
ACCUMULATES = {"gather": 2}


def fields_touched(cls: type, kernel: str) -> tuple[set[str], set[str]]:
    """(read, written) field names that a kernel of stage class ``cls`` touches, from its
    source and the source of every method of ``cls`` it calls (transitively), including
    methods of the stages it holds as ``PARTS`` (``{"contacts": ContactStage}``: a call
    ``self.contacts.f(...)`` is followed into ``ContactStage.f``).

    A field counts as written when it is (inside) an assignment target or the first argument
    of a ``ti.atomic_*`` call, and as read wherever it appears except as the target of a
    plain assignment (so an augmented assignment or an atomic is both). Fields are
    recognised by name, whatever object they are reached through.
    """
    declared = {v.name for g in groups().values() for v in g}
    reads: set[str] = set()
    writes: set[str] = set()
    todo, seen = [(cls, kernel)], set()
    while todo:
        owner, name = todo.pop()
        if (owner, name) in seen:
            continue
        seen.add((owner, name))
        func = inspect.unwrap(getattr(owner, name))
        func = getattr(func, "func", func)  # a Taichi kernel wraps the Python function
        tree = ast.parse(textwrap.dedent(inspect.getsource(func)))
        parts = getattr(owner, "PARTS", {})
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
                target = node.func.value
                if isinstance(target, ast.Name) and target.id == "self":
                    if hasattr(owner, node.func.attr):
                        todo.append((owner, node.func.attr))
                elif (
                    isinstance(target, ast.Attribute)
                    and isinstance(target.value, ast.Name)
                    and target.value.id == "self"
                    and target.attr in parts
                ):
                    # A method of a stage this one holds (``self.contacts.body(...)``).
                    todo.append((parts[target.attr], node.func.attr))
            targets: list[ast.AST] = []
            if isinstance(node, ast.Assign):
                targets = node.targets
            elif isinstance(node, ast.AugAssign):
                targets = [node.target]
                reads.update(_field_names(node.target, declared))
            elif (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Attribute)
                and node.func.attr.startswith("atomic_")
                and node.args
            ):
                targets = [node.args[0]]
            elif (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Name)
                and node.func.id in ACCUMULATES
            ):
                # A function that adds to fields it is handed (``gather.gather``).
                targets = node.args[: ACCUMULATES[node.func.id]]
            for t in targets:
                writes.update(_field_names(t, declared))
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and node.attr in declared:
                if not _is_target(node, tree):
                    reads.add(node.attr)
    return reads, writes


def _field_names(node: ast.AST, declared: set[str]) -> set[str]:
    """Declared field names reached as attributes inside an assignment target."""
    while isinstance(node, ast.Subscript):
        node = node.value
    if isinstance(node, ast.Attribute) and node.attr in declared:
        return {node.attr}
    if isinstance(node, ast.Tuple):
        return set().union(*(_field_names(e, declared) for e in node.elts))
    return set()


def _is_target(attr: ast.Attribute, tree: ast.AST) -> bool:
    """True if ``attr`` is (inside) the target of a plain assignment, which writes without
    reading. (An augmented assignment or an atomic reads and writes.)"""
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign):
            for t in node.targets:
                if any(base is attr for base in _target_bases(t)):
                    return True
    return False


def _target_bases(node: ast.AST) -> list[ast.AST]:
    """The objects an assignment target stores into: ``a.f[i][j]`` -> ``a.f`` (the indices,
    which are read, are not bases)."""
    if isinstance(node, ast.Tuple):
        return [b for e in node.elts for b in _target_bases(e)]
    while isinstance(node, ast.Subscript):
        node = node.value
    return [node]


def traffic(
    stages: Mapping[str, type],
    layout: Layout,
    contacts: float,
    kernels: Collection[str] | None = None,
) -> dict[str, float]:
    """Bytes per step that each kernel must move, from the stages' declarations.

    Compulsory traffic: each element a kernel declares is counted once per launch (a
    neighbour's data gathered again is taken to hit the cache), reads and writes separately,
    so the bound it gives is optimistic. Switched-off fields (``when``) cost nothing. A
    ``per_contact`` field is charged for ``contacts`` elements (one per contact of the step,
    two for body data, which both bodies of a contact need) instead of its declared shape.

    Args:
        stages: ``{"hash": SpatialHash, ...}``: stage classes by the name their kernels are
            reported under (``hash.build``).
        layout: the batch's layout.
        contacts: contacts of the step.
        kernels: the ``"stage.kernel"`` names a step launches; default every kernel of
            ``stages``.

    Returns:
        ``{"stage.kernel": bytes}`` and ``"total"``.
    """
    out: dict[str, float] = {}
    for stage_name, cls in stages.items():
        for kernel, access in cls.ACCESS.items():
            if kernels is not None and f"{stage_name}.{kernel}" not in kernels:
                continue
            total = 0.0
            for name in (*access.reads, *access.writes):
                v = var(name)
                if not layout.exists(v):
                    continue
                if name in access.per_contact:
                    # Only the slots of this step's contacts are touched, and only the
                    # bodies in a contact; other axes (energy columns) stay whole.
                    rest = [layout.size(s) for s in v.shape if s not in ("n_bodies", "slots")]
                    per = contacts if "slots" in v.shape else min(layout.n_bodies, 2.0 * contacts)
                    elements = per * float(np.prod(rest, dtype=np.float64))
                else:
                    elements = float(np.prod(layout.shape(v), dtype=np.float64))
                total += elements * v.item_bytes(layout.precision)
            out[f"{stage_name}.{kernel}"] = total
    out["total"] = sum(out.values())
    return out
