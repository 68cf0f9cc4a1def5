"""Two-handed swings (2.7): a golf swing and a baseball bat swing.

Both hands hold one club: their wrists follow a grip path laid out in the chest frame (keys from
the address over the back shoulder, down through the hit and up over the front shoulder), so the
posture and wander the composer adds later carry both hands together and they stay a hand's
width apart. The trunk does most of the work: the hips and the
chest wind up towards the back shoulder's side and unwind through the hit to face the target,
the head keeps its eyes on the ball until the follow-through, the weight goes back and then
onto the front foot, and the back foot rolls up onto its toe (which does not move) as the hips
open. The bat swing first strides the front foot towards the pitcher and steps back after it.
"""
from __future__ import annotations

import numpy as np

from .curves import frame_times, keyframes
from .footwork import Persona, Plant, Stance, Swing, flat_pitch, foot_track, max_pelvis_height
from .kinematics import FPS, BodyModel, arm_angles_for_target, foot_vector, heading_vectors, ypr_matrix
from .segment import Segment, knee_poles, num_frames, standing_pose

__all__ = ["swing", "GRIP_GAP"]

#: Distance (m) between the two wrists on the club's grip.
GRIP_GAP = 0.06


def _tempo(mods: tuple[str, ...]) -> float:
    return 1.35 if "slowly" in mods else (0.75 if "quickly" in mods else 1.0)


def _grip_within_reach(grip: np.ndarray, offsets: dict, body: BodyModel, reach: float = 0.96) -> np.ndarray:
    """``grip`` ``(N, 3)`` (chest frame) pulled towards the shoulders' midpoint where a hand (at
    the grip plus its offset) would be beyond ``reach`` of its arm's length, so both wrists are
    met exactly and stay the same distance apart."""
    centre = body.shoulder_offsets.mean(0)

    def worst(g):
        return np.max([np.linalg.norm(g + off - body.shoulder_offsets[k], axis=-1)
                       / (reach * (body.upper_arm[k] + body.forearm[k])) for k, off in offsets.items()], axis=0)

    lo, hi = np.zeros(len(grip)), np.ones(len(grip))
    fits = worst(grip) <= 1.0
    for _ in range(30):                               # bisect the largest scale towards the centre that fits
        mid = 0.5 * (lo + hi)
        ok = worst(centre + (grip - centre) * mid[:, None]) <= 1.0
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    scale = np.where(fits, 1.0, lo)
    return centre + (grip - centre) * scale[:, None]


