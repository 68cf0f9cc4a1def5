"""Body model of the procedural corpus: forward kinematics and analytic limb IK.

Every clip is built on the HumanML3D 22-joint skeleton with its *target* bone lengths
(``humanml3d_eval_facts`` §1.1), so bone lengths are exact by construction:

* torso, neck and head come from forward kinematics of per-joint local rotations over a rest
  pose (the target offsets with the bone directions of a relaxed standing pose, measured on
  real HumanML3D data);
* legs and arms are two-bone chains placed by analytic inverse kinematics (law of cosines and a
  pole vector), which is what lets stance feet stay exactly planted (no foot sliding).

A :class:`Pose` holds the per-frame controls of one clip; :func:`assemble` turns it into joints
``(N, J, 3)``. Coordinate frame: +Y up, floor at y = 0; a body with yaw 0 faces +Z and its left
side is +X. Yaw is positive when turning left (counter-clockwise seen from above).
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from functools import lru_cache

import numpy as np

from ...skeleton import Skeleton, get_skeleton

__all__ = [
    "FPS",
    "BodyModel",
    "body_model",
    "Pose",
    "assemble",
    "rot_x",
    "rot_y",
    "rot_z",
    "ypr_matrix",
    "two_bone_ik",
    "clamp_ankle",
    "ANKLE_RANGE",
    "arm_direction",
    "arm_angles_for_target",
    "foot_vector",
    "heading_vectors",
    "TRUNK_JOINTS",
    "trunk_frames",
]

#: Frame rate of every clip (HumanML3D).
FPS = 20.0

# Rest bone directions (body frame: x = left, y = up, z = forward) of a relaxed upright stand.
# Hips, spine1 and feet follow the medians measured on HumanML3D clip 012314 in its heading
# frame; the upper spine, neck and collars are made more upright than that (slouching) clip.
# Limb bones are absent: the IK places them.
_REST_DIRECTIONS: dict[str, tuple[float, float, float]] = {
    "left_hip": (0.563, -0.823, -0.06),
    "right_hip": (-0.563, -0.823, -0.06),
    "spine1": (0.0, 0.974, -0.228),
    "spine2": (0.0, 0.97, 0.23),
    "spine3": (0.0, 0.6, 0.8),
    "neck": (0.0, 0.99, -0.12),
    "left_collar": (0.52, 0.84, -0.1),
    "right_collar": (-0.52, 0.84, -0.1),
    "head": (0.0, 0.75, 0.66),
    "left_shoulder": (0.98, -0.08, -0.1),
    "right_shoulder": (-0.98, -0.08, -0.1),
}

#: Share of the total spine bend taken by spine1, spine2 and spine3 (lumbar bends most).
SPINE_SHARE = (0.45, 0.35, 0.2)
#: Share of the head rotation taken by the neck base (the rest turns the head on the neck).
NECK_SHARE = 0.5
#: Joints of :attr:`Pose.trunk`, the per-segment rotations laid after the shares (2.3).
TRUNK_JOINTS = ("spine1", "spine2", "spine3", "neck", "head")


# ----------------------------------------------------------------------------- rotations
def rot_x(a) -> np.ndarray:
    """``(..., 3, 3)`` rotation about +X by ``a`` radians (positive tips +Y towards +Z)."""
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def rot_y(a) -> np.ndarray:
    """``(..., 3, 3)`` rotation about +Y (positive turns +Z towards +X, i.e. to the left)."""
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def rot_z(a) -> np.ndarray:
    """``(..., 3, 3)`` rotation about +Z (positive tips +Y towards -X)."""
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def ypr_matrix(ypr: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` from ``(..., 3)`` (yaw, pitch, roll).

    ``R = Ry(yaw) Rx(pitch) Rz(-roll)``: yaw > 0 turns left, pitch > 0 bends forward (tips the
    up axis towards the front), roll > 0 leans towards the body's left side.
    """
    ypr = np.asarray(ypr, dtype=np.float64)
    return rot_y(ypr[..., 0]) @ rot_x(ypr[..., 1]) @ rot_z(-ypr[..., 2])


def heading_vectors(yaw) -> tuple[np.ndarray, np.ndarray]:
    """Forward and left unit vectors ``(..., 3)`` of a heading ``yaw``."""
    yaw = np.asarray(yaw, dtype=np.float64)
    z = np.zeros_like(yaw)
    fwd = np.stack([np.sin(yaw), z, np.cos(yaw)], -1)
    left = np.stack([np.cos(yaw), z, -np.sin(yaw)], -1)
    return fwd, left


