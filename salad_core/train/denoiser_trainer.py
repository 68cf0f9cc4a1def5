"""Training of the latent denoiser (paper §3.2, eqs. 7-8; official ``DenoiserTrainer.train_forward``).

One step, for a batch of motions ``(B, N, D)`` with lengths ``L``:

1. ``z = mu + eps * exp(logvar / 2)`` from the **frozen** VAE (sampled, as the official code
   does), masked to the ``L // 4`` valid latent frames;
2. ``t ~ U{0..T-1}``, masked noise, ``x_t = add_noise(z, noise, t)`` (diffusers scheduler);
3. each caption is replaced by the null text ``""`` with probability ``cond_drop_prob``
   (classifier-free guidance, eq. 9), and encoded by the frozen text encoder without gradients;
4. the target is ``v``, ``eps`` or ``z`` by prediction type; the loss is the MSE over valid
   latent elements.

All random draws come from the trainer's shared generator for the global batch, so the run is
reproducible and independent of the number of processes.

Since 0.6 (defaults; each has a switch in :class:`DenoiserTrainConfig`):

* ``latent_cache``: ``mu`` and ``logvar`` of every window an item can take are encoded once per
  (VAE, corpus) and looked up (:mod:`salad_core.train.latent_cache`); ``eps`` is still drawn at
  every step. With ``vae_pad_to_max`` the cached posteriors equal the on-the-fly ones; without it
  each window is encoded alone (on the fly, it was encoded inside its batch, padded to the batch's
  longest window, so its last latent frames depended on the batch).
* ``batching="buckets"``: length-sorted batches (:mod:`salad_core.train.batching`); the summed
  squared error of a training batch is then divided by ``batch x expected valid latent elements
  per item`` instead of the batch's own count, so every valid element weighs the same in every
  batch and the objective is not tilted towards short clips (validation keeps the per-batch mean).

Otherwise motions are encoded at the padded
``max_length`` (as the official loader pads to 196; ``vae_pad_to_max``), which makes a sample's
latent independent of the other samples in its batch; latents are then trimmed to the longest
sample of the batch, which the denoiser's key-padding masks make exact. Motions are normalised
with the statistics the VAE was trained with (``mean_std.safetensors`` of its run folder).
"""
from __future__ import annotations

import logging
import os
from functools import partial
from pathlib import Path
from typing import Any, Callable, Sequence

import torch
from torch import nn

from salad_core.io import CheckpointError, config_to_dict
from salad_core.sampling import training_target
from salad_core.train.assemble import vae_source

from .common import StepContext, TrainResult, TrainTask, fit
from .batching import expected_latent_frames
from .config import DenoiserTrainConfig
from .distributed import DistEnv, all_reduce_sum, init_distributed

__all__ = ["DenoiserObjective", "CaptionFeatureCache", "train_denoiser", "build_denoiser_task", "load_frozen_vae",
           "resolve_checkpoint", "cached_latents", "denoiser_latent_cache", "denoiser_latent_stats", "prepare_denoiser_batch",
           "split_denoiser_inputs", "vae_statistics"]

log = logging.getLogger(__name__)


class DenoiserObjective(nn.Module):
    """``forward(...) -> dict(loss)``: masked MSE between the denoiser output and the target.

    A module so that DDP can wrap it (see :class:`~salad_core.train.vae_trainer.VAEObjective`).
    """

    def __init__(self, denoiser: nn.Module) -> None:
        super().__init__()
        self.denoiser = denoiser

    def forward(self, noisy: torch.Tensor, timesteps: torch.Tensor, text: torch.Tensor, text_mask: torch.Tensor,
                frame_mask: torch.Tensor, target: torch.Tensor, denom: torch.Tensor) -> dict[str, torch.Tensor]:
        """Loss for one batch.

        Parameters
        ----------
        noisy, target : Tensor ``(B, N', P, Dz)``
        timesteps : Tensor ``(B,)`` long
        text : Tensor ``(B, W, C)``; text_mask : Tensor ``(B, W)`` bool (True = real token)
        frame_mask : Tensor ``(B, N')`` bool (True = valid latent frame)
        denom : Tensor ``()``
            Number of valid elements the squared errors are divided by (under DDP the global
            count divided by the world size, so that DDP's gradient average is the global mean).
        """
        pred = self.denoiser(noisy, timesteps, text, text_mask, frame_mask)      # (B, N', P, Dz)
        sq = (pred - target).pow(2) * frame_mask[:, :, None, None].to(pred.dtype)
        return {"loss": sq.sum() / denom}


