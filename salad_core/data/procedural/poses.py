"""Arm gestures on and across the body: hands on the hips, scratching the head, a salute,
crossing the arms, reaching across the body, arm circles; and :func:`target_gesture`, which
turns keyed wrist targets into a :class:`~.gestures.Gesture`.

Wrist targets are in the chest frame measured from the shoulder (x outwards for either arm, y
up, z forward; metres): a negative x crosses towards the body's midline (the shoulders sit
about 0.2 m either side of it). The law of cosines gives the elbow, so every target within
reach is met exactly (up to the cross-fade with the base arms at the ends).
"""
from __future__ import annotations

import numpy as np

from .curves import envelope, frame_times, keyframes
from .footwork import Persona
from .gestures import SIDES, Gesture
from .kinematics import FPS, BodyModel, arm_angles_for_target, arm_direction
from .segment import num_frames

__all__ = ["FADE", "pace_factor", "rest_target", "target_gesture", "hands_on_hips", "scratch_head", "salute",
           "cross_arms", "reach_across", "arm_circles"]

#: Cross-fade (s) between the base arm motion and a gesture, as in :mod:`.gestures`.
FADE = 0.3


def pace_factor(mods: tuple[str, ...]) -> float:
    """Duration factor of the speed modifiers ("slowly" 1.5, "quickly" 0.65, else 1)."""
    return 1.5 if "slowly" in mods else (0.65 if "quickly" in mods else 1.0)


def rest_target(persona: Persona, body: BodyModel, k: int) -> np.ndarray:
    """``(3,)`` wrist target of arm ``k`` (0 left, 1 right) hanging at the performer's rest pose."""
    flex, abd, elbow = persona.arm_rest
    up, fo = body.upper_arm[k], body.forearm[k]
    return arm_direction(flex, abd) * np.sqrt(up ** 2 + fo ** 2 + 2 * up * fo * np.cos(elbow))


def target_gesture(persona: Persona, body: BodyModel, times, targets: dict[int, np.ndarray], pole,
                   spine: np.ndarray | None = None, neck: np.ndarray | None = None) -> Gesture:
    """A gesture whose wrists follow keyed targets.

    Parameters
    ----------
    times : ``(K,)`` key times (s), starting at 0; the gesture lasts until the last key
    targets : ``{arm: (K, 3)}`` wrist targets per driven arm (0 left, 1 right), chest frame from
        the shoulder, x outwards; the first and last keys should be :func:`rest_target`
    pole : ``(3,)`` elbow pole (chest frame, x outwards) of the driven arms
    spine, neck : ``(K, 3)``, optional
        Keyed spine bend and head rotation (yaw, pitch, roll; rad) added to the base.

    Returns
    -------
    Gesture of ``num_frames(times[-1])`` frames; the driven arms' weight fades in and out over
    :data:`FADE` seconds.
    """
    times = np.asarray(times, dtype=np.float64)
    n = num_frames(float(times[-1]))
    t = frame_times(n, FPS)
    arm = np.tile(np.asarray(persona.arm_rest, dtype=np.float64), (n, 2, 1))
    arm_pole = np.tile(np.asarray(persona.arm_pole, dtype=np.float64), (n, 2, 1))
    weight = np.zeros((n, 2))
    w = envelope(t, 0.0, t[-1], FADE)
    for k, keys in targets.items():
        path = keyframes(t, times, np.asarray(keys, dtype=np.float64))
        arm[:, k] = arm_angles_for_target(path, body.upper_arm[k], body.forearm[k])
        arm_pole[:, k] = pole
        weight[:, k] = w
    sp = np.zeros((n, 3)) if spine is None else keyframes(t, times, np.asarray(spine, dtype=np.float64))
    nk = np.zeros((n, 3)) if neck is None else keyframes(t, times, np.asarray(neck, dtype=np.float64))
    return Gesture(arm, arm_pole, weight, nk, sp)


