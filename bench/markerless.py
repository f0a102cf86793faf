"""Markerless tracking speed: the browser's face-mesh tracker on a real video, headless.

    python bench/markerless.py [--video V] [--layout mediapipe68] [--frames N] [--repeats 1]

Prints, for --video (default ../shared/data/video/face_expressions_480.mp4, 480 x 480
H.264, 30 fps, 1008 frames; the --frames first frames, default all):

    decode      OpenCV alone: frames per second of `VideoReader` (what the command line's
                decoding costs)
    command     `track_video_markerless` (the browser's tracker driven headless, the
                reference for the native face mesh of `retarget track --method markerless`
                and the server's video tracking: bench/facemesh.py, bench/track_job.py):
                tracked frames per second including decoding, the JPEG hand-over and the
                tracking, browser start and model load excluded (printed apart as
                startup), and the share of frames with a face. Median over --repeats.

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

from bench.stream import machine  # noqa: E402
from retarget.sources.markerless import track_video_markerless  # noqa: E402
from retarget.sources.video import VideoReader  # noqa: E402
from server.web import WEB_DIR  # noqa: E402

VIDEO = ROOT.parent / "shared" / "data" / "video" / "face_expressions_480.mp4"


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


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--video", type=Path, default=VIDEO)
    parser.add_argument("--layout", default="mediapipe68")
    parser.add_argument("--frames", type=int, default=None, help="first N frames (default all)")
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args(argv)

    print(f"machine: {machine()}")
    with VideoReader(args.video) as reader:
        print(f"video: {args.video.name}, {reader.size[0]}x{reader.size[1]}, {reader.fps:g} fps, "
              f"{reader.n_frames} frames (header)")
    print(f"decode    {decode_fps(args.video, args.frames):8.1f} frames/s (OpenCV, VideoReader)")

    runs = [command_run(args.video, args.layout, args.frames) for _ in range(args.repeats)]
    median = statistics.median(run["fps_tracked"] for run in runs)
    run = runs[0]
    each = ", ".join(f"{r['fps_tracked']:.2f}" for r in runs)
    print(f"command   {median:8.2f} frames/s tracked incl. decoding (median of {len(runs)}: {each}), "
          f"{run['frames']} frames, face in {run['frames_with_face']} ({100 * run['face_share']:.1f} %), "
          f"startup {statistics.median(r['startup_s'] for r in runs):.1f} s (browser + model)")


if __name__ == "__main__":
    main()
