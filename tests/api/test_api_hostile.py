"""The audit's malformed files through the API: each is refused with a 4xx whose detail
names the problem (they were 500s, or accepted and broken later, or refused with a
message about something else), and the project is left as it was. A valid file with a
byte-order mark is accepted.

Through the real server, every read goes through an isolated child (`server.isolation`);
the library-level tests (test_source_files, test_mesh, test_landmarks) cover each
reader's checks in detail, and tests/e2e/test_fuzz_uploads.py mutates every format."""

from __future__ import annotations

import io
import json
import struct
import zipfile

import numpy as np
import pytest
from fastapi.testclient import TestClient

from server.app import create_app


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    with TestClient(create_app(tmp_path_factory.mktemp("hostile"))) as c:
        yield c


@pytest.fixture(scope="module")
def sample_id(client):
    return client.get("/api/projects").json()[0]["id"]


def _zip(patch=None) -> bytes:
    """A zip of two OBJ frames; `patch(bytearray, local_offset, central_offset)` edits it."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for i in range(2):
            archive.writestr(f"face_{i:04d}.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    data = bytearray(buffer.getvalue())
    if patch is not None:
        patch(data, 0, data.index(b"PK\x01\x02"))
    return bytes(data)


def _encrypted(data, local, central):
    data[local + 6] |= 1      # general purpose flag bit 0: encrypted
    data[central + 8] |= 1


def _unknown_method(data, local, central):
    struct.pack_into("<H", data, local + 8, 99)
    struct.pack_into("<H", data, central + 10, 99)


def _bad_crc(data, local, central):
    for offset in (local + 14, central + 16):
        struct.pack_into("<I", data, offset, 0x12345678)


def _npy_claiming(shape) -> bytes:
    header = f"{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}".encode()
    header += b" " * (-(10 + len(header) + 1) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header + b"\0" * 64


TAKES = {
    "csv cell over the csv module's field limit":
        ("huge.csv", b"frame,a_x,a_y\n0," + b"1" * 200_000 + b",2\n", {}, "row 2"),
    "json nested 200k deep":
        ("deep.json", b"[" * 200_000 + b"]" * 200_000, {}, "nested"),
    "npy header claiming 1.48 TiB":
        ("huge.npy", _npy_claiming((1_800_000_000, 68, 3)), {"layout": "ibug68"}, "1800000000"),
    "zip member encrypted":
        ("enc.zip", _zip(_encrypted), {"labelled_vertices": '{"a": 0}'}, "encrypted"),
    "zip member with an unknown compression method":
        ("odd.zip", _zip(_unknown_method), {"labelled_vertices": '{"a": 0}'}, "compress"),
    "zip member with a bad CRC":
        ("crc.zip", _zip(_bad_crc), {"labelled_vertices": '{"a": 0}'}, "CRC"),
    "mapping nested 200k deep":
        ("t.csv", b"frame,a_x,a_y\n0,1,2\n", {"mapping": "[" * 200_000 + "]" * 200_000},
         "form field 'mapping' is JSON nested too deeply to read"),
}


@pytest.mark.parametrize("case", TAKES)
def test_a_malformed_take_file_is_a_4xx_that_names_the_problem(client, sample_id, case):
    name, data, form, reason = TAKES[case]
    before = client.get(f"/api/projects/{sample_id}/takes").json()
    r = client.post(f"/api/projects/{sample_id}/takes", files={"file": (name, data)}, data=form)
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert detail.startswith(f"take file {name!r} refused: ") and reason in detail, detail
    assert client.get(f"/api/projects/{sample_id}/takes").json() == before


def _gltf(buffers, views, positions_count=3, scale=None) -> bytes:
    node = {"mesh": 0, **({"scale": [scale] * 3} if scale is not None else {})}
    return json.dumps({
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [node],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "buffers": buffers, "bufferViews": views,
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": positions_count,
                       "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}],
    }).encode()


_TRIANGLE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "<f4").tobytes()
_EMBEDDED = [{"byteLength": 36, "uri": "data:application/octet-stream;base64,"
              + __import__("base64").b64encode(_TRIANGLE).decode()}]


def _binary_stl(claimed: int, actual: int) -> bytes:
    triangle = struct.pack("<12fH", *([0.0] * 3 + [0, 0, 0, 1, 0, 0, 0, 1, 0]), 0)
    return b"\0" * 80 + struct.pack("<I", claimed) + triangle * actual


MESHES = {
    "all-degenerate OBJ": ("flat.obj", b"v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 2 3 4\n", "zero area"),
    "one-vertex mesh": ("dot.obj", b"v 0 0 0\nf 1 1 1\n", "vert"),
    "binary STL with a wrong triangle count": ("cut.stl", _binary_stl(1000, 2), "1,000 triangles"),
    "glTF buffer with an external URI": (
        "ext.gltf", _gltf([{"byteLength": 36, "uri": "mesh.bin"}], [{"buffer": 0, "byteLength": 36}]),
        "'mesh.bin'"),
    "glTF bufferView past its buffer": (
        "past.gltf", _gltf(_EMBEDDED, [{"buffer": 0, "byteOffset": 24, "byteLength": 36}]), "bufferView 0"),
    "OBJ face index 0": ("zero.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "face index 0"),
    "glTF node scale 1e308": (
        "huge.gltf", _gltf(_EMBEDDED, [{"buffer": 0, "byteLength": 36}], scale=1e308), "1e+09"),
}


@pytest.mark.parametrize("case", MESHES)
def test_a_malformed_mesh_is_refused_at_the_door_with_its_reason(client, case):
    name, data, reason = MESHES[case]
    pid = client.post("/api/projects", json={"name": case}).json()["id"]
    r = client.put(f"/api/projects/{pid}/mesh", files={"file": (name, data)})
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert detail.startswith(f"uploaded mesh {name!r} refused: ") and reason in detail, detail
    assert "Error:" not in detail.split("refused: ", 1)[1][:40]  # words, not an exception's name
    assert client.get(f"/api/projects/{pid}").json()["mesh"] is None


def test_an_obj_with_a_byte_order_mark_is_a_valid_file(client):
    pid = client.post("/api/projects", json={"name": "bom"}).json()["id"]
    data = "\ufeffv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n".encode()
    r = client.put(f"/api/projects/{pid}/mesh", files={"file": ("bom.obj", data)})
    assert r.status_code == 200, r.text
    assert r.json()["mesh"]["n_vertices"] == 4 and r.json()["mesh"]["n_faces"] == 2


def test_ten_thousand_landmark_positions_are_refused_before_the_work(client, sample_id):
    before = client.get(f"/api/projects/{sample_id}/landmarks").json()
    positions = np.random.default_rng(0).normal(size=(10_000, 3)).round(4).tolist()
    r = client.put(f"/api/projects/{sample_id}/landmarks", json={"positions": positions})
    assert r.status_code == 422 and "2,048" in r.json()["detail"], r.text
    assert client.get(f"/api/projects/{sample_id}/landmarks").json() == before
