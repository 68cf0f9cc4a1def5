"""The protocol's real test batches, its random streams and the evaluator embeddings of a batch.

One *replication* (Guo et al. 2022; ``humanml3d_eval_facts`` §5) iterates the test split in a fresh
random order and cuts it into batches of ``batch_size``; each item carries a random caption of its
clip and a random crop whose length is a multiple of the unit length (4 frames), as the T2M loader
(:class:`~salad_core.data.dataset.MotionTextDataset`) draws them. The crops, captions and order are
a function of ``(settings.seed, replication)`` only.

Used by :mod:`salad_core.eval.protocol` (generation) and :mod:`salad_core.eval.reconstruction`
(VAE round trips), which score the very same batches.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from os import PathLike
from typing import Any

import numpy as np
import torch

from salad_core.skeleton import Skeleton, get_skeleton

from .settings import EvalSettings

__all__ = [
    "RealBatch",
    "TAG_ORDER",
    "TAG_GEN",
    "TAG_MM",
    "TAG_DIV",
    "TAG_MMPAIRS",
    "REFERENCE_EPOCH",
    "derived_seed",
    "derived_rng",
    "skeleton_of",
    "evaluation_dataset",
    "num_batches",
    "batches_for",
    "real_batches",
    "motion_embeddings",
    "text_embeddings",
]

# Seed-sequence tags keep the random streams of the protocol apart (order, generation noise,
# MultiModality noise, Diversity pairs, MultiModality pairs).
TAG_ORDER, TAG_GEN, TAG_MM, TAG_DIV, TAG_MMPAIRS = range(5)
#: Data-loader epoch offset of the independent reference pass of the real row.
REFERENCE_EPOCH = 1_000_000


@dataclass(frozen=True)
class RealBatch:
    """One evaluation batch of real test items (raw, de-normalised features)."""

    captions: list[str]            # B caption strings, as given to the generator
    tokens: list[list[str]]        # B "word/POS" token lists, as given to the evaluator
    lengths: np.ndarray            # (B,) int64 frames, multiples of the unit length
    motions: np.ndarray            # (B, N, D) float32 raw features, zero past each length
    names: list[str]               # dataset item names


def derived_seed(settings: EvalSettings, *tags: int) -> int:
    """An int seed of the stream ``tags`` (e.g. ``TAG_GEN, replication, batch``) under ``settings.seed``."""
    return int(np.random.SeedSequence([settings.seed, *tags]).generate_state(1)[0])


def derived_rng(settings: EvalSettings, *tags: int) -> np.random.Generator:
    """A numpy generator of the stream ``tags`` under ``settings.seed``."""
    return np.random.default_rng(np.random.SeedSequence([settings.seed, *tags]))


def skeleton_of(evaluator: Any) -> Skeleton:
    """The skeleton whose feature width the evaluator expects (``evaluator.config.dim_pose``)."""
    d = evaluator.config.dim_pose
    for name in ("humanml3d", "kit"):
        sk = get_skeleton(name)
        if sk.feature_dim == d:
            return sk
    raise ValueError(f"the evaluator expects {d}-d features; no known skeleton has that width (263, 251)")


def evaluation_dataset(dataset_root: str | PathLike, settings: EvalSettings, skeleton: Skeleton) -> Any:
    """The split as a random-crop :class:`~salad_core.data.dataset.MotionTextDataset` of raw features."""
    from salad_core.data.dataset import MotionTextDataset

    # raw features: the evaluator normalises with its own statistics (humanml3d_eval_facts §5.4)
    return MotionTextDataset(dataset_root, settings.split, skeleton=skeleton, normalize=False, random_crop=True,
                             seed=settings.seed)


def num_batches(n_items: int, settings: EvalSettings) -> int:
    """Full batches of one replication (capped by ``settings.max_samples``); at least one or an error."""
    n = n_items // settings.batch_size
    if n == 0:
        raise ValueError(f"split {settings.split!r} has {n_items} usable items, fewer than one batch of "
                         f"{settings.batch_size}")
    if settings.max_samples is not None:
        n = min(n, math.ceil(settings.max_samples / settings.batch_size))
    return n


def batches_for(dataset: Any, settings: EvalSettings, epoch: int, order_tag: int) -> list[RealBatch]:
    """The batches of one pass: crops and captions of loader epoch ``epoch``, item order of ``order_tag``.

    The real row's reference pass uses another epoch with the same order tag: the same items with
    independent crops and captions.
    """
    dataset.set_epoch(epoch)
    order = derived_rng(settings, TAG_ORDER, order_tag).permutation(len(dataset))
    out = []
    bs = settings.batch_size
    for b in range(num_batches(len(dataset), settings)):
        items = [dataset[int(i)] for i in order[b * bs:(b + 1) * bs]]
        lengths = np.array([it["length"] for it in items], dtype=np.int64)
        n = int(lengths.max())
        motions = np.stack([it["motion"][:n] for it in items]).astype(np.float32)
        out.append(RealBatch([it["caption"] for it in items], [list(it["tokens"]) for it in items], lengths,
                             motions, [it["name"] for it in items]))
    return out


def real_batches(dataset_root: str | PathLike, settings: EvalSettings, replication: int,
                 skeleton: str | Skeleton = "humanml3d") -> list[RealBatch]:
    """The real batches of one replication, exactly as :func:`~salad_core.eval.protocol.evaluate_generator`
    iterates them.

    The crops, captions and order are a function of ``(settings.seed, replication)`` only, so the
    same call always returns the same batches (useful for replay generators in tests).
    """
    if not isinstance(replication, (int, np.integer)) or replication < 0:
        raise ValueError(f"replication={replication!r} must be an int >= 0")
    return batches_for(evaluation_dataset(dataset_root, settings, get_skeleton(skeleton)), settings,
                       int(replication), int(replication))


def motion_embeddings(evaluator: Any, motions: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """``(B, C)`` float64 evaluator embeddings of raw motions ``(B, N, D)`` with ``lengths`` ``(B,)``."""
    x = evaluator.normalize(motions)                                  # (B, N, D) evaluator statistics
    return evaluator.motion_embeddings(x, torch.as_tensor(lengths), mask_padding=True).double().cpu().numpy()


def text_embeddings(evaluator: Any, tokens: list[list[str]]) -> np.ndarray:
    """``(B, C)`` float64 evaluator embeddings of ``B`` "word/POS" token lists."""
    return evaluator.caption_embeddings(tokens).double().cpu().numpy()
