"""Joint recovery from HumanML3D-style features that keeps bone lengths and planted feet.

The 263-d features (:mod:`salad_core.motion`) describe every frame three times over: joint
positions ("ric"), chain-local 6D swing rotations ("rot") and joint velocities, plus 4 foot-contact
channels. The standard recovery (HumanML3D ``recover_from_ric``) reads only the positions, so
whatever error a generator leaves in them shows as bones that stretch and feet that slide. This
module recovers joints ``(..., N, J, 3)`` in three ways, chosen with ``method``:

``"positions"``
    :func:`salad_core.motion.features_to_joints`, unchanged (the raw recovery the metrics use).
``"fk"``
    Forward kinematics of the rotation features with fixed bone lengths (the skeleton's, or the
    motion's own median lengths measured on the position features) and the root from the root
    channels. Optionally (default) each frame's FK body is turned about the vertical through the
    root onto the heading of the position features: the heading that the rotation features were
    made with can differ from the one the root channels integrate to (see below), and then FK and
    the positions disagree by a yaw of the whole body.
``"fit"``
    A skeleton fit: per frame, each bone (root outwards) points from its already fitted parent at
    the predicted position of its child (optionally blended with the rotation features' bone
    direction) and has the fixed length, so bone lengths are exact and each joint lands as close
    to its predicted position as its fitted parent allows. Then the feet are locked where the
    contact channels say so (see :func:`lock_feet`) and no joint is left below the floor
    (:func:`lift_above_floor`).

Why ``"fk"`` turns the body onto the positions' heading. HumanML3D stores the root's yaw velocity
as ``arcsin(y)`` of the per-frame heading increment ``dq = r_{t+1} r_t^-1`` with heading
quaternions of non-negative ``w``. When the heading passes 180 degrees from the first frame's
(a motion that turns around), ``r_{t+1}`` flips sign, ``dq`` gets ``w < 0`` and the stored increment
has the wrong sign: from that frame on the integrated heading is off by twice that step. The
position recovery then turns the whole body (and the rest of the root path) one way and FK of the
rotation features turns it the other way, because the first bone of every chain is stored
relative to ``r_t`` (measured on the tiny procedural corpus: 3 of 200 motions, up to 0.74 m between
the two recoveries; 0.00001 m on the real clip 012314, which does not turn around).

All three methods are vectorised numpy over frames (Python loops run over joints, contact runs and
motions of a batch); they accept numpy arrays or torch tensors and return numpy arrays (not
differentiable), float32 for float32 input and float64 otherwise.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple, Union

import numpy as np
import torch
from scipy.ndimage import gaussian_filter1d

from .motion import check_features, features_to_joints, features_to_joints_rot
from .skeleton import Skeleton, get_skeleton

__all__ = [
    "METHODS",
    "check_method",
    "DEFAULT_METHOD",
    "RecoveryConfig",
    "recover_joints",
    "fk_joints",
    "fit_joints",
    "fit_skeleton",
    "branch_joints",
    "branch_rest_offsets",
    "plant_feet",
    "motion_bone_lengths",
    "contact_lock_mask",
    "lock_feet",
    "two_bone_ik",
    "lift_above_floor",
]

Array = Union[np.ndarray, torch.Tensor]
SkeletonLike = Union[str, Skeleton]

#: Recovery methods of :func:`recover_joints`.
METHODS: tuple[str, ...] = ("positions", "fk", "fit")
#: The method :func:`recover_joints` uses when none is given.
DEFAULT_METHOD = "fit"

_EPS = 1e-9
_UP = np.array([0.0, 1.0, 0.0])


# =========================================================================== configuration
@dataclass(frozen=True)
class RecoveryConfig:
    """Options of the ``"fk"`` and ``"fit"`` recoveries (``"positions"`` has none).

    Lengths are in metres for HumanML3D; for skeletons in other units (KIT, millimetres) the
    heights are divided by ``skeleton.feature_scale``.
    """

    lengths: str = "skeleton"                 # bone lengths: "skeleton" (target) or "motion" (median of the positions)
    align_heading: bool = True                # fk: turn the FK body onto the position features' heading
    rotation_weight: float = 0.0              # fit: weight of the rotation features' bone directions, in [0, 1]
    smooth_sigma: float = 0.5                 # fit: std (frames) of a Gaussian over time on the positions first; 0 = off
    lock_contacts: bool = True                # fit: lock feet where the contact channels are on
    contact_threshold: float = 0.5            # a contact channel is on above this value
    contact_heights: tuple[float, float] = (0.12, 0.06)  # (ankle, toe): highest joint y (m) that may lock
    contact_speed: float | None = 0.5         # highest horizontal speed (m/s) in the velocity channels that may lock
    min_contact_frames: int = 3               # shorter contact runs are ignored (flicker, not a plant)
    blend_frames: int = 3                     # frames over which a lock fades in before and out after a run
    floor: bool = True                        # fit: no joint below y = 0 (feet by IK, else the frame is lifted)
    max_foot_shift: float | None = 0.04       # fit: farthest (m, horizontal) a planted foot is held from where the
                                              # model put it; a foot that glides further slides along (None: no limit)
    reach_slack: float = 0.03                 # fit: how much straighter (m, hip-ankle distance) IK may make a leg than
                                              # the model made it; beyond that the body (root) moves towards the foot
    root_sigma: float = 2.0                   # fit: std (frames) of the Gaussian that smooths the root's shift
    move_root: bool = False                   # fit: move the body where a leg cannot reach its planted foot
                                              # (off: measured less faithful and no less sliding, see plant_feet)
    rigid_branches: bool = True               # fit: hips/spine and neck/collars move as one rigid body each
    refine: int = 2                           # fit: sweeps that turn each bone to bring its whole subtree closest

    def __post_init__(self) -> None:
        if self.lengths not in ("skeleton", "motion"):
            raise ValueError(f"lengths must be 'skeleton' or 'motion', got {self.lengths!r}")
        if not 0.0 <= float(self.rotation_weight) <= 1.0:
            raise ValueError(f"rotation_weight must be in [0, 1], got {self.rotation_weight!r}")
        if not (np.isfinite(self.smooth_sigma) and self.smooth_sigma >= 0):
            raise ValueError(f"smooth_sigma must be a finite number of frames >= 0, got {self.smooth_sigma!r}")
        if not 0.0 < float(self.contact_threshold) < 1.0:
            raise ValueError(f"contact_threshold must be in (0, 1), got {self.contact_threshold!r}")
        heights = tuple(self.contact_heights)
        if len(heights) != 2 or not all(np.isfinite(h) and h > 0 for h in heights):
            raise ValueError(f"contact_heights must be two positive heights (ankle, toe) in metres, "
                             f"got {self.contact_heights!r}")
        if self.contact_speed is not None and not (np.isfinite(self.contact_speed) and self.contact_speed > 0):
            raise ValueError(f"contact_speed must be a positive speed in m/s or None, got {self.contact_speed!r}")
        if int(self.min_contact_frames) != self.min_contact_frames or self.min_contact_frames < 1:
            raise ValueError(f"min_contact_frames must be an integer >= 1, got {self.min_contact_frames!r}")
        if int(self.blend_frames) != self.blend_frames or self.blend_frames < 0:
            raise ValueError(f"blend_frames must be an integer >= 0, got {self.blend_frames!r}")
        if self.max_foot_shift is not None and not (np.isfinite(self.max_foot_shift) and self.max_foot_shift > 0):
            raise ValueError(f"max_foot_shift must be a positive distance in metres or None, "
                             f"got {self.max_foot_shift!r}")
        if not (np.isfinite(self.reach_slack) and self.reach_slack >= 0):
            raise ValueError(f"reach_slack must be a distance in metres >= 0, got {self.reach_slack!r}")
        if isinstance(self.refine, bool) or int(self.refine) != self.refine or self.refine < 0:
            raise ValueError(f"refine must be an integer >= 0, got {self.refine!r}")
        if not (np.isfinite(self.root_sigma) and self.root_sigma >= 0):
            raise ValueError(f"root_sigma must be a finite number of frames >= 0, got {self.root_sigma!r}")


# =========================================================================== helpers
def _as_numpy(features: Array, sk: Skeleton) -> tuple[np.ndarray, np.dtype]:
    """Checked features as float64 numpy plus the dtype to return."""
    features = check_features(features, sk)
    if isinstance(features, torch.Tensor):
        features = features.detach().cpu().numpy()
    out = np.float32 if features.dtype == np.float32 else np.float64
    return np.asarray(features, dtype=np.float64), out


def _normalize(v: np.ndarray, fallback: np.ndarray | None = None) -> np.ndarray:
    """Unit vectors along the last axis; (near-)zero vectors become ``fallback`` (or stay 0)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    out = v / np.maximum(n, _EPS)
    if fallback is not None:
        out = np.where(n > 1e-6, out, fallback)
    return out


