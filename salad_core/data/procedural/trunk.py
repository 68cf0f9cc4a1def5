"""Trunk actions standing on planted feet: the side bend (a standing side stretch) and the torso twist.

Both leave the feet where they are and move the upper body about the pelvis: the side bend rolls
the spine towards one side with the far arm reaching over the head and the near hand sliding
down the thigh; the twist turns the chest to one side and back, the arms swinging along with it.
They vary pose dimensions little else in the corpus does (the upper body sideways, the chest
turned against the hips).
"""
from __future__ import annotations

import numpy as np

from .curves import frame_times, keyframes
from .footwork import Persona, Stance, max_pelvis_height
from .kinematics import FPS, BodyModel, heading_vectors, ypr_matrix
from .segment import Segment, num_frames, standing_pose

__all__ = ["side_bend", "twist"]


def _tempo(mods: tuple[str, ...]) -> float:
    return 1.35 if "slowly" in mods else (0.75 if "quickly" in mods else 1.0)


def _there_and_back(rng: np.random.Generator, tempo: float, reps: int) -> tuple[list[float], list[float], float, float]:
    """Key times and weights (0 -> 1 -> hold -> 0, ``reps`` times), the onset and the end (s)."""
    u = rng.uniform
    t = u(0.2, 0.3)
    t0 = t
    times, w = [0.0, t], [0.0, 0.0]
    for _ in range(reps):
        t += u(0.6, 0.9) * tempo
        times.append(t); w.append(1.0)
        t += u(0.25, 0.7) * tempo
        times.append(t); w.append(1.0)
        t += u(0.55, 0.8) * tempo
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
