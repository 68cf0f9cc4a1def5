"""Trunk actions standing on planted feet: the side bend (a standing side stretch), the torso
twist and (2.7) touching the toes.

All leave the feet where they are and move the upper body about the pelvis: the side bend rolls
the spine towards one side with the far arm reaching over the head and the near hand sliding
down the thigh; the twist turns the chest to one side and back, the arms swinging along with it;
touching the toes folds the trunk down over straight-ish legs until the hands are on the toes
(both hands, or one hand across to the other foot, the trunk turning towards it). They vary pose
dimensions little else in the corpus does (the upper body sideways, the chest turned against
the hips, the trunk hanging down over the legs).
"""
from __future__ import annotations

import numpy as np

from .curves import frame_times, keyframes, min_jerk
from .footwork import Persona, Stance, flat_pitch, max_pelvis_height
from .kinematics import FPS, BodyModel, foot_vector, heading_vectors, ypr_matrix
from .reach import arm_controls_for, nearest_controls, shoulders, wrist_reach
from .segment import Segment, num_frames, standing_pose

__all__ = ["side_bend", "twist", "touch_toes", "TOE_TOUCH_HEIGHT"]


def _tempo(mods: tuple[str, ...]) -> float:
    return 1.35 if "slowly" in mods else (0.75 if "quickly" in mods else 1.0)


def _there_and_back(rng: np.random.Generator, tempo: float, reps: int, go: tuple[float, float] = (0.6, 0.9),
                    hold: tuple[float, float] = (0.25, 0.7), back: tuple[float, float] = (0.55, 0.8)
                    ) -> tuple[list[float], list[float], float, float]:
    """Key times and weights (0 -> 1 -> hold -> 0, ``reps`` times), the onset and the end (s); the
    going, holding and coming back last a draw from ``go``, ``hold`` and ``back`` (s) times ``tempo``."""
    u = rng.uniform
    t = u(0.2, 0.3)
    t0 = t
    times, w = [0.0, t], [0.0, 0.0]
    for _ in range(reps):
        t += u(*go) * tempo
        times.append(t); w.append(1.0)
        t += u(*hold) * tempo
        times.append(t); w.append(1.0)
        t += u(*back) * tempo
        times.append(t); w.append(0.0)
    return times, w, t0, t


def side_bend(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *, side: int,
              mods: tuple[str, ...] = (), reps: int = 1) -> Segment:
    """Bend the trunk sideways towards ``side`` (0 left, 1 right) and come back up, ``reps`` times.

    The spine rolls 0.35-0.6 rad ("low": 0.55-0.8) towards that side while the hips shift a few
    centimetres the other way over the planted feet; the far arm reaches up over the head and
    the near hand slides down the side of the thigh.
    """
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    sgn = 1.0 if side == 0 else -1.0                     # + rolls towards the body's left
    angle = u(0.55, 0.8) if "low" in mods else u(0.35, 0.6)
    times, keys, t0, t1 = _there_and_back(rng, tempo, reps)
    total = t1 + u(0.3, 0.4)
    n = num_frames(total)
    tt = frame_times(n, FPS)
    w = np.clip(keyframes(tt, times, keys), 0.0, 1.0)
    pose = standing_pose(start, persona, n, body, rng=None, idle=False)
    _, left = heading_vectors(start.yaw)
    pose.spine[:, 2] += sgn * angle * w
    pose.pelvis_ypr[:, 2] -= sgn * 0.08 * angle * w
    pose.pelvis += (-sgn * u(0.02, 0.05) * w)[:, None] * left[None]
    far, near = 1 - side, side
    over = np.array([u(0.0, 0.35), u(2.4, 2.9), u(0.2, 0.6)])     # (flex, abd, elbow): up over the head
    down = np.array([u(-0.05, 0.1), u(0.05, 0.15), u(0.0, 0.15)])  # along the thigh
    pose.arm[:, far] += w[:, None] * (over - pose.arm[:, far])
    pose.arm[:, near] += w[:, None] * (down - pose.arm[:, near])
    bound = max_pelvis_height(pose.pelvis, ypr_matrix(pose.pelvis_ypr), pose.ankle, body) - 0.004
    pose.pelvis[:, 1] = np.minimum(pose.pelvis[:, 1], bound)
    core = (max(0, int(np.floor((t0 - 0.05) * FPS))), min(n, int(np.ceil((t1 + 0.05) * FPS)) + 1))
    return Segment(pose, start, core, arms_free=False, info=dict(angle=float(sgn * angle), reps=reps))


def twist(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *, side: int,
          mods: tuple[str, ...] = (), reps: int = 1) -> Segment:
    """Turn the chest towards ``side`` (0 left, 1 right) over the planted feet and back, ``reps`` times.

    The spine turns 0.5-0.8 rad, the pelvis a fifth of that, the head a little further than the
    chest; the arms, bent at the elbows, swing along (the trailing one across the body).
    """
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    sgn = 1.0 if side == 0 else -1.0                     # + turns to the left
    angle = u(0.5, 0.8)
    times, keys, t0, t1 = _there_and_back(rng, tempo, reps)
    total = t1 + u(0.3, 0.4)
    n = num_frames(total)
    tt = frame_times(n, FPS)
    w = np.clip(keyframes(tt, times, keys), -0.1, 1.0)
    pose = standing_pose(start, persona, n, body, rng=None, idle=False)
    pose.spine[:, 0] += sgn * angle * w
    pose.pelvis_ypr[:, 0] += sgn * 0.2 * angle * w
    pose.neck[:, 0] += sgn * u(0.1, 0.3) * w
    lift = np.array([u(0.4, 0.8), u(0.2, 0.4), u(1.2, 1.7)])        # forearms up in front
    for k in range(2):
        pose.arm[:, k] += w[:, None] * (lift - pose.arm[:, k])
    lead, trail = side, 1 - side
    pose.arm[:, lead, 1] += 0.3 * w                       # the leading elbow opens to the side
    pose.arm[:, trail, 1] -= 0.25 * w                     # the trailing forearm comes across
    bound = max_pelvis_height(pose.pelvis, ypr_matrix(pose.pelvis_ypr), pose.ankle, body) - 0.004
    pose.pelvis[:, 1] = np.minimum(pose.pelvis[:, 1], bound)
    core = (max(0, int(np.floor((t0 - 0.05) * FPS))), min(n, int(np.ceil((t1 + 0.05) * FPS)) + 1))
    return Segment(pose, start, core, arms_free=False, info=dict(angle=float(sgn * angle), reps=reps))


