"""Retargeting with files: the library's file-level API, what ``retarget transfer`` and
``retarget export-gltf`` run.

`transfer_files` takes a target mesh and its landmarks, a source's neutral S0 and frames S
in ``.npy`` files, and writes the deformed target, (F, V, 3) float32 ``.npy``;
`export_gltf_files` writes the rigged face (or the face with its muscles, or with ARKit's 52
blendshapes), and the take animated, as one glTF 2.0 binary. With drive "arkit" both
solve the take into ARKit weights per frame and can write them as Live Link Face CSV.
Both read and check their inputs alike (`source_arrays`, `layout_for`, `mask_for`), get
their skin weights alike (`rig_weights`: read from a rig file or computed) and retarget
through one `retarget.performance.Performance` (Dutreve et al. 2008 §4).

The checked readers and writers here serve the command line too: every failure (a missing
or unreadable file, arrays that do not agree, an output folder that does not exist) is a
`RetargetError` that names the file or option, raised before any slow work where it can
be. Progress bars (tqdm) go to stderr unless `quiet`.
"""

from __future__ import annotations

import inspect
import json
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

import numpy as np
from tqdm import tqdm

from retarget.arkit.clip import ArkitClip
from retarget.arkit.shapes import ArkitShapes, arkit_shapes
from retarget.arkit.solve import ArkitSolver
from retarget.clips import ContractionClip, clip_at_rate
from retarget.errors import RetargetError
from retarget.gltf import write_arkit_gltf, write_gltf, write_muscles_gltf
from retarget.gltf.glb import glb_document
from retarget.gltf.influences import is_joint_based
from retarget.gltf.keys import Keys
from retarget.gltf.writer import FORMS
from retarget.landmarks import SurfacePoints, load_landmarks
from retarget.layouts import Layout, get_layout
from retarget.mesh import Mesh, load_mesh
from retarget.muscles import MuscleFace, place_muscles
from retarget.muscles.drive import MuscleDrive
from retarget.muscles.morphs import muscle_morphs
from retarget.performance import Performance
from retarget.pipeline import DEFAULT_KERNEL, transfer
from retarget.skin import SkinWeights
from retarget.units import export_scale, unit_scale
from retarget.units import mesh_units as unit_of
from retarget.sources.arkit_curves import ArkitCurves, live_link_csv
from retarget.weights import DEFAULT_METHOD, METHODS, compute_weights

__all__ = ["ExportResult", "TransferResult", "arkit_shapes_for", "contractions_files", "export_gltf_files",
           "muscles_for", "transfer_files"]

DRIVES = ("points", "muscles", "arkit")


# ---------------------------------------------------------------------------------------
# transfer


