"""Triangle winding made consistent and outward (`retarget.winding`), which the zero-click
landmark finder's pictures need (a face wound inward reads as a dark silhouette)."""

from __future__ import annotations

import numpy as np
import trimesh

from retarget.sample_face import sample_face
from retarget.winding import outward_faces


def same_turn(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(F,) bool: each triangle of a (F, 3) is b's (F, 3) same row in the same cyclic order."""
    return np.any([np.all(np.roll(a, k, axis=1) == b, axis=1) for k in range(3)], axis=0)


def test_a_face_wound_inward_or_mixed_comes_back_outward():
    face = sample_face(1)
    f = np.asarray(face.faces, np.int64)
    rng = np.random.default_rng(0)
    mixed = f.copy()
    flip = rng.random(len(f)) < 0.2
    mixed[flip] = mixed[flip][:, ::-1]
    for given in (f[:, ::-1], mixed):
        out = outward_faces(face.vertices, given)
        assert same_turn(out, f).all()
        # only corners are swapped: each row keeps its triangle
        assert (np.sort(out, axis=1) == np.sort(given, axis=1)).all()
    # an outward face comes back as it was
    assert np.array_equal(outward_faces(face.vertices, f), f)
    # a triangle soup (an STL's: each triangle its own corners) wound inward: corners at
    # one place are one vertex, so the triangles still make one surface to turn
    soup = np.asarray(face.vertices)[f].reshape(-1, 3)
    own = np.arange(len(soup)).reshape(-1, 3)
    assert same_turn(outward_faces(soup, own[:, ::-1]), own).all()


def test_a_triangle_listed_twice_does_not_cut_the_surface():
    # 2000 triangles listed again (one of them wound the other way): every edge round
    # them is shared by three or four triangles, which cut the face into patches, and the
    # patches' own centroids turned 480 triangles inward
    face = sample_face(1)
    f = np.asarray(face.faces, np.int64)
    again = f[:2000].copy()
    again[0] = again[0, ::-1]
    listed = np.vstack([f, again])
    out = outward_faces(face.vertices, listed)
    assert same_turn(out, np.vstack([f, f[:2000]])).all()


def test_each_part_is_turned_outward_on_its_own():
    outer = trimesh.creation.icosphere(subdivisions=3, radius=5.0)
    inner = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    vertices = np.vstack([outer.vertices, inner.vertices + [8.0, 0.0, 0.0]])
    faces = np.vstack([outer.faces[:, ::-1], inner.faces + len(outer.vertices)])   # the first inward
    out = outward_faces(vertices, faces)
    assert same_turn(out, np.vstack([outer.faces, inner.faces + len(outer.vertices)])).all()
    assert outward_faces(vertices, np.zeros((0, 3), np.int64)).shape == (0, 3)


def test_an_edge_shared_by_three_triangles_does_not_break_the_walk():
    # two outward triangles and a fin on their shared edge, wound the other way
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.2], [0.5, 0.5, 1.0]], float)
    faces = np.array([[0, 1, 2], [1, 3, 2], [1, 2, 4]])
    out = outward_faces(vertices, faces)
    assert out.shape == faces.shape
    assert (np.sort(out, axis=1) == np.sort(faces, axis=1)).all()
