"""Going down to the floor: kneeling on one knee, lying down on the back (and getting up).

Kneeling is built from its end pose backwards: the kneeling leg's toe stays on the floor while
its heel rises, its knee rests on the floor at :data:`KNEE_FLOOR`, its thigh stands about
upright over the knee, and that fixes the hip and the pelvis; the other foot stays planted in
front. The kneeling foot first steps back into a lunge (a planted step, no sliding).
Lying down sits down first (:func:`~.actions.sit`, feet planted, knees up) and then lowers the
trunk onto the floor; getting up runs the same motion backwards, so the feet never move.
"""
from __future__ import annotations

from dataclasses import fields

import numpy as np

from . import actions
from .curves import frame_times, keyframes
from .footwork import ANKLE_HEIGHT, Persona, Plant, Stance, Swing, flat_pitch, foot_track, max_pelvis_height, \
    standing_height
from .kinematics import FPS, BodyModel, Pose, assemble, foot_vector, heading_vectors, ypr_matrix
from .reach import arm_controls_for
from .segment import Segment, num_frames, standing_pose

__all__ = ["KNEE_FLOOR", "kneel", "lie_down", "reversed_pose"]

#: Height (m) of the knee joint's centre when the knee rests on the floor.
KNEE_FLOOR = 0.06


def _tempo(mods: tuple[str, ...]) -> float:
    return 1.35 if "slowly" in mods else (0.75 if "quickly" in mods else 1.0)


def reversed_pose(pose: Pose) -> Pose:
    """The pose played backwards (frame order reversed)."""
    return Pose(**{f.name: getattr(pose, f.name)[::-1].copy() for f in fields(Pose)})


