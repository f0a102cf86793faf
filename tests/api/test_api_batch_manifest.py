"""A project and its takes exported as a batch manifest (server/routers/batch.py): the zip
unpacks into a manifest `retarget batch` runs, and the glTF it makes animates the take as
the project's own export.glb does."""

import io
import zipfile

import numpy as np
import pytest

from retarget.batch import plan_batch, read_manifest, run_batch
from retarget.cli import main
from retarget.gltf import read_gltf
from retarget.sample_face import demo_weights, sample_face


@pytest.fixture(scope="module")
def project(client):
    """The sample project's id, with one take uploaded: (pid, take info)."""
    pid = next(p["id"] for p in client.get("/api/projects").json() if p["landmarks"])
    assert client.get(f"/api/projects/{pid}/manifest.zip").status_code == 409  # no takes yet
    face = sample_face(identity=np.array([0.8, 0.5, -0.6]))
    lm = np.asarray(face.landmarks68)
    frames = face.vertices[lm] + np.tensordot(demo_weights(30, 30.0), face.expressions[:, lm], axes=1)
    buffer = io.BytesIO()
    np.save(buffer, frames.astype(np.float32))
    r = client.post(f"/api/projects/{pid}/takes", files={"file": ("smile.npy", buffer.getvalue())},
                    data={"layout": "ibug68", "fps": "30"})
    assert r.status_code == 201, r.text
    return pid, r.json()


def test_project_manifest_runs_as_a_batch(client, project, tmp_path):
    pid, take = project
    r = client.get(f"/api/projects/{pid}/manifest.zip", params={"outputs": "gltf,npy"})
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/zip"
    assert r.content == client.get(f"/api/projects/{pid}/manifest.zip", params={"outputs": "gltf,npy"}).content
    zipfile.ZipFile(io.BytesIO(r.content)).extractall(tmp_path / "in")
    manifest = read_manifest(tmp_path / "in" / "manifest.json")
    assert len(manifest.characters) == 1 and [t.name for t in manifest.takes] == ["smile"]
    report = run_batch(plan_batch(manifest, tmp_path / "out"), workers=0)
    assert report.failed == {} and len(report.succeeded) == 1
    made = read_gltf(next((tmp_path / "out").rglob("animation.glb")))
    exported = read_gltf(client.get(f"/api/projects/{pid}/export.glb", params={"takes": take["id"]}).content)
    np.testing.assert_allclose(made.clips[0].displacements, exported.clips[0].displacements, atol=1e-4)
    assert next((tmp_path / "out").rglob("vertices.npy")).is_file()
    # the zip as it is: `retarget batch BATCH.zip` unpacks it beside the outputs and runs it
    (tmp_path / "batch.zip").write_bytes(r.content)
    assert main(["batch", str(tmp_path / "batch.zip"), "--out", str(tmp_path / "out2"), "--no-dask", "-q"]) == 0
    assert (next((tmp_path / "out2").rglob("animation.glb")).read_bytes()
            == next((tmp_path / "out").rglob("animation.glb")).read_bytes())


def test_manifest_refusals(client, project):
    pid, _ = project
    assert client.get("/api/projects/AAAAAAAAAAAAAAAAAAAAAA/manifest.zip").status_code == 404
    r = client.get(f"/api/projects/{pid}/manifest.zip", params={"outputs": "gif"})
    assert r.status_code == 422 and "outputs" in r.json()["detail"]
    r = client.get(f"/api/projects/{pid}/manifest.zip", params={"settings": '{"filter": "wobbly"}'})
    assert r.status_code == 422 and "filter" in r.json()["detail"]
    assert client.get("/api/manifest.zip", params={"projects": "all"}).status_code == 200
