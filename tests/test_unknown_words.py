"""What the model cannot read: the shipped training vocabularies, the prompt checks, the pipelines'
UnknownWordsWarning and ``out.unknown_words``, and the command line's one-line notes (issue 64)."""
from __future__ import annotations

import json
import shutil
import warnings

import numpy as np
import pytest

from salad_core import cli
from salad_core.data.texts import parse_text_line, split_words
from salad_core.pipeline import default_weights_dir
from salad_core.vocabulary import (UnknownWordsWarning, check_prompt, describe_unknown, load_vocabulary,
                                   training_vocabulary, vocabulary_info, write_vocabulary)

SALAD_VOCAB = load_vocabulary(default_weights_dir())
CHINESE = "一个人在跳舞"          # "a person is dancing"
EMOJI = "🕺💃🤸"


@pytest.fixture(scope="module")
def tiny_pipe(make_tiny_pipeline):
    """A tiny pipeline that reads with the shipped SALAD weights' vocabulary."""
    pipe = make_tiny_pipeline(seed=0)
    pipe.vocabulary, pipe.vocabulary_source = SALAD_VOCAB, "procedural corpus 2.4"
    return pipe


@pytest.fixture(scope="module")
def vocab_weights(tiny_pipe, tmp_path_factory):
    """The tiny pipeline saved as a weights folder, with the shipped vocabulary.json beside it."""
    return tiny_pipe.save_pretrained(tmp_path_factory.mktemp("vocab_weights"))


# ----------------------------------------------------------------------------- the vocabulary files
@pytest.mark.parametrize("model, version, n_words", [("salad", "2.4", 711), ("keymotion", "2.7", 726)])
def test_shipped_weights_record_their_training_vocabulary(model, version, n_words):
    root = default_weights_dir().parent / model
    doc = vocabulary_info(root)
    assert doc["corpus_version"] == version and doc["split"] == "train" and doc["n_clips"] == 6400
    words = doc["words"]
    assert len(words) == doc["n_words"] == n_words and words == sorted(set(words))
    assert all(w == split_words(w)[0] for w in words)                     # the split_words word forms
    vocab = load_vocabulary(root)
    assert {"a", "person", "walks", "jumps", "waves", "left", "right", "hand", "kicks"} <= vocab
    assert not {"cartwheel", "handstand", "flip", "backflip"} & vocab     # the corpus never had them
    assert ("golf" in vocab) == (version == "2.7")                        # corpus 2.7's new actions


def test_training_vocabulary_reads_the_training_captions_only(tiny_procedural_corpus, tmp_path):
    root = tiny_procedural_corpus
    words = training_vocabulary(root)
    assert words == sorted(set(words)) and len(words) > 100
    expected: set[str] = set()
    for clip in (root / "train.txt").read_text().split():
        for line in (root / "texts" / f"{clip}.txt").read_text().splitlines():
            expected.update(split_words(parse_text_line(line).caption))
    assert set(words) == expected
    assert set(training_vocabulary(root, "all")) >= expected
    path = write_vocabulary(words, tmp_path, corpus="procedural", corpus_version="test")
    assert load_vocabulary(tmp_path) == frozenset(words) and json.loads(path.read_text())["n_words"] == len(words)
    assert load_vocabulary(tmp_path / "nowhere") is None
    with pytest.raises(FileNotFoundError, match="val2.txt"):
        training_vocabulary(root, "val2")


# ----------------------------------------------------------------------------- the prompt check
def test_check_prompt_names_unknown_words_and_unreadable_text():
    cart = check_prompt("a person does a cartwheel", SALAD_VOCAB)
    assert cart.terms == ["cartwheel"] and cart.mostly_unknown      # the only content word
    line = describe_unknown(cart, 0, "procedural corpus 2.4")
    assert "cartwheel" in line and "mostly unknown" in line and line.startswith("prompt 0 'a person does")
    mixed = check_prompt("a man does a backflip and then walks forward", SALAD_VOCAB)
    assert mixed.terms == ["backflip"] and not mixed.mostly_unknown
    assert not check_prompt("a man waves his left hand", SALAD_VOCAB)
    for text in (CHINESE, EMOJI):
        c = check_prompt(text, SALAD_VOCAB, tokens=["[CLS]", "[UNK]", "[SEP]"])
        assert c.terms == [text] and c.mostly_unknown and c.unk_tokens == 1
        assert "another script" in describe_unknown(c) and "[UNK]" in describe_unknown(c)
    # without a vocabulary only unreadable text is found
    assert not check_prompt("a person does a cartwheel", None)
    assert check_prompt(f"a person walks {EMOJI}", None).terms == [EMOJI]


