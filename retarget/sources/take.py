"""`Take`: a recorded performance, frames of named source feature points.

Every source (marker tracking, stereo, markerless tracking, motion-capture and animation
files) produces a `Take`; conditioning, retargeting, the server and the CLI consume one.
A point that is lost in a frame (occluded, out of view, no face found) is a NaN row, so
the arrays keep one shape for the whole take and the retargeter holds lost points at
their neutral (see `retarget.pipeline`).

File form (`Take.save` / `Take.load`): an ``.npz`` holding ``points`` (F, N, D) float32,
``times`` (F,) float64, ``names`` (N,) unicode and ``info``, a JSON string with ``fps``,
``layout``, ``source`` and ``meta``. It is read without pickle.
"""

from __future__ import annotations

import difflib
import io
import json
import math
import os
import zipfile
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from retarget.errors import RetargetError
from retarget.layouts import get_layout

DEFAULT_FPS = 30.0
"""The nominal frame rate of a take whose source states none (a file, a video container)."""

MAX_TAKE_VALUES = 30_000_000
"""Most coordinates (frames x points x 2|3) a take read from a file may hold; the readers
refuse a file that declares more before they make its arrays. 30 million are 240 MB as
float64 (120 MB as the take's float32): a 478-point MediaPipe mesh in 3D for 20,000
frames, 11 minutes at 30 fps."""

__all__ = ["MAX_TAKE_VALUES", "Take", "marker_names", "npy_array"]

_FORMAT = "retarget-take-1"
_MEMBERS = ("points", "times", "names", "info")
_ZIP_METHODS = (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED)  # what np.savez writes
_MAX_NPZ_BYTES = 8 * MAX_TAKE_VALUES + (64 << 20)
"""Most uncompressed bytes read from a take's .npz: the points as float64 and 64 MiB for
the times, names and info."""


