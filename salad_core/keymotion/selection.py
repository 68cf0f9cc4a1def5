"""Keyframe selection (KeyMotion §III-A and supplement A).

Three selectors return the sorted indices of ``k`` keyframes of a motion ``(N, D)``; the first
and last frames are always included:

- ``"uniform"``: evenly spaced indices (the paper's baseline).
- ``"mdo"`` (Maximum-Distance-Optimal, the paper's method): maximise the sum of Euclidean distances
  between the feature vectors of consecutive keyframes, solved exactly by dynamic programming,
  ``F[m, j] = max_{i<j} F[m-1, i] + d(i, j)``, in ``O(k N^2)``, vectorised over ``(i, j)``.
- ``"mieo"`` (Minimum-Interpolation-Error-Optimal, Roberts et al. 2018, the paper's ablation):
  minimise the total squared error of linearly interpolating every frame between consecutive
  keyframes, ``G[m, j] = min_{i<j} G[m-1, i] + e(i, j)``. The segment errors ``e(i, j)`` for all
  pairs come from prefix sums in ``O(N^2 D)`` (no triple loop).

Both DPs are exact: ties are broken towards the smallest predecessor index, so results are
deterministic.
"""
from __future__ import annotations

import numpy as np

__all__ = ["select_keyframes", "uniform_keyframes", "mdo_keyframes", "mieo_keyframes",
           "interpolation_errors", "feature_distances", "optimal_keyframe_path", "KEYFRAME_METHODS"]

KEYFRAME_METHODS = ("mdo", "uniform", "mieo")


def _features(features: np.ndarray) -> np.ndarray:
    x = np.asarray(features, dtype=np.float64)
    if x.ndim != 2:
        raise ValueError(f"features must have shape (N, D), got {x.shape}")
    if not np.isfinite(x).all():
        raise ValueError("features contain NaN or infinite values")
    return x


def _check_k(k: int, n: int) -> None:
    if not isinstance(k, (int, np.integer)) or k < 2:
        raise ValueError(f"k must be an integer >= 2 (first and last frame), got {k!r}")
    if k > n:
        raise ValueError(f"k={k} keyframes requested from a motion of only {n} frames")


def _check(features: np.ndarray, k: int) -> np.ndarray:
    x = _features(features)
    _check_k(k, x.shape[0])
    return x


def uniform_keyframes(num_frames: int, k: int) -> np.ndarray:
    """``k`` evenly spaced indices in ``[0, num_frames - 1]``, endpoints included."""
    if k < 2 or k > num_frames:
        raise ValueError(f"need 2 <= k <= num_frames, got k={k}, num_frames={num_frames}")
    idx = np.round(np.linspace(0, num_frames - 1, k)).astype(np.int64)
    return idx


def _backtrack(back: np.ndarray, n: int, k: int) -> np.ndarray:
    idx = [n - 1]
    for m in range(k - 1, 0, -1):
        idx.append(int(back[m, idx[-1]]))
    return np.asarray(idx[::-1], dtype=np.int64)


def _dp(score: np.ndarray, k: int, maximise: bool) -> np.ndarray:
    """Best path 0 -> N-1 through exactly ``k`` nodes with pair scores ``score[i, j]`` (i < j)."""
    n = score.shape[0]
    bad = -np.inf if maximise else np.inf
    pair = np.where(np.triu(np.ones((n, n), dtype=bool), 1), score, bad)  # only i < j allowed
    best = np.full(n, bad)
    best[0] = 0.0  # one keyframe chosen: frame 0
    back = np.zeros((k, n), dtype=np.int64)
    for m in range(1, k):
        total = best[:, None] + pair                       # (i, j)
        arg = total.argmax(0) if maximise else total.argmin(0)
        best = total[arg, np.arange(n)]
        back[m] = arg
    if not np.isfinite(best[n - 1]):
        raise ValueError("no valid keyframe path")  # unreachable for 2 <= k <= n
    return _backtrack(back, n, k)


def optimal_keyframe_path(score: np.ndarray, k: int, maximise: bool = True) -> np.ndarray:
    """The exact DP behind MDO and MIEO for any pair score: the sorted indices (length ``k``, first 0, last N-1)
    of the path through exactly ``k`` frames whose consecutive pairs ``(i, j)`` have the largest (``maximise``) or
    smallest total ``score[i, j]``; ``score`` is ``(N, N)`` and only its upper triangle (i < j) is read. How a
    selection with an extra per-frame term is built (e.g. MDO's distances plus a bonus on chosen frames ``j``,
    ``feature_distances(x) + bonus[None, :]``).

    Raises
    ------
    ValueError
        ``score`` is not square, holds NaN, or ``k`` is not an integer in ``[2, N]``.
    """
    s = np.asarray(score, dtype=np.float64)
    if s.ndim != 2 or s.shape[0] != s.shape[1]:
        raise ValueError(f"score must be a square (N, N) matrix, got shape {s.shape}")
    if np.isnan(s).any():
        raise ValueError("score contains NaN")
    _check_k(k, s.shape[0])
    return _dp(s, k, maximise=maximise)


