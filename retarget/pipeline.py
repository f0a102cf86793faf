"""The retargeting pipeline, Dutreve et al. 2008 §4.

Setup: an RBF space transform ``F = RBF(S0, T0)`` trained on the neutral source and
target feature points, and skin weights W for the target mesh. Every frame:

    T_f = F(S_f),   d_f = (T_f - F(S0)) · mask,   v_f = v_0 + W d_f

``F(S0)`` rather than T0 is subtracted so a smoothed (non-interpolating) transform still
gives zero displacement at the neutral pose. The mask is Dutreve's partial retargeting
(§4, Fig. 3): disabled feature points keep their neutral position. It is given with the
frames, not fitted, so changing it (a viewer ticking regions during a performance)
refits nothing. A source point that is lost (NaN, a tracker dropout) also keeps its
neutral position for that frame.

A source may have fewer points than the target rig (21 face markers driving a 68-joint
rig): the target points it lacks are NaN rows of the neutral S0. The transform is trained
on the pairs the source has, and the other joints follow by interpolating the driven
joints' displacements over the target's neutral points with the same RBF (the dense RBF
deformer of Zhang et al. §2.1, applied to the joints instead of the vertices).
"""

from __future__ import annotations

import numpy as np

from retarget.errors import RetargetError
from retarget.rbf import RBFInterpolant, RBFTransform, SimilarityTransform, as_points, spans_volume
from retarget.skin import SkinWeights, skin_displacements

DEFAULT_KERNEL = "linear"
# Relative smoothing of the transform (see `retarget.rbf.RBFInterpolant`) by source
# dimension, the best on the ICT benchmark (bench/accuracy.py) over three identity pairs.
# 3D sources: nearly the linear polynomial's affine map, which carries displacements
# between faces of different shape with the least distortion. 2D sources: much less, so
# the map keeps bending the image plane onto the target's curved face, which restores
# part of the depth motion that the image lost.
DEFAULT_SMOOTHING = {3: 100.0, 2: 3.0}
# A 3D source with at least this many driven points (the face mesh's 468; every built-in
# sparse layout has at most 68) takes, by default, the similarity transform instead
# (`retarget.rbf.SimilarityTransform`): points over the whole face pin the near-affine
# map to the two faces' proportions (a longer, flatter or narrower face), which then
# stretch and shear every displacement. On the ICT benchmark's dense scenario
# (bench/accuracy.py --dense, seeds 0-13) the similarity takes the matched-points error
# from 18.1 to 16.9 % and the found-points one from 24.7 to 24.2 %. A smaller RBF
# smoothing, or an RBF on top of the similarity, is worse there. A flat source (a 2D one
# given with z = 0) keeps the RBF transform, which lifts its plane onto the face.
DENSE_SOURCE_POINTS = 200


