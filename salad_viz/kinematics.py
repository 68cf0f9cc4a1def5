"""Rotations from joint positions (for BVH), forward kinematics and a T-pose rest skeleton.

BVH stores one rotation per joint that turns *all* of its children's rest offsets, plus the root
position. HumanML3D joints only give positions, so :func:`solve_rotations` recovers rotations:

* **Rest pose.** A T-pose: bone directions from the skeleton's raw offsets, except that arms point
  sideways and the head points up (HumanML3D's raw offsets hang the arms down and point the head
  forward, which imports into Blender as an odd rest pose). Bone lengths are the motion's median
  lengths (or the skeleton's target lengths).
* **Joints with several children** (pelvis -> hips and spine1, spine3 -> neck and collars; KIT's
  root and chest). Their children move as one rigid body in HumanML3D data and in the pipeline's
  ``"fit"`` recovery, but not at the rest angles of the raw offsets. So the rest offsets of these
  children are the motion's own rigid geometry: the Procrustes mean of the children's offsets over
  the frames (:func:`procrustes_mean`; frame 0's geometry when the group is rigid), turned as a
  whole as close as possible to the T-pose directions. The joint's rotation is then the
  least-squares (Kabsch) rotation mapping the rest offsets onto the observed ones: exact for a
  rigid group, the least-squares compromise for a group that is not.
* **Joints with one child.** The rotation is the *swing* that moves the rest bone direction (as
  carried by the parent) onto the observed direction, with zero twist relative to the parent:
  positions do not constrain twist, and zero relative twist keeps limbs from spinning; a (nearly)
  half-turn swing, whose smallest-swing axis is undefined, keeps the previous frame's axis, so the
  twist stays continuous over time.
* **Leaves** copy their parent's rotation (no child to orient).

Each rotation aims from where the BVH puts the joint (the forward kinematics of the rotations
solved so far), not from the input's own position of it, so a joint the rigid skeleton cannot
reach exactly does not pass its error down the chain.

Forward kinematics of the result reproduces the input to float precision when bone lengths are
constant and multi-child groups are rigid (real HumanML3D data, the ``"fit"`` recovery);
otherwise the residual is the deviation from that, which :func:`fk_error` / :func:`fk_errors`
report.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from salad_core.skeleton import PART_NAMES, Skeleton, get_skeleton

__all__ = [
    "SolvedMotion",
    "rest_directions",
    "rest_pose",
    "children_of",
    "forward_kinematics",
    "solve_rotations",
    "fk_error",
    "fk_errors",
    "procrustes_mean",
    "swing_rotation",
    "kabsch",
    "axis_angle_matrix",
]


def children_of(skeleton: Skeleton) -> tuple[tuple[int, ...], ...]:
    """Children of each joint, in index order."""
    kids: list[list[int]] = [[] for _ in range(skeleton.num_joints)]
    for j, p in enumerate(skeleton.parents):
        if p >= 0:
            kids[p].append(j)
    return tuple(tuple(k) for k in kids)


def rest_directions(skeleton: str | Skeleton = "humanml3d", *, arms: str = "t") -> np.ndarray:
    """``(J, 3)`` unit rest direction of the bone parent->j (root row is zero).

    Parameters
    ----------
    skeleton : str or Skeleton
    arms : {"t", "down"}
        ``"t"``: every arm bone points sideways (T-pose, the BVH rest pose). ``"down"``: the upper
        and lower arm (the last two bones of each arm chain) hang down, the collar stays sideways.
        Bones of the head part always point up; other bones follow the raw offsets.
    """
    skel = get_skeleton(skeleton)
    if arms not in ("t", "down"):
        raise ValueError(f"arms must be 't' or 'down', got {arms!r}")
    raw = np.asarray(skel.raw_offsets, dtype=np.float64)
    arm_parts = {PART_NAMES.index("left arm"), PART_NAMES.index("right arm")}
    head_part = PART_NAMES.index("head")
    out = raw.copy()
    for j in range(1, skel.num_joints):
        if skel.joint_to_part[j] == head_part:
            out[j] = (0.0, 1.0, 0.0)
    for chain in skel.kinematic_chains:
        limb = [j for j in chain[1:] if skel.joint_to_part[j] in arm_parts]
        if not limb:
            continue
        lateral = next((np.sign(raw[j, 0]) for j in limb if abs(raw[j, 0]) > 0.5), 1.0)
        for k, j in enumerate(limb):
            hang = arms == "down" and k >= len(limb) - 2
            out[j] = (0.0, -1.0, 0.0) if hang else (lateral, 0.0, 0.0)
    norms = np.linalg.norm(out, axis=1, keepdims=True)
    return np.where(norms > 0, out / np.where(norms > 0, norms, 1.0), 0.0)


def rest_pose(skeleton: str | Skeleton = "humanml3d", *, arms: str = "t", bone_lengths=None) -> np.ndarray:
    """``(J, 3)`` joint positions of the rest pose, feet on the floor (min y = 0), root at x = z = 0.

    ``bone_lengths`` (``(J,)``, root entry ignored) defaults to the skeleton's target lengths.
    """
    skel = get_skeleton(skeleton)
    if bone_lengths is None:
        if skel.bone_lengths is None:
            raise ValueError(f"skeleton {skel.name!r} has no target bone lengths; pass bone_lengths=")
        bone_lengths = skel.bone_lengths
    lengths = np.asarray(bone_lengths, dtype=np.float64)
    if lengths.shape != (skel.num_joints,):
        raise ValueError(f"bone_lengths must have shape ({skel.num_joints},), got {lengths.shape}")
    offsets = rest_directions(skel, arms=arms) * lengths[:, None]
    pos = np.zeros((skel.num_joints, 3))
    for j, p in enumerate(skel.parents):
        if p >= 0:
            pos[j] = pos[p] + offsets[j]
    pos[:, 1] -= pos[:, 1].min()
    return pos


# --------------------------------------------------------------------------- rotation helpers
def axis_angle_matrix(axis, angle) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` about unit ``axis`` ``(..., 3)`` by ``angle`` radians ``(...)``."""
    axis = np.asarray(axis, dtype=np.float64)
    angle = np.asarray(angle, dtype=np.float64)
    axis, angle = np.broadcast_arrays(axis, angle[..., None])
    angle = angle[..., 0]
    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    c, s = np.cos(angle), np.sin(angle)
    t = 1.0 - c
    return np.stack([
        np.stack([t * x * x + c, t * x * y - s * z, t * x * z + s * y], -1),
        np.stack([t * x * y + s * z, t * y * y + c, t * y * z - s * x], -1),
        np.stack([t * x * z - s * y, t * y * z + s * x, t * z * z + c], -1),
    ], -2)


