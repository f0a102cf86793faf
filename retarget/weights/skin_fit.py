"""Any rig as a glTF skin of at most four influences a vertex: the fit and its error.

Why: a dense rig (RBF, region RBF, Laplacian, biharmonic) has negative weights and rows
above 1, so glTF holds it exactly only as 3N morph targets (`retarget.gltf.morph`): 296 MiB
for a 133k-vertex face with 68 features. A skin of four influences a vertex (one
JOINTS_0 / WEIGHTS_0 set: all that three.js's SkinnedMesh, Unity's default quality and
Unreal read) holds the same face in under 10 MiB, but its weights must be non-negative and
sum to at most 1, a static root taking the rest (`retarget.gltf.influences`; the root then
fills one of the four slots). So each row w (N,) of the rig becomes a row ŵ that fits.

What is minimised: the error the vertex makes in the motion it plays. Under feature
displacements d (N, 3) a vertex moves by Σ_i w_i d_i (Dutreve §3.1), so ŵ makes the error
``(w - ŵ)ᵀ d dᵀ (w - ŵ)``, whose mean over the motion is ``(w - ŵ)ᵀ C (w - ŵ)`` with
``C = E[d dᵀ]`` (N, N, summed over the axes). C is the clips' second moment, normalised,
plus `PRIOR_SHARE` of a spatial prior ``exp(-(|p_i - p_j| / σ)²)``, σ = `PRIOR_WIDTH` face
sizes (features move like their neighbours): the prior keeps the fit sensible for a
feature the take never moves, and is the whole C for a rig exported without a clip. On
the sample face's demo take this gives 4.8 % RMS error against 6.7 % for the prior alone
and 8.8 % for the four largest weights rescaled to the row's sum.

How: per vertex the candidates are its four largest weights; for every subset S of them
the minimiser over S has a closed form, both with a free sum (the root takes 1 - Σ, so
at most three features) and with Σ = 1 (no root, so up to four); the best one with every
weight ≥ 0 and Σ ≤ 1 is kept. A row that already fits (at most three non-negative
weights summing to at most 1, or four summing to 1) is kept as it is.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from retarget.errors import RetargetError
from retarget.skin import SkinWeights

__all__ = ["PRIOR_SHARE", "PRIOR_WIDTH", "SkinFitError", "four_influence_skin", "skin_fit_error"]

SLOTS = 4
PRIOR_SHARE = 0.05
PRIOR_WIDTH = 0.2
CHUNK = 16384
"""Vertices per block: the subsets' (CHUNK, 5, 5) systems stay a few MiB."""


@dataclass(frozen=True)
class SkinFitError:
    """How far the fitted skin draws from the rig over the clips' frames.

    rms_relative : RMS of the vertex error over the RMS of the vertex motion (all
        vertices and frames), a fraction.
    rms : RMS vertex error, mesh units.
    worst_vertex : the RMS error over the frames of the vertex where it is largest, mesh
        units.
    frames : how many frames were measured.
    """

    rms_relative: float
    rms: float
    worst_vertex: float
    frames: int


def four_influence_skin(weights: SkinWeights, points, motion=None) -> SkinWeights:
    """Skin weights of at most `SLOTS` influences a vertex, root included, non-negative and
    summing to at most 1, drawing as close to `weights` as the motion allows (module
    docstring).

    weights : (V, K) any rig over N features.
    points : (N, 3) the features' neutral positions, mesh units (for the prior).
    motion : (F, N, 3) feature displacements the face plays (clips' frames), or None.

    Returns (V, 3) or (V, 4) `SkinWeights` (three features and the root, or four) with the
    rig's method name.
    """
    points = np.asarray(points, dtype=np.float64)
    if points.shape != (weights.n_joints, 3):
        raise RetargetError(f"{weights.n_joints} features need ({weights.n_joints}, 3) points; "
                            f"got {points.shape}")
    c = motion_moment(points, motion)
    dense = weights.dense()
    k = min(SLOTS, weights.n_joints)
    indices = np.empty((len(dense), k), np.int32)
    values = np.empty((len(dense), k), np.float32)
    for start in range(0, len(dense), CHUNK):
        block = slice(start, start + CHUNK)
        indices[block], values[block] = _fitted_rows(dense[block], c, k)
    return SkinWeights(indices, values, weights.n_joints, weights.method)


