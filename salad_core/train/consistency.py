"""Latent consistency distillation: a few-step student of a trained SALAD pipeline.

Latent consistency models (Luo et al. 2023, "LCM"; MotionLCM, Dai et al. ECCV 2024, for a motion latent
diffusion model) distil the guided probability-flow ODE of a teacher into a *consistency function*
``f(x_t, t)`` that maps any point of a trajectory to the trajectory's clean end, so that 1-4 evaluations
sample a motion. Here the student is a :class:`~salad_core.models.denoiser.Denoiser` of the teacher's class
and config, initialised from the teacher (so its weight folder is an ordinary SALAD folder and attention
capture, hooks and edits see the same sites), and sampled with the ``"lcm"`` solver of
:mod:`salad_core.sampling` through :func:`~salad_core.sampling.denoise`, guidance off.

One training step, for clean latents ``z0 (B, N', P, Dz)`` (the cached VAE posteriors of the denoiser trainer,
:mod:`salad_core.train.latent_cache`, sampled ``mu + sigma eps``, in the teacher's latent space):

1. a grid index ``n ~ U{0..N-1}`` per item on the LCM grid ``t_n = (n + 1) T / N - 1`` (``N = grid_steps``,
   50: ``19, 39, ..., 999``), ``x = add_noise(z0, noise, t_n)`` (:func:`lcm_grid`);
2. the teacher's ODE step, **one DDIM step** of the classifier-free-guided prediction (eq. 9 at the fixed
   guidance of the teacher's weights, refinements included) from ``t_n`` to ``s_n = max(t_n - skip, 0)``
   (:func:`teacher_ddim_step`); guidance is baked into the student, which runs the conditional branch only;
3. the target ``f_target(x_prev, s_n)`` by the EMA copy of the student (no gradient) and the prediction
   ``f_student(x, t_n)``, each ``c_skip(t) x + c_out(t) x0(x, t)`` with ``x0`` from the model's output (for
   v-prediction ``x0 = sqrt(abar) x - sqrt(1 - abar) v``) and LCM's boundary scalings
   (:func:`boundary_scalings`: ``sigma_data = 0.5``, timestep scaling 10, so ``f(x, 0) = x`` exactly);
4. the loss: the pseudo-Huber distance ``sqrt(d^2 + c^2) - c`` (LCM's, ``c = 0.001``; or ``"l2"``,
   ``d^2``) per latent element, summed over the valid (unpadded) latent frames and divided by their count.

The EMA target (decay 0.95, LCM's) is updated once per optimiser step *before the next step's forward*
(:meth:`ConsistencyPair.update_target`), so the training loop (:func:`salad_core.train.common.fit`) needs no
hook: the trained module is the :class:`ConsistencyPair` (student, target and the step the target was last
updated at), whose state is in every checkpoint and train state, so ``--resume`` is exact. The teacher is
frozen and reloaded from its folder.

:func:`export_realtime` writes a complete weight folder: the teacher's VAE, statistics, text encoder and
vocabulary, the student denoiser, and ``pipeline.json`` with ``"solver": "lcm"``, ``"num_steps"`` and
guidance 1, which :meth:`SaladPipeline.from_pretrained <salad_core.pipeline.SaladPipeline.from_pretrained>`
samples by default.
"""
from __future__ import annotations

import copy
import json
import logging
import os
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, Callable

import torch
from torch import nn

from salad_core.io import config_from_dict, config_to_dict, load_state_into, read_checkpoint, register_model
from salad_core.models.denoiser import Denoiser, DenoiserConfig, TextContext
from salad_core.sampling import Guidance, GuidanceStep, make_scheduler

from .common import StepContext, TrainResult, TrainTask, fit
from .config import DenoiserTrainConfig
from .distributed import DistEnv, all_reduce_sum, init_distributed

__all__ = ["ConsistencyTrainConfig", "ConsistencyPair", "ConsistencyObjective", "lcm_grid", "boundary_scalings",
           "predicted_x0", "consistency_function", "ddim_step", "guided_teacher_prediction", "teacher_ddim_step",
           "consistency_distance", "prepare_consistency_batch", "build_consistency_task", "train_consistency",
           "export_realtime", "load_student", "SIGMA_DATA", "TIMESTEP_SCALING", "CONSISTENCY_LOSSES",
           "DEFAULT_SAMPLE_STEPS", "MODEL_TYPE"]

log = logging.getLogger(__name__)

#: LCM's boundary-condition constants (diffusers ``LCMScheduler``: ``sigma_data`` 0.5, ``timestep_scaling`` 10).
SIGMA_DATA = 0.5
TIMESTEP_SCALING = 10.0
#: The distances of :attr:`ConsistencyTrainConfig.loss`.
CONSISTENCY_LOSSES = ("huber", "l2")
#: Sampling steps an exported folder names when none are given.
DEFAULT_SAMPLE_STEPS = 4
#: The registered checkpoint type of a :class:`ConsistencyPair` (``latest.*`` / ``best.*`` of a run).
MODEL_TYPE = "consistency_denoiser"


