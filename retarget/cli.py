"""The ``retarget`` command line: retarget feature-point animation onto a mesh from files.

Subcommands (``retarget <command> --help`` for the details):

``transfer``
    Dutreve et al. 2008 §4 end to end: a target mesh and its landmarks T0, a source's
    neutral points S0 and frames S, skin weights computed (or read with ``--rig``), and
    the deformed target written as an (F, V, 3) float32 ``.npy``.
``rig``
    Only the skin weights (Dutreve §3), written as an ``.npz`` that ``transfer --rig``
    reuses, so a slow solve (biharmonic, Laplacian) runs once per mesh.
``demo``
    The built-in example: the sample face driven by another identity's landmarks, with
    the error against the known answer. Needs no files.
``layouts``
    The landmark layouts and the names ``--mask`` accepts.
``track``
    A performance video -> (F, N, 3) source points per frame: ring markers (Dutreve §5,
    one camera, z = 0), a colour-marker stereo pair (Woodward §5) or markerless face-mesh
    tracking (the web app's browser tracker, run in a headless Chromium).
``condition``
    A performance file (landmark table, TRC/C3D motion capture, animated glTF face, OBJ
    sequence, a tracked take) read in a layout's order and conditioned as the app plays a
    take (neutral, head pose, filter, gain) into S0 and S for ``transfer``/``export-gltf``.
``calibrate``
    A stereo camera pair's calibration from checkerboard or circle-grid views, for
    ``track --method stereo``.
``export-gltf``
    The target mesh rigged (feature points as joints of a glTF skin, or morph targets
    for rigs with negative weights) and, given a source, the retargeted take animated,
    as one glTF 2.0 binary (`retarget.gltf`).

The CLI only parses, calls the library and serialises. Every refusal (a `RetargetError`,
a missing or unreadable file, arrays that do not agree) is one line
``retarget: error: <message>`` on stderr and exit status 2; success is status 0.
Progress bars (tqdm) go to stderr, the results to stdout; ``--quiet`` hides the bars.
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from retarget import __version__
from retarget.errors import RetargetError
from retarget.clips import clip_at_rate
from retarget.gltf import write_gltf
from retarget.gltf.influences import is_joint_based
from retarget.landmarks import SurfacePoints, load_landmarks
from retarget.layouts import GROUPS, LAYOUTS, REGIONS, Layout, get_layout
from retarget.mesh import Mesh, load_mesh, mesh_from_arrays, save_mesh
from retarget.performance import Performance
from retarget.pipeline import DEFAULT_KERNEL, DEFAULT_SMOOTHING, transfer
from retarget.rbf import KERNELS
from retarget.skin import SkinWeights
from retarget.weights import DEFAULT_METHOD, METHODS, compute_weights

__all__ = ["main", "build_parser", "transfer_files", "TransferResult", "export_gltf_files",
           "ExportResult"]

PROG = "retarget"
DEMO_FRAMES = 90
DEMO_DIR = "retarget-demo"
SERVE_DATA_DIR = "retarget-data"


class _UsageError(Exception):
    """An argparse refusal, carried to `main` instead of argparse's own exit."""

    def __init__(self, message: str, usage: str):
        super().__init__(message)
        self.usage = usage


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's hook; the default prints and exits
        raise _UsageError(message, self.format_usage())


# ---------------------------------------------------------------------------------------
# transfer


@dataclass(frozen=True)
class TransferResult:
    """What `transfer_files` did.

    vertices : (F, V, 3) float32, the deformed target, mesh units (also written to `out`).
    rest : (V, 3) float64, the target mesh's neutral vertices as read.
    n_points : N, the number of feature points.
    method : the deformer (the rig's method when the weights were read from a file).
    weights_seconds, transfer_seconds : wall time of the weight solve (or rig read) and of
        the per-frame transfer.
    out : the path written.
    """

    vertices: np.ndarray
    rest: np.ndarray
    n_points: int
    method: str
    weights_seconds: float
    transfer_seconds: float
    out: Path

    def summary(self) -> str:
        """The one-line report `transfer` prints."""
        f, v, _ = self.vertices.shape
        total = self.weights_seconds + self.transfer_seconds
        rate = f / self.transfer_seconds if self.transfer_seconds > 0 else float("inf")
        return (
            f"transferred {f} frames onto {v} vertices from {self.n_points} points "
            f"with {self.method}: {total:.2f} s (weights {self.weights_seconds:.2f} s, "
            f"frames {self.transfer_seconds:.2f} s, {rate:.0f} frames/s) -> {self.out}"
        )


