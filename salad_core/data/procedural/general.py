"""General (uncaptioned) motion: smooth random movement of every joint, any body orientation, varied root paths.

The captioned corpus shows 25 actions; a VAE trained only on them cannot represent motion outside
that set (real capture: lying, rolling, cartwheels, get-ups, runs, turns). This generator covers
the space of poses and root paths instead, for VAE training only (no captions):

* every joint angle of :data:`~.general_body.DOFS` follows a smooth track through random key
  poses (monotone cubic between keys, so it never overshoots a key and stays inside the
  anatomical :data:`~.general_body.LIMITS`);
* key poses come from *postures* (standing, bending, squatting, lunging, kicking, kneeling,
  sitting on the floor, lying supine / prone / on the side, crawling, on all fours, handstand)
  with everything the posture leaves free drawn from the full joint ranges;
* seven modes (:data:`MODES`) chain them: upright free movement, locomotion (walking and running
  forwards, backwards, sideways and diagonally, turning on curved paths, changing speed,
  stopping), jumps (vertical, long, sideways and spinning, with ballistic flight), floor work
  (postures on the ground and the transitions between them: lying down, rolling over, getting up,
  crawling), acrobatics (forward/backward rolls, log rolls, cartwheels, handstands, flips);
* :mod:`.general_root` puts the body on the floor: the lowest joint rests on it, supporting joints
  do not slide (so stepping legs carry the body and a rolling body rolls), flights are ballistic,
  and feet in contact are pinned by exact leg IK.

Clips are 20 fps, 41-197 joint frames (40-196 feature rows, HumanML3D's range), on the HumanML3D
skeleton with its exact target bone lengths, nothing below the floor. :func:`generate_general`
is a pure function of ``(seed, index)``.

Every clip records the plan it followed (:attr:`GeneralClip.events`, see :data:`EVENTS`): the
captions of the general set (:mod:`.general_language`) are made from it. Recording takes no random
draw, so the clips are the same as before it was recorded (general set 1.1).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .curves import frame_times, smooth
from .general_body import DOF_INDEX, DOFS, forward_kinematics, limits_array, rest_dofs
from .general_root import intervals, plant_feet, solve_root
from .kinematics import FPS

__all__ = ["MODES", "GeneralConfig", "GeneralClip", "GeneralEvent", "generate_general", "sample_general",
           "smooth_track", "POSTURES", "EVENTS"]

#: Modes and their default shares. Upright movement and locomotion dominate real capture, so
#: they get half; the rest buys coverage the captioned corpus lacks (floor, inversions, flight).
MODES: dict[str, float] = {"free": 0.22, "locomotion": 0.26, "jump": 0.14, "floor": 0.24, "acrobatic": 0.14}

#: The events a clip's plan records (:class:`GeneralEvent` actions) and what their ``info`` holds.
EVENTS: dict[str, str] = {
    "free": "free mode, the whole plan: postures (the key poses' posture info) and times (their frames)",
    "walk": "a gait key of locomotion, walking: direction (deg, 0 forwards, +90 to the left, 180 backwards), "
            "amplitude (deg of leg swing), key (frame)",
    "run": "a gait key of locomotion, running: as walk",
    "stand": "a gait key of locomotion with no leg swing (a stop): as walk",
    "posture": "floor work, the move from one key posture to the next: from, to (posture info: posture name, "
               "and e.g. knee / front 'l' or 'r', high, twist_sign, lean_back, arms_under)",
    "crawl_swing": "floor work, frames with swinging limbs on hands and knees: weight, sign, swing (deg)",
    "jump": "crouch, take-off, flight, landing: flight (frames), air (tuck / star / split / plain), spin (deg, > 0 "
            "to the left), distance (m), direction (deg, as walk), flip 0",
    "flip": "a jump with a somersault: as jump, flip (deg, > 0 forwards)",
    "start": "acrobatics, the posture the plan starts in (an instant)",
    "roll": "a forward (sign > 0) or backward roll through a tuck",
    "logroll": "lying down (from lie, a frame) and rolling about the long axis: sign (> 0 to the left), turn (deg)",
    "cartwheel": "a cartwheel: sign (> 0 towards the left)",
    "handstand": "down to the hands, up into a handstand (up: first and last handstand key frames), down "
                 "(walkover: on the other side) and up to standing",
}

_LO, _HI = limits_array()
_D = len(DOFS)
_I = DOF_INDEX


@dataclass(frozen=True)
class GeneralConfig:
    """Settings of the general-motion generator.

    Parameters
    ----------
    min_frames, max_frames : int
        Joint frames of a clip (features have one row fewer); default 41..197 (HumanML3D's 40..196 rows).
    modes : dict
        Mode name -> relative weight (names from :data:`MODES`; weights >= 0, not all zero).
    """

    min_frames: int = 41
    max_frames: int = 197
    modes: dict = field(default_factory=lambda: dict(MODES))

    def __post_init__(self) -> None:
        if isinstance(self.min_frames, bool) or not isinstance(self.min_frames, int) or self.min_frames < 8:
            raise ValueError(f"GeneralConfig.min_frames={self.min_frames!r} must be an int >= 8")
        if not isinstance(self.max_frames, int) or self.max_frames < self.min_frames:
            raise ValueError(f"GeneralConfig.max_frames={self.max_frames!r} must be an int >= min_frames "
                             f"({self.min_frames})")
        bad = sorted(set(self.modes) - set(MODES))
        if bad:
            raise ValueError(f"GeneralConfig.modes has unknown modes {bad}; allowed: {sorted(MODES)}")
        w = [self.modes[m] for m in self.modes]
        if any(not np.isfinite(x) or x < 0 for x in w) or sum(w) <= 0:
            raise ValueError(f"GeneralConfig.modes weights must be finite, >= 0 and not all 0, got {self.modes}")


@dataclass(frozen=True)
class GeneralEvent:
    """One thing the generator made the body do, on the clip's timeline (the plan; see :data:`EVENTS`).

    ``frames`` is the joint-frame interval ``[f0, f1)`` inside the clip; ``planned`` the interval
    the plan gave it before the clip's window cropped it (it may reach before frame 0 or after the
    last frame: then the clip shows only part of it, ``whole`` is False). ``info`` holds what the
    event needs to be named (postures, sides as ``"l"`` / ``"r"``, directions, turns).
    """

    action: str
    frames: tuple[int, int]
    planned: tuple[int, int]
    info: dict = field(default_factory=dict, hash=False, compare=False)

    @property
    def whole(self) -> bool:
        return self.planned == self.frames


@dataclass
class GeneralClip:
    """A generated motion: joints ``(N, 22, 3)`` metres (+Y up, floor y = 0), 20 fps.

    ``events`` is the plan the generator followed (:class:`GeneralEvent` s in time order): the
    ground truth of :mod:`.general_language`'s captions.
    """

    joints: np.ndarray
    mode: str
    dofs: np.ndarray            # (N, D) joint angles (radians) the joints were built from
    flight: np.ndarray          # (N,) bool, frames in the air
    events: tuple[GeneralEvent, ...] = ()

    @property
    def num_frames(self) -> int:
        return int(self.joints.shape[0])


# ----------------------------------------------------------------------------- tracks
def smooth_track(t: np.ndarray, key_t: np.ndarray, key_v: np.ndarray) -> np.ndarray:
    """Monotone piecewise-cubic curves through keys: ``(N, ...)`` at times ``t`` (seconds).

    Tangents follow Fritsch-Butland (zero at a local extremum, a harmonic mean of the adjacent
    slopes elsewhere), so the curve never leaves the range of two neighbouring keys: keys inside
    the joint limits give a track inside them. Constant before the first and after the last key.
    """
    key_t = np.asarray(key_t, dtype=np.float64)
    key_v = np.asarray(key_v, dtype=np.float64)
    if key_t.ndim != 1 or len(key_t) != len(key_v) or len(key_t) < 1:
        raise ValueError(f"smooth_track: key_t {key_t.shape} and key_v {key_v.shape} must match, K >= 1")
    if np.any(np.diff(key_t) <= 0):
        raise ValueError(f"smooth_track: key times must increase, got {np.round(key_t, 3).tolist()}")
    if len(key_t) == 1:
        return np.broadcast_to(key_v[0], (len(t),) + key_v.shape[1:]).copy()
    h = np.diff(key_t).reshape((-1,) + (1,) * (key_v.ndim - 1))
    slope = np.diff(key_v, axis=0) / h
    vel = np.zeros_like(key_v)
    a, b = slope[:-1], slope[1:]
    same = a * b > 0
    vel[1:-1] = np.where(same, 2.0 * a * b / np.where(same, a + b, 1.0), 0.0)
    k = np.clip(np.searchsorted(key_t, t, side="right") - 1, 0, len(key_t) - 2)
    hk = (key_t[k + 1] - key_t[k])
    s = np.clip((t - key_t[k]) / hk, 0.0, 1.0).reshape((-1,) + (1,) * (key_v.ndim - 1))
    hk = hk.reshape(s.shape)
    s2, s3 = s * s, s * s * s
    return ((2 * s3 - 3 * s2 + 1) * key_v[k] + (s3 - 2 * s2 + s) * hk * vel[k]
            + (-2 * s3 + 3 * s2) * key_v[k + 1] + (s3 - s2) * hk * vel[k + 1])


def _deg(rng, lo, hi, size=None):
    return np.radians(rng.uniform(lo, hi, size))


# ----------------------------------------------------------------------------- postures
def _free_pose(rng: np.random.Generator, calm: float) -> np.ndarray:
    """A key pose with every non-root angle drawn; ``calm`` in [0, 1] pulls it towards the rest pose."""
    d = rest_dofs()
    lo, hi = _LO[4:], _HI[4:]
    wild = lo + (hi - lo) * rng.random(_D - 4)
    # arms hang and legs stand more often than not: draw each group wild or near its rest value
    near = d[4:] + np.radians(rng.normal(0.0, 12.0, _D - 4))
    pick_wild = rng.random(_D - 4) < (1.0 - calm)
    d[4:] = np.clip(np.where(pick_wild, wild, near), lo, hi)
    # legs of an upright body are refined by the postures; keep hip flexion moderate by default
    for s in "lr":
        d[_I[f"{s}_hip_flex"]] = np.clip(d[_I[f"{s}_hip_flex"]], np.radians(-20), np.radians(60))
        d[_I[f"{s}_knee"]] = min(d[_I[f"{s}_knee"]], np.radians(90))
    d[_I["spine_flex"]] = np.clip(d[_I["spine_flex"]], np.radians(-25), np.radians(45))
    return d


def _set(d: np.ndarray, name: str, value_deg) -> None:
    i = _I[name]
    d[i] = np.clip(np.radians(value_deg), _LO[i], _HI[i])


def _flat_foot(d: np.ndarray, side: str, jitter: float) -> None:
    """Ankle angle that keeps a foot flat on the floor for the current pitch, hip and knee."""
    v = np.degrees(d[_I[f"{side}_hip_flex"]] - d[_I[f"{side}_knee"]] - d[_I["pitch"]]) + jitter
    _set(d, f"{side}_ankle", v)


def _leg(d, s, thigh_world, knee, abd=None, rot=None):
    """Set a leg by its thigh's angle from the vertical in the world (forward > 0), not the pelvis."""
    _set(d, f"{s}_hip_flex", thigh_world + np.degrees(d[_I["pitch"]]))
    _set(d, f"{s}_knee", knee)
    if abd is not None:
        _set(d, f"{s}_hip_abd", abd)
    if rot is not None:
        _set(d, f"{s}_hip_rot", rot)


