"""Text-to-motion metrics on evaluator embeddings (numpy in, Python floats out).

The definitions follow Guo et al. 2022 (T2M ``utils/metrics.py`` and ``final_evaluations.py``,
identical in SALAD and MoMask; ``humanml3d_eval_facts`` §5.1):

- R-precision and MM-Dist pair text ``i`` with motion ``i``;
- FID, Diversity and MultiModality use motion embeddings only;
- a protocol repeats everything (20 replications) and reports :func:`mean_ci`.

Embeddings are ``(N, C)`` arrays (``C = 512`` for the official evaluator). Functions that sample
take ``rng``: a ``numpy.random.Generator``, an int seed, or ``None`` for fresh entropy.
"""
from __future__ import annotations

import logging
import warnings

import numpy as np
from scipy import linalg

__all__ = [
    "euclidean_distance_matrix",
    "r_precision",
    "matching_score",
    "activation_statistics",
    "frechet_distance",
    "fid",
    "diversity",
    "multimodality",
    "mpjpe",
    "mean_ci",
]

logger = logging.getLogger(__name__)

#: R-precision batch size of the T2M protocol; chance level of top-k is k / 32.
R_PRECISION_BATCH = 32


def _as_2d(x, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 2:
        raise ValueError(f"{name} must be a 2-D array (N, C), got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} contains NaN or inf")
    return a


def _pair_check(a: np.ndarray, b: np.ndarray, na: str, nb: str) -> None:
    if a.shape != b.shape:
        raise ValueError(f"{na} {a.shape} and {nb} {b.shape} must have the same shape (N, C): row i of "
                         f"one is paired with row i of the other")


def _rng(rng) -> np.random.Generator:
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None or isinstance(rng, (int, np.integer)):
        return np.random.default_rng(rng)
    raise TypeError(f"rng must be a numpy Generator, an int seed or None, got {type(rng).__name__}")


def euclidean_distance_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """All pairwise Euclidean distances.

    Parameters
    ----------
    a : array ``(N1, C)``
    b : array ``(N2, C)``

    Returns
    -------
    array ``(N1, N2)``
        ``sqrt(|a_i|^2 + |b_j|^2 - 2 a_i.b_j)`` as in T2M, with round-off negatives clipped to 0.
    """
    a = _as_2d(a, "a")
    b = _as_2d(b, "b")
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"a and b must have the same width C, got {a.shape[1]} and {b.shape[1]}")
    sq = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * a @ b.T
    return np.sqrt(np.maximum(sq, 0.0))


def r_precision(text_emb: np.ndarray, motion_emb: np.ndarray, top_k: int = 3,
                batch_size: int = R_PRECISION_BATCH, drop_last: bool = True) -> tuple[float, ...]:
    """R-precision: how often a text's own motion is among its ``k`` nearest motions.

    The rows are cut into consecutive batches of ``batch_size`` (the caller shuffles, as the T2M
    loader does). Within a batch each text ranks the batch's motions by Euclidean distance
    (stable sort); top-k counts texts whose paired motion ranks ``< k``. Hits are summed over
    batches and divided by the number of evaluated rows. Random pairs score about
    ``k / batch_size``.

    Parameters
    ----------
    text_emb, motion_emb : array ``(N, C)``
        Row ``i`` of each is a matched text/motion pair.
    top_k : int
        Largest k; the result has one entry per k = 1..top_k.
    batch_size : int
        32 in every published table; do not change it when comparing with them.
    drop_last : bool
        Drop a final incomplete batch (the T2M loader's ``drop_last=True``; logged). If False, an
        incomplete batch raises, since it would change the chance level.

    Returns
    -------
    tuple of ``top_k`` floats
        ``(top1, top2, top3)`` by default.
    """
    t = _as_2d(text_emb, "text_emb")
    m = _as_2d(motion_emb, "motion_emb")
    _pair_check(t, m, "text_emb", "motion_emb")
    if not isinstance(batch_size, (int, np.integer)) or batch_size < 2:
        raise ValueError(f"batch_size must be an int >= 2, got {batch_size!r}")
    if not isinstance(top_k, (int, np.integer)) or not 1 <= top_k <= batch_size:
        raise ValueError(f"top_k must be an int in [1, batch_size={batch_size}], got {top_k!r}")
    n = t.shape[0]
    n_batches, rest = divmod(n, batch_size)
    if n_batches == 0:
        raise ValueError(f"r_precision needs at least batch_size={batch_size} pairs, got {n}")
    if rest:
        if not drop_last:
            raise ValueError(f"N={n} is not a multiple of batch_size={batch_size} and drop_last=False")
        logger.info("r_precision: dropping the last %d of %d pairs (incomplete batch)", rest, n)
    hits = np.zeros(top_k, dtype=np.int64)
    for b in range(n_batches):
        sl = slice(b * batch_size, (b + 1) * batch_size)
        dist = euclidean_distance_matrix(t[sl], m[sl])                  # (32 texts, 32 motions)
        order = np.argsort(dist, axis=1, kind="stable")
        rank = np.argmax(order == np.arange(batch_size)[:, None], axis=1)  # position of the paired motion
        hits += (rank[:, None] < np.arange(1, top_k + 1)[None, :]).sum(0)
    return tuple(float(h) / (n_batches * batch_size) for h in hits)


