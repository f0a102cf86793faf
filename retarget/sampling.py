"""An image sampled at any number of points.

`cv2.remap` samples an image at the points of a map, but refuses a map 32767 or more rows
or columns long (SHRT_MAX): a list of points given as one column fails past that, as the
landmark finder's textured picture did (its straight view shows about 100,000 pixels of
face). `sampled` lays the points out in rows of `_ROW` for it.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["sampled"]

_ROW = 1024


def sampled(image: np.ndarray, x, y, interpolation: int = cv2.INTER_LINEAR,
            border: int = cv2.BORDER_REPLICATE) -> np.ndarray:
    """(*shape, C) or (*shape) values of `image` (h, w[, C]) at pixel positions x, y (float
    arrays of one shape; pixel centres at integers), as `cv2.remap` gives them."""
    xs = np.asarray(x, np.float32)
    ys = np.asarray(y, np.float32)
    n = xs.size
    rows = max(1, -(-n // _ROW))
    grid = [np.pad(a.ravel(), (0, rows * _ROW - n)).reshape(rows, _ROW) for a in (xs, ys)]
    out = cv2.remap(image, grid[0], grid[1], interpolation, borderMode=border)
    return out.reshape(rows * _ROW, *out.shape[2:])[:n].reshape(*xs.shape, *out.shape[2:])
