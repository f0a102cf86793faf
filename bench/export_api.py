"""Exporting and importing a project through the server: time and file size.

    python bench/export_api.py [--seconds 30] [--fps 30] [--repeats 5] [--rigs biharmonic ellipsoid]

The built-in sample project (8430 vertices, 68 iBUG landmarks) in a fresh data dir, with a
take of --seconds at --fps uploaded to it (a second identity performing the demo). For
each rig (biharmonic, the sample's: morph targets; ellipsoid: a glTF skin):

    export   GET /api/projects/{id}/export.glb?takes=all through the app (FastAPI's
             TestClient, no network): conditioning, retargeting and writing the .glb
    none     the same without takes (mesh and rig only)
    import   POST /api/projects/import of the export
    MiB      the .glb with the take, and without

Times are wall-clock medians over --repeats. Figures on stdout.
"""

from __future__ import annotations

import argparse
import io
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fastapi.testclient import TestClient  # noqa: E402

from bench.stream import machine  # noqa: E402
from retarget.sample_face import demo_weights, sample_face  # noqa: E402
from server.app import create_app  # noqa: E402


def median_seconds(fn, repeats: int):
    """(median wall seconds, the last result) of fn() over `repeats` calls."""
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def ok(response):
    assert response.status_code < 300, response.text
    return response


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--rigs", nargs="+", default=["biharmonic", "ellipsoid"])
    args = parser.parse_args()

    performer = sample_face(identity=np.array([0.8, 0.5, -0.6, 1.0, 0.3]))
    lm = np.asarray(performer.landmarks68)
    n_frames = int(round(args.seconds * args.fps))
    frames = performer.vertices[lm] + np.tensordot(demo_weights(n_frames, args.fps),
                                                   performer.expressions[:, lm], axes=1)
    npy = io.BytesIO()
    np.save(npy, frames.astype(np.float32))
    print(f"# {machine()}")
    print(f"sample project: 8430 vertices, 68 joints; take: {n_frames} frames at {args.fps:g} fps "
          f"({args.seconds:g} s); median of {args.repeats}")
    print(f"{'rig':<11} {'kind':<6} {'export s':>8} {'none s':>7} {'import s':>8} {'MiB':>6} {'none MiB':>8}")
    with tempfile.TemporaryDirectory() as data, TestClient(create_app(Path(data))) as client:
        pid = client.get("/api/projects").json()[0]["id"]
        ok(client.post(f"/api/projects/{pid}/takes", files={"file": ("take.npy", npy.getvalue())},
                       data={"layout": "ibug68", "fps": str(args.fps)}))
        url = f"/api/projects/{pid}/export.glb"
        for method in args.rigs:
            if client.get(f"/api/projects/{pid}/rig").json()["method"] != method:
                job = ok(client.post(f"/api/projects/{pid}/rig", json={"method": method})).json()
                while (job := client.get(f"/api/jobs/{job['id']}").json())["state"] == "running":
                    time.sleep(0.1)
            with_take, full = median_seconds(lambda: ok(client.get(url, params={"takes": "all"})).content,
                                             args.repeats)
            without, bare = median_seconds(lambda: ok(client.get(url)).content, args.repeats)
            imported, _ = median_seconds(lambda: ok(client.post(
                "/api/projects/import", files={"file": ("face.glb", full)})), args.repeats)
            kind = "skin" if method in ("ellipsoid", "geodesic") else "morph"
            print(f"{method:<11} {kind:<6} {with_take:>8.3f} {without:>7.3f} {imported:>8.3f} "
                  f"{len(full) / 2**20:>6.1f} {len(bare) / 2**20:>8.1f}", flush=True)


if __name__ == "__main__":
    main()
