"""Skin weights of every deformer on the built-in face (no external data)."""

import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.landmarks import from_vertex_indices
from retarget.layouts import get_layout
from retarget.operators import boundary_vertices
from retarget.sample_face import sample_face
from retarget.skin import skin_displacements
from retarget.weights import METHODS, compute_weights
from retarget.weights.geodesic import geodesic_distances


@pytest.fixture(scope="module")
def face():
    f = sample_face()
    layout = get_layout("ibug51")
    idx = f.landmarks68[17:]
    return f, layout, from_vertex_indices(idx, len(f.vertices), layout.name)


@pytest.fixture(scope="module")
def all_weights(face):
    f, layout, pts = face
    return {m: compute_weights(m, f.vertices, f.faces, pts, layout) for m in METHODS}


def _lip_vertices(f, layout, pts):
    """Upper- and lower-lip boundary vertices of the mouth slit away from the corners."""
    v = f.vertices
    boundary = boundary_vertices(f.faces, len(v))
    corners = v[pts.nearest_vertices()[layout.region_mask("mouth_corners")]]
    x_min, x_max = np.sort(corners[:, 0])[[0, -1]]
    y_mouth = corners[:, 1].mean()
    inner = (v[:, 0] > x_min + 0.6) & (v[:, 0] < x_max - 0.6) & (np.abs(v[:, 1] - y_mouth) < 1.0) & boundary
    # Which sheet a slit vertex is on: nearer the upper or the lower inner-lip centre along
    # the surface (in space the two sheets touch).
    g = geodesic_distances(v, f.faces, pts)
    closer_up = g[layout.index("lip_upper_inner_center")] < g[layout.index("lip_lower_inner_center")]
    return np.flatnonzero(inner & closer_up), np.flatnonzero(inner & ~closer_up)


@pytest.mark.parametrize("method", list(METHODS))
def test_every_method_gives_a_bounded_rig_that_follows_its_features(face, all_weights, method):
    f, layout, pts = face
    sk = all_weights[method]
    assert sk.n_vertices == len(f.vertices) and sk.n_joints == pts.n_points
    assert np.isfinite(sk.weights).all()
    sums = sk.row_sums()
    if method in ("ellipsoid", "geodesic"):
        assert sums.max() < 1.0 + 1e-5 and sums.min() >= 0.0
    else:  # interpolating deformers may overshoot a little between features
        assert -0.1 < sums.min() and sums.max() < 1.1
    # A translation of every feature moves the feature vertices with it (the rig reaches them).
    moved = skin_displacements(sk, np.tile([0.0, 1.0, 0.0], (pts.n_points, 1)))
    assert np.all(moved[pts.nearest_vertices(), 1] > 0.5)


@pytest.mark.parametrize("method", ["rbf", "biharmonic"])
def test_interpolating_deformers_reproduce_each_feature(face, all_weights, method):
    _, _, pts = face
    dense = all_weights[method].dense()[pts.nearest_vertices()]
    np.testing.assert_allclose(dense, np.eye(pts.n_points), atol=1e-3)


def test_laplacian_soft_constraints_pull_each_feature_mostly_with_its_own_joint(face, all_weights):
    _, _, pts = face  # Zhang's eq. 7 with w = 1: soft, so not exact
    dense = all_weights["laplacian"].dense()[pts.nearest_vertices()]
    assert np.diag(dense).min() > 0.7
    assert np.array_equal(dense.argmax(1), np.arange(pts.n_points))


def test_ellipsoid_rows_are_normalised_top_k_and_far_vertices_stay_still(face, all_weights):
    f, _, _ = face
    sk = all_weights["ellipsoid"]
    assert sk.n_influences == 4
    sums = sk.row_sums()
    assert np.all((np.abs(sums - 1) < 1e-5) | (sums == 0))
    back = f.vertices[:, 2] < np.percentile(f.vertices[:, 2], 5)  # the far back of the head
    assert np.all(sums[back] == 0)


