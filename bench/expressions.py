"""Expression recognition from muscle contractions (issue 15, Woodward §10) on ICT
cross-identity performances: performer A shows one of the six universal expressions
(`bench.ict.UNIVERSAL`, ARKit recipes) at an intensity, its 58 feature points drive target
B through the RBF space transform (Dutreve §4), the muscle IK (Woodward §7) solves B's
contractions, and the recogniser names the expression.

Identities are drawn by seed: the presets shipped in `retarget/muscles/expression_presets.json`
are fitted (``bench/expression_presets.py``) on seeds from TRAIN_SEED, the figures here
on seeds from TEST_SEED, so no identity tested was tuned on.

    .venv/bin/python -m bench.expressions [--pairs 12] [--noise 0.1] [--style 0.5]

prints the accuracy per expression and intensity, the confusion matrix, and the same for
the paper's hand-written presets and point distance (t = 1 only) for comparison.
"""

from __future__ import annotations

import argparse

import numpy as np

from bench.ict import UNIVERSAL, benchmark_layout, expression_weights, load_model
from retarget.muscles import place_muscles
from retarget.muscles.expressions import EXPRESSIONS, ExpressionRecogniser, default_recogniser, paper_presets
from retarget.muscles.ik import MuscleIK
from retarget.pipeline import Retargeter

TRAIN_SEED = 1000
TEST_SEED = 0
INTENSITIES = (0.4, 0.7, 1.0)


def contraction_samples(model, seeds, intensities=INTENSITIES, noise_cm: float = 0.0, style: float = 0.0,
                        progress=None):
    """Solved contraction vectors of every (expression, intensity) on identity pairs.

    seeds : one seed per pair (A performer, B target, both drawn from it).
    noise_cm : std of Gaussian noise added to A's expressed feature points (tracker-like).
    style : how differently each sample makes the expression (people differ, §10): every
        shape of the recipe scaled by exp(N(0, style)) and two other shapes mixed in at up
        to style / 2 (0: the recipe exactly).
    Returns (X, D) contractions, (X,) labels, (X,) intensities (0 for neutral), the dof names.
    """
    layout = benchmark_layout()
    fv = model.feature_vertices()
    weights, labels = expression_weights(model.names, 0, np.random.default_rng(0))
    order = [labels.index(e) for e in EXPRESSIONS[1:]]
    weights = weights[order]                                       # (6, 53) in EXPRESSIONS order
    others = [i for i, n in enumerate(model.names) if not n.startswith("eyeLook")]
    rows, names, levels, dofs = [], [], [], None
    for n, seed in enumerate(seeds):
        rng = np.random.default_rng(seed)
        a = model.identity_face(rng.standard_normal(100))
        b = model.identity_face(rng.standard_normal(100))
        muscles = place_muscles(b, model.faces, b[fv], layout)
        dofs = muscles.names
        rt = Retargeter().fit(a[fv], b[fv])
        ik = MuscleIK(muscles, fv)
        shown = [("neutral", 0.0, np.zeros(len(model.names)))]
        shown += [(e, t, w) for e, w in zip(EXPRESSIONS[1:], weights) for t in intensities]
        for label, t, w in shown:
            if style > 0 and label != "neutral":
                w = w * np.exp(rng.normal(0.0, style, w.shape))
                w[rng.choice(others, 2, replace=False)] += rng.uniform(0.0, style / 2, 2)
            offset = model.expression_offsets(t * w[None])[0, fv]   # (58, 3) cm
            source = a[fv] + offset + rng.normal(0.0, noise_cm, offset.shape)
            ik.reset()  # each sample stands alone: no earlier frame to start from
            rows.append(ik.push(rt.displacements(source)))
            names.append(label)
            levels.append(t)
        if progress:
            progress(n + 1, len(seeds))
    return np.asarray(rows), np.asarray(names), np.asarray(levels), dofs


def confusion(recogniser, contractions, labels) -> np.ndarray:
    """(7, 7) counts: rows the expression shown, columns the one recognised."""
    got = recogniser.recognise(contractions).labels
    m = np.zeros((len(EXPRESSIONS), len(EXPRESSIONS)), int)
    for want, have in zip(labels, got):
        m[EXPRESSIONS.index(want), EXPRESSIONS.index(have)] += 1
    return m


def print_report(title: str, recogniser, contractions, labels, levels) -> float:
    got = recogniser.recognise(contractions).labels
    ok = got == labels
    six = labels != "neutral"
    print(f"\n{title}: {100 * ok[six].mean():.1f} % of the six expressions "
          f"({ok[six].sum()}/{six.sum()}), neutral {ok[~six].sum()}/{(~six).sum()}")
    print("intensity " + "".join(f"{e[:9]:>10}" for e in EXPRESSIONS[1:]))
    for t in sorted(set(levels[six])):
        print(f"{t:>9.1f} " + "".join(f"{100 * ok[(labels == e) & (levels == t)].mean():>9.0f}%"
                                      for e in EXPRESSIONS[1:]))
    m = confusion(recogniser, contractions, labels)
    print("confusion (rows shown, columns recognised)")
    print(" " * 10 + "".join(f"{e[:8]:>9}" for e in EXPRESSIONS))
    for e, row in zip(EXPRESSIONS, m):
        print(f"{e[:9]:<10}" + "".join(f"{v:>9d}" for v in row))
    return float(ok[six].mean())


def point_distance(recogniser) -> ExpressionRecogniser:
    """The paper's own rule on the same presets: distance to the full preset only."""
    return ExpressionRecogniser(recogniser.names, recogniser.labels, recogniser.presets,
                                recogniser.scale, t_min=1.0, rest_radius=0.0)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--pairs", type=int, default=12, help="identity pairs tested (default 12)")
    p.add_argument("--noise", type=float, default=0.1, help="tracker noise on the source, cm (default 0.1)")
    p.add_argument("--style", type=float, default=0.5,
                   help="per-sample variation of the expression recipes (default 0.5; see contraction_samples)")
    args = p.parse_args(argv)
    model = load_model()
    seeds = range(TEST_SEED, TEST_SEED + args.pairs)
    for noise, style in ((0.0, 0.0), (args.noise, args.style)):
        c, labels, levels, names = contraction_samples(
            model, seeds, noise_cm=noise, style=style,
            progress=lambda i, n: print(f"\r  pairs solved {i}/{n}", end=""))
        print(f"\n=== {args.pairs} held-out identity pairs, source noise {noise} cm, recipe variation "
              f"{style}; intensities {INTENSITIES}; recipes {sorted(UNIVERSAL)} ===")
        print_report("shipped presets (fitted, segment distance)", default_recogniser(names), c, labels, levels)
        print_report("shipped presets, the paper's point distance", point_distance(default_recogniser(names)),
                     c, labels, levels)
        print_report("the paper's hand-written presets (segment distance)", paper_presets(names), c, labels, levels)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
