"""Feature-point layouts: which facial points a landmark set holds, and what they are.

A `Layout` names N feature points and, for each, its facial region, its side, its
left/right mirror partner, its index in the 68-point iBUG / Multi-PIE order and the
MediaPipe face-mesh vertex that best matches it. The retargeting itself (Dutreve et al.
2008, §4: an RBF space transform trained on N source/target point pairs) only needs the
pairs; the layout is what lets a source of a different kind (a 68-point 2D tracker, a
468-point MediaPipe mesh, an animated 3D face) be read into the same N points, and what
partial retargeting (§4, last paragraph and Figure 3: "transfer only eyes or mouth
motions") selects by region.

Layouts (`LAYOUTS`)
-------------------
``"ibug68"`` (68 points)
    The Multi-PIE / iBUG 300-W order: jaw contour 0-16, brows 17-26, nose 27-35, eyes
    36-47, outer lip 48-59, inner lip 60-67 (table in ``shared/data/ict_face/README.md``).
``"ibug51"`` (51 points)
    ``ibug68`` without the jaw contour 0-16, whose points are image-silhouette points
    rather than fixed anatomical ones (they slide over the face as the head turns).
``"dutreve21"`` (21 points)
    The set of Dutreve et al. 2008, §5: 3 per brow, 2 per eye, 3 on the nose, 8 around
    the mouth. The paper gives the counts, not the exact spots; the iBUG points chosen:

    - brows: outer, middle, inner = 17, 19, 21 (right) and 22, 24, 26 (left);
    - eyes: the upper and lower lids stand for the lid centres. Of the two iBUG points on
      each lid, 38/43 (upper) and 40/47 (lower), the inner ones, are taken: on the ICT
      face model's ``eyeBlink`` they move 8.0 mm and 2.7 mm against 7.9 mm and 1.0 mm for
      the outer ones 37/44 and 41/46;
    - nose: right ala 31, tip 30, left ala 35;
    - mouth, outer lip contour: corners 48, 54, upper lip 49, 51, 53, lower lip 55, 57,
      59, i.e. eight points about 45 degrees apart round the lip ellipse (the cupid's-bow
      peaks 50/52 would bunch the upper points near the midline).
``"dutreve22"`` (22 points)
    ``dutreve21`` and the chin (iBUG 8): the mouth's eight points alone cannot open a jaw,
    so an open mouth only stretched the lower lip; with the chin the jaw follows. One more
    click (the chin is on the midline; *Mirror* places the other side's partners), which is
    why the web app starts new projects in it.
``"mediapipe68"`` (68 points)
    The same 68 points as ``ibug68``, named for reading MediaPipe face-mesh output:
    ``from_mediapipe468(mesh, get_layout("mediapipe68"))`` gives 68 iBUG-ordered points.

``"mediapipe468"`` (468 points)
    Every vertex of MediaPipe's face mesh, in its order, for dense sources (the face mesh
    itself: the webcam, ``track --method markerless``) and targets whose points are found
    with no clicks (`retarget.facemesh.placement`). Its 68 iBUG vertices (the table
    below) keep their iBUG names and regions; the others are named ``<region>_<side>_<k>``
    and take their region from where they lie among the iBUG points on the canonical face
    (`_dense_regions`), with two regions no other layout has, ``cheeks`` and ``forehead``.
    Its ``ibug68`` column is -1 for the 400 vertices that are no iBUG point, so a 68-point
    source cannot drive it (`from_ibug68` says so).

Every point of every layout has the same name, region and side as the ``ibug68`` point at
its ``ibug68`` index, so names mean one thing across layouts.

Sides
-----
"right" and "left" are the **subject's** right and left. With the ICT face model's and
MediaPipe's canonical axes (+y up, +z out of the face, +x toward the subject's left) a
"right" point has x < 0 and a "left" point x > 0; "center" points lie on the midline and
are their own mirror partner. `Layout.mirrored` mirrors a placement about x = 0.

The MediaPipe table
-------------------
`IBUG68_TO_MEDIAPIPE468` gives, for each iBUG point, one vertex of MediaPipe's 468-vertex
face mesh (``mediapipe/modules/face_geometry/data/canonical_face_model.obj``, Apache-2.0;
the 478-point "refined" output appends 10 iris points, which are not used). It is written
for this module after the correspondences in common use (e.g. PeizhiYan/
Mediapipe_2_Dlib_Landmarks, ros4hri/hri_face_detect's table), one vertex per point, and
checked three ways (see ``tests/unit/test_layouts.py``):

1. Left/right: the table maps every iBUG mirror pair to a mirror pair of the canonical
   model (equal y, z and opposite x) and every midline point to a midline vertex
   (x = 0); the anchors 33/263 (outer eye corners), 61/291 (mouth corners), 13/14
   (inner-lip centres) and 152 (chin) sit where MediaPipe documents them.
2. Geometry: fitting the canonical vertices of points 17-67 to the ICT face model's
   landmarks by a similarity transform (scale 1.01: both are in cm) leaves every one
   within 5 mm (RMS 2.7 mm). Where published tables disagree, that fit chose; where
   the fit's nearest vertex breaks with the point's meaning, the meaning won:

   - eye lids 37/38/40/41: the lid-margin ring 160, 158, 153, 144 (what a tracker's lid
     points follow in a blink), though ICT's upper-lid landmarks sit about 1 mm nearer
     the next ring out (29, 28);
   - nose tip 30 -> 4, the most anterior midline vertex: MediaPipe's vertex 1, often
     called the nose tip, is 7 mm lower, toward the columella, and fits ICT's tip worse
     (5.4 mm against 2.7 mm); nose bridge 29 -> 195 (4.5 mm; 5 is 6.3 mm), alar bases
     31/35 -> 98/327 (3.7 mm; 75/305 are 8.1 mm);
   - inner lip 61/63/65/67 -> 81/311/402/178, the inner-lip-line vertices about midway
     between corner and centre (ICT fit 2.4-3.2 mm; the 82/312/317/87 of some tables,
     nearer the centre, 4.9-6.0 mm).
3. The jaw contour 0-16 follows MediaPipe's face-oval ring (127 ... 152 ... 356), the
   silhouette of a frontal face, as iBUG's jaw points do: 0.6-1.3 cm from the ICT jaw
   landmarks in a frontal (x, y) projection. In 3D the oval lies further back than
   ICT's jawline vertices (up to 2.3 cm); treat jaw points from either source as 2D
   silhouette points, or leave them out (``ibug51``).

Every layout's ``mediapipe468`` is this table read at its ``ibug68`` indices, so the table
is the one source of truth.

Custom layouts
--------------
A user's own markers make a layout too (`retarget.custom_layouts.layout_from_spec`, from a
JSON spec: each point's name, region, side, mirror partner, and optionally head-anchor
flag, iBUG point, face-mesh vertex and reference position). Its name is
``custom-<16 hex digits>``, a hash of the spec, registered in a bounded per-process
registry so that `get_layout` resolves it like a built-in name; files that name one carry
its spec (`Layout.spec`), and loading them registers it. A custom point that stands for
no iBUG point / face-mesh vertex has -1 there: a 68-point or face-mesh source cannot drive
it (`from_ibug68`, `from_mediapipe468` say so), and without reference positions
`Layout.reference_points` says the layout has none.
"""

