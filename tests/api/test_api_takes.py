"""Takes over the REST API and as stream sources: upload, list, trim, rename, delete,
download, replay through conditioning and retargeting, live points pushed over the
WebSocket and recorded into a take, stereo colour-marker pairs tracked in a job (with a
calibration file or checkerboard videos) against the rendered truth, and bad input that
leaves everything intact."""

import io

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from retarget.layouts import get_layout
from retarget.pipeline import Retargeter
from retarget.sample_face import demo_weights, sample_face
from retarget.sources.calibration import StereoCalibration, calibration_views
from retarget.testing.marker_video import render_marker_video
from retarget.testing.stereo_rig import (
    checkerboard_views,
    render_stereo_video,
    rig_calibration,
    stereo_cameras,
)
from server.app import create_app
from server.wire import FLAG_HEAD_ROTATION, encode_points
from tests.ws_messages import binary_frames, replies
from tests.waits import wait_job

FPS = 30.0


@pytest.fixture(scope="module")
def performance():
    """A performer's 68 landmarks: neutral (68, 3) and 60 frames, cm."""
    face = sample_face(identity=np.array([0.8, 0.5, -0.6, 1.0, 0.3]))
    lm = np.asarray(face.landmarks68)
    weights = demo_weights(60, FPS)
    neutral = face.vertices[lm]
    frames = neutral + np.tensordot(weights, face.expressions[:, lm], axes=1)
    return neutral.astype(np.float32), frames.astype(np.float32)


def npy_bytes(array) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.asarray(array, dtype=np.float32))
    return buffer.getvalue()


def upload(client, pid, name, data, **fields):
    return client.post(f"/api/projects/{pid}/takes", files={"file": (name, data)}, data=fields)


def write_video(path, frames, fps=30.0):
    """`frames` (H, W, 3) uint8 BGR into a lossless FFV1 .mkv at `path`; the path."""
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), fps, (w, h))
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path


@pytest.fixture(scope="module")
def rig():
    return stereo_cameras()


@pytest.fixture(scope="module")
def stereo(tmp_path_factory, rig):
    """Rendered stereo material (bytes by name): an 8-frame colour-marker pair ("left.mkv",
    "right.mkv", truth in "truth"), the rig's exact calibration ("exact.npz"), and 6
    checkerboard view pairs as videos ("board_left.mkv", "board_right.mkv")."""
    folder = tmp_path_factory.mktemp("stereo")
    truth = render_stereo_video(folder / "take.mkv", n_frames=8, cameras=rig, start=3.6, seed=2)
    rig_calibration(*rig).save(folder / "exact.npz")
    lefts, rights, _ = checkerboard_views(*rig, 6, seed=0)
    files = {"left.mkv": truth.videos[0], "right.mkv": truth.videos[1], "exact.npz": folder / "exact.npz",
             "board_left.mkv": write_video(folder / "bl.mkv", lefts),
             "board_right.mkv": write_video(folder / "br.mkv", rights)}
    material = {name: open(path, "rb").read() for name, path in files.items()}
    material["truth"] = truth
    return material


def track_stereo(client, pid, files: dict, **fields):
    """POST a stereo track request; files maps a form field to (file name, bytes)."""
    return client.post(f"/api/projects/{pid}/takes/track", files=files,
                       data={"method": "stereo", **fields})


def tracked_points(client, pid, answer):
    """The finished job's take: its info and (F, N, 3) points."""
    job = wait_job(client, answer["id"], timeout_s=120, poll_s=0.05)
    assert job["state"] == "done", job["detail"]
    take_id = job["result"]["take"]
    info = client.get(f"/api/projects/{pid}/takes/{take_id}").json()
    points = np.load(io.BytesIO(client.get(f"/api/projects/{pid}/takes/{take_id}/points").content))
    return info, points


