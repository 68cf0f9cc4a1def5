"""The physical-plausibility benchmark: a fixed list of prompts with per-action checks, the reference
rows of real motions, and the runner that generates, measures and reports.

Prompts are in the procedural corpus's language (every one is said by the corpus's phrase rules, which
``tests/test_physics.py`` checks) and cover its actions: locomotion (walk, run, jog, march, backward,
sidestep, circle, turn, spin), jumps (jump, high, hop, forward, jumping jacks), legs (kick, knee lift),
whole body (squat, sit, bow), arms (wave, raise, punch, clap, stretch, arms out), head (nod, shake,
look) and two combinations.

Each prompt carries checks of what the prompt asks for, measured on the generated joints: a walk
travels (forward displacement, m), a named limb is the one that moves (activity of the named arm or
leg over the other, :func:`salad_core.eval.physics.limb_activity`), a jump's pelvis rise is within the
range of the corpus's jumps, sitting lowers the pelvis, a turn turns the hips the named way, etc.
Thresholds were set from the corpus's own single-action clips (train split of a small corpus built
with ``salad corpus build --out /tmp/h4_corpus --size small --seed 0`` at commit ``bb0d404``; the
values in the comments are the minimum over those clips), below that minimum (mostly at a half to
two thirds of it), since generated motions are 6 s long and need not look like one corpus clip;
``tests/test_physics.py`` checks that the corpus's own clips pass them.

A second set, :data:`GENERAL_PROMPTS` (13), asks for the general-motion set's actions, said in the
words of its captions (``salad_core.data.procedural.general_language``: ``GENERAL_ACTIONS``' example prompts and
the phrase rules) or of the action corpus's (kneeling on a knee, lying down, crawling, climbing stairs): a
cartwheel (and one to the left), a handstand, a forward roll (two wordings), a backflip, lying down on the back,
kneeling on the left and on the right knee, crawling forward on all fours, climbing stairs (two wordings) and
getting up from the floor. Their checks use measures of :mod:`salad_core.eval.physics` written for them: the head
below the pelvis, upside down on the hands, the trunk's head-over-heels turn, every joint off the floor, the
pelvis height at the end, the chest facing up, the named knee on the floor with the other foot planted, both hands
near the floor and forward travel, and the pelvis rise with the feet planted higher step by step
(:func:`~salad_core.eval.physics.planted_rise`: a figure that rises with nothing to stand on plants no foot up
there). Their thresholds come the same way from the corpus's single-action clips of those actions
(:func:`corpus_windows`, :func:`corpus_check_values`: a general clip on its phrase's frames and 0.5 s after, since
the general set's windows carry unsaid movement around the step), on the seed-0 corpus built with
``salad corpus build --size default --seed 0 --with-general 2000`` at commit ``d4fdbe1`` (its action clips are
those of corpus 2.7); ``tests/test_physics_general.py`` checks that the clips which set them pass. The general
prompts are a set of their own (``salad eval --physics --prompt-set general``; "core", the default, is
:data:`PROMPTS` alone, so every record stays comparable), and the report adds the seeds whose motion passed every
check of its prompt (:func:`general_pass_rows`) and the general-motion target: each prompt of cartwheel, roll, lie
down, kneel, crawl and climb stairs in at least 80 % of its seeds.

The jump-height ranges are measured, not chosen: :data:`REFERENCE_RANGES` holds the range of the pelvis
rise (:func:`salad_core.eval.physics.measure_motion`'s ``jump_rise_m``) over the corpus's clips whose
every caption is a single jump phrase (and over its jumping-jacks clips), measured with
:func:`corpus_reference_ranges` on that corpus (all splits). The runner re-measures them on the
corpus it is given when that corpus has annotations, and says which it used.

The runner also reports the field's measures (:mod:`salad_core.eval.physics`: GMD's skating ratio, PhysDiff's
joint-based Penetrate / Float / Skate, stance sliding apart from low swings, floating during stance,
per-segment flight fits, p99 instead of single worst frames), the deviation of the shown joints from
the raw position read of the same features (:func:`~salad_core.eval.physics.recovery_deviation`; a
generator returns :class:`Generated` with both), a per-prompt breakdown and a reference row of real
motion capture (:func:`real_capture_row`: HumanML3D clip 012314, shipped in
``salad_core/eval/reference``, and pybullet's DeepMimic clips when pybullet is installed), against which
:func:`targets` states the "[field]" targets. The real clips are evaluation data only: no threshold was
set on them.
"""
from __future__ import annotations

import contextlib
import functools
import json
import math
import os
import re
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Mapping, Sequence, Union

import numpy as np

from ..skeleton import Skeleton, get_skeleton
from . import physics as ph

__all__ = ["Check", "CheckResult", "BenchmarkPrompt", "PROMPTS", "GENERAL_PROMPTS", "PROMPT_SETS", "PROMPT_SET_GROUPS",
           "prompt_set", "corpus_windows", "corpus_check_values", "general_pass_rows", "GENERAL_TARGET_ACTIONS",
           "GENERAL_PASS_SHARE", "MEASURES", "REFERENCE_RANGES",
           "BenchSettings", "Generator", "corpus_reference_ranges", "corpus_reference_rises", "rise_ranges",
           "load_joints", "measure_clips",
           "caption_diversity", "reference_rows", "run_benchmark", "benchmark_markdown", "targets",
           "saved_generators", "Generated", "PROMPT_SUMMARY", "REAL_CAPTURE_DEEPMIMIC", "humanml3d_reference_joints",
           "real_capture_clips", "real_capture_row"]


@dataclass(frozen=True)
class Generated:
    """What a generator made of one batch: the joints it shows (measured) and, optionally, the raw
    position read of the same features (compared with them by
    :func:`~salad_core.eval.physics.recovery_deviation`), one ``(N_b, J, 3)`` array per prompt each."""

    shown: Sequence[np.ndarray]
    raw: Sequence[np.ndarray] | None = None


#: A generator: ``(prompts, lengths, seed) -> list of joints (N_b, J, 3)`` (one per prompt), or a
#: :class:`Generated` with the raw joints beside the shown ones.
Generator = Callable[[list[str], list[int], int], Union[list[np.ndarray], Generated]]

SIDES = ("left", "right")


# ------------------------------------------------------------------------------------ measures
def _other(side: str) -> str:
    return "right" if side == "left" else "left"


def _need_side(side: str | None, what: str) -> str:
    if side not in SIDES:
        raise ValueError(f"measure {what!r} needs side 'left' or 'right', got {side!r}")
    return side


def _joint(sk: Skeleton, name: str) -> int:
    return sk.joint_names.index(name)


def _seconds(sk: Skeleton, s: float) -> int:
    return max(1, int(round(s * sk.fps)))


def _turn(x, sk, side):
    yaw = ph.heading_yaw(x, sk)
    return math.degrees(yaw[-1] - yaw[0])


def _pelvis_drop(x, sk, side):
    return ph.standing_height(x, sk) - float(x[:, 0, 1].min())


def _pelvis_end_drop(x, sk, side):
    return ph.standing_height(x, sk) - float(x[-_seconds(sk, 0.5):, 0, 1].mean())


def _head_drop(x, sk, side):
    head = x[:, _joint(sk, "head"), 1]
    return float(head[:_seconds(sk, 0.5)].mean() - head.min())


def _arm_ratio(x, sk, side):
    s = _need_side(side, "arm_ratio")
    a = ph.limb_activity(x, sk)
    return a[f"{s}_arm"] / max(a[f"{_other(s)}_arm"], 1e-6)


def _leg_ratio(x, sk, side):
    s = _need_side(side, "leg_ratio")
    a = ph.limb_activity(x, sk)
    return a[f"{s}_leg"] / max(a[f"{_other(s)}_leg"], 1e-6)


def _arms_min(x, sk, side):
    a = ph.limb_activity(x, sk)
    return min(a["left_arm"], a["right_arm"])


def _arms_balance(x, sk, side):
    a = ph.limb_activity(x, sk)
    return min(a["left_arm"], a["right_arm"]) / max(a["left_arm"], a["right_arm"], 1e-6)


def _wrist_over_head(x, sk, side):
    s = _need_side(side, "wrist_over_head")
    return float((x[:, _joint(sk, f"{s}_wrist"), 1] - x[:, _joint(sk, "head"), 1]).max())


def _wrist_lead(x, sk, side):
    s = _need_side(side, "wrist_lead")
    return float((x[:, _joint(sk, f"{s}_wrist"), 1] - x[:, _joint(sk, f"{_other(s)}_wrist"), 1]).max())


def _knee_rise(x, sk, side):
    s = _need_side(side, "knee_rise")
    rel = x[:, _joint(sk, f"{s}_knee"), 1] - x[:, 0, 1]
    return float(rel.max() - rel[0])


# general-motion measures (GENERAL_PROMPTS): heights are above the floor (y = 0, where HumanML3D and the corpus put it)
def _end(sk) -> slice:
    return slice(-_seconds(sk, 0.5), None)


def _start(sk) -> slice:
    return slice(None, _seconds(sk, 0.5))


def _pelvis_rise(x, sk, side):
    return float(x[_end(sk), 0, 1].mean() - x[_start(sk), 0, 1].mean())


def _chest_up_end(x, sk, side):
    return float(ph.trunk_axes(x, sk)[2][_end(sk), 1].mean())


def _kneel_frames(x, sk, side):
    return float(ph.kneel_frames(x, _need_side(side, "kneel_frames"), sk).sum())


#: The lowest joint's height (m) above which the whole body is off the floor: 3 cm above the lowest a joint
#: rests (a flat foot's toe joint, 1.2 cm), as the corpus's captions measure it (``general_language.airborne``).
AIRBORNE_M = 0.042