from __future__ import annotations

import difflib
import re
from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass, fields
from functools import lru_cache

import numpy as np
from scipy.spatial import cKDTree

from retarget.errors import RetargetError
from retarget.facemesh.canonical import BROWS, canonical_face
from retarget.similarity import similarity_transform
from retarget.sample_face import sample_face

__all__ = [
    "REGIONS",
    "GROUPS",
    "SIDES",
    "IBUG68_TO_MEDIAPIPE468",
    "Layout",
    "LAYOUTS",
    "get_layout",
    "register_layout",
    "CUSTOM_NAME",
    "from_ibug68",
    "from_mediapipe468",
]

REGIONS: tuple[str, ...] = (
    "brows",
    "eyes",
    "nose",
    "upper_lip",
    "lower_lip",
    "mouth_corners",
    "jaw",
    "cheeks",
    "forehead",
)
"""The fixed region vocabulary; every point belongs to exactly one region. Only the dense
``mediapipe468`` layout has points on the cheeks and forehead."""

GROUPS: dict[str, tuple[str, ...]] = {
    "mouth": ("upper_lip", "lower_lip", "mouth_corners"),
    "upper_face": ("brows", "eyes", "forehead"),
    "lower_face": ("upper_lip", "lower_lip", "mouth_corners", "jaw"),
    "all": REGIONS,
}
"""Named unions of regions, for partial retargeting (Dutreve 2008, Figure 3)."""

SIDES: tuple[str, ...] = ("right", "center", "left")
"""Subject's right (x < 0), midline, subject's left (x > 0)."""

CUSTOM_NAME = re.compile(r"custom-[0-9a-f]{16}")
"""The name of a custom layout: ``custom-`` and 16 hex digits of its spec's hash."""

SPEC_FORMAT = "retarget-layout/1"
"""The ``"format"`` of a layout spec (`Layout.spec`)."""

MAX_REGISTERED = 256
"""Most custom layouts one process keeps registered (least recently used go first): a
server holds every project's, each one re-registered when its files are read again."""

_MEDIAPIPE_MESH_SIZES = (468, 478)  # face mesh; face mesh + 10 iris points ("refined")

