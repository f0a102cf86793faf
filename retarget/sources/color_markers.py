"""Coloured sticker markers in one image: detection, and a template that names them.

Woodward et al., §5 "Marker tracking", Algorithm 1: each image goes through

1. colour segmentation with a colour predicate (Woodward: YUV; here HSV, which their §8.1
   benchmark also uses: a hue window, and a floor on saturation and value because "low
   intensity regions were more ambiguous and were thresholded out"), a median filter and
   connected components analysis;
2. merging of nearby components of the same colour (a marker split by a highlight or a
   partial occlusion counts once);
3. centroids of the components as candidate marker positions;
4. a marker template (the markers' positions and velocities) assigns candidates to named
   markers frame to frame; "a marker is considered to have disappeared if a new position
   that is below a certain distance threshold cannot be found - in this case the previous
   marker position is carried through". Here the carried position is flagged (`held_`) and
   kept for at most `hold` frames, after which the marker is NaN until it is found again
   near where it was last seen.

Centroids are sub-pixel: a sticker's anti-aliased rim mixes its colour with the skin
around it, so each pixel near the component gets the share of marker colour it holds,
``alpha = (p - skin) . (marker - skin) / |marker - skin|²`` (BGR, the two colours the
medians of the component's core and of a ring outside it), and the centroid is the
alpha-weighted mean pixel position. A binary component's centroid would be off by up to a
few tenths of a pixel, which the stereo depth (`retarget.sources.stereo`) multiplies.

Pixel positions: (x, y) in OpenCV's image convention (x right, y down, pixel centres at
integer coordinates), float32.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import linear_sum_assignment

from retarget.errors import RetargetError
from retarget.layouts import Layout, get_layout

__all__ = [
    "MarkerColor",
    "MARKER_COLORS",
    "Blobs",
    "color_mask",
    "color_blobs",
    "refined_centres",
    "MarkerTemplate",
    "layout_marker_colors",
    "sticker_color",
]


@dataclass(frozen=True)
class MarkerColor:
    """A colour predicate in OpenCV's 8-bit HSV (hue 0-179, saturation and value 0-255).

    name : the colour's name.
    hue : hue at the window's centre, degrees / 2 as OpenCV stores it.
    hue_tol : half-width of the hue window (same units); the window wraps at 180.
    min_saturation, min_value : floors that keep skin, shadows and grey out.
    """

    name: str
    hue: float
    hue_tol: float = 12.0
    min_saturation: float = 110.0
    min_value: float = 50.0


MARKER_COLORS: dict[str, MarkerColor] = {
    c.name: c
    for c in (
        # Skin sits at hue 0-25 with saturation 50-150: red, orange and yellow stickers
        # would need tighter floors, so the defaults keep to the other side of the wheel.
        MarkerColor("green", 60.0),
        MarkerColor("cyan", 90.0),
        MarkerColor("blue", 115.0),
        MarkerColor("magenta", 150.0),
        MarkerColor("yellow", 30.0, hue_tol=6.0, min_saturation=170.0),
    )
}
"""The built-in colours by name; Woodward's stickers are blue."""


