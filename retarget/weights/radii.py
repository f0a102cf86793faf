"""Face frame and per-feature ellipsoid radii derived from the landmark layout.

Dutreve §3.2 sizes each feature's ellipsoid from feature relationships: "r_x depends on
the distance between the eye's corners, r_y on the distance with the eyebrow". The radii
here are such ratios of layout measurements (eye width, eye-to-brow distance, nose width,
mouth width, chin height, face width), so they follow the target's own proportions and
units. Axes are those of a face frame fitted to the landmarks (x across the face toward
the subject's left, y up, z out of the face), so a mesh in any orientation gets the same
ellipsoids; without a layout the frame is the mesh's own axes.
"""

from __future__ import annotations

import numpy as np

# Radii (r_x, r_y, r_z) per region as multiples of a layout measurement.
# Tuned once on the ICT benchmark's generic face (bench/accuracy.py) for the paper's
# method, then frozen: they are ratios, so they carry over to any face size.
_REGION_RADII = {
    "brows": ("eye_width", (0.75, 0.75, 0.75)),
    "eyes": ("eye_width", (0.6, 0.45, 0.6)),
    "nose": ("nose_width", (0.7, 0.8, 0.8)),
    "upper_lip": ("mouth_width", (0.4, 0.3, 0.4)),
    "lower_lip": ("mouth_width", (0.4, 0.3, 0.4)),
    "mouth_corners": ("mouth_width", (0.35, 0.35, 0.4)),
    "jaw": ("chin_height", (1.0, 0.8, 0.8)),
    # only the dense mediapipe468 layout has these; not tuned (the bench tunes 58 points)
    "cheeks": ("eye_width", (0.8, 0.8, 0.8)),
    "forehead": ("eye_width", (0.9, 0.9, 0.9)),
}


def face_frame(points: np.ndarray, layout=None) -> np.ndarray:
    """(3, 3) rotation whose rows are the face's x (toward subject's left), y (up), z (out).

    Fitted from eye and mouth landmarks of the layout; identity (the mesh's own axes, the
    paper's assumption) when the layout has no eyes or mouth on both sides.
    """
    if layout is None:
        return np.eye(3)
    regions = np.asarray(layout.regions)
    sides = np.asarray(layout.sides)
    left = (regions == "eyes") & (sides == "left")
    right = (regions == "eyes") & (sides == "right")
    mouth = np.isin(regions, ("upper_lip", "lower_lip", "mouth_corners"))
    if not (left.any() and right.any() and mouth.any()):
        return np.eye(3)
    x = points[left].mean(0) - points[right].mean(0)
    x /= np.linalg.norm(x)
    up = 0.5 * (points[left].mean(0) + points[right].mean(0)) - points[mouth].mean(0)
    y = up - (up @ x) * x
    y /= np.linalg.norm(y)
    return np.stack([x, y, np.cross(x, y)])


def layout_measurements(local: np.ndarray, layout) -> dict[str, float]:
    """Layout distances (target units) from (N, 3) points in the face frame."""
    regions, sides = np.asarray(layout.regions), np.asarray(layout.sides)
    face_width = float(np.ptp(local[:, 0])) or 1.0

    def span_x(mask):
        return float(np.ptp(local[mask, 0])) if mask.sum() >= 2 else 0.0

    eye_widths = [span_x((regions == "eyes") & (sides == s)) for s in ("left", "right")]
    eye_width = float(np.mean([w for w in eye_widths if w > 0])) if any(eye_widths) else 0.25 * face_width
    corners = regions == "mouth_corners"
    mouth_width = span_x(corners) or span_x(np.isin(regions, ("upper_lip", "lower_lip"))) or 0.5 * face_width
    nose_width = span_x(regions == "nose") or 0.4 * mouth_width
    mouth = np.isin(regions, ("upper_lip", "lower_lip", "mouth_corners"))
    jaw = regions == "jaw"
    if jaw.any() and mouth.any():
        chin_height = float(local[mouth, 1].mean() - local[jaw, 1].min())
    else:
        chin_height = 0.0
    chin_height = chin_height if chin_height > 0 else 0.5 * mouth_width
    return {"face_width": face_width, "eye_width": eye_width, "mouth_width": mouth_width,
            "nose_width": nose_width, "chin_height": chin_height}


def feature_radii(points: np.ndarray, layout=None) -> tuple[np.ndarray, np.ndarray]:
    """Per-feature ellipsoid radii (N, 3) in the face frame, and that frame (3, 3).

    Without a layout every feature gets a sphere of twice its nearest-neighbour distance
    (a documented fallback: no relationships are known).
    """
    p = np.asarray(points, dtype=np.float64)
    frame = face_frame(p, layout)
    if layout is None:
        d = np.linalg.norm(p[:, None] - p[None], axis=2)
        np.fill_diagonal(d, np.inf)
        r = 2.0 * d.min(1) if len(p) > 1 else np.ones(1)
        return np.repeat(r[:, None], 3, axis=1), frame
    m = layout_measurements(p @ frame.T, layout)
    radii = np.empty((len(p), 3))
    for i, region in enumerate(layout.regions):
        measure, ratios = _REGION_RADII[region]
        radii[i] = m[measure] * np.asarray(ratios)
    return radii, frame
