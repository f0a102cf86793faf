"""Orthographic pictures of a mesh for the face mesh to look at, and the way back from a
pixel to the surface.

A face found in a picture is only useful if each of its points can be carried back onto
the mesh exactly, so the views are orthographic: a pixel's ray is the viewing direction
through it, and the z-buffer (`retarget.raster`) already holds the triangle and the
barycentric weights it hits. Shading is what a face detector trained on photographs
needs to see a face: Lambert under a light at the viewer or beside it (`relit`; its
texture when the mesh has one), with back faces dark, so that eye and mouth openings read
as dark holes as they do in a photograph.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import distance_transform_edt

from retarget.mesh import Mesh
from retarget.raster import Raster, rasterise
from retarget.sampling import sampled
from retarget.welding import welded

__all__ = ["AT_VIEWER", "View", "Picture", "look_from", "picture", "relit", "texture_rgb", "vertex_normals",
           "surface_hits"]

_BACKGROUND = 0
_BACK_FACE = 20
_AMBIENT = 0.25
_ALBEDO = 200.0
AT_VIEWER = np.array([0.0, 0.0, -1.0])   # a light at the viewer, in a view's axes


@dataclass(frozen=True, eq=False)
class View:
    """An orthographic camera.

    rotation : (3, 3) float64 rows: the image's x (right), its y (down) and the viewing
        direction (into the picture), in world coordinates.
    centre : (3,) float64 world point at the picture's centre.
    scale : pixels per world unit.
    size : side of the square picture, pixels.
    """

    rotation: np.ndarray
    centre: np.ndarray
    scale: float
    size: int

    def to_image(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) float64: pixels x, y (pixel centres at integers) and depth (world units
        along the viewing direction) of world points (..., 3)."""
        local = (np.asarray(points, dtype=np.float64) - self.centre) @ self.rotation.T
        half = (self.size - 1) / 2
        return np.concatenate([local[..., :2] * self.scale + half, local[..., 2:]], -1)

    def to_world(self, image: np.ndarray) -> np.ndarray:
        """(..., 3) float64 world points of image points (..., 3) (x, y pixels, depth in
        world units): the inverse of `to_image`."""
        p = np.asarray(image, dtype=np.float64)
        half = (self.size - 1) / 2
        local = np.concatenate([(p[..., :2] - half) / self.scale, p[..., 2:]], -1)
        return local @ self.rotation + self.centre


def look_from(direction: np.ndarray, up: np.ndarray, centre: np.ndarray, width: float, size: int) -> View:
    """The view looking along `direction` (3,) at `centre` (3,), `up` (3,) shown up the
    picture, `width` world units across its `size` pixels."""
    forward = np.asarray(direction, dtype=np.float64)
    forward = forward / np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, dtype=np.float64))
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return View(np.stack([right, down, forward]), np.asarray(centre, dtype=np.float64), size / width, size)


@dataclass(frozen=True, eq=False)
class Picture:
    """One view of a mesh: rgb (size, size, 3) uint8 and what each pixel sees."""

    view: View
    rgb: np.ndarray
    raster: Raster


def picture(mesh: Mesh, view: View, normals: np.ndarray, texture: np.ndarray | None = None) -> Picture:
    """The mesh seen through `view`: Lambert-shaded grey, or its texture (rgb (h, w, 3)
    uint8 sampled with the mesh's uv) times the shading, lit from the viewer; back faces
    dark.

    normals : (V, 3) unit vertex normals (`vertex_normals`), computed once per mesh.
    """
    image_points = view.to_image(mesh.vertices)
    raster = rasterise(image_points[:, :2], image_points[:, 2], mesh.faces, (view.size, view.size),
                       perspective=False, cull_back=False)
    return Picture(view, _shaded(view, raster, mesh, normals, texture, AT_VIEWER[None])[0], raster)


def relit(pic: Picture, mesh: Mesh, normals: np.ndarray, texture: np.ndarray | None,
          lights: np.ndarray) -> list[Picture]:
    """`pic` shaded again under each light of `lights` (L, 3), directions toward the light
    in the view's axes (x right, y down, z into the picture; `AT_VIEWER` is (0, 0, -1)).
    The raster, the pixels' normals and albedo are shared: a light costs one shading pass
    over the seen pixels, not a rasterisation."""
    return [Picture(pic.view, rgb, pic.raster)
            for rgb in _shaded(pic.view, pic.raster, mesh, normals, texture, lights)]


