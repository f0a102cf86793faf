"""Ring markers a few pixels across, tracked without a layout (issue 17 §1).

Dutreve et al. 2008, §5's markers (a white dot in a black ring) on other people's footage:
a 640x480 webcam at about 60 cm makes 3 mm markers about 5 px across, blurred, noisy,
compressed, unevenly lit, sometimes oblique or hidden, where `retarget.sources.markers`'
ring detector (a dark component with a round hole) finds only the clearest few. Here a
matched filter (`ring_score`, `score_peaks`, `ring_contrast`) finds them in every frame,
and `RingTracks` follows every marker in view through a whole clip with stable columns;
`retarget.sources.markers.track_marker_video` runs it without a layout, or names its
tracks after a layout.
"""

from __future__ import annotations

import numpy as np

from retarget.errors import RetargetError
from retarget.sources.markers import _gray

__all__ = ["ring_template", "ring_score", "ring_contrast", "score_peaks", "RingTracks"]


_SCORE_RADII = (2.0, 2.6, 3.4, 4.4)   # px, outer ring radii of the matched filter's templates
_BIRTH_SCORE = 0.55    # correlation that starts a track, with a dot brighter than its ring
_MIN_DOT_CONTRAST = 8.0  # grey levels by which a new marker's dot outshines its ring all round
_APART = 4.0           # px: two markers' centres are at least this far apart (a marker
                       # of 3 mm radius at 60 cm is 5.5 px across)
_CLEAR_DOT = 40.0      # grey levels of a dot over its ring that start a track whatever the
                       # correlation (skin features never passed 35 on the hard material)
_KEEP_SCORE = 0.25     # correlation of a peak that keeps a track near its prediction
_STRAY = 5.0           # px (a marker's width): a faint peak this far from where its
                       # neighbours carry a track's last bright sighting is skin, not its marker
_SNAP = 3.0            # px, how far from its prediction a tracked marker's peak may lie
_REACQUIRE = 4.0       # px, the same for a marker lost for a while
_LOST_GRACE = 2        # frames a track may be lost before its guess is doubted
_LOST_COST = 0.5       # px added per frame lost after that to a lost track's distance to a peak
_LOST_CAP = 2.5        # px, at most (so a bright peak retakes a long-lost track within 1.5 px)
_NEIGHBOURS = 6        # markers whose motion predicts a marker's
_MIN_SPREAD = 12.0     # grey levels: standard deviation in a template's window below which
                       # nothing there is taken for a marker (noise on flat background)
_PAIR = 12.0           # px: two tracks predicted this near are placed by one two-marker fit
                       # when either lacks a bright peak (rings 8 px apart make a ghost
                       # peak between them, or merge into one)
_PAIR_BLUR = 0.7       # px, the camera's blur in the two-marker picture
_PAIR_DRIFT = 0.1      # cost (correlation) per px that a close pair's distance changes in a
                       # frame (a ghost peak between two markers halves it)
_PAIR_GAIN = 0.05      # cost by which the fit must beat the matched peaks to move them
_PAIR_SNAP = 1.0       # px: a fitted centre this near a peak takes the peak (sharper)
_MAX_MARKERS = 200     # tracks matched in one frame past which a clip is not of markers (the
                       # work per frame grows with tracks x peaks; a face carries < 100)
_LINK = 8.0            # px: median distance between two tracks' sightings and where the
                       # other carries it, under which they are one marker's (`_linked`)
_LINK_AGE = 10         # frames from its sighting within which a track is carried for that
_LINK_SHARED = 0.02    # share of the shorter's frames two tracks of one marker may share
_FILL = 2.0            # px: a gap's peak this near where the clip carries its track fills it
_FILL_AGE = 5          # frames from a sighting within which gaps are filled
_MODEL_RANK = 10       # modes of the markers' shape model (`_shape_places`)
_MODEL_WINDOW = 100    # frames it is learned from (the last ones)
_MODEL_FRAMES = 30     # frames before it is used
_MODEL_BRIGHT = 0.5    # share of those frames a track must be bright in to count in it
_MODEL_FILLS = 2       # times its places where a track was not bright are filled from the modes
_MODEL_NOISE = 1.0     # px: a bright peak's noise against the model
_MODEL_FIT = _SNAP     # px: no model where it puts a bright marker farther from its peak
_FAINT_SLACK = 0.25    # px a frame from its bright sightings by which a track's faint point
                       # may stray from where they carry it (a marker turning edge-on)


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
    from retarget.sampling import sampled

    g = _gray(gray)
    c = np.asarray(centres, dtype=np.float32).reshape(-1, 2)
    if len(c) == 0:
        return np.zeros(0, np.float32)
    angle = np.arange(8) * (np.pi / 4)
    ring = c[:, None] + 0.8 * np.asarray(ring_radius, np.float32).reshape(-1, 1, 1) * np.stack(
        [np.cos(angle), np.sin(angle)], 1)[None].astype(np.float32)
    where = np.concatenate([c[:, None], ring], 1)                       # (K, 9, 2)
    values = sampled(g.astype(np.float32), where[..., 0], where[..., 1])
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


