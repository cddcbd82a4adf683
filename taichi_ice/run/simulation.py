"""Simulation: one scene (or a batch of scenes) stepped, sampled and written to HDF5.

    sim = Simulation(load_scenario("scenarios/pillar.toml"), friction=RateState())
    result = sim.run(until=20.0, out="runs/pillar_rs.h5")
    result.series["friction_energy"][-1]

The time step is the scene's (``dt = "auto"`` or seconds), shortened if needed so that an
output interval is a whole number of steps: frames fall exactly on 0, interval, 2 interval...
"""

from __future__ import annotations

import math
import time as _time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import backend
from ..engine.contact_rows import contact_rows
from ..engine.energy import CONTACTS_COLUMN, STATUS_COLUMN
from ..engine.options import Options, options_of
from ..errors import (
    DivergenceError,
    Interrupted,
    RunFileError,
    TaichiIceError,
    UsageError,
)
from ..physics.timestep import check_approach
from . import budget, checkpoint, output, runfile_read
from .progress import Progress, StopRequest
from .runfile import DiskFullError, RunWriter

# The most samples one stepping launch takes (Simulation.run): 0.64 s of the paper's scene
# at its 0.01 s series interval.
SAMPLES_PER_LAUNCH = 64
# Wall-clock seconds between writes of the run files (``Simulation.run(flush_every=)``):
# opening a file and appending to its ~15 datasets costs ~15 ms, as much as stepping a
# batch of 17 small worlds for a frame. Rows wait in memory until then, or until they
# take FLUSH_BYTES.
FLUSH_EVERY = 5.0
FLUSH_BYTES = 64 << 20
# The most steps between two frames: a stepping plan counts steps per sample in 32-bit
# integers (``World.advance_sampled``), and a dt this small is a mistake, not a run.
MAX_STEPS_PER_FRAME = 2**31 - 1


@dataclass
class RunResult:
    """What a run produced, per world (lists have one entry per world; a scene is world 0).

    Attributes:
        series: per world, ``{name: array}`` as in the HDF5 ``/series`` group.
        paths: HDF5 files written (empty if ``out`` was None).
        steps: steps taken; for a failed run, to the sample that found the failure.
        dt: time step (s). wall_time: seconds of wall clock.
        status: 'complete' or 'failed'. failure: the error message if failed.
        warning: why the result is suspect ("" if not): a dt forced above the stability
            limit, a budget residual past ``budget.RESIDUAL_WARNING``.
    """

    series: list[dict[str, np.ndarray]]
    paths: list[Path] = field(default_factory=list)
    steps: int = 0
    dt: float = 0.0
    wall_time: float = 0.0
    status: str = "complete"
    failure: str = ""
    warning: str = ""

    def __getattr__(self, name):
        # A single scene reads like its only world: result.time, result.friction_energy ...
        series = self.__dict__.get("series")
        if series and len(series) == 1 and name in series[0]:
            return series[0][name]
        raise AttributeError(name)


