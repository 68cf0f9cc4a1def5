"""A reference for the ``overheads`` section: SALAD's Algorithm 1 written as the official code runs it.

Three separate guided forwards per denoising step (source, probe, edited), eager attention
everywhere, the cross-attention maps passed between them by hand: the structure of the official
``Text2Motion.edit``. ``salad bench`` times it beside :meth:`~salad_core.pipeline.SaladPipeline.edit`
(which batches the rows into one forward) to show what the batched layout saves.

The loop is :func:`salad_core.sampling.denoise` over the stacked latents ``[z (B); z* (B)]``, as
Algorithm 1 of the supplement writes it; :class:`NaiveAlgorithm1Prediction` is its strategy.
"""
from __future__ import annotations

from contextlib import nullcontext
from typing import Any, ContextManager, Sequence

import torch
import torch.nn.functional as F

from salad_core.models.attention import EagerProcessor, SiteInfo, use_processors
from salad_core.models.denoiser import Denoiser, TextContext
from salad_core.sampling import Guidance, StepInfo, as_guidance, denoise, make_scheduler

from .plan import GUIDANCE

__all__ = ["NaiveAlgorithm1Prediction", "naive_algorithm1"]


class NaiveAlgorithm1Prediction:
    """Algorithm 1 with three separate guided forwards per step, as a :class:`~salad_core.sampling.Prediction`.

    The latents it predicts for are the stacked ``[z (B); z* (B)]`` (source, edited). Per step:
    the source ``Denoise(z_t, t, c)`` records its conditional cross maps ``M``, the probe
    ``Denoise(z*_t, t, c*)`` records the target's own ``M*`` (its prediction is discarded), and the
    edited ``Denoise(z*_t, t, c*){M <- M_hat}`` replaces every conditional cross map by
    ``controller.edit_cross(M, M*)``. Each forward has its unconditional and conditional rows
    (``2 B``), eager attention at every site; guidance combines each (eq. 9). The probe runs at
    every step (also where the edit does not read ``M*``), as in the official code.

    Parameters
    ----------
    denoiser : Denoiser
    controller : salad_core.attention.EditController
        Built with ``cfg=True``; its :meth:`edit_cross` builds ``M_hat`` ``(B, H, N', P, W)`` with
        ``W = controller.width``.
    source, target, null : TextContext
        ``[null (B); source (B)]`` and ``[null (B); target (B)]`` are the two texts of the forwards.
    guidance : float or Guidance
        The CFG weight ``w`` (must guide: ``w != 1``).
    """

    desc = "naive Algorithm 1"

    def __init__(self, denoiser: Denoiser, controller, *, source: TextContext, target: TextContext,
                 null: TextContext, guidance: "float | Guidance" = GUIDANCE) -> None:
        self.model, self.controller = denoiser, controller
        self.guidance = as_guidance(guidance)
        if not self.guidance.cfg or not controller.cfg:
            raise ValueError(f"the naive Algorithm 1 runs guided forwards: guidance scale {self.guidance.scale} and "
                             f"controller cfg={controller.cfg} (need a scale != 1 and cfg=True)")
        b = self.batch_size = controller.batch
        for name, ctx in (("source", source), ("target", target)):
            if ctx.batch_size != b:
                raise ValueError(f"{name} has {ctx.batch_size} prompts; the controller pairs {b}")
        nulls = null.repeat(b) if null.batch_size != b else null
        self.source_text = TextContext.concat([nulls, source])
        self.target_text = TextContext.concat([nulls, target])

    def session(self, timesteps: torch.Tensor, num_train_timesteps: int) -> ContextManager[Any]:
        return nullcontext()      # no per-call caches: each forward installs its own processors

    def guided(self, timestep: float) -> bool:
        return True

    def _forward(self, x: torch.Tensor, t: torch.Tensor, text: TextContext, hook) -> torch.Tensor:
        """One guided forward of ``x (B, N', P, Dz)``, ``hook(site, probs)`` at every site."""
        with use_processors(self.model, EagerProcessor(hook)):
            uncond, cond = self.model(torch.cat([x, x]), t, text_context=text).chunk(2)
        return self.guidance.combine(uncond, cond)                              # eq. 9

    def _named(self, site: SiteInfo, probs: torch.Tensor) -> torch.Tensor:
        """Flat conditional cross probabilities ``(B, H, N'P, W_site)`` -> ``(B, H, N', P, W)``."""
        named = probs.view(self.batch_size, site.heads, site.frames, site.parts, -1)
        return F.pad(named, (0, self.controller.width - named.shape[-1]))

    def __call__(self, z: torch.Tensor, t: torch.Tensor, info: StepInfo) -> torch.Tensor:
        """Guided predictions ``(2 B, N', P, Dz)`` of the stacked latents ``z = [z (B); z* (B)]``."""
        b = self.batch_size
        self.controller.on_step(info)
        zs, ze = z[:b], z[b:]
        t = t.reshape(1).to(z.device)
        source_maps: dict[str, torch.Tensor] = {}
        own_maps: dict[str, torch.Tensor] = {}

        def record(store: dict[str, torch.Tensor]):
            def hook(site: SiteInfo, probs: torch.Tensor) -> None:
                if site.kind == "cross":
                    store[site.name] = probs[b:].clone()        # the conditional rows' maps
            return hook

        def edit(site: SiteInfo, probs: torch.Tensor) -> torch.Tensor | None:
            if site.kind != "cross":
                return None
            m_hat = self.controller.edit_cross(self._named(site, source_maps[site.name]),
                                               self._named(site, own_maps[site.name]))
            out = probs.clone()
            out[b:] = m_hat[..., :site.tokens].reshape(b, site.heads, -1, site.tokens)
            return out

        source = self._forward(zs, t, self.source_text, record(source_maps))   # Denoise(z_t, t, c): M
        self._forward(ze, t, self.target_text, record(own_maps))               # probe: M*, output discarded
        edited = self._forward(ze, t, self.target_text, edit)                  # Denoise(z*_t, t, c*){M <- M_hat}
        return torch.cat([source, edited])


