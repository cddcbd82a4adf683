"""Where a cold `make test` spends its compiling: every Taichi kernel the suite's pytest
workers compile, by test file and by kernel, from an empty Taichi cache.

    python benchmarks/suite_compile.py --out out/suite_compile            # the CPU suite, 2 workers
    python benchmarks/suite_compile.py --out DIR -- tests/test_engine.py  # pytest's arguments

The suite runs as `make test` runs it (`-n JOBS --dist loadfile`), on a Taichi cache that
starts empty in ``--out``, with this file loaded into each worker as a pytest plugin
(``-p suite_compile``): it wraps Taichi's ``Kernel.materialize`` (the Python front end of a
new instance of a kernel) and the first launch of that instance (its compile, and one run),
and writes a row per compile to ``--out/rows/<pid>.jsonl``: the worker, the test, the
kernel, the class of the object it belongs to, a hash of that object's ``layout`` (the
engine's stages carry one) and the layout's fields, the front end's and the first launch's
seconds. Processes the
tests start (the command line's tests) are not counted.

Writes ``pytest.log`` (pytest's output, as it runs), ``suite_compile.json`` (the wall time,
pytest's last line, the sums by worker, test file and kernel, the kernels compiled by both
workers and those compiled more than once in one worker) and ``suite_compile.png`` (the
compile seconds of the costliest test files).
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def pytest_configure(config) -> None:
    """Loaded as a plugin (``-p suite_compile``): log every compile of this process."""
    folder = os.environ.get("SUITE_COMPILE_ROWS")
    if folder:
        install(Path(folder))


def install(folder: Path) -> None:
    """Wrap Taichi's kernel front end and launch so that each new kernel instance's compile
    writes a row to ``folder/<pid>.jsonl``."""
    import taichi.lang.kernel_impl as kernel_impl

    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{os.getpid()}.jsonl"
    pending: dict[int, tuple[str, str, str, float, dict]] = {}
    materialize, launch = kernel_impl.Kernel.materialize, kernel_impl.Kernel.launch_kernel

    def owner(args) -> tuple[str, str, dict]:
        if not args:
            return "", "", {}
        layout = getattr(args[0], "layout", None)
        if layout is None:
            return type(args[0]).__name__, "", {}
        mark = hashlib.sha1(repr(layout).encode()).hexdigest()[:10]
        fields = dataclasses.asdict(layout) if dataclasses.is_dataclass(layout) else {}
        return type(args[0]).__name__, mark, fields

    def timed_materialize(self, key=None, args=None, arg_features=None):
        new = key not in self.compiled_kernels
        start = time.perf_counter()
        out = materialize(self, key=key, args=args, arg_features=arg_features)
        if new:
            cls, mark, fields = owner(args)
            front = time.perf_counter() - start
            pending[id(self.compiled_kernels[key])] = (self.func.__name__, cls, mark, front, fields)
        return out

    def timed_launch(self, t_kernel, *args):
        entry = pending.pop(id(t_kernel), None)
        if entry is None:
            return launch(self, t_kernel, *args)
        start = time.perf_counter()
        out = launch(self, t_kernel, *args)
        row = {
            "worker": os.environ.get("PYTEST_XDIST_WORKER", ""),
            "test": os.environ.get("PYTEST_CURRENT_TEST", "").split(" ")[0],
            "kernel": entry[0],
            "owner": entry[1],
            "layout": entry[2],
            "front_s": entry[3],
            "launch_s": time.perf_counter() - start,
            "layout_fields": entry[4],
        }
        with open(path, "a") as f:
            f.write(json.dumps(row) + "\n")
        return out

    kernel_impl.Kernel.materialize = timed_materialize
    kernel_impl.Kernel.launch_kernel = timed_launch


def summarise(rows: list[dict]) -> dict:
    """The rows' sums (s): by worker, test file and kernel (``owner.kernel``); the seconds
    spent compiling again what the other worker compiled (a kernel of one owner and layout:
    the cheaper copy counted), and what one worker compiled more than once (other fields of
    one layout: every copy after the first). Kernels whose owner carries no layout (Taichi's
    ``to_numpy``, the engine's ``Transfer``) are not told apart: left out of those two."""

    def cost(r):
        return r["front_s"] + r["launch_s"]

    def total(by):
        sums: dict[str, float] = collections.defaultdict(float)
        for r in rows:
            sums[by(r)] += cost(r)
        return dict(sorted(sums.items(), key=lambda kv: -kv[1]))

    kind = collections.defaultdict(list)
    for r in rows:
        if r["layout"]:
            kind[(r["owner"], r["kernel"], r["layout"])].append(r)
    across = 0.0
    again = 0.0
    for copies in kind.values():
        workers = collections.defaultdict(list)
        for r in copies:
            workers[r["worker"]].append(cost(r))
        if len(workers) > 1:
            across += min(min(c) for c in workers.values())
        again += sum(sum(c) - c[0] for c in workers.values())
    return {
        "kernels": len(rows),
        "compile_s": sum(cost(r) for r in rows),
        "front_s": sum(r["front_s"] for r in rows),
        "by_worker": total(lambda r: r["worker"] or "main"),
        "by_file": total(lambda r: r["test"].split("::")[0] or "(outside a test)"),
        "by_kernel": total(lambda r: f"{r['owner']}.{r['kernel']}".lstrip(".")),
        "both_workers_s": across,
        "again_in_a_worker_s": again,
    }


def plot(summary: dict, path: Path, files: int = 20) -> None:
    """The compile seconds of the ``files`` costliest test files (bars)."""
    from matplotlib.figure import Figure

    items = list(summary["by_file"].items())[:files][::-1]
    fig = Figure(figsize=(8, 0.3 * len(items) + 1.4), constrained_layout=True)
    ax = fig.subplots()
    ax.barh([k.replace("tests/", "") for k, _ in items], [v for _, v in items], color="C0")
    ax.set_xlabel("compile seconds (front end + first launch), summed over workers")
    ax.set_title(
        f"Cold suite: {summary['kernels']} kernels compiled, {summary['compile_s']:.0f} s "
        f"of {summary['wall_s']:.0f} s wall x {len(summary['by_worker'])} workers",
        fontsize=10,
    )
    ax.tick_params(axis="y", labelsize=7)
    fig.savefig(path, dpi=80)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="out/suite_compile", help="output folder")
    parser.add_argument("--jobs", type=int, default=2, help="pytest workers (make test's JOBS)")
    parser.add_argument("pytest_args", nargs="*", help="after --: pytest's (default: tests)")
    args = parser.parse_args(argv)
    out = Path(args.out)
    rows_dir = out / "rows"
    if rows_dir.exists():
        for old in rows_dir.glob("*.jsonl"):
            old.unlink()
    cache = out / "ticache"
    cache.mkdir(parents=True, exist_ok=True)
    if any(cache.iterdir()):
        print(f"suite_compile: {cache} is not empty: remove it for a cold run", file=sys.stderr)
        return 2
    env = dict(os.environ)
    env["TI_OFFLINE_CACHE_FILE_PATH"] = str(cache.resolve())
    env["SUITE_COMPILE_ROWS"] = str(rows_dir.resolve())
    env["PYTHONPATH"] = os.pathsep.join(
        p for p in (str(ROOT), str(ROOT / "benchmarks"), env.get("PYTHONPATH", "")) if p
    )
    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider"]
    command += ["-p", "suite_compile", "-n", str(args.jobs), "--dist", "loadfile"]
    command += args.pytest_args or ["tests"]
    log = out / "pytest.log"
    print(f"suite_compile: running the suite cold (pytest's output: {log}) ...", flush=True)
    start = time.perf_counter()
    with open(log, "w") as f:
        done = subprocess.run(command, cwd=ROOT, env=env, stdout=f, stderr=subprocess.STDOUT)
    wall = time.perf_counter() - start
    lines = [ln for ln in log.read_text().splitlines() if ln.strip()]
    rows = [
        json.loads(ln)
        for f in sorted(rows_dir.glob("*.jsonl"))
        for ln in f.read_text().splitlines()
    ]
    summary = {"wall_s": wall, "pytest": lines[-1] if lines else "", "exit": done.returncode}
    summary.update(summarise(rows))
    (out / "suite_compile.json").write_text(json.dumps(summary, indent=1) + "\n")
    plot(summary, out / "suite_compile.png")
    print(
        f"suite_compile: {summary['pytest']} ({wall:.0f} s); {summary['kernels']} kernels, "
        f"{summary['compile_s']:.0f} s compiling in the workers "
        f"({', '.join(f'{k} {v:.0f} s' for k, v in summary['by_worker'].items())}); "
        f"wrote {out}/suite_compile.json and .png"
    )
    return done.returncode


if __name__ == "__main__":
    sys.exit(main())