class Retargeter:
    """Source feature frames -> target feature displacements -> target vertices.

    Parameters
    ----------
    kernel, degree, smoothing : the RBF space transform's (see `retarget.rbf`); smoothing
        None takes `DEFAULT_SMOOTHING` for the source's dimension, except that a dense 3D
        source (`DENSE_SOURCE_POINTS`) with the default kernel and degree takes the
        similarity transform.

    `fit` is the costly step, once per neutral; `displacements` is per frame, with the
    partial-retargeting mask of that frame.
    """

    def __init__(self, kernel: str = DEFAULT_KERNEL, *, degree: int | None = None,
                 smoothing: float | None = None):
        self.kernel = kernel
        self.degree = degree
        self.smoothing = smoothing

    def fit(self, source_neutral, target_neutral) -> "Retargeter":
        """Train on (N, 2|3) neutral source points S0 and (N, 3) neutral target points T0.

        NaN rows of S0 are target points the source does not have: their displacements
        are interpolated from the others' (see the module docstring).
        """
        s = np.asarray(source_neutral, dtype=np.float64)
        if s.ndim != 2 or s.shape[1] not in (2, 3):
            raise RetargetError(f"source neutral must have shape (N, 2) or (N, 3); got {s.shape}")
        t0 = as_points(target_neutral, "target neutral", dims=(3,))
        if len(s) != len(t0):
            raise RetargetError(f"source and target must have the same number of feature points; "
                                f"got {len(s)} and {len(t0)}")
        driven = np.isfinite(s).all(axis=1)
        s0 = as_points(s[driven], "source neutral")
        self.source_dims_ = s.shape[1]
        smoothing = DEFAULT_SMOOTHING[self.source_dims_] if self.smoothing is None else self.smoothing
        if (self.source_dims_ == 3 and len(s0) >= DENSE_SOURCE_POINTS and self.smoothing is None
                and self.kernel == DEFAULT_KERNEL and self.degree is None and spans_volume(s0)):
            self.transform_ = SimilarityTransform().fit(s0, t0[driven])
        else:
            self.transform_ = RBFTransform(self.kernel, degree=self.degree,
                                           smoothing=smoothing).fit(s0, t0[driven])
        rest = np.full((len(s), 3), np.nan)
        rest[driven] = self.transform_.transform(s0)
        self.target_rest_ = rest
        self.driven_ = driven
        # (U, D) operator: driven joints' displacements -> the undriven joints'
        self.fill_ = (RBFInterpolant("linear").fit(t0[driven]).operator(t0[~driven])
                      if not driven.all() else None)
        return self

    def displacements(self, source_frames, mask=None) -> np.ndarray:
        """(N, D) or (F, N, D) source points -> (N, 3) or (F, N, 3) float32 target feature
        displacements d_f (zero for masked-out and lost points).

        mask : (N,) bool of the active feature points, or None for all (partial
            retargeting, Dutreve §4).
        """
        if not hasattr(self, "transform_"):
            raise RetargetError("Retargeter is not fitted; call fit() first")
        s = np.asarray(source_frames, dtype=np.float64)
        n = len(self.driven_)
        mask = _checked_mask(mask, n)
        if s.ndim not in (2, 3) or s.shape[-2:] != (n, self.source_dims_):
            raise RetargetError(
                f"source frames must have shape (F, {n}, {self.source_dims_}) like the source "
                f"neutral; got {s.shape}")
        d = self.transform_.transform(s) - self.target_rest_
        d = np.nan_to_num(d, nan=0.0)
        if self.fill_ is not None:
            d[..., ~self.driven_, :] = np.einsum("ud,...dk->...uk", self.fill_, d[..., self.driven_, :])
        if mask is not None:
            d[..., ~mask, :] = 0.0
        return d.astype(np.float32)


def transfer(vertices, weights: SkinWeights, retargeter: Retargeter, source_frames,
             progress=None, chunk: int = 64) -> np.ndarray:
    """(F, V, 3) float32 deformed target vertices for (F, N, D) source frames.

    retargeter : a fitted `Retargeter`, or anything with its ``displacements(frames)``,
        such as a `retarget.performance.Performance` with its neutral set (whose regions
        then apply).
    progress : optional callable taking the fraction done in [0, 1].
    """
    v0 = np.asarray(vertices, dtype=np.float64)
    frames = np.asarray(source_frames, dtype=np.float64)
    if frames.ndim != 3:
        raise RetargetError(f"source frames must have shape (F, N, 2|3); got {frames.shape}")
    if weights.n_vertices != len(v0) or weights.n_joints != frames.shape[1]:
        raise RetargetError(
            f"the rig has {weights.n_joints} joints for {weights.n_vertices} vertices; the mesh "
            f"has {len(v0)} vertices and the source {frames.shape[1]} points")
    w = weights.matrix()
    out = np.empty((len(frames), len(v0), 3), dtype=np.float32)
    for i in range(0, len(frames), chunk):
        d = retargeter.displacements(frames[i:i + chunk])
        out[i:i + chunk] = v0 + skin_displacements(w, d)
        if progress is not None:
            progress(min(1.0, (i + chunk) / max(len(frames), 1)))
    return out


def _checked_mask(mask, n: int) -> np.ndarray | None:
    """`mask` as an (N,) bool array (not copied), or None for all points."""
    if mask is None:
        return None
    m = np.asarray(mask)
    if m.shape != (n,) or m.dtype != bool:
        raise RetargetError(f"mask must be a boolean array of shape ({n},); got {m.dtype} {m.shape}")
    return m
