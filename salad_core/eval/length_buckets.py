"""Faster evaluation of SALAD: denoise each batch in groups of similar length.

:class:`LengthBucketed` wraps a pipeline so that short motions of a protocol batch are not denoised
at the batch's longest length (:func:`length_groups` picks the groups with the least padding); the
motions are the same as one batched call's, up to floating-point reduction order.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

__all__ = ["length_groups", "BucketedOutput", "LengthBucketed"]


def length_groups(lengths: Sequence[int], groups: int) -> list[np.ndarray]:
    """Split a batch into at most ``groups`` groups of consecutive lengths with the least padding.

    Minimises ``sum over groups of (size x longest length)``, the frames a denoiser processes when
    each group is padded to its longest motion (exact dynamic programme over the sorted lengths).

    Returns
    -------
    list of int64 arrays
        Indices into ``lengths``; together they are a permutation of ``range(len(lengths))``.
    """
    lens = np.asarray(lengths, dtype=np.int64).reshape(-1)
    if lens.size == 0:
        raise ValueError("lengths is empty")
    if isinstance(groups, bool) or not isinstance(groups, (int, np.integer)) or groups < 1:
        raise ValueError(f"groups={groups!r} must be an int >= 1")
    order = np.argsort(lens, kind="stable")
    s = lens[order]
    n, k = len(s), min(int(groups), len(s))
    # cost[g][i]: least padded frames for the first i sorted items in g groups (a group [j, i) costs (i - j) * s[i-1])
    cost = np.full((k + 1, n + 1), np.inf)
    cut = np.zeros((k + 1, n + 1), dtype=np.int64)
    cost[0, 0] = 0.0
    for g in range(1, k + 1):
        for i in range(g, n + 1):
            j = np.arange(g - 1, i)
            c = cost[g - 1, j] + (i - j) * s[i - 1]
            best = int(np.argmin(c))
            cost[g, i], cut[g, i] = c[best], j[best]
    g = int(np.argmin(cost[1:, n])) + 1               # fewer groups when more do not help
    bounds, i = [], n
    while g > 0:
        j = int(cut[g, i])
        bounds.append((j, i))
        i, g = j, g - 1
    return [order[a:b] for a, b in reversed(bounds)]


@dataclass
class BucketedOutput:
    """What :class:`LengthBucketed` returns (the fields the protocol and the notebooks read)."""

    features: np.ndarray           # (B, max(lengths), D) raw features, zero past each length
    joints: list[np.ndarray]       # per sample (N_b, J, 3)
    texts: list[str]               # the prompts
    lengths: list[int]             # N_b


class LengthBucketed:
    """A SALAD generator that denoises each batch in groups of similar length.

    ``SaladPipeline`` pads a batch to its longest motion; in the T2M protocol's batches of 32
    random test items the longest is often twice the mean, so most of the work is padding.
    Grouping (:func:`length_groups`) removes most of it. Each sample keeps its own noise seed
    (``seed + b``, as the pipeline draws it) and padded frames are masked, so the motions equal
    those of one batched call up to floating-point reduction order.

    Parameters
    ----------
    pipe : SaladPipeline
        Or anything whose call takes per-sample seeds ``seed=[...]`` and returns ``features``,
        ``joints``, ``texts``, ``lengths``.
    groups : int
        Most calls per batch.
    """

    def __init__(self, pipe: Any, groups: int = 3) -> None:
        if isinstance(groups, bool) or not isinstance(groups, int) or groups < 1:
            raise ValueError(f"groups={groups!r} must be an int >= 1")
        self.pipe = pipe
        self.groups = groups
        self.source = getattr(pipe, "source", None)

    def __call__(self, prompts: Sequence[str], lengths: Sequence[int], seed: int | Sequence[int] = 0,
                 **kwargs: Any) -> BucketedOutput:
        prompts = [prompts] if isinstance(prompts, str) else list(prompts)
        if isinstance(lengths, (int, np.integer)):
            lengths = [int(lengths)] * len(prompts)
        lengths = [int(n) for n in lengths]
        if len(lengths) != len(prompts):
            raise ValueError(f"got {len(lengths)} lengths for {len(prompts)} prompts; give one length per prompt")
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            seeds = [int(seed) + b for b in range(len(prompts))]   # the pipeline's own per-sample rule
        else:
            seeds = [int(s) for s in seed]
            if len(seeds) != len(prompts):
                raise ValueError(f"got {len(seeds)} seeds for {len(prompts)} prompts")
        feats: np.ndarray | None = None
        joints: list[Any] = [None] * len(prompts)
        for idx in length_groups(lengths, self.groups):
            out = self.pipe([prompts[i] for i in idx], lengths=[lengths[i] for i in idx],
                            seed=[seeds[i] for i in idx], **kwargs)
            f = np.asarray(out.features)
            if feats is None:
                feats = np.zeros((len(prompts), max(lengths), f.shape[-1]), dtype=np.float32)
            for j, i in enumerate(idx):
                feats[i, : lengths[i]] = f[j, : lengths[i]]
                joints[i] = out.joints[j]
        return BucketedOutput(features=feats, joints=joints, texts=prompts, lengths=lengths)
