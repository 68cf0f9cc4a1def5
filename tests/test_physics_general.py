"""The general-motion prompts of the physics benchmark (issue 69): their measures on synthetic motions with known
answers, their words (the corpus's language), their thresholds against the corpus's own clips (the single-action
clips that set them), the runner's report of the share of seeds passing and ``salad eval --physics --prompt-set``."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from _doubles import rest_pose
from salad_core.eval import physics as ph
from salad_core.eval import physics_prompts as pp
from salad_core.skeleton import get_skeleton

SK = get_skeleton("humanml3d")
J = {n: i for i, n in enumerate(SK.joint_names)}

#: Motions of the seed-0 procedural corpus (``salad corpus build --size default --seed 0 --with-general 2000`` at
#: the commit that set the thresholds) whose single-action clips set the general prompts' thresholds: for every
#: check the clip of its minimum (maximum for an upper bound) and a few others; each motion with its mirror.
#: Action-corpus motions (``<id>`` / ``M<id>``): climbing stairs, crawling, lying down, kneeling, lying down and
#: getting up.
ACTION_MOTIONS = (2273, 2205, 149, 1104, 1762, 2844, 66, 275, 86, 2573, 3668, 1236)
#: General-set motions (``G<id>`` / ``MG<id>``): lying down, kneeling, cartwheels (some to a side), a handstand,
#: forward rolls, backflips.
GENERAL_MOTIONS = (1054, 904, 451, 1326, 1529, 1058, 105, 1306, 344, 1944, 915, 1915, 1386, 986, 663, 774)


@pytest.fixture(scope="module")
def reference_corpus(tmp_path_factory):
    """Those motions of the seed-0 corpus (each generated from its own stream ``(seed, index)``, so they are the
    clips of any build of seed 0 that includes them), written in the corpus layout: all in train, two in test."""
    from salad_core.data.procedural.corpus import make_general_captioned, make_motion, write_motion

    root = tmp_path_factory.mktemp("general_reference")
    for d in ("new_joint_vecs", "new_joints", "texts", "annotations"):
        (root / d).mkdir()
    ids = []
    for make, indices in ((make_motion, ACTION_MOTIONS), (make_general_captioned, GENERAL_MOTIONS)):
        for i in indices:
            motion = make(0, i)
            write_motion(root, motion)
            ids += [k for k in motion if not k.startswith("_")]
    (root / "train.txt").write_text("\n".join(ids) + "\n")
    (root / "test.txt").write_text("\n".join(ids[:2]) + "\n")
    return root


def still(n: int = 30) -> np.ndarray:
    return np.repeat(rest_pose()[None], n, axis=0)


def about_left_axis(x: np.ndarray, deg: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Each frame of ``x`` turned by ``deg[f]`` about the +X axis (the figure's left) through ``centre``:
    positive tips the head forwards (+Z)."""
    out = np.empty_like(x)
    for f, a in enumerate(np.radians(deg)):
        r = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
        out[f] = (x[f] - centre) @ r.T + centre
    return out


# ----------------------------------------------------------------------------- measures with known answers
def test_a_full_forward_turn_is_360_degrees_head_over_heels_and_upside_down_half_the_time():
    n = 41
    x = about_left_axis(still(n), np.linspace(0.0, 360.0, n), np.array([0.0, 0.9, 0.0]))
    assert ph.pitch_rotation(x) == pytest.approx(360.0, abs=1e-6)
    assert ph.pitch_rotation(x[::-1]) == pytest.approx(-360.0, abs=1e-6)           # played backwards: a backflip
    inv = ph.inverted_frames(x)                                                  # 9 deg a frame
    assert 18 <= inv.sum() <= 21 and inv[12:28].all() and not inv[:8].any() and not inv[32:].any()
    assert pp.MEASURES["inverted_frames"][0](x, SK, None) == inv.sum()
    up, right, front = ph.trunk_axes(x[:4])
    assert front[0] == pytest.approx([0.0, 0.0, 1.0], abs=1e-9)                  # the chest faces +Z standing
    assert right[0] == pytest.approx([-1.0, 0.0, 0.0], abs=1e-9) and up[0] == pytest.approx([0.0, 1.0, 0.0])


