"""Trainers for the SALAD VAE and denoiser: atomic checkpoints, exact resume, ``torchrun``/DDP.

Entry points: :func:`train_vae`, :func:`train_denoiser` and their configs; the ``salad train`` command
line is :mod:`salad_core.cli.train` (also ``python -m salad_core.train``). The shared loop and the
out-folder layout are described in :mod:`salad_core.train.common`; length-bucketed batches in
:mod:`salad_core.train.batching`, the cache of frozen-VAE posteriors in :mod:`salad_core.train.latent_cache`,
and the per-part step profile (``salad bench --sections train``) in :mod:`salad_core.train.profile`.
:mod:`salad_core.train.consistency` distils a trained pipeline into a few-step student (latent consistency
distillation: ``train_consistency``, ``export_realtime``), on the same loop, datasets and latent cache.
"""
from salad_core.lazy import lazy_exports

#: The public names and the module each comes from.
_EXPORTS: dict[str, str] = {
    "LengthBucketBatchSampler": "batching", "TrainResult": "common", "TrainTask": "common", "fit": "common",
    "DenoiserTrainConfig": "config", "TrainConfig": "config", "VAETrainConfig": "config",
    "load_train_config": "config", "save_train_config": "config", "train_denoiser": "denoiser_trainer",
    "LatentCache": "latent_cache", "lr_at_step": "schedules", "train_vae": "vae_trainer",
}

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
]


# imported on first use: importing the package loads no torch (python -m tunes the process first)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
