"""The taichi-ice command: a run writes its file and summary; mistakes end in one line."""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

import h5py
import pytest

from taichi_ice.commands.args import parse_dt, parse_duration, parse_friction, positive_float
from taichi_ice.commands.cli import build_parser, main
from taichi_ice.physics.friction import Coulomb, RateState

TWO_SQUARES = "scenarios/two_squares.toml"


def test_run_writes_a_complete_file_and_a_summary(tmp_path, capsys):
    """`run` writes a complete HDF5 file and a one-line summary with the budget residual."""
    out = tmp_path / "sq.h5"
    assert main(["run", TWO_SQUARES, "--out", str(out), "--until", "0.3", "--quiet"]) == 0
    line = capsys.readouterr().out
    assert "wrote" in line and "residual" in line
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "complete"
        assert f["frames/time"][-1] == pytest.approx(0.3)


def test_friction_override_is_recorded(tmp_path):
    """`--friction coulomb:0.3` replaces the scene's law, and the file says so."""
    out = tmp_path / "sq.h5"
    main(
        [
            "run",
            TWO_SQUARES,
            "--out",
            str(out),
            "--until",
            "0.05",
            "--quiet",
            "--friction",
            "coulomb:0.3",
        ]
    )
    with h5py.File(out, "r") as f:
        assert f.attrs["friction"] == "coulomb"
        assert '"mu": 0.3' in f.attrs["friction_params"]


def test_parse_friction():
    """Law strings map to laws with the given parameters; nonsense is refused."""
    assert parse_friction("coulomb:0.9") == Coulomb(0.9)
    assert parse_friction("rate-state:A=0.04,t_c=2") == RateState(A=0.04, t_c=2.0)
    with pytest.raises(Exception, match="unknown law"):
        parse_friction("viscous")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["run", "scenarios/nope.toml"], "cannot read"),
        (["run", TWO_SQUARES, "--dt", "0.01"], "stability limit"),
    ],
)
def test_mistakes_end_in_one_line_without_traceback(args, message):
    """A missing file or an unstable dt: exit 2, one error line naming the fix, no traceback."""
    proc = subprocess.run(
        [sys.executable, "-m", "taichi_ice", *args], capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 2
    assert message in proc.stderr
    assert "Traceback" not in proc.stderr


def test_plot_writes_figures(tmp_path):
    """`plot` writes the probe-force, energy and snapshot figures of a run."""
    out = tmp_path / "sq.h5"
    main(["run", TWO_SQUARES, "--out", str(out), "--until", "0.2", "--quiet"])
    assert main(["plot", str(out), "--out", str(tmp_path / "figs")]) == 0
    names = sorted(p.name for p in (tmp_path / "figs").iterdir())
    assert names == ["sq_energy.png", "sq_positions.png", "sq_probe_force.png"]


def test_a_launch_the_gpu_driver_refuses_ends_in_one_line_and_a_failed_file(
    tmp_path, capsys, monkeypatch
):
    """Lavapipe refuses a launch of more than 65,535 workgroups (Taichi raises a bare
    RuntimeError, "Dispatch error"): one line that says why and what to use, exit 2, and the
    run file kept, marked failed. (The refusal is Taichi's own message, raised here.)"""
    from taichi_ice.engine.world import World

    def refused(self, plan):
        raise RuntimeError(
            "[runtime.cpp:launch_kernel@572] Dispatch error : RhiResult(not_supported)"
        )

    monkeypatch.setattr(World, "advance_sampled", refused)
    out = tmp_path / "sq.h5"
    assert main(["run", TWO_SQUARES, "--out", str(out), "--until", "0.05", "--quiet"]) == 2
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if line.startswith("taichi-ice: error")]
    assert len(errors) == 1 and "Traceback" not in err
    assert "refused a kernel launch" in errors[0] and "--arch cpu" in errors[0]
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "failed"


# Options that take a time (simulated or wall clock), by name; and the value types that read
# one, so that a new time option is caught whatever its name.
TIME_OPTIONS = {"--until", "--dt", "--checkpoint-every", "--box2d-dt"}
TIME_TYPES = (parse_dt, parse_duration, positive_float)
# A unit of time as the help writes it: "in s", "(s)", "seconds", or a duration like 30s, 1h.
TIME_UNIT = re.compile(r"(?<![\w'])s\b|\bseconds?\b|\b\d+(?:s|min|h)\b")