def sticker_color(spec) -> MarkerColor:
    """A colour predicate for small stickers filmed by webcams, from a user's choice.

    spec : a `MarkerColor` (used as is); a built-in colour name; (B, G, R) 0-255 (a
    sticker's colour picked from an image); or ``"hsv:H,S,V"`` (OpenCV's 8-bit HSV).
    Names and picked colours get a wide hue window (22, i.e. 44 degrees) and low floors
    (saturation 70, value 35): a 5 px sticker through a webcam's blur and JPEG chroma
    subsampling keeps only part of its colour (blue at saturation 230 arrives at
    80-150), while skin stays at hue 0-25 and grey background below saturation 40.
    """
    if isinstance(spec, MarkerColor):
        return spec
    if isinstance(spec, str) and spec in MARKER_COLORS:
        return MarkerColor(spec, MARKER_COLORS[spec].hue, hue_tol=22.0, min_saturation=70.0,
                           min_value=35.0)
    if isinstance(spec, str) and spec.startswith("hsv:"):
        try:
            hsv = [float(v) for v in spec[4:].split(",")]
        except ValueError:
            hsv = []
        if len(hsv) != 3:
            raise RetargetError(f"colour {spec!r}: give hsv:H,S,V (OpenCV's 8-bit HSV)")
        h = hsv[0]
    else:
        try:
            bgr = np.asarray(spec, dtype=np.float64).reshape(3)
        except (TypeError, ValueError):
            raise RetargetError(
                f"unknown sticker colour {spec!r}: a name ({', '.join(MARKER_COLORS)}), "
                "B,G,R or hsv:H,S,V") from None
        h = float(cv2.cvtColor(np.clip(bgr, 0, 255).astype(np.uint8)[None, None], cv2.COLOR_BGR2HSV)[0, 0, 0])
    return MarkerColor(f"hue{h:g}", h, hue_tol=22.0, min_saturation=70.0, min_value=35.0)


def _colors(colors) -> tuple[MarkerColor, ...]:
    if isinstance(colors, (str, MarkerColor)):
        colors = (colors,)
    out = []
    for c in colors:
        if isinstance(c, MarkerColor):
            out.append(c)
        elif c in MARKER_COLORS:
            out.append(MARKER_COLORS[c])
        else:
            raise RetargetError(
                f"unknown marker colour {c!r}; built-in colours: {', '.join(MARKER_COLORS)}"
            )
    if not out:
        raise RetargetError("colors is empty; give at least one marker colour")
    return tuple(out)


def layout_marker_colors(layout: Layout | str,
                         palette: Sequence[str] = ("green", "magenta", "blue", "cyan", "yellow"),
                         ) -> tuple[str, ...]:
    """(N,) a sticker colour for each point of `layout`, same colours far apart.

    Woodward uses one colour for all 13 stickers; with several, the template and the
    stereo matching only ever weigh markers of one colour against each other, so a marker
    is confused only with distant ones. Colours are dealt greedily down the face (the
    built-in face's landmarks, `Layout.reference_points`): each point takes the palette
    colour whose nearest point already holding it is furthest away (for ``dutreve21``,
    5 colours: same-coloured stickers at least 2.9 cm apart, against 1.6 cm when the
    colours are simply cycled). Dealt once per layout and palette, then cached.
    """
    layout = layout if isinstance(layout, Layout) else get_layout(layout)
    return _dealt_colors(layout, tuple(palette))


@functools.lru_cache(maxsize=16)
def _dealt_colors(layout: Layout, palette: tuple[str, ...]) -> tuple[str, ...]:
    _colors(palette)
    xy = layout.reference_points()[:, :2]
    order = np.lexsort((xy[:, 0], -xy[:, 1]))
    chosen = np.full(layout.n_points, -1)
    for i in order:
        gaps = []
        for c in range(len(palette)):
            same = chosen == c
            gaps.append(np.inf if not same.any() else np.linalg.norm(xy[same] - xy[i], axis=1).min())
        chosen[i] = int(np.argmax(gaps))
    return tuple(palette[c] for c in chosen)


def _bgr(image) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise RetargetError(
            f"image must be a BGR uint8 array (H, W, 3); got {img.dtype} {img.shape}"
        )
    return img


def _predicate(hsv: np.ndarray, color: MarkerColor) -> np.ndarray:
    """(H, W) uint8 0/255: the colour predicate, before any filtering."""
    lo, hi = color.hue - color.hue_tol, color.hue + color.hue_tol
    floor = (color.min_saturation, color.min_value)
    # The hue window may wrap past 0 or 180: up to two ranges.
    ranges = [(max(lo, 0.0), min(hi, 179.0))]
    if lo < 0:
        ranges.append((180.0 + lo, 179.0))
    if hi > 179:
        ranges.append((0.0, hi - 180.0))
    mask = None
    for h0, h1 in ranges:
        # float64 bounds on both sides: inRange refuses mixed types (an integer hue).
        part = cv2.inRange(hsv, np.array([np.ceil(h0), *floor], dtype=np.float64),
                           np.array([np.floor(h1), 255, 255], dtype=np.float64))
        mask = part if mask is None else cv2.bitwise_or(mask, part)
    return mask


