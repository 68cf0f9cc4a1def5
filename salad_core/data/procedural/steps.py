"""Footwork beyond walking: stepping up onto a step and back down, climbing a flight of stairs,
pivoting on the ball of one foot, and touching a raised knee with the opposite hand.

Feet are planted (:class:`~.footwork.Plant`) at stair heights (ankles at ``ANKLE_HEIGHT`` plus
the step's rise), so a foot on a step stays put exactly as one on the floor. A pivot turns the
pivot foot about its toe with the heel raised: the toe joint does not move, the ankle circles
above the floor. The pelvis rides over the supporting feet and its height is bounded by the
legs' reach.
"""
from __future__ import annotations

import numpy as np

from .curves import envelope, frame_times, keyframes, min_jerk, smooth
from .footwork import ANKLE_HEIGHT, Persona, Plant, Stance, Swing, flat_pitch, foot_track, max_pelvis_height
from .kinematics import FPS, BodyModel, assemble, foot_vector, heading_vectors, rot_y, ypr_matrix
from .reach import arm_controls_for, shoulders, wrist_reach
from .segment import Segment, knee_poles, num_frames, standing_pose

__all__ = ["step_up", "climb_stairs", "descend_stairs", "shuffle", "lunge", "pivot", "touch_knee"]


def _tempo(mods: tuple[str, ...]) -> float:
    return 1.35 if "slowly" in mods else (0.75 if "quickly" in mods else 1.0)


def _stepping(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator,
              moves: list[tuple[int, np.ndarray, float]], swing_t: float, total: float, lift: float,
              roll_out: float = -0.3, roll_in: float = 0.1, pitch_mid: float = 0.15):
    """A standing pose whose feet make ``moves`` (foot, new flat ankle, lift-off time).

    The pelvis follows the feet (their mean, smoothed), rises with their height and stays
    within the legs' reach. ``roll_out`` / ``roll_in`` (rad) roll the foot off its toe and onto
    its heel, ``pitch_mid`` pitches it toe-up in mid-swing (0, 0, 0 with a small ``lift``: a
    shuffle, the sole gliding just over the floor). Returns the pose, the planted flags
    ``(N, 2)`` and the final ankles.
    """
    n = num_frames(total)
    tt = frame_times(n, FPS)
    pose = standing_pose(start, persona, n, body, rng=None, idle=False)
    plants: list[list[Plant]] = [[Plant(-np.inf, np.inf, start.ankles[k], float(start.foot_yaw[k]))] for k in range(2)]
    for foot, to, t_lift in moves:
        last = plants[foot][-1]
        plants[foot][-1] = Plant(last.t_on, t_lift, last.ankle, last.yaw, roll_in=last.roll_in,
                                 roll_in_time=last.roll_in_time, roll_out=roll_out,
                                 roll_out_time=0.12 if roll_out else 0.0)
        plants[foot].append(Plant(t_lift + swing_t, np.inf, to, float(start.foot_yaw[foot]), roll_in=roll_in,
                                  roll_in_time=0.08 if roll_in else 0.0))
    planted = np.zeros((n, 2))
    for k in range(2):
        airs = [Swing(lift, 0.45, pitch_mid)] * (len(plants[k]) - 1)
        pose.ankle[:, k], pose.toe[:, k], planted[:, k] = foot_track(tt, plants[k], airs, body, k)
    feet = smooth(pose.ankle.mean(1), 0.3 * FPS)
    rise = feet[:, 1] - feet[0, 1]
    pose.pelvis[:, [0, 2]] += (feet - feet[0])[:, [0, 2]]
    pose.pelvis[:, 1] += rise
    g0 = ypr_matrix(pose.pelvis_ypr)
    bound = max_pelvis_height(pose.pelvis, g0, pose.ankle, body, planted=planted > 0.5) - 0.004
    pose.pelvis[:, 1] = np.minimum(pose.pelvis[:, 1], bound)
    ends = np.stack([plants[k][-1].ankle for k in range(2)])
    return pose, planted, ends


