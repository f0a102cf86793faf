"""Zero-click landmarks: the 468 face-mesh points found on any face mesh, with how much
to trust each one.

The mesh is pictured (`retarget.facemesh.views`), the face mesh runs on the picture, and
each point's ray is followed back onto the surface. In steps:

1. **Find the face.** The front view first (the face toward +z, +y up, the convention
   of glTF, ICT and MediaPipe's canonical model); when the detector is not sure of a
   face there, the six axis directions x four in-plane turns, keeping the face the
   landmark model is surest of (its presence; the detector's score was fooled by a
   speckled face upside down). A detection whose box shows mostly back faces is none (a
   mask seen from behind is its dark silhouette), and a face the landmark model does not
   see (`MIN_PRESENCE`) is refused by name rather than placed anywhere.
   The pictures are of the mesh wound consistently outward (`retarget.winding`): wound
   inward (a converter, a mirror) or mixed, the back faces they paint dark were the
   whole face, a dark silhouette in which no face was found; the points come back on
   the mesh's own triangles, corners in its order.
2. **Face it.** The 468 points on that view give a face frame (eye line, forehead to
   chin), and the mesh is pictured again looking straight at the face, zoomed on it;
   the landmark model runs twice there, the second time on the region its first points
   give, as the tracker does from frame to frame.
   **Under a ring of lights**: that straight picture is lit in turn from `LIGHT_RING`
   directions `LIGHT_TILT` off the viewing axis, and the model's points (pixels and
   depth) are averaged over the lights. One light's points carry a bias of their own
   (which shading cue the model reads); lights around the face average part of it out.
   On the ICT dense-source benchmark (`bench/accuracy.py --dense`, seed 0) the same point
   found on identities A and B came from 4.3 to 3.4 mm apart (2.9/2.8 to 2.7/2.7 on
   seeds 1/2), and the retargeting error from 26.3 to 23.9 %; jittering the model's
   region (13 runs) or the view's yaw and pitch by 2 degrees (5 renders) gave 24.1 and
   26.0 %, and 16 or 66 lit views no better than 8. Most of the disagreement is bias
   that no averaging removes, and the gain is not uniform (table in step 4).
3. **Back to the surface.** Points whose pixel sees a front face are followed exactly;
   a point in a hole (an eye or mouth opening reads dark) snaps to the nearest
   front-facing pixel. The inner-lip points first move a hair into their own lip, so
   that on closed lips each lands on its lip and not on the other.
   **Each lip point on its own lip**: the model's lip lines are biased per face by a few
   millimetres, enough for a ray near the contact line to meet the other lip (a point
   that then opens with the jaw instead of staying, or the reverse: 20-25 mm off on a
   wide-open mouth). Where the lips are two sheets on the mesh, the surface says which
   lip a hit is on, and a point on the wrong one moves toward its own until it lands
   there (`_onto_own_lip_sheets`). The dense benchmark's error (%, `bench/accuracy.py
   --dense`, "468 found"), seeds 0-5 and 6-13:

       lips as the rays fall    23.1 26.0 30.3 36.0 26.7 23.3 | 28.0 18.8 28.0 26.6 26.0 23.4 42.9 44.7
       each on its own lip      23.0 22.3 25.3 31.6 21.2 18.5 | 25.8 18.1 25.2 24.4 22.8 21.1 33.1 32.7

   (means 27.6 and 29.8 to 23.7 and 25.4). Mirrored pictures averaged in (to cancel the
   model's left-right bias) gave seeds 6-13 the same mean (25.61 against 25.60, before
   the corners joined the upper lip) for twice the model's runs, and were left out.
   **On the contact line**: on its own lip or not, the model's lip lines sit off where the
   lips meet by a bias of their own per face (ICT seed 0: A's inner upper lip 1.3-2.0 mm
   above the contact line, B's within 0.5 of it), so the same lip point lands on
   different places of two faces, and costs most near the contact line, where the
   expression's motion changes fastest (the jaw drops: the upper lip stays, the lower
   goes). The surface shows the line (`_onto_contact_line`): up and down each inner-lip
   point's pixel column, the deepest pixel where closed lips meet, or the rims of the
   opening where they part. The inner lines move onto it (then `LIP_PUSH` into their
   lips), the lips' other rings follow their inner line's move by a share falling from 1
   to a third at the vermilion border (`RING_FOLLOW`), and the rings' ends go
   `CORNER_PUSH` pushes above the line; where no line shows (a crease under
   `CREASE_DEPTH`, an opening wider than the search), the model's lines stay. The dense
   benchmark (%, "468 found"), seeds 0-2 and held-out 3-13:

       0-2      22.5 20.9 24.3 -> 22.2 19.6 22.0   (A and B 2.99/2.19/2.01 -> 2.84/2.06/1.96 mm apart)
       3-13     31.2 18.8 18.2 25.4 17.5 23.9 23.3 20.7 19.2 31.2 31.5
             -> 29.2 20.0 18.4 24.6 17.6 23.8 22.8 19.9 18.7 29.9 30.4   (mean 23.7 -> 23.2)

   Seed 2's mouth region 1.22 -> 0.94 mm. Tried and left: the inner lines alone on the
   contact line (A's and B's inner-lip points 2.38 -> 1.10 mm apart on seed 0, yet the
   14 seeds' mean 23.47 -> 23.46: lines that agree under rings that do not), the rings
   following all the way (23.41; seed 8 23.9 -> 27.8) or by a half (23.23), the ends
   left where the model put them (22.98) or put on the contact line itself (seed 11
   19.2 -> 23.6: there either lip is as near), and the inner lines half a push from the
   line (22.67, within the seeds' noise of one push's 22.78, and less room on lips that
   touch). The corners' place along the mouth stays the model's (not tried: the crease
   fades out gradually toward them, and where it falls under 0.5 mm, 0-5 pixels from the
   model's corners on seeds 0 and 2, hangs on that threshold).
4. **The face oval** (jaw line, temples, hairline) is the silhouette of a frontal face,
   where a ray grazes the surface and lands anywhere along it. Those points are placed
   with the model's own depth instead: the similarity that carries the model's 3D
   points onto the surface hits of the inner points carries the oval too, which is then
   snapped to the closest surface point. So is any other point whose hit lies more than
   `DEPTH_CHECK` eye widths from where that similarity puts the model's point: a ray
   that grazed the side of the nose or of the cheek and went on to another surface
   (on ICT faces, hits 16-27 mm deep off). The inner-lip points are left to their hits:
   the closest surface point to a mouth corner may be on the other lip. The benchmark's
   error (%, seeds 0/1/2), one light at the viewer or the ring, without or with the check:

       one light             26.3 / 30.4 / 32.3      with the check  25.2 / 27.4 / 29.8
       ring of 8 lights      23.9 / 30.3 / 37.6      with the check  23.1 / 27.0 / 30.4

   (before each lip point was kept on its own lip, step 3)
5. **Halfway to the model's depth.** Two faces' placements of the same point disagree
   mostly by a bias that is smooth over the face and stable under the picture: the points
   found on one ICT face under 9 perturbed straight views (zoom 0.85/1.15, shifts of 2 %
   of the picture, 10 degree turns in the picture plane) spread 0.4 mm RMS, against 2.5 to
   3.2 mm between faces A and B of the dense benchmark (seeds 0-2), and averaging those
   runs (test-time augmentation), larger turns (yaw and pitch of 8 or 15 degrees, 5 views)
   or a Laplacian smoothing of the points' offsets from the canonical face left the
   benchmark's error within a point of where it was, no better on average. What did help:
   the ray hit and the model's own 3D point (carried by the similarity that best maps the
   model's inner points onto their final places) err differently, and the point halfway
   between the two, snapped to the closest surface point, agrees better from face to face.
   The lips stay on their rays (the closest surface point may be the other lip), and so
   do the eyes (moved all the way to the model's points, A's and B's eye points drew apart
   on 10 of 14 seeds, 2.2 -> 3.8 mm on seed 8; halfway changed nothing). The dense
   benchmark (%, "468 found", `DEPTH_BLEND` 0 -> 0.5), seeds 0-2 and held-out 3-13:

       0-2      23.1 22.2 24.8 -> 22.5 20.9 24.3   (A and B 3.22/2.48/2.46 -> 2.99/2.19/2.01 mm apart)
       3-13     32.4 20.6 18.9 25.1 17.4 24.6 24.5 20.7 20.3 33.3 31.2
             -> 31.2 18.8 18.2 25.4 17.5 23.9 23.3 20.7 19.2 31.2 31.5   (mean 24.5 -> 23.7)

   All the way (`DEPTH_BLEND` 1) gave 22.3/20.8/24.7 on seeds 0-2 but a held-out mean no
   better than the rays'; a share growing with the surface's slant (0.25-0.75), or the
   mean of the hit, the similarity's and an affine map's point, gave means within 0.3 of
   halfway (22.8 and 22.8 on seeds 0-2, 23.7 and 23.5 on 3-13). `bench/landmarks.py`
   (ICT, corrected, mean/p95 mm): brows 2.7/6.1 -> 2.2/4.6, nose 1.5/3.7 -> 1.2/2.9, all
   2.0/5.6 -> 1.8/5.3 (the offset table measured again on the new placement did no
   better, and was left as it was).
6. **Toward the shape the other points give.** What still differs most between two faces'
   placements is where the surface shows little: with each region's points in turn put
   where the other face's fell (the oracle, ICT's shared topology, replayed on the
   model's saved points), the dense benchmark's error falls by (points, mean of seeds
   0-13) forehead 1.1, brows 1.0, nose 0.8, cheeks 0.7, eyes, jaw, lower lip and mouth
   corners 0.2-0.3, and the upper lip not at all (-0.2). On seed 0 the forehead, brows
   and cheeks are 3.5-3.7 mm apart on the two faces, the lips, eyes and nose 1.4-1.8 (the
   brows 7 and 10 mm on seeds 6 and 12: brows are hair, which a picture of bare geometry
   lacks). So those regions lean on the better-placed ones: MediaPipe's canonical face
   is carried onto the lips, eyes, mouth corners and jaw inside the oval by the
   similarity that best maps it there, each point's offset from its canonical vertex is
   filled in over the others from those around it (harmonically over the canonical mesh:
   a filled offset is the mean of its neighbours'), and the forehead, cheek, brow and nose
   points move their `SHAPE_PULL` share (0.75, 0.75, 0.75, 0.25) of the way there, then
   snap to the closest surface point. The iBUG points among them (10 on the brows, 9 on
   the nose) stay: `layout_landmarks` corrects them by offsets measured where they are,
   and moved with the others (mean of seeds 0-13 22.17 against 22.19 below),
   `bench/landmarks.py` had them nearer the known points uncorrected (ICT brows 5.5 -> 4.4
   mm, nose 3.0 -> 2.7; the sample face's brows 8.4 -> 4.7) but some farther corrected
   (ICT brows 2.2/4.6 -> 2.6/5.8 mean/p95, the sample face's nose 1.6/3.0 -> 1.8/3.5);
   as they stay, its figures are unchanged. The dense benchmark (%, "468 found"), seeds
   0-2 and held-out 3-13:

       0-2      22.2 19.6 22.0 -> 21.5 18.9 21.4   (A and B 2.84/2.06/1.96 -> 2.51/1.96/1.82 mm apart)
       3-13     29.2 20.0 18.4 24.6 17.6 23.8 22.8 19.9 18.7 29.9 30.4
             -> 29.4 19.3 18.8 23.4 17.7 22.0 23.3 19.4 18.0 28.4 29.1   (mean 23.2 -> 22.6)

   Tried and left (means over seeds 0-13, from 22.79; the shares above give 22.19): the
   brows and nose filled in but left where they are (22.36), the brows among the guides
   (22.68), forehead, brows, cheeks and nose all the way (22.81: seeds 0-2 worse),
   forehead and brows alone (22.47), cheeks alone (22.73 half way, 22.71 all the way;
   cast along the view's rays instead of snapped 23.86: grazing); and, from 22.17 (all
   brow and nose points moved, the cheeks half way), the jaw or the mouth corners pulled
   too (22.18, 22.42), the eyes (24.07), a biharmonic fill (22.20, seed 0 22.2 -> 24.6),
   inverse-length or cotangent weights in the fill (22.15, 22.20), the model's own 3D
   points in the canonical face's place (22.41; the mean of the two 22.27). The nose tip
   as the surface's most forward point near the model's (pronasale) lay 1.9 mm apart on
   the two faces (mean of the 14 seeds; 0-4.1), the model's own tip 1.6 (0.5-2.8, 5.7 on
   seed 13): not used.

Confidence per point (0..1) says which points a user should check: exact hits on a
surface that faces the viewer score high; points that had to snap, that sit on grazing
surface, or on the oval or failed the depth check (moved by a fit, not observed) score
lower.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import trimesh
from scipy.sparse.csgraph import dijkstra, laplacian

from retarget.errors import RetargetError
from retarget.facemesh.canonical import BROWS, FACE_OVAL, canonical_face
from retarget.facemesh.detector import Detection
from retarget.facemesh.tracker import N_POINTS, FaceMeshTracker, Roi, roi_from_detection
from retarget.facemesh.views import (Picture, View, look_from, picture, relit, surface_hits,
                                     texture_rgb, vertex_normals)
from retarget.landmarks import SurfacePoints
from retarget.layouts import Layout, get_layout
from retarget.mesh import Mesh
from retarget.operators import edge_graph
from retarget.similarity import similarity_transform
from retarget.winding import outward_faces

__all__ = ["FACE_OVAL", "FaceOnMesh", "find_face_mesh", "layout_landmarks", "landmark_offsets"]

EYE_CORNERS = (33, 263)   # outer corners of the subject's right and left eye
INNER_UPPER_LIP = (191, 80, 81, 82, 13, 312, 311, 310, 415)   # corners 78 and 308 excluded
INNER_LOWER_LIP = (95, 88, 178, 87, 14, 317, 402, 318, 324)
MOUTH_CORNERS = (78, 308)  # where the inner lip lines meet
# The face mesh's lip rings from the outer (vermilion border) to the inner line: the outer
# rings anchor each lip's sheet, the others must land on it (step 3). The rings' corners
# sit on the contact line, where either lip is as right as the other: they count with the
# upper lip, so that two faces make the same call.
OUTER_UPPER_LIP = (185, 40, 39, 37, 0, 267, 269, 270, 409)
OUTER_LOWER_LIP = (146, 91, 181, 84, 17, 314, 405, 321, 375)
UPPER_LIP = ((184, 74, 73, 72, 11, 302, 303, 304, 408, 183, 42, 41, 38, 12, 268, 271, 272, 407)
             + INNER_UPPER_LIP + (61, 76, 62, 291, 306, 292) + MOUTH_CORNERS)
LOWER_LIP = (77, 90, 180, 85, 16, 315, 404, 320, 307, 96, 89, 179, 86, 15, 316, 403, 319, 325) + INNER_LOWER_LIP
LIP_PUSH = 0.01           # eye widths (about 0.9 mm) an inner-lip point is moved into its lip
# the lip rings between the inner line and the vermilion border (`OUTER_UPPER_LIP` and
# `OUTER_LOWER_LIP` the last), from the inner line out, and the share of the inner line's
# move onto the contact line each ring follows (step 3)
UPPER_RINGS = ((183, 42, 41, 38, 12, 268, 271, 272, 407), (184, 74, 73, 72, 11, 302, 303, 304, 408),
               (185, 40, 39, 37, 0, 267, 269, 270, 409))
LOWER_RINGS = ((96, 89, 179, 86, 15, 316, 403, 319, 325), (77, 90, 180, 85, 16, 315, 404, 320, 307),
               (146, 91, 181, 84, 17, 314, 405, 321, 375))
RING_FOLLOW = (1.0, 2 / 3, 1 / 3)
LIP_CORNERS = MOUTH_CORNERS + (62, 292, 76, 306, 61, 291)   # the rings' ends, on the contact line
CREASE_WINDOW = 0.06      # eye widths (about 5 mm) either side of the model's lip line searched for the contact line
CREASE_DEPTH = 0.005      # eye widths (about 0.45 mm) the contact line must lie deeper than the window's ends
CORNER_PUSH = 2.0         # LIP_PUSHes a ring's end is kept above the contact line (it counts with the upper lip)
FOREHEAD, CHIN = 10, 152
SEARCH_SIZE = 256         # pixels of the views searched for a face
FACE_SIZE = 512           # pixels of the view looking straight at the face
FACE_MARGIN = 1.6         # the straight view's width over the face's width
CHECK_BELOW = 0.6         # confidence under which a point is flagged for checking
SPREAD_SCALE = 0.08       # eye widths of offset spread that cut a point's confidence by e
_FRONT_SCORE = 0.75       # a frontal detection this sure ends the search
FRONT_SHARE = 0.5         # share of a detected face's box that must show front faces (`_seen_from_front`)
MIN_PRESENCE = 0.5        # the landmark model's face presence under which a view shows no face
LIGHT_RING = 8            # lights around the viewing axis the straight view is lit from in turn
LIGHT_TILT = 35.0         # degrees between each of those lights and the viewing axis
LIP_STEPS = 8             # pushes of LIP_PUSH tried to bring a point that hit the other lip onto its own
LIPS_APART = 1.6          # surface over straight distance between the lips' centres that says the lips are apart
DEPTH_CHECK = 0.12        # eye widths (about 11 mm) a hit may lie from the model's fitted point
DEPTH_BLEND = 0.5         # share of the way from its hit toward the model's fitted point a point moves (step 5)
# the lids and eye corners (the mediapipe468 layout's eye region): kept on their rays
EYES = (7, 33, 130, 133, 144, 145, 153, 154, 155, 157, 158, 159, 160, 161, 163, 173, 243, 246,
        249, 263, 359, 362, 373, 374, 380, 381, 382, 384, 385, 386, 387, 388, 390, 398, 463, 466)
# share of the way each region's points move toward the canonical face's shape filled in
# from the other points (step 6); the regions named here and the oval are filled in (none
# of their points guides the others); the iBUG points stay, as does the oval outside these
# regions (the jaw's; the forehead's part of it moves with the forehead)
SHAPE_PULL = {"forehead": 0.75, "cheeks": 0.75, "brows": 0.75, "nose": 0.25}
OFFSETS = Path(__file__).resolve().parent / "landmark_offsets.json"


@dataclass(frozen=True, eq=False)
class FaceOnMesh:
    """The face mesh's 468 points on a mesh.

    points : SurfacePoints of the 468 points, in MediaPipe's order.
    confidence : (468,) float64 in 0..1; under `CHECK_BELOW` asks to be checked.
    view : the straight-on view the points were found in.
    presence : the landmark model's face presence in that view, 0..1.
    """

    points: SurfacePoints
    confidence: np.ndarray
    view: View
    presence: float


def find_face_mesh(mesh: Mesh, tracker: FaceMeshTracker | None = None, progress=None) -> FaceOnMesh:
    """The 468 face-mesh points on `mesh` (module docstring); RetargetError when no view
    shows a face. `tracker` lends its models (one is made when None); `progress(fraction)`,
    when given, hears how far the work is (0..1)."""
    report = progress if progress is not None else (lambda fraction: None)
    tracker = FaceMeshTracker() if tracker is None else tracker
    given = mesh
    mesh = _wound_outward(mesh)
    normals = vertex_normals(mesh)
    texture = texture_rgb(mesh)
    report(0.05)
    pic, face = _search(mesh, normals, texture, tracker, report)
    image, _ = _landmarks_twice(tracker, pic, roi_from_detection(face))
    # ray-cast the first guess only to set up the straight view: its points need not be final
    tri, bary, _ = surface_hits(pic, mesh, image[:, :2])
    hits = SurfacePoints(mesh.faces[tri], bary).positions(mesh.vertices)
    view = _straight_view(hits, image, pic.view)
    report(0.6)
    pic = picture(mesh, view, normals, texture)
    projected = view.to_image(hits)[:, :2]
    roi = Roi.around(projected.min(0), projected.max(0), projected[EYE_CORNERS[0]], projected[EYE_CORNERS[1]])
    image, presence = _landmarks_under_lights(tracker, pic, roi, mesh, normals, texture)
    if presence < MIN_PRESENCE:
        raise RetargetError(f"no face found on the mesh: looking straight at the face the detector saw, the "
                            f"landmark model sees none (face presence {presence:.2f}); place the points by hand")
    report(0.8)
    pixels = _onto_own_lips(_onto_contact_line(pic, image[:, :2]))
    tri, bary, snap = surface_hits(pic, mesh, pixels)
    tri, bary = _onto_own_lip_sheets(mesh, pic, pixels, tri, bary, snap)
    surface = _surface(mesh)
    points, fitted = _placed_from_depth(mesh, pic, image, SurfacePoints(mesh.faces[tri], bary), snap, surface)
    points = _halfway_to_depth(mesh, pic, image, points, surface)
    points = _toward_canonical_shape(mesh, points, surface)
    confidence = _confidence(normals, points, view, snap, fitted, presence, textured=texture is not None)
    report(1.0)
    return FaceOnMesh(_as_wound(points, mesh, given), confidence, view, presence)


def layout_landmarks(found: FaceOnMesh, layout: Layout, mesh: Mesh, *,
                     corrected: bool = True) -> tuple[SurfacePoints, np.ndarray]:
    """The layout's points on `mesh` and their confidence (N,) 0..1.

    Each point starts at its face-mesh vertex (the layout's ``mediapipe468`` column).
    Where the layout's point means something else than that vertex (iBUG's brows sit on
    the brow's lower edge, its jaw on the jaw bone rather than the face's outline),
    `corrected` moves it by the point's offset in `OFFSETS`, measured in the face's own
    frame and eye width, and snaps it back onto the surface; the offset's spread over the
    faces it was measured on lowers the point's confidence. A layout with points beyond
    the iBUG 68 (``mediapipe468``) is the face mesh's own vertices, as a face-mesh source
    gives them, and is never moved.
    """
    rows = np.asarray(layout.mediapipe468, dtype=np.int64)
    tri, bary = found.points.vertex_indices[rows], found.points.barycentric[rows]
    confidence = found.confidence[rows].copy()
    if corrected and layout.has_ibug68:
        offsets, spread = landmark_offsets()
        ibug = np.asarray(layout.ibug68, dtype=np.int64)
        everywhere = found.points.positions(mesh.vertices)
        eye_width = np.linalg.norm(everywhere[EYE_CORNERS[1]] - everywhere[EYE_CORNERS[0]])
        moved = everywhere[rows] + eye_width * offsets[ibug] @ found.view.rotation
        tri, bary = _closest_surface_points(mesh, moved)
        confidence *= np.exp(-spread[ibug] / SPREAD_SCALE)
    return SurfacePoints(tri, bary, layout.name), confidence


@lru_cache(maxsize=1)
def landmark_offsets() -> tuple[np.ndarray, np.ndarray]:
    """(68, 3) float64 offsets from each iBUG point's face-mesh vertex to the point, in
    eye widths along the straight view's axes (image x, image y down, viewing
    direction), and (68,) their RMS spread in eye widths; from ``OFFSETS``, which
    ``bench/landmark_offsets.py`` measures on the ICT face model's identities."""
    table = json.loads(OFFSETS.read_text())
    return np.asarray(table["offsets"], dtype=np.float64), np.asarray(table["spread"], dtype=np.float64)


