"""Accuracy of cross-identity retargeting on the ICT face model, for every deformer.

    python bench/accuracy.py [--seed 0] [--random 24] [--methods ...] [--kernel linear]
    python bench/accuracy.py --dense-only --seed 0     (the 468-point rows alone)

Source identity A and target identity B are random ICT identities; expressions are the six
universal ones plus random sparse ARKit combinations; the truth is B with the same
expression weights. Source conditions: "same" (A's 3D points in the target's frame),
"foreign" (A under another scale, rotation and translation), "2d" (A's points as pixels
of a frontal camera, z = 0). The first row, "paper", is Dutreve 2008 as written: adaptive
multiquadric transfer and ellipsoid LBS. "true" rows feed the deformer the true target
feature motion, to separate deformer error from transfer error. --dense adds the
dense-source rows (`dense_rows`): MediaPipe's 468 points found on A and B with no clicks;
their "as A's" row drives B's found points by A's displacements unchanged, which ICT's
truth (the same expression offsets on every identity) moves by, to separate what the
similarity transform's scale and turn cost from what the placement costs (seeds 0/1/2,
"468 found": similarity 21.5/18.9/21.4 %, as A's 19.7/15.5/16.8; the similarity's scale
0.995/1.061/1.099 and turn 4.0/3.6/0.7 degrees).

Figures: relative error = sum of per-vertex error norms / sum of true displacement norms
over the face area (ICT vertices [0, 9409)) and all expressions; mean and 95th-percentile
per-vertex error in mm; mean error per region in mm; lip leakage = share of upper-lip
vertices taking more than 5% weight from lower-lip or jaw points (and the reverse).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.ict import (DATA, REPORT_REGIONS, benchmark_layout, expression_weights,  # noqa: E402
                       foreign_frame, image_points, load_model, vertex_regions)
from bench.timing import median_ms  # noqa: E402
from retarget.landmarks import from_vertex_indices  # noqa: E402
from retarget.layouts import get_layout  # noqa: E402
from retarget.pipeline import DEFAULT_KERNEL, DEFAULT_SMOOTHING, Retargeter  # noqa: E402
from retarget.rbf import SimilarityTransform  # noqa: E402
from retarget.skin import skin_displacements  # noqa: E402
from retarget.weights import DEFAULT_METHOD, METHODS, compute_weights  # noqa: E402

CONDITIONS = ("same", "foreign", "2d")


def lip_leakage(dense: np.ndarray, layout_region: np.ndarray, regions: np.ndarray) -> tuple[float, float]:
    """Shares of upper-lip vertices with > 5% weight on lower-lip or jaw features, and of
    lower-lip vertices with > 5% on upper-lip features."""
    w = np.abs(dense[: len(layout_region)])
    upper_v, lower_v = layout_region == "upper_lip", layout_region == "lower_lip"
    from_lower = w[:, np.isin(regions, ("lower_lip", "jaw"))].sum(1)
    from_upper = w[:, regions == "upper_lip"].sum(1)
    return float((from_lower[upper_v] > 0.05).mean()), float((from_upper[lower_v] > 0.05).mean())



def error_figures(pred: np.ndarray, truth: np.ndarray, rest: np.ndarray, report: np.ndarray) -> dict:
    """Figures over the face area for (X, V, 3) predicted and true vertices, in mm."""
    n = len(report)
    err = np.linalg.norm(pred[:, :n] - truth[:, :n], axis=2) * 10.0
    true = np.linalg.norm(truth[:, :n] - rest[:n], axis=2) * 10.0
    out = {"rel": err.sum() / true.sum(), "mean": err.mean(), "p95": np.percentile(err, 95)}
    for r in REPORT_REGIONS:
        m = report == r
        out[r] = err[:, m].mean() if m.any() else float("nan")
    return out


def scenario(seed: int, n_random: int):
    """(model, A's neutral (V, 3), B's neutral (V, 3), expression offsets (X, V, 3)) for a
    seed: identities A and B and the expressions, cm."""
    model = load_model()
    rng = np.random.default_rng(seed)
    a, b = rng.standard_normal(100), rng.standard_normal(100)
    weights_x, _ = expression_weights(model.names, n_random, rng)
    return model, model.identity_face(a), model.identity_face(b), model.expression_offsets(weights_x)


def run(seed: int, n_random: int, methods: list[str], kernel: str, smoothing: float | None,
        true_motion: bool) -> list[dict]:
    model, src0, tgt0, offsets = scenario(seed, n_random)
    feats = model.feature_vertices()
    layout = benchmark_layout()
    points = from_vertex_indices(feats, len(tgt0), layout.name)
    report, layout_region = vertex_regions(tgt0, model.faces, feats, layout, model.face_count)
    truth = tgt0 + offsets
    s0, s = src0[feats], (src0 + offsets)[:, feats]
    sources = {
        "same": (s0, s),
        "foreign": (foreign_frame(s0), foreign_frame(s)),
        "2d": (image_points(s0), image_points(s)),
    }
    rows = []
    setups = [("paper", "ellipsoid", "adaptive_multiquadric", 0.0)] + [(m, m, kernel, smoothing) for m in methods]
    for label, method, kern, smooth in setups:
        t = time.perf_counter()
        sk = compute_weights(method, tgt0, model.faces, points, layout)
        rig_s = time.perf_counter() - t
        dense = sk.dense()
        matrix = sk.matrix()
        leak = lip_leakage(dense, layout_region, np.asarray(layout.regions))
        conds = list(CONDITIONS) + (["true"] if true_motion else [])
        for cond in conds:
            fit_ms = frame_ms = float("nan")
            if cond == "true":
                d = offsets[:, feats]
            else:
                src_neutral, src_frames = sources[cond]
                rt = Retargeter(kern, smoothing=smooth).fit(src_neutral, tgt0[feats])
                d = rt.displacements(src_frames)
                fit_ms = median_ms(lambda: Retargeter(kern, smoothing=smooth).fit(src_neutral, tgt0[feats]), 50)
                frame_ms = median_ms(lambda: skin_displacements(matrix, rt.displacements(src_frames[0])), 50)
            pred = tgt0 + skin_displacements(matrix, d)
            fig = error_figures(pred, truth, tgt0, report)
            rows.append({"setup": label, "kernel": kern if cond != "true" else "-", "condition": cond,
                         "rig_s": rig_s, "fit_ms": fit_ms, "frame_ms": frame_ms,
                         "leak_upper": leak[0], "leak_lower": leak[1], **fig})
    return rows


def dense_rows(seed: int, n_random: int, method: str, kernel: str, smoothing: float | None) -> list[dict]:
    """The dense-source scenario (issue 14, section 3): all 468 face-mesh points, found with
    no clicks (`find_face_mesh`) on A's and on B's neutral, drive B from A's surface points.

    Rows: "found" (each identity's own placement: what a user gets), "matched" (B's points
    at A's surface locations, which ICT's shared topology allows: placement made perfectly
    consistent, so the row separates the placement's cost from the transfer's), "true"
    (B's own points' true motion: the deformer's floor with 468 joints). The "found" row
    also carries how far apart the two placements are: B's points carried onto A's surface
    through ICT's shared topology against A's own (mm, mean and p95), the disagreement
    that separates "found" from "matched". B is rigged with the ``mediapipe468`` layout,
    as the app and `retarget landmarks` label the points they find.
    """
    from retarget.facemesh.placement import find_face_mesh
    from retarget.facemesh.tracker import FaceMeshTracker
    from retarget.mesh import mesh_from_arrays

    model, src0, tgt0, offsets = scenario(seed, n_random)
    layout = get_layout("mediapipe468")
    report, _ = vertex_regions(tgt0, model.faces, model.feature_vertices(), benchmark_layout(), model.face_count)
    truth = tgt0 + offsets
    tracker = FaceMeshTracker()
    on_a = find_face_mesh(mesh_from_arrays(src0, model.faces), tracker).points
    on_b = find_face_mesh(mesh_from_arrays(tgt0, model.faces), tracker).points
    s0, s = on_a.positions(src0), on_a.positions(src0 + offsets)
    # (468,) mm: the same face-mesh point placed on A and on B, compared on A's surface
    apart = np.linalg.norm(on_b.positions(src0) - s0, axis=1) * 10.0
    rows = []
    for label, target in (("found", on_b), ("matched", on_a)):
        t = time.perf_counter()
        matrix = compute_weights(method, tgt0, model.faces, target, layout).matrix()
        rig_s = time.perf_counter() - t
        t0 = target.positions(tgt0)
        rt = Retargeter(kernel, smoothing=smoothing).fit(s0, t0)
        frame_ms = median_ms(lambda: skin_displacements(matrix, rt.displacements(s[0])), 50)
        transfer_ms = median_ms(lambda: rt.displacements(s[0]), 200)
        pred = tgt0 + skin_displacements(matrix, rt.displacements(s))
        # the pipeline's default for a dense 3D source is the similarity transform
        shown = "similarity" if isinstance(rt.transform_, SimilarityTransform) else kernel
        rows.append({"setup": f"468 {label}", "kernel": shown, "condition": "same", "rig_s": rig_s,
                     "fit_ms": median_ms(lambda: Retargeter(kernel, smoothing=smoothing).fit(s0, t0), 20),
                     "frame_ms": frame_ms, "transfer_ms": transfer_ms,
                     "leak_upper": float("nan"), "leak_lower": float("nan"),
                     **error_figures(pred, truth, tgt0, report)})
        if label == "found":
            rows[-1].update(apart_mean=float(apart.mean()), apart_p95=float(np.percentile(apart, 95)))
            pred = tgt0 + skin_displacements(matrix, target.positions(truth) - t0)
            rows.append({**rows[-1], "kernel": "-", "condition": "true", "fit_ms": float("nan"),
                         "frame_ms": float("nan"), "transfer_ms": float("nan"),
                         **error_figures(pred, truth, tgt0, report)})
            # What the space transform costs against this truth: ICT's expression offsets
            # are the same on every identity, so A's displacements carried over unscaled and
            # unturned are what the truth moves by, where the similarity scales them by the
            # faces' size ratio and turns them by their shapes' relative turn.
            pred = tgt0 + skin_displacements(matrix, s - s0)
            rows.append({**rows[-1], "condition": "as A's", **error_figures(pred, truth, tgt0, report)})
    return rows


def print_rows(rows: list[dict]) -> None:
    head = (f"{'setup':<12}{'kernel':<22}{'cond':<8}{'rel%':>6}{'mean':>7}{'p95':>7}"
            + "".join(f"{r:>7}" for r in REPORT_REGIONS) + f"{'leakU%':>8}{'leakL%':>8}{'rig s':>7}{'fit ms':>8}{'frame ms':>9}")
    print(head)
    print("-" * len(head))
    for r in rows:
        print(f"{r['setup']:<12}{r['kernel']:<22}{r['condition']:<8}{100 * r['rel']:>6.1f}"
              f"{r['mean']:>7.2f}{r['p95']:>7.2f}" + "".join(f"{r[g]:>7.2f}" for g in REPORT_REGIONS)
              + f"{100 * r['leak_upper']:>8.1f}{100 * r['leak_lower']:>8.1f}{r['rig_s']:>7.2f}"
              + f"{r['fit_ms']:>8.3f}{r['frame_ms']:>9.3f}")
    for r in rows:
        if "transfer_ms" in r and np.isfinite(r["transfer_ms"]):
            print(f"{r['setup']}: the space transform alone (the server's per-frame work; the browser "
                  f"skins): {r['transfer_ms']:.3f} ms a frame")
        if r["condition"] == "as A's":
            print(f"{r['setup']}, as A's: A's displacements unscaled and unturned (ICT's expression "
                  f"offsets are the same on every identity), not a transform a product can use")
        if "apart_mean" in r and r["condition"] == "same":
            print(f"{r['setup']}: A's and B's placements of the same point, compared on A's surface: "
                  f"{r['apart_mean']:.2f} mm apart (p95 {r['apart_p95']:.2f})")
    print("errors in mm over the ICT face area; rel% = sum |error| / sum |true displacement|;\n"
          "rig s: weights for the 11k-vertex face; fit ms: the space transform; frame ms: transform\n"
          "+ skinning of one frame (medians of 50; run bench/speed.py on an idle core for speed figures)")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--random", type=int, default=24, help="random sparse expressions besides the six universal ones")
    p.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    p.add_argument("--kernel", default=DEFAULT_KERNEL)
    p.add_argument("--smoothing", type=float, default=None, help="default: the pipeline's per-dimension default")
    p.add_argument("--no-true", action="store_true", help="skip the true-feature-motion rows")
    p.add_argument("--dense", action="store_true",
                   help="also the dense-source rows: 468 face-mesh points found on A and B (deformer: --dense-method)")
    p.add_argument("--dense-method", default=DEFAULT_METHOD, choices=list(METHODS))
    p.add_argument("--dense-only", action="store_true", help="only the dense-source rows (implies --dense)")
    args = p.parse_args(argv)
    if not DATA.exists():
        print(f"ICT data not found at {DATA}", file=sys.stderr)
        return 2
    args.dense |= args.dense_only
    rows = [] if args.dense_only else run(args.seed, args.random, args.methods, args.kernel, args.smoothing,
                                          not args.no_true)
    print(f"ICT cross-identity retargeting, seed {args.seed}, {6 + args.random} expressions, "
          f"58 feature points; transfer: kernel {args.kernel!r}, smoothing "
          f"{args.smoothing if args.smoothing is not None else DEFAULT_SMOOTHING} "
          f"(paper row: adaptive_multiquadric, 0); default deformer {DEFAULT_METHOD!r}")
    if args.dense:
        rows += dense_rows(args.seed, args.random, args.dense_method, args.kernel, args.smoothing)
    print_rows(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
