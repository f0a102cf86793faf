"""A video through the server's tracking job, as the web app's *Track video...* sends it:
from the POST to the job done, on a real `retarget serve`.

    python bench/track_job.py [--video V] [--method markerless] [--layout ibug68] [--repeats 3]

Against `retarget serve` (subprocess, temp data dir, free port; its sample project), each
repeat timed by the client, wall clock:

    answer   POST /api/projects/{id}/takes/track (multipart: the video, method, layout)
             until its 202: the upload stored, the video opened and checked in a child
             process (`server.isolation`)
    job      then GET /api/jobs/{job} every 20 ms until done: a child decodes and tracks
             every frame, the take is stored
    total    POST to done

Prints the frames, the frames with a face (markerless), each repeat's seconds and the
total's frames per second (median over --repeats). --video defaults to
../shared/data/video/face_expressions_480.mp4 (480 x 480 H.264, 30 fps, 1,008 frames).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.stream import ServerProcess, http_json, machine, sample_project  # noqa: E402

VIDEO = ROOT.parent / "shared" / "data" / "video" / "face_expressions_480.mp4"
POLL_S = 0.02


def multipart(fields: dict[str, str], filename: str, data: bytes) -> tuple[bytes, str]:
    """(body, content type) of a form with `fields` and one file part named "file"."""
    boundary = uuid.uuid4().hex
    body = b"".join(f"--{boundary}\r\nContent-Disposition: form-data; name=\"{k}\"\r\n\r\n{v}\r\n".encode()
                    for k, v in fields.items())
    body += (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"{filename}\"\r\n"
             "Content-Type: application/octet-stream\r\n\r\n").encode()
    return body + data + f"\r\n--{boundary}--\r\n".encode(), f"multipart/form-data; boundary={boundary}"


def one_run(url: str, pid: str, video: Path, data: bytes, fields: dict) -> dict:
    body, content_type = multipart(fields, video.name, data)
    start = time.perf_counter()
    job = http_json(f"{url}/api/projects/{pid}/takes/track", "POST", body, timeout=300,
                    headers={"Content-Type": content_type})
    answered = time.perf_counter()
    while job["state"] == "running":
        time.sleep(POLL_S)
        job = http_json(f"{url}/api/jobs/{job['id']}")
    done = time.perf_counter()
    if job["state"] != "done":
        raise RuntimeError(f"the tracking job failed: {job['detail']}")
    return {"answer": answered - start, "job": done - answered, "total": done - start, **job["result"]}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--video", type=Path, default=VIDEO)
    parser.add_argument("--method", default="markerless", choices=["markerless", "markers"])
    parser.add_argument("--layout", default=None, help="default: the server's (markerless: the "
                        "sample project's ibug68)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    data = args.video.read_bytes()
    fields = {"method": args.method, **({"layout": args.layout} if args.layout else {})}

    print(f"machine: {machine()}")
    with ServerProcess() as server:
        print(f"server: answered {server.startup_s:.2f} s after its start")
        pid = sample_project(server.url)
        runs = []
        for i in range(args.repeats):
            runs.append(one_run(server.url, pid, args.video, data, fields))
            run = runs[-1]
            print(f"run {i + 1}: answer {run['answer']:.3f} s, job {run['job']:.2f} s, "
                  f"total {run['total']:.2f} s", file=sys.stderr)
    run = runs[0]
    face = f", a face in {run['frames_with_face']}" if "frames_with_face" in run else ""
    total = statistics.median(r["total"] for r in runs)
    each = ", ".join(f"{r['total']:.2f}" for r in runs)
    print(f"video: {args.video.name}, {len(data) / 2**20:.1f} MiB, {run['frames']} frames{face} "
          f"({args.method})")
    print(f"answer  {statistics.median(r['answer'] for r in runs):7.3f} s  (POST to 202)")
    print(f"job     {statistics.median(r['job'] for r in runs):7.2f} s  (202 to done)")
    print(f"total   {total:7.2f} s  POST to done, {run['frames'] / total:.0f} frames/s "
          f"(median of {len(runs)}: {each})")


if __name__ == "__main__":
    main()