def color_mask(image, color: str | MarkerColor, median: int = 3) -> np.ndarray:
    """(H, W) uint8 0/255: pixels passing `color`'s predicate, median filtered.

    image : (H, W, 3) uint8 BGR. median : odd aperture of the median filter (1 = none);
    it removes isolated pixels of camera noise (Woodward §5, Algorithm 1 step 3).
    """
    img = _bgr(image)
    (c,) = _colors(color)
    mask = _predicate(cv2.cvtColor(img, cv2.COLOR_BGR2HSV), c)
    return cv2.medianBlur(mask, median) if median > 1 else mask


@dataclass(frozen=True)
class Blobs:
    """Candidate markers found in one image.

    centroids : (M, 2) float32 sub-pixel positions (x right, y down, px).
    colors : (M,) int index of each blob's colour in `names`.
    areas : (M,) int32 pixel count of each (merged) component after filtering.
    names : the colour names `colors` indexes.
    """

    centroids: np.ndarray
    colors: np.ndarray
    areas: np.ndarray
    names: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.centroids)

    def of_color(self, name: str) -> np.ndarray:
        """(M,) bool: the blobs of the colour called `name`."""
        if name not in self.names:
            return np.zeros(len(self), dtype=bool)
        return self.colors == self.names.index(name)


_KERNEL3 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))


def _alpha_centroid(img: np.ndarray, labels: np.ndarray, members: np.ndarray,
                    box: tuple[int, int, int, int]) -> np.ndarray:
    """(2,) float64 centroid of one component weighted by its pixels' marker-colour share.

    labels : (H, W) component labels; members : the labels that make the marker;
    box : (x0, y0, x1, y1) their bounding box, end-exclusive.
    """
    x0, y0, x1, y1 = box
    pad = 3
    h, w = labels.shape
    xa, ya, xb, yb = max(x0 - pad, 0), max(y0 - pad, 0), min(x1 + pad, w), min(y1 + pad, h)
    window = labels[ya:yb, xa:xb]
    m = (window == members[0] if len(members) == 1 else np.isin(window, members)).astype(np.uint8)
    roi = img[ya:yb, xa:xb].astype(np.float64)
    near = cv2.dilate(m, _KERNEL3, iterations=2)
    ring = (cv2.dilate(near, _KERNEL3) > 0) & (near == 0)
    core = cv2.erode(m, _KERNEL3) > 0
    if not core.any():
        core = m > 0
    if not ring.any():
        # The component fills its surroundings (cut by the image border): binary centroid.
        ys, xs = np.nonzero(m)
        return np.array([xs.mean() + xa, ys.mean() + ya])
    ys, xs = np.nonzero(near)
    skin = np.median(roi[ring], axis=0)
    axis = np.median(roi[core], axis=0) - skin
    alpha = np.clip((roi[ys, xs] - skin) @ axis / max(axis @ axis, 1e-9), 0.0, 1.0)
    total = alpha.sum()
    if total <= 0:
        ys, xs = np.nonzero(m)
        return np.array([xs.mean() + xa, ys.mean() + ya])
    return np.array([alpha @ xs / total + xa, alpha @ ys / total + ya])