# The 68 iBUG points: (name, region, MediaPipe face-mesh vertex). Sides and mirror
# partners follow from the names ("right" <-> "left"); see the module docstring for how
# the MediaPipe column was chosen and checked.
_IBUG68_ROWS: tuple[tuple[str, str, int], ...] = (
    # 0-16 jaw contour, subject's right ear -> chin -> left ear (MediaPipe face oval)
    ("jaw_right_1", "jaw", 127),
    ("jaw_right_2", "jaw", 234),
    ("jaw_right_3", "jaw", 93),
    ("jaw_right_4", "jaw", 132),
    ("jaw_right_5", "jaw", 58),
    ("jaw_right_6", "jaw", 136),
    ("jaw_right_7", "jaw", 149),
    ("jaw_right_8", "jaw", 176),
    ("chin", "jaw", 152),
    ("jaw_left_8", "jaw", 400),
    ("jaw_left_7", "jaw", 378),
    ("jaw_left_6", "jaw", 365),
    ("jaw_left_5", "jaw", 288),
    ("jaw_left_4", "jaw", 361),
    ("jaw_left_3", "jaw", 323),
    ("jaw_left_2", "jaw", 454),
    ("jaw_left_1", "jaw", 356),
    # 17-21 right brow, outer -> inner; 22-26 left brow, inner -> outer
    ("brow_right_outer", "brows", 70),
    ("brow_right_outer_mid", "brows", 63),
    ("brow_right_middle", "brows", 105),
    ("brow_right_inner_mid", "brows", 66),
    ("brow_right_inner", "brows", 107),
    ("brow_left_inner", "brows", 336),
    ("brow_left_inner_mid", "brows", 296),
    ("brow_left_middle", "brows", 334),
    ("brow_left_outer_mid", "brows", 293),
    ("brow_left_outer", "brows", 300),
    # 27-30 nose bridge, top -> tip; 31-35 nose base, right ala -> left ala
    ("nose_root", "nose", 168),
    ("nose_bridge_upper", "nose", 197),
    ("nose_bridge_lower", "nose", 195),
    ("nose_tip", "nose", 4),
    ("nose_ala_right", "nose", 98),
    ("nostril_right", "nose", 97),
    ("nose_base_center", "nose", 2),
    ("nostril_left", "nose", 326),
    ("nose_ala_left", "nose", 327),
    # 36-41 right eye: outer corner, upper lid (outer, inner), inner corner, lower lid
    ("eye_right_outer", "eyes", 33),
    ("eye_right_upper_outer", "eyes", 160),
    ("eye_right_upper_inner", "eyes", 158),
    ("eye_right_inner", "eyes", 133),
    ("eye_right_lower_inner", "eyes", 153),
    ("eye_right_lower_outer", "eyes", 144),
    # 42-47 left eye: inner corner, upper lid (inner, outer), outer corner, lower lid
    ("eye_left_inner", "eyes", 362),
    ("eye_left_upper_inner", "eyes", 385),
    ("eye_left_upper_outer", "eyes", 387),
    ("eye_left_outer", "eyes", 263),
    ("eye_left_lower_outer", "eyes", 373),
    ("eye_left_lower_inner", "eyes", 380),
    # 48-59 outer lip: right corner, upper lip right -> left, left corner, lower left -> right
    ("mouth_corner_right", "mouth_corners", 61),
    ("lip_upper_right", "upper_lip", 39),
    ("lip_upper_right_peak", "upper_lip", 37),
    ("lip_upper_center", "upper_lip", 0),
    ("lip_upper_left_peak", "upper_lip", 267),
    ("lip_upper_left", "upper_lip", 269),
    ("mouth_corner_left", "mouth_corners", 291),
    ("lip_lower_left", "lower_lip", 321),
    ("lip_lower_left_mid", "lower_lip", 314),
    ("lip_lower_center", "lower_lip", 17),
    ("lip_lower_right_mid", "lower_lip", 84),
    ("lip_lower_right", "lower_lip", 91),
    # 60-67 inner lip: right corner, upper right -> left, left corner, lower left -> right
    ("mouth_inner_corner_right", "mouth_corners", 78),
    ("lip_upper_inner_right", "upper_lip", 81),
    ("lip_upper_inner_center", "upper_lip", 13),
    ("lip_upper_inner_left", "upper_lip", 311),
    ("mouth_inner_corner_left", "mouth_corners", 308),
    ("lip_lower_inner_left", "lower_lip", 402),
    ("lip_lower_inner_center", "lower_lip", 14),
    ("lip_lower_inner_right", "lower_lip", 178),
)

IBUG68_TO_MEDIAPIPE468: tuple[int, ...] = tuple(row[2] for row in _IBUG68_ROWS)
"""(68,) for iBUG point i, the MediaPipe face-mesh vertex that stands for it."""


