"""A run file as VTK files for ParaView: the floes as polygons, one file a frame.

    taichi-ice export runs/pillar.h5 --vtk out/pillar_vtk
    # ParaView: File > Open > out/pillar_vtk/pillar.pvd, Apply, then play

``export_vtk(run, folder)`` writes, for a run file ``NAME.h5``:

- ``NAME_000000.vtp``, ``NAME_000001.vtp``, ...: VTK XML PolyData, one per frame: every body
  as a polygon (its outline turned to the frame's angle and placed at its centroid, z = 0),
  with cell data ``velocity`` (m/s, 3 components, z = 0), ``angular_velocity`` (rad/s,
  counter-clockwise), ``body`` (index in scene order) and ``kind`` (0 dynamic, 1 fixed,
  2 kinematic), and the frame's time as field data ``TimeValue`` (s);
- ``NAME.pvd``: the collection of those files with their times, which ParaView opens as one
  time series;
- for a run that wrote its contacts (``run --contacts``, ``/contacts``), the force chains:
  ``NAME_contacts_000000.vtp``, ... and ``NAME_contacts.pvd``, a second time series beside
  the floes (open both; colour the lines by ``force_normal``): one line per contact, from
  ``body_a``'s centroid through the contact point to ``body_b``'s (a polyline of three
  points), with cell data ``force_normal``, ``force_tangential`` (N, on ``body_b``),
  ``force`` (N, on ``body_b``, 3 components, z = 0), ``slip_rate`` (m/s), ``theta`` (NaN
  where none), ``mu``, ``stuck`` (1 stuck, 0 sliding), ``body_a`` and ``body_b``: the
  frame's rows, the contacts of the step that starts at its time.

Plain NumPy and the standard library (no VTK package): arrays are written inline, as
base64 of little-endian bytes behind a UInt64 byte count (VTK's "binary" format), or as text
(``binary=False``). Each file is written under a temporary name and renamed, the ``.pvd``
last, so an interrupted export never leaves a collection that names missing frames. VTK's
own vtkXMLPolyDataReader reads every file back in tests/test_export.py.
"""

from __future__ import annotations

import base64
import contextlib
import os
from collections.abc import Mapping
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from ..codes import BodyKind
from ..errors import OutputError, UsageError
from .output import check_folder
from .runfile_read import frame_contacts, read_run

__all__ = ["export_vtk", "floe_polygons"]

# VTK type names of the NumPy dtypes written.
_VTK_TYPES = {
    np.dtype("<f8"): "Float64",
    np.dtype("<i8"): "Int64",
    np.dtype("<i4"): "Int32",
}


def floe_polygons(vertices: np.ndarray, offsets: np.ndarray, position, angle) -> np.ndarray:
    """``(V, 2)`` world coordinates of every body's outline at one frame.

    Args:
        vertices: ``(V, 2)`` centroid-relative, unturned outlines (``/bodies/vertices``).
        offsets: ``(N + 1,)`` body i owns ``vertices[offsets[i]:offsets[i + 1]]``.
        position: ``(N, 2)`` centroids (m). angle: ``(N,)`` counter-clockwise (rad).
    """
    counts = np.diff(offsets)
    owner = np.repeat(np.arange(len(counts)), counts)
    c, s = np.cos(angle)[owner], np.sin(angle)[owner]
    x, y = vertices[:, 0], vertices[:, 1]
    return np.stack([c * x - s * y, s * x + c * y], axis=1) + position[owner]