def feature_distances(features: np.ndarray) -> np.ndarray:
    """Euclidean distances ``(N, N)`` between the frames of ``features (N, D)``: MDO's pair score.

    Raises
    ------
    ValueError
        ``features`` is not 2-D or holds NaN or infinite values.
    """
    x = _features(features)
    sq = (x * x).sum(1)
    return np.sqrt(np.maximum(sq[:, None] + sq[None, :] - 2.0 * x @ x.T, 0.0))


def mdo_keyframes(features: np.ndarray, k: int) -> np.ndarray:
    """Maximum-Distance-Optimal keyframes of ``features (N, D)`` (sorted indices, length ``k``)."""
    x = _check(features, k)
    return _dp(feature_distances(x), k, maximise=True)


def interpolation_errors(features: np.ndarray) -> np.ndarray:
    """``(N, N)`` matrix ``e[i, j]``: summed squared error of linearly interpolating frames
    ``i..j`` from frames ``i`` and ``j`` (upper triangle; zero on and below the diagonal).

    With ``L = j - i``, ``a_t = (j - t)/L``, ``b_t = (t - i)/L`` the error expands to
    ``sum|x_t|^2 - 2 x_i.sum(a_t x_t) - 2 x_j.sum(b_t x_t) + |x_i|^2 sum a^2 + 2 x_i.x_j sum ab
    + |x_j|^2 sum b^2``; the sums over ``t`` come from prefix sums of ``x_t``, ``t x_t``, ``|x_t|^2``.
    """
    x = np.asarray(features, dtype=np.float64)
    n = x.shape[0]
    t = np.arange(n, dtype=np.float64)
    p0 = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x, 0)])            # (N+1, D)
    p1 = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(t[:, None] * x, 0)])
    pq = np.concatenate([[0.0], np.cumsum((x * x).sum(1))])                  # (N+1,)
    g0 = p0 @ x.T                                                           # g0[m, c] = P0[m].x_c
    g1 = p1 @ x.T
    i = np.arange(n)[:, None]
    j = np.arange(n)[None, :]
    jj = np.broadcast_to(j + 1, (n, n))
    ii = np.broadcast_to(i, (n, n))
    L = np.maximum(j - i, 1).astype(np.float64)
    # dot products of the segment sums with the endpoints
    s0_xi = g0[jj, ii] - g0[ii, ii]          # (sum_t x_t) . x_i
    s1_xi = g1[jj, ii] - g1[ii, ii]          # (sum_t t x_t) . x_i
    s0_xj = g0[jj, np.broadcast_to(j, (n, n))] - g0[ii, np.broadcast_to(j, (n, n))]
    s1_xj = g1[jj, np.broadcast_to(j, (n, n))] - g1[ii, np.broadcast_to(j, (n, n))]
    sum_a_x_xi = (j * s0_xi - s1_xi) / L
    sum_b_x_xj = (s1_xj - i * s0_xj) / L
    # closed forms over t = i..j of a^2, b^2, ab with u = t - i in 0..L: b = u/L, a = 1 - b
    m = L + 1
    su = L * (L + 1) / 2
    su2 = L * (L + 1) * (2 * L + 1) / 6
    sb2 = su2 / L**2
    sab = su / L - sb2
    sa2 = m - 2 * su / L + sb2
    sqn = (x * x).sum(1)
    xij = x @ x.T
    err = (pq[jj] - pq[ii]) - 2 * sum_a_x_xi - 2 * sum_b_x_xj \
        + sqn[:, None] * sa2 + 2 * xij * sab + sqn[None, :] * sb2
    return np.where(j > i, np.maximum(err, 0.0), 0.0)


def mieo_keyframes(features: np.ndarray, k: int) -> np.ndarray:
    """Minimum-Interpolation-Error-Optimal keyframes of ``features (N, D)``."""
    x = _check(features, k)
    return _dp(interpolation_errors(x), k, maximise=False)


def select_keyframes(features: np.ndarray, k: int, method: str = "mdo") -> np.ndarray:
    """Sorted indices of ``k`` keyframes of ``features (N, D)``; frames 0 and N-1 always included.

    ``method`` is ``"mdo"`` (default, KeyMotion), ``"uniform"`` or ``"mieo"``.
    """
    if method not in KEYFRAME_METHODS:
        raise ValueError(f"unknown keyframe method {method!r}; choose one of {', '.join(KEYFRAME_METHODS)}")
    x = _check(features, k)
    if method == "uniform":
        return uniform_keyframes(x.shape[0], k)
    if method == "mdo":
        return mdo_keyframes(x, k)
    return mieo_keyframes(x, k)
