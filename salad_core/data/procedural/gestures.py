"""Upper-body gestures layered over a base action: arm gestures and head movements.

A :class:`Gesture` holds arm controls with a per-arm blend weight (the gesture replaces the base
arm motion, e.g. the walking arm swing, and cross-fades in and out) and an additive head
rotation. Arm poses are authored either as (flex, abd, elbow) angles or as wrist targets in the
chest frame measured from the shoulder (x outwards, y up, z forward), converted to angles by
the law of cosines. Every gesture starts and ends in the performer's resting arm pose.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .curves import envelope, frame_times, keyframes
from .footwork import Persona
from .kinematics import FPS, BodyModel, arm_angles_for_target, arm_direction
from .segment import num_frames

__all__ = ["Gesture", "SIDES", "wave", "raise_arm", "punch", "stretch_forward", "clap", "arms_out",
           "nod", "shake_head", "look"]

#: Which arms a side name drives (0 left, 1 right).
SIDES = {"left": (0,), "right": (1,), "both": (0, 1)}
#: Cross-fade between the base arm motion and a gesture (s).
FADE = 0.3


@dataclass
class Gesture:
    """An upper-body gesture over ``n`` frames."""

    arm: np.ndarray             # (n, 2, 3) arm controls (flex, abd, elbow), x outwards
    arm_pole: np.ndarray        # (n, 2, 3) elbow poles, chest frame, x outwards
    arm_weight: np.ndarray      # (n, 2) blend weight of the gesture over the base arms
    neck: np.ndarray            # (n, 3) head rotation added to the base (yaw, pitch, roll)
    spine: np.ndarray           # (n, 3) spine bend added to the base
    info: dict = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return self.arm.shape[0]


def _pace(mods: tuple[str, ...]) -> float:
    """Duration factor of "slowly" / "quickly"."""
    return 1.5 if "slowly" in mods else (0.65 if "quickly" in mods else 1.0)


def _empty(n: int, persona: Persona) -> Gesture:
    arm = np.tile(np.asarray(persona.arm_rest, dtype=np.float64), (n, 2, 1))
    pole = np.tile(np.asarray(persona.arm_pole, dtype=np.float64), (n, 2, 1))
    return Gesture(arm, pole, np.zeros((n, 2)), np.zeros((n, 3)), np.zeros((n, 3)))


def _rest_target(persona: Persona, body: BodyModel, k: int) -> np.ndarray:
    flex, abd, elbow = persona.arm_rest
    up, fo = body.upper_arm[k], body.forearm[k]
    reach = np.sqrt(up ** 2 + fo ** 2 + 2 * up * fo * np.cos(elbow))
    return arm_direction(flex, abd) * reach


def _set_arms(g: Gesture, arms: tuple[int, ...], angles: np.ndarray, pole, t: np.ndarray) -> None:
    """Write ``angles`` ``(n, 3)`` (or ``(n, 2, 3)``) to ``arms`` with a faded weight."""
    w = envelope(t, 0.0, t[-1], FADE)
    for k in arms:
        g.arm[:, k] = angles if angles.ndim == 2 else angles[:, k]
        g.arm_pole[:, k] = pole
        g.arm_weight[:, k] = w


def _hold_time(duration: float | None, fixed: float, default: float) -> float:
    """Hold length that makes the gesture last ``duration`` (at least 0.2 s)."""
    return default if duration is None else max(0.2, duration - fixed)


# ----------------------------------------------------------------------------- arm gestures
def wave(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str, *,
         mods: tuple[str, ...] = (), variant: str = "hand", duration: float | None = None) -> Gesture:
    """Wave a hand beside the head (``variant="hand"``) or both arms overhead (``"arms"``).

    "high" / "low" raise or lower the waving hand.
    """
    u = rng.uniform
    pace = _pace(mods)
    arms = SIDES[side]
    rise, lower = u(0.35, 0.5) * pace, u(0.35, 0.5) * pace
    if variant == "arms":
        target = np.array([u(0.18, 0.25), u(0.44, 0.5), u(0.04, 0.1)])
        freq, amp = u(0.8, 1.1) / pace, u(0.45, 0.6)
        pole = np.array([1.0, 0.0, -0.3])
    else:
        if "high" in mods:
            target = np.array([u(0.08, 0.14), u(0.46, 0.5), u(0.06, 0.12)])
        elif "low" in mods:
            target = np.array([u(0.18, 0.25), u(-0.12, -0.04), u(0.26, 0.32)])
        else:
            target = np.array([u(0.14, 0.2), u(0.22, 0.32), u(0.1, 0.18)])
        freq, amp = u(1.6, 2.4) / pace, u(0.1, 0.15)     # amp: sideways travel of the hand (m)
        pole = np.array([1.0, -0.6, 0.0])
    cycles = rng.integers(2, 4) if duration is None else max(1, int(round((duration - rise - lower) * freq)))
    wave_t = cycles / freq
    total = rise + wave_t + lower
    n = num_frames(total)
    t = frame_times(n, FPS)
    g = _empty(n, persona)
    for k in arms:
        pose = arm_angles_for_target(target, body.upper_arm[k], body.forearm[k])
        rest = np.asarray(persona.arm_rest, dtype=np.float64)
        base = keyframes(t, [0.0, rise, rise + wave_t, total], np.stack([rest, pose, pose, rest]))
        osc = np.sin(2 * np.pi * freq * (t - rise)) * envelope(t, rise - 0.1, rise + wave_t + 0.1, 0.2)
        if variant == "arms":
            sign = 1.0 if k == 0 else -1.0  # both hands sway to the same side of the body
            base[:, 1] += sign * amp * osc
        else:
            # the hand swings from side to side at a constant height (the forearm pivots at the
            # elbow): the oscillation is solved in wrist positions, not added to the angles
            path = np.tile(target, (n, 1))
            path[:, 0] += amp * osc
            base += arm_angles_for_target(path, body.upper_arm[k], body.forearm[k]) - pose
        _set_arms(g, (k,), base, pole, t)
    g.info = dict(wrist_target_height=float(target[1]), frequency=float(freq))
    return g


def raise_arm(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str, *,
              mods: tuple[str, ...] = (), duration: float | None = None) -> Gesture:
    """Raise one or both arms and hold them up; "high" straight overhead, "low" to shoulder height."""
    # each raised arm draws its own pose (2.1: both arms of "both" moved as one, and the ranges
    # were narrow; the corpus's arm poses varied less, and less independently, than real ones)
    if "high" in mods:
        ranges = ((2.75, 3.05), (-0.25, 0.05), (0.0, 0.15))
    elif "low" in mods:
        ranges = ((1.25, 1.6), (0.05, 0.5), (0.05, 0.3))
    else:
        ranges = ((2.15, 2.6), (-0.35, 0.1), (0.1, 0.4))
    g, poses = _hold_arm_pose(persona, rng, side, mods, duration, ranges, (1.0, 0.0, -0.4), move=(0.45, 0.7),
                              hold=(0.5, 1.4), sway=0.03)
    g.info = dict(flex=float(poses[SIDES[side][0]][0]))
    return g


def punch(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str, *,
          mods: tuple[str, ...] = (), reps: int = 1, duration: float | None = None) -> Gesture:
    """Punch straight forward ``reps`` times from a guard near the chin."""
    u = rng.uniform
    pace = _pace(mods)
    arms = SIDES[side]
    times, targets = [0.0], []
    guard = np.array([-u(0.06, 0.12), u(0.0, 0.06), u(0.18, 0.24)])
    hit = np.array([-u(0.05, 0.1), u(0.0, 0.05), u(0.47, 0.5)])
    t = u(0.3, 0.4) * pace
    times.append(t)
    for r in range(reps):
        times.append(t + 0.12 * pace + u(0.0, 0.04)); t = times[-1]
        times.append(t + u(0.04, 0.08)); t = times[-1]
        times.append(t + u(0.18, 0.24) * pace); t = times[-1]
        if r < reps - 1:
            times.append(t + u(0.08, 0.2)); t = times[-1]
    times.append(t + u(0.35, 0.45) * pace)
    total = times[-1]
    n = num_frames(total)
    tt = frame_times(n, FPS)
    g = _empty(n, persona)
    for k in arms:
        rest = _rest_target(persona, body, k)
        seq = [rest, guard]
        for r in range(reps):
            seq += [hit, hit, guard] + ([guard] if r < reps - 1 else [])
        seq.append(rest)
        path = keyframes(tt, times, np.stack(seq))
        angles = arm_angles_for_target(path, body.upper_arm[k], body.forearm[k])
        _set_arms(g, (k,), angles, np.array([0.6, -1.0, 0.0]), tt)
    g.info = dict(reach=float(hit[2]))
    return g


def _hold_arm_pose(persona: Persona, rng: np.random.Generator, side: str, mods: tuple[str, ...],
                   duration: float | None, pose_ranges: tuple[tuple[float, float], ...], swivel, *,
                   move: tuple[float, float] = (0.45, 0.65), hold: tuple[float, float] = (0.8, 1.8),
                   sway: float = 0.0) -> tuple[Gesture, np.ndarray]:
    """Raise the arms of ``side`` to a pose drawn from ``pose_ranges`` (3 joint-angle ranges, each arm its
    own), hold, lower. Rising and lowering each take a draw from ``move`` (s, times the pace), the hold one
    from ``hold`` or what ``duration`` leaves; ``sway`` (rad) adds a 0.7 Hz flex sway while held.
    Returns the gesture and the two arms' drawn poses ``(2, 3)``."""
    u = rng.uniform
    pace = _pace(mods)
    arms = SIDES[side]
    poses = np.array([[u(lo, hi) for lo, hi in pose_ranges] for _ in range(2)])     # each arm its own
    rise, lower = u(*move) * pace, u(*move) * pace
    held = _hold_time(duration, rise + lower, u(*hold) * pace)
    total = rise + held + lower
    n = num_frames(total)
    t = frame_times(n, FPS)
    g = _empty(n, persona)
    rest = np.asarray(persona.arm_rest, dtype=np.float64)
    angles = np.stack([keyframes(t, [0.0, rise, rise + held, total], np.stack([rest, p, p, rest])) for p in poses], 1)
    if sway:
        angles[:, :, 0] += (sway * np.sin(2 * np.pi * 0.7 * t) * envelope(t, rise, rise + held, 0.2))[:, None]
    _set_arms(g, arms, angles, np.asarray(swivel, dtype=np.float64), t)
    return g, poses


