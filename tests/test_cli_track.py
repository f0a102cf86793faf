"""`retarget track` and `retarget calibrate` on videos the project renders itself, with the
error against the rendered truth, and their refusals."""

import numpy as np

from retarget.cli import main
from retarget.synthetic.marker_video import render_marker_video
from retarget.synthetic.stereo_rig import checkerboard_views, render_stereo_video, stereo_cameras


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
