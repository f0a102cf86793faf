"""Woodward et al.'s Table 1: the 21 virtual muscles, with anatomical names and how each
is placed from the 68 iBUG landmarks (`placement.place_muscles`).

The paper placed its muscles by hand in a C++ tool (§4, Fig. 1) and names them loosely
("labii nasi", "lateral corugator"); here each row keeps the paper's number and name, gives
the anatomical muscle it stands for, and says where its origin (on the skull) and
insertion (in the skin) or its ellipsoid come from. Placement recipes are written for the
subject's left side (iBUG 22-26 brow, 42-47 eye, 54 mouth corner, 35 nose ala, 9-16 jaw
line); the right side uses the mirror points (21-17, 39-36, 48, 31, 7-0). E is the distance
between the two eye centres, the unit every zone is sized in.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["MUSCLE_TABLE", "MuscleRow", "dof_names"]


@dataclass(frozen=True)
class MuscleRow:
    """One line of Table 1.

    numbers : the paper's muscle numbers (left, right) or (n,) for the midline.
    paper_name : the paper's name.
    base : snake_case dof name; paired muscles get ``_left`` / ``_right``.
    anatomy : the anatomical muscle and, for the frontalis, the part.
    kind : "linear" or "sphincter" (the paper's "ellipsoid").
    side : "left-right" (one per side) or "midline".
    placement : how origin/insertion (or centre/axes) are derived from the landmarks.
    action : what contracting it does (the motion the tests check).
    """

    numbers: tuple[int, ...]
    paper_name: str
    base: str
    anatomy: str
    kind: str
    side: str
    placement: str
    action: str


MUSCLE_TABLE: tuple[MuscleRow, ...] = (
    MuscleRow((1, 2), "Zygomatic major", "zygomatic_major", "zygomaticus major", "linear", "left-right",
              "origin: the zygomatic bone, midway between jaw point 15 (1) and the outer eye corner "
              "45 (36), 0.1 E below the lower eyelid; insertion: the mouth corner 54 (48)",
              "pulls the mouth corner up and back (smile)"),
    MuscleRow((3, 4), "Frontalis major", "frontalis_major", "frontalis (central part)", "linear", "left-right",
              "insertion: brow point 23 (20); origin 0.9 E above it, 0.08 E back, on the frontal bone",
              "raises the brow's inner-middle part"),
    MuscleRow((5, 6), "Frontalis secondary", "frontalis_secondary", "frontalis (lateral-central part)", "linear",
              "left-right", "insertion: brow point 24 (19); origin 0.9 E above it, 0.08 E back",
              "raises the middle of the brow"),
    MuscleRow((7, 8), "Orbicularis oculi", "orbicularis_oculi", "orbicularis oculi", "sphincter", "left-right",
              "ellipsoid a quarter of the lid slit above the lower lid (46, 47 / 40, 41), semi-axes "
              "0.55, 0.42, 0.5 E along the face's x, y, z, pulling mostly across the slit (gains "
              "0.25, 1, 0.5)",
              "narrows the eye (squint); negative contraction opens it wide (levator palpebrae)"),
    MuscleRow((9,), "Orbicularis oris", "orbicularis_oris", "orbicularis oris", "sphincter", "midline",
              "ellipsoid centred one half mouth width in front of the lips (mean of 48-67), semi-axes "
              "1.7 half mouth widths across, 1.8 half lip heights (51-57) up, 2.2 half widths deep",
              "purses the lips: corners in, lips together and forward"),
    MuscleRow((10, 11), "Frontalis outer", "frontalis_outer", "frontalis (lateral part)", "linear", "left-right",
              "insertion: the brow between 25 and 26 (18 and 17); origin 0.9 E above it, 0.08 E back",
              "raises the brow's tail"),
    MuscleRow((12, 13), "Frontalis inner", "frontalis_inner", "frontalis (medial part)", "linear", "left-right",
              "insertion: the brow's head 22 (21); origin 0.9 E above it, 0.08 E back",
              "raises the inner brow (sadness, surprise, fear)"),
    MuscleRow((14, 15), "Lateral corugator", "corrugator_supercilii", "corrugator supercilii", "linear",
              "left-right",
              "origin: the medial brow ridge, 0.08 E beside the nasal bridge top 27, 0.15 E up, "
              "0.05 E out (a lowered brow bunches forward); insertion: brow point 24 (19); its "
              "40-degree range takes in the brow from its head 22 (21) to 25 (18) and leaves the "
              "upper eyelid out",
              "draws the brow down and toward the midline (frown; lowers the brows in fear, anger)"),
    MuscleRow((16, 17), "Inner labii nasi", "levator_labii_superioris_alaeque_nasi",
              "levator labii superioris alaeque nasi", "linear", "left-right",
              "origin: the maxilla's frontal process, between the inner eye corner 42 (39) and the "
              "nasal bridge 28, 0.1 E up, 0.05 E out; insertion: the nose ala 35 (31)",
              "raises the nose flange and the upper lip beside it (sneer, disgust, fear)"),
    MuscleRow((18, 19), "Labii nasi", "levator_labii_superioris", "levator labii superioris", "linear",
              "left-right",
              "origin: the infraorbital margin, 0.15 E below the lower eyelid (46, 47 / 40, 41), 0.05 E out; "
              "insertion: the upper lip between 52 and 53 (50 and 49)",
              "raises the upper lip"),
    MuscleRow((20, 21), "Angular depressor", "depressor_anguli_oris", "depressor anguli oris", "linear",
              "left-right",
              "origin: the mandible straight below the mouth corner, at the height of jaw points 10-11 "
              "(6-5), 0.1 E outward; insertion: the mouth corner 54 (48)",
              "lowers the mouth corner (sadness)"),
)
"""The paper's Table 1 in its order: muscles 1-21 (each pair left then right)."""


def dof_names() -> tuple[str, ...]:
    """The 22 dof names: the 21 muscles in Table 1's order, then ``"jaw"``."""
    names = []
    for row in MUSCLE_TABLE:
        names.extend([row.base] if row.side == "midline" else [f"{row.base}_left", f"{row.base}_right"])
    return (*names, "jaw")
