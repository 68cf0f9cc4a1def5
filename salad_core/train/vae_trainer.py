"""Training of the skeleto-temporal VAE (paper §3.1, eq. 3; official ``VAETrainer``).

Each step takes a batch of normalised ``window``-frame windows (``MotionWindowDataset``),
encodes them, samples ``z = mu + eps * exp(logvar / 2)``, decodes and minimises
``L_rec + λ_pos L_pos + λ_vel L_vel + λ_kl L_kl`` (:meth:`MotionVAE.loss`).

The reparameterisation noise ``eps`` comes from the trainer's shared generator for the global
batch (see :class:`~salad_core.train.distributed.GlobalBatchRandom`), so runs are reproducible and
independent of the number of processes.
"""
from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any, Callable

import torch
from torch import nn
from torch.utils.data import default_collate

from .common import StepContext, TrainResult, TrainTask, fit
from .config import VAETrainConfig
from .distributed import DistEnv, init_distributed

__all__ = ["VAEObjective", "train_vae", "build_vae_task"]

log = logging.getLogger(__name__)


class VAEObjective(nn.Module):
    """``forward(motion, eps) -> dict(loss, rec, pos, vel, kl)`` for one batch.

    A module (not a function) so that DDP can wrap it: DDP synchronises gradients only for
    computations that run through a wrapped module's ``forward``.

    Parameters
    ----------
    vae : MotionVAE
        The model being trained.
    """

    def __init__(self, vae: nn.Module, stats: tuple[torch.Tensor, torch.Tensor] | None = None) -> None:
        super().__init__()
        self.vae = vae
        self.stats = stats          # (mean, std) (D,): the bone-length term measures de-normalised features

    def forward(self, motion: torch.Tensor, eps: torch.Tensor,
                eps_latent: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """``motion (B, N, D)`` normalised windows; ``eps (B, N', P, Dz)`` standard normal noise;
        ``eps_latent`` (same shape, with ``latent_noise > 0``) the extra latent perturbation."""
        enc = self.vae.encode(motion, sample=False)
        z = enc.mu + eps * torch.exp(0.5 * enc.logvar)      # reparameterisation (official forward)
        if eps_latent is not None:
            # decoder robustness (an addition): decode latents near, not only on, the posterior
            z = z + self.vae.config.latent_noise * eps_latent
        recon = self.vae.decode(z)                           # (B, N, D)
        return self.vae.loss(motion, recon, enc.mu, enc.logvar, stats=self.stats)


def _collate_windows(items: list[dict[str, Any]]) -> dict[str, torch.Tensor]:
    return default_collate(items)


def build_vae_task(data_dir: str | os.PathLike, model_config: Any, train_config: VAETrainConfig,
                   env: DistEnv) -> TrainTask:
    """The :class:`TrainTask` of a VAE run (model built with ``train_config.seed``)."""
    from salad_core.data.dataset import MotionWindowDataset
    from salad_core.models.vae import MotionVAE, VAEConfig

    if model_config is None:
        model_config = VAEConfig()
    if not isinstance(model_config, VAEConfig):
        raise TypeError(f"model_config must be a VAEConfig, got {type(model_config).__name__}")
    if train_config.window % model_config.downsample:
        raise ValueError(f"VAETrainConfig.window={train_config.window} must be a multiple of the VAE's temporal "
                         f"down-sampling {model_config.downsample}")
    general = train_config.general_data
    if general is None:
        train_set = MotionWindowDataset(data_dir, "train", window=train_config.window, skeleton=model_config.skeleton)
        mean, std = train_set.mean, train_set.std
    else:
        # corpus + uncaptioned general motion at general_ratio, normalised with the mixture's own
        # statistics (the general clips' spread is 2-6x the corpus's)
        from salad_core.data.general_dataset import MixtureWindowDataset, general_windows, mixture_mean_std

        ratio = float(train_config.general_ratio)
        mean, std = mixture_mean_std(data_dir, general, ratio, skeleton=model_config.skeleton)
        corpus = MotionWindowDataset(data_dir, "train", window=train_config.window, skeleton=model_config.skeleton,
                                     mean=mean, std=std)
        extra = general_windows(general, "train", window=train_config.window, mean=mean, std=std,
                                skeleton=model_config.skeleton)
        train_set = MixtureWindowDataset(corpus, extra, ratio=ratio, seed=train_config.seed)
        log.info("VAE data: %d corpus and %d general windows, general share %.2f per epoch (%d items)",
                 len(corpus), len(extra), ratio, len(train_set))
    try:
        # validation on the captioned corpus (what the denoiser's latents come from)
        val_set = MotionWindowDataset(data_dir, "val", window=train_config.window, skeleton=model_config.skeleton,
                                      mean=mean, std=std)
    except (FileNotFoundError, ValueError) as exc:
        log.warning("no validation windows (%s)", exc)
        val_set = None

    torch.manual_seed(train_config.seed)  # same initial weights on every rank and every run
    vae = MotionVAE(model_config).to(env.device)
    latent_shape = (train_config.window // vae.downsample, vae.num_parts, vae.latent_dim)

    noisy = model_config.latent_noise > 0

    def prepare(batch: dict[str, torch.Tensor], ctx: StepContext) -> dict[str, torch.Tensor]:
        motion = batch["motion"].to(ctx.env.device, non_blocking=True)
        out = {"motion": motion, "eps": ctx.rand.randn(motion.shape[0], latent_shape)}
        if noisy:
            out["eps_latent"] = ctx.rand.randn(motion.shape[0], latent_shape)
        return out

    stats = (torch.as_tensor(mean, dtype=torch.float32), torch.as_tensor(std, dtype=torch.float32))
    meta = {"data": str(Path(data_dir)), "window": train_config.window}
    extra_config = {"kind": "vae", "data": str(Path(data_dir).resolve())}
    if general is not None:
        meta.update(general_data=str(Path(general)), general_ratio=float(train_config.general_ratio))
        extra_config["general_data"] = str(Path(general).resolve())
    return TrainTask(
        model=vae, model_type="salad_vae", model_config=model_config,
        objective=VAEObjective(vae, stats if model_config.lambda_bone > 0 else None),
        train_set=train_set, val_set=val_set, collate=_collate_windows, prepare=prepare,
        meta=meta, extra_config=extra_config,
        extra_files={"mean_std.safetensors": {"mean": stats[0], "std": stats[1]}},
    )


def train_vae(data_dir: str | os.PathLike, out_dir: str | os.PathLike, model_config: Any = None,
              train_config: VAETrainConfig | None = None, resume: bool = False, *,
              env: DistEnv | None = None, on_step: Callable[[int], None] | None = None) -> TrainResult:
    """Train a :class:`~salad_core.models.vae.MotionVAE` on a HumanML3D-layout folder.

    Parameters
    ----------
    data_dir : path
        Folder with ``new_joint_vecs/``, ``train.txt`` (and ``val.txt``), ``Mean.npy``, ``Std.npy``.
    out_dir : path
        Run folder: ``latest.*``, ``best.*``, ``train_state.*``, ``log.jsonl``, ``config.json``
        and ``mean_std.safetensors`` (the normalisation the model was trained with).
    model_config : VAEConfig, optional
        Architecture and loss weights (default: the official HumanML3D VAE).
    train_config : VAETrainConfig, optional
        Default: the official recipe.
    resume : bool
        Continue the run in ``out_dir`` exactly where it stopped.
    env : DistEnv, optional
        Process group (default: from the ``torchrun`` environment).
    on_step : callable, optional
        Called with the step count after every optimiser step.

    Returns
    -------
    TrainResult
    """
    train_config = train_config or VAETrainConfig()
    env = env or init_distributed(train_config.device)
    task = build_vae_task(data_dir, model_config, train_config, env)
    return fit(task, out_dir, train_config, resume=resume, env=env, on_step=on_step)
