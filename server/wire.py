"""Every binary format between the server and the browser, in one place. Each has one
JavaScript twin in `web/static/js/net/wire.js`, and tests run the two against each other.

- stream frame ``RTDF`` (server -> page, WebSocket): a frame's feature displacements;
- contraction frame ``RTMC`` (server -> page, WebSocket, muscle mode): a frame's muscle
  contractions and the expression they show;
- source points ``RTSP`` (page -> server, WebSocket): one frame of tracked points;
- stereo pair ``RTSJ`` (page -> server, WebSocket): two cameras' JPEGs of one moment;
- mesh arrays ``RTMA`` (GET .../mesh/arrays): vertices and triangles to draw, and uv;
- rig weights ``RTSW`` (GET .../rig/weights): joint indices and weights per vertex;
- weight edit ``RTSE`` (PATCH .../rig/weights): painted rows;
- played muscles ``RTMM`` (GET .../muscles/played): the muscles' morph targets and jaw.
- ARKit weight frame ``RTAW`` (server -> page or any subscriber, WebSocket, ARKit mode):
  the 52 blendshape weights, or their JSON form (`weights_json`); ARKit shapes ``RTAK``
  (GET .../arkit/shapes): the 52 morph targets, sparse int16 (both at the end of this
  module).

All little-endian; every array starts at a multiple of 4 bytes, so the page views it in
place (``new Float32Array(buffer, offset, n)``) without copying.

Stream frame (RTDF)
-------------------
One WebSocket binary message per frame. Layout (byte offsets):


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

Contraction frame (RTMC)
------------------------
What a stream driven by muscles sends instead of RTDF (the page plays the muscles' morph
targets and jaw, `RTMM`, in its shader): D + E + 2 numbers a frame instead of 3N::

    0   4 bytes  magic b"RTMC"
    4   uint16   version (1)
    6   uint16   flags: RTDF's bits (1 lost points, 2 head rotation, 3 last frame)
    8   uint32   frame index
    12  uint16   D, dof count (the muscles, then the jaw)
    14  uint16   E, expression count (`retarget.muscles.expressions.EXPRESSIONS`' order)
    16  float64  source timestamp, seconds
    24  float64  publish timestamp, seconds since the Unix epoch
    32  D float32 contractions, the jaw's last in radians
    ... E float32 normalised distances to each expression
    ... float32  confidence of the nearest expression, in [0, 1]
    ... uint32   index of the nearest expression
    ... 4 float32 (with flag bit 2 only) the head rotation, as in RTDF

Played muscles (RTMM)
---------------------
`retarget.muscles.morphs.MuscleMorphs`, what the page's shader plays::

    offset      size    field
    0           4       magic b"RTMM"
    4           4       uint32 format version (1)
    8           4       uint32 V, vertex count
    12          4       uint32 T = M + C, morph target count: M muscles, C correctives
    16          4       uint32 J, bytes of the JSON header (padded with spaces to a multiple of 4)
    20          J       UTF-8 JSON: {"names": T target names (the muscles', then the
                        correctives' ``<muscle>*jaw``), "dofs": D = M + 1 dof names (the
                        muscles then "jaw"), "high": M contractions that weight 1 stands
                        for, "corrective_of": C muscle indices, "limits": D [low, high],
                        "jaw_limits": [low, high], "jaw_pivot": [x, y, z], "jaw_axis":
                        [x, y, z], "expressions": E names}
    20+J        12 T V  float32 targets, (T, V, 3) row-major, mesh units
    ...         4 V     float32 jaw weights, (V,)

A pose c (D,) plays as v = rest + sum_t weight_t targets[t], weight_m = c_m / high_m for
a muscle and weight_(corrective of m) = weight_m c[-1] / jaw_limits[1], then the jaw's
linear blend skinning about the axis through the pivot by the angle c[-1], weighted per
vertex (`retarget.muscles.morphs.played_displacements`).

Mesh arrays (RTMA)
------------------
::

    offset  size    field
    0       4       magic b"RTMA"
    4       4       uint32 format version (1)
    8       4       uint32 V, vertex count
    12      4       uint32 F, triangle count
    16      12 V    float32 vertices, (V, 3) row-major, in the mesh's own units
    16+12V  12 F    uint32 faces, (F, 3) row-major, indices into the vertices
    (only for a mesh with uv; without them the bytes end here)
    16+12V+12F  4   uint32 flags: bit 0 = a base-colour texture is served at
                    GET .../mesh/texture (sampled with the uv)
    20+12V+12F  8 V float32 uv, (V, 2) row-major, OBJ's convention (v up, origin at the
                    image's bottom-left)

Vertex order is exactly `retarget.mesh.load_mesh`'s, which landmark indices refer to. The uv
block is a tail, so readers of vertices and faces alone need not know it.

Rig weights (RTSW)
------------------
Version 1 (GET .../rig/weights), float32::

    offset      size    field
    0           4       magic b"RTSW"
    4           4       uint32 format version (1)
    8           4       uint32 V, vertex count
    12          4       uint32 K, influences per vertex
    16          4       uint32 N, joint (feature point) count
    20          2 V K   uint16 joint indices, (V, K) row-major, each in [0, N)
    20+2VK      0 or 2  zero padding, so the weights start at a multiple of 4
    ...         4 V K   float32 weights, (V, K) row-major

Version 2 (GET .../rig/weights?version=2, what the page reads; gzip-encoded for a client
that accepts it), quantised to 20 bits: 5.7 MiB gzip-encoded against version 1's 51.7 MiB
for the dense biharmonic rig of the 132,907-vertex built-in face (`bench/rig.py`)::

    offset      size    field
    0           4       magic b"RTSW"
    4           4       uint32 format version (2)
    8           4       uint32 V, vertex count
    12          4       uint32 K, influences per vertex
    16          4       uint32 N, joint (feature point) count
    20          4       uint32 flags: bit 0 = dense, every vertex lists joints 0..K-1 in
                        that order (K = N): the joint indices are not sent, and the
                        weights are quantised
    24          4       float32 step, a power of two: a weight is step x q (0 when not dense)
    28          2 V K   uint16 joint indices, (V, K) row-major (absent when dense)
    ...         0 or 2  zero padding, so the weights start at a multiple of 4
    (not dense: the rest is version 1's, 4 V K float32 weights, (V, K) row-major; a sparse
    rig is small, and painting and the glTF skin need its rows to sum as computed)
    ...         V K     bits 0-3 of the 20-bit signed q (0..15), slot-major: q[0, 0],
                        q[1, 0], ..., q[V-1, 0], q[0, 1], ... (a slot's weights over the
                        mesh are a smooth field: its bytes deflate well)
    ...         V K     bits 4-11 of q, in the same order
    ...         V K     bits 12-19 of q (a signed byte), in the same order

step is the smallest power of two with every |weight| <= (2^19 - 1) step (2^-18 for that
rig): each weight is rounded to within step / 2 (1.9e-6 there), and step x q is exact in
float32, so both sides dequantise to the same bits. (16 bits, a step 16 times coarser, made
2.4 MiB but turned the normals of that face by up to 11 degrees at a few vertices under
strong poses.)

Weights are `retarget.skin.SkinWeights`: unused slots have weight 0; the rest of a row's
1 belongs to the static root joint.

Weight edit (RTSE)
------------------
::

    offset      size    field
    0           4       magic b"RTSE"
    4           4       uint32 format version (1)
    8           4       uint32 R, rows (edited vertices)
    12          4       uint32 K, influences per row
    16          4       uint32 N, joint count (the rig's)
    20          4       uint32 rig version the edit was made on (``version`` of GET rig)
    24          4 R     uint32 vertex indices
    24+4R       2 R K   uint16 joint indices, (R, K) row-major
    ...         0 or 2  zero padding, so the weights start at a multiple of 4
    ...         4 R K   float32 weights, (R, K) row-major
"""

