"""Takes from files: landmark tables, motion-capture files and animated faces.

`read_take` dispatches on the file name's extension; every reader returns a `Take` and
refuses bad input with a `RetargetError` that names the file and, where it applies, the
row, column, frame, label or member file. Size limits on the upload are the caller's;
this module bounds what a file can make it allocate beyond its own size
(`MAX_ARCHIVE_BYTES` unpacked from a zip, `MAX_ACCESSOR_ELEMENTS`, `MAX_SAMPLED_FRAMES`,
table cells no longer than a number) and reads no file a glTF names outside its own
folder. C3D files are parsed by ezc3d, in-process, after a header check.

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
    `retarget.mesh.load_mesh`. Needs `labelled_vertices`.

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

import base64
import csv
import io
import json
import math
import os
import re
import tempfile
import warnings
import zipfile
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from retarget.errors import RetargetError
from retarget.landmarks import from_vertex_indices, landmarks_from_json
from retarget.layouts import LAYOUTS, from_ibug68, from_mediapipe468, get_layout
from retarget.sources.take import Take

__all__ = ["TAKE_FORMATS", "read_take", "write_take_csv"]

TAKE_FORMATS = ("csv", "json", "npy", "npz", "trc", "c3d", "glb", "gltf", "zip")
"""File extensions `read_take` reads."""

DEFAULT_FPS = 30.0
"""Frame rate assumed for files that carry none (CSV, JSON and NPY without times, OBJ
sequences) when the caller gives none."""

MAX_ARCHIVE_BYTES = 2 << 30
"""Most uncompressed bytes read out of an OBJ-sequence zip (a zip bomb stops here)."""

MAX_ACCESSOR_ELEMENTS = 1 << 26
"""Most elements a glTF accessor without a buffer view may declare (it allocates zeros)."""

MAX_SAMPLED_FRAMES = 200_000
"""Most frames a glTF animation is sampled into (an hour and more at 30 fps)."""

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
    if kind == "npy":
        take = _read_npy(data, label, layout, fps)
    elif kind == "npz":
        take = Take.load(data)
        if fps is not None:
            take = Take(take.points, take.names, fps, take.times, take.layout, take.source, take.meta)
    elif kind in ("glb", "gltf"):
        take = _read_gltf(data, label, kind, folder, labelled_vertices, layout, fps)
    elif kind == "zip":
        take = _read_obj_zip(data, label, labelled_vertices, layout, fps)
    elif kind == "c3d":
        take = _read_c3d(data, label, fps)
    else:
        text = _text(data, label)
        reader = {"csv": _read_csv, "json": _read_json, "trc": _read_trc}[kind]
        take = reader(text, label, fps, layout)
    return _finished(take, label, layout, mapping)


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
    rows, lines = [], []
    header = None
    for cells in reader:
        if not any(c.strip() for c in cells):
            continue
        if header is None:
            header = [c.strip() for c in cells]
            continue
        if len(cells) != len(header):
            raise RetargetError(
                f"{label}: row {reader.line_num} has {len(cells)} cells, the header has {len(header)}")
        rows.append(cells)
        lines.append(reader.line_num)
    if header is None:
        raise RetargetError(f"{label} is empty")
    if not rows:
        raise RetargetError(f"{label} has a header but no frames")
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
    values = _numeric(rows, label,
                      lambda i: lines[i], lambda j: repr(header[j]))
    names = tuple(axes)
    columns = [axes[p][a] for p in names for a in wanted]
    points = values[:, columns].reshape(len(rows), len(names), dims)
    times = None
    if time_col is not None:
        times = values[:, time_col]
        if np.isnan(times).any():
            raise RetargetError(
                f"{label}: row {lines[int(np.flatnonzero(np.isnan(times))[0])]} has no time")
        times = times - times[0]
    rate, assumed = _fps(fps, None, times)
    return _take(points, names, rate, times, "csv", {"fps_assumed": assumed}, label)


def _read_json(text: str, label: str, fps, layout) -> Take:
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise RetargetError(f"{label} is not JSON: {exc}") from None
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
    try:
        points = np.load(io.BytesIO(data), allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise RetargetError(f"{label} is not a NumPy .npy array: {exc}") from None
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
    rows, numbers = [], []
    for number, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        cells = line.split("\t")
        while len(cells) > width and not cells[-1].strip():
            cells.pop()  # trailing tabs
        if len(cells) > width:
            raise RetargetError(
                f"{label}: row {number} has {len(cells)} cells; {len(markers)} markers take {width}")
        rows.append(cells + [""] * (width - len(cells)))
        numbers.append(number)
    if not rows:
        raise RetargetError(f"{label} has no frames")
    columns = ["Frame#", "Time"] + [f"{m} {a}" for m in markers for a in "XYZ"]
    values = _numeric(rows, label,
                      lambda i: numbers[i], lambda j: repr(columns[j]))
    times = values[:, 1]
    times = None if np.isnan(times).any() else times - times[0]
    points = values[:, 2:].reshape(len(rows), len(markers), 3)
    rate, _ = _fps(fps, rate, times)
    meta = {"units": info.get("Units", "")}
    return _take(points, _unique(markers), rate, times, "trc", meta, label)


def _read_c3d(data: bytes, label: str, fps) -> Take:
    import ezc3d

    if len(data) < 512 or data[1] != 0x50:
        raise RetargetError(f"{label} is not a C3D file (no C3D header)")
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


# --- animated meshes ---------------------------------------------------------------------

def _surface_points(labelled, rest: np.ndarray, faces: np.ndarray, layout, label):
    """((K, 3) vertex indices, (K, 3) barycentric weights, K names) of the labelled points."""
    if labelled is None:
        raise RetargetError(
            f"{label}: an animated mesh needs labelled_vertices ({{point name: vertex index}} "
            "or a landmarks JSON object) to say which vertices are the feature points")
    if not isinstance(labelled, dict) or not labelled:
        raise RetargetError(f"{label}: labelled_vertices must be a non-empty object")
    if any(key in labelled for key in ("vertex_indices", "positions", "triangles")):
        name = labelled.get("layout") or layout
        if not name:
            raise RetargetError(
                f"{label}: the landmarks JSON has no \"layout\" to name its points; give a layout")
        names = get_layout(name).point_names
        points = landmarks_from_json(labelled, rest, faces)
        if points.n_points != len(names):
            raise RetargetError(
                f"{label}: the landmarks JSON has {points.n_points} points; layout {name!r} "
                f"has {len(names)}")
    else:
        names = tuple(str(k) for k in labelled)
        indices = list(labelled.values())
        if not all(isinstance(i, int) and not isinstance(i, bool) for i in indices):
            raise RetargetError(f"{label}: labelled_vertices values must be vertex indices (integers)")
        points = from_vertex_indices(np.array(indices, dtype=np.int64), len(rest))
    return points.vertex_indices, points.barycentric, names


def _labelled_positions(posed, used, vertex_indices, barycentric) -> np.ndarray:
    """(F, K, 3): surface points from (F, U, 3) posed vertices at the (U,) sorted `used`."""
    rows = np.searchsorted(used, vertex_indices)
    return np.einsum("fkjd,kj->fkd", posed[:, rows], barycentric)


def _read_obj_zip(data: bytes, label: str, labelled, layout, fps) -> Take:
    from retarget.mesh import load_mesh

    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
    except zipfile.BadZipFile as exc:
        raise RetargetError(f"{label} is not a zip archive: {exc}") from None
    members = []
    for info in archive.infolist():
        base = info.filename.rsplit("/", 1)[-1]
        if info.is_dir() or info.filename.startswith("__MACOSX/") or base.startswith(".") \
                or not base.lower().endswith(".obj"):
            continue
        numbers = re.findall(r"\d+", base[:-4])
        if not numbers:
            raise RetargetError(f"{label}: {info.filename!r} has no frame number in its name")
        members.append((int(numbers[-1]), info))
    if not members:
        raise RetargetError(f"{label} holds no .obj files")
    members.sort(key=lambda m: m[0])
    for (a, first), (b, second) in zip(members, members[1:]):
        if a == b:
            raise RetargetError(
                f"{label}: {first.filename!r} and {second.filename!r} have the same frame number {a}")
    budget = MAX_ARCHIVE_BYTES

    def member_text(info) -> str:
        nonlocal budget
        with archive.open(info) as handle:
            raw = handle.read(budget + 1)  # the header's size may lie: bound the read itself
        budget -= len(raw)
        if budget < 0:
            raise RetargetError(f"{label} unpacks to more than {MAX_ARCHIVE_BYTES} bytes")
        return raw.decode("utf-8", errors="replace")

    first_name = members[0][1].filename
    first_text = member_text(members[0][1])
    mesh = load_mesh(first_text.encode("utf-8"), "obj")
    vertex_indices, barycentric, names = _surface_points(
        labelled, mesh.vertices, mesh.faces, layout, label)
    used = np.unique(vertex_indices)
    topology = _obj_faces(first_text)
    posed = np.empty((len(members), len(used), 3))
    for f, (_, info) in enumerate(members):
        text = first_text if f == 0 else member_text(info)
        vertices = _obj_vertices(text, f"{label}: {info.filename!r}")
        if len(vertices) != mesh.n_vertices:
            raise RetargetError(
                f"{label}: {info.filename!r} has {len(vertices)} vertices, {first_name!r} has "
                f"{mesh.n_vertices}; every frame needs the same topology")
        if f and _obj_faces(text) != topology:
            raise RetargetError(
                f"{label}: {info.filename!r} has other faces than {first_name!r}; every frame "
                "needs the same topology")
        posed[f] = vertices[used]
    points = _labelled_positions(posed, used, vertex_indices, barycentric)
    rate, assumed = _fps(fps, None, None)
    meta = {"fps_assumed": assumed, "n_vertices": mesh.n_vertices}
    return _take(points, names, rate, None, "obj", meta, label)


def _obj_vertices(text: str, where: str) -> np.ndarray:
    """(V, 3) float64 from an OBJ's ``v`` lines, in file order (colours after xyz ignored)."""
    found = re.findall(r"^[ \t]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)", text, re.MULTILINE)
    try:
        vertices = np.array(found, dtype=np.float64).reshape(-1, 3)
    except ValueError:
        raise RetargetError(f"{where}: a v line holds something that is not a number") from None
    if len(vertices) != len(re.findall(r"^[ \t]*v[ \t]", text, re.MULTILINE)):
        raise RetargetError(f"{where}: a v line has fewer than 3 coordinates")
    if not np.isfinite(vertices).all():
        raise RetargetError(f"{where}: a vertex is NaN or infinite")
    return vertices


