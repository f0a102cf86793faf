"""Hostile inputs for the server's upload routes: a valid seed file of every format the
server reads, made by code (nothing binary is committed), and seeded mutators that damage
them the way fuzzers and malicious users do.

Used by ``tests/e2e/test_fuzz_uploads.py`` (a bounded fuzz through a real server) and
``bench/hostile.py`` (hundreds of mutants per format plus the audit's named inputs).

Seeds (`take_seeds`, `mesh_seeds`, `import_seed`) are built from a small face: a few
hundred vertices of the library's procedural sample face (`retarget.sample_face`),
re-triangulated over its texture plane, with its 12 expressions and its 68 iBUG landmarks
as vertices 0-67. Takes are 10 frames of those landmarks (ibug68) posed by the demo
performance.

Mutators are functions ``(data, rng) -> (label, bytes)`` with ``rng`` a `random.Random`:
generic byte damage (`GENERIC`) and format-aware damage (`FORMAT_AWARE`, by file
extension) that aims at the fields parsers trust: C3D header and parameter bytes, zip
central directories and sizes, glTF JSON (counts, offsets, indices), .npy headers, mesh
headers and indices, and text tables and JSON (huge numbers, deep nesting, long cells).
`mutants` draws a reproducible sequence of them for one seed.
"""

from __future__ import annotations

import io
import json
import random
import struct
import tempfile
import zipfile
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

__all__ = ["FORMAT_AWARE", "GENERIC", "LABELLED", "MESH_EXTENSIONS", "Mutant", "ROUTES", "Seed",
           "SmallFace", "TAKE_EXTENSIONS", "answer_fault", "c3d_seed", "c3d_two_bytes",
           "glb_bytes", "glb_parts", "import_seed", "mesh_seeds", "mutants", "send_upload",
           "small_face", "take_seeds"]

TAKE_EXTENSIONS = ("csv", "json", "npy", "trc", "c3d", "glb", "gltf", "zip")
MESH_EXTENSIONS = ("obj", "ply", "stl", "off", "glb", "gltf")
N_FRAMES = 10
FPS = 10.0
ROUTES = {
    "take": ("POST", "/api/projects/{project}/takes"),
    "mesh": ("PUT", "/api/projects/{project}/mesh"),
    "import": ("POST", "/api/projects/import"),
}
"""(method, path) of each kind of upload; ``{project}`` is the target project's id."""


@dataclass(frozen=True)
class Seed:
    """A valid upload: `kind` one of `ROUTES`, its file extension, bytes and the extra
    multipart form fields its route needs (``layout``, ``labelled_vertices``...)."""

    kind: str
    ext: str
    data: bytes
    form: dict = field(default_factory=dict)

    @property
    def filename(self) -> str:
        return f"seed.{self.ext}"


@dataclass(frozen=True)
class Mutant:
    """A damaged `Seed`: what was done (`label`, for reports), the bytes and form fields."""

    seed: Seed
    index: int
    label: str
    data: bytes
    form: dict

    @property
    def filename(self) -> str:
        return f"fuzz-{self.index:04d}.{self.seed.ext}"


# --- the small face ------------------------------------------------------------------------

@dataclass(frozen=True)
class SmallFace:
    """vertices : (V, 3) float64 cm; faces : (T, 3) int64; expressions : (E, V, 3)
    float64 cm; weights : (N_FRAMES, E) float64, the demo performance's expression
    weights at 10 fps; landmarks: vertices 0-67 are the iBUG 68 points in order."""

    vertices: np.ndarray
    faces: np.ndarray
    expressions: np.ndarray
    weights: np.ndarray

    def posed(self) -> np.ndarray:
        """(N_FRAMES, V, 3) float64 cm, the face in every frame."""
        return self.vertices + np.einsum("fe,evd->fvd", self.weights, self.expressions)

    def landmark_frames(self) -> np.ndarray:
        """(N_FRAMES, 68, 3) float64 cm, the iBUG points in every frame."""
        return self.posed()[:, :68]


