"""Sweeps: one scene over layouts x friction laws x scene overrides, run in batches on Dask.

    from taichi_ice.sweep import load_sweep, run_sweep
    sweep = load_sweep("sweeps/pillar.toml")
    result = run_sweep(sweep, "out/sweep", workers=2)     # an embedded Dask LocalCluster
    ds = result.dataset()                                  # xarray.Dataset, one row per world

A sweep file (TOML, checked as strictly as a scene file; every message names the file, the
table and the key):

    [sweep]
    scene = "pillar"                  # a scene file (relative to this file) or a bundled scene
    seeds = { start = 0, count = 8 }  # layouts (field-jitter seeds), or a list: [0, 3, 7]
    until = 20.0                      # s; default the scene's duration
    metrics = ["peak_force", "released"]   # kept in the dataset; default all (ensemble.METRICS)
    window = 1.0                      # s: the metrics' window (concentration, final force)
    batch_size = 16                   # worlds per batch; default: the device's share (below)
    runs = [0, 5]                     # worlds whose HDF5 run is written: a list, "all", "none"

    [[law]]                           # one table per law; a list is a grid axis
    law = "coulomb"
    mu = [0.1, 0.5, 0.9]

    [[law]]
    law = "rate-state"                # every law and variant: rate-state, steady-state,
    below_v_star = ["paper", "healing"]   # memory-only, their parameters and choices

    [overrides]                       # scene keys to vary; each a number or a list of them
    "ice.thickness" = [0.2, 0.3]      # [simulation], [ice], [water]: any numeric key
    "body.pusher.speed" = [0.05, 0.1] # body.NAME.KEY and field.NAME.KEY: numeric keys, and
    "field.rubble.area_fraction" = [0.7, 0.85]   # the derived keys speed and area_fraction

The worlds are every law x every combination of override values x every seed (in that
order: world 0 is the first law, the first values, the first seed). Worlds that can share
one ``World`` (the same law kind and theta integrator, ice, water and time step) are cut
into batches; each batch is one ``Simulation`` (``ensemble.run_worlds``) and one task on
``dask.distributed``: an embedded ``LocalCluster`` of ``workers`` processes (one Taichi
runtime each, started once per process) or an existing cluster (``scheduler``). Every world
is bit-identical alone and in any batch (the engine sums forces in fixed point), so the
results do not depend on the number of workers or the batch size; a batch that fails (a
world diverged) is run again world by world, so that one world's failure never cuts another
short.

Everything lands in the output folder as it completes: ``batches/batch-<id>.json`` (written
whole or not at all), so a sweep that is interrupted and started again runs only the worlds
no batch file holds. At the end ``sweep.nc`` (netCDF-4, ``taichi_ice.dataset``) holds one
row per world: the metrics, with units and long names, the coordinates seed, law and every
swept parameter, and which batch ran which world.

Derived overrides: ``body.NAME.speed`` and ``field.NAME.speed`` set the magnitude of the
velocity, keeping its direction; ``field.NAME.area_fraction`` sets the share of the
lattice's area that is ice (block area / (spacing x * spacing y)) by moving the rows closer
or further apart (spacing y), keeping the last row where it is (its distance to whatever
lies ahead) and moving every kinematic body (the pusher) with the first row.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import hashlib
import itertools
import json
import math
import os
import sys
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._version import __version__
from .codes import ThetaMethod
from .ensemble import METRICS
from .errors import Interrupted, OutputError, ScenarioError, TaichiIceError
from .ledger import record_digest
from .table import Table, check_keys, is_number, type_name

__all__ = [
    "Sweep",
    "SweepError",
    "SweepResult",
    "World",
    "WorldPool",
    "load_sweep",
    "parse_sweep",
    "run_batch",
    "run_sweep",
    "sweep_from_dict",
]

_SWEEP_KEYS = ("scene", "seeds", "until", "metrics", "window", "batch_size", "runs")
_TOP_KEYS = ("sweep", "law", "overrides")
# Keys of a scene's tables that an override may set (the scene's own check then reads the
# value); the seed is the sweep's own axis.
_TABLES = ("simulation", "ice", "water")
_DERIVED = {"body": ("speed",), "field": ("speed", "area_fraction")}

# Worlds per batch at most: on a CPU a batch is stepped a thread per world, and more worlds
# than threads only lengthen the batch; on a GPU a batch should fill the device.
MAX_BATCH = {"cpu": 64, "gpu": 4096}
# Most worlds one sweep runs: its plan, its state file and its results (every world's
# metrics) are held in memory and rewritten as it goes; 1e8 seeds used to end in a
# MemoryError after minutes. A million worlds of the pillar scene is ~20 CPU-years.
MAX_WORLDS = 1_000_000
# Most workers of the embedded local cluster (one process and one Taichi runtime each).
MAX_WORKERS = 1024
# A worker compiles the kernels once per layout (WorldPool); a batch shorter than the others
# of its kind is padded to their size when running the copies costs less than a compile.
# Measured on the 2-core VM (pillar scene, 3 worlds): a World built in 4 s and its kernels
# compiled in 15.5 s; a thread steps small worlds at 1.2-1.4 M body-steps/s (world.py).
COMPILE_SECONDS = 20.0
BODY_STEPS_PER_SECOND = 1.2e6

BATCH_DIR = "batches"
DATASET = "sweep.nc"
STATE = "sweep-state.json"
LOG = "sweep-log.json"


class SweepError(TaichiIceError, ValueError):
    """A sweep file (or options) that is not valid, or an output folder that holds another
    sweep; the message names the file, the table and the key, and says how to fix it."""


# --------------------------------------------------------------------------------------------
# The sweep
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class World:
    """One world of a sweep.

    Attributes:
        index: position in the sweep (laws, then override values, then seeds).
        seed: the field-jitter seed. law: the law's table (``Law.to_dict``). label: its label.
        overrides: ``((key, value), ...)`` in the sweep's order.
    """

    index: int
    seed: int
    law: Mapping[str, Any]
    label: str
    overrides: tuple[tuple[str, float], ...]

    @property
    def key(self) -> str:
        """What determines this world's result besides the sweep's scene and settings: the
        name of its result in a batch file, so that a resumed (or grown) sweep finds it."""
        return json.dumps(
            {"law": dict(self.law), "overrides": dict(self.overrides), "seed": self.seed},
            sort_keys=True,
        )

    @property
    def run_name(self) -> str:
        """File name of its HDF5 run: law, override values, seed."""
        parts = [self.label] + [f"{k.rsplit('.', 1)[-1]}{v:g}" for k, v in self.overrides]
        return "_".join(parts) + f"_seed-{self.seed:04d}.h5"


@dataclass(frozen=True)
class Sweep:
    """A validated sweep (``load_sweep``, ``sweep_from_dict``).

    Attributes:
        source: the sweep file (or ``<options>``); text: the sweep as TOML.
        scene: the base Scene. seeds: layouts. laws: friction laws (``friction.Law``).
        overrides: ``{key: (value, ...)}`` in file order. metrics: metric names kept.
        until: end time (s). window: the metrics' window (s).
        batch_size: worlds per batch, or None (chosen from the device and workers).
        runs: world indices whose HDF5 run is written.
    """

    source: str
    text: str
    scene: Any
    seeds: tuple[int, ...]
    laws: tuple[Any, ...]
    overrides: Mapping[str, tuple[float, ...]]
    metrics: tuple[str, ...] = METRICS
    until: float = 0.0
    window: float = 1.0
    batch_size: int | None = None
    runs: frozenset[int] = frozenset()

    def worlds(self) -> list[World]:
        """Every world: each law x each combination of override values x each seed."""
        keys = list(self.overrides)
        combos = list(itertools.product(*(self.overrides[k] for k in keys)))
        out = []
        for law in self.laws:
            for combo in combos:
                for seed in self.seeds:
                    out.append(
                        World(len(out), seed, law.to_dict(), law.label, tuple(zip(keys, combo)))
                    )
        return out

    def scene_for(self, world: World):
        """The Scene of ``world``: overrides applied, reseeded, its law at every contact."""
        return world_scene(self.scene, world.overrides, world.seed, world.law)


def world_scene(base, overrides, seed: int, law: Mapping[str, Any]):
    """``base`` with ``overrides`` applied, reseeded with ``seed`` and ``law`` at every contact.

    Raises:
        ScenarioError: the overridden scene is not valid (the scene's own message).
    """
    from .friction import law_from_table

    scene = apply_overrides(base, overrides) if overrides else base
    return scene.reseeded(seed).with_friction(law_from_table(law))


def apply_overrides(base, overrides: Sequence[tuple[str, float]]):
    """``base`` (a Scene) with each ``(key, value)`` of ``overrides`` set (module docstring).

    Raises:
        ScenarioError: the result is not a valid scene, or a derived key cannot be applied.
    """
    from .scenario import scene_from_dict

    raw = copy.deepcopy(dict(base.raw))
    derived = []
    for key, value in overrides:
        kind, name, leaf = _split(key)
        if kind in _TABLES:
            raw.setdefault(kind, {})[leaf] = value
        elif leaf in _DERIVED[kind]:
            derived.append((kind, name, leaf, value))
        else:
            _named(raw, kind, name)[leaf] = value
    if derived:
        # Derived keys read the scene as the plain overrides left it.
        scene = scene_from_dict(raw, source=base.source)
        for kind, name, leaf, value in derived:
            table = _named(raw, kind, name)
            if leaf == "speed":
                v = np.asarray(table.get("velocity", [0.0, 0.0]), dtype=float)
                norm = float(np.hypot(*v))
                if norm == 0.0:
                    raise ScenarioError(
                        f"{base.source}: override '{key_of(kind, name, leaf)}': {kind} "
                        f"'{name}' does not move, so its speed has no direction; vary its "
                        "velocity in the scene instead"
                    )
                table["velocity"] = (v * (value / norm)).tolist()
            else:
                _set_area_fraction(raw, scene, name, value)
    return scene_from_dict(raw, source=base.source)


def key_of(kind: str, name: str | None, leaf: str) -> str:
    return f"{kind}.{leaf}" if name is None else f"{kind}.{name}.{leaf}"


def _split(key: str) -> tuple[str, str | None, str]:
    kind, _, rest = key.partition(".")
    if kind in _TABLES:
        return kind, None, rest
    name, _, leaf = rest.rpartition(".")
    return kind, name, leaf


def _named(raw: dict, kind: str, name: str) -> dict:
    """The ``[[body]]`` or ``[[field]]`` table of ``raw`` named ``name``."""
    for i, table in enumerate(raw.get(kind, [])):
        if table.get("name", f"{kind}{i}") == name:
            return table
    raise KeyError(name)


def _set_area_fraction(raw: dict, scene, name: str, fraction: float) -> None:
    """Set field ``name``'s row spacing so that ``fraction`` of its lattice area is ice; the
    last row stays, the first row and every kinematic body move by the same distance."""
    from .geometry import mass_properties

    spec = next(f for f in scene.fields if f.name == name)
    area = mass_properties(spec.vertices)[0]
    new_sy = area / (spec.spacing[0] * fraction)
    shift = (spec.rows - 1) * (spec.spacing[1] - new_sy)
    table = _named(raw, "field", name)
    table["spacing"] = [float(spec.spacing[0]), float(new_sy)]
    table["origin"] = [float(spec.origin[0]), float(spec.origin[1] + shift)]
    for body in raw.get("body", []):
        if body.get("kind") == "kinematic":
            x, y = body["position"]
            body["position"] = [x, y + shift]


# --------------------------------------------------------------------------------------------
# Reading a sweep
# --------------------------------------------------------------------------------------------


def load_sweep(path: str | Path) -> Sweep:
    """Read and validate a sweep file.

    Raises:
        SweepError, ScenarioError: the file, its scene or a world's scene is not valid.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise SweepError(f"{path}: cannot read the sweep file ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise SweepError(_not_utf8(path, exc)) from None
    return parse_sweep(text, source=str(path), base_dir=path.parent)


def _not_utf8(path, exc: UnicodeDecodeError) -> str:
    return (
        f"{path}: not UTF-8 text (byte {exc.object[exc.start]:#04x} at offset {exc.start}); "
        "TOML files are UTF-8: save it as UTF-8"
    )


def parse_sweep(text: str, source: str = "<string>", base_dir=".") -> Sweep:
    """Validate a sweep given as TOML text; ``source`` names it in messages, ``base_dir`` is
    where a relative scene path starts."""
    from .tomlio import TOMLDecodeError, loads

    try:
        data = loads(text)
    except TOMLDecodeError as exc:
        raise SweepError(f"{source}: TOML syntax error: {exc}") from None
    return sweep_from_dict(data, source=source, base_dir=base_dir, text=text)


def sweep_from_dict(
    data: Mapping[str, Any], source: str = "<dict>", base_dir=".", text: str | None = None
) -> Sweep:
    """Validate a sweep given as the sweep file's tables (see the module docstring).

    Every world's scene is built here (overrides applied, reseeded), so a value that makes
    a scene invalid is refused before anything runs.

    Raises:
        SweepError: the first problem found, naming the file, the table and the key.
        ScenarioError: the scene file itself is not valid.
    """
    from .scenario import load_scenario
    from .tomlio import dump_toml

    if not isinstance(data, Mapping):
        raise SweepError(f"{source}: a sweep must be a table, got {type_name(data)}")
    try:
        check_keys(source, "the top level", data, _TOP_KEYS, what="table")
        t = Table(source, "[sweep]", data.get("sweep", {}), _SWEEP_KEYS)
    except ScenarioError as exc:
        raise SweepError(str(exc)) from None
    if "sweep" not in data:
        raise SweepError(f'{source}: missing table [sweep]; add it with scene = "<scene file>"')
    scene_name = _string(t, "scene")
    scene_path = Path(base_dir) / scene_name
    scene = load_scenario(scene_path if scene_path.exists() else scene_name)

    seeds = _seeds(t, scene)
    until = _number(t, "until", scene.simulation.duration)
    window = _number(t, "window", 1.0)
    metrics = _metrics(t)
    batch_size = None
    if "batch_size" in t:
        batch_size = _wrap(lambda: t.integer("batch_size", minimum=1))
    laws = _laws(source, data.get("law"), scene)
    overrides = _overrides(source, data.get("overrides", {}), scene)
    n_worlds = len(laws) * len(seeds) * math.prod(len(v) for v in overrides.values())
    if n_worlds > MAX_WORLDS:
        raise SweepError(
            f"{source}: {len(seeds):,} seeds x {len(laws)} laws x the overrides' values make "
            f"{n_worlds:,} worlds: {_too_many(n_worlds)}"
        )
    runs = _runs(t, n_worlds)

    sweep = Sweep(
        source=source,
        text=text if text is not None else dump_toml(data),
        scene=scene,
        seeds=seeds,
        laws=laws,
        overrides=overrides,
        metrics=metrics,
        until=until,
        window=window,
        batch_size=batch_size,
        runs=runs,
    )
    _check_scenes(sweep)
    return sweep


def _too_many(n: int) -> str:
    return (
        f"a sweep runs at most {MAX_WORLDS:,} worlds (its plan and results are held in "
        "memory); split it into several sweeps, each with its own --out"
    )


def _wrap(read):
    try:
        return read()
    except ScenarioError as exc:
        raise SweepError(str(exc)) from None


def _string(t: Table, key: str) -> str:
    return _wrap(lambda: t.string(key))


def _number(t: Table, key: str, default: float) -> float:
    return float(_wrap(lambda: t.number(key, default, positive=True, unit=" s")))


def _error(t: Table, key: str, message: str) -> SweepError:
    return SweepError(str(t.error(key, message)))


def _seeds(t: Table, scene) -> tuple[int, ...]:
    v = t.get("seeds", [scene.simulation.seed])
    fix = "write a list of seeds, [0, 1, 2], or a range, { start = 0, count = 8 }"
    if isinstance(v, Mapping):
        r = _wrap(lambda: Table(t.source, "[sweep] seeds", v, ("start", "count")))
        start = _wrap(lambda: r.integer("start", 0, minimum=0))
        count = _wrap(lambda: r.integer("count", minimum=1))
        if count > MAX_WORLDS:
            raise _error(t, "seeds", f"count = {count:,}: {_too_many(count)}")
        return tuple(range(start, start + count))
    if not isinstance(v, (list, tuple)) or not v:
        raise _error(t, "seeds", f"expected a list or a range, got {type_name(v)}; {fix}")
    for s in v:
        if not isinstance(s, int) or isinstance(s, bool) or s < 0:
            raise _error(t, "seeds", f"{s!r} is not a whole number >= 0; {fix}")
    if len(set(v)) != len(v):
        raise _error(t, "seeds", f"seeds repeat in {list(v)}; give each once")
    return tuple(int(s) for s in v)


def _metrics(t: Table) -> tuple[str, ...]:
    v = t.get("metrics", list(METRICS))
    if not isinstance(v, (list, tuple)) or not v or not all(isinstance(m, str) for m in v):
        raise _error(t, "metrics", f"expected a list of metric names, got {type_name(v)}")
    for m in v:
        _known(f"{t.source}: [sweep], key 'metrics'", m, METRICS, what="metric")
    return tuple(v)


def _runs(t: Table, n_worlds: int) -> frozenset[int]:
    v = t.get("runs", "none")
    if v == "all":
        return frozenset(range(n_worlds))
    if v == "none":
        return frozenset()
    if not isinstance(v, (list, tuple)) or not all(
        isinstance(i, int) and not isinstance(i, bool) for i in v
    ):
        raise _error(t, "runs", f'expected "all", "none" or a list of world indices, got {v!r}')
    bad = [i for i in v if not 0 <= i < n_worlds]
    if bad:
        raise _error(
            t,
            "runs",
            f"world {bad[0]} does not exist: the sweep has {n_worlds} (0 to {n_worlds - 1})",
        )
    return frozenset(v)


def _laws(source: str, tables: Any, scene) -> tuple[Any, ...]:
    """Every law of the ``[[law]]`` tables, each table's lists expanded as a grid."""
    from .friction import LawError, law_from_table

    if tables is None:
        return (scene.friction,)
    if not isinstance(tables, list) or not tables:
        raise SweepError(
            f"{source}: 'law' must be an array of tables: write [[law]] (double brackets)"
        )
    laws: dict[str, tuple[Any, str]] = {}
    for i, table in enumerate(tables):
        label = f"[[law]] #{i}"
        if not isinstance(table, Mapping):
            raise SweepError(f"{source}: {label} must be a table, got {type_name(table)}")
        if "law" not in table:
            raise SweepError(
                f"{source}: {label}: missing key 'law'; add law = \"coulomb\" (or "
                '"rate-state", ...)'
            )
        keys = list(table)
        axes = []
        for key in keys:
            value = table[key]
            if isinstance(value, list):
                if not value:
                    raise SweepError(
                        f"{source}: {label}, key '{key}': an empty list; give one value or more"
                    )
                if key == "law":
                    raise SweepError(
                        f"{source}: {label}, key 'law': one law per table; add a [[law]] "
                        "table per law"
                    )
                axes.append(value)
            else:
                axes.append([value])
        for combo in itertools.product(*axes):
            try:
                law = law_from_table(dict(zip(keys, combo)))
            except LawError as exc:
                key = f", key '{exc.key}'" if exc.key else ""
                raise SweepError(
                    f'{source}: {label} (law = "{table["law"]}"){key}: {exc}'
                ) from None
            ident = json.dumps(law.to_dict(), sort_keys=True)
            if ident in laws:
                raise SweepError(
                    f"{source}: {label}: the law {law.label} is already in {laws[ident][1]}; "
                    "give each law once"
                )
            laws[ident] = (law, label)
    return tuple(law for law, _ in laws.values())


def _overrides(source: str, table: Any, scene) -> dict[str, tuple[float, ...]]:
    """``{dotted key: values}``; TOML's dotted keys (``ice.thickness = ...``) arrive nested."""
    if not isinstance(table, Mapping):
        raise SweepError(f"{source}: [overrides] must be a table, got {type_name(table)}")
    flat: dict[str, Any] = {}

    def walk(prefix: str, v: Any) -> None:
        if isinstance(v, Mapping):
            for k, x in v.items():
                walk(f"{prefix}.{k}" if prefix else k, x)
        else:
            flat[prefix] = v

    walk("", table)
    out = {}
    for key, value in flat.items():
        where = f"{source}: [overrides], key '{key}'"
        _check_override_key(where, key, scene)
        values = value if isinstance(value, list) else [value]
        if not values or not all(is_number(x) for x in values):
            raise SweepError(
                f"{where}: expected a number or a list of numbers, got {type_name(value)}; "
                "vary a vector through its derived key (speed) or write it in the scene"
            )
        if len(set(values)) != len(values):
            raise SweepError(f"{where}: values repeat in {values}; give each once")
        out[key] = tuple(values)
    return out


def _check_override_key(where: str, key: str, scene) -> None:
    from .scenario import _BODY_KEYS, _FIELD_KEYS, _ICE_KEYS, _SIMULATION_KEYS, _WATER_KEYS

    kind, name, leaf = _split(key)
    form = "TABLE.KEY ([simulation], [ice], [water]) or body.NAME.KEY / field.NAME.KEY"
    known = {"simulation": _SIMULATION_KEYS, "ice": _ICE_KEYS, "water": _WATER_KEYS}
    if kind in known:
        if leaf == "seed" and kind == "simulation":
            raise SweepError(f"{where}: the seed is the sweep's own axis; use [sweep] seeds")
        if kind == "water" and scene.water is None:
            raise SweepError(
                f"{where}: the scene has no [water] table (no drag); add one to the scene"
            )
        _known(where, leaf, known[kind])
        return
    if kind not in ("body", "field") or not name or not leaf:
        raise SweepError(f"{where}: not a scene key; write {form}")
    names = [b.name for b in scene.bodies] if kind == "body" else [f.name for f in scene.fields]
    if name not in names:
        listed = ", ".join(names[:12]) or "none"
        plural = "bodies" if kind == "body" else "fields"
        raise SweepError(f"{where}: the scene has no {kind} named '{name}'; its {plural}: {listed}")
    keys = (_BODY_KEYS if kind == "body" else _FIELD_KEYS) + _DERIVED[kind]
    _known(where, leaf, tuple(k for k in keys if k != "name"))


def _known(where: str, leaf: str, keys: Sequence[str], what: str = "key") -> None:
    if leaf not in keys:
        import difflib

        close = difflib.get_close_matches(leaf, keys, n=1)
        hint = f"did you mean '{close[0]}'? " if close else ""
        raise SweepError(f"{where}: unknown {what} '{leaf}'; {hint}known: {', '.join(keys)}")


def _check_scenes(sweep: Sweep) -> None:
    """Build the scene of every combination of override values and seed (laws do not
    change the layout), so that an invalid one is refused before anything runs."""
    keys = list(sweep.overrides)
    for combo in itertools.product(*(sweep.overrides[k] for k in keys)):
        pairs = tuple(zip(keys, combo))
        said = ", ".join(f"{k} = {v:g}" for k, v in pairs)
        try:
            scene = apply_overrides(sweep.scene, pairs) if pairs else sweep.scene
        except ScenarioError as exc:
            raise SweepError(f"{sweep.source}: [overrides] {said}: {exc}") from None
        for seed in sweep.seeds:
            try:
                scene.reseeded(seed)
            except ScenarioError as exc:
                at = f"[overrides] {said}, " if said else ""
                raise SweepError(f"{sweep.source}: {at}seed {seed}: {exc}") from None


# --------------------------------------------------------------------------------------------
# Batches
# --------------------------------------------------------------------------------------------


def _override_scene(sweep: Sweep, overrides, scenes: dict):
    """The sweep's scene with ``overrides`` applied (memoised in ``scenes``)."""
    scene = scenes.get(overrides)
    if scene is None:
        scene = apply_overrides(sweep.scene, overrides) if overrides else sweep.scene
        scenes[overrides] = scene
    return scene


def _share_key(sweep: Sweep, world: World, scenes: dict, law_kind: bool = False) -> str:
    """Worlds with equal keys can share one World: same law kind and integrator, ice, water,
    simulation settings (time step, intervals) and whether their runs are written.

    With ``law_kind``, the key of the compiled kernels instead: the law's name becomes
    "coulomb" or "rate-state" (every other law runs on the rate-and-state kernels), so
    batches of rate-state, steady-state and memory-only worlds of one size share a layout.
    """
    scene = _override_scene(sweep, world.overrides, scenes)
    settings = dataclasses.replace(scene.simulation, seed=0)
    law, method = world.law["law"], world.law.get("method")
    if law_kind:
        # A law without a theta integrator runs on the default one (assemble).
        law = "coulomb" if law == "coulomb" else "rate-state"
        method = method or (None if law == "coulomb" else ThetaMethod.EXPONENTIAL.label)
    return repr(
        (
            law,
            method,
            scene.dt,
            settings,
            scene.ice,
            scene.water,
            world.index in sweep.runs,
        )
    )


@dataclass(frozen=True)
class Batch:
    """A batch of a sweep's plan: its worlds, and ``pad`` copies of its last world run
    with them (not recorded) so that it has the size of the other batches of its layout."""

    worlds: tuple[World, ...]
    pad: int = 0


def plan_batches(
    sweep: Sweep, worlds: Sequence[World], workers: int, arch: str = "cpu"
) -> list[Batch]:
    """Cut ``worlds`` into batches of worlds that can share one World.

    The batch size is the sweep's, or else each group's worlds split evenly over the
    workers (so every worker gets work), at most ``MAX_BATCH`` worlds, the group cut into
    batches whose sizes differ by one at most.

    A worker compiles the kernels once per layout (``WorldPool``), and a batch's layout
    depends on its size: where a kind of batch (the law's kernels, the same scene settings)
    has more batches than there are workers, a batch shorter than the largest of its kind
    is padded with copies of its last world when running them costs less than compiling
    (``COMPILE_SECONDS``, ``BODY_STEPS_PER_SECOND``). Each world is bit-identical in any
    batch, so padding changes the cost, never a result.
    """
    groups: dict[str, list[World]] = {}
    scenes: dict = {}
    for w in worlds:
        groups.setdefault(_share_key(sweep, w, scenes), []).append(w)
    cap = MAX_BATCH["cpu" if arch == "cpu" else "gpu"]
    chunks: list[list[World]] = []
    for group in groups.values():
        if sweep.batch_size:
            size = sweep.batch_size
        else:
            size = min(cap, max(1, math.ceil(len(group) / max(workers, 1))))
            # As even as the number of batches allows: 7 worlds in 4 + 3, not 6 + 1.
            size = math.ceil(len(group) / math.ceil(len(group) / size))
        chunks += [group[i : i + size] for i in range(0, len(group), size)]

    kinds = [_share_key(sweep, c[0], scenes, law_kind=True) for c in chunks]
    largest: dict[str, int] = {}
    for kind, chunk in zip(kinds, chunks):
        largest[kind] = max(largest.get(kind, 0), len(chunk))
    batches = []
    for kind, chunk in zip(kinds, chunks):
        pad = largest[kind] - len(chunk)
        # Only where a worker runs more than one batch of the kind; never a batch whose
        # runs are written (its files are its worlds').
        shared = kinds.count(kind) > max(workers, 1)
        written = chunk[-1].index in sweep.runs
        if not shared or written or _pad_seconds(sweep, chunk, pad) > COMPILE_SECONDS:
            pad = 0
        batches.append(Batch(tuple(chunk), pad))
    return batches


def _pad_seconds(sweep: Sweep, chunk: Sequence[World], pad: int) -> float:
    """Estimated seconds (one thread) to run ``pad`` more copies of a world of ``chunk``."""
    scene = _override_scene(sweep, chunk[-1].overrides, {})
    steps = math.ceil(sweep.until / scene.dt)
    return pad * len(scene.bodies) * steps / BODY_STEPS_PER_SECOND


def contact_slots(sweep: Sweep) -> int:
    """Contact slots per body that every batch of ``sweep`` gets: the most that any world
    needs (``assemble``'s default). Batches of equal slots and size share a layout, so a
    worker compiles once for all of them."""
    from .assemble import assemble

    keys = list(sweep.overrides)
    slots = 1
    for combo in itertools.product(*(sweep.overrides[k] for k in keys)):
        pairs = tuple(zip(keys, combo))
        scene = apply_overrides(sweep.scene, pairs) if pairs else sweep.scene
        # Seeds move blocks, never change their shapes: the slots are the scene's.
        slots = max(slots, assemble([scene], force_dt=True).layout.slots)
    return slots


def batch_id(worlds: Sequence[World]) -> str:
    """A batch's name: a hash of its worlds' keys (the same worlds, the same name)."""
    h = hashlib.sha1("\n".join(w.key for w in worlds).encode()).hexdigest()
    return h[:12]


def batch_spec(
    sweep: Sweep,
    batch: Batch | Sequence[World],
    run_dir: Path | None,
    arch,
    precision,
    slots: int | None = None,
):
    """What a worker needs to run a batch: plain data (it travels to other machines)."""
    if not isinstance(batch, Batch):
        batch = Batch(tuple(batch))
    worlds = batch.worlds
    return {
        "id": batch_id(worlds),
        "scene_text": sweep.scene.text,
        "scene_source": sweep.scene.source,
        "until": sweep.until,
        "window": sweep.window,
        "arch": arch,
        "precision": precision,
        "slots": slots,
        "pad": batch.pad,
        "worlds": [
            {
                "index": w.index,
                "key": w.key,
                "seed": w.seed,
                "law": dict(w.law),
                "overrides": list(w.overrides),
                "run": str(run_dir / w.run_name) if run_dir and w.index in sweep.runs else None,
            }
            for w in worlds
        ],
    }


class WorldPool:
    """The Worlds a process keeps between batches, their kernels compiled.

    A World's kernels specialise on its layout and close over its fields, so each new
    World compiles them all again (about 20 s for the pillar scene on 2 cores). The pool
    hands out an idle World of the same layout reloaded with the new scenes
    (``World.reload``: bit for bit what a new World gives) and builds one only when it has
    none. A World serves one batch at a time: ``lease()`` gives what makes the Worlds of a
    batch (``Simulation(worlds=...)``) and, on leaving, gives them back.

    Attributes:
        built, reloaded: Worlds built, and Worlds handed out again, so far.
    """

    def __init__(self):
        self._idle: list[tuple[Any, str]] = []  # (World, stepping asked for)
        self._lock = threading.Lock()
        self.built = 0
        self.reloaded = 0

    def get(
        self,
        scenes: Sequence,
        dt: float | None = None,
        precision: str = "f64",
        slots: int | None = None,
        force_dt: bool = False,
        stepping: str = "auto",
    ):
        """A World of ``scenes`` (``World``'s arguments): an idle one reloaded, or a new one.
        With ``slots`` None any idle World's slots are taken."""
        from .errors import UsageError
        from .world import World as Engine

        scenes = list(scenes)
        n_bodies = sum(len(s.bodies) for s in scenes)
        with self._lock:
            candidates = [
                (w, step)
                for w, step in self._idle
                if step == stepping
                and w.precision == precision
                and w.layout.n_worlds == len(scenes)
                and w.layout.n_bodies == n_bodies
                and slots in (None, w.layout.slots)
            ]
        for entry in candidates:
            with self._lock:
                if entry not in self._idle:
                    continue
                self._idle.remove(entry)
            try:
                entry[0].reload(scenes, dt=dt, force_dt=force_dt)
            except UsageError:  # another layout: the World is as it was
                self.put(entry[0], stepping)
                continue
            except BaseException:
                self.put(entry[0], stepping)
                raise
            self.reloaded += 1
            return entry[0]
        world = Engine(
            scenes, dt=dt, precision=precision, slots=slots, force_dt=force_dt, stepping=stepping
        )
        self.built += 1
        return world

    def put(self, world, stepping: str = "auto") -> None:
        """Give ``world`` back (built with ``stepping``): the next batch may take it."""
        with self._lock:
            self._idle.append((world, stepping))

    @contextlib.contextmanager
    def lease(self):
        """``with pool.lease() as make: Simulation(scenes, worlds=make)``: the Worlds
        ``make`` hands out go back to the pool on leaving."""
        out: list[tuple[Any, str]] = []

        def make(scenes, **kwargs):
            world = self.get(scenes, **kwargs)
            out.append((world, kwargs.get("stepping", "auto")))
            return world

        try:
            yield make
        finally:
            for world, stepping in out:
                self.put(world, stepping)


# This process's Worlds: a Dask worker keeps them from one batch to the next.
POOL = WorldPool()


def run_batch(spec: dict) -> dict:
    """Run one batch (a Dask task, or in this process): its worlds as one Simulation.

    Taichi starts on the first batch a process runs and stays up for the next ones, and
    so do the Worlds (``POOL``): a batch of a layout this process has run before reuses
    its World, its kernels compiled. ``spec["pad"]`` copies of the last world run along
    (their results dropped). If the batch fails (a world diverged or overflowed), each of
    its worlds is run again alone, so that every world's result is the one it has alone.

    Returns:
        ``{"id", "worker", "wall_time", "world_steps", "worlds": [{"key", "index", "status",
        "failure", "steps", "dt", "metrics"}]}``.
    """
    import socket

    from .ensemble import run_worlds
    from .scenario import parse_scenario

    start = time.perf_counter()
    base = parse_scenario(spec["scene_text"], source=spec["scene_source"])
    worlds = spec["worlds"]
    scenes = [
        world_scene(base, tuple(map(tuple, w["overrides"])), w["seed"], w["law"]) for w in worlds
    ]

    def run(index: list[int], pad: int = 0):
        paths = [worlds[i]["run"] for i in index]
        for p in paths:
            if p:
                Path(p).parent.mkdir(parents=True, exist_ok=True)
        with POOL.lease() as make:
            ens = run_worlds(
                [scenes[i] for i in index] + [scenes[index[-1]]] * pad,
                until=spec["until"],
                out=paths if all(paths) and not pad else None,
                arch=spec["arch"],
                precision=spec["precision"],
                slots=spec.get("slots"),
                window=spec["window"],
                worlds=make,
            )
        return [
            {
                "key": worlds[i]["key"],
                "index": worlds[i]["index"],
                "status": ens.status,
                "failure": ens.failure,
                "steps": ens.steps,
                "dt": ens.dt,
                "metrics": m,
            }
            for i, m in zip(index, ens.metrics)
        ]

    results = run(list(range(len(worlds))), spec.get("pad", 0))
    if len(worlds) > 1 and any(r["status"] != "complete" for r in results):
        results = [r for i in range(len(worlds)) for r in run([i])]
    return {
        "id": spec["id"],
        "worker": f"{socket.gethostname()}:{os.getpid()}",
        "wall_time": time.perf_counter() - start,
        "world_steps": int(sum(r["steps"] for r in results)),
        "worlds": results,
    }


# --------------------------------------------------------------------------------------------
# Running a sweep
# --------------------------------------------------------------------------------------------


@dataclass
class SweepResult:
    """What ``run_sweep`` did.

    Attributes:
        out: the output folder; path: its ``sweep.nc``.
        ran: world indices run this time; reused: world indices found in batch files.
        failed_batches: ``{batch id: error}`` of batches that raised (not written; a resume
            runs them again).
        wall_time: s. world_steps: steps x worlds run this time.
        workers: Dask workers (0: this process).
    """

    out: Path
    path: Path
    ran: list[int]
    reused: list[int]
    failed_batches: dict[str, str]
    wall_time: float
    world_steps: int
    workers: int

    def dataset(self):
        """The per-world dataset, as an ``xarray.Dataset`` (``dataset.open_sweep``)."""
        from .dataset import open_sweep

        return open_sweep(self.path)


def _identity(sweep: Sweep, arch: str, precision: str) -> dict:
    """What every world's result depends on besides its key: a resume must match it."""
    return {
        "scene_sha1": hashlib.sha1(sweep.scene.text.encode()).hexdigest(),
        "until": sweep.until,
        "window": sweep.window,
        "arch": arch,
        "precision": precision,
        "taichi_ice": __version__,
    }


def load_done(out: Path, identity: dict) -> dict[str, dict]:
    """The world results the batch files of ``out`` hold, by world key; refuses a folder
    that holds a sweep of another scene or settings."""
    state = out / STATE
    if state.exists():
        old = _read_json(state)
        if not isinstance(old, dict):
            raise SweepError(
                f"{state}: damaged (not the JSON a sweep writes, or not matching its digest), so "
                "this folder's settings cannot be checked; give another --out, or delete the "
                "folder (or this file, if you are sure the folder holds this sweep) to start "
                "again"
            )
        diff = [k for k in identity if old.get(k) != identity[k]]
        if diff:
            said = ", ".join(f"{k}: {old.get(k)!r} there, {identity[k]!r} now" for k in diff)
            raise SweepError(
                f"{out}: holds a sweep with other settings ({said}); its results cannot be "
                "reused: give another --out, or delete the folder to start again"
            )
    done: dict[str, dict] = {}
    for path in sorted((out / BATCH_DIR).glob("batch-*.json")):
        batch = _read_json(path)
        try:
            worlds = [
                {**w, "batch": batch["id"], "worker": batch["worker"]} for w in batch["worlds"]
            ]
            keys = [w["key"] for w in worlds]
        except (TypeError, KeyError):
            worlds = None
        if worlds is None:
            # Written whole or not at all, so damaged from outside: set aside, and its
            # worlds run again.
            aside = path.with_name(path.name + ".damaged")
            os.replace(path, aside)
            print(
                f"sweep: {path} is damaged; moved to {aside.name}, its worlds run again",
                file=sys.stderr,
            )
            continue
        done.update(zip(keys, worlds))
    return done


def _read_json(path: Path) -> Any:
    """The JSON in ``path``, or None if it is not JSON (truncated, empty, garbled) or is a
    table whose ``digest`` does not match it (a byte damaged that still parses: a metric's
    digit, a status). Tables written before digests have none and are read as they are."""
    try:
        data = json.loads(path.read_bytes().decode("utf-8"))
    except (ValueError, UnicodeDecodeError):
        return None
    if isinstance(data, dict) and "digest" in data:
        if data.pop("digest") != record_digest(data):
            return None
    return data


def _write_json(path: Path, data: Any) -> None:
    """Write ``data`` whole or not at all (a kill mid-write leaves no half file; fsync
    before the rename, so that a power cut does not leave an empty file in its place); a
    table carries the digest ``_read_json`` checks."""
    if isinstance(data, dict):
        data = {**data, "digest": record_digest(data)}
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as fh:
        fh.write(json.dumps(data, indent=1, allow_nan=True) + "\n")
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def default_workers() -> int:
    """One Dask worker per CPU core."""
    return max(1, os.cpu_count() or 1)


def run_sweep(
    sweep: Sweep,
    out: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    arch: str = "cpu",
    precision: str = "f64",
    progress: bool = True,
) -> SweepResult:
    """Run every world of ``sweep`` that ``out`` does not hold yet, then write ``sweep.nc``.

    Args:
        sweep: the sweep.
        out: output folder (created; a folder of the same sweep is resumed).
        workers: Dask workers of an embedded LocalCluster, one process each (default one
            per CPU core); 0 runs the batches here, one after the other, without Dask.
        scheduler: address of a running Dask scheduler (``tcp://host:8786``) to use instead.
        arch, precision: as for ``Simulation`` (every worker uses the same).
        progress: a line per batch on stderr.

    Returns:
        SweepResult. Batches that raised are listed in ``failed_batches``; their worlds are
        NaN with status 'missing' in the dataset, and a resume runs them.
    """
    from .io import RunLock

    if workers is not None and not 0 <= workers <= MAX_WORKERS:
        raise SweepError(
            f"workers = {workers}: use 0 (no Dask) to {MAX_WORKERS} local workers, or "
            "--scheduler for a cluster"
        )
    out = Path(out)
    (out / BATCH_DIR).mkdir(parents=True, exist_ok=True)
    # One sweep a folder: two would both run the missing worlds and race on the dataset.
    lock = RunLock(out / "sweep")
    try:
        lock.acquire()
    except OutputError:
        other = lock.owner()
        raise SweepError(
            f"{out}: another sweep is running in this folder (pid {other.get('pid', '?')} on "
            f"{other.get('host', '?')} since {other.get('since', '?')}); wait for it, or "
            f"give another --out (if it is gone, delete {lock.path})"
        ) from None
    try:
        return _run_sweep(sweep, out, workers, scheduler, arch, precision, progress)
    finally:
        lock.release()


def _run_sweep(sweep, out: Path, workers, scheduler, arch, precision, progress) -> SweepResult:
    from .dataset import build_dataset, write_dataset

    start = time.perf_counter()
    identity = _identity(sweep, arch, precision)
    done = load_done(out, identity)
    _write_json(out / STATE, identity)
    (out / "sweep.toml").write_text(sweep.text)

    worlds = sweep.worlds()
    missing = [w for w in worlds if w.key not in done]
    reused = [w.index for w in worlds if w.key in done]
    n_workers = 0 if scheduler is None and workers == 0 else (workers or default_workers())
    runs_dir = out / "runs" if sweep.runs else None
    failed: dict[str, str] = {}
    ran: list[int] = []
    world_steps = 0
    if missing:
        if scheduler is not None:
            n_workers = 0  # counted once connected
        batches = plan_batches(sweep, missing, max(n_workers, 1), arch)
        slots = contact_slots(sweep)
        specs = [batch_spec(sweep, b, runs_dir, arch, precision, slots) for b in batches]
        say = _Reporter(progress, len(specs), len(missing), len(reused))
        say.start(scheduler or (f"{n_workers} Dask workers" if n_workers else "this process"))
        for spec, result, error in _execute(specs, n_workers, scheduler, say):
            if error:
                failed[spec["id"]] = error
                say.failed(spec, error)
                continue
            result["worlds"] = [
                {**w, "metrics": _keep(w["metrics"], sweep.metrics)} for w in result["worlds"]
            ]
            _write_json(out / BATCH_DIR / f"batch-{result['id']}.json", result)
            for w in result["worlds"]:
                done[w["key"]] = {**w, "batch": result["id"], "worker": result["worker"]}
                ran.append(w["index"])
            world_steps += result["world_steps"]
            say.done(spec, result)
        if scheduler is not None:
            n_workers = say.workers
    elif progress:
        print(
            f"sweep: all {len(worlds)} worlds are in {out}/{BATCH_DIR}; nothing to run",
            file=sys.stderr,
        )

    wall = time.perf_counter() - start
    log_path = out / LOG
    log = _read_json(log_path) if log_path.exists() else []
    if not isinstance(log, list):  # damaged: kept aside, a new log begins
        os.replace(log_path, log_path.with_name(log_path.name + ".damaged"))
        print(f"sweep: {log_path} was damaged; kept as {log_path.name}.damaged", file=sys.stderr)
        log = []
    log.append(
        {
            "started": time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(time.time() - wall)),
            "workers": n_workers,
            "scheduler": scheduler,
            "worlds_run": len(ran),
            "worlds_reused": len(reused),
            "failed_batches": failed,
            "wall_time": wall,
            "world_steps": world_steps,
            "world_steps_per_s": world_steps / wall if wall > 0 else math.nan,
        }
    )
    _write_json(log_path, log)
    ds = build_dataset(sweep, worlds, done, arch=arch, precision=precision)
    path = write_dataset(ds, out / DATASET)
    if progress:
        print(
            f"sweep: {len(ran)} worlds run, {len(reused)} reused, in {wall:.0f} s "
            f"({world_steps / max(wall, 1e-9):.0f} world-steps/s); wrote {path}"
            + (f"; {len(failed)} batches FAILED (run again to retry)" if failed else ""),
            file=sys.stderr,
        )
    return SweepResult(out, path, sorted(ran), reused, failed, wall, world_steps, n_workers)