def color_blobs(
    image,
    colors: Sequence[str | MarkerColor] | str = ("blue",),
    *,
    min_area: int = 3,
    merge_distance: float = 4.0,
    median: int = 3,
) -> Blobs:
    """Candidate markers of the given colours in one image (Woodward §5, Algorithm 1, 3-6).

    image : (H, W, 3) uint8 BGR.
    colors : colour names from `MARKER_COLORS` or `MarkerColor`s.
    min_area : components with fewer pixels (after the median filter) are noise.
    merge_distance : px; components of one colour closer than this (gap between their
        pixels) are one marker.
    median : the median filter's aperture (odd; 1 = none).
    """
    img = _bgr(image)
    cols = _colors(colors)
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
    # One image of colour indices (0 = no marker colour) and one connected-components
    # pass over their union: stickers of different colours do not touch.
    index = np.zeros(img.shape[:2], dtype=np.uint8)
    for ci, color in enumerate(cols):
        index[_predicate(hsv, color) > 0] = ci + 1
    mask = (index > 0).astype(np.uint8) * 255
    if median > 1:
        mask = cv2.medianBlur(mask, median)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    on = mask > 0
    votes = np.bincount(labels[on] * (len(cols) + 1) + index[on], minlength=n * (len(cols) + 1))
    component_color = votes.reshape(n, len(cols) + 1)[:, 1:].argmax(axis=1)
    big = stats[:, cv2.CC_STAT_AREA] >= min_area
    big[0] = False
    centroids, color_idx, areas = [], [], []
    for ci in range(len(cols)):
        keep = np.flatnonzero(big & (component_color == ci))
        for members in _merged(stats, keep, merge_distance):
            x0 = stats[members, cv2.CC_STAT_LEFT].min()
            y0 = stats[members, cv2.CC_STAT_TOP].min()
            x1 = (stats[members, cv2.CC_STAT_LEFT] + stats[members, cv2.CC_STAT_WIDTH]).max()
            y1 = (stats[members, cv2.CC_STAT_TOP] + stats[members, cv2.CC_STAT_HEIGHT]).max()
            centroids.append(_alpha_centroid(img, labels, members, (x0, y0, x1, y1)))
            color_idx.append(ci)
            areas.append(int(stats[members, cv2.CC_STAT_AREA].sum()))
    return Blobs(
        centroids=np.array(centroids, dtype=np.float32).reshape(-1, 2),
        colors=np.array(color_idx, dtype=np.int64),
        areas=np.array(areas, dtype=np.int32),
        names=tuple(c.name for c in cols),
    )


def refined_centres(image, centres, color: str | MarkerColor, *, radius: float = 3.5,
                    ring: float = 2.0, iterations: int = 4) -> np.ndarray:
    """(K, 2) float64 sub-pixel centres of small stickers near `centres` (K, 2) px.

    image : (H, W, 3) uint8 BGR. Each centre is moved to the centroid, within `radius` px
    of it, of the weight ``luma contrast x chroma share``, re-centred `iterations` times:
    luma contrast is how much darker (or, for a sticker brighter than its surround,
    lighter) a pixel is than the median of the ring `radius`..`radius + ring` px out;
    chroma share is the pixel's chroma along `color`'s hue, from the ring's median (0) to
    the window's peak (1), clipped. Why both: webcam JPEG / MPEG-4 keep chroma at half
    resolution, so a chroma-only centroid of a 3-6 px sticker is coarse (about 0.13 px
    median error in the vertical disparity on issue 17's material, 1.6 mm of depth per
    0.1 px), while the luma is full resolution (0.10 px); luma alone is pulled by dark
    features beside a sticker (brows, lip lines), which the chroma share masks out.
    A centre whose window has no weight, or NaN, is returned unchanged.
    """
    img = _bgr(image)
    (c,) = _colors(color)
    c0 = np.asarray(centres, dtype=np.float64).reshape(-1, 2)
    out = c0.copy()
    ok = np.isfinite(c0).all(axis=1)
    if not ok.any():
        return out
    # The colour's chromatic direction in BGR (its grey part removed).
    hue = cv2.cvtColor(np.array([[[c.hue, 255, 255]]], np.uint8), cv2.COLOR_HSV2BGR)[0, 0]
    axis = hue.astype(np.float64) - hue.mean()
    axis /= max(np.linalg.norm(axis), 1e-9)
    h, w = img.shape[:2]
    half = int(np.ceil(radius + ring + 1))
    off = np.arange(-half, half + 1)
    at = c0[ok]
    for _ in range(max(1, iterations)):
        base = np.rint(at).astype(np.int64)
        xs = base[:, 0, None, None] + off[None, None, :]           # (K, 1, S)
        ys = base[:, 1, None, None] + off[None, :, None]           # (K, S, 1)
        patch = img[np.clip(ys, 0, h - 1), np.clip(xs, 0, w - 1)].astype(np.float64)  # (K, S, S, 3)
        luma = patch @ np.array([0.114, 0.587, 0.299])
        chroma = patch @ axis
        dist = np.hypot(xs - at[:, 0, None, None], ys - at[:, 1, None, None])
        inside = (dist <= radius) & (xs >= 0) & (xs < w) & (ys >= 0) & (ys < h)
        around = (dist > radius) & (dist <= radius + ring)
        ring_luma = _masked_median(luma, around)
        ring_chroma = _masked_median(chroma, around)
        peak = np.where(inside, chroma, -np.inf).max(axis=(1, 2))
        share = np.clip((chroma - ring_chroma[:, None, None])
                        / np.maximum(peak - ring_chroma, 1e-3)[:, None, None], 0.0, 1.0)
        contrast = luma - ring_luma[:, None, None]
        sign = np.sign((np.where(inside, share * contrast, 0.0)).sum(axis=(1, 2)))
        weight = np.clip(sign[:, None, None] * contrast, 0.0, None) * share * inside
        total = weight.sum(axis=(1, 2))
        good = total > 0
        new = np.stack([(weight * xs).sum(axis=(1, 2)), (weight * ys).sum(axis=(1, 2))], axis=1)
        at = np.where(good[:, None], new / np.where(good, total, 1.0)[:, None], at)
    out[ok] = at
    return out