def transfer_files(
    target_mesh,
    target_landmarks,
    source_neutral,
    source_frames,
    out,
    *,
    deformer: str = DEFAULT_METHOD,
    kernel: str = DEFAULT_KERNEL,
    smoothing: float | None = None,
    mask: list[str] | None = None,
    layout: str | None = None,
    rig=None,
    quiet: bool = False,
) -> TransferResult:
    """Retarget source frames in files onto a target mesh in a file; write (F, V, 3).

    target_mesh : mesh file (see `retarget.mesh.load_mesh`).
    target_landmarks : landmarks JSON (see `retarget.landmarks`), N points.
    source_neutral : ``.npy`` (N, 2|3) float, the source's neutral points S0.
    source_frames : ``.npy`` (F, N, 2|3) float, the source's points per frame S, in the
        order and dimension of S0; NaN marks a lost point (it keeps its neutral place).
    out : ``.npy`` written with the (F, V, 3) float32 deformed target vertices, in the
        mesh's units and vertex order; the path is used exactly as given.
    deformer : a name of `retarget.weights.METHODS`; ignored when `rig` is given.
    kernel, smoothing : the RBF space transform's (`retarget.pipeline.Retargeter`).
    mask : names (regions, groups, points of the layout) and/or feature indices (as
        strings or ints) of the active points, their union; None for all.
    layout : layout name; default the landmarks JSON's ``"layout"``, if any.
    rig : ``.npz`` from `SkinWeights.save` to use instead of computing weights.

    Raises `RetargetError` for every refusal, naming the file or option.
    """
    out = Path(out)
    _require_parent(out)
    mesh = _read_mesh(target_mesh)
    points = _read_landmarks(target_landmarks, mesh)
    n = points.n_points
    s0 = _read_npy(source_neutral, "source neutral")
    frames = _read_npy(source_frames, "source frames")
    _check_source(s0, frames, n)
    the_layout = _layout_for(layout, points)
    active = _mask_for(mask, the_layout, n)

    start = time.perf_counter()
    if rig is not None:
        weights = _read_rig(rig, mesh, n)
        method = weights.method or "rig"
    else:
        weights = _weights(deformer, mesh, points, the_layout, quiet=quiet)
        method = deformer
    weights_seconds = time.perf_counter() - start

    start = time.perf_counter()
    performance = Performance(points.positions(mesh.vertices), the_layout, regions=active,
                              kernel=kernel, smoothing=smoothing)
    performance.set_neutral(s0)
    with _bar(len(frames), "transfer", "frame", quiet) as advance:
        result = transfer(mesh.vertices, weights, performance, frames, progress=advance)
    transfer_seconds = time.perf_counter() - start

    _write_npy(out, result)
    return TransferResult(
        result, mesh.vertices, n, method, weights_seconds, transfer_seconds, out
    )


def _check_source(s0: np.ndarray, frames: np.ndarray, n_target: int) -> None:
    """Shapes and values of S0 (N, D) and S (F, N, D) against the target's N points."""
    if s0.ndim != 2 or s0.shape[1] not in (2, 3):
        raise RetargetError(f"source neutral must have shape (N, 2) or (N, 3); got {s0.shape}")
    if frames.ndim != 3 or frames.shape[2] not in (2, 3):
        raise RetargetError(
            f"source frames must have shape (F, N, 2) or (F, N, 3); got {frames.shape}"
        )
    if len(frames) == 0:
        raise RetargetError(f"source frames hold no frames (shape {frames.shape})")
    if len(s0) != n_target:
        raise RetargetError(
            f"source neutral has {len(s0)} points but target landmarks have {n_target}"
        )
    if frames.shape[1] != len(s0):
        raise RetargetError(
            f"source frames have {frames.shape[1]} points but source neutral has {len(s0)}"
        )
    if frames.shape[2] != s0.shape[1]:
        raise RetargetError(
            f"source frames are {frames.shape[2]}D but source neutral is {s0.shape[1]}D; "
            "give both in the same dimension"
        )
    bad = ~np.isfinite(s0).all(axis=1)
    if bad.any():
        raise RetargetError(
            f"source neutral has {int(bad.sum())} point(s) with NaN or inf coordinates "
            f"(first: point {int(np.flatnonzero(bad)[0])}); the neutral must be complete"
        )
    if np.isinf(frames).any():
        f, i = np.argwhere(np.isinf(frames))[0][:2]
        raise RetargetError(
            f"source frames hold infinite coordinates (first: frame {f}, point {i}); "
            "mark a lost point with NaN instead"
        )


def _layout_for(name: str | None, points: SurfacePoints) -> Layout | None:
    """The layout named by --layout, else by the landmarks JSON, checked against N."""
    if name is None:
        name = points.layout or None
        where = "the landmarks JSON's 'layout'"
    else:
        where = "--layout"
    if name is None:
        return None
    layout = get_layout(name)
    if layout.n_points != points.n_points:
        raise RetargetError(
            f"layout {name!r} (from {where}) has {layout.n_points} points but target "
            f"landmarks have {points.n_points}"
        )
    return layout


def _mask_for(values, layout: Layout | None, n: int) -> np.ndarray | None:
    """(N,) bool union of --mask values (names of `layout`, or feature indices), or None."""
    if not values:
        return None
    mask = np.zeros(n, dtype=bool)
    for value in values:
        text = str(value).strip()
        try:
            index = int(text)
        except ValueError:
            if layout is None:
                raise RetargetError(
                    f"--mask {text!r} is a name, which needs a layout: give --layout or a "
                    "\"layout\" in the landmarks JSON, or use feature indices"
                ) from None
            mask |= layout.region_mask(text)
            continue
        if not 0 <= index < n:
            raise RetargetError(f"--mask index {index} is outside the {n} feature points [0, {n})")
        mask[index] = True
    return mask


