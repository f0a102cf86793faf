"""Single-camera tracking of ring markers (Dutreve et al. 2008, §5 "Results and Conclusion").

The paper's tracker: white markers with a black circle drawn round each ("to make the
tracking more robust by increasing the contrast of markers"), a 640x480 webcam, and the
pyramidal Lucas-Kanade feature tracker [Bouguet 2002] following their 2D positions. Here:

1. `detect_ring_markers` finds the markers in a frame: an adaptive threshold marks dark
   pixels, and a dark component with one round bright hole of plausible size is a marker;
   its centre is the intensity-weighted centroid of the white dot (sub-pixel).
2. `assign_markers` names them: the detected centres are matched to a layout's reference
   positions (the built-in face seen from the front) by alternating a Hungarian assignment
   and a similarity, then affine, fit.
3. `MarkerTracker` follows them with pyramidal Lucas-Kanade (``cv2.calcOpticalFlowPyrLK``)
   and re-centres every tracked point on its dot each frame, so the error does not
   accumulate; a marker whose dot and ring lose their contrast (occluded) or that leaves
   the frame is lost (NaN) until a detection near its predicted place brings it back.
4. `track_marker_video` runs the three over a video and returns a 2D `Take` in pixels with
   y up (x right, ``y_up = height - y``).

That suits markers ten pixels and more across. On the paper's own set-up as others film
it (a 640x480 webcam at 60 cm: 3 mm markers about 5 px across, blurred, noisy, compressed,
unevenly lit, some oblique or hidden; issue 17) the dot is a pixel or two and the ring
rarely closes, so:

5. `ring_score` is a matched filter, the normalised correlation with `ring_template`s of
   2-4.4 px ring radius; its peaks (`score_peaks`, sub-pixel) lie on the dots within about
   0.15 px, and `ring_contrast` (dot over the brightest of its ring) tells a marker from
   an eye corner when a track starts.
6. `RingTracks` follows every marker in view through a whole clip without a layout:
   each track moves with its neighbours' motion (plus its own expression's), snaps to the
   nearest peak, established tracks first; strong peaks no track claims start new tracks
   at any frame, followed back to where the marker appeared. `track_marker_video` uses it
   without a layout (columns m01..mM) or when the first frame shows fewer rings than the
   layout has (named by `assign_markers` on the frame that sees most).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.sources.take import Take
from retarget.sources.video import VideoReader

__all__ = [
    "RingBlobs",
    "ring_blobs",
    "detect_ring_markers",
    "reference_points",
    "assign_markers",
    "MarkerTracker",
    "track_marker_video",
    "ring_template",
    "ring_score",
    "score_peaks",
    "ring_contrast",
    "RingTracks",
]

_THRESHOLD_BLOCK = 31      # px, adaptive-threshold neighbourhood (a few marker diameters)
_THRESHOLD_OFFSET = 25.0   # grey levels below the local mean that count as dark
_LOST_SHARE = 0.35         # a marker whose contrast drops below this share of its first is lost
_MIN_CONTRAST = 12.0       # grey levels: dot over ring and skin over ring, whatever the share
_RING_RATIO = 2.0          # ring / dot radius assumed where a ring merges with a dark region


@dataclass(frozen=True, eq=False)
class RingBlobs:
    """Ring markers found in one image.

    centres : (M, 2) float64 sub-pixel dot centres (pixels, x right, y down).
    shape : (M, 2, 2) float64 covariance of each white dot (pixels^2); a round dot of
        radius r has r^2 / 4 times the identity, an oblique one an ellipse's.
    ratio : (M,) float64 outer ring radius over dot radius.
    """

    centres: np.ndarray
    shape: np.ndarray
    ratio: np.ndarray

    @property
    def dot_radius(self) -> np.ndarray:
        """(M,) float64 equivalent radius of each dot (of the disc of equal area), pixels."""
        return _equivalent_radius(self.shape)

    @property
    def ring_radius(self) -> np.ndarray:
        """(M,) float64 equivalent outer radius of each ring, pixels."""
        return self.ratio * self.dot_radius


def ring_blobs(
    gray: np.ndarray,
    *,
    min_dot_radius: float = 1.0,
    max_ring_radius: float = 25.0,
) -> RingBlobs:
    """Ring markers (white dot in a black ring) in a grey image (h, w) uint8.

    A candidate is a hole of a dark component (pixels 25 grey levels under their 31 px
    local mean) that is roundish (area / enclosing-circle area > 0.3, a disc seen up to
    about 70 degrees off-axis), with equivalent radii within the bounds (where the ring
    merges with a shadow, its radius is taken as twice the dot's). The centre is then
    refined on the grey values, and a candidate whose dot and surrounding skin are not
    both brighter than its ring by 12 grey levels is dropped (see `_centred`).
    """
    import cv2

    g = _gray(gray)
    dark = cv2.adaptiveThreshold(g, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY_INV,
                                 _THRESHOLD_BLOCK, _THRESHOLD_OFFSET)
    contours, hierarchy = cv2.findContours(dark, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    empty = RingBlobs(np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0))
    if hierarchy is None:
        return empty
    hierarchy = hierarchy[0]
    holes = np.flatnonzero(hierarchy[:, 3] >= 0)
    centres, shapes, ratios = [], [], []
    for k in holes:
        hole = contours[k]
        parent = contours[hierarchy[k, 3]]
        # contours run through the centres of the dark pixels: a hole's inside them, a
        # component's outline half a pixel in from its edge
        a_hole, a_ring = cv2.contourArea(hole), cv2.contourArea(parent)
        r_dot = np.sqrt(a_hole / np.pi) - 0.5
        r_ring = np.sqrt(a_ring / np.pi) + 0.5
        if r_ring > 3.0 * r_dot:       # the ring runs into a shadow: assume a usual ring
            r_ring = _RING_RATIO * r_dot
        if not (min_dot_radius <= r_dot and r_ring <= max_ring_radius and 1.3 * r_dot < r_ring):
            continue
        (_, _), r_enclosing = cv2.minEnclosingCircle(hole)
        if a_hole < 0.3 * np.pi * r_enclosing**2:      # round, or an oblique view of round
            continue
        m = cv2.moments(hole)
        if m["m00"] <= 0:
            continue
        cov = np.array([[m["mu20"], m["mu11"]], [m["mu11"], m["mu02"]]]) / m["m00"]
        centres.append((m["m10"] / m["m00"], m["m01"] / m["m00"]))
        shapes.append(cov * (r_dot / (r_dot + 0.5)) ** 2)
        ratios.append(r_ring / r_dot)
    if not centres:
        return empty
    refined, shape, dot_c, ring_c = _centred(g, np.array(centres), np.array(shapes), np.array(ratios))
    keep = (dot_c > _MIN_CONTRAST) & (ring_c > _MIN_CONTRAST)
    return RingBlobs(refined[keep], shape[keep], np.array(ratios)[keep])


def detect_ring_markers(gray: np.ndarray) -> np.ndarray:
    """(M, 2) float32 sub-pixel centres of the ring markers in a grey image (h, w) uint8
    (pixels, x right, y down); see `ring_blobs`."""
    return ring_blobs(gray).centres.astype(np.float32)


def reference_points(layout: str) -> np.ndarray:
    """(N, 2) float64 the layout's points on the built-in face seen from the front, in
    image orientation: x toward the subject's left (the viewer's right), y down; cm
    (`Layout.reference_points` projected)."""
    return get_layout(layout).reference_points()[:, :2] * [1.0, -1.0]


def assign_markers(detected: np.ndarray, reference: np.ndarray, *, gate: float = 0.75) -> np.ndarray:
    """(N,) int64: for each reference point, the index of its detected marker, -1 for none.

    detected : (M, 2) float marker centres in an image (pixels, y down).
    reference : (N, 2) float where the points lie on a face in the same orientation (any
        units, e.g. `reference_points`); the face in the image may be shifted, scaled,
        rotated up to about 40 degrees and stretched.
    gate : a point stays unassigned when its nearest marker, after the fit, is further than
        `gate` times the reference's median nearest-neighbour spacing.

    Alternates an optimal one-to-one assignment (Hungarian, with the option "none" at the
    gate's cost) and a least-squares fit of the reference onto its markers (similarity
    first, affine after five rounds), from several starting rotations and scales about the
    medians' alignment; the run with the lowest total cost wins.
    """
    from scipy.optimize import linear_sum_assignment
    from scipy.spatial.distance import cdist

    det = _points(detected, "detected")
    ref = _points(reference, "reference")
    if len(ref) < 3:
        raise RetargetError(f"assign_markers needs at least 3 reference points, got {len(ref)}")
    out = np.full(len(ref), -1, dtype=np.int64)
    if len(det) == 0:
        return out
    spacing = np.median(np.sort(cdist(ref, ref), 1)[:, 1])
    if spacing <= 0:
        raise RetargetError("assign_markers: reference points coincide")
    # medians, so that stray detections do not drag the starting guesses
    mid_det, mid_ref = np.median(det, 0), np.median(ref, 0)
    spread_det = np.median(np.linalg.norm(det - mid_det, axis=1))
    spread_ref = np.median(np.linalg.norm(ref - mid_ref, axis=1))
    scale = spread_det / spread_ref if spread_det > 0 else 1.0
    best_cost, best = np.inf, out
    starts = [(a, f) for a in (0.0, -20.0, 20.0, -40.0, 40.0) for f in (1.0, 0.8, 1.25)]
    for angle, factor in starts:
        c, s = np.cos(np.radians(angle)), np.sin(np.radians(angle))
        A = factor * scale * np.array([[c, -s], [s, c]])
        b = mid_det - mid_ref @ A.T
        match = out
        for it in range(30):
            moved = ref @ A.T + b
            limit = gate * spacing * np.sqrt(abs(np.linalg.det(A)))
            cost = np.concatenate([cdist(moved, det), np.full((len(ref), len(ref)), limit)], 1)
            rows, cols = linear_sum_assignment(cost)
            new = np.full(len(ref), -1, dtype=np.int64)
            hit = cols < len(det)
            new[rows[hit]] = cols[hit]
            total = cost[rows, cols].sum()
            if (new >= 0).sum() < 3:
                break
            settled = np.array_equal(new, match)
            match = new
            pairs = match >= 0
            A, b = _fit(ref[pairs], det[match[pairs]], affine=it >= 5)
            if settled and it >= 6:
                break
        if (match >= 0).sum() >= 3 and total < best_cost:
            best_cost, best = total, match
        if (match >= 0).all() and total < 0.2 * limit * len(ref):
            break                       # every point matched closely: no need to look on
    return best


class MarkerTracker:
    """Pyramidal Lucas-Kanade tracking of ring markers with per-frame re-centring
    (Dutreve et al. 2008, §5; Bouguet's pyramidal LK).

    win_size : LK window side in pixels; max_level : pyramid levels above the image.
    lost_share : a marker is lost when its dot-over-ring or skin-over-ring contrast drops
        under this share of what it was at `start` (or under 12 grey levels).

    `start` takes the first frame and the markers' positions, `update` each following
    frame; both return (N, 2) float32 pixel positions (x right, y down), NaN for lost
    markers. Learned state: ``points_`` (N, 2), ``lost_`` (N,) bool.
    """

    def __init__(self, win_size: int = 21, max_level: int = 3, lost_share: float = _LOST_SHARE) -> None:
        self.win_size = int(win_size)
        self.max_level = int(max_level)
        self.lost_share = float(lost_share)

    def start(self, gray: np.ndarray, points: np.ndarray, blobs: RingBlobs | None = None) -> np.ndarray:
        """Begin on a first frame (h, w) uint8 with the markers near points (N, 2) pixels.

        Each point snaps to the nearest detected ring marker (`blobs`, detected here when
        not given) within twice that marker's ring radius; RetargetError naming the point
        index when none is that near.
        """
        g = _gray(gray)
        pts = _points(points, "points")
        blobs = ring_blobs(g) if blobs is None else blobs
        if len(blobs.centres) == 0:
            raise RetargetError("no ring markers found in the first frame")
        d = np.linalg.norm(pts[:, None] - blobs.centres[None], axis=2)
        near = d.argmin(1)
        far = d[np.arange(len(pts)), near] > 2.0 * blobs.ring_radius[near]
        if far.any():
            raise RetargetError(
                f"no ring marker within two ring radii of point(s) {np.flatnonzero(far).tolist()} "
                f"at {pts[far].round(1).tolist()} in the first frame")
        twins = [i for i in range(len(pts)) if (near[:i] == near[i]).any()]
        if twins:
            raise RetargetError(
                f"point(s) {twins} at {pts[twins].round(1).tolist()} snap to a marker another "
                f"point already took in the first frame")
        self.ratio_ = blobs.ratio[near].copy()
        self.size_ = g.shape[::-1]
        centres, self.shape_, dot_c, ring_c = _centred(g, blobs.centres[near], blobs.shape[near], self.ratio_)
        self.dot_contrast_, self.ring_contrast_ = dot_c, ring_c
        self.points_ = centres
        self.reference_ = centres.copy()
        self.velocity_ = np.zeros_like(centres)
        self.lost_ = ~np.isfinite(centres).all(1)
        self._previous = g
        return self._output()

    def update(self, gray: np.ndarray) -> np.ndarray:
        """(N, 2) float32 marker positions in the next frame (h, w) uint8, NaN where lost."""
        import cv2

        if not hasattr(self, "points_"):
            raise RetargetError("MarkerTracker.update before start")
        g = _gray(gray)
        if g.shape[::-1] != self.size_:
            raise RetargetError(f"frame is {g.shape[1]}x{g.shape[0]}, the tracker started on "
                                f"{self.size_[0]}x{self.size_[1]}")
        live = np.flatnonzero(~self.lost_)
        new = np.full_like(self.points_, np.nan)
        if live.size:
            prev = self.points_[live].astype(np.float32).reshape(-1, 1, 2)
            guess = (self.points_[live] + self.velocity_[live]).astype(np.float32).reshape(-1, 1, 2)
            flow, status, _ = cv2.calcOpticalFlowPyrLK(
                self._previous, g, prev, guess, winSize=(self.win_size, self.win_size),
                maxLevel=self.max_level, flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
                criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 0.03))
            ok = status.ravel() == 1
            moved = flow.reshape(-1, 2).astype(np.float64)
            centres, shape, dot_c, ring_c = _centred(g, moved, self.shape_[live], self.ratio_[live], passes=2)
            keep = ok & self._contrasty(live, dot_c, ring_c) & self._inside(centres, shape, self.ratio_[live])
            new[live[keep]] = centres[keep]
            self.shape_[live[keep]] = shape[keep]
        new = self._apart(new)
        found = np.isfinite(new).all(1)
        if (~found).any():
            new = self._reacquired(g, new)
        found = np.isfinite(new).all(1)
        was = ~self.lost_
        self.velocity_ = np.where((found & was)[:, None], new - self.points_, 0.0)
        self.points_ = np.where(found[:, None], new, self.points_)
        self.lost_ = ~found
        self._previous = g
        return self._output()

    def _output(self) -> np.ndarray:
        out = self.points_.astype(np.float32)
        out[self.lost_] = np.nan
        return out

    def _contrasty(self, idx, dot_c, ring_c) -> np.ndarray:
        return ((dot_c > np.maximum(self.lost_share * self.dot_contrast_[idx], _MIN_CONTRAST))
                & (ring_c > np.maximum(self.lost_share * self.ring_contrast_[idx], _MIN_CONTRAST)))

    def _inside(self, centres, shape, ratio) -> np.ndarray:
        """(K,) bool: the whole ring lies in the image."""
        w, h = self.size_
        rx = ratio * 2.0 * np.sqrt(shape[:, 0, 0]) + 1.0       # the ellipse's x and y reach
        ry = ratio * 2.0 * np.sqrt(shape[:, 1, 1]) + 1.0
        x, y = centres[:, 0], centres[:, 1]
        with np.errstate(invalid="ignore"):
            return (x - rx >= -0.5) & (x + rx <= w - 0.5) & (y - ry >= -0.5) & (y + ry <= h - 0.5)

    def _apart(self, new: np.ndarray) -> np.ndarray:
        """new (N, 2) with both points of any pair closer than a ring radius lost: one of
        them followed the other's marker, and which one is not known here."""
        d = np.linalg.norm(new[:, None] - new[None], axis=2)
        np.fill_diagonal(d, np.inf)
        ring = self.ratio_ * _equivalent_radius(self.shape_)
        with np.errstate(invalid="ignore"):
            clash = (d < np.maximum(ring[:, None], ring[None])).any(1)
        new[clash] = np.nan
        return new

    def _reacquired(self, g: np.ndarray, new: np.ndarray) -> np.ndarray:
        """new (N, 2) with lost markers filled from a detection near where the tracked ones
        say they should be: the similarity from their start positions to now carries each
        lost marker's start position; the nearest free blob within a gate takes it."""
        from scipy.optimize import linear_sum_assignment

        found = np.isfinite(new).all(1)
        if found.sum() < 2:
            return new
        blobs = ring_blobs(g)
        if len(blobs.centres) == 0:
            return new
        taken = np.linalg.norm(blobs.centres[:, None] - new[found][None], axis=2).min(1)
        free = np.flatnonzero(taken > 1.5 * blobs.ring_radius)
        lost = np.flatnonzero(~found)
        if free.size == 0:
            return new
        A, b = _fit(self.reference_[found], new[found], affine=False)
        predicted = self.reference_[lost] @ A.T + b
        cand = blobs.centres[free]
        d = np.linalg.norm(predicted[:, None] - cand[None], axis=2)
        spacing = np.median(np.sort(np.linalg.norm(
            self.reference_[:, None] - self.reference_[None], axis=2), 1)[:, 1])
        gate = 4.0 * (self.ratio_ * _equivalent_radius(self.shape_))[lost, None] + 0.5 * spacing
        rows, cols = linear_sum_assignment(np.where(d < gate, d, 1e6))
        for r, c in zip(rows, cols):
            if d[r, c] < gate[r, 0]:
                k = lost[r]
                centre, shape, dot_c, ring_c = _centred(
                    g, cand[c][None], blobs.shape[free[c]][None], self.ratio_[k:k + 1])
                if self._contrasty([k], dot_c, ring_c)[0] and self._inside(centre, shape, self.ratio_[k:k + 1])[0]:
                    new[k] = centre[0]
                    self.shape_[k] = shape[0]
        return new


def track_marker_video(
    path: str | Path,
    *,
    layout: str | None = "dutreve21",
    assignment: np.ndarray | None = None,
    progress: Callable[[int, int], None] | None = None,
    tracker: MarkerTracker | None = None,
    tracks: RingTracks | None = None,
) -> Take:
    """Track a ring-marker video into a 2D `Take` (Dutreve et al. 2008, §5).

    path : the video.
    layout : the layout whose points the markers stand for: its markers are found and
        named in the first frame and followed by `MarkerTracker`; where the first frame
        shows fewer ring markers than the layout has (markers a few pixels across, some
        hidden), `RingTracks` follows every marker through the whole clip and
        `assign_markers` names them on the frame where most are seen.
        None: no layout, every marker in view, `RingTracks`' columns named m01..mM.
        "auto": dutreve21 when the first frame shows exactly its 21 markers in its
        arrangement, None otherwise.
    assignment : None to find and name the markers in the first frame automatically
        (`assign_markers` against `reference_points`), or (N, 2) first-frame pixel
        positions (x right, y down, as in the image) in the layout's point order; each
        snaps to the nearest marker.
    progress : called as progress(frames_done, frames_claimed) after each frame
        (frames_claimed is the header's count, 0 when unknown).
    tracker : a configured `MarkerTracker`; tracks : a configured `RingTracks`
        (default settings otherwise).

    Returns a Take with points (F, N, 2) float32 in pixels, x right and **y up**
    (``y_up = height - y``), NaN where a marker is lost; source "markers"; meta with the
    video size, the header's frame count, whether the video was truncated and which
    tracker ran ("tracker": "MarkerTracker" or "RingTracks").
    """
    import cv2

    path = Path(path)
    if layout == "auto" and assignment is not None:
        raise RetargetError('layout "auto" cannot take an assignment: name the layout')
    lay = None if layout in (None, "auto") else get_layout(layout)
    if lay is None and assignment is not None:
        raise RetargetError("an assignment needs a layout")
    with VideoReader(path) as reader:
        frames = iter(reader)
        _, first = next(frames)
        g = cv2.cvtColor(first, cv2.COLOR_BGR2GRAY)
        blobs = ring_blobs(g)
        if layout == "auto":
            auto = get_layout("dutreve21")
            if len(blobs.centres) == auto.n_points and (
                    assign_markers(blobs.centres, reference_points(auto.name)) >= 0).all():
                lay = auto
        follow = lay is not None and (assignment is not None or len(blobs.centres) >= lay.n_points)
        if follow:
            track = _followed(reader, frames, g, blobs, lay, assignment, path, progress, tracker)
        else:
            grays = [g]
            if progress is not None:
                progress(1, reader.n_frames)
            for i, frame in frames:
                grays.append(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY))
                if progress is not None:
                    progress(i + 1, reader.n_frames)
        width, height = reader.size
        meta = {
            "video": path.name, "size": [width, height], "units": "px", "y_axis": "up",
            "frames_claimed": reader.n_frames, "truncated": reader.truncated,
            "fps_known": reader.fps_known, "tracker": "MarkerTracker" if follow else "RingTracks",
        }
        fps = reader.fps
    if follow:
        points, names = np.stack(track), lay.point_names
    else:
        tracks = RingTracks() if tracks is None else tracks
        points = tracks.fit(grays).points_
        if lay is None:
            names = tuple(f"m{k + 1:0{max(2, len(str(points.shape[1])))}d}" for k in range(points.shape[1]))
        else:
            points = points[:, _named_tracks(points, lay, len(blobs.centres), path)]
            names = lay.point_names
    points = points.copy()
    points[..., 1] = height - points[..., 1]
    meta["lost_share"] = float(np.isnan(points[..., 0]).mean()) if points.size else 1.0
    return Take(points, names, fps, layout=None if lay is None else lay.name, source="markers", meta=meta)