def _leg(sk: Skeleton, contact: int) -> tuple[int, int]:
    """(root, middle) of the two-bone chain that ends at a contact ankle: its grandparent and parent."""
    mid = sk.parents[contact]
    return sk.parents[mid], mid


def _check_method(method: str) -> str:
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(map(repr, METHODS))}, got {method!r}")
    return method


def _config(config: RecoveryConfig | None) -> RecoveryConfig:
    if config is None:
        return RecoveryConfig()
    if not isinstance(config, RecoveryConfig):
        raise TypeError(f"config must be a RecoveryConfig, got {type(config).__name__}")
    return config


def _recover(features: Array, skeleton: SkeletonLike, config: RecoveryConfig | None,
             method: Callable[[np.ndarray, np.ndarray, Skeleton, RecoveryConfig], np.ndarray]) -> np.ndarray:
    """``method(f, positions, sk, cfg)`` on the features ``f (..., N, D)`` (float64) and their position
    features ``positions (..., N, J, 3)``; joints in the input's float precision (see :func:`_as_numpy`)."""
    sk = get_skeleton(skeleton)
    cfg = _config(config)
    f, out = _as_numpy(features, sk)
    return method(f, features_to_joints(f, sk), sk, cfg).astype(out)


def motion_bone_lengths(joints: np.ndarray, skeleton: SkeletonLike = "humanml3d") -> np.ndarray:
    """Median length of every bone over frames: joints ``(..., N, J, 3)`` -> ``(..., J)`` (root 0).

    The median is robust to the frames where a generator stretches a bone, so it is the motion's
    own body size.
    """
    sk = get_skeleton(skeleton)
    joints = np.asarray(joints, dtype=np.float64)
    parents = [max(p, 0) for p in sk.parents]
    return np.median(np.linalg.norm(joints - joints[..., parents, :], axis=-1), axis=-2)


def _lengths(positions: np.ndarray, sk: Skeleton, mode: str) -> np.ndarray:
    """Bone lengths ``(..., J)`` for the config's ``lengths`` mode."""
    if mode == "motion":
        return motion_bone_lengths(positions, sk)
    if sk.bone_lengths is None:
        raise ValueError(f"skeleton {sk.name!r} has no target bone lengths; use RecoveryConfig(lengths='motion')")
    return np.broadcast_to(np.asarray(sk.bone_lengths, dtype=np.float64), positions.shape[:-3] + (sk.num_joints,))


