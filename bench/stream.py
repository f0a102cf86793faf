"""Server cost and loopback latency of the live stream, 68 feature points.

    python bench/stream.py [--frames 3000] [--seconds 10] [--fps 60] [--compression deflate|none]
                           [--skip-server]

(a) In process, no sockets: the demo source's work for one frame, each part timed
    separately over --frames frames (median and p99):
      displacements  `DemoPlayer.displacements` (the library's Retargeter, 68 points)
      encode         `server.wire.encode_frame`
      publish        `StreamHub.publish` to one viewer's Mailbox, and to 50
      total          the three together (publish to one viewer)
(a') The same frames driven by muscles (issue 15): `MuscleDrive.frame` (the muscle IK,
    warm-started, and the expression read out) and `server.wire.encode_contractions`
    timed per frame, and the bytes a frame takes both ways.
(b) A real server: `retarget serve` in a subprocess (a fresh temp data dir, so the
    built-in 68-point sample project is made on start) on a free port; one `websockets`
    client opens /api/projects/{id}/stream, sends {"type": "start", "source": "demo",
    "fps": 60} and reads frames for --seconds. Latency = receive time minus the frame's
    header timestamp (bytes 24..32, float64 epoch seconds, stamped by encode_frame just
    before hub.publish, so it covers mailbox wait, the server's send, the socket and the
    client's read). Also: frames received against frames expected, achieved fps and
    frame-index gaps (frames the one-slot mailbox dropped).

The client offers permessage-deflate like a browser does (uvicorn accepts it), unless
--compression none. Progress goes to stderr; figures to stdout; nothing asserts speed.

The server helpers here (`ServerProcess`, `sample_project`, `stats`) are shared by
bench/viewers.py and bench/upload.py.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import struct
import subprocess
import sys
import tempfile
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tqdm import tqdm  # noqa: E402

HEADER = struct.Struct("<4sHHIIdd")  # the stream frame header (server/wire.py)
STARTUP_S = 120.0


# -- shared helpers ----------------------------------------------------------------------

def stats(values) -> dict:
    """median, p99, max, mean and count of a sequence (NaN when empty)."""
    a = np.asarray(values, dtype=np.float64)
    if a.size == 0:
        return {"median": float("nan"), "p99": float("nan"), "max": float("nan"),
                "mean": float("nan"), "n": 0}
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99)),
            "max": float(a.max()), "mean": float(a.mean()), "n": int(a.size)}


def fmt(s: dict, unit: str = "ms", digits: int = 3) -> str:
    return (f"median {s['median']:.{digits}f} {unit}, p99 {s['p99']:.{digits}f} {unit}, "
            f"max {s['max']:.{digits}f} {unit}  (n={s['n']})")


def machine() -> str:
    """CPUs, load average and Linux CPU pressure (share of time some task waited for a CPU):
    other work on the machine shows up as stalls and tail latency in these figures."""
    text = f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}"
    try:
        some = open("/proc/pressure/cpu").readline().split()
        text += f", CPU pressure {some[1].split('=')[1]} % (10 s) / {some[2].split('=')[1]} % (60 s)"
    except (OSError, IndexError):
        pass
    return f"{text}, Python {sys.version.split()[0]}"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def serve_command(port: int, data_dir: Path) -> list[str]:
    """`retarget serve` of this checkout's environment (the console script when present)."""
    script = Path(sys.executable).with_name("retarget")
    head = [str(script)] if script.exists() else [sys.executable, "-m", "server.cli"]
    return head + ["serve", "--port", str(port), "--data-dir", str(data_dir)]


def http_json(url: str, method: str = "GET", body=None, timeout: float = 60.0, headers=None):
    data = None if body is None else (body if isinstance(body, bytes) else json.dumps(body).encode())
    req = urllib.request.Request(url, data=data, method=method, headers=headers or {})
    if body is not None and not isinstance(body, bytes):
        req.add_header("Content-Type", "application/json")
    with urllib.request.urlopen(req, timeout=timeout) as reply:
        raw = reply.read()
    return json.loads(raw) if raw else None


@dataclass
class ServerProcess:
    """A server subprocess on 127.0.0.1 with a temp data dir; `with` starts and stops it.

    command : argv builder (port, data_dir) -> list; `retarget serve` by default.
    """

    command: object = serve_command
    port: int = field(default_factory=free_port)
    process: subprocess.Popen | None = None
    startup_s: float = 0.0

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def ws_url(self) -> str:
        return f"ws://127.0.0.1:{self.port}"

    @property
    def pid(self) -> int:
        return self.process.pid

    def __enter__(self) -> "ServerProcess":
        self._tmp = tempfile.TemporaryDirectory(prefix="retarget-bench-")
        tmp = Path(self._tmp.name)
        self.log = tmp / "server.log"
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        t0 = time.perf_counter()
        with open(self.log, "wb") as out:
            self.process = subprocess.Popen(self.command(self.port, tmp / "data"), stdout=out,
                                            stderr=subprocess.STDOUT, cwd=ROOT, env=env)
        deadline = time.monotonic() + STARTUP_S
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"server exited with {self.process.returncode}:\n{self.log.read_text()}")
            try:
                http_json(self.url + "/api/projects", timeout=1)
                self.startup_s = time.perf_counter() - t0
                return self
            except OSError:
                time.sleep(0.1)
        self.__exit__(None, None, None)
        raise RuntimeError(f"server did not answer within {STARTUP_S} s")

    def __exit__(self, *exc) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self._tmp.cleanup()