from __future__ import annotations

import json
import struct
import time
from dataclasses import dataclass

import numpy as np

from retarget.errors import RetargetError
from retarget.muscles.drive import MuscleFrame
from retarget.muscles.morphs import MuscleMorphs
from retarget.skin import SkinWeights

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


# -- contraction frames (RTMC): muscle mode ----------------------------------------------

CONTRACTIONS_MAGIC = b"RTMC"
CONTRACTIONS_VERSION = 1
_CONTRACTIONS_HEADER = struct.Struct("<4sHHIHHdd")


@dataclass(frozen=True)
class ContractionFrame:
    """A decoded contraction frame: (D,) contractions, (E,) distances, and its header."""

    contractions: np.ndarray
    distances: np.ndarray
    confidence: float
    label: int
    frame_index: int
    source_time: float
    send_time: float
    flags: int = 0
    head_rotation: np.ndarray | None = None


def encode_contractions(frame: MuscleFrame, *, frame_index: int, source_time: float, flags: int = 0,
                        send_time: float | None = None, head_rotation=None) -> bytes:
    """Bytes of one contraction frame (module docstring) for a `MuscleFrame`."""
    c = np.asarray(frame.contractions, dtype="<f4")
    e = np.asarray(frame.distances, dtype="<f4")
    if c.ndim != 1 or e.ndim != 1 or not (np.isfinite(c).all() and np.isfinite(e).all()):
        raise ValueError(f"contractions and distances must be finite vectors; got {c.shape} and {e.shape}")
    if not 0 <= frame.label < len(e):
        raise ValueError(f"label must index the {len(e)} expressions; got {frame.label}")
    tail = b""
    if head_rotation is not None:
        flags |= FLAG_HEAD_ROTATION
        tail = np.asarray(head_rotation, dtype="<f4").reshape(4).tobytes()
    sent = time.time() if send_time is None else send_time
    header = _CONTRACTIONS_HEADER.pack(CONTRACTIONS_MAGIC, CONTRACTIONS_VERSION, flags, frame_index, len(c),
                                       len(e), float(source_time), float(sent))
    return (header + c.tobytes() + e.tobytes() + struct.pack("<fI", frame.confidence, frame.label) + tail)


