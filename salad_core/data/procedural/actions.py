"""Non-walking base actions: jumps, jumping jacks, kicks, knee lifts, squats, sitting, bowing.

Each function takes the standing :class:`Stance` it starts from and returns a :class:`Segment`
that ends standing (sitting ends seated). Flight phases are ballistic: the pelvis follows
``y = y0 + v0 t - g t^2 / 2`` with ``v0 = sqrt(2 g H)`` for an apex ``H``, and the feet leave
and touch the floor toes first. Planted feet never move; supporting legs reach them by IK.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .curves import ease, envelope, frame_times, keyframes, min_jerk
from .footwork import (ANKLE_HEIGHT, Persona, Plant, Stance, flat_pitch, foot_track, max_pelvis_height,
                       plant_pose, standing_height)
from .kinematics import FPS, BodyModel, Pose, assemble, foot_vector, heading_vectors, ypr_matrix
from .reach import arm_controls_for
from .segment import Segment, knee_poles, num_frames, standing_pose

__all__ = ["GRAVITY", "Hop", "hops", "jump", "jumping_jacks", "kick", "knee_lift", "balance", "squat", "sit", "bow"]

#: Gravity (m/s^2) of the flight phases.
GRAVITY = 9.81


def _frames(t0: float, t1: float, n: int) -> tuple[int, int]:
    return max(0, int(np.floor(t0 * FPS))), min(n, int(np.ceil(t1 * FPS)) + 1)


# ============================================================================ hops and jumps
@dataclass(frozen=True)
class Hop:
    """One jump of a chain."""

    height: float               # apex rise of the pelvis above take-off (m)
    crouch: float               # pelvis drop below standing at the bottom of the crouch (m)
    crouch_time: float          # time into the crouch (from standing or from the last landing)
    push_time: float            # time from the bottom of the crouch to take-off
    advance: float = 0.0        # horizontal travel of the body (m, along the heading)
    land_width: float | None = None  # half distance between the feet after landing (None: unchanged)
    arms: tuple = (1.2, 0.1, 0.3)    # (flex, abd, elbow) of both arms in flight
    arms_back: tuple = (-0.6, 0.15, 0.35)  # arms at the bottom of the crouch
    lean: float = 0.35          # trunk lean at the bottom of the crouch (rad)
    toe_roll: float = 0.75      # heel lift at take-off and landing (rad): the feet leave toes last
    arms_through: bool = True   # arms keyed half-way at take-off (a jump's swing); False: one sweep
                                # from the crouch to the apex (jacks: a gentler wrist acceleration)

    def __post_init__(self) -> None:
        if not self.height > 0:
            raise ValueError(f"Hop.height={self.height} must be positive (m)")
        if self.crouch < 0 or self.crouch_time <= 0 or self.push_time <= 0:
            raise ValueError(f"Hop: crouch={self.crouch} must be >= 0 and crouch_time={self.crouch_time}, "
                             f"push_time={self.push_time} positive")


def hops(start: Stance, persona: Persona, chain: list[Hop], body: BodyModel, land_crouch: float,
         recover_time: float) -> tuple[Pose, Stance, list[tuple[float, float]]]:
    """A chain of jumps from standing to standing; returns the pose, the end stance and the
    (take-off, landing) times of every flight."""
    yaw = start.yaw
    fwd, left = heading_vectors(yaw)
    phi0 = flat_pitch(body)

    # ---- feet of every stance of the chain
    stances = [start]
    for hop in chain:
        prev = stances[-1]
        centre = prev.ankles.mean(0) + fwd * hop.advance
        width = (np.linalg.norm(prev.ankles[0] - prev.ankles[1]) / 2) if hop.land_width is None else hop.land_width
        ankles = np.stack([centre + left * width, centre - left * width])
        ankles[:, 1] = ANKLE_HEIGHT
        stances.append(Stance(ankles, prev.foot_yaw, yaw))
    h_stand = [standing_height(s, body, pitch=0.03) for s in stances]

    def takeoff_height(s: Stance, ahead: float, toe_roll: float) -> float:
        """Pelvis height with the legs extended and the heels up (toes on the floor)."""
        ank = []
        for k in range(2):
            toe = s.ankles[k] + foot_vector(s.foot_yaw[k], phi0[k], body.foot[k])
            ank.append(toe - foot_vector(s.foot_yaw[k], phi0[k] + toe_roll, body.foot[k]))
        ank = np.stack(ank)[None]
        pel = (s.ground + fwd * ahead)[None]
        return float(max_pelvis_height(pel, ypr_matrix(np.array([[yaw, 0.05, 0.0]])), ank, body, 0.985)[0])

    # ---- timeline of pelvis keys (time, xyz, velocity)
    keys_t, keys_p, keys_v = [0.0], [start.ground + np.array([0, h_stand[0], 0])], [np.zeros(3)]
    lean_k, arm_k, head_k = [(0.0, 0.03)], [(0.0,) + tuple(persona.arm_rest)], [(0.0, persona.head_pitch)]
    flights: list[tuple[float, float]] = []
    t = 0.0
    for i, hop in enumerate(chain):
        s0, s1 = stances[i], stances[i + 1]
        ahead = 0.08 if hop.advance > 0.2 else 0.02
        v0 = np.sqrt(2 * GRAVITY * hop.height)
        flight = 2 * v0 / GRAVITY
        y_to = takeoff_height(s0, ahead, hop.toe_roll)
        y_land = takeoff_height(s1, -0.02, hop.toe_roll)
        # bottom of the crouch
        t += hop.crouch_time
        bottom = s0.ground - fwd * (0.06 if hop.advance > 0.2 else 0.02) + np.array([0, h_stand[i] - hop.crouch, 0])
        keys_t.append(t); keys_p.append(bottom); keys_v.append(np.zeros(3))
        lean_k.append((t, hop.lean)); arm_k.append((t,) + tuple(hop.arms_back)); head_k.append((t, persona.head_pitch + 0.25))
        # take-off: a ballistic flight between equal-height ends needs |v_y| equal at both ends
        t += hop.push_time
        p_to = s0.ground + fwd * ahead + np.array([0, y_to, 0])
        p_land = s1.ground - fwd * 0.02 + np.array([0, y_land, 0])
        y_apex = max(y_to, y_land) + hop.height
        v_up = np.sqrt(2 * GRAVITY * max(y_apex - y_to, 1e-4))
        v_dn = np.sqrt(2 * GRAVITY * max(y_apex - y_land, 1e-4))
        flight = (v_up + v_dn) / GRAVITY
        v_h = (p_land - p_to) / flight
        v_h[1] = 0.0
        keys_t.append(t); keys_p.append(p_to); keys_v.append(v_h + np.array([0, v_up, 0]))
        lean_k.append((t, 0.05)); arm_k.append((t,) + tuple(hop.arms)); head_k.append((t, persona.head_pitch - 0.12))
        t_to = t
        # the arms swing through: past the front at take-off, fully up at the apex
        mid_arms = tuple(0.5 * (a + b) for a, b in zip(hop.arms_back, hop.arms))
        if hop.arms_through:
            arm_k[-1] = (t,) + mid_arms
        else:
            arm_k.pop()
        arm_k.append((t + 0.5 * flight,) + tuple(hop.arms))
        t += flight
        keys_t.append(t); keys_p.append(p_land); keys_v.append(v_h + np.array([0, -v_dn, 0]))
        lean_k.append((t, 0.08)); arm_k.append((t,) + tuple(hop.arms)); head_k.append((t, persona.head_pitch - 0.02))
        flights.append((t_to, t))
    # absorb the last landing, then stand up
    last = stances[-1]
    t += 0.22
    keys_t.append(t); keys_p.append(last.ground - fwd * 0.02 + np.array([0, h_stand[-1] - land_crouch, 0])); keys_v.append(np.zeros(3))
    lean_k.append((t, 0.25 + land_crouch)); arm_k.append((t, 0.5, 0.15, 0.4)); head_k.append((t, persona.head_pitch + 0.14))
    t += recover_time
    keys_t.append(t); keys_p.append(last.ground + np.array([0, h_stand[-1], 0])); keys_v.append(np.zeros(3))
    lean_k.append((t, 0.03)); arm_k.append((t,) + tuple(persona.arm_rest)); head_k.append((t, persona.head_pitch))
    total = t + 0.15

    n = num_frames(total)
    tt = frame_times(n, FPS)
    pelvis = keyframes(tt, keys_t, np.array(keys_p), np.array(keys_v))
    # the crouch of a chained hop starts from the previous landing: keys hold the ballistic ends

    def key_curve(keys):
        arr = np.array(keys)
        return keyframes(tt, arr[:, 0], arr[:, 1:])

    lean = key_curve(lean_k)[:, 0]
    arms = key_curve(arm_k)
    head = key_curve(head_k)[:, 0]

    # ---- feet: planted between flights, carried under the hips in the air
    ankle = np.zeros((n, 2, 3))
    toe = np.zeros((n, 2, 3))
    for k in range(2):
        plants, airs = [], []
        for i in range(len(stances)):
            t_on = -np.inf if i == 0 else flights[i - 1][1]
            t_off = np.inf if i == len(chain) else flights[i][0]
            roll_in = -chain[i - 1].toe_roll if i > 0 else 0.0
            roll_out = -chain[i].toe_roll if i < len(chain) else 0.0
            push = chain[i].push_time if i < len(chain) else 0.0
            plants.append(Plant(t_on, t_off, stances[i].ankles[k], float(stances[i].foot_yaw[k]),
                                roll_in=roll_in, roll_in_time=0.09, roll_out=roll_out,
                                roll_out_time=max(0.08, 0.9 * push)))
        for i in range(len(chain)):
            airs.append(_flight_feet(plants[i], plants[i + 1], k, body, tt_all=tt, pelvis=pelvis,
                                     tuck=0.03 + 0.15 * min(chain[i].height, 0.45)))
        ankle[:, k], toe[:, k], _ = foot_track(tt, plants, airs, body, k)

    ypr = np.stack([np.full(n, yaw), 0.03 + 0.6 * (lean - 0.03), np.zeros(n)], -1)
    spine = np.stack([np.zeros(n), 0.03 + 0.4 * (lean - 0.03), np.zeros(n)], -1)
    g0 = ypr_matrix(ypr)
    bound = max_pelvis_height(pelvis, g0, ankle, body) - 0.003
    grounded = np.ones(n, dtype=bool)
    for a, b in flights:
        grounded &= ~((tt > a) & (tt < b))
    pelvis[:, 1] = np.where(grounded, np.minimum(pelvis[:, 1], bound), pelvis[:, 1])
    neck = np.stack([np.zeros(n), head, np.zeros(n)], -1)
    arm = np.stack([arms, arms], 1)
    pole = np.tile(np.asarray(persona.arm_pole, dtype=np.float64), (n, 2, 1))
    poles = knee_poles(np.tile(start.foot_yaw, (n, 1)))
    return Pose(pelvis, ypr, spine, neck, ankle, toe, poles, arm, pole), stances[-1], flights


def _flight_feet(a: Plant, b: Plant, k: int, body: BodyModel, tt_all: np.ndarray, pelvis: np.ndarray,
                 tuck: float):
    """Feet in the air: their offsets from the pelvis blend from take-off to landing, tucked up."""
    phi0 = flat_pitch(body)[k]
    a_ank, _ = plant_pose(a, np.array([a.t_off]), body, k)
    b_ank, _ = plant_pose(b, np.array([b.t_on]), body, k)
    p_a = np.array([np.interp(a.t_off, tt_all, pelvis[:, d]) for d in range(3)])
    p_b = np.array([np.interp(b.t_on, tt_all, pelvis[:, d]) for d in range(3)])
    off_a, off_b = a_ank[0] - p_a, b_ank[0] - p_b
    fwd, _ = heading_vectors(b.yaw)

    def air(t: np.ndarray):
        tau = np.clip((t - a.t_off) / (b.t_on - a.t_off), 0.0, 1.0)
        m = min_jerk(tau)[:, None]
        pel = np.stack([np.interp(t, tt_all, pelvis[:, d]) for d in range(3)], -1)
        bump = np.sin(np.pi * tau)[:, None]
        ankle = pel + off_a + (off_b - off_a) * m + bump * (np.array([0.0, tuck, 0.0]) + 0.3 * tuck * fwd)
        pitch = phi0 - a.roll_out + (a.roll_out - b.roll_in) * m[:, 0] - 0.25 * np.sin(np.pi * tau)
        yaw = a.yaw + (b.yaw - a.yaw) * m[:, 0]
        return ankle, ankle + foot_vector(yaw, pitch, np.full_like(tau, body.foot[k]))
    return air


def jump(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
         forward: bool = False, mods: tuple[str, ...] = (), reps: int = 1) -> Segment:
    """Jump ``reps`` times in place or forward; "high" / "low" change the apex height."""
    u = rng.uniform
    high, low = "high" in mods, "low" in mods
    chain = []
    for r in range(reps):
        if high:
            h, crouch = u(0.3, 0.42), u(0.2, 0.26)
        elif low:
            h, crouch = u(0.05, 0.09), u(0.06, 0.1)
        else:
            h, crouch = u(0.14, 0.22), u(0.12, 0.18)
        arms_up = u(2.3, 2.8) if high else u(0.9, 1.6)
        chain.append(Hop(height=h, crouch=crouch, crouch_time=u(0.32, 0.45) if r == 0 else u(0.18, 0.26),
                         push_time=u(0.14, 0.2), advance=u(0.5, 0.9) if forward else 0.0,
                         arms=(arms_up, u(0.05, 0.2), u(0.15, 0.4)), arms_back=(-u(0.5, 0.8), 0.15, 0.35),
                         lean=u(0.3, 0.45)))
    pose, end, flights = hops(start, persona, chain, body, land_crouch=u(0.1, 0.16), recover_time=u(0.35, 0.5))
    n = pose.num_frames
    core = _frames(0.05, flights[-1][1] + 0.35, n)
    apex = max(c.height for c in chain)
    return Segment(pose, end, core, info=dict(height=apex, advance=sum(c.advance for c in chain), flights=flights))


def jumping_jacks(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
                  mods: tuple[str, ...] = (), reps: int = 2) -> Segment:
    """``reps`` jumping jacks: hop the feet apart with the arms overhead, then back together."""
    u = rng.uniform
    tempo = 1.35 if "slowly" in mods else (0.8 if "quickly" in mods else 1.0)
    width_in = np.linalg.norm(start.ankles[0] - start.ankles[1]) / 2
    width_out = u(0.24, 0.32)
    # real jacks keep the wrists under ~130 m/s^2: the arms do not travel the full 2.9 rad each hop
    up = (u(0.0, 0.15), u(2.35, 2.7), u(0.15, 0.4))
    down = (u(0.0, 0.1), u(0.22, 0.4), u(0.2, 0.4))
    chain = []
    for r in range(reps):
        for out in (True, False):
            chain.append(Hop(height=u(0.05, 0.08), crouch=u(0.04, 0.07),
                             crouch_time=(u(0.25, 0.35) if not chain else u(0.14, 0.19)) * tempo,
                             push_time=u(0.08, 0.12) * tempo, land_width=width_out if out else width_in,
                             arms=up if out else down, arms_back=up if not out else down, lean=0.08,
                             toe_roll=0.4, arms_through=False))
    pose, end, flights = hops(start, persona, chain, body, land_crouch=0.05, recover_time=0.3)
    n = pose.num_frames
    core = _frames(0.05, flights[-1][1] + 0.2, n)
    return Segment(pose, end, core, arms_free=False, info=dict(jacks=reps, flights=flights))


# ============================================================================ one-legged actions
def _weight_shift_pose(start: Stance, persona: Persona, body: BodyModel, rng, n: int, support: int,
                       shift_keys: list[tuple[float, float]]) -> Pose:
    """Standing pose with the pelvis shifted over the ``support`` foot by keyed amounts (0..1)."""
    pose = standing_pose(start, persona, n, body, rng=None, idle=False)
    t = frame_times(n, FPS)
    arr = np.array(shift_keys)
    w = keyframes(t, arr[:, 0], arr[:, 1])
    target = start.ankles[support].copy()
    target[1] = 0.0
    centre = start.ground.copy()
    lateral = (target - centre) * 0.75
    lateral[1] = 0.0
    pose.pelvis += w[:, None] * lateral[None]
    return pose


def _leg_action(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, side: int,
                keys: list[tuple[float, np.ndarray, float]], lean_keys: list[tuple[float, float]],
                t_lift: float, t_plant: float, total: float, knee_up: float) -> Pose:
    """The ``side`` foot leaves the floor at ``t_lift``, follows ankle ``keys`` (time, local
    offset from its plant in the body frame (x left, y up, z forward), foot pitch) and lands
    back on its plant at ``t_plant``; the other leg supports the body. While the foot is up the
    knee pole turns towards ``knee_up`` (up, or down if negative: 2.7's back kick and balance)."""
    n = num_frames(total)
    t = frame_times(n, FPS)
    support = 1 - side
    pose = _weight_shift_pose(start, persona, body, rng, n, support,
                              [(0.0, 0.0), (t_lift, 1.0), (t_plant, 1.0), (total - 0.1, 0.0)])
    yaw = start.yaw
    fwd, left = heading_vectors(yaw)
    plant = start.ankles[side]
    phi0 = flat_pitch(body)[side]
    kt = np.array([k[0] for k in keys])
    off = np.array([k[1] for k in keys])
    pitch = np.array([k[2] for k in keys])
    world = plant[None] + off[:, :1] * left + off[:, 1:2] * np.array([0, 1.0, 0]) + off[:, 2:3] * fwd
    p0 = Plant(-np.inf, t_lift, plant, float(start.foot_yaw[side]), roll_out=-0.35, roll_out_time=0.12)
    p1 = Plant(t_plant, np.inf, plant, float(start.foot_yaw[side]), roll_in=-0.2, roll_in_time=0.1)
    # the air path starts and ends exactly where the plants leave and take the foot
    a0, _ = plant_pose(p0, np.array([t_lift]), body, side)
    a1, _ = plant_pose(p1, np.array([t_plant]), body, side)
    kt = np.concatenate([[t_lift], kt, [t_plant]])
    world = np.concatenate([a0, world, a1])
    pitch = np.concatenate([[phi0 - p0.roll_out], pitch + phi0, [phi0 - p1.roll_in]])

    def air(tq: np.ndarray):
        ank = keyframes(tq, kt, world)
        pt = keyframes(tq, kt, pitch)
        return ank, ank + foot_vector(np.full_like(tq, start.foot_yaw[side]), pt, np.full_like(tq, body.foot[side]))

    ankle, toe, _ = foot_track(t, [p0, p1], [air], body, side)
    pose.ankle[:, side], pose.toe[:, side] = ankle, toe
    lk = np.array(lean_keys)
    lean = keyframes(t, lk[:, 0], lk[:, 1])
    pose.pelvis_ypr[:, 1] += lean * 0.6
    pose.spine[:, 1] += lean * 0.4
    lift = envelope(t, t_lift, t_plant, 0.25)
    # a lifted leg bends its knee upwards: the pole turns from the foot direction to straight up
    pole = pose.knee_pole[:, side] * (1.0 - 0.5 * lift)[:, None] + np.array([0.0, knee_up, 0.0]) * lift[:, None]
    pose.knee_pole[:, side] = pole
    # arms open a little for balance
    pose.arm[:, :, 1] += (0.25 * lift)[:, None]
    pose.arm[:, side, 0] -= 0.25 * lift
    pose.arm[:, 1 - side, 0] += 0.2 * lift
    g0 = ypr_matrix(pose.pelvis_ypr)
    bound = max_pelvis_height(pose.pelvis, g0, pose.ankle[:, [support, support]], body) - 0.003
    pose.pelvis[:, 1] = np.minimum(pose.pelvis[:, 1], bound)
    return pose


def kick(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *, side: int,
         mods: tuple[str, ...] = (), reps: int = 1, direction: str = "front") -> Segment:
    """Kick forward with one leg (0 left, 1 right); "high" / "low" set the foot height.

    ``direction`` "side" or "back" (2.7): a side kick (the leg out to its own side, the trunk
    leaning away over the supporting leg) or a back kick (the leg behind, the trunk leaning forward).
    """
    if direction != "front":
        return _kick_out(start, persona, body, rng, side=side, mods=mods, reps=reps, back=direction == "back")
    u = rng.uniform
    tempo = 1.3 if "slowly" in mods else (0.75 if "quickly" in mods else 1.0)
    elev = u(0.3, 0.5) if "high" in mods else (-u(0.45, 0.55) if "low" in mods else -u(0.0, 0.15))
    reach = u(0.72, 0.78)
    hip_h = 0.84
    t = u(0.35, 0.45) * tempo
    t_lift = t
    keys: list = []
    lean_keys = [(0.0, 0.0), (t, 0.0)]
    counter_keys = [(0.0, 0.0), (t, 0.0)]
    sgn = 1.0 if side == 0 else -1.0
    width = np.linalg.norm(start.ankles[0] - start.ankles[1]) / 2
    for r in range(reps):
        t += u(0.18, 0.24) * tempo                      # chamber: knee up, foot under it
        keys.append((t, np.array([-sgn * 0.3 * width, 0.3, 0.12]), 0.45))
        lean_keys.append((t, -0.05))
        t += u(0.14, 0.2) * tempo                       # extension
        ext = np.array([-sgn * 0.5 * width, hip_h - ANKLE_HEIGHT + reach * np.sin(elev), reach * np.cos(elev)])
        keys.append((t, ext, 0.7))
        lean_keys.append((t, -0.12 - 0.35 * max(elev, 0.0)))
        counter_keys.append((t, 1.0))
        t += u(0.05, 0.1)
        keys.append((t, ext + np.array([0, 0.01, -0.02]), 0.7))
        counter_keys.append((t, 1.0))
        t += u(0.16, 0.22) * tempo                      # retract
        keys.append((t, np.array([-sgn * 0.3 * width, 0.3, 0.1]), 0.4))
        lean_keys.append((t, -0.04))
        counter_keys.append((t, 0.3))
    t_plant = t + u(0.2, 0.28) * tempo
    lean_keys += [(t_plant, 0.0)]
    counter_keys += [(t_plant, 0.0)]
    total = t_plant + u(0.35, 0.45)
    pose = _leg_action(start, persona, body, rng, side, keys, lean_keys, t_lift, t_plant, total, knee_up=1.2)
    # the upper body counters the kick: the kicking side's arm swings back, the other one forward,
    # and the shoulders turn against the kicking hip
    ck = np.array(counter_keys)
    c = keyframes(frame_times(pose.num_frames, FPS), ck[:, 0], ck[:, 1])
    swing = 1.0 + 0.4 * max(elev, 0.0)             # (the trunk's lean back already carries both arms back)
    pose.arm[:, side, 0] -= u(0.1, 0.3) * swing * c
    pose.arm[:, 1 - side, 0] += u(0.5, 0.9) * swing * c
    pose.arm[:, :, 2] += (u(0.1, 0.4) * c)[:, None]
    pose.spine[:, 0] -= sgn * u(0.1, 0.22) * c
    core = _frames(t_lift - 0.2, t_plant + 0.05, pose.num_frames)
    return Segment(pose, start, core, info=dict(foot_height=float(hip_h + reach * np.sin(elev))))


def _kick_out(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *, side: int,
              mods: tuple[str, ...], reps: int, back: bool) -> Segment:
    """The side and back kicks of :func:`kick` (2.7)."""
    u = rng.uniform
    tempo = 1.3 if "slowly" in mods else (0.75 if "quickly" in mods else 1.0)
    if back:
        elev = u(0.0, 0.25) if "high" in mods else (-u(0.5, 0.6) if "low" in mods else -u(0.15, 0.35))
    else:
        elev = u(0.25, 0.45) if "high" in mods else (-u(0.5, 0.6) if "low" in mods else -u(0.05, 0.25))
    reach = u(0.7, 0.76)
    hip_h = 0.84
    sgn = 1.0 if side == 0 else -1.0
    t = u(0.35, 0.45) * tempo
    t_lift = t
    keys: list = []
    lean_keys = [(0.0, 0.0), (t, 0.0)]
    counter_keys = [(0.0, 0.0), (t, 0.0)]
    lean_out = u(0.35, 0.55) + 0.4 * max(elev, 0.0)           # back: forward over the support leg
    for r in range(reps):
        t += u(0.2, 0.26) * tempo                              # chamber: the knee comes up
        keys.append((t, np.array([sgn * 0.05, 0.32, 0.12 if back else 0.05]), 0.45))
        lean_keys.append((t, 0.1 if back else 0.0))
        t += (u(0.19, 0.24) if back else u(0.15, 0.2)) * tempo  # extension
        if back:
            ext = np.array([0.0, hip_h - ANKLE_HEIGHT + reach * np.sin(elev), -reach * np.cos(elev)])
        else:
            # a little forward of the side (with the knee pointing up, a leg straight out to the
            # side bends its knee backwards about the hips' left axis)
            ahead = u(0.35, 0.5)
            ext = np.array([sgn * reach * np.cos(elev) * np.cos(ahead), hip_h - ANKLE_HEIGHT + reach * np.sin(elev),
                            reach * np.cos(elev) * np.sin(ahead)])
        keys.append((t, ext, 0.6 if back else 0.3))
        lean_keys.append((t, lean_out if back else 0.05))
        counter_keys.append((t, 1.0))
        t += u(0.06, 0.12)
        keys.append((t, ext + np.array([0, 0.01, 0.0]), 0.6 if back else 0.3))
        lean_keys.append((t, lean_out if back else 0.05))
        counter_keys.append((t, 1.0))
        t += u(0.18, 0.24) * tempo                             # retract
        keys.append((t, np.array([sgn * 0.05, 0.3, 0.08]), 0.4))
        lean_keys.append((t, 0.05))
        counter_keys.append((t, 0.3))
    t_plant = t + u(0.2, 0.28) * tempo
    lean_keys += [(t_plant, 0.0)]
    counter_keys += [(t_plant, 0.0)]
    total = t_plant + u(0.35, 0.45)
    pose = _leg_action(start, persona, body, rng, side, keys, lean_keys, t_lift, t_plant, total,
                       knee_up=-1.0 if back else 1.5)
    ck = np.array(counter_keys)
    c = keyframes(frame_times(pose.num_frames, FPS), ck[:, 0], ck[:, 1])
    if back:
        # the arms come forward for balance as the trunk tips over the supporting leg
        pose.arm[:, :, 0] += (u(0.4, 0.8) * c)[:, None]
        pose.neck[:, 1] -= 0.6 * lean_out * c                  # the eyes stay ahead
    else:
        # the trunk leans away from the kick over the supporting leg, the hips turn away a little,
        # the fists come up in a guard
        roll = u(0.3, 0.5) + 0.3 * max(elev, 0.0)
        pose.spine[:, 2] -= sgn * roll * c
        pose.pelvis_ypr[:, 2] -= sgn * 0.35 * roll * c
        pose.pelvis_ypr[:, 0] -= sgn * u(0.05, 0.15) * c
        pose.neck[:, 2] += sgn * 0.5 * roll * c
        pose.arm[:, :, 0] += (u(0.3, 0.6) * c)[:, None]
        pose.arm[:, :, 2] += c[:, None] * (u(1.3, 1.7) - pose.arm[:, :, 2])
        g0 = ypr_matrix(pose.pelvis_ypr)
        bound = max_pelvis_height(pose.pelvis, g0, pose.ankle[:, [1 - side, 1 - side]], body) - 0.003
        pose.pelvis[:, 1] = np.minimum(pose.pelvis[:, 1], bound)
    core = _frames(t_lift - 0.2, t_plant + 0.05, pose.num_frames)
    return Segment(pose, start, core, info=dict(foot_height=float(hip_h + reach * np.sin(elev)),
                                                direction="back" if back else "side"))


def balance(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *, side: int,
            mods: tuple[str, ...] = ()) -> Segment:
    """Balance on the ``side`` leg (0 left, 1 right) in a T-balance (2.7): the trunk tips forward
    towards level while the other leg rises out straight behind, the arms spread out to the
    sides; hold a moment and come back up, the foot back on its plant."""
    u = rng.uniform
    tempo = (1.3 if "slowly" in mods else (0.75 if "quickly" in mods else 1.0)) * persona.tempo
    lift = 1 - side
    t_lift = u(0.3, 0.4) * tempo
    t_up = t_lift + u(0.7, 0.95) * tempo
    t_hold = t_up + u(0.5, 1.0) * tempo
    t_plant = t_hold + u(0.7, 0.9) * tempo
    total = t_plant + u(0.3, 0.4)
    lean = u(1.25, 1.5)
    lean_keys = [(0.0, 0.0), (t_lift, 0.0), (t_up, lean), (t_hold, lean), (t_plant, 0.0)]
    fwd, left = heading_vectors(start.yaw)
    up = np.array([0.0, 1.0, 0.0])

    def build(back: np.ndarray) -> Pose:
        keys = [(t_lift + 0.35 * (t_up - t_lift), np.array([0.0, 0.22, -0.2]), 0.5),
                (t_up, back, 0.9), (t_hold, back + np.array([0.0, 0.01, -0.01]), 0.9),
                (t_hold + 0.6 * (t_plant - t_hold), np.array([0.0, 0.2, -0.15]), 0.4)]
        return _leg_action(start, persona, body, rng, lift, keys, lean_keys, t_lift, t_plant, total, knee_up=-1.0)

    # the raised leg points straight back from its hip, near level: found on a first build of the body
    probe = build(np.array([0.0, 0.6, -0.7]))
    hold = int(round(0.5 * (t_up + t_hold) * FPS))
    hip = assemble(probe.slice(hold, hold + 1), body)[0, body.j("left_hip" if lift == 0 else "right_hip")]
    elev = u(1.2, 1.45)                                    # from straight down, behind
    ankle = hip + 0.96 * float(body.leg[lift]) * (-np.cos(elev) * up - np.sin(elev) * fwd)
    d = ankle - start.ankles[lift]
    pose = build(np.array([float(d @ left), float(d[1]), float(d @ fwd)]))
    tt = frame_times(pose.num_frames, FPS)
    w = np.clip(keyframes(tt, [t_lift, t_up, t_hold, t_plant], [0.0, 1.0, 1.0, 0.0]), 0.0, 1.0)
    spread = np.array([u(-0.2, 0.2), u(1.3, 1.6), u(0.05, 0.3)])          # arms out to the sides
    pose.arm += w[:, None, None] * (spread[None, None] - pose.arm)
    pose.neck[:, 1] -= 0.55 * lean * w                        # the eyes ahead, not on the floor
    core = _frames(t_lift - 0.15, t_plant + 0.05, pose.num_frames)
    return Segment(pose, start, core, arms_free=False, info=dict(lean=float(lean), lifted=lift))


def knee_lift(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *, side: int,
              mods: tuple[str, ...] = (), reps: int = 1) -> Segment:
    """Raise one knee (thigh angle set by "high" / "low"), hold, put the foot back down."""
    u = rng.uniform
    tempo = 1.3 if "slowly" in mods else (0.75 if "quickly" in mods else 1.0)
    theta = u(1.75, 1.95) if "high" in mods else (u(0.6, 0.8) if "low" in mods else u(1.3, 1.5))
    thigh, shin = body.thigh[side], body.shin[side]
    sgn = 1.0 if side == 0 else -1.0
    width = np.linalg.norm(start.ankles[0] - start.ankles[1]) / 2
    hip_h = 0.86
    knee = np.array([0.0, hip_h - thigh * np.cos(theta), thigh * np.sin(theta)])
    ank = knee + np.array([0.0, -shin * 0.97, -0.08])
    lifted = np.array([-sgn * 0.3 * width, ank[1] - ANKLE_HEIGHT, ank[2]])
    t = u(0.3, 0.4) * tempo
    t_lift = t
    keys: list = []
    lean_keys = [(0.0, 0.0), (t, 0.0)]
    for r in range(reps):
        t += u(0.35, 0.5) * tempo
        keys.append((t, lifted, 0.5))
        lean_keys.append((t, -0.04))
        t += u(0.3, 0.7) * tempo
        keys.append((t, lifted + np.array([0, -0.01, 0.0]), 0.5))
        if r < reps - 1:
            t += u(0.3, 0.4) * tempo
            keys.append((t, np.array([-sgn * 0.1 * width, 0.06, 0.03]), 0.3))
    t_plant = t + u(0.35, 0.5) * tempo
    lean_keys += [(t_plant, 0.0)]
    total = t_plant + u(0.3, 0.4)
    pose = _leg_action(start, persona, body, rng, side, keys, lean_keys, t_lift, t_plant, total, knee_up=1.0)
    core = _frames(t_lift - 0.15, t_plant + 0.05, pose.num_frames)
    return Segment(pose, start, core, info=dict(thigh_angle=float(theta)))


# ============================================================================ lowering the body
def _planted_action(start: Stance, persona: Persona, body: BodyModel, n: int) -> Pose:
    return standing_pose(start, persona, n, body, rng=None, idle=False)


def squat(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
          mods: tuple[str, ...] = (), reps: int = 1, arms_forward: bool | None = None) -> Segment:
    """Squat down and up ``reps`` times; "low" squats deeper, "slowly"/"quickly" set the pace."""
    u = rng.uniform
    tempo = 1.4 if "slowly" in mods else (0.7 if "quickly" in mods else 1.0)
    depth = u(0.4, 0.47) if "low" in mods else u(0.22, 0.35)     # pelvis drop (m)
    arms_forward = bool(rng.random() < 0.6) if arms_forward is None else arms_forward
    fwd, _ = heading_vectors(start.yaw)
    h = standing_height(start, body, pitch=0.03)
    base = start.ground + np.array([0, h, 0])
    kt, kp, kl, ka = [0.0], [base], [0.0], [0.0]
    t = u(0.2, 0.3)
    kt.append(t); kp.append(base); kl.append(0.0); ka.append(0.0)
    for r in range(reps):
        t += u(0.6, 0.8) * tempo
        bottom = base + np.array([0, -depth, 0]) - fwd * (0.35 * depth)
        kt.append(t); kp.append(bottom); kl.append(0.55 + 0.6 * (depth - 0.3)); ka.append(1.0)
        t += u(0.15, 0.4) * tempo
        kt.append(t); kp.append(bottom + np.array([0, 0.005, 0])); kl.append(kl[-1]); ka.append(1.0)
        t += u(0.6, 0.8) * tempo
        kt.append(t); kp.append(base); kl.append(0.0); ka.append(0.0 if r == reps - 1 else 0.6)
    total = t + u(0.25, 0.4)
    n = num_frames(total)
    tt = frame_times(n, FPS)
    pose = _planted_action(start, persona, body, n)
    pose.pelvis = keyframes(tt, kt, np.array(kp))
    lean = keyframes(tt, kt, kl)
    arms = keyframes(tt, kt, ka)
    pose.pelvis_ypr[:, 1] += 0.75 * lean
    pose.spine[:, 1] += 0.25 * lean - 0.1 * arms
    pose.neck[:, 1] -= 0.5 * lean
    if arms_forward:
        pose.arm[:, :, 0] += (1.45 * arms)[:, None]
        pose.arm[:, :, 2] *= (1.0 - 0.7 * arms)[:, None]
    else:
        pose.arm[:, :, 0] += (0.5 * lean)[:, None]
    g0 = ypr_matrix(pose.pelvis_ypr)
    bound = max_pelvis_height(pose.pelvis, g0, pose.ankle, body) - 0.003
    pose.pelvis[:, 1] = np.minimum(pose.pelvis[:, 1], bound)
    core = _frames(kt[1] - 0.05, kt[-1] + 0.05, n)
    return Segment(pose, start, core, arms_free=not arms_forward,
                   info=dict(depth=float(depth), arms_forward=arms_forward))


#: Height (m) of the wrist joint over the floor when the palm rests on it.
WRIST_ON_FLOOR = 0.04


def sit(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
        mods: tuple[str, ...] = (), hold: float = 1.0) -> Segment:
    """Sit down on the ground (knees up, hands on the floor behind) and stay seated."""
    u = rng.uniform
    tempo = 1.35 if "slowly" in mods else (0.75 if "quickly" in mods else 1.0)
    fwd, _ = heading_vectors(start.yaw)
    h = standing_height(start, body, pitch=0.03)
    base = start.ground + np.array([0, h, 0])
    back = u(0.36, 0.46)
    seat = start.ground - fwd * back + np.array([0, u(0.13, 0.16), 0])
    t1 = u(0.2, 0.35)
    t2 = t1 + u(0.6, 0.8) * tempo                # crouch
    t3 = t2 + u(0.55, 0.75) * tempo              # down to the floor
    t4 = t3 + u(0.3, 0.4)                        # settle
    total = t4 + hold
    crouch = base + np.array([0, -0.42, 0]) - fwd * 0.18
    kt = [0.0, t1, t2, t3, t4]
    kp = np.array([base, base, crouch, seat + np.array([0, 0.01, 0]), seat])
    kv = np.zeros_like(kp)
    kv[2] = (seat - crouch) / (t3 - t2) * 0.5     # keep moving through the crouch
    n = num_frames(total)
    tt = frame_times(n, FPS)
    pose = _planted_action(start, persona, body, n)
    pose.pelvis = keyframes(tt, kt, kp, kv)
    lean = keyframes(tt, kt, [0.0, 0.0, 0.6, 0.0, -0.4])           # leaning back onto the hands
    spine = keyframes(tt, kt, [0.0, 0.0, 0.1, 0.25, 0.2])
    arms = keyframes(tt, kt, [0.0, 0.0, 0.5, 1.0, 1.0])
    pose.pelvis_ypr[:, 1] += lean
    pose.spine[:, 1] += spine
    pose.neck[:, 1] -= 0.3 * lean
    # the hands come forward while crouching, then reach back to the floor
    pose.arm[:, :, 0] += (-0.55 * arms + 0.3 * np.sin(np.pi * np.clip(arms, 0.0, 1.0)))[:, None]
    pose.arm[:, :, 1] += (0.25 * arms)[:, None]
    pose.arm[:, :, 2] *= (1.0 - 0.6 * arms)[:, None]
    seated = keyframes(tt, kt, [0.0, 0.0, 0.5, 1.0, 1.0])
    pose.knee_pole += (np.array([0.0, 0.8, 0.0]) * seated[:, None])[:, None, :]
    # the hands land on the floor behind the hips and stay there (1.0: they hovered 13-17 cm up)
    _, left = heading_vectors(start.yaw)
    behind, out = u(0.08, 0.16), u(0.15, 0.21)
    on_floor = keyframes(tt, kt, [0.0, 0.0, 0.0, 1.0, 1.0])[:, None]
    hand_t = np.zeros((n, 2, 3))
    for k, sign in enumerate((1.0, -1.0)):
        palm = seat - fwd * behind + left * (sign * out)
        palm[1] = start.ground[1] + WRIST_ON_FLOOR
        hand_t[:, k] = palm
        solved = arm_controls_for(pose, body, k, hand_t[:, k])
        pose.arm[:, k] = (1.0 - on_floor) * pose.arm[:, k] + on_floor * solved
    core = _frames(t1 - 0.05, t4 + 0.1, n)
    # breathing while seated
    pose.spine[:, 1] += 0.01 * np.sin(2 * np.pi * 0.25 * tt) * ease(tt, t4, t4 + 0.5)
    hands = (on_floor.repeat(2, 1), hand_t)
    return Segment(pose, start, core, arms_free=False, seated=True, hands=hands,
                   info=dict(seat_height=float(seat[1])))


def bow(start: Stance, persona: Persona, body: BodyModel, rng: np.random.Generator, *,
        mods: tuple[str, ...] = (), reps: int = 1) -> Segment:
    """Bend forward from the hips and come back up; "low" (deeply) bends further."""
    u = rng.uniform
    tempo = 1.4 if "slowly" in mods else (0.7 if "quickly" in mods else 1.0)
    angle = u(0.95, 1.25) if "low" in mods else u(0.4, 0.8)
    fwd, _ = heading_vectors(start.yaw)
    kt, kb = [0.0], [0.0]
    t = u(0.2, 0.3)
    kt.append(t); kb.append(0.0)
    for r in range(reps):
        t += u(0.5, 0.75) * tempo
        kt.append(t); kb.append(angle)
        t += u(0.3, 0.7) * tempo
        kt.append(t); kb.append(angle * 0.97)
        t += u(0.6, 0.85) * tempo
        kt.append(t); kb.append(0.0)
    total = t + u(0.25, 0.4)
    n = num_frames(total)
    tt = frame_times(n, FPS)
    pose = _planted_action(start, persona, body, n)
    bend = keyframes(tt, kt, kb)
    pose.pelvis_ypr[:, 1] += 0.35 * bend
    pose.spine[:, 1] += 0.65 * bend
    pose.neck[:, 1] += u(0.35, 0.5) * bend / max(angle, 1e-6)   # the head drops into the bow
    pose.pelvis -= fwd[None] * (0.07 * bend)[:, None]
    # arms hang towards the floor rather than staying with the chest
    pose.arm[:, :, 0] += (0.75 * bend)[:, None]
    g0 = ypr_matrix(pose.pelvis_ypr)
    bound = max_pelvis_height(pose.pelvis, g0, pose.ankle, body) - 0.003
    pose.pelvis[:, 1] = np.minimum(pose.pelvis[:, 1], bound)
    core = _frames(kt[1] - 0.05, kt[-1] + 0.05, n)
    return Segment(pose, start, core, arms_free=False, info=dict(bend=float(angle)))
