"""Ring-marker tracking (Dutreve 2008, §5) on rendered videos: accuracy and speed.

    python bench/markers.py [--frames 300] [--repeats 3] [--keep DIR]
                            [--webcam 4] [--webcam-frames 150] [--only-webcam]

Renders the built-in face with the 21 Dutreve markers playing the 10 s demo loop (talking,
surprise, smiles, frowns, cheek puff, blinks, a wink) under seeded head motion, at
640x480 and 30 fps, once as MJPG (.avi) and once as MPEG-4 Part 2 (.mp4), then prints:

- 2D error of the tracked points against the rendered truth (pixels; markers the truth
  calls visible: wholly drawn and facing the camera within 73 degrees): median, 95th
  percentile, max; the share of visible markers reported lost, and of the others
  (partly hidden or edge-on) the share still tracked and their median error;
- tracking speed on one core (``cv2.setNumThreads(1)``), median over repeats of wall and
  process-CPU time: the
  `MarkerTracker` alone on decoded grey frames (decode excluded), and
  `track_marker_video` end to end (decode, grey conversion, detection and assignment in
  the first frame, tracking, the Take; decode included); plus one full-frame detection
  (what each frame with a lost marker adds, to find it again). The load average is
  printed with them: other processes on the machine slow every figure.

With ``--webcam N`` (default 4; 0 skips) it then tracks issue 17's hard material, N seeds
of `render_webcam_marker_video` (24 markers about 5 px across, a 640x480 webcam at 60 cm,
head turns up to about 18 degrees, light gradient, motion blur, noise, JPEG q30 then
MPEG-4, a finger over one marker for the first 8 frames; ``--webcam-frames`` long), and,
when ../shared/data/ict_face is there, the same on the ICT face (its generic neutral with
its own ARKit shapes for the demo's 12), all without a layout (`RingTracks`), and prints
per clip: markers found of those in clear view (visible and facing the camera within 60
degrees in 5 frames or more), tracks, identity switches (a track's nearest true marker
changing), median and 95th-percentile error (px) and the share within 3 px over the
clear-view marker-frames (a missed one counts as outside), and of the marker-frames
seen more obliquely (73-60 degrees), the share tracked within 3 px.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.timing import median_ms  # noqa: E402
from retarget.sources.markers import (  # noqa: E402
    MarkerTracker,
    assign_markers,
    reference_points,
    ring_blobs,
    track_marker_video,
)
from retarget.sample_face import EXPRESSION_NAMES, SampleFace  # noqa: E402
from retarget.testing.marker_video import (  # noqa: E402
    GroundTruth,
    render_marker_video,
    render_webcam_marker_video,
    unnamed_track_scores,
)

VIDEOS = (("mjpg.avi", 1), ("mp4v.mp4", 2))   # file name, seed
ICT = Path(__file__).resolve().parents[2] / "shared" / "data" / "ict_face" / "ict_face.npz"


def ict_face() -> SampleFace | None:
    """The ICT face model's generic neutral as a `SampleFace` (ICT-FaceKit, MIT licence,
    USC Institute for Creative Technologies), its shapes for the demo's 12 (`_L` + `_R`
    summed where ICT splits one), or None without ../shared/data/ict_face."""
    if not ICT.exists():
        return None
    with np.load(ICT) as d:
        names = [str(n) for n in d["expression_names"]]
        deltas = d["expressions"].astype(np.float64)
        shapes = []
        for name in EXPRESSION_NAMES:
            parts = [name] if name in names else [name + "_L", name + "_R"]
            shapes.append(sum(deltas[names.index(p)] for p in parts))
        v = d["neutral"].astype(np.float64)
        return SampleFace(v, d["faces"].astype(np.int64), np.zeros((len(v), 2)),
                          d["landmarks_68"].astype(np.int64), EXPRESSION_NAMES, np.stack(shapes))


def webcam_section(folder: Path, seeds: int, n_frames: int) -> None:
    faces = [("sample", None)]
    ict = ict_face()
    if ict is not None:
        faces.append(("ict", ict))
    else:
        print("  (no ../shared/data/ict_face: the ICT clips are skipped)")
    for label, face in faces:
        for seed in range(seeds):
            path = folder / f"webcam_{label}_{seed}.mp4"
            t = time.perf_counter()
            truth = GroundTruth.load(path.with_suffix(".npz")) if path.with_suffix(".npz").exists() else None
            if truth is None or len(truth.points2d) != n_frames or truth.facing is None or not path.exists():
                truth = render_webcam_marker_video(path, n_frames=n_frames, seed=seed, face=face)
            rendered_s = time.perf_counter() - t
            t = time.perf_counter()
            take = track_marker_video(path, layout=None)
            tracked_s = time.perf_counter() - t
            p = take.points.astype(np.float64)
            p[..., 1] = take.meta["size"][1] - p[..., 1]
            s = unnamed_track_scores(p, truth)
            print(f"  {label:<6} seed {seed}: found {len(s['found'] & s['wanted'])}/{len(s['wanted'])} in clear view, "
                  f"{s['tracks']} tracks, {s['switches']} identity switches; median {s['median']:.3f} px, "
                  f"p95 {s['p95']:.2f} px, {100 * s['within3']:.1f} % within 3 px; oblique "
                  f"{100 * s['oblique']:.0f} % within 3 px  (rendered or read in {rendered_s:.0f} s, "
                  f"tracked at {n_frames / tracked_s:.0f} fps)")


def rendered(folder: Path, n_frames: int) -> list[tuple[Path, GroundTruth]]:
    """The bench videos in `folder`, rendered unless already there with as many frames."""
    out = []
    for name, seed in VIDEOS:
        path = folder / name
        truth_path = path.with_suffix(".npz")
        if truth_path.exists() and path.exists():
            truth = GroundTruth.load(truth_path)
            if len(truth.points2d) == n_frames:
                out.append((path, truth))
                continue
        t = time.perf_counter()
        truth = render_marker_video(path, n_frames=n_frames, seed=seed)
        print(f"  rendered {name}: {n_frames} frames in {time.perf_counter() - t:.0f} s")
        out.append((path, truth))
    return out


def grey_frames(path: Path) -> list[np.ndarray]:
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY))
    cap.release()
    return frames


def errors(path: Path, truth: GroundTruth) -> dict:
    take = track_marker_video(path, layout=truth.layout)
    p = take.points.astype(np.float64)
    p[..., 1] = take.meta["size"][1] - p[..., 1]
    err = np.linalg.norm(p - truth.points2d[:, 0], axis=2)
    vis = truth.visible[:, 0]
    seen = err[vis]
    return {
        "n": int(vis.sum()), "median": float(np.nanmedian(seen)),
        "p95": float(np.nanpercentile(seen, 95)), "max": float(np.nanmax(seen)),
        "lost": float(np.isnan(seen).mean()),
        "others": int((~vis).sum()),
        "others_tracked": float(np.isfinite(err[~vis]).mean()) if (~vis).any() else 0.0,
        "others_median": float(np.nanmedian(err[~vis])) if np.isfinite(err[~vis]).any() else float("nan"),
    }


def wall_and_cpu_ms(fn, repeats: int) -> np.ndarray:
    """(2,) median wall and process-CPU milliseconds of fn() over repeats, after a warm-up.
    On a busy machine the CPU time is the one-core cost; the wall time adds the waits."""
    fn()
    times = []
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        fn()
        times.append((time.perf_counter() - wall, time.process_time() - cpu))
    return 1e3 * np.median(np.array(times), axis=0)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--frames", type=int, default=300, help="frames per video (300 = the whole 10 s loop)")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--keep", type=Path, help="folder to render into and reuse (default: a temporary one)")
    p.add_argument("--webcam", type=int, default=4, help="seeds of the hard webcam material (0: none)")
    p.add_argument("--webcam-frames", type=int, default=150, help="frames per webcam clip")
    p.add_argument("--only-webcam", action="store_true", help="skip the first two sections")
    args = p.parse_args(argv)
    cv2.setNumThreads(1)
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        if args.only_webcam:
            print(f"Webcam material (issue 17), {args.webcam_frames} frames per clip, no layout:")
            webcam_section(folder, args.webcam, args.webcam_frames)
            return 0
        print(f"Marker videos: 640x480, 30 fps, 21 ring markers (dutreve21), {args.frames} frames each")
        videos = rendered(folder, args.frames)

        print("2D error vs rendered truth (visible markers, px):")
        for path, truth in videos:
            e = errors(path, truth)
            print(f"  {path.name:<9} median {e['median']:.3f}  p95 {e['p95']:.3f}  max {e['max']:.3f}  "
                  f"(n {e['n']}; visible lost {100 * e['lost']:.2f} %; "
                  f"{e['others']} partly hidden or edge-on: {100 * e['others_tracked']:.0f} % still tracked, "
                  f"median error {e['others_median']:.2f})")

        load = os.getloadavg()[0]
        print(f"Tracking speed, one core, 640x480 (median of {args.repeats}; load average {load:.1f} "
              f"on {os.cpu_count()} cores):")
        for path, truth in videos:
            frames = grey_frames(path)
            blobs = ring_blobs(frames[0])
            start = blobs.centres[assign_markers(blobs.centres, reference_points(truth.layout))]
            tracker = MarkerTracker()

            def track_only():
                tracker.start(frames[0], start, blobs)
                for g in frames[1:]:
                    tracker.update(g)

            tracked = wall_and_cpu_ms(track_only, args.repeats) / (len(frames) - 1)
            full = wall_and_cpu_ms(lambda: track_marker_video(path, layout=truth.layout), args.repeats) / len(frames)
            detect_ms = median_ms(lambda: ring_blobs(frames[len(frames) // 2]), 10 * args.repeats)
            print(f"  {path.name:<9} decode excluded {1e3 / tracked[0]:4.0f} fps wall, {1e3 / tracked[1]:4.0f} fps CPU "
                  f"({tracked[1]:.2f} ms/frame CPU)   decode included {1e3 / full[0]:4.0f} fps wall, "
                  f"{1e3 / full[1]:4.0f} fps CPU ({full[1]:.2f} ms/frame CPU)   "
                  f"full-frame detection {detect_ms:.2f} ms")
        if args.webcam:
            print(f"Webcam material (issue 17), {args.webcam_frames} frames per clip, no layout:")
            webcam_section(folder, args.webcam, args.webcam_frames)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