def _followed(reader, frames, g, blobs, lay, assignment, path, progress, tracker) -> list:
    """[(N, 2)] per frame: `MarkerTracker` from the first frame (grey g) on."""
    import cv2

    tracker = MarkerTracker() if tracker is None else tracker
    if assignment is None:
        start = _auto_assignment(blobs, lay, path)
    else:
        start = _points(assignment, "assignment")
        if start.shape != (lay.n_points, 2):
            raise RetargetError(
                f"assignment must be ({lay.n_points}, 2) pixel positions for layout "
                f"{lay.name!r}, got {start.shape}")
    try:
        track = [tracker.start(g, start, blobs)]
    except RetargetError as exc:
        raise RetargetError(f"{path}: {exc}") from None
    if progress is not None:
        progress(1, reader.n_frames)
    for i, frame in frames:
        track.append(tracker.update(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)))
        if progress is not None:
            progress(i + 1, reader.n_frames)
    return track


def _named_tracks(points: np.ndarray, lay, first_found: int, path: Path) -> np.ndarray:
    """(N,) int64 the `RingTracks` column (of points (F, M, 2)) of each of the layout's
    points, named by `assign_markers` on the frame where most markers are seen."""
    seen = np.isfinite(points[..., 0])
    best = int(seen.sum(1).argmax()) if len(points) else 0
    cols = np.flatnonzero(seen[best]) if len(points) else np.zeros(0, np.int64)
    if len(cols) < lay.n_points:
        raise RetargetError(
            f"{path}: found {first_found} ring markers in the first frame, layout {lay.name!r} needs "
            f"{lay.n_points} (white dots with a black ring; at most {len(cols)} seen at once in the clip)")
    match = assign_markers(points[best, cols].astype(np.float64), reference_points(lay.name))
    if (match < 0).any():
        missing = [lay.point_names[i] for i in np.flatnonzero(match < 0)]
        raise RetargetError(
            f"{path}: no marker matches point(s) {', '.join(missing)} of layout {lay.name!r} "
            f"in frame {best}, where most markers are seen (are they placed as the layout's "
            f"reference face shows?)")
    return cols[match]