def step_up(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
            mods: tuple[str, ...] = (), reps: int = 1) -> Segment:
    """Step up onto a step (0.15-0.3 m) with both feet and back down, ``reps`` times."""
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    fwd, _ = heading_vectors(start.yaw)
    height, depth = u(0.15, 0.3), u(0.3, 0.38)
    beat = u(0.55, 0.7) * tempo
    lead = int(rng.integers(2))
    t = u(0.25, 0.35)
    t0 = t
    moves = []
    for _ in range(reps):
        for foot, up in ((lead, True), (1 - lead, True), (lead, False), (1 - lead, False)):
            to = start.ankles[foot] + (fwd * depth + np.array([0.0, height, 0.0]) if up else 0.0)
            moves.append((foot, to, t))
            t += beat * (1.6 if (foot != lead and up) else 1.0)    # a moment on top
    total = t + u(0.3, 0.45)
    pose, _, _ = _stepping(start, persona, body, rng, moves, 0.6 * beat, total, 0.1 + 0.4 * height)
    tt = frame_times(pose.num_frames, FPS)
    act = envelope(tt, t0 - 0.1, t, 0.3)
    pose.pelvis_ypr[:, 1] += 0.12 * act                     # lean into the step
    pose.spine[:, 1] += 0.06 * act
    pose.arm[:, :, 0] += (0.2 * act)[:, None]
    n = pose.num_frames
    core = (max(0, int(np.floor((t0 - 0.1) * FPS))), min(n, int(np.ceil((t + 0.05) * FPS)) + 1))
    return Segment(pose, start, core, info=dict(step_height=float(height), reps=reps))


def _flight(start: Stance, fwd: np.ndarray, lead: int, stairs: int, run: float, rise: float, t: float,
            beat: float) -> tuple[list, float]:
    """Foot moves ``[(foot, ankle target (3,), time)]`` one foot per stair up (``rise`` > 0) or down
    (``rise`` < 0) a flight of ``stairs`` from ``start``, the trailing foot joining the leader on the
    last one; and the time after the last move. ``lead`` (0 left, 1 right) takes the first stair."""
    moves = []
    for i in range(1, stairs + 1):
        foot = (lead + i - 1) % 2
        moves.append((foot, start.ankles[foot] + fwd * (0.12 + i * run) + np.array([0.0, i * rise, 0.0]), t))
        t += beat
    last = (lead + stairs) % 2
    moves.append((last, start.ankles[last] + fwd * (0.12 + stairs * run) + np.array([0.0, stairs * rise, 0.0]), t))
    return moves, t + beat


def climb_stairs(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
                 mods: tuple[str, ...] = ()) -> Segment:
    """Walk up a flight of 3-5 stairs (one foot per stair) and stand on the top step."""
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    fwd, _ = heading_vectors(start.yaw)
    rise, run = u(0.14, 0.18), u(0.27, 0.31)
    stairs = int(rng.integers(3, 6))
    beat = u(0.6, 0.75) * tempo
    lead = int(rng.integers(2))
    t0 = u(0.25, 0.35)
    moves, t = _flight(start, fwd, lead, stairs, run, rise, t0, beat)
    total = t + u(0.3, 0.4)
    pose, _, ends = _stepping(start, persona, body, rng, moves, 0.7 * beat, total, 0.08 + 0.5 * rise)
    tt = frame_times(pose.num_frames, FPS)
    act = envelope(tt, t0 - 0.1, t, 0.4)
    pose.pelvis_ypr[:, 1] += 0.1 * act
    pose.spine[:, 1] += 0.06 * act
    # the arms swing a little, as in walking
    phase = np.clip((tt - t0) / beat, 0.0, None)
    swing = 0.2 * np.sin(np.pi * phase) * act
    pose.arm[:, 0, 0] += swing if lead == 1 else -swing
    pose.arm[:, 1, 0] += -swing if lead == 1 else swing
    n = pose.num_frames
    core = (max(0, int(np.floor((t0 - 0.1) * FPS))), min(n, int(np.ceil((t + 0.05) * FPS)) + 1))
    end = Stance(ends, start.foot_yaw, start.yaw)
    return Segment(pose, end, core, info=dict(stairs=stairs, rise=float(rise), top=float(stairs * rise)))


def _within_reach(pose, body: BodyModel, sigma: float = 2.0) -> None:
    """Keep the pelvis within reach of both ankle targets in every frame, smoothly (in place).

    A foot reaching down to a lower stair must get there before it lands: bounding the pelvis
    by the planted feet only would drop it in one frame at touch-down.
    """
    bound = max_pelvis_height(pose.pelvis, ypr_matrix(pose.pelvis_ypr), pose.ankle, body) - 0.006
    y = np.minimum(pose.pelvis[:, 1], bound)
    # smoothing a minimum can lift it back over the bound where the bound dips: take the lower
    pose.pelvis[:, 1] = np.minimum(smooth(y, sigma), bound)


