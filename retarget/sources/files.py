"""Takes from files: landmark tables, motion-capture files and animated faces.

`read_take` dispatches on the file name's extension; every reader returns a `Take` and
refuses bad input with a `RetargetError` that names the file and, where it applies, the
row, column, byte offset, frame, label or member file. Nothing else leaves `read_take`:
an unexpected exception from a reader or a library on a malformed file becomes
``<file> could not be read as <kind>: <what, in words>``.

Limits
------
Size limits on the upload are the caller's. This module bounds what a file can make it
allocate or compute beyond its own size, and checks each bound on what the file
declares, before the work:

* every take: at most `retarget.sources.take.MAX_TAKE_VALUES` coordinates (frames x
  points x 2|3); CSV and TRC tables are converted a block of cells at a time and
  refused at the row that passes it; table cells no longer than a number.
* JSON: nested at most 64 levels (a cheap scan of the brackets before parsing).
* NPY and NPZ: the .npy header is read first (`retarget.sources.take.npy_array`): no
  Python objects or fields, shape x itemsize equal to the bytes present; an .npz's
  members are checked from the zip directory (encryption, compression, sizes) and their
  headers before they are unpacked.
* C3D: parsed by ezc3d, in-process, which trusts the file and crashes the process on
  some malformed ones, so only after `retarget.sources.c3d_header.c3d_layout` has
  walked the header and parameter section as ezc3d will and checked every offset,
  length, dimension, type and count ezc3d trusts against the file, and the frames,
  points and analog samples against ``MAX_C3D_POINT_SAMPLES``, ``MAX_C3D_ANALOG_SAMPLES``
  and ``MAX_C3D_SUBFRAMES`` of that module.
* glTF / GLB: `retarget.gltf.document.MAX_ACCESSOR_ELEMENTS` per accessor made of
  nothing; from the JSON's counts, ``MAX_INSTANCED_VERTICES``, ``MAX_KEYFRAME_VALUES``,
  ``MAX_SAMPLED_FRAMES`` and ``MAX_SAMPLED_VALUES`` of `retarget.sources.gltf_take`; no
  file a glTF names outside its own folder is read.
* OBJ-sequence zip: `MAX_ARCHIVE_BYTES` unpacked in all, and the entry count, the
  per-frame size, the compression ratio and frames x vertices of
  `retarget.sources.obj_sequence`, all from the zip directory and the first frame
  before the other frames are unpacked; every read is bounded too.

Accepted files
--------------
``.csv`` landmark table, one row per frame, a header row of column names:
    ``<point>_x, <point>_y[, <point>_z]`` per point (the separator before the axis may
    be ``_``, ``.``, ``:`` or a space; axis letters in either case), in any column
    order; optional ``frame`` (also ``frame#``, ``index``) and ``time`` (also
    ``time_s``, ``timestamp``, ``t``; seconds) columns. Every point needs x and y, and
    all points the same axes. An empty cell or ``nan`` is a lost point. Fields may be
    quoted; a UTF-8 byte-order mark is ignored. `write_take_csv` writes this form.
``.json``
    ``{"fps": 30, "names": [...], "frames": [[[x, y, z], ...], ...]}``, optionally
    ``"times": [...]`` (seconds), ``"layout": "<name>"`` and ``"units": "..."``; with a
    layout, ``"names"`` may be left out (the layout's points, in its order). A lost
    point is ``null`` or a row of ``null``.
ARKit weights (``.csv`` or ``.json`` whose columns or ``"weights"`` name ARKit shapes)
    a Live Link Face CSV take or a plain table of named ARKit weights per frame
    (`retarget.sources.arkit_curves`): the ARKit reference face making each frame's
    expression, as `layout`'s points (default ``ibug68``), cm, turned by the head rotation
    when the file has one. Weights must be finite and in [0, 1].
``.npy``
    an (F, N, 2|3) float array of a layout's points (N = the layout's N), or of the 68
    iBUG points (N = 68), or of a MediaPipe face mesh (N = 468 or 478); needs `layout`.
``.npz``
    a take written by `Take.save`.
``.trc`` (OpenSim / Motion Analysis "PathFileType 4" text, tab-separated)
    the DataRate / NumMarkers / Units header, the marker-name row, the X1 Y1 Z1 row, then
    ``frame, time, x, y, z, ...`` rows; empty cells are lost markers; rows may stop
    early (the missing markers are lost).
``.c3d`` (read by ezc3d)
    POINT data with POINT:LABELS (and LABELS2, ...), POINT:RATE and POINT:UNITS; a
    point with a negative residual is lost. Repeated labels get ``_2``, ``_3`` suffixes.
``.glb`` / ``.gltf`` animated face (read by pygltflib)
    the first animation, sampled every 1 / fps s from its first to its last keyframe:
    node translation / rotation / scale (LINEAR, STEP, CUBICSPLINE; rotation LINEAR is
    slerp), morph-target weights, and skinning (JOINTS_n / WEIGHTS_n, inverse bind
    matrices) evaluated as glTF 2.0 specifies (morphing, then skinning; a skinned mesh
    ignores its own node transform). Without `fps`, evenly spaced keyframes give the
    rate, else 30. Every triangle primitive of every mesh node counts, concatenated in
    the order `retarget.mesh.load_mesh` gives, so vertex indices picked on the same file
    in the app are valid here. A ``.gltf`` may embed its buffers as data URIs; read from
    a path, it may also name files in its own folder. Needs `labelled_vertices`.
``.zip`` of an OBJ sequence
    one ``.obj`` per frame, ordered by the last number in each file name (``face_0001.obj``
    ...), all with the first file's vertex count and faces; other members (``.mtl``,
    images, ``__MACOSX/``) are ignored. Vertex order is the file's ``v`` order, as in
    `retarget.mesh.load_mesh`. Needs `labelled_vertices`. Members are stored or
    Deflate-compressed (not encrypted, not bzip2 / LZMA / Deflate64); their declared
    sizes are bounded before anything is unpacked (`MAX_ARCHIVE_BYTES` in all, and the
    limits of `retarget.sources.obj_sequence`).

Animated meshes and `labelled_vertices`: ``{point name: vertex index}``, or a landmarks
JSON object of the project's kind (`retarget.landmarks`: ``vertex_indices``,
``triangles`` + ``barycentric``, or ``positions`` snapped to the rest mesh) whose points
are named by its ``"layout"`` or by the `layout` argument. The take's points are those
surface points on the animated mesh, in the mesh's units.

After reading: with `layout`, `Take.to_layout(layout, mapping)`; without it, `mapping`
renames labels, and a take whose names are exactly a layout's points gets that layout.
A point lost in every frame is refused (named).
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
import struct
import tempfile
import zipfile
import zlib
from pathlib import Path

import numpy as np

from retarget.errors import RetargetError
from retarget.layouts import LAYOUTS, from_ibug68, from_mediapipe468, get_layout
from retarget.sources.arkit_curves import arkit_curves, arkit_take
from retarget.sources.json_text import json_document
from retarget.sources.c3d_header import c3d_layout
from retarget.sources.gltf_take import gltf_points
from retarget.sources.obj_sequence import obj_sequence_points
from retarget.sources.take import DEFAULT_FPS, MAX_TAKE_VALUES, Take, npy_array

__all__ = ["TAKE_FORMATS", "read_take", "write_take_csv"]

TAKE_FORMATS = ("csv", "json", "npy", "npz", "trc", "c3d", "glb", "gltf", "zip")
"""File extensions `read_take` reads."""

_KINDS = {"csv": "a CSV landmark table", "json": "a JSON take", "npy": "a NumPy .npy array",
          "npz": "a take file (.npz)", "trc": "a TRC file", "c3d": "a C3D file",
          "glb": "a GLB animated face", "gltf": "a glTF animated face",
          "zip": "a zip of OBJ frames"}

MAX_ARCHIVE_BYTES = 256 << 20
"""Most bytes the .obj members of an OBJ-sequence zip may unpack to in all, checked on
their declared sizes before any is unpacked and on every read. An upload is at most
64 MiB (`server.app.DEFAULT_MAX_UPLOAD_BYTES`) and OBJ text deflates about 4:1, so a real
sequence that fits the upload fits here: 300 frames of an 8,000-vertex face (0.8 MB
each); parsing 256 MiB of OBJ text takes tens of seconds, which is the point of the
bound (`retarget.sources.obj_sequence` bounds the rest)."""

_MAX_NUMBER_CHARS = 64  # longer cells cannot be numbers worth reading
_AXIS_COLUMN = re.compile(r"^(.+?)[_.: ]([xyzXYZ])$")
_FRAME_COLUMNS = ("frame", "frame#", "frame_index", "index")
_TIME_COLUMNS = ("time", "time_s", "timestamp", "t")


def read_take(source, *, filename: str | None = None, layout: str | None = None,
              mapping: dict[str, str] | None = None, fps: float | None = None,
              labelled_vertices: dict | None = None) -> Take:
    """A `Take` read from a file of one of `TAKE_FORMATS` (see the module docstring).

    source : a path, or the file's bytes.
    filename : the file's name; its extension picks the reader (default: the path's).
    layout : a layout name to select and order the points by (`Take.to_layout`).
    mapping : {file label: layout point name} for labels that are not point names.
    fps : the nominal frame rate, overriding the file's; default the file's rate, else
        inferred from its times, else `DEFAULT_FPS`. For glTF, the sampling rate.
    labelled_vertices : for animated meshes (glTF, OBJ zip), which vertices are points.
    """
    data, label, folder = _source(source, filename)
    name = filename if filename is not None else str(source)
    kind = Path(name).suffix.lower().lstrip(".")
    if kind not in TAKE_FORMATS:
        raise RetargetError(
            f"{label}: unsupported take file type {Path(name).suffix or '(none)'!r}; "
            f"supported: {', '.join('.' + k for k in TAKE_FORMATS)}")
    if fps is not None and (isinstance(fps, bool) or not isinstance(fps, (int, float))
                            or not math.isfinite(fps) or fps <= 0):
        raise RetargetError(f"fps must be a positive number, got {fps!r}")
    try:
        take = _read(kind, data, label, folder, layout, fps, labelled_vertices)
        return _finished(take, label, layout, mapping)
    except RetargetError:
        raise
    except Exception as exc:  # a reader's or library's own error on a malformed file
        raise RetargetError(f"{label} could not be read as {_KINDS[kind]}: {_plain(exc)}") from exc


def _read(kind: str, data: bytes, label: str, folder, layout, fps, labelled_vertices) -> Take:
    """The take in `data`, read by the reader of `kind`."""
    if kind == "npy":
        return _read_npy(data, label, layout, fps)
    if kind == "npz":
        take = Take.load(data, label=label)
        if fps is not None:
            take = Take(take.points, take.names, fps, take.times, take.layout, take.source, take.meta)
        return take
    if kind in ("glb", "gltf"):
        points, names, rate, meta = gltf_points(data, label, kind, folder, labelled_vertices, layout, fps)
        return _take(points, names, rate, None, "gltf", meta, label)
    if kind == "zip":
        points, names, meta = obj_sequence_points(data, label, labelled_vertices, layout, MAX_ARCHIVE_BYTES)
        rate, assumed = _fps(fps, None, None)
        return _take(points, names, rate, None, "obj", {"fps_assumed": assumed, **meta}, label)
    if kind == "c3d":
        return _read_c3d(data, label, fps)
    text = _text(data, label)
    if kind in ("csv", "json"):
        curves = arkit_curves(text, kind, label, fps)
        if curves is not None:  # ARKit weights: the reference face making them, in the layout
            return arkit_take(curves, layout or "ibug68")
    reader = {"csv": _read_csv, "json": _read_json, "trc": _read_trc}[kind]
    return reader(text, label, fps, layout)


def _plain(exc: Exception) -> str:
    """What an unexpected exception from reading a file says about the file, in words."""
    detail = f"{type(exc).__name__}: {str(exc)[:160]}"
    if isinstance(exc, MemoryError):
        return "it would take more memory than there is"
    if isinstance(exc, RecursionError):
        return "it is nested too deeply"
    if isinstance(exc, UnicodeError):
        return f"it holds text that cannot be decoded ({detail})"
    if isinstance(exc, OverflowError):
        return f"a number in it is too large ({detail})"
    if isinstance(exc, (zipfile.BadZipFile, zlib.error)):
        return f"its compressed data is damaged ({detail})"
    if isinstance(exc, (struct.error, EOFError)):
        return f"it is truncated or malformed ({detail})"
    if isinstance(exc, (IndexError, KeyError)):
        return f"it refers to a part it does not hold ({detail})"
    return f"it is malformed ({detail})"


def write_take_csv(take: Take, path) -> None:
    """Write `take` as a landmark CSV (``frame, time, <point>_x, <point>_y[, <point>_z]``;
    lost points as empty cells) to a path or a text file object."""
    axes = "xyz"[:take.dims]
    header = ["frame", "time"] + [f"{name}_{a}" for name in take.names for a in axes]
    times = take.frame_times()
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(header)
    flat = take.points.reshape(take.n_frames, -1)
    for i in range(take.n_frames):
        cells = ["" if np.isnan(v) else repr(float(v)) for v in flat[i]]
        writer.writerow([i, repr(float(times[i]))] + cells)
    if hasattr(path, "write"):
        path.write(out.getvalue())
    else:
        Path(path).write_text(out.getvalue())


# --- common ------------------------------------------------------------------------------

def _source(source, filename):
    """(bytes, label for messages, folder for side files or None)."""
    if isinstance(source, (bytes, bytearray, memoryview)):
        if filename is None:
            raise RetargetError("read_take needs filename= for bytes, to tell the file type")
        return bytes(source), repr(filename), None
    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        try:
            return path.read_bytes(), repr(filename or str(path)), path.parent
        except OSError as exc:
            raise RetargetError(f"could not read {str(path)!r}: {exc}") from None
    raise RetargetError(f"read_take reads a path or bytes, got {type(source).__name__}")


def _text(data: bytes, label: str) -> str:
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise RetargetError(f"{label} is not UTF-8 text (byte {exc.start})") from None


def _finished(take: Take, label: str, layout, mapping) -> Take:
    """The take selected to `layout` (or renamed by `mapping`), lost-throughout refused."""
    if layout is not None:
        try:
            take = take.to_layout(layout, mapping)
        except RetargetError as exc:
            raise RetargetError(f"{label}: {exc}") from None
    else:
        if mapping:
            unknown = [k for k in mapping if k not in take.names]
            if unknown:
                raise RetargetError(f"{label}: mapping names labels the file lacks: {', '.join(unknown)}")
            take = Take(take.points, tuple(mapping.get(n, n) for n in take.names), take.fps,
                        take.times, None, take.source, take.meta)
        if take.layout is None:
            match = next((n for n, lay in LAYOUTS.items() if lay.point_names == take.names), None)
            if match is not None:
                take = Take(take.points, take.names, take.fps, take.times, match,
                            take.source, take.meta)
    never = np.isnan(take.points[..., 0]).all(axis=0)
    if never.any():
        lost = np.asarray(take.names)[never]
        raise RetargetError(
            f"{label}: {len(lost)} point(s) have no position in any frame: "
            f"{', '.join(lost[:20])}{' ...' if len(lost) > 20 else ''}")
    return take


def _fps(fps, file_fps, times) -> tuple[float, bool]:
    """(frame rate, whether it was assumed): the caller's, the file's, the times', 30."""
    if fps is not None:
        return float(fps), False
    if file_fps is not None and np.isfinite(file_fps) and file_fps > 0:
        return float(file_fps), False
    if times is not None and len(times) > 1:
        step = np.median(np.diff(times))
        if step > 0:
            return float(1.0 / step), False
    return DEFAULT_FPS, True


