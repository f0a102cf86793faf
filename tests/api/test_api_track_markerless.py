"""Markerless tracking of a video on the server (``POST .../takes/track``, method
markerless): a job tracks a rendered face video whose points are known into a take of the
project's layout; a file that is not a video, a video without a face and one longer than
the server's frame limit are refused with the reason, and nothing is stored.

The face video is the built-in face with its jaw opening over 10 frames
(`retarget.testing.face_video`, lossless FFV1, so decoding adds no error); its truth is its
68 landmarks projected by the same camera.
"""

from __future__ import annotations

import io
import shutil

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.testing.face_video import render_face_video
from server.app import create_app
from server.readers import face_mesh_take
from tests.api.test_api_takes import write_video
from tests.waits import wait_job

SIZE, N_FRAMES, FPS = 480, 10, 30.0


@pytest.fixture(scope="module")
def face_video(tmp_path_factory):
    """(path, truth): the face opening its jaw over N_FRAMES frames (FFV1), and (F, 68, 2)
    its iBUG landmarks in pixels (x right, y up from the bottom edge, the take's)."""
    path = tmp_path_factory.mktemp("face") / "performer.mkv"
    return path, render_face_video(path, N_FRAMES, size=SIZE, fps=FPS)


@pytest.fixture(scope="module")
def noise_video(tmp_path_factory):
    """8 frames of noise: a video without a face."""
    rng = np.random.default_rng(4)
    frames = [rng.integers(0, 256, (96, 96, 3), dtype=np.uint8) for _ in range(8)]
    return write_video(tmp_path_factory.mktemp("noise") / "noise.mkv", frames)


def track(client, pid, filename, data, **fields):
    return client.post(f"/api/projects/{pid}/takes/track", files={"file": (filename, data)},
                       data={"method": "markerless", **fields})


def takes(client, pid) -> list[dict]:
    return client.get(f"/api/projects/{pid}/takes").json()


def scratch_files(app) -> list:
    return list(app.state.store.scratch_dir.iterdir())


def test_a_face_video_is_tracked_in_a_job_into_a_take_of_the_projects_layout(client, app, sample_id,
                                                                            face_video):
    path, truth = face_video
    before = takes(client, sample_id)
    r = track(client, sample_id, "performer.mkv", path.read_bytes())
    assert r.status_code == 202, r.text
    assert r.json()["kind"] == "track" and r.json()["state"] == "running"
    polled = []
    job = wait_job(client, r.json()["id"], timeout_s=120, poll_s=0.02, progress=polled)
    assert job["state"] == "done", job["detail"]
    assert polled == sorted(polled) and polled[-1] == 1.0
    result = job["result"]
    assert (result["frames"], result["frames_with_face"], result["frames_claimed"],
            result["truncated"]) == (N_FRAMES, N_FRAMES, N_FRAMES, False)
    assert job["detail"] == f"tracked {N_FRAMES} frames into take 'performer'"

    info = client.get(f"/api/projects/{sample_id}/takes/{result['take']}").json()
    # the sample project's landmarks are ibug68: the layout the take is in when none is sent
    assert (info["name"], info["source"], info["layout"]) == ("performer", "video: performer.mkv", "ibug68")
    assert (info["n_frames"], info["n_points"], info["dims"], info["fps"]) == (N_FRAMES, 68, 3, FPS)
    points = np.load(io.BytesIO(client.get(f"/api/projects/{sample_id}/takes/{info['id']}/points").content))
    assert points.shape == (N_FRAMES, 68, 3) and np.isfinite(points).all()

    # brows, eyes, nose and mouth on the rendered face's, each frame, within a few percent of
    # the eye distance (the jaw line of the generated face is its own design)
    eyes_apart = np.linalg.norm(truth[:, 36:42].mean(1) - truth[:, 42:48].mean(1), axis=1)
    error = np.linalg.norm(points[:, 17:, :2] - truth[:, 17:], axis=2) / eyes_apart[:, None]
    assert np.median(error, axis=1).max() < 0.08, np.median(error, axis=1)
    # the mouth opens with the rendered one: the inner lip gap follows the truth's
    gap = points[:, 62, 1] - points[:, 66, 1]
    true_gap = truth[:, 62, 1] - truth[:, 66, 1]
    assert np.corrcoef(gap, true_gap)[0, 1] > 0.9
    assert gap[-1] > 4 * max(gap[0], 1.0) and gap[-1] > 0.6 * true_gap[-1]
    assert [t["id"] for t in takes(client, sample_id)] == [t["id"] for t in before] + [info["id"]]
    assert scratch_files(app) == []

    # another layout's points come from the same face mesh: dutreve21's are ibug68's where
    # both layouts name the same point
    r = track(client, sample_id, "performer.mkv", path.read_bytes(), layout="dutreve21", name="lips")
    job = wait_job(client, r.json()["id"], timeout_s=120, poll_s=0.05)
    assert job["state"] == "done", job["detail"]
    dutreve = get_layout("dutreve21")
    lips = np.load(io.BytesIO(client.get(f"/api/projects/{sample_id}/takes/{job['result']['take']}/points").content))
    assert lips.shape == (N_FRAMES, 21, 3)
    ibug = get_layout("ibug68").point_names
    shared = [n for n in dutreve.point_names if n in ibug]
    assert len(shared) >= 10
    np.testing.assert_array_equal(lips[:, [dutreve.point_names.index(n) for n in shared]],
                                  points[:, [ibug.index(n) for n in shared]])
    for take in takes(client, sample_id)[len(before):]:
        client.delete(f"/api/projects/{sample_id}/takes/{take['id']}")