def _frame_peaks(gray: np.ndarray, radii=_SCORE_RADII, keep: float = _KEEP_SCORE,
                 min_spread: float = _MIN_SPREAD):
    """(centres (K, 2) float64 px, scores (K,), dot contrasts (K,), ring radii (K,) px): the
    candidates of one grey frame (h, w) uint8, its `ring_score` peaks over `keep` with the
    `ring_contrast` of each at the radius of the template that matched it best."""
    score, radius = _ring_scores(gray, radii, min_spread)
    cand, val = score_peaks(score, keep)
    ix = np.rint(cand).astype(np.int64)
    peak_radius = radius[ix[:, 1], ix[:, 0]]
    return cand, val, ring_contrast(gray, cand, peak_radius), peak_radius


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
    dearer, only near the two neighbour guesses and only within `_STRAY` px of where its
    neighbours carry its last bright sighting, one candidate per track (Hungarian, tracks
    seen in `min_frames` frames choosing first, "none" costing the gate); two matches
    closer than a marker's width are one marker or a ghost between two, and the dearer is
    undone. A track without a candidate is lost in that frame (NaN) and put where the
    similarity of its nearest tracks seen both then and now carries its last sighting
    (`_carried`), until a candidate within `reacquire` px, or a strong one within 2.5
    times that, takes it back. That guess drifts off its marker, onto a neighbour's, the
    longer the track stays lost (a lower-lip track carried while the jaw drops lands on the
    mouth corner, whose own track is lost a frame or two), so after `_LOST_GRACE` frames
    lost every frame adds `_LOST_COST` px to its distance to a peak, up to `_LOST_CAP`: a
    long-lost track takes a peak by matching only within 1.5 px of its guess (a strong
    peak still within 10 px if no other track took it). On the real footage below (840
    frames, seeds 0-4, clear view within 3 px / identity switches) it took 80.9 / 48,
    84.4 / 69, 80.3 / 93, 78.2 / 106, 80.1 / 79 (mean 80.8 %, 395 switches) to 87.8 / 35,
    85.2 / 45, 84.5 / 43, 86.7 / 60, 82.3 / 47 (85.3 %, 230), and the first 150 frames of
    those clips of seeds 0-2 from 28 tracks / 1 switch / 93.0 %, 29 / 13 / 91.0, 29 / 3 /
    91.8 to 27 / 2 / 93.7, 27 / 1 / 93.9, 27 / 2 / 93.8; the rendered webcam clips keep 0 switches, but
    three ICT ones hold fewer oblique frames (77 -> 69, 65 -> 53, 100 -> 89 %): a marker
    turning edge-on is lost often and comes back on a weak peak. Without the grace (a
    frame lost already doubted) the first 150 frames of seed 0 had 9 switches; the cost
    added to the Hungarian's costs but not to the gate changed nothing (it is the gate
    that keeps the wrong peak off). A lost track that comes within `snap` px of another,
    the two never seen in one frame, is one marker followed twice, and the two columns
    become one (`_followed_twice`). A track
    held by faint peaks only is handed a strong free peak near where its neighbours carry
    its last bright sighting (and twice nearer than its faint peak): faint peaks let a
    marker turning edge-on creep onto the skin, and the marker facing the camera again
    then became a new track beside it. Two tracks predicted within `_PAIR` px of each
    other, one of them without a bright peak, are placed together (`_split_pairs`): the
    two rings make a ghost peak between them (or one peak for both), which a prediction
    pulled toward the other marker took, one track after the other; a fit of two ring
    markers to the image, the pair's distance kept from jumping, puts each on its own
    marker, never swapping the two. A strong
    peak (`ring_score` over `birth` with a bright dot, or a clear dot whatever the score)
    that no track claims starts a new track, at any frame, and the clip is then walked
    backward from there, so that a marker found late (uncovered, turned into view) is
    followed back to where it appeared. Tracks matched in fewer than `min_frames` frames,
    or with a median score under `min_score` and no clear dot, are dropped (skin features
    that looked like a marker for a moment). Then the whole clip is looked at once: the
    tracks of bright peaks that took one marker in turns (one lost, a new one born on the
    marker, the old one taking it back later) become one column (`_linked`: each one's
    sightings lie where the other's carry it, and the two are hardly ever seen together),
    and each track keeps its faint points, or takes a peak in a gap, only where its bright
    sightings on either side carry it (`_gap_filled`).

    Once `_MODEL_FRAMES` frames are in, the markers' shape over the last `_MODEL_WINDOW`
    frames is a low-rank model too (`_shape_places`: the head's pose and a few
    expressions), which this frame's bright markers fix: a track lost now takes a bright
    free peak within `snap` px of where the model puts it, and one still lost is carried
    there rather than by its nearest tracks. A lower-lip marker whose track is lost while
    the jaw drops goes where the chin says, not where the upper lip beside it stays
    (``python bench/markers_real.py --seed S``, 840 frames, seeds 0-4, clear view within
    3 px / identity switches, without -> with it: 80.5 / 72 -> 80.9 / 48, 76.6 / 80 -> 84.4
    / 69, 73.9 / 131 -> 80.3 / 93, 74.6 / 126 -> 78.2 / 106, 70.9 / 96 -> 80.1 / 79; mean
    75.3 -> 80.8 %, 505 -> 395 switches; the first 150 frames of seed 0 92.7 / 1 -> 93.1 /
    1). Without the check that the model fits the markers seen now (`_MODEL_FIT`), the
    first jaw drop of a take, which the model had not seen, took the first 150 frames
    from 1 switch to 6.

    A clip where over `_MAX_MARKERS` (200) tracks hold a peak in one frame is refused
    (`RetargetError`): noise or a fine texture, whose ring-like peaks would else pile up
    tracks and the work per frame with them.

    `fit(frames)` takes the grey frames; learned: ``points_`` (F, M, 2) float32 pixels
    (x right, y down; NaN where a marker is not seen), ``scores_`` and ``contrasts_``
    (F, M) float32 (the matched peaks' `ring_score` and `ring_contrast`), in a stable
    order: by the frame each marker is first seen, then top to bottom.

    On issue 17's webcam material (`render_webcam_marker_video`, 150 frames, four seeds
    each on the sample face and on the ICT face; ``python bench/markers.py
    --only-webcam``): every marker in clear view found, median error 0.12-0.15 px,
    99.2-100 % within 3 px, 43-89 % of the oblique frames; no identity switch on any of
    the eight (one ICT clip had 6 before the faint-peak rule above, another 1 before the
    pair fit, where a lip marker's track followed the ghost peak between it and one 8 px
    below for a dozen frames).

    On real footage (``python bench/markers_real.py``: 27 markers 5.4 px across drawn on a
    real face video, JPEG q40 + MPEG-4, 840 frames): 56 -> 42 tracks, 112 -> 72 identity
    switches, clear view 66.5 -> 80.5 % within 3 px, 29.2 -> 17.4 % missed, median 0.13
    px where held, once the whole clip was looked at (`_linked`, `_gap_filled`); the
    first 150 frames 30 -> 27 tracks, 1 switch, 90.5 -> 92.7 % within 3 px (before that,
    lost tracks carried by their neighbours' fit, a marker followed twice merged and faint
    peaks held near the last bright sighting had taken 215 tracks, 2569 switches, 37.6 %
    to 56, 112, 66.5 %). Of the faint points the forward pass holds there, under 40 % are
    on a marker (95 % of the bright ones); the shape model above then 38 tracks, 48
    switches, 80.9 %. What still fails: markers faint for long (the lower lip in shadow)
    or everything blurred by fast head turns, where tracks break.
    """

    def __init__(self, *, radii=_SCORE_RADII, birth: float = _BIRTH_SCORE, keep: float = _KEEP_SCORE,
                 snap: float = _SNAP, reacquire: float = _REACQUIRE, neighbours: int = _NEIGHBOURS,
                 min_frames: int = 3, min_score: float = 0.4, min_spread: float = _MIN_SPREAD,
                 min_contrast: float = _MIN_DOT_CONTRAST) -> None:
        self.radii = tuple(float(r) for r in radii)
        self.birth, self.keep = float(birth), float(keep)
        self.snap, self.reacquire = float(snap), float(reacquire)
        self.neighbours, self.min_frames, self.min_score = int(neighbours), int(min_frames), float(min_score)
        self.min_spread, self.min_contrast = float(min_spread), float(min_contrast)

    def fit(self, frames) -> RingTracks:
        """Track the markers through frames, a sequence of (h, w) uint8 grey images."""
        grays = [_gray(f) for f in frames]
        if not grays:
            raise RetargetError("RingTracks.fit needs at least one frame")
        n = len(grays)
        peaks, bright, strong, ring = [], [], [], []
        for g in grays:
            cand, val, contrast, peak_radius = _frame_peaks(g, self.radii, self.keep, self.min_spread)
            peaks.append((cand, val, contrast))
            bright.append(contrast >= self.min_contrast)
            # the markers' size in this frame, for the two-marker fit
            ring.append(float(np.median(peak_radius[bright[-1]])) if bright[-1].any() else self.radii[1])
            # births: a clear match with a dot, or a clear dot in a ring the round
            # templates fit less well (a marker seen obliquely)
            strong.append(bright[-1] & ((val >= self.birth) | (contrast >= _CLEAR_DOT)))
        pts = np.full((n, 0, 2), np.nan)
        sc = np.full((n, 0), np.nan)
        ct = np.full((n, 0), np.nan)           # the matched peaks' dot contrast
        pos = np.zeros((0, 2))                  # where each track is (or is thought to be)
        anchor = np.zeros((0, 2))               # where its neighbours carry its last bright match
        rel = np.zeros((0, 2))                  # its motion last frame, less its neighbours'
        lost_for = np.zeros(0, np.int64)        # frames since it was last matched
        born = []
        places, sightings = [], []              # the last frames' pos, and which were bright matches
        for t in range(n):
            live = np.isfinite(pts[t - 1, :, 0]) if t > 0 else np.zeros(len(pos), bool)
            cand, val, contrast = peaks[t]
            if t > 0 and pos.size:
                own, guess, rel, head = self._flow(grays[t - 1], grays[t], pos, live, rel)
                # four guesses: the marker's own flow, its neighbours' (the skin's round it),
                # theirs plus its own last relative motion (an expression going on, which
                # may also stop or turn), and the whole face's (a lip that stays while the
                # jaw drops): a bright candidate near any will do, a faint one only near
                # the neighbours' (the own flow and the face's let a faint skin peak that
                # stays put hold a marker that moved on)
                near = [np.linalg.norm(pos[:, None] + step[:, None] - cand[None], axis=2)
                        for step in (guess, guess - rel, own, np.broadcast_to(head, own.shape))]
                d = np.where(bright[t][None], np.min(near, axis=0), np.minimum(near[0], near[1]))
                pos = pos + guess
                anchor = anchor + guess - rel
            else:
                d = np.linalg.norm(pos[:, None] - cand[None], axis=2)
            # a faint peak (no dot brighter than its ring all round) takes a marker only
            # near where it should be, and only if nothing brighter is as near
            d = d + np.where(bright[t], 0.0, 0.5)[None]
            # a lost track's place is a guess that drifts further off its marker with every
            # frame it stays lost, onto its neighbours' (a lower-lip track carried while the
            # jaw drops lands on the mouth corner): the longer lost, the nearer a peak must be
            d = d + np.minimum(_LOST_COST * np.maximum(lost_for - _LOST_GRACE, 0), _LOST_CAP)[:, None]
            gate = np.where(live, self.snap, self.reacquire)[:, None]
            gate = np.where(bright[t][None] | live[:, None], gate, self.snap)
            # nor farther than `_STRAY` from where its neighbours carry its last bright
            # sighting: a marker that moves unlike its neighbours (a lip with the jaw) left
            # its track on a faint skin peak, which it then held for dozens of frames
            stray = np.linalg.norm(anchor[:, None] - cand[None], axis=2) > _STRAY
            gate = np.where(~bright[t][None] & stray, 0.0, gate)
            take = _matched(d, gate, first=np.isfinite(pts[:t, :, 0]).sum(0) >= self.min_frames)
            # a strong peak near a track lost for a while: the marker back, not a new one
            lost = np.flatnonzero(take < 0)
            _hand_back(take, lost, pos[lost], cand, strong[t], np.full(lost.size, 2.5 * self.reacquire))
            # a track held by faint peaks (its marker edge-on) may have crept onto the skin
            # with them, a few tenths of a pixel a frame: a strong free peak near where its
            # neighbours carry its last bright sighting, and twice as near as the faint peak,
            # is its marker facing the camera again (not a skin feature beside a marker that
            # only dimmed for a frame)
            faint = np.flatnonzero((take >= 0) & ~bright[t][np.maximum(take, 0)])
            crept = np.linalg.norm(cand[take[faint]] - anchor[faint], axis=1)
            _hand_back(take, faint, anchor[faint], cand, strong[t],
                       np.minimum(2.5 * self.reacquire, 0.5 * crept))
            take = _apart(take, cand, d, _APART)
            # two markers close together: a ghost peak between their rings, or one peak for
            # both, may hold one of them; one fit of both markers to the image places them
            take, split, split_val = _split_pairs(grays[t], pos, pts[t - 1] if t else pos + np.nan, take, cand,
                                                  bright[t], d < gate, ring[t])
            if len(split):
                split_contrast = ring_contrast(grays[t], split, np.full(len(split), ring[t]))
                cand = np.concatenate([cand, split])
                val = np.concatenate([val, split_val])
                contrast = np.concatenate([contrast, split_contrast])
                strong_t = np.concatenate([strong[t], np.zeros(len(split), bool)])
                bright_t = np.concatenate([bright[t], split_contrast >= self.min_contrast])
            else:
                strong_t, bright_t = strong[t], bright[t]
            # a track lost now may be where the shape model of the markers bright now puts
            # it: a bright peak no track took within `snap` px of there is its marker
            model = _shape_places(places, sightings, take, cand, bright_t)
            if model is not None:
                cols, where = model
                lost = take[cols] < 0
                _hand_back(take, cols[lost], where[lost], cand, bright_t, np.full(lost.sum(), self.snap))
            hit = take >= 0
            if hit.sum() > _MAX_MARKERS:
                raise RetargetError(f"frame {t}: over {_MAX_MARKERS} ring-marker-like spots followed at "
                                    "once; this does not look like a video of ring markers (noise or a "
                                    "fine texture?)")
            pts[t, hit] = cand[take[hit]]
            sc[t, hit] = val[take[hit]]
            ct[t, hit] = contrast[take[hit]]
            rel[hit] += cand[take[hit]] - pos[hit]      # the correction is the track's own
            rel[~hit] = 0.0
            rel = np.clip(rel, -self.snap, self.snap)
            lost_for = np.where(hit, 0, lost_for + 1)
            pos[hit] = cand[take[hit]]
            sighted = hit & bright_t[np.maximum(take, 0)]
            anchor[sighted] = pos[sighted]
            # a lost track is where its neighbours carry its last sighting (not where its
            # neighbours' flow, summed frame after frame, has let it drift off its marker)
            pos = _carried(pts[:t + 1], hit, pos, self.neighbours)
            if model is not None:   # better still, where the shape model puts it
                cols, where = model
                pos[cols[~hit[cols]]] = where[~hit[cols]]
            twice = _followed_twice(pos, hit, np.isfinite(pts[:t + 1, :, 0]), self.snap)
            if twice is not None:
                # one marker followed twice (a track born while the lost one had drifted off
                # it): the older column takes the younger's frames and the held one's state,
                # rather than the two taking the marker in turns
                a, b = twice
                older, younger = (a, b) if born[a] <= born[b] else (b, a)
                later = np.isfinite(pts[:, younger, 0])
                pts[later, older], sc[later, older], ct[later, older] = (
                    pts[later, younger], sc[later, younger], ct[later, younger])
                pos[older], anchor[older], rel[older], lost_for[older] = pos[b], anchor[b], rel[b], lost_for[b]
                take[older], hit[older] = take[b], hit[b]
                keep = np.arange(len(pos)) != younger
                pts, sc, ct = pts[:, keep], sc[:, keep], ct[:, keep]
                pos, anchor, rel, lost_for = pos[keep], anchor[keep], rel[keep], lost_for[keep]
                take, hit, born = take[keep], hit[keep], born[:younger] + born[younger + 1:]
                places = [np.delete(p, younger, 0) if len(p) > younger else p for p in places]
                sightings = [np.delete(p, younger, 0) if len(p) > younger else p for p in sightings]
            # births: strong peaks away from every track
            free = np.ones(len(cand), bool)
            free[take[hit]] = False
            if len(pos):
                free &= np.linalg.norm(cand[:, None] - pos[None], axis=2).min(1) > 2.0 * self.snap
            new = np.flatnonzero(free & strong_t)
            if new.size:
                # two strong peaks of one marker: keep the stronger
                new = new[np.argsort(-val[new])]
                alone = np.ones(len(new), bool)
                close = np.linalg.norm(cand[new, None] - cand[new][None], axis=2) <= 2.0 * self.snap
                for i in range(len(new)):
                    if alone[i]:
                        alone[i + 1:] &= ~close[i, i + 1:]
                new = new[alone]
                add = np.full((n, len(new), 2), np.nan)
                add[t] = cand[new]
                pts = np.concatenate([pts, add], 1)
                now = np.arange(n)[:, None] == t
                sc = np.concatenate([sc, np.where(now, val[new][None], np.nan)], 1)
                ct = np.concatenate([ct, np.where(now, contrast[new][None], np.nan)], 1)
                pos = np.concatenate([pos, cand[new]])
                anchor = np.concatenate([anchor, cand[new]])
                rel = np.concatenate([rel, np.zeros((len(new), 2))])
                lost_for = np.concatenate([lost_for, np.zeros(len(new), np.int64)])
                born += [t] * len(new)
            places = [*places[-(_MODEL_WINDOW - 1):], pos.copy()]
            sightings = [*sightings[-(_MODEL_WINDOW - 1):],
                         np.isfinite(pts[t, :, 0]) & (np.nan_to_num(ct[t]) >= self.min_contrast)]
        born = np.array(born, dtype=np.int64)
        for m in np.flatnonzero(born > 0):
            self._backward(peaks, pts, sc, ct, m, born[m])
        seen = np.isfinite(pts[..., 0])
        with np.errstate(all="ignore"):
            quality = np.nanmedian(np.where(seen, sc, np.nan), 0)
            clear = np.nanmedian(np.where(seen, ct, np.nan), 0)
        good = (seen.sum(0) >= min(self.min_frames, n)) & (
            (np.nan_to_num(quality) >= self.min_score) | (np.nan_to_num(clear) >= _CLEAR_DOT))
        pts, sc, ct = pts[:, good], sc[:, good], ct[:, good]
        # the whole clip in view: faint peaks held a track through, but are skin more often
        # than not; the bright ones tell which tracks are one marker's, and the faint
        # peaks where the clip says a marker is come back
        bright = ct >= self.min_contrast
        pts, sc, ct, bright = _linked(pts, sc, ct, bright, self.neighbours)
        pts, sc, ct = _gap_filled(pts, sc, ct, bright, peaks, self.neighbours)
        seen = np.isfinite(pts[..., 0])
        good = seen.sum(0) >= min(self.min_frames, n)
        pts, sc, ct, seen = pts[:, good], sc[:, good], ct[:, good], seen[:, good]
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
            near = np.flatnonzero(d <= self.snap)
            others = np.isfinite(pts[t, :, 0])
            others[m] = False
            if others.any() and near.size:
                taken = np.linalg.norm(cand[near, None] - pts[t, others][None], axis=2).min(1) < 1.5
                d[near[taken]] = np.inf
            k = int(d.argmin())
            if d[k] > self.snap:
                return
            pts[t, m] = p = cand[k]
            sc[t, m] = val[k]
            ct[t, m] = contrast[k]


def _shape_places(history: list[np.ndarray], bright_history: list[np.ndarray], take: np.ndarray,
                  cand: np.ndarray, bright: np.ndarray):
    """(cols (C,) int64, places (C, 2) float64 px) or None: where a low-rank shape model of
    the markers puts the tracks `cols` in this frame, given the ones matched to a bright
    peak now (take (M,) each track's candidate of cand (K, 2), -1 for none; bright (K,)).

    The model is the markers' places over the last frames (history: (M_t, 2) px per frame,
    what each track was matched to or carried to; bright_history: (M_t,) bool, matched to
    a bright peak), the tracks present through all of them and bright in at least
    `_MODEL_BRIGHT` of them: their mean and `_MODEL_RANK` principal modes, the places
    where a track was not bright filled in from the modes (`_MODEL_FILLS` times, as EM for
    PCA with missing data does). A face's markers move with a few degrees of freedom (head
    pose, under 2D projection nearly affine, and a handful of expressions: the low-rank
    non-rigid shape of Bregler et al. 2000), so this frame's bright markers fix the mode
    weights (ridge, Gaussian prior of unit variance on the modes scaled by their spread,
    `_MODEL_NOISE` px noise) and with them every other marker's place: a lower lip that
    drops with the jaw while its upper-lip neighbours stay, which no neighbour's flow
    predicts. None when fewer than 8 tracks qualify, too few are bright now, or the model
    puts one of those over `_MODEL_FIT` px from its peak (bench figures: `RingTracks`)."""
    w = len(history)
    if w < _MODEL_FRAMES:
        return None
    m0 = len(history[0])
    X = np.stack([p[:m0] for p in history])
    seen = np.stack([o[:m0] for o in bright_history])
    cols = np.flatnonzero(np.isfinite(X).all(axis=(0, 2)) & (seen.mean(0) >= _MODEL_BRIGHT))
    if cols.size < 8:
        return None
    x = X[:, cols].reshape(w, -1)
    missing = ~np.repeat(seen[:, cols], 2, axis=1)
    k = min(_MODEL_RANK, w - 1)
    for step in range(_MODEL_FILLS + 1):
        mean = x.mean(0)
        _, spread, modes = np.linalg.svd(x - mean, full_matrices=False)
        if step < _MODEL_FILLS:
            x = np.where(missing, mean + ((x - mean) @ modes[:k].T) @ modes[:k], x)
    basis = modes[:k].T * (spread[:k] / np.sqrt(w))          # (2C, k) px per unit weight
    now = take[cols]
    known = (now >= 0) & bright[np.maximum(now, 0)]
    if known.sum() < k // 2 + 3:
        return None
    rows = np.repeat(known, 2)
    b = basis[rows]
    seen_now = cand[now[known]].reshape(-1) - mean[rows]
    weights = np.linalg.solve(b.T @ b + _MODEL_NOISE**2 * np.eye(k), b.T @ seen_now)
    # a marker seen now that the model puts farther than the snap gate from its peak: the
    # face does what the last frames never showed (the first jaw drop of a take), and the
    # model's places are guesses
    if np.linalg.norm((b @ weights - seen_now).reshape(-1, 2), axis=1).max() > _MODEL_FIT:
        return None
    return cols, (mean + basis @ weights).reshape(-1, 2)


def _carried(pts: np.ndarray, hit: np.ndarray, pos: np.ndarray, k: int) -> np.ndarray:
    """(M, 2) pos (M, 2) with each track not matched now (hit (M,) False) that was seen
    before moved to its last sighting carried to the last frame of pts (T, M, 2) by its
    `k` nearest tracks (`_carried_to`; kept where fewer than 3 are seen both then and now)."""
    pos = pos.copy()
    seen = np.isfinite(pts[..., 0])
    now = np.array([len(pts) - 1])
    for a in np.flatnonzero(~hit & seen.any(0)):
        then = len(pts) - 1 - int(seen[::-1, a].argmax())
        p = _carried_to(pts, seen, a, then, now, k)[0]
        if np.isfinite(p).all():
            pos[a] = p
    return pos


def _carried_to(pts: np.ndarray, seen: np.ndarray, a: int, then: int, frames: np.ndarray, k: int,
                least: int = 3) -> np.ndarray:
    """(T, 2) float64 track a's point at frame `then` carried to each of `frames` (T,) by
    the similarity (rotation, uniform scale, shift; least squares) that takes its `k`
    nearest tracks at `then` among those seen both then and in that frame from the one to
    the other: where the skin round a marker went. NaN where fewer than `least` are seen.
    pts (F, M, 2) px, seen (F, M) bool."""
    frames = np.asarray(frames, dtype=np.int64)
    out = np.full((len(frames), 2), np.nan)
    others = np.flatnonzero(seen[then])
    others = others[others != a]
    if len(others) < least or not len(frames):
        return out
    others = others[np.argsort(np.linalg.norm(pts[then, others] - pts[then, a], axis=1))]
    # complex numbers: a 2D similarity is z -> alpha z + beta
    src = pts[then, others, 0] + 1j * pts[then, others, 1]                   # (K,)
    w = seen[frames][:, others]
    w &= np.cumsum(w, 1) <= k                                                 # the k nearest seen
    dst = np.where(w, np.nan_to_num(pts[frames][:, others, 0] + 1j * pts[frames][:, others, 1]), 0)
    n = w.sum(1)
    ok = n >= least
    sm = (w * src).sum(1) / np.maximum(n, 1)
    dm = dst.sum(1) / np.maximum(n, 1)
    s, d = np.where(w, src - sm[:, None], 0), np.where(w, dst - dm[:, None], 0)
    alpha = (d * np.conj(s)).sum(1) / np.maximum((np.abs(s) ** 2).sum(1), 1e-12)
    z = alpha * (pts[then, a, 0] + 1j * pts[then, a, 1] - sm) + dm
    out[ok] = np.stack([z.real, z.imag], 1)[ok]
    return out


def _followed_twice(pos: np.ndarray, hit: np.ndarray, seen: np.ndarray, near: float):
    """(a, b) or None: a track a not matched now (hit (M,) False) whose position pos (M, 2)
    lies within `near` px of a matched track b's, the two never seen in one frame (seen
    (T, M) bool); of several such pairs, the one with the latest-born track (one a frame
    is enough: a marker is found twice only now and then)."""
    lost, held = np.flatnonzero(~hit), np.flatnonzero(hit)
    if not lost.size or not held.size:
        return None
    d = np.linalg.norm(pos[lost][:, None] - pos[held][None], axis=2)
    d[(seen[:, lost, None] & seen[:, None, held]).any(0)] = np.inf
    i, j = np.nonzero(d < near)
    if not i.size:
        return None
    latest = np.argmax(np.maximum(lost[i], held[j]))
    return int(lost[i[latest]]), int(held[j[latest]])


def _filled(pts: np.ndarray, seen: np.ndarray, a: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(where (F, 2) float64 px, age (F,) frames): track a's point in every frame, its own
    where seen (age 0), else its sightings on either side carried there by their
    neighbours (`_carried_to`, with 2 neighbours enough) and blended by how near in time
    each lies (one side only before its first and after its last), age the frames to the
    nearer sighting; NaN (age inf) where nothing carries it. pts (F, M, 2), seen (F, M)."""
    n = len(pts)
    where = np.full((n, 2), np.nan)
    age = np.full(n, np.inf)
    at = np.flatnonzero(seen[:, a])
    if not at.size:
        return where, age
    where[at], age[at] = pts[at, a], 0
    ends = [(np.arange(at[0]), at[0]), (np.arange(at[-1] + 1, n), at[-1])]
    for frames, then in ends:
        where[frames] = _carried_to(pts, seen, a, then, frames, k, least=2)
        age[frames] = np.abs(frames - then)
    for s1, s2 in zip(at[:-1], at[1:]):
        if s2 - s1 < 2:
            continue
        frames = np.arange(s1 + 1, s2)
        p1 = _carried_to(pts, seen, a, s1, frames, k, least=2)
        p2 = _carried_to(pts, seen, a, s2, frames, k, least=2)
        w = ((frames - s1) / (s2 - s1))[:, None]
        where[frames] = np.where(np.isnan(p1), p2, np.where(np.isnan(p2), p1, (1 - w) * p1 + w * p2))
        age[frames] = np.minimum(frames - s1, s2 - frames)
    age[np.isnan(where[:, 0])] = np.inf
    return where, age