class _Table:
    """Rows of string cells read into a (R, C) float64 array a block at a time, so that
    no more than a block of cells is held as strings; empty or "nan" cells become NaN.

    `add(cells, number)` takes a row (`number` names it in messages, `column_of(j)` a
    column); a table past `MAX_TAKE_VALUES` cells is refused there, before its arrays.
    """

    _BLOCK = 1 << 16  # cells converted at once: at most 16 MB of 64-character strings

    def __init__(self, label: str, width: int, column_of):
        self.label, self.width, self.column_of = label, width, column_of
        self.numbers: list[int] = []
        self._pending: list[list[str]] = []
        self._blocks: list[np.ndarray] = []

    def add(self, cells: list[str], number: int) -> None:
        if (len(self.numbers) + 1) * self.width > MAX_TAKE_VALUES:
            raise RetargetError(
                f"{self.label}: row {number} takes the table past {MAX_TAKE_VALUES} values "
                f"({len(self.numbers) + 1} rows of {self.width} columns); split the take")
        self.numbers.append(number)
        self._pending.append(cells)
        if len(self._pending) * self.width >= self._BLOCK:
            self._flush()

    def values(self) -> np.ndarray:
        """(R, C) float64 of every row added."""
        self._flush()
        if not self._blocks:
            return np.zeros((0, self.width))
        return np.concatenate(self._blocks) if len(self._blocks) > 1 else self._blocks[0]

    def _flush(self) -> None:
        if self._pending:
            first = len(self.numbers) - len(self._pending)
            self._blocks.append(_numeric(self._pending, self.label,
                                         lambda i: self.numbers[first + i], self.column_of))
            self._pending = []


