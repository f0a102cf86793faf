"""The default rig of a large face: its solve, and its download to the page (issue 19).

    python bench/rig.py [--resolution 4] [--rounds 3] [--no-ict]

Solve: the biharmonic rig (the default) of the built-in face at --resolution (4: 132,907
vertices) with 68 ibug68 points, by the sparse Cholesky of `retarget.weights.cholesky`
against the SuperLU path it replaced (`quadratic.constrained_weights` without vertices),
alternated in --rounds so both see the same load; medians [min, max] of wall and process
CPU seconds, the ratio of the medians, and the largest weight difference.

Download: the bytes of `GET .../rig/weights` for that rig in RTSW version 1 (float32) and
version 2 (quantised, what the page reads), raw and gzip-encoded as the server sends it
(level 1), with the time to encode, against float16 weights (no indices) for comparison;
and what the quantisation costs: the largest weight error, and on random poses that move
each feature by 3 % of the face's size (as tests/e2e/test_shader.py does) the largest
vertex error relative to the face's size and the largest turn of a vertex normal. With
../shared present, the ICT benchmark (bench/accuracy.py's scenario, true feature motion,
the biharmonic rig) with the float32, version 2 and float16 weights: error in mm.

Machine load goes with the figures (the rig is CPU-bound: other work on this shared
2-core machine slows both paths alike).
"""

from __future__ import annotations

import argparse
import gzip
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import retarget.weights.biharmonic as biharmonic  # noqa: E402
from bench.stream import machine  # noqa: E402
from retarget.landmarks import from_vertex_indices  # noqa: E402
from retarget.layouts import get_layout  # noqa: E402
from retarget.sample_face import sample_face  # noqa: E402
from retarget.skin import SkinWeights, skin_displacements  # noqa: E402
from retarget.weights.quadratic import constrained_weights  # noqa: E402
from server.wire import weights_binary, weights_from_binary  # noqa: E402

MiB = 2.0**20


def superlu_weights(*args, vertices=None, **kwargs):
    """`constrained_weights` as it was: SuperLU, one factorisation per group."""
    return constrained_weights(*args, **kwargs)


def timed_rig(face, points, layout, old: bool) -> tuple[SkinWeights, float, float]:
    biharmonic.constrained_weights = superlu_weights if old else constrained_weights
    try:
        wall, cpu = time.perf_counter(), time.process_time()
        rig = biharmonic.biharmonic_weights(face.vertices, face.faces, points, layout)
        return rig, time.perf_counter() - wall, time.process_time() - cpu
    finally:
        biharmonic.constrained_weights = constrained_weights


def spread(values) -> str:
    return f"{np.median(values):6.2f} s [{min(values):.2f}, {max(values):.2f}]"