class Simulation:
    """A scene, or a batch of independent scenes, on the Taichi fields of one World.

    Args:
        scene: a Scene, a scene file's path, or a sequence of Scenes run together as
            independent worlds.
        friction: a ``Coulomb`` or ``RateState`` law that replaces the scenes' own.
        options: the engine's settings (``options.Options``: arch, precision, dt, force_dt,
            slots, stepping, integrator; ``energy`` must stay True: a Simulation's outputs
            are its budget's, ``World(scenes, energy=False)`` steps without one); arch and
            precision None are what Taichi already runs in this process, else 'cpu' and
            'f64'; dt None is the scenes'. A dt is refused above the stability limit
            unless ``force_dt``; it is shortened to a whole number of steps per sample and
            frame (``dt_note`` says so).
        **changes: options by name, for short (``Simulation(scene, dt=1e-4, arch="gpu")``).
        worlds: what makes the World, called with the scenes and the Options; default: this
            process's ``pool.POOL`` hands out a World of the same layout that no one uses
            any more (no Simulation, no name holds it), reloaded (nothing compiles again),
            or builds one. A sweep passes one that leases from the pool (``POOL.lease()``).
        contacts: also write every contact at every frame to the run files (``/contacts``,
            ``runfile_contacts``): the contacts of the step that starts at the frame, from
            the state read back (``engine.contact_rows``; the run steps bit for bit as
            without, and costs about 0.2 ms of host time per contact per frame).
    """

    def __init__(
        self,
        scene,
        friction=None,
        options: Options | None = None,
        *,
        worlds=None,
        contacts: bool = False,
        **changes,
    ):
        from ..engine.pool import POOL
        from ..limits import check_size
        from ..scene.model import Scene

        if isinstance(scene, (str, Path)):
            from ..scene.parse import load_scenario

            scene = load_scenario(scene)
        scenes = list(scene) if isinstance(scene, Sequence) else [scene]
        if not scenes:
            raise UsageError("Simulation needs at least one scene; got an empty sequence")
        for s in scenes:
            if not isinstance(s, Scene):
                raise UsageError(
                    f"Simulation takes Scenes (load_scenario(path)) or a scene file's path, "
                    f"got {type(s).__name__}"
                )
        check_size(
            sum(s.n_bodies for s in scenes),
            f"a batch of {len(scenes)} scene(s)",
            fix="run fewer worlds at a time, or smaller scenes",
        )
        if friction is not None:
            scenes = [s.with_friction(friction) for s in scenes]
        if not isinstance(contacts, (bool, np.bool_)):
            raise UsageError(f"contacts must be True or False, got {contacts!r}")
        self.contacts = bool(contacts)
        # The integrator decided (the option's, the files' or the laws'; dt = "auto" follows).
        options, scenes = options_of(options, changes).resolved().for_scenes(scenes)
        if not options.energy:
            # Its series, run files, residual warning and the check that no world creates
            # energy all read the budget (without, it failed later, asking for energy=True).
            raise UsageError(
                "Simulation keeps the energy budget (its series, run files and the check "
                "that no world creates energy read it): energy=False is an option of a World "
                "stepped directly (World(scenes, energy=False): the same trajectories, no "
                "budget); drop energy=False here"
            )
        self.scenes = scenes = list(scenes)
        self.options = options
        self.arch, self.precision = options.arch, options.precision
        first = scenes[0].simulation
        requested, _ = options.time_step(scenes)
        for s in scenes:
            check_approach(s)
        backend.init(options.arch, options.precision)
        # What Taichi actually runs on (a GPU arch resolves to cuda, vulkan or metal).
        self.arch_used = backend.actual_arch() or options.arch
        self.dt_requested = requested
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
        if self.frame_every > MAX_STEPS_PER_FRAME:
            raise UsageError(
                f"dt = {requested:g} s makes {self.frame_every:.3g} steps per frame "
                f"(output_interval {first.output_interval:g} s); the engine takes at most "
                f"{MAX_STEPS_PER_FRAME} (2^31 - 1): use a larger dt or a shorter "
                "[simulation] output_interval"
            )
        self.dt = first.output_interval / self.frame_every
        self.series_every = self.series_every or max(1, round(first.series_interval / self.dt))
        # Said, never silent: the step was shortened so that samples fall on whole steps.
        self.dt_note = ""
        if not math.isclose(self.dt, requested, rel_tol=1e-9):
            self.dt_note = (
                f"dt {requested:.4g} s shortened to {self.dt:.4g} s: a whole number of steps "
                f"per sample ({first.series_interval:g} s) and frame ({first.output_interval:g} s)"
            )
        if worlds is None:
            self.world = POOL.take(scenes, options.replace(dt=self.dt), owner=self)
        else:
            self.world = worlds(scenes, options.replace(dt=self.dt))
        # Said, never silent either: a step forced above the stability limit.
        self.forced_note = ""
        if self.dt > self.world.stable_dt:
            self.forced_note = (
                f"dt = {self.dt:.4g} s is {self.dt / self.world.stable_dt:.3g} x the stability "
                f"limit {self.world.stable_dt:.4g} s (forced): past what the contact "
                "integration is known to resolve"
            )
        # Kinetic and elastic energy at t = 0: the budget's starting capital.
        self.initial_energy = self.world.energies().copy()
        self._probe_slices = self.world.probe_slices()  # each world's probe rows

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
        self._check_status(self.world.data.status.to_numpy()[: len(self.scenes)], self.time)

    def _check_status(self, status: np.ndarray, time: float) -> None:
        """``check`` on the ``(W, len(Status))`` status words read at ``time``."""
        try:
            self.world.raise_for(status, time)
        except DivergenceError as exc:
            if self.dt <= self.world.stable_dt:
                raise
            ratio = self.dt / self.world.stable_dt
            raise DivergenceError(f"{exc}; dt is {ratio:.3g} x the limit (forced)") from None

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
        *,
        overwrite: bool = True,
        resume: bool = False,
        checkpoint_every: float | None = None,
        flush_every: float = FLUSH_EVERY,
    ) -> RunResult:
        """Run to ``until`` (s; default the scene's duration), sampling series and frames.

        Args:
            until: end time (s), measured from t = 0 of the scene: a second ``run`` continues
                from where the first stopped, to this time.
            out: run file (one scene) or one file per world (a batch); None writes nothing.
            progress: show progress on stderr (``progress.Progress``): "compiling kernels",
                then a bar on a terminal or in a notebook, a line at most every 15 s elsewhere.
            overwrite: replace an existing ``out`` (the command line asks ``--overwrite``);
                False refuses it. Two writers of one path are always refused (a lock file).
            resume: continue the run in ``out`` from its checkpoint (``out`` + ".ckpt"):
                the state is restored, rows written after the checkpoint are cut, and the
                run goes on, bit for bit as if it had never stopped.
            checkpoint_every: seconds of wall clock between checkpoints (taken at frames),
                0 for every frame; None for none. Needs ``out``.
            flush_every: seconds of wall clock between writes of the rows kept so far to
                ``out`` (at frames; 0: at every frame); the files are also written at every
                checkpoint, when the rows kept take 64 MiB, and at the end. Between writes a
                file is closed and whole; a reader sees the rows of the last write.

        Returns:
            RunResult with the series of every world.

        Raises:
            DivergenceError, CapacityError, Interrupted (SIGINT or SIGTERM): the run stopped;
                every file written so far is closed with status 'failed' and the reason, and
                stays readable.
            OutputError: ``out`` exists (without ``overwrite``), is taken by another run, or
                cannot be written; raised before any step.
        """
        until = self._end_time(until)
        paths = _paths(out, len(self.scenes))
        if (resume or checkpoint_every is not None) and not paths:
            raise UsageError("checkpoints and resume need an output file (out=...)")
        if checkpoint_every is not None and not checkpoint_every >= 0:
            raise UsageError(f"checkpoint_every = {checkpoint_every!r}: use seconds, 0 or more")
        if not flush_every >= 0:
            raise UsageError(f"flush_every = {flush_every!r}: use seconds, 0 or more")
        claimed: list[Path] = []
        try:
            for p in paths:
                output.claim(p, overwrite=overwrite, resume=resume)
                claimed.append(p)
            return self._run(until, paths, progress, resume, checkpoint_every, flush_every)
        finally:
            for p in claimed:
                output.release(p)

    def _end_time(self, until) -> float:
        if until is None:
            return self.scenes[0].simulation.duration
        try:
            until = float(until)
        except (TypeError, ValueError):
            raise UsageError(f"until = {until!r}: use an end time in seconds") from None
        if not (0.0 < until < math.inf):
            raise UsageError(f"until = {until!r}: use a positive finite end time in seconds")
        if round(until / self.dt) < self.world.steps:
            raise UsageError(
                f"until = {until:g} s is before the simulation's time {self.time:g} s; "
                "until is measured from t = 0 of the scene"
            )
        return until

    def _run(self, until, paths, progress, resume, checkpoint_every, flush_every) -> RunResult:
        n_end = round(until / self.dt)
        attrs = {
            "arch": self.arch_used,
            "arch_requested": self.arch,
            "precision": self.precision,
            "integrator": self.options.integrator,
            "dt": self.dt,
            "dt_requested": self.dt_requested,
            "stable_dt": self.world.stable_dt,
            "wall_time": 0.0,
        }
        series: list[dict[str, list]] = [
            {k: [] for k in ("time", "probe_force", "n_contacts", *budget.SERIES)}
            for _ in self.scenes
        ]
        ckpt_path = checkpoint.path_for(paths[0]) if paths else None
        if resume:
            ckpt = checkpoint.read(ckpt_path)
            checkpoint.restore(self, ckpt, ckpt_path)
            rows = list(zip(ckpt["attrs"]["n_samples"], ckpt["attrs"]["n_frames"]))
            ids = ckpt["attrs"].get("run_ids") or [None] * len(paths)
            if len(rows) != len(paths) or len(ids) != len(paths):
                raise RunFileError(
                    f"{ckpt_path}: a checkpoint of {len(rows)} run file(s), not of these "
                    f"{len(paths)}; start anew with --overwrite"
                )
            for p, (samples, frames), i in zip(paths, rows, ids):  # all before any changes
                runfile_read.check_resumable(p, i, samples, frames, self.contacts)
            writers = [
                RunWriter(p, s, attrs, resume=r, run_id=i, contacts=self.contacts)
                for p, s, r, i in zip(paths, self.scenes, rows, ids)
            ]
            for s, writer in zip(series, writers):
                old = runfile_read.read_run(writer.path)["series"]
                for key in s:
                    s[key].extend(old[key][: writer.n_samples])
            if n_end < self.world.steps:
                raise UsageError(
                    f"until = {until:g} s is before the checkpoint's time {self.time:g} s"
                )
        else:
            if ckpt_path is not None:
                checkpoint.remove(ckpt_path)  # an earlier run's, stale for this one
            writers = [
                RunWriter(p, s, attrs, contacts=self.contacts) for p, s in zip(paths, self.scenes)
            ]
        bar = Progress(n_end, self.dt, enabled=progress)
        bar.compiling(self.world.compiled("sampled"), self.world.steps)
        start = _time.perf_counter()
        last_checkpoint = last_flush = _time.monotonic()
        status, failure, warning = "complete", "", ""
        # Steps to the last sample checked: a failed run's files and result end there (the
        # launch that found it may have stepped on to its plan's end).
        seen = self.world.steps
        stop = StopRequest()
        try:
            with stop.deferring():
                if not resume:
                    rows, impulses = self.world.advance_sampled([(0, 1)])
                    self._sample(series, writers, rows[0], impulses[0], self.world.steps, 0)
                    self._frame(writers)
                k = self.world.steps
                while k < n_end:
                    # Step to the next frame or the end in one go, sampling on the way
                    # (World.advance_sampled: one launch for all of it when the worlds are
                    # stepped a thread each); then the samples in order, each checked.
                    # At most SAMPLES_PER_LAUNCH samples a launch: frames far apart cost no
                    # more host memory, and a stop request waits for no more than that.
                    stop_at = min(k + self.frame_every - k % self.frame_every, n_end)
                    plan, ends, at = [], [], k
                    while at < stop_at and len(plan) < SAMPLES_PER_LAUNCH:
                        n = min(self.series_every - at % self.series_every, stop_at - at)
                        at += n
                        ends.append(at)
                        plan.append((n, int(at % self.series_every == 0 or at == n_end)))
                    rows, impulses = self.world.advance_sampled(plan)
                    # The launch's samples judged at once (the status words, the budget);
                    # only a sample found wanting is judged again, alone, to raise.
                    tripped = self.world.tripped(rows[:, :, STATUS_COLUMN:]).any(axis=1)
                    bad = budget.breaches(rows[:, :, :CONTACTS_COLUMN], self.initial_energy)
                    bad = bad.any(axis=1)  # energy created: the budget's check raises
                    for s, ((_n, record), end) in enumerate(zip(plan, ends)):
                        seen = end
                        if tripped[s]:
                            self._check_status(rows[s, :, STATUS_COLUMN:], end * self.dt)
                        if record:
                            since = end % self.series_every or self.series_every
                            self._sample(series, writers, rows[s], impulses[s], end, since, bad[s])
                    k = ends[-1]
                    bar.update(k)
                    if k % self.frame_every == 0:
                        self._frame(writers)
                        now = _time.monotonic()
                        due = (
                            checkpoint_every is not None
                            and now - last_checkpoint >= checkpoint_every
                            and k < n_end
                        )
                        if (
                            due
                            or now - last_flush >= flush_every
                            or sum(w.buffered_bytes for w in writers) >= FLUSH_BYTES
                        ):
                            for w in writers:
                                w.flush(self.world.steps)
                            last_flush = _time.monotonic()
                        if due:
                            self._checkpoint(ckpt_path, writers)
                            last_checkpoint = _time.monotonic()
                    if stop.signal is not None:
                        if checkpoint_every is not None:
                            for w in writers:
                                w.flush(self.world.steps)
                            self._checkpoint(ckpt_path, writers)
                        raise Interrupted(
                            f"stopped by {stop.signal} at t = {self.time:.4g} s"
                            + (
                                "; continue it with --resume (resume=True)"
                                if checkpoint_every is not None
                                else ""
                            )
                        )
                if checkpoint_every is not None:
                    for w in writers:
                        w.flush(self.world.steps)
                    self._checkpoint(ckpt_path, writers)
            warning = "; ".join(w for w in (self.forced_note, self._budget_warning()) if w)
        except BaseException as exc:
            # Any exception ends the run as failed, ours with their message, any other
            # (a bug, an OSError of the disk) with its type too: a file never says
            # complete for a run that did not complete.
            status = "failed"
            if isinstance(exc, (TaichiIceError, KeyboardInterrupt)):
                failure = str(exc) or type(exc).__name__
            else:
                failure = f"{type(exc).__name__}: {exc}"
            # What was sampled before the failure travels with the error (``exc.result``).
            try:
                exc.result = self._result(series, paths, status, failure, start, seen)
            except AttributeError:  # an exception type that takes no attributes
                pass
            raise
        finally:
            wall = _time.perf_counter() - start
            bar.close()
            unwritten = None
            for w in writers:
                steps = seen if status == "failed" else self.world.steps
                try:
                    w.close(status, failure, steps=steps, wall_time=wall, warning=warning)
                except DiskFullError as exc:  # marked failed; every file is closed first
                    unwritten = unwritten or exc
            if unwritten is not None:
                raise unwritten
        result = self._result(series, paths, status, failure, start, self.world.steps)
        result.warning = warning
        return result

    def _checkpoint(self, path: Path, writers) -> None:
        checkpoint.write(
            self,
            path,
            [w.n_samples for w in writers],
            [w.n_frames for w in writers],
            [w.run_id for w in writers],
        )

    def _budget_warning(self) -> str:
        """A warning when a world's energy budget misses by more than
        ``budget.RESIDUAL_WARNING`` (``budget.residual_warning``)."""
        return budget.residual_warning(self.world.energies(), self.initial_energy)

    def _result(
        self, series, paths, status: str, failure: str, start: float, steps: int
    ) -> RunResult:
        return RunResult(
            series=[{k: np.asarray(v) for k, v in s.items()} for s in series],
            paths=paths,
            steps=steps,
            dt=self.dt,
            wall_time=_time.perf_counter() - start,
            status=status,
            failure=failure,
        )

    def _sample(self, series, writers, rows, impulses, steps, since, breach=True) -> None:
        """Record one sample of every world, taken after ``steps`` steps: ``rows`` ``(W,
        SAMPLE_COLUMNS)`` and the probes' ``impulses`` ``(P, 2)`` over the ``since`` steps
        since the last sample (``World.advance_sampled``); the probe force is their mean.
        Then the budget's check, unless ``breach`` is False (``budget.breaches`` found none
        on these rows already)."""
        t = steps * self.dt
        energies = rows[:, :CONTACTS_COLUMN]
        for w, (s, probes) in enumerate(zip(series, self._probe_slices)):
            force = impulses[probes] / (since * self.dt) if since else impulses[probes] * 0
            contacts = int(rows[w, CONTACTS_COLUMN])
            row = (t, force, contacts, *energies[w])
            for key, value in zip(s, row):
                s[key].append(value)
            if writers:
                writers[w].add_sample(t, force, energies[w], contacts)
        if breach:
            self._check_budget(energies, t)

    def _check_budget(self, energies: np.ndarray, time: float | None = None) -> None:
        """Raise DivergenceError if a world's kinetic energy and what it dissipated far
        exceed what came in (``budget.breached``): an explicit integration past its limit
        creates energy from nothing. ``time``: when the energies were taken (default now)."""
        time = self.world.time if time is None else time
        bad = budget.breached(energies, self.initial_energy)
        if bad.size:
            w = int(bad[0])
            now = budget.as_series(energies[w])
            start = budget.as_series(self.initial_energy[w])
            raise DivergenceError(
                f"world {w} created {float(budget.created(now, start)):.4g} J of energy from "
                f"{float(budget.came_in(now, start)):.4g} J in (its kinetic energy and what it "
                f"dissipated exceed what came in by over {100 * budget.BREACH:g} %) at t = "
                f"{time:.4g} s; the run diverged{self._truth()}"
            )

    def _truth(self) -> str:
        """How dt stands against the stability limit, and the fix, for a divergence."""
        limit = self.world.stable_dt
        if self.dt > limit:
            return (
                f": dt = {self.dt:.4g} s is {self.dt / limit:.3g} x the stability limit "
                f"{limit:.4g} s (forced); lower dt below the limit (or use dt = 'auto' "
                "without force_dt)"
            )
        return (
            f" at dt = {self.dt:.4g} s, {self.dt / limit:.3g} x the stability limit "
            f"{limit:.4g} s: lower dt (or the scene's dt_safety)"
        )

    def _frame(self, writers) -> None:
        if not writers:
            return
        pos, ang, vel, om = self.world.motion()
        rows = contact_rows(self.world) if self.contacts else [None] * len(writers)
        for w, sl, r in zip(writers, self.world.world_slices(), rows):
            w.add_frame(self.world.time, pos[sl], ang[sl], vel[sl], om[sl], contacts=r)


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
