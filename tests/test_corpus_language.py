"""Corpus 2.0's language (issue 27, item 5): vocabulary and sentence frames, style and intent
words inside the phrase spans, the parser round trip on the new phrases, and mirroring."""
from __future__ import annotations

import numpy as np
import pytest

from salad_core.data.procedural import (FIGURE_PROMPTS, PRIMITIVES, Action, Plan, Step, in_language, parse_prompt,
                                        render_captions, sample_plan, sentence_frame, sentence_frames, vocabulary)
from salad_core.data.procedural.language import (LEXICON, POS_TAGS, SPEED_STYLE, VERBS, Caption, mirror_caption,
                                                 phrase_realisations, render_caption)
from salad_core.data.texts import split_words


@pytest.fixture(scope="module")
def sampled() -> list[tuple[Plan, Caption]]:
    """Captions of 250 random plans (3 each)."""
    out = []
    for i in range(250):
        rng = np.random.default_rng([31, i])
        plan = sample_plan(rng)
        out += [(plan, c) for c in render_captions(plan, rng, 3)]
    return out


def test_designed_vocabulary_and_frames_meet_the_targets():
    words = vocabulary()
    assert len(words) >= 600
    assert all(w in LEXICON for w in words), sorted(w for w in words if w not in LEXICON)
    frames = sentence_frames()
    assert len(frames) >= 100
    assert "<S> <A> then <A>" in frames and "at first <S> <A> later <P> <A>" in frames
    for lemma, forms in VERBS.items():                         # verb forms lemmatise to their verb
        assert all(LEXICON[f][0] == lemma for f in forms), lemma


def test_sampled_captions_are_varied(sampled):
    words = {w for _, c in sampled for w in c.words}
    frames = {c.frame for _, c in sampled}
    print(f"\n{len(sampled)} captions: {len(words)} words, {len(frames)} frames")
    assert len(words) >= 380 and len(frames) >= 120
    share = {w: np.mean([w in c.words for _, c in sampled]) for w in ("slowly", "quickly")}
    assert share["slowly"] < 0.1 and share["quickly"] < 0.1          # 1.0 had "slowly" in 16 %
    connective = {"then", "while", "and", "before", "after", "as", "first", "later", "eventually", "next",
                  "finally", "afterwards", "meanwhile", "simultaneously", "when", "throughout"}
    none = np.mean([not (set(c.frame.split()) & connective) for _, c in sampled])
    assert none < 0.45                                              # 1.0: 49 %


def test_every_sampled_caption_parses_back_exactly(sampled):
    for plan, cap in sampled:
        acts = plan.actions()
        parsed = parse_prompt(cap.text)
        assert parsed is not None and len(parsed) == len(acts), cap.text
        order = sorted(range(len(acts)), key=lambda k: cap.spans[k][0])
        for k, ph in zip(order, parsed):
            a = acts[k][2]
            assert ph.words == cap.spans[k], cap.text
            assert (ph.kind, ph.mods) == (a.kind, a.mods), cap.text
            assert ph.side in (None, a.side) and ph.reps in (None, a.reps), cap.text
        for word, (tok, pos) in zip(cap.words, cap.tokens):
            assert word in LEXICON and pos in POS_TAGS
            assert tok == (LEXICON[word][0] if pos in ("NOUN", "VERB") else word)


