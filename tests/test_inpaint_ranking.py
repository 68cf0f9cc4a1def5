"""In-painting from the best of K fresh-noise seeds (``Inpaint(candidates=K)``): the scoring window, the prompt's
evaluator tokens, the shipped evaluator's text-motion distance on corpus clips, and the ranked edit (shipped
weights, few steps, one thread)."""
from __future__ import annotations

import dataclasses
import io
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from salad_core.attention import Inpaint
from salad_core.attention import ranking
from salad_core.attention.edits import seeded_noise
from salad_core.attention.composite import seam_jerk_ratio
from salad_core.attention.inpaint import SCORE_MODES, SEAM_BOUND, SPAN_CANDIDATES
from salad_core.attention.ranking import (MIN_FRAMES, TextMotionScorer, candidate_seam_ratios, candidate_specs,
                                          caption_tokens, isolate_parts, pick_candidate, ranked_edit, scoring_window)
from salad_core.eval.train_evaluator import default_evaluator_dir
from salad_core.pipeline import EditOutput, MotionOutput
from _weights import needs_weights

STEPS = 10
FRAMES = 48
SOURCE = "a person walks forward"
WAVE = "a man waves his right hand"

needs_evaluator = pytest.mark.skipif(not (default_evaluator_dir() / "evaluator.json").is_file(),
                                     reason="needs the shipped evaluator (salad_core/weights/evaluator)")


# ------------------------------------------------------------------------------ the spec and the window
@pytest.mark.parametrize("k", [0, -2, True, 2.0, "4"])
def test_bad_candidates_are_refused(k):
    with pytest.raises(ValueError, match=r"Inpaint.candidates=.* must be an int >= 1"):
        Inpaint(parts="arms", candidates=k)


def test_auto_candidates_rank_a_span_of_one_inverted_motion_only():
    span = Inpaint(frames=(8, 24))
    assert span.candidates == "auto" and span.candidates_for(True) == SPAN_CANDIDATES == 8
    assert span.candidates_for(False) == 1                              # a generated source: its own noise
    assert span.candidates_for(True, motions=2) == 1                    # a batch: one edit each
    assert Inpaint(frames=(8, 24), noise="source").candidates_for(True) == 1
    assert Inpaint(frames=(8, 24), noise="fresh").candidates_for(False) == 1   # not where it was chosen
    assert Inpaint(parts="arms").candidates_for(True) == 1              # body parts alone
    assert Inpaint(parts="arms", candidates=3).candidates_for(False) == 3
    assert Inpaint(frames=(8, 24), candidates=1).candidates_for(True) == 1
    assert ranking.ranked_inpaint([Inpaint(parts="arms")], True) is None
    assert ranking.ranked_inpaint([span], True) is span and ranking.ranked_inpaint([span], False) is None
    assert ranking.ranked_inpaint([span], True, motions=2) is None


def test_candidate_specs_count_the_seeds_up_and_keep_the_other_edits():
    from salad_core.attention import Reweight

    rw = Reweight("waves", 2.0)
    spec = Inpaint(frames=(8, 24), seed=5, candidates=3, guidance=6.0)
    specs = candidate_specs([rw, spec], spec, 3)
    assert [s[1].seed for s in specs] == [5, 6, 7]
    assert all(s[0] is rw and s[1].candidates == 1 and s[1].guidance == 6.0 for s in specs)
    assert specs[0][1] == dataclasses.replace(spec, candidates=1)


def test_scoring_window_grows_a_short_span_with_context_to_the_minimum():
    assert scoring_window(120, None) == (0, 120)                      # body parts alone: every frame
    assert scoring_window(120, (40, 80)) == (40, 80)                  # long enough already
    assert scoring_window(120, (40, 60)) == (28, 68)                  # 20 frames: 3 units before, 2 after
    assert scoring_window(120, (0, 16)) == (0, 40)                    # a prefix grows to the right only
    assert scoring_window(120, (104, 120)) == (80, 120)               # a suffix to the left only
    assert scoring_window(32, (8, 16)) == (0, 32)                     # a short motion is scored whole
    for span in [(40, 60), (0, 16), (104, 120), (52, 56)]:
        a, b = scoring_window(120, span)
        assert a <= span[0] and span[1] <= b and b - a == MIN_FRAMES and a % 4 == 0
    with pytest.raises(ValueError, match="does not lie inside the motion of 48 frames"):
        scoring_window(48, (40, 60))


# ------------------------------------------------------------------------------ the evaluator's text side
def test_caption_tokens_tag_a_free_prompt_as_the_corpus_does():
    assert caption_tokens("A man waves his right hand.") == ["a/DET", "man/NOUN", "wave/VERB", "his/DET",
                                                             "right/ADJ", "hand/NOUN"]
    assert caption_tokens("someone punches forward")[1] == "punch/VERB"        # listed as a noun, read as a verb
    assert caption_tokens("someone does two punches")[-1] == "punch/NOUN"      # after a number: the noun
    assert caption_tokens("a person zorbs")[-1] == "zorbs/OTHER"               # unknown: the evaluator's unk
    with pytest.raises(ValueError, match="has no word"):
        caption_tokens("?!")


def _corpus_clips(n: int, seed: int = 777):
    """``n`` clips of a procedural corpus of another seed than the evaluator's (features ``(N, 263)``, their
    captions and the corpus's ``word/POS`` tokens of each)."""
    from salad_core.data.procedural.corpus import make_motion

    clips = []
    for i in range(n):
        files = make_motion(seed, i)[f"{i:06d}"]
        lines = [line.split("#") for line in files["texts"].strip().splitlines()]
        clips.append((np.load(io.BytesIO(files["new_joint_vecs"])), [l[0] for l in lines],
                      [l[1].split() for l in lines]))
    return clips


@needs_evaluator
def test_caption_tokens_give_the_evaluator_the_corpus_captions_input():
    """What the evaluator reads of a token (its word row and POS one-hot) agrees with the corpus's own tokens for most
    corpus captions (89 % of 658 captions in a probe; the rest differ in a tag the one-hot keeps)."""
    vec = TextMotionScorer().evaluator.vectorizer

    def read(tokens):
        return [(t.rpartition("/")[0] if t.rpartition("/")[0] in vec else "unk", vec.lookup(t)[1]) for t in tokens]

    pairs = [(cap, toks) for _, caps, tokens in _corpus_clips(12) for cap, toks in zip(caps, tokens)]
    same = [read(caption_tokens(cap)) == read(toks) for cap, toks in pairs]
    assert len(pairs) > 30 and np.mean(same) >= 0.8


