"""The stream's binary frame: target feature displacements for one frame.

One WebSocket binary message per frame, little-endian; its JavaScript twin is
`web/static/js/StreamDecoder.js`, and `tests/test_stream_codec.py` checks the two
against each other. Layout (byte offsets):

    0   4 bytes  magic b"RTDF"
    4   uint16   version (1)
    6   uint16   flags: bit 0 = neutral (all displacements zero, a reset),
                        bit 1 = some source points were lost this frame,
                        bit 2 = a head rotation follows the displacements
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
