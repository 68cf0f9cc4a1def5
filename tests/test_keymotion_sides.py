"""KeyMotion's side cue: left/right token ids, the PST's ``side_embed``, the pipeline, the trainer's
PST batches and fine-tuning a PST without the cue (``KeyMotionTrainConfig.init_from``).

Tiny seeded models on one CPU thread and the hashing text encoder (``HashTextEncoder``), except for
the side ids of real MiniLM tokens and the shipped PST's checkpoint, which are loaded as they are.
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from salad_core.io import CheckpointError, load_model, save_checkpoint, save_tensors
from salad_core.keymotion.kf_vae import KeyframeVAE, KeyframeVAEConfig
from salad_core.keymotion.mmae import MMAEConfig, MotionMaskedAutoencoder
from salad_core.keymotion.pipeline import DEFAULT_WEIGHTS_DIR, KeyMotionPipeline
from salad_core.keymotion.pst import PST_DIFFUSION, ParallelSkipTransformer, PSTConfig, sample_latents
from salad_core.keymotion.sides import LEFT, NO_SIDE, RIGHT, side_ids, side_ids_of
from salad_core.keymotion.train import KeyMotionTrainConfig, load_pst_init
from salad_core.sampling import make_scheduler
from _doubles import HashTextEncoder

TEXT_DIM = 16
K = 8
SIDE_PROMPTS = ["a man waves his left hand", "a man waves his right hand", "a man walks forward"]

pytestmark = pytest.mark.usefixtures("single_thread")


# ------------------------------------------------------------------------------ helpers
def tiny_pst_config(**kw) -> PSTConfig:
    base = dict(latent_size=2, latent_dim=16, text_dim=TEXT_DIM, width=32, num_heads=4, ff_dim=64,
                num_cond_layers=1, num_cross_layers=2, dropout=0.0)
    base.update(kw)
    return PSTConfig(**base)


def with_cue(plain: ParallelSkipTransformer) -> ParallelSkipTransformer:
    """A side-cue copy of ``plain`` (its weights, ``side_embed`` zero)."""
    cue = ParallelSkipTransformer(dataclasses.replace(plain.config, side_cue=True))
    missing, unexpected = cue.load_state_dict(plain.state_dict(), strict=False)
    assert missing == ["side_embed.weight"] and unexpected == []
    return cue.eval()


def set_sides(pst: ParallelSkipTransformer, seed: int = 0) -> None:
    """Non-zero left and right rows (row 0, "no side", stays zero)."""
    with torch.no_grad():
        pst.side_embed.weight[1:] = torch.randn(2, pst.config.width, generator=torch.Generator().manual_seed(seed))


def _inputs(enc, prompts):
    tb = enc.encode(prompts)
    b = len(prompts)
    x = torch.randn(b, 2, 16, generator=torch.Generator().manual_seed(1))
    return tb, x, torch.arange(b) * 100 + 7, torch.full((b,), 60)


# ----------------------------------------------------------------------------- side ids
def test_side_ids_of_hand_written_tokens_pad_and_skip_wordpiece_continuations():
    tokens = [["[CLS]", "a", "man", "waves", "his", "Left", "hand", "[SEP]"],
              ["[CLS]", "right", "-", "hand", "punch", "[SEP]"],
              ["[CLS]", "steps", "left", "##ward", "##s", "then", "RIGHT", "##WARD", "[SEP]"],
              ["[CLS]", "the", "left", "##over", "##s", "and", "##left", "right</w>", "[SEP]"],
              []]
    ids = side_ids(tokens, 10)
    assert ids.dtype == torch.long and ids.shape == (5, 10)
    assert ids[0].tolist() == [0, 0, 0, 0, 0, LEFT, 0, 0, 0, 0]
    assert ids[1].tolist() == [0, RIGHT, 0, 0, 0, 0, 0, 0, 0, 0]
    # a word's first piece carries its side, its "##" pieces none
    assert ids[2].tolist() == [0, 0, LEFT, 0, 0, 0, RIGHT, 0, 0, 0]
    # "leftovers" is no side; a lone "##left" piece neither; CLIP's end-of-word mark is ignored
    assert ids[3].tolist() == [0, 0, 0, 0, 0, 0, 0, RIGHT, 0, 0]
    assert ids[4].tolist() == [NO_SIDE] * 10
    assert side_ids([], 4).shape == (0, 4)
    with pytest.raises(ValueError, match="prompt 1 has 9 tokens, more than width=8"):
        side_ids(tokens[1:3], 8)
    with pytest.raises(TypeError, match="list of token lists"):
        side_ids(["[CLS]", "left", "[SEP]"], 3)
    with pytest.raises(ValueError, match="width=-1 is invalid"):
        side_ids(tokens, -1)


@pytest.fixture(scope="module")
def minilm():
    from salad_core.text import load_text_encoder

    return load_text_encoder("minilm")


def test_side_ids_of_real_minilm_tokens_align_with_the_feature_columns(minilm):
    prompts = ["a man waves his left hand", "A man waves his RIGHT hand",
               "he steps leftwards, then kicks with the right leg", "a person walks"]
    tb = minilm.encode(prompts)
    ids = side_ids_of(tb)
    assert ids.shape == tuple(tb.mask.shape) and ids.device == tb.features.device
    assert torch.equal(ids, side_ids(tb.tokens, tb.features.shape[1]))
    assert not ids[~tb.mask].any()                                              # padding is 0
    for b, toks in enumerate(tb.tokens):
        marked = {toks[j]: int(ids[b, j]) for j in range(len(toks)) if ids[b, j]}
        assert all(tok in ("left", "right") for tok in marked)
    assert tb.tokens[0][int(ids[0].argmax())] == "left" and ids[0].tolist().count(LEFT) == 1
    assert tb.tokens[1][int(ids[1].argmax())] == "right" and ids[1].tolist().count(RIGHT) == 1
    row = ids[2, : len(tb.tokens[2])].tolist()
    left_at = tb.tokens[2].index("left")
    assert tb.tokens[2][left_at + 1].startswith("##")                          # "leftwards" is split
    assert row[left_at] == LEFT and row[left_at + 1] == NO_SIDE and row.count(RIGHT) == 1
    assert not ids[3].any()
    assert not side_ids_of(minilm.encode([""], allow_empty=True)).any()


# ----------------------------------------------------------------------------------- PST
def test_zero_initialised_cue_is_exactly_the_pst_without_it():
    torch.manual_seed(0)
    plain = ParallelSkipTransformer(tiny_pst_config()).eval()
    cue = with_cue(plain)
    assert torch.count_nonzero(cue.side_embed.weight) == 0
    assert cue.num_parameters() == plain.num_parameters() + 3 * 32
    enc = HashTextEncoder()
    tb, x, t, lens = _inputs(enc, SIDE_PROMPTS)
    sides = side_ids_of(tb)
    assert sides[0].tolist().count(LEFT) == 1 and sides[1].tolist().count(RIGHT) == 1
    with torch.no_grad():
        assert torch.equal(cue(x, t, tb.features, tb.mask, lens, sides), plain(x, t, tb.features, tb.mask, lens))


def test_a_trained_cue_separates_left_from_right_and_leaves_other_prompts_alone():
    torch.manual_seed(0)
    plain = ParallelSkipTransformer(tiny_pst_config()).eval()
    cue = with_cue(plain)
    set_sides(cue)
    enc = HashTextEncoder()
    tb, x, t, lens = _inputs(enc, SIDE_PROMPTS)
    sides = side_ids_of(tb)
    with torch.no_grad():
        ref = plain(x, t, tb.features, tb.mask, lens)
        out = cue(x, t, tb.features, tb.mask, lens, sides)
        torch.testing.assert_close(out[2], ref[2], rtol=0, atol=1e-6)          # no side word: unchanged
        assert not torch.allclose(out[:2], ref[:2], atol=1e-3)
        # the same features read as "left" or as "right" give different noise
        left = cue(x[:1], t[:1], tb.features[:1], tb.mask[:1], lens[:1], sides[:1])
        as_right = cue(x[:1], t[:1], tb.features[:1], tb.mask[:1], lens[:1], torch.where(sides[:1] == LEFT, RIGHT, 0))
        assert not torch.allclose(left, as_right, atol=1e-3)
    # row 0 ("no side") is a padding row: it never learns
    cue.train()
    loss = cue(x, t, tb.features, tb.mask, lens, sides).square().mean()
    loss.backward()
    grad = cue.side_embed.weight.grad
    assert torch.count_nonzero(grad[0]) == 0 and torch.count_nonzero(grad[1]) > 0 and torch.count_nonzero(grad[2]) > 0


def test_guided_with_the_cue_equals_the_two_branches_by_hand():
    torch.manual_seed(0)
    cue = with_cue(ParallelSkipTransformer(tiny_pst_config()))
    set_sides(cue, 1)
    enc = HashTextEncoder()
    tb, x, t, lens = _inputs(enc, SIDE_PROMPTS)
    null = enc.encode([""], allow_empty=True)
    sides, w = side_ids_of(tb), 3.5
    with torch.no_grad():
        guided = cue.guided(x, t, tb.features, tb.mask, null.features, null.mask, w, lens, sides)
        cond = cue(x, t, tb.features, tb.mask, lens, sides)
        b = len(SIDE_PROMPTS)
        uncond = cue(x, t, null.features.expand(b, -1, -1), null.mask.expand(b, -1), lens,
                     torch.zeros(b, null.features.shape[1], dtype=torch.long))
        torch.testing.assert_close(guided, uncond + w * (cond - uncond), atol=1e-5, rtol=1e-5)
        assert torch.equal(cue.guided(x, t, tb.features, tb.mask, null.features, null.mask, 1.0, lens, sides), cond)
        # the loop: sample_latents threads the sides to every step
        noise = torch.randn(b, 2, 16, generator=torch.Generator().manual_seed(2))
        z = sample_latents(cue, make_scheduler(PST_DIFFUSION, "ddim"), tb.features, tb.mask, null.features,
                           null.mask, noise, lengths=lens, guidance_scale=w, num_steps=3, text_sides=sides)
        z0 = sample_latents(cue, make_scheduler(PST_DIFFUSION, "ddim"), tb.features, tb.mask, null.features,
                            null.mask, noise, lengths=lens, guidance_scale=w, num_steps=3,
                            text_sides=torch.zeros_like(sides))
        torch.testing.assert_close(z[2], z0[2], rtol=0, atol=1e-6)
        assert not torch.allclose(z[:2], z0[:2], atol=1e-4)


def test_missing_unexpected_and_bad_text_sides_are_clear_errors():
    torch.manual_seed(0)
    plain = ParallelSkipTransformer(tiny_pst_config()).eval()
    cue = with_cue(plain)
    enc = HashTextEncoder()
    tb, x, t, lens = _inputs(enc, SIDE_PROMPTS)
    null = enc.encode([""], allow_empty=True)
    sides = side_ids_of(tb)
    f, m = tb.features, tb.mask
    sched = make_scheduler(PST_DIFFUSION, "ddim")
    missing = r"side cue \(PSTConfig.side_cue=True\): pass text_sides"
    with pytest.raises(ValueError, match=missing):
        cue(x, t, f, m, lens)
    with pytest.raises(ValueError, match=missing):
        cue.guided(x, t, f, m, null.features, null.mask, 2.0, lens)
    with pytest.raises(ValueError, match=missing):
        sample_latents(cue, sched, f, m, null.features, null.mask, x, lengths=lens, num_steps=2)
    unexpected = r"text_sides was given but this PST has no side cue"
    with pytest.raises(ValueError, match=unexpected):
        plain(x, t, f, m, lens, sides)
    with pytest.raises(ValueError, match=unexpected):
        plain.guided(x, t, f, m, null.features, null.mask, 2.0, lens, sides)
    with pytest.raises(ValueError, match=unexpected):
        sample_latents(plain, sched, f, m, null.features, null.mask, x, lengths=lens, num_steps=2, text_sides=sides)
    with pytest.raises(ValueError, match=r"text_sides must be \(B, W\) = \(3, 8\), got \(3, 7\)"):
        cue(x, t, f, m, lens, sides[:, :7])
    with pytest.raises(ValueError, match=r"text_sides must be \(B, W\) = \(3, 8\), got \(2, 8\)"):
        cue.guided(x, t, f, m, null.features, null.mask, 2.0, lens, sides[:2])
    with pytest.raises(ValueError, match="integer side ids"):
        cue(x, t, f, m, lens, sides.float())
    with pytest.raises(ValueError, match=r"in 0..2 .* got values 0..3"):
        cue(x, t, f, m, lens, sides + (sides == 2).long())
    with pytest.raises(ValueError, match="side_cue='yes' is invalid"):
        tiny_pst_config(side_cue="yes")


def test_checkpoints_without_the_field_load_as_no_cue_and_cue_checkpoints_round_trip(tmp_path):
    shipped = json.loads((DEFAULT_WEIGHTS_DIR / "pst.json").read_text())
    assert "side_cue" not in shipped["config"]
    model, config, _ = load_model(DEFAULT_WEIGHTS_DIR / "pst")
    assert config.side_cue is False and model.side_embed is None
    torch.manual_seed(0)
    cue = with_cue(ParallelSkipTransformer(tiny_pst_config()))
    set_sides(cue)
    save_checkpoint(tmp_path / "pst", cue, model_type="keymotion_pst", config=cue.config)
    again, config, _ = load_model(tmp_path / "pst")
    assert config.side_cue is True and torch.equal(again.side_embed.weight, cue.side_embed.weight)


# ------------------------------------------------------------------------------ pipeline
def tiny_components():
    torch.manual_seed(0)
    vae = KeyframeVAE(KeyframeVAEConfig(num_keyframes=K, frame_dim=56, index_dim=8, latent_size=2, latent_dim=16,
                                        num_layers=1, num_heads=4, ff_dim=128, dropout=0.0))
    mmae = MotionMaskedAutoencoder(MMAEConfig(text_dim=TEXT_DIM, width=64, num_layers=1, num_heads=4, ff_dim=128,
                                              dropout=0.0))
    return vae, ParallelSkipTransformer(tiny_pst_config()), mmae


def test_pipeline_with_a_cue_pst_runs_end_to_end_and_reads_the_sides(tmp_path):
    vae, plain, mmae = tiny_components()
    cue = with_cue(plain)
    enc = HashTextEncoder()
    kw = dict(lengths=[40, 40, 48], seed=3, guidance_scale=2.5, num_steps=3)
    ref = KeyMotionPipeline(vae, plain, mmae, enc, default_length=40)(SIDE_PROMPTS, **kw)
    pipe = KeyMotionPipeline(vae, cue, mmae, enc, default_length=40)
    out = pipe(SIDE_PROMPTS, **kw)
    np.testing.assert_array_equal(out.latents, ref.latents)                  # a zero cue changes nothing
    np.testing.assert_array_equal(out.features, ref.features)
    set_sides(cue)
    out = pipe(SIDE_PROMPTS, **kw)
    np.testing.assert_allclose(out.latents[2], ref.latents[2], rtol=0, atol=1e-6)
    assert not np.allclose(out.latents[:2], ref.latents[:2], atol=1e-4)
    assert out.features.shape == ref.features.shape and len(out.joints) == 3
    single = pipe("someone kicks with the left leg", num_steps=2, guidance_scale=1.0)   # conditional branch only
    assert single.latents.shape == (1, 2, 16)
    loaded = KeyMotionPipeline.from_pretrained(pipe.save_pretrained(tmp_path / "km"), text_encoder=enc)
    assert loaded.pst.config.side_cue is True
    np.testing.assert_array_equal(loaded(SIDE_PROMPTS, **kw).latents, out.latents)


# ------------------------------------------------------------------------------- trainer
def _side_corpus(root: Path) -> Path:
    """The fake corpus with captions that name sides (and one that does not)."""
    from _doubles import make_fake_corpus

    make_fake_corpus(root, n_train=6, n_val=2, lengths=(44, 90))
    verbs = ["waves the left hand", "waves the right hand", "kicks with the right leg", "steps leftwards",
             "walks forward", "raises the left arm", "punches with the right hand", "turns around"]
    for i, path in enumerate(sorted((root / "texts").glob("*.txt"))):
        v = verbs[i % len(verbs)]
        path.write_text(f"a person {v}#a/DET person/NOUN#0.0#0.0\nsomeone {v} slowly#someone/PRON#0.0#0.0\n")
    return root


@pytest.fixture(scope="module")
def side_corpus(tmp_path_factory) -> Path:
    return _side_corpus(tmp_path_factory.mktemp("fake_sides"))


def _tiny_kf_vae(train) -> KeyframeVAE:
    torch.manual_seed(0)
    vae = KeyframeVAE(KeyframeVAEConfig(num_keyframes=K, max_length=96, frame_dim=32, latent_dim=16, num_layers=1,
                                        ff_dim=64, dropout=0.0)).eval()
    vae.set_normalization(train.mean, train.std)
    return vae


def _keyframe_sets(root: Path):
    from salad_core.data.dataset import MotionTextDataset
    from salad_core.keymotion.train import KeyframeDataset

    train = MotionTextDataset(root, "train", max_length=96, random_crop=True, seed=0)
    val = MotionTextDataset(root, "val", max_length=96, mean=train.mean, std=train.std, random_crop=False)
    return KeyframeDataset(train, K, "uniform"), KeyframeDataset(val, K, "uniform")


@pytest.mark.parametrize("cache_size", [100, 1, 0])
def test_pst_batch_carries_text_sides_aligned_with_the_tokens(side_corpus, cache_size):
    from salad_core.keymotion.train import PrefilledCaptions, collate_keyframes, prepare_pst_batch
    from salad_core.train.common import StepContext
    from salad_core.train.denoiser_trainer import CaptionFeatureCache
    from salad_core.train.distributed import DistEnv, GlobalBatchRandom

    train, _ = _keyframe_sets(side_corpus)
    vae = _tiny_kf_vae(train)
    enc = HashTextEncoder()
    batch = collate_keyframes([train[i] for i in range(6)])
    captions = list(batch["caption"])
    assert any("left" in c for c in captions) and any("right" in c for c in captions)
    env = DistEnv()

    def prepare(side_cue: bool, drop: float = 0.0, train_mode: bool = True):
        text = PrefilledCaptions(CaptionFeatureCache(enc, cache_size), captions)
        ctx = StepContext(GlobalBatchRandom(torch.Generator().manual_seed(2), env), env, train=train_mode, step=0)
        cfg = KeyMotionTrainConfig(max_length=96, num_threads=1, progress=False, cond_drop_prob=drop)
        return prepare_pst_batch(batch, ctx, vae=vae, text=text, scheduler=make_scheduler(PST_DIFFUSION, "ddim"),
                                 config=cfg, latent_shape=vae.latent_shape, side_cue=side_cue)

    plain, cued = prepare(False), prepare(True)
    assert "text_sides" not in plain
    for k, v in plain.items():                                   # the cue adds its ids and changes nothing else
        assert torch.equal(cued[k], v), k
    sides = cued["text_sides"]
    assert sides.dtype == torch.long and sides.shape == cued["text_mask"].shape
    for b, caption in enumerate(captions):
        tokens = enc.encode([caption]).tokens[0]
        assert torch.equal(sides[b], side_ids([tokens], sides.shape[1])[0])
        for j, tok in enumerate(tokens):
            assert int(sides[b, j]) == {"left": LEFT, "leftwards": LEFT, "right": RIGHT}.get(tok, NO_SIDE), tok
    assert not sides[~cued["text_mask"]].any()
    assert (sides == LEFT).any() and (sides == RIGHT).any()
    dropped = prepare(True, drop=1.0)                            # "" for every caption: no side anywhere
    assert not dropped["text_sides"].any() and dropped["text_sides"].shape == dropped["text_mask"].shape
    val = prepare(True, drop=1.0, train_mode=False)              # validation keeps the captions
    assert torch.equal(val["text_sides"], sides)


def test_caption_cache_keeps_tokens_beside_features():
    from salad_core.train.denoiser_trainer import CaptionFeatureCache

    enc = HashTextEncoder()
    caps = ["a person waves the left hand", "", "someone kicks right"]
    for size in (100, 2, 0):
        cache = CaptionFeatureCache(enc, size)
        if size == 100:
            assert cache.prefill(caps) == 3
        feats, mask, tokens = cache.encode_with_tokens(caps + caps[:1])
        ref = enc.encode(caps + caps[:1], allow_empty=True)
        assert tokens == ref.tokens and torch.equal(mask, ref.mask)
        torch.testing.assert_close(feats, ref.features)
        assert set(cache._tokens) == set(cache._store) and len(cache._store) <= max(size, 0)


def _save_pst(path: Path, pst: ParallelSkipTransformer) -> Path:
    save_checkpoint(path, pst, model_type="keymotion_pst", config=pst.config)
    return path


def test_init_from_loads_a_no_cue_pst_into_a_cue_pst_and_names_real_mismatches(tmp_path):
    torch.manual_seed(0)
    plain = ParallelSkipTransformer(tiny_pst_config()).eval()
    stem = _save_pst(tmp_path / "plain", plain)
    torch.manual_seed(1)
    cue = ParallelSkipTransformer(tiny_pst_config(side_cue=True, dropout=0.1, max_length=96)).eval()
    assert load_pst_init(cue, str(stem) + ".json") == stem
    assert torch.count_nonzero(cue.side_embed.weight) == 0
    enc = HashTextEncoder()
    tb, x, t, lens = _inputs(enc, SIDE_PROMPTS)
    with torch.no_grad():
        assert torch.equal(cue(x, t, tb.features, tb.mask, lens, side_ids_of(tb)),
                           plain(x, t, tb.features, tb.mask, lens))
    # a pipeline folder and a training root's run folder resolve to their PST
    vae, _, mmae = tiny_components()
    folder = KeyMotionPipeline(vae, plain, mmae, enc).save_pretrained(tmp_path / "pipe")
    assert load_pst_init(with_cue(plain), folder) == folder / "pst"
    (tmp_path / "root" / "pst").mkdir(parents=True)
    _save_pst(tmp_path / "root" / "pst" / "latest", plain)
    assert load_pst_init(with_cue(plain), tmp_path / "root") == tmp_path / "root" / "pst" / "latest"
    # the shipped PST (no cue) starts a cue PST of its architecture
    shipped = PSTConfig(**{**json.loads((DEFAULT_WEIGHTS_DIR / "pst.json").read_text())["config"], "side_cue": True})
    assert load_pst_init(ParallelSkipTransformer(shipped), DEFAULT_WEIGHTS_DIR) == DEFAULT_WEIGHTS_DIR / "pst"
    # real mismatches
    with pytest.raises(ValueError, match=r"another architecture.*width: 32 \(init_from\) vs 64"):
        load_pst_init(ParallelSkipTransformer(tiny_pst_config(width=64, side_cue=True)), stem)
    with pytest.raises(ValueError, match=r"num_heads: 4 \(init_from\) vs 2"):
        load_pst_init(ParallelSkipTransformer(tiny_pst_config(num_heads=2)), stem)
    cue_stem = _save_pst(tmp_path / "cue", with_cue(plain))
    with pytest.raises(CheckpointError, match=r"unexpected keys \['side_embed.weight'\]"):
        load_pst_init(ParallelSkipTransformer(tiny_pst_config()), cue_stem)
    state = {k: v for k, v in plain.state_dict().items() if k != "out.bias"}
    state["extra.weight"] = torch.zeros(1)
    save_tensors(tmp_path / "broken.safetensors", state)
    (tmp_path / "broken.json").write_text(stem.with_suffix(".json").read_text())
    with pytest.raises(CheckpointError, match=r"missing keys \['out.bias'\]; unexpected keys \['extra.weight'\]"):
        load_pst_init(with_cue(plain), tmp_path / "broken")
    with pytest.raises(FileNotFoundError, match="init_from='.*nowhere' is neither"):
        load_pst_init(cue, tmp_path / "nowhere")
    save_checkpoint(tmp_path / "vae", vae, model_type="keymotion_kf_vae", config=vae.config)
    with pytest.raises(ValueError, match="holds a 'keymotion_kf_vae' model, not a 'keymotion_pst'"):
        load_pst_init(cue, tmp_path / "vae")
    with pytest.raises(ValueError, match="init_from='' is invalid"):
        KeyMotionTrainConfig(init_from="")


def test_train_pst_fine_tunes_a_no_cue_pst_with_the_cue_and_records_it(side_corpus, tmp_path, caplog):
    from salad_core.keymotion.train import build_kf_vae_task, train_pst
    from salad_core.train.distributed import DistEnv

    train, _ = _keyframe_sets(side_corpus)
    vae = _tiny_kf_vae(train)
    save_checkpoint(tmp_path / "kf_vae", vae, model_type="keymotion_kf_vae", config=vae.config)
    torch.manual_seed(0)
    plain = ParallelSkipTransformer(tiny_pst_config(max_length=96))
    stem = _save_pst(tmp_path / "old_pst", plain)
    enc = HashTextEncoder()
    cfg = KeyMotionTrainConfig(batch_size=4, max_steps=2, lr=1e-3, warmup_steps=1, val_every=2, val_batches=1,
                               ckpt_every=1, log_every=1, seed=7, num_threads=1, device="cpu", max_length=96,
                               progress=False, keyframe_method="uniform", init_from=str(stem))
    with caplog.at_level("INFO", logger="salad_core.keymotion.train"):
        res = train_pst(side_corpus, tmp_path / "pst", tmp_path / "kf_vae", tiny_pst_config(max_length=96,
                                                                                              side_cue=True),
                        cfg, enc)
    assert res.step == 2 and res.best_val is not None                       # trained and validated
    assert any("PST initialised from" in r.getMessage() for r in caplog.records)
    doc = json.loads((tmp_path / "pst" / "config.json").read_text())
    assert doc["train"]["init_from"] == str(stem) and doc["task"]["init_from"] == str(stem.resolve())
    assert doc["model"]["side_cue"] is True
    model, config, meta = load_model(tmp_path / "pst" / "latest")
    assert config.side_cue and meta["init_from"] == str(stem)
    assert torch.count_nonzero(model.side_embed.weight[1:]) > 0              # the cue learned
    assert torch.count_nonzero(model.side_embed.weight[0]) == 0
    with pytest.raises(ValueError, match="init_from=.*holds a 'keymotion_pst' model, not a 'keymotion_kf_vae'"):
        build_kf_vae_task(side_corpus, None, cfg, DistEnv())          # each stage starts only from its own kind


def test_fp16_keyframe_vae_statistics_are_not_another_corpus(side_corpus, tmp_path, caplog):
    """The shipped pipelines store the keyframe VAE's Mean/Std in fp16 (~5e-4 relative rounding): fine-tuning
    on their own corpus must not warn that the statistics differ; another corpus's statistics must."""
    from salad_core.keymotion.train import build_pst_task
    from salad_core.train.distributed import DistEnv

    train, _ = _keyframe_sets(side_corpus)
    cfg = KeyMotionTrainConfig(batch_size=4, max_steps=1, num_threads=1, device="cpu", max_length=96,
                               progress=False, keyframe_method="uniform", latent_cache=False)
    warned = {}
    for name, shift in (("same_fp16", 0.0), ("other", 0.1)):
        vae = _tiny_kf_vae(train)
        vae.set_normalization(train.mean + shift, train.std)
        save_checkpoint(tmp_path / name, vae, model_type="keymotion_kf_vae", config=vae.config,
                        dtype=torch.float16)
        caplog.clear()
        with caplog.at_level("WARNING", logger="salad_core.keymotion.train"):
            build_pst_task(side_corpus, tmp_path / name, tiny_pst_config(max_length=96), cfg, DistEnv(),
                           HashTextEncoder())
        warned[name] = any("other normalisation statistics" in r.getMessage() for r in caplog.records)
    assert warned == {"same_fp16": False, "other": True}