# ---------------------------------------------------------------------------------------
# Markers a few pixels across, no layout: matched filter, detection near predictions,
# births and a backward pass (issue 17 §1: other people's webcam footage).

_SCORE_RADII = (2.0, 2.6, 3.4, 4.4)   # px, outer ring radii of the matched filter's templates
_BIRTH_SCORE = 0.55    # correlation that starts a track, with a dot brighter than its ring
_MIN_DOT_CONTRAST = 8.0  # grey levels by which a new marker's dot outshines its ring all round
_APART = 4.0           # px: two markers' centres are at least this far apart (a marker
                       # of 3 mm radius at 60 cm is 5.5 px across)
_JOIN = 0.45           # a track that starts this near (times the spacing of the markers
                       # there) where one that ended would be now continues it
_CLEAR_DOT = 40.0      # grey levels of a dot over its ring that start a track whatever the
                       # correlation (skin features never passed 35 on the hard material)
_KEEP_SCORE = 0.25     # correlation of a peak that keeps a track near its prediction
_SNAP = 3.0            # px, how far from its prediction a tracked marker's peak may lie
_REACQUIRE = 4.0       # px, the same for a marker lost for a while
_NEIGHBOURS = 6        # markers whose motion predicts a marker's
_MIN_SPREAD = 12.0     # grey levels: standard deviation in a template's window below which
                       # nothing there is taken for a marker (noise on flat background)


