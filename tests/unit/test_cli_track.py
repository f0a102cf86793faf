"""`retarget track` and `retarget calibrate` on videos the project renders itself, with the
error against the rendered truth, and their refusals."""

import numpy as np

from retarget.cli import main
from retarget.testing.marker_video import render_marker_video, render_webcam_marker_video
from retarget.testing.stereo_rig import checkerboard_views, render_stereo_video, stereo_cameras


def test_track_markers_writes_frames_close_to_the_truth(tmp_path, capsys):
    truth = render_marker_video(tmp_path / "markers.avi", n_frames=24, style="ring", seed=3)
    out, take = tmp_path / "frames.npy", tmp_path / "take.npz"
    assert main(["track", str(truth.videos[0]), "--method", "markers", "--out", str(out),
                 "--take", str(take), "-q"]) == 0
    printed = capsys.readouterr().out
    assert "tracked 24 frames of 21 points (dutreve21)" in printed and " fps" in printed
    frames = np.load(out)
    assert frames.shape == (24, 21, 3) and frames.dtype == np.float32
    assert np.all(frames[..., 2] == 0)  # one camera: z = 0
    height = truth.cameras[0].size[1]
    expected = truth.points2d[:, 0].copy()
    expected[..., 1] = height - expected[..., 1]  # the take's y points up
    seen = truth.visible[:, 0] & np.isfinite(frames[..., 0])
    assert seen.mean() > 0.9
    error = np.linalg.norm(frames[..., :2] - expected, axis=-1)[seen]
    assert np.median(error) < 0.5


def test_track_markers_without_a_layout_writes_every_marker_in_a_stable_order(tmp_path, capsys):
    """Webcam footage of 24 small markers (no built-in layout has 24): no --layout, so
    every marker in view, columns m01..mM by when each is first seen."""
    from retarget.sources.take import Take

    truth = render_webcam_marker_video(tmp_path / "webcam.mp4", n_frames=16, seed=2, occluded_frames=0)
    out, take_path = tmp_path / "frames.npy", tmp_path / "take.npz"
    assert main(["track", str(truth.videos[0]), "--method", "markers", "--out", str(out),
                 "--take", str(take_path), "-q"]) == 0
    frames = np.load(out)
    n = frames.shape[1]
    assert f"tracked 16 frames of {n} points (own labels)" in capsys.readouterr().out
    assert frames.shape == (16, n, 3) and frames.dtype == np.float32 and 20 <= n <= 24
    take = Take.load(take_path)
    assert take.names == tuple(f"m{k:02d}" for k in range(1, n + 1)) and take.layout is None
    # each column is one marker throughout, within a pixel
    image = frames[..., :2].astype(np.float64)
    image[..., 1] = truth.cameras[0].size[1] - image[..., 1]
    d = np.linalg.norm(image[:, :, None] - truth.points2d[:, 0][:, None], axis=3)
    nearest = np.nan_to_num(d, nan=np.inf).argmin(2)
    seen = np.isfinite(image[..., 0])
    assert seen.mean() > 0.9
    for m in range(n):
        assert len(set(nearest[seen[:, m], m])) == 1
    assert np.median(d.min(2)[seen]) < 0.5
    # the order: by first frame seen, then top to bottom
    first = seen.argmax(0)
    assert (np.diff(first) >= 0).all()
    top = image[0, first == 0, 1]
    assert (np.diff(top) >= 0).all()