@lru_cache(maxsize=1)
def small_face(n_extra: int = 230) -> SmallFace:
    """The sample face cut down to its 68 landmarks plus `n_extra` spread vertices,
    triangulated (Delaunay) over its texture coordinates, which are a plane."""
    from scipy.spatial import Delaunay

    from retarget.sample_face import demo_weights, sample_face

    face = sample_face(1)
    landmarks = np.asarray(face.landmarks68)
    others = np.setdiff1d(np.arange(len(face.vertices)), landmarks)
    extra = others[np.linspace(0, len(others) - 1, n_extra).astype(int)]
    keep = np.concatenate([landmarks, extra])
    uv = face.uv[keep].copy()
    # slit copies share their uv: nudge repeats apart so every vertex is triangulated
    _, first, counts = np.unique(uv.round(9), axis=0, return_index=True, return_counts=True)
    for row in first[counts > 1]:
        same = np.flatnonzero(np.all(np.abs(uv - uv[row]) < 1e-9, axis=1))
        uv[same[1:]] += 1e-4 * np.arange(1, len(same))[:, None]
    triangles = Delaunay(uv).simplices.astype(np.int64)
    # counter-clockwise seen from +z (the face looks toward +z)
    v = face.vertices[keep]
    normal_z = np.cross(v[triangles[:, 1]] - v[triangles[:, 0]], v[triangles[:, 2]] - v[triangles[:, 0]])[:, 2]
    triangles[normal_z < 0] = triangles[normal_z < 0][:, ::-1]
    weights = demo_weights(int(4.5 * 30), 30)[105::3][:N_FRAMES]
    return SmallFace(v, triangles, face.expressions[:, keep], np.asarray(weights, dtype=np.float64))


def _ibug_names() -> tuple[str, ...]:
    from retarget.layouts import get_layout

    return get_layout("ibug68").point_names


LABELLED = json.dumps({"vertex_indices": list(range(68)), "layout": "ibug68"})
"""`labelled_vertices` of the small face's animated files: its first 68 vertices."""


# --- seeds -----------------------------------------------------------------------------------

def take_seeds() -> dict[str, Seed]:
    """One valid take file per extension of `TAKE_EXTENSIONS`."""
    face = small_face()
    points = face.landmark_frames()  # (F, 68, 3) cm
    names = _ibug_names()
    return {
        "csv": Seed("take", "csv", _csv(points, names)),
        "json": Seed("take", "json", json.dumps(
            {"layout": "ibug68", "fps": FPS, "units": "cm",
             "frames": np.round(points, 5).tolist()}).encode()),
        "npy": Seed("take", "npy", _npy(points.astype("<f4")), {"layout": "ibug68"}),
        "trc": Seed("take", "trc", _trc(points * 10, names)),
        "c3d": c3d_seed(),
        "glb": Seed("take", "glb", _animated_gltf(binary=True), {"labelled_vertices": LABELLED}),
        "gltf": Seed("take", "gltf", _animated_gltf(binary=False), {"labelled_vertices": LABELLED}),
        "zip": Seed("take", "zip", _obj_zip(face.posed()[:6], face.faces),
                    {"labelled_vertices": LABELLED, "fps": "24"}),
    }


def mesh_seeds() -> dict[str, Seed]:
    """One valid mesh file per extension of `MESH_EXTENSIONS` (the small face)."""
    from retarget.mesh import mesh_from_arrays, save_mesh

    face = small_face()
    mesh = mesh_from_arrays(face.vertices, face.faces, name="small_face")
    seeds = {}
    with tempfile.TemporaryDirectory() as folder:
        for ext in MESH_EXTENSIONS:
            path = Path(folder) / f"small_face.{ext}"
            save_mesh(mesh, path)
            seeds[ext] = Seed("mesh", ext, path.read_bytes())
    return seeds


@lru_cache(maxsize=1)
def c3d_seed() -> Seed:
    """A C3D take (ezc3d): the 68 iBUG points in mm at 120 fps, residuals and camera masks."""
    import ezc3d

    points = small_face().landmark_frames() * 10
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [120.0]
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = tuple(_ibug_names())
    f, n = points.shape[:2]
    data = np.ones((4, n, f))
    data[:3] = points.transpose(2, 1, 0)
    c3d["data"]["points"] = data
    c3d["data"]["meta_points"]["residuals"] = np.zeros((1, n, f))
    c3d["data"]["meta_points"]["camera_masks"] = np.zeros((7, n, f), dtype=bool)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "take.c3d"
        c3d.write(str(path))
        return Seed("take", "c3d", path.read_bytes())


def import_seed(method: str = "geodesic") -> Seed:
    """A .glb as the app exports a project (`retarget.gltf.export_gltf`): the small
    face, its 68 landmarks, a rig of `method` (a joint rig is a glTF skin, ~30 kB; an
    interpolating one, e.g. biharmonic, morph targets, ~800 kB) and one 10-frame
    animation."""
    from retarget.gltf import export_gltf
    from retarget.landmarks import from_vertex_indices
    from retarget.layouts import get_layout
    from retarget.mesh import mesh_from_arrays
    from retarget.performance import take_clip
    from retarget.sources.take import Take
    from retarget.weights import compute_weights

    face = small_face()
    mesh = mesh_from_arrays(face.vertices, face.faces, name="small_face")
    points = from_vertex_indices(np.arange(68), len(face.vertices), layout="ibug68")
    weights = compute_weights(method, mesh.vertices, mesh.faces, points, get_layout("ibug68"))
    take = Take(face.landmark_frames(), _ibug_names(), FPS, layout="ibug68", source="fuzz")
    clip = take_clip("performance", take, face.vertices[:68], "ibug68")
    return Seed("import", "glb", export_gltf(mesh, points, weights, [clip]))