def _weights(method: str, mesh: Mesh, points: SurfacePoints, layout: Layout | None, *,
             quiet: bool, **options) -> SkinWeights:
    """`compute_weights` with a progress bar where the method reports progress."""
    if method not in METHODS:
        raise RetargetError(f"unknown deformer {method!r}; choose one of {', '.join(METHODS)}")
    if "progress" not in inspect.signature(METHODS[method]).parameters:
        return compute_weights(method, mesh.vertices, mesh.faces, points, layout, **options)
    with _bar(100, f"{method} weights", "%", quiet) as advance:
        return compute_weights(
            method, mesh.vertices, mesh.faces, points, layout, progress=advance, **options
        )


class _bar:
    """A tqdm bar on stderr as a context manager yielding ``advance(fraction)``."""

    def __init__(self, total: int, desc: str, unit: str, quiet: bool):
        self._bar = tqdm(total=total, desc=desc, unit=unit, file=sys.stderr,
                         disable=quiet, leave=False, dynamic_ncols=True)

    def __enter__(self):
        def advance(fraction: float) -> None:
            done = round(min(max(float(fraction), 0.0), 1.0) * self._bar.total)
            self._bar.update(done - self._bar.n)

        return advance

    def __exit__(self, *exc):
        self._bar.close()
        return False


# ---------------------------------------------------------------------------------------
# export-gltf


@dataclass(frozen=True)
class ExportResult:
    """What `export_gltf_files` did.

    n_vertices, n_points : V and N of the exported face.
    n_frames : F frames of the animation (0 without a source).
    fps : the animation's frame rate.
    deformation : "skin" or "morph" (see `retarget.gltf.writer`).
    method : the rig's method.
    seconds : wall time, weights and retargeting included.
    n_bytes : size of the file written.
    out : the path written.
    """

    n_vertices: int
    n_points: int
    n_frames: int
    fps: float
    deformation: str
    method: str
    seconds: float
    n_bytes: int
    out: Path

    def summary(self) -> str:
        """The one-line report `export-gltf` prints."""
        animation = (f", {self.n_frames} frames at {self.fps:g} fps" if self.n_frames
                     else ", no animation")
        kind = "feature joints of a skin" if self.deformation == "skin" else \
            "feature joints, morph targets"
        return (f"exported {self.n_vertices} vertices, {self.n_points} {kind} "
                f"({self.method}){animation}: {self.n_bytes / 2**20:.1f} MiB in "
                f"{self.seconds:.2f} s -> {self.out}")


def export_gltf_files(
    mesh_path,
    landmarks,
    out,
    *,
    rig=None,
    deformer: str = DEFAULT_METHOD,
    source_neutral=None,
    source_frames=None,
    fps: float = 30.0,
    kernel: str | None = None,
    smoothing: float | None = None,
    mask: list[str] | None = None,
    layout: str | None = None,
    quiet: bool = False,
) -> ExportResult:
    """Write a target mesh, rigged and optionally animated, as a glTF 2.0 binary (.glb).

    mesh_path, landmarks : the target mesh file and its landmarks JSON (N points); the
        joints are named after the layout's points (`retarget.gltf.joint_names`).
    out : the .glb written (`retarget.gltf.export_gltf`; mesh units kept).
    rig : ``.npz`` from `SkinWeights.save`; else weights of `deformer` are computed.
    source_neutral, source_frames : ``.npy`` S0 (N, 2|3) and S (F, N, 2|3), as for
        `transfer_files`; both or neither. Given, the take is retargeted (Dutreve §4)
        and exported as one animation named after the frames file, frame f at f / fps.
    kernel, smoothing, mask : the retargeting's (`transfer_files`); they need a source.
    layout : layout name; default the landmarks JSON's ``"layout"``, if any.

    Raises `RetargetError` for every refusal, naming the file or option.
    """
    start = time.perf_counter()
    out = Path(out)
    _require_parent(out)
    if (source_neutral is None) != (source_frames is None):
        raise RetargetError("--source-neutral and --source-frames go together: give both "
                            "for an animation, or neither")
    if source_frames is None and (mask or kernel is not None or smoothing is not None):
        raise RetargetError("--mask, --kernel and --smoothing shape the animation: give "
                            "--source-neutral and --source-frames too")
    if not np.isfinite(fps) or fps <= 0:
        raise RetargetError(f"fps must be a positive number; got {fps!r}")
    mesh = _read_mesh(mesh_path)
    points = _read_landmarks(landmarks, mesh)
    the_layout = _layout_for(layout, points)
    if the_layout is not None:
        points = replace(points, layout=the_layout.name)
    n = points.n_points
    clips = []
    if source_frames is not None:
        s0 = _read_npy(source_neutral, "source neutral")
        frames = _read_npy(source_frames, "source frames")
        _check_source(s0, frames, n)
        active = _mask_for(mask, the_layout, n)
    if rig is not None:
        weights = _read_rig(rig, mesh, n)
    else:
        weights = _weights(deformer, mesh, points, the_layout, quiet=quiet)
    if source_frames is not None:
        performance = Performance(points.positions(mesh.vertices), the_layout, regions=active,
                                  kernel=kernel or DEFAULT_KERNEL, smoothing=smoothing)
        performance.set_neutral(s0)
        d = np.empty((len(frames), n, 3), np.float32)
        chunk = 256
        with _bar(len(frames), "retarget", "frame", quiet) as advance:
            for i in range(0, len(frames), chunk):
                d[i:i + chunk] = performance.displacements(frames[i:i + chunk])
                advance((i + chunk) / len(frames))
        clips.append(clip_at_rate(Path(source_frames).stem, d, fps))
    written = []
    with _bar(100, "glTF", "%", quiet) as advance:
        _write_with(out, lambda f: written.append(
            write_gltf(f, mesh, points, weights, clips, progress=advance)))
    return ExportResult(mesh.n_vertices, n, clips[0].n_frames if clips else 0, fps,
                        "skin" if is_joint_based(weights) else "morph",
                        weights.method or ("rig" if rig is not None else deformer),
                        time.perf_counter() - start, written[0], out)


