"""HumanML3D motion representation: joints <-> 263-d (KIT: 251-d) features, mirroring, normalisation.

The feature vector (``humanml3d_eval_facts`` §2.1, slices in ``Skeleton.feature_slices``) per frame:
root yaw velocity (half angle), root linear velocity (x, z in the heading frame), root height,
rotation-invariant joint coordinates ("ric", joints 1..J-1), chain-local swing rotations as cont6d
(joints 1..J-1), local joint velocities (all J joints) and 4 binary foot contacts.

:func:`joints_to_features` reproduces HumanML3D's ``process_file`` including its quirks (§2.3-2.4):
the sign slip of the hip term in the IK heading, the sigma-20 Gaussian smoothing of the forward
direction, the identity heading forced on frame 0 and the arm chains that restart from the root
rotation. It is vectorised over frames (the only Python loops run over joints or chains).

:func:`features_to_joints` is the standard ``recover_from_ric`` and works on numpy arrays and
(differentiably) on torch tensors with any leading batch axes.

Axes: joints ``(N, J, 3)`` (frames, joints, xyz; Y up, metres for HumanML3D), features
``(..., N, D)`` with ``D = skeleton.feature_dim``.
"""
from __future__ import annotations

import logging
from collections.abc import Iterable
from functools import lru_cache
from typing import Union

import numpy as np
import torch
from scipy.ndimage import gaussian_filter1d

from .quaternion import qbetween, qinv, qmul, qrot, quat_to_cont6d, quat_to_matrix, cont6d_to_matrix
from .skeleton import Skeleton, get_skeleton

__all__ = [
    "joints_to_features",
    "features_to_joints",
    "features_to_joints_rot",
    "recover_root",
    "process_joints",
    "retarget_joints",
    "mirror_joints",
    "mirror_features",
    "bone_lengths",
    "normalize",
    "denormalize",
    "compute_mean_std",
    "check_features",
    "check_joints",
    "FEATURE_BLOCKS",
    "HEADING_SMOOTH_SIGMA",
]

logger = logging.getLogger(__name__)

Array = Union[np.ndarray, torch.Tensor]
SkeletonLike = Union[str, Skeleton]

#: The 7 blocks whose std HumanML3D's ``cal_mean_variance`` averages (names of ``feature_slices``).
FEATURE_BLOCKS: tuple[str, ...] = (
    "root_rot_vel", "root_lin_vel", "root_y", "ric", "rot", "local_vel", "contacts",
)
#: Std (in frames) of the Gaussian that smooths the IK forward direction (``smooth_forward=True``).
HEADING_SMOOTH_SIGMA = 20.0

_UP = np.array([0.0, 1.0, 0.0])
_FORWARD = np.array([0.0, 0.0, 1.0])
_EPS = 1e-12


# =========================================================================== validation
def _shape(x) -> tuple[int, ...]:
    return tuple(x.shape)


def _as_array(x, name: str):
    """Pass real-valued torch tensors and numpy arrays through; turn other array-likes into numpy.

    Complex arrays (whose imaginary part a cast would drop with only a ComplexWarning), strings,
    booleans and objects are refused.
    """
    if isinstance(x, torch.Tensor):
        if x.is_complex() or x.dtype == torch.bool:
            raise TypeError(f"{name} must hold real numbers, got a {x.dtype} tensor")
        return x
    if isinstance(x, np.ndarray):
        if not (np.issubdtype(x.dtype, np.floating) or np.issubdtype(x.dtype, np.integer)) or x.dtype == bool:
            raise TypeError(f"{name} must hold real numbers, got dtype {x.dtype}")
        return x
    try:
        return np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name} must be a numpy array or torch tensor of real numbers, got {type(x).__name__}") from err


def _check_finite(x, name: str) -> None:
    finite = torch.isfinite(x) if isinstance(x, torch.Tensor) else np.isfinite(x)
    if not bool(finite.all()):
        bad = (~finite).nonzero()
        first = tuple(int(b[0]) for b in bad) if isinstance(bad, tuple) else tuple(bad[0].tolist())
        n_bad = int((~finite).sum())
        raise ValueError(f"{name} contains {n_bad} non-finite values (NaN or inf); the first is at index {first}")


#: Largest magnitude :func:`features_to_joints` accepts: HumanML3D features are metres, metres per
#: frame, radians and 6D rotations (all of order 1; the real sample's largest is under 2), so a value
#: beyond this is another unit or a broken array, and its joints would lie kilometres away.
MAX_FEATURE_MAGNITUDE = 1e4


