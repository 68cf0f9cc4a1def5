"""Rest padding: training windows in which a whole clip is held still before and after it.

KeyMotion's keyframe VAE encodes keyframe positions normalised to the motion's length (``u = i / (L - 1)``), so a
keyframe latent has no time scale of its own: decoded at a longer length, the same latent gives the same motion
slowed down. The procedural corpus (like HumanML3D) ties a caption's length to its content (a one-action caption
such as "a man jumps forward" comes with a clip of about 2 s), so asked for a one-action caption at 6 s, a PST
trained on it has never seen that pair and produces the short clip's latent: the jump then lasts three times as long
and floats. Rest-padded windows show it the pair: the clip as it is, preceded and followed by its first and last
pose held still, the caption unchanged, at a longer length.

:func:`hold_features` builds such a window from HumanML3D-layout features; :class:`RestPaddedDataset` adds a share
of them (whole-clip entries, a fixed padding per entry) to a :class:`~salad_core.data.dataset.MotionTextDataset`,
with window keys that no real window has (an offset below 0 or a window past the clip's end), so per-window caches
(keyframe selections, the PST's latent cache) keep them apart.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from salad_core.skeleton import Skeleton, get_skeleton

__all__ = ["hold_features", "RestPaddedDataset"]

#: Feature groups that are velocities: zero in a held frame.
_VELOCITY_GROUPS = ("root_rot_vel", "root_lin_vel", "local_vel")


def hold_features(features: np.ndarray, before: int, after: int, skeleton: str | Skeleton = "humanml3d") -> np.ndarray:
    """``features`` ``(N, D)`` (de-normalised) with its first pose held for ``before`` frames ahead of it and its
    last pose for ``after`` frames behind it: ``(before + N + after, D)``.

    A held frame repeats its pose (root height, root-relative joint positions, joint rotations, foot contacts)
    with every velocity channel (root rotation and planar velocity, joint velocities) zero; the clip's own frames
    are unchanged.

    Raises
    ------
    ValueError
        ``features`` is not ``(N, D)`` with the skeleton's ``D`` and ``N >= 1``, or a count is negative.
    """
    sk = get_skeleton(skeleton)
    x = np.asarray(features)
    if x.ndim != 2 or x.shape[1] != sk.feature_dim or len(x) < 1:
        raise ValueError(f"features must be (N >= 1, {sk.feature_dim}) {sk.name} features, got shape {x.shape}")
    for name, n in (("before", before), ("after", after)):
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ValueError(f"{name}={n!r} must be a non-negative int (frames held)")
    first, last = x[:1].copy(), x[-1:].copy()
    for held in (first, last):
        for group in _VELOCITY_GROUPS:
            held[:, sk.feature_slices[group]] = 0
    return np.concatenate([np.repeat(first, before, 0), x, np.repeat(last, after, 0)], 0)


class RestPaddedDataset:
    """A :class:`~salad_core.data.dataset.MotionTextDataset` plus rest-padded windows of some of its whole clips.

    Items ``0 .. len(base) - 1`` are the base's; the following ones are padded windows, each of a whole-clip entry
    (captions that describe the whole clip) shorter than the longest length: its floored length ``F`` grown to
    ``T``, drawn uniformly among the multiples of ``unit_length`` in ``(F, max_length]``, of which ``before``
    (uniform in ``0 .. T - F``) frames hold the first pose and the rest the last one. Which entries are padded and how
    is fixed by ``seed`` (the windows stay the same across epochs, so a latent cache holds them); the caption is
    drawn as the base draws it. A padded window's key ``(motion_id, -before, T)`` starts before the clip or ends
    after it, which no real window does.

    Parameters
    ----------
    base : MotionTextDataset
        Normalised or not; its ``crop_features`` gives the windows.
    share : float
        Share of the items that are padded windows, in ``[0, 0.9]``: ``round(share / (1 - share) x len(base))``
        padded windows (at most one per eligible entry).
    seed : int

    Raises
    ------
    ValueError
        A share out of range, or a positive share and no entry to pad.
    """

    def __init__(self, base: Any, share: float, seed: int = 0) -> None:
        if isinstance(share, bool) or not isinstance(share, (int, float)) or not 0.0 <= share <= 0.9:
            raise ValueError(f"share={share!r} must be a float in [0, 0.9] (the share of padded items)")
        self.base = base
        self.share = float(share)
        self.seed = int(seed)
        u, longest = base.unit_length, (base.max_length // base.unit_length) * base.unit_length
        eligible = [i for i in range(len(base)) if self._whole_clip(i) and (base.entry(i)[2] // u) * u < longest]
        want = int(round(self.share / (1.0 - self.share) * len(base))) if self.share > 0 else 0
        if want and not eligible:
            raise ValueError(f"rest padding (share {share}) found no whole clip shorter than {longest} frames to pad")
        rng = np.random.default_rng((self.seed, 0x5E57))
        chosen = sorted(rng.choice(len(eligible), size=min(want, len(eligible)), replace=False).tolist())
        self._padded: list[tuple[int, int, int]] = []          # (base index, before, total length)
        for j in chosen:
            index = eligible[j]
            floored = (base.entry(index)[2] // u) * u
            total = int(rng.integers(floored // u + 1, longest // u + 1)) * u
            before = int(rng.integers(0, total - floored + 1))
            self._padded.append((index, before, total))
        self._by_key = {self._key(p): p for p in self._padded}

    # --------------------------------------------------------------------------------------- helpers
    def _whole_clip(self, index: int) -> bool:
        motion_id, start, length = self.base.entry(index)
        return start == 0 and length == self.base.clip_length(motion_id)

    def _key(self, padded: tuple[int, int, int]) -> tuple[str, int, int]:
        index, before, total = padded
        return (self.base.entry(index)[0], -before, total)

    # ------------------------------------------------------------------------------ dataset protocol
    def __len__(self) -> int:
        return len(self.base) + len(self._padded)

    @property
    def num_padded(self) -> int:
        """Padded windows among the items."""
        return len(self._padded)

    def __getattr__(self, name: str) -> Any:       # root, split, skeleton, mean, std, unit_length, min_length, ...
        if name == "base":
            raise AttributeError(name)
        return getattr(self.base, name)

    @property
    def lengths(self) -> np.ndarray:
        """``(len(self),)`` frames of each item before flooring (padded windows: their length)."""
        return np.concatenate([self.base.lengths, np.array([t for _, _, t in self._padded], dtype=np.int64)])

    def set_epoch(self, epoch: int) -> None:
        self.base.set_epoch(epoch)

    def crops(self) -> list[tuple[str, int, int]]:
        """The base's windows, then the padded ones."""
        return list(self.base.crops()) + [self._key(p) for p in self._padded]

    def crop_features(self, motion_id: str, offset: int, length: int) -> np.ndarray:
        """``(length, D)`` float32 features of a window: the base's, or a padded window (key as in :meth:`crops`)."""
        padded = self._by_key.get((motion_id, int(offset), int(length)))
        if padded is None:
            return self.base.crop_features(motion_id, offset, length)
        index, before, total = padded
        clip = self.base.crop_features(motion_id, 0, self.base.clip_length(motion_id))
        floored = (len(clip) // self.base.unit_length) * self.base.unit_length
        raw = clip[:floored].astype(np.float64)
        normalised = getattr(self.base, "normalize", True) and self.base.mean is not None
        if normalised:
            raw = raw * self.base.std + self.base.mean
        out = hold_features(raw, before, total - floored - before, self.base.skeleton)
        if normalised:
            out = (out - self.base.mean) / self.base.std
        return out.astype(np.float32)

    def __getitem__(self, index: int) -> dict[str, Any]:
        if not -len(self) <= index < len(self):
            raise IndexError(f"index {index} out of range for a dataset of {len(self)} items")
        index %= len(self)
        if index < len(self.base):
            return self.base[index]
        base_index, before, total = self._padded[index - len(self.base)]
        item = self.base[base_index]                 # the caption (and tokens) as the base draws them
        key = self._key((base_index, before, total))
        motion = self.crop_features(*key)
        padded = np.zeros((self.base.max_length, motion.shape[1]), dtype=np.float32)
        padded[:total] = motion
        item.update(motion=padded, length=total, offset=key[1], name=f"{item['name']}_rest")
        item.pop("annotation", None)
        return item

    def __repr__(self) -> str:
        return f"RestPaddedDataset({self.base!r}, share={self.share}, padded={len(self._padded)})"
