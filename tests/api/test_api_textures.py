"""A textured mesh through the API: an OBJ uploaded with its MTL and image (or one zip of
them) is stored as one zip, its texture is served as PNG and kept in the export; side
files of other kinds, too many of them, or a missing image are refused and change
nothing."""

from __future__ import annotations

import io
import zipfile

import pytest
from fastapi.testclient import TestClient
from PIL import Image

from retarget.gltf import read_gltf
from server.app import create_app
from tests.unit.test_textures import MTL, _image, _obj


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    with TestClient(create_app(tmp_path_factory.mktemp("textures"), sample=False)) as c:
        yield c


def _project(client) -> str:
    return client.post("/api/projects", json={"name": "scan"}).json()["id"]


def _upload(client, pid, files):
    return client.put(f"/api/projects/{pid}/mesh", files=files)


def test_an_obj_with_its_mtl_and_image_is_stored_and_its_texture_served(client):
    pid = _project(client)
    r = _upload(client, pid, [("file", ("head.obj", _obj())), ("files", ("face.mtl", MTL)),
                              ("files", ("skin.jpg", _image(size=(32, 16))))])
    assert r.status_code == 200, r.text
    assert r.json()["mesh"] == {"filename": "head.obj", "format": "zip", "n_vertices": 4, "n_faces": 2}
    texture = client.get(f"/api/projects/{pid}/mesh/texture")
    assert texture.status_code == 200 and texture.headers["content-type"] == "image/png"
    assert Image.open(io.BytesIO(texture.content)).size == (32, 16)
    stored = zipfile.ZipFile(io.BytesIO(client.get(f"/api/projects/{pid}/mesh").content))
    assert sorted(stored.namelist()) == ["face.mtl", "head.obj", "skin.jpg"]


def test_a_zip_of_them_is_read_as_it_is_and_the_texture_reaches_the_export(client):
    pid = _project(client)
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("scan/head.obj", _obj())
        archive.writestr("scan/face.mtl", MTL)
        archive.writestr("scan/maps/skin.jpg", _image())
    r = _upload(client, pid, {"file": ("scan.zip", out.getvalue())})
    assert r.status_code == 200 and r.json()["mesh"]["format"] == "zip", r.text
    r = client.put(f"/api/projects/{pid}/landmarks", json={"vertex_indices": [0, 1, 2]})
    assert r.status_code == 200, r.text
    job = client.post(f"/api/projects/{pid}/rig", json={"method": "ellipsoid"}).json()
    client.app.state.jobs.wait(job["id"], 120)
    glb = client.get(f"/api/projects/{pid}/export.glb")
    assert glb.status_code == 200, glb.text
    face = read_gltf(glb.content)
    assert Image.open(io.BytesIO(face.mesh.material.base_color_texture)).size == (16, 8)


@pytest.mark.parametrize("files, code, reason", [
    ([("files", ("face.mtl", MTL)), ("files", ("run.exe", b"MZ"))], 415, "'.exe'"),
    ([("files", ("face.mtl", MTL))], 422, "uses the texture image 'skin.jpg', which was not given"),
    ([("files", (f"{i}.png", b"x")) for i in range(17)], 422, "at most 16"),
])
def test_side_files_that_do_not_belong_are_refused_and_nothing_is_stored(client, files, code, reason):
    pid = _project(client)
    r = _upload(client, pid, [("file", ("head.obj", _obj()))] + files)
    assert r.status_code == code and reason in r.json()["detail"], r.text
    assert client.get(f"/api/projects/{pid}").json()["mesh"] is None
    assert client.get(f"/api/projects/{pid}/mesh/texture").status_code == 409


def test_a_mesh_without_a_texture_has_none_to_serve(client):
    pid = _project(client)
    assert _upload(client, pid, {"file": ("head.obj", _obj())}).status_code == 200
    r = client.get(f"/api/projects/{pid}/mesh/texture")
    assert r.status_code == 404 and "has no texture" in r.json()["detail"]
