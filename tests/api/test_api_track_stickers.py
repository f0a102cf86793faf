"""Woodward's unnamed stickers of one colour tracked by the server (issue 17 §2 and §3):
``POST .../takes/track`` with method stereo and layout ``*`` follows every sticker of the
chosen colour through a rendered vertical webcam pair (issue 17's take: 13 blue stickers,
head turns that hide a temple) into a take of columns m01..mM in the head frame, as
``retarget track --method stereo`` does without a layout; a layout made from the take
(``GET .../layouts/from-take``) keeps where each sticker sits, which live sessions are
named by. Wrong colours and anchors are refused before any tracking, naming the field."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from retarget.sources.stereo import track_stereo_videos
from retarget.testing.stereo_rig import STICKER_ANCHORS, render_sticker_video, rig_calibration, sticker_scores
from tests.waits import wait_job


@pytest.fixture(scope="module")
def stickers(tmp_path_factory):
    """The pair's files as bytes by form name, their paths, the exact calibration and truth."""
    folder = tmp_path_factory.mktemp("stickers")
    truth = render_sticker_video(folder / "take.mp4", n_frames=45, seed=1)
    calibration = rig_calibration(*truth.cameras)
    calibration.save(folder / "rig.npz")
    paths = {"file": Path(truth.videos[0]), "right": Path(truth.videos[1]), "calibration": folder / "rig.npz"}
    files = {field: (path.name, path.read_bytes()) for field, path in paths.items()}
    return files, paths, calibration, truth


def track(client, pid, files, **fields):
    return client.post(f"/api/projects/{pid}/takes/track", files=files,
                       data={"method": "stereo", "layout": "*", **fields})


def test_stickers_of_one_colour_become_a_take_and_a_layout_by_place(client, sample_id, stickers):
    files, paths, calibration, truth = stickers
    r = track(client, sample_id, files, color="Blue", name="stickers")
    assert r.status_code == 202, r.text
    job = wait_job(client, r.json()["id"], timeout_s=120, poll_s=0.05)
    assert job["state"] == "done", job["detail"]
    take_id = job["result"]["take"]
    info = client.get(f"/api/projects/{sample_id}/takes/{take_id}").json()
    assert (info["source"], info["layout"], info["dims"], info["n_frames"]) == ("stereo", None, 3, 45)
    points = np.load(io.BytesIO(client.get(f"/api/projects/{sample_id}/takes/{take_id}/points").content))
    # the library's own unnamed sticker tracking, head motion removed on the chosen anchors
    local = track_stereo_videos(paths["file"], paths["right"], calibration, layout=None, color="blue")
    np.testing.assert_allclose(points, local.points, atol=1e-3)
    names = client.get(f"/api/projects/{sample_id}/layouts/from-take/{take_id}").json()
    assert names["names"] == [f"m{k:02d}" for k in range(1, 14)]
    # every sticker its own column, each column on one sticker (owners from the camera frame)
    kept = track_stereo_videos(paths["file"], paths["right"], calibration, layout=None, head_motion="keep")
    scores = sticker_scores(kept.points, points, truth)
    assert sorted(scores["owner"]) == list(range(13)) and scores["switches"] == 0
    # mm, the shape in the head frame (a take that kept the head motion would be tens of mm
    # off); anchors chosen on 1.5 s are rough, as in `bench/stereo.py`'s short takes
    assert np.nanmedian(scores["error"]) < 4.0
    # the layout's reference keeps each sticker's place, with depth
    reference = np.array(names["reference"])
    assert reference.shape == (13, 3) and np.ptp(reference[:, 2]) > 1.0   # cm on the built-in face's scale
    # named anchors: the take is in the head frame of those stickers
    anchors = ",".join(f"m{m + 1:02d}" for m in np.flatnonzero(scores["owner"] < STICKER_ANCHORS))
    r = track(client, sample_id, files, anchors=anchors)
    assert r.status_code == 202, r.text
    job = wait_job(client, r.json()["id"], timeout_s=120, poll_s=0.05)
    assert job["state"] == "done", job["detail"]
    named = np.load(io.BytesIO(client.get(f"/api/projects/{sample_id}/takes/{job['result']['take']}/points").content))
    error = sticker_scores(kept.points, named, truth)["error"]
    assert np.nanmedian(error) < 2.5 and np.nanmedian(error) < np.nanmedian(scores["error"])


def test_bad_sticker_requests_are_refused_before_tracking(client, app, sample_id, stickers):
    files = stickers[0]
    before = client.get(f"/api/projects/{sample_id}/takes").json()
    cases = [
        ({"color": "purple"}, "unknown sticker colour 'purple'"),
        ({"color": "300,0,0"}, "B, G and R are 0-255"),
        ({"anchors": "m01,m02"}, "at least 3 different stickers"),
        ({"anchors": "m01,m02,nose"}, "'nose' is none"),
        ({"color": "green"}, "of colour 'green' seen by both cameras; at least 3 are needed"),
        ({"layout": "dutreve21", "color": "blue"}, "'color' and 'anchors' are for method 'stereo' with layout '*'"),
    ]
    for fields, message in cases:
        r = track(client, sample_id, files, **fields)
        assert r.status_code == 422 and message in r.json()["detail"], (fields, r.text)
    r = client.post(f"/api/projects/{sample_id}/takes/track", files={"file": files["file"]},
                    data={"method": "markerless", "layout": "*"})
    assert r.status_code == 422 and "for methods 'markers' and 'stereo'" in r.json()["detail"]
    assert client.get(f"/api/projects/{sample_id}/takes").json() == before
    assert list(app.state.store.scratch_dir.iterdir()) == []