def stretch_forward(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str = "both", *,
                    mods: tuple[str, ...] = (), duration: float | None = None) -> Gesture:
    """Stretch the arms straight forward at shoulder height and hold."""
    return _hold_arm_pose(persona, rng, side, mods, duration, ((1.35, 1.75), (-0.1, 0.2), (0.02, 0.2)),
                          (0.5, -1.0, 0.0))[0]


def clap(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str = "both", *,
         mods: tuple[str, ...] = (), reps: int = 4, duration: float | None = None) -> Gesture:
    """Clap the hands ``reps`` times in front of the chest."""
    u = rng.uniform
    pace = _pace(mods)
    period = u(0.38, 0.5) * pace
    if duration is not None:
        reps = max(2, int(round((duration - 0.8 * pace) / period)))
    y, z = -u(0.08, 0.16), u(0.28, 0.34)
    times = [0.0, u(0.35, 0.45) * pace]
    closed_at = []
    for r in range(reps):
        times.append(times[-1] + 0.5 * period); closed_at.append(len(times) - 1)
        times.append(times[-1] + 0.5 * period)
    times.append(times[-1] + u(0.35, 0.45) * pace)
    total = times[-1]
    n = num_frames(total)
    t = frame_times(n, FPS)
    g = _empty(n, persona)
    for k in (0, 1):
        mid = -abs(body.shoulder_offsets[k][0])
        closed = np.array([mid + 0.035, y, z])
        opened = np.array([mid + u(0.15, 0.2), y + 0.02, z - 0.03])
        seq = [_rest_target(persona, body, k)] + [opened] * (len(times) - 2) + [_rest_target(persona, body, k)]
        for i in closed_at:
            seq[i] = closed
        path = keyframes(t, times, np.stack(seq))
        angles = arm_angles_for_target(path, body.upper_arm[k], body.forearm[k])
        _set_arms(g, (k,), angles, np.array([1.0, -0.8, -0.2]), t)
    g.info = dict(claps=reps)
    return g