def test_a_stereo_pair_with_a_calibration_file_tracks_the_truth(client, sample_id, stereo, rig, tmp_path):
    files = {"file": ("left.mkv", stereo["left.mkv"]), "right": ("right.mkv", stereo["right.mkv"]),
             "calibration": ("exact.npz", stereo["exact.npz"])}
    r = track_stereo(client, sample_id, files, name="pair")
    assert r.status_code == 202, r.text
    answer = r.json()
    assert answer["calibration"]["source"] == "file"
    assert answer["calibration"]["baseline"] == pytest.approx(150.0) and answer["calibration"]["size"] == [640, 480]
    info, points = tracked_points(client, sample_id, answer)
    assert (info["name"], info["source"], info["layout"], info["dims"]) == ("pair", "stereo", "dutreve21", 3)
    assert points.shape == (8, 21, 3)
    # the left camera's frame, mm; the head motion is kept (the panel's conditioning removes it)
    err = np.linalg.norm(points - rig[0].to_camera(stereo["truth"].points3d), axis=2)
    assert np.isfinite(err).all() and np.median(err) < 0.3 and err.max() < 1.5
    # the take carries its calibration, downloadable for the next pairs of the same cameras
    r = client.get(f"/api/projects/{sample_id}/takes/{info['id']}/calibration")
    assert r.status_code == 200
    path = tmp_path / "back.npz"
    path.write_bytes(r.content)
    back, exact = StereoCalibration.load(path), rig_calibration(*rig)
    for name in ("K1", "K2", "R", "T", "F"):
        np.testing.assert_allclose(getattr(back, name), getattr(exact, name))


def test_a_stereo_pair_calibrated_from_checkerboard_videos(client, sample_id, stereo, rig):
    files = {"file": ("left.mkv", stereo["left.mkv"]), "right": ("right.mkv", stereo["right.mkv"]),
             "calibration_left": ("board_left.mkv", stereo["board_left.mkv"]),
             "calibration_right": ("board_right.mkv", stereo["board_right.mkv"])}
    r = track_stereo(client, sample_id, files, cols="9", rows="6", square="25")
    assert r.status_code == 202, r.text
    cal = r.json()["calibration"]
    assert cal["source"] == "checkerboard" and cal["views"] == 6 and cal["rms"] < 0.3
    assert cal["baseline"] == pytest.approx(150.0, rel=0.01)  # mm, the rig's
    info, points = tracked_points(client, sample_id, r.json())
    assert info["name"] == "left" and points.shape == (8, 21, 3)
    err = np.linalg.norm(points - rig[0].to_camera(stereo["truth"].points3d), axis=2)
    assert np.median(err) < 1.5  # mm at 1 m, with an estimated calibration
    r = client.get(f"/api/projects/{sample_id}/takes/{info['id']}/calibration")
    assert r.status_code == 200 and r.content[:2] == b"PK"


