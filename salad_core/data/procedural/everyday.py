"""Everyday whole-body actions: throwing, picking something up from the floor, stepping over
something, stumbling, and (2.7) reaching up high across the body.

Throwing and picking up keep both feet planted (the pelvis shifts and lowers over them, its
height bounded by the legs' reach); picking up puts the wrist(s) at a point on the floor below
the shoulders at the bottom of a deep squat (exact, by :mod:`.reach`). Stepping over and
stumbling are walks (:func:`~.gait.locomotion`: planted feet, no sliding) with a high swing, or a
forward lurch of the trunk with the arms thrown out and a quick recovery.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .curves import ease, frame_times, keyframes
from .footwork import Persona, Plant, Stance, Swing, flat_pitch, foot_track, max_pelvis_height
from .gait import Route, gait_style, locomotion
from .kinematics import FPS, BodyModel, arm_angles_for_target, assemble, foot_vector, heading_vectors, ypr_matrix
from .poses import rest_target
from .reach import arm_controls_for, nearest_controls, shoulders, wrist_reach
from .segment import Segment, num_frames, standing_pose

__all__ = ["throw", "pick_up", "step_over", "stumble", "reach_up", "FLOOR_WRIST_HEIGHT"]

#: Wrist height (m) when the hand rests on the floor to pick something up (as a palm on the
#: floor, :data:`.actions.WRIST_ON_FLOOR`).
FLOOR_WRIST_HEIGHT = 0.04


def _tempo(mods: tuple[str, ...]) -> float:
    return 1.35 if "slowly" in mods else (0.75 if "quickly" in mods else 1.0)


def _bound_pelvis(pose, body) -> None:
    g0 = ypr_matrix(pose.pelvis_ypr)
    bound = max_pelvis_height(pose.pelvis, g0, pose.ankle, body) - 0.003
    pose.pelvis[:, 1] = np.minimum(pose.pelvis[:, 1], bound)


def throw(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *, side: int,
          underhand: bool = False, mods: tuple[str, ...] = ()) -> Segment:
    """Throw with arm ``side`` (0 left, 1 right), overhand (wind up behind the head) or underhand.

    The chest winds up towards the throwing side and turns through the release; the weight
    moves back, then forward; the other arm points ahead, then pulls in.
    """
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    sgn = 1.0 if side == 0 else -1.0
    fwd, _ = heading_vectors(start.yaw)
    if underhand:
        back = np.array([u(0.08, 0.14), -u(0.42, 0.47), -u(0.22, 0.28)])
        release = np.array([u(-0.02, 0.03), -u(0.12, 0.2), u(0.42, 0.47)])
        follow = np.array([u(-0.08, -0.03), u(0.02, 0.1), u(0.42, 0.46)])
    else:
        back = np.array([u(0.26, 0.32), u(0.17, 0.24), -u(0.18, 0.25)])      # the hand winds up over the head
        release = np.array([u(0.12, 0.16), u(0.28, 0.34), u(0.28, 0.34)])
        follow = np.array([-u(0.08, 0.12), -u(0.38, 0.42), u(0.26, 0.32)])
    t_wind = u(0.25, 0.35)
    t_back = t_wind + u(0.45, 0.65) * tempo
    t_rel = t_back + u(0.06, 0.1) + u(0.22, 0.28) * tempo
    t_follow = t_rel + u(0.25, 0.35) * tempo
    t_rest = t_follow + u(0.5, 0.7) * tempo
    total = t_rest + u(0.2, 0.3)
    n = num_frames(total)
    tt = frame_times(n, FPS)
    pose = standing_pose(start, persona, n, body, rng=None, idle=False)
    kt = [0.0, t_wind, t_back, t_back + 0.06, t_rel, t_follow, t_rest]
    up, fo = body.upper_arm[side], body.forearm[side]
    keys = np.stack([rest_target(persona, body, side)] * 2 + [back, back, release, follow,
                                                              rest_target(persona, body, side)])
    path = keyframes(tt, kt, keys)
    pose.arm[:, side] = arm_angles_for_target(path, up, fo)
    # the elbow points back and out for either throw: a downward pole (2.0's underhand) bent the
    # hanging arm's forearm backwards (the physics benchmark's elbow rule flagged every toss)
    pose.arm_pole[:, side] = (0.6, -0.3, -1.0)
    other = 1 - side
    o_rest = pose.arm[0, other].copy()
    o_point = np.array([u(1.0, 1.3), u(0.1, 0.25), u(0.2, 0.4)])
    o_pull = np.array([u(0.2, 0.4), u(0.1, 0.2), u(1.2, 1.5)])
    # the guiding arm draws in over the whole release and follow-through, slower than the throwing one
    pose.arm[:, other] = keyframes(tt, kt, np.stack([o_rest, o_rest, o_point, o_point, 0.5 * (o_point + o_pull),
                                                     o_pull, o_rest]))
    turn = keyframes(tt, kt, [0.0, 0.0, sgn * u(0.35, 0.5), sgn * 0.45, -sgn * u(0.3, 0.45), -sgn * 0.35, 0.0])
    shift = keyframes(tt, kt, [0.0, 0.0, -u(0.03, 0.05), -0.04, u(0.05, 0.08), 0.06, 0.0])
    lean = keyframes(tt, kt, [0.0, 0.0, -0.06, -0.06, u(0.15, 0.25), 0.2, 0.0])
    dip = keyframes(tt, kt, [0.0, 0.0, u(0.02, 0.04), 0.03, u(0.03, 0.06), 0.04, 0.0])
    pose.pelvis += fwd[None] * shift[:, None]
    pose.pelvis[:, 1] -= dip + (0.04 * ease(tt, t_wind, t_back) * (1 - ease(tt, t_follow, t_rest)) if underhand else 0.0)
    pose.pelvis_ypr[:, 0] += 0.35 * turn
    pose.spine[:, 0] += 0.65 * turn
    pose.pelvis_ypr[:, 1] += 0.4 * lean
    pose.spine[:, 1] += 0.6 * lean
    pose.neck[:, 0] -= 0.8 * turn                             # the eyes stay on the target
    _bound_pelvis(pose, body)
    core = (max(0, int(np.floor((t_wind - 0.05) * FPS))), min(n, int(np.ceil((t_rest + 0.05) * FPS)) + 1))
    return Segment(pose, start, core, arms_free=False,
                   info=dict(style="underhand" if underhand else "overhand", release_time=float(t_rel)))


def pick_up(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *, arms: tuple[int, ...],
            mods: tuple[str, ...] = ()) -> Segment:
    """Squat and bend down, put the hand(s) ``arms`` on the floor, and stand up holding the thing.

    At the bottom the wrists are at :data:`FLOOR_WRIST_HEIGHT` exactly, below the shoulders.
    """
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    fwd, left = heading_vectors(start.yaw)
    t1 = u(0.2, 0.3)
    t2 = t1 + u(0.8, 1.05) * tempo
    t3 = t2 + u(0.3, 0.5) * tempo
    t4 = t3 + u(0.85, 1.1) * tempo
    t5 = t4 + u(0.35, 0.6)
    t6 = t5 + u(0.45, 0.6) * tempo
    total = t6 + u(0.15, 0.25)
    n = num_frames(total)
    tt = frame_times(n, FPS)
    kt = [0.0, t1, t2, t3, t4, t5, t6]
    base = standing_pose(start, persona, n, body, rng=None, idle=False)
    drop, lean = u(0.46, 0.52), u(0.72, 0.82)
    for _ in range(6):                            # lower further until the floor is within reach
        pose = base.copy()
        down = keyframes(tt, kt, [0.0, 0.0, 1.0, 0.98, 0.0, 0.0, 0.0])
        pose.pelvis[:, 1] -= drop * down
        pose.pelvis -= fwd[None] * (0.3 * drop * down)[:, None]
        pose.pelvis_ypr[:, 1] += lean * down
        pose.spine[:, 1] += 0.6 * lean * down
        pose.neck[:, 1] -= 0.3 * down
        _bound_pelvis(pose, body)
        bottom = int(np.ceil(t2 * FPS))           # first frame with the hands down (weight 1)
        sh = shoulders(pose.slice(bottom, bottom + 1), body)[0]
        ks = list(arms)
        spot = sh[ks].mean(0) + fwd * 0.04
        spot[1] = FLOOR_WRIST_HEIGHT
        need = max(np.linalg.norm(sh[k] - (spot + left * (0.1 if k == 0 else -0.1) * (len(ks) == 2))) for k in ks)
        if need < 0.97 * min(wrist_reach(body, k) for k in ks):
            break
        drop, lean = min(drop + 0.02, 0.56), lean + 0.05
    reach_w = keyframes(tt, kt, [0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    hold_w = keyframes(tt, kt, [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0])
    hand_w, hand_t = np.zeros((n, 2)), np.zeros((n, 2, 3))
    for k in arms:
        target = spot + left * ((0.1 if k == 0 else -0.1) if len(arms) == 2 else 0.0)
        # the composer re-solves the reach after the posture is laid on (exact at the floor)
        hand_w[:, k] = reach_w
        hand_t[:, k] = target
        touch = arm_controls_for(pose, body, k, np.tile(target, (n, 1)))
        held = arm_angles_for_target(np.array([-0.06 if len(arms) == 1 else -0.1, -u(0.32, 0.36), u(0.22, 0.28)]),
                                     body.upper_arm[k], body.forearm[k])
        rest = pose.arm[:, k].copy()
        pose.arm[:, k] = rest + reach_w[:, None] * (touch - rest) + hold_w[:, None] * (held - rest)
        pose.arm_pole[:, k] = (0.5, -0.6, -0.6)
    for k in set((0, 1)) - set(arms):             # the free arm hangs forward of the knees
        pose.arm[:, k, 0] += 0.6 * keyframes(tt, kt, [0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    core = (max(0, int(np.floor((t1 - 0.05) * FPS))), min(n, int(np.ceil((t5 + 0.05) * FPS)) + 1))
    return Segment(pose, start, core, arms_free=False, hands=(hand_w, hand_t),
                   info=dict(floor_point=spot.tolist(), bottom_frame=bottom, drop=float(drop)))


def step_over(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
              mods: tuple[str, ...] = ()) -> Segment:
    """Step over an obstacle: two or three slow steps with the feet lifted high over it."""
    u = rng.uniform
    style = gait_style("walk", rng, mods, persona.tempo)
    style = replace(style, speed=style.speed * u(0.55, 0.7), cadence=style.cadence * u(0.7, 0.8),
                    swing=Swing(u(0.3, 0.4), u(0.42, 0.5), u(0.25, 0.4), lead=u(0.06, 0.1)),
                    lean=style.lean + u(0.06, 0.1), arm_abd=u(0.15, 0.3), duty=0.66)
    seg = locomotion(start, persona, style, Route(), int(rng.integers(2, 4)), body)
    seg.info["swing_height"] = style.swing.height
    return seg


def stumble(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
            mods: tuple[str, ...] = ()) -> Segment:
    """Walk, trip mid-stride (the trunk pitches forward, the arms fly out), and recover."""
    u = rng.uniform
    style = gait_style("walk", rng, mods, persona.tempo)
    steps = int(rng.integers(4, 6))
    seg = locomotion(start, persona, style, Route(), steps, body)
    pose = seg.pose
    n = pose.num_frames
    tt = frame_times(n, FPS)
    step_t = 1.0 / style.cadence
    t_trip = 0.25 + u(1.2, 1.8) * step_t
    t_peak = t_trip + u(0.18, 0.26)
    t_back = t_peak + u(0.5, 0.7)
    lurch = keyframes(tt, [0.0, t_trip, t_peak, t_back], [0.0, 0.0, 1.0, 0.0])
    amount = u(0.3, 0.42)
    pose.pelvis_ypr[:, 1] += 0.4 * amount * lurch
    pose.spine[:, 1] += 0.6 * amount * lurch
    pose.neck[:, 1] -= 0.5 * amount * lurch                  # the head comes up to look ahead
    pose.pelvis[:, 1] -= u(0.03, 0.05) * lurch
    pose.arm[:, :, 0] += (u(0.7, 1.0) * lurch)[:, None]
    pose.arm[:, :, 1] += (u(0.35, 0.6) * lurch)[:, None]
    pose.arm[:, :, 2] = pose.arm[:, :, 2] * (1 - 0.5 * lurch)[:, None]
    # no reach bound here: the lurch lowers the pelvis by more than pitching moves the hips
    seg.info.update(trip_time=float(t_trip), lurch=float(amount))
    return Segment(pose, seg.end, seg.core, arms_free=False, info=seg.info)


def reach_up(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *, side: int,
             mods: tuple[str, ...] = ()) -> Segment:
    """Reach up high across the body with hand ``side`` (0 left, 1 right): step out forward and
    to the other side, rise onto the toes, stretch the trunk up and over towards the reach with
    the arm straight above the head (a high shelf), hold, come down and step back (2.7).

    On the toes the toe joints stay where the feet landed and the heels rise about them; the
    reaching wrist goes to a point 0.96 of the arm's length above and beyond the shoulder.
    """
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    sgn = 1.0 if side == 0 else -1.0                 # + the left hand, reaching over to the right
    k, o = side, 1 - side                            # the foot on the reach side steps out
    fwd, left = heading_vectors(start.yaw)
    up = np.array([0.0, 1.0, 0.0])
    way = fwd * u(0.5, 0.9) - sgn * left
    way /= np.linalg.norm(way)
    t_lift = u(0.2, 0.3)
    swing_t = u(0.35, 0.45) * tempo
    t_land = t_lift + swing_t
    t_up = t_land + u(0.5, 0.7) * tempo
    t_hold = t_up + u(0.3, 0.6) * tempo
    t_down = t_hold + u(0.5, 0.7) * tempo
    t_back = t_down + u(0.15, 0.25)
    t_home = t_back + swing_t
    total = t_home + u(0.3, 0.4)
    n = num_frames(total)
    tt = frame_times(n, FPS)
    pose = standing_pose(start, persona, n, body, rng=None, idle=False)
    # ---- feet: the step out and back, and both heels up about the toes while reaching
    out = start.ankles[o] + way * u(0.4, 0.55)
    yaw_o = float(start.foot_yaw[o])
    plants = [Plant(-np.inf, t_lift, start.ankles[o], yaw_o, roll_out=-0.25, roll_out_time=0.1),
              Plant(t_land, t_back, out, yaw_o, roll_in=0.1, roll_in_time=0.08, roll_out=-0.2, roll_out_time=0.1),
              Plant(t_home, np.inf, start.ankles[o], yaw_o, roll_in=0.1, roll_in_time=0.08)]
    pose.ankle[:, o], pose.toe[:, o], planted_o = foot_track(tt, plants, [Swing(u(0.05, 0.08), 0.5, 0.1)] * 2, body, o)
    rise = np.clip(keyframes(tt, [t_land + 0.1, t_up, t_hold, t_down], [0.0, 1.0, 1.0, 0.0]), 0.0, 1.0)
    heel = u(0.35, 0.5) * rise
    phi0 = flat_pitch(body)
    for f in (k, o):
        on = heel > 1e-9
        toe = pose.toe[on, f]
        yaw = np.full(on.sum(), float(start.foot_yaw[f]))
        pose.ankle[on, f] = toe - foot_vector(yaw, phi0[f] + heel[on], np.full(on.sum(), body.foot[f]))
    lifted = float(body.foot.mean() * (np.sin(phi0.mean() + heel.max()) - np.sin(phi0.mean())))
    # ---- the body: weight over the front foot, up on the toes, the trunk stretching over
    weight = keyframes(tt, [0.0, t_lift, t_land, t_up, t_hold, t_down, t_home], [0.0, 0.0, 0.5, 1.0, 1.0, 0.6, 0.0])
    d = (out - start.ankles[o]) * np.array([1.0, 0.0, 1.0])
    pose.pelvis += weight[:, None] * (0.6 * d)[None]
    pose.pelvis[:, 1] += 0.8 * lifted * rise
    pose.pelvis_ypr[:, 0] += -sgn * u(0.1, 0.25) * weight
    pose.pelvis_ypr[:, 2] += sgn * 0.05 * rise
    pose.spine[:, 1] += -u(0.05, 0.15) * rise
    pose.spine[:, 2] += -sgn * u(0.4, 0.6) * rise
    pose.spine[:, 0] += -sgn * u(0.25, 0.4) * rise
    pose.neck[:, 1] += -u(0.3, 0.5) * rise                # looking up at the hand
    pose.neck[:, 0] += -sgn * u(0.1, 0.25) * rise
    planted = np.stack([np.ones(n), planted_o], 1) if o == 1 else np.stack([planted_o, np.ones(n)], 1)
    bound = max_pelvis_height(pose.pelvis, ypr_matrix(pose.pelvis_ypr), pose.ankle, body,
                              planted=planted > 0.5) - 0.004
    pose.pelvis[:, 1] = np.minimum(pose.pelvis[:, 1], bound)
    # ---- the reaching arm: forward and up over the head, to a point above and beyond the step
    peak = int(np.clip(np.round(0.5 * (t_up + t_hold) * FPS), 0, n - 1))
    sh = shoulders(pose.slice(peak, peak + 1), body)[0, k]
    aim = up + 0.45 * way
    target = sh + aim / np.linalg.norm(aim) * 0.96 * wrist_reach(body, k)
    reach = arm_controls_for(pose, body, k, np.tile(target, (n, 1)))
    # forward and up over the head (not round the back), written one way in every frame
    reach = nearest_controls(reach, nearest_controls(reach[peak], pose.arm[peak, k]))
    aw = np.clip(keyframes(tt, [t_land - 0.1, t_up, t_hold, t_down + 0.1], [0.0, 1.0, 1.0, 0.0]), 0.0, 1.0)
    pose.arm[:, k] += aw[:, None] * (reach - pose.arm[:, k])
    pose.arm[:, o, 1] += 0.25 * rise                     # the other arm opens a little for balance
    wrist = assemble(pose.slice(peak, peak + 1), body)[0, body.j("left_wrist" if k == 0 else "right_wrist")]
    core = (max(0, int(np.floor((t_lift - 0.05) * FPS))), min(n, int(np.ceil((t_home + 0.05) * FPS)) + 1))
    return Segment(pose, start, core, arms_free=False,
                   info=dict(reach_height=float(wrist[1]), peak_frame=peak, step=float(np.linalg.norm(d)),
                             heel_lift=float(heel.max())))