@dataclass(frozen=True)
class ConsistencyTrainConfig(DenoiserTrainConfig):
    """Latent consistency distillation: the denoiser recipe's data fields, LCM's distillation settings.

    The latent space, normalisation, text encoder and diffusion schedule are the teacher's; ``latent_norm`` must
    stay False (a teacher trained with latent normalisation brings its statistics in its folder).
    """

    teacher: str | None = None                 # teacher pipeline folder (None: the shipped weights)
    guidance: float | None = None              # CFG weight w of the teacher's ODE (None: the teacher's default
                                               # guidance, with its rescale and interval)
    grid_steps: int = 50                       # N: the DDIM grid t_n = (n + 1) T / N - 1 the student is trained on
    skip: int = 20                             # k: training timesteps the teacher's DDIM step spans (t_n -> t_n - k)
    ema_decay: float = 0.95                    # the target network's EMA decay (LCM)
    loss: str = "huber"                        # "huber" (pseudo-Huber, LCM) or "l2"
    huber_c: float = 0.001                     # c of the pseudo-Huber distance sqrt(d^2 + c^2) - c
    cond_drop_prob: float = 0.0                # guidance is baked in: the student learns the prompts' guided ODE
    lr: float = 1e-4                           # fine-tuning the teacher's weights
    warmup_steps: int = 100
    milestones: tuple[int, ...] = ()
    val_every: int = 500
    micro_batches: int = 1                     # the objective is not split

    def __post_init__(self) -> None:
        super().__post_init__()

        def need(cond: bool, name: str, allowed: str) -> None:
            if not cond:
                raise ValueError(f"ConsistencyTrainConfig.{name}={getattr(self, name)!r} is invalid; {allowed}")

        need(self.teacher is None or (isinstance(self.teacher, str) and bool(self.teacher)), "teacher",
             "use a pipeline folder (str) or None (the shipped weights)")
        need(self.guidance is None or (not isinstance(self.guidance, bool) and isinstance(self.guidance, (int, float))
                                       and abs(float(self.guidance)) <= 100.0), "guidance",
             "use None (the teacher's default) or a weight in -100..100")
        need(isinstance(self.grid_steps, int) and not isinstance(self.grid_steps, bool) and self.grid_steps >= 2,
             "grid_steps", "use an integer >= 2")
        need(isinstance(self.skip, int) and not isinstance(self.skip, bool) and self.skip >= 1, "skip",
             "use an integer >= 1 (training timesteps per teacher step)")
        need(isinstance(self.ema_decay, (int, float)) and 0.0 <= float(self.ema_decay) < 1.0, "ema_decay",
             "use a float in [0, 1)")
        need(self.loss in CONSISTENCY_LOSSES, "loss", f"use one of {CONSISTENCY_LOSSES}")
        need(isinstance(self.huber_c, (int, float)) and float(self.huber_c) > 0, "huber_c", "use a positive float")
        need(not self.latent_norm, "latent_norm", "the latent space is the teacher's: leave it False")