def test_bad_stereo_input_is_refused_before_tracking(client, app, sample_id, stereo, rig, tmp_path):
    left, right = ("left.mkv", stereo["left.mkv"]), ("right.mkv", stereo["right.mkv"])
    exact = ("exact.npz", stereo["exact.npz"])
    boards = {"calibration_left": ("board_left.mkv", stereo["board_left.mkv"]),
              "calibration_right": ("board_right.mkv", stereo["board_right.mkv"])}
    pattern = {"cols": "9", "rows": "6", "square": "25"}
    truth = stereo["truth"]
    short = write_video(tmp_path / "short.mkv", [np.full((480, 640, 3), 90, np.uint8)] * 5)
    np.savez(tmp_path / "other.npz", points=np.zeros(3))
    rig_calibration(*stereo_cameras(size=(320, 240))).save(tmp_path / "small.npz")
    cases = [
        ({"file": left, "calibration": exact}, {}, 422, "'right', which is missing"),
        ({"right": right, "calibration": exact}, {}, 422, "left camera's as 'file', which is missing"),
        ({"file": left, "right": right}, {}, 422, "needs the cameras' calibration"),
        ({"file": left, "right": right, "calibration": exact, **boards}, pattern, 422, "not both"),
        ({"file": left, "right": right, "calibration_left": boards["calibration_left"]}, pattern, 422,
         "'calibration_right' is missing"),
        ({"file": left, "right": right, **boards}, {"cols": "9", "rows": "6"}, 422, "pattern's square"),
        ({"file": left, "right": ("right.txt", b"text"), "calibration": exact}, {}, 415, "'.txt'"),
        ({"file": left, "right": right, "calibration": ("cal.json", b"{}")}, {}, 415, "'.json'"),
        ({"file": left, "right": ("right.mkv", b"not a video at all"), "calibration": exact}, {}, 422,
         "'right.mkv' is not a video OpenCV can open"),
        ({"file": left, "right": ("short.mkv", short.read_bytes()), "calibration": exact}, {}, 422,
         f"'left.mkv' has {truth.points3d.shape[0]} frames but 'short.mkv' has 5"),
        ({"file": left, "right": right, "calibration": ("other.npz", (tmp_path / "other.npz").read_bytes())},
         {}, 422, "'other.npz' is not a stereo calibration"),
        ({"file": left, "right": right, "calibration": ("zip.npz", b"PK\x03\x04" + b"x" * 64)}, {}, 422,
         "'zip.npz' is not a stereo calibration"),
        ({"file": left, "right": right, "calibration": ("small.npz", (tmp_path / "small.npz").read_bytes())},
         {}, 422, "the calibration is for 320x240"),
        # calibration failure: the pattern is in none of the views
        ({"file": left, "right": right, "calibration_left": left, "calibration_right": right}, pattern, 422,
         "pattern (9x6) was found in both images of 0 of 8 pairs"),
        # no markers: the checkerboard videos as the take
        ({"file": boards["calibration_left"], "right": boards["calibration_right"], "calibration": exact}, {},
         422, "0 markers matched"),
    ]
    before = client.get(f"/api/projects/{sample_id}/takes").json()
    for files, fields, code, message in cases:
        r = track_stereo(client, sample_id, files, **fields)
        assert r.status_code == code and message in r.json()["detail"], (message, r.text)
        assert "scratch" not in r.json()["detail"]  # uploads are named by their file names
    r = client.post(f"/api/projects/{sample_id}/takes/track", files={"file": left, "right": right},
                    data={"method": "markers"})
    assert r.status_code == 422 and "right: for method 'stereo'" in r.json()["detail"]
    assert client.get(f"/api/projects/{sample_id}/takes").json() == before
    assert list(app.state.store.scratch_dir.iterdir()) == []  # no upload left behind
    plain = upload(client, sample_id, "plain.npy", npy_bytes(np.zeros((2, 68, 3))), layout="ibug68").json()
    r = client.get(f"/api/projects/{sample_id}/takes/{plain['id']}/calibration")
    assert r.status_code == 404 and "no stereo calibration" in r.json()["detail"]
    client.delete(f"/api/projects/{sample_id}/takes/{plain['id']}")