def _keep(metrics: dict, names: Sequence[str]) -> dict:
    return {k: metrics[k] for k in names}


def _execute(specs: list[dict], workers: int, scheduler: str | None, say):
    """Yield ``(spec, result, error)`` for every batch as it completes."""
    if scheduler is None and workers == 0:
        for spec in specs:
            try:
                yield spec, run_batch(spec), None
            except Interrupted:  # Ctrl-C, SIGTERM: the sweep stops (a resume runs the batch)
                raise
            except TaichiIceError as exc:
                yield spec, None, str(exc)
        return
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        # One single-threaded worker process per slot; Taichi's own thread pool in each gets
        # an equal share of the cores.
        threads = max(1, (os.cpu_count() or 1) // workers)
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            env={"TI_CPU_MAX_NUM_THREADS": str(threads)},
        )
        client = Client(cluster)
    else:
        try:
            client = Client(scheduler, timeout="30s")
        except OSError as exc:
            raise SweepError(
                f"--scheduler {scheduler}: cannot reach a Dask scheduler there ({exc}); start "
                "one with `dask scheduler` and workers with `dask worker ADDRESS`"
            ) from None
    try:
        say.workers = len(client.scheduler_info()["workers"])
        by_key = {}
        futures = []
        for spec in specs:
            f = client.submit(run_batch, spec, key=f"taichi-ice-batch-{spec['id']}", pure=False)
            by_key[f.key] = spec
            futures.append(f)
        for future in as_completed(futures):
            spec = by_key[future.key]
            try:
                yield spec, future.result(), None
            except TaichiIceError as exc:
                yield spec, None, str(exc)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