def _linked(pts: np.ndarray, sc: np.ndarray, ct: np.ndarray, bright: np.ndarray, k: int):
    """(pts, sc, ct, bright) with the tracks that are one marker's joined into one column,
    over the whole clip: a marker lost and found again (dim in shadow, blurred by a fast
    turn) becomes a new track while the old one, carried by its neighbours, waits beside it
    and may take it back later, so one marker's frames end up dealt among several tracks
    that take it in turns.

    pts (F, M, 2) px, sc and ct (F, M): tracks; bright (F, M) bool: their points on bright
    peaks, the only ones looked at (on real footage such a point is its marker about 95 %
    of the time, a faint one under 40 %). Two tracks are one marker's when each one's
    sightings lie near where the other would be (`_filled`, within `_LINK_AGE` frames of
    its own sighting): median distance under `_LINK` px over at least 3 such frames, and
    both are seen in at most `_LINK_SHARED` of the frames of the shorter (two markers are
    seen together all the time). The nearest pair is joined first (in a frame both hold, a
    bright point over a faint one, else the longer track's), and again until none is left."""
    m = pts.shape[1]
    if m < 2:
        return pts, sc, ct, bright
    pts, sc, ct, bright = pts.copy(), sc.copy(), ct.copy(), bright.copy()
    sighted = np.where(bright[..., None], pts, np.nan)     # the bright points alone
    filled = [_filled(sighted, bright, a, k) for a in range(m)]
    cost = np.full((m, m), np.inf)

    def costs(a, others):
        for b in others:
            if b == a or not bright[:, b].any():
                continue
            shared = (bright[:, a] & bright[:, b]).sum()
            mine = bright[:, b] & ~bright[:, a] & (filled[a][1] <= _LINK_AGE)
            theirs = bright[:, a] & ~bright[:, b] & (filled[b][1] <= _LINK_AGE)
            e = np.concatenate([np.linalg.norm(pts[mine, b] - filled[a][0][mine], axis=1),
                                np.linalg.norm(pts[theirs, a] - filled[b][0][theirs], axis=1)])
            ok = len(e) >= 3 and shared <= _LINK_SHARED * min(bright[:, a].sum(), bright[:, b].sum())
            cost[a, b] = cost[b, a] = np.median(e) if ok else np.inf

    for a in range(m):
        costs(a, range(a + 1, m))
    while True:
        a, b = np.unravel_index(np.argmin(cost), cost.shape)
        if not cost[a, b] < _LINK:
            break
        if bright[:, b].sum() > bright[:, a].sum():
            a, b = b, a
        more = np.isfinite(pts[:, b, 0]) & ~bright[:, a] & (bright[:, b] | np.isnan(pts[:, a, 0]))
        pts[more, a], sc[more, a], ct[more, a], bright[more, a] = pts[more, b], sc[more, b], ct[more, b], bright[more, b]
        pts[:, b], sc[:, b], ct[:, b], bright[:, b] = np.nan, np.nan, np.nan, False
        sighted[:, a] = np.where(bright[:, a, None], pts[:, a], np.nan)
        sighted[:, b] = np.nan
        cost[b], cost[:, b] = np.inf, np.inf
        filled[a] = _filled(sighted, bright, a, k)
        costs(a, range(m))
    keep = bright.any(0)
    return pts[:, keep], sc[:, keep], ct[:, keep], bright[:, keep]


