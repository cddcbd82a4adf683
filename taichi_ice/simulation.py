"""Simulation: one scene (or a batch of scenes) stepped, sampled and written to HDF5.

    sim = Simulation(load_scenario("scenarios/pillar.toml"), friction=RateState())
    result = sim.run(until=20.0, out="runs/pillar_rs.h5")
    result.series["friction_energy"][-1]

The time step is the scene's (``dt = "auto"`` or seconds), shortened if needed so that an
output interval is a whole number of steps: frames fall exactly on 0, interval, 2 interval...
"""

from __future__ import annotations

import math
import sys
import time as _time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import backend, budget
from .errors import DivergenceError, TaichiIceError
from .io import RunWriter


@dataclass
class RunResult:
    """What a run produced, per world (lists have one entry per world; a scene is world 0).

    Attributes:
        series: per world, ``{name: array}`` as in the HDF5 ``/series`` group.
        paths: HDF5 files written (empty if ``out`` was None).
        steps: steps taken. dt: time step (s). wall_time: seconds of wall clock.
        status: 'complete' or 'failed'. failure: the error message if failed.
    """

    series: list[dict[str, np.ndarray]]
    paths: list[Path] = field(default_factory=list)
    steps: int = 0
    dt: float = 0.0
    wall_time: float = 0.0
    status: str = "complete"
    failure: str = ""

    def __getattr__(self, name):
        # A single scene reads like its only world: result.time, result.friction_energy ...
        series = self.__dict__.get("series")
        if series and len(series) == 1 and name in series[0]:
            return series[0][name]
        raise AttributeError(name)


