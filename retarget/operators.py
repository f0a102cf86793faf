"""Discrete operators on triangle meshes (libigl names and sign conventions).

- `cotmatrix`: cotangent Laplacian, (V, V) sparse, negative semi-definite,
  ``L_ij = (cot a_ij + cot b_ij) / 2``, rows sum to 0.
- `massmatrix`: barycentric lumped mass, (V, V) sparse diagonal, area units.
- `uniform_laplacian`: Zhang et al. eq. 5, ``L = I - D^-1 A`` (umbrella operator).
- `edge_graph`: (V, V) sparse symmetric edge lengths, for graph geodesics.
- `boundary_vertices`: (V,) bool, vertices on an open boundary (mouth slit, eye holes, neck).

All take vertices (V, 3) float and faces (F, 3) int.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def _edges(faces: np.ndarray) -> np.ndarray:
    """(3F, 2) directed half-edges (i -> j) of the triangles."""
    f = np.asarray(faces)
    return np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])


def adjacency(faces: np.ndarray, n_vertices: int) -> sp.csr_matrix:
    """(V, V) sparse symmetric 0/1 vertex adjacency."""
    e = _edges(faces)
    a = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_vertices, n_vertices))
    a = ((a + a.T) > 0).astype(np.float64)
    return a.tocsr()


def edge_graph(vertices: np.ndarray, faces: np.ndarray) -> sp.csr_matrix:
    """(V, V) sparse symmetric matrix of edge lengths (same units as vertices)."""
    v = np.asarray(vertices, dtype=np.float64)
    a = adjacency(faces, len(v)).tocoo()
    lengths = np.linalg.norm(v[a.row] - v[a.col], axis=1)
    # An explicit zero would read as "no edge" to csgraph; keep zero-length edges tiny.
    lengths = np.maximum(lengths, 1e-12 * max(float(lengths.max(initial=0.0)), 1e-300))
    return sp.csr_matrix((lengths, (a.row, a.col)), shape=a.shape)


def cotmatrix(vertices: np.ndarray, faces: np.ndarray) -> sp.csr_matrix:
    """(V, V) cotangent Laplacian (libigl ``cotmatrix``): negative semi-definite."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    n = len(v)
    rows, cols, vals = [], [], []
    for k in range(3):
        i, j, o = f[:, (k + 1) % 3], f[:, (k + 2) % 3], f[:, k]
        a, b = v[i] - v[o], v[j] - v[o]
        cross = np.linalg.norm(np.cross(a, b), axis=1)
        cot = (a * b).sum(1) / np.maximum(cross, 1e-300)
        rows += [i, j]
        cols += [j, i]
        vals += [0.5 * cot, 0.5 * cot]
    rows, cols, vals = map(np.concatenate, (rows, cols, vals))
    off = sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()
    return (off - sp.diags(np.asarray(off.sum(1)).ravel())).tocsr()


def massmatrix(vertices: np.ndarray, faces: np.ndarray) -> sp.dia_matrix:
    """(V, V) barycentric lumped mass matrix: a third of each incident triangle's area."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    m = np.bincount(f.ravel(), weights=np.repeat(area / 3.0, 3), minlength=len(v))
    # An isolated vertex would get zero mass and a singular M^-1; give it a tiny one.
    m = np.maximum(m, 1e-12 * max(float(m.max(initial=0.0)), 1e-300))
    return sp.diags(m)


def uniform_laplacian(faces: np.ndarray, n_vertices: int) -> sp.csr_matrix:
    """(V, V) ``I - D^-1 A`` (Zhang et al. eq. 5): vertex minus its neighbours' mean."""
    a = adjacency(faces, n_vertices)
    deg = np.asarray(a.sum(1)).ravel()
    inv = np.divide(1.0, deg, out=np.zeros_like(deg), where=deg > 0)
    return (sp.identity(n_vertices, format="csr") - sp.diags(inv) @ a).tocsr()


def boundary_vertices(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """(V,) bool: vertices on an edge used by exactly one triangle."""
    e = np.sort(_edges(faces), axis=1)
    uniq, counts = np.unique(e, axis=0, return_counts=True)
    out = np.zeros(n_vertices, dtype=bool)
    out[uniq[counts == 1].ravel()] = True
    return out