def _gap_filled(pts: np.ndarray, sc: np.ndarray, ct: np.ndarray, bright: np.ndarray, peaks, k: int):
    """(pts, sc, ct): each track's frames without a bright point (bright (F, M) bool) kept
    or filled where its bright sightings on either side carry it (`_filled`): its own faint
    point if within `_SNAP` px of there, plus `_FAINT_SLACK` px a frame from the nearer
    sighting (before its first bright sighting and after its last, whatever: one side
    alone carries a marker turning edge-on too loosely), else (at most `_FILL_AGE` frames
    from a sighting) the peak of that frame's `peaks` (centres (K, 2), scores (K,),
    contrasts (K,)) within `_FILL` px, one to one, none within `_APART` px of another
    track's point; else none. Faint peaks held a track through the clip, but many were
    skin beside a marker that moved on; the whole clip tells which were the marker."""
    sighted = np.where(bright[..., None], pts, np.nan)     # the bright points alone
    want = np.full(pts.shape, np.nan)
    out = (sighted, np.where(bright, sc, np.nan), np.where(bright, ct, np.nan))
    for a in range(pts.shape[1]):
        where, age = _filled(sighted, bright, a, k)
        inside = np.zeros(len(pts), bool)
        at = np.flatnonzero(bright[:, a])
        inside[at[0]:at[-1]] = True
        own = ~bright[:, a] & np.isfinite(pts[:, a, 0]) & (
            ~inside | (np.linalg.norm(pts[:, a] - where, axis=1) < _SNAP + _FAINT_SLACK * age))
        for o, v in zip(out, (pts, sc, ct)):
            o[own, a] = v[own, a]
        gap = ~bright[:, a] & ~own & (age <= _FILL_AGE)
        want[gap, a] = where[gap]
    pts, sc, ct = out
    for t in np.flatnonzero(np.isfinite(want[..., 0]).any(1)):
        cand, val, contrast = peaks[t]
        rows = np.flatnonzero(np.isfinite(want[t, :, 0]))
        if not len(cand):
            continue
        d = np.linalg.norm(want[t, rows][:, None] - cand[None], axis=2)
        held = pts[t, np.isfinite(pts[t, :, 0])]
        if len(held):
            d[:, np.linalg.norm(cand[:, None] - held[None], axis=2).min(1) < _APART] = np.inf
        take = _matched(d, _FILL)
        got = take >= 0
        pts[t, rows[got]], sc[t, rows[got]], ct[t, rows[got]] = cand[take[got]], val[take[got]], contrast[take[got]]
    return pts, sc, ct