def kneel(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *, side: int,
          mods: tuple[str, ...] = (), hold: float | None = None) -> Segment:
    """Step back and go down on knee ``side`` (0 left, 1 right), hold, and stand up again."""
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    k, o = side, 1 - side
    fwd, left = heading_vectors(start.yaw)
    up = np.array([0.0, 1.0, 0.0])
    yaw_k = float(start.foot_yaw[k])
    phi0 = flat_pitch(body)[k]
    L = body.foot[k]
    # ---- the kneeling pose, from the floor up
    back = u(0.9, 1.0)        # the kneeling foot steps back far enough for an upright front shin
    a_back = start.ankles[k] - fwd * back             # flat ankle of the kneeling foot after the step
    a_back[1] = ANKLE_HEIGHT
    toe = a_back + foot_vector(yaw_k, phi0, L)       # stays on the floor from here on
    pitch_k = u(1.45, 1.52)                          # toes tucked under a near-vertical foot: keeps
    #                                                  the shin-to-foot angle within ANKLE_RANGE
    ankle_k = toe - foot_vector(yaw_k, pitch_k, L)
    drop = ankle_k[1] - KNEE_FLOOR
    knee = ankle_k + fwd * np.sqrt(body.shin[k] ** 2 - drop ** 2) - up * drop
    lean = u(0.02, 0.1)
    g_k = u(0.05, 0.15)                               # thigh a little forward of vertical
    hip = knee + body.thigh[k] * (np.cos(g_k) * up + np.sin(g_k) * fwd)
    ypr_kneel = np.array([start.yaw, 0.03 + lean, 0.0])
    pelvis_kneel = hip - ypr_matrix(ypr_kneel) @ body.hip_offsets[k]
    # ---- timeline
    t1 = u(0.2, 0.3)                                  # weight onto the front foot
    t2 = t1 + u(0.45, 0.6) * tempo                    # the kneeling foot lands behind
    t3 = t2 + u(0.7, 0.9) * tempo                     # knee on the floor
    t4 = t3 + (u(0.6, 1.2) if hold is None else hold)
    t5 = t4 + u(0.7, 0.9) * tempo                     # back up into the lunge
    t6 = t5 + u(0.45, 0.6) * tempo                    # the foot steps back beside the other
    total = t6 + u(0.25, 0.35)
    n = num_frames(total)
    tt = frame_times(n, FPS)
    pose = standing_pose(start, persona, n, body, rng=None, idle=False)
    h = standing_height(start, body, pitch=0.03)
    stand = start.ground + up * h
    shift = start.ankles[o] - start.ankles[k]
    shift[1] = 0.0
    lunge = stand - fwd * (0.45 * back) - up * 0.12
    kt = [0.0, t1, t2, t3, t4, t5, t6]
    pose.pelvis = keyframes(tt, kt, np.stack([stand, stand + 0.25 * shift, lunge, pelvis_kneel, pelvis_kneel,
                                              lunge, stand]))
    bend = keyframes(tt, kt, [0.0, 0.0, 0.5, 1.0, 1.0, 0.5, 0.0])
    pose.pelvis_ypr[:, 1] += lean * bend
    pose.spine[:, 1] += 0.1 * bend
    # ---- the kneeling foot: step back, heel up about the toe, heel down, step forward
    lift0 = u(0.55, 0.65)     # lands on the ball of the foot: a flat back foot in a lunge over-bends the ankle
    plants = [Plant(-np.inf, t1, start.ankles[k], yaw_k, roll_out=-0.3, roll_out_time=0.12),
              Plant(t2, t5, a_back, yaw_k, roll_in=-lift0, roll_in_time=0.1, roll_out=-lift0, roll_out_time=0.1),
              Plant(t6, np.inf, start.ankles[k], yaw_k, roll_in=0.15, roll_in_time=0.1)]
    swing = Swing(u(0.05, 0.08), 0.5, 0.1)
    pose.ankle[:, k], pose.toe[:, k], planted_k = foot_track(tt, plants, [swing, swing], body, k)
    on = (tt >= t2) & (tt <= t5)
    lift = keyframes(tt[on], [t2, t3, t4, t5], [lift0, pitch_k - phi0, pitch_k - phi0, lift0])
    vec = foot_vector(np.full(on.sum(), yaw_k), phi0 + lift, np.full(on.sum(), L))
    pose.ankle[on, k] = toe - vec
    pose.toe[on, k] = toe
    # ---- hips within the legs' reach until the knee goes down (the kneel pose is exact)
    planted = np.stack([planted_k, np.ones(n)], 1) if k == 0 else np.stack([np.ones(n), planted_k], 1)
    g0 = ypr_matrix(pose.pelvis_ypr)
    bound = max_pelvis_height(pose.pelvis, g0, pose.ankle, body, reach=0.985, planted=planted > 0.5) - 0.003
    free = (tt < t2 + 0.5 * (t3 - t2)) | (tt > t4 + 0.5 * (t5 - t4))
    pose.pelvis[:, 1] = np.where(free, np.minimum(pose.pelvis[:, 1], bound), pose.pelvis[:, 1])
    # the kneeling knee bends towards its floor point exactly (the default pole points a little outwards)
    to_knee = (knee - hip) / np.linalg.norm(knee - hip)
    pole = (1.0 - bend)[:, None] * pose.knee_pole[:, k] + bend[:, None] * to_knee
    pose.knee_pole[:, k] = pole / np.linalg.norm(pole, axis=-1, keepdims=True)
    # the hands rest on the front thigh while kneeling
    pose.arm[:, :, 0] += (0.35 * bend)[:, None]
    pose.arm[:, :, 2] += (0.5 * bend)[:, None]
    core = (max(0, int(np.floor((t1 - 0.05) * FPS))), min(n, int(np.ceil((t6 + 0.05) * FPS)) + 1))
    return Segment(pose, start, core, arms_free=False, info=dict(knee_floor=KNEE_FLOOR, step_back=float(back),
                                                                 kneel_time=(float(t3), float(t4))))


