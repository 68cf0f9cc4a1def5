"""In-painting's paste-then-harmonise prior (``Inpaint(prior="prompt")``, issue 67): the spec, where the pasted motion
comes from and goes, and its effect on the edit loop with the shipped weights (few steps, one thread)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from salad_core.attention import Inpaint
from salad_core.attention.editing import edit_latents
from salad_core.attention.inpaint import PRIOR_MODES
from _weights import needs_weights

STEPS = 8
FRAMES = 64
SOURCE = "a person walks forward"
TARGET = "a person jumps"



# ------------------------------------------------------------------------------ the spec
@pytest.mark.parametrize("kwargs, match", [
    (dict(prior="generated"), r"Inpaint.prior='generated'; allowed: \('auto', 'none', 'prompt'\)"),
    (dict(prior="prompt", prior_strength=0), r"prior_strength=0 must be a number in \(0, 1\]"),
    (dict(prior="prompt", prior_strength=1.5), r"prior_strength=1.5 must be a number in \(0, 1\]"),
    (dict(prior="prompt", prior_strength=True), r"prior_strength=True must be a number"),
])
def test_bad_prior_options_are_refused_by_name(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Inpaint(frames=(16, 32), **kwargs)


def test_prior_release_is_the_first_free_step():
    assert PRIOR_MODES == ("auto", "none", "prompt")
    assert Inpaint(frames=(16, 32), prior="none").prior_release(50) == 0         # no prior: free from the start
    assert Inpaint(frames=(16, 32), prior="prompt", prior_strength=0.5).prior_release(50) == 25
    assert Inpaint(frames=(16, 32), prior="prompt", prior_strength=0.7).prior_release(50) == 15
    assert Inpaint(frames=(16, 32), prior="prompt", prior_strength=1.0).prior_release(50) == 0
    assert Inpaint(frames=(16, 32), prior="prompt", prior_strength=0.5).prior_release(8) == 4


def test_auto_prior_pastes_where_it_was_chosen():
    """``prior="auto"``: the prompt's sample for body parts of an inverted take (instead of RePaint's resampling), for
    its frame spans and for a frame span of a generated source; nothing for a generated source's parts."""
    from salad_core.attention.inpaint import PARTS_RESAMPLE, PRIOR_STRENGTH, SPAN_PRIOR_STRENGTH

    parts, span = Inpaint(parts="arms"), Inpaint(frames=(16, 32))
    assert parts.prior_for(inverted=True) == "prompt" and parts.passes_for(inverted=True) == 1
    assert parts.prior_for(inverted=False) == "none" and parts.passes_for(inverted=False) == 1
    assert span.prior_for(inverted=False) == "prompt" and span.prior_for(inverted=True) == "prompt"
    # held longer for an inverted take's span (its candidates are ranked by how closely they follow it)
    assert PRIOR_STRENGTH == 0.5 and SPAN_PRIOR_STRENGTH == 0.7
    assert span.prior_strength_for(False) == 0.5 and span.prior_strength_for(True) == 0.7
    assert parts.prior_strength_for(True) == 0.5
    assert Inpaint(frames=(16, 32), prior_strength=0.6).prior_strength_for(True) == 0.6
    assert span.prior_release(50, inverted=False) == 25 and span.prior_release(50, inverted=True) == 15
    # without the prior an inverted take's parts are resampled as before; a given mode is kept everywhere
    assert Inpaint(parts="arms", prior="none").passes_for(inverted=True) == PARTS_RESAMPLE
    assert Inpaint(frames=(16, 32), prior="prompt").prior_for(inverted=True) == "prompt"
    assert Inpaint(parts="arms", prior="none").prior_for(inverted=True) == "none"


def test_prior_window_pads_a_short_span_to_the_shortest_clip_and_pastes_its_middle():
    # a 16-frame span (latent frames 4..8) of a 64-frame motion: the prior is a 40-frame clip (10 latent frames),
    # whose middle 4 latent frames (3..7) go to the span
    assert Inpaint(frames=(16, 32), prior="prompt").prior_window(64, 40) == (4, 8, 40, 3)
    # a span longer than the shortest clip: the prior is the span itself
    assert Inpaint(frames=(8, 56), prior="prompt").prior_window(64, 40) == (2, 14, 48, 0)
    # an open end: up to the motion's end
    assert Inpaint(frames=(40, None), prior="prompt").prior_window(64, 24) == (10, 16, 24, 0)
    # body parts alone: the whole motion
    assert Inpaint(parts="arms", prior="prompt").prior_window(64, 40) == (0, 16, 64, 0)