def _hand_back(take: np.ndarray, tracks: np.ndarray, where: np.ndarray, cand: np.ndarray,
               strong: np.ndarray, gate: np.ndarray) -> None:
    """Give `tracks` (T,) the strong candidates no track took (in place in take (M,)), each
    the nearest to its `where` (T, 2) within its `gate` (T,) px, one to one."""
    free = np.ones(len(cand), bool)
    free[take[take >= 0]] = False
    back = np.flatnonzero(free & strong)
    if tracks.size and back.size:
        again = _matched(np.linalg.norm(where[:, None] - cand[back][None], axis=2), gate[:, None])
        take[tracks[again >= 0]] = back[again[again >= 0]]


def _split_pairs(gray: np.ndarray, pos: np.ndarray, last: np.ndarray, take: np.ndarray, cand: np.ndarray,
                 bright: np.ndarray, near: np.ndarray, ring_radius: float):
    """(take (M,), centres (E, 2) float64 px, scores (E,)): each pair of tracks seen last
    frame at last (M, 2) (NaN: not seen) and predicted at pos (M, 2) within `_PAIR` px of
    each other, one of them without a bright peak, placed by one fit of two ring markers to
    the grey image (h, w) uint8 round them.

    take (M,): each track's candidate (of cand (K, 2), bright (K,) bool), -1 for none;
    near (M, K) bool: the candidates each track may take; ring_radius: the markers' outer
    ring radius, px. Each track of a pair may be at one of its `near` candidates that no
    other track took, or, if it has none matched (its peak went to the other), at its
    prediction. Of the pairs of places at least `_APART` px apart and in the tracks' order
    (a pair never swaps), the one whose two-marker picture correlates best with the image,
    less `_PAIR_DRIFT` per px that the pair's distance changed since last frame (two
    markers this near move nearly alike; a ghost peak between them halves it), is chosen;
    one with a prediction in it is refined by Gauss-Newton (one peak for both lies between
    them). It replaces the matched peaks if it costs `_PAIR_GAIN` less than they do (a
    track without one: only the other's picture, no distance term). A fitted centre within
    `_PAIR_SNAP` px of a free candidate takes it; the others are the new centres, appended
    after cand (take's indices count them), with their picture's correlation as their
    score. Pairs go nearest first; a track a nearer pair placed (or left) stays there."""
    take = take.copy()
    extra, scores = [], []
    h, w = gray.shape
    margin = 1.6 * ring_radius + _SNAP
    placed = np.zeros(len(take), bool)
    for i, j in _close_pairs(pos, last, take, bright):
        if placed[i] and placed[j]:
            continue
        ends, offset = pos[[i, j]], last[j] - last[i]
        lo = np.maximum(np.floor(ends.min(0) - margin), 0).astype(int)
        hi = np.minimum(np.ceil(ends.max(0) + margin), [w - 1, h - 1]).astype(int)
        if (hi - lo < 2).any():   # both predicted off the picture (carried out of view)
            continue
        ys, xs = np.mgrid[lo[1]:hi[1] + 1, lo[0]:hi[0] + 1]
        xy = np.stack([xs.ravel(), ys.ravel()], 1).astype(np.float64)
        patch = gray[lo[1]:hi[1] + 1, lo[0]:hi[0] + 1].ravel().astype(np.float64)
        everyone = np.concatenate([cand, extra]) if extra else cand
        others = np.delete(take, [i, j])
        free = np.ones(len(everyone), bool)
        free[others[others >= 0]] = False
        # each track's places: the free candidates near it, and for one that lost its peak to
        # the other (one peak for both) its prediction; one that a closer pair placed (or
        # left where it was) stays
        spots = np.concatenate([everyone, ends])
        opts = [[take[k]] if placed[k] else
                np.append(np.flatnonzero(near[k] & free[:len(cand)]), [len(everyone) + n] if take[k] < 0 else [])
                for n, k in enumerate((i, j))]
        choice = np.stack(np.meshgrid(*opts, indexing="ij"), -1).reshape(-1, 2).astype(np.int64)
        pairs = spots[choice]                                                   # (C, 2, 2)
        gap = pairs[:, 1] - pairs[:, 0]
        ok = (np.linalg.norm(gap, axis=1) >= _APART) & (gap @ offset > 0)
        if not ok.any():
            continue
        cost = _pair_costs(xy, patch, pairs[ok], ring_radius, offset)
        fitted, best = pairs[ok][cost.argmin()], cost.min()
        if (choice[ok][cost.argmin()] >= len(everyone)).any():
            # a track where no peak is (one peak for both): both move to fit the picture
            fitted = _refined(xy, patch, fitted, ring_radius, offset)
            best = _pair_costs(xy, patch, fitted[None], ring_radius, offset)[0]
        held = take[[i, j]] >= 0
        now = _pair_costs(xy, patch, np.array([everyone[take[k]] if take[k] >= 0 else _FAR for k in (i, j)])[None],
                          ring_radius, offset if held.all() else np.zeros(2))[0]
        placed[[i, j]] = True
        if best >= now - _PAIR_GAIN:
            continue
        for k, c in zip((i, j), fitted):
            d = np.where(free, np.linalg.norm(everyone - c, axis=1), np.inf)
            if d.size and d.min() < _PAIR_SNAP:
                take[k] = int(d.argmin())
            else:
                take[k] = len(everyone)
                extra.append(c)
                scores.append(-_pair_costs(xy, patch, fitted[None], ring_radius, np.zeros(2))[0])
                everyone = np.concatenate([everyone, c[None]])
                free = np.append(free, True)
            free[take[k]] = False
    return take, np.array(extra, np.float64).reshape(-1, 2), np.array(scores, np.float32)


