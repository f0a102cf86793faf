"""Weights of deformers that minimise a quadratic surface energy under feature constraints.

Zhang et al. §2.2 (eq. 7, after Sorkine et al. 2004) and the biharmonic deformer solve

    min_d  dᵀ Q d + w² Σ_j |C_j d - c_j|²

for vertex displacements d given feature displacements c, where Q (V, V) is a positive
semi-definite energy and C (N, V) evaluates the mesh at each feature's surface point. The
minimiser is linear in c:

    d = (Q + w² CᵀC)⁻¹ w² Cᵀ c = W c,

so the system is factorised once per rig (`*_precompute`) and W (V, N) is the deformer;
each frame then costs one skinning product. With w large the constraints are near-hard.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from retarget.errors import RetargetError
from retarget.weights.cholesky import cholesky


def constraint_matrix(points, n_vertices: int) -> sp.csr_matrix:
    """(N, V) sparse: row j holds feature j's barycentric weights on its triangle."""
    n = points.n_points
    return sp.csr_matrix(
        (points.barycentric.ravel(), (np.repeat(np.arange(n), 3), points.vertex_indices.ravel())),
        shape=(n, n_vertices))


def constrained_weights(energy: sp.spmatrix, points, constraint_weight: float,
                        progress=None, supports=(), vertices=None) -> np.ndarray:
    """(V, N) float64 W of the module docstring for energy Q and `SurfacePoints`.

    constraint_weight : w² relative to the median diagonal of Q (scale-free).
    supports : pairs (features (N,) bool, outside (V,) bool): those features' weights are
        held at exactly zero on the `outside` vertices, which are eliminated from their
        system. Features in no pair have no such limit.
    vertices : (V, 3) float, the mesh's vertices: the system is then solved by
        `cholesky.cholesky` (nested dissection on them; the pair with the smallest
        `outside` shares the whole system's factorisation, each other pair has its own).
        Without them, by SuperLU (one factorisation per pair and one for the rest).
    """
    q = sp.csc_matrix(energy)
    c = constraint_matrix(points, q.shape[0])
    scale = float(np.median(np.abs(q.diagonal()))) or 1.0
    w2 = constraint_weight * scale
    # A tiny ridge keeps pieces of the mesh that carry no feature point (a separate
    # eyeball, say) solvable: they stay still instead of making the system singular.
    # (one merge with the large energy: the constraints and the ridge are summed first)
    a = (q + (w2 * (c.T @ c) + sp.identity(q.shape[0], format="csc") * (1e-10 * scale))).tocsc()
    n = points.n_points
    free = np.ones(n, dtype=bool)
    groups = []
    for features, outside in supports:
        groups.append((np.flatnonzero(features & free), np.asarray(outside, dtype=bool)))
        free &= ~features
    groups.append((np.flatnonzero(free), None))
    groups = [(cols, outside) for cols, outside in groups if len(cols)]
    rhs = (w2 * c.T).tocsc()
    out = np.zeros((a.shape[0], n))
    solve = _cholesky_solver(a, vertices, groups) if vertices is not None else _superlu_solve
    for g, (cols, outside) in enumerate(groups):
        out[:, cols] = solve(a, rhs[:, cols].toarray(), outside)
        if progress is not None:
            progress((g + 1) / len(groups))
    if not np.isfinite(out).all():
        raise RetargetError("the deformation system gave non-finite weights (degenerate mesh triangles?)")
    return out


def _superlu_solve(a: sp.csc_matrix, b: np.ndarray, outside: np.ndarray | None) -> np.ndarray:
    """(V, k) solution of A x = b, or of A without the `outside` rows and columns (zero
    there), by SuperLU."""
    keep = np.ones(a.shape[0], dtype=bool) if outside is None else ~outside
    ag = a if outside is None else a[keep][:, keep].tocsc()
    try:
        # The system is symmetric positive definite: a symmetric ordering and
        # diagonal pivots make SuperLU some thirty times faster than its default.
        lu = splu(ag, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                  options={"SymmetricMode": True})
    except RuntimeError as exc:
        raise RetargetError(f"the deformation system could not be factorised ({exc})") from exc
    x = np.zeros_like(b)
    x[keep] = lu.solve(b[keep])
    return x


def _cholesky_solver(a: sp.csc_matrix, vertices, groups):
    """`_superlu_solve`'s twin by `cholesky.cholesky`; the group with the smallest
    `outside` is the tail of the whole system's factorisation."""
    v = np.asarray(vertices, dtype=np.float64)
    tail = min((o for _, o in groups if o is not None), key=np.sum, default=None)
    factors = {}

    def solve(a, b, outside):
        if outside is None or outside is tail:
            if "whole" not in factors:
                factors["whole"] = cholesky(a, v, tail)
            return factors["whole"].solve(b, restricted=outside is not None)
        keep = ~outside
        x = np.zeros_like(b)
        x[keep] = cholesky(a[keep][:, keep], v[keep]).solve(b[keep])
        return x

    return solve