def test_prior_flags_reach_the_spec():
    from salad_core import cli
    from salad_core.cli._common import UserError
    from salad_core.cli.generate import INPAINT_PRIOR, _edit_specs

    assert INPAINT_PRIOR == PRIOR_MODES
    flags = ["edit", SOURCE, "--target", TARGET, "--inpaint", "@12:28", "--out", "x"]

    def spec(*extra):
        return _edit_specs(cli.build_parser().parse_args(flags + list(extra)))[0]

    assert spec().prior == "auto" and spec().prior_strength == "auto"
    got = spec("--inpaint-prior", "prompt", "--inpaint-prior-strength", "0.7")
    assert got.prior == "prompt" and got.prior_strength == 0.7
    with pytest.raises(UserError, match=r"--inpaint @12:28: Inpaint.prior_strength=2.0 must be a number in \(0, 1\]"):
        spec("--inpaint-prior", "prompt", "--inpaint-prior-strength", "2")


# ------------------------------------------------------------------------------ with the shipped weights
@pytest.fixture(scope="module")
def pipe(single_thread):
    from salad_core.pipeline import SaladPipeline

    return SaladPipeline.from_pretrained()


def _region(shape, s, e):
    m = torch.zeros(shape[:2], dtype=torch.bool)
    m[:, s:e] = True
    return m


@needs_weights
def test_pasted_prior_draws_the_region_towards_the_prompt_alone_and_keeps_the_rest(pipe):
    kw = dict(target=TARGET, lengths=FRAMES, seed=0, num_steps=STEPS)
    span = dict(frames=(16, 48), composite=False, blend=0, guidance=None, noise="fresh")
    plain = pipe.edit(SOURCE, edits=[Inpaint(**span, prior="none")], **kw)
    strong = pipe.edit(SOURCE, edits=[Inpaint(**span, prior="prompt", prior_strength=0.25)], **kw)
    weak = pipe.edit(SOURCE, edits=[Inpaint(**span, prior="prompt", prior_strength=0.75)], **kw)
    free = pipe.edit(SOURCE, edits=[Inpaint(**span, prior="prompt", prior_strength=1.0)], **kw)
    region = _region(plain.edited.latents.shape, 4, 12)
    # the source branch is never touched; outside the region the edit is the source
    for out in (strong, weak):
        torch.testing.assert_close(out.source.latents, plain.source.latents, atol=0, rtol=0)
        torch.testing.assert_close(out.edited.latents[~region], out.source.latents[~region], atol=0, rtol=0)
    # a prior released at the first step is only noise: the plain edit
    torch.testing.assert_close(free.edited.latents, plain.edited.latents, atol=0, rtol=0)
    # the settings say what was pasted and until which step; the auto prior of a generated span is the same edit
    assert strong.settings["inpaint_prior"] == strong.edited.settings["inpaint_prior"] == {
        "mode": "prompt", "strength": 0.25, "release_step": 6, "forward_rows": 2 * STEPS,
        "windows": [[4, 12, 40, 1]]}     # latent frames 4..12 <- the 40-frame prior's latent frames 1..9
    assert "inpaint_prior" not in plain.settings and "inpaint_prior" not in free.settings
    assert plain.prior is None and free.prior is None
    # the pasted motion itself comes with the edit: the target alone, 40 frames, decoded
    assert strong.prior.texts == [TARGET] and strong.prior.lengths == [40]
    assert strong.prior.joints[0].shape == (40, 22, 3)
    auto = pipe.edit(SOURCE, edits=[Inpaint(**span)], **kw)
    half = pipe.edit(SOURCE, edits=[Inpaint(**span, prior="prompt", prior_strength=0.5)], **kw)
    torch.testing.assert_close(auto.edited.latents, half.edited.latents, atol=0, rtol=0)
    # what was pasted: the target sampled alone over the span (32 frames, padded to the 40-frame shortest clip)
    inp = Inpaint(**span, prior="prompt")
    text, null = pipe.encode_text([TARGET])
    prior, alone = pipe._inpaint_prior(inp, text, null, [FRAMES], FRAMES // 4, pipe.resolve_guidance(None), STEPS,
                                       "ddim")
    torch.testing.assert_close(prior[region], alone.latents[:, 1:9].reshape(prior[region].shape), atol=0, rtol=0)
    torch.testing.assert_close(alone.latents, strong.prior.latents, atol=0, rtol=0)
    assert tuple(prior.shape) == tuple(plain.edited.latents.shape)
    assert prior[~region].abs().max() == 0 and prior[region].abs().mean() > 0.1

    def dist(out):
        return float((out.edited.latents[region] - prior[region]).pow(2).mean().sqrt())

    # the longer the prior is held, the closer the region ends to it
    assert dist(strong) < dist(weak) < dist(plain)
    assert dist(strong) < 0.6 * dist(plain)