@dataclass(eq=False)
class Take:
    """A recorded performance: frames of named source feature points.

    points : (F, N, D) float32, D in (2, 3), the source's units (pixels with y up for
        image trackers, cm or mm for 3D sources). A lost point is a NaN row; a row with
        any NaN coordinate is made all-NaN. Infinite values are refused.
    names : N unique point names: the layout's point names, in its order, when `layout`
        is set; else the source's own labels (marker or C3D labels).
    fps : nominal frame rate, > 0.
    times : (F,) float64 seconds, finite and non-decreasing, or None for
        ``arange(F) / fps``.
    layout : name of a built-in layout (`retarget.layouts.LAYOUTS`) whose points `names`
        are, or None.
    source : what produced the take ("markers", "stereo", "markerless", "csv", "c3d",
        "trc", "gltf", ...).
    meta : JSON-able extras (video size, camera, units).

    Construction validates and coerces (points to a float32 copy); a bad field raises
    `RetargetError` naming it.
    """

    points: np.ndarray
    names: tuple[str, ...]
    fps: float
    times: np.ndarray | None = None
    layout: str | None = None
    source: str = ""
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        try:
            points = np.array(self.points, dtype=np.float32)
        except (TypeError, ValueError) as exc:
            raise RetargetError(f"Take points must be a numeric (F, N, D) array: {exc}") from None
        if points.ndim != 3 or points.shape[2] not in (2, 3) or 0 in points.shape[:2]:
            raise RetargetError(
                f"Take points must have shape (F, N, 2|3) with F, N >= 1; got {points.shape}")
        if np.isinf(points).any():
            f, n = np.argwhere(np.isinf(points).any(axis=2))[0]
            raise RetargetError(f"Take points: frame {f}, point {n} is infinite")
        points[np.isnan(points).any(axis=2)] = np.nan
        self.points = points

        if isinstance(self.names, str):
            raise RetargetError(f"Take names must be a sequence of strings, got {self.names!r}")
        self.names = tuple(str(name) for name in self.names)
        if len(self.names) != points.shape[1]:
            raise RetargetError(
                f"Take has {points.shape[1]} points but {len(self.names)} names")
        if len(set(self.names)) != len(self.names):
            seen: set[str] = set()
            repeated = next(n for n in self.names if n in seen or seen.add(n))
            raise RetargetError(f"Take names repeat {repeated!r}; each point needs its own name")

        try:
            fps = float(self.fps)
        except (TypeError, ValueError):
            raise RetargetError(f"Take fps must be a positive number, got {self.fps!r}") from None
        if not np.isfinite(fps) or fps <= 0:
            raise RetargetError(f"Take fps must be a positive number, got {self.fps!r}")
        self.fps = fps

        if self.times is not None:
            try:
                times = np.array(self.times, dtype=np.float64)
            except (TypeError, ValueError):
                raise RetargetError("Take times must be a numeric (F,) array") from None
            if times.shape != (points.shape[0],):
                raise RetargetError(
                    f"Take times must have shape ({points.shape[0]},), one per frame; "
                    f"got {times.shape}")
            if not np.isfinite(times).all():
                raise RetargetError("Take times must be finite")
            back = np.flatnonzero(np.diff(times) < 0)
            if len(back):
                raise RetargetError(
                    f"Take times go backwards at frame {back[0] + 1} "
                    f"({times[back[0]]:.6g} s -> {times[back[0] + 1]:.6g} s)")
            self.times = times

        if self.layout is not None:
            expected = get_layout(self.layout).point_names
            if self.names != expected:
                raise RetargetError(
                    f"Take names are not the points of layout {self.layout!r} in its order; "
                    f"use to_layout({self.layout!r}) to select and reorder them")
        self.source = str(self.source)
        if not isinstance(self.meta, dict):
            raise RetargetError(f"Take meta must be a dict, got {type(self.meta).__name__}")
        try:
            json.dumps(self.meta)
        except (TypeError, ValueError) as exc:
            raise RetargetError(f"Take meta must be JSON-able: {exc}") from None

    @property
    def n_frames(self) -> int:
        """F, the number of frames."""
        return self.points.shape[0]

    @property
    def n_points(self) -> int:
        """N, the number of points."""
        return self.points.shape[1]

    @property
    def dims(self) -> int:
        """D, 2 or 3."""
        return self.points.shape[2]

    def frame_times(self) -> np.ndarray:
        """(F,) float64 seconds: `times`, or ``arange(F) / fps`` when there are none."""
        if self.times is not None:
            return self.times.copy()
        return np.arange(self.n_frames, dtype=np.float64) / self.fps

    def neutral(self, frame: int | None = None, seconds: float = 0.5) -> np.ndarray:
        """(N, D) float32 neutral points: frame `frame`, or the per-point median over the
        frames within `seconds` of the first (at least the first frame), lost frames
        ignored. Woodward et al. §5.1 record the neutral "during the first few seconds of
        marker motion capture" while the face keeps still.

        Raises `RetargetError` naming the points lost throughout that frame or span.
        """
        if frame is not None:
            if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) \
                    or not -self.n_frames <= frame < self.n_frames:
                raise RetargetError(
                    f"neutral frame must be an integer in [0, {self.n_frames}), got {frame!r}")
            frame = int(frame) % self.n_frames
            span = self.points[frame:frame + 1]
            where = f"neutral frame {frame}"
        else:
            if not np.isfinite(seconds) or seconds < 0:
                raise RetargetError(f"neutral seconds must be >= 0, got {seconds!r}")
            t = self.frame_times()
            count = max(1, int(np.searchsorted(t, t[0] + seconds, side="right")))
            span = self.points[:count]
            where = f"the first {seconds:g} s ({count} frames)"
        lost = np.isnan(span[..., 0]).all(axis=0)
        if lost.any():
            raise RetargetError(
                f"no neutral for points lost throughout {where}: "
                f"{', '.join(np.asarray(self.names)[lost][:12])}"
                + (f" and {int(lost.sum()) - 12} more" if lost.sum() > 12 else ""))
        if len(span) == 1:
            return span[0].copy()
        return np.nanmedian(span, axis=0).astype(np.float32)

    def trimmed(self, start: float = 0.0, stop: float | None = None) -> "Take":
        """The frames with ``start <= t < stop`` (seconds from the first frame), times
        re-based to start at 0. Raises `RetargetError` when no frame is left."""
        t = self.frame_times()
        t = t - t[0]
        keep = t >= start
        if stop is not None:
            keep &= t < stop
        rows = np.flatnonzero(keep)
        if rows.size == 0:
            raise RetargetError(
                f"trimmed({start!r}, {stop!r}) leaves no frame of a {t[-1]:.3f} s take")
        # without times the frames stay evenly spaced, so arange(F) / fps still holds
        times = None if self.times is None else t[rows] - t[rows[0]]
        return replace(self, points=self.points[rows], times=times, meta=dict(self.meta))

    def to_layout(self, layout: str, mapping: dict[str, str] | None = None, *,
                  partial: bool = False) -> "Take":
        """This take's points selected and reordered to `layout`'s point order.

        mapping : {source label: layout point name} for labels that are not the point
            names themselves; points not mapped are looked up by their own name.
        partial : layout points the take does not hold become NaN (never present) rows,
            which the retargeter fills from the others (`retarget.pipeline`); at least one
            point must match.
        Raises `RetargetError` listing the layout points the take does not hold.
        """
        target = get_layout(layout)
        lookup = {name: i for i, name in enumerate(self.names)}
        for label, point in (mapping or {}).items():
            if label not in lookup:
                raise RetargetError(f"mapping names label {label!r}, which the take does not have")
            if point not in target.point_names:
                target.index(point)  # raises, with close matches
            lookup[point] = lookup[label]
        missing = [name for name in target.point_names if name not in lookup]
        if partial and len(missing) < target.n_points:
            points = np.full((self.n_frames, target.n_points, self.dims), np.nan, np.float32)
            present = [i for i, name in enumerate(target.point_names) if name in lookup]
            points[:, present] = self.points[:, [lookup[target.point_names[i]] for i in present]]
            return replace(self, points=points, names=target.point_names, layout=target.name,
                           meta=dict(self.meta), times=None if self.times is None else self.times.copy())
        if missing:
            hints = []
            lowered = {name.lower(): name for name in self.names}
            for name in missing[:3]:
                close = difflib.get_close_matches(name, list(lowered), n=2)
                if close:
                    hints.append(f"{name} ~ {' / '.join(lowered[c] for c in close)}")
            if len(missing) == target.n_points:
                labels = ", ".join(self.names[:6]) + (", ..." if self.n_points > 6 else "")
                raise RetargetError(
                    f"none of the take's {self.n_points} labels ({labels}) is a point of layout "
                    f"{target.name!r}" + (f" (close: {'; '.join(hints)})" if hints else ""))
            raise RetargetError(
                f"the take lacks {len(missing)} of the {target.n_points} points of layout "
                f"{target.name!r}: {', '.join(missing[:20])}{' ...' if len(missing) > 20 else ''}"
                + (f" (close labels: {'; '.join(hints)}; map them with `mapping`)" if hints else ""))
        rows = [lookup[name] for name in target.point_names]
        return replace(self, points=self.points[:, rows], names=target.point_names,
                       layout=target.name, meta=dict(self.meta),
                       times=None if self.times is None else self.times.copy())

    def save(self, path) -> None:
        """Write the take as ``.npz`` (see the module docstring) to a path or binary file."""
        info = {"format": _FORMAT, "fps": self.fps, "layout": self.layout,
                "source": self.source, "meta": self.meta}
        np.savez_compressed(
            path, points=self.points, times=self.frame_times(),
            names=np.array(self.names, dtype=str), info=np.array(json.dumps(info)))

    @classmethod
    def load(cls, source, *, label: str | None = None) -> "Take":
        """Read a take written by `save` from a path, bytes or binary file; validated as
        by construction. Raises `RetargetError` for anything else; its messages name the
        file as `label` (default: the path, or "the take data").

        The .npz is read member by member as a zip of .npy files: each member's size and
        .npy header are checked (`npy_array`: shape, dtype, bytes, `MAX_TAKE_VALUES`)
        before its data is unpacked, and at most `_MAX_NPZ_BYTES` are unpacked in all.
        """
        if label is None:
            label = repr(str(source)) if isinstance(source, (str, os.PathLike)) else "the take data"
        if isinstance(source, (bytes, bytearray, memoryview)):
            source = io.BytesIO(bytes(source))
        elif isinstance(source, (str, os.PathLike)):
            try:
                source = io.BytesIO(Path(source).read_bytes())
            except OSError as exc:
                raise RetargetError(f"could not read {label} as a take (.npz): {exc}") from None
        try:
            archive = zipfile.ZipFile(source)
        except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
            raise RetargetError(f"could not read {label} as a take (.npz): {exc}") from None
        with archive:
            found = {info.filename: info for info in archive.infolist()}
            lacking = [key for key in _MEMBERS if f"{key}.npy" not in found]
            if lacking:
                raise RetargetError(f"{label} is not a take file: it lacks {', '.join(lacking)}")
            members = [found[f"{key}.npy"] for key in _MEMBERS]
            total = sum(info.file_size for info in members)
            if total > _MAX_NPZ_BYTES:
                raise RetargetError(
                    f"{label}: its arrays unpack to {total} bytes "
                    f"({', '.join(f'{i.filename} {i.file_size}' for i in members)}); at most "
                    f"{_MAX_NPZ_BYTES} are read")
            arrays = {key: _npz_member(archive, info, label)
                      for key, info in zip(_MEMBERS, members)}
        try:
            info = json.loads(str(arrays["info"]))
        except json.JSONDecodeError as exc:
            raise RetargetError(f"{label}: the take's info is not JSON: {exc}") from None
        if not isinstance(info, dict) or info.get("format") != _FORMAT:
            raise RetargetError(f"{label} is not a take file (format {_FORMAT!r} expected)")
        if arrays["names"].dtype.kind != "U" or arrays["names"].ndim != 1:
            raise RetargetError(f"{label}: names must be a 1D array of strings")
        meta = info.get("meta") or {}
        return cls(points=arrays["points"], names=tuple(arrays["names"].tolist()),
                   fps=info.get("fps"), times=arrays["times"], layout=info.get("layout"),
                   source=info.get("source", ""), meta=meta)