#: Per-prompt measures: name -> (function(joints, skeleton, side) -> float, unit, what it is).
MEASURES: dict[str, tuple[Callable, str, str]] = {
    "forward_m": (lambda x, sk, s: ph.root_travel(x, sk)["forward"], "m",
                  "pelvis displacement along the frame-0 heading"),
    "left_m": (lambda x, sk, s: ph.root_travel(x, sk)["left"], "m",
               "pelvis displacement to the frame-0 left"),
    "displacement_m": (lambda x, sk, s: ph.root_travel(x, sk)["displacement"], "m",
                       "pelvis ground displacement, start to end"),
    "sideways_m": (lambda x, sk, s: abs(ph.root_travel(x, sk)["left"]), "m",
                   "pelvis displacement across the frame-0 heading, either way"),
    "turn_deg": (_turn, "deg", "heading change of the hips, start to end (positive = to the left)"),
    "abs_turn_deg": (lambda x, sk, s: abs(_turn(x, sk, s)), "deg", "absolute heading change of the hips"),
    "jump_rise_m": (lambda x, sk, s: float(x[:, 0, 1].max()) - ph.standing_height(x, sk), "m",
                    "pelvis apex above its standing height"),
    "flight_frames": (lambda x, sk, s: float(ph.flight_frames(x, sk).sum()), "frames",
                      "frames with both feet off the ground"),
    "pelvis_drop_m": (_pelvis_drop, "m", "standing pelvis height minus its lowest"),
    "pelvis_end_drop_m": (_pelvis_end_drop, "m", "standing pelvis height minus its mean over the last 0.5 s"),
    "head_drop_m": (_head_drop, "m", "head height over the first 0.5 s minus its lowest"),
    "arm_ratio": (_arm_ratio, "x", "activity of the named arm over the other arm's"),
    "leg_ratio": (_leg_ratio, "x", "activity of the named leg over the other leg's"),
    "arms_min_ms": (_arms_min, "m/s", "activity of the less active arm"),
    "arms_balance": (_arms_balance, "x", "activity of the less active arm over the more active one"),
    "wrist_over_head_m": (_wrist_over_head, "m", "highest the named wrist gets above the head joint"),
    "wrist_lead_m": (_wrist_lead, "m", "highest the named wrist gets above the other wrist"),
    "knee_rise_m": (_knee_rise, "m", "rise of the named knee relative to the pelvis"),
    "head_ms": (lambda x, sk, s: ph.limb_activity(x, sk)["head"], "m/s", "head activity relative to the neck"),
    "stride_m": (lambda x, sk, s: float(np.median(v)) if (v := ph.strides(x, sk)).size else 0.0, "m",
                 "median distance a foot travels from lift-off to touch-down (0: the feet never step)"),
    # ---- general motions (GENERAL_PROMPTS)
    "inverted_frames": (lambda x, sk, s: float(ph.inverted_frames(x, sk).sum()), "frames",
                        "frames with the head below the pelvis"),
    "on_hands_frames": (lambda x, sk, s: float(ph.on_hands_frames(x, sk).sum()), "frames",
                        "frames upside down on the hands (head below the pelvis, a wrist or elbow the lowest joint)"),
    "pitch_deg": (lambda x, sk, s: ph.pitch_rotation(x, sk), "deg",
                  "head-over-heels turn of the trunk, summed frame to frame (positive = forwards)"),
    "airborne_frames": (lambda x, sk, s: float((x[..., 1].min(axis=1) > AIRBORNE_M).sum()), "frames",
                        f"frames with every joint off the floor (the lowest above {AIRBORNE_M} m)"),
    "pelvis_min_m": (lambda x, sk, s: float(x[:, 0, 1].min()), "m", "lowest pelvis height above the floor"),
    "pelvis_end_m": (lambda x, sk, s: float(x[_end(sk), 0, 1].mean()), "m",
                     "pelvis height above the floor, mean over the last 0.5 s"),
    "pelvis_rise_m": (_pelvis_rise, "m", "pelvis height over the last 0.5 s minus over the first 0.5 s"),
    "chest_up_end": (_chest_up_end, "x", "height component of the chest's facing over the last 0.5 s "
                                         "(1: lying on the back, -1: face down)"),
    "kneel_frames": (_kneel_frames, "frames", "frames kneeling on the named knee (it within 0.15 m of the floor, "
                                              "the other knee 0.1 m higher, the other foot within 0.12 m)"),
    "hands_down_share": (lambda x, sk, s: float(ph.hands_down_frames(x, sk).mean()), "x",
                         "share of frames with both wrists within 0.2 m of the floor"),
    "planted_rise_m": (lambda x, sk, s: ph.planted_rise(x, sk), "m",
                       "height of the feet's last plant minus the lower toe's at the start (a plant: a toe still "
                       "for >= 3 frames, at any height)"),
}

#: Ranges (m) of the pelvis rise measured on the corpus (see the module docstring):
#: ``corpus_reference_ranges(root, splits=("train", "val", "test"))`` on the small corpus, seed 0,
#: generator version 2.1 (commit 8ed532e; "springs up" counted as a jump). Generator 1.0 gave
#: jumps 0.131-0.47 m and jumping jacks 0.083-0.124 m; 2.1's high jumps rise up to 0.49 m.
REFERENCE_RANGES: dict[str, tuple[float, float]] = {
    "jump_rise_m": (0.209, 0.493),
    "jumping_jacks_rise_m": (0.078, 0.108),
}


@dataclass(frozen=True)
class CheckResult:
    """One check on one motion: the measured value, the bounds and whether it passed."""

    check: str
    value: float
    lo: float | None
    hi: float | None
    passed: bool


@dataclass(frozen=True)
class Check:
    """A condition ``lo <= measure(joints) <= hi`` on one motion.

    ``reference`` names a range of :data:`REFERENCE_RANGES` (or of the ranges given to
    :meth:`evaluate`) to use as the bounds instead of ``lo`` / ``hi``; ``side`` is the limb the
    prompt names, for the measures that compare sides.
    """

    measure: str                       # key of MEASURES
    lo: float | None = None            # lower bound (inclusive), None: none
    hi: float | None = None            # upper bound (inclusive), None: none
    side: str | None = None            # "left" / "right" for side measures
    reference: str | None = None       # key of the reference ranges, replaces lo / hi

    def __post_init__(self) -> None:
        if self.measure not in MEASURES:
            raise ValueError(f"unknown measure {self.measure!r}; known: {', '.join(MEASURES)}")
        if self.side not in (None, *SIDES):
            raise ValueError(f"side must be None, 'left' or 'right', got {self.side!r}")
        if self.reference is not None:
            if self.lo is not None or self.hi is not None:
                raise ValueError(f"check {self.measure}: give either reference={self.reference!r} or lo/hi, not both")
        elif self.lo is None and self.hi is None:
            raise ValueError(f"check {self.measure}: give lo, hi or a reference range")
        if self.lo is not None and self.hi is not None and self.lo > self.hi:
            raise ValueError(f"check {self.measure}: lo={self.lo} is above hi={self.hi}")

    def bounds(self, references: Mapping[str, tuple[float, float]] = REFERENCE_RANGES
               ) -> tuple[float | None, float | None]:
        if self.reference is None:
            return self.lo, self.hi
        if self.reference not in references:
            raise KeyError(f"check {self.measure}: no reference range {self.reference!r}; have {sorted(references)}")
        lo, hi = references[self.reference]
        return float(lo), float(hi)

    @property
    def name(self) -> str:
        return self.measure + (f"[{self.side}]" if self.side else "")

    def describe(self, references: Mapping[str, tuple[float, float]] = REFERENCE_RANGES) -> str:
        lo, hi = self.bounds(references)
        unit = MEASURES[self.measure][1]
        if lo is not None and hi is not None:
            return f"{lo:g} <= {self.name} <= {hi:g} {unit}"
        return f"{self.name} >= {lo:g} {unit}" if lo is not None else f"{self.name} <= {hi:g} {unit}"

    def evaluate(self, joints, skeleton: str | Skeleton = "humanml3d",
                 references: Mapping[str, tuple[float, float]] = REFERENCE_RANGES) -> CheckResult:
        sk = get_skeleton(skeleton)
        x = np.asarray(joints, dtype=np.float64)
        value = float(MEASURES[self.measure][0](x, sk, self.side))
        lo, hi = self.bounds(references)
        ok = math.isfinite(value) and (lo is None or value >= lo) and (hi is None or value <= hi)
        return CheckResult(self.describe(references), value, lo, hi, bool(ok))


@dataclass(frozen=True)
class BenchmarkPrompt:
    """A benchmark prompt, the corpus action it asks for and its checks."""

    text: str
    action: str                      # corpus primitive(s), for grouping
    checks: tuple[Check, ...]
    length: int = 120                # frames (6 s at 20 fps)
    group: str = "core"              # the prompt set: "core" (PROMPTS) or "general" (GENERAL_PROMPTS)
    #: the corpus captions that say what the prompt says (:func:`corpus_windows`): alternatives, each one tuple per
    #: phrase of the names it may have: general-motion step actions (``general_language.GENERAL_RULES``) and
    #: action-corpus primitives
    corpus: tuple[tuple[tuple[str, ...], ...], ...] = ()

    def __post_init__(self) -> None:
        if not self.text.strip():
            raise ValueError("a benchmark prompt needs text")
        if not self.checks:
            raise ValueError(f"prompt {self.text!r} has no checks")
        if self.group not in PROMPT_SET_GROUPS:
            raise ValueError(f"prompt {self.text!r}: group must be one of {PROMPT_SET_GROUPS}, got {self.group!r}")


#: The groups a benchmark prompt belongs to (``BenchmarkPrompt.group``).
PROMPT_SET_GROUPS = ("core", "general")


def _P(text: str, action: str, *checks: Check, length: int = 120) -> BenchmarkPrompt:
    return BenchmarkPrompt(text, action, tuple(checks), length)


_C = Check
_JUMP = (_C("jump_rise_m", reference="jump_rise_m"), _C("flight_frames", lo=2))   # corpus jumps: >= 4 frames
# Limb checks: in the corpus the named arm moves 2^6-2^8 times more than the other, the named leg
# 2^2.4 (knee lift) to 2^3.5 (kick) times; a ratio of 2 asks that the named limb clearly leads.
_ARM = {s: _C("arm_ratio", lo=2.0, side=s) for s in SIDES}
_LEG = {s: _C("leg_ratio", lo=2.0, side=s) for s in SIDES}
_BOTH_ARMS = _C("arms_balance", lo=0.5)                                            # corpus >= 0.88
# Walking makes steps: the generators' target stride (corpus minima: walk 0.83 m, slow walk 0.50 m, march 0.60 m,
# jog 1.11 m, run 1.46 m)
_STRIDE = _C("stride_m", lo=0.4)