def ring_template(ring_radius: float, *, dot_share: float = 0.5, skin_reach: float = 1.6,
                  blur: float = 0.6) -> np.ndarray:
    """(P, P) float32 picture of a ring marker seen head-on: a white dot of
    `dot_share` x `ring_radius` inside a black ring of `ring_radius` px on skin out to
    `skin_reach` x `ring_radius`, supersampled 8x8 per pixel and blurred by `blur` px
    (the camera's own blur), for `ring_score`."""
    import cv2

    n = int(np.ceil(ring_radius * skin_reach)) + 1
    ss = 8
    ax = (np.arange((2 * n + 1) * ss) + 0.5) / ss - (n + 0.5)
    r = np.hypot(ax[None, :], ax[:, None])
    v = np.where(r < dot_share * ring_radius, 1.0, np.where(r < ring_radius, 0.0, 0.6))
    t = v.reshape(2 * n + 1, ss, 2 * n + 1, ss).mean((1, 3)).astype(np.float32)
    return cv2.GaussianBlur(t, (0, 0), blur)


def ring_score(gray: np.ndarray, radii=_SCORE_RADII, min_spread: float = _MIN_SPREAD) -> np.ndarray:
    """(h, w) float32 matched-filter response to ring markers in a grey image (h, w) uint8:
    at each pixel the highest normalised cross-correlation (``TM_CCOEFF_NORMED``, -1..1)
    with `ring_template` over the ring radii `radii` (px), -1 where a template does not
    fit or where the window's grey levels spread (standard deviation) less than
    `min_spread`. Normalised correlation ignores the local gain and offset, so uneven
    light leaves it be; its peak lies on a marker's centre within about 0.15 px on the
    hard material (blur, noise, JPEG)."""
    return _ring_scores(_gray(gray), radii, min_spread)[0]


