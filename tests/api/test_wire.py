"""Every binary format of server/wire.py against its JavaScript twin, web/static/js/net/wire.js,
run in node (tests/js/wire.mjs): what one side encodes the other decodes to the same values,
bit for bit, odd counts (padding) included, and both refuse malformed input saying why.

- stream frames (RTDF): Python encodes, JavaScript decodes;
- source points (RTSP): JavaScript encodes, Python decodes;
- mesh arrays (RTMA) and rig weights (RTSW, both versions): Python encodes, JavaScript
  decodes;
- weight edits (RTSE): JavaScript encodes, Python decodes."""

import json
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.skin import SkinWeights
from server.wire import (FLAG_HEAD_ROTATION, FLAG_LOST_POINTS, FLAG_NEUTRAL, HEADER_BYTES,
                         decode_frame, decode_points, edit_arrays, encode_frame, encode_points,
                         mesh_arrays, weights_binary)

ROOT = Path(__file__).resolve().parents[2]
WIRE_JS = ROOT / "tests" / "js" / "wire.mjs"


def node() -> str:
    path = shutil.which("node")
    assert path, "node (Node.js 20) is required: the browser's codecs are tested with it"
    return path


def decode_in_node(tmp_path, messages: list[bytes], command: str = "decode-frames") -> list[dict]:
    """What wire.js's decoder makes of each message: a dict of its fields, or {"error": msg}."""
    path = tmp_path / "messages.bin"
    path.write_bytes(b"".join(struct.pack("<I", len(m)) + m for m in messages))
    out = subprocess.run([node(), str(WIRE_JS), command, str(path)],
                         capture_output=True, text=True, timeout=60, check=True)
    return json.loads(out.stdout)


def encode_in_node(tmp_path, command: str, spec: dict):
    """Run one wire.js encoder on `spec` (JSON); the finished process and the output path."""
    src, out = tmp_path / "spec.json", tmp_path / "encoded.bin"
    src.write_text(json.dumps(spec))
    run = subprocess.run([node(), str(WIRE_JS), command, str(src), str(out)],
                         capture_output=True, text=True, timeout=60)
    return run, out


def bits(values) -> list[int]:
    """The float32 bit patterns of `values`, flattened (exact comparison, NaN and -0 included)."""
    return np.ascontiguousarray(values, dtype="<f4").ravel().view(np.uint32).tolist()


def test_javascript_decodes_exactly_what_python_encodes(tmp_path):
    rng = np.random.default_rng(7)
    cases = [
        (rng.normal(size=(68, 3)).astype(np.float32), 0, 0.0, 0),
        (rng.normal(size=(1, 3)).astype(np.float32), 2**32 - 1, -3.25, FLAG_LOST_POINTS),
        (rng.normal(scale=1e3, size=(468, 3)).astype(np.float32), 123456, 1e9 + 0.123456, 0),
        (np.zeros((21, 3), np.float32), 7, 12.5, FLAG_NEUTRAL),
        (np.array([[np.float32(1e-45), -0.0, np.float32(3.4e38)]], np.float32), 1, 0.5, 3),
    ]
    frames = [encode_frame(d, frame_index=i, source_time=t, flags=fl, send_time=1.7e9 + i)
              for d, i, t, fl in cases]
    decoded = decode_in_node(tmp_path, frames)
    for (d, i, t, fl), js in zip(cases, decoded):
        assert js["frameIndex"] == i and js["count"] == len(d) and js["flags"] == fl
        assert js["sourceTime"] == t and js["sendTime"] == 1.7e9 + i and js["version"] == 1
        assert js["bits"] == d.ravel().view(np.uint32).tolist()
        assert js["rotationBits"] is None


