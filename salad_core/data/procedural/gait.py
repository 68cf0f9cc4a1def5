"""Locomotion: walking, running, jogging, marching, backwards, sidesteps, circles, turns, spins.

A footstep planner places every foot plant on the route at the root position of its own
mid-stance (plus the lateral stance offset), so the root travels exactly one step length per
step and a planted foot never moves: the root speed is consistent with the stride by
construction and there is no foot sliding. Between plants each foot swings along a lifted arc;
heel-strike and toe-off roll the planted foot about the ankle or the toe. The pelvis bobs,
sways towards the stance foot and rotates with the legs; shoulders counter-rotate and the arms
swing in counter-phase. The pelvis height is finally clamped so both hips reach their ankles.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .curves import ease, frame_times, keyframes, smooth, wrap_angle
from .footwork import ANKLE_HEIGHT, PELVIS_AHEAD, Persona, Plant, Stance, Swing, foot_track, \
    max_pelvis_height, standing_height
from .kinematics import FPS, BodyModel, Pose, heading_vectors, rot_y, ypr_matrix
from .segment import Segment, knee_poles, num_frames

__all__ = ["GaitStyle", "Route", "locomotion", "gait_style", "GAITS"]

#: Gravity (m/s^2) of a running flight's crest above the lift-off reach.
GRAVITY_RUN = 9.81

#: Gaits that :func:`gait_style` knows.
GAITS = ("walk", "run", "jog", "march", "backward", "sidestep", "turn", "spin", "circle")


@dataclass(frozen=True)
class GaitStyle:
    """How a gait moves (all speeds at cruise)."""

    speed: float            # travel speed along the route (m/s); 0 steps in place
    cadence: float          # steps per second
    duty: float             # fraction of a stride each foot is planted (walk ~0.6, run ~0.35)
    swing: Swing            # the swing arc of the feet
    roll_in: float          # foot pitch at touch-down (rad): + heel strike, - toe first
    roll_out: float         # foot pitch at lift-off (rad): - toe-off, + heel last
    width: float            # half distance between the feet while stepping (m)
    bob: float              # pelvis vertical oscillation (m)
    drop: float             # pelvis lowered below standing at cruise (m)
    lean: float             # forward trunk lean at cruise (rad)
    sway: float             # pelvis sway towards the stance foot (m)
    twist: float            # pelvic rotation amplitude (rad)
    arm_swing: float        # shoulder swing amplitude (rad)
    arm_abd: float          # extra arm abduction (rad)
    elbow: float            # elbow flexion at cruise (rad)
    running: bool = False   # flight phases: pelvis lowest in stance, highest in flight
    ramp_strides: float = 0.8  # strides to speed up and to slow down
    plant_at: float = 0.5   # where in its stance the root passes over a foot plant (0 touch-down, 1 lift-off)
    arm_center: float = 0.0  # running: upper-arm flexion the swing is centred on (rad, heading frame)
    step_var: tuple = ()    # relative deviation of each step's duration from 1/cadence, cycled (e.g. +-0.03)

    def __post_init__(self) -> None:
        if not 0.1 <= self.duty <= 0.8:
            raise ValueError(f"GaitStyle.duty={self.duty} must lie in [0.1, 0.8]")
        if not self.cadence > 0:
            raise ValueError(f"GaitStyle.cadence={self.cadence} must be positive")
        if self.speed < 0:
            raise ValueError(f"GaitStyle.speed={self.speed} must be >= 0 (use Route.heading to go backwards)")
        if not 0.2 <= self.plant_at <= 0.8:
            raise ValueError(f"GaitStyle.plant_at={self.plant_at} must lie in [0.2, 0.8]")
        if any(not -0.15 <= v <= 0.15 for v in self.step_var):
            raise ValueError(f"GaitStyle.step_var={self.step_var} must hold deviations in [-0.15, 0.15]")


@dataclass(frozen=True)
class Route:
    """Where the root goes, in the start body frame."""

    kind: str = "line"      # "line", "arc" or "turn" (in place)
    heading: float = 0.0    # line: direction of travel (0 forward, pi backward, +pi/2 left)
    radius: float = 1.0     # arc: radius (m)
    side: float = 1.0       # arc/turn: +1 turns left (counter-clockwise), -1 right
    angle: float = 0.0      # turn: heading change (rad, >= 0; the side gives the sign)

    def __post_init__(self) -> None:
        if self.kind not in ("line", "arc", "turn"):
            raise ValueError(f"Route.kind={self.kind!r}; allowed: 'line', 'arc', 'turn'")
        if self.side not in (1.0, -1.0):
            raise ValueError(f"Route.side={self.side!r} must be +1 (left) or -1 (right)")


def _route_local(route: Route, dist: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Local position ``(N, 3)`` and heading change ``(N,)`` after travelling ``dist`` metres."""
    z = np.zeros_like(dist)
    if route.kind == "line":
        return np.stack([np.sin(route.heading) * dist, z, np.cos(route.heading) * dist], -1), z
    if route.kind == "arc":
        th = dist / route.radius
        return np.stack([route.side * route.radius * (1 - np.cos(th)), z, route.radius * np.sin(th)], -1), route.side * th
    return np.stack([z, z, z], -1), route.side * route.angle * u