def swing(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *, side: int,
          bat: bool = False, mods: tuple[str, ...] = ()) -> Segment:
    """Swing a golf club (or, ``bat``, a baseball bat) that winds up over the ``side`` shoulder
    (0 left, 1 right: a right-handed player's club goes back over the right shoulder) and
    follows through over the other one.

    The grip goes through keys in the chest frame (address or stance, the top of the back swing
    over the ``side`` shoulder, the hit low in front for golf or at the belly for the bat, the
    finish over the other shoulder) with a continuous speed through the down swing and the hit.
    ``info`` holds the key times.
    """
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    sgn = 1.0 if side == 0 else -1.0                 # + winds up towards the body's left
    back, front = side, 1 - side                     # the back foot is on the wind-up side
    fwd, left = heading_vectors(start.yaw)
    # ---- timeline: set up, (stride,) back swing, down swing, follow through, hold, return
    t_set = u(0.2, 0.3)
    t_addr = t_set + u(0.55, 0.75) * tempo
    t_top = t_addr + u(0.3, 0.5) * tempo + u(0.65, 0.85) * tempo
    t_hit = t_top + u(0.3, 0.36)
    t_fin = t_hit + u(0.3, 0.38)
    t_hold = t_fin + u(0.3, 0.6) * tempo
    t_end = t_hold + u(0.75, 0.95) * tempo
    total = t_end + u(0.3, 0.4)
    n = num_frames(total)
    tt = frame_times(n, FPS)
    pose = standing_pose(start, persona, n, body, rng=None, idle=False)
    kt = [0.0, t_set, t_addr, t_top, t_hit, t_fin, t_hold, t_end]

    def curve(values, velocities=None):
        return keyframes(tt, kt, np.asarray(values, dtype=np.float64),
                         None if velocities is None else np.asarray(velocities, dtype=np.float64))

    if bat:
        # grip keys (chest frame, x towards the wind-up side): stance at the back shoulder, load,
        # half way down, the hit in front of the belly, half way round, the finish over the front shoulder
        grip_keys = [(0.15, 0.1, 0.28), (0.18, 0.12, 0.24), (0.08, -0.05, 0.33), (-0.04, -0.1, 0.34),
                     (-0.16, 0.0, 0.28), (-0.16, 0.22, 0.22)]
        pitch = [0.0, 0.0, u(0.08, 0.14), 0.12, 0.1, 0.05, 0.05, 0.0]           # pelvis (forward lean)
        chest = [0.0, 0.0, 0.05, 0.05, 0.0, -0.05, -0.05, 0.0]
        knees = [0.0, 0.0, u(0.04, 0.07), 0.07, 0.06, 0.03, 0.03, 0.0]          # pelvis drop (m)
        hips = [0.0, 0.0, 0.0, sgn * u(0.1, 0.2), -sgn * u(0.5, 0.65), -sgn * u(0.8, 0.95), -sgn * 0.85, 0.0]
        shoulders = [0.0, 0.0, sgn * 0.15, sgn * u(0.3, 0.4), -sgn * u(0.15, 0.25), -sgn * u(0.5, 0.65), -sgn * 0.55, 0.0]
        look = -sgn * u(1.0, 1.2)                    # the eyes on the pitcher, off the front shoulder
        shift = [0.0, 0.0, 0.02, 0.05, -0.06, -0.09, -0.08, 0.0]                 # + over the back foot
    else:
        # address, top of the back swing over the back shoulder, half way down, the hit, half way
        # round, the finish over the front shoulder
        grip_keys = [(0.02, -0.15, 0.3), (0.16, 0.26, 0.25), (0.08, -0.03, 0.31), (0.02, -0.15, 0.3),
                     (-0.08, -0.03, 0.31), (-0.16, 0.26, 0.25)]
        lean = u(0.4, 0.55)
        pitch = [0.0, 0.0, lean, lean, lean, 0.2, 0.15, 0.0]
        chest = [0.0, 0.0, u(0.1, 0.2), 0.1, 0.12, -0.05, -0.05, 0.0]
        knees = [0.0, 0.0, u(0.04, 0.07), 0.06, 0.06, 0.03, 0.03, 0.0]
        hips = [0.0, 0.0, 0.0, sgn * u(0.4, 0.5), -sgn * u(0.25, 0.35), -sgn * u(0.8, 0.95), -sgn * 0.85, 0.0]
        shoulders = [0.0, 0.0, 0.0, sgn * u(0.8, 0.95), sgn * 0.1, -sgn * u(0.55, 0.7), -sgn * 0.6, 0.0]
        look = 0.0                                   # the eyes on the ball in front
        shift = [0.0, 0.0, 0.0, 0.04, -0.03, -0.07, -0.06, 0.0]
    # ---- the grip: held from the set-up on, through the keys; at speed through the hit
    g = (np.asarray(grip_keys) + rng.uniform(-0.01, 0.01, size=(len(grip_keys), 3))) * np.array([sgn, 1.0, 1.0])
    t_mid, t_mid2 = t_top + 0.55 * (t_hit - t_top), t_hit + 0.45 * (t_fin - t_hit)
    gt = [t_addr, t_top, t_mid, t_hit, t_mid2, t_fin]
    vel = np.zeros_like(g)
    for i in (2, 3, 4):                              # Catmull-Rom speeds through the down swing and the hit
        vel[i] = (g[i + 1] - g[i - 1]) / (gt[i + 1] - gt[i - 1])
    grip = keyframes(tt, gt, g, vel)
    offsets = {front: np.zeros(3), back: np.array([0.0, GRIP_GAP if bat else -GRIP_GAP, 0.0])}
    grip = _grip_within_reach(grip, offsets, body)
    # the hands hold the grip a hand's width apart (in the chest frame): on a golf club the back
    # hand is below the front one, on a bat above it (the offsets above)
    hands_on = curve([0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0])
    for k in (front, back):
        wrist = grip + offsets[k]
        local = wrist - body.shoulder_offsets[k][None]
        if k == 1:
            local[:, 0] *= -1.0                      # arm controls: x outwards for either arm
        held = arm_angles_for_target(local, body.upper_arm[k], body.forearm[k])
        pose.arm[:, k] += hands_on[:, None] * (held - pose.arm[:, k])
        pole = np.array([0.3, -0.6, -0.8]) if k == front else np.array([0.5, -0.8, -0.3])
        pose.arm_pole[:, k] += hands_on[:, None] * (pole - pose.arm_pole[:, k])
    pose.arm_pole /= np.linalg.norm(pose.arm_pole, axis=-1, keepdims=True)
    # ---- trunk and head
    hip_yaw, chest_yaw = curve(hips), curve(shoulders)
    pose.pelvis_ypr[:, 0] += hip_yaw
    pose.pelvis_ypr[:, 1] += curve(pitch)
    pose.spine[:, 0] += chest_yaw
    pose.spine[:, 1] += curve(chest)
    eyes = curve([0.0, 0.0, 1.0, 1.0, 1.0, 0.35, 0.3, 0.0])          # 1: on the ball / the pitcher
    pose.neck[:, 0] += np.clip(eyes * (look - 0.85 * (hip_yaw + chest_yaw)), -1.3, 1.3)
    pose.neck[:, 1] += (0.0 if bat else u(0.25, 0.4)) * eyes
    # ---- feet: the back foot rolls up onto its toe as the hips open; the bat strides first
    phi0 = flat_pitch(body)
    toe = start.ankles[back] + foot_vector(float(start.foot_yaw[back]), phi0[back], body.foot[back])
    lift = curve([0.0, 0.0, 0.0, 0.0, 0.25, u(0.6, 0.8), 0.7, 0.0])
    yaw_b = start.foot_yaw[back] + curve([0.0, 0.0, 0.0, 0.0, 0.0, -sgn * u(0.3, 0.45), -sgn * 0.35, 0.0])
    pose.ankle[:, back] = toe - foot_vector(yaw_b, phi0[back] + lift, np.full(n, body.foot[back]))
    pose.toe[:, back] = toe
    planted = np.ones((n, 2), dtype=bool)
    stride = 0.0
    if bat:
        stride = u(0.2, 0.3)
        out = start.ankles[front] - sgn * left * stride
        t_lift = t_addr + 0.15 * tempo
        t_land = t_top - 0.05
        t_off = t_hold + 0.1
        plants = [Plant(-np.inf, t_lift, start.ankles[front], float(start.foot_yaw[front]), roll_out=-0.25,
                        roll_out_time=0.1),
                  Plant(t_land, t_off, out, float(start.foot_yaw[front]), roll_in=0.05, roll_in_time=0.06,
                        roll_out=-0.2, roll_out_time=0.1),
                  Plant(t_end - 0.2, np.inf, start.ankles[front], float(start.foot_yaw[front]), roll_in=0.1,
                        roll_in_time=0.08)]
        pose.ankle[:, front], pose.toe[:, front], on = foot_track(tt, plants, [Swing(u(0.05, 0.08), 0.5, 0.1)] * 2,
                                                                  body, front)
        planted[:, front] = on
    feet = pose.ankle.mean(1)
    pose.pelvis[:, [0, 2]] += (feet - feet[0])[:, [0, 2]] * 0.8
    pose.pelvis += (sgn * curve(shift))[:, None] * left[None]
    pose.pelvis[:, 1] -= curve(knees)
    pose.pelvis -= fwd[None] * (0.18 * (curve(pitch)))[:, None]      # the hips go back as the trunk bends
    foot_yaw = np.tile(start.foot_yaw, (n, 1))
    foot_yaw[:, back] = yaw_b
    pose.knee_pole = knee_poles(foot_yaw)
    bound = max_pelvis_height(pose.pelvis, ypr_matrix(pose.pelvis_ypr), pose.ankle, body, planted=planted) - 0.004
    pose.pelvis[:, 1] = np.minimum(pose.pelvis[:, 1], bound)
    core = (max(0, int(np.floor((t_set - 0.05) * FPS))), min(n, int(np.ceil((t_end + 0.05) * FPS)) + 1))
    return Segment(pose, start, core, arms_free=False,
                   info=dict(style="bat" if bat else "golf", hit_time=float(t_hit), top_time=float(t_top),
                             finish_time=float(t_fin), stride=float(stride), back_toe=toe.tolist()))
