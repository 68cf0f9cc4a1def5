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
  ground in a frame when its height above the clip's *contact level* is below
  ``PhysicsConfig.contact_heights`` (ankle, toe; the procedural corpus's thresholds) and, if
  ``contact_max_vspeed`` is set, its vertical speed is below that. The contact level
  (``PhysicsConfig.contact_reference``, :func:`contact_level`) is by default a robust low percentile
  (``contact_percentile``, 5 %) over frames of the lowest foot joint's height, so that one or a few
  penetrating frames do not lift the level under the feet of every other frame (before, it was
  the single lowest foot point of the clip: one frame 10 cm into the floor turned the whole stance into
  "flight"); ``"floor"`` uses ``y = floor`` and ``"clip_min"`` the old lowest point. It is the clip's
  own rather than ``y = 0`` by default so that a figure hovering over or sunk into the floor is still
  checked for sliding (its floating / penetration is measured apart).
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
  "flights" of 1.5-2.7 s for that reason). Beside the pooled mean of the second differences (dominated by
  whichever motion has most flight frames), :func:`flight_fit_accelerations` fits a parabola
  ``y = a t^2 + b t + c`` (least squares) to the pelvis height over each flight segment of at least
  ``flight_min_frames`` (3) frames and reports ``2a`` per segment; a motion reports the median over its
  segments and their number, the aggregate the median over all segments of all motions.
* **Stride** (m): how far a foot travels through the air between two ground contacts: the
  horizontal distance of its ankle from lift-off (the last frame of a run of at least
  ``min_contact_frames`` contact frames of the ankle or toe) to the next touch-down (the first
  frame of the next run), for swings of at most ``max_swing_s`` (a step, not a float); median over
  the motion, 0 when no foot steps. A figure that glides (feet sliding while in contact) or floats
  (feet off the ground for seconds) has short or no strides however far it travels.
* **Seed diversity** (cm): mean joint distance between motions of the same prompt made from
  different seeds (:func:`seed_diversity`).

Measures of the field, beside the ones above:

* **GMD foot-skating ratio** (:func:`gmd_skating_ratio`), as Guided Motion Diffusion (Karunratanakul et
  al., ICCV 2023) defines it and OmniControl (Xie et al., ICLR 2024) reuses it: "the proportion of
  frames in which either foot skids more than a certain distance (2.5 cm) while maintaining contact
  with the ground (foot height < 5 cm)". As in their released code (``calculate_skating_ratio``): the
  feet are the HumanML3D *toe* joints (``left_foot`` / ``right_foot``, indices 10 and 11); a frame pair
  counts when a toe is below 5 cm above the floor (``y = floor``, absolute height, as HumanML3D floors
  every clip) in both frames and its horizontal speed exceeds 0.5 m/s (2.5 cm per frame at 20 fps) both
  in that pair and in the 5-frame moving average (``scipy.ndimage.uniform_filter1d``, zero padding at
  the ends, as theirs); the ratio is over the N - 1 frame pairs.
* **PhysDiff's Penetrate / Float / Skate / Phys-Err** (Yuan et al., ICCV 2023), a *joint-based*
  version (:func:`physdiff_measures`; PhysDiff measures the SMPL mesh, which joint positions do not
  have, so joint centres stand in for vertices and read lower than the mesh would: a standing toe
  joint is 1-2 cm above the skin that touches the floor). Per frame, Penetrate is the depth below the
  floor of the lowest joint (counted when deeper than the 5 mm tolerance), Float the height of the
  lowest joint above the floor (counted when higher than 5 mm; UHC's mesh code takes the lowest vertex
  *above* the floor, which for a sparse joint set would count a figure standing on one toe as floating
  on its other joints, so the lowest joint itself is used); both are averaged over frames
  (frames without count 0). Skate: "foot joints that contact the ground in two adjacent frames" (toe
  joints within the 5 mm tolerance of the floor in both frames), their mean horizontal displacement
  in that frame pair, averaged over all frame pairs (0 where no foot is in contact). Phys-Err is the
  sum of the three. All in mm, as PhysDiff reports them; the tolerance is ``float_tolerance``.