def _search(mesh: Mesh, normals, texture, tracker: FaceMeshTracker, report) -> tuple[Picture, Detection]:
    """The picture and detection of the face over the search views (reporting progress from
    0.05 to 0.5 as the views go by): the front view's when the detector is sure of it
    (`_FRONT_SCORE`), else the one whose face the landmark model is surest of (its
    presence, then the detector's score). The detector alone is fooled by a picture that
    is not quite a face: the sample face with 2 % of its triangles missing scored 0.55
    upright and 0.62 upside down, where the landmark model then saw no face (presence 0)."""
    lo, hi = mesh.vertices.min(0), mesh.vertices.max(0)
    centre, width = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) * 1.05
    found: list[tuple[float, float, Picture, Detection]] = []
    directions = _search_directions()
    for i, (facing, up) in enumerate(directions):
        report(0.05 + 0.45 * i / len(directions))
        pic = picture(mesh, look_from(-facing, up, centre, width, SEARCH_SIZE), normals, texture)
        faces = [face for face in tracker.detector.detect(pic.rgb) if _seen_from_front(pic, face)]
        if not faces:
            continue
        if i == 0 and faces[0].score >= _FRONT_SCORE:
            return pic, faces[0]
        presence = _landmarks_twice(tracker, pic, roi_from_detection(faces[0]))[1]
        found.append((presence, faces[0].score, pic, faces[0]))
    if not found:
        raise RetargetError("no face found on the mesh: none of 24 views (6 directions x 4 turns) "
                            "shows one to the face detector; place the points by hand")
    presence, _, pic, face = max(found, key=lambda item: item[:2])
    if presence < MIN_PRESENCE:
        raise RetargetError(f"no face found on the mesh: where the face detector saw one, the landmark model "
                            f"sees none (face presence {presence:.2f}); place the points by hand")
    return pic, face