def decode_contractions(data: bytes) -> ContractionFrame:
    """Parse one contraction frame; ValueError on a bad magic, version or length."""
    if len(data) < _CONTRACTIONS_HEADER.size:
        raise ValueError(f"frame is {len(data)} bytes, shorter than its {_CONTRACTIONS_HEADER.size}-byte header")
    magic, version, flags, index, d, e, source_time, send_time = _CONTRACTIONS_HEADER.unpack_from(data)
    if magic != CONTRACTIONS_MAGIC or version != CONTRACTIONS_VERSION:
        raise ValueError(f"not a contraction frame version {CONTRACTIONS_VERSION} (magic {magic!r}, version {version})")
    body = _CONTRACTIONS_HEADER.size + 4 * (d + e + 2)
    if len(data) != body + (16 if flags & FLAG_HEAD_ROTATION else 0):
        raise ValueError(f"contraction frame of {d} dofs and {e} expressions has the wrong length {len(data)}")
    at = _CONTRACTIONS_HEADER.size
    c = np.frombuffer(data, "<f4", d, at)
    dist = np.frombuffer(data, "<f4", e, at + 4 * d)
    confidence, label = struct.unpack_from("<fI", data, at + 4 * (d + e))
    q = np.frombuffer(data, "<f4", 4, body) if flags & FLAG_HEAD_ROTATION else None
    return ContractionFrame(c, dist, confidence, label, index, source_time, send_time, flags, q)


# -- source points (RTSP): the browser's tracker -> the server ----------------------------
#
# One WebSocket binary message per tracked frame. Layout (byte offsets):
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


# -- stereo pair (RTSJ): the page's two cameras -> the server ------------------------------
#
# One WebSocket binary message per frame pair (`server.routers.stereo_live`). Layout:
#
#     0   4 bytes  magic b"RTSJ"
#     4   uint16   version (1)
#     6   uint16   flags (0; reserved)
#     8   uint32   frame index
#     12  uint32   L, the left camera's JPEG length, bytes
#     16  uint32   R, the right camera's JPEG length, bytes
#     20  4 bytes  reserved (zero)
#     24  float64  capture time, seconds since the Unix epoch (the page's clock, for the
#                  camera-to-screen latency)
#     32  L bytes  the left image, a baseline or progressive JPEG (starts FF D8)
#     ... R bytes  the right image, likewise
#
# Only the framing is checked here; the JPEGs are decoded in a child process.

STEREO_MAGIC = b"RTSJ"
STEREO_VERSION = 1
_STEREO_HEADER = struct.Struct("<4sHHIII4xd")
MAX_STEREO_JPEG = 384 * 1024
"""Bytes one camera's JPEG may take (a 640 x 480 webcam frame at quality 0.9 is ~60 kB)."""


@dataclass(frozen=True)
class StereoPair:
    """A decoded stereo-pair message: the two JPEGs (bytes, undecoded) and its header."""

    left: bytes
    right: bytes
    frame_index: int
    capture_time: float