def descend_stairs(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
                   mods: tuple[str, ...] = ()) -> Segment:
    """Walk down a flight of 3-5 stairs (one foot per stair) onto the floor.

    The performer starts on the top landing, the flight's height above ``start`` (an initial
    primitive: it opens a clip) and ends standing on the floor at ``start``'s level, about a
    metre further on. The gaze goes down to the steps.
    """
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    fwd, _ = heading_vectors(start.yaw)
    rise, run = u(0.14, 0.18), u(0.27, 0.31)
    stairs = int(rng.integers(3, 6))
    top = stairs * rise
    high = Stance(start.ankles + np.array([0.0, top, 0.0]), start.foot_yaw, start.yaw)
    beat = u(0.6, 0.75) * tempo
    lead = int(rng.integers(2))
    t0 = u(0.25, 0.35)
    moves, t = _flight(high, fwd, lead, stairs, run, -rise, t0, beat)
    total = t + u(0.3, 0.4)
    pose, _, ends = _stepping(high, persona, body, rng, moves, 0.7 * beat, total, 0.05 + 0.3 * rise)
    _within_reach(pose, body)
    tt = frame_times(pose.num_frames, FPS)
    act = envelope(tt, t0 - 0.1, t, 0.4)
    pose.neck[:, 1] += u(0.2, 0.4) * act                        # watching the steps
    pose.spine[:, 1] += 0.04 * act
    phase = np.clip((tt - t0) / beat, 0.0, None)
    swing = 0.15 * np.sin(np.pi * phase) * act
    pose.arm[:, 0, 0] += swing if lead == 1 else -swing
    pose.arm[:, 1, 0] += -swing if lead == 1 else swing
    pose.arm[:, :, 1] += (0.12 * act)[:, None]                 # arms a little out for balance
    n = pose.num_frames
    core = (max(0, int(np.floor((t0 - 0.1) * FPS))), min(n, int(np.ceil((t + 0.05) * FPS)) + 1))
    end = Stance(ends, start.foot_yaw, start.yaw)
    return Segment(pose, end, core, info=dict(stairs=stairs, rise=float(rise), top=float(top)))


def shuffle(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
            side: int | None = None, mods: tuple[str, ...] = ()) -> Segment:
    """Shuffle a few short steps forward (``side`` None) or sideways (0 left, 1 right).

    The soles glide a centimetre or two over the floor (no heel-toe roll): the moving foot
    stays within contact height, as in real shuffling, while the other one is planted.
    Sideways, the leading foot steps out and the other one closes up; forward, the feet
    take turns, each passing the other by a short step.
    """
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    fwd, left = heading_vectors(start.yaw)
    beat = u(0.3, 0.42) * tempo
    glide = u(0.6, 0.75) * beat
    t = u(0.2, 0.3)
    t0 = t
    ankles = start.ankles.copy()
    moves = []
    if side is None:
        step, n_steps = u(0.12, 0.2), int(rng.integers(4, 8))
        k = int(rng.integers(2))
        for i in range(n_steps):
            d = step if i in (0, n_steps - 1) else 2 * step            # start and finish side by side
            ankles[k] = ankles[k] + fwd * d
            moves.append((k, ankles[k].copy(), t))
            t += beat
            k = 1 - k
        dist = step * (n_steps - 1)
    else:
        step, n_steps = u(0.15, 0.25), int(rng.integers(2, 5))
        way = left * (1.0 if side == 0 else -1.0)
        for _ in range(n_steps):
            for k in (side, 1 - side):                                # lead out, trail closes
                ankles[k] = ankles[k] + way * step
                moves.append((k, ankles[k].copy(), t))
                t += beat * (0.8 if k == side else 1.0)
        dist = step * n_steps
    total = t + u(0.3, 0.4)
    pose, _, ends = _stepping(start, persona, body, rng, moves, glide, total, u(0.004, 0.012),
                              roll_out=0.0, roll_in=0.0, pitch_mid=0.0)
    tt = frame_times(pose.num_frames, FPS)
    act = envelope(tt, t0 - 0.1, t, 0.3)
    pose.pelvis[:, 1] -= u(0.01, 0.03) * act                   # knees a little softer
    pose.spine[:, 1] += u(0.02, 0.1) * act
    pose.arm[:, :, 1] += (u(0.05, 0.2) * act)[:, None]
    _within_reach(pose, body, sigma=1.0)
    n = pose.num_frames
    core = (max(0, int(np.floor((t0 - 0.1) * FPS))), min(n, int(np.ceil((t + 0.05) * FPS)) + 1))
    end = Stance(ends, start.foot_yaw, start.yaw)
    return Segment(pose, end, core, info=dict(steps=len(moves), distance=float(dist)))