def test_ellipsoids_leak_across_the_mouth_but_surface_aware_weights_do_not(face, all_weights):
    f, layout, pts = face
    upper_v, lower_v = _lip_vertices(f, layout, pts)
    assert len(upper_v) >= 3 and len(lower_v) >= 3
    lower_feats = layout.region_mask(["lower_lip", "jaw"])
    upper_feats = layout.region_mask("upper_lip")
    leak = {m: (np.abs(all_weights[m].dense()[np.ix_(upper_v, np.flatnonzero(lower_feats))]).sum(1).max(),
                np.abs(all_weights[m].dense()[np.ix_(lower_v, np.flatnonzero(upper_feats))]).sum(1).max())
            for m in ("ellipsoid", "geodesic", "biharmonic")}
    assert max(leak["ellipsoid"]) > 0.05  # the paper's Euclidean falloff crosses the slit
    assert max(leak["geodesic"]) <= 0.05
    assert max(leak["biharmonic"]) <= 0.05


def test_geodesic_distance_goes_round_the_mouth(face):
    f, layout, pts = face
    d = geodesic_distances(f.vertices, f.faces, pts)
    up, low = layout.index("lip_upper_inner_center"), layout.index("lip_lower_inner_center")
    straight = np.linalg.norm(pts.positions(f.vertices)[up] - pts.positions(f.vertices)[low])
    assert d[up, pts.nearest_vertices()[low]] > 5 * straight


def test_weights_follow_the_mesh_not_its_pose(face):
    """A rotated, scaled copy of the face gets the same ellipsoid weights (face frame, ratios);
    a handful of vertices may differ where the top-4 cut meets a near-tie."""
    f, layout, pts = face
    c, s = np.cos(0.7), np.sin(0.7)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]) @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    moved = 2.5 * f.vertices @ rot.T + [10.0, -3.0, 7.0]
    a = compute_weights("ellipsoid", f.vertices, f.faces, pts, layout).dense()
    b = compute_weights("ellipsoid", moved, f.faces, pts, layout).dense()
    same = np.abs(a - b).max(1) < 1e-4
    assert same.mean() > 0.999


def test_unknown_method_and_layoutless_region_split_are_refused(face):
    f, _, pts = face
    with pytest.raises(RetargetError, match="unknown weight method 'magic'"):
        compute_weights("magic", f.vertices, f.faces, pts)
    with pytest.raises(RetargetError, match="needs a landmark layout"):
        compute_weights("region_rbf", f.vertices, f.faces, pts)


def test_layoutless_ellipsoid_falls_back_to_spheres(face):
    f, _, pts = face
    sk = compute_weights("ellipsoid", f.vertices, f.faces, pts)
    assert sk.row_sums().max() <= 1 + 1e-6 and (sk.row_sums() > 0).sum() > pts.n_points


@pytest.fixture(scope="module")
def dense_face():
    """The sample face and its 468 face-mesh points, found with no clicks."""
    from retarget.facemesh.placement import find_face_mesh
    from retarget.mesh import mesh_from_arrays

    face = sample_face(1)
    return face, find_face_mesh(mesh_from_arrays(face.vertices, face.faces)).points


@pytest.mark.parametrize("method", sorted(METHODS))
def test_every_method_rigs_the_dense_layout(method, dense_face):
    """The dense mediapipe468 layout's regions (cheeks and forehead among them) are known to
    every method: each vertex near the face is driven, every joint drives something."""
    face, found = dense_face
    layout = get_layout("mediapipe468")
    weights = compute_weights(method, face.vertices, face.faces, found, layout).dense()
    assert weights.shape == (len(face.vertices), 468) and np.isfinite(weights).all()
    near = np.linalg.norm(face.vertices[:, None] - found.positions(face.vertices)[None], axis=2).min(1) < 0.3
    assert (np.abs(weights[near]).sum(1) > 0.5).all()
    # every joint drives something; those of the new regions clearly (close pairs of
    # points, such as the inner lips, share their vertices under the RBF methods)
    assert (np.abs(weights).max(0) > 0.02).all()
    new = np.isin(layout.regions, ("cheeks", "forehead"))
    assert (np.abs(weights[:, new]).max(0) > 0.1).all()


