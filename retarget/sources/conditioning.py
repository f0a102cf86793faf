"""Conditioning of source feature points before retargeting: neutral capture, head-motion
removal, temporal filtering and per-region gain.

Per frame, in this order (Woodward et al. §5 and §5.1):

1. neutral: the rest points S0, captured from the first seconds of the performance
   ("acquired during the first few seconds of marker motion capture", the face still,
   head movement allowed), taken from one frame, or given;
2. head pose (3D sources only): the rigid head motion is removed on the layout's stable
   points (`retarget.sources.headpose`), so only facial motion reaches the target; the
   head's rotation is kept in `rotation_` for a consumer that turns the target's head;
3. filter: none, Woodward's 3-frame temporal mean, or the One Euro filter with per-region
   parameters (`retarget.sources.filters`);
4. gain: ``S0 + g_region (S - S0)``, exaggerating or damping a region's motion.

`SourceConditioner` works online (`push` one frame at a time); `condition_take` runs it
over a whole take, so a recorded take and a live stream are conditioned alike.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from retarget.errors import RetargetError
from retarget.layouts import GROUPS, LAYOUTS, REGIONS, Layout, get_layout
from retarget.sources.filters import OneEuroFilter, TemporalMean
from retarget.sources.headpose import HeadMotionRemover, head_neutral, remove_head_motion, stable_indices
from retarget.sources.take import Take

__all__ = ["ConditionSettings", "NeutralMoved", "SourceConditioner", "condition_take", "eye_distance"]

NEUTRAL_MODES = ("first_seconds", "frame", "given")
HEAD_POSE_MODES = ("remove", "keep")
FILTERS = ("none", "mean3", "one_euro")
DEFAULT_ONE_EURO = {"min_cutoff": 1.0, "beta": 5.0}

# Region keys the settings accept: regions, groups and the point names of every layout.
_SELECTORS = set(REGIONS) | set(GROUPS) | {p for lay in LAYOUTS.values() for p in lay.point_names}


class NeutralMoved(RetargetError):
    """A neutral capture refused because the performer moved during it; ``motion`` is the
    largest point motion found (`SourceConditioner._capture_motion`: how far apart the
    middle half of a point's positions in the capture lie), in eye distances
    (`SourceConditioner`'s ``max_neutral_motion``)."""

    def __init__(self, motion: float, allowed: float):
        self.motion = motion
        super().__init__(
            "You moved during the neutral capture: hold still and capture again "
            f"(a point moved {motion:.2f} eye distances; at most {allowed:.2f} is still)")


@dataclass
class ConditionSettings:
    """How a source is conditioned; JSON-able with `to_dict` / `from_dict`.

    neutral : {"mode": "first_seconds" | "frame" | "given", "seconds": float >= 0,
        "frame": int >= 0}. "first_seconds": the per-point median of the frames within
        `seconds` of the first (3D with head pose removal: each registered on the stable
        points first, `headpose.head_neutral`), frames before the neutral is known give
        no output; frames without any point (a camera that sees no face) wait, and a
        capture that fails starts again with the next frame; "frame": the `frame`-th frame; "given": the caller passes it.
    head_pose : "remove" (3D sources: rigid head motion removed, Woodward §5.1) or "keep".
        2D sources keep it whatever this says.
    apply_rotation : whether the consumer should turn the target's head by the
        performer's head rotation (`SourceConditioner.rotation_`); the points are the
        same either way. The app's "turn the head"; a take played with it carries the
        rotations into its clip, which the glTF export plays as a ``head`` node
        (`retarget.gltf.head`).
    filter : "none", "mean3" (Woodward §5, 3-frame mean) or "one_euro".
    one_euro : {selector: {"min_cutoff": Hz > 0, "beta": >= 0}}, optionally "d_cutoff"
        (Hz > 0) at the top level. beta is in seconds per face size: speeds are measured
        in face sizes per second (the RMS distance of the neutral points from their
        centroid), so one setting suits pixels, cm and mm.
    gain : {selector: float >= 0}, 1 = as performed.

    A selector is a region, a group (`retarget.layouts.GROUPS`, e.g. "mouth", "all") or
    a point name; entries apply in the order given, a later one overriding an earlier
    one for the points both select. Points no entry selects get `DEFAULT_ONE_EURO` and
    gain 1.
    """

    neutral: dict = field(default_factory=lambda: {"mode": "first_seconds", "seconds": 0.5, "frame": 0})
    head_pose: str = "remove"
    apply_rotation: bool = False
    filter: str = "none"
    one_euro: dict = field(default_factory=dict)
    gain: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.neutral = _neutral(self.neutral)
        for name, allowed in (("head_pose", HEAD_POSE_MODES), ("filter", FILTERS)):
            if getattr(self, name) not in allowed:
                raise RetargetError(
                    f"settings {name} must be one of {', '.join(allowed)}; got {getattr(self, name)!r}")
        if not isinstance(self.apply_rotation, bool):
            raise RetargetError(f"settings apply_rotation must be true or false; got {self.apply_rotation!r}")
        self.one_euro = _one_euro(self.one_euro)
        self.gain = _gain(self.gain)

    def to_dict(self) -> dict:
        """A JSON-able copy."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict | None) -> "ConditionSettings":
        """Settings from `to_dict`'s form; missing keys take the defaults, unknown keys are
        refused by name."""
        if data is None:
            return cls()
        if not isinstance(data, dict):
            raise RetargetError(f"conditioning settings must be an object; got {type(data).__name__}")
        unknown = sorted(set(data) - set(cls.__dataclass_fields__))
        if unknown:
            raise RetargetError(
                f"unknown conditioning settings: {', '.join(unknown)}; known: "
                f"{', '.join(cls.__dataclass_fields__)}")
        return cls(**data)


class SourceConditioner:
    """Online conditioning of one source's frames (see the module docstring).

    layout : the layout the points follow (a name or `Layout`), or None for points with
        no layout (then only the "all" selector, and no head pose removal).
    dims : 2 or 3, the source's dimension.
    settings : `ConditionSettings` (or its dict form); default `ConditionSettings()`.
    neutral : (N, dims) float, the neutral for mode "given" (refused otherwise).
    max_neutral_motion : None, or the most a point may move during a "first_seconds"
        capture, in eye distances (`eye_distance`): a point's motion is how far apart the
        middle half of its positions in the capture lie (`_capture_motion`; registered on
        the stable points when head motion is removed, so moving the head is allowed, as
        Woodward §5.1 has it). A
        capture that moved more raises `NeutralMoved`, and no neutral is taken (`push`
        gives None) until `reset()`: a live performer is asked to capture again rather
        than have a grimace become the rest pose.
    lost_wait : None, or seconds a "first_seconds" capture goes on past its span while a
        point has been lost in every frame of it (a live tracker that finds the last
        markers a few frames in, or a stalled camera that gave only a frame or two).
        After that the neutral is taken without those points (NaN rows, ``waiting_``
        names them) and each joins when it shows: its neutral is the median of its
        positions over its first `seconds` seen (in the head frame when head motion is
        removed; an anchor then anchors too), and ``neutral_`` is replaced by a new array
        with it. Woodward's temple stickers show only when the head turns; a live session
        waits for none of them. Without `lost_wait` such a capture is refused at once,
        naming the points.

    `push(points (N, D), t seconds) -> (N, D) float32 | None`: None while the neutral is
    being captured; lost points (NaN rows) stay NaN. After the capture, ``neutral_``
    (N, D) float32 holds S0 (in the head frame when head motion is removed) and
    ``rotation_`` (3, 3) the performer's head rotation relative to the neutral in the
    latest frame (identity for 2D sources, with head_pose "keep", and before a pose is
    known). `reset()` starts over, capturing the neutral again unless it was given.
    """

    def __init__(self, layout, dims: int, settings=None, neutral=None, *,
                 max_neutral_motion: float | None = None, lost_wait: float | None = None):
        self.layout = None if layout is None else layout if isinstance(layout, Layout) else get_layout(layout)
        if dims not in (2, 3):
            raise RetargetError(f"dims must be 2 or 3; got {dims!r}")
        self.dims = dims
        self.settings = settings if isinstance(settings, ConditionSettings) \
            else ConditionSettings.from_dict(settings)
        s = self.settings
        self.removes_head = dims == 3 and s.head_pose == "remove"
        if self.removes_head and self.layout is None:
            raise RetargetError("head pose removal needs a layout (it works on the stable points)")
        self._stable = stable_indices(self.layout) if self.removes_head else None
        self._n = None if self.layout is None else self.layout.n_points
        self._given = None
        if s.neutral["mode"] == "given":
            if neutral is None:
                raise RetargetError('neutral mode "given" needs the neutral points')
            self._given = self._checked(neutral, "neutral")
            if np.isnan(self._given).any():
                raise RetargetError(f"the given neutral has lost points: {self._names(np.isnan(self._given[:, 0]))}")
        elif neutral is not None:
            raise RetargetError(f'a neutral was given but the neutral mode is {s.neutral["mode"]!r}')
        if max_neutral_motion is not None and not (math.isfinite(max_neutral_motion) and max_neutral_motion > 0):
            raise RetargetError(f"max_neutral_motion must be a positive number of eye distances; got {max_neutral_motion!r}")
        self.max_neutral_motion = max_neutral_motion
        if lost_wait is not None and not (math.isfinite(lost_wait) and lost_wait >= 0):
            raise RetargetError(f"lost_wait must be a number of seconds >= 0; got {lost_wait!r}")
        self.lost_wait = lost_wait
        self.reset()

    def reset(self) -> None:
        """Forget all state: the neutral is captured again (unless given), filters restart."""
        self.neutral_ = None
        self.rotation_ = np.eye(3)
        self._refused = False  # a capture moved: none is taken until reset()
        self._captured: list[np.ndarray] = []
        self._t0 = None
        self._count = 0
        self._remover = self._filter = self._gain = None
        self.waiting_: tuple[str, ...] = ()
        self._late: dict[int, list] = {}   # a point joining late: [first time seen, positions]
        if self._given is not None:
            self._start(self._given)

    def push(self, points, t: float) -> np.ndarray | None:
        """The conditioned (N, D) float32 points of one frame at time `t` (seconds), or
        None while the neutral is still being captured."""
        p = self._checked(points, "points")
        t = float(t)
        if not math.isfinite(t):
            raise RetargetError(f"frame time must be finite; got {t!r}")
        index, self._count = self._count, self._count + 1
        if self._refused:
            return None
        if self.neutral_ is None:
            mode = self.settings.neutral
            if mode["mode"] == "frame":
                if index < mode["frame"]:
                    return None
                lost = np.isnan(p[:, 0])
                if lost.any():
                    raise RetargetError(f"neutral frame {index} has lost points: {self._names(lost)}")
                self._start(p)
            else:
                if self._t0 is None:
                    if np.isnan(p[:, 0]).all():
                        return None  # nothing tracked yet (a live camera without a face)
                    self._t0 = t
                if t <= self._t0 + mode["seconds"] or self._waits_for_lost(t):
                    self._captured.append(p)
                    return None
                self._start(self._captured_neutral())
        return self._conditioned(p, t)

    def _waits_for_lost(self, t: float) -> bool:
        """Whether a capture past its span goes on (`lost_wait`): a point is lost in every
        frame so far and the wait has not run out."""
        if self.lost_wait is None or not self._captured:
            return False
        end = self._t0 + self.settings.neutral["seconds"] + self.lost_wait
        return t <= end and bool(np.isnan(np.stack(self._captured)[..., 0]).all(axis=0).any())

    def _captured_neutral(self) -> np.ndarray:
        frames = np.stack(self._captured)
        self._captured, self._t0 = [], None  # a failed capture starts again at the next frame
        lost = np.isnan(frames[..., 0]).all(axis=0)
        if lost.any() and (self.lost_wait is None or lost.all()):
            raise RetargetError(
                f"no neutral for points lost throughout the first {self.settings.neutral['seconds']:g} s: "
                f"{self._names(lost)}")
        seen = np.flatnonzero(~lost)
        neutral = np.full(frames.shape[1:], np.nan, np.float32)
        if self.removes_head:
            stable = np.flatnonzero(np.isin(seen, self._stable))
            if len(stable) < 3:
                raise RetargetError(
                    f"no neutral: only {len(stable)} of the head's stable points were seen in the first "
                    f"{self.settings.neutral['seconds']:g} s (3 are needed); lost: {self._names(lost)}")
            neutral[seen] = head_neutral(frames[:, seen], stable)
        else:
            neutral[seen] = frames[0, seen] if len(frames) == 1 else np.nanmedian(frames[:, seen], axis=0)
        # A point seen only in frames whose anchors fixed no pose has no place either: it
        # waits and joins once seen, as a point never seen does.
        self.waiting_ = tuple(self._names(np.isnan(neutral[:, 0]), every=True))
        if self.max_neutral_motion is not None:
            motion = self._capture_motion(frames[:, seen], neutral[seen], seen)
            if motion > self.max_neutral_motion:
                self._refused = True
                raise NeutralMoved(motion, self.max_neutral_motion)
        return neutral

    def _capture_motion(self, frames: np.ndarray, neutral: np.ndarray, seen: np.ndarray) -> float:
        """How far the face moved during the capture, in eye distances: the largest, over
        the points `seen` ((K,) indices) of (F, K, D) `frames` (head motion taken out
        first when it is removed against `neutral` (K, D)), of how far apart the middle
        half of a point's positions lie (the length of its per-axis interquartile range,
        the quartiles taken as frames, not between them); 0 for one frame.

        The middle half, not the largest distance from the neutral: a point away for
        under a quarter of the frames (a blink, a live tracker's depth spike) leaves each
        point's median, the neutral, as the still face's, while one away for a quarter or
        more (a word, a smile begun, which the median may take as the rest pose) spreads
        its middle half. Quartiles as frames, so that a capture of 3 or 4 frames (a page
        tracking a frame a second), half of them a grimace, spans the grimace, where an
        interpolated quartile or median halves it. (The largest distance refused live
        stickers on a still face: issue 17's take at 10 pairs/s, 0.33 eye distances.)"""
        if self.removes_head:
            frames = remove_head_motion(frames, neutral, np.flatnonzero(np.isin(seen, self._stable)))[0]
        if not np.isfinite(frames).any():
            return 0.0
        with warnings.catch_warnings():   # a point lost in every registered frame
            warnings.simplefilter("ignore", RuntimeWarning)
            low, high = np.nanpercentile(frames, [25, 75], axis=0, method="nearest")
        spread = np.linalg.norm(high - low, axis=1)   # (K,), NaN for a point never seen
        full = np.full((self._n, neutral.shape[1]), np.nan)
        full[seen] = neutral
        return float(np.nanmax(spread)) / eye_distance(full, self.layout)

    def _start(self, neutral: np.ndarray) -> None:
        """Set S0 and build the per-frame steps that depend on it."""
        self.neutral_ = np.asarray(neutral, dtype=np.float32)
        if self.removes_head:
            self._remover = HeadMotionRemover(self.neutral_, self._stable)
        s = self.settings
        self._gain = self._per_point(s.gain, 1.0) if s.gain else None
        if s.filter == "mean3":
            self._filter = TemporalMean(3)
        elif s.filter == "one_euro":
            centred = self.neutral_ - np.nanmean(self.neutral_, axis=0)
            size = float(np.sqrt(np.nanmean(np.sum(centred**2, axis=1)))) or 1.0
            params = {k: v for k, v in s.one_euro.items() if k != "d_cutoff"}
            min_cutoff = self._per_point({k: v["min_cutoff"] for k, v in params.items()},
                                         DEFAULT_ONE_EURO["min_cutoff"])
            beta = self._per_point({k: v["beta"] for k, v in params.items()}, DEFAULT_ONE_EURO["beta"])
            self._filter = OneEuroFilter(min_cutoff, beta / size, s.one_euro.get("d_cutoff", 1.0))

    def _conditioned(self, p: np.ndarray, t: float) -> np.ndarray:
        if self._remover is not None:
            p = self._remover(p)
            rotation = self._remover.rotation_
            self.rotation_ = rotation.T if np.isfinite(rotation).all() else np.eye(3)
        if self.waiting_:
            p = self._joined(p, t)
        if self._filter is not None:
            p = self._filter(p, t)
        if self._gain is not None:
            p = self.neutral_ + self._gain[:, None] * (p - self.neutral_)
        return np.asarray(p, dtype=np.float32)

    def _joined(self, p: np.ndarray, t: float) -> np.ndarray:
        """`p` (N, D), registered, with the points still waiting for their neutral NaN;
        a waiting point seen for `seconds` joins (`lost_wait`)."""
        waiting = np.flatnonzero(np.isnan(self.neutral_[:, 0]))
        for i in waiting[np.isfinite(p[waiting, 0])]:
            first, positions = self._late.setdefault(int(i), [t, []])
            if t <= first + self.settings.neutral["seconds"]:   # its span, as the capture's
                positions.append(p[i].copy())
                continue
            neutral = self.neutral_.copy()   # a new array: a consumer refits on it
            neutral[i] = np.median(positions, axis=0)
            if self._remover is not None and i in self._stable:
                self._remover.place([i], neutral[i:i + 1])
            self.neutral_ = neutral
            del self._late[int(i)]
        lost = np.isnan(self.neutral_[:, 0])
        self.waiting_ = tuple(self._names(lost, every=True))
        p = p.copy()
        p[lost] = np.nan
        return p

    def settled_neutral(self) -> np.ndarray:
        """(N, D) float32 ``neutral_`` with each point still waiting to join at the median
        of its positions so far (NaN for one not seen since the capture): the end of a
        take that stops inside a late point's span."""
        neutral = self.neutral_.copy()
        for i, (_, positions) in self._late.items():
            if positions:
                neutral[i] = np.median(positions, axis=0)
        return neutral

    def _per_point(self, entries: dict, default: float) -> np.ndarray:
        """(N,) float64 values from {selector: value}, later entries overriding."""
        out = np.full(self._n, default, dtype=np.float64)
        for selector, value in entries.items():
            if self.layout is None:
                if selector != "all":
                    raise RetargetError(
                        f"points without a layout take only the selector 'all'; got {selector!r}")
                out[:] = value
            else:
                out[self.layout.region_mask(selector)] = value
        return out

    def _checked(self, points, what: str) -> np.ndarray:
        try:
            p = np.array(points, dtype=np.float32)
        except (TypeError, ValueError):
            raise RetargetError(f"{what} must be a numeric (N, {self.dims}) array") from None
        if self._n is None and p.ndim == 2:
            self._n = len(p)  # without a layout, the first frame tells N
        if p.shape != (self._n, self.dims):
            raise RetargetError(f"{what} must have shape ({self._n}, {self.dims}); got {p.shape}")
        if np.isinf(p).any():
            raise RetargetError(f"{what} has infinite coordinates")
        p[np.isnan(p).any(axis=1)] = np.nan
        return p

    def _names(self, mask: np.ndarray, *, every: bool = False):
        """The names of the points in `mask`: a text (the first 12), or every name as a list."""
        idx = np.flatnonzero(mask)
        names = [self.layout.point_names[i] if self.layout else f"point {i}" for i in idx]
        if every:
            return names
        return ", ".join(names[:12]) + (f" and {len(idx) - 12} more" if len(idx) > 12 else "")



def eye_distance(points, layout: Layout | None) -> float:
    """The distance between the eye centres of (N, D) `points` (the means of the layout's
    ``eye_left*`` and ``eye_right*`` points), in the points' units; without a layout or
    eye points, the face size (RMS distance of the points from their centroid). Never 0:
    1.0 for a degenerate face."""
    p = np.asarray(points, dtype=np.float64)
    if layout is not None:
        names = np.array(layout.point_names)
        left, right = np.char.startswith(names, "eye_left"), np.char.startswith(names, "eye_right")
        if left.any() and right.any():
            d = float(np.linalg.norm(np.nanmean(p[left], axis=0) - np.nanmean(p[right], axis=0)))
            if math.isfinite(d) and d > 0:
                return d
    centred = p - np.nanmean(p, axis=0)
    size = float(np.sqrt(np.nanmean(np.sum(centred**2, axis=1))))
    return size if math.isfinite(size) and size > 0 else 1.0


def condition_take(take: Take, settings=None, neutral=None, *, with_rotations: bool = False):
    """(conditioned take, (N, D) float32 neutral): every frame of `take` pushed through a
    `SourceConditioner`, as a live stream of it would be once its neutral is known.

    A recorded take is all there before it plays, so its neutral is found first (from the
    first seconds or the chosen frame, as a live capture would find it) and then every
    frame is conditioned against it: no frame is left out, and the result has the take's
    own times (a 6.72 s take stays 6.72 s; an export keeps the mouth in sync with the
    take's sound). `RetargetError` when the take ends before its neutral capture does.
    A point lost throughout the capture's span takes its place once seen, as in a live
    capture with ``lost_wait`` (a stereo sticker take's temple, hidden until the head
    turns); a neutral frame ("frame" mode) must still see every point.

    Points that are lost in every frame (a 21-marker take read into a 68-point layout)
    are left out of the conditioning, which runs on the sub-layout of the others
    (`Layout.select`), and come back as NaN rows of the result and of the neutral.

    with_rotations : also return the (F, 3, 3) head rotations (``rotation_``) of the
        frames, for a player that turns the target's head.
    """
    present = ~np.isnan(take.points[..., 0]).all(axis=0)
    layout = get_layout(take.layout) if take.layout else None
    rows = slice(None)  # the points conditioned
    if layout is not None and not present.all() and present.any():
        rows, layout = present, layout.select(present)
        if neutral is not None:
            neutral = np.asarray(neutral)[rows]
    points = take.points[:, rows]
    times = take.frame_times()
    asked = settings if isinstance(settings, ConditionSettings) else ConditionSettings.from_dict(settings)
    settings = asked
    if neutral is None and asked.neutral["mode"] != "given":
        neutral = _captured_neutral(layout, take.dims, asked, points, times)
        settings = replace(asked, neutral={**asked.neutral, "mode": "given"})
    conditioner = SourceConditioner(layout, take.dims, settings, neutral)
    out, rotations = [], []
    for i in range(take.n_frames):
        out.append(conditioner.push(points[i], times[i]))
        rotations.append(conditioner.rotation_)
    conditioned = np.full((take.n_frames, take.n_points, take.dims), np.nan, np.float32)
    neutral_out = np.full((take.n_points, take.dims), np.nan, np.float32)
    conditioned[:, rows] = np.stack(out)
    neutral_out[rows] = conditioner.neutral_
    meta = dict(take.meta, conditioning=asked.to_dict())
    result = Take(conditioned, take.names, take.fps, times - times[0], take.layout,
                  take.source, meta)
    if with_rotations:
        return result, neutral_out, np.stack(rotations)
    return result, neutral_out


def _captured_neutral(layout, dims: int, settings, points: np.ndarray,
                      times: np.ndarray) -> np.ndarray:
    """The neutral a live capture of these frames would take (`SourceConditioner`), the
    points lost throughout its span included as they join once seen (``lost_wait`` 0: a
    take holds them all; a stereo sticker take's temple shows only when the head turns,
    and no frame may see both temples)."""
    capture = SourceConditioner(layout, dims, settings, lost_wait=0.0)
    for i in range(len(points)):
        if capture.push(points[i], times[i]) is not None and not capture.waiting_:
            return capture.neutral_
    if capture.neutral_ is not None:   # a point first seen in the take's last moments
        return capture.settled_neutral()
    raise RetargetError(
        f"the take ({times[-1] - times[0]:.3f} s) ends before its neutral capture does "
        f"({settings.neutral['seconds']:g} s)")


def _neutral(value) -> dict:
    if not isinstance(value, dict):
        raise RetargetError(f"settings neutral must be an object; got {value!r}")
    unknown = sorted(set(value) - {"mode", "seconds", "frame"})
    if unknown:
        raise RetargetError(f"settings neutral has unknown keys: {', '.join(unknown)}")
    out = {"mode": value.get("mode", "first_seconds"), "seconds": value.get("seconds", 0.5),
           "frame": value.get("frame", 0)}
    if out["mode"] not in NEUTRAL_MODES:
        raise RetargetError(f"settings neutral mode must be one of {', '.join(NEUTRAL_MODES)}; got {out['mode']!r}")
    seconds = out["seconds"]
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) \
            or not math.isfinite(seconds) or seconds < 0:
        raise RetargetError(f"settings neutral seconds must be a number >= 0; got {seconds!r}")
    frame = out["frame"]
    if isinstance(frame, bool) or not isinstance(frame, int) or frame < 0:
        raise RetargetError(f"settings neutral frame must be an integer >= 0; got {frame!r}")
    out["seconds"] = float(seconds)
    return out


def _selector(key, what: str) -> str:
    if key not in _SELECTORS:
        raise RetargetError(
            f"settings {what} selector {key!r} is not a region, group or point name "
            f"(regions: {', '.join(REGIONS)}; groups: {', '.join(GROUPS)})")
    return key


def _number(value, what: str, positive: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or (value <= 0 if positive else value < 0):
        raise RetargetError(f"settings {what} must be a number {'> 0' if positive else '>= 0'}; got {value!r}")
    return float(value)


def _one_euro(value) -> dict:
    if not isinstance(value, dict):
        raise RetargetError(f"settings one_euro must be an object; got {value!r}")
    out = {}
    for key, params in value.items():
        if key == "d_cutoff":
            out[key] = _number(params, "one_euro d_cutoff", positive=True)
            continue
        _selector(key, "one_euro")
        if not isinstance(params, dict) or set(params) - {"min_cutoff", "beta"}:
            raise RetargetError(
                f"settings one_euro[{key!r}] must be {{\"min_cutoff\": Hz, \"beta\": number}}; got {params!r}")
        out[key] = {
            "min_cutoff": _number(params.get("min_cutoff", DEFAULT_ONE_EURO["min_cutoff"]),
                                  f"one_euro[{key!r}] min_cutoff", positive=True),
            "beta": _number(params.get("beta", DEFAULT_ONE_EURO["beta"]),
                            f"one_euro[{key!r}] beta", positive=False),
        }
    return out


def _gain(value) -> dict:
    if not isinstance(value, dict):
        raise RetargetError(f"settings gain must be an object; got {value!r}")
    return {_selector(k, "gain"): _number(v, f"gain[{k!r}]", positive=False) for k, v in value.items()}
