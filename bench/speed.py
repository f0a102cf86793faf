"""Speed of the retargeting core on one CPU core.

    python bench/speed.py [--repeats 200] [--big-resolution 4]
    python bench/speed.py --dense [--repeats 200] [--rounds 5]

Prints medians over repeats:
- fit of the RBF space transform for 68 points (default kernel and Dutreve's);
- one frame (transform of 68 points + skinning of the face) for the default dense
  deformer and its 8-influence truncation (what the GPU shader takes), on the ICT face
  when ../shared is present and on the built-in face otherwise;
- auto-rig of a ~100k-vertex built-in face with 68 points, for every weight method.
Ratios are against the paper's method (adaptive multiquadric, ellipsoid) run in the same
process.

--dense prints only the dense layout's per-frame space transform (issue 14, section 3: the
server's work a frame, target < 1 ms): `Retargeter.displacements` of one 468-point frame
of the built-in performer (its widest expression in the first second) onto the built-in
face, per kernel, against the transform as it was before its hot path was rewritten
(`displacements_before`, kept here only for the ratio), alternated in rounds so both see
the same load; with the largest difference between the two relative to the frame's
largest displacement.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.timing import median_ms  # noqa: E402
from scipy.spatial.distance import cdist  # noqa: E402

from retarget.landmarks import from_vertex_indices  # noqa: E402
from retarget.layouts import get_layout  # noqa: E402
from retarget.pipeline import DEFAULT_KERNEL, DEFAULT_SMOOTHING, Retargeter  # noqa: E402
from retarget.rbf import _polynomial, kernel_values  # noqa: E402
from retarget.sample_face import demo_points, sample_face  # noqa: E402
from retarget.skin import skin_displacements  # noqa: E402
from retarget.weights import DEFAULT_METHOD, METHODS, compute_weights  # noqa: E402


def face_for_frames():
    """(vertices, faces, 68 landmark vertices, label): ICT's generic face if present."""
    ict = Path(__file__).resolve().parents[2] / "shared" / "data" / "ict_face" / "ict_face.npz"
    if ict.exists():
        d = np.load(ict)
        return d["neutral"].astype(np.float64), d["faces"].astype(np.int64), d["landmarks_68"], "ICT face"
    f = sample_face()
    return f.vertices, f.faces, f.landmarks68, "built-in face"


def displacements_before(rt: Retargeter, frame: np.ndarray) -> np.ndarray:
    """(N, 3) float32 `Retargeter.displacements` of one fully driven, unmasked (N, 3)
    frame as computed before the hot path's rewrite: the (M, N+P) basis (kernel matrix
    from cdist distances, polynomial columns stacked onto it) times the coefficients."""
    rbf = rt.transform_
    x = np.asarray(frame, dtype=np.float64)
    k = kernel_values(rbf.kernel, cdist(x, rbf.centers_), rbf.shape_[None, :])
    if rbf.degree_ >= 0:
        k = np.hstack([k, _polynomial(x, rbf.origin_, rbf.axes_)])
    return np.nan_to_num(k @ rbf.coefs_ - rt.target_rest_, nan=0.0).astype(np.float32)


