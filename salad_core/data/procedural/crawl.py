"""Crawling on hands and knees.

A crawl clip starts and ends on all fours (the corpus's clips may start mid-motion): the knees
rest on the floor under the hips, the shins lie back along the floor, the hands are planted
under the shoulders. The limbs step in the quadruped walk order (right hand, left knee, left
hand, right knee, a quarter cycle apart), three on the floor at any time, while the body moves
forward at a constant speed. Each knee is placed exactly a thigh's length from its hip towards
its floor point (so it stays within millimetres of it), the shin follows; the wrists are put on
their floor points by :mod:`.reach` (and re-solved by the composer after the posture is laid on).
"""
from __future__ import annotations

import numpy as np

from .curves import frame_times, min_jerk
from .floorwork import KNEE_FLOOR
from .footwork import Persona, Stance
from .kinematics import FPS, BodyModel, Pose, foot_vector, heading_vectors, ypr_matrix
from .reach import arm_controls_for, shoulders, wrist_reach
from .segment import Segment, num_frames

__all__ = ["crawl", "CRAWL_ORDER", "HAND_ON_FLOOR"]

#: Limb phases (fraction of a cycle) of the quadruped walk: (limb, phase); limbs are
#: ("hand", 1) = right hand, ("knee", 0) = left knee, ...
CRAWL_ORDER = ((("hand", 1), 0.0), (("knee", 0), 0.25), (("hand", 0), 0.5), (("knee", 1), 0.75))
#: Wrist height (m) of a hand planted on the floor (a palm on the floor, as when sitting).
HAND_ON_FLOOR = 0.04
#: Share of a cycle a limb spends in the air.
SWING_SHARE = 0.25


def _tempo(mods: tuple[str, ...]) -> float:
    return 1.35 if "slowly" in mods else (0.75 if "quickly" in mods else 1.0)


def _limb_track(t: np.ndarray, lands: list[float], spots: list[np.ndarray], swing: float, lift: float) -> np.ndarray:
    """``(N, 3)`` floor-point track of one limb: at ``spots[i]`` from landing ``lands[i]`` on, moving
    to ``spots[i+1]`` during the ``swing`` seconds before ``lands[i+1]`` with a ``lift`` m arc."""
    out = np.tile(spots[0], (len(t), 1)).astype(np.float64)
    for i in range(1, len(spots)):
        t0, t1 = lands[i] - swing, lands[i]
        tau = np.clip((t - t0) / swing, 0.0, 1.0)
        m = min_jerk(tau)[:, None]
        seg = spots[i - 1] + (spots[i] - spots[i - 1]) * m
        seg[:, 1] += lift * np.sin(np.pi * tau)
        out = np.where((t >= t0)[:, None], seg, out)
    return out


