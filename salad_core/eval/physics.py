"""Physical plausibility of motions given as joint positions: per-motion measures and their aggregate.

Every function takes joints ``(N, J, 3)`` in metres, +Y up, at the skeleton's frame rate (20 fps for
HumanML3D), as :func:`salad_core.motion.features_to_joints` returns them. Everything is vectorised
numpy; nothing here depends on how the motion was made, so real clips, corpus clips and generated
motions are measured the same way.

Definitions (units in the names of :class:`PhysicsReport`'s fields):

* **Bone length** (cm): the length of every bone ``parent -> joint`` in every frame, against
  (a) the skeleton's reference lengths (``Skeleton.bone_lengths``, the HumanML3D target skeleton) and
  (b) the motion's own median length of that bone over its frames, so a motion made for another body
  size is not charged for its size, only for its bones changing length. p95 and max over all
  frames x bones.
* **Foot contact**: a foot joint (ankle, toe of each foot, ``Skeleton.contact_joints``) touches the
  ground in a frame when its height above the clip's *contact level* (the lowest height any foot joint
  reaches in the clip) is below ``PhysicsConfig.contact_heights`` (ankle, toe; the procedural
  corpus's thresholds) and, if ``contact_max_vspeed`` is set, its vertical speed is below that.
  The contact level is the clip's own, not ``y = 0``, so that a figure hovering over or sunk
  into the floor is still checked for sliding (its floating / penetration is measured apart).
* **Foot skating** (m/s), after PhysDiff (Yuan et al., ICCV 2023, "Skate"): the horizontal speed of a
  foot joint between two consecutive frames in which it is in contact in both; mean and p95 over
  those joint-transitions, and the share of them faster than ``skate_threshold`` (10 cm/s).
* **Floor**: ``y = floor`` (0 by default). HumanML3D's processing (and the corpus's) shifts each clip
  so that its lowest joint over all frames is at 0, so 0 is the floor real motions stand on; a
  generator trained on such clips should keep to it.
* **Ground penetration** (cm), after PhysDiff's "Penetrate": per frame, how far the lowest joint
  (any joint: hips below the floor count) is below the floor; max and mean over frames.
* **Floating** (cm), after PhysDiff's "Float": per frame, the height of the lowest foot joint above
  the floor (less a 5 mm tolerance, clipped at 0); mean over frames, and the minimum over the clip
  (above 0: the feet never reach the floor).
* **Jitter** (m/s^3): mean over frames and joints of the norm of the third finite difference of
  the positions times fps^3. **Acceleration** (m/s^2): the same with the second difference.
* **Hyper-extension** (degrees): the knee's flexion angle (between thigh and shin, 0 = straight)
  when it bends the wrong way, i.e. the shin turns forward of the thigh about the hips' left axis.
  The elbow: with joint positions alone the upper arm's twist is unknown, so the direction an elbow
  may bend in is only determined while the upper arm hangs (within ``elbow_hang_deg`` of the
  trunk's down axis): then a forearm bending backwards (more than 120 degrees away from the trunk's
  forward axis) would need about 120 degrees or more of humeral rotation away from the neutral
  (forward) bend, more than a shoulder's 70-90, so its flexion angle counts as hyper-extension. Max over frames and sides, and the share of frames above ``hyper_threshold_deg``.
* **Pelvis**: its height range (cm); the jump rise (m): its apex above the standing height (the
  90th percentile of its height in frames where both feet touch the ground); the feet clearance
  (m): the highest the lowest foot joint gets above the contact level.
* **Flight** (both feet off the ground: no foot joint in contact): the number of flight frames, the
  longest flight (s) and the pelvis's vertical acceleration (m/s^2, second difference at frames
  whose neighbours are in flight too), which ballistic flight keeps near -9.81. The pelvis is not
  the centre of mass, so tucking the legs in flight moves it by a little. The ground is taken to
  be flat: a foot standing on a raised step counts as off the ground (corpus stair clips show
  "flights" of 1.5-2.7 s for that reason).
* **Stride** (m): how far a foot travels through the air between two ground contacts: the
  horizontal distance of its ankle from lift-off (the last frame of a run of at least
  ``min_contact_frames`` contact frames of the ankle or toe) to the next touch-down (the first
  frame of the next run), for swings of at most ``max_swing_s`` (a step, not a float); median over
  the motion, 0 when no foot steps. A figure that glides (feet sliding while in contact) or floats
  (feet off the ground for seconds) has short or no strides however far it travels.
* **Seed diversity** (cm): mean joint distance between motions of the same prompt made from
  different seeds (:func:`seed_diversity`).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Iterable, Mapping, Sequence

import numpy as np

from ..skeleton import Skeleton, get_skeleton

__all__ = [
    "PhysicsConfig", "PhysicsReport", "measure_motion", "aggregate_reports", "AGGREGATION",
    "bone_length_errors", "contact_level", "foot_contacts", "foot_skating", "strides", "pooled_bone_p95",
    "ground_penetration", "floating", "jitter", "acceleration", "flexion_angles", "hyperextension",
    "standing_height", "flight_frames", "flight_acceleration", "heading_yaw", "root_travel", "limb_activity",
    "seed_diversity", "GRAVITY", "report_table", "joints_reader",
]

#: Standard gravity (m/s^2), what the pelvis's acceleration in flight should be near (negative: down).
GRAVITY = 9.80665


@dataclass(frozen=True)
class PhysicsConfig:
    """Thresholds of the measures (see the module docstring for the definitions)."""

    fps: float | None = None                          # frames per second (None: the skeleton's)
    floor: float = 0.0                                # floor height (m)
    contact_heights: tuple[float, float] = (0.08, 0.035)  # ankle, toe height (m) above the contact level
    contact_max_vspeed: float | None = None           # optional vertical-speed bound (m/s) for contact
    skate_threshold: float = 0.10                     # foot speed (m/s) above which a contact skates
    float_tolerance: float = 0.005                    # height (m) of the lowest foot not counted as floating
    hyper_threshold_deg: float = 5.0                  # hyper-extension (deg) counted in the share of frames
    elbow_hang_deg: float = 45.0                      # upper arm within this of the trunk's down axis
    min_contact_frames: int = 2                       # shortest run of contact that counts as a footfall
    max_swing_s: float = 1.0                          # longest time (s) a foot may be off the ground in a step

    def __post_init__(self) -> None:
        if self.fps is not None and not (isinstance(self.fps, (int, float)) and self.fps > 0):
            raise ValueError(f"fps must be a positive number or None, got {self.fps!r}")
        if len(self.contact_heights) != 2 or any(not (h > 0) for h in self.contact_heights):
            raise ValueError(f"contact_heights must be two positive heights (ankle, toe) in metres, "
                             f"got {self.contact_heights!r}")
        if self.contact_max_vspeed is not None and not self.contact_max_vspeed > 0:
            raise ValueError(f"contact_max_vspeed must be positive or None, got {self.contact_max_vspeed!r}")
        for name in ("skate_threshold", "float_tolerance", "hyper_threshold_deg"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if isinstance(self.min_contact_frames, bool) or not isinstance(self.min_contact_frames, int) \
                or self.min_contact_frames < 1:
            raise ValueError(f"min_contact_frames must be a positive int, got {self.min_contact_frames!r}")
        if not self.max_swing_s > 0:
            raise ValueError(f"max_swing_s must be positive (seconds), got {self.max_swing_s!r}")
        if not 0 < self.elbow_hang_deg < 90:
            raise ValueError(f"elbow_hang_deg must be in (0, 90) degrees, got {self.elbow_hang_deg!r}")


@dataclass(frozen=True)
class PhysicsReport:
    """The measures of one motion; units are in the field names (cm, m, m/s, m/s^2, m/s^3, deg, s).

    ``nan`` marks a measure the motion has nothing to measure on (no contact, no flight frame, a
    skeleton without reference bone lengths).
    """

    frames: int                  # N
    bone_ref_p95_cm: float       # |length - reference length|, p95 over frames x bones
    bone_ref_max_cm: float       # the same, max
    bone_self_p95_cm: float      # |length - the motion's median length of that bone|, p95
    bone_self_max_cm: float      # the same, max
    skate_mean_ms: float         # mean horizontal foot speed in contact
    skate_p95_ms: float          # its p95
    skate_share: float           # share of contact transitions faster than skate_threshold
    contact_count: int           # contact transitions (foot joint x frame pair) measured
    penetration_max_cm: float    # deepest joint below the floor
    penetration_mean_cm: float   # mean over frames of the lowest joint's depth below the floor
    float_mean_cm: float         # mean over frames of the lowest foot joint above the floor
    float_min_cm: float          # lowest the feet get over the clip (> 0: never on the floor)
    jitter_ms3: float            # mean norm of the third difference
    accel_ms2: float             # mean norm of the second difference
    knee_hyper_max_deg: float    # largest knee hyper-extension
    knee_hyper_share: float      # share of frames with a knee hyper-extended past the threshold
    elbow_hyper_max_deg: float   # largest elbow hyper-extension (hanging upper arm only)
    elbow_hyper_share: float     # share of frames with an elbow hyper-extended past the threshold
    pelvis_range_cm: float       # max - min pelvis height
    jump_rise_m: float           # pelvis apex above standing height
    feet_clearance_m: float      # highest the lowest foot joint gets above the contact level
    flight_frames: int           # frames with both feet off the ground
    longest_flight_s: float      # longest run of flight frames
    flight_accel_ms2: float      # mean pelvis vertical acceleration inside flight (nan: none)
    flight_accel_count: int      # frames that mean is over
    stride_m: float              # median lift-off to touch-down distance of a foot (0: no step)

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


# ------------------------------------------------------------------------------------ helpers
def _prepare(joints, skeleton) -> tuple[np.ndarray, Skeleton]:
    sk = get_skeleton(skeleton)
    x = np.asarray(joints, dtype=np.float64)
    if x.ndim != 3 or x.shape[1:] != (sk.num_joints, 3):
        raise ValueError(f"joints must have shape (N, {sk.num_joints}, 3) for skeleton {sk.name!r}, "
                         f"got shape {x.shape}")
    if x.shape[0] < 4:
        raise ValueError(f"joints has {x.shape[0]} frames; the measures need at least 4")
    if not np.isfinite(x).all():
        raise ValueError("joints contain NaN or infinite values")
    return x, sk


def _fps(sk: Skeleton, config: PhysicsConfig) -> float:
    return float(config.fps if config.fps is not None else sk.fps)


def _idx(sk: Skeleton, name: str) -> int:
    try:
        return sk.joint_names.index(name)
    except ValueError:
        raise ValueError(f"skeleton {sk.name!r} has no joint {name!r}; this measure needs the HumanML3D "
                         "joint names") from None


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


def _angle_deg(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    cos = (_unit(u) * _unit(v)).sum(-1)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _hips_left(x: np.ndarray, sk: Skeleton) -> np.ndarray:
    """``(N, 3)`` horizontal unit vector from the right hip to the left hip (the body's left)."""
    across = x[:, _idx(sk, "left_hip")] - x[:, _idx(sk, "right_hip")]
    across = across * np.array([1.0, 0.0, 1.0])
    return _unit(across)


def _chest_frames(x: np.ndarray, sk: Skeleton) -> np.ndarray:
    """``(N, 3, 3)`` rows (left, up, forward) of the trunk: left from the right to the left collar,
    up from spine3 to the neck (made orthogonal to left)."""
    left = _unit(x[:, _idx(sk, "left_collar")] - x[:, _idx(sk, "right_collar")])
    up = x[:, _idx(sk, "neck")] - x[:, _idx(sk, "spine3")]
    fwd = _unit(np.cross(left, up))
    up = np.cross(fwd, left)
    return np.stack([left, up, fwd], 1)


def _runs(mask: np.ndarray) -> np.ndarray:
    """Lengths of the runs of True in a 1-D boolean array."""
    m = np.concatenate([[False], mask.astype(bool), [False]])
    edges = np.flatnonzero(m[1:] != m[:-1])
    return edges[1::2] - edges[::2]


# ------------------------------------------------------------------------------------ measures
def bone_length_errors(joints, skeleton: str | Skeleton = "humanml3d") -> dict[str, np.ndarray]:
    """Per-frame bone lengths and their errors.

    Returns
    -------
    dict with ``lengths`` ``(N, J-1)`` (m, bone ``parents[j] -> j`` for j >= 1), ``self_error``
    ``(N, J-1)`` = |length - the bone's median length over the motion| (m) and ``ref_error``
    ``(N, J-1)`` = |length - ``skeleton.bone_lengths``| (m; absent for a skeleton without reference
    lengths, e.g. KIT).
    """
    x, sk = _prepare(joints, skeleton)
    par = np.asarray(sk.parents[1:])
    lengths = np.linalg.norm(x[:, 1:] - x[:, par], axis=-1)
    out = {"lengths": lengths, "self_error": np.abs(lengths - np.median(lengths, axis=0))}
    if sk.bone_lengths is not None:
        out["ref_error"] = np.abs(lengths - np.asarray(sk.bone_lengths[1:]))
    return out


def contact_level(joints, skeleton: str | Skeleton = "humanml3d") -> float:
    """The clip's contact level (m): the lowest height any foot joint reaches."""
    x, sk = _prepare(joints, skeleton)
    return float(x[:, list(sk.contact_joints), 1].min())


def foot_contacts(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
                  ) -> np.ndarray:
    """``(N, 4)`` bool: foot joint (``skeleton.contact_joints`` order: left ankle, left toe, right
    ankle, right toe) in contact with the ground in each frame (see the module docstring)."""
    x, sk = _prepare(joints, skeleton)
    cj = list(sk.contact_joints)
    h = x[:, cj, 1] - x[:, cj, 1].min()
    limit = np.asarray(config.contact_heights * 2)                   # ankle, toe, ankle, toe
    on = h < limit
    if config.contact_max_vspeed is not None:
        vy = np.abs(np.gradient(x[:, cj, 1], axis=0)) * _fps(sk, config)
        on &= vy < config.contact_max_vspeed
    return on


def foot_skating(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
                 ) -> np.ndarray:
    """Horizontal speeds (m/s) of the foot joints over the frame pairs in which they are in contact
    at both ends: a 1-D array (empty when the feet never touch the ground)."""
    x, sk = _prepare(joints, skeleton)
    on = foot_contacts(x, sk, config)
    both = on[1:] & on[:-1]                                           # (N-1, 4)
    feet = x[:, list(sk.contact_joints)][..., [0, 2]]                 # (N, 4, 2)
    speed = np.linalg.norm(np.diff(feet, axis=0), axis=-1) * _fps(sk, config)
    return speed[both]


def strides(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
            ) -> np.ndarray:
    """Distances (m, on the ground plane) an ankle travels from lift-off to the next touch-down of
    the same foot within ``config.max_swing_s``, both feet together: a 1-D array, empty when no
    foot steps."""
    x, sk = _prepare(joints, skeleton)
    on = foot_contacts(x, sk, config)
    cj = sk.contact_joints
    out = []
    for foot in (0, 2):                                               # (ankle, toe) columns of each foot
        c = np.concatenate([[False], on[:, foot] | on[:, foot + 1], [False]])
        edges = np.flatnonzero(c[1:] != c[:-1])
        runs = [(a, b) for a, b in zip(edges[::2], edges[1::2]) if b - a >= config.min_contact_frames]
        if len(runs) < 2:
            continue
        lift = np.array([b - 1 for _, b in runs[:-1]])                # last contact frame of each run
        land = np.array([a for a, _ in runs[1:]])                     # first frame of the next run
        step = (land - lift) <= config.max_swing_s * _fps(sk, config)
        ankle = x[:, cj[foot]][:, [0, 2]]
        out.append(np.linalg.norm(ankle[land[step]] - ankle[lift[step]], axis=-1))
    return np.concatenate(out) if out else np.zeros(0)


def pooled_bone_p95(motions: Sequence[np.ndarray], skeleton: str | Skeleton = "humanml3d") -> float:
    """p95 (cm) of the reference bone-length error over all frames x bones of all ``motions`` together
    (the figure the issue's target "bone-length error p95 <= 3 cm over the benchmark" asks for)."""
    errs = [bone_length_errors(m, skeleton).get("ref_error") for m in motions]
    errs = [e.ravel() for e in errs if e is not None]
    return float(np.percentile(np.concatenate(errs), 95) * 100.0) if errs else float("nan")


def ground_penetration(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
                       ) -> np.ndarray:
    """``(N,)`` depth (m, >= 0) of the lowest joint below the floor in each frame."""
    x, _ = _prepare(joints, skeleton)
    return np.maximum(config.floor - x[..., 1].min(-1), 0.0)


def floating(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
             ) -> np.ndarray:
    """``(N,)`` height (m, >= 0) of the lowest foot joint above the floor less the tolerance."""
    x, sk = _prepare(joints, skeleton)
    low = x[:, list(sk.contact_joints), 1].min(-1) - config.floor
    return np.maximum(low - config.float_tolerance, 0.0)


def jitter(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()) -> float:
    """Mean norm (m/s^3) of the third finite difference of all joints, times fps^3."""
    x, sk = _prepare(joints, skeleton)
    fps = _fps(sk, config)
    return float(np.linalg.norm(np.diff(x, n=3, axis=0), axis=-1).mean() * fps ** 3)


def acceleration(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()) -> float:
    """Mean norm (m/s^2) of the second finite difference of all joints, times fps^2."""
    x, sk = _prepare(joints, skeleton)
    fps = _fps(sk, config)
    return float(np.linalg.norm(np.diff(x, n=2, axis=0), axis=-1).mean() * fps ** 2)


def flexion_angles(joints, skeleton: str | Skeleton = "humanml3d", hang_deg: float = 45.0) -> dict[str, np.ndarray]:
    """Knee and elbow flexion (deg, 0 = straight) and the sense of each bend, per side.

    Returns
    -------
    dict of ``(N, 2)`` arrays (left, right): ``knee``, ``elbow`` (flexion angles);
    ``knee_wrong`` (bool: the shin turns forward of the thigh about the hips' left axis);
    ``elbow_wrong`` (bool: the upper arm hangs, i.e. is within ``hang_deg`` of the trunk's down
    axis, and the forearm bends backwards, see the module docstring; False wherever the direction
    is not determined).
    """
    x, sk = _prepare(joints, skeleton)
    left = _hips_left(x, sk)
    chest = _chest_frames(x, sk)
    out: dict[str, list] = {"knee": [], "elbow": [], "knee_wrong": [], "elbow_wrong": []}
    for side in ("left", "right"):
        hip, knee, ankle = (x[:, _idx(sk, f"{side}_{n}")] for n in ("hip", "knee", "ankle"))
        thigh, shin = knee - hip, ankle - knee
        out["knee"].append(_angle_deg(thigh, shin))
        # flexion turns the shin backwards about the body's left axis: (thigh x shin) . left > 0
        out["knee_wrong"].append((np.cross(thigh, shin) * left).sum(-1) < 0)
        sho, elb, wri = (x[:, _idx(sk, f"{side}_{n}")] for n in ("shoulder", "elbow", "wrist"))
        upper, fore = _unit(elb - sho), wri - elb
        out["elbow"].append(_angle_deg(upper, fore))
        hangs = (upper * -chest[:, 1]).sum(-1) > math.cos(math.radians(hang_deg))
        bend = _unit(fore - (fore * upper).sum(-1, keepdims=True) * upper)
        backward = (bend * chest[:, 2]).sum(-1) < -0.5                 # > 120 deg from forward
        out["elbow_wrong"].append(hangs & backward)
    return {k: np.stack(v, 1) for k, v in out.items()}


def hyperextension(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
                   ) -> dict[str, np.ndarray]:
    """``knee`` and ``elbow``: ``(N, 2)`` hyper-extension angles (deg, 0 where the joint bends the
    right way or its direction is not determined)."""
    a = flexion_angles(joints, skeleton, config.elbow_hang_deg)
    return {"knee": np.where(a["knee_wrong"], a["knee"], 0.0),
            "elbow": np.where(a["elbow_wrong"], a["elbow"], 0.0)}


def standing_height(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
                    ) -> float:
    """Pelvis standing height (m): the 90th percentile of its height over the frames in which both
    feet touch the ground (frame 0's height when there is no such frame)."""
    x, sk = _prepare(joints, skeleton)
    on = foot_contacts(x, sk, config)
    both = (on[:, 0] | on[:, 1]) & (on[:, 2] | on[:, 3])
    y = x[:, 0, 1]
    return float(np.percentile(y[both], 90)) if both.any() else float(y[0])


def flight_frames(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
                  ) -> np.ndarray:
    """``(N,)`` bool: no foot joint in contact (both feet off the ground)."""
    return ~foot_contacts(joints, skeleton, config).any(-1)


def flight_acceleration(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
                        ) -> np.ndarray:
    """Pelvis vertical accelerations (m/s^2) at the flight frames whose two neighbours are in flight
    too (central second difference): a 1-D array, empty without such frames."""
    x, sk = _prepare(joints, skeleton)
    fl = flight_frames(x, sk, config)
    inner = fl[1:-1] & fl[:-2] & fl[2:]
    acc = np.diff(x[:, 0, 1], n=2) * _fps(sk, config) ** 2
    return acc[inner]


def heading_yaw(joints, skeleton: str | Skeleton = "humanml3d") -> np.ndarray:
    """``(N,)`` unwrapped heading angle (rad) of the hips about +Y; positive = turned to the left
    (counter-clockwise seen from above), 0 = facing +Z."""
    x, sk = _prepare(joints, skeleton)
    left = _hips_left(x, sk)
    fwd = np.cross(left, np.array([0.0, 1.0, 0.0]))
    return np.unwrap(np.arctan2(fwd[:, 0], fwd[:, 2]))


def root_travel(joints, skeleton: str | Skeleton = "humanml3d") -> dict[str, float]:
    """How far the pelvis goes on the ground plane.

    Returns
    -------
    dict: ``displacement`` (m, start to end), ``path`` (m, summed per-frame steps), and
    ``forward`` / ``left`` (m): the displacement in the frame-0 heading (forward, to the left).
    """
    x, sk = _prepare(joints, skeleton)
    p = x[:, 0, [0, 2]]
    d = p[-1] - p[0]
    yaw0 = heading_yaw(x, sk)[0]
    fwd = np.array([math.sin(yaw0), math.cos(yaw0)])                  # (x, z) of the frame-0 heading
    left = np.array([math.cos(yaw0), -math.sin(yaw0)])
    return {"displacement": float(np.linalg.norm(d)), "path": float(np.linalg.norm(np.diff(p, axis=0), axis=-1).sum()),
            "forward": float(d @ fwd), "left": float(d @ left)}


def limb_activity(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
                  ) -> dict[str, float]:
    """Mean speed (m/s) of each limb's end relative to the body, so that travelling does not count.

    Arms: the wrist relative to spine3 in the trunk frame (bending the trunk does not count);
    legs: the ankle relative to the pelvis in the hips' heading frame; head: the head joint relative
    to the neck in the trunk frame. Keys ``left_arm``, ``right_arm``, ``left_leg``, ``right_leg``,
    ``head``.
    """
    x, sk = _prepare(joints, skeleton)
    fps = _fps(sk, config)
    chest = _chest_frames(x, sk)
    left = _hips_left(x, sk)
    up = np.broadcast_to(np.array([0.0, 1.0, 0.0]), left.shape)
    hips = np.stack([left, up, np.cross(left, up)], 1)

    def speed(j: str, anchor: str, frames: np.ndarray) -> float:
        rel = x[:, _idx(sk, j)] - x[:, _idx(sk, anchor)]
        local = np.einsum("nij,nj->ni", frames, rel)
        return float(np.linalg.norm(np.diff(local, axis=0), axis=-1).mean() * fps)

    return {"left_arm": speed("left_wrist", "spine3", chest), "right_arm": speed("right_wrist", "spine3", chest),
            "left_leg": speed("left_ankle", "pelvis", hips), "right_leg": speed("right_ankle", "pelvis", hips),
            "head": speed("head", "neck", chest)}


def seed_diversity(motions: Sequence[np.ndarray]) -> float:
    """Mean joint distance (cm) between motions of one prompt made with different seeds.

    Parameters
    ----------
    motions : sequence of ``(N_i, J, 3)`` arrays (at least 2), compared over their common first
        ``min(N_i)`` frames in world coordinates.

    Returns
    -------
    float: mean over the pairs of the mean over frames and joints of the Euclidean distance, in cm
    (0 for identical motions).
    """
    if len(motions) < 2:
        raise ValueError(f"seed_diversity needs at least 2 motions, got {len(motions)}")
    arrays = [np.asarray(m, dtype=np.float64) for m in motions]
    shapes = {a.shape[1:] for a in arrays}
    if len(shapes) != 1 or any(a.ndim != 3 or a.shape[-1] != 3 for a in arrays):
        raise ValueError(f"motions must all be (N, J, 3) with the same J, got shapes {[a.shape for a in arrays]}")
    n = min(a.shape[0] for a in arrays)
    x = np.stack([a[:n] for a in arrays])                             # (M, n, J, 3)
    i, j = np.triu_indices(len(arrays), k=1)
    return float(np.linalg.norm(x[i] - x[j], axis=-1).mean() * 100.0)


# ------------------------------------------------------------------------------------ one motion
def _stat(v: np.ndarray, fn, scale: float = 1.0) -> float:
    return float(fn(v) * scale) if v.size else float("nan")


def measure_motion(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
                   ) -> PhysicsReport:
    """Every per-motion measure of one motion ``(N, J, 3)`` (metres, +Y up); see the module docstring."""
    x, sk = _prepare(joints, skeleton)
    fps = _fps(sk, config)
    bones = bone_length_errors(x, sk)
    ref = bones.get("ref_error", np.zeros(0))
    skate = foot_skating(x, sk, config)
    pen = ground_penetration(x, sk, config)
    flo = floating(x, sk, config)
    hyper = hyperextension(x, sk, config)
    thr = config.hyper_threshold_deg
    on = foot_contacts(x, sk, config)
    fl = ~on.any(-1)
    facc = flight_acceleration(x, sk, config)
    feet_low = x[:, list(sk.contact_joints), 1].min(-1) - x[:, list(sk.contact_joints), 1].min()
    pelvis = x[:, 0, 1]
    runs = _runs(fl)
    steps = strides(x, sk, config)
    return PhysicsReport(
        frames=int(x.shape[0]),
        bone_ref_p95_cm=_stat(ref, lambda v: np.percentile(v, 95), 100.0),
        bone_ref_max_cm=_stat(ref, np.max, 100.0),
        bone_self_p95_cm=float(np.percentile(bones["self_error"], 95) * 100.0),
        bone_self_max_cm=float(bones["self_error"].max() * 100.0),
        skate_mean_ms=_stat(skate, np.mean),
        skate_p95_ms=_stat(skate, lambda v: np.percentile(v, 95)),
        skate_share=_stat(skate, lambda v: (v > config.skate_threshold).mean()),
        contact_count=int(skate.size),
        penetration_max_cm=float(pen.max() * 100.0),
        penetration_mean_cm=float(pen.mean() * 100.0),
        float_mean_cm=float(flo.mean() * 100.0),
        float_min_cm=float(flo.min() * 100.0),
        jitter_ms3=jitter(x, sk, config),
        accel_ms2=acceleration(x, sk, config),
        knee_hyper_max_deg=float(hyper["knee"].max()),
        knee_hyper_share=float((hyper["knee"] > thr).any(-1).mean()),
        elbow_hyper_max_deg=float(hyper["elbow"].max()),
        elbow_hyper_share=float((hyper["elbow"] > thr).any(-1).mean()),
        pelvis_range_cm=float((pelvis.max() - pelvis.min()) * 100.0),
        jump_rise_m=float(pelvis.max() - standing_height(x, sk, config)),
        feet_clearance_m=float(feet_low.max()),
        flight_frames=int(fl.sum()),
        longest_flight_s=float(runs.max() / fps) if runs.size else 0.0,
        flight_accel_ms2=_stat(facc, np.mean),
        flight_accel_count=int(facc.size),
        stride_m=float(np.median(steps)) if steps.size else 0.0,
    )


# ------------------------------------------------------------------------------------ aggregate
#: How each field of :class:`PhysicsReport` is aggregated over motions: "mean" (of the per-motion
#: values, nan ignored), "max", "sum", or "pooled:<count field>" (mean weighted by that count,
#: i.e. the measure over all the motions' contact / flight frames together).
AGGREGATION: dict[str, str] = {
    "frames": "sum", "bone_ref_p95_cm": "mean", "bone_ref_max_cm": "max", "bone_self_p95_cm": "mean",
    "bone_self_max_cm": "max", "skate_mean_ms": "pooled:contact_count", "skate_p95_ms": "mean",
    "skate_share": "pooled:contact_count", "contact_count": "sum", "penetration_max_cm": "max",
    "penetration_mean_cm": "mean", "float_mean_cm": "mean", "float_min_cm": "mean", "jitter_ms3": "mean",
    "accel_ms2": "mean", "knee_hyper_max_deg": "max", "knee_hyper_share": "mean", "elbow_hyper_max_deg": "max",
    "elbow_hyper_share": "mean", "pelvis_range_cm": "mean", "jump_rise_m": "mean", "feet_clearance_m": "mean",
    "flight_frames": "sum", "longest_flight_s": "max", "flight_accel_ms2": "pooled:flight_accel_count",
    "flight_accel_count": "sum", "stride_m": "mean",
}
assert set(AGGREGATION) == {f.name for f in fields(PhysicsReport)}, "AGGREGATION must cover PhysicsReport"


def aggregate_reports(reports: Iterable[PhysicsReport | Mapping[str, float]]) -> dict[str, float]:
    """Aggregate per-motion reports over many motions (rule per field in :data:`AGGREGATION`).

    Returns a dict with every field of :class:`PhysicsReport` plus ``motions`` (how many) and
    ``<field>_median`` for the "mean" fields (robust to one wild motion).
    """
    rows = [r.as_dict() if isinstance(r, PhysicsReport) else dict(r) for r in reports]
    if not rows:
        raise ValueError("aggregate_reports needs at least one report")
    out: dict[str, float] = {"motions": len(rows)}
    for name, rule in AGGREGATION.items():
        v = np.array([float(r[name]) for r in rows])
        ok = v[np.isfinite(v)]
        if rule == "sum":
            out[name] = float(ok.sum())
        elif rule == "max":
            out[name] = float(ok.max()) if ok.size else float("nan")
        elif rule == "mean":
            out[name] = float(ok.mean()) if ok.size else float("nan")
            out[name + "_median"] = float(np.median(ok)) if ok.size else float("nan")
        else:
            w = np.array([float(r[rule.split(":", 1)[1]]) for r in rows])
            keep = np.isfinite(v) & (w > 0)
            out[name] = float((v[keep] * w[keep]).sum() / w[keep].sum()) if keep.any() else float("nan")
    return out


#: Columns of :func:`report_table`: (aggregate key, header, format).
TABLE_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("motions", "motions", "{:.0f}"),
    ("bone_ref_p95_pooled_cm", "bone err p95 pooled (cm)", "{:.1f}"),
    ("bone_ref_p95_cm", "bone err p95 mean (cm)", "{:.1f}"),
    ("bone_ref_max_cm", "bone err max (cm)", "{:.1f}"),
    ("bone_self_p95_cm", "bone drift p95 (cm)", "{:.1f}"),
    ("skate_mean_ms", "skate (m/s)", "{:.3f}"),
    ("skate_share", "skate > 10 cm/s", "{:.2f}"),
    ("penetration_max_cm", "penetration max (cm)", "{:.1f}"),
    ("float_mean_cm", "float mean (cm)", "{:.1f}"),
    ("jitter_ms3", "jitter (m/s^3)", "{:.1f}"),
    ("accel_ms2", "accel (m/s^2)", "{:.2f}"),
    ("knee_hyper_max_deg", "knee hyper max (deg)", "{:.0f}"),
    ("knee_hyper_share", "knee hyper frames", "{:.3f}"),
    ("elbow_hyper_max_deg", "elbow hyper max (deg)", "{:.0f}"),
    ("pelvis_range_cm", "pelvis range (cm)", "{:.1f}"),
    ("jump_rise_m", "jump rise (m)", "{:.2f}"),
    ("flight_accel_ms2", "flight accel (m/s^2)", "{:.1f}"),
    ("longest_flight_s", "longest flight (s)", "{:.2f}"),
    ("seed_diversity_cm", "seed diversity (cm)", "{:.1f}"),
)


