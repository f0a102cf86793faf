"""Hostile inputs against a real server: the upload fuzz at scale, the audit's named
inputs, cross-origin and foreign-host attempts, and what each costs the server's memory.

    python bench/hostile.py [--per-format 300] [--seed 0] [--skip-fuzz] [--skip-named]

`retarget serve` runs in a subprocess (temp data dir, free port, default limits: 64 MiB
uploads). Then:

fuzz      every upload format: `--per-format` mutants of a valid seed file
          (`tests.hostile_inputs`: take .csv .json .npy .trc .c3d .glb .gltf .zip, mesh
          .obj .ply .stl .off .glb .gltf, project import .glb with a skin rig and with a
          morph-target rig, a tenth as many of the sample project's own 7 MB export), each
          to its route.
named     the audit's inputs: a 500 MB mesh upload (declared and chunked), a chunked
          300 MB PATCH rig/weights with no Content-Length, a 50 MB landmarks JSON, a 20 MB
          and a 0.9 MB settings object, OBJ-frame zip bombs (1 GiB in one member; 4 GiB in
          200 members, sizes honest and sizes lying), a glTF mesh instanced by 5,000
          nodes (as a mesh of the small face, of the 8,430-vertex sample face, and as an
          animated take; and a triangle instanced by 5,000 nodes as a take), 10,000 landmark positions, JSON nested 200,000 deep (request
          bodies, a take file, a take form field, a stream control message), a .npy whose
          header claims 1.48 TiB.
origin    requests a page on http://evil.example could make, and a DNS-rebound Host:
          each must be refused (403 or 400, or the WebSocket handshake refused).

Memory, for every request: the server's peak is reset before it (``5`` written to
/proc/<pid>/clear_refs) and its VmRSS read; after it VmHWM is read: growth = VmHWM after -
VmRSS before. The isolated readers (children of the server's forkserver) are sampled every
10 ms by a thread (VmHWM of every descendant, found through /proc/<pid>/task/*/children),
and reported apart; a child that lives under 10 ms may be missed.

Progress goes to stderr (tqdm); the table to stdout: inputs tried, answers 2xx / 4xx (by
status, every 4xx checked for a JSON ``detail`` that is a non-empty string, and the most
common reasons) / 5xx (target 0), connection errors, server crashes (target 0; a crashed
server is restarted and the run goes on), the largest server RSS growth of one request
and which, the largest isolated-reader peak, cross-origin and foreign-host attempts
refused / made, the slowest answers, and the total time. Every improper answer is listed
with how to reproduce it (format, seed, mutant index).
"""

from __future__ import annotations

import argparse
import io
import json
import os
import re
import select
import socket
import struct
import sys
import threading
import time
import uuid
import zlib
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import httpx  # noqa: E402
from tqdm import tqdm  # noqa: E402

from bench.stream import ServerProcess, machine  # noqa: E402
from tests.hostile_inputs import (  # noqa: E402
    LABELLED,
    Seed,
    answer_fault,
    glb_bytes,
    glb_parts,
    import_seed,
    mesh_seeds,
    mutants,
    send_upload,
    small_face,
    take_seeds,
)

MiB = 1 << 20
EVIL = "http://evil.example"


# --- memory --------------------------------------------------------------------------------------

def _status_kib(pid: int, key: str) -> int | None:
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith(key + ":"):
                    return int(line.split()[1])
    except (OSError, ValueError):
        return None
    return None


def descendants(pid: int) -> list[int]:
    """Every live descendant of `pid` (children of each of its threads, recursively)."""
    found, stack = [], [pid]
    while stack:
        parent = stack.pop()
        try:
            tasks = os.listdir(f"/proc/{parent}/task")
        except OSError:
            continue
        for task in tasks:
            try:
                with open(f"/proc/{parent}/task/{task}/children") as children:
                    kids = [int(k) for k in children.read().split()]
            except (OSError, ValueError):
                continue
            found += kids
            stack += kids
    return found


class Memory:
    """The server's per-request peak (clear_refs / VmHWM) and a sampler of its
    descendants' peaks. `helpers` are the descendants alive when it starts (the
    forkserver and multiprocessing's resource tracker), reported apart from readers."""

    def __init__(self, pid: int):
        self.pid = pid
        self.helpers = set(descendants(pid))
        self.helper_peak_kib = 0
        self.window_peak_kib = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)
        self._thread.start()

    def _sample(self) -> None:
        while not self._stop.wait(0.01):
            for child in descendants(self.pid):
                peak = _status_kib(child, "VmHWM")
                if peak is None:
                    continue
                with self._lock:
                    if child in self.helpers:
                        self.helper_peak_kib = max(self.helper_peak_kib, peak)
                    else:
                        self.window_peak_kib = max(self.window_peak_kib, peak)

    def start(self) -> int:
        """Reset the server's peak and the readers' window; the server's VmRSS, KiB."""
        try:
            with open(f"/proc/{self.pid}/clear_refs", "w") as clear:
                clear.write("5")
        except OSError:
            pass
        with self._lock:
            self.window_peak_kib = 0
        return _status_kib(self.pid, "VmRSS") or 0

    def finish(self) -> tuple[int, int]:
        """(server VmHWM, largest reader VmHWM seen since `start`), KiB."""
        time.sleep(0.02)  # one more sample of readers still exiting
        with self._lock:
            return _status_kib(self.pid, "VmHWM") or 0, self.window_peak_kib

    def close(self) -> None:
        self._stop.set()
        self._thread.join(1)


