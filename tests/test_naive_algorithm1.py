"""salad_core.bench.naive_algorithm1: the official code's three-forward Algorithm 1, run by the one
denoising loop, edits exactly as the batched ``SaladPipeline.edit(probe=True)`` does."""
from __future__ import annotations

import pytest
import torch

from salad_core.attention import Refine
from salad_core.bench import REFINED, SOURCE
from salad_core.bench.naive_algorithm1 import NaiveAlgorithm1Prediction, naive_algorithm1


@pytest.fixture(scope="module")
def tiny_pipe(make_tiny_pipeline, single_thread):
    return make_tiny_pipeline(seed=0)


def test_naive_algorithm1_equals_the_batched_edit_with_a_probe(tiny_pipe):
    calls = []
    handle = tiny_pipe.denoiser.register_forward_hook(lambda mod, args, out: calls.append(out.shape[0]))
    try:
        naive = naive_algorithm1(tiny_pipe, SOURCE, REFINED, [Refine()], length=24, steps=4)
    finally:
        handle.remove()
    # three guided forwards (2 rows each: unconditional, conditional) per step
    assert calls == [2] * 3 * 4
    out = tiny_pipe.edit(SOURCE, REFINED, edits=[Refine()], lengths=24, seed=0, num_steps=4, probe=True,
                         solver="ddim", guidance_scale=7.5)
    batched = out.edited.latents
    assert naive.shape == batched.shape == (1, 6, *tiny_pipe.latent_shape)
    # same edit, other kernels (eager softmax vs the folded cross-attention): float rounding only
    assert torch.allclose(naive, batched, atol=1e-4, rtol=0)
    # and it is an edit: the refined prompt's motion differs from the source's
    assert (naive - out.source.latents).abs().max() > 0.05


def test_naive_prediction_refuses_unguided_sampling(tiny_pipe):
    from salad_core.attention import EditController, TokenInfo

    den = tiny_pipe.denoiser
    ts, null = tiny_pipe.encode_text([SOURCE])
    ctx = den.prepare_text(ts.features, ts.mask)
    ctrl = EditController([Refine()], TokenInfo.from_batch(ts), TokenInfo.from_batch(ts), ts.features.shape[1],
                          cfg=True, probe=True)
    with pytest.raises(ValueError, match="guidance scale 1.0"):
        NaiveAlgorithm1Prediction(den, ctrl, source=ctx, target=ctx, null=den.prepare_text(null.features, null.mask),
                                  guidance=1.0)