# ---------------------------------------------------------------------------------------
# file reading and writing: every failure becomes a RetargetError naming the file


def _read_mesh(path) -> Mesh:
    _require_file(path, "target mesh")
    return load_mesh(path)


def _read_landmarks(path, mesh: Mesh) -> SurfacePoints:
    _require_file(path, "target landmarks")
    return load_landmarks(path, mesh.vertices, mesh.faces)


def _read_npy(path, what: str) -> np.ndarray:
    """A numeric ``.npy`` as float64; `what` names it in messages."""
    _require_file(path, what)
    try:
        array = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise RetargetError(f"could not read {what} {str(path)!r} as .npy: {exc}") from exc
    if not isinstance(array, np.ndarray):  # an .npz archive
        array.close()
        raise RetargetError(f"{what} {str(path)!r} is an .npz archive; give one .npy array")
    if array.dtype.kind not in "iuf":
        raise RetargetError(
            f"{what} {str(path)!r} must hold numbers, got dtype {array.dtype}"
        )
    return array.astype(np.float64)


def _read_rig(path, mesh: Mesh, n_points: int) -> SkinWeights:
    _require_file(path, "rig")
    weights = SkinWeights.load(path)
    if weights.n_joints != n_points:
        raise RetargetError(
            f"rig {str(path)!r} has {weights.n_joints} joints but target landmarks have "
            f"{n_points} points"
        )
    if weights.n_vertices != mesh.n_vertices:
        raise RetargetError(
            f"rig {str(path)!r} has weights for {weights.n_vertices} vertices but the "
            f"target mesh has {mesh.n_vertices}"
        )
    return weights


def _require_file(path, what: str) -> None:
    p = Path(path)
    if not p.is_file():
        state = "is not a file" if p.exists() else "does not exist"
        raise RetargetError(f"{what} {str(p)!r} {state}")


def _require_parent(path: Path) -> None:
    """Refuse an output path whose directory is missing, before any work is done."""
    if not path.parent.is_dir():
        raise RetargetError(f"cannot write {str(path)!r}: directory {str(path.parent)!r} does not exist")


def _write_with(path: Path, save) -> None:
    """Write exactly `path` through ``save(binary file)`` (numpy's savers would append
    their suffix to another one)."""
    try:
        with open(path, "wb") as f:
            save(f)
    except OSError as exc:
        raise RetargetError(f"could not write {str(path)!r}: {exc}") from exc


def _write_npy(path: Path, array: np.ndarray) -> None:
    _write_with(path, lambda f: np.save(f, array))


def _write_json(path: Path, data: dict) -> None:
    try:
        path.write_text(json.dumps(data) + "\n")
    except OSError as exc:
        raise RetargetError(f"could not write {str(path)!r}: {exc}") from exc


# ---------------------------------------------------------------------------------------
# subcommands


def _cmd_transfer(args) -> int:
    result = transfer_files(
        args.target_mesh,
        args.target_landmarks,
        args.source_neutral,
        args.source_frames,
        args.out,
        deformer=args.deformer or DEFAULT_METHOD,
        kernel=args.kernel,
        smoothing=args.smoothing,
        mask=args.mask,
        layout=args.layout,
        rig=args.rig,
        quiet=args.quiet,
    )
    print(result.summary())
    return 0


def _cmd_export_gltf(args) -> int:
    result = export_gltf_files(
        args.mesh,
        args.landmarks,
        args.out,
        rig=args.rig,
        deformer=args.deformer or DEFAULT_METHOD,
        source_neutral=args.source_neutral,
        source_frames=args.source_frames,
        fps=args.fps,
        kernel=args.kernel,
        smoothing=args.smoothing,
        mask=args.mask,
        layout=args.layout,
        quiet=args.quiet,
    )
    print(result.summary())
    return 0


def _cmd_rig(args) -> int:
    out = Path(args.out)
    _require_parent(out)
    mesh = _read_mesh(args.mesh)
    points = _read_landmarks(args.landmarks, mesh)
    layout = _layout_for(args.layout, points)
    options = {} if args.k is None else {"k": args.k}
    start = time.perf_counter()
    weights = _weights(args.method, mesh, points, layout, quiet=args.quiet, **options)
    seconds = time.perf_counter() - start
    _write_with(out, weights.save)
    print(
        f"rig {args.method}: {weights.n_vertices} vertices, {weights.n_joints} joints, "
        f"{weights.n_influences} influences per vertex, {seconds:.2f} s -> {out}"
    )
    return 0


