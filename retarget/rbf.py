"""Radial basis function interpolation and the RBF space transform.

Dutreve et al. 2008, §2: an RBF network trained on source feature points S0 and their
target duals T0 maps any point of the source space into the target space,
``F(s) = sum_i w_i h(||s - s_i||)`` (eq. 1) with ``t_j = F(s_j)`` (eq. 2, 3).

Kernels (``phi(r)``; names follow ``scipy.interpolate.RBFInterpolator`` where the maths is
the same, so scipy is the test oracle):

- ``adaptive_multiquadric``: Dutreve §2, ``h(r) = sqrt(r² + sc_j²)`` with ``sc_j`` the
  distance from centre j to its nearest other centre. Not in scipy (its ``multiquadric``
  has one global shape), hence its own name. Default degree -1 (no polynomial), as written.
- ``linear``: ``-r``, the biharmonic spline of Woodward et al. §6.1, with a linear
  polynomial (default degree 1); identical to scipy's ``linear``.
- ``thin_plate_spline``: ``r² log r``, degree 1; identical to scipy's.
- ``exponential``: ``exp(-r / c)``, Zhang et al. §2.1 (they use c = 64 in their units);
  default degree -1.
- ``gaussian``: ``exp(-(r / c)²)``; scipy's ``gaussian`` with ``epsilon = 1 / c``.

``c`` is ``shape`` if given, else derived from the centres (never from absolute units):
three times the median nearest-neighbour distance between centres.

Degenerate input has a written policy:
- non-finite coordinates, coincident centres, fewer centres than the polynomial needs,
  or collinear centres with a linear polynomial: `RetargetError` naming the points;
- coplanar centres (a 2D source with z = 0, Dutreve §4) with a linear polynomial: the
  polynomial spans only the centres' own plane (its normal direction would be
  undetermined), so a 2D source still maps into 3D target space.

`SimilarityTransform` is the transform's polynomial alone with its linear part held to a
similarity (scale times an orthogonal matrix): what `retarget.pipeline` uses for dense 3D
sources, where a free affine part would carry the two faces' proportions into the motion.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.distance import cdist

from retarget.errors import RetargetError

KERNELS = ("adaptive_multiquadric", "linear", "thin_plate_spline", "exponential", "gaussian")
_DEFAULT_DEGREE = {
    "adaptive_multiquadric": -1,
    "linear": 1,
    "thin_plate_spline": 1,
    "exponential": -1,
    "gaussian": -1,
}
# Relative tolerance (to the centres' spread) under which two centres coincide or a
# direction of the centre cloud counts as flat.
_COINCIDENT_TOL = 1e-9
_FLAT_TOL = 1e-6


def as_points(points, name: str, dims=(2, 3)) -> np.ndarray:
    """(N, 2|3) array-like -> (N, 3) float64, 2D points padded with z = 0 (Dutreve §4).

    Raises `RetargetError` naming `name` for a wrong shape or non-finite values.
    """
    arr = np.asarray(points, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] not in dims:
        raise RetargetError(f"{name} must have shape (N, 2) or (N, 3); got {arr.shape}")
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        raise RetargetError(
            f"{name} has {int(bad.sum())} point(s) with NaN or inf coordinates "
            f"(first: point {int(np.flatnonzero(bad)[0])})")
    if arr.shape[1] == 2:
        arr = np.hstack([arr, np.zeros((len(arr), 1))])
    return arr


def kernel_values(kernel: str, r: np.ndarray, shape: np.ndarray | float) -> np.ndarray:
    """phi(r) for distances r (any shape) and per-centre shape (broadcast on the last axis)."""
    if kernel == "adaptive_multiquadric":
        return np.sqrt(r * r + np.square(shape))
    if kernel == "linear":
        return -r
    if kernel == "thin_plate_spline":
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(r > 0, r * r * np.log(np.where(r > 0, r, 1.0)), 0.0)
    if kernel == "exponential":
        return np.exp(-r / shape)
    if kernel == "gaussian":
        return np.exp(-np.square(r / shape))
    raise RetargetError(f"unknown RBF kernel {kernel!r}; choose one of {', '.join(KERNELS)}")


class RBFInterpolant:
    """Linear operator from values at centres to values anywhere (Dutreve eq. 1-3).

    Fitting solves the system once for an identity right-hand side, so the result is a
    matrix: ``values(x) = operator(x) @ values_at_centres``. That one object serves the
    space transform (values = target coordinates) and the dense RBF deformer (values =
    feature displacements, Zhang §2.1).

    Parameters
    ----------
    kernel : one of `KERNELS`.
    degree : polynomial degree, -1 (none), 0 (constant) or 1 (linear); None takes the
        kernel's default.
    smoothing : >= 0, added to the kernel matrix diagonal in units of the kernel matrix's
        mean absolute entry, so it means the same at any scale: 0 interpolates exactly,
        larger values fit noisy sources more loosely, and very large values leave only the
        polynomial (a least-squares affine map for degree 1).
    shape : the kernel's length scale c (same units as the centres) for ``exponential``
        and ``gaussian``; None derives it from the centres.
    """

    def __init__(self, kernel: str = "adaptive_multiquadric", *, degree: int | None = None,
                 smoothing: float = 0.0, shape: float | None = None):
        if kernel not in KERNELS:
            raise RetargetError(f"unknown RBF kernel {kernel!r}; choose one of {', '.join(KERNELS)}")
        if degree is not None and degree not in (-1, 0, 1):
            raise RetargetError(f"RBF degree must be -1, 0 or 1; got {degree!r}")
        if not np.isfinite(smoothing) or smoothing < 0:
            raise RetargetError(f"RBF smoothing must be a finite number >= 0; got {smoothing!r}")
        if shape is not None and not (np.isfinite(shape) and shape > 0):
            raise RetargetError(f"RBF shape must be a positive number; got {shape!r}")
        self.kernel = kernel
        self.degree = degree
        self.smoothing = float(smoothing)
        self.shape = shape

    def fit(self, centers) -> "RBFInterpolant":
        """Factor the system for (N, 2|3) centres; returns self.

        Learned: ``centers_`` (N, 3), ``shape_`` (N,) per-centre kernel shape,
        ``origin_`` (3,), ``axes_`` (P-1, 3) polynomial frame, ``solution_`` (N+P, N).
        """
        c = as_points(centers, "centers")
        n = len(c)
        degree = _DEFAULT_DEGREE[self.kernel] if self.degree is None else self.degree
        d = cdist(c, c)
        spread = float(np.sqrt(((c - c.mean(0)) ** 2).sum(1).mean())) if n > 1 else 0.0
        if n > 1:
            iu = np.triu_indices(n, 1)
            close = d[iu] <= _COINCIDENT_TOL * max(spread, 1e-300)
            if close.any():
                i, j = iu[0][close][0], iu[1][close][0]
                raise RetargetError(
                    f"source points {i} and {j} coincide at {c[i].tolist()}; "
                    "every feature point needs its own position")
        origin, axes = _polynomial_frame(c, degree, spread)
        n_poly = 0 if degree < 0 else 1 + len(axes)
        if n < max(1, n_poly):
            raise RetargetError(
                f"need at least {max(1, n_poly)} feature points for kernel {self.kernel!r} "
                f"with degree {degree}; got {n}")
        nearest = np.where(np.eye(n, dtype=bool), np.inf, d).min(1) if n > 1 else np.ones(1)
        if self.kernel == "adaptive_multiquadric":
            shape = nearest
        elif self.shape is not None:
            shape = np.full(n, float(self.shape))
        else:
            shape = np.full(n, 3.0 * float(np.median(nearest)))
        k = kernel_values(self.kernel, d, shape[None, :])
        if self.smoothing:
            k[np.diag_indices(n)] += self.smoothing * float(np.abs(k).mean())
        lhs = np.zeros((n + n_poly, n + n_poly))
        lhs[:n, :n] = k
        if n_poly:
            p = _polynomial(c, origin, axes)
            lhs[:n, n:] = p
            lhs[n:, :n] = p.T
        rhs = np.zeros((n + n_poly, n))
        rhs[:n] = np.eye(n)
        try:
            sol = np.linalg.solve(lhs, rhs)
        except np.linalg.LinAlgError as exc:
            raise RetargetError(f"the RBF system for these feature points is singular ({exc})") from exc
        if not np.isfinite(sol).all():
            raise RetargetError("the RBF system for these feature points is singular")
        self.centers_ = c
        self.shape_ = shape
        self.degree_ = degree
        self.origin_ = origin
        self.axes_ = axes
        self.solution_ = sol
        return self

    def operator(self, points) -> np.ndarray:
        """(M, N) float64 matrix mapping values at the N centres to values at (M, 2|3) points."""
        self._check_fitted()
        x = as_points(points, "points")
        return self._combination(x, self.solution_)

    def _combination(self, x: np.ndarray, coefs: np.ndarray) -> np.ndarray:
        """(M, K) float64: the kernel and polynomial terms at (M, 3) points times (N+P, K)
        coefficients, ``[phi(|x - c|), poly(x)] @ coefs``.

        The per-frame hot path (the dense 468-point transform): the (M, N) kernel matrix is
        the only large array, made by one distance pass and at most two in-place passes,
        and the small polynomial block is multiplied apart instead of stacked onto it.
        """
        n = len(self.centers_)
        if self.kernel == "linear":
            # phi = -r is linear in r: negate the (N, K) weights, not the (M, N) distances
            out = cdist(x, self.centers_) @ -coefs[:n]
        elif self.kernel == "adaptive_multiquadric":
            # sqrt(r² + sc²) from the squared distances, in place: no r or r² temporaries
            k = cdist(x, self.centers_, "sqeuclidean")
            k += np.square(self.shape_)
            out = np.sqrt(k, out=k) @ coefs[:n]
        else:
            out = kernel_values(self.kernel, cdist(x, self.centers_), self.shape_[None, :]) @ coefs[:n]
        if self.degree_ >= 0:
            out += _polynomial(x, self.origin_, self.axes_) @ coefs[n:]
        return out

    def _check_fitted(self):
        if not hasattr(self, "solution_"):
            raise RetargetError(f"{type(self).__name__} is not fitted; call fit() first")


class RBFTransform(RBFInterpolant):
    """Dutreve §2 space transform: fit on (S0 -> T0), then map source points to target space.

    ``fit(source, target)`` takes (N, 2|3) source and (N, 3) target feature points in the
    same order; ``transform(points)`` maps (..., 2|3) source-space points to (..., 3).
    Learned in addition: ``coefs_`` (N+P, 3) = weights w_i and polynomial coefficients.
    """

    def fit(self, source, target) -> "RBFTransform":
        t = as_points(target, "target", dims=(3,))
        s = as_points(source, "source")
        if len(s) != len(t):
            raise RetargetError(
                f"source and target must have the same number of feature points; "
                f"got {len(s)} and {len(t)}")
        super().fit(s)
        self.coefs_ = self.solution_ @ t
        return self

    def transform(self, points) -> np.ndarray:
        """(..., 2|3) source-space points -> (..., 3) float64 target-space points.

        Non-finite input rows give NaN rows out (a lost tracker point stays lost; the
        pipeline decides what a lost point does).
        """
        self._check_fitted()
        x = np.asarray(points, dtype=np.float64)
        if x.ndim < 1 or x.shape[-1] not in (2, 3):
            raise RetargetError(f"points must have shape (..., 2) or (..., 3); got {x.shape}")
        lead = x.shape[:-1]
        x = x.reshape(-1, x.shape[-1])
        if x.shape[1] == 2:
            x = np.hstack([x, np.zeros((len(x), 1))])
        finite = np.isfinite(x)
        if finite.all():
            # the usual frame: no lost point, so no per-row test and no row selection copies
            return self._combination(x, self.coefs_).reshape(*lead, 3)
        ok = finite.all(1)
        out = np.full((len(x), 3), np.nan)
        if ok.any():
            out[ok] = self._combination(x[ok], self.coefs_)
        return out.reshape(*lead, 3)


def _polynomial_frame(c: np.ndarray, degree: int, spread: float):
    """Origin (3,) and orthonormal axes (P-1, 3) of the linear polynomial term.

    For degree 1 the axes span the centres' affine hull (3 directions, or 2 for coplanar
    centres such as a 2D source), scaled by the spread so the system stays well
    conditioned whatever the units.
    """
    origin = c.mean(0)
    if degree < 1:
        return origin, np.zeros((0, 3))
    _, sv, vt = np.linalg.svd(c - origin, full_matrices=False)
    rank = int((sv > _FLAT_TOL * max(sv[0], 1e-300)).sum()) if len(sv) else 0
    if rank < 2:
        raise RetargetError(
            "feature points are collinear (or fewer than 3): a linear RBF polynomial needs "
            "at least 3 points that span a plane")
    return origin, vt[:rank] / max(spread, 1e-300)


def spans_volume(points) -> bool:
    """Whether (N, 3) points span 3D space (no direction flat within `_FLAT_TOL` of the
    widest): what `SimilarityTransform` needs; a 2D source padded with z = 0 does not."""
    p = np.asarray(points, dtype=np.float64)
    sv = np.linalg.svd(p - p.mean(0), compute_uv=False) if len(p) >= 4 else np.zeros(1)
    return len(sv) == 3 and sv[-1] > _FLAT_TOL * max(sv[0], 1e-300)


def _polynomial(x: np.ndarray, origin: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(M, 1 + len(axes)) polynomial basis [1, projections on the axes]."""
    return np.hstack([np.ones((len(x), 1)), (x - origin) @ axes.T])


