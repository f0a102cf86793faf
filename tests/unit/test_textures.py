"""Textured meshes (issue 13 item 2, the library part): an OBJ with its MTL and images,
given as side files, beside a path or in a zip, and a glTF whose buffers and images are
separate files; the base-colour texture is kept as PNG on the mesh's material, and a
file that is not there, not an image or too large is refused by name."""

from __future__ import annotations

import base64
import io
import json
import struct
import zipfile
import zlib

import numpy as np
import pytest
from PIL import Image

from retarget.errors import RetargetError
from retarget.mesh import load_mesh
from retarget.material import MAX_TEXTURE_PIXELS

VERTICES = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
UV = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
FACES = np.array([[0, 1, 2], [0, 2, 3]])


def _obj(mtllib="face.mtl", material="skin") -> bytes:
    lines = [f"mtllib {mtllib}"] + [f"v {x} {y} {z}" for x, y, z in VERTICES]
    lines += [f"vt {u} {v}" for u, v in UV] + [f"usemtl {material}"]
    lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in FACES]
    return "\n".join(lines).encode()


def _image(fmt="JPEG", size=(16, 8), colour=(200, 100, 50)) -> bytes:
    out = io.BytesIO()
    Image.new("RGB", size, colour).save(out, fmt)
    return out.getvalue()


MTL = b"newmtl other\nKd 0 0 1\nnewmtl skin\nKd 0.8 0.7 0.6\nd 1\nmap_Kd -s 1 1 1 textures\\skin.jpg\n"


def _texture(mesh) -> Image.Image:
    return Image.open(io.BytesIO(mesh.material.base_color_texture))


def test_an_obj_with_its_mtl_and_image_keeps_its_texture():
    mesh = load_mesh(_obj(), "obj", files={"face.mtl": MTL, "skin.jpg": _image()})
    assert mesh.material.name == "skin" and mesh.material.base_color == (0.8, 0.7, 0.6, 1.0)
    texture = _texture(mesh)
    assert texture.format == "PNG" and texture.size == (16, 8)
    assert np.abs(np.asarray(texture.convert("RGB"), int) - [200, 100, 50]).max() < 8  # JPEG
    np.testing.assert_allclose(mesh.uv, UV)
    assert load_mesh(_obj(), "obj").material is None  # no side files: the plain surface


def test_a_zip_of_the_obj_mtl_and_image_in_folders_reads_as_one_mesh():
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("scan/head.obj", _obj())
        archive.writestr("scan/face.mtl", MTL)
        archive.writestr("scan/textures/skin.jpg", _image())
        archive.writestr("__MACOSX/scan/._head.obj", b"junk")
    mesh = load_mesh(out.getvalue(), "zip")
    assert mesh.n_vertices == 4 and _texture(mesh).size == (16, 8)


def test_an_obj_path_reads_the_mtl_and_image_beside_it(tmp_path):
    (tmp_path / "head.obj").write_bytes(_obj())
    (tmp_path / "face.mtl").write_bytes(MTL)
    (tmp_path / "skin.jpg").write_bytes(_image())
    assert _texture(load_mesh(tmp_path / "head.obj")).size == (16, 8)


@pytest.mark.parametrize("files, reason", [
    ({"face.mtl": MTL}, "uses the texture image 'skin.jpg', which was not given"),
    ({"face.mtl": MTL, "skin.jpg": b"not an image"}, "texture image 'skin.jpg' is not an image"),
    ({"face.mtl": b"newmtl skin\nKd red green blue\n"}, "Kd, d or Tr is not a number"),
])
def test_a_texture_that_is_missing_or_unreadable_is_refused_by_name(files, reason):
    with pytest.raises(RetargetError, match=reason):
        load_mesh(_obj(), "obj", files=files)


def test_a_texture_too_large_is_refused_from_its_header():
    side = int(np.sqrt(MAX_TEXTURE_PIXELS)) + 1
    # a PNG header claiming side x side pixels, with a tiny (invalid) body: never decoded
    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", side, side, 8, 2, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b""))
    with pytest.raises(RetargetError, match=f"is {side}x{side} pixels; a texture may have at most"):
        load_mesh(_obj(), "obj", files={"face.mtl": MTL, "skin.jpg": png})


def _zip(members) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in members:
            archive.writestr(name, data)
    return out.getvalue()


@pytest.mark.parametrize("members, reason", [
    ([("a.obj", _obj()), ("b.obj", _obj())], "must hold one mesh file"),
    ([("face.mtl", MTL)], "must hold one mesh file"),
    ([("a.obj", _obj())] + [(f"{i}.png", b"x") for i in range(70)], "may hold at most 64"),
    ([("a.obj", _obj()), ("bomb.png", b"\0" * (8 << 20))], "zip bomb"),
])
def test_a_zip_that_is_not_one_mesh_with_its_files_is_refused(members, reason):
    with pytest.raises(RetargetError, match=reason):
        load_mesh(_zip(members), "zip")


def test_a_gltf_with_separate_buffer_and_image_files_keeps_its_texture():
    positions = VERTICES.astype("<f4").tobytes()
    uvs = UV.astype("<f4").tobytes()
    indices = FACES.astype("<u2").tobytes()
    blob = positions + uvs + indices
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2,
                                    "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        "textures": [{"source": 0}], "images": [{"uri": "skin.png"}],
        "buffers": [{"byteLength": len(blob), "uri": "face.bin"}],
        "bufferViews": [{"buffer": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 32},
                        {"buffer": 0, "byteOffset": 80, "byteLength": 12}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                      {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}],
    }
    gltf = json.dumps(doc).encode()
    mesh = load_mesh(gltf, "gltf", files={"face.bin": blob, "skin.png": _image("PNG")})
    assert mesh.n_vertices == 4 and _texture(mesh).size == (16, 8)
    with pytest.raises(RetargetError, match="refers to the external file 'face.bin'"):
        load_mesh(gltf, "gltf")
    embedded = dict(doc, buffers=[{"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                                   + base64.b64encode(blob).decode()}])
    assert load_mesh(json.dumps(embedded).encode(), "gltf", files={"skin.png": _image("PNG")}).n_vertices == 4