def test_biharmonic_separates_the_lips_of_sparse_layouts_only(face, all_weights, dense_face):
    """A sparse layout's rig holds each lip's features off the other lip; a dense one's is
    pinned by each lip's own points, and there the cells the separation would cut leave
    the weights summing to one round the mouth."""
    f, layout, pts = face
    separated = compute_weights("biharmonic", f.vertices, f.faces, pts, layout, separate_lips=True)
    np.testing.assert_array_equal(all_weights["biharmonic"].dense(), separated.dense())
    dense_f, found = dense_face
    weights = compute_weights("biharmonic", dense_f.vertices, dense_f.faces, found,
                              get_layout("mediapipe468")).dense()
    lips = get_layout("mediapipe468").region_mask(("upper_lip", "lower_lip", "mouth_corners"))
    at_lips = found.positions(dense_f.vertices)[lips]
    near = np.linalg.norm(dense_f.vertices[:, None] - at_lips[None], axis=2).min(1) < 0.5
    assert near.sum() > 50
    assert np.abs(weights[near].sum(1) - 1.0).max() < 0.005   # 0.02 separated


# -- the sparse Cholesky of the quadratic rigs (retarget/weights/cholesky.py) --------------

def _system(f, pts):
    """The biharmonic rig's system matrix and right-hand sides on the built-in face."""
    import scipy.sparse as sp

    from retarget.operators import cotmatrix, massmatrix
    from retarget.weights.quadratic import constraint_matrix

    lap, mass = cotmatrix(f.vertices, f.faces), massmatrix(f.vertices, f.faces)
    q = lap.T @ sp.diags(1.0 / mass.diagonal()) @ lap - 0.1 * lap + 0.01 * mass
    c = constraint_matrix(pts, len(f.vertices))
    w2 = 1e4 * float(np.median(q.diagonal()))
    a = (q + w2 * (c.T @ c)).tocsc()
    return a, (w2 * c.T).toarray()


def test_cholesky_solves_as_scipy_does_with_and_without_its_tail(face):
    """The multifrontal factor against SciPy's spsolve (an independent oracle), for the
    whole system and for the system without its tail unknowns."""
    from scipy.sparse.linalg import spsolve

    from retarget.weights.cholesky import cholesky

    f, _, pts = face
    a, b = _system(f, pts)
    b = b[:, :6]
    tail = f.vertices[:, 1] > np.quantile(f.vertices[:, 1], 0.9)
    factor = cholesky(a, f.vertices, tail, leaf_size=32)
    expected = spsolve(a, b)
    np.testing.assert_allclose(factor.solve(b), expected, rtol=0, atol=1e-9 * np.abs(expected).max())
    keep = ~tail
    restricted = np.zeros_like(expected)
    restricted[keep] = spsolve(a[keep][:, keep].tocsc(), b[keep])
    np.testing.assert_allclose(factor.solve(b, restricted=True), restricted, rtol=0,
                               atol=1e-9 * np.abs(restricted).max())
    np.testing.assert_allclose(factor.solve(b[:, 0]), expected[:, 0], rtol=0,
                               atol=1e-9 * np.abs(expected).max())


def test_cholesky_refuses_a_matrix_that_is_not_positive_definite(face):
    import scipy.sparse as sp

    from retarget.weights.cholesky import cholesky

    f = face[0]
    a = -sp.identity(len(f.vertices), format="csc")
    with pytest.raises(RetargetError, match="not positive definite"):
        cholesky(a, f.vertices)


@pytest.mark.parametrize("method", ["biharmonic", "laplacian"])
def test_quadratic_rigs_equal_superlu_s(method):
    """The rigs solved by the Cholesky factor equal the SuperLU path's within 1e-6 (lip
    supports included: ibug68 has lower-lip, jaw and upper-lip features)."""
    import retarget.weights.biharmonic as biharmonic
    import retarget.weights.laplacian as laplacian
    from retarget.weights.quadratic import constrained_weights

    f = sample_face()
    layout = get_layout("ibug68")
    pts = from_vertex_indices(f.landmarks68, len(f.vertices), layout.name)
    module = biharmonic if method == "biharmonic" else laplacian
    new = compute_weights(method, f.vertices, f.faces, pts, layout).dense()

    def superlu(*args, vertices=None, **kwargs):
        return constrained_weights(*args, **kwargs)

    mp = pytest.MonkeyPatch()
    mp.setattr(module, "constrained_weights", superlu)
    try:
        old = compute_weights(method, f.vertices, f.faces, pts, layout).dense()
    finally:
        mp.undo()
    assert np.abs(new - old).max() < 1e-6
