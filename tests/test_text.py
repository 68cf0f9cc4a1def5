"""Text encoders: MiniLM (shipped model) and CLIP (tiny random model built in tmp_path)."""
from __future__ import annotations

import json
import warnings
from pathlib import Path

import pytest
import torch

from salad_core.data.texts import split_words
from salad_core.text import (
    CLIPTextEncoder,
    MiniLMTextEncoder,
    TextBatch,
    TextEncoder,
    cat_text_batches,
    load_text_encoder,
    word_spans,
)


@pytest.fixture(scope="module")
def minilm() -> MiniLMTextEncoder:
    return MiniLMTextEncoder()


def _bert_word(tokens: list[str]) -> str:
    return "".join(t[2:] if t.startswith("##") else t for t in tokens)


# ---------------------------------------------------------------------------------- MiniLM
def test_minilm_shapes_mask_and_special_tokens(minilm):
    assert isinstance(minilm, TextEncoder)
    assert (minilm.name, minilm.dim, minilm.max_tokens, minilm.source) == ("minilm", 384, 512, "minilm")
    prompts = ["a man jumps", "a person somersaults, then walks forward!"]
    tb = minilm.encode(prompts)
    n = [len(t) for t in tb.tokens]
    assert tb.features.shape == (2, max(n), 384) and tb.features.dtype == torch.float32
    assert tb.mask.dtype == torch.bool and tb.mask.sum(1).tolist() == n
    assert tb.tokens[0] == ["[CLS]", "a", "man", "jumps", "[SEP]"]
    for toks, t2w in zip(tb.tokens, tb.token_to_word):
        assert toks[0] == "[CLS]" and toks[-1] == "[SEP]" and t2w[0] is None and t2w[-1] is None
    assert tb.words == [split_words(p) for p in prompts] and tb.prompts == prompts
    assert torch.all(tb.features[0, n[0]:] == 0)  # padding carries nothing
    assert tb.features[0, : n[0]].abs().sum(-1).min() > 0
    assert not tb.features.requires_grad


def test_minilm_word_map_with_multi_token_word(minilm):
    tb = minilm.encode(["a person somersaults, then walks!"])
    cols = tb.word_token_indices(0, "somersaults")
    assert len(cols) >= 2 and cols == list(range(cols[0], cols[-1] + 1))
    assert _bert_word([tb.tokens[0][j] for j in cols]) == "somersaults"
    assert tb.word_token_indices(0, 2) == cols and tb.word_token_indices(0, "SOMERSAULTS") == cols
    for w, word in enumerate(tb.words[0]):  # every word is exactly its tokens
        assert _bert_word([tb.tokens[0][j] for j in tb.word_token_indices(0, w)]) == word
    punct = [j for j, t in enumerate(tb.tokens[0]) if t in {",", "!"}]
    assert len(punct) == 2 and all(tb.token_to_word[0][j] is None for j in punct)
    assert tb.word_to_tokens(0)[2] == cols
    with pytest.raises(ValueError, match="'jumps' is not in prompt 0"):
        tb.word_token_indices(0, "jumps")
    with pytest.raises(IndexError, match="word index 9 is out of range"):
        tb.word_token_indices(0, 9)


def test_minilm_repeated_word_returns_every_occurrence(minilm):
    tb = minilm.encode(["walk, then walk again"])
    cols = tb.word_token_indices(0, "walk")
    assert [tb.tokens[0][j] for j in cols] == ["walk", "walk"] and len(cols) == 2


def test_minilm_padding_does_not_change_features(minilm):
    alone = minilm.encode(["a man jumps"])
    batched = minilm.encode(["a man jumps", "a person walks in a wide circle and then sits down"])
    n = len(alone.tokens[0])
    torch.testing.assert_close(batched.features[0, :n], alone.features[0], atol=1e-5, rtol=1e-5)


