"""The stream's binary frame: target feature displacements for one frame.

One WebSocket binary message per frame, little-endian; its JavaScript twin is
`web/static/js/StreamDecoder.js`, and `tests/test_stream_codec.py` checks the two
against each other. Layout (byte offsets):

    0   4 bytes  magic b"RTDF"
    4   uint16   version (1)
    6   uint16   flags: bit 0 = neutral (all displacements zero, a reset),
                        bit 1 = some source points were lost this frame,
                        bit 2 = a head rotation follows the displacements,
                        bit 3 = the source's last frame (a take played once ends)
    8   uint32   frame index
    12  uint32   point count N
    16  float64  source timestamp, seconds (when the source produced the frame)
    24  float64  publish timestamp, seconds since the Unix epoch, taken when the frame is
                 encoded, just before the hub publishes it (for latency figures)
    32  N x 3 float32 displacements, point-major (x0 y0 z0 x1 ...), target units
    ... 4 float32 (with flag bit 2 only) the performer's head rotation as a unit
        quaternion x, y, z, w, in the source's axes, which the viewer may apply to the
        whole target (the rigid motion that head-pose removal took out of the points)

The header is 32 bytes, a multiple of 4, so the decoder views the payload as a
Float32Array without copying.
"""

from __future__ import annotations

import struct
import time
from dataclasses import dataclass

import numpy as np

MAGIC = b"RTDF"
VERSION = 1
FLAG_NEUTRAL = 1
FLAG_LOST_POINTS = 2
FLAG_HEAD_ROTATION = 4
FLAG_LAST = 8
_HEADER = struct.Struct("<4sHHIIdd")
HEADER_BYTES = _HEADER.size


@dataclass(frozen=True)
class Frame:
    """A decoded frame: displacements (N, 3) float32 and its header fields."""

    displacements: np.ndarray
    frame_index: int
    source_time: float
    send_time: float
    flags: int = 0
    head_rotation: np.ndarray | None = None  # (4,) quaternion x, y, z, w


def encode_frame(displacements, *, frame_index: int, source_time: float, flags: int = 0,
                 send_time: float | None = None, head_rotation=None) -> bytes:
    """Bytes of one frame for (N, 3) displacements (see the module docstring).

    head_rotation : (4,) unit quaternion x, y, z, w, or None; given, flag bit 2 is set."""
    d = np.asarray(displacements, dtype="<f4")
    if d.ndim != 2 or d.shape[1] != 3:
        raise ValueError(f"displacements must have shape (N, 3); got {d.shape}")
    if not np.isfinite(d).all():
        raise ValueError("displacements must be finite; lost points are sent as zero with flag bit 1")
    if not 0 <= frame_index < 2**32:
        raise ValueError(f"frame_index must fit in uint32; got {frame_index}")
    if not 0 <= flags < 2**16:
        raise ValueError(f"flags must fit in uint16; got {flags}")
    tail = b""
    if head_rotation is not None:
        q = np.asarray(head_rotation, dtype="<f4")
        if q.shape != (4,) or not np.isfinite(q).all():
            raise ValueError(f"head_rotation must be a finite quaternion of shape (4,); got {q!r}")
        flags |= FLAG_HEAD_ROTATION
        tail = q.tobytes()
    elif flags & FLAG_HEAD_ROTATION:
        raise ValueError("flag bit 2 (head rotation) is set but no head_rotation was given")
    sent = time.time() if send_time is None else send_time
    header = _HEADER.pack(MAGIC, VERSION, flags, frame_index, len(d), float(source_time), float(sent))
    return header + np.ascontiguousarray(d).tobytes() + tail


def decode_frame(data: bytes) -> Frame:
    """Parse one frame's bytes; ValueError on a bad magic, version or length."""
    if len(data) < HEADER_BYTES:
        raise ValueError(f"frame is {len(data)} bytes, shorter than its {HEADER_BYTES}-byte header")
    magic, version, flags, index, n, source_time, send_time = _HEADER.unpack_from(data)
    if magic != MAGIC:
        raise ValueError(f"not a displacement frame (magic {magic!r})")
    if version != VERSION:
        raise ValueError(f"unsupported frame version {version}")
    size = HEADER_BYTES + 12 * n + (16 if flags & FLAG_HEAD_ROTATION else 0)
    if len(data) != size:
        raise ValueError(f"frame for {n} points must be {size} bytes; got {len(data)}")
    d = np.frombuffer(data, dtype="<f4", offset=HEADER_BYTES, count=3 * n).reshape(n, 3)
    q = (np.frombuffer(data, dtype="<f4", offset=HEADER_BYTES + 12 * n, count=4)
         if flags & FLAG_HEAD_ROTATION else None)
    return Frame(d, index, source_time, send_time, flags, q)


# -- source points: the browser's tracker -> the server ------------------------------------
#
# One WebSocket binary message per tracked frame, little-endian; its JavaScript twin is
# `web/static/js/PointsEncoder.js`. Layout (byte offsets):
#
#     0   4 bytes  magic b"RTSP"
#     4   uint16   version (1)
#     6   uint16   dims D (2 or 3)
#     8   uint32   frame index
#     12  uint32   point count N
#     16  float64  capture time, seconds (the tracker's clock)
#     24  8 bytes  reserved (zero), so the points start at a multiple of 8
#     32  N x D float32 source points in the layout's order, NaN for a lost point

POINTS_MAGIC = b"RTSP"
POINTS_VERSION = 1
_POINTS_HEADER = struct.Struct("<4sHHIId8x")
MAX_POINTS = 1024


@dataclass(frozen=True)
class PointsFrame:
    """A decoded source-points message: points (N, D) float32 and its header fields."""

    points: np.ndarray
    frame_index: int
    capture_time: float


def encode_points(points, *, frame_index: int, capture_time: float) -> bytes:
    """Bytes of one source-points message (what the browser sends; used by tests and
    benchmarks)."""
    p = np.asarray(points, dtype="<f4")
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise ValueError(f"points must have shape (N, 2) or (N, 3); got {p.shape}")
    header = _POINTS_HEADER.pack(POINTS_MAGIC, POINTS_VERSION, p.shape[1], frame_index, len(p),
                                 float(capture_time))
    return header + np.ascontiguousarray(p).tobytes()


def decode_points(data: bytes) -> PointsFrame:
    """Parse a source-points message; ValueError naming what is wrong."""
    if len(data) < _POINTS_HEADER.size:
        raise ValueError(f"points message is {len(data)} bytes, shorter than its "
                         f"{_POINTS_HEADER.size}-byte header")
    magic, version, dims, index, n, t = _POINTS_HEADER.unpack_from(data)
    if magic != POINTS_MAGIC:
        raise ValueError(f"not a source-points message (magic {magic!r})")
    if version != POINTS_VERSION:
        raise ValueError(f"unsupported source-points version {version}")
    if dims not in (2, 3) or not 0 < n <= MAX_POINTS:
        raise ValueError(f"source-points message has {n} points of {dims} coordinates; "
                         f"expected 1..{MAX_POINTS} points of 2 or 3")
    size = _POINTS_HEADER.size + 4 * n * dims
    if len(data) != size:
        raise ValueError(f"source-points message for {n} x {dims} must be {size} bytes; got {len(data)}")
    if not np.isfinite(t):
        raise ValueError("source-points capture time must be finite")
    p = np.frombuffer(data, dtype="<f4", offset=_POINTS_HEADER.size).reshape(n, dims)
    if np.isinf(p).any():
        raise ValueError("source points must be finite or NaN (lost); got an infinity")
    return PointsFrame(p, index, t)