def test_head_rotation_travels_after_the_displacements(tmp_path):
    d = np.random.default_rng(3).normal(size=(21, 3)).astype(np.float32)
    q = np.array([0.1, -0.2, 0.05, 0.97], np.float32)
    data = encode_frame(d, frame_index=9, source_time=0.3, flags=FLAG_LOST_POINTS, head_rotation=q)
    assert len(data) == HEADER_BYTES + 21 * 12 + 16
    frame = decode_frame(data)
    assert frame.flags == FLAG_LOST_POINTS | FLAG_HEAD_ROTATION
    np.testing.assert_array_equal(frame.displacements, d)
    np.testing.assert_array_equal(frame.head_rotation, q)
    js, = decode_in_node(tmp_path, [data])
    assert js["flags"] == FLAG_LOST_POINTS | FLAG_HEAD_ROTATION
    assert js["bits"] == d.ravel().view(np.uint32).tolist()
    assert js["rotationBits"] == q.view(np.uint32).tolist()
    # without its 16 bytes the frame is refused by both decoders
    with pytest.raises(ValueError, match="must be"):
        decode_frame(data[:-16])
    assert "must be" in decode_in_node(tmp_path, [data[:-16]])[0]["error"]


def test_javascript_refuses_broken_frames_with_its_class_name(tmp_path):
    good = encode_frame(np.ones((4, 3)), frame_index=1, source_time=0.0)
    broken = [b"XXXX" + good[4:], good[:-4], good[:10], good[:4] + b"\x02\x00" + good[6:]]
    decoded = decode_in_node(tmp_path, broken)
    messages = [d["error"] for d in decoded]
    assert all(m.startswith("StreamDecoder:") for m in messages)
    assert "bad magic" in messages[0] and "must be 80 bytes, got 76" in messages[1]
    assert "shorter than its header" in messages[2] and "version 2" in messages[3]


def test_python_round_trip_and_header_size():
    d = np.arange(30, dtype=np.float32).reshape(10, 3)
    data = encode_frame(d, frame_index=5, source_time=2.0, flags=FLAG_LOST_POINTS)
    assert len(data) == HEADER_BYTES + 10 * 12 and HEADER_BYTES % 4 == 0
    f = decode_frame(data)
    np.testing.assert_array_equal(f.displacements, d)
    assert (f.frame_index, f.source_time, f.flags) == (5, 2.0, FLAG_LOST_POINTS)


@pytest.mark.parametrize("kwargs,message", [
    ({"displacements": np.ones((4, 2))}, r"shape \(N, 3\)"),
    ({"displacements": np.full((2, 3), np.nan)}, "finite"),
    ({"frame_index": -1}, "uint32"),
    ({"flags": 70000}, "uint16"),
    ({"flags": FLAG_HEAD_ROTATION}, "no head_rotation"),
    ({"head_rotation": [0, 0, 1]}, r"shape \(4,\)"),
])
def test_encoder_refuses_bad_frames(kwargs, message):
    args = {"displacements": np.ones((4, 3)), "frame_index": 0, "source_time": 0.0, **kwargs}
    with pytest.raises(ValueError, match=message):
        encode_frame(args.pop("displacements"), **args)


def test_python_decoder_refuses_broken_frames():
    good = encode_frame(np.ones((4, 3)), frame_index=1, source_time=0.0)
    for bad, message in ((b"XXXX" + good[4:], "magic"), (good[:-1], "must be 80 bytes"), (good[:8], "shorter")):
        with pytest.raises(ValueError, match=message):
            decode_frame(bad)


def encode_points_in_node(tmp_path, points, dims, frame_index, capture_time):
    values = [None if np.isnan(v) else float(v) for v in np.asarray(points, np.float32).ravel()]
    return encode_in_node(tmp_path, "encode-points", {"points": values, "dims": dims,
                                                      "frameIndex": frame_index, "captureTime": capture_time})


def test_python_decodes_exactly_what_javascript_encodes_for_live_points(tmp_path):
    rng = np.random.default_rng(11)
    for dims in (2, 3):
        p = rng.normal(scale=300, size=(68, dims)).astype(np.float32)
        p[5] = np.nan  # a lost point
        run, out = encode_points_in_node(tmp_path, p, dims, 4_000_000_000, 1234.5678)
        assert run.returncode == 0, run.stdout + run.stderr
        data = out.read_bytes()
        assert data == encode_points(p, frame_index=4_000_000_000, capture_time=1234.5678)
        frame = decode_points(data)
        np.testing.assert_array_equal(frame.points, p)
        assert (frame.frame_index, frame.capture_time) == (4_000_000_000, 1234.5678)
    run, _ = encode_points_in_node(tmp_path, np.zeros((4, 3)), 4, 0, 0.0)
    assert run.returncode == 3 and "dims must be 2 or 3" in run.stdout


