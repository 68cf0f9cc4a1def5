"""Hooks and caches on every attention site: names, read-only equivalence, replacement against
references, scoping, errors, and what run_with_cache keeps."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from salad_core.attention import CaptureConfig, hook_point_names, select_hook_points, use_hooks
from salad_core.models.attention import EagerProcessor, SDPAProcessor, use_processors
from salad_core.models.denoiser import Denoiser
from salad_core.pipeline import SaladPipeline
from salad_core.sampling import denoise, make_scheduler
from salad_core.skeleton import NUM_PARTS

PROMPTS = ["a man does a cartwheel and walks", "a person jumps high"]
LENGTHS = [40, 28]
STEPS = 6
SEED = 3

pytestmark = pytest.mark.usefixtures("single_thread")


def _run(pipe, **kwargs):
    return pipe(PROMPTS, lengths=LENGTHS, num_steps=STEPS, seed=SEED, **kwargs)


@pytest.fixture(scope="module")
def plain(pipe):
    return _run(pipe)


def _nothing_installed(den: Denoiser) -> bool:
    plain_processors = all(isinstance(p, SDPAProcessor) for p in den.attn_processors.values())
    no_module_hooks = all(not m._forward_hooks and not m._forward_pre_hooks for m in den.modules())
    return plain_processors and no_module_hooks


def _copy_pipeline(pipe: SaladPipeline) -> SaladPipeline:
    den = Denoiser(pipe.denoiser.config)
    den.load_state_dict(pipe.denoiser.state_dict())
    return SaladPipeline(pipe.vae, den, pipe.text_encoder, pipe.mean, pipe.std)


# ------------------------------------------------------------------------------------ names
def test_hook_point_names_are_pinned(pipe):
    names = hook_point_names(pipe.denoiser)
    assert len(names) == 3 * 3 * 5                                     # 3 layers x 3 sites x 5 points
    assert names[:10] == ["layers.0.temporal", "layers.0.temporal.out", "layers.0.temporal.q", "layers.0.temporal.k",
                          "layers.0.temporal.v", "layers.0.skeletal", "layers.0.skeletal.out", "layers.0.skeletal.q",
                          "layers.0.skeletal.k", "layers.0.skeletal.v"]
    assert names[-5:] == ["layers.2.cross", "layers.2.cross.out", "layers.2.cross.q", "layers.2.cross.k",
                          "layers.2.cross.v"]
    # every site name of the model is a hook point (its probabilities)
    assert set(pipe.denoiser.attention_sites) <= set(names)


def test_select_hook_points_filters_by_name_layer_and_store(pipe):
    den = pipe.denoiser

    def names(**kw):
        return [hp.name for hp in select_hook_points(den, **kw)]

    assert names(names="layers.1.cross") == ["layers.1.cross"]
    assert names(names="layers.*.cross") == ["layers.0.cross", "layers.1.cross", "layers.2.cross"]
    assert names(names="layers.1.cross", store="outputs") == ["layers.1.cross.out"]
    assert names(names="layers.1.cross", store=("probs", "inputs")) == [
        "layers.1.cross", "layers.1.cross.q", "layers.1.cross.k", "layers.1.cross.v"]
    assert names(names=lambda n: n.endswith("skeletal"), layers=[0, 2]) == ["layers.0.skeletal", "layers.2.skeletal"]
    assert names(names=["layers.0.temporal", "layers.2.*.out"], store=("probs", "outputs")) == [
        "layers.0.temporal", "layers.0.temporal.out", "layers.2.temporal.out", "layers.2.skeletal.out",
        "layers.2.cross.out"]
    assert len(names()) == 9 and len(names(layers=1, store=("probs", "inputs", "outputs"))) == 15
    with pytest.raises(KeyError, match=r"no hook point matches 'layers.7.cross'.*layers.0.temporal.out"):
        select_hook_points(den, "layers.7.cross")
    with pytest.raises(ValueError, match="store='logits' is unknown"):
        select_hook_points(den, store="logits")
    with pytest.raises(ValueError, match=r"layers=\[5\]: the denoiser has layers 0..2"):
        select_hook_points(den, layers=[5])


# -------------------------------------------------------------------------- reading hooks
def test_read_only_hooks_at_every_point_see_everything_and_change_nothing(pipe, plain):
    seen = []

    def read(t, ctx):
        assert t.dim() == len(ctx.axes) and ctx.axes[0] == "batch"
        assert t.shape[0] == 4 and ctx.cond == slice(2, 4) and ctx.uncond == slice(0, 2)   # [uncond; cond]
        if ctx.point == "probs":
            torch.testing.assert_close(t.sum(-1), torch.ones_like(t.sum(-1)), rtol=0, atol=1e-5)
        if ctx.point == "out":
            assert t.shape[1:] == (10, NUM_PARTS, 32)
        seen.append((ctx.name, ctx.step, ctx.p, ctx.layer, ctx.kind))

    out = _run(pipe, hooks=[("*", read)])
    assert torch.equal(out.latents, plain.latents) and np.array_equal(out.features, plain.features)   # bit for bit
    names = hook_point_names(pipe.denoiser)
    assert len(seen) == len(names) * STEPS
    assert {(n, s) for n, s, *_ in seen} == {(n, s) for n in names for s in range(STEPS)}
    assert all(math.isclose(p, s / STEPS) for _, s, p, *_ in seen)
    assert {(n, layer, kind) for n, _, _, layer, kind in seen if n == "layers.2.skeletal.out"} == {
        ("layers.2.skeletal.out", 2, "skeletal")}
    assert _nothing_installed(pipe.denoiser)


def test_hooks_with_capture_share_the_processors_and_capture_sees_the_replacement(pipe, plain):
    """Identity replacements keep the motion bit for bit; a uniform replacement of the cond rows'
    cross maps is what the captured maps show."""
    out = _run(pipe, hooks=[("layers.*.cross", lambda t, ctx: t.clone())], capture_attention=True)
    assert torch.equal(out.latents, plain.latents)
    reference = _run(pipe, capture_attention=True).attention
    np.testing.assert_array_equal(out.attention.cross_map(0), reference.cross_map(0))

    def uniform(t, ctx):
        new = t.clone()
        valid = (t[ctx.cond] > 0).any(dim=(1, 2, 3), keepdim=True).to(t.dtype)    # (B, 1, 1, 1, W)
        new[ctx.cond] = (valid / valid.sum(-1, keepdim=True)).expand_as(t[ctx.cond])
        return new

    out = _run(pipe, hooks=[("layers.*.cross", uniform)], capture_attention=True)
    assert not torch.equal(out.latents, plain.latents)
    for b in range(2):
        m = out.attention.cross_map(b)
        np.testing.assert_allclose(m, np.full_like(m, 1.0 / m.shape[-1]), atol=1e-6)


# -------------------------------------------------------------------------- replacing hooks
def test_zeroing_outputs_equals_zero_output_weights(pipe, plain):
    """A hook that zeroes a site's output (every row) gives the motion of a model whose ``Wo`` of
    that site is zero: the folded cross route and the temporal route (its ``Wo``) alike."""
    zero = _copy_pipeline(pipe)
    sites = zero.denoiser.attention_sites
    with torch.no_grad():
        for name in ("layers.0.cross", "layers.1.cross", "layers.2.cross", "layers.1.temporal"):
            sites[name].Wo.weight.zero_()
            sites[name].Wo.bias.zero_()
    expected = zero(PROMPTS, lengths=LENGTHS, num_steps=STEPS, seed=SEED)
    out = _run(pipe, hooks=[("layers.*.cross.out", lambda t, ctx: torch.zeros_like(t)),
                            ("layers.1.temporal.out", lambda t, ctx: torch.zeros_like(t))])
    assert not torch.equal(expected.latents, plain.latents)
    assert torch.equal(out.latents, expected.latents)
    assert _nothing_installed(pipe.denoiser)


def test_replacing_probabilities_matches_an_eager_reference(pipe):
    """Skeletal maps of the cond rows replaced by the identity (each part attends to itself) at
    layer 1: the same as an explicit-softmax run that does the same."""
    def identity_map(probs):                      # (n, N', H, P, P)
        return torch.eye(NUM_PARTS).expand_as(probs).clone()

    def hook(t, ctx):
        new = t.clone()
        new[ctx.cond] = identity_map(t[ctx.cond])
        return new

    out = _run(pipe, hooks=[("layers.1.skeletal", hook)])
    text, null = pipe.encode_text(PROMPTS)
    n_lat = max(LENGTHS) // 4
    noise = pipe.make_noise([SEED, SEED + 1], n_lat)

    def controller(site, probs):
        if site.name != "layers.1.skeletal":
            return None
        named = site.to_named(probs).clone()                # (2B, N', H, P, P), cond rows last
        named[2:] = identity_map(named[2:])
        return site.from_named(named)

    with use_processors(pipe.denoiser, EagerProcessor(controller)):
        ref = denoise(pipe.denoiser, make_scheduler(), pipe.denoiser.prepare_text(text.features, text.mask),
                      pipe.denoiser.prepare_text(null.features, null.mask), noise, pipe.frame_mask(LENGTHS, n_lat),
                      num_steps=STEPS)
    torch.testing.assert_close(out.latents, ref, rtol=1e-4, atol=1e-4)
    assert not torch.allclose(out.latents, _run(pipe).latents, atol=1e-3)     # the replacement did something


def test_rows_a_hook_leaves_equal_keep_the_plain_values(pipe):
    """A probability hook that changes only the cond rows: at the first step (same latents as the
    plain run) the site's output of the uncond rows is plain sampling's bit for bit, the cond rows'
    is not."""
    def sharpen(t, ctx):
        new = t.clone()
        new[ctx.cond] = t[ctx.cond] ** 2 / (t[ctx.cond] ** 2).sum(-1, keepdim=True)
        return new

    def keep(store):
        def read(t, ctx):
            if ctx.step == 0:
                store["uncond"], store["cond"] = t[ctx.uncond].clone(), t[ctx.cond].clone()
        return read

    plain, hooked = {}, {}
    _run(pipe, hooks=[("layers.0.cross.out", keep(plain))])
    _run(pipe, hooks=[("layers.0.cross", sharpen), ("layers.0.cross.out", keep(hooked))])
    assert torch.equal(hooked["uncond"], plain["uncond"])
    assert not torch.allclose(hooked["cond"], plain["cond"], atol=1e-4)


# ---------------------------------------------------------------------------- scoping and errors
def test_errors_name_the_problem_and_nothing_stays_installed(pipe, plain):
    den = pipe.denoiser
    with pytest.raises(KeyError, match=r"unknown hook point 'layers.3.cross'.*known hook points.*layers.2.cross.out"):
        _run(pipe, hooks=[("layers.3.cross", lambda t, ctx: None)])
    with pytest.raises(ValueError, match=r"returned shape \(4, 2\); expected \(4, 10, 7, 32\)"):
        _run(pipe, hooks=[("layers.0.cross.out", lambda t, ctx: torch.zeros(4, 2))])
    assert _nothing_installed(den)
    with pytest.raises(ValueError, match="NaN or infinite"):
        _run(pipe, hooks=[("layers.1.temporal", lambda t, ctx: torch.full_like(t, float("nan")))])
    assert _nothing_installed(den)
    with pytest.raises(ValueError, match="q is read-only"):
        _run(pipe, hooks=[("layers.0.cross.q", lambda t, ctx: t)])
    with pytest.raises(TypeError, match=r"hooks\[0\] must be a \(name, fn\) pair"):
        _run(pipe, hooks=["layers.0.cross"])
    with pytest.raises(TypeError, match="fn must be callable"):
        _run(pipe, hooks=[("layers.0.cross", 3)])
    with pytest.raises(TypeError, match=r"hooks must be a list of \(name, fn\) pairs"):
        _run(pipe, hooks=lambda t, ctx: None)

    def boom(t, ctx):
        if ctx.step == 2:
            raise RuntimeError("boom")

    with pytest.raises(RuntimeError, match="boom"):
        _run(pipe, hooks=[("layers.*.skeletal.out", boom), ("layers.0.cross", boom)])
    assert _nothing_installed(den)
    assert torch.equal(_run(pipe).latents, plain.latents)         # the next call is plain sampling


def test_use_hooks_needs_the_step_hook(pipe):
    text, null = pipe.encode_text(PROMPTS[:1])
    noise = pipe.make_noise([0], 5)
    with pytest.raises(RuntimeError, match="controller_hooks=\\[session.on_step\\]"):
        with use_hooks(pipe.denoiser, [("layers.0.cross", lambda t, ctx: None)]):
            denoise(pipe.denoiser, make_scheduler(), pipe.denoiser.prepare_text(text.features, text.mask),
                    pipe.denoiser.prepare_text(null.features, null.mask), noise, num_steps=2)
    assert _nothing_installed(pipe.denoiser)


# ------------------------------------------------------------------------------ run_with_cache
@pytest.fixture(scope="module")
def cached(pipe):
    return _cache(pipe, store=("probs", "inputs", "outputs"))


def _cache(pipe, **kwargs):
    return pipe.run_with_cache(PROMPTS, LENGTHS, num_steps=STEPS, seed=SEED, **kwargs)


def test_run_with_cache_keeps_the_motion_and_documents_its_axes(pipe, plain, cached):
    out, cache = cached
    assert torch.equal(out.latents, plain.latents)                                # bit for bit
    assert cache.names() == hook_point_names(pipe.denoiser) and len(cache) == 45
    assert cache.steps() == tuple(range(STEPS)) and cache.num_steps == STEPS
    w = len(pipe.text_encoder.encode(PROMPTS).tokens[0])
    assert cache["layers.1.cross"].shape == (STEPS, 2, 2, 10, NUM_PARTS, w)
    assert cache.axes("layers.1.cross") == ("step", "batch", "head", "frame", "part", "token")
    assert cache["layers.0.temporal"].shape == (STEPS, 2, NUM_PARTS, 2, 10, 10)
    assert cache["layers.2.skeletal.out"].shape == (STEPS, 2, 10, NUM_PARTS, 32)
    assert cache.axes("layers.2.skeletal.out") == ("step", "batch", "frame", "part", "channel")
    assert cache["layers.0.cross.k"].shape == (STEPS, 2, 2, w, 16)
    assert cache.point("layers.2.cross.v").layer == 2
    with pytest.raises(KeyError, match="not in this cache; it holds"):
        cache["layers.9.cross"]
    with pytest.raises(TypeError):
        cache["layers.0.cross"] = torch.zeros(1)                                    # read-only mapping


def test_cached_probabilities_follow_from_the_cached_queries_and_keys(cached, pipe):
    _, cache = cached
    text = pipe.text_encoder.encode(PROMPTS)
    for b, length in enumerate(LENGTHS):
        n = length // 4
        # temporal: padded frames are masked keys
        q, k = cache["layers.1.temporal.q"][:, b], cache["layers.1.temporal.k"][:, b]     # (S, P, H, N', dh)
        scores = q @ k.transpose(-1, -2) / math.sqrt(q.shape[-1])
        scores[..., n:] = float("-inf")
        torch.testing.assert_close(scores.softmax(-1), cache["layers.1.temporal"][:, b], rtol=1e-5, atol=1e-6)
        # cross (the folded route: the queries are projected for the cache): padding tokens masked
        w = len(text.tokens[b])
        q, k = cache["layers.2.cross.q"][:, b], cache["layers.2.cross.k"][:, b]     # (S, H, N', P, dh), (S, H, W, dh)
        scores = torch.einsum("shnpd,shwd->shnpw", q, k) / math.sqrt(q.shape[-1])
        scores[..., w:] = float("-inf")
        torch.testing.assert_close(scores.softmax(-1), cache["layers.2.cross"][:, b], rtol=1e-5, atol=1e-6)
        # the output is Wo of the probabilities mixing the values
        v = cache["layers.2.cross.v"][:, b]
        mixed = torch.einsum("shnpw,shwd->snphd", cache["layers.2.cross"][:, b], v).flatten(-2)
        wo = pipe.denoiser.attention_sites["layers.2.cross"].Wo
        torch.testing.assert_close(torch.nn.functional.linear(mixed, wo.weight, wo.bias),
                                   cache["layers.2.cross.out"][:, b], rtol=1e-4, atol=1e-5)


def test_cache_to_attention_maps_agrees_with_full_capture(pipe, cached):
    _, cache = cached
    full = _run(pipe, capture_attention=CaptureConfig(mode="full", self_attention=True)).attention
    maps = cache.to_attention_maps()
    assert maps.kinds == ("cross", "temporal", "skeletal") and maps.layers == (0, 1, 2)
    for b in range(2):
        np.testing.assert_allclose(maps.cross_map(b), full.cross_map(b), atol=2e-3)        # capture keeps float16
        np.testing.assert_allclose(maps.temporal_map(b), full.temporal_map(b), atol=2e-3)
        np.testing.assert_allclose(maps.select(steps=(0.5, 1.0), layers=[1]).cross_map(b),
                                   full.select(steps=(0.5, 1.0), layers=[1]).cross_map(b), atol=2e-3)
    assert maps.word_map(0, "cartwheel").shape == (NUM_PARTS, 10)


def test_cache_filters_and_step_window(pipe, cached):
    _, everything = cached
    out, cache = _cache(pipe, names="layers.*.cross", layers=[0, 2], steps=(0.5, 1.0), store=("probs", "outputs"))
    assert cache.names() == ["layers.0.cross", "layers.0.cross.out", "layers.2.cross", "layers.2.cross.out"]
    assert cache.steps() == (3, 4, 5) and cache.fractions() == (0.5, 4 / 6, 5 / 6)
    for name in cache:
        assert torch.equal(cache[name], everything[name][3:])
    _, one = _cache(pipe, names=lambda n: n == "layers.1.skeletal")
    assert one.names() == ["layers.1.skeletal"]
    with pytest.raises(ValueError, match="select no hook point"):
        _cache(pipe, names="layers.1.skeletal.q", store="probs")
    with pytest.raises(RuntimeError, match="nothing was recorded"):
        _cache(pipe, names="layers.0.cross", steps=(0.9, 1.0))
    with pytest.raises(TypeError, match="edits"):
        _cache(pipe, edits=[])


def test_cache_with_hooks_keeps_what_the_run_used(pipe):
    out, cache = _cache(pipe, names="layers.0.cross.out", store="outputs",
                        hooks=[("layers.0.cross.out", lambda t, ctx: torch.zeros_like(t))])
    assert float(cache["layers.0.cross.out"].abs().max()) == 0.0


def test_hooks_serve_the_ablation_without_cross_attention(pipe):
    """The "w/o CrossAttn" ablation's sentence sites have hook points too (key 0: the sentence)."""
    from salad_core.models.denoiser import DenoiserConfig

    torch.manual_seed(1)
    den = Denoiser(DenoiserConfig(width=32, heads=2, ff_dim=64, layers=3, text_dim=384, cross_attention=False))
    ablation = SaladPipeline(pipe.vae, den, pipe.text_encoder, pipe.mean, pipe.std)
    plain = ablation(PROMPTS, lengths=LENGTHS, num_steps=3, seed=SEED)
    shapes = {}

    def read(t, ctx):
        shapes[ctx.name] = (tuple(t.shape), ctx.axes)

    out = ablation(PROMPTS, lengths=LENGTHS, num_steps=3, seed=SEED, hooks=[("layers.1.sentence*", read)])
    assert torch.equal(out.latents, plain.latents)
    keys = 1 + 10 * NUM_PARTS
    assert shapes["layers.1.sentence"] == ((4, 2, 10, NUM_PARTS, keys), ("batch", "head", "frame", "part", "key"))
    assert shapes["layers.1.sentence.out"][0] == (4, 10, NUM_PARTS, 32)
    assert shapes["layers.1.sentence.k"][0] == (4, 2, keys, 16)