# =========================================================================== "fk"
def _yaw_onto(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Per frame, the rotation about +Y through joint 0 that best maps ``source`` onto ``target``.

    Both ``(..., N, J, 3)``; returns ``source`` turned (least squares over the horizontal
    components of the joints relative to joint 0; the root itself is kept).
    """
    a = source - source[..., :1, :]
    b = target - target[..., :1, :]
    # rotation by phi about +y maps (x, z) to (x cos + z sin, -x sin + z cos); the best phi
    # maximises sum(b . R a) = cos * sum(ax bx + az bz) + sin * sum(az bx - ax bz)
    dot = (a[..., 0] * b[..., 0] + a[..., 2] * b[..., 2]).sum(-1)
    crs = (a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]).sum(-1)
    phi = np.arctan2(crs, dot)[..., None]                                 # (..., N, 1)
    c, s = np.cos(phi), np.sin(phi)
    x = a[..., 0] * c + a[..., 2] * s
    z = -a[..., 0] * s + a[..., 2] * c
    return np.stack([x, a[..., 1], z], -1) + source[..., :1, :]


def _fk(f: np.ndarray, positions: np.ndarray, sk: Skeleton, cfg: RecoveryConfig) -> np.ndarray:
    lengths = _lengths(positions, sk, cfg.lengths)                        # (..., J)
    raw = np.asarray(sk.raw_offsets, dtype=np.float64)
    if lengths.ndim == 1:
        joints = features_to_joints_rot(f, sk, offsets=raw * lengths[:, None])
    else:  # per-motion lengths: one FK per motion of the batch
        flat_f = f.reshape(-1, *f.shape[-2:])
        flat_l = lengths.reshape(-1, sk.num_joints)
        joints = np.stack([features_to_joints_rot(m, sk, offsets=raw * ln[:, None])
                           for m, ln in zip(flat_f, flat_l)]).reshape(positions.shape)
    if cfg.align_heading:
        joints = _yaw_onto(joints, positions)
    return joints


def fk_joints(features: Array, skeleton: SkeletonLike = "humanml3d", *,
              config: RecoveryConfig | None = None) -> np.ndarray:
    """Forward kinematics of the rotation features with fixed bone lengths (method ``"fk"``).

    Parameters
    ----------
    features : ``(..., N, D)`` numpy array or torch tensor
        De-normalised features.
    skeleton : name or Skeleton
    config : RecoveryConfig, optional
        Uses ``lengths`` (skeleton target or the motion's median lengths) and ``align_heading``.

    Returns
    -------
    ndarray ``(..., N, J, 3)``
        Every bone has exactly its fixed length in every frame; the root is the root channels'.
    """
    return _recover(features, skeleton, config, _fk)


# =========================================================================== "fit"
def branch_joints(skeleton: SkeletonLike = "humanml3d") -> dict[int, tuple[int, ...]]:
    """Joints with two or more children and their children: ``{parent: (child, ...)}``.

    For HumanML3D: the pelvis (hips and spine) and spine3 (neck and collars). A BVH (and every
    rig) holds such a joint's children at fixed offsets in the joint's frame, so a fit whose output
    a BVH is to reproduce exactly must move them together as one rigid body.
    """
    sk = get_skeleton(skeleton)
    children: dict[int, list[int]] = {}
    for j, par in enumerate(sk.parents):
        if par >= 0:
            children.setdefault(par, []).append(j)
    return {par: tuple(ch) for par, ch in children.items() if len(ch) >= 2}


def _kabsch(ref: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """Rotations ``(..., 3, 3)`` that best map the rest vectors ``ref (C, 3)`` onto ``obs (..., C, 3)``
    (least squares, proper rotations)."""
    m = np.einsum("...ci,cj->...ij", obs, ref)                            # sum_c obs_c ref_c^T
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt))
    u = u.copy()
    u[..., :, -1] *= np.where(d == 0, 1.0, d)[..., None]
    return u @ vt


def branch_rest_offsets(offsets: np.ndarray, lengths: np.ndarray, iterations: int = 4) -> np.ndarray:
    """The rigid rest geometry of one branch joint's children over a motion (a Procrustes mean).

    Parameters
    ----------
    offsets : ndarray ``(N, C, 3)``
        Per frame, each child's offset from the branch joint (e.g. the pelvis's to both hips and spine1).
    lengths : ndarray ``(C,)``
        The bone length each child keeps.

    Returns
    -------
    ndarray ``(C, 3)``: offsets of exactly ``lengths``, in the orientation of the motion's median frame,
    that every frame's offsets are closest to up to one rotation per frame. (A processed HumanML3D
    clip's pelvis holds its hips 8-9 cm below and 6 cm beside it; the rig's unit rest directions, purely
    sideways, are not this geometry, so it is measured, not assumed.)
    """
    o = np.asarray(offsets, dtype=np.float64)
    ln = np.asarray(lengths, dtype=np.float64)[:, None]
    rest = _normalize(o[o.shape[0] // 2]) * ln
    for _ in range(iterations):
        rot = _kabsch(rest, o)                                               # (N, 3, 3)
        rest = _normalize(np.einsum("nji,ncj->nci", rot, o).mean(0)) * ln    # frames turned back, averaged
    return rest


def fit_skeleton(positions: np.ndarray, lengths: np.ndarray, skeleton: SkeletonLike = "humanml3d", *,
                 directions: np.ndarray | None = None, direction_weight: float = 0.0,
                 rigid_branches: bool = False, refine: int = 0) -> np.ndarray:
    """Fixed-bone-length joints closest to ``positions``, fitted root outwards.

    Joint ``j`` is placed at ``q[parent] + lengths[j] * u`` with ``u`` the unit vector from the
    fitted parent to the predicted ``positions[j]`` (blended with ``directions[j]`` by
    ``direction_weight`` when given). The root stays where it is. With ``rigid_branches`` the
    children of each joint of :func:`branch_joints` are instead placed together: the skeleton's
    rest offsets (rest direction x length) turned by the rotation that best maps them onto the
    predicted offsets of that frame (Kabsch), so hips, spine, neck and collars keep the rig's
    geometry in every frame (what a BVH can hold exactly).

    Parameters
    ----------
    positions : ndarray ``(..., N, J, 3)``
        Predicted joints.
    lengths : ndarray ``(J,)`` or ``(..., J)``
        Bone length of ``parent(j) -> j`` (root entry ignored).
    skeleton : name or Skeleton
    directions : ndarray ``(..., N, J, 3)``, optional
        Another estimate of each bone's unit direction (e.g. from the rotation features).
    direction_weight : float
        Weight of ``directions`` in ``[0, 1]``.

    Returns
    -------
    ndarray ``(..., N, J, 3)`` float64 with ``|q[j] - q[parent(j)]| == lengths[j]`` exactly.
    """
    sk = get_skeleton(skeleton)
    p = np.asarray(positions, dtype=np.float64)
    if p.shape[-2:] != (sk.num_joints, 3):
        raise ValueError(f"positions must have shape (..., N, {sk.num_joints}, 3), got shape {p.shape}")
    if not 0.0 <= direction_weight <= 1.0:
        raise ValueError(f"direction_weight must be in [0, 1], got {direction_weight!r}")
    ln = np.asarray(lengths, dtype=np.float64)
    if ln.shape[-1] != sk.num_joints:
        raise ValueError(f"lengths must have a last axis of {sk.num_joints}, got shape {ln.shape}")
    ln = ln[..., None, :, None]                                          # (..., 1, J, 1) over frames
    raw = np.asarray(sk.raw_offsets, dtype=np.float64)
    q = np.empty_like(p)
    q[..., 0, :] = p[..., 0, :]
    placed: dict[int, np.ndarray] = {}
    if rigid_branches:
        lens = np.broadcast_to(np.asarray(lengths, dtype=np.float64), p.shape[:-3] + (sk.num_joints,))
        for par, kids in branch_joints(sk).items():
            obs = p[..., list(kids), :] - p[..., par:par + 1, :]             # (..., N, C, 3) predicted offsets
            flat_o = obs.reshape(-1, *obs.shape[-3:])
            flat_l = lens.reshape(-1, sk.num_joints)[:, list(kids)]
            if flat_l.shape[0] == 1 and flat_o.shape[0] > 1:
                flat_l = np.repeat(flat_l, flat_o.shape[0], axis=0)
            off = []
            for o, kid_lengths in zip(flat_o, flat_l):
                rest = branch_rest_offsets(o, kid_lengths)
                off.append(np.einsum("nij,cj->nci", _kabsch(rest, o), rest))
            off = np.stack(off).reshape(obs.shape)
            for c, kid in enumerate(kids):
                placed[kid] = off[..., c, :]
    for j in range(1, sk.num_joints):
        par = sk.parents[j]
        if j in placed:
            q[..., j, :] = q[..., par, :] + placed[j]
            continue
        # fallback for a child predicted on its fitted parent: the predicted bone, else the rest direction
        fallback = _normalize(p[..., j, :] - p[..., par, :], fallback=raw[j])
        u = _normalize(p[..., j, :] - q[..., par, :], fallback=fallback)
        if directions is not None and direction_weight > 0:
            u = _normalize((1.0 - direction_weight) * u + direction_weight * directions[..., j, :], fallback=u)
        q[..., j, :] = q[..., par, :] + ln[..., j, :] * u
    if refine > 0:
        subtree = _subtrees(sk)
        for _ in range(refine):
            for j in range(1, sk.num_joints):
                if j in placed:
                    continue
                par, sub = sk.parents[j], subtree[j]
                # turn bone par -> j so that its whole subtree, carried along rigidly, lands closest
                # to its predicted joints (one block of coordinate descent on sum |q - p|^2)
                goal = (p[..., sub, :] - (q[..., sub, :] - q[..., j:j + 1, :])).mean(-2)
                u = _normalize(goal - q[..., par, :], fallback=_normalize(q[..., j, :] - q[..., par, :]))
                move = q[..., par, :] + ln[..., j, :] * u - q[..., j, :]
                q[..., sub, :] += move[..., None, :]
    return q


def _subtrees(sk: Skeleton) -> dict[int, list[int]]:
    """Every joint's subtree (itself first, then its descendants)."""
    out = {j: [j] for j in range(sk.num_joints)}
    for j in range(sk.num_joints - 1, 0, -1):        # parents come before their children
        out[sk.parents[j]] += out[j]
    return out