def marker_names(m: int) -> tuple[str, ...]:
    """The columns of `m` markers tracked without a layout: m01..mM (wider past 99), in
    the order the tracker gives them."""
    width = max(2, len(str(m)))
    return tuple(f"m{k + 1:0{width}d}" for k in range(m))


def npy_array(source, where: str, size: int, max_values: int | None = None) -> np.ndarray:
    """The array of a .npy file read from the binary file object `source` (positioned at
    its start; `size` bytes long), its header read and checked before its data: a plain
    numeric, boolean or string dtype (no Python objects, no fields), no negative
    dimension, at most `max_values` elements (default `MAX_TAKE_VALUES`) and exactly the
    bytes the shape needs.

    Refusals are `RetargetError`s that start with `where` (a file or member name). The
    array may be a read-only view of the bytes read.
    """
    from numpy.lib import format as npy

    try:
        version = npy.read_magic(source)
    except ValueError as exc:
        raise RetargetError(f"{where} is not a NumPy .npy array: {exc}") from None
    if version not in ((1, 0), (2, 0)):
        raise RetargetError(f"{where}: .npy format version {version[0]}.{version[1]} is not read "
                            "(1.0 and 2.0 are)")
    try:
        read_header = npy.read_array_header_1_0 if version == (1, 0) else npy.read_array_header_2_0
        shape, fortran, dtype = read_header(source)
    except Exception as exc:  # numpy raises ValueError, literal_eval others on a hostile header
        raise RetargetError(
            f"{where} is not a NumPy .npy array: its header is malformed "
            f"({type(exc).__name__}: {str(exc)[:200]})") from None
    if dtype.hasobject:
        raise RetargetError(f"{where} holds Python objects (dtype {dtype}), which are not read "
                            "(they would need pickle)")
    if dtype.fields is not None or dtype.subdtype is not None or dtype.kind not in "biufUS" \
            or dtype.itemsize == 0:
        raise RetargetError(f"{where} has dtype {dtype}; a plain number or string type is read")
    if any(d < 0 for d in shape):
        raise RetargetError(f"{where}: its header gives the negative shape {shape}")
    count = math.prod(shape)
    need = count * dtype.itemsize
    max_values = MAX_TAKE_VALUES if max_values is None else max_values
    present = size - source.tell()
    if need != present:
        raise RetargetError(
            f"{where}: its header declares a {'x'.join(map(str, shape)) or 'scalar'} {dtype} "
            f"array{' (Fortran order)' if fortran else ''}, {need} bytes, but {present} bytes "
            "of data follow it")
    if count > max_values:
        raise RetargetError(
            f"{where}: its header declares a {'x'.join(map(str, shape))} array, {count} "
            f"values; at most {max_values} are read")
    raw = source.read(need + 1)  # past the end, so that a zip member's CRC is checked
    if len(raw) != need:
        raise RetargetError(f"{where}: its data ends after {len(raw)} of {need} bytes")
    return np.frombuffer(raw, dtype, count).reshape(shape, order="F" if fortran else "C")


def _npz_member(archive: zipfile.ZipFile, info: zipfile.ZipInfo, label: str) -> np.ndarray:
    """The array of one member of a take's .npz, its zip entry and .npy header checked."""
    where = f"{label}: member {info.filename!r}"
    if info.flag_bits & 0x1:
        raise RetargetError(f"{where} is encrypted")
    if info.compress_type not in _ZIP_METHODS:
        raise RetargetError(f"{where} uses compression method {info.compress_type}, which is "
                            "not read (stored and deflate are)")
    try:
        with archive.open(info) as handle:
            return npy_array(handle, where, info.file_size)
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError, NotImplementedError) as exc:
        raise RetargetError(f"{where} is damaged: {exc}") from None