def motion_moment(points: np.ndarray, motion=None) -> np.ndarray:
    """(N, N) float64 C: the motion's normalised second moment plus the spatial prior."""
    span = np.ptp(points, axis=0) if len(points) else np.zeros(3)
    sigma = PRIOR_WIDTH * max(float(np.linalg.norm(span)), 1e-12)
    distance = np.linalg.norm(points[:, None] - points[None], axis=2)
    prior = np.exp(-(distance / sigma) ** 2) / len(points)
    if motion is None or not len(motion):
        return prior
    d = np.asarray(motion, dtype=np.float64)
    moment = np.einsum("fna,fma->nm", d, d) / len(d)
    trace = np.trace(moment)
    return prior if trace <= 0 else moment / trace + PRIOR_SHARE * prior


def _fitted_rows(w: np.ndarray, c: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """((n, k) features, (n, k) weights) of the best feasible subset fit of each row."""
    n = len(w)
    order = np.argsort(-w, axis=1, kind="stable")[:, :k]
    cs = c[order[:, :, None], order[:, None, :]]                  # (n, k, k)
    b = np.take_along_axis(w @ c, order, axis=1)                  # (n, k) (C w)_S
    ridge = 1e-12 * np.trace(c) / len(c)
    best = np.full(n, np.inf)
    fitted = np.zeros((n, k))
    for size in range(1, k + 1):
        for subset in map(list, itertools.combinations(range(k), size)):
            a = cs[:, subset][:, :, subset] + ridge * np.eye(size)
            for summing_to_one in (False, True):
                if size == SLOTS and not summing_to_one:
                    continue  # four features and a root share need a fifth slot
                x = _subset_minimiser(a, b[:, subset], summing_to_one)
                feasible = (x >= -1e-9).all(1) & (x.sum(1) <= 1 + 1e-6)
                # the objective up to the row's constant wᵀCw
                cost = np.einsum("ni,nij,nj->n", x, a, x) - 2 * (x * b[:, subset]).sum(1)
                better = feasible & (cost < best)
                best[better] = cost[better]
                row = np.zeros((n, k))
                row[:, subset] = np.clip(x, 0.0, None)
                fitted[better] = row[better]
    return order.astype(np.int32), fitted.astype(np.float32)


def _subset_minimiser(a: np.ndarray, b: np.ndarray, summing_to_one: bool) -> np.ndarray:
    """(n, s) argmin of xᵀAx - 2bᵀx, free or subject to Σx = 1 (its KKT system)."""
    n, s = b.shape
    if not summing_to_one:
        return np.linalg.solve(a, b[..., None])[..., 0]
    kkt = np.zeros((n, s + 1, s + 1))
    kkt[:, :s, :s] = a
    kkt[:, s, :s] = kkt[:, :s, s] = 1.0
    rhs = np.concatenate([b, np.ones((n, 1))], axis=1)
    return np.linalg.solve(kkt, rhs[..., None])[..., 0][:, :s]


def skin_fit_error(weights: SkinWeights, fitted: SkinWeights, motion) -> SkinFitError:
    """How far `fitted` draws from `weights` over the (F, N, 3) `motion` (every frame),
    exactly, from the motion's second moment: a vertex's squared errors summed over the
    frames are eᵀ M e with M = Σ_f d_f d_fᵀ (no (V, F) product is formed)."""
    d = np.asarray(motion, dtype=np.float64)
    w = weights.dense()
    e = w - fitted.dense()
    moment = np.einsum("fna,fma->nm", d, d)                      # (N, N) M
    summed = np.maximum(((e @ moment) * e).sum(axis=1), 0.0)      # (V,) per vertex
    moved = float(((w @ moment) * w).sum())
    frames = max(len(d), 1)
    return SkinFitError(rms_relative=float(np.sqrt(summed.sum() / moved)) if moved > 0 else 0.0,
                        rms=float(np.sqrt(summed.sum() / (frames * max(len(w), 1)))),
                        worst_vertex=float(np.sqrt(summed.max(initial=0.0) / frames)),
                        frames=len(d))