def _numeric(rows: list[list[str]], label: str, row_of, column_of) -> np.ndarray:
    """(R, C) float64 from rows of string cells; empty or "nan" cells become NaN. A cell
    that is not a number raises naming its row and column (via `row_of(i)`, `column_of(j)`)."""

    def refuse(i, j, cell):
        raise RetargetError(
            f"{label}: row {row_of(i)}, column {column_of(j)}: {cell.strip()[:40]!r} is not a number")

    # a numpy string array is as wide as its longest cell: bound that before making it
    longest = max((len(cell) for row in rows for cell in row), default=0)
    if longest > _MAX_NUMBER_CHARS:
        i, j = next((i, j) for i, row in enumerate(rows) for j, cell in enumerate(row)
                    if len(cell) > _MAX_NUMBER_CHARS)
        refuse(i, j, rows[i][j])
    cells = np.char.strip(np.array(rows, dtype=f"U{max(longest, 1)}"))
    cells[cells == ""] = "nan"
    try:
        values = cells.astype(np.float64)
    except ValueError:
        for (i, j), cell in np.ndenumerate(cells):
            try:
                float(cell)
            except ValueError:
                refuse(i, j, cell)
        raise
    bad = np.argwhere(np.isinf(values))
    if len(bad):
        i, j = bad[0]
        raise RetargetError(f"{label}: row {row_of(i)}, column {column_of(j)} is infinite")
    return values


