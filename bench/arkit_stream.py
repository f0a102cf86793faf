"""The live half of ARKit's 52 blendshapes (issue 16), in figures:

    python bench/arkit_stream.py [--resolution 1 4] [--frames 2000] [--fps 60]

- bytes a stream frame: ARKit weights (RTAW, and its JSON form) against feature points
  (RTDF) for the layout's points;
- the shapes' download (RTAK, sparse int16) against float32 dense, per face resolution
  (1: the 8,430-vertex sample face; 4: the 132,907-vertex one);
- generation: `arkit_shapes` on each face (the server's job runs the same in a child);
- the server's per-frame cost of a source driven by ARKit: `DemoPlayer.frame` (conditioning,
  transform, `ArkitDrive.weights`, `encode_arkit_weights`) against the same player driven
  by feature points, and `ArkitDrive.weights` (the solve and gains) alone.

Every figure is measured here on the sample face's own demo performance, on this machine
(printed first: a loaded machine inflates the times).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.stream import fmt, machine, stats  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--resolution", type=int, nargs="+", default=[1],
                   help="sample face resolutions (1: 8,430 vertices; 4: 132,907)")
    p.add_argument("--frames", type=int, default=2000)
    p.add_argument("--fps", type=float, default=60.0)
    args = p.parse_args(argv)

    from retarget.arkit import ARKIT_NAMES, ArkitDrive, arkit_shapes
    from retarget.landmarks import landmarks_from_json
    from retarget.sample_face import sample_face
    from server.players import DemoPlayer
    from server.wire import arkit_shapes_binary, encode_arkit_weights, encode_frame, weights_json

    print(f"machine: {machine()}")
    for resolution in args.resolution:
        face = sample_face(resolution)
        points = landmarks_from_json({"vertex_indices": np.asarray(face.landmarks68).tolist()},
                                     face.vertices, face.faces)
        t0 = time.perf_counter()
        shapes = arkit_shapes(face.vertices, face.faces, points, "ibug68")
        made = time.perf_counter() - t0
        t0 = time.perf_counter()
        binary = arkit_shapes_binary(shapes.names, shapes.deltas)
        encoded = time.perf_counter() - t0
        print(f"face resolution {resolution}, {len(face.vertices)} vertices: shapes made in {made:.1f} s; "
              f"download RTAK {len(binary) / 1e6:.2f} MB (encoded in {1e3 * encoded:.0f} ms) against "
              f"{shapes.deltas.nbytes / 1e6:.2f} MB as dense float32")
        if resolution != args.resolution[0]:
            continue

        weights = np.zeros(len(ARKIT_NAMES), np.float32)
        rtaw = encode_arkit_weights(weights, frame_index=0, source_time=0.0)
        rtdf = encode_frame(np.zeros((68, 3)), frame_index=0, source_time=0.0)
        named = json.dumps(weights_json(encode_arkit_weights(np.full(52, 0.123456, np.float32), frame_index=123,
                                                             source_time=12.345), ARKIT_NAMES))
        print(f"bytes a frame, 68 points: feature points (RTDF) {len(rtdf)}, ARKit weights (RTAW) {len(rtaw)}, "
              f"ARKit JSON about {len(named)}; 468 points: RTDF "
              f"{len(encode_frame(np.zeros((468, 3)), frame_index=0, source_time=0.0))}, RTAW {len(rtaw)} "
              f"(+16 either binary way with a head rotation)")

        clock = time.perf_counter_ns
        target = points.positions(face.vertices)
        by_points = DemoPlayer(target, "ibug68", args.fps)
        by_arkit = DemoPlayer(target, "ibug68", args.fps)
        by_arkit.set_drive(ArkitDrive(shapes))
        solve_only = ArkitDrive(shapes)
        parts = {k: np.empty(args.frames) for k in ("points", "arkit", "solve")}
        for i in range(-50, args.frames):  # 50 warm-up frames
            t0 = clock()
            by_points.frame(i % 100000)
            t1 = clock()
            by_arkit.frame(i % 100000)
            t2 = clock()
            d = by_arkit.displacements(i % 100000)
            t3 = clock()
            solve_only.weights(d)
            t4 = clock()
            if i >= 0:
                parts["points"][i] = (t1 - t0) / 1e6
                parts["arkit"][i] = (t2 - t1) / 1e6
                parts["solve"][i] = (t4 - t3) / 1e6
        print(f"server cost a frame of the demo at {args.fps:g} fps ({args.frames} frames):")
        print(f"  {'DemoPlayer.frame, points':<34} {fmt(stats(parts['points']))}")
        print(f"  {'DemoPlayer.frame, ARKit drive':<34} {fmt(stats(parts['arkit']))}")
        print(f"  {'ArkitDrive.weights (solve, gains)':<34} {fmt(stats(parts['solve']))}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
