"""Unnamed secondary motion laid on stepping: a hand to the face, the head or a pocket, a
pointing arm, a glance around, a lean or twist of the trunk.

Real performers do such things while they walk, and real captions leave them unsaid when they
are not the clip's point ("a person walks forward" while touching the chin). Generator 2.3 kept
the trunk over the hips and the arms in the gait's swing through every stepping action: its
within-clip joint spread was 5.1 cm (real clip 9.7) and the pose PCA needed only 10 components
for 90 % of the variance (target 12), the first (whole-body height) holding 47 %. Each fidget
moves one part its own way (one arm, or the head, or the trunk), so the parts vary
independently across the corpus.

A fidget is a :class:`~.gestures.Gesture` with an empty ``info`` that the composer lays over a
stepping action's core but records no event for: it only ever drives parts that the action
moves incidentally (:func:`.primitives.primitive_parts`), so the annotations stay exact.
Wrist targets are in the chest frame measured from the shoulder (x outwards, y up, z forward;
metres), as in :mod:`.poses`.
"""
from __future__ import annotations

import numpy as np

from .footwork import Persona
from .gestures import Gesture
from .kinematics import FPS, BodyModel, arm_direction
from .poses import rest_target, target_gesture

__all__ = ["ARM_FIDGETS", "ARM_FIDGET_KINDS", "UPPER_FIDGET_KINDS", "FIDGET_P", "arm_fidget", "glance",
           "trunk_shift", "MIN_SPAN", "MARGIN", "step_fidgets"]

#: Base actions during which a free arm may fidget (the arm-carriage kinds: the performer steps
#: and the arms are theirs; runners and jumpers keep their swing).
ARM_FIDGET_KINDS = frozenset({"walk", "walk_backward", "sidestep", "circle", "turn", "pivot", "step_over",
                              "step_up", "climb_stairs", "descend_stairs", "shuffle", "lunge"})
#: Base actions during which the head may glance around and the trunk lean or twist (they move
#: the spine and the head only incidentally).
UPPER_FIDGET_KINDS = ARM_FIDGET_KINDS | {"jog", "march"}
#: Chance per eligible step of a fidget of each free arm (drawn per arm), a glance and a trunk shift
#: (2.5: 0.7 / 0.6 / 0.9, was 0.5 / 0.5 / 0.7; 2.6: 0.85 / 0.7 / 1.0).
FIDGET_P = {"arm": 0.85, "glance": 0.7, "trunk": 1.0}
#: Shortest core (s) of a step that takes a fidget, and frames kept clear at either end of the
#: core (the neighbouring actions cross-fade there).
MIN_SPAN, MARGIN = 1.4, 6
#: The arm fidgets: where the wrist goes (chest frame box, from the shoulder), the elbow pole and
#: whether the path must pass the via point (a hand going up to the head from the side).
ARM_FIDGETS: dict[str, tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float], bool]] = {
    "chin": ((-0.18, 0.08, 0.1), (-0.12, 0.16, 0.17), (0.6, -1.0, -0.2), True),
    "ear": ((-0.06, 0.19, -0.01), (0.0, 0.25, 0.05), (1.0, -0.6, -0.2), True),
    "head": ((-0.1, 0.27, -0.04), (-0.05, 0.32, 0.03), (1.0, 0.3, -0.3), True),
    "chest": ((-0.2, -0.18, 0.14), (-0.12, -0.08, 0.2), (1.0, -0.6, -0.2), False),
    "hip": ((-0.06, -0.45, -0.03), (-0.02, -0.38, 0.02), (1.0, 0.0, -0.6), False),
    "pocket": ((-0.02, -0.47, 0.03), (0.03, -0.42, 0.09), (1.0, 0.0, -0.8), False),
    "phone": ((-0.14, -0.26, 0.24), (-0.06, -0.16, 0.34), (0.6, -1.0, -0.2), False),
    "point": ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.3, 0.0, -1.0), False),   # drawn as a direction
}
#: Via point for a hand going up to the head (as :data:`.poses._VIA`).
_VIA = np.array([0.06, -0.08, 0.3])


