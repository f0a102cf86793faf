"""Native face-mesh tracking (`retarget.facemesh`, LiteRT) on a real video, against the
browser's tracker.

    python bench/facemesh.py [--video V] [--frames N] [--repeats 3] [--agree 150] [--before]

Prints, for --video (default ../shared/data/video/face_expressions_480.mp4, 480 x 480
H.264, 30 fps, 1008 frames; the first --frames, default all):

    decode      OpenCV alone (`VideoReader`): frames per second
    tracking    `FaceMeshTracker.track` alone: ms a frame (median frame of the median run)
                and frames per second, and the share of frames with a face
    whole       start-up (models loaded, interpreters built) plus decoding plus tracking
                of every frame: frames per second, start-up included, as a command sees it
    before      (--before) `FaceMeshTracker.track` against the tracker as it was before
                its crop was rewritten (`TrackerBefore`, kept here only for the ratio),
                frame by frame in alternating order so both see the same load: median ms
                a frame of each, the median of the per-frame ratios, and the largest
                difference between their points, px
    stress      (--stress) hard frames made from the video's (blank, rolled 42 degrees,
                jumps, upside down, a small face, dark) through both trackers: how often
                they agree that there is a face, per kind of frame
    agreement   the first --agree frames tracked by the browser's tracker as well
                (`track_video_markerless`, headless Chromium, the mediapipe68 points):
                median, p95 and mean offset of the native points from the page's, px

Medians over --repeats; tracking and whole on one inference thread (LiteRT's XNNPACK; a
server job or a batch worker) and on the cores, at most 4 (`retarget track`'s default). The
machine's load is printed first: the figures move with it.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

from bench.stream import machine  # noqa: E402
from retarget.layouts import get_layout  # noqa: E402
from retarget.sources.video import VideoReader  # noqa: E402

VIDEO = ROOT.parent / "shared" / "data" / "video" / "face_expressions_480.mp4"


def decode(video: Path, frames: int | None) -> list[np.ndarray]:
    """The first `frames` frames of `video`, RGB."""
    out = []
    with VideoReader(video) as reader:
        for _, frame in reader:
            out.append(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))
            if frames and len(out) == frames:
                break
    return out


def whole_run(video: Path, frames: int | None, threads: int = 1) -> tuple[float, int, list[float], int]:
    """(seconds of start-up + decode + track, frames, per-frame tracking seconds, frames with
    a face), the models on `threads` inference threads."""
    start = time.perf_counter()
    from retarget.facemesh.tracker import FaceMeshTracker

    tracker = FaceMeshTracker(threads=threads)
    per_frame, found, count = [], 0, 0
    with VideoReader(video) as reader:
        for _, frame in reader:
            rgb = cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
            t = time.perf_counter()
            points = tracker.track(rgb)
            per_frame.append(time.perf_counter() - t)
            found += points is not None
            count += 1
            if frames and count == frames:
                break
    return time.perf_counter() - start, count, per_frame, found


def tracker_before():
    """A `FaceMeshTracker` whose crop is made as before its rewrite: the 3-channel frame
    warped whole, scaled into a new array and copied into the model by set_tensor."""
    from retarget.facemesh.tracker import INPUT, N_POINTS, FaceMeshTracker

    class TrackerBefore(FaceMeshTracker):
        def landmarks(self, rgb, roi):
            axes = roi.axes()
            linear = axes / INPUT
            offset = roi.centre + axes @ np.full(2, 0.5 / INPUT - 0.5) - 0.5
            crop = cv2.warpAffine(rgb, np.column_stack([linear, offset]), (INPUT, INPUT),
                                  flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
            self._interpreter.set_tensor(self._input, crop[None].astype(np.float32) / 255.0)
            self._interpreter.invoke()
            raw = self._interpreter.get_tensor(self._points).reshape(N_POINTS, 3).astype(np.float64)
            logit = float(self._interpreter.get_tensor(self._presence).ravel()[0])
            presence = 1.0 / (1.0 + np.exp(-np.clip(logit, -100.0, 100.0)))
            xy = roi.centre + (raw[:, :2] / INPUT - 0.5) @ axes.T
            return np.column_stack([xy, raw[:, 2] / INPUT * roi.side]), presence

    return TrackerBefore()


def against_before(rgb: list[np.ndarray]) -> tuple[float, float, float, float]:
    """(ms a frame now, ms before, median per-frame ratio, largest point difference px)
    of `FaceMeshTracker` and `tracker_before` on the frames, alternately first."""
    from retarget.facemesh.tracker import FaceMeshTracker

    trackers = [FaceMeshTracker(), tracker_before()]
    seconds, difference = [[], []], 0.0
    for i, frame in enumerate(rgb):
        points = [None, None]
        for k in (0, 1) if i % 2 else (1, 0):
            t = time.perf_counter()
            points[k] = trackers[k].track(frame)
            seconds[k].append(time.perf_counter() - t)
        if (points[0] is None) != (points[1] is None):
            difference = float("inf")
        elif points[0] is not None:
            difference = max(difference, float(np.abs(points[0] - points[1]).max()))
    now, before = np.array(seconds)
    return 1000 * np.median(now), 1000 * np.median(before), float(np.median(now / before)), difference


def stress_frames(rgb: list[np.ndarray], rng: np.random.Generator) -> tuple[list[np.ndarray], list[str]]:
    """Hard frames made from the video's: runs of blank frames, a 42-degree roll, jumps
    between distant frames, upside-down frames, a small face in a large frame and a
    darkened one, each run named."""
    h, w = rgb[0].shape[:2]
    out, kinds = [], []

    def add(kind, frames):
        out.extend(frames)
        kinds.extend([kind] * len(frames))

    add("plain", rgb[:30])
    add("blank", [np.zeros_like(rgb[0])] * 8 + [np.full_like(rgb[0], 128)] * 7)
    add("plain", rgb[30:45])
    turn = cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), 42.0, 1.0)
    add("roll 42", [cv2.warpAffine(f, turn, (w, h), borderMode=cv2.BORDER_REPLICATE) for f in rgb[45:85]])
    add("jumps", [rgb[i] for i in rng.integers(0, len(rgb), 30)])
    add("upside down", [f[::-1, ::-1].copy() for f in rgb[85:115]])
    small = cv2.getRotationMatrix2D((0.0, 0.0), 0.0, 0.35)
    add("small face", [cv2.warpAffine(f, small, (w, h), borderMode=cv2.BORDER_CONSTANT) for f in rgb[115:145]])
    add("dark", [(f * 0.25).astype(np.uint8) for f in rgb[145:175]])
    return out, kinds


def stress(rgb: list[np.ndarray], folder: Path) -> None:
    """Face / no-face answers of the native and the browser's tracker on `stress_frames`."""
    from retarget.facemesh.tracker import FaceMeshTracker
    from retarget.sources.markerless import track_video_markerless
    from server import WEB_DIR

    frames, kinds = stress_frames(rgb, np.random.default_rng(3))
    path = folder / "stress.webm"
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"VP80"), 30.0, (w, h))
    for f in frames:
        writer.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    writer.release()
    # both trackers see the same decoded frames: the video's, not the ones before encoding
    decoded = decode(path, None)
    page = np.asarray(track_video_markerless(path, layout=get_layout("mediapipe68"), web_root=WEB_DIR).points)
    page_face = np.isfinite(page[:, :, 0]).all(axis=1)
    tracker = FaceMeshTracker()
    ours = np.array([tracker.track(f) is not None for f in decoded])
    n = min(len(ours), len(page_face), len(kinds))
    print(f"stress      {n} frames: same face / no-face answer in {int((ours[:n] == page_face[:n]).sum())}")
    for kind in dict.fromkeys(kinds):
        rows = [i for i in range(n) if kinds[i] == kind]
        print(f"            {kind:<12} face: native {int(ours[rows].sum()):>3}, browser "
              f"{int(page_face[rows].sum()):>3} of {len(rows)}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--video", type=Path, default=VIDEO)
    parser.add_argument("--frames", type=int, default=None)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--agree", type=int, default=150, help="frames compared with the browser (0: none)")
    parser.add_argument("--before", action="store_true",
                        help="also tracking against the tracker before its crop rewrite (`against_before`)")
    parser.add_argument("--stress", action="store_true",
                        help="also the face / no-face answers of both trackers on hard frames (`stress_frames`)")
    args = parser.parse_args()
    if not args.video.is_file():
        raise SystemExit(f"no video at {args.video} (the shared data set lies beside the checkout)")
    print(machine())

    t = time.perf_counter()
    rgb = decode(args.video, args.frames)
    print(f"decode      {len(rgb) / (time.perf_counter() - t):8.0f} frames/s  ({len(rgb)} frames)")

    # one thread (a server job, a batch worker) and the cores (`retarget track`'s default),
    # alternated so both see the same load
    cores = min(os.cpu_count() or 1, 4)
    counts = (1, cores) if cores > 1 else (1,)
    runs = {n: [] for n in counts}
    for _ in tqdm(range(args.repeats), desc="whole runs"):
        for n in counts:
            runs[n].append(whole_run(args.video, args.frames, n))
    for n in counts:
        runs[n].sort(key=lambda run: run[0])
        seconds, count, per_frame, found = runs[n][len(runs[n]) // 2]
        ms = 1000 * statistics.median(per_frame)
        print(f"tracking    {ms:8.2f} ms a frame, {1000 / ms:.0f} frames/s on {n} thread{'s' * (n > 1)}; "
              f"face in {found}/{count} frames")
        print(f"whole       {count / seconds:8.0f} frames/s on {n} thread{'s' * (n > 1)}, start-up, decoding "
              f"and tracking included ({seconds:.2f} s for {count} frames)")

    if args.before:
        for _ in range(args.repeats):
            now, before, ratio, difference = against_before(rgb)
            print(f"before      {now:8.2f} ms a frame now, {before:.2f} ms before ({ratio:.2f}x per frame); "
                  f"points differ by {difference:.1e} px at most")

    if args.agree:
        from retarget.facemesh.tracker import FaceMeshTracker
        from retarget.sources.markerless import track_video_markerless
        from server import WEB_DIR

        layout = get_layout("mediapipe68")
        n = min(args.agree, len(rgb))
        page = np.asarray(track_video_markerless(args.video, layout=layout, web_root=WEB_DIR,
                                                 max_frames=n).points)[:, :, :2]
        tracker = FaceMeshTracker()
        ours = np.full_like(page, np.nan)
        for i in range(n):
            points = tracker.track(rgb[i])
            if points is not None:
                ours[i] = points[list(layout.mediapipe468), :2]
        difference = (ours - page).reshape(-1, 2)
        both = np.isfinite(difference).all(axis=1)
        distance = np.linalg.norm(difference[both], axis=1)
        print(f"agreement   median {np.median(distance):.2f} px, p95 {np.percentile(distance, 95):.2f} px, "
              f"mean offset ({difference[both, 0].mean():+.2f}, {difference[both, 1].mean():+.2f}) px "
              f"over {n} frames; face found by both in {int(both.reshape(n, -1).all(axis=1).sum())}, "
              f"by one only in {int((np.isfinite(ours[:, 0, 0]) != np.isfinite(page[:, 0, 0])).sum())}")
    if args.stress:
        with tempfile.TemporaryDirectory() as folder:
            stress(rgb, Path(folder))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