# --- landmark tables ---------------------------------------------------------------------

def _read_csv(text: str, label: str, fps, layout) -> Take:
    reader = csv.reader(io.StringIO(text))
    rows = _csv_rows(reader, label)
    header = next(rows, None)
    if header is None:
        raise RetargetError(f"{label} is empty")
    header = [c.strip() for c in header]
    frame_col = time_col = None
    axes: dict[str, dict[str, int]] = {}
    for j, column in enumerate(header):
        low = column.lower()
        if low in _FRAME_COLUMNS and frame_col is None:
            frame_col = j
        elif low in _TIME_COLUMNS and time_col is None:
            time_col = j
        elif (m := _AXIS_COLUMN.match(column)) is not None:
            point, axis = m.group(1), m.group(2).lower()
            if axis in axes.setdefault(point, {}):
                raise RetargetError(f"{label}: column {column!r} repeats {point!r} {axis}")
            axes[point][axis] = j
        else:
            raise RetargetError(
                f"{label}: column {column!r} is neither frame, time nor a coordinate "
                "(<point>_x, <point>_y, <point>_z)")
    if not axes:
        raise RetargetError(f"{label}: the header names no <point>_x / <point>_y columns")
    dims = 3 if any("z" in a for a in axes.values()) else 2
    wanted = "xyz"[:dims]
    for point, have in axes.items():
        missing = [a for a in wanted if a not in have]
        if missing:
            raise RetargetError(
                f"{label}: point {point!r} has no {'/'.join(missing)} column"
                + (" (other points have z)" if missing == ["z"] else ""))
    table = _Table(label, len(header), lambda j: repr(header[j]))
    for cells in rows:
        if len(cells) != len(header):
            raise RetargetError(
                f"{label}: row {reader.line_num} has {len(cells)} cells, the header has {len(header)}")
        table.add(cells, reader.line_num)
    if not table.numbers:
        raise RetargetError(f"{label} has a header but no frames")
    values, lines = table.values(), table.numbers
    names = tuple(axes)
    columns = [axes[p][a] for p in names for a in wanted]
    points = values[:, columns].reshape(len(lines), len(names), dims)
    times = None
    if time_col is not None:
        times = values[:, time_col]
        if np.isnan(times).any():
            raise RetargetError(
                f"{label}: row {lines[int(np.flatnonzero(np.isnan(times))[0])]} has no time")
        times = times - times[0]
    rate, assumed = _fps(fps, None, times)
    return _take(points, names, rate, times, "csv", {"fps_assumed": assumed}, label)