#: Via point (chest frame, from the shoulder) for a hand going from the side up to the head: a
#: straight path would pass through the shoulder and fold the elbow completely.
_VIA = np.array([0.06, -0.08, 0.3])


def _hold_keys(rng: np.random.Generator, mods: tuple[str, ...], duration: float | None,
               reach: tuple[float, float] = (0.45, 0.65)) -> tuple[float, float, float]:
    """(rise, hold, lower) times of a reach-hold-return gesture lasting about ``duration``."""
    pace = pace_factor(mods)
    rise, lower = rng.uniform(*reach) * pace, rng.uniform(*reach) * pace
    hold = rng.uniform(0.8, 1.6) * pace if duration is None else max(0.3, duration - rise - lower)
    return rise, hold, lower


def hands_on_hips(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str = "both", *,
                  mods: tuple[str, ...] = (), duration: float | None = None) -> Gesture:
    """Put the hands on the hips (wrists at the sides of the pelvis, elbows out) and hold."""
    u = rng.uniform
    rise, hold, lower = _hold_keys(rng, mods, duration)
    times = [0.0, rise, rise + hold, rise + hold + lower]
    targets = {}
    for k in SIDES[side]:
        on = np.array([u(-0.06, -0.02), u(-0.46, -0.42), u(-0.03, 0.02)])    # at the iliac crest
        rest = rest_target(persona, body, k)
        targets[k] = np.stack([rest, on, on + np.array([0.0, 0.005, 0.0]), rest])
    g = target_gesture(persona, body, times, targets, np.array([1.0, 0.0, -0.6]))
    g.info = dict(contact="hips", hold=float(hold))
    return g


def scratch_head(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str, *,
                 mods: tuple[str, ...] = (), duration: float | None = None) -> Gesture:
    """Bring one hand to the side of the head and scratch (small fast strokes), head tilted."""
    u = rng.uniform
    rise, hold, lower = _hold_keys(rng, mods, duration, reach=(0.4, 0.55))
    (k,) = SIDES[side]
    on = np.array([u(-0.13, -0.1), u(0.24, 0.28), u(0.02, 0.06)])
    strokes = max(2, int(round(hold * u(2.0, 2.8))))
    times = [0.0, 0.5 * rise, rise] + [rise + hold * (i + 1) / (strokes + 1) for i in range(strokes)]
    times += [rise + hold, rise + hold + 0.5 * lower, rise + hold + lower]
    keys = [rest_target(persona, body, k), _VIA, on]
    for i in range(strokes):
        keys.append(on + np.array([0.0, 0.02 if i % 2 == 0 else -0.01, 0.015 if i % 2 == 0 else -0.01]))
    keys += [on, _VIA, rest_target(persona, body, k)]
    sgn = 1.0 if k == 0 else -1.0
    tilt = np.zeros((len(times), 3))
    tilt[2:-2, 2] = -sgn * u(0.1, 0.18)         # the head leans away from the scratching hand
    tilt[2:-2, 1] = u(0.05, 0.12)
    g = target_gesture(persona, body, times, {k: np.stack(keys)}, np.array([1.0, 0.4, 0.0]), neck=tilt)
    g.info = dict(contact="head", strokes=strokes)
    return g


def salute(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str, *,
           mods: tuple[str, ...] = (), duration: float | None = None) -> Gesture:
    """A military salute: the hand's edge to the brow, elbow out to the side, held, then down."""
    u = rng.uniform
    rise, hold, lower = _hold_keys(rng, mods, duration, reach=(0.35, 0.5))
    (k,) = SIDES[side]
    on = np.array([u(-0.17, -0.14), u(0.24, 0.27), u(0.1, 0.13)])
    times = [0.0, 0.5 * rise, rise, rise + hold, rise + hold + 0.5 * lower, rise + hold + lower]
    rest = rest_target(persona, body, k)
    g = target_gesture(persona, body, times, {k: np.stack([rest, _VIA, on, on, _VIA, rest])}, np.array([1.0, 0.1, 0.0]))
    g.info = dict(contact="brow")
    return g


