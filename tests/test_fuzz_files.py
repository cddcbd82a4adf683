"""Property-based fuzzing (hypothesis) of what users and schedulers hand the package: scene
and sweep TOML with any value in any place, and run, checkpoint and ledger files damaged byte
by byte or cut short (issue 27, item 8).

Every outcome must be a result or one of the package's own errors (one line on the command
line, exit 2); never another exception, never a traceback. A damaged checkpoint or ledger
must not cost the files that were whole: the run file a refused resume would have continued
reads back as before. hypothesis draws the inputs (seeded by its database; ``derandomize``
keeps CI's runs the same), so a failure prints the smallest input that shows it.
"""

from __future__ import annotations

import copy
import shutil
import tempfile
from pathlib import Path

import hypothesis
import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from test_fuzz_scenes import leaves  # every table entry and array item

from taichi_ice import Simulation, load_scenario
from taichi_ice.commands.cli import main
from taichi_ice.errors import TaichiIceError
from taichi_ice.experiments.sweep.spec import parse_sweep
from taichi_ice.run import checkpoint as ckpt
from taichi_ice.run.runfile_read import read_run
from taichi_ice.tomlio import dump_toml

ROOT = Path(__file__).resolve().parents[1]
TWO_SQUARES = ROOT / "scenarios" / "two_squares.toml"

FUZZ = settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    # Report a failing input as found: shrinking re-reads damaged files hundreds of times.
    phases=[Phase.explicit, Phase.reuse, Phase.generate],
)

# Any TOML value: numbers at and beyond float64's ends, text, booleans, arrays and tables.
SCALARS = st.one_of(
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, 1, -1, 0.0, 1e-300, 1e300, 2**31, 0.5]),
    st.text(max_size=12),
    st.booleans(),
)
VALUES = st.recursive(
    SCALARS,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4),
        st.dictionaries(st.text(min_size=1, max_size=8), inner, max_size=3),
    ),
    max_leaves=8,
)


@st.composite
def mutated(draw, raw: dict) -> dict:
    """``raw`` with one to three places changed: a value replaced, a key added to a table, or
    an entry removed."""
    raw = copy.deepcopy(raw)
    for _ in range(draw(st.integers(1, 3))):
        spots = list(leaves(raw))
        path, _ = draw(st.sampled_from(spots))
        holder = raw
        for key in path[:-1]:
            holder = holder[key]
        action = draw(st.sampled_from(["replace", "add", "remove"]))
        if action == "replace":
            holder[path[-1]] = draw(VALUES)
        elif action == "add" and isinstance(holder, dict):
            holder[draw(st.text(min_size=1, max_size=10))] = draw(VALUES)
        elif isinstance(holder, dict):
            del holder[path[-1]]
        elif holder:
            holder.pop(path[-1])
    return raw


def as_toml(raw: dict) -> str | None:
    """The TOML text of ``raw``, or None where TOML cannot hold it (tomli_w refuses)."""
    try:
        return dump_toml(raw)
    except (TypeError, ValueError):
        return None


SCENE_RAW = dict(load_scenario(TWO_SQUARES).raw)


@FUZZ
@given(raw=mutated(SCENE_RAW))
def test_any_scene_file_loads_or_is_one_error_naming_the_file(raw, tmp_path):
    text = as_toml(raw)
    hypothesis.assume(text is not None)
    path = tmp_path / "fuzz.toml"
    path.write_text(text, encoding="utf-8")
    try:
        load_scenario(path)
    except TaichiIceError as exc:
        message = str(exc)
        assert str(path) in message and "\n" not in message, message


@FUZZ
@given(text=st.text(max_size=200), at=st.floats(0.0, 1.0), cut=st.booleans())
def test_any_scene_text_loads_or_is_one_error(text, at, cut, tmp_path):
    """The scene's text with arbitrary text spliced in (or cut there): a parse error, a
    table error or a scene, nothing else."""
    base = TWO_SQUARES.read_text()
    i = int(at * len(base))
    path = tmp_path / "fuzz.toml"
    path.write_text(base[:i] + text + ("" if cut else base[i:]), encoding="utf-8")
    try:
        load_scenario(path)
    except TaichiIceError as exc:
        assert "\n" not in str(exc), str(exc)


SWEEP = {
    "sweep": {"scene": str(TWO_SQUARES), "seeds": {"start": 0, "count": 2}, "until": 0.1},
    "law": [{"law": "coulomb", "mu": [0.3, 0.5]}, {"law": "rate-state"}],
    "overrides": {"ice.thickness": [0.2, 0.3]},
}


@FUZZ
@given(raw=mutated(SWEEP))
def test_any_sweep_file_parses_or_is_one_error(raw):
    text = as_toml(raw)
    hypothesis.assume(text is not None)
    try:
        parse_sweep(text, source="fuzz.toml", base_dir=ROOT)
    except TaichiIceError as exc:
        assert "\n" not in str(exc), str(exc)


# --------------------------------------------------------------------------------------------
# Damaged files
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def finished(tmp_path_factory, taichi_runtime):
    """A short two_squares run with its checkpoint (kept: the run stopped at 0.03 s of its
    0.05), and a finished ensemble folder with its ledger."""
    arch, precision = taichi_runtime
    folder = tmp_path_factory.mktemp("finished")
    scene = load_scenario(TWO_SQUARES)
    run = folder / "run.h5"
    Simulation(scene, arch=arch, precision=precision).run(until=0.03, out=run, checkpoint_every=0.0)
    assert ckpt.path_for(run).exists()
    ens = folder / "ens"
    argv = ["ensemble", str(TWO_SQUARES), "--seeds", "2", "--until", "0.02", "--out", str(ens)]
    assert main([*argv, "--quiet", "--arch", arch, "--precision", precision]) == 0
    return {"run": run, "ckpt": ckpt.path_for(run), "ens": ens, "argv": argv}