def encode_stereo_pair(left: bytes, right: bytes, *, frame_index: int, capture_time: float) -> bytes:
    """Bytes of one stereo-pair message (what the page sends; used by tests and benchmarks)."""
    header = _STEREO_HEADER.pack(STEREO_MAGIC, STEREO_VERSION, 0, frame_index, len(left), len(right),
                                 float(capture_time))
    return header + bytes(left) + bytes(right)


def decode_stereo_pair(data: bytes) -> StereoPair:
    """Parse a stereo-pair message's framing; ValueError naming what is wrong."""
    if len(data) < _STEREO_HEADER.size:
        raise ValueError(f"stereo pair message is {len(data)} bytes, shorter than its "
                         f"{_STEREO_HEADER.size}-byte header")
    magic, version, _, index, n_left, n_right, t = _STEREO_HEADER.unpack_from(data)
    if magic != STEREO_MAGIC:
        raise ValueError(f"not a stereo pair message (magic {magic!r})")
    if version != STEREO_VERSION:
        raise ValueError(f"unsupported stereo pair version {version}")
    for side, n in (("left", n_left), ("right", n_right)):
        if not 0 < n <= MAX_STEREO_JPEG:
            raise ValueError(f"stereo pair: the {side} JPEG is {n} bytes; expected 1..{MAX_STEREO_JPEG}")
    size = _STEREO_HEADER.size + n_left + n_right
    if len(data) != size:
        raise ValueError(f"stereo pair message with JPEGs of {n_left} and {n_right} bytes must be "
                         f"{size} bytes; got {len(data)}")
    if not np.isfinite(t):
        raise ValueError("stereo pair capture time must be finite")
    at = _STEREO_HEADER.size
    left, right = bytes(data[at:at + n_left]), bytes(data[at + n_left:])
    for side, jpeg in (("left", left), ("right", right)):
        if jpeg[:2] != b"\xff\xd8":
            raise ValueError(f"stereo pair: the {side} image is not a JPEG (it must start FF D8)")
    return StereoPair(left, right, index, t)


# -- mesh arrays (RTMA) ------------------------------------------------------------------

ARRAYS_MAGIC = b"RTMA"
ARRAYS_VERSION = 1
ARRAYS_HEADER = struct.Struct("<4sIII")


ARRAYS_TEXTURED = 1
"""RTMA flags bit 0: the mesh has a base-colour texture."""


def mesh_arrays(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray | None = None, *,
                textured: bool = False) -> bytes:
    """The RTMA bytes of a mesh (module docstring): vertices (V, 3), faces (F, 3) and, when
    given, uv (V, 2) with the `textured` flag (ignored without uv: nothing could sample it)."""
    v = np.ascontiguousarray(vertices, dtype="<f4")
    f = np.ascontiguousarray(faces, dtype="<u4")
    data = ARRAYS_HEADER.pack(ARRAYS_MAGIC, ARRAYS_VERSION, len(v), len(f)) + v.tobytes() + f.tobytes()
    if uv is None:
        return data
    uv = np.ascontiguousarray(uv, dtype="<f4")
    if uv.shape != (len(v), 2):
        raise ValueError(f"uv must be ({len(v)}, 2) for {len(v)} vertices; got {uv.shape}")
    flags = ARRAYS_TEXTURED if textured else 0
    return data + struct.pack("<I", flags) + uv.tobytes()


# -- played muscles (RTMM) ---------------------------------------------------------------

MORPHS_MAGIC = b"RTMM"
MORPHS_VERSION = 1
MORPHS_HEADER = struct.Struct("<4sIIII")


def morphs_binary(morphs: MuscleMorphs, dofs, limits, expressions) -> bytes:
    """The RTMM bytes of the played muscles (module docstring): `dofs` (D,) the model's dof
    names and `limits` (D, 2) their ranges (the sliders'), `expressions` the names a
    contraction frame's label indexes."""
    header = json.dumps({
        "names": [*morphs.names, *morphs.corrective_names], "dofs": list(dofs), "high": morphs.high.tolist(),
        "corrective_of": morphs.corrective_of.tolist(), "limits": np.asarray(limits, float).tolist(),
        "jaw_limits": morphs.jaw_limits.tolist(), "jaw_pivot": morphs.jaw_pivot.tolist(),
        "jaw_axis": morphs.jaw_axis.tolist(), "expressions": list(expressions)}).encode()
    header += b" " * (-len(header) % 4)
    m, v, _ = morphs.targets.shape
    c = len(morphs.corrective_of)
    return (MORPHS_HEADER.pack(MORPHS_MAGIC, MORPHS_VERSION, v, m + c, len(header)) + header
            + np.ascontiguousarray(morphs.targets, "<f4").tobytes()
            + np.ascontiguousarray(morphs.correctives, "<f4").tobytes()
            + np.ascontiguousarray(morphs.jaw_weights, "<f4").tobytes())