def _array(
    name: str | None,
    data: np.ndarray,
    components: int,
    binary: bool,
    indent: str,
    field: bool = False,
) -> str:
    """One DataArray; ``field``: of FieldData, whose arrays must say their NumberOfTuples
    (VTK's XML readers take a field array without it as empty)."""
    data = np.ascontiguousarray(data)
    data = data.astype(data.dtype.newbyteorder("<"), copy=False)
    kind = _VTK_TYPES[data.dtype]
    named = f" Name={quoteattr(name)}" if name else ""
    head = f'{indent}<DataArray type="{kind}"{named} NumberOfComponents="{components}"'
    if field:
        head += f' NumberOfTuples="{data.size // components}"'
    # VTK's text reader cannot read a NaN (theta where a contact has none): such an array is
    # written in base64 whatever was asked (a file may mix the two, array by array).
    if binary or (data.dtype.kind == "f" and not np.all(np.isfinite(data))):
        raw = data.tobytes()
        blob = base64.b64encode(np.uint64(len(raw)).astype("<u8").tobytes() + raw).decode()
        return f'{head} format="binary">{blob}</DataArray>\n'
    flat = data.reshape(-1)
    if flat.dtype.kind == "f":
        text = " ".join(repr(float(v)) for v in flat)
    else:
        text = " ".join(str(int(v)) for v in flat)
    return f'{head} format="ascii">{text}</DataArray>\n'


def _polydata(
    points,
    offsets,
    cells: Mapping[str, tuple[np.ndarray, int]],
    time,
    binary,
    kind: str = "Polys",
    attributes: str = 'Scalars="angular_velocity" Vectors="velocity"',
):
    """A PolyData file of cells of ``kind`` ("Polys" or "Lines"): cell ``k`` joins points
    ``offsets[k]`` to ``offsets[k + 1]`` in turn; ``attributes``: the CellData's active
    arrays."""
    n_points, n_cells = len(points), len(offsets) - 1
    n_lines, n_polys = (n_cells, 0) if kind == "Lines" else (0, n_cells)
    xyz = np.zeros((n_points, 3))
    xyz[:, :2] = points
    parts = [
        '<?xml version="1.0"?>\n',
        '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64">\n',
        "  <PolyData>\n",
        "    <FieldData>\n",
        _array("TimeValue", np.array([time], dtype="<f8"), 1, binary, "      ", field=True),
        "    </FieldData>\n",
        f'    <Piece NumberOfPoints="{n_points}" NumberOfVerts="0" NumberOfLines="{n_lines}" '
        f'NumberOfStrips="0" NumberOfPolys="{n_polys}">\n',
        "      <Points>\n",
        _array("Points", xyz, 3, binary, "        "),
        "      </Points>\n",
        f"      <{kind}>\n",
        _array("connectivity", np.arange(n_points, dtype="<i8"), 1, binary, "        "),
        _array("offsets", np.asarray(offsets[1:], dtype="<i8"), 1, binary, "        "),
        f"      </{kind}>\n",
        f"      <CellData {attributes}>\n",
    ]
    for name, (values, components) in cells.items():
        parts.append(_array(name, values, components, binary, "        "))
    parts += ["      </CellData>\n", "    </Piece>\n", "  </PolyData>\n", "</VTKFile>\n"]
    return "".join(parts)


def _force_chains(rows: Mapping[str, np.ndarray], position: np.ndarray, time, binary) -> str:
    """A frame's contacts as VTK lines: ``body_a``'s centroid, the contact point,
    ``body_b``'s centroid, with the rows as cell data (``export_vtk``)."""
    a, b = np.asarray(rows["body_a"]), np.asarray(rows["body_b"])
    n = len(a)
    points = np.stack([position[a], rows["point"], position[b]], axis=1).reshape(-1, 2)
    normal = np.asarray(rows["normal"], dtype=np.float64).reshape(-1, 2)
    tangent = np.stack([-normal[:, 1], normal[:, 0]], axis=1)
    force = np.zeros((n, 3))
    force[:, :2] = (
        rows["force_normal"][:, None] * normal + rows["force_tangential"][:, None] * tangent
    )

    def real(name):
        return (np.asarray(rows[name], dtype="<f8"), 1)

    cells = {
        "force_normal": real("force_normal"),
        "force_tangential": real("force_tangential"),
        "force": (force, 3),
        "slip_rate": real("slip_rate"),
        "theta": real("theta"),
        "mu": real("mu"),
        "stuck": (np.asarray(rows["stuck"], dtype="<i4"), 1),
        "body_a": (a.astype("<i8"), 1),
        "body_b": (b.astype("<i8"), 1),
    }
    offsets = 3 * np.arange(n + 1)
    return _polydata(
        points, offsets, cells, time, binary, "Lines", 'Scalars="force_normal" Vectors="force"'
    )


