"""Compile once per kind: the wall time from a fresh process to its first steps, for scenes
that differ from one already compiled in a value (stiffness, viscosity, strength, dt, floe
size) or in a size (body count).

    python benchmarks/compile_reuse.py --out out/compile
    python benchmarks/compile_reuse.py --out out/compile --scene scenarios/pushed_field.toml
    python benchmarks/compile_reuse.py --out out/compile-full --optimize full

``--optimize`` is the compile setting every case runs with (``TAICHI_ICE_OPTIMIZE``: off, on
or full; default: the environment's, else on; ``taichi_ice/backend.py``).

Every case runs in a fresh Python process (as a user's next command would), one after the
other, all on one Taichi offline cache that starts empty (``TI_OFFLINE_CACHE_FILE_PATH``, a
temporary folder): the first case compiles every kernel of its kind; a case that reuses them
loads them from the cache. Each process builds a ``Simulation`` of its scene and runs it for
``--until`` simulated seconds; "to first steps" is that wall time (compiling, loading the
cache, building and running), "import" the ``import taichi_ice`` before it. The same
process then changes the scene's stiffness and runs again (``in_process_s``): what a
sweep's second value costs in one process; and then adds three bodies (``in_process_bodies_s``).

Writes ``compile_reuse.json`` (the cases, the machine, the git state) and
``compile_reuse.png`` (a bar a case) into ``--out``, and prints the table.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# (name, what differs from the first case, changes to the scene's tables)
CASES = (
    ("first of its kind", "nothing: an empty cache", {}),
    ("the same scene again", "nothing", {}),
    ("another stiffness", "[ice] contact_stiffness x 2", {"ice.contact_stiffness": 2.0}),
    (
        "another viscosity and stick spring",
        "[ice] contact_viscosity x 0.5, tangential_stiffness 0.4",
        {"ice.contact_viscosity": 0.5, "ice.tangential_stiffness=": 0.4},
    ),
    ("another dt", "[simulation] dt_safety 0.1", {"simulation.dt_safety=": 0.1}),
    ("larger floes", "every outline and position x 1.5 (same count)", {"scale": 1.5}),
    ("one body more", "a copy of the last body, 5 m above it", {"add_body": 1}),
    ("five bodies more", "copies of the last body, 5 m apart above it", {"add_body": 5}),
    ("ten bodies more", "copies of the last body, 5 m apart above it", {"add_body": 10}),
    ("250 bodies more", "copies of the last body, 5 m apart above it", {"add_body": 250}),
    ("260 bodies more", "past the floor of 256 bodies", {"add_body": 260}),
    ("a wall", "a fixed 20 m x 1 m wall 5 m below (a large body)", {"add_wall": 1}),
)


def changed(raw: dict, changes: dict) -> dict:
    """The scene's tables with ``changes``: ``"table.key": factor`` multiplies,
    ``"table.key=": value`` sets, ``"scale"`` scales every outline and position,
    ``"add_body": n`` adds n copies of the last body, 5 m apart above it, ``"add_wall"`` a
    fixed wall 5 m below the origin."""
    import copy

    import numpy as np

    raw = copy.deepcopy(raw)
    for key, value in changes.items():
        if key == "scale":
            for body in raw["body"]:
                for size in ("width", "length", "radius", "side"):
                    if size in body:
                        body[size] = body[size] * value
                if "position" in body:
                    body["position"] = [x * value for x in body["position"]]
                if "vertices" in body:
                    body["vertices"] = (np.asarray(body["vertices"], float) * value).tolist()
            continue
        if key == "add_body":
            last = raw["body"][-1]
            for k in range(1, int(value) + 1):
                extra = copy.deepcopy(last)
                extra["position"] = [last["position"][0], last["position"][1] + 5.0 * k]
                extra["name"] = f"{last.get('name', 'body')}-copy{k}"
                extra.pop("probe", None)
                raw["body"].append(extra)
            continue
        if key == "add_wall":
            raw["body"].insert(  # first: "add_body" copies the last body
                0, {"name": "wall", "shape": "rectangle", "width": 20.0, "length": 1.0,
                    "position": [0.0, -5.0], "kind": "fixed"}
            )  # fmt: skip
            continue
        table, name = key.rstrip("=").split(".")
        section = raw.setdefault(table, {})
        if key.endswith("="):
            section[name] = value
        else:
            from taichi_ice.scene.model import IceProperties

            section[name] = section.get(name, getattr(IceProperties(), name)) * value
    return raw


def worker(scene_path: str, changes: dict, until: float) -> dict:
    """One case in this process: import, build, run; then in the same process the stiffness
    x 3, and three bodies more."""
    start = time.perf_counter()
    from taichi_ice import Simulation, load_scenario
    from taichi_ice.scene.parse import scene_from_dict

    imported = time.perf_counter()
    base = load_scenario(scene_path)
    scene = scene_from_dict(changed(base.raw, changes), source=base.source)
    Simulation(scene, arch="cpu").run(until=until)
    first = time.perf_counter()
    again = scene_from_dict(changed(scene.raw, {"ice.contact_stiffness": 3.0}), base.source)
    Simulation(again, arch="cpu").run(until=until)
    stiffer = time.perf_counter()
    bigger = scene_from_dict(changed(scene.raw, {"add_body": 3}), base.source)
    Simulation(bigger, arch="cpu").run(until=until)
    return {
        "import_s": imported - start,
        "to_first_steps_s": first - imported,
        "in_process_s": stiffer - first,
        "in_process_bodies_s": time.perf_counter() - stiffer,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/compile_reuse"))
    ap.add_argument("--scene", default=str(ROOT / "scenarios" / "two_squares.toml"))
    ap.add_argument("--until", type=float, default=0.05, help="simulated seconds a case runs")
    ap.add_argument(
        "--optimize",
        choices=("off", "on", "full"),
        help="the compile setting of every case (TAICHI_ICE_OPTIMIZE; default: the "
        "environment's, else on)",
    )
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.scene, json.loads(args.worker), args.until)))
        return 0

    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory(prefix="ti-cache-") as cache:
        env = {**os.environ, "TI_OFFLINE_CACHE_FILE_PATH": cache}
        if args.optimize:
            env["TAICHI_ICE_OPTIMIZE"] = args.optimize
        optimize = env.get("TAICHI_ICE_OPTIMIZE") or "on"
        for name, what, changes in CASES:
            cmd = [sys.executable, __file__, "--scene", args.scene, "--until", str(args.until)]
            proc = subprocess.run(
                [*cmd, "--worker", json.dumps(changes)], env=env, capture_output=True, text=True
            )
            if proc.returncode != 0:
                print(proc.stderr[-2000:], file=sys.stderr)
                return 1
            row = {"case": name, "differs": what, **json.loads(proc.stdout.splitlines()[-1])}
            rows.append(row)
            print(
                f"{name:38s} import {row['import_s']:5.1f} s  to first steps "
                f"{row['to_first_steps_s']:5.1f} s  in process, stiffness x 3: "
                f"{row['in_process_s']:5.1f} s, 3 bodies more: {row['in_process_bodies_s']:5.1f} s",
                flush=True,
            )
    git = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    (args.out / "compile_reuse.json").write_text(
        json.dumps(
            {
                "scene": args.scene,
                "until": args.until,
                "machine": platform.platform(),
                "cpus": os.cpu_count(),
                "git": git,
                "optimize": optimize,
                "cases": rows,
            },
            indent=1,
        )
    )
    _chart(rows, args.out / "compile_reuse.png", f"{Path(args.scene).stem} ({optimize})")
    return 0


def _chart(rows, path: Path, scene: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 0.55 * len(rows) + 1.4), layout="constrained")
    y = range(len(rows))
    bars = (
        ("to_first_steps_s", "tab:blue", "fresh process"),
        ("in_process_s", "tab:orange", "same process, stiffness x 3 next"),
        ("in_process_bodies_s", "tab:green", "same process, then 3 bodies more"),
    )
    for k, (key, colour, label) in enumerate(bars):
        ax.barh(
            [i + 0.28 * (k - 1) for i in y],
            [r.get(key, 0.0) for r in rows],
            height=0.26,
            color=colour,
            label=label,
        )
    ax.set_yticks(list(y), [r["case"] for r in rows])
    ax.invert_yaxis()
    ax.set_xlabel("wall time to the first steps (s)")
    ax.set_title(f"{scene}: compiled once per kind, one Taichi cache")
    ax.legend(loc="center right", fontsize=8)
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
