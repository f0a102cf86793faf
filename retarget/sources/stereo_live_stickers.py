"""Live stereo capture of unnamed stickers of one colour (issue 17 §3, Woodward §5).

Woodward et al. film 13 blue stickers with two webcams, live. Offline,
`retarget.sources.stereo` follows such stickers through a take (`StickerTracks`), then
fits the head pose over the whole take (`anchored_poses`) and smooths each sticker's
depth along its line of sight over a centred window (`sight_smoothed`). Here every step
is causal, one frame pair in, that pair's points out (`LiveStickerTracker.push`):

1. the stickers are followed frame by frame by the same `StickerTracks`; each confirmed
   track is a column, m01..mM in the order confirmed (those confirmed in one pair top to
   bottom, then left to right), so a sticker that appears later gets a new column at the
   end and M only grows. Offline orders the same tracks by the pair first seen, and a
   track confirmed after others may have been seen first (issue 17's take, seed 0: the
   right brow's, seen from the first pair and confirmed at the seventh), so a sticker's
   live name need not be its offline one;
2. a **set-up span** (`setup_seconds` of capture time from the first pair showing 3
   stickers) fixes the head frame. The anchors are the named ones (1 s is enough), or a
   layout's own found by place (below; 1 s), or
   else the 4 most mutually rigid stickers of the span (`rigid_anchors`), which needs the
   face to move in it (talk, smile, raise the brows: 3 s by default; on a still span any
   sticker looks rigid. Issue 17's take, seed 0, 120 pairs, median / p95 shape error
   after the set-up: 1 s, mostly of the neutral face, 1.61 / 4.50 mm, 3 s 1.01 / 3.43).
   The head may move. The head frame is that of the span's first pair seeing 3 anchors
   (`anchored_poses`). Every pair of the span comes out NaN;
3. after it, each pair's head pose is the rigid fit of every column it sees onto its
   place, weighted by the column's steadiness, then twice reweighted by how far each
   lies off its place (Cauchy, 1 mm: `_fit`), so that the stickers an expression moves
   count little and the nose, brows at rest and anchors carry it. Each column's place is
   the median of its first `_KEEP` registrations in the head frame (the span's, then
   those of pairs where 3 placed anchors are seen): a median, since a temple's first
   sightings, half hidden at a grazing angle, are millimetres off, and frozen once full,
   so the head frame cannot drift in a long session. The anchors fix the head frame and
   decide which pairs are learned from; a column not seen in the span joins with its
   first registration, loose (`_PRIOR_SPREAD`) until it has more: the pose never jumps
   when the visible set changes, and a pair with no fit holds the last pose. Fitted to
   the 3-4 anchors alone, the pose took their triangulation noise with it (at 1 m with
   an 80 mm baseline, a tenth of a pixel is about 1.6 mm along the line of sight):
   1.24 / 4.08 mm against 0.89 / 3.17 on the bench below (3 seeds), 1.28 / 5.26 against
   0.95 / 3.84 on seeds 3-5; weighing the columns by steadiness alone, with no
   reweighting, 0.94 / 3.42 and 1.20 / 4.07 (all with the 3-frame mean of step 5);
4. the depth is steadied causally: in the head frame, each sticker's component along
   its line of sight moves to the weighted median of its last `depth_window` positions
   (and this one) along that line, each weighted by how near it lay across the line
   (Gaussian, `across` mm) to this pair's position: the one-sided form of
   `sight_smoothed` (a triangulated sticker's error lies along its line of sight; across
   it the position is a tenth of a pixel sure, and an expression's move shows there).
   Measured on issue 17's take (seed 0, 120 pairs, named anchors, median / p95 mm):
   window 1 (none) 1.65 / 5.43, 15 1.37 / 3.71, 30 1.21 / 3.55, 45 1.17 / 3.33, 60
   1.17 / 3.11 (with the pose fitted to the anchors alone). The window starts filled
   with the set-up span's positions, posed by `anchored_poses`;
5. Woodward's causal 3-frame mean (`temporal_window`) is off by default, as offline
   (`track_stereo_frames`): a causal mean lags the motion by a pair, and the lower lip
   and chin move 5-10 mm a pair when the jaw drops or the performer talks (issue 17's
   take at 30 fps). The depth median above already steadies what the mean would. On
   the bench below (3 seeds, named anchors, median / p95 mm) the mean gave 0.89 / 3.17
   against 0.90 / 2.77 without; on seeds 3-5 0.95 / 3.84 against 0.93 / 3.19; a causal
   one-euro filter in its place 0.85 / 2.91-3.40.

How far this is from offline (`bench/stereo_live.py --stickers`: issue 17's sticker take,
150 pairs, 3 seeds, shape error median / p95 over the pairs after the set-up): named
anchors live 0.90 / 2.77 mm (seed 0 alone 1.17 / 3.64), offline 0.62 / 1.81; anchors
chosen live 1.19 / 3.38, offline 0.83 / 2.84 (targets 1 / 3); held-out seeds 3-5 named
0.93 / 2.90 live (seed 5 0.79 / 2.88), offline 0.63 / 2.14. What is left is mostly
the lower lip and chin while the jaw moves fast, a sticker's first pairs in view (a
temple turning in, half hidden: 5-6 mm off for a few pairs, where offline's centred
windows see its later pairs) and the lip stickers that merge. Before the pose
took every column (above), the gap was the pose: fitted to one pair's anchors it was 1.9
mm off at the median; a causal alpha-beta filter of it lagged the head's turns and did
worse (1.5-2.6 mm).

A live player needs points in its target's layout order: `by_name` picks the columns of
a layout's points by name (NaN for a point no column has yet). Given a `layout` with a 3D
reference (one made from a stereo sticker take, `retarget.custom_layouts.take_reference`),
the columns are named by where they sit, not by the order met: once the head frame is set
up, the columns placed in `_PLACED` posed pairs are matched to the reference together
(`retarget.sources.place_names.matched_places`: similarity and assignment), and a column
placed later against the fit to those named; ``names_`` then gives each column its
layout point's name, "" for one that matches none (an extra sticker, or one not placed
yet; it is matched again as its place firms up). When such a layout marks head anchors and none are named, they are the anchors:
at the span's end its columns are named at their median places in a head frame fitted
to them all, and a layout anchor named later joins them. A column not yet placed also
takes registrations from pairs posed short of anchors, so that a temple hidden through
the set-up gets named (and joins) while the other temple is hidden. On issue 17's take
(`bench/stereo_live.py --stickers`: 3 seeds, a layout from the offline take of 150 pairs,
live sessions from pairs 0, 49 and 100) every point of the layout ends driven by its
sticker, none wrong; by the order met, 72, 54 and 28 %. Without such a layout the columns are m01..mM in the order met, and a layout's
points of those names take them. 3D points are in the calibration's units (mm), in the
left camera's frame at the head pose of the span's first anchored pair.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Sequence

import numpy as np

from retarget.custom_layouts import stereo_reference
from retarget.errors import RetargetError
from retarget.layouts import Layout
from retarget.sources.calibration import StereoCalibration
from retarget.sources.filters import temporal_mean
from retarget.sources.headpose import anchored_poses, rigid_anchors, rigid_transform
from retarget.sources.place_names import matched_places
from retarget.sources.stereo_live import checked_pair
from retarget.sources.stereo_depth import weighted_median_along
from retarget.sources.stereo_tracks import StickerTracks
from retarget.sources.take import marker_names

__all__ = ["LiveStickerTracker", "by_name", "MAX_STICKERS", "named_by_place", "sticker_index", "sticker_points"]

MAX_STICKERS = 99
"""Most columns a live sticker tracker gives (m01..m99): the names keep two digits, so
a column's name never changes while the session runs; later stickers are not followed."""