# -- rig weights (RTSW) and weight edits (RTSE) ------------------------------------------

WEIGHTS_MAGIC = b"RTSW"
WEIGHTS_VERSION = 1
WEIGHTS_VERSIONS = (1, 2)
WEIGHTS_HEADER = struct.Struct("<4sIIII")
WEIGHTS_HEADER_V2 = struct.Struct("<4sIIIIIf")
WEIGHTS_DENSE = 1
WEIGHTS_QUANTA = 2**19 - 1  # version 2: the largest |q|
EDIT_MAGIC = b"RTSE"
EDIT_VERSION = 1
EDIT_HEADER = struct.Struct("<4sIIIII")


def weights_binary(rig: SkinWeights, version: int = WEIGHTS_VERSION) -> bytes:
    """The RTSW bytes of a rig in format `version` (1 or 2, module docstring)."""
    if version not in WEIGHTS_VERSIONS:
        raise RetargetError(f"rig weights format version must be one of {WEIGHTS_VERSIONS}; got {version}")
    if rig.n_joints > 0xFFFF:
        raise RetargetError(f"rig has {rig.n_joints} joints; the binary form holds 65535")
    v, k = rig.indices.shape
    if version == 1:
        indices = np.ascontiguousarray(rig.indices, dtype="<u2").tobytes()
        padding = b"\0" * (-len(indices) % 4)
        weights = np.ascontiguousarray(rig.weights, dtype="<f4").tobytes()
        header = WEIGHTS_HEADER.pack(WEIGHTS_MAGIC, 1, v, k, rig.n_joints)
        return header + indices + padding + weights
    dense = _is_dense(rig)
    if not dense:
        indices = np.ascontiguousarray(rig.indices, dtype="<u2").tobytes()
        header = WEIGHTS_HEADER_V2.pack(WEIGHTS_MAGIC, 2, v, k, rig.n_joints, 0, 0.0)
        return (header + indices + b"\0" * (-len(indices) % 4)
                + np.ascontiguousarray(rig.weights, dtype="<f4").tobytes())
    step = _weights_step(rig)
    q = np.round(rig.weights.T / step).astype(np.int32)  # (K, V), slot-major, |q| < 2^19
    planes = np.empty((3, k, v), dtype=np.uint8)  # a cast to uint8 keeps the low 8 bits
    np.bitwise_and(q, 0xF, out=planes[0], casting="unsafe")
    np.right_shift(q, 4, out=planes[1], casting="unsafe")
    np.right_shift(q, 12, out=planes[2], casting="unsafe")
    planes = planes.tobytes()
    header = WEIGHTS_HEADER_V2.pack(WEIGHTS_MAGIC, 2, v, k, rig.n_joints, WEIGHTS_DENSE, step)
    return header + planes


def _is_dense(rig: SkinWeights) -> bool:
    """Whether every vertex lists joints 0..N-1 in that order (version 2 quantises it)."""
    k = rig.indices.shape[1]
    return k == rig.n_joints and bool((rig.indices == np.arange(k)).all())


def _weights_step(rig: SkinWeights) -> float:
    """Version 2's step for a rig: the smallest power of two with every |weight| <=
    WEIGHTS_QUANTA steps (1 for an all-zero rig)."""
    top = float(np.abs(rig.weights).max(initial=0.0))
    return 2.0 ** int(np.ceil(np.log2(top / WEIGHTS_QUANTA))) if top > 0 else 1.0


def quantised_weights(rig: SkinWeights) -> SkinWeights:
    """The rig as version 2 carries it (a dense rig's weights rounded to the step, a sparse
    rig as it is): bit for bit what
    `weights_from_binary(weights_binary(rig, 2))` reads, with the rig's method. The store
    keeps automatic rigs so (`server.store.ProjectStore.put_rig`): the page's copy is then the
    stored rig exactly, and rows it sends back unpainted (a stroke's neighbours, an undo)
    equal the automatic ones."""
    if not _is_dense(rig):
        return rig
    step = _weights_step(rig)
    weights = np.round(rig.weights / np.float32(step)).astype(np.float32) * np.float32(step)
    return SkinWeights(rig.indices, weights, rig.n_joints, rig.method)


