"""Dance: the side-to-side step-touch and a standing hip sway.

The step-touch moves the feet between floor plants (no sliding): the lead foot steps out, the
other one closes beside it, then both come back; the pelvis follows the weight over the feet,
dips a little on every beat and rolls with the hips, and the arms swing to the side of travel.
The sway keeps both feet planted and moves the hips from side to side under a counter-leaning
chest; its arms stay free for a gesture on top.
"""
from __future__ import annotations

import numpy as np

from .curves import envelope, frame_times, smooth
from .footwork import Persona, Plant, Stance, Swing, foot_track, max_pelvis_height
from .kinematics import FPS, BodyModel, heading_vectors, ypr_matrix
from .segment import Segment, num_frames, standing_pose

__all__ = ["step_touch", "sway"]


def _tempo(mods: tuple[str, ...]) -> float:
    return 1.35 if "slowly" in mods else (0.75 if "quickly" in mods else 1.0)


def step_touch(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
               mods: tuple[str, ...] = (), cycles: int | None = None) -> Segment:
    """Dance a step-touch: ``cycles`` times out to one side and back (the first side at random)."""
    u = rng.uniform
    beat = u(0.42, 0.55) * _tempo(mods) * persona.tempo
    cycles = int(rng.integers(2, 4)) if cycles is None else int(cycles)
    d = u(0.24, 0.34)
    side = 1.0 if rng.random() < 0.5 else -1.0
    _, left = heading_vectors(start.yaw)
    shift = left * (side * d)
    lead = 0 if side > 0 else 1                    # the foot on the side of travel steps first
    home = [start.ankles[0].copy(), start.ankles[1].copy()]
    pre = u(0.25, 0.35)
    swing_t = 0.55 * beat
    moves = []                                     # (foot, from, to, lift time)
    t = pre
    for _ in range(cycles):
        for foot, out in ((lead, True), (1 - lead, True), (1 - lead, False), (lead, False)):
            moves.append((foot, home[foot] + (0.0 if out else 1.0) * shift, home[foot] + (1.0 if out else 0.0) * shift, t))
            t += beat
    total = t + u(0.3, 0.45)
    n = num_frames(total)
    tt = frame_times(n, FPS)
    pose = standing_pose(start, persona, n, body, rng=None, idle=False)
    plants: list[list[Plant]] = [[], []]
    for k in range(2):
        plants[k].append(Plant(-np.inf, np.inf, home[k], float(start.foot_yaw[k])))
    for foot, _, to, t_lift in moves:
        last = plants[foot][-1]
        plants[foot][-1] = Plant(last.t_on, t_lift, last.ankle, last.yaw, roll_in=last.roll_in,
                                 roll_in_time=last.roll_in_time, roll_out=-0.25, roll_out_time=0.1)
        plants[foot].append(Plant(t_lift + swing_t, np.inf, to, float(start.foot_yaw[foot]), roll_in=-0.15,
                                  roll_in_time=0.08))
    planted = np.zeros((n, 2))
    for k in range(2):
        airs = [Swing(u(0.05, 0.08), 0.5, 0.1)] * (len(plants[k]) - 1)
        pose.ankle[:, k], pose.toe[:, k], planted[:, k] = foot_track(tt, plants[k], airs, body, k)
    # the pelvis rides over the feet (their mean), dipping on each beat
    centre = smooth(pose.ankle.mean(1), 0.12 * beat * FPS)
    act = envelope(tt, pre - 0.15, t + 0.1, 0.3)
    pose.pelvis[:, [0, 2]] += (centre - centre[0])[:, [0, 2]]
    phase = np.clip((tt - pre) / beat, 0.0, None)
    dip = u(0.025, 0.045)
    pose.pelvis[:, 1] -= dip * 0.5 * (1.0 - np.cos(2 * np.pi * phase)) * act
    sway = np.sin(np.pi * phase) * act            # one side per two beats
    pose.pelvis_ypr[:, 2] += 0.07 * side * sway
    pose.pelvis_ypr[:, 0] += 0.12 * side * np.sin(np.pi * phase + 0.5) * act
    pose.spine[:, 2] -= 0.1 * side * sway
    pose.neck[:, 1] += 0.08 * np.sin(2 * np.pi * phase) * act
    # arms: elbows bent, both swinging to the side of travel
    swing = side * u(0.35, 0.5) * np.sin(np.pi * phase - 0.6) * act
    pose.arm[:, :, 0] += (u(0.35, 0.55) * act)[:, None]
    pose.arm[:, :, 2] += (u(0.9, 1.2) * act)[:, None]
    pose.arm[:, 0, 1] += swing + 0.1 * act
    pose.arm[:, 1, 1] += -swing + 0.1 * act
    g0 = ypr_matrix(pose.pelvis_ypr)
    bound = max_pelvis_height(pose.pelvis, g0, pose.ankle, body, planted=planted > 0.5) - 0.004
    pose.pelvis[:, 1] = np.minimum(pose.pelvis[:, 1], bound)
    f0 = max(0, int(np.floor((pre - 0.1) * FPS)))
    f1 = min(n, int(np.ceil((t + 0.1) * FPS)) + 1)
    end = Stance(np.stack(home), start.foot_yaw, start.yaw)
    return Segment(pose, end, (f0, f1), arms_free=False, info=dict(cycles=cycles, step=float(d), beat=float(beat)))


def sway(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
         mods: tuple[str, ...] = (), cycles: int | None = None, duration: float | None = None) -> Segment:
    """Sway the hips from side to side with both feet planted, the chest leaning against them."""
    u = rng.uniform
    period = u(1.1, 1.5) * _tempo(mods) * persona.tempo
    if duration is not None:
        cycles = max(2, int(round(duration / period)))
    cycles = int(rng.integers(2, 4)) if cycles is None else int(cycles)
    pre = u(0.2, 0.3)
    span = cycles * period
    total = pre + span + u(0.3, 0.45)
    n = num_frames(total)
    tt = frame_times(n, FPS)
    pose = standing_pose(start, persona, n, body, rng=None, idle=False)
    _, left = heading_vectors(start.yaw)
    act = envelope(tt, pre, pre + span, 0.35)
    s = np.sin(2 * np.pi * (tt - pre) / period) * act
    amp = u(0.05, 0.08)
    pose.pelvis += left[None] * (amp * s)[:, None]
    pose.pelvis[:, 1] -= u(0.015, 0.03) * np.abs(np.cos(2 * np.pi * (tt - pre) / period)) * act
    pose.pelvis_ypr[:, 2] -= 0.12 * s                        # the hip drops on the far side
    pose.spine[:, 2] += 0.2 * s                              # the chest leans back over the middle
    pose.neck[:, 2] -= 0.08 * s
    pose.arm[:, 0, 1] += 0.12 * s
    pose.arm[:, 1, 1] -= 0.12 * s
    g0 = ypr_matrix(pose.pelvis_ypr)
    bound = max_pelvis_height(pose.pelvis, g0, pose.ankle, body) - 0.004
    pose.pelvis[:, 1] = np.minimum(pose.pelvis[:, 1], bound)
    f0 = max(0, int(np.floor((pre - 0.05) * FPS)))
    f1 = min(n, int(np.ceil((pre + span + 0.05) * FPS)) + 1)
    return Segment(pose, start, (f0, f1), info=dict(cycles=cycles, amplitude=float(amp)))