_SIGHT_RATIO = 6.0   # depth noise over cross-ray noise of the set-up span's anchors, as offline
_PRIOR_SPREAD, _PRIOR_HITS = 5.0, 10   # mm, pairs: a column's spread before it has registrations
_KEEP = 30   # registrations kept per column for its place (1 s at 30 fps; 90: 1.25 / 3.19 mm against 1.17 / 3.33)
_ROBUST = 1.0   # mm: the pose's Cauchy scale; a sticker this far off its place counts half
_ROBUST_STEPS = 2   # reweighted fits after the first
_PLACED = 3   # registrations before a column is named by place (a median of 3 outvotes a bad one; one pair names well)
_NAME = re.compile(r"m(\d{2,3})")


def sticker_index(anchor: int | str) -> int:
    """The column of an anchor given as a name m01..m99 or a 0-based index."""
    if isinstance(anchor, str):
        match = _NAME.fullmatch(anchor)
        if match is None or not 1 <= int(match.group(1)) <= MAX_STICKERS:
            raise RetargetError(f"a sticker anchor is named m01..m{MAX_STICKERS} (or is a column "
                                f"index); got {anchor!r:.40}")
        return int(match.group(1)) - 1
    if isinstance(anchor, bool) or not isinstance(anchor, (int, np.integer)) or not 0 <= anchor < MAX_STICKERS:
        raise RetargetError(f"a sticker anchor index is 0..{MAX_STICKERS - 1}; got {anchor!r:.40}")
    return int(anchor)