# ------------------------------------------------------------------ side-canonical training
@pytest.mark.parametrize("text, mirrored, left_first", [
    ("a man waves his left hand", "a man waves his right hand", True),
    ("Turns Left, then kicks with the RIGHT foot", "Turns Right, then kicks with the LEFT foot", True),
    ("kicks with the right leg, then steps leftwards", "kicks with the left leg, then steps rightwards", False),
    ("walks counterclockwise in a circle", "walks clockwise in a circle", True),
    ("walks clockwise in a circle", "walks counterclockwise in a circle", False),
    ("walks counter-clockwise", "walks clockwise", True),
    ("a left-handed throw", "a right-handed throw", True),
    ("a man walks forward", "a man walks forward", False),
    ("leftover lefty bright", "leftover lefty bright", False),
])
def test_mirror_side_words_swaps_every_side_word_and_names_left_first_reads_the_first(text, mirrored, left_first):
    from salad_core.keymotion.sides import mirror_side_words, names_left_first

    assert mirror_side_words(text) == mirrored
    assert names_left_first(text) is left_first
    assert names_left_first(mirrored) is (left_first if mirrored == text else not left_first)
    if "counter-" not in text:
        assert mirror_side_words(mirrored) == text                  # an involution


def test_side_canonical_pst_batch_mirrors_left_first_items_and_keeps_the_rest(side_corpus):
    """Items whose caption names the left kind first get the posterior of their mirrored keyframes and the
    swapped caption; right-first, side-free and dropped items are as without the option; the draws agree."""
    from salad_core.keymotion.kf_vae import gather_keyframes, indices_to_positions
    from salad_core.keymotion.sides import mirror_side_words, names_left_first
    from salad_core.keymotion.train import PrefilledCaptions, collate_keyframes, prepare_pst_batch
    from salad_core.motion import mirror_features
    from salad_core.train.common import StepContext
    from salad_core.train.denoiser_trainer import CaptionFeatureCache
    from salad_core.train.distributed import DistEnv, GlobalBatchRandom

    train, _ = _keyframe_sets(side_corpus)
    vae = _tiny_kf_vae(train)
    enc = HashTextEncoder()
    batch = collate_keyframes([train[i] for i in range(6)])
    captions = list(batch["caption"])
    left_first = [names_left_first(c) for c in captions]
    assert any(left_first) and not all(left_first)
    env = DistEnv()

    def prepare(canonical: bool, drop: float = 0.0):
        text = PrefilledCaptions(CaptionFeatureCache(enc, 100), captions + [mirror_side_words(c) for c in captions])
        ctx = StepContext(GlobalBatchRandom(torch.Generator().manual_seed(2), env), env, train=True, step=0)
        cfg = KeyMotionTrainConfig(max_length=96, num_threads=1, progress=False, cond_drop_prob=drop)
        return prepare_pst_batch(batch, ctx, vae=vae, text=text, scheduler=make_scheduler(PST_DIFFUSION, "ddim"),
                                 config=cfg, latent_shape=vae.latent_shape, side_canonical=canonical)

    plain, canon = prepare(False), prepare(True)
    assert torch.equal(plain["timesteps"], canon["timesteps"]) and torch.equal(plain["target"], canon["target"])
    # the mirrored items' clean latents, by hand: eps and the noise are the draws of the step in this order
    g = GlobalBatchRandom(torch.Generator().manual_seed(2), env)
    eps, t = g.randn(6, vae.latent_shape), g.randint(6, PST_DIFFUSION.num_train_timesteps)
    noise = g.randn(6, vae.latent_shape)
    motion = batch["motion"]
    kf = gather_keyframes(motion, batch["keyframes"])
    mirrored = vae.norm.normalize(mirror_features(vae.norm.denormalize(kf), "humanml3d"))
    sched = make_scheduler(PST_DIFFUSION, "ddim")
    with torch.no_grad():
        pos = indices_to_positions(batch["keyframes"], batch["length"])
        enc_plain = vae.encode(kf, pos, sample=False)
        enc_mirror = vae.encode(mirrored, pos, sample=False)
    for b, lf in enumerate(left_first):
        src = enc_mirror if lf else enc_plain
        z = src.mu[b] + eps[b] * torch.exp(0.5 * src.logvar[b])
        want = sched.add_noise(z[None], noise[b][None], t[b: b + 1])[0]
        torch.testing.assert_close(canon["noisy"][b], want, rtol=0, atol=1e-5)
        caption = mirror_side_words(captions[b]) if lf else captions[b]
        feats, mask = enc.encode([caption]).features, enc.encode([caption]).mask
        n = int(mask.sum())
        torch.testing.assert_close(canon["text"][b, :n], feats[0, :n].to(canon["text"].dtype))
        if not lf:
            assert torch.equal(canon["noisy"][b], plain["noisy"][b])
        else:
            assert not torch.allclose(canon["noisy"][b], plain["noisy"][b], atol=1e-3)
    dropped = prepare(True, drop=1.0)                              # every caption dropped: no item mirrored
    assert torch.equal(dropped["noisy"], prepare(False, drop=1.0)["noisy"])