def _ring_scores(g: np.ndarray, radii, min_spread: float):
    """(score (h, w) float32, radius (h, w) float32: the ring radius of the best template)."""
    import cv2

    g = g.astype(np.float32)
    g2 = g * g
    best = np.full(g.shape, -1.0, np.float32)
    radius = np.zeros(g.shape, np.float32)
    for r in radii:
        t = ring_template(r)
        n = t.shape[0] // 2
        m = cv2.matchTemplate(g, t, cv2.TM_CCOEFF_NORMED)
        np.nan_to_num(m, copy=False, nan=-1.0)
        # correlation is scale-free: on flat background, noise alone can look like a ring;
        # a marker's window holds a white dot and a black ring, so a wide spread of grey
        inner = (slice(n, n + m.shape[0]), slice(n, n + m.shape[1]))
        mean = cv2.boxFilter(g, -1, t.shape, borderType=cv2.BORDER_REPLICATE)[inner]
        var = cv2.boxFilter(g2, -1, t.shape, borderType=cv2.BORDER_REPLICATE)[inner]
        var -= mean * mean
        m[var < min_spread * min_spread] = -1.0
        better = m > best[inner]
        np.copyto(best[inner], m, where=better)
        radius[inner][better] = r
    return best, radius


def ring_contrast(gray: np.ndarray, centres: np.ndarray, ring_radius: np.ndarray) -> np.ndarray:
    """(K,) float32 grey levels by which each marker's dot centre outshines the brightest
    of eight points round its ring (at 0.8 x `ring_radius` (K,) px from centres (K, 2));
    positive all round only for a bright spot in a dark ring, not for an eye corner or a
    nostril's edge, which `ring_score` may still like."""
    import cv2

    g = _gray(gray)
    c = np.asarray(centres, dtype=np.float32).reshape(-1, 2)
    if len(c) == 0:
        return np.zeros(0, np.float32)
    angle = np.arange(8) * (np.pi / 4)
    ring = c[:, None] + 0.8 * np.asarray(ring_radius, np.float32).reshape(-1, 1, 1) * np.stack(
        [np.cos(angle), np.sin(angle)], 1)[None].astype(np.float32)
    where = np.concatenate([c[:, None], ring], 1)                       # (K, 9, 2)
    values = cv2.remap(g.astype(np.float32), where[..., 0], where[..., 1], cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_REPLICATE)
    return values[:, 0] - values[:, 1:].max(1)