def test_a_file_that_is_not_a_video_is_refused_before_any_job(client, app, sample_id):
    project, before = client.get(f"/api/projects/{sample_id}").json(), takes(client, sample_id)
    r = track(client, sample_id, "notes.mp4", b"not a video at all\n" * 50)
    assert r.status_code == 422
    assert r.json()["detail"].startswith("'notes.mp4' is not a video OpenCV can open"), r.json()
    # a broken file with a video's first bytes, and an empty one
    r = track(client, sample_id, "broken.mp4", b"\x00\x00\x00\x18ftypmp42" + bytes(range(256)) * 40)
    assert r.status_code == 422 and "'broken.mp4'" in r.json()["detail"], r.json()
    r = track(client, sample_id, "empty.webm", b"")
    assert r.status_code == 422 and r.json()["detail"] == "the uploaded video 'empty.webm' is empty"
    r = track(client, sample_id, "face.gif", b"GIF89a")
    assert r.status_code == 415 and ".webm" in r.json()["detail"]
    r = track(client, sample_id, "face.mkv", b"x", layout="nope")
    assert r.status_code == 422 and "nope" in r.json()["detail"]
    assert client.get(f"/api/projects/{sample_id}").json() == project
    assert takes(client, sample_id) == before and scratch_files(app) == []


def test_a_video_without_a_face_fails_its_job_and_keeps_nothing(client, app, sample_id, noise_video):
    before = takes(client, sample_id)
    r = track(client, sample_id, "noise.mkv", noise_video.read_bytes())
    assert r.status_code == 202, r.text
    job = wait_job(client, r.json()["id"], timeout_s=120, poll_s=0.05)
    assert job["state"] == "failed" and job["result"] is None
    assert job["detail"] == "no face was found in any of the 8 frames of 'noise.mkv': nothing to keep"
    assert takes(client, sample_id) == before and scratch_files(app) == []


def test_a_video_over_the_frame_limit_is_refused(tmp_path, sample_data_dir, face_video):
    """Refused before tracking when the header says so (422); a header that claims fewer
    frames than the file holds is caught as the frames are read, within the limit."""
    path, _ = face_video
    data = tmp_path / "data"
    shutil.copytree(sample_data_dir, data)
    app = create_app(data, max_video_frames=N_FRAMES - 1)
    with TestClient(app) as client:
        pid = next(p["id"] for p in client.get("/api/projects").json() if p["settings"].get("sample"))
        r = track(client, pid, "performer.mkv", path.read_bytes())
        assert r.status_code == 422
        assert r.json()["detail"] == (f"video 'performer.mkv' has {N_FRAMES} frames (0.333 s at 30 fps); "
                                      f"the server tracks at most {N_FRAMES - 1} frames (0.3 s) of a "
                                      "video: cut it into shorter takes")
        assert takes(client, pid) == [] and scratch_files(app) == []
        # within the limit: tracked
        short = write_video(tmp_path / "short.mkv", [frame for _, frame in zip(range(N_FRAMES - 1), _frames(path))])
        r = track(client, pid, "short.mkv", short.read_bytes())
        job = wait_job(client, r.json()["id"], timeout_s=120, poll_s=0.05)
        assert job["state"] == "done" and job["result"]["frames"] == N_FRAMES - 1, job
    # the job's own bound, for a header that says less than the file holds
    with pytest.raises(RetargetError, match=r"^video 'performer.mkv' runs past 4 frames; the server "
                                            r"tracks at most 4 frames \(0.133 s\)"):
        face_mesh_take(path, "ibug68", 4, {path: "performer.mkv"}, None)


def _frames(path):
    capture = cv2.VideoCapture(str(path))
    while True:
        ok, frame = capture.read()
        if not ok:
            capture.release()
            return
        yield frame