def foot_vector(yaw, pitch, length) -> np.ndarray:
    """Ankle-to-toe vector ``(..., 3)``: pointing along ``yaw``, tipped down by ``pitch`` radians."""
    yaw = np.asarray(yaw, dtype=np.float64)
    pitch = np.asarray(pitch, dtype=np.float64)
    cp = np.cos(pitch)
    v = np.stack([np.sin(yaw) * cp, -np.sin(pitch), np.cos(yaw) * cp], -1)
    return v * np.asarray(length, dtype=np.float64)[..., None]


def _unit(v: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    ok = n > 1e-9
    return np.where(ok, v / np.where(ok, n, 1.0), fallback)


# ----------------------------------------------------------------------------- body model
@dataclass(frozen=True)
class BodyModel:
    """Joint indices, rest offsets and limb lengths of the target skeleton."""

    skeleton: Skeleton            # the HumanML3D skeleton
    index: dict                   # joint name -> index
    rest_offsets: np.ndarray      # (J, 3) rest offset of each bone parent->joint (torso bones only)
    lengths: np.ndarray           # (J,) target length of the bone ending at each joint

    def j(self, name: str) -> int:
        return self.index[name]

    # limb lengths, (left, right)
    @property
    def thigh(self) -> np.ndarray:
        return self.lengths[[self.j("left_knee"), self.j("right_knee")]]

    @property
    def shin(self) -> np.ndarray:
        return self.lengths[[self.j("left_ankle"), self.j("right_ankle")]]

    @property
    def foot(self) -> np.ndarray:
        return self.lengths[[self.j("left_foot"), self.j("right_foot")]]

    @property
    def upper_arm(self) -> np.ndarray:
        return self.lengths[[self.j("left_elbow"), self.j("right_elbow")]]

    @property
    def forearm(self) -> np.ndarray:
        return self.lengths[[self.j("left_wrist"), self.j("right_wrist")]]

    @property
    def leg(self) -> np.ndarray:
        """Hip-to-ankle length with a straight knee, (left, right)."""
        return self.thigh + self.shin

    @property
    def hip_offsets(self) -> np.ndarray:
        """``(2, 3)`` pelvis-to-hip offsets in the pelvis frame (left, right)."""
        return self.rest_offsets[[self.j("left_hip"), self.j("right_hip")]]

    @property
    def shoulder_offsets(self) -> np.ndarray:
        """``(2, 3)`` spine3-to-shoulder offsets in the chest frame (collar + collar bone)."""
        out = []
        for side in ("left", "right"):
            out.append(self.rest_offsets[self.j(f"{side}_collar")] + self.rest_offsets[self.j(f"{side}_shoulder")])
        return np.stack(out)


@lru_cache(maxsize=None)
def body_model(skeleton: str | Skeleton = "humanml3d") -> BodyModel:
    """The body model of a skeleton that has target bone lengths (HumanML3D)."""
    sk = get_skeleton(skeleton)
    if sk.bone_lengths is None:
        raise ValueError(f"skeleton {sk.name!r} has no target bone lengths; the procedural corpus "
                         f"needs one that does (humanml3d)")
    index = {n: i for i, n in enumerate(sk.joint_names)}
    missing = sorted(set(_REST_DIRECTIONS) - set(index))
    if missing:
        raise ValueError(f"skeleton {sk.name!r} lacks joints {missing} used by the procedural body model")
    lengths = np.asarray(sk.bone_lengths, dtype=np.float64)
    offsets = np.asarray(sk.raw_offsets, dtype=np.float64) * lengths[:, None]
    for name, d in _REST_DIRECTIONS.items():
        j = index[name]
        d = np.asarray(d, dtype=np.float64)
        offsets[j] = d / np.linalg.norm(d) * lengths[j]
    offsets.setflags(write=False)
    lengths.setflags(write=False)
    return BodyModel(sk, index, offsets, lengths)


# ----------------------------------------------------------------------------- pose controls
@dataclass
class Pose:
    """Per-frame controls of a clip (N frames). Arrays are float64.

    Arm controls are in the chest frame and side-agnostic: x points *outwards* for both arms
    (the right arm is mirrored when assembled). ``arm`` holds (flex, abd, elbow) radians:
    flex > 0 swings the shoulder-to-wrist line forward, abd > 0 out to the side, elbow is the
    elbow flexion (0 = straight). ``arm_pole`` is the direction the elbow points to.
    """

    pelvis: np.ndarray      # (N, 3) pelvis position, world
    pelvis_ypr: np.ndarray  # (N, 3) pelvis yaw (heading), pitch (forward lean), roll
    spine: np.ndarray       # (N, 3) total spine bend (yaw, pitch, roll) relative to the pelvis
    neck: np.ndarray        # (N, 3) head rotation (yaw = look left, pitch = look down, roll)
    ankle: np.ndarray       # (N, 2, 3) ankle targets (left, right), world
    toe: np.ndarray         # (N, 2, 3) toe targets (left, right), world
    knee_pole: np.ndarray   # (N, 2, 3) direction the knees point to, world
    arm: np.ndarray         # (N, 2, 3) (flex, abd, elbow) per arm (left, right)
    arm_pole: np.ndarray    # (N, 2, 3) elbow pole per arm, chest frame, x outwards
    #: (N, 5, 3) extra local (yaw, pitch, roll) of each trunk joint (:data:`TRUNK_JOINTS`: spine1,
    #: spine2, spine3, neck base, head), laid after its share of ``spine`` / ``neck``; None = zeros.
    #: The shares alone bend the segments in lockstep (2.2: spine rotations varied 0.35-0.65x the
    #: real Std); this lets lumbar, thoracic and cervical segments bend each their own way.
    trunk: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = self.pelvis.shape[0]
        if self.trunk is None:
            self.trunk = np.zeros((n, len(TRUNK_JOINTS), 3))
        shapes = {"pelvis": (n, 3), "pelvis_ypr": (n, 3), "spine": (n, 3), "neck": (n, 3),
                  "ankle": (n, 2, 3), "toe": (n, 2, 3), "knee_pole": (n, 2, 3), "arm": (n, 2, 3),
                  "arm_pole": (n, 2, 3), "trunk": (n, len(TRUNK_JOINTS), 3)}
        for name, shape in shapes.items():
            got = getattr(self, name).shape
            if got != shape:
                raise ValueError(f"Pose.{name} must have shape {shape} for {n} frames, got {got}")

    @property
    def num_frames(self) -> int:
        return self.pelvis.shape[0]

    def slice(self, start: int, stop: int) -> "Pose":
        return Pose(**{f.name: getattr(self, f.name)[start:stop].copy() for f in fields(self)})

    @staticmethod
    def concat(poses: list["Pose"]) -> "Pose":
        return Pose(**{f.name: np.concatenate([getattr(p, f.name) for p in poses], 0) for f in fields(Pose)})

    def copy(self) -> "Pose":
        return Pose(**{f.name: getattr(self, f.name).copy() for f in fields(self)})


# ----------------------------------------------------------------------------- limb IK
def two_bone_ik(root: np.ndarray, target: np.ndarray, l1, l2, pole: np.ndarray,
                ) -> tuple[np.ndarray, np.ndarray]:
    """Middle and end joints of a two-bone chain reaching for ``target``.

    Parameters
    ----------
    root, target, pole : ndarray ``(N, 3)``
        Chain root, wanted end position and the direction the middle joint bends towards.
    l1, l2 : float
        Bone lengths.

    Returns
    -------
    mid, end : ndarray ``(N, 3)``
        ``|mid - root| = l1`` and ``|end - mid| = l2`` exactly. Out-of-reach targets are clamped
        onto the reachable shell along the root-to-target line.
    """
    d = target - root
    dist = np.linalg.norm(d, axis=-1)
    u = _unit(d, np.array([0.0, -1.0, 0.0]))
    reach = np.clip(dist, abs(l1 - l2) + 1e-6, (l1 + l2) * (1.0 - 1e-6))
    cos_a = np.clip((l1 ** 2 + reach ** 2 - l2 ** 2) / (2.0 * l1 * reach), -1.0, 1.0)
    sin_a = np.sqrt(1.0 - cos_a ** 2)
    v = pole - (pole * u).sum(-1, keepdims=True) * u
    # fall back to any perpendicular if the pole is parallel to the chain
    alt = np.cross(u, np.array([1.0, 0.0, 0.0]))
    alt = _unit(alt, np.array([0.0, 0.0, 1.0]))
    v = _unit(v, alt)
    mid = root + l1 * (cos_a[:, None] * u + sin_a[:, None] * v)
    end = root + reach[:, None] * u
    return mid, end


def arm_direction(flex, abd) -> np.ndarray:
    """Unit shoulder-to-wrist direction ``(..., 3)`` in the chest frame, x outwards.

    ``Rz(abd) Rx(-flex)`` applied to the hanging direction (0, -1, 0).
    """
    flex = np.asarray(flex, dtype=np.float64)
    abd = np.asarray(abd, dtype=np.float64)
    cf = np.cos(flex)
    return np.stack([cf * np.sin(abd), -cf * np.cos(abd), np.sin(flex)], -1)


def arm_angles_for_target(target, upper: float, fore: float) -> np.ndarray:
    """(flex, abd, elbow) that put the wrist at ``target`` (chest frame, from the shoulder, x out).

    Valid for targets not behind the shoulder's frontal plane's far side (|flex| <= 90 deg).
    """
    target = np.asarray(target, dtype=np.float64)
    dist = np.linalg.norm(target, axis=-1)
    dist = np.clip(dist, abs(upper - fore) + 1e-6, upper + fore - 1e-6)
    cos_e = np.clip((dist ** 2 - upper ** 2 - fore ** 2) / (2 * upper * fore), -1.0, 1.0)
    elbow = np.arccos(cos_e)
    d = target / np.linalg.norm(target, axis=-1, keepdims=True)
    flex = np.arcsin(np.clip(d[..., 2], -1.0, 1.0))
    abd = np.arctan2(d[..., 0], -d[..., 1])
    return np.stack([flex, abd, elbow], -1)


# ----------------------------------------------------------------------------- assembly
def trunk_frames(pose: Pose) -> tuple[np.ndarray, ...]:
    """World orientations ``(N, 3, 3)`` of spine1, spine2, spine3 (the chest), the neck and the head.

    Spine joint ``i`` turns by its share of ``pose.spine`` (:data:`SPINE_SHARE`) and then by its
    own ``pose.trunk[:, i]``; the neck base by :data:`NECK_SHARE` of ``pose.neck`` and
    ``trunk[:, 3]``, the head by the rest of ``pose.neck`` and ``trunk[:, 4]``. Each frame orients
    the bone to the next joint (spine1's frame the spine1 -> spine2 bone, ...).
    """
    g = ypr_matrix(pose.pelvis_ypr)
    out = []
    for i, share in enumerate(SPINE_SHARE):
        g = g @ ypr_matrix(pose.spine * share) @ ypr_matrix(pose.trunk[:, i])
        out.append(g)
    g = g @ ypr_matrix(pose.neck * NECK_SHARE) @ ypr_matrix(pose.trunk[:, 3])
    out.append(g)
    out.append(g @ ypr_matrix(pose.neck * (1.0 - NECK_SHARE)) @ ypr_matrix(pose.trunk[:, 4]))
    return tuple(out)


def assemble(pose: Pose, body: BodyModel | None = None, keep_toes: bool = False) -> np.ndarray:
    """Joint positions ``(N, J, 3)`` of a :class:`Pose` (float64).

    Torso: ``p_child = p_joint + G_joint @ rest_offset_child`` with ``G_joint = G_parent @ R_joint``.
    Limbs: two-bone IK (legs to the ankle targets with the knee poles, arms to the wrist targets
    given by the arm controls), then the toe at the foot length along the toe target direction.

    ``keep_toes``: where the ankle's range of motion (:func:`clamp_ankle`) would push a toe below
    its target (a shin leaning far over a flat foot), lift the heel about the toe target instead
    and solve the leg again, so the toe stays where it was put (2.1; a few run steps of slow
    runners sank the toe 0.4-1.2 cm and slid it).
    """
    body = body or body_model("humanml3d")
    j = body.j
    off = body.rest_offsets
    n = pose.num_frames
    out = np.zeros((n, body.skeleton.num_joints, 3))

    g0 = ypr_matrix(pose.pelvis_ypr)                                   # (N, 3, 3) pelvis frame
    out[:, j("pelvis")] = pose.pelvis
    for side in ("left", "right"):
        out[:, j(f"{side}_hip")] = pose.pelvis + g0 @ off[j(f"{side}_hip")]

    # spine, neck and head: the bends shared over the joints (lumbar first), each joint's own on top
    frames = trunk_frames(pose)
    prev = j("pelvis")
    for name, g in zip(("spine1", "spine2", "spine3"), (g0,) + frames[:2]):
        out[:, j(name)] = out[:, prev] + g @ off[j(name)]
        prev = j(name)
    chest, g_neck, g_head = frames[2], frames[3], frames[4]            # spine3's, neck's, head's frames
    sp3 = out[:, j("spine3")]
    out[:, j("neck")] = sp3 + g_neck @ off[j("neck")]
    out[:, j("head")] = out[:, j("neck")] + g_head @ off[j("head")]

    # arms (chest frame, mirrored for the right arm)
    for k, side in enumerate(("left", "right")):
        sign = np.array([1.0, 1.0, 1.0]) if k == 0 else np.array([-1.0, 1.0, 1.0])
        collar = sp3 + chest @ off[j(f"{side}_collar")]
        shoulder = collar + chest @ off[j(f"{side}_shoulder")]
        out[:, j(f"{side}_collar")] = collar
        out[:, j(f"{side}_shoulder")] = shoulder
        up, fo = body.upper_arm[k], body.forearm[k]
        flex, abd, elbow = pose.arm[:, k, 0], pose.arm[:, k, 1], pose.arm[:, k, 2]
        reach = np.sqrt(up ** 2 + fo ** 2 + 2 * up * fo * np.cos(elbow))
        d_local = arm_direction(flex, abd) * sign
        wrist_t = shoulder + (chest @ (d_local * reach[:, None])[..., None])[..., 0]
        pole = (chest @ (pose.arm_pole[:, k] * sign)[..., None])[..., 0]
        elbow_p, wrist = two_bone_ik(shoulder, wrist_t, up, fo, pole)
        out[:, j(f"{side}_elbow")] = elbow_p
        out[:, j(f"{side}_wrist")] = wrist

    # legs: IK to the ankle targets; the toe keeps its target direction at the exact foot length,
    # turned back into the ankle's range of motion if the leg pose asks too much of it
    for k, side in enumerate(("left", "right")):
        hip = out[:, j(f"{side}_hip")]
        target = pose.ankle[:, k].copy()
        toe_t = pose.toe[:, k]
        length = body.foot[k]
        for _ in range(4 if keep_toes else 1):
            knee, ankle = two_bone_ik(hip, target, body.thigh[k], body.shin[k], pose.knee_pole[:, k])
            want = _unit(toe_t - target, np.array([0.0, 0.0, 1.0]))
            foot_dir = clamp_ankle(knee - ankle, want)
            sink = toe_t[:, 1] - (ankle + foot_dir * length)[:, 1]
            bad = sink > 1e-4
            if not keep_toes or not bad.any():
                break
            # pitch the foot further toe-down about the toe target by the angle that lifts the toe back
            pitch = np.arcsin(np.clip(-want[bad, 1], -1.0, 1.0)) + np.arcsin(np.clip(sink[bad] / length, 0.0, 1.0)) + 0.02
            yaw = np.arctan2(want[bad, 0], want[bad, 2])
            target[bad] = toe_t[bad] - foot_vector(yaw, pitch, np.full(bad.sum(), length))
        out[:, j(f"{side}_knee")] = knee
        out[:, j(f"{side}_ankle")] = ankle
        out[:, j(f"{side}_foot")] = ankle + foot_dir * body.foot[k]
    return out


#: Range of the angle between the shin (ankle to knee) and the foot (ankle to toe), degrees:
#: about 25 deg of dorsiflexion and 55 deg of plantarflexion around the standing 105 deg.
ANKLE_RANGE = (68.0, 160.0)


def clamp_ankle(shin: np.ndarray, foot_dir: np.ndarray, limits: tuple[float, float] = ANKLE_RANGE) -> np.ndarray:
    """Rotate unit foot directions ``(N, 3)`` towards or away from the shin ``(N, 3)`` so that
    the shin-to-foot angle stays within ``limits`` (degrees); feet within the range are unchanged."""
    s = _unit(shin, np.array([0.0, 1.0, 0.0]))
    cos = np.clip((s * foot_dir).sum(-1), -1.0, 1.0)
    ang = np.arccos(cos)
    lo, hi = np.radians(limits[0]), np.radians(limits[1])
    target = np.clip(ang, lo, hi)
    perp = _unit(foot_dir - cos[:, None] * s, np.array([0.0, 0.0, 1.0]))
    fixed = np.cos(target)[:, None] * s + np.sin(target)[:, None] * perp
    return np.where((np.abs(target - ang) > 1e-9)[:, None], fixed, foot_dir)