# --- results -------------------------------------------------------------------------------------

@dataclass
class Result:
    """One input's outcome. status: HTTP status, or for a WebSocket "ws-refused" (the
    handshake), "ws-error" (an error message, stream still open), "ws-..." otherwise;
    None with `error` for a connection error."""

    group: str
    label: str
    status: int | str | None
    detail: str = ""
    fault: str | None = None
    error: str | None = None
    seconds: float = 0.0
    rss_before_kib: int = 0
    rss_growth_kib: int = 0
    reader_peak_kib: int = 0
    crashed: bool = False
    repro: str = ""
    answer: object = field(default=None, repr=False)  # the httpx.Response, when one came


@dataclass
class Tally:
    results: list[Result] = field(default_factory=list)
    crashes: list[str] = field(default_factory=list)
    origin_refused: int = 0
    origin_total: int = 0
    origin_notes: list[str] = field(default_factory=list)


def reason(detail: str) -> str:
    """A 4xx detail with its particulars (names, numbers, quotes) blanked, to group by."""
    text = re.sub(r"'[^']*'|\"[^\"]*\"", "'…'", detail)
    text = re.sub(r"\d+(\.\d+)?(e[+-]?\d+)?", "N", text)
    return text[:110]


# --- the server under test --------------------------------------------------------------------

class Target:
    """The server and the projects inputs go to; `check()` restarts a crashed server
    (counting the crash) so the run goes on."""

    def __init__(self, tally: Tally):
        self.tally = tally
        self.server: ServerProcess | None = None
        self.start()

    def start(self) -> None:
        self.server = ServerProcess().__enter__()
        self.client = httpx.Client(base_url=self.server.url, timeout=httpx.Timeout(300, connect=30))
        self.memory = Memory(self.server.pid)
        projects = self.client.get("/api/projects").json()
        self.sample = next(p["id"] for p in projects if p["name"] == "Sample face")
        reply = send_upload(self.client, "import", None, "takes.glb", import_seed().data)
        reply.raise_for_status()
        self.take_project = reply.json()["project"]["id"]  # 68 iBUG landmarks and a rig
        self.mesh_project = self.client.post("/api/projects", json={"name": "meshes"}).json()["id"]
        self.landmark_project = self.client.post("/api/projects", json={"name": "landmarks"}).json()["id"]
        mesh = mesh_seeds()["obj"]
        send_upload(self.client, "mesh", self.landmark_project, "face.obj", mesh.data).raise_for_status()

    def alive(self) -> bool:
        return self.server.process.poll() is None

    def check(self, after: str) -> bool:
        """True if the server is up; otherwise record the crash, restart, False."""
        if self.alive():
            return True
        log = self.server.log.read_text(errors="replace")[-4000:]
        self.tally.crashes.append(f"after {after}: exit {self.server.process.returncode}\n{log}")
        tqdm.write(f"SERVER CRASHED after {after} (exit {self.server.process.returncode}); restarting")
        self.stop()
        self.start()
        return False

    def stop(self) -> None:
        self.memory.close()
        self.client.close()
        self.server.__exit__(None, None, None)

    def measured(self, group: str, label: str, send, repro: str = "") -> Result:
        """`send()` (returning an httpx.Response, or a Result to complete) measured."""
        before = self.memory.start()
        t0 = time.perf_counter()
        try:
            answer = send()
            if isinstance(answer, Result):
                result = answer
            else:
                result = Result(group, label, answer.status_code, fault=answer_fault(answer))
                if 400 <= answer.status_code < 500 and result.fault is None:
                    result.detail = answer.json()["detail"]
                result.answer = answer
        except (httpx.TransportError, OSError) as exc:
            result = Result(group, label, None, error=f"{type(exc).__name__}: {exc}"[:300])
        except Exception as exc:  # noqa: BLE001 - e.g. a WebSocket client error: recorded
            result = Result(group, label, None, error=f"client: {type(exc).__name__}: {exc}"[:300])
        result.group, result.label, result.repro = group, label, repro
        result.seconds = time.perf_counter() - t0
        peak, readers = self.memory.finish()
        result.rss_before_kib, result.rss_growth_kib = before, max(0, peak - before)
        result.reader_peak_kib = readers
        result.crashed = not self.check(label)
        self.tally.results.append(result)
        return result


# --- the fuzz ----------------------------------------------------------------------------------

