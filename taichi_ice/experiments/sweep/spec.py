"""Sweep specifications: one scene over layouts x friction laws x scene overrides, checked.

    from taichi_ice.experiments.sweep.spec import load_sweep
    sweep = load_sweep("sweeps/pillar.toml")
    cases = sweep.worlds()                                # one Case per world, in order

A sweep file (TOML, checked as strictly as a scene file; every message names the file, the
table and the key):

    [sweep]
    scene = "pillar"                  # a scene file (relative to this file) or a bundled scene
    seeds = { start = 0, count = 8 }  # layouts (field-jitter seeds), or a list: [0, 3, 7]
    until = 20.0                      # s; default the scene's duration
    metrics = ["peak_force", "released"]   # kept in the dataset; default all (metrics.METRICS)
    window = 1.0                      # s: the metrics' window (concentration, final force)
    batch_size = 16                   # worlds per batch; default: the device's share
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
order: world 0 is the first law, the first values, the first seed); each is a ``Case``
(its seed, law and override values), and ``Sweep.scene_for`` builds its scene.

Derived overrides: ``body.NAME.speed`` and ``field.NAME.speed`` set the magnitude of the
velocity, keeping its direction; ``field.NAME.area_fraction`` sets the share of the
lattice's area that is ice (block area / (spacing x * spacing y)) by moving the rows closer
or further apart (spacing y), keeping the last row where it is (its distance to whatever
lies ahead) and moving every kinematic body (the pusher) with the first row.

This module reads and checks; it runs nothing. Cutting the worlds into batches is
``sweep.plan``'s, running them ``sweep.run``'s, the command line ``commands.sweep``'s.
"""

from __future__ import annotations

import copy
import itertools
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import ScenarioError, TaichiIceError
from ...scene.table import Table, check_keys, is_number, type_name
from ..metrics import METRICS

__all__ = [
    "Case",
    "Sweep",
    "SweepError",
    "apply_overrides",
    "load_sweep",
    "parse_sweep",
    "sweep_from_dict",
    "world_scene",
]

_SWEEP_KEYS = ("scene", "seeds", "until", "metrics", "window", "batch_size", "runs")
_TOP_KEYS = ("sweep", "law", "overrides")
# Keys of a scene's tables that an override may set (the scene's own check then reads the
# value); the seed is the sweep's own axis.
_TABLES = ("simulation", "ice", "water")
_DERIVED = {"body": ("speed",), "field": ("speed", "area_fraction")}

# Most worlds one sweep runs: its plan, its state file and its results (every world's
# metrics) are held in memory and rewritten as it goes; 1e8 seeds used to end in a
# MemoryError after minutes. A million worlds of the pillar scene is ~20 CPU-years.
MAX_WORLDS = 1_000_000


class SweepError(TaichiIceError, ValueError):
    """A sweep file (or options) that is not valid, or an output folder that holds another
    sweep; the message names the file, the table and the key, and says how to fix it."""


# --------------------------------------------------------------------------------------------
# The sweep
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Case:
    """One case of a sweep: what one of its worlds runs (its scene is ``Sweep.scene_for``).

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

    def worlds(self) -> list[Case]:
        """Every world's case: each law x each combination of override values x each seed."""
        keys = list(self.overrides)
        combos = list(itertools.product(*(self.overrides[k] for k in keys)))
        out = []
        for law in self.laws:
            for combo in combos:
                for seed in self.seeds:
                    out.append(
                        Case(len(out), seed, law.to_dict(), law.label, tuple(zip(keys, combo)))
                    )
        return out

    def scene_for(self, case: Case):
        """The Scene of ``case``: overrides applied, reseeded, its law at every contact."""
        return world_scene(self.scene, case.overrides, case.seed, case.law)


def world_scene(base, overrides, seed: int, law: Mapping[str, Any]):
    """``base`` with ``overrides`` applied, reseeded with ``seed`` and ``law`` at every contact.

    Raises:
        ScenarioError: the overridden scene is not valid (the scene's own message).
    """
    from ...physics.friction_parse import law_from_table
    from ...scene.parse import reseeded

    scene = apply_overrides(base, overrides) if overrides else base
    return reseeded(scene, seed).with_friction(law_from_table(law))


def apply_overrides(base, overrides: Sequence[tuple[str, float]]):
    """``base`` (a Scene) with each ``(key, value)`` of ``overrides`` set (module docstring).

    Raises:
        ScenarioError: the result is not a valid scene, or a derived key cannot be applied.
    """
    from ...scene.parse import scene_from_dict

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
    from ...physics.polygon import mass_properties

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
        raise SweepError(not_utf8(path, exc)) from None
    return parse_sweep(text, source=str(path), base_dir=path.parent)


def not_utf8(path, exc: UnicodeDecodeError) -> str:
    """The message for a sweep (or scene) file that is not UTF-8 text."""
    return (
        f"{path}: not UTF-8 text (byte {exc.object[exc.start]:#04x} at offset {exc.start}); "
        "TOML files are UTF-8: save it as UTF-8"
    )


def parse_sweep(text: str, source: str = "<string>", base_dir=".") -> Sweep:
    """Validate a sweep given as TOML text; ``source`` names it in messages, ``base_dir`` is
    where a relative scene path starts."""
    from ...tomlio import TOMLDecodeError, loads

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
    from ...scene.parse import load_scenario
    from ...tomlio import dump_toml

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
    from ...physics.friction import LawError
    from ...physics.friction_parse import law_from_table

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
    from ...scene.tables import BODY_KEYS, FIELD_KEYS, ICE_KEYS, SIMULATION_KEYS, WATER_KEYS

    kind, name, leaf = _split(key)
    form = "TABLE.KEY ([simulation], [ice], [water]) or body.NAME.KEY / field.NAME.KEY"
    known = {"simulation": SIMULATION_KEYS, "ice": ICE_KEYS, "water": WATER_KEYS}
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
    keys = (BODY_KEYS if kind == "body" else FIELD_KEYS) + _DERIVED[kind]
    if kind == "field":
        # A tessellation or a file field takes its own keys (concentration, floes, ...), and
        # of the derived ones only speed: area_fraction sets a lattice's spacing.
        from ...scene.floes import FILE_KEYS
        from ...scene.voronoi import VORONOI_KEYS

        own = {"voronoi": VORONOI_KEYS, "file": FILE_KEYS}
        spec = next(f for f in scene.fields if f.name == name)
        if getattr(spec, "kind", "lattice") in own:
            keys = (*own[spec.kind], "speed")
    _known(where, leaf, tuple(k for k in keys if k not in ("name", "kind")))


def _known(where: str, leaf: str, keys: Sequence[str], what: str = "key") -> None:
    if leaf not in keys:
        import difflib

        close = difflib.get_close_matches(leaf, keys, n=1)
        hint = f"did you mean '{close[0]}'? " if close else ""
        raise SweepError(f"{where}: unknown {what} '{leaf}'; {hint}known: {', '.join(keys)}")


def _check_scenes(sweep: Sweep) -> None:
    """Build the scene of every combination of override values and seed (laws do not
    change the layout), so that an invalid one is refused before anything runs."""
    from ...scene.parse import reseeded

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
                reseeded(scene, seed)
            except ScenarioError as exc:
                at = f"[overrides] {said}, " if said else ""
                raise SweepError(f"{sweep.source}: {at}seed {seed}: {exc}") from None
