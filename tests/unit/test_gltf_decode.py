"""retarget.gltf.decode builds the same pygltflib objects as pygltflib's own decoding
(dataclasses_json), value for value and type for type, and refuses what pygltflib refuses
with the same exception: on our exports of every kind, on a document using every class
and field pygltflib has, on values of the wrong type or shape, and on hostile mutants
(tests/hostile_inputs.py) of those files.

`==` of pygltflib documents cannot be the check: `Attributes` compares by identity, NaN
is unequal to itself and 1 == 1.0 == True. `_structure` compares types and reprs.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import warnings

import numpy as np
import pygltflib
import pytest

from retarget.arkit.shapes import arkit_shapes
from retarget.gltf import export_arkit_gltf, export_mesh_gltf, export_muscles_gltf
from retarget.gltf.decode import gltf_from_glb, gltf_from_json
from retarget.landmarks import from_vertex_indices
from retarget.layouts import get_layout
from retarget.mesh import mesh_from_arrays
from retarget.muscles import place_muscles
from retarget.muscles.morphs import muscle_morphs
from retarget.weights import compute_weights
from tests.hostile_inputs import Seed, glb_bytes, import_seed, mutants, small_face, take_seeds

KITCHEN_SINK = {
    "asset": {"version": "2.0", "generator": "test", "copyright": "c", "minVersion": "2.0",
              "extras": {"a": [1, 2]}},
    "extensionsUsed": ["KHR_materials_unlit", "EXT_unknown"],
    "extensionsRequired": ["EXT_unknown"],
    "extensions": {"EXT_unknown": {"x": 1}},
    "extras": {"retarget": {"scale": 1, "landmarks": {"a": [0.5, None]}}, "n": 2.5},
    "scene": 0,
    "scenes": [{"name": "s", "nodes": [0, 1], "extras": {}}],
    "nodes": [{"mesh": 0, "skin": 0, "children": [1], "translation": [0, 1, 2],
               "rotation": [0, 0, 0, 1], "scale": [1, 1, 1], "weights": [0.5], "name": "n",
               "unknownKey": 3},
              {"camera": 0, "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "_CUSTOM": 2},
                                "indices": 3, "mode": 4, "material": 0,
                                "targets": [{"POSITION": 4}, {"NORMAL": 5}],
                                "extras": {"targetNames": ["a", "b"]}},
                               {"attributes": {}}],
                "weights": [0, 0.5], "name": "m", "extras": {"targetScale": 0.01}}],
    "accessors": [{"bufferView": 0, "byteOffset": 0, "componentType": 5126, "normalized": False,
                   "count": 3, "type": "VEC3", "max": [1, 1.5, 2], "min": [0, 0, 0], "name": "a"},
                  {"componentType": 5126, "count": 3, "type": "VEC3",
                   "sparse": {"count": 1,
                              "indices": {"bufferView": 0, "byteOffset": 0, "componentType": 5125},
                              "values": {"bufferView": 0, "byteOffset": 4}}}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36, "byteStride": 12,
                     "target": 34962, "name": "v"}],
    "buffers": [{"byteLength": 36}],
    "cameras": [{"type": "perspective",
                 "perspective": {"aspectRatio": 1.5, "yfov": 1, "zfar": 100, "znear": 0.1}},
                {"type": "orthographic",
                 "orthographic": {"xmag": 1, "ymag": 1, "zfar": 10, "znear": 0}}],
    "materials": [{"name": "mat",
                   "pbrMetallicRoughness": {"baseColorFactor": [1, 0.5, 0.5, 1], "metallicFactor": 0,
                                            "roughnessFactor": 0.5,
                                            "baseColorTexture": {"index": 0, "texCoord": 0},
                                            "metallicRoughnessTexture": {"index": 0}},
                   "normalTexture": {"index": 0, "scale": 2},
                   "occlusionTexture": {"index": 0, "strength": 0.5},
                   "emissiveTexture": {"index": 0}, "emissiveFactor": [0, 0, 0],
                   "alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": True,
                   "extensions": {"KHR_materials_unlit": {}}},
                  {}],
    "textures": [{"sampler": 0, "source": 0, "name": "t"}],
    "images": [{"uri": "face.png", "mimeType": "image/png", "name": "i"},
               {"bufferView": 0, "mimeType": "image/jpeg"}],
    "samplers": [{"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33648}],
    "skins": [{"inverseBindMatrices": 0, "skeleton": 0, "joints": [0, 1], "name": "sk"}],
    "animations": [{"name": "an",
                    "samplers": [{"input": 0, "output": 1, "interpolation": "STEP"},
                                 {"input": 0, "output": 1}],
                    "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}},
                                 {"sampler": 1, "target": {"path": "weights"}}]}],
}
"""A document with every pygltflib class and field (and some it does not know)."""

ODD_VALUES = [
    # values dataclasses_json converts by the field's type
    (("accessors", 0, "count"), 3.0), (("accessors", 0, "count"), "3"),
    (("accessors", 0, "count"), True), (("accessors", 0, "name"), 5),
    (("accessors", 0, "name"), [1]), (("accessors", 0, "normalized"), 1),
    (("accessors", 0, "normalized"), "no"), (("accessors", 0, "max"), [1, "2", True]),
    (("accessors", 0, "max"), [float("nan"), float("inf"), -0.0]), (("scene",), "0"),
    (("extensionsUsed",), [None, 1]), (("accessors",), [None]),
    (("meshes", 0, "primitives", 0, "targets"), [None, 3, "x"]),
    (("meshes", 0, "primitives", 0, "attributes"), {"POSITION": "x", "args": 1}),
    (("meshes", 0, "primitives", 0, "attributes"), []),
    (("extras",), None), (("asset",), None), (("accessors", 1, "sparse"), None),
    (("bufferViews", 0, "byteLength"), 10 ** 30), (("accessors", 0, "max"), [10 ** 30]),
    # values of another shape: pygltflib's own decoding decides
    (("accessors", 0, "max"), "12"), (("accessors",), {}), (("nodes", 0, "children"), {"1": 2}),
    (("meshes", 0, "primitives", 0, "targets"), {"POSITION": 1}),
    # values pygltflib refuses
    (("accessors", 0, "count"), "x"), (("accessors", 0, "count"), float("inf")),
    (("accessors", 0, "count"), float("nan")), (("accessors", 0, "count"), [3]),
    (("accessors", 0, "max"), [None]), (("accessors", 0, "max"), 5),
    (("accessors", 0, "max"), [10 ** 400]), (("accessors",), {"a": 1}), (("accessors",), [5]),
    (("extras",), "x"), (("extras",), [1]), (("asset",), "2.0"), (("accessors", 1, "sparse"), []),
    (("meshes",), [None]), (("meshes", 0, "primitives"), None), (("meshes", 0, "primitives"), [7]),
    (("meshes", 0, "primitives", 0, "attributes"), [1]),
    (("meshes", 0, "primitives", 0, "attributes"), {"self": 1}),
    (("meshes", 0, "primitives", 0, "attributes"), "POSITION"),
]
"""(path into KITCHEN_SINK, value put there)."""

REMOVED = [("meshes", 0, "primitives", 0, "attributes"), ("asset",), ("accessors", 0, "count"),
           ("materials", 0, "pbrMetallicRoughness", "baseColorFactor")]
"""Paths into KITCHEN_SINK whose key is removed."""

WHOLE_DOCUMENTS = [None, [], 5, "glTF", {}, {"asset": {"version": "2.0"}}]


def _structure(value):
    """A comparable form of a decoded document: types and reprs all the way down (floats
    by repr, so NaN equals NaN and 1.0 differs from 1), and any attribute beyond the
    dataclass fields (the GLB's binary chunk)."""
    if dataclasses.is_dataclass(value):
        names = [f.name for f in dataclasses.fields(value)]
        extra = {k: v for k, v in vars(value).items() if k not in names}
        return (type(value), tuple((n, _structure(getattr(value, n))) for n in names),
                _structure(extra))
    if isinstance(value, pygltflib.Attributes):
        return type(value), _structure(vars(value))
    if isinstance(value, dict):
        return dict, tuple((k, _structure(v)) for k, v in value.items())
    if isinstance(value, list):
        return list, tuple(_structure(v) for v in value)
    return type(value), repr(value)


def _outcome(decode, data):
    """("read", structure) or ("refused", exception type, message)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return "read", _structure(decode(data))
    except Exception as exc:  # noqa: BLE001 - what pygltflib raises is what is compared
        return "refused", type(exc), str(exc)


def _assert_same_as_pygltflib(data: bytes, binary: bool):
    """Our decoding of a .glb or .gltf's bytes against pygltflib's; returns the outcome."""
    if binary:
        ours, theirs = _outcome(gltf_from_glb, data), _outcome(pygltflib.GLTF2.load_from_bytes, data)
    else:
        text = data.decode("utf-8-sig")  # GltfDocument refuses other bytes before decoding
        ours, theirs = _outcome(gltf_from_json, text), _outcome(pygltflib.GLTF2.from_json, text)
    assert ours == theirs
    return ours


def _json_bytes(doc) -> bytes:
    return json.dumps(doc, allow_nan=True).encode()


def _set(doc, path, value):
    doc = copy.deepcopy(doc)
    *parents, key = path
    container = doc
    for k in parents:
        container = container[k]
    container[key] = value
    return doc


@pytest.fixture(scope="module")
def exports() -> dict[str, bytes]:
    """.glb exports of the small hostile-input face of every kind: joint-rig skin,
    dense morph rigs, ARKit shapes, muscles, the mesh alone."""
    face = small_face()
    mesh = mesh_from_arrays(face.vertices, face.faces, name="small_face")
    points = from_vertex_indices(np.arange(68), len(face.vertices), layout="ibug68")
    rig = compute_weights("ellipsoid", mesh.vertices, mesh.faces, points, get_layout("ibug68"))
    model = place_muscles(mesh.vertices, mesh.faces, mesh.vertices[:68])
    files = {m: import_seed(m).data for m in ("ellipsoid", "rbf", "biharmonic")}
    files["arkit"] = export_arkit_gltf(mesh, arkit_shapes(mesh.vertices, mesh.faces, points,
                                                          "ibug68", rig))
    files["muscles"] = export_muscles_gltf(mesh, muscle_morphs(model))
    files["mesh"] = export_mesh_gltf(mesh)
    return files


def test_exports_decode_as_pygltflib_does_without_its_decoding(exports, monkeypatch):
    expected = {name: _assert_same_as_pygltflib(data, True) for name, data in exports.items()}
    assert all(outcome[0] == "read" for outcome in expected.values())

    def unused(*args, **kwargs):
        raise AssertionError("a well-formed export fell back to dataclasses_json")

    monkeypatch.setattr(pygltflib, "_decode_dataclass", unused)
    for name, data in exports.items():
        assert _outcome(gltf_from_glb, data) == expected[name], name


def test_take_files_decode_as_pygltflib_does():
    seeds = take_seeds()
    assert _assert_same_as_pygltflib(seeds["glb"].data, True)[0] == "read"
    assert _assert_same_as_pygltflib(seeds["gltf"].data, False)[0] == "read"


@pytest.mark.parametrize("binary", [True, False], ids=["glb", "gltf"])
def test_every_class_and_odd_values_decode_as_pygltflib_does(binary):
    docs = [KITCHEN_SINK] + [_set(KITCHEN_SINK, path, value) for path, value in ODD_VALUES]
    for path in REMOVED:
        doc = copy.deepcopy(KITCHEN_SINK)
        *parents, key = path
        container = doc
        for k in parents:
            container = container[k]
        del container[key]
        docs.append(doc)
    outcomes = [_assert_same_as_pygltflib(glb_bytes(doc, b"\0" * 36) if binary else _json_bytes(doc),
                                          binary) for doc in docs + WHOLE_DOCUMENTS]
    kinds = [outcome[0] for outcome in outcomes]
    assert kinds[0] == "read" and "refused" in kinds and kinds.count("read") > len(ODD_VALUES) // 2


def test_broken_containers_and_text_are_refused_as_pygltflib_does():
    glb = glb_bytes(KITCHEN_SINK, b"\0" * 36)
    for data in (glb[:30], glb[:12] + b"\xff\xff\xff\xff" + glb[16:], glb[:16] + b"BIN\0" + glb[20:]):
        assert _assert_same_as_pygltflib(data, True)[0] == "refused"
    # no chunk at all: no document (which GltfDocument refuses)
    assert _assert_same_as_pygltflib(b"glTF" + bytes(8), True) == ("read", _structure(None))
    for text in (b"{", b"", b"[1, 2", b'{"asset": {"version": "2.0"}} x'):
        assert _assert_same_as_pygltflib(text, False)[0] == "refused"


@pytest.mark.parametrize("name,count", [("glb", 40), ("gltf", 40), ("kitchen.glb", 80),
                                        ("kitchen.gltf", 80), ("ellipsoid.glb", 20)])
def test_hostile_mutants_decode_as_pygltflib_does(name, count, exports):
    """Mutants as the upload fuzz makes them: damaged bytes, containers and JSON values."""
    seeds = take_seeds()
    seed = {"glb": seeds["glb"], "gltf": seeds["gltf"],
            "kitchen.glb": Seed("take", "glb", glb_bytes(KITCHEN_SINK, b"\0" * 36)),
            "kitchen.gltf": Seed("take", "gltf", _json_bytes(KITCHEN_SINK)),
            "ellipsoid.glb": Seed("import", "glb", exports["ellipsoid"])}[name]
    binary = seed.ext == "glb"
    kinds = []
    for mutant in mutants(seed, count, rng_seed=7):
        if not binary:
            try:
                mutant.data.decode("utf-8-sig")
            except UnicodeDecodeError:
                continue
        kinds.append(_assert_same_as_pygltflib(mutant.data, binary)[0])
    assert "read" in kinds
