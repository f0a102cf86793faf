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

5. `retarget.sources.ring_tracks.ring_score` is a matched filter, the normalised correlation with `ring_template`s of
   2-4.4 px ring radius; its peaks (`score_peaks`, sub-pixel) lie on the dots within about
   0.15 px, and `ring_contrast` (dot over the brightest of its ring) tells a marker from
   an eye corner when a track starts.
6. `retarget.sources.ring_tracks.RingTracks` follows every marker in view through a whole clip without a layout:
   each track moves with its neighbours' motion (plus its own expression's), snaps to the
   nearest peak, established tracks first; two markers within a marker's width or two of
   each other are placed together by a two-marker fit (the ghost peak between their rings
   takes neither); strong peaks no track claims start new tracks at any frame, followed
   back to where the marker appeared. `track_marker_video` uses it without a layout
   (columns m01..mM) or when the first frame shows fewer rings than the layout has (named
   by `assign_markers` on the frame that sees most).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.sources.take import Take, marker_names
from retarget.sources.video import VideoReader

if TYPE_CHECKING:
    from retarget.sources.ring_tracks import RingTracks

__all__ = [
    "RingBlobs",
    "ring_blobs",
    "detect_ring_markers",
    "reference_points",
    "assign_markers",
    "MarkerTracker",
    "track_marker_video",
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
    starts = []
    for angle, factor in [(a, f) for a in (0.0, -20.0, 20.0, -40.0, 40.0) for f in (1.0, 0.8, 1.25)]:
        c, s = np.cos(np.radians(angle)), np.sin(np.radians(angle))
        A = factor * scale * np.array([[c, -s], [s, c]])
        starts.append((A, mid_det - mid_ref @ A.T))
    starts += _pair_starts(ref, det, gate * spacing, scale)
    for A, b in starts:
        match = out
        for it in range(30):
            moved = ref @ A.T + b
            limit = gate * spacing * np.sqrt(abs(np.linalg.det(A)))
            cost = np.concatenate([cdist(moved, det), np.full((len(ref), len(ref)), limit)], 1)
            rows, cols = linear_sum_assignment(cost)
            new = np.full(len(ref), -1, dtype=np.int64)
            hit = cols < len(det)
            new[rows[hit]] = cols[hit]
            # in the reference's units: in pixels, an affine fit that shrinks the face
            # would shrink every "none" cost with it and win with a handful of matches
            total = cost[rows, cols].sum() / np.sqrt(abs(np.linalg.det(A)))
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
        if (match >= 0).all() and total < 0.2 * gate * spacing * len(ref):
            break                       # every point matched closely: no need to look on
    return best


def _pair_starts(ref: np.ndarray, det: np.ndarray, limit: float, scale: float,
                 n_pairs: int = 8, keep: int = 3) -> list[tuple[np.ndarray, np.ndarray]]:
    """The `keep` similarity transforms (A (2, 2), b (2,)) that best lay the reference
    (N, 2) on the detections (M, 2), among those mapping one of `n_pairs` long reference
    pairs onto a detected pair (rotation within 60 degrees, scale within 4x of `scale`).

    `assign_markers`' median alignment misses when the two sets differ by more than a few
    points (markers the first take never saw, or hidden now): the medians then sit a
    marker's spacing apart and the fit locks one row off. A pair of points fixes a
    similarity whatever the others do; each is scored by the reference's points' distance
    to their nearest detection, capped at `limit` (reference units).
    """
    from scipy.spatial import cKDTree

    if len(ref) < 2 or len(det) < 2:
        return []
    i, j = np.triu_indices(len(ref), 1)
    length = np.linalg.norm(ref[j] - ref[i], axis=1)
    long = np.flatnonzero(length >= np.median(length))
    picked = long[np.linspace(0, len(long) - 1, min(n_pairs, len(long))).astype(int)]
    c, d = np.nonzero(~np.eye(len(det), dtype=bool))
    v_ref = ref[j[picked]] - ref[i[picked]]                            # (P, 2)
    v_det = det[d] - det[c]                                            # (Q, 2)
    z = (v_det[None, :, 0] + 1j * v_det[None, :, 1]) / (v_ref[:, None, 0] + 1j * v_ref[:, None, 1])
    ok = (np.abs(np.angle(z)) <= np.radians(60)) & (np.abs(z) > scale / 4) & (np.abs(z) < scale * 4)
    pp, qq = np.nonzero(ok)
    if len(pp) == 0:
        return []
    z = z[pp, qq]
    shift = (det[c[qq], 0] + 1j * det[c[qq], 1]) - z * (ref[i[picked[pp]], 0] + 1j * ref[i[picked[pp]], 1])
    moved = z[:, None] * (ref[None, :, 0] + 1j * ref[None, :, 1]) + shift[:, None]   # (T, N)
    gap = cKDTree(det).query(np.stack([moved.real.ravel(), moved.imag.ravel()], 1))[0]
    cost = np.minimum(gap.reshape(moved.shape) / np.abs(z)[:, None], limit).sum(axis=1)
    out = []
    for t in np.argsort(cost)[:keep]:
        A = np.array([[z[t].real, -z[t].imag], [z[t].imag, z[t].real]])
        out.append((A, np.array([shift[t].real, shift[t].imag])))
    return out


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

    from retarget.sources.ring_tracks import RingTracks

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
            names = marker_names(points.shape[1])
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
