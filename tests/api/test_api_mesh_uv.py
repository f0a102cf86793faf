"""The mesh arrays the browser draws (RTMA) carry the uv, and flag a mesh whose texture
GET .../mesh/texture serves."""

from __future__ import annotations

import io
import struct

import numpy as np
import pytest
from fastapi.testclient import TestClient
from PIL import Image

from server.app import create_app

VERTICES = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
UV = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.25, 0.75)]
FACES = [(0, 1, 2), (0, 2, 3)]
MTL = b"newmtl skin\nKd 1 1 1\nmap_Kd skin.png\n"


def _obj(with_uv=True) -> bytes:
    lines = ["mtllib face.mtl", *(f"v {x} {y} {z}" for x, y, z in VERTICES)]
    if with_uv:
        lines += [f"vt {u} {v}" for u, v in UV] + ["usemtl skin"]
        lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in FACES]
    else:
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in FACES]
    return "\n".join(lines).encode()


def _png() -> bytes:
    out = io.BytesIO()
    Image.new("RGB", (8, 8), (255, 0, 0)).save(out, "PNG")
    return out.getvalue()


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    with TestClient(create_app(tmp_path_factory.mktemp("uv"), sample=False)) as c:
        yield c


def _arrays(client, files) -> tuple[int, np.ndarray | None]:
    """(flags or -1 without a uv block, uv (V, 2) or None) of an uploaded mesh's arrays."""
    pid = client.post("/api/projects", json={"name": "scan"}).json()["id"]
    r = client.put(f"/api/projects/{pid}/mesh", files=files)
    assert r.status_code == 200, r.text
    data = client.get(f"/api/projects/{pid}/mesh/arrays").content
    v, f = struct.unpack_from("<II", data, 8)
    end = 16 + 12 * v + 12 * f
    if len(data) == end:
        return -1, None
    assert len(data) == end + 4 + 8 * v
    return struct.unpack_from("<I", data, end)[0], np.frombuffer(data, "<f4", 2 * v, end + 4).reshape(v, 2)


def test_a_textured_obj_sends_its_uv_and_the_texture_flag(client):
    flags, uv = _arrays(client, [("file", ("head.obj", _obj())), ("files", ("face.mtl", MTL)),
                                 ("files", ("skin.png", _png()))])
    assert flags == 1
    np.testing.assert_allclose(uv, UV)


def test_uv_without_a_texture_are_sent_unflagged_and_no_uv_sends_no_block(client):
    flags, uv = _arrays(client, [("file", ("head.obj", _obj().replace(b"mtllib face.mtl\n", b"")))])
    assert flags == 0
    np.testing.assert_allclose(uv, UV)
    assert _arrays(client, [("file", ("head.obj", _obj(with_uv=False)))]) == (-1, None)
