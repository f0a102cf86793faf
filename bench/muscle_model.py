"""The muscle model itself (issue 15, Woodward §4): how far its linear form is from the
exact deformation, and how much of each ARKit shape of the ICT face its 21 muscles and jaw
can reproduce.

    python bench/muscle_model.py [--samples 64]

Sections:
    linear form   relative error of `MuscleFace.linearised` (one morph target per dof)
                  against `displacements` over random poses within the limits, on the
                  sample face and the ICT face: all dofs, the jaw alone, the muscles with
                  the jaw closed (0 by construction: the muscles are linear).
    ICT shapes    muscles placed on ICT's neutral (cm) from its 68 points; for each ARKit
                  shape at weight 1 and each universal expression (bench/ict.UNIVERSAL), the
                  bounded least-squares contractions (Gauss-Newton on the exact model, 8
                  steps) at the 68 points, the residual as a share of the shape's motion
                  there, and the three strongest contractions. A shape no muscle makes
                  (mouthShrugLower, the mentalis's) stays near 1.
Needs ../shared/data/ict_face for the second part (skipped without it).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import lsq_linear

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.ict import _LEFT_JAWLINE, _RIGHT_JAWLINE, DATA, UNIVERSAL, load_model  # noqa: E402
from retarget.muscles import place_muscles  # noqa: E402
from retarget.sample_face import sample_face  # noqa: E402

SHAPES = ("browDown", "browInnerUp", "browOuterUp", "noseSneer", "mouthUpperUp", "eyeWide", "eyeSquint",
          "cheekSquint", "mouthSmile", "mouthFrown", "mouthPucker", "mouthStretch", "mouthPress",
          "mouthShrugLower", "jawOpen")


def linear_form_errors(model, n: int, seed: int = 0) -> dict[str, float]:
    """Relative error of the linear form for three kinds of random pose."""
    rng = np.random.default_rng(seed)
    fields = model.linearised().astype(np.float64)
    high = model.limits[:, 1]
    jaw = np.eye(model.n_dof, dtype=bool)[-1]
    out = {}
    for label, mask in (("all dofs", np.ones(model.n_dof, bool)), ("jaw alone", jaw), ("jaw closed", ~jaw)):
        err = ref = 0.0
        for _ in range(n):
            c = np.where(mask, rng.uniform(model.limits[:, 0], high), 0.0)
            exact = model.displacements(c)
            err += float(((np.tensordot(c / high, fields, 1) - exact) ** 2).sum())
            ref += float((exact ** 2).sum())
        out[label] = float(np.sqrt(err / ref))
    return out


def fitted(small, target: np.ndarray, steps: int = 8) -> np.ndarray:
    """(D,) bounded least-squares contractions placing the model's vertices at (K, 3) target
    displacements."""
    low, high = small.limits[:, 0], small.limits[:, 1]
    c = np.zeros(small.n_dof)
    for _ in range(steps):
        j = small.jacobian(c).reshape(-1, small.n_dof)
        r = (target - small.displacements(c)).ravel()
        c = lsq_linear(j, r + j @ c, bounds=(low, high)).x
    return c


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=64)
    args = parser.parse_args()

    face = sample_face()
    sample = place_muscles(face.vertices, face.faces, face.vertices[face.landmarks68])
    print("linear form, relative error (sample face):",
          ", ".join(f"{k} {v:.1%}" for k, v in linear_form_errors(sample, args.samples).items()))
    if not DATA.exists():
        print("ICT data absent: skipping the ICT sections")
        return
    ict = load_model()
    ids = np.array([_RIGHT_JAWLINE[i] if i < 8 else _LEFT_JAWLINE[i - 9] if 8 < i < 17 else ict.landmarks68[i]
                    for i in range(68)])
    model = place_muscles(ict.neutral, ict.faces, ict.neutral[ids])
    print("linear form, relative error (ICT face):   ",
          ", ".join(f"{k} {v:.1%}" for k, v in linear_form_errors(model, args.samples).items()))
    small = model.restricted(ids)
    index = {n: i for i, n in enumerate(ict.names)}

    def offsets(recipe: dict) -> np.ndarray:
        w = np.zeros(len(ict.names))
        for base, value in recipe.items():
            for name in (base, base + "_L", base + "_R"):
                if name in index:
                    w[index[name]] = value
        return ict.expression_offsets(w[None])[0][ids]

    print(f"\n{'ICT shape':16s} residual  strongest contractions")
    for label, recipe in [(s, {s: 1.0}) for s in SHAPES] + list(UNIVERSAL.items()):
        target = offsets(recipe)
        c = fitted(small, target)
        residual = np.linalg.norm(target - small.displacements(c)) / np.linalg.norm(target)
        top = np.argsort(-np.abs(c))[:3]
        print(f"{label:16s} {residual:8.2f}  " + ", ".join(f"{model.names[k]} {c[k]:.2f}" for k in top))


if __name__ == "__main__":
    main()
