"""Batched editing (SALAD supplement B, Algorithm 1): source and edited sample side by side.

The loop is :func:`salad_core.sampling.denoise`; :class:`EditPrediction` is its strategy for
editing, and :func:`edit_latents` joins the two. Per step ``i`` with timestep ``t``:

1. the controller plans the step (:meth:`EditController.on_step`): which rows the forward batch
   needs (:class:`~salad_core.attention.controller.RowLayout`);
2. one forward of the denoiser computes all rows; at every hooked attention site the controller
   builds ``M_hat`` from the source rows (and the target's own maps) and substitutes it in the
   edited rows (:class:`~salad_core.attention.processor.HookedProcessor`);
3. classifier-free guidance per branch, ``pred = uncond + w (cond - uncond)`` (eq. 9);
4. the loop's one ``scheduler.step`` on the stacked latents ``[z (B); z* (B)]`` (so multistep
   solvers keep one consistent state), optional per-step corrections (exact inversion), re-masking.

Both branches start from the same noise (Algorithm 1 line 4), except when an edit gives the edited
sample its own (:class:`~salad_core.attention.edits.ExampleBased`: variations of an example, drawn by
:func:`~salad_core.attention.edits.seeded_noise`). The same strategy also
reconstructs an inverted motion (``edited=False``: source rows only) with per-step null texts
(null-text inversion) and per-step corrections.
"""
from __future__ import annotations

import dataclasses
import logging
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Iterator, Sequence

import torch
import torch.nn.functional as F

from salad_core.models.attention import use_processors
from salad_core.models.denoiser import Denoiser, TextContext
from salad_core.sampling import Guidance, StepInfo, as_guidance, denoise

from .controller import EditController, RowLayout
from .edits import seeded_noise
from .mirror_take import composite, take_of
from .processor import HookedProcessor

__all__ = ["EditRun", "EditPrediction", "Resampler", "edit_latents", "pad_context"]

log = logging.getLogger(__name__)


@dataclass
class EditRun:
    """Result of :func:`edit_latents`."""

    source: torch.Tensor            # (B, N', P, Dz) final source latents
    edited: torch.Tensor | None     # (B, N', P, Dz) final edited latents (None if edited=False)
    rows: int                       # forward rows summed over the steps (plain CFG generation: 2 B S)
    probe_steps: int                # steps that ran probe rows
    edited_noise: torch.Tensor | None = None   # (B, N', P, Dz) the edited sample's own noise, if not the source's
    inpaint_mask: torch.Tensor | None = None   # (B, N', P, 1) the in-painting region (1 = regenerated), if any


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


