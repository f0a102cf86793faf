"""A take's `source` says what made it: the page sends one for the points it tracked from a
video ('video: clip.mp4'), else it is the file's format."""

from __future__ import annotations

import io

import numpy as np
import pytest
from fastapi.testclient import TestClient

from server.app import create_app


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    with TestClient(create_app(tmp_path_factory.mktemp("source"), sample=False)) as c:
        yield c


def _upload(client, **fields):
    """(project id, the answer) of a bare .npy take uploaded with `fields`."""
    pid = client.post("/api/projects", json={"name": "takes"}).json()["id"]
    out = io.BytesIO()
    np.save(out, np.zeros((3, 21, 3), np.float32))
    return pid, client.post(f"/api/projects/{pid}/takes", files={"file": ("clip.npy", out.getvalue())},
                            data={"layout": "dutreve21", "fps": "30", **fields})


def test_a_take_keeps_the_source_it_was_sent_with(client):
    pid, r = _upload(client, source="video: clip.mp4")
    assert r.status_code == 201, r.text
    assert r.json()["source"] == "video: clip.mp4"
    assert [t["source"] for t in client.get(f"/api/projects/{pid}/takes").json()] == ["video: clip.mp4"]


def test_without_one_the_source_is_the_format_and_an_overlong_one_is_refused(client):
    assert _upload(client)[1].json()["source"] == "npy"
    _, r = _upload(client, source="v" * 201)
    assert r.status_code == 422 and "source" in r.json()["detail"]