def test_a_ring_marker_video_is_tracked_in_a_job(client, sample_id, tmp_path):
    truth = render_marker_video(tmp_path / "rings.mkv", n_frames=4, seed=3, start=0.55)
    r = client.post(f"/api/projects/{sample_id}/takes/track", data={"method": "markers"},
                    files={"file": ("rings.mkv", (tmp_path / "rings.mkv").read_bytes())})
    assert r.status_code == 202, r.text
    info, points = tracked_points(client, sample_id, r.json())
    assert (info["name"], info["source"], info["dims"]) == ("rings", "markers", 2)
    detail = client.get(f"/api/jobs/{r.json()['id']}").json()["result"]
    assert (detail["frames"], detail["frames_claimed"], detail["truncated"]) == (4, 4, False)
    # a cut-off file gives its frames up to the cut, and the job says so
    whole = (tmp_path / "rings.mkv").read_bytes()
    r = client.post(f"/api/projects/{sample_id}/takes/track", data={"method": "markers"},
                    files={"file": ("cut.mkv", whole[:int(0.6 * len(whole))])})
    detail = wait_job(client, r.json()["id"], timeout_s=120, poll_s=0.05)["result"]
    assert (detail["frames"], detail["frames_claimed"], detail["truncated"]) == (2, 4, True)
    expected = truth.points2d[:, 0] * [1, -1] + [0, 480]  # pixels, y up
    assert np.nanmedian(np.linalg.norm(points - expected, axis=2)) < 0.5
    r = client.post(f"/api/projects/{sample_id}/takes/track", data={"method": "markers"},
                    files={"file": ("rings.mkv", b"not a video")})
    assert r.status_code == 422 and r.json()["detail"].startswith("'rings.mkv' is not a video OpenCV can open")
    # a video without markers fails in the job, named
    plain = write_video(tmp_path / "plain.mkv", [np.full((480, 640, 3), 200, np.uint8)] * 2)
    r = client.post(f"/api/projects/{sample_id}/takes/track", data={"method": "markers"},
                    files={"file": ("plain.mkv", plain.read_bytes())})
    job = wait_job(client, r.json()["id"], timeout_s=120, poll_s=0.05)
    assert job["state"] == "failed" and job["detail"].startswith("'plain.mkv': found 0 ring markers")


def test_calibration_views_are_pairs_spread_over_the_videos(tmp_path):
    """Frame i of both videos is grey level 5 i: the kept pairs show which frames they are."""
    frames = [np.full((48, 64, 3), 5 * i, np.uint8) for i in range(45)]
    a, b = write_video(tmp_path / "a.mkv", frames), write_video(tmp_path / "b.mkv", frames)
    lefts, rights = calibration_views(a, b, 8)
    index = [int(f[0, 0, 0]) // 5 for f in lefts]
    assert index == [int(f[0, 0, 0]) // 5 for f in rights]
    assert 4 <= len(index) <= 8 and index[0] == 0 and index[-1] >= 30
    assert len(set(np.diff(index))) == 1  # evenly spaced



def test_upload_list_trim_rename_download_delete(client, sample_id, performance):
    neutral, frames = performance
    take = np.concatenate([np.repeat(neutral[None], 30, 0), frames])
    r = upload(client, sample_id, "smile.npy", npy_bytes(take), layout="ibug68", fps="30")
    assert r.status_code == 201, r.text
    info = r.json()
    assert (info["name"], info["n_frames"], info["n_points"], info["dims"]) == ("smile", 90, 68, 3)
    assert info["duration"] == pytest.approx(89 / 30) and info["trim"] == [0, pytest.approx(89 / 30)]
    assert any(t["id"] == info["id"] for t in client.get(f"/api/projects/{sample_id}/takes").json())

    r = client.patch(f"/api/projects/{sample_id}/takes/{info['id']}", json={"name": "Smile 1", "trim": [1.0, 2.0]})
    assert r.status_code == 200 and r.json()["name"] == "Smile 1" and r.json()["trim"] == [1.0, 2.0]
    got = np.load(io.BytesIO(client.get(f"/api/projects/{sample_id}/takes/{info['id']}/points").content))
    np.testing.assert_array_equal(got, take[30:60])  # [1 s, 2 s) at 30 fps

    for bad, message in (([2.0, 1.0], "after the start"), ([-1, None], "start must be"), ([0, 99], "at most")):
        r = client.patch(f"/api/projects/{sample_id}/takes/{info['id']}", json={"trim": bad})
        assert r.status_code == 422 and message in r.json()["detail"]
    assert client.get(f"/api/projects/{sample_id}/takes/{info['id']}").json()["trim"] == [1.0, 2.0]

    assert client.delete(f"/api/projects/{sample_id}/takes/{info['id']}").status_code == 204
    assert client.get(f"/api/projects/{sample_id}/takes/{info['id']}").status_code == 404


def test_bad_take_files_are_refused_and_nothing_is_stored(client, sample_id):
    before = client.get(f"/api/projects/{sample_id}/takes").json()
    cases = [
        ("take.exe", b"MZ", 415, "'.exe'"),
        ("empty.csv", b"", 422, "empty"),
        ("nan.npy", npy_bytes(np.full((5, 68, 3), np.nan)), 422, "take file 'nan.npy' refused"),
        ("short.npy", npy_bytes(np.zeros((5, 68))), 422, "take file 'short.npy' refused"),
        ("junk.c3d", b"not a c3d file at all", 422, "take file 'junk.c3d' refused"),
    ]
    for name, data, code, message in cases:
        r = upload(client, sample_id, name, data, layout="ibug68", fps="30")
        assert r.status_code == code and message in r.json()["detail"], (name, r.text)
    assert client.get(f"/api/projects/{sample_id}/takes").json() == before
    assert client.get(f"/api/projects/{sample_id}/takes/AAAAAAAAAAAAAAAA").status_code == 404
    assert client.get(f"/api/projects/{sample_id}/takes/../../etc").status_code == 404


def test_a_take_replays_through_the_retargeter(client, sample_id, performance):
    """The streamed displacements are the library's for the take's frames."""
    neutral, frames = performance
    take = np.concatenate([np.repeat(neutral[None], 15, 0), frames])
    info = upload(client, sample_id, "replay.npy", npy_bytes(take), layout="ibug68", fps="30").json()
    target = _target_points(client, sample_id)
    settings = {"neutral": {"mode": "frame", "frame": 0}, "head_pose": "keep", "filter": "none"}
    expected = Retargeter().fit(neutral, target).displacements(take)
    with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "start", "source": "take", "take": info["id"], "loop": False, "settings": settings})
        started = replies(ws, 1)[0]
        assert started["type"] == "started" and started["source"] == "take" and started["frames"] == 75
        got = binary_frames(ws, 20)
        for f in got:
            np.testing.assert_allclose(f.displacements, expected[f.frame_index], atol=1e-4)
            assert f.source_time == pytest.approx(f.frame_index / 30)
        ws.send_json({"type": "stop"})