def _lunge_timeline(u, home: np.ndarray, out: np.ndarray, k: int, t: float, reps: int, swing: float, tempo: float,
                    *, sink: tuple[float, float], rise: tuple[float, float]):
    """The step-sink-hold-rise-return timeline of a lunge, ``reps`` times, from time ``t`` (s).

    ``u`` draws uniforms (``rng.uniform``; the draws are sink, hold, rise per repetition, in that order);
    ``home`` / ``out`` (3,) are the lunging foot's ankle targets at rest and lunged. Returns the foot
    ``moves`` for :func:`_stepping` ((foot, ankle target, start time) tuples), the sink weight's keyframe
    times and values (0 standing, 1 at the bottom) and the time the last return step starts.
    """
    moves, sink_t, sink_w = [], [0.0, t], [0.0, 0.0]
    for _ in range(reps):
        moves.append((k, out.copy(), t))
        t += swing
        sink_t.append(t); sink_w.append(0.15)
        t += u(*sink) * tempo
        sink_t.append(t); sink_w.append(1.0)
        t += u(0.2, 0.5) * tempo                                # hold at the bottom
        sink_t.append(t); sink_w.append(1.0)
        t += u(*rise) * tempo
        sink_t.append(t); sink_w.append(0.1)
        moves.append((k, home.copy(), t))
        t += swing
        sink_t.append(t); sink_w.append(0.0)
    return moves, sink_t, sink_w, t


def lunge(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *, side: int,
          mods: tuple[str, ...] = (), reps: int = 1, sideways: bool = False, arms_forward: bool = True) -> Segment:
    """Lunge forward with the ``side`` leg (0 left, 1 right) and push back to standing, ``reps`` times.

    The front foot steps out 0.6-0.85 m, the pelvis sinks between the feet (the front thigh
    towards level, the rear knee towards the floor, the rear heel rising off it as the shin
    leans over the foot) and the front foot pushes back to its place.

    ``sideways`` (2.7): a side lunge. The ``side`` foot steps out to that side (0.5-0.7 m beyond
    the stance), the pelvis travels over it and sinks (its knee bends, the other leg stays
    straight, its foot flat: the straight leg's reach sets how low the pelvis goes), the trunk
    leans forward over the bent knee with the arms reaching forward for balance, and the foot
    pushes back to its place (``arms_forward`` False: the arms stay free for a gesture on top).
    """
    if sideways:
        return _side_lunge(start, persona, body, rng, side=side, mods=mods, reps=reps, arms_forward=arms_forward)
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    fwd, _ = heading_vectors(start.yaw)
    k = side
    length = u(0.6, 0.85) * float(body.leg[k]) / 0.85
    depth = u(0.28, 0.38) if "low" in mods else u(0.18, 0.3)
    swing = u(0.3, 0.4) * tempo
    t = u(0.2, 0.3)
    t0 = t
    moves, sink_t, sink_w, t = _lunge_timeline(u, start.ankles[k], start.ankles[k] + fwd * length, k, t, reps,
                                               swing, tempo, sink=(0.35, 0.5), rise=(0.3, 0.45))
    total = t + u(0.3, 0.4)
    pose, _, ends = _stepping(start, persona, body, rng, moves, swing, total, 0.06, roll_out=0.0, roll_in=0.15)
    tt = frame_times(pose.num_frames, FPS)
    w = np.clip(keyframes(tt, sink_t, sink_w), 0.0, 1.0)
    pose.pelvis[:, 1] -= depth * w
    pose.pelvis_ypr[:, 1] += u(0.0, 0.15) * w                 # a slight forward lean of the trunk
    pose.spine[:, 1] += u(-0.1, 0.1) * w
    pose.arm[:, :, 0] += (u(0.0, 0.3) * w)[:, None]
    _within_reach(pose, body, sigma=1.0)
    n = pose.num_frames
    core = (max(0, int(np.floor((t0 - 0.1) * FPS))), min(n, int(np.ceil((t + 0.05) * FPS)) + 1))
    return Segment(pose, start, core, info=dict(length=float(length), depth=float(depth), reps=reps))