def commands(parser, name="taichi-ice"):
    """``(name, parser)`` of the command and of every subcommand under it."""
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub, p in action.choices.items():
                yield from commands(p, f"{name} {sub}")


def test_every_option_of_every_command_has_help_and_a_time_says_its_unit():
    """`--help` of the command and of each subcommand explains every option and argument
    (-h aside), and the help of each option that takes a time names its unit."""
    missing, unitless, timed = [], [], set()
    found = list(commands(build_parser()))
    assert {name.split()[-1] for name, _ in found} >= {"run", "plot", "paper", "sweep", "study"}
    for name, parser in found:
        parser.format_help()  # every help string formats (a stray % would raise)
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            label = f"{name} {'/'.join(action.option_strings) or action.dest}"
            if not (action.help or "").strip() or action.help == argparse.SUPPRESS:
                missing.append(label)
            for choice in getattr(action, "_choices_actions", []):  # the subcommands listed
                if not (choice.help or "").strip():
                    missing.append(f"{label} {choice.dest}")
            if action.type in TIME_TYPES or TIME_OPTIONS & set(action.option_strings):
                timed.add(label)
                if not TIME_UNIT.search(action.help or ""):
                    unitless.append(f"{label}: {action.help!r}")
    assert missing == []
    assert unitless == []
    assert {"taichi-ice run --until", "taichi-ice run --dt", "taichi-ice bench --box2d-dt"} <= timed
    assert "taichi-ice run --checkpoint-every" in timed


def test_run_help_says_a_bundled_scene_works_and_names_each(capsys):
    """`run --help` says a scene may be a bundled one, and names every scene shipped in
    the package's scenarios folder."""
    shipped = sorted(
        p.stem for p in (Path(__file__).parents[1] / "taichi_ice" / "scenarios").glob("*.toml")
    )
    assert "pillar" in shipped
    with pytest.raises(SystemExit) as exc:
        main(["run", "--help"])
    assert exc.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "bundled with taichi-ice" in text
    for name in shipped:
        assert name in text, name


def test_slots_help_says_what_a_slot_is_and_what_happens_past_it(capsys):
    """`--slots` is explained as the most contacts a body holds at once, with what a run
    does when a body needs more."""
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    options = text[text.index("options:") :]  # past the usage line
    slots = options[options.index("--slots N") : options.index("--integrator {")]
    assert "most contacts one body can hold at once" in slots
    assert "stops the run" in slots and "raise it" in slots


def test_optimize_sets_a_new_taichis_setting_and_refuses_another_in_a_running_one(
    monkeypatch, tmp_path, capsys
):
    """``--optimize`` becomes ``TAICHI_ICE_OPTIMIZE``, which ``backend.init`` reads when it
    starts Taichi and a command's worker processes inherit; a process whose Taichi already
    compiles in another setting (fixed when it starts) refuses it in one line, before any
    file is written."""
    import os

    from taichi_ice import backend

    running = backend.compile_level()  # the session's (tests/conftest.py)
    other = "full" if running != "full" else "off"
    monkeypatch.setenv(backend.OPTIMIZE_ENV, os.environ.get(backend.OPTIMIZE_ENV, ""))
    out = tmp_path / "r.h5"
    args = ["run", TWO_SQUARES, "--optimize", other, "--until", "0.001", "--out", str(out)]
    assert main([*args, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"--optimize {other}" in err and f"'{running}'" in err and "new process" in err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()
    # As in a process that has not started Taichi: the option is the environment's setting.
    monkeypatch.setattr(backend, "_level", None)
    assert backend.ask_optimize(" FULL ") == "full"
    assert os.environ[backend.OPTIMIZE_ENV] == "full"
    assert backend.optimize_level() == "full"
    # The parser takes the three settings only.
    assert build_parser().parse_args(["run", TWO_SQUARES, "--optimize", "on"]).optimize == "on"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["run", TWO_SQUARES, "--optimize", "fast"])