def score_peaks(score: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """(centres (K, 2) float64 pixels x right y down, values (K,) float32): the local
    maxima (3x3) of a `ring_score` map over `threshold`, refined to sub-pixel by a
    parabola through each peak and its neighbours along x and along y."""
    import cv2

    peak = (score >= cv2.dilate(score, np.ones((3, 3), np.uint8))) & (score > threshold)
    ys, xs = np.nonzero(peak)
    h, w = score.shape
    inner = (xs > 0) & (ys > 0) & (xs < w - 1) & (ys < h - 1)
    xs, ys = xs[inner], ys[inner]
    c = score[ys, xs]
    left, right, up, down = score[ys, xs - 1], score[ys, xs + 1], score[ys - 1, xs], score[ys + 1, xs]
    dx = 0.5 * (left - right) / np.minimum(left - 2 * c + right, -1e-6)
    dy = 0.5 * (up - down) / np.minimum(up - 2 * c + down, -1e-6)
    centres = np.stack([xs + np.clip(dx, -0.5, 0.5), ys + np.clip(dy, -0.5, 0.5)], 1)
    return centres.astype(np.float64), c


class RingTracks:
    """Every ring marker in view tracked through a whole clip, without a layout (issue 17
    §1; Dutreve et al. 2008, §5's markers on other people's footage: a few pixels across,
    blurred, compressed, unevenly lit, sometimes hidden).

    Per frame, `ring_score`'s peaks over `keep` are the candidates. Each track has four
    guesses of where its marker went (`_flow`): its own pyramidal Lucas-Kanade flow where
    that agrees with the next guess, the median flow of its `neighbours` nearest tracks
    plus its own motion relative to them in the last frame (an expression going on), the
    neighbours' alone (an expression stopping) and the whole face's (a lip that stays
    while the jaw drops): a rigid-plus-motion gate. It takes the candidate nearest any
    guess within `snap` px, faint ones (no dot brighter than its ring all round) 0.5 px
    dearer, one candidate per track (Hungarian, tracks seen in `min_frames` frames choosing
    first, "none" costing the gate); two matches closer than a marker's width are one
    marker or a ghost between two, and the dearer is undone. A track without a candidate
    is lost in that frame (NaN) and coasts with its neighbours' motion until a candidate
    within `reacquire` px, or a strong one within 2.5 times that, takes it back. A strong
    peak (`ring_score` over `birth` with a bright dot, or a clear dot whatever the score)
    that no track claims starts a new track, at any frame, and the clip is then walked
    backward from there, so that a marker found late (uncovered, turned into view) is
    followed back to where it appeared. A track that starts where one that ended would
    be by now (its neighbours carrying it; within `join` times the local spacing)
    continues it (`_joined`). Tracks matched in fewer than `min_frames` frames, or with a
    median score under `min_score` and no clear dot, are dropped (skin features that
    looked like a marker for a moment).

    `fit(frames)` takes the grey frames; learned: ``points_`` (F, M, 2) float32 pixels
    (x right, y down; NaN where a marker is not seen), ``scores_`` and ``contrasts_``
    (F, M) float32 (the matched peaks' `ring_score` and `ring_contrast`), in a stable
    order: by the frame each marker is first seen, then top to bottom.

    On issue 17's webcam material (`render_webcam_marker_video`, 150 frames, four seeds
    each on the sample face and on the ICT face; ``python bench/markers.py
    --only-webcam``): every marker in clear view found, median error 0.12-0.15 px, 99.3-100
    % within 3 px; no identity switch on the sample face, 1 and 6 on two ICT clips, where
    a track slid onto the skin as its marker turned edge-on.
    """

    def __init__(self, *, radii=_SCORE_RADII, birth: float = _BIRTH_SCORE, keep: float = _KEEP_SCORE,
                 snap: float = _SNAP, reacquire: float = _REACQUIRE, neighbours: int = _NEIGHBOURS,
                 min_frames: int = 3, min_score: float = 0.4, min_spread: float = _MIN_SPREAD,
                 min_contrast: float = _MIN_DOT_CONTRAST, join: float = _JOIN) -> None:
        self.radii = tuple(float(r) for r in radii)
        self.birth, self.keep = float(birth), float(keep)
        self.snap, self.reacquire = float(snap), float(reacquire)
        self.neighbours, self.min_frames, self.min_score = int(neighbours), int(min_frames), float(min_score)
        self.min_spread, self.min_contrast, self.join = float(min_spread), float(min_contrast), float(join)

    def fit(self, frames) -> RingTracks:
        """Track the markers through frames, a sequence of (h, w) uint8 grey images."""
        grays = [_gray(f) for f in frames]
        if not grays:
            raise RetargetError("RingTracks.fit needs at least one frame")
        n = len(grays)
        peaks, bright, strong = [], [], []
        for g in grays:
            score, radius = _ring_scores(g, self.radii, self.min_spread)
            cand, val = score_peaks(score, self.keep)
            ix = np.rint(cand).astype(np.int64)
            contrast = ring_contrast(g, cand, radius[ix[:, 1], ix[:, 0]])
            peaks.append((cand, val, contrast))
            bright.append(contrast >= self.min_contrast)
            # births: a clear match with a dot, or a clear dot in a ring the round
            # templates fit less well (a marker seen obliquely)
            strong.append(bright[-1] & ((val >= self.birth) | (contrast >= _CLEAR_DOT)))
        pts = np.full((n, 0, 2), np.nan)
        sc = np.full((n, 0), np.nan)
        ct = np.full((n, 0), np.nan)           # the matched peaks' dot contrast
        pos = np.zeros((0, 2))                  # where each track is (or is thought to be)
        rel = np.zeros((0, 2))                  # its motion last frame, less its neighbours'
        born = []
        for t in range(n):
            live = np.isfinite(pts[t - 1, :, 0]) if t > 0 else np.zeros(len(pos), bool)
            cand, val, contrast = peaks[t]
            if t > 0 and pos.size:
                own, guess, rel, head = self._flow(grays[t - 1], grays[t], pos, live, rel)
                # four guesses: the marker's own flow, its neighbours' (the skin's round it),
                # theirs plus its own last relative motion (an expression going on, which
                # may also stop or turn), and the whole face's (a lip that stays while the
                # jaw drops): the candidate near any will do
                d = np.min([np.linalg.norm(pos[:, None] + step[:, None] - cand[None], axis=2)
                            for step in (own, guess, guess - rel, np.broadcast_to(head, own.shape))], axis=0)
                pos = pos + guess
            else:
                d = np.linalg.norm(pos[:, None] - cand[None], axis=2)
            # a faint peak (no dot brighter than its ring all round) takes a marker only
            # near where it should be, and only if nothing brighter is as near
            d = d + np.where(bright[t], 0.0, 0.5)[None]
            gate = np.where(live, self.snap, self.reacquire)[:, None]
            gate = np.where(bright[t][None] | live[:, None], gate, self.snap)
            take = _matched(d, gate, first=np.isfinite(pts[:t, :, 0]).sum(0) >= self.min_frames)
            # a strong peak near a track lost for a while: the marker back, not a new one
            free = np.ones(len(cand), bool)
            free[take[take >= 0]] = False
            lost = np.flatnonzero(take < 0)
            back = np.flatnonzero(free & strong[t])
            if lost.size and back.size:
                again = _matched(np.linalg.norm(pos[lost][:, None] - cand[back][None], axis=2),
                                 np.full((lost.size, 1), 2.5 * self.reacquire))
                take[lost[again >= 0]] = back[again[again >= 0]]
            take = _apart(take, cand, d, _APART)
            hit = take >= 0
            pts[t, hit] = cand[take[hit]]
            sc[t, hit] = val[take[hit]]
            ct[t, hit] = contrast[take[hit]]
            rel[hit] += cand[take[hit]] - pos[hit]      # the correction is the track's own
            rel[~hit] = 0.0
            rel = np.clip(rel, -self.snap, self.snap)
            pos[hit] = cand[take[hit]]
            # births: strong peaks away from every track
            free = np.ones(len(cand), bool)
            free[take[hit]] = False
            if len(pos):
                free &= np.linalg.norm(cand[:, None] - pos[None], axis=2).min(1) > 2.0 * self.snap
            new = np.flatnonzero(free & strong[t])
            if new.size:
                # two strong peaks of one marker: keep the stronger
                new = new[np.argsort(-val[new])]
                keep_new = []
                for k in new:
                    if all(np.linalg.norm(cand[k] - cand[j]) > 2.0 * self.snap for j in keep_new):
                        keep_new.append(k)
                new = np.array(keep_new)
                add = np.full((n, len(new), 2), np.nan)
                add[t] = cand[new]
                pts = np.concatenate([pts, add], 1)
                now = np.arange(n)[:, None] == t
                sc = np.concatenate([sc, np.where(now, val[new][None], np.nan)], 1)
                ct = np.concatenate([ct, np.where(now, contrast[new][None], np.nan)], 1)
                pos = np.concatenate([pos, cand[new]])
                rel = np.concatenate([rel, np.zeros((len(new), 2))])
                born += [t] * len(new)
        born = np.array(born, dtype=np.int64)
        for m in np.flatnonzero(born > 0):
            self._backward(peaks, pts, sc, ct, m, born[m])
        pts, sc, ct = _joined(pts, sc, ct, self.join, self.neighbours)
        seen = np.isfinite(pts[..., 0])
        with np.errstate(all="ignore"):
            quality = np.nanmedian(np.where(seen, sc, np.nan), 0)
            clear = np.nanmedian(np.where(seen, ct, np.nan), 0)
        good = (seen.sum(0) >= min(self.min_frames, n)) & (
            (np.nan_to_num(quality) >= self.min_score) | (np.nan_to_num(clear) >= _CLEAR_DOT))
        pts, sc, seen = pts[:, good], sc[:, good], seen[:, good]
        first = np.where(seen.any(0), seen.argmax(0), n)
        y0 = pts[np.minimum(first, n - 1), np.arange(pts.shape[1]), 1]
        order = np.lexsort((pts[np.minimum(first, n - 1), np.arange(pts.shape[1]), 0], y0, first))
        self.points_ = pts[:, order].astype(np.float32)
        self.scores_ = sc[:, order].astype(np.float32)
        self.contrasts_ = ct[:, order].astype(np.float32)
        return self

    def _flow(self, prev, cur, pos, live, rel):
        """(own (M, 2), guess (M, 2), rel (M, 2), head (2,)): predictions of each track's
        image motion from prev to cur, the guess's part beyond its neighbours', and the
        whole face's motion. `own` is its pyramidal LK flow (often pulled off by the skin
        round a marker a few pixels across; the guess where LK fails or disagrees);
        `guess` is the median LK flow of the `neighbours` nearest seen tracks plus the
        track's own relative motion of the last frame (the expression's, which is
        smooth); `head` is the median LK flow of all seen tracks."""
        import cv2

        p = pos.astype(np.float32).reshape(-1, 1, 2)
        flow, status, _ = cv2.calcOpticalFlowPyrLK(
            prev, cur, p, None, winSize=(15, 15), maxLevel=2,
            criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 0.03))
        own = flow.reshape(-1, 2) - pos
        ok = (status.ravel() == 1) & np.isfinite(own).all(1)
        trusted = ok & live
        if trusted.sum() == 0:
            own = np.where(ok[:, None], own, 0.0)
            return own, own, rel, np.zeros(2)
        src = np.flatnonzero(trusted)
        d = np.linalg.norm(pos[:, None] - pos[src][None], axis=2)
        near = np.argsort(d, 1)[:, :min(self.neighbours, len(src))]
        head = np.median(own[src][near], axis=1)
        guess = head + rel
        # LK pulled off by the skin disagrees with the neighbours: the guess stands alone
        agree = ok & (np.linalg.norm(own - guess, axis=1) < 0.5 * self.snap)
        return np.where(agree[:, None], own, guess), guess, rel, np.median(own[src], axis=0)
    def _backward(self, peaks, pts, sc, ct, m, t0) -> None:
        """Follow track m from frame t0 back toward frame 0 (in place): its neighbours'
        motion from frame t to t - 1 moves it, the nearest free peak within `snap` px takes
        it; the first frame without one ends the walk."""
        p = pts[t0, m].copy()
        for t in range(t0 - 1, -1, -1):
            both = np.isfinite(pts[t, :, 0]) & np.isfinite(pts[t + 1, :, 0])
            both[m] = False
            if both.any():
                d = np.linalg.norm(pts[t + 1, both] - p, axis=1)
                near = np.argsort(d)[:self.neighbours]
                p = p + np.median((pts[t, both] - pts[t + 1, both])[near], axis=0)
            cand, val, contrast = peaks[t]
            if len(cand) == 0:
                return
            d = np.linalg.norm(cand - p, axis=1)
            others = np.isfinite(pts[t, :, 0])
            others[m] = False
            if others.any():
                taken = np.linalg.norm(cand[:, None] - pts[t, others][None], axis=2).min(1) < 1.5
                d[taken] = np.inf
            k = int(d.argmin())
            if d[k] > self.snap:
                return
            pts[t, m] = p = cand[k]
            sc[t, m] = val[k]
            ct[t, m] = contrast[k]