#: The fixed benchmark prompts (41); corpus minima over single-action clips in the comments.
PROMPTS: tuple[BenchmarkPrompt, ...] = (
    _P("a person walks forward", "walk", _C("forward_m", lo=1.0), _STRIDE),              # 1.74 m
    _P("a man walks slowly", "walk", _C("forward_m", lo=0.5), _STRIDE),                  # 1.05 m
    _P("a person runs forward", "run", _C("forward_m", lo=2.0), _STRIDE),                # 3.01 m
    _P("a woman jogs forward", "jog", _C("forward_m", lo=1.5), _STRIDE),                 # 2.44 m
    _P("someone jogs in place", "jog", _C("displacement_m", hi=0.3)),                    # 0.00 m
    _P("a man marches forward", "march", _C("forward_m", lo=0.8), _STRIDE),              # 1.21 m
    _P("a person walks backward", "walk_backward", _C("forward_m", hi=-0.4)),            # -0.56 m
    _P("a man sidesteps to the left", "sidestep", _C("left_m", lo=0.3)),                 # 0.39 m
    _P("a person steps sideways to the right", "sidestep", _C("left_m", hi=-0.3)),
    _P("a man walks in a circle to the left", "circle", _C("turn_deg", lo=180.0)),      # 331 deg
    _P("a person turns left", "turn", _C("turn_deg", lo=60.0)),                          # 83 deg
    _P("a man turns to the right", "turn", _C("turn_deg", hi=-60.0)),
    _P("a woman turns around", "turn", _C("abs_turn_deg", lo=135.0)),                    # 180 deg
    _P("someone spins around", "spin", _C("abs_turn_deg", lo=270.0)),                    # 360 deg
    _P("a person jumps", "jump", *_JUMP),
    _P("a man is jumping high", "jump", *_JUMP),
    _P("a person hops in place", "jump", *_JUMP),
    _P("a man jumps forward", "jump", *_JUMP, _C("forward_m", lo=0.3)),                 # 0.51 m
    _P("a person does jumping jacks", "jumping_jacks", _C("jump_rise_m", reference="jumping_jacks_rise_m"),
       _C("wrist_over_head_m", lo=0.1, side="left"), _C("wrist_over_head_m", lo=0.1, side="right")),  # 0.29 m
    _P("a man kicks with his left leg", "kick", _LEG["left"]),
    _P("a person kicks his right leg forward", "kick", _LEG["right"]),
    _P("a woman lifts her left knee", "knee_lift", _LEG["left"], _C("knee_rise_m", lo=0.15, side="left")),  # 0.29 m
    _P("a man raises his right knee high", "knee_lift", _LEG["right"], _C("knee_rise_m", lo=0.15, side="right")),
    _P("a person squats down", "squat", _C("pelvis_drop_m", lo=0.2)),                    # 0.27 m
    _P("a man sits on the ground", "sit", _C("pelvis_end_drop_m", lo=0.5)),              # 0.77 m
    _P("a person bows", "bow", _C("head_drop_m", lo=0.1), _C("pelvis_drop_m", hi=0.15)),  # 0.17 m; 0.00 m
    _P("a man waves his right hand", "wave", _ARM["right"], _C("wrist_over_head_m", lo=0.0, side="right")),  # 0.10 m
    _P("a woman waves with her left hand", "wave", _ARM["left"]),
    _P("a person raises his left arm", "raise", _ARM["left"]),
    _P("a man raises his right hand up high", "raise", _ARM["right"],
       _C("wrist_over_head_m", lo=0.1, side="right")),                                   # 0.31 m
    _P("a person raises both arms", "raise", _C("arms_min_ms", lo=0.2), _BOTH_ARMS),     # 0.49 m/s
    _P("a man punches with his left hand", "punch", _ARM["left"]),
    _P("someone punches forward with their right fist", "punch", _ARM["right"]),
    _P("a person claps his hands", "clap", _C("arms_min_ms", lo=0.3), _BOTH_ARMS),       # 0.60 m/s
    _P("the person stretches their arms forward", "stretch", _C("arms_min_ms", lo=0.15), _BOTH_ARMS),  # 0.32
    _P("a woman spreads her arms wide", "arms_out", _C("arms_min_ms", lo=0.15), _BOTH_ARMS),  # 0.33 m/s
    _P("a man nods his head", "nod", _C("head_ms", lo=0.04)),                            # 0.08 m/s
    _P("a person shakes his head", "shake_head", _C("head_ms", lo=0.06)),                # 0.12 m/s
    _P("a man looks to the left", "look", _C("head_ms", lo=0.02)),                       # 0.04 m/s
    _P("a man is walking while raising his left hand up high", "walk+raise", _C("forward_m", lo=1.0),
       _C("wrist_lead_m", lo=0.3, side="left")),
    _P("a person walks forward while waving his right hand", "walk+wave", _C("forward_m", lo=1.0),
       _C("wrist_lead_m", lo=0.3, side="right")),
)


def _G(text: str, action: str, corpus: tuple[tuple[tuple[str, ...], ...], ...], *checks: Check, length: int = 120
       ) -> BenchmarkPrompt:
    return BenchmarkPrompt(text, action, tuple(checks), length, group="general", corpus=corpus)


_CARTWHEEL = (("cartwheel",),)
_ROLL = (("forward_roll",),)
_KNEEL_ONE = (("kneel_one", "kneeling_one", "kneel"),)
_CRAWL = (("crawl_forward", "crawl_forward_knees", "crawl"),)
_STAIRS = (("climb_stairs",),)
_LIE_GET_UP = (("lying_back", "lie_down_back"), ("get_up", "stand_up"))

#: The general-motion prompts (13: cartwheel, roll, lie down, kneel, crawl, climb stairs, and a
#: handstand, a backflip, getting up). Words from ``general_language.GENERAL_ACTIONS``' example prompts and the
#: corpus's phrase rules (each prompt says one of the corpus's captions' phrases). Thresholds from the corpus's
#: own single-action clips, ``corpus_check_values(root, prompt)`` (the module docstring has the corpus; clips:
#: cartwheel 42, to the left 4, handstand 34, forward roll 24, backflip 12, lying down 18, kneeling 15 a side,
#: crawling 18, stairs 6, lying and getting up 14); the minima (maxima for upper bounds) over those clips in the
#: comments, the thresholds mostly at a half to two thirds of them.
GENERAL_PROMPTS: tuple[BenchmarkPrompt, ...] = (
    # corpus cartwheels come with a run-up and travel 3.9-11 m sideways; a standing cartwheel covers about 1.5 m
    _G("a person does a cartwheel", "cartwheel", (_CARTWHEEL,),
       _C("inverted_frames", lo=4), _C("on_hands_frames", lo=3), _C("sideways_m", lo=1.0)),   # 7; 6 frames; 3.91 m
    _G("someone does a cartwheel to the left", "cartwheel", (_CARTWHEEL,),
       _C("inverted_frames", lo=4), _C("on_hands_frames", lo=3), _C("left_m", lo=1.0)),        # 12; 8; 3.97 m
    _G("a person does a handstand", "handstand", ((("handstand",),),), _C("on_hands_frames", lo=10)),   # 17 frames
    _G("a person does a forward roll", "forward_roll", (_ROLL,),
       _C("pitch_deg", lo=180.0), _C("inverted_frames", lo=4)),                                  # 272 deg; 6 frames
    _G("someone rolls forward on the floor", "forward_roll", (_ROLL,),
       _C("pitch_deg", lo=180.0), _C("inverted_frames", lo=4)),
    _G("a person does a backflip", "flip", ((("back_flip",),),),
       _C("pitch_deg", hi=-180.0), _C("airborne_frames", lo=6)),                                # -331 deg; 13 frames
    # lying: the corpus's posture names call a pelvis below 0.35 m lying (general_language.measured_postures)
    _G("a person lies down on their back", "lie_down", ((("lie_down_back", "lie_down"),),),
       _C("pelvis_end_m", hi=0.35), _C("chest_up_end", lo=0.5)),                                 # 0.31 m; 0.77
    _G("a man kneels on his left knee", "kneel", (_KNEEL_ONE,), _C("kneel_frames", lo=4, side="left")),     # 6 frames
    _G("a woman kneels down on her right knee", "kneel", (_KNEEL_ONE,), _C("kneel_frames", lo=4, side="right")),
    _G("a woman crawls forward on all fours", "crawl", (_CRAWL,),
       _C("hands_down_share", lo=0.5), _C("forward_m", lo=0.2)),                                 # 1.0; 0.39 m
    _G("a person climbs the stairs", "climb_stairs", (_STAIRS,),
       _C("pelvis_rise_m", lo=0.3), _C("planted_rise_m", lo=0.3)),                               # 0.48 m; 0.51 m
    _G("a man walks up a flight of stairs", "climb_stairs", (_STAIRS,),
       _C("pelvis_rise_m", lo=0.3), _C("planted_rise_m", lo=0.3)),
    _G("a person lies on the floor and gets up", "get_up", (_LIE_GET_UP, (("lie_down_get_up",),)),
       _C("pelvis_min_m", hi=0.35), _C("pelvis_end_m", lo=0.6)),                                 # 0.15 m; 0.89 m
)

#: The prompt sets of ``salad eval --physics --prompt-set``: "core" (the 41 of :data:`PROMPTS`, the default, so
#: records stay comparable), "general" (:data:`GENERAL_PROMPTS`) and "all" (both, core first).
PROMPT_SETS: dict[str, tuple[BenchmarkPrompt, ...]] = {
    "core": PROMPTS, "general": GENERAL_PROMPTS, "all": PROMPTS + GENERAL_PROMPTS}


def prompt_set(name: str) -> tuple[BenchmarkPrompt, ...]:
    """The prompts of a set of :data:`PROMPT_SETS` ("core", "general" or "all")."""
    if name not in PROMPT_SETS:
        raise ValueError(f"unknown prompt set {name!r}; choose one of {', '.join(PROMPT_SETS)}")
    return PROMPT_SETS[name]


# ------------------------------------------------------------------------------------ corpus references
def _prompt_sides(prompt: BenchmarkPrompt, n: int) -> list[str | None]:
    """The side each phrase of ``prompt`` names (None: none), read with whichever of the corpus's parsers
    reads it in ``n`` phrases (no sides when neither does)."""
    from ..data.procedural.general_language import parse_general_prompt
    from ..data.procedural.language import parse_prompt

    for parsed in (parse_general_prompt(prompt.text), parse_prompt(prompt.text)):
        if parsed is not None and len(parsed) == n:
            return [p.side for p in parsed]
    return [None] * n


