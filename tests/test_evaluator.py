"""T2M evaluator networks, official checkpoint loading, word vectorizer and matching loss."""
from __future__ import annotations

import os
import pickle

import numpy as np
import pytest
import torch
from torch.nn.utils.rnn import pack_padded_sequence

from salad_core import io as sio
from salad_core.eval.t2m import (
    EvaluatorConfig,
    T2MEvaluator,
    load_evaluator,
    matching_loss,
    save_evaluator,
)
from salad_core.eval.word_vectorizer import (
    POS_ENUMERATOR,
    UnsafePickleError,
    WordVectorizer,
    load_plain_pickle,
)
from salad_core.skeleton import get_skeleton

SMALL = dict(dim_word=8, dim_text_hidden=16, dim_coemb=12, dim_movement_enc_hidden=16,
             dim_movement_latent=16, dim_motion_hidden=16)

OFFICIAL_TEXT_KEYS = [
    "hidden", "pos_emb.weight", "pos_emb.bias", "input_emb.weight", "input_emb.bias",
    *[f"gru.{w}_{g}_l0{s}" for s in ("", "_reverse") for w, g in
      (("weight", "ih"), ("weight", "hh"), ("bias", "ih"), ("bias", "hh"))],
    "output_net.0.weight", "output_net.0.bias", "output_net.1.weight", "output_net.1.bias",
    "output_net.3.weight", "output_net.3.bias",
]


