"""The built-in face with its lips welded: a closed-lip mesh like most scans and sculpts,
for testing `retarget.lips` and the rigs on joined lips.

The sample face's lips are separate sheets that meet at the corners (the slit's vertices
are duplicated for the lower lip); here every lower-lip duplicate is merged with its
upper-lip vertex at their midpoint, so the lips are one surface. The inner-lip landmarks,
which sat on the two sheets of the slit and would now coincide, move one grid row up
(upper lip) or down (lower lip), where a user clicking a closed mouth would put them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.sample_face import DEMO_PERFORMER, sample_face

__all__ = ["WeldedFace", "copies_of", "mouth_opened_to", "welded_lips_face"]

_UPPER_INNER, _LOWER_INNER = (61, 62, 63), (65, 66, 67)


@dataclass(frozen=True, eq=False)
class WeldedFace:
    """vertices (V, 3) cm, faces (F, 3), uv (V, 2), landmarks68 (68,) vertex indices;
    welded : (W,) the vertices the lips were welded along (the closed mouth's line)."""

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    landmarks68: np.ndarray
    welded: np.ndarray


def welded_lips_face(resolution: int = 1, identity=None) -> WeldedFace:
    """`retarget.sample_face.sample_face` with the lips welded (module docstring)."""
    face = sample_face(resolution, identity)
    uv, n = face.uv, len(face.vertices)
    mouth_row = uv[face.landmarks68[48], 1]
    on_row = np.flatnonzero(np.isclose(uv[:, 1], mouth_row))
    # a slit vertex and its lower-lip copy share their uv; the copy has the larger index
    order = on_row[np.lexsort((on_row, uv[on_row, 0]))]
    same = np.isclose(uv[order[1:], 0], uv[order[:-1], 0])
    upper, copy = order[:-1][same], order[1:][same]
    vertices = face.vertices.copy()
    vertices[upper] = 0.5 * (vertices[upper] + vertices[copy])
    keep = np.ones(n, bool)
    keep[copy] = False
    new_index = np.cumsum(keep) - 1
    target = np.arange(n)
    target[copy] = upper
    faces = new_index[target[face.faces]]
    landmarks = target[face.landmarks68]
    for k, step in [(k, +1) for k in _UPPER_INNER] + [(k, -1) for k in _LOWER_INNER]:
        landmarks[k] = _row_neighbour(uv, keep, landmarks[k], step)
    return WeldedFace(vertices[keep], faces, uv[keep], new_index[landmarks], new_index[upper])


def _row_neighbour(uv: np.ndarray, keep: np.ndarray, v: int, step: int) -> int:
    """The kept vertex in the same grid column as v, one row up (step +1) or down (-1)."""
    column = np.flatnonzero(keep & np.isclose(uv[:, 0], uv[v, 0]))
    rows = uv[column, 1]
    ahead = column[(rows - uv[v, 1]) * step > 1e-12]
    return int(ahead[np.argmin(np.abs(uv[ahead, 1] - uv[v, 1]))])


def mouth_opened_to(fraction: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """(neutral, opened): the demo performer's 68 points (cm, (68, 3) float64) at rest and
    with its jaw open (its ``jawOpen`` shape, bisected on the weight) until its inner lip
    centres are `fraction` of its mouth width apart: the source of issue 13's figure."""
    performer = sample_face(1, identity=DEMO_PERFORMER)
    neutral = performer.vertices[performer.landmarks68]
    jaw = performer.expressions[list(performer.expression_names).index("jawOpen")][performer.landmarks68]
    width = np.linalg.norm(neutral[54] - neutral[48])
    lo, hi = 0.0, 4.0
    for _ in range(60):
        w = 0.5 * (lo + hi)
        gap = np.linalg.norm((neutral[62] + w * jaw[62]) - (neutral[66] + w * jaw[66]))
        lo, hi = (w, hi) if gap < fraction * width else (lo, w)
    return neutral, neutral + w * jaw


def copies_of(copies: np.ndarray, originals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How a mouth cut's copies (K, 3) lie by the line's vertices (K, 3) they copy (a hair
    below each: `retarget.lips.CUT_GAP`): (K,) each copy's nearest original, and (K,)
    the distance to it (mesh units)."""
    d = np.linalg.norm(np.asarray(copies, np.float64)[:, None] - np.asarray(originals, np.float64)[None], axis=2)
    return d.argmin(1), d.min(1)
