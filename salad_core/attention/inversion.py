"""DDIM inversion of given motions, faithful under classifier-free guidance (editing real motions).

The paper leaves editing motions it did not generate to future work (SALAD §5: "integrating
diffusion inversion methods could enable text-driven editing of real motion sequences") and the
official code cannot do it. Here a motion is encoded by the VAE (posterior mean) to clean latents
``z_0`` and run *backwards* through the deterministic DDIM sampler to noise ``z_T`` under its
source prompt; editing then starts both branches of Algorithm 1 from that noise.

One DDIM step (eta = 0) from level ``b`` (timestep ``t_b``, ``abar_b``) to the next level ``a`` is
affine in the current latent for a fixed model prediction (:func:`ddim_step_coefficients`)::

    z_a = alpha * z_b + beta * pred(z_b, t_b)

Inverting a step means solving this for ``z_b`` given ``z_a``; ``pred(z_b)`` is unknown.

* ``"ddim"`` (plain inversion, Song et al.): use the prediction at the point already known,
  ``z_b = (z_a - beta * pred(z_a, t_b)) / alpha``, with the conditional model only (w = 1).
  Sampling back with guidance w = 7.5 drifts from this trajectory.
* ``"fixed_point"``: iterate ``z_b <- (z_a - beta * pred_w(z_b, t_b)) / alpha`` with the *guided*
  prediction, keeping the iterate with the smallest step residual
  ``|alpha z_b + beta pred_w(z_b) - z_a|`` (the first iterate is plain DDIM inversion under
  guidance). Cost: ``iterations + 1`` guided forwards per step. It converges where the guided
  model is contractive enough, which near the noisy end with w = 7.5 it may not be; the residual is
  reported per step.
* ``"null_text"`` (Mokady et al., null-text inversion): keep the plain (w = 1) trajectory as a pivot
  and, per step, optimise the null-text token features so that the guided step from the current
  latent lands on the pivot (Adam, early stop). The optimised nulls are used for the unconditional
  rows of both branches when editing. Cost: a forward and backward per inner iteration.

``exact=True`` adds, for any method, the per-step residual ``z_a - (alpha z_b + beta pred_w(z_b))``
back after each sampling step of both branches, which makes the source reconstruction exact up to
float rounding (the deterministic analogue of edit-friendly DDPM inversion). It changes nothing
at the source but shifts the edited branch by the same corrections.

Choice of the default, by measurement (``lab/scripts/editing/measure_editing.py``; no shipped weights existed
yet, so a width-64 denoiser trained for 1,000 steps on the tiny procedural corpus; 3 test motions,
50 DDIM steps, w = 7.5). Error the inversion adds on top of the VAE (root-aligned MPJPE of the
reconstruction against the VAE's own decoding; the VAE's floor was 2.8 cm) and wall time:

=====================  ==========  ========  =====================================
method                 error (cm)  time (s)  forward rows (a generation: 100)
=====================  ==========  ========  =====================================
ddim (w = 1)           7.1         0.3       50
null_text, 10 steps    0.94        6.8       650 (plus backward passes)
fixed_point, 5         0.016       1.9       600
fixed_point + exact    0.00002     2.2       600
=====================  ==========  ========  =====================================

Fixed-point inversion is the most faithful without corrections and cheaper than null-text
optimisation, and a mirror edit still acts on the inverted motion (left/right activity change
0.95 log units vs 0.46 after plain DDIM inversion), so it is the default method.

Re-measured on the shipped v0.2 weights (8 held-out corpus motions, 50 steps, w = 7.5; root-aligned
MPJPE of the reconstruction against the input, VAE floor 1.5 cm; mirror: change of the log left/right
activity ratio of the arms/legs after a Mirror edit of the inverted motion):

=====================  ==========  ========  ============
method                 error (cm)  time (s)  mirror acts
=====================  ==========  ========  ============
ddim (w = 1)           6.2         0.5       0.75
fixed_point            3.9         5.3       1.83
null_text              1.7         13.6      1.57
fixed_point + exact    1.5         5.1       2.17
=====================  ==========  ========  ============

With the trained model, fixed-point inversion alone loses detail (a raised-arms phase vanished at 20
steps), while the corrections cost nothing extra and do not weaken the edit, so
:meth:`SaladPipeline.invert` and ``salad invert`` use ``exact=True`` by default.
:func:`invert_latents` itself keeps ``exact=False`` as its default (the plain method).

The v3 weights (session 12; 12 held-out corpus 2.4 motions, 50 steps, w = 7.5, VAE floor 1.7 cm;
``lab/scripts/editing/measure_editing.py``): ddim 9.6 cm, fixed_point 5.5 cm, null_text 2.4 cm, fixed_point + exact
1.7 cm; mirror acts 0.77 / 0.97 / 0.95 / 1.13. The sharper model is less contractive under guidance at
a few low-noise steps: on 80 frames of HumanML3D 012314 at 20 steps and w = 4.5, five fixed-point
iterations leave 4.8 cm, twenty 1.0 cm (DDIM 30 cm); the exact replay closes the rest either way.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from salad_core.models.denoiser import Denoiser, TextContext
from salad_core.sampling import Guidance, GuidedPrediction, as_guidance, eval_mode, progress_bar

__all__ = [
    "INVERSION_METHODS",
    "DEFAULT_ITERATIONS",
    "ddim_step_coefficients",
    "ddim_schedule",
    "LatentInversion",
    "invert_latents",
    "Inversion",
]

log = logging.getLogger(__name__)

#: Inversion methods of :func:`invert_latents`.
INVERSION_METHODS: tuple[str, ...] = ("ddim", "fixed_point", "null_text")
#: Default inner iterations: fixed-point updates, null-text optimiser steps (Mokady et al.: 10).
DEFAULT_ITERATIONS: dict[str, int] = {"ddim": 0, "fixed_point": 5, "null_text": 10}


def ddim_step_coefficients(abar_from: float, abar_to: float, prediction_type: str) -> tuple[float, float]:
    """``(alpha, beta)`` with ``z_to = alpha * z_from + beta * pred`` for one DDIM step (eta = 0).

    ``pred`` is the model output of type ``prediction_type`` ("v_prediction", "epsilon" or
    "sample") at ``(z_from, t_from)``; ``abar`` are cumulative alphas of the two levels.
    """
    a, b = float(abar_from), float(abar_to)
    sa, s1a, sb, s1b = math.sqrt(a), math.sqrt(1 - a), math.sqrt(b), math.sqrt(1 - b)
    if prediction_type == "v_prediction":
        # x0 = sa z - s1a v, eps = s1a z + sa v  ->  z_to = sb x0 + s1b eps
        return sb * sa + s1b * s1a, s1b * sa - sb * s1a
    if prediction_type == "epsilon":
        # x0 = (z - s1a eps) / sa
        return sb / sa, s1b - sb * s1a / sa
    if prediction_type == "sample":
        if s1a == 0.0:
            raise ValueError("a 'sample' prediction cannot be inverted at abar = 1")
        # eps = (z - sa x0) / s1a
        return s1b / s1a, sb - s1b * sa / s1a
    raise ValueError(f"prediction_type must be 'v_prediction', 'epsilon' or 'sample', got {prediction_type!r}")


def ddim_schedule(scheduler, num_steps: int) -> list[tuple[torch.Tensor, float, float]]:
    """Per sampling step ``i``: ``(t_i, abar(t_i), abar(next level))`` of a diffusers DDIM scheduler.

    The next level is ``t_i - T / S`` or, after the last step, ``final_alpha_cumprod`` (1 with the
    official ``set_alpha_to_one=True``), exactly as ``DDIMScheduler.step`` computes them.
    """
    if type(scheduler).__name__ != "DDIMScheduler":
        raise ValueError("inversion needs the deterministic DDIM sampler (solver='ddim'), "
                         f"got {type(scheduler).__name__}")
    scheduler.set_timesteps(num_steps)
    ratio = scheduler.config.num_train_timesteps // scheduler.num_inference_steps
    acp = scheduler.alphas_cumprod
    out = []
    for t in scheduler.timesteps:
        prev = int(t) - ratio
        a_prev = float(acp[prev]) if prev >= 0 else float(scheduler.final_alpha_cumprod)
        out.append((t, float(acp[int(t)]), a_prev))
    return out


@dataclass
class LatentInversion:
    """Result of :func:`invert_latents` (latent space)."""

    noise: torch.Tensor                       # (B, N', P, Dz) z_T: where sampling starts
    trajectory: torch.Tensor                  # (S+1, B, N', P, Dz): [0] = z_T ... [S] = z_0
    null_texts: list[torch.Tensor] | None     # null_text: per step (B, W0, C) token features
    corrections: torch.Tensor | None          # exact: (S, B, N', P, Dz) added after step i
    residuals: np.ndarray                     # (S,) RMS of the guided step's miss before correction (nan: not computed)
    forward_rows: int                         # denoiser rows evaluated (a CFG generation costs 2 B S)
    seconds: float                            # wall time


def _rms(x: torch.Tensor, keep: torch.Tensor) -> float:
    return float(((x * keep) ** 2).sum().div(keep.expand_as(x).sum().clamp(min=1)).sqrt())


def invert_latents(denoiser: Denoiser, scheduler, latents: torch.Tensor, cond: TextContext,
                   null: TextContext | None, frame_mask: torch.Tensor | None = None, *,
                   method: str = "fixed_point", guidance_scale: "float | Guidance" = 7.5, num_steps: int = 50,
                   iterations: int | None = None, exact: bool = False, learning_rate: float = 1e-2,
                   progress: bool = False) -> LatentInversion:
    """Invert clean latents to the noise from which the guided DDIM sampler regenerates them.

    Parameters
    ----------
    denoiser : Denoiser
    scheduler
        A diffusers ``DDIMScheduler`` (:func:`salad_core.sampling.make_scheduler` with ``"ddim"``).
    latents : torch.Tensor
        ``(B, N', P, Dz)`` clean latents (the VAE's posterior means), zero on padded frames.
    cond : TextContext
        The ``B`` source prompts.
    null : TextContext
        The null text (batch 1 or ``B``); needed unless ``guidance_scale == 1``.
    frame_mask : torch.Tensor, optional
        ``(B, N')`` bool, True = valid latent frame.
    method : str
        One of :data:`INVERSION_METHODS` (see the module docstring).
    guidance_scale, num_steps
        The sampling settings the inversion must be faithful to (a CFG weight or a
        :class:`~salad_core.sampling.Guidance`; null-text inversion takes a plain weight only).
    iterations : int, optional
        Fixed-point updates or null-text optimiser steps per sampling step (defaults
        :data:`DEFAULT_ITERATIONS`).
    exact : bool
        Also return per-step corrections that make the reconstruction exact.
    learning_rate : float
        Adam step size of the null-text optimisation.
    """
    if method not in INVERSION_METHODS:
        raise ValueError(f"method={method!r}; allowed: {INVERSION_METHODS}")
    if latents.dim() != 4:
        raise ValueError(f"latents must be (B, N', P, Dz), got shape {tuple(latents.shape)}")
    iterations = DEFAULT_ITERATIONS[method] if iterations is None else int(iterations)
    if iterations < 0 or (method != "ddim" and iterations < 1):
        raise ValueError(f"iterations={iterations} must be >= 1 for method {method!r}")
    guidance = as_guidance(guidance_scale)
    w = guidance.scale
    if w != 1.0 and null is None:
        raise ValueError(f"guidance_scale={w} needs the null text")
    if method == "null_text" and guidance != Guidance(w):
        raise ValueError(f"null-text inversion takes a plain guidance weight, got {guidance}; use method='fixed_point'")
    num_train = int(scheduler.config.num_train_timesteps)
    b, n = latents.shape[:2]
    cond = cond.repeat(b)
    if frame_mask is None:
        frame_mask = torch.ones(b, n, dtype=torch.bool, device=latents.device)
    frame_mask = frame_mask.to(device=latents.device, dtype=torch.bool)
    keep = frame_mask[:, :, None, None].to(latents.dtype)
    null_b = None if null is None else (null.repeat(b) if null.batch_size != b else null)
    # the sampler's own guided prediction (eq. 9, one batched forward; the conditional rows alone
    # outside a guidance interval), and the plain conditional one (w = 1) of DDIM inversion
    guided = GuidedPrediction(denoiser, cond, null_b, guidance, frame_mask, num_train_timesteps=num_train)
    plain = GuidedPrediction(denoiser, cond, None, 1.0, frame_mask, num_train_timesteps=num_train)
    pt = scheduler.config.prediction_type
    schedule = ddim_schedule(scheduler, num_steps)
    start = time.perf_counter()
    rows = 0
    s_count = len(schedule)
    traj = [None] * (s_count + 1)
    traj[s_count] = latents * keep
    residuals = np.full(s_count, np.nan)
    corrections = torch.zeros((s_count, *latents.shape), dtype=latents.dtype) if exact else None
    with eval_mode(denoiser):
        with torch.inference_mode():
            # backwards through the sampler: step i maps level i to level i + 1
            for i in progress_bar(reversed(range(s_count)), f"inverting ({method})", progress, total=s_count):
                t, abar_t, abar_next = schedule[i]
                alpha, beta = ddim_step_coefficients(abar_t, abar_next, pt)
                z_a = traj[i + 1]
                if method == "fixed_point":
                    z_b, best, best_res, best_pred = z_a, None, math.inf, None
                    for k in range(iterations + 1):
                        pred = guided(z_b, t)
                        rows += guided.forward_rows(float(t))
                        if k > 0:
                            res = _rms(alpha * z_b + beta * pred - z_a, keep)
                            if res < best_res:
                                best, best_res, best_pred = z_b, res, pred
                        z_b = ((z_a - beta * pred) / alpha) * keep
                    if best is None:      # every residual NaN/inf: the iteration left the finite numbers
                        top = float(latents.abs().max())
                        raise ValueError(
                            f"the inversion diverged at step {s_count - i} of {s_count} (t={int(t)}): the fixed-point "
                            f"iterate is not finite. The motion's latents reach |z| = {top:.3g} (the model's are of "
                            "order 1), so the motion lies far outside what the model was trained on; check its "
                            "units and scale (raw HumanML3D features, metres)")
                    traj[i] = best
                    residuals[i] = best_res
                    if exact:
                        corrections[i] = (z_a - (alpha * best + beta * best_pred)) * keep
                else:
                    pred = plain(z_a, t)                                          # plain: w = 1
                    rows += plain.forward_rows(float(t))
                    traj[i] = ((z_a - beta * pred) / alpha) * keep
            null_texts = None
            if method == "ddim" and exact:
                # corrections of the guided sampler along the plain trajectory
                for i in range(s_count):
                    t, abar_t, abar_next = schedule[i]
                    alpha, beta = ddim_step_coefficients(abar_t, abar_next, pt)
                    pred = guided(traj[i], t)
                    rows += guided.forward_rows(float(t))
                    miss = (traj[i + 1] - (alpha * traj[i] + beta * pred)) * keep
                    corrections[i] = miss
                    residuals[i] = _rms(miss, keep)
        if method == "null_text":
            if w == 1.0:
                raise ValueError("null-text inversion needs guidance (guidance_scale != 1); with w = 1 use 'ddim'")
            null_texts, n_rows = _null_text(denoiser, schedule, traj, cond, null_b, frame_mask, keep, guidance, pt,
                                            iterations, learning_rate, residuals, corrections)
            rows += n_rows
    seconds = time.perf_counter() - start
    log.info("inversion %s: %d steps, %d forward rows, %.1f s, max step residual %.3g", method, s_count, rows,
             seconds, np.nanmax(residuals) if np.isfinite(residuals).any() else float("nan"))
    return LatentInversion(traj[0].clone(), torch.stack(traj).clone(), null_texts, corrections, residuals, rows,
                           seconds)


def _null_text(denoiser: Denoiser, schedule, traj, cond: TextContext, null: TextContext, frame_mask, keep,
               guidance: Guidance, pt: str, iterations: int, lr: float, residuals: np.ndarray,
               corrections: torch.Tensor | None) -> tuple[list[torch.Tensor], int]:
    """Null-text optimisation (Mokady et al. 2023) along the pivot trajectory ``traj``."""
    b = cond.batch_size
    rows = 0
    features = null.text.detach().clone()                      # (B, W0, C), optimised step by step
    mask = null.mask
    z = traj[0].detach().clone()
    out: list[torch.Tensor] = []
    for i, (t, abar_t, abar_next) in enumerate(schedule):
        alpha, beta = ddim_step_coefficients(abar_t, abar_next, pt)
        tt = t.reshape(1)
        target = traj[i + 1]
        with torch.inference_mode():
            c = denoiser(z, tt, frame_mask=frame_mask, text_context=cond)
        rows += b
        c = c.clone()
        zc = z.clone()
        feat = features.clone().requires_grad_(True)
        opt = torch.optim.Adam([feat], lr=lr)
        # Mokady et al.'s early stop: epsilon grows with the step index
        eps = 1e-5 + i * 2e-5
        with torch.enable_grad():
            for _ in range(iterations):
                u = denoiser(zc, tt, frame_mask=frame_mask, text_context=TextContext(feat, mask))
                rows += b
                pred = guidance.combine(u, c)                              # eq. 9
                loss = (((alpha * zc + beta * pred - target) * keep) ** 2).sum() / keep.expand_as(zc).sum()
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                if loss.item() < eps:
                    break
        features = feat.detach()
        out.append(features.clone())
        with torch.inference_mode():
            u = denoiser(z, tt, frame_mask=frame_mask, text_context=TextContext(features, mask))
            rows += b
            z_next = (alpha * z + beta * guidance.combine(u, c)) * keep
            miss = (target - z_next) * keep
            residuals[i] = _rms(miss, keep)
            if corrections is not None:
                corrections[i] = miss
                z_next = target.clone()
        z = z_next
    return out, rows


@dataclass
class Inversion:
    """A given motion inverted to noise under its prompt, ready for :meth:`SaladPipeline.edit`.

    Everything needed to regenerate the source and to edit it: the noise, the per-step null texts
    or corrections of the method, the sampling settings, and the measured reconstruction.
    """

    prompts: list[str]                   # source prompts
    lengths: list[int]                   # frames (multiples of 4)
    features: list[np.ndarray]           # per sample the input (N_b, D) raw features
    latents: torch.Tensor                # (B, N', P, Dz) VAE posterior means, zero on padded frames
    noise: torch.Tensor                  # (B, N', P, Dz) inverted noise z_T
    trajectory: torch.Tensor             # (S+1, B, N', P, Dz)
    method: str
    guidance_scale: float
    num_steps: int
    exact: bool
    iterations: int
    guidance: Any = None                           # salad_core.sampling.Guidance made for (None: plain w)
    null_texts: list[torch.Tensor] | None = None   # per step (B, W0, C) (null_text)
    null_mask: torch.Tensor | None = None          # (B, W0) mask of the null-text tokens
    corrections: torch.Tensor | None = None        # (S, B, N', P, Dz) (exact)
    residuals: np.ndarray | None = None            # (S,) per-step RMS miss of the guided sampler
    forward_rows: int = 0
    seconds: float = 0.0
    reconstruction: Any = None                     # MotionOutput of the unedited reconstruction
    # mpjpe / mpjpe_global: reconstruction vs the input joints (root-aligned / not, metres);
    # vae_mpjpe(_global): VAE decode(encode(x)) vs input, the floor of any inversion;
    # inversion_mpjpe(_global): reconstruction vs that VAE decoding (the inversion's own error);
    # latent_rmse: reconstructed vs encoded latents
    errors: dict[str, float] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.prompts)