def _collection(entries: list[tuple[float, str]]) -> str:
    rows = "".join(
        f'    <DataSet timestep="{t!r}" group="" part="0" file={quoteattr(name)}/>\n'
        for t, name in entries
    )
    return (
        '<?xml version="1.0"?>\n'
        '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
        f"  <Collection>\n{rows}  </Collection>\n</VTKFile>\n"
    )


def _write(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(text, encoding="ascii")
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def export_vtk(
    run: str | Path,
    folder: str | Path,
    *,
    overwrite: bool = False,
    binary: bool = True,
    every: int = 1,
) -> Path:
    """Write the frames of run file ``run`` to ``folder`` as VTK PolyData and a collection.

    Args:
        run: a run file (``taichi-ice run --out``).
        folder: output folder (made if missing).
        overwrite: replace the files of an earlier export of this run in ``folder``.
        binary: arrays as base64 (smaller, faster for ParaView); False for text (but an
            array that holds a NaN, which VTK's text reader cannot read: base64).
        every: write every ``every``-th frame (1: all).

    Returns:
        The ``.pvd`` collection's path (the floes'; a run with contacts has its force chains
        in ``STEM_contacts.pvd`` beside it).

    Raises:
        RunFileError: ``run`` is not a run file. UsageError: ``every`` < 1, or a run with
            no frame. OutputError: ``folder`` cannot be written, or holds an earlier export
            (without ``overwrite``).
    """
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise UsageError(f"every = {every!r}: use a whole number of frames, 1 or more")
    data = read_run(run)
    frames, bodies = data["frames"], data["bodies"]
    times = np.asarray(frames["time"], dtype=np.float64)
    if times.size == 0:
        raise UsageError(f"{run}: the run has no frame yet; nothing to export")
    out = check_folder(folder)
    stem = Path(run).stem
    pvd = out / f"{stem}.pvd"
    if pvd.exists() and not overwrite:
        raise OutputError(
            f"{pvd}: exists (an earlier export); pass --overwrite (overwrite=True) to "
            "replace it, or give another folder"
        )
    if not overwrite:
        # Frame files of an earlier export whose .pvd is gone (interrupted) are not ours
        # to replace without being asked either.
        for old in out.glob(f"{stem}_*.vtp"):
            raise OutputError(
                f"{old}: exists (an earlier export); pass --overwrite (overwrite=True) to "
                "replace it, or give another folder"
            )

    offsets = np.asarray(bodies["vertex_offsets"], dtype=np.int64)
    vertices = np.asarray(bodies["vertices"], dtype=np.float64).reshape(-1, 2)
    n = len(offsets) - 1
    kinds = np.array([int(BodyKind.from_label(str(k))) for k in bodies["kinds"]], dtype="<i4")
    index = np.arange(n, dtype="<i4")
    width = max(6, len(str(len(times) - 1)))
    entries, chains = [], []
    for f in range(0, len(times), every):
        points = floe_polygons(vertices, offsets, frames["position"][f], frames["angle"][f])
        velocity = np.zeros((n, 3))
        velocity[:, :2] = frames["velocity"][f]
        cells = {
            "velocity": (velocity, 3),
            "angular_velocity": (np.asarray(frames["omega"][f], dtype="<f8"), 1),
            "body": (index, 1),
            "kind": (kinds, 1),
        }
        name = f"{stem}_{f:0{width}d}.vtp"
        _write(out / name, _polydata(points, offsets, cells, float(times[f]), binary))
        entries.append((float(times[f]), name))
        if "contacts" in data and f < len(data["contacts"]["row_size"]):
            rows = frame_contacts(data, f)
            name = f"{stem}_contacts_{f:0{width}d}.vtp"
            text = _force_chains(rows, frames["position"][f], float(times[f]), binary)
            _write(out / name, text)
            chains.append((float(times[f]), name))
    if "contacts" in data:
        _write(out / f"{stem}_contacts.pvd", _collection(chains))
    _write(pvd, _collection(entries))
    return pvd