def _seen_from_front(pic: Picture, face: Detection) -> bool:
    """Whether most of what `face`'s box shows of the mesh is front faces (`FRONT_SHARE`):
    a face mask seen from behind is its own silhouette, painted dark, in which the detector
    finds a face (the sample face with 2 % of its triangles missing: 0.83 from behind, more
    than its speckled front; its points then landed 13 cm off)."""
    x0, y0, x1, y1 = np.clip(np.rint(face.box), 0, pic.view.size - 1).astype(np.int64)
    seen = pic.raster.triangle[y0:y1 + 1, x0:x1 + 1] >= 0
    front = pic.raster.front[y0:y1 + 1, x0:x1 + 1] & seen
    return bool(front.sum() >= FRONT_SHARE * max(seen.sum(), 1))


def _search_directions() -> list[tuple[np.ndarray, np.ndarray]]:
    """(direction the face looks toward, up) pairs: +z with +y up first, then every axis
    direction with each of its four perpendicular axes as up."""
    axes = np.vstack([np.eye(3), -np.eye(3)])
    front = (np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))
    pairs = [front]
    for facing in axes:
        for up in axes:
            if abs(facing @ up) < 0.5 and not (np.array_equal(facing, front[0]) and np.array_equal(up, front[1])):
                pairs.append((facing, up))
    return pairs