def test_minilm_deterministic_and_cached(minilm):
    a = minilm.encode(["a person kicks with the left leg"])
    b = minilm.encode(["a person kicks with the left leg"])
    assert torch.equal(a.features, b.features)
    again = MiniLMTextEncoder()
    assert again.model is minilm.model and again.tokenizer is minilm.tokenizer
    assert isinstance(load_text_encoder("minilm"), MiniLMTextEncoder)


def test_minilm_truncation_warns_with_dropped_words(minilm):
    short = MiniLMTextEncoder(max_tokens=6)
    assert short.model is minilm.model
    with pytest.warns(UserWarning, match=r"over the minilm limit of 6.*dropping the words: then walks") as rec:
        tb = short.encode(["a person somersaults then walks"])
    assert "cutting the word 'somersaults' in part" in str(rec[0].message)
    assert tb.features.shape[1] == 6 and tb.tokens[0][-1] == "[SEP]"
    assert tb.word_token_indices(0, "walks") == []
    # the model's own limit (512 positions)
    long_prompt = "a person walks " * 200 + "and finally jumps"
    with pytest.warns(UserWarning, match=r"limit of 512.*dropping the words: .*and finally jumps"):
        tb = minilm.encode([long_prompt])
    assert tb.features.shape == (1, 512, 384) and bool(tb.mask.all())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        minilm.encode(["a person walks"])  # no warning below the limit
    with pytest.raises(ValueError, match="max_tokens=600"):
        MiniLMTextEncoder(max_tokens=600)


def test_minilm_has_no_words_for_emoji_and_unknown_tokens_for_other_scripts(minilm):
    """What the pipelines' UnknownWordsWarning reads: emoji and most CJK become [UNK] and map to no word."""
    from salad_core.vocabulary import check_prompt

    tb = minilm.encode(["🕺💃🤸", "一个人在跳舞", "a person walks 🤸"])
    assert tb.words == [[], [], ["a", "person", "walks"]]
    assert tb.tokens[0] == ["[CLS]", "[UNK]", "[SEP]"] and "[UNK]" in tb.tokens[1]
    assert all(w is None for w in tb.token_to_word[1])
    checks = [check_prompt(p, {"a", "person", "walks"}, t) for p, t in zip(tb.prompts, tb.tokens)]
    assert [c.unk_tokens for c in checks] == [1, tb.tokens[1].count("[UNK]"), 1]
    assert [c.mostly_unknown for c in checks] == [True, True, False]


def test_prompt_validation_and_null_text(minilm):
    for bad in ([""], ["   "], ["a man walks", "\t"]):
        with pytest.raises(ValueError, match="empty or whitespace"):
            minilm.encode(bad)
    with pytest.raises(ValueError, match="non-empty list"):
        minilm.encode([])
    with pytest.raises(TypeError, match="wrap it in a list"):
        minilm.encode("a man walks")
    with pytest.raises(TypeError, match=r"prompts\[1\] must be a string"):
        minilm.encode(["a man walks", 3])
    with pytest.raises(ValueError, match="empty or whitespace"):
        minilm.encode(["  "], allow_empty=True)  # only the exact null text "" is allowed
    null = minilm.encode(["", "a man walks"], allow_empty=True)
    assert null.tokens[0] == ["[CLS]", "[SEP]"] and null.words[0] == [] and null.token_to_word[0] == [None, None]
    n2 = minilm.encode_null(3)
    assert n2.features.shape == (3, 2, 384)
    torch.testing.assert_close(n2.features[0], null.features[0, :2], atol=1e-5, rtol=1e-5)


def test_cat_text_batches_pads_with_masked_zeros(minilm):
    cond = minilm.encode(["a person somersaults, then walks forward"])
    both = cat_text_batches([cond, minilm.encode_null(2)])
    w = cond.features.shape[1]
    assert both.features.shape == (3, w, 384) and both.mask.sum(1).tolist() == [w, 2, 2]
    assert torch.all(both.features[1:, 2:] == 0)
    assert both.prompts == [cond.prompts[0], "", ""]
    torch.testing.assert_close(both.features[0], cond.features[0])
    with pytest.raises(ValueError, match="at least one"):
        cat_text_batches([])


