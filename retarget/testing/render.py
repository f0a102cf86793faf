"""A small software renderer for test material: shaded meshes with markers, checkerboards.

Nothing here aims at realism beyond what the trackers need: a z-buffered, Lambert-shaded
mesh (Gouraud normals, perspective-correct interpolation), and markers drawn as flat discs
on the mesh's tangent plane at chosen vertices, supersampled so that the centroid of a
drawn marker is the projection of its vertex to a few hundredths of a pixel. Two styles:

- ``"ring"``: a white dot inside a black ring, the markers of Dutreve et al. 2008, §5
  ("white markers ... we draw black circles on them" to raise their contrast);
- ``"color"``: saturated coloured discs, the markers of Woodward et al., §5, told apart by
  hue.

Images are BGR uint8 (OpenCV's order); geometry is in the camera's world units (cm for
`retarget.sample_face`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.errors import RetargetError
from retarget.raster import rasterise
from retarget.testing.camera import Camera

__all__ = [
    "MARKER_COLORS",
    "MARKER_STYLES",
    "FaceRender",
    "BoardRender",
    "vertex_normals",
    "render_face",
    "render_checkerboard",
]

MARKER_STYLES = ("ring", "color")

MARKER_COLORS: dict[str, tuple[int, int, int]] = {
    "red": (40, 40, 230),
    "green": (40, 200, 40),
    "blue": (230, 80, 30),
    "yellow": (30, 220, 230),
    "magenta": (220, 40, 220),
    "cyan": (230, 220, 30),
}
"""BGR colours of the "color" style, in the order markers cycle through them by default."""

_SKIN = np.array([120.0, 150.0, 200.0])      # BGR albedo
_WHITE, _BLACK = 245.0, 18.0                   # ring-marker albedos (grey levels)
_LIGHT = np.array([0.35, 0.45, 1.0]) / np.linalg.norm([0.35, 0.45, 1.0])  # toward the light
_AMBIENT, _DIFFUSE = 0.35, 0.65
_MIN_FACING = 0.3   # cos of the viewing angle below which a marker counts as not visible


@dataclass(frozen=True, eq=False)
class FaceRender:
    """One rendered view.

    image : (h, w, 3) uint8 BGR.
    depth : (h, w) float64 camera depth of the mesh at each pixel centre, inf off the mesh.
    points2d : (N,) -> (N, 2) float64 projected marker centres (pixels, x right, y down).
    visible : (N,) bool: the marker faces the camera (cos > 0.3) and all of its disc is
        drawn (inside the image, unoccluded), so its centroid is its projected centre.
    coverage : (N,) float64 share of the disc that is drawn.
    """

    image: np.ndarray
    depth: np.ndarray
    points2d: np.ndarray
    visible: np.ndarray
    coverage: np.ndarray


@dataclass(frozen=True, eq=False)
class BoardRender:
    """One rendered checkerboard view.

    image : (h, w, 3) uint8 BGR.
    corners3d : (rows * cols, 3) float64 inner corners in world units, row-major (x fastest):
        the order of ``cv2.findChessboardCorners`` when the board's +z points away from the
        camera (+y down the image as +x goes across), up to its 180-degree ambiguity.
    object_points : (rows * cols, 3) float32 the same corners on the board (z = 0), as
        ``cv2.calibrateCamera`` takes them.
    corners2d : (rows * cols, 2) float64 their projections (pixels).
    """

    image: np.ndarray
    corners3d: np.ndarray
    object_points: np.ndarray
    corners2d: np.ndarray


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) float64 unit area-weighted normals of a mesh (V, 3), (T, 3) counter-clockwise."""
    v = np.asarray(vertices, dtype=np.float64)
    a, b, c = v[faces[:, 0]], v[faces[:, 1]], v[faces[:, 2]]
    fn = np.cross(b - a, c - a)
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def render_face(
    camera: Camera,
    vertices: np.ndarray,
    faces: np.ndarray,
    marker_vertices: np.ndarray = (),
    *,
    style: str = "ring",
    marker_radius: float = 0.3,
    dot_radius: float = 0.15,
    marker_colors: np.ndarray | None = None,
    skin: np.ndarray = _SKIN,
    background: float = 45.0,
    noise: float = 0.0,
    rng: np.random.Generator | None = None,
    supersample: int = 4,
) -> FaceRender:
    """A shaded mesh with markers at some of its vertices.

    camera : the view.
    vertices : (V, 3) float world positions; faces : (T, 3) int, counter-clockwise seen
        from outside (back faces are culled).
    marker_vertices : (N,) int vertices carrying a marker (none by default).
    style : "ring" (white dot of `dot_radius` in a black ring of `marker_radius`) or
        "color" (a disc of `marker_radius` in `marker_colors`).
    marker_radius, dot_radius : world units (cm for the sample face).
    marker_colors : (N, 3) BGR 0-255 for "color"; default cycles through `MARKER_COLORS`.
    skin : (3,) BGR albedo of the mesh; background : grey level off the mesh.
    noise : standard deviation (grey levels) of Gaussian sensor noise, drawn from `rng`.
    supersample : marker samples per pixel along each axis (anti-aliasing).
    """
    if style not in MARKER_STYLES:
        raise RetargetError(f"style must be one of {MARKER_STYLES}, got {style!r}")
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise RetargetError(f"vertices must be (V, 3) and faces (T, 3), got {v.shape} and {f.shape}")
    markers = np.asarray(marker_vertices, dtype=np.int64).reshape(-1)
    if markers.size and (markers.min() < 0 or markers.max() >= len(v)):
        raise RetargetError(f"marker_vertices must index the {len(v)} vertices")
    if style == "ring" and not 0 < dot_radius < marker_radius:
        raise RetargetError(f"need 0 < dot_radius < marker_radius, got {dot_radius} and {marker_radius}")
    normals = vertex_normals(v, f)
    w, h = camera.size
    raster = rasterise(camera.project(v), camera.depth(v), f, camera.size)
    tri, bary, depth = raster.triangle, raster.barycentric, raster.depth
    image = np.full((h, w, 3), float(background))
    hit = tri >= 0
    n = np.einsum("pk,pkc->pc", bary[hit], normals[f[tri[hit]]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    image[hit] = np.asarray(skin, dtype=np.float64) * _shade(n)[:, None]
    points2d = camera.project(v[markers])
    if markers.size:
        if marker_colors is None:
            palette = np.array(list(MARKER_COLORS.values()), dtype=np.float64)
            marker_colors = palette[np.arange(markers.size) % len(palette)]
        colors = np.asarray(marker_colors, dtype=np.float64).reshape(-1, 3)
        if style == "color" and len(colors) != markers.size:
            raise RetargetError(f"marker_colors must be ({markers.size}, 3), got {colors.shape}")
        coverage, facing = _draw_markers(
            image, depth, camera, v[markers], normals[markers], style,
            marker_radius, dot_radius, colors, supersample)
    else:
        coverage, facing = np.zeros(0), np.zeros(0, dtype=bool)
    if noise > 0:
        rng = np.random.default_rng() if rng is None else rng
        image += rng.normal(0.0, noise, image.shape)
    out = np.clip(np.rint(image), 0, 255).astype(np.uint8)
    return FaceRender(out, depth, points2d, facing & (coverage > 0.99), coverage)


def render_checkerboard(
    camera: Camera,
    pose: tuple[np.ndarray, np.ndarray],
    rows: int,
    cols: int,
    square: float,
    *,
    background: float = 90.0,
) -> BoardRender:
    """A planar checkerboard seen by `camera`, for calibration tests.

    pose : (R (3, 3), t (3,)) board -> world: board point (x, y, 0) is at ``R @ p + t``.
    rows, cols : inner corners down and across (OpenCV's pattern size is (cols, rows));
        the board has (rows + 1) x (cols + 1) squares, the corner square at (-1, -1)
        black, inside a white margin one square wide.
    square : side of a square in world units; background : grey level off the board.

    Anti-aliased analytically: each pixel is box-filtered over the board-plane box that
    bounds its footprint (separable, so exact for the checker's xor of two square waves
    on that box), which keeps every corner where the geometry puts it.
    """
    if min(rows, cols) < 2 or square <= 0:
        raise RetargetError(f"a checkerboard needs rows, cols >= 2 and square > 0, got {rows}, {cols}, {square}")
    R_b, t_b = (np.asarray(a, dtype=np.float64) for a in pose)
    w, h = camera.size
    ys, xs = np.mgrid[0:h + 1, 0:w + 1].astype(np.float64) - 0.5       # pixel corners
    uv_corner, ok_corner = _board_coords(camera, R_b, t_b, np.stack([xs, ys], -1))
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    uv, ok = _board_coords(camera, R_b, t_b, np.stack([xs, ys], -1))
    uv /= square
    uv_corner /= square
    dx = 0.5 * (uv_corner[:-1, 1:] - uv_corner[:-1, :-1] + uv_corner[1:, 1:] - uv_corner[1:, :-1])
    dy = 0.5 * (uv_corner[1:, :-1] - uv_corner[:-1, :-1] + uv_corner[1:, 1:] - uv_corner[:-1, 1:])
    width = np.abs(dx) + np.abs(dy) + 1e-9                             # (h, w, 2) in squares
    ok &= ok_corner[:-1, :-1] & ok_corner[1:, 1:] & ok_corner[:-1, 1:] & ok_corner[1:, :-1]
    lo, hi = uv - 0.5 * width, uv + 0.5 * width
    pattern = _box_overlap(lo, hi, [-1.0, -1.0], [cols, rows])
    # the checker's share of the part of the box that lies on the pattern
    lo_in, hi_in = np.maximum(lo, [-1.0, -1.0]), np.minimum(hi, [cols, rows])
    span = np.maximum(hi_in - lo_in, 1e-9)
    wave = (_square_wave_integral(lo_in + span) - _square_wave_integral(lo_in)) / span
    black = 0.5 * (1.0 + wave[..., 0] * wave[..., 1])      # cells (i, j) with i + j even
    board = _box_overlap(lo, hi, [-2.0, -2.0], [cols + 1.0, rows + 1.0]) * ok
    white, dark = 235.0, 20.0
    gray = board * (white - (white - dark) * pattern * black) + (1.0 - board) * float(background)
    image = np.repeat(np.clip(np.rint(gray), 0, 255).astype(np.uint8)[..., None], 3, 2)
    j, i = np.meshgrid(np.arange(cols), np.arange(rows))
    obj = np.stack([j.ravel() * square, i.ravel() * square, np.zeros(rows * cols)], 1)
    corners3d = obj @ R_b.T + t_b
    return BoardRender(image, corners3d, obj.astype(np.float32), camera.project(corners3d))


def _board_coords(camera, R_b, t_b, pixels):
    """(..., 2) board-plane coordinates where the rays through pixels (..., 2) meet the
    board, and (...,) bool where they meet it in front of the camera."""
    d = camera.rays(pixels)
    normal = R_b[:, 2]
    facing = np.einsum("...k,k->...", d, normal)
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = (normal @ (t_b - camera.center)) / facing
    ok = np.isfinite(lam) & (lam > 0)
    hit = camera.center + np.where(ok, lam, 0.0)[..., None] * d - t_b
    return np.stack([hit @ R_b[:, 0], hit @ R_b[:, 1]], -1), ok


def _square_wave_integral(u):
    """Integral from 0 to u of the square wave +1 on [0, 1), -1 on [1, 2) (period 2)."""
    return 1.0 - np.abs(np.mod(u, 2.0) - 1.0)


def _box_overlap(lo, hi, a, b):
    """(...) share of the box [lo, hi] (..., 2) inside the rectangle [a, b] (2,)."""
    share = (np.minimum(hi, b) - np.maximum(lo, a)).clip(0.0) / (hi - lo)
    return share[..., 0] * share[..., 1]


def _shade(normals: np.ndarray) -> np.ndarray:
    """(...,) Lambert factor of unit normals (..., 3) under the fixed key light."""
    return _AMBIENT + _DIFFUSE * np.clip(normals @ _LIGHT, 0.0, None)


def _draw_markers(image, depth, camera, centres, normals, style, radius, dot_radius,
                  colors, supersample):
    """Composite the markers into `image` (h, w, 3) float in place.

    Each marker is a disc on the tangent plane at its centre (N, 3) with normal (N, 3);
    every pixel of its footprint is sampled `supersample`^2 times, and a sample is drawn
    where its ray meets the disc no more than one marker radius behind the z-buffer (a
    flat sticker on a curved patch, such as the slope under the lower lip, dips under
    the surface by up to about that; a real occluder is centimetres in front).
    Markers facing away are not drawn.
    Returns (coverage (N,) float64, facing (N,) bool: cos of the viewing angle > 0.3).
    """
    h, w = depth.shape
    eye = camera.center
    to_eye = eye - centres
    cos = np.einsum("nk,nk->n", normals, to_eye) / np.linalg.norm(to_eye, axis=1)
    centre_px = camera.project(centres)
    z = camera.depth(centres)
    focal = camera.K[[0, 1], [0, 1]].max()
    reach = int(np.ceil(np.nanmax(np.where(z > 0, focal * radius / z, 0.0)) * 1.3)) + 2
    grid = np.arange(-reach, reach + 1)
    s = supersample
    offsets = (np.arange(s) + 0.5) / s - 0.5
    base = np.nan_to_num(np.rint(centre_px), nan=-10 * reach).astype(np.int64)   # (N, 2)
    gx = base[:, 0, None, None] + grid[None, None, :]                             # (N, 1, P)
    gy = base[:, 1, None, None] + grid[None, :, None]                             # (N, P, 1)
    gx, gy = np.broadcast_arrays(gx, gy)
    sx = gx[..., None, None] + offsets[None, None, None, None, :]
    sy = gy[..., None, None] + offsets[None, None, None, :, None]
    sx, sy = np.broadcast_arrays(sx, sy)
    rays = camera.rays(np.stack([sx, sy], -1))                    # (N, P, P, s, s, 3)
    nn = normals[:, None, None, None, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.einsum("nk,nk->n", normals, centres - eye)[:, None, None, None, None] / np.sum(rays * nn, -1)
    hit = eye + lam[..., None] * rays
    rho = np.linalg.norm(hit - centres[:, None, None, None, None, :], axis=-1)
    disc = (lam > 0) & (rho < radius) & (cos > 0)[:, None, None, None, None]
    in_image = (gx >= 0) & (gx < w) & (gy >= 0) & (gy < h)
    surface = np.full(gx.shape, np.inf)
    surface[in_image] = depth[gy[in_image], gx[in_image]]
    sample_depth = camera.depth(hit)
    drawn = disc & in_image[..., None, None] & (sample_depth <= surface[..., None, None] + radius)
    total = disc.sum((1, 2, 3, 4))
    coverage = np.divide(drawn.sum((1, 2, 3, 4)), total, out=np.zeros(len(centres)), where=total > 0)
    shade = _shade(normals)
    if style == "ring":
        value = np.where(rho < dot_radius, _WHITE, _BLACK)[..., None] * np.ones(3)
        value = value * shade[:, None, None, None, None, None]
    else:
        value = np.broadcast_to((colors * shade[:, None])[:, None, None, None, None, :], rho.shape + (3,))
    weight = drawn.mean((3, 4))                                   # (N, P, P) pixel cover
    paint = (value * drawn[..., None]).mean((3, 4))               # (N, P, P, 3)
    cover = np.zeros((h, w))
    color = np.zeros((h, w, 3))
    sel = weight > 0
    np.add.at(cover, (gy[sel], gx[sel]), weight[sel])
    np.add.at(color, (gy[sel], gx[sel]), paint[sel])
    over = cover > 1.0                                            # overlapping markers share
    color[over] /= cover[over, None]
    cover = np.minimum(cover, 1.0)
    image *= 1.0 - cover[..., None]
    image += color
    return coverage, cos > _MIN_FACING