def named_by_place(layout: Layout) -> bool:
    """Whether live sticker columns go to `layout`'s points by where they sit (module doc):
    its reference has depth, as one made from a stereo sticker take has
    (`retarget.custom_layouts.take_reference`; a 2D take's lies flat, z 0), else by name."""
    return layout.reference is not None and bool(np.ptp(layout.reference_points()[:, 2]) > 0)


def sticker_points(layout: Layout) -> tuple[str, ...]:
    """The points of `layout` that live sticker columns can drive: every one when it is
    named by place (`named_by_place`), else those named as the columns are (m01..m99)."""
    if named_by_place(layout):
        return layout.point_names
    columns = set(marker_names(MAX_STICKERS))
    return tuple(name for name in layout.point_names if name in columns)


def by_name(points: np.ndarray, names: Sequence[str], wanted: Sequence[str]) -> np.ndarray:
    """(len(wanted), D) rows of `points` (M, D) picked by name, NaN for a wanted name that
    `names` (M,) lacks (a sticker not yet tracked, or a layout point no sticker carries)."""
    column = {name: k for k, name in enumerate(names)}
    out = np.full((len(wanted), points.shape[1]), np.nan, np.float32)
    rows = [(i, column[w]) for i, w in enumerate(wanted) if w in column]
    if rows:
        i, k = np.array(rows).T
        out[i] = points[k]
    return out


