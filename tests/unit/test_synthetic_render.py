"""The synthetic test material: cameras agree with OpenCV, the renderer's truth holds in its
pixels (marker centroids, occlusion, checkerboard corners), marker videos are deterministic
and carry their ground truth."""

import cv2
import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.sample_face import sample_face
from retarget.testing.camera import Camera, look_at
from retarget.testing.marker_video import (
    GroundTruth,
    default_camera,
    marker_vertices,
    render_marker_video,
)
from retarget.testing.render import render_checkerboard, render_face


@pytest.fixture(scope="module")
def face():
    return sample_face(1)


def test_projection_matches_opencv_with_distortion():
    rng = np.random.default_rng(0)
    cam = look_at((10.0, 5.0, 60.0), (0.0, 0.0, 5.0), fov_deg=30,
                  dist=(-0.2, 0.05, 0.001, -0.002, 0.01))
    pts = rng.uniform(-10, 10, (50, 3))
    rvec, _ = cv2.Rodrigues(cam.R)
    ref, _ = cv2.projectPoints(pts, rvec, cam.t, cam.K, cam.dist)
    np.testing.assert_allclose(cam.project(pts), ref.reshape(-1, 2), atol=1e-9)
    # rays invert the projection, distortion included
    d = cam.rays(cam.project(pts))
    along = (pts - cam.center) / np.linalg.norm(pts - cam.center, axis=1, keepdims=True)
    np.testing.assert_allclose(d, along, atol=1e-8)
    back = Camera.from_dict(cam.to_dict())
    np.testing.assert_allclose(back.project(pts), cam.project(pts))


def test_look_at_shows_the_target_centred_and_up_up():
    cam = look_at((0.0, 0.0, 50.0), (0.0, 0.0, 0.0), size=(320, 240))
    centre, above, left = cam.project(np.array([[0, 0, 0], [0, 5, 0], [5, 0, 0.0]]))
    np.testing.assert_allclose(centre, [159.5, 119.5])
    assert above[1] < centre[1]      # world +y is up the image (smaller row)
    assert left[0] > centre[0]       # the subject's left (+x) faces the camera's right
    assert np.isnan(cam.project(np.array([0.0, 0.0, 60.0]))).all()   # behind the camera
    with pytest.raises(RetargetError, match="parallel"):
        look_at((0, 0, 10), (0, 0, 0), up=(0, 0, 1))


@pytest.mark.parametrize("style", ["ring", "color"])
def test_marker_centroids_are_their_projected_vertices(face, style):
    # On black skin the image is the markers alone: the intensity centroid round each
    # marker is the drawn marker's, which must be the projection of its vertex.
    shot = render_face(default_camera(), face.vertices, face.faces, marker_vertices(face),
                       style=style, skin=(0, 0, 0), background=0)
    image = shot.image.astype(np.float64).sum(2)
    assert shot.visible.all()
    r = 9
    ys, xs = np.mgrid[-r:r + 1, -r:r + 1]
    for p in shot.points2d:
        x0, y0 = np.rint(p).astype(int)
        patch = image[y0 - r:y0 + r + 1, x0 - r:x0 + r + 1]
        centroid = np.array([(patch * xs).sum(), (patch * ys).sum()]) / patch.sum() + [x0, y0]
        assert np.linalg.norm(centroid - p) < 0.04


def test_zbuffer_hides_far_triangles_whatever_their_order():
    cam = look_at((0.0, 0.0, 20.0), (0.0, 0.0, 0.0), size=(64, 48), fov_deg=40)
    quad = np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0.0]])
    v = np.concatenate([quad, quad * [0.5, 0.5, 1] + [0, 0, 2]])     # small quad in front
    tris = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    for order in (tris, tris[::-1]):
        r = render_face(cam, v, order)
        near, far = np.rint(cam.project(np.array([[0.5, 0.5, 2.0], [2.2, 0.5, 0.0]]))).astype(int)
        assert np.isclose(r.depth[near[1], near[0]], 18.0, atol=1e-6)   # the near quad wins
        assert np.isclose(r.depth[far[1], far[0]], 20.0, atol=1e-6)     # only the far one there
        assert np.isinf(r.depth[0, 0])


