"""Corpus 2.0's new action primitives (issue 27, item 4): each one moves the body parts its
annotation names more than the others, keeps the feet clean and the bones exact, and does what
its name says (hands on the floor, a knee on the floor, a toe that a pivot turns about, ...)."""
from __future__ import annotations

import numpy as np
import pytest

from salad_core.data.procedural import PRIMITIVES, Action, Plan, Step, part_speeds, phrase_activity, realise
from salad_core.data.procedural.checks import bone_length_error, joint_angles
from salad_core.data.procedural.everyday import FLOOR_WRIST_HEIGHT
from salad_core.data.procedural.floorwork import KNEE_FLOOR
from salad_core.data.procedural.footwork import ANKLE_HEIGHT, TOE_HEIGHT, Persona, Stance
from salad_core.data.procedural.kinematics import ANKLE_RANGE, assemble, body_model
from salad_core.data.procedural.language import RULES
from salad_core.data.procedural.primitives import build_base, build_gesture
from salad_core.data.procedural.reach import arm_controls_for, shoulders
from salad_core.data.procedural.segment import standing_pose
from salad_core.motion import mirror_joints
from salad_core.skeleton import get_skeleton

SK = get_skeleton("humanml3d")
BODY = body_model()
J = {n: i for i, n in enumerate(SK.joint_names)}

#: The primitives corpus 2.0 added (the first 25 are covered by test_procedural).
NEW = ("dance", "sway", "throw", "pick_up", "step_over", "stumble", "kneel", "lie_down", "lie_down_get_up",
       "step_up", "climb_stairs", "pivot", "touch_knee", "guard", "jab_cross", "hook", "uppercut",
       "hands_on_hips", "scratch_head", "salute", "cross_arms", "reach_across", "arm_circles")


def _action(kind: str, k: int = 0) -> Action:
    spec = PRIMITIVES[kind]
    return Action(kind, spec.sides[k % len(spec.sides)], (), spec.reps[0], spec.variants[k % len(spec.variants)])


def _raw(kind: str, seed: int = 0, **kw):
    """(segment or gesture, start stance, persona) built directly, without the realiser's extras."""
    rng = np.random.default_rng(seed)
    persona = Persona.sample(rng)
    stance = Stance.at((0.0, 0.0), 0.0, persona)
    action = Action(kind, **kw) if kw else _action(kind)
    if action.spec.track == "base":
        return build_base(action, stance, persona, BODY, rng), stance, persona
    return build_gesture(action, persona, BODY, rng), stance, persona


def test_inventory_has_forty_primitives_with_language():
    assert len(PRIMITIVES) >= 40
    assert set(NEW) <= set(PRIMITIVES)
    for kind in PRIMITIVES:
        assert RULES.get(kind), kind                           # every primitive can be said


@pytest.mark.parametrize("kind", NEW)
def test_new_primitive_is_clean_and_moves_its_parts(kind):
    clip = realise(Plan((Step(_action(kind, 1)),)), np.random.default_rng([4, NEW.index(kind)]))
    j = clip.joints
    ev = clip.events[0]
    err = bone_length_error(j)
    assert err["max_std"] < 1e-6 and err["max_error"] < 1e-6
    assert j[..., 1].min() > -0.01                             # nothing below the floor
    # a foot joint resting on the floor does not move (planted feet, pivots turn about the toe)
    for joint, h in zip(SK.contact_joints, (ANKLE_HEIGHT, TOE_HEIGHT) * 2):
        y = j[:, joint, 1]
        rest = (y[1:] < h + 5e-4) & (y[:-1] < h + 5e-4)
        step = np.linalg.norm(np.diff(j[:, joint][:, [0, 2]], axis=0), axis=-1)[rest]
        assert step.size == 0 or step.max() < 1e-3, (kind, SK.joint_names[joint], step.max())
    ang = joint_angles(j)
    assert ang["knee"].max() < 150 and ang["elbow"].max() < 160 and ang["knee_bend"].min() > -0.02
    lo, hi = ANKLE_RANGE
    assert lo - 1 <= ang["ankle"].min() and ang["ankle"].max() <= hi + 1
    r = phrase_activity(part_speeds(j), [{"frames": ev.frames, "parts": ev.parts}], [ev.secondary])[0]
    assert r["driven"] > 0.03, (kind, r)
    assert r["ratio_idle"] > 2.0, (kind, r)
    acc = np.linalg.norm(j[2:] - 2 * j[1:-1] + j[:-2], axis=-1).max() * 400.0
    assert acc < 135.0, (kind, acc)                           # m/s^2 at 20 fps; the real data's maximum ~128