def weights_from_binary(data: bytes) -> SkinWeights:
    """The rig of RTSW bytes of either version (its weights dequantised for version 2);
    RetargetError when malformed."""
    if len(data) < WEIGHTS_HEADER.size:
        raise RetargetError(f"rig weights: {len(data)} bytes is shorter than the header")
    magic, version, v, k, n = WEIGHTS_HEADER.unpack_from(data)
    if magic != WEIGHTS_MAGIC or version not in WEIGHTS_VERSIONS:
        raise RetargetError(f"rig weights: expected magic {WEIGHTS_MAGIC!r} version 1 or 2, "
                            f"got {magic!r} version {version}")
    flags, step, start = 0, None, WEIGHTS_HEADER.size
    if version == 2:
        if len(data) < WEIGHTS_HEADER_V2.size:
            raise RetargetError(f"rig weights: {len(data)} bytes is shorter than the header")
        *_, flags, step = WEIGHTS_HEADER_V2.unpack_from(data)
        start = WEIGHTS_HEADER_V2.size
    dense = bool(flags & WEIGHTS_DENSE)
    index_bytes = 0 if dense else 2 * v * k
    offset = start + index_bytes + (-index_bytes % 4)
    size = offset + (3 if dense else 4) * v * k
    if len(data) != size or (dense and k != n):
        raise RetargetError(f"rig weights: {v} rows of {k} influences of {n} joints need "
                            f"{size} bytes; got {len(data)}")
    if dense:
        indices = np.broadcast_to(np.arange(k, dtype=np.int32), (v, k)).copy()
    else:
        indices = np.frombuffer(data, "<u2", v * k, start).reshape(v, k).astype(np.int32)
    if not dense:
        weights = np.frombuffer(data, "<f4", v * k, offset).reshape(v, k).astype(np.float32)
    else:
        low, middle, high = np.frombuffer(data, np.uint8, 3 * v * k, offset).reshape(3, k, v)
        q = (high.view(np.int8).astype(np.int32) << 12) | (middle.astype(np.int32) << 4) | low
        weights = q.T.astype(np.float32) * np.float32(step)
    return SkinWeights(indices, np.ascontiguousarray(weights), n)


def edit_arrays(body: bytes) -> tuple[int, int, np.ndarray, np.ndarray, np.ndarray]:
    """(rig version, N, (R,) vertices, (R, K) joints, (R, K) weights) of the binary form."""
    if len(body) < EDIT_HEADER.size:
        raise RetargetError(f"weight edit: {len(body)} bytes is shorter than its "
                            f"{EDIT_HEADER.size}-byte header")
    magic, fmt, r, k, n, version = EDIT_HEADER.unpack_from(body)
    if magic != EDIT_MAGIC or fmt != EDIT_VERSION:
        raise RetargetError(f"weight edit: expected magic {EDIT_MAGIC!r} version {EDIT_VERSION}, "
                            f"got {magic!r} version {fmt}")
    index_bytes = 2 * r * k
    start = EDIT_HEADER.size + 4 * r + index_bytes + (-index_bytes % 4)
    if len(body) != start + 4 * r * k:
        raise RetargetError(f"weight edit: {r} rows of {k} influences need {start + 4 * r * k} "
                            f"bytes; got {len(body)}")
    vertices = np.frombuffer(body, "<u4", r, EDIT_HEADER.size)
    joints = np.frombuffer(body, "<u2", r * k, EDIT_HEADER.size + 4 * r).reshape(r, k)
    weights = np.frombuffer(body, "<f4", r * k, start).reshape(r, k)
    return version, n, vertices, joints, weights


