"""How much each of the 7 body parts moves: per-part speeds of joint positions (numpy in, numpy out).

Shared by the procedural corpus's checks (is a phrase's annotated part the one that moves?) and by
the attention measurements (:mod:`salad_core.attention.measure`: does a mirroring edit swap the
busy side?), so neither depends on the other.

Part activity (m/s) is the speed of the part's fastest joint, each part measured in its own
reference frame so that it says what the part itself does:

* root: the pelvis in the world (speed) plus its yaw rate times :data:`YAW_LEVER` (0.5 m), so
  turning on the spot counts as root motion;
* legs and spine: joints relative to the pelvis, in the heading frame of the hips;
* arms and head: joints relative to spine3, in the chest frame (the collars), so that bending the
  trunk does not count as arm motion.

Joints are ``(N, J, 3)`` (Y up, metres) at the skeleton's frame rate; parts are in the order of
:data:`salad_core.skeleton.PART_NAMES`.
"""
from __future__ import annotations

import numpy as np

from salad_core.skeleton import PART_NAMES, Skeleton, get_skeleton

__all__ = ["YAW_LEVER", "heading_frames", "chest_frames", "part_speeds", "part_activity"]

#: Lever arm (m) that turns the root's yaw rate into a speed.
YAW_LEVER = 0.5


def _idx(sk: Skeleton, name: str) -> int:
    return sk.joint_names.index(name)


def heading_frames(joints: np.ndarray, skeleton: str | Skeleton = "humanml3d") -> np.ndarray:
    """``(N, 3, 3)`` rows = (left, up, forward) unit axes of the hips' heading (yaw only, Y up)."""
    sk = get_skeleton(skeleton)
    joints = np.asarray(joints, dtype=np.float64)
    across = joints[:, _idx(sk, "left_hip")] - joints[:, _idx(sk, "right_hip")]
    across[:, 1] = 0.0
    across /= np.maximum(np.linalg.norm(across, axis=-1, keepdims=True), 1e-9)
    up = np.broadcast_to(np.array([0.0, 1.0, 0.0]), across.shape)
    fwd = np.cross(across, up)
    return np.stack([across, up, fwd], 1)


def chest_frames(joints: np.ndarray, skeleton: str | Skeleton = "humanml3d") -> np.ndarray:
    """``(N, 3, 3)`` rows = (left, up, forward) unit axes of the chest, from spine3 and the collars."""
    sk = get_skeleton(skeleton)
    joints = np.asarray(joints, dtype=np.float64)
    lc, rc = joints[:, _idx(sk, "left_collar")], joints[:, _idx(sk, "right_collar")]
    x = lc - rc
    x /= np.maximum(np.linalg.norm(x, axis=-1, keepdims=True), 1e-9)
    up = 0.5 * (lc + rc) - joints[:, _idx(sk, "spine3")]
    z = np.cross(x, up)
    z /= np.maximum(np.linalg.norm(z, axis=-1, keepdims=True), 1e-9)
    y = np.cross(z, x)
    return np.stack([x, y, z], 1)


def part_speeds(joints: np.ndarray, skeleton: str | Skeleton = "humanml3d") -> np.ndarray:
    """``(N-1, P)`` speed (m/s) of each body part's fastest joint between consecutive frames.

    Parameters
    ----------
    joints : array ``(N, J, 3)``
        Metres, Y up, at ``skeleton.fps``; ``N >= 2``.
    skeleton : str or Skeleton

    Returns
    -------
    array ``(N-1, P)`` float64
        Column ``p`` is part ``PART_NAMES[p]``, measured in its own frame (see the module docstring).
    """
    sk = get_skeleton(skeleton)
    joints = np.asarray(joints, dtype=np.float64)
    if joints.ndim != 3 or joints.shape[1:] != (sk.num_joints, 3) or len(joints) < 2:
        raise ValueError(f"joints must be (N >= 2, {sk.num_joints}, 3) positions of {sk.name!r}, "
                         f"got shape {joints.shape}")
    fps = sk.fps
    n = joints.shape[0]
    pelvis = joints[:, 0]
    head = heading_frames(joints, sk)
    chest = chest_frames(joints, sk)
    in_pelvis = np.einsum("nij,nkj->nki", head, joints - pelvis[:, None])
    anchor = joints[:, _idx(sk, "spine3")]
    in_chest = np.einsum("nij,nkj->nki", chest, joints - anchor[:, None])
    out = np.zeros((n - 1, len(PART_NAMES)))
    for p, name in enumerate(PART_NAMES):
        members = [j for j, q in enumerate(sk.joint_to_part) if q == p]
        if name == "root":
            lin = np.linalg.norm(np.diff(pelvis, axis=0), axis=-1) * fps
            yaw = np.arctan2(head[:, 2, 0], head[:, 2, 2])
            dyaw = np.abs((np.diff(yaw) + np.pi) % (2 * np.pi) - np.pi) * fps
            out[:, p] = lin + YAW_LEVER * dyaw
            continue
        local = in_chest if name in ("left arm", "right arm", "head") else in_pelvis
        sp = np.linalg.norm(np.diff(local[:, members], axis=0), axis=-1) * fps      # (N-1, m)
        out[:, p] = sp.max(-1)
    return out


def part_activity(joints: np.ndarray | None, frames: tuple[int, int] | None = None,
                  skeleton: str | Skeleton = "humanml3d", speeds: np.ndarray | None = None) -> np.ndarray:
    """``(P,)`` mean part speed (m/s) over frames ``[f0, f1)`` (all frames by default).

    ``speeds`` (``(N-1, P)`` from :func:`part_speeds`) skips recomputing them; ``joints`` may then
    be None. An empty interval gives zeros.
    """
    s = part_speeds(joints, skeleton) if speeds is None else speeds
    if frames is None:
        return s.mean(0)
    f0, f1 = int(frames[0]), min(int(frames[1]), s.shape[0])
    if f1 <= f0:
        return np.zeros(s.shape[1])
    return s[f0:f1].mean(0)