@needs_evaluator
def test_the_scorer_puts_a_clips_own_caption_closer_than_other_clips_captions():
    clips = _corpus_clips(6)
    scorer = TextMotionScorer()
    for i, (feats, caps, _) in enumerate(clips):
        own = scorer.distance(feats, caps[0])
        others = [scorer.distance(feats, c[1][0]) for j, c in enumerate(clips) if j != i]
        assert own < np.median(others), (caps[0], own, others)


@needs_evaluator
def test_the_scorer_reads_only_the_window_and_refuses_bad_features():
    feats, caps, _ = _corpus_clips(1)[0]
    scorer = TextMotionScorer()
    n = len(feats) - len(feats) % 4
    a, b = scorer.window(n, (48, 56))
    changed = feats.copy()
    changed[:a] += 1.0                                                 # outside the window: no effect
    changed[b:] -= 1.0
    assert scorer.distance(changed[:n], caps[0], (48, 56)) == scorer.distance(feats[:n], caps[0], (48, 56))
    changed[a:b] += 0.5
    assert scorer.distance(changed[:n], caps[0], (48, 56)) != scorer.distance(feats[:n], caps[0], (48, 56))
    with pytest.raises(ValueError, match=r"must be \(N, 263\)"):
        scorer.distance(feats[:, :100], caps[0])
    with pytest.raises(ValueError, match="too short to score"):
        scorer.distance(feats[:3], caps[0])