def test_broken_points_messages_are_refused_with_the_reason():
    good = encode_points(np.ones((21, 3)), frame_index=1, capture_time=0.5)
    inf = encode_points(np.full((21, 3), np.inf), frame_index=1, capture_time=0.5)
    for bad, message in ((good[:20], "shorter than"), (b"XXXX" + good[4:], "magic"), (good[:-4], "must be"),
                         (good[:6] + b"\x04\x00" + good[8:], "of 4 coordinates"), (inf, "infinity")):
        with pytest.raises(ValueError, match=message):
            decode_points(bad)


def test_javascript_refuses_points_that_are_not_whole_points(tmp_path):
    run, _ = encode_in_node(tmp_path, "encode-points", {"points": [1.0] * 7, "dims": 3, "frameIndex": 0,
                                                        "captureTime": 0.0})
    assert run.returncode == 3 and run.stdout.startswith("PointsEncoder:") and "7 values" in run.stdout


# -- mesh arrays (RTMA): Python encodes, JavaScript decodes ---------------------------------

@pytest.mark.parametrize("n_vertices,n_faces", [(1, 0), (3, 1), (7, 5), (1001, 1999)])
def test_javascript_decodes_exactly_the_mesh_arrays_python_encodes(tmp_path, n_vertices, n_faces):
    rng = np.random.default_rng(n_vertices)
    vertices = rng.normal(scale=10, size=(n_vertices, 3)).astype(np.float32)
    vertices[0] = [np.float32(1e-45), -0.0, np.float32(3.4e38)]
    faces = rng.integers(0, n_vertices, size=(n_faces, 3)).astype(np.uint32)
    data = mesh_arrays(vertices, faces)
    assert len(data) == 16 + 12 * n_vertices + 12 * n_faces
    (js,) = decode_in_node(tmp_path, [data], "decode-mesh")
    assert js["positionBits"] == bits(vertices)
    assert js["faces"] == faces.ravel().tolist()
    assert js["uvBits"] is None and js["textured"] is False


@pytest.mark.parametrize("n_vertices,n_faces,textured", [(1, 0, True), (3, 1, False), (1001, 1999, True)])
def test_javascript_decodes_exactly_the_uv_python_encodes(tmp_path, n_vertices, n_faces, textured):
    rng = np.random.default_rng(n_vertices)
    vertices = rng.normal(size=(n_vertices, 3)).astype(np.float32)
    faces = rng.integers(0, n_vertices, size=(n_faces, 3)).astype(np.uint32)
    uv = rng.uniform(-0.5, 1.5, size=(n_vertices, 2)).astype(np.float32)
    uv[0] = [np.float32(1e-45), -0.0]
    data = mesh_arrays(vertices, faces, uv, textured=textured)
    assert len(data) == 16 + 12 * n_vertices + 12 * n_faces + 4 + 8 * n_vertices
    (js,) = decode_in_node(tmp_path, [data], "decode-mesh")
    assert js["positionBits"] == bits(vertices) and js["faces"] == faces.ravel().tolist()
    assert js["uvBits"] == bits(uv) and js["textured"] is textured


def test_python_refuses_uv_that_are_not_one_pair_per_vertex():
    with pytest.raises(ValueError, match=r"uv must be \(4, 2\)"):
        mesh_arrays(np.ones((4, 3)), np.array([[0, 1, 2]]), np.ones((3, 2)))


