"""Expression recognition from muscle contractions (Woodward et al. §10).

The paper recognises an expression by the Euclidean distance from the solved contraction
vector to a preset vector per expression, followed over time (its Fig. 12: the curve that
dips is the expression shown). It failed on fear and confused disgust with anger. Two
changes keep the method explainable and make it reliable:

- **Distances are normalised per DOF** (divided by the spread that DOF shows within an
  expression, pooled over the seven), so a jaw in radians and a brow muscle that barely
  moves weigh what their evidence is worth: a diagonal Mahalanobis distance.
- **An expression is a segment, not a point**: the preset is the full expression p_e and a
  face shows it at some intensity t, so the distance is to the segment {t p_e : t in
  [t_min, 1]} (the paper's point distance is the case t = 1). A faint smile is then near
  the happiness segment instead of nearer neutral or another full expression.
- **Neutral is a ball, not a point**: a still face read through a noisy tracker solves to
  small contractions, biased positive by the limits, that lean toward some preset; the
  neutral distance is max(0, |c| - r), r fitted with the presets.

Presets are either written by hand as muscle recipes (`paper_presets`, the paper's way) or
fitted to contraction vectors of known expressions (`ExpressionRecogniser.fit`: per
expression the least-squares direction through the rest pose and the pooled per-DOF
spread). `retarget/muscles/expression_presets.json` holds the fitted ones the product uses
(made by ``bench/expression_presets.py``).

Shapes: D DOFs (the model's ``names``), E expressions (E = 7 with neutral), F frames.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from retarget.errors import RetargetError

__all__ = ["EXPRESSIONS", "ExpressionRecogniser", "Recognition", "default_recogniser", "paper_presets"]

EXPRESSIONS = ("neutral", "happiness", "sadness", "surprise", "fear", "anger", "disgust")
"""The six universal expressions (Ekman) and neutral, in the order every array uses."""

PRESETS_FILE = Path(__file__).with_name("expression_presets.json")

_T_MIN = 0.25  # the faintest intensity that still counts as the expression (of the preset)

# The paper's way: each expression as the muscles that make it (FACS action units mapped
# onto the 21 muscles and the jaw), contraction values by hand (the jaw in radians). Names are Table 1's dofs
# without the side; a recipe applies to both sides.
_RECIPES = {
    "happiness": {"zygomatic_major": 0.8, "orbicularis_oculi": 0.3},
    "sadness": {"frontalis_inner": 0.6, "corrugator_supercilii": 0.3, "depressor_anguli_oris": 0.7},
    "surprise": {"frontalis_inner": 0.7, "frontalis_major": 0.7, "frontalis_secondary": 0.7,
                 "frontalis_outer": 0.7, "orbicularis_oculi": -0.5, "jaw": 0.25},
    "fear": {"frontalis_inner": 0.6, "corrugator_supercilii": 0.5, "orbicularis_oculi": -0.6,
             "depressor_anguli_oris": 0.4, "levator_labii_superioris_alaeque_nasi": 0.3, "jaw": 0.1},
    "anger": {"corrugator_supercilii": 0.9, "orbicularis_oculi": 0.4, "orbicularis_oris": 0.5},
    "disgust": {"levator_labii_superioris_alaeque_nasi": 0.9, "levator_labii_superioris": 0.6,
                "corrugator_supercilii": 0.4, "orbicularis_oculi": 0.3},
}


@dataclass(frozen=True)
class Recognition:
    """Per-frame readout.

    labels : (F,) str, the nearest expression.
    distances : (F, E) float64 normalised distances to each expression (EXPRESSIONS order
        of the recogniser's ``labels``).
    confidence : (F,) float64 in [0, 1]: (d2 - d1) / (d2 + d1) for the nearest distance d1
        and the next d2; 0 when two expressions are equally near.
    """

    labels: np.ndarray
    distances: np.ndarray
    confidence: np.ndarray


@dataclass(frozen=True, eq=False)
class ExpressionRecogniser:
    """Nearest expression by normalised distance to expression segments.

    names : (D,) the contraction vector's DOF names (a `MuscleFace`'s ``names``).
    labels : (E,) expression names, ``"neutral"`` first.
    presets : (E, D) float64 full-intensity contraction vectors (the neutral row is zeros).
    scale : (D,) float64 > 0, each DOF's spread (contraction units; radians for the jaw).
    t_min : float, the faintest intensity of an expression, as a fraction of its preset.
    rest_radius : float >= 0, the neutral ball's radius (scaled units).
    """

    names: tuple[str, ...]
    labels: tuple[str, ...]
    presets: np.ndarray
    scale: np.ndarray
    t_min: float = _T_MIN
    rest_radius: float = 0.0

    def __post_init__(self) -> None:
        p, s = np.asarray(self.presets, float), np.asarray(self.scale, float)
        if p.shape != (len(self.labels), len(self.names)) or s.shape != (len(self.names),):
            raise RetargetError(f"presets must be ({len(self.labels)}, {len(self.names)}) and scale "
                                f"({len(self.names)},); got {p.shape} and {s.shape}")
        if not (np.isfinite(p).all() and np.isfinite(s).all() and (s > 0).all()):
            raise RetargetError("presets must be finite and every scale positive")
        object.__setattr__(self, "presets", p)
        object.__setattr__(self, "scale", s)

    def distances(self, contractions) -> np.ndarray:
        """(..., D) contraction vectors -> (..., E) normalised distances to each expression.

        Neutral: the distance to the neutral ball round the rest pose. Any other: to the segment from t_min p_e to
        p_e in the scaled space (the clamp of the projection onto the preset's ray).
        """
        c = np.asarray(contractions, float)
        if c.shape[-1] != len(self.names):
            raise RetargetError(f"contraction vectors must have {len(self.names)} values; got {c.shape}")
        x = c / self.scale                                      # (..., D)
        p = self.presets / self.scale                           # (E, D)
        norm2 = np.einsum("ed,ed->e", p, p)
        active = norm2 > 0
        t = np.where(active, x @ p.T / np.where(active, norm2, 1.0), 0.0)  # (..., E)
        t = np.where(active, np.clip(t, self.t_min, 1.0), 0.0)
        closest = t[..., :, None] * p                            # (..., E, D)
        d = np.linalg.norm(x[..., None, :] - closest, axis=-1)
        return np.where(active, d, np.maximum(d - self.rest_radius, 0.0))

    def recognise(self, contractions) -> Recognition:
        """(F, D) or (D,) contraction vectors -> the nearest expression per frame."""
        d = np.atleast_2d(self.distances(contractions))
        order = np.argsort(d, axis=1)
        d1 = np.take_along_axis(d, order[:, :1], 1)[:, 0]
        d2 = np.take_along_axis(d, order[:, 1:2], 1)[:, 0]
        confidence = np.where(d1 + d2 > 0, (d2 - d1) / np.maximum(d1 + d2, 1e-12), 0.0)
        return Recognition(np.asarray(self.labels)[order[:, 0]], d, confidence)

    @classmethod
    def fit(cls, names, contractions, labels, intensities) -> "ExpressionRecogniser":
        """Presets fitted to contraction vectors of known expressions.

        contractions : (X, D) solved contraction vectors; labels : (X,) expression names
        (neutral samples too); intensities : (X,) the intensity each was made at (1 = full).
        Each preset is the least-squares direction through the rest pose,
        p_e = sum t_i c_i / sum t_i^2; the scale is the per-DOF RMS of the samples about
        their own segment point t_i p_e, pooled over expressions (neutral samples about 0);
        the neutral ball's radius is the one that recognises the samples best.
        """
        c = np.asarray(contractions, float)
        lab = np.asarray(labels)
        t = np.asarray(intensities, float)
        if c.ndim != 2 or c.shape[1] != len(names) or len(lab) != len(c) or len(t) != len(c):
            raise RetargetError("contractions must be (X, D) with one label and intensity each")
        missing = [e for e in EXPRESSIONS if not (lab == e).any()]
        if missing:
            raise RetargetError(f"no samples of {', '.join(missing)}")
        presets = np.zeros((len(EXPRESSIONS), len(names)))
        fitted = np.zeros_like(c)
        for k, e in enumerate(EXPRESSIONS):
            m = lab == e
            if e != "neutral":
                presets[k] = t[m] @ c[m] / max(float(t[m] @ t[m]), 1e-12)
                fitted[m] = t[m, None] * presets[k]
        residual = c - fitted
        scale = np.sqrt(np.mean(residual ** 2, axis=0))
        # a DOF no sample moves keeps a floor, so it neither divides by zero nor dominates
        scale = np.maximum(scale, 1e-3 * max(float(scale.max()), 1e-12) + 1e-9)
        # the neutral ball: of radii that hold a share of the neutral samples, the one that
        # recognises the samples best (too small and noisy rest reads as an expression, too
        # large and faint expressions read as rest)
        rest = np.linalg.norm(c[lab == "neutral"] / scale, axis=1)
        fits = [cls(tuple(names), EXPRESSIONS, presets, scale, rest_radius=float(r))
                for r in np.percentile(rest, np.arange(0, 101, 5))]
        return max(fits, key=lambda f: (f.recognise(c).labels == lab).mean())

    def to_json(self) -> dict:
        return {"names": list(self.names), "labels": list(self.labels), "t_min": self.t_min,
                "rest_radius": round(self.rest_radius, 6),
                "presets": np.round(self.presets, 6).tolist(), "scale": np.round(self.scale, 8).tolist()}

    @classmethod
    def from_json(cls, data: dict) -> "ExpressionRecogniser":
        try:
            return cls(tuple(data["names"]), tuple(data["labels"]), np.asarray(data["presets"], float),
                       np.asarray(data["scale"], float), float(data.get("t_min", _T_MIN)),
                       float(data.get("rest_radius", 0.0)))
        except (KeyError, TypeError, ValueError) as exc:
            raise RetargetError(f"not an expression recogniser: {exc}") from None


def paper_presets(names) -> ExpressionRecogniser:
    """The paper's recogniser: hand-written muscle recipes (`_RECIPES`), unit scale."""
    names = tuple(names)
    presets = np.zeros((len(EXPRESSIONS), len(names)))
    for k, e in enumerate(EXPRESSIONS[1:], start=1):
        for base, value in _RECIPES[e].items():
            hits = [i for i, n in enumerate(names) if n in (base, f"{base}_left", f"{base}_right")]
            if not hits:
                raise RetargetError(f"no DOF named {base} for the {e} preset")
            presets[k, hits] = value
    return ExpressionRecogniser(names, EXPRESSIONS, presets, np.ones(len(names)))


def default_recogniser(names) -> ExpressionRecogniser:
    """The recogniser the product uses: the fitted presets shipped with the package
    (`PRESETS_FILE`), or the paper's hand-written ones where no fitted file matches `names`."""
    fitted = _shipped()
    if fitted is not None and fitted.names == tuple(names):
        return fitted
    return paper_presets(names)


@lru_cache(maxsize=1)
def _shipped() -> ExpressionRecogniser | None:
    """The fitted presets file, read once (every muscle-driven player asks for it)."""
    if not PRESETS_FILE.exists():
        return None
    return ExpressionRecogniser.from_json(json.loads(PRESETS_FILE.read_text()))