class _Reporter:
    """A line on stderr per batch: what ran where, how fast, how much is left."""

    def __init__(self, enabled: bool, n_batches: int, n_worlds: int, n_reused: int):
        self.enabled, self.n_batches, self.n_worlds = enabled, n_batches, n_worlds
        self.n_reused = n_reused
        self.k = 0
        self.worlds_done = 0
        self.start_time = time.perf_counter()
        self.workers = 0

    def start(self, where: str) -> None:
        if self.enabled:
            reused = f" ({self.n_reused} already done)" if self.n_reused else ""
            print(
                f"sweep: {self.n_worlds} worlds to run{reused} in {self.n_batches} batches on "
                f"{where}",
                file=sys.stderr,
                flush=True,
            )

    def done(self, spec: dict, result: dict) -> None:
        self.k += 1
        self.worlds_done += len(spec["worlds"])
        if not self.enabled:
            return
        elapsed = time.perf_counter() - self.start_time
        left = elapsed / self.worlds_done * (self.n_worlds - self.worlds_done)
        status = {w["status"] for w in result["worlds"]}
        rate = result["world_steps"] / max(result["wall_time"], 1e-9)
        print(
            f"sweep: batch {self.k}/{self.n_batches} {spec['id']} "
            f"({len(spec['worlds'])} worlds, {spec['worlds'][0]['law']['law']}) "
            f"{'/'.join(sorted(status))} in {result['wall_time']:.0f} s on {result['worker']} "
            f"({rate:.0f} world-steps/s); {self.worlds_done}/{self.n_worlds} worlds, "
            f"~{left:.0f} s left",
            file=sys.stderr,
            flush=True,
        )

    def failed(self, spec: dict, error: str) -> None:
        self.k += 1
        if self.enabled:
            print(f"sweep: batch {spec['id']} FAILED: {error}", file=sys.stderr, flush=True)