class EditPrediction:
    """Algorithm 1's batched row layout as a :class:`~salad_core.sampling.Prediction`.

    The latents it predicts for are the stacked ``[z (B); z* (B)]`` (source, edited; the source
    alone when ``controller.edited`` is False). Per step the controller plans the rows
    (:meth:`EditController.on_step`), one forward computes them all with the hooked processors
    installed (:meth:`session`), and classifier-free guidance combines each branch's rows (eq. 9).

    Parameters
    ----------
    denoiser : Denoiser
    controller : EditController
    source, target : TextContext
        ``B`` source and target prompts (``target`` unused without editing).
    null : TextContext or sequence of TextContext or None
        The null text (batch 1 or ``B``), or one per step (null-text inversion).
    frame_mask : torch.Tensor
        ``(B, N')`` bool, True = valid latent frame.
    guidance : float or Guidance
    num_steps : int
        Steps the per-step null texts and the schedule must have.
    """

    def __init__(self, denoiser: Denoiser, controller: EditController, *, source: TextContext,
                 target: TextContext | None, null: TextContext | Sequence[TextContext] | None,
                 frame_mask: torch.Tensor, guidance: "float | Guidance", num_steps: int) -> None:
        self.model, self.controller = denoiser, controller
        self.guidance = as_guidance(guidance)
        b = controller.batch
        self.batch_size, self.num_steps = b, int(num_steps)
        self.edited = controller.edited
        self.branches = 2 if self.edited else 1
        self.desc = "editing" if self.edited else "reconstructing"
        if self.guidance.cfg != controller.cfg:
            raise ValueError(f"controller built with cfg={controller.cfg} but guidance_scale={self.guidance.scale}")
        if self.guidance.cfg and null is None:
            raise ValueError(f"guidance_scale={self.guidance.scale} needs the null text; pass null= or use "
                             "guidance_scale=1")
        self.per_step_null = isinstance(null, (list, tuple))
        if self.per_step_null and len(null) != num_steps:
            raise ValueError(f"got {len(null)} per-step null texts for num_steps={num_steps}")
        if self.edited and target is None:
            raise ValueError("editing needs the target prompts' text context")
        width = controller.width
        self.null = null
        self.source = pad_context(_expand(source, b), width)
        self.target = pad_context(_expand(target, b), width) if self.edited else None
        self.frame_mask = frame_mask
        self.keep = frame_mask[:, :, None, None]
        self._contexts: dict[tuple, TextContext] = {}
        self._num_train = 0
        # in-painting may guide the edited branch with its own weight (Inpaint.guidance)
        scale = getattr(latent_edit(controller) if self.edited else None, "edited_guidance", None)
        self.edited_guidance = (None if scale is None or not self.guidance.cfg
                                else dataclasses.replace(self.guidance, scale=float(scale)))

    @contextmanager
    def session(self, timesteps: torch.Tensor, num_train_timesteps: int) -> Iterator[None]:
        """The hooked processors on the sites the controller reads or records, for the whole loop."""
        if len(timesteps) != self.num_steps:
            raise ValueError(f"the scheduler made {len(timesteps)} timesteps for num_steps={self.num_steps}")
        self._num_train = int(num_train_timesteps)
        kinds = {"cross"} | set(self.controller.site_kinds)
        hook = HookedProcessor(self.controller)
        processors = {name: hook for name, mod in self.model.attention_sites.items() if mod.kind in kinds}
        with use_processors(self.model, processors):
            self.model.prepare_timesteps(timesteps)       # every step's FiLMs in one product
            yield

    def guided(self, timestep: float) -> bool:
        # the unconditional rows run at every step here, also outside a guidance interval (their
        # output is then not used), so source and edit follow the plain sampler's guided prediction
        return self.guidance.cfg

    def context(self, lay: RowLayout, step: int) -> TextContext:
        """The text of the step's rows (cached per layout; per step with per-step null texts)."""
        key = (lay.probe, lay.share_uncond, step if self.per_step_null else -1)
        if key not in self._contexts:
            if self.per_step_null:
                # a new step's null text: the previous steps' contexts (and their cached text
                # projections) are not needed again
                for old in [k for k in self._contexts if k[2] != key[2]]:
                    del self._contexts[old]
            parts: list[TextContext] = []
            if lay.cfg:
                null = self.null[step] if self.per_step_null else self.null
                parts += [pad_context(_expand(null, self.batch_size), self.controller.width)] * (
                    lay.num_uncond // self.batch_size)
            parts.append(self.source)
            if lay.probe:
                parts.append(self.target)
            if lay.edited:
                parts.append(self.target)
            self._contexts[key] = TextContext.concat(parts)
        return self._contexts[key]

    def __call__(self, z: torch.Tensor, t: torch.Tensor, info: StepInfo) -> torch.Tensor:
        """Guided predictions ``(branches * B, N', P, Dz)`` of the stacked latents ``z``."""
        b = self.batch_size
        zs, ze = z[:b], (z[b:] if self.edited else None)
        lay = self.controller.on_step(info, latents_equal=self.edited and torch.equal(zs, ze))
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
        mask = self.frame_mask.repeat(len(rows), 1)
        out = self.model(torch.cat(rows), t.reshape(1).to(z.device), frame_mask=mask,
                         text_context=self.context(lay, info.index))
        pairs = [(lay.source_uncond, lay.source_cond)]
        if self.edited:
            pairs.append((lay.edited_uncond, lay.edited_cond))
        active = self.guidance.active(float(t), self._num_train)
        keep = self.keep.to(out.dtype)
        preds = []
        for k, (u_rows, c_rows) in enumerate(pairs):
            cond = out[c_rows]
            if lay.cfg:
                guidance = self.edited_guidance if (k == 1 and self.edited_guidance is not None) else self.guidance
                cond = guidance.combine(out[u_rows], cond, keep=keep, active=active)   # eq. 9
            preds.append(cond)
        return torch.cat(preds)


def latent_edit(controller: EditController):
    """The controller's latent-space edit (an :class:`~salad_core.attention.inpaint.Inpaint`; at most one), or None."""
    return next((e for e in controller.edits if e.role == "latent"), None)


class Resampler:
    """RePaint's resampling (Lugmayr et al., CVPR 2022) as the edit loop's latent hook.

    After step ``i`` the stacked latents ``[z (B); z* (B)]`` are merged as the plain hook does (``merge``: the kept
    region of ``z*`` is the source's). When :meth:`Inpaint.resampling <salad_core.attention.inpaint.Inpaint.
    resampling>` says so, the edited latents are noised back ``jump`` steps by the forward process
    (``z*_k = sqrt(a_k / a_{i+1}) z*_{i+1} + sqrt(1 - a_k / a_{i+1}) eps``, ``a`` the scheduler's cumulative
    alphas, ``k = i + 1 - jump``), their kept region set to the source's latents of that level, and steps
    ``k .. i`` run again (the same rows, text and attention edits; the source rows keep their recorded latents),
    ``passes - 1`` times (:meth:`Inpaint.passes_for <salad_core.attention.inpaint.Inpaint.passes_for>`). The source
    branch is never changed. Attention stores are not fed during the extra
    passes (they would count a step twice).

    Parameters
    ----------
    merge : callable
        ``merge(step_info, z) -> z`` on ``(2B, N', P, Dz)``: the per-step replacement of the kept region.
    prediction : EditPrediction
    scheduler
        A DDIM scheduler (stateless steps; the loop has called ``set_timesteps``).
    inpaint : Inpaint
    passes : int
        Times each jump of steps is denoised (> 1).
    region : torch.Tensor
        ``(B, N', P, 1)`` the in-painting mask (1 = regenerated).
    start : torch.Tensor
        ``(2B, N', P, Dz)`` the loop's initial latents (scaled by ``init_noise_sigma``, padding zeroed).
    corrections : torch.Tensor, optional
        ``(S, 2B, N', P, Dz)`` the per-step corrections the loop adds.
    keep : torch.Tensor
        ``(2B, N', 1, 1)`` 1 on valid latent frames.
    """

    def __init__(self, merge, prediction: EditPrediction, scheduler, inpaint, passes: int, region: torch.Tensor,
                 start: torch.Tensor, corrections: torch.Tensor | None, keep: torch.Tensor) -> None:
        if not self.supports(scheduler):
            raise ValueError(f"Inpaint(resample={inpaint.resample!r}) needs the DDIM sampler (solver='ddim'), got "
                             f"{type(scheduler).__name__}")
        self.merge, self.prediction, self.scheduler, self.inpaint = merge, prediction, scheduler, inpaint
        self.passes = int(passes)
        self.b = prediction.batch_size
        self.region, self.corrections, self.keep = region, corrections, keep
        self.history = [start[:self.b]]          # the source's latents before each step
        self.generator = torch.Generator().manual_seed(int(inpaint.seed) + 1_000_003)
        self.extra_steps = 0                     # sampler steps run again

    @staticmethod
    def supports(scheduler) -> bool:
        """Whether ``scheduler`` steps without state (DDIM), so that steps can be run again."""
        return type(scheduler).__name__ == "DDIMScheduler"

    def _alpha(self, t) -> torch.Tensor:
        return self.scheduler.alphas_cumprod[int(t)].to(torch.float64)

    def renoise(self, ed: torch.Tensor, t_from, t_to) -> torch.Tensor:
        """``ed`` ``(B, N', P, Dz)`` at the noise level of timestep ``t_from`` noised to that of ``t_to``."""
        ratio = self._alpha(t_to) / self._alpha(t_from)
        eps = torch.randn(ed.shape, generator=self.generator, dtype=torch.float32).to(ed)
        return float(ratio.sqrt()) * ed + float((1 - ratio).sqrt()) * eps

    def __call__(self, info: StepInfo, z: torch.Tensor) -> torch.Tensor:
        b = self.b
        z = self.merge(info, z)
        self.history.append(z[:b] * self.keep[:b])
        i, steps = info.index, info.num_steps
        if not self.inpaint.resampling(info.fraction, i, steps, self.passes):
            return z
        k0 = max(0, i + 1 - self.inpaint.jump)
        ts = self.scheduler.timesteps
        controller = self.prediction.controller
        stores, controller.stores = controller.stores, {}
        try:
            for _ in range(self.passes - 1):
                ed = self.renoise(z[b:], ts[i + 1], ts[k0])
                ed = self.region * ed + (1.0 - self.region) * self.history[k0]
                zz = torch.cat([self.history[k0], ed]) * self.keep
                for k in range(k0, i + 1):
                    t = ts[k]
                    step = StepInfo(k, steps, float(t), self.prediction.guided(float(t)), b)
                    out = self.prediction(self.scheduler.scale_model_input(zz, t), t, step)
                    zz = self.scheduler.step(out, t, zz).prev_sample
                    if self.corrections is not None:
                        zz = zz + self.corrections[k]
                    zz = self.merge(step, torch.cat([self.history[k + 1], zz[b:]])) * self.keep
                    self.extra_steps += 1
                z = zz
        finally:
            controller.stores = stores
        return z


def edit_latents(denoiser: Denoiser, scheduler, controller: EditController, *, source: TextContext,
                 target: TextContext | None, null: TextContext | Sequence[TextContext] | None,
                 noise: torch.Tensor, frame_mask: torch.Tensor | None = None,
                 guidance_scale: "float | Guidance" = 7.5,
                 num_steps: int = 50, corrections: torch.Tensor | None = None, progress: bool = False,
                 generator: torch.Generator | None = None, edited_noise: torch.Tensor | None = None,
                 region_prior: torch.Tensor | None = None) -> EditRun:
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
        ``(S, B, N', P, Dz)`` added to both branches after step ``i`` (exact inversion); only to the
        source when the edited sample has its own noise (they belong to the source's trajectory).
    edited_noise : torch.Tensor, optional
        ``(B, N', P, Dz)`` the edited sample's own initial noise. Default: the source's ``noise``, or,
        when an edit asks for its own (:attr:`EditSpec.edited_seed
        <salad_core.attention.edits.EditSpec.edited_seed>`), :func:`seeded_noise` of that seed.
    region_prior : torch.Tensor, optional
        ``(B, N', P, Dz)`` clean latents pasted into the in-painting region for the steps before
        :meth:`Inpaint.prior_release <salad_core.attention.inpaint.Inpaint.prior_release>` (``Inpaint(prior="prompt")``):
        there the region's latents are ``sqrt(a_t) prior + sqrt(1 - a_t) eps`` at each step's level ``t`` (``eps``: the
        edited branch's initial noise), the kept region the source's as always. Needs an :class:`Inpaint` and the
        scheduler's ``alphas_cumprod``.

    Returns
    -------
    EditRun
    """
    if noise.dim() != 4:
        raise ValueError(f"noise must be (B, N', P, Dz), got shape {tuple(noise.shape)}")
    b, n = noise.shape[:2]
    if controller.batch != b:
        raise ValueError(f"the controller pairs {controller.batch} prompts but the noise has batch {b}")
    if corrections is not None and tuple(corrections.shape) != (num_steps, *noise.shape):
        raise ValueError(f"corrections must have shape {(num_steps, *noise.shape)}, got {tuple(corrections.shape)}")
    if frame_mask is None:
        frame_mask = torch.ones(b, n, dtype=torch.bool, device=noise.device)
    elif tuple(frame_mask.shape) != (b, n):
        raise ValueError(f"frame_mask must be (B, N') = {(b, n)}, got {tuple(frame_mask.shape)}")
    frame_mask = frame_mask.to(device=noise.device, dtype=torch.bool)
    prediction = EditPrediction(denoiser, controller, source=source, target=target, null=null,
                                frame_mask=frame_mask, guidance=guidance_scale, num_steps=num_steps)
    k = prediction.branches
    seeds = [e.edited_seed for e in controller.edits if e.edited_seed is not None]
    if edited_noise is None and seeds and prediction.edited:
        edited_noise = seeded_noise(seeds[0], noise.shape).to(noise)
    elif edited_noise is not None and tuple(edited_noise.shape) != tuple(noise.shape):
        raise ValueError(f"edited_noise must have the noise's shape {tuple(noise.shape)}, got "
                         f"{tuple(edited_noise.shape)}")
    take = take_of(controller.edits) if prediction.edited else None
    edited_corrections = None
    if take is not None:
        # mirroring a take (MirrorTake): the chosen parts start from the mirror image's inverted noise and take
        # its corrections, the other parts the source's
        if edited_noise is not None:
            raise ValueError("MirrorTake gives the edited sample its noise (the mirror's); it cannot be combined "
                             "with edited_noise or an edit with its own seed (ExampleBased)")
        take.check(noise, num_steps)
        take_mask = take.mask(noise.shape[2]).to(noise)
        mirror_traj = take.mirrored.trajectory
        edited_noise = composite(take_mask, take.mirrored.noise, noise, noise)
        edited_corrections = composite(take_mask, take.mirrored.corrections, corrections,
                                       torch.zeros(num_steps, *noise.shape, dtype=noise.dtype))
    inpaint = latent_edit(controller) if prediction.edited else None
    region = hook = None
    if inpaint is not None:
        region = inpaint.mask(frame_mask, noise.shape[2]).to(noise)
        if inpaint.fresh_noise(corrections is not None):
            # the regenerated region starts from new noise drawn from the seed (an inverted take's own noise holds
            # its motion there; "matched": shaped to the source noise's statistics) and without the inversion's
            # corrections (they belong to the source's trajectory)
            fresh = (region > 0).to(noise)
            base = noise if edited_noise is None else edited_noise.to(noise)
            edited_noise = fresh * inpaint.region_noise(noise, frame_mask) + (1.0 - fresh) * base
            if corrections is not None or edited_corrections is not None:
                base_c = edited_corrections if edited_corrections is not None else corrections
                edited_corrections = base_c * (1.0 - fresh)
    release = 0
    if region_prior is not None:
        if inpaint is None:
            raise ValueError("region_prior pastes latents into an in-painting region: the edits have no Inpaint")
        if tuple(region_prior.shape) != tuple(noise.shape):
            raise ValueError(f"region_prior must have the noise's shape {tuple(noise.shape)}, got "
                             f"{tuple(region_prior.shape)}")
        if not hasattr(scheduler, "alphas_cumprod") or float(scheduler.init_noise_sigma) != 1.0:
            raise ValueError(f"Inpaint(prior='prompt') noises the pasted motion by the forward process and needs a "
                             f"variance-preserving scheduler (alphas_cumprod, unscaled inputs: DDIM, DPM-Solver++), "
                             f"got {type(scheduler).__name__}")
        release = inpaint.prior_release(num_steps, corrections is not None)
        if release > 0 and edited_noise is None:
            # the region gets its own start; the edited branch keeps the source's noise and corrections elsewhere
            edited_noise = noise.clone()
            if corrections is not None and edited_corrections is None:
                edited_corrections = corrections
    own_noise = edited_noise is not None and prediction.edited
    # both branches start from the same noise (Algorithm 1, line 4) and take the same corrections,
    # unless the edited sample has its own noise: then the corrections are the source's alone (a
    # mirrored take's: the mirror's on the mirrored parts)
    latents = torch.cat([noise, edited_noise.to(noise)]) if own_noise else torch.cat([noise] * k)
    if edited_corrections is not None:
        corrections = torch.cat([torch.zeros_like(edited_corrections) if corrections is None else corrections,
                                 edited_corrections], 1)
    elif corrections is not None:
        corrections = (torch.cat([corrections, torch.zeros_like(corrections)], 1) if own_noise
                       else corrections.repeat(1, k, 1, 1, 1))
    pasted = None
    if release > 0:
        # paste, then harmonise: the region follows the prior's forward-noised latents until step `release`
        scheduler.set_timesteps(num_steps)
        eps = edited_noise.to(noise)
        prior = region_prior.to(noise)

        def pasted(level: int) -> torch.Tensor:
            """The region's latents at the level of the sampler's step ``level`` (its input)."""
            a = float(scheduler.alphas_cumprod[int(scheduler.timesteps[level])])
            return a ** 0.5 * prior + (1.0 - a) ** 0.5 * eps

        edited_noise = region * pasted(0) + (1.0 - region) * eps
        latents = torch.cat([noise, edited_noise])
    if inpaint is not None or take is not None:
        def hook(info, z: torch.Tensor) -> torch.Tensor:
            src, ed = z[:b], z[b:]
            if pasted is not None and info.index + 1 < release:
                ed = region * pasted(info.index + 1) + (1.0 - region) * ed
            if take is not None:
                # the other parts: the source branch's latents of this step; the mirrored parts: the mirror's
                # inversion trajectory (the latents after step i are trajectory[i + 1])
                if take.keeping(info.fraction):
                    ed = ed * take_mask + src * (1.0 - take_mask)
                if take.following(info.fraction):
                    ed = ed * (1.0 - take_mask) + mirror_traj[info.index + 1].to(ed) * take_mask
            if inpaint is not None and inpaint.active(info.fraction):
                # in-painting: after each step the edited latents outside the region are the source's of that step
                ed = ed * region + src * (1.0 - region)
            return torch.cat([src, ed])
        # resample="auto" resamples with the DDIM sampler only; an explicit resample > 1 refuses other solvers
        passes = 1 if inpaint is None else inpaint.passes_for(corrections is not None)
        if passes > 1 and (inpaint.resample != "auto" or Resampler.supports(scheduler)):
            keep = frame_mask.repeat(k, 1)[:, :, None, None].to(noise)
            hook = Resampler(hook, prediction, scheduler, inpaint, passes, region,
                             latents * scheduler.init_noise_sigma * keep, corrections, keep)
    z = denoise(denoiser, scheduler, latents=latents, frame_mask=frame_mask.repeat(k, 1),
                num_steps=num_steps, prediction=prediction, progress=progress, generator=generator,
                corrections=corrections, latent_hook=hook)
    log.debug("edit loop: %d steps, %d forward rows, %d probe steps", num_steps, controller.rows_total,
              controller.probe_steps)
    return EditRun(z[:b], z[b:] if prediction.edited else None, controller.rows_total, controller.probe_steps,
                   edited_noise if own_noise else None, region)
