"""Temporal filters for tracked feature points: Woodward's 3-frame mean and the One Euro
filter, each offline (a whole take) and online (one frame at a time, same result).

Lost points (NaN rows) are skipped: they come out NaN and do not disturb the others.

- `temporal_mean` / `TemporalMean`: Woodward et al., §5 (marker tracking): "an
  empirically determined, temporal mean filtering over three frames was applied to
  stabilize 3-D marker positions" (4.5 mm -> 1.6 mm std at 1.2 m). Causal: the mean of
  the current and the previous ``window - 1`` frames, so it lags ``(window - 1) / 2``
  frames and divides white-noise std by ``sqrt(window)``.
- `one_euro` / `OneEuroFilter`: Casiez, Roussel and Vogel, "1€ Filter: A Simple
  Speed-based Low-pass Filter for Noisy Input in Interactive Systems", CHI 2012. A
  first-order low-pass whose cutoff rises with speed (``fc = min_cutoff + beta |dx/dt|``):
  little jitter at rest, little lag in fast motion.
"""

from __future__ import annotations

import numpy as np

from retarget.errors import RetargetError

__all__ = ["temporal_mean", "TemporalMean", "one_euro", "OneEuroFilter"]


def temporal_mean(frames, window: int = 3) -> np.ndarray:
    """(F, N, D) float32: each frame the mean of itself and the ``window - 1`` frames
    before it (fewer at the start), over the frames where the point is not lost; NaN where
    it is lost in all of them. Woodward et al. §5 use ``window = 3``.

    frames : (F, N, D) float, any units.
    """
    x = _frames(frames)
    _check_window(window)
    valid = ~np.isnan(x)
    values = np.where(valid, x, 0.0).astype(np.float64)
    total = np.zeros_like(values)
    count = np.zeros(x.shape, dtype=np.int64)
    for lag in range(min(window, len(x))):
        total[lag:] += values[:len(x) - lag]
        count[lag:] += valid[:len(x) - lag]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan).astype(np.float32)


class TemporalMean:
    """Online `temporal_mean`: call with each frame in turn.

    window : frames averaged, >= 1 (Woodward et al. §5: 3).
    ``__call__(points (N, D), t=None) -> (N, D) float32``; `t` is accepted for the same
    call shape as `OneEuroFilter` and unused. `reset()` forgets the past frames.
    """

    def __init__(self, window: int = 3):
        _check_window(window)
        self.window = window
        self.reset()

    def reset(self) -> None:
        """Forget the frames seen so far."""
        self._past: list[np.ndarray] = []

    def __call__(self, points, t: float | None = None) -> np.ndarray:
        x = _points(points)
        if self._past and self._past[0].shape != x.shape:
            raise RetargetError(
                f"TemporalMean: points have shape {x.shape}, earlier frames {self._past[0].shape}")
        self._past = [*self._past[-(self.window - 1):], x] if self.window > 1 else [x]
        return temporal_mean(np.stack(self._past), self.window)[-1]


