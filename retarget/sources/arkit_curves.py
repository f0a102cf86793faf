"""ARKit blendshape curves as a source: Live Link Face CSV takes and plain tables of named
weights, read as weights per frame and turned into a `Take` of feature points through the
ARKit reference (`retarget.arkit.reference`: the reference face making each frame's
expression, ``neutral + sum_k w_k motion_k``), which then retargets like any take.

Accepted files (names matched without case; ``EyeBlinkLeft`` is ``eyeBlinkLeft``):

Live Link Face CSV (Epic Games' iPhone app)
    ``Timecode, BlendShapeCount, EyeBlinkLeft, ... TongueOut, HeadYaw, HeadPitch,
    HeadRoll, LeftEyeYaw, LeftEyePitch, LeftEyeRoll, RightEyeYaw, RightEyePitch,
    RightEyeRoll``. Timecode is ``HH:MM:SS:FF`` or ``HH:MM:SS:FF.sss`` with FF counted at
    the app's rate: the rate is `fps` when given, else one more than the largest FF when
    the take spans a second boundary, else Live Link Face's default 60. BlendShapeCount is
    not used (it counts the head and eye columns too).
plain CSV
    a header of ARKit names, optionally ``time`` (seconds) or ``frame``, and the head
    columns; one row per frame.
JSON
    ``{"fps": 60, "names": [...], "weights": [[...], ...]}`` (rows in ``names`` order) or
    ``{"fps": 60, "weights": [{"jawOpen": 0.3, ...}, ...]}``, optionally ``"times"``
    (seconds) and ``"head"`` ([yaw, pitch, roll] per frame, radians).

`live_link_csv` writes weights as Live Link Face CSV, the reader's inverse.

Any subset of the 52 names may be given (the others stay 0); other columns or keys are
ignored and listed in the take's ``meta["ignored"]``. Policy: a weight must be a finite
number in [0, 1] (a table on a 0-100 scale is refused with that hint); NaN, empty or
non-numeric cells, a row of the wrong length, no ARKit name at all, or more than
`MAX_TAKE_VALUES` values are refused naming the row and column.

Head rotation (HeadYaw, HeadPitch, HeadRoll, radians, ARKit's right-handed y-up frame:
yaw about +y, pitch about +x, roll about +z, applied roll first) turns the points about
the reference face's origin (inside the head), so the take carries it as a tracked 3D
take does and conditioning removes it as rigid head motion and keeps it for "turn the
head" (`retarget.sources.conditioning`). The eye rotations are not used (the rig has no
eyeballs).
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass

import numpy as np

from retarget.arkit.reference import ARKIT_NAMES, arkit_index, arkit_reference
from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.sources.json_text import json_document
from retarget.sources.take import MAX_TAKE_VALUES, Take

__all__ = ["ArkitCurves", "LIVE_LINK_COLUMNS", "LIVE_LINK_FPS", "arkit_curves", "arkit_take",
           "live_link_csv"]

LIVE_LINK_FPS = 60.0
"""Live Link Face's default recording rate, taken when a CSV's timecodes do not show it."""

LIVE_LINK_COLUMNS: tuple[str, ...] = (
    "Timecode", "BlendShapeCount",
    *(n[0].upper() + n[1:] for n in ARKIT_NAMES[:15]), "JawRight", "JawLeft",
    *(n[0].upper() + n[1:] for n in ARKIT_NAMES[17:21]), "MouthRight", "MouthLeft",
    *(n[0].upper() + n[1:] for n in ARKIT_NAMES[23:]),
    "HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
    "RightEyeYaw", "RightEyePitch", "RightEyeRoll",
)
"""The columns of a Live Link Face CSV, in the app's order: Apple's 52 names capitalised, but
for JawRight before JawLeft and MouthRight before MouthLeft (as the app writes them), then
the head's and the eyes' rotations (radians). The reader goes by name; `live_link_csv` writes
this order."""

HEAD_COLUMNS = tuple(c.lower() for c in LIVE_LINK_COLUMNS[-9:-6])
_TIME_COLUMNS = ("time", "time_s", "timestamp", "t")
_FRAME_COLUMNS = ("frame", "frame#", "frame_index", "index")
_TIMECODE = re.compile(r"^\s*(\d+):(\d{1,2}):(\d{1,2})[:;.](\d+(?:\.\d*)?)\s*$")
_MAX_CELL = 64  # characters: longer cells cannot be numbers worth reading
_BLOCK_ROWS = 4096  # rows converted to numbers at once


@dataclass(frozen=True, eq=False)
class ArkitCurves:
    """ARKit weights per frame.

    weights : (F, 52) float64 in [0, 1], `ARKIT_NAMES` order (names the file lacks are 0).
    fps : frame rate, > 0.
    times : (F,) float64 seconds from the first frame, or None for ``arange(F) / fps``.
    head : (F, 3) float64 yaw, pitch, roll in radians, or None when the file has none.
    meta : what was assumed or ignored (``fps_assumed``, ``ignored``, ``format``).
    """

    weights: np.ndarray
    fps: float
    times: np.ndarray | None
    head: np.ndarray | None
    meta: dict


def arkit_curves(text: str, kind: str, label: str, fps: float | None = None) -> ArkitCurves | None:
    """The curves in a ``csv`` or ``json`` file's text (module docstring), or None when the
    file is not ARKit weights (a landmark table: no ARKit column, or no ``"weights"``).
    Raises `RetargetError` naming the file (`label`), row and column for a malformed one."""
    if kind == "csv":
        return _from_csv(text, label, fps)
    if kind == "json":
        return _from_json(text, label, fps)
    raise RetargetError(f"ARKit curves are read from CSV or JSON, not {kind!r}")


def arkit_take(curves: ArkitCurves, layout: str = "ibug68", *, head: bool = True,
               source: str = "arkit") -> Take:
    """A `Take` of `layout`'s points (the reference face's cm) making `curves`' expressions,
    turned by the head rotation when `head` and the curves have one (module docstring)."""
    ref = arkit_reference(layout)
    frames = len(curves.weights)
    if frames * len(ref.neutral) * 3 > MAX_TAKE_VALUES:
        raise RetargetError(f"{frames} frames of {len(ref.neutral)} points exceed the {MAX_TAKE_VALUES} "
                            "values a take may hold; split the take")
    points = ref.points(curves.weights)
    turned = head and curves.head is not None
    if turned:
        points = np.einsum("fij,fnj->fni", head_rotations(curves.head), points)
    meta = {**curves.meta, "head_rotation": "applied to the points" if turned else "none",
            "neutral": np.round(ref.neutral, 5).tolist()}
    return Take(points, get_layout(layout).point_names, curves.fps, curves.times, layout, source, meta)


def head_rotations(angles: np.ndarray) -> np.ndarray:
    """(F, 3, 3) float64 rotation matrices ``Ry(yaw) Rx(pitch) Rz(roll)`` for (F, 3) yaw,
    pitch, roll in radians (module docstring)."""
    yaw, pitch, roll = (np.asarray(angles, dtype=np.float64)[:, i] for i in range(3))
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    one, zero = np.ones_like(yaw), np.zeros_like(yaw)
    ry = np.stack([np.stack([cy, zero, sy], -1), np.stack([zero, one, zero], -1),
                   np.stack([-sy, zero, cy], -1)], -2)
    rx = np.stack([np.stack([one, zero, zero], -1), np.stack([zero, cp, -sp], -1),
                   np.stack([zero, sp, cp], -1)], -2)
    rz = np.stack([np.stack([cr, -sr, zero], -1), np.stack([sr, cr, zero], -1),
                   np.stack([zero, zero, one], -1)], -2)
    return ry @ rx @ rz


def live_link_csv(curves: ArkitCurves) -> str:
    """The text of a Live Link Face CSV holding `curves` (`LIVE_LINK_COLUMNS`), the inverse of
    the reader: ``arkit_curves(text, "csv", label)`` gives back the weights to float32
    rounding (each cell is the shortest text of the weight's float32 value: read and rounded
    to float32, the same number), the head rotation likewise (zero when `curves` has none;
    the eye rotations are zero), and the times to 1/2000 of a frame.

    Timecodes start at 00:00:00:00 and count frames at ``curves.fps`` with a thousandths
    fraction (``HH:MM:SS:FF.sss``), so the reader finds the rate from a take of a second or
    more; give it `fps` for a shorter take (else it assumes Live Link Face's 60) or a rate
    that is not a whole number. BlendShapeCount is 61, as the app writes (52 shapes and 9
    rotations).
    """
    weights = np.asarray(curves.weights, dtype=np.float64)
    k = len(ARKIT_NAMES)
    if weights.ndim != 2 or weights.shape[1] != k or len(weights) == 0:
        raise RetargetError(f"weights must have shape (F, {k}) with F >= 1; got {weights.shape}")
    _check_weights(weights, "the weights")
    if not np.isfinite(curves.fps) or curves.fps <= 0:
        raise RetargetError(f"fps must be a positive number; got {curves.fps!r}")
    frames = len(weights)
    times = np.arange(frames) / curves.fps if curves.times is None \
        else np.asarray(curves.times, dtype=np.float64) - curves.times[0]
    head = np.zeros((frames, 3)) if curves.head is None else np.asarray(curves.head, dtype=np.float64)
    if times.shape != (frames,) or head.shape != (frames, 3):
        raise RetargetError(f"times must have shape ({frames},) and head ({frames}, 3); got "
                            f"{times.shape} and {head.shape}")
    # whole thousandths of a frame: the seconds and frames of a timecode then never round up
    # to a frame number of fps (which would make the reader find the rate one too high)
    per_second = round(curves.fps * 1000)
    seconds, thousandths = np.divmod(np.round(times * curves.fps * 1000).astype(np.int64), per_second)
    order = [arkit_index(c) for c in LIVE_LINK_COLUMNS[2:2 + k]]
    table = np.hstack([weights[:, order], head, np.zeros((frames, 6))]).astype(np.float32)
    lines = [",".join(LIVE_LINK_COLUMNS)]
    for s, ff, row in zip(seconds.tolist(), thousandths.tolist(), table):
        code = f"{s // 3600:02d}:{s // 60 % 60:02d}:{s % 60:02d}:{ff // 1000:02d}.{ff % 1000:03d}"
        cells = (np.format_float_positional(x, unique=True, trim="0") for x in row)
        lines.append(f"{code},{len(LIVE_LINK_COLUMNS) - 2},{','.join(cells)}")
    return "\n".join(lines) + "\n"


# --- CSV ---------------------------------------------------------------------------------

def _from_csv(text: str, label: str, fps) -> ArkitCurves | None:
    reader = csv.reader(io.StringIO(text))
    try:
        header = next(reader, None)
    except csv.Error as exc:
        raise RetargetError(f"{label}: the header row is not CSV: {exc}") from None
    if header is None:
        return None
    names = [c.strip() for c in header]
    lowered = [n.lower() for n in names]
    shapes = {j: arkit_index(n) for j, n in enumerate(names) if arkit_index(n) >= 0}
    if not shapes:
        return None
    repeated = [names[j] for j in shapes if list(shapes.values()).count(shapes[j]) > 1]
    if repeated:
        raise RetargetError(f"{label}: column {repeated[0]!r} names an ARKit shape twice")
    live_link = "timecode" in lowered
    head_cols = [lowered.index(h) if h in lowered else -1 for h in HEAD_COLUMNS]
    if 0 < sum(j >= 0 for j in head_cols) < 3:
        missing = [("HeadYaw", "HeadPitch", "HeadRoll")[i] for i, j in enumerate(head_cols) if j < 0]
        raise RetargetError(f"{label}: head rotation needs HeadYaw, HeadPitch and HeadRoll; it lacks "
                            f"{', '.join(missing)}")
    time_col = next((j for j, n in enumerate(lowered) if n in _TIME_COLUMNS), -1)
    timecode_col = lowered.index("timecode") if live_link else -1
    used = set(shapes) | {j for j in head_cols if j >= 0} | {time_col, timecode_col}
    ignored = [n for j, n in enumerate(names) if j not in used and n.lower() not in
               ("blendshapecount", *_FRAME_COLUMNS)]
    numeric = sorted(set(shapes) | {j for j in head_cols if j >= 0} | ({time_col} - {-1}))
    width, columns = len(names), [names[j] for j in numeric]
    blocks, pending, codes, numbers = [], [], [], []
    try:
        for number, row in enumerate(reader, start=2):
            if not any(cell.strip() for cell in row):
                continue  # a blank line (a trailing newline pair)
            if len(row) != width:
                raise RetargetError(f"{label}: row {number} has {len(row)} cells, the header {width}")
            if (len(numbers) + 1) * len(numeric) > MAX_TAKE_VALUES:
                raise RetargetError(f"{label}: row {number} takes the table past {MAX_TAKE_VALUES} "
                                    "values; split the take")
            pending.append([row[j] for j in numeric])
            numbers.append(number)
            if live_link:
                codes.append(row[timecode_col])
            if len(pending) == _BLOCK_ROWS:  # hold a block of rows as strings, not the file
                blocks.append(_numbers(pending, numbers[-len(pending):], label, columns))
                pending = []
    except csv.Error as exc:
        raise RetargetError(f"{label}: not CSV past row {len(numbers) + 1}: {exc}") from None
    if not numbers:
        raise RetargetError(f"{label}: the header is not followed by any frame")
    if pending:
        blocks.append(_numbers(pending, numbers[-len(pending):], label, columns))
    table = np.concatenate(blocks)
    column = {j: i for i, j in enumerate(numeric)}
    weights = np.zeros((len(table), len(ARKIT_NAMES)))
    for j, k in shapes.items():
        weights[:, k] = table[:, column[j]]
    _check_weights(weights, label)
    head = table[:, [column[j] for j in head_cols]] if min(head_cols) >= 0 else None
    meta = {"format": "live_link_face" if live_link else "arkit_csv", "ignored": ignored}
    if live_link:
        times, rate, assumed = _timecodes(codes, numbers, label, fps)
    elif time_col >= 0:
        times = table[:, column[time_col]]
        times = times - times[0]
        rate, assumed = _rate(fps, times)
    else:
        times, (rate, assumed) = None, _rate(fps, None)
    return _curves(weights, rate, times, head, {**meta, "fps_assumed": assumed}, label)


def _numbers(rows: list[list[str]], numbers: list[int], label: str, columns: list[str]) -> np.ndarray:
    """(R, C) float64 from string cells; refuses empty, non-numeric and non-finite cells,
    naming the file's row (`numbers`, the header is row 1) and column."""
    longest = max((len(c) for row in rows for c in row), default=1)
    cells = np.char.strip(np.array(rows, dtype=f"U{min(max(longest, 1), _MAX_CELL + 1)}"))
    bad = (np.char.str_len(cells) == 0) | (np.char.str_len(cells) > _MAX_CELL)
    if not bad.any():
        try:
            values = cells.astype(np.float64)
        except ValueError:
            values = None
        if values is not None and np.isfinite(values).all():
            return values
    for (i, j), cell in np.ndenumerate(cells):
        try:
            ok = len(cell) <= _MAX_CELL and np.isfinite(float(cell))
        except ValueError:
            ok = False
        if not ok:
            raise RetargetError(f"{label}: row {numbers[i]}, column {columns[j]}: {cell[:40]!r} is not a "
                                "finite number")
    raise AssertionError("unreachable: some cell was refused above")


def _timecodes(codes: list[str], numbers: list[int], label: str, fps) -> tuple[np.ndarray, float, bool]:
    """(F,) seconds from the first frame, the rate and whether it was assumed, from Live Link
    Face timecodes ``HH:MM:SS:FF[.sss]`` (module docstring)."""
    parts = np.zeros((len(codes), 4))
    for i, code in enumerate(codes):
        m = _TIMECODE.match(code)
        if m is None:
            raise RetargetError(f"{label}: row {numbers[i]}, column Timecode: {code[:40]!r} is not "
                                "HH:MM:SS:FF or HH:MM:SS:FF.sss")
        parts[i] = [float(g) for g in m.groups()]
    whole = parts[:, 0] * 3600 + parts[:, 1] * 60 + parts[:, 2]
    if fps is not None:
        rate, assumed = float(fps), False
    elif np.ptp(whole) >= 1:
        rate, assumed = float(np.floor(parts[:, 3].max()) + 1), False
    else:
        rate, assumed = LIVE_LINK_FPS, True
    times = whole + parts[:, 3] / rate
    times -= times[0]
    back = np.flatnonzero(np.diff(times) < 0)
    if len(back):
        raise RetargetError(f"{label}: row {numbers[back[0] + 1]}: the timecode "
                            f"{codes[back[0] + 1]!r} goes back "
                            f"from {codes[back[0]]!r}")
    return times, rate, assumed


# --- JSON --------------------------------------------------------------------------------

def _from_json(text: str, label: str, fps) -> ArkitCurves | None:
    if '"weights"' not in text:
        return None
    doc = json_document(text, label)
    if not isinstance(doc, dict) or "weights" not in doc:
        return None
    rows = doc["weights"]
    if not isinstance(rows, list) or not rows:
        raise RetargetError(f'{label}: "weights" must be a non-empty list of frames')
    if len(rows) * len(ARKIT_NAMES) > MAX_TAKE_VALUES:
        raise RetargetError(f"{label}: {len(rows)} frames exceed the {MAX_TAKE_VALUES} values a take "
                            "may hold")
    ignored: set[str] = set()
    weights = np.zeros((len(rows), len(ARKIT_NAMES)))
    if all(isinstance(r, dict) for r in rows):
        named = False
        for f, row in enumerate(rows):
            for key, value in row.items():
                k = arkit_index(key)
                if k < 0:
                    ignored.add(str(key))
                else:
                    named = True
                    weights[f, k] = _json_number(value, label, f"frame {f}, {key!r}")
        if not named:
            raise RetargetError(f"{label}: the weights name none of the 52 ARKit shapes"
                                + (f" (they name {', '.join(sorted(ignored)[:5])})" if ignored else ""))
    else:
        names = doc.get("names")
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise RetargetError(f'{label}: rows of "weights" that are lists need "names", a list of '
                                'strings')
        index = [arkit_index(n) for n in names]
        if max(index, default=-1) < 0:
            raise RetargetError(f'{label}: "names" holds none of the 52 ARKit names')
        if len({k for k in index if k >= 0}) != sum(k >= 0 for k in index):
            raise RetargetError(f'{label}: "names" names an ARKit shape twice')
        ignored = {n for n, k in zip(names, index) if k < 0}
        for f, row in enumerate(rows):
            if not isinstance(row, list) or len(row) != len(names):
                got = len(row) if isinstance(row, list) else type(row).__name__
                raise RetargetError(f'{label}: frame {f} of "weights" has {got} values, "names" '
                                    f'{len(names)}')
            for j, k in enumerate(index):
                if k >= 0:
                    weights[f, k] = _json_number(row[j], label, f"frame {f}, {names[j]!r}")
    _check_weights(weights, label)
    times = doc.get("times")
    if times is not None:
        if not isinstance(times, list) or len(times) != len(rows):
            raise RetargetError(f'{label}: "times" must be a list of {len(rows)} numbers, one per frame')
        times = np.array([_json_number(t, label, f'"times"[{i}]') for i, t in enumerate(times)])
        times -= times[0]
    head = doc.get("head")
    if head is not None:
        if not isinstance(head, list) or len(head) != len(rows) or \
                not all(isinstance(h, list) and len(h) == 3 for h in head):
            raise RetargetError(f'{label}: "head" must be a list of {len(rows)} [yaw, pitch, roll]')
        head = np.array([[_json_number(a, label, f'"head"[{i}]') for a in h] for i, h in enumerate(head)])
    file_fps = doc.get("fps")
    if file_fps is not None and fps is None:
        fps = _json_number(file_fps, label, '"fps"')
        if fps <= 0:
            raise RetargetError(f'{label}: "fps" must be positive, got {fps!r}')
    rate, assumed = _rate(fps, times)
    return _curves(weights, rate, times, head, {"format": "arkit_json", "ignored": sorted(ignored),
                                                "fps_assumed": assumed}, label)


def _json_number(value, label: str, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise RetargetError(f"{label}: {where} must be a finite number, got {value!r:.40}")
    return float(value)


# --- common ------------------------------------------------------------------------------

def _check_weights(weights: np.ndarray, label: str) -> None:
    """Refuse weights outside [0, 1] (ARKit's range), naming the first."""
    bad = np.argwhere((weights < 0) | (weights > 1))
    if len(bad):
        f, k = bad[0]
        hint = " (a 0-100 scale? divide by 100)" if weights.max() > 1 and weights.max() <= 100 else ""
        raise RetargetError(f"{label}: frame {f}, {ARKIT_NAMES[k]} is {weights[f, k]:g}; ARKit weights "
                            f"are in [0, 1]{hint}")


def _rate(fps, times) -> tuple[float, bool]:
    """(frame rate, assumed): the caller's, the times' median step, `LIVE_LINK_FPS`."""
    if fps is not None:
        return float(fps), False
    if times is not None and len(times) > 1:
        step = float(np.median(np.diff(times)))
        if step > 0:
            return 1.0 / step, False
    return LIVE_LINK_FPS, True


def _curves(weights, rate, times, head, meta, label) -> ArkitCurves:
    if times is not None and (np.diff(times) < 0).any():
        f = int(np.flatnonzero(np.diff(times) < 0)[0]) + 1
        raise RetargetError(f"{label}: the time goes back at frame {f}")
    if head is not None and (np.abs(head) > np.pi).any():
        f, a = np.argwhere(np.abs(head) > np.pi)[0]
        raise RetargetError(f"{label}: frame {f}, head {('yaw', 'pitch', 'roll')[a]} is {head[f, a]:g}; "
                            "head angles are radians within [-pi, pi] (degrees? divide by 57.3)")
    return ArkitCurves(weights, rate, times, head, meta)