def _posture(name: str, rng: np.random.Generator, calm: float, info: dict | None = None) -> np.ndarray:
    """A key pose of a named posture (see :data:`POSTURES`): root pitch/roll/twist and limbs.

    ``info``, if given, receives what the draw chose that a caption may name (which knee is
    down, which leg kicks, ...; sides as ``"l"`` / ``"r"``). It takes no random draw.
    """
    u = rng.uniform
    d = _free_pose(rng, calm)
    sides = ("l", "r") if rng.random() < 0.5 else ("r", "l")
    a, b = sides
    info = {} if info is None else info
    info["posture"] = name
    if name == "stand":
        d[_I["pitch"]] = _deg(rng, -8, 12)
        d[_I["roll"]] = _deg(rng, -6, 6)
        for s in "lr":
            _leg(d, s, u(-12, 25), u(0, 30), u(-5, 20))
            _flat_foot(d, s, u(-5, 10))
    elif name == "bend":                           # hinge at the hips, reach to the floor
        d[_I["pitch"]] = _deg(rng, 25, 80)
        _set(d, "spine_flex", u(20, 95))
        for s in "lr":
            _leg(d, s, u(-10, 15), u(0, 40), u(0, 15))
            _flat_foot(d, s, 0.0)
        for s in "lr":
            _set(d, f"{s}_sh_flex", u(40, 90))
    elif name == "squat":
        d[_I["pitch"]] = _deg(rng, 5, 45)
        knee = u(70, 150)
        for s in "lr":
            _leg(d, s, u(0.5, 0.75) * knee, knee + u(-8, 8), u(5, 35), u(10, 40))
            _flat_foot(d, s, u(-5, 15))
    elif name == "lunge":
        info["front"] = a
        d[_I["pitch"]] = _deg(rng, -5, 20)
        _leg(d, a, u(40, 90), u(50, 110), u(0, 15))
        _leg(d, b, u(-35, -10), u(0, 70), u(0, 15))
        for s in "lr":
            _flat_foot(d, s, u(0, 20))
    elif name == "kick":                           # one leg up (front, side or back), the other stands
        d[_I["pitch"]] = _deg(rng, -15, 25)
        _leg(d, a, u(-8, 10), u(0, 25), u(0, 10))
        _flat_foot(d, a, 0.0)
        kind = rng.integers(3)
        info["leg"], info["kick"] = b, ("front", "side", "back")[int(kind)]
        if kind == 0:
            _leg(d, b, u(30, 110), u(0, 130), u(-10, 20))
        elif kind == 1:
            _leg(d, b, u(0, 40), u(0, 60), u(30, 65))
        else:
            _leg(d, b, u(-45, -20), u(0, 100), u(0, 15))
        _set(d, f"{b}_ankle", u(-10, 50))
    elif name == "reach":                          # arms overhead
        d[_I["pitch"]] = _deg(rng, -15, 10)
        for s in "lr":
            _leg(d, s, u(-8, 8), u(0, 15), u(0, 15))
            _flat_foot(d, s, u(0, 30))
            _set(d, f"{s}_sh_abd", u(120, 178))
            _set(d, f"{s}_sh_flex", u(-20, 60))
        _set(d, "spine_flex", u(-35, 10))
    elif name == "kneel":                          # upright kneeling or sitting on the heels
        d[_I["pitch"]] = _deg(rng, -10, 30)
        high = rng.random() < 0.5
        info["high"] = bool(high)
        for s in "lr":
            _leg(d, s, u(-10, 25) if high else u(40, 75), u(80, 110) if high else u(135, 150), u(0, 15))
            _set(d, f"{s}_ankle", u(30, 50))
    elif name == "kneel1":                         # one knee down
        info["knee"], info["front"] = b, a
        d[_I["pitch"]] = _deg(rng, -5, 25)
        _leg(d, a, u(70, 100), u(80, 110), u(0, 15))
        _flat_foot(d, a, 0.0)
        _leg(d, b, u(-15, 10), u(80, 110), u(0, 10))
        _set(d, f"{b}_ankle", u(-20, 10))
    elif name == "sit":                            # sitting on the floor
        d[_I["pitch"]] = _deg(rng, -35, 10)
        for s in "lr":
            _leg(d, s, u(55, 100), u(0, 140), u(0, 45), u(-10, 40))
        info["lean_back"] = bool(rng.random() < 0.5)
        if info["lean_back"]:                      # leaning back on the hands
            for s in "lr":
                _set(d, f"{s}_sh_flex", u(-60, -35))
                _set(d, f"{s}_sh_abd", u(5, 30))
                _set(d, f"{s}_elbow", u(0, 20))
    elif name in ("supine", "prone", "side"):
        d[_I["pitch"]] = _deg(rng, -100, -80)      # on the back; twist turns the body over
        sgn = rng.choice([-1, 1])                  # drawn for every lying posture (the draws stay in step)
        if name == "side":
            info["twist_sign"] = int(sgn)          # +1: twisted +90 deg from the back
        base = {"supine": 0.0, "side": 90.0 * sgn, "prone": 180.0}[name]
        d[_I["twist"]] = np.radians(base + u(-15, 15))
        for s in "lr":
            _set(d, f"{s}_hip_flex", u(-15, 90) if name != "prone" else u(-20, 40))
            _set(d, f"{s}_knee", u(0, 120))
        if name == "prone" and rng.random() < 0.4:  # push-up: arms point down from the chest
            info["arms_under"] = True
            for s in "lr":
                _set(d, f"{s}_sh_flex", u(60, 90))
                _set(d, f"{s}_sh_abd", u(0, 25))
                _set(d, f"{s}_elbow", u(0, 100))
    elif name == "crawl":                          # hands and knees
        d[_I["pitch"]] = _deg(rng, 70, 95)
        for s in "lr":
            _leg(d, s, u(-10, 15), u(80, 110), u(0, 15))
            _set(d, f"{s}_ankle", u(20, 50))
            _set(d, f"{s}_sh_flex", min(90.0, np.degrees(d[_I["pitch"]])) + u(-15, 5))
            _set(d, f"{s}_sh_abd", u(0, 20))
            _set(d, f"{s}_elbow", u(0, 25))
        _set(d, "neck_pitch", u(-55, 0))
    elif name == "allfours":                       # hands and feet, hips high
        d[_I["pitch"]] = _deg(rng, 60, 110)
        for s in "lr":
            _leg(d, s, u(-20, 10), u(0, 60), u(0, 20))
            _set(d, f"{s}_ankle", u(-20, 20))
            _set(d, f"{s}_sh_flex", u(60, 90))
            _set(d, f"{s}_sh_abd", u(0, 90) if d[_I["pitch"]] > np.radians(90) else u(0, 20))
            _set(d, f"{s}_elbow", u(0, 20))
    elif name == "handstand":                      # upside down on the hands, arms overhead
        d[_I["pitch"]] = _deg(rng, 160, 200)
        for s in "lr":
            _set(d, f"{s}_sh_abd", u(155, 178))
            _set(d, f"{s}_sh_flex", u(-10, 25))
            _set(d, f"{s}_elbow", u(0, 25))
            _set(d, f"{s}_hip_flex", u(-25, 60))
            _set(d, f"{s}_hip_abd", u(0, 65))
            _set(d, f"{s}_knee", u(0, 90))
        _set(d, "spine_flex", u(-35, 20))
    elif name == "tuck":                           # knees to the chest (rolls, flips)
        d[_I["pitch"]] = 0.0
        _set(d, "spine_flex", u(50, 95))
        for s in "lr":
            _set(d, f"{s}_hip_flex", u(100, 130))
            _set(d, f"{s}_knee", u(110, 150))
            _set(d, f"{s}_sh_flex", u(40, 90))
            _set(d, f"{s}_elbow", u(60, 140))
    elif name == "star":                           # spread arms and legs (cartwheel)
        d[_I["pitch"]] = _deg(rng, -10, 10)
        for s in "lr":
            _set(d, f"{s}_sh_abd", u(140, 178))
            _set(d, f"{s}_sh_flex", u(-15, 20))
            _set(d, f"{s}_elbow", u(0, 20))
            _set(d, f"{s}_hip_abd", u(25, 65))
            _set(d, f"{s}_hip_flex", u(-10, 25))
            _set(d, f"{s}_knee", u(0, 30))
    else:
        raise ValueError(f"unknown posture {name!r}; allowed: {POSTURES}")
    return d