# -- ARKit weight frames (RTAW) and ARKit shapes (RTAK): issue 16 -------------------------
#
# ARKit weight frame (RTAW), what a stream driven by ARKit sends instead of RTDF (server ->
# page or any subscriber, WebSocket): the 52 weights in ARKit's order
# (`retarget.arkit.ARKIT_NAMES`), K + 8 numbers a frame instead of 3N:
#
#     0   4 bytes  magic b"RTAW"
#     4   uint16   version (1)
#     6   uint16   flags: RTDF's bits (1 lost points, 2 head rotation, 3 last frame)
#     8   uint32   frame index
#     12  uint16   K, weight count (52)
#     14  uint16   reserved (0)
#     16  float64  source timestamp, seconds
#     24  float64  publish timestamp, seconds since the Unix epoch
#     32  K float32 weights in [0, 1], the user's gains applied (`retarget.arkit.drive`)
#     ... 4 float32 (with flag bit 2 only) the head rotation, as in RTDF
#
# Its JSON form (`weights_json`), for a viewer that asked for ``{"type": "format",
# "format": "json"}`` (or ``?format=json``): ``{"type": "weights", "frame", "t" (source
# seconds), "sent" (publish time), "weights": {name: w, ...}, "head_rotation": [x, y, z, w]
# or null, "lost": bool, "last": bool}``.
#
# ARKit shapes (RTAK), GET .../arkit/shapes: the 52 morph targets, sparse and quantised:
# a vertex is sent when it moves at least `SHAPES_FLOOR` (1/1000) of the shape's largest
# motion (a dense RBF rig moves the whole face a little), an int16 per coordinate holding
# it to 1/65534 of the shape's largest coordinate; so every delta is within 0.1 % of its
# shape's peak. 1.8 MB for the 8,430-vertex sample face against 5.3 MB as float32:
#
#     0       4     magic b"RTAK"
#     4       4     uint32 format version (1)
#     8       4     uint32 V, vertex count
#     12      4     uint32 K, shape count (52)
#     16      4     uint32 J, bytes of the JSON header (padded with spaces to a multiple of 4)
#     20      J     UTF-8 JSON {"names": K names, "counts": K vertex counts M_k,
#                   "scales": K floats s_k (mesh units per int16 step)}
#     then per shape k, in order:
#             4 M_k     uint32 vertex indices, ascending
#             6 M_k     int16 deltas (M_k, 3) row-major; the delta is value * s_k
#             0 or 2    zero padding to a multiple of 4
#
# Vertices a shape leaves out do not move in it (less than the floor).

ARKIT_WEIGHTS_MAGIC = b"RTAW"
ARKIT_WEIGHTS_VERSION = 1
_ARKIT_WEIGHTS_HEADER = struct.Struct("<4sHHIHHdd")
ARKIT_SHAPES_MAGIC = b"RTAK"
ARKIT_SHAPES_VERSION = 1
ARKIT_SHAPES_HEADER = struct.Struct("<4sIIII")
SHAPES_FLOOR = 1e-3


@dataclass(frozen=True)
class ArkitWeightsFrame:
    """A decoded ARKit weight frame: (K,) float32 weights and its header fields."""

    weights: np.ndarray
    frame_index: int
    source_time: float
    send_time: float
    flags: int = 0
    head_rotation: np.ndarray | None = None


def encode_arkit_weights(weights, *, frame_index: int, source_time: float, flags: int = 0,
                         send_time: float | None = None, head_rotation=None) -> bytes:
    """Bytes of one ARKit weight frame (RTAW, above) for (K,) weights."""
    w = np.asarray(weights, dtype="<f4")
    if w.ndim != 1 or not 0 < len(w) < 2**16 or not np.isfinite(w).all():
        raise ValueError(f"weights must be a finite vector of 1..65535; got {w.shape}")
    tail = b""
    if head_rotation is not None:
        flags |= FLAG_HEAD_ROTATION
        tail = np.asarray(head_rotation, dtype="<f4").reshape(4).tobytes()
    sent = time.time() if send_time is None else send_time
    header = _ARKIT_WEIGHTS_HEADER.pack(ARKIT_WEIGHTS_MAGIC, ARKIT_WEIGHTS_VERSION, flags, frame_index % 2**32,
                                        len(w), 0, float(source_time), float(sent))
    return header + w.tobytes() + tail


