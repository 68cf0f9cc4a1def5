"""Denoiser architecture, official checkpoint layout, attention sites and processors."""
from __future__ import annotations

import math

import pytest
from dataclasses import replace
import torch
import torch.nn.functional as F

from salad_core.io import CheckpointError
from salad_core.models.attention import (
    EagerProcessor,
    SDPAProcessor,
    SiteInfo,
    cross_probs_by_part,
    site_names,
    use_processors,
)
from salad_core.models.denoiser import Denoiser, DenoiserConfig, TextContext
from salad_core.models.inference import stacked_qkv, timestep_table
from salad_core.skeleton import NUM_PARTS

TINY = DenoiserConfig(latent_dim=4, width=32, heads=4, ff_dim=48, layers=5, text_dim=12, max_len=256)


pytestmark = pytest.mark.usefixtures("single_thread")


def _inputs(cfg: DenoiserConfig, b: int = 3, n: int = 6, w: int = 5, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(b, n, cfg.num_parts, cfg.latent_dim, generator=g)
    t = torch.randint(0, 1000, (b,), generator=g)
    text = torch.randn(b, w, cfg.text_dim, generator=g)
    text_mask = torch.ones(b, w, dtype=torch.bool)
    text_mask[1, 3:] = False  # padded tokens
    text_mask[2, 2:] = False
    frame_mask = torch.ones(b, n, dtype=torch.bool)
    frame_mask[0, 4:] = False  # padded frames
    frame_mask[2, 2:] = False
    return x, t, text, text_mask, frame_mask


def _model(cfg: DenoiserConfig = TINY, seed: int = 0) -> Denoiser:
    torch.manual_seed(seed)
    return Denoiser(cfg).eval()


# ------------------------------------------------------------------ size and layout
def test_parameter_count_paper_defaults():
    model = Denoiser(DenoiserConfig())
    assert sum(p.numel() for p in model.parameters()) == 9_894_176
    # CLIP ViT-L/14 features (768) add 256 * 256 weights to word_emb (fact sheet §2.4)
    big = Denoiser(DenoiserConfig(text_dim=768))
    assert sum(p.numel() for p in big.parameters()) == 9_894_176 + 65_536


def test_tiny_shapes_and_dtype():
    model = _model()
    x, t, text, text_mask, frame_mask = _inputs(TINY)
    out = model(x, t, text, text_mask, frame_mask)
    assert out.shape == x.shape and out.dtype == torch.float32
    assert torch.isfinite(out).all()
    # scalar timestep broadcasts
    out_scalar = model(x, 500, text, text_mask, frame_mask)
    out_vec = model(x, torch.full((3,), 500), text, text_mask, frame_mask)
    torch.testing.assert_close(out_scalar, out_vec)


def test_generalises_to_other_odd_depths_and_one_part():
    for layers in (1, 3, 7):
        cfg = DenoiserConfig(latent_dim=4, width=16, heads=2, ff_dim=32, layers=layers, text_dim=8, max_len=128)
        model = _model(cfg)
        assert len(model.transformer.input_blocks) == layers // 2 == len(model.transformer.skip_blocks)
        assert list(model.attn_processors) == site_names(layers)
        x, t, text, tm, fm = _inputs(cfg)
        assert model(x, t, text, tm, fm).shape == x.shape
    one_part = DenoiserConfig(latent_dim=8, num_parts=1, width=16, heads=2, ff_dim=32, layers=3, text_dim=8)
    x, t, text, tm, fm = _inputs(one_part)
    assert _model(one_part)(x, t, text, tm, fm).shape == (3, 6, 1, 8)


@pytest.mark.parametrize("kwargs, word", [
    (dict(layers=4), "odd"),
    (dict(width=30, heads=4), "divisible"),
    (dict(dropout=1.0), "dropout"),
    (dict(activation="tanh"), "activation"),
    (dict(latent_dim=0), "latent_dim"),
])
def test_config_validation(kwargs, word):
    with pytest.raises(ValueError, match=word):
        DenoiserConfig(**kwargs)


def _expected_official_shapes(w=256, c=512, dz=32, ff=1024, max_len=5000):
    shapes = {
        "input_process.layers.0.weight": (w, dz), "input_process.layers.0.bias": (w,),
        "input_process.layers.2.weight": (w, w), "input_process.layers.2.bias": (w,),
        "output_process.layers.0.weight": (w,), "output_process.layers.0.bias": (w,),
        "output_process.layers.1.weight": (w, w), "output_process.layers.1.bias": (w,),
        "output_process.layers.3.weight": (dz, w), "output_process.layers.3.bias": (dz,),
        "timestep_emb.mlp.0.weight": (w, w), "timestep_emb.mlp.0.bias": (w,),
        "timestep_emb.mlp.2.weight": (w, w), "timestep_emb.mlp.2.bias": (w,),
        "word_emb.weight": (w, c), "word_emb.bias": (w,),
        "pos_emb.pe": (1, max_len, w),
    }
    for blk in ("input_blocks.0", "input_blocks.1", "middle_block", "output_blocks.0", "output_blocks.1"):
        p = f"transformer.{blk}."
        for attn in ("skel_attn", "temp_attn", "cross_attn"):
            for lin in ("Wq", "Wk", "Wv", "Wo"):
                shapes[f"{p}{attn}.{lin}.weight"] = (w, w)
                shapes[f"{p}{attn}.{lin}.bias"] = (w,)
        for norm in ("skel_norm", "temp_norm", "cross_src_norm", "cross_tgt_norm", "ffn_norm"):
            shapes[f"{p}{norm}.weight"] = (w,)
            shapes[f"{p}{norm}.bias"] = (w,)
        shapes[f"{p}ffn_linear1.weight"] = (ff, w)
        shapes[f"{p}ffn_linear1.bias"] = (ff,)
        shapes[f"{p}ffn_linear2.weight"] = (w, ff)
        shapes[f"{p}ffn_linear2.bias"] = (w,)
        for film in ("skel_film", "temp_film", "cross_film", "ffn_film"):
            shapes[f"{p}{film}.linear.1.weight"] = (2 * w, w)
            shapes[f"{p}{film}.linear.1.bias"] = (2 * w,)
    for i in (0, 1):
        shapes[f"transformer.skip_blocks.{i}.weight"] = (w, 2 * w)
        shapes[f"transformer.skip_blocks.{i}.bias"] = (w,)
    return shapes


def test_official_key_set_and_shapes():
    sd = Denoiser(DenoiserConfig()).official_state_dict()
    expected = _expected_official_shapes()
    assert len(expected) == 251 and len(sd) == 251
    assert set(sd) == set(expected)
    assert {k: tuple(v.shape) for k, v in sd.items()} == expected
    # the positional table: sin on even, cos on odd channels over the flattened index
    pe = sd["pos_emb.pe"][0]
    assert torch.allclose(pe[3, 0], torch.tensor(math.sin(3.0)))
    assert torch.allclose(pe[3, 1], torch.tensor(math.cos(3.0)))


def test_official_round_trip_identical_outputs_and_ignores_clip_keys():
    model = _model()
    sd = model.official_state_dict()
    sd["clip_model.model.text_model.embeddings.position_ids"] = torch.arange(77)[None]
    again = Denoiser.from_official_state_dict(sd, heads=TINY.heads).eval()
    assert again.config == TINY
    x, t, text, tm, fm = _inputs(TINY)
    assert torch.equal(model(x, t, text, tm, fm), again(x, t, text, tm, fm))


def test_our_checkpoint_format_rebuilds_the_model(tmp_path):
    from salad_core.io import config_from_dict, load_state_into, read_checkpoint, save_checkpoint

    cfg = DenoiserConfig(latent_dim=4, width=32, heads=4, ff_dim=48, layers=3, text_dim=12,
                         max_len=128, cross_attention=False)
    model = _model(cfg)
    save_checkpoint(tmp_path / "den", model, model_type="denoiser", config=cfg)
    doc, state = read_checkpoint(tmp_path / "den")
    again = Denoiser(config_from_dict(DenoiserConfig, doc["config"])).eval()
    load_state_into(again, state)
    assert doc["type"] == "denoiser" and again.config == cfg
    x, t, text, tm, fm = _inputs(cfg)
    assert torch.equal(model(x, t, text, tm, fm), again(x, t, text, tm, fm))


def test_wrong_state_dicts_error_clearly():
    sd = _model().official_state_dict()
    bad = dict(sd)
    bad["transformer.middle_block.cross_attn.Wk.weight"] = torch.zeros(32, 31)
    with pytest.raises(CheckpointError, match=r"cross_attn\.Wk\.weight.*\(32, 32\).*\(32, 31\)"):
        Denoiser.from_official_state_dict(bad, heads=TINY.heads)
    extra = dict(sd, **{"transformer.middle_block.bogus.weight": torch.zeros(1)})
    with pytest.raises(CheckpointError, match="unexpected keys.*bogus"):
        Denoiser.from_official_state_dict(extra, heads=TINY.heads)
    missing = {k: v for k, v in sd.items() if "ffn_film" not in k}
    with pytest.raises(CheckpointError, match="missing keys.*ffn_film"):
        Denoiser.from_official_state_dict(missing, heads=TINY.heads)
    with pytest.raises(CheckpointError, match="input_process"):
        Denoiser.from_official_state_dict({"foo": torch.zeros(1)})
    with pytest.raises(ValueError, match="official layout"):
        Denoiser(DenoiserConfig(width=16, heads=2, layers=1, film=False)).official_state_dict()


# --------------------------------------------------- an independent reference forward
def _ref_attn(p, prefix, q_in, kv_in, key_valid, heads):
    """Official MultiheadAttention from the fact sheet: masked_fill(-1e9), softmax, weights @ V."""
    lin = lambda name, x: F.linear(x, p[f"{prefix}.{name}.weight"], p[f"{prefix}.{name}.bias"])  # noqa: E731
    r, lq, w = q_in.shape
    dh = w // heads
    q = lin("Wq", q_in).view(r, lq, heads, dh).transpose(1, 2)
    k = lin("Wk", kv_in).view(r, -1, heads, dh).transpose(1, 2)
    v = lin("Wv", kv_in).view(r, -1, heads, dh).transpose(1, 2)
    s = q @ k.transpose(-1, -2) / math.sqrt(dh)
    if key_valid is not None:
        s = s.masked_fill(~key_valid[:, None, None, :], -1e9)
    o = (s.softmax(-1) @ v).transpose(1, 2).reshape(r, lq, w)
    return lin("Wo", o)


def _reference_forward(p, cfg, x, t, text, text_mask, frame_mask):
    """The official forward written from the fact sheet (§2.1) directly on the state dict."""
    b, n, j, _ = x.shape
    w = cfg.width
    lin = lambda name, v: F.linear(v, p[f"{name}.weight"], p[f"{name}.bias"])  # noqa: E731
    ln = lambda name, v: F.layer_norm(v, (w,), p[f"{name}.weight"], p[f"{name}.bias"])  # noqa: E731
    h = lin("input_process.layers.2", F.relu(lin("input_process.layers.0", x)))
    h = (h.reshape(b, n * j, w) + p["pos_emb.pe"][:, : n * j]).view(b, n, j, w)
    half = w // 2
    freqs = torch.exp(-math.log(10000) * torch.arange(half) / half)
    ts = torch.cat([torch.cos(t[:, None].float() * freqs), torch.sin(t[:, None].float() * freqs)], -1)
    temb = lin("timestep_emb.mlp.2", F.silu(lin("timestep_emb.mlp.0", ts)))
    mem = lin("word_emb", text)

    def film(name, out):
        scale, shift = lin(f"{name}.linear.1", F.silu(temb)).chunk(2, -1)
        return out * (1 + scale[:, None, None]) + shift[:, None, None]

    def block(pre, z):
        tq = z.permute(0, 2, 1, 3).reshape(b * j, n, w)
        tmask = frame_mask.repeat_interleave(j, dim=0)  # rows (batch, part), batch-major
        o = _ref_attn(p, f"{pre}.temp_attn", ln(f"{pre}.temp_norm", tq), ln(f"{pre}.temp_norm", tq), tmask, cfg.heads)
        z = z + film(f"{pre}.temp_film", o.view(b, j, n, w).permute(0, 2, 1, 3))
        sq = ln(f"{pre}.skel_norm", z.reshape(b * n, j, w))
        z = z + film(f"{pre}.skel_film", _ref_attn(p, f"{pre}.skel_attn", sq, sq, None, cfg.heads).view(b, n, j, w))
        cq = ln(f"{pre}.cross_src_norm", z.reshape(b, n * j, w))
        o = _ref_attn(p, f"{pre}.cross_attn", cq, ln(f"{pre}.cross_tgt_norm", mem), text_mask, cfg.heads)
        z = z + film(f"{pre}.cross_film", o.view(b, n, j, w))
        f = lin(f"{pre}.ffn_linear2", F.gelu(lin(f"{pre}.ffn_linear1", ln(f"{pre}.ffn_norm", z))))
        return z + film(f"{pre}.ffn_film", f)

    skips = []
    for i in range(cfg.layers // 2):
        h = block(f"transformer.input_blocks.{i}", h)
        skips.append(h)
    h = block("transformer.middle_block", h)
    for i in range(cfg.layers // 2):
        h = lin(f"transformer.skip_blocks.{i}", torch.cat([h, skips.pop()], -1))
        h = block(f"transformer.output_blocks.{i}", h)
    return lin("output_process.layers.3", F.relu(lin("output_process.layers.1", ln("output_process.layers.0", h))))


def test_matches_reference_forward_of_the_official_architecture():
    model = _model()
    x, t, text, tm, fm = _inputs(TINY)
    with torch.no_grad():
        # random, non-trivial values for every parameter (norms and biases included)
        for prm in model.parameters():
            prm.normal_(0, 0.2)
        ref = _reference_forward(model.official_state_dict(), TINY, x, t, text, tm, fm)
        out = model(x, t, text, tm, fm)
    torch.testing.assert_close(out, ref, atol=1e-5, rtol=1e-5)


# ----------------------------------------------------------------- attention sites
def test_site_names_pinned_for_five_layers():
    expected = [
        "layers.0.temporal", "layers.0.skeletal", "layers.0.cross",
        "layers.1.temporal", "layers.1.skeletal", "layers.1.cross",
        "layers.2.temporal", "layers.2.skeletal", "layers.2.cross",
        "layers.3.temporal", "layers.3.skeletal", "layers.3.cross",
        "layers.4.temporal", "layers.4.skeletal", "layers.4.cross",
    ]
    model = _model()
    assert list(model.attn_processors) == expected
    sites = model.attention_sites
    tr = model.transformer
    # execution order: input blocks, middle, output blocks
    assert sites["layers.0.temporal"] is tr.input_blocks[0].temp_attn
    assert sites["layers.2.skeletal"] is tr.middle_block.skel_attn
    assert sites["layers.3.cross"] is tr.output_blocks[0].cross_attn
    assert sites["layers.4.cross"] is tr.output_blocks[1].cross_attn
    assert all(isinstance(p, SDPAProcessor) for p in model.attn_processors.values())
    ablation = Denoiser(DenoiserConfig(width=16, heads=2, layers=3, text_dim=8, cross_attention=False))
    assert list(ablation.attn_processors)[2] == "layers.0.sentence"


def test_set_attn_processor_with_dict_and_unknown_name():
    model = _model()
    eager = EagerProcessor()
    model.set_attn_processor({"layers.1.cross": eager, "layers.3.temporal": eager})
    procs = model.attn_processors
    assert procs["layers.1.cross"] is eager and procs["layers.3.temporal"] is eager
    assert sum(p is eager for p in procs.values()) == 2
    with pytest.raises(KeyError, match="layers.9.cross.*valid sites"):
        model.set_attn_processor({"layers.9.cross": eager})
    model.set_attn_processor(SDPAProcessor())
    assert not any(isinstance(p, EagerProcessor) for p in model.attn_processors.values())


def test_use_processors_restores_on_exit_and_on_exception():
    model = _model()
    before = model.attn_processors
    with use_processors(model, EagerProcessor()):
        assert all(isinstance(p, EagerProcessor) for p in model.attn_processors.values())
    assert model.attn_processors == before
    with pytest.raises(RuntimeError, match="boom"):
        with use_processors(model, {"layers.0.cross": EagerProcessor()}):
            assert isinstance(model.attn_processors["layers.0.cross"], EagerProcessor)
            raise RuntimeError("boom")
    assert model.attn_processors == before


@pytest.mark.parametrize("cross_attention", [True, False])
def test_eager_matches_sdpa_with_masks(cross_attention):
    cfg = DenoiserConfig(latent_dim=4, width=32, heads=4, ff_dim=48, layers=3, text_dim=12,
                         cross_attention=cross_attention)
    model = _model(cfg)
    x, t, text, tm, fm = _inputs(cfg)
    with torch.no_grad():
        fast = model(x, t, text, tm, fm)
        with use_processors(model, EagerProcessor()):
            eager = model(x, t, text, tm, fm)
    assert (fast - eager).abs().max().item() < 1e-5


class _Recorder:
    def __init__(self):
        self.calls: list[tuple[SiteInfo, torch.Tensor]] = []

    def __call__(self, site, probs):
        self.calls.append((site, probs.detach().clone()))
        return None


def test_controller_sees_every_site_with_documented_shapes_and_valid_rows():
    model = _model()
    x, t, text, tm, fm = _inputs(TINY)
    rec = _Recorder()
    with torch.no_grad(), use_processors(model, EagerProcessor(rec)):
        model(x, t, text, tm, fm)
    assert [s.name for s, _ in rec.calls] == site_names(TINY.layers)
    b, n, p, w = 3, 6, NUM_PARTS, 5
    for site, probs in rec.calls:
        assert site.batch == b and site.frames == n and site.parts == p and site.heads == TINY.heads
        assert tuple(probs.shape) == site.probs_shape
        assert int(site.name.split(".")[1]) == site.layer
        named = site.to_named(probs)
        assert named.shape[:1] == (b,) and len(site.named_axes) == named.dim()
        assert torch.equal(site.from_named(named), probs)
        torch.testing.assert_close(probs.sum(-1), torch.ones(probs.shape[:-1]))
        if site.kind == "temporal":
            assert probs.shape == (b * p, TINY.heads, n, n)
            # padded frames get no attention: sample 0 has 4 valid frames, rows (batch, part)
            assert torch.all(named[0, :, :, :, 4:] == 0) and torch.all(named[2, :, :, :, 2:] == 0)
            assert torch.all(named[1] > 0)
        elif site.kind == "skeletal":
            assert probs.shape == (b * n, TINY.heads, p, p)
        else:
            assert probs.shape == (b, TINY.heads, n * p, w)
            by_part = cross_probs_by_part(probs, n, p)
            assert torch.equal(by_part, named)
            # rows sum to 1 over valid tokens; masked tokens get exactly 0
            torch.testing.assert_close((named * tm[:, None, None, None, :]).sum(-1), torch.ones(b, TINY.heads, n, p))
            assert torch.all(named[1, ..., 3:] == 0) and torch.all(named[2, ..., 2:] == 0)


def test_controller_that_returns_its_input_changes_nothing_and_modified_probs_change_output():
    model = _model()
    x, t, text, tm, fm = _inputs(TINY)
    with torch.no_grad():
        ref = model(x, t, text, tm, fm)
        with use_processors(model, EagerProcessor(lambda site, probs: probs)):
            same = model(x, t, text, tm, fm)

        def flatten_cross(site, probs):
            if site.kind != "cross":
                return None
            uniform = tm[:, None, None, :].float()
            return (uniform / uniform.sum(-1, keepdim=True)).expand_as(probs).contiguous()

        with use_processors(model, EagerProcessor(flatten_cross)):
            edited = model(x, t, text, tm, fm)
    assert (same - ref).abs().max() < 1e-5
    assert (edited - ref).abs().max() > 1e-3

    def wrong_shape(site, probs):
        return probs[..., :1]

    with pytest.raises(ValueError, match="controller returned probs of shape"):
        with torch.no_grad(), use_processors(model, EagerProcessor(wrong_shape)):
            model(x, t, text, tm, fm)


# ------------------------------------------------------------------------- masking
@pytest.mark.parametrize("cross_attention", [True, False])
def test_valid_outputs_ignore_padded_frames_and_padded_tokens(cross_attention):
    cfg = DenoiserConfig(latent_dim=4, width=32, heads=4, ff_dim=48, layers=3, text_dim=12,
                         cross_attention=cross_attention)
    model = _model(cfg)
    x, t, text, tm, fm = _inputs(cfg)
    pooled = torch.randn(3, cfg.text_dim)  # fixed sentence feature: padded tokens must not matter
    x2, text2 = x.clone(), text.clone()
    x2[~fm] = torch.randn_like(x2[~fm]) * 10
    text2[~tm] = torch.randn_like(text2[~tm]) * 10
    with torch.no_grad():
        a = model(x, t, frame_mask=fm, text_context=model.prepare_text(text, tm, pooled))
        b = model(x2, t, frame_mask=fm, text_context=model.prepare_text(text2, tm, pooled))
    assert torch.allclose(a[fm], b[fm], atol=1e-5)
    assert not torch.allclose(a[~fm], b[~fm], atol=1e-3)  # the padded content did change


def test_default_pooled_sentence_is_mean_of_valid_tokens():
    text = torch.randn(2, 4, 3)
    mask = torch.tensor([[True, True, False, False], [True, True, True, True]])
    ctx = TextContext(text, mask)
    torch.testing.assert_close(ctx.pooled[0], text[0, :2].mean(0))
    torch.testing.assert_close(ctx.pooled[1], text[1].mean(0))
    with pytest.raises(ValueError, match="no valid token"):
        TextContext(text, torch.zeros(2, 4, dtype=torch.bool))


# -------------------------------------------------------------------- text context
def test_text_context_caches_projections_and_follows_weight_changes():
    model = _model()
    x, t, text, tm, fm = _inputs(TINY)
    ctx = model.prepare_text(text, tm)
    with torch.no_grad():
        a = model(x, t, frame_mask=fm, text_context=ctx)
        cache = ctx._cache
        b = model(x, t, frame_mask=fm, text_context=ctx)
        assert ctx._cache is cache  # projected once
        assert torch.equal(a, b)
        assert torch.equal(a, model(x, t, text, tm, fm))
        model.transformer.middle_block.cross_attn.Wv.weight.mul_(2.0)  # in-place weight change
        c = model(x, t, frame_mask=fm, text_context=ctx)
    assert ctx._cache is not cache
    # the autograd route (per-layer FiLMs, F.linear) agrees up to float rounding
    torch.testing.assert_close(c, model(x, t, text, tm, fm).detach())
    assert not torch.allclose(a, c)
    # replacing the parameter objects (load_state_dict(assign=True)) also invalidates the cache
    other = _model(seed=1).state_dict()
    model.load_state_dict(other, assign=True)
    with torch.no_grad():
        d = model(x, t, frame_mask=fm, text_context=ctx)
        assert torch.equal(d, model(x, t, text, tm, fm))
    # with gradients on, nothing is cached and word_emb receives gradients
    ctx2 = model.prepare_text(text, tm)
    model(x, t, frame_mask=fm, text_context=ctx2).square().mean().backward()
    assert ctx2._cache is None and model.word_emb.weight.grad.abs().sum() > 0


# ------------------------------------------------------------ timestep conditioning
def test_inference_forward_equals_the_autograd_forward():
    """Sampling's route (FiLM table, trimmed padding, oneDNN dense layers) against training's
    (per-layer FiLMs, F.linear), on the paper width where the dense layers are large enough."""
    cfg = DenoiserConfig(latent_dim=8, width=64, heads=4, ff_dim=128, layers=3, text_dim=16)
    model = _model(cfg)
    x, _, text, tm, fm = _inputs(cfg, b=3, n=6, w=9)
    tm[:, 6:] = False                                    # trailing padding in every row: trimmed
    for t in (torch.tensor([417]), torch.tensor([417, 12, 417])):
        with torch.enable_grad():
            ref = model(x, t, text, tm, fm)              # parameters need gradients: training route
        assert ref.requires_grad
        with torch.inference_mode():
            fast = model(x, t, text, tm, fm)
        torch.testing.assert_close(fast, ref.detach(), rtol=1e-5, atol=1e-5)


def test_timestep_table_is_filled_once_and_follows_weight_changes():
    model = _model()
    x, _, text, tm, fm = _inputs(TINY)
    t = torch.tensor([981])
    with torch.inference_mode():
        model.prepare_timesteps(torch.tensor([981, 961, 941]))
        table = timestep_table(model).rows(model)
        assert sorted(table) == [941.0, 961.0, 981.0]
        row = table[981.0]
        a = model(x, t, text, tm, fm)
        assert timestep_table(model).rows(model)[981.0] is row        # a hit, not recomputed
        temb, films = model.timestep_conditioning(torch.tensor([981, 5]))
        assert temb.shape == (2, TINY.width) and len(films) == TINY.layers
        assert films[0][0][0].shape == (2, 1, 1, TINY.width) and 5.0 in timestep_table(model).rows(model)
        expect = model.transformer.layers[2].cross_film(model.timestep_emb(torch.tensor([5])))
        torch.testing.assert_close(films[2][2][0][1:], expect[0])
        torch.testing.assert_close(films[2][2][1][1:], expect[1])
    with torch.no_grad():
        model.transformer.layers[1].ffn_film.linear[1].bias.add_(0.5)   # in-place change: table rebuilt
    with torch.inference_mode():
        b = model(x, t, text, tm, fm)
        assert 961.0 not in timestep_table(model).rows(model)
    with torch.enable_grad():
        ref = model(x, t, text, tm, fm)
    assert not torch.allclose(a, b)
    torch.testing.assert_close(b, ref.detach(), rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="no FiLM"):
        _model(replace(TINY, film=False)).timestep_conditioning(t)


def test_timestep_table_starts_over_when_full_and_keeps_the_call_s_timesteps(monkeypatch):
    import salad_core.models.inference as inference

    monkeypatch.setattr(inference, "TIMESTEP_CACHE", 3)
    model = _model()
    with torch.inference_mode():
        model.prepare_timesteps(torch.tensor([1, 2, 3]))
        temb, films = model.timestep_conditioning(torch.tensor([3, 7, 7]))   # 3 cached, 7 new: overflow
        assert sorted(timestep_table(model).rows(model)) == [3.0, 7.0]
    with torch.enable_grad():
        ref = model.timestep_emb(torch.tensor([3, 7, 7]))
    torch.testing.assert_close(temb, ref.detach())
    assert films[0][0][0].shape == (3, 1, 1, TINY.width)


def test_concat_pads_token_axes():
    a = TextContext(torch.randn(1, 3, 4), torch.ones(1, 3, dtype=torch.bool))
    b = TextContext(torch.randn(2, 5, 4), torch.ones(2, 5, dtype=torch.bool))
    c = TextContext.concat([a, b])
    assert c.text.shape == (3, 5, 4)
    assert c.mask.tolist()[0] == [True, True, True, False, False]
    assert torch.equal(c.text[0, :3], a.text[0]) and torch.all(c.text[0, 3:] == 0)
    assert a.repeat(4).batch_size == 4
    with pytest.raises(ValueError, match="only batch 1"):
        b.repeat(4)


# ------------------------------------------------------------------------ ablations
@pytest.mark.parametrize("flags", [dict(cross_attention=False), dict(film=False),
                                   dict(cross_attention=False, film=False)])
def test_ablation_variants_forward_backward(flags):
    cfg = DenoiserConfig(latent_dim=4, width=32, heads=4, ff_dim=48, layers=3, text_dim=12, **flags)
    model = _model(cfg).train()
    x, t, text, tm, fm = _inputs(cfg)
    out = model(x, t, text, tm, fm)
    assert out.shape == x.shape
    out.square().mean().backward()
    grads = {n: p.grad for n, p in model.named_parameters()}
    assert all(g is not None for g in grads.values())
    assert grads["word_emb.weight"].abs().sum() > 0          # text reaches the output
    assert grads["timestep_emb.mlp.0.weight"].abs().sum() > 0  # the timestep reaches the output
    if not cfg.film:
        assert not any("film" in n for n in grads)
    model.eval()
    with torch.no_grad():
        t2 = (t + 300) % 1000
        assert not torch.allclose(model(x, t, text, tm, fm), model(x, t2, text, tm, fm))
        other_text = torch.randn_like(text)
        assert not torch.allclose(model(x, t, text, tm, fm), model(x, t, other_text, tm, fm))


def test_input_errors_are_clear():
    model = _model()
    x, t, text, tm, fm = _inputs(TINY)
    with pytest.raises(ValueError, match="P=7, Dz=4"):
        model(x[..., :3], t, text, tm, fm)
    with pytest.raises(ValueError, match="C=12"):
        model(x, t, text[..., :5], tm, fm)
    with pytest.raises(ValueError, match="frame_mask"):
        model(x, t, text, tm, fm[:, :3])
    with pytest.raises(ValueError, match="no valid frame"):
        model(x, t, text, tm, torch.zeros_like(fm))
    with pytest.raises(ValueError, match="max_len"):
        model(torch.randn(1, 40, NUM_PARTS, 4), t[:1], text[:1], tm[:1])


@pytest.mark.parametrize("axis", [1, 2])
def test_attend_within_equals_attention_over_permuted_tokens(axis):
    """Self-attention along frames (temporal) or parts (skeletal) from one stacked QKV product equals
    the per-sequence attention of the permuted tokens, with and without a key mask."""
    from salad_core.models.attention import Attention, CallDims

    torch.manual_seed(axis)
    b, n, p, w = 2, 5, 3, 16
    attn = Attention(w, 4, 0.0, "temporal" if axis == 1 else "skeletal").eval()
    x = torch.randn(b, n, p, w)
    dims = CallDims(b, n, p, 0)
    if axis == 1:
        seq = x.permute(0, 2, 1, 3).reshape(b * p, n, w)          # rows (batch, part)
        mask = torch.ones(b * p, n, dtype=torch.bool)
        mask[p:, 3:] = False                                      # the second sample has 3 valid frames
    else:
        seq, mask = x.reshape(b * n, p, w), None                  # rows (batch, frame)
    with torch.no_grad():
        ref = attn(seq, key_mask=mask, dims=dims)
        out = attn.attend_within(x, axis, key_mask=mask, dims=dims)
    back = ref.view(b, p, n, w).permute(0, 2, 1, 3) if axis == 1 else ref.view(b, n, p, w)
    torch.testing.assert_close(out, back, rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="axis"):
        attn.attend_within(x, 3, dims=dims)


def test_stacked_qkv_cache_follows_weight_changes_and_lets_gradients_through():
    from salad_core.models.attention import Attention

    torch.manual_seed(0)
    attn = Attention(8, 2, 0.0, "temporal")
    with torch.inference_mode():
        w1, b1 = stacked_qkv(attn)
        assert stacked_qkv(attn)[0] is w1                         # cached while nothing changed
    torch.testing.assert_close(w1, torch.cat([attn.Wq.weight, attn.Wk.weight, attn.Wv.weight]).detach())
    with torch.no_grad():
        attn.Wk.weight.add_(1.0)                                  # an in-place update (optimiser step)
        w2, _ = stacked_qkv(attn)
    assert w2 is not w1 and torch.equal(w2[8:16], attn.Wk.weight)
    attn.load_state_dict({k: torch.zeros_like(v) for k, v in attn.state_dict().items()})
    with torch.no_grad():
        assert float(stacked_qkv(attn)[0].abs().sum()) == 0.0
    assert "_qkv_cache" not in "".join(attn.state_dict())          # not a buffer
    w3, b3 = stacked_qkv(attn)                                     # with gradients: a differentiable cat
    (w3.sum() + b3.sum()).backward()
    assert attn.Wv.weight.grad is not None and float(attn.Wv.weight.grad.sum()) == 64.0