def _masked_median(values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(K,) median over the last two axes of `values` (K, S, S) where `mask` holds (NaN
    where it holds nowhere)."""
    v = np.sort(np.where(mask, values, np.inf).reshape(len(values), -1), axis=1)
    n = mask.reshape(len(values), -1).sum(axis=1)
    lo = np.take_along_axis(v, np.maximum((n - 1) // 2, 0)[:, None], axis=1)[:, 0]
    hi = np.take_along_axis(v, np.maximum(n // 2, 0)[:, None], axis=1)[:, 0]
    return np.where(n > 0, 0.5 * (lo + hi), np.nan)


def _merged(stats: np.ndarray, keep: np.ndarray, distance: float) -> list[np.ndarray]:
    """Groups of component labels whose bounding boxes come within `distance` px."""
    if keep.size <= 1 or distance <= 0:
        return [np.array([k]) for k in keep]
    x0 = stats[keep, cv2.CC_STAT_LEFT].astype(np.float64)
    y0 = stats[keep, cv2.CC_STAT_TOP].astype(np.float64)
    x1 = x0 + stats[keep, cv2.CC_STAT_WIDTH]
    y1 = y0 + stats[keep, cv2.CC_STAT_HEIGHT]
    # Gap between boxes along each axis (negative when they overlap); stickers are
    # compact, so the boxes' gap stands for the pixels' gap.
    gx = np.maximum(x0[:, None], x0[None]) - np.minimum(x1[:, None], x1[None])
    gy = np.maximum(y0[:, None], y0[None]) - np.minimum(y1[:, None], y1[None])
    near = np.maximum(gx, gy) < distance
    # Each component takes the smallest index it reaches through near pairs.
    group = np.arange(keep.size)
    while True:
        spread = np.where(near, group[None, :], keep.size).min(axis=1)
        if np.array_equal(spread, group):
            break
        group = spread
    return [keep[group == g] for g in np.unique(group)]


class MarkerTemplate:
    """Named markers followed from frame to frame (Woodward §5, the marker template).

    names : (N,) marker names.
    colors : (N,) colour name of each marker (a name used in the `Blobs` it is given).
    max_jump : px; a candidate further than this from a marker's predicted position
        (last position + last velocity) is not that marker.
    hold : frames a lost marker keeps its last position (flagged in `held_`) before it
        becomes NaN; it is looked for near that position from then on.

    `fit(blobs, positions)` initialises the template on one image: each marker takes
    the candidate of its colour nearest to its given position (one-to-one, within
    `max_jump`); a marker without one starts lost (NaN) at that position. Calling the
    template with the next image's `Blobs` returns its (N, 2) float32 positions. After
    `fit` or a call: ``positions_`` (N, 2) float32 the current output (NaN for markers
    lost longer than `hold` frames), ``held_`` (N,) bool a position carried over,
    ``lost_`` (N,) int frames since each marker was last seen.
    """

    def __init__(self, names: Sequence[str], colors: Sequence[str], *, max_jump: float = 12.0,
                 hold: int = 5):
        self.names = tuple(str(n) for n in names)
        self.colors = tuple(str(c) for c in colors)
        if len(self.colors) != len(self.names) or not self.names:
            raise RetargetError(
                f"MarkerTemplate needs one colour per marker: {len(self.names)} names, "
                f"{len(self.colors)} colours"
            )
        if not max_jump > 0:
            raise RetargetError(f"MarkerTemplate max_jump must be > 0 px, got {max_jump!r}")
        if isinstance(hold, bool) or not isinstance(hold, (int, np.integer)) or hold < 0:
            raise RetargetError(f"MarkerTemplate hold must be an integer >= 0, got {hold!r}")
        self.max_jump = float(max_jump)
        self.hold = int(hold)

    def fit(self, blobs: Blobs, positions) -> MarkerTemplate:
        """Initialise on one image's candidates near `positions` (N, 2) px; returns self."""
        p = np.asarray(positions, dtype=np.float64)
        if p.shape != (len(self.names), 2) or not np.all(np.isfinite(p)):
            raise RetargetError(
                f"MarkerTemplate.fit: positions must be finite with shape "
                f"({len(self.names)}, 2); got {p.shape}"
            )
        match = self._assigned(blobs, p)
        found = match >= 0
        self.position_ = p.copy()
        self.position_[found] = blobs.centroids[match[found]]
        self.velocity_ = np.zeros_like(self.position_)
        self.lost_ = np.where(found, 0, self.hold + 1).astype(np.int64)
        self.held_ = np.zeros(len(self.names), dtype=bool)
        return self

    @property
    def positions_(self) -> np.ndarray:
        """(N, 2) float32 current positions, NaN for markers lost longer than `hold`."""
        out = self.position_.astype(np.float32)
        out[self.lost_ > self.hold] = np.nan
        return out

    def __call__(self, blobs: Blobs) -> np.ndarray:
        if not hasattr(self, "position_"):
            raise RetargetError("MarkerTemplate: call fit(blobs, positions) before tracking")
        predicted = self.position_ + self.velocity_
        match = self._assigned(blobs, predicted)
        found = match >= 0
        new = blobs.centroids[match[found]].astype(np.float64)
        # A marker seen again after a loss restarts with no velocity: the gap's motion is
        # not one frame's.
        moving = np.zeros_like(self.velocity_)
        moving[found] = new - self.position_[found]
        self.velocity_ = np.where((found & (self.lost_ == 0))[:, None], moving, 0.0)
        self.position_[found] = new
        self.lost_[found] = 0
        self.lost_[~found] += 1
        self.held_ = ~found & (self.lost_ <= self.hold)
        return self.positions_

    def _assigned(self, blobs: Blobs, at: np.ndarray) -> np.ndarray:
        """(N,) index into `blobs` per marker (-1 none): same colour, within max_jump."""
        match = np.full(len(self.names), -1, dtype=np.int64)
        if len(blobs) == 0:
            return match
        blob_color = np.asarray(blobs.names)[blobs.colors]
        same = np.asarray(self.colors)[:, None] == blob_color[None, :]
        d = np.linalg.norm(at[:, None, :] - blobs.centroids[None, :, :], axis=2)
        allowed = same & (d <= self.max_jump)
        # Forbidden pairs cost more than any sum of allowed ones, so they are taken only
        # when nothing else is left, and then dropped.
        big = self.max_jump * (len(self.names) + 1) + 1.0
        rows, cols = linear_sum_assignment(np.where(allowed, d, big))
        ok = allowed[rows, cols]
        match[rows[ok]] = cols[ok]
        return match