def decode_arkit_weights(data: bytes) -> ArkitWeightsFrame:
    """Parse one ARKit weight frame; ValueError on a bad magic, version or length."""
    size = _ARKIT_WEIGHTS_HEADER.size
    if len(data) < size:
        raise ValueError(f"frame is {len(data)} bytes, shorter than its {size}-byte header")
    magic, version, flags, index, k, _, source_time, send_time = _ARKIT_WEIGHTS_HEADER.unpack_from(data)
    if magic != ARKIT_WEIGHTS_MAGIC or version != ARKIT_WEIGHTS_VERSION:
        raise ValueError(f"not an ARKit weight frame version {ARKIT_WEIGHTS_VERSION} "
                         f"(magic {magic!r}, version {version})")
    body = size + 4 * k
    if len(data) != body + (16 if flags & FLAG_HEAD_ROTATION else 0):
        raise ValueError(f"ARKit weight frame of {k} weights has the wrong length {len(data)}")
    w = np.frombuffer(data, "<f4", k, size)
    q = np.frombuffer(data, "<f4", 4, body) if flags & FLAG_HEAD_ROTATION else None
    return ArkitWeightsFrame(w, index, source_time, send_time, flags, q)


def is_arkit_weights(data: bytes) -> bool:
    """Whether `data` is an RTAW frame (by its magic)."""
    return data[:4] == ARKIT_WEIGHTS_MAGIC


def weights_json(data: bytes, names) -> dict:
    """The JSON form of an RTAW frame (above), its weights named by `names` (K,)."""
    frame = decode_arkit_weights(data)
    return {"type": "weights", "frame": frame.frame_index, "t": frame.source_time, "sent": frame.send_time,
            "weights": {name: round(float(w), 6) for name, w in zip(names, frame.weights)},
            "head_rotation": None if frame.head_rotation is None else [float(x) for x in frame.head_rotation],
            "lost": bool(frame.flags & FLAG_LOST_POINTS), "last": bool(frame.flags & FLAG_LAST)}


def arkit_shapes_binary(names, deltas) -> bytes:
    """The RTAK bytes (above) of (K, V, 3) morph targets named `names`."""
    d = np.asarray(deltas, dtype=np.float32)
    if d.ndim != 3 or d.shape[2] != 3 or d.shape[0] != len(names) or not np.isfinite(d).all():
        raise ValueError(f"deltas must be finite with shape ({len(names)}, V, 3); got {d.shape}")
    k, v, _ = d.shape
    peaks = np.abs(d).max(axis=(1, 2)).astype(np.float64)
    scales = np.where(peaks > 0, peaks / 32767.0, 1.0)
    blocks, counts = [], []
    for s in range(k):
        q = np.rint(d[s] / scales[s]).astype("<i2")
        moving = np.flatnonzero(q.any(axis=1) & (np.linalg.norm(d[s], axis=1) >= SHAPES_FLOOR * peaks[s]))
        moving = moving.astype("<u4")
        values = np.ascontiguousarray(q[moving]).tobytes()
        blocks += [moving.tobytes(), values, b"\0" * (-len(values) % 4)]
        counts.append(len(moving))
    header = json.dumps({"names": list(names), "counts": counts, "scales": scales.tolist()}).encode()
    header += b" " * (-len(header) % 4)
    return (ARKIT_SHAPES_HEADER.pack(ARKIT_SHAPES_MAGIC, ARKIT_SHAPES_VERSION, v, k, len(header))
            + header + b"".join(blocks))


def decode_arkit_shapes(data: bytes) -> tuple[list[str], np.ndarray]:
    """(K names, (K, V, 3) float32 deltas) of RTAK bytes; ValueError when malformed."""
    if len(data) < ARKIT_SHAPES_HEADER.size:
        raise ValueError("ARKit shapes: shorter than the header")
    magic, version, v, k, j = ARKIT_SHAPES_HEADER.unpack_from(data)
    if magic != ARKIT_SHAPES_MAGIC or version != ARKIT_SHAPES_VERSION:
        raise ValueError(f"not ARKit shapes version {ARKIT_SHAPES_VERSION} (magic {magic!r}, version {version})")
    at = ARKIT_SHAPES_HEADER.size
    header = json.loads(data[at:at + j])
    at += j
    deltas = np.zeros((k, v, 3), np.float32)
    for s, (count, scale) in enumerate(zip(header["counts"], header["scales"])):
        vertices = np.frombuffer(data, "<u4", count, at)
        at += 4 * count
        deltas[s, vertices] = np.frombuffer(data, "<i2", 3 * count, at).reshape(count, 3) * np.float32(scale)
        at += 6 * count + (-6 * count % 4)
    if at != len(data):
        raise ValueError(f"ARKit shapes: {len(data)} bytes, expected {at}")
    return header["names"], deltas
