"""A video of the built-in face opening its jaw, with its landmarks' true pixel positions:
material for tests of markerless tracking (the native face mesh, `retarget.facemesh`),
which needs a face that looks like one and points that are known."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from retarget.errors import RetargetError
from retarget.sample_face import EXPRESSION_NAMES, posed_vertices, sample_face
from retarget.testing.camera import look_at
from retarget.testing.render import render_face

__all__ = ["FACE_IDENTITY", "render_face_video"]

FACE_IDENTITY = np.array([-0.3, 0.5, 0.2, -0.4, 0.1])
"""The performer's identity parameters (`sample_face`): a face the face mesh finds."""


def render_face_video(path, n_frames: int = 10, *, size: int = 480, fps: float = 30.0,
                      codec: str = "FFV1", jaw: float = 0.8) -> np.ndarray:
    """Write a video of the built-in face seen from the front, its ``jawOpen`` weight going
    from 0 to `jaw` over `n_frames` frames.

    path : the video file, its container matching `codec` (FFV1: .mkv, lossless; VP80 or
        VP90: .webm; MJPG: .avi). size : width and height in pixels.

    Returns (n_frames, 68, 2) float64: the iBUG 68 landmarks in pixels, x right and y up
    from the image's bottom edge (a take's convention), continuous coordinates (a pixel's
    centre at .5).
    """
    import cv2

    face = sample_face(1, identity=FACE_IDENTITY)
    centre = face.vertices.mean(0)
    camera = look_at(centre + np.array([0.0, 0.0, 45.0]), centre, size=(size, size), fov_deg=30)
    weights = np.zeros((n_frames, len(EXPRESSION_NAMES)))
    weights[:, list(EXPRESSION_NAMES).index("jawOpen")] = np.linspace(0.0, jaw, n_frames)
    writer = cv2.VideoWriter(str(Path(path)), cv2.VideoWriter_fourcc(*codec), fps, (size, size))
    if not writer.isOpened():
        raise RetargetError(f"OpenCV cannot write {codec} to {str(path)!r}")
    truth = []
    try:
        for vertices in posed_vertices(face, weights):
            writer.write(render_face(camera, vertices, face.faces).image)
            points = camera.R @ vertices[face.landmarks68].T + camera.t[:, None]
            pixels = ((camera.K @ points)[:2] / points[2]).T + 0.5  # OpenCV's centres -> continuous
            truth.append(np.column_stack([pixels[:, 0], size - pixels[:, 1]]))
    finally:
        writer.release()
    return np.array(truth)
