"""Training of the three KeyMotion models on the shared trainer (:func:`salad_core.train.fit`).

Each model is a :class:`~salad_core.train.TrainTask` (objective module, data, ``prepare``), so
KeyMotion gets the same progress bar, atomic checkpoints, exact resume, validation/best, SIGINT
handling and ``torchrun`` DDP as the SALAD trainers. The stages:

1. **keyframe VAE** (:func:`train_kf_vae`): keyframes of each training item (selected with
   :func:`~salad_core.keymotion.selection.select_keyframes` on its normalised features, MDO by
   default), their positions ``u = i / (L - 1)``; loss eq. 2 (plus optional feature-group terms,
   ``KeyframeVAEConfig.lambda_root`` etc.). ``init_from`` with ``train_parts="decoder"`` fine-tunes the
   decoder of a trained keyframe VAE with the encoder frozen, so a PST trained on its latents still fits
   (:func:`load_kf_vae_init`).
2. **PST** (:func:`train_pst`): the frozen VAE's posterior sample ``z`` of the keyframes, noised
   on the scaled-linear schedule; ε-prediction MSE (eq. 7); captions replaced by ``""`` with
   probability ``cond_drop_prob`` for classifier-free guidance. A PST with ``PSTConfig.side_cue``
   also gets each caption's token side ids (``text_sides``, :mod:`salad_core.keymotion.sides`), from
   the token strings the caption cache keeps. ``KeyMotionTrainConfig.init_from`` starts from a trained
   PST (fine-tuning, e.g. the shipped one with a new side cue: :func:`load_pst_init`).
3. **MMAE** (:func:`train_mmae`): the motion with everything but its keyframes masked, the
   caption; loss eq. 9 (plus an optional foot-contact term, ``MMAEConfig.lambda_foot``). Optional
   Gaussian noise on the input keyframes (``keyframe_noise``, in normalised units) makes the in-filling
   robust to imperfect generated keyframes (paper Table VII); ``keyframe_roundtrip`` gives a share of the
   items the keyframe VAE's reconstruction of their keyframes instead (:func:`roundtrip_keyframes`: the
   errors generation makes, not Gaussian ones). ``init_from`` starts from a trained MMAE (fine-tuning with
   other loss weights: :func:`load_mmae_init`).

:func:`train_keymotion` runs the three stages into ``out/kf_vae``, ``out/pst``, ``out/mmae`` and
writes ``out/keymotion.json``, so ``KeyMotionPipeline.from_pretrained(out)`` loads the result.
:class:`KeyMotionRecipe` is its JSON configuration (``configs/keymotion-0.2.json``), read by
``salad train keymotion`` (:mod:`salad_core.cli.train`). The PST and MMAE stages share one
caption-feature cache, filled in batches at their first step (:class:`PrefilledCaptions`).

Items come from :class:`~salad_core.data.dataset.MotionTextDataset` (random crops and captions,
lengths multiples of 4); every item keeps ``K = num_keyframes`` keyframes whatever its length.
All random draws of a step come from the trainer's shared generator for the global batch.

Throughput (switches in :class:`KeyMotionTrainConfig`): the PST looks the keyframe VAE's
posteriors up in a latent cache of every window an item can take (``latent_cache``; keyframes
selected and encoded once per keyframe VAE and corpus, ``eps`` still drawn per step); the MMAE,
whose cost grows with the frames of a batch, gets length-bucketed batches (``batching``) and then
weighs its per-batch mean losses by ``valid frames / (batch x expected frames per item)``, so every
frame weighs the same in every batch (see :mod:`salad_core.train.batching`).
"""
from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn
from torch.utils.data import Dataset

from salad_core.io import atomic_write_text, config_to_dict
from salad_core.train.batching import expected_latent_frames
from salad_core.train.common import StepContext, TrainResult, TrainTask, fit
from salad_core.train.config import TrainConfig
from salad_core.train.denoiser_trainer import CaptionFeatureCache, resolve_checkpoint
from salad_core.train.distributed import DistEnv, init_distributed

from .kf_vae import KeyframeVAE, KeyframeVAEConfig, gather_keyframes, indices_to_positions
from .mmae import MMAEConfig, MotionMaskedAutoencoder, scatter_keyframes
from .models import NORMALISATION_TOLERANCE, normalisation_gap
from .pst import PST_DIFFUSION, ParallelSkipTransformer, PSTConfig
from .selection import KEYFRAME_METHODS, select_keyframes
from .sides import mirror_side_words, names_left_first, side_ids