def _landmarks_twice(tracker: FaceMeshTracker, pic: Picture, roi: Roi) -> tuple[np.ndarray, float]:
    """(468, 3) image points (x, y pixels down, z the model's depth in pixels, away from
    the viewer) and presence, from the model run on `roi` and again on the region its
    points give."""
    points, _ = tracker.landmarks(pic.rgb, roi)
    roi = Roi.around(points[:, :2].min(0), points[:, :2].max(0),
                     points[EYE_CORNERS[0], :2], points[EYE_CORNERS[1], :2])
    return tracker.landmarks(pic.rgb, roi)


def _landmarks_under_lights(tracker: FaceMeshTracker, pic: Picture, roi: Roi, mesh: Mesh,
                            normals: np.ndarray, texture: np.ndarray | None) -> tuple[np.ndarray, float]:
    """(468, 3) image points (as `_landmarks_twice`) averaged over `pic` relit from each of
    `_light_ring()`'s lights, and the mean presence (module docstring, step 2)."""
    runs = [_landmarks_twice(tracker, lit, roi) for lit in relit(pic, mesh, normals, texture, _light_ring())]
    return np.mean([points for points, _ in runs], axis=0), float(np.mean([p for _, p in runs]))


def _light_ring() -> np.ndarray:
    """(LIGHT_RING, 3) unit directions toward the lights, in a view's axes (x right, y down,
    z into the picture): `LIGHT_TILT` degrees off the viewing axis, evenly around it,
    starting above the face."""
    around = 2 * np.pi * np.arange(LIGHT_RING) / LIGHT_RING
    tilt = np.radians(LIGHT_TILT)
    return np.column_stack([np.sin(tilt) * np.sin(around), -np.sin(tilt) * np.cos(around),
                            np.full(LIGHT_RING, -np.cos(tilt))])