def _cmd_track(args) -> int:
    out = Path(args.out)
    _require_parent(out)
    _require_file(args.video, "video")
    take_out = Path(args.take) if args.take else None
    if take_out is not None:
        _require_parent(take_out)
    layout = args.layout or ("ibug68" if args.method == "markerless" else "dutreve21")
    if args.method == "stereo":
        if not (args.right and args.calibration):
            raise RetargetError("--method stereo needs --right RIGHT_VIDEO and --calibration CALIB.npz")
        _require_file(args.right, "right video")
        _require_file(args.calibration, "stereo calibration")
    elif args.right or args.calibration:
        raise RetargetError(f"--right and --calibration are for --method stereo, not {args.method}")
    start = time.perf_counter()
    with _bar(100, f"tracking ({args.method})", "%", args.quiet) as advance:
        def progress(done: int, total: int) -> None:  # the trackers count frames
            if total:
                advance(done / total)

        if args.method == "markers":
            from retarget.sources.markers import track_marker_video
            take = track_marker_video(args.video, layout=layout, progress=progress)
        elif args.method == "markerless":
            from retarget.sources.markerless import track_video_markerless
            take = track_video_markerless(args.video, layout=layout, progress=progress,
                                          max_frames=args.max_frames)
        else:
            from retarget.sources.calibration import StereoCalibration
            from retarget.sources.stereo import track_stereo_videos
            take = track_stereo_videos(args.video, args.right, StereoCalibration.load(args.calibration),
                                       layout=layout, progress=progress)
    seconds = time.perf_counter() - start
    points = take.points
    if take.dims == 2:  # image points: z = 0 (Dutreve §4)
        points = np.concatenate([points, np.zeros_like(points[..., :1])], axis=-1)
    _write_npy(out, np.ascontiguousarray(points, dtype=np.float32))
    if take_out is not None:
        _write_with(take_out, take.save)
    found = np.isfinite(take.points).all(axis=2)
    print(f"tracked {take.n_frames} frames of {take.n_points} points ({take.layout or 'own labels'}) "
          f"in {seconds:.2f} s: {take.n_frames / max(seconds, 1e-9):.1f} fps; "
          f"all points found in {100 * found.all(axis=1).mean():.1f} % of frames, "
          f"none in {100 * (~found.any(axis=1)).mean():.1f} % -> {out}")
    return 0


def _cmd_calibrate(args) -> int:
    from retarget.sources.calibration import calibrate_stereo

    out = Path(args.out)
    _require_parent(out)
    left, right = _views(args.left, "left"), _views(args.right, "right")
    pattern = (args.pattern, args.cols, args.rows, args.square)
    calibration = calibrate_stereo(left, right, pattern)
    _write_with(out, calibration.save)
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
    _require_file(path, f"{side} calibration views")
    with VideoReader(path) as reader:
        return [frame for _, frame in reader]


def _cmd_demo(args) -> int:
    from retarget.sample_face import demo_performance, demo_weights, posed_vertices, sample_face

    out_dir = Path(args.out)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RetargetError(f"could not create --out directory {str(out_dir)!r}: {exc}") from exc
    target = sample_face()
    expression = demo_weights(args.frames)
    s0, s = demo_performance(n_frames=args.frames)

    paths = {name: out_dir / name for name in (
        "target.obj", "target_landmarks.json", "source_neutral.npy",
        "source_frames.npy", "out.npy")}
    save_mesh(mesh_from_arrays(target.vertices, target.faces, uv=target.uv, name="target"),
              paths["target.obj"])
    _write_json(paths["target_landmarks.json"],
                {"vertex_indices": np.asarray(target.landmarks68).tolist(), "layout": "ibug68"})
    _write_npy(paths["source_neutral.npy"], s0)
    _write_npy(paths["source_frames.npy"], s)

    result = transfer_files(
        paths["target.obj"], paths["target_landmarks.json"], paths["source_neutral.npy"],
        paths["source_frames.npy"], paths["out.npy"], deformer=args.deformer,
        quiet=args.quiet,
    )
    truth = posed_vertices(target, expression)
    error = np.linalg.norm(result.vertices - truth, axis=-1)          # (F, V) cm
    motion = np.linalg.norm(truth - target.vertices, axis=-1)         # (F, V) cm
    relative = error.sum() / motion.sum() if motion.sum() > 0 else float("nan")

    f, v, _ = result.vertices.shape
    rate = f / result.transfer_seconds if result.transfer_seconds > 0 else float("inf")
    print(
        f"retarget demo: the sample face ({v} vertices, in cm) animated by a performer of "
        f"another identity through {len(s0)} iBUG landmarks, {f} frames\n"
        f"  wrote {out_dir}/: target.obj, target_landmarks.json, "
        f"source_neutral.npy {s0.shape}, source_frames.npy {s.shape}\n"
        f"  retargeted with {result.method} in "
        f"{result.weights_seconds + result.transfer_seconds:.2f} s (weights "
        f"{result.weights_seconds:.2f} s, then {rate:.0f} frames/s) -> {result.out} "
        f"{result.vertices.shape} float32\n"
        f"  error against the ground truth (the target posed with the same expression "
        f"weights):\n"
        f"    mean {error.mean():.3f} cm, max {error.max():.3f} cm per vertex; relative "
        f"{100 * relative:.1f} % (sum of error lengths / sum of true displacement lengths)\n"
        f"  the same from the files: {PROG} transfer --target-mesh {paths['target.obj']} "
        f"--target-landmarks {paths['target_landmarks.json']} "
        f"--source-neutral {paths['source_neutral.npy']} "
        f"--source-frames {paths['source_frames.npy']} --out {paths['out.npy']}"
    )
    return 0