def test_a_take_with_fewer_points_drives_the_whole_rig(client, sample_id, performance):
    """A dutreve21 take (21 named points) on the 68-point sample project."""
    neutral, frames = performance
    layout = get_layout("dutreve21")
    take = np.concatenate([np.repeat(neutral[None], 5, 0), frames])[:, list(layout.ibug68)]
    info = upload(client, sample_id, "markers.npy", npy_bytes(take), layout="dutreve21", fps="30").json()
    with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "start", "source": "take", "take": info["id"],
                      "settings": {"neutral": {"mode": "frame", "frame": 0}}})
        got = binary_frames(ws, 40)
        moving = np.stack([f.displacements for f in got])
        driven = np.zeros(68, bool)
        driven[list(layout.ibug68)] = True
        assert np.abs(moving[:, ~driven]).max() > 1e-3  # undriven joints follow
        ws.send_json({"type": "stop"})


def test_live_points_are_retargeted_and_recorded(client, sample_id, performance):
    neutral, frames = performance
    target = _target_points(client, sample_id)
    # the performer's head turns 10 degrees about y while performing
    angle = np.radians(10)
    turn = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    centre = neutral.mean(0)
    settings = {"neutral": {"mode": "first_seconds", "seconds": 0.2}, "head_pose": "remove",
                "apply_rotation": True, "filter": "none"}
    with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "start", "source": "live", "dims": 3, "settings": settings})
        assert replies(ws, 1)[0]["source"] == "live"
        ws.send_json({"type": "record"})
        assert replies(ws, 1)[0]["type"] == "recording"
        t = 0.0
        for i in range(10):  # neutral capture: 0.2 s at 30 fps
            ws.send_bytes(encode_points(neutral, frame_index=i, capture_time=t))
            t += 1 / FPS
        sent = []
        for j, frame in enumerate(frames[:20]):
            turned = (frame - centre) @ turn.T + centre
            ws.send_bytes(encode_points(turned, frame_index=10 + j, capture_time=t))
            sent.append(frame)
            t += 1 / FPS
        got = binary_frames(ws, 5)
        expected = Retargeter().fit(neutral, target).displacements(np.stack(sent))
        last = got[-1]
        assert last.flags & FLAG_HEAD_ROTATION
        # the head turn is taken out of the points and comes back as the rotation
        np.testing.assert_allclose(last.displacements, expected[last.frame_index - 10], atol=0.02)
        w = last.head_rotation[3]
        assert 2 * np.degrees(np.arccos(min(1.0, abs(w)))) == pytest.approx(10, abs=0.5)
        ws.send_json({"type": "record_stop", "name": "webcam take"})
        recorded = replies(ws, 1)[0]
        assert recorded["type"] == "recorded" and recorded["take"]["n_frames"] == 30
        assert recorded["take"]["name"] == "webcam take" and recorded["take"]["source"] == "live"
        # malformed points get an error and the stream goes on
        ws.send_bytes(encode_points(neutral[:10], frame_index=99, capture_time=t))
        assert "68 points" in replies(ws, 1)[0]["detail"]
        ws.send_bytes(b"RTSP" + b"\0" * 10)
        assert "shorter than" in replies(ws, 1)[0]["detail"]
        ws.send_json({"type": "stop"})
    stored = np.load(io.BytesIO(client.get(
        f"/api/projects/{sample_id}/takes/{recorded['take']['id']}/points").content))
    assert stored.shape == (30, 68, 3)
    np.testing.assert_allclose(stored[:10], np.repeat(neutral[None], 10, 0), atol=1e-6)


