"""End-to-end latency of the webcam source: a camera frame in the page to the target face
drawn with that frame's motion, in the real app, with Chromium's fake camera.

    python bench/webcam_latency.py [--frames 300] [--size 480] [--demo-seconds 10] [--timeout 300]
                                   [--reply-delay-ms 0]

Runs `retarget serve` (subprocess, temp data dir, free port; bench/stream.py's
`ServerProcess`) and Debian's Chromium, headless, through Playwright. Chromium's camera is
a Y4M file of the first 5 s of ../shared/data/video/face_expressions_480.mp4 (--size
pixels square, 30 fps, looped). The app is opened on the built-in sample project (68
landmarks, 8,430 vertices), the webcam source is chosen and played, and for --frames
tracked frames the page records, on its own clock:

    camera      the frame's capture time (requestVideoFrameCallback's captureTime) to the
                callback that hands it to the tracker
    tracking    that callback to the points message leaving (MediaPipe face mesh on the
                frame, the layout's points picked and encoded; tracking/webcam.js)
    round trip  points sent to the retargeted frame applied to the face (the frame carries
                the points' frame index back), split at the server's publish time into
                up (socket, conditioning, retargeting, encoding) and down (mailbox,
                socket, decoding, the skinning texture update)
    render      applied to the next animation frame, when the face is drawn with it
    total       callback to that animation frame (camera to screen: add `camera`)

--reply-delay-ms emulates a remote server (or one slowed by a loaded machine): the page
handles each retargeted frame that much later (a timer around the stream's message
handler; counted in `down`), so it comes back while the next frame may already be tracked.

It also prints the tracker's frame rate and the share of frames with a face, and, as the
baseline without a camera, the demo source in the same browser and server
(bench/latency.py's run: publish to applied and to the next animation frame).

Everything runs on the CPU: no GPU, WebGL2 (the app's face and MediaPipe's graph alike)
through SwiftShader, a software rasteriser that shares the page's cores with the tracker's
wasm. Figures move with other load on the machine (printed first); nothing asserts them.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.latency import CHROMIUM, SWIFTSHADER, one_run  # noqa: E402
from bench.stream import ServerProcess, machine, sample_project  # noqa: E402
from tests.e2e.fake_camera import video_frames, write_y4m  # noqa: E402

VIDEO = ROOT.parent / "shared" / "data" / "video" / "face_expressions_480.mp4"
CAMERA_FPS = 30
CLIP_FRAMES = 5 * CAMERA_FPS
FAKE_CAMERA = ["--use-fake-device-for-media-stream", "--use-fake-ui-for-media-stream"]

# Installed before Play. The webcam loop asks for the next camera frame only after the
# last one's points went out, so the callback seen last when a points message leaves is
# that message's frame.
_RECORDER = """(replyDelayMs) => {
    const bench = window.bench = { callback: null, sent: new Map(), back: [], faces: 0, tracked: 0 };
    const video = document.getElementById('webcam-video');
    const request = video.requestVideoFrameCallback.bind(video);
    video.requestVideoFrameCallback = (callback) => request((now, metadata) => {
        bench.callback = { at: performance.now(), capture: metadata.captureTime ?? NaN };
        callback(now, metadata);
    });
    const stream = window.app.stream;
    if (replyDelayMs > 0) {
        // a server or network that slow: each frame reaches the page's event loop later
        const onMessage = stream._onMessage.bind(stream);
        stream._onMessage = (event) => event.data instanceof ArrayBuffer
            ? setTimeout(() => onMessage(event), replyDelayMs) : onMessage(event);
    }
    const sendPoints = stream.sendPoints.bind(stream);
    stream.sendPoints = (buffer) => {
        const index = new DataView(buffer).getUint32(8, true);
        const found = !Number.isNaN(new Float32Array(buffer, 32, 1)[0]);
        bench.tracked++;
        if (found) bench.faces++;
        bench.sent.set(index, { ...bench.callback, sent: performance.now() });
        return sendPoints(buffer);
    };
    // registered after the app's own handler: it runs once the frame is applied
    stream.addEventListener('frame', (event) => {
        const frame = event.detail;
        const entry = bench.sent.get(frame.frameIndex);
        if (entry === undefined || frame.flags & 1) return;
        const applied = performance.now();
        const published = frame.sendTime * 1000 - performance.timeOrigin;  // the server's clock, same machine
        requestAnimationFrame(() => bench.back.push({ ...entry, published, applied, drawn: performance.now() }));
    });
}"""


def spread(values) -> str:
    """'median X ms, p95 Y ms, max Z ms (n=N)' of a sequence of milliseconds: the tail
    (frames drawn late) is what a performer notices, and on a loaded machine it is a few
    frames in a hundred, around the p95."""
    a = np.asarray(values, dtype=np.float64)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return "n/a (n=0)"
    return (f"median {np.median(a):7.1f} ms, p95 {np.percentile(a, 95):7.1f} ms, "
            f"max {a.max():7.1f} ms  (n={a.size})")


def webcam_run(browser, url: str, project_id: str, frames: int, timeout_s: float,
               reply_delay_ms: float = 0.0) -> dict:
    """Timings (ms, page clock) of the first `frames` frames that came back, the tracked
    frame count, frames with a face and the tracking seconds."""
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    try:
        page.goto(f"{url}/#p={project_id}")
        page.wait_for_function("() => window.app && window.app.projectId")
        page.evaluate("() => window.app.ready")
        page.wait_for_function("() => window.app.face && window.app.face.nJoints > 0", timeout=60_000)
        page.wait_for_function("() => window.app.stream && window.app.stream.state === 'open'", timeout=30_000)
        page.evaluate(_RECORDER, reply_delay_ms)
        # the neutral from one frame: the looped performer never holds still through a
        # capture window, which the live source would refuse
        page.click("#conditioning summary")
        page.select_option("#neutral-mode", "frame")
        page.fill("#neutral-value", "0")
        page.dispatch_event("#neutral-value", "change")
        page.select_option("#source-select", "webcam")
        page.click("#play")
        page.wait_for_function("() => window.bench.back.length > 0", timeout=120_000)
        start = time.monotonic()
        page.evaluate("() => { window.bench.back.length = 0; window.bench.tracked = window.bench.faces = 0; }")
        last = 0
        while last < frames and time.monotonic() - start < timeout_s:
            time.sleep(2.0)
            last = page.evaluate("() => window.bench.back.length")
            print(f"  webcam: {last}/{frames} frames back", file=sys.stderr, flush=True)
        result = page.evaluate("() => ({ back: window.bench.back, tracked: window.bench.tracked,"
                               " faces: window.bench.faces })")
        result["seconds"] = time.monotonic() - start
        page.dispatch_event("#stop", "click")
    finally:
        page.close()
    return result


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--frames", type=int, default=300, help="tracked frames to measure")
    p.add_argument("--size", type=int, default=480, help="camera frame size, pixels square (even)")
    p.add_argument("--demo-seconds", type=float, default=10.0, help="seconds of the demo baseline")
    p.add_argument("--timeout", type=float, default=300.0, help="stop measuring after this many seconds")
    p.add_argument("--reply-delay-ms", type=float, default=0.0,
                   help="hand each retargeted frame to the page this much later (a remote server)")
    args = p.parse_args(argv)
    if not VIDEO.exists():
        p.error(f"{VIDEO} is missing: this benchmark needs ../shared beside the repository")

    from playwright.sync_api import sync_playwright

    print(machine())
    with tempfile.TemporaryDirectory(prefix="retarget-webcam-") as tmp:
        camera = write_y4m(Path(tmp) / "camera.y4m", video_frames(VIDEO, CLIP_FRAMES, args.size), CAMERA_FPS)
        with ServerProcess() as server, sync_playwright() as pw:
            project_id = sample_project(server.url)
            browser = pw.chromium.launch(executable_path=CHROMIUM, args=[
                *SWIFTSHADER, *FAKE_CAMERA, f"--use-file-for-fake-video-capture={camera}"])
            try:
                run = webcam_run(browser, server.url, project_id, args.frames, args.timeout, args.reply_delay_ms)
                print("  demo baseline", file=sys.stderr, flush=True)
                demo = one_run(browser, server.url, project_id, args.demo_seconds, CAMERA_FPS, draw=True)
            finally:
                browser.close()

    back = {k: np.array([b[k] for b in run["back"]], dtype=np.float64)
            for k in ("capture", "at", "sent", "published", "applied", "drawn")}
    print(f"\nwebcam source, fake camera {args.size}x{args.size} at {CAMERA_FPS} fps "
          f"(SwiftShader, headless, no GPU), the sample project (68 points, 8,430 vertices):")
    print(f"  tracker: {run['tracked'] / run['seconds']:.1f} frames/s over {run['seconds']:.0f} s, "
          f"a face in {100 * run['faces'] / max(run['tracked'], 1):.1f} % of {run['tracked']} frames")
    print(f"  camera      capture -> callback          {spread(back['at'] - back['capture'])}")
    print(f"  tracking    callback -> points sent      {spread(back['sent'] - back['at'])}")
    print(f"  round trip  points sent -> applied       {spread(back['applied'] - back['sent'])}")
    print(f"    up        points sent -> published     {spread(back['published'] - back['sent'])}")
    print(f"    down      published -> applied         {spread(back['applied'] - back['published'])}")
    print(f"  render      applied -> animation frame   {spread(back['drawn'] - back['applied'])}")
    print(f"  total       callback -> animation frame  {spread(back['drawn'] - back['at'])}")
    print(f"  camera to screen                         {spread(back['drawn'] - back['capture'])}")
    print(f"\ndemo source in the same browser, {args.demo_seconds:g} s at {CAMERA_FPS} fps (bench/latency.py):")
    print(f"  published -> applied                     {spread(demo['applied'])}")
    print(f"  published -> animation frame             {spread(demo['painted'])}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