def _cmd_condition(args) -> int:
    from retarget.sources.conditioning import ConditionSettings, condition_take
    from retarget.sources.files import read_take

    out, neutral_out = Path(args.out), Path(args.neutral_out)
    for path in (out, neutral_out):
        _require_parent(path)
    _require_file(args.take, "take file")
    options = {name: _read_json_file(getattr(args, name), name.replace("_", " "))
               for name in ("mapping", "labelled_vertices", "settings")}
    take = read_take(args.take, layout=args.layout, mapping=options["mapping"], fps=args.fps,
                     labelled_vertices=options["labelled_vertices"])
    settings = ConditionSettings.from_dict(options["settings"])
    conditioned, neutral = condition_take(take, settings)
    _write_npy(out, np.ascontiguousarray(conditioned.points, dtype=np.float32))
    _write_npy(neutral_out, np.ascontiguousarray(neutral, dtype=np.float32))
    print(f"{take.source or 'take'} {take.n_frames} frames of {take.n_points} {take.dims}D points "
          f"({take.layout}) at {take.fps:g} fps: neutral from {settings.neutral['mode']}, head "
          f"{settings.head_pose}, filter {settings.filter}; {conditioned.n_frames} frames "
          f"-> {out}, neutral -> {neutral_out}")
    return 0


