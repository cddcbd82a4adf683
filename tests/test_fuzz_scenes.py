"""Fuzz: mutate the landed scenes (types, values, polygons, tables) and hold every outcome to
a scene that loads (and, for a few, runs) or one error line naming the file; never another
exception, never a traceback."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest

from taichi_ice.commands.cli import main
from taichi_ice.errors import TaichiIceError
from taichi_ice.scene.model import Scene
from taichi_ice.scene.parse import load_scenario, scene_from_dict
from taichi_ice.tomlio import dump_toml

ROOT = Path(__file__).resolve().parents[1]
SCENES = sorted((ROOT / "scenarios").glob("*.toml"))
MUTANTS = 80  # per scene, seeded
RUNS = 3  # mutants of two_squares that load are also run (a few: each run costs seconds)

TYPES = ["text", "1.0", True, [], {}, [1.0, 2.0, 3.0], [[0.0, 0.0]], {"x": 1}]
VALUES = [0, -1, 0.5, -1e300, 1e300, math.nan, math.inf, -math.inf, 1e-300, 2**63 - 1, -(2**63)]
STAR = (np.stack([np.cos(a := np.pi / 2 + 0.8 * np.pi * np.arange(5)), np.sin(a)], 1)).tolist()
POLYGONS = [
    STAR,  # crosses itself
    [[0, 0], [0, 1], [1, 1], [1, 0]],  # clockwise
    [[0, 0], [1, 0], [1, 0], [0, 1]],  # repeated vertex
    [[0, 0], [1, 0], [2, 0]],  # collinear
    [[0, 0], [1, 0]],  # too few
    [[0.3 * math.cos(t), 0.3 * math.sin(t)] for t in np.linspace(0, 6.2, 17)],  # 17 vertices
    [[0, 0], [1e200, 0], [0, 1e200]],  # overflows
    [["a", "b"], [1, 0], [0, 1]],  # not numbers
    [[0, 0], [1, 0], [0.2, 0.2], [0, 1]],  # reflex
]


def leaves(node, path=()):
    """Every (path, value) below ``node``: table entries and array items."""
    items = node.items() if isinstance(node, dict) else enumerate(node)
    for key, value in items:
        yield (*path, key), value
        if isinstance(value, (dict, list)):
            yield from leaves(value, (*path, key))


def parent(raw, path):
    for key in path[:-1]:
        raw = raw[key]
    return raw


def mutate(raw: dict, rng: np.random.Generator) -> str:
    """Change ``raw`` in place at random; returns what was done."""
    op = rng.choice(["type", "value", "polygon", "delete", "unknown", "table"])
    spots = list(leaves(raw))
    path, _ = spots[rng.integers(len(spots))]
    if op == "type":
        new = TYPES[rng.integers(len(TYPES))]
        parent(raw, path)[path[-1]] = copy.deepcopy(new)
        return f"{path} = {new!r}"
    if op == "value":
        numbers = [(p, v) for p, v in spots if isinstance(v, (int, float)) and v is not True]
        path, _ = numbers[rng.integers(len(numbers))]
        new = VALUES[rng.integers(len(VALUES))]
        parent(raw, path)[path[-1]] = new
        return f"{path} = {new!r}"
    if op == "polygon":
        tables = raw.get("body", []) + raw.get("field", [])
        table = tables[rng.integers(len(tables))]
        table.pop("width", None)
        table.pop("length", None)
        poly = POLYGONS[rng.integers(len(POLYGONS))]
        table.update(shape="polygon", vertices=copy.deepcopy(poly))
        return f"{table.get('name')}: vertices = {poly}"
    if op == "delete":
        del parent(raw, path)[path[-1]]
        return f"del {path}"
    if op == "unknown":
        tables = [v for _, v in spots if isinstance(v, dict)] + [raw]
        tables[rng.integers(len(tables))]["colour"] = "blue"
        return "unknown key colour"
    kind = rng.integers(4)
    if kind == 0:
        key = list(raw)[rng.integers(len(raw))]
        del raw[key]
        return f"del [{key}]"
    if kind == 1 and raw.get("body"):
        raw["body"].append(copy.deepcopy(raw["body"][0]))
        return "body 0 twice"
    if kind == 2 and raw.get("body"):
        raw["body"] = raw["body"][0]
        return "[body] as a table"
    raw["field"] = {"rows": 3}
    return "[field] as a table"


def outcome(raw: dict, source: str):
    """The Scene, or the error's message; any other exception propagates."""
    try:
        return scene_from_dict(raw, source=source)
    except TaichiIceError as exc:
        return str(exc)


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_mutated_scenes_load_or_fail_with_one_line_naming_the_file(path):
    base = dict(load_scenario(path).raw)
    rng = np.random.default_rng(sum(path.stem.encode()))
    errors = 0
    for i in range(MUTANTS):
        raw = copy.deepcopy(base)
        what = mutate(raw, rng)
        source = f"{path.stem}-mutant{i}.toml"
        try:
            result = outcome(raw, source)
        except Exception as exc:  # the finding is which one
            pytest.fail(f"{what}: {type(exc).__name__}: {exc}")
        if isinstance(result, Scene):
            continue
        errors += 1
        assert "\n" not in result and result.startswith(source), (what, result)
    assert errors > MUTANTS // 2  # most mutations are mistakes the checks must catch


def test_mutants_that_load_run_or_stop_with_one_line(tmp_path, capsys):
    base = dict(load_scenario(ROOT / "scenarios" / "two_squares.toml").raw)
    rng = np.random.default_rng(7)
    ran = 0
    for i in range(200):
        raw = copy.deepcopy(base)
        numbers = [(p, v) for p, v in leaves(raw) if isinstance(v, float)]
        path, _ = numbers[rng.integers(len(numbers))]
        parent(raw, path)[path[-1]] = float(rng.choice([-3.0, 0.01, 7.0, 1e4, 1e-4]))
        if not isinstance(outcome(copy.deepcopy(raw), "m.toml"), Scene):
            continue
        scene = tmp_path / f"m{i}.toml"
        scene.write_text(dump_toml(raw))
        out = tmp_path / f"m{i}.h5"
        code = main(["run", str(scene), "--out", str(out), "--until", "0.005", "--quiet"])
        err = capsys.readouterr().err
        assert "Traceback" not in err, (path, err)
        if code != 0:
            assert code == 2 and err.strip().splitlines()[-1].startswith("taichi-ice: error:")
        ran += 1
        if ran == RUNS:
            break
    assert ran == RUNS