def dense_transform(repeats: int, rounds: int) -> None:
    """Print the --dense section (module docstring)."""
    layout = get_layout("mediapipe468")
    s0, frames = demo_points(layout, n_frames=30)
    t0 = layout.reference_points()
    frame = frames[np.abs(frames - s0).max(axis=(1, 2)).argmax()]  # the widest expression
    print(f"Space transform of one {len(s0)}-point frame, Retargeter.displacements "
          f"(median of {repeats}, {rounds} alternated rounds):")
    for kernel in (DEFAULT_KERNEL, "adaptive_multiquadric"):
        rt = Retargeter(kernel).fit(s0, t0)
        before, after = [], []
        for _ in range(rounds):
            before.append(median_ms(lambda: displacements_before(rt, frame), repeats))
            after.append(median_ms(lambda: rt.displacements(frame), repeats))
        ref = displacements_before(rt, frame)
        error = np.abs(rt.displacements(frame) - ref).max() / np.abs(ref).max()
        ratio = np.median(np.divide(after, before))
        print(f"  {kernel:<22} before {np.median(before):6.3f} ms  now {np.median(after):6.3f} ms  "
              f"({ratio:.2f}x)  max difference {error:.1e} of the largest displacement")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeats", type=int, default=200)
    p.add_argument("--big-resolution", type=int, default=4, help="built-in face resolution for the auto-rig figures")
    p.add_argument("--dense", action="store_true", help="only the dense 468-point transform (module docstring)")
    p.add_argument("--rounds", type=int, default=5, help="--dense: alternated rounds of before and now")
    args = p.parse_args(argv)
    if args.dense:
        dense_transform(args.repeats, args.rounds)
        return 0
    layout = get_layout("ibug68")
    rng = np.random.default_rng(0)

    v, f, lm, label = face_for_frames()
    t0 = v[lm]
    s0 = 1.3 * t0 + rng.normal(scale=0.3, size=t0.shape)
    frame = s0 + rng.normal(scale=0.1, size=s0.shape)
    print(f"RBF fit, 68 points (median of {args.repeats}):")
    paper_fit = median_ms(lambda: Retargeter("adaptive_multiquadric", smoothing=0.0).fit(s0, t0), args.repeats)
    ours_fit = median_ms(lambda: Retargeter().fit(s0, t0), args.repeats)
    print(f"  paper (adaptive_multiquadric):           {paper_fit:7.3f} ms")
    print(f"  default ({DEFAULT_KERNEL}, smoothing {DEFAULT_SMOOTHING[3]:g}):     {ours_fit:7.3f} ms  ({ours_fit / paper_fit:.2f}x paper)")

    pts = from_vertex_indices(lm, len(v), layout.name)
    rt = Retargeter().fit(s0, t0)
    print(f"One frame: transform 68 points + skin {len(v)} vertices ({label}, median of {args.repeats}):")
    paper_w = compute_weights("ellipsoid", v, f, pts, layout).matrix()
    dense = compute_weights(DEFAULT_METHOD, v, f, pts, layout)
    dense_matrix = dense.matrix()
    top8 = dense.top_k(8).matrix()
    transform_ms = median_ms(lambda: rt.displacements(frame), args.repeats)
    paper_ms = median_ms(lambda: skin_displacements(paper_w, rt.displacements(frame)), args.repeats)
    dense_ms = median_ms(lambda: skin_displacements(dense_matrix, rt.displacements(frame)), args.repeats)
    top8_ms = median_ms(lambda: skin_displacements(top8, rt.displacements(frame)), args.repeats)
    print(f"  transform only:                          {transform_ms:7.3f} ms")
    print(f"  paper (ellipsoid, 4 influences):         {paper_ms:7.3f} ms")
    print(f"  {DEFAULT_METHOD} dense (68 influences):       {dense_ms:7.3f} ms  ({dense_ms / paper_ms:.2f}x paper)")
    print(f"  {DEFAULT_METHOD} top-8 (shader's layout):     {top8_ms:7.3f} ms  ({top8_ms / paper_ms:.2f}x paper)")

    big = sample_face(resolution=args.big_resolution)
    big_pts = from_vertex_indices(big.landmarks68, len(big.vertices), layout.name)
    print(f"Auto-rig, built-in face at resolution {args.big_resolution:g}: {len(big.vertices)} vertices, 68 points (one run each):")
    base = None
    for method in METHODS:
        t = time.perf_counter()
        compute_weights(method, big.vertices, big.faces, big_pts, layout)
        s = time.perf_counter() - t
        base = base or s
        print(f"  {method:<12} {s:8.2f} s  ({s / base:.1f}x ellipsoid)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