# --------------------------------------------------------------------------------------------
# Command line: taichi-ice sweep
# --------------------------------------------------------------------------------------------

EXAMPLES = """examples:
  taichi-ice sweep sweeps/pillar.toml --out out/sweep              # local cluster, worker per core
  taichi-ice sweep sweeps/pillar.toml --out out/sweep --workers 0  # in this process, no Dask
  taichi-ice sweep --scene pillar --seeds 0-15 --friction coulomb:0.5 --friction rate-state \\
      --override field.rubble.area_fraction=0.7,0.85 --until 10 --out out/sweep
  taichi-ice sweep sweeps/pillar.toml --out out/sweep --scheduler tcp://10.0.0.1:8786
Run it again with the same --out to resume: only the worlds no batch file holds run."""


def add_options(p) -> None:
    """The options of ``taichi-ice sweep`` (beside the engine options the CLI adds)."""
    from .cli import parse_friction

    p.epilog = EXAMPLES
    p.add_argument("sweep", nargs="?", help="sweep file (TOML); or give --scene and the axes")
    p.add_argument("--out", required=True, help="output folder (an existing one is resumed)")
    p.add_argument("--scene", help="scene file or bundled scene name (without a sweep file)")
    p.add_argument(
        "--seeds",
        help="layouts: a count from the scene's seed (8), a range (0-15) or a list (0,3,7)",
    )
    p.add_argument(
        "--friction",
        type=parse_friction,
        action="append",
        help="a law (repeatable): coulomb[:MU], rate-state[:..], steady-state, memory-only",
    )
    p.add_argument(
        "--override",
        action="append",
        metavar="KEY=V1,V2",
        help="a scene key and its values (repeatable), e.g. ice.thickness=0.2,0.3",
    )
    p.add_argument("--metrics", help="metrics to keep, comma-separated (default all)")
    add_cluster_options(p)
    p.add_argument(
        "--batch-size", type=_batch_size, default=None, help="worlds per batch (default: auto)"
    )
    p.add_argument("--runs", help='worlds whose HDF5 run is written: "all", "none" or 0,5,9')