def test_generation_is_deterministic():
    for kind in ("dance", "kneel", "jab_cross"):
        a = realise(Plan((Step(_action(kind)),)), np.random.default_rng(3)).joints
        b = realise(Plan((Step(_action(kind)),)), np.random.default_rng(3)).joints
        assert np.array_equal(a, b)


def test_reach_puts_a_wrist_exactly_on_a_world_point():
    rng = np.random.default_rng(0)
    persona = Persona.sample(rng)
    pose = standing_pose(Stance.at((0.3, -0.2), 0.8, persona), persona, 5, BODY)
    pose.pelvis_ypr[:, 1] += np.linspace(0.0, 0.9, 5)          # bending forward while reaching
    pose.spine[:, 0] += 0.3
    for k, name in ((0, "left_wrist"), (1, "right_wrist")):
        target = shoulders(pose, BODY)[:, k] + np.array([-0.1, -0.3, 0.25])
        pose.arm[:, k] = arm_controls_for(pose, BODY, k, target)
        assert np.abs(assemble(pose, BODY)[:, J[name]] - target).max() < 1e-9


def test_pick_up_puts_the_hands_on_the_floor():
    for side, hands in (("right", ["right_wrist"]), ("both", ["left_wrist", "right_wrist"])):
        seg, _, _ = _raw("pick_up", 1, side=side)
        j = assemble(seg.pose, BODY)
        bottom = seg.info["bottom_frame"]
        for name in hands:
            assert j[bottom, J[name], 1] == pytest.approx(FLOOR_WRIST_HEIGHT, abs=1e-6)
        if side == "right":
            assert j[bottom, J["left_wrist"], 1] > FLOOR_WRIST_HEIGHT + 0.1     # the other hand does not
        assert j[-1, J["pelvis"], 1] > 0.85                                   # and stands up again


def test_kneel_puts_the_knee_on_the_floor_and_the_toe_stays():
    seg, start, _ = _raw("kneel", 2, side="left")
    j = assemble(seg.pose, BODY)
    t3, t4 = seg.info["kneel_time"]
    held = slice(int(np.ceil(t3 * 20)), int(np.floor(t4 * 20)))
    assert np.abs(j[held, J["left_knee"], 1] - KNEE_FLOOR).max() < 1e-6
    assert j[held, J["right_knee"], 1].min() > 0.35                          # the front knee is up
    toe = j[held, J["left_foot"]]
    assert np.abs(toe - toe[0]).max() < 1e-9
    assert np.abs(j[-1] - j[0]).max() < 0.02                                  # back to the stand


def test_pivot_turns_about_a_fixed_toe():
    for variant, angle in (("", 90.0), ("around", 180.0)):
        seg, _, _ = _raw("pivot", 0, side="right", variant=variant)
        j = assemble(seg.pose, BODY)
        toe = j[:, J["right_foot"]]
        assert np.abs(toe - toe[0]).max() < 1e-9
        hips = j[:, J["left_hip"]] - j[:, J["right_hip"]]
        yaw = np.degrees(np.unwrap(np.arctan2(-hips[:, 2], hips[:, 0])))
        assert yaw[0] - yaw[-1] == pytest.approx(angle, abs=20.0)             # turned right
        assert j[:, J["right_ankle"], 1].max() > 0.09                         # on the ball: heel up


def test_climbing_stairs_plants_the_feet_on_the_steps():
    seg, _, _ = _raw("climb_stairs", 5)
    j = assemble(seg.pose, BODY)
    top = seg.info["top"]
    assert j[-1, J["left_ankle"], 1] == pytest.approx(ANKLE_HEIGHT + top, abs=1e-6)
    assert j[-1, J["right_ankle"], 1] == pytest.approx(ANKLE_HEIGHT + top, abs=1e-6)
    assert seg.end.ankles[:, 1] == pytest.approx(ANKLE_HEIGHT + top)
    assert j[-1, J["pelvis"], 1] - j[0, J["pelvis"], 1] == pytest.approx(top, abs=0.05)


def test_lying_down_and_getting_up():
    seg, _, _ = _raw("lie_down", 0)
    j = assemble(seg.pose, BODY)
    assert seg.seated and seg.end is None and PRIMITIVES["lie_down"].terminal
    assert j[-1, J["spine3"], 1] < 0.3 and j[-1, J["head"], 1] < 0.4          # lying on the back
    assert j[..., 1].min() > -1e-9
    up, start, _ = _raw("lie_down_get_up", 0)
    ju = assemble(up.pose, BODY)
    assert not up.seated and ju[:, J["spine3"], 1].min() < 0.3
    assert np.abs(ju[-1] - ju[0]).max() < 1e-9                                # back where it started


