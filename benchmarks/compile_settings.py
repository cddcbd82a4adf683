"""The compile settings against each other: how long a World's kernels take to compile in
each (``off``, ``on``, ``full``; ``taichi_ice/backend.py``) and how fast they then step.

    python benchmarks/compile_settings.py --out out/settings
    python benchmarks/compile_settings.py --out out/settings-cuda --arch cuda --blocks 100000
    python benchmarks/compile_settings.py --out out/settings-vk --arch vulkan --no-stepping

Compiling: each case in each setting in a fresh process on an empty Taichi cache (a
temporary folder), the settings in turn, ``--repeat`` rounds: the wall time from the World's
construction to the end of its first step (Taichi's front end, its passes, LLVM or the
SPIR-V compiler, the first launch).

Stepping: one process a case, a World per setting on fields of its own. Taichi reads its
compile options (``backend.COMPILE_OPTIONS``) from its config when a kernel compiles, so the
process sets them before it builds each World. The Worlds are advanced ``--warm`` simulated
seconds (the pillar: into its jam), then timed in ``--pairs`` rounds of one chunk each, the
settings' order rotating from round to round; reported: each setting's median time a step,
the median and quartiles of its chunk over ``full``'s chunk in the same round, and whether
the Worlds' positions and velocities are the same bit for bit at the end.

Cases: the pillar scene with rate and state, a world a thread (``pillar-euler``,
``pillar-coupled``: the coupled step, whose kernels take the advanced passes longest), and a
random box of ``--blocks`` blocks with rate and state, stepped as ``World`` chooses (the team
of threads on the CPU, a kernel per stage on a GPU). Writes ``compile_settings.json`` and
``compile_settings.png`` (compile times; step-time ratios) into ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SETTINGS = ("off", "on", "full")
CASES = ("pillar-euler", "pillar-coupled", "box")


def make_world(case: str, blocks: int):
    """A World of ``case`` (the bench's random box is cached in the system's temp folder)."""
    from taichi_ice import load_scenario
    from taichi_ice.engine.world import World
    from taichi_ice.experiments.bench.scenes import bench_scene
    from taichi_ice.physics.friction_parse import parse_law

    if case == "box":
        cache = Path(tempfile.gettempdir()) / "taichi-ice-bench-scenes"
        cache.mkdir(exist_ok=True)
        scene, _ = bench_scene("random", blocks, "rate-state", False, 0, cache=cache)
        return World([scene])
    scene = load_scenario("pillar").with_friction(parse_law("rate-state"))
    return World([scene], stepping="worlds", integrator=case.split("-")[1])


def compile_worker(case: str, arch: str, blocks: int) -> dict:
    """One case's first step in this process (its setting from the environment)."""
    from taichi_ice import backend

    backend.init(arch)
    start = time.perf_counter()
    world = make_world(case, blocks)
    world.advance(1)
    world.check()
    return {"first_step_s": time.perf_counter() - start, "setting": backend.compile_level()}