def test_calibrate_then_track_stereo(tmp_path, capsys):
    import cv2

    left, right = stereo_cameras()
    views_l, views_r, _ = checkerboard_views(left, right, 8, seed=2)
    for side, views in (("left", views_l), ("right", views_r)):
        (tmp_path / side).mkdir()
        for i, image in enumerate(views):
            cv2.imwrite(str(tmp_path / side / f"view{i:02d}.png"), image)
    calib = tmp_path / "calib.npz"
    assert main(["calibrate", str(tmp_path / "left"), str(tmp_path / "right"), "--cols", "9",
                 "--rows", "6", "--square", "25", "--out", str(calib)]) == 0
    printed = capsys.readouterr().out
    assert "from 8 of 8 view pairs" in printed
    rms = float(printed.split("RMS ")[1].split(" px")[0])
    assert rms < 0.5

    truth = render_stereo_video(tmp_path / "pair.mkv", n_frames=6, seed=1)
    out = tmp_path / "stereo.npy"
    assert main(["track", truth.videos[0], "--method", "stereo", "--right", truth.videos[1],
                 "--calibration", str(calib), "--out", str(out), "-q"]) == 0
    frames = np.load(out)
    assert frames.shape == (6, 21, 3) and np.isfinite(frames).all(axis=2).mean() > 0.9


def test_track_and_calibrate_refusals(tmp_path, capsys):
    video = tmp_path / "broken.mp4"
    video.write_bytes(b"\x00\x00\x00\x18ftypmp42 this is no video")
    cases = [
        (["track", str(video), "--method", "markers", "--out", str(tmp_path / "o.npy")], "broken.mp4"),
        (["track", str(tmp_path / "missing.mp4"), "--method", "markers", "--out", str(tmp_path / "o.npy")],
         "missing.mp4"),
        (["track", str(video), "--method", "stereo", "--out", str(tmp_path / "o.npy")], "--right"),
        (["track", str(video), "--method", "markers", "--right", str(video), "--out", str(tmp_path / "o.npy")],
         "--method stereo"),
        (["calibrate", str(tmp_path), str(tmp_path), "--cols", "9", "--rows", "6", "--square", "25",
          "--out", str(tmp_path / "c.npz")], "holds no images"),
    ]
    for argv, message in cases:
        assert main(argv + ["-q"]) == 2
        err = capsys.readouterr().err
        assert message in err and err.startswith("retarget: error:"), (argv, err)
    assert not (tmp_path / "o.npy").exists()


def test_condition_a_motion_capture_file_then_transfer_it(tmp_path, capsys):
    """A C3D of a performer's 68 landmarks under head motion, conditioned from the CLI,
    then transferred: the target moves with the performer's expression, without the head."""
    import ezc3d
    from scipy.spatial.transform import Rotation

    from retarget.layouts import get_layout
    from retarget.mesh import mesh_from_arrays, save_mesh
    from retarget.sample_face import demo_weights, posed_vertices, sample_face

    performer = sample_face(1, identity=np.array([0.9, -0.4, 0.5, 0.2, -0.3]))
    expression = posed_vertices(performer, demo_weights(60, 30.0))[:, performer.landmarks68]
    expression[:15] = performer.vertices[performer.landmarks68]              # 0.5 s of neutral
    turn = Rotation.from_rotvec(np.c_[np.zeros(60), np.linspace(0, 0.3, 60), np.zeros(60)]).as_matrix()
    moved = np.einsum("fij,fnj->fni", turn, expression) + np.c_[np.linspace(0, 2, 60), np.zeros((60, 2))][:, None]
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [30.0]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = [f"M{i:02d}" for i in range(68)]
    data = np.ones((4, 68, 60))
    data[:3] = (10 * moved).transpose(2, 1, 0)                                # mm
    c3d["data"]["points"] = data
    c3d.write(str(tmp_path / "perf.c3d"))
    mapping = dict(zip([f"M{i:02d}" for i in range(68)], get_layout("ibug68").point_names))
    (tmp_path / "map.json").write_text(__import__("json").dumps(mapping))

    assert main(["condition", str(tmp_path / "perf.c3d"), "--layout", "ibug68", "--mapping",
                 str(tmp_path / "map.json"), "--neutral-out", str(tmp_path / "s0.npy"),
                 "--out", str(tmp_path / "s.npy"), "-q"]) == 0
    assert "60 frames of 68 3D points" in capsys.readouterr().out
    s0, s = np.load(tmp_path / "s0.npy"), np.load(tmp_path / "s.npy")
    assert s0.shape == (68, 3) and s.shape == (60, 68, 3)  # every frame, the neutral's too
    # head motion removed: the conditioned frames equal the expression in the neutral's head frame
    shape = lambda a: a - a.mean(axis=-2, keepdims=True)  # noqa: E731
    assert np.abs(shape(s) - shape(np.einsum("ij,fnj->fni", turn[0], expression * 10))).max() < 0.05  # mm

    target = sample_face(1)
    save_mesh(mesh_from_arrays(target.vertices, target.faces), tmp_path / "target.obj")
    (tmp_path / "t0.json").write_text(__import__("json").dumps(
        {"vertex_indices": [int(i) for i in target.landmarks68], "layout": "ibug68"}))
    assert main(["transfer", "--target-mesh", str(tmp_path / "target.obj"), "--target-landmarks",
                 str(tmp_path / "t0.json"), "--source-neutral", str(tmp_path / "s0.npy"),
                 "--source-frames", str(tmp_path / "s.npy"), "--deformer", "ellipsoid",
                 "--out", str(tmp_path / "out.npy"), "-q"]) == 0
    out = np.load(tmp_path / "out.npy")
    assert out.shape == (len(s), len(target.vertices), 3)
    # the jaw follows the performer's: the chin moves with the source chin, frame by frame
    chin = get_layout("ibug68").index("chin")
    target_chin = out[:, target.landmarks68[chin]] - target.vertices[target.landmarks68[chin]]
    source_chin = np.linalg.norm(s[:, chin] - s0[chin], axis=1)
    assert np.abs(target_chin).max() > 0.1 and np.corrcoef(np.linalg.norm(target_chin, axis=1), source_chin)[0, 1] > 0.9
    assert main(["condition", str(tmp_path / "perf.c3d"), "--layout", "ibug68", "--neutral-out",
                 str(tmp_path / "x.npy"), "--out", str(tmp_path / "y.npy"), "-q"]) == 2
    assert "none of the take's 68 labels (M00, M01" in capsys.readouterr().err