class LiveStickerTracker:
    """Unnamed stickers of one colour followed live by a calibrated camera pair (module doc).

    calibration : the pair's `StereoCalibration`; frames must be its size.
    color : the stickers' colour as `sticker_color` takes it (a name, (B, G, R), "hsv:H,S,V").
    anchors : >= 3 columns (m01..m99 or 0-based indices) that move with the head only
        (temples, forehead, nose bridge); None: the 4 most rigid of the set-up span.
    setup_seconds : capture time of the set-up span (module doc, step 2); default 1 s
        with named anchors, 3 s to choose them.
    depth_window : pairs of the causal depth median (1: none); across : its weight's
        width across the line of sight (calibration units).
    temporal_window : pairs of the causal mean (Woodward §5 use 3; 1 = none, the default:
        module doc, step 5).
    max_epipolar : px, as `StickerTracks`.
    setup_frames : pairs the set-up may take (performer not in view, too few stickers,
        named anchors not seen) before `push` raises.
    history : pairs of `StickerTracks`' history kept (a lost sticker is predicted from
        where it was last seen: one hidden longer than this comes back as a new column);
        the session's memory and time per pair stay bounded however long it runs.
    layout : the target layout; when its reference has depth (made from a stereo sticker
        take), the columns are named by place as its points (module doc), else m01..mM.
        Its anchors, if it marks any and `anchors` is None, are the head anchors (found
        by place at the set-up's end, 1 s by default).

    ``push(left, right, time)`` takes (H, W, 3) uint8 BGR images and the capture time (s,
    increasing) and returns (M, 3) float32 head-frame points, NaN where lost and through
    the set-up span. After a call: ``names_`` (M,) the columns' names, ``camera_`` (M, 3)
    float64 this pair's triangulated points in the left camera's frame (head motion
    kept), ``anchors_`` (K,) the anchor columns (None during the set-up),
    ``identified_`` (stickers are tracked), ``anchored_`` (the head frame is set up),
    ``frames_`` (pairs pushed), ``setup_error_`` (why the set-up waits).
    """

    def __init__(self, calibration: StereoCalibration, color="blue", *,
                 anchors: Sequence[int | str] | None = None, setup_seconds: float | None = None,
                 depth_window: int = 45, across: float = 2.0,
                 temporal_window: int = 1, max_epipolar: float = 3.0, setup_frames: int = 300,
                 history: int = 900, layout: Layout | None = None):
        self.calibration = calibration
        self.tracks = StickerTracks(calibration, color, max_epipolar=max_epipolar)
        if anchors is not None:
            items = [anchors] if isinstance(anchors, (str, int)) else list(anchors)
            idx = [sticker_index(a) for a in items]
            if len(set(idx)) < 3:
                raise RetargetError(f"anchors must name at least 3 different stickers; got {anchors!r:.80}")
            anchors = np.array(sorted(set(idx)), np.int64)
        self.named_anchors = anchors
        self._layout = layout if layout is not None and named_by_place(layout) else None
        # The layout's own anchors, found by place at the set-up's end, unless named here.
        self._by_layout = anchors is None and self._layout is not None and bool(self._layout.anchors)
        if setup_seconds is None:
            setup_seconds = 1.0 if anchors is not None or self._by_layout else 3.0
        if not setup_seconds >= 0 or depth_window < 1 or temporal_window < 1 or history < 30:
            raise RetargetError("setup_seconds must be >= 0, depth_window and temporal_window >= 1, "
                                "history >= 30")
        self.setup_seconds, self.depth_window, self.across = float(setup_seconds), int(depth_window), float(across)
        self.temporal_window = int(temporal_window)
        self.setup_frames, self.history = int(setup_frames), int(history)
        self._rows = np.zeros(0, np.int64)      # the tracks' row of each column
        self._named = np.zeros(0, np.int64)     # each column's layout point, -1 for none
        self._tried = np.zeros(0)               # each column's registrations when last matched
        self._time = -np.inf
        self._setup: list[np.ndarray] = []       # camera-frame points of the set-up span
        self._setup_start: float | None = None
        self._pose_: tuple[np.ndarray, np.ndarray] | None = None
        self._steady: list[np.ndarray] = []      # head-frame positions, last depth_window pairs
        self._out: list[np.ndarray] = []         # steadied points, last temporal_window pairs
        self.anchors_: np.ndarray | None = None
        self._places = None   # cache of `_place_all`
        self.camera_ = np.zeros((0, 3))
        self.frames_ = 0
        self.identified_ = self.anchored_ = False
        self.setup_error_ = "waiting for 3 stickers seen by both cameras"

    @property
    def names_(self) -> tuple[str, ...]:
        if self._layout is None:
            return marker_names(len(self._rows))
        named = np.pad(self._named, (0, len(self._rows) - len(self._named)), constant_values=-1)
        return tuple(self._layout.point_names[k] if k >= 0 else "" for k in named)

    def push(self, left: np.ndarray, right: np.ndarray, time: float) -> np.ndarray:
        """(M, 3) float32 head-frame points of this pair (steadied: module doc, steps 3-5)."""
        self._time = checked_pair(self.calibration, left, right, time, self._time)
        self.frames_ += 1
        self.tracks(left, right)
        self._forget()
        xyz = self._columns()
        self.camera_ = xyz
        if not self.anchored_ and not self._set_up(xyz):
            if self.frames_ >= self.setup_frames:
                raise RetargetError(f"live stickers: no head frame after {self.frames_} frame pairs: "
                                    f"{self.setup_error_}")
            return np.full(xyz.shape, np.nan, np.float32)
        points = self._mean(self._stabilised(xyz))
        if self._layout is not None:
            self._name_placed()
        return points

    # -- columns -------------------------------------------------------------------------

    def _columns(self) -> np.ndarray:
        """(M, 3) float64 this pair's confirmed stickers in column order (camera frame).

        `StickerTracks` keeps its tracks in the order they were born and confirms them in
        that order (a new track after `confirm` pairs in a row, or dropped), so confirmed
        tracks are the first rows and keep their rows; the ones confirmed this pair are
        ordered top to bottom, then left to right (module doc, step 1)."""
        confirmed, xyz, px = self.tracks.latest()
        confirmed = np.flatnonzero(confirmed)
        new = confirmed[len(self._rows):][: MAX_STICKERS - len(self._rows)]
        if new.size:
            self._rows = np.concatenate([self._rows, new[np.lexsort((px[new, 0], px[new, 1]))]])
            self.identified_ = True
        return xyz[self._rows].astype(np.float64)

    def _forget(self) -> None:
        """Keep `history` pairs of the tracks' history (it serves the prediction of a lost
        sticker from where it was last seen; the live columns never read it)."""
        if self.tracks.n_frames - self.history >= self.history // 4:   # in steps: trimming a list copies it
            self.tracks.forget(self.history)

    # -- head frame ----------------------------------------------------------------------

    def _set_up(self, xyz: np.ndarray) -> bool:
        """Collect the set-up span; at its end choose the anchors and place them."""
        if self._setup_start is None:
            if np.isfinite(xyz[:, 0]).sum() < 3:
                return False
            self._setup_start = self._time
        self._setup.append(xyz)
        if self._time - self._setup_start < self.setup_seconds:
            self.setup_error_ = ("set-up span: keep the stickers in view"
                                 if self.named_anchors is not None or self._by_layout else
                                 "set-up span: talk, smile and raise the brows, so the stickers that "
                                 "do not move show")
            return False
        m = len(xyz)
        span = np.stack([np.pad(p, ((0, m - len(p)), (0, 0)), constant_values=np.nan) for p in self._setup])
        try:
            if self._by_layout:
                anchors = self._anchors_by_place(span)
            else:
                anchors = rigid_anchors(span, min(4, m)) if self.named_anchors is None else self.named_anchors
            tracked = anchors[anchors < m]
            if tracked.size < 3:
                raise RetargetError(f"{tracked.size} of the anchors {', '.join(f'm{a + 1:02d}' for a in anchors)} "
                                    f"are tracked ({m} stickers so far); 3 are needed")
            rot, trans, ref = anchored_poses(span, tracked, sight_ratio=_SIGHT_RATIO)
        except RetargetError as exc:
            self.setup_error_ = str(exc)
            self._setup, self._setup_start = [], None   # a new span
            return False
        # A named anchor not tracked yet has no place: it joins when first seen (`_learn`).
        if np.isfinite(ref[tracked]).all(axis=1).sum() < 3:
            self.setup_error_ = "fewer than 3 anchors were seen with a head pose in the set-up span"
            self._setup, self._setup_start = [], None
            return False
        self.anchors_ = anchors
        # Every column's head-frame place and spread, for pairs short of anchors.
        registered = np.einsum("fnj,fij->fni", span, rot) + trans[:, None]
        seen = np.isfinite(registered).all(axis=2)
        self._reg = np.full((_KEEP, m, 3), np.nan)
        self._hits = np.zeros(m)
        for head in registered[seen.any(axis=1)]:
            self._register(head)
        if self.depth_window > 1:
            self._steady = list(registered[-(self.depth_window - 1):])
        self._setup = []
        self.anchored_ = True
        self.setup_error_ = ""
        return True

    def _anchors_by_place(self, span: np.ndarray) -> np.ndarray:
        """(K,) the columns that are the layout's anchors: the span's columns (F, M, 3
        camera frame) named by place, each at its median place over the span in a head
        frame fitted to every column (no pair need see them all, and the expressions'
        moves are millimetres). This is the session's first naming (`_name_placed` goes
        on from it); `RetargetError` when fewer than 3 anchors are found."""
        _, _, places = anchored_poses(span, np.arange(span.shape[1]))
        seen = np.isfinite(places).all(axis=1)
        named = np.full(len(places), -1, np.int64)
        shape = stereo_reference(places[seen]) if seen.sum() >= 3 else None
        if shape is not None:
            named[seen] = matched_places(shape, self._layout.reference_points())
        anchors = np.flatnonzero(np.isin(named, self._layout.anchors))
        if anchors.size < 3:
            wanted = ", ".join(self._layout.point_names[k] for k in self._layout.anchors)
            raise RetargetError(f"{anchors.size} of the layout's head anchors ({wanted}) were found by "
                                "place in the set-up span; 3 are needed: keep them in view")
        self._named, self._tried = named, np.full(len(named), -1.0)
        return anchors

    def _register(self, head: np.ndarray, keep: int = _KEEP) -> None:
        """Keep this pair's head-frame positions (M, 3) of the columns it sees, up to each
        column's first `keep` (`_KEEP`: then its place is frozen, the head frame cannot
        drift)."""
        grow = len(head) - self._reg.shape[1]
        if grow > 0:
            self._reg = np.concatenate([self._reg, np.full((_KEEP, grow, 3), np.nan)], axis=1)
            self._hits = np.concatenate([self._hits, np.zeros(grow)])
        seen = np.flatnonzero(np.isfinite(head).all(axis=1) & (self._hits < keep))
        if seen.size == 0:
            return
        self._reg[self._hits[seen].astype(np.int64), seen] = head[seen]
        self._hits[seen] += 1
        self._places = None

    def _place_all(self) -> tuple[np.ndarray, np.ndarray]:
        """(M, 3) every column's head-frame place: the median of its kept registrations
        (robust to a temple's first, half-hidden sightings; NaN for one never registered),
        and (M,) the squared spread round it (median squared distance)."""
        if self._places is None:
            with warnings.catch_warnings():   # a column never registered: NaN
                warnings.simplefilter("ignore", RuntimeWarning)
                place = np.nanmedian(self._reg, axis=0)
                spread2 = np.nanmedian(((self._reg - place) ** 2).sum(axis=2), axis=0)
            self._places = place, spread2
        return self._places

    def _fit(self, xyz: np.ndarray):
        """(R, t, full) of this pair (``head = p @ R.T + t``); None when nothing fixes it.

        Every column seen that has a place is fitted to it, weighted by its steadiness (1 /
        its spread squared, a sticker seen in few posed pairs counting as `_PRIOR_SPREAD`
        mm loose: the anchors and the nose weigh most, the lips least), then again
        `_ROBUST_STEPS` times with each weight times the Cauchy weight of its residual
        (1 / (1 + (r / `_ROBUST`)^2)): an expression moves the lips and brows off their
        places, and the fit follows the stickers that stayed. `full` when 3 placed anchors
        are among them: then the pair's positions are learned (`_learn`). Fitted to the
        anchors alone, a pair's pose took their triangulation noise (at 1 m with an 80 mm
        baseline, millimetres along each line of sight) with it (module doc)."""
        m = len(xyz)
        places, spread2 = self._place_all()
        n = len(places)
        k = self.anchors_[self.anchors_ < min(m, n)]
        full = (np.isfinite(xyz[k]).all(axis=1) & np.isfinite(places[k]).all(axis=1)).sum() >= 3
        hits = np.minimum(self._hits, _KEEP)
        spread2 = (np.nan_to_num(spread2) * hits + _PRIOR_HITS * _PRIOR_SPREAD**2) / (hits + _PRIOR_HITS)
        use = np.isfinite(xyz[:n]).all(axis=1) & np.isfinite(places).all(axis=1)
        if use.sum() < 3:
            return None
        src, dst, weight = xyz[:n][use], places[use], 1.0 / spread2[use]
        try:
            rot, trans = rigid_transform(src, dst, weight)
            for _ in range(_ROBUST_STEPS):
                r = np.linalg.norm(src @ rot.T + trans - dst, axis=1)
                rot, trans = rigid_transform(src, dst, weight / (1.0 + (r / _ROBUST) ** 2))
        except RetargetError:   # collinear
            return None
        return rot, trans, full

    def _learn(self, xyz: np.ndarray, rot: np.ndarray, trans: np.ndarray) -> None:
        """After a pair whose pose 3 anchors fixed, every column's place and spread take
        it in: an anchor seen for the first time joins at its place in the head frame (no
        jump: the pose did not use it), and the anchors' places, the mean of their
        registrations, grow steadier."""
        self._register(xyz @ rot.T + trans)

    def _name_placed(self) -> None:
        """Name by place the columns placed (`_PLACED` registrations) and not named yet,
        each time one of them has more registrations than when last matched: the first 3
        or more together, later ones against the fit to those named (a name, once given,
        stays); those named as the layout's anchors join the anchors. A column left
        unnamed is matched again as its place firms up: a sticker's first registrations
        (a temple half hidden, posed short of anchors) can put it past the gate, and one
        matched once for good stayed unnamed, its point never driven."""
        m = len(self._hits)
        named = np.pad(self._named, (0, m - len(self._named)), constant_values=-1)
        tried = np.pad(self._tried, (0, m - len(self._tried)), constant_values=-1.0)
        unnamed = (self._hits >= _PLACED) & (named < 0)
        use = (named >= 0) | unnamed
        if not (unnamed & (self._hits > tried)).any() or use.sum() < 3:
            return
        places = stereo_reference(self._place_all()[0][use])
        if places is None:   # the placed columns coincide: no shape to match yet
            return
        named[use] = matched_places(places, self._layout.reference_points(), known=named[use])
        self._named, self._tried = named, np.where(use, self._hits, tried)
        if self._by_layout:   # a layout anchor named late joins the anchors, as a named one met late
            self.anchors_ = np.union1d(self.anchors_, np.flatnonzero(np.isin(named, self._layout.anchors)))

    def _stabilised(self, xyz: np.ndarray) -> np.ndarray:
        """(M, 3) head-frame points with their depth steadied (module doc, steps 3-4)."""
        fit = self._fit(xyz)
        held = fit is None
        if held:
            if self._pose_ is None:
                return np.full(xyz.shape, np.nan)
            fit = (*self._pose_, False)   # the last pose, held
        rot, trans, full = fit
        head = xyz @ rot.T + trans
        ray = xyz / np.linalg.norm(xyz, axis=1, keepdims=True) @ rot.T
        past = self._past(len(xyz))
        steady = _sight_median(past, head, ray, self.across) if len(past) else head
        self._pose_ = (rot, trans)
        if full:
            self._learn(xyz, rot, trans)
        elif self._layout is not None and not held:
            # Naming by place needs a column placed: one hidden through the set-up (the
            # second temple) would else wait for 3 placed anchors, and it may be the third.
            # Fitted to every column, the pose is a few mm sure: enough to name it by.
            self._register(head, keep=_PLACED)
        self._steady = [*self._steady[-(self.depth_window - 1):], head] if self.depth_window > 1 else []
        return steady

    def _past(self, m: int) -> np.ndarray:
        """(W, M, 3) the last head-frame positions, NaN for columns born since."""
        if not self._steady:
            return np.zeros((0, m, 3))
        return np.stack([np.pad(p, ((0, m - len(p)), (0, 0)), constant_values=np.nan) for p in self._steady])

    def _mean(self, points: np.ndarray) -> np.ndarray:
        """Woodward's causal mean over the last `temporal_window` pairs (columns born since
        a pair count as lost in it)."""
        m = len(points)
        self._out = [*self._out[-(self.temporal_window - 1):], points] if self.temporal_window > 1 else [points]
        stack = np.stack([np.pad(p, ((0, m - len(p)), (0, 0)), constant_values=np.nan) for p in self._out])
        return temporal_mean(stack, self.temporal_window)[-1]


def _sight_median(past: np.ndarray, head: np.ndarray, ray: np.ndarray, across: float) -> np.ndarray:
    """(M, 3) `head` (M, 3) moved along `ray` (M, 3, unit) to the weighted median of the
    window `past` (W, M, 3) and itself along the ray, each weighted by exp(-d^2 / 2
    across^2), d its distance across the ray from `head` (the causal `sight_smoothed`)."""
    window = np.concatenate([past, head[None]])                       # (W + 1, M, 3)
    shift = weighted_median_along((window - head).transpose(1, 2, 0)[None], ray[None], across)[0]
    # A point not seen this pair stays lost (NaN): the window only steadies a seen one.
    return head + np.nan_to_num(shift)[:, None] * ray
