"""Datasets over a folder in the HumanML3D layout (real HumanML3D/KIT-ML or the procedural corpus).

Layout (``humanml3d_eval_facts`` §3.1)::

    root/new_joint_vecs/<id>.npy   (N, D) features, D = skeleton.feature_dim (263 / 251)
    root/texts/<id>.txt            caption#word/POS ...#start_sec#end_sec, one caption per line
    root/{train,val,test}.txt      one id per line
    root/Mean.npy, root/Std.npy    (D,) normalisation statistics
    root/annotations/<id>.json     optional: the procedural corpus's word -> (parts, frames) truth

:class:`MotionTextDataset` follows the T2M / SALAD ``Text2MotionDataset`` conventions
(``salad_official_facts`` §4): keep clips with ``min_length <= N < 200``; a caption with a
non-zero start/end is its own item over ``motion[int(start*20) : int(end*20)]``; per item a random
caption, a length floored to a multiple of 4 and with probability 1/3 shortened by another 4, a
random start, z-normalisation and zero padding to ``max_length`` (196).
:class:`MotionWindowDataset` is the VAE's dataset: every ``window``-frame window of every clip.

Everything is read into memory once at construction; items are cheap slices.
"""
from __future__ import annotations

import json
import logging
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import torch
from torch.utils.data import Dataset
from tqdm.auto import tqdm

from salad_core import limits
from salad_core.data.texts import TextLine, parse_text_line, split_words
from salad_core.skeleton import PART_NAMES, Skeleton, get_skeleton

__all__ = [
    "TEXT_FPS",
    "MotionTextDataset",
    "MotionWindowDataset",
    "collate_motion_text",
    "load_mean_std",
    "load_annotation",
    "check_annotation",
    "read_split",
    "read_texts",
]

logger = logging.getLogger(__name__)

#: Frame rate used to turn caption start/end seconds into frames. HumanML3D's loaders hard-code
#: 20, also for KIT-ML (``salad_official_facts`` §8.3); we keep that so item counts match.
TEXT_FPS = 20.0
_NONFINITE_MODES = ("raise", "skip")


# ----------------------------------------------------------------------------- file readers
def _check_root(root: str | Path) -> Path:
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"dataset root {root} does not exist or is not a folder")
    return root


def read_split(root: str | Path, split: str) -> list[str]:
    """Ids listed in ``root/<split>.txt`` (blank lines ignored)."""
    root = _check_root(root)
    path = root / f"{split}.txt"
    if not path.is_file():
        found = sorted(p.stem for p in root.glob("*.txt"))
        raise FileNotFoundError(
            f"split file {path.name!r} not found: looked for {path}; split files present in {root}: "
            f"{', '.join(found) or 'none'}"
        )
    return [line.strip() for line in path.read_text().splitlines() if line.strip()]


def read_texts(root: str | Path, name: str) -> list[TextLine]:
    """Parsed lines of ``root/texts/<name>.txt``; a malformed line raises naming file and line."""
    path = Path(root) / "texts" / f"{name}.txt"
    if not path.is_file():
        raise FileNotFoundError(f"no text file for id {name!r}: looked for {path}")
    out = []
    for lineno, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        if line.strip():
            out.append(parse_text_line(line, f"{path}:{lineno}"))
    return out


def load_mean_std(root: str | Path, skeleton: str | Skeleton = "humanml3d") -> tuple[np.ndarray, np.ndarray]:
    """``root/Mean.npy`` and ``root/Std.npy`` as float32 ``(D,)`` arrays, checked against the skeleton.

    Raises if either file is missing, has the wrong width, holds a non-finite value, or if any std
    entry is not positive (normalising would divide by it).
    """
    root = _check_root(root)
    sk = get_skeleton(skeleton)
    out = []
    for fname in ("Mean.npy", "Std.npy"):
        path = root / fname
        if not path.is_file():
            raise FileNotFoundError(f"{fname} not found: looked for {path}")
        arr = limits.read_npy(path)       # header checked first: never unpickles, bounded size
        if arr.shape != (sk.feature_dim,):
            raise ValueError(f"{path} has shape {arr.shape}; skeleton {sk.name!r} expects ({sk.feature_dim},)")
        if not np.isfinite(arr).all():
            raise ValueError(f"{path} contains NaN or inf")
        out.append(arr.astype(np.float32))
    bad = np.flatnonzero(out[1] <= 0)
    if bad.size:
        raise ValueError(f"{root / 'Std.npy'} has non-positive entries at dims {bad[:10].tolist()}")
    return out[0], out[1]