# ====================================================================== the consistency function
def lcm_grid(num_train_timesteps: int, grid_steps: int) -> torch.Tensor:
    """The DDIM grid of the distillation, ``(N,)`` long ascending: ``t_n = (n + 1) T / N - 1`` (``19, 39, ..., 999``
    for ``T = 1000, N = 50``), the grid diffusers' ``LCMScheduler`` samples on (``original_inference_steps = N``)."""
    if num_train_timesteps % grid_steps:
        raise ValueError(f"grid_steps={grid_steps} must divide the {num_train_timesteps} training timesteps")
    return torch.arange(1, grid_steps + 1, dtype=torch.long) * (num_train_timesteps // grid_steps) - 1


def boundary_scalings(timesteps: torch.Tensor, sigma_data: float = SIGMA_DATA,
                      timestep_scaling: float = TIMESTEP_SCALING) -> tuple[torch.Tensor, torch.Tensor]:
    """LCM's ``(c_skip, c_out)`` at integer ``timesteps (B,)``, each ``(B,)`` float64:
    ``c_skip = sd^2 / ((s t)^2 + sd^2)``, ``c_out = s t / sqrt((s t)^2 + sd^2)`` (``sd = sigma_data``,
    ``s = timestep_scaling``): ``(1, 0)`` at ``t = 0``, so ``f(x, 0) = x``, and near ``(0, 1)`` from ``t = 19`` on."""
    scaled = timesteps.to(torch.float64) * float(timestep_scaling)
    denom = scaled ** 2 + sigma_data ** 2
    return sigma_data ** 2 / denom, scaled / denom.sqrt()


def _per_sample(values: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """``values (B,)`` viewed ``(B, 1, ..., 1)`` in the dtype and device of ``like (B, ...)``."""
    return values.to(device=like.device, dtype=like.dtype).view(-1, *(1,) * (like.dim() - 1))


def _alpha_bar(alphas_cumprod: torch.Tensor, timesteps: torch.Tensor) -> torch.Tensor:
    """``alphas_cumprod[t]`` ``(B,)`` float64 for integer ``timesteps (B,)``."""
    table = alphas_cumprod.to(torch.float64)
    return table[timesteps.long().to(table.device)].to(timesteps.device)


def predicted_x0(x: torch.Tensor, pred: torch.Tensor, alpha_bar: torch.Tensor, prediction_type: str) -> torch.Tensor:
    """The clean-sample estimate ``(B, ...)`` of a model output ``pred (B, ...)`` at noisy ``x (B, ...)`` with
    ``alpha_bar (B,)``: v-prediction ``sqrt(a) x - sqrt(1 - a) v``, epsilon ``(x - sqrt(1 - a) eps) / sqrt(a)``,
    sample ``pred``."""
    sa, sb = _per_sample(alpha_bar.sqrt(), x), _per_sample((1 - alpha_bar).clamp_min(0).sqrt(), x)
    if prediction_type == "v_prediction":
        return sa * x - sb * pred
    if prediction_type == "epsilon":
        return (x - sb * pred) / sa
    if prediction_type == "sample":
        return pred
    raise ValueError(f"prediction_type {prediction_type!r} is not one of v_prediction, epsilon, sample")


def _predicted_eps(x: torch.Tensor, pred: torch.Tensor, alpha_bar: torch.Tensor, prediction_type: str) -> torch.Tensor:
    """The noise estimate ``(B, ...)`` of a model output (as DDIM derives it for each prediction type)."""
    sa, sb = _per_sample(alpha_bar.sqrt(), x), _per_sample((1 - alpha_bar).clamp_min(0).sqrt(), x)
    if prediction_type == "v_prediction":
        return sa * pred + sb * x
    if prediction_type == "epsilon":
        return pred
    return (x - sa * pred) / sb


def consistency_function(pred: torch.Tensor, x: torch.Tensor, timesteps: torch.Tensor, alphas_cumprod: torch.Tensor,
                         prediction_type: str = "v_prediction") -> torch.Tensor:
    """``f(x, t) = c_skip(t) x + c_out(t) x0(x, t)`` ``(B, N', P, Dz)`` for a model output ``pred`` at noisy
    latents ``x`` (both ``(B, N', P, Dz)``) and integer ``timesteps (B,)`` (:func:`boundary_scalings`); what
    ``LCMScheduler.step`` returns as ``denoised``."""
    c_skip, c_out = boundary_scalings(timesteps)
    x0 = predicted_x0(x, pred, _alpha_bar(alphas_cumprod, timesteps), prediction_type)
    return _per_sample(c_skip, x) * x + _per_sample(c_out, x) * x0


def ddim_step(x: torch.Tensor, pred: torch.Tensor, timesteps: torch.Tensor, prev_timesteps: torch.Tensor,
              alphas_cumprod: torch.Tensor, prediction_type: str = "v_prediction") -> torch.Tensor:
    """One deterministic DDIM step (eta 0) per item from ``timesteps (B,)`` to ``prev_timesteps (B,)`` (integers,
    ``prev <= t``): ``sqrt(a_prev) x0 + sqrt(1 - a_prev) eps`` with ``x0, eps`` from ``pred``; ``(B, ...)`` like
    ``x``. With ``prev = t`` it returns ``x`` (up to rounding)."""
    a = _alpha_bar(alphas_cumprod, timesteps)
    a_prev = _alpha_bar(alphas_cumprod, prev_timesteps)
    x0 = predicted_x0(x, pred, a, prediction_type)
    eps = _predicted_eps(x, pred, a, prediction_type)
    return _per_sample(a_prev.sqrt(), x) * x0 + _per_sample((1 - a_prev).sqrt(), x) * eps


def guided_teacher_prediction(teacher: nn.Module, x: torch.Tensor, timesteps: torch.Tensor, cond: TextContext,
                              uncond: TextContext, frame_mask: torch.Tensor | None, guidance: Guidance,
                              alphas_cumprod: torch.Tensor, prediction_type: str = "v_prediction") -> torch.Tensor:
    """The teacher's classifier-free-guided output ``(B, N', P, Dz)`` at ``x (B, N', P, Dz)``, per-item integer
    ``timesteps (B,)``: both branches in one ``2B`` forward (unconditional rows first), combined by
    :meth:`Guidance.combine` (eq. 9, then its refinements); items outside a guidance interval take the
    conditional output. ``cond`` has batch ``B``, ``uncond`` ``B`` or 1; ``frame_mask (B, N')`` bool."""
    b = x.shape[0]
    num_train = len(alphas_cumprod)
    if not guidance.cfg:
        return teacher(x, timesteps, frame_mask=frame_mask, text_context=cond)
    both = TextContext.concat([uncond.repeat(b), cond])
    masks = None if frame_mask is None else torch.cat([frame_mask, frame_mask])
    out_u, out_c = teacher(torch.cat([x, x]), torch.cat([timesteps, timesteps]), frame_mask=masks,
                           text_context=both).chunk(2)
    keep = None if frame_mask is None else frame_mask[:, :, None, None].to(out_c.dtype)
    active = torch.tensor([guidance.active(float(t), num_train) for t in timesteps.tolist()], device=x.device)
    if not guidance.on_clean_sample:
        guided = guidance.combine(out_u, out_c, keep=keep)
    else:      # projection and threshold act on each item's own clean-sample estimate
        a = _alpha_bar(alphas_cumprod, timesteps).tolist()
        guided = torch.cat([guidance.combine(out_u[i:i + 1], out_c[i:i + 1], None if keep is None else keep[i:i + 1],
                                             step=GuidanceStep(x[i:i + 1], a[i], prediction_type)) for i in range(b)])
    return torch.where(active.view(-1, 1, 1, 1), guided, out_c)


def teacher_ddim_step(teacher: nn.Module, x: torch.Tensor, timesteps: torch.Tensor, prev_timesteps: torch.Tensor,
                      cond: TextContext, uncond: TextContext, frame_mask: torch.Tensor | None, guidance: Guidance,
                      alphas_cumprod: torch.Tensor, prediction_type: str = "v_prediction") -> torch.Tensor:
    """The teacher's ODE solver: one DDIM step ``(B, N', P, Dz)`` of the guided prediction
    (:func:`guided_teacher_prediction`) from ``timesteps (B,)`` to ``prev_timesteps (B,)``, padded frames zeroed as
    :func:`~salad_core.sampling.denoise` re-masks them."""
    pred = guided_teacher_prediction(teacher, x, timesteps, cond, uncond, frame_mask, guidance, alphas_cumprod,
                                     prediction_type)
    out = ddim_step(x, pred, timesteps, prev_timesteps, alphas_cumprod, prediction_type)
    return out if frame_mask is None else out * frame_mask[:, :, None, None].to(out.dtype)


def consistency_distance(a: torch.Tensor, b: torch.Tensor, frame_mask: torch.Tensor, loss: str = "huber",
                         huber_c: float = 0.001) -> torch.Tensor:
    """Summed distance ``()`` between ``a`` and ``b`` ``(B, N', P, Dz)`` over the valid frames of
    ``frame_mask (B, N')``: per element ``sqrt(d^2 + c^2) - c`` (``"huber"``) or ``d^2`` (``"l2"``)."""
    if loss not in CONSISTENCY_LOSSES:
        raise ValueError(f"loss {loss!r} is not one of {CONSISTENCY_LOSSES}")
    d2 = (a.float() - b.float()) ** 2
    per = (d2 + huber_c ** 2).sqrt() - huber_c if loss == "huber" else d2
    return (per * frame_mask[:, :, None, None].to(per.dtype)).sum()


# ============================================================================ the trained module
class ConsistencyPair(nn.Module):
    """The trained module of a distillation run: the ``student`` (optimised), its EMA ``target`` (no gradients)
    and ``ema_step``, the optimiser step the target last caught up with (a buffer, so checkpoints and resume keep
    it). Both are :class:`~salad_core.models.denoiser.Denoiser` of one config."""

    def __init__(self, student: Denoiser, target: Denoiser | None = None) -> None:
        super().__init__()
        self.student = student
        self.target = copy.deepcopy(student) if target is None else target
        if self.target.config != student.config:
            raise ValueError("the EMA target must have the student's config")
        for p in self.target.parameters():
            p.requires_grad_(False)
        self.register_buffer("ema_step", torch.zeros((), dtype=torch.long))

    @property
    def config(self) -> DenoiserConfig:
        return self.student.config

    @torch.no_grad()
    def update_target(self, step: int, decay: float) -> bool:
        """``target <- decay * target + (1 - decay) * student`` once, if ``step`` (optimiser steps completed) is past
        :attr:`ema_step`; returns whether it updated. Called at the start of each training forward, so the target
        has seen every completed step by the time it is read, and a resumed run repeats no update."""
        if int(step) <= int(self.ema_step):
            return False
        targets = list(self.target.parameters())
        for t, s in zip(targets, self.student.parameters()):
            t.lerp_(s.detach(), 1.0 - float(decay))
        torch.autograd.graph.increment_version(targets)       # the no-grad caches see the new weights
        self.ema_step.fill_(int(step))
        return True

    def train(self, mode: bool = True) -> "ConsistencyPair":
        super().train(mode)
        self.target.eval()                                      # the target never drops out
        return self


class ConsistencyObjective(nn.Module):
    """``forward(...) -> {"loss"}``: the consistency distillation loss of one batch (steps 2-4 of the module
    docstring). Holds the frozen ``teacher`` and the :class:`ConsistencyPair`; the teacher and the target stay in
    eval mode whatever :meth:`train` is told."""

    def __init__(self, teacher: Denoiser, pair: ConsistencyPair, guidance: Guidance, alphas_cumprod: torch.Tensor,
                 prediction_type: str, *, ema_decay: float = 0.95, loss: str = "huber", huber_c: float = 0.001) -> None:
        super().__init__()
        self.teacher = teacher.eval()
        for p in self.teacher.parameters():
            p.requires_grad_(False)
        self.pair = pair
        self.guidance = guidance
        self.register_buffer("alphas_cumprod", alphas_cumprod.detach().to(torch.float64).clone(), persistent=False)
        self.prediction_type = prediction_type
        self.ema_decay = float(ema_decay)
        self.loss = loss
        self.huber_c = float(huber_c)

    def train(self, mode: bool = True) -> "ConsistencyObjective":
        super().train(mode)
        self.teacher.eval()
        self.pair.target.eval()
        return self

    def forward(self, noisy: torch.Tensor, timesteps: torch.Tensor, target_timesteps: torch.Tensor, text: torch.Tensor,
                text_mask: torch.Tensor, null_text: torch.Tensor, null_mask: torch.Tensor, frame_mask: torch.Tensor,
                denom: torch.Tensor, step: int | None = None) -> dict[str, torch.Tensor]:
        """Loss for one batch.

        Parameters
        ----------
        noisy : Tensor ``(B, N', P, Dz)``
            ``x`` at ``timesteps``.
        timesteps, target_timesteps : Tensor ``(B,)`` long
            ``t_n`` (grid) and ``s_n`` (the teacher's step's end, ``<= t_n``).
        text : Tensor ``(B, W, C)``; text_mask : Tensor ``(B, W)`` bool
        null_text : Tensor ``(1, W0, C)``; null_mask : Tensor ``(1, W0)`` bool
            The null text "" (the teacher's unconditional branch).
        frame_mask : Tensor ``(B, N')`` bool (True = valid latent frame)
        denom : Tensor ``()``
            Valid elements the summed distance is divided by.
        step : int, optional
            Optimiser steps completed; in training the EMA target first catches up with it.
        """
        if self.training and step is not None:
            self.pair.update_target(step, self.ema_decay)
        acp, kind = self.alphas_cumprod, self.prediction_type
        with torch.no_grad():
            cond = TextContext(text, text_mask)
            x_prev = teacher_ddim_step(self.teacher, noisy, timesteps, target_timesteps, cond,
                                       TextContext(null_text, null_mask), frame_mask, self.guidance, acp, kind)
            out_target = self.pair.target(x_prev, target_timesteps, frame_mask=frame_mask,
                                          text_context=TextContext(text, text_mask))
            f_target = consistency_function(out_target, x_prev, target_timesteps, acp, kind)
        out = self.pair.student(noisy, timesteps, text, text_mask, frame_mask)
        f_student = consistency_function(out, noisy, timesteps, acp, kind)
        dist = consistency_distance(f_student, f_target, frame_mask, self.loss, self.huber_c)
        return {"loss": dist / denom}


def _build_pair(config: DenoiserConfig) -> ConsistencyPair:
    return ConsistencyPair(Denoiser(config))


register_model(MODEL_TYPE, DenoiserConfig, _build_pair)


# ================================================================================== batches
def _clean_latents(batch: dict[str, Any], eps: torch.Tensor, frame_mask: torch.Tensor, *, vae: nn.Module,
                   config: DenoiserTrainConfig, latents: Any, latent_stats: tuple[torch.Tensor, torch.Tensor] | None
                   ) -> torch.Tensor:
    """``z0 = mu + sigma eps`` ``(B, N', P, Dz)`` of a batch (cached posteriors, else the frozen VAE), in the
    teacher's latent space, zero on padded frames (as the denoiser trainer's
    :func:`~salad_core.train.denoiser_trainer.prepare_denoiser_batch`)."""
    dev = frame_mask.device
    n_lat = frame_mask.shape[1]
    length = batch["length"].to(dev)
    if latents is not None:
        keys = list(zip(batch["motion_id"], (int(o) for o in batch["offset"]), length.tolist()))
        mu, logvar = (t.to(dev) for t in latents.lookup(keys, n_lat))
    else:
        motion = batch["motion"].to(dev)
        if not config.vae_pad_to_max:
            motion = motion[:, : n_lat * vae.downsample]
        enc = vae.encode(motion, sample=False)
        mu, logvar = enc.mu[:, :n_lat], enc.logvar[:, :n_lat]
    z = mu + eps * torch.exp(0.5 * logvar)
    if latent_stats is not None:
        z = (z - latent_stats[0].to(z)) / latent_stats[1].to(z)
    return z * frame_mask[:, :, None, None].to(z.dtype)


def prepare_consistency_batch(batch: dict[str, Any], ctx: StepContext, *, vae: nn.Module, text: Any, scheduler: Any,
                              config: ConsistencyTrainConfig, latent_shape: tuple[int, int, int], grid: torch.Tensor,
                              latents: Any = None, latent_stats: tuple[torch.Tensor, torch.Tensor] | None = None
                              ) -> dict[str, Any]:
    """The :class:`ConsistencyObjective` inputs of a batch (step 1 of the module docstring).

    ``batch`` has ``motion (B, N, D)`` (normalised), ``length (B,)``, ``caption`` (and, with ``latents``,
    ``motion_id`` and ``offset``); ``latent_shape`` is ``(N', P, Dz)`` at the padded length; ``grid (N,)`` the
    timesteps of :func:`lcm_grid`. Every draw comes from ``ctx.rand`` (the global batch), in a fixed order, so the
    inputs depend only on the batch and the step.
    """
    env, rand, dev = ctx.env, ctx.rand, ctx.env.device
    length = batch["length"].to(dev)
    b = length.shape[0]
    lat_len = length // vae.downsample
    n_lat = int(lat_len.max())
    frame_mask = torch.arange(n_lat, device=dev)[None, :] < lat_len[:, None]          # (B, N')
    m = frame_mask[:, :, None, None].to(torch.float32)

    eps = rand.randn(b, latent_shape)[:, :n_lat]                       # VAE reparameterisation
    index = rand.randint(b, len(grid))                                 # n ~ U{0..N-1}
    noise = rand.randn(b, latent_shape)[:, :n_lat] * m
    drop = rand.rand(b) < config.cond_drop_prob
    if not ctx.train and not config.val_cond_drop:
        drop = torch.zeros_like(drop)
    timesteps = grid.to(dev)[index]
    target_timesteps = (timesteps - config.skip).clamp_min(0)
    with torch.no_grad():
        z = _clean_latents(batch, eps, frame_mask, vae=vae, config=config, latents=latents, latent_stats=latent_stats)
        noisy = scheduler.add_noise(z, noise, timesteps)
        captions = ["" if d else c for d, c in zip(drop.tolist(), batch["caption"])]
        text_feats, text_mask = text.encode(captions)                  # (B, W, C), (B, W)
        null_feats, null_mask = text.encode([""])                      # (1, W0, C), (1, W0)
    count = frame_mask.sum().to(torch.float64) * (latent_shape[1] * latent_shape[2])
    if ctx.train and env.distributed:
        count = all_reduce_sum(count, env) / env.world_size
    return {"noisy": noisy, "timesteps": timesteps, "target_timesteps": target_timesteps,
            "text": text_feats.to(dev), "text_mask": text_mask.to(dev), "null_text": null_feats.to(dev),
            "null_mask": null_mask.to(dev), "frame_mask": frame_mask, "denom": count.clamp_min(1.0).float(),
            "step": ctx.step if ctx.train else None}


# ===================================================================================== the task
def _teacher_pipeline(teacher: str | os.PathLike | None, text_encoder: Any):
    """The teacher :class:`~salad_core.pipeline.SaladPipeline` (``None``: the shipped weights)."""
    from salad_core.pipeline import SaladPipeline

    return SaladPipeline.from_pretrained(teacher, text_encoder=text_encoder)


def _resolve_teacher_guidance(pipe: Any, weight: float | None) -> Guidance:
    """The fixed guidance of the teacher's ODE: the teacher's default, with ``weight`` as its scale when given."""
    from salad_core.sampling import resolve_guidance

    guidance = resolve_guidance(pipe.guidance, weight)
    if guidance.projection is not None and guidance.momentum != 0:
        raise ValueError(f"the teacher's guidance {guidance.describe()} uses APG momentum, which averages over a "
                         "sampling loop; a single distillation step has none: give a guidance without momentum")
    return guidance


def build_consistency_task(data_dir: str | os.PathLike, config: ConsistencyTrainConfig, env: DistEnv,
                           text_encoder: Any = None, *, cache_dir: str | os.PathLike | None = None) -> TrainTask:
    """The :class:`TrainTask` of a distillation run: the teacher of ``config.teacher`` (its VAE, statistics, text
    encoder unless ``text_encoder`` is given, diffusion schedule and guidance), the student and target initialised
    from its denoiser, and the denoiser trainer's datasets and latent cache (``cache_dir`` as in
    :func:`~salad_core.train.denoiser_trainer.build_denoiser_task`)."""
    from salad_core.data.dataset import MotionTextDataset, collate_motion_text

    from .denoiser_trainer import CaptionFeatureCache, cached_latents

    pipe = _teacher_pipeline(config.teacher, text_encoder)
    vae = pipe.vae.to(env.device).eval()
    for p in vae.parameters():
        p.requires_grad_(False)
    teacher = pipe.denoiser.to(env.device)
    guidance = _resolve_teacher_guidance(pipe, config.guidance)
    scheduler = make_scheduler(pipe.diffusion, "ddim")
    grid = lcm_grid(pipe.diffusion.num_train_timesteps, config.grid_steps)
    if config.max_length % vae.downsample:
        raise ValueError(f"ConsistencyTrainConfig.max_length={config.max_length} must be a multiple of the VAE's "
                         f"temporal down-sampling {vae.downsample}")
    skeleton = vae.config.skeleton
    train_set = MotionTextDataset(data_dir, "train", skeleton=skeleton, max_length=config.max_length,
                                  unit_length=vae.downsample, mean=pipe.mean, std=pipe.std, random_crop=True,
                                  seed=config.seed)
    try:
        val_set = MotionTextDataset(data_dir, "val", skeleton=skeleton, max_length=config.max_length,
                                    unit_length=vae.downsample, mean=pipe.mean, std=pipe.std, random_crop=False)
    except (FileNotFoundError, ValueError) as exc:
        log.warning("no validation items (%s)", exc)
        val_set = None

    student = copy.deepcopy(teacher).train()
    for p in student.parameters():
        p.requires_grad_(True)
    pair = ConsistencyPair(student)
    objective = ConsistencyObjective(teacher, pair, guidance, scheduler.alphas_cumprod, pipe.diffusion.prediction_type,
                                     ema_decay=config.ema_decay, loss=config.loss, huber_c=config.huber_c)
    text_cache = CaptionFeatureCache(pipe.text_encoder, config.text_cache_size)
    captions = [line.caption for ds in (train_set, val_set) if ds is not None for line in ds.all_captions()]
    text_cache.prefill([*captions, ""])
    latents = cached_latents(vae, train_set, val_set, config, cache_dir, env)
    latent_shape = (config.max_length // vae.downsample, vae.num_parts, vae.latent_dim)
    prepare = partial(prepare_consistency_batch, vae=vae, text=text_cache, scheduler=scheduler, config=config,
                      latent_shape=latent_shape, grid=grid, latents=latents, latent_stats=pipe.latent_stats)
    encoder_name = getattr(pipe.text_encoder, "source", type(pipe.text_encoder).__name__)
    meta = {"diffusion": config_to_dict(pipe.diffusion), "teacher": str(pipe.source), "text_encoder": str(encoder_name),
            "guidance": guidance.to_json_dict(), "grid_steps": config.grid_steps, "skip": config.skip,
            "data": str(Path(data_dir))}
    numerics = {"latents": "cached posteriors, eps drawn per step" if latents is not None else "encoded at every step",
                "loss": (f"pseudo-Huber (c {config.huber_c:g})" if config.loss == "huber" else "squared error")
                + " over valid latent elements, divided by their count",
                "teacher_solver": f"one DDIM step of {config.skip} timesteps at guidance {guidance.describe()}",
                "target": f"EMA of the student, decay {config.ema_decay:g}"}
    extra_files = {"mean_std.safetensors": {"mean": torch.as_tensor(pipe.mean), "std": torch.as_tensor(pipe.std)}}
    return TrainTask(
        model=pair, model_type=MODEL_TYPE, model_config=teacher.config, objective=objective, train_set=train_set,
        val_set=val_set, collate=partial(collate_motion_text, trim=False), prepare=prepare, meta=meta,
        extra_config={"kind": "consistency", **meta, "data": str(Path(data_dir).resolve()), "numerics": numerics},
        lengths=train_set.lengths, extra_files=extra_files)


def train_consistency(data_dir: str | os.PathLike, out_dir: str | os.PathLike,
                      train_config: ConsistencyTrainConfig | None = None, text_encoder: Any = None,
                      resume: bool = False, *, env: DistEnv | None = None,
                      on_step: Callable[[int], None] | None = None) -> TrainResult:
    """Distil the teacher of ``train_config.teacher`` into a few-step student on the corpus ``data_dir``.

    Parameters
    ----------
    data_dir : path
        HumanML3D-layout folder (the corpus the teacher was trained on).
    out_dir : path
        Run folder (layout in :mod:`salad_core.train.common`; its ``latest``/``best`` hold the
        :class:`ConsistencyPair`); :func:`export_realtime` turns it into a weight folder.
    train_config : ConsistencyTrainConfig, optional
    text_encoder : optional
        An already loaded encoder instead of the one the teacher's folder names.
    resume, env, on_step
        As in :func:`salad_core.train.common.fit`.
    """
    train_config = train_config or ConsistencyTrainConfig()
    env = env or init_distributed(train_config.device)
    task = build_consistency_task(data_dir, train_config, env, text_encoder, cache_dir=Path(out_dir) / "latent_cache")
    return fit(task, out_dir, train_config, resume=resume, env=env, on_step=on_step)


# =================================================================================== export
def load_student(run: str | os.PathLike, which: str = "student", checkpoint: str | None = None) -> Denoiser:
    """The ``"student"`` or its EMA ``"target"`` of a distillation run (``checkpoint``: ``"best"``, ``"latest"``,
    default ``best`` when validated, else ``latest``), in eval mode. The target is brought up to the checkpoint's
    step first (its last EMA update is otherwise applied at the next step's forward)."""
    from .assemble import run_checkpoint

    if which not in ("student", "target"):
        raise ValueError(f"which={which!r}: choose 'student' or 'target'")
    run = Path(run)
    stem = run / checkpoint if checkpoint is not None else run_checkpoint(run)
    doc, state = read_checkpoint(stem)
    if doc["type"] != MODEL_TYPE:
        raise ValueError(f"{stem} holds a {doc['type']!r}, not a consistency distillation run ({MODEL_TYPE!r})")
    config = config_from_dict(DenoiserConfig, doc["config"], source=f"{stem}.json: 'config'")
    pair = _build_pair(config)
    load_state_into(pair, state, source=str(stem))
    step = doc.get("meta", {}).get("step")
    if which == "target" and step is not None:
        decay = json.loads((run / "config.json").read_text())["train"]["ema_decay"]
        pair.update_target(int(step), decay)
    return getattr(pair, which).eval()


def export_realtime(run: str | os.PathLike, out: str | os.PathLike, *, teacher: str | os.PathLike | None = None,
                    num_steps: int = DEFAULT_SAMPLE_STEPS, which: str = "student", checkpoint: str | None = None,
                    text_encoder: Any = None, dtype: torch.dtype | None = torch.float16) -> Path:
    """Write a complete SALAD weight folder of a distillation run: the teacher's VAE, statistics, text encoder
    entry and vocabulary, the run's student (``which="target"``: its EMA target) as ``denoiser.*``, and
    ``pipeline.json`` with ``"solver": "lcm"``, ``"num_steps": num_steps`` and guidance 1 (baked in), plus
    ``runs.json`` with the run's record. ``teacher`` defaults to the folder the run recorded; ``dtype`` is the
    storage dtype (float16 as the shipped weights; None keeps float32)."""
    from salad_core.io import atomic_write_text
    from salad_core.pipeline import SaladPipeline

    from .assemble import _run_record

    run, out = Path(run), Path(out)
    record = json.loads((run / "config.json").read_text())
    task = record.get("task", {})
    if task.get("kind") != "consistency":
        raise ValueError(f"{run} is not a consistency distillation run (its config.json task kind is "
                         f"{task.get('kind')!r})")
    teacher_pipe = _teacher_pipeline(teacher if teacher is not None else task.get("teacher"), text_encoder)
    lcm_grid_steps = make_scheduler(teacher_pipe.diffusion, "lcm").config.original_inference_steps
    if int(task.get("grid_steps", 0)) != lcm_grid_steps:
        raise ValueError(f"{run} was distilled on a {task.get('grid_steps')}-step grid; the 'lcm' solver samples on "
                         f"its {lcm_grid_steps}-step grid: distil with grid_steps={lcm_grid_steps}")
    student = load_student(run, which, checkpoint)
    if student.config != teacher_pipe.denoiser.config:
        raise ValueError(f"the run's denoiser config differs from the teacher's ({teacher_pipe.source}): export with "
                         "the teacher the run was distilled from")
    pipe = SaladPipeline(teacher_pipe.vae, student, teacher_pipe.text_encoder, teacher_pipe.mean, teacher_pipe.std,
                         diffusion=teacher_pipe.diffusion, solver="lcm", guidance=Guidance(1.0),
                         recovery=teacher_pipe.recovery, latent_stats=teacher_pipe.latent_stats, num_steps=num_steps)
    pipe.vocabulary, pipe.vocabulary_source = teacher_pipe.vocabulary, teacher_pipe.vocabulary_source
    meta = {"distilled_from": str(teacher_pipe.source), "distillation_run": str(run), "which": which}
    pipe.save_pretrained(out, dtype=dtype, meta=meta)
    runs_path = Path(str(teacher_pipe.source)) / "runs.json"
    runs = json.loads(runs_path.read_text()) if runs_path.is_file() else {}
    runs["consistency"] = _run_record(run)
    atomic_write_text(out / "runs.json", json.dumps(runs, indent=2) + "\n")
    return out
