"""Markerless tracking speed: the browser's face-mesh tracker on a real video, headless.

    python bench/markerless.py [--video V] [--layout mediapipe68] [--frames N] [--repeats 1]
                               [--web-frames 150]

Prints, for --video (default ../shared/data/video/face_expressions_480.mp4, 480 x 480
H.264, 30 fps, 1008 frames; the --frames first frames, default all):

    decode      OpenCV alone: frames per second of `VideoReader` (what the command line's
                decoding costs)
    command     `track_video_markerless` (the `retarget track --method markerless` path):
                tracked frames per second including decoding, the JPEG hand-over and the
                tracking, browser start and model load excluded (printed apart as
                startup), and the share of frames with a face. Median over --repeats.
    in-page     the web app's own path (`trackVideo` of web/static/js/tracking/videoTake.js,
                the <video> decoded and stepped by the page) on the first --web-frames
                frames, through a real `retarget serve`; and the page's two ways of reaching
                every frame without tracking: seeking to each frame vs pausing playback on
                each frame (ms per frame).

Headless Chromium runs MediaPipe's GPU graph on SwiftShader, a CPU rasteriser: the
figures are CPU figures and move with other load on the machine (printed first).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tqdm import tqdm  # noqa: E402

from bench.stream import ServerProcess, machine  # noqa: E402
from retarget.layouts import get_layout  # noqa: E402
from retarget.sources.markerless import track_video_markerless  # noqa: E402
from retarget.sources.video import VideoReader  # noqa: E402
from server.web import WEB_DIR  # noqa: E402

VIDEO = ROOT.parent / "shared" / "data" / "video" / "face_expressions_480.mp4"
CHROMIUM = "/usr/bin/chromium"
SWIFTSHADER = ["--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--ignore-gpu-blocklist"]

IN_PAGE = """async ([url, indices, frames, fps]) => {
    const { trackVideo } = window.retargetTracking;
    const take = await trackVideo(url, { layoutIndices: indices, maxFrames: frames, fps });
    const blob = await (await fetch(url)).blob();
    const video = document.createElement('video');
    video.muted = true;
    video.src = URL.createObjectURL(blob);
    await new Promise((resolve) => video.addEventListener('loadeddata', resolve, { once: true }));
    const seek = (t) => new Promise((resolve) => {
        video.addEventListener('seeked', resolve, { once: true });
        video.currentTime = t;
    });
    let start = performance.now();
    for (let i = 0; i < frames; i++) await seek((i + 0.5) / fps);
    const seekMs = (performance.now() - start) / frames;
    await seek(0);
    let shown = 0;
    start = performance.now();
    await new Promise((resolve) => {
        const onFrame = () => {
            video.pause();
            if (++shown >= frames || video.ended) return resolve();
            video.requestVideoFrameCallback(onFrame);
            video.play().catch(() => {});
        };
        video.requestVideoFrameCallback(onFrame);
        video.play().catch(() => {});
    });
    const stepMs = (performance.now() - start) / shown;
    return { n_frames: take.n_frames, faces: take.faces, seconds: take.seconds, sought: take.sought, seekMs, stepMs };
}"""


def decode_fps(video: Path, frames: int | None) -> float:
    start = time.perf_counter()
    count = 0
    with VideoReader(video) as reader:
        for count, _ in enumerate(reader, 1):
            if frames is not None and count >= frames:
                break
    return count / (time.perf_counter() - start)


def command_run(video: Path, layout: str, frames: int | None) -> dict:
    with tqdm(desc="command", unit="frame", file=sys.stderr, leave=False) as bar:
        def progress(done: int, total: int | None) -> None:
            bar.total = total
            bar.update(done - bar.n)

        take = track_video_markerless(video, layout=layout, web_root=WEB_DIR, max_frames=frames,
                                      progress=progress)
    return {"frames": take.n_frames, **take.meta}


def in_page_run(video: Path, layout: str, frames: int, fps: float) -> dict:
    from playwright.sync_api import sync_playwright

    body = video.read_bytes()
    with ServerProcess() as server, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=SWIFTSHADER)
        page = browser.new_page()
        page.route("**/bench-video", lambda route: route.fulfill(body=body, content_type="video/mp4"))
        page.goto(server.url + "/static/track.html")
        page.wait_for_function("() => window.retargetTracking")
        result = page.evaluate(IN_PAGE, [server.url + "/bench-video",
                                         list(get_layout(layout).mediapipe468), frames, fps])
        browser.close()
    return result


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--video", type=Path, default=VIDEO)
    parser.add_argument("--layout", default="mediapipe68")
    parser.add_argument("--frames", type=int, default=None, help="first N frames (default all)")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--web-frames", type=int, default=150, help="0 skips the in-page path")
    args = parser.parse_args(argv)

    print(f"machine: {machine()}")
    with VideoReader(args.video) as reader:
        print(f"video: {args.video.name}, {reader.size[0]}x{reader.size[1]}, {reader.fps:g} fps, "
              f"{reader.n_frames} frames (header)")
        fps = reader.fps
    print(f"decode    {decode_fps(args.video, args.frames):8.1f} frames/s (OpenCV, VideoReader)")

    runs = [command_run(args.video, args.layout, args.frames) for _ in range(args.repeats)]
    median = statistics.median(run["fps_tracked"] for run in runs)
    run = runs[0]
    each = ", ".join(f"{r['fps_tracked']:.2f}" for r in runs)
    print(f"command   {median:8.2f} frames/s tracked incl. decoding (median of {len(runs)}: {each}), "
          f"{run['frames']} frames, face in {run['frames_with_face']} ({100 * run['face_share']:.1f} %), "
          f"startup {statistics.median(r['startup_s'] for r in runs):.1f} s (browser + model)")

    if args.web_frames > 0:
        page = in_page_run(args.video, args.layout, args.web_frames, fps)
        print(f"in-page   {page['n_frames'] / page['seconds']:8.2f} frames/s tracked incl. decoding "
              f"(trackVideo, first {page['n_frames']} frames, face in {page['faces']}, "
              f"{page['sought']} sought)")
        print(f"          reaching each frame without tracking: seek {page['seekMs']:.1f} ms/frame, "
              f"paused playback {page['stepMs']:.1f} ms/frame")


if __name__ == "__main__":
    main()
