"""Corpus 2.0 realism (issue 27): the stats functions on hand-made inputs with known answers,
and behaviour checks on a few generated clips (running, co-articulated sequences, contact)."""
from __future__ import annotations

import numpy as np
import pytest

from salad_core.data.procedural import Action, Plan, Step, realise
from salad_core.data.procedural.checks import bone_length_error
from salad_core.data.procedural.stats import (body_speed, boundary_figures, canonical_pose, neutral_pose,
                                              pca_components, pose_spread, run_figures, sentence_frame,
                                              sequence_boundaries, top_level_phrases, upper_arm_flexion)
from salad_core.skeleton import get_skeleton

SK = get_skeleton("humanml3d")


# ============================================================================ stats on known inputs
def test_body_speed_of_a_uniform_translation():
    n, j = 5, SK.num_joints
    joints = np.zeros((n, j, 3))
    joints[:, :, 2] = (np.arange(n) * 0.01)[:, None]          # 1 cm per frame at 20 fps
    np.testing.assert_allclose(body_speed(joints), 0.2)
    with pytest.raises(ValueError, match="joints must have shape"):
        body_speed(joints[:1])


def test_pca_components_counts_independent_directions():
    rng = np.random.default_rng(0)
    x = np.zeros((2000, 10))
    x[:, :3] = rng.normal(size=(2000, 3)) * np.array([3.0, 2.0, 1.0])
    assert pca_components(x, 0.5) == 1
    assert pca_components(x, 0.99) == 3
    with pytest.raises(ValueError, match="share"):
        pca_components(x, 1.5)


def test_pose_spread_of_a_still_and_of_a_moving_clip():
    d = SK.feature_dim
    still = np.zeros((10, d))
    assert pose_spread(still) == 0.0
    moving = np.zeros((10, d))
    ric = SK.feature_slices["ric"]
    moving[:, ric.start] = np.tile([0.1, -0.1], 5)            # one coordinate +-10 cm: std 0.1
    assert pose_spread(moving) == pytest.approx(0.1 / (3 * (SK.num_joints - 1)))


def test_top_level_phrases_and_boundaries():
    main0 = {"frames": [5, 40]}
    layer0 = {"frames": [10, 30]}
    main1 = {"frames": [38, 80]}
    overlay = {"frames": [5, 80]}
    assert top_level_phrases([main0, layer0, main1, overlay]) == [main0, main1]
    ann = {"num_frames": 90, "captions": [{"phrases": [overlay, main1, layer0, main0]}]}
    assert sequence_boundaries(ann, pad=2) == [(36, 43)]        # overlap 38..40, padded
    ann1 = {"num_frames": 90, "captions": [{"phrases": [main0, layer0]}]}
    assert sequence_boundaries(ann1) == []


def test_boundary_figures_see_a_dead_stop_at_the_neutral_stand():
    n = 30
    still = np.tile(neutral_pose(), (n, 1, 1)) + np.array([0.0, 0.93, 0.0])
    fig = boundary_figures(still, [(10, 20)])
    assert fig[0]["min_speed"] == pytest.approx(0.0, abs=1e-12)
    assert fig[0]["min_neutral_distance"] < 1e-9


def test_sentence_frame_drops_subjects_and_phrases():
    cap = "a man walks forward and then jumps twice . the person waves"
    spans = [(2, 4), (6, 8), (10, 11)]                         # split_words drops the "."
    assert sentence_frame(cap, spans) == "<P> and then <P> <S> <P>"
    assert sentence_frame("someone kicks", [(1, 2)]) == "<P>"


def test_upper_arm_flexion_sign():
    c = np.tile(neutral_pose(), (2, 1, 1))
    sh, el = SK.joint_names.index("left_shoulder"), SK.joint_names.index("left_elbow")
    c[1, el] = c[1, sh] + np.array([0.0, -0.2, 0.2])         # upper arm 45 deg forward
    flex = upper_arm_flexion(c)
    assert flex[1, 0] == pytest.approx(45.0, abs=1.0)
    assert abs(flex[0, 0]) < 25.0                              # hanging arm: near vertical


# ============================================================================ generated clips
def _clip(kind, seed, **kw):
    return realise(Plan((Step(Action(kind, **kw)),)), np.random.default_rng(seed))


@pytest.mark.parametrize("kind", ["run", "jog"])
def test_running_swings_the_arms_across_vertical_and_bobs(kind):
    bobs, backs, fronts = [], [], []
    for seed in range(3):
        clip = _clip(kind, seed)
        fig = run_figures(clip.joints, clip.events[0].frames)
        bobs.append(fig["bob"])
        backs.append(fig["arm_back"])
        fronts.append(fig["arm_front"])
        assert 60 <= fig["elbow_min"] and fig["elbow_max"] <= 115
        err = bone_length_error(clip.joints)
        assert err["max_error"] < 1e-6
        assert clip.joints[..., 1].min() > -0.005
    assert 0.05 <= np.median(bobs) <= 0.10, bobs
    assert max(backs) < -20 and min(fronts) > 20, (backs, fronts)


def test_running_has_airborne_frames():
    shares = []
    for seed in range(4):                                      # one performer may run slowly: pool a few
        clip = _clip("run", seed)
        f0, f1 = clip.events[0].frames
        feet = clip.joints[f0:f1][:, list(SK.contact_joints), 1].min(-1)
        shares.append((feet > 0.03).mean())                    # both feet clearly off the floor
    assert np.median(shares) > 0.2 and min(shares) > 0.1, shares


