"""The ``dutreve22`` layout (the web app's default for new projects): Dutreve's 21 points and
the chin, one more click with Mirror, and a jaw that follows an open mouth. On the built-in
face with its lips welded and cut open (`retarget.lips`), a performer opening the mouth
to 30 % of its width moves the target's chin about as far as its own with ``dutreve22``,
and under half as far with ``dutreve21``, which has no chin point."""

from __future__ import annotations

import numpy as np
import pytest

from retarget.landmarks import from_vertex_indices
from retarget.layouts import LAYOUTS, get_layout
from retarget.lips import opened_mouth
from retarget.mesh import mesh_from_arrays
from retarget.pipeline import Retargeter
from retarget.skin import skin_displacements
from retarget.testing.welded import mouth_opened_to, welded_lips_face
from retarget.weights import compute_weights

CHIN = 8  # iBUG


def test_dutreve22_is_dutreve21_and_the_chin():
    d21, d22 = get_layout("dutreve21"), get_layout("dutreve22")
    assert list(LAYOUTS).index("dutreve22") == list(LAYOUTS).index("dutreve21") + 1
    assert d22.n_points == 22 and d22.point_names[:21] == d21.point_names
    assert d22.ibug68[21] == CHIN and d22.point_names[21] == "chin"
    assert d22.regions[21] == "jaw" and d22.sides[21] == "center" and d22.mirror[21] == 21

    def clicks(layout):  # Mirror places the partner of every left/right pair
        return sum(1 for i, m in enumerate(layout.mirror) if m >= i)

    assert clicks(d21) == 12 and clicks(d22) == 13 and clicks(get_layout("ibug68")) == 39


def _chin_motion(layout_name: str) -> tuple[float, float]:
    """(target chin displacement, performer chin displacement), cm, on the opened welded
    face with the performer's jaw open until its inner lips are 30 % of its mouth width
    apart."""
    layout = get_layout(layout_name)
    idx = np.array(layout.ibug68)
    face = welded_lips_face(1)
    mesh = mesh_from_arrays(face.vertices, face.faces, uv=face.uv)
    points = from_vertex_indices(face.landmarks68[idx], mesh.n_vertices, layout_name)
    opened = opened_mouth(mesh, points, layout)
    neutral, frame = mouth_opened_to(0.3)
    weights = compute_weights("biharmonic", opened.mesh.vertices, opened.mesh.faces,
                              opened.points, layout)
    retargeter = Retargeter().fit(neutral[idx], opened.points.positions(opened.mesh.vertices))
    d = retargeter.displacements(frame[idx][None])[0]
    moved = skin_displacements(weights, d[None])[0]
    return float(np.linalg.norm(moved[face.landmarks68[CHIN]])), float(np.linalg.norm(frame[CHIN] - neutral[CHIN]))


@pytest.mark.parametrize("name, least, most", [("dutreve22", 0.8, 1.3), ("dutreve21", 0.0, 0.5)])
def test_the_chin_follows_an_open_mouth_only_with_a_chin_point(name, least, most):
    target, source = _chin_motion(name)
    assert least * source < target < most * source, (name, target, source)
