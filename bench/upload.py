"""Upload to a rigged, moving face: the REST API end to end on a real server.

    python bench/upload.py [--resolution 4] [--method biharmonic] [--k K] [--repeats 1] [--fps 60]

The built-in procedural face at --resolution (3: 74,732 vertices, 4: 132,907; the grid is
integer, so ~100k is not available and 4 is the smallest at or above it) is saved as OBJ
(not timed), then against `retarget serve` (subprocess, temp data dir, free port), each
stage timed by the client, wall clock:

    create     POST /api/projects
    mesh       PUT  /api/projects/{id}/mesh        (multipart, the OBJ's bytes)
    landmarks  PUT  /api/projects/{id}/landmarks   (the face's 68 vertex indices, ibug68)
    rig        POST /api/projects/{id}/rig {"method"}, then GET /api/jobs/{job} every 50 ms
               until done (the rig job's own progress feeds the progress bar)
    download   GET  mesh/arrays and rig/weights?version=2, accepting gzip (what the
               browser fetches to draw it; sizes as sent)
    stream     WS   /api/projects/{id}/stream: hello, {"type": "start", "source": "demo"},
               until the first binary frame arrives

Prints each stage's seconds and the total (median over --repeats, each repeat a new
project on the same server). Progress on stderr.
"""

from __future__ import annotations

import argparse
import asyncio
import gzip
import json
import sys
import tempfile
import time
import urllib.request
import uuid
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tqdm import tqdm  # noqa: E402

from bench.stream import ServerProcess, connect, http_json, machine  # noqa: E402

STAGES = ("create", "mesh", "landmarks", "rig", "download", "stream")


def multipart(field: str, filename: str, data: bytes) -> tuple[bytes, str]:
    boundary = uuid.uuid4().hex
    head = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"{field}\"; "
            f"filename=\"{filename}\"\r\nContent-Type: application/octet-stream\r\n\r\n").encode()
    return head + data + f"\r\n--{boundary}--\r\n".encode(), f"multipart/form-data; boundary={boundary}"


def get_bytes(url: str) -> tuple[bytes, int]:
    """The body of GET `url` as the page gets it, and its bytes on the wire: the page
    accepts gzip, as every browser does, and inflates what the server encoded."""
    request = urllib.request.Request(url, headers={"Accept-Encoding": "gzip"})
    with urllib.request.urlopen(request, timeout=300) as reply:
        data = reply.read()
        encoded = reply.headers.get("Content-Encoding") == "gzip"
    return (gzip.decompress(data) if encoded else data), len(data)


async def first_frame(ws_url: str, fps: float) -> None:
    async with connect(ws_url) as ws:
        hello = json.loads(await ws.recv())
        assert hello["type"] == "hello", hello
        await ws.send(json.dumps({"type": "start", "source": "demo", "fps": fps}))
        while True:
            msg = await ws.recv()
            if isinstance(msg, bytes):
                return
            reply = json.loads(msg)
            if reply["type"] == "error":
                raise RuntimeError(f"stream refused: {reply}")


def one_run(server: ServerProcess, obj: bytes, landmarks: list[int], method: str, k, fps: float,
            run: int) -> dict:
    t = {}
    clock = time.perf_counter
    t0 = clock()
    project = http_json(server.url + "/api/projects", "POST", {"name": f"bench upload {run}"})
    pid = project["id"]
    base = f"{server.url}/api/projects/{pid}"
    t["create"] = clock() - t0

    t0 = clock()
    body, content_type = multipart("file", "face.obj", obj)
    project = http_json(base + "/mesh", "PUT", body, timeout=300, headers={"Content-Type": content_type})
    t["mesh"] = clock() - t0

    t0 = clock()
    http_json(base + "/landmarks", "PUT", {"vertex_indices": landmarks, "layout": "ibug68"}, timeout=300)
    t["landmarks"] = clock() - t0

    t0 = clock()
    job = http_json(base + "/rig", "POST", {"method": method, **({"k": k} if k else {})}, timeout=300)
    with tqdm(total=100, desc=f"rig {method} (run {run + 1})", unit="%", file=sys.stderr, leave=False) as bar:
        while job["state"] == "running":
            time.sleep(0.05)
            job = http_json(f"{server.url}/api/jobs/{job['id']}")
            bar.n = int(100 * job["progress"])
            bar.refresh()
    if job["state"] != "done":
        raise RuntimeError(f"rig job failed: {job}")
    t["rig"] = clock() - t0

    t0 = clock()
    _, arrays = get_bytes(base + "/mesh/arrays")
    _, weights = get_bytes(base + "/rig/weights?version=2")  # what the page reads
    t["download"] = clock() - t0

    t0 = clock()
    asyncio.run(first_frame(f"{server.ws_url}/api/projects/{pid}/stream", fps))
    t["stream"] = clock() - t0
    t["total"] = sum(t[s] for s in STAGES)
    t["bytes"] = (len(obj), arrays, weights)
    t["detail"] = job["detail"]
    return t


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--resolution", type=int, default=4, help="built-in face resolution (4: 132,907 vertices)")
    p.add_argument("--method", default=None, help="rig method (default: the server's default)")
    p.add_argument("--k", type=int, default=None, help="influences per vertex kept by the rig "
                   "(default: the method's own; the browser's shader takes 8)")
    p.add_argument("--repeats", type=int, default=1)
    p.add_argument("--fps", type=float, default=60.0)
    args = p.parse_args(argv)
    from retarget.mesh import mesh_from_arrays, save_mesh
    from retarget.sample_face import sample_face
    from retarget.weights import DEFAULT_METHOD

    method = args.method or DEFAULT_METHOD
    print(f"machine: {machine()}")
    t0 = time.perf_counter()
    face = sample_face(args.resolution)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "face.obj"
        save_mesh(mesh_from_arrays(face.vertices, face.faces, name="face"), path)
        obj = path.read_bytes()
    print(f"face: resolution {args.resolution}, {len(face.vertices)} vertices, {len(face.faces)} triangles, "
          f"OBJ {len(obj) / 2**20:.1f} MiB (made in {time.perf_counter() - t0:.1f} s, not timed below); "
          f"rig method {method}" + (f", k {args.k}" if args.k else ""))
    landmarks = np.asarray(face.landmarks68).tolist()
    runs = []
    with ServerProcess() as server:
        print(f"server up in {server.startup_s:.1f} s")
        for run in range(args.repeats):
            runs.append(one_run(server, obj, landmarks, method, args.k, args.fps, run))
            r = runs[-1]
            print(f"  run {run + 1}: " + ", ".join(f"{s} {r[s]:.2f} s" for s in STAGES)
                  + f"; total {r['total']:.2f} s", flush=True)
    print(f"upload -> first frame of the rigged, moving {len(face.vertices)}-vertex face "
          f"({'median of ' + str(len(runs)) if len(runs) > 1 else 'one run'}):")
    for s in (*STAGES, "total"):
        values = [r[s] for r in runs]
        extra = ""
        if s == "download":
            extra = (f"  (mesh arrays {runs[0]['bytes'][1] / 2**20:.1f} MiB + rig weights "
                     f"{runs[0]['bytes'][2] / 2**20:.1f} MiB)")
        if s == "rig":
            extra = f"  ({runs[0]['detail']})"
        print(f"  {s:<10} {np.median(values):8.2f} s" + (f"  [min {min(values):.2f}, max {max(values):.2f}]"
                                                          if len(runs) > 1 else "") + extra)
    print(f"machine at the end: {machine()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