def arms_out(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str = "both", *,
             mods: tuple[str, ...] = (), duration: float | None = None) -> Gesture:
    """Hold the arms straight out to the sides at shoulder height."""
    return _hold_arm_pose(persona, rng, side, mods, duration, ((-0.15, 0.35), (1.3, 1.75), (0.02, 0.25)),
                          (0.0, -1.0, -0.4))[0]


# ----------------------------------------------------------------------------- head
def nod(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str | None = None, *,
        mods: tuple[str, ...] = (), reps: int = 2, duration: float | None = None) -> Gesture:
    """Nod ``reps`` times (pitch the head down and back up)."""
    g, reps = _head_cycles(persona, rng, mods, reps, duration, (0.35, 0.5), 0.2, 1,
                           lambda t, phase, amp, total: amp * 0.5 * (1.0 - np.cos(2 * np.pi * phase)))
    g.info = dict(nods=reps)
    return g


def shake_head(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str | None = None, *,
               mods: tuple[str, ...] = (), reps: int = 2, duration: float | None = None) -> Gesture:
    """Shake the head (yaw left and right) ``reps`` times."""
    g, reps = _head_cycles(persona, rng, mods, reps, duration, (0.45, 0.65), 0.3, 0,
                           lambda t, phase, amp, total: amp * np.sin(2 * np.pi * phase)
                           * envelope(t, 0.05, total - 0.05, 0.15))
    g.info = dict(shakes=reps)
    return g