def two_bone_ik(root: np.ndarray, mid: np.ndarray, goal: np.ndarray, len1, len2,
                hint: np.ndarray | None = None, max_reach=None) -> tuple[np.ndarray, np.ndarray]:
    """Analytic two-bone IK: place ``mid`` and the end so that the end reaches ``goal``.

    The chain ``root -> mid -> end`` keeps its bone lengths; the bend stays in the plane of the
    current ``mid`` (or, for a straight chain, of ``hint``). A goal out of reach is approached as
    closely as the lengths allow (fully stretched, or fully folded).

    Parameters
    ----------
    root, mid, goal : ndarray ``(..., 3)``
        Fixed chain root (hip), current middle joint (knee), goal of the end joint (ankle).
    len1, len2 : float or ndarray ``(...)``
        Lengths of ``root -> mid`` and ``mid -> end``.
    hint : ndarray ``(..., 3)``, optional
        Direction to bend towards when the current chain is straight (e.g. the foot's forward).
    max_reach : float or ndarray ``(...)``, optional
        Farthest root-to-end distance allowed (below ``len1 + len2``): a goal beyond it is approached
        along the same line only that far, so the chain is never straighter than this.

    Returns
    -------
    mid, end : ndarray ``(..., 3)``
    """
    l1 = np.asarray(len1, dtype=np.float64)[..., None]
    l2 = np.asarray(len2, dtype=np.float64)[..., None]
    v = goal - root
    dist = np.linalg.norm(v, axis=-1, keepdims=True)
    u = _normalize(v, fallback=_normalize(mid - root, fallback=-_UP))
    lo = np.abs(l1 - l2) + 1e-6
    hi = l1 + l2 - 1e-6
    if max_reach is not None:
        hi = np.minimum(hi, np.maximum(np.asarray(max_reach, dtype=np.float64)[..., None], lo))
    d = np.clip(dist, lo, hi)
    cos_a = np.clip((l1 ** 2 + d ** 2 - l2 ** 2) / (2.0 * l1 * d), -1.0, 1.0)
    sin_a = np.sqrt(1.0 - cos_a ** 2)
    pole = mid - root
    if hint is not None:
        # a small share of the hint decides only when the current bend is (nearly) straight
        pole = pole + 0.05 * l1 * _normalize(hint)
    pole = pole - (pole * u).sum(-1, keepdims=True) * u
    side = _normalize(np.cross(u, _UP), fallback=np.array([1.0, 0.0, 0.0]))
    m = _normalize(pole, fallback=_normalize(np.cross(side, u)))
    new_mid = root + l1 * (cos_a * u + sin_a * m)
    return new_mid, root + d * u


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and end (exclusive) of the runs of True in a 1-D bool array."""
    edge = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return np.nonzero(edge == 1)[0], np.nonzero(edge == -1)[0]


def contact_lock_mask(features: Array, joints: np.ndarray | None = None, skeleton: SkeletonLike = "humanml3d",
                      *, config: RecoveryConfig | None = None) -> np.ndarray:
    """Frames where each contact joint is locked: ``(..., N, 4)`` bool, in ``skeleton.contact_joints`` order.

    A joint locks where its contact channel is above ``contact_threshold``, it is no higher than
    ``contact_heights`` (ankle, toe) above y = 0 in ``joints`` (default: the position recovery),
    and the run of such frames lasts at least ``min_contact_frames``. HumanML3D's contact label
    (squared displacement under 0.002 m^2 per frame, i.e. up to 0.9 m/s) is on for most frames of a
    slow motion, also for a heel that is already rising; the height gate keeps those from locking.
    """
    sk = get_skeleton(skeleton)
    cfg = _config(config)
    f, _ = _as_numpy(features, sk)
    if joints is None:
        joints = features_to_joints(f, sk)
    joints = np.asarray(joints, dtype=np.float64)
    if joints.shape[:-2] != f.shape[:-1]:
        raise ValueError(f"joints {joints.shape} do not match features {f.shape} (need (..., N, J, 3))")
    on = f[..., sk.feature_slices["contacts"]] > cfg.contact_threshold             # (..., N, 4)
    scale = 1.0 / sk.feature_scale
    limit = np.array(cfg.contact_heights * 2) * scale                              # ankle, toe, ankle, toe
    heights = joints[..., list(sk.contact_joints), 1]
    lock = on & (heights <= limit)
    if cfg.contact_speed is not None:
        vel = f[..., sk.feature_slices["local_vel"]].reshape(*f.shape[:-1], sk.num_joints, 3)
        speed = np.linalg.norm(vel[..., list(sk.contact_joints), :][..., [0, 2]], axis=-1) * sk.fps
        lock &= speed <= cfg.contact_speed * scale
    if cfg.min_contact_frames > 1:
        flat = lock.reshape(-1, *lock.shape[-2:]).copy()
        for m in flat:
            for k in range(m.shape[-1]):
                starts, ends = _runs(m[:, k])
                for s, e in zip(starts, ends):
                    if e - s < cfg.min_contact_frames:
                        m[s:e, k] = False
        lock = flat.reshape(lock.shape)
    return lock


def _lock_goals(track: np.ndarray, lock: np.ndarray, blend: int, floor: float | None,
                leash: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame lock weight ``(N,)`` in [0, 1] and goal ``(N, 3)`` of one contact joint.

    Every locked run is anchored at the joint's median position over the run (height at least
    ``floor``); inside the run the goal is the anchor. Outside, the goal is the joint's own track
    plus the correction it had at the run's nearer edge, faded out over ``blend`` frames with the
    smoothstep weight ``3s^2 - 2s^3``, ``s = 1 - distance / (blend + 1)`` (corrections of the runs
    before and after a frame add up). Fading the *correction*, not pulling towards the anchor,
    leaves a fast swing between two plants on its own path.
    """
    n = track.shape[0]
    goal = track.copy()
    weight = np.zeros(n)
    starts, ends = _runs(lock)
    if len(starts) == 0:
        return weight, goal
    idx = np.arange(n)
    for s, e in zip(starts, ends):
        anchor = np.median(track[s:e], axis=0)
        if floor is not None:
            anchor[1] = max(anchor[1], floor)
        run_goal = np.broadcast_to(anchor, track[s:e].shape).copy()
        if leash is not None:
            # held at most ``leash`` (horizontally) from the joint's own track: a foot that the model
            # glides further than that slides along instead of pulling the leg out of shape
            off = run_goal[:, [0, 2]] - track[s:e][:, [0, 2]]
            norm = np.linalg.norm(off, axis=-1, keepdims=True)
            run_goal[:, [0, 2]] = track[s:e][:, [0, 2]] + off * np.minimum(1.0, leash / np.maximum(norm, _EPS))
        goal[s:e] = run_goal
        weight[s:e] = 1.0
        for edge, dist, cor in ((s, s - idx, run_goal[0] - track[s]), (e - 1, idx - (e - 1), run_goal[-1] - track[e - 1])):
            near = (dist >= 1) & (dist <= blend) & ~lock
            if not near.any():
                continue
            x = 1.0 - dist[near] / (blend + 1.0)
            w = x * x * (3.0 - 2.0 * x)
            goal[near] += w[:, None] * cor
            weight[near] = np.maximum(weight[near], w)
    return weight, goal