def test_javascript_refuses_broken_mesh_arrays_with_its_class_name(tmp_path):
    good = mesh_arrays(np.ones((4, 3)), np.array([[0, 1, 2], [1, 2, 3]]))
    broken = [b"XXXX" + good[4:], good[:4] + struct.pack("<I", 2) + good[8:], good[:-4], good + b"\0" * 4,
              good[:10], mesh_arrays(np.ones((4, 3)), np.array([[0, 1, 2], [1, 2, 3]]), np.ones((4, 2)))[:-8]]
    messages = [d["error"] for d in decode_in_node(tmp_path, broken, "decode-mesh")]
    assert all(m.startswith("MeshArraysDecoder:") for m in messages), messages
    assert '"RTMA"' in messages[0] and "version 2" in messages[1]
    assert "4 vertices and 2 triangles need 88 bytes (124 with uv), got 84" in messages[2]
    assert "need 88 bytes (124 with uv), got 92" in messages[3] and "shorter than its 16-byte header" in messages[4]
    assert "got 116" in messages[5]


# -- rig weights (RTSW): Python encodes, JavaScript decodes ---------------------------------

def skin(n_vertices: int, k: int, n_joints: int, seed: int) -> SkinWeights:
    rng = np.random.default_rng(seed)
    indices = rng.integers(0, n_joints, size=(n_vertices, k)).astype(np.int32)
    weights = rng.uniform(-0.2, 1.0, size=(n_vertices, k)).astype(np.float32)
    weights[0, 0] = 0.0  # an unused slot
    return SkinWeights(indices, weights, n_joints, "test")


@pytest.mark.parametrize("n_vertices,k,n_joints",
                         [(1, 1, 1), (3, 3, 21), (4, 8, 68), (5, 68, 68), (257, 3, 65535)])
def test_javascript_decodes_exactly_the_rig_weights_python_encodes(tmp_path, n_vertices, k, n_joints):
    rig = skin(n_vertices, k, n_joints, seed=n_vertices * k)
    data = weights_binary(rig)
    padding = 2 if n_vertices * k % 2 else 0  # odd V*K: the weights start 2 bytes later
    assert len(data) == 20 + 2 * n_vertices * k + padding + 4 * n_vertices * k
    (js,) = decode_in_node(tmp_path, [data], "decode-weights")
    assert (js["nJoints"], js["nInfluences"]) == (n_joints, k)
    assert js["indices"] == rig.indices.ravel().tolist()
    assert js["weightBits"] == bits(rig.weights)


def test_rig_weights_beyond_uint16_joints_are_refused_by_python():
    with pytest.raises(RetargetError, match="65536 joints"):
        weights_binary(SkinWeights(np.zeros((2, 1), np.int32), np.ones((2, 1), np.float32), 65536))


def test_javascript_refuses_broken_rig_weights_with_its_class_name(tmp_path):
    good = weights_binary(skin(3, 3, 21, seed=0))  # 9 indices: 2 bytes of padding
    broken = [b"XXXX" + good[4:], good[:4] + struct.pack("<I", 7) + good[8:], good[:-2],
              good[:20] + good[22:], good[:12]]
    messages = [d["error"] for d in decode_in_node(tmp_path, broken, "decode-weights")]
    assert all(m.startswith("RigWeightsDecoder:") for m in messages), messages
    assert '"RTSW"' in messages[0] and "version 7" in messages[1]
    assert "3 rows of 3 influences need 76 bytes, got 74" in messages[2]
    assert "need 76 bytes, got 74" in messages[3] and "shorter than its 20-byte header" in messages[4]


@pytest.mark.parametrize("n_vertices,k,n_joints,dense",
                         [(1, 1, 1, True), (3, 3, 21, False), (5, 68, 68, True), (5, 68, 68, False),
                          (257, 3, 65535, False)])
