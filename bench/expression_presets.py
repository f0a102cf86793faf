"""Fit the expression presets the product ships (`retarget/muscles/expression_presets.json`)
on ICT-FaceKit identities: the six universal expressions at several intensities, carried
from a performer identity onto a target identity and solved into contractions by the
muscle IK, exactly as `bench/expressions.py` measures them (on other identities).

    .venv/bin/python -m bench.expression_presets [--pairs 24] [--noise 0.1] [--style 0.5] [--out PATH]

Needs ../shared/data/ict_face; the table carries the ICT-FaceKit MIT notice (it is derived
from the model). Run it again whenever the muscle model or its placement changes.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bench.expressions import TRAIN_SEED, contraction_samples
from bench.ict import load_model
from bench.landmark_offsets import ICT_NOTICE
from retarget.muscles.expressions import PRESETS_FILE, ExpressionRecogniser

FIT_INTENSITIES = (0.3, 0.5, 0.7, 0.85, 1.0)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--pairs", type=int, default=24, help="identity pairs fitted on (default 24)")
    p.add_argument("--noise", type=float, default=0.1,
                   help="tracker noise on half the samples' source points, cm (default 0.1)")
    p.add_argument("--style", type=float, default=0.5,
                   help="recipe variation on the noisy half (default 0.5; see bench.expressions)")
    p.add_argument("--out", type=Path, default=PRESETS_FILE)
    args = p.parse_args(argv)
    model = load_model()
    seeds = list(range(TRAIN_SEED, TRAIN_SEED + args.pairs))
    parts = [contraction_samples(model, seeds[k::2], FIT_INTENSITIES, noise_cm=noise, style=style,
                                 progress=lambda i, n: print(f"\r  pairs solved {i}/{n}", end=""))
             for k, (noise, style) in enumerate(((0.0, 0.0), (args.noise, args.style)))]
    c = np.concatenate([q[0] for q in parts])
    labels = np.concatenate([q[1] for q in parts])
    levels = np.concatenate([q[2] for q in parts])
    recogniser = ExpressionRecogniser.fit(parts[0][3], c, labels, levels)
    table = {"notice": ICT_NOTICE.replace("bench/landmark_offsets.py", "bench/expression_presets.py"),
             "what": "expression presets (full-intensity contraction vectors) and per-DOF spread, fitted "
                     f"on {args.pairs} ICT identity pairs (seeds {seeds[0]}..{seeds[-1]}), intensities "
                     f"{list(FIT_INTENSITIES)}, half with {args.noise} cm source noise and recipe variation {args.style}",
             **recogniser.to_json()}
    args.out.write_text(json.dumps(table, indent=1) + "\n")
    print(f"\nwrote {args.out} ({len(c)} samples)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
