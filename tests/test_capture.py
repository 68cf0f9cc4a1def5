"""Cross-attention capture: bit-identity with plain sampling, the maps' numbers, selection, scoping."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from salad_core.attention import AttentionMaps, CaptureConfig, capture_cross_attention
from salad_core.models.attention import EagerProcessor, SDPAProcessor, cross_probs_by_part, use_processors
from salad_core.models.denoiser import Denoiser, DenoiserConfig
from salad_core.sampling import denoise, make_scheduler
from salad_core.skeleton import NUM_PARTS

PROMPTS = ["a man does a cartwheel and walks", "a person jumps high"]
LENGTHS = [40, 28]
STEPS = 10


pytestmark = pytest.mark.usefixtures("single_thread")


@pytest.fixture(scope="module")
def plain(pipe):
    return pipe(PROMPTS, lengths=LENGTHS, num_steps=STEPS, seed=3)


@pytest.fixture(scope="module")
def full(pipe):
    return pipe(PROMPTS, lengths=LENGTHS, num_steps=STEPS, seed=3,
                capture_attention=CaptureConfig(mode="full", self_attention=True))


@pytest.fixture(scope="module")
def mean(pipe):
    return pipe(PROMPTS, lengths=LENGTHS, num_steps=STEPS, seed=3, capture_attention=True)


def test_capture_never_changes_the_motion(plain, full, mean):
    for out in (full, mean):
        assert torch.equal(out.latents, plain.latents)          # bit for bit
        assert np.array_equal(out.features, plain.features)
    assert plain.attention is None and isinstance(mean.attention, AttentionMaps)


def test_maps_are_cropped_probabilities_with_their_tokens(pipe, mean):
    maps = mean.attention
    text = pipe.text_encoder.encode(PROMPTS)
    for b in range(2):
        m = maps.cross_map(b)
        assert m.shape == (NUM_PARTS, LENGTHS[b] // 4, len(text.tokens[b]))
        # mean of post-softmax rows: every (part, frame) sums to one over the tokens
        np.testing.assert_allclose(m.sum(-1), 1.0, atol=1e-5)
        assert maps.tokens(b) == text.tokens[b] and maps.words(b) == text.words[b]
        assert maps.token_to_word(b) == text.token_to_word[b]
    assert maps.latent_lengths == [10, 7] and maps.prompts == PROMPTS
    assert maps.num_steps == STEPS and maps.layers == (0, 1, 2) and maps.step_window == (0.0, 1.0)


def test_word_map_sums_the_sub_tokens(mean):
    maps = mean.attention
    cols = maps.word_columns(0, "cartwheel")
    assert len(cols) > 1                     # MiniLM splits it into word pieces
    np.testing.assert_allclose(maps.word_map(0, "cartwheel"), sum(maps.token_map(0, c) for c in cols), rtol=1e-6)
    phrase = maps.word_map(0, "does a cartwheel")
    # words 2, 3, 4 of ['a', 'man', 'does', 'a', 'cartwheel', 'and', 'walks']: only the second "a"
    np.testing.assert_allclose(phrase, maps.word_map(0, 2) + maps.word_map(0, 3) + maps.word_map(0, 4), rtol=1e-5)
    np.testing.assert_allclose(maps.word_map(0, (2, 5)), phrase, rtol=1e-6)
    np.testing.assert_allclose(maps.word_map(0, "a"), maps.word_map(0, 0) + maps.word_map(0, 3), rtol=1e-5)
    words = maps.word_maps(1)
    assert list(words) == maps.words(1) and words["jumps"].shape == (NUM_PARTS, 7)
    with pytest.raises(ValueError, match=r"'flips' is not in prompt 1.*\['a', 'person', 'jumps', 'high'\]"):
        maps.word_map(1, "flips")
    with pytest.raises(IndexError, match="out of range"):
        maps.token_map(1, 99)


def _reference(pipe, steps_window=(0.0, 1.0)):
    """Straightforward recording: an eager controller appends every cross site's cond rows."""
    prompts, lengths = PROMPTS, LENGTHS
    text, null = pipe.encode_text(prompts)
    n_lat = max(lengths) // 4
    noise = pipe.make_noise([3, 4], n_lat)
    mask = pipe.frame_mask(lengths, n_lat)
    records, state = [], {}

    def hook(info):
        state["i"] = info.index

    def controller(site, probs):
        if site.kind == "cross" and steps_window[0] <= state["i"] / STEPS < steps_window[1]:
            records.append(cross_probs_by_part(probs, site.frames, site.parts)[2:].clone())   # cond rows
        return None

    with use_processors(pipe.denoiser, EagerProcessor(controller)):
        denoise(pipe.denoiser, make_scheduler(), pipe.denoiser.prepare_text(text.features, text.mask),
                pipe.denoiser.prepare_text(null.features, null.mask), noise, mask, num_steps=STEPS,
                controller_hooks=[hook])
    stack = torch.stack(records)                          # (S*L, B, H, N', P, W)
    return stack.mean((0, 2)).permute(0, 2, 1, 3).numpy(), text  # (B, P, N', W)