def _onto_contact_line(pic: Picture, pixels: np.ndarray) -> np.ndarray:
    """(468, 2) pixels with the lips' lines moved onto the contact line the surface shows
    (module docstring, step 3); `pixels` as they are where it does not show one.

    Each inner-lip point looks up and down its own pixel column, within `CREASE_WINDOW`
    eye widths of its pair's mean row (the upper and lower inner-lip points of the same
    place along the mouth), for the contact line: on closed lips the deepest pixel (seen
    away from the viewer), where the lips meet; on parted lips the mouth opening (pixels
    that see no front face), whose top rim the upper point takes and bottom rim the lower.
    A crease under `CREASE_DEPTH` eye widths deeper than the window's ends, or an opening
    that reaches them, is no contact line found: then nothing moves. Otherwise the
    inner-lip points move there (`_onto_own_lips` then pushes them into their lips), each
    of the lips' other rings follows the inner line's move by its `RING_FOLLOW` share (the
    move interpolated along the mouth), and each ring end (`LIP_CORNERS`) whose own column
    shows a crease goes `CORNER_PUSH` pushes above it.
    """
    view, raster = pic.view, pic.raster
    eye_width = float(np.linalg.norm(pixels[EYE_CORNERS[1]] - pixels[EYE_CORNERS[0]]))
    half = int(np.ceil(CREASE_WINDOW * eye_width))
    deep_enough = CREASE_DEPTH * eye_width / view.scale
    depth = np.where(raster.front & (raster.triangle >= 0), raster.depth, np.inf)
    size = view.size

    def column(x: float, centre: float) -> tuple[int, np.ndarray]:
        col = int(np.clip(np.rint(x), 0, size - 1))
        top = int(np.clip(np.rint(centre) - half, 0, size - 1))
        return top, depth[top:int(np.clip(np.rint(centre) + half, 0, size - 1)) + 1, col]

    def crease(x: float, centre: float) -> tuple[float, float] | None:
        """(top, bottom) rows of the contact line in column x near row `centre`, or None."""
        top, seen = column(x, centre)
        if len(seen) < 3:
            return None
        opening = np.flatnonzero(np.isinf(seen))
        if len(opening):
            if opening[0] == 0 or opening[-1] == len(seen) - 1:
                return None
            return top + opening[0] - 0.5, top + opening[-1] + 0.5
        k = int(np.argmax(seen))
        if seen[k] - max(seen[0], seen[-1]) < deep_enough:
            return None
        return float(top + k), float(top + k)

    out = pixels.copy()
    upper, lower = list(INNER_UPPER_LIP), list(INNER_LOWER_LIP)
    centres = (pixels[upper, 1] + pixels[lower, 1]) / 2
    found = [crease(pixels[i, 0], c) for i, c in zip(upper, centres)]
    found += [crease(pixels[i, 0], c) for i, c in zip(lower, centres)]
    if any(f is None for f in found):
        return out
    out[upper, 1] = [f[0] for f in found[:len(upper)]]
    out[lower, 1] = [f[1] for f in found[len(upper):]]
    for line, rings in ((upper, UPPER_RINGS), (lower, LOWER_RINGS)):
        order = np.argsort(pixels[line, 0])
        xs, moves = pixels[line, 0][order], (out[line, 1] - pixels[line, 1])[order]
        for ring, share in zip(rings, RING_FOLLOW):
            ring = list(ring)
            out[ring, 1] += share * np.interp(pixels[ring, 0], xs, moves)
    for i in LIP_CORNERS:
        line = crease(pixels[i, 0], pixels[i, 1])
        if line is not None:
            out[i, 1] = line[0] - CORNER_PUSH * LIP_PUSH * eye_width
    return out


