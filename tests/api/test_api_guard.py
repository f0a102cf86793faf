"""The door of the API (`server.access`, `server.limits`, `server.errors`): foreign Host
names, other web pages and, off loopback, requests without the access token are
refused; request bodies are held to their route's cap; every refusal is
``{"detail": str}`` as the OpenAPI schema says; a retried take upload is stored once.

In process with FastAPI's TestClient; `tests/e2e/test_server_guard.py` checks the same
on a real port with real clients and a real browser."""

from __future__ import annotations

import io
import json
import os
import re
import stat

import numpy as np
import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from retarget.layouts import get_layout
from server.access import TOKEN_COOKIE, Access, token_for
from server.app import create_app
from server.web import WEB_DIR, app_csp

EVIL = "http://evil.example"


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    return create_app(tmp_path_factory.mktemp("data"), max_upload_bytes=200_000)


@pytest.fixture
def client(app):
    with TestClient(app) as c:
        yield c


@pytest.fixture(scope="module")
def sample_id(app):
    return TestClient(app).get("/api/projects").json()[0]["id"]


def project_ids(client) -> list[str]:
    return [p["id"] for p in client.get("/api/projects").json()]


# -- Host ------------------------------------------------------------------------------------

@pytest.mark.parametrize("host", ["evil.example", "evil.example:8000", "127.0.0.1.evil.example",
                                  "localhost.evil.example:80", ""])
def test_a_foreign_host_name_is_refused(client, host):
    r = client.get("/api/projects", headers={"host": host})
    assert r.status_code == 400 and "does not answer to the host name" in r.json()["detail"]


@pytest.mark.parametrize("host", ["127.0.0.1:8000", "localhost:8000", "[::1]:8000", "LOCALHOST"])
def test_loopback_names_are_answered(client, host):
    assert client.get("/api/projects", headers={"host": host}).status_code == 200


def test_a_server_on_every_interface_answers_ip_literals_and_its_names_only():
    access = Access.for_bind("0.0.0.0", token="t" * 43, allowed_hosts=("faces.studio.lan",))
    assert all(access.host_allowed(h) for h in ("192.168.1.20:8000", "[fe80::1]:8000", "10.0.0.7",
                                                 "localhost", "faces.studio.lan:8000"))
    assert not any(access.host_allowed(h) for h in ("evil.example", "192.168.1.20.nip.io", None))
    with pytest.raises(ValueError, match="access token is required"):
        Access.for_bind("0.0.0.0")
    assert Access.for_bind("127.0.0.1").token is None
    assert not Access.for_bind("127.0.0.1").host_allowed("testserver")  # `retarget serve`: loopback only


# -- Origin ----------------------------------------------------------------------------------

@pytest.mark.parametrize("headers", [{"origin": EVIL}, {"origin": "null"},
                                     {"origin": "http://127.0.0.1:9999"},  # another port: another origin
                                     {"origin": "https://testserver"},     # another scheme
                                     {"sec-fetch-site": "cross-site"}, {"sec-fetch-site": "same-site"}])
def test_state_changing_requests_from_other_pages_are_refused_and_change_nothing(client, headers):
    before = project_ids(client)
    r = client.post("/api/projects", json={"name": "forged"}, headers=headers)
    assert r.status_code == 403 and "another web page" in r.json()["detail"]
    r = client.delete(f"/api/projects/{before[0]}", headers=headers)
    assert r.status_code == 403
    files = {"file": ("x.glb", b"glTF", "model/gltf-binary")}
    assert client.post("/api/projects/import", files=files, headers=headers).status_code == 403
    assert project_ids(client) == before


def test_the_app_s_own_page_and_plain_clients_may_change_state(client):
    own = client.post("/api/projects", json={"name": "own"},
                      headers={"origin": "http://testserver", "sec-fetch-site": "same-origin"})
    plain = client.post("/api/projects", json={"name": "curl"})  # no Origin: not a browser
    assert own.status_code == plain.status_code == 201
    for r in (own, plain):
        assert client.delete(f"/api/projects/{r.json()['id']}").status_code == 204


def test_reads_from_another_origin_get_no_cors_permission(client):
    r = client.get("/api/projects", headers={"origin": EVIL})
    assert r.status_code == 200 and "access-control-allow-origin" not in r.headers


def test_a_websocket_from_another_page_is_refused(client, sample_id):
    with pytest.raises(WebSocketDisconnect) as refused:
        with client.websocket_connect(f"/api/projects/{sample_id}/stream", headers={"origin": EVIL}):
            pass
    assert refused.value.code == 1008
    with client.websocket_connect(f"/api/projects/{sample_id}/stream",
                                  headers={"origin": "http://testserver"}) as ws:
        assert ws.receive_json()["type"] == "hello"