def _side_lunge(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *, side: int,
                mods: tuple[str, ...], reps: int, arms_forward: bool = True) -> Segment:
    """The side lunge of :func:`lunge` (``sideways=True``)."""
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    fwd, left = heading_vectors(start.yaw)
    k = side
    way = left * (1.0 if side == 0 else -1.0)
    length = u(0.5, 0.7) * float(body.leg[k]) / 0.85
    depth = u(0.3, 0.4) if "low" in mods else u(0.2, 0.3)
    over = u(0.25, 0.35)                                       # how far the pelvis goes past the feet's mean
    swing = u(0.3, 0.4) * tempo
    t = u(0.2, 0.3)
    t0 = t
    moves, sink_t, sink_w, t = _lunge_timeline(u, start.ankles[k], start.ankles[k] + way * length, k, t, reps,
                                               swing, tempo, sink=(0.4, 0.55), rise=(0.35, 0.5))
    total = t + u(0.3, 0.4)
    pose, _, _ = _stepping(start, persona, body, rng, moves, swing, total, 0.05, roll_out=-0.15, roll_in=0.1)
    tt = frame_times(pose.num_frames, FPS)
    w = np.clip(keyframes(tt, sink_t, sink_w), 0.0, 1.0)
    pose.pelvis += (over * length * w)[:, None] * way[None]
    pose.pelvis[:, 1] -= depth * w
    pose.pelvis -= fwd[None] * (0.08 * w)[:, None]           # the hips sit back
    lean = u(0.25, 0.45)
    pose.pelvis_ypr[:, 1] += lean * w                          # the trunk leans over the bent knee
    pose.pelvis_ypr[:, 2] -= (0.08 if side == 0 else -0.08) * w
    pose.spine[:, 1] += u(0.0, 0.15) * w
    pose.spine[:, 2] += (0.12 if side == 0 else -0.12) * w     # the chest stays over the middle
    pose.neck[:, 1] -= 0.5 * lean * w
    flex, elbow = u(0.8, 1.3), u(0.0, 0.5)
    if arms_forward:                                           # the arms reach forward for balance
        pose.arm[:, :, 0] += (flex * w)[:, None]
        pose.arm[:, :, 2] += (elbow * w)[:, None]
    _within_reach(pose, body, sigma=1.0)
    n = pose.num_frames
    core = (max(0, int(np.floor((t0 - 0.1) * FPS))), min(n, int(np.ceil((t + 0.05) * FPS)) + 1))
    return Segment(pose, start, core, arms_free=not arms_forward,
                   info=dict(length=float(length), depth=float(depth), reps=reps, sideways=True))


