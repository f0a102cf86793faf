"""A ring-marker video tracked with every marker in view (``layout=*``, issue 17): the take
names its columns m01..mM, and keeps the first frame (a JPEG the server encodes, at most
640 px wide) with where each column is on it, for the page to make the user's own layout
by clicking the markers. Checked against the rendered truth; refusals, deletion and a
restart."""

from __future__ import annotations

import io
import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from retarget.testing.marker_video import render_marker_video
from server.app import create_app
from tests.waits import wait_job

FRAMES = 30
EVIL = "http://evil.example"


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return tmp_path_factory.mktemp("own-markers") / "data"


@pytest.fixture(scope="module")
def client(data):
    with TestClient(create_app(data, sample=False)) as c:
        yield c


@pytest.fixture(scope="module")
def project(client) -> str:
    return client.post("/api/projects", json={"name": "own markers"}).json()["id"]


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    """(bytes, truth, path) of a 30-frame 640x480 ring-marker video of dutreve21's 21 markers."""
    path = tmp_path_factory.mktemp("video") / "rings.mkv"
    truth = render_marker_video(path, n_frames=FRAMES, seed=3, start=0.55)
    return path.read_bytes(), truth, path


def track(client, pid, name, data, **fields):
    r = client.post(f"/api/projects/{pid}/takes/track", files={"file": (name, data)},
                    data={"method": "markers", **fields})
    assert r.status_code == 202, r.text
    job = wait_job(client, r.json()["id"], timeout_s=120, poll_s=0.05)
    assert job["state"] == "done", job["detail"]
    return job["result"]["take"]


@pytest.fixture(scope="module")
def own_take(client, project, video):
    return track(client, project, "rings.mkv", video[0], layout="*")


def test_every_marker_in_view_becomes_a_column_named_m01_on(client, project, video, own_take):
    info = client.get(f"/api/projects/{project}/takes/{own_take}").json()
    assert (info["name"], info["source"], info["layout"], info["dims"]) == ("rings", "markers", None, 2)
    assert (info["n_frames"], info["n_points"]) == (FRAMES, 21)
    names = client.get(f"/api/projects/{project}/layouts/from-take/{own_take}").json()["names"]
    assert names == [f"m{k:02d}" for k in range(1, 22)]


def test_the_first_frame_and_each_marker_on_it_are_served(client, project, video, own_take):
    truth = video[1]
    r = client.get(f"/api/projects/{project}/takes/{own_take}/preview")
    assert r.status_code == 200 and r.headers["content-type"] == "image/jpeg"
    image = cv2.imdecode(np.frombuffer(r.content, np.uint8), cv2.IMREAD_COLOR)
    assert image.shape == (480, 640, 3)
    markers = client.get(f"/api/projects/{project}/takes/{own_take}/preview/markers").json()
    assert markers["size"] == [640, 480]
    assert [m["name"] for m in markers["markers"]] == [f"m{k:02d}" for k in range(1, 22)]
    places = np.array([[np.nan if m["x"] is None else m["x"], np.nan if m["y"] is None else m["y"]]
                       for m in markers["markers"]])
    # the take's first frame, y flipped: null where the tracker had no marker yet (it
    # picks up the nose alae of this clip a few frames in)
    points = np.load(io.BytesIO(client.get(f"/api/projects/{project}/takes/{own_take}/points").content))
    np.testing.assert_allclose(places, points[0] * [1, -1] + [0, 480], atol=0.01)
    seen = np.isfinite(places[:, 0])
    assert seen.sum() >= 19
    # each column seen is on one rendered marker of the first frame (x right, y down), no two on one
    distance = np.linalg.norm(places[seen][:, None] - truth.points2d[0, 0][None], axis=2)
    assert distance.min(axis=1).max() < 1.0
    assert len(set(distance.argmin(axis=1))) == seen.sum()
    # the image shows the video's first frame: a ring's dark outline around a bright dot
    x, y = np.round(places[0]).astype(int)
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY).astype(float)
    assert grey[y, x] > grey[y - 8:y + 9, x - 8:x + 9].min() + 60


def test_a_wide_video_s_preview_is_scaled_to_640_px(client, project, video, own_take, tmp_path):
    """The clip's frames on a canvas twice as wide: the markers keep their pixels."""
    capture = cv2.VideoCapture(str(video[2]))
    path = tmp_path / "wide.mkv"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 30.0, (1280, 480))
    while (read := capture.read())[0]:
        writer.write(np.pad(read[1], ((0, 0), (0, 640), (0, 0))))
    writer.release()
    take = track(client, project, "wide.mkv", path.read_bytes(), layout="*")
    r = client.get(f"/api/projects/{project}/takes/{take}/preview")
    image = cv2.imdecode(np.frombuffer(r.content, np.uint8), cv2.IMREAD_COLOR)
    assert image.shape == (240, 640, 3)
    wide = client.get(f"/api/projects/{project}/takes/{take}/preview/markers").json()
    assert wide["size"] == [1280, 480]
    narrow = client.get(f"/api/projects/{project}/takes/{own_take}/preview/markers").json()
    assert wide["markers"] == narrow["markers"]  # places stay in the video's pixels
    assert client.delete(f"/api/projects/{project}/takes/{take}").status_code == 204