def test_javascript_decodes_version_2_rig_weights_as_python_does(tmp_path, n_vertices, k, n_joints, dense):
    """Version 2: a dense rig's weights quantised to 20 bits (both sides dequantise to the
    same float32 bits, within step / 2 of the rig, as `quantised_weights` rounds them) and
    no indices; any other rig as version 1 carries it."""
    from server.wire import quantised_weights, weights_from_binary

    rig = skin(n_vertices, k, n_joints, seed=n_vertices * k + 1)
    if dense:
        rig = SkinWeights(np.broadcast_to(np.arange(k, dtype=np.int32), (n_vertices, k)).copy(),
                          rig.weights * 1.5, n_joints, "test")
    data = weights_binary(rig, 2)
    index_bytes = 0 if dense else 2 * n_vertices * k + (2 * n_vertices * k) % 4
    assert len(data) == 28 + index_bytes + (3 if dense else 4) * n_vertices * k
    python = weights_from_binary(data)
    step = struct.unpack_from("<f", data, 24)[0]
    if dense:
        top = np.abs(rig.weights).max()
        assert step == (2.0 ** np.ceil(np.log2(top / (2**19 - 1))) if top else 1.0)
        assert np.abs(python.weights - rig.weights).max() <= step / 2
    else:
        assert step == 0 and np.array_equal(python.weights, rig.weights)
    assert np.array_equal(quantised_weights(rig).weights, python.weights)
    assert (python.indices == rig.indices).all() and python.n_joints == n_joints
    (js,) = decode_in_node(tmp_path, [data], "decode-weights")
    assert (js["nJoints"], js["nInfluences"]) == (n_joints, k)
    assert js["indices"] == rig.indices.ravel().tolist()
    assert js["weightBits"] == bits(python.weights)
    version_1 = weights_from_binary(weights_binary(rig))
    assert (version_1.weights == rig.weights).all() and (version_1.indices == rig.indices).all()


def test_both_sides_refuse_broken_version_2_rig_weights(tmp_path):
    from server.wire import weights_from_binary

    good = weights_binary(skin(3, 3, 21, seed=0), 2)  # 9 indices: 2 bytes of padding
    dense_k_not_n = bytearray(weights_binary(SkinWeights(np.zeros((2, 1), np.int32),
                                                         np.ones((2, 1), np.float32), 1), 2))
    dense_k_not_n[16:20] = struct.pack("<I", 3)
    broken = [good[:-1], good[:24], bytes(dense_k_not_n)]
    messages = [d["error"] for d in decode_in_node(tmp_path, broken, "decode-weights")]
    assert "3 rows of 3 influences of 21 joints need 84 bytes, got 83" in messages[0]
    assert "shorter than its 28-byte header" in messages[1]
    assert "2 rows of 1 influences of 3 joints" in messages[2]
    for data in broken:
        with pytest.raises(RetargetError, match="rig weights"):
            weights_from_binary(data)
    with pytest.raises(RetargetError, match="version must be one of"):
        weights_binary(skin(3, 3, 21, seed=0), 3)


# -- weight edits (RTSE): JavaScript encodes, Python decodes --------------------------------

def rtse(version: int, n_joints: int, vertices, joints, weights) -> bytes:
    """The RTSE bytes written out from server/wire.py's docstring: the test's own oracle."""
    r, k = np.shape(joints)
    index_bytes = np.asarray(joints, "<u2").tobytes()
    return (struct.pack("<4sIIIII", b"RTSE", 1, r, k, n_joints, version)
            + np.asarray(vertices, "<u4").tobytes() + index_bytes + b"\0" * (len(index_bytes) % 4)
            + np.asarray(weights, "<f4").tobytes())


@pytest.mark.parametrize("rows,k", [(1, 1), (3, 3), (2, 4), (5, 8), (1, 68), (3001, 3)])
def test_python_decodes_exactly_the_weight_edits_javascript_encodes(tmp_path, rows, k):
    rng = np.random.default_rng(rows + k)
    vertices = np.sort(rng.choice(100_000, size=rows, replace=False)).astype(np.uint32)
    joints = rng.integers(0, 68, size=(rows, k)).astype(np.uint16)
    weights = rng.uniform(0, 1, size=(rows, k)).astype(np.float32)
    run, out = encode_in_node(tmp_path, "encode-edit", {
        "version": 4_000_000_001, "nJoints": 68, "k": k, "vertices": vertices.tolist(),
        "indices": joints.ravel().tolist(), "weights": weights.ravel().tolist()})
    assert run.returncode == 0, run.stdout + run.stderr
    data = out.read_bytes()
    assert data == rtse(4_000_000_001, 68, vertices, joints, weights)
    version, n, got_vertices, got_joints, got_weights = edit_arrays(data)
    assert (version, n) == (4_000_000_001, 68)
    np.testing.assert_array_equal(got_vertices, vertices)
    np.testing.assert_array_equal(got_joints, joints)
    assert bits(got_weights) == bits(weights)