def swing_rotation(a, b) -> np.ndarray:
    """Smallest rotations ``(..., 3, 3)`` taking unit vectors ``a`` onto unit vectors ``b`` (``(..., 3)``)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    a, b = np.broadcast_arrays(a, b)
    v = np.cross(a, b)
    c = np.sum(a * b, axis=-1)
    s = np.linalg.norm(v, axis=-1)
    axis = np.where(s[..., None] > 1e-9, v / np.maximum(s, 1e-12)[..., None], 0.0)
    # antiparallel vectors: any axis perpendicular to a works; pick one deterministically
    opposite = (s <= 1e-9) & (c < 0)
    if opposite.any():
        helper = np.where(np.abs(a[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
        perp = np.cross(a, helper)
        perp /= np.linalg.norm(perp, axis=-1, keepdims=True)
        axis = np.where(opposite[..., None], perp, axis)
    angle = np.arctan2(s, c)
    return axis_angle_matrix(axis, angle)


def kabsch(rest, observed) -> np.ndarray:
    """Rotations ``(N, 3, 3)`` best mapping ``rest`` ``(K, 3)`` onto ``observed`` ``(N, K, 3)`` (least squares)."""
    h = np.einsum("ki,nkj->nij", rest, observed)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.einsum("nji,nkj->nik", vt, u)))
    d = np.where(d == 0, 1.0, d)
    corr = np.zeros_like(h)
    corr[:, 0, 0] = 1.0
    corr[:, 1, 1] = 1.0
    corr[:, 2, 2] = d
    # R = V diag(1, 1, d) U^T
    return np.einsum("nji,njk,nlk->nil", vt, corr, u)


# --------------------------------------------------------------------------- FK / IK
@dataclass(frozen=True)
class SolvedMotion:
    """A motion as rest offsets plus per-frame rotations: what a BVH file stores."""

    offsets: np.ndarray          # (J, 3) rest offset of each joint from its parent (root row 0)
    end_sites: dict              # leaf joint -> (3,) offset of its End Site
    rotations: np.ndarray        # (N, J, 3, 3) local rotation of each joint (relative to its parent)
    root_positions: np.ndarray   # (N, 3) world position of the root
    parents: tuple[int, ...]     # parent index per joint


def forward_kinematics(offsets, parents, rotations, root_positions) -> np.ndarray:
    """World joint positions ``(N, J, 3)``.

    Parameters
    ----------
    offsets : array (J, 3)
        Rest offset of each joint in its parent's frame.
    parents : sequence of int
        Parent per joint (-1 for the root), topologically ordered.
    rotations : array (N, J, 3, 3)
        Local rotation of each joint; joint j's world rotation is its parent's times its own, and a
        child sits at ``parent_position + parent_world_rotation @ offset``.
    root_positions : array (N, 3)
    """
    rot = np.asarray(rotations, dtype=np.float64)
    off = np.asarray(offsets, dtype=np.float64)
    n, j = rot.shape[:2]
    world = np.empty_like(rot)
    pos = np.empty((n, j, 3))
    for k, p in enumerate(parents):
        if p < 0:
            world[:, k] = rot[:, k]
            pos[:, k] = root_positions
        else:
            world[:, k] = world[:, p] @ rot[:, k]
            pos[:, k] = pos[:, p] + world[:, p] @ off[k]
    return pos


def _measured_lengths(joints: np.ndarray, parents) -> np.ndarray:
    lengths = np.zeros(joints.shape[1])
    for j, p in enumerate(parents):
        if p >= 0:
            lengths[j] = float(np.median(np.linalg.norm(joints[:, j] - joints[:, p], axis=-1)))
    return lengths


def procrustes_mean(vectors, *, iterations: int = 20, tol: float = 1e-12) -> np.ndarray:
    """The rigid template ``(K, 3)`` best fitting per-frame vectors ``(N, K, 3)`` up to a rotation per frame.

    Generalised Procrustes without scaling: start from frame 0, rotate every frame onto the template
    (Kabsch), average, repeat until the template stops moving. When the vectors are one rigid body
    turned per frame (``vectors[t] = R_t @ template``) the result is frame 0's geometry exactly;
    otherwise it is the least-squares rigid body, so that the per-frame fit spreads the residual
    over all the vectors instead of putting it on some of them.
    """
    vec = np.asarray(vectors, dtype=np.float64)
    tmpl = vec[0].copy()
    for _ in range(iterations):
        rot = kabsch(tmpl, vec)                                          # (N, 3, 3): template -> frame
        new = np.einsum("nji,nkj->nki", rot, vec).mean(axis=0)          # frames turned back, averaged
        done = float(np.abs(new - tmpl).max()) <= tol * max(1.0, float(np.abs(tmpl).max()))
        tmpl = new
        if done:
            break
    return tmpl


def _group_rest_offsets(joints: np.ndarray, joint: int, kids, rest_dirs: np.ndarray, lengths: np.ndarray | None):
    """Rest offsets of a multi-child joint's children: the motion's own rigid geometry (the
    Procrustes mean of the children's offsets, :func:`procrustes_mean`), turned as a whole as close
    as possible onto the T-pose directions. ``lengths`` (``(J,)``) rescales each offset to a given
    length (``None``: keep the motion's)."""
    vecs = joints[:, list(kids)] - joints[:, joint][:, None]                 # (N, K, 3)
    tmpl = procrustes_mean(vecs)                                             # (K, 3)
    norm = np.maximum(np.linalg.norm(tmpl, axis=-1, keepdims=True), 1e-12)
    # turn the measured group as close as possible onto the T-pose directions (one rotation)
    align = kabsch(tmpl / norm, rest_dirs[list(kids)][None])[0]
    out = {}
    for i, c in enumerate(kids):
        off = align @ tmpl[i]
        if lengths is not None:
            off = off / norm[i, 0] * lengths[c]
        out[c] = off
    return out


def solve_rotations(joints, skeleton: str | Skeleton = "humanml3d", *, lengths: str = "motion") -> SolvedMotion:
    """Rest offsets and per-frame local rotations that reproduce joint positions (see module doc).

    Parameters
    ----------
    joints : array (N, J, 3)
        Joint positions in metres.
    skeleton : str or Skeleton
    lengths : {"motion", "target"}
        Bone lengths of the rest offsets: the motion's own (median lengths of the single-child
        bones, the rigid geometry of the branches: exact FK for any skeleton scale) or the
        skeleton's target lengths (directions as with ``"motion"``).

    Returns
    -------
    SolvedMotion
    """
    from ._arrays import as_joints

    skel = get_skeleton(skeleton)
    pos = as_joints(joints, skel)
    parents = skel.parents
    kids = children_of(skel)
    if lengths == "motion":
        bone = _measured_lengths(pos, parents)
    elif lengths == "target":
        if skel.bone_lengths is None:
            raise ValueError(f"skeleton {skel.name!r} has no target bone lengths; use lengths='motion'")
        bone = np.asarray(skel.bone_lengths, dtype=np.float64)
    else:
        raise ValueError(f"lengths must be 'motion' or 'target', got {lengths!r}")
    dirs = rest_directions(skel, arms="t")
    offsets = dirs * bone[:, None]
    for j, ch in enumerate(kids):
        if len(ch) >= 2:
            group = _group_rest_offsets(pos, j, ch, dirs, None if lengths == "motion" else bone)
            for c, off in group.items():
                offsets[c] = off
    n, J = pos.shape[:2]
    world = np.empty((n, J, 3, 3))
    # where the file puts each joint: rotations aim from these (not from the input's own parent
    # position), so that a joint the rigid skeleton cannot reach exactly does not pass its error on
    placed = np.empty_like(pos)
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    for j in range(J):
        p = parents[j]
        parent_world = eye if p < 0 else world[:, p]
        placed[:, j] = pos[:, j] if p < 0 else placed[:, p] + np.einsum("nab,b->na", world[:, p], offsets[j])
        ch = kids[j]
        if len(ch) >= 2:
            observed = pos[:, list(ch)] - placed[:, j][:, None]
            world[:, j] = kabsch(offsets[list(ch)], observed)
        elif len(ch) == 1:
            c = ch[0]
            v = pos[:, c] - placed[:, j]
            norm = np.linalg.norm(v, axis=-1, keepdims=True)
            carried = parent_world @ (offsets[c] / max(np.linalg.norm(offsets[c]), 1e-12))
            target = np.where(norm > 1e-9, v / np.maximum(norm, 1e-12), carried)
            world[:, j] = _continuous_swing(carried, target) @ parent_world
        else:
            world[:, j] = parent_world
    local = np.empty_like(world)
    for j in range(J):
        p = parents[j]
        local[:, j] = world[:, j] if p < 0 else np.swapaxes(world[:, p], -1, -2) @ world[:, j]
    end_sites = {j: dirs[j] * max(0.04, 0.5 * bone[j]) for j in range(1, J) if not kids[j]}
    return SolvedMotion(offsets=offsets, end_sites=end_sites, rotations=local,
                        root_positions=pos[:, 0].copy(), parents=tuple(parents))


def _continuous_swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`swing_rotation` of unit vectors ``a`` onto ``b`` ``(N, 3)``, with the axis of
    (nearly) half-turn swings, where the smallest swing's axis is undefined, taken from the
    previous frame's axis so that the joint does not spin about its bone from one frame to the next."""
    rot = swing_rotation(a, b)
    c = np.sum(a * b, axis=-1)
    s = np.linalg.norm(np.cross(a, b), axis=-1)
    flip = np.nonzero((c < 0) & (s < 1e-3))[0]
    if flip.size == 0:
        return rot
    axes = np.cross(a, b)
    axes /= np.maximum(np.linalg.norm(axes, axis=-1, keepdims=True), 1e-12)
    for t in flip:
        if t == 0:
            continue
        prev = axes[t - 1] - np.dot(axes[t - 1], a[t]) * a[t]      # last frame's axis, perpendicular to a
        if np.linalg.norm(prev) < 1e-6:
            continue
        prev /= np.linalg.norm(prev)
        turn = axis_angle_matrix(prev, np.arctan2(s[t], c[t]))
        # the rotation about ``prev`` by the swing angle takes a close to b; finish with the tiny swing
        rot[t] = swing_rotation(turn @ a[t], b[t]) @ turn
        axes[t] = prev
    return rot


def fk_errors(solved: SolvedMotion, joints) -> np.ndarray:
    """Distances ``(N, J)`` in metres between ``joints`` ``(N, J, 3)`` and the FK of ``solved``."""
    rec = forward_kinematics(solved.offsets, solved.parents, solved.rotations, solved.root_positions)
    return np.linalg.norm(rec - np.asarray(joints, dtype=np.float64), axis=-1)


def fk_error(solved: SolvedMotion, joints) -> float:
    """Largest distance in metres between ``joints`` ``(N, J, 3)`` and the FK of ``solved``."""
    rec = forward_kinematics(solved.offsets, solved.parents, solved.rotations, solved.root_positions)
    return float(np.linalg.norm(rec - np.asarray(joints, dtype=np.float64), axis=-1).max())