class SimilarityTransform(RBFTransform):
    """The space transform ``F(s) = c Q s + t`` (scale c > 0, orthogonal Q, translation t)
    that best maps (N, 3) source onto (N, 3) target points in least squares: orthogonal
    Procrustes with scale (Umeyama 1991, eq. 40-42, without the det(Q) = +1 constraint, so
    a mirrored source frame is mapped as the affine map would map it).

    It is `RBFTransform`'s linear polynomial with every kernel weight zero, the limit of
    infinite smoothing, except that the least-squares affine part there is replaced by the
    closest map that only rotates, mirrors and scales uniformly: a displacement keeps its
    direction relative to the face and is scaled by the faces' size ratio, instead of being
    stretched and sheared by how the two faces' proportions differ. The learned attributes
    are `RBFTransform`'s but ``solution_`` (``coefs_`` holds zeros for the kernel terms), so
    code that reads the transform's coefficients reads this one too; ``transform``
    evaluates the polynomial alone.
    """

    def __init__(self):
        super().__init__("linear", degree=1)

    def fit(self, source, target) -> "SimilarityTransform":
        t = as_points(target, "target", dims=(3,))
        s = as_points(source, "source", dims=(3,))
        if len(s) != len(t):
            raise RetargetError(
                f"source and target must have the same number of feature points; "
                f"got {len(s)} and {len(t)}")
        if not spans_volume(s):
            raise RetargetError("a similarity transform needs 3D source points that span a volume")
        spread = float(np.sqrt(((s - s.mean(0)) ** 2).sum(1).mean()))
        origin, axes = _polynomial_frame(s, 1, spread)
        mu_s, mu_t = s.mean(0), t.mean(0)
        a, b = s - mu_s, t - mu_t
        u, sigma, vt = np.linalg.svd(b.T @ a)
        q = u @ vt                                  # (3, 3) maximises trace(Qᵀ BᵀA)
        scale = float(sigma.sum() / (a ** 2).sum())
        linear = scale * q                          # F(s) = linear @ s + shift
        n = len(s)
        coefs = np.zeros((n + 4, 3))
        # the polynomial basis is [1, (s - origin_) @ axes_ᵀ] (`_polynomial`)
        coefs[n] = mu_t + linear @ (origin - mu_s)
        coefs[n + 1:] = np.linalg.solve(axes.T, linear.T)
        self.centers_, self.shape_, self.degree_ = s, np.ones(n), 1
        self.origin_, self.axes_, self.coefs_ = origin, axes, coefs
        return self

    def operator(self, points):
        raise RetargetError("a similarity transform is not linear in the target points: it has "
                            "no operator on values; use transform()")

    def _check_fitted(self):
        if not hasattr(self, "coefs_"):
            raise RetargetError(f"{type(self).__name__} is not fitted; call fit() first")

    def _combination(self, x: np.ndarray, coefs: np.ndarray) -> np.ndarray:
        """(M, K): the polynomial terms alone (the kernel weights are zero)."""
        return _polynomial(x, self.origin_, self.axes_) @ coefs[len(self.centers_):]
