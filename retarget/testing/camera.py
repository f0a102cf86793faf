"""A pinhole camera in OpenCV's convention, for rendering test material with known truth.

Camera axes: x right, y down, the camera looks along +z. A world point X maps to camera
coordinates ``R @ X + t``, then to pixels through the intrinsics K after OpenCV's
distortion model (k1, k2, p1, p2[, k3]), exactly as ``cv2.projectPoints`` does, so
calibration code can be checked against it. Pixel centres sit at integer coordinates: the
top-left pixel covers [-0.5, 0.5)^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.errors import RetargetError

__all__ = ["Camera", "look_at"]


@dataclass(frozen=True, eq=False)
class Camera:
    """Intrinsics, pose and image size of one camera.

    K : (3, 3) float64 intrinsic matrix (pixels).
    R : (3, 3) float64 rotation world -> camera.
    t : (3,) float64 translation world -> camera (world units, e.g. cm).
    size : (width, height) of the image in pixels.
    dist : (5,) float64 OpenCV distortion (k1, k2, p1, p2, k3), or None for none.
    """

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    size: tuple[int, int] = (640, 480)
    dist: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name, shape in (("K", (3, 3)), ("R", (3, 3)), ("t", (3,))):
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.shape != shape or not np.all(np.isfinite(value)):
                raise RetargetError(f"Camera {name} must be finite with shape {shape}, got {value.shape}")
            object.__setattr__(self, name, value)
        if not np.allclose(self.R @ self.R.T, np.eye(3), atol=1e-6) or np.linalg.det(self.R) < 0:
            raise RetargetError("Camera R must be a rotation matrix (orthonormal, det +1)")
        size = tuple(int(s) for s in self.size)
        if len(size) != 2 or min(size) < 1:
            raise RetargetError(f"Camera size must be (width, height) >= 1, got {self.size!r}")
        object.__setattr__(self, "size", size)
        if self.dist is not None:
            dist = np.zeros(5)
            given = np.asarray(self.dist, dtype=np.float64).ravel()
            if given.size not in (4, 5) or not np.all(np.isfinite(given)):
                raise RetargetError(f"Camera dist must hold 4 or 5 finite values, got {given.size}")
            dist[: given.size] = given
            object.__setattr__(self, "dist", dist)

    @property
    def center(self) -> np.ndarray:
        """(3,) float64 camera centre in world coordinates."""
        return -self.R.T @ self.t

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) float64 camera coordinates of world points (..., 3)."""
        return _linear(np.asarray(points, dtype=np.float64), self.R) + self.t

    def depth(self, points: np.ndarray) -> np.ndarray:
        """(...,) float64 distance of world points (..., 3) along the viewing axis."""
        return self.to_camera(points)[..., 2]

    def project(self, points: np.ndarray) -> np.ndarray:
        """(..., 2) float64 pixel positions of world points (..., 3) (x right, y down).

        Points at or behind the camera plane (depth <= 0) project to NaN.
        """
        c = self.to_camera(points)
        z = c[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = np.where((z > 0)[..., None], c[..., :2] / z[..., None], np.nan)
        xy = self._distorted(xy)
        return xy * self.K[[0, 1], [0, 1]] + xy[..., ::-1] * [self.K[0, 1], 0.0] + self.K[:2, 2]

    def rays(self, pixels: np.ndarray) -> np.ndarray:
        """(..., 3) float64 unit world directions of the rays through pixels (..., 2).

        The rays start at `center`; distortion is inverted by Newton's method.
        """
        px = np.asarray(pixels, dtype=np.float64)
        flat = px.reshape(-1, 2)
        fy, cy = self.K[1, 1], self.K[1, 2]
        y = (flat[:, 1] - cy) / fy
        x = (flat[:, 0] - self.K[0, 2] - self.K[0, 1] * y) / self.K[0, 0]
        xy = self._undistorted(np.stack([x, y], 1))
        d = _linear(np.concatenate([xy, np.ones((len(xy), 1))], 1), self.R.T)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return d.reshape(px.shape[:-1] + (3,))

    def to_dict(self) -> dict:
        """JSON-able description; `from_dict` inverts it."""
        return {
            "K": self.K.tolist(), "R": self.R.tolist(), "t": self.t.tolist(),
            "size": list(self.size), "dist": None if self.dist is None else self.dist.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict) -> Camera:
        """The camera `to_dict` described; RetargetError naming a missing key."""
        missing = [k for k in ("K", "R", "t", "size") if k not in data]
        if missing:
            raise RetargetError(f"camera description lacks {', '.join(missing)}")
        return cls(data["K"], data["R"], data["t"], tuple(data["size"]), data.get("dist"))

    def _undistorted(self, xd: np.ndarray) -> np.ndarray:
        """(M, 2) normalised coordinates whose distortion is xd (M, 2) (Newton's method)."""
        if self.dist is None:
            return xd
        k1, k2, p1, p2, k3 = self.dist
        xy = xd.copy()
        for _ in range(20):
            x, y = xy[:, 0], xy[:, 1]
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            slope = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)          # d radial / d r2
            cross = 2.0 * x * y * slope + 2.0 * p1 * x + 2.0 * p2 * y
            jxx = radial + 2.0 * x * x * slope + 2.0 * p1 * y + 6.0 * p2 * x
            jyy = radial + 2.0 * y * y * slope + 6.0 * p1 * y + 2.0 * p2 * x
            res = self._distorted(xy) - xd
            if np.abs(res).max(initial=0.0) < 1e-13:
                break
            det = jxx * jyy - cross * cross
            xy[:, 0] -= (jyy * res[:, 0] - cross * res[:, 1]) / det
            xy[:, 1] -= (jxx * res[:, 1] - cross * res[:, 0]) / det
        return xy

    def _distorted(self, xy: np.ndarray) -> np.ndarray:
        """Normalised image coordinates (..., 2) through OpenCV's radial-tangential model."""
        if self.dist is None:
            return xy
        k1, k2, p1, p2, k3 = self.dist
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        return np.stack([xd, yd], -1)


def _linear(points: np.ndarray, M: np.ndarray) -> np.ndarray:
    """(..., 3) M @ p for points (..., 3) and M (3, 3), as three axpys: a tall (M, 3) @ (3, 3)
    goes through BLAS threads, tens of times slower on a busy machine."""
    return points[..., 0, None] * M[:, 0] + points[..., 1, None] * M[:, 1] + points[..., 2, None] * M[:, 2]


def look_at(
    eye: np.ndarray,
    target: np.ndarray,
    up: np.ndarray = (0.0, 1.0, 0.0),
    fov_deg: float = 30.0,
    size: tuple[int, int] = (640, 480),
    dist: np.ndarray | None = None,
) -> Camera:
    """A camera at `eye` (3,) looking at `target` (3,), world `up` (3,) shown up the image.

    fov_deg : vertical field of view in degrees; square pixels, principal point at the
        image centre ((w - 1) / 2, (h - 1) / 2).
    """
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    forward = target - eye
    if np.linalg.norm(forward) == 0:
        raise RetargetError("look_at: eye and target coincide")
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    if np.linalg.norm(right) < 1e-9:
        raise RetargetError("look_at: up is parallel to the viewing direction")
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    if not 0 < fov_deg < 180:
        raise RetargetError(f"look_at: fov_deg must be in (0, 180), got {fov_deg!r}")
    w, h = size
    f = 0.5 * h / np.tan(np.radians(fov_deg) / 2)
    K = np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
    R = np.stack([right, down, forward])
    return Camera(K, R, -R @ eye, (w, h), dist)
