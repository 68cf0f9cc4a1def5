"""The batched edit loop (SALAD supplement B, Algorithm 1): source and edited sample side by side.

:func:`edit_latents` is the one visible loop. Per step ``i`` with timestep ``t``:

1. the controller plans the step (:meth:`EditController.on_step`): which rows the forward batch
   needs (:class:`~salad_core.attention.controller.RowLayout`);
2. one forward of the denoiser computes all rows; at every hooked attention site the controller
   builds ``M_hat`` from the source rows (and the target's own maps) and substitutes it in the
   edited rows (:class:`~salad_core.attention.processor.HookedProcessor`);
3. classifier-free guidance per branch, ``pred = uncond + w (cond - uncond)`` (eq. 9);
4. one ``scheduler.step`` on the stacked latents ``[z (B); z* (B)]`` (so multistep solvers keep
   one consistent state), optional per-step corrections (exact inversion), re-masking.

Both branches start from the same noise (Algorithm 1 line 4). The loop also reconstructs an
inverted motion (``edited=False``: source rows only) with per-step null texts (null-text
inversion) and per-step corrections.
"""
from __future__ import annotations

import inspect
import logging
from dataclasses import dataclass
from typing import Sequence

import torch
import torch.nn.functional as F

from salad_core.models.attention import use_processors
from salad_core.models.denoiser import Denoiser, TextContext
from salad_core.sampling import StepInfo, Guidance, as_guidance

from .controller import EditController, RowLayout
from .processor import HookedProcessor

__all__ = ["EditRun", "edit_latents", "pad_context"]

log = logging.getLogger(__name__)


@dataclass
class EditRun:
    """Result of :func:`edit_latents`."""

    source: torch.Tensor            # (B, N', P, Dz) final source latents
    edited: torch.Tensor | None     # (B, N', P, Dz) final edited latents (None if edited=False)
    rows: int                       # forward rows summed over the steps (plain CFG generation: 2 B S)
    probe_steps: int                # steps that ran probe rows


def pad_context(ctx: TextContext, width: int) -> TextContext:
    """The context with its token axis padded (masked zeros) to ``width``."""
    pad = width - ctx.num_tokens
    if pad < 0:
        raise ValueError(f"cannot pad a text context of {ctx.num_tokens} tokens down to {width}")
    if pad == 0:
        return ctx
    return TextContext(F.pad(ctx.text, (0, 0, 0, pad)), F.pad(ctx.mask, (0, pad), value=False), ctx.pooled)


def _expand(ctx: TextContext, b: int) -> TextContext:
    return ctx.repeat(b) if ctx.batch_size != b else ctx