def fuzz(target: Target, per_format: int, rng_seed: int) -> None:
    seeds: list[tuple[str, Seed, int]] = []
    seeds += [(f"take .{ext}", seed, per_format) for ext, seed in take_seeds().items()]
    seeds += [(f"mesh .{ext}", seed, per_format) for ext, seed in mesh_seeds().items()]
    seeds.append(("import .glb (skin rig)", import_seed("geodesic"), per_format))
    seeds.append(("import .glb (morph rig)", import_seed("biharmonic"), max(1, per_format // 3)))
    sample_export = target.client.get(f"/api/projects/{target.sample}/export.glb", timeout=300)
    sample_export.raise_for_status()
    seeds.append(("import sample export .glb", Seed("import", "glb", sample_export.content),
                  max(1, per_format // 10)))
    for group, seed, count in seeds:
        for mutant in tqdm(mutants(seed, count, rng_seed), total=count, desc=group, file=sys.stderr,
                           leave=False, mininterval=1):
            def send(mutant=mutant):
                project_now = {"take": target.take_project, "mesh": target.mesh_project}.get(seed.kind)
                return send_upload(target.client, seed.kind, project_now, mutant.filename,
                                   mutant.data, mutant.form)
            result = target.measured(
                "fuzz " + group, f"{group} #{mutant.index}: {mutant.label}", send,
                repro=f"tests.hostile_inputs.mutants(<{seed.kind} .{seed.ext} seed>, {count}, "
                      f"{rng_seed}) item {mutant.index}")
            answer = result.answer
            if answer is not None and answer.status_code in (200, 201):
                forget(target, seed.kind, target.take_project, answer.json())
        done = [r for r in target.tally.results if r.group == "fuzz " + group]
        codes = Counter(r.status for r in done)
        tqdm.write(f"{group:28s} {len(done):4d} inputs: " + ", ".join(
            f"{code}: {n}" for code, n in sorted(codes.items(), key=lambda kv: str(kv[0]))),
            file=sys.stderr)


def forget(target: Target, kind: str, project: str | None, answer: dict) -> None:
    """Delete what an accepted mutant stored (a take, an imported project)."""
    try:
        if kind == "take":
            target.client.delete(f"/api/projects/{project}/takes/{answer['id']}")
        elif kind == "import":
            target.client.delete(f"/api/projects/{answer['project']['id']}")
    except httpx.HTTPError:
        pass


# --- raw HTTP for bodies too big to hold ---------------------------------------------------------

def stream_request(port: int, method: str, path: str, headers: dict, chunks, total: int | None,
                   timeout: float = 300.0) -> Result:
    """Send a request whose body comes from `chunks` (with ``Content-Length: total``, or
    chunked when `total` is None), stopping as soon as the server answers (a refusal
    before the body is in); the Result has the status and detail (or the error) and how
    many body bytes went out (in `detail` when no answer came)."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    sent = 0
    try:
        head = [f"{method} {path} HTTP/1.1", f"Host: 127.0.0.1:{port}", "Connection: close"]
        head += [f"{k}: {v}" for k, v in headers.items()]
        head.append(f"Content-Length: {total}" if total is not None else "Transfer-Encoding: chunked")
        sock.sendall(("\r\n".join(head) + "\r\n\r\n").encode())
        send_error = None
        try:
            for chunk in chunks:
                if select.select([sock], [], [], 0)[0]:
                    break  # the server has answered
                sock.sendall(chunk if total is not None else b"%x\r\n%s\r\n" % (len(chunk), chunk))
                sent += len(chunk)
            else:
                if total is None:
                    sock.sendall(b"0\r\n\r\n")
        except OSError as exc:  # the server closed while we sent: its answer may be waiting
            send_error = exc
        data = b""
        try:
            while b"\r\n\r\n" not in data or not _complete(data):
                part = sock.recv(65536)
                if not part:
                    break
                data += part
        except OSError as exc:
            if not data:
                return Result("", "", None, error=f"{type(exc).__name__} after {sent} body bytes "
                              f"(send: {send_error!r}): {exc}")
        if not data:
            return Result("", "", None, error=f"no answer after {sent} body bytes (send: {send_error!r})")
        status = int(data.split(b" ", 2)[1])
        body = data.split(b"\r\n\r\n", 1)[1]
        result = Result("", "", status)
        try:
            detail = json.loads(body).get("detail")
        except ValueError:
            detail = None
        if 400 <= status < 500 and (not isinstance(detail, str) or not detail.strip()):
            result.fault = f"HTTP {status} without a detail: {body[:200]!r}"
        elif status >= 500:
            result.fault = f"HTTP {status}: {body[:300]!r}"
        result.detail = f"{detail or ''} [{sent / MiB:.1f} MiB of the body sent]"
        return result
    finally:
        sock.close()


def _complete(data: bytes) -> bool:
    head, _, body = data.partition(b"\r\n\r\n")
    match = re.search(rb"content-length:\s*(\d+)", head, re.I)
    return match is None or len(body) >= int(match.group(1))


def repeated(block: bytes, total: int, size: int = MiB):
    """`block` repeated, `total` bytes in all, in chunks of about `size` bytes (whole
    blocks, so the stream is the block repeated whatever the chunk size)."""
    piece = block * max(1, size // len(block))
    left = total
    while left > 0:
        yield piece[:min(len(piece), left)]
        left -= len(piece)


def multipart_stream(filename: str, body_chunks, body_size: int, fields: dict | None = None):
    """(chunks, total size, content type) of a multipart body with one file part."""
    boundary = uuid.uuid4().hex
    head = b"".join(f"--{boundary}\r\nContent-Disposition: form-data; name=\"{k}\"\r\n\r\n{v}\r\n".encode()
                    for k, v in (fields or {}).items())
    head += (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"{filename}\"\r\n"
             "Content-Type: application/octet-stream\r\n\r\n").encode()
    tail = f"\r\n--{boundary}--\r\n".encode()

    def chunks():
        yield head
        yield from body_chunks
        yield tail

    return chunks(), len(head) + body_size + len(tail), f"multipart/form-data; boundary={boundary}"


# --- the named inputs ---------------------------------------------------------------------------

def zip_of(members: list[tuple[str, bytes, int, int]]) -> bytes:
    """A zip of already deflated members: (name, deflated bytes, crc32, size claimed)."""
    out, central = io.BytesIO(), io.BytesIO()
    for name, data, crc, size in members:
        offset = out.tell()
        raw = name.encode()
        out.write(struct.pack("<4sHHHHHIIIHH", b"PK\x03\x04", 20, 0, 8, 0, 0x21, crc, len(data),
                              size, len(raw), 0) + raw + data)
        central.write(struct.pack("<4sHHHHHHIIIHHHHHII", b"PK\x01\x02", 20, 20, 0, 8, 0, 0x21, crc,
                                  len(data), size, len(raw), 0, 0, 0, 0, 0, offset) + raw)
    start = out.tell()
    out.write(central.getvalue())
    n = len(members)
    out.write(struct.pack("<4sHHHHIIH", b"PK\x05\x06", 0, 0, n, n, len(central.getvalue()), start, 0))
    return out.getvalue()


def deflated(block: bytes, size: int) -> tuple[bytes, int]:
    """(raw deflate stream, crc32) of `block` repeated to `size` bytes."""
    squeeze = zlib.compressobj(9, zlib.DEFLATED, -15)
    parts, crc = [], 0
    for chunk in repeated(block, size, 4 * MiB):
        crc = zlib.crc32(chunk, crc)
        parts.append(squeeze.compress(chunk))
    parts.append(squeeze.flush())
    return b"".join(parts), crc


def instanced_glb(data: bytes, n: int) -> bytes:
    """`data` (a .glb whose node 0 holds a mesh) with that mesh instanced by `n` more nodes."""
    doc, blob = glb_parts(data)
    doc["nodes"] += [{"mesh": doc["nodes"][0]["mesh"], "translation": [float(i), 0.0, 0.0]}
                     for i in range(n)]
    doc["scenes"][0]["nodes"] = list(range(len(doc["nodes"])))
    return glb_bytes(doc, blob)


def triangles_glb(n: int) -> bytes:
    """A .glb of one triangle instanced by `n` nodes, node 0 moved by an animation: a
    take whose instanced vertices (3 n) are few, but whose instances are many."""
    blob = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "<f4").tobytes() + np.arange(3, dtype="<u4").tobytes()
            + np.array([0, 1], "<f4").tobytes() + np.array([[0, 0, 0], [0, 1, 0]], "<f4").tobytes())
    views = [{"buffer": 0, "byteOffset": o, "byteLength": n_bytes} for o, n_bytes in ((0, 36), (36, 12), (48, 8), (56, 24))]
    accessors = [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
                 {"bufferView": 1, "componentType": 5125, "count": 3, "type": "SCALAR"},
                 {"bufferView": 2, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0], "max": [1]},
                 {"bufferView": 3, "componentType": 5126, "count": 2, "type": "VEC3"}]
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": list(range(n))}],
           "nodes": [{"mesh": 0, "translation": [float(i), 0.0, 0.0]} for i in range(n)],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
           "accessors": accessors, "bufferViews": views, "buffers": [{"byteLength": len(blob)}],
           "animations": [{"samplers": [{"input": 2, "output": 3}],
                           "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}]}]}
    return glb_bytes(doc, blob)


def sample_face_glb() -> bytes:
    from retarget.gltf import export_mesh_gltf
    from retarget.mesh import mesh_from_arrays
    from retarget.sample_face import sample_face

    face = sample_face(1)
    return export_mesh_gltf(mesh_from_arrays(face.vertices, face.faces, name="sample"))


def deep(depth: int) -> str:
    return "[" * depth + "]" * depth


def npy_claiming(shape: tuple, body: bytes) -> bytes:
    header = f"{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}"
    header += " " * (-(len(header) + 11) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode() + body


def named_inputs(target: Target) -> None:
    port = target.server.port
    c = lambda: target.client  # noqa: E731 - the client of the server now up (after restarts)
    t, m, lm = (lambda: target.take_project), (lambda: target.mesh_project), (lambda: target.landmark_project)

    def raw(method, path, headers, chunks, total):
        return lambda: stream_request(target.server.port, method, path(), headers, chunks(), total)

    def upload_stream(kind_path, filename, size, block, declared, fields=None):
        def send():
            chunks, total, ctype = multipart_stream(filename, repeated(block, size), size, fields)
            return stream_request(target.server.port, *ROUTE_OF[kind_path](), {"Content-Type": ctype},
                                  chunks, total if declared else None)
        return send

    ROUTE_OF = {"mesh": lambda: ("PUT", f"/api/projects/{m()}/mesh"),
                "take": lambda: ("POST", f"/api/projects/{t()}/takes")}
    face = small_face()
    inputs = []
    inputs.append(("500 MB mesh upload, Content-Length declared (limit 64 MiB)",
                   upload_stream("mesh", "huge.obj", 500_000_000, b"v 0 0 0\n", True)))
    inputs.append(("500 MB mesh upload, chunked",
                   upload_stream("mesh", "huge.obj", 500_000_000, b"v 0 0 0\n", False)))
    inputs.append(("300 MB PATCH rig/weights, chunked, no Content-Length",
                   raw("PATCH", lambda: f"/api/projects/{t()}/rig/weights",
                       {"Content-Type": "application/octet-stream"},
                       lambda: repeated(b"RTSE", 300_000_000), None)))
    def big_landmarks():
        yield b'{"positions": ['
        yield from repeated(b"[0.5, 0.25, 1.0], ", 50_000_000 - 32)
        yield b"[0, 0, 0]]}"

    size_50 = len(b'{"positions": [') + 50_000_000 - 32 + len(b"[0, 0, 0]]}")
    inputs.append(("50 MB landmarks JSON, Content-Length declared",
                   raw("PUT", lambda: f"/api/projects/{lm()}/landmarks",
                       {"Content-Type": "application/json"}, big_landmarks, size_50)))
    inputs.append(("50 MB landmarks JSON, chunked",
                   raw("PUT", lambda: f"/api/projects/{lm()}/landmarks",
                       {"Content-Type": "application/json"}, big_landmarks, None)))
    inputs.append(("20 MB settings object (PATCH project)",
                   lambda: c().patch(f"/api/projects/{lm()}",
                                     json={"settings": {"blob": "x" * 20_000_000}})))
    inputs.append(("20 MB settings object (POST project)",
                   lambda: c().post("/api/projects", json={"name": "big", "settings": {
                       f"k{i}": "x" * 1000 for i in range(20_000)}})))
    inputs.append(("0.9 MB settings object (under the JSON cap, over the settings cap)",
                   lambda: c().patch(f"/api/projects/{lm()}",
                                     json={"settings": {f"k{i}": "x" * 900 for i in range(1000)}})))
    inputs.append(("10,000 landmark positions",
                   lambda: c().put(f"/api/projects/{lm()}/landmarks", json={"positions": (
                       face.vertices[np.random.default_rng(0).integers(0, len(face.vertices), 10_000)]
                       + np.random.default_rng(1).normal(0, 0.01, (10_000, 3))).round(4).tolist()})))
    depth = 200_000
    inputs.append(("JSON nested 200k deep: POST /api/projects body",
                   lambda: c().post("/api/projects", content='{"name": "deep", "settings": {"a": '
                                    + deep(depth) + "}}", headers={"Content-Type": "application/json"})))
    inputs.append(("JSON nested 200k deep: PUT landmarks body",
                   lambda: c().put(f"/api/projects/{lm()}/landmarks", content='{"positions": '
                                   + deep(depth) + "}", headers={"Content-Type": "application/json"})))
    inputs.append(("JSON nested 200k deep: PATCH rig/weights JSON body",
                   lambda: c().patch(f"/api/projects/{t()}/rig/weights", content='{"version": 1, "vertices": '
                                     + deep(depth) + "}", headers={"Content-Type": "application/json"})))
    inputs.append(("JSON nested 200k deep: .json take file",
                   lambda: send_upload(c(), "take", t(), "deep.json",
                                       ('{"layout": "ibug68", "frames": ' + deep(depth) + "}").encode())))
    seeds = take_seeds()
    inputs.append(("JSON nested 200k deep: take form field 'mapping'",
                   lambda: send_upload(c(), "take", t(), "take.csv", seeds["csv"].data,
                                       {"mapping": deep(depth)})))
    inputs.append(("JSON nested 200k deep: take form field 'labelled_vertices'",
                   lambda: send_upload(c(), "take", t(), "take.glb", seeds["glb"].data,
                                       {"labelled_vertices": deep(depth)})))
    inputs.append(("JSON nested 200k deep: stream control message",
                   lambda: ws_message(target, deep(depth))))
    body = io.BytesIO()
    np.save(body, face.landmark_frames().astype("<f4"))
    npy_body = body.getvalue()[body.getvalue().index(b"\n") + 1:]
    inputs.append((".npy header claiming 1.48 TiB (2e9 x 68 x 3 float32)",
                   lambda: send_upload(c(), "take", t(), "huge.npy", npy_claiming((2_000_000_000, 68, 3), npy_body),
                                       {"layout": "ibug68"})))
    # zip bombs of OBJ frames
    # an OBJ frame of the small face (vertices and triangles) repeated: every member parses
    frame = (mesh_seeds()["obj"].data.rstrip(b"\n") + b"\n")
    labelled = {"labelled_vertices": LABELLED}

    def one_gib_bomb():
        size = (1 << 30) // len(frame) * len(frame)
        data, crc = deflated(frame, size)
        return zip_of([("seq/face_0001.obj", data, crc, size)])

    def many_bomb(lie: bool):
        size = 20 * MiB // len(frame) * len(frame)
        data, crc = deflated(frame, size)
        return zip_of([(f"seq/face_{i + 1:04d}.obj", data, crc, len(frame) if lie else size)
                       for i in range(200)])

    built = {}

    def bomb(name, make):
        def send():
            if name not in built:
                built[name] = make()
            return send_upload(c(), "take", t(), f"{name}.zip", built[name], labelled)
        return send

    inputs.append(("zip bomb: one OBJ frame of 1 GiB", bomb("bomb1", one_gib_bomb)))
    inputs.append(("zip bomb: 200 OBJ frames of 20 MiB (4 GiB), sizes honest",
                   bomb("bomb200", lambda: many_bomb(False))))
    inputs.append(("zip bomb: 200 OBJ frames of 20 MiB, sizes claimed one frame's",
                   bomb("bomb200lie", lambda: many_bomb(True))))
    mesh_glb = mesh_seeds()["glb"].data
    inputs.append(("glTF mesh instanced by 5,000 nodes: mesh upload (small face, 1.5 M vertices)",
                   lambda: send_upload(c(), "mesh", m(), "instanced.glb", instanced_glb(mesh_glb, 5000))))
    inputs.append(("glTF mesh instanced by 5,000 nodes: mesh upload (sample face, 42 M vertices)",
                   lambda: send_upload(c(), "mesh", m(), "instanced.glb", instanced_glb(sample_face_glb(), 5000))))
    inputs.append(("glTF mesh instanced by 5,000 nodes: animated take (small face)",
                   lambda: send_upload(c(), "take", t(), "instanced.glb",
                                       instanced_glb(seeds["glb"].data, 5000), labelled)))
    inputs.append(("glTF triangle instanced by 5,000 nodes: animated take (15,000 vertices)",
                   lambda: send_upload(c(), "take", t(), "triangles.glb", triangles_glb(5000),
                                       {"labelled_vertices": json.dumps({"a": 0, "b": 14_999})})))
    for label, send in tqdm(inputs, desc="named inputs", file=sys.stderr, leave=False):
        result = target.measured("named", label, send)
        answer = result.answer
        if answer is not None and answer.status_code in (200, 201) and "/takes" in str(answer.request.url):
            forget(target, "take", target.take_project, answer.json())
        shown = result.status if result.error is None else f"connection error: {result.error}"
        tqdm.write(f"  {label}: {shown} {result.detail[:150]!r} ({result.seconds:.1f} s, server +"
                   f"{result.rss_growth_kib / 1024:.1f} MiB, reader peak {result.reader_peak_kib / 1024:.0f} MiB)",
                   file=sys.stderr)


def ws_message(target: Target, text: str, origin: str | None = None) -> Result:
    """Open the sample project's stream, send `text`, and say what came back: an error
    message with the stream still answering a ping ("ws-error"), or how it ended."""
    from websockets.exceptions import ConnectionClosed, InvalidStatus
    from websockets.sync.client import connect

    url = target.server.url.replace("http://", "ws://") + f"/api/projects/{target.sample}/stream"
    try:
        with connect(url, origin=origin, open_timeout=30, max_size=2**22) as ws:
            hello = json.loads(ws.recv(timeout=30))
            if hello.get("type") != "hello":
                return Result("", "", "ws-no-hello", fault=f"first message {hello!r:.200}")
            ws.send(text)
            while True:
                message = ws.recv(timeout=30)
                if isinstance(message, str):
                    break
            reply = json.loads(message)
            ws.send(json.dumps({"type": "ping", "t": 1}))
            while True:
                pong = ws.recv(timeout=30)
                if isinstance(pong, str) and json.loads(pong).get("type") == "pong":
                    break
        if reply.get("type") == "error" and reply.get("detail"):
            return Result("", "", "ws-error", detail=reply["detail"])
        return Result("", "", "ws-answered", detail=str(reply)[:200],
                      fault=f"no error message: {reply!r:.200}")
    except InvalidStatus as exc:
        return Result("", "", "ws-refused", detail=f"handshake answered {exc.response.status_code}")
    except ConnectionClosed as exc:
        return Result("", "", "ws-closed", detail=str(exc), fault=f"stream closed: {exc}")


# --- cross-origin and foreign hosts --------------------------------------------------------------

def raw_handshake(port: int, path: str, host: str, origin: str | None) -> int:
    """The status a WebSocket handshake with these Host and Origin headers gets."""
    key = "dGhlIHNhbXBsZSBub25jZQ=="
    lines = [f"GET {path} HTTP/1.1", f"Host: {host}", "Upgrade: websocket", "Connection: Upgrade",
             f"Sec-WebSocket-Key: {key}", "Sec-WebSocket-Version: 13"]
    if origin:
        lines.append(f"Origin: {origin}")
    with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
        sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        data = b""
        while b"\r\n" not in data:
            part = sock.recv(4096)
            if not part:
                break
            data += part
    return int(data.split(b" ", 2)[1]) if data else 0


def cross_origin(target: Target) -> None:
    tally = target.tally
    own = f"http://127.0.0.1:{target.server.port}"
    seed = mesh_seeds()["obj"]
    stream = f"/api/projects/{target.sample}/stream"
    attempts = [
        ("POST /api/projects, Origin evil.example",
         lambda: target.client.post("/api/projects", json={"name": "csrf"}, headers={"Origin": EVIL})),
        ("PUT mesh of the sample, Origin evil.example",
         lambda: target.client.put(f"/api/projects/{target.sample}/mesh", headers={"Origin": EVIL},
                                   files={"file": ("x.obj", seed.data)})),
        ("DELETE the sample project, Origin evil.example",
         lambda: target.client.delete(f"/api/projects/{target.sample}", headers={"Origin": EVIL})),
        ("POST /api/projects, Origin null",
         lambda: target.client.post("/api/projects", json={"name": "csrf"}, headers={"Origin": "null"})),
        ("POST /api/projects, Sec-Fetch-Site cross-site",
         lambda: target.client.post("/api/projects", json={"name": "csrf"},
                                    headers={"Sec-Fetch-Site": "cross-site"})),
        ("POST /api/projects, Origin on another port of 127.0.0.1",
         lambda: target.client.post("/api/projects", json={"name": "csrf"},
                                    headers={"Origin": f"http://127.0.0.1:{target.server.port + 1}"})),
        ("GET /api/projects, Host evil.example (DNS rebinding)",
         lambda: target.client.get("/api/projects", headers={"Host": "evil.example"})),
        ("POST /api/projects, Host evil.example",
         lambda: target.client.post("/api/projects", json={"name": "rebind"}, headers={"Host": "evil.example"})),
        ("GET the sample's mesh, Host evil.example:80",
         lambda: target.client.get(f"/api/projects/{target.sample}/mesh", headers={"Host": "evil.example:80"})),
        ("WebSocket stream, Origin evil.example",
         lambda: ws_status(raw_handshake(target.server.port, stream, f"127.0.0.1:{target.server.port}", EVIL))),
        ("WebSocket stream, Host evil.example",
         lambda: ws_status(raw_handshake(target.server.port, stream, "evil.example", None))),
        ("WebSocket stream, Host evil.example and its own Origin",
         lambda: ws_status(raw_handshake(target.server.port, stream, "evil.example", EVIL))),
    ]
    before = len(target.client.get("/api/projects").json())
    for label, send in attempts:
        result = target.measured("origin", label, send)
        tally.origin_total += 1
        refused = result.status in (400, 403, "ws-refused")
        tally.origin_refused += refused
        if not refused:
            tally.origin_notes.append(f"NOT refused: {label}: {result.status} {result.error or ''}")
    after = len(target.client.get("/api/projects").json())
    if after != before:
        tally.origin_notes.append(f"the project count changed from {before} to {after}")
    # the server's own page is not refused (a control, not counted)
    control = target.client.post("/api/projects", json={"name": "same-origin"}, headers={"Origin": own})
    tally.origin_notes.append(f"control: POST with the server's own Origin answered {control.status_code}")
    if control.status_code == 201:
        target.client.delete(f"/api/projects/{control.json()['id']}")
    code = raw_handshake(target.server.port, stream, f"127.0.0.1:{target.server.port}", own)
    tally.origin_notes.append(f"control: WebSocket with the server's own Origin answered {code}")


def ws_status(code: int) -> Result:
    return Result("", "", "ws-refused" if code in (400, 403) else f"ws-{code}",
                  detail=f"handshake answered {code}",
                  fault=None if code in (400, 403) else f"handshake answered {code}")


# --- the report ----------------------------------------------------------------------------------

def report(tally: Tally, seconds: float, args) -> None:
    results = tally.results
    http = [r for r in results if isinstance(r.status, int)]
    ok = [r for r in http if 200 <= r.status < 300]
    refused = [r for r in http if 400 <= r.status < 500]
    bad4 = [r for r in refused if r.fault]
    server_errors = [r for r in http if r.status >= 500]
    ws = [r for r in results if isinstance(r.status, str)]
    ws_bad = [r for r in ws if r.fault]
    conn = [r for r in results if r.status is None]
    worst = max(results, key=lambda r: r.rss_growth_kib, default=None)
    reader = max(results, key=lambda r: r.reader_peak_kib, default=None)
    slow = sorted(results, key=lambda r: -r.seconds)[:5]
    mib = lambda kib: f"{kib / 1024:.1f} MiB"  # noqa: E731
    print()
    print(f"bench/hostile.py --per-format {args.per_format} --seed {args.seed}")
    print(f"machine: {machine()}")
    print()
    rows = [
        ("inputs tried", f"{len(results)}  (fuzz {sum(r.group.startswith('fuzz') for r in results)}, "
                         f"named {sum(r.group == 'named' for r in results)}, "
                         f"cross-origin/host {sum(r.group == 'origin' for r in results)})"),
        ("answered 2xx", f"{len(ok)}"),
        ("answered 4xx", f"{len(refused)}  (" + ", ".join(f"{code}: {n}" for code, n in sorted(
            Counter(r.status for r in refused).items())) + f"); without a JSON detail string: {len(bad4)}"),
        ("WebSocket outcomes", ", ".join(f"{s}: {n}" for s, n in sorted(Counter(r.status for r in ws).items()))
         + f"; improper: {len(ws_bad)}"),
        ("answered 5xx (target 0)", f"{len(server_errors)}"),
        ("connection errors", f"{len(conn)}"),
        ("server crashes (target 0)", f"{len(tally.crashes)}"),
        ("largest server RSS growth, one request",
         f"{mib(worst.rss_growth_kib)}  ({worst.label[:90]}; RSS before {mib(worst.rss_before_kib)})"
         if worst else "-"),
        ("largest isolated-reader peak (VmHWM)",
         f"{mib(reader.reader_peak_kib)}  ({reader.label[:90]})" if reader else "-"),
        ("cross-origin / foreign-host refused", f"{tally.origin_refused} / {tally.origin_total}"),
        ("total time", f"{seconds:.0f} s"),
    ]
    width = max(len(k) for k, _ in rows)
    for key, value in rows:
        print(f"{key:<{width}}  {value}")
    print()
    print("server RSS growth per request: median "
          f"{mib(float(np.median([r.rss_growth_kib for r in results]))) if results else '-'}, "
          f"requests over 64 MiB: {sum(r.rss_growth_kib > 64 * 1024 for r in results)}")
    print("most common 4xx reasons:")
    for text, n in Counter(f"{r.status} {reason(r.detail)}" for r in refused).most_common(12):
        print(f"  {n:5d}  {text}")
    print("slowest answers:")
    for r in slow:
        print(f"  {r.seconds:7.1f} s  {r.status}  {r.label[:100]}")
    print("named inputs:")
    for r in (r for r in results if r.group == "named"):
        shown = r.status if r.error is None else f"connection error ({r.error[:80]})"
        print(f"  {str(shown):>11}  {r.seconds:6.1f} s  server +{mib(r.rss_growth_kib):>10}  "
              f"reader {mib(r.reader_peak_kib):>10}  {r.label}")
        if r.detail:
            print(f"{'':14}{r.detail[:160]}")
    for note in tally.origin_notes:
        print(f"  {note}")
    improper = server_errors + bad4 + conn + ws_bad
    if improper:
        print(f"IMPROPER ANSWERS ({len(improper)}):")
        for r in improper:
            print(f"  [{r.group}] {r.label[:160]}\n      -> {r.fault or r.error}"
                  + (f"\n      repro: {r.repro}" if r.repro else ""))
    for crash in tally.crashes:
        print(f"SERVER CRASH {crash}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--per-format", type=int, default=300, metavar="N",
                        help="mutants per upload format (default 300)")
    parser.add_argument("--seed", type=int, default=0, help="the mutators' seed (default 0)")
    parser.add_argument("--skip-fuzz", action="store_true", help="only the named and origin inputs")
    parser.add_argument("--skip-named", action="store_true", help="no named inputs")
    args = parser.parse_args()
    t0 = time.perf_counter()
    tally = Tally()
    target = Target(tally)
    try:
        cross_origin(target)
        if not args.skip_fuzz:
            fuzz(target, args.per_format, args.seed)
        if not args.skip_named:
            named_inputs(target)
        target.check("the end")
    finally:
        target.stop()
    report(tally, time.perf_counter() - t0, args)


if __name__ == "__main__":
    main()