def test_sequences_do_not_stop_dead():
    speeds = []
    for seed in range(6):
        plan = Plan((Step(Action("walk")), Step(Action("jump"))))
        clip = realise(plan, np.random.default_rng(seed))
        (a0, a1), (b0, b1) = clip.events[0].frames, clip.events[1].frames
        assert b0 <= a1 + 1                                     # the next action starts before the last ends
        lo, hi = sorted((a1, b0))
        speeds.append(body_speed(clip.joints)[lo - 2:hi + 3].min())
        assert clip.joints[..., 1].min() > -0.005
        assert bone_length_error(clip.joints)["max_error"] < 1e-6
    assert np.median(speeds) > 0.05, speeds


def test_clips_start_facing_forward_at_the_origin():
    clip = _clip("wave", 2, side="left")
    assert np.allclose(clip.joints[0, 0, [0, 2]], 0.0)
    c = canonical_pose(clip.joints[:1])
    assert c.shape == (1, SK.num_joints, 3)


def _stride_lengths(seg) -> np.ndarray:
    """Distances between consecutive plants of the same foot of a locomotion segment (m)."""
    out = []
    for k in range(2):
        a = seg.pose.ankle[:, k]
        still = np.r_[False, np.linalg.norm(np.diff(a, axis=0), axis=1) < 1e-9]
        starts = np.nonzero(still & ~np.r_[False, still[:-1]])[0]
        plants = a[starts]
        out.append(np.linalg.norm(np.diff(plants[:, [0, 2]], axis=0), axis=1))
    return np.concatenate([s[2:-2] for s in out])          # cruise only: drop the speed-up and slow-down


def test_steps_vary_in_length_by_a_few_percent():
    import dataclasses

    from salad_core.data.procedural.footwork import Persona, Stance
    from salad_core.data.procedural.gait import Route, gait_style, locomotion
    from salad_core.data.procedural.kinematics import body_model

    body = body_model("humanml3d")
    persona = Persona.sample(np.random.default_rng(0))
    style = gait_style("walk", np.random.default_rng(1), tempo=persona.tempo)
    start = Stance.at((0.0, 0.0), 0.0, persona)
    varied = _stride_lengths(locomotion(start, persona, style, Route(), 14, body))
    even = _stride_lengths(locomotion(start, persona, dataclasses.replace(style, step_var=()), Route(), 14, body))
    assert varied.size >= 6
    assert np.std(even) / np.mean(even) < 0.005                     # one cadence: identical strides
    assert 0.01 < np.std(varied) / np.mean(varied) < 0.06           # real walkers: 2-4 %
    assert np.mean(varied) == pytest.approx(np.mean(even), rel=0.05)
    with pytest.raises(ValueError, match="step_var"):
        dataclasses.replace(style, step_var=(0.5,))


def test_jumping_jack_wrists_stay_under_real_accelerations():
    w = [SK.joint_names.index("left_wrist"), SK.joint_names.index("right_wrist")]
    peaks = []
    for seed in range(4):
        clip = realise(Plan((Step(Action("jumping_jacks", None, (), 2, "")),)), np.random.default_rng(seed))
        acc = np.linalg.norm(np.diff(clip.joints[:, w], 2, axis=0), axis=-1) * SK.fps ** 2
        peaks.append(acc.max())
        assert (clip.joints[:, w, 1] > clip.joints[:, [SK.joint_names.index("head")], 1]).any()   # arms overhead
    assert max(peaks) < 140.0, peaks                 # real maximum ~128 m/s^2 (issue 27); 1.0: 168-205


def test_kick_upper_body_counters_the_leg():
    for seed in range(3):
        clip = _clip("kick", seed, side="left")
        f0, f1 = clip.events[0].frames
        flex = upper_arm_flexion(clip.joints[f0:f1])
        # the arm opposite the kicking leg swings forward, well past the kicking side's arm
        assert (flex[:, 1] - flex[:, 0]).max() > 55.0, (seed, flex.min(0), flex.max(0))   # 1.0: 28-36 deg


