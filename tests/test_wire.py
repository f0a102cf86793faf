"""The stream's frame encoder (Python) against its decoder (JavaScript, run in node), and the
browser's source-points encoder (JavaScript) against the server's decoder."""

import json
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

from server.wire import (FLAG_HEAD_ROTATION, FLAG_LOST_POINTS, FLAG_NEUTRAL, HEADER_BYTES, decode_frame,
                                 decode_points, encode_frame, encode_points)

ROOT = Path(__file__).resolve().parents[1]


def decode_in_node(tmp_path, frames: list[bytes]) -> list[dict]:
    node = shutil.which("node")
    assert node, "node (Node.js 20) is required: the browser decoder is tested with it"
    path = tmp_path / "frames.bin"
    path.write_bytes(b"".join(struct.pack("<I", len(f)) + f for f in frames))
    out = subprocess.run([node, str(ROOT / "tests" / "js" / "decode_stream.mjs"), str(path)],
                         capture_output=True, text=True, timeout=60, check=True)
    return json.loads(out.stdout)


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


def encode_in_node(tmp_path, points, dims, frame_index, capture_time):
    values = [None if np.isnan(v) else float(v) for v in np.asarray(points, np.float32).ravel()]
    src, out = tmp_path / "points.json", tmp_path / "points.bin"
    src.write_text(json.dumps({"points": values, "dims": dims, "frameIndex": frame_index,
                               "captureTime": capture_time}))
    run = subprocess.run([shutil.which("node"), str(ROOT / "tests" / "js" / "encode_points.mjs"),
                          str(src), str(out)], capture_output=True, text=True, timeout=60)
    return run, out


def test_python_decodes_exactly_what_javascript_encodes_for_live_points(tmp_path):
    rng = np.random.default_rng(11)
    for dims in (2, 3):
        p = rng.normal(scale=300, size=(68, dims)).astype(np.float32)
        p[5] = np.nan  # a lost point
        run, out = encode_in_node(tmp_path, p, dims, 4_000_000_000, 1234.5678)
        assert run.returncode == 0, run.stdout + run.stderr
        data = out.read_bytes()
        assert data == encode_points(p, frame_index=4_000_000_000, capture_time=1234.5678)
        frame = decode_points(data)
        np.testing.assert_array_equal(frame.points, p)
        assert (frame.frame_index, frame.capture_time) == (4_000_000_000, 1234.5678)
    run, _ = encode_in_node(tmp_path, np.zeros((4, 3)), 4, 0, 0.0)
    assert run.returncode == 3 and "dims must be 2 or 3" in run.stdout


def test_broken_points_messages_are_refused_with_the_reason():
    good = encode_points(np.ones((21, 3)), frame_index=1, capture_time=0.5)
    inf = encode_points(np.full((21, 3), np.inf), frame_index=1, capture_time=0.5)
    for bad, message in ((good[:20], "shorter than"), (b"XXXX" + good[4:], "magic"), (good[:-4], "must be"),
                         (good[:6] + b"\x04\x00" + good[8:], "of 4 coordinates"), (inf, "infinity")):
        with pytest.raises(ValueError, match=message):
            decode_points(bad)
