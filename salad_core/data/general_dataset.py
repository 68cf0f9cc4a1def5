"""VAE training data beyond the captioned corpus: uncaptioned motion folders and a corpus/general mixture.

The VAE trainer (:mod:`salad_core.train.vae_trainer`) consumes :class:`~.dataset.MotionWindowDataset`
items, ``dict(motion=float32 (window, D))`` normalised, and reads ``dataset.mean`` / ``dataset.std``
for the statistics it saves with the model. :class:`MixtureWindowDataset` gives exactly those items,
drawing a share ``ratio`` of every epoch from a second window set (the general-motion set built by
:func:`~salad_core.data.procedural.general_build.build_general`) and the rest from the corpus.

Wiring (what the VAE trainer would do)::

    mean, std = mixture_mean_std(corpus_root, general_root, ratio=0.5)
    corpus = MotionWindowDataset(corpus_root, "train", window=64, mean=mean, std=std)
    general = general_windows(general_root, "train", window=64, mean=mean, std=std)
    train_set = MixtureWindowDataset(corpus, general, ratio=0.5, seed=seed)

**Default ratio 0.5.** The corpus's windows are the only motion the denoiser will generate and
captioned actions must keep their reconstruction, so they keep half of every batch; the other
half buys coverage of poses, orientations and root paths the 25 actions never show. An epoch is
``len(corpus) / (1 - ratio)`` items, so every corpus window is still drawn once per epoch (the
corpus is seen as often per epoch as without the mixture; epochs take twice the steps).

**Normalisation.** Pass one pair of statistics to both parts (the VAE has one input scaling).
Measured (``lab/scripts/vae/measure_vae_real.py --stats``, corpus "small" seed 0 against the general set
n=4000 seed 0, training splits): 7-14 % of the general values of root velocity and ric fall
outside the corpus's per-dimension range, the per-dimension std of the general set is 2-6 times
the corpus's, and its 99th percentile of ``|x - mean| / std`` under the corpus statistics is 7-12
against the corpus's own 3.5-6.4. With the corpus's statistics the general half of each batch
would dominate the (L1-like) loss, so the mixture should be normalised with statistics of the
mixture itself: :func:`mixture_mean_std` (HumanML3D's block-averaged std over the corpus's and the
general set's training clips, the general share matching ``ratio``). The trainer saves them with
the model (``mean_std.safetensors``) and the denoiser is retrained on the new VAE anyway.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from torch.utils.data import Dataset

from .dataset import MotionWindowDataset

__all__ = ["DEFAULT_RATIO", "general_windows", "mixture_mean_std", "MixtureWindowDataset"]

#: Share of general-motion windows in a mixture epoch (see the module notes).
DEFAULT_RATIO = 0.5


def general_windows(root: str | Path, split: str = "train", window: int = 64, *, mean: np.ndarray,
                    std: np.ndarray, skeleton: str = "humanml3d") -> MotionWindowDataset:
    """Every ``window``-frame window of an uncaptioned motion folder, normalised with the given statistics.

    The folder needs ``new_joint_vecs/`` and ``<split>.txt`` only (no texts, no Mean/Std): the
    statistics are those of the data it is mixed with, so they are required here.
    """
    if mean is None or std is None:
        raise ValueError("general_windows needs mean and std (the statistics the VAE is trained with)")
    return MotionWindowDataset(root, split, window=window, skeleton=skeleton, mean=mean, std=std)


def mixture_mean_std(corpus_root: str | Path, general_root: str | Path, ratio: float = DEFAULT_RATIO,
                     split: str = "train", seed: int = 0, skeleton: str = "humanml3d") -> tuple[np.ndarray, np.ndarray]:
    """Mean/Std ``(D,)`` float32 of a corpus/general mixture (HumanML3D's block-averaged std).

    All of the corpus's ``split`` clips, plus general clips (in a seeded order) until their frames
    are ``ratio / (1 - ratio)`` times the corpus's, so the statistics match the mixture's share.
    """
    from salad_core.motion import compute_mean_std
    from salad_core.skeleton import get_skeleton

    from .dataset import read_split

    if not 0.0 <= float(ratio) < 1.0:
        raise ValueError(f"ratio={ratio!r} must be a float in [0, 1)")
    corpus_root, general_root = Path(corpus_root), Path(general_root)
    from salad_core.limits import read_npy

    arrays = [read_npy(corpus_root / "new_joint_vecs" / f"{i}.npy") for i in read_split(corpus_root, split)]
    want = float(ratio) / (1.0 - float(ratio)) * sum(len(a) for a in arrays)
    ids = read_split(general_root, split)
    got = 0
    for k in np.random.default_rng([int(seed), 0x57A7]).permutation(len(ids)):
        if got >= want:
            break
        a = read_npy(general_root / "new_joint_vecs" / f"{ids[k]}.npy")
        arrays.append(a)
        got += len(a)
    mean, std = compute_mean_std(arrays, get_skeleton(skeleton))
    return np.asarray(mean, dtype=np.float32), np.asarray(std, dtype=np.float32)


class MixtureWindowDataset(Dataset):
    """Windows drawn from ``primary`` and, with share ``ratio``, from ``secondary``.

    Parameters
    ----------
    primary, secondary : MotionWindowDataset (or any dataset of the same items)
        The corpus and the general set. They must share the normalisation (``mean``, ``std``).
    ratio : float in [0, 1)
        Share of items of an epoch taken from ``secondary`` (exact up to rounding).
    seed : int
        With :meth:`set_epoch`, every item is a function of ``(seed, epoch, index)``.
    length : int, optional
        Items per epoch (default ``round(len(primary) / (1 - ratio))``: each primary window once).

    Items are the sources' items unchanged: ``dict(motion=float32 (window, D))``.
    """

    def __init__(self, primary: Dataset, secondary: Dataset, ratio: float = DEFAULT_RATIO, seed: int = 0,
                 length: int | None = None) -> None:
        if isinstance(ratio, bool) or not isinstance(ratio, (int, float)) or not 0.0 <= float(ratio) < 1.0:
            raise ValueError(f"ratio={ratio!r} must be a float in [0, 1)")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed={seed!r} must be a non-negative int")
        if len(primary) == 0 or (ratio > 0 and len(secondary) == 0):
            raise ValueError(f"both datasets must hold items (primary {len(primary)}, secondary {len(secondary)})")
        for what in ("mean", "std"):
            a, b = getattr(primary, what, None), getattr(secondary, what, None)
            if a is not None and b is not None and not np.array_equal(np.asarray(a), np.asarray(b)):
                raise ValueError(f"primary and secondary use different normalisation ({what} differs); build the "
                                 f"secondary with the primary's statistics (general_windows(..., mean=, std=))")
        self.primary, self.secondary = primary, secondary
        self.ratio, self.seed = float(ratio), int(seed)
        if length is None:
            length = int(round(len(primary) / (1.0 - self.ratio)))
        if isinstance(length, bool) or not isinstance(length, int) or length < 1:
            raise ValueError(f"length={length!r} must be a positive int")
        self.length = length
        self.mean = getattr(primary, "mean", None)
        self.std = getattr(primary, "std", None)
        self.epoch = 0
        self._plan_epoch: int | None = None

    def __len__(self) -> int:
        return self.length

    def set_epoch(self, epoch: int) -> None:
        """Draw a new assignment of items to sources (deterministic per ``(seed, epoch)``)."""
        self.epoch = int(epoch)

    def _plan(self) -> tuple[np.ndarray, np.ndarray]:
        """Per item: source (0 primary, 1 secondary) and the index within it, for this epoch."""
        if self._plan_epoch != self.epoch:
            rng = np.random.default_rng([self.seed, self.epoch, 0x5A1AD])
            n_sec = int(round(self.ratio * self.length))
            source = np.zeros(self.length, dtype=np.int8)
            source[rng.permutation(self.length)[:n_sec]] = 1
            index = np.empty(self.length, dtype=np.int64)
            for s, ds in ((0, self.primary), (1, self.secondary)):
                slots = np.flatnonzero(source == s)
                if slots.size:
                    # whole permutations of the source, repeated as needed: no window drawn twice
                    # before every window has been drawn once
                    reps = -(-slots.size // len(ds))
                    order = np.concatenate([rng.permutation(len(ds)) for _ in range(reps)])[: slots.size]
                    index[slots] = order
            self._source, self._index, self._plan_epoch = source, index, self.epoch
        return self._source, self._index

    def locate(self, index: int) -> tuple[str, int]:
        """``("primary" | "secondary", index within that dataset)`` of item ``index`` this epoch."""
        if not -len(self) <= index < len(self):
            raise IndexError(f"index {index} out of range for a mixture of {len(self)} items")
        source, idx = self._plan()
        i = index % len(self)
        return ("secondary" if source[i] else "primary"), int(idx[i])

    def __getitem__(self, index: int) -> dict[str, Any]:
        which, i = self.locate(index)
        return (self.secondary if which == "secondary" else self.primary)[i]

    def __repr__(self) -> str:
        return (f"MixtureWindowDataset(items={len(self)}, ratio={self.ratio}, primary={len(self.primary)}, "
                f"secondary={len(self.secondary)}, seed={self.seed}, epoch={self.epoch})")