def _clip_phrases(root: Path, clip_id: str) -> list[tuple[set[str], str | None, tuple[int, int]]] | None:
    """The phrases of a clip's first caption in time order: (what they name: general step actions or the
    primitive, the side they name, frames); None when the caption does not parse phrase for phrase."""
    from ..data.procedural.general_language import parse_general_prompt
    from ..data.procedural.language import parse_prompt

    path = root / "annotations" / f"{clip_id}.json"
    if not path.is_file():
        return None
    caps = json.loads(path.read_text(encoding="utf-8")).get("captions") or []
    if not caps or not caps[0].get("phrases"):
        return None
    cap = caps[0]
    general = clip_id.lstrip("M").startswith("G")
    parsed = (parse_general_prompt if general else parse_prompt)(cap["caption"])
    if parsed is None or len(parsed) != len(cap["phrases"]):
        return None
    out = []
    for ann in cap["phrases"]:
        i0, i1 = ann["words"]
        best = max(parsed, key=lambda q: min(i1, q.words[1]) - max(i0, q.words[0]))
        if min(i1, best.words[1]) <= max(i0, best.words[0]):
            return None
        names = set(best.actions) if general else {best.kind}
        out.append((names, best.side, (int(ann["frames"][0]), int(ann["frames"][1]))))
    return sorted(out, key=lambda t: t[2])


def corpus_windows(root: str | Path, prompt: BenchmarkPrompt, splits: Sequence[str] = ("train", "val", "test"),
                   skeleton: str | Skeleton = "humanml3d", mode: str = "single", hold: int = 10,
                   min_frames: int = 8) -> list[tuple[str, np.ndarray]]:
    """The corpus's own motions of a general prompt: ``(clip id, joints)`` per clip of a procedural corpus
    (with its ``annotations/``) whose first caption says what the prompt says.

    The caption's phrases are read with the corpus's parsers (a general clip's, ``G<id>`` / ``MG<id>``, with
    ``parse_general_prompt``; an action clip's with ``parse_prompt``) and must name, phrase for phrase and in
    time order, one of the actions of an alternative of ``prompt.corpus``, with the prompt's side where it
    names one.

    ``mode`` "single" (the single-action clips the thresholds come from): the caption says nothing else.
    An action clip is measured whole, as the core prompts' clips are; a general clip on its phrases' frames
    and up to ``hold`` frames after them (0.5 s: a posture reached at a phrase's last frame is held), because
    the general set's windows carry unnamed movement around the step (parts of other acrobatics cut by the
    window) that its captions leave unsaid. ``mode`` "phrase": any clip with such phrases among others,
    measured on those phrases' frames and up to ``hold`` frames after them, until the next phrase begins.
    """
    if not prompt.corpus:
        raise ValueError(f"prompt {prompt.text!r} names no corpus phrases (BenchmarkPrompt.corpus)")
    if mode not in ("single", "phrase"):
        raise ValueError(f"mode must be 'single' or 'phrase', got {mode!r}")
    root = Path(root)
    alts = [([set(c) for c in alt], _prompt_sides(prompt, len(alt))) for alt in prompt.corpus]
    out = []
    for split in splits:
        if not (root / f"{split}.txt").is_file():
            continue
        for cid in _split_ids(root, split):
            phrases = _clip_phrases(root, cid)
            found = None
            for want, sides in ([] if phrases is None else alts):
                m = len(want)
                starts = [0] if mode == "single" and len(phrases) == m else \
                    range(len(phrases) - m + 1) if mode == "phrase" else []
                for k in starts:
                    seq = phrases[k:k + m]
                    if all(names & w and (s is None or side == s) for (names, side, _), w, s in zip(seq, want, sides)):
                        found = (k, m)
                        break
                if found:
                    break
            if found is None:
                continue
            k, m = found
            x = load_joints(root, cid, skeleton)
            n = x.shape[0]
            if mode == "single" and not cid.lstrip("M").startswith("G"):
                f0, f1 = 0, n
            else:
                last_end = phrases[k + m - 1][2][1]
                nxt = phrases[k + m][2][0] if k + m < len(phrases) else n
                f0, f1 = phrases[k][2][0], min(last_end + hold, max(nxt, last_end), n)
            if f1 - f0 >= min_frames:
                out.append((cid, x[f0:f1]))
    return out


def corpus_check_values(root: str | Path, prompt: BenchmarkPrompt, mode: str = "single",
                        skeleton: str | Skeleton = "humanml3d") -> dict[str, list[tuple[str, float]]]:
    """Each check's measure on the corpus's own motions of a general prompt (:func:`corpus_windows`):
    check name -> ``[(clip id, value), ...]``; their minimum (maximum for an upper bound) is what the
    threshold was set from."""
    sk = get_skeleton(skeleton)
    windows = corpus_windows(root, prompt, mode=mode, skeleton=sk)
    return {c.name: [(cid, float(MEASURES[c.measure][0](x, sk, c.side))) for cid, x in windows] for c in prompt.checks}


# ------------------------------------------------------------------------------------ real motions
def load_joints(root: str | Path, clip_id: str, skeleton: str | Skeleton = "humanml3d") -> np.ndarray:
    """Joints ``(N, J, 3)`` of one clip of a HumanML3D-layout folder: ``new_joints/<id>.npy``, or
    recovered from ``new_joint_vecs/<id>.npy`` when the folder has no joints."""
    root = Path(root)
    path = root / "new_joints" / f"{clip_id}.npy"
    from .. import limits

    if path.is_file():
        return limits.read_npy(path).astype(np.float64)
    vec = root / "new_joint_vecs" / f"{clip_id}.npy"
    if not vec.is_file():
        raise FileNotFoundError(f"clip {clip_id!r}: neither {path} nor {vec} exists")
    from ..motion import features_to_joints

    return np.asarray(features_to_joints(limits.read_npy(vec), skeleton), dtype=np.float64)


def _split_ids(root: Path, split: str) -> list[str]:
    path = root / f"{split}.txt"
    if not path.is_file():
        raise FileNotFoundError(f"no split file {path}; a HumanML3D-layout folder has train/val/test.txt")
    return [line.strip() for line in path.read_text().splitlines() if line.strip()]


def measure_clips(root: str | Path, ids: Sequence[str], skeleton: str | Skeleton = "humanml3d",
                  min_frames: int = 4) -> list[ph.PhysicsReport]:
    """:func:`~salad_core.eval.physics.measure_motion` of every clip (clips shorter than
    ``min_frames`` are skipped)."""
    out = []
    for cid in ids:
        x = load_joints(root, cid, skeleton)
        if x.shape[0] >= min_frames:
            out.append(ph.measure_motion(x, skeleton))
    return out


def _captions(root: Path, clip_id: str) -> list[str]:
    path = root / "texts" / f"{clip_id}.txt"
    if not path.is_file():
        return []
    caps = [line.split("#", 1)[0].strip().rstrip(".").lower() for line in path.read_text(encoding="utf-8").splitlines()]
    return [c for c in caps if c]


def caption_diversity(root: str | Path, splits: Sequence[str] = ("train", "val", "test"),
                      skeleton: str | Skeleton = "humanml3d", max_groups: int = 200) -> tuple[float, int]:
    """The seed diversity of real motions: mean joint distance (cm) between clips that share a
    caption (the same prompt said of different motions), mirrors (``M<id>``) left out.

    All ``splits`` are pooled because few captions repeat within one split (3 groups in the test
    split of the small corpus, 139 in its train split, both 9.2-9.3 cm).

    Returns (mean over the first ``max_groups`` groups of
    :func:`~salad_core.eval.physics.seed_diversity`, number of groups used); ``(nan, 0)`` when no
    two clips share a caption.
    """
    root = Path(root)
    groups: dict[str, set[str]] = {}
    for split in splits:
        if not (root / f"{split}.txt").is_file():
            continue
        for cid in _split_ids(root, split):
            if cid.startswith("M"):
                continue
            for cap in _captions(root, cid):
                groups.setdefault(cap, set()).add(cid)
    shared = sorted({tuple(sorted(g)) for g in groups.values() if len(g) > 1})[:max_groups]
    if not shared:
        return float("nan"), 0
    vals = [ph.seed_diversity([load_joints(root, c, skeleton) for c in g]) for g in shared]
    return float(np.mean(vals)), len(shared)


_JUMP_WORDS = re.compile(r"\b(jump|jumps|jumping|hop|hops|hopping|leap|leaps|leaping|skip|skips|skipping|spring|springs|springing)\b")


def corpus_reference_rises(root: str | Path, splits: Sequence[str] = ("train", "val", "test"),
                           skeleton: str | Skeleton = "humanml3d") -> dict[str, list[float]]:
    """The pelvis rises (m) of a procedural corpus's reference clips (needs its ``annotations/``), per
    :data:`REFERENCE_RANGES` key: one value per reference clip, so their number says how much a range rests on.

    A clip is a jump reference when every caption of its annotation is one phrase with a jump word
    (jump, hop, leap, skip: the corpus's paraphrases of a jump) and no "jacks"; a jumping-jacks
    reference when every caption is one phrase with "jacks". Keys without clips are left out.
    """
    root = Path(root)
    rises: dict[str, list[float]] = {"jump_rise_m": [], "jumping_jacks_rise_m": []}
    for split in splits:
        if not (root / f"{split}.txt").is_file():
            continue
        for cid in _split_ids(root, split):
            ann_path = root / "annotations" / f"{cid}.json"
            if not ann_path.is_file():
                continue
            caps = json.loads(ann_path.read_text(encoding="utf-8")).get("captions", [])
            phrases = [c.get("phrases", []) for c in caps]
            if not caps or any(len(p) != 1 for p in phrases):
                continue
            texts = [p[0]["text"].lower() for p in phrases]
            if all("jacks" in t for t in texts):
                key = "jumping_jacks_rise_m"
            elif all(_JUMP_WORDS.search(t) and "jacks" not in t for t in texts):
                key = "jump_rise_m"
            else:
                continue
            rises[key].append(ph.measure_motion(load_joints(root, cid, skeleton), skeleton).jump_rise_m)
    return {k: v for k, v in rises.items() if v}


def rise_ranges(rises: Mapping[str, Sequence[float]]) -> dict[str, tuple[float, float]]:
    """(min, max) of each key's rises, widened to whole millimetres so that every reference clip lies inside."""
    return {k: (math.floor(min(v) * 1000) / 1000, math.ceil(max(v) * 1000) / 1000) for k, v in rises.items() if v}


def corpus_reference_ranges(root: str | Path, splits: Sequence[str] = ("train", "val", "test"),
                            skeleton: str | Skeleton = "humanml3d") -> dict[str, tuple[float, float]]:
    """Measure :data:`REFERENCE_RANGES` on a procedural corpus: :func:`rise_ranges` of
    :func:`corpus_reference_rises` (the reference clips are defined there)."""
    return rise_ranges(corpus_reference_rises(root, splits, skeleton))


