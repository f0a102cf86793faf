"""The built-in procedural face: a valid, human-sized, symmetric mesh with working shapes."""

import numpy as np
import pytest
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from retarget.errors import RetargetError
from retarget.sample_face import (
    EXPRESSION_NAMES,
    SampleFace,
    demo_weights,
    posed_vertices,
    sample_face,
)

REQUIRED = (
    "jawOpen", "mouthSmile_L", "mouthSmile_R", "mouthPucker", "browInnerUp", "browOuterUp_L",
    "browOuterUp_R", "eyeBlink_L", "eyeBlink_R", "mouthFrown_L", "mouthFrown_R", "cheekPuff",
)
# Multi-PIE 68: the subject's right side (-x), the midline, and the mirror pairs.
RIGHT = [*range(0, 8), *range(17, 22), 31, 32, *range(36, 42), 48, 49, 50, 58, 59, 60, 61, 67]
MIDLINE = [8, 27, 28, 29, 30, 33, 51, 57, 62, 66]
PAIRS = [(k, 16 - k) for k in range(8)] + [(17 + k, 26 - k) for k in range(5)] + [
    (31, 35), (32, 34), (36, 45), (37, 44), (38, 43), (39, 42), (40, 47), (41, 46),
    (48, 54), (49, 53), (50, 52), (55, 59), (56, 58), (60, 64), (61, 63), (65, 67)]


@pytest.fixture(scope="module")
def face():
    return sample_face()


def _pose(face, **weights):
    w = np.zeros(len(face.expression_names))
    for name, value in weights.items():
        w[face.expression_names.index(name)] = value
    return posed_vertices(face, w)


def _edges(faces):
    """(K, 2) unique undirected edges and how many triangles use each."""
    e = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    return np.unique(e, axis=0, return_counts=True)


def _edge_graph(v, faces):
    e, _ = _edges(faces)
    w = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    g = coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(v), len(v)))
    return (g + g.T).tocsr()


def test_arrays_have_the_documented_shapes_and_dtypes(face):
    v, f = face.vertices, face.faces
    assert isinstance(face, SampleFace)
    assert v.ndim == 2 and v.shape[1] == 3 and v.dtype == np.float64
    assert f.ndim == 2 and f.shape[1] == 3 and f.dtype == np.int64
    assert face.uv.shape == (len(v), 2) and face.uv.dtype == np.float64
    assert face.uv.min() >= 0.0 and face.uv.max() <= 1.0
    assert face.landmarks68.shape == (68,) and face.landmarks68.dtype == np.int64
    assert isinstance(face.expression_names, tuple) and set(REQUIRED) <= set(face.expression_names)
    assert face.expression_names == EXPRESSION_NAMES
    assert face.expressions.shape == (len(face.expression_names), len(v), 3)
    assert face.expressions.dtype == np.float64
    assert np.isfinite(v).all() and np.isfinite(face.expressions).all()
    assert 5_000 <= len(v) <= 15_000


def test_landmarks_are_68_distinct_vertices(face):
    lm = face.landmarks68
    assert len(np.unique(lm)) == 68
    assert lm.min() >= 0 and lm.max() < len(face.vertices)


def test_mesh_is_one_connected_manifold_with_consistent_winding(face):
    v, f = face.vertices, face.faces
    assert f.min() >= 0 and f.max() < len(v)
    assert len(np.unique(f)) == len(v)                      # every vertex is used
    edges, count = _edges(f)
    assert count.max() <= 2                                  # manifold edges
    boundary = edges[count == 1]
    assert np.bincount(boundary.ravel(), minlength=len(v)).max() <= 2   # no pinched vertices
    n_parts, _ = connected_components(_edge_graph(v, f), directed=False)
    assert n_parts == 1
    mesh = trimesh.Trimesh(v, f, process=False)
    assert mesh.is_winding_consistent


def test_no_degenerate_triangles_and_no_duplicate_positions(face):
    v, f = face.vertices, face.faces
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    assert area.min() > 1e-4                                 # cm^2
    d, _ = cKDTree(v).query(v, k=2)
    assert d[:, 1].min() > 1e-4                              # cm
    merged = trimesh.Trimesh(v, f)                           # loaders that merge keep the count
    assert len(merged.vertices) == len(v)