@dataclass(frozen=True)
class Layout:
    """N named feature points with their region, side, mirror partner and source indices.

    name : layout name (a key of `LAYOUTS` for the built-in ones).
    description : one line on what the points are.
    point_names : (N,) unique snake_case names.
    regions : (N,) each point's region, from `REGIONS`.
    sides : (N,) each point's side, from `SIDES` (subject's right = -x).
    mirror : (N,) index of each point's left/right partner; its own index on the midline.
    ibug68 : (N,) index of each point in the 68-point iBUG / Multi-PIE order, -1 for a
        point that has none (the dense layout's cheeks, forehead, ...; `has_ibug68`).
    mediapipe468 : (N,) index of the matching vertex of MediaPipe's 468-vertex face mesh,
        -1 for a custom point that has none (`has_mediapipe468`).
    anchors : indices of the points that move with the head only (head-pose anchors) as
        the user marked them; empty: chosen by name (`retarget.sources.headpose`).
    reference : (N, 3) the points' positions on a reference face (cm, the sample face's
        axes) as the user gave them, or None: then found from ibug68 / mediapipe468.

    Construction checks the structure (lengths, vocabularies, index ranges, that
    `mirror` is an involution) and raises `RetargetError` naming the offending field.
    """

    name: str
    description: str
    point_names: tuple[str, ...]
    regions: tuple[str, ...]
    sides: tuple[str, ...]
    mirror: tuple[int, ...]
    ibug68: tuple[int, ...]
    mediapipe468: tuple[int, ...]
    anchors: tuple[int, ...] = ()
    reference: tuple[tuple[float, float, float], ...] | None = None

    def __post_init__(self) -> None:
        for field in ("point_names", "regions", "sides", "mirror", "ibug68", "mediapipe468"):
            value = getattr(self, field)
            if isinstance(value, (str, bytes)) or not isinstance(value, Iterable):
                raise RetargetError(
                    f"Layout {self.name!r}: {field} must be a sequence, got {value!r}"
                )
            if field in ("mirror", "ibug68", "mediapipe468"):
                value = tuple(int(v) for v in value)
            else:
                value = tuple(str(v) for v in value)
            object.__setattr__(self, field, value)
        n = len(self.point_names)
        if n == 0:
            raise RetargetError(f"Layout {self.name!r}: point_names is empty")
        for field in ("regions", "sides", "mirror", "ibug68", "mediapipe468"):
            if len(getattr(self, field)) != n:
                raise RetargetError(
                    f"Layout {self.name!r}: {field} has {len(getattr(self, field))} entries, "
                    f"point_names has {n}"
                )
        seen: set[str] = set()
        for point in self.point_names:
            if point in seen:
                raise RetargetError(f"Layout {self.name!r}: point name {point!r} is repeated")
            seen.add(point)
        for field, vocabulary in (("regions", REGIONS), ("sides", SIDES)):
            for value in getattr(self, field):
                if value not in vocabulary:
                    raise RetargetError(
                        f"Layout {self.name!r}: {field} value {value!r} is not one of {vocabulary}"
                    )
        for field, low, size in (("mirror", 0, n), ("ibug68", -1, 68), ("mediapipe468", -1, 468)):
            for value in getattr(self, field):
                if not low <= value < size:
                    raise RetargetError(
                        f"Layout {self.name!r}: {field} index {value} is outside [{low}, {size})"
                    )
        for i, j in enumerate(self.mirror):
            if self.mirror[j] != i:
                raise RetargetError(
                    f"Layout {self.name!r}: mirror is not an involution: "
                    f"{i} -> {j} -> {self.mirror[j]}"
                )
        self._check_extras(n)

    def _check_extras(self, n: int) -> None:
        """Normalise and check the optional `anchors` and `reference`."""
        anchors = tuple(int(i) for i in self.anchors)
        if any(not 0 <= i < n for i in anchors) or len(set(anchors)) != len(anchors):
            raise RetargetError(f"Layout {self.name!r}: anchors must be distinct indices in [0, {n})")
        object.__setattr__(self, "anchors", anchors)
        if self.reference is not None:
            ref = _as_float_array(self.reference, "reference")
            if ref.shape != (n, 3) or not np.isfinite(ref).all():
                raise RetargetError(f"Layout {self.name!r}: reference must be {n} finite [x, y, z] "
                                    f"rows, got shape {ref.shape}")
            object.__setattr__(self, "reference", tuple(tuple(float(v) for v in row) for row in ref))

    def __reduce__(self):
        # a custom layout travels as its spec, so a child process (the server's forkserver)
        # that unpickles it registers it and resolves its name like a built-in one
        if self.is_custom:
            return _registered_from_spec, (self.spec(),)
        return Layout, tuple(getattr(self, f.name) for f in fields(self))

    @property
    def is_custom(self) -> bool:
        """Made from a user's spec (`retarget.custom_layouts`), named ``custom-<hash>``."""
        return CUSTOM_NAME.fullmatch(self.name) is not None

    def spec(self) -> dict:
        """The JSON form `retarget.custom_layouts.layout_from_spec` reads back into this
        layout's points (optional keys only where they say something)."""
        points = []
        for i, point in enumerate(self.point_names):
            row = {"name": point, "region": self.regions[i], "side": self.sides[i]}
            if self.mirror[i] != i:
                row["mirror"] = self.point_names[self.mirror[i]]
            if i in self.anchors:
                row["anchor"] = True
            if self.ibug68[i] >= 0:
                row["ibug68"] = self.ibug68[i]
            if self.mediapipe468[i] >= 0:
                row["mediapipe468"] = self.mediapipe468[i]
            if self.reference is not None:
                row["reference"] = list(self.reference[i])
            points.append(row)
        return {"format": SPEC_FORMAT, "description": self.description, "points": points}

    @property
    def n_points(self) -> int:
        """N, the number of points."""
        return len(self.point_names)

    def index(self, name: str) -> int:
        """Position of the point called `name` in this layout."""
        try:
            return self.point_names.index(name)
        except ValueError:
            close = difflib.get_close_matches(str(name), self.point_names, n=4)
            hint = f"; close matches: {', '.join(close)}" if close else ""
            raise RetargetError(
                f"Layout {self.name!r} has no point named {name!r}{hint}"
            ) from None

    def region_mask(self, names: str | Iterable[str]) -> np.ndarray:
        """(N,) bool: the points in any of `names`.

        names : one name or several; each a region (`REGIONS`), a group (`GROUPS`) or a
        point name of this layout. An unknown name raises `RetargetError` naming it.
        """
        if isinstance(names, str):
            names = (names,)
        mask = np.zeros(self.n_points, dtype=bool)
        regions = np.asarray(self.regions)
        for name in names:
            if not isinstance(name, str):
                raise RetargetError(f"Layout {self.name!r}: region_mask takes names, got {name!r}")
            if name in GROUPS:
                mask |= np.isin(regions, GROUPS[name])
            elif name in REGIONS:
                mask |= regions == name
            elif name in self.point_names:
                mask[self.point_names.index(name)] = True
            else:
                vocabulary = list(REGIONS) + list(GROUPS) + list(self.point_names)
                close = difflib.get_close_matches(name, vocabulary, n=4)
                hint = f"; close matches: {', '.join(close)}" if close else ""
                raise RetargetError(
                    f"Layout {self.name!r}: {name!r} is not a region {REGIONS}, a group "
                    f"{tuple(GROUPS)} or a point name{hint}"
                )
        return mask

    @property
    def has_ibug68(self) -> bool:
        """Every point is one of the 68 iBUG points (a 68-point source can drive it)."""
        return min(self.ibug68) >= 0

    @property
    def has_mediapipe468(self) -> bool:
        """Every point is a face-mesh vertex (a face-mesh source can drive it)."""
        return min(self.mediapipe468) >= 0

    def reference_points(self) -> np.ndarray:
        """(N, 3) float64, read-only: this layout's points on the built-in sample face
        (`retarget.sample_face.sample_face`, resolution 1, the default identity), cm, with
        the face's axes (+y up, +z out of the face, +x toward the subject's left).

        The face a user places points by (the landmark picker shows it) and the shape a
        marker tracker identifies its markers against. The face is built once per process
        (about a second), then this is a cached lookup. A custom layout's are the ones its
        spec gives; without them, every point needs an iBUG point or face-mesh vertex, else
        `RetargetError` says so.
        """
        if self.reference is not None:
            out = np.array(self.reference, dtype=np.float64)
            out.flags.writeable = False
            return out
        lost = [p for p, i, m in zip(self.point_names, self.ibug68, self.mediapipe468) if i < 0 and m < 0]
        if lost:
            raise RetargetError(
                f"layout {self.name!r} ({self.description}) has no reference positions: "
                f"{len(lost)} of its points ({', '.join(lost[:4])}{', ...' if len(lost) > 4 else ''}) "
                "stand for no iBUG point or face-mesh vertex; give each point a 'reference' "
                "[x, y, z] in its spec")
        return _reference_points(self.ibug68, self.mediapipe468)

    def mirrored(self, points: np.ndarray) -> np.ndarray:
        """Mirror a placement of this layout's points about the plane x = 0.

        points : (..., N, D) float, D >= 1, x in column 0 (any units).
        Returns (..., N, D) float: row i is row ``mirror[i]`` with x negated, so a
        symmetric face maps (nearly) onto itself.
        """
        p = _as_float_array(points, "points")
        if p.ndim < 2 or p.shape[-2] != self.n_points or p.shape[-1] < 1:
            raise RetargetError(
                f"Layout {self.name!r}: points must have shape (..., {self.n_points}, D), "
                f"got {p.shape}"
            )
        out = p[..., list(self.mirror), :]  # fancy indexing copies
        out[..., 0] *= -1.0
        return out

    def select(
        self,
        names_or_indices: str | int | Iterable[str | int] | np.ndarray,
        name: str | None = None,
    ) -> Layout:
        """A sub-layout holding some of this layout's points, in this layout's order.

        names_or_indices : point names, region or group names (as in `region_mask`) and/or
            point indices into this layout, repeats harmless; or an (N,) bool mask such
            as `region_mask` returns.
        name : the new layout's name; default ``"<this name>_subset"``.
        The mirror indices are remapped into the sub-layout; a point whose partner is not
        selected becomes its own partner. Rows of this layout's arrays that the
        sub-layout keeps: ``[self.index(p) for p in sub.point_names]``.
        """
        if isinstance(names_or_indices, (str, int, np.integer)):
            names_or_indices = (names_or_indices,)
        keep = np.zeros(self.n_points, dtype=bool)
        if isinstance(names_or_indices, np.ndarray) and names_or_indices.dtype == bool:
            if names_or_indices.shape != (self.n_points,):
                raise RetargetError(
                    f"Layout {self.name!r}: a select mask must have shape ({self.n_points},), "
                    f"got {names_or_indices.shape}"
                )
            keep[:] = names_or_indices
            names_or_indices = ()
        for item in names_or_indices:
            if isinstance(item, (bool, np.bool_)):
                raise RetargetError(
                    f"Layout {self.name!r}: select takes names or indices, got {item!r}"
                )
            if isinstance(item, (int, np.integer)):
                if not -self.n_points <= item < self.n_points:
                    raise RetargetError(
                        f"Layout {self.name!r}: point index {item} is outside [0, {self.n_points})"
                    )
                keep[item] = True
            else:
                keep |= self.region_mask(item)
        rows = np.flatnonzero(keep)
        if rows.size == 0:
            raise RetargetError(
                f"Layout {self.name!r}: select({names_or_indices!r}) selects no points"
            )
        new_index = {int(old): new for new, old in enumerate(rows)}
        mirror = tuple(new_index.get(self.mirror[old], new) for new, old in enumerate(rows))
        return Layout(
            name=name if name is not None else f"{self.name}_subset",
            description=f"{len(rows)} of the {self.n_points} points of {self.name!r}",
            point_names=tuple(self.point_names[i] for i in rows),
            regions=tuple(self.regions[i] for i in rows),
            sides=tuple(self.sides[i] for i in rows),
            mirror=mirror,
            ibug68=tuple(self.ibug68[i] for i in rows),
            mediapipe468=tuple(self.mediapipe468[i] for i in rows),
            anchors=tuple(new_index[a] for a in self.anchors if a in new_index),
            reference=None if self.reference is None else tuple(self.reference[i] for i in rows),
        )