def _obj_faces(text: str) -> int:
    """A hash of the vertex indices of an OBJ's ``f`` lines (texture / normal indices out)."""
    lines = re.findall(r"^[ \t]*f[ \t]+(.*?)[ \t]*$", text, re.MULTILINE)
    return hash(re.sub(r"/\S*", "", "\n".join(lines)))


# --- glTF --------------------------------------------------------------------------------

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16,
               5125: np.uint32, 5126: np.float32}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


class _Gltf:
    """A parsed glTF document with bounds-checked accessor reads."""

    def __init__(self, data: bytes, label: str, folder):
        import pygltflib

        self.label = label
        binary = data[:4] == b"glTF"
        if binary and (len(data) < 20 or int.from_bytes(data[4:8], "little") != 2
                       or int.from_bytes(data[8:12], "little") > len(data) or data[16:20] != b"JSON"):
            raise RetargetError(f"could not read {label} as glTF: not a version 2 GLB with a JSON chunk")
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # pygltflib warns on odd chunks; errors come below
                doc = pygltflib.GLTF2.load_from_bytes(data) if binary \
                    else pygltflib.GLTF2.from_json(_text(data, label))
        except RetargetError:
            raise
        except Exception as exc:
            raise RetargetError(f"could not read {label} as glTF: {type(exc).__name__}: {exc}") from None
        if doc is None:
            raise RetargetError(f"could not read {label} as glTF")
        self.doc = doc
        self.buffers = [self._buffer(i, b, folder) for i, b in enumerate(self.doc.buffers or [])]
        self.node_weights = _node_weights(data, label)


    def _buffer(self, index, buffer, folder) -> bytes:
        uri = buffer.uri
        if uri is None:
            blob = self.doc.binary_blob()
            if blob is None:
                raise RetargetError(f"{self.label}: buffer {index} has no data (no GLB binary chunk)")
            return blob
        if uri.startswith("data:"):
            try:
                return base64.b64decode(uri.split(",", 1)[1], validate=True)
            except (IndexError, ValueError):
                raise RetargetError(f"{self.label}: buffer {index} has a malformed data URI") from None
        name = unquote(uri)
        if folder is None:
            raise RetargetError(
                f"{self.label}: buffer {index} is the external file {name!r}, which cannot be "
                "read from an upload; export a .glb or embed the buffers")
        path = (folder / name).resolve()
        if path.parent != Path(folder).resolve():
            raise RetargetError(f"{self.label}: buffer {index} names {name!r}, outside the file's folder")
        try:
            return path.read_bytes()
        except OSError as exc:
            raise RetargetError(f"{self.label}: buffer {index}: could not read {name!r}: {exc}") from None

    def _item(self, items, index, what):
        if items is None or isinstance(index, bool) or not isinstance(index, int) \
                or not 0 <= index < len(items):
            raise RetargetError(f"{self.label}: {what} {index!r} does not exist")
        return items[index]

    def accessor(self, index: int) -> np.ndarray:
        """(count, width) float64 values of an accessor (normalised integers scaled to
        [0, 1] or [-1, 1]; sparse substitutions applied)."""
        acc = self._item(self.doc.accessors, index, "accessor")
        dtype = _COMPONENTS.get(acc.componentType)
        width = _WIDTHS.get(acc.type)
        count = acc.count
        if dtype is None or width is None or not isinstance(count, int) or count < 0:
            raise RetargetError(f"{self.label}: accessor {index} has an unknown type or count")
        if acc.bufferView is None:
            if count * width > MAX_ACCESSOR_ELEMENTS:
                raise RetargetError(f"{self.label}: accessor {index} declares {count} elements")
            values = np.zeros((count, width))
        else:
            values = self._view_array(acc.bufferView, acc.byteOffset or 0, count, dtype, width,
                                      f"accessor {index}").astype(np.float64)
        if acc.sparse is not None and acc.sparse.count:
            sparse = acc.sparse
            idx_type = _COMPONENTS.get(sparse.indices.componentType)
            if idx_type is None:
                raise RetargetError(f"{self.label}: accessor {index} has sparse indices of unknown type")
            rows = self._view_array(sparse.indices.bufferView, sparse.indices.byteOffset or 0,
                                    sparse.count, idx_type, 1, f"accessor {index} sparse indices")[:, 0]
            if (rows >= count).any():
                raise RetargetError(f"{self.label}: accessor {index} has sparse indices past its count")
            values[rows.astype(np.int64)] = self._view_array(
                sparse.values.bufferView, sparse.values.byteOffset or 0, sparse.count, dtype,
                width, f"accessor {index} sparse values")
        if acc.normalized and dtype is not np.float32:
            info = np.iinfo(dtype)
            values = np.maximum(values / info.max, -1.0)
        return values

    def _view_array(self, view_index, offset, count, dtype, width, what) -> np.ndarray:
        view = self._item(self.doc.bufferViews, view_index, f"{what}: bufferView")
        data = self._item(self.buffers, view.buffer, f"{what}: buffer")
        item = np.dtype(dtype).itemsize
        element = item * width
        stride = view.byteStride or element
        start = (view.byteOffset or 0) + offset
        end_view = (view.byteOffset or 0) + view.byteLength
        end = start + stride * (count - 1) + element if count else start
        if stride < element or end > end_view or end_view > len(data):
            raise RetargetError(f"{self.label}: {what} reads past the end of its buffer")
        if count == 0:
            return np.zeros((0, width), dtype)
        return np.ndarray((count, width), np.dtype(dtype).newbyteorder("<"), data, start,
                          (stride, item)).copy()