def _check_stats(mean: Any, std: Any, sk: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    if (mean is None) != (std is None):
        raise ValueError("pass both mean and std, or neither (they are then read from the dataset root)")
    mean = np.asarray(mean, dtype=np.float32)
    std = np.asarray(std, dtype=np.float32)
    for what, arr in (("mean", mean), ("std", std)):
        if arr.shape != (sk.feature_dim,):
            raise ValueError(f"{what} has shape {arr.shape}; skeleton {sk.name!r} expects ({sk.feature_dim},)")
    if (std <= 0).any() or not np.isfinite(std).all():
        raise ValueError(f"std must be finite and positive; bad dims {np.flatnonzero(~(std > 0))[:10].tolist()}")
    return mean, std


def load_annotation(root: str | Path, name: str) -> dict | None:
    """The parsed ``root/annotations/<name>.json``, or None if there is no such file."""
    path = Path(root) / "annotations" / f"{name}.json"
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        raise ValueError(f"{path} is not valid JSON: {err}") from None


def check_annotation(ann: Any, captions: Sequence[str], num_frames: int, where: str = "<annotation>") -> None:
    """Check an annotation against its clip's captions (text-file order) and feature rows.

    Raises ``ValueError`` naming ``where`` and the offending field.
    """
    if not isinstance(ann, dict) or not isinstance(ann.get("captions"), list):
        raise ValueError(f"{where}: expected an object with a 'captions' list")
    if ann.get("num_frames") != num_frames:
        raise ValueError(f"{where}: num_frames is {ann.get('num_frames')!r} but the motion has {num_frames} rows")
    caps = ann["captions"]
    if len(caps) != len(captions):
        raise ValueError(f"{where}: {len(caps)} annotated captions for {len(captions)} text lines")
    for i, (c, text) in enumerate(zip(caps, captions)):
        at = f"{where}: captions[{i}]"
        if not isinstance(c, dict) or not isinstance(c.get("phrases"), list):
            raise ValueError(f"{at}: expected an object with 'caption' and a 'phrases' list")
        if str(c.get("caption", "")).strip() != text.strip():
            raise ValueError(f"{at}: caption {c.get('caption')!r} differs from the text line {text!r}")
        n_words = len(split_words(text))
        for j, ph in enumerate(c["phrases"]):
            pat = f"{at}.phrases[{j}]"
            if not isinstance(ph, dict):
                raise ValueError(f"{pat}: expected an object")
            w, f, parts = ph.get("words"), ph.get("frames"), ph.get("parts")
            if not (isinstance(w, list) and len(w) == 2 and 0 <= w[0] < w[1] <= n_words):
                raise ValueError(f"{pat}: words {w!r} is not a half-open range inside the caption's {n_words} words")
            if not (isinstance(f, list) and len(f) == 2 and 0 <= f[0] <= f[1] <= num_frames):
                raise ValueError(f"{pat}: frames {f!r} is not a half-open range inside [0, {num_frames}]")
            if not isinstance(parts, list) or any(p not in PART_NAMES for p in parts):
                raise ValueError(f"{pat}: parts {parts!r} must be a list of names from {list(PART_NAMES)}")


def _load_motion(path: Path, sk: Skeleton) -> np.ndarray | str:
    """``(N, D)`` float32 features, or ``"nonfinite"``; wrong shape raises naming the file."""
    if not path.is_file():
        raise FileNotFoundError(f"split id {path.stem!r} has no motion file: looked for {path}")
    # the header first (salad_core.limits.read_npy): never unpickles, refuses a text file, a header that
    # does not parse, a size over the limit or beyond the file's end, before reading the data
    arr = limits.read_npy(path)
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"{path} holds {arr.dtype} values; motion files hold float (N, D) features")
    if arr.ndim != 2 or arr.shape[1] != sk.feature_dim:
        found = arr.shape[1] if arr.ndim == 2 else f"shape {arr.shape}"
        raise ValueError(f"{path}: expected width {sk.feature_dim} (skeleton {sk.name!r}, (N, D) array), found {found}")
    if not np.isfinite(arr).all():
        return "nonfinite"
    return np.ascontiguousarray(arr, dtype=np.float32)