@lru_cache(maxsize=None)
def _reference_points(ibug68: tuple[int, ...], mediapipe468: tuple[int, ...]) -> np.ndarray:
    ibug = np.asarray(ibug68)
    out = _sample_landmarks68()[np.maximum(ibug, 0)]
    if (ibug < 0).any():
        # points with no iBUG counterpart: MediaPipe's canonical face carried onto the sample
        # face by the similarity that best fits its inner 51 iBUG points to the sample's
        canonical = canonical_face().vertices
        inner = list(range(17, 68))
        scale, rotation, shift = similarity_transform(canonical[list(np.asarray(IBUG68_TO_MEDIAPIPE468)[inner])],
                                             _sample_landmarks68()[inner])
        placed = scale * canonical[np.asarray(mediapipe468)[ibug < 0]] @ rotation.T + shift
        out[ibug < 0] = placed
    out.flags.writeable = False
    return out



@lru_cache(maxsize=1)
def _sample_landmarks68() -> np.ndarray:
    """(68, 3) float64 the built-in face's landmarks, cm (built once: it takes a while)."""
    face = sample_face(1)
    return face.vertices[face.landmarks68]


def _as_float_array(value, what: str) -> np.ndarray:
    try:
        a = np.asarray(value)
    except Exception as exc:  # ragged lists and the like
        raise RetargetError(f"{what} is not an array: {exc}") from None
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise RetargetError(f"{what} must be numeric, got dtype {a.dtype}")
    if not np.issubdtype(a.dtype, np.floating):
        a = a.astype(np.float64)
    return a


