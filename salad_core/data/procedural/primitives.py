"""The action primitives of the corpus: what each one is, which body parts it drives, which
sides, modifiers and repetitions it takes, and how to build its motion.

An :class:`Action` names a primitive with its side, modifiers, repetitions and variant.
Base primitives (locomotion, jumps, leg and whole-body actions) become a
:class:`~.segment.Segment`; gesture primitives (arms, head) become a :class:`~.gestures.Gesture`
layered over a base.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from . import actions, boxing, crawl, dance, everyday, floorwork, gestures, poses, sports, steps, trunk
from .footwork import Persona, Stance
from .gait import Route, gait_style, locomotion
from .kinematics import BodyModel

__all__ = ["Action", "PrimitiveSpec", "PRIMITIVES", "MODIFIERS", "SIDE_WORDS", "build_base",
           "build_gesture", "primitive_parts", "CATEGORIES"]

#: Modifiers a caption may carry; each changes the motion measurably.
MODIFIERS = ("high", "low", "slowly", "quickly")
#: Sides an action may take.
SIDE_WORDS = ("left", "right", "both")
#: Primitive categories (the body part groups of the issue).
CATEGORIES = ("locomotion", "jump", "arms", "legs", "whole body", "head")

_LOWER = ("root", "left leg", "right leg")
_UPPER = ("spine", "left arm", "right arm", "head")


@dataclass(frozen=True)
class Action:
    """One action of a clip: a primitive with its parameters."""

    kind: str                       # primitive name, a key of PRIMITIVES
    side: str | None = None         # "left", "right", "both" or None
    mods: tuple[str, ...] = ()      # subset of MODIFIERS, sorted
    reps: int = 1                   # repetitions (1 = once)
    variant: str = ""               # e.g. "in_place", "forward", "around", "arms"

    def __post_init__(self) -> None:
        spec = PRIMITIVES.get(self.kind)
        if spec is None:
            raise ValueError(f"unknown primitive {self.kind!r}; known: {', '.join(sorted(PRIMITIVES))}")
        if self.side not in spec.sides:
            raise ValueError(f"{self.kind}: side {self.side!r} not allowed; allowed: {spec.sides}")
        bad = [m for m in self.mods if m not in spec.mods]
        if bad:
            raise ValueError(f"{self.kind}: modifiers {bad} not allowed; allowed: {spec.mods}")
        if tuple(sorted(self.mods)) != self.mods:
            raise ValueError(f"{self.kind}: mods must be sorted, got {self.mods}")
        if self.reps not in spec.reps:
            raise ValueError(f"{self.kind}: reps={self.reps} not allowed; allowed: {spec.reps}")
        if self.variant not in spec.variants:
            raise ValueError(f"{self.kind}: variant {self.variant!r} not allowed; allowed: {spec.variants}")
        if self.kind == "wave" and self.variant == "arms" and self.side != "both":
            raise ValueError(f"wave variant 'arms' (both arms overhead) needs side 'both', got {self.side!r}")

    @property
    def spec(self) -> "PrimitiveSpec":
        return PRIMITIVES[self.kind]

    def mirrored(self) -> "Action":
        """The same action with left and right swapped (HumanML3D mirror augmentation)."""
        side = {"left": "right", "right": "left"}.get(self.side, self.side)
        return replace(self, side=side)


@dataclass(frozen=True)
class PrimitiveSpec:
    """What a primitive is and what it may take."""

    name: str                           # key in PRIMITIVES
    category: str                       # one of CATEGORIES
    track: str                          # "base" or "gesture"
    sides: tuple = (None,)              # allowed sides
    mods: tuple[str, ...] = ()          # allowed modifiers
    reps: tuple[int, ...] = (1,)        # allowed repetition counts
    variants: tuple[str, ...] = ("",)   # allowed variants
    accepts: tuple[str, ...] = ()       # base: gesture categories that may be layered on it
    weight: float = 1.0                 # sampling weight
    terminal: bool = False              # base: must end the clip (ends seated)
    initial: bool = False               # base: must start the clip (starts off the feet)

    def __post_init__(self) -> None:
        if self.category not in CATEGORIES:
            raise ValueError(f"{self.name}: category {self.category!r} not in {CATEGORIES}")
        if self.track not in ("base", "gesture"):
            raise ValueError(f"{self.name}: track {self.track!r} must be 'base' or 'gesture'")


_SPEED = ("quickly", "slowly")
#: 2.5 weights: the head gestures (0.55 / 0.5 / 0.55 -> 0.4), shuffles and sways (0.5 -> 0.4), whose
#: clips barely changed posture (2-4 cm within-clip spread), are drawn less; spins, circles, picking
#: up, lunges and knee touches (6-9 cm) more.
#: 2.7 weights: the new standing whole-body actions thinned out the floor actions, whose pelvis
#: heights make the root height's spread (its std fell to 0.81 of the real one): sitting 1.1 -> 2.8,
#: lying down and getting up 0.45 -> 1.6 (a long action: most plans holding it do not fit in a
#: clip), stairs up 0.6 -> 0.9. Kicks (1.3 -> 3.8, now three ways), the balance, swings, runs
#: (1.2 -> 1.5) and spins (1.0 -> 2.0) vary the legs and the trunk in directions little else does
#: (each one of them drawn more lowered the share of the first 11 principal components), against
#: the toe touches and the floor, which load the first one.
PRIMITIVES: dict[str, PrimitiveSpec] = {s.name: s for s in [
    # locomotion
    PrimitiveSpec("walk", "locomotion", "base", mods=_SPEED, variants=("", "in_place"), accepts=("arms", "head"), weight=2.5),
    PrimitiveSpec("run", "locomotion", "base", mods=("quickly",), accepts=("arms", "head"), weight=1.5),
    PrimitiveSpec("jog", "locomotion", "base", mods=_SPEED, variants=("", "in_place"), accepts=("arms", "head"), weight=1.0),
    PrimitiveSpec("march", "locomotion", "base", mods=_SPEED, variants=("", "in_place"), accepts=("head",), weight=0.8),
    PrimitiveSpec("walk_backward", "locomotion", "base", mods=_SPEED, accepts=("arms", "head"), weight=1.0),
    PrimitiveSpec("sidestep", "locomotion", "base", sides=("left", "right"), mods=_SPEED, accepts=("arms", "head"), weight=1.0),
    PrimitiveSpec("circle", "locomotion", "base", sides=("left", "right"), mods=_SPEED, accepts=("arms", "head"), weight=1.1),
    PrimitiveSpec("turn", "locomotion", "base", sides=("left", "right"), mods=_SPEED, variants=("", "around"), accepts=("arms", "head"), weight=1.2),
    # jumps
    PrimitiveSpec("jump", "jump", "base", mods=("high", "low"), reps=(1, 2, 3), variants=("", "forward"), accepts=("arms", "head"), weight=2.0),
    # legs
    PrimitiveSpec("kick", "legs", "base", sides=("left", "right"), mods=("high", "low", "quickly"), reps=(1, 2),
                  variants=("", "side", "back"), accepts=("head",), weight=3.8),
    PrimitiveSpec("knee_lift", "legs", "base", sides=("left", "right"), mods=("high", "slowly", "quickly"), reps=(1, 2), accepts=("arms", "head"), weight=1.0),
    # whole body
    PrimitiveSpec("squat", "whole body", "base", mods=("low", "slowly", "quickly"), reps=(1, 2, 3), accepts=("arms", "head"), weight=1.6),
    PrimitiveSpec("sit", "whole body", "base", mods=("slowly",), weight=2.8, terminal=True),
    PrimitiveSpec("bow", "whole body", "base", mods=("low", "slowly"), reps=(1, 2), weight=1.1),
    PrimitiveSpec("jumping_jacks", "whole body", "base", mods=_SPEED, reps=(2, 3, 4), accepts=("head",), weight=0.9),
    PrimitiveSpec("spin", "whole body", "base", sides=("left", "right"), accepts=("arms",), weight=2.0),
    # arms
    PrimitiveSpec("wave", "arms", "gesture", sides=SIDE_WORDS, mods=("high", "low", "slowly", "quickly"), variants=("", "arms"), weight=2.0),
    PrimitiveSpec("raise", "arms", "gesture", sides=SIDE_WORDS, mods=("high", "low", "slowly", "quickly"), weight=2.2),
    PrimitiveSpec("punch", "arms", "gesture", sides=("left", "right"), mods=("quickly",), reps=(1, 2, 3), weight=1.2),
    PrimitiveSpec("stretch", "arms", "gesture", sides=("both",), mods=_SPEED, weight=1.0),
    PrimitiveSpec("clap", "arms", "gesture", sides=("both",), mods=_SPEED, reps=(1, 3, 4, 5), weight=0.9),
    PrimitiveSpec("arms_out", "arms", "gesture", sides=("both",), mods=_SPEED, weight=0.9),
    # head
    PrimitiveSpec("nod", "head", "gesture", mods=_SPEED, reps=(2, 3), weight=0.4),
    PrimitiveSpec("shake_head", "head", "gesture", mods=_SPEED, reps=(2, 3), weight=0.4),
    PrimitiveSpec("look", "head", "gesture", sides=("left", "right"), mods=_SPEED, weight=0.4),
    # --- corpus 2.0: wider coverage
    # dance
    PrimitiveSpec("dance", "whole body", "base", mods=_SPEED, accepts=("head",), weight=1.2),
    PrimitiveSpec("sway", "whole body", "base", mods=_SPEED, accepts=("arms", "head"), weight=0.4),
    # everyday whole-body actions
    PrimitiveSpec("throw", "arms", "base", sides=("left", "right"), mods=_SPEED, variants=("", "underhand"), weight=1.1),
    PrimitiveSpec("pick_up", "whole body", "base", sides=SIDE_WORDS, mods=("slowly",), weight=1.2),
    PrimitiveSpec("step_over", "locomotion", "base", mods=("slowly",), accepts=("head",), weight=0.8),
    PrimitiveSpec("stumble", "locomotion", "base", weight=0.7),
    # down to the floor
    PrimitiveSpec("kneel", "legs", "base", sides=("left", "right"), mods=_SPEED, weight=1.3),
    PrimitiveSpec("lie_down", "whole body", "base", mods=("slowly",), weight=0.45, terminal=True),
    PrimitiveSpec("lie_down_get_up", "whole body", "base", mods=("slowly",), weight=1.6),
    # footwork: steps, stairs, pivots, a cross-body knee touch
    PrimitiveSpec("step_up", "legs", "base", mods=_SPEED, reps=(1, 2), accepts=("arms", "head"), weight=0.8),
    PrimitiveSpec("climb_stairs", "locomotion", "base", mods=_SPEED, accepts=("head",), weight=0.9, terminal=True),
    PrimitiveSpec("pivot", "locomotion", "base", sides=("left", "right"), mods=_SPEED, variants=("", "around"),
                  accepts=("arms", "head"), weight=0.8),
    PrimitiveSpec("touch_knee", "whole body", "base", sides=("left", "right"), mods=_SPEED, reps=(1, 2), weight=1.3),
    # boxing
    PrimitiveSpec("guard", "arms", "gesture", sides=("both",), weight=0.5),
    PrimitiveSpec("jab_cross", "arms", "gesture", sides=("left", "right"), mods=("quickly",), reps=(1, 2), weight=0.8),
    PrimitiveSpec("hook", "arms", "gesture", sides=("left", "right"), mods=("quickly",), reps=(1, 2), weight=0.6),
    PrimitiveSpec("uppercut", "arms", "gesture", sides=("left", "right"), mods=("quickly",), reps=(1, 2), weight=0.6),
    # hands on the body and across it
    PrimitiveSpec("hands_on_hips", "arms", "gesture", sides=("both",), mods=_SPEED, weight=0.7),
    PrimitiveSpec("scratch_head", "arms", "gesture", sides=("left", "right"), mods=_SPEED, weight=0.6),
    PrimitiveSpec("salute", "arms", "gesture", sides=("left", "right"), mods=("quickly",), weight=0.5),
    PrimitiveSpec("cross_arms", "arms", "gesture", sides=("both",), mods=_SPEED, weight=0.6),
    PrimitiveSpec("reach_across", "arms", "gesture", sides=("left", "right"), mods=_SPEED, weight=0.6),
    PrimitiveSpec("arm_circles", "arms", "gesture", sides=("both",), mods=_SPEED, weight=0.6),
    # --- corpus 2.1: on all fours (a whole clip: starts and ends there)
    # (it only ever fills a one-action clip, so its weight is high for about 1 % of the motions;
    # 2.2: 1.0, as 3.0 gave 2.1 % and its horizontal trunk took 33-57 % of the pose variance)
    PrimitiveSpec("crawl", "locomotion", "base", mods=_SPEED, weight=1.0, terminal=True, initial=True),
    # --- corpus 2.2: down a flight of stairs (from the top landing: it opens a clip), shuffling
    # steps (the soles glide over the floor), lunges (legs far beyond walking)
    PrimitiveSpec("descend_stairs", "locomotion", "base", mods=_SPEED, accepts=("head",), weight=0.5, initial=True),
    PrimitiveSpec("shuffle", "locomotion", "base", sides=(None, "left", "right"), mods=_SPEED,
                  accepts=("arms", "head"), weight=0.4),
    PrimitiveSpec("lunge", "legs", "base", sides=("left", "right"), mods=("low", "slowly", "quickly"), reps=(1, 2),
                  variants=("", "side"), accepts=("arms", "head"), weight=1.8),
    # the trunk alone: a standing side stretch and a torso twist (the upper body sideways and
    # turned against the hips: pose dimensions little else varies)
    PrimitiveSpec("side_bend", "whole body", "base", sides=("left", "right"), mods=("low", "slowly", "quickly"),
                  reps=(1, 2), weight=0.8),
    PrimitiveSpec("twist", "whole body", "base", sides=("left", "right"), mods=_SPEED, reps=(1, 2), weight=0.7),
    # --- corpus 2.7: whole-body actions with large trunk motion (2.6's clips spread their joints
    # 6.3 cm, the real clip 9.7; its trunk joints moved half as much as in real capture): touching
    # the toes (both hands, or one hand across to the other foot: a windmill), a golf or baseball
    # bat swing, and reaching up high across the body with a step and onto the toes. The lunge
    # takes a sideways variant (2.7) as well.
    PrimitiveSpec("touch_toes", "whole body", "base", sides=("both", "left", "right"), mods=_SPEED, reps=(1, 2),
                  weight=2.3),
    PrimitiveSpec("swing", "whole body", "base", sides=("left", "right"), mods=_SPEED, variants=("", "bat"),
                  weight=2.6),
    PrimitiveSpec("reach_up", "whole body", "base", sides=("left", "right"), mods=_SPEED, weight=1.0),
    # a T-balance on one leg (the side is the standing leg); kicks also go out to the side and back (2.7)
    PrimitiveSpec("balance", "whole body", "base", sides=("left", "right"), mods=_SPEED, weight=3.6),
]}


def primitive_parts(action: Action) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(driven parts, incidentally moved parts) of an action, by the registry's definitions.

    This is what the annotations record (driven) and what the checks discount (incidental).
    """
    k, side = action.kind, action.side
    arms = {"left": ("left arm",), "right": ("right arm",), "both": ("left arm", "right arm")}
    legs = {"left": ("left leg", "right leg"), "right": ("right leg", "left leg")}
    if k in ("walk", "jog", "march") and action.variant == "in_place":
        return ("left leg", "right leg"), ("root",) + _UPPER
    if k in ("walk", "run", "jog", "march", "walk_backward", "sidestep", "circle", "turn", "spin"):
        return _LOWER, _UPPER
    if k == "jump":
        return _LOWER + _UPPER, ()
    if k == "jumping_jacks":
        return _LOWER + ("left arm", "right arm"), ("spine", "head")
    if k in ("kick", "knee_lift"):
        leg, other = legs[side]
        return (leg,), ("root", other, "spine", "left arm", "right arm")
    if k in ("squat", "sit"):
        return _LOWER + ("spine",), ("left arm", "right arm", "head")
    if k == "bow":
        return ("spine", "head"), _LOWER + ("left arm", "right arm")
    if k in ("wave", "raise", "punch", "stretch", "clap", "arms_out"):
        # 2.6: the trunk leans into the gesture (composition._lean_into)
        return arms.get(side or "both", arms["both"]), ("spine",)
    if k in ("nod", "shake_head"):
        return ("head",), ()
    if k in ("hands_on_hips", "cross_arms", "arm_circles"):
        return arms["both"], ("spine",)
    if k in ("guard", "jab_cross"):      # a jab-cross's side is its lead hand; both arms strike
        return arms["both"], ("spine",)
    if k in ("scratch_head", "salute"):
        return arms[side], ("head",)
    if k == "reach_across":
        return arms[side], ("spine",)
    if k in ("hook", "uppercut"):
        other = "right arm" if side == "left" else "left arm"
        return arms[side], (other, "spine")
    if k == "dance":
        return _LOWER + ("left arm", "right arm"), ("spine", "head")
    if k == "sway":
        return ("root", "spine"), ("left leg", "right leg", "left arm", "right arm", "head")
    if k == "throw":
        # "throws a ball" names no arm, so a reading of the words alone (the corpus checks) takes
        # the first side: both arms count as moved, whichever side the words leave open
        return arms[side] + ("spine",), _LOWER + ("left arm", "right arm", "head")
    if k == "pick_up":
        rest = tuple(a for a in ("left arm", "right arm") if a not in arms[side])
        return _LOWER + ("spine",) + arms[side], rest + ("head",)
    if k == "step_over":
        return _LOWER, _UPPER
    if k == "stumble":
        return _LOWER + ("spine",), ("left arm", "right arm", "head")
    if k == "kneel":
        return _LOWER, ("spine", "left arm", "right arm", "head")
    if k in ("lie_down", "lie_down_get_up"):
        return _LOWER + ("spine",), ("left arm", "right arm", "head")
    if k in ("step_up", "climb_stairs", "pivot", "descend_stairs", "shuffle"):
        return _LOWER, _UPPER
    if k == "lunge":
        return _LOWER, _UPPER
    if k == "side_bend":     # the side is where the trunk bends; the far arm goes over the head
        far, near = ("right arm", "left arm") if side == "left" else ("left arm", "right arm")
        return ("spine", far), ("root", "left leg", "right leg", near, "head")
    if k == "twist":         # the legs turn a little under the pelvis, the arms swing along
        return ("spine",), ("root", "left leg", "right leg", "left arm", "right arm", "head")
    if k == "touch_knee":     # the side is the hand; it touches the other knee, which rises
        knee_leg = "right leg" if side == "left" else "left leg"
        support = "left leg" if side == "left" else "right leg"
        other = "right arm" if side == "left" else "left arm"
        return arms[side] + (knee_leg, "spine"), ("root", support, other, "head")
    if k == "touch_toes":    # both hands to the toes, or (a side) one hand across to the other foot
        if side == "both":
            return ("spine", "left arm", "right arm"), ("root", "left leg", "right leg", "head")
        other = "right arm" if side == "left" else "left arm"
        return arms[side] + ("spine",), ("root", "left leg", "right leg", other, "head")
    if k == "swing":         # both hands on the club whichever way it winds up; the legs turn under it
        return ("left arm", "right arm", "spine"), ("root", "left leg", "right leg", "head")
    if k == "reach_up":      # the side is the reaching hand; the other foot steps out, up on the toes
        other = "right arm" if side == "left" else "left arm"
        return arms[side] + ("spine",), ("root", "left leg", "right leg", other, "head")
    if k == "balance":       # the side is the standing leg; the other one rises out behind
        stand, free = ("left leg", "right leg") if side == "left" else ("right leg", "left leg")
        return (free, "spine"), ("root", stand, "left arm", "right arm", "head")
    if k == "look":
        return ("head",), ("spine",)
    if k == "crawl":
        return _LOWER + ("left arm", "right arm"), ("spine", "head")
    raise ValueError(f"no parts defined for primitive {k!r}")