# ----------------------------------------------------------------------------- the pipelines
def test_generation_warns_once_and_records_the_unknown_words(tiny_pipe):
    with pytest.warns(UnknownWordsWarning) as rec:
        out = tiny_pipe(["a person does a cartwheel", CHINESE, "a man waves his left hand"], lengths=8,
                        num_steps=1)
    assert len([r for r in rec if r.category is UnknownWordsWarning]) == 1
    msg = str(rec[0].message)
    assert "prompt 0 'a person does a cartwheel'" in msg and "cartwheel" in msg and "procedural corpus 2.4" in msg
    assert f"prompt 1 '{CHINESE}'" in msg and "[UNK] tokens" in msg and msg.count("mostly unknown") == 2
    assert "prompt 2" not in msg
    assert rec[0].filename == __file__                              # points at the caller
    assert out.unknown_words == [["cartwheel"], [CHINESE], []]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert tiny_pipe("a man waves his left hand", lengths=8, num_steps=1).unknown_words == [[]]
        tiny_pipe.warn_unknown_words = False
        try:
            assert tiny_pipe(EMOJI, lengths=8, num_steps=1).unknown_words == [[EMOJI]]
        finally:
            tiny_pipe.warn_unknown_words = True


def test_edit_and_invert_warn_about_their_prompts(tiny_pipe, sample_features):
    from salad_core.attention import Reweight

    with pytest.warns(UnknownWordsWarning, match=r"target 0 'a man raises his hand in a cartwheel'.*cartwheel"):
        out = tiny_pipe.edit("a man raises his hand", "a man raises his hand in a cartwheel", edits=[],
                             lengths=8, num_steps=1)
    assert out.source.unknown_words == [[]] and out.edited.unknown_words == [["cartwheel"]]
    with pytest.warns(UnknownWordsWarning, match="handstand"):
        tiny_pipe.edit("a man does a handstand", edits=[Reweight(words="man", scale=2)], lengths=8, num_steps=1)
    with pytest.warns(UnknownWordsWarning, match="somersault"):
        inv = tiny_pipe.invert(sample_features[:8], "a person does a somersault", num_steps=1, reconstruct=False)
    assert tiny_pipe.reconstruct(inv).unknown_words == [["somersault"]]


def test_weights_folders_carry_their_vocabulary(vocab_weights):
    from salad_core.pipeline import SaladPipeline

    assert load_vocabulary(vocab_weights) == SALAD_VOCAB
    again = SaladPipeline.from_pretrained(vocab_weights)
    assert again.vocabulary == SALAD_VOCAB and again.vocabulary_source == "procedural corpus 2.4"


def test_shipped_pipelines_load_their_vocabularies_and_keymotion_warns():
    from salad_core.keymotion.pipeline import DEFAULT_WEIGHTS_DIR, KeyMotionPipeline

    km = KeyMotionPipeline.from_pretrained()
    assert km.vocabulary == load_vocabulary(DEFAULT_WEIGHTS_DIR) and km.vocabulary_source == "procedural corpus 2.7"
    with pytest.warns(UnknownWordsWarning, match=r"cartwheel.*procedural corpus 2\.7"):
        out = km(["a person does a cartwheel", "a person swings a golf club"], lengths=20, num_steps=1)
    assert out.unknown_words == [["cartwheel"], []]


# ----------------------------------------------------------------------------- the command line
def _err_lines(capsys) -> list[str]:
    return [line for line in capsys.readouterr().err.splitlines() if "salad_viz.export" not in line]


def test_generate_notes_unknown_words_and_marks_them_in_the_figure(vocab_weights, tmp_path, capsys, monkeypatch):
    import salad_viz

    seen = []
    real = salad_viz.plot_attention_grid

    def spy(*args, **kwargs):
        fig = real(*args, **kwargs)
        seen.append((kwargs, [ax.get_title() for ax in fig.axes if ax.images]))
        return fig
    monkeypatch.setattr(salad_viz, "plot_attention_grid", spy)
    out = tmp_path / "g"
    code = cli.main(["-q", "generate", "a person does a cartwheel", "a man waves his left hand", "--length", "8",
                     "--steps", "1", "--no-render", "--weights", str(vocab_weights), "--out", str(out)])
    assert code == 0
    err = _err_lines(capsys)
    assert err == ["salad generate: warning: prompt 0 'a person does a cartwheel': 1 word never seen in the "
                   "training captions (procedural corpus 2.4): cartwheel; the prompt is mostly unknown to the model "
                   "(none of its content words known), so the motion will not follow it"]
    assert (out / "00_a_person_does_a_cartwheel_attention.png").is_file()
    assert (out / "01_a_man_waves_his_left_hand_attention.png").is_file()
    (kwargs, titles), _ = seen
    assert kwargs["normalize"] == "global" and titles == ["person", "does", "cartwheel (unknown)"]
    code = cli.main(["-q", "generate", "a man waves his left hand", "--length", "8", "--steps", "1", "--no-render",
                     "--normalize", "each", "--weights", str(vocab_weights), "--out", str(tmp_path / "each")])
    assert code == 0 and seen[-1][0]["normalize"] == "each" and _err_lines(capsys) == []