def test_normals_point_out_of_the_face(face):
    v, f = face.vertices, face.faces
    n = trimesh.Trimesh(v, f, process=False).face_normals
    centre = v[f].mean(axis=1)
    front = (np.abs(centre[:, 0]) < 4.0) & (centre[:, 2] > 6.0)
    assert front.sum() > 1000 and (n[front, 2] > 0).mean() > 0.97
    inside = np.array([0.0, 1.0, 0.0])                       # a point inside the head
    assert np.all(np.einsum("ij,ij->i", centre - inside, n) > 0)


def test_mouth_slit_is_a_cut_between_the_lip_sheets(face):
    v, f, lm = face.vertices, face.faces, face.landmarks68
    edges, count = _edges(f)
    on_boundary = np.zeros(len(v), bool)
    on_boundary[edges[count == 1].ravel()] = True
    assert on_boundary[lm[[60, 61, 62, 63, 64, 65, 66, 67]]].all()
    dist = dijkstra(_edge_graph(v, f), indices=lm[[61, 62, 63]])
    for row, up in enumerate((61, 62, 63)):
        for low in (65, 66, 67):
            gap = np.linalg.norm(v[lm[up]] - v[lm[low]])
            round_corner = min(np.linalg.norm(v[lm[up]] - v[lm[c]]) + np.linalg.norm(v[lm[c]] - v[lm[low]])
                               for c in (60, 64))
            assert dist[row, lm[low]] > 0.9 * round_corner
            if up + low == 128:                              # facing pairs 61-67, 62-66, 63-65
                assert dist[row, lm[low]] > 10 * gap
    # The boundary loop through the lips is the mouth alone: it holds both corners and stays small.
    b = edges[count == 1]
    g = coo_matrix((np.ones(len(b)), (b[:, 0], b[:, 1])), shape=(len(v), len(v)))
    _, label = connected_components(g + g.T, directed=False)
    loop = np.flatnonzero(label == label[lm[62]])
    assert set(lm[[60, 64, 66]]) <= set(loop)
    assert np.linalg.norm(v[loop] - v[lm[62]], axis=1).max() < 4.0


def test_jaw_open_parts_the_lips_and_leaves_the_brows(face):
    v, lm = face.vertices, face.landmarks68
    posed = _pose(face, jawOpen=1.0)
    before = np.linalg.norm(v[lm[62]] - v[lm[66]])
    after = np.linalg.norm(posed[lm[62]] - posed[lm[66]])
    assert after - before > 1.0
    assert np.linalg.norm(posed[lm[17:27]] - v[lm[17:27]], axis=1).max() < 0.05
    assert v[lm[8], 1] - posed[lm[8], 1] > 1.5               # the chin drops


@pytest.mark.parametrize("side, pairs, other", [
    ("L", [(43, 47), (44, 46)], [(37, 41), (38, 40)]),
    ("R", [(37, 41), (38, 40)], [(43, 47), (44, 46)]),
])
def test_blink_closes_its_own_eye_only(face, side, pairs, other):
    v, lm = face.vertices, face.landmarks68
    posed = _pose(face, **{f"eyeBlink_{side}": 1.0})
    for a, b in pairs:
        open_ = np.linalg.norm(v[lm[a]] - v[lm[b]])
        assert 0.6 < open_ < 1.3
        assert np.linalg.norm(posed[lm[a]] - posed[lm[b]]) < 0.15 * open_
    for a, b in other:
        assert np.allclose(posed[lm[[a, b]]], v[lm[[a, b]]], atol=1e-6)


def test_sizes_are_those_of_a_human_face(face):
    p = face.vertices[face.landmarks68]
    assert 8.0 < np.linalg.norm(p[36] - p[45]) < 10.0      # outer eye corners
    assert 4.5 < np.linalg.norm(p[48] - p[54]) < 6.0       # mouth corners
    assert 10.0 < np.linalg.norm(p[27] - p[8]) < 12.5      # nasion to chin
    assert 2.8 < np.linalg.norm(p[39] - p[42]) < 4.2       # inner eye corners
    assert np.argmax(p[:, 2]) == 30                          # the nose tip leads
    assert p[30, 2] - p[[39, 42], 2].mean() > 2.0            # and protrudes


def test_landmarks_sit_on_their_side_and_in_vertical_order(face):
    p = face.vertices[face.landmarks68]
    assert np.all(p[RIGHT, 0] < -0.2)
    assert np.all(p[[16 - k for k in range(8)] + [26, 25, 24, 23, 22, 35, 34, 45, 44, 43, 42, 47, 46,
                                                  54, 53, 52, 56, 55, 64, 63, 65], 0] > 0.2)
    assert np.allclose(p[MIDLINE, 0], 0.0, atol=1e-9)
    y = {k: p[v, 1].mean() for k, v in {"brow": range(17, 27), "eye": range(36, 48), "tip": [30],
                                        "mouth": range(60, 68), "chin": [8]}.items()}
    assert y["brow"] > y["eye"] > y["tip"] > y["mouth"] > y["chin"]
    assert p[51, 1] > p[62, 1] > p[66, 1] > p[57, 1]         # outer and inner lips stack


