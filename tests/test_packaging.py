"""The package as users get it: runs on its oldest Python, installs as a wheel, starts quietly.

The wheel test builds the wheel from a copy of the sources, installs it into a folder of its
own and runs ``taichi-ice paper`` from another directory, so that nothing of the checkout
(the scenes in ``scenarios/``, the editable install) can stand in for what the wheel lacks.
"""

from __future__ import annotations

import ast
import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "taichi_ice"

# The oldest Python that pyproject.toml's requires-python admits.
OLDEST_PYTHON = "3.9"

PIP = (sys.executable, "-m", "pip")

# Wall-clock limits (s) of the subprocesses: generous, so that only a hang fails on them.
BUILD_TIMEOUT = 120
RUN_TIMEOUT = 180


def _environment(**changes: str | None) -> dict[str, str]:
    """This process's environment without any Taichi message setting, then ``changes``."""
    env = dict(os.environ)
    env.pop("ENABLE_TAICHI_HEADER_PRINT", None)
    env.pop("PYTHONPATH", None)
    for key, value in changes.items():
        if value is None:
            env.pop(key, None)
        else:
            env[key] = value
    return env


# ------------------------------------------------------------------------------------------
# The oldest Python
# ------------------------------------------------------------------------------------------

# Decorators whose functions' annotations Taichi evaluates at run time (kernel argument types).
_TAICHI_DECORATORS = {"kernel", "func", "real_func", "pyfunc"}


def _runtime_union_lines(path: Path) -> set[int]:
    """Lines of ``path`` with an ``X | Y`` that Python evaluates when the module runs.

    vermin's union-type check (a heuristic) also reports annotations, which a module with
    ``from __future__ import annotations`` never evaluates, so they are fine on 3.9; the
    annotations of Taichi kernels and functions are evaluated (by Taichi) and stay in.
    """
    tree = ast.parse(path.read_text(encoding="utf-8"))
    postponed = any(
        isinstance(node, ast.ImportFrom)
        and node.module == "__future__"
        and any(alias.name == "annotations" for alias in node.names)
        for node in tree.body
    )
    unevaluated: set[int] = set()  # ids of the nodes inside unevaluated annotations
    for node in ast.walk(tree) if postponed else ():
        annotations = []
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            decorators = {
                d.attr if isinstance(d, ast.Attribute) else getattr(d, "id", "")
                for d in node.decorator_list
            }
            if decorators & _TAICHI_DECORATORS:
                continue
            args = node.args
            every = [*args.posonlyargs, *args.args, *args.kwonlyargs, args.vararg, args.kwarg]
            annotations = [a.annotation for a in every if a is not None]
            annotations.append(node.returns)
        elif isinstance(node, ast.AnnAssign):
            annotations = [node.annotation]
        for annotation in annotations:
            if annotation is not None:
                unevaluated.update(id(n) for n in ast.walk(annotation))
    return {
        node.lineno
        for node in ast.walk(tree)
        if isinstance(node, ast.BinOp)
        and isinstance(node.op, ast.BitOr)
        and id(node) not in unevaluated
    }


def _vermin_findings(paths: list[Path]) -> list[tuple[Path, int, str]]:
    """``(file, line, what)`` for each construct in ``paths`` that needs a newer Python.

    vermin flags (tried on a small example of each construct): ``-t=3.9-`` the target;
    ``--violations`` only what misses it; ``--feature union-types`` also ``isinstance(x, A |
    B)`` and aliases ``T = A | B`` (3.10), which it does not check by default; it catches
    ``zip(strict=)``, ``dataclass(kw_only=, slots=)``, ``match``, new modules and members
    (``tomllib``, ``itertools.pairwise``) without options. ``# novm`` on a line excuses it.
    """
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from vermin.main import main; sys.exit(main())",
            f"-t={OLDEST_PYTHON}-",
            "--violations",
            "--no-tips",
            "--feature",
            "union-types",
            "--format",
            "parsable",
            "--no-config-file",
            *map(str, paths),
        ],
        capture_output=True,
        text=True,
        timeout=BUILD_TIMEOUT,
    )
    # 0: no violation, 1: some; the last line, a summary, says that vermin ran to the end.
    lines = out.stdout.splitlines()
    assert out.returncode in (0, 1) and lines and lines[-1].startswith(":::"), out.stderr
    runtime_unions: dict[str, set[int]] = {}
    findings = []
    for line in lines:
        # file:line:column:py2:py3:feature; lines without a line number are summaries.
        parts = line.rsplit(":", 5)
        if len(parts) != 6 or not parts[1]:
            continue
        file, lineno, _, _, needs, feature = parts
        if feature.startswith("union types"):
            if file not in runtime_unions:
                runtime_unions[file] = _runtime_union_lines(Path(file))
            if int(lineno) not in runtime_unions[file]:
                continue
        findings.append((Path(file), int(lineno), f"{feature} (needs {needs})"))
    return findings


