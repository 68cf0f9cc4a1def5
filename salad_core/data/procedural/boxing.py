"""Boxing: a raised guard, the jab-cross combination, hooks and uppercuts.

Every strike starts and ends in the guard (fists in front of the chin, elbows down) and turns the
chest with the punch (the spine's yaw), as a boxer's hips and shoulders do; the straight punches
reach about 0.5 m in front of the shoulder, the hook sweeps across at shoulder height with the
elbow bent, the uppercut rises from below the chest. Wrist targets are in the chest frame from
the shoulder (x outwards, y up, z forward), see :mod:`.poses`.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .footwork import Persona
from .gestures import SIDES, Gesture
from .kinematics import BodyModel
from .poses import pace_factor, rest_target, target_gesture

__all__ = ["guard", "jab_cross", "hook", "uppercut"]

_POLE = np.array([0.5, -1.0, 0.0])      # elbows down and a little out


def _guard_target(rng: np.random.Generator) -> np.ndarray:
    return np.array([-rng.uniform(0.07, 0.11), rng.uniform(0.02, 0.07), rng.uniform(0.2, 0.25)])


def _strike(persona: Persona, body: BodyModel, rng: np.random.Generator, mods: tuple[str, ...],
            strikes: list[tuple[int, list[np.ndarray], float]], lead_in: float | None = None) -> Gesture:
    """Guard up, then the strikes in order, then back to rest.

    ``strikes``: (arm, wrist keys from the guard out and back, chest yaw during the strike).
    """
    u = rng.uniform
    pace = pace_factor(mods)
    guard = {k: _guard_target(rng) for k in (0, 1)}
    times = [0.0, (u(0.3, 0.4) if lead_in is None else lead_in) * pace]
    keys = {k: [rest_target(persona, body, k), guard[k]] for k in (0, 1)}
    yaw = [0.0, 0.0]
    for arm, path, turn in strikes:
        for i, p in enumerate(path):
            # a strike leg lasts at least 0.1 s: faster ones reach wrist accelerations (~190 m/s^2)
            # well above the real data's (~130)
            times.append(times[-1] + (u(0.12, 0.16) if i == 0 else u(0.1, 0.13)) * pace)
            for k in (0, 1):
                keys[k].append(p if k == arm else guard[k])
            yaw.append(turn)
        times.append(times[-1] + u(0.16, 0.22) * pace)        # back to the guard
        for k in (0, 1):
            keys[k].append(guard[k])
        yaw.append(0.0)
    times.append(times[-1] + u(0.15, 0.3) * pace)             # hold the guard a moment
    for k in (0, 1):
        keys[k].append(guard[k])
    yaw.append(0.0)
    times.append(times[-1] + u(0.35, 0.45) * pace)
    for k in (0, 1):
        keys[k].append(rest_target(persona, body, k))
    yaw.append(0.0)
    spine = np.zeros((len(times), 3))
    spine[:, 0] = yaw
    spine[1:-1, 1] = 0.05                                     # a boxer's slight hunch
    return target_gesture(persona, body, times, {k: np.stack(v) for k, v in keys.items()}, _POLE, spine=spine)


def guard(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str = "both", *,
          mods: tuple[str, ...] = (), duration: float | None = None) -> Gesture:
    """Raise both fists to a boxing guard and hold it, bobbing a little, then lower them."""
    u = rng.uniform
    pace = pace_factor(mods)
    rise, lower = u(0.35, 0.5) * pace, u(0.4, 0.55) * pace
    hold = u(1.0, 1.8) * pace if duration is None else max(0.4, duration - rise - lower)
    g_pos = {k: _guard_target(rng) for k in (0, 1)}
    bobs = max(1, int(round(hold * u(1.5, 2.2))))
    times = [0.0, rise] + [rise + hold * (i + 1) / (bobs + 1) for i in range(bobs)] + [rise + hold, rise + hold + lower]
    keys = {}
    for k in (0, 1):
        seq = [rest_target(persona, body, k), g_pos[k]]
        seq += [g_pos[k] + np.array([0.0, -0.025 if i % 2 == 0 else 0.0, 0.01 * (k - 0.5)]) for i in range(bobs)]
        seq += [g_pos[k], rest_target(persona, body, k)]
        keys[k] = np.stack(seq)
    spine = np.zeros((len(times), 3))
    spine[1:-1, 1] = 0.06
    g = target_gesture(persona, body, times, keys, _POLE, spine=spine)
    g.info = dict(hold=float(hold))
    return g


def jab_cross(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str = "left", *,
              mods: tuple[str, ...] = (), reps: int = 1, duration: float | None = None) -> Gesture:
    """``reps`` one-two combinations: a jab with the ``side`` (lead) hand, then a cross with the
    other that turns the chest further ("left": an orthodox stance; its mirror is the southpaw's)."""
    u = rng.uniform
    (lead,) = SIDES[side]
    sgn = 1.0 if lead == 0 else -1.0
    strikes = []
    for _ in range(reps):
        jab = np.array([-u(0.06, 0.1), u(0.02, 0.06), u(0.47, 0.5)])
        cross = np.array([-u(0.14, 0.2), u(0.02, 0.06), u(0.46, 0.5)])
        strikes.append((lead, [jab], -sgn * u(0.12, 0.2)))
        strikes.append((1 - lead, [cross], sgn * u(0.35, 0.5)))
    g = _strike(persona, body, rng, mods, strikes)
    g.info = dict(combinations=reps)
    return g


def hook(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str, *,
         mods: tuple[str, ...] = (), reps: int = 1, duration: float | None = None) -> Gesture:
    """A hook with one arm: the fist swings out, then across in front at shoulder height."""
    def draw(u: Callable[[float, float], float]) -> tuple[list[np.ndarray], float]:
        out = np.array([u(0.12, 0.18), u(-0.02, 0.03), u(0.22, 0.28)])
        mid = np.array([-u(0.02, 0.06), u(0.0, 0.04), u(0.4, 0.44)])
        through = np.array([-u(0.24, 0.3), u(0.0, 0.04), u(0.33, 0.38)])
        return [out, mid, through], u(0.45, 0.6)

    g = _one_arm_strikes(persona, body, rng, side, mods, reps, draw)
    g.info = dict(hooks=reps)
    return g


def uppercut(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str, *,
             mods: tuple[str, ...] = (), reps: int = 1, duration: float | None = None) -> Gesture:
    """An uppercut with one arm: the fist drops below the chest, then drives up in front of the chin."""
    def draw(u: Callable[[float, float], float]) -> tuple[list[np.ndarray], float]:
        low = np.array([-u(0.0, 0.04), -u(0.26, 0.32), u(0.2, 0.26)])
        top = np.array([-u(0.1, 0.14), u(0.08, 0.13), u(0.3, 0.35)])
        return [low, top], u(0.25, 0.35)

    g = _one_arm_strikes(persona, body, rng, side, mods, reps, draw)
    g.info = dict(uppercuts=reps)
    return g


def _one_arm_strikes(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str, mods: tuple[str, ...],
                     reps: int, draw: Callable[[Callable[[float, float], float]], tuple[list[np.ndarray], float]]
                     ) -> Gesture:
    """``reps`` strikes with the arm of ``side`` (see :func:`_strike`): each ``draw(rng.uniform)`` gives
    the strike's wrist keys (3,) each and how far (rad) the chest turns away from the striking arm."""
    (k,) = SIDES[side]
    sgn = 1.0 if k == 0 else -1.0
    strikes = []
    for _ in range(reps):
        path, turn = draw(rng.uniform)
        strikes.append((k, path, -sgn * turn))
    return _strike(persona, body, rng, mods, strikes)