def _csv_rows(reader, label: str):
    """The reader's rows that hold something; a row the csv module cannot parse (a cell
    over its field size limit, say) is refused naming the row."""
    while True:
        try:
            cells = next(reader)
        except StopIteration:
            return
        except csv.Error as exc:
            row = reader.line_num
            if "field larger than field limit" in str(exc):
                raise RetargetError(
                    f"{label}: row {row} has a cell longer than {csv.field_size_limit()} "
                    "characters; a cell holds one number") from None
            raise RetargetError(f"{label}: row {row} is not valid CSV: {exc}") from None
        if any(c.strip() for c in cells):
            yield cells


def _read_json(text: str, label: str, fps, layout) -> Take:
    doc = json_document(text, label)
    if not isinstance(doc, dict) or "frames" not in doc:
        raise RetargetError(f'{label}: a JSON take is an object with "frames" (and "names" or "layout")')
    frames = doc["frames"]
    if not isinstance(frames, list) or not frames:
        raise RetargetError(f'{label}: "frames" must be a non-empty list of frames')
    file_layout = doc.get("layout")
    names = doc.get("names")
    if names is None:
        if file_layout is None and layout is None:
            raise RetargetError(f'{label}: give "names" or "layout" to name the points')
        names = get_layout(file_layout or layout).point_names
    if not isinstance(names, list | tuple) or not all(isinstance(n, str) for n in names):
        raise RetargetError(f'{label}: "names" must be a list of strings')
    n = len(names)
    dims = None
    rows = []
    for f, frame in enumerate(frames):
        if not isinstance(frame, list) or len(frame) != n:
            got = len(frame) if isinstance(frame, list) else type(frame).__name__
            raise RetargetError(f"{label}: frame {f} has {got} points, names has {n}")
        for p, point in enumerate(frame):
            if point is None:
                continue
            if not isinstance(point, list) or len(point) not in (2, 3) \
                    or (dims is not None and len(point) != dims):
                raise RetargetError(
                    f"{label}: frame {f}, point {names[p]!r} must be [x, y] or [x, y, z]"
                    + (f" like the others ({dims} values)" if dims else "") + f", got {point!r:.60}")
            dims = len(point)
        rows.append(frame)
    if dims is None:
        raise RetargetError(f"{label}: every point is null in every frame")
    if len(frames) * n * dims > MAX_TAKE_VALUES:
        raise RetargetError(
            f"{label}: {len(frames)} frames of {n} points in {dims}D are "
            f"{len(frames) * n * dims} values; at most {MAX_TAKE_VALUES} are read")
    points = np.full((len(frames), n, dims), np.nan)
    for f, frame in enumerate(rows):
        for p, point in enumerate(frame):
            if point is None:
                continue
            for d, v in enumerate(point):
                if v is None:
                    continue
                if isinstance(v, bool) or not isinstance(v, (int, float)) or abs(v) > 1e300:
                    raise RetargetError(
                        f"{label}: frame {f}, point {names[p]!r}: {v!r:.40} is not a number")
                points[f, p, d] = v
    times = doc.get("times")
    if times is not None:
        try:
            times = np.asarray(times, dtype=np.float64) if isinstance(times, list) else None
        except (TypeError, ValueError, OverflowError):
            raise RetargetError(f'{label}: "times" must be a list of numbers (seconds)') from None
        if times is None or times.shape != (len(frames),):
            raise RetargetError(f'{label}: "times" must list one time per frame ({len(frames)})')
        times = times - times[0]
    file_fps = doc.get("fps")
    if file_fps is not None and (isinstance(file_fps, bool) or not isinstance(file_fps, (int, float))):
        raise RetargetError(f'{label}: "fps" must be a number, got {file_fps!r}')
    rate, assumed = _fps(fps, file_fps, times)
    meta = {"fps_assumed": assumed}
    if isinstance(doc.get("units"), str):
        meta["units"] = doc["units"]
    take = _take(points, tuple(names), rate, times, "json", meta, label)
    if file_layout is not None and layout is None:
        take = take.to_layout(file_layout)
    return take


