"""The Export panel's *Batch manifest*: the project and its takes downloaded as the zip the
server makes for the panel's conditioning (server/routers/batch.py), which `retarget
batch` reads; a project without takes is refused with the server's reason."""

from __future__ import annotations

import io
import json
import zipfile

import httpx
import numpy as np

from retarget.sample_face import demo_weights, sample_face
from tests.e2e.conftest import open_project
from tests.waits import scaled_ms


def test_batch_manifest_button_downloads_the_projects_batch(server, page, tmp_path):
    pid = next(p["id"] for p in server.api("GET", "/api/projects") if p["settings"].get("sample"))
    open_project(page, server, pid)
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 68", timeout=scaled_ms(30_000))
    page.click("#export-manifest")  # no takes yet
    page.wait_for_function("() => document.getElementById('export-note').textContent.includes('no takes')")

    face = sample_face(identity=np.array([0.8, 0.5, -0.6]))
    lm = np.asarray(face.landmarks68)
    frames = face.vertices[lm] + np.tensordot(demo_weights(30, 30.0), face.expressions[:, lm], axes=1)
    buffer = io.BytesIO()
    np.save(buffer, frames.astype(np.float32))
    r = httpx.post(f"{server.url}/api/projects/{pid}/takes", timeout=30,
                   files={"file": ("talk.npy", buffer.getvalue())}, data={"layout": "ibug68", "fps": "30"})
    assert r.status_code == 201, r.text
    page.evaluate("() => window.app.errors.clear()")
    with page.expect_download() as download:
        page.click("#export-manifest")
    assert download.value.suggested_filename == "Sample-face.manifest.zip"
    path = tmp_path / "batch.zip"
    download.value.save_as(path)
    settings = page.evaluate("() => JSON.stringify(window.app.conditioning.toJSON())")
    expected = httpx.get(f"{server.url}/api/projects/{pid}/manifest.zip", timeout=60,
                         params={"settings": settings, "outputs": "gltf,arkit_csv,npy"}).content
    assert path.read_bytes() == expected
    manifest = json.loads(zipfile.ZipFile(path).read("manifest.json"))
    assert [t["name"] for t in manifest["takes"]] == ["talk"] and len(manifest["characters"]) == 1
    assert page.inner_text("#export-note").startswith("Saved Sample-face.manifest.zip")