# ----------------------------------------------------------------------------- builders
#: Chance that a forward walk, run, jog or march drifts along a gentle arc, and the range of the
#: heading it gains over the whole route (rad): a capture-room walk is seldom a ruler line, but a
#: drift this small still reads as "forward" (a turn is 0.45-0.55 pi, a circle a full one).
DRIFT_P, DRIFT_ANGLE = 0.6, (0.15, 0.55)


def _drift_route(rng: np.random.Generator, style, n_steps: int, in_place: bool) -> Route:
    """A straight :class:`Route`, or with :data:`DRIFT_P` a gentle arc to either side whose
    heading gain over the route's distance lies in :data:`DRIFT_ANGLE` (2.5)."""
    if in_place or style.speed <= 0.0 or rng.random() >= DRIFT_P:
        return Route()
    dist = style.speed * (n_steps + 0.5) / style.cadence
    angle = rng.uniform(*DRIFT_ANGLE)
    side = 1.0 if rng.random() < 0.5 else -1.0
    return Route("arc", radius=float(max(dist / angle, 2.5)), side=side)


def _steps(rng: np.random.Generator, lo: int, hi: int) -> int:
    return int(rng.integers(lo, hi + 1))


def build_base(action: Action, start: Stance, persona: Persona, body: BodyModel,
               rng: np.random.Generator, duration: float | None = None, keep_arms: bool = False):
    """The :class:`~.segment.Segment` of a base action starting from ``start``.

    ``duration`` (seconds) is a hint for stretchable actions (locomotion length);
    ``keep_arms`` asks for a variant that leaves the arms free (an arm gesture goes on top).
    """
    k, mods = action.kind, action.mods
    sgn = 1.0 if action.side == "left" else -1.0
    tempo = persona.tempo
    in_place = action.variant == "in_place"

    def steps_for(style, lo, hi):
        if duration is None:
            return _steps(rng, lo, hi)
        return int(np.clip(round(duration * style.cadence) - 1, 2, 24))

    if k in ("walk", "run", "jog", "march"):
        style = gait_style(k, rng, mods, tempo, in_place=in_place)
        lo, hi = {"walk": (4, 7), "run": (4, 7), "jog": (4, 7), "march": (4, 6)}[k]
        n = steps_for(style, lo, hi)
        return locomotion(start, persona, style, _drift_route(rng, style, n, in_place), n, body)
    if k == "walk_backward":
        style = gait_style("backward", rng, mods, tempo)
        return locomotion(start, persona, style, Route(heading=np.pi), steps_for(style, 3, 5), body)
    if k == "sidestep":
        style = gait_style("sidestep", rng, mods, tempo)
        return locomotion(start, persona, style, Route(heading=sgn * np.pi / 2), steps_for(style, 3, 5), body)
    if k == "circle":
        style = gait_style("circle", rng, mods, tempo)
        radius = rng.uniform(0.7, 1.1)
        # keep the sideways (centripetal) acceleration of walking on a small circle human: v^2/r <= 2.2
        style = replace(style, speed=min(style.speed, float(np.sqrt(2.2 * radius))))
        step = style.speed / style.cadence
        n = int(np.clip(round(rng.uniform(0.8, 1.0) * 2 * np.pi * radius / step) + 2, 6, 16))
        return locomotion(start, persona, style, Route("arc", radius=radius, side=sgn), n, body)
    if k == "turn":
        style = gait_style("turn", rng, mods, tempo)
        angle = np.pi if action.variant == "around" else rng.uniform(0.45, 0.55) * np.pi
        n = int(np.ceil(angle / rng.uniform(0.75, 1.0))) + 1
        return locomotion(start, persona, style, Route("turn", side=sgn, angle=angle), n, body)
    if k == "spin":
        style = gait_style("spin", rng, mods, tempo)
        n = int(np.ceil(2 * np.pi / rng.uniform(0.9, 1.2))) + 1
        return locomotion(start, persona, style, Route("turn", side=sgn, angle=2 * np.pi), n, body)
    if k == "jump":
        return actions.jump(start, persona, body, rng, forward=action.variant == "forward", mods=mods,
                            reps=action.reps)
    if k == "jumping_jacks":
        return actions.jumping_jacks(start, persona, body, rng, mods=mods, reps=action.reps)
    if k == "kick":
        return actions.kick(start, persona, body, rng, side=0 if action.side == "left" else 1, mods=mods,
                            reps=action.reps, direction=action.variant or "front")
    if k == "balance":
        return actions.balance(start, persona, body, rng, side=0 if action.side == "left" else 1, mods=mods)
    if k == "knee_lift":
        return actions.knee_lift(start, persona, body, rng, side=0 if action.side == "left" else 1, mods=mods,
                                 reps=action.reps)
    if k == "squat":
        return actions.squat(start, persona, body, rng, mods=mods, reps=action.reps,
                             arms_forward=False if keep_arms else None)
    if k == "sit":
        return actions.sit(start, persona, body, rng, mods=mods, hold=rng.uniform(0.6, 1.2))
    if k == "bow":
        return actions.bow(start, persona, body, rng, mods=mods, reps=action.reps)
    side = 0 if action.side == "left" else 1
    if k == "dance":
        return dance.step_touch(start, persona, body, rng, mods=mods)
    if k == "sway":
        return dance.sway(start, persona, body, rng, mods=mods, duration=duration)
    if k == "throw":
        return everyday.throw(start, persona, body, rng, side=side, underhand=action.variant == "underhand", mods=mods)
    if k == "pick_up":
        arms = (0, 1) if action.side == "both" else (side,)
        return everyday.pick_up(start, persona, body, rng, arms=arms, mods=mods)
    if k == "step_over":
        return everyday.step_over(start, persona, body, rng, mods=mods)
    if k == "stumble":
        return everyday.stumble(start, persona, body, rng, mods=mods)
    if k == "kneel":
        return floorwork.kneel(start, persona, body, rng, side=side, mods=mods)
    if k in ("lie_down", "lie_down_get_up"):
        return floorwork.lie_down(start, persona, body, rng, mods=mods, get_up=k == "lie_down_get_up")
    if k == "step_up":
        return steps.step_up(start, persona, body, rng, mods=mods, reps=action.reps)
    if k == "climb_stairs":
        return steps.climb_stairs(start, persona, body, rng, mods=mods)
    if k == "descend_stairs":
        return steps.descend_stairs(start, persona, body, rng, mods=mods)
    if k == "shuffle":
        return steps.shuffle(start, persona, body, rng, side=None if action.side is None else side, mods=mods)
    if k == "lunge":
        return steps.lunge(start, persona, body, rng, side=side, mods=mods, reps=action.reps,
                           sideways=action.variant == "side", arms_forward=not keep_arms)
    if k == "touch_toes":
        return trunk.touch_toes(start, persona, body, rng, hands=(0, 1) if action.side == "both" else (side,),
                                mods=mods, reps=action.reps)
    if k == "swing":
        return sports.swing(start, persona, body, rng, side=side, bat=action.variant == "bat", mods=mods)
    if k == "reach_up":
        return everyday.reach_up(start, persona, body, rng, side=side, mods=mods)
    if k == "side_bend":
        return trunk.side_bend(start, persona, body, rng, side=side, mods=mods, reps=action.reps)
    if k == "twist":
        return trunk.twist(start, persona, body, rng, side=side, mods=mods, reps=action.reps)
    if k == "pivot":
        angle = np.pi if action.variant == "around" else rng.uniform(0.45, 0.55) * np.pi
        return steps.pivot(start, persona, body, rng, side=side, angle=angle, mods=mods)
    if k == "crawl":
        return crawl.crawl(start, persona, body, rng, mods=mods)
    if k == "touch_knee":
        return steps.touch_knee(start, persona, body, rng, hand=side, mods=mods, reps=action.reps)
    raise ValueError(f"primitive {k!r} is not a base action")