def _node_weights(data: bytes, label: str) -> dict[int, list]:
    """{node: default morph weights} read from the glTF JSON (pygltflib's Node drops them)."""
    if data[:4] == b"glTF":
        length = int.from_bytes(data[12:16], "little")
        data = data[20:20 + length]
    try:
        nodes = json.loads(data.decode("utf-8-sig")).get("nodes") or []
    except (UnicodeDecodeError, json.JSONDecodeError, AttributeError):
        raise RetargetError(f"could not read {label} as glTF: its JSON is malformed") from None
    return {n: node["weights"] for n, node in enumerate(nodes)
            if isinstance(node, dict) and isinstance(node.get("weights"), list)}


def _read_gltf(data, label, kind, folder, labelled, layout, fps) -> Take:
    gltf = _Gltf(data, label, folder)
    doc = gltf.doc
    nodes = doc.nodes or []
    instances = _mesh_instances(gltf)
    if not instances:
        raise RetargetError(f"{label} holds no triangle mesh")
    if not doc.animations:
        raise RetargetError(f"{label} holds no animation")
    animation = doc.animations[0]
    channels = _channels(gltf, animation)
    keys = np.unique(np.concatenate([c[2] for c in channels]))
    start, stop = float(keys[0]), float(keys[-1])
    if fps is None:
        steps = np.diff(keys)
        even = len(steps) and np.allclose(steps, steps[0], rtol=1e-3) and steps[0] > 0
        fps, assumed = (float(1.0 / steps[0]), False) if even else (DEFAULT_FPS, True)
    else:
        assumed = False
    count = math.floor((stop - start) * fps + 1e-3) + 1  # key times are often float32
    if count > MAX_SAMPLED_FRAMES:
        raise RetargetError(
            f"{label}: the animation lasts {stop - start:.6g} s, {count} frames at {fps:g} fps; "
            f"at most {MAX_SAMPLED_FRAMES} are sampled")
    times = start + np.arange(count) / fps

    static = _node_transforms(gltf, nodes, [], np.zeros(1))[0]
    order = _load_mesh_order(data, kind, folder, instances, static, gltf, label)
    blocks, offset = [], 0
    for i in order:
        blocks.append(offset)
        offset += len(instances[i]["positions"])
    rest = np.concatenate([_apply(static[instances[i]["node"]], instances[i]["positions"])
                           for i in order])
    faces = np.concatenate([instances[i]["faces"] + blocks[k] for k, i in enumerate(order)])
    vertex_indices, barycentric, names = _surface_points(labelled, rest, faces, layout, label)
    used = np.unique(vertex_indices)

    world = _node_transforms(gltf, nodes, channels, times)      # (F, nodes, 4, 4)
    weights = _animated_weights(gltf, channels, times)          # {node: (F, targets)}
    posed = np.empty((len(times), len(used), 3))
    for k, i in enumerate(order):
        inst = instances[i]
        inside = (used >= blocks[k]) & (used < blocks[k] + len(inst["positions"]))
        if inside.any():
            posed[:, inside] = _posed(gltf, inst, used[inside] - blocks[k], world, weights, times)
    points = _labelled_positions(posed, used, vertex_indices, barycentric)
    meta = {"fps_assumed": assumed, "animation": animation.name or "0",
            "animations": len(doc.animations), "n_vertices": int(len(rest))}
    return _take(points, names, fps, None, "gltf", meta, label)