def stepping_worker(case: str, arch: str, blocks: int, warm: float, pairs: int) -> dict:
    """The case's Worlds, one a setting, warmed up and timed in alternating chunks."""
    import numpy as np
    from taichi.lang import impl

    from taichi_ice import backend

    backend.init(arch)
    cfg = impl.current_cfg()
    worlds = {}
    for level in SETTINGS:
        for key, value in backend.COMPILE_OPTIONS[level].items():
            setattr(cfg, key, value)
        world = worlds[level] = make_world(case, blocks)
        # Warmed up in its own setting: a kernel first launched now compiles in it too.
        world.advance(int(warm / world.dt) if case != "box" else 50)
        world.check()
    chunk = int(0.05 / worlds["full"].dt) if case != "box" else 30
    times = {level: [] for level in SETTINGS}
    for r in range(pairs):
        for k in range(len(SETTINGS)):
            level = SETTINGS[(r + k) % len(SETTINGS)]
            start = time.perf_counter()
            worlds[level].advance(chunk)
            worlds[level].check()
            times[level].append((time.perf_counter() - start) / chunk)
    ref = worlds["full"]
    out = {"steps_per_chunk": chunk, "stepping": ref.stepping}
    for level in SETTINGS:
        ratios = sorted(a / b for a, b in zip(times[level], times["full"]))
        w = worlds[level]
        out[level] = {
            "us_per_step": 1e6 * statistics.median(times[level]),
            "ratio_to_full": statistics.median(ratios),
            "ratio_quartiles": [ratios[len(ratios) // 4], ratios[(3 * len(ratios)) // 4]],
            "same_bits_as_full": bool(
                np.array_equal(w.positions(), ref.positions())
                and np.array_equal(w.velocities(), ref.velocities())
            ),
        }
    return out


def _run(args, mode: str, case: str, env: dict) -> dict:
    cmd = [
        sys.executable, __file__, "--arch", args.arch, "--blocks", str(args.blocks),
        "--warm", str(args.warm), "--pairs", str(args.pairs), f"--{mode}", case,
    ]  # fmt: skip
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise ChildFailed(f"the {mode} process of {case} failed:\n{proc.stderr[-2000:]}")
    return json.loads(proc.stdout.splitlines()[-1])


class ChildFailed(Exception):
    """A case's process ended with an error (its stderr's end is the message)."""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/compile_settings"))
    ap.add_argument("--arch", default="cpu", help="cpu, cuda, vulkan, ... (backend.ARCHES)")
    ap.add_argument("--cases", default=",".join(CASES), help=f"of {', '.join(CASES)}")
    ap.add_argument("--blocks", type=int, default=10_000, help="blocks of the random box")
    ap.add_argument("--repeat", type=int, default=2, help="compile rounds, the settings in turn")
    ap.add_argument("--warm", type=float, default=8.0, help="pillar's simulated s before timing")
    ap.add_argument("--pairs", type=int, default=30, help="timed rounds of one chunk a setting")
    ap.add_argument("--no-stepping", action="store_true", help="compile times only")
    ap.add_argument("--compile", help=argparse.SUPPRESS)
    ap.add_argument("--stepping", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.compile:
        print(json.dumps(compile_worker(args.compile, args.arch, args.blocks)))
        return 0
    if args.stepping:
        result = stepping_worker(args.stepping, args.arch, args.blocks, args.warm, args.pairs)
        print(json.dumps(result))
        return 0

    cases = [c for c in args.cases.split(",") if c]
    unknown = sorted(set(cases) - set(CASES))
    if unknown:
        ap.error(f"--cases: unknown {', '.join(unknown)}; choose from {', '.join(CASES)}")
    from taichi_ice import backend
    from taichi_ice.errors import BackendError

    try:
        # Taichi falls back to the CPU where the arch is missing: the results would be the
        # CPU's under the GPU's name. A child process tries the arch first.
        args.arch = backend.probe(args.arch)
        args.out.mkdir(parents=True, exist_ok=True)
        return _measure(args, cases)
    except (BackendError, ChildFailed) as e:
        print(f"compile_settings: {e}", file=sys.stderr)
        return 1


def _measure(args, cases: list) -> int:
    compile_rows, stepping_rows = [], {}
    for r in range(args.repeat):
        for case in cases:
            for level in SETTINGS if r % 2 == 0 else SETTINGS[::-1]:
                with tempfile.TemporaryDirectory(prefix="ti-cache-") as cache:
                    env = {**os.environ, "TI_OFFLINE_CACHE_FILE_PATH": cache}
                    env["TAICHI_ICE_OPTIMIZE"] = level
                    row = {"case": case, "setting": level, "round": r}
                    row.update(_run(args, "compile", case, env))
                compile_rows.append(row)
                print(f"compile  {case:15s} {level:5s} {row['first_step_s']:7.1f} s", flush=True)
    if not args.no_stepping:
        with tempfile.TemporaryDirectory(prefix="ti-cache-") as cache:
            env = {**os.environ, "TI_OFFLINE_CACHE_FILE_PATH": cache}
            for case in cases:
                res = _run(args, "stepping", case, env)
                stepping_rows[case] = res
                for level in SETTINGS:
                    s = res[level]
                    q = s["ratio_quartiles"]
                    print(
                        f"stepping {case:15s} {level:5s} {s['us_per_step']:9.1f} us a step, "
                        f"against full {s['ratio_to_full']:.3f} ({q[0]:.3f}-{q[1]:.3f}), "
                        f"same bits: {s['same_bits_as_full']}",
                        flush=True,
                    )
    from taichi_ice.provenance import git_describe

    record = {
        "arch": args.arch,
        "blocks": args.blocks,
        "warm_s": args.warm,
        "pairs": args.pairs,
        "machine": platform.platform(),
        "cpus": os.cpu_count(),
        "git": git_describe(),
        "compile": compile_rows,
        "stepping": stepping_rows,
    }
    (args.out / "compile_settings.json").write_text(json.dumps(record, indent=1) + "\n")
    _chart(record, args.out / "compile_settings.png")
    print(f"wrote {args.out / 'compile_settings.json'} and compile_settings.png")
    return 0


def _chart(record: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = list(dict.fromkeys(r["case"] for r in record["compile"]))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    width = 0.27
    for k, level in enumerate(SETTINGS):
        for i, case in enumerate(cases):
            vals = [
                r["first_step_s"]
                for r in record["compile"]
                if (r["case"], r["setting"]) == (case, level)
            ]
            axes[0].scatter([i + (k - 1) * width] * len(vals), vals, color=f"C{k}", s=18)
            axes[0].bar(i + (k - 1) * width, statistics.median(vals), width, color=f"C{k}",
                        alpha=0.4, label=level if i == 0 else None)  # fmt: skip
    axes[0].set_xticks(range(len(cases)), cases)
    axes[0].set_ylabel("first step from an empty cache (s)")
    axes[0].set_title(f"compiling ({record['arch']})")
    if cases:
        axes[0].legend(title="setting")
    steps = record["stepping"]
    for k, level in enumerate(SETTINGS):
        for i, case in enumerate(steps):
            s = steps[case][level]
            lo, hi = s["ratio_quartiles"]
            mid = s["ratio_to_full"]
            axes[1].errorbar(i + (k - 1) * width, mid, yerr=[[mid - lo], [hi - mid]], fmt="o",
                             color=f"C{k}", label=level if i == 0 else None)  # fmt: skip
    axes[1].axhline(1.0, color="grey", lw=0.8)
    axes[1].set_xticks(range(len(steps)), list(steps))
    axes[1].set_ylabel("time a step / full's (median, quartiles)")
    axes[1].set_title("stepping, alternating chunks in one process")
    if steps:
        axes[1].legend(title="setting")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