def test_on_hands_needs_the_arms_lowest():
    x = about_left_axis(still(10), np.full(10, 180.0), np.array([0.0, 0.9, 0.0]))   # upside down, arms "up"
    assert ph.inverted_frames(x).all() and not ph.on_hands_frames(x).any()      # the head is the lowest joint
    arms = [J[n] for n in ("left_elbow", "right_elbow", "left_wrist", "right_wrist")]
    x[:, arms, 1] = x[:, :, 1].min() - 0.3                                       # the arms reach below the head
    assert ph.on_hands_frames(x).all()


def test_kneeling_on_a_named_knee():
    x = still(20)
    x[5:15, J["left_knee"], 1] = 0.05                                            # the left knee on the floor
    assert ph.kneel_frames(x, "left").sum() == 10 and ph.kneel_frames(x, "right").sum() == 0
    both = x.copy()
    both[5:15, J["right_knee"], 1] = 0.06                                        # both knees down: not one knee
    assert ph.kneel_frames(both, "left").sum() == 0
    lifted = x.copy()
    lifted[5:10, [J["right_ankle"], J["right_foot"]], 1] += 0.3                 # the other foot off the floor
    assert ph.kneel_frames(lifted, "left").sum() == 5
    assert pp.Check("kneel_frames", lo=4, side="left").evaluate(x).passed
    with pytest.raises(ValueError, match="side"):
        ph.kneel_frames(x, "both")


def test_hands_down_share():
    x = still(20)
    x[:10, [J["left_wrist"], J["right_wrist"]], 1] = 0.05
    assert ph.hands_down_frames(x).sum() == 10
    x[:5, J["left_wrist"], 1] = 0.5                                             # one hand up
    assert pp.MEASURES["hands_down_share"][0](x, SK, None) == pytest.approx(0.25)


def stairs(steps: int = 4, rise: float = 0.17, hold: int = 6, move: int = 4, air: bool = False) -> np.ndarray:
    """The figure rises ``rise`` per step; its feet stand still for ``hold`` frames at each level (stairs) or,
    with ``air``, keep moving up (a figure rising without anything to stand on)."""
    frames = []
    level = 0.0
    for k in range(steps + 1):
        frames += [level] * hold
        if k < steps:
            frames += list(level + rise * np.arange(1, move + 1) / move)
            level += rise
    h = np.asarray(frames)
    if air:
        h = np.linspace(0.0, steps * rise, len(h))
    x = still(len(h)) + h[:, None, None] * np.array([0.0, 1.0, 0.0])
    x[:, :, 2] += np.linspace(0.0, 0.3 * steps, len(h))[:, None] * (0.0 if not air else 1.0)
    return x


def test_planted_rise_of_stairs_and_of_a_figure_rising_in_the_air():
    x = stairs()
    plants = ph.foot_plants(x)
    assert {p[0] for p in plants} == {"left", "right"} and len(plants) == 10
    assert [round(p[3] - plants[0][3], 3) for p in plants[::2]] == [0.0, 0.17, 0.34, 0.51, 0.68]
    assert ph.planted_rise(x) == pytest.approx(0.68, abs=0.01)                  # toe heights differ by 1 cm
    assert 0.6 < pp.MEASURES["pelvis_rise_m"][0](x, SK, None) < 0.68            # the first and last 0.5 s
    air = stairs(air=True)                                                       # same rise, no step to stand on
    assert ph.foot_plants(air) == [] and ph.planted_rise(air) == 0.0
    assert pp.MEASURES["pelvis_rise_m"][0](air, SK, None) > 0.5                 # it rises all the same
    assert ph.planted_rise(still(10)) == pytest.approx(0.0, abs=0.01)