@dataclass(frozen=True)
class TransferResult:
    """What `transfer_files` did.

    vertices : (F, V, 3) float32, the deformed target, mesh units (also written to `out`).
    rest : (V, 3) float64, the target mesh's neutral vertices as read.
    n_points : N, the number of feature points.
    method : the deformer (the rig's method when the weights were read from a file;
        "muscles" when driven by muscles, "arkit" by ARKit's shapes).
    weights_seconds, transfer_seconds : wall time of the weight solve (or rig read, or
        muscle placement) and of the per-frame transfer.
    out : the path written.
    contractions : (F, D) float64 solved muscle contractions when driven by muscles.
    arkit_weights : (F, 52) float64 solved ARKit weights when driven by ARKit's shapes.
    """

    vertices: np.ndarray
    rest: np.ndarray
    n_points: int
    method: str
    weights_seconds: float
    transfer_seconds: float
    out: Path
    contractions: np.ndarray | None = None
    arkit_weights: np.ndarray | None = None

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
    drive: str = "points",
    muscles=None,
    contractions_out=None,
    arkit=None,
    weights_out=None,
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
    rig : ``.npz`` from `SkinWeights.save` to use instead of computing weights (with drive
        "arkit": the rig the shapes are made with).
    drive : "points" (feature points as skinning joints, Dutreve §3), "muscles" (the
        feature points' motion solved into muscle contractions by the muscle IK and made by
        the muscles, Woodward §4, §7; no rig) or "arkit" (the feature points' motion solved
        per frame into ARKit's 52 weights, `retarget.arkit.solve.ArkitSolver` on the shapes'
        feature-point motion, and made by the shapes, ``v0 + sum_k w_k delta_k``).
    muscles : with drive "muscles", a ``retarget muscles`` JSON; default: placed on the mesh
        from its landmarks.
    contractions_out : with drive "muscles", ``.npy`` written with the (F, D) contractions.
    arkit : with drive "arkit", a ``retarget arkit`` SHAPES.npz for this mesh; default: the
        shapes generated from the landmarks (`retarget.arkit.arkit_shapes`, through `rig`
        when given, else the shapes' own rig).
    weights_out : with drive "arkit", the (F, 52) weights written here as Live Link Face
        CSV (`retarget.sources.arkit_curves.live_link_csv`; times at 30 fps: ``.npy``
        source frames carry no rate).

    Raises `RetargetError` for every refusal, naming the file or option.
    """
    if drive != "muscles" and (muscles is not None or contractions_out is not None):
        raise RetargetError("muscles and contractions_out need drive 'muscles'")
    _check_drive(drive, muscles, arkit, weights_out, rig)
    out = Path(out)
    require_parent(out)
    for extra in (contractions_out, weights_out):
        if extra is not None:
            require_parent(Path(extra))
    mesh = read_mesh(target_mesh)
    points = read_landmarks(target_landmarks, mesh)
    n = points.n_points
    s0, frames = source_arrays(source_neutral, source_frames, n)
    the_layout = layout_for(layout, points)
    active = mask_for(mask, the_layout, n)

    start = time.perf_counter()
    if drive == "muscles":
        model = muscles_for(muscles, mesh, points, the_layout)
        placed_seconds = time.perf_counter() - start
        start = time.perf_counter()
        performance = _performance(mesh, points, the_layout, active, kernel, smoothing, s0)
        muscle_drive = MuscleDrive(model, points)
        contractions = _contractions(muscle_drive, performance, frames, quiet)
        result = mesh.vertices + muscle_drive.displacements(contractions)
        transfer_seconds = time.perf_counter() - start
        write_npy(out, result.astype(np.float32))
        if contractions_out is not None:
            write_npy(Path(contractions_out), contractions)
        return TransferResult(result.astype(np.float32), mesh.vertices, n, "muscles", placed_seconds,
                              transfer_seconds, out, contractions)
    if drive == "arkit":
        shapes = arkit_shapes_for(arkit, mesh, points, the_layout, rig)
        shapes_seconds = time.perf_counter() - start
        start = time.perf_counter()
        performance = _performance(mesh, points, the_layout, active, kernel, smoothing, s0)
        weights = _arkit_weights(shapes, performance, frames, quiet)
        result = shapes.posed(mesh.vertices, weights)
        transfer_seconds = time.perf_counter() - start
        write_npy(out, result)
        if weights_out is not None:
            write_live_link(Path(weights_out), weights, TRANSFER_FPS)
        return TransferResult(result, mesh.vertices, n, "arkit", shapes_seconds, transfer_seconds, out,
                              arkit_weights=weights)
    weights = rig_weights(rig, deformer, mesh, points, the_layout, quiet=quiet)
    method = (weights.method or "rig") if rig is not None else deformer
    weights_seconds = time.perf_counter() - start

    start = time.perf_counter()
    performance = _performance(mesh, points, the_layout, active, kernel, smoothing, s0)
    with progress_bar(len(frames), "transfer", "frame", quiet) as advance:
        result = transfer(mesh.vertices, weights, performance, frames, progress=advance)
    transfer_seconds = time.perf_counter() - start

    write_npy(out, result)
    return TransferResult(
        result, mesh.vertices, n, method, weights_seconds, transfer_seconds, out
    )


def contractions_files(target_mesh, target_landmarks, source_neutral, source_frames, *,
                       layout: str | None = None, muscles=None, kernel: str = DEFAULT_KERNEL,
                       smoothing: float | None = None, quiet: bool = False) -> tuple[np.ndarray, tuple[str, ...]]:
    """(F, D) muscle contractions of a source's frames on a target (as `transfer_files`
    with drive "muscles" solves them) and the D dof names."""
    mesh = read_mesh(target_mesh)
    points = read_landmarks(target_landmarks, mesh)
    s0, frames = source_arrays(source_neutral, source_frames, points.n_points)
    the_layout = layout_for(layout, points)
    drive = MuscleDrive(muscles_for(muscles, mesh, points, the_layout), points)
    performance = _performance(mesh, points, the_layout, None, kernel, smoothing, s0)
    return _contractions(drive, performance, frames, quiet), drive.names


def muscles_for(path, mesh: Mesh, points: SurfacePoints, layout: Layout | None) -> MuscleFace:
    """The muscles read from `path` (a ``retarget muscles`` JSON for this mesh), or (path
    None) placed on the mesh from its feature points."""
    if path is not None:
        require_file(path, "muscles")
        try:
            data = json.loads(Path(path).read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise RetargetError(f"could not read muscles {str(path)!r} as JSON: {exc}") from None
        if not isinstance(data, dict):
            raise RetargetError(f"muscles {str(path)!r} is not a JSON object")
        return MuscleFace.from_json(data, mesh.vertices)
    if layout is None:
        raise RetargetError("placing muscles needs the landmarks' layout: give --layout or a "
                            "landmarks JSON with \"layout\"")
    return place_muscles(mesh.vertices, mesh.faces, points, layout)


def _contractions(drive: MuscleDrive, performance: Performance, frames: np.ndarray, quiet: bool) -> np.ndarray:
    """(F, D) contractions of (F, N, 2|3) source frames, solved in order, with a progress bar."""
    return _solved(drive.contractions, len(drive.names), performance, frames, quiet, "muscle IK", 64)


def _solved(solve, width: int, performance: Performance, frames: np.ndarray, quiet: bool, label: str,
            chunk: int) -> np.ndarray:
    """(F, width) `solve` of the retargeted feature displacements of (F, N, 2|3) source frames,
    `chunk` frames at a time in order (a solver warm-starts each frame from the last), with
    a progress bar."""
    out = np.empty((len(frames), width))
    with progress_bar(len(frames), label, "frame", quiet) as advance:
        for i in range(0, len(frames), chunk):
            out[i:i + chunk] = solve(performance.displacements(frames[i:i + chunk]))
            advance(min(1.0, (i + chunk) / max(len(frames), 1)))
    return out


TRANSFER_FPS = 30.0
"""The rate `transfer_files` writes Live Link Face timecodes at (its ``.npy`` frames have none)."""


def _check_drive(drive: str, muscles, arkit, weights_out, rig) -> None:
    """Refuse a drive not in `DRIVES` and options that need another drive."""
    if drive not in DRIVES:
        raise RetargetError(f"unknown drive {drive!r}; choose one of {', '.join(DRIVES)}")
    if drive != "muscles" and muscles is not None:
        raise RetargetError("--muscles needs --drive muscles")
    if drive != "arkit" and (arkit is not None or weights_out is not None):
        raise RetargetError("--arkit and --weights-out need --drive arkit")
    if drive == "muscles" and rig is not None:
        raise RetargetError("drive 'muscles' makes the motion with the muscles, not a rig: drop the rig")
    if arkit is not None and rig is not None:
        raise RetargetError("--arkit gives shapes already made (by 'retarget arkit', with a rig of "
                            "its own): drop --rig, or drop --arkit to make the shapes with --rig")


def arkit_shapes_for(path, mesh: Mesh, points: SurfacePoints, layout: Layout | None,
                     rig=None) -> ArkitShapes:
    """ARKit's 52 shapes for the mesh: read from `path` (``retarget arkit``'s SHAPES.npz,
    checked against the mesh's V vertices and N points), or (path None) generated from the
    feature points (`arkit_shapes`, through the `rig` file's weights when given)."""
    if path is not None:
        require_file(path, "ARKit shapes")
        shapes = ArkitShapes.load(path)
        v, n = shapes.deltas.shape[1], shapes.at_points.shape[1]
        if v != mesh.n_vertices:
            raise RetargetError(f"ARKit shapes {str(path)!r} move {v} vertices but the mesh has "
                                f"{mesh.n_vertices}: make them for this mesh with 'retarget arkit'")
        if n != points.n_points:
            raise RetargetError(f"ARKit shapes {str(path)!r} are fitted at {n} feature points but the "
                                f"landmarks have {points.n_points}")
        return shapes
    if layout is None:
        raise RetargetError("making the ARKit shapes needs the landmarks' layout: give --layout, a "
                            "landmarks JSON with \"layout\", or shapes with --arkit")
    weights = None if rig is None else read_rig(rig, mesh, points.n_points)
    return arkit_shapes(mesh.vertices, mesh.faces, points, layout, weights)


def _arkit_weights(shapes: ArkitShapes, performance: Performance, frames: np.ndarray, quiet: bool) -> np.ndarray:
    """(F, 52) ARKit weights of (F, N, 2|3) source frames: the retargeted feature
    displacements solved frame after frame (each warm-starting the next), with a progress bar."""
    solver = ArkitSolver(shapes.at_points)
    return _solved(solver.solve_frames, len(shapes.names), performance, frames, quiet, "ARKit weights", 256)


def write_live_link(path: Path, weights: np.ndarray, fps: float) -> None:
    """Write (F, 52) ARKit weights at `fps` as Live Link Face CSV."""
    text = live_link_csv(ArkitCurves(weights, float(fps), None, None, {}))
    try:
        path.write_text(text)
    except OSError as exc:
        raise RetargetError(f"could not write {str(path)!r}: {exc}") from exc


# ---------------------------------------------------------------------------------------
# export-gltf


@dataclass(frozen=True)
class ExportResult:
    """What `export_gltf_files` did.

    n_vertices, n_points : V and N of the exported face.
    n_frames : F frames of the animation (0 without a source).
    fps : the animation's frame rate.
    deformation : "skin", "morph", "muscles" or "arkit" (see `retarget.gltf.writer` and
        `retarget.gltf.arkit`).
    method : the rig's method ("muscles" for the muscles, "arkit" for ARKit's shapes).
    seconds : wall time, weights and retargeting included.
    n_bytes : size of the file written.
    out : the path written.
    arkit_weights : (F, 52) float64 the solved ARKit weights, with drive "arkit" and a source.
    source_units : the mesh's unit, as given or guessed ("m", "cm", "mm", "in").
    scale : what every length was multiplied by (0.01 for a centimetre mesh in metres, 1.0
        with units "keep").
    fit : with form "skin", the fit's record (``extras.retarget.fit``: ``rms_relative``,
        ``rms_mm``, ``worst_vertex_mm`` with a take), else None.
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
    arkit_weights: np.ndarray | None = None
    source_units: str = "m"
    scale: float = 1.0
    fit: dict | None = None

    def summary(self) -> str:
        """The one-line report `export-gltf` prints."""
        animation = (f", {self.n_frames} frames at {self.fps:g} fps" if self.n_frames
                     else ", no animation")
        kind = {"skin": f"{self.n_points} feature joints of a skin",
                "morph": f"{self.n_points} feature joints, morph targets",
                "muscles": "a morph target per muscle and a jaw joint",
                "arkit": "ARKit's 52 blendshapes as morph targets"}[self.deformation]
        units = (f"in metres (the mesh in {self.source_units}, x{self.scale:g})" if self.scale != 1.0
                 or self.source_units == "m" else f"in the mesh's {self.source_units}")
        fit = ""
        if self.fit is not None and "rms_relative" in self.fit:
            fit = (f" (four influences a vertex, fitted: {100 * self.fit['rms_relative']:.1f} % "
                   f"RMS error, {self.fit['rms_mm']:.3f} mm; worst vertex {self.fit['worst_vertex_mm']:.2f} mm)")
        elif self.fit is not None:
            fit = " (four influences a vertex, fitted)"
        return (f"exported {self.n_vertices} vertices, {kind}{fit} "
                f"({self.method}){animation}, {units}: {self.n_bytes / 2**20:.1f} MiB in "
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
    drive: str = "points",
    muscles=None,
    arkit=None,
    weights_out=None,
    form: str = "exact",
    rate: float | None = None,
    key_tolerance: float = 0.0,
    units: str = "m",
    mesh_units: str = "guess",
    quiet: bool = False,
) -> ExportResult:
    """Write a target mesh, rigged and optionally animated, as a glTF 2.0 binary (.glb).

    mesh_path, landmarks : the target mesh file and its landmarks JSON (N points); the
        joints are named after the layout's points (`retarget.gltf.joint_names`).
    out : the .glb written (`retarget.gltf.export_gltf`).
    rig : ``.npz`` from `SkinWeights.save`; else weights of `deformer` are computed.
    source_neutral, source_frames : ``.npy`` S0 (N, 2|3) and S (F, N, 2|3), as for
        `transfer_files`; both or neither. Given, the take is retargeted (Dutreve §4)
        and exported as one animation named after the frames file, frame f at f / fps.
    kernel, smoothing, mask : the retargeting's (`transfer_files`); they need a source.
    layout : layout name; default the landmarks JSON's ``"layout"``, if any.
    drive : "points" (the rig above); "muscles": the face with its muscles as morph
        targets and a jaw joint (`retarget.gltf.write_muscles_gltf`, no rig), the take's
        feature motion solved into contractions (as `transfer_files` does); "arkit": the
        face with ARKit's 52 shapes as named, sparse morph targets
        (`retarget.gltf.write_arkit_gltf`, no rig), the take's feature motion solved into
        their weights per frame (as `transfer_files` does).
    muscles : with drive "muscles", a ``retarget muscles`` JSON; default: placed on the
        mesh from its landmarks.
    arkit : with drive "arkit", a ``retarget arkit`` SHAPES.npz for this mesh; default:
        generated from the landmarks (through `rig` when given, `deformer` is not used).
    weights_out : with drive "arkit" and a source, the (F, 52) weights written here as Live
        Link Face CSV at `fps`.
    form : with drive "points", "exact" (the rig as it is) or "skin" (a four-influence skin
        fitted to the take, `retarget.weights.skin_fit`; its error in the result).
    rate : None (the take's own frames) or 24, 25, 30, 60 fps for the keys.
    key_tolerance : millimetres; keys within it of the line between their neighbours are
        dropped (`retarget.gltf.keys`); 0 keeps them all.
    units : "m" (lengths in metres, glTF's unit; the default) or "keep" (the mesh's own
        numbers); the scale is recorded in the file (`retarget.gltf.units`).
    mesh_units : the mesh's unit, "m", "cm", "mm", "in", or "guess" from its size
        (`retarget.units.guess_units`).

    Raises `RetargetError` for every refusal, naming the file or option.
    """
    start = time.perf_counter()
    export_scale(units, "m")  # a bad choice is refused before any work
    keys = Keys(rate, key_tolerance)
    if form not in FORMS:
        raise RetargetError(f"the export form must be one of {', '.join(FORMS)}; got {form!r}")
    if form != "exact" and drive != "points":
        raise RetargetError(f"--form {form} shapes the rig's export: it goes with --drive points")
    if mesh_units != "guess":
        unit_scale(mesh_units)
    _check_drive(drive, muscles, arkit, weights_out, rig)
    if weights_out is not None and source_frames is None:
        raise RetargetError("--weights-out writes the take's weights: give --source-neutral and "
                            "--source-frames too")
    out = Path(out)
    require_parent(out)
    if weights_out is not None:
        require_parent(Path(weights_out))
    if (source_neutral is None) != (source_frames is None):
        raise RetargetError("--source-neutral and --source-frames go together: give both "
                            "for an animation, or neither")
    if source_frames is None and (mask or kernel is not None or smoothing is not None):
        raise RetargetError("--mask, --kernel and --smoothing shape the animation: give "
                            "--source-neutral and --source-frames too")
    if not np.isfinite(fps) or fps <= 0:
        raise RetargetError(f"fps must be a positive number; got {fps!r}")
    mesh = read_mesh(mesh_path)
    source_units = unit_of(mesh_units, mesh.vertices)
    scaling = {"units": units, "mesh_units": source_units, "rate": keys.rate,
               "key_tolerance": keys.tolerance}
    points = read_landmarks(landmarks, mesh)
    the_layout = layout_for(layout, points)
    if the_layout is not None:
        points = replace(points, layout=the_layout.name)
    n = points.n_points
    clips = []
    if source_frames is not None:
        s0, frames = source_arrays(source_neutral, source_frames, n)
        active = mask_for(mask, the_layout, n)
    if drive == "muscles":
        model = muscles_for(muscles, mesh, points, the_layout)
        morphs = muscle_morphs(model)
    elif drive == "arkit":
        shapes = arkit_shapes_for(arkit, mesh, points, the_layout, rig)
    else:
        weights = rig_weights(rig, deformer, mesh, points, the_layout, quiet=quiet)
    solved = None
    if source_frames is not None:
        performance = _performance(mesh, points, the_layout, active, kernel or DEFAULT_KERNEL,
                                   smoothing, s0)
        name = Path(source_frames).stem
        if drive == "muscles":
            contractions = _contractions(MuscleDrive(model, points), performance, frames, quiet)
            clips.append(ContractionClip(name, contractions, np.arange(len(frames)) / float(fps)))
        elif drive == "arkit":
            solved = _arkit_weights(shapes, performance, frames, quiet)
            clips.append(ArkitClip.at_rate(name, solved, fps))
        else:
            d = np.empty((len(frames), n, 3), np.float32)
            chunk = 256
            with progress_bar(len(frames), "retarget", "frame", quiet) as advance:
                for i in range(0, len(frames), chunk):
                    d[i:i + chunk] = performance.displacements(frames[i:i + chunk])
                    advance((i + chunk) / len(frames))
            clips.append(clip_at_rate(name, d, fps))
    if drive == "muscles":
        save = partial(write_muscles_gltf, mesh=mesh, morphs=morphs, clips=clips, **scaling)
        deformation, method = "muscles", "muscles"
    elif drive == "arkit":
        save = partial(write_arkit_gltf, mesh=mesh, shapes=shapes, clips=clips, **scaling)
        deformation, method = "arkit", "arkit"
    else:
        save = partial(write_gltf, mesh=mesh, points=points, weights=weights, clips=clips,
                       form=form, **scaling)
        deformation = "skin" if form == "skin" or is_joint_based(weights) else "morph"
        method = weights.method or ("rig" if rig is not None else deformer)
    written = []
    with progress_bar(100, "glTF", "%", quiet) as advance:
        write_file(out, lambda f: written.append(save(f, progress=advance)))
    if weights_out is not None:
        write_live_link(Path(weights_out), solved, fps)
    with open(out, "rb") as f:
        record = glb_document(f)["scenes"][0]["extras"]["retarget"]
    frames = keys.resampled(clips)[0].n_frames if clips else 0
    return ExportResult(mesh.n_vertices, n, frames, keys.rate or fps, deformation,
                        method, time.perf_counter() - start, written[0], out, solved,
                        source_units, export_scale(units, source_units), record.get("fit"))


# ---------------------------------------------------------------------------------------
# what the two share


def source_arrays(source_neutral, source_frames, n_target: int) -> tuple[np.ndarray, np.ndarray]:
    """S0 (N, D) and S (F, N, D) float64 read from their ``.npy`` files and checked against
    each other and the target's N points."""
    s0 = read_npy(source_neutral, "source neutral")
    frames = read_npy(source_frames, "source frames")
    _check_source(s0, frames, n_target)
    return s0, frames


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


def layout_for(name: str | None, points: SurfacePoints) -> Layout | None:
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


def mask_for(values, layout: Layout | None, n: int) -> np.ndarray | None:
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


def rig_weights(rig, deformer: str, mesh: Mesh, points: SurfacePoints, layout: Layout | None, *,
                quiet: bool) -> SkinWeights:
    """The skin weights read from the `rig` file, or (`rig` None) computed by `deformer`."""
    if rig is not None:
        return read_rig(rig, mesh, points.n_points)
    return computed_weights(deformer, mesh, points, layout, quiet=quiet)


def _performance(mesh: Mesh, points: SurfacePoints, layout: Layout | None, mask, kernel: str,
                 smoothing: float | None, s0: np.ndarray) -> Performance:
    """The mesh's feature points driven by a source whose neutral is `s0` (frames read from
    files are taken as conditioned)."""
    performance = Performance(points.positions(mesh.vertices), layout, regions=mask,
                              kernel=kernel, smoothing=smoothing)
    performance.set_neutral(s0)
    return performance


def computed_weights(method: str, mesh: Mesh, points: SurfacePoints, layout: Layout | None, *,
                     quiet: bool, **options) -> SkinWeights:
    """`compute_weights` with a progress bar where the method reports progress."""
    if method not in METHODS:
        raise RetargetError(f"unknown deformer {method!r}; choose one of {', '.join(METHODS)}")
    if "progress" not in inspect.signature(METHODS[method]).parameters:
        return compute_weights(method, mesh.vertices, mesh.faces, points, layout, **options)
    with progress_bar(100, f"{method} weights", "%", quiet) as advance:
        return compute_weights(
            method, mesh.vertices, mesh.faces, points, layout, progress=advance, **options
        )


@contextmanager
def progress_bar(total: int, desc: str, unit: str, quiet: bool):
    """A tqdm bar of `total` steps on stderr (hidden when `quiet`), as a context manager
    yielding ``advance(fraction done)``."""
    bar = tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, disable=quiet, leave=False,
               dynamic_ncols=True)

    def advance(fraction: float) -> None:
        done = round(min(max(float(fraction), 0.0), 1.0) * bar.total)
        bar.update(done - bar.n)

    try:
        yield advance
    finally:
        bar.close()


# ---------------------------------------------------------------------------------------
# file reading and writing: every failure becomes a RetargetError naming the file


def read_mesh(path) -> Mesh:
    require_file(path, "target mesh")
    return load_mesh(path)


def read_landmarks(path, mesh: Mesh) -> SurfacePoints:
    require_file(path, "target landmarks")
    return load_landmarks(path, mesh.vertices, mesh.faces)


def read_npy(path, what: str) -> np.ndarray:
    """A numeric ``.npy`` as float64; `what` names it in messages."""
    require_file(path, what)
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


def read_rig(path, mesh: Mesh, n_points: int) -> SkinWeights:
    require_file(path, "rig")
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


def require_file(path, what: str) -> None:
    p = Path(path)
    if not p.is_file():
        state = "is not a file" if p.exists() else "does not exist"
        raise RetargetError(f"{what} {str(p)!r} {state}")


def require_parent(path: Path) -> None:
    """Refuse an output path whose directory is missing, before any work is done."""
    if not path.parent.is_dir():
        raise RetargetError(f"cannot write {str(path)!r}: directory {str(path.parent)!r} does not exist")


def write_file(path: Path, save) -> None:
    """Write exactly `path` through ``save(binary file)`` (numpy's savers would append
    their suffix to another one)."""
    try:
        with open(path, "wb") as f:
            save(f)
    except OSError as exc:
        raise RetargetError(f"could not write {str(path)!r}: {exc}") from exc


def write_npy(path: Path, array: np.ndarray) -> None:
    write_file(path, lambda f: np.save(f, array))


def write_json(path: Path, data: dict) -> None:
    try:
        path.write_text(json.dumps(data) + "\n")
    except OSError as exc:
        raise RetargetError(f"could not write {str(path)!r}: {exc}") from exc