def vertex_normals(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) unit area-weighted vertex normals."""
    p = positions.astype(np.float64)
    n = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
    out = np.zeros_like(p)
    for corner in range(3):
        np.add.at(out, faces[:, corner], n)
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-300)


def float16_rig(rig: SkinWeights) -> SkinWeights:
    return SkinWeights(rig.indices, rig.weights.astype(np.float16).astype(np.float32), rig.n_joints)


def int16_rig(rig: SkinWeights) -> tuple[SkinWeights, bytes]:
    """The rig rounded to 16 bits over a power-of-two step (the first draft of version 2),
    and those 16 bits as two slot-major byte planes."""
    step = 2.0 ** np.ceil(np.log2(np.abs(rig.weights).max() / 32767))
    q = np.round(rig.weights / step).astype(np.int16)
    planes = np.ascontiguousarray(q.T).view(np.uint8).reshape(-1, 2).T.tobytes()
    return SkinWeights(rig.indices, (q * step).astype(np.float32), rig.n_joints), planes


def pose_cost(face, rig: SkinWeights, other: SkinWeights, seeds=(1, 2, 3)) -> tuple[float, float, float]:
    """(largest vertex error / face size, largest and 99.9th-percentile normal turn in
    degrees) of skinning with `other` instead of `rig` over random poses."""
    v = face.vertices.astype(np.float32)
    size = float(np.linalg.norm(v.max(0) - v.min(0)))
    used = np.unique(face.faces)
    a, b = rig.matrix(), other.matrix()
    position, angles = 0.0, []
    for seed in seeds:
        d = (np.random.default_rng(seed).normal(size=(rig.n_joints, 3)) * 0.03 * size).astype(np.float32)
        pa, pb = v + skin_displacements(a, d), v + skin_displacements(b, d)
        position = max(position, float(np.abs(pa - pb).max()) / size)
        na, nb = vertex_normals(pa, face.faces)[used], vertex_normals(pb, face.faces)[used]
        angles.append(np.degrees(np.arccos(np.clip((na * nb).sum(1), -1, 1))))
    angles = np.concatenate(angles)
    return position, float(angles.max()), float(np.percentile(angles, 99.9))


def ict_rows() -> None:
    from bench.accuracy import error_figures, scenario
    from bench.ict import DATA, benchmark_layout, vertex_regions
    from retarget.weights import compute_weights

    if not DATA.exists():
        print("ICT: ../shared/data/ict_face absent, skipped")
        return
    model, _, tgt0, offsets = scenario(0, 24)
    feats = model.feature_vertices()
    layout = benchmark_layout()
    points = from_vertex_indices(feats, len(tgt0), layout.name)
    report, _ = vertex_regions(tgt0, model.faces, feats, layout, model.face_count)
    rig = compute_weights("biharmonic", tgt0, model.faces, points, layout)
    rigs = {"float32 (version 1)": rig, "20-bit (version 2)": weights_from_binary(weights_binary(rig, 2)),
            "float16": float16_rig(rig)}
    d = offsets[:, feats]
    truth = tgt0 + offsets
    base = tgt0 + skin_displacements(rig.matrix(), d)
    print(f"ICT benchmark (seed 0, {len(offsets)} expressions, true feature motion, biharmonic "
          f"rig, {len(tgt0)} vertices): error over the face area, mm")
    for name, r in rigs.items():
        pred = tgt0 + skin_displacements(r.matrix(), d)
        fig = error_figures(pred, truth, tgt0, report)
        off = float(np.abs(pred - base).max()) * 10.0
        print(f"  {name:<20} relative {fig['rel']:.4f}, mean {fig['mean']:.4f}, p95 {fig['p95']:.4f}; "
              f"largest vertex change from float32 {off:.2e} mm")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--resolution", type=int, default=4, help="built-in face resolution (4: 132,907 vertices)")
    p.add_argument("--rounds", type=int, default=3, help="alternated rounds of the new and old solve")
    p.add_argument("--no-ict", action="store_true", help="skip the ICT accuracy rows")
    args = p.parse_args(argv)
    print(f"machine: {machine()}")
    face = sample_face(args.resolution)
    layout = get_layout("ibug68")
    points = from_vertex_indices(face.landmarks68, len(face.vertices), layout.name)
    print(f"biharmonic rig of the built-in face at resolution {args.resolution}: "
          f"{len(face.vertices)} vertices, 68 points, {args.rounds} alternated rounds")
    runs = {"cholesky": [], "superlu": []}
    rigs = {}
    for r in range(args.rounds):
        for name in ("cholesky", "superlu"):
            rig, wall, cpu = timed_rig(face, points, layout, old=name == "superlu")
            runs[name].append((wall, cpu))
            rigs[name] = rig
            print(f"  round {r + 1} {name:<8} wall {wall:6.2f} s, CPU {cpu:6.2f} s", flush=True)
    for name in runs:
        walls, cpus = zip(*runs[name])
        print(f"  {name:<8} wall {spread(walls)}, CPU {spread(cpus)}")
    new, old = (np.median([w for w, _ in runs[k]]) for k in ("cholesky", "superlu"))
    new_cpu, old_cpu = (np.median([c for _, c in runs[k]]) for k in ("cholesky", "superlu"))
    diff = float(np.abs(rigs["cholesky"].dense() - rigs["superlu"].dense()).max())
    print(f"  new / old: wall {new / old:.2f}x ({old / new:.1f} times faster), CPU {new_cpu / old_cpu:.2f}x; "
          f"largest weight difference {diff:.1e}")

    rig = rigs["cholesky"]
    print(f"download of that rig (V {rig.n_vertices}, K {rig.n_influences}, N {rig.n_joints}):")
    t = time.perf_counter()
    v1 = weights_binary(rig, 1)
    v1_s = time.perf_counter() - t
    t = time.perf_counter()
    v2 = weights_binary(rig, 2)
    v2_s = time.perf_counter() - t
    t = time.perf_counter()
    v2_gz = gzip.compress(v2, compresslevel=1, mtime=0)
    gz_s = time.perf_counter() - t
    f16 = rig.weights.astype("<f2").tobytes()
    rig16, planes16 = int16_rig(rig)
    print(f"  RTSW version 1, float32:           {len(v1) / MiB:6.2f} MiB (encode {v1_s:.2f} s)")
    print(f"  float16 weights, no indices:       {len(f16) / MiB:6.2f} MiB, gzip "
          f"{len(gzip.compress(f16, 6, mtime=0)) / MiB:.2f} MiB (not used)")
    print(f"  16-bit planes, no indices:         {len(planes16) / MiB:6.2f} MiB, gzip "
          f"{len(gzip.compress(planes16, 1, mtime=0)) / MiB:.2f} MiB (not used)")
    print(f"  RTSW version 2, 20-bit planes:     {len(v2) / MiB:6.2f} MiB (encode {v2_s:.2f} s)")
    print(f"  RTSW version 2, gzip (as sent):    {len(v2_gz) / MiB:6.2f} MiB (gzip {gz_s:.2f} s); "
          f"{len(v1) / len(v2_gz):.0f} times smaller than version 1")
    quantised = weights_from_binary(v2)
    step = float(np.frombuffer(v2, "<f4", 1, 24)[0])
    for name, other in (("version 2", quantised), ("16-bit", rig16), ("float16", float16_rig(rig))):
        position, angle, p999 = pose_cost(face, rig, other)
        print(f"  cost of {name:<9}: weights off by up to {np.abs(other.weights - rig.weights).max():.1e}"
              + (f" (step {step:.1e})" if name == "version 2" else "")
              + f"; over 3 random poses moving features 3 % of the face's size, vertices off by up to "
              f"{position:.1e} of its size, normals turned by up to {angle:.2f} degrees "
              f"(99.9 % of vertices under {p999:.3f})")
    if not args.no_ict:
        ict_rows()
    print(f"machine at the end: {machine()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