#: Height (m) of the wrist joint over the toe joint when the fingers touch the toes.
TOE_TOUCH_HEIGHT = 0.06


def touch_toes(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
               hands: tuple[int, ...], mods: tuple[str, ...] = (), reps: int = 1) -> Segment:
    """Fold forward from the hips, touch the toes and come back up, ``reps`` times (2.7).

    ``hands`` (0, 1): both hands go down to their own feet, the knees soft. ``hands``
    ``(k,)``: hand ``k`` (0 left, 1 right) reaches across to the other foot while the chest turns
    towards it and the other arm rises out to the side, pointing at the ceiling (a windmill).
    The hips go back over the planted feet as the trunk folds; where the toes are out of reach
    the knees bend (the pelvis drops) until they are within it, so at the bottom the wrists are
    :data:`TOE_TOUCH_HEIGHT` above the toe joints exactly (held there by the composer).
    """
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    fwd, left = heading_vectors(start.yaw)
    up = np.array([0.0, 1.0, 0.0])
    one = len(hands) == 1
    times, keys, t0, t = _there_and_back(rng, tempo, reps, go=(0.85, 1.15), hold=(0.3, 0.6), back=(0.8, 1.05))
    total = t + u(0.3, 0.4)
    n = num_frames(total)
    tt = frame_times(n, FPS)
    w = np.clip(keyframes(tt, times, keys), 0.0, 1.0)
    bottom = int(np.ceil(times[2] * FPS))               # first frame at the bottom (weight 1)
    base = standing_pose(start, persona, n, body, rng=None, idle=False)
    phi0 = flat_pitch(body)
    toes = np.stack([start.ankles[k] + foot_vector(float(start.foot_yaw[k]), phi0[k], body.foot[k]) for k in range(2)])
    feet = [1 - k for k in hands] if one else list(hands)
    hip, chest, back, drop = u(1.45, 1.65), u(0.85, 1.05), u(0.22, 0.3), u(0.02, 0.05)
    turn = (1.0 if (one and hands[0] == 1) else -1.0) * u(0.8, 1.05) if one else 0.0    # towards the far foot
    targets = {k: toes[f] + up * TOE_TOUCH_HEIGHT - fwd * 0.02 for k, f in zip(hands, feet)}
    for _ in range(8):                              # bend the knees until the toes are within reach
        pose = base.copy()
        pose.pelvis_ypr[:, 1] += hip * w
        pose.pelvis_ypr[:, 0] += 0.25 * turn * w
        pose.spine[:, 1] += chest * w
        pose.spine[:, 0] += 0.75 * turn * w
        pose.neck[:, 1] += 0.2 * w
        pose.pelvis -= fwd[None] * (back * w)[:, None]
        pose.pelvis[:, 1] -= drop * w
        bound = max_pelvis_height(pose.pelvis, ypr_matrix(pose.pelvis_ypr), pose.ankle, body) - 0.004
        pose.pelvis[:, 1] = np.minimum(pose.pelvis[:, 1], bound)
        sh = shoulders(pose.slice(bottom, bottom + 1), body)[0]
        if all(np.linalg.norm(targets[k] - sh[k]) < 0.96 * wrist_reach(body, k) for k in hands):
            break
        drop, hip = min(drop + 0.03, 0.25), min(hip + 0.04, 1.8)
    # the arms reach with the chest (the controls of the bottom frame, blended in) and the hands
    # are held on the toes (re-solved by the composer) only while the trunk is all the way down
    hand_w, hand_t = np.zeros((n, 2)), np.zeros((n, 2, 3))
    hold = min_jerk((w - 0.8) / 0.2)
    for k in hands:
        touch = arm_controls_for(pose.slice(bottom, bottom + 1), body, k, targets[k][None])[0]
        touch = nearest_controls(touch, pose.arm[0, k])          # forward and down, not round the side
        pose.arm[:, k] += w[:, None] * (touch[None] - pose.arm[:, k])
        pole = pose.arm_pole[:, k] + w[:, None] * (np.array([0.4, -0.3, -1.0]) - pose.arm_pole[:, k])
        pose.arm_pole[:, k] = pole / np.linalg.norm(pole, axis=-1, keepdims=True)
        hand_w[:, k], hand_t[:, k] = hold, targets[k]
    if one:                                         # the other arm opens out to the side, up at the ceiling
        other = 1 - hands[0]
        raised = np.array([u(-0.2, 0.15), u(1.35, 1.6), u(0.05, 0.25)])
        pose.arm[:, other] += w[:, None] * (raised - pose.arm[:, other])
    core = (max(0, int(np.floor((t0 - 0.05) * FPS))), min(n, int(np.ceil((t + 0.05) * FPS)) + 1))
    return Segment(pose, start, core, arms_free=False, hands=(hand_w, hand_t),
                   info=dict(bottom_frame=bottom, feet=feet, knee_drop=float(drop), reps=reps))
