"""``retarget track``, ``condition`` and ``calibrate``: performances read into source
points, from videos (the trackers of `retarget.sources`) or from performance files
(`retarget.sources.files`, conditioned by `retarget.sources.conditioning`).

The trackers are imported when a command runs, so the other commands start without OpenCV's
video stack.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from retarget.cli.parser import layout_name, positive_float, positive_int
from retarget.errors import RetargetError
from retarget.files import progress_bar, require_file, require_parent, write_file, write_npy
from retarget.layouts import LAYOUTS

__all__ = ["add_calibrate", "add_condition", "add_track"]


# ---------------------------------------------------------------------------------------
# track


def add_track(commands, parents) -> None:
    p = commands.add_parser(
        "track", parents=parents, help="track a performance video into source points",
        description="Track a video into (F, N, 3) float32 source points in a layout's order "
        "(NaN rows where a point or the face is lost; z = 0 for one-camera markers) and print "
        "the frames per second. One-camera markers without --layout: every marker in view, "
        "in a stable order (m01..mM, in the --take file's names).")
    p.add_argument("video", metavar="VIDEO", help="the video (the left one for stereo)")
    p.add_argument("--method", choices=["markerless", "markers", "stereo"], required=True,
                   help="markerless: MediaPipe's face mesh (run natively, no browser); markers: white dots with a black ring, one camera; stereo: "
                   "coloured markers seen by a calibrated pair")
    p.add_argument("--layout", choices=list(LAYOUTS), metavar="NAME",
                   help="points to produce (default: ibug68 for markerless, dutreve21 for stereo; for "
                   "markers, dutreve21 when the first frame shows its 21 markers, else every marker "
                   "in view, named m01..mM by when it is first seen, then top to bottom)")
    p.add_argument("--right", metavar="VIDEO", help="stereo: the right camera's video")
    p.add_argument("--calibration", metavar="CALIB.npz", help="stereo: from 'retarget calibrate'")
    p.add_argument("--color", default="blue", metavar="COLOUR",
                   help="stereo without --layout: dutreve21 when the first frames show its coloured "
                   "markers, else every sticker of this one colour in view, named m01..mM: a name "
                   "(blue, green, cyan, magenta, yellow), B,G,R picked from the video, or hsv:H,S,V "
                   "(default blue)")
    p.add_argument("--anchors", metavar="m01,m03,...",
                   help="stereo without --layout: the stickers that fix the head (3 or more; "
                   "default the 4 most mutually rigid)")
    p.add_argument("--max-frames", type=positive_int, metavar="F",
                   help="markerless: track only the first F frames")
    p.add_argument("--threads", type=positive_int, default=min(os.cpu_count() or 1, 4), metavar="T",
                   help="markerless: the face-mesh models' inference threads (default: the cores, at most 4)")
    p.add_argument("--out", required=True, metavar="FRAMES.npy", help="(F, N, 3) float32 points")
    p.add_argument("--take", metavar="TAKE.npz",
                   help="also write the take (points, times, names) for upload to the web app")
    p.set_defaults(run=_track)


def _track(args) -> int:
    out = Path(args.out)
    require_parent(out)
    require_file(args.video, "video")
    take_out = Path(args.take) if args.take else None
    if take_out is not None:
        require_parent(take_out)
    # Stereo without --layout: dutreve21's coloured set if the first frames show it, else
    # every sticker of one colour in view, m01..mM.
    layout = args.layout or {"markerless": "ibug68", "markers": "auto", "stereo": None}[args.method]
    if args.method == "stereo":
        if not (args.right and args.calibration):
            raise RetargetError("--method stereo needs --right RIGHT_VIDEO and --calibration CALIB.npz")
        require_file(args.right, "right video")
        require_file(args.calibration, "stereo calibration")
        if layout is not None and (args.anchors or args.color != "blue"):
            raise RetargetError("--color and --anchors are for stereo stickers without --layout")
    elif args.right or args.calibration or args.anchors or args.color != "blue":
        raise RetargetError(f"--right, --calibration, --color and --anchors are for --method "
                            f"stereo, not {args.method}")
    start = time.perf_counter()
    with progress_bar(100, f"tracking ({args.method})", "%", args.quiet) as advance:
        def progress(done: int, total: int) -> None:  # the trackers count frames
            if total:
                advance(done / total)

        if args.method == "markers":
            from retarget.sources.markers import track_marker_video
            take = track_marker_video(args.video, layout=layout, progress=progress)
        elif args.method == "markerless":
            from retarget.sources.facemesh_video import track_video_facemesh
            take = track_video_facemesh(args.video, layout=layout, progress=progress,
                                        max_frames=args.max_frames, threads=args.threads)
        else:
            from retarget.sources.calibration import StereoCalibration
            from retarget.sources.stereo import stereo_layout, track_stereo_videos
            calibration = StereoCalibration.load(args.calibration)
            if layout is None and args.color == "blue" and not args.anchors:
                # The coloured dutreve21 set when the first frames show it (as before).
                layout = stereo_layout(args.video, args.right, calibration)
            sticker = {} if layout is not None else {
                "color": _color_option(args.color),
                "anchors": args.anchors.split(",") if args.anchors else None}
            take = track_stereo_videos(args.video, args.right, calibration,
                                       layout=layout, progress=progress, **sticker)
    seconds = time.perf_counter() - start
    points = take.points
    if take.dims == 2:  # image points: z = 0 (Dutreve §4)
        points = np.concatenate([points, np.zeros_like(points[..., :1])], axis=-1)
    write_npy(out, np.ascontiguousarray(points, dtype=np.float32))
    if take_out is not None:
        write_file(take_out, take.save)
    found = np.isfinite(take.points).all(axis=2)
    print(f"tracked {take.n_frames} frames of {take.n_points} points ({take.layout or 'own labels'}) "
          f"in {seconds:.2f} s: {take.n_frames / max(seconds, 1e-9):.1f} fps; "
          f"all points found in {100 * found.all(axis=1).mean():.1f} % of frames, "
          f"none in {100 * (~found.any(axis=1)).mean():.1f} % -> {out}")
    return 0


def _color_option(text: str):
    """--color: a name or hsv:H,S,V as given, B,G,R as three numbers."""
    parts = text.split(",")
    if len(parts) == 3 and not text.startswith("hsv:"):
        try:
            return tuple(float(v) for v in parts)
        except ValueError:
            raise RetargetError(f"--color {text!r}: B,G,R must be three numbers 0-255") from None
    return text


# ---------------------------------------------------------------------------------------
# condition


def add_condition(commands, parents) -> None:
    p = commands.add_parser(
        "condition", parents=parents, help="read a take file and condition it into source points",
        description="Read a performance file (landmark CSV/JSON/NPY, TRC or C3D motion capture, an "
        "animated glTF/GLB face or a zip of OBJ frames with --labelled-vertices, or a take .npz "
        "from 'track --take') in a layout's point order, condition it as the web app plays a "
        "take (neutral capture, head-motion removal, jitter filter, gain per region) and write "
        "the neutral and the frames for 'transfer' and 'export-gltf'.")
    p.add_argument("take", metavar="TAKE", help="the performance file")
    p.add_argument("--layout", type=layout_name, required=True, metavar="NAME|L.json",
                   help="the layout whose points to produce, in its order (every point needed): "
                   f"a built-in one ({', '.join(LAYOUTS)}) or a custom layout file")
    p.add_argument("--mapping", metavar="MAP.json", help='{"file label": "layout point name"} for '
                   "labels that are not point names (motion-capture marker names)")
    p.add_argument("--labelled-vertices", metavar="LV.json", help="animated meshes: "
                   '{"point name": vertex index}, or a landmarks JSON of the animated mesh')
    p.add_argument("--fps", type=float, metavar="F", help="frame rate (default: the file's)")
    p.add_argument("--settings", metavar="SETTINGS.json", help="conditioning settings, as the web "
                   'app\'s (e.g. {"neutral": {"mode": "frame", "frame": 0}, "head_pose": "remove", '
                   '"filter": "one_euro"}); default: the first 0.5 s, head motion removed, no filter')
    p.add_argument("--neutral-out", required=True, metavar="S0.npy", help="(N, D) float32 neutral")
    p.add_argument("--out", required=True, metavar="FRAMES.npy",
                   help="(F, N, D) float32 conditioned frames, every frame of the take")
    p.set_defaults(run=_condition)


def _condition(args) -> int:
    from retarget.sources.conditioning import ConditionSettings, condition_take
    from retarget.sources.files import read_take

    out, neutral_out = Path(args.out), Path(args.neutral_out)
    for path in (out, neutral_out):
        require_parent(path)
    require_file(args.take, "take file")
    options = {name: _read_json_file(getattr(args, name), name.replace("_", " "))
               for name in ("mapping", "labelled_vertices", "settings")}
    take = read_take(args.take, layout=args.layout, mapping=options["mapping"], fps=args.fps,
                     labelled_vertices=options["labelled_vertices"])
    settings = ConditionSettings.from_dict(options["settings"])
    conditioned, neutral = condition_take(take, settings)
    write_npy(out, np.ascontiguousarray(conditioned.points, dtype=np.float32))
    write_npy(neutral_out, np.ascontiguousarray(neutral, dtype=np.float32))
    print(f"{take.source or 'take'} {take.n_frames} frames of {take.n_points} {take.dims}D points "
          f"({take.layout}) at {take.fps:g} fps: neutral from {settings.neutral['mode']}, head "
          f"{settings.head_pose}, filter {settings.filter}; {conditioned.n_frames} frames "
          f"-> {out}, neutral -> {neutral_out}")
    return 0


def _read_json_file(path, what: str):
    """The JSON in the file `path` (None when not given)."""
    if path is None:
        return None
    require_file(path, what)
    try:
        return json.loads(Path(path).read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RetargetError(f"{what} {str(path)!r} is not readable JSON: {exc}") from None


# ---------------------------------------------------------------------------------------
# calibrate


def add_calibrate(commands, parents) -> None:
    p = commands.add_parser(
        "calibrate", parents=parents, help="calibrate a stereo camera pair",
        description="Calibrate a stereo pair from views of a calibration pattern (each side a "
        "folder of images or a video) for 'retarget track --method stereo'.")
    p.add_argument("left", metavar="LEFT", help="left camera: folder of images or a video")
    p.add_argument("right", metavar="RIGHT", help="right camera: the same views, same order")
    p.add_argument("--pattern", choices=["checkerboard", "circles"], default="checkerboard",
                   help="checkerboard (inner corners) or symmetric circle grid")
    p.add_argument("--cols", type=positive_int, required=True, help="pattern columns (inner corners or circles)")
    p.add_argument("--rows", type=positive_int, required=True, help="pattern rows")
    p.add_argument("--square", type=positive_float, required=True, metavar="SIZE",
                   help="square (or circle spacing) size; the units of the 3D points, e.g. mm")
    p.add_argument("--out", required=True, metavar="CALIB.npz", help="the calibration, written here")
    p.set_defaults(run=_calibrate)


def _calibrate(args) -> int:
    from retarget.sources.calibration import calibrate_stereo

    out = Path(args.out)
    require_parent(out)
    left, right = _views(args.left, "left"), _views(args.right, "right")
    pattern = (args.pattern, args.cols, args.rows, args.square)
    calibration = calibrate_stereo(left, right, pattern)
    write_file(out, calibration.save)
    skipped = calibration.meta.get("skipped") or []
    print(f"stereo calibration from {len(left) - len(skipped)} of {len(left)} view pairs: "
          f"reprojection RMS {calibration.rms:.3f} px, baseline {calibration.baseline:.1f} "
          f"(pattern units) -> {out}")
    return 0


_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def _views(path: str, side: str) -> list:
    """The calibration views of one camera: the images of a folder (sorted by name) or
    the frames of a video, BGR uint8."""
    import cv2

    from retarget.sources.video import VideoReader

    p = Path(path)
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if f.suffix.lower() in _IMAGE_SUFFIXES)
        if not files:
            raise RetargetError(f"{side} calibration folder {path!r} holds no images "
                                f"({', '.join(_IMAGE_SUFFIXES)})")
        images = []
        for f in files:
            image = cv2.imread(str(f))
            if image is None:
                raise RetargetError(f"{side} calibration view {str(f)!r} is not a readable image")
            images.append(image)
        return images
    require_file(path, f"{side} calibration views")
    with VideoReader(path) as reader:
        return [frame for _, frame in reader]
