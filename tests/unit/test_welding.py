"""Vertices at one position are one surface point for the rig (`retarget.welding`): a UV
seam (glTF splits a vertex wherever its uv changes) or an STL's triangle soup no longer
cuts the face into pieces rigged on their own."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from retarget.landmarks import from_vertex_indices
from retarget.layouts import get_layout
from retarget.mesh import load_mesh
from retarget.sample_face import sample_face
from retarget.testing.seams import seam_split
from retarget.weights import compute_weights
from retarget.welding import welded

IBUG = get_layout("ibug68")


@pytest.fixture(scope="module")
def face():
    f = sample_face(1)
    return np.asarray(f.vertices, np.float64), np.asarray(f.faces, np.int64), np.asarray(f.landmarks68)


def test_a_soup_welds_back_into_the_indexed_mesh(face):
    vertices, faces, _ = face
    soup = vertices[faces].reshape(-1, 3)
    weld = welded(soup, np.arange(len(soup)).reshape(-1, 3))
    assert weld.any and len(weld.vertices) == len(np.unique(faces))
    # the welded vertices in the order first met; every copy points at its position
    np.testing.assert_array_equal(weld.vertices[weld.index], soup)
    assert (np.diff(weld.index[np.unique(weld.index, return_index=True)[1]]) > 0).all()
    assert len(weld.faces) == len(faces)
    # a triangle whose corners weld into one point is dropped; a mesh without copies is kept
    sliver = welded(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0]], float), [[0, 1, 2], [0, 1, 3]])
    np.testing.assert_array_equal(sliver.faces, [[0, 1, 2]])
    assert not welded(vertices, faces).any


def test_a_uv_seam_does_not_tear_the_rig(face):
    vertices, faces, landmarks = face
    split, split_faces, seam, copies = seam_split(vertices, faces, x=1.5)   # through the left cheek
    points = from_vertex_indices(landmarks, len(split), "ibug68")
    for method in ("biharmonic", "geodesic", "laplacian"):
        w = compute_weights(method, split, split_faces, points, IBUG).dense()
        # a jaw drop of 10 mm: the two sides of the seam move as one (it tore 6.9 mm open
        # with the biharmonic rig built on the split connectivity)
        drop = np.zeros((IBUG.n_points, 3))
        drop[np.isin(IBUG.regions, ("jaw", "lower_lip")), 1] = -1.0
        moved = w @ drop
        assert np.abs(moved[seam] - moved[copies]).max() < 1e-6, method
        # and the rig is the one of the mesh without the seam
        whole = compute_weights(method, vertices, faces, from_vertex_indices(landmarks, len(vertices), "ibug68"),
                                IBUG).dense()
        np.testing.assert_allclose(w[: len(vertices)], whole, atol=1e-5, err_msg=method)


def test_an_stl_face_is_rigged_as_one_surface(face, tmp_path):
    vertices, faces, landmarks = face
    trimesh.Trimesh(vertices, faces, process=False).export(tmp_path / "face.stl")
    mesh = load_mesh(tmp_path / "face.stl")
    assert mesh.n_vertices == 3 * len(faces)   # STL stores each triangle's own corners
    # the landmarks on the soup's copies of the iBUG vertices
    first = {tuple(p): i for i, p in reversed(list(enumerate(mesh.vertices.tolist())))}
    on_soup = np.array([first[tuple(vertices[i].astype(np.float32).astype(np.float64).tolist())]
                        for i in landmarks])
    w = compute_weights("biharmonic", mesh.vertices, mesh.faces,
                        from_vertex_indices(on_soup, mesh.n_vertices, "ibug68"), IBUG).dense()
    # before: 99.9 % of the soup's vertices had no weight at all (each triangle a surface)
    assert np.median(w.sum(1)) > 0.1
    # and each corner has the weights of its vertex in the indexed mesh
    whole = compute_weights("biharmonic", vertices, faces, from_vertex_indices(landmarks, len(vertices), "ibug68"),
                            IBUG).dense()
    np.testing.assert_allclose(w, whole[faces.ravel()], atol=1e-3)