def _read_npy(data: bytes, label: str, layout, fps) -> Take:
    if layout is None:
        raise RetargetError(f"{label}: an .npy take holds no point names; choose its layout")
    lay = get_layout(layout)
    points = npy_array(io.BytesIO(data), label, len(data))  # the header checked before the data
    if not isinstance(points, np.ndarray) or points.dtype.kind not in "fiu" \
            or points.ndim != 3 or points.shape[2] not in (2, 3):
        raise RetargetError(
            f"{label}: expected an (F, N, 2|3) numeric array, got "
            f"{getattr(points, 'dtype', '?')} {getattr(points, 'shape', '?')}")
    n = points.shape[1]
    if n == lay.n_points:
        names = lay.point_names
    elif n == 68:
        points, names = from_ibug68(points, lay), lay.point_names
    elif n in (468, 478):
        points, names = from_mediapipe468(points, lay), lay.point_names
    else:
        raise RetargetError(
            f"{label} has {n} points per frame; layout {lay.name!r} has {lay.n_points} "
            "(68 iBUG points and 468/478-point MediaPipe meshes are also read)")
    rate, assumed = _fps(fps, None, None)
    return _take(points, names, rate, None, "npy", {"fps_assumed": assumed}, label)


# --- motion capture ----------------------------------------------------------------------