def test_points_without_a_live_source_and_unknown_takes_are_errors(client, sample_id):
    with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_bytes(encode_points(np.zeros((68, 3)), frame_index=0, capture_time=0.0))
        assert "live source" in replies(ws, 1)[0]["detail"]
        ws.send_json({"type": "start", "source": "take", "take": "AAAAAAAAAAAAAAAA"})
        assert "no take" in replies(ws, 1)[0]["detail"]
        ws.send_json({"type": "record"})
        assert "live" in replies(ws, 1)[0]["detail"]


def test_takes_survive_a_restart_and_a_new_mesh(tmp_path, performance):
    neutral, frames = performance
    app = create_app(tmp_path)
    with TestClient(app) as client:
        pid = next(p["id"] for p in client.get("/api/projects").json() if p["landmarks"])
        info = upload(client, pid, "keep.npy", npy_bytes(frames), layout="ibug68", fps="30").json()
        mesh = client.get(f"/api/projects/{pid}/mesh")
        fmt = client.get(f"/api/projects/{pid}").json()["mesh"]["format"]
        assert client.put(f"/api/projects/{pid}/mesh", files={"file": (f"again.{fmt}", mesh.content)}).status_code == 200
    with TestClient(create_app(tmp_path)) as client:
        takes = client.get(f"/api/projects/{pid}/takes").json()
        assert [t["id"] for t in takes] == [info["id"]]
        got = np.load(io.BytesIO(client.get(f"/api/projects/{pid}/takes/{info['id']}/points").content))
        np.testing.assert_array_equal(got, frames)


def _target_points(client, pid):
    from retarget.landmarks import landmarks_from_json
    from retarget.mesh import load_mesh

    project = client.get(f"/api/projects/{pid}").json()
    mesh = load_mesh(client.get(f"/api/projects/{pid}/mesh").content, project["mesh"]["format"])
    points = landmarks_from_json(client.get(f"/api/projects/{pid}/landmarks").json(), mesh.vertices, mesh.faces)
    return points.positions(mesh.vertices)