def _joined(pts: np.ndarray, sc: np.ndarray, ct: np.ndarray, gate: float, k: int):
    """(pts, sc, ct) with the tracks of one marker that was lost for a while (hidden,
    edge-on) and found again as a new track joined into one column.

    pts (F, M, 2), sc and ct (F, M): tracks, their scores and contrasts. A track b that
    starts after a track a ends continues a when b's first position lies within `gate`
    times the distance to the nearest other track (at either end) of a's last position
    carried to b's first frame by the similarity that takes a's `k` nearest neighbours
    (tracks seen in both frames) from the one frame to the other; the closest such pair
    (relative to that spacing) is joined first, and again until none is left.
    """
    n = len(pts)
    while pts.shape[1] > 1:
        seen = np.isfinite(pts[..., 0])
        if not seen.any():
            break
        first = np.where(seen.any(0), seen.argmax(0), n)
        last = np.where(seen.any(0), n - 1 - seen[::-1].argmax(0), -1)
        best = (np.inf, -1, -1)
        for a in np.flatnonzero(last < n - 1):
            for b in np.flatnonzero(first > last[a]):
                if first[b] >= n:
                    continue
                ta, tb = last[a], first[b]
                common = seen[ta] & seen[tb]
                common[[a, b]] = False
                if common.sum() < 3:
                    continue
                src, dst = pts[ta, common], pts[tb, common]
                apart = np.linalg.norm(src - pts[ta, a], axis=1)
                near = np.argsort(apart)[:k]
                A, t = _fit(src[near], dst[near], affine=False)
                d = np.linalg.norm(pts[ta, a] @ A.T + t - pts[tb, b])
                # a marker alone (a cheek) may be looked for further than one in a row
                spacing = min(apart.min(), np.linalg.norm(dst - pts[tb, b], axis=1).min())
                if d < gate * spacing and d / spacing < best[0]:
                    best = (d / spacing, a, b)
        _, a, b = best
        if a < 0:
            break
        later = seen[:, b]
        pts[later, a], sc[later, a], ct[later, a] = pts[later, b], sc[later, b], ct[later, b]
        keep = np.arange(pts.shape[1]) != b
        pts, sc, ct = pts[:, keep], sc[:, keep], ct[:, keep]
    return pts, sc, ct


def _apart(take: np.ndarray, cand: np.ndarray, cost: np.ndarray, apart: float) -> np.ndarray:
    """take (M,) (each track's candidate, -1 for none) with the dearer (cost (M, K)) of any
    two matches closer than `apart` px undone: two markers' centres are at least a
    marker's width apart, so two peaks that close are one marker, or a ghost between two
    whose rings merge."""
    take = take.copy()
    while True:
        rows = np.flatnonzero(take >= 0)
        if rows.size < 2:
            return take
        c = cand[take[rows]]
        d = np.linalg.norm(c[:, None] - c[None], axis=2)
        np.fill_diagonal(d, np.inf)
        i, j = np.unravel_index(d.argmin(), d.shape)
        if d[i, j] >= apart:
            return take
        ri, rj = rows[i], rows[j]
        take[ri if cost[ri, take[ri]] > cost[rj, take[rj]] else rj] = -1


def _matched(d: np.ndarray, gate: np.ndarray, first: np.ndarray | None = None) -> np.ndarray:
    """(M,) int64 the candidate each track takes, -1 for none, from distances d (M, K):
    the one-to-one assignment of least total cost where a pair costs its distance, if
    under gate (broadcast to (M, K)), and leaving a track without one costs its gate (so
    that no pair is broken up to make two worse ones). Tracks in `first` (M,) bool
    choose before the others."""
    from scipy.optimize import linear_sum_assignment

    out = np.full(d.shape[0], -1, dtype=np.int64)
    if d.size == 0:
        return out
    gate = np.broadcast_to(gate, d.shape)
    order = [np.arange(d.shape[0])] if first is None else [np.flatnonzero(first), np.flatnonzero(~first)]
    free = np.ones(d.shape[1], bool)
    for rows_in in order:
        if rows_in.size == 0 or not free.any():
            continue
        cols_in = np.flatnonzero(free)
        dd, gg = d[np.ix_(rows_in, cols_in)], gate[np.ix_(rows_in, cols_in)]
        ok = dd < gg
        none = np.full((len(rows_in), len(rows_in)), 1e6)
        np.fill_diagonal(none, gg.max(1))
        rows, cols = linear_sum_assignment(np.concatenate([np.where(ok, dd, 1e6), none], 1))
        pick = cols < len(cols_in)
        rows, cols = rows[pick], cols[pick]
        good = ok[rows, cols]
        out[rows_in[rows[good]]] = cols_in[cols[good]]
        free[cols_in[cols[good]]] = False
    return out


def _auto_assignment(blobs: RingBlobs, lay, path: Path) -> np.ndarray:
    """(N, 2) first-frame positions of the layout's markers, named by `assign_markers`."""
    found = len(blobs.centres)
    if found < lay.n_points:
        raise RetargetError(
            f"{path}: found {found} ring markers in the first frame, layout {lay.name!r} needs "
            f"{lay.n_points} (white dots with a black ring, all in view in the first frame)")
    match = assign_markers(blobs.centres, reference_points(lay.name))
    if (match < 0).any():
        missing = [lay.point_names[i] for i in np.flatnonzero(match < 0)]
        raise RetargetError(
            f"{path}: no marker in the first frame matches point(s) {', '.join(missing)} of layout "
            f"{lay.name!r} (are the markers placed as the layout's reference face shows?)")
    return blobs.centres[match]