def crawl(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
          mods: tuple[str, ...] = ()) -> Segment:
    """Crawl forward on hands and knees for two to four cycles (starts and ends on all fours)."""
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    fwd, left = heading_vectors(start.yaw)
    up = np.array([0.0, 1.0, 0.0])
    period = u(1.1, 1.5) * tempo
    stride = u(0.18, 0.28)
    cycles = int(rng.integers(2, 4))
    lead, tail = u(0.3, 0.5), u(0.3, 0.5)
    total = lead + cycles * period + tail
    n = num_frames(total)
    tt = frame_times(n, FPS)
    swing = SWING_SHARE * period
    speed = stride / period
    # the body advances steadily while the limbs step
    x = speed * np.clip(tt - lead, 0.0, cycles * period)
    pelvis_xz = start.ground[None] + fwd[None] * x[:, None]

    # ---- trunk: near horizontal, the head up to look ahead (the head's share of the posture is
    # taken off here: the composer lays it on again)
    pitch = u(1.25, 1.4)
    ypr = np.tile(np.array([start.yaw, pitch, 0.0]), (n, 1))
    w = 2 * np.pi * tt / period
    ypr[:, 2] += u(0.03, 0.06) * np.sin(w)                     # hips roll with the knees
    spine = np.zeros((n, 3))
    spine[:, 0] += u(0.04, 0.08) * np.sin(w + np.pi / 2)       # shoulders turn with the hands
    spine[:, 1] = u(-0.1, 0.1)          # (the composer lays a quarter of the posture on a propped trunk)
    neck = np.tile(np.array([0.0, -u(0.6, 0.9) + 0.5 * persona.slouch, 0.0]), (n, 1))
    g0 = ypr_matrix(ypr)
    hip_off = np.einsum("nij,kj->nki", g0, body.hip_offsets)   # (N, 2, 3)
    # pelvis height: each hip a thigh's length over its knee's floor point (mean of the two)
    thigh = body.thigh
    hip_h = KNEE_FLOOR + thigh - hip_off[:, :, 1]              # (N, 2) pelvis heights per leg
    pelvis = pelvis_xz.copy()
    pelvis[:, 1] = hip_h.mean(1)
    pose = Pose(pelvis, ypr, spine, neck, np.zeros((n, 2, 3)), np.zeros((n, 2, 3)), np.zeros((n, 2, 3)),
                np.tile(np.asarray(persona.arm_rest, dtype=np.float64), (n, 2, 1)),
                np.tile(np.array([0.3, -1.0, 0.0]), (n, 2, 1)))
    # bend the chest down until the hands reach the floor over the whole stance (shoulders up to
    # half a stride ahead of or behind the planted hand), with the elbows a little soft
    arm = min(wrist_reach(body, k) for k in range(2))
    allowed = np.sqrt((0.97 * arm) ** 2 - (0.4 * stride + 0.04) ** 2)
    for _ in range(8):
        excess = shoulders(pose, body)[..., 1].max() - HAND_ON_FLOOR - allowed
        if excess <= 0.0:
            break
        pose.spine[:, 1] += min(0.2, excess / 0.35 + 0.01)
    # ---- where the limbs land: knees under the hips, hands under the shoulders, at the middle
    # of the stance that follows
    hips = pelvis[:, None] + hip_off
    sh = shoulders(pose, body)
    mid = (1.0 - SWING_SHARE) * 0.5 * period

    def at(track: np.ndarray, time: float) -> np.ndarray:
        return np.array([np.interp(time, tt, track[:, c]) for c in range(3)])

    knees = np.zeros((n, 2, 3))
    wrists = np.zeros((n, 2, 3))
    for (limb, k), phase in CRAWL_ORDER:
        lands = [-np.inf] + [lead + (c + phase) * period + swing for c in range(cycles)]
        src = hips[:, k] if limb == "knee" else sh[:, k] + fwd * 0.04
        spots = [at(src, 0.0)] + [at(src, min(t_l + mid, tt[-1])) for t_l in lands[1:]]
        for s in spots:
            s[1] = KNEE_FLOOR if limb == "knee" else HAND_ON_FLOOR
        track = _limb_track(tt, lands, spots, swing, 0.04 if limb == "knee" else 0.06)
        (knees if limb == "knee" else wrists)[:, k] = track
    # ---- legs: the knee a thigh's length from the hip towards its floor point, the shin back
    # along the floor (rising a little to the ankle), the foot pointing back, toes off the floor
    for k in range(2):
        d = knees[:, k] - hips[:, k]
        knee = hips[:, k] + thigh[k] * d / np.linalg.norm(d, axis=-1, keepdims=True)
        rise = np.arcsin(0.075 / body.shin[k])
        shin_dir = -fwd * np.cos(rise) + up * np.sin(rise)
        ankle = knee + body.shin[k] * shin_dir[None]
        pose.ankle[:, k] = ankle
        pose.toe[:, k] = ankle + foot_vector(start.yaw + np.pi, 0.3, body.foot[k])[None]
        pose.knee_pole[:, k] = knee - hips[:, k]
    # ---- arms: wrists on their floor points (elbows back towards the knees)
    for k in range(2):
        pose.arm[:, k] = arm_controls_for(pose, body, k, wrists[:, k])
    reach = np.linalg.norm(wrists - shoulders(pose, body), axis=-1)
    hands = (np.ones((n, 2)), wrists)
    core = (max(0, int(np.floor((lead - 0.1) * FPS))), n)
    return Segment(pose, None, core, arms_free=False, seated=True, hands=hands,
                   info=dict(cycles=cycles, stride=float(stride), period=float(period),
                             reach_margin=float(min(wrist_reach(body, k) for k in range(2)) - reach.max())))