# -- access token ----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def token_app(tmp_path_factory):
    data = tmp_path_factory.mktemp("token")
    token = token_for(data)
    access = Access(hosts=frozenset({"testserver"}), token=token)
    return create_app(data, access=access), token


def test_off_loopback_every_request_needs_the_token(token_app):
    app, token = token_app
    client = TestClient(app)
    for path in ("/api/projects", "/docs", "/openapi.json", "/"):
        r = client.get(path)
        assert r.status_code == 401 and "access token" in r.json()["detail"], path
    assert client.get("/static/js/net/api.js").status_code == 200  # the client's code holds no data
    assert client.get("/api/projects", headers={"authorization": f"Bearer {token}"}).status_code == 200
    assert client.get("/api/projects", headers={"authorization": "Bearer wrong"}).status_code == 401
    assert client.get("/?token=wrong").status_code == 401


def test_the_printed_address_hands_the_token_to_the_page_as_a_cookie(token_app):
    app, token = token_app
    client = TestClient(app)
    r = client.get(f"/?token={token}", follow_redirects=False)
    assert r.status_code == 303 and r.headers["location"] == "/"
    cookie = r.headers["set-cookie"]
    assert cookie.startswith(f"{TOKEN_COOKIE}={token}") and "HttpOnly" in cookie
    assert "SameSite=Strict" in cookie and "Path=/" in cookie
    assert client.get("/").status_code == 200  # the cookie jar now holds it
    sample = client.get("/api/projects").json()[0]["id"]
    with client.websocket_connect(f"/api/projects/{sample}/stream") as ws:
        assert ws.receive_json()["type"] == "hello"
    stranger = TestClient(app)
    with pytest.raises(WebSocketDisconnect):
        with stranger.websocket_connect(f"/api/projects/{sample}/stream"):
            pass


def test_the_token_is_made_once_and_kept_private(tmp_path):
    token = token_for(tmp_path)
    assert len(token) >= 43 and token_for(tmp_path) == token
    mode = stat.S_IMODE(os.stat(tmp_path / "access-token").st_mode)
    assert mode == 0o600


# -- headers -----------------------------------------------------------------------------------

def test_answers_carry_the_security_headers_and_the_page_its_policy(client):
    for path in ("/", "/api/projects", "/static/js/net/api.js", "/api/projects/nope"):
        r = client.get(path)
        assert r.headers["x-content-type-options"] == "nosniff", path
        assert r.headers["x-frame-options"] == "DENY", path
        assert r.headers["referrer-policy"] == "no-referrer", path
    page = client.get("/")
    policy = page.headers["content-security-policy"]
    assert policy == app_csp((WEB_DIR / "static" / "index.html").read_text())
    assert "frame-ancestors 'none'" in policy and "object-src 'none'" in policy
    # the import map is the page's one inline script, allowed by its hash alone
    assert re.search(r"script-src 'self' 'wasm-unsafe-eval' 'unsafe-eval' 'sha256-[A-Za-z0-9+/]{43}='$",
                     policy.split(";")[1].strip())


# -- body limits ---------------------------------------------------------------------------------

def test_a_json_body_over_its_cap_is_413_before_it_is_parsed(client, sample_id):
    before = client.get(f"/api/projects/{sample_id}/landmarks").json()
    huge = {"positions": [[0.0, 0.0, 0.0]] * 120_000}  # ~1.9 MB of JSON
    r = client.put(f"/api/projects/{sample_id}/landmarks", json=huge)
    assert r.status_code == 413 and "over the limit of 1048576 bytes" in r.json()["detail"]
    assert client.get(f"/api/projects/{sample_id}/landmarks").json() == before


def test_an_upload_over_the_route_cap_is_413_by_its_declared_length(client):
    pid = client.post("/api/projects", json={"name": "cap"}).json()["id"]
    body = b"--b\r\n" + b"x" * 1_000_000  # over 3 files of 200 kB plus the multipart slack
    r = client.put(f"/api/projects/{pid}/mesh", content=body,
                   headers={"content-type": "multipart/form-data; boundary=b"})
    assert r.status_code == 413 and "over the limit" in r.json()["detail"]
    assert client.get(f"/api/projects/{pid}").json()["mesh"] is None
    r = client.put(f"/api/projects/{pid}/mesh", content=b"1",
                   headers={"content-type": "multipart/form-data; boundary=b", "content-length": "x1"})
    assert r.status_code == 400


def test_settings_are_bounded_when_created_and_when_merged(client):
    big = {"notes": "x" * 70_000}
    r = client.post("/api/projects", json={"name": "s", "settings": big})
    assert r.status_code == 422 and "the limit is 65536" in r.json()["detail"]
    pid = client.post("/api/projects", json={"name": "s", "settings": {"a": "x" * 40_000}}).json()["id"]
    r = client.patch(f"/api/projects/{pid}", json={"settings": {"b": "x" * 40_000}})
    assert r.status_code == 422
    assert set(client.get(f"/api/projects/{pid}").json()["settings"]) == {"a"}
    r = client.patch(f"/api/projects/{pid}", json={"settings": {"a": None, "b": "x" * 40_000}})
    assert r.status_code == 200 and set(r.json()["settings"]) == {"b"}