def sample_project(url: str) -> str:
    """Id of the server's built-in 68-landmark sample project."""
    for p in http_json(url + "/api/projects"):
        if (p.get("landmarks") or {}).get("n_points") == 68 and p.get("rig"):
            return p["id"]
    raise RuntimeError("the server has no rigged 68-landmark project")


def rss_mb(pid: int) -> float:
    """Resident set size of a process in MiB (/proc/<pid>/status VmRSS)."""
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of a process (/proc/<pid>/stat)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def connect(url: str, compression: str | None = "deflate"):
    from websockets.asyncio.client import connect as ws_connect
    return ws_connect(url, compression=compression, proxy=None, max_size=2**22)


# -- (a) in process ----------------------------------------------------------------------

def in_process(frames: int, fps: float) -> None:
    from retarget.sample_face import sample_face
    from server.hub import StreamHub
    from server.players import DemoPlayer
    from server.wire import encode_frame

    face = sample_face(1)  # the sample project's face and landmarks
    setup = []
    for _ in range(3):
        t0 = time.perf_counter()
        source = DemoPlayer(face.vertices[face.landmarks68], "ibug68", fps)
        setup.append(time.perf_counter() - t0)
    hub1, hub50 = StreamHub(), StreamHub()
    box = hub1.subscribe("p")
    boxes = [hub50.subscribe("p") for _ in range(50)]
    clock = time.perf_counter_ns
    parts = {k: np.empty(frames) for k in ("displacements", "encode", "publish", "publish50", "total")}
    for i in range(-50, frames):  # 50 warm-up frames
        t0 = clock()
        d = source.displacements(i % 100000)
        t1 = clock()
        frame = encode_frame(d, frame_index=i % 100000, source_time=i / fps)
        t2 = clock()
        hub1.publish("p", frame)
        t3 = clock()
        hub50.publish("p", frame)
        t4 = clock()
        if i >= 0:
            parts["displacements"][i] = (t1 - t0) / 1e6
            parts["encode"][i] = (t2 - t1) / 1e6
            parts["publish"][i] = (t3 - t2) / 1e6
            parts["publish50"][i] = (t4 - t3) / 1e6
            parts["total"][i] = (t3 - t0) / 1e6
    print(f"(a) in process, one frame of 68 points, {frames} frames ({len(frame)} bytes each):")
    labels = {"displacements": "displacements (Retargeter)", "encode": "encode_frame",
              "publish": "hub.publish, 1 mailbox", "publish50": "hub.publish, 50 mailboxes",
              "total": "total (1 mailbox)"}
    for key, label in labels.items():
        print(f"  {label:<28} {fmt(stats(parts[key]))}")
    assert box.backlog <= 1 and all(b.backlog <= 1 for b in boxes)
    print(f"  DemoPlayer set-up (on every 'start': performer face, {len(source.frames)} frames, fit): "
          f"median {1e3 * np.median(setup):.0f} ms of 3")
    budget = 1e3 / fps
    print(f"  => {100 * np.median(parts['total']) / budget:.2f} % of the {budget:.1f} ms frame "
          f"budget at {fps:g} fps (median); mailbox backlog after {frames} unread frames: "
          f"{max(b.backlog for b in [box, *boxes])} (dropped {box.dropped})")