_FAR = np.array([1e6, 1e6])   # a centre no pixel sees: "no marker" in `_pair_picture`


def _close_pairs(pos: np.ndarray, last: np.ndarray, take: np.ndarray, bright: np.ndarray) -> np.ndarray:
    """(Q, 2) int64 pairs (i < j) of tracks seen last frame (last (M, 2) finite) whose
    predictions pos (M, 2) lie within `_PAIR` px, one of them not holding a bright peak
    (take (M,), bright (K,)), nearest first."""
    held = (take >= 0) & bright[np.maximum(take, 0)] if len(bright) else np.zeros(len(take), bool)
    live = np.isfinite(last[:, 0])
    d = np.linalg.norm(pos[:, None] - pos[None], axis=2)
    i, j = np.nonzero(np.triu(d < _PAIR, 1) & live[:, None] & live[None])
    doubt = np.flatnonzero(~(held[i] & held[j]))
    doubt = doubt[np.argsort(d[i[doubt], j[doubt]], kind="stable")]
    return np.stack([i[doubt], j[doubt]], 1)


def _pair_picture(xy: np.ndarray, centres: np.ndarray, ring_radius: float) -> np.ndarray:
    """(C, P) float64 `ring_template`'s picture (dot 1, ring 0, skin 0.6) of two ring
    markers of `ring_radius` px at centres (C, 2, 2) (`_FAR`: no marker), at pixels xy
    (P, 2), blurred by `_PAIR_BLUR` px; where one's ring covers the other's skin it is dark."""
    from scipy.special import ndtr

    r = np.linalg.norm(xy[None, None] - centres[:, :, None], axis=3)          # (C, 2, P)
    ring = ndtr((ring_radius - r) / _PAIR_BLUR)
    dot = ndtr((0.5 * ring_radius - r) / _PAIR_BLUR)
    return 0.6 * (1.0 - ring).prod(1) + dot.sum(1)