def _read_trc(text: str, label: str, fps, layout) -> Take:
    lines = text.splitlines()
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise RetargetError(f"{label} is not a TRC file: it must start with a PathFileType line")
    if "\t" not in lines[1]:
        raise RetargetError(f"{label}: a TRC file is tab-separated; line 2 has no tabs")
    keys = [k.strip() for k in lines[1].split("\t")]
    info = dict(zip(keys, (v.strip() for v in lines[2].split("\t"))))
    markers = [c.strip() for c in lines[3].split("\t")[2:] if c.strip()]
    if not markers:
        raise RetargetError(f"{label}: line 4 names no markers (Frame#, Time, names...)")
    try:
        declared = int(info.get("NumMarkers", len(markers)))
        rate = float(info["DataRate"]) if "DataRate" in info else None
    except ValueError:
        raise RetargetError(f"{label}: NumMarkers / DataRate on line 3 are not numbers") from None
    if declared != len(markers):
        raise RetargetError(f"{label}: NumMarkers is {declared} but line 4 names {len(markers)} markers")
    width = 2 + 3 * len(markers)
    columns = ["Frame#", "Time"] + [f"{m} {a}" for m in markers for a in "XYZ"]
    table = _Table(label, width, lambda j: repr(columns[j]))
    for number, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        cells = line.split("\t")
        while len(cells) > width and not cells[-1].strip():
            cells.pop()  # trailing tabs
        if len(cells) > width:
            raise RetargetError(
                f"{label}: row {number} has {len(cells)} cells; {len(markers)} markers take {width}")
        table.add(cells + [""] * (width - len(cells)), number)
    if not table.numbers:
        raise RetargetError(f"{label} has no frames")
    values = table.values()
    times = values[:, 1]
    times = None if np.isnan(times).any() else times - times[0]
    points = values[:, 2:].reshape(len(values), len(markers), 3)
    rate, _ = _fps(fps, rate, times)
    meta = {"units": info.get("Units", "")}
    return _take(points, _unique(markers), rate, times, "trc", meta, label)