def test_track_markerless_follows_a_rendered_face_with_the_native_face_mesh(tmp_path, capsys):
    import cv2

    from retarget.sample_face import sample_face
    from retarget.testing.camera import look_at
    from retarget.testing.render import render_face

    face = sample_face(1, identity=np.array([0.2, -0.3, 0.4, 0.1, -0.5]))
    centre = face.vertices.mean(0)
    size, n_frames = 320, 10
    video = tmp_path / "face.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 25, (size, size))
    truth = []
    for i in range(n_frames):  # the face drifts right and up by half a centimetre a frame
        target = centre - np.array([0.5 * i, 0.5 * i, 0.0])
        camera = look_at(target + np.array([0.0, 0.0, 45.0]), target, size=(size, size), fov_deg=30)
        writer.write(render_face(camera, face.vertices, face.faces).image)
        points = camera.R @ face.vertices[face.landmarks68].T + camera.t[:, None]
        pixels = ((camera.K @ points)[:2] / points[2]).T + 0.5
        truth.append(np.column_stack([pixels[:, 0], size - pixels[:, 1]]))
    writer.release()
    out = tmp_path / "frames.npy"
    assert main(["track", str(video), "--method", "markerless", "--layout", "ibug68", "--out", str(out), "-q"]) == 0
    assert f"tracked {n_frames} frames of 68 points (ibug68)" in capsys.readouterr().out
    frames = np.load(out)
    assert frames.shape == (n_frames, 68, 3) and np.isfinite(frames).all()
    truth = np.asarray(truth)
    inter_ocular = np.linalg.norm(truth[:, 36:42].mean(1) - truth[:, 42:48].mean(1), axis=1)
    error = np.linalg.norm(frames[:, 17:, :2] - truth[:, 17:], axis=2) / inter_ocular[:, None]
    assert np.median(error) < 0.08
    # the camera moves left and down, so the face moves right and up (y up): so do the points
    drift = frames[-1, 17:, :2].mean(0) - frames[0, 17:, :2].mean(0)
    assert drift[0] > 20 and drift[1] > 20