def naive_algorithm1(pipe, source: str, target: str, edits: Sequence, length: int, steps: int) -> torch.Tensor:
    """Edit ``source`` into ``target`` with :class:`NaiveAlgorithm1Prediction` (DDIM, guidance
    :data:`~salad_core.bench.plan.GUIDANCE`, seed 0), decode both motions, and return the edited
    latents ``(1, N', P, Dz)``: the whole call ``salad bench`` times (text, denoising, decoding).

    Parameters
    ----------
    pipe : SaladPipeline
    source, target : str
        The prompts.
    edits : sequence of EditSpec
    length : int
        Motion length in frames (a multiple of the skeleton's unit length).
    steps : int
        DDIM steps.
    """
    from salad_core.attention import EditController, TokenInfo

    den = pipe.denoiser
    ts, null = pipe.encode_text([source])
    tt = pipe.text_encoder.encode([target])
    width = max(ts.features.shape[1], tt.features.shape[1], null.features.shape[1])
    ctrl = EditController(edits, TokenInfo.from_batch(ts), TokenInfo.from_batch(tt), width, cfg=True, probe=True)
    prediction = NaiveAlgorithm1Prediction(den, ctrl, source=den.prepare_text(ts.features, ts.mask),
                                           target=den.prepare_text(tt.features, tt.mask),
                                           null=den.prepare_text(null.features, null.mask))
    noise = pipe.make_noise([0], length // pipe.skeleton.unit_length)
    # both branches start from the same noise (Algorithm 1, line 4)
    z = denoise(den, make_scheduler(pipe.diffusion, "ddim"), latents=torch.cat([noise, noise]),
                num_steps=steps, prediction=prediction)
    pipe.decode(z, [length, length])
    return z[1:]
