"""Count the repetitions of an action: from its cross-attention over frames, and from the motion.

MotionCLR (Chen et al. 2024) reads how many times an action happens from the peaks of its word's
attention over time. Here:

* :func:`attention_signal` / :func:`count_repetitions`: a phrase's attention (summed over its
  tokens and the chosen body parts) per latent frame, and the number of its peaks;
* :func:`motion_signal` / :func:`motion_repetitions`: the number of excursions of the driven
  parts away from their rest pose, measured on the joints (what the motion really does; used to
  score the attention count);
* :func:`count_peaks`: the peak counter both use (pure numpy/scipy).

A latent frame covers ``unit_length`` motion frames (4, i.e. 0.2 s at 20 fps), so the attention
signal can separate repetitions at most about 2.5 per second; motion signals are at the motion's
frame rate. Joints are ``(N, J, 3)`` metres, Y up.

Measured with the shipped weights on 16 held-out captions that state a count (12 say two, 4 say
three; ``lab/scripts/editing/measure_new_edits.py --sections d``): the attention count equalled the generated
motion's own count for 11 of 16 (0.69) but the caption's number for 5 (0.31), because the motions
mostly do the action once (the motion count matched the caption for 3 of 16; answering "2" always
would score 0.75). The motion counter itself matched the caption on 7 of these 16 corpus clips
(0.44; 0.755 on the 155 training-split phrases it was tuned on).
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.signal import find_peaks

from salad_core.part_activity import chest_frames, heading_frames
from salad_core.skeleton import PART_NAMES, Skeleton, get_skeleton

__all__ = ["count_peaks", "attention_signal", "count_repetitions", "motion_signal", "motion_repetitions",
           "ATTENTION_COUNT", "MOTION_COUNT"]

#: Defaults of :func:`count_repetitions` (latent frames): a peak must rise ``prominence`` of the
#: signal's range above its surroundings; ``smooth`` is a Gaussian sigma in latent frames.
ATTENTION_COUNT = {"prominence": 0.3, "smooth": 0.0}
#: Defaults of :func:`motion_repetitions` (motion frames), chosen on training-split corpus clips
#: (``lab/scripts/editing/measure_new_edits.py --calibrate --split train``: 0.755 of 155 stated-count phrases of 200
#: training-split motions counted right), never on the test clips it reports.
MOTION_COUNT = {"prominence": 0.6, "smooth": 0.0}


def count_peaks(signal: Any, *, prominence: float = 0.3, smooth: float = 0.0, min_distance: int = 1) -> int:
    """Number of peaks of a 1-D signal whose prominence is at least ``prominence`` times its range.

    Parameters
    ----------
    signal : array ``(T,)``
    prominence : float
        In (0, 1]: relative to ``max - min`` of the (smoothed) signal.
    smooth : float
        Gaussian sigma in samples (0: none).
    min_distance : int
        Smallest distance between two peaks, in samples.

    Returns
    -------
    int
        0 for a flat or empty signal. The ends count: the signal is padded with its minimum, so a
        rise that is still high at the first or last sample is one peak.
    """
    x = np.asarray(signal, dtype=np.float64).reshape(-1)
    if not 0.0 < float(prominence) <= 1.0:
        raise ValueError(f"prominence={prominence!r} must be in (0, 1] (a fraction of the signal's range)")
    if smooth < 0:
        raise ValueError(f"smooth={smooth!r} must be >= 0 (a Gaussian sigma in samples)")
    if isinstance(min_distance, bool) or not isinstance(min_distance, (int, np.integer)) or min_distance < 1:
        raise ValueError(f"min_distance={min_distance!r} must be a positive int")
    if x.size == 0 or not np.isfinite(x).all():
        if x.size and not np.isfinite(x).all():
            raise ValueError("signal contains NaN or infinite values")
        return 0
    if smooth > 0:
        x = gaussian_filter1d(x, float(smooth), mode="nearest")
    span = x.max() - x.min()
    if span <= 1e-12 * max(1.0, abs(x.max())):
        return 0
    padded = np.concatenate([[x.min()], x, [x.min()]])
    peaks, _ = find_peaks(padded, prominence=float(prominence) * span, distance=int(min_distance))
    return int(len(peaks))


def _part_rows(parts: Sequence[str] | None) -> list[int]:
    if parts is None:
        return list(range(len(PART_NAMES)))
    if isinstance(parts, str):
        parts = [parts]
    unknown = [p for p in parts if p not in PART_NAMES]
    if unknown or not list(parts):
        raise ValueError(f"parts={list(parts)!r} must be a non-empty list of {PART_NAMES}")
    return [PART_NAMES.index(p) for p in parts]


def attention_signal(maps: Any, word: str | int | tuple[int, int], b: int = 0,
                     parts: Sequence[str] | None = None) -> np.ndarray:
    """``(N'_b,)``: a word's (phrase's, word span's) attention per latent frame, summed over its
    tokens and over ``parts`` (default all seven).

    ``maps`` is an :class:`~salad_core.attention.capture.AttentionMaps` (its current selection of
    steps and layers), or a ``(P, N')`` word map already summed over the word's tokens.
    """
    if isinstance(maps, np.ndarray):
        m = np.asarray(maps, dtype=np.float64)
        if m.ndim != 2 or m.shape[0] != len(PART_NAMES):
            raise ValueError(f"a word map must be (P={len(PART_NAMES)}, N'), got shape {m.shape}")
    else:
        m = np.asarray(maps.word_map(b, word), dtype=np.float64)
    return m[_part_rows(parts)].sum(0)


def count_repetitions(maps: Any, word: str | int | tuple[int, int], b: int = 0, *,
                      parts: Sequence[str] | None = None, frames: tuple[int, int] | None = None,
                      unit_length: int | None = None, prominence: float | None = None,
                      smooth: float | None = None) -> int:
    """How many times the action of ``word`` happens, read from its attention over frames.

    Parameters
    ----------
    maps : AttentionMaps or array ``(P, N')``
        Captured cross-attention (e.g. ``pipe(..., capture_attention=True).attention``) or a word map.
    word : str, int or (start, stop)
        The action's word, phrase or word span (its tokens are summed).
    b : int
        Sample of ``maps``.
    parts : sequence of str, optional
        Body parts whose rows are summed (default all; the phrase's driven parts give a cleaner signal).
    frames : (f0, f1), optional
        Motion frames to look at (e.g. the phrase's annotated interval); latent frame ``t`` covers
        motion frames ``[t u, (t+1) u)``.
    unit_length : int, optional
        ``u``: motion frames per latent frame (default ``maps.unit_length``, else 4).
    prominence, smooth
        As :func:`count_peaks` (defaults :data:`ATTENTION_COUNT`).

    Returns
    -------
    int
        The number of attention peaks (0 if the word has no attention there).
    """
    sig = attention_signal(maps, word, b, parts)
    if frames is not None:
        unit = int(unit_length or getattr(maps, "unit_length", 0) or 4)
        t0 = max(int(frames[0]) // unit, 0)
        t1 = min(-(-int(frames[1]) // unit), len(sig))
        if t1 <= t0:
            raise ValueError(f"frames={frames!r} hold no latent frame of a {len(sig)}-frame map (unit {unit})")
        sig = sig[t0:t1]
    return count_peaks(sig, prominence=ATTENTION_COUNT["prominence"] if prominence is None else prominence,
                       smooth=ATTENTION_COUNT["smooth"] if smooth is None else smooth)


def motion_signal(joints: np.ndarray, parts: Sequence[str], frames: tuple[int, int] | None = None,
                  skeleton: str | Skeleton = "humanml3d") -> np.ndarray:
    """``(n,)``: how far the driven parts are from their rest pose, frame by frame.

    The joints of ``parts`` are expressed in their own reference frames (legs and spine: relative
    to the pelvis in the hips' heading frame; arms and head: relative to spine3 in the chest frame;
    root: the pelvis height), restricted to ``frames``, and projected on their first principal
    component; the sign is chosen so that the larger excursion from the rest pose (the mean of the
    first and last tenth of the frames) is positive. One
    repetition of an action (a jump, a squat, a punch out and back) is then one peak.
    """
    sk = get_skeleton(skeleton)
    j = np.asarray(joints, dtype=np.float64)
    if j.ndim != 3 or j.shape[1:] != (sk.num_joints, 3) or len(j) < 2:
        raise ValueError(f"joints must be (N >= 2, {sk.num_joints}, 3) positions of {sk.name!r}, got {j.shape}")
    rows = _part_rows(parts)
    if frames is not None:
        f0, f1 = max(int(frames[0]), 0), min(int(frames[1]), len(j))
        if f1 - f0 < 2:
            raise ValueError(f"frames={frames!r} hold fewer than 2 of the motion's {len(j)} frames")
        j = j[f0:f1]
    pelvis = j[:, 0]
    head = heading_frames(j, sk)
    chest = chest_frames(j, sk)
    in_pelvis = np.einsum("nij,nkj->nki", head, j - pelvis[:, None])
    in_chest = np.einsum("nij,nkj->nki", chest, j - j[:, sk.joint_names.index("spine3")][:, None])
    cols = []
    for p in rows:
        name = PART_NAMES[p]
        if name == "root":
            cols.append(pelvis[:, 1:2])
            continue
        members = [k for k, q in enumerate(sk.joint_to_part) if q == p]
        local = in_chest if name in ("left arm", "right arm", "head") else in_pelvis
        cols.append(local[:, members].reshape(len(j), -1))
    x = np.concatenate(cols, 1)
    x = x - x.mean(0)
    if not np.abs(x).max() > 1e-9:
        return np.zeros(len(j))
    _, _, vt = np.linalg.svd(x, full_matrices=False)
    score = x @ vt[0]
    # the rest pose is where the interval starts and ends; an action leaves it and comes back, so
    # the side of the larger excursion from it is made positive (a squat's troughs become peaks)
    edge = max(1, len(score) // 10)
    rest = 0.5 * (score[:edge].mean() + score[-edge:].mean())
    if (rest - score.min()) > (score.max() - rest):
        score = -score
    return score


def motion_repetitions(joints: np.ndarray, parts: Sequence[str], frames: tuple[int, int] | None = None,
                       skeleton: str | Skeleton = "humanml3d", *, prominence: float | None = None,
                       smooth: float | None = None) -> int:
    """How many times the driven ``parts`` leave their rest pose and come back within ``frames``:
    the peaks of :func:`motion_signal` (defaults :data:`MOTION_COUNT`)."""
    return count_peaks(motion_signal(joints, parts, frames, skeleton),
                       prominence=MOTION_COUNT["prominence"] if prominence is None else prominence,
                       smooth=MOTION_COUNT["smooth"] if smooth is None else smooth)