def add_cluster_options(p) -> None:
    """``--workers`` and ``--scheduler``: where the batches run (sweep and study)."""
    p.add_argument(
        "--workers",
        type=_workers,
        default=None,
        help="Dask workers of an embedded local cluster (default: one per core; 0: no Dask)",
    )
    p.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://host:8786")


def _workers(text: str) -> int:
    import argparse

    from .cli import _nonnegative_int

    value = _nonnegative_int(text)
    if value > MAX_WORKERS:
        raise argparse.ArgumentTypeError(
            f"{text!r}: at most {MAX_WORKERS} local workers (a process each); for more, "
            "start a Dask cluster and give --scheduler"
        )
    return value


def _batch_size(text: str) -> int:
    from .cli import _positive_int

    return _positive_int(text)


def _seed_option(text: str, scene_seed: int):
    try:
        if "-" in text:
            a, b = (int(x) for x in text.split("-", 1))
            return {"start": a, "count": b - a + 1}
        if "," in text:
            return [int(x) for x in text.split(",") if x.strip()]
        return {"start": scene_seed, "count": int(text)}
    except ValueError:
        raise SweepError(
            f"--seeds {text!r}: use a count (8), a range (0-15) or a list (0,3,7)"
        ) from None


def _number_list(key: str, text: str) -> list:
    values = []
    for item in text.split(","):
        try:
            values.append(int(item) if item.strip().lstrip("-").isdigit() else float(item))
        except ValueError:
            raise SweepError(f"--override {key}={text}: {item!r} is not a number") from None
    return values