def test_javascript_refuses_rows_that_do_not_fit_their_count(tmp_path):
    run, _ = encode_in_node(tmp_path, "encode-edit", {"version": 1, "nJoints": 68, "k": 3, "vertices": [1, 2],
                                                      "indices": [0] * 6, "weights": [0.5] * 5})
    assert run.returncode == 3 and run.stdout.startswith("WeightEditEncoder:")
    assert "2 rows of 3 influences need 6 indices and weights, got 6 and 5" in run.stdout


def test_python_refuses_broken_weight_edits_with_the_reason():
    good = rtse(2, 68, [3, 9, 11], np.ones((3, 3)), np.full((3, 3), 0.25))  # 9 indices: padded
    for bad, message in ((good[:20], "shorter than its 24-byte header"), (b"XXXX" + good[4:], "magic"),
                         (good[:4] + struct.pack("<I", 2) + good[8:], "version 2"),
                         (good[:-4], "need 92 bytes; got 88"), (good + b"\0\0", "got 94"),
                         (good[:54] + good[56:], "got 90")):  # the padding left out
        with pytest.raises(RetargetError, match=message):
            edit_arrays(bad)


# -- ARKit weight frames (RTAW) and shapes (RTAK) ------------------------------------------

def test_javascript_decodes_exactly_the_arkit_weight_frames_python_encodes(tmp_path):
    from server.wire import (FLAG_LAST, decode_arkit_weights, encode_arkit_weights, is_arkit_weights,
                             weights_json)

    w = np.random.default_rng(16).random(52).astype(np.float32)
    q = np.array([0.1, -0.2, 0.05, 0.97], np.float32)
    frames = [encode_arkit_weights(w, frame_index=2**32 - 1, source_time=-3.25, send_time=1.7e9,
                                   flags=FLAG_LOST_POINTS),
              encode_arkit_weights(w, frame_index=7, source_time=0.5, flags=FLAG_LAST, send_time=1.7e9,
                                   head_rotation=q)]
    assert len(frames[0]) == 32 + 4 * 52 and is_arkit_weights(frames[1])
    plain, rotated = decode_in_node(tmp_path, frames, "decode-arkit-weights")
    for js, data in ((plain, frames[0]), (rotated, frames[1])):
        ours = decode_arkit_weights(data)
        assert js["bits"] == bits(w) == bits(ours.weights) and js["sendTime"] == 1.7e9
        assert (js["frameIndex"], js["flags"], js["sourceTime"]) == (ours.frame_index, ours.flags, ours.source_time)
    assert plain["frameIndex"] == 2**32 - 1 and plain["rotationBits"] is None
    assert rotated["flags"] == FLAG_LAST | FLAG_HEAD_ROTATION and rotated["rotationBits"] == bits(q)
    assert "ArkitWeightsDecoder" in decode_in_node(tmp_path, [frames[0][:-4]], "decode-arkit-weights")[0]["error"]
    with pytest.raises(ValueError, match="wrong length"):
        decode_arkit_weights(frames[0][:-4])
    named = weights_json(frames[1], [f"s{k}" for k in range(52)])
    assert named["last"] and not named["lost"] and named["frame"] == 7 and len(named["weights"]) == 52