#: Posture names understood by the key-pose sampler.
POSTURES = ("stand", "bend", "squat", "lunge", "kick", "reach", "kneel", "kneel1", "sit", "supine", "prone",
            "side", "crawl", "allfours", "handstand", "tuck", "star")
# Floor work: which posture may follow which (transitions a body can make in about a second).
_FLOOR_NEXT = {
    "stand": ("squat", "kneel1", "bend", "kneel", "sit"),
    "squat": ("stand", "sit", "kneel", "kneel1", "crawl", "allfours"),
    "kneel1": ("stand", "kneel", "squat"),
    "kneel": ("kneel1", "crawl", "sit", "squat", "prone"),
    "sit": ("supine", "side", "kneel", "squat", "sit"),
    "supine": ("sit", "side", "prone", "supine"),
    "side": ("supine", "prone", "sit", "side"),
    "prone": ("side", "crawl", "supine", "prone", "kneel"),
    "crawl": ("kneel", "prone", "allfours", "crawl", "squat"),
    "allfours": ("crawl", "squat", "stand", "prone"),
    "bend": ("stand", "squat"),
}


def _closest_turn(current: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Shift the target's twist by whole turns to the nearest equivalent of the current twist."""
    t = target.copy()
    i = _I["twist"]
    t[i] += 2 * np.pi * np.round((current[i] - t[i]) / (2 * np.pi))
    return t


# ----------------------------------------------------------------------------- modes
class _Plan:
    """Key poses on a timeline, flights with pushes, and additive overlays."""

    def __init__(self, rng: np.random.Generator, duration: float) -> None:
        self.rng, self.duration = rng, duration
        self.times: list[float] = []
        self.poses: list[np.ndarray] = []
        self.flights: list[tuple[float, float, np.ndarray]] = []   # (t0, t1, push in the heading frame)
        self.events: list[tuple[str, float, float, dict]] = []     # (action, t0, t1, info): what is done when

    def event(self, action: str, t0: float, t1: float, **info) -> None:
        """Record what the body does from ``t0`` to ``t1`` (plan seconds); no random draw."""
        self.events.append((action, float(t0), float(t1), info))

    def key(self, time: float, pose: np.ndarray, spin: tuple[str, ...] = ()) -> float:
        """Add a key pose. Its pitch, roll and twist move by whole turns to the nearest equivalent
        of the previous key's, so a body that has rolled or flipped stays wound up instead of
        spinning back; the angles named in ``spin`` are being turned on purpose and are kept.
        Returns the key's time (moved 0.05 s past the previous key if it was not after it)."""
        pose = np.asarray(pose, dtype=np.float64).copy()
        if self.times and time <= self.times[-1] + 1e-3:
            time = self.times[-1] + 0.05
        if self.poses:
            for name in {"pitch", "roll", "twist"} - set(spin):
                i = _I[name]
                pose[i] += 2 * np.pi * np.round((self.poses[-1][i] - pose[i]) / (2 * np.pi))
        self.times.append(float(time))
        self.poses.append(pose)
        return float(time)

    @property
    def last(self) -> np.ndarray:
        return self.poses[-1]

    def heading_walk(self, pose: np.ndarray, max_turn_deg: float) -> np.ndarray:
        pose = pose.copy()
        pose[_I["heading"]] = self.last[_I["heading"]] + _deg(self.rng, -max_turn_deg, max_turn_deg)
        return pose


def _mode_free(p: _Plan) -> None:
    rng = p.rng
    calm = rng.uniform(0.1, 0.9)
    t = 0.0
    weights = {"stand": 0.4, "bend": 0.12, "squat": 0.1, "lunge": 0.08, "kick": 0.12, "reach": 0.1, "kneel1": 0.04,
               "tuck": 0.04}
    names, w = list(weights), np.array(list(weights.values()))
    p.key(0.0, _posture("stand", rng, calm))
    tempo = rng.uniform(0.5, 1.6)
    postures: list[dict] = [{"posture": "stand"}]
    while t < p.duration:
        t += rng.uniform(0.25, 1.3) * tempo
        name = names[rng.choice(len(names), p=w / w.sum())]
        postures.append({})
        p.key(t, p.heading_walk(_posture(name, rng, calm, postures[-1]), 100.0 if rng.random() < 0.3 else 25.0))
    p.event("free", 0.0, p.times[-1], postures=postures, times=list(p.times))


def _gait_overlay(t: np.ndarray, dofs: np.ndarray, rng: np.random.Generator, record: list | None = None) -> np.ndarray:
    """Legs (and arm swing) of walking / running over ``dofs``; returns the flight mask.

    ``record`` (a list) receives one ``("walk" | "run" | "stand", t0, t1, info)`` per gait key, over
    the clip seconds nearest that key (``info``: ``direction`` in degrees, 0 forwards, +90 to the
    left, 180 backwards; ``amplitude`` of the leg swing in degrees; ``key`` the key's time)."""
    n = len(t)
    dur = t[-1] + 1e-9
    kt = np.linspace(0.0, dur, int(rng.integers(2, 6)))
    run = rng.random(len(kt)) < rng.uniform(0.0, 0.8)               # walk or run per key
    cadence = np.where(run, rng.uniform(1.25, 1.7, len(kt)), rng.uniform(0.75, 1.1, len(kt)))
    amp = np.where(run, rng.uniform(22, 45, len(kt)), rng.uniform(10, 28, len(kt)))
    amp = np.where(rng.random(len(kt)) < 0.15, 0.0, amp)              # stops
    stance = np.where(run, rng.uniform(0.34, 0.45, len(kt)), rng.uniform(0.58, 0.66, len(kt)))
    swing_knee = np.where(run, rng.uniform(80, 125, len(kt)), rng.uniform(45, 65, len(kt)))
    dirs = rng.choice([0.0, 0.0, 0.0, 180.0, 90.0, -90.0, 45.0, -45.0, 135.0, -135.0], len(kt))
    if rng.random() < 0.5:
        dirs[:] = dirs[0]
    if record is not None:
        bounds = np.concatenate([[0.0], 0.5 * (kt[1:] + kt[:-1]), [dur]])
        for k in range(len(kt)):
            gait = "stand" if amp[k] == 0.0 else ("run" if run[k] else "walk")
            record.append((gait, float(bounds[k]), float(bounds[k + 1]),
                           {"direction": float(dirs[k]), "amplitude": float(amp[k]), "key": float(kt[k])}))
    c = smooth_track(t, kt, cadence)
    a = np.radians(smooth_track(t, kt, amp))
    sf = smooth_track(t, kt, stance)
    kn = np.radians(smooth_track(t, kt, swing_knee))
    alpha = np.radians(smooth_track(t, kt, dirs))
    phase = np.cumsum(c) / FPS + rng.random()
    out_stance = np.zeros((n, 2), dtype=bool)
    sweeps = []
    for k, s in enumerate("lr"):
        ph = np.mod(phase + 0.5 * k, 1.0)
        st = ph < sf
        out_stance[:, k] = st
        x_st = ph / sf                                               # 0..1 through stance
        x_sw = (ph - sf) / (1.0 - sf)                                # 0..1 through swing
        # swing: a cubic from back (-1) to front (+1) that leaves and reaches the floor at the stance's
        # sweep rate, so the foot has no speed over the ground at toe-off and touch-down (it keeps
        # moving back a little after toe-off and retracts before landing, as feet do)
        m = -2.0 * (1.0 - sf) / sf                                   # stance rate in swing-phase units
        xs = np.clip(x_sw, 0.0, 1.0)
        hermite = (-1.0 * (2 * xs ** 3 - 3 * xs ** 2 + 1) + (-2 * xs ** 3 + 3 * xs ** 2)
                   + m * (xs ** 3 - 2 * xs ** 2 + xs) + m * (xs ** 3 - xs ** 2))
        sweep = np.where(st, 1.0 - 2.0 * x_st, hermite)               # +1 front .. -1 back
        lift = np.where(st, 0.0, np.sin(np.pi * np.clip(x_sw, 0, 1)) ** 2)   # knee flexion, no jerk at toe-off
        sign = 1.0 if s == "l" else -1.0
        hf = a * sweep * np.cos(alpha)
        dofs[:, _I[f"{s}_hip_flex"]] += hf
        dofs[:, _I[f"{s}_hip_abd"]] += sign * a * sweep * np.sin(alpha) * (a > 0)
        dofs[:, _I[f"{s}_knee"]] += kn * lift * (a > np.radians(2)) + np.where(st, 0.15 * a * np.sin(np.pi * x_st), 0.0)
        knee, hip = dofs[:, _I[f"{s}_knee"]], dofs[:, _I[f"{s}_hip_flex"]]
        toe_off = np.where(st, np.radians(25) * np.clip((x_st - 0.6) / 0.4, 0, 1) ** 2, np.radians(10) * lift)
        dofs[:, _I[f"{s}_ankle"]] = hip - knee - dofs[:, _I["pitch"]] + toe_off
        sweeps.append(sweep)
    if rng.random() < 0.6:                                           # arms swing against the legs
        arm = rng.uniform(0.4, 1.1)
        for k, s in enumerate("lr"):
            dofs[:, _I[f"{s}_sh_flex"]] = np.radians(5) + arm * a * sweeps[1 - k] * np.cos(alpha)
            dofs[:, _I[f"{s}_sh_abd"]] = np.radians(rng.uniform(5, 20))
            dofs[:, _I[f"{s}_elbow"]] = np.where(sf < 0.5, np.radians(rng.uniform(70, 100)), np.radians(rng.uniform(10, 40)))
    dofs[:, _I["pitch"]] += np.radians(12) * (sf < 0.5) * (np.cos(alpha) > 0.5)   # runners lean forwards
    return ~(out_stance[:, 0] | out_stance[:, 1])


def _mode_locomotion(p: _Plan) -> None:
    rng = p.rng
    calm = rng.uniform(0.5, 1.0)
    t = 0.0
    rate = 0.0
    base = _posture("stand", rng, calm)
    for s in "lr":
        base[_I[f"{s}_hip_flex"]] = base[_I[f"{s}_knee"]] = base[_I[f"{s}_hip_abd"]] = 0.0
        base[_I[f"{s}_hip_abd"]] = np.radians(rng.uniform(0, 6))
        base[_I[f"{s}_knee"]] = np.radians(rng.uniform(0, 10))
    base[_I["pitch"]] = np.radians(rng.uniform(-3, 8))
    base[_I["roll"]] = 0.0
    p.key(0.0, base)
    while t < p.duration:
        dt = rng.uniform(0.6, 2.0)
        t += dt
        rate = rng.choice([0.0, rng.uniform(-90, 90), rng.uniform(-200, 200)], p=[0.35, 0.45, 0.2])
        pose = _posture("stand", rng, calm) if rng.random() < 0.3 else base.copy()
        pose[_I["pitch"]] = base[_I["pitch"]]
        pose[_I["roll"]] = 0.0
        for s in "lr":                                   # the gait overlay drives the legs
            for dname in ("hip_flex", "hip_abd", "knee", "hip_rot"):
                pose[_I[f"{s}_{dname}"]] = base[_I[f"{s}_{dname}"]]
        pose[_I["heading"]] = p.last[_I["heading"]] + np.radians(rate) * dt
        p.key(t, pose)
    p.overlay = _gait_overlay


def _jump(p: _Plan, t: float, calm: float, flip: float = 0.0) -> float:
    """Crouch, take off, fly, land, recover from time ``t``; returns the end time.

    Records a ``"jump"`` event (or ``"flip"`` with ``flip``) from the crouch to the recovery."""
    rng, u = p.rng, p.rng.uniform
    t_start = t
    crouch = _posture("squat", rng, calm)
    crouch[_I["pitch"]] = np.radians(u(15, 40))
    knee = u(60, 110)
    for s in "lr":
        _leg(crouch, s, 0.6 * knee, knee)
        _flat_foot(crouch, s, 0.0)
        _set(crouch, f"{s}_sh_flex", u(-60, 0))
    crouch[_I["heading"]] = p.last[_I["heading"]]
    t += u(0.25, 0.6)
    p.key(t, crouch)
    take = _posture("stand", rng, calm)
    take[_I["heading"]] = crouch[_I["heading"]]
    for s in "lr":
        _leg(take, s, u(-10, 5), u(0, 10))
        _set(take, f"{s}_ankle", u(35, 50))
        _set(take, f"{s}_sh_flex", u(30, 90))
        _set(take, f"{s}_sh_abd", u(10, 170))
    t += u(0.12, 0.2)
    p.key(t, take)
    take = p.last                                    # with its pitch wound like the keys before it
    t_fly = u(0.55, 0.8) if flip else u(0.18, 0.6)
    air_kind = rng.integers(4)
    air = _posture("tuck" if (flip or air_kind == 0) else ("star" if air_kind == 1 else "stand"), rng, calm)
    if air_kind == 2 and not flip:                   # split in the air
        _set(air, "l_hip_flex", u(30, 80))
        _set(air, "r_hip_flex", u(-25, 0))
    spin = np.radians(rng.choice([0.0, 0.0, 0.0, 90.0, 180.0, 360.0]) * rng.choice([-1, 1]))
    air[_I["heading"]] = take[_I["heading"]] + 0.5 * spin
    air[_I["pitch"]] = take[_I["pitch"]] + 0.5 * flip
    p.key(t + 0.5 * t_fly, air, spin=("pitch",) if flip else ())
    land = _posture("stand", rng, calm)
    land[_I["heading"]] = take[_I["heading"]] + spin
    land[_I["pitch"]] = take[_I["pitch"]] + flip + np.radians(u(5, 25))
    for s in "lr":
        _leg(land, s, u(5, 30), u(15, 40))
        _set(land, f"{s}_ankle", u(0, 30))
    p.key(t + t_fly, land, spin=("pitch",) if flip else ())
    dist = u(0.0, 1.8) if not flip else u(0.0, 0.5)
    ang = np.radians(rng.choice([0.0, 0.0, 180.0, 90.0, -90.0, 45.0, -45.0]))
    p.flights.append((t, t + t_fly, np.array([np.sin(ang), np.cos(ang)]) * dist / t_fly))
    air_name = "tuck" if (flip or air_kind == 0) else ("star" if air_kind == 1 else ("split" if air_kind == 2 else
                                                                                     "plain"))
    jump_info = {"flight": (float(t), float(t + t_fly)), "air": air_name, "spin": float(np.degrees(spin)),
                 "distance": float(dist), "direction": float(np.degrees(ang)), "flip": float(np.degrees(flip))}
    t += t_fly
    absorb = _posture("squat", rng, calm)
    absorb[_I["heading"]] = land[_I["heading"]]
    absorb[_I["pitch"]] = land[_I["pitch"]] + np.radians(u(0, 25))
    knee = u(50, 100)
    for s in "lr":
        _leg(absorb, s, 0.6 * knee, knee)
        _flat_foot(absorb, s, 0.0)
    t += u(0.15, 0.3)
    p.key(t, absorb)
    rest = _posture("stand", rng, calm)
    rest[_I["heading"]] = absorb[_I["heading"]]
    rest[_I["pitch"]] = absorb[_I["pitch"]] - np.radians(u(15, 45))
    t += u(0.3, 0.7)
    p.key(t, rest)
    p.event("flip" if flip else "jump", t_start, t, **jump_info)
    return t


def _mode_jump(p: _Plan) -> None:
    rng = p.rng
    calm = rng.uniform(0.4, 1.0)
    p.key(0.0, _posture("stand", rng, calm))
    t = rng.uniform(0.0, 0.4)
    while t < p.duration:
        flip = np.radians(rng.choice([-360.0, 360.0])) if rng.random() < 0.15 else 0.0
        t = _jump(p, t, calm, flip)
        t += rng.uniform(0.0, 0.6)


def _crawl_overlay(t: np.ndarray, dofs: np.ndarray, rng: np.random.Generator, record: list | None = None) -> np.ndarray:
    """Alternating diagonal limb swings wherever the body is on hands and knees.

    ``record`` (a list) receives ``("crawl_swing", t0, t1, info)`` per run of frames with swinging
    limbs (``info``: ``weight`` the largest share of the full swing, ``sign`` of the swing)."""
    horizontal = np.clip((np.cos(dofs[:, _I["pitch"]] - np.pi / 2) - 0.85) / 0.15, 0.0, 1.0)
    horizontal *= (dofs[:, _I["l_knee"]] > np.radians(60)) & (np.abs(np.cos(dofs[:, _I["twist"]])) > 0.9)
    if not horizontal.any():
        return np.zeros(len(t), dtype=bool)
    phase = 2 * np.pi * (rng.uniform(0.5, 1.2) * t + rng.random())
    swing, sign = rng.uniform(8, 20), rng.choice([1.0, -1.0])
    amp = np.radians(swing) * horizontal * sign
    if record is not None:
        for i0, i1 in intervals(horizontal > 0):
            record.append(("crawl_swing", float(t[i0]), float(t[i1 - 1]) + 1.0 / FPS,
                           {"weight": float(horizontal[i0:i1].max()), "sign": float(sign), "swing": float(swing)}))
    for k, s in enumerate("lr"):
        ph = phase + np.pi * k
        dofs[:, _I[f"{s}_hip_flex"]] += amp * np.sin(ph)
        dofs[:, _I[f"{s}_knee"]] += 0.5 * np.abs(amp) * np.maximum(np.cos(ph), 0.0)
        dofs[:, _I[f"{s}_sh_flex"]] += amp * np.sin(ph + np.pi)
        dofs[:, _I[f"{s}_elbow"]] += 0.6 * np.abs(amp) * np.maximum(np.cos(ph + np.pi), 0.0)
    return np.zeros(len(t), dtype=bool)


def _mode_floor(p: _Plan) -> None:
    rng = p.rng
    calm = rng.uniform(0.2, 0.9)
    name = rng.choice(list(_FLOOR_NEXT)) if rng.random() < 0.6 else "stand"
    info: dict = {}
    t_prev = p.key(0.0, _posture(str(name), rng, calm, info))
    t = 0.0
    while t < p.duration:
        if rng.random() < 0.55:
            name = rng.choice(_FLOOR_NEXT[str(name)])
        t += rng.uniform(0.6, 1.8)
        nxt: dict = {}
        pose = p.heading_walk(_posture(str(name), rng, calm, nxt), 40.0)
        t_key = p.key(t, _closest_turn(p.last, pose))
        p.event("posture", t_prev, t_key, **{"from": info, "to": nxt})   # the move from one key posture to the next
        info, t_prev = nxt, t_key
    p.overlay = _crawl_overlay


def _mode_acrobatic(p: _Plan) -> None:
    rng, u = p.rng, p.rng.uniform
    calm = rng.uniform(0.3, 0.9)
    first = str(rng.choice(["stand", "squat", "supine", "stand"]))
    p.key(0.0, _posture(first, rng, calm))
    p.event("start", 0.0, 0.0, posture=first)
    t = 0.0
    while t < p.duration:
        kind = rng.choice(["roll", "logroll", "cartwheel", "handstand", "flip"], p=[0.28, 0.14, 0.26, 0.2, 0.12])
        h = p.last[_I["heading"]]
        t_start = t
        if kind == "flip":
            t = _jump(p, t, calm, np.radians(rng.choice([-360.0, 360.0])))
            continue
        if kind == "roll":                              # forward or backward roll through a tuck
            sgn = rng.choice([-1.0, 1.0])
            start = _posture("squat", rng, calm)
            start[_I["heading"]] = h
            t += u(0.3, 0.7)
            p.key(t, start)
            pitch0 = p.last[_I["pitch"]]
            for frac in (0.33, 0.66):
                mid = _posture("tuck", rng, calm)
                mid[_I["heading"]] = h
                mid[_I["pitch"]] = pitch0 + sgn * 2 * np.pi * frac
                t += u(0.25, 0.45)
                p.key(t, mid, spin=("pitch",))
            end = _posture("squat", rng, calm)
            end[_I["heading"]] = h
            end[_I["pitch"]] = pitch0 + sgn * 2 * np.pi
            t += u(0.3, 0.5)
            t = p.key(t, end, spin=("pitch",))
            p.event("roll", t_start, t, sign=float(sgn))               # sign > 0: forwards (pitch tips forwards)
        elif kind == "logroll":                          # lying, turning over about the long axis
            sgn = rng.choice([-1.0, 1.0])
            lie = _posture("supine", rng, 0.8)
            lie[_I["heading"]] = h
            lie = _closest_turn(p.last, lie)
            t += u(0.6, 1.2)
            p.key(t, lie)
            t_lie = t
            twist0 = p.last[_I["twist"]]
            for _ in range(int(rng.integers(2, 5))):
                nxt = _posture("supine", rng, 0.8)
                nxt[_I["heading"]] = h
                nxt[_I["twist"]] = p.last[_I["twist"]] + sgn * np.radians(u(80, 120))
                t += u(0.25, 0.5)
                t = p.key(t, nxt)
            p.event("logroll", t_start, t, sign=float(sgn), lie=float(t_lie),
                    turn=float(np.degrees(p.last[_I["twist"]] - twist0)))
        elif kind == "cartwheel":                        # sideways over the hands: roll 360 in a star
            sgn = rng.choice([-1.0, 1.0])
            roll0 = p.last[_I["roll"]]
            for frac in (0.0, 0.25, 0.5, 0.75, 1.0):
                st = _posture("star", rng, calm)
                st[_I["heading"]] = h
                st[_I["roll"]] = roll0 + sgn * 2 * np.pi * frac
                t += u(0.3, 0.5) if frac == 0.0 else u(0.18, 0.32)
                p.key(t, st, spin=("roll",))
            end = _posture("stand", rng, calm)
            end[_I["heading"]] = h
            end[_I["roll"]] = roll0 + sgn * 2 * np.pi
            t += u(0.3, 0.6)
            t = p.key(t, end, spin=("roll",))
            p.event("cartwheel", t_start, t, sign=float(sgn))          # sign > 0: towards the left (roll leans left)
        else:                                            # kick up to a handstand, hold, come down
            bend = _posture("allfours", rng, calm)
            bend[_I["heading"]] = h
            t += u(0.3, 0.6)
            p.key(t, bend)
            holds = int(rng.integers(1, 4))
            up_t = []
            for _ in range(holds):
                hs = _posture("handstand", rng, calm)
                hs[_I["heading"]] = h
                t += u(0.3, 0.7)
                up_t.append(p.key(t, hs))
            down = _posture("allfours" if rng.random() < 0.5 else "bend", rng, calm)
            down[_I["heading"]] = h
            turns = 2 * np.pi * np.round((p.last[_I["pitch"]] - np.pi) / (2 * np.pi))
            walkover = bool(rng.random() < 0.4)
            if walkover:                                 # walk-over: come down on the other side
                down[_I["pitch"]] = turns + 2 * np.pi - down[_I["pitch"]]
            else:
                down[_I["pitch"]] += turns
            t += u(0.4, 0.8)
            p.key(t, down, spin=("pitch",))
            up = _posture("stand", rng, calm)
            up[_I["heading"]] = h
            t += u(0.4, 0.8)
            t = p.key(t, up)
            p.event("handstand", t_start, t, up=(up_t[0], up_t[-1]), walkover=walkover)


_BUILDERS = {"free": _mode_free, "locomotion": _mode_locomotion, "jump": _mode_jump, "floor": _mode_floor,
             "acrobatic": _mode_acrobatic}


# ----------------------------------------------------------------------------- clips
def _facing_ok(joints: np.ndarray) -> bool:
    """Frame 0 must have a horizontal facing direction (``joints_to_features`` orients by it)."""
    from ...skeleton import get_skeleton

    r_hip, l_hip, sdr_r, sdr_l = get_skeleton("humanml3d").face_joint_indx
    across = (joints[0, r_hip] - joints[0, l_hip]) + (joints[0, sdr_r] - joints[0, sdr_l])
    return bool(np.hypot(across[0], across[2]) > 0.7 * np.linalg.norm(across))


def sample_general(rng: np.random.Generator, config: GeneralConfig | None = None, mode: str | None = None,
                   tries: int = 20) -> GeneralClip:
    """Draw one general motion from ``rng``.

    Parameters
    ----------
    rng : numpy Generator
    config : GeneralConfig, optional
    mode : str, optional
        Force a mode from :data:`MODES` (default: drawn with the config's weights).
    tries : int
        Redraws allowed when frame 0 has no horizontal facing direction (HumanML3D cannot orient it).

    Returns
    -------
    GeneralClip
    """
    config = config or GeneralConfig()
    names = list(config.modes)
    w = np.array([config.modes[m] for m in names], dtype=np.float64)
    if mode is not None and mode not in MODES:
        raise ValueError(f"mode={mode!r}; allowed: {sorted(MODES)}")
    for _ in range(tries):
        m = mode or names[int(rng.choice(len(names), p=w / w.sum()))]
        n = int(rng.integers(config.min_frames, config.max_frames + 1))
        clip = _realise(rng, m, n)
        if _facing_ok(clip.joints):
            return clip
    raise RuntimeError(f"no {mode or 'general'} clip with an orientable first frame after {tries} tries")


def _realise(rng: np.random.Generator, mode: str, n: int) -> GeneralClip:
    t = frame_times(n, FPS)
    # plan a little past both ends and crop a random window, so clips start and end mid-movement
    lead = rng.uniform(0.0, 1.0)
    plan = _Plan(rng, t[-1] + lead + 0.5)
    plan.overlay = None
    _BUILDERS[mode](plan)
    times = np.asarray(plan.times) - lead
    poses = np.stack(plan.poses)
    poses[:, _I["heading"]] += rng.uniform(-np.pi, np.pi)      # a random world heading
    dofs = smooth_track(t, times, poses)
    flight = np.zeros(n, dtype=bool)
    overlay_events: list = []
    if plan.overlay is not None:
        flight |= plan.overlay(t, dofs, rng, overlay_events)
    # overlays add to the tracks: clip them back into the joint ranges, then smooth the kinks away
    dofs = np.clip(dofs, _LO, _HI)
    dofs[:, 4:] = np.clip(smooth(dofs[:, 4:], 0.8), _LO[4:], _HI[4:])
    push = np.zeros((n, 2))
    for t0, t1, v in plan.flights:
        sel = (t >= t0 - lead) & (t < t1 - lead)
        flight |= sel
        if sel.any():
            yaw = dofs[np.flatnonzero(sel)[0], _I["heading"]]
            c, s = np.cos(yaw), np.sin(yaw)
            push[sel] = [c * v[0] + s * v[1], -s * v[0] + c * v[1]]
    rel = forward_kinematics(dofs)
    root = solve_root(rel, flight, push)
    joints = plant_feet(rel + root[:, None, :], flight)
    events = [(a, t0 - lead, t1 - lead, _shift_times(info, -lead)) for a, t0, t1, info in plan.events]
    events += overlay_events                              # already on the clip's clock
    return GeneralClip(joints.astype(np.float64), mode, dofs, flight, _clip_events(events, n))


#: Keys of an event's ``info`` that hold times (seconds on the plan's clock, frames in a GeneralEvent).
_TIME_KEYS = ("flight", "up", "lie", "key", "times")


def _shift_times(info: dict, dt: float) -> dict:
    out = dict(info)
    for k in _TIME_KEYS:
        if k in out:
            v = out[k]
            out[k] = type(v)(x + dt for x in v) if isinstance(v, (tuple, list)) else v + dt
    return out


def _clip_events(events: list, n: int) -> tuple[GeneralEvent, ...]:
    """Events ``(action, t0, t1, info)`` in clip seconds as :class:`GeneralEvent` s in joint frames
    (also the times in ``info``), in time order; events wholly outside the clip are dropped."""
    def frame(x: float) -> int:
        return int(round(x * FPS))

    out = []
    for action, t0, t1, info in events:
        planned = (frame(t0), max(frame(t0), frame(t1)))
        frames = (min(max(planned[0], 0), n), min(max(planned[1], 0), n))
        instant = planned[0] == planned[1]
        if planned[0] >= n or (not instant and (planned[1] < 0 or frames[0] == frames[1])):
            continue                                      # (an instant before the clip is kept at frame 0)
        info = dict(info)
        for k in _TIME_KEYS:
            if k in info:
                v = info[k]
                info[k] = type(v)(frame(x) for x in v) if isinstance(v, (tuple, list)) else frame(v)
        out.append(GeneralEvent(action, frames, planned, info))
    out.sort(key=lambda e: (e.planned[0], e.planned[1]))
    return tuple(out)


def generate_general(seed: int, index: int, config: GeneralConfig | None = None) -> GeneralClip:
    """Motion ``index`` of the general set with ``seed``: a pure function of ``(seed, index, config)``."""
    rng = np.random.default_rng([int(seed), int(index), 0x6E4])
    return sample_general(rng, config)
