"""Which side a prompt names, which side a motion uses, and whether mirroring would make them agree.

A generator trained on a mirror-symmetric corpus (HumanML3D and salad's corpus hold every motion and
its mirror image with "left" and "right" swapped) may still take the side from its noise rather than
from the text. The mirror image of a motion it made is then an equally likely motion of the
side-swapped prompt, so when a motion uses the other side than the prompt names, its mirror image
(:func:`salad_core.motion.mirror_features`, exact in feature space) is the motion to show. This module
finds the prompt's side cues and measures the motion's side; :class:`KeyMotionPipeline
<salad_core.keymotion.pipeline.KeyMotionPipeline>` uses it as a sampling-time step (``side_check``).

Cues (:func:`side_cues`): every side word (``left``, ``right``, ``leftward(s)``, ``rightward(s)``) gets
a kind from the words around it:

* ``"arm"``: a hand/arm word among the next three words ("his left hand", "the left arm"), or, when
  no body-part word follows, an arm verb in the prompt ("punches with the left");
* ``"leg"``: the same with leg words ("left leg", "right knee") or leg verbs ("kicks with the left");
* ``"turn"``: a turning verb before it ("turns left", "walks in a circle to the left", "spins right");
* ``"lateral"``: a sideways-moving verb before it ("sidesteps to the left", "steps sideways to the right");
* otherwise no cue ("looks to the left": the head's side is not measured).

Measures on joints ``(N, J, 3)`` (+Y up; HumanML3D's left is +X of the first frame's body):

* arm / leg: the log2 ratio of the left and the right limb's activity (summed frame-to-frame motion of
  elbow and wrist relative to the chest, of knee and ankle relative to the pelvis); positive = left;
* turn: the body's total change of heading (degrees, positive = towards its left);
* lateral: the pelvis's displacement along the first frame's left axis (metres).

A cue is *kept* when the measure has its side beyond a margin (``ratio_margin``, ``turn_margin_deg``,
``lateral_margin_m``), *broken* when it has the other side beyond it, and undecided in between.
:func:`should_mirror` says to mirror only when at least one cue is broken and none is kept.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .skeleton import Skeleton, get_skeleton

__all__ = ["SideCue", "side_cues", "side_measure", "cue_verdict", "should_mirror", "KINDS"]

#: Kinds of side cue, in the order they are tried.
KINDS = ("arm", "leg", "turn", "lateral")

_LEFT = {"left", "leftward", "leftwards"}
_RIGHT = {"right", "rightward", "rightwards"}
_ARM_WORDS = {"hand", "hands", "arm", "arms", "wrist", "fist", "fists", "elbow", "shoulder", "palm", "fingers",
              "finger"}
_LEG_WORDS = {"leg", "legs", "foot", "feet", "knee", "knees", "ankle", "toe", "toes", "heel", "thigh", "shin"}
_ARM_VERBS = {"punch", "punches", "punching", "punched", "wave", "waves", "waving", "waved", "throw", "throws",
              "throwing", "threw", "reach", "reaches", "reaching", "swing", "swings", "swinging"}
_LEG_VERBS = {"kick", "kicks", "kicking", "kicked", "stomp", "stomps", "stomping", "hop", "hops", "hopping"}
_TURN_VERBS = {"turn", "turns", "turning", "turned", "spin", "spins", "spinning", "spun", "rotate", "rotates",
               "rotating", "circle", "circles", "circling", "pivot", "pivots", "pivoting"}
_LATERAL_WORDS = {"sidestep", "sidesteps", "sidestepping", "sideways", "sidewards", "strafe", "strafes",
                  "shuffle", "shuffles", "shuffling", "side"}

_WORD = re.compile(r"[a-z]+")


@dataclass(frozen=True)
class SideCue:
    """A side the prompt names for one kind of measure: ``kind`` in :data:`KINDS`, ``side`` +1 left / -1 right."""

    kind: str
    side: int
    word_index: int


def side_cues(prompt: str) -> list[SideCue]:
    """The side cues of a prompt (see the module docstring); empty when it names no measurable side."""
    if not isinstance(prompt, str):
        raise TypeError(f"prompt must be a string, got {type(prompt).__name__}")
    words = _WORD.findall(prompt.lower())
    cues = []
    for i, w in enumerate(words):
        side = 1 if w in _LEFT else -1 if w in _RIGHT else 0
        if not side:
            continue
        after, before = set(words[i + 1:i + 4]), set(words[max(0, i - 6):i])
        kind = None
        if after & _ARM_WORDS:
            kind = "arm"
        elif after & _LEG_WORDS:
            kind = "leg"
        elif before & _TURN_VERBS:
            kind = "turn"
        elif before & _LATERAL_WORDS:
            kind = "lateral"
        elif before & _ARM_VERBS:
            kind = "arm"
        elif before & _LEG_VERBS:
            kind = "leg"
        if kind is not None:
            cues.append(SideCue(kind, side, i))
    return cues


def _joint(sk: Skeleton, name: str) -> int:
    try:
        return sk.joint_names.index(name)
    except ValueError:
        raise ValueError(f"skeleton {sk.name!r} has no joint {name!r}, which the side check needs") from None


def _activity(x: np.ndarray, joints: Sequence[int], anchor: int) -> float:
    rel = x[:, list(joints)] - x[:, anchor:anchor + 1]
    return float(np.linalg.norm(np.diff(rel, axis=0), axis=-1).sum())


def _heading(x: np.ndarray, sk: Skeleton) -> np.ndarray:
    """Per-frame yaw (radians) of the body's forward axis, from the hips' across vector."""
    across = x[:, _joint(sk, "left_hip")] - x[:, _joint(sk, "right_hip")]
    forward = np.cross(across, np.array([0.0, 1.0, 0.0]))               # left x up... -> forward (+Z at rest)
    return np.arctan2(forward[:, 0], forward[:, 2])


def side_measure(joints, kind: str, skeleton: str | Skeleton = "humanml3d") -> float:
    """The motion's side for one kind of cue: positive = left (see the module docstring for units).

    Parameters
    ----------
    joints : array ``(N, J, 3)``
    kind : one of :data:`KINDS`
    """
    sk = get_skeleton(skeleton)
    x = np.asarray(joints, dtype=np.float64)
    if x.ndim != 3 or x.shape[1:] != (sk.num_joints, 3) or x.shape[0] < 2:
        raise ValueError(f"joints must have shape (N >= 2, {sk.num_joints}, 3), got {x.shape}")
    if kind in ("arm", "leg"):
        if kind == "arm":
            anchor = _joint(sk, "spine3")
            left = [_joint(sk, "left_elbow"), _joint(sk, "left_wrist")]
            right = [_joint(sk, "right_elbow"), _joint(sk, "right_wrist")]
        else:
            anchor = _joint(sk, "pelvis")
            left = [_joint(sk, "left_knee"), _joint(sk, "left_ankle")]
            right = [_joint(sk, "right_knee"), _joint(sk, "right_ankle")]
        a, b = _activity(x, left, anchor), _activity(x, right, anchor)
        return float(np.log2((a + 1e-6) / (b + 1e-6)))
    if kind == "turn":
        yaw = np.unwrap(_heading(x, sk))
        return float(np.degrees(yaw[-1] - yaw[0]))
    if kind == "lateral":
        yaw0 = _heading(x[:1], sk)[0]
        left_axis = np.array([np.cos(yaw0), 0.0, -np.sin(yaw0)])        # forward (sin, 0, cos) turned a quarter left
        return float((x[-1, 0] - x[0, 0]) @ left_axis)
    raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")


#: Margins beyond which a measure has a side (log2 ratio, degrees, metres).
MARGINS = {"arm": 0.5, "leg": 0.5, "turn": 30.0, "lateral": 0.1}


def cue_verdict(cue: SideCue, joints, skeleton: str | Skeleton = "humanml3d") -> int:
    """+1 when the motion keeps the cue's side beyond its margin, -1 when it has the other side, 0 between."""
    m = side_measure(joints, cue.kind, skeleton)
    if m * cue.side > MARGINS[cue.kind]:
        return 1
    if m * cue.side < -MARGINS[cue.kind]:
        return -1
    return 0


def should_mirror(prompt: str, joints, skeleton: str | Skeleton = "humanml3d") -> bool:
    """True when the motion breaks at least one of the prompt's side cues and keeps none of them."""
    verdicts = [cue_verdict(c, joints, skeleton) for c in side_cues(prompt)]
    return bool(verdicts) and min(verdicts) < 0 and max(verdicts) <= 0