def test_hands_on_the_body_and_across_it():
    g, _, persona = _raw("hands_on_hips", 0)
    pose = standing_pose(Stance.at((0.0, 0.0), 0.0, persona), persona, g.num_frames, BODY)
    pose.arm, pose.arm_pole = g.arm, g.arm_pole
    j = assemble(pose, BODY)
    mid = g.num_frames // 2
    for side in ("left", "right"):
        assert np.linalg.norm(j[mid, J[f"{side}_wrist"]] - j[mid, J[f"{side}_hip"]]) < 0.15
    for kind, side in (("reach_across", "left"), ("cross_arms", "both")):
        g, _, persona = _raw(kind, 0, side=side)
        pose = standing_pose(Stance.at((0.0, 0.0), 0.0, persona), persona, g.num_frames, BODY)
        pose.arm, pose.arm_pole, pose.spine = g.arm, g.arm_pole, pose.spine + g.spine
        j = assemble(pose, BODY)
        mid = g.num_frames // 2
        # x is the body's left: the left wrist crosses to the right of the midline
        assert j[mid, J["left_wrist"], 0] < j[mid, J["spine3"], 0] - 0.05, kind
    seg, _, _ = _raw("touch_knee", 0, side="right")
    j = assemble(seg.pose, BODY)
    gap = np.linalg.norm(j[:, J["right_wrist"]] - j[:, J["left_knee"]], axis=-1)
    assert gap.min() < 0.1 and j[gap.argmin(), J["left_knee"], 1] > 0.6       # on the raised opposite knee


def test_throw_styles_and_strikes():
    over, _, _ = _raw("throw", 0, side="right")
    under, _, _ = _raw("throw", 0, side="right", variant="underhand")
    jo, ju = assemble(over.pose, BODY), assemble(under.pose, BODY)
    assert jo[:, J["right_wrist"], 1].max() > jo[:, J["head"], 1].max()       # overhand: above the head
    assert ju[:, J["right_wrist"], 1].max() < ju[:, J["right_shoulder"], 1].max()
    speed = np.linalg.norm(np.diff(jo, axis=0), axis=-1) * 20.0
    assert speed[:, J["right_wrist"]].max() > 1.5 * speed[:, J["left_wrist"]].max()
    for kind in ("hook", "uppercut"):
        g, _, _ = _raw(kind, 0, side="left")
        assert np.ptp(g.arm[:, 0], axis=0).max() > 0.8 and np.abs(g.spine[:, 0]).max() > 0.2


def test_step_over_lifts_the_feet_high_and_dance_travels():
    seg, _, _ = _raw("step_over", 0)
    j = assemble(seg.pose, BODY)
    assert max(j[:, J["left_ankle"], 1].max(), j[:, J["right_ankle"], 1].max()) > 0.3
    seg, _, _ = _raw("dance", 0)
    j = assemble(seg.pose, BODY)
    assert np.ptp(j[:, J["pelvis"], 0]) > 0.12                                # side to side
    assert np.abs(j[-1, J["left_ankle"]] - j[0, J["left_ankle"]]).max() < 1e-9


def _built(kind: str, side: str, seed: int) -> np.ndarray:
    """Joints of ``kind`` on ``side`` built with a symmetric performer (no realiser extras)."""
    rng = np.random.default_rng(seed)
    persona = Persona(width=0.1, toe_out=0.2, arm_rest=(0.05, 0.14, 0.3), arm_pole=(0.3, 0.0, -1.0),
                      sway=0.0, head_pitch=0.0, tempo=1.0)
    stance = Stance.at((0.0, 0.0), 0.0, persona)
    action = Action(kind, side)
    if action.spec.track == "base":
        return assemble(build_base(action, stance, persona, BODY, rng).pose, BODY)
    g = build_gesture(action, persona, BODY, rng)
    pose = standing_pose(stance, persona, g.num_frames, BODY)
    pose.arm, pose.arm_pole, pose.spine = g.arm, g.arm_pole, pose.spine + g.spine
    return assemble(pose, BODY)


def test_mirrored_left_action_looks_like_the_right_one():
    for kind in ("jab_cross", "kneel", "throw", "touch_knee"):
        left, right = _built(kind, "left", 7), _built(kind, "right", 7)
        # the skeleton's left and right bones differ by up to ~1 cm, hence the tolerance
        assert np.abs(mirror_joints(left) - right).max() < 0.06, kind
        assert np.abs(left - right).max() > 0.1, kind                         # and the sides differ