# ----------------------------------------------------------------------------- the prompts
def test_general_prompts_say_the_corpus_language_and_cover_the_issue():
    from salad_core.data.procedural.general_language import GENERAL_RULES, parse_general_prompt
    from salad_core.data.procedural.language import in_language
    from salad_core.data.procedural.primitives import PRIMITIVES

    texts = [p.text for p in pp.GENERAL_PROMPTS]
    assert len(set(texts)) == len(texts) and not set(texts) & {p.text for p in pp.PROMPTS}
    assert [t for t in texts if parse_general_prompt(t) is None and not in_language(t)] == []
    for p in pp.GENERAL_PROMPTS:
        assert p.group == "general" and p.corpus and p.length == 120
        for alt in p.corpus:
            for names in alt:
                assert set(names) <= set(GENERAL_RULES) | set(PRIMITIVES), (p.text, names)
        for c in p.checks:
            c.describe()
    assert set(pp.GENERAL_TARGET_ACTIONS) <= {p.action for p in pp.GENERAL_PROMPTS}
    # the core set is the 41 prompts of every record so far, unchanged
    assert pp.prompt_set("core") == pp.PROMPTS and len(pp.PROMPTS) == 41 and all(p.group == "core" for p in pp.PROMPTS)
    assert pp.prompt_set("all") == pp.PROMPTS + pp.GENERAL_PROMPTS
    with pytest.raises(ValueError, match="unknown prompt set"):
        pp.prompt_set("everything")
    with pytest.raises(ValueError, match="group"):
        pp.BenchmarkPrompt("a person waves", "wave", (pp.Check("head_ms", lo=0.0),), group="extra")


def test_corpus_single_action_clips_pass_the_general_checks(reference_corpus):
    """Every general prompt's checks hold on the corpus's single-action clips of its action (among them the clips
    whose values set the thresholds), i.e. the thresholds ask for what the training data does."""
    checked = 0
    for p in pp.GENERAL_PROMPTS:
        windows = pp.corpus_windows(reference_corpus, p)
        assert windows, p.text                              # the clips that set the thresholds are still there
        for cid, x in windows:
            for c in p.checks:
                r = c.evaluate(x)
                assert r.passed, (p.text, cid, r)
                checked += 1
    assert checked >= 100
    # the sided prompts find only their side; the mirrors of the same motions the other side
    left = {cid for cid, _ in pp.corpus_windows(reference_corpus, pp.GENERAL_PROMPTS[1])}
    assert left and all(cid.startswith("MG") for cid in left)              # 1306, 344, 1944 cartwheel right
    kneel_left = {cid for cid, _ in pp.corpus_windows(reference_corpus, pp.GENERAL_PROMPTS[7])}
    kneel_right = {cid for cid, _ in pp.corpus_windows(reference_corpus, pp.GENERAL_PROMPTS[8])}
    assert kneel_left and kneel_right and not kneel_left & kneel_right
    assert {c.lstrip("M") for c in kneel_left} == {c.lstrip("M") for c in kneel_right}
    # "phrase" mode also finds the phrases inside longer captions
    roll = pp.GENERAL_PROMPTS[3]
    n_single = len(pp.corpus_windows(reference_corpus, roll))
    assert len(pp.corpus_windows(reference_corpus, roll, mode="phrase")) >= n_single
    values = pp.corpus_check_values(reference_corpus, roll)
    assert set(values) == {"pitch_deg", "inverted_frames"} and min(v for _, v in values["pitch_deg"]) > 180
    with pytest.raises(ValueError, match="mode"):
        pp.corpus_windows(reference_corpus, roll, mode="all")
    with pytest.raises(ValueError, match="names no corpus phrases"):
        pp.corpus_windows(reference_corpus, pp.PROMPTS[0])


def _replay(root):
    """A generator that plays each general prompt's first corpus clip, whatever length is asked."""
    clips = {p.text: pp.corpus_windows(root, p)[0][1] for p in pp.GENERAL_PROMPTS}

    def gen(texts, lengths, seed):
        return [clips[t] for t in texts]
    return gen


