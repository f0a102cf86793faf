"""Target landmarks as surface points: vertex indices, positions, barycentric JSON."""

import json
import tracemalloc

import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.landmarks import (
    MAX_LANDMARKS,
    from_barycentric,
    from_positions,
    from_vertex_indices,
    landmarks_from_json,
    load_landmarks,
)
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


def test_the_landmark_cap_fits_the_largest_layout():
    assert 468 <= MAX_LANDMARKS <= 4096  # MediaPipe's face mesh is the largest layout


@pytest.mark.parametrize("kind", ["vertex_indices", "positions", "triangles"])
def test_landmark_count_is_capped_in_every_constructor(face, kind):
    k = MAX_LANDMARKS + 1
    rows = np.arange(k) % len(face.faces)
    data = {
        "vertex_indices": {"vertex_indices": list(range(k))},
        "positions": {"positions": face.vertices[face.faces[rows, 0]].tolist()},
        "triangles": {"triangles": face.faces[rows].tolist(),
                      "barycentric": [[1 / 3, 1 / 3, 1 / 3]] * k},
    }[kind]
    message = rf"{kind} holds {k:,} landmarks, above the limit of {MAX_LANDMARKS:,}"
    with pytest.raises(RetargetError, match=message):
        landmarks_from_json(data, face.vertices, face.faces)


def test_constructors_refuse_over_the_cap_directly(face):
    k = MAX_LANDMARKS + 1
    with pytest.raises(RetargetError, match=r"above the limit"):
        from_vertex_indices(np.arange(k), len(face.vertices))
    with pytest.raises(RetargetError, match=r"above the limit"):
        from_positions(np.zeros((k, 3)), face.vertices, face.faces)
    with pytest.raises(RetargetError, match=r"above the limit"):
        from_barycentric(np.zeros((k, 3), int), np.full((k, 3), 1 / 3), len(face.vertices))


def test_position_repeats_are_found_without_a_distance_matrix(face):
    # MAX_LANDMARKS points on the surface, the last two on one spot: a K x K distance
    # matrix (2048^2 float64) alone is 32 MiB, so a small peak shows it is not built
    rows = np.linspace(0, len(face.faces) - 1, MAX_LANDMARKS).astype(int)
    points = face.vertices[face.faces[rows]].mean(axis=1)
    points[-1] = points[-2]
    tracemalloc.start()
    try:
        with pytest.raises(RetargetError, match=rf"landmarks {MAX_LANDMARKS - 2} and "
                           rf"{MAX_LANDMARKS - 1} sit on the same surface point"):
            from_positions(points, face.vertices, face.faces)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 16 * 2**20


@pytest.mark.parametrize("layout, shown", [
    (0, "0"), (False, "false"), ([], r"\[\]"), ({"name": "ibug68"}, r"\{\"name\": \"ibug68\"\}"),
])
def test_layout_must_be_a_string_or_null(face, layout, shown):
    data = {"vertex_indices": [1, 2, 3], "layout": layout}
    message = rf"landmarks JSON 'layout' must be a string or null, got {shown}"
    with pytest.raises(RetargetError, match=message):
        landmarks_from_json(data, face.vertices, face.faces)


def test_null_or_missing_layout_is_no_layout(face):
    for data in ({"vertex_indices": [1, 2, 3], "layout": None}, {"vertex_indices": [1, 2, 3]}):
        assert landmarks_from_json(data, face.vertices, face.faces).layout == ""
    data = {"vertex_indices": [1, 2, 3], "layout": "ibug68"}
    assert landmarks_from_json(data, face.vertices, face.faces).layout == "ibug68"
