"""A sticker whose track ended (hidden by a head turn) and came back as a new column is
joined into one column again (issue 17, held-out seed 6: a brow and a cheek, 15 tracks
for 13 stickers), without the lost track's stray last sightings."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from retarget.sources.stereo_tracks import rejoined_tracks


def _take(seed=0, n=120, m=7):
    rng = np.random.default_rng(seed)
    face = rng.uniform(-60, 60, (m, 3)) * [1, 1, 0.3] + [0, 0, 1000.0]
    turns = Rotation.from_euler("y", (30 * np.sin(np.arange(n) / 15))[:, None], degrees=True).as_matrix()
    centre = face.mean(0)
    pts = np.einsum("fij,nj->fni", turns, face - centre) + centre
    return pts + rng.normal(0, 0.5, pts.shape)


def test_a_split_sticker_is_one_column_again_without_its_stray_sighting():
    pts = _take()
    split = np.concatenate([pts, np.full_like(pts[:, :1], np.nan)], axis=1)
    split[50:, 3] = np.nan                # lost at frame 50 ...
    split[70:, 7] = pts[70:, 3]           # ... and back as a new track at frame 70
    split[62, 3] = pts[62, 4]             # the lost track's one stray sighting: a neighbour
    out, groups = rejoined_tracks(split)
    assert out.shape == pts.shape
    assert [3, 7] in groups
    col = groups.index([3, 7])
    seen = np.isfinite(out[:, col, 0])
    assert seen[:50].all() and seen[70:].all() and not seen[50:70].any()
    np.testing.assert_allclose(out[70:, col], pts[70:, 3])


def test_stickers_seen_together_are_not_joined():
    pts = _take(1)
    out, groups = rejoined_tracks(pts)
    assert out.shape == pts.shape and all(len(g) == 1 for g in groups)
    np.testing.assert_array_equal(out, pts)


def test_a_lost_tracks_one_stray_sighting_on_a_neighbour_is_dropped():
    pts = _take(2)
    tracked = pts.copy()
    tracked[60:90, 2] = np.nan             # hidden by a head turn ...
    tracked[74, 2] = pts[74, 5]            # ... but for one frame on a neighbour's blob
    tracked[30, 4] = np.nan                # a one-frame miss inside a run stays as it is
    out, groups = rejoined_tracks(tracked)
    assert all(len(g) == 1 for g in groups)
    assert np.isnan(out[74, 2]).all()
    np.testing.assert_array_equal(np.isfinite(out[..., 0]).sum(0),
                                  np.isfinite(tracked[..., 0]).sum(0) - np.eye(len(groups))[2])
