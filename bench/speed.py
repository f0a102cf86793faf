"""Speed of the retargeting core on one CPU core.

    python bench/speed.py [--repeats 200] [--big-resolution 4]

Prints medians over repeats:
- fit of the RBF space transform for 68 points (default kernel and Dutreve's);
- one frame (transform of 68 points + skinning of the face) for the default dense
  deformer and its 8-influence truncation (what the GPU shader takes), on the ICT face
  when ../shared is present and on the built-in face otherwise;
- auto-rig of a ~100k-vertex built-in face with 68 points, for every weight method.
Ratios are against the paper's method (adaptive multiquadric, ellipsoid) run in the same
process.
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
from retarget.landmarks import from_vertex_indices  # noqa: E402
from retarget.layouts import get_layout  # noqa: E402
from retarget.pipeline import DEFAULT_KERNEL, DEFAULT_SMOOTHING, Retargeter  # noqa: E402
from retarget.sample_face import sample_face  # noqa: E402
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


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeats", type=int, default=200)
    p.add_argument("--big-resolution", type=int, default=4, help="built-in face resolution for the auto-rig figures")
    args = p.parse_args(argv)
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