@pytest.mark.parametrize("prompt,want", [
    ("a person dances happily", [("dance", None, (), "")]),
    ("a person throws a ball", [("throw", None, (), "")]),
    ("a person walks on a treadmill", [("walk", None, (), "in_place")]),
    ("a man carefully kneels down on his left knee", [("kneel", "left", ("slowly",), "")]),
    ("the boxer throws a jab with his left hand and a cross with his right hand", [("jab_cross", "left", (), "")]),
    ("someone picks up a box with both hands, then walks forward energetically",
     [("pick_up", "both", (), ""), ("walk", None, ("quickly",), "")]),
    ("a woman scratches her head with her right hand as if confused", [("scratch_head", "right", (), "")]),
    ("at first a man does arm circles, later he lies down on his back",
     [("arm_circles", "both", (), ""), ("lie_down", None, (), "")]),
    ("we see a person tossing a ball underhand and then pivoting on their right foot",
     [("throw", None, (), "underhand"), ("pivot", "right", (), "")]),
    ("the person touches their left knee with their right hand", [("touch_knee", "right", (), "")]),
    # corpus 2.7
    ("a man bends down and touches his toes", [("touch_toes", "both", (), "")]),
    ("a woman touches her left foot with her right hand, then swings a golf club",
     [("touch_toes", "right", (), ""), ("swing", None, (), "")]),
    ("someone swings a baseball bat from his left shoulder", [("swing", "left", (), "bat")]),
    ("a person slowly reaches up to a high shelf with their right hand", [("reach_up", "right", ("slowly",), "")]),
    ("the man balances on his left leg as if doing yoga", [("balance", "left", (), "")]),
    ("a man kicks backward with his right leg and then lunges to the left",
     [("kick", "right", (), "back"), ("lunge", "left", (), "side")]),
    ("a person does a side kick with their left leg", [("kick", "left", (), "side")]),
])
def test_new_phrases_parse(prompt, want):
    got = [(p.kind, p.side, p.mods, p.variant) for p in parse_prompt(prompt)]
    assert got == want


def test_style_words_belong_to_the_phrase():
    (ph,) = parse_prompt("a man waves his left hand as if greeting a friend")
    assert ph.text == "waves his left hand as if greeting a friend" and ph.parts == ("left arm",)
    (ph,) = parse_prompt("a woman briskly walks forward")
    assert ph.words == (2, 5) and ph.mods == ("quickly",)
    a, b = parse_prompt("a man walks forward slowly, then jumps happily")
    assert a.mods == ("slowly",) and b.mods == () and b.text == "jumps happily"
    assert not in_language("a man flies to the moon happily")
    assert not in_language("happily")                                 # a style word needs its phrase


def test_speed_is_said_by_style_words_and_still_parses():
    action = Action("walk", None, ("slowly",))
    rng = np.random.default_rng(0)
    plan = Plan((Step(action),))
    caps = [render_caption(plan, rng) for _ in range(80)]
    said = [w for c in caps for w in c.words if any(w in x.split() for x in SPEED_STYLE["slowly"][0] + SPEED_STYLE["slowly"][1])]
    assert len(set(said)) >= 6                                       # not always "slowly"
    assert np.mean(["slowly" in c.words for c in caps]) < 0.6
    assert all(parse_prompt(c.text)[0].mods == ("slowly",) for c in caps)


def test_sentence_frame_of_a_caption():
    words = split_words("At first, a young man walks forward happily, later he jumps twice.")
    assert sentence_frame(words, [(5, 8), (10, 12)]) == "at first <S> <A> later <P> <A>"
    assert sentence_frame(split_words("we see the boxer throwing a left hook"), [(4, 8)]) == "we see <S> <A>"


def test_figure_prompts_stay_in_the_language():
    for prompt in FIGURE_PROMPTS:
        assert in_language(prompt), prompt


@pytest.mark.parametrize("kind", ["throw", "hook", "uppercut", "jab_cross", "kneel", "pivot", "touch_knee",
                                  "reach_across", "scratch_head", "salute", "pick_up",
                                  "touch_toes", "swing", "reach_up", "balance"])
def test_mirrored_captions_say_the_mirrored_action(kind):
    spec = PRIMITIVES[kind]
    for side in [s for s in spec.sides if s in ("left", "right")]:
        action = Action(kind, side, (), spec.reps[0], spec.variants[0])
        mirrored = action.mirrored()
        for i, items in enumerate(phrase_realisations(action, "pres", "his")):
            text = "a man " + " ".join(w for w, _, _ in items)
            cap = Caption(text, tuple((t, p) for _, t, p in [("a", "a", "DET"), ("man", "man", "NOUN")] + items),
                          ((2, 2 + len(items)),))
            m = mirror_caption(cap)
            (ph,) = parse_prompt(m.text)
            assert ph.kind == kind and ph.side in (None, mirrored.side), (text, m.text)
            assert m.spans == cap.spans
            swap = {"left": "right", "right": "left"}
            assert m.words == [swap.get(w, w) for w in cap.words]
            if i > 12:
                break
