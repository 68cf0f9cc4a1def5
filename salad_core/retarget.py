"""Move a motion from one rig's rigid torso geometry to another's, keeping every limb.

HumanML3D's joints are those of SMPL bodies, so its rigid torso relations are fixed for every clip: the
hips hang about 58 degrees below the line between them, the spine and collars keep SMPL's rest angles.
Motion capture of another rig (DeepMimic's humanoid: hips level with the pelvis, a straight spine; a BVH
file's rig) brings other rigid relations; the VAE, which has only ever seen SMPL's, "corrects" them (the
DeepMimic hips came back 9-11 cm off, the root height about 6 cm: ``lab/docs/vae_real_motion.md``).
:func:`rerig` re-poses such a motion on the target rig:

* the torso's two rigid segments (:data:`SEGMENTS`: the pelvis with the hips and the lower spine; the
  chest with the upper spine, neck, collars and shoulders) each get a rotation per frame, fitted
  (Kabsch) to the source bones of the segment against the source rig's rest directions; the target
  rig's rest directions are laid in that rotation;
* the head turns from the chest as it does in the source;
* every other bone (thighs, shins, feet, upper arms, forearms) keeps its direction per frame;
* bones get the target lengths, the root stays where it was.

Rest directions are ``(J, 3)`` unit vectors of the bone ending at each joint (parent -> joint; the root's
is 0) in a rest pose facing +Z with +Y up (:func:`rest_directions` of a rest pose;
:func:`smpl_rest_directions` for HumanML3D's own geometry).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from salad_core.skeleton import Skeleton, get_skeleton

__all__ = ["SEGMENTS", "bone_directions", "rest_directions", "smpl_rest_directions", "kabsch", "swing", "rerig"]

#: Rigid segments of the torso for :func:`rerig`: ``(fit, emit)`` joints. A segment's rotation is fitted to
#: the bones ending at ``fit``; the bones ending at ``emit`` are laid along the target rest directions in it.
SEGMENTS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "pelvis": (("left_hip", "right_hip", "spine1"), ("left_hip", "right_hip", "spine1", "spine2")),
    "chest": (("spine3", "left_collar", "right_collar"),
              ("spine3", "neck", "left_collar", "right_collar", "left_shoulder", "right_shoulder")),
}


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def bone_directions(joints: np.ndarray, skeleton: str | Skeleton = "humanml3d") -> np.ndarray:
    """Unit direction ``(..., J, 3)`` of the bone ending at each joint of ``joints (..., J, 3)`` (the root's is 0)."""
    sk = get_skeleton(skeleton)
    j = np.asarray(joints, dtype=np.float64)
    out = np.zeros_like(j)
    out[..., 1:, :] = _unit(j[..., 1:, :] - j[..., np.asarray(sk.parents[1:]), :])
    return out


def rest_directions(rest_pose: np.ndarray, skeleton: str | Skeleton = "humanml3d") -> np.ndarray:
    """Rest directions ``(J, 3)`` of a rig from one rest pose ``(J, 3)`` (facing +Z, +Y up)."""
    pose = np.asarray(rest_pose, dtype=np.float64)
    if pose.ndim != 2 or pose.shape[1] != 3:
        raise ValueError(f"rest_pose must be (J, 3), got {pose.shape}")
    return bone_directions(pose, skeleton)


@lru_cache(maxsize=None)
def _smpl_rest(skeleton_name: str) -> np.ndarray:
    from salad_core.data.procedural.kinematics import body_model

    off = np.asarray(body_model(skeleton_name).rest_offsets, dtype=np.float64)
    out = np.zeros_like(off)
    out[1:] = _unit(off[1:])
    out.setflags(write=False)
    return out


def smpl_rest_directions(skeleton: str = "humanml3d") -> np.ndarray:
    """Rest directions ``(J, 3)`` of HumanML3D's (SMPL's) geometry, from the procedural body model."""
    return _smpl_rest(skeleton).copy()


def kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Rotations ``(N, 3, 3)`` that best map the vectors ``src (K, 3)`` onto ``dst (N, K, 3)`` (least squares)."""
    h = np.einsum("ki,nkj->nij", np.asarray(src, np.float64), np.asarray(dst, np.float64))
    u, _, vt = np.linalg.svd(h)
    v, ut = np.transpose(vt, (0, 2, 1)), np.transpose(u, (0, 2, 1))
    fix = np.broadcast_to(np.eye(3), h.shape).copy()
    fix[:, 2, 2] = np.sign(np.linalg.det(v @ ut))           # a rotation, never a reflection
    return v @ fix @ ut


def swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotations ``(N, 3, 3)`` taking unit vectors ``a (N, 3)`` onto ``b (N, 3)`` (``a != -b``)."""
    a, b = _unit(np.asarray(a, np.float64)), _unit(np.asarray(b, np.float64))
    v, c = np.cross(a, b), (a * b).sum(-1)
    kx = np.zeros(a.shape[:-1] + (3, 3))
    kx[..., 0, 1], kx[..., 0, 2], kx[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    kx = kx - np.swapaxes(kx, -1, -2)
    return np.eye(3) + kx + kx @ kx / np.maximum(1.0 + c, 1e-9)[..., None, None]


def rerig(joints: np.ndarray, src_dirs: np.ndarray, dst_dirs: np.ndarray, skeleton: str | Skeleton = "humanml3d",
          lengths: np.ndarray | None = None) -> np.ndarray:
    """A motion ``(N, J, 3)`` of the source rig re-posed on the target rig (see the module docstring).

    Parameters
    ----------
    joints : array ``(N, J, 3)``
        The motion on the source rig (metres, +Y up).
    src_dirs, dst_dirs : array ``(J, 3)``
        Rest directions of the source and the target rig.
    lengths : array ``(J,)``, optional
        Bone lengths of the result (default: the skeleton's target lengths).

    Returns
    -------
    array ``(N, J, 3)``, float64: the root unchanged, every limb bone in its source direction.
    """
    sk = get_skeleton(skeleton)
    ix = {n: i for i, n in enumerate(sk.joint_names)}
    j = np.asarray(joints, dtype=np.float64)
    if j.ndim != 3 or j.shape[1:] != (sk.num_joints, 3):
        raise ValueError(f"joints must be (N, {sk.num_joints}, 3), got {j.shape}")
    src, dst = np.asarray(src_dirs, np.float64), np.asarray(dst_dirs, np.float64)
    for name, d in (("src_dirs", src), ("dst_dirs", dst)):
        if d.shape != (sk.num_joints, 3):
            raise ValueError(f"{name} must be ({sk.num_joints}, 3), got {d.shape}")
    d = bone_directions(j, sk)
    rot = {seg: kabsch(src[[ix[n] for n in fit]], d[:, [ix[n] for n in fit]]) for seg, (fit, _) in SEGMENTS.items()}
    h = ix["head"]
    head_rot = swing(np.einsum("nij,j->ni", rot["chest"], src[h]), d[:, h]) @ rot["chest"]
    new_d = d.copy()
    for seg, (_, emit) in SEGMENTS.items():
        for n in emit:
            new_d[:, ix[n]] = np.einsum("nij,j->ni", rot[seg], dst[ix[n]])
    new_d[:, h] = np.einsum("nij,j->ni", head_rot, dst[h])
    length = np.asarray(sk.bone_lengths if lengths is None else lengths, np.float64)
    out = np.zeros_like(j)
    out[:, 0] = j[:, 0]
    for c in range(1, sk.num_joints):
        out[:, c] = out[:, sk.parents[c]] + new_d[:, c] * length[c]
    return out