def _fit(times, span: float) -> np.ndarray:
    """Key ``times`` (s) scaled to end at ``min(span, times[-1])`` rounded down to a whole frame,
    so that the last frame lands on the last key (the fidget ends exactly where it began)."""
    times = np.asarray(times, dtype=np.float64)
    end = np.floor(min(span, times[-1]) * FPS + 1e-9) / FPS
    return times * (end / times[-1])


def _times(span: float, rng: np.random.Generator, move: tuple[float, float]) -> tuple[float, float, float]:
    """(go, hold, back) durations (s) of a go-hold-return fidget lasting at most ``span``."""
    go, back = rng.uniform(*move), rng.uniform(*move)
    hold = min(rng.uniform(0.5, 2.0), max(0.2, span - go - back))
    return go, hold, back


def arm_fidget(persona: Persona, body: BodyModel, rng: np.random.Generator, arm: int, span: float,
               kind: str | None = None) -> Gesture:
    """One arm goes to a point on the body or points away, holds, and returns (at most ``span`` s).

    Parameters
    ----------
    arm : 0 (left) or 1 (right)
    span : longest duration (s); the fidget lasts ``min(span, ~1.3-3.4 s)``
    kind : a key of :data:`ARM_FIDGETS` (default: drawn)

    Returns
    -------
    Gesture driving ``arm`` only (a "phone" look also pitches the head down), ``info["fidget"]``
    naming what it did.
    """
    if arm not in (0, 1):
        raise ValueError(f"arm={arm!r} must be 0 (left) or 1 (right)")
    if span <= 0.5:
        raise ValueError(f"span={span} s is too short for an arm fidget; it needs more than 0.5 s")
    names = list(ARM_FIDGETS)
    kind = names[int(rng.integers(len(names)))] if kind is None else kind
    if kind not in ARM_FIDGETS:
        raise ValueError(f"kind={kind!r} unknown; known: {', '.join(names)}")
    low, high, pole, via = ARM_FIDGETS[kind]
    u = rng.uniform
    if kind == "point":
        reach = 0.97 * float(body.upper_arm[arm] + body.forearm[arm])
        on = arm_direction(u(1.1, 1.6), u(0.0, 0.7)) * reach
    else:
        on = rng.uniform(low, high)
    go, hold, back = _times(span, rng, (0.4, 0.65) if via else (0.35, 0.55))
    rest = rest_target(persona, body, arm)
    jitter = np.array([u(-0.01, 0.01), u(-0.015, 0.015), u(-0.01, 0.01)])   # a held hand is never frozen
    if via:
        times = [0.0, 0.5 * go, go, go + hold, go + hold + 0.5 * back, go + hold + back]
        keys = [rest, _VIA, on, on + jitter, _VIA, rest]
    else:
        times = [0.0, go, go + hold, go + hold + back]
        keys = [rest, on, on + jitter, rest]
    times = _fit(times, span)                   # a short span: quicker moves, a shorter hold
    neck = None
    if kind == "phone":                          # looking at what the hand holds
        neck = np.zeros((len(times), 3))
        neck[1:-1, 1] = u(0.25, 0.45)
    g = target_gesture(persona, body, times, {arm: np.stack(keys)}, np.asarray(pole, dtype=np.float64), neck=neck)
    g.info = {"fidget": kind, "arm": arm}
    return g