@pytest.mark.parametrize("layout", [0, False, [], {}, 68])
def test_a_landmarks_layout_that_is_not_a_name_is_refused(client, sample_id, layout):
    before = client.get(f"/api/projects/{sample_id}").json()
    r = client.put(f"/api/projects/{sample_id}/landmarks",
                   json={"vertex_indices": list(range(68)), "layout": layout})
    assert r.status_code == 422 and "must be a layout name" in r.json()["detail"]
    assert client.get(f"/api/projects/{sample_id}").json() == before


# -- one error shape -------------------------------------------------------------------------------

def test_request_validation_errors_are_one_sentence(client):
    r = client.post("/api/projects", json={"name": ""})
    assert r.status_code == 422
    assert r.json()["detail"] == "body field 'name': String should have at least 1 character"
    r = client.get("/api/projects/x/export.glb", params={"takes": 5})
    assert r.status_code == 404 and isinstance(r.json()["detail"], str)


def test_a_body_too_deep_to_parse_says_so(client):
    r = client.post("/api/projects", content=b"[" * 200_000 + b"]" * 200_000,
                    headers={"content-type": "application/json"})
    assert r.status_code == 400 and r.json()["detail"] == "the request body is nested too deeply to read"


def test_a_wrong_method_names_every_method_of_the_path(client, sample_id):
    r = client.put("/api/projects")
    assert r.status_code == 405 and r.headers["allow"] == "GET, HEAD, POST"
    r = client.post(f"/api/projects/{sample_id}")
    assert r.status_code == 405 and r.headers["allow"] == "DELETE, GET, HEAD, PATCH"
    assert isinstance(r.json()["detail"], str)


def test_the_schema_documents_every_refusal_as_a_string_detail(client):
    schema = client.get("/openapi.json").json()
    components = schema["components"]["schemas"]
    assert "HTTPValidationError" not in components
    assert components["Error"]["properties"]["detail"]["type"] == "string"
    for path, methods in schema["paths"].items():
        for method, operation in methods.items():
            codes = set(operation["responses"])
            assert {"400", "403", "413", "422"} <= codes, (method, path)
            if "{project_id}" in path or "{job_id}" in path:
                assert "404" in codes, (method, path)
            for code in codes - {"200", "201", "202", "204"}:
                content = operation["responses"][code]["content"]["application/json"]
                assert content["schema"] == {"$ref": "#/components/schemas/Error"}, (method, path, code)
    upload = schema["paths"]["/api/projects/{project_id}/takes"]["post"]["responses"]
    assert {"415", "503"} <= set(upload)


# -- WebSocket -----------------------------------------------------------------------------------

def test_a_deeply_nested_control_message_is_answered_and_the_stream_goes_on(client, sample_id):
    with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        assert ws.receive_json()["type"] == "hello"
        ws.send_text("[" * 200_000 + "]" * 200_000)
        reply = ws.receive_json()
        assert reply == {"type": "error", "detail": "control message is nested too deeply to be one of ours"}
        ws.send_text(json.dumps({"type": "ping", "t": 1}))
        assert ws.receive_json()["type"] == "pong"


# -- idempotent take uploads ----------------------------------------------------------------------

def _take_npy() -> bytes:
    n = get_layout("ibug68").n_points
    buffer = io.BytesIO()
    np.save(buffer, np.random.default_rng(0).normal(size=(5, n, 3)).astype(np.float32))
    return buffer.getvalue()


def test_a_retried_upload_with_its_key_is_stored_once(client):
    pid = client.post("/api/projects", json={"name": "retry"}).json()["id"]
    url = f"/api/projects/{pid}/takes"

    def upload(key):
        headers = {} if key is None else {"idempotency-key": key}
        return client.post(url, files={"file": ("t.npy", _take_npy())}, data={"layout": "ibug68"},
                           headers=headers)

    first, again = upload("k-1"), upload("k-1")
    assert first.status_code == 201 and again.status_code == 200
    assert again.json() == first.json()
    other = upload("k-2")
    assert other.status_code == 201 and other.json()["id"] != first.json()["id"]
    assert [t["id"] for t in client.get(url).json()] == [first.json()["id"], other.json()["id"]]
    assert upload(None).status_code == 201  # without a key every upload is new
    r = upload("no spaces allowed")
    assert r.status_code == 422 and "Idempotency-Key" in r.json()["detail"]
    assert len(client.get(url).json()) == 3