def test_streaming_mean_equals_a_straightforward_recording(pipe, mean):
    ref, text = _reference(pipe)
    for b in range(2):
        n, w = LENGTHS[b] // 4, len(text.tokens[b])
        np.testing.assert_allclose(mean.attention.cross_map(b), ref[b, :, :n, :w], atol=2e-5)


def test_full_mode_agrees_with_the_mean_mode_and_selects_anything(mean, full):
    fm, mm = full.attention, mean.attention
    assert fm.full(0).shape == (STEPS, 3, 2, 10, NUM_PARTS, len(fm.tokens(0))) and fm.full(0).dtype == np.float16
    np.testing.assert_allclose(fm.cross_map(0), mm.cross_map(0), atol=2e-3)
    # with 10 steps and 10 bins every bin holds one step: any bin-aligned window agrees
    for steps, layers in (((0.0, 0.5), [0, 1]), ((0.3, 1.0), [2]), ((0.9, 1.0), None)):
        a, b = fm.select(steps=steps, layers=layers), mm.select(steps=steps, layers=layers)
        assert a.step_window == b.step_window == steps
        np.testing.assert_allclose(a.cross_map(1), b.cross_map(1), atol=2e-3)
    # the selection really narrows: early and late maps differ, their average is the whole
    early, late = mm.select(steps=(0.0, 0.5)).cross_map(0), mm.select(steps=(0.5, 1.0)).cross_map(0)
    np.testing.assert_allclose((early + late) / 2, mm.cross_map(0), atol=1e-5)
    assert np.abs(early - late).max() > 1e-4
    # heads only in full mode
    h0 = fm.select(heads=[0]).cross_map(0)
    np.testing.assert_allclose((h0 + fm.select(heads=1).cross_map(0)) / 2, fm.cross_map(0), atol=2e-3)
    with pytest.raises(ValueError, match="heads can only be selected in a mode='full'"):
        mm.select(heads=[0])
    with pytest.raises(ValueError, match="multiples of 1/10"):
        mm.select(steps=(0.0, 0.33))
    with pytest.raises(ValueError, match=r"layers \[5\] were not captured"):
        mm.select(layers=[5])


def test_self_attention_maps_on_request(full, mean):
    fm = full.attention
    t, s = fm.temporal_map(1), fm.skeletal_map(1)
    assert t.shape == (NUM_PARTS, 7, 7) and s.shape == (7, NUM_PARTS, NUM_PARTS)
    # sample 1 is the shorter one: padded key frames are masked, so its rows still sum to one
    np.testing.assert_allclose(t.sum(-1), 1.0, atol=2e-3)
    np.testing.assert_allclose(s.sum(-1), 1.0, atol=2e-3)
    assert fm.kinds == ("cross", "temporal", "skeletal")
    with pytest.raises(ValueError, match="self_attention=True"):
        mean.attention.temporal_map(0)


