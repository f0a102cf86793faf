"""Tests for retarget.sources.color_markers: sub-pixel centroids of anti-aliased coloured
discs drawn at known positions, the median filter and merging, the marker template's
identity keeping, lost-marker hold then NaN, and refused input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.sample_face import sample_face
from retarget.sources.color_markers import (
    MARKER_COLORS,
    Blobs,
    MarkerTemplate,
    color_blobs,
    color_mask,
    layout_marker_colors,
    refined_centres,
    sticker_color,
)

BGR = {"green": (40, 200, 40), "blue": (230, 80, 30), "magenta": (220, 40, 220),
       "cyan": (230, 220, 30), "yellow": (30, 220, 230)}
SKIN = np.array([120.0, 150.0, 200.0])
SUPER = 8  # supersampling of the drawn test images


def _image(centres, colors, radius=3.5, size=(320, 240), noise=2.0, seed=0, cuts=()):
    """Anti-aliased discs on shaded skin: (H, W, 3) uint8, discs centred at `centres` px.

    cuts : (x0, x1, y0, y1) skin-coloured bars drawn over the discs.
    """
    w, h = size
    ys, xs = np.mgrid[0:h * SUPER, 0:w * SUPER]
    shade = 0.6 + 0.4 * xs / (w * SUPER)  # light falls off across the image
    big = (SKIN * shade[..., None]).astype(np.float32)
    # Sample (i, j) of the supersampled image lies at pixel ((j + 0.5) / S - 0.5, ...).
    px, py = (xs + 0.5) / SUPER - 0.5, (ys + 0.5) / SUPER - 0.5
    for (cx, cy), name in zip(centres, colors):
        r0, c0 = max(int((cy - radius - 1) * SUPER), 0), max(int((cx - radius - 1) * SUPER), 0)
        win = np.s_[r0:int((cy + radius + 2) * SUPER), c0:int((cx + radius + 2) * SUPER)]
        inside = (px[win] - cx) ** 2 + (py[win] - cy) ** 2 <= radius**2
        big[win][inside] = np.array(BGR[name], np.float32) * shade[win][inside][:, None]
    for x0, x1, y0, y1 in cuts:
        rows = slice(int((y0 + 0.5) * SUPER), int((y1 + 0.5) * SUPER))
        big[rows, int((x0 + 0.5) * SUPER):int((x1 + 0.5) * SUPER)] = SKIN
    img = cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA)
    img += np.random.default_rng(seed).normal(0.0, noise, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _nearest(found, truth):
    d = np.linalg.norm(found[:, None] - truth[None], axis=2)
    return d.argmin(axis=0), d.min(axis=0)


def test_blobs_have_sub_pixel_centroids_and_the_right_colours():
    rng = np.random.default_rng(3)
    centres = np.stack([np.linspace(30, 290, 12), rng.uniform(30, 210, 12)], 1)
    centres += rng.uniform(-0.5, 0.5, (12, 2))  # sub-pixel positions
    names = [("green", "blue", "magenta", "cyan", "yellow")[i % 5] for i in range(12)]
    blobs = color_blobs(_image(centres, names), ("green", "blue", "magenta", "cyan", "yellow"))
    assert len(blobs) == 12
    idx, err = _nearest(blobs.centroids, centres)
    assert err.max() < 0.1  # px; a binary centroid is off by up to ~0.3 px at this size
    assert [blobs.names[c] for c in blobs.colors[idx]] == names
    assert blobs.centroids.dtype == np.float32 and np.all(blobs.areas[idx] > 20)


def test_only_the_asked_colours_are_found_and_skin_is_not_a_marker():
    centres = np.array([[60.0, 60.0], [160.0, 120.0], [260.0, 180.0]])
    img = _image(centres, ["green", "blue", "magenta"])
    blobs = color_blobs(img, ("blue",))
    assert len(blobs) == 1 and np.linalg.norm(blobs.centroids[0] - centres[1]) < 0.1
    assert blobs.of_color("blue").all() and not blobs.of_color("green").any()
    skin_only = _image([], [])
    assert len(color_blobs(skin_only, tuple(MARKER_COLORS))) == 0


def test_median_filter_removes_speckle():
    img = _image([[100.0, 100.0]], ["green"], noise=0.0)
    rng = np.random.default_rng(1)
    spots = rng.integers([10, 10], [310, 230], (40, 2))
    img[spots[:, 1], spots[:, 0]] = BGR["green"]  # isolated single-pixel noise
    assert len(color_blobs(img, ("green",), median=1, min_area=1)) > 30
    blobs = color_blobs(img, ("green",))
    assert len(blobs) == 1 and np.linalg.norm(blobs.centroids[0] - [100, 100]) < 0.1
    mask = color_mask(img, "green")
    assert mask[100, 100] == 255 and mask[spots[:, 1], spots[:, 0]].max() == 0


def test_a_marker_cut_in_two_is_merged_into_one():
    img = _image([[100.0, 100.0], [200.0, 100.0]], ["blue", "blue"], radius=5.0,
                 cuts=[(99.0, 101.0, 90, 110)])  # a 2 px gap, as a hair would leave
    assert len(color_blobs(img, ("blue",), merge_distance=0)) == 3
    blobs = color_blobs(img, ("blue",))
    assert len(blobs) == 2
    _, err = _nearest(blobs.centroids, np.array([[100.0, 100.0], [200.0, 100.0]]))
    assert err.max() < 0.5


def _blobs(points, colors, names=("green", "blue")):
    return Blobs(np.asarray(points, np.float32).reshape(-1, 2),
                 np.array([names.index(c) for c in colors], dtype=np.int64),
                 np.full(len(colors), 30, np.int32), names)


def test_template_keeps_identities_of_moving_markers():
    start = np.array([[50.0, 50.0], [80.0, 50.0], [50.0, 90.0]])
    colors = ["green", "green", "blue"]
    template = MarkerTemplate(["a", "b", "c"], colors, max_jump=10.0).fit(
        _blobs(start + 2.0, colors), start)
    assert np.allclose(template.positions_, start + 2.0)
    velocity = np.array([[6.0, 0.0], [-6.0, 0.0], [0.0, 6.0]])
    p = start + 2.0
    for _ in range(4):
        p = p + velocity
        order = [2, 1, 0]  # candidates come in any order
        out = template(_blobs(p[order], [colors[i] for i in order]))
        assert np.allclose(out, p)
        assert not template.held_.any() and not template.lost_.any()
    # a and b (same colour, 6 px/frame toward each other) are now 10 px apart and
    # about to cross; the constant-velocity prediction keeps them apart.
    p = p + velocity
    assert np.allclose(template(_blobs(p, colors)), p)


def test_lost_marker_is_held_then_nan_then_found_again():
    start = np.array([[50.0, 50.0], [120.0, 50.0]])
    template = MarkerTemplate(["a", "b"], ["green", "blue"], max_jump=8.0, hold=2)
    template.fit(_blobs(start, ["green", "blue"]), start)
    only_a = _blobs(start[:1], ["green"])
    for k in (1, 2):
        out = template(only_a)
        assert np.allclose(out[1], start[1]) and template.held_[1] and template.lost_[1] == k
        assert not template.held_[0]
    out = template(only_a)
    assert np.isnan(out[1]).all() and not template.held_[1] and template.lost_[1] == 3
    # A blue candidate far away is not b, a green one near b's spot neither.
    out = template(_blobs([start[0], start[1] + [30.0, 0.0], start[1] + [1.0, 0.0]],
                          ["green", "blue", "green"]))
    assert np.isnan(out[1]).all()
    out = template(_blobs([start[0], start[1] + [3.0, 1.0]], ["green", "blue"]))
    assert np.allclose(out[1], start[1] + [3.0, 1.0]) and template.lost_[1] == 0


def test_fit_starts_unfound_markers_lost_where_they_are_expected():
    start = np.array([[50.0, 50.0], [120.0, 50.0]])
    template = MarkerTemplate(["a", "b"], ["green", "blue"], max_jump=8.0, hold=2)
    template.fit(_blobs(start[:1], ["green"]), start)
    assert np.isnan(template.positions_[1]).all() and template.lost_[1] > template.hold
    out = template(_blobs(start + 1.0, ["green", "blue"]))
    assert np.allclose(out, start + 1.0)


def test_layout_colours_keep_same_coloured_markers_apart():
    colors = np.array(layout_marker_colors("dutreve21"))
    face = sample_face(1)
    xy = face.vertices[face.landmarks68[list(get_layout("dutreve21").ibug68)], :2]
    d = np.linalg.norm(xy[:, None] - xy[None], axis=2)
    off = ~np.eye(len(xy), dtype=bool)
    nearest_same = d[(colors[:, None] == colors[None]) & off].min()
    cycled = np.array([("green", "magenta", "blue", "cyan", "yellow")[i % 5] for i in range(len(xy))])
    nearest_cycled = d[(cycled[:, None] == cycled[None]) & off].min()
    assert nearest_same > 2.5 and nearest_same > 1.5 * nearest_cycled  # cm on the face
    assert set(colors) <= set(MARKER_COLORS)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: color_blobs(np.zeros((10, 10, 3), np.float32)), "BGR uint8"),
        (lambda: color_blobs(np.zeros((10, 10), np.uint8)), "BGR uint8"),
        (lambda: color_blobs(np.zeros((10, 10, 3), np.uint8), ("purple",)), "unknown marker colour 'purple'"),
        (lambda: color_blobs(np.zeros((10, 10, 3), np.uint8), ()), "colors is empty"),
        (lambda: MarkerTemplate(["a", "b"], ["green"]), "one colour per marker"),
        (lambda: MarkerTemplate(["a"], ["green"], hold=-1), "hold"),
        (lambda: MarkerTemplate(["a"], ["green"])(_blobs([], [])), "fit"),
        (lambda: MarkerTemplate(["a"], ["green"]).fit(_blobs([], []), [[np.nan, 0.0]]), "finite"),
    ],
)
def test_bad_input_is_refused(call, match):
    with pytest.raises(RetargetError, match=match):
        call()


def test_sticker_color_takes_names_picked_colours_and_hsv():
    from retarget.sources.color_markers import MarkerColor, sticker_color

    blue = sticker_color("blue")
    assert blue.hue == MARKER_COLORS["blue"].hue and blue.min_saturation < MARKER_COLORS["blue"].min_saturation
    picked = sticker_color((230, 80, 30))          # BGR of a blue sticker
    assert abs(picked.hue - 112) <= 2               # OpenCV hue (degrees / 2)
    assert sticker_color("hsv:60,200,200").hue == 60
    own = MarkerColor("mine", 40.0)
    assert sticker_color(own) is own
    for bad in ("teal", "hsv:1,2", (1, 2)):
        with pytest.raises(RetargetError, match="colour"):
            sticker_color(bad)
    # An integer hue makes the same mask as a float one (inRange needs one bound type).
    img = np.zeros((4, 4, 3), np.uint8)
    img[1:3, 1:3] = (230, 80, 30)
    assert (color_mask(img, MarkerColor("b", 105, hue_tol=12), median=1) > 0).sum() == 4


def test_refined_centres_find_small_stickers_through_jpeg():
    # Issue 17's stickers are 3-6 px across and webcam JPEG keeps chroma at half
    # resolution (the gain over the blobs' centres on the rendered webcam material is
    # tested in test_stereo_stickers.py).
    rng = np.random.default_rng(8)
    centres = np.stack([np.linspace(30, 290, 12), rng.uniform(30, 210, 12)], 1)
    centres += rng.uniform(-0.5, 0.5, (12, 2))
    raw = _image(centres, ["blue"] * 12, radius=2.5, noise=3.0)
    _, jpeg = cv2.imencode(".jpg", raw, [cv2.IMWRITE_JPEG_QUALITY, 75])
    img = cv2.imdecode(jpeg, cv2.IMREAD_COLOR)
    start = centres + rng.uniform(-0.7, 0.7, centres.shape)
    err = np.linalg.norm(refined_centres(img, start, sticker_color("blue")) - centres, axis=1)
    assert np.median(err) < 0.15 and err.max() < 0.3
    # NaN rows pass through; a centre with no sticker near it stays within its window.
    out = refined_centres(img, [[np.nan, np.nan], [5.0, 5.0]], "blue")
    assert np.isnan(out[0]).all() and np.linalg.norm(out[1] - 5.0) < 3.5