class _Leg(NamedTuple):
    """One leg's joints, bone lengths ``(N,)`` (foot ``(N, 1)``) and goals ``(N, 3)`` for :func:`lock_feet` /
    :func:`plant_feet`; ``weight (N,)`` > 0 where a goal applies."""

    ankle: int
    toe: int
    hip: int
    knee: int
    l1: np.ndarray
    l2: np.ndarray
    lf: np.ndarray
    goal_a: np.ndarray
    goal_t: np.ndarray
    weight: np.ndarray


def _leg_goals(q: np.ndarray, lock: np.ndarray, side: int, sk: Skeleton, blend: int, floor: float | None,
               leash: float | None = None) -> _Leg:
    """The goals of one leg's ankle and toe from their locks (:func:`_lock_goals`); where the toe is planted and
    the heel free, the ankle goes a foot length from the toe's goal; goals no lower than ``floor``."""
    ankle, toe = sk.contact_joints[2 * side], sk.contact_joints[2 * side + 1]
    if sk.parents[toe] != ankle:
        raise ValueError(f"skeleton {sk.name!r}: contact joint {toe} is not the child of {ankle}")
    hip, knee = _leg(sk, ankle)
    l1 = np.linalg.norm(q[:, knee] - q[:, hip], axis=-1)
    l2 = np.linalg.norm(q[:, ankle] - q[:, knee], axis=-1)
    lf = np.linalg.norm(q[:, toe] - q[:, ankle], axis=-1)[:, None]
    wa, goal_a = _lock_goals(q[:, ankle], lock[:, 2 * side], blend, floor, leash)
    wt, goal_t = _lock_goals(q[:, toe], lock[:, 2 * side + 1], blend, floor, leash)
    heel_free = (wt * (1.0 - wa))[:, None]
    via_toe = goal_t + lf * _normalize(goal_a - goal_t, fallback=_UP)
    goal_a = goal_a + heel_free * (via_toe - goal_a)
    if floor is not None:
        goal_a[:, 1] = np.maximum(goal_a[:, 1], floor)
        goal_t[:, 1] = np.maximum(goal_t[:, 1], floor)
    return _Leg(ankle, toe, hip, knee, l1, l2, lf, goal_a, goal_t, np.maximum(wa, wt))