def _lie_back(seated: Pose, body: BodyModel, rng: np.random.Generator, tempo: float) -> Pose:
    """From the last seated frame, lower the trunk onto the floor (knees stay up, feet planted)."""
    u = rng.uniform
    last = seated.slice(seated.num_frames - 1, seated.num_frames)
    t1 = u(0.9, 1.2) * tempo
    n = num_frames(t1 + u(0.2, 0.3))
    tt = frame_times(n, FPS)
    pose = Pose.concat([last] * n)
    w = keyframes(tt, [0.0, t1], [0.0, 1.0])
    yaw = float(last.pelvis_ypr[0, 0])
    fwd, _ = heading_vectors(yaw)
    lie_pitch = -u(1.35, 1.45)
    pose.pelvis_ypr[:, 1] += w * (lie_pitch - last.pelvis_ypr[0, 1])
    pose.spine[:, 1] += w * (-0.1 - last.spine[0, 1])
    pose.neck[:, 1] += w * (0.5 - last.neck[0, 1])           # chin a little towards the chest
    pose.pelvis[:, 1] += w * (u(0.1, 0.12) - last.pelvis[0, 1])
    pose.pelvis -= fwd[None] * (0.05 * w)[:, None]
    # the arms go from propping the trunk to resting the hands on the belly (clear of the floor,
    # which the performer's joint-angle wander could push hands lying on it into)
    _, left = heading_vectors(yaw)
    for k, sgn in ((0, 1.0), (1, -1.0)):
        spot = pose.pelvis[-1] - fwd * u(0.14, 0.2) + left * (sgn * u(0.06, 0.09))
        spot[1] = pose.pelvis[-1, 1] + u(0.12, 0.15)
        lying = arm_controls_for(pose, body, k, np.tile(spot, (n, 1)))
        pose.arm[:, k] = pose.arm[:, k] + w[:, None] * (lying - pose.arm[:, k])
        # elbows out to the sides and up, not back (which is down into the floor when lying)
        pole = pose.arm_pole[:, k] + w[:, None] * (np.array([1.0, 0.0, 0.5]) - pose.arm_pole[:, k])
        pose.arm_pole[:, k] = pole / np.linalg.norm(pole, axis=-1, keepdims=True)
    joints = assemble(pose, body)
    low = joints[..., 1].min(-1)
    if low.min() < 0.0:                                   # keep every joint on or above the floor
        pose.pelvis[:, 1] += np.maximum(0.0, 0.005 - low)
    return pose


def lie_down(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
             mods: tuple[str, ...] = (), get_up: bool = False) -> Segment:
    """Sit down, lie back on the floor (knees up) and stay there, or (``get_up``) rest a moment
    and get back up the same way."""
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    sit = actions.sit(start, persona, body, rng, mods=mods, hold=u(0.15, 0.25))
    down = _lie_back(sit.pose, body, rng, tempo)
    parts = [sit.pose, down.slice(1, down.num_frames)]
    if get_up:
        rest = Pose.concat([down.slice(down.num_frames - 1, down.num_frames)] * num_frames(u(0.6, 1.2)))
        rest.spine[:, 1] += 0.01 * np.sin(2 * np.pi * 0.25 * frame_times(rest.num_frames, FPS))
        parts += [rest.slice(1, rest.num_frames), reversed_pose(down).slice(1, down.num_frames),
                  reversed_pose(sit.pose).slice(1, sit.num_frames)]
    pose = Pose.concat(parts)
    n = pose.num_frames
    # the seated hands stay on the floor (re-solved by the composer) until the trunk lies back
    sw, st = sit.hands
    off = 1.0 - keyframes(frame_times(down.num_frames, FPS), [0.0, 0.3 * down.num_frames / FPS], [0.0, 1.0])
    hand_w = [sw, (sw[-1:] * off[:, None])[1:]]
    hand_t = [st, np.repeat(st[-1:], down.num_frames - 1, 0)]
    if get_up:
        hand_w += [np.zeros((rest.num_frames - 1, 2)), hand_w[1][::-1], sw[::-1][1:]]
        hand_t += [np.repeat(st[-1:], rest.num_frames - 1 + down.num_frames - 1, 0), st[::-1][1:]]
    hands = (np.concatenate(hand_w), np.concatenate(hand_t))
    f0 = sit.core[0]
    f1 = n - max(1, sit.core[0]) if get_up else n
    return Segment(pose, start if get_up else None, (f0, f1), arms_free=False, seated=not get_up, hands=hands,
                   info=dict(lying_height=float(down.pelvis[-1, 1]), gets_up=bool(get_up)))