@needs_weights
def test_prior_of_body_parts_pastes_the_whole_motions_parts(pipe):
    kw = dict(target="a man waves his right hand", lengths=FRAMES, seed=0, num_steps=STEPS)
    arms = dict(parts="arms", composite=False, noise="fresh", resample=1)
    # the plain edit from another seed (from the same seed its region starts from the prior's own noise)
    plain = pipe.edit(SOURCE, edits=[Inpaint(**arms, seed=1, prior="none")], **kw)
    pasted = pipe.edit(SOURCE, edits=[Inpaint(**arms, prior="prompt", prior_strength=0.25)], **kw)
    text, null = pipe.encode_text(["a man waves his right hand"])
    prior, _ = pipe._inpaint_prior(Inpaint(**arms, prior="prompt"), text, null, [FRAMES], FRAMES // 4,
                                   pipe.resolve_guidance(None), STEPS, "ddim")
    from salad_core.skeleton import PART_NAMES

    part = [PART_NAMES.index("left arm"), PART_NAMES.index("right arm")]
    kept = [p for p in range(7) if p not in part]
    torch.testing.assert_close(pasted.edited.latents[:, :, kept], pasted.source.latents[:, :, kept], atol=0, rtol=0)
    # the prior is a whole-length sample: the arms of every frame are pasted, nothing else
    assert bool((prior[:, :, part].abs().amax(dim=(2, 3)) > 0).all()) and prior[:, :, kept].abs().max() == 0
    near = float((pasted.edited.latents[:, :, part] - prior[:, :, part]).pow(2).mean())
    far = float((plain.edited.latents[:, :, part] - prior[:, :, part]).pow(2).mean())
    assert near < 0.6 * far


@needs_weights
def test_prior_with_candidates_pastes_each_seeds_own_sample(pipe):
    """Each candidate seed samples its own prior, so ranked candidates differ in what was pasted."""
    text, null = pipe.encode_text([TARGET])
    g = pipe.resolve_guidance(None)
    a, _ = pipe._inpaint_prior(Inpaint(frames=(16, 48), prior="prompt", seed=0), text, null, [FRAMES], 16, g, 4,
                               "ddim")
    b, _ = pipe._inpaint_prior(Inpaint(frames=(16, 48), prior="prompt", seed=1), text, null, [FRAMES], 16, g, 4,
                               "ddim")
    again, _ = pipe._inpaint_prior(Inpaint(frames=(16, 48), prior="prompt", seed=0), text, null, [FRAMES], 16, g, 4,
                                   "ddim")
    torch.testing.assert_close(a, again, atol=0, rtol=0)
    assert (a - b).abs().mean() > 0.1


def test_edit_latents_refuses_a_prior_without_inpaint_or_of_the_wrong_shape():
    from diffusers import EulerDiscreteScheduler

    from salad_core.attention.controller import EditController
    from salad_core.attention.capture import TokenInfo
    from salad_core.models.denoiser import TextContext

    noise = torch.zeros(1, 4, 7, 4)
    ctx = TextContext(torch.zeros(1, 3, 8), torch.ones(1, 3, dtype=torch.bool))
    tokens = TokenInfo(prompts=["a b"], tokens=[["<s>", "a", "b"]], token_to_word=[[None, 0, 1]], words=[["a", "b"]])

    def call(edits, prior, scheduler=None):
        controller = EditController(edits, tokens, tokens, 3, cfg=False)
        return edit_latents(torch.nn.Identity(), scheduler, controller, source=ctx, target=ctx, null=None,
                            noise=noise, guidance_scale=1.0, num_steps=2, region_prior=prior)

    with pytest.raises(ValueError, match="region_prior pastes latents into an in-painting region: the edits have no "
                                         "Inpaint"):
        call([], torch.zeros_like(noise))
    with pytest.raises(ValueError, match=r"region_prior must have the noise's shape \(1, 4, 7, 4\)"):
        call([Inpaint(frames=(4, 8), prior="prompt")], torch.zeros(1, 3, 7, 4))
    with pytest.raises(ValueError, match="needs a variance-preserving scheduler"):
        call([Inpaint(frames=(4, 8), prior="prompt")], torch.zeros_like(noise),
             EulerDiscreteScheduler(num_train_timesteps=1000))