def _followed(points, truth) -> np.ndarray:
    """(M,) the rendered marker each column of a take (y up) follows: the nearest in the
    first frame where the column is seen."""
    seen = np.isfinite(points[..., 0])
    first = seen.argmax(axis=0)
    xy = points[first, np.arange(points.shape[1])] * [1, -1] + [0, 480]
    return np.linalg.norm(xy[:, None] - truth.points2d[first, 0], axis=2).argmin(axis=1)


def test_a_layout_made_of_the_markers_names_them_in_the_next_video(client, project, video, own_take, tmp_path):
    """The layout made from the take keeps where each marker sat (the from-take answer's
    reference); a second video of the same markers, other head motion, tracked in that
    layout, has each point follow the marker it followed in the first."""
    made = client.get(f"/api/projects/{project}/layouts/from-take/{own_take}").json()
    assert len(made["reference"]) == len(made["names"]) and all(len(r) == 3 for r in made["reference"])
    spec = {"points": [{"name": n, "region": "cheeks", "side": "center", "reference": r}
                       for n, r in zip(made["names"], made["reference"])]}
    r = client.put(f"/api/projects/{project}/layouts/rings", json=spec)
    assert r.status_code in (200, 201), r.text
    path = tmp_path / "again.mkv"
    truth = render_marker_video(path, n_frames=FRAMES, seed=7, start=2.0)
    again = track(client, project, "again.mkv", path.read_bytes(), layout="rings")
    info = client.get(f"/api/projects/{project}/takes/{again}").json()
    assert info["layout"] == r.json()["name"] and info["n_points"] == len(made["names"])

    def points(take):
        return np.load(io.BytesIO(client.get(f"/api/projects/{project}/takes/{take}/points").content))

    np.testing.assert_array_equal(_followed(points(again), truth), _followed(points(own_take), video[1]))


def test_every_marker_is_for_ring_markers_and_stereo_stickers(client, project):
    r = client.post(f"/api/projects/{project}/takes/track", files={"file": ("v.mkv", b"x")},
                    data={"method": "markerless", "layout": "*"})
    assert r.status_code == 422, r.text
    assert r.json()["detail"] == ("layout '*' (every marker in view) is for methods 'markers' and 'stereo'; "
                                  "'markerless' tracks a layout's points")
    # stereo: every sticker of one colour (tests/api/test_api_track_stickers.py); here the
    # pair's own checks refuse it
    r = client.post(f"/api/projects/{project}/takes/track", files={"file": ("v.mkv", b"x")},
                    data={"method": "stereo", "layout": "*"})
    assert r.status_code == 422 and "'right', which is missing" in r.json()["detail"], r.text


def test_takes_without_a_preview_and_bad_ids_are_404(client, project):
    data = b'{"names": ["a", "b", "c"], "frames": [[[0, 0, 0], [1, 0, 0], [0, 1, 0]]]}'
    r = client.post(f"/api/projects/{project}/takes", files={"file": ("x.json", data)}, data={"fps": "30"})
    assert r.status_code == 201, r.text
    plain = r.json()["id"]
    for path in ("preview", "preview/markers"):
        r = client.get(f"/api/projects/{project}/takes/{plain}/{path}")
        assert r.status_code == 404 and "has no first-frame preview" in r.json()["detail"]
        for bad in ("..%2F..%2Findex.sqlite", "AAAAAAAAAAAAAAAA", "x" * 300):
            assert client.get(f"/api/projects/{project}/takes/{bad}/{path}").status_code == 404
        assert client.get(f"/api/projects/AAAAAAAAAAAAAAAAAAAAAA/takes/{plain}/{path}").status_code == 404


def test_another_origin_cannot_track(client, project, video):
    before = client.get(f"/api/projects/{project}/takes").json()
    r = client.post(f"/api/projects/{project}/takes/track", files={"file": ("rings.mkv", video[0])},
                    data={"method": "markers", "layout": "*"}, headers={"Origin": EVIL})
    assert r.status_code == 403
    assert client.get(f"/api/projects/{project}/takes").json() == before


def test_the_preview_survives_a_restart_and_goes_with_its_take(client, project, data, video):
    take = track(client, project, "again.mkv", video[0], layout="*")
    jpeg = client.get(f"/api/projects/{project}/takes/{take}/preview").content
    with TestClient(create_app(data, sample=False)) as second:  # its store sweeps the folder
        assert second.get(f"/api/projects/{project}/takes/{take}/preview").content == jpeg
        assert second.delete(f"/api/projects/{project}/takes/{take}").status_code == 204
    assert client.get(f"/api/projects/{project}/takes/{take}/preview").status_code == 404
    assert not list((data / "projects" / project).glob(f"take-{take}.*"))