@pytest.mark.parametrize("n_vertices", [1, 7, 300])
def test_javascript_decodes_exactly_the_arkit_shapes_python_encodes(tmp_path, n_vertices):
    from server.wire import arkit_shapes_binary, decode_arkit_shapes

    rng = np.random.default_rng(n_vertices)
    deltas = rng.normal(size=(52, n_vertices, 3)).astype(np.float32)
    deltas[:, rng.random(n_vertices) < 0.5] = 0  # sparse: half the vertices still
    deltas[3] = 0  # a shape that moves nothing (tongueOut on ICT)
    deltas[4, :, 0] = 1e-6 * deltas[4, :, 1]  # below the floor of the shape's peak: dropped
    names = [f"s{k}" for k in range(52)]
    data = arkit_shapes_binary(names, deltas)
    ours_names, ours = decode_arkit_shapes(data)
    peaks = np.abs(deltas).max(axis=(1, 2))
    assert ours_names == names and (np.abs(ours - deltas).max(axis=(1, 2)) <= 1.01e-3 * peaks + 1e-12).all()
    js, = decode_in_node(tmp_path, [data], "decode-arkit-shapes")
    assert js["names"] == names and js["nVertices"] == n_vertices
    for k, shape in enumerate(js["shapes"]):
        vertices = np.array(shape["vertices"], dtype=np.int64)
        values = np.array(shape["values"], dtype=np.float32).reshape(-1, 3) * np.float32(shape["scale"])
        np.testing.assert_array_equal(values, ours[k, vertices])
        assert not np.delete(ours[k], vertices, axis=0).any()
    assert not js["shapes"][3]["vertices"]
    assert "ArkitShapesDecoder" in decode_in_node(tmp_path, [data[:-4]], "decode-arkit-shapes")[0]["error"]
    with pytest.raises(ValueError):
        decode_arkit_shapes(data[:-4])


# -- stereo pair (RTSJ): JavaScript encodes, Python decodes ---------------------------------

def test_python_decodes_exactly_the_stereo_pairs_javascript_encodes(tmp_path):
    from server.wire import decode_stereo_pair, encode_stereo_pair

    rng = np.random.default_rng(5)
    left = b"\xff\xd8" + rng.integers(0, 256, 999).astype(np.uint8).tobytes()
    right = b"\xff\xd8" + rng.integers(0, 256, 4321).astype(np.uint8).tobytes()
    run, out = encode_in_node(tmp_path, "encode-stereo-pair", {"left": list(left), "right": list(right),
                                                               "frameIndex": 4_000_000_000,
                                                               "captureTime": 1764662400.125})
    assert run.returncode == 0, run.stdout + run.stderr
    data = out.read_bytes()
    assert data == encode_stereo_pair(left, right, frame_index=4_000_000_000, capture_time=1764662400.125)
    pair = decode_stereo_pair(data)
    assert (pair.left, pair.right, pair.frame_index, pair.capture_time) == (left, right, 4_000_000_000,
                                                                           1764662400.125)
    run, _ = encode_in_node(tmp_path, "encode-stereo-pair", {"left": [1, 2, 3], "right": list(right),
                                                             "frameIndex": 0, "captureTime": 0.0})
    assert run.returncode == 3 and "the left image is not JPEG bytes" in run.stdout


def test_broken_stereo_pairs_are_refused_with_the_reason():
    from server.wire import MAX_STEREO_JPEG, decode_stereo_pair, encode_stereo_pair

    jpeg = b"\xff\xd8" + b"\x00" * 100
    good = encode_stereo_pair(jpeg, jpeg, frame_index=1, capture_time=0.5)
    huge = good[:12] + struct.pack("<I", MAX_STEREO_JPEG + 1) + good[16:]
    for bad, message in ((good[:20], "shorter than"), (b"XXXX" + good[4:], "magic"),
                         (good[:-1], "must be 236 bytes; got 235"), (huge, "left JPEG is 393217 bytes"),
                         (encode_stereo_pair(jpeg, b"GIF89a", frame_index=1, capture_time=0.5),
                          "right image is not a JPEG"),
                         (encode_stereo_pair(jpeg, jpeg, frame_index=1, capture_time=np.nan), "finite")):
        with pytest.raises(ValueError, match=message):
            decode_stereo_pair(bad)
