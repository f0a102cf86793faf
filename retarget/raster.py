"""A z-buffer rasteriser of triangle meshes in numpy: which triangle, where in it, and how
deep each pixel sees.

Used to render test material (`retarget.testing.render`, perspective) and the views the
face mesh searches for landmarks on (`retarget.facemesh.views`, orthographic). Pixel
centres sit at integer coordinates (the top-left pixel covers [-0.5, 0.5)^2), x right and
y down.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Raster", "rasterise"]


@dataclass(frozen=True, eq=False)
class Raster:
    """What each pixel of an (h, w) image sees.

    triangle : (h, w) int64 index of the nearest triangle, -1 where none.
    barycentric : (h, w, 3) float64 the pixel centre's weights in that triangle (zeros
        where none), perspective-correct for a perspective projection.
    depth : (h, w) float64 depth of the surface at the pixel centre, inf where none.
    front : (h, w) bool the triangle turns its front (counter-clockwise side) to the viewer.
    """

    triangle: np.ndarray
    barycentric: np.ndarray
    depth: np.ndarray
    front: np.ndarray


def rasterise(pixels: np.ndarray, depth: np.ndarray, faces: np.ndarray, size: tuple[int, int], *,
              perspective: bool = True, cull_back: bool = True) -> Raster:
    """Z-buffer of a mesh already projected to the image.

    pixels : (V, 2) float vertex positions in pixels (x right, y down).
    depth : (V,) float vertex depths along the viewing axis (positive in front of the
        viewer for a perspective projection; any sign for an orthographic one).
    faces : (T, 3) int, counter-clockwise seen from the front in a y-up world, so
        clockwise in the y-down image.
    size : (width, height) of the image.
    perspective : interpolate 1/depth affinely (a pinhole camera); else depth itself (an
        orthographic view).
    cull_back : draw front faces only; else back faces too (`Raster.front` tells them apart).
    """
    w, h = size
    uv = np.asarray(pixels, dtype=np.float64)
    z = np.asarray(depth, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    a, b, c = uv[f[:, 0]], uv[f[:, 1]], uv[f[:, 2]]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    keep = (area < -1e-12) if cull_back else (np.abs(area) > 1e-12)
    keep &= np.all(np.isfinite(uv[f]), axis=(1, 2))
    if perspective:
        keep &= np.all(z[f] > 1e-6, axis=1)
    tri_ids = np.flatnonzero(keep)
    corners = uv[f[tri_ids]]                                   # (T', 3, 2)
    lo = np.clip(np.ceil(corners.min(1) - 1e-9), 0, [w - 1, h - 1]).astype(np.int64)
    hi = np.clip(np.floor(corners.max(1) + 1e-9), [-1, -1], [w - 1, h - 1]).astype(np.int64)
    span = np.maximum(hi - lo + 1, 0)
    count = span[:, 0] * span[:, 1]
    k = np.repeat(np.arange(len(tri_ids)), count)
    local = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    px = lo[k, 0] + local % span[k, 0]
    py = lo[k, 1] + local // span[k, 0]
    ca, cb, cc = corners[k, 0], corners[k, 1], corners[k, 2]
    dx, dy = px - ca[:, 0], py - ca[:, 1]
    denom = area[tri_ids][k]
    lb = (dx * (cc[:, 1] - ca[:, 1]) - dy * (cc[:, 0] - ca[:, 0])) / denom
    lc = ((cb[:, 0] - ca[:, 0]) * dy - (cb[:, 1] - ca[:, 1]) * dx) / denom
    screen = np.stack([1.0 - lb - lc, lb, lc], 1)
    inside = np.all(screen >= -1e-9, axis=1)
    k, px, py, screen = k[inside], px[inside], py[inside], screen[inside]
    pixel = py * w + px
    if perspective:
        # 1/z is affine in screen space: interpolate it, and attributes as attribute / z
        over_z = screen / z[f[tri_ids[k]]]
        nearness = over_z.sum(1)
        weights = over_z / nearness[:, None]
    else:
        nearness = -np.einsum("pk,pk->p", screen, z[f[tri_ids[k]]])
        weights = screen
    best = np.full(h * w, -np.inf)
    np.maximum.at(best, pixel, nearness)
    win = nearness >= best[pixel]
    tri = np.full(h * w, -1, dtype=np.int64)
    bary = np.zeros((h * w, 3))
    tri[pixel[win]] = tri_ids[k[win]]
    bary[pixel[win]] = weights[win]
    seen = np.isfinite(best)
    out_depth = np.full(h * w, np.inf)
    out_depth[seen] = 1.0 / best[seen] if perspective else -best[seen]
    front = np.zeros(h * w, dtype=bool)
    front[seen] = area[tri[seen]] < 0
    return Raster(tri.reshape(h, w), bary.reshape(h, w, 3), out_depth.reshape(h, w), front.reshape(h, w))