def reference_rows(data_root: str | Path | None = None, sample_dir: str | Path | None = None,
                   split: str = "test", skeleton: str | Skeleton = "humanml3d") -> dict[str, dict[str, float]]:
    """Aggregates of real motions: the corpus's ``split`` (with :func:`caption_diversity` over all
    its splits as ``seed_diversity_cm``) and every clip of a real-data sample folder (evaluation only)."""
    rows: dict[str, dict[str, float]] = {}
    if data_root is not None:
        root = Path(data_root)
        motions = [load_joints(root, c, skeleton) for c in _split_ids(root, split)]
        motions = [x for x in motions if x.shape[0] >= 4]
        agg = ph.aggregate_reports([ph.measure_motion(x, skeleton) for x in motions])
        agg.update(_pooled_extras(motions, get_skeleton(skeleton)))
        agg["seed_diversity_cm"], agg["diversity_groups"] = caption_diversity(root, skeleton=skeleton)
        rows[f"corpus {split} split (real)"] = agg
    if sample_dir is not None:
        sdir = Path(sample_dir)
        ids = sorted(p.stem for p in (sdir / "new_joints").glob("*.npy")) or \
            sorted(p.stem for p in (sdir / "new_joint_vecs").glob("*.npy"))
        if not ids:
            raise FileNotFoundError(f"sample folder {sdir} holds no new_joints/*.npy or new_joint_vecs/*.npy")
        motions = [load_joints(sdir, c, skeleton) for c in ids]
        agg = ph.aggregate_reports([ph.measure_motion(x, skeleton) for x in motions])
        agg.update(_pooled_extras(motions, get_skeleton(skeleton)))
        rows[f"HumanML3D {', '.join(ids)} (real)"] = agg
    return rows


# ------------------------------------------------------------------------------------ real capture
#: pybullet's DeepMimic clips (:mod:`salad_core.data.deepmimic`) in the real-capture row: the upright,
#: foot-supported ones. Left out: cartwheel, crawl, roll and the two get-ups, which put hands, knees
#: or the back on the floor (the foot measures do not describe them).
REAL_CAPTURE_DEEPMIMIC: tuple[str, ...] = (
    "backflip", "dance_a", "dance_b", "jump", "kick", "punch", "run", "spin", "spinkick", "walk",
    "walker/0walk_forward", "walker/turn_left0", "walker/turn_left1", "walker/turn_right0", "walker/turn_right1")
#: Looping DeepMimic clips are played enough cycles to last this many frames (HumanML3D's shortest clips).
_MIN_CLIP_FRAMES = 40
_SAMPLE_JOINTS = Path(__file__).resolve().parents[2] / "tests" / "data" / "humanml3d_sample" / "new_joints" / "012314.npy"


def humanml3d_reference_joints(path: str | Path | None = None) -> np.ndarray | None:
    """The joints ``(170, 22, 3)`` (metres, float64) of HumanML3D clip 012314, or None where it is missing.

    The clip is not part of the installed package (HumanML3D's motions come from AMASS, whose licence
    governs their redistribution): it is read from ``path`` or from a source checkout's
    ``tests/data/humanml3d_sample`` (see its ``SOURCE.md``).
    """
    p = Path(path) if path is not None else _SAMPLE_JOINTS
    if p.is_dir():
        p = p / "new_joints" / "012314.npy"
    return np.load(p).astype(np.float64) if p.is_file() else None


@contextlib.contextmanager
def _quiet_native_output():
    """Silence file descriptors 1 and 2 inside the block: pybullet's C++ URDF importer prints a warning
    per joint of every clip it loads (to the C ``stdout``, flushed before the descriptors come back)."""
    streams = [f for f in (sys.stdout, sys.stderr) if f is not None]
    try:
        fds = sorted({f.fileno() for f in streams})
    except (AttributeError, OSError, ValueError):
        yield
        return
    for f in streams:
        f.flush()
    saved = [os.dup(fd) for fd in fds]
    try:
        with open(os.devnull, "w") as null:
            for fd in fds:
                os.dup2(null.fileno(), fd)
            try:
                yield
            finally:
                try:
                    import ctypes

                    ctypes.CDLL(None).fflush(None)
                except (OSError, AttributeError):
                    pass
    finally:
        for fd, keep in zip(fds, saved):
            os.dup2(keep, fd)
            os.close(keep)


@functools.lru_cache(maxsize=1)
def _deepmimic_joints() -> tuple[tuple[str, np.ndarray], ...]:
    """The clips of :data:`REAL_CAPTURE_DEEPMIMIC` as HumanML3D joints: features of the converted clip
    (retargeted to HumanML3D's bones, floor at the lowest joint, facing +Z, as HumanML3D processes its
    clips) read back with the position recovery."""
    from salad_core.data import deepmimic
    from salad_core.motion import features_to_joints

    out = []
    with _quiet_native_output():
        for name in REAL_CAPTURE_DEEPMIMIC:
            clip = deepmimic.load_clip(name)
            if clip.loop and clip.num_frames < _MIN_CLIP_FRAMES:
                clip = deepmimic.load_clip(name, cycles=math.ceil(_MIN_CLIP_FRAMES / max(clip.num_frames - 1, 1)))
            joints = features_to_joints(deepmimic.clip_features(clip), "humanml3d")
            out.append((name, np.asarray(joints, dtype=np.float64)))
    return tuple(out)


def real_capture_clips(deepmimic: bool | None = None) -> tuple[dict[str, np.ndarray], str]:
    """The real motion-capture clips of the reference row, ``name -> joints (N, 22, 3)``, and a note on
    what they are.

    ``deepmimic``: None (default) adds pybullet's DeepMimic clips when pybullet is installed; True
    requires them (ImportError naming the extra without pybullet); False leaves them out. HumanML3D clip
    012314 is always in.
    """
    use, auto = _resolve_deepmimic(deepmimic)
    return _clips(use, auto)


def _resolve_deepmimic(deepmimic: bool | None) -> tuple[bool, bool]:
    """(use the DeepMimic clips, decided by whether pybullet is installed)."""
    if deepmimic is not None:
        return bool(deepmimic), False
    from salad_core.data.deepmimic import pybullet_available

    with _quiet_native_output():                       # importing pybullet prints its build time
        return pybullet_available(), True


def _clips(use: bool, auto: bool) -> tuple[dict[str, np.ndarray], str]:
    sample = humanml3d_reference_joints()
    clips = {} if sample is None else {"HumanML3D 012314": sample}
    first = "" if sample is None else "HumanML3D 012314 and "
    if use:
        deepmimic = {f"DeepMimic {n}": x for n, x in _deepmimic_joints()}
        clips.update(deepmimic)
        note = (f"{first}{len(deepmimic)} of pybullet's DeepMimic clips "
                f"({', '.join(REAL_CAPTURE_DEEPMIMIC)}), converted to HumanML3D joints")
    elif sample is None:
        note = ("none: the HumanML3D sample 012314 ships only with a source checkout (tests/data) and pybullet "
                "(the optional extra 'deepmimic') is " + ("not installed" if auto else "left out"))
    elif auto:
        note = "the HumanML3D sample 012314 alone: pybullet (the optional extra 'deepmimic') is not installed"
    else:
        note = "the HumanML3D sample 012314 alone (DeepMimic clips left out)"
    return clips, note


@functools.lru_cache(maxsize=8)
def _real_capture_cached(use: bool, auto: bool, skeleton_name: str) -> tuple[str, dict, dict, str]:
    clips, note = _clips(use, auto)
    sk = get_skeleton(skeleton_name)
    reports = {n: ph.measure_motion(x, sk) for n, x in clips.items()}
    agg = ph.aggregate_reports(list(reports.values()))
    agg.update(_pooled_extras(list(clips.values()), sk))
    dm = sum(1 for n in clips if n.startswith("DeepMimic"))
    hml = "HumanML3D 012314" in clips
    name = (f"real capture (HumanML3D 012314 + {dm} DeepMimic clips)" if dm and hml else
            f"real capture ({dm} DeepMimic clips)" if dm else
            "real capture (HumanML3D 012314 only)" if hml else "real capture (none available)")
    return name, agg, {n: r.as_dict() for n, r in reports.items()}, note


def real_capture_row(deepmimic: bool | None = None, skeleton: str | Skeleton = "humanml3d") -> dict:
    """The real-capture reference row, measured once per process.

    ``deepmimic`` as :func:`real_capture_clips`.

    Returns
    -------
    dict: ``name`` (the row's label, which says whether DeepMimic clips are in), ``aggregate``
    (:func:`~salad_core.eval.physics.aggregate_reports` of the clips, with the pooled bone p95 / p99 and
    penetration p99), ``clips`` (each clip's report) and ``note`` (what the clips are; says so when
    pybullet is missing).
    """
    sk = get_skeleton(skeleton)
    use, auto = _resolve_deepmimic(deepmimic)
    name, agg, clips, note = _real_capture_cached(use, auto, sk.name)
    return {"name": name, "aggregate": dict(agg), "clips": {k: dict(v) for k, v in clips.items()}, "note": note}


# ------------------------------------------------------------------------------------ the runner
@dataclass(frozen=True)
class BenchSettings:
    """How the benchmark samples: steps, guidance, seeds and which prompts."""

    steps: int = 50                          # sampler steps
    guidance: float | None = None            # CFG weight given to the generators (None: their defaults)
    seeds: tuple[int, ...] = (0, 1, 2)       # noise seeds, one motion per prompt and seed
    num_prompts: int | None = None           # the first n prompts of the list (None: all)

    def __post_init__(self) -> None:
        if isinstance(self.steps, bool) or not isinstance(self.steps, int) or self.steps < 1:
            raise ValueError(f"steps must be a positive int, got {self.steps!r}")
        if self.guidance is not None and not (isinstance(self.guidance, (int, float)) and not isinstance(
                self.guidance, bool) and math.isfinite(self.guidance) and self.guidance >= 0):
            raise ValueError(f"guidance must be None or a finite number >= 0, got {self.guidance!r}")
        if len(self.seeds) < 1 or len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"seeds must be distinct and at least one, got {self.seeds!r}")
        if self.num_prompts is not None and not (isinstance(self.num_prompts, int) and self.num_prompts >= 1):
            raise ValueError(f"num_prompts must be a positive int or None, got {self.num_prompts!r}")