def test_face_is_mirror_symmetric_and_L_R_shapes_mirror(face):
    v, lm = face.vertices, face.landmarks68
    mirror = np.array([-1.0, 1.0, 1.0])
    d, _ = cKDTree(v).query(v * mirror)
    assert d.max() < 1e-6
    for a, b in PAIRS:
        assert np.allclose(v[lm[a]] * mirror, v[lm[b]], atol=1e-6)
    for left, right in [("mouthSmile_L", "mouthSmile_R"), ("eyeBlink_L", "eyeBlink_R"),
                        ("browOuterUp_L", "browOuterUp_R"), ("mouthFrown_L", "mouthFrown_R")]:
        d, _ = cKDTree(_pose(face, **{right: 1.0})).query(_pose(face, **{left: 1.0}) * mirror)
        assert d.max() < 1e-6


def test_left_shapes_act_on_plus_x(face):
    v, lm = face.vertices, face.landmarks68
    smile = _pose(face, mouthSmile_L=1.0)
    assert smile[lm[54], 1] - v[lm[54], 1] > 0.3 and abs(smile[lm[48], 1] - v[lm[48], 1]) < 0.05
    frown = _pose(face, mouthFrown_L=1.0)
    assert v[lm[54], 1] - frown[lm[54], 1] > 0.3
    brow = _pose(face, browOuterUp_L=1.0)
    assert brow[lm[26], 1] - v[lm[26], 1] > 0.3 and abs(brow[lm[17], 1] - v[lm[17], 1]) < 0.05
    for name in ("mouthSmile_L", "eyeBlink_L", "browOuterUp_L", "mouthFrown_L"):
        moved = np.linalg.norm(face.expressions[face.expression_names.index(name)], axis=1) > 1e-2
        assert np.all(v[moved, 0] > -0.5)


def test_every_shape_moves_the_face_by_a_plausible_amount(face):
    largest = np.linalg.norm(face.expressions, axis=2).max(axis=1)
    assert np.all(largest > 0.4) and np.all(largest < 5.0)
    lm = face.landmarks68
    pucker = _pose(face, mouthPucker=1.0)
    assert np.linalg.norm(pucker[lm[48]] - pucker[lm[54]]) < np.linalg.norm(
        face.vertices[lm[48]] - face.vertices[lm[54]]) - 0.5
    puff = _pose(face, cheekPuff=1.0)
    cheek = np.argmin(np.linalg.norm(face.vertices - (face.vertices[lm[48]] + [-1.0, 0.5, 0.0]), axis=1))
    assert np.dot(puff[cheek] - face.vertices[cheek], face.vertices[cheek] - [0.0, 1.0, 0.0]) > 0
    raised = _pose(face, browInnerUp=1.0)
    assert np.all(raised[lm[[21, 22]], 1] - face.vertices[lm[[21, 22]], 1] > 0.3)


def test_expressions_keep_the_mesh_unfolded(face):
    v, f = face.vertices, face.faces
    inside = np.array([0.0, 1.0, 0.0])
    for k in range(len(face.expression_names)):
        w = v + face.expressions[k]
        n = np.cross(w[f[:, 1]] - w[f[:, 0]], w[f[:, 2]] - w[f[:, 0]])
        assert np.all(np.einsum("ij,ij->i", w[f].mean(axis=1) - inside, n) > 0), face.expression_names[k]


def test_identities_differ_in_shape_but_share_the_topology(face):
    other = sample_face(identity=[1.5, -1.2, 1.0, 1.2, -1.0])
    assert other.vertices.shape == face.vertices.shape
    assert np.array_equal(other.faces, face.faces)
    assert np.array_equal(other.landmarks68, face.landmarks68)
    assert other.expression_names == face.expression_names
    assert np.linalg.norm(other.vertices - face.vertices, axis=1).max() > 0.5
    p, q = face.vertices[face.landmarks68], other.vertices[other.landmarks68]
    assert abs(np.linalg.norm(q[0] - q[16]) - np.linalg.norm(p[0] - p[16])) > 0.3   # face width
    assert np.linalg.norm(q[39] - q[42]) < np.linalg.norm(p[39] - p[42]) - 0.2     # eye spacing
    assert q[30, 1] > p[30, 1] + 0.1                                               # shorter nose
    # Same weights, corresponding motion: jawOpen parts both mouths.
    gap = np.linalg.norm(_pose(other, jawOpen=1.0)[other.landmarks68[[62]]]
                         - _pose(other, jawOpen=1.0)[other.landmarks68[[66]]])
    assert gap > 1.0
    assert trimesh.Trimesh(other.vertices, other.faces, process=False).is_winding_consistent