def test_generate_says_why_a_prompt_in_another_script_gets_no_figure(vocab_weights, tmp_path, capsys):
    out = tmp_path / "g"
    code = cli.main(["-q", "generate", CHINESE, "--length", "8", "--steps", "1", "--no-render",
                     "--weights", str(vocab_weights), "--out", str(out)])
    assert code == 0
    err = _err_lines(capsys)
    assert err[0] == (f"salad generate: warning: prompt 0 '{CHINESE}' has no English (a-z) words, the words "
                      "attention maps are drawn for: no attention figure for it")
    assert err[1].startswith(f"salad generate: warning: prompt 0 '{CHINESE}': text the model cannot read")
    assert "mostly unknown" in err[1] and len(err) == 2
    assert sorted(p.name for p in out.iterdir()) == ["00_motion.bvh", "00_motion_features.npy",
                                                     "00_motion_joints.npy"]


def test_edit_notes_unknown_target_words_and_draws_signed_maps(vocab_weights, tmp_path, capsys, monkeypatch):
    import salad_viz

    seen = []
    real = salad_viz.plot_attention_grid

    def spy(*args, **kwargs):
        fig = real(*args, **kwargs)
        seen.append([(im.norm, im.get_cmap().name) for ax in fig.axes for im in ax.images])
        return fig
    monkeypatch.setattr(salad_viz, "plot_attention_grid", spy)
    out = tmp_path / "e"
    code = cli.main(["-q", "edit", "a man raises his right hand high", "--reweight", "high=-2", "--attention",
                     "--length", "8", "--steps", "2", "--weights", str(vocab_weights), "--out", str(out)])
    assert code == 0 and _err_lines(capsys) == []
    assert (out / "edited_attention.png").is_file()
    from matplotlib.colors import CenteredNorm

    assert all(isinstance(norm, CenteredNorm) and norm.vcenter == 0 and cmap == "RdBu_r" for norm, cmap in seen[0])
    code = cli.main(["-q", "edit", "a man raises his hand", "--target", "a man raises his hand in a cartwheel",
                     "--refine", "--length", "8", "--steps", "1", "--weights", str(vocab_weights),
                     "--out", str(tmp_path / "e2")])
    assert code == 0
    assert _err_lines(capsys) == ["salad edit: warning: target 'a man raises his hand in a cartwheel': 1 word never "
                                  "seen in the training captions (procedural corpus 2.4): cartwheel; the motion "
                                  "will not follow these words"]


def test_invert_notes_unknown_prompt_words(vocab_weights, sample_dir, tmp_path, capsys):
    path = tmp_path / "take_features.npy"
    np.save(path, np.load(sample_dir / "new_joint_vecs" / "012314.npy")[:40])
    code = cli.main(["-q", "invert", str(path), "--prompt", "a person does a handstand", "--steps", "1",
                     "--no-render", "--weights", str(vocab_weights), "--out", str(tmp_path / "inv")])
    assert code == 0
    err = _err_lines(capsys)
    assert len(err) == 1 and err[0].startswith("salad invert: warning: prompt 'a person does a handstand': 1 word")
    assert "handstand" in err[0]


def test_weights_without_a_vocabulary_note_only_unreadable_text(make_tiny_pipeline, tmp_path, capsys):
    weights = make_tiny_pipeline(seed=0).save_pretrained(tmp_path / "w")
    assert not (weights / "vocabulary.json").exists()
    code = cli.main(["-q", "generate", "a person does a cartwheel", f"a person walks {EMOJI}", "--length", "8",
                     "--steps", "1", "--no-render", "--no-attention", "--weights", str(weights),
                     "--out", str(tmp_path / "g")])
    assert code == 0
    err = _err_lines(capsys)
    assert len(err) == 1 and f"prompt 1 'a person walks {EMOJI}': text the model cannot read" in err[0]
    shutil.rmtree(weights)