* **Stance sliding and low swings** (:func:`stance_analysis`): the old skating mixes sliding stance
  feet with feet that pass low over the floor. A foot joint's frame pair is *low* when the joint is in
  contact by height (above) at both ends; it is *stance* when, besides, its vertical speed over the
  pair is below ``stance_max_vspeed`` (0.1 m/s: PhysDiff's 5 mm per frame at 20 fps) and the pair lies
  in a run of such pairs spanning at least ``stance_min_frames`` (3) frames. Stance sliding (m/s):
  the horizontal speed over the stance pairs (mean, p95, count); low swings: the same over the low
  pairs that are not stance. **Floating during stance** (cm): for every foot and frame with one of its
  joints in stance, the height above the floor (``y = floor``) of the lower of its ankle and toe joints,
  averaged (signed: below 0 the stance foot is sunk).
* **p99** of the reference bone-length error (over frames x bones) and of the per-frame penetration
  depth, beside their max (one wild frame decides a max; the benchmark also pools the p99 over all
  frames of all motions, :func:`pooled_bone_percentile`, :func:`pooled_penetration_percentile`).
* **General motions** (the benchmark's general-motion prompts; heights of joint centres above ``config.floor``):
  :func:`trunk_axes` (up: pelvis to neck; right: across the hips and shoulders; front: the way the chest faces),
  :func:`inverted_frames` (the head below the pelvis), :func:`on_hands_frames` (inverted with a wrist or elbow
  the lowest joint), :func:`pitch_rotation` (degrees the trunk turns head over heels, summed frame to frame about
  the body's left axis: > 0 forwards), :func:`kneel_frames` (the named knee within 0.15 m of the floor, the other
  knee 0.1 m higher and the other foot within 0.12 m: kneeling on one knee, the corpus's posture definition),
  :func:`hands_down_frames` (both wrists within 0.2 m of the floor) and :func:`foot_plants` /
  :func:`planted_rise` (a toe still, slower than 0.25 m/s, for at least ``stance_min_frames`` frames at any
  height is a plant; the rise is the height of the last plant less the lower toe's at the start: a stair climb
  plants the feet higher step by step, a figure rising with nothing under it plants none up there).
* **Shown vs raw** (:func:`recovery_deviation`): the distance (cm) between the joints a recovery shows
  and the raw position read of the same features, per joint (p95, max) and over all frames x joints
  (p95, p99, max), and the travel ratio (the shown pelvis's ground path over the raw one's).
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
    "CONTACT_REFERENCES", "gmd_skating_ratio", "physdiff_measures", "stance_analysis", "flight_fit_accelerations",
    "pooled_bone_percentile", "pooled_penetration_percentile", "recovery_deviation", "travel_ratio",
    "FIELD_TABLE_COLUMNS", "trunk_axes", "inverted_frames", "on_hands_frames", "pitch_rotation", "kneel_frames",
    "hands_down_frames", "foot_plants", "planted_rise", "KNEE_DOWN_M", "FOOT_DOWN_M", "KNEE_GAP_M", "HAND_DOWN_M",
]

#: Standard gravity (m/s^2), what the pelvis's acceleration in flight should be near (negative: down).
GRAVITY = 9.80665

#: What the contact level of :func:`foot_contacts` is referenced to (``PhysicsConfig.contact_reference``).
CONTACT_REFERENCES = ("percentile", "floor", "clip_min")


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
    contact_reference: str = "percentile"             # contact level: "percentile", "floor" or "clip_min"
    contact_percentile: float = 5.0                   # with "percentile": of the lowest foot joint's height
    stance_max_vspeed: float = 0.10                   # vertical speed (m/s) below which a low foot is in stance
    stance_min_frames: int = 3                        # shortest run of stance (frames)
    flight_min_frames: int = 3                        # shortest flight segment fitted with a parabola
    gmd_height: float = 0.05                          # GMD skating ratio: toe height (m) in contact
    gmd_speed: float = 0.50                           # GMD: horizontal toe speed (m/s) that skids
    gmd_window: int = 5                               # GMD: moving-average window (frames)

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
        if self.contact_reference not in CONTACT_REFERENCES:
            raise ValueError(f"contact_reference must be one of {CONTACT_REFERENCES}, got {self.contact_reference!r}")
        if not 0 <= self.contact_percentile <= 100:
            raise ValueError(f"contact_percentile must be in [0, 100], got {self.contact_percentile!r}")
        for name in ("stance_max_vspeed", "gmd_height", "gmd_speed"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name, low in (("stance_min_frames", 2), ("flight_min_frames", 3), ("gmd_window", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < low:
                raise ValueError(f"{name} must be an int >= {low}, got {v!r}")


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
    # ---- the field's measures (module docstring, "Measures of the field")
    contact_level_m: float       # the contact level the contacts above were measured from
    bone_ref_p99_cm: float       # |length - reference length|, p99 over frames x bones
    penetration_p99_cm: float    # p99 over frames of the lowest joint's depth below the floor
    gmd_skate_ratio: float       # GMD / OmniControl foot-skating ratio (share of frame pairs)
    physdiff_penetrate_mm: float  # PhysDiff's Penetrate, joint-based (mean over frames)
    physdiff_float_mm: float     # PhysDiff's Float, joint-based
    physdiff_skate_mm: float     # PhysDiff's Skate, joint-based (mean over frame pairs)
    physdiff_err_mm: float       # Phys-Err: the sum of the three
    stance_slide_mean_ms: float  # horizontal speed of stance foot joints (nan: no stance)
    stance_slide_p95_ms: float   # its p95
    stance_count: int            # stance joint x frame pairs
    low_swing_mean_ms: float     # horizontal speed of low foot joints not in stance (nan: none)
    low_swing_count: int         # low, non-stance joint x frame pairs
    stance_float_cm: float       # mean height above the floor of the stance feet (lower of ankle / toe)
    stance_foot_frames: int      # foot x frames that mean is over
    flight_fit_accel_ms2: float  # median over flight segments of the fitted pelvis acceleration (nan: none)
    flight_segments: int         # flight segments of >= flight_min_frames frames
    flight_segment_accels: tuple = ()  # each segment's fitted acceleration (m/s^2)

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


def contact_level(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig | None = None) -> float:
    """The clip's contact level (m), the height foot contact is measured from
    (``config.contact_reference``): ``"percentile"`` the ``contact_percentile`` percentile over frames of
    the lowest foot joint's height; ``"floor"`` ``config.floor``; ``"clip_min"`` the lowest height any
    foot joint reaches (the only level there used to be; also what ``config=None`` gives, for callers of
    the old one-argument form)."""
    x, sk = _prepare(joints, skeleton)
    low = x[:, list(sk.contact_joints), 1].min(-1)
    if config is None or config.contact_reference == "clip_min":
        return float(low.min())
    if config.contact_reference == "floor":
        return float(config.floor)
    return float(np.percentile(low, config.contact_percentile))


def foot_contacts(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
                  ) -> np.ndarray:
    """``(N, 4)`` bool: foot joint (``skeleton.contact_joints`` order: left ankle, left toe, right
    ankle, right toe) in contact with the ground in each frame (see the module docstring)."""
    x, sk = _prepare(joints, skeleton)
    cj = list(sk.contact_joints)
    h = x[:, cj, 1] - contact_level(x, sk, config)
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


# ------------------------------------------------------------------------------------ the field's measures
def _toes(sk: Skeleton) -> list[int]:
    return [_idx(sk, "left_foot"), _idx(sk, "right_foot")]


def gmd_skating_ratio(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
                      ) -> float:
    """GMD's foot-skating ratio of one motion: the share of its N - 1 frame pairs in which either toe
    joint skids (module docstring; Karunratanakul et al., "Guided Motion Diffusion for Controllable
    Human Motion Synthesis", ICCV 2023, reused by OmniControl, ICLR 2024).

    A toe (HumanML3D joints ``left_foot`` / ``right_foot``, 10 and 11, as in GMD's
    ``calculate_skating_ratio``) skids over a frame pair when it is below ``config.gmd_height`` (5 cm)
    above ``config.floor`` in both frames and its horizontal speed is above ``config.gmd_speed``
    (0.5 m/s = 2.5 cm per frame at 20 fps) in the pair and in the ``gmd_window``-frame (5) moving
    average of the speeds (zero-padded at the ends, ``uniform_filter1d(mode="constant")`` as GMD's)."""
    from scipy.ndimage import uniform_filter1d

    x, sk = _prepare(joints, skeleton)
    toes = x[:, _toes(sk)]                                            # (N, 2, 3)
    speed = np.linalg.norm(np.diff(toes[..., [0, 2]], axis=0), axis=-1) * _fps(sk, config)   # (N-1, 2)
    avg = uniform_filter1d(speed, size=config.gmd_window, axis=0, mode="constant", origin=0)
    low = toes[..., 1] - config.floor < config.gmd_height
    contact = low[:-1] & low[1:]
    skids = contact & (speed > config.gmd_speed) & (avg > config.gmd_speed)
    return float(skids.any(-1).mean())


def physdiff_measures(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
                      ) -> dict[str, float]:
    """PhysDiff's physical measures (Yuan et al., "PhysDiff: Physics-Guided Human Motion Diffusion
    Model", ICCV 2023), computed on joints instead of the SMPL mesh (module docstring).

    Returns
    -------
    dict (mm): ``penetrate`` (mean over frames of the lowest joint's depth below ``config.floor``, where
    deeper than ``config.float_tolerance``), ``float`` (mean over frames of the lowest joint's height
    above the floor, where higher than the tolerance), ``skate`` (mean over frame pairs of the mean
    horizontal displacement of the toe joints within the tolerance of the floor in both frames; 0 for a
    pair without such a toe) and ``err`` (Phys-Err, the sum of the three).
    """
    x, sk = _prepare(joints, skeleton)
    tol = config.float_tolerance
    y = x[..., 1] - config.floor                                      # (N, J)
    low = y.min(-1)
    pen = np.where(low < -tol, -low, 0.0)
    flo = np.where(low > tol, low, 0.0)
    toes = x[:, _toes(sk)]
    on = toes[..., 1] - config.floor <= tol
    both = on[:-1] & on[1:]                                           # (N-1, 2)
    disp = np.linalg.norm(np.diff(toes[..., [0, 2]], axis=0), axis=-1)
    n = both.sum(-1)
    skate = np.where(n > 0, (disp * both).sum(-1) / np.maximum(n, 1), 0.0)
    out = {"penetrate": float(pen.mean() * 1000), "float": float(flo.mean() * 1000),
           "skate": float(skate.mean() * 1000)}
    out["err"] = out["penetrate"] + out["float"] + out["skate"]
    return out


def _long_runs(mask: np.ndarray, min_len: int) -> np.ndarray:
    """``mask`` (1-D bool) with the runs of True shorter than ``min_len`` cleared."""
    m = np.concatenate([[False], mask.astype(bool), [False]])
    edges = np.flatnonzero(m[1:] != m[:-1])
    out = np.zeros(mask.shape, bool)
    for a, b in zip(edges[::2], edges[1::2]):
        if b - a >= min_len:
            out[a:b] = True
    return out


def stance_analysis(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
                    ) -> dict[str, np.ndarray]:
    """Stance and low-swing frame pairs of the foot joints (module docstring, "Stance sliding").

    Returns
    -------
    dict: ``low`` ``(N-1, 4)`` bool (foot joint in contact by height at both ends of the pair),
    ``stance`` ``(N-1, 4)`` bool (low, vertical speed below ``stance_max_vspeed`` and in a run spanning
    at least ``stance_min_frames`` frames), ``low_swing`` = low and not stance, ``speed`` ``(N-1, 4)``
    horizontal speed (m/s), ``stance_frames`` ``(N, 4)`` bool (the frames of the stance pairs) and
    ``stance_float`` ``(K,)`` (m): per foot x frame with a joint in stance, the height above
    ``config.floor`` of the lower of that foot's ankle and toe. Columns in ``contact_joints`` order.
    """
    x, sk = _prepare(joints, skeleton)
    fps = _fps(sk, config)
    cj = list(sk.contact_joints)
    feet = x[:, cj]                                                   # (N, 4, 3)
    h = feet[..., 1] - contact_level(x, sk, config)
    under = h < np.asarray(config.contact_heights * 2)
    low = under[:-1] & under[1:]
    vy = np.abs(np.diff(feet[..., 1], axis=0)) * fps
    still = low & (vy < config.stance_max_vspeed)
    stance = np.stack([_long_runs(still[:, k], config.stance_min_frames - 1) for k in range(4)], 1)
    speed = np.linalg.norm(np.diff(feet[..., [0, 2]], axis=0), axis=-1) * fps
    frames = np.zeros(h.shape, bool)
    frames[:-1] |= stance
    frames[1:] |= stance
    heights = feet[..., 1] - config.floor
    floats = []
    for a, b in ((0, 1), (2, 3)):                                     # (ankle, toe) columns of each foot
        on = frames[:, a] | frames[:, b]
        floats.append(np.minimum(heights[:, a], heights[:, b])[on])
    return {"low": low, "stance": stance, "low_swing": low & ~stance, "speed": speed, "stance_frames": frames,
            "stance_float": np.concatenate(floats)}


def flight_fit_accelerations(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
                             ) -> np.ndarray:
    """Per flight segment (a run of at least ``config.flight_min_frames`` flight frames), the pelvis's
    vertical acceleration (m/s^2) of the least-squares parabola through its height over the segment
    (``2a`` of ``y = a t^2 + b t + c``): a 1-D array in time order, empty without such a segment."""
    x, sk = _prepare(joints, skeleton)
    fps = _fps(sk, config)
    fl = np.concatenate([[False], flight_frames(x, sk, config), [False]])
    edges = np.flatnonzero(fl[1:] != fl[:-1])
    out = []
    for a, b in zip(edges[::2], edges[1::2]):
        if b - a >= config.flight_min_frames:
            t = np.arange(b - a) / fps
            out.append(2.0 * np.polyfit(t, x[a:b, 0, 1], 2)[0])
    return np.asarray(out, dtype=np.float64)


def pooled_bone_percentile(motions: Sequence[np.ndarray], q: float = 99.0, skeleton: str | Skeleton = "humanml3d"
                           ) -> float:
    """The ``q``-th percentile (cm) of the reference bone-length error over all frames x bones of all
    ``motions`` together (nan for a skeleton without reference lengths)."""
    errs = [bone_length_errors(m, skeleton).get("ref_error") for m in motions]
    errs = [e.ravel() for e in errs if e is not None]
    return float(np.percentile(np.concatenate(errs), q) * 100.0) if errs else float("nan")


def pooled_penetration_percentile(motions: Sequence[np.ndarray], q: float = 99.0,
                                  skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()
                                  ) -> float:
    """The ``q``-th percentile (cm) of the per-frame penetration depth (:func:`ground_penetration`) over
    all frames of all ``motions`` together."""
    if not len(motions):
        return float("nan")
    depth = np.concatenate([ground_penetration(m, skeleton, config) for m in motions])
    return float(np.percentile(depth, q) * 100.0)


def _path_length(x: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(x[:, 0, [0, 2]], axis=0), axis=-1).sum())


def travel_ratio(shown, raw) -> float:
    """The shown pelvis's ground path length over the raw one's (summed over motions when given
    sequences of motions); nan when the raw pelvis does not travel."""
    shown_l, raw_l = _motion_list(shown), _motion_list(raw)
    s = sum(_path_length(a) for a in shown_l)
    r = sum(_path_length(b) for b in raw_l)
    return s / r if r > 0 else float("nan")


def _motion_list(m) -> list[np.ndarray]:
    if isinstance(m, np.ndarray) and m.ndim == 3:
        return [np.asarray(m, dtype=np.float64)]
    out = [np.asarray(a, dtype=np.float64) for a in m]
    if not out or any(a.ndim != 3 or a.shape[-1] != 3 for a in out):
        raise ValueError("expected joints (N, J, 3) or a non-empty sequence of them")
    return out


def recovery_deviation(shown, raw, skeleton: str | Skeleton | None = "humanml3d") -> dict:
    """How far the joints a recovery shows are from the raw position read of the same features.

    Parameters
    ----------
    shown, raw : ``(N, J, 3)`` joints of one motion (metres), or sequences of them (the same motions in
        the same order, the same frames each): the deviations are then pooled over all motions.
    skeleton : names the joints of ``worst_joint`` (None: joint indices).

    Returns
    -------
    dict: ``per_joint_p95_cm`` and ``per_joint_max_cm`` (lists of J, over frames), ``p95_cm``, ``p99_cm``,
    ``max_cm`` and ``mean_cm`` (over frames x joints), ``worst_joint`` (the joint of the largest p95),
    ``travel_ratio`` (:func:`travel_ratio`), ``shown_path_m`` / ``raw_path_m`` (pelvis ground paths) and
    ``frames``. Identical arrays give 0 everywhere and a travel ratio of 1 (nan without travel).
    """
    s_list, r_list = _motion_list(shown), _motion_list(raw)
    if len(s_list) != len(r_list) or any(a.shape != b.shape for a, b in zip(s_list, r_list)):
        raise ValueError(f"shown and raw must be the same motions with the same shapes, got "
                         f"{[a.shape for a in s_list]} and {[b.shape for b in r_list]}")
    if not all(np.isfinite(a).all() for a in s_list + r_list):
        raise ValueError("shown / raw joints contain NaN or infinite values")
    d = np.concatenate([np.linalg.norm(a - b, axis=-1) for a, b in zip(s_list, r_list)]) * 100.0   # (sum N, J)
    per_p95 = np.percentile(d, 95, axis=0)
    names = get_skeleton(skeleton).joint_names if skeleton is not None else None
    worst = int(np.argmax(per_p95))
    s_path = sum(_path_length(a) for a in s_list)
    r_path = sum(_path_length(b) for b in r_list)
    return {"per_joint_p95_cm": [float(v) for v in per_p95], "per_joint_max_cm": [float(v) for v in d.max(0)],
            "p95_cm": float(np.percentile(d, 95)), "p99_cm": float(np.percentile(d, 99)), "max_cm": float(d.max()),
            "mean_cm": float(d.mean()),
            "worst_joint": names[worst] if names is not None and len(names) == d.shape[1] else worst,
            "travel_ratio": s_path / r_path if r_path > 0 else float("nan"),
            "shown_path_m": s_path, "raw_path_m": r_path, "frames": int(d.shape[0])}


# ------------------------------------------------------------------------------------ general motions
#: Heights (m, joint centres above ``config.floor``) of the postures of the general-motion measures, as the
#: corpus's captions name them (``salad_core.data.procedural.general_language.measured_postures``): a knee
#: resting on the floor is about 0.05 up, a flat foot's ankle 0.08, a hand on the floor's wrist 0.03-0.06.
KNEE_DOWN_M, FOOT_DOWN_M, KNEE_GAP_M, HAND_DOWN_M = 0.15, 0.12, 0.10, 0.20


def trunk_axes(joints, skeleton: str | Skeleton = "humanml3d") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame unit vectors of the trunk, ``(N, 3)`` each: ``up`` (pelvis to neck), ``right`` (left to
    right hip plus left to right shoulder, square to ``up``) and ``front`` (``up x right``: the way the
    chest faces; its height component is 1 lying on the back, -1 on the front)."""
    x, sk = _prepare(joints, skeleton)
    up = _unit(x[:, _idx(sk, "neck")] - x[:, 0])
    right = (x[:, _idx(sk, "right_hip")] - x[:, _idx(sk, "left_hip")]) + \
        (x[:, _idx(sk, "right_shoulder")] - x[:, _idx(sk, "left_shoulder")])
    right = _unit(right - (right * up).sum(-1, keepdims=True) * up)
    return up, right, np.cross(up, right)


def inverted_frames(joints, skeleton: str | Skeleton = "humanml3d") -> np.ndarray:
    """``(N,)`` bool: the head joint below the pelvis (a cartwheel, handstand, roll or flip)."""
    x, sk = _prepare(joints, skeleton)
    return x[:, _idx(sk, "head"), 1] < x[:, 0, 1]


def on_hands_frames(joints, skeleton: str | Skeleton = "humanml3d") -> np.ndarray:
    """``(N,)`` bool: upside down on the hands: the head below the pelvis and the lowest joint a wrist or an
    elbow (the skeleton has no hand joints)."""
    x, sk = _prepare(joints, skeleton)
    arms = [_idx(sk, n) for n in ("left_elbow", "right_elbow", "left_wrist", "right_wrist")]
    return inverted_frames(x, sk) & np.isin(x[..., 1].argmin(axis=1), arms)


def pitch_rotation(joints, skeleton: str | Skeleton = "humanml3d") -> float:
    """Degrees the trunk turned head over heels, summed frame to frame about the body's left axis
    (> 0: forwards, a forward roll or front flip; < 0: backwards, a backflip)."""
    up, right, _ = trunk_axes(joints, skeleton)
    axis = -right[:-1]
    cross = np.cross(up[:-1], up[1:])
    return float(np.degrees(np.arctan2((cross * axis).sum(-1), (up[:-1] * up[1:]).sum(-1)).sum()))


def kneel_frames(joints, side: str, skeleton: str | Skeleton = "humanml3d",
                 config: PhysicsConfig = PhysicsConfig()) -> np.ndarray:
    """``(N,)`` bool: kneeling on the ``side`` ("left" / "right") knee: that knee within ``KNEE_DOWN_M`` of the
    floor, the other knee at least ``KNEE_GAP_M`` higher and the other foot planted (the lower of its ankle and
    toe within ``FOOT_DOWN_M`` of the floor)."""
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    x, sk = _prepare(joints, skeleton)
    other = "right" if side == "left" else "left"
    y = x[..., 1] - config.floor
    knee, o_knee = y[:, _idx(sk, f"{side}_knee")], y[:, _idx(sk, f"{other}_knee")]
    o_foot = np.minimum(y[:, _idx(sk, f"{other}_ankle")], y[:, _idx(sk, f"{other}_foot")])
    return (knee < KNEE_DOWN_M) & (o_knee > knee + KNEE_GAP_M) & (o_foot < FOOT_DOWN_M)


def hands_down_frames(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig(),
                      height: float = HAND_DOWN_M) -> np.ndarray:
    """``(N,)`` bool: both wrists within ``height`` of the floor (on all fours, while crawling)."""
    x, sk = _prepare(joints, skeleton)
    y = x[..., 1] - config.floor
    return np.maximum(y[:, _idx(sk, "left_wrist")], y[:, _idx(sk, "right_wrist")]) < height


def foot_plants(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig(),
                max_speed: float = 0.25) -> list[tuple[str, int, int, float]]:
    """Where the feet stand still, at any height (a step of a stair is a plant above the floor).

    A toe joint (``left_foot`` / ``right_foot``) is planted over a run of at least ``config.stance_min_frames``
    frames in which it moves slower than ``max_speed`` (m/s, 3-D) from frame to frame. Returns per plant
    ``(foot, first frame, last frame + 1, height)``, the height (m above ``config.floor``) the median of the
    toe's over the run; in time order.
    """
    x, sk = _prepare(joints, skeleton)
    fps = _fps(sk, config)
    out = []
    for foot in ("left", "right"):
        toe = x[:, _idx(sk, f"{foot}_foot")]
        slow = np.linalg.norm(np.diff(toe, axis=0), axis=-1) * fps < max_speed       # (N-1,) frame pairs
        runs = _long_runs(slow, config.stance_min_frames - 1)
        m = np.concatenate([[False], runs, [False]])
        edges = np.flatnonzero(m[1:] != m[:-1])
        for a, b in zip(edges[::2], edges[1::2]):                                    # pairs a..b-1: frames a..b
            out.append((foot, int(a), int(b + 1), float(np.median(toe[a:b + 1, 1]) - config.floor)))
    return sorted(out, key=lambda p: (p[1], p[0]))


def planted_rise(joints, skeleton: str | Skeleton = "humanml3d", config: PhysicsConfig = PhysicsConfig()) -> float:
    """How much higher (m) the feet end up standing than they start: the height of the last :func:`foot_plants`
    plant less the lower toe's over the first ``config.stance_min_frames`` frames (0 without a plant). A stair climb
    plants the feet step by step higher; a figure that rises with nothing under it plants none up there."""
    x, sk = _prepare(joints, skeleton)
    plants = foot_plants(x, sk, config)
    if not plants:
        return 0.0
    toes = [_idx(sk, "left_foot"), _idx(sk, "right_foot")]
    start = float(x[:config.stance_min_frames, toes, 1].min(axis=1).mean()) - config.floor
    last_start = max(p[1] for p in plants)
    return float(np.mean([p[3] for p in plants if p[1] == last_start]) - start)


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
    level = contact_level(x, sk, config)
    feet_low = x[:, list(sk.contact_joints), 1].min(-1) - level
    pelvis = x[:, 0, 1]
    runs = _runs(fl)
    steps = strides(x, sk, config)
    pd = physdiff_measures(x, sk, config)
    st = stance_analysis(x, sk, config)
    slide, swing = st["speed"][st["stance"]], st["speed"][st["low_swing"]]
    fits = flight_fit_accelerations(x, sk, config)
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
        contact_level_m=level,
        bone_ref_p99_cm=_stat(ref, lambda v: np.percentile(v, 99), 100.0),
        penetration_p99_cm=float(np.percentile(pen, 99) * 100.0),
        gmd_skate_ratio=gmd_skating_ratio(x, sk, config),
        physdiff_penetrate_mm=pd["penetrate"], physdiff_float_mm=pd["float"], physdiff_skate_mm=pd["skate"],
        physdiff_err_mm=pd["err"],
        stance_slide_mean_ms=_stat(slide, np.mean),
        stance_slide_p95_ms=_stat(slide, lambda v: np.percentile(v, 95)),
        stance_count=int(slide.size),
        low_swing_mean_ms=_stat(swing, np.mean),
        low_swing_count=int(swing.size),
        stance_float_cm=_stat(st["stance_float"], np.mean, 100.0),
        stance_foot_frames=int(st["stance_float"].size),
        flight_fit_accel_ms2=_stat(fits, np.median),
        flight_segments=int(fits.size),
        flight_segment_accels=tuple(float(v) for v in fits),
    )


# ------------------------------------------------------------------------------------ aggregate
#: How each field of :class:`PhysicsReport` is aggregated over motions: "mean" (of the per-motion
#: values, nan ignored), "max", "sum", "pooled:<count field>" (mean weighted by that count,
#: i.e. the measure over all the motions' contact / flight frames together), "median_of:<field>" (the
#: median over the concatenated per-segment values of that tuple field) or "drop" (not aggregated).
AGGREGATION: dict[str, str] = {
    "frames": "sum", "bone_ref_p95_cm": "mean", "bone_ref_max_cm": "max", "bone_self_p95_cm": "mean",
    "bone_self_max_cm": "max", "skate_mean_ms": "pooled:contact_count", "skate_p95_ms": "mean",
    "skate_share": "pooled:contact_count", "contact_count": "sum", "penetration_max_cm": "max",
    "penetration_mean_cm": "mean", "float_mean_cm": "mean", "float_min_cm": "mean", "jitter_ms3": "mean",
    "accel_ms2": "mean", "knee_hyper_max_deg": "max", "knee_hyper_share": "mean", "elbow_hyper_max_deg": "max",
    "elbow_hyper_share": "mean", "pelvis_range_cm": "mean", "jump_rise_m": "mean", "feet_clearance_m": "mean",
    "flight_frames": "sum", "longest_flight_s": "max", "flight_accel_ms2": "pooled:flight_accel_count",
    "flight_accel_count": "sum", "stride_m": "mean",
    "contact_level_m": "mean", "bone_ref_p99_cm": "mean", "penetration_p99_cm": "mean", "gmd_skate_ratio": "mean",
    "physdiff_penetrate_mm": "mean", "physdiff_float_mm": "mean", "physdiff_skate_mm": "mean",
    "physdiff_err_mm": "mean", "stance_slide_mean_ms": "pooled:stance_count", "stance_slide_p95_ms": "mean",
    "stance_count": "sum", "low_swing_mean_ms": "pooled:low_swing_count", "low_swing_count": "sum",
    "stance_float_cm": "pooled:stance_foot_frames", "stance_foot_frames": "sum",
    "flight_fit_accel_ms2": "median_of:flight_segment_accels", "flight_segments": "sum",
    "flight_segment_accels": "drop",
}
assert set(AGGREGATION) == {f.name for f in fields(PhysicsReport)}, "AGGREGATION must cover PhysicsReport"


def aggregate_reports(reports: Iterable[PhysicsReport | Mapping[str, float]]) -> dict[str, float]:
    """Aggregate per-motion reports over many motions (rule per field in :data:`AGGREGATION`).

    Returns a dict with every field of :class:`PhysicsReport` (but the "drop" ones) plus ``motions``
    (how many) and ``<field>_median`` for the "mean" fields (robust to one wild motion). A mapping
    without a field (a report saved before the field existed) counts as nan / empty for it.
    """
    rows = [r.as_dict() if isinstance(r, PhysicsReport) else dict(r) for r in reports]
    if not rows:
        raise ValueError("aggregate_reports needs at least one report")
    out: dict[str, float] = {"motions": len(rows)}
    for name, rule in AGGREGATION.items():
        if rule == "drop":
            continue
        if rule.startswith("median_of:"):
            vals = np.array([float(a) for r in rows for a in (r.get(rule.split(":", 1)[1]) or ())
                             if a is not None], dtype=np.float64)
            vals = vals[np.isfinite(vals)]
            out[name] = float(np.median(vals)) if vals.size else float("nan")
            continue
        v = np.array([_num(r.get(name)) for r in rows])
        ok = v[np.isfinite(v)]
        if rule == "sum":
            out[name] = float(ok.sum())
        elif rule == "max":
            out[name] = float(ok.max()) if ok.size else float("nan")
        elif rule == "mean":
            out[name] = float(ok.mean()) if ok.size else float("nan")
            out[name + "_median"] = float(np.median(ok)) if ok.size else float("nan")
        else:
            w = np.array([_num(r.get(rule.split(":", 1)[1])) for r in rows])
            keep = np.isfinite(v) & (w > 0)
            out[name] = float((v[keep] * w[keep]).sum() / w[keep].sum()) if keep.any() else float("nan")
    return out


def _num(v) -> float:
    return float("nan") if v is None else float(v)


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


#: Columns of the field's measures for :func:`report_table` (``columns=FIELD_TABLE_COLUMNS``).
FIELD_TABLE_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("motions", "motions", "{:.0f}"),
    ("stance_slide_mean_ms", "stance slide (m/s)", "{:.3f}"),
    ("stance_slide_p95_ms", "stance slide p95 (m/s)", "{:.3f}"),
    ("low_swing_mean_ms", "low swing (m/s)", "{:.3f}"),
    ("gmd_skate_ratio", "GMD skate ratio", "{:.3f}"),
    ("physdiff_penetrate_mm", "PhysDiff penetrate (mm)", "{:.1f}"),
    ("physdiff_float_mm", "PhysDiff float (mm)", "{:.1f}"),
    ("physdiff_skate_mm", "PhysDiff skate (mm)", "{:.1f}"),
    ("physdiff_err_mm", "Phys-Err (mm)", "{:.1f}"),
    ("stance_float_cm", "stance float (cm)", "{:.2f}"),
    ("bone_ref_p99_pooled_cm", "bone err p99 pooled (cm)", "{:.2f}"),
    ("penetration_p99_pooled_cm", "penetration p99 pooled (cm)", "{:.2f}"),
    ("flight_fit_accel_ms2", "flight accel fit median (m/s^2)", "{:.1f}"),
    ("flight_segments", "flight segments", "{:.0f}"),
    ("contact_level_m", "contact level (m)", "{:.3f}"),
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


def joints_reader(method: str, skeleton: str | Skeleton = "humanml3d", with_raw: bool = False):
    """``output -> list of joints`` (``(N_b, J, 3)`` metres each): which joints of a generator's output
    the benchmark measures (``salad eval --physics --recovery METHOD``).

    ``method``: ``'positions'`` reads the raw position features (the model's own output);
    ``'fk'`` / ``'fit'``: :func:`salad_core.recovery.recover_joints`; ``'pipeline'``: ``out.joints``.
    The output needs ``features`` ``(B, N, D)`` and ``lengths`` (and ``joints`` for 'pipeline').

    ``with_raw=True``: the reader returns ``(shown, raw)``, the joints of ``method`` and the raw
    position read of the same features (for :func:`recovery_deviation`; the features are read twice,
    not generated twice).
    """
    if with_raw:
        shown_of, raw_of = joints_reader(method, skeleton), joints_reader("positions", skeleton)
        return lambda out: (shown_of(out), raw_of(out))
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