def _n_params(module: torch.nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


@pytest.fixture(scope="module")
def official_size():
    torch.manual_seed(0)
    return T2MEvaluator(EvaluatorConfig.for_skeleton("humanml3d")).eval()


@pytest.fixture()
def small():
    torch.manual_seed(1)
    return T2MEvaluator(EvaluatorConfig.for_skeleton("humanml3d", **SMALL)).eval()


# --------------------------------------------------------------------------- sizes and names
def test_parameter_counts_match_official(official_size):
    assert _n_params(official_size.movement_encoder) == 1_842_688
    assert _n_params(official_size.text_encoder) == 4_100_288
    assert _n_params(official_size.motion_encoder) == 15_747_584
    # KIT differs only in the movement encoder input: 251 - 4 = 247 channels
    kit = EvaluatorConfig.for_skeleton("kit")
    assert kit.dim_pose == get_skeleton("kit").feature_dim == 251 and kit.movement_input_dim == 247
    assert official_size.config.movement_input_dim == 259
    assert EvaluatorConfig() == EvaluatorConfig.for_skeleton("humanml3d")
    torch.manual_seed(0)
    kit_movement = T2MEvaluator(kit).movement_encoder
    assert _n_params(kit_movement) == 247 * 512 * 4 + 512 + 512 * 512 * 4 + 512 + 512 * 512 + 512


def test_state_dict_keys_are_official(official_size):
    assert sorted(official_size.movement_encoder.state_dict()) == sorted(
        ["main.0.weight", "main.0.bias", "main.3.weight", "main.3.bias", "out_net.weight", "out_net.bias"])
    assert sorted(official_size.text_encoder.state_dict()) == sorted(OFFICIAL_TEXT_KEYS)
    motion_keys = [k for k in OFFICIAL_TEXT_KEYS if not k.startswith("pos_emb")]
    assert sorted(official_size.motion_encoder.state_dict()) == sorted(motion_keys)
    sd = official_size.motion_encoder.state_dict()
    assert sd["hidden"].shape == (2, 1, 1024) and sd["gru.weight_ih_l0"].shape == (3 * 1024, 1024)
    assert official_size.movement_encoder.state_dict()["main.0.weight"].shape == (512, 259, 4)


def test_config_validation():
    with pytest.raises(ValueError, match="unit_length must be 4"):
        EvaluatorConfig(unit_length=2)
    with pytest.raises(ValueError, match="dim_pos_ohot must be 15"):
        EvaluatorConfig(dim_pos_ohot=10)
    with pytest.raises(ValueError, match="num_contacts"):
        EvaluatorConfig(dim_pose=4, num_contacts=4)
    with pytest.raises(ValueError, match="dim_coemb"):
        EvaluatorConfig(dim_coemb=0)


# --------------------------------------------------------------------------- fake official release
def _write_glove(folder, dim, rng):
    words = ["sos", "eos", "unk", "a", "man", "walk", "forward", "quickly", "his", "left", "hand", "and",
             "jump"]
    rows = rng.permutation(len(words))          # word -> row indirection, as in our_vab_idx.pkl
    table = np.zeros((len(words), dim), dtype=np.float32)
    vecs = rng.normal(size=(len(words), dim)).astype(np.float32)
    table[rows] = vecs
    folder.mkdir(parents=True)
    np.save(folder / "our_vab_data.npy", table)
    (folder / "our_vab_words.pkl").write_bytes(pickle.dumps(words))
    (folder / "our_vab_idx.pkl").write_bytes(pickle.dumps({w: int(r) for w, r in zip(words, rows)}))
    return words, vecs


def test_fake_finest_tar_round_trip(tmp_path, official_size):
    rng = np.random.default_rng(0)
    src = official_size
    ds = tmp_path / "checkpoints" / "t2m"
    (ds / "text_mot_match" / "model").mkdir(parents=True)
    # an Adam state dict as the release stores it (plain dicts, tensors, floats, tuples)
    opt = {"state": {0: {"step": torch.tensor(3.0), "exp_avg": torch.zeros(2, 1, 512)}},
           "param_groups": [{"lr": 1e-4, "betas": (0.9, 0.999), "eps": 1e-8, "params": [0, 1]}]}
    torch.save({
        "text_encoder": src.text_encoder.state_dict(),
        "motion_encoder": src.motion_encoder.state_dict(),
        "movement_encoder": src.movement_encoder.state_dict(),
        "opt_text_encoder": opt,
        "opt_motion_encoder": opt,
        "epoch": 7, "iter": 1234,
    }, ds / "text_mot_match" / "model" / "finest.tar")
    meta = ds / "Comp_v6_KLD005" / "meta"
    meta.mkdir(parents=True)
    mean = rng.normal(size=263).astype(np.float32)
    std = rng.uniform(0.5, 2.0, size=263).astype(np.float32)
    np.save(meta / "mean.npy", mean)
    np.save(meta / "std.npy", std)
    words, vecs = _write_glove(tmp_path / "glove", 300, rng)

    ev = T2MEvaluator.from_official(tmp_path / "checkpoints", "humanml3d")
    assert not ev.training
    for name in ("movement_encoder", "text_encoder", "motion_encoder"):
        a, b = getattr(src, name).state_dict(), getattr(ev, name).state_dict()
        assert all(torch.equal(a[k], b[k]) for k in a)
    np.testing.assert_array_equal(ev.mean.numpy(), mean)
    np.testing.assert_array_equal(ev.std.numpy(), std)
    assert ev.config.vocab == tuple(words)
    np.testing.assert_array_equal(ev.vectorizer.vectors, vecs)     # the idx indirection resolved

    # same embeddings as the source networks
    x = torch.randn(3, 24, 263)
    lengths = torch.tensor([24, 16, 20])
    torch.testing.assert_close(ev.motion_embeddings(x, lengths), src.motion_embeddings(x, lengths))
    caps = [["a/DET", "man/NOUN", "walk/VERB"], ["jump/VERB"]]
    t = ev.caption_embeddings(caps)
    w, p, n = ev.vectorizer.process_batch(caps)
    torch.testing.assert_close(t, src.text_embeddings(w, p, n))
    # normalize uses the evaluator's statistics
    raw = torch.randn(2, 263)
    torch.testing.assert_close(ev.normalize(raw), (raw - torch.from_numpy(mean)) / torch.from_numpy(std))

    # and through our safetensors checkpoint
    stem = tmp_path / "ours" / "t2m_eval"
    save_evaluator(stem, ev, meta={"source": "fake"})
    back, back_meta = load_evaluator(stem)
    assert back_meta == {"source": "fake"} and back.config == ev.config
    torch.testing.assert_close(back.motion_embeddings(x, lengths), ev.motion_embeddings(x, lengths))
    torch.testing.assert_close(back.caption_embeddings(caps), t)


def test_from_official_reports_missing_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="finest.tar"):
        T2MEvaluator.from_official(tmp_path, "humanml3d")
    (tmp_path / "kit" / "text_mot_match" / "model").mkdir(parents=True)
    (tmp_path / "kit" / "text_mot_match" / "model" / "finest.tar").write_bytes(b"x")
    with pytest.raises(FileNotFoundError, match="Comp_v6_KLD005"):
        T2MEvaluator.from_official(tmp_path, "kit")


def test_registered_for_generic_checkpoint_loading(small, tmp_path):
    config_cls, builder = sio._REGISTRY["t2m_evaluator"]
    doc_stem = tmp_path / "small"
    save_evaluator(doc_stem, small)
    doc, state = sio.read_checkpoint(doc_stem)
    assert doc["type"] == "t2m_evaluator"
    rebuilt = builder(sio.config_from_dict(config_cls, doc["config"]))
    sio.load_state_into(rebuilt, state)
    x, lengths = torch.randn(2, 12, 263), torch.tensor([12, 8])
    torch.testing.assert_close(rebuilt.eval().motion_embeddings(x, lengths), small.motion_embeddings(x, lengths))


