"""Trainers for the SALAD VAE and denoiser: atomic checkpoints, exact resume, ``torchrun``/DDP.

Entry points: :func:`train_vae`, :func:`train_denoiser`, their configs, and :func:`main` (the
``salad train`` command line). The shared loop and the out-folder layout are described in
:mod:`salad_core.train.common`; length-bucketed batches in :mod:`salad_core.train.batching`, the
cache of frozen-VAE posteriors in :mod:`salad_core.train.latent_cache`, and the per-part step profile
(``salad bench --sections train``) in :mod:`salad_core.train.profile`.
"""
from .cli import main
from .batching import LengthBucketBatchSampler
from .common import TrainResult, TrainTask, fit
from .config import DenoiserTrainConfig, TrainConfig, VAETrainConfig, load_train_config, save_train_config
from .denoiser_trainer import train_denoiser
from .latent_cache import LatentCache
from .schedules import lr_at_step
from .vae_trainer import train_vae

__all__ = [
    "train_vae",
    "train_denoiser",
    "TrainConfig",
    "VAETrainConfig",
    "DenoiserTrainConfig",
    "load_train_config",
    "save_train_config",
    "TrainResult",
    "TrainTask",
    "fit",
    "LengthBucketBatchSampler",
    "LatentCache",
    "lr_at_step",
    "main",
]
