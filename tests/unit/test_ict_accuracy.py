"""Cross-identity retargeting on the ICT face model (skips when ../shared is absent).

The benchmark's own code (bench/accuracy.py) on a small expression set: the default
pipeline must beat the paper's method in every source condition, keep the lips apart, and
be blind to the performer's scale, rotation and translation.
"""

import numpy as np
import pytest

from bench.ict import DATA

pytestmark = pytest.mark.skipif(not DATA.exists(), reason="ICT data set (../shared) not present")


@pytest.fixture(scope="module")
def rows():
    from bench.accuracy import run
    from retarget.pipeline import DEFAULT_KERNEL
    from retarget.weights import DEFAULT_METHOD

    out = run(seed=3, n_random=4, methods=[DEFAULT_METHOD], kernel=DEFAULT_KERNEL,
              smoothing=None, true_motion=True)
    return {(r["setup"], r["condition"]): r for r in out}


def test_default_beats_the_paper_in_every_condition(rows):
    from retarget.weights import DEFAULT_METHOD

    for cond in ("same", "foreign", "2d"):
        ours, paper = rows[(DEFAULT_METHOD, cond)], rows[("paper", cond)]
        assert ours["rel"] < paper["rel"] - 0.08, cond
        assert ours["mouth"] < paper["mouth"], cond


def test_default_keeps_the_lips_apart_and_the_paper_does_not(rows):
    from retarget.weights import DEFAULT_METHOD

    ours, paper = rows[(DEFAULT_METHOD, "same")], rows[("paper", "same")]
    assert ours["leak_upper"] == 0.0 and ours["leak_lower"] == 0.0
    assert paper["leak_upper"] > 0.2


def test_performer_pose_and_size_do_not_matter(rows):
    from retarget.weights import DEFAULT_METHOD

    same, foreign = rows[(DEFAULT_METHOD, "same")], rows[(DEFAULT_METHOD, "foreign")]
    assert np.isclose(same["rel"], foreign["rel"], rtol=1e-4)


def test_our_transfer_adds_less_error_than_the_papers(rows):
    """Transfer error = error with transferred features minus error with the true ones."""
    from retarget.weights import DEFAULT_METHOD

    def added(setup):
        return rows[(setup, "same")]["rel"] - rows[(setup, "true")]["rel"]

    assert 0.0 <= added(DEFAULT_METHOD) < 0.8 * added("paper")


@pytest.fixture(scope="module")
def tracker():
    from retarget.facemesh.tracker import FaceMeshTracker

    return FaceMeshTracker()


def test_lip_points_found_on_two_identities_open_with_the_same_lip(tracker):
    # bench/accuracy.py seed 1's identities A and B: each lip point found on both, and how
    # far it drops when the jaw opens fully (ICT's jawOpen: 35 mm at the lower lip) on
    # each. On the lip the ray met, four upper-lip points of B and six lower-lip points of
    # A sat on the opposite lip: 4.3 mm apart on average, 25.6 at worst; on their own lips
    # 0.9 (the rest is sliding along the lip near the corners, 13 mm at worst)
    from bench.accuracy import scenario
    from retarget.facemesh.placement import LOWER_LIP, UPPER_LIP, find_face_mesh
    from retarget.mesh import mesh_from_arrays

    model, a, b, _ = scenario(1, 0)
    jaw = model.expressions[model.names.index("jawOpen")]
    lips = list(UPPER_LIP + LOWER_LIP)
    drop = [find_face_mesh(mesh_from_arrays(v, model.faces), tracker).points.positions(jaw)[lips, 1]
            for v in (a, b)]
    apart_mm = np.abs(drop[0] - drop[1]) * 10.0
    assert apart_mm.mean() < 2.0, apart_mm
    assert (apart_mm > 15.0).sum() == 0, apart_mm


@pytest.fixture(scope="module")
def dense_seed2():
    from bench.accuracy import dense_rows
    from retarget.pipeline import DEFAULT_KERNEL
    from retarget.weights import DEFAULT_METHOD

    return {(r["setup"], r["condition"]): r for r in dense_rows(2, 24, DEFAULT_METHOD, DEFAULT_KERNEL, None)}


def test_dense_points_found_with_no_clicks_retarget_within_bound(dense_seed2):
    # bench/accuracy.py --dense --seed 2: 30.3 % with the lip points where their rays fell,
    # 25.3 % on their own lips, 24.8 % with the similarity transform for dense sources
    found, matched = dense_seed2[("468 found", "same")], dense_seed2[("468 matched", "same")]
    assert found["rel"] < 0.255, found["rel"]
    assert found["mouth"] < 1.5, found["mouth"]   # mm; 1.85 before
    assert matched["rel"] < found["rel"]


def test_dense_rig_weights_sum_to_one_at_the_mouth(tracker):
    # seed 1's B rigged on A's 468 found points (the same ICT vertices) with the
    # mediapipe468 layout: the sparse layouts' lip separation cut the lips' interleaved
    # Voronoi cells near the corners, and mouth rows summed up to 2.0 off one
    from bench.accuracy import scenario
    from bench.ict import benchmark_layout, vertex_regions
    from retarget.facemesh.placement import find_face_mesh
    from retarget.layouts import get_layout
    from retarget.mesh import mesh_from_arrays
    from retarget.weights import compute_weights

    model, a, b, _ = scenario(1, 0)
    points = find_face_mesh(mesh_from_arrays(a, model.faces), tracker).points
    report, _ = vertex_regions(b, model.faces, model.feature_vertices(), benchmark_layout(),
                               model.face_count)
    w = compute_weights("biharmonic", b, model.faces, points, get_layout("mediapipe468")).dense()
    off_one = np.abs(w[: len(report)][report == "mouth"].sum(1) - 1.0)
    assert off_one.max() < 0.05, off_one.max()


def test_dense_source_motion_keeps_its_direction(dense_seed2):
    # The same ICT vertices on both faces (no placement error): the near-affine transform
    # stretched and sheared A's motion by the two faces' proportions and the lip separation
    # broke the weights near the mouth corners, 21.6 % (19.7 without the separation);
    # with the similarity transform the pipeline takes for dense 3D sources and the dense
    # layout's lips unseparated, 17.8
    assert dense_seed2[("468 matched", "same")]["rel"] < 0.185


def test_dense_transfer_is_blind_to_the_performers_pose_size_and_handedness():
    # seed 2's A driving B through the dense similarity transform: A under another scale,
    # rotation and translation, or mirrored (a left-handed tracker frame), gives B the same
    # displacements
    from bench.accuracy import scenario
    from bench.ict import foreign_frame
    from retarget.pipeline import Retargeter

    model, a, b, offsets = scenario(2, 2)
    dense = np.arange(0, 9409, 17)                    # 554 face-area vertices
    s0, s = a[dense], (a + offsets)[:, dense]
    expected = Retargeter().fit(s0, b[dense]).displacements(s)
    mirror = np.array([-1.0, 1.0, 1.0])
    for f in (foreign_frame, lambda p: foreign_frame(p * mirror)):
        got = Retargeter().fit(f(s0), b[dense]).displacements(f(s))
        np.testing.assert_allclose(got, expected, atol=1e-4 * np.abs(expected).max())
    # a flat source (one camera's points given with z = 0) keeps the RBF transform, which
    # lifts the image plane onto the face: its motion still reaches B, in depth too
    flat = np.array([1.0, 1.0, 0.0])
    got = Retargeter().fit(s0 * flat, b[dense]).displacements(s * flat)
    assert np.isfinite(got).all() and np.abs(got[..., 2]).max() > 0.1 * np.abs(expected[..., 2]).max()
