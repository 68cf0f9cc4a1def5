"""Length-aware batching: batches of clips of similar length, so a batch pays for the frames it has.

A random batch is padded to its longest member: on the procedural corpus (clips of 40-196 frames,
mean 79) a random batch of 32 holds about 2.2x the valid latent frames it computes on. The
:class:`LengthBucketBatchSampler` shuffles the items, cuts the shuffled order into *pools* of
``pool_batches`` global batches, sorts each pool by length, cuts it into global batches and shuffles
the order of all the epoch's batches. A batch is then padded by a few frames at most while every
epoch still draws new batch compositions and a new order.

Everything is a function of ``(seed, epoch)``: every rank computes the same list of global batches
and keeps its share (positions ``rank, rank + W, ...`` of each length-sorted global batch, so ranks
get items of similar length and the same number of items), which makes the ranks' batches disjoint,
equally many, and the union over ranks the single-process batch. Resuming mid-epoch skips the
``start`` batches already used without loading them, as
:class:`~salad_core.train.common.ResumableBatchSampler` does.

Loss weighting (why the trainers change their normaliser with this sampler): a masked mean over
the valid frames of a *batch* gives each frame the weight ``1 / (frames in its batch)``. With
random batches that count is about the same for every batch, so every frame weighs about the same
and a long clip counts in proportion to its length. With length-sorted batches a batch of short
clips has few frames, so the same mean would give each of its frames a larger weight and bias the
objective towards short clips. The trainers therefore divide the summed squared error of a bucketed
batch by ``batch_size x expected valid frames per item`` (a constant of the dataset, see
:func:`expected_latent_frames`): every frame has the same weight in every batch, the expected
gradient is the per-frame mean of the whole corpus (what random batches estimate), and only its
batch-to-batch spread changes.

Measured cost of the sorting (default denoiser config, small procedural corpus, shipped VAE, 300
steps, two seeds; ``bench/bench_training.py`` and one evaluation of every step-300 checkpoint with
the same noise): the bucketed trainer runs 2.33x / 2.35x the steps per second of release 0.5, but
learns less per step: validation loss 0.803 / 0.806 against 0.763 / 0.753 (random batches), 0.785
with ``pool_batches=4``, 0.762 with random batches and the latent cache (so the cache is not the
cause). Batches of equal length hold similar clips (on the procedural corpus length
follows the action), so their gradients vary more. At equal wall-clock time the bucketed run is
ahead (training loss 0.80 at its step 300 against 0.88 at the old trainer's step 130). A smaller
pool trades padding (1.30x at 4 batches against 1.09x at 16) for batch diversity.

``equal_frames=True`` (``batching="frames"``) cuts the same sorted pools into batches of about
``batch_size x mean length`` valid frames (short clips in bigger batches), so every step sees as many
frames as a random batch: validation loss at step 300 0.789 / 0.794, between the two. The denoiser's
default is therefore neither: random batches cut into length-sorted *micro-batches*
(``config.micro_batches``, :func:`~salad_core.train.denoiser_trainer.split_denoiser_inputs`), which
keep the random batch's composition and gradient and still skip most padded frames (2.03x release
0.5's samples x frames/s with the latent cache, the same loss curve: docs/performance.md).
"""
from __future__ import annotations

import math
from typing import Iterator, Sequence

import numpy as np
from torch.utils.data import Sampler

__all__ = ["LengthBucketBatchSampler", "expected_latent_frames", "padding_ratio"]


