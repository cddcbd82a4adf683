"""The house: each folder of the package is a layer, and imports run only downward (issue 29).

The package's imports are read from its source (``ast``: module-level and function-level
imports alike, since a lazy import is a dependency too) and checked against the layers of
docs/architecture.md: no module imports one of a higher layer or a public re-export module,
no circle of imports, no module over ``MAX_LINES`` lines; and the NumPy layers import no
Taichi, in a child process that starts clean.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "taichi_ice"

# Lowest first. A top-level module (errors, codes, backend, ...) is the base layer.
LAYERS = ("base", "physics", "scene", "engine", "run", "experiments", "commands")
# The public names a module kept after it moved: re-exports for users' code and the entry
# points; nothing in the package imports them.
FACADES = (
    "taichi_ice",
    "taichi_ice.__main__",
    "taichi_ice.friction",
    "taichi_ice.geometry",
    "taichi_ice.dataset",
    "taichi_ice.batched",
)
MAX_LINES = 600


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """The package's modules that module ``name`` imports (a name imported from a package
    counts as the package, or as its submodule when it is one)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            for alias in node.names:
                child = f"{module}.{alias.name}"
                found.add(child if child in MODULES else module)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
    return {m for m in found if m in MODULES and m != name}


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def layer(name: str) -> str:
    parts = name.split(".")
    if len(parts) > 2 or (len(parts) == 2 and (PACKAGE / parts[1]).is_dir()):
        return parts[1]
    return "base"


def test_layers_are_the_folders_of_the_package():
    folders = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists()}
    assert folders == set(LAYERS[1:])


def upward(graph: dict[str, set[str]]) -> list[str]:
    """The imports of ``graph`` that run up a layer or into a public re-export module."""
    up = []
    for name, targets in graph.items():
        if name in FACADES:
            continue
        for target in targets:
            if target in FACADES:
                up.append(f"{name} -> {target} (a public re-export; import its home)")
            elif LAYERS.index(layer(target)) > LAYERS.index(layer(name)):
                up.append(f"{name} ({layer(name)}) -> {target} ({layer(target)})")
    return sorted(up)


def first_circle(graph: dict[str, set[str]]) -> list[str] | None:
    """A circle of imports in ``graph`` (depth-first search for a back edge), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(name: str) -> list[str] | None:
        state[name] = 1
        stack.append(name)
        for target in sorted(graph[name]):
            if state.get(target) == 1:
                return [*stack[stack.index(target) :], target]
            if target not in state and (circle := visit(target)):
                return circle
        stack.pop()
        state[name] = 2
        return None

    for name in sorted(graph):
        if name not in state and (circle := visit(name)):
            return circle
    return None


def test_imports_run_only_downward():
    up = upward(GRAPH)
    assert not up, "imports that run up:\n" + "\n".join(up)


def test_no_circle_of_imports():
    circle = first_circle(GRAPH)
    assert circle is None, "a circle of imports: " + " -> ".join(circle)


def test_the_checks_catch_a_planted_upward_import_and_a_planted_circle():
    """The package's graph with one edge added: the engine importing the run layer is
    named as running up, and with the run layer's import of the engine it closes a circle;
    a re-export module imported from inside is named too."""
    planted = {name: set(targets) for name, targets in GRAPH.items()}
    assert "taichi_ice.engine.pool" in planted["taichi_ice.run.simulation"]
    planted["taichi_ice.engine.pool"].add("taichi_ice.run.simulation")
    planted["taichi_ice.engine.assemble"].add("taichi_ice.friction")
    assert upward(planted) == [
        "taichi_ice.engine.assemble -> taichi_ice.friction (a public re-export; import its home)",
        "taichi_ice.engine.pool (engine) -> taichi_ice.run.simulation (run)",
    ]
    circle = first_circle(planted)
    assert circle is not None and circle[0] == circle[-1]
    assert {"taichi_ice.engine.pool", "taichi_ice.run.simulation"} <= set(circle)


def test_no_module_is_over_600_lines():
    long = {
        str(p.relative_to(PACKAGE.parent)): n
        for p in MODULES.values()
        if (n := len(p.read_text().splitlines())) > MAX_LINES
    }
    assert not long


@pytest.mark.parametrize(
    "module",
    [
        "taichi_ice.scene",
        "taichi_ice.scene.parse",
        *(
            f"taichi_ice.physics.{m}"
            for m in (
                *("polygon", "friction", "friction_parse", "fmath", "slip", "drag"),
                *("contact_law", "exact", "timestep"),
            )
        ),
        *(
            f"taichi_ice.engine.{m}"
            for m in (
                *("options", "schema", "stages", "assemble", "reference", "reference_contact"),
                "contact_rows",
            )
        ),
        "taichi_ice.friction",
        "taichi_ice.experiments.sweep.spec",
    ],
)
def test_the_numpy_layers_import_no_taichi(module):
    """In a fresh interpreter: the scene layer, the NumPy halves of the twin pairs, the
    engine's NumPy modules (options, the state table, assembly, the reference step) and the
    sweep specification import neither Taichi nor anything that does."""
    code = f"import sys, {module}; print('taichi' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"