def test_textbatch_validates_itself():
    with pytest.raises(ValueError, match="mask must be a bool tensor"):
        TextBatch(torch.zeros(1, 3, 4), torch.ones(1, 3), [["a", "b", "c"]], [[None, 0, None]], [["b"]], ["b"])
    with pytest.raises(ValueError, match="must agree"):
        TextBatch(torch.zeros(1, 3, 4), torch.ones(1, 3, dtype=torch.bool), [["a", "b"]], [[None, 0]], [["b"]], ["b"])


def test_word_spans_match_split_words():
    prompt = "A man's café-walk: 3D jumps!"
    spans = word_spans(prompt)
    assert [prompt[s:e].lower() for s, e in spans] == split_words(prompt) == ["a", "man", "s", "caf", "walk", "d", "jumps"]


def test_load_text_encoder_unknown_name(tmp_path):
    with pytest.raises(ValueError, match=r"unknown text encoder 'clip-b32'.*\"minilm\""):
        load_text_encoder("clip-b32")
    with pytest.raises(FileNotFoundError, match="no config.json"):
        CLIPTextEncoder(tmp_path)


# ------------------------------------------------------------------------------------ CLIP
def _byte_chars() -> list[str]:
    """The 256 printable stand-ins of byte-level BPE (GPT-2/CLIP convention)."""
    keep = [*range(ord("!"), ord("~") + 1), *range(ord("¡"), ord("¬") + 1), *range(ord("®"), ord("ÿ") + 1)]
    extra = [b for b in range(256) if b not in keep]
    return [chr(c) for c in keep] + [chr(256 + i) for i in range(len(extra))]


@pytest.fixture(scope="module")
def clip_dir(tmp_path_factory) -> Path:
    """A tiny CLIP folder: hand-made vocab.json/merges.txt and a random 2-layer CLIPTextModel."""
    from transformers import CLIPTextConfig, CLIPTextModel

    root = tmp_path_factory.mktemp("tiny_clip")
    chars = _byte_chars()
    vocab: dict[str, int] = {}
    for tok in chars + [c + "</w>" for c in chars]:
        vocab.setdefault(tok, len(vocab))
    merges = []
    for word in ("a", "person", "walks", "jumps", "forward", "man"):  # "somersaults" stays split
        symbols = list(word[:-1]) + [word[-1] + "</w>"]
        cur = symbols[0]
        for s in symbols[1:]:
            merges.append(f"{cur} {s}")
            cur += s
            vocab.setdefault(cur, len(vocab))
    bos, eos = "<|startoftext|>", "<|endoftext|>"
    vocab[bos] = len(vocab)
    vocab[eos] = len(vocab)
    (root / "vocab.json").write_text(json.dumps(vocab))
    (root / "merges.txt").write_text("#version: 0.2\n" + "\n".join(merges) + "\n")
    (root / "tokenizer_config.json").write_text(json.dumps({"tokenizer_class": "CLIPTokenizer", "model_max_length": 77}))
    cfg = CLIPTextConfig(vocab_size=len(vocab), hidden_size=32, intermediate_size=64, num_hidden_layers=2,
                         num_attention_heads=2, max_position_embeddings=77, bos_token_id=vocab[bos],
                         eos_token_id=vocab[eos], pad_token_id=vocab[eos])
    torch.manual_seed(0)
    CLIPTextModel(cfg).save_pretrained(root)
    return root


@pytest.fixture(scope="module")
def clip(clip_dir) -> CLIPTextEncoder:
    return CLIPTextEncoder(clip_dir)