def _solve_leg(q: np.ndarray, leg: _Leg, max_reach=None) -> None:
    """In place: hip -> knee -> ankle by :func:`two_bone_ik` towards the ankle goal, the toe aimed at its goal,
    on the frames where the leg's weight is above 0."""
    active = leg.weight > 0
    if not active.any():
        return
    new_knee, new_ankle = two_bone_ik(q[:, leg.hip], q[:, leg.knee], leg.goal_a, leg.l1, leg.l2,
                                      hint=q[:, leg.toe] - q[:, leg.ankle], max_reach=max_reach)
    new_toe = new_ankle + leg.lf * _normalize(leg.goal_t - new_ankle,
                                              fallback=_normalize(q[:, leg.toe] - q[:, leg.ankle]))
    q[active, leg.knee] = new_knee[active]
    q[active, leg.ankle] = new_ankle[active]
    q[active, leg.toe] = new_toe[active]


def _motion_and_lock(joints: np.ndarray, lock: np.ndarray, sk: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """A float64 copy of one motion's ``joints`` ``(N, J, 3)`` and ``lock`` as ``(N, 4)`` bool; ``ValueError``
    naming the array whose shape is not that."""
    q = np.array(joints, dtype=np.float64)
    if q.ndim != 3 or q.shape[1:] != (sk.num_joints, 3):
        raise ValueError(f"joints must have shape (N, {sk.num_joints}, 3), got shape {q.shape}")
    lock = np.asarray(lock, dtype=bool)
    if lock.shape != (q.shape[0], 4):
        raise ValueError(f"lock must have shape ({q.shape[0]}, 4), got shape {lock.shape}")
    return q, lock


def lock_feet(joints: np.ndarray, lock: np.ndarray, skeleton: SkeletonLike = "humanml3d", *,
              blend_frames: int = 3, floor: float | None = 0.0) -> np.ndarray:
    """Keep the contact joints in place while they are locked, moving the legs by two-bone IK.

    Each locked run of a contact joint is anchored at the joint's median position over the run;
    the correction this makes at the run's edges fades in over ``blend_frames`` frames before the
    run and out after it, so nothing pops. Per foot, the ankle's goal is its (blended) anchor; where the toe is locked and the ankle
    is not, the ankle goal moves to a foot length from the toe's anchor. Hip -> knee -> ankle is
    solved by :func:`two_bone_ik` (the knee keeps its bend plane), then the toe is aimed at its goal
    from the new ankle. Bone lengths are unchanged; joints above the knees are untouched.

    Parameters
    ----------
    joints : ndarray ``(N, J, 3)``
        One motion with fixed bone lengths.
    lock : ndarray ``(N, 4)`` bool
        From :func:`contact_lock_mask`, in ``skeleton.contact_joints`` order (left ankle, left toe,
        right ankle, right toe for HumanML3D).
    skeleton : name or Skeleton
    blend_frames : int
    floor : float or None
        Lowest height of an anchor and a goal (``None``: no floor).

    Returns
    -------
    ndarray ``(N, J, 3)`` float64
    """
    sk = get_skeleton(skeleton)
    q, lock = _motion_and_lock(joints, lock, sk)
    for side in (0, 1):
        if lock[:, 2 * side:2 * side + 2].any():
            _solve_leg(q, _leg_goals(q, lock, side, sk, blend_frames, floor))
    return q


def plant_feet(joints: np.ndarray, lock: np.ndarray, skeleton: SkeletonLike = "humanml3d", *,
               blend_frames: int = 3, floor: float | None = 0.0, max_foot_shift: float | None = 0.04,
               reach_slack: float = 0.03, root_sigma: float = 2.0, move_root: bool = False) -> np.ndarray:
    """Plant the feet where they are locked, moving the legs and, where a leg cannot reach, the body.

    The faithful version of :func:`lock_feet`: it never stretches a leg to a place the model did
    not put it. Per contact joint, each locked run is anchored at the joint's median position over
    the run, but the goal stays within ``max_foot_shift`` (horizontally) of the joint's own track,
    so a foot that the model glides further slides along; the correction fades in and out over
    ``blend_frames`` frames. Then, per leg, the hip-to-ankle-goal distance is compared with how
    far the model itself extended that leg in that frame (plus ``reach_slack``, at most the leg's
    length): what is left over is the share the body must move, horizontally towards the goal (and
    down only where the foot is further below the hip than the leg reaches). The
    legs' shares are averaged (double support), smoothed over time with a Gaussian of
    ``root_sigma`` frames and added to every joint (the root and the whole body translate, the pose
    is kept). Last, hip -> knee -> ankle is solved by :func:`two_bone_ik` no straighter than that
    reach, and the toe aimed at its goal. A foot joint below ``floor`` (planted or not) gets a goal
    on the floor the same way.

    Parameters
    ----------
    joints : ndarray ``(N, J, 3)``
        One motion with fixed bone lengths.
    lock : ndarray ``(N, 4)`` bool
        From :func:`contact_lock_mask`, in ``skeleton.contact_joints`` order.
    skeleton : name or Skeleton
    blend_frames, floor, max_foot_shift, reach_slack, root_sigma, move_root
        As in :class:`RecoveryConfig` (``move_root=False``: a foot out of reach is approached only
        as far as ``reach`` allows and slides by the rest).

    Returns
    -------
    ndarray ``(N, J, 3)`` float64, bone lengths unchanged.
    """
    sk = get_skeleton(skeleton)
    q, lock = _motion_and_lock(joints, lock, sk)
    legs, reaches = [], []
    for side in (0, 1):
        leg = _leg_goals(q, lock, side, sk, blend_frames, floor, max_foot_shift)
        if floor is not None:           # a foot joint below the floor gets a goal on it, planted or not
            below = (q[:, leg.ankle, 1] < floor) | (q[:, leg.toe, 1] < floor)
            leg = leg._replace(weight=np.where(below, 1.0, leg.weight))
        legs.append(leg)
        # how straight the model made this leg, and how far IK may go beyond that
        ext = np.linalg.norm(q[:, leg.ankle] - q[:, leg.hip], axis=-1)
        reaches.append(np.minimum(ext + reach_slack, leg.l1 + leg.l2 - 1e-6))
    if move_root:
        q += _root_shift(q, legs, reaches, root_sigma)[:, None, :]
    for leg, reach in zip(legs, reaches):
        _solve_leg(q, leg, max_reach=reach)
    return q


def _root_shift(q: np.ndarray, legs: list[_Leg], reaches: list[np.ndarray], sigma: float) -> np.ndarray:
    """``(N, 3)``: the body's share of :func:`plant_feet` (``move_root``): per leg, what its ankle goal is
    beyond ``reach`` from the hip, horizontally first (a gliding body catches up with its planted foot) and
    down only when the foot is lower than the leg reaches even straight below the hip (a body hovering over
    its feet); the legs' shares averaged (double support) and smoothed with a Gaussian of ``sigma`` frames."""
    need = np.zeros((q.shape[0], 3))
    count = np.zeros((q.shape[0], 1))
    for leg, reach in zip(legs, reaches):
        v = leg.goal_a - q[:, leg.hip]
        horiz = np.linalg.norm(v[:, [0, 2]], axis=-1)
        below = np.maximum(-v[:, 1], 0.0)
        h_reach = np.sqrt(np.maximum(reach ** 2 - below ** 2, 0.0))
        s_h = np.maximum(horiz - h_reach, 0.0) * (leg.weight > 0)
        s_v = np.maximum(below - reach, 0.0) * (leg.weight > 0)
        step = np.zeros_like(v)
        step[:, [0, 2]] = (s_h / np.maximum(horiz, _EPS))[:, None] * v[:, [0, 2]]
        step[:, 1] = -s_v
        need += step
        count += ((s_h > 0) | (s_v > 0))[:, None]
    shift = need / np.maximum(count, 1.0)
    if sigma > 0 and q.shape[0] > 1:
        shift = gaussian_filter1d(shift, sigma, axis=0, mode="nearest")
    return shift


def lift_above_floor(joints: np.ndarray, floor: float = 0.0) -> np.ndarray:
    """Lift every frame whose lowest joint is below ``floor`` by the difference (bones unchanged).

    ``joints`` ``(..., N, J, 3)``; returns a new float64 array.
    """
    q = np.array(joints, dtype=np.float64)
    deficit = np.maximum(floor - q[..., 1].min(-1), 0.0)                    # (..., N)
    q[..., 1] += deficit[..., None]
    return q


def _fit_one(f: np.ndarray, positions: np.ndarray, sk: Skeleton, cfg: RecoveryConfig) -> np.ndarray:
    lengths = _lengths(positions, sk, cfg.lengths)
    if cfg.smooth_sigma > 0 and positions.shape[0] > 1:
        # a per-frame fit cannot remove frame-to-frame noise, and short bones (spine3: 6 cm) turn
        # small position noise into large direction noise (unsmoothed, the fit's jitter is ~20 %
        # above the raw positions' on generated motions); half a frame brings it back down
        positions = gaussian_filter1d(positions, cfg.smooth_sigma, axis=0, mode="nearest")
    directions = None
    if cfg.rotation_weight > 0:
        fk = _fk(f, positions, sk, cfg)
        parents = [max(p, 0) for p in sk.parents]
        directions = _normalize(fk - fk[..., parents, :])
    q = fit_skeleton(positions, lengths, sk, directions=directions, direction_weight=cfg.rotation_weight,
                     rigid_branches=cfg.rigid_branches, refine=cfg.refine)
    floor = 0.0 if cfg.floor else None
    if cfg.lock_contacts or cfg.floor:
        lock = contact_lock_mask(f, q, sk, config=cfg) if cfg.lock_contacts else np.zeros((q.shape[0], 4), bool)
        q = plant_feet(q, lock, sk, blend_frames=cfg.blend_frames, floor=floor,
                       max_foot_shift=cfg.max_foot_shift, reach_slack=cfg.reach_slack, root_sigma=cfg.root_sigma,
                       move_root=cfg.move_root)
    if cfg.floor:
        q = lift_above_floor(q, 0.0)
    return q


def _fit(f: np.ndarray, positions: np.ndarray, sk: Skeleton, cfg: RecoveryConfig) -> np.ndarray:
    """:func:`_fit_one` for each motion of a batch ``(..., N, D)``, positions ``(..., N, J, 3)``."""
    flat_f = f.reshape(-1, *f.shape[-2:])
    flat_p = positions.reshape(-1, *positions.shape[-3:])
    return np.stack([_fit_one(a, b, sk, cfg) for a, b in zip(flat_f, flat_p)]).reshape(positions.shape)


def fit_joints(features: Array, skeleton: SkeletonLike = "humanml3d", *,
               config: RecoveryConfig | None = None) -> np.ndarray:
    """Skeleton fit with fixed bone lengths, locked feet and a floor (method ``"fit"``).

    Parameters
    ----------
    features : ``(..., N, D)`` numpy array or torch tensor
        De-normalised features.
    skeleton : name or Skeleton
    config : RecoveryConfig, optional

    Returns
    -------
    ndarray ``(..., N, J, 3)``
        Bone lengths fixed in every frame; locked feet keep their place; with ``floor`` no joint
        below y = 0.
    """
    return _recover(features, skeleton, config, _fit)


# =========================================================================== entry point
def _positions(f: np.ndarray, positions: np.ndarray, sk: Skeleton, cfg: RecoveryConfig) -> np.ndarray:
    """The position features as they are (method ``"positions"``)."""
    return positions


#: Joints from ``(f, positions, sk, cfg)`` for each of :data:`METHODS`.
_BY_METHOD: dict[str, Callable[[np.ndarray, np.ndarray, Skeleton, RecoveryConfig], np.ndarray]] = {
    "positions": _positions, "fk": _fk, "fit": _fit}


def check_method(method) -> str:
    """``method`` if it is one of :data:`METHODS` (what a pipeline's ``recovery`` may be), else ``ValueError``."""
    if method not in METHODS:
        raise ValueError(f"recovery must be one of {METHODS}, got {method!r}")
    return str(method)


def recover_joints(features: Array, method: str = DEFAULT_METHOD, skeleton: SkeletonLike = "humanml3d", *,
                   config: RecoveryConfig | None = None) -> np.ndarray:
    """Joints ``(..., N, J, 3)`` from de-normalised features ``(..., N, D)``.

    Parameters
    ----------
    features : ``(..., N, D)`` numpy array or torch tensor
        De-normalised features (HumanML3D 263-d, KIT 251-d), one motion ``(N, D)`` or a batch.
    method : {"positions", "fk", "fit"}
        ``"positions"``: the position features as they are (HumanML3D ``recover_from_ric``);
        ``"fk"``: forward kinematics of the rotation features with fixed bone lengths;
        ``"fit"``: fixed-length skeleton fitted to the positions, feet locked from the contact
        channels, nothing below the floor. See the module docstring.
    skeleton : name or Skeleton
    config : RecoveryConfig, optional
        Options of ``"fk"`` and ``"fit"``.

    Returns
    -------
    ndarray ``(..., N, J, 3)``, metres for HumanML3D; float32 for float32 input, else float64.

    Raises
    ------
    ValueError
        For an unknown method, a feature width that does not match the skeleton, or NaN/inf.
    """
    _check_method(method)
    return _recover(features, skeleton, config, _BY_METHOD[method])