def _side(name: str) -> str:
    tokens = name.split("_")
    return "right" if "right" in tokens else "left" if "left" in tokens else "center"


def _partner_name(name: str) -> str:
    swap = {"right": "left", "left": "right"}
    return "_".join(swap.get(token, token) for token in name.split("_"))


def _partner_index(names: tuple[str, ...], point: str, layout_name: str) -> int:
    partner = _partner_name(point)
    if partner not in names:
        raise RetargetError(f"Layout {layout_name!r}: {point!r} has no mirror partner {partner!r}")
    return names.index(partner)


def _ibug_layout(name: str, description: str, ibug_indices: Iterable[int]) -> Layout:
    """A layout of some iBUG points, everything but the choice read from `_IBUG68_ROWS`."""
    idx = tuple(int(i) for i in ibug_indices)
    names = tuple(_IBUG68_ROWS[i][0] for i in idx)
    return Layout(
        name=name,
        description=description,
        point_names=names,
        regions=tuple(_IBUG68_ROWS[i][1] for i in idx),
        sides=tuple(_side(n) for n in names),
        mirror=tuple(_partner_index(names, n, name) for n in names),
        ibug68=idx,
        mediapipe468=tuple(IBUG68_TO_MEDIAPIPE468[i] for i in idx),
    )