__all__ = [
    "KeyMotionTrainConfig",
    "KeyframeDataset",
    "collate_keyframes",
    "KeyframeVAEObjective",
    "PSTObjective",
    "MMAEObjective",
    "build_kf_vae_task",
    "build_pst_task",
    "build_mmae_task",
    "prepare_pst_batch",
    "train_kf_vae",
    "train_pst",
    "train_mmae",
    "train_keymotion",
    "load_frozen_kf_vae",
    "roundtrip_keyframes",
    "kf_vae_latent_cache",
    "kf_latent_stats",
    "PrefilledCaptions",
    "PST_ARCHITECTURE_FIELDS",
    "resolve_pst_source",
    "load_pst_init",
    "load_mmae_init",
    "load_kf_vae_init",
    "MMAE_FREE_FIELDS",
    "KF_VAE_FREE_FIELDS",
    "STAGES",
    "KeyMotionRecipe",
    "load_keymotion_recipe",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class KeyMotionTrainConfig(TrainConfig):
    """Recipe of the KeyMotion stages (the paper trains with Adam at a constant rate)."""

    batch_size: int = 32
    max_epochs: int = 200
    lr: float = 2e-4                           # constant after warm-up (no milestones)
    warmup_steps: int = 200
    milestones: tuple[int, ...] = ()
    weight_decay: float = 0.0
    val_every: int = 500
    max_length: int = 196                      # motions are cropped/padded to this many frames
    keyframe_method: str = "mdo"               # "mdo" (paper), "uniform" or "mieo"
    cond_drop_prob: float = 0.1                # PST: captions replaced by "" (classifier-free guidance)
    text_cache_size: int = 32768               # captions whose token features are kept (0: encode every batch);
                                               # when all fit, they are encoded up front in batches
    keyframe_noise: float = 0.0                # MMAE: std of noise added to the input keyframes (normalised units)
    keyframe_ratio: float = 0.0                # MMAE: > 0 gives each item max(2, round(ratio x length)) keyframes
                                               # (the paper's 10 %); 0: num_keyframes whatever the length (the
                                               # keyframe VAE and PST need 0: their K is fixed by the VAE)
    latent_cache: bool = True                  # PST: keyframe-VAE posteriors of every window encoded once
    latent_cache_dir: str | None = None        # PST: where the cache lives (None: the run folder's latent_cache/)
    init_from: str | None = None               # a checkpoint stem, run folder, KeyMotion pipeline folder or
                                               # training root whose weights of that stage start the model
                                               # (fine-tuning: load_kf_vae_init, load_pst_init, load_mmae_init)
    train_parts: str = "all"                   # keyframe VAE: "all" | "decoder"; "decoder" freezes the encoder so
                                               # the posteriors a trained PST relies on stay the same; needs init_from
    keyframe_roundtrip: float = 0.0            # MMAE: share of items whose input keyframes (and their frames) are
                                               # the roundtrip_vae's reconstruction of the true ones, as generation
                                               # gives them; needs keyframe_ratio 0 (the VAE's fixed K)
    roundtrip_vae: str | None = None           # MMAE: the keyframe VAE of keyframe_roundtrip (a KeyMotion pipeline
                                               # folder or training root, a keyframe-VAE run folder or stem)
    rest_padding: float = 0.0                  # share of the training items that are whole clips held still
                                               # before and after, at a longer length (rest_padding.py: a one-action
                                               # caption asked for longer does the action and stands, not slower)

    def __post_init__(self) -> None:
        super().__post_init__()
        name = type(self).__name__
        if self.keyframe_method not in KEYFRAME_METHODS:
            raise ValueError(f"{name}.keyframe_method={self.keyframe_method!r} is invalid; choose one of {KEYFRAME_METHODS}")
        if not 0.0 <= self.cond_drop_prob <= 1.0:
            raise ValueError(f"{name}.cond_drop_prob={self.cond_drop_prob!r} is invalid; use a float in [0, 1]")
        if not isinstance(self.max_length, int) or self.max_length < 2:
            raise ValueError(f"{name}.max_length={self.max_length!r} is invalid; use an integer >= 2")
        if not isinstance(self.text_cache_size, int) or self.text_cache_size < 0:
            raise ValueError(f"{name}.text_cache_size={self.text_cache_size!r} is invalid; use an integer >= 0")
        if not self.keyframe_noise >= 0.0:
            raise ValueError(f"{name}.keyframe_noise={self.keyframe_noise!r} is invalid; use a float >= 0")
        if isinstance(self.keyframe_ratio, bool) or not isinstance(self.keyframe_ratio, (int, float)) \
                or not 0.0 <= self.keyframe_ratio <= 1.0:
            raise ValueError(f"{name}.keyframe_ratio={self.keyframe_ratio!r} is invalid; use a float in [0, 1] "
                             "(0: a fixed num_keyframes)")
        if self.init_from is not None and (not isinstance(self.init_from, str) or not self.init_from):
            raise ValueError(f"{name}.init_from={self.init_from!r} is invalid; use a checkpoint or folder path "
                             "(str) or None")
        if isinstance(self.keyframe_roundtrip, bool) or not isinstance(self.keyframe_roundtrip, (int, float)) \
                or not 0.0 <= self.keyframe_roundtrip <= 1.0:
            raise ValueError(f"{name}.keyframe_roundtrip={self.keyframe_roundtrip!r} is invalid; use a float in [0, 1]")
        if self.keyframe_roundtrip > 0 and not (isinstance(self.roundtrip_vae, str) and self.roundtrip_vae):
            raise ValueError(f"{name}.keyframe_roundtrip={self.keyframe_roundtrip} needs roundtrip_vae (the keyframe "
                             "VAE whose reconstructions the MMAE learns to in-fill)")
        if self.keyframe_roundtrip > 0 and self.keyframe_ratio:
            raise ValueError(f"{name}.keyframe_roundtrip needs keyframe_ratio=0: the keyframe VAE reconstructs its "
                             f"fixed number of keyframes, not {self.keyframe_ratio:.0%} of the frames")
        if isinstance(self.rest_padding, bool) or not isinstance(self.rest_padding, (int, float)) \
                or not 0.0 <= self.rest_padding <= 0.9:
            raise ValueError(f"{name}.rest_padding={self.rest_padding!r} is invalid; use a share in [0, 0.9] "
                             "(0: no padded windows)")
        if self.train_parts not in ("all", "decoder"):
            raise ValueError(f"{name}.train_parts={self.train_parts!r} is invalid; use 'all' or 'decoder'")
        if self.train_parts == "decoder" and self.init_from is None:
            raise ValueError(f"{name}.train_parts='decoder' needs init_from (a trained keyframe VAE): a frozen "
                             "randomly initialised encoder has no latent space worth keeping")


# ----------------------------------------------------------------------------------- data
class KeyframeDataset(Dataset):
    """A :class:`MotionTextDataset` whose items also hold ``keyframes``: ``(K,)`` int64 frame indices.

    Keyframes are selected on the item's normalised features (its random crop), and cached per
    ``(motion_id, offset, length)`` because the MDO dynamic programme costs ~10 ms per item.

    Parameters
    ----------
    base : MotionTextDataset
    num_keyframes : int
        ``K``; every item must have at least ``K`` frames (unused with a ``ratio``).
    method : str
        Selection method (:data:`~salad_core.keymotion.selection.KEYFRAME_METHODS`).
    cache_size : int
        Selections kept (the oldest are dropped beyond it; ~200 bytes each).
    ratio : float
        0 (default): ``num_keyframes`` keyframes per item. Above 0: ``max(2, round(ratio x L))``
        keyframes for an item of ``L`` frames, so the keyframes are a fixed share of the frames
        (KeyMotion's 10 %), as the MMAE can in-fill from any number of keyframes.
    """

    def __init__(self, base: Any, num_keyframes: int, method: str = "mdo", cache_size: int = 200_000,
                 ratio: float = 0.0) -> None:
        if method not in KEYFRAME_METHODS:
            raise ValueError(f"method={method!r} is invalid; choose one of {KEYFRAME_METHODS}")
        if not 0.0 <= ratio <= 1.0:
            raise ValueError(f"ratio={ratio!r} is invalid; use a float in [0, 1] (0: num_keyframes per item)")
        u = base.unit_length
        shortest = (base.min_length // u) * u - u   # a floored length, shortened by one unit 1 time in 3
        need = 2 if ratio > 0 else num_keyframes
        if shortest < need:
            raise ValueError(f"items of {base.root} may have only {shortest} frames (min_length={base.min_length}), "
                             f"fewer than num_keyframes={need}; raise min_length or lower num_keyframes")
        self.base = base
        self.num_keyframes = num_keyframes
        self.method = method
        self.ratio = float(ratio)
        self.cache_size = cache_size
        self._cache: dict[tuple[str, int, int], np.ndarray] = {}

    def count(self, length: int) -> int:
        """Keyframes of an item of ``length`` frames: ``num_keyframes``, or ``max(2, round(ratio x length))``."""
        if self.ratio <= 0:
            return self.num_keyframes
        return int(min(length, max(2, round(self.ratio * length))))

    @property
    def mean(self) -> np.ndarray:
        return self.base.mean

    @property
    def std(self) -> np.ndarray:
        return self.base.std

    def __len__(self) -> int:
        return len(self.base)

    @property
    def lengths(self) -> np.ndarray:
        """``(len(self),)`` frames of each item before cropping (for length-bucketed batches)."""
        return self.base.lengths

    def set_epoch(self, epoch: int) -> None:
        self.base.set_epoch(epoch)

    def keyframes_of(self, key: tuple[str, int, int], motion: np.ndarray | None = None) -> np.ndarray:
        """``(K,)`` int64 keyframe indices of the window ``key = (motion_id, offset, length)`` (cached)."""
        idx = self._cache.get(key)
        if idx is None:
            if motion is None:
                motion = self.base.crop_features(*key)
            idx = select_keyframes(motion[: key[2]], self.count(key[2]), self.method).astype(np.int64)
            self._cache[key] = idx
            if len(self._cache) > self.cache_size:
                self._cache.pop(next(iter(self._cache)))   # dicts keep insertion order: drop the oldest
        return idx

    def __getitem__(self, index: int) -> dict[str, Any]:
        item = self.base[index]
        key = (item["motion_id"], int(item["offset"]), int(item["length"]))
        item["keyframes"] = self.keyframes_of(key, item["motion"]).copy()
        return item


def collate_keyframes(items: list[dict[str, Any]]) -> dict[str, Any]:
    """:func:`collate_motion_text` (trimmed to the longest item) plus ``keyframes`` ``(B, K)`` long
    and ``keyframe_count`` ``(B,)``.

    Items with fewer keyframes than the batch's most (a keyframe ratio) repeat their last index up
    to ``K``: gathering and scattering a repeated keyframe writes the same frame twice, so the
    padded batch places exactly each item's own keyframes.
    """
    from salad_core.data.dataset import collate_motion_text

    batch = collate_motion_text(items, trim=True)
    counts = [len(it["keyframes"]) for it in items]
    k = max(counts)
    batch["keyframes"] = torch.as_tensor(np.stack([np.pad(it["keyframes"], (0, k - c), mode="edge")
                                                   for it, c in zip(items, counts)]), dtype=torch.long)
    batch["keyframe_count"] = torch.as_tensor(counts, dtype=torch.long)
    return batch


def _datasets(data_dir: str | os.PathLike, skeleton: str, num_keyframes: int, config: KeyMotionTrainConfig,
              ratio: float = 0.0) -> tuple[KeyframeDataset, KeyframeDataset | None]:
    from salad_core.data.dataset import MotionTextDataset

    train = MotionTextDataset(data_dir, "train", skeleton=skeleton, max_length=config.max_length,
                              random_crop=True, seed=config.seed)
    padded = train
    if config.rest_padding > 0:
        from salad_core.keymotion.rest_padding import RestPaddedDataset

        padded = RestPaddedDataset(train, config.rest_padding, seed=config.seed)
        log.info("rest padding: %d held-still windows of whole clips among %d training items", padded.num_padded,
                 len(padded))
    train_set = KeyframeDataset(padded, num_keyframes, config.keyframe_method, ratio=ratio)
    try:
        val = MotionTextDataset(data_dir, "val", skeleton=skeleton, max_length=config.max_length,
                                mean=train.mean, std=train.std, random_crop=False)
        val_set = KeyframeDataset(val, num_keyframes, config.keyframe_method, ratio=ratio)
    except (FileNotFoundError, ValueError) as exc:
        log.warning("no validation items (%s)", exc)
        val_set = None
    return train_set, val_set


def _mean_std_file(dataset: KeyframeDataset) -> dict[str, torch.Tensor]:
    return {"mean": torch.as_tensor(dataset.mean, dtype=torch.float32),
            "std": torch.as_tensor(dataset.std, dtype=torch.float32)}


def _keyframe_inputs(batch: dict[str, Any], device: str) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    motion = batch["motion"].to(device, non_blocking=True)            # (B, N, D) normalised
    length = batch["length"].to(device)
    idx = batch["keyframes"].to(device)                               # (B, K)
    return motion, length, idx, gather_keyframes(motion, idx)


class PrefilledCaptions:
    """Caption features of a :class:`CaptionFeatureCache`, prefilled at the first :meth:`encode`.

    Encoding captions one by one costs one text-encoder forward per caption during the first epoch
    (most of a CPU step); the prefill encodes all the stage's captions in fixed batches, which
    depend only on the set of captions, so runs stay exactly reproducible and resumable. It runs
    at the first batch rather than at construction so that a finished stage that is resumed (and
    trains nothing) does not pay for it. A cache already holding the captions (shared by the PST
    and MMAE stages) encodes nothing again; nothing is prefilled when they do not all fit.

    Parameters
    ----------
    cache : CaptionFeatureCache
    captions : list of str
        The captions to prefill (e.g. of the train and validation splits).
    """

    def __init__(self, cache: CaptionFeatureCache, captions: list[str]) -> None:
        self.cache = cache
        self._todo: list[str] | None = list(captions)

    def _prefill(self) -> None:
        if self._todo is not None:
            n = self.cache.prefill(self._todo)
            self._todo = None
            if n:
                log.info("text features of %d captions computed up front", n)

    def encode(self, captions: list[str]) -> tuple[torch.Tensor, torch.Tensor]:
        """``(features (B, W, C), mask (B, W) bool)`` of ``captions`` (see :meth:`CaptionFeatureCache.encode`)."""
        self._prefill()
        return self.cache.encode(captions)

    def encode_with_tokens(self, captions: list[str]) -> tuple[torch.Tensor, torch.Tensor, list[list[str]]]:
        """``(features (B, W, C), mask (B, W) bool, token strings per caption)``
        (see :meth:`CaptionFeatureCache.encode_with_tokens`)."""
        self._prefill()
        return self.cache.encode_with_tokens(captions)


def _stage_captions(text_cache: CaptionFeatureCache | None, encoder: Any, config: KeyMotionTrainConfig,
                    *datasets: KeyframeDataset | None) -> PrefilledCaptions:
    if text_cache is None:
        text_cache = CaptionFeatureCache(encoder, config.text_cache_size)
    _check_cache(text_cache, encoder)
    return PrefilledCaptions(text_cache, [line.caption for ds in datasets if ds is not None
                                          for line in ds.base.all_captions()])


def _check_cache(text_cache: Any, encoder: Any) -> None:
    if not isinstance(text_cache, CaptionFeatureCache):
        raise TypeError(f"text_cache must be a CaptionFeatureCache, got {type(text_cache).__name__}")
    if text_cache.encoder is not encoder:
        raise ValueError("text_cache wraps another text encoder than the one this stage trains with")


def _text_encoder(text_encoder: Any, device: str) -> tuple[Any, str]:
    from salad_core.text import load_text_encoder

    if isinstance(text_encoder, (str, Path)):
        return load_text_encoder(text_encoder, device=device), str(text_encoder)
    return text_encoder, getattr(text_encoder, "name", type(text_encoder).__name__)


# ------------------------------------------------------------------------------ objectives
class KeyframeVAEObjective(nn.Module):
    """``forward(keyframes, positions, eps) -> dict(loss, rec, kl, bone, index, ...)`` (eq. 2).

    ``freeze_encoder``: decoder fine-tuning; the encoder's parameters get no gradient and it stays in
    eval mode (no dropout), so the decoder learns from exactly the posteriors a PST trained on it sees.
    """

    def __init__(self, vae: KeyframeVAE, freeze_encoder: bool = False) -> None:
        super().__init__()
        self.vae = vae
        self.freeze_encoder = freeze_encoder
        if freeze_encoder:
            vae.freeze_encoder()

    def train(self, mode: bool = True) -> "KeyframeVAEObjective":
        """As ``nn.Module.train``, but a frozen encoder stays in eval mode."""
        super().train(mode)
        if self.freeze_encoder:
            for part in self.vae.encoder_modules():
                part.eval()
        return self

    def forward(self, keyframes: torch.Tensor, positions: torch.Tensor, eps: torch.Tensor,
                latent_noise: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """``keyframes (B, K, D)``, ``positions (B, K)``, ``eps (B, Lz, Dz)`` standard normal (the
        reparameterisation); ``latent_noise (B, Lz, Dz)`` standard normal, scaled by the config's
        :attr:`~salad_core.keymotion.kf_vae.KeyframeVAEConfig.latent_noise` and added to the latent the
        decoder reads (the KL term still sees the posterior)."""
        scale = self.vae.config.latent_noise
        extra = 0.0 if latent_noise is None or scale == 0 else scale * latent_noise
        if self.freeze_encoder:
            with torch.no_grad():
                enc = self.vae.encode(keyframes, positions, sample=False)
            mu, logvar = enc.mu, enc.logvar
        else:
            mu, logvar = self.vae.encode(keyframes, positions, sample=False)[1:]
        decoding = self.vae.decode(mu + eps * torch.exp(0.5 * logvar) + extra)
        return self.vae.loss(keyframes, positions, decoding, mu, logvar)


class PSTObjective(nn.Module):
    """``forward(noisy, timesteps, text, text_mask, lengths, target[, text_sides]) -> dict(loss)`` (eq. 7)."""

    def __init__(self, pst: ParallelSkipTransformer) -> None:
        super().__init__()
        self.pst = pst

    def forward(self, noisy: torch.Tensor, timesteps: torch.Tensor, text: torch.Tensor, text_mask: torch.Tensor,
                lengths: torch.Tensor, target: torch.Tensor,
                text_sides: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """``noisy, target (B, Lz, Dz)``, ``timesteps (B,)``, ``text (B, W, C)``, ``text_mask (B, W)``,
        ``text_sides (B, W)`` long (side-cue PSTs only)."""
        pred = self.pst(noisy, timesteps, text, text_mask, lengths, text_sides)
        return {"loss": F.mse_loss(pred, target)}


class MMAEObjective(nn.Module):
    """``forward(motion, inputs, keyframe_mask, frame_mask, text, text_mask) -> dict(loss, rec, bone, vel)`` (eq. 9)."""

    def __init__(self, mmae: MotionMaskedAutoencoder) -> None:
        super().__init__()
        self.mmae = mmae

    def forward(self, motion: torch.Tensor, inputs: torch.Tensor, keyframe_mask: torch.Tensor,
                frame_mask: torch.Tensor, text: torch.Tensor, text_mask: torch.Tensor,
                frame_weight: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """``motion (B, N, D)`` target, ``inputs (B, N, D)`` (keyframe rows read), masks ``(B, N)``.

        ``frame_weight`` (scalar, length-bucketed training): multiplies the per-batch mean losses,
        ``valid frames / (batch x expected frames per item)``, so that each frame weighs the same
        in every batch (the velocity term's ``frames - 1`` pairs are weighed as frames).
        """
        pred = self.mmae(inputs, keyframe_mask, frame_mask, text, text_mask)
        losses = self.mmae.loss(pred, motion, frame_mask)
        if frame_weight is not None:
            losses = {k: v * frame_weight for k, v in losses.items()}
        return losses


# ------------------------------------------------------------------------------- prepare
def _prepare_vae(batch: dict[str, Any], ctx: StepContext, *, latent_shape: tuple[int, int],
                 latent_noise: bool = False, position_span: int | None = None) -> dict[str, torch.Tensor]:
    """``latent_noise``: also draw the decoder's extra latent noise (after ``eps``; without it the random
    stream is the one of a run without the option). ``position_span``: the model's
    :attr:`~salad_core.keymotion.kf_vae.KeyframeVAE.position_span` (None: relative timing)."""
    _, length, idx, keyframes = _keyframe_inputs(batch, ctx.env.device)
    out = {"keyframes": keyframes, "positions": indices_to_positions(idx, length, position_span),
           "eps": ctx.rand.randn(keyframes.shape[0], latent_shape)}
    if latent_noise:
        out["latent_noise"] = ctx.rand.randn(keyframes.shape[0], latent_shape)
    return out


def prepare_pst_batch(batch: dict[str, Any], ctx: StepContext, *, vae: KeyframeVAE, text: PrefilledCaptions,
                      scheduler: Any, config: KeyMotionTrainConfig, latent_shape: tuple[int, int],
                      latents: Any = None, side_cue: bool = False,
                      latent_stats: tuple[torch.Tensor, torch.Tensor] | None = None,
                      side_canonical: bool = False) -> dict[str, Any]:
    """The :class:`PSTObjective` inputs of a training batch (eq. 7 with condition dropout).

    Draws, in this order from the step's shared generator: the VAE reparameterisation noise, the
    timesteps ``t ~ U{0..T-1}``, the diffusion noise and the caption drop mask (``cond_drop_prob``;
    no caption is dropped outside training). The keyframe latent is ``z = mu + eps sigma`` of the
    frozen keyframe VAE's posterior, looked up in ``latents`` (a
    :func:`kf_vae_latent_cache`) or encoded from the batch's keyframes; both give the same ``z``.

    Parameters
    ----------
    batch : dict
        :func:`collate_keyframes` output: ``motion (B, N, D)`` normalised, ``length (B,)``,
        ``keyframes (B, K)``, ``caption`` (and ``motion_id``, ``offset`` for the cache).
    ctx : StepContext
    vae : KeyframeVAE
        Frozen, for on-the-fly encoding.
    text : PrefilledCaptions
        Caption features (``encode(captions) -> (B, W, C), (B, W)``; with ``side_cue``
        ``encode_with_tokens(captions)``, which also gives the token strings).
    scheduler
        The training scheduler of :data:`PST_DIFFUSION` (``add_noise``).
    config : KeyMotionTrainConfig
    latent_shape : tuple
        ``(Lz, Dz)``.
    latents : LatentCache, optional
    side_cue : bool
        The PST has ``PSTConfig.side_cue``: also return ``text_sides``.
    latent_stats : (Tensor, Tensor), optional
        ``(mean, std)`` ``(Lz, Dz)`` of a ``PSTConfig.latent_norm`` PST: the diffused latent is ``(z - mean) / std``.
    side_canonical : bool
        ``PSTConfig.side_canonical``: an item whose (not dropped) caption names the left kind first
        (:func:`~salad_core.keymotion.sides.names_left_first`) is replaced by its mirror image: its keyframes
        mirrored (:func:`salad_core.motion.mirror_features`, same frames) and encoded, its caption's side words
        swapped. The draws from the step's generator are the same either way.

    Returns
    -------
    dict: ``noisy (B, Lz, Dz)``, ``timesteps (B,)``, ``text (B, W, C)``, ``text_mask (B, W)``,
    ``lengths (B,)``, ``target (B, Lz, Dz)`` (the noise); with ``side_cue`` also ``text_sides (B, W)``
    long, the side ids of the (possibly dropped, then all 0) captions' tokens, column for column.
    """
    dev = ctx.env.device
    _, length, idx, keyframes = _keyframe_inputs(batch, dev)
    b = keyframes.shape[0]
    eps = ctx.rand.randn(b, latent_shape)                             # VAE reparameterisation
    t = ctx.rand.randint(b, scheduler.config.num_train_timesteps)     # t ~ U{0..T-1}
    noise = ctx.rand.randn(b, latent_shape)
    drop = ctx.rand.rand(b) < config.cond_drop_prob                   # classifier-free guidance
    if not ctx.train:
        drop = torch.zeros_like(drop)
    with torch.no_grad():
        if latents is not None:
            keys = list(zip(batch["motion_id"], (int(o) for o in batch["offset"]), length.tolist()))
            mu, logvar = (t_.to(dev) for t_ in latents.lookup(keys))      # (B, Lz, Dz)
        else:
            enc = vae.encode(keyframes, vae.positions_of(idx, length), sample=False)
            mu, logvar = enc.mu, enc.logvar
        captions = list(batch["caption"])
        if side_canonical:          # dropped captions keep their items: the unconditional branch learns all data
            mu, logvar, captions = _side_canonical(vae, keyframes, idx, length, mu, logvar, captions,
                                                   keep=(~drop).tolist())
        z = mu + eps * torch.exp(0.5 * logvar)
        if latent_stats is not None:
            z = (z - latent_stats[0].to(z)) / latent_stats[1].to(z)
        noisy = scheduler.add_noise(z, noise, t)
        captions = ["" if d else c for d, c in zip(drop.tolist(), captions)]
        if side_cue:
            feats, mask, tokens = text.encode_with_tokens(captions)
        else:
            feats, mask = text.encode(captions)
    out = {"noisy": noisy, "timesteps": t, "text": feats.to(dev), "text_mask": mask.to(dev), "lengths": length,
           "target": noise}
    if side_cue:
        out["text_sides"] = side_ids(tokens, feats.shape[1]).to(dev)
    return out


def _side_canonical(vae: KeyframeVAE, keyframes: torch.Tensor, idx: torch.Tensor, length: torch.Tensor,
                    mu: torch.Tensor, logvar: torch.Tensor, captions: list[str], keep: list[bool]
                    ) -> tuple[torch.Tensor, torch.Tensor, list[str]]:
    """Items whose caption names the left kind first replaced by their mirror images (``PSTConfig.side_canonical``).

    ``keyframes (B, K, D)`` normalised, ``idx (B, K)``, ``length (B,)``, posteriors ``mu, logvar (B, Lz, Dz)``;
    returns the posteriors and captions with those items' keyframes mirrored (same frames) and encoded again and
    their side words swapped; only items with ``keep[i]`` (their caption is not dropped for guidance).
    """
    from salad_core.motion import mirror_features

    flip = [i for i, c in enumerate(captions) if keep[i] and names_left_first(c)]
    if not flip:
        return mu, logvar, captions
    rows = torch.tensor(flip, device=keyframes.device)
    raw = vae.norm.denormalize(keyframes[rows])
    mirrored = vae.norm.normalize(mirror_features(raw, vae.skeleton))
    enc = vae.encode(mirrored, vae.positions_of(idx[rows], length[rows]), sample=False)
    mu, logvar = mu.clone(), logvar.clone()
    mu[rows], logvar[rows] = enc.mu.to(mu.dtype), enc.logvar.to(logvar.dtype)
    flipped = set(flip)
    captions = [mirror_side_words(c) if i in flipped else c for i, c in enumerate(captions)]
    return mu, logvar, captions


def roundtrip_keyframes(vae: KeyframeVAE, keyframes: torch.Tensor, indices: torch.Tensor, lengths: torch.Tensor
                        ) -> tuple[torch.Tensor, torch.Tensor]:
    """The keyframe VAE's reconstruction of keyframes, as generation would give them to the MMAE.

    ``keyframes (B, K, D)`` normalised, ``indices (B, K)``, ``lengths (B,)`` -> decoded keyframes ``(B, K, D)``
    (posterior mean decoded, sorted by position) and their frames ``(B, K)`` (strictly increasing, first 0,
    last ``L - 1``).
    """
    from .pipeline import decode_keyframes

    with torch.no_grad():
        enc = vae.encode(keyframes, vae.positions_of(indices, lengths), sample=False)
        return decode_keyframes(vae, enc.mu, lengths)


def _prepare_mmae(batch: dict[str, Any], ctx: StepContext, *, text: PrefilledCaptions,
                  config: KeyMotionTrainConfig, frames_norm: float | None = None,
                  roundtrip_vae: KeyframeVAE | None = None) -> dict[str, Any]:
    dev = ctx.env.device
    motion, length, idx, keyframes = _keyframe_inputs(batch, dev)
    b, n, d = motion.shape
    if roundtrip_vae is not None:
        pick = (ctx.rand.rand(b) < config.keyframe_roundtrip).to(dev)        # (B,) items given decoded keyframes
        if bool(pick.any()):
            kf_rt, idx_rt = roundtrip_keyframes(roundtrip_vae, keyframes[pick], idx[pick], length[pick])
            keyframes, idx = keyframes.clone(), idx.clone()
            keyframes[pick], idx[pick] = kf_rt.to(keyframes.dtype), idx_rt
    noise = ctx.rand.randn(b, (idx.shape[1], d)) * config.keyframe_noise
    if "keyframe_count" in batch:
        # a padded slot repeats its item's last keyframe: give it that keyframe's noise too, so the
        # repeated frame is scattered with one value (identity when no item is padded)
        slot = torch.arange(idx.shape[1], device=dev)[None].minimum(batch["keyframe_count"].to(dev)[:, None] - 1)
        noise = torch.gather(noise, 1, slot[..., None].expand(-1, -1, d))
    inputs, kf_mask = scatter_keyframes(keyframes + noise, idx, n)
    frame_mask = torch.arange(n, device=dev)[None] < length[:, None]
    with torch.no_grad():
        feats, mask = text.encode(list(batch["caption"]))
    out = {"motion": motion, "inputs": inputs, "keyframe_mask": kf_mask, "frame_mask": frame_mask,
           "text": feats.to(dev), "text_mask": mask.to(dev)}
    if ctx.train and frames_norm is not None:
        # the nominal per-rank batch, not b: with equal-frame batches b varies and the weight must not
        nominal = config.batch_size // ctx.env.world_size
        out["frame_weight"] = frame_mask.sum().to(motion.dtype) / (nominal * frames_norm)
    return out


# --------------------------------------------------------------------------------- tasks
def build_kf_vae_task(data_dir: str | os.PathLike, model_config: KeyframeVAEConfig | None,
                      train_config: KeyMotionTrainConfig, env: DistEnv) -> TrainTask:
    """The :class:`TrainTask` of a keyframe-VAE run (model built with ``train_config.seed``)."""
    model_config = model_config or KeyframeVAEConfig(max_length=train_config.max_length)
    if not isinstance(model_config, KeyframeVAEConfig):
        raise TypeError(f"model_config must be a KeyframeVAEConfig, got {type(model_config).__name__}")
    _check_max_length(model_config.max_length, train_config)
    _check_fixed_keyframes(train_config, "keyframe VAE")
    train_set, val_set = _datasets(data_dir, model_config.skeleton, model_config.num_keyframes, train_config)
    torch.manual_seed(train_config.seed)  # same initial weights on every rank and every run
    vae = KeyframeVAE(model_config).to(env.device)
    vae.set_normalization(train_set.mean, train_set.std)
    meta = {"data": str(Path(data_dir)), "keyframe_method": train_config.keyframe_method}
    if train_config.init_from is not None:
        init_stem = load_kf_vae_init(vae, train_config.init_from)
        _warn_other_statistics(train_set, vae, "keyframe VAE", init_stem)
        log.info("keyframe VAE initialised from %s (training %s)", init_stem, train_config.train_parts)
        meta.update(init_from=str(init_stem), train_parts=train_config.train_parts)
    objective = KeyframeVAEObjective(vae, freeze_encoder=train_config.train_parts == "decoder")
    return TrainTask(
        model=vae, model_type="keymotion_kf_vae", model_config=model_config, objective=objective,
        train_set=train_set, val_set=val_set, collate=collate_keyframes,
        prepare=partial(_prepare_vae, latent_shape=vae.latent_shape,
                        latent_noise=vae.config.latent_noise > 0, position_span=vae.position_span), meta=meta,
        extra_config={"kind": "keymotion_kf_vae", **meta, "data": str(Path(data_dir).resolve())},
        extra_files={"mean_std.safetensors": _mean_std_file(train_set)},
    )


def load_frozen_kf_vae(path: str | os.PathLike, device: str | torch.device = "cpu") -> KeyframeVAE:
    """A trained keyframe VAE (run folder, stem or file) in eval mode with gradients off."""
    from salad_core.io import load_model

    stem = resolve_checkpoint(path)
    vae, _, _ = load_model(stem)
    if not isinstance(vae, KeyframeVAE):
        raise TypeError(f"{stem} holds a {type(vae).__name__}, not a KeyframeVAE")
    vae = vae.to(device).eval()
    for p in vae.parameters():
        p.requires_grad_(False)
    return vae


def _encode_windows(vae: KeyframeVAE, source: Mapping[tuple, KeyframeDataset], keys: list[tuple],
                    batch_size: int = 256) -> Iterator[tuple[int, torch.Tensor, torch.Tensor]]:
    """``(first index, mu, logvar)`` of the keyframe VAE's posteriors ``(B, Lz, Dz)`` of the windows ``keys``
    (``(motion_id, offset, length)``, each selected and cropped by its dataset in ``source``), in batches."""
    device = next(vae.parameters()).device
    for b0 in range(0, len(keys), batch_size):
        chunk = keys[b0: b0 + batch_size]
        idx = np.stack([source[k].keyframes_of(k) for k in chunk])                 # (B, K)
        frames = np.stack([source[k].base.crop_features(*k)[i] for k, i in zip(chunk, idx)])   # (B, K, D)
        lengths = torch.tensor([k[2] for k in chunk])
        positions = vae.positions_of(torch.from_numpy(idx), lengths)
        with torch.no_grad():
            enc = vae.encode(torch.from_numpy(frames).to(device), positions.to(device), sample=False)
        yield b0, enc.mu, enc.logvar


def kf_latent_stats(vae: KeyframeVAE, dataset: KeyframeDataset, latents: Any = None,
                    batch_size: int = 256) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean and std ``(Lz, Dz)`` of the latents ``z = mu + sigma eps`` a PST is trained on, over every window of
    ``dataset`` (its posteriors looked up in ``latents``, a :func:`kf_vae_latent_cache`, or encoded).

    ``std^2 = var(mu) + mean(sigma^2)`` per token and channel: the spread of the sampled training latents, as
    SALAD's :func:`~salad_core.train.denoiser_trainer.denoiser_latent_stats`. Deterministic for a VAE and a
    corpus, so a resumed run computes the same numbers.
    """
    keys = list(dataset.base.crops())
    if not keys:
        raise ValueError("the dataset has no windows to compute latent statistics from")
    shape = vae.latent_shape
    total, total_sq, total_var = (torch.zeros(shape, dtype=torch.float64) for _ in range(3))
    if latents is not None:
        chunks = ((b0, *latents.lookup(keys[b0: b0 + batch_size])) for b0 in range(0, len(keys), batch_size))
    else:
        chunks = _encode_windows(vae, {k: dataset for k in keys}, keys, batch_size)
    for _, mu, logvar in chunks:
        mu = mu.detach().double().cpu()
        total += mu.sum(0)
        total_sq += (mu ** 2).sum(0)
        total_var += logvar.detach().double().cpu().exp().sum(0)
    n = len(keys)
    mean = total / n
    var = (total_sq / n - mean ** 2).clamp_min(0) + total_var / n
    return mean.float(), var.sqrt().clamp_min(1e-6).float()


def kf_vae_latent_cache(vae: KeyframeVAE, datasets: list[KeyframeDataset], cache_dir: str | os.PathLike,
                        env: DistEnv, *, prune: bool = False, batch_size: int = 256) -> Any:
    """The keyframe VAE's posteriors ``(Lz, Dz)`` of every window of ``datasets`` (a
    :class:`~salad_core.train.latent_cache.LatentCache` keyed by ``(motion_id, offset, length)``).

    Keyframes are selected once per window (and kept in the datasets' selection caches, so the
    PST's data loading then finds them); the signature covers the VAE's weights, the corpus, the
    selection method and the number of keyframes. Built by rank 0 under ``torchrun``.
    """
    import hashlib

    from salad_core.train.latent_cache import (CACHE_FORMAT, build_latent_cache, corpus_digest, module_digest,
                                               open_or_build_shared)

    source: dict[tuple, KeyframeDataset] = {}
    for ds in datasets:
        for key in ds.base.crops():
            source.setdefault(key, ds)
    keys = list(source)
    methods = sorted({f"{ds.method}/{ds.num_keyframes}" for ds in datasets})
    parts = [CACHE_FORMAT, "keymotion-kf-vae", module_digest(vae), *methods, *(corpus_digest(ds.base) for ds in datasets)]
    signature = hashlib.sha256("|".join(parts).encode()).hexdigest()
    lz, dz = vae.latent_shape

    def batches() -> Any:
        for b0, mu, logvar in _encode_windows(vae, source, keys, batch_size):
            yield list(range(b0, b0 + mu.shape[0])), mu, logvar

    def build(folder: Path) -> Any:
        log.info("selecting keyframes and encoding the posteriors of %d windows into %s", len(keys), folder)
        return build_latent_cache(folder, signature, keys, [lz] * len(keys), (dz,), batches(),
                                  meta={"kind": "keymotion_kf_vae", "methods": methods, "windows": len(keys)})

    return open_or_build_shared(cache_dir, signature, build, env, prune=prune)


def build_pst_task(data_dir: str | os.PathLike, vae_path: str | os.PathLike, model_config: PSTConfig | None,
                   train_config: KeyMotionTrainConfig, env: DistEnv, text_encoder: Any = "minilm",
                   diffusion_config: Any = None, *, text_cache: CaptionFeatureCache | None = None,
                   cache_dir: str | os.PathLike | None = None) -> TrainTask:
    """The :class:`TrainTask` of a PST run on the latents of a frozen keyframe VAE.

    ``text_cache`` (a :class:`CaptionFeatureCache` of the same encoder object) lets stages share
    caption features; by default one of ``train_config.text_cache_size`` entries is built here.
    Either way it is prefilled with the captions of the splits (see :class:`PrefilledCaptions`).
    ``cache_dir``: the latent cache's folder when ``train_config.latent_cache`` is on and
    ``train_config.latent_cache_dir`` is not set (:func:`train_pst` passes the run's ``latent_cache/``;
    without either a temporary folder is used).
    """
    from salad_core.sampling import DiffusionConfig, make_scheduler

    diffusion_config = diffusion_config or PST_DIFFUSION
    if not isinstance(diffusion_config, DiffusionConfig):
        raise TypeError(f"diffusion_config must be a DiffusionConfig, got {type(diffusion_config).__name__}")
    if diffusion_config.prediction_type != "epsilon":
        raise ValueError("the PST is trained with epsilon prediction (paper eq. 7); "
                         f"diffusion_config.prediction_type={diffusion_config.prediction_type!r}")
    vae = load_frozen_kf_vae(vae_path, env.device)
    encoder, encoder_name = _text_encoder(text_encoder, env.device)
    vc = vae.config
    if model_config is None:
        model_config = PSTConfig(latent_size=vc.latent_size, latent_dim=vc.latent_dim, text_dim=encoder.dim,
                                 max_length=train_config.max_length)
    if not isinstance(model_config, PSTConfig):
        raise TypeError(f"model_config must be a PSTConfig, got {type(model_config).__name__}")
    for name, want in (("latent_size", vc.latent_size), ("latent_dim", vc.latent_dim), ("text_dim", encoder.dim)):
        if getattr(model_config, name) != want:
            raise ValueError(f"PSTConfig.{name}={getattr(model_config, name)} does not fit: the "
                             f"{'text encoder' if name == 'text_dim' else 'keyframe VAE'} gives {want}; set {name}={want}")
    _check_max_length(vc.max_length, train_config)
    _check_all_parts(train_config, "PST")
    _check_fixed_keyframes(train_config, "PST")
    train_set, val_set = _datasets(data_dir, vc.skeleton, vc.num_keyframes, train_config)
    # fp16 weights (the shipped pipelines) round the stored statistics: not a different corpus
    if normalisation_gap(train_set.mean, train_set.std, vae.norm.mean, vae.norm.std) > NORMALISATION_TOLERANCE:
        log.warning("the keyframe VAE was trained with other normalisation statistics than %s's", data_dir)
    torch.manual_seed(train_config.seed)
    pst = ParallelSkipTransformer(model_config)
    init_stem = None
    if train_config.init_from is not None:
        init_stem = load_pst_init(pst, train_config.init_from)
        _warn_other_kf_vae(init_stem, vae)
        log.info("PST initialised from %s%s", init_stem,
                 " (side_embed starts at zero)" if model_config.side_cue else "")
    pst = pst.to(env.device)
    scheduler = make_scheduler(diffusion_config, "ddim")
    text = _stage_captions(text_cache, encoder, train_config, train_set, val_set)
    latents = None
    if train_config.latent_cache:
        where = train_config.latent_cache_dir or cache_dir
        if where is None:
            import tempfile

            where = tempfile.mkdtemp(prefix="salad_kf_latent_cache_")
            log.warning("no latent cache folder given: using %s (pass cache_dir)", where)
        latents = kf_vae_latent_cache(vae, [d for d in (train_set, val_set) if d is not None], where, env,
                                      prune=train_config.latent_cache_dir is None and cache_dir is not None)
    latent_stats = None
    if model_config.latent_norm:
        if init_stem is None:
            pst.set_latent_stats(*kf_latent_stats(vae, train_set, latents))
        latent_stats = (pst.latent_mean.detach().clone(), pst.latent_std.detach().clone())
        log.info("PST latent normalisation: training latents' mean %.3f, std %.3f (averaged over tokens and "
                 "channels)%s", float(latent_stats[0].mean()), float(latent_stats[1].mean()),
                 " (from init_from)" if init_stem is not None else "")
    prepare = partial(prepare_pst_batch, vae=vae, text=text, scheduler=scheduler, config=train_config,
                      latent_shape=vae.latent_shape, latents=latents, side_cue=model_config.side_cue,
                      latent_stats=latent_stats, side_canonical=model_config.side_canonical)
    meta = {"diffusion": config_to_dict(diffusion_config), "text_encoder": encoder_name,
            "kf_vae": str(resolve_checkpoint(vae_path)), "data": str(Path(data_dir))}
    extra_config = {"kind": "keymotion_pst", **meta, "data": str(Path(data_dir).resolve())}
    if init_stem is not None:
        meta["init_from"] = str(init_stem)
        extra_config["init_from"] = str(init_stem.resolve())
    numerics = {"latents": "cached keyframe-VAE posteriors, eps drawn per step" if latents is not None
                else "encoded at every step"}
    return TrainTask(
        model=pst, model_type="keymotion_pst", model_config=model_config, objective=PSTObjective(pst),
        train_set=train_set, val_set=val_set, collate=collate_keyframes, prepare=prepare, meta=meta,
        extra_config={**extra_config, "numerics": numerics},
        extra_files={"mean_std.safetensors": _mean_std_file(train_set)},
    )


#: PSTConfig fields that define the network and must match for ``init_from``; ``dropout``,
#: ``max_length``, ``max_text_tokens`` (a non-persistent table) and ``side_cue`` (its embedding
#: starts at zero) may differ.
PST_ARCHITECTURE_FIELDS = ("latent_size", "latent_dim", "text_dim", "width", "num_heads", "ff_dim",
                           "num_cond_layers", "num_cross_layers", "activation", "length_condition", "latent_norm")


def resolve_pst_source(path: str | os.PathLike) -> Path:
    """Checkpoint stem of the PST at ``path``: a KeyMotion pipeline folder (``pst.json``) or training
    root (``pst/`` run folder), a PST run folder (``best`` or else ``latest``), a stem, or its
    ``.json``/``.safetensors`` file."""
    return _resolve_stage_source(path, "pst")


def _resolve_stage_source(path: str | os.PathLike, stage: str) -> Path:
    """Checkpoint stem of stage ``stage`` ("pst", "mmae") at ``path`` (see :func:`resolve_pst_source`)."""
    from .pipeline import _resolve_component

    p = Path(path)
    if p.is_dir():
        if (p / f"{stage}.json").is_file() or (p / stage).is_dir():
            return _resolve_component(p, stage)
        return resolve_checkpoint(p)
    stem = p.with_suffix("") if p.suffix in (".json", ".safetensors") else p
    if not stem.with_suffix(".json").is_file():
        raise FileNotFoundError(f"{stem}.json does not exist")
    return stem


def _read_init(path: str | os.PathLike, stage: str) -> tuple[Path, dict, dict]:
    """``(stem, doc, state)`` of the trained ``stage`` model that ``init_from=path`` names, with errors that say
    what was expected."""
    from salad_core.io import CheckpointError, read_checkpoint

    source = f"KeyMotionTrainConfig.init_from={str(path)!r}"
    label = {"kf_vae": "a keyframe VAE", "pst": "a PST", "mmae": "an MMAE"}[stage]
    try:
        stem = _resolve_stage_source(path, stage)
    except (FileNotFoundError, CheckpointError) as exc:
        raise FileNotFoundError(f"{source} is neither a KeyMotion pipeline folder or training root, {label} run "
                                f"folder (best/latest) nor {label} checkpoint stem: {exc}") from None
    doc, state = read_checkpoint(stem)
    if doc["type"] != f"keymotion_{stage}":
        raise ValueError(f"{source}: {stem}.json holds a {doc['type']!r} model, not a 'keymotion_{stage}'")
    return stem, doc, state


def load_pst_init(pst: ParallelSkipTransformer, path: str | os.PathLike) -> Path:
    """Load the trained PST at ``path`` (:func:`resolve_pst_source`) into ``pst``; returns its stem.

    The two must have the same :data:`PST_ARCHITECTURE_FIELDS`. The only parameters ``pst`` may have
    that the checkpoint lacks are ``side_embed.*`` (a side cue added by the fine-tuning), which keep
    their zero initialisation, so the model starts as exactly the loaded one. Any other missing or
    unexpected key, or a shape mismatch, is an error naming the keys.
    """
    from salad_core.io import CheckpointError, config_from_dict

    source = f"KeyMotionTrainConfig.init_from={str(path)!r}"
    stem, doc, state = _read_init(path, "pst")
    init_config = config_from_dict(PSTConfig, doc["config"])
    diff = [f"{k}: {getattr(init_config, k)!r} (init_from) vs {getattr(pst.config, k)!r} (model config)"
            for k in PST_ARCHITECTURE_FIELDS if getattr(init_config, k) != getattr(pst.config, k)]
    if diff:
        raise ValueError(f"{source} holds a PST of another architecture; make the model config match it "
                         f"({'; '.join(diff)})")
    own = pst.state_dict()
    missing = sorted(set(own) - set(state))
    cue = [k for k in missing if k.startswith("side_embed.")]
    problems = []
    if len(cue) < len(missing):
        problems.append(f"missing keys {_key_list([k for k in missing if k not in cue])}")
    unexpected = sorted(set(state) - set(own))
    if unexpected:
        problems.append(f"unexpected keys {_key_list(unexpected)}")
    bad_shape = [k for k in own if k in state and tuple(own[k].shape) != tuple(state[k].shape)]
    if bad_shape:
        problems.append("shape mismatch at " + ", ".join(f"{k} (model {tuple(own[k].shape)} vs init_from "
                                                          f"{tuple(state[k].shape)})" for k in bad_shape[:5]))
    if problems:
        raise CheckpointError(f"{source} ({stem}) does not fit the PST (only side_embed.* may be missing): "
                              + "; ".join(problems))
    merged = {k: own[k] for k in cue}
    merged.update({k: v.to(own[k].dtype) for k, v in state.items()})
    pst.load_state_dict(merged, strict=True)
    return stem


def _key_list(keys: list[str], limit: int = 8) -> str:
    return f"{keys[:limit]}" + (f" ... ({len(keys)} in all)" if len(keys) > limit else "")


def _warn_other_kf_vae(pst_stem: Path, vae: KeyframeVAE) -> None:
    """Warn when the PST to fine-tune comes with a keyframe VAE (pipeline folder or training root)
    whose weights are not those of the frozen VAE this run diffuses the latents of."""
    from salad_core.io import load_tensors

    from .pipeline import _resolve_component

    root = pst_stem.parent if pst_stem.name == "pst" else pst_stem.parent.parent
    try:
        stem = _resolve_component(root, "kf_vae")
        theirs = load_tensors(stem.with_suffix(".safetensors"))
    except (FileNotFoundError, ValueError):
        return
    own = vae.state_dict()
    same = set(theirs) == set(own) and all(
        theirs[k].shape == own[k].shape and torch.equal(theirs[k].to(own[k].device, own[k].dtype), own[k])
        for k in own)
    if not same:
        log.warning("the PST of %s was trained on the latents of the keyframe VAE %s, not on those of the frozen "
                    "keyframe VAE of this run: fine-tuning starts from a model of another latent space", pst_stem, stem)


def build_mmae_task(data_dir: str | os.PathLike, model_config: MMAEConfig | None, train_config: KeyMotionTrainConfig,
                    env: DistEnv, text_encoder: Any = "minilm", num_keyframes: int = 20, *,
                    text_cache: CaptionFeatureCache | None = None) -> TrainTask:
    """The :class:`TrainTask` of an MMAE run (``num_keyframes`` must match the keyframe VAE's).

    ``text_cache``: as in :func:`build_pst_task`.
    """
    encoder, encoder_name = _text_encoder(text_encoder, env.device)
    if model_config is None:
        model_config = MMAEConfig(text_dim=encoder.dim, max_length=train_config.max_length)
    if not isinstance(model_config, MMAEConfig):
        raise TypeError(f"model_config must be an MMAEConfig, got {type(model_config).__name__}")
    if model_config.text_dim != encoder.dim:
        raise ValueError(f"MMAEConfig.text_dim={model_config.text_dim} does not fit: the text encoder gives "
                         f"{encoder.dim}; set text_dim={encoder.dim}")
    _check_max_length(model_config.max_length, train_config)
    _check_all_parts(train_config, "MMAE")
    train_set, val_set = _datasets(data_dir, model_config.skeleton, num_keyframes, train_config,
                                   ratio=train_config.keyframe_ratio)
    torch.manual_seed(train_config.seed)
    mmae = MotionMaskedAutoencoder(model_config).to(env.device)
    mmae.set_normalization(train_set.mean, train_set.std)
    init_stem = None
    if train_config.init_from is not None:
        init_stem = load_mmae_init(mmae, train_config.init_from)
        _warn_other_statistics(train_set, mmae, "MMAE", init_stem)
        log.info("MMAE initialised from %s", init_stem)
    roundtrip_vae, roundtrip_stem = None, None
    if train_config.keyframe_roundtrip > 0:
        roundtrip_stem = _resolve_stage_source(train_config.roundtrip_vae, "kf_vae")
        roundtrip_vae = load_frozen_kf_vae(roundtrip_stem, env.device)
        if roundtrip_vae.num_keyframes != num_keyframes:
            raise ValueError(f"KeyMotionTrainConfig.roundtrip_vae={train_config.roundtrip_vae!r} has "
                             f"{roundtrip_vae.num_keyframes} keyframes; this MMAE run selects num_keyframes="
                             f"{num_keyframes}")
        if normalisation_gap(roundtrip_vae.norm.mean, roundtrip_vae.norm.std, mmae.norm.mean,
                             mmae.norm.std) > NORMALISATION_TOLERANCE:
            raise ValueError(f"KeyMotionTrainConfig.roundtrip_vae={train_config.roundtrip_vae!r} normalises features "
                             "with other statistics than the MMAE: its keyframes would mean something else to it")
        log.info("MMAE in-fills the keyframe VAE %s's reconstructions for %.0f%% of the items", roundtrip_stem,
                 100 * train_config.keyframe_roundtrip)
    text = _stage_captions(text_cache, encoder, train_config, train_set, val_set)
    bucketing = train_config.batching in ("buckets", "frames")
    u = train_set.base.unit_length
    frames_norm = u * expected_latent_frames(train_set.lengths, u) if bucketing else None
    prepare = partial(_prepare_mmae, text=text, config=train_config, frames_norm=frames_norm,
                      roundtrip_vae=roundtrip_vae)
    meta = {"text_encoder": encoder_name, "num_keyframes": num_keyframes,
            "keyframe_method": train_config.keyframe_method, "keyframe_ratio": train_config.keyframe_ratio,
            "data": str(Path(data_dir))}
    if init_stem is not None:
        meta["init_from"] = str(init_stem)
    if roundtrip_stem is not None:
        meta.update(roundtrip_vae=str(roundtrip_stem), keyframe_roundtrip=train_config.keyframe_roundtrip)
    numerics = {"loss_normaliser": (f"per-batch means x valid frames / (batch x {frames_norm:.4g} expected frames)"
                                    if frames_norm is not None else "per-batch means over valid frames")}
    return TrainTask(
        model=mmae, model_type="keymotion_mmae", model_config=model_config, objective=MMAEObjective(mmae),
        train_set=train_set, val_set=val_set, collate=collate_keyframes, prepare=prepare, meta=meta,
        extra_config={"kind": "keymotion_mmae", **meta, "data": str(Path(data_dir).resolve()), "numerics": numerics},
        lengths=train_set.lengths,
        extra_files={"mean_std.safetensors": _mean_std_file(train_set)},
    )


def _check_all_parts(config: KeyMotionTrainConfig, stage: str) -> None:
    if config.train_parts != "all":
        raise ValueError(f"KeyMotionTrainConfig.train_parts={config.train_parts!r} is for the keyframe VAE only "
                         f"(decoder fine-tuning); the {stage} trains all its parts: set train_parts='all'")


def _check_fixed_keyframes(config: KeyMotionTrainConfig, stage: str) -> None:
    if config.keyframe_ratio:
        raise ValueError(f"KeyMotionTrainConfig.keyframe_ratio={config.keyframe_ratio} is for the MMAE only: the "
                         f"{stage} works on the keyframe VAE's fixed num_keyframes; set keyframe_ratio=0 for it")
    if config.keyframe_roundtrip:
        raise ValueError(f"KeyMotionTrainConfig.keyframe_roundtrip={config.keyframe_roundtrip} is for the MMAE only "
                         f"(its input keyframes); set keyframe_roundtrip=0 for the {stage}")


#: MMAEConfig fields that may differ between a fine-tuned MMAE and the one it starts from (loss weights,
#: dropout, table sizes); every other field defines the network and must match.
MMAE_FREE_FIELDS = ("lambda_bone", "lambda_vel", "lambda_foot", "lambda_foot_vel", "foot_vel_gate", "dropout",
                    "max_text_tokens")

#: KeyframeVAEConfig fields that may differ between a fine-tuned keyframe VAE and the one it starts from (loss
#: weights and dropout).
KF_VAE_FREE_FIELDS = ("lambda_kl", "lambda_bone", "lambda_index", "lambda_root", "lambda_local_vel",
                      "lambda_contact", "lambda_feet_height", "latent_noise", "dropout")


def _load_stage_init(model: nn.Module, path: str | os.PathLike, stage: str, config_class: type,
                     free_fields: tuple[str, ...], label: str) -> Path:
    """Load the trained ``stage`` model at ``path`` into ``model`` (normalisation included) when their configurations
    agree except for ``free_fields``; returns its stem."""
    from dataclasses import asdict

    from salad_core.io import config_from_dict, load_state_into

    source = f"KeyMotionTrainConfig.init_from={str(path)!r}"
    stem, doc, state = _read_init(path, stage)
    theirs, mine = asdict(config_from_dict(config_class, doc["config"])), asdict(model.config)
    diff = [f"{k}: {theirs[k]!r} (init_from) vs {mine[k]!r} (model config)" for k in mine
            if k not in free_fields and theirs.get(k) != mine[k]]
    if diff:
        raise ValueError(f"{source} holds {label} of another architecture; make the model config match it: "
                         + "; ".join(diff))
    load_state_into(model, state, source=f"{source} ({stem})")
    return stem


def load_mmae_init(mmae: MotionMaskedAutoencoder, path: str | os.PathLike) -> Path:
    """Load the trained MMAE at ``path`` (a KeyMotion pipeline folder or training root, an MMAE run folder,
    a checkpoint stem or its file) into ``mmae``, normalisation included; returns its stem.

    The configurations must agree except for :data:`MMAE_FREE_FIELDS`; the state must fit exactly.
    """
    return _load_stage_init(mmae, path, "mmae", MMAEConfig, MMAE_FREE_FIELDS, "an MMAE")


def load_kf_vae_init(vae: KeyframeVAE, path: str | os.PathLike) -> Path:
    """Load the trained keyframe VAE at ``path`` (a KeyMotion pipeline folder or training root, a keyframe-VAE
    run folder, a checkpoint stem or its file) into ``vae``, normalisation included; returns its stem.

    The configurations must agree except for :data:`KF_VAE_FREE_FIELDS`; the state must fit exactly.
    """
    return _load_stage_init(vae, path, "kf_vae", KeyframeVAEConfig, KF_VAE_FREE_FIELDS, "a keyframe VAE")


def _warn_other_statistics(dataset: KeyframeDataset, model: nn.Module, label: str, stem: Path) -> None:
    """Warn when the fine-tuning corpus's normalisation differs from the one the loaded model keeps."""
    if normalisation_gap(dataset.mean, dataset.std, model.norm.mean, model.norm.std) > NORMALISATION_TOLERANCE:
        log.warning("the %s of %s was trained with other normalisation statistics than this corpus's; it "
                    "keeps its own (its weights are tied to them)", label, stem)


def _check_max_length(model_max: int, config: KeyMotionTrainConfig) -> None:
    if config.max_length > model_max:
        raise ValueError(f"KeyMotionTrainConfig.max_length={config.max_length} exceeds the model's "
                         f"max_length={model_max}")


# ------------------------------------------------------------------------------- entry points
def train_kf_vae(data_dir: str | os.PathLike, out_dir: str | os.PathLike, model_config: KeyframeVAEConfig | None = None,
                 train_config: KeyMotionTrainConfig | None = None, resume: bool = False, *,
                 env: DistEnv | None = None, on_step: Callable[[int], None] | None = None) -> TrainResult:
    """Train a :class:`KeyframeVAE` on a HumanML3D-layout folder (run folder layout of :func:`fit`)."""
    train_config = train_config or KeyMotionTrainConfig()
    env = env or init_distributed(train_config.device)
    return fit(build_kf_vae_task(data_dir, model_config, train_config, env), out_dir, train_config,
               resume=resume, env=env, on_step=on_step)


def train_pst(data_dir: str | os.PathLike, out_dir: str | os.PathLike, vae_path: str | os.PathLike,
              model_config: PSTConfig | None = None, train_config: KeyMotionTrainConfig | None = None,
              text_encoder: Any = "minilm", resume: bool = False, *, diffusion_config: Any = None,
              env: DistEnv | None = None, on_step: Callable[[int], None] | None = None,
              text_cache: CaptionFeatureCache | None = None) -> TrainResult:
    """Train a :class:`ParallelSkipTransformer` on the latents of the frozen VAE at ``vae_path``.

    Fine-tuning a trained PST (``train_config.init_from``) must use the keyframe VAE it was trained
    on, e.g. the shipped weights with a side cue added::

        train_pst(data, out, DEFAULT_WEIGHTS_DIR / "kf_vae", PSTConfig(..., side_cue=True),
                  KeyMotionTrainConfig(init_from=str(DEFAULT_WEIGHTS_DIR), ...))
    """
    train_config = train_config or KeyMotionTrainConfig()
    env = env or init_distributed(train_config.device)
    task = build_pst_task(data_dir, vae_path, model_config, train_config, env, text_encoder, diffusion_config,
                          text_cache=text_cache, cache_dir=Path(out_dir) / "latent_cache")
    return fit(task, out_dir, train_config, resume=resume, env=env, on_step=on_step)


def train_mmae(data_dir: str | os.PathLike, out_dir: str | os.PathLike, model_config: MMAEConfig | None = None,
               train_config: KeyMotionTrainConfig | None = None, text_encoder: Any = "minilm",
               resume: bool = False, *, num_keyframes: int = 20, env: DistEnv | None = None,
               on_step: Callable[[int], None] | None = None,
               text_cache: CaptionFeatureCache | None = None) -> TrainResult:
    """Train a :class:`MotionMaskedAutoencoder` (in-filling from ``num_keyframes`` keyframes, or
    from ``train_config.keyframe_ratio`` of the frames when that is set)."""
    train_config = train_config or KeyMotionTrainConfig()
    env = env or init_distributed(train_config.device)
    task = build_mmae_task(data_dir, model_config, train_config, env, text_encoder, num_keyframes,
                           text_cache=text_cache)
    return fit(task, out_dir, train_config, resume=resume, env=env, on_step=on_step)


def train_keymotion(data_dir: str | os.PathLike, out_dir: str | os.PathLike, *,
                    vae_config: KeyframeVAEConfig | None = None, pst_config: PSTConfig | None = None,
                    mmae_config: MMAEConfig | None = None, vae_train: KeyMotionTrainConfig | None = None,
                    pst_train: KeyMotionTrainConfig | None = None, mmae_train: KeyMotionTrainConfig | None = None,
                    text_encoder: Any = "minilm", resume: bool = False, env: DistEnv | None = None
                    ) -> dict[str, TrainResult]:
    """Train the keyframe VAE, then the PST on its latents, then the MMAE; returns the results by stage.

    Writes ``out_dir/{kf_vae,pst,mmae}/`` (run folders) and ``out_dir/keymotion.json``, so that
    :meth:`KeyMotionPipeline.from_pretrained(out_dir) <salad_core.keymotion.pipeline.KeyMotionPipeline.from_pretrained>`
    loads the trained pipeline (each stage's ``best`` checkpoint if it was validated, else
    ``latest``). With ``resume`` a finished stage is skipped and an interrupted one continues.
    A stage stopped by a signal (SIGINT/SIGTERM) ends the call: the later stages are not started,
    the returned dict holds the stages run so far, and ``keymotion.json`` is not written.
    The PST and MMAE share one caption-feature cache when their ``text_cache_size`` agree.
    """
    out = Path(out_dir)
    vae_train = vae_train or KeyMotionTrainConfig()
    pst_train, mmae_train = pst_train or vae_train, mmae_train or vae_train
    env = env or init_distributed(vae_train.device)
    encoder, encoder_name = _text_encoder(text_encoder, env.device)   # loaded once for both text stages
    results: dict[str, TrainResult] = {}
    results["kf_vae"] = train_kf_vae(data_dir, out / "kf_vae", vae_config, vae_train, resume, env=env)
    if results["kf_vae"].interrupted:
        return results
    # the MMAE in-fills from as many keyframes as the trained VAE generates
    vae_doc = json.loads(resolve_checkpoint(out / "kf_vae").with_suffix(".json").read_text())
    num_keyframes = int(vae_doc["config"]["num_keyframes"])
    pst_cache = CaptionFeatureCache(encoder, pst_train.text_cache_size)
    mmae_cache = pst_cache if mmae_train.text_cache_size == pst_train.text_cache_size else None
    results["pst"] = train_pst(data_dir, out / "pst", out / "kf_vae", pst_config, pst_train, encoder, resume,
                               env=env, text_cache=pst_cache)
    if results["pst"].interrupted:
        return results
    results["mmae"] = train_mmae(data_dir, out / "mmae", mmae_config, mmae_train, encoder, resume,
                                 num_keyframes=num_keyframes, env=env, text_cache=mmae_cache)
    if env.is_main and not results["mmae"].interrupted:
        # 120 frames (6 s) unless the models were trained on shorter motions
        default_length = min(120, vae_train.max_length, pst_train.max_length, mmae_train.max_length)
        doc = {"format": "keymotion_pipeline", "version": 1, "text_encoder": encoder_name,
               "diffusion": config_to_dict(PST_DIFFUSION), "default_length": default_length}
        atomic_write_text(out / "keymotion.json", json.dumps(doc, indent=2) + "\n")
        from salad_core.train.assemble import numerics_note, write_numerics_section

        # the card of the loadable folder says when the stages' numerics differ from release 0.5
        write_numerics_section(out / "MODEL_CARD.md", numerics_note({stage: out / stage for stage in STAGES}))
    return results


# --------------------------------------------------------------------------- config files
#: The three stages, in training order (run folders and config sections of that name).
STAGES: tuple[str, ...] = ("kf_vae", "pst", "mmae")
_MODEL_CONFIGS: dict[str, type] = {"kf_vae": KeyframeVAEConfig, "pst": PSTConfig, "mmae": MMAEConfig}


@dataclass(frozen=True)
class KeyMotionRecipe:
    """Everything :func:`train_keymotion` needs, read from / written to one JSON document.

    The document (``configs/keymotion-0.2.json``; a run's ``config.json``)::

        {"text_encoder": "minilm",
         "train":  {...},                                  fields shared by the three stages
         "kf_vae": {"model": {...}, "train": {...}},       KeyframeVAEConfig, stage train fields
         "pst":    {"model": {...}, "train": {...}},       PSTConfig
         "mmae":   {"model": {...}, "train": {...}}}       MMAEConfig

    A stage's train config is the shared ``"train"`` fields updated by its own. Omitted model
    configs use the model defaults; the PST's ``latent_size``/``latent_dim`` default to the
    keyframe VAE's.
    """

    kf_vae_model: KeyframeVAEConfig | None = None      # None: KeyframeVAEConfig defaults
    pst_model: PSTConfig | None = None                 # None: sized from the VAE and the text encoder
    mmae_model: MMAEConfig | None = None               # None: MMAEConfig defaults (text_dim of the encoder)
    kf_vae_train: KeyMotionTrainConfig = KeyMotionTrainConfig()   # keyframe VAE recipe
    pst_train: KeyMotionTrainConfig = KeyMotionTrainConfig()      # PST recipe
    mmae_train: KeyMotionTrainConfig = KeyMotionTrainConfig()     # MMAE recipe
    text_encoder: str = "minilm"                       # "minilm" or a local CLIP folder

    def __post_init__(self) -> None:
        for stage in STAGES:
            model, train = getattr(self, f"{stage}_model"), getattr(self, f"{stage}_train")
            if model is not None and not isinstance(model, _MODEL_CONFIGS[stage]):
                raise TypeError(f"KeyMotionRecipe.{stage}_model must be a {_MODEL_CONFIGS[stage].__name__} or None, "
                                f"got {type(model).__name__}")
            if not isinstance(train, KeyMotionTrainConfig):
                raise TypeError(f"KeyMotionRecipe.{stage}_train must be a KeyMotionTrainConfig, got {type(train).__name__}")
        if not isinstance(self.text_encoder, str) or not self.text_encoder:
            raise ValueError(f"KeyMotionRecipe.text_encoder={self.text_encoder!r} is invalid; use 'minilm' or a CLIP folder")

    @classmethod
    def from_doc(cls, doc: dict[str, Any], *, train_overrides: dict[str, Any] | None = None,
                 stage_overrides: dict[str, dict[str, Any]] | None = None) -> "KeyMotionRecipe":
        """Build from a document (see the class docstring).

        ``train_overrides`` replace fields of every stage's train config, then
        ``stage_overrides[stage]`` those of one stage (e.g. ``{"pst": {"max_steps": 900}}``);
        None values are ignored.
        """
        from salad_core.io import config_from_dict

        if not isinstance(doc, dict):
            raise ValueError(f"a KeyMotion config must be a JSON object, got {type(doc).__name__}")
        known = {"text_encoder", "train", *STAGES}
        unknown = sorted(k for k in doc if k not in known and not k.startswith("_"))
        if unknown:
            raise ValueError(f"unknown keys {unknown} in the KeyMotion config; allowed: {sorted(known)}")
        stage_overrides = stage_overrides or {}
        bad = sorted(set(stage_overrides) - set(STAGES))
        if bad:
            raise ValueError(f"stage_overrides has unknown stages {bad}; use {list(STAGES)}")
        shared = doc.get("train") or {}
        kw: dict[str, Any] = {"text_encoder": doc.get("text_encoder", "minilm")}
        for stage in STAGES:
            section = doc.get(stage) or {}
            extra = sorted(set(section) - {"model", "train"})
            if extra:
                raise ValueError(f"section {stage!r} of the KeyMotion config has unknown keys {extra}; "
                                 "allowed: ['model', 'train']")
            fields = {**shared, **(section.get("train") or {})}
            for over in (train_overrides or {}, stage_overrides.get(stage) or {}):
                fields.update({k: v for k, v in over.items() if v is not None})
            kw[f"{stage}_train"] = config_from_dict(KeyMotionTrainConfig, fields)
            model = dict(section.get("model") or {})
            if stage == "pst" and model and kw["kf_vae_model"] is not None:
                vae = kw["kf_vae_model"]
                model.setdefault("latent_size", vae.latent_size)
                model.setdefault("latent_dim", vae.latent_dim)
            kw[f"{stage}_model"] = config_from_dict(_MODEL_CONFIGS[stage], model) if model else None
        return cls(**kw)

    def to_doc(self) -> dict[str, Any]:
        """The document (full train config per stage, no shared ``"train"`` section)."""
        doc: dict[str, Any] = {"text_encoder": self.text_encoder}
        for stage in STAGES:
            model = getattr(self, f"{stage}_model")
            section: dict[str, Any] = {"train": config_to_dict(getattr(self, f"{stage}_train"))}
            if model is not None:
                section["model"] = config_to_dict(model)
            doc[stage] = section
        return doc

    def train_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`train_keymotion`."""
        return {"vae_config": self.kf_vae_model, "pst_config": self.pst_model, "mmae_config": self.mmae_model,
                "vae_train": self.kf_vae_train, "pst_train": self.pst_train, "mmae_train": self.mmae_train,
                "text_encoder": self.text_encoder}


def load_keymotion_recipe(path: str | os.PathLike, **overrides: Any) -> KeyMotionRecipe:
    """Read a KeyMotion config JSON file (``overrides``: those of :meth:`KeyMotionRecipe.from_doc`)."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path} is not valid JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: a KeyMotion config must be a JSON object, got {type(doc).__name__}")
    return KeyMotionRecipe.from_doc(doc, **overrides)