# --------------------------------------------------------------------------- order handling
def test_motion_embeddings_are_in_input_order(small):
    torch.manual_seed(2)
    b, n = 6, 40
    x = torch.randn(b, n, 263)
    lengths = torch.tensor([12, 40, 20, 8, 36, 28])
    out = small.motion_embeddings(x, lengths)
    perm = torch.tensor([3, 0, 5, 1, 4, 2])
    out_perm = small.motion_embeddings(x[perm], lengths[perm])
    torch.testing.assert_close(out_perm, out[perm], atol=1e-5, rtol=1e-5)
    assert not torch.allclose(out[0], out[1], atol=1e-3)   # rows really differ

    # the official procedure: sort by length descending, pack sorted, embeddings in sorted order
    order = torch.argsort(lengths, descending=True)
    xs = x[order] * (torch.arange(n)[None, :] < lengths[order][:, None])[..., None]
    mov = small.movement_encoder(xs[..., :259])
    enc = small.motion_encoder
    packed = pack_padded_sequence(enc.input_emb(mov), lengths[order] // 4, batch_first=True)
    with torch.no_grad():
        _, last = enc.gru(packed, enc.hidden.repeat(1, b, 1))
        official_sorted = enc.output_net(torch.cat([last[0], last[1]], -1))
    torch.testing.assert_close(out[order], official_sorted, atol=1e-5, rtol=1e-5)


def test_text_embeddings_are_in_input_order(small):
    rng = np.random.default_rng(3)
    w = rng.normal(size=(5, 22, 8)).astype(np.float32)
    p = np.eye(15, dtype=np.float32)[rng.integers(0, 15, size=(5, 22))]
    n = np.array([5, 22, 3, 11, 9])
    out = small.text_embeddings(w, p, n)
    perm = np.array([2, 4, 0, 3, 1])
    torch.testing.assert_close(small.text_embeddings(w[perm], p[perm], n[perm]), out[perm], atol=1e-5, rtol=1e-5)
    # tokens past sent_len do not matter
    w2 = w.copy()
    w2[2, 3:] = 100.0
    torch.testing.assert_close(small.text_embeddings(w2, p, n)[2], out[2])


def test_motion_padding_and_contacts(small):
    torch.manual_seed(4)
    x = torch.randn(2, 32, 263)
    lengths = torch.tensor([16, 32])
    ref = small.motion_embeddings(x, lengths)
    junk = x.clone()
    junk[0, 16:] = 50.0
    junk[:, :, 259:] = -7.0                      # contact channels are ignored
    torch.testing.assert_close(small.motion_embeddings(junk, lengths), ref)
    # without masking the convolutions see past the length (as the official code would)
    assert not torch.allclose(small.motion_embeddings(junk, lengths, mask_padding=False)[0], ref[0])
    with pytest.raises(ValueError, match=r"lengths must be \(2,\) ints in \[4, N=32\]"):
        small.motion_embeddings(x, torch.tensor([3, 32]))
    with pytest.raises(ValueError, match="motions must be"):
        small.motion_embeddings(x[..., :259], lengths)


# --------------------------------------------------------------------------- word vectorizer
def _vocab(dim=4):
    words = ["sos", "eos", "unk", "a", "man", "walk", "forward", "quickly", "his", "left", "hand", "and"]
    vectors = np.arange(len(words) * dim, dtype=np.float32).reshape(len(words), dim)
    return WordVectorizer(words, vectors), words, vectors


def test_word_vectorizer_known_caption():
    wv, words, vectors = _vocab()
    # "a man walks forward quickly with his left hand and ..." as HumanML3D tokens; "with" is OOV
    tokens = ["a/DET", "man/NOUN", "walk/VERB", "forward/ADV", "quickly/ADV", "with/ADP", "his/PRON",
              "left/ADJ", "hand/NOUN", "and/CCONJ"]
    word_embs, pos_ohot, sent_len = wv.process_tokens(tokens)
    assert word_embs.shape == (22, 4) and pos_ohot.shape == (22, 15) and sent_len == 12
    P = POS_ENUMERATOR
    expected = [P["OTHER"], P["DET"], P["NOUN"], P["Act_VIP"], P["Loc_VIP"], P["Desc_VIP"], P["OTHER"],
                P["PRON"], P["Loc_VIP"], P["Body_VIP"], P["OTHER"], P["OTHER"]] + [P["OTHER"]] * 10
    assert pos_ohot.argmax(1).tolist() == expected
    assert (pos_ohot.sum(1) == 1).all()
    row = {w: vectors[i] for i, w in enumerate(words)}
    seq = ["sos", "a", "man", "walk", "forward", "quickly", "unk", "his", "left", "hand", "and", "eos"]
    np.testing.assert_array_equal(word_embs[:12], np.stack([row[w] for w in seq]))
    np.testing.assert_array_equal(word_embs[12:], np.tile(row["unk"], (10, 1)))   # unk padding


def test_word_vectorizer_crops_long_captions_and_batches():
    wv, _, vectors = _vocab()
    long = ["man/NOUN"] * 19 + ["walk/VERB"] * 6       # 25 tokens -> 20 kept
    w, p, n = wv.process_tokens(long)
    assert n == 22 and w.shape == (22, 4)
    assert p.argmax(1).tolist() == [14] + [1] * 19 + [12, 14]
    exactly = wv.process_tokens(["a/DET"] * 20)
    assert exactly[2] == 22
    W, Pb, N = wv.process_batch([long, ["a/DET"]])
    assert W.shape == (2, 22, 4) and Pb.shape == (2, 22, 15) and N.tolist() == [22, 3]
    with pytest.raises(ValueError, match="word/POS"):
        wv.process_tokens(["walk"])
    with pytest.raises(ValueError, match="special words"):
        WordVectorizer(["a", "b"], np.zeros((2, 3)))


def test_glove_folder_and_restricted_unpickler(tmp_path):
    rng = np.random.default_rng(5)
    words, vecs = _write_glove(tmp_path / "glove", 6, rng)
    wv = WordVectorizer.from_glove(tmp_path / "glove")
    assert wv.words == tuple(words) and wv.dim == 6
    np.testing.assert_array_equal(wv.lookup("jump/VERB")[0], vecs[words.index("jump")])
    assert load_plain_pickle(tmp_path / "glove" / "our_vab_idx.pkl")["sos"] >= 0


class _Evil:
    def __reduce__(self):
        return (os.system, ("echo pwned",))


class _Custom:
    pass


def test_restricted_unpickler_refuses_non_builtin_globals(tmp_path):
    path = tmp_path / "x.pkl"
    for obj, name in ((_Evil(), "system"), (_Custom(), "_Custom"), ({"a": _Custom()}, "_Custom")):
        path.write_bytes(pickle.dumps(obj))
        with pytest.raises(UnsafePickleError, match=name):
            load_plain_pickle(path)
    # eval is a builtin but not an allowed type
    path.write_bytes(b"cbuiltins\neval\n(V1+1\ntR.")
    with pytest.raises(UnsafePickleError, match="builtins.eval"):
        load_plain_pickle(path)
    path.write_bytes(b"c__builtin__\nset\n((lp0\nI1\naI2\natR.")   # a Python 2 set([1, 2])
    assert load_plain_pickle(path) == {1, 2}
    path.write_bytes(pickle.dumps({"w": [1, 2.5, "x", (True, None)]}, protocol=2))
    assert load_plain_pickle(path) == {"w": [1, 2.5, "x", (True, None)]}
    # a poisoned GloVe folder is refused too
    rng = np.random.default_rng(6)
    _write_glove(tmp_path / "glove", 3, rng)
    (tmp_path / "glove" / "our_vab_words.pkl").write_bytes(pickle.dumps(_Evil()))
    with pytest.raises(UnsafePickleError):
        WordVectorizer.from_glove(tmp_path / "glove")


# --------------------------------------------------------------------------- matching loss
def test_matching_loss_known_values():
    text = torch.zeros(3, 2)
    motion = torch.tensor([[3.0, 0.0], [0.0, 4.0], [12.0, 0.0]])
    loss = matching_loss(text, motion, margin=10.0, shift=1)
    # positives: d = 3, 4, 12; negatives text i vs motion i+1: d = 4, 12, 3
    assert loss.positive.item() == pytest.approx((9 + 16 + 144) / 3, rel=1e-5)
    assert loss.negative.item() == pytest.approx((36 + 0 + 49) / 3, rel=1e-5)
    assert loss.total.item() == pytest.approx(loss.positive.item() + loss.negative.item())


def test_matching_loss_zero_when_separated_and_gradients_flow():
    motion = torch.eye(4) * 20.0                  # distinct rows are 28 apart > margin
    assert matching_loss(motion.clone(), motion, shift=2).total.item() == pytest.approx(0.0, abs=1e-8)
    text = torch.zeros(4, 3, requires_grad=True)
    m = torch.randn(4, 3, generator=torch.Generator().manual_seed(0))
    matching_loss(text, m, generator=torch.Generator().manual_seed(1)).total.backward()
    assert text.grad is not None and text.grad.abs().sum() > 0
    # the random shift is never 0 (which would use the positives as negatives)
    pair = torch.tensor([[0.0], [1.0]])         # matched exactly; the only other pair is 1 apart
    for seed in range(20):
        neg = matching_loss(pair, pair.clone(), generator=torch.Generator().manual_seed(seed)).negative.item()
        assert neg == pytest.approx((10 - 1.0) ** 2, rel=1e-4)     # shift 0 would give 100
    with pytest.raises(ValueError, match="shift"):
        matching_loss(text, m, shift=4)
    with pytest.raises(ValueError, match="at least 2"):
        matching_loss(text[:1], m[:1])