def glance(persona: Persona, body: BodyModel, rng: np.random.Generator, span: float) -> Gesture:
    """The head looks around: to one side (sometimes on to the other), up or down, and back.

    Smaller and shorter than the annotated ``look`` (0.3-0.8 rad against 0.95-1.25), with the
    chest turning a little along. Lasts at most ``span`` s; drives no arm.
    """
    if span <= 0.5:
        raise ValueError(f"span={span} s is too short for a glance; it needs more than 0.5 s")
    u = rng.uniform
    sign = 1.0 if rng.random() < 0.5 else -1.0
    looks = [np.array([sign * u(0.3, 0.8), u(-0.15, 0.3), u(-0.08, 0.08)])]
    if rng.random() < 0.35:
        looks.append(np.array([-sign * u(0.25, 0.7), u(-0.15, 0.3), u(-0.08, 0.08)]))
    times, keys, t = [0.0], [np.zeros(3)], 0.0
    for look in looks:
        t += u(0.35, 0.6)
        times.append(t)
        keys.append(look)
        t += u(0.3, 1.0)
        times.append(t)
        keys.append(look * 0.95)
    t += u(0.35, 0.6)
    times.append(t)
    keys.append(np.zeros(3))
    times = _fit(times, span)
    keys_arr = np.stack(keys)
    g = target_gesture(persona, body, times, {}, np.array([0.3, 0.0, -1.0]), neck=keys_arr,
                       spine=keys_arr * np.array([0.15, 0.0, 0.0]))
    g.info = {"fidget": "glance", "looks": len(looks)}
    return g


def trunk_shift(persona: Persona, body: BodyModel, rng: np.random.Generator, span: float) -> Gesture:
    """The trunk leans forward or back, sideways and twists to a new carriage and back.

    One or two held keyposes (yaw +-0.4, pitch -0.1..0.4, roll +-0.25 rad; 2.5, was +-0.25,
    -0.08..0.3, +-0.15) over at most
    ``span`` s; the head keeps its gaze (it turns back by half the pitch). Drives no arm.
    """
    if span <= 0.5:
        raise ValueError(f"span={span} s is too short for a trunk shift; it needs more than 0.5 s")
    u = rng.uniform
    n_keys = 1 if rng.random() < 0.6 else 2
    times, keys, t = [0.0], [np.zeros(3)], 0.0
    for _ in range(n_keys):
        t += u(0.5, 0.9)
        times.append(t)
        keys.append(np.array([u(-0.4, 0.4), u(-0.1, 0.4), u(-0.25, 0.25)]))
        t += u(0.3, 1.0)
        times.append(t)
        keys.append(keys[-1] + u(-0.02, 0.02, size=3))
    t += u(0.5, 0.9)
    times.append(t)
    keys.append(np.zeros(3))
    times = _fit(times, span)
    spine = np.stack(keys)
    neck = spine * np.array([0.0, -0.5, 0.0])
    g = target_gesture(persona, body, times, {}, np.array([0.3, 0.0, -1.0]), spine=spine, neck=neck)
    g.info = {"fidget": "trunk", "keys": n_keys}
    return g


def step_fidgets(persona: Persona, body: BodyModel, rng: np.random.Generator, core: tuple[int, int],
                 arms: tuple[int, ...], head: bool, trunk: bool) -> list[tuple[int, Gesture]]:
    """Fidgets of one step whose core spans frames ``core`` ``[f0, f1)``: ``[(first frame, Gesture)]``.

    ``arms``: the arms free to fidget (each draws one with :data:`FIDGET_P` ["arm"]); ``head`` /
    ``trunk``: whether a glance / a trunk shift may be drawn. Every fidget lies inside the core,
    :data:`MARGIN` frames clear of its ends; a core shorter than :data:`MIN_SPAN` takes none.
    """
    w0, w1 = int(core[0]) + MARGIN, int(core[1]) - MARGIN
    span = (w1 - w0 - 1) / FPS
    if span < MIN_SPAN:
        return []
    out = []

    def place(g: Gesture) -> None:
        slack = max(0, w1 - w0 - g.num_frames)
        out.append((w0 + int(rng.integers(0, slack + 1)), g))

    for k in arms:
        if rng.random() < FIDGET_P["arm"]:
            place(arm_fidget(persona, body, rng, k, span))
    if head and rng.random() < FIDGET_P["glance"]:
        place(glance(persona, body, rng, span))
    if trunk and rng.random() < FIDGET_P["trunk"]:
        place(trunk_shift(persona, body, rng, span))
    return out
