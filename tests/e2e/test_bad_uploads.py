"""Bad uploads in the browser: each shows the server's reason and loses nothing."""

from __future__ import annotations

import json

import pytest

from tests.e2e.conftest import Server, sample_copy
from tests.waits import scaled_ms


@pytest.fixture(scope="module")
def small_server(tmp_path_factory, sample_data_dir):
    """A server that takes uploads of at most 0.25 MiB, so "too big" is quick to send."""
    srv = Server(sample_copy(sample_data_dir, tmp_path_factory.mktemp("small") / "data"),
                 args=("--max-upload-mb", "0.25")).start()
    yield srv
    srv.stop()



BAD = {
    "not_a_mesh.obj": (b"this is not a mesh\n" * 10, "no triangle mesh"),
    "empty.ply": (b"", "empty"),
    "nan.obj": (b"v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n", "NaN"),
    "huge.obj": (b"v 0 0 0\n" * 40_000, "over the limit"),
    "face.docx": (b"PK\x03\x04", ".docx"),
}


@pytest.mark.parametrize("name", list(BAD))
def test_bad_upload_shows_the_reason_and_keeps_projects(small_server, page, tmp_path, name):
    data, reason = BAD[name]
    projects = json.loads(small_server.read("/api/projects"))
    (sample,) = projects
    before = {path: small_server.read(f"/api/projects/{sample['id']}{path}")
              for path in ("", "/mesh/arrays", "/landmarks", "/rig/weights")}

    page.goto(f"{small_server.url}/#p={sample['id']}")
    page.wait_for_function("() => window.app && window.app.projectId")
    page.evaluate("() => window.app.ready")
    file = tmp_path / name
    file.write_bytes(data)
    page.set_input_files("#file-input", str(file))
    page.wait_for_function("() => document.querySelector('#error').innerText.trim() !== ''",
                           timeout=scaled_ms(15_000))
    message = page.inner_text("#error")
    assert reason.lower() in message.lower(), message

    after = {path: small_server.read(f"/api/projects/{sample['id']}{path}") for path in before}
    assert after == before
    assert json.loads(small_server.read("/api/projects")) == projects
    # the face on screen is still the sample's
    n = json.loads(before[""])["mesh"]["n_vertices"]
    assert page.evaluate("() => window.app.face.mesh.geometry.attributes.position.count") == n