def test_step_window_and_layers_of_the_config(pipe, full):
    out = pipe(PROMPTS, lengths=LENGTHS, num_steps=STEPS, seed=3,
               capture_attention=CaptureConfig(steps=(0.5, 1.0), layers=(1,)))
    maps = out.attention
    assert maps.step_window == (0.5, 1.0) and maps.layers == (1,)
    np.testing.assert_allclose(maps.cross_map(0), full.attention.select(steps=(0.5, 1.0), layers=[1]).cross_map(0),
                               atol=2e-3)


def test_the_model_is_restored_even_after_an_error(pipe):
    text = pipe.text_encoder.encode(PROMPTS)
    before = pipe.denoiser.attn_processors
    with pytest.raises(RuntimeError, match="boom"):
        with capture_cross_attention(pipe.denoiser, text, LENGTHS) as store:
            assert any(type(p).__name__ == "HookedProcessor" for p in pipe.denoiser.attn_processors.values())
            raise RuntimeError("boom")
    assert pipe.denoiser.attn_processors == before
    assert all(isinstance(p, SDPAProcessor) for p in pipe.denoiser.attn_processors.values())
    with pytest.raises(RuntimeError, match="no step was recorded"):
        store.result()


@pytest.mark.parametrize("kwargs, match", [
    (dict(mode="sum"), "mode must be one of"),
    (dict(steps=(0.5, 0.2)), "0 <= start < stop <= 1"),
    (dict(step_bins=0), "step_bins must be a positive int"),
    (dict(layers=[]), "non-empty sequence"),
    (dict(full_dtype="int8"), "full_dtype"),
])
def test_config_validation(kwargs, match):
    with pytest.raises((ValueError, TypeError), match=match):
        CaptureConfig(**kwargs)


def test_capture_refuses_the_ablation_without_cross_attention(pipe):
    den = Denoiser(DenoiserConfig(width=32, heads=2, ff_dim=64, layers=3, text_dim=384, cross_attention=False))
    with pytest.raises(ValueError, match="w/o CrossAttn"):
        with capture_cross_attention(den, pipe.text_encoder.encode(PROMPTS), LENGTHS):
            pass


def test_softmax_last_matches_torch_softmax_and_leaves_its_input():
    from salad_core.models.kernels import softmax_last

    g = torch.Generator().manual_seed(0)
    for width in (1, 5, 14, 32, 77):
        x = torch.randn(2, 4, 343, width, generator=g) * 5
        x[0, :, :, 0] = float("-inf") if width > 1 else 0.0         # masked keys
        before = x.clone()
        torch.testing.assert_close(softmax_last(x), x.softmax(-1), rtol=1e-6, atol=1e-7)
        assert torch.equal(x, before)
    assert softmax_last(torch.full((1, 3), float("-inf"))).isnan().all()     # as torch.softmax
    assert softmax_last(torch.full((1, 20), float("-inf"))).isnan().all()
    # differentiable (null-text inversion optimises through it)
    x = torch.randn(3, 5, requires_grad=True)
    w = torch.randn(3, 5)
    (softmax_last(x) * w).sum().backward()
    ref = x.detach().clone().requires_grad_(True)
    (ref.softmax(-1) * w).sum().backward()
    torch.testing.assert_close(x.grad, ref.grad)


def test_row_taker_slices_consecutive_rows_and_gathers_others():
    from salad_core.attention.processor import row_taker

    x = torch.arange(40.0).view(10, 4)
    view = row_taker(torch.tensor([3, 4, 5]))(x)
    assert torch.equal(view, x[3:6]) and view.data_ptr() == x[3:6].data_ptr()      # no copy
    for rows in ([1, 3, 5], [5, 4], [2]):
        torch.testing.assert_close(row_taker(torch.tensor(rows))(x), x[torch.tensor(rows)])
    assert row_taker(torch.tensor([7]))(x).data_ptr() == x[7:8].data_ptr()


