"""Head poses from anchors never all seen together (issue 17, held-out seed 4: the two
temples, each seen with the forehead and the nose bridge alone): the anchors' head-frame
places tied by the other stickers (`anchored_poses`' marker_weight) and the poses smoothed
over time (pose_window)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from retarget.sources.headpose import anchored_poses


def _take(seed=4, n=150):
    rng = np.random.default_rng(seed)
    # Temples, forehead, nose bridge, then 8 stickers that move a little with expression.
    head = np.array([[-65, 20, -50], [65, 20, -50], [0, 70, 0], [0, 30, 20]], dtype=np.float64)
    others = np.array([[-35, 50, -5], [35, 50, -5], [-45, -10, -10], [45, -10, -10],
                       [0, 5, 35], [-20, -35, 10], [20, -35, 10], [0, -60, 5]], dtype=np.float64)
    face = np.concatenate([head, others])
    yaw = np.radians(35) * np.sin(np.linspace(0, 4 * np.pi, n))
    rot = Rotation.from_rotvec(yaw[:, None] * np.array([0.1, 1.0, 0.05])).as_matrix()
    trans = np.array([0.0, 0.0, 1000.0]) + np.stack([10 * np.sin(np.linspace(0, 5, n)),
                                                     np.zeros(n), np.zeros(n)], 1)
    expression = np.zeros((n, len(face), 3))
    expression[:, 4:] = 1.5 * np.sin(np.linspace(0, 11, n)[:, None, None] + rng.uniform(0, 6, (8, 3)))
    clean = np.einsum("fij,fnj->fni", rot, face + expression) + trans[:, None]
    ray = clean / np.linalg.norm(clean, axis=2, keepdims=True)
    points = clean + rng.normal(0, 0.3, clean.shape) + rng.normal(0, 2.0, clean.shape[:2] + (1,)) * ray
    # A temple is seen while the head is turned towards the cameras' side of it.
    points[yaw > -0.05, 0] = np.nan
    points[yaw < 0.05, 1] = np.nan
    return points, face, rot, trans


def test_temples_never_seen_together_are_placed_by_the_other_stickers():
    points, face, rot, trans = _take()
    true_gap = np.linalg.norm(face[0] - face[1])
    off = []
    for weight in (0.0, 5.0):
        _, _, ref = anchored_poses(points, np.arange(4), sight_ratio=6.0, marker_weight=weight)
        off.append(abs(np.linalg.norm(ref[0] - ref[1]) - true_gap))
    assert off[1] < 0.8 and off[1] < 0.5 * off[0]   # 1.5 -> 0.4 mm


def test_smoothed_poses_are_nearer_the_truth():
    points, face, rot, trans = _take(5)
    errors = []
    for window in (1, 17):
        r, t, _ = anchored_poses(points, np.arange(4), sight_ratio=6.0, marker_weight=5.0,
                                 pose_window=window)
        clean = np.einsum("fij,nj->fni", rot, face[:4]) + trans[:, None]
        stab = np.einsum("fnj,fij->fni", clean, r) + t[:, None]
        errors.append(np.median(np.linalg.norm(stab - stab.mean(axis=0), axis=2)))
    assert errors[1] < 0.7 * errors[0]   # 1.03 -> 0.50 mm