def test_vermin_catches_newer_constructs(tmp_path: Path) -> None:
    """The check flags each construct newer than 3.9 and passes annotations it need not run."""
    sample = tmp_path / "sample.py"
    sample.write_text(
        "from __future__ import annotations\n"
        "import dataclasses\n"
        "def f(a: int | None, b: list[int]) -> str | None:\n"  # 3: fine, not evaluated
        "    x: float | None = None\n"  # 4: fine, not evaluated
        "    for p, q in zip(b, b, strict=True):\n"  # 5
        "        pass\n"
        "    if isinstance(a, int | float):\n"  # 7
        "        return 'n'\n"
        "    match a:\n"  # 9
        "        case 1:\n"
        "            return 'one'\n"
        "    return None\n"
        "@dataclasses.dataclass(kw_only=True)\n"  # 13
        "class A:\n"
        "    y: int | None = None\n",  # 15: fine, not evaluated
        encoding="utf-8",
    )
    assert sorted(line for _, line, _ in _vermin_findings([sample])) == [5, 7, 9, 13]


def test_package_runs_on_oldest_python() -> None:
    """No module of taichi_ice uses a construct that Python 3.9 lacks (vermin)."""
    found = _vermin_findings([PACKAGE])
    findings = [f"{path.relative_to(ROOT)}:{line}: {what}" for path, line, what in found]
    assert not findings, f"needs a Python newer than {OLDEST_PYTHON}:\n" + "\n".join(findings)


# ------------------------------------------------------------------------------------------
# Taichi's messages
# ------------------------------------------------------------------------------------------

START_TAICHI = (
    "from taichi_ice import backend\n"
    "import taichi\n"  # the banner, if any, prints at this import
    "backend.init('cpu')\n"
    "print('ok')\n"
)


def test_taichi_starts_quietly(tmp_path: Path) -> None:
    """Importing the package, then Taichi, and starting it prints no '[Taichi]' line."""
    out = subprocess.run(
        [sys.executable, "-c", START_TAICHI],
        cwd=tmp_path,
        env=_environment(),
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout == "ok\n"
    assert "[Taichi]" not in out.stderr


def test_taichi_messages_on_request(tmp_path: Path) -> None:
    """ENABLE_TAICHI_HEADER_PRINT=1 brings back Taichi's banner and its start-up line."""
    out = subprocess.run(
        [sys.executable, "-c", START_TAICHI],
        cwd=tmp_path,
        env=_environment(ENABLE_TAICHI_HEADER_PRINT="1"),
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT,
    )
    assert out.returncode == 0, out.stderr
    assert "[Taichi] version" in out.stdout and "[Taichi] Starting on arch=" in out.stdout


# ------------------------------------------------------------------------------------------
# The wheel
# ------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The wheel built from a copy of the sources (the checkout stays free of build/)."""
    for module in ("setuptools", "wheel"):
        pytest.importorskip(module, reason="the test extra builds the wheel offline")
    work = tmp_path_factory.mktemp("wheel")
    source = work / "source"
    source.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, source / name)
    shutil.copytree(PACKAGE, source / "taichi_ice", ignore=shutil.ignore_patterns("__pycache__"))
    dist = work / "dist"
    out = subprocess.run(
        [
            *(*PIP, "wheel", str(source), "--no-deps", "--no-build-isolation", "--no-index"),
            *("--quiet", "-w", str(dist)),
        ],
        capture_output=True,
        text=True,
        timeout=BUILD_TIMEOUT,
        env=_environment(),
    )
    assert out.returncode == 0, out.stdout + out.stderr
    (path,) = dist.glob("taichi_ice-*.whl")
    return path


def test_wheel_contents(wheel: Path) -> None:
    """The wheel holds the scenes and the version module; its metadata admits Python 3.9."""
    from taichi_ice import __version__
    from taichi_ice.scene import parse as scenario

    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        (metadata,) = [n for n in names if n.endswith(".dist-info/METADATA")]
        meta = z.read(metadata).decode()
    for scene in scenario.bundled_scenes():
        assert f"taichi_ice/scenarios/{scene}.toml" in names
    assert "taichi_ice/_version.py" in names
    assert f"Version: {__version__}\n" in meta
    assert "Requires-Python: <3.14,>=3.9" in meta
    assert "tomli-w" in meta and 'tomli>=1.1; python_version < "3.11"' in meta


def test_wheel_runs_paper_anywhere(wheel: Path, tmp_path: Path) -> None:
    """Installed from the wheel, `python -m taichi_ice paper` runs from any directory, quietly."""
    site = tmp_path / "site"
    out = subprocess.run(
        [*PIP, "install", "--no-deps", "--quiet", "--target", str(site), str(wheel)],
        capture_output=True,
        text=True,
        timeout=BUILD_TIMEOUT,
        env=_environment(),
    )
    assert out.returncode == 0, out.stdout + out.stderr
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = _environment(PYTHONPATH=str(site))

    # The package found is the installed one, not the editable checkout this venv also has.
    where = subprocess.run(
        [sys.executable, "-c", "import taichi_ice; print(taichi_ice.__file__)"],
        cwd=elsewhere,
        env=env,
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT,
    )
    assert where.returncode == 0, where.stderr
    assert Path(where.stdout.strip()).parent == site / "taichi_ice"

    paper = tmp_path / "paper"
    args = ["paper", "--out", str(paper), "--until", "0.2", "--seeds", "0", "--quick"]
    args.append("--paper-only")
    run = subprocess.run(
        [sys.executable, "-m", "taichi_ice", *args],
        cwd=elsewhere,
        env=env,
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    summary = json.loads((paper / "summary.json").read_text())
    assert summary
    for model in ("mu0.1", "mu0.5", "mu0.9", "rate-state"):
        assert (paper / "runs" / f"{model}.h5").is_file(), model
    assert "[Taichi]" not in run.stdout + run.stderr
