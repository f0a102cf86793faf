"""Target landmarks as surface points: vertex indices, positions, barycentric JSON."""

import json

import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.landmarks import from_positions, from_vertex_indices, landmarks_from_json, load_landmarks
from retarget.sample_face import sample_face


@pytest.fixture(scope="module")
def face():
    return sample_face()


def test_vertex_landmarks_sit_on_their_vertices_and_follow_the_mesh(face):
    pts = from_vertex_indices(face.landmarks68, len(face.vertices), "ibug68")
    np.testing.assert_array_equal(pts.positions(face.vertices), face.vertices[face.landmarks68])
    moved = face.vertices + face.expressions[0]
    np.testing.assert_allclose(pts.positions(moved), moved[face.landmarks68])
    assert pts.to_json() == {"vertex_indices": face.landmarks68.tolist(), "layout": "ibug68"}


def test_positions_snap_to_the_surface_and_round_trip_through_json(face):
    v, f = face.vertices, face.faces
    tri = f[[100, 2000, 5000]]
    on_surface = v[tri].mean(axis=1)  # triangle centroids
    pts = from_positions(on_surface + 1e-9, v, f)
    np.testing.assert_allclose(pts.positions(v), on_surface, atol=1e-6)
    back = landmarks_from_json(json.loads(json.dumps(pts.to_json())), v, f)
    np.testing.assert_allclose(back.positions(v), on_surface, atol=1e-6)


@pytest.mark.parametrize("data,message", [
    ({"vertex_indices": [1, 2, 99999999]}, r"vertex_indices\[2\] = 99999999 is not a vertex"),
    ({"vertex_indices": [5, 6, 5]}, "repeats vertex 5 \\(points 0 and 2\\)"),
    ({"vertex_indices": []}, "non-empty list of integers"),
    ({"vertex_indices": [1.5, 2]}, "non-empty list of integers"),
    ({"positions": [[0, 0, np.nan]]}, "NaN or inf"),
    ({"positions": [[0, 0, 20.0], [0, 0, 20.0]]}, "sit on the same surface point"),
    ({"triangles": [[0, 1, 2]], "barycentric": [[0.5, 0.6, 0.1]]}, "sum to 1"),
    ({"points": []}, "needs 'vertex_indices', 'positions' or 'triangles'"),
    ([1, 2, 3], "must be an object"),
])
def test_bad_landmarks_are_refused_with_a_reason(face, data, message):
    with pytest.raises(RetargetError, match=message):
        landmarks_from_json(data, face.vertices, face.faces)


def test_unreadable_file_is_refused(face, tmp_path):
    (tmp_path / "t0.json").write_text("{not json")
    with pytest.raises(RetargetError, match="could not read landmarks JSON"):
        load_landmarks(tmp_path / "t0.json", face.vertices, face.faces)
