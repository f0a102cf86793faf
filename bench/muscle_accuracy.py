"""Muscle mode against feature-point mode on ICT cross-identity retargeting (issue 15):
identity A's 58 feature points drive identity B (`bench.accuracy.scenario`: the six
universal expressions and random ARKit combinations, truth B with the same weights),
once through B's default rig (feature points as joints) and once through B's muscles
(the feature motion solved into 21 contractions and the jaw, `retarget.muscles.drive`),
clean and with tracker-like noise on the source points. Woodward et al. claim the
muscles absorb noise: the ratio noisy / clean error says whether they do.

    .venv/bin/python -m bench.muscle_accuracy [--seeds 0 1 2] [--random 24] [--noise 0.05 0.1]

Relative error = sum of vertex error lengths / sum of true displacement lengths over the
face area (all expressions, and "six": the universal ones alone); mouth = mean error of the mouth region, mm; jitter = mean frame-to-frame
vertex motion added by the noise on a still face, mm (needs ../shared).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from bench.accuracy import error_figures, scenario
from bench.ict import benchmark_layout, vertex_regions
from retarget.landmarks import from_vertex_indices
from retarget.muscles import place_muscles
from retarget.muscles.drive import MuscleDrive
from retarget.pipeline import Retargeter
from retarget.skin import skin_displacements
from retarget.weights import DEFAULT_METHOD, compute_weights

STILL_FRAMES = 60


def rows_for(seed: int, n_random: int, noises) -> list[dict]:
    model, src0, tgt0, offsets = scenario(seed, n_random)
    feats = model.feature_vertices()
    layout = benchmark_layout()
    points = from_vertex_indices(feats, len(tgt0), layout.name)
    report, _ = vertex_regions(tgt0, model.faces, feats, layout, model.face_count)
    truth = tgt0 + offsets
    s0, s = src0[feats], (src0 + offsets)[:, feats]
    rt = Retargeter().fit(s0, tgt0[feats])
    skin = compute_weights(DEFAULT_METHOD, tgt0, model.faces, points, layout).matrix()
    drive = MuscleDrive(place_muscles(tgt0, model.faces, tgt0[feats], layout), points)
    rng = np.random.default_rng(seed)
    still = np.repeat(s0[None], STILL_FRAMES, axis=0)
    rows = []
    for noise in (0.0, *noises):
        frames = s + rng.normal(0.0, noise, s.shape)
        shaky = still + rng.normal(0.0, noise, still.shape)
        d = rt.displacements(frames)
        drive.reset()
        start = time.perf_counter()
        c = np.stack([drive.contractions(x) for x in d])  # frames apart: each a cold problem
        ik_ms = 1000 * (time.perf_counter() - start) / len(d)
        for mode, pred, jitter in (
                ("points", tgt0 + skin_displacements(skin, d),
                 skin_displacements(skin, rt.displacements(shaky))),
                ("muscles", tgt0 + drive.displacements(c),
                 drive.displacements(drive.contractions(rt.displacements(shaky))))):
            fig = error_figures(pred, truth, tgt0, report)
            six = error_figures(pred[:6], truth[:6], tgt0, report)  # the universal expressions come first
            moved = np.linalg.norm(np.diff(jitter[:, :len(report)], axis=0), axis=2).mean() * 10.0
            rows.append({"seed": seed, "noise": noise, "mode": mode, "rel": fig["rel"], "six": six["rel"], "mean": fig["mean"],
                         "mouth": fig["mouth"], "jitter": moved, "ik_ms": ik_ms if mode == "muscles" else np.nan})
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--random", type=int, default=24, help="random ARKit combinations besides the six (default 24)")
    p.add_argument("--noise", type=float, nargs="+", default=[0.05, 0.1],
                   help="std of the noise on the source points, cm (default 0.05 0.1)")
    args = p.parse_args(argv)
    rows = [r for seed in args.seeds for r in rows_for(seed, args.random, args.noise)]
    print(f"{'noise cm':>8} {'mode':<8} {'rel %':>7} {'six %':>7} {'mean mm':>8} {'mouth mm':>9} {'jitter mm':>10}   (mean of seeds "
          f"{args.seeds})")
    for noise in (0.0, *args.noise):
        for mode in ("points", "muscles"):
            sel = [r for r in rows if r["noise"] == noise and r["mode"] == mode]
            m = {k: np.mean([r[k] for r in sel]) for k in ("rel", "six", "mean", "mouth", "jitter")}
            print(f"{noise:>8.2f} {mode:<8} {100 * m['rel']:>7.1f} {100 * m['six']:>7.1f} {m['mean']:>8.2f} {m['mouth']:>9.2f} {m['jitter']:>10.3f}")
    for noise in args.noise:
        ratio = {mode: np.mean([r["rel"] for r in rows if r["noise"] == noise and r["mode"] == mode])
                 / np.mean([r["rel"] for r in rows if r["noise"] == 0.0 and r["mode"] == mode])
                 for mode in ("points", "muscles")}
        jit = {mode: np.mean([r["jitter"] for r in rows if r["noise"] == noise and r["mode"] == mode])
               for mode in ("points", "muscles")}
        print(f"noise {noise} cm: error grows x{ratio['points']:.2f} with points, x{ratio['muscles']:.2f} with "
              f"muscles; still-face jitter muscles / points = {jit['muscles'] / jit['points']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