def report_table(rows: Mapping[str, Mapping[str, float]], columns=TABLE_COLUMNS) -> str:
    """A Markdown table with one row per name of ``rows`` (aggregates from :func:`aggregate_reports`,
    optionally with ``seed_diversity_cm`` and ``bone_ref_p95_pooled_cm`` from :func:`pooled_bone_p95`);
    missing or nan values print as ``-``."""
    head = "| | " + " | ".join(h for _, h, _ in columns) + " |"
    sep = "|---|" + "---:|" * len(columns)
    lines = [head, sep]
    for name, agg in rows.items():
        cells = []
        for key, _, fmt in columns:
            v = agg.get(key)
            cells.append("-" if v is None or not np.isfinite(v) else fmt.format(v))
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def joints_reader(method: str, skeleton: str | Skeleton = "humanml3d"):
    """``output -> list of joints`` (``(N_b, J, 3)`` metres each): which joints of a generator's output
    the benchmark measures (``salad eval --physics --recovery METHOD``).

    ``method``: ``'positions'`` reads the raw position features (the model's own output);
    ``'fk'`` / ``'fit'``: :func:`salad_core.recovery.recover_joints`; ``'pipeline'``: ``out.joints``.
    The output needs ``features`` ``(B, N, D)`` and ``lengths`` (and ``joints`` for 'pipeline').
    """
    if method == "pipeline":
        return lambda out: list(out.joints)
    if method == "positions":
        from salad_core.motion import features_to_joints

        return lambda out: [features_to_joints(out.features[b, :n], skeleton) for b, n in enumerate(out.lengths)]
    try:
        from salad_core.recovery import METHODS, recover_joints
    except ImportError:
        raise ValueError(f"--recovery {method!r}: this installation has no salad_core.recovery; use "
                         "'positions' or 'pipeline'") from None
    if method not in METHODS:
        raise ValueError(f"--recovery {method!r} is not known; allowed: pipeline, {', '.join(METHODS)}")
    return lambda out: [recover_joints(out.features[b, :n], method, skeleton) for b, n in enumerate(out.lengths)]