def _csv(points: np.ndarray, names) -> bytes:
    from retarget.sources.files import write_take_csv
    from retarget.sources.take import Take

    out = io.StringIO()
    write_take_csv(Take(points, tuple(names), FPS, layout="ibug68", source="fuzz"), out)
    return out.getvalue().encode()


def _npy(array: np.ndarray) -> bytes:
    out = io.BytesIO()
    np.save(out, array)
    return out.getvalue()


def _trc(mm: np.ndarray, labels) -> bytes:
    f, n = mm.shape[:2]
    rate = 100.0
    lines = ["PathFileType\t4\t(X/Y/Z)\ttake.trc",
             "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
             f"{rate}\t{rate}\t{f}\t{n}\tmm\t{rate}\t1\t{f}",
             "Frame#\tTime\t" + "\t\t\t".join(labels) + "\t\t",
             "\t\t" + "\t".join(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(n)),
             ""]
    for i in range(f):
        lines.append("\t".join([str(i + 1), f"{i / rate:.5f}"] + [f"{v:.6f}" for v in mm[i].ravel()]))
    return ("\n".join(lines) + "\n").encode()


def _obj(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    return ("\n".join(lines) + "\n").encode()


def _obj_zip(frames: np.ndarray, faces: np.ndarray) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
        for i, vertices in enumerate(frames):
            archive.writestr(f"seq/face_{i + 1:04d}.obj", _obj(vertices, faces))
    return out.getvalue()


def _animated_gltf(binary: bool) -> bytes:
    """The small face with its expressions as morph targets, animated by the demo
    weights at 10 fps (linear): as .glb, or as .gltf with a data-URI buffer."""
    face = small_face()
    blob = bytearray()
    accessors, views = [], []

    def accessor(array, kind, component, extra=None):
        array = np.ascontiguousarray(array)
        blob.extend(b"\0" * (-len(blob) % 4))
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": array.nbytes})
        blob.extend(array.tobytes())
        width = {"SCALAR": 1, "VEC3": 3}[kind]
        accessors.append({"bufferView": len(views) - 1, "componentType": component,
                          "count": array.size // width, "type": kind, **(extra or {})})
        return len(accessors) - 1

    def vec3(array):
        array = np.asarray(array, dtype="<f4")
        return accessor(array, "VEC3", 5126, {"min": array.min(0).tolist(), "max": array.max(0).tolist()})

    primitive = {"attributes": {"POSITION": vec3(face.vertices)},
                 "indices": accessor(face.faces.astype("<u4").ravel(), "SCALAR", 5125),
                 "targets": [{"POSITION": vec3(t)} for t in face.expressions]}
    times = accessor((np.arange(N_FRAMES) / FPS).astype("<f4"), "SCALAR", 5126,
                     {"min": [0.0], "max": [(N_FRAMES - 1) / FPS]})
    values = accessor(face.weights.astype("<f4").ravel(), "SCALAR", 5126)
    doc = {"asset": {"version": "2.0", "generator": "tests.hostile_inputs"},
           "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0, "name": "face"}],
           "meshes": [{"primitives": [primitive], "weights": [0.0] * len(face.expressions)}],
           "accessors": accessors, "bufferViews": views,
           "animations": [{"name": "performance",
                           "samplers": [{"input": times, "output": values, "interpolation": "LINEAR"}],
                           "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}]}],
           "buffers": [{"byteLength": len(blob)}]}
    if binary:
        return glb_bytes(doc, bytes(blob))
    import base64

    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(bytes(blob)).decode()
    return json.dumps(doc).encode()


def glb_bytes(doc: dict, blob: bytes) -> bytes:
    """A GLB container of the JSON `doc` and the binary chunk `blob`, lengths consistent."""
    text = json.dumps(doc, allow_nan=True).encode()
    text += b" " * (-len(text) % 4)
    blob = blob + b"\0" * (-len(blob) % 4)
    chunks = struct.pack("<I4s", len(text), b"JSON") + text
    if blob:
        chunks += struct.pack("<I4s", len(blob), b"BIN\0") + blob
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


def glb_parts(data: bytes) -> tuple[dict, bytes]:
    """(JSON document, binary chunk) of a well-formed GLB."""
    n = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + n])
    rest = data[20 + n:]
    blob = rest[8:8 + struct.unpack_from("<I", rest, 0)[0]] if len(rest) >= 8 else b""
    return doc, blob


# --- generic mutators ------------------------------------------------------------------------

INTERESTING_32 = (0, 1, 0x7F, 0x80, 0xFF, 0x7FFF, 0x8000, 0xFFFF, 0x10000, 0x7FFFFFFF,
                  0x80000000, 0xFFFFFFFF, 0xFFFFFFFE, 1 << 20, 1 << 24, 1 << 30)
INTERESTING_NUMBERS = (-1, 0, 1, 2 ** 31 - 1, 2 ** 31, 2 ** 32 - 1, 2 ** 32 + 5, 2 ** 53 + 1,
                       10 ** 12, 10 ** 30, -(2 ** 63), 1e308, 1e-320, 0.5, -0.0)


def flip_bytes(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    out = bytearray(data)
    n = rng.randint(1, 8)
    at = [rng.randrange(len(out)) for _ in range(n)]
    for i in at:
        out[i] ^= rng.randint(1, 255)
    return f"xor {n} bytes at {sorted(at)[:8]}", bytes(out)


def overwrite_bytes(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    out = bytearray(data)
    n = rng.randint(1, 8)
    at = rng.randrange(len(out))
    out[at:at + n] = bytes(rng.choice((0, 0xFF, 0x7F, 0x80, rng.randrange(256))) for _ in range(n))
    return f"overwrite {n} bytes at {at}", bytes(out)


def interesting_int(data: bytes, rng: random.Random, lo: int = 0, hi: int | None = None) -> tuple[str, bytes]:
    """A 16- or 32-bit boundary value written over bytes in [lo, hi)."""
    hi = len(data) if hi is None else min(hi, len(data))
    width = rng.choice((2, 4))
    if hi - lo < width:
        return flip_bytes(data, rng)
    at = rng.randrange(lo, hi - width + 1)
    value = rng.choice(INTERESTING_32) & ((1 << (8 * width)) - 1)
    order = rng.choice("<>")
    packed = struct.pack(order + ("H" if width == 2 else "I"), value)
    return f"{8 * width}-bit {value:#x} ({'LE' if order == '<' else 'BE'}) at {at}", \
        data[:at] + packed + data[at + width:]


def truncate(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    cut = rng.choice((rng.randrange(1, len(data)), rng.randrange(1, min(len(data), 64) + 1),
                      len(data) - rng.randint(1, min(len(data) - 1, 16))))
    return f"truncated to {cut} of {len(data)} bytes", data[:cut]


def duplicate_chunk(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    start = rng.randrange(len(data))
    size = rng.randint(1, min(4096, len(data) - start))
    at = rng.randrange(len(data) + 1)
    times = rng.choice((1, 1, 2, 16))
    return f"copied {size} bytes from {start} to {at} x{times}", \
        data[:at] + data[start:start + size] * times + data[at:]


def insert_junk(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    at = rng.randrange(len(data) + 1)
    junk = rng.choice((bytes(rng.randrange(256) for _ in range(rng.randint(1, 64))),
                       b"\0" * rng.randint(1, 512), b"\xff" * rng.randint(1, 512),
                       b"\xef\xbb\xbf", b"\r\n" * 8, "é€😀".encode(), b"\x80\x81\xfe"))
    return f"inserted {len(junk)} junk bytes at {at}", data[:at] + junk + data[at:]


def zero_range(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    start = rng.randrange(len(data))
    size = rng.randint(1, min(len(data) - start, rng.choice((4, 64, 1024, len(data)))))
    return f"zeroed {size} bytes at {start}", data[:start] + b"\0" * size + data[start + size:]


GENERIC = (flip_bytes, overwrite_bytes, interesting_int, truncate, duplicate_chunk, insert_junk, zero_range)


# --- format-aware mutators ---------------------------------------------------------------------

def c3d_header_or_parameters(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """1-2 bytes (or a boundary value) in the header or parameter section, before the data
    block the header names: the numbers ezc3d trusts to size and index what it reads."""
    data_block = struct.unpack_from("<H", data, 16)[0] if len(data) >= 18 else 2
    end = max(8, min(len(data), (max(data_block, 2) - 1) * 512))
    if rng.random() < 0.3:
        label, out = interesting_int(data, rng, 0, end)
        return "c3d " + label, out
    out = bytearray(data)
    n = rng.choice((1, 2, 2))
    at = sorted(rng.randrange(end) for _ in range(n))
    for i in at:
        out[i] = rng.randrange(256)
    return f"c3d random bytes at {at} (header+parameters end at {end})", bytes(out)


def c3d_two_bytes(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """Two random bytes set anywhere (the audit's crashing mutation)."""
    out = bytearray(data)
    at = sorted(rng.randrange(len(out)) for _ in range(2))
    for i in at:
        out[i] = rng.randrange(256)
    return f"c3d 2 random bytes at {at}", bytes(out)


def _zip_records(data: bytes, signature: bytes) -> list[int]:
    found, at = [], data.find(signature)
    while at >= 0:
        found.append(at)
        at = data.find(signature, at + 4)
    return found


def zip_directory(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """A field of the end record, a central directory entry or a local header set to a
    boundary value (sizes, counts, offsets, name lengths)."""
    records = [(at, "end", (8, 10, 12, 16, 20)) for at in _zip_records(data, b"PK\x05\x06")]
    records += [(at, "central", (10, 20, 24, 28, 30, 32, 42)) for at in _zip_records(data, b"PK\x01\x02")]
    records += [(at, "local", (8, 18, 22, 26, 28)) for at in _zip_records(data, b"PK\x03\x04")]
    if not records:
        return flip_bytes(data, rng)
    at, kind, offsets = rng.choice(records)
    where = at + rng.choice(offsets)
    width = 2 if (kind, where - at) in {("end", 8), ("end", 10), ("end", 20), ("central", 10),
                                         ("central", 28), ("central", 30), ("central", 32),
                                         ("local", 8), ("local", 26), ("local", 28)} else 4
    value = rng.choice(INTERESTING_32) & ((1 << (8 * width)) - 1)
    packed = struct.pack("<H" if width == 2 else "<I", value)
    return f"zip {kind} record at {at}: field +{where - at} = {value:#x}", \
        data[:where] + packed + data[where + width:]


def zip_central_bytes(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """Random bytes inside the central directory and end record."""
    start = min(_zip_records(data, b"PK\x01\x02") or [len(data) - 22])
    out = bytearray(data)
    n = rng.randint(1, 6)
    at = sorted(rng.randrange(start, len(out)) for _ in range(n))
    for i in at:
        out[i] = rng.randrange(256)
    return f"zip central directory bytes at {at}", bytes(out)


def _json_slots(node, path=()):
    """Every (container, key, path) of a JSON tree, leaves and branches."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for key, value in items:
        yield node, key, path + (key,)
        if isinstance(value, (dict, list)) and len(path) < 12:
            # long numeric lists: visit a few elements only
            if isinstance(value, list) and len(value) > 8:
                for i in sorted(random.Random(len(value)).sample(range(len(value)), 4)):
                    yield value, i, path + (key, i)
                    if isinstance(value[i], (dict, list)):
                        yield from _json_slots(value[i], path + (key, i))
            else:
                yield from _json_slots(value, path + (key,))


def hostile_json_value(rng: random.Random):
    """A value that parsers of JSON documents mishandle."""
    kind = rng.randrange(9)
    if kind == 0:
        return rng.choice(INTERESTING_NUMBERS)
    if kind == 1:
        return rng.choice((float("nan"), float("inf"), float("-inf")))
    if kind == 2:
        return None
    if kind == 3:
        return rng.choice(("", "x" * rng.choice((1, 1000, 100_000)), "../../etc/passwd", "\u0000"))
    if kind == 4:
        return rng.choice(([], {}, [[]], {"a": 1}))
    if kind == 5:
        return [rng.choice(INTERESTING_NUMBERS)] * rng.choice((2, 5, 1000, 100_000))
    if kind == 6:
        return rng.choice((True, False))
    if kind == 7:
        return -rng.randint(1, 10)
    return rng.randint(0, 64)


def _mutated_doc(doc, rng: random.Random) -> tuple[str, object]:
    slots = list(_json_slots(doc))
    if not slots:
        return "empty document", doc
    container, key, path = rng.choice(slots)
    shown = "/".join(map(str, path))
    if isinstance(container, dict) and rng.random() < 0.15:
        del container[key]
        return f"removed {shown}", doc
    value = hostile_json_value(rng)
    container[key] = value
    text = repr(value)
    return f"{shown} = {text[:40]}{'...' if len(text) > 40 else ''}", doc


def gltf_json(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """One value of a .gltf document (an index, count, offset, type...) made hostile."""
    try:
        doc = json.loads(data)
    except ValueError:
        return flip_bytes(data, rng)
    label, doc = _mutated_doc(doc, rng)
    return "gltf " + label, json.dumps(doc, allow_nan=True).encode()


def glb_json(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """As `gltf_json` for the JSON chunk of a .glb, the container rebuilt consistently so
    the damage reaches the document's reader."""
    try:
        doc, blob = glb_parts(data)
    except (ValueError, struct.error):
        return flip_bytes(data, rng)
    label, doc = _mutated_doc(doc, rng)
    return "glb " + label, glb_bytes(doc, blob)


def glb_container(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """A GLB header or chunk header field (magic, version, lengths, chunk types)."""
    fields = [0, 4, 8, 12, 16]
    if len(data) >= 20:
        n = struct.unpack_from("<I", data, 12)[0]
        fields += [20 + n, 24 + n]
    where = rng.choice([f for f in fields if f + 4 <= len(data)])
    value = rng.choice(INTERESTING_32 + (len(data), len(data) + 4, len(data) - 4))
    return f"glb header field {where} = {value:#x}", data[:where] + struct.pack("<I", value & 0xFFFFFFFF) + data[where + 4:]


def glb_instanced(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """The mesh instanced by up to 200 more nodes (each one more copy for a reader that
    flattens the scene; `bench/hostile.py` sends 5,000 as a named input)."""
    try:
        doc, blob = glb_parts(data)
    except (ValueError, struct.error):
        return flip_bytes(data, rng)
    n = rng.choice((20, 50, 200))
    mesh = doc.get("nodes", [{}])[0].get("mesh", 0)
    doc["nodes"] = doc.get("nodes", []) + [{"mesh": mesh, "translation": [i * 1.0, 0.0, 0.0]} for i in range(n)]
    doc.setdefault("scenes", [{"nodes": []}])[0]["nodes"] = list(range(len(doc["nodes"])))
    return f"glb mesh instanced by {n} more nodes", glb_bytes(doc, blob)


def json_text(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """A JSON take made hostile: a structured edit, deep nesting, or huge numbers."""
    kind = rng.randrange(5)
    if kind == 0:
        depth = rng.choice((1000, 20_000, 200_000))
        return f"frames nested {depth} deep", \
            ('{"layout": "ibug68", "frames": ' + "[" * depth + "]" * depth + "}").encode()
    if kind == 1:
        digits = rng.choice((400, 5000, 100_000))
        text = data.decode()
        at = text.find("[", text.find('"frames"')) + 3
        return f"a {digits}-digit number", (text[:at] + "1" * digits + ", " + text[at:]).encode()
    if kind == 2:
        token = rng.choice(("1e400", "-1e400", "NaN", "Infinity", "1e-400", "0x10", "01"))
        text = data.decode()
        at = text.find("[", text.find('"frames"')) + 3
        end = text.find(",", at)
        return f"a number replaced by {token}", (text[:at] + token + text[end:]).encode()
    if kind == 3:
        names = [f"p{i}" for i in range(rng.choice((10_000, 50_000)))]
        return f"{len(names)} names, one frame", json.dumps({"names": names, "frames": [[[0, 0, 0]] * len(names)]}).encode()
    label, doc = _mutated_doc(json.loads(data), rng)
    return "json " + label, json.dumps(doc, allow_nan=True).encode()


def table_text(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """A CSV or TRC take made hostile: a huge, long or non-number cell, a ragged row,
    thousands of columns, NUL bytes or a line without breaks."""
    sep = b"\t" if data.startswith(b"PathFileType") else b","
    lines = data.split(b"\n")
    row = rng.randrange(len(lines))
    cells = lines[row].split(sep)
    col = rng.randrange(len(cells))
    kind = rng.randrange(8)
    if kind == 0:
        cells[col] = rng.choice((b"1e999", b"-1e999", b"nan", b"inf", b"1" * 5000, b"0x1p3", b"1_000"))
    elif kind == 1:
        cells[col] = b"x" * rng.choice((1000, 200_000, 2_000_000))
    elif kind == 2:
        cells += [b"1.0"] * rng.choice((1, 100, 100_000))
    elif kind == 3:
        del cells[rng.randrange(len(cells)):]
    elif kind == 4:
        cells[col] = cells[col] + b"\0" * 4
    elif kind == 5:
        cells[col] = b'"' + cells[col]  # an unclosed quote
    elif kind == 6:
        lines = [line.replace(b"\n", b"") for line in lines]
        return "every line break removed", b"".join(lines)
    else:
        lines = lines[:row] + lines[row:row + 1] * rng.choice((2, 1000)) + lines[row + 1:]
        return f"line {row} repeated", b"\n".join(lines)
    lines[row] = sep.join(cells)
    return f"table line {row} cell {col}: edit {kind}", b"\n".join(lines)


def npy_header(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """A .npy with a hostile header: a shape claiming terabytes, odd dtypes, a wrong
    header length or version; the data bytes unchanged."""
    body = data[data.index(b"\n") + 1:] if b"\n" in data else data
    shape = rng.choice(("(2000000000, 68, 3)", "(10, 68, 3)", "(-1, 68, 3)", "(10, 68)", "()",
                        "(0, 68, 3)", "(10, 68, 3, 1)", "(4294967296, 4294967296, 3)", "(10, 68, 3"))
    descr = rng.choice(("'<f4'", "'<f4'", "'>f8'", "'|O'", "'<U8'", "'<c16'", "'V12'", "'<M8[s]'",
                        "[('a', '<f4')]", "'<f2'", "'|b1'", "'xyz'"))
    order = rng.choice(("False", "False", "True", "None"))
    header = f"{{'descr': {descr}, 'fortran_order': {order}, 'shape': {shape}, }}"
    header = header + " " * (-(len(header) + 11) % 64) + "\n"
    version = rng.choice((b"\x01\x00", b"\x01\x00", b"\x02\x00", b"\x03\x00", b"\x09\x00"))
    length = len(header)
    if rng.random() < 0.2:
        length = rng.choice((0, 1, 0xFFFF, length + 7))
    if version == b"\x01\x00":
        prefix = b"\x93NUMPY" + version + struct.pack("<H", length & 0xFFFF)
    else:
        prefix = b"\x93NUMPY" + version + struct.pack("<I", length)
    return f"npy v{version[0]} descr {descr} order {order} shape {shape} header length {length}", \
        prefix + header.encode() + body


def mesh_text(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """OBJ, OFF or ASCII PLY made hostile: huge or negative indices and counts, NaN
    coordinates, faces of thousands of corners."""
    text = data.decode("latin-1")
    lines = text.split("\n")
    kind = rng.randrange(6)
    if kind == 0:  # a face to a vertex that is not there
        i = rng.choice((-(10 ** 9), -1, 0, 2 ** 31, 10 ** 12, 2 ** 64))
        new = [f"f 1 2 {i}", f"3 0 1 {i}"]
    elif kind == 1:
        new = [f"v {rng.choice(('nan', 'inf', '1e400', '-1e999'))} 0 0", "1e400 0 0"]
    elif kind == 2:
        corners = rng.choice((100, 10_000))
        new = ["f " + " ".join(str(1 + k % 3) for k in range(corners)),
               f"{corners} " + " ".join(str(k % 3) for k in range(corners))]
    elif kind == 3:  # header counts (OFF's first numbers, PLY's element lines)
        huge = rng.choice(("4294967295", "2147483648", "-1", "1000000000000", "0"))
        for n, line in enumerate(lines[:20]):
            if line.startswith("element ") or (n <= 1 and line[:1].isdigit()):
                parts = line.split()
                parts[-1 if line.startswith("element ") else 0] = huge
                lines[n] = " ".join(parts)
                return f"header line {n} count = {huge}", "\n".join(lines).encode("latin-1")
        new = [f"f {huge} 1 2"]
    elif kind == 4:
        new = ["vt 0.5", "vn", "f 1/99999/1 2/1/99999 3//", "usemtl x", "mtllib ../../../etc/passwd", "o", "g"]
    else:
        new = ["v 1 2", "f 1", "f", "v"]
    at = rng.randrange(len(lines) + 1)
    chosen = rng.sample(new, rng.randint(1, len(new)))
    lines[at:at] = chosen
    return f"mesh lines inserted at {at}: {[c[:30] for c in chosen]}", "\n".join(lines).encode("latin-1")


def ply_header(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """A binary PLY's header: counts, property types, format."""
    end = data.find(b"end_header")
    if end < 0:
        return mesh_text(data, rng)
    header, body = data[:end].decode("latin-1"), data[end:]
    lines = header.split("\n")
    kind = rng.randrange(4)
    if kind == 0:
        n = rng.choice([i for i, line in enumerate(lines) if line.startswith("element")] or [0])
        value = rng.choice(("4294967295", "2147483647", "-5", "0", "1000000000000", "x"))
        parts = lines[n].split()
        parts[-1] = value
        lines[n] = " ".join(parts)
        label = f"ply {lines[n]}"
    elif kind == 1:
        n = rng.choice([i for i, line in enumerate(lines) if line.startswith("property")] or [0])
        lines[n] = rng.choice(("property list uint int vertex_indices", "property list uchar uint vertex_indices",
                               "property double x", "property list int int vertex_indices",
                               "property char x", "property float128 x"))
        label = f"ply {lines[n]}"
    elif kind == 2:
        lines[1] = rng.choice(("format ascii 1.0", "format binary_big_endian 1.0", "format binary_little_endian 9.9"))
        label = f"ply {lines[1]}"
    else:
        lines.insert(rng.randrange(1, len(lines) + 1), rng.choice(
            ("element vertex 5", "comment " + "x" * 100_000, "obj_info", "property list uchar int vertex_indices")))
        label = "ply header line inserted"
    return label, "\n".join(lines).encode("latin-1") + body


def stl_count(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """A binary STL's triangle count (bytes 80-83) set to a boundary value."""
    if len(data) < 84:
        return flip_bytes(data, rng)
    value = rng.choice(INTERESTING_32 + ((len(data) - 84) // 50 + 1, (len(data) - 84) // 50 - 1))
    out = data[:80] + struct.pack("<I", value & 0xFFFFFFFF) + data[84:]
    if rng.random() < 0.3:
        out = b"solid " + out[6:]  # a binary file that claims to be ASCII
    return f"stl triangle count {value:#x}", out


def _form_mutant(seed: Seed, rng: random.Random) -> tuple[str, dict]:
    """The take form's fields made hostile (the file is left valid)."""
    deep = "[" * 100_000 + "]" * 100_000
    fields = {
        "fps": ("0", "-1", "nan", "inf", "1e309", "abc", "1001", "", "1" * 5000),
        "layout": ("nope", "", "ibug68" * 100, "../ibug68", "\u0000"),
        "mapping": ("{", "[]", '{"a": 1}', '{"x": "jaw_0"}', deep, '"text"', "null"),
        "labelled_vertices": ('{"vertex_indices": [1e20]}', '{"a": -1}', '{"vertex_indices": [], "layout": "ibug68"}',
                              '{"vertex_indices": [0, 0, 0], "layout": "ibug68"}', deep, "[1, 2]",
                              '{"triangles": [[0, 1, 2]], "barycentric": [[1e308, -1e308, 0]]}',
                              json.dumps({"vertex_indices": list(range(68)), "layout": "mediapipe468"}),
                              json.dumps({f"p{i}": i % 50 for i in range(10_000)})),
        "name": ("x" * 201, "", "\u202e"),
    }
    key = rng.choice(list(fields))
    value = rng.choice(fields[key])
    return f"form {key} = {value[:40]!r}", {**seed.form, key: value}


FORMAT_AWARE = {
    "c3d": (c3d_header_or_parameters, c3d_header_or_parameters, c3d_two_bytes),
    "zip": (zip_directory, zip_directory, zip_central_bytes),
    "glb": (glb_json, glb_json, glb_json, glb_container, glb_instanced),
    "gltf": (gltf_json,),
    "json": (json_text,),
    "csv": (table_text,),
    "trc": (table_text,),
    "npy": (npy_header,),
    "obj": (mesh_text,),
    "off": (mesh_text,),
    "ply": (ply_header,),
    "stl": (stl_count,),
}
"""Format-aware mutators by file extension (repeats weight the draw)."""


def mutants(seed: Seed, count: int, rng_seed: int = 0, *, aware: float = 0.6,
            form: float = 0.08):
    """`count` reproducible `Mutant`s of `seed`: a fraction `aware` format-aware, a
    fraction `form` with a hostile form field instead (takes only), the rest generic;
    one in five stacks a second generic mutation. A generator: mutants are made as they
    are consumed (some are megabytes)."""
    rng = random.Random(f"{rng_seed}:{seed.kind}:{seed.ext}")
    aware_fns = FORMAT_AWARE.get(seed.ext, ())
    for index in range(count):
        draw = rng.random()
        if seed.kind == "take" and draw < form:
            label, fields = _form_mutant(seed, rng)
            yield Mutant(seed, index, label, seed.data, fields)
            continue
        fn = rng.choice(aware_fns) if aware_fns and draw < form + aware else rng.choice(GENERIC)
        label, data = fn(seed.data, rng)
        if rng.random() < 0.2 and data:
            more, data = rng.choice(GENERIC)(data, rng)
            label = f"{label}; {more}"
        yield Mutant(seed, index, label, data, dict(seed.form))


# --- sending and judging -----------------------------------------------------------------------

def send_upload(client, kind: str, project: str | None, filename: str, data: bytes,
                form: dict | None = None):
    """The `httpx.Response` to uploading `data` as `filename` to `kind`'s route (`ROUTES`)
    of `project`, with the multipart `form` fields beside the file."""
    method, path = ROUTES[kind]
    return client.request(method, path.format(project=project),
                          files={"file": (filename, data, "application/octet-stream")},
                          data=form or {})


def answer_fault(response) -> str | None:
    """What is wrong with an answer to hostile input, or None when it is a proper one:
    2xx, or 4xx with a JSON body ``{"detail": "<non-empty text>"}``."""
    code = response.status_code
    if 200 <= code < 300:
        return None
    if not 400 <= code < 500:
        return f"HTTP {code}: {response.text[:500]!r}"
    try:
        detail = response.json().get("detail")
    except (ValueError, AttributeError):
        return f"HTTP {code} without a JSON object body: {response.text[:300]!r}"
    if not isinstance(detail, str) or not detail.strip():
        return f"HTTP {code} whose detail is not a non-empty string: {response.text[:300]!r}"
    return None
