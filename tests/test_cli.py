"""The taichi-ice command: a run writes its file and summary; mistakes end in one line."""

from __future__ import annotations

import subprocess
import sys

import h5py
import pytest

from taichi_ice.commands.args import parse_friction
from taichi_ice.commands.cli import main
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