def test_side_canonical_pipeline_gives_left_prompts_the_exact_mirror_of_the_right_ones(tmp_path):
    """A side-canonical PST generates a left-first prompt as its mirror image and mirrors the motion back, so a
    "left" prompt's motion is the exact mirror of its "right" twin's, seed for seed; side-free prompts are as
    with the same PST without the flag; the flag is saved and loaded with the weights."""
    from salad_core.motion import mirror_features

    vae, plain, mmae = tiny_components()
    canon = ParallelSkipTransformer(dataclasses.replace(plain.config, side_canonical=True))
    canon.load_state_dict(plain.state_dict())
    canon.eval()
    enc = HashTextEncoder()
    pipe = KeyMotionPipeline(vae, canon, mmae, enc, default_length=40)
    prompts = ["a man waves his left hand", "a man waves his right hand", "a man walks forward",
               "turns counterclockwise, then kicks with the right leg"]
    kw = dict(lengths=40, seed=5, guidance_scale=2.5, num_steps=3, side_check=False)
    out = pipe(prompts, **kw)
    assert out.canonical_mirrored == [True, False, False, True]
    right = pipe(["a man waves his right hand", "a man waves his right hand"], **kw)
    # same seed and row: the left prompt's motion is the mirror image of the right prompt's
    np.testing.assert_allclose(out.features[0], mirror_features(right.features[0]), rtol=0, atol=1e-5)
    np.testing.assert_allclose(out.latents[0], right.latents[0], rtol=0, atol=1e-4)   # other batch padding
    twin = pipe(["turns clockwise, then kicks with the left leg"] * 4, **kw)
    np.testing.assert_allclose(out.features[3], mirror_features(twin.features[3]), rtol=0, atol=1e-5)
    ref = KeyMotionPipeline(vae, plain.eval(), mmae, enc, default_length=40)(prompts, **kw)
    np.testing.assert_array_equal(out.features[1:3], ref.features[1:3])       # nothing else changes
    assert ref.canonical_mirrored == [False] * 4
    loaded = KeyMotionPipeline.from_pretrained(pipe.save_pretrained(tmp_path / "km"), text_encoder=enc)
    assert loaded.pst.config.side_canonical is True
    np.testing.assert_allclose(loaded(prompts, **kw).features, out.features, rtol=0, atol=1e-6)