def _clean(v):
    """JSON-safe: nan/inf -> None, numpy scalars -> Python."""
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    if isinstance(v, (np.floating, float)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    return v


#: Per-prompt summary: the report fields averaged over a prompt's seeds (nan ignored), and
#: from the shown-vs-raw deviation ``deviation_p95_cm``, ``deviation_p99_cm``, ``travel_ratio``.
PROMPT_SUMMARY: tuple[str, ...] = (
    "bone_ref_p99_cm", "bone_ref_max_cm", "penetration_p99_cm", "penetration_max_cm", "skate_mean_ms",
    "stance_slide_mean_ms", "low_swing_mean_ms", "gmd_skate_ratio", "physdiff_penetrate_mm", "physdiff_float_mm",
    "physdiff_skate_mm", "physdiff_err_mm", "stance_float_cm", "jump_rise_m", "stride_m", "flight_accel_ms2",
    "flight_fit_accel_ms2", "flight_segments")


def _mean_of(values) -> float:
    v = np.array([np.nan if x is None else float(x) for x in values], dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else float("nan")


def _pooled_extras(motions: Sequence[np.ndarray], sk: Skeleton) -> dict[str, float]:
    return {"bone_ref_p95_pooled_cm": ph.pooled_bone_p95(motions, sk),
            "bone_ref_p99_pooled_cm": ph.pooled_bone_percentile(motions, 99.0, sk),
            "penetration_p99_pooled_cm": ph.pooled_penetration_percentile(motions, 99.0, sk)}


def run_benchmark(generators: Mapping[str, Generator], settings: BenchSettings = BenchSettings(),
                  data_root: str | Path | None = None, sample_dir: str | Path | None = None,
                  prompts: Sequence[BenchmarkPrompt] = PROMPTS, skeleton: str | Skeleton = "humanml3d",
                  info: Mapping[str, object] | None = None, log: Callable[[str], None] | None = None,
                  motions_sink: dict | None = None, real_capture: bool = True,
                  deepmimic: bool | None = None) -> dict:
    """Generate every prompt with every seed and generator, measure, check and aggregate.

    Parameters
    ----------
    generators : name -> :data:`Generator`, in table order (e.g. SALAD, then KeyMotion). A generator
        returning :class:`Generated` with ``raw`` joints gets the shown-vs-raw deviation measured.
    settings : BenchSettings
    data_root : corpus folder for the reference row (its test split) and the jump ranges
    sample_dir : folder of real clips (HumanML3D layout) for a reference row of its own
    prompts : the benchmark prompts (default :data:`PROMPTS`)
    info : extra settings to record (weights paths, ...)
    log : called with progress lines
    motions_sink : dict, optional
        Receives the generated joints, ``"<generator>/<prompt index>/<seed>" -> (N, J, 3)`` (and the raw
        ones under ``".../raw"``), so they can be saved and measured again without generating.
    real_capture : add the real-capture reference row (:func:`real_capture_row`; HumanML3D skeleton only)
    deepmimic : with it, pybullet's DeepMimic clips (None: when pybullet is installed)

    Returns
    -------
    dict (JSON-ready): ``settings``, ``references`` (aggregates of real motions), ``real_capture`` (the
    real-capture row's ``name``, ``note`` and per-clip reports, or None), ``reference_ranges`` and their
    ``reference_source``, and per generator its ``aggregate`` (with ``seed_diversity_cm`` and the pooled
    p95 / p99 columns), ``deviation`` (:func:`~salad_core.eval.physics.recovery_deviation` pooled over
    all its motions, or None without raw joints), ``checks_passed`` / ``checks_total``, ``seconds`` and
    per prompt its ``group`` ("core" / "general"), the per-seed reports, deviations and check results,
    ``seeds_passed`` (seeds whose motion passed every check of the prompt), the seed diversity and ``summary``
    (:data:`PROMPT_SUMMARY` averaged over the seeds).
    """
    say = log or (lambda s: None)
    sk = get_skeleton(skeleton)
    chosen = list(prompts)[: settings.num_prompts] if settings.num_prompts else list(prompts)
    ranges, source = dict(REFERENCE_RANGES), "recorded (salad_core.eval.physics_prompts.REFERENCE_RANGES)"
    if data_root is not None and (Path(data_root) / "annotations").is_dir():
        rises = corpus_reference_rises(data_root, skeleton=sk)
        if rises:
            ranges.update(rise_ranges(rises))
            counts = ", ".join(f"{k} from {len(v)} clip{'s' if len(v) != 1 else ''}" for k, v in sorted(rises.items()))
            source = f"measured on {data_root} ({counts}; others recorded)"
    t0 = time.perf_counter()
    references = reference_rows(data_root, sample_dir, skeleton=sk)
    real = None
    if real_capture and sk.name == "humanml3d":
        row = real_capture_row(deepmimic, sk)
        references[row["name"]] = row["aggregate"]
        real = {"name": row["name"], "note": row["note"], "clips": row["clips"]}
    say(f"reference rows measured ({time.perf_counter() - t0:.0f} s)")
    texts, lengths = [p.text for p in chosen], [p.length for p in chosen]
    out_gens: dict[str, dict] = {}
    for name, gen in generators.items():
        t0 = time.perf_counter()
        motions: list[list[np.ndarray]] = [[] for _ in chosen]
        raws: list[list[np.ndarray]] | None = [[] for _ in chosen]
        for seed in settings.seeds:
            made = gen(texts, lengths, int(seed))
            joints, raw = (made.shown, made.raw) if isinstance(made, Generated) else (made, None)
            if len(joints) != len(chosen) or (raw is not None and len(raw) != len(chosen)):
                raise ValueError(f"generator {name!r} returned {len(joints)} motions for {len(chosen)} prompts")
            if raw is None:
                raws = None
            for i, x in enumerate(joints):
                motions[i].append(np.asarray(x, dtype=np.float64))
                if raws is not None:
                    raws[i].append(np.asarray(raw[i], dtype=np.float64))
                if motions_sink is not None:
                    motions_sink[f"{name}/{i:02d}/{seed}"] = np.asarray(x, dtype=np.float32)
                    if raw is not None:
                        motions_sink[f"{name}/{i:02d}/{seed}/raw"] = np.asarray(raw[i], dtype=np.float32)
            say(f"{name}: seed {seed} generated ({time.perf_counter() - t0:.0f} s)")
        per_prompt, reports, passed, total, div = [], [], 0, 0, []
        for i, (p, xs) in enumerate(zip(chosen, motions)):
            reps = [ph.measure_motion(x, sk) for x in xs]
            checks = [[c.evaluate(x, sk, ranges) for c in p.checks] for x in xs]
            d = ph.seed_diversity(xs) if len(xs) > 1 else float("nan")
            div.append(d)
            reports += reps
            passed += sum(r.passed for row in checks for r in row)
            total += sum(len(row) for row in checks)
            rows = [r.as_dict() for r in reps]
            summary = {k: _mean_of(r[k] for r in rows) for k in PROMPT_SUMMARY}
            devs = None
            if raws is not None:
                devs = []
                for x, r in zip(xs, raws[i]):
                    dv = ph.recovery_deviation(x, r, sk)
                    devs.append({k: dv[k] for k in ("p95_cm", "p99_cm", "max_cm", "mean_cm", "travel_ratio",
                                                     "worst_joint")})
                summary.update(deviation_p95_cm=_mean_of(v["p95_cm"] for v in devs),
                               deviation_p99_cm=_mean_of(v["p99_cm"] for v in devs),
                               travel_ratio=_mean_of(v["travel_ratio"] for v in devs))
            per_prompt.append({"text": p.text, "action": p.action, "length": p.length, "group": p.group,
                               "seeds": list(settings.seeds),
                               "seeds_passed": sum(all(r.passed for r in row) for row in checks),
                               "diversity_cm": d, "summary": summary,
                               "reports": rows, "deviations": devs,
                               "checks": [[asdict(r) for r in row] for row in checks]})
        agg = ph.aggregate_reports(reports)
        every = [x for xs in motions for x in xs]
        agg.update(_pooled_extras(every, sk))
        agg["seed_diversity_cm"] = float(np.nanmean(div)) if np.isfinite(div).any() else float("nan")
        deviation = None
        if raws is not None:
            deviation = ph.recovery_deviation(every, [x for xs in raws for x in xs], sk)
            deviation["joint_names"] = list(sk.joint_names)
        out_gens[name] = {"aggregate": agg, "deviation": deviation, "checks_passed": passed, "checks_total": total,
                          "seconds": time.perf_counter() - t0, "prompts": per_prompt}
        say(f"{name}: measured, checks {passed}/{total}")
    doc = {"settings": {**asdict(settings), "num_prompts": len(chosen), "skeleton": sk.name,
                        "data": None if data_root is None else str(data_root),
                        "sample": None if sample_dir is None else str(sample_dir), **dict(info or {})},
           "references": references, "real_capture": real,
           "reference_ranges": {k: list(v) for k, v in ranges.items()},
           "reference_source": source, "generators": out_gens}
    return _clean(doc)


def targets(result: Mapping) -> list[dict]:
    """The benchmark's targets (the plausibility targets; the generator targets, written for KeyMotion, shown for every generator
    except the relative diversity one, which compares with the first generator; the field's, stated
    against the real-capture row and marked "[field]") evaluated on a :func:`run_benchmark` result:
    per target its text and, per generator, ``(value, passed)`` (``passed`` None when the reference or
    the raw joints it needs are missing).

    The "[field]" targets: stance sliding and GMD's skating ratio on the forward walks and runs at most 1.5x
    the real-capture row's (over all its clips); floating during stance at most 2 cm; the shown joints
    within p95 5 cm and p99 10 cm of the raw position read; bones exact (pooled p99 of the reference
    bone error at most 0.1 cm); nothing below the floor (pooled p99 penetration at most 0.5 cm,
    PhysDiff's 5 mm tolerance); the shown pelvis travelling within 20 % of the raw one; and the jumps'
    median per-segment flight fit within 25 % of -9.81 m/s^2."""
    gens = result["generators"]
    corpus = next((v for k, v in result["references"].items() if k.startswith("corpus")), None)
    ref = (lambda key: None if corpus is None or corpus.get(key) is None else float(corpus[key]))
    first = next(iter(gens.values()), None)

    def ratio(v, bound):
        return (v, None if bound is None or v is None else v <= bound)

    rows = []

    def add(text, fn, only_later: bool = False):
        cells = {}
        for i, (name, g) in enumerate(gens.items()):
            if only_later and i == 0:
                continue
            cells[name] = fn(g["aggregate"], g)
        rows.append({"target": text, "cells": cells})

    sk = ref("skate_mean_ms")
    add("bone error p95 <= 3 cm (pooled over frames x bones x motions)",
        lambda a, g: (a.get("bone_ref_p95_pooled_cm"), _le(a.get("bone_ref_p95_pooled_cm"), 3.0)))
    add("bone error max <= 8 cm", lambda a, g: (a.get("bone_ref_max_cm"), _le(a.get("bone_ref_max_cm"), 8.0)))
    add(f"foot skating <= 1.5x the corpus's ({_fmt(sk, '{:.3f}')} m/s)",
        lambda a, g: ratio(a.get("skate_mean_ms"), None if sk is None else 1.5 * sk))
    add("ground penetration <= 2 cm (max over motions)",
        lambda a, g: (a.get("penetration_max_cm"), _le(a.get("penetration_max_cm"), 2.0)))
    add("jump heights within the corpus's range (jump checks passed)", lambda a, g: _count_cell(g, "jump_rise_m"))
    dv = ref("seed_diversity_cm")
    add(f"seed diversity >= the corpus's paraphrases ({_fmt(dv, '{:.1f}')} cm)",
        lambda a, g: (a.get("seed_diversity_cm"), None if dv is None else _ge(a.get("seed_diversity_cm"), dv)))
    add("[generator] walking stride >= 0.4 m (stride checks passed)", lambda a, g: _count_cell(g, "stride_m"))
    add("[generator] foot skating on the forward walks and runs <= 2x the corpus's",
        lambda a, g: ratio(_pooled(g, _FORWARD_GAITS, "skate_mean_ms", "contact_count"),
                           None if sk is None else 2 * sk))
    add("[generator] jumps near-ballistic: pelvis acceleration in flight on the jump prompts within 25 % of "
        "-9.81 m/s^2", lambda a, g: _ballistic(_pooled(g, ("jump", "jumping_jacks"), "flight_accel_ms2",
                                                        "flight_accel_count")))
    sd = None if first is None else first["aggregate"].get("seed_diversity_cm")
    add("[generator] seed diversity >= half of the first generator's",
        lambda a, g: (a.get("seed_diversity_cm"), None if sd is None else _ge(a.get("seed_diversity_cm"), sd / 2)),
        only_later=True)
    # ---- the field's measures, against the real-capture row
    real_name = (result.get("real_capture") or {}).get("name")
    real = result["references"].get(real_name) if real_name else None
    rv = (lambda key: None if real is None or real.get(key) is None else float(real[key]))
    slide, gmd = rv("stance_slide_mean_ms"), rv("gmd_skate_ratio")
    add(f"[field] stance sliding on the forward walks and runs <= 1.5x the real capture's "
        f"({_fmt(slide, '{:.3f}')} m/s)",
        lambda a, g: ratio(_pooled(g, _FORWARD_GAITS, "stance_slide_mean_ms", "stance_count"),
                           None if slide is None else 1.5 * slide))
    add(f"[field] GMD skating ratio on the forward walks and runs <= 1.5x the real capture's "
        f"({_fmt(gmd, '{:.3f}')})",
        lambda a, g: ratio(_mean_over(g, _FORWARD_GAITS, "gmd_skate_ratio"), None if gmd is None else 1.5 * gmd))
    add("[field] floating during stance <= 2 cm (mean height of the stance feet above the floor)",
        lambda a, g: (a.get("stance_float_cm"), _le(a.get("stance_float_cm"), 2.0)))
    add("[field] shown vs raw: p95 <= 5 cm and p99 <= 10 cm", _deviation_cell)
    add("[field] bones exact: bone error p99 <= 0.1 cm (pooled over frames x bones x motions)",
        lambda a, g: (a.get("bone_ref_p99_pooled_cm"), _le(a.get("bone_ref_p99_pooled_cm"), 0.1)))
    add("[field] nothing below the floor: penetration p99 <= 0.5 cm (pooled over frames x motions)",
        lambda a, g: (a.get("penetration_p99_pooled_cm"), _le(a.get("penetration_p99_pooled_cm"), 0.5)))
    add("[field] travel within 20 % of raw (shown / raw pelvis ground path)", _travel_cell)
    add("[field] jumps near-ballistic: median per-segment flight fit on the jump prompts within 25 % of "
        "-9.81 m/s^2", lambda a, g: _ballistic(_segments_median(g, ("jump", "jumping_jacks"))))
    if any(p.get("group") == "general" and p["action"] in GENERAL_TARGET_ACTIONS
           for g in gens.values() for p in g["prompts"]):
        add(f"[general] general-motion prompts ({', '.join(GENERAL_TARGET_ACTIONS)}): each passes every check in "
            f">= {GENERAL_PASS_SHARE * 100:.0f} % of its seeds", lambda a, g: _general_cell(g))
    return rows


#: The actions of the general-motion target (cartwheel, roll, lie down, kneel, crawl, climb stairs): the target row
#: "[general]" asks that each of their :data:`GENERAL_PROMPTS` passes every check in :data:`GENERAL_PASS_SHARE`
#: of its seeds.
GENERAL_TARGET_ACTIONS = ("cartwheel", "forward_roll", "lie_down", "kneel", "crawl", "climb_stairs")
GENERAL_PASS_SHARE = 0.8


def general_pass_rows(gen: Mapping) -> list[dict]:
    """Per general-motion prompt of one generator's result: ``text``, ``action``, ``seeds_passed`` (seeds
    whose motion passed every check), ``seeds``, ``share`` and ``passed`` (share >= :data:`GENERAL_PASS_SHARE`)."""
    out = []
    for p in gen["prompts"]:
        if p.get("group") != "general":
            continue
        k = p.get("seeds_passed")
        if k is None:
            k = sum(all(r["passed"] for r in row) for row in p["checks"])
        n = len(p["checks"])
        out.append({"text": p["text"], "action": p["action"], "seeds_passed": int(k), "seeds": n,
                    "share": k / n if n else float("nan"), "passed": bool(n and k / n >= GENERAL_PASS_SHARE)})
    return out


def _general_cell(gen: Mapping):
    rows = [r for r in general_pass_rows(gen) if r["action"] in GENERAL_TARGET_ACTIONS]
    ok = sum(r["passed"] for r in rows)
    return (f"{ok}/{len(rows)} prompts", (ok == len(rows)) if rows else None)


def _mean_over(gen: Mapping, actions: Sequence[str], key: str) -> float | None:
    """Mean of ``key`` over one generator's per-motion reports on the prompts of ``actions``."""
    v = [r[key] for p in gen["prompts"] if p["action"] in actions for r in p["reports"] if r.get(key) is not None]
    return float(np.mean(v)) if v else None


def _segments_median(gen: Mapping, actions: Sequence[str]) -> float | None:
    """Median of the per-segment flight fits of one generator's motions on the prompts of ``actions``."""
    v = [a for p in gen["prompts"] if p["action"] in actions for r in p["reports"]
         for a in (r.get("flight_segment_accels") or ()) if a is not None]
    return float(np.median(v)) if v else None


def _deviation_cell(agg: Mapping, gen: Mapping):
    dev = gen.get("deviation")
    if not dev or dev.get("p95_cm") is None or dev.get("p99_cm") is None:
        return (None, None)
    return (f"p95 {dev['p95_cm']:.2f} / p99 {dev['p99_cm']:.2f} cm",
            bool(dev["p95_cm"] <= 5.0 and dev["p99_cm"] <= 10.0))


def _travel_cell(agg: Mapping, gen: Mapping):
    dev = gen.get("deviation")
    v = None if not dev else dev.get("travel_ratio")
    return (v, None if v is None else bool(0.8 <= v <= 1.2))


#: Actions of the prompts whose skating the generators' walking target is about.
_FORWARD_GAITS = ("walk", "run", "jog", "march")


def _pooled(gen: Mapping, actions: Sequence[str], key: str, weight: str) -> float | None:
    """``key`` of one generator's per-motion reports on the prompts of ``actions``, averaged with
    the weights ``weight`` (None when nothing is weighted)."""
    pairs = [(r[key], r[weight]) for p in gen["prompts"] if p["action"] in actions for r in p["reports"]
             if r[key] is not None and r[weight]]
    if not pairs:
        return None
    v, w = np.array(pairs, dtype=float).T
    return float((v * w).sum() / w.sum())


def _ballistic(v: float | None):
    return (v, None if v is None else bool(abs(v + ph.GRAVITY) <= 0.25 * ph.GRAVITY))


def _le(v, bound):
    return None if v is None else bool(v <= bound)


def _ge(v, bound):
    return None if v is None else bool(v >= bound)


def _count_cell(gen: Mapping, measure: str):
    hits = [r["passed"] for p in gen["prompts"] for row in p["checks"] for r in row
            if _check_measure(r["check"]) == measure]
    return (f"{sum(hits)}/{len(hits)}", (sum(hits) == len(hits)) if hits else None)


def _check_measure(desc: str) -> str:
    """The measure name in a check description ("lo <= name[side] <= hi unit" or "name >= lo unit")."""
    words = desc.split()
    name = words[2] if len(words) > 2 and words[1] == "<=" and words[3:4] == ["<="] else words[0]
    return name.split("[")[0]


def saved_generators(motions: Mapping[str, np.ndarray]) -> dict[str, Generator]:
    """Generators that replay the joints a run saved (``run_benchmark(..., motions_sink=...)``, e.g.
    ``physics_motions.npz``: ``"<generator>/<prompt index>/<seed>" -> (N, J, 3)``, and the raw joints
    under ``".../raw"`` when the run had them), so the same motions can be measured again (after a
    change of the measures) without generating them. A generator whose raw joints were saved replays
    :class:`Generated` (shown and raw), otherwise the list of shown joints."""
    names: dict[str, None] = {}
    for key in motions:
        parts = key.split("/")
        ok = len(parts) in (3, 4) and parts[1].isdigit() and parts[2].lstrip("-").isdigit() and \
            (len(parts) == 3 or parts[3] == "raw")
        if not ok:
            raise ValueError(f"saved motion key {key!r} is not '<generator>/<prompt index>/<seed>[/raw]'")
        names.setdefault(parts[0], None)

    def replay(name: str) -> Generator:
        def gen(texts, lengths, seed):
            keys = [f"{name}/{i:02d}/{seed}" for i in range(len(texts))]
            missing = [k for k in keys if k not in motions]
            if missing:
                raise KeyError(f"the saved motions have no {missing[0]!r} (and {len(missing) - 1} more); "
                               "replay with the prompts and seeds of the saved run")
            shown = [np.asarray(motions[k]) for k in keys]
            if all(f"{k}/raw" in motions for k in keys):
                return Generated(shown, [np.asarray(motions[f"{k}/raw"]) for k in keys])
            return shown
        return gen

    return {name: replay(name) for name in names}


def _fmt(v, fmt: str = "{:.2f}") -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else fmt.format(v)


#: Per-prompt columns of the report: (key of the prompt's ``summary`` or "diversity_cm",
#: header, format); every value is the mean over the prompt's seeds.
_PROMPT_COLUMNS = (
    ("bone_ref_p99_cm", "bone p99 (cm)", "{:.2f}"),
    ("penetration_p99_cm", "penetr. p99 (cm)", "{:.1f}"),
    ("stance_slide_mean_ms", "stance slide (m/s)", "{:.3f}"),
    ("low_swing_mean_ms", "low swing (m/s)", "{:.2f}"),
    ("gmd_skate_ratio", "GMD ratio", "{:.3f}"),
    ("stance_float_cm", "stance float (cm)", "{:.1f}"),
    ("physdiff_err_mm", "Phys-Err (mm)", "{:.0f}"),
    ("jump_rise_m", "rise (m)", "{:.2f}"),
    ("stride_m", "stride (m)", "{:.2f}"),
    ("flight_fit_accel_ms2", "flight fit (m/s^2)", "{:.1f}"),
    ("deviation_p95_cm", "shown-raw p95 (cm)", "{:.1f}"),
    ("travel_ratio", "travel ratio", "{:.2f}"),
    ("diversity_cm", "div (cm)", "{:.1f}"),
)


def _nan_rows(rows: Mapping[str, Mapping]) -> dict[str, dict]:
    return {k: {kk: (float("nan") if vv is None else vv) for kk, vv in v.items()
                if not isinstance(vv, (list, tuple, dict, str))} for k, v in rows.items()}


def benchmark_markdown(result: Mapping) -> str:
    """The report of :func:`run_benchmark` as Markdown: settings, the measures tables (real motions
    first: the old measures, then the field's with the real-capture row), the shown-vs-raw
    deviation, the targets, the per-action checks and a per-prompt table per generator."""
    s = result["settings"]
    gens = result["generators"]
    real = result.get("real_capture")
    lines = ["# Physical-plausibility benchmark", "",
             "Settings: " + ", ".join(f"{k} = {v}" for k, v in s.items()), "",
             f"Jump-height ranges: {result['reference_ranges']} ({result['reference_source']}).", "",
             "Definitions and units: `salad_core/eval/physics.py`; bone error against the HumanML3D "
             "reference skeleton, drift against each motion's own median bone lengths; skating pooled "
             "over all contact frames; max columns are the max over motions, others means over motions.",
             "", "## Measures", ""]
    rows = dict(result["references"])
    rows.update({name: g["aggregate"] for name, g in gens.items()})
    rows = _nan_rows(rows)
    lines += [ph.report_table(rows), ""]
    lines += ["## The field's measures", "",
              "Stance sliding: foot joints low and vertically still for >= 3 frames (pooled over those frame pairs); "
              "low swing: low but not in stance; GMD skate ratio: share of frames with a toe below 5 cm skidding "
              "faster than 0.5 m/s (GMD / OmniControl); PhysDiff's Penetrate / Float / Skate computed on joints, not "
              "the mesh; stance float: height of the stance feet above the floor; p99 columns pooled over every "
              "frame of every motion; flight fit: median over flight segments of the pelvis parabola's "
              "acceleration. Contact is measured from the 5th percentile of the lowest foot joint's height.", ""]
    if real:
        lines += [f"Real capture: {real['note']}. Evaluation only: no threshold was set on these clips.", ""]
    lines += [ph.report_table(rows, ph.FIELD_TABLE_COLUMNS), ""]
    if real and real.get("clips"):
        lines += ["Real capture, per clip:", "",
                  ph.report_table(_nan_rows(real["clips"]), _CLIP_COLUMNS), ""]
    if not gens:
        return "\n".join(lines) + "\n"
    names = list(gens)
    lines += ["## Shown vs raw", "",
              "Distance between the joints measured above (the recovery of the settings) and the raw position read "
              "of the same features, over all frames x joints of every motion; travel ratio = shown pelvis ground "
              "path / raw.", "",
              "| generator | p95 (cm) | p99 (cm) | max (cm) | mean (cm) | worst joint (its p95, cm) | travel ratio |",
              "|---|---:|---:|---:|---:|---|---:|"]
    for n in names:
        dev = gens[n].get("deviation")
        if not dev:
            lines.append(f"| {n} | - | - | - | - | (no raw joints) | - |")
            continue
        worst = dev["worst_joint"]
        jn = dev.get("joint_names") or []
        wi = jn.index(worst) if worst in jn else (worst if isinstance(worst, int) else None)
        wp = dev["per_joint_p95_cm"][wi] if wi is not None else None
        lines.append(f"| {n} | {_fmt(dev['p95_cm'])} | {_fmt(dev['p99_cm'])} | {_fmt(dev['max_cm'])} | "
                     f"{_fmt(dev['mean_cm'])} | {worst} ({_fmt(wp)}) | {_fmt(dev['travel_ratio'], '{:.3f}')} |")
    lines.append("")
    lines += ["## Targets", "", "| target | " + " | ".join(names) + " |",
              "|---|" + "---|" * len(names)]
    for t in targets(result):
        cells = []
        for n in names:
            if n not in t["cells"]:
                cells.append("")
                continue
            v, ok = t["cells"][n]
            val = v if isinstance(v, str) else _fmt(v, "{:.3g}")
            cells.append(f"{val} {'-' if ok is None else ('pass' if ok else 'FAIL')}")
        lines.append(f"| {t['target']} | " + " | ".join(cells) + " |")
    lines.append("")
    lines += ["## Per-action checks", "",
              "Each cell: seeds passing / seeds, and the median measured value.", "",
              "| prompt | check | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    first = gens[names[0]]["prompts"]
    for i, p in enumerate(first):
        for c in range(len(p["checks"][0])):
            cells = []
            for n in names:
                row = [seed_checks[c] for seed_checks in gens[n]["prompts"][i]["checks"]]
                vals = [r["value"] for r in row if r["value"] is not None]
                median = float(np.median(vals)) if vals else None
                cells.append(f"{sum(r['passed'] for r in row)}/{len(row)} ({_fmt(median)})")
            text = p["text"] if c == 0 else ""
            lines.append(f"| {text} | {p['checks'][0][c]['check']} | " + " | ".join(cells) + " |")
    passed = "; ".join(f"{n} {g['checks_passed']}/{g['checks_total']}" for n, g in gens.items())
    lines += ["", "Checks passed: " + passed, ""]
    lines += _general_section(gens, names)
    lines += ["## Per prompt", "",
              "Every value is the mean over the prompt's seeds (nan ignored); diversity = mean joint distance "
              "between the seeds' motions (cm).", ""]
    for n in names:
        lines += [f"### {n}", "", "| prompt | " + " | ".join(h for _, h, _ in _PROMPT_COLUMNS) + " |",
                  "|---|" + "---:|" * len(_PROMPT_COLUMNS)]
        for q in gens[n]["prompts"]:
            summary = dict(q.get("summary") or {}, diversity_cm=q["diversity_cm"])
            lines.append(f"| {q['text']} | " + " | ".join(_fmt(summary.get(k), fmt) for k, _, fmt in _PROMPT_COLUMNS)
                         + " |")
        lines.append("")
    return "\n".join(lines)


def _general_section(gens: Mapping, names: Sequence[str]) -> list[str]:
    """The report's section on the general-motion prompts (none without them)."""
    per = {n: general_pass_rows(gens[n]) for n in names}
    first = per[names[0]]
    if not first:
        return []
    lines = ["## General-motion prompts", "",
             "Each cell: seeds whose motion passed every check of the prompt / seeds (share). The target asks for "
             f">= {GENERAL_PASS_SHARE * 100:.0f} % on the prompts of {', '.join(GENERAL_TARGET_ACTIONS)} "
             "(marked *).", "",
             "| prompt | action | checks | " + " | ".join(names) + " |", "|---|---|---|" + "---|" * len(names)]
    checks = {p["text"]: "; ".join(r["check"] for r in p["checks"][0]) for p in gens[names[0]]["prompts"]
              if p.get("group") == "general" and p["checks"]}
    for i, row in enumerate(first):
        star = " *" if row["action"] in GENERAL_TARGET_ACTIONS else ""
        cells = [f"{r['seeds_passed']}/{r['seeds']} ({r['share'] * 100:.0f} %)" for r in (per[n][i] for n in names)]
        lines.append(f"| {row['text']}{star} | {row['action']} | {checks.get(row['text'], '')} | "
                     + " | ".join(cells) + " |")
    summary = []
    for n in names:
        k = sum(r["seeds_passed"] for r in per[n])
        m = sum(r["seeds"] for r in per[n])
        marked = [r for r in per[n] if r["action"] in GENERAL_TARGET_ACTIONS]
        summary.append(f"{n} {k}/{m} seeds ({k / m * 100:.0f} %), marked prompts at >= "
                       f"{GENERAL_PASS_SHARE * 100:.0f} %: {sum(r['passed'] for r in marked)}/{len(marked)}"
                       if m else f"{n} -")
    return lines + ["", "Seeds passing every check of their prompt: " + "; ".join(summary) + ".", ""]


#: Columns of the real-capture per-clip table.
_CLIP_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("frames", "frames", "{:.0f}"),
    ("stance_slide_mean_ms", "stance slide (m/s)", "{:.3f}"),
    ("low_swing_mean_ms", "low swing (m/s)", "{:.3f}"),
    ("gmd_skate_ratio", "GMD skate ratio", "{:.3f}"),
    ("physdiff_err_mm", "Phys-Err (mm)", "{:.1f}"),
    ("stance_float_cm", "stance float (cm)", "{:.2f}"),
    ("penetration_p99_cm", "penetration p99 (cm)", "{:.2f}"),
    ("flight_fit_accel_ms2", "flight fit (m/s^2)", "{:.1f}"),
    ("flight_segments", "flight segments", "{:.0f}"),
)
