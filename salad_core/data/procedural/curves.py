"""Smooth 1-D curves for procedural animation: easing, envelopes, keyframes, oscillations.

Everything is vectorised over a time axis ``t`` (seconds, shape ``(N,)``); values may carry
trailing axes. Easing uses the minimum-jerk polynomial so that velocity and acceleration are
zero at both ends, which is what makes segment joins and cross-fades look smooth.
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

__all__ = [
    "min_jerk",
    "smoothstep",
    "ease",
    "envelope",
    "keyframes",
    "hermite",
    "smooth",
    "wrap_angle",
    "frame_times",
]


def frame_times(n: int, fps: float) -> np.ndarray:
    """``(n,)`` time of each frame in seconds."""
    return np.arange(n, dtype=np.float64) / fps


def min_jerk(x) -> np.ndarray:
    """``10x^3 - 15x^4 + 6x^5`` on ``x`` clipped to [0, 1]: 0 -> 1 with zero end velocity/acceleration."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return x * x * x * (10.0 + x * (-15.0 + 6.0 * x))


def smoothstep(x) -> np.ndarray:
    """``3x^2 - 2x^3`` on ``x`` clipped to [0, 1]."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def ease(t, t0: float, t1: float) -> np.ndarray:
    """0 before ``t0``, 1 after ``t1``, min-jerk in between (a step if ``t1 <= t0``)."""
    t = np.asarray(t, dtype=np.float64)
    if t1 <= t0:
        return (t >= t0).astype(np.float64)
    return min_jerk((t - t0) / (t1 - t0))


def envelope(t, t0: float, t1: float, fade_in: float, fade_out: float | None = None) -> np.ndarray:
    """Weight that eases 0 -> 1 over ``[t0, t0+fade_in]`` and 1 -> 0 over ``[t1-fade_out, t1]``."""
    fade_out = fade_in if fade_out is None else fade_out
    span = max(t1 - t0, 1e-9)
    fi, fo = min(fade_in, span / 2), min(fade_out, span / 2)
    return ease(t, t0, t0 + fi) * (1.0 - ease(t, t1 - fo, t1))


def hermite(t, t0: float, t1: float, p0, p1, v0=0.0, v1=0.0) -> np.ndarray:
    """Cubic Hermite from ``(t0, p0, v0)`` to ``(t1, p1, v1)``; ``t`` is clipped to the interval."""
    h = max(t1 - t0, 1e-9)
    s = np.clip((np.asarray(t, dtype=np.float64) - t0) / h, 0.0, 1.0)
    p0, p1 = np.asarray(p0, dtype=np.float64), np.asarray(p1, dtype=np.float64)
    v0, v1 = np.asarray(v0, dtype=np.float64), np.asarray(v1, dtype=np.float64)
    s = s.reshape(s.shape + (1,) * max(p0.ndim, p1.ndim, v0.ndim, v1.ndim))
    s2, s3 = s * s, s * s * s
    return ((2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * h * v0
            + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * h * v1)


def keyframes(t, times, values, velocities=None) -> np.ndarray:
    """Piecewise-cubic curve through keys ``(times[k], values[k])``.

    Parameters
    ----------
    t : ``(N,)`` seconds
    times : ``(K,)`` increasing key times
    values : ``(K, ...)`` key values
    velocities : ``(K, ...)``, optional
        Velocity at each key; zero by default (each key is an ease-in/ease-out pose).

    Returns
    -------
    ``(N, ...)``; constant before the first and after the last key.
    """
    t = np.asarray(t, dtype=np.float64)
    times = np.asarray(times, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    if times.ndim != 1 or len(times) != len(values) or len(times) == 0:
        raise ValueError(f"keyframes: times {times.shape} and values {values.shape} must match, K >= 1")
    if np.any(np.diff(times) < 0):
        raise ValueError(f"keyframes: times must be non-decreasing, got {times.tolist()}")
    vel = np.zeros_like(values) if velocities is None else np.asarray(velocities, dtype=np.float64)
    out = np.empty((len(t),) + values.shape[1:])
    out[:] = values[0]
    for k in range(len(times) - 1):
        a, b = times[k], times[k + 1]
        sel = (t >= a) & (t <= b) if k == len(times) - 2 else (t >= a) & (t < b)
        if b > a and sel.any():
            out[sel] = hermite(t[sel], a, b, values[k], values[k + 1], vel[k], vel[k + 1])
    out[t > times[-1]] = values[-1]
    return out


def smooth(x: np.ndarray, sigma_frames: float, axis: int = 0) -> np.ndarray:
    """Gaussian smoothing along ``axis`` (edges held, 'nearest')."""
    if sigma_frames <= 0:
        return np.asarray(x, dtype=np.float64)
    return gaussian_filter1d(np.asarray(x, dtype=np.float64), sigma_frames, axis=axis, mode="nearest")


def wrap_angle(a) -> np.ndarray:
    """Angle(s) wrapped to (-pi, pi]."""
    a = np.asarray(a, dtype=np.float64)
    return np.pi - np.mod(np.pi - a, 2 * np.pi)