def _centred(g: np.ndarray, centres: np.ndarray, shape: np.ndarray, ratio: np.ndarray, passes: int = 3):
    """Re-centre markers on their white dots in a grey image g (h, w) uint8.

    centres : (K, 2) float64 starting points; shape : (K, 2, 2) the dots' covariances
    (see `RingBlobs`); ratio : (K,) ring radius over dot radius.

    Inside a window halfway between the dot's edge and the ring's, only the dot stands out
    of the ring's dark level, so the centroid of (grey - ring level) there is the dot's
    centroid whatever the window's offset, as long as the window holds the whole dot. The
    window is an ellipse: the dot's shape scaled out, so that an oblique marker keeps the
    skin out of it; the shape follows the weights' second moments, pass after pass.
    Returns (centres (K, 2), shape (K, 2, 2), dot contrast (K,), skin contrast (K,)):
    the grey levels of the dot's middle and of the skin just outside the ring, over the
    ring's.
    """
    k = len(centres)
    if k == 0:
        return centres.copy(), shape.copy(), np.zeros(0), np.zeros(0)
    scale = 0.5 * (1.0 + ratio)                      # window / dot
    major = 2.0 * np.sqrt(np.linalg.eigvalsh(shape)[:, 1])
    cov, c = shape.copy(), centres.copy()
    for _ in range(passes):
        xs, ys, patch = _patches(g, c, np.max(scale * major) + 2.0)
        u, r_dot = _ellipse_distance(xs - c[:, 0, None, None], ys - c[:, 1, None, None], cov)
        u /= scale[:, None, None]                    # 1 on the window's edge
        r_win = (scale * r_dot)[:, None, None]
        band = (u >= 1.0) & (u < 1.0 + 1.0 / r_win)  # about a pixel wide, on the ring
        base = (patch * band).sum((1, 2)) / np.maximum(band.sum((1, 2)), 1)
        weight = np.clip(patch - base[:, None, None], 0.0, None) * np.clip((1.0 - u) * r_win + 0.5, 0.0, 1.0)
        total = weight.sum((1, 2))
        with np.errstate(invalid="ignore", divide="ignore"):
            mx = (weight * xs).sum((1, 2)) / total
            my = (weight * ys).sum((1, 2)) / total
            dx, dy = xs - mx[:, None, None], ys - my[:, None, None]
            wx, wy = weight * dx, weight * dy
            sxy = (wx * dy).sum((1, 2))
            second = np.stack([(wx * dx).sum((1, 2)), sxy, sxy, (wy * dy).sum((1, 2))],
                              1).reshape(-1, 2, 2) / total[:, None, None]
        good = np.isfinite(mx) & np.isfinite(my) & np.isfinite(second).all((1, 2))
        c = np.where(good[:, None], np.stack([mx, my], 1), c)
        second = np.where(good[:, None, None], second, cov) + 0.02 * np.eye(2)
        # a dot grows or shrinks between frames, it does not balloon into the skin
        sane = good & (np.linalg.det(second) > 0.01) & (_equivalent_radius(second) < 1.5 * _equivalent_radius(shape))
        cov = np.where(sane[:, None, None], second, cov)
    xs, ys, patch = _patches(g, c, np.max(ratio * major) + 3.5)
    u, r_dot = _ellipse_distance(xs - c[:, 0, None, None], ys - c[:, 1, None, None], cov)
    ring = (u >= scale[:, None, None]) & (u < (scale + 1.0 / r_dot)[:, None, None])
    middle = u <= np.maximum(0.5, 1.0 / r_dot)[:, None, None]
    skin_in = (ratio + 1.0 / r_dot)[:, None, None]
    skin = (u >= skin_in) & (u < skin_in + (2.0 / r_dot)[:, None, None])
    base = (patch * ring).sum((1, 2)) / np.maximum(ring.sum((1, 2)), 1)
    dot_c = (patch * middle).sum((1, 2)) / np.maximum(middle.sum((1, 2)), 1) - base
    ring_c = (patch * skin).sum((1, 2)) / np.maximum(skin.sum((1, 2)), 1) - base
    return c, cov, dot_c, ring_c


def _patches(g: np.ndarray, centres: np.ndarray, reach: float):
    """Square patches of g (h, w) round centres (K, 2), edge pixels repeated outside:
    (xs (K, 1, P), ys (K, P, 1) int64 pixel coordinates, patch (K, P, P) float32)."""
    h, w = g.shape
    grid = np.arange(-int(np.ceil(reach)), int(np.ceil(reach)) + 1)
    ix = np.rint(centres).astype(np.int64)
    xs = ix[:, 0, None, None] + grid[None, None, :]
    ys = ix[:, 1, None, None] + grid[None, :, None]
    return xs, ys, g[np.clip(ys, 0, h - 1), np.clip(xs, 0, w - 1)].astype(np.float32)


def _ellipse_distance(dx, dy, cov):
    """(u (K, P, P), r (K,)): u = 1 on the edge of the uniform ellipse with covariance cov
    (K, 2, 2) round offsets dx, dy (K, P, P); r is its equivalent radius (pixels)."""
    a, b, d = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    det = a * d - b * b
    ia, ib, id_ = (x[:, None, None] / (4.0 * det[:, None, None]) for x in (d, -b, a))
    u = np.sqrt(np.maximum(ia * dx * dx + 2.0 * ib * dx * dy + id_ * dy * dy, 0.0))
    return u, _equivalent_radius(cov)


def _equivalent_radius(cov: np.ndarray) -> np.ndarray:
    """(K,) radius of the disc with the area of the uniform ellipse of covariance (K, 2, 2)."""
    return 2.0 * np.maximum(np.linalg.det(cov), 0.0) ** 0.25


def _fit(src: np.ndarray, dst: np.ndarray, *, affine: bool):
    """(A (2, 2), b (2,)) least-squares dst ~ src @ A.T + b: a similarity (rotation and
    uniform scale, no reflection) or, with `affine`, a general affine map."""
    ms, md = src.mean(0), dst.mean(0)
    s, d = src - ms, dst - md
    if affine and len(src) >= 3:
        A = np.linalg.lstsq(s, d, rcond=None)[0].T
    else:
        a = (s * d).sum()
        bb = (s[:, 0] * d[:, 1] - s[:, 1] * d[:, 0]).sum()
        A = np.array([[a, -bb], [bb, a]]) / max((s * s).sum(), 1e-12)
    return A, md - ms @ A.T


def _gray(image: np.ndarray) -> np.ndarray:
    import cv2

    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] == 3:
        a = cv2.cvtColor(a, cv2.COLOR_BGR2GRAY)
    if a.ndim != 2 or a.dtype != np.uint8:
        raise RetargetError(f"expected a grey (h, w) uint8 image, got {a.shape} {a.dtype}")
    return a


def _points(value, what: str) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise RetargetError(f"{what} must be an (M, 2) array of numbers") from None
    if a.ndim != 2 or a.shape[1] != 2 or not np.isfinite(a).all():
        raise RetargetError(f"{what} must be a finite (M, 2) array, got shape {a.shape}")
    return a