def _check_magnitude(x, name: str, limit: float = MAX_FEATURE_MAGNITUDE) -> None:
    top = float(x.detach().abs().max()) if isinstance(x, torch.Tensor) else float(np.abs(x).max(initial=0.0))
    if top > limit:
        raise ValueError(f"{name} reach |value| = {top:.3g}, beyond {limit:g}: not HumanML3D features (metres, "
                         "radians, metres per frame; of order 1); check the array's units and scaling")


def check_features(features: Array, skeleton: SkeletonLike = "humanml3d", *, name: str = "features",
                   min_frames: int = 1, check_finite: bool = True) -> Array:
    """Check a feature array ``(..., N, D)`` against a skeleton and return it (array-likes -> numpy).

    Raises
    ------
    ValueError
        If the last axis is not ``skeleton.feature_dim`` wide, there is no frame axis, there are
        fewer than ``min_frames`` frames, or (with ``check_finite``) a value is NaN or inf.
    """
    sk = get_skeleton(skeleton)
    features = _as_array(features, name)
    shape = _shape(features)
    if len(shape) < 2 or shape[-1] != sk.feature_dim:
        raise ValueError(
            f"{name} must have shape (..., N, {sk.feature_dim}) for skeleton {sk.name!r} "
            f"(width {sk.feature_dim} = 4 + 9*(J-1) + 3*J + 4 with J = {sk.num_joints}), got shape {shape}"
        )
    if shape[-2] < min_frames:
        raise ValueError(f"{name} needs at least {min_frames} frame(s) on axis -2, got shape {shape}")
    if check_finite:
        _check_finite(features, name)
    return features


def check_joints(joints: Array, skeleton: SkeletonLike = "humanml3d", *, name: str = "joints",
                 min_frames: int = 1, check_finite: bool = True) -> Array:
    """Check a joint array ``(..., N, J, 3)`` against a skeleton and return it (array-likes -> numpy).

    Raises
    ------
    ValueError
        If the trailing axes are not ``(J, 3)``, there are fewer than ``min_frames`` frames, or
        (with ``check_finite``) a value is NaN or inf.
    """
    sk = get_skeleton(skeleton)
    joints = _as_array(joints, name)
    shape = _shape(joints)
    if len(shape) < 3 or shape[-2:] != (sk.num_joints, 3):
        raise ValueError(
            f"{name} must have shape (..., N, {sk.num_joints}, 3) for skeleton {sk.name!r}, got shape {shape}"
        )
    if shape[-3] < min_frames:
        raise ValueError(f"{name} needs at least {min_frames} frame(s) on axis -3, got shape {shape}")
    if check_finite:
        _check_finite(joints, name)
    return joints