def cross_arms(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str = "both", *,
               mods: tuple[str, ...] = (), duration: float | None = None) -> Gesture:
    """Fold the arms across the chest: each wrist crosses the midline to the other upper arm."""
    u = rng.uniform
    rise, hold, lower = _hold_keys(rng, mods, duration)
    times = [0.0, rise, rise + hold, rise + hold + lower]
    top = int(rng.integers(2))                  # which forearm lies on top (in front)
    targets = {}
    for k in (0, 1):
        on = np.array([-u(0.33, 0.36), -u(0.16, 0.2) + (0.03 if k == top else -0.02),
                       u(0.17, 0.19) + (0.04 if k == top else 0.0)])
        rest = rest_target(persona, body, k)
        targets[k] = np.stack([rest, on, on + np.array([0.0, -0.005, 0.0]), rest])
    g = target_gesture(persona, body, times, targets, np.array([1.0, -0.8, 0.2]))
    g.info = dict(contact="arms", top=top)
    return g


def reach_across(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str, *,
                 mods: tuple[str, ...] = (), duration: float | None = None) -> Gesture:
    """Reach one arm across the body to the far side, the chest turning with it, and back."""
    u = rng.uniform
    rise, hold, lower = _hold_keys(rng, mods, duration, reach=(0.5, 0.7))
    (k,) = SIDES[side]
    sgn = 1.0 if k == 0 else -1.0
    far = np.array([-u(0.4, 0.44), u(-0.08, 0.12), u(0.22, 0.28)])
    times = [0.0, rise, rise + hold, rise + hold + lower]
    rest = rest_target(persona, body, k)
    spine = np.zeros((4, 3))
    spine[1:3, 0] = -sgn * u(0.25, 0.4)         # the left arm reaching right turns the chest right
    g = target_gesture(persona, body, times, {k: np.stack([rest, far, far + np.array([-0.01, 0.0, 0.01]), rest])},
                       np.array([0.3, -1.0, 0.0]), spine=spine)
    g.info = dict(crosses_midline=True, wrist_target=far.tolist())
    return g


def arm_circles(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str = "both", *,
                mods: tuple[str, ...] = (), duration: float | None = None) -> Gesture:
    """Arms out to the sides at shoulder height drawing circles (flexion and abduction in quadrature)."""
    u = rng.uniform
    pace = pace_factor(mods)
    freq = u(0.9, 1.3) / pace
    radius = u(0.3, 0.42)
    rise, lower = u(0.4, 0.55) * pace, u(0.4, 0.55) * pace
    cycles = int(rng.integers(3, 6)) if duration is None else max(2, int(round((duration - rise - lower) * freq)))
    span = cycles / freq
    total = rise + span + lower
    n = num_frames(total)
    t = frame_times(n, FPS)
    arm = np.tile(np.asarray(persona.arm_rest, dtype=np.float64), (n, 2, 1))
    held = np.array([0.0, u(1.4, 1.55), u(0.02, 0.1)])
    rest = np.asarray(persona.arm_rest, dtype=np.float64)
    base = keyframes(t, [0.0, rise, rise + span, total], np.stack([rest, held, held, rest]))
    phase = 2 * np.pi * freq * (t - rise)
    on = envelope(t, rise - 0.1, rise + span + 0.1, 0.25)
    weight = np.zeros((n, 2))
    pole = np.tile(np.asarray(persona.arm_pole, dtype=np.float64), (n, 2, 1))
    for k in SIDES[side]:
        arm[:, k] = base
        arm[:, k, 0] += radius * np.sin(phase) * on
        arm[:, k, 1] += radius * (np.cos(phase) - 1.0) * on
        weight[:, k] = envelope(t, 0.0, t[-1], FADE)
        pole[:, k] = (0.0, -1.0, -0.3)
    g = Gesture(arm, pole, weight, np.zeros((n, 3)), np.zeros((n, 3)))
    g.info = dict(circles=cycles, frequency=float(freq))
    return g