class Simulation:
    """A scene, or a batch of independent scenes, on the Taichi fields of one World.

    Args:
        scene: a Scene, or a sequence of Scenes run together as independent worlds.
        friction: a ``Coulomb`` or ``RateState`` law that replaces the scenes' own.
        arch: 'cpu' or 'gpu'. precision: 'f64' or 'f32'.
        dt: time step (s) overriding the scenes' (still refused above the stability limit
            unless ``force_dt``).
        slots: contact slots per body (default sized from the scene).
        stepping: how the worlds are stepped (``World``): "auto", "worlds" (a thread per
            world, many steps per kernel launch) or "bodies" (parallel over bodies).
    """

    def __init__(
        self,
        scene,
        friction=None,
        arch: str = "cpu",
        precision: str = "f64",
        dt: float | None = None,
        force_dt: bool = False,
        slots: int | None = None,
        stepping: str = "auto",
    ):
        from .world import World

        scenes = list(scene) if isinstance(scene, Sequence) else [scene]
        if friction is not None:
            scenes = [s.with_friction(friction) for s in scenes]
        self.scenes = scenes
        self.arch, self.precision = arch, precision
        backend.init(arch, precision)
        first = scenes[0].simulation
        requested = dt if dt is not None else min(s.dt for s in scenes)
        # Whole steps per output interval, so frames land on multiples of the interval; and
        # when the series interval divides it (the usual case), whole steps per sample too,
        # so samples land on multiples of theirs (and on every frame).
        samples_per_frame = round(first.output_interval / first.series_interval)
        if samples_per_frame >= 1 and math.isclose(
            samples_per_frame * first.series_interval, first.output_interval, rel_tol=1e-9
        ):
            self.series_every = max(1, math.ceil(first.series_interval / requested * (1 - 1e-12)))
            self.frame_every = samples_per_frame * self.series_every
        else:
            self.frame_every = max(1, math.ceil(first.output_interval / requested * (1 - 1e-12)))
            self.series_every = 0
        self.dt = first.output_interval / self.frame_every
        self.series_every = self.series_every or max(1, round(first.series_interval / self.dt))
        self.world = World(
            scenes,
            dt=self.dt,
            precision=precision,
            slots=slots,
            force_dt=force_dt,
            stepping=stepping,
        )
        # Kinetic and elastic energy at t = 0: the budget's starting capital.
        self.initial_energy = self.world.energies().copy()

    # ----------------------------------------------------------------------------------------

    @property
    def time(self) -> float:
        """Simulated time (s)."""
        return self.world.time

    @property
    def steps(self) -> int:
        return self.world.steps

    def step(self, n: int = 1) -> None:
        """Advance ``n`` steps (no output, no checks; call ``check`` or use ``run``)."""
        self.world.advance(n)

    def check(self) -> None:
        """Raise CapacityError or DivergenceError if the last steps overflowed or diverged."""
        self.world.check()

    def positions(self, world: int = 0) -> np.ndarray:
        """``(N, 2)`` body centroids of one world (m)."""
        return self.world.positions()[self.world.world_slices()[world]]

    def angles(self, world: int = 0) -> np.ndarray:
        return self.world.angles()[self.world.world_slices()[world]]

    def velocities(self, world: int = 0) -> np.ndarray:
        return self.world.velocities()[self.world.world_slices()[world]]

    def omegas(self, world: int = 0) -> np.ndarray:
        return self.world.omegas()[self.world.world_slices()[world]]

    def energies(self, world: int = 0) -> dict[str, float]:
        """The energy budget of one world now (J), with its residual (``budget``)."""
        out = {k: float(v) for k, v in budget.as_series(self.world.energies()[world]).items()}
        out["residual"] = float(budget.residual(out, budget.as_series(self.initial_energy[world])))
        return out

    # ----------------------------------------------------------------------------------------

    def run(
        self,
        until: float | None = None,
        out: str | Path | Sequence[str | Path] | None = None,
        progress: bool = False,
    ) -> RunResult:
        """Run to ``until`` (s; default the scene's duration), sampling series and frames.

        Args:
            until: end time (s), measured from t = 0 of the scene.
            out: HDF5 file (one scene) or one file per world (a batch); None writes nothing.
            progress: show a progress bar on stderr.

        Returns:
            RunResult with the series of every world.

        Raises:
            DivergenceError, CapacityError: the run stopped; every file written so far is
                closed with status 'failed' and the reason, and stays readable.
        """
        until = self.scenes[0].simulation.duration if until is None else float(until)
        n_total = round(until / self.dt)
        paths = _paths(out, len(self.scenes))
        attrs = {
            "arch": self.arch,
            "precision": self.precision,
            "dt": self.dt,
            "stable_dt": self.world.stable_dt,
            "wall_time": 0.0,
        }
        # No ``out``: no files; otherwise _paths gave one path per scene.
        writers = [RunWriter(p, s, attrs) for p, s in zip(paths, self.scenes)] if paths else []
        series: list[dict[str, list]] = [
            {k: [] for k in ("time", "probe_force", "n_contacts", *budget.SERIES)}
            for _ in self.scenes
        ]
        bar = Progress(n_total, self.dt, enabled=progress)
        start = _time.perf_counter()
        status, failure = "complete", ""
        try:
            self._sample(series, writers, sample_dt=self.series_every * self.dt)
            self._frame(writers)
            k = 0
            while k < n_total:
                # Step to the next sample, frame or the end in one go (World.advance: one
                # launch for all of them when the worlds are stepped a thread each).
                stride = min(
                    self.series_every - k % self.series_every,
                    self.frame_every - k % self.frame_every,
                    n_total - k,
                )
                self.world.advance(stride)
                k += stride
                if k % self.series_every == 0 or k == n_total:
                    self.world.check()
                    steps_since = k % self.series_every or self.series_every
                    self._sample(series, writers, sample_dt=steps_since * self.dt)
                    bar.update(k)
                if k % self.frame_every == 0:
                    self._frame(writers)
                    for w in writers:
                        w.flush(self.world.steps)
        except (TaichiIceError, KeyboardInterrupt) as exc:
            status = "failed"
            failure = str(exc) or type(exc).__name__
            # What was sampled before the failure travels with the error (``exc.result``).
            exc.result = self._result(series, paths, status, failure, start)
            raise
        finally:
            wall = _time.perf_counter() - start
            bar.close()
            for w in writers:
                w.close(status, failure, steps=self.world.steps, wall_time=wall)
        return self._result(series, paths, status, failure, start)

    def _result(self, series, paths, status: str, failure: str, start: float) -> RunResult:
        return RunResult(
            series=[{k: np.asarray(v) for k, v in s.items()} for s in series],
            paths=paths,
            steps=self.world.steps,
            dt=self.dt,
            wall_time=_time.perf_counter() - start,
            status=status,
            failure=failure,
        )

    def _sample(self, series, writers, sample_dt: float) -> None:
        energies = self.world.energies()
        impulses = self.world.take_probe_impulses()
        contacts = self.world.contact_counts()
        t = self.world.time
        for w, (s, probes) in enumerate(zip(series, self.world.probe_slices())):
            force = impulses[probes] / sample_dt if self.world.steps else impulses[probes] * 0
            row = (t, force, int(contacts[w]), *energies[w])
            for key, value in zip(s, row):
                s[key].append(value)
            if writers:
                writers[w].add_sample(t, force, energies[w], int(contacts[w]))
        self._check_budget(energies)

    def _check_budget(self, energies: np.ndarray) -> None:
        """Raise DivergenceError if a world holds or has dissipated far more energy than it
        was given: an explicit integration past its limit creates energy from nothing."""
        bad = budget.breached(energies, self.initial_energy)
        if bad.size:
            w = int(bad[0])
            now = budget.as_series(energies[w])
            start = budget.as_series(self.initial_energy[w])
            raise DivergenceError(
                f"world {w} created {-budget.residual(now, start):.4g} J of energy from "
                f"{budget.came_in(now, start):.4g} J in at t = {self.world.time:.4g} s "
                f"(dt = {self.dt:.3g} s); the run diverged: lower dt (or use dt = 'auto' "
                "without force_dt)"
            )

    def _frame(self, writers) -> None:
        if not writers:
            return
        pos, ang = self.world.positions(), self.world.angles()
        vel, om = self.world.velocities(), self.world.omegas()
        for w, sl in zip(writers, self.world.world_slices()):
            w.add_frame(self.world.time, pos[sl], ang[sl], vel[sl], om[sl])