def sweep_from_args(args) -> Sweep:
    """The Sweep the command line names: a sweep file (with ``--until``, ``--metrics``,
    ``--batch-size`` and ``--runs`` replacing its values) or ``--scene`` and the axes."""
    from .tomlio import TOMLDecodeError, loads

    axes = {"--scene": args.scene, "--seeds": args.seeds, "--friction": args.friction}
    axes["--override"] = args.override
    if args.sweep:
        given = [k for k, v in axes.items() if v]
        if given:
            raise SweepError(
                f"{args.sweep}: {', '.join(given)} cannot be combined with a sweep file; "
                "write them in its [sweep], [[law]] and [overrides] tables"
            )
        path = Path(args.sweep)
        try:
            text = path.read_text(encoding="utf-8")
            data = loads(text)
        except OSError as exc:
            raise SweepError(
                f"{path}: cannot read the sweep file ({exc.strerror or exc})"
            ) from None
        except UnicodeDecodeError as exc:
            raise SweepError(_not_utf8(path, exc)) from None
        except TOMLDecodeError as exc:
            raise SweepError(f"{path}: TOML syntax error: {exc}") from None
        source, base_dir = str(path), path.parent
    else:
        if not args.scene:
            raise SweepError("give a sweep file, or --scene SCENE with --seeds, --friction ...")
        from .scenario import load_scenario

        seed = load_scenario(args.scene).simulation.seed
        data = {"sweep": {"scene": str(args.scene)}}
        if args.seeds:
            data["sweep"]["seeds"] = _seed_option(args.seeds, seed)
        if args.friction:
            data["law"] = [law.to_dict() for law in args.friction]
        overrides = {}
        for item in args.override or []:
            key, eq, values = item.partition("=")
            if not eq:
                raise SweepError(
                    f"--override {item!r}: write KEY=V1,V2 (e.g. ice.thickness=0.2,0.3)"
                )
            overrides[key.strip()] = _number_list(key, values)
        if overrides:
            data["overrides"] = overrides
        source, base_dir, text = "<command line>", ".", None
    original = dict(data.get("sweep", {}))
    table = dict(original)
    if args.until is not None:
        table["until"] = args.until
    if args.batch_size is not None:
        table["batch_size"] = args.batch_size
    if args.metrics:
        table["metrics"] = [m.strip() for m in args.metrics.split(",")]
    if args.runs:
        runs = args.runs.strip()
        table["runs"] = runs if runs in ("all", "none") else _number_list("runs", runs)
    data = {**data, "sweep": table}
    # The file's own text when the command line changed nothing in it; else the tables.
    text = text if table == original else None
    return sweep_from_dict(data, source=source, base_dir=base_dir, text=text)


def sweep_command(args) -> int:
    """The body of ``taichi-ice sweep``."""
    sweep = sweep_from_args(args)
    result = run_sweep(
        sweep,
        args.out,
        workers=args.workers,
        scheduler=args.scheduler,
        arch=args.arch,
        precision=args.precision,
        progress=not args.quiet,
    )
    print(
        f"wrote {result.path}: {len(result.ran)} worlds run, {len(result.reused)} reused, "
        f"{result.wall_time:.0f} s, {result.world_steps / max(result.wall_time, 1e-9):.0f} "
        "world-steps/s"
    )
    return 1 if result.failed_batches else 0