def test_hand_wave_is_sideways_and_overhead_waving_is_wide():
    from salad_core.part_activity import chest_frames

    lw, ls = SK.joint_names.index("left_wrist"), SK.joint_names.index("left_shoulder")
    for variant, side in (("", "left"), ("arms", "both")):
        for seed in range(3):
            clip = realise(Plan((Step(Action("wave", side, (), 1, variant)),)), np.random.default_rng(seed))
            f0, f1 = clip.events[0].frames
            j = clip.joints[f0:f1]
            # the hand about its shoulder in the chest frame (the trunk may lean with the arm)
            w = np.einsum("nij,nj->ni", chest_frames(j, SK), j[:, lw] - j[:, ls])
            mid = w[len(w) // 4: 3 * len(w) // 4]                    # while waving (not rising / lowering)
            sideways, vertical = np.ptp(mid[:, 0]), np.ptp(mid[:, 1])
            if variant == "":
                assert sideways > 2.5 * vertical, (seed, sideways, vertical)     # 1.0: about equal
            else:
                assert sideways > 0.38, (seed, sideways)                       # 1.0: 0.26-0.38 m


def test_seated_hands_rest_on_the_floor():
    w = [SK.joint_names.index("left_wrist"), SK.joint_names.index("right_wrist")]
    for seed in range(4):
        j = _clip("sit", seed).joints
        floor = j[..., 1].min() - 0.012                   # the toes rest 1.2 cm over the floor
        assert (j[-1, w, 1] - floor < 0.10).all(), (seed, j[-1, w, 1] - floor)     # 1.0: 13-17 cm
        assert (j[:, w, 1] - floor > 0.0).all()                                    # never through it


def test_trunk_turns_with_one_arm_but_not_with_both():
    from salad_core.data.procedural.composition import TRUNK_YAW_PER_FLEX, _trunk_follows_arms
    from salad_core.data.procedural.footwork import Persona, Stance
    from salad_core.data.procedural.kinematics import body_model
    from salad_core.data.procedural.segment import standing_pose

    body = body_model("humanml3d")
    persona = Persona.sample(np.random.default_rng(0))
    stance = Stance.at((0.0, 0.0), 0.0, persona)
    one = standing_pose(stance, persona, 60, body, rng=None, idle=False)
    both = one.copy()
    one.arm[30:, 1, 0] += 1.0                                   # the right arm swings forward and stays
    both.arm[30:, :, 0] += 1.0
    yaw0 = one.spine[:, 0].copy()
    _trunk_follows_arms(one, persona)
    _trunk_follows_arms(both, persona)
    turn = one.spine[:, 0] - yaw0
    assert turn[59] == pytest.approx(TRUNK_YAW_PER_FLEX, rel=0.02)   # turns left (+yaw) with the right arm
    assert abs(turn[5]) < 1e-3                                       # long before the arm moves: nothing
    np.testing.assert_allclose(both.spine[:, 0], yaw0, atol=1e-12)    # symmetric arms: no turn


def test_long_sequences_are_drawn_and_said():
    """Corpus 2.1 draws plans of four co-articulated actions; their captions parse back."""
    from salad_core.data.procedural import GENERATOR_VERSION, in_language, render_captions
    from salad_core.data.procedural.composition import PLAN_TYPES, sample_plan

    assert GENERATOR_VERSION == "2.7"
    assert PLAN_TYPES["sequence3"] + PLAN_TYPES["sequence4"] >= 0.5          # 2.5: 0.57 (2.4: 0.43)
    assert PLAN_TYPES["single"] + PLAN_TYPES["gesture"] <= 0.1
    for i in range(5):
        rng = np.random.default_rng([12, i])
        plan = sample_plan(rng, "sequence4")
        assert len(plan.steps) == 4
        assert all(a.main.kind != b.main.kind for a, b in zip(plan.steps, plan.steps[1:]))
        for cap in render_captions(plan, rng, 2):
            assert in_language(cap.text), cap.text


def test_trunk_joints_bend_each_their_own_way():
    """Pose.trunk (2.3) bends one trunk joint alone: the bones above it turn, the ones below do
    not, bone lengths stay exact, and reach.chest_frames is the chest assemble builds."""
    from salad_core.data.procedural.footwork import Persona, Stance
    from salad_core.data.procedural.kinematics import assemble, body_model, trunk_frames
    from salad_core.data.procedural.reach import chest_frames
    from salad_core.data.procedural.segment import standing_pose

    body = body_model("humanml3d")
    persona = Persona.sample(np.random.default_rng(3))
    pose = standing_pose(Stance.at((0.0, 0.0), 0.0, persona), persona, 4, body, rng=None, idle=False)
    assert pose.trunk.shape == (4, 5, 3) and not pose.trunk.any()
    before = assemble(pose, body)
    pose.trunk[:, 2, 1] = 0.3                      # the upper back (spine3) bends forward alone
    after = assemble(pose, body)
    J = body.index
    for name in ("pelvis", "spine1", "spine2", "spine3", "left_hip", "left_knee"):
        np.testing.assert_allclose(after[:, J[name]], before[:, J[name]], atol=1e-12)
    for name in ("neck", "head", "left_shoulder", "right_wrist"):
        assert np.linalg.norm(after[:, J[name]] - before[:, J[name]], axis=-1).min() > 0.02
    par = np.asarray(body.skeleton.parents[1:])
    np.testing.assert_allclose(np.linalg.norm(after[:, 1:] - after[:, par], axis=-1),
                               np.broadcast_to(body.lengths[1:], (4, 21)), atol=1e-9)
    chest = chest_frames(pose)
    np.testing.assert_allclose(chest, trunk_frames(pose)[2], atol=1e-12)
    collar = after[:, J["spine3"]] + chest @ body.rest_offsets[J["left_collar"]]
    np.testing.assert_allclose(collar, after[:, J["left_collar"]], atol=1e-12)


def test_performers_curve_and_share_the_spine_their_own_way():
    """trunk_curvature keeps the chest's orientation (the spine rows sum to zero per axis) and
    differs between performers; spine_shares sum to one per axis; bad values are named."""
    from dataclasses import replace

    from salad_core.data.procedural.composition import _share_spine
    from salad_core.data.procedural.footwork import Persona, Stance, spine_shares, trunk_curvature
    from salad_core.data.procedural.kinematics import body_model, trunk_frames
    from salad_core.data.procedural.segment import standing_pose

    curves = np.array([trunk_curvature(np.random.default_rng(i)) for i in range(200)])   # (200, 5, 3)
    np.testing.assert_allclose(curves[:, :3].sum(1), 0.0, atol=1e-12)
    lumbar_pitch = curves[:, 0, 1]
    assert 0.06 < lumbar_pitch.std() < 0.2 and np.abs(curves).max() <= 0.5
    assert np.corrcoef(curves[:, 3, 1], curves[:, 4, 1])[0, 1] < -0.5      # a forward neck, a level gaze
    shares = np.array([spine_shares(np.random.default_rng(i)) for i in range(200)])      # (200, 3, 3)
    np.testing.assert_allclose(shares.sum(1), 1.0, atol=1e-12)
    assert 0.05 < shares[:, 0, 1].std() < 0.15 and abs(shares[:, 0, 1].mean() - 0.45) < 0.03

    body = body_model("humanml3d")
    base = Persona.sample(np.random.default_rng(0))
    chests, spine2 = [], []
    for sh in (((0.7,) * 3, (0.2,) * 3, (0.1,) * 3), ((0.2,) * 3, (0.3,) * 3, (0.5,) * 3)):
        persona = replace(base, spine_share=sh)
        pose = standing_pose(Stance.at((0.0, 0.0), 0.0, persona), persona, 2, body, rng=None, idle=False)
        pose.spine[:] = (0.1, 0.6, 0.2)            # a bow, a little turned and leaning
        _share_spine(pose, persona)
        chests.append(trunk_frames(pose)[2])
        spine2.append(trunk_frames(pose)[0])
    turn = np.degrees(np.arccos(np.clip((np.trace(chests[0][0].T @ chests[1][0]) - 1) / 2, -1, 1)))
    lumbar = np.degrees(np.arccos(np.clip((np.trace(spine2[0][0].T @ spine2[1][0]) - 1) / 2, -1, 1)))
    assert turn < 3.0 and lumbar > 15.0            # the same chest, bent from a different place
    with pytest.raises(ValueError, match="spine_share"):
        replace(base, spine_share=((0.5,) * 3, (0.5,) * 3, (0.5,) * 3))
    with pytest.raises(ValueError, match="trunk_posture"):
        replace(base, trunk_posture=((0.0, 0.9, 0.0),) * 5)


def test_feet_are_handed_over_without_a_jump():
    """_feet_handover shortens an overlap so that the next segment moves a foot only once the
    earlier one has put it where the next one starts it (2.3: a pivot then a quick walk)."""
    from salad_core.data.procedural.composition import _feet_handover
    from salad_core.data.procedural.footwork import Persona, Stance
    from salad_core.data.procedural.kinematics import body_model
    from salad_core.data.procedural.segment import standing_pose

    body = body_model("humanml3d")
    persona = Persona.sample(np.random.default_rng(1))
    acc = standing_pose(Stance.at((0.0, 0.0), 0.0, persona), persona, 20, body, rng=None, idle=False)
    nxt = standing_pose(Stance.at((0.0, 0.0), 0.0, persona), persona, 20, body, rng=None, idle=False)
    slide = np.zeros((20, 3))
    slide[:17, 0] = np.linspace(0.3, 0.01, 17)           # acc's left foot lands at frame 17
    acc.ankle[:, 0] += slide
    acc.toe[:, 0] += slide
    lift = np.zeros((20, 3))
    lift[3:, 1] = 0.05                                   # nxt lifts the left foot from frame 3
    nxt.ankle[:, 0] += lift
    nxt.toe[:, 0] += lift
    assert _feet_handover(acc, nxt, 8) == 6              # 20 - 6 + 3 = 17: the foot is down by then
    assert _feet_handover(acc, nxt, 5) == 5              # already clean
    still = nxt.copy()
    still.ankle[:, 0] -= lift
    still.toe[:, 0] -= lift
    assert _feet_handover(acc, still, 8) == 8            # a foot the next segment leaves alone


# ============================================================================ fidgets (2.4)
def _chest_wrist(pose, joints: np.ndarray, k: int) -> np.ndarray:
    """``(N, 3)`` wrist of arm ``k`` from its shoulder in the chest frame of ``pose``, x outwards."""
    from salad_core.data.procedural.reach import chest_frames

    side = ("left", "right")[k]
    d = joints[:, SK.joint_names.index(f"{side}_wrist")] - joints[:, SK.joint_names.index(f"{side}_shoulder")]
    local = np.einsum("nji,nj->ni", chest_frames(pose), d)
    return local * np.array([1.0 if k == 0 else -1.0, 1.0, 1.0])


def test_arm_fidget_puts_the_wrist_on_its_target_and_drives_one_arm():
    from salad_core.data.procedural.composition import _blend
    from salad_core.data.procedural.fidgets import ARM_FIDGETS, arm_fidget
    from salad_core.data.procedural.footwork import Persona, Stance
    from salad_core.data.procedural.kinematics import assemble, body_model
    from salad_core.data.procedural.segment import standing_pose

    body = body_model("humanml3d")
    persona = Persona.sample(np.random.default_rng(3))
    for kind in ("chin", "head", "pocket", "phone"):
        for k in (0, 1):
            g = arm_fidget(persona, body, np.random.default_rng([4, k]), k, span=3.0, kind=kind)
            assert g.info == {"fidget": kind, "arm": k}
            assert g.num_frames <= 61                                    # at most the 3 s span
            assert (g.arm_weight[:, 1 - k] == 0).all() and g.arm_weight[[0, -1], k].max() < 1e-9
            pose = standing_pose(Stance.at((0.0, 0.0), 0.0, persona), persona, g.num_frames, body, rng=None, idle=False)
            _blend(pose, g, 0)
            wrist = _chest_wrist(pose, assemble(pose, body), k)
            mid = int(np.argmax(g.arm_weight[:, k] > 0.999)) + 2          # well into the hold
            low, high, _, _ = ARM_FIDGETS[kind]
            assert np.all(wrist[mid] > np.array(low) - 0.02) and np.all(wrist[mid] < np.array(high) + 0.03), (kind, k, wrist[mid])
    with pytest.raises(ValueError, match="kind='wiggle'"):
        arm_fidget(persona, body, np.random.default_rng(0), 0, 2.0, kind="wiggle")
    with pytest.raises(ValueError, match="arm=2"):
        arm_fidget(persona, body, np.random.default_rng(0), 2, 2.0)
    with pytest.raises(ValueError, match="span=0.3"):
        arm_fidget(persona, body, np.random.default_rng(0), 0, 0.3)


def test_glance_and_trunk_shift_move_only_head_and_trunk():
    from salad_core.data.procedural.fidgets import glance, trunk_shift
    from salad_core.data.procedural.footwork import Persona
    from salad_core.data.procedural.kinematics import body_model

    body = body_model("humanml3d")
    persona = Persona.sample(np.random.default_rng(5))
    yaws, pitches = [], []
    for i in range(30):
        g = glance(persona, body, np.random.default_rng([6, i]), span=2.5)
        assert g.num_frames <= 51 and (g.arm_weight == 0).all()
        assert np.abs(g.neck[[0, -1]]).max() < 1e-9                      # from ahead back to ahead
        yaws.append(np.abs(g.neck[:, 0]).max())
        t = trunk_shift(persona, body, np.random.default_rng([7, i]), span=2.5)
        assert t.num_frames <= 51 and (t.arm_weight == 0).all() and np.abs(t.spine[[0, -1]]).max() < 1e-9
        np.testing.assert_allclose(t.neck[:, 1], -0.5 * t.spine[:, 1])   # the gaze stays level
        pitches.append(t.spine[:, 1].max())
    # glances are smaller than the annotated look (0.95-1.25 rad) but clearly there
    assert 0.3 <= min(yaws) and max(yaws) <= 0.8 + 1e-9
    assert max(pitches) > 0.15


def test_fidgets_respect_the_core_and_the_parts_the_plan_names():
    """step_fidgets stays inside the core (clear of its ends); the composer gives no fidget to an
    arm a layered gesture drives, no glance under a layered head gesture, none to a kick."""
    from salad_core.data.procedural.composition import _fidgets_of
    from salad_core.data.procedural.fidgets import MARGIN, step_fidgets
    from salad_core.data.procedural.footwork import Persona
    from salad_core.data.procedural.kinematics import body_model
    from salad_core.data.procedural.segment import Segment

    body = body_model("humanml3d")
    persona = Persona.sample(np.random.default_rng(8))
    seen = set()
    for i in range(40):
        out = step_fidgets(persona, body, np.random.default_rng([9, i]), (10, 70), (0, 1), True, True)
        for at, g in out:
            assert at >= 10 + MARGIN and at + g.num_frames <= 70 - MARGIN
            seen.add(g.info["fidget"])
    assert {"glance", "trunk"} <= seen and len(seen) >= 6
    assert step_fidgets(persona, body, np.random.default_rng(0), (0, 30), (0, 1), True, True) == []   # too short

    seg = Segment(None, None, (0, 80))
    wave = Step(Action("walk"), Action("wave", "right"))
    nod = Step(Action("walk"), Action("nod", reps=2))
    for i in range(40):
        for at, g in _fidgets_of(wave, None, seg, (0, 80), persona, body, np.random.default_rng([10, i])):
            assert (g.arm_weight[:, 1] == 0).all()
        for at, g in _fidgets_of(nod, None, seg, (0, 80), persona, body, np.random.default_rng([11, i])):
            assert g.info["fidget"] != "glance"
        over = _fidgets_of(Step(Action("walk")), Action("clap", "both"), seg, (0, 80), persona, body,
                           np.random.default_rng([12, i]))
        assert all((g.arm_weight == 0).all() for _, g in over)


def test_walks_fidget_but_their_annotation_still_holds():
    """Over a few seeded walks the arms and head leave the gait's swing (fidgets), while the
    walk's legs still move more than any part no phrase names (the annotation checks)."""
    from salad_core.data.procedural import part_speeds, phrase_activity

    plan = Plan((Step(Action("walk")),))
    wrist_range, ratios = [], []
    for i in range(6):
        clip = realise(plan, np.random.default_rng([13, i]))
        ev = clip.events[0]
        r = phrase_activity(part_speeds(clip.joints), [{"frames": ev.frames, "parts": ev.parts}], [ev.secondary])[0]
        ratios.append(r["ratio_idle"])
        c = canonical_pose(clip.joints)
        wrist_range.append(max(np.ptp(c[:, SK.joint_names.index(f"{s}_wrist"), 1]) for s in ("left", "right")))
        assert bone_length_error(clip.joints)["max_error"] < 1e-6
    assert min(ratios) > 1.5
    assert max(wrist_range) > 0.3          # some hand went up to the face or the head (a swing alone: < 0.15)


def test_targets_table_shows_the_pelvis_relative_pca_as_info():
    from salad_core.data.procedural.stats import BASELINE, targets_table

    fig = {k: v for k, v in BASELINE.items()}
    fig.update(boundaries=10, run_phrases=0, jog_phrases=0, pca_90=10, pca_90_pelvis_relative=12,
               boundary_speed_median=0.3)
    for g in ("run", "jog"):
        for k in ("bob", "arm_back", "arm_front", "elbow_min", "elbow_max"):
            fig[f"{g}_{k}"] = float("nan")
    rows = {r.name.strip(): r for r in targets_table(fig)}
    assert rows["principal components for 90 % of pose variance"].passed is False
    info = rows["the same with the root height taken off (pelvis-relative)"]
    assert info.value == "12" and info.passed is None


def test_one_arm_swings_more_than_the_other():
    """Persona.swing_scale (2.4) scales each arm's walking swing on its own; it is validated."""
    from dataclasses import replace

    from salad_core.data.procedural.footwork import Persona, Stance
    from salad_core.data.procedural.gait import Route, gait_style, locomotion
    from salad_core.data.procedural.kinematics import body_model

    body = body_model("humanml3d")
    base = Persona.sample(np.random.default_rng(14))
    ranges = []
    for scale in ((1.0, 1.0), (1.3, 0.7)):
        persona = replace(base, swing_scale=scale)
        style = gait_style("walk", np.random.default_rng(15), (), 1.0)
        seg = locomotion(Stance.at((0.0, 0.0), 0.0, persona), persona, style, Route(), 6, body)
        ranges.append(np.ptp(seg.pose.arm[:, :, 0], axis=0))          # flexion range per arm
    np.testing.assert_allclose(ranges[0][0], ranges[0][1], rtol=0.05)
    assert ranges[1][0] > 1.5 * ranges[1][1]
    with pytest.raises(ValueError, match="swing_scale"):
        replace(base, swing_scale=(1.0, 2.5))


def test_forward_walks_drift_along_gentle_arcs():
    """2.5: a forward walk, run, jog or march drifts along an arc with DRIFT_P; its heading gain
    over the route lies in DRIFT_ANGLE (well under a turn), in-place gaits stay straight, and the
    planted feet still do not slide."""
    from salad_core.data.procedural.checks import foot_sliding
    from salad_core.data.procedural.footwork import Persona, Stance
    from salad_core.data.procedural.gait import Route, gait_style, locomotion
    from salad_core.data.procedural.kinematics import assemble, body_model
    from salad_core.data.procedural.primitives import DRIFT_ANGLE, DRIFT_P, build_base

    body = body_model("humanml3d")
    persona = Persona.sample(np.random.default_rng(20))
    start = Stance.at((0.0, 0.0), 0.0, persona)
    turns = {}
    for kind in ("walk", "run"):
        turns[kind] = []
        for i in range(24):
            seg = build_base(Action(kind), start, persona, body, np.random.default_rng([21, i]))
            turns[kind].append(seg.info["turn"])
            if i < 3:                       # the arc slides the planted feet no more than a line does
                style = gait_style(kind, np.random.default_rng([26, i]))
                slide = [foot_sliding(assemble(locomotion(start, persona, style, r, 6, body).pose, body,
                                               keep_toes=True))["mean"]
                         for r in (Route(), Route("arc", radius=8.0, side=1.0))]
                assert slide[1] <= 1.05 * slide[0] + 1e-3, slide
        t = np.abs(turns[kind])
        curved = t > 1e-6
        assert 0.3 < curved.mean() < 0.9                               # about DRIFT_P = 0.6 of them
        assert DRIFT_ANGLE[0] * 0.8 <= t[curved].min() and t[curved].max() <= DRIFT_ANGLE[1] * 1.25
        assert (np.sign(np.asarray(turns[kind])[curved]) > 0).any() and (np.sign(np.asarray(turns[kind])[curved]) < 0).any()
    assert 0.0 < DRIFT_P < 1.0 and DRIFT_ANGLE[1] < 0.45 * np.pi       # a drift is never a turn
    in_place = build_base(Action("walk", variant="in_place"), start, persona, body, np.random.default_rng(22))
    assert abs(in_place.info["turn"]) < 1e-9


def test_posture_drift_is_slow_large_and_spares_gesture_arms():
    """2.5: _drift moves the trunk, head and free arms by several degrees over seconds (slowly:
    the drift's angular speed stays far below an action's), and leaves arms a gesture drives and
    a trunk propped on its hands (nearly) alone."""
    from salad_core.data.procedural.composition import DRIFT_AMP, _drift
    from salad_core.data.procedural.footwork import Persona, Stance
    from salad_core.data.procedural.kinematics import FPS, body_model
    from salad_core.data.procedural.segment import standing_pose

    body = body_model("humanml3d")
    persona = Persona.sample(np.random.default_rng(23))
    n = 160
    base = standing_pose(Stance.at((0.0, 0.0), 0.0, persona), persona, n, body, rng=None, idle=False)
    spine_std, arm_std, rates = [], [], []
    for i in range(8):
        pose = base.copy()
        gest = np.zeros((n, 2))
        gest[:, 1] = 1.0                                                 # a gesture drives the right arm
        propped = np.zeros(n)
        propped[100:] = 1.0
        _drift(pose, persona, np.random.default_rng([24, i]), propped=propped, gesture_arms=gest)
        d_spine = pose.spine - base.spine
        d_arm = pose.arm - base.arm
        np.testing.assert_allclose(d_arm[:, 1], 0.0, atol=1e-12)         # the gesture's arm is its own
        assert np.abs(d_spine[130:]).max() < 0.25 * np.abs(d_spine[:80]).max() + 1e-9
        spine_std.append(d_spine[:90, 1].std())
        arm_std.append(d_arm[:, 0, 0].std())
        rates.append(np.abs(np.diff(d_arm[:, 0, 0])).max() * FPS)
        np.testing.assert_allclose(pose.ankle, base.ankle)               # the feet are not touched
        np.testing.assert_allclose(pose.pelvis, base.pelvis)
    assert np.mean(spine_std) > 0.2 * DRIFT_AMP["spine"][1] * persona.liveliness
    assert np.mean(arm_std) > 0.03                                       # rad: a visible drift of the free arm
    assert max(rates) < 0.6                                              # rad/s: slow (a wave swings > 3)
    # an arm a pose holds across the body (abduction below 0.02 rad) is not snapped out of it
    pose = base.copy()
    pose.arm[:, 0, 1] = np.linspace(-0.3, 0.3, n)
    _drift(pose, persona, np.random.default_rng(27))
    # (no snap: a held crossing snapped out would jump 0.28 rad; 2.6's drift with both arms
    # drifting together moves up to ~0.02 rad a frame of its own)
    assert np.abs(np.diff(pose.arm[:, 0, 1])).max() < 0.03
    assert pose.arm[0, 0, 1] < 0.0


def test_performers_range_wider_in_posture_and_carriage():
    """2.5: performers' stance width, twist and per-arm carriage span wider ranges than 2.4's."""
    from salad_core.data.procedural.footwork import Persona

    ps = [Persona.sample(np.random.default_rng([25, i])) for i in range(300)]
    width = np.array([p.width for p in ps])
    twist = np.array([p.twist for p in ps])
    offs = np.array([p.arm_offsets for p in ps])                          # (300, 2, 3)
    assert width.min() < 0.06 and width.max() > 0.18
    assert np.abs(twist).max() > 0.3
    assert offs[..., 0].max() > 0.2 and offs[..., 1].max() > 0.25
    # the two arms of a performer are drawn each their own
    assert abs(np.corrcoef(offs[:, 0, 0], offs[:, 1, 0])[0, 1]) < 0.2


def test_settle_shifts_the_weight_while_the_feet_stay_planted():
    """2.6: _settle moves a standing pelvis between held lower-body postures: the weight onto
    one foot (the pelvis travels SETTLE_RANGE['shift'] of the way to it, at most SETTLE_MAX_SHIFT),
    soft knees, a hinge at the hips. The feet do not move (exactly), the bones keep their lengths,
    nothing goes under the floor and the pelvis moves slowly."""
    from salad_core.data.procedural.composition import SETTLE_MAX_SHIFT, SETTLE_MOVE, SETTLE_RANGE, _settle
    from salad_core.data.procedural.footwork import Persona, Stance
    from salad_core.data.procedural.kinematics import FPS, assemble, body_model
    from salad_core.data.procedural.segment import standing_pose

    body = body_model("humanml3d")
    feet = [SK.joint_names.index(n) for n in ("left_ankle", "right_ankle", "left_foot", "right_foot")]
    shifts, hinges = [], []
    for i in range(6):
        persona = Persona.sample(np.random.default_rng([30, i]))
        stance = Stance.at((0.0, 0.0), 0.3 * i, persona)
        base = standing_pose(stance, persona, 160, body, rng=None, idle=False)
        pose = base.copy()
        keys = _settle(pose, persona, body, np.random.default_rng([31, i]))
        j0, j1 = assemble(base, body, keep_toes=True), assemble(pose, body, keep_toes=True)
        np.testing.assert_allclose(j1[:, feet], j0[:, feet], atol=1e-9)          # planted exactly
        assert bone_length_error(j1)["max_error"] < 1e-6
        assert j1[..., 1].min() > -1e-6
        # the pelvis's travel towards the loaded foot, against the stance's half width
        half = np.linalg.norm(stance.ankles[0] - stance.ankles[1]) / 2
        travel = np.linalg.norm((pose.pelvis - base.pelvis)[:, [0, 2]], axis=-1)
        lat = np.abs(keys[:, 0])
        held = lat > SETTLE_RANGE["shift"][0] * 0.99
        if held.any() and not (keys[held, 2] > 0.01).any():
            want = np.minimum(lat[held] * half, SETTLE_MAX_SHIFT)
            np.testing.assert_allclose(travel[held], want, atol=2e-3)
        shifts.append(travel.max())
        hinges.append(keys[:, 2].max())
        speed = np.linalg.norm(np.diff(pose.pelvis - base.pelvis, axis=0), axis=-1) * FPS
        # m/s: a min-jerk move peaks at 1.875x its mean speed: SETTLE_MAX_SHIFT (plus the hinge's
        # travel back) over at least SETTLE_MOVE[0] s stays under 0.35 m/s, its mean under 0.1
        assert speed.max() < 1.875 * (SETTLE_MAX_SHIFT + 0.08) / SETTLE_MOVE[0]
        assert speed.mean() < 0.1
    assert max(shifts) > 0.06 and max(hinges) > 0.5 * SETTLE_RANGE["hinge"][0]   # (scaled by liveliness)


def test_settle_leaves_stepping_frames_alone():
    """2.6: frames where a foot moves (and a margin around them) keep the segment's own pelvis."""
    from salad_core.data.procedural.composition import _settle
    from salad_core.data.procedural.footwork import Persona, Stance
    from salad_core.data.procedural.kinematics import body_model
    from salad_core.data.procedural.primitives import build_base
    from salad_core.data.procedural.segment import standing_pose
    from salad_core.data.procedural.kinematics import Pose

    body = body_model("humanml3d")
    persona = Persona.sample(np.random.default_rng(32))
    start = Stance.at((0.0, 0.0), 0.0, persona)
    walk = build_base(Action("walk"), start, persona, body, np.random.default_rng(33))
    stand = standing_pose(walk.end, persona, 80, body, rng=None, idle=False)
    base = Pose.concat([walk.pose, stand])
    pose = base.copy()
    keys = _settle(pose, persona, body, np.random.default_rng(34))
    moving = np.zeros(base.num_frames, dtype=bool)
    for k in range(2):
        d = np.linalg.norm(np.diff(base.ankle[:, k], axis=0), axis=-1) > 1e-6
        moving[1:] |= d
        moving[:-1] |= d
    last = np.flatnonzero(moving).max()
    np.testing.assert_allclose(pose.pelvis[:last + 1], base.pelvis[:last + 1], atol=1e-12)
    assert np.abs(keys[:last + 1]).max() == 0.0
    assert np.abs(pose.pelvis[last + 30:] - base.pelvis[last + 30:]).max() > 0.0 or np.abs(keys).max() == 0.0


def test_trunk_leans_into_arm_gestures_and_its_annotation_says_so():
    """2.6: an arm gesture's trunk lean follows the gesture's arm weight (none before and after),
    the head turns back by about half of it, hand-to-head gestures keep the trunk, and the spine
    is recorded as moved incidentally."""
    from salad_core.data.procedural.composition import LEAN_KINDS, LEAN_RANGE, _lean_into
    from salad_core.data.procedural.footwork import Persona
    from salad_core.data.procedural.kinematics import body_model
    from salad_core.data.procedural.primitives import build_gesture, primitive_parts

    body = body_model("humanml3d")
    persona = Persona.sample(np.random.default_rng(35))
    leans = []
    for i, kind in enumerate(("wave", "stretch", "arms_out", "raise")):
        a = Action(kind, "both" if kind in ("stretch", "arms_out") else "left")
        g = build_gesture(a, persona, body, np.random.default_rng([36, i]))
        spine0, neck0 = g.spine.copy(), g.neck.copy()
        _lean_into(g, a, persona, np.random.default_rng([37, i]))
        d = g.spine - spine0
        w = g.arm_weight.max(1)
        peak = d[int(np.argmax(w))]
        np.testing.assert_allclose(d, w[:, None] * peak[None] / max(w.max(), 1e-9), atol=1e-9)
        np.testing.assert_allclose(d[0], 0.0, atol=1e-9)
        np.testing.assert_allclose(g.neck - neck0, -d * np.array([0.5, 0.6, 0.5]), atol=1e-9)
        for x, (lo, hi) in zip(peak, LEAN_RANGE):
            assert lo * persona.liveliness - 1e-9 <= x <= hi * persona.liveliness + 1e-9
        leans.append(np.abs(peak).max())
        assert "spine" in primitive_parts(a)[1]
    assert max(leans) > 0.1
    sal = Action("salute", "right")
    assert "salute" not in LEAN_KINDS and "scratch_head" not in LEAN_KINDS
    g = build_gesture(sal, persona, body, np.random.default_rng(38))
    spine0 = g.spine.copy()
    _lean_into(g, sal, persona, np.random.default_rng(39))
    np.testing.assert_array_equal(g.spine, spine0)


def test_free_arms_change_carriage_only_while_stepping():
    """2.6: in a plan with an action that needs the arms, a free arm takes or changes its
    carriage only inside a stepping action's core, keeps it through a gesture step and lets it
    go inside the next action's core."""
    from salad_core.data.procedural.composition import _carriage_by_step
    from salad_core.data.procedural.footwork import Persona
    from salad_core.data.procedural.kinematics import body_model

    body = body_model("humanml3d")
    persona = Persona.sample(np.random.default_rng(40))
    plan = Plan((Step(Action("walk")), Step(Action("nod", reps=2)), Step(Action("jump"))))
    changed = 0
    for i in range(12):
        clip = realise(plan, np.random.default_rng([41, i]), body, persona)
        ev = {e.step: e.frames for e in clip.events if e.role == "main"}
        # re-run the carriage alone on a copy of a plain pose of the clip's length
        from salad_core.data.procedural.segment import standing_pose
        from salad_core.data.procedural.footwork import Stance
        n = clip.num_frames
        base = standing_pose(Stance.at((0.0, 0.0), 0.0, persona), persona, n, body, rng=None, idle=False)
        pose = base.copy()
        events = {("main", s): (f, {}) for s, f in ev.items()}
        _carriage_by_step(pose, body, plan, events, np.random.default_rng([42, i]))
        d = np.abs(np.diff(pose.arm - base.arm, axis=0)).max(axis=(1, 2))      # (n-1,) change per frame
        walk0, walk1 = ev[0]
        nod0, nod1 = ev[1]
        jump0, jump1 = ev[2]
        assert d[nod1:jump0].max(initial=0.0) < 1e-12 or nod1 >= jump0
        assert d[max(walk1, 0):jump0].max(initial=0.0) < 1e-12                 # held through the nod
        assert d[:walk0].max(initial=0.0) < 1e-12
        assert d[min(jump1, n - 1):].max(initial=0.0) < 1e-12
        changed += (pose.arm - base.arm)[walk1:jump0].std() > 0.01
    assert changed >= 3