def _read_c3d(data: bytes, label: str, fps) -> Take:
    import ezc3d

    layout = c3d_layout(data, label)  # ezc3d trusts the file: only a checked one reaches it
    if layout.points == 0 or layout.frames == 0:
        raise RetargetError(f"{label} holds no 3D point data (POINT:USED is 0 or there are no frames)")
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "take.c3d"
        path.write_bytes(data)
        try:
            c3d = ezc3d.c3d(str(path))
        except Exception as exc:  # ezc3d raises plain RuntimeErrors on malformed files
            raise RetargetError(f"could not read {label} as C3D: {exc}") from None
    group = c3d["parameters"].get("POINT", {})
    points = np.asarray(c3d["data"]["points"], dtype=np.float64)
    if points.ndim != 3 or points.shape[1] == 0 or points.shape[2] == 0:
        raise RetargetError(f"{label} holds no 3D point data (POINT:USED is 0 or there are no frames)")
    labels = []
    for key in ["LABELS"] + [f"LABELS{i}" for i in range(2, 100)]:
        if key not in group:
            break
        labels += [str(v).strip() for v in group[key]["value"]]
    n = points.shape[1]
    labels = (labels + [f"point{i + 1}" for i in range(len(labels), n)])[:n]
    labels = [name or f"point{i + 1}" for i, name in enumerate(labels)]
    xyz = points[:3].transpose(2, 1, 0)  # (F, N, 3)
    residuals = c3d["data"]["meta_points"].get("residuals")
    if residuals is not None and np.shape(residuals)[1:] == points.shape[1:]:
        xyz[np.asarray(residuals)[0].T < 0] = np.nan
    rate = group.get("RATE", {}).get("value", [None])
    rate = float(rate[0]) if len(rate) else None
    rate, _ = _fps(fps, rate or c3d["header"]["points"].get("frame_rate"), None)
    units = group.get("UNITS", {}).get("value", [""])
    meta = {"units": str(units[0]).strip() if len(units) else ""}
    return _take(xyz, _unique(labels), rate, None, "c3d", meta, label)


def _unique(labels) -> tuple[str, ...]:
    """`labels` with repeats suffixed ``_2``, ``_3``, ... in order."""
    seen: dict[str, int] = {}
    out = []
    for name in labels:
        seen[name] = seen.get(name, 0) + 1
        out.append(name if seen[name] == 1 else f"{name}_{seen[name]}")
    return tuple(out)


def _take(points, names, fps, times, source, meta, label) -> Take:
    try:
        return Take(points, names, fps, times, None, source, meta)
    except RetargetError as exc:
        raise RetargetError(f"{label}: {exc}") from None