# ------------------------------------------------------------------------------ ranking, without weights
def _fake_output(value: float, n: int = 40) -> EditOutput:
    feats = np.full((1, n, 263), value, dtype=np.float32)
    motion = MotionOutput(feats, [np.zeros((n, 22, 3))], [WAVE], [n], torch.zeros(1, n // 4, 7, 4),
                          torch.zeros(1, n // 4, 7, 4), [0])
    return EditOutput(motion, dataclasses.replace(motion), motion.noise, (), {})


class _StubScorer:
    """Distance = |mean feature - 2|: the candidate whose features are 2 wins."""

    evaluator = SimpleNamespace(config=SimpleNamespace(dim_pose=263))
    source = "stub"

    def window(self, n, span):
        return scoring_window(n, span)

    def distance(self, features, text, span=None):
        return abs(float(np.mean(features)) - 2.0)


def test_ranked_edit_keeps_the_candidate_the_scorer_prefers_and_records_every_score():
    spec = Inpaint(parts="arms", seed=10, candidates=4)
    seen = []

    def run(specs):
        seen.append(specs[0].seed)
        return _fake_output(specs[0].seed - 10.0)                      # seeds 10..13 -> features 0..3

    out = ranked_edit(run, [spec], inverted=True, skeleton="humanml3d", scorer=_StubScorer())
    assert seen == [10, 11, 12, 13]
    assert out.edited.features.mean() == 2.0 and out.edits[0].seed == 12 and out.edits[0].candidates == 1
    rec = out.settings["inpaint_candidates"]
    assert rec == out.edited.settings["inpaint_candidates"]
    assert rec["seeds"] == [10, 11, 12, 13] and rec["chosen"] == 2 and rec["seed"] == 12
    assert rec["distances"] == [2.0, 1.0, 0.0, 1.0] and rec["frames"] == [0, 40] and rec["score"] == "whole"


def test_ranked_edit_refusals():
    with pytest.raises(ValueError, match="candidates would be alike; give noise='fresh'"):
        ranked_edit(lambda s: None, [Inpaint(parts="arms", candidates=2)], inverted=False, skeleton="humanml3d",
                    scorer=_StubScorer())
    with pytest.raises(ValueError, match="ranks the candidates of one motion; the edit has 3"):
        ranked_edit(lambda s: None, [Inpaint(parts="arms", candidates=2)], inverted=True, motions=3,
                    skeleton="humanml3d", scorer=_StubScorer())
    with pytest.raises(ValueError, match="reads 263-d features"):
        ranked_edit(lambda s: None, [Inpaint(parts="arms", candidates=2)], inverted=True, skeleton="kit",
                    scorer=_StubScorer())
    two = _fake_output(0.0)
    two = dataclasses.replace(two, edited=dataclasses.replace(two.edited, texts=[WAVE, WAVE]))
    with pytest.raises(ValueError, match="ranks the candidates of one motion; the edit has 2"):
        ranked_edit(lambda s: two, [Inpaint(parts="arms", candidates=2)], inverted=True, skeleton="humanml3d",
                    scorer=_StubScorer())
    with pytest.raises(ValueError, match="needs an Inpaint with candidates > 1"):
        ranked_edit(lambda s: None, [Inpaint(parts="arms")], inverted=True, skeleton="humanml3d")


# ------------------------------------------------------------------------------ scoring the regenerated parts alone
@pytest.mark.parametrize("score", ["best", "PARTS", 1, None])
def test_bad_score_modes_are_refused(score):
    with pytest.raises(ValueError, match=r"Inpaint.score=.*; allowed: \('auto', 'whole', 'parts', 'prior', 'first_smooth'\)"):
        Inpaint(parts="arms", score=score)


def test_parts_scoring_needs_kept_parts_and_auto_scores_the_whole_motion():
    with pytest.raises(ValueError, match="regenerates every part; name the parts"):
        Inpaint(frames=(8, 24), score="parts")
    with pytest.raises(ValueError, match="regenerates every part; name the parts"):
        Inpaint(parts="all", frames=(8, 24), score="parts")
    assert Inpaint(parts="arms", score="parts").score_for(True) == "parts"
    assert Inpaint(parts="legs", frames=(8, 24), score="parts").score_for(False) == "parts"
    assert Inpaint(parts="arms", score="whole").score_for(True) == "whole"
    assert Inpaint(parts="arms").score_for(True) == Inpaint(parts="arms").score_for(False) == "whole"
    for spec in (Inpaint(frames=(8, 24)), Inpaint(parts="arms", frames=(8, 24))):
        # a span of an inverted take: by the pasted prior's heights; a generated source's span: the evaluator
        assert spec.score == "auto" and spec.score_for(True) == "prior" and spec.score_for(False) == "whole"
        assert dataclasses.replace(spec, prior="none").score_for(True) == "whole"
    # the candidates of a ranked edit keep the scoring mode
    spec = Inpaint(parts="arms", candidates=2, score="parts")
    assert [s[0].score for s in candidate_specs([spec], spec, 2)] == ["parts", "parts"]


def _part_columns(sk, parts):
    """Feature columns ``(D,)`` bool of the joints drawn in ``parts``."""
    from salad_core.attention.composite import part_joint_weights

    cols = np.zeros(sk.feature_dim, bool)
    for j in np.flatnonzero(part_joint_weights(parts, sk)):
        cols[list(sk.joint_feature_index[j])] = True
    return cols


def test_isolate_parts_keeps_the_regenerated_joints_and_holds_the_rest_still(sample_features):
    from salad_core.recovery import recover_joints
    from salad_core.skeleton import get_skeleton

    sk = get_skeleton("humanml3d")
    fs = sk.feature_slices
    f = sample_features.astype(np.float32)
    iso = isolate_parts(f, "arms")
    assert iso.shape == f.shape and iso.dtype == f.dtype
    arms = _part_columns(sk, ("left arm", "right arm"))
    assert arms.sum() == 8 * 12                                         # 2 x (collar, shoulder, elbow, wrist)
    np.testing.assert_array_equal(iso[:, arms], f[:, arms])            # the regenerated joints exactly
    kept = ~arms
    np.testing.assert_array_equal(iso[:, kept], np.broadcast_to(iso[:1, kept], iso[:, kept].shape))  # constant
    pose = np.zeros(sk.feature_dim, bool)
    for name in ("root_y", "ric", "rot"):
        pose[fs[name]] = True
    np.testing.assert_allclose(iso[0, kept & pose], np.median(f[:, kept & pose], axis=0))      # the median pose
    assert (iso[:, fs["root_rot_vel"]] == 0).all() and (iso[:, fs["root_lin_vel"]] == 0).all()
    vel = np.zeros(sk.feature_dim, bool)
    vel[fs["local_vel"]] = True
    assert (iso[:, kept & vel] == 0).all() and (iso[:, fs["contacts"]] == 1).all()
    # recovered: the kept joints stand still in the world, the arms still move
    joints = recover_joints(iso, "positions", sk)
    arm_joints = [j for j in range(sk.num_joints) if sk.part_names[sk.joint_to_part[j]] in ("left arm", "right arm")]
    still = [j for j in range(sk.num_joints) if j not in arm_joints]
    assert np.ptp(joints[:, still], axis=0).max() < 1e-5
    wrists = [sk.joint_names.index("left_wrist"), sk.joint_names.index("right_wrist")]
    assert np.ptp(joints[:, wrists], axis=0).max() > 0.1                # metres


def test_isolate_parts_of_a_leg_keeps_its_contacts_and_of_the_lower_body_its_root(sample_features):
    from salad_core.skeleton import get_skeleton

    sk = get_skeleton("humanml3d")
    fs = sk.feature_slices
    f = sample_features
    con = f[:, fs["contacts"]]
    assert 0 < con.mean() < 1                                           # the take steps: contacts change
    left = isolate_parts(f, "left_leg")[:, fs["contacts"]]             # left ankle, left toe, right ankle, right toe
    np.testing.assert_array_equal(left[:, :2], con[:, :2])
    assert (left[:, 2:] == 1).all()
    lower = isolate_parts(f, "lower")                                   # root and legs move
    np.testing.assert_array_equal(lower[:, fs["root"]], f[:, fs["root"]])
    np.testing.assert_array_equal(lower[:, _part_columns(sk, ("root", "left leg", "right leg"))],
                                  f[:, _part_columns(sk, ("root", "left leg", "right leg"))])
    arms = _part_columns(sk, ("left arm", "right arm"))
    assert np.ptp(lower[:, arms], axis=0).max() == 0


def test_isolate_parts_refusals(sample_features):
    with pytest.raises(ValueError, match=r"must be \(N, 263\) de-normalised humanml3d features"):
        isolate_parts(sample_features[:, :100], "arms")
    with pytest.raises(ValueError, match=r"got shape \(0, 263\)"):
        isolate_parts(sample_features[:0], "arms")
    with pytest.raises(ValueError, match="unknown body part 'wings'"):
        isolate_parts(sample_features, "wings")


class _SpeedScorer:
    """Distance = |speed - 1|, speed = the mean over frames of the summed absolute velocity columns (root turn and
    step, joints' local velocities): a prompt that asks for one unit of motion."""

    evaluator = SimpleNamespace(config=SimpleNamespace(dim_pose=263))
    source = "speed"

    def window(self, n, span):
        return scoring_window(n, span)

    def distance(self, features, text, span=None):
        from salad_core.skeleton import get_skeleton

        fs = get_skeleton("humanml3d").feature_slices
        vel = np.concatenate([features[:, fs["root_rot_vel"]], features[:, fs["root_lin_vel"]],
                              features[:, fs["local_vel"]]], axis=1)
        return abs(float(np.abs(vel).sum(1).mean()) - 1.0)


@pytest.mark.parametrize("score, chosen", [("whole", 1), ("auto", 1), ("parts", 0)])
def test_the_scoring_mode_changes_the_chosen_candidate(score, chosen):
    """Two candidates of an arms edit share the kept body, which walks forward at one unit of speed; candidate 0's
    right wrist moves at one unit, candidate 1's arms are still. Scored whole, the walk alone already gives the
    motion the prompt asks for and the still arms win; scored on the arms alone, the moving arm wins."""
    from salad_core.skeleton import get_skeleton

    sk = get_skeleton("humanml3d")
    wrist = sk.feature_slices["local_vel"].start + 3 * sk.joint_names.index("right_wrist")

    def run(specs):
        f = np.zeros((40, 263), np.float32)
        f[:, 2] = 1.0                                                   # the kept root's forward step
        f[:, wrist] = 1.0 if specs[0].seed == 0 else 0.0
        out = _fake_output(0.0)
        return dataclasses.replace(out, edited=dataclasses.replace(out.edited, features=f[None]))

    spec = Inpaint(parts="arms", candidates=2, score=score)
    out = ranked_edit(run, [spec], inverted=True, skeleton="humanml3d", scorer=_SpeedScorer())
    rec = out.settings["inpaint_candidates"]
    assert rec["chosen"] == chosen and out.edits[0].seed == chosen
    assert rec["score"] == ("parts" if score == "parts" else "whole")
    assert rec["distances"] == ([0.0, 1.0] if score == "parts" else [1.0, 0.0])
    assert out.edited.features[0, 0, wrist] == (1.0 if chosen == 0 else 0.0)


@needs_evaluator
def test_isolated_arms_of_a_walk_no_longer_read_as_the_walk(sample_features):
    """The HumanML3D sample walks and turns: with everything but the arms held still, its embedding moves away from
    its own caption and towards arm prompts (what the whole motion's embedding cannot see)."""
    scorer = TextMotionScorer()
    iso = isolate_parts(sample_features, "arms")
    own = "a person walks forward and turns around"
    assert scorer.distance(iso, own) > scorer.distance(sample_features, own)
    for arm_prompt in (WAVE, "a person raises both arms"):
        assert scorer.distance(iso, arm_prompt) < scorer.distance(sample_features, arm_prompt)


@pytest.mark.parametrize("command", [["edit", SOURCE], ["invert", "take.npy", "--prompt", SOURCE]])
def test_inpaint_score_flag_reaches_the_spec(command):
    from salad_core import cli
    from salad_core.cli._common import UserError
    from salad_core.cli.generate import INPAINT_SCORE, _edit_specs

    assert INPAINT_SCORE == SCORE_MODES
    flags = ["--target", WAVE, "--inpaint", "arms", "--out", "x"]
    assert _edit_specs(cli.build_parser().parse_args(command + flags + ["--inpaint-score", "parts"]))[0].score == "parts"
    assert _edit_specs(cli.build_parser().parse_args(command + flags))[0].score == "auto"
    span = ["--target", "a person jumps", "--inpaint", "@12:28", "--inpaint-score", "parts", "--out", "x"]
    with pytest.raises(UserError, match="--inpaint @12:28: Inpaint\\(score='parts'\\)"):
        _edit_specs(cli.build_parser().parse_args(command + span))


# ------------------------------------------------------------------------------ seam-aware ranking of a span
#: The source of the seam tests: joint 0 moves along x as c t^3 / 6 (third difference c per frame^3 at every frame),
#: joint 1 stands still; jerk mean over joints c / 2 at every frame, so its 95th percentile is c / 2 too.
_C = 1e-3


def _smooth_source(n: int = 60) -> np.ndarray:
    t = np.arange(n, dtype=np.float64)
    joints = np.zeros((n, 2, 3))
    joints[:, 0, 0] = _C * t ** 3 / 6
    return joints


def _stepped(source: np.ndarray, at: int, height: float) -> np.ndarray:
    """``source`` with both joints lifted by ``height`` (along y) from frame ``at`` on: a jump in jerk there."""
    out = source.copy()
    out[at:, :, 1] += height
    return out


def test_seam_jerk_ratio_of_a_known_step_next_to_the_seam():
    src = _smooth_source()
    h = 0.01
    # a step of h at frame 20: the third differences that end on it hold h, -2h, h; the largest is |-2h| (per joint,
    # joint 0 adds its own c along x)
    expected = (np.hypot(_C, 2 * h) + 2 * h) / 2 / (_C / 2)
    assert seam_jerk_ratio(src, _stepped(src, 20, h), [20]) == pytest.approx(expected, rel=1e-9)
    assert seam_jerk_ratio(src, _stepped(src, 20, h), [20, 40]) == pytest.approx(expected, rel=1e-9)
    assert seam_jerk_ratio(src, src, [20]) == pytest.approx(1.0, rel=1e-9)       # the source's own jerk: 1x
    # a step 6 frames after the seam is no longer within 4 frames of it: the seam sees the source's jerk
    assert seam_jerk_ratio(src, _stepped(src, 26, h), [20]) == pytest.approx(1.0, rel=1e-9)
    assert seam_jerk_ratio(src, _stepped(src, 20, h), []) == 0.0                 # no seam
    # the reference is the source's percentile: a source twice as jerky halves the ratio
    assert seam_jerk_ratio(2 * src, _stepped(src, 20, h), [20]) == pytest.approx(expected / 2, rel=1e-9)


def test_seam_jerk_ratio_refusals():
    src = _smooth_source()
    with pytest.raises(ValueError, match=r"source must be joint positions \(N, J, 3\), got shape \(60, 6\)"):
        seam_jerk_ratio(src.reshape(60, 6), src, [20])
    with pytest.raises(ValueError, match=r"edited must be joint positions"):
        seam_jerk_ratio(src, src[..., :2], [20])
    with pytest.raises(ValueError, match="the source has 3 frames"):
        seam_jerk_ratio(src[:3], src, [20])
    with pytest.raises(ValueError, match="percentile=120"):
        seam_jerk_ratio(src, src, [20], percentile=120)


def test_pick_candidate_keeps_the_closest_smooth_candidate_and_falls_back_to_the_smoothest():
    dist = [3.0, 1.0, 2.0, 0.5]
    assert pick_candidate(dist) == 3                                             # no bound: the closest
    assert pick_candidate(dist, [1.2, 2.0, 1.4, 3.0], None) == 3
    assert pick_candidate(dist, [1.2, 2.0, 1.4, 3.0], 1.5) == 2                  # closest of the smooth 0 and 2
    assert pick_candidate(dist, [1.2, 2.0, 1.5, 3.0], 1.5) == 2                  # the bound itself is within
    assert pick_candidate(dist, [1.2, 2.0, 1.6, 3.0], 1.5) == 0
    assert pick_candidate(dist, [2.0, 1.8, 3.0, 1.6], 1.5) == 3                  # none within: the smoothest
    assert pick_candidate(dist, [2.0, 1.6, 3.0, 1.6], 1.5) == 1                  # ... the first of equal ones
    with pytest.raises(ValueError, match="3 seam ratios for 4 candidates"):
        pick_candidate(dist, [1.0, 1.0, 1.0], 1.5)
    with pytest.raises(ValueError, match="one distance per candidate"):
        pick_candidate([], [], 1.5)


@pytest.mark.parametrize("bound", [0, -1.5, True, "1.5", float("nan"), float("inf")])
def test_bad_seam_bounds_are_refused(bound):
    with pytest.raises(ValueError, match=r"Inpaint.seam_bound=.* must be a finite number > 0"):
        Inpaint(frames=(8, 24), seam_bound=bound)


def test_seam_bound_resolves_for_spans_only():
    span = Inpaint(frames=(8, 24))
    assert span.seam_bound == "auto" and span.seam_bound_for(True) == SEAM_BOUND == 1.5   # a take's span
    assert span.seam_bound_for(False) is None                          # a generated source: not where it was chosen
    assert Inpaint(frames=(8, 24), seam_bound=2).seam_bound_for(False) == 2.0
    assert isinstance(Inpaint(frames=(8, 24), seam_bound=2).seam_bound, float)
    assert Inpaint(frames=(8, 24), seam_bound=None).seam_bound_for(True) is None
    for bound in ("auto", 1.5, None):                                   # body parts have no seam
        parts = Inpaint(parts="arms", seam_bound=bound)
        assert parts.seam_bound_for(True) is None and parts.seam_bound_for(False) is None
    spec = Inpaint(frames=(20, 40), candidates=2, seam_bound=1.5)               # the candidates keep the bound
    assert [s[0].seam_bound for s in candidate_specs([spec], spec, 2)] == [1.5, 1.5]


def _span_output(value: float, step: float, n: int = 60) -> EditOutput:
    """One motion of ``n`` frames: features all ``value`` (the stub scorer's distance is ``|value - 2|``), the source's
    joints :func:`_smooth_source`, the edit's the same with a step of ``step`` at frame 20."""
    src_j = _smooth_source(n)
    feats = np.full((1, n, 263), value, dtype=np.float32)
    z = torch.zeros(1, n // 4, 7, 4)
    source = MotionOutput(feats, [src_j], [WAVE], [n], z, z, [0])
    edited = MotionOutput(feats, [_stepped(src_j, 20, step)], [WAVE], [n], z, z, [0])
    return EditOutput(source, edited, z, (), {})


#: Candidates of the seam tests, by seed: (features -> distance |value - 2|, seam step). Seed 0 is the closest with a
#: sharp seam, seed 1 the closest of the smooth ones, seed 2 smooth but farther, seed 3 the smoothest.
_CANDIDATES = {0: (2.0, 0.01), 1: (2.5, 0.0002), 2: (3.0, 0.0001), 3: (0.0, 0.0)}


def _run_candidates(table):
    seen = []

    def run(specs):
        seen.append(specs[0].seed)
        return _span_output(*table[specs[0].seed])

    return run, seen


def _ratio(step: float) -> float:
    src = _smooth_source()
    return seam_jerk_ratio(src, _stepped(src, 20, step), [20, 40])


@pytest.mark.parametrize("bound, chosen", [(1.5, 1), (None, 0), ("auto", 1), (1e-9, 3)])
def test_ranked_edit_of_a_span_keeps_the_closest_smooth_candidate_and_records_the_seams(bound, chosen):
    ratios = [_ratio(step) for _, step in _CANDIDATES.values()]
    assert ratios[0] > 1.5 >= ratios[1] > ratios[2] > ratios[3] == pytest.approx(1.0)  # what the table means
    spec = Inpaint(frames=(20, 40), candidates=4, seam_bound=bound, prior="none")     # ranked by the evaluator
    run, seen = _run_candidates(_CANDIDATES)
    out = ranked_edit(run, [spec], inverted=True, skeleton="humanml3d", scorer=_StubScorer())
    rec = out.settings["inpaint_candidates"]
    assert seen == [0, 1, 2, 3] and rec["distances"] == [0.0, 0.5, 1.0, 2.0]
    np.testing.assert_allclose(rec["seam_ratios"], ratios, rtol=1e-12)
    assert rec["seam_bound"] == {"auto": SEAM_BOUND, None: None}.get(bound, bound)
    assert rec["chosen"] == chosen and out.edits[0].seed == chosen
    np.testing.assert_array_equal(out.edited.joints[0], _span_output(*_CANDIDATES[chosen]).edited.joints[0])


# ------------------------------------------------------------------------------ ranking by the pasted prior's heights
def _prior_output(pelvis_off: float, step: float, n: int = 60, prior: str = "prompt") -> EditOutput:
    """One motion of ``n`` frames (22 joints, the pelvis 0.9 m above feet on the floor) whose span [20, 40) was
    pasted from a 40-frame prior (windows: latent frames 5..10 <- the prior's 0..5); the edit has a seam step of
    ``step`` at frame 20, and the prior's pasted frames are the edit's heights with its pelvis ``pelvis_off`` lower."""
    t = np.arange(n, dtype=np.float64)
    src = np.zeros((n, 22, 3))
    src[:, :, 0] = _C * t[:, None] ** 3 / 6
    src[:, 0, 1] = 0.9
    ed = _stepped(src, 20, step)
    pri = ed[20:60].copy()
    pri[20:, :, 1] -= step                                 # its frames not pasted stand on 0: its floor is the edit's
    pri[:20, 0, 1] -= pelvis_off
    z = torch.zeros(1, n // 4, 7, 4)
    feats = np.zeros((1, n, 263), dtype=np.float32)
    source = MotionOutput(feats, [src], [WAVE], [n], z, z, [0])
    edited = MotionOutput(feats, [ed], [WAVE], [n], z, z, [0])
    if prior == "none":
        return EditOutput(source, edited, z, (), {})
    alone = MotionOutput(np.zeros((1, 40, 263), np.float32), [pri], [WAVE], [40], z[:, :10], z[:, :10], [0])
    return EditOutput(source, edited, z, (), {"inpaint_prior": {"windows": [[5, 10, 40, 0]]}}, prior=alone)


def test_prior_height_distance_reads_the_pelvis_and_feet_heights_over_the_pasted_frames():
    spec = Inpaint(frames=(20, 40), prior="prompt")
    assert ranking.prior_height_cm(_prior_output(0.0, 0.01), spec) == pytest.approx(0.0, abs=1e-9)
    # the prior's pelvis 10 cm lower on every pasted frame: 10 cm on 1 of the 5 joints read
    assert ranking.prior_height_cm(_prior_output(0.10, 0.0), spec) == pytest.approx(2.0)
    with pytest.raises(ValueError, match="pasted no prior"):
        ranking.prior_height_cm(_prior_output(0.0, 0.0, prior="none"), spec)
    with pytest.raises(ValueError, match="score='prior'.*prior='none' pastes none"):
        Inpaint(frames=(20, 40), prior="none", score="prior")
    assert Inpaint(frames=(20, 40), score="prior").score_for(True) == "prior"


def test_height_distance_reads_a_pelvis_that_no_longer_rises_and_ignores_a_bodily_lift():
    joints = (0, 7, 10, 8, 11)                      # pelvis, left ankle / toe, right ankle / toe (humanml3d)
    rng = np.random.default_rng(1)
    prior = rng.normal(size=(40, 22, 3))
    prior[:, 1:, 1] = np.abs(prior[:, 1:, 1])       # feet at or above 0: the prior's floor is its lowest foot joint
    edited = rng.normal(size=(120, 22, 3))
    edited[:, list(joints[1:]), 1] = 0.3            # outside the span the feet stand at 0.3 m: the floor
    edited[40:56] = prior[8:24] + np.array([0.0, 0.3 - prior[:, list(joints[1:]), 1].min(), 0.0])
    # the same heights above each motion's own floor: 0, whatever the horizontal or vertical offset
    assert ranking.height_distance_cm(edited, prior, (40, 56), 8) == pytest.approx(0.0, abs=1e-9)
    # the pelvis 20 cm lower on every span frame (a flattened jump): 20 cm on 1 of the 5 joints
    edited[40:56, 0, 1] -= 0.20
    assert ranking.height_distance_cm(edited, prior, (40, 56), 8) == pytest.approx(4.0)
    # the root-relative pose distance would see the lowered pelvis as every other joint moved up instead
    rel = (edited[40:56] - edited[40:56, :1]) - (prior[8:24] - prior[8:24, :1])
    assert np.linalg.norm(rel, axis=-1).mean() * 100 > 10
    with pytest.raises(ValueError, match="one length"):
        ranking.height_distance_cm(edited, prior, (40, 80), 8)      # 40 span frames, 32 prior frames left


#: seed -> (the prior's pelvis offset: distance offset * 100 / 5 cm, seam step): seed 0 follows the prior exactly
#: with a sharp seam, seed 1 is the closest smooth one, seed 3 the smoothest.
_PRIOR_CANDIDATES = {0: (0.0, 0.01), 1: (0.10, 0.0002), 2: (0.30, 0.0001), 3: (0.5, 0.0)}


@pytest.mark.parametrize("bound", [1.5, 1e-9])
def test_ranked_edit_by_the_prior_keeps_the_closest_smooth_candidate_or_falls_back_without_the_prior(bound):
    spec = Inpaint(frames=(20, 40), candidates=4, prior="prompt", prior_strength=0.7, score="prior", seam_bound=bound)
    seen = []

    def run(specs):
        seen.append((specs[0].seed, specs[0].prior, specs[0].score))
        off, step = _PRIOR_CANDIDATES[specs[0].seed]
        if specs[0].prior == "none":                   # the fallback's candidates: ranked by the (stub) evaluator
            return _span_output(*_CANDIDATES[specs[0].seed])
        return _prior_output(off, step)

    out = ranked_edit(run, [spec], inverted=True, skeleton="humanml3d", scorer=_StubScorer())
    rec = out.settings["inpaint_candidates"]
    assert rec["score"] == "prior" and rec["evaluator"] is None
    np.testing.assert_allclose(rec["distances"], [0.0, 2.0, 6.0, 10.0], atol=1e-9)
    assert rec["frames"] == [20, 40]
    if bound == 1.5:
        assert seen == [(s, "prompt", "prior") for s in range(4)] and "fallback" not in rec
        assert rec["chosen"] == 1 and out.edits[0].seed == 1 and out.edits[0].prior == "prompt"
    else:       # no candidate within the bound: the four again without the prior, by the evaluator (the smoothest)
        assert seen == [(s, "prompt", "prior") for s in range(4)] + [(s, "none", "whole") for s in range(4)]
        fb = rec["fallback"]
        assert fb["distances"] == [0.0, 0.5, 1.0, 2.0] and fb["evaluator"] == "stub" and fb["chosen"] == 3
        assert rec["seed"] == 3 and out.edits[0].seed == 3 and out.edits[0].prior == "none"
        np.testing.assert_array_equal(out.edited.joints[0], _span_output(*_CANDIDATES[3]).edited.joints[0])


def test_a_seam_bound_does_not_change_a_body_part_ranking():
    """Body parts have no seam: the same candidates (whose joints would give the span's seam ratios) rank the same
    with any bound, and no seam ratio is recorded."""
    outs = {}
    for bound in (None, "auto", 1.5, 1e-9):
        run, _ = _run_candidates(_CANDIDATES)
        out = ranked_edit(run, [Inpaint(parts="arms", candidates=4, seam_bound=bound)], inverted=True,
                          skeleton="humanml3d", scorer=_StubScorer())
        rec = out.settings["inpaint_candidates"]
        assert rec["seam_ratios"] is None and rec["seam_bound"] is None
        outs[bound] = rec["chosen"]
    assert outs == {None: 0, "auto": 0, 1.5: 0, 1e-9: 0}
    assert candidate_seam_ratios([_span_output(2.0, 0.01)], Inpaint(parts="arms")) is None


@pytest.mark.parametrize("command", [["edit", SOURCE], ["invert", "take.npy", "--prompt", SOURCE]])
def test_inpaint_seam_bound_flag_reaches_the_spec(command):
    from salad_core import cli
    from salad_core.cli._common import UserError
    from salad_core.cli.generate import _edit_specs

    flags = ["--target", "a person jumps", "--inpaint", "@12:28", "--out", "x"]

    def spec(*extra):
        return _edit_specs(cli.build_parser().parse_args(command + flags + list(extra)))[0]

    assert spec().seam_bound == "auto"
    assert spec("--inpaint-seam-bound", "1.5").seam_bound == 1.5
    assert spec("--inpaint-seam-bound", "off").seam_bound is None
    assert spec("--inpaint-seam-bound", "auto").seam_bound == "auto"
    with pytest.raises(UserError, match="--inpaint-seam-bound lots: give a number"):
        spec("--inpaint-seam-bound", "lots")
    with pytest.raises(UserError, match=r"--inpaint @12:28: Inpaint.seam_bound=0.0 must be a finite number > 0"):
        spec("--inpaint-seam-bound", "0")


# ------------------------------------------------------------------------------ with the shipped weights
@pytest.fixture(scope="module")
def pipe(single_thread):
    from salad_core.pipeline import SaladPipeline

    return SaladPipeline.from_pretrained()


@pytest.fixture(scope="module")
def inversion(pipe, sample_features):
    return pipe.invert(sample_features[:FRAMES], "a person walks forward and turns around", num_steps=STEPS)


def _never_ranked(monkeypatch):
    def fail(*args, **kwargs):
        raise AssertionError("one candidate must not be ranked")

    monkeypatch.setattr(ranking, "ranked_edit", fail)


@needs_weights
def test_one_candidate_is_one_edit_from_the_seed_and_never_ranks(pipe, inversion, monkeypatch):
    """``candidates=1`` (and "auto" where it resolves to 1) is the edit as it was before ranking: one run of the
    edit loop, the region's fresh noise from ``seed`` itself, nothing recorded."""
    from salad_core.attention.editing import edit_latents

    plain = pipe.edit(SOURCE, target=WAVE, edits=[Inpaint(parts="arms")], lengths=FRAMES, seed=0, num_steps=STEPS)
    runs = []
    monkeypatch.setattr("salad_core.attention.editing.edit_latents",
                        lambda *a, **k: runs.append(1) or edit_latents(*a, **k))
    _never_ranked(monkeypatch)
    one = pipe.edit(SOURCE, target=WAVE, edits=[Inpaint(parts="arms", candidates=1)], lengths=FRAMES, seed=0,
                    num_steps=STEPS)
    np.testing.assert_array_equal(one.edited.features, plain.edited.features)
    torch.testing.assert_close(one.edited.latents, plain.edited.latents, atol=0, rtol=0)
    assert "inpaint_candidates" not in one.settings and one.settings == plain.settings
    span = pipe.edit(inversion=inversion, target="a person jumps",
                     edits=[Inpaint(frames=(16, 32), candidates=1, prior="none")])
    assert runs == [1, 1] and "inpaint_candidates" not in span.settings
    z = span.edited.noise                                               # the span's latent frames 4..7: seed 0's
    torch.testing.assert_close(z[:, 4:8], seeded_noise(0, z.shape)[:, 4:8], atol=0, rtol=0)
    torch.testing.assert_close(z[:, :4], inversion.noise[:, :4], atol=0, rtol=0)


@needs_weights
@needs_evaluator
@pytest.mark.parametrize("case", ["generated parts, K=3", "generated parts, K=3, scored on parts",
                                  "generated span, K=3", "inverted span, auto", "inverted span, seam bound 1.2"])
def test_best_of_k_is_the_best_of_the_k_seeds_run_one_by_one(pipe, inversion, case):
    spec, target, kw = {
        "generated parts, K=3": (Inpaint(parts="arms", noise="fresh", seed=3, candidates=3), WAVE, {}),
        "generated parts, K=3, scored on parts": (Inpaint(parts="arms", noise="fresh", seed=3, candidates=3,
                                                          score="parts"), WAVE, {}),
        "generated span, K=3": (Inpaint(frames=(16, 32), noise="fresh", candidates=3), "a person jumps", {}),
        "inverted span, auto": (Inpaint(frames=(16, 32)), "a person jumps", {"inversion": inversion}),
        "inverted span, seam bound 1.2": (Inpaint(frames=(16, 32), seam_bound=1.2), "a person jumps",
                                          {"inversion": inversion}),
    }[case]
    source = {} if kw else dict(source=SOURCE, lengths=FRAMES, seed=0, num_steps=STEPS)
    out = pipe.edit(target=target, edits=[spec], **source, **kw)
    rec = out.settings["inpaint_candidates"]
    k = spec.candidates_for(bool(kw))
    assert len(rec["seeds"]) == k == (SPAN_CANDIDATES if kw else 3)
    scorer = TextMotionScorer()
    singles = [pipe.edit(target=target, edits=[dataclasses.replace(spec, seed=spec.seed + i, candidates=1)],
                         **source, **kw) for i in range(k)]
    span = spec.frame_span(FRAMES)
    scored = [s.edited.features[0, :FRAMES] for s in singles]
    if spec.score == "parts":                                          # the arms alone, the rest held still
        scored = [isolate_parts(f, spec.parts) for f in scored]
    assert rec["score"] == spec.score_for(bool(kw))
    if rec["score"] == "prior":     # an inverted take's span: each candidate against its own pasted sample
        mine = [ranking.prior_height_cm(s, spec) for s in singles]
        assert all(s.prior.seeds == [spec.seed + i] for i, s in enumerate(singles))
    else:
        mine = [scorer.distance(f, target, span) for f in scored]
    assert len(set(mine)) == k                                         # the seeds give different motions
    np.testing.assert_allclose(rec["distances"], mine, rtol=1e-6)
    if spec.frames is None:
        assert rec["seam_ratios"] is None
    else:                                                               # each candidate's seams, as measured
        cuts = [b for b in span if 0 < b < FRAMES]
        seams = [seam_jerk_ratio(s.source.joints[0], s.edited.joints[0], cuts) for s in singles]
        np.testing.assert_allclose(rec["seam_ratios"], seams, rtol=1e-9)
    bound = spec.seam_bound_for(bool(kw))
    assert rec["seam_bound"] == bound
    best = pick_candidate(mine, rec["seam_ratios"], bound)
    assert rec["chosen"] == best
    if rec["score"] == "prior" and min(rec["seam_ratios"]) > bound:    # none smooth: the candidates without prior
        fb = rec["fallback"]
        assert out.edits[0].prior == "none" and rec["seed"] == spec.seed + fb["chosen"] == out.edits[0].seed
        assert len(fb["distances"]) == k and out.prior is None
        return
    assert "fallback" not in rec
    assert rec["seed"] == spec.seed + best and out.edits[0].seed == spec.seed + best
    np.testing.assert_array_equal(out.edited.features, singles[best].edited.features)
    np.testing.assert_array_equal(out.source.features, singles[0].source.features)
    # scored frames: the evaluator's window, or the regenerated latent frames for the prior's heights
    assert rec["frames"] == (list(span) if rec["score"] == "prior" else list(scorer.window(FRAMES, span)))


@needs_weights
def test_ranking_a_generated_sources_own_noise_is_refused_before_sampling(pipe, monkeypatch):
    monkeypatch.setattr(type(pipe), "decode", lambda *a, **k: pytest.fail("sampled"))
    with pytest.raises(ValueError, match="noise='auto' the region of a generated motion starts from the source's own"):
        pipe.edit(SOURCE, target=WAVE, edits=[Inpaint(parts="arms", candidates=2)], lengths=FRAMES, num_steps=2)


@needs_weights
def test_ranking_by_the_prior_on_an_inverted_take_scores_what_was_pasted(pipe, inversion):
    """``score="prior"`` through ``pipe.edit``: two candidates, each with its own seed's pasted prior; the chosen
    edit carries its prior, and its recorded distance is :func:`prior_height_cm` of it (no evaluator involved)."""
    spec = Inpaint(frames=(16, 32), candidates=2, prior="prompt", prior_strength=0.7, score="prior", seam_bound=None)
    out = pipe.edit(inversion=inversion, target="a person jumps", edits=[spec])
    rec = out.settings["inpaint_candidates"]
    assert rec["score"] == "prior" and rec["evaluator"] is None and "fallback" not in rec
    assert out.prior is not None and out.prior.texts == ["a person jumps"] and out.prior.seeds == [rec["seed"]]
    assert rec["distances"][rec["chosen"]] == pytest.approx(ranking.prior_height_cm(out, out.edits[0]), abs=1e-6)
    assert rec["distances"][rec["chosen"]] == min(rec["distances"]) and len(set(rec["distances"])) == 2
    assert out.settings["inpaint_prior"]["windows"] == [[4, 8, 40, 3]]


def test_a_region_from_the_sources_own_noise_has_no_fallback_and_keeps_the_smoothest_pasted_candidate():
    """A generated source's span from its own noise (``noise="source"``) with pasted candidates: when none is smooth
    there are no candidates without the prior to fall back to (they would be alike); the smoothest pasted one stays."""
    spec = Inpaint(frames=(20, 40), candidates=4, noise="source", prior="prompt", score="prior", seam_bound=1e-9)
    seen = []

    def run(specs):
        seen.append(specs[0].prior)
        return _prior_output(*_PRIOR_CANDIDATES[specs[0].seed])

    out = ranked_edit(run, [spec], inverted=False, skeleton="humanml3d", scorer=_StubScorer())
    rec = out.settings["inpaint_candidates"]
    assert seen == ["prompt"] * 4 and "fallback" not in rec
    assert rec["chosen"] == 3 and out.edits[0].seed == 3                 # seed 3: the smoothest (no seam step)


# ------------------------------------------------------------------------------ the first smooth candidate
def test_first_smooth_index_takes_the_first_within_the_bound_else_the_smoothest():
    assert ranking.first_smooth_index([2.0, 1.4, 1.0], 1.5) == 1        # the first smooth, not the smoothest
    assert ranking.first_smooth_index([1.2, 1.0], 1.5) == 0
    assert ranking.first_smooth_index([3.0, 2.0, 2.5], 1.5) == 1        # none smooth: the smallest ratio
    with pytest.raises(ValueError, match="one seam ratio per candidate"):
        ranking.first_smooth_index([], 1.5)


def test_first_smooth_needs_a_seam_and_a_bound_and_resolves_its_bound_for_a_generated_source():
    with pytest.raises(ValueError, match="has no seam"):
        Inpaint(parts="arms", score="first_smooth")
    with pytest.raises(ValueError, match="seam_bound=None sets no bound"):
        Inpaint(frames=(20, 40), score="first_smooth", seam_bound=None)
    spec = Inpaint(frames=(20, 40), candidates=4, score="first_smooth")
    assert spec.seam_bound_for(False) == SEAM_BOUND and spec.seam_bound_for(True) == SEAM_BOUND
    assert spec.score_for(False) == "first_smooth"


@pytest.mark.parametrize("table, run_seeds, chosen", [
    ({0: (2.0, 0.0), 1: (2.0, 0.01), 2: (2.0, 0.0), 3: (2.0, 0.0)}, [0], 0),           # seed 0 smooth: nothing more
    ({0: (2.0, 0.01), 1: (2.0, 0.01), 2: (9.0, 0.0002), 3: (0.0, 0.0)}, [0, 1, 2], 2),  # stops at the first smooth
    ({0: (2.0, 0.01), 1: (2.0, 0.02), 2: (2.0, 0.005), 3: (2.0, 0.008)}, [0, 1, 2, 3], 2),  # none: the smoothest
])
def test_ranked_edit_first_smooth_runs_candidates_until_one_joins_smoothly(table, run_seeds, chosen):
    """``score="first_smooth"``: candidates run one at a time, the first within the bound ends the run; no evaluator
    is loaded or asked (the stub scorer would fail if it were), the record holds the seeds run and their seams."""
    spec = Inpaint(frames=(20, 40), candidates=4, noise="source", prior="prompt", score="first_smooth")
    run, seen = _run_candidates(table)

    class _NoScorer:
        def __getattr__(self, name):
            raise AssertionError(f"first_smooth asked the evaluator for {name}")

    out = ranked_edit(run, [spec], inverted=False, skeleton="humanml3d", scorer=_NoScorer())
    rec = out.settings["inpaint_candidates"]
    assert seen == run_seeds and rec["seeds"] == run_seeds and rec["evaluator"] is None
    np.testing.assert_allclose(rec["seam_ratios"], [_ratio(table[s][1]) for s in run_seeds], rtol=1e-12)
    assert rec["distances"] == rec["seam_ratios"] and rec["score"] == "first_smooth"
    assert rec["chosen"] == chosen and out.edits[0].seed == chosen
    np.testing.assert_array_equal(out.edited.joints[0], _span_output(*table[chosen]).edited.joints[0])