class OneEuroFilter:
    """The One Euro filter (Casiez et al. 2012), vectorised over N points, online.

    min_cutoff : float or (N,) Hz, > 0, the cutoff at rest: lower = less jitter, more lag.
    beta : float or (N,), >= 0, in s per source unit: how fast the cutoff rises with
        speed (``fc = min_cutoff + beta * speed``). Its scale depends on the units (pixels,
        cm, mm): a beta for cm is ten times the one for mm.
    d_cutoff : Hz, > 0, the cutoff of the low-pass on the speed estimate.

    Each point gets one cutoff from the norm of its velocity (the paper filters scalar
    signals; one cutoff per point keeps a point's coordinates filtered alike, so its lag
    does not depend on the direction it moves). A lost point (NaN) comes out NaN and keeps
    its state; when it comes back the elapsed time is long, so the filter catches up.

    ``__call__(points (N, D), t seconds) -> (N, D) float32``; `t` must not decrease.
    `reset()` forgets the state.
    """

    def __init__(self, min_cutoff=1.0, beta=0.0, d_cutoff: float = 1.0):
        self.min_cutoff = _positive(min_cutoff, "min_cutoff")
        self.beta = _positive(beta, "beta", allow_zero=True)
        self.d_cutoff = float(_positive(d_cutoff, "d_cutoff"))
        if np.ndim(self.d_cutoff) != 0:
            raise RetargetError("OneEuroFilter d_cutoff must be a number")
        self.reset()

    def reset(self) -> None:
        """Forget the state: the next frame passes through unchanged."""
        self._x = None     # (N, D) float64 last estimate
        self._dx = None    # (N, D) float64 last filtered velocity, units/s
        self._t = None     # (N,) float64 time of each point's last estimate, NaN before

    def __call__(self, points, t: float) -> np.ndarray:
        x = _points(points).astype(np.float64)
        n = len(x)
        for name in ("min_cutoff", "beta"):
            value = getattr(self, name)
            if np.ndim(value) == 1 and len(value) != n:
                raise RetargetError(
                    f"OneEuroFilter {name} has {len(value)} values for {n} points")
        t = float(t)
        if not np.isfinite(t):
            raise RetargetError(f"OneEuroFilter: time must be finite, got {t!r}")
        if self._x is None:
            self._x = np.full_like(x, np.nan)
            self._dx = np.zeros_like(x)
            self._t = np.full(n, np.nan)
        elif self._x.shape != x.shape:
            raise RetargetError(
                f"OneEuroFilter: points have shape {x.shape}, earlier frames {self._x.shape}")
        last = np.nanmax(self._t) if np.isfinite(self._t).any() else -np.inf
        if t < last:
            raise RetargetError(f"OneEuroFilter: time went backwards ({last:.6g} s -> {t:.6g} s)")

        seen = ~np.isnan(x[:, 0])
        first = seen & np.isnan(self._t)
        going = seen & ~first
        te = t - self._t[going]                     # (n,) s, >= 0
        dx = np.zeros((int(going.sum()), x.shape[1]))
        moved = te > 0
        dx[moved] = (x[going][moved] - self._x[going][moved]) / te[moved, None]
        edx = _low_pass(dx, self._dx[going], _alpha(self.d_cutoff, te))
        cutoff = _at(self.min_cutoff, going) + _at(self.beta, going) * np.linalg.norm(edx, axis=1)
        self._x[going] = _low_pass(x[going], self._x[going], _alpha(cutoff, te))
        self._dx[going] = edx
        self._x[first] = x[first]
        self._dx[first] = 0.0
        self._t[seen] = t
        out = np.full_like(x, np.nan)
        out[seen] = self._x[seen]
        return out.astype(np.float32)


def one_euro(frames, times, min_cutoff=1.0, beta=0.0, d_cutoff: float = 1.0) -> np.ndarray:
    """(F, N, D) float32: `frames` through a fresh `OneEuroFilter` frame by frame.

    frames : (F, N, D) float; times : (F,) seconds, non-decreasing (e.g.
    `Take.frame_times()`); the parameters as for `OneEuroFilter`.
    """
    x = _frames(frames)
    t = np.asarray(times, dtype=np.float64)
    if t.shape != (len(x),):
        raise RetargetError(f"one_euro: times must have shape ({len(x)},), got {t.shape}")
    f = OneEuroFilter(min_cutoff, beta, d_cutoff)
    out = np.empty(x.shape, dtype=np.float32)
    for i in range(len(x)):
        out[i] = f(x[i], t[i])
    return out


def _alpha(cutoff, te):
    """Smoothing factor of a first-order low-pass at `cutoff` Hz over `te` s (Casiez
    et al. 2012, eq. 2 written as te / (te + tau) so te = 0 gives 0, not 0 / 0)."""
    tau = 1.0 / (2.0 * np.pi * cutoff)
    return te / (te + tau)


def _low_pass(x, previous, alpha):
    """(n, D): ``alpha x + (1 - alpha) previous`` with (n,) alpha."""
    alpha = np.asarray(alpha)[:, None] if np.ndim(alpha) else alpha
    return alpha * x + (1.0 - alpha) * previous


def _at(value, mask):
    return value[mask] if np.ndim(value) else value


def _positive(value, name: str, allow_zero: bool = False):
    try:
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise RetargetError(f"OneEuroFilter {name} must be a number or (N,) array, got {value!r}") from None
    if a.ndim > 1 or not np.isfinite(a).all() or ((a < 0).any() if allow_zero else (a <= 0).any()):
        bound = ">= 0" if allow_zero else "> 0"
        raise RetargetError(f"OneEuroFilter {name} must be finite and {bound}, got {value!r}")
    return a if a.ndim else float(a)


def _check_window(window) -> None:
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1:
        raise RetargetError(f"temporal mean window must be an integer >= 1, got {window!r}")


def _frames(frames) -> np.ndarray:
    try:
        x = np.asarray(frames, dtype=np.float64)
    except (TypeError, ValueError):
        raise RetargetError("frames must be a numeric (F, N, D) array") from None
    if x.ndim != 3:
        raise RetargetError(f"frames must have shape (F, N, D), got {x.shape}")
    return x


def _points(points) -> np.ndarray:
    try:
        x = np.asarray(points, dtype=np.float32)
    except (TypeError, ValueError):
        raise RetargetError("points must be a numeric (N, D) array") from None
    if x.ndim != 2:
        raise RetargetError(f"points must have shape (N, D), got {x.shape}")
    x = x.copy()
    x[np.isnan(x).any(axis=1)] = np.nan
    return x
