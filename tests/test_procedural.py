"""The procedural motion-language corpus (salad_core.data.procedural).

One ``tiny`` corpus (200 motions + mirrors) is built per session and shared; everything else
uses single generated clips. The sample HumanML3D motion 012314 is the physical reference.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from salad_core.data.procedural import (FIGURE_PROMPTS, PRIMITIVES, Action, Plan, Step, build_corpus,
                                        corpus_digest, corpus_figures, generate_clip, in_language, parse_prompt,
                                        part_activity, primitive_parts, realise, render_captions, sample_plan)
from salad_core.data.procedural.checks import bone_length_error, joint_angles
from salad_core.data.procedural.composition import MAX_FRAMES, MIN_FRAMES
from salad_core.data.procedural.kinematics import ANKLE_RANGE, body_model
from salad_core.data.procedural.language import LEXICON, POS_TAGS, mirror_caption
from salad_core.data.texts import parse_text_line, split_words
from salad_core.motion import features_to_joints, joints_to_features, mirror_joints
from salad_core.skeleton import PART_MIRROR, PART_NAMES, get_skeleton

SK = get_skeleton("humanml3d")


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("tiny_corpus")
    build_corpus(root, size="tiny", seed=0, progress=False)
    return root


@pytest.fixture(scope="module")
def figures(tiny, sample_dir) -> dict:
    return corpus_figures(tiny, reference=sample_dir)


def _ids(root: Path, split: str) -> list[str]:
    return (root / f"{split}.txt").read_text().split()


def _clip(kind: str, side=None, mods=(), reps=1, variant="", seed=0):
    return realise(Plan((Step(Action(kind, side, tuple(sorted(mods)), reps, variant)),)), np.random.default_rng(seed))


# ============================================================================ building
def test_build_is_deterministic_byte_for_byte(tiny, tmp_path):
    again = tmp_path / "again"
    build_corpus(again, size="tiny", seed=0, progress=False)
    assert corpus_digest(again) == corpus_digest(tiny)


def test_workers_and_seeds(tmp_path):
    one = build_corpus(tmp_path / "one", size=24, seed=3, progress=False, workers=1)
    two = build_corpus(tmp_path / "two", size=24, seed=3, progress=False, workers=2)
    assert one == two
    assert corpus_digest(tmp_path / "one") == corpus_digest(tmp_path / "two")
    build_corpus(tmp_path / "other", size=24, seed=4, progress=False)
    assert corpus_digest(tmp_path / "other") != corpus_digest(tmp_path / "one")


def test_refuses_non_empty_folder(tmp_path):
    out = tmp_path / "c"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match="not empty"):
        build_corpus(out, size=20, progress=False)
    build_corpus(out, size=20, progress=False, overwrite=True)
    assert (out / "notes.txt").read_text() == "mine"          # only the corpus's files are replaced
    assert len(_ids(out, "all")) == 40


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="size='huge'.*tiny"):
        build_corpus("/nonexistent/never", size="huge")
    with pytest.raises(ValueError, match="seed"):
        build_corpus("/nonexistent/never", size="tiny", seed=-1)
    with pytest.raises(ValueError, match="side 'left' not allowed"):
        Action("clap", "left")
    with pytest.raises(ValueError, match="unknown primitive"):
        Action("fly")
    with pytest.raises(ValueError, match="must end the plan"):
        Plan((Step(Action("sit")), Step(Action("walk"))))
    with pytest.raises(ValueError, match="cannot be layered on 'jumping_jacks'"):
        Step(Action("jumping_jacks", reps=2), Action("wave", "left"))
    with pytest.raises(ValueError, match="overlay must be an arm gesture"):
        Plan((Step(Action("walk")),), Action("nod", reps=2))


def test_layout_splits_and_stats(tiny):
    summary = json.loads((tiny / "corpus.json").read_text())
    assert summary["motions"] == 200 and summary["clips"] == 400 and summary["seed"] == 0
    splits = {s: _ids(tiny, s) for s in ("train", "val", "test")}
    assert [len(splits[s]) for s in ("train", "val", "test")] == [320, 20, 60]      # 0.80 / 0.05 / 0.15
    everything = set().union(*splits.values())
    assert len(everything) == 400 and sorted(everything) == _ids(tiny, "all")
    for ids in splits.values():                                 # mirrors live beside their originals
        originals = {i for i in ids if not i.startswith("M")}
        assert {i for i in ids if i.startswith("M")} == {"M" + i for i in originals}
    for mid in _ids(tiny, "all"):
        for sub, ext in (("new_joint_vecs", "npy"), ("new_joints", "npy"), ("texts", "txt"), ("annotations", "json")):
            assert (tiny / sub / f"{mid}.{ext}").is_file()
    feats = np.load(tiny / "new_joint_vecs" / "000000.npy")
    assert feats.dtype == np.float32 and feats.shape[1] == SK.feature_dim
    assert MIN_FRAMES - 1 <= summary["frames"]["min"] and summary["frames"]["max"] <= MAX_FRAMES - 1
    mean, std = np.load(tiny / "Mean.npy"), np.load(tiny / "Std.npy")
    train = np.concatenate([np.load(tiny / "new_joint_vecs" / f"{i}.npy") for i in splits["train"]])
    np.testing.assert_allclose(mean, train.mean(0), atol=1e-4)
    sl = SK.feature_slices["ric"]                                # std is averaged within a block
    assert np.allclose(std[sl], std[sl][0]) and abs(std[sl][0] - train[:, sl].std(0).mean()) < 1e-4


def test_dataset_loader_reads_the_corpus(tiny):
    from salad_core.data import MotionTextDataset

    ds = MotionTextDataset(tiny, "train", seed=0, with_annotations=True)
    assert ds.num_clips == 320 and not ds.skipped
    item = ds[5]
    assert item["motion"].shape == (196, SK.feature_dim) and item["length"] % 4 == 0
    ann = item["annotation"]
    assert ann["caption"] == item["caption"]
    words = split_words(item["caption"])
    for ph in ann["phrases"]:
        assert 0 <= ph["frames"][0] <= ph["frames"][1] <= item["length"]
        assert " ".join(words[ph["words"][0]:ph["words"][1]]) == ph["text"]
    test = MotionTextDataset(tiny, "test", random_crop=False)
    assert len(test) == 60


# ============================================================================ motions
def test_round_trip_through_the_features():
    clip = generate_clip(np.random.default_rng(11))
    feats = joints_to_features(clip.joints)
    rec = features_to_joints(feats)
    # the conversion puts the lowest joint on the floor; the clip starts at the origin facing +Z
    expected = clip.joints[:-1] - np.array([0.0, clip.joints[..., 1].min(), 0.0])
    assert np.abs(rec - expected).max() < 2e-4


def test_bone_lengths_exact_and_constant(figures):
    assert figures["bone_length_std_max"] < 1e-5
    assert figures["bone_length_error_max"] < 1e-5                # the target lengths of §1.1


def test_no_joint_below_the_floor_and_feet_on_it(tiny):
    for i in range(40):                                          # generated (before flooring)
        joints = generate_clip(np.random.default_rng([5, i])).joints
        assert joints[..., 1].min() > -0.01
    lowest = []
    for mid in _ids(tiny, "all")[::7]:
        joints = np.load(tiny / "new_joints" / f"{mid}.npy")
        lowest.append(joints[..., 1].min(-1))
    lowest = np.concatenate(lowest)
    assert lowest.min() > -0.01
    assert (lowest < 0.02).mean() > 0.9                          # something touches the floor


def test_foot_sliding_no_worse_than_real_data(figures):
    print(f"\nfoot sliding: corpus {figures['foot_sliding']:.4f} m/s, "
          f"HumanML3D 012314 {figures['foot_sliding_reference']:.4f} m/s")
    assert figures["foot_sliding"] <= figures["foot_sliding_reference"]
    assert figures["foot_sliding"] < 0.05


def test_planted_feet_do_not_slide_and_root_follows_the_stride():
    from salad_core.data.procedural.footwork import ANKLE_HEIGHT, TOE_HEIGHT

    for i in range(30):                      # raw clips: a foot joint resting on the floor stays put
        j = generate_clip(np.random.default_rng([7, i])).joints
        for joint, h in zip(SK.contact_joints, (ANKLE_HEIGHT, TOE_HEIGHT) * 2):
            y = j[:, joint, 1]
            rest = (y[1:] < h + 5e-4) & (y[:-1] < h + 5e-4)
            step = np.linalg.norm(np.diff(j[:, joint][:, [0, 2]], axis=0), axis=-1)[rest]
            assert step.size == 0 or step.max() < 1e-3, (i, joint, step.max())
    from salad_core.data.procedural.kinematics import rot_y

    for seed in (2, 3, 4):
        clip = _clip("walk", seed=seed)
        j = clip.joints
        root = j[-1, 0] - j[0, 0]
        # 2.5: a walk may drift along a gentle arc; the feet end around the root as they began,
        # turned by the heading the walk gained
        turn = clip.events[0].info["turn"]
        for toe in (SK.fid_l[1], SK.fid_r[1]):   # the feet travel exactly as far as the root
            off = j[0, toe] - j[0, 0]
            want = root + rot_y(turn) @ off - off
            np.testing.assert_allclose((j[-1, toe] - j[0, toe])[[0, 2]], want[[0, 2]], atol=0.02)
        assert np.linalg.norm(root[[0, 2]]) > 2.0


def test_joint_angles_in_human_ranges(figures):
    assert figures["knee_flexion_max_deg"] < 150
    assert figures["elbow_flexion_max_deg"] < 160
    assert figures["knee_bend_min"] > -0.02                       # knees never bend backwards
    lo, hi = figures["ankle_angle_range_deg"]
    assert ANKLE_RANGE[0] - 1 <= lo and hi <= ANKLE_RANGE[1] + 1


def test_smooth_blends():
    for i in range(20):
        j = generate_clip(np.random.default_rng([9, i])).joints
        acc = np.linalg.norm(j[2:] - 2 * j[1:-1] + j[:-2], axis=-1) * 400.0   # m/s^2 at 20 fps
        assert acc.max() < 300.0, i


def test_fk_and_ik_build_exact_bones():
    body = body_model()
    clip = _clip("kick", "left", ("high",))
    err = bone_length_error(clip.joints)
    assert err["max_std"] < 1e-9 and err["max_error"] < 1e-9
    angles = joint_angles(clip.joints)
    assert angles["knee"].max() > 60                              # the kick bends the knee
    assert body.leg[0] == pytest.approx(0.39362 + 0.43243)


# ============================================================================ primitives and modifiers
def test_primitive_inventory():
    assert len(PRIMITIVES) >= 20
    driven = set()
    for kind, spec in PRIMITIVES.items():
        for side in spec.sides:
            driven |= set(primitive_parts(Action(kind, side, (), spec.reps[0], ""))[0])
    assert driven == set(PART_NAMES)                              # all 7 body parts
    for kind in ("wave", "raise", "punch", "kick", "knee_lift", "look", "sidestep", "turn"):
        assert {"left", "right"} <= set(PRIMITIVES[kind].sides)
    cats = {s.category for s in PRIMITIVES.values()}
    assert cats == {"locomotion", "jump", "arms", "legs", "whole body", "head"}


@pytest.mark.parametrize("kind,side,part", [("wave", "left", "left arm"), ("raise", "right", "right arm"),
                                            ("kick", "left", "left leg"), ("knee_lift", "right", "right leg"),
                                            ("nod", None, "head"), ("look", "left", "head"),
                                            ("walk", None, "root"), ("bow", None, "spine")])
def test_each_primitive_moves_its_part_most(kind, side, part):
    clip = _clip(kind, side, reps=PRIMITIVES[kind].reps[0], seed=4)
    act = part_activity(clip.joints, clip.events[0].frames)
    driven = PART_NAMES.index(part)
    _, secondary = primitive_parts(clip.events[0].action)
    idle = [p for p in range(len(PART_NAMES)) if PART_NAMES[p] not in clip.events[0].parts + secondary]
    # 2x (1.0: 3x): idle parts now breathe, shift weight and wander (issue 27, item 3)
    assert all(act[driven] > 2 * act[p] for p in idle), (act.round(3), idle)


def _mean(values):
    return float(np.mean(values))


def test_modifiers_change_the_motion_measurably():
    seeds = range(3)
    apex = {m: _mean([_clip("jump", mods=m, seed=s).joints[:, 0, 1].max() for s in seeds]) for m in ((), ("high",), ("low",))}
    assert apex[("high",)] > apex[()] + 0.1 and apex[()] > apex[("low",)] + 0.05
    wrist = {m: _mean([_clip("raise", "left", m, seed=s).joints[:, SK.joint_names.index("left_wrist"), 1].max() for s in seeds])
             for m in ((), ("high",), ("low",))}
    assert wrist[("high",)] > wrist[()] + 0.05 and wrist[()] > wrist[("low",)] + 0.2
    kick = {m: _mean([_clip("kick", "right", m, seed=s).joints[:, SK.joint_names.index("right_ankle"), 1].max() for s in seeds])
            for m in (("high",), ("low",))}
    assert kick[("high",)] > kick[("low",)] + 0.3

    def speed(c):
        f0, f1 = c.events[0].frames
        return np.linalg.norm(c.joints[f1 - 1, 0, [0, 2]] - c.joints[f0, 0, [0, 2]]) / ((f1 - f0) / 20)
    walk = {m: _mean([speed(_clip("walk", mods=m, seed=s)) for s in seeds]) for m in (("slowly",), (), ("quickly",))}
    assert walk[("slowly",)] < 0.75 * walk[()] and walk[("quickly",)] > 1.2 * walk[()]
    dur = {m: _mean([np.diff(_clip("wave", "right", m, seed=s).events[0].frames)[0] for s in seeds])
           for m in (("slowly",), ("quickly",))}
    assert dur[("slowly",)] > dur[("quickly",)]
    depth = {m: _mean([_clip("squat", mods=m, seed=s).joints[:, 0, 1].min() for s in seeds]) for m in ((), ("low",))}
    assert depth[("low",)] < depth[()] - 0.05


def test_mirrored_left_action_looks_like_the_right_one():
    import dataclasses

    from salad_core.data.procedural.footwork import Persona

    # a symmetric performer without idle sway or wander: those are (deliberately) not mirrored
    persona = dataclasses.replace(Persona.sample(np.random.default_rng(3)), tilt=0.0, arm_asym=0.0,
                                  liveliness=0.0, sway=0.0, twist=0.0, arm_offsets=((0.0,) * 3,) * 2)

    def clip(side):
        return realise(Plan((Step(Action("wave", side)),)), np.random.default_rng(3), persona=persona)
    left, right = clip("left"), clip("right")
    mirrored = mirror_joints(left.joints)
    act_l, act_m = part_activity(left.joints), part_activity(mirrored)
    la, ra = PART_NAMES.index("left arm"), PART_NAMES.index("right arm")
    assert act_m[ra] == pytest.approx(act_l[la], rel=1e-6) and act_m[la] == pytest.approx(act_l[ra], rel=1e-6)
    assert act_m[ra] > 20 * act_m[la]
    # the skeleton's left and right bones differ by up to ~1 cm, hence the tolerance
    assert np.abs(mirrored - right.joints).max() < 0.05


# ============================================================================ captions and ground truth
def test_captions_format(tiny, figures):
    assert figures["captions_per_clip_min"] >= 3
    for mid in _ids(tiny, "all")[::9]:
        lines = (tiny / "texts" / f"{mid}.txt").read_text().splitlines()
        assert len(lines) >= 3 and len(set(lines)) == len(lines)
        for n, line in enumerate(lines):
            t = parse_text_line(line, f"{mid}:{n}")
            words = split_words(t.caption)
            assert len(t.tokens) == len(words) and t.whole_clip
            for word, tok in zip(words, t.tokens):
                lemma, pos = tok.split("/")
                assert pos in POS_TAGS
                if pos in ("NOUN", "VERB"):
                    assert lemma == LEXICON.get(word, (lemma,))[0]
                else:
                    assert lemma == word


def test_tokens_are_lemmatised():
    plan = Plan((Step(Action("jump", variant="forward")), Step(Action("walk"))), Action("wave", "both", (), 1, "arms"))
    caps = render_captions(plan, np.random.default_rng(0), 20)
    cap = next(c for c in caps if "waving" in c.words)
    tokens = dict(zip(cap.words, cap.tokens))
    assert tokens["waving"] == ("wave", "VERB") and tokens["arms"] == ("arm", "NOUN")


def test_annotations_match_captions_and_motion(tiny):
    for mid in _ids(tiny, "all")[::5]:
        ann = json.loads((tiny / "annotations" / f"{mid}.json").read_text())
        rows = np.load(tiny / "new_joint_vecs" / f"{mid}.npy").shape[0]
        lines = [parse_text_line(ln).caption for ln in (tiny / "texts" / f"{mid}.txt").read_text().splitlines()]
        assert ann["name"] == mid and ann["num_frames"] == rows and ann["fps"] == 20
        assert [c["caption"] for c in ann["captions"]] == lines
        for cap in ann["captions"]:
            words = split_words(cap["caption"])
            phrases = cap["phrases"]
            assert phrases and all(p["parts"] and set(p["parts"]) <= set(PART_NAMES) for p in phrases)
            spans = sorted(tuple(p["words"]) for p in phrases)
            assert all(a[1] <= b[0] for a, b in zip(spans, spans[1:]))        # phrases do not overlap
            for p in phrases:
                assert " ".join(words[p["words"][0]:p["words"][1]]) == p["text"]
                assert 0 <= p["frames"][0] < p["frames"][1] <= rows


def test_phrase_parts_move_more_than_the_other_parts(figures):
    print(f"\nphrases {figures['phrases']}: driven/idle ratio min {figures['phrase_ratio_idle_min']:.2f} "
          f"median {figures['phrase_ratio_idle_median']:.1f}; vs all non-phrase parts: "
          f"{100 * figures['phrase_ratio_others_pass']:.1f}% pass")
    assert figures["phrase_ratio_idle_pass"] == 1.0
    assert figures["phrase_ratio_idle_min"] > 1.5
    assert figures["phrase_driven_activity_min"] > 0.02           # driven parts really move (m/s)
    assert figures["phrase_ratio_others_median"] > 2.0


def test_mirror_swaps_left_and_right(tiny, figures):
    assert figures["mirror_annotations_consistent"] == 1.0
    found = 0
    for mid in _ids(tiny, "all"):
        if mid.startswith("M"):
            continue
        orig = (tiny / "texts" / f"{mid}.txt").read_text()
        if " left " not in orig:
            continue
        mirrored = (tiny / "texts" / f"M{mid}.txt").read_text()
        swap = {"left": "right", "right": "left", "clockwise": "counterclockwise", "counterclockwise": "clockwise"}
        assert split_words(mirrored) == [swap.get(w, w) for w in split_words(orig)]
        a_o = json.loads((tiny / "annotations" / f"{mid}.json").read_text())
        a_m = json.loads((tiny / "annotations" / f"M{mid}.json").read_text())
        for c_o, c_m in zip(a_o["captions"], a_m["captions"]):
            for p_o, p_m in zip(c_o["phrases"], c_m["phrases"]):
                assert sorted(p_m["parts"]) == sorted(PART_NAMES[PART_MIRROR[PART_NAMES.index(p)]] for p in p_o["parts"])
                assert p_m["frames"] == p_o["frames"] and p_m["words"] == p_o["words"]
        found += 1
    assert found >= 10


def test_mirror_caption_keeps_spans():
    plan = Plan((Step(Action("walk"), Action("raise", "left", ("high",))),))
    cap = render_captions(plan, np.random.default_rng(1), 1)[0]
    m = mirror_caption(cap)
    assert m.spans == cap.spans and "right" in m.words and "left" not in m.words
    assert [t for t, _ in m.tokens] == [{"left": "right"}.get(t, t) for t, _ in cap.tokens]


# ============================================================================ language
def test_figure_prompts_are_in_the_language():
    expected = [
        [("jump", None, (), "forward"), ("walk", None, (), ""), ("wave", "both", (), "arms")],
        [("jump", None, ("high",), "")],
        [("sit", None, (), "")],
        [("stretch", "both", (), "")],
        [("raise", "both", (), "")],
        [("walk", None, (), ""), ("raise", "left", ("high",), "")],
    ]
    for prompt, want in zip(FIGURE_PROMPTS, expected):
        assert in_language(prompt), prompt
        got = [(p.kind, p.side, p.mods, p.variant) for p in parse_prompt(prompt)]
        assert got == want, prompt
    parsed = parse_prompt(FIGURE_PROMPTS[5])
    assert [p.text for p in parsed] == ["walking", "raising his left hand up high"]
    # Corpus 2.0 reads "walking on a treadmill" as walking in place; these stay outside the language
    assert not in_language("a person juggles three balls")
    assert not in_language("a person rides a bicycle")
    assert not in_language("a man flies to the moon")


def test_captions_parse_back_to_their_plans():
    for i in range(150):
        rng = np.random.default_rng([2, i])
        plan = sample_plan(rng)
        acts = plan.actions()
        for cap in render_captions(plan, rng, 3):
            parsed = parse_prompt(cap.text)
            assert parsed is not None and len(parsed) == len(acts), cap.text
            order = sorted(range(len(acts)), key=lambda k: cap.spans[k][0])
            for k, ph in zip(order, parsed):
                a = acts[k][2]
                assert ph.words == cap.spans[k] and ph.kind == a.kind and ph.mods == a.mods, cap.text
                assert ph.side in (None, a.side) and ph.reps in (None, a.reps), cap.text


def test_every_caption_word_is_in_the_lexicon(tiny, figures):
    assert figures["captions_in_language"] == 1.0
    for mid in _ids(tiny, "all")[::11]:
        for line in (tiny / "texts" / f"{mid}.txt").read_text().splitlines():
            for w in split_words(parse_text_line(line).caption):
                assert w in LEXICON, w


def test_parsed_phrase_parts_follow_the_annotation_definition():
    from salad_core.data.procedural import parse_prompt

    phrases = parse_prompt("a man is walking while raising his left hand up high")
    assert [ph.parts for ph in phrases] == [("root", "left leg", "right leg"), ("left arm",)]
    (mirror,) = [ph for ph in parse_prompt("a man raises his right hand") if ph.kind == "raise"]
    assert mirror.parts == ("right arm",)
