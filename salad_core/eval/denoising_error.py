"""How well a latent diffusion model's denoiser recovers the clean latent at each noise level.

Two denoisers that differ only in what they predict (the clean latent ``x0``, the noise ``eps`` or the velocity
``v``) define the same sampler once their outputs are turned into an estimate of ``x0``; if the two estimates are
equally close to the truth at every timestep, the two models make the same motions and no metric of the generated
motions can order them. This module measures exactly that, on real clips:

* the clips' posterior means ``x0`` ``(B, N', P, Dz)`` in the diffusion's normalised space
  (:meth:`salad_core.pipeline.SaladPipeline.encode_motion`), each motion encoded at its own length;
* fixed Gaussian noise per clip (the same for every denoiser on the same latent shape: paired) and a grid of
  timesteps ``t``: ``x_t = sqrt(a_t) x0 + sqrt(1 - a_t) eps`` (the training scheduler's ``add_noise``);
* the denoiser's output for the clip's caption (conditional) and, with classifier-free guidance at ``w``, the guided
  output ``u + w (c - u)`` (the sampler's), optionally the unconditional (empty-prompt) output ``u`` alone, each
  turned into ``x0_hat`` (:func:`x0_estimate`);
* per clip: the mean squared error of ``x0_hat`` in the normalised latent space over the clip's latent frames, and
  the mean joint distance between the motions decoded from ``x0_hat`` and from ``x0`` (raw position recovery,
  metres), which compares denoisers on different latent spaces too;
* with an evaluator, per timestep the FID between the clips and the motions decoded from ``x0_hat`` (one set per
  timestep, so no per-clip pairing), beside the FID of the decoded clean latents (the VAE's own share): what the
  metric of Table 3 sees of a one-step estimate at that noise level (at ``t = 0`` the sampler's last step).

:func:`denoising_error` returns the per-clip values, so two denoisers measured on the same batches can be compared
clip by clip (:func:`paired_difference`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import torch

__all__ = ["x0_estimate", "DenoisingError", "denoising_error", "paired_difference", "DEFAULT_TIMESTEPS"]

#: the timesteps measured by default (of 1,000 training timesteps): denser where the signal dominates
DEFAULT_TIMESTEPS = (0, 10, 25, 50, 100, 200, 300, 400, 500, 600, 700, 800, 900, 999)


def x0_estimate(output: torch.Tensor, x_t: torch.Tensor, alpha_bar: torch.Tensor, prediction_type: str
                ) -> torch.Tensor:
    """A denoiser's output turned into its estimate of the clean latent.

    ``output``, ``x_t``: ``(B, ...)``; ``alpha_bar``: ``(B,)`` cumulative products ``a_t`` of the items' timesteps.
    ``prediction_type``: ``"sample"`` (the output is ``x0``), ``"epsilon"`` (``x0 = (x_t - sqrt(1 - a) eps) /
    sqrt(a)``) or ``"v_prediction"`` (``x0 = sqrt(a) x_t - sqrt(1 - a) v``, with ``v = sqrt(a) eps - sqrt(1 - a)
    x0``)."""
    a = alpha_bar.to(x_t).view(-1, *(1,) * (x_t.dim() - 1))
    if prediction_type == "sample":
        return output
    if prediction_type == "epsilon":
        return (x_t - (1 - a).sqrt() * output) / a.sqrt()
    if prediction_type == "v_prediction":
        return a.sqrt() * x_t - (1 - a).sqrt() * output
    raise ValueError(f"prediction_type {prediction_type!r}: expected 'sample', 'epsilon' or 'v_prediction'")


@dataclass
class DenoisingError:
    """Per-clip errors of one denoiser: ``latent[mode][t]`` and ``joints[mode][t]`` are ``(clips,)`` arrays, ``mode``
    ``"cond"`` (the caption's output), ``"uncond"`` (the empty prompt's) or ``"guided"`` (classifier-free guidance at
    ``guidance_scale``)."""

    timesteps: tuple[int, ...]
    guidance_scale: float
    prediction_type: str
    latent_shape: tuple[int, int] = ()
    clips: list[str] = field(default_factory=list)
    latent: dict[str, dict[int, np.ndarray]] = field(default_factory=dict)
    joints: dict[str, dict[int, np.ndarray]] = field(default_factory=dict)
    fid: dict[str, dict[int, float]] = field(default_factory=dict)   # with an evaluator: {mode: {t: FID}}
    fid_clean: float | None = None                                     # FID of the decoded clean latents

    def means(self) -> dict[str, dict[str, dict[int, float]]]:
        """``{"latent"|"joints": {mode: {t: mean over clips}}}``, and ``"fid": {mode: {t: FID}}`` when measured."""
        out = {name: {mode: {t: float(v.mean()) for t, v in per_t.items()} for mode, per_t in table.items()}
               for name, table in (("latent", self.latent), ("joints", self.joints))}
        if self.fid:
            out["fid"] = {mode: dict(per_t) for mode, per_t in self.fid.items()}
        return out


def paired_difference(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Mean of ``a - b`` over the same clips and its 95 % half-width (normal approximation)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if a.shape != b.shape or a.ndim != 1 or len(a) < 2:
        raise ValueError(f"paired values must be two equal 1-d arrays of at least 2 clips, got {a.shape}, {b.shape}")
    d = a - b
    return float(d.mean()), float(1.96 * d.std(ddof=1) / np.sqrt(len(d)))


def _clip_noise(shape: tuple[int, ...], seed: int) -> torch.Tensor:
    return torch.randn(*shape, generator=torch.Generator().manual_seed(int(seed)))


@torch.inference_mode()
def denoising_error(pipe: Any, batches: Sequence[Any], *, timesteps: Sequence[int] = DEFAULT_TIMESTEPS,
                    guidance_scale: float | None = 7.5, noise_seed: int = 0, decode: bool = True,
                    evaluator: Any = None, unconditional: bool = False) -> DenoisingError:
    """Measure ``pipe``'s denoiser on real batches.

    Parameters
    ----------
    pipe : SaladPipeline
        VAE, denoiser, text encoder, latent statistics and diffusion config.
    batches : sequence of RealBatch
        ``captions``, ``lengths`` ``(B,)`` (multiples of the unit length), ``motions`` ``(B, N, D)`` raw features and
        ``names`` (:func:`salad_core.eval.batches.batches_for`).
    timesteps : ints in ``[0, T)``
    guidance_scale : float or None
        The guided mode's weight; None measures the conditional output only.
    noise_seed : int
        Clip ``i`` (in batch order) gets the noise ``torch.Generator(noise_seed + i)`` draws at the batch's padded
        latent shape, so two denoisers of the same latent shape see the same noise on the same clips.
    decode : bool
        Also decode ``x0_hat`` and ``x0`` and measure the joints (the slow part).
    evaluator : T2MEvaluator, optional
        Also the FID per mode and timestep (needs ``decode``), and of the decoded clean latents.
    unconditional : bool
        Also measure the unconditional output (mode ``"uncond"``: the branch classifier-free guidance extrapolates
        away from).
    """
    from salad_core.eval import metrics as M
    from salad_core.eval.batches import motion_embeddings
    from salad_core.sampling import make_scheduler

    if evaluator is not None and not decode:
        raise ValueError("the FID needs the decoded motions: decode=True")
    scheduler = make_scheduler(pipe.diffusion, "ddim")
    n_train = int(scheduler.config.num_train_timesteps)
    ts = tuple(int(t) for t in timesteps)
    if not ts or any(t < 0 or t >= n_train for t in ts):
        raise ValueError(f"timesteps {list(timesteps)} must be in [0, {n_train})")
    kind = pipe.diffusion.prediction_type
    modes = ("cond",) + (("uncond",) if unconditional else ()) + (("guided",) if guidance_scale is not None else ())
    out = DenoisingError(ts, float(guidance_scale) if guidance_scale is not None else float("nan"), kind,
                         tuple(pipe.latent_shape))
    out.latent = {m: {t: [] for t in ts} for m in modes}
    out.joints = {m: {t: [] for t in ts} for m in modes}
    alphas = scheduler.alphas_cumprod
    unit = pipe.skeleton.unit_length
    den = pipe.denoiser.eval()
    p, dz = pipe.latent_shape
    real_emb, clean_emb = [], []
    est_emb = {m: {t: [] for t in ts} for m in modes}
    clip = 0
    for batch in batches:
        lengths = [int(x) for x in batch.lengths]
        if any(x % unit or x <= 0 for x in lengths):
            raise ValueError(f"clip lengths {lengths} must be positive multiples of {unit}")
        n_lat = max(lengths) // unit
        x0 = torch.zeros(len(lengths), n_lat, p, dz)
        for i, length in enumerate(lengths):
            x0[i, : length // unit] = pipe.encode_motion(np.asarray(batch.motions[i, :length], np.float32))[0]
        mask = pipe.frame_mask(lengths, n_lat)                                     # (B, N')
        keep = mask[:, :, None, None].to(x0.dtype)
        noise = torch.stack([_clip_noise((n_lat, p, dz), noise_seed + clip + i) for i in range(len(lengths))]) * keep
        text, null = pipe.encode_text(list(batch.captions))
        cond = den.prepare_text(text.features, text.mask)
        uncond = den.prepare_text(null.features, null.mask).repeat(len(lengths))
        if decode:
            feats, truth = pipe.decode(x0, lengths, recovery="positions")
            if evaluator is not None:
                real_emb.append(motion_embeddings(evaluator, np.asarray(batch.motions, np.float32), batch.lengths))
                clean_emb.append(motion_embeddings(evaluator, feats, batch.lengths))
        for t in ts:
            tt = torch.full((len(lengths),), t, dtype=torch.long)
            x_t = scheduler.add_noise(x0, noise, tt) * keep
            c = den(x_t, tt, frame_mask=mask, text_context=cond)
            outputs = {"cond": c}
            if "guided" in modes or "uncond" in modes:
                u = den(x_t, tt, frame_mask=mask, text_context=uncond)
                if "uncond" in modes:
                    outputs["uncond"] = u
                if "guided" in modes:
                    outputs["guided"] = u + guidance_scale * (c - u)
            a = alphas[tt]
            for mode, o in outputs.items():
                est = x0_estimate(o, x_t, a, kind) * keep
                sq = ((est - x0) ** 2).sum(dim=(1, 2, 3)) / (mask.sum(1) * p * dz)
                out.latent[mode][t].extend(sq.double().tolist())
                if decode:
                    feats, joints = pipe.decode(est, lengths, recovery="positions")
                    if evaluator is not None:
                        est_emb[mode][t].append(motion_embeddings(evaluator, feats, batch.lengths))
                    out.joints[mode][t].extend(float(np.linalg.norm(j - g, axis=-1).mean())
                                               for j, g in zip(joints, truth))
        out.clips.extend(batch.names)
        clip += len(lengths)
    out.latent = {m: {t: np.asarray(v) for t, v in d.items()} for m, d in out.latent.items()}
    out.joints = {m: {t: np.asarray(v) for t, v in d.items()} for m, d in out.joints.items()} if decode else {}
    if evaluator is not None:
        real = np.concatenate(real_emb)
        out.fid_clean = float(M.fid(real, np.concatenate(clean_emb)))
        out.fid = {m: {t: float(M.fid(real, np.concatenate(v))) for t, v in d.items()} for m, d in est_emb.items()}
    return out