def test_runner_reports_the_share_of_seeds_passing(reference_corpus):
    def statue(texts, lengths, seed):
        return [still(n) for n in lengths]

    res = pp.run_benchmark({"corpus": _replay(reference_corpus), "statue": statue},
                           pp.BenchSettings(steps=1, seeds=(0, 1)), prompts=pp.GENERAL_PROMPTS, real_capture=False)
    c, s = res["generators"]["corpus"], res["generators"]["statue"]
    assert [p["group"] for p in c["prompts"]] == ["general"] * len(pp.GENERAL_PROMPTS)
    assert all(p["seeds_passed"] == 2 for p in c["prompts"])                    # the corpus's own motions pass
    assert all(p["seeds_passed"] == 0 for p in s["prompts"])                    # standing still does none of it
    rows = pp.general_pass_rows(c)
    assert len(rows) == len(pp.GENERAL_PROMPTS) and all(r["passed"] and r["share"] == 1.0 for r in rows)
    issue = next(t for t in pp.targets(res) if t["target"].startswith("[general]"))
    n_issue = sum(p.action in pp.GENERAL_TARGET_ACTIONS for p in pp.GENERAL_PROMPTS)
    assert issue["cells"]["corpus"] == (f"{n_issue}/{n_issue} prompts", True)
    assert issue["cells"]["statue"] == (f"0/{n_issue} prompts", False)
    md = pp.benchmark_markdown(res)
    assert "## General-motion prompts" in md
    assert "| a person does a cartwheel * | cartwheel |" in md and "| a person does a handstand | handstand |" in md
    assert "2/2 (100 %) | 0/2 (0 %) |" in md
    assert f"corpus {2 * len(pp.GENERAL_PROMPTS)}/{2 * len(pp.GENERAL_PROMPTS)} seeds (100 %)" in md
    # a core run's report has neither the section nor the target
    core = pp.run_benchmark({"statue": statue}, pp.BenchSettings(steps=1, seeds=(0,)), prompts=pp.PROMPTS[:2],
                            real_capture=False)
    assert core["generators"]["statue"]["prompts"][0]["group"] == "core"
    assert "General-motion prompts" not in pp.benchmark_markdown(core)
    assert not any(t["target"].startswith("[general]") for t in pp.targets(core))


def test_salad_eval_physics_prompt_set_general_measures_saved_motions(reference_corpus, tmp_path, capsys):
    """``salad eval --physics --prompt-set general`` on saved joints (no generation): the general prompts, their
    section and the set recorded in the settings."""
    from salad_core.cli.eval import main

    gen = _replay(reference_corpus)
    texts = [p.text for p in pp.GENERAL_PROMPTS]
    lengths = [p.length for p in pp.GENERAL_PROMPTS]
    motions = {f"SALAD/{i:02d}/0": x.astype(np.float32) for i, x in enumerate(gen(texts, lengths, 0))}
    np.savez(tmp_path / "physics_motions.npz", **motions)
    out = tmp_path / "general"
    assert main(["--physics", "--data", str(reference_corpus), "--motions", str(tmp_path / "physics_motions.npz"),
                 "--prompt-set", "general", "--seeds", "1", "--sample", "none", "--out", str(out)]) == 0
    doc = json.loads((out / "physics.json").read_text())
    assert doc["settings"]["prompt_set"] == "general" and doc["settings"]["num_prompts"] == len(pp.GENERAL_PROMPTS)
    assert [p["text"] for p in doc["generators"]["SALAD"]["prompts"]] == texts
    assert all(p["seeds_passed"] == 1 for p in doc["generators"]["SALAD"]["prompts"])
    assert "## General-motion prompts" in (out / "physics.md").read_text()
    capsys.readouterr()
    assert main(["--data", str(reference_corpus), "--prompt-set", "general"]) == 2        # not the T2M protocol
    assert "--prompt-set is for --physics" in capsys.readouterr().err