def _pair_costs(xy: np.ndarray, patch: np.ndarray, pairs: np.ndarray, ring_radius: float,
                offset: np.ndarray) -> np.ndarray:
    """(C,) cost of two markers at pairs (C, 2, 2) px: minus the normalised correlation (as
    `ring_score`'s, blind to the light's gain and offset) of their `_pair_picture` at pixels
    xy (P, 2) with the image patch (P,), plus `_PAIR_DRIFT` per px that their distance
    differs from the length of offset (2,) (zero: no such term)."""
    m = _pair_picture(xy, pairs, ring_radius)
    m -= m.mean(1, keepdims=True)
    p = patch - patch.mean()
    corr = (m @ p) / np.sqrt((m * m).sum(1) * (p @ p) + 1e-12)
    drift = np.abs(np.linalg.norm(pairs[:, 1] - pairs[:, 0], axis=1) - np.linalg.norm(offset)) if offset.any() else 0.0
    return _PAIR_DRIFT * drift - corr


def _refined(xy: np.ndarray, patch: np.ndarray, centres: np.ndarray, ring_radius: float,
             offset: np.ndarray, steps: int = 4) -> np.ndarray:
    """(2, 2) two markers' centres (2, 2) px moved by Gauss-Newton to fit `_pair_picture`
    to the patch (P,) at pixels xy (P, 2), a step at most 1 px per marker, kept while they
    stay `_APART` px apart in the order of offset (2,) and cost less (`_pair_costs`)."""
    probe = 0.2 * np.concatenate([np.zeros((1, 4)), np.eye(4), -np.eye(4)])  # central differences
    p = patch - patch.mean()
    best = centres
    cost = _pair_costs(xy, patch, centres[None], ring_radius, offset)[0]
    theta = centres.ravel()
    for _ in range(steps):
        pics = _pair_picture(xy, (theta + probe).reshape(-1, 2, 2), ring_radius)
        pics -= pics.mean(1, keepdims=True)
        gain = (pics[0] @ p) / max(pics[0] @ pics[0], 1e-12)
        jac = gain * (pics[1:5] - pics[5:9]) / 0.4                              # (4, P)
        step = np.linalg.lstsq(jac.T, p - gain * pics[0], rcond=None)[0].reshape(2, 2)
        step *= np.minimum(1.0, 1.0 / np.maximum(np.linalg.norm(step, axis=1), 1e-12))[:, None]
        theta = theta + step.ravel()
        c = theta.reshape(2, 2)
        gap = c[1] - c[0]
        if np.linalg.norm(gap) < _APART or gap @ offset <= 0:
            break
        now = _pair_costs(xy, patch, c[None], ring_radius, offset)[0]
        if now < cost:
            best, cost = c.copy(), now
    return best


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