def _onto_own_lips(pixels: np.ndarray) -> np.ndarray:
    """(468, 2) pixels with the inner-lip points moved `LIP_PUSH` eye widths into their own
    lip: on closed lips both inner-lip lines fall on the contact line, where a ray meets
    either lip (a coin toss between two surfaces that part when the mouth opens)."""
    out = pixels.copy()
    push = LIP_PUSH * np.linalg.norm(pixels[EYE_CORNERS[1]] - pixels[EYE_CORNERS[0]])
    out[list(INNER_UPPER_LIP), 1] -= push   # image y runs down: up into the upper lip
    out[list(INNER_LOWER_LIP), 1] += push
    return out


def _onto_own_lip_sheets(mesh: Mesh, pic: Picture, pixels: np.ndarray, tri: np.ndarray, bary: np.ndarray,
                         snap: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (468,) and barycentric weights (468, 3) of the hits of `pixels` (468, 2)
    (`tri`, `bary`, `snap` as `surface_hits` gives them) with every lip point on its own
    lip (module docstring, step 3).

    The model's lip lines carry a bias of their own per face, so near the contact line a
    ray can meet the other lip: on ICT seed 1 four upper-lip points of one identity and
    six lower-lip points of the other drove the opposite lip, a jaw drop of 25 mm against
    5. `_lip_sides` tells the two lips apart by the surface; a point of `UPPER_LIP` or
    `LOWER_LIP` whose hit is on the other lip moves toward its own in steps of `LIP_PUSH`
    eye widths (at most `LIP_STEPS`) to the first pixel that sees its own lip, and stays
    where it was if none does. Joined lips (one surface across the contact line, where
    the surface cannot tell the lips apart) are left to `_onto_own_lips`.
    """
    sides = _lip_sides(mesh, tri, bary)
    if sides is None:
        return tri, bary
    own = np.zeros(N_POINTS, dtype=np.int64)
    own[list(UPPER_LIP)], own[list(LOWER_LIP)] = 1, -1
    wrong = np.flatnonzero((own != 0) & (_landed(mesh, sides, tri, bary) == -own))
    if not len(wrong):
        return tri, bary
    step = LIP_PUSH * np.linalg.norm(pixels[EYE_CORNERS[1]] - pixels[EYE_CORNERS[0]])
    k = np.arange(1, LIP_STEPS + 1)
    # (W, LIP_STEPS, 2): image y runs down, so an upper-lip point moves to smaller y
    tries = np.repeat(pixels[wrong, None, :], LIP_STEPS, axis=1)
    tries[..., 1] -= step * k[None, :] * own[wrong, None]
    t_tri, t_bary, t_snap = surface_hits(pic, mesh, tries.reshape(-1, 2))
    ok = ((t_snap == 0) & (_landed(mesh, sides, t_tri, t_bary) == np.repeat(own[wrong], LIP_STEPS)))
    ok = ok.reshape(len(wrong), LIP_STEPS)
    found = ok.any(1)
    pick = np.flatnonzero(found) * LIP_STEPS + np.argmax(ok[found], axis=1)
    tri, bary = tri.copy(), bary.copy()
    tri[wrong[found]], bary[wrong[found]] = t_tri[pick], t_bary[pick]
    return tri, bary


def _landed(mesh: Mesh, sides: np.ndarray, tri: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """(K,) the lip side (`_lip_sides`) of the vertex nearest each hit in triangles `tri`
    (K,) at barycentric weights `bary` (K, 3)."""
    return sides[mesh.faces[tri, np.argmax(bary, axis=1)]]


def _lip_sides(mesh: Mesh, tri: np.ndarray, bary: np.ndarray) -> np.ndarray | None:
    """(V,) int: +1 for vertices nearer along the surface to the upper lip's outer ring
    (`OUTER_UPPER_LIP`, on the vermilion border, 5-8 mm from the contact line: out of
    reach of the model's bias) than to the lower's, -1 the reverse, 0 for vertices more
    than an eye width from both. The rings' ends beside the mouth corners are left out: a
    corner is about as near to either. None when the lips are joined: the surface path
    between the two rings' centres is under `LIPS_APART` times their straight distance
    (it crosses the contact line instead of going round a corner; 3.3-4.1 on ICT
    identities and the sample face, 1.3 on the sample face with its lips welded).
    `tri`, `bary`: the 468 hits."""
    seeds = _landed(mesh, np.arange(len(mesh.vertices)), tri, bary)   # each hit's nearest vertex
    at = mesh.vertices
    upper, lower = seeds[list(OUTER_UPPER_LIP[1:-1])], seeds[list(OUTER_LOWER_LIP[1:-1])]
    reach = float(np.linalg.norm(at[seeds[EYE_CORNERS[1]]] - at[seeds[EYE_CORNERS[0]]]))
    graph = edge_graph(at, mesh.faces)
    centre_up, centre_low = seeds[OUTER_UPPER_LIP[4]], seeds[OUTER_LOWER_LIP[4]]
    around = dijkstra(graph, indices=centre_up, limit=reach)[centre_low]
    if around < LIPS_APART * np.linalg.norm(at[centre_up] - at[centre_low]):
        return None
    to_upper = dijkstra(graph, indices=upper, min_only=True, limit=reach)
    to_lower = dijkstra(graph, indices=lower, min_only=True, limit=reach)
    return (to_upper < to_lower).astype(np.int64) - (to_lower < to_upper)


def _straight_view(hits: np.ndarray, image: np.ndarray, seen_from: View) -> View:
    """The view looking straight at the face whose points are `hits` (468, 3) world:
    x along the eye line, up from chin to forehead, zoomed to the face."""
    inner = np.ones(N_POINTS, dtype=bool)
    inner[list(FACE_OVAL)] = False
    across = hits[EYE_CORNERS[1]] - hits[EYE_CORNERS[0]]           # toward the subject's left
    up = hits[FOREHEAD] - hits[CHIN]
    up -= (up @ across) / max(across @ across, 1e-300) * across
    if not (np.linalg.norm(across) > 0 and np.linalg.norm(up) > 0):
        # the rays of the eyes, forehead and chin met no surface facing the view (only
        # back faces: a shell seen from inside) and snapped onto one place
        raise RetargetError("no face found on the mesh: the face seen has no surface under its eyes "
                            "and chin; place the points by hand")
    across /= np.linalg.norm(across)
    up /= np.linalg.norm(up)
    facing = np.cross(across, up)
    # the face's extent from the model's points in the view they were found in
    # (its oval outlines the face; the hits of oval points may lie anywhere on the side)
    span = (image[:, :2].max(0) - image[:, :2].min(0)).max() / seen_from.scale
    centre = hits[inner].mean(0)
    return look_from(-facing, up, centre, FACE_MARGIN * span, FACE_SIZE)


def _placed_from_depth(mesh: Mesh, pic: Picture, image: np.ndarray, hits: SurfacePoints,
                       snap: np.ndarray, surface: trimesh.Trimesh | None = None) -> tuple[SurfacePoints, np.ndarray]:
    """`hits` with the oval points, and the others whose hit is more than `DEPTH_CHECK`
    eye widths from the model's fitted point, re-placed from the model's 3D points `image`
    (468, 3) (module docstring, step 4); and (468,) bool of the points so placed."""
    fitted = np.zeros(N_POINTS, dtype=bool)
    fitted[list(FACE_OVAL)] = True
    view = pic.view
    model = view.to_world(np.column_stack([image[:, :2], image[:, 2] / view.scale]))
    at = hits.positions(mesh.vertices)
    fit = ~fitted & (snap == 0)
    if fit.sum() < 10:
        return hits, fitted
    scale, rotation, shift = similarity_transform(model[fit], at[fit])
    model = scale * model @ rotation.T + shift
    eye_width = np.linalg.norm(at[EYE_CORNERS[1]] - at[EYE_CORNERS[0]])
    astray = np.linalg.norm(model - at, axis=1) > DEPTH_CHECK * eye_width
    astray[list(INNER_UPPER_LIP + INNER_LOWER_LIP + MOUTH_CORNERS)] = False
    fitted |= astray
    corners, weights = _closest_surface_points(mesh, model[fitted], surface)
    tri, bary = hits.vertex_indices.copy(), hits.barycentric.copy()
    tri[fitted], bary[fitted] = corners, weights
    return SurfacePoints(tri, bary), fitted


def _halfway_to_depth(mesh: Mesh, pic: Picture, image: np.ndarray, points: SurfacePoints,
                      surface: trimesh.Trimesh | None = None) -> SurfacePoints:
    """`points` (468 on `mesh`, as `_placed_from_depth` leaves them) with each point but
    the lips, the eyes and the oval moved `DEPTH_BLEND` of the way toward the model's 3D
    point (`image` (468, 3) as `_landmarks_twice`), carried onto the surface by the
    similarity that best maps the model's inner points onto `points`, then snapped to
    the closest surface point (module docstring, step 5)."""
    view = pic.view
    model = view.to_world(np.column_stack([image[:, :2], image[:, 2] / view.scale]))
    at = points.positions(mesh.vertices)
    inner = np.ones(N_POINTS, dtype=bool)
    inner[list(FACE_OVAL)] = False
    scale, rotation, shift = similarity_transform(model[inner], at[inner])
    model = scale * model @ rotation.T + shift
    moved = inner.copy()
    moved[list(UPPER_LIP + LOWER_LIP + EYES)] = False
    goal = at[moved] + DEPTH_BLEND * (model[moved] - at[moved])
    corners, weights = _closest_surface_points(mesh, goal, surface)
    tri, bary = points.vertex_indices.copy(), points.barycentric.copy()
    tri[moved], bary[moved] = corners, weights
    return SurfacePoints(tri, bary)


def _toward_canonical_shape(mesh: Mesh, points: SurfacePoints,
                            surface: trimesh.Trimesh | None = None) -> SurfacePoints:
    """`points` (468 on `mesh`, as `_halfway_to_depth` leaves them) with the forehead,
    cheek, brow and nose points (but the iBUG ones) moved their `SHAPE_PULL` share of the
    way toward the place the other points give them (module docstring, step 6), then
    snapped to the closest surface point.

    The canonical face is carried onto the points outside `SHAPE_PULL`'s regions and the
    oval (lips, eyes, mouth corners, jaw inside the oval) by the similarity that best maps
    it there; each point's offset from its carried canonical vertex is known there and
    filled in over the others by the canonical mesh's graph Laplacian (each filled offset
    the mean of its neighbours'; the forehead, with no point above it, takes what the eyes
    give); a pulled point's place is its canonical vertex plus that offset."""
    pull, free, fill = _shape_pull()
    at = points.positions(mesh.vertices)
    canonical = canonical_face().vertices
    scale, rotation, shift = similarity_transform(canonical[~free], at[~free])
    carried = scale * canonical @ rotation.T + shift
    goal = at.copy()
    goal[free] = carried[free] + fill @ (at - carried)[~free]
    moved = np.flatnonzero(pull > 0)
    goal = at[moved] + pull[moved, None] * (goal[moved] - at[moved])
    corners, weights = _closest_surface_points(mesh, goal, surface)
    tri, bary = points.vertex_indices.copy(), points.barycentric.copy()
    tri[moved], bary[moved] = corners, weights
    return SurfacePoints(tri, bary)


@lru_cache(maxsize=1)
def _shape_pull() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(468,) each point's `SHAPE_PULL` share, (468,) bool the points whose offsets
    `_toward_canonical_shape` fills in (`SHAPE_PULL`'s regions and the oval), and
    (F, 468 - F) the map from the other points' offsets to theirs: the harmonic fill over
    the canonical face mesh's graph (degree minus adjacency, each filled offset the mean
    of its neighbours'). The share is 0 for the points that stay: the other regions, the
    jaw's oval among them, and the iBUG points, whose `OFFSETS` were measured where they
    are (the forehead's oval left too: seeds 0-13 22.23 against 22.19)."""
    layout = get_layout("mediapipe468")
    regions = np.asarray(layout.regions)
    pull = np.zeros(N_POINTS)
    for region, share in SHAPE_PULL.items():
        pull[regions == region] = share
    pull[np.asarray(layout.ibug68) >= 0] = 0.0
    free = np.isin(regions, list(SHAPE_PULL))
    free[list(FACE_OVAL)] = True
    triangles = canonical_face().triangles
    edges = np.vstack([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    adjacency = np.zeros((N_POINTS, N_POINTS))
    adjacency[edges[:, 0], edges[:, 1]] = adjacency[edges[:, 1], edges[:, 0]] = 1.0
    lap = laplacian(adjacency)
    fill = -np.linalg.solve(lap[np.ix_(free, free)], lap[np.ix_(free, ~free)])
    return pull, free, fill


def _wound_outward(mesh: Mesh) -> Mesh:
    """`mesh` with its triangles wound consistently outward (`retarget.winding`), which
    the pictures need to paint back faces dark (an inward or mixed winding, from a
    converter or a mirror, reads as a dark silhouette that shows no face); `mesh` itself
    when it already is."""
    faces = outward_faces(mesh.vertices, mesh.faces)
    if np.array_equal(faces, mesh.faces):
        return mesh
    faces.flags.writeable = False
    return replace(mesh, faces=faces)


def _as_wound(points: SurfacePoints, wound: Mesh, given: Mesh) -> SurfacePoints:
    """`points`, whose triangles are `wound`'s, with each triangle's corners (and their
    weights) in the order of the `given` mesh's same triangle (`_wound_outward` only swaps
    corners 1 and 2 of some)."""
    if wound is given:
        return points
    swapped = given.faces[:, 1] != wound.faces[:, 1]
    rows = lambda tri: np.ascontiguousarray(tri, np.int64).view(np.dtype((np.void, 24))).ravel()   # noqa: E731
    back = np.isin(rows(points.vertex_indices), rows(wound.faces[swapped]))
    order = np.where(back[:, None], [0, 2, 1], [0, 1, 2])
    return SurfacePoints(np.take_along_axis(points.vertex_indices, order, 1),
                         np.take_along_axis(points.barycentric, order, 1), points.layout)


def _surface(mesh: Mesh) -> trimesh.Trimesh:
    """`mesh` as a trimesh, whose closest-point search tree is built once for the steps that snap."""
    return trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)


def _closest_surface_points(mesh: Mesh, points: np.ndarray,
                            surface: trimesh.Trimesh | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(K, 3) triangle vertex indices and (K, 3) barycentric weights of the surface points
    closest to points (K, 3); `surface`: `mesh` as `_surface` gives it, or None to build it."""
    surface = _surface(mesh) if surface is None else surface
    closest, _, triangle = trimesh.proximity.closest_point(surface, points)
    corners = mesh.faces[triangle]
    weights = np.clip(trimesh.triangles.points_to_barycentric(mesh.vertices[corners], closest), 0.0, None)
    return corners, weights / weights.sum(1, keepdims=True)


def _confidence(normals: np.ndarray, points: SurfacePoints, view: View, snap: np.ndarray,
                fitted: np.ndarray, presence: float, textured: bool) -> np.ndarray:
    """(468,) 0..1: the presence, lowered for points that snapped (halved per 4 pixels),
    on grazing surface (by the cosine to the viewer), placed by the depth fit (`fitted`
    (468,) bool: the oval and the points that failed the depth check; at most 0.5) and, on a
    mesh without a texture, on the brows (at most 0.5): brows are hair, which a picture
    of bare geometry does not show, so the model guesses them from the brow ridge alone
    (15 mm off on the project's sample face, whose ridge is faint)."""
    n = points.positions(normals)
    facing = np.clip(-(n @ view.rotation[2]) / np.maximum(np.linalg.norm(n, axis=1), 1e-12), 0.0, 1.0)
    confidence = presence * 0.5 ** (snap / 4.0) * np.sqrt(facing)
    confidence[fitted] = np.minimum(confidence[fitted], 0.5)
    if not textured:
        brows = list(BROWS)
        confidence[brows] = np.minimum(confidence[brows], 0.5)
    return confidence