def _paths(out, n_worlds: int) -> list[Path]:
    if out is None:
        return []
    if isinstance(out, (str, Path)):
        if n_worlds != 1:
            raise ValueError(f"a batch of {n_worlds} worlds needs one output path per world")
        return [Path(out)]
    paths = [Path(p) for p in out]
    if len(paths) != n_worlds:
        raise ValueError(f"{len(paths)} output paths for {n_worlds} worlds")
    return paths


class Progress:
    """A one-line progress bar on stderr: simulated time, steps per second, time left."""

    def __init__(self, total: int, dt: float, enabled: bool = True, width: int = 30):
        self.total, self.dt, self.enabled, self.width = max(total, 1), dt, enabled, width
        self.start = _time.perf_counter()
        self.last = 0.0
        # On a terminal the bar redraws in place; in a log file it is a line every 15 s.
        self.tty = sys.stderr.isatty()
        self.every = 0.2 if self.tty else 15.0

    def update(self, k: int) -> None:
        if not self.enabled:
            return
        now = _time.perf_counter()
        if now - self.last < self.every and k < self.total:
            return
        self.last = now
        frac = k / self.total
        rate = k / max(now - self.start, 1e-9)
        eta = (self.total - k) / max(rate, 1e-9)
        filled = int(self.width * frac)
        start, end = ("\r", " ") if self.tty else ("", "\n")
        sys.stderr.write(
            f"{start}[{'#' * filled}{'.' * (self.width - filled)}] {100 * frac:5.1f}%  "
            f"t = {k * self.dt:7.3f} s  {rate:8.0f} steps/s  {eta:5.0f} s left{end}"
        )
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled and self.tty:
            sys.stderr.write("\n")
            sys.stderr.flush()