def refused(code: int, err: str) -> bool:
    """Whether a command ended in one error line (exit 2) rather than a result (exit 0);
    asserts there was no traceback and no second error line."""
    assert "Traceback" not in err, err
    if code == 0:
        return False
    errors = [x for x in err.splitlines() if x.startswith("taichi-ice") and "error:" in x]
    assert code == 2 and len(errors) == 1, (code, err)
    return True


DAMAGE = st.one_of(
    st.lists(st.tuples(st.floats(0.0, 1.0), st.integers(0, 255)), min_size=1, max_size=16),
    st.floats(0.0, 1.0).map(lambda f: ("cut", f)),
)


def damage(src: Path, dst: Path, how) -> bytes:
    """Copy ``src`` to ``dst`` with bytes overwritten at fractions of its length, or cut at
    one; returns the damaged bytes."""
    data = bytearray(src.read_bytes())
    if isinstance(how, tuple) and how[0] == "cut":
        data = data[: int(how[1] * len(data))]
    else:
        for at, value in how:
            data[min(int(at * len(data)), len(data) - 1)] = value
    dst.write_bytes(bytes(data))
    return bytes(data)


@FUZZ
@given(how=DAMAGE)
def test_a_damaged_run_file_reads_or_is_one_error(finished, how, tmp_path):
    path = tmp_path / "damaged.h5"
    damage(finished["run"], path, how)
    try:
        run = read_run(path)
    except TaichiIceError as exc:
        assert str(path) in str(exc) and "\n" not in str(exc), str(exc)
        return
    assert set(run) == {"attrs", "series", "frames", "bodies"}


@settings(FUZZ, max_examples=12)
@given(how=DAMAGE)
def test_plot_and_export_of_a_damaged_run_file_are_one_line(finished, how, tmp_path, capsys):
    """A bit-flipped run file was a RuntimeError traceback in plot and export."""
    path = tmp_path / "damaged.h5"
    damage(finished["run"], path, how)
    for argv in (
        ["plot", str(path), "--out", str(tmp_path / "fig")],
        ["export", str(path), "--vtk", str(tmp_path / "exp"), "--overwrite"],
    ):
        refused(main(argv), capsys.readouterr().err)


@settings(FUZZ, max_examples=25)
@given(how=DAMAGE)
def test_a_damaged_checkpoint_resumes_or_is_refused_and_the_run_file_stays_whole(
    finished, how, tmp_path, capsys, taichi_runtime
):
    arch, precision = taichi_runtime
    run = tmp_path / "run.h5"
    shutil.copyfile(finished["run"], run)
    damage(finished["ckpt"], ckpt.path_for(run), how)
    before = read_run(run)
    argv = ["run", str(TWO_SQUARES), "--out", str(run), "--resume", "--until", "0.05"]
    code = main([*argv, "--quiet", "--arch", arch, "--precision", precision])
    after = read_run(run)  # readable either way
    if not refused(code, capsys.readouterr().err):  # the damage missed what a resume reads
        assert after["attrs"]["status"] == "complete"
        assert after["series"]["time"][-1] == pytest.approx(0.05)
        return
    for name, values in before["series"].items():  # refused: the file as it was
        np.testing.assert_array_equal(after["series"][name], values)
    assert after["attrs"]["status"] == before["attrs"]["status"]


def test_a_checkpoint_whose_field_name_is_not_text_is_refused_as_damaged(
    finished, tmp_path, capsys, taichi_runtime
):
    """A damaged byte in a field's name can leave a name that is not UTF-8 (h5py then gives
    bytes, which do not sort with the other names): the resume is refused as damaged, in
    one line, not a traceback (found by the fuzz test above on 2026-12-02)."""
    import h5py

    arch, precision = taichi_runtime
    run = tmp_path / "run.h5"
    shutil.copyfile(finished["run"], run)
    shutil.copyfile(finished["ckpt"], ckpt.path_for(run))
    with h5py.File(ckpt.path_for(run), "r+") as f:
        f["data"].move("body_angle", b"body_angl\xe9")
        assert b"body_angl\xe9" in list(f["data"])  # h5py gives the name as bytes
    before = read_run(run)
    argv = ["run", str(TWO_SQUARES), "--out", str(run), "--resume", "--until", "0.05"]
    code = main([*argv, "--quiet", "--arch", arch, "--precision", precision])
    err = capsys.readouterr().err
    assert refused(code, err) and "a damaged checkpoint" in err
    after = read_run(run)  # the file as it was
    np.testing.assert_array_equal(after["series"]["time"], before["series"]["time"])


@settings(FUZZ, max_examples=25)
@given(how=DAMAGE)
def test_a_damaged_ledger_resumes_or_is_refused_and_the_runs_stay_whole(
    finished, how, tmp_path, capsys, taichi_runtime
):
    arch, precision = taichi_runtime
    folder = Path(tempfile.mkdtemp(dir=tmp_path)) / "ens"  # one per example
    shutil.copytree(finished["ens"], folder)
    ledger = folder / "ensemble-state.json"
    damage(finished["ens"] / "ensemble-state.json", ledger, how)
    runs = sorted(folder.rglob("*.h5"))
    before = {p: read_run(p)["series"]["time"] for p in runs}
    argv = [*finished["argv"][:-1], str(folder), "--resume", "--quiet"]
    code = main([*argv, "--arch", arch, "--precision", precision])
    if refused(code, capsys.readouterr().err):
        for p, time in before.items():
            np.testing.assert_array_equal(read_run(p)["series"]["time"], time)