def matching_score(text_emb: np.ndarray, motion_emb: np.ndarray) -> float:
    """MM-Dist ("Matching Score"): mean Euclidean distance between each text and its motion.

    Parameters
    ----------
    text_emb, motion_emb : array ``(N, C)``, row ``i`` paired.

    Returns
    -------
    float
        T2M sums ``trace(dist)`` over its 32-batches and divides by N; that is this mean over
        whatever rows are given (pass the same rows as to :func:`r_precision` to match it exactly).
    """
    t = _as_2d(text_emb, "text_emb")
    m = _as_2d(motion_emb, "motion_emb")
    _pair_check(t, m, "text_emb", "motion_emb")
    if t.shape[0] == 0:
        raise ValueError("matching_score needs at least one pair, got 0")
    return float(np.linalg.norm(t - m, axis=1).mean())


def activation_statistics(emb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean ``(C,)`` and covariance ``(C, C)`` (``np.cov(rowvar=False)``, ddof 1) of ``emb (N, C)``."""
    e = _as_2d(emb, "emb")
    if e.shape[0] < 2:
        raise ValueError(f"activation statistics need at least 2 embeddings, got {e.shape[0]}")
    return e.mean(0), np.atleast_2d(np.cov(e, rowvar=False))


def frechet_distance(mu1: np.ndarray, sigma1: np.ndarray, mu2: np.ndarray, sigma2: np.ndarray,
                     eps: float = 1e-6) -> float:
    """Fréchet distance between two Gaussians.

    ``|mu1 - mu2|^2 + Tr(sigma1 + sigma2 - 2 sqrtm(sigma1 sigma2))``. As in T2M: if the matrix
    square root is not finite, retry with ``eps`` added to both diagonals; an imaginary part whose
    diagonal exceeds 1e-3 is an error, a smaller one is dropped.

    Parameters
    ----------
    mu1, mu2 : array ``(C,)``
    sigma1, sigma2 : array ``(C, C)``
    """
    mu1, mu2 = np.atleast_1d(np.asarray(mu1, np.float64)), np.atleast_1d(np.asarray(mu2, np.float64))
    sigma1, sigma2 = np.atleast_2d(np.asarray(sigma1, np.float64)), np.atleast_2d(np.asarray(sigma2, np.float64))
    c = mu1.shape[0]
    if mu1.shape != (c,) or mu2.shape != (c,):
        raise ValueError(f"mu1 {mu1.shape} and mu2 {mu2.shape} must both be (C,)")
    if sigma1.shape != (c, c) or sigma2.shape != (c, c):
        raise ValueError(f"sigma1 {sigma1.shape} and sigma2 {sigma2.shape} must both be (C, C) with C={c}")
    diff = mu1 - mu2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", linalg.LinAlgWarning)
        warnings.simplefilter("ignore", RuntimeWarning)
        covmean = linalg.sqrtm(sigma1 @ sigma2)
        if not np.isfinite(covmean).all():
            logger.warning("fid: sqrtm(sigma1 sigma2) is not finite; adding %g to the diagonals", eps)
            offset = np.eye(c) * eps
            covmean = linalg.sqrtm((sigma1 + offset) @ (sigma2 + offset))
    if np.iscomplexobj(covmean):
        if not np.allclose(np.diagonal(covmean).imag, 0, atol=1e-3):
            raise ValueError(f"fid: sqrtm has an imaginary component of size {np.abs(covmean.imag).max():.3g}")
        covmean = covmean.real
    return float(diff @ diff + np.trace(sigma1) + np.trace(sigma2) - 2.0 * np.trace(covmean))


def fid(real_emb: np.ndarray, gen_emb: np.ndarray, eps: float = 1e-6) -> float:
    """FID between real and generated motion embeddings ``(N1, C)`` and ``(N2, C)``.

    Fits a Gaussian to each (:func:`activation_statistics`) and returns their
    :func:`frechet_distance`. For replications against one fixed real set, compute its statistics
    once and call :func:`frechet_distance` directly.
    """
    r = _as_2d(real_emb, "real_emb")
    g = _as_2d(gen_emb, "gen_emb")
    if r.shape[1] != g.shape[1]:
        raise ValueError(f"real_emb and gen_emb must have the same width C, got {r.shape[1]} and {g.shape[1]}")
    return frechet_distance(*activation_statistics(r), *activation_statistics(g), eps=eps)


def diversity(emb: np.ndarray, n_pairs: int = 300, rng=None) -> float:
    """Diversity: mean distance between ``n_pairs`` random pairs of (generated) motion embeddings.

    Two index sets of size ``n_pairs`` are drawn independently, each without replacement, and
    row ``a_i`` is paired with row ``b_i`` (T2M; a pair may repeat an index and then adds 0).

    Parameters
    ----------
    emb : array ``(N, C)`` with ``N > n_pairs``
        MoMask and SALAD use ``n_pairs = 300`` when ``N > 300`` and 100 otherwise.
    n_pairs : int
    rng : numpy Generator, int seed or None
    """
    e = _as_2d(emb, "emb")
    if not isinstance(n_pairs, (int, np.integer)) or n_pairs < 1:
        raise ValueError(f"n_pairs must be a positive int, got {n_pairs!r}")
    if e.shape[0] <= n_pairs:
        raise ValueError(f"diversity needs more than n_pairs={n_pairs} embeddings, got N={e.shape[0]} "
                         f"(use a smaller n_pairs, e.g. 100 as MoMask/SALAD do for N <= 300)")
    g = _rng(rng)
    first = g.choice(e.shape[0], n_pairs, replace=False)
    second = g.choice(e.shape[0], n_pairs, replace=False)
    return float(np.linalg.norm(e[first] - e[second], axis=1).mean())


def multimodality(emb: np.ndarray, n_pairs: int = 10, rng=None) -> float:
    """MultiModality: mean distance between generations of the same text.

    One draw of ``n_pairs`` first and ``n_pairs`` second repeat indices (each without
    replacement) is shared by all texts, as in T2M.

    Parameters
    ----------
    emb : array ``(n_texts, n_repeats, C)`` with ``n_repeats > n_pairs``
        Protocol: 100 (T2M) or 96 (MoMask/SALAD) texts x 30 repeats, 10 pairs.
    n_pairs : int
    rng : numpy Generator, int seed or None
    """
    e = np.asarray(emb, dtype=np.float64)
    if e.ndim != 3:
        raise ValueError(f"emb must be (n_texts, n_repeats, C), got shape {e.shape}")
    if not np.isfinite(e).all():
        raise ValueError("emb contains NaN or inf")
    if not isinstance(n_pairs, (int, np.integer)) or n_pairs < 1:
        raise ValueError(f"n_pairs must be a positive int, got {n_pairs!r}")
    if e.shape[0] == 0:
        raise ValueError("multimodality needs at least one text, got n_texts=0")
    if e.shape[1] <= n_pairs:
        raise ValueError(f"multimodality needs n_repeats > n_pairs={n_pairs}, got n_repeats={e.shape[1]}")
    g = _rng(rng)
    first = g.choice(e.shape[1], n_pairs, replace=False)
    second = g.choice(e.shape[1], n_pairs, replace=False)
    return float(np.linalg.norm(e[:, first] - e[:, second], axis=2).mean())


def mpjpe(pred_joints: np.ndarray, gt_joints: np.ndarray, root_aligned: bool = True,
          mask: np.ndarray | None = None, root: int = 0) -> float:
    """Mean per-joint position error, averaged over joints and then over (valid) poses.

    As SALAD's VAE evaluation: per pose, optionally subtract each skeleton's root joint, take the
    Euclidean error of every joint, average over joints; then average over all poses.

    Parameters
    ----------
    pred_joints, gt_joints : array ``(..., N, J, 3)``
        E.g. ``(N, J, 3)`` or ``(B, N, J, 3)``; in metres for HumanML3D (so is the result).
    root_aligned : bool
        Subtract joint ``root`` from every joint of the same pose first.
    mask : bool array ``(..., N)``, optional
        True for poses that count (frames before each motion's length).
    root : int
        Index of the root joint; 0 in every salad skeleton (``skeleton.parents[0] == -1``).
    """
    p = np.asarray(pred_joints, dtype=np.float64)
    g = np.asarray(gt_joints, dtype=np.float64)
    if p.shape != g.shape:
        raise ValueError(f"pred_joints {p.shape} and gt_joints {g.shape} must have the same shape")
    if p.ndim < 3 or p.shape[-1] != 3:
        raise ValueError(f"joints must be (..., N, J, 3), got shape {p.shape}")
    if not -p.shape[-2] <= root < p.shape[-2]:
        raise ValueError(f"root={root} is not a joint index for J={p.shape[-2]}")
    if root_aligned:
        p = p - p[..., root:root + 1, :]
        g = g - g[..., root:root + 1, :]
    per_pose = np.linalg.norm(p - g, axis=-1).mean(-1)          # (..., N)
    if mask is None:
        if per_pose.size == 0:
            raise ValueError("mpjpe needs at least one pose")
        return float(per_pose.mean())
    m = np.asarray(mask)
    if m.shape != per_pose.shape:
        raise ValueError(f"mask must have the joints' leading shape {per_pose.shape}, got {m.shape}")
    m = m.astype(bool)
    if not m.any():
        raise ValueError("mask selects no pose")
    return float(per_pose[m].mean())


def mean_ci(values, confidence_z: float = 1.96) -> tuple[np.float64 | np.ndarray, np.float64 | np.ndarray]:
    """Mean and 95% confidence half-width over replications.

    ``half_width = z * std / sqrt(R)`` with ``std = np.std(values, axis=0)``, i.e. the population
    standard deviation (ddof = 0), exactly as T2M / MoMask / SALAD report ``mean ± half_width``.

    Parameters
    ----------
    values : array ``(R,)`` or ``(R, M)``
        R replications of one metric, or of M metrics side by side.
    confidence_z : float
        1.96 for a 95% interval.

    Returns
    -------
    mean, half_width : ``np.float64`` scalars (a float subclass) for ``(R,)`` input, ``(M,)`` arrays
        for ``(R, M)`` input
    """
    v = np.asarray(values, dtype=np.float64)
    if v.ndim not in (1, 2):
        raise ValueError(f"values must be (R,) or (R, M), got shape {v.shape}")
    if v.shape[0] < 1:
        raise ValueError("mean_ci needs at least one replication")
    if not np.isfinite(v).all():
        raise ValueError("values contains NaN or inf")
    mean = v.mean(axis=0)
    half = confidence_z * v.std(axis=0) / np.sqrt(v.shape[0])
    return mean, half