def muscle_mode(frames: int, fps: float) -> None:
    from retarget.landmarks import landmarks_from_json
    from retarget.muscles import place_muscles
    from retarget.muscles.drive import MuscleDrive
    from retarget.sample_face import sample_face
    from server.players import DemoPlayer
    from server.wire import encode_contractions, encode_frame

    face = sample_face(1)
    points = landmarks_from_json({"vertex_indices": np.asarray(face.landmarks68).tolist()}, face.vertices,
                                 face.faces)
    t0 = time.perf_counter()
    model = place_muscles(face.vertices, face.faces, points, "ibug68")
    placed = time.perf_counter() - t0
    source = DemoPlayer(face.vertices[face.landmarks68], "ibug68", fps)
    drive = MuscleDrive(model, points)
    clock = time.perf_counter_ns
    parts = {k: np.empty(frames) for k in ("ik", "encode")}
    lost = np.zeros(68, bool)
    for i in range(-50, frames):  # 50 warm-up frames
        d = source.displacements(i % 100000)
        t0 = clock()
        seen = drive.frame(d, lost)
        t1 = clock()
        frame = encode_contractions(seen, frame_index=i % 100000, source_time=i / fps)
        t2 = clock()
        if i >= 0:
            parts["ik"][i] = (t1 - t0) / 1e6
            parts["encode"][i] = (t2 - t1) / 1e6
    points_bytes = len(encode_frame(d, frame_index=0, source_time=0.0))
    print(f"(a') muscle mode, {frames} frames: bytes a frame, feature points {points_bytes}, "
          f"muscles {len(frame)} ({len(seen.contractions)} contractions, {len(seen.distances)} "
          f"expression distances, confidence, label); +16 either way with a head rotation")
    print(f"  {'MuscleDrive.frame (IK, read)':<28} {fmt(stats(parts['ik']))}")
    print(f"  {'encode_contractions':<28} {fmt(stats(parts['encode']))}")
    print(f"  muscles placed on the sample face (once per project): {1e3 * placed:.0f} ms")


# -- (b) a real server -------------------------------------------------------------------

async def _receive(ws_url: str, project: str, seconds: float, fps: float, compression):
    async with connect(f"{ws_url}/api/projects/{project}/stream", compression) as ws:
        hello = json.loads(await ws.recv())
        assert hello["type"] == "hello", hello
        t_start = time.time()
        await ws.send(json.dumps({"type": "start", "source": "demo", "fps": fps}))
        recv_t, send_t, index = [], [], []
        bar = tqdm(total=round(seconds), desc="stream", unit="s", file=sys.stderr, leave=False)
        while True:
            msg = await ws.recv()
            now = time.time()
            if isinstance(msg, str):
                continue  # the "started" reply
            _, _, _, i, _, _, sent = HEADER.unpack_from(msg)
            recv_t.append(now)
            send_t.append(sent)
            index.append(i)
            if int(now - recv_t[0]) > bar.n and bar.n < bar.total:
                bar.update(1)
            if now - recv_t[0] >= seconds:
                break
        bar.close()
        extensions = [type(e).__name__ for e in ws.protocol.extensions]
    return np.array(recv_t), np.array(send_t), np.array(index), t_start, extensions


def real_server(seconds: float, fps: float, compression) -> None:
    print("(b) real server (`retarget serve`, loopback):", flush=True)
    with ServerProcess() as server:
        project = sample_project(server.url)
        print(f"  server up in {server.startup_s:.1f} s (includes making the sample project's rig); "
              f"sample project {project}")
        cpu0, wall0 = cpu_seconds(server.pid), time.perf_counter()
        recv_t, send_t, index, t_start, ext = asyncio.run(
            _receive(server.ws_url, project, seconds, fps, compression))
        server_cpu = (cpu_seconds(server.pid) - cpu0) / (time.perf_counter() - wall0)
    latency = 1e3 * (recv_t - send_t)
    elapsed = recv_t[-1] - recv_t[0]
    span = int(index[-1] - index[0]) + 1
    gaps = int(np.sum(np.diff(index) > 1))
    print(f"  websocket extensions: {', '.join(ext) or 'none'}")
    print(f"  'start' sent -> first frame received: {1e3 * (recv_t[0] - t_start):.1f} ms "
          "(DemoPlayer set-up included)")
    print(f"  send -> receive latency: {fmt(stats(latency))}")
    print(f"  frames received {len(index)} in {elapsed:.2f} s; expected {elapsed * fps + 1:.0f} "
          f"at {fps:g} fps; achieved {(len(index) - 1) / elapsed:.2f} fps")
    print(f"  frame indices {index[0]}..{index[-1]}: {span - len(index)} missing ({gaps} gaps, "
          f"i.e. frames the mailbox dropped), {int(np.sum(np.diff(index) <= 0))} out of order")
    intervals = 1e3 * np.diff(recv_t)
    print(f"  inter-arrival: {fmt(stats(intervals))}")
    print(f"  server process CPU while streaming to 1 viewer: {100 * server_cpu:.1f} % of one core")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--frames", type=int, default=3000, help="frames for the in-process part (a)")
    p.add_argument("--seconds", type=float, default=10.0, help="streaming time for part (b)")
    p.add_argument("--fps", type=float, default=60.0)
    p.add_argument("--compression", choices=("deflate", "none"), default="deflate",
                   help="permessage-deflate offered by the client (browsers offer it)")
    p.add_argument("--skip-server", action="store_true", help="only part (a)")
    args = p.parse_args(argv)
    print(f"machine: {machine()}")
    in_process(args.frames, args.fps)
    muscle_mode(args.frames, args.fps)
    if not args.skip_server:
        real_server(args.seconds, args.fps, None if args.compression == "none" else "deflate")
    print(f"machine at the end: {machine()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
