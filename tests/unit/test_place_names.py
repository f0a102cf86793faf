"""Unnamed 3D stickers named by where they sit (retarget.sources.place_names): the sticker
material's 13 stickers against a layout reference made from them, the head turned, a
sticker missing, one extra, and one met later."""

from __future__ import annotations

import numpy as np
import pytest

from retarget.custom_layouts import stereo_reference
from retarget.errors import RetargetError
from retarget.sample_face import sample_face
from retarget.sources.place_names import matched_places
from retarget.testing.stereo_rig import MM_PER_CM, sticker_vertices


@pytest.fixture(scope="module")
def stickers() -> np.ndarray:
    """(13, 3) mm the stickers in a camera's axes (x right, y down, z away), 1 m off."""
    face = sample_face(1)
    return face.vertices[sticker_vertices(face)] * MM_PER_CM * [1, -1, -1] + [0, 0, 1000]


def _turned(points: np.ndarray, yaw: float) -> np.ndarray:
    """(N, 3) `points` turned `yaw` degrees about the vertical through their mean."""
    a = np.radians(yaw)
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    mid = points.mean(axis=0)
    return (points - mid) @ rot.T + mid


@pytest.mark.parametrize("yaw", [-50.0, 0.0, 35.0])
def test_a_session_s_places_are_named_despite_a_turn_a_missing_and_an_extra_sticker(stickers, yaw):
    reference = stereo_reference(stickers)
    rng = np.random.default_rng(int(yaw) + 100)
    order = rng.permutation(13)                      # the order another session met them
    places = _turned(stickers, yaw)[order] + rng.normal(0, 0.7, (13, 3))
    places[order == 6] = np.nan                      # a cheek sticker never seen
    places = np.vstack([places, [[0.0, -30.0, 1040.0]]])   # a stray blue spot behind the face
    rows = matched_places(stereo_reference(places[np.isfinite(places[:, 0])]), reference)
    expected = np.append(order[order != 6], -1)
    np.testing.assert_array_equal(rows, expected)
    # NaN rows are none; the places' frame may be any similarity of the reference's.
    nan_kept = matched_places(places * [0.1, -0.1, -0.1] + 5.0, reference)
    np.testing.assert_array_equal(nan_kept, np.insert(expected, np.flatnonzero(order == 6)[0], -1))


def test_a_sticker_met_later_takes_a_free_row_and_the_named_keep_theirs(stickers):
    reference = stereo_reference(stickers)
    places = _turned(stickers, 20.0)[::-1]             # named m13..m01
    known = np.arange(13)[::-1].copy()
    known[4] = -1                                      # row 8's sticker, met later
    rows = matched_places(places, reference, known=known)
    assert rows[4] == 8 and (np.delete(rows, 4) == np.delete(known, 4)).all()


def test_a_bad_reference_is_refused(stickers):
    with pytest.raises(RetargetError, match="reference points coincide"):
        matched_places(stickers, np.zeros((4, 3)))
    with pytest.raises(RetargetError, match=r"a reference \(N >= 3, 3\)"):
        matched_places(stickers, stickers[:2])