def pivot(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *, side: int,
          angle: float, mods: tuple[str, ...] = ()) -> Segment:
    """Turn ``angle`` rad (left for ``side`` 0, right for 1) on the ball of the foot on that side.

    The pivot foot's toe stays where it is while its heel is up and the foot turns about it; the
    other foot steps around (twice for more than a quarter turn).
    """
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    k, o = side, 1 - side
    sgn = 1.0 if side == 0 else -1.0
    phi0 = flat_pitch(body)[k]
    L = body.foot[k]
    toe = start.ankles[k] + foot_vector(float(start.foot_yaw[k]), phi0, L)
    t1 = u(0.2, 0.3)                                   # heel up
    t2 = t1 + u(0.12, 0.18)
    t3 = t2 + angle / u(2.6, 3.4) * tempo              # turning
    t4 = t3 + u(0.12, 0.18)                            # heel down
    total = t4 + u(0.3, 0.4)
    n = num_frames(total)
    tt = frame_times(n, FPS)
    turn = sgn * angle * min_jerk((tt - t2) / (t3 - t2))
    heel = keyframes(tt, [0.0, t1, t2, t3, t4], [0.0, 0.0, 0.4, 0.4, 0.0])
    yaw_k = start.foot_yaw[k] + turn
    pose = standing_pose(start, persona, n, body, rng=None, idle=False)
    pose.ankle[:, k] = toe - foot_vector(yaw_k, phi0 + heel, np.full(n, L))
    pose.toe[:, k] = toe
    # the rest of the body turns about the pivot toe
    centre = toe * np.array([1.0, 0.0, 1.0])
    rot = rot_y(turn)                                   # (N, 3, 3)
    lean = 0.5 * (start.ankles[k] - start.ankles[o]) * np.array([1.0, 0.0, 1.0])
    weight = envelope(tt, t1 - 0.1, t4 + 0.1, 0.15)
    pel0 = pose.pelvis[0] + 0.0
    pose.pelvis = centre + np.einsum("nij,j->ni", rot, pel0 - centre) + weight[:, None] * lean * 0.6
    pose.pelvis_ypr[:, 0] = start.yaw + turn
    # the free foot: one or two steps around the pivot
    steps = 1 if angle <= np.pi / 2 + 1e-6 else 2
    yaw_end = start.yaw + sgn * angle
    plants = [Plant(-np.inf, t2, start.ankles[o], float(start.foot_yaw[o]), roll_out=-0.3, roll_out_time=0.1)]
    span = (t3 - t2) / steps
    for s in range(1, steps + 1):
        a = sgn * angle * s / steps
        r = rot_y(np.array(a))
        ank = centre + r @ (start.ankles[o] - centre)
        ank[1] = ANKLE_HEIGHT
        t_on = t2 + s * span if s < steps else t3 + 0.05
        t_off = t2 + s * span + 0.5 * span if s < steps else np.inf
        plants.append(Plant(t_on, t_off, ank, float(start.foot_yaw[o] + a), roll_in=0.1, roll_in_time=0.08))
        if s < steps:
            plants[-1] = Plant(t_on, min(t_off, t3 - 0.05), ank, float(start.foot_yaw[o] + a), roll_in=0.1,
                               roll_in_time=0.08, roll_out=-0.2, roll_out_time=0.06)
    airs = [Swing(u(0.06, 0.09), 0.5, 0.1)] * (len(plants) - 1)
    pose.ankle[:, o], pose.toe[:, o], planted_o = foot_track(tt, plants, airs, body, o)
    foot_yaw = np.stack([yaw_k, start.foot_yaw[o] + turn], 1) if k == 0 else np.stack([start.foot_yaw[o] + turn, yaw_k], 1)
    pose.knee_pole = knee_poles(foot_yaw)
    planted = np.ones((n, 2))
    planted[:, o] = planted_o
    g0 = ypr_matrix(pose.pelvis_ypr)
    bound = max_pelvis_height(pose.pelvis, g0, pose.ankle, body, planted=planted > 0.5) - 0.004
    pose.pelvis[:, 1] = np.minimum(pose.pelvis[:, 1] - 0.02 * weight, bound)
    pose.arm[:, :, 1] += (0.2 * weight)[:, None]
    ankles = np.stack([pose.ankle[-1, 0], pose.ankle[-1, 1]])
    ankles[k] = toe - foot_vector(float(yaw_k[-1]), phi0, L)
    end = Stance(ankles, foot_yaw[-1], float(yaw_end))
    core = (max(0, int(np.floor((t1 - 0.05) * FPS))), min(n, int(np.ceil((t4 + 0.05) * FPS)) + 1))
    return Segment(pose, end, core, info=dict(turn=float(sgn * angle), pivot_toe=toe.tolist()))