def _progress(t: np.ndarray, t_s: float, t_e: float, ramp: float) -> np.ndarray:
    """Normalised speed profile (1 at cruise) and its integral (seconds at cruise speed)."""
    v = ease(t, t_s, t_s + ramp) * (1.0 - ease(t, t_e - ramp, t_e))
    dt = np.diff(t, prepend=t[0])
    s = np.cumsum(0.5 * (v + np.concatenate([[v[0]], v[:-1]])) * dt)
    return v, s


def locomotion(start: Stance, persona: Persona, style: GaitStyle, route: Route, n_steps: int,
               body: BodyModel, first: int | None = None) -> Segment:
    """Step ``n_steps`` times along ``route`` from a standing ``start`` to a standing end.

    Parameters
    ----------
    start : Stance
    persona : Persona
    style : GaitStyle
    route : Route
    n_steps : int
        Number of steps (>= 2); the last two bring the feet side by side.
    body : BodyModel
    first : int, optional
        Foot that steps first (0 left, 1 right); default: the side the route goes to, else left.

    Returns
    -------
    Segment with ``info`` holding the cruise ``speed``, ``distance``, ``turn`` and step count.
    """
    if n_steps < 2:
        raise ValueError(f"n_steps={n_steps} must be >= 2")
    step_t = 1.0 / style.cadence
    swing_t = max(0.18, (1.0 - style.duty) * 2.0 * step_t)
    pre, post = 0.25, 0.35
    # steps differ a little in duration (and so, over a smoothly moving root, in length)
    var = np.array([style.step_var[k % len(style.step_var)] if style.step_var else 0.0 for k in range(n_steps)])
    if style.running:               # a long stance pushes off far behind the hips: runners vary less
        var = 0.5 * var
    lifts = pre + np.concatenate([[0.0], np.cumsum(step_t * (1.0 + var[:-1]))])
    lands = lifts + swing_t
    total = lands[-1] + post
    n = num_frames(total)
    t = frame_times(n, FPS)
    t_s = pre - 0.35 * step_t
    t_e = lands[-1] + 0.1 * step_t
    ramp = min(style.ramp_strides * 2 * step_t, (t_e - t_s) / 2)

    # root progress along the route (fine grid so that plants at arbitrary times are exact)
    fine = np.linspace(0.0, total, int(total * 400) + 2)
    _, s_fine = _progress(fine, t_s, t_e, ramp)
    s_total = s_fine[-1]
    distance = style.speed * s_total

    def along(tq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = np.interp(tq, fine, s_fine)
        u = s / s_total
        loc, dyaw = _route_local(route, style.speed * s, u)
        pos = start.ground + loc @ rot_y(start.yaw).T
        return pos, start.yaw + dyaw

    if first is None:
        if route.kind == "line" and abs(np.sin(route.heading)) > 0.5:
            first = 0 if np.sin(route.heading) > 0 else 1
        elif route.kind in ("arc", "turn"):
            first = 0 if route.side > 0 else 1
        else:
            first = 0
    feet = [(first + k) % 2 for k in range(n_steps)]

    # ---- foot plants: each at the root position of its own mid-stance
    end_pos, end_yaw = along(np.array([total]))
    end_stance = Stance.at((end_pos[0, 0], end_pos[0, 2]), float(end_yaw[0]), persona)
    plants: list[list[Plant]] = [[], []]
    airs: list[list[Swing]] = [[], []]
    first_lift = {f: lifts[feet.index(f)] for f in (0, 1)}
    for f in (0, 1):
        # the first foot pushes off from a stand; the other one from behind a moving body, like any step
        trailing = f != first
        plants[f].append(Plant(-np.inf, first_lift[f], start.ankles[f], float(start.foot_yaw[f]),
                               roll_out=style.roll_out if trailing else 0.5 * style.roll_out,
                               roll_out_time=min(0.25, 0.45 * (first_lift[f] - t_s)) if trailing
                               else min(0.18, 0.6 * step_t)))
    for k in range(n_steps):
        f = feet[k]
        nxt = lifts[k + 2] if k + 2 < n_steps else np.inf
        if k >= n_steps - 2:
            ankle, yaw = end_stance.ankles[f], float(end_stance.foot_yaw[f])
            roll_out = 0.0
        else:
            # runners land a little ahead of the hips and push off far behind them
            tm = lands[k] + style.plant_at * (nxt - lands[k])
            pos, hd = along(np.array([tm]))
            fwd, left = heading_vectors(hd[0])
            sign = 1.0 if f == 0 else -1.0
            ankle = pos[0] + left * (sign * style.width) - fwd * PELVIS_AHEAD
            # walkers' steps also vary in length independently of the timing (a runner's longer
            # step would over-reach its push-off: runs vary through the timing alone)
            if style.step_var and not style.running:
                ankle = ankle + fwd * (style.step_var[(k + 7) % len(style.step_var)] * style.speed / style.cadence)
            ankle[1] = ANKLE_HEIGHT
            yaw = float(hd[0] + sign * persona.toe_out)
            roll_out = style.roll_out
        stance_t = (nxt - lands[k]) if np.isfinite(nxt) else 1.0
        plant = Plant(lands[k], nxt, ankle, yaw, roll_in=style.roll_in,
                      roll_in_time=min(0.12, 0.3 * stance_t), roll_out=roll_out,
                      roll_out_time=min(0.25, (0.7 if style.running else 0.45) * stance_t))
        if route.kind in ("turn",) and k < n_steps - 2 and plant.pivot_window() is not None:
            # turning steps pivot on the ball of the stance foot for half of the turn made
            # during the stance (2.0's feet only turned in the air: 5.5 % of in-contact foot
            # frames moved, 27.5 % in real data)
            _, hd = along(np.array([lands[k], nxt]))
            turn = 0.5 * wrap_angle(float(hd[1] - hd[0]))
            plant = replace(plant, yaw=yaw - 0.5 * turn, yaw_turn=turn)
        plants[f].append(plant)
        airs[f].append(style.swing)
    ankle = np.zeros((n, 2, 3))
    toe = np.zeros((n, 2, 3))
    planted = np.zeros((n, 2))
    for f in (0, 1):
        ankle[:, f], toe[:, f], pl = foot_track(t, plants[f], airs[f], body, f)
        planted[:, f] = pl

    # ---- root, pelvis and trunk
    ground, heading = along(t)
    fwd, left = heading_vectors(heading)
    act = ease(t, 0.05, pre) * (1.0 - ease(t, lands[-1], lands[-1] + 0.8 * post))
    # stride phase: the foot that steps at step k goes from behind (-1) to ahead (+1)
    c = np.interp(t, np.append(lifts, lifts[-1] + step_t), np.arange(n_steps + 1.0))
    lead_first = -np.cos(np.pi * c) * act
    lead = np.stack([lead_first, -lead_first], 1) if first == 0 else np.stack([-lead_first, lead_first], 1)
    sig = max(1.0, 0.2 * step_t * FPS)
    side = smooth(planted[:, 0] - planted[:, 1], sig) * act           # +1: left foot supports
    pelvis = ground + left * (style.sway * side)[:, None]
    h_stand = standing_height(start, body, pitch=0.03)
    twist = -style.twist * lead[:, 0]
    ypr = np.stack([heading + twist, 0.03 + 0.4 * style.lean * act, -0.05 * side], -1)
    g0 = ypr_matrix(ypr)
    if style.running:
        pelvis[:, 1] = _running_height(t, planted, pelvis, g0, ankle, body, style, h_stand, act)
    else:
        single = smooth(np.abs(planted[:, 0] - planted[:, 1]), sig)
        bob = style.bob * (2.0 * single - 1.0)
        pelvis[:, 1] = h_stand - style.drop * act + bob * act
        for _ in range(2):
            bound = max_pelvis_height(pelvis, g0, ankle, body, planted=planted > 0.5) - 0.004
            pelvis[:, 1] = np.minimum(smooth(np.minimum(pelvis[:, 1], bound), 1.0), bound)
    spine = np.stack([-1.3 * twist, 0.03 + 0.6 * style.lean * act, 0.04 * side], -1)
    neck = np.stack([np.zeros(n), persona.head_pitch - 0.5 * style.lean * act, np.zeros(n)], -1)

    # ---- arms swing against the legs (the left arm comes forward with the right foot)
    rest = np.asarray(persona.arm_rest, dtype=np.float64)
    arm = np.tile(rest, (n, 2, 1))
    if style.running:
        chest_pitch = ypr[:, 1] + spine[:, 1]
        for k in range(2):
            arm[:, k] = _running_arm(lead[:, 1 - k], chest_pitch, act, rest, style, body, k)
    else:
        for k in range(2):
            swing = style.arm_swing * persona.swing_scale[k] * lead[:, 1 - k]
            arm[:, k, 0] = rest[0] + swing + 0.1 * act
            arm[:, k, 1] = rest[1] + style.arm_abd * act
            arm[:, k, 2] = rest[2] + (style.elbow - rest[2]) * act + 0.35 * np.maximum(swing, 0.0)
    pole = np.tile(np.asarray(persona.arm_pole, dtype=np.float64), (n, 2, 1))
    if style.running:
        # elbows point back *and down*: a backward-only pole would flip the elbow above a
        # forward-swinging forearm (its component along the arm line vanishes)
        w = act[:, None, None]
        pole = (1.0 - w) * pole + w * np.array([0.25, -0.7, -1.0])
    foot_yaw = np.stack([heading + persona.toe_out, heading - persona.toe_out], 1)
    pose = Pose(pelvis, ypr, spine, neck, ankle, toe, knee_poles(foot_yaw), arm, pole)

    f0 = int(np.floor(t_s * FPS))
    f1 = min(n, int(np.ceil((lands[-1] + 0.1) * FPS)) + 1)
    turned = float(end_yaw[0] - start.yaw)
    info = dict(speed=style.speed, distance=float(distance), turn=turned, steps=n_steps,
                cadence=style.cadence, duration=float(total))
    return Segment(pose, end_stance, (max(0, f0), f1), info=info)


def _running_height(t: np.ndarray, planted: np.ndarray, pelvis: np.ndarray, g0: np.ndarray, ankle: np.ndarray,
                    body: BodyModel, style: GaitStyle, h_stand: float, act: np.ndarray) -> np.ndarray:
    """``(N,)`` pelvis height of a running gait: lowest in mid-stance, highest in mid-flight.

    The peak-to-peak range is ``2 * style.bob``. The crest of each flight sits where the legs
    can just reach the floor at the surrounding lift-off and touch-down (``max_pelvis_height``
    there, both feet's rolls included), the trough of each stance ``2 * bob`` below it; a
    Hermite curve with zero vertical velocity at the keys joins them. Only stance frames are
    then bounded by the leg reach, so flight frames really are airborne and the bob survives
    (1.0 clamped a sine onto the reach bound, which flattened it to 1-2 cm).
    """
    n = len(t)
    on = planted > 0.5
    anyon = on.any(1)
    bound = max_pelvis_height(pelvis, g0, ankle, body, planted=on) - 0.004
    # stance and flight intervals of the cruise (runs of frames with / without a planted foot)
    edges = np.flatnonzero(np.diff(anyon.astype(int))) + 1
    runs = np.split(np.arange(n), edges)
    keys_t, keys_h = [], []
    for r in runs:
        if anyon[r[0]]:
            continue
        lo, hi = max(r[0] - 1, 0), min(r[-1] + 1, n - 1)       # last stance frame before, first after
        crest = min(bound[lo], bound[hi]) + 0.25 * GRAVITY_RUN * ((hi - lo) / FPS / 2) ** 2
        keys_t.append(0.5 * (t[lo] + t[hi]))
        keys_h.append(crest)
    if len(keys_t) < 2:
        # no flight (too slow a start/stop): fall back to a bounded sine
        h = h_stand - style.drop * act
        return np.minimum(h, bound)
    cruise = np.array(keys_h)
    keys = [(keys_t[0], cruise[0])]
    for i in range(1, len(keys_t)):
        keys.append((0.5 * (keys_t[i - 1] + keys_t[i]), min(cruise[i - 1], cruise[i]) - 2 * style.bob))
        keys.append((keys_t[i], cruise[i]))
    kt, kh = np.array(keys).T
    h = keyframes(t, kt, kh)
    # before the first and after the last flight: ease from / to the standing height
    w = np.clip(act, 0.0, 1.0)
    h_out = np.where(t < kt[0], h_stand - style.drop * w, np.where(t > kt[-1], h_stand - style.drop * w, h))
    blend = ease(t, kt[0] - 0.3, kt[0]) * (1.0 - ease(t, kt[-1], kt[-1] + 0.3))
    h = (1.0 - blend) * np.minimum(h_out, h_stand) + blend * h
    for _ in range(2):
        h = np.where(anyon, np.minimum(h, bound), h)
        h = np.where(anyon, np.minimum(smooth(h, 0.7), bound), smooth(h, 0.7))
    return h


def _running_arm(lead: np.ndarray, chest_pitch: np.ndarray, act: np.ndarray, rest: np.ndarray,
                 style: GaitStyle, body: BodyModel, k: int) -> np.ndarray:
    """``(N, 3)`` (flex, abd, elbow) of arm ``k`` swinging about a neutral shoulder while running.

    The *upper arm* swings ``arm_center +- arm_swing`` (rad, heading frame) with ``lead`` in
    [-1, 1]: forward of vertical and behind it, as runners do. The elbow stays near
    ``style.elbow`` and flexes further as the arm comes forward. The arm control is the
    shoulder-to-wrist line, which runs ahead of the upper arm by the elbow triangle's angle,
    and is measured in the chest frame, which a forward lean tips backwards: the lean is added.
    """
    upper = style.arm_center + style.arm_swing * lead + chest_pitch
    elbow = style.elbow + 0.17 * lead
    up, fo = body.upper_arm[k], body.forearm[k]
    ahead = np.arctan2(fo * np.sin(elbow), up + fo * np.cos(elbow))
    run = np.stack([upper + ahead, np.full_like(lead, rest[1] + style.arm_abd), elbow], -1)
    w = act[:, None]
    return (1.0 - w) * rest[None] + w * run


# ----------------------------------------------------------------------------- style presets
def _pace(mods: tuple[str, ...]) -> int:
    return -1 if "slowly" in mods else (1 if "quickly" in mods else 0)


#: Std of the step-to-step variation of step duration and of step length (real walkers: 2-4 %).
STEP_VARIATION = 0.04


def gait_style(kind: str, rng: np.random.Generator, mods: tuple[str, ...] = (), tempo: float = 1.0,
               in_place: bool = False) -> GaitStyle:
    """A randomised :class:`GaitStyle` of a gait ``kind`` (see :data:`GAITS`), whose steps vary
    in duration and length by about :data:`STEP_VARIATION` (std) from step to step."""
    st = _gait_style(kind, rng, mods, tempo, in_place)
    return replace(st, step_var=tuple(np.clip(rng.normal(0.0, STEP_VARIATION, 16), -0.1, 0.1).round(4).tolist()))


def _gait_style(kind: str, rng: np.random.Generator, mods: tuple[str, ...], tempo: float,
                in_place: bool) -> GaitStyle:
    """A randomised :class:`GaitStyle` of a gait ``kind`` (see :data:`GAITS`).

    ``mods`` may hold "slowly" / "quickly", which change the speed and cadence measurably.
    """
    u = rng.uniform
    pace = _pace(mods)
    if kind in ("walk", "circle"):
        speed = [u(0.5, 0.72), u(1.05, 1.4), u(1.65, 1.95)][pace + 1]
        cadence = [u(1.3, 1.5), u(1.7, 1.9), u(2.0, 2.2)][pace + 1] * tempo
        # a slow-tempo performer walking fast must not take 1 m steps: the trailing leg cannot
        # reach its toe-off (the ankle's range clamps the foot and the planted toe slides)
        speed = min(speed, 0.85 * cadence)
        st = GaitStyle(speed=speed, cadence=cadence, duty=[0.64, 0.61, 0.58][pace + 1],
                       swing=Swing(u(0.06, 0.1), u(0.4, 0.5), u(0.05, 0.2)), roll_in=u(0.2, 0.32),
                       roll_out=-u(0.45, 0.65), width=u(0.07, 0.1), bob=u(0.012, 0.022), drop=u(0.0, 0.02),
                       lean=u(0.02, 0.06) + 0.03 * pace, sway=u(0.015, 0.03), twist=u(0.04, 0.08),
                       arm_swing=u(0.22, 0.5) * (1 + 0.3 * pace), arm_abd=u(0.0, 0.1), elbow=u(0.15, 0.7))  # 2.5: wider
        if in_place:
            st = replace(st, speed=0.0, swing=replace(st.swing, height=u(0.1, 0.15)), roll_in=0.05, roll_out=-0.3)
        return st
    if kind == "run":
        return GaitStyle(speed=[u(2.6, 3.0), u(3.0, 3.6), u(3.8, 4.4)][pace + 1], cadence=u(2.6, 2.95) * tempo,
                         duty=u(0.31, 0.35), swing=Swing(u(0.24, 0.32), u(0.35, 0.42), u(0.1, 0.25)),
                         roll_in=u(0.0, 0.12), roll_out=-u(0.6, 0.75), width=u(0.04, 0.07), bob=u(0.042, 0.052),
                         drop=u(0.04, 0.07), lean=u(0.1, 0.18), sway=u(0.005, 0.012), twist=u(0.08, 0.12),
                         arm_swing=u(0.6, 0.75), arm_abd=u(0.0, 0.08), elbow=u(1.45, 1.65), running=True,
                         ramp_strides=1.2, plant_at=u(0.38, 0.45), arm_center=u(-0.08, 0.04))
    if kind == "jog":
        st = GaitStyle(speed=[u(1.4, 1.75), u(1.8, 2.3), u(2.4, 2.7)][pace + 1], cadence=u(2.4, 2.7) * tempo,
                       duty=u(0.34, 0.38), swing=Swing(u(0.13, 0.19), u(0.38, 0.45), u(0.05, 0.15)),
                       roll_in=u(0.05, 0.15), roll_out=-u(0.5, 0.65), width=u(0.05, 0.08), bob=u(0.04, 0.05),
                       drop=u(0.03, 0.05), lean=u(0.06, 0.12), sway=u(0.008, 0.015), twist=u(0.06, 0.1),
                       arm_swing=u(0.5, 0.65), arm_abd=u(0.0, 0.08), elbow=u(1.4, 1.6), running=True,
                       ramp_strides=1.0, plant_at=u(0.4, 0.47), arm_center=u(-0.08, 0.04))
        if in_place:
            st = replace(st, speed=0.0, roll_in=0.0, roll_out=-0.5, swing=replace(st.swing, height=u(0.15, 0.22)))
        return st
    if kind == "march":
        return GaitStyle(speed=0.0 if in_place else u(0.7, 1.0), cadence=[u(1.3, 1.5), u(1.6, 1.9), u(2.0, 2.2)][pace + 1] * tempo,
                         duty=0.62, swing=Swing(u(0.2, 0.3), 0.45, -u(0.2, 0.35), lead=u(0.1, 0.16)),
                         roll_in=0.0, roll_out=-u(0.15, 0.3), width=u(0.08, 0.1), bob=u(0.01, 0.02),
                         drop=u(0.0, 0.01), lean=u(-0.02, 0.02), sway=u(0.02, 0.03), twist=u(0.02, 0.05),
                         arm_swing=u(0.7, 0.95), arm_abd=u(0.0, 0.05), elbow=u(0.05, 0.25))
    if kind == "backward":
        return GaitStyle(speed=[u(0.35, 0.5), u(0.55, 0.8), u(0.9, 1.1)][pace + 1], cadence=[u(1.2, 1.4), u(1.5, 1.8), u(1.9, 2.1)][pace + 1] * tempo,
                         duty=0.63, swing=Swing(u(0.06, 0.09), 0.5, u(0.0, 0.1)), roll_in=-u(0.2, 0.35),
                         roll_out=u(0.05, 0.15), width=u(0.08, 0.11), bob=u(0.008, 0.015), drop=u(0.0, 0.02),
                         lean=u(-0.05, 0.0), sway=u(0.015, 0.025), twist=u(0.02, 0.05),
                         arm_swing=u(0.1, 0.2), arm_abd=u(0.0, 0.08), elbow=u(0.25, 0.5))
    if kind == "sidestep":
        return GaitStyle(speed=[u(0.3, 0.4), u(0.45, 0.62), u(0.65, 0.8)][pace + 1], cadence=[u(1.2, 1.4), u(1.5, 1.8), u(1.9, 2.1)][pace + 1] * tempo,
                         duty=0.66, swing=Swing(u(0.05, 0.07), 0.5, 0.0), roll_in=0.0, roll_out=-0.1,
                         width=u(0.15, 0.18), bob=u(0.005, 0.012), drop=u(0.02, 0.04), lean=u(0.0, 0.04),
                         sway=u(0.01, 0.02), twist=0.0, arm_swing=0.0, arm_abd=u(0.05, 0.15), elbow=u(0.2, 0.4))
    if kind in ("turn", "spin"):
        fast = kind == "spin"
        cad = (u(2.4, 3.0) if fast else [u(1.2, 1.4), u(1.6, 1.9), u(2.0, 2.3)][pace + 1]) * tempo
        return GaitStyle(speed=0.0, cadence=cad, duty=0.6, swing=Swing(u(0.05, 0.08), 0.5, 0.0),
                         roll_in=0.0, roll_out=-0.15, width=u(0.08, 0.11), bob=0.008, drop=u(0.01, 0.03),
                         lean=0.02, sway=0.012, twist=0.0, arm_swing=0.05,
                         arm_abd=u(0.35, 0.7) if fast else 0.03, elbow=u(0.3, 0.6))
    raise ValueError(f"unknown gait {kind!r}; known gaits: {', '.join(GAITS)}")