def _dense_layout() -> Layout:
    """All 468 face-mesh vertices (`_dense_regions`): the iBUG ones with their iBUG names and
    regions, the others named ``<region>_<side>_<k>`` (k counts the region's pairs, 0-padded;
    a pair's two points share k); partners from the canonical model's exact symmetry."""
    vertices = canonical_face().vertices
    mirror = cKDTree(vertices).query(vertices * [-1.0, 1.0, 1.0])[1]
    regions = _dense_regions(vertices[:, :2])
    regions = [regions[j] if vertices[i, 0] > 0 else regions[i] for i, j in enumerate(mirror)]
    ibug_of = {v: i for i, v in enumerate(IBUG68_TO_MEDIAPIPE468)}
    names: list[str | None] = [None] * len(vertices)
    counts: dict[str, int] = {}
    for i in range(len(vertices)):
        if i in ibug_of:
            names[i] = _IBUG68_ROWS[ibug_of[i]][0]
        elif names[i] is None:
            k = counts[regions[i]] = counts.get(regions[i], 0) + 1
            if mirror[i] == i:
                names[i] = f"{regions[i]}_center_{k:03d}"
            else:
                right, left = (i, mirror[i]) if vertices[i, 0] < 0 else (mirror[i], i)
                names[right] = f"{regions[i]}_right_{k:03d}"
                names[left] = f"{regions[i]}_left_{k:03d}"
    names_t = tuple(names)
    return Layout(
        name="mediapipe468",
        description="All 468 points of MediaPipe's face mesh: lips, eyes, brows, nose, jaw, cheeks and forehead",
        point_names=names_t,
        regions=tuple(regions),
        sides=tuple(_side(n) for n in names_t),
        mirror=tuple(int(j) for j in mirror),
        ibug68=tuple(ibug_of.get(i, -1) for i in range(len(vertices))),
        mediapipe468=tuple(range(len(vertices))),
    )


def _dense_regions(xy: np.ndarray) -> list[str]:
    """(468,) region of each canonical face-mesh vertex from its frontal position xy (468, 2)
    cm, by where it lies among the iBUG points: the philtrum (under the nose's base, above
    the lip's top, within 30% of the mouth's half-width) and the lip outline grown by 12%
    (above or below the inner-lip line; within 4.5 mm of a corner: the corner), the eye outlines grown by
    45%, within 7.5 mm of a brow point, inside the nose's outline (root to alae); else by
    height: above the eyes the forehead, more than a cm below the mouth the jaw, between
    them the cheeks. The face mesh's eyebrow rings are brows; iBUG points keep their own
    region; a vertex and its mirror image get the same one (their positions mirror
    exactly)."""
    at = lambda *ibug: xy[[IBUG68_TO_MEDIAPIPE468[i] for i in ibug]]  # noqa: E731
    region = np.full(len(xy), "cheeks", dtype=object)
    region[xy[:, 1] > at(36, 39, 42, 45)[:, 1].mean()] = "forehead"
    region[xy[:, 1] < at(48, 54)[:, 1].mean() - 1.0] = "jaw"
    root, ala_r, base, ala_l = at(27)[0], at(31)[0], at(33)[0], at(35)[0]
    nose = np.array([root - [0.9, 0.0], ala_r - [0.3, 0.0], base - [0.0, 0.2], ala_l + [0.3, 0.0], root + [0.9, 0.0]])
    region[_inside(nose, xy)] = "nose"
    # the philtrum: skin between the nose's base and the lip that moves with the upper lip
    span = 0.3 * np.abs(at(48, 54)[:, 0]).max()
    philtrum = (np.abs(xy[:, 0]) < span) & (xy[:, 1] < base[1]) & (xy[:, 1] > at(51)[0, 1])
    region[philtrum] = "upper_lip"
    for brow in ((17, 18, 19, 20, 21), (22, 23, 24, 25, 26)):
        near = np.linalg.norm(xy[:, None] - at(*brow)[None], axis=2).min(1) < 0.75
        region[near] = "brows"
    for eye in ((36, 37, 38, 39, 40, 41), (42, 43, 44, 45, 46, 47)):
        region[_inside(at(*eye), xy, grow=1.45)] = "eyes"
    lips = _inside(at(*range(48, 60)), xy, grow=1.12)
    line = np.vstack([at(60), (at(62) + at(66)) / 2, at(64)])
    above = xy[:, 1] >= np.interp(xy[:, 0], line[:, 0], line[:, 1])
    region[lips & above] = "upper_lip"
    region[lips & ~above] = "lower_lip"
    corner = np.linalg.norm(xy[:, None] - at(48, 54)[None], axis=2).min(1) < 0.45
    region[lips & corner] = "mouth_corners"
    region[list(BROWS)] = "brows"
    for name, row_region, vertex in _IBUG68_ROWS:
        region[vertex] = row_region
    return [str(r) for r in region]