def _head_cycles(persona: Persona, rng: np.random.Generator, mods: tuple[str, ...], reps: int,
                 duration: float | None, amp_range: tuple[float, float], margin: float, axis: int,
                 curve: Callable[[np.ndarray, np.ndarray, float, float], np.ndarray]) -> tuple[Gesture, int]:
    """A head movement repeated ``reps`` times: a period drawn from 0.45-0.6 s (times the pace), an
    amplitude from ``amp_range``, and ``margin`` s of stillness split before and after the cycles; a
    ``duration`` sets the count instead (at least 2). Head rotation ``axis`` (0 yaw, 1 pitch) takes
    ``curve(t, phase, amp, total)``, with frame times ``t`` ``(n,)``, the cycles done ``phase`` ``(n,)``
    in [0, reps] and the gesture's length ``total`` (s). Returns the gesture and the count."""
    u = rng.uniform
    period = u(0.45, 0.6) * _pace(mods)
    if duration is not None:
        reps = max(2, int(round((duration - margin) / period)))
    amp = u(*amp_range)
    total = reps * period + margin
    n = num_frames(total)
    t = frame_times(n, FPS)
    g = _empty(n, persona)
    phase = np.clip((t - margin / 2) / period, 0.0, reps)
    g.neck[:, axis] = curve(t, phase, amp, total)
    return g, reps


def look(persona: Persona, body: BodyModel, rng: np.random.Generator, side: str, *,
         mods: tuple[str, ...] = (), duration: float | None = None) -> Gesture:
    """Turn the head to look to one side, hold, and look ahead again."""
    u = rng.uniform
    pace = _pace(mods)
    sign = 1.0 if side == "left" else -1.0
    amp = u(0.95, 1.25)
    turn, back = u(0.35, 0.5) * pace, u(0.4, 0.55) * pace
    hold = _hold_time(duration, turn + back, u(0.5, 1.2) * pace)
    total = turn + hold + back
    n = num_frames(total)
    t = frame_times(n, FPS)
    g = _empty(n, persona)
    yaw = keyframes(t, [0.0, turn, turn + hold, total], [0.0, amp, amp * 0.97, 0.0]) * sign
    # while looking, the gaze wanders a little over that side (a held head is never frozen)
    scan_f = u(0.35, 0.6) / pace
    yaw += sign * u(0.1, 0.16) * np.sin(2 * np.pi * scan_f * (t - turn)) * envelope(t, turn, turn + hold, 0.25)
    g.neck[:, 0] = 0.85 * yaw
    g.neck[:, 1] = u(-0.1, 0.1) * envelope(t, 0.0, total, turn)
    g.spine[:, 0] = 0.15 * yaw
    g.info = dict(yaw=float(sign * amp))
    return g