def touch_knee(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *, hand: int,
               mods: tuple[str, ...] = (), reps: int = 1) -> Segment:
    """Raise the knee opposite ``hand`` (0 left, 1 right) and touch it with that hand across the
    body, the trunk bending and turning towards it (a standing cross-body crunch)."""
    u = rng.uniform
    tempo = _tempo(mods) * persona.tempo
    leg, sup = 1 - hand, hand
    sgn_hand = 1.0 if hand == 0 else -1.0
    fwd, left = heading_vectors(start.yaw)
    up = np.array([0.0, 1.0, 0.0])
    t = u(0.25, 0.35)
    t_lift = t
    keys_t, keys_a, touch_t, touch_w = [], [], [0.0, t], [0.0, 0.0]
    plant = start.ankles[leg]
    high = plant + up * u(0.38, 0.45) + fwd * u(0.12, 0.18) + left * (0.04 * sgn_hand)
    for r in range(reps):
        t += u(0.45, 0.6) * tempo
        keys_t.append(t); keys_a.append(high)
        touch_t.append(t); touch_w.append(1.0)
        t += u(0.25, 0.45) * tempo
        keys_t.append(t); keys_a.append(high - up * 0.01)
        touch_t.append(t); touch_w.append(1.0)
        if r < reps - 1:
            t += u(0.35, 0.45) * tempo
            keys_t.append(t); keys_a.append(plant + up * 0.08 + fwd * 0.03)
            touch_t.append(t); touch_w.append(0.2)
    t_plant = t + u(0.4, 0.5) * tempo
    touch_t.append(t_plant); touch_w.append(0.0)
    total = t_plant + u(0.3, 0.4)
    n = num_frames(total)
    tt = frame_times(n, FPS)
    pose = standing_pose(start, persona, n, body, rng=None, idle=False)
    yaw = float(start.foot_yaw[leg])
    p0 = Plant(-np.inf, t_lift, plant, yaw, roll_out=-0.3, roll_out_time=0.12)
    p1 = Plant(t_plant, np.inf, plant, yaw, roll_in=-0.15, roll_in_time=0.1)
    phi0 = flat_pitch(body)[leg]

    def air(tq: np.ndarray):
        a0 = plant + foot_vector(yaw, phi0, body.foot[leg]) - foot_vector(yaw, phi0 + 0.3, body.foot[leg])
        kt = np.concatenate([[t_lift], keys_t, [t_plant]])
        ka = np.concatenate([a0[None], np.stack(keys_a), plant[None]])
        ank = keyframes(tq, kt, ka)
        pitch = keyframes(tq, kt, np.concatenate([[phi0 + 0.3], np.full(len(keys_t), phi0 + 0.5), [phi0]]))
        return ank, ank + foot_vector(np.full_like(tq, yaw), pitch, np.full_like(tq, body.foot[leg]))

    pose.ankle[:, leg], pose.toe[:, leg], _ = foot_track(tt, [p0, p1], [air], body, leg)
    lifted = envelope(tt, t_lift, t_plant, 0.25)
    shift = (start.ankles[sup] - start.ground) * np.array([1.0, 0.0, 1.0])
    pose.pelvis += (0.75 * lifted)[:, None] * shift
    pose.knee_pole[:, leg] = pose.knee_pole[:, leg] * (1.0 - 0.5 * lifted)[:, None] + np.outer(lifted, up)
    w = keyframes(tt, touch_t, touch_w)
    pose.pelvis_ypr[:, 1] += 0.25 * w
    pose.spine[:, 1] += u(0.45, 0.55) * w
    pose.spine[:, 0] += -sgn_hand * u(0.45, 0.6) * w           # the right hand's shoulder comes across
    planted = np.ones((n, 2))
    planted[:, leg] = 1.0 - (lifted > 0.0)
    g0 = ypr_matrix(pose.pelvis_ypr)
    bound = max_pelvis_height(pose.pelvis, g0, pose.ankle, body, planted=planted > 0.5) - 0.003
    pose.pelvis[:, 1] = np.minimum(pose.pelvis[:, 1], bound)
    # the hand goes to the top of the raised knee (found by a first assembly of the body)
    knee = assemble(pose, body)[:, body.j("left_knee" if leg == 0 else "right_knee")]
    target = knee + up * 0.07 + fwd * 0.02
    reach = np.linalg.norm(target - shoulders(pose, body)[:, hand], axis=-1)
    touch = arm_controls_for(pose, body, hand, target)
    pose.arm[:, hand] = pose.arm[:, hand] + w[:, None] * (touch - pose.arm[:, hand])
    pose.arm_pole[:, hand] = (0.6, -0.6, -0.5)
    pose.arm[:, leg, 1] += 0.3 * w                              # the other arm opens for balance
    pose.arm[:, leg, 0] -= 0.3 * w
    core = (max(0, int(np.floor((t_lift - 0.15) * FPS))), min(n, int(np.ceil((t_plant + 0.05) * FPS)) + 1))
    held = w > 0.99
    gap = float(np.max(reach[held] - wrist_reach(body, hand))) if held.any() else 0.0
    hand_w, hand_t = np.zeros((n, 2)), np.zeros((n, 2, 3))
    hand_w[:, hand], hand_t[:, hand] = w, target
    return Segment(pose, start, core, arms_free=False, hands=(hand_w, hand_t), info=dict(touch_gap=max(0.0, gap)))