def _inside(polygon: np.ndarray, points: np.ndarray, grow: float = 1.0) -> np.ndarray:
    """(K,) bool: points (K, 2) inside `polygon` (M, 2) scaled by `grow` about its centroid
    (even-odd rule)."""
    centre = polygon.mean(0)
    q = centre + (polygon - centre) * grow
    x, y = points[:, 0, None], points[:, 1, None]
    x0, y0 = q[:, 0], q[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    crossing = (y0 > y) != (y1 > y)
    at_x = (x1 - x0) * (y - y0) / np.where(y1 != y0, y1 - y0, 1.0) + x0
    return (crossing & (x < at_x)).sum(1) % 2 == 1


_DUTREVE21_IBUG = (
    17, 19, 21, 22, 24, 26,  # brows: right outer, middle, inner; left inner, middle, outer
    38, 40, 43, 47,  # eyes: right upper/lower lid, left upper/lower lid
    31, 30, 35,  # nose: right ala, tip, left ala
    48, 49, 51, 53, 54, 55, 57, 59,  # outer lip: corners, 3 upper, 3 lower
)

_DUTREVE22_IBUG = _DUTREVE21_IBUG + (8,)  # and the chin

LAYOUTS: dict[str, Layout] = {
    layout.name: layout
    for layout in (
        _ibug_layout(
            "dutreve21",
            "Dutreve et al. 2008 §5: 3 per brow, 2 per eye, 3 on the nose, 8 around the mouth",
            _DUTREVE21_IBUG,
        ),
        _ibug_layout(
            "dutreve22",
            "Dutreve et al.'s 21 points and the chin, so the jaw follows the mouth",
            _DUTREVE22_IBUG,
        ),
        _ibug_layout(
            "ibug68",
            "The 68 iBUG / Multi-PIE points: jaw contour, brows, nose, eyes, outer and inner lips",
            range(68),
        ),
        _ibug_layout(
            "ibug51",
            "The 68 iBUG points without the jaw contour 0-16 (brows, nose, eyes, lips)",
            range(17, 68),
        ),
        _ibug_layout(
            "mediapipe68",
            "The 68 iBUG points read from MediaPipe's 468-vertex face mesh",
            range(68),
        ),
        _dense_layout(),
    )
}
"""The built-in layouts by name."""


_REGISTERED: OrderedDict[str, Layout] = OrderedDict()


def register_layout(layout: Layout) -> Layout:
    """Make a custom layout resolvable by `get_layout` in this process; answers it."""
    if not isinstance(layout, Layout) or not layout.is_custom:
        raise RetargetError(f"only custom layouts are registered, got {layout!r:.80}")
    _REGISTERED[layout.name] = layout
    _REGISTERED.move_to_end(layout.name)
    while len(_REGISTERED) > MAX_REGISTERED:
        _REGISTERED.popitem(last=False)
    return layout


def get_layout(name: str | Layout) -> Layout:
    """The built-in layout called `name` (a key of `LAYOUTS`), or a registered custom one
    (`register_layout`); a `Layout` is answered as it is (a custom one registered)."""
    if isinstance(name, Layout):
        return register_layout(name) if name.is_custom else name
    if isinstance(name, str) and name in LAYOUTS:
        return LAYOUTS[name]
    if isinstance(name, str) and name in _REGISTERED:
        _REGISTERED.move_to_end(name)
        return _REGISTERED[name]
    if isinstance(name, str) and CUSTOM_NAME.fullmatch(name):
        raise RetargetError(
            f"custom layout {name!r} is not loaded: read the landmarks JSON or layout file "
            "that carries its spec first")
    raise RetargetError(
        f"unknown layout {name!r:.80}; available: {', '.join(sorted(LAYOUTS))}, or a custom "
        "layout's file") from None


def _registered_from_spec(spec: dict) -> Layout:
    from retarget.custom_layouts import layout_from_spec  # it builds on this module
    return layout_from_spec(spec)


def _resolve(layout: Layout | str) -> Layout:
    if isinstance(layout, (Layout, str)):
        return get_layout(layout)
    raise RetargetError(f"layout must be a Layout or a layout name, got {layout!r}")


def from_ibug68(points68: np.ndarray, layout: Layout | str) -> np.ndarray:
    """A layout's points picked out of 68 iBUG-ordered points.

    points68 : (..., 68, D) float, any units (2D tracker output, 3D landmarks).
    layout : a `Layout` or a name from `LAYOUTS`.
    Returns (..., N, D), a copy (integer input becomes float64).
    """
    layout = _resolve(layout)
    if not layout.has_ibug68:
        raise RetargetError(f"layout {layout.name!r} has points that are none of the 68 iBUG points; "
                            "read it from a 468-point face mesh (from_mediapipe468)")
    p = _as_float_array(points68, "points68")
    if p.ndim < 2 or p.shape[-2] != 68:
        raise RetargetError(f"points68 must have shape (..., 68, D), got {p.shape}")
    return p[..., list(layout.ibug68), :]


def from_mediapipe468(points468: np.ndarray, layout: Layout | str) -> np.ndarray:
    """A layout's points picked out of a MediaPipe face mesh.

    points468 : (..., 468, D) or (..., 478, D) float, MediaPipe face-mesh landmarks (478
        with the iris points of the refined model, which are not used).
    layout : a `Layout` or a name from `LAYOUTS`.
    Returns (..., N, D), a copy (integer input becomes float64).
    """
    layout = _resolve(layout)
    if not layout.has_mediapipe468:
        raise RetargetError(f"layout {layout.name!r} has points that are no face-mesh vertex; a "
                            "468-point face mesh cannot drive it")
    p = _as_float_array(points468, "points468")
    if p.ndim < 2 or p.shape[-2] not in _MEDIAPIPE_MESH_SIZES:
        raise RetargetError(f"points468 must have shape (..., 468 or 478, D), got {p.shape}")
    return p[..., list(layout.mediapipe468), :]