class CaptionFeatureCache:
    """Token features per caption, computed once and kept (LRU) for later batches.

    Each caption is encoded *alone*, so its features never depend on which other captions share
    its batch (padding can change the floating-point result of a batched forward); a cached run
    is therefore exactly reproducible and resumable whatever the cache holds. Only the valid tokens
    are kept; a batch is re-padded to its longest caption with a False mask, which cross-attention
    ignores. Each caption's token strings (``TextBatch.tokens``) are kept beside its features, for
    models that read the tokens themselves (:meth:`encode_with_tokens`; KeyMotion's side cue).

    Parameters
    ----------
    encoder : TextEncoder
        ``encode(prompts, allow_empty=True) -> TextBatch``.
    max_entries : int
        Captions kept (least recently used are evicted); 0 disables the cache and encodes each
        batch in one call.
    """

    def __init__(self, encoder: Any, max_entries: int) -> None:
        from collections import OrderedDict

        self.encoder = encoder
        self.max_entries = max_entries
        self._store: "OrderedDict[str, torch.Tensor]" = OrderedDict()
        self._tokens: dict[str, list[str]] = {}                        # same keys as _store
        self.hits = 0
        self.misses = 0

    def _entry(self, caption: str) -> tuple[torch.Tensor, list[str]]:
        """``(features (W_valid, C), token strings (W_valid,))`` of one caption, encoded alone."""
        feats = self._store.get(caption)
        if feats is not None:
            self._store.move_to_end(caption)
            self.hits += 1
            return feats, self._tokens[caption]
        self.misses += 1
        tb = self.encoder.encode([caption], allow_empty=True)
        feats = tb.features[0, tb.mask[0]].clone()                     # (W_valid, C)
        tokens = list(tb.tokens[0])
        self._store[caption] = feats
        self._tokens[caption] = tokens
        if len(self._store) > self.max_entries:
            old, _ = self._store.popitem(last=False)
            del self._tokens[old]
        return feats, tokens

    def _one(self, caption: str) -> torch.Tensor:
        return self._entry(caption)[0]

    def prefill(self, captions: Sequence[str], batch_size: int = 64) -> int:
        """Encode every caption of a dataset up front, in fixed batches of similar length.

        Encoding captions one by one costs a text-encoder forward per caption during the first
        epochs (most of a CPU step); batches are ~20x cheaper. The batches depend only on the set
        of captions (sorted by length, then text), never on the data order or the cache history,
        so runs stay exactly reproducible and resumable. Returns the number of captions encoded;
        nothing is done when they would not all fit in the cache.
        """
        todo = sorted({c for c in captions if c not in self._store}, key=lambda c: (len(c), c))
        if not todo or len(self._store) + len(todo) > self.max_entries:
            return 0
        for i in range(0, len(todo), batch_size):
            chunk = todo[i: i + batch_size]
            tb = self.encoder.encode(chunk, allow_empty=True)
            for j, caption in enumerate(chunk):
                self._store[caption] = tb.features[j, tb.mask[j]].clone()
                self._tokens[caption] = list(tb.tokens[j])
        return len(todo)

    def encode(self, captions: list[str]) -> tuple[torch.Tensor, torch.Tensor]:
        """``(features (B, W, C), mask (B, W) bool)`` on the CPU."""
        feats, mask, _ = self.encode_with_tokens(captions)
        return feats, mask

    def encode_with_tokens(self, captions: list[str]) -> tuple[torch.Tensor, torch.Tensor, list[list[str]]]:
        """:meth:`encode` and each caption's unpadded token strings (``TextBatch.tokens``): token ``j``
        of caption ``b`` is feature column ``j``."""
        if self.max_entries <= 0:
            tb = self.encoder.encode(captions, allow_empty=True)
            return tb.features, tb.mask, [list(t) for t in tb.tokens]
        entries = [self._entry(c) for c in captions]
        return (*self._pad([f for f, _ in entries]), [t for _, t in entries])

    @staticmethod
    def _pad(rows: list[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """Rows ``(W_b, C)`` right-padded into ``(features (B, W, C), mask (B, W) bool)``."""
        w = max(r.shape[0] for r in rows)
        feats = rows[0].new_zeros((len(rows), w, rows[0].shape[1]))
        mask = torch.zeros((len(rows), w), dtype=torch.bool)
        for i, r in enumerate(rows):
            feats[i, : r.shape[0]] = r
            mask[i, : r.shape[0]] = True
        return feats, mask


def resolve_checkpoint(path: str | os.PathLike) -> Path:
    """A checkpoint stem from a run folder (``best`` if present, else ``latest``), a stem, or a file."""
    p = Path(path)
    if p.is_dir():
        for stem in ("best", "latest"):
            if (p / f"{stem}.safetensors").is_file():
                return p / stem
        raise CheckpointError(f"{p} holds no best.safetensors or latest.safetensors (is it a training run folder?)")
    return p.with_suffix("") if p.suffix in (".json", ".safetensors") else p


def load_frozen_vae(path: str | os.PathLike, device: str | torch.device = "cpu") -> nn.Module:
    """Load a trained VAE in eval mode with gradients off: a run folder, an exported VAE or pipeline folder,
    or a checkpoint stem (:func:`salad_core.train.assemble.vae_source`)."""
    import salad_core.models.vae  # noqa: F401  (registers the "salad_vae" type)
    from salad_core.io import load_model

    stem = vae_source(path).stem
    vae, _, _ = load_model(stem)
    vae = vae.to(device).eval()
    for p in vae.parameters():
        p.requires_grad_(False)
    return vae


def vae_statistics(vae_path: str | os.PathLike) -> tuple[Any, Any]:
    """The normalisation the VAE was trained with (``mean_std.safetensors`` of its run, or ``stats.safetensors``
    of an exported VAE or pipeline folder: :func:`salad_core.train.assemble.vae_source`), else ``(None, None)``:
    the latents only mean what the VAE learned if the motions are normalised the same way."""
    from salad_core.io import load_tensors

    source = vae_source(vae_path)
    if source.has_stats:
        stats = load_tensors(source.stats)
        return stats["mean"].numpy(), stats["std"].numpy()
    log.info("no %s beside %s: normalising with the data folder's Mean.npy/Std.npy", source.stats.name, source.stem)
    return None, None


def prepare_denoiser_batch(batch: dict[str, Any], ctx: StepContext, *, vae: nn.Module, text: CaptionFeatureCache,
                           scheduler: Any, config: DenoiserTrainConfig, prediction_type: str,
                           latent_shape: tuple[int, int, int], latents: Any = None, frames_norm: float | None = None,
                           latent_stats: tuple[torch.Tensor, torch.Tensor] | None = None) -> dict[str, Any]:
    """The :class:`DenoiserObjective` inputs of a training batch: steps 1-4 of the module docstring.

    ``batch`` has ``motion`` ``(B, N, D)`` (normalised), ``length`` ``(B,)`` and ``caption`` (and,
    with ``latents``, ``motion_id`` and ``offset``); ``latent_shape`` is ``(N', P, Dz)`` at the
    padded length. Every draw comes from ``ctx.rand`` (global batch), so the result depends only
    on the batch and the step.

    ``latents`` (a :class:`~salad_core.train.latent_cache.LatentCache` keyed by ``(motion_id, offset,
    length)``) replaces the VAE encoder; ``frames_norm`` (expected valid latent frames per item) makes
    the training loss ``sum of squared errors / (batch x frames_norm x P x Dz)`` (see the module docstring).
    ``latent_stats`` ``(mean, std)`` of shape ``(P, Dz)``: diffuse the normalised latent ``(z - mean) / std``.
    """
    env, rand, dev = ctx.env, ctx.rand, ctx.env.device
    motion = batch["motion"].to(dev, non_blocking=True)                 # (B, max_length, D)
    length = batch["length"].to(dev)
    b = motion.shape[0]
    ds = vae.downsample
    lat_len = length // ds                                               # valid latent frames
    n_lat = int(lat_len.max())                                           # trimmed N'
    frame_mask = torch.arange(n_lat, device=dev)[None, :] < lat_len[:, None]   # (B, N')
    m = frame_mask[:, :, None, None].to(motion.dtype)

    # draws for the global batch (sliced to this rank), always in the same order and full size
    eps = rand.randn(b, latent_shape)[:, :n_lat]                         # VAE reparameterisation
    t = rand.randint(b, scheduler.config.num_train_timesteps)            # t ~ U{0..T-1}
    noise = rand.randn(b, latent_shape)[:, :n_lat] * m
    drop = rand.rand(b) < config.cond_drop_prob                          # CFG caption dropping
    if not ctx.train and not config.val_cond_drop:
        drop = torch.zeros_like(drop)

    with torch.no_grad():
        if latents is not None:
            keys = list(zip(batch["motion_id"], (int(o) for o in batch["offset"]), length.tolist()))
            mu, logvar = (t_.to(dev) for t_ in latents.lookup(keys, n_lat))   # (B, N', P, Dz)
        else:
            if not config.vae_pad_to_max:
                motion = motion[:, : n_lat * ds]                         # faster; latents then depend on the batch
            enc = vae.encode(motion, sample=False)                       # (B, N/4, P, Dz)
            mu, logvar = enc.mu[:, :n_lat], enc.logvar[:, :n_lat]
        z = mu + eps * torch.exp(0.5 * logvar)
        if latent_stats is not None:
            z = (z - latent_stats[0].to(z)) / latent_stats[1].to(z)
        z = z * m
        noisy = scheduler.add_noise(z, noise, t)
        target = training_target(scheduler, z, noise, t, prediction_type)
        captions = ["" if d else c for d, c in zip(drop.tolist(), batch["caption"])]
        text_feats, text_mask = text.encode(captions)                    # (B, W, C), (B, W)
    if ctx.train and frames_norm is not None:
        # a constant per item: every valid element weighs the same in every (length-sorted) batch
        # (the nominal per-rank batch, not b: with equal-frame batches b varies and the weight must not)
        nominal = config.batch_size // env.world_size
        count = torch.tensor(nominal * frames_norm * latent_shape[1] * latent_shape[2], dtype=torch.float64, device=dev)
    else:
        count = frame_mask.sum().to(torch.float64) * (latent_shape[1] * latent_shape[2])
        if ctx.train and env.distributed:
            count = all_reduce_sum(count, env) / env.world_size
    return {"noisy": noisy, "timesteps": t, "text": text_feats.to(dev), "text_mask": text_mask.to(dev),
            "frame_mask": frame_mask, "target": target, "denom": count.clamp_min(1.0).to(motion.dtype)}


def denoiser_latent_cache(vae: nn.Module, datasets: Sequence[Any], config: DenoiserTrainConfig,
                          cache_dir: str | os.PathLike, env: DistEnv, *, prune: bool = False) -> Any:
    """The :class:`~salad_core.train.latent_cache.LatentCache` of every window of ``datasets`` under ``vae``.

    Opened from ``cache_dir/<signature>`` or built there (by rank 0; the other ranks wait and open
    it). The signature covers the VAE's weights, the datasets' clips, statistics and windows, and the
    encoding (padded to ``max_length`` when ``config.vae_pad_to_max``, else each window alone).
    """
    import hashlib

    from .latent_cache import (CACHE_FORMAT, build_latent_cache, corpus_digest, encode_motion_windows,
                               module_digest, open_or_build_shared)

    pad_to = config.max_length if config.vae_pad_to_max else None
    source: dict[tuple, Any] = {}
    for ds in datasets:
        for key in ds.crops():
            source.setdefault(key, ds)
    keys = list(source)
    parts = [CACHE_FORMAT, module_digest(vae), f"pad_to={pad_to}", config.latent_cache_dtype,
             *(corpus_digest(ds) for ds in datasets)]
    signature = hashlib.sha256("|".join(parts).encode()).hexdigest()

    def build(folder: Path) -> Any:
        log.info("encoding the VAE posteriors of %d windows into %s", len(keys), folder)
        batches = encode_motion_windows(vae, lambda k: source[k].crop_features(*k), keys, pad_to=pad_to)
        return build_latent_cache(folder, signature, keys, [k[2] // vae.downsample for k in keys],
                                  (vae.num_parts, vae.latent_dim), batches, dtype=config.latent_cache_dtype,
                                  meta={"pad_to": pad_to, "splits": [str(getattr(d, "split", "?")) for d in datasets],
                                        "windows": len(keys)})

    return open_or_build_shared(cache_dir, signature, build, env, prune=prune)


def cached_latents(vae, train_set, val_set, config, cache_dir, env):
    """The frozen VAE's posteriors of every training window of ``train_set`` and ``val_set``
    (:func:`denoiser_latent_cache`), or None when ``config.latent_cache`` is off. The cache lives in
    ``config.latent_cache_dir`` (kept) or else ``cache_dir`` (the run's, pruned of stale entries), or else a
    temporary folder nobody removes (warned)."""
    if not config.latent_cache:
        return None
    own = config.latent_cache_dir is None and cache_dir is not None
    where = config.latent_cache_dir or cache_dir
    if where is None:
        import tempfile

        where = tempfile.mkdtemp(prefix="salad_latent_cache_")
        log.warning("no latent cache folder given: using %s (removed by nobody; pass cache_dir)", where)
    return denoiser_latent_cache(vae, [d for d in (train_set, val_set) if d is not None], config, where, env,
                                 prune=own)


def build_denoiser_task(data_dir: str | os.PathLike, vae_path: str | os.PathLike, model_config: Any,
                        train_config: DenoiserTrainConfig, env: DistEnv, text_encoder: Any = "minilm",
                        diffusion_config: Any = None, *, cache_dir: str | os.PathLike | None = None) -> TrainTask:
    """The :class:`TrainTask` of a denoiser run (model built with ``train_config.seed``).

    ``cache_dir``: where the latent cache lives when ``train_config.latent_cache`` is on and
    ``train_config.latent_cache_dir`` is not set (:func:`train_denoiser` passes the run folder's
    ``latent_cache/``; without either a temporary folder is used).
    """
    from salad_core.data.dataset import MotionTextDataset, collate_motion_text
    from salad_core.models.denoiser import Denoiser, DenoiserConfig
    from salad_core.sampling import DiffusionConfig, make_scheduler
    from salad_core.text import load_text_encoder

    diffusion_config = diffusion_config or DiffusionConfig()
    if not isinstance(diffusion_config, DiffusionConfig):
        raise TypeError(f"diffusion_config must be a DiffusionConfig, got {type(diffusion_config).__name__}")
    vae = load_frozen_vae(vae_path, env.device)
    encoder = load_text_encoder(text_encoder, device=env.device) if isinstance(text_encoder, (str, Path)) else text_encoder
    encoder_name = str(text_encoder) if isinstance(text_encoder, (str, Path)) else getattr(encoder, "source", type(encoder).__name__)
    if model_config is None:
        model_config = DenoiserConfig(latent_dim=vae.latent_dim, num_parts=vae.num_parts, text_dim=encoder.dim)
    if not isinstance(model_config, DenoiserConfig):
        raise TypeError(f"model_config must be a DenoiserConfig, got {type(model_config).__name__}")
    for name, want in (("latent_dim", vae.latent_dim), ("num_parts", vae.num_parts), ("text_dim", encoder.dim)):
        if getattr(model_config, name) != want:
            raise ValueError(f"DenoiserConfig.{name}={getattr(model_config, name)} does not fit: the "
                             f"{'text encoder' if name == 'text_dim' else 'VAE'} gives {want}; set {name}={want}")
    if train_config.max_length % vae.downsample:
        raise ValueError(f"DenoiserTrainConfig.max_length={train_config.max_length} must be a multiple of the "
                         f"VAE's temporal down-sampling {vae.downsample}")

    skeleton = vae.config.skeleton
    mean, std = vae_statistics(vae_path)
    train_set = MotionTextDataset(data_dir, "train", skeleton=skeleton, max_length=train_config.max_length,
                                  unit_length=vae.downsample, mean=mean, std=std, random_crop=True,
                                  seed=train_config.seed)
    try:
        val_set = MotionTextDataset(data_dir, "val", skeleton=skeleton, max_length=train_config.max_length,
                                    unit_length=vae.downsample, mean=train_set.mean, std=train_set.std,
                                    random_crop=False)
    except (FileNotFoundError, ValueError) as exc:
        log.warning("no validation items (%s)", exc)
        val_set = None

    torch.manual_seed(train_config.seed)  # same initial weights on every rank and every run
    denoiser = Denoiser(model_config).to(env.device)
    scheduler = make_scheduler(diffusion_config, "ddim")
    latent_shape = (train_config.max_length // vae.downsample, vae.num_parts, vae.latent_dim)
    text_cache = CaptionFeatureCache(encoder, train_config.text_cache_size)
    captions = [line.caption for ds in (train_set, val_set) if ds is not None for line in ds.all_captions()]
    if text_cache.prefill(captions):
        log.info("text features of %d captions computed up front", len(text_cache._store))
    latents = cached_latents(vae, train_set, val_set, train_config, cache_dir, env)
    latent_stats = denoiser_latent_stats(vae, train_set) if train_config.latent_norm else None
    bucketing = train_config.batching in ("buckets", "frames")
    frames_norm = expected_latent_frames(train_set.lengths, vae.downsample) if bucketing else None
    prepare = partial(prepare_denoiser_batch, vae=vae, text=text_cache,
                      scheduler=scheduler, config=train_config,
                      prediction_type=diffusion_config.prediction_type, latent_shape=latent_shape,
                      latents=latents, frames_norm=frames_norm, latent_stats=latent_stats)
    meta = {"diffusion": config_to_dict(diffusion_config), "text_encoder": encoder_name,
            "vae": str(vae_source(vae_path).stem), "data": str(Path(data_dir))}
    numerics = {
        "latents": (f"cached posteriors ({'padded to max_length' if train_config.vae_pad_to_max else 'each window alone'}, "
                    f"{train_config.latent_cache_dtype}), eps drawn per step" if latents is not None
                    else "encoded at every step"),
        "loss_normaliser": (f"batch x expected valid latent frames per item ({frames_norm:.4g}) x parts x latent dim"
                            if frames_norm is not None else "valid latent elements of the batch"),
        "latent_norm": "per part and channel, training-set statistics" if latent_stats is not None else "none",
    }
    extra_files = {"mean_std.safetensors": {"mean": torch.as_tensor(train_set.mean, dtype=torch.float32),
                                            "std": torch.as_tensor(train_set.std, dtype=torch.float32)}}
    if latent_stats is not None:
        extra_files["latent_stats.safetensors"] = {"latent_mean": latent_stats[0], "latent_std": latent_stats[1]}
    return TrainTask(
        model=denoiser, model_type="denoiser", model_config=model_config, objective=DenoiserObjective(denoiser),
        train_set=train_set, val_set=val_set, collate=partial(collate_motion_text, trim=False), prepare=prepare,
        meta=meta, extra_config={"kind": "denoiser", **meta, "data": str(Path(data_dir).resolve()), "numerics": numerics},
        lengths=train_set.lengths, extra_files=extra_files, split=split_denoiser_inputs,
    )


def split_denoiser_inputs(inputs: dict[str, Any], parts: int) -> list[dict[str, Any]]:
    """Cut one batch's objective inputs into ``parts`` micro-batches of similar length.

    The items are sorted by valid latent frames, cut into ``parts`` groups and each group is trimmed
    to its own longest item; ``denom`` (the whole batch's normaliser) is kept, so the micro-batches'
    losses sum to the batch's loss and their gradients to its gradient (the key-padding masks make
    each item's prediction independent of the frames trimmed away). The batch's composition, and so
    the learning per step, is that of the unsplit batch; only fewer padded frames are computed.

    Parameters
    ----------
    inputs : dict
        :func:`prepare_denoiser_batch`'s output: ``noisy``/``target`` ``(B, N', P, Dz)``, ``timesteps``
        ``(B,)``, ``text`` ``(B, W, C)``, ``text_mask`` ``(B, W)``, ``frame_mask`` ``(B, N')``, ``denom`` ``()``.
    parts : int
        Micro-batches wanted (fewer when the batch has fewer items).
    """
    frames = inputs["frame_mask"].sum(dim=1)                                   # (B,)
    order = torch.argsort(frames, stable=True)
    out = []
    for idx in torch.tensor_split(order, min(parts, len(order))):
        n = max(int(frames[idx].max()), 1)
        out.append({"noisy": inputs["noisy"][idx, :n], "timesteps": inputs["timesteps"][idx],
                    "text": inputs["text"][idx], "text_mask": inputs["text_mask"][idx],
                    "frame_mask": inputs["frame_mask"][idx, :n], "target": inputs["target"][idx, :n],
                    "denom": inputs["denom"]})
    return out


def denoiser_latent_stats(vae: nn.Module, dataset: Any, batch: int = 64) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean and std ``(P, Dz)`` of the sampled training latents ``z = mu + sigma * eps`` over every valid
    latent frame of every clip of ``dataset`` (each clip encoded whole, up to its max length, once).

    ``std^2 = var(mu) + mean(sigma^2)``: the spread of the latents the diffusion is trained on, as
    latent diffusion models scale theirs (Rombach et al. 2022, sec. 4.3: "rescale the latent"); per part
    and channel because the seven parts' latents need not share a scale. Deterministic for a VAE and a
    corpus (no sampling), so a resumed run recomputes the same numbers.
    """
    ds = vae.downsample
    p, dz = vae.num_parts, vae.latent_dim
    total = torch.zeros(p, dz, dtype=torch.float64)
    total_sq = torch.zeros(p, dz, dtype=torch.float64)
    total_var = torch.zeros(p, dz, dtype=torch.float64)
    count = 0
    first: dict[str, tuple[int, int]] = {}
    for mid, offset, length in dataset.crops():           # one (the first, longest) window per clip
        if mid not in first or length > first[mid][1]:
            first[mid] = (offset, length)
    with torch.no_grad():
        for mid, (offset, length) in first.items():
            clip = dataset.crop_features(mid, offset, length)         # (length, D) normalised
            n = (clip.shape[0] // ds) * ds
            if n == 0:
                continue
            enc = vae.encode(torch.as_tensor(clip[None, :n], dtype=torch.float32), sample=False)
            mu = enc.mu[0].double().reshape(-1, p, dz)
            total += mu.sum(0)
            total_sq += (mu ** 2).sum(0)
            total_var += enc.logvar[0].double().exp().reshape(-1, p, dz).sum(0)
            count += mu.shape[0]
    if count == 0:
        raise ValueError("no latent frames to measure the latent statistics on")
    mean = total / count
    var = (total_sq / count - mean ** 2).clamp_min(0) + total_var / count
    return mean.float(), var.sqrt().clamp_min(1e-6).float()


def train_denoiser(data_dir: str | os.PathLike, out_dir: str | os.PathLike, vae_path: str | os.PathLike,
                   model_config: Any = None, train_config: DenoiserTrainConfig | None = None,
                   text_encoder: Any = "minilm", resume: bool = False, *, diffusion_config: Any = None,
                   env: DistEnv | None = None, on_step: Callable[[int], None] | None = None) -> TrainResult:
    """Train a :class:`~salad_core.models.denoiser.Denoiser` on the latents of a frozen VAE.

    Parameters
    ----------
    data_dir : path
        HumanML3D-layout folder (``new_joint_vecs/``, ``texts/``, splits, ``Mean.npy``/``Std.npy``).
    out_dir : path
        Run folder (layout in :mod:`salad_core.train.common`).
    vae_path : path
        A VAE run folder (``best`` is used if present, else ``latest``) or a checkpoint stem/file.
    model_config : DenoiserConfig, optional
        Default: the paper's architecture sized to the VAE latent and the text encoder.
    train_config : DenoiserTrainConfig, optional
        Default: the official recipe.
    text_encoder : str, path or encoder
        ``"minilm"`` (default), a local CLIP folder, or an object with ``encode(prompts,
        allow_empty=True) -> TextBatch`` and ``dim``.
    resume : bool
        Continue the run in ``out_dir`` exactly where it stopped.
    diffusion_config : DiffusionConfig, optional
        Noise schedule and prediction type (default: the paper's; stored in checkpoint meta).
    env, on_step
        As in :func:`salad_core.train.common.fit`.
    """
    train_config = train_config or DenoiserTrainConfig()
    env = env or init_distributed(train_config.device)
    task = build_denoiser_task(data_dir, vae_path, model_config, train_config, env, text_encoder, diffusion_config,
                               cache_dir=Path(out_dir) / "latent_cache")
    return fit(task, out_dir, train_config, resume=resume, env=env, on_step=on_step)