def test_clip_shapes_mask_and_special_tokens(clip, clip_dir):
    assert (clip.name, clip.dim, clip.max_tokens) == ("clip", 32, 77)
    assert isinstance(load_text_encoder(str(clip_dir)), CLIPTextEncoder)
    tb = clip.encode(["a man jumps", "a person somersaults, then walks!"])
    assert tb.features.shape == (2, 77, 32) and tb.features.dtype == torch.float32
    assert tb.tokens[0] == ["<|startoftext|>", "a</w>", "man</w>", "jumps</w>", "<|endoftext|>"]
    assert tb.mask.sum(1).tolist() == [len(t) for t in tb.tokens]
    assert tb.mask[0, :5].all() and not tb.mask[0, 5:].any()  # BOS .. first EOS visible
    assert tb.token_to_word[0] == [None, 0, 1, 2, None]
    cols = tb.word_token_indices(1, "somersaults")
    assert len(cols) > 2 and "".join(tb.tokens[1][j] for j in cols).replace("</w>", "") == "somersaults"
    for w, word in enumerate(tb.words[1]):
        assert "".join(tb.tokens[1][j] for j in tb.word_token_indices(1, w)).replace("</w>", "") == word


def test_clip_features_are_text_model_without_attention_mask(clip, clip_dir):
    """As the official code: last_hidden_state of input_ids padded to 77, no mask passed."""
    from transformers import AutoTokenizer, CLIPTextModel

    model = CLIPTextModel.from_pretrained(str(clip_dir)).eval()
    tok = AutoTokenizer.from_pretrained(str(clip_dir))
    prompts = ["a person walks forward", ""]
    ids = tok(prompts, padding="max_length", max_length=77, return_tensors="pt")["input_ids"]
    with torch.no_grad():
        ref = model(input_ids=ids).last_hidden_state
    tb = clip.encode(prompts, allow_empty=True)
    torch.testing.assert_close(tb.features, ref)
    # the null text "" is encoded like any prompt: BOS + EOS visible
    assert tb.tokens[1] == ["<|startoftext|>", "<|endoftext|>"] and tb.mask[1].sum() == 2
    # real tokens do not depend on the padding (CLIP's causal mask)
    alone = clip.encode(["a person walks forward"])
    assert torch.equal(alone.features, clip.encode(["a person walks forward"]).features)
    torch.testing.assert_close(alone.features[0], tb.features[0])


def test_clip_loads_text_tower_of_full_clip_folder(clip_dir, tmp_path):
    """A downloaded openai/clip-* folder holds a CLIPModel; only its text tower must be used."""
    import shutil

    from transformers import CLIPConfig, CLIPModel, CLIPTextConfig, CLIPVisionConfig

    text_cfg = CLIPTextConfig.from_pretrained(str(clip_dir))
    vis_cfg = CLIPVisionConfig(hidden_size=16, intermediate_size=32, num_hidden_layers=1,
                               num_attention_heads=2, image_size=32, patch_size=16)
    torch.manual_seed(1)
    full = CLIPModel(CLIPConfig(text_config=text_cfg.to_dict(), vision_config=vis_cfg.to_dict(),
                                projection_dim=8)).eval()
    full.save_pretrained(tmp_path)
    for f in ("vocab.json", "merges.txt", "tokenizer_config.json"):
        shutil.copy(clip_dir / f, tmp_path / f)
    enc = load_text_encoder(tmp_path)
    assert isinstance(enc, CLIPTextEncoder)
    tb = enc.encode(["the man jumps"])
    ids = enc.tokenizer(["the man jumps"], padding="max_length", max_length=77, return_tensors="pt")["input_ids"]
    with torch.no_grad():
        ref = full.text_model(input_ids=ids).last_hidden_state
    torch.testing.assert_close(tb.features, ref)


def test_clip_truncation_and_validation(clip):
    prompt = "a person walks " * 30 + "then jumps forward"  # 90 + 3 word tokens > 75
    with pytest.warns(UserWarning, match=r"over the clip limit of 77.*dropping the words: .*then jumps forward"):
        tb = clip.encode([prompt])
    assert tb.features.shape == (1, 77, 32) and bool(tb.mask.all()) and tb.tokens[0][-1] == "<|endoftext|>"
    assert tb.word_token_indices(0, "jumps") == []
    with pytest.raises(ValueError, match="empty or whitespace"):
        clip.encode([""])
    a, b = clip.encode(["a man jumps"]), clip.encode(["a man jumps"])
    assert torch.equal(a.features, b.features)
