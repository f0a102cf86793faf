"""The client's files and the layouts route, in-process."""

import pytest
from fastapi.testclient import TestClient

from retarget.layouts import LAYOUTS, get_layout
from server.app import create_app
from server.web import VENDORED


@pytest.fixture
def client(tmp_path):
    return TestClient(create_app(tmp_path, sample=False))


def test_index_page_and_vendored_modules_are_served_locally(client):
    page = client.get("/")
    assert page.status_code == 200 and "<html" in page.text.lower()
    assert "cdn" not in page.text.lower() and "https://" not in page.text
    assert client.get("/vendor/three/build/three.module.js").status_code == 200
    assert client.get("/vendor/three-mesh-bvh/src/index.js").status_code == 200
    assert client.get("/static/js/net/wire.js").status_code == 200
    # the markerless tracker: its script, and the wasm it fetches with a type that
    # lets the browser compile it while it streams in
    assert client.get("/vendor/@mediapipe/face_mesh/face_mesh.js").status_code == 200
    wasm = client.get("/vendor/@mediapipe/face_mesh/face_mesh_solution_simd_wasm_bin.wasm")
    assert wasm.status_code == 200 and wasm.headers["content-type"] == "application/wasm"


def test_api_docs_load_swagger_ui_locally(client):
    docs = client.get("/docs")
    assert docs.status_code == 200
    assert "/vendor/swagger-ui-dist/swagger-ui-bundle.js" in docs.text
    assert "cdn" not in docs.text.lower() and "https://" not in docs.text
    assert client.get("/vendor/swagger-ui-dist/swagger-ui-bundle.js").status_code == 200
    assert client.get("/openapi.json").json()["info"]["title"] == "retarget"


def test_vendor_mounts_hold_only_the_listed_packages(client):
    assert VENDORED == ("three", "three-mesh-bvh", "swagger-ui-dist", "@mediapipe/face_mesh")
    assert client.get("/vendor/gltf-validator/package.json").status_code == 404
    assert client.get("/vendor/three/../../package.json").status_code == 404


def test_missing_npm_packages_give_a_page_that_says_how_to_install(tmp_path):
    from server.web import mount_web
    from fastapi import FastAPI

    web = tmp_path / "web"
    (web / "static").mkdir(parents=True)
    (web / "static" / "index.html").write_text("<html></html>")
    app = FastAPI()
    mount_web(app, web)
    reply = TestClient(app).get("/")
    assert reply.status_code == 503
    assert "npm ci --prefix web" in reply.text and "three" in reply.text


def test_layouts_list_every_layout_with_reference_positions(client):
    layouts = client.get("/api/layouts").json()
    assert [layout["name"] for layout in layouts] == list(LAYOUTS)
    for layout in layouts:
        lib = get_layout(layout["name"])
        assert layout["n_points"] == lib.n_points == len(layout["points"])
        assert [p["name"] for p in layout["points"]] == list(lib.point_names)
        assert [p["mirror"] for p in layout["points"]] == list(lib.mirror)
        assert [p["mediapipe468"] for p in layout["points"]] == list(lib.mediapipe468)
        for point in layout["points"]:
            assert len(point["reference"]) == 3
    ibug = next(layout for layout in layouts if layout["name"] == "ibug68")
    # the reference face looks down +z with the subject's right at -x
    right = [p["reference"][0] for p in ibug["points"] if p["side"] == "right"]
    left = [p["reference"][0] for p in ibug["points"] if p["side"] == "left"]
    assert max(right) < 0 < min(left)


def test_unknown_layout_is_refused_with_the_known_names(client):
    reply = client.get("/api/layouts/nope")
    assert reply.status_code == 422
    assert "ibug68" in reply.json()["detail"]


def test_info_says_what_the_server_accepts(tmp_path):
    from retarget.weights import DEFAULT_METHOD, METHODS

    info = TestClient(create_app(tmp_path, sample=False, max_upload_bytes=1234,
                                 max_vertices=99)).get("/api/info").json()
    assert info["max_upload_bytes"] == 1234 and info["max_vertices"] == 99
    assert "obj" in info["mesh_extensions"] and "glb" in info["mesh_extensions"]
    assert info["rig_methods"] == list(METHODS) and info["default_rig_method"] == DEFAULT_METHOD
