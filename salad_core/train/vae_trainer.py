"""Training of the skeleto-temporal VAE (paper §3.1, eq. 3; official ``VAETrainer``).

Each step takes a batch of normalised ``window``-frame windows (``MotionWindowDataset``),
encodes them, samples ``z = mu + eps * exp(logvar / 2)``, decodes and minimises
``L_rec + λ_pos L_pos + λ_vel L_vel + λ_kl L_kl`` (:meth:`MotionVAE.loss`).

Fine-tuning: ``VAETrainConfig.init_from`` starts from a trained VAE (weights and normalisation) and
``train_parts="decoder"`` freezes its encoder, so the posteriors a denoiser was trained on stay
bit-identical while the decoder learns new terms (e.g. ``lambda_root``).

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

from salad_core.io import load_state_into

from .common import StepContext, TrainResult, TrainTask, fit
from .config import VAETrainConfig
from .distributed import DistEnv, init_distributed

__all__ = ["VAEObjective", "train_vae", "build_vae_task", "load_init_vae", "freeze_vae_encoder", "encoder_modules",
           "ARCHITECTURE_FIELDS"]

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

    def __init__(self, vae: nn.Module, stats: tuple[torch.Tensor, torch.Tensor] | None = None,
                 freeze_encoder: bool = False) -> None:
        super().__init__()
        self.vae = vae
        self.stats = stats          # (mean, std) (D,): the bone and root terms measure de-normalised features
        self.freeze_encoder = freeze_encoder
        if freeze_encoder:
            freeze_vae_encoder(vae)

    def train(self, mode: bool = True) -> "VAEObjective":
        """As ``nn.Module.train``, but a frozen encoder stays in eval mode (no dropout): the decoder
        then learns from exactly the posteriors a denoiser trained on this encoder sees."""
        super().train(mode)
        if self.freeze_encoder:
            for part in encoder_modules(self.vae):
                part.eval()
        return self

    def forward(self, motion: torch.Tensor, eps: torch.Tensor,
                eps_latent: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """``motion (B, N, D)`` normalised windows; ``eps (B, N', P, Dz)`` standard normal noise;
        ``eps_latent`` (same shape, with ``latent_noise > 0``) the extra latent perturbation."""
        if self.freeze_encoder:
            with torch.no_grad():
                enc = self.vae.encode(motion, sample=False)
        else:
            enc = self.vae.encode(motion, sample=False)
        # reparameterisation (official forward: posterior_noise 1); posterior_noise 0 decodes the mean
        z = enc.mu + self.vae.config.posterior_noise * eps * torch.exp(0.5 * enc.logvar)
        if eps_latent is not None:
            # decoder robustness (an addition): decode latents near, not only on, the posterior
            z = z + self.vae.config.latent_noise * eps_latent
        recon = self.vae.decode(z)                           # (B, N, D)
        return self.vae.loss(motion, recon, enc.mu, enc.logvar, stats=self.stats)


def encoder_modules(vae: nn.Module) -> list[nn.Module]:
    """The encoder of a :class:`~salad_core.models.vae.MotionVAE`: joint MLPs, conv stack and the
    posterior head (everything that maps features to ``mu, logvar``)."""
    return [vae.motion_enc, vae.conv_enc, vae.dist]


def freeze_vae_encoder(vae: nn.Module) -> int:
    """Turn off gradients of the encoder's parameters (decoder fine-tuning); returns how many
    parameter tensors were frozen. The optimiser of :func:`~salad_core.train.common.fit` only takes
    parameters with ``requires_grad``, so the encoder's weights never change."""
    count = 0
    for part in encoder_modules(vae):
        for p in part.parameters():
            p.requires_grad_(False)
            count += 1
    return count


#: VAEConfig fields that define the network (must match for ``init_from``); the others are loss
#: weights and training-time regularisers a fine-tuning run may change.
ARCHITECTURE_FIELDS = ("skeleton", "kind", "latent_dim", "kernel_size", "n_layers", "n_extra_layers",
                       "activation", "norm", "pose_latent_dim", "pose_width")


def load_init_vae(path: str | os.PathLike) -> tuple[Any, dict[str, torch.Tensor], Any, Any, str]:
    """``(config, state_dict, mean, std, description)`` of the VAE that starts a fine-tuning run.

    Parameters
    ----------
    path : path
        A VAE training run (``best.*`` or else ``latest.*`` + ``mean_std.safetensors``), an exported VAE or
        pipeline folder (``vae.*`` + ``stats.safetensors``), or a checkpoint stem in one
        (:func:`salad_core.train.assemble.vae_source`).

    Raises
    ------
    FileNotFoundError
        If ``path`` is neither, or holds no normalisation statistics (the latents only mean what the
        VAE learned if motions are normalised as in its training).
    """
    from salad_core.io import load_model, load_tensors
    from salad_core.train.assemble import vae_source

    try:
        source = vae_source(path)
    except (FileNotFoundError, NotADirectoryError) as exc:
        raise FileNotFoundError(f"VAETrainConfig.init_from={str(path)!r} is neither a VAE run folder (best/latest), "
                                f"an exported VAE or pipeline folder (vae.*), nor a checkpoint stem: {exc}") from None
    stem, stats_file = source.stem, source.stats
    if not stats_file.is_file():
        raise FileNotFoundError(f"VAETrainConfig.init_from={str(path)!r} has no {stats_file.name}: the normalisation "
                                "the VAE was trained with is needed to keep its latent space")
    model, config, _ = load_model(stem)
    stats = load_tensors(stats_file)
    return config, dict(model.state_dict()), stats["mean"].numpy(), stats["std"].numpy(), f"{stem}"


def _check_same_architecture(init_config: Any, model_config: Any, path: str) -> None:
    diff = [f"{k}: {getattr(init_config, k)!r} (init_from) vs {getattr(model_config, k)!r} (model config)"
            for k in ARCHITECTURE_FIELDS if getattr(init_config, k) != getattr(model_config, k)]
    if diff:
        raise ValueError(f"VAETrainConfig.init_from={path!r} holds a VAE of another architecture; "
                         f"make the model config match it ({'; '.join(diff)})")


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
    init = None
    if train_config.init_from is not None:
        # fine-tuning: the run's weights and its normalisation (not the data's), so the latent space holds
        init = load_init_vae(train_config.init_from)
        _check_same_architecture(init[0], model_config, train_config.init_from)
        log.info("VAE initialised from %s (normalisation from it too); training %s", init[4], train_config.train_parts)
    general = train_config.general_data
    if general is None:
        stats_kw = {} if init is None else {"mean": init[2], "std": init[3]}
        train_set = MotionWindowDataset(data_dir, "train", window=train_config.window, skeleton=model_config.skeleton,
                                        **stats_kw)
        mean, std = train_set.mean, train_set.std
    else:
        # corpus + uncaptioned general motion at general_ratio, normalised with the mixture's own
        # statistics (the general clips' spread is 2-6x the corpus's)
        from salad_core.data.general_dataset import MixtureWindowDataset, general_windows, mixture_mean_std

        ratio = float(train_config.general_ratio)
        if init is None:
            mean, std = mixture_mean_std(data_dir, general, ratio, skeleton=model_config.skeleton)
        else:
            mean, std = init[2], init[3]
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
    vae = MotionVAE(model_config)
    if init is not None:
        load_state_into(vae, init[1], source=f"VAETrainConfig.init_from={train_config.init_from!r}")
    vae = vae.to(env.device)
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
    if init is not None:
        meta.update(init_from=str(Path(train_config.init_from)), train_parts=train_config.train_parts)
        extra_config["init_from"] = str(Path(train_config.init_from).resolve())
    return TrainTask(
        model=vae, model_type="salad_vae", model_config=model_config,
        objective=VAEObjective(vae, stats if (model_config.lambda_bone > 0 or model_config.lambda_root > 0
                                              or model_config.lambda_foot > 0) else None,
                               freeze_encoder=train_config.train_parts == "decoder"),
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