def test_resolution_scales_the_vertex_count_and_keeps_the_landmarks(face):
    fine = sample_face(resolution=2)
    assert 3.0 < len(fine.vertices) / len(face.vertices) < 5.0
    moved = np.linalg.norm(fine.vertices[fine.landmarks68] - face.vertices[face.landmarks68], axis=1)
    assert moved.max() < 0.35                                # same anatomical spots


def test_demo_weights_are_a_smooth_loop_that_shows_every_shape():
    w = demo_weights(300)                                    # 10 s at 30 fps
    assert w.shape == (300, len(EXPRESSION_NAMES)) and w.dtype == np.float64
    assert w.min() >= 0.0 and w.max() <= 1.0
    assert np.all(w.max(axis=0) > 0.5)
    assert np.abs(np.diff(w, axis=0)).max() < 0.4           # even blinks take several frames
    assert np.allclose(demo_weights(600)[300:], w)           # it loops every 10 s
    assert np.allclose(demo_weights(100, fps=10.0), w[::3])  # fps only resamples the timeline
    assert (w[:, EXPRESSION_NAMES.index("jawOpen")] > 0.05).mean() > 0.2   # talking, not a pose
    assert demo_weights(0).shape == (0, len(EXPRESSION_NAMES))


def test_posed_vertices_is_the_linear_blend(face):
    e = len(face.expression_names)
    assert np.array_equal(posed_vertices(face, np.zeros(e)), face.vertices)
    w = demo_weights(5)
    frames = posed_vertices(face, w)
    assert frames.shape == (5, len(face.vertices), 3)
    assert np.allclose(frames[3], face.vertices + np.einsum("e,evd->vd", w[3], face.expressions))
    with pytest.raises(RetargetError, match="weights"):
        posed_vertices(face, np.zeros(e + 1))
    with pytest.raises(RetargetError, match="weights"):
        posed_vertices(face, np.full(e, np.nan))


@pytest.mark.parametrize("kwargs", [
    {"resolution": 0}, {"resolution": 1.5}, {"resolution": True},
    {"identity": np.zeros(9)}, {"identity": [np.nan]}, {"identity": np.zeros((2, 2))},
])
def test_bad_arguments_are_refused(kwargs):
    with pytest.raises(RetargetError, match=next(iter(kwargs))):
        sample_face(**kwargs)


def test_bad_demo_arguments_are_refused():
    with pytest.raises(RetargetError, match="n_frames"):
        demo_weights(-1)
    with pytest.raises(RetargetError, match="fps"):
        demo_weights(10, fps=0.0)


def test_the_demo_performance_in_any_layout():
    from retarget.layouts import get_layout
    from retarget.sample_face import demo_performance, demo_points

    neutral68, frames68 = demo_performance(30.0, n_frames=90)
    short = get_layout("dutreve22")
    neutral, frames = demo_points(short, 30.0, n_frames=90)
    assert np.array_equal(neutral, neutral68[list(short.ibug68)])
    assert np.array_equal(frames, frames68[:, list(short.ibug68)])
    # the dense layout: the performer's 468 face-mesh points, found with no clicks
    dense = get_layout("mediapipe468")
    neutral, frames = demo_points(dense, 30.0, n_frames=90)
    assert neutral.shape == (468, 3) and frames.shape == (90, 468, 3)
    rows = [i for i, k in enumerate(dense.ibug68) if 17 <= k]      # inner iBUG points
    inner = [dense.ibug68[i] for i in rows]
    # raw face-mesh vertices, not moved to iBUG's meaning (bench/landmarks.py: ~5 mm)
    assert np.median(np.linalg.norm(neutral[rows] - neutral68[inner], axis=1)) < 0.6   # cm
    # they perform what the 68 perform: the same motion at the same iBUG points
    motion, motion68 = frames[:, rows] - neutral[rows], frames68[:, inner] - neutral68[inner]
    assert np.corrcoef(motion.ravel(), motion68.ravel())[0, 1] > 0.9