def _shaded(view: View, raster: Raster, mesh: Mesh, normals: np.ndarray, texture: np.ndarray | None,
            lights: np.ndarray) -> list[np.ndarray]:
    """(size, size, 3) uint8 rgb of the raster under each light of `lights` (L, 3) (as
    `relit`)."""
    seen = raster.triangle >= 0
    bary = raster.barycentric[seen]
    corners = mesh.faces[raster.triangle[seen]]
    n = np.einsum("pk,pkc->pc", bary, normals[corners])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    if texture is not None and mesh.uv is not None:
        uv = np.einsum("pk,pkc->pc", bary, mesh.uv[corners])
        h, w = texture.shape[:2]
        x = (np.mod(uv[:, 0], 1.0) * w - 0.5).astype(np.float32)
        y = ((1.0 - np.mod(uv[:, 1], 1.0)) * h - 0.5).astype(np.float32)  # OBJ's v runs up
        albedo = sampled(texture, x, y, border=cv2.BORDER_WRAP).astype(np.float64)
    else:
        albedo = np.full((len(n), 3), _ALBEDO)
    back = ~raster.front[seen]
    facing = np.clip(n @ (np.asarray(lights, dtype=np.float64) @ view.rotation).T, 0.0, 1.0)   # (P, L)
    out = []
    for shade in (_AMBIENT + (1.0 - _AMBIENT) * facing).T:
        color = albedo * shade[:, None]
        color[back] = _BACK_FACE
        rgb = np.full((view.size, view.size, 3), _BACKGROUND, dtype=np.uint8)
        rgb[seen] = np.clip(np.rint(color), 0, 255).astype(np.uint8)
        out.append(rgb)
    return out


def texture_rgb(mesh: Mesh) -> np.ndarray | None:
    """The mesh's base colour texture as (h, w, 3) uint8 RGB, or None without one."""
    png = mesh.material.base_color_texture if mesh.material is not None else None
    if png is None or mesh.uv is None:
        return None
    bgr = cv2.imdecode(np.frombuffer(png, dtype=np.uint8), cv2.IMREAD_COLOR)
    return None if bgr is None else np.ascontiguousarray(bgr[..., ::-1])


def vertex_normals(mesh: Mesh) -> np.ndarray:
    """(V, 3) float64 area-weighted unit vertex normals (zero for unused vertices), summed
    over every triangle at the vertex's position (`retarget.welding`): a UV seam shows no
    crease in the shading, and an STL's triangle soup is shaded smooth, not faceted."""
    v, f = mesh.vertices, mesh.faces
    at = welded(v, f).index
    face_normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n = np.stack([np.bincount(at[f].ravel(), np.repeat(face_normals[:, k], 3), len(v)) for k in range(3)], 1)[at]
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def surface_hits(pic: Picture, mesh: Mesh, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the rays through `pixels` (K, 2) (x, y) meet the front of the mesh.

    A ray that meets a front face is followed exactly (orthographic: the point's
    barycentric weights in the triangle its pixel sees). One that falls into a hole, on a
    back face or off the mesh snaps to the nearest pixel that sees a front face, as a
    user would move a point that slipped into an eye opening onto the lid.

    Returns triangles (K,) int64, barycentric (K, 3) float64 and snap (K,) float64: how
    far (pixels) the point had to move, 0 for an exact hit.
    """
    front = pic.raster.front & (pic.raster.triangle >= 0)
    size = pic.view.size
    xy = np.clip(np.asarray(pixels, dtype=np.float64), 0, size - 1)
    col, row = np.rint(xy).astype(np.int64).T
    _, (near_row, near_col) = distance_transform_edt(~front, return_indices=True)
    r, c = near_row[row, col], near_col[row, col]
    snap = np.hypot(r - xy[:, 1], c - xy[:, 0]) * ~front[row, col]
    target = np.where(front[row, col, None], xy, np.column_stack([c, r]).astype(np.float64))
    triangles = pic.raster.triangle[r, c]
    corners = pic.view.to_image(mesh.vertices[mesh.faces[triangles]])[..., :2]   # (K, 3, 2)
    return triangles, _barycentric_clamped(target, corners), snap


def _barycentric_clamped(p: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(K, 3) weights of 2D points p (K, 2) in triangles (K, 3, 2), clamped into the
    triangle (a pixel centre's triangle may hold the exact point only to within a pixel)."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    e1, e2, d = b - a, c - a, p - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    safe = np.where(np.abs(det) > 1e-12, det, 1.0)
    wb = (d[:, 0] * e2[:, 1] - d[:, 1] * e2[:, 0]) / safe
    wc = (e1[:, 0] * d[:, 1] - e1[:, 1] * d[:, 0]) / safe
    w = np.clip(np.column_stack([1.0 - wb - wc, wb, wc]), 0.0, None)
    total = w.sum(1, keepdims=True)
    return np.where(total > 0, w / np.where(total > 0, total, 1.0), 1.0 / 3.0)