class LengthBucketBatchSampler(Sampler[list[int]]):
    """Batches of items of similar length, deterministic per ``(seed, epoch)``, for one rank.

    Parameters
    ----------
    lengths : sequence of int, shape ``(n,)``
        The cost of each item (frames); only their order matters.
    batch_size : int
        The *global* batch (split over ``world_size`` ranks; must be divisible by it).
    rank, world_size : int
        This process and the number of processes.
    seed : int
        Seeds the shuffles together with the epoch.
    pool_batches : int
        Global batches per pool sorted by length (larger: less padding, batch compositions closer
        to a fixed sort; 1: random batches, each sorted internally).
    start : int
        Batches of the epoch already consumed (resume): iteration starts after them.

    Notes
    -----
    Every epoch uses ``n // batch_size`` full global batches; the ``n % batch_size`` left-over items
    are drawn at random each epoch (before pooling, so the long clips are not the ones dropped).
    """

    def __init__(self, lengths: Sequence[int], batch_size: int, *, rank: int = 0, world_size: int = 1,
                 seed: int = 0, pool_batches: int = 16, start: int = 0, equal_frames: bool = False) -> None:
        lengths = np.asarray(lengths)
        if lengths.ndim != 1 or lengths.size == 0:
            raise ValueError(f"lengths must be a non-empty 1-d sequence, got shape {lengths.shape}")
        for name, value, low in (("batch_size", batch_size, 1), ("world_size", world_size, 1),
                                 ("pool_batches", pool_batches, 1), ("start", start, 0), ("rank", rank, 0)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise ValueError(f"{name}={value!r} is invalid; use an integer >= {low}")
        if rank >= world_size:
            raise ValueError(f"rank={rank} is invalid; use 0 <= rank < world_size={world_size}")
        if batch_size % world_size:
            raise ValueError(f"batch_size={batch_size} is not divisible by world_size={world_size}; it is the "
                             "global batch and is split evenly")
        self.lengths = lengths.astype(np.int64)
        self.batch_size, self.rank, self.world_size = int(batch_size), int(rank), int(world_size)
        self.seed, self.pool_batches, self.start = int(seed), int(pool_batches), int(start)
        self.equal_frames = bool(equal_frames)
        self.frames_per_batch = float(batch_size * self.lengths.mean())
        self.epoch = 0
        self._cached: tuple[int, list[np.ndarray]] | None = None

    def set_epoch(self, epoch: int) -> None:
        """Select the epoch whose batches :meth:`__iter__` yields."""
        self.epoch = int(epoch)

    @property
    def batches_per_epoch(self) -> int:
        """Global batches of the current epoch (with ``equal_frames`` it varies a little by epoch)."""
        if self.equal_frames:
            return len(self.global_batches())
        return len(self.lengths) // self.batch_size

    def global_batches(self, epoch: int | None = None) -> list[np.ndarray]:
        """The epoch's global batches in order, each an array of item indices sorted by length.

        Fixed mode: ``(batch_size,)`` items each. ``equal_frames``: a multiple of ``world_size`` items
        each, about ``batch_size x mean length`` valid frames each.
        """
        epoch = self.epoch if epoch is None else int(epoch)
        if self.equal_frames:
            if self._cached is None or self._cached[0] != epoch:
                self._cached = (epoch, self._equal_frame_batches(epoch))
            return self._cached[1]
        rng = np.random.default_rng([self.seed, epoch, 0x5A1AD])
        n_batches, bs = self.batches_per_epoch, self.batch_size
        used = rng.permutation(len(self.lengths))[: n_batches * bs]
        pool = self.pool_batches * bs
        batches: list[np.ndarray] = []
        for p0 in range(0, len(used), pool):
            chunk = used[p0: p0 + pool]
            # stable sort of a shuffled chunk: equal lengths stay in random order
            chunk = chunk[np.argsort(self.lengths[chunk], kind="stable")]
            batches += [chunk[i: i + bs] for i in range(0, len(chunk), bs)]
        order = rng.permutation(len(batches))
        return [batches[i] for i in order]

    def _equal_frame_batches(self, epoch: int) -> list[np.ndarray]:
        """Length-sorted pools cut where the running sum of lengths crosses multiples of the pool's
        frames / round(pool's frames / frames_per_batch), at item counts that are multiples of
        ``world_size``: every batch holds about the same number of valid frames."""
        rng = np.random.default_rng([self.seed, epoch, 0xF4A3E])
        w = self.world_size
        n = len(self.lengths) - len(self.lengths) % w
        used = rng.permutation(len(self.lengths))[:n]
        pool = self.pool_batches * self.batch_size
        batches: list[np.ndarray] = []
        for p0 in range(0, n, pool):
            chunk = used[p0: p0 + pool]
            chunk = chunk[np.argsort(self.lengths[chunk], kind="stable")]
            sizes = self.lengths[chunk].astype(np.float64)
            n_b = max(1, int(round(sizes.sum() / self.frames_per_batch)))
            n_b = min(n_b, len(chunk) // w)
            if n_b == 0:        # a last pool smaller than one item per rank: nothing to share out
                continue
            cum = np.cumsum(sizes)
            cuts = np.searchsorted(cum, cum[-1] * np.arange(1, n_b) / n_b, side="left") + 1
            cuts = np.clip(np.round(cuts / w).astype(np.int64) * w, w, len(chunk) - w)
            edges = np.unique(np.concatenate([[0], cuts, [len(chunk)]]))
            batches += [chunk[a: b] for a, b in zip(edges[:-1], edges[1:]) if b > a]
        order = rng.permutation(len(batches))
        return [batches[i] for i in order]

    def __iter__(self) -> Iterator[list[int]]:
        for batch in self.global_batches()[self.start:]:
            yield batch[self.rank::self.world_size].tolist()

    def __len__(self) -> int:
        return max(0, self.batches_per_epoch - self.start)


def expected_latent_frames(lengths: Sequence[int], unit: int, shorten_prob: float = 1.0 / 3.0) -> float:
    """Mean valid latent frames of an item under the T2M random crop.

    An item of ``L`` frames is floored to ``F = (L // unit) * unit`` frames and shortened by one
    unit with probability ``shorten_prob`` (``MotionTextDataset``'s "double"), so it has
    ``F / unit - shorten_prob`` latent frames on average (never fewer than one).

    Parameters
    ----------
    lengths : sequence of int ``(n,)``
        Frames of each item before flooring.
    unit : int
        Frames per latent frame (the VAE's temporal down-sampling).
    shorten_prob : float
        Probability of the one-unit shortening.
    """
    full = np.asarray(lengths, dtype=np.int64) // unit
    if full.size == 0:
        raise ValueError("lengths is empty")
    short = np.maximum(full - 1, 1)
    return float(np.mean((1.0 - shorten_prob) * full + shorten_prob * short))


def padding_ratio(lengths: Sequence[int], batches: Sequence[Sequence[int]]) -> float:
    """Frames computed over valid frames when each batch is padded to its longest item (>= 1)."""
    lengths = np.asarray(lengths)
    padded = sum(len(b) * int(lengths[list(b)].max()) for b in batches if len(b))
    valid = sum(int(lengths[list(b)].sum()) for b in batches if len(b))
    return padded / valid if valid else math.nan
