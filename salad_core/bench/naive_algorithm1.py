"""A reference for the ``overheads`` section: SALAD's Algorithm 1 written as the official code runs it.

Three separate guided forwards per denoising step (source, probe, edited), eager attention
everywhere, the cross-attention maps passed between them by hand: the structure of the official
``Text2Motion.edit``. ``salad bench`` times it beside :meth:`~salad_core.pipeline.SaladPipeline.edit`
(which batches the three rows into one forward) to show what the batched layout saves.
"""
from __future__ import annotations

import torch

from salad_core.sampling import make_scheduler

from .plan import GUIDANCE

__all__ = ["naive_algorithm1"]


def naive_algorithm1(pipe, source: str, target: str, edits, length: int, steps: int) -> torch.Tensor:
    """Three separate guided forwards per step (source, probe, edited; eager attention everywhere),
    the maps passed between them: the structure of the official ``Text2Motion.edit``."""
    from salad_core.attention import EditController, TokenInfo
    from salad_core.models.attention import EagerProcessor, use_processors
    from salad_core.models.denoiser import TextContext
    from salad_core.sampling import StepInfo

    den = pipe.denoiser
    ts, null = pipe.encode_text([source])
    tt = pipe.text_encoder.encode([target])
    width = max(ts.features.shape[1], tt.features.shape[1], null.features.shape[1])
    ctrl = EditController(edits, TokenInfo.from_batch(ts), TokenInfo.from_batch(tt), width, cfg=True, probe=True)

    def both(ctx):
        return TextContext.concat([den.prepare_text(null.features, null.mask), ctx])

    cs, ct = both(den.prepare_text(ts.features, ts.mask)), both(den.prepare_text(tt.features, tt.mask))
    noise = pipe.make_noise([0], length // pipe.skeleton.unit_length)
    sched = make_scheduler(pipe.diffusion, "ddim")
    sched.set_timesteps(steps)
    z, ze = noise.clone(), noise.clone()
    pad = lambda p: torch.nn.functional.pad(p, (0, width - p.shape[-1]))  # noqa: E731
    with torch.inference_mode():
        for i, t in enumerate(sched.timesteps):
            ctrl.on_step(StepInfo(i, steps, float(t), True, 1))
            src, own = {}, {}

            def record(store):
                def fn(site, probs):
                    store[site.name] = probs[1:].clone()
                return fn

            def edit(site, probs):
                if site.kind != "cross":
                    return None
                m = pad(src[site.name].view(1, site.heads, site.frames, site.parts, -1))
                o = pad(own[site.name].view(1, site.heads, site.frames, site.parts, -1))
                new = ctrl.edit_cross(m, o)[..., :site.tokens]
                out = probs.clone()
                out[1:] = new.reshape(1, site.heads, -1, site.tokens)
                return out

            outs = []
            for x, ctx, ctl in ((z, cs, record(src)), (ze, ct, record(own)), (ze, ct, edit)):
                with use_processors(den, EagerProcessor(ctl)):
                    u, c = den(torch.cat([x, x]), t.reshape(1), text_context=ctx).chunk(2)
                outs.append(u + GUIDANCE * (c - u))
            z = sched.step(outs[0], t, z).prev_sample
            ze = sched.step(outs[2], t, ze).prev_sample
    pipe.decode(torch.cat([z, ze]), [length, length])
    return ze