def _mesh_instances(gltf: _Gltf) -> list[dict]:
    """Every triangle primitive of every node with a mesh, in node then primitive order:
    {node, mesh, positions (n, 3), faces (m, 3) local, targets (T, n, 3), skin, joints,
    weights, default_weights}."""
    doc = gltf.doc
    out = []
    for n, node in enumerate(doc.nodes or []):
        if node.mesh is None:
            continue
        mesh = gltf._item(doc.meshes, node.mesh, f"node {n}: mesh")
        for p, prim in enumerate(mesh.primitives):
            if (prim.mode if prim.mode is not None else 4) != 4:
                continue
            attributes = prim.attributes
            if attributes.POSITION is None:
                raise RetargetError(f"{gltf.label}: mesh {node.mesh} primitive {p} has no POSITION")
            positions = gltf.accessor(attributes.POSITION)[:, :3]
            if prim.indices is not None:
                faces = gltf.accessor(prim.indices)[:, 0].astype(np.int64)
            else:
                faces = np.arange(len(positions), dtype=np.int64)
            faces = faces[:len(faces) // 3 * 3].reshape(-1, 3)
            if len(faces) and (faces.max() >= len(positions)):
                raise RetargetError(f"{gltf.label}: mesh {node.mesh} primitive {p} indexes past its vertices")
            targets = np.stack([gltf.accessor(t["POSITION"])[:, :3] if t.get("POSITION") is not None
                                else np.zeros_like(positions) for t in (prim.targets or [])]) \
                if prim.targets else np.zeros((0, len(positions), 3))
            if targets.shape[1:] != positions.shape:
                raise RetargetError(
                    f"{gltf.label}: mesh {node.mesh} primitive {p} has morph targets of another size")
            joints, weights = [], []
            for s in range(8):
                j, w = getattr(attributes, f"JOINTS_{s}", None), getattr(attributes, f"WEIGHTS_{s}", None)
                if j is None or w is None:
                    break
                joints.append(gltf.accessor(j).astype(np.int64))
                weights.append(gltf.accessor(w))
            default = gltf.node_weights.get(n, mesh.weights)
            out.append({
                "node": n, "mesh": node.mesh, "positions": positions, "faces": faces,
                "targets": targets, "skin": node.skin if joints else None,
                "joints": np.concatenate(joints, axis=1) if joints else None,
                "weights": np.concatenate(weights, axis=1) if weights else None,
                "default_weights": np.zeros(len(targets)) if default is None
                else np.resize(np.asarray(default, dtype=np.float64), len(targets)),
            })
    return out


def _load_mesh_order(data, kind, folder, instances, static, gltf, label) -> list[int]:
    """Indices into `instances` in the order `retarget.mesh.load_mesh` concatenates the
    file's meshes (trimesh's scene order), matched by vertex count and rest positions."""
    if len(instances) == 1:
        return [0]
    import trimesh

    resolver = trimesh.resolvers.FilePathResolver(str(folder)) if folder is not None else None
    try:
        scene = trimesh.load_scene(io.BytesIO(data), file_type=kind, resolver=resolver,
                                   process=False, maintain_order=True)
    except Exception as exc:
        raise RetargetError(f"could not read {label} as a mesh: {exc}") from None
    free = list(range(len(instances)))
    order = []
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        part = scene.geometry[name]
        if not isinstance(part, trimesh.Trimesh):
            continue
        seen = part.vertices @ transform[:3, :3].T + transform[:3, 3]
        match = next((i for i in free if len(instances[i]["positions"]) == len(seen) and np.allclose(
            _apply(static[instances[i]["node"]], instances[i]["positions"]), seen, atol=1e-5)), None)
        if match is None:
            raise RetargetError(f"{label}: could not match the mesh {name!r} to a glTF primitive")
        free.remove(match)
        order.append(match)
    return order + free


def _channels(gltf: _Gltf, animation) -> list[tuple]:
    """[(node, path, (K,) key times, (K, width) or (K, 3, width) values, interpolation)]."""
    out = []
    for c, channel in enumerate(animation.channels):
        target = channel.target
        if target.node is None or target.path not in ("translation", "rotation", "scale", "weights"):
            continue
        gltf._item(gltf.doc.nodes, target.node, f"animation channel {c}: node")
        sampler = gltf._item(animation.samplers, channel.sampler, f"animation channel {c}: sampler")
        keys = gltf.accessor(sampler.input)[:, 0]
        values = gltf.accessor(sampler.output)
        interpolation = sampler.interpolation or "LINEAR"
        if len(keys) == 0 or not np.isfinite(keys).all() or (np.diff(keys) < 0).any():
            raise RetargetError(f"{gltf.label}: animation channel {c} has no or unordered key times")
        per_key = 3 if interpolation == "CUBICSPLINE" else 1
        if target.path == "weights":
            if len(values) % (len(keys) * per_key):
                raise RetargetError(f"{gltf.label}: animation channel {c}: weights do not fit the keys")
            values = values.reshape(len(keys) * per_key, -1)
        if len(values) != len(keys) * per_key:
            raise RetargetError(
                f"{gltf.label}: animation channel {c} has {len(values)} values for {len(keys)} keys")
        if per_key == 3:
            values = values.reshape(len(keys), 3, -1)
        out.append((target.node, target.path, keys, values, interpolation))
    if not out:
        raise RetargetError(f"{gltf.label}: the animation animates no node or morph weights")
    return out


def _sampled(keys, values, interpolation, times, rotation: bool) -> np.ndarray:
    """(F, width) values of one glTF animation sampler at `times` (glTF 2.0 §3.11;
    held at the first and last key outside them)."""
    t = np.clip(times, keys[0], keys[-1])
    if len(keys) == 1:
        value = values[0, 1] if interpolation == "CUBICSPLINE" else values[0]
        return np.repeat(value[None], len(times), axis=0)
    i = np.clip(np.searchsorted(keys, t, side="right") - 1, 0, len(keys) - 2)
    span = keys[i + 1] - keys[i]
    u = np.divide(t - keys[i], span, out=np.zeros_like(t), where=span > 0)[:, None]
    if interpolation == "STEP":
        return values[np.where(t >= keys[i + 1], i + 1, i)]
    if interpolation == "CUBICSPLINE":
        d = span[:, None]
        a, v, b = values[:, 0], values[:, 1], values[:, 2]
        out = ((2 * u**3 - 3 * u**2 + 1) * v[i] + (u**3 - 2 * u**2 + u) * d * b[i]
               + (-2 * u**3 + 3 * u**2) * v[i + 1] + (u**3 - u**2) * d * a[i + 1])
        return out / np.linalg.norm(out, axis=1, keepdims=True) if rotation else out
    if not rotation:
        return (1 - u) * values[i] + u * values[i + 1]
    q0, q1 = values[i], values[i + 1]
    dot = np.sum(q0 * q1, axis=1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)  # the short way round
    theta = np.arccos(np.clip(np.abs(dot), -1.0, 1.0))
    sin = np.sin(theta)
    small = sin < 1e-6
    w0 = np.where(small, 1 - u, np.sin((1 - u) * theta) / np.where(small, 1, sin))
    w1 = np.where(small, u, np.sin(u * theta) / np.where(small, 1, sin))
    out = w0 * q0 + w1 * q1
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _node_transforms(gltf, nodes, channels, times) -> np.ndarray:
    """(F, nodes, 4, 4) world matrices of every node at `times` (animated TRS)."""
    f = len(times)
    local = np.empty((f, len(nodes), 4, 4))
    animated = {(c[0], c[1]): c for c in channels if c[1] != "weights"}
    for n, node in enumerate(nodes):
        if node.matrix is not None and not any((n, p) in animated for p in ("translation", "rotation", "scale")):
            local[:, n] = np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T
            continue
        trs = {}
        for path, default in (("translation", node.translation or [0, 0, 0]),
                              ("rotation", node.rotation or [0, 0, 0, 1]),
                              ("scale", node.scale or [1, 1, 1])):
            if (n, path) in animated:
                _, _, keys, values, interpolation = animated[(n, path)]
                trs[path] = _sampled(keys, values, interpolation, times, path == "rotation")
            else:
                trs[path] = np.repeat(np.asarray(default, dtype=np.float64)[None], f, axis=0)
        local[:, n] = _trs_matrix(trs["translation"], trs["rotation"], trs["scale"])
    parent = {}
    for n, node in enumerate(nodes):
        for child in node.children or []:
            gltf._item(nodes, child, f"node {n}: child")
            parent[child] = n
    world = np.empty_like(local)
    done = np.zeros(len(nodes), dtype=bool)

    def resolve(n, depth=0):
        if done[n]:
            return
        if depth > len(nodes):
            raise RetargetError(f"{gltf.label}: the node hierarchy has a cycle")
        if n in parent:
            resolve(parent[n], depth + 1)
            world[:, n] = world[:, parent[n]] @ local[:, n]
        else:
            world[:, n] = local[:, n]
        done[n] = True

    for n in range(len(nodes)):
        resolve(n)
    return world


def _trs_matrix(t, q, s) -> np.ndarray:
    """(F, 4, 4) T R S from (F, 3) translations, (F, 4) xyzw quaternions, (F, 3) scales."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    r = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], 1)
    m = np.zeros((len(t), 4, 4))
    m[:, :3, :3] = r * s[:, None, :]
    m[:, :3, 3] = t
    m[:, 3, 3] = 1.0
    return m


def _apply(matrix, points) -> np.ndarray:
    """(..., n, 3) points moved by (..., 4, 4) matrices."""
    return points @ np.swapaxes(matrix[..., :3, :3], -1, -2) + matrix[..., None, :3, 3]


def _animated_weights(gltf, channels, times) -> dict[int, np.ndarray]:
    return {node: _sampled(keys, values, interpolation, times, False)
            for node, path, keys, values, interpolation in channels if path == "weights"}


def _posed(gltf, inst, rows, world, weights, times) -> np.ndarray:
    """(F, len(rows), 3) positions of the primitive's vertices `rows` at every time:
    morph targets, then skinning (or the node's world transform), glTF 2.0 §3.7."""
    f = len(times)
    base = inst["positions"][rows]
    targets = inst["targets"][:, rows]
    w = weights.get(inst["node"])
    if w is None:
        w = np.repeat(inst["default_weights"][None], f, axis=0)
    elif w.shape[1] != len(targets):
        raise RetargetError(
            f"{gltf.label}: the animation gives {w.shape[1]} morph weights for node {inst['node']}, "
            f"whose mesh has {len(targets)} targets")
    morphed = base[None] + np.einsum("ft,tnd->fnd", w, targets)
    if inst["skin"] is None:
        return _apply(world[:, inst["node"]], morphed)
    skin = gltf._item(gltf.doc.skins, inst["skin"], f"node {inst['node']}: skin")
    joints = np.asarray(skin.joints, dtype=np.int64)
    if skin.inverseBindMatrices is not None:
        inverse = gltf.accessor(skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
        if len(inverse) != len(joints):
            raise RetargetError(f"{gltf.label}: skin {inst['skin']} has {len(inverse)} inverse bind "
                                f"matrices for {len(joints)} joints")
    else:
        inverse = np.repeat(np.eye(4)[None], len(joints), axis=0)
    index, weight = inst["joints"][rows], inst["weights"][rows]
    if index.max(initial=0) >= len(joints) or index.min(initial=0) < 0:
        raise RetargetError(f"{gltf.label}: skin {inst['skin']}: a vertex names a joint the skin lacks")
    joint_matrices = world[:, joints] @ inverse[None]                      # (F, J, 4, 4)
    blended = np.einsum("nk,fnkab->fnab", weight, joint_matrices[:, index])  # (F, n, 4, 4)
    return np.einsum("fnab,fnb->fna", blended[..., :3, :3], morphed) + blended[..., :3, 3]
