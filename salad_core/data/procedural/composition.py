"""Composing actions into clips: sequences, layering, repetition, and the plan sampler.

A :class:`Plan` is a sequence of :class:`Step` s ("X, then Y"); each step has a main action and
optionally a gesture layered on it ("X while Y"); an optional overlay gesture spans the whole
sequence ("X and then Y, while Z"). :func:`realise` turns a plan into joints: base segments are
chained (each starts where the previous one left the feet), standing idles fill the gaps, and
gestures replace the base arm motion with cross-fades and add head motion. Every action's frame
interval and body parts are recorded as an :class:`Event`: the ground truth of the captions.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .carriage import FREE_ARM_KINDS, apply_carriage, sample_carriages
from .curves import min_jerk, smooth, wrap_angle
from .fidgets import ARM_FIDGET_KINDS, UPPER_FIDGET_KINDS, step_fidgets
from .footwork import ANKLE_HEIGHT, TOE_HEIGHT, Persona, Stance, max_pelvis_height
from .gestures import Gesture
from .kinematics import FPS, BodyModel, Pose, assemble, body_model, heading_vectors, rot_y, ypr_matrix
from .primitives import PRIMITIVES, Action, build_base, build_gesture, primitive_parts
from .reach import arm_controls_for, nearest_controls
from .segment import Segment, standing_pose

__all__ = ["Step", "Plan", "Event", "Clip", "realise", "sample_action", "sample_plan", "generate_clip",
           "MIN_FRAMES", "MAX_FRAMES", "PLAN_TYPES"]

#: Joint frames of a clip: features have one row fewer, and HumanML3D keeps 40..196 rows.
MIN_FRAMES, MAX_FRAMES = 41, 197
#: Plan shapes and how often the sampler draws them (short clips dominate).
#: Corpus 2.0 draws more sequences and layers than 1.0 (0.35 / 0.19 / 0.25 / 0.15 / 0.02 / 0.04), whose
#: captions had no connective in half the cases.
#: Corpus 2.1 draws longer sequences (three and four co-articulated actions): a clip that goes
#: through several poses spreads its joints further (2.0's within-clip spread was 4.1 cm, 12 %
#: of its single-action clips under 2.5 cm; the real clip 9.7).
#: Corpus 2.4 draws longer plans again (one-action clips spread 4.2 cm, four-action ones 6.6; clips
#: averaged 4.5 s where HumanML3D's run 2-10 s, 7.1 s on average): 5.6 s on average now.
#: Corpus 2.5 shifts the draw again towards three and four actions (0.57, was 0.43) and away from
#: one-action clips (0.17, was 0.27), whose joints spread 4 cm against 6-7 for a sequence: 5.8 s.
PLAN_TYPES = {"single": 0.06, "gesture": 0.03, "layered": 0.08, "sequence": 0.2, "sequence3": 0.3,
              "sequence4": 0.27, "overlay": 0.06}


@dataclass(frozen=True)
class Step:
    """One element of a sequence: a main action and an optional gesture layered on it."""

    main: Action
    layer: Action | None = None

    def __post_init__(self) -> None:
        if self.layer is None:
            return
        layer, main = self.layer.spec, self.main.spec
        if layer.track != "gesture":
            raise ValueError(f"Step.layer must be a gesture, got {self.layer.kind!r} ({layer.track})")
        if main.track == "base" and layer.category not in main.accepts:
            raise ValueError(f"a {layer.category} gesture ({self.layer.kind!r}) cannot be layered on "
                             f"{self.main.kind!r}; it accepts {main.accepts or 'nothing'}")
        if main.track == "gesture" and (main.category == layer.category):
            raise ValueError(f"Step: {self.main.kind!r} and {self.layer.kind!r} drive the same parts")


@dataclass(frozen=True)
class Plan:
    """What a clip shows."""

    steps: tuple[Step, ...]
    overlay: Action | None = None   # a gesture spanning the whole sequence

    def __post_init__(self) -> None:
        if not self.steps:
            raise ValueError("Plan.steps must hold at least one step")
        for i, s in enumerate(self.steps[:-1]):
            if s.main.spec.terminal:
                raise ValueError(f"Plan step {i} ({s.main.kind!r}) must end the plan")
        for i, s in enumerate(self.steps[1:], 1):
            if s.main.spec.initial:
                raise ValueError(f"Plan step {i} ({s.main.kind!r}) must start the plan")
        if self.overlay is not None:
            if self.overlay.spec.category != "arms":
                raise ValueError(f"Plan.overlay must be an arm gesture, got {self.overlay.kind!r}")
            bad = [s.main.kind for s in self.steps if s.layer is not None or "arms" not in s.main.spec.accepts]
            if bad:
                raise ValueError(f"an overlay needs steps that take arm gestures and have no layer; not {bad}")

    def actions(self) -> list[tuple[str, int, Action]]:
        """``(role, step, action)`` in caption order: main and layer per step, then the overlay."""
        out = []
        for i, s in enumerate(self.steps):
            out.append(("main", i, s.main))
            if s.layer is not None:
                out.append(("layer", i, s.layer))
        if self.overlay is not None:
            out.append(("overlay", -1, self.overlay))
        return out

    def mirrored(self) -> "Plan":
        steps = tuple(Step(s.main.mirrored(), None if s.layer is None else s.layer.mirrored()) for s in self.steps)
        return Plan(steps, None if self.overlay is None else self.overlay.mirrored())


@dataclass(frozen=True)
class Event:
    """Where and what one action of a clip is."""

    role: str                       # "main", "layer" or "overlay"
    step: int                       # step index (-1 for the overlay)
    action: Action
    frames: tuple[int, int]         # joint frames [f0, f1)
    parts: tuple[str, ...]          # body parts the action drives
    secondary: tuple[str, ...]      # parts it moves incidentally
    info: dict


@dataclass
class Clip:
    """A realised plan."""

    joints: np.ndarray              # (N, J, 3) float64
    plan: Plan
    events: list[Event]             # in the order of plan.actions()
    persona: Persona

    @property
    def num_frames(self) -> int:
        return self.joints.shape[0]


# ----------------------------------------------------------------------------- realisation
def _arms_of(action: Action | None) -> set[str]:
    if action is None or action.spec.category != "arms":
        return set()
    return set(primitive_parts(action)[0])


def _blend(pose: Pose, g: Gesture, at: int) -> None:
    """Lay gesture ``g`` over ``pose`` from frame ``at`` (in place)."""
    sl = slice(at, at + g.num_frames)
    w = g.arm_weight[:, :, None]
    pose.arm[sl] = (1.0 - w) * pose.arm[sl] + w * g.arm
    pole = (1.0 - w) * pose.arm_pole[sl] + w * g.arm_pole
    pose.arm_pole[sl] = pole / np.linalg.norm(pole, axis=-1, keepdims=True)
    pose.neck[sl] += g.neck
    pose.spine[sl] += g.spine


def _idle(stance: Stance, persona: Persona, n: int, body: BodyModel, rng) -> Segment:
    return Segment(standing_pose(stance, persona, n, body, rng, idle=True), stance, (0, n))


def _rest_seated(last: Pose, n: int, rng) -> Segment:
    """Stay seated for ``n`` frames (the last pose, breathing)."""
    p = last.slice(last.num_frames - 1, last.num_frames)
    pose = Pose.concat([p] * n)
    t = np.arange(n) / FPS
    pose.spine[:, 1] += 0.01 * np.sin(2 * np.pi * rng.uniform(0.2, 0.3) * t)
    return Segment(pose, None, (0, n), arms_free=False, seated=True)


def _frames(seconds: tuple[float, float], rng) -> int:
    return int(round(rng.uniform(*seconds) * FPS))


#: Frames by which the next action may begin before the previous one's core has ended.
OVERLAP_FRAMES = (2, 9)
#: Pose fields cross-faded where two segments overlap (the feet follow their own rule).
_BODY_FIELDS = ("pelvis", "pelvis_ypr", "spine", "neck", "trunk", "arm", "arm_pole", "knee_pole")


def _join(acc: Pose, nxt: Pose, overlap: int) -> Pose:
    """``acc`` followed by ``nxt``, their last / first ``overlap`` frames cross-faded.

    With ``overlap == 1`` the single shared frame is ``nxt``'s first (segments chained from
    standing share it exactly). Over a longer overlap the body controls blend with a min-jerk
    weight, so the body keeps moving from one action into the next (co-articulation); each foot
    keeps the earlier segment's track until the next segment moves it: both segments hold it
    planted on the same stance there, so the blend cannot make it slide.
    """
    overlap = int(np.clip(overlap, 1, min(acc.num_frames, nxt.num_frames)))
    head = acc.slice(0, acc.num_frames - overlap)
    a, b = acc.slice(acc.num_frames - overlap, acc.num_frames), nxt.slice(0, overlap)
    w = min_jerk((np.arange(overlap) + 1.0) / overlap)
    mid = b.copy()
    for name in _BODY_FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        ww = w.reshape((-1,) + (1,) * (x.ndim - 1))
        if name == "pelvis_ypr":
            d = y - x
            d[:, 0] = wrap_angle(d[:, 0])
            setattr(mid, name, x + ww * d)
        else:
            setattr(mid, name, (1.0 - ww) * x + ww * y)
    for k in range(2):
        moved = (np.linalg.norm(b.ankle[:, k] - nxt.ankle[0, k], axis=-1)
                 + np.linalg.norm(b.toe[:, k] - nxt.toe[0, k], axis=-1)) > 1e-6
        own = np.cumsum(moved) > 0                      # once the next segment moves a foot, it owns it
        mid.ankle[:, k] = np.where(own[:, None], b.ankle[:, k], a.ankle[:, k])
        mid.toe[:, k] = np.where(own[:, None], b.toe[:, k], a.toe[:, k])
    norm = np.linalg.norm(mid.arm_pole, axis=-1, keepdims=True)
    mid.arm_pole = mid.arm_pole / np.maximum(norm, 1e-9)
    # a blend of two reachable pelvis heights over the same loaded feet may still over-reach
    loaded = (mid.ankle[..., 1] < 0.15)
    bound = max_pelvis_height(mid.pelvis, ypr_matrix(mid.pelvis_ypr), mid.ankle, body_model("humanml3d"),
                              planted=loaded) - 0.004
    mid.pelvis[:, 1] = np.minimum(mid.pelvis[:, 1], bound)
    return Pose.concat([head, mid, nxt.slice(overlap, nxt.num_frames)])


def _feet_handover(acc: Pose, nxt: Pose, overlap: int) -> int:
    """The largest overlap up to ``overlap`` at which :func:`_join` hands each foot over cleanly.

    :func:`_join` keeps a foot on the earlier segment's track until the next segment moves it;
    if the next one moves a foot before the earlier one has put it down where the next starts
    it (a pivot still turning its feet when a walk's first step begins), the foot would jump
    (2.3: a pivot then a quick walk moved a resting toe 30 cm in one frame). Shorter overlaps
    are tried until every foot the next segment moves inside the overlap is already still there.
    """
    for ov in range(int(overlap), 1, -1):
        a = acc.slice(acc.num_frames - ov, acc.num_frames)
        ok = True
        for k in range(2):
            moved = (np.linalg.norm(nxt.ankle[:ov, k] - nxt.ankle[0, k], axis=-1)
                     + np.linalg.norm(nxt.toe[:ov, k] - nxt.toe[0, k], axis=-1)) > 1e-6
            if not moved.any():
                continue
            first = int(np.argmax(moved))
            gap = (np.linalg.norm(a.ankle[:first + 1, k] - nxt.ankle[0, k], axis=-1)
                   + np.linalg.norm(a.toe[:first + 1, k] - nxt.toe[0, k], axis=-1))
            if gap[-1] > 1e-6:
                ok = False
                break
        if ok:
            return ov
    return 1


def _wander(n: int, rng: np.random.Generator, dims: int, period: tuple[float, float] = (1.2, 3.0)) -> np.ndarray:
    """``(n, dims)`` smooth zero-mean noise of unit std: a sum of three random sines per dim."""
    t = np.arange(n) / FPS
    out = np.zeros((n, dims))
    for _ in range(3):
        f = 1.0 / rng.uniform(*period, size=dims)
        ph = rng.uniform(0, 2 * np.pi, size=dims)
        out += np.sin(2 * np.pi * f[None] * t[:, None] + ph[None]) * rng.uniform(0.5, 1.0, size=dims)[None]
    return out / np.sqrt(1.5)


def _alive(pose: Pose, persona: Persona, rng: np.random.Generator, propped: np.ndarray | None = None,
           gesture_arms: np.ndarray | None = None, head_calm: np.ndarray | None = None) -> None:
    """Lay the performer's posture and a low-frequency wander of the joint angles on ``pose``.

    Posture (slouch, sideways tilt, arm asymmetry) is constant over the clip; the wander
    (trunk, head, arms; amplitude set by ``persona.liveliness``) keeps held poses from freezing.
    Neither touches the pelvis position or the feet, so contact and reach are unchanged.
    ``propped`` ``(N,)`` in [0, 1]: where the hands hold the body up (sitting back on them, on all
    fours) the trunk wanders a tenth as much (2.2; a quarter before the wider postures), so the hands stay within reach of the floor.
    ``gesture_arms`` ``(N, 2)`` in [0, 1]: where a gesture drives an arm, the persona's per-arm
    carriage offsets (``arm_offsets``) fade out, so claps still meet and salutes reach the brow.
    ``head_calm`` ``(N,)`` in [0, 1]: where a head gesture is annotated the arms wander half as
    much (a turn of the head is the slowest annotated motion; the idle arms must not out-move it).
    """
    n = pose.num_frames
    live = persona.liveliness
    trunk = 1.0 if propped is None else (1.0 - 0.9 * smooth(np.asarray(propped, dtype=np.float64), 4.0))[:, None]
    pose.spine[:, 1] += persona.slouch * trunk[:, 0] if propped is not None else persona.slouch
    pose.neck[:, 1] -= 0.5 * persona.slouch               # the gaze stays level
    pose.spine[:, 2] += persona.tilt * trunk[:, 0] if propped is not None else persona.tilt
    pose.spine[:, 0] += persona.twist * trunk[:, 0] if propped is not None else persona.twist
    pose.arm[:, 0, 0] += 0.5 * persona.arm_asym
    pose.arm[:, 1, 0] -= 0.5 * persona.arm_asym
    free = np.ones((n, 2)) if gesture_arms is None else 1.0 - np.clip(gesture_arms, 0.0, 1.0)
    pose.arm += free[:, :, None] * np.asarray(persona.arm_offsets, dtype=np.float64)[None]
    # amplitudes (rad, std) small enough that a resting arm or head stays well below an
    # annotated action's part speed (the phrase-activity checks), large enough to never freeze
    # (2.1: about twice 2.0's, whose spine and head rotations varied 0.5-0.6x as much as real ones)
    noise = _wander(n, rng, 12, period=(1.8, 4.0)) * live
    pose.spine += noise[:, 0:3] * np.array([0.1, 0.12, 0.11]) * trunk
    pose.neck += noise[:, 3:6] * np.array([0.1, 0.07, 0.05])
    # 2.3: each trunk segment its own curvature and its own slow wander (lumbar, thoracic, neck and
    # head do not bend in lockstep); the spine joints' wander is weighted towards the upper back,
    # whose bend moves no spine joint (the chest turns on spine3) and so cannot out-move an action
    pose.trunk += np.asarray(persona.trunk_posture, dtype=np.float64)[None] * (trunk if propped is None else trunk[:, :, None])
    seg = _wander(n, rng, 15, period=(1.5, 4.0)).reshape(n, 5, 3) * live
    amp = np.array([[0.04, 0.05, 0.04], [0.06, 0.07, 0.06], [0.14, 0.13, 0.11], [0.06, 0.07, 0.06], [0.03, 0.04, 0.03]])
    pose.trunk += seg * amp[None] * (trunk if propped is None else trunk[:, :, None])
    arm_scale = 1.0 if head_calm is None else (1.0 - 0.5 * np.clip(head_calm, 0.0, 1.0))[:, None]
    pose.arm[:, :, 0] += noise[:, 6:8] * 0.035 * arm_scale
    pose.arm[:, :, 1] += noise[:, 8:10] * 0.025 * arm_scale
    pose.arm[:, :, 2] = np.maximum(pose.arm[:, :, 2] + noise[:, 10:12] * 0.05 * arm_scale, 0.02)


#: Std (rad, at liveliness 1) of the slow posture drift of :func:`_drift`: spine (yaw, pitch, roll),
#: neck (yaw, pitch), arms (flexion, abduction), both arms together (out/in, to one side); and its
#: periods (s). 2.6: spine, neck and arms larger (2.5: 0.09/0.1/0.07, 0.12/0.06, 0.16/0.08) and the pair.
DRIFT_AMP = {"spine": (0.15, 0.16, 0.11), "neck": (0.16, 0.08), "arm": (0.2, 0.09), "arm_pair": (0.12, 0.1)}
DRIFT_PERIOD = (4.0, 9.0)


def _drift(pose: Pose, persona: Persona, rng: np.random.Generator, propped: np.ndarray | None = None,
           gesture_arms: np.ndarray | None = None, head_calm: np.ndarray | None = None) -> None:
    """Lay a slow drift of the posture on ``pose`` (in place): the trunk leans and turns, the head
    turns and the free arms settle forward or back over seconds (2.5).

    Real performers do not hold one carriage through a clip: between and during actions they
    shift their weight, lean, let the arms drift. :func:`_alive`'s wander is quicker and smaller
    (periods 1.5-4 s); this one is slow (:data:`DRIFT_PERIOD`), so its joint speeds stay a few
    cm/s (well under any annotated action's) while the pose moves by several centimetres. Each
    channel draws its own phase, so trunk, head and the two arms drift independently.
    ``propped``, ``gesture_arms`` and ``head_calm`` limit it as in :func:`_alive`: a trunk held up
    by the hands drifts a tenth as much, an arm a gesture drives not at all (claps meet, salutes
    reach the brow), and during a head gesture the arms stay and the trunk drifts a third as much.
    """
    n = pose.num_frames
    live = persona.liveliness
    noise = _wander(n, rng, 9, period=DRIFT_PERIOD) * live
    # 2.6: a trunk whose hands hold something drifts not at all (the larger 2.6 drift carried a
    # hand on the floor 6 mm into it through the re-solved arm's blend)
    trunk = np.ones(n) if propped is None else np.clip(1.0 - 1.5 * smooth(np.asarray(propped, dtype=np.float64), 4.0), 0.0, 1.0)
    calm = np.zeros(n) if head_calm is None else np.clip(head_calm, 0.0, 1.0)
    trunk = trunk * (1.0 - 0.67 * calm)
    pose.spine += noise[:, 0:3] * np.asarray(DRIFT_AMP["spine"])[None] * trunk[:, None]
    pose.neck[:, :2] += noise[:, 3:5] * np.asarray(DRIFT_AMP["neck"])[None] * (1.0 - 0.67 * calm)[:, None]
    free = np.ones((n, 2)) if gesture_arms is None else 1.0 - np.clip(gesture_arms, 0.0, 1.0)
    free = free * (1.0 - calm)[:, None]
    pose.arm[:, :, 0] += noise[:, 5:7] * DRIFT_AMP["arm"][0] * free
    # 2.6: the two arms also drift together: both elbows out or in (hands to the hips, arms
    # loosely akimbo) and both hands to one side (the shoulders' line turns, one arm across the
    # body): directions in which the arms of the corpus hardly varied (0.5 % and 1.6 % of the
    # pose variance, against 5-9 % for the gestures' arm-forward and arm-swing directions)
    both = _wander(n, rng, 2, period=DRIFT_PERIOD) * live
    sym = both[:, 0] * DRIFT_AMP["arm_pair"][0]
    side = both[:, 1] * DRIFT_AMP["arm_pair"][1]
    d_abd = noise[:, 7:9] * DRIFT_AMP["arm"][1] + np.stack([sym + side, sym - side], 1)
    # abduction: the drift may not carry a hanging arm into the body (below 0.02 rad), but an arm
    # a pose already holds across it (a salute, a hand on the chest) keeps its own, continuous
    abd = pose.arm[:, :, 1]
    pose.arm[:, :, 1] = np.maximum(abd + d_abd * free, np.minimum(abd, 0.02))
    # the arm the other one reaches across to comes forward a little (the hand passes in front)
    pose.arm[:, :, 0] += 0.8 * np.maximum(-np.stack([side, -side], 1), 0.0) * free


#: The lower-body postures of :func:`_settle` (2.6): per posture key, the chance of each kind and
#: the ranges of its parameters. ``shift``: the fraction of the way from the feet's midpoint to
#: the loaded foot that the pelvis travels (weight on one leg); ``drop``: how far the pelvis sinks
#: (m, knees bending); ``hinge``: forward pitch of the pelvis (rad, hips back, trunk over the feet).
SETTLE_KINDS = {"neutral": 0.2, "weight": 0.4, "soft": 0.15, "hinge": 0.25}
SETTLE_RANGE = {"shift": (0.5, 0.95), "drop": (0.02, 0.06), "hinge": (0.18, 0.45), "hinge_drop": (0.03, 0.07)}
#: Seconds a posture is held and the transitions between postures take.
SETTLE_HOLD, SETTLE_MOVE = (1.2, 3.2), (0.9, 1.6)
#: Largest pelvis travel (m) of a weight shift, and the pelvis's travel back (m per rad) under a hinge.
SETTLE_MAX_SHIFT, SETTLE_BACK = 0.13, 0.16


def _settle_mask(pose: Pose, body: BodyModel, hands: np.ndarray | None) -> np.ndarray:
    """``(N,)`` in [0, 1]: where both feet stand still and flat and the body stands upright and
    slowly, eroded so that it is 0 for a while before and after any foot moves, and smoothed."""
    n = pose.num_frames
    if n < 3:
        return np.zeros(n)
    still = np.ones(n, dtype=bool)
    for k in range(2):
        d = (np.linalg.norm(np.diff(pose.ankle[:, k], axis=0), axis=-1)
             + np.linalg.norm(np.diff(pose.toe[:, k], axis=0), axis=-1))
        moving = np.concatenate([[False], d > 1e-6]) | np.concatenate([d > 1e-6, [False]])
        flat = np.abs((pose.ankle[:, k, 1] - pose.toe[:, k, 1]) - (ANKLE_HEIGHT - TOE_HEIGHT)) < 2e-3
        still &= ~moving & flat
    sp = np.linalg.norm(np.diff(pose.pelvis, axis=0), axis=-1) * FPS
    sp = np.concatenate([sp[:1], sp])
    still &= sp < 0.3
    stand = max_pelvis_height(pose.pelvis, ypr_matrix(pose.pelvis_ypr), pose.ankle, body, reach=0.975)
    still &= pose.pelvis[:, 1] > stand - 0.05
    still &= np.abs(pose.pelvis_ypr[:, 1]) < 0.25
    if hands is not None:
        still &= np.asarray(hands) < 1e-3
    # erode: the posture is back before a foot leaves (and only starts once both stand)
    k = 10
    pad = np.pad(still.astype(np.float64), k, mode="edge")
    er = np.lib.stride_tricks.sliding_window_view(pad, 2 * k + 1).min(-1)
    # smoothed over about 0.4 s; exactly 0 from a few frames inside the eroded margin
    return np.clip((smooth(er, 3.0) - 0.02) / 0.98, 0.0, 1.0)


def _settle_keys(n: int, rng: np.random.Generator, live: float) -> np.ndarray:
    """``(n, 3)`` (shift, drop, hinge): held lower-body postures joined by min-jerk moves."""
    t = np.arange(n) / FPS
    kinds = list(SETTLE_KINDS)
    p = np.asarray(list(SETTLE_KINDS.values()))
    out = np.zeros((n, 3))
    cur = np.zeros(3)
    at = -rng.uniform(0.0, 1.5)            # the clip opens in whatever posture the performer was in
    first = True
    while at < t[-1]:
        kind = kinds[int(rng.choice(len(kinds), p=p / p.sum()))]
        u = rng.uniform
        key = np.zeros(3)
        if kind == "weight":
            key[0] = u(*SETTLE_RANGE["shift"]) * (1.0 if rng.random() < 0.5 else -1.0)
            key[1] = u(0.0, 0.02)
        elif kind == "soft":
            key[1] = u(*SETTLE_RANGE["drop"])
            key[0] = u(-0.2, 0.2)
        elif kind == "hinge":
            key[2] = u(*SETTLE_RANGE["hinge"])
            key[1] = u(*SETTLE_RANGE["hinge_drop"])
            key[0] = u(-0.3, 0.3)
        key *= live
        key[0] = np.clip(key[0], -1.0, 1.0)
        move = 0.0 if first else u(*SETTLE_MOVE)
        first = False
        a, b = at, at + move
        w = min_jerk(np.clip((t - a) / max(b - a, 1e-9), 0.0, 1.0))[:, None] if move > 0 else (t >= a)[:, None] * 1.0
        out = np.where((t >= a)[:, None], cur[None] + (key - cur)[None] * w, out)
        cur = key
        at = b + u(*SETTLE_HOLD)
    return out


def _settle(pose: Pose, persona: Persona, body: BodyModel, rng: np.random.Generator,
            hands: np.ndarray | None = None, head_calm: np.ndarray | None = None) -> np.ndarray:
    """Let the performer settle into lower-body postures while standing (in place; 2.6).

    Where both feet stand still and flat (:func:`_settle_mask`) the pelvis moves between held
    postures (:func:`_settle_keys`): the weight onto one leg (the pelvis travels towards that
    foot, the hip on the unloaded side drops, the trunk leans back over the feet), soft knees (the
    pelvis sinks a few cm), or a hinge at the hips (the pelvis pitches forward and goes back, the
    trunk leans forward less and the gaze stays level). The feet are not touched: the legs reach
    them by IK, the pelvis is kept within their reach, so they stay planted exactly. Changes take
    about a second (the legs move at a few cm/s, far under any annotated action's part speed)
    and fade out before a foot leaves the floor; under a head gesture a third as much.

    Returns the ``(N, 3)`` (shift, drop, hinge) actually laid on (after the mask).
    """
    n = pose.num_frames
    m = _settle_mask(pose, body, hands)
    # scaled by the performer's liveliness (0: a frozen performer does not settle)
    keys = _settle_keys(n, rng, float(np.clip(persona.liveliness, 0.0, 1.4)))
    if head_calm is not None:
        m = m * (1.0 - 0.67 * np.clip(head_calm, 0.0, 1.0))
    keys = keys * m[:, None]
    if not m.any():
        return keys
    yaw = pose.pelvis_ypr[:, 0]
    fwd, left = heading_vectors(yaw)
    mid = 0.5 * (pose.ankle[:, 0] + pose.ankle[:, 1])
    shift = keys[:, 0]
    # towards the left foot for shift > 0, the right for shift < 0
    to = np.where((shift >= 0)[:, None], pose.ankle[:, 0] - mid, pose.ankle[:, 1] - mid)
    to[:, 1] = 0.0
    norm = np.linalg.norm(to, axis=-1, keepdims=True)
    travel = np.minimum(np.abs(shift)[:, None] * norm, SETTLE_MAX_SHIFT)
    move = to / np.maximum(norm, 1e-9) * travel
    lateral = (move * left).sum(-1)                      # + towards the body's left
    hinge = keys[:, 2]
    pose.pelvis += move - fwd * (SETTLE_BACK * hinge)[:, None]
    pose.pelvis[:, 1] -= keys[:, 1]
    pose.pelvis_ypr[:, 1] += hinge
    pose.pelvis_ypr[:, 2] -= 1.2 * lateral               # the hip drops on the unloaded side
    pose.spine[:, 2] += 1.8 * lateral                    # the trunk leans back over the feet
    pose.spine[:, 1] -= 0.45 * hinge                     # the chest leans forward by about half
    pose.neck[:, 1] -= 0.35 * hinge                      # and the head keeps the gaze
    planted = np.ones((n, 2), dtype=bool)
    bound = max_pelvis_height(pose.pelvis, ypr_matrix(pose.pelvis_ypr), pose.ankle, body, planted=planted) - 0.004
    pose.pelvis[:, 1] = np.where(m > 0, np.minimum(pose.pelvis[:, 1], bound), pose.pelvis[:, 1])
    return keys


def _share_spine(pose: Pose, persona: Persona) -> None:
    """Redistribute the spine's bend over spine1-3 by the performer's own shares (in place).

    :func:`.kinematics.assemble` shares ``pose.spine`` by the fixed :data:`.kinematics.SPINE_SHARE`;
    the difference to ``persona.spine_share`` goes to the per-joint ``pose.trunk``. The shares sum
    to one, so the chest ends up turned (nearly) as before and held hands are re-solved after.
    """
    if persona.spine_share is None:
        return
    from .kinematics import SPINE_SHARE

    extra = np.asarray(persona.spine_share, dtype=np.float64) - np.asarray(SPINE_SHARE, dtype=np.float64)[:, None]
    pose.trunk[:, :3] += extra[None] * pose.spine[:, None, :]


#: Body speed (m/s) above which a stretch of motion needs no extra liveliness (see :func:`_hold_mask`).
HOLD_SPEED = 0.2
#: Scale of the extra hold motion of the parts a head gesture does not drive, during it: a turn of
#: the head is the slowest annotated motion, and the trunk and arms must not out-move it.
_HEAD_EVENT_CALM = 0.5


def _hold_mask(pose: Pose, body: BodyModel, calm: list[tuple[int, int]]) -> np.ndarray:
    """``(N, 3)`` weights in [0, 1] (trunk, head, arms) of the extra motion of :func:`_lively_holds`.

    It is near 1 where the body is held (mean joint speed well under :data:`HOLD_SPEED`) and
    upright, 0 where it already moves or lies (a trunk that sways there could touch the floor),
    smoothed over about 0.5 s so that it fades in and out. Inside the frame intervals ``calm``
    (head gestures) the arms get none and the trunk :data:`_HEAD_EVENT_CALM` of it.
    """
    j = assemble(pose, body)
    n = len(j)
    sp = np.linalg.norm(np.diff(j, axis=0), axis=-1).mean(-1) * FPS
    sp = np.concatenate([sp[:1], sp]) if n > 1 else np.zeros(n)
    still = np.clip(1.0 - sp / HOLD_SPEED, 0.0, 1.0)
    sp3 = body.j("spine3")
    trunk = j[:, sp3] - j[:, 0]
    upright = np.clip((trunk[:, 1] / np.maximum(np.linalg.norm(trunk, axis=-1), 1e-9) - 0.75) / 0.2, 0.0, 1.0)
    k = 11
    head = np.zeros(n)
    for f0, f1 in calm:             # widened by half the smoothing so it is whole inside the interval
        head[max(0, f0 - k // 2):max(0, f1 + k // 2)] = 1.0
    ker = np.hanning(k + 2)[1:-1]
    ker /= ker.sum()

    def smooth(x):
        return np.convolve(np.pad(x, k // 2, mode="edge"), ker, mode="valid")

    w = np.clip(smooth(still * upright), 0.0, 1.0)
    head = np.clip(smooth(head), 0.0, 1.0)
    # a low pelvis (sitting, kneeling) may rest the hands on the floor: they stay there
    low = np.clip(smooth((j[:, 0, 1] - 0.45) / 0.2), 0.0, 1.0)
    # (trunk, head, arms): during a head gesture the arms stay put and the trunk nearly so
    return np.stack([w * (1.0 - (1.0 - _HEAD_EVENT_CALM) * head), w, w * (1.0 - head) * low], 1)


def _lively_holds(pose: Pose, weight: np.ndarray, persona: Persona, rng: np.random.Generator) -> None:
    """Add a slow sway of the trunk, head and arms where ``weight`` ``(N, 3)`` (trunk, head, arms)
    says the body is held.

    Real performers are never still between and inside actions (the real sample has 3 % of its
    frames under 5 cm/s): the trunk rocks and twists a little, the arms drift and the head moves.
    The feet and the pelvis position are untouched, so contact and reach are unchanged.
    """
    n = pose.num_frames
    live = np.sqrt(persona.liveliness) * weight     # a calm performer still sways (0: frozen)
    # amplitudes (rad, std at liveliness 1): enough to lift a held body over 5 cm/s mean joint speed
    noise = _wander(n, rng, 9, period=(1.0, 2.6))
    pose.spine += noise[:, 0:3] * live[:, 0:1] * np.array([0.10, 0.11, 0.09])
    pose.neck += (noise[:, 3:5] * live[:, 1:2]) @ np.array([[0.12, 0.0, 0.0], [0.0, 0.07, 0.0]])
    arm = noise[:, 5:9] * live[:, 2:3]
    pose.arm[:, :, 0] += arm[:, 0:2] * 0.12
    pose.arm[:, :, 1] += arm[:, 2:4] * 0.05
    pose.arm[:, :, 2] = np.maximum(pose.arm[:, :, 2] + arm[:, 0:2] * 0.12, 0.02)


#: Trunk response to asymmetric arm motion: spine yaw per rad of flexion difference, spine roll
#: per rad of abduction difference (see :func:`_trunk_follows_arms`).
TRUNK_YAW_PER_FLEX, TRUNK_ROLL_PER_ABD = 0.35, 0.2


def _trunk_follows_arms(pose: Pose, persona: Persona, weight: np.ndarray | None = None) -> None:
    """Turn and bend the trunk with the arms (secondary motion, in place).

    ``weight`` ``(N, 2)`` (left, right arm; default 1) limits it to the arms of gestures: a base
    action that puts a hand at a world point (picking up, hands on the floor) must keep it there.

    An arm swung forward brings its shoulder with it (the trunk turns to the other side); an arm
    raised to the side bends the trunk a little away from it. The response is proportional to
    the difference between the arms (smoothed over about 0.3 s), so symmetric motions (jumps,
    claps) leave the trunk alone.
    """
    rest = np.asarray(persona.arm_rest, dtype=np.float64)
    # the trunk follows the held arm pose, not an oscillation (a waving hand, a gait's swing),
    # which would make an un-annotated spine move as much as the waving arm
    d = pose.arm - rest[None, None]
    if weight is not None:
        d = d * weight[:, :, None]
    d = smooth(d, 6.0)
    pose.spine[:, 0] += TRUNK_YAW_PER_FLEX * (d[:, 1, 0] - d[:, 0, 0])
    pose.spine[:, 2] -= TRUNK_ROLL_PER_ABD * (d[:, 0, 1] - d[:, 1, 1])


def _held_hands(n: int, held: list[tuple[int, tuple[np.ndarray, np.ndarray]]]) -> tuple[np.ndarray, np.ndarray]:
    """``(weights (n, 2), wrist targets (n, 2, 3))`` of the clip from its segments' held hands."""
    w, tgt = np.zeros((n, 2)), np.zeros((n, 2, 3))
    for at, (hw, ht) in held:
        m = min(len(hw), n - at)
        if m <= 0:
            continue
        sel = hw[:m] > w[at:at + m]
        w[at:at + m] = np.where(sel, hw[:m], w[at:at + m])
        tgt[at:at + m] = np.where(sel[..., None], ht[:m], tgt[at:at + m])
    if held:
        at, (hw, ht) = held[-1]
        end = at + len(hw)
        if end < n:                       # the padding after the last segment keeps its hands
            w[end:], tgt[end:] = hw[-1], ht[-1]
    return w, tgt


def _hold_hands(pose: Pose, body: BodyModel, hands: tuple[np.ndarray, np.ndarray]) -> None:
    """Put the hands of base actions back on their world points (in place).

    ``hands`` (from :func:`_held_hands`) holds the weights and world wrist targets of hands that
    touch something (the floor, a knee; :attr:`.segment.Segment.hands`). The posture and the
    wander (:func:`_alive`) turn the trunk after the segment solved its arms, which moved such
    hands by up to 6 cm (into the floor when picking up): the arms are solved again on the final
    trunk and blended in by the weights (exact at 1 when within reach). A seated segment's last
    hold carries over the seated rest that pads the clip.
    """
    w, tgt = hands
    for k in range(2):
        wk = w[:, k]
        if not (wk > 0).any():
            continue
        # 2.7: written nearest to the arm's own controls, so that the blend cannot swing the arm
        # the other way round (a hand down at the toes of a trunk folded past 90 deg)
        solved = nearest_controls(arm_controls_for(pose, body, k, tgt[:, k]), pose.arm[:, k])
        pose.arm[:, k] += wk[:, None] * (solved - pose.arm[:, k])


def _anchor(joints: np.ndarray, body: BodyModel) -> np.ndarray:
    """``joints`` moved so that frame 0's pelvis is over the origin and frame 0 faces +Z, with
    the facing HumanML3D's processing measures (hips and shoulders), as clips always started."""
    r_hip, l_hip, sdr_r, sdr_l = body.skeleton.face_joint_indx
    p0 = joints[0]
    across = (p0[r_hip] - p0[l_hip]) + (p0[sdr_r] - p0[sdr_l])
    fwd = np.cross(np.array([0.0, 1.0, 0.0]), across)
    yaw = float(np.arctan2(fwd[0], fwd[2]))
    out = joints - joints[0, 0] * np.array([1.0, 0.0, 1.0])
    return out @ rot_y(-yaw).T


#: 2.6: plans that also hold actions needing the arms carry the free arms step by step
#: (:func:`_carriage_by_step`); chance that a stepping action changes an arm's carriage.
CARRIAGE_BY_STEP, CARRIAGE_CHANGE_P = True, 0.6


#: 2.6: arm gestures whose trunk leans into them (the spine moves incidentally:
#: :func:`.primitives.primitive_parts`), and the range of the lean (yaw, pitch, roll; rad) held
#: while the arms act. Gestures that put a hand to the head keep the trunk as it is.
LEAN_KINDS = frozenset({"wave", "raise", "punch", "stretch", "clap", "arms_out", "hands_on_hips", "cross_arms",
                        "arm_circles"})
LEAN_RANGE = ((-0.3, 0.3), (-0.12, 0.35), (-0.25, 0.25))


def _lean_into(g: Gesture, action: Action, persona: Persona, rng: np.random.Generator) -> None:
    """Let the trunk lean into an arm gesture (in place; 2.6): a lean drawn from
    :data:`LEAN_RANGE` follows the gesture's arm weight in and out (whole-body reaching: a wave
    turned towards someone, a stretch bent forward, arms raised with the chest back), and the
    head turns back by about half of it so that the gaze stays where it was. The lean scales with
    ``persona.liveliness`` (a frozen performer does not lean)."""
    if action.kind not in LEAN_KINDS:
        return
    w = g.arm_weight.max(1)
    lean = np.array([rng.uniform(*r) for r in LEAN_RANGE]) * persona.liveliness
    g.spine = g.spine + w[:, None] * lean[None]
    g.neck = g.neck - w[:, None] * (lean * np.array([0.5, 0.6, 0.5]))[None]


def _carriage_by_step(pose: Pose, body: BodyModel, plan: Plan, events: dict, rng: np.random.Generator) -> None:
    """Carry each free arm step by step (in place; 2.6).

    An arm takes, changes or drops a carriage (:data:`.carriage.CARRIAGES`) only inside the core
    of a stepping action that moves the arms incidentally (:data:`.carriage.FREE_ARM_KINDS`), keeps
    it through gesture steps (a gesture takes the arms it drives from it) and lets it go over the
    first frames of any other action (its arms are driven or move incidentally there).
    """
    from .carriage import CARRIAGES, CARRY_P

    n = pose.num_frames
    t = np.arange(n, dtype=np.float64)
    for k in range(2):
        epochs: list[tuple[object, float, float]] = []     # (carriage and target or None, ramp start, ramp end)
        cur = None
        for i, step in enumerate(plan.steps):
            (f0, f1), _ = events[("main", i)]
            kind = step.main
            if kind.spec.track == "gesture":
                continue
            if kind.kind in FREE_ARM_KINDS:
                if rng.random() >= CARRIAGE_CHANGE_P or f1 - f0 < 16:
                    continue
                c = CARRIAGES[int(rng.integers(len(CARRIAGES)))] if rng.random() < CARRY_P else None
                new = None if c is None else (c, rng.uniform(c.low, c.high))
                if new is None and cur is None:
                    continue
                ramp = float(rng.uniform(10, 16))
                a = f0 + rng.uniform(0.15, 0.5) * max(0.0, f1 - f0 - ramp)
                epochs.append((new, a, a + ramp))
                cur = new
            elif cur is not None:
                ramp = float(min(10, max(3, (f1 - f0) // 3)))
                epochs.append((None, float(f0), f0 + ramp))
                cur = None
        for j, (ck, a, b) in enumerate(epochs):
            if ck is None:
                continue
            w = min_jerk(np.clip((t - a) / (b - a), 0.0, 1.0))
            if j + 1 < len(epochs):
                nxt, a2, b2 = epochs[j + 1]
                if nxt is None:
                    w = w * (1.0 - min_jerk(np.clip((t - a2) / (b2 - a2), 0.0, 1.0)))
                else:
                    w = np.where(t >= b2, 0.0, w)
            apply_carriage(pose, body, [ck if q == k else None for q in range(2)], w)


def _fidgets_of(step: Step, overlay: Action | None, seg: Segment, core: tuple[int, int], persona: Persona,
                body: BodyModel, rng: np.random.Generator) -> list[tuple[int, Gesture]]:
    """Unnamed fidgets (:mod:`.fidgets`) of a stepping step, on the parts it moves incidentally
    and no gesture of the plan takes: arms not driven by its layer or the overlay and holding
    nothing, the head unless a head gesture is layered on the step, the trunk."""
    secondary = primitive_parts(step.main)[1]
    taken = _arms_of(step.layer) | _arms_of(overlay)
    arms = ()
    if step.main.kind in ARM_FIDGET_KINDS and seg.hands is None and seg.arms_free:   # 2.7: not a side lunge's reach
        arms = tuple(k for k, a in enumerate(("left arm", "right arm")) if a in secondary and a not in taken)
    head = "head" in secondary and (step.layer is None or step.layer.spec.category != "head")
    return step_fidgets(persona, body, rng, core, arms, head, "spine" in secondary)


def realise(plan: Plan, rng: np.random.Generator, body: BodyModel | None = None,
            persona: Persona | None = None, min_frames: int = MIN_FRAMES) -> Clip:
    """Build the joints and events of ``plan`` (random choices from ``rng``).

    Consecutive actions are co-articulated: the next segment starts while the previous one is
    still finishing and their body controls cross-fade (:func:`_join`), so a sequence does not
    pass through a dead stop. The clip starts near the first action's onset and stops shortly
    after the last one ends (mid-motion, in whatever pose it ends), padded with a lively stand
    (or seated rest) only as far as ``min_frames`` and the gestures need.
    """
    body = body or body_model("humanml3d")
    persona = persona or Persona.sample(rng)
    # the fidgets draw from a stream of their own: how many there are does not change the rest
    fidget_rng = np.random.default_rng(int(rng.integers(2 ** 62)))
    stance = Stance.at((0.0, 0.0), 0.0, persona)
    overlay_arms = _arms_of(plan.overlay)
    acc: Pose | None = None
    prev_tail = 0                                   # frames of the last segment after its core

    def append(seg: Segment, core: tuple[int, int]) -> int:
        """Append a segment overlapping the previous one's tail; return its offset."""
        nonlocal acc, prev_tail
        if acc is None:
            acc = seg.pose.copy()
            prev_tail = seg.num_frames - core[1]
            return 0
        extra = int(rng.integers(OVERLAP_FRAMES[0], OVERLAP_FRAMES[1] + 1))
        overlap = prev_tail + core[0] + extra
        overlap = int(np.clip(overlap, 1, min(acc.num_frames - 1, seg.num_frames - 1)))
        overlap = _feet_handover(acc, seg.pose, overlap)
        at = acc.num_frames - overlap
        acc = _join(acc, seg.pose, overlap)
        prev_tail = seg.num_frames - core[1]
        return at

    placed: list[tuple[int, Gesture]] = []
    fidgets: list[tuple[int, Gesture]] = []        # unnamed secondary motion (no events)
    held_hands: list[tuple[int, tuple[np.ndarray, np.ndarray]]] = []   # (offset, Segment.hands)
    events: dict[tuple[str, int], tuple[tuple[int, int], dict]] = {}
    seated = False
    for i, step in enumerate(plan.steps):
        main = step.main
        if main.spec.track == "base":
            arm_layer = bool(_arms_of(step.layer) or overlay_arms)
            seg = build_base(main, stance, persona, body, rng, keep_arms=arm_layer)
            seated = seg.seated
            at = append(seg, seg.core)
            if seg.hands is not None:
                held_hands.append((at, seg.hands))
            core = (at + seg.core[0], at + seg.core[1])
            events[("main", i)] = (core, seg.info)
            stance = seg.end
            if main.kind in UPPER_FIDGET_KINDS:
                fidgets += _fidgets_of(step, plan.overlay, seg, core, persona, body, fidget_rng)
            if step.layer is not None:
                span = (core[1] - core[0]) / FPS
                g = build_gesture(step.layer, persona, body, rng, duration=span * rng.uniform(0.75, 0.92))
                _lean_into(g, step.layer, persona, fidget_rng)
                slack = max(0, core[1] - core[0] - g.num_frames)
                g_at = core[0] + int(rng.integers(0, slack + 1))
                placed.append((g_at, g))
                events[("layer", i)] = ((g_at, g_at + g.num_frames), g.info)
        else:
            g = build_gesture(main, persona, body, rng)
            _lean_into(g, main, persona, fidget_rng)
            # under a turn of the head (the slowest annotated motion) the weight shifts are calmer
            heady = main.spec.category == "head" or (step.layer is not None and step.layer.spec.category == "head")
            calm = replace(persona, sway=0.4 * persona.sway) if heady else persona
            seg = _idle(stance, calm, g.num_frames + 2, body, rng)
            at = append(seg, (1, 1 + g.num_frames))
            placed.append((at + 1, g))
            events[("main", i)] = ((at + 1, at + 1 + g.num_frames), g.info)
            if step.layer is not None:
                span = g.num_frames / FPS
                h = build_gesture(step.layer, persona, body, rng, duration=span * rng.uniform(0.7, 0.9))
                slack = max(0, g.num_frames - h.num_frames)
                h_at = at + 1 + int(rng.integers(0, slack + 1))
                placed.append((h_at, h))
                events[("layer", i)] = ((h_at, h_at + h.num_frames), h.info)
    if plan.overlay is not None:
        f0 = events[("main", 0)][0][0]
        f1 = events[("main", len(plan.steps) - 1)][0][1]
        g = build_gesture(plan.overlay, persona, body, rng, duration=(f1 - f0) / FPS)
        _lean_into(g, plan.overlay, persona, fidget_rng)
        placed.append((f0, g))
        events[("overlay", -1)] = ((f0, f0 + g.num_frames), g.info)
    # the clip opens shortly before the first action's onset (sometimes just after it) and
    # closes shortly after the last one ends: no forced stand at either end
    first = events[("main", 0)][0][0]
    s0 = int(np.clip(first - int(rng.integers(-2, 5)), 0, max(0, first + 2)))
    last = max(f1 for (f0, f1), _ in events.values())
    stop = last + int(rng.integers(1, 8))
    stop = max(stop, s0 + min_frames, max(at + g.num_frames for at, g in placed) if placed else 0)
    if stop > acc.num_frames:
        n_pad = stop - acc.num_frames + 1
        pad = _rest_seated(acc, n_pad, rng) if seated else _idle(stance, persona, n_pad, body, rng)
        acc = _join(acc, pad.pose, 1)
    pose = acc
    if all(s.main.spec.track == "gesture" or s.main.kind in FREE_ARM_KINDS for s in plan.steps):
        # free arms keep the performer's carriage (each arm its own); gestures take them from it
        apply_carriage(pose, body, sample_carriages(rng))
    elif CARRIAGE_BY_STEP:
        # 2.6: other plans carry the free arms step by step (they take a carriage while stepping,
        # keep it through gestures, let it go as an action needs the arms)
        _carriage_by_step(pose, body, plan, events, fidget_rng)
    gesture_arms = np.zeros((pose.num_frames, 2))
    for at, g in fidgets + placed:
        _blend(pose, g, at)
        sl = slice(at, at + g.num_frames)
        gesture_arms[sl] = np.maximum(gesture_arms[sl], g.arm_weight)
    _trunk_follows_arms(pose, persona, gesture_arms)
    hands = _held_hands(pose.num_frames, held_hands)
    calm = [events[(role, i)][0] for role, i, a in plan.actions() if a.spec.category == "head"]
    head_calm = np.zeros(pose.num_frames)
    for f0, f1 in calm:
        head_calm[max(0, f0 - 6):max(0, f1 + 6)] = 1.0
    _alive(pose, persona, rng, propped=hands[0].max(1), gesture_arms=gesture_arms, head_calm=smooth(head_calm, 2.0))
    # the drift draws from the fidgets' stream: the main stream's later draws stay as they were
    _drift(pose, persona, fidget_rng, propped=hands[0].max(1), gesture_arms=gesture_arms,
           head_calm=smooth(head_calm, 2.0))
    mask = _hold_mask(pose, body, calm)
    # a trunk propped on its hands sways a tenth as much (as in _alive): the hands stay within reach
    mask[:, 0] *= 1.0 - 0.9 * smooth(hands[0].max(1), 4.0)
    _lively_holds(pose, mask, persona, rng)
    # 2.6: lower-body postures while standing (weight on one leg, soft knees, a hinge at the hips)
    _settle(pose, persona, body, fidget_rng, hands=hands[0].max(1), head_calm=smooth(head_calm, 2.0))
    _share_spine(pose, persona)
    _hold_hands(pose, body, hands)
    joints = _anchor(assemble(pose, body, keep_toes=True)[s0:stop], body)

    out: list[Event] = []
    n = joints.shape[0]
    gestures_at = [(role, i, events[(role, i)][0]) for role, i, a in plan.actions() if a.spec.category == "arms"]
    for role, i, action in plan.actions():
        (f0, f1), info = events[(role, i)]
        parts, secondary = primitive_parts(action)
        if action.spec.track == "base":
            # an arm gesture covering most of this action takes its arms over
            taken: set[str] = set()
            for g_role, g_i, (g0, g1) in gestures_at:
                if (g_role == "overlay" or g_i == i) and min(f1, g1) - max(f0, g0) >= 0.5 * (f1 - f0):
                    taken |= _arms_of(plan.overlay if g_role == "overlay" else plan.steps[g_i].layer)
            parts = tuple(p for p in parts if p not in taken)
            secondary = tuple(p for p in secondary if p not in taken)
        out.append(Event(role, i, action, (max(0, f0 - s0), min(n, f1 - s0)), parts, secondary, dict(info)))
    return Clip(joints, plan, out, persona)


# ----------------------------------------------------------------------------- sampling
_HEIGHT = ("high", "low")
_SPEED = ("quickly", "slowly")
_VARIANT_P = {"walk": {"in_place": 0.12}, "jog": {"in_place": 0.2}, "march": {"in_place": 0.4},
              "jump": {"forward": 0.4}, "turn": {"around": 0.4}, "wave": {"arms": 0.3}, "throw": {"underhand": 0.35},
              "lunge": {"side": 0.45}, "swing": {"bat": 0.45}, "kick": {"side": 0.3, "back": 0.25}}
#: Chance of a speed modifier where one is allowed (1.0: 0.25, "slowly" was in 16 % of captions; 2.0: 0.2;
#: 2.1 draws longer sequences, so 0.17 keeps "slowly" and "quickly" each under 10 % of captions;
#: 2.2: 0.14, with three more primitives that take them, "slowly" was back in 12 %).
_SPEED_P = 0.14
#: Arm gestures that can last a whole sequence (an overlay).
_OVERLAYS = ("wave", "raise", "stretch", "arms_out", "clap", "hands_on_hips", "cross_arms", "arm_circles", "guard")
#: Gestures a spin does not take (a spinning body does not strike).
_NOT_ON_SPIN = ("punch", "jab_cross", "hook", "uppercut")


def _pick(rng, items, weights=None):
    items = list(items)
    if weights is None:
        return items[int(rng.integers(len(items)))]
    w = np.asarray(weights, dtype=np.float64)
    return items[int(rng.choice(len(items), p=w / w.sum()))]


def sample_action(rng: np.random.Generator, kinds: list[str]) -> Action:
    """A random action among ``kinds`` (weighted by the registry), with side, modifiers,
    repetitions and variant drawn from what the primitive allows."""
    kind = _pick(rng, kinds, [PRIMITIVES[k].weight for k in kinds])
    spec = PRIMITIVES[kind]
    variant = ""
    for v, p in _VARIANT_P.get(kind, {}).items():
        if rng.random() < p:
            variant = v
    side = _pick(rng, spec.sides)
    if kind == "wave" and variant == "arms":
        side = "both"
    mods = []
    heights = [m for m in _HEIGHT if m in spec.mods]
    speeds = [m for m in _SPEED if m in spec.mods]
    if variant in ("arms", "forward"):
        heights = []
    if heights and rng.random() < 0.38:
        mods.append(_pick(rng, heights, [2.0 if m == "high" else 1.0 for m in heights]))
    if speeds and rng.random() < _SPEED_P:
        mods.append(_pick(rng, speeds))
    reps = spec.reps[0]
    if len(spec.reps) > 1:
        reps = _pick(rng, spec.reps, [3.0 if r == spec.reps[0] else 1.0 for r in spec.reps])
    return Action(kind, side, tuple(sorted(mods)), reps, variant)


def _bases(accepting: str | None = None, terminal: bool = True, initial: bool = True) -> list[str]:
    return [k for k, s in PRIMITIVES.items() if s.track == "base" and (terminal or not s.terminal)
            and (initial or not s.initial) and (accepting is None or accepting in s.accepts)]


def _gestures(category: str | None = None) -> list[str]:
    return [k for k, s in PRIMITIVES.items() if s.track == "gesture" and (category is None or s.category == category)]


def _layer_for(rng, base: Action) -> Action | None:
    cats = base.spec.accepts
    if not cats:
        return None
    cat = _pick(rng, cats, [3.0 if c == "arms" else 1.0 for c in cats])
    kinds = [k for k in _gestures(cat) if not (base.kind == "spin" and k in _NOT_ON_SPIN)]
    return sample_action(rng, kinds)


def _step(rng, terminal: bool, allow_gesture: bool = True, layer_p: float = 0.15, initial: bool = True) -> Step:
    if allow_gesture and rng.random() < 0.25:
        main = sample_action(rng, _gestures())
        layer = None
        if main.spec.category == "arms" and rng.random() < layer_p:
            layer = sample_action(rng, _gestures("head"))
        return Step(main, layer)
    main = sample_action(rng, _bases(terminal=terminal, initial=initial))
    layer = _layer_for(rng, main) if rng.random() < layer_p else None
    return Step(main, layer)


def sample_plan(rng: np.random.Generator, plan_type: str | None = None) -> Plan:
    """A random plan; ``plan_type`` one of :data:`PLAN_TYPES` (default: drawn by its weight)."""
    if plan_type is None:
        plan_type = _pick(rng, PLAN_TYPES, list(PLAN_TYPES.values()))
    if plan_type not in PLAN_TYPES:
        raise ValueError(f"plan_type {plan_type!r} unknown; known: {', '.join(PLAN_TYPES)}")
    if plan_type == "single":
        return Plan((Step(sample_action(rng, _bases())),))
    if plan_type == "gesture":
        main = sample_action(rng, _gestures())
        head = main.spec.category == "arms" and rng.random() < 0.2
        return Plan((Step(main, sample_action(rng, _gestures("head")) if head else None),))
    if plan_type == "layered":
        base = sample_action(rng, [k for k in _bases() if PRIMITIVES[k].accepts])
        return Plan((Step(base, _layer_for(rng, base)),))
    if plan_type in ("sequence", "sequence3", "sequence4"):
        n = {"sequence": 2, "sequence3": 3, "sequence4": 4}[plan_type]
        steps: list[Step] = []
        while len(steps) < n:
            s = _step(rng, terminal=len(steps) == n - 1, initial=not steps)
            if steps and s.main.kind == steps[-1].main.kind:
                continue
            steps.append(s)
        return Plan(tuple(steps))
    # overlay: bases that take arm gestures, one arm gesture over all of them
    steps = []
    while len(steps) < 2:
        a = sample_action(rng, _bases("arms", terminal=False))
        if steps and a.kind == steps[-1].main.kind:
            continue
        steps.append(Step(a))
    over = sample_action(rng, list(_OVERLAYS))
    if over.kind == "clap":
        over = Action("clap", "both", over.mods, 1, "")   # an overlay lasts the whole sequence
    return Plan(tuple(steps), over)


def generate_clip(rng: np.random.Generator, body: BodyModel | None = None, tries: int = 30,
                  plan_type: str | None = None) -> Clip:
    """Sample plans until one realises to at most ``MAX_FRAMES`` joint frames (clips shorter
    than ``MIN_FRAMES`` are stretched with standing still by :func:`realise`)."""
    body = body or body_model("humanml3d")
    for _ in range(tries):
        plan = sample_plan(rng, plan_type)
        clip = realise(plan, rng, body)
        if clip.num_frames <= MAX_FRAMES:
            return clip
    raise RuntimeError(f"no plan of type {plan_type!r} fitted in {MAX_FRAMES} frames after {tries} tries")