def _load_motions(root: Path, ids: list[str], sk: Skeleton, nonfinite: str, skipped: Counter) -> dict[str, np.ndarray]:
    """Load every listed motion once (serially: threads were slower for small files)."""
    if nonfinite not in _NONFINITE_MODES:
        raise ValueError(f"nonfinite={nonfinite!r} must be one of {_NONFINITE_MODES}")
    vec_dir = root / "new_joint_vecs"
    if not vec_dir.is_dir():
        raise FileNotFoundError(f"motion folder not found: looked for {vec_dir}")
    unique = list(dict.fromkeys(ids))
    paths = [vec_dir / f"{i}.npy" for i in unique]
    loaded = [_load_motion(p, sk) for p in tqdm(paths, desc=f"loading {root.name}/{vec_dir.name}",
                                                 disable=True if len(paths) < 2000 else None)]
    out = {}
    for name, path, arr in zip(unique, paths, loaded):
        if isinstance(arr, str):
            if nonfinite == "raise":
                raise ValueError(f"{path} contains NaN or inf values (pass nonfinite='skip' to skip such clips)")
            logger.warning("skipping %s: it contains NaN or inf values", path)
            skipped["nonfinite"] += 1
            continue
        out[name] = arr
    return out


# ------------------------------------------------------------------------------ text dataset
@dataclass(frozen=True)
class _Entry:
    name: str                               # item name: the id, or "<id>_sub<line>" for a sub-clip
    motion_id: str                          # file stem in new_joint_vecs/
    start: int                              # first frame of the entry within the motion file
    length: int                             # frames of the entry
    captions: tuple[tuple[int, TextLine], ...]  # (line index in texts/<id>.txt, parsed line)


