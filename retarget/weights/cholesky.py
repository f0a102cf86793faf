"""Sparse Cholesky factorisation of a mesh's symmetric positive definite system, for many
right-hand sides at once.

The rigs of `quadratic.constrained_weights` solve ``A X = B`` for one column of B per
feature (68 for ibug68) on a (V, V) system whose graph is the mesh's (two rings for the
bilaplacian). SuperLU, a general sparse LU, factorises it column by column and solves one
right-hand side at a time, reading its whole factor (L and U, 19.4M entries each on the
133k-vertex built-in face) once per column: most of the rig's time. Here instead:

- **Geometric nested dissection** (George 1973, "Nested dissection of a regular finite
  element mesh"; Miller, Teng, Thurston & Vavasis 1997 for the geometric separators): the
  vertices are split at their median along the longest extent (near the top of the tree,
  along whichever of the three axes gives the smallest separator); the vertices of one
  half that touch the other half (in the system's graph, so two rings thick for the
  bilaplacian) form a separator ordered after both halves, recursively down to blocks of
  `leaf_size`.
- **Multifrontal Cholesky** (Duff & Reid 1983; Liu 1992, "The multifrontal method for
  sparse matrix solution: theory and practice", SIAM Review 34(1), §4-5): each block of
  the dissection is one dense front, factorised with LAPACK and passing its Schur
  complement (update matrix) to its parent, the block that owns the first row of its
  boundary. One triangle instead of LU's two (26M entries on that face), in dense BLAS 3
  blocks.
- **Blocked triangular solves**: every right-hand side goes through each front at once as
  a dense (rows, columns) block, so the factor is read twice in all, not twice per column;
  fronts where every column is still zero are skipped.

On that face the biharmonic rig takes a quarter of SuperLU's time (`bench/rig.py`).
Everything is float64: the near-hard constraints (w² = 1e4 times the energy's scale) and
the ridge of 1e-10 put the condition number far beyond float32's 1 / eps = 1.7e7.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.linalg import blas, lapack
from threadpoolctl import threadpool_limits

from retarget.errors import RetargetError


@dataclass(frozen=True, eq=False)
class Front:
    """One block of the factor: columns ``start:stop`` of the permuted system.

    boundary : (b,) int64, sorted rows below the block where its columns are nonzero.
    lower : (m, m) float64, the block's own lower Cholesky factor (m = stop - start).
    below : (b, m) float64, the factor's rows `boundary` in the block's columns.
    """

    start: int
    stop: int
    boundary: np.ndarray
    lower: np.ndarray
    below: np.ndarray


def nested_dissection(graph: sp.spmatrix, points: np.ndarray, leaf_size: int = 96) -> tuple[np.ndarray, np.ndarray]:
    """Fill-reducing order of a symmetric sparsity pattern whose nodes have positions.

    graph : (n, n) sparse, symmetric pattern (values ignored, diagonal allowed).
    points : (n, d) float, each node's position (mesh vertices).
    Returns order (n,) int64 (position -> original index) and bounds (B + 1,) int64, the
    blocks' first positions then n: block i is ``order[bounds[i]:bounds[i + 1]]``, each
    block after every block it separates.
    """
    g = sp.csr_matrix(graph)
    indptr, indices = g.indptr, g.indices
    n = g.shape[0]
    p = np.asarray(points, dtype=np.float64)
    far = np.zeros(n, dtype=bool)  # scratch: the far half of the split being made
    blocks: list[np.ndarray] = []

    def dissect(nodes: np.ndarray) -> None:
        if len(nodes) <= leaf_size:
            blocks.append(nodes)
            return
        starts, counts = indptr[nodes], indptr[nodes + 1] - indptr[nodes]
        row = np.repeat(np.arange(len(nodes)), counts)
        neighbours = indices[np.arange(len(row)) + np.repeat(starts - np.cumsum(counts) + counts, counts)]
        xyz = p[nodes]
        half = len(nodes) // 2
        # the cut across the longest extent; near the top of the tree, where separators
        # cost the most, the one of the three axes with the smallest separator
        axes = range(3) if len(nodes) > 64 * leaf_size else [int(np.argmax(np.ptp(xyz, axis=0)))]
        best = None
        for axis in axes:
            is_far = np.zeros(len(nodes), dtype=bool)
            is_far[np.argpartition(xyz[:, axis], half)[half:]] = True
            far[nodes[is_far]] = True
            hit = far[neighbours] & ~is_far[row]
            far[nodes[is_far]] = False
            touches = np.bincount(row[hit], minlength=len(nodes)) > 0
            if best is None or touches.sum() < best[1].sum():
                best = is_far, touches
        is_far, touches = best
        dissect(nodes[~is_far & ~touches])
        dissect(nodes[is_far])
        if touches.any():
            blocks.append(nodes[touches])

    dissect(np.arange(n))
    order = np.concatenate(blocks) if blocks else np.zeros(0, np.int64)
    bounds = np.concatenate([[0], np.cumsum([len(b) for b in blocks])]).astype(np.int64)
    return order.astype(np.int64), bounds


class Cholesky:
    """Cholesky factor of a symmetric positive definite sparse matrix, A = P L Lᵀ Pᵀ.

    Made by `cholesky`. `solve(b)` answers A⁻¹ b; `solve(b, restricted=True)` answers
    the system without the unknowns `cholesky` was given as ``tail``: those are ordered
    last, so the factor's leading block is the Cholesky factor of A without their rows and
    columns, and one factorisation serves both systems.

    order : (n,) int64, position in the factor -> unknown.
    fronts : the dense blocks, in elimination order.
    n_lead : unknowns before the tail (n without one).
    """

    def __init__(self, order: np.ndarray, fronts: list[Front], n_lead: int):
        self.order = order
        self.fronts = fronts
        self.n_lead = n_lead

    @property
    def n(self) -> int:
        return len(self.order)

    @property
    def nnz(self) -> int:
        """Stored factor entries (the dense fronts' lower triangles and rows below)."""
        return sum(f.lower.shape[0] * (f.lower.shape[0] + 1) // 2 + f.below.size for f in self.fronts)

    def solve(self, b: np.ndarray, restricted: bool = False) -> np.ndarray:
        """A⁻¹ b for b (n,) or (n, k) float: float64, b's shape. With `restricted`, the
        solution of the system without the tail unknowns (their rows of b are ignored and
        their rows of the answer are zero)."""
        b = np.asarray(b, dtype=np.float64)
        if b.shape[0] != self.n:
            raise RetargetError(f"right-hand side has {b.shape[0]} rows; the system has {self.n}")
        stop = self.n_lead if restricted else self.n
        fronts = [f for f in self.fronts if f.stop <= stop]
        x = np.array(b.reshape(self.n, -1)[self.order], order="C")
        x[stop:] = 0.0
        with threadpool_limits(1):
            for f in fronts:  # L y = b, fronts in order
                y = x[f.start:f.stop]
                if not y.any():  # a feature's column is zero below its own fronts' path
                    continue
                y = blas.dtrsm(1.0, f.lower, y, lower=1)
                x[f.start:f.stop] = y
                if len(f.boundary):
                    x[f.boundary] -= f.below @ y
            x[stop:] = 0.0
            for f in reversed(fronts):  # Lᵀ x = y, fronts in reverse
                y = x[f.start:f.stop]
                if len(f.boundary):
                    y = y - f.below.T @ x[f.boundary]
                x[f.start:f.stop] = blas.dtrsm(1.0, f.lower, y, lower=1, trans_a=1)
        out = np.empty_like(x)
        out[self.order] = x
        return out.reshape(b.shape)


def cholesky(a: sp.spmatrix, points: np.ndarray, tail: np.ndarray | None = None,
             leaf_size: int = 96) -> Cholesky:
    """Factorise a (n, n) symmetric positive definite sparse matrix whose unknowns sit at
    `points` (n, d): `nested_dissection`, then the multifrontal method of the module
    docstring, its dense kernels on one BLAS thread (their blocks are small: more threads
    only contend on a shared machine).

    tail : (n,) bool, unknowns ordered last (`Cholesky.solve`'s ``restricted``).
    Raises RetargetError when a pivot is not positive (A not positive definite, or too
    ill-conditioned for float64).
    """
    n = a.shape[0]
    tail = np.zeros(n, dtype=bool) if tail is None else np.asarray(tail, dtype=bool)
    lead_ids, tail_ids = np.flatnonzero(~tail), np.flatnonzero(tail)
    order, bounds = [], [np.zeros(1, np.int64)]
    for ids in (lead_ids, tail_ids):
        if len(ids):
            o, b = nested_dissection(a[ids][:, ids], np.asarray(points)[ids], leaf_size)
            bounds.append(b[1:] + sum(len(x) for x in order))
            order.append(ids[o])
    order = np.concatenate(order) if order else np.zeros(0, np.int64)
    bounds = np.concatenate(bounds)
    with threadpool_limits(1):
        fronts = _multifrontal(sp.csc_matrix(a)[order][:, order], bounds)
    return Cholesky(order, fronts, len(lead_ids))


def _multifrontal(pa: sp.spmatrix, bounds: np.ndarray) -> list[Front]:
    """The fronts of the permuted (n, n) matrix `pa` for the blocks ``bounds[i]:bounds[i + 1]``."""
    pa = sp.csc_matrix(pa)
    pa.sum_duplicates()
    owner = np.repeat(np.arange(len(bounds) - 1), np.diff(bounds))
    pending: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
    fronts = []
    for i in range(len(bounds) - 1):
        s, e = int(bounds[i]), int(bounds[i + 1])
        m = e - s
        lo, hi = pa.indptr[s], pa.indptr[e]
        rows = pa.indices[lo:hi]
        cols = np.repeat(np.arange(m), np.diff(pa.indptr[s:e + 1]))
        vals = pa.data[lo:hi]
        keep = rows >= s
        rows, cols, vals = rows[keep], cols[keep], vals[keep]
        children = pending.pop(i, [])
        boundary = np.unique(np.concatenate([rows[rows >= e]] + [c[0][c[0] >= e] for c in children]))
        index = np.concatenate([np.arange(s, e), boundary])
        size = len(index)
        # the front: A's entries, then the children's update matrices (extend-add). Only
        # lower triangles are read (LAPACK's lower Cholesky, BLAS's lower rank-k update).
        front = np.zeros((size, size))
        front[np.where(rows < e, rows - s, m + np.searchsorted(boundary, rows)), cols] = vals
        flat = front.reshape(-1)
        for child_rows, update in children:
            at = np.searchsorted(index, child_rows)
            np.add.at(flat, (at[None, :] * size + at[:, None]).ravel(), update.ravel(order="F"))
        lower, info = lapack.dpotrf(front[:m, :m], lower=1, clean=1)
        if info != 0:
            raise RetargetError("the deformation system is not positive definite "
                                f"(Cholesky pivot {info} of a {m}-row block failed)")
        below = blas.dtrsm(1.0, lower, front[m:, :m], side=1, lower=1, trans_a=1)
        fronts.append(Front(s, e, boundary, lower, below))
        if len(boundary):
            update = blas.dsyrk(-1.0, below, beta=1.0, c=front[m:, m:], lower=1)
            pending.setdefault(int(owner[boundary[0]]), []).append((boundary, update))
    return fronts