def _read_json_file(path, what: str):
    """The JSON in the file `path` (None when not given)."""
    if path is None:
        return None
    _require_file(path, what)
    try:
        return json.loads(Path(path).read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RetargetError(f"{what} {str(path)!r} is not readable JSON: {exc}") from None


def _cmd_layouts(args) -> int:
    for name, layout in LAYOUTS.items():
        counts = {r: layout.regions.count(r) for r in REGIONS if r in layout.regions}
        regions = ", ".join(f"{r} {c}" for r, c in counts.items())
        print(f"{name:<12} {layout.n_points:>3} points  {regions}")
    print(
        f"--mask takes regions ({', '.join(REGIONS)}), groups ({', '.join(GROUPS)}), "
        "point names or feature indices"
    )
    return 0


def _cmd_serve(args) -> int:
    # the web stack is imported here only: the library stays usable without it
    try:
        from server.serve import serve
    except ImportError as exc:
        raise RetargetError(
            f"'{PROG} serve' needs the web server's packages ({exc.name} is missing): "
            "pip install fastapi 'uvicorn[standard]' python-multipart"
        ) from exc
    limits = {}  # flags not given keep the app's defaults
    if args.max_upload_mb is not None:
        limits["max_upload_bytes"] = int(args.max_upload_mb * 2**20)
    if args.max_vertices is not None:
        limits["max_vertices"] = args.max_vertices
    serve(Path(args.data_dir), host=args.host, port=args.port,
          allowed_hosts=tuple(args.allowed_host), token=args.token, **limits)
    return 0


# ---------------------------------------------------------------------------------------
# parser


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port number, got {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port in [0, 65535], got {value}")
    return value


def _number(cast, *, minimum: float, strict: bool, what: str):
    """An argparse type: `cast(text)`, finite and > `minimum` (`strict`) or >= it."""
    def parse(text: str):
        try:
            value = cast(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not np.isfinite(value) or value < minimum or (strict and value == minimum):
            raise argparse.ArgumentTypeError(f"expected {what}, got {value}")
        return value
    return parse


_positive_float = _number(float, minimum=0.0, strict=True, what="a positive number")
_positive_int = _number(int, minimum=1, strict=False, what="a positive integer")
_non_negative_float = _number(float, minimum=0.0, strict=False, what="a finite number >= 0")


def build_parser() -> argparse.ArgumentParser:
    """The ``retarget`` argument parser (refusals raise `_UsageError`, see `main`)."""
    quiet = _Parser(add_help=False)
    quiet.add_argument("-q", "--quiet", action="store_true",
                       help="hide the progress bars on stderr")
    methods, kernels = ", ".join(METHODS), ", ".join(KERNELS)

    parser = _Parser(
        prog=PROG,
        description="Facial animation retargeting from feature points (Dutreve et al. 2008).",
        epilog=f"'{PROG} demo' runs a complete example that needs no files.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True,
                                     parser_class=_Parser)

    p = commands.add_parser(
        "transfer", parents=[quiet], help="retarget source frames onto a target mesh",
        description="Retarget source feature-point frames onto a target mesh and write the "
        "deformed vertices, (F, V, 3) float32, as .npy.")
    p.add_argument("--target-mesh", required=True, metavar="MESH",
                   help="target mesh (obj, ply, stl, off, gltf, glb)")
    p.add_argument("--target-landmarks", required=True, metavar="T0.json",
                   help='its N landmarks: {"vertex_indices": [...]} or {"positions": '
                   '[[x, y, z], ...]}, optionally with "layout"')
    p.add_argument("--source-neutral", required=True, metavar="S0.npy",
                   help="(N, 2|3) neutral source points")
    p.add_argument("--source-frames", required=True, metavar="S.npy",
                   help="(F, N, 2|3) source points per frame, in S0's order; NaN = lost point")
    p.add_argument("--out", required=True, metavar="OUT.npy",
                   help="(F, V, 3) float32 deformed target vertices, written here")
    weights = p.add_mutually_exclusive_group()
    weights.add_argument("--deformer", choices=list(METHODS), default=None, metavar="NAME",
                         help=f"one of {methods} (default: {DEFAULT_METHOD})")
    weights.add_argument("--rig", metavar="RIG.npz",
                         help="skin weights from 'retarget rig', instead of computing them")
    p.add_argument("--kernel", choices=list(KERNELS), default=DEFAULT_KERNEL, metavar="NAME",
                   help=f"RBF space-transform kernel: one of {kernels} (default: {DEFAULT_KERNEL})")
    p.add_argument("--smoothing", type=_non_negative_float, default=None, metavar="X",
                   help="space-transform smoothing, relative (default: "
                   + ", ".join(f"{v:g} for {d}D sources" for d, v in DEFAULT_SMOOTHING.items()) + ")")
    p.add_argument("--mask", nargs="+", action="extend", metavar="NAME",
                   help="partial retargeting: move only these regions, groups, point names "
                   "or feature indices (their union); names need a layout")
    p.add_argument("--layout", choices=list(LAYOUTS), metavar="NAME",
                   help=f"landmark layout ({', '.join(LAYOUTS)}); default: the landmarks "
                   "JSON's \"layout\"")
    p.set_defaults(run=_cmd_transfer)

    p = commands.add_parser(
        "rig", parents=[quiet], help="compute skin weights for a mesh and its landmarks",
        description="Compute the skin weights of a target mesh and write them as .npz "
        "(joint_indices and weights, (V, K)) for 'retarget transfer --rig'.")
    p.add_argument("mesh", metavar="MESH", help="target mesh")
    p.add_argument("--landmarks", required=True, metavar="T0.json", help="its landmarks JSON")
    p.add_argument("--out", required=True, metavar="RIG.npz", help="the rig, written here")
    p.add_argument("--method", choices=list(METHODS), default=DEFAULT_METHOD, metavar="NAME",
                   help=f"one of {methods} (default: {DEFAULT_METHOD})")
    p.add_argument("--k", type=_positive_int, metavar="K",
                   help="influences kept per vertex (default: the method's own, 4 for "
                   "ellipsoid and geodesic, all for the others)")
    p.add_argument("--layout", choices=list(LAYOUTS), metavar="NAME",
                   help="landmark layout; default: the landmarks JSON's \"layout\"")
    p.set_defaults(run=_cmd_rig)

    p = commands.add_parser(
        "demo", parents=[quiet], help="run the built-in example (no files needed)",
        description="Retarget the built-in sample face from a performer of another identity, "
        "write the inputs and the result, and report the error against the ground truth.")
    p.add_argument("--out", default=DEMO_DIR, metavar="DIR",
                   help=f"directory for the files (default: ./{DEMO_DIR})")
    p.add_argument("--frames", type=_positive_int, default=DEMO_FRAMES, metavar="F",
                   help=f"number of frames (default: {DEMO_FRAMES})")
    p.add_argument("--deformer", choices=list(METHODS), default=DEFAULT_METHOD, metavar="NAME",
                   help=f"one of {methods} (default: {DEFAULT_METHOD})")
    p.set_defaults(run=_cmd_demo)

    p = commands.add_parser(
        "track", parents=[quiet], help="track a performance video into source points",
        description="Track a video into (F, N, 3) float32 source points in a layout's order "
        "(NaN rows where a point or the face is lost; z = 0 for one-camera markers) and print "
        "the frames per second.")
    p.add_argument("video", metavar="VIDEO", help="the video (the left one for stereo)")
    p.add_argument("--method", choices=["markerless", "markers", "stereo"], required=True,
                   help="markerless: face-mesh tracking (needs the 'markerless' extra and "
                   "Chromium); markers: white dots with a black ring, one camera; stereo: "
                   "coloured markers seen by a calibrated pair")
    p.add_argument("--layout", choices=list(LAYOUTS), metavar="NAME",
                   help="points to produce (default: dutreve21 for markers and stereo, ibug68 for markerless)")
    p.add_argument("--right", metavar="VIDEO", help="stereo: the right camera's video")
    p.add_argument("--calibration", metavar="CALIB.npz", help="stereo: from 'retarget calibrate'")
    p.add_argument("--max-frames", type=_positive_int, metavar="F",
                   help="markerless: track only the first F frames")
    p.add_argument("--out", required=True, metavar="FRAMES.npy", help="(F, N, 3) float32 points")
    p.add_argument("--take", metavar="TAKE.npz",
                   help="also write the take (points, times, names) for upload to the web app")
    p.set_defaults(run=_cmd_track)

    p = commands.add_parser(
        "condition", parents=[quiet], help="read a take file and condition it into source points",
        description="Read a performance file (landmark CSV/JSON/NPY, TRC or C3D motion capture, an "
        "animated glTF/GLB face or a zip of OBJ frames with --labelled-vertices, or a take .npz "
        "from 'track --take') in a layout's point order, condition it as the web app plays a "
        "take (neutral capture, head-motion removal, jitter filter, gain per region) and write "
        "the neutral and the frames for 'transfer' and 'export-gltf'.")
    p.add_argument("take", metavar="TAKE", help="the performance file")
    p.add_argument("--layout", choices=list(LAYOUTS), required=True, metavar="NAME",
                   help="the layout whose points to produce, in its order (every point needed)")
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
                   help="(F, N, D) float32 conditioned frames (the neutral capture left out)")
    p.set_defaults(run=_cmd_condition)

    p = commands.add_parser(
        "calibrate", parents=[quiet], help="calibrate a stereo camera pair",
        description="Calibrate a stereo pair from views of a calibration pattern (each side a "
        "folder of images or a video) for 'retarget track --method stereo'.")
    p.add_argument("left", metavar="LEFT", help="left camera: folder of images or a video")
    p.add_argument("right", metavar="RIGHT", help="right camera: the same views, same order")
    p.add_argument("--pattern", choices=["checkerboard", "circles"], default="checkerboard",
                   help="checkerboard (inner corners) or symmetric circle grid")
    p.add_argument("--cols", type=_positive_int, required=True, help="pattern columns (inner corners or circles)")
    p.add_argument("--rows", type=_positive_int, required=True, help="pattern rows")
    p.add_argument("--square", type=_positive_float, required=True, metavar="SIZE",
                   help="square (or circle spacing) size; the units of the 3D points, e.g. mm")
    p.add_argument("--out", required=True, metavar="CALIB.npz", help="the calibration, written here")
    p.set_defaults(run=_cmd_calibrate)

    p = commands.add_parser(
        "export-gltf", parents=[quiet], help="export the rigged, animated face as glTF (.glb)",
        description="Write the target mesh (with its uv, normals and material), a joint per "
        "feature point and the rig (a glTF skin; morph targets for rigs with negative "
        "weights) as a glTF 2.0 binary; with a source, the retargeted take as an animation. "
        "Units are the mesh's own.")
    p.add_argument("--mesh", required=True, metavar="MESH",
                   help="target mesh (obj, ply, stl, off, gltf, glb)")
    p.add_argument("--landmarks", required=True, metavar="T0.json", help="its landmarks JSON")
    p.add_argument("--out", required=True, metavar="OUT.glb", help="the glTF binary, written here")
    weights = p.add_mutually_exclusive_group()
    weights.add_argument("--deformer", choices=list(METHODS), default=None, metavar="NAME",
                         help=f"one of {methods} (default: {DEFAULT_METHOD}); ellipsoid and "
                         "geodesic export as a skin, the others as morph targets")
    weights.add_argument("--rig", metavar="RIG.npz",
                         help="skin weights from 'retarget rig', instead of computing them")
    p.add_argument("--source-neutral", metavar="S0.npy",
                   help="(N, 2|3) neutral source points (with --source-frames: animate)")
    p.add_argument("--source-frames", metavar="S.npy",
                   help="(F, N, 2|3) source points per frame; the animation takes its name")
    p.add_argument("--fps", type=_positive_float, default=30.0,
                   help="frames per second of the source frames (default: 30)")
    p.add_argument("--kernel", choices=list(KERNELS), default=None, metavar="NAME",
                   help=f"RBF space-transform kernel (default: {DEFAULT_KERNEL})")
    p.add_argument("--smoothing", type=_non_negative_float, default=None, metavar="X",
                   help="space-transform smoothing, relative (default: as for transfer)")
    p.add_argument("--mask", nargs="+", action="extend", metavar="NAME",
                   help="partial retargeting: move only these regions, groups, point names "
                   "or feature indices")
    p.add_argument("--layout", choices=list(LAYOUTS), metavar="NAME",
                   help="landmark layout (joint names); default: the landmarks JSON's \"layout\"")
    p.set_defaults(run=_cmd_export_gltf)

    p = commands.add_parser("layouts", help="list the landmark layouts and their regions",
                            description="List the landmark layouts, their point counts and "
                            "regions.")
    p.set_defaults(run=_cmd_layouts, quiet=True)

    p = commands.add_parser("serve", help="run the web server",
                            description="Serve the web app and its REST API (docs at /docs); "
                            "projects are kept in --data-dir across restarts.")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default: 127.0.0.1, this machine only; any other "
                   "address needs the access token the server prints)")
    p.add_argument("--allowed-host", action="append", default=[], metavar="NAME",
                   help="another host name the server is reached by (repeatable); requests "
                   "naming other hosts are refused")
    p.add_argument("--token", action="store_true",
                   help="require the access token on loopback too")
    p.add_argument("--port", type=_port, default=8000, help="port (default: 8000)")
    p.add_argument("--data-dir", default=SERVE_DATA_DIR, metavar="DIR",
                   help=f"project store folder, created if missing (default: ./{SERVE_DATA_DIR})")
    p.add_argument("--max-upload-mb", type=_positive_float, metavar="MB",
                   help="largest uploaded file (mesh, take, video, .glb), MiB (default: 64)")
    p.add_argument("--max-vertices", type=_positive_int, metavar="V",
                   help="most vertices an uploaded mesh may have (default: 500000)")
    p.set_defaults(run=_cmd_serve, quiet=True)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the ``retarget`` command line; returns the exit status (0, or 2 on error)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        return args.run(args)
    except _UsageError as exc:
        sys.stderr.write(exc.usage)
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    except SystemExit as exc:  # --help and --version
        return exc.code if isinstance(exc.code, int) else 0
    except BrokenPipeError:  # stdout closed early (`retarget layouts | head -1`)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except (RetargetError, OSError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