def build_gesture(action: Action, persona: Persona, body: BodyModel, rng: np.random.Generator,
                  duration: float | None = None) -> gestures.Gesture:
    """The :class:`~.gestures.Gesture` of a gesture action (``duration``: fit to this length)."""
    k, mods, side = action.kind, action.mods, action.side
    if k == "wave":
        return gestures.wave(persona, body, rng, side, mods=mods, variant="arms" if action.variant == "arms" else "hand",
                             duration=duration)
    if k == "raise":
        return gestures.raise_arm(persona, body, rng, side, mods=mods, duration=duration)
    if k == "punch":
        return gestures.punch(persona, body, rng, side, mods=mods, reps=action.reps)
    if k == "stretch":
        return gestures.stretch_forward(persona, body, rng, mods=mods, duration=duration)
    if k == "clap":
        reps = action.reps if action.reps > 1 else int(rng.integers(3, 6))
        return gestures.clap(persona, body, rng, mods=mods, reps=reps,
                             duration=duration if action.reps == 1 else None)
    if k == "arms_out":
        return gestures.arms_out(persona, body, rng, mods=mods, duration=duration)
    if k == "nod":
        return gestures.nod(persona, body, rng, mods=mods, reps=action.reps)
    if k == "shake_head":
        return gestures.shake_head(persona, body, rng, mods=mods, reps=action.reps)
    if k == "look":
        return gestures.look(persona, body, rng, side, mods=mods, duration=duration)
    simple = {"hands_on_hips": poses.hands_on_hips, "scratch_head": poses.scratch_head, "salute": poses.salute,
              "cross_arms": poses.cross_arms, "reach_across": poses.reach_across, "arm_circles": poses.arm_circles,
              "guard": boxing.guard}
    if k in simple:
        return simple[k](persona, body, rng, side, mods=mods, duration=duration)
    strikes = {"jab_cross": boxing.jab_cross, "hook": boxing.hook, "uppercut": boxing.uppercut}
    if k in strikes:
        return strikes[k](persona, body, rng, side, mods=mods, reps=action.reps)
    raise ValueError(f"primitive {k!r} is not a gesture")