# =========================================================================== skeleton tables
@lru_cache(maxsize=None)
def _chain_tables(sk: Skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IK/FK bookkeeping, one entry per joint 1..J-1, derived from ``kinematic_chains``.

    Returns ``pred`` (the joint before it in its chain), ``starts_chain`` (True for the first
    bone of a chain, whose IK restarts from the root rotation, §2.4 step 3) and ``ancestors``
    ``(J, J)``: ``ancestors[j, k] = 1`` when bone k (parent(k) -> k) lies on the path root -> j.
    """
    j = sk.num_joints
    pred = np.full(j, -1, dtype=np.int64)
    starts = np.zeros(j, dtype=bool)
    for chain in sk.kinematic_chains:
        for i in range(1, len(chain)):
            b = chain[i]
            if pred[b] != -1:
                raise ValueError(f"skeleton {sk.name!r}: joint {b} appears in more than one chain")
            pred[b] = chain[i - 1]
            starts[b] = i == 1
    missing = [b for b in range(1, j) if pred[b] == -1]
    if missing:
        raise ValueError(f"skeleton {sk.name!r}: joints {missing} are in no kinematic chain")
    if any(pred[b] != sk.parents[b] for b in range(1, j)):
        raise ValueError(f"skeleton {sk.name!r}: kinematic chains disagree with the parent list")
    anc = np.zeros((j, j))
    for b in range(1, j):
        k = b
        while k > 0:
            anc[b, k] = 1.0
            k = sk.parents[k]
    return pred[1:], starts[1:], anc


@lru_cache(maxsize=None)
def _mirror_tables(sk: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """Column permutation and signs that mirror a feature vector (x -> -x, left <-> right).

    ``mirrored = features[..., perm] * sign``. Each entry of ``perm`` reads the counterpart
    joint's column; ``sign`` flips the x components, the yaw velocity and the cont6d entries that
    change under ``M R M`` with ``M = diag(-1, 1, 1)`` (entry (i, k) is multiplied by m_i m_k).
    """
    s = sk.feature_slices
    j = sk.num_joints
    mm = sk.mirror_map
    d = sk.feature_dim
    perm = np.arange(d)
    sign = np.ones(d, dtype=np.float32)
    sign[s["root_rot_vel"].start] = -1.0          # yaw reverses under a reflection
    sign[s["root_lin_vel"].start] = -1.0          # x component of (x, z)
    # cont6d = (R00, R10, R20, R01, R11, R21): signs m_i * m_k of diag(-1,1,1) R diag(-1,1,1)
    rot_sign = np.array([1, -1, -1, -1, 1, 1], dtype=np.float32)
    for jnt in range(1, j):
        src = mm[jnt]
        r0, rs = s["ric"].start + 3 * (jnt - 1), s["ric"].start + 3 * (src - 1)
        perm[r0:r0 + 3] = np.arange(rs, rs + 3)
        sign[r0] = -1.0
        o0, os_ = s["rot"].start + 6 * (jnt - 1), s["rot"].start + 6 * (src - 1)
        perm[o0:o0 + 6] = np.arange(os_, os_ + 6)
        sign[o0:o0 + 6] = rot_sign
    for jnt in range(j):
        src = mm[jnt]
        v0, vs = s["local_vel"].start + 3 * jnt, s["local_vel"].start + 3 * src
        perm[v0:v0 + 3] = np.arange(vs, vs + 3)
        sign[v0] = -1.0
    contacts = sk.contact_joints
    for k, jnt in enumerate(contacts):
        if mm[jnt] not in contacts:
            raise ValueError(f"skeleton {sk.name!r}: contact joint {jnt} mirrors to a non-contact joint")
        perm[s["contacts"].start + k] = s["contacts"].start + contacts.index(mm[jnt])
    if mm[0] != 0:
        raise ValueError(f"skeleton {sk.name!r}: the root must be its own mirror")
    return perm, sign


# =========================================================================== joints -> features
def _normalize_rows(v: np.ndarray, fallback: np.ndarray | None = None) -> np.ndarray:
    """Unit vectors along the last axis; zero vectors become ``fallback`` (or stay zero)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    out = v / np.maximum(n, _EPS)
    if fallback is not None:
        out = np.where(n > _EPS, out, np.broadcast_to(fallback, out.shape))
    return out


def retarget_joints(joints: np.ndarray, skeleton: SkeletonLike = "humanml3d") -> np.ndarray:
    """Give a motion the skeleton's target bone lengths (HumanML3D ``uniform_skeleton``, §2.3 step 1).

    HumanML3D runs IK on the source positions and FK with the target offsets; because the IK
    rotations are pure swings from the rest direction onto each bone, that amounts to keeping every
    bone's direction per frame and replacing its length, with the root translation scaled by the
    ratio of target to source leg length (bones ``skeleton.leg_bones``, measured on frame 0).

    Parameters
    ----------
    joints : ndarray ``(N, J, 3)``
    skeleton : name or Skeleton with ``bone_lengths``

    Returns
    -------
    ndarray ``(N, J, 3)`` float64
    """
    sk = get_skeleton(skeleton)
    if sk.bone_lengths is None:
        raise ValueError(f"skeleton {sk.name!r} has no target bone lengths; it cannot be retargeted")
    joints = check_joints(joints, sk, min_frames=1)
    if isinstance(joints, torch.Tensor):
        joints = joints.detach().cpu().numpy()
    p = np.asarray(joints, dtype=np.float64)
    if p.ndim != 3:
        raise ValueError(f"joints must have shape (N, {sk.num_joints}, 3) (one motion), got shape {p.shape}")
    parents = np.asarray(sk.parents[1:])
    bones = p[:, 1:] - p[:, parents]                               # (N, J-1, 3)
    src_len = np.linalg.norm(bones[0], axis=-1)                    # frame-0 lengths, (J-1,)
    tgt_len = np.asarray(sk.bone_lengths[1:], dtype=np.float64)
    l1, l2 = sk.leg_bones
    src_leg = src_len[l1 - 1] + src_len[l2 - 1]
    if src_leg <= _EPS:
        raise ValueError(f"joints: the leg bones {sk.leg_bones} have zero length in frame 0; cannot scale")
    scale = (tgt_len[l1 - 1] + tgt_len[l2 - 1]) / src_leg
    raw = np.asarray(sk.raw_offsets[1:], dtype=np.float64)
    dirs = _normalize_rows(bones, fallback=raw)                    # (N, J-1, 3)
    _, _, anc = _chain_tables(sk)
    # joint j = scaled root + sum of the (target-length) bones on the path root -> j
    out = anc[:, 1:] @ (dirs * tgt_len[None, :, None])            # (J, J-1) @ (N, J-1, 3)
    return out + scale * p[:, :1]


def _face_z(p: np.ndarray, sk: Skeleton) -> np.ndarray:
    """Floor at y=0, frame-0 root at x=z=0, frame 0 facing +Z (§2.3 steps 2-4)."""
    p = p.copy()
    p[..., 1] -= p[..., 1].min()
    p -= p[0, 0] * np.array([1.0, 0.0, 1.0])
    r_hip, l_hip, sdr_r, sdr_l = sk.face_joint_indx
    across = (p[0, r_hip] - p[0, l_hip]) + (p[0, sdr_r] - p[0, sdr_l])
    forward = _normalize_rows(np.cross(_UP, _normalize_rows(across)))
    if np.linalg.norm(forward) < 0.5:
        raise ValueError("joints: frame 0 has no horizontal facing direction (hips and shoulders "
                         "are vertically aligned); cannot orient the motion")
    q0 = qbetween(forward, _FORWARD)
    return qrot(np.broadcast_to(q0, p.shape[:-1] + (4,)), p)


def process_joints(joints: np.ndarray, skeleton: SkeletonLike = "humanml3d", *,
                   retarget: bool = True) -> np.ndarray:
    """The global positions that the features encode: retargeted, on the floor, facing +Z.

    ``features_to_joints(joints_to_features(x)) == process_joints(x)[:-1]`` (up to float error).

    Parameters
    ----------
    joints : ndarray ``(N, J, 3)``
    skeleton : name or Skeleton
    retarget : bool
        Retarget to the skeleton's bone lengths (skipped anyway when it has none, e.g. KIT).

    Returns
    -------
    ndarray ``(N, J, 3)`` float32
    """
    return _process(joints, get_skeleton(skeleton), retarget).astype(np.float32)


def _process(joints, sk: Skeleton, retarget: bool) -> np.ndarray:
    joints = check_joints(joints, sk, min_frames=1)
    if isinstance(joints, torch.Tensor):  # extraction is numpy-only (not differentiable)
        joints = joints.detach().cpu().numpy()
    p = np.asarray(joints, dtype=np.float64)
    if p.ndim != 3:
        raise ValueError(f"joints must have shape (N, {sk.num_joints}, 3) (one motion), got shape {p.shape}")
    if retarget and sk.bone_lengths is not None:
        p = retarget_joints(p, sk)
    return _face_z(p, sk)


def _heading(p: np.ndarray, sk: Skeleton, smooth: bool = True) -> np.ndarray:
    """Per-frame root quaternion ``(N, 4)`` of the IK (§2.4 steps 1-2), mapping world -> heading frame."""
    # Quirk kept on purpose: the IK unpacks face_joint_indx as (l_hip, r_hip, sdr_r, sdr_l), so
    # the hip term enters with the opposite sign to the shoulder term (shoulders dominate).
    l_hip, r_hip, sdr_r, sdr_l = sk.face_joint_indx
    across = (p[:, r_hip] - p[:, l_hip]) + (p[:, sdr_r] - p[:, sdr_l])
    forward = np.cross(_UP, _normalize_rows(across))
    if smooth:
        forward = gaussian_filter1d(forward, HEADING_SMOOTH_SIGMA, axis=0, mode="nearest")
    forward = _normalize_rows(forward, fallback=_FORWARD)
    root = qbetween(forward, np.broadcast_to(_FORWARD, forward.shape))
    root[0] = (1.0, 0.0, 0.0, 0.0)  # HumanML3D forces frame 0 to identity
    return root


def _ik_rotations(p: np.ndarray, root: np.ndarray, sk: Skeleton) -> np.ndarray:
    """Chain-local swing rotations ``(N, J-1, 4)`` of joints 1..J-1 (§2.4 step 3).

    Global swing ``g_b = qbetween(raw_b, dir(pred_b -> b))``; stored ``q_b = R^-1 g_b`` with
    ``R = g_pred`` inside a chain and ``R = root`` for a chain's first bone (also for the arm
    chains that start at the spine, which is why these are not SMPL local rotations).
    """
    pred, starts, _ = _chain_tables(sk)
    raw = np.asarray(sk.raw_offsets[1:], dtype=np.float64)
    dirs = _normalize_rows(p[:, 1:] - p[:, pred], fallback=raw)   # (N, J-1, 3)
    g = qbetween(np.broadcast_to(raw, dirs.shape), dirs)          # (N, J-1, 4)
    g_all = np.concatenate([root[:, None], g], axis=1)            # index by joint id
    prev = np.where(starts[None, :, None], root[:, None], g_all[:, pred])
    return qmul(qinv(prev), g)


def _contacts(p: np.ndarray, sk: Skeleton, threshold: float) -> np.ndarray:
    """Binary contacts ``(N-1, 4)``: squared per-frame displacement below ``threshold`` (§2.3 step 5)."""
    cj = list(sk.contact_joints)
    disp2 = ((p[1:, cj] - p[:-1, cj]) ** 2).sum(-1)
    return (disp2 < threshold).astype(np.float64)


def joints_to_features(joints: np.ndarray, skeleton: SkeletonLike = "humanml3d",
                       feet_threshold: float | None = None, *, retarget: bool = True,
                       official_heading: bool = False) -> np.ndarray:
    """HumanML3D ``process_file``: joint positions to the 263-d (KIT: 251-d) feature vector.

    Parameters
    ----------
    joints : ndarray ``(N, J, 3)``
        Global joint positions, Y up, N >= 2 frames.
    skeleton : name or Skeleton
    feet_threshold : float, optional
        Squared per-frame displacement below which a foot joint is in contact; defaults to
        ``skeleton.foot_threshold`` (0.002 m^2 for HumanML3D, 0.05 for KIT).
    retarget : bool
        Retarget to the target bone lengths first, as HumanML3D does (a no-op for skeletons
        without bone lengths, e.g. KIT). Turn off for joints already on the target skeleton when
        bone-length asymmetry matters (e.g. comparing against :func:`mirror_features`).
    official_heading : bool
        Reproduce the official code's root-rotation velocity exactly, including its wrong sign on
        frames where the heading passes 180 degrees (``arcsin`` of a yaw increment with w < 0). The
        default stores the correct increment; the two agree on every other frame (and on every
        frame of motions that never turn around, such as the real sample 012314).

    Returns
    -------
    ndarray ``(N-1, D)`` float32
    """
    sk = get_skeleton(skeleton)
    thr = sk.foot_threshold if feet_threshold is None else float(feet_threshold)
    if not thr > 0:
        raise ValueError(f"feet_threshold must be positive, got {feet_threshold!r}")
    joints = check_joints(joints, sk, min_frames=2)
    p = _process(joints, sk, retarget)                              # (N, J, 3) global positions
    n = p.shape[0]

    contacts = _contacts(p, sk, thr)                                # (N-1, 4)
    root = _heading(p, sk, smooth=True)                             # (N, 4)
    rot6d = quat_to_cont6d(_ik_rotations(p, root, sk))              # (N, J-1, 6)

    # root linear velocity in the heading frame of the *next* frame (§2.3 step 7)
    lin = qrot(root[1:], p[1:, 0] - p[:-1, 0])[:, [0, 2]]            # (N-1, 2)
    # yaw increment r_{t+1} r_t^-1 is a pure y rotation; HumanML3D stores arcsin(y) = half angle
    dq = qmul(root[1:], qinv(root[:-1]))
    if not official_heading:
        # q and -q are the same rotation, but arcsin(y) is the half angle only for w >= 0: when the
        # heading passes 180 deg the product has w < 0 and the official code stores the wrong sign,
        # so every later frame of the recovered motion turns and drifts (measured: 41-47 cm on the
        # 3 of 200 corpus clips that turn around). Canonical sign first; identical wherever w >= 0.
        dq = dq * np.where(dq[:, :1] < 0, -1.0, 1.0)
    rot_vel = np.arcsin(np.clip(dq[:, 2:3], -1.0, 1.0))              # (N-1, 1)

    # ric: root-relative in x and z (y stays absolute), rotated into the heading frame (step 8)
    rel = p - p[:, :1] * np.array([1.0, 0.0, 1.0])
    ric = qrot(root[:, None], rel)                                  # (N, J, 3)
    root_y = p[:, 0, 1:2]

    # local velocity in the *current* heading frame (step 9)
    local_vel = qrot(root[:-1, None], p[1:] - p[:-1])               # (N-1, J, 3)

    m = n - 1
    feats = np.concatenate([
        rot_vel, lin, root_y[:m],
        ric[:m, 1:].reshape(m, -1),
        rot6d[:m].reshape(m, -1),
        local_vel.reshape(m, -1),
        contacts,
    ], axis=-1)
    assert feats.shape[1] == sk.feature_dim
    return feats.astype(np.float32)


# =========================================================================== features -> joints
def _cat(xs, axis):
    return torch.cat(xs, dim=axis) if isinstance(xs[0], torch.Tensor) else np.concatenate(xs, axis=axis)


def _stack(xs, axis):
    return torch.stack(xs, dim=axis) if isinstance(xs[0], torch.Tensor) else np.stack(xs, axis=axis)


def _cumsum(x, axis):
    return torch.cumsum(x, dim=axis) if isinstance(x, torch.Tensor) else np.cumsum(x, axis=axis)


def _zeros_like(x):
    return torch.zeros_like(x) if isinstance(x, torch.Tensor) else np.zeros_like(x)


def _trig(x):
    if isinstance(x, torch.Tensor):
        return torch.cos(x), torch.sin(x)
    return np.cos(x), np.sin(x)


def _to_float(features):
    """numpy: compute in float64 and remember the dtype to return; torch: keep as is."""
    if isinstance(features, torch.Tensor):
        if not features.is_floating_point():
            features = features.float()
        return features, None
    out_dtype = features.dtype if np.issubdtype(features.dtype, np.floating) else np.float32
    return features.astype(np.float64), out_dtype


def _recover_root(f):
    """Root heading quaternion ``(..., N, 4)`` and root position ``(..., N, 3)`` (§2.5).

    The half-angle is integrated from 0 (the last row's yaw velocity is unused), the stored
    velocity of row t-1 moves the root from frame t-1 to t in frame t's heading frame.
    """
    zero = _zeros_like(f[..., :1, 0])
    half = _cumsum(_cat([zero, f[..., :-1, 0]], -1), -1)          # (..., N)
    c, s = _trig(half)
    z = _zeros_like(half)
    r = _stack([c, z, s, z], -1)                                  # (..., N, 4)
    vx = _cat([zero, f[..., :-1, 1]], -1)
    vz = _cat([zero, f[..., :-1, 2]], -1)
    step = qrot(qinv(r), _stack([vx, z, vz], -1))                 # world-frame displacement
    xz = _cumsum(step, -2)
    pos = _stack([xz[..., 0], f[..., 3], xz[..., 2]], -1)
    return r, pos


def recover_root(features: Array, skeleton: SkeletonLike = "humanml3d") -> tuple[Array, Array]:
    """HumanML3D ``recover_root_rot_pos``: root heading and position from features ``(..., N, D)``.

    Returns
    -------
    heading : ``(..., N, 4)``
        Quaternion ``(cos a, 0, sin a, 0)`` per frame mapping world to the heading frame
        (``a`` is the integrated half angle; frame 0 is the identity).
    root : ``(..., N, 3)``
        Root position in world coordinates (x, z integrated from 0; y absolute).

    Same kind as ``features``; numpy results keep the input's float dtype.
    """
    sk = get_skeleton(skeleton)
    features = check_features(features, sk)
    f, out_dtype = _to_float(features)
    r, root = _recover_root(f)
    if out_dtype is not None:
        r, root = r.astype(out_dtype), root.astype(out_dtype)
    return r, root


def features_to_joints(features: Array, skeleton: SkeletonLike = "humanml3d") -> Array:
    """HumanML3D ``recover_from_ric``: features ``(..., N, D)`` to joints ``(..., N, J, 3)``.

    numpy in -> numpy out (same float dtype, computed in float64); torch in -> torch out
    (differentiable, computed in the input dtype and device).
    """
    sk = get_skeleton(skeleton)
    features = check_features(features, sk)
    _check_magnitude(features, "features")
    f, out_dtype = _to_float(features)
    j = sk.num_joints
    r, root = _recover_root(f)
    ric = f[..., sk.feature_slices["ric"]]
    ric = ric.reshape(*ric.shape[:-1], j - 1, 3)                   # (..., N, J-1, 3)
    world = qrot(qinv(r)[..., None, :], ric)
    offset = _stack([root[..., 0], _zeros_like(root[..., 0]), root[..., 2]], -1)[..., None, :]
    joints = _cat([root[..., None, :], world + offset], -2)       # (..., N, J, 3)
    return joints if out_dtype is None else joints.astype(out_dtype)


def features_to_joints_rot(features: Array, skeleton: SkeletonLike = "humanml3d",
                           offsets: Array | None = None) -> Array:
    """HumanML3D ``recover_from_rot``: forward kinematics of the cont6d rotations.

    Parameters
    ----------
    features : ``(..., N, D)`` numpy array or torch tensor
    skeleton : name or Skeleton
    offsets : ``(J, 3)``, optional
        Rest offsets (raw direction x bone length); defaults to ``skeleton.target_offsets``.
        Required for skeletons without bone lengths (KIT).

    Returns
    -------
    joints ``(..., N, J, 3)``, same kind as ``features``. The bone lengths are exactly the
    offsets' lengths; positions differ from :func:`features_to_joints` where the stored swing
    rotations cannot express the motion (twist is not stored, so only bone directions count).
    """
    sk = get_skeleton(skeleton)
    features = check_features(features, sk)
    f, out_dtype = _to_float(features)
    if offsets is None:
        offsets = sk.target_offsets
    offsets = np.asarray(offsets.detach().cpu() if isinstance(offsets, torch.Tensor) else offsets,
                         dtype=np.float64)
    if offsets.shape != (sk.num_joints, 3):
        raise ValueError(f"offsets must have shape ({sk.num_joints}, 3), got shape {offsets.shape}")
    if isinstance(f, torch.Tensor):
        off = torch.as_tensor(offsets, dtype=f.dtype, device=f.device)
    else:
        off = offsets
    j = sk.num_joints
    r, root = _recover_root(f)
    rot = f[..., sk.feature_slices["rot"]]
    mats = cont6d_to_matrix(rot.reshape(*rot.shape[:-1], j - 1, 6))  # (..., N, J-1, 3, 3)
    root_mat = quat_to_matrix(r)                                      # (..., N, 3, 3)
    pos: list = [None] * j
    pos[0] = root
    for chain in sk.kinematic_chains:
        mat = root_mat
        for i in range(1, len(chain)):
            b = chain[i]
            mat = mat @ mats[..., b - 1, :, :]
            pos[b] = pos[chain[i - 1]] + (mat @ off[b][:, None])[..., 0]
    joints = _stack(pos, -2)
    return joints if out_dtype is None else joints.astype(out_dtype)


# =========================================================================== mirroring
def _joints_of(joints: Array, sk: Skeleton) -> Array:
    """``joints`` as an array of shape ``(..., J, 3)`` for ``sk``, else a ValueError naming the shape."""
    joints = _as_array(joints, "joints")
    shape = _shape(joints)
    if len(shape) < 2 or shape[-2:] != (sk.num_joints, 3):
        raise ValueError(f"joints must have shape (..., {sk.num_joints}, 3) for skeleton {sk.name!r}, "
                         f"got shape {shape}")
    return joints


def mirror_joints(joints: Array, skeleton: SkeletonLike = "humanml3d") -> Array:
    """Mirror joints ``(..., J, 3)`` across the YZ plane: negate x and swap left/right joints.

    This is HumanML3D's augmentation that produces the ``M<id>`` clips. numpy or torch.
    """
    sk = get_skeleton(skeleton)
    joints = _joints_of(joints, sk)
    idx = list(sk.mirror_map)
    out = joints[..., idx, :]
    if isinstance(out, torch.Tensor):
        flip = torch.tensor([-1.0, 1.0, 1.0], dtype=out.dtype, device=out.device)
    else:
        flip = np.array([-1.0, 1.0, 1.0], dtype=out.dtype if np.issubdtype(out.dtype, np.floating) else None)
    return out * flip


def bone_lengths(joints: Array, skeleton: SkeletonLike = "humanml3d") -> Array:
    """Length of every bone ``parent -> joint`` per frame: joints ``(..., J, 3)`` -> ``(..., J)``.

    Entry 0 (the root, which has no parent) is 0. numpy or torch. Generated motions are not
    constrained to one skeleton (the features hold joint positions), so their bone lengths drift;
    this measures by how much.
    """
    sk = get_skeleton(skeleton)
    joints = _joints_of(joints, sk)
    parents = [max(p, 0) for p in sk.parents]          # the root is its own "parent": length 0
    diff = joints - joints[..., parents, :]
    if isinstance(diff, torch.Tensor):
        return torch.linalg.vector_norm(diff, dim=-1)
    return np.linalg.norm(diff, axis=-1)


def mirror_features(features: Array, skeleton: SkeletonLike = "humanml3d") -> Array:
    """Mirror a feature array ``(..., N, D)`` directly (numpy or torch).

    Swaps the counterpart joints' ric / rot / local-velocity blocks and the left/right contact
    channels, negates the x components and the yaw velocity, and mirrors rotations as ``M R M``
    with ``M = diag(-1, 1, 1)``. A signed column permutation, so mirroring twice is exactly the
    identity. It agrees with ``joints_to_features(mirror_joints(joints), retarget=False)`` to
    float precision; with retargeting the asymmetric target bone lengths make them differ
    (the mirrored features keep the swapped lengths, re-extraction restores the target ones).
    """
    sk = get_skeleton(skeleton)
    features = check_features(features, sk, check_finite=False)
    perm, sign = _mirror_tables(sk)
    if isinstance(features, torch.Tensor):
        idx = torch.as_tensor(perm, device=features.device)
        return features[..., idx] * torch.as_tensor(sign, dtype=features.dtype, device=features.device)
    out = features[..., perm]
    return out * sign.astype(out.dtype if np.issubdtype(out.dtype, np.floating) else np.float32)


# =========================================================================== normalisation
def _stats_like(stat, features, name: str, width: int):
    if isinstance(features, torch.Tensor):
        stat = torch.as_tensor(
            stat.detach() if isinstance(stat, torch.Tensor) else np.asarray(stat),
            dtype=features.dtype, device=features.device,
        )
    else:
        stat = stat.detach().cpu().numpy() if isinstance(stat, torch.Tensor) else np.asarray(stat)
        if np.issubdtype(features.dtype, np.floating):
            stat = stat.astype(features.dtype, copy=False)
    if _shape(stat) != (width,):
        raise ValueError(f"{name} must have shape ({width},) to match the features' last axis, "
                         f"got shape {_shape(stat)}")
    return stat


def normalize(features: Array, mean: Array, std: Array) -> Array:
    """``(features - mean) / std`` over the last axis; ``features`` ``(..., D)``, stats ``(D,)``.

    The statistics are converted to the features' kind, dtype and device.
    """
    features = _as_array(features, "features")
    width = _shape(features)[-1]
    mean = _stats_like(mean, features, "mean", width)
    std = _stats_like(std, features, "std", width)
    if not bool((std > 0).all()):
        raise ValueError("std must be positive everywhere (compute_mean_std guards zero blocks)")
    return (features - mean) / std


def denormalize(features: Array, mean: Array, std: Array) -> Array:
    """``features * std + mean``, the inverse of :func:`normalize`."""
    features = _as_array(features, "features")
    width = _shape(features)[-1]
    mean = _stats_like(mean, features, "mean", width)
    std = _stats_like(std, features, "std", width)
    return features * std + mean


def compute_mean_std(feature_arrays: Iterable[np.ndarray] | np.ndarray,
                     skeleton: SkeletonLike = "humanml3d", *, min_std: float = 1e-6,
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Dataset mean and std as HumanML3D's ``cal_mean_variance`` computes them.

    The mean is per dimension. The (population, ddof=0) std is per dimension and then replaced
    by its average within each block of :data:`FEATURE_BLOCKS` (root rot-vel, root lin-vel,
    root y, ric, rot, local velocity, contacts), so every dimension of a block is scaled alike.
    Arrays containing NaN/inf are skipped with a warning, as HumanML3D skipped clip 007975.
    A block whose averaged std is below ``min_std`` (e.g. contacts that never change in a small
    synthetic corpus) gets ``min_std`` instead, with a warning, so normalising never divides by 0.

    Parameters
    ----------
    feature_arrays : iterable of ``(N_i, D)`` arrays, or one array ``(..., D)``
    skeleton : name or Skeleton
    min_std : float
        Floor for a block's std.

    Returns
    -------
    mean, std : ndarray ``(D,)`` float32
    """
    sk = get_skeleton(skeleton)
    d = sk.feature_dim
    if isinstance(feature_arrays, (np.ndarray, torch.Tensor)):
        feature_arrays = [feature_arrays]
    count = 0
    mean = np.zeros(d)
    m2 = np.zeros(d)
    skipped = 0
    for i, arr in enumerate(feature_arrays):
        if isinstance(arr, torch.Tensor):
            arr = arr.detach().cpu().numpy()
        arr = np.asarray(arr, dtype=np.float64)
        if arr.ndim < 1 or arr.shape[-1] != d:
            raise ValueError(f"feature_arrays[{i}] must have shape (..., {d}) for skeleton {sk.name!r}, "
                             f"got shape {arr.shape}")
        arr = arr.reshape(-1, d)
        if not np.isfinite(arr).all():
            skipped += 1
            continue
        n_b = arr.shape[0]
        if n_b == 0:
            continue
        mean_b = arr.mean(0)
        m2_b = ((arr - mean_b) ** 2).sum(0)
        # Chan et al.'s pairwise merge: exact, streams over thousands of clips without concatenating
        tot = count + n_b
        delta = mean_b - mean
        mean = mean + delta * (n_b / tot)
        m2 = m2 + m2_b + delta ** 2 * (count * n_b / tot)
        count = tot
    if skipped:
        logger.warning("compute_mean_std: skipped %d array(s) containing NaN or inf", skipped)
    if count == 0:
        raise ValueError("feature_arrays holds no finite frame; cannot compute statistics")
    std = np.sqrt(m2 / count)
    for block in FEATURE_BLOCKS:
        sl = sk.feature_slices[block]
        value = std[sl].mean()
        if value < min_std:
            logger.warning("compute_mean_std: block %r has std %.3g < min_std; using %.3g",
                           block, value, min_std)
            value = min_std
        std[sl] = value
    return mean.astype(np.float32), std.astype(np.float32)