@pytest.mark.parametrize("keys", [7, 15, 16, 40])
def test_fast_attention_matches_sdpa_with_and_without_a_key_mask(keys):
    import torch.nn.functional as F

    from salad_core.models.kernels import SHORT_KEYS, fast_attention

    g = torch.Generator().manual_seed(keys)
    q, k, v = (torch.randn(3, 2, 10, 8, generator=g) for _ in range(3))
    q, k, v = q, k[:, :, :1].expand(-1, -1, keys, -1) + torch.randn(3, 2, keys, 8, generator=g), \
        torch.randn(3, 2, keys, 8, generator=g)
    mask = torch.ones(3, keys, dtype=torch.bool)
    mask[1, keys // 2:] = False
    for m in (None, mask):
        ref = F.scaled_dot_product_attention(q, k, v, attn_mask=None if m is None else m[:, None, None, :])
        torch.testing.assert_close(fast_attention(q, k, v, m, 0.0), ref, rtol=1e-5, atol=1e-6)
    assert SHORT_KEYS == 50


def test_trailing_padding_is_trimmed_and_gives_the_same_attention():
    import torch.nn.functional as F

    from salad_core.models.kernels import fast_attention, trim_masked_keys

    g = torch.Generator().manual_seed(0)
    q, k, v = (torch.randn(2, 2, 9, 8, generator=g) for _ in range(3))
    k, v = torch.randn(2, 2, 30, 8, generator=g), torch.randn(2, 2, 30, 8, generator=g)
    mask = torch.zeros(2, 30, dtype=torch.bool)
    mask[0, :5] = True
    mask[1, :12] = True
    mask[1, 3] = False                                   # interior padding stays (masked)
    k2, v2, m2 = trim_masked_keys(k, v, mask)
    assert k2.shape[2] == v2.shape[2] == 12 and m2.shape == (2, 12) and bool(m2[1, :3].all()) and not m2[1, 3]
    assert k2.data_ptr() == k.data_ptr()                 # a view, no copy
    ref = F.scaled_dot_product_attention(q, k, v, attn_mask=mask[:, None, None, :])
    torch.testing.assert_close(fast_attention(q, k, v, mask, 0.0), ref, rtol=1e-5, atol=1e-6)
    full = torch.ones(2, 30, dtype=torch.bool)
    full[:, 20:] = False
    assert trim_masked_keys(k, v, full)[2] is None        # all that is left is valid: no mask
    assert trim_masked_keys(k, v, torch.ones(2, 30, dtype=torch.bool))[0] is k


@pytest.mark.parametrize("keys", [12, 60])          # explicit route (probabilities reused) and SDPA route
def test_hooked_processor_output_is_plain_attention_and_hook_sees_all_keys(keys):
    from salad_core.attention.processor import HookedProcessor
    from salad_core.models.attention import SiteInfo
    from salad_core.models.kernels import attention_probs, fast_attention

    g = torch.Generator().manual_seed(keys)
    b, h, frames, parts = 2, 2, 3, NUM_PARTS
    q = torch.randn(b, h, frames * parts, 8, generator=g)
    k, v = torch.randn(b, h, keys + 5, 8, generator=g), torch.randn(b, h, keys + 5, 8, generator=g)
    mask = torch.zeros(b, keys + 5, dtype=torch.bool)
    mask[0, :keys] = True
    mask[1, :keys // 2] = True                        # the last 5 keys are padding in every row: trimmed
    site = SiteInfo("layers.0.cross", "cross", 0, 1, h, b, frames, parts, keys + 5)
    seen = {}

    class Hook:
        def rows(self, site):
            return torch.tensor([1])

        def process(self, site, rows, probs):
            seen["probs"] = probs.clone()

    out = HookedProcessor(Hook())(site, q, k, v, mask, 0.0)
    assert torch.equal(out, fast_attention(q, k, v, mask, 0.0))           # bit for bit
    probs = seen["probs"]                                                 # (1, H, N', P, W) named
    assert probs.shape == (1, h, frames, parts, keys + 5)
    ref = attention_probs(q[1:], k[1:], mask[1:]).view(1, h, frames, parts, keys + 5)
    torch.testing.assert_close(probs, ref, rtol=1e-5, atol=1e-6)
    assert float(probs[..., keys // 2:].abs().max()) == 0.0                # masked and trimmed keys: 0


def test_prefix_key_runs_finds_runs_and_refuses_other_masks():
    from salad_core.models.kernels import MAX_KEY_RUNS, prefix_key_runs

    mask = torch.zeros(5, 9, dtype=torch.bool)
    mask[:3, :6] = True                  # three prompts of 6 tokens, then two empty prompts (2 tokens)
    mask[3:, :2] = True
    assert prefix_key_runs(mask) == ((0, 3, 6), (3, 5, 2))
    mask[4, 2] = True                    # changed in place: not mistaken for the cached mask
    assert prefix_key_runs(mask) == ((0, 3, 6), (3, 4, 2), (4, 5, 3))
    holes = mask.clone()
    holes[0, 1] = False                  # not a prefix mask
    assert prefix_key_runs(holes) is None
    empty = mask.clone()
    empty[1] = False                     # a row without any valid key
    assert prefix_key_runs(empty) is None
    many = torch.arange(9)[None] < torch.arange(1, MAX_KEY_RUNS + 2)[:, None]
    assert prefix_key_runs(many) is None and prefix_key_runs(many[:MAX_KEY_RUNS]) is not None
    assert prefix_key_runs(torch.ones(2, 4, dtype=torch.bool)) == ((0, 2, 4),)


def test_attention_by_row_runs_matches_masked_attention_and_hook_gets_zeros_for_masked_keys():
    import torch.nn.functional as F

    from salad_core.attention.processor import HookedProcessor
    from salad_core.models.attention import SiteInfo
    from salad_core.models.kernels import attention_probs, fast_attention, prefix_key_runs

    g = torch.Generator().manual_seed(1)
    b, h, frames, parts, keys = 4, 2, 3, NUM_PARTS, 11
    q = torch.randn(b, h, frames * parts, 8, generator=g)
    k, v = torch.randn(b, h, keys, 8, generator=g), torch.randn(b, h, keys, 8, generator=g)
    mask = torch.arange(keys)[None] < torch.tensor([7, 7, 2, 2])[:, None]     # guidance: two runs
    assert prefix_key_runs(mask) == ((0, 2, 7), (2, 4, 2))
    ref = F.scaled_dot_product_attention(q, k, v, attn_mask=mask[:, None, None, :])
    out = fast_attention(q, k, v, mask, 0.0)
    torch.testing.assert_close(out, ref, rtol=1e-5, atol=1e-6)
    site = SiteInfo("layers.0.cross", "cross", 0, 1, h, b, frames, parts, keys)
    seen = {}

    class Hook:
        def rows(self, site):
            return torch.tensor([1, 2])

        def process(self, site, rows, probs):
            seen["probs"] = probs.clone()

    assert torch.equal(HookedProcessor(Hook())(site, q, k, v, mask, 0.0), out)      # bit for bit
    probs = seen["probs"]
    assert probs.shape == (2, h, frames, parts, keys)
    torch.testing.assert_close(probs, attention_probs(q[1:3], k[1:3], mask[1:3]).view(2, h, frames, parts, keys))
    assert float(probs[0, ..., 7:].abs().max()) == 0.0 and float(probs[1, ..., 2:].abs().max()) == 0.0
    q.requires_grad_(True)                   # with gradients (null-text optimisation): same values
    torch.testing.assert_close(fast_attention(q, k, v, mask, 0.0), out)


def _fold_model():
    torch.manual_seed(5)
    return Denoiser(DenoiserConfig(width=32, heads=2, ff_dim=32, layers=3, text_dim=12)).eval()


def _fold_inputs(model, lengths=(9, 2), tokens=20):
    g = torch.Generator().manual_seed(6)
    b = len(lengths)
    x = torch.randn(b, 4, NUM_PARTS, model.config.latent_dim, generator=g)
    text = torch.randn(b, tokens, model.config.text_dim, generator=g)
    mask = torch.arange(tokens)[None] < torch.tensor(lengths)[:, None]
    return x, model.prepare_text(text, mask)


class _NoFold(SDPAProcessor):
    takes_folded = False


def test_folded_cross_attention_equals_the_projected_route_and_follows_weight_changes():
    model = _fold_model()
    x, ctx = _fold_inputs(model)
    with torch.inference_mode():
        folds = ctx.layer_folds(model)
        assert all(f is not None for f in folds) and folds[0].keys == (9, 2)   # 2 heads x 9 keys < width 32
        out = model(x, torch.tensor([7]), text_context=ctx)
        with use_processors(model, _NoFold()):
            ref = model(x, torch.tensor([7]), text_context=ctx)
        torch.testing.assert_close(out, ref, rtol=1e-5, atol=1e-5)
        assert ctx.layer_folds(model) is folds                                   # cached
    with torch.no_grad():
        model.transformer.layers[1].cross_attn.Wq.weight.mul_(2.0)
    with torch.inference_mode():
        assert ctx.layer_folds(model) is not folds                               # Wq changed: rebuilt
        with use_processors(model, _NoFold()):
            ref = model(x, torch.tensor([7]), text_context=ctx)
        torch.testing.assert_close(model(x, torch.tensor([7]), text_context=ctx), ref, rtol=1e-5, atol=1e-5)
    with pytest.raises(RuntimeError, match="without gradients"):
        ctx.layer_folds(model)


def test_fold_is_skipped_where_it_does_not_pay_or_the_mask_has_holes():
    from salad_core.models.kernels import fold_text

    model = _fold_model()
    attn = model.transformer.layers[0].cross_attn

    def fold(k, v, mask):
        return fold_text(k, v, mask, attn.Wq, attn.Wo, attn.heads)

    k, v = torch.randn(2, 2, 20, 16), torch.randn(2, 2, 20, 16)
    long = torch.arange(20)[None] < torch.tensor([16, 3])[:, None]         # 2 heads x 16 keys = width
    assert fold(k, v, long) is None
    holes = torch.arange(20)[None] < torch.tensor([6, 3])[:, None]
    holes[0, 2] = False
    assert fold(k, v, holes) is None
    assert fold(k[..., :10, :], v[..., :10, :], None).keys == (10, 10)


def test_hooked_processor_on_the_folded_route_keeps_outputs_and_serves_the_hook():
    """Capture on the folded route: output bit for bit plain sampling's; the hook's probabilities
    are those of the projected route (zeros for padding); replaced rows equal the projected route
    with the same replacement."""
    from salad_core.attention.processor import HookedProcessor

    model = _fold_model()
    x, ctx = _fold_inputs(model)
    t = torch.tensor([7])
    seen = {}

    class Watch:
        def rows(self, site):
            return torch.tensor([0]) if site.kind == "cross" else None

        def process(self, site, rows, probs):
            seen[site.name] = probs.clone()

    class Flatten(Watch):            # replaces row 0's maps by uniform attention over its 9 tokens
        def process(self, site, rows, probs):
            new = torch.zeros_like(probs)
            new[..., :9] = 1.0 / 9
            return rows, new

    recorded = {}

    def record(site, probs):
        if site.kind == "cross":
            recorded[site.name] = probs[:1].clone()

    def flatten(site, probs):
        if site.kind != "cross":
            return None
        new = probs.clone()
        new[:1] = 0.0
        new[:1, ..., :9] = 1.0 / 9
        return new

    with torch.inference_mode():
        plain = model(x, t, text_context=ctx)
        with use_processors(model, HookedProcessor(Watch())):
            assert torch.equal(model(x, t, text_context=ctx), plain)              # bit for bit
        with use_processors(model, EagerProcessor(record)):
            model(x, t, text_context=ctx)
        for name, probs in seen.items():
            named = probs.reshape(recorded[name].shape)
            torch.testing.assert_close(named, recorded[name], rtol=1e-5, atol=1e-6)
            assert float(probs[..., 9:].abs().max()) == 0.0                         # padding keys
        with use_processors(model, HookedProcessor(Flatten())):
            edited = model(x, t, text_context=ctx)
        with use_processors(model, EagerProcessor(flatten)):
            ref = model(x, t, text_context=ctx)
    torch.testing.assert_close(edited, ref, rtol=1e-5, atol=1e-5)
    assert not torch.allclose(edited[0], plain[0], atol=1e-3)                       # the edit acted