class MotionTextDataset(Dataset):
    """Text-motion pairs in the T2M / SALAD ``Text2MotionDataset`` conventions.

    Parameters
    ----------
    root : str or Path
        Folder in the HumanML3D layout.
    split : str
        Split file stem: ``train``, ``val``, ``test`` (or any ``<split>.txt`` in ``root``).
    skeleton : str or Skeleton
        Sets the feature width D and the default ``min_length``.
    max_length : int, optional
        Items are zero-padded to this many frames (default ``skeleton.max_length``, 196). Clips
        are kept while their floored length fits: ``N < (max_length // unit_length + 1) *
        unit_length`` (200 for 196, the official bound).
    min_length : int, optional
        Shortest clip or sub-clip kept (default ``skeleton.min_length``: 40, KIT 24).
    unit_length : int, optional
        Item lengths are multiples of this (default ``skeleton.unit_length``, 4: the latent's
        temporal down-sampling).
    mean, std : array (D,), optional
        Normalisation statistics; default ``root/Mean.npy``, ``root/Std.npy``. SALAD trains with
        the evaluator's statistics, so pass those when reproducing the paper.
    normalize : bool
        Apply ``(x - mean) / std``.
    random_crop : bool
        Training mode: random caption, random "double" shortening and random start.
        False: the whole floored clip from frame 0 and the first caption (evaluation).
    seed : int, optional
        Makes every random choice a function of ``(seed, epoch, index)``; see :meth:`set_epoch`.
    with_annotations : bool
        Read ``annotations/<id>.json`` and return the chosen caption's phrase annotation.
    nonfinite : {"raise", "skip"}
        What to do with a motion file holding NaN/inf (HumanML3D has two: 007975, M007975).

    Items are dicts: ``motion`` float32 ``(max_length, D)`` (rows ``>= length`` are 0),
    ``length`` int, ``caption`` str, ``tokens`` list of "word/POS" str, ``name`` str,
    ``motion_id`` str, ``offset`` int (first frame within ``new_joint_vecs/<motion_id>.npy``) and,
    with annotations, ``annotation`` (dict or None, frames relative to the returned motion).
    """

    def __init__(
        self,
        root: str | Path,
        split: str = "train",
        skeleton: str | Skeleton = "humanml3d",
        max_length: int | None = None,
        min_length: int | None = None,
        unit_length: int | None = None,
        mean: np.ndarray | None = None,
        std: np.ndarray | None = None,
        normalize: bool = True,
        random_crop: bool = True,
        seed: int | None = None,
        with_annotations: bool = False,
        nonfinite: str = "raise",
    ) -> None:
        self.root = _check_root(root)
        self.split = split
        self.skeleton = get_skeleton(skeleton)
        sk = self.skeleton
        self.min_length = sk.min_length if min_length is None else min_length
        max_length = sk.max_length if max_length is None else max_length
        unit_length = sk.unit_length if unit_length is None else unit_length
        for what, v in (("max_length", max_length), ("min_length", self.min_length), ("unit_length", unit_length)):
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{what}={v!r} must be a positive int")
        if self.min_length > max_length:
            raise ValueError(f"min_length={self.min_length} must not exceed max_length={max_length}")
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
            raise ValueError(f"seed={seed!r} must be a non-negative int or None")
        self.max_length, self.unit_length = max_length, unit_length
        # Official: drop len >= 200 with max 196; i.e. keep what floors to at most max_length.
        self.max_frames = (max_length // unit_length + 1) * unit_length
        self.normalize, self.random_crop, self.seed = normalize, random_crop, seed
        self.with_annotations = with_annotations
        self.epoch = 0

        if normalize:
            if mean is None and std is None:
                mean, std = load_mean_std(self.root, self.skeleton)
            mean, std = _check_stats(mean, std, self.skeleton)
        elif mean is not None or std is not None:
            mean, std = _check_stats(mean, std, self.skeleton)
        self.mean, self.std = mean, std

        ids = read_split(self.root, split)
        self.skipped: Counter = Counter()
        self._motions = _load_motions(self.root, ids, self.skeleton, nonfinite, self.skipped)
        self._annotations: dict[str, dict | None] = {}
        self._entries: list[_Entry] = []
        for mid in ids:
            if mid in self._motions:
                self._add_clip(mid)
        self._motions = {e.motion_id: self._motions[e.motion_id] for e in self._entries}  # free dropped clips
        if not self._entries:
            raise ValueError(f"split {split!r} of {self.root} has no usable items (skipped: {dict(self.skipped)})")
        logger.info("%s/%s: %d items from %d clips; skipped %s", self.root.name, split, len(self._entries),
                    len(self._motions), dict(self.skipped) or "nothing")

    def _add_clip(self, mid: str) -> None:
        motion = self._motions[mid]
        n = len(motion)
        if n < self.min_length:
            self.skipped["too_short"] += 1
            return
        if n >= self.max_frames:
            self.skipped["too_long"] += 1
            return
        lines = read_texts(self.root, mid)
        if not lines:
            self.skipped["no_caption"] += 1
            logger.warning("skipping %s: %s has no captions", mid, self.root / "texts" / f"{mid}.txt")
            return
        if self.with_annotations:
            ann = load_annotation(self.root, mid)
            if ann is not None:
                check_annotation(ann, [t.caption for t in lines], n, str(self.root / "annotations" / f"{mid}.json"))
            self._annotations[mid] = ann
        whole = tuple((i, t) for i, t in enumerate(lines) if t.whole_clip)
        if whole:
            self._entries.append(_Entry(mid, mid, 0, n, whole))
        for i, t in enumerate(lines):
            if t.whole_clip:
                continue
            f0 = int(t.start * TEXT_FPS)
            f1 = min(int(t.end * TEXT_FPS), n)
            length = max(f1 - f0, 0)
            if length < self.min_length:
                self.skipped["subclip_too_short"] += 1
            elif length >= self.max_frames:
                self.skipped["subclip_too_long"] += 1
            else:
                self._entries.append(_Entry(f"{mid}_sub{i}", mid, f0, length, ((i, t),)))

    # ------------------------------------------------------------------ dataset protocol
    def __len__(self) -> int:
        return len(self._entries)

    def all_captions(self) -> list[TextLine]:
        """Every caption line of every item (for pre-computing text features)."""
        return [line for e in self._entries for _, line in e.captions]

    def set_epoch(self, epoch: int) -> None:
        """Change the random crops/captions of every item (with ``seed``: deterministically)."""
        self.epoch = int(epoch)

    @property
    def names(self) -> list[str]:
        return [e.name for e in self._entries]

    @property
    def lengths(self) -> np.ndarray:
        """``(len(self),)`` frames of each entry before flooring/cropping."""
        return np.array([e.length for e in self._entries], dtype=np.int64)

    @property
    def num_clips(self) -> int:
        """Motion files that contribute at least one item."""
        return len(self._motions)

    def entry(self, index: int) -> tuple[str, int, int]:
        """``(motion_id, start, length)`` of item ``index``'s entry: its clip, first frame and frames (before any
        cropping)."""
        e = self._entries[index]
        return e.motion_id, e.start, e.length

    def clip_length(self, motion_id: str) -> int:
        """Frames of a loaded clip (``new_joint_vecs/<motion_id>.npy``)."""
        motion = self._motions.get(motion_id)
        if motion is None:
            raise KeyError(f"motion_id {motion_id!r} is not a clip of this dataset ({self.root}/{self.split})")
        return len(motion)

    def _rng(self, index: int) -> np.random.Generator:
        if self.seed is None:
            return np.random.default_rng()
        return np.random.default_rng((self.seed, self.epoch, index))

    def _crop_lengths(self, e: _Entry) -> tuple[int, ...]:
        """The lengths an item of ``e`` can have: floored, and (random crop) one unit shorter."""
        u = self.unit_length
        full = (e.length // u) * u
        return (full, max(full - u, u)) if self.random_crop else (full,)

    def crops(self) -> list[tuple[str, int, int]]:
        """Every ``(motion_id, offset, length)`` window an item can return, without repeats.

        With ``random_crop`` an entry of ``L`` frames yields its floored length ``F`` and ``F - unit``
        at every start in ``[0, L - length]`` (6 to 12 windows); without, the one window ``__getitem__``
        returns. Items' ``(motion_id, offset, length)`` are always among these (for caches of
        per-window results such as VAE posteriors).
        """
        out: dict[tuple[str, int, int], None] = {}
        for e in self._entries:
            for m_len in dict.fromkeys(self._crop_lengths(e)):
                starts = range(e.length - m_len + 1) if self.random_crop else range(1)
                for s in starts:
                    out[(e.motion_id, e.start + s, m_len)] = None
        return list(out)

    def crop_features(self, motion_id: str, offset: int, length: int) -> np.ndarray:
        """``(length, D)`` float32 features (normalised if ``normalize``) of a window of a loaded clip."""
        motion = self._motions.get(motion_id)
        if motion is None:
            raise KeyError(f"motion_id {motion_id!r} is not a clip of this dataset ({self.root}/{self.split})")
        if not (0 <= offset and length >= 1 and offset + length <= len(motion)):
            raise ValueError(f"window offset={offset}, length={length} does not fit clip {motion_id!r} of "
                             f"{len(motion)} frames")
        window = motion[offset:offset + length]
        if self.normalize:
            window = (window - self.mean) / self.std
        return np.asarray(window, dtype=np.float32)

    def __getitem__(self, index: int) -> dict[str, Any]:
        if not -len(self) <= index < len(self):
            raise IndexError(f"index {index} out of range for a dataset of {len(self)} items")
        index = index % len(self)
        e = self._entries[index]
        if self.random_crop:
            rng = self._rng(index)
            line, text = e.captions[int(rng.integers(len(e.captions)))]
            full, shorter = self._crop_lengths(e)
            m_len = shorter if rng.random() < 1.0 / 3.0 else full  # T2M's "double": one unit shorter, 1 time in 3
            start = int(rng.integers(0, e.length - m_len + 1))
        else:
            line, text = e.captions[0]
            m_len, start = self._crop_lengths(e)[0], 0
        offset = e.start + start
        motion = self.crop_features(e.motion_id, offset, m_len)
        padded = np.zeros((self.max_length, motion.shape[1]), dtype=np.float32)
        padded[:m_len] = motion
        item = dict(motion=padded, length=m_len, caption=text.caption,
                    tokens=[t for t in text.tokens], name=e.name, motion_id=e.motion_id, offset=offset)
        if self.with_annotations:
            item["annotation"] = self._crop_annotation(e.motion_id, line, offset, m_len)
        return item

    def _crop_annotation(self, mid: str, line: int, offset: int, length: int) -> dict | None:
        """The caption's phrases with frames shifted to the crop and clipped to ``[0, length]``.

        A phrase whose frames fall outside the crop keeps an empty range at the nearest edge, so
        the phrase list still covers the caption's words.
        """
        ann = self._annotations.get(mid)
        if ann is None:
            return None
        cap = ann["captions"][line]
        phrases = []
        for ph in cap["phrases"]:
            f0 = min(max(ph["frames"][0] - offset, 0), length)
            f1 = min(max(ph["frames"][1] - offset, f0), length)
            phrases.append(dict(ph, words=list(ph["words"]), parts=list(ph["parts"]), frames=[f0, f1]))
        return dict(caption=cap["caption"], phrases=phrases, offset=offset, num_frames=length)

    def __repr__(self) -> str:
        return (f"MotionTextDataset(root={str(self.root)!r}, split={self.split!r}, items={len(self)}, "
                f"clips={self.num_clips}, skipped={dict(self.skipped)})")


# ---------------------------------------------------------------------------- window dataset
class MotionWindowDataset(Dataset):
    """Every ``window``-frame window of every clip at least that long (the VAE's dataset).

    Item ``i`` enumerates windows clip by clip, start frame by start frame; a clip of N frames
    gives ``N - window + 1`` windows. (The official ``MotionDataset`` counts ``N - window`` and
    never uses a clip's last window.) Items: ``dict(motion=float32 (window, D))``, normalised.
    """

    def __init__(
        self,
        root: str | Path,
        split: str = "train",
        window: int = 64,
        skeleton: str | Skeleton = "humanml3d",
        mean: np.ndarray | None = None,
        std: np.ndarray | None = None,
        normalize: bool = True,
        nonfinite: str = "raise",
    ) -> None:
        self.root = _check_root(root)
        self.split = split
        self.skeleton = get_skeleton(skeleton)
        if isinstance(window, bool) or not isinstance(window, int) or window < 1:
            raise ValueError(f"window={window!r} must be a positive int")
        self.window, self.normalize = window, normalize
        if normalize:
            if mean is None and std is None:
                mean, std = load_mean_std(self.root, self.skeleton)
            mean, std = _check_stats(mean, std, self.skeleton)
        self.mean, self.std = mean, std
        self.skipped: Counter = Counter()
        motions = _load_motions(self.root, read_split(self.root, split), self.skeleton, nonfinite, self.skipped)
        self._names, self._motions = [], []
        for name, m in motions.items():
            if len(m) < window:
                self.skipped["too_short"] += 1
                continue
            self._names.append(name)
            self._motions.append((m - mean) / std if normalize else m)
        counts = np.array([len(m) - window + 1 for m in self._motions], dtype=np.int64)
        self._cum = np.concatenate([[0], np.cumsum(counts)])
        if len(self) == 0:
            raise ValueError(f"split {split!r} of {self.root} has no clip of at least {window} frames "
                             f"(skipped: {dict(self.skipped)})")
        logger.info("%s/%s: %d windows of %d frames from %d clips; skipped %s", self.root.name, split,
                    len(self), window, len(self._motions), dict(self.skipped) or "nothing")

    def __len__(self) -> int:
        return int(self._cum[-1])

    def _clip_of(self, index: int) -> tuple[int, int]:
        if not -len(self) <= index < len(self):
            raise IndexError(f"index {index} out of range for a dataset of {len(self)} windows")
        index %= len(self)
        clip = int(np.searchsorted(self._cum, index, side="right")) - 1
        return clip, int(index - self._cum[clip])

    def locate(self, index: int) -> tuple[str, int]:
        """``(clip id, start frame)`` of window ``index``."""
        clip, start = self._clip_of(index)
        return self._names[clip], start

    def __getitem__(self, index: int) -> dict[str, np.ndarray]:
        clip, start = self._clip_of(index)
        return dict(motion=np.asarray(self._motions[clip][start:start + self.window], dtype=np.float32))


# ----------------------------------------------------------------------------------- collate
def collate_motion_text(items: Sequence[dict[str, Any]], trim: bool = True) -> dict[str, Any]:
    """Batch :class:`MotionTextDataset` items.

    Parameters
    ----------
    items : list of dict
        Items with at least ``motion (N, D)`` and ``length``.
    trim : bool
        Cut the padding to the longest ``length`` in the batch (else keep the items' N).

    Returns
    -------
    dict
        ``motion`` float32 ``(B, N, D)``, ``length`` long ``(B,)``, ``mask`` bool ``(B, N)``
        (True on real frames), and every other key as a list (``caption``, ``name``, ...).
    """
    if not items:
        raise ValueError("collate_motion_text needs at least one item, got none")
    keys = list(items[0])
    for i, it in enumerate(items):
        if "motion" not in it or "length" not in it:
            raise ValueError(f"item {i} lacks 'motion' or 'length' (keys: {sorted(it)})")
        if list(it) != keys:
            raise ValueError(f"item {i} has keys {sorted(it)}, item 0 has {sorted(keys)}")
    motion = torch.from_numpy(np.stack([np.asarray(it["motion"], dtype=np.float32) for it in items]))
    length = torch.tensor([int(it["length"]) for it in items], dtype=torch.long)
    if int(length.max()) > motion.shape[1]:
        raise ValueError(f"an item's length {int(length.max())} exceeds its motion's {motion.shape[1]} frames")
    if trim:
        motion = motion[:, : int(length.max())].contiguous()
    batch: dict[str, Any] = dict(
        motion=motion,
        length=length,
        mask=torch.arange(motion.shape[1])[None, :] < length[:, None],
    )
    for k in keys:
        if k not in batch:
            batch[k] = [it[k] for it in items]
    return batch
