"""The least-squares similarity between two point sets (Umeyama 1991, "Least-squares
estimation of transformation parameters between two point patterns", eq. 40-42)."""

from __future__ import annotations

import numpy as np

__all__ = ["similarity_transform"]


def similarity_transform(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(s, R (3, 3), t (3,)) minimising sum |dst - (s R src + t)|^2 over points src, dst
    (K, 3), K >= 3 not all on a line; R is a proper rotation (det +1)."""
    mu_s, mu_d = src.mean(0), dst.mean(0)
    a, b = src - mu_s, dst - mu_d
    u, sigma, vt = np.linalg.svd(b.T @ a / len(src))
    d = np.ones(3)
    d[2] = np.sign(np.linalg.det(u @ vt)) or 1.0
    rotation = (u * d) @ vt
    scale = float((sigma * d).sum() / (a ** 2).sum(1).mean())
    return scale, rotation, mu_d - scale * rotation @ mu_s