def test_a_turned_head_hides_its_far_markers(face):
    yaw = np.radians(60)
    R = np.array([[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]])
    verts = marker_vertices(face)
    pivot = np.array([0, 0, 4.0])
    turned = (face.vertices - pivot) @ R.T + pivot
    shot = render_face(default_camera(), turned, face.faces, verts)
    away = face.vertices[verts, 0] > 2.5        # +yaw turns +z toward +x: the left side away
    toward = face.vertices[verts, 0] < -2.5
    assert away.sum() == toward.sum() == 5
    assert not shot.visible[away].any() and shot.visible[toward].all()
    assert (shot.coverage[toward] == 1).all()
    assert ((shot.coverage[away] > 0.1) & (shot.coverage[away] < 0.9)).any()   # half behind the face


def test_checkerboard_corners_are_found_where_the_truth_says():
    cam = look_at((0.0, 0.0, 600.0), (0.0, 0.0, 0.0), fov_deg=50, dist=(-0.1, 0.02, 0, 0, 0))
    a = np.radians(180 + 25)        # board +z away from the camera, tilted 25 degrees
    R = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    board = render_checkerboard(cam, (R, np.array([-100.0, 70.0, 0.0])), rows=6, cols=9, square=25.0)
    gray = cv2.cvtColor(board.image, cv2.COLOR_BGR2GRAY)
    found, corners = cv2.findChessboardCorners(gray, (9, 6))
    assert found
    corners = cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1),
                               (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4)).reshape(-1, 2)
    truth = board.corners2d
    if np.linalg.norm(corners[0] - truth[0]) > np.linalg.norm(corners[0] - truth[-1]):
        corners = corners[::-1]                       # OpenCV may start from either end
    assert np.abs(corners - truth).max() < 0.1
    np.testing.assert_allclose(board.corners3d[10], R @ board.object_points[10] + [-100, 70, 0], atol=1e-4)


def test_marker_video_is_deterministic_and_carries_its_truth(tmp_path, face):
    kw = dict(n_frames=3, seed=4, start=1.0)
    truth = render_marker_video(tmp_path / "a.mkv", **kw)
    again = render_marker_video(tmp_path / "b.mkv", **kw)
    frames = []
    for name in ("a.mkv", "b.mkv"):
        cap = cv2.VideoCapture(str(tmp_path / name))
        frames.append([cap.read()[1] for _ in range(3)])
        assert not cap.read()[0]                       # exactly n_frames
    assert all(np.array_equal(x, y) for x, y in zip(*frames))
    np.testing.assert_array_equal(truth.points2d, again.points2d)
    loaded = GroundTruth.load(tmp_path / "a.npz")
    np.testing.assert_array_equal(loaded.points2d, truth.points2d)
    assert loaded.names == truth.names and len(truth.names) == 21
    cam = loaded.cameras[0]
    np.testing.assert_allclose(cam.project(truth.points3d), truth.points2d[:, 0])
    # the 3D truth is the head-moved marker vertices
    assert truth.points2d.shape == (3, 1, 21, 2) and truth.visible.shape == (3, 1, 21)
    moved = truth.points3d[0] - truth.head_translation[0]
    posed = moved @ truth.head_rotation[0]
    np.testing.assert_allclose(posed[:, 0], face.vertices[truth.marker_vertices, 0], atol=0.5)


def test_two_named_cameras_write_two_videos(tmp_path):
    cams = {"left": default_camera(size=(160, 120)), "right": default_camera(size=(160, 120))}
    truth = render_marker_video(tmp_path / "s.avi", n_frames=1, cameras=cams, style="color",
                                head_motion=False)
    assert [p.rsplit("/", 1)[-1] for p in truth.videos] == ["s_left.avi", "s_right.avi"]
    assert all(cv2.VideoCapture(p).read()[0] for p in truth.videos)
    np.testing.assert_allclose(truth.points2d[:, 0], truth.points2d[:, 1])


def test_bad_requests_are_refused(tmp_path):
    with pytest.raises(RetargetError, match="must end in"):
        render_marker_video(tmp_path / "x.gif", n_frames=1)
    with pytest.raises(RetargetError, match="n_frames"):
        render_marker_video(tmp_path / "x.avi", n_frames=0)
    with pytest.raises(RetargetError, match="style"):
        render_face(default_camera(), np.zeros((3, 3)), np.array([[0, 1, 2]]), style="dots")
    with pytest.raises(RetargetError, match="not a marker-video ground truth"):
        (tmp_path / "bad.npz").write_bytes(b"nope")
        GroundTruth.load(tmp_path / "bad.npz")