def edit_latents(denoiser: Denoiser, scheduler, controller: EditController, *, source: TextContext,
                 target: TextContext | None, null: TextContext | Sequence[TextContext] | None,
                 noise: torch.Tensor, frame_mask: torch.Tensor | None = None,
                 guidance_scale: "float | Guidance" = 7.5,
                 num_steps: int = 50, corrections: torch.Tensor | None = None, progress: bool = False,
                 generator: torch.Generator | None = None) -> EditRun:
    """Sample the source and the edited motion latents together (see the module docstring).

    Parameters
    ----------
    denoiser : Denoiser
    scheduler
        A diffusers scheduler; ``set_timesteps(num_steps)`` is called here.
    controller : EditController
        Plans the rows and edits the maps; its ``stores`` record attention if any.
    source, target : TextContext
        ``B`` source and target prompts (``target`` unused when ``controller.edited`` is False).
    null : TextContext or sequence of TextContext
        The null text (batch 1 or ``B``), or one per step (null-text inversion). None only
        without guidance.
    noise : torch.Tensor
        ``(B, N', P, Dz)`` initial noise shared by both branches.
    frame_mask : torch.Tensor, optional
        ``(B, N')`` bool, True = valid latent frame.
    guidance_scale, num_steps
        As :func:`salad_core.sampling.denoise` (a :class:`~salad_core.sampling.Guidance` with an
        interval still runs the unconditional rows at every step here; outside the interval their
        output is not used, so source and edit follow the plain sampler's guided prediction).
    corrections : torch.Tensor, optional
        ``(S, B, N', P, Dz)`` added to both branches after step ``i`` (exact inversion).

    Returns
    -------
    EditRun
    """
    if noise.dim() != 4:
        raise ValueError(f"noise must be (B, N', P, Dz), got shape {tuple(noise.shape)}")
    b, n = noise.shape[:2]
    if controller.batch != b:
        raise ValueError(f"the controller pairs {controller.batch} prompts but the noise has batch {b}")
    edited = controller.edited
    guidance = as_guidance(guidance_scale)
    use_cfg = guidance.cfg
    if use_cfg != controller.cfg:
        raise ValueError(f"controller built with cfg={controller.cfg} but guidance_scale={guidance.scale}")
    if use_cfg and null is None:
        raise ValueError(f"guidance_scale={guidance.scale} needs the null text; pass null= or use guidance_scale=1")
    per_step_null = isinstance(null, (list, tuple))
    if per_step_null and len(null) != num_steps:
        raise ValueError(f"got {len(null)} per-step null texts for num_steps={num_steps}")
    if corrections is not None and tuple(corrections.shape) != (num_steps, *noise.shape):
        raise ValueError(f"corrections must have shape {(num_steps, *noise.shape)}, got {tuple(corrections.shape)}")
    if edited and target is None:
        raise ValueError("editing needs the target prompts' text context")
    width = controller.width
    source = pad_context(_expand(source, b), width)
    target = pad_context(_expand(target, b), width) if edited else None
    if frame_mask is None:
        frame_mask = torch.ones(b, n, dtype=torch.bool, device=noise.device)
    elif tuple(frame_mask.shape) != (b, n):
        raise ValueError(f"frame_mask must be (B, N') = {(b, n)}, got {tuple(frame_mask.shape)}")
    frame_mask = frame_mask.to(device=noise.device, dtype=torch.bool)
    keep = frame_mask[:, :, None, None].to(noise.dtype)
    branches = 2 if edited else 1

    contexts: dict[tuple, TextContext] = {}

    def context(lay: RowLayout, step: int) -> TextContext:
        key = (lay.probe, lay.share_uncond, step if per_step_null else -1)
        if key not in contexts:
            if per_step_null:
                # a new step's null text: the previous steps' contexts (and their cached text
                # projections) are not needed again
                for old in [k for k in contexts if k[2] != key[2]]:
                    del contexts[old]
            parts: list[TextContext] = []
            if lay.cfg:
                nul = pad_context(_expand(null[step] if per_step_null else null, b), width)
                parts += [nul] * (lay.num_uncond // b)
            parts.append(source)
            if lay.probe:
                parts.append(target)
            if lay.edited:
                parts.append(target)
            contexts[key] = TextContext.concat(parts)
        return contexts[key]

    step_kwargs = {"generator": generator} if "generator" in inspect.signature(scheduler.step).parameters else {}
    scheduler.set_timesteps(num_steps, device=noise.device)
    timesteps = scheduler.timesteps
    num_train = int(scheduler.config.num_train_timesteps)
    if len(timesteps) != num_steps:
        raise ValueError(f"the scheduler made {len(timesteps)} timesteps for num_steps={num_steps}")
    kinds = {"cross"} | {k for e in controller.injections for k in e.kinds}
    for store in controller.stores.values():
        kinds |= set(store.kinds)
    hook = HookedProcessor(controller)
    processors = {name: hook for name, mod in denoiser.attention_sites.items() if mod.kind in kinds}

    was_training = denoiser.training
    denoiser.eval()
    try:
        with torch.inference_mode(), use_processors(denoiser, processors):
            denoiser.prepare_timesteps(timesteps)       # every step's FiLMs in one product, as denoise() does
            z = torch.cat([noise] * branches) * scheduler.init_noise_sigma
            z = z * torch.cat([keep] * branches)
            iterator = timesteps
            if progress:
                from tqdm.auto import tqdm
                iterator = tqdm(timesteps, desc="editing" if edited else "reconstructing", leave=False)
            for i, t in enumerate(iterator):
                info = StepInfo(i, num_steps, float(t), use_cfg, b)
                equal = edited and torch.equal(z[:b], z[b:])
                lay = controller.on_step(info, latents_equal=equal)
                model_in = scheduler.scale_model_input(z, t)
                zs, ze = model_in[:b], (model_in[b:] if edited else None)
                rows = []
                if lay.cfg:
                    rows.append(zs)
                    if lay.num_uncond > b:
                        rows.append(ze)
                rows.append(zs)
                if lay.probe:
                    rows.append(ze)
                if lay.edited:
                    rows.append(ze)
                x = torch.cat(rows)
                mask = frame_mask.repeat(len(rows), 1)
                out = denoiser(x, t.reshape(1).to(noise.device), frame_mask=mask, text_context=context(lay, i))
                preds = []
                pairs = [(lay.source_uncond, lay.source_cond)]
                if edited:
                    pairs.append((lay.edited_uncond, lay.edited_cond))
                active = guidance.active(float(t), num_train)
                for u_rows, c_rows in pairs:
                    cond = out[c_rows]
                    if lay.cfg:
                        cond = guidance.combine(out[u_rows], cond, keep=keep, active=active)   # eq. 9
                    preds.append(cond)
                z = scheduler.step(torch.cat(preds), t, z, **step_kwargs).prev_sample
                if corrections is not None:
                    z = z + torch.cat([corrections[i]] * branches)
                z = z * torch.cat([keep] * branches)
    finally:
        denoiser.train(was_training)
    log.debug("edit loop: %d steps, %d forward rows, %d probe steps", num_steps, controller.rows_total,
              controller.probe_steps)
    return EditRun(z[:b], z[b:] if edited else None, controller.rows_total, controller.probe_steps)
