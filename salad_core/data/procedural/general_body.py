"""Joint-angle body for general (uncaptioned) motion: degrees of freedom, anatomical limits, FK.

The captioned corpus places limbs by IK towards action targets; the general-motion generator
instead drives every joint angle directly, so that it can cover the space of poses. A pose is a
vector of :data:`DOFS` angles (radians) per frame; :func:`forward_kinematics` turns ``(N, D)``
angles into joints ``(N, 22, 3)`` on the HumanML3D skeleton with its exact target bone lengths
(every bone is a rotated rest offset of :func:`~.kinematics.body_model`).

Conventions (body frame: x = left, y = up, z = forward; right limbs are the mirror images of the
left ones, so one set of angles means the same movement on either side):

* root: ``R = Ry(heading) Rx(pitch) Rz(-roll) Ry(twist)``; pitch > 0 tips the body forward
  (+90 deg: prone, -90 deg: supine, 180 deg: upside down), roll > 0 leans to the left, twist
  turns the body about its own long axis (rolling over while lying);
* spine: total (twist, flexion, lateral bend) shared by spine1-3 as in the corpus;
* hip: flexion (thigh forwards), abduction (outwards), external rotation; knee: flexion;
  ankle: plantar flexion relative to a flat foot under a vertical shin, and yaw;
* collar: elevation, protraction; shoulder: (flexion, abduction) set the upper-arm direction
  like :func:`~.kinematics.arm_direction` (abduction 180 deg = arm overhead), then a twist about
  the upper arm; elbow: flexion.

:data:`LIMITS` holds the anatomical range of each angle (degrees); generated angle tracks stay
inside it by construction.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from .footwork import ANKLE_HEIGHT, TOE_HEIGHT, flat_pitch
from .kinematics import body_model, rot_x, rot_y, rot_z, ypr_matrix

__all__ = ["DOFS", "DOF_INDEX", "LIMITS", "ROOT_DOFS", "FLESH_RADIUS", "limits_array", "rest_dofs",
           "forward_kinematics", "flesh_radii"]

_SIDE_DOFS = ("hip_flex", "hip_abd", "hip_rot", "knee", "ankle", "ankle_yaw",
              "collar_elev", "collar_prot", "sh_flex", "sh_abd", "sh_twist", "elbow")
#: Root orientation angles: unbounded (rolls and flips wind them past 360 deg).
ROOT_DOFS = ("heading", "pitch", "roll", "twist")
#: Every angle of a pose, in column order.
DOFS: tuple[str, ...] = ROOT_DOFS + ("spine_flex", "spine_lat", "spine_twist", "neck_pitch", "neck_yaw",
                                     "neck_roll") + tuple(f"{s}_{d}" for s in "lr" for d in _SIDE_DOFS)
DOF_INDEX = {name: i for i, name in enumerate(DOFS)}

#: Anatomical range (degrees) of every non-root angle; side angles apply to both sides.
LIMITS: dict[str, tuple[float, float]] = {
    "spine_flex": (-35.0, 95.0),     # extension .. forward flexion (total over the three joints)
    "spine_lat": (-40.0, 40.0),
    "spine_twist": (-50.0, 50.0),
    "neck_pitch": (-55.0, 65.0),     # looking up .. chin to chest
    "neck_yaw": (-75.0, 75.0),
    "neck_roll": (-35.0, 35.0),
    "hip_flex": (-25.0, 130.0),
    "hip_abd": (-25.0, 65.0),
    "hip_rot": (-40.0, 45.0),        # internal .. external
    "knee": (0.0, 150.0),
    "ankle": (-25.0, 50.0),          # dorsiflexion .. plantar flexion around a flat foot
    "ankle_yaw": (-20.0, 20.0),
    "collar_elev": (-10.0, 30.0),
    "collar_prot": (-20.0, 25.0),
    "sh_flex": (-60.0, 90.0),        # arm behind .. arm forward (elevation towards the front)
    "sh_abd": (-30.0, 178.0),        # across the body .. overhead
    "sh_twist": (-80.0, 80.0),
    "elbow": (0.0, 150.0),
}

#: Height (m) a joint centre keeps above the floor when it rests on it (the flesh around it):
#: the feet use the corpus's flat-foot heights; pelvis and spine are the buttocks and back.
FLESH_RADIUS: dict[str, float] = {
    "pelvis": 0.11, "left_hip": 0.09, "right_hip": 0.09, "spine1": 0.10, "left_knee": 0.05,
    "right_knee": 0.05, "spine2": 0.10, "left_ankle": ANKLE_HEIGHT, "right_ankle": ANKLE_HEIGHT,
    "spine3": 0.10, "left_foot": TOE_HEIGHT, "right_foot": TOE_HEIGHT, "neck": 0.07,
    "left_collar": 0.08, "right_collar": 0.08, "head": 0.09, "left_shoulder": 0.06,
    "right_shoulder": 0.06, "left_elbow": 0.04, "right_elbow": 0.04, "left_wrist": 0.03,
    "right_wrist": 0.03,
}

_SPINE_SHARE = (0.45, 0.35, 0.2)
_MIRROR = np.diag([-1.0, 1.0, 1.0])


def limits_array() -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` arrays ``(D,)`` in radians; root angles are unbounded (``-inf, inf``)."""
    lo = np.full(len(DOFS), -np.inf)
    hi = np.full(len(DOFS), np.inf)
    for i, name in enumerate(DOFS):
        key = name[2:] if name[:2] in ("l_", "r_") else name
        if key in LIMITS:
            lo[i], hi[i] = np.radians(LIMITS[key])
    return lo, hi


def rest_dofs() -> np.ndarray:
    """``(D,)`` a relaxed upright stand: arms hanging slightly out, knees and elbows soft."""
    d = np.zeros(len(DOFS))
    for s in "lr":
        d[DOF_INDEX[f"{s}_hip_rot"]] = np.radians(8.0)
        d[DOF_INDEX[f"{s}_knee"]] = np.radians(5.0)
        d[DOF_INDEX[f"{s}_hip_flex"]] = np.radians(2.0)
        d[DOF_INDEX[f"{s}_ankle"]] = np.radians(3.0)
        d[DOF_INDEX[f"{s}_sh_abd"]] = np.radians(8.0)
        d[DOF_INDEX[f"{s}_elbow"]] = np.radians(15.0)
    return d


@lru_cache(maxsize=None)
def flesh_radii() -> np.ndarray:
    """``(22,)`` :data:`FLESH_RADIUS` in the skeleton's joint order."""
    sk = body_model("humanml3d").skeleton
    return np.array([FLESH_RADIUS[n] for n in sk.joint_names])


def _side(m: np.ndarray, side: str) -> np.ndarray:
    """A left-side local rotation, mirrored for the right side (``M R M``, still a rotation)."""
    return m if side == "l" else _MIRROR @ m @ _MIRROR


def forward_kinematics(dofs: np.ndarray, root: np.ndarray | None = None) -> np.ndarray:
    """Joint positions ``(N, 22, 3)`` (metres, float64) of pose angles ``dofs (N, D)`` (radians).

    Parameters
    ----------
    dofs : ndarray ``(N, len(DOFS))``
        Angles in :data:`DOFS` order.
    root : ndarray ``(N, 3)``, optional
        Pelvis positions (default: the origin).

    Returns
    -------
    ndarray ``(N, 22, 3)``; every bone has exactly the HumanML3D target length.
    """
    dofs = np.asarray(dofs, dtype=np.float64)
    if dofs.ndim != 2 or dofs.shape[1] != len(DOFS):
        raise ValueError(f"dofs must have shape (N, {len(DOFS)}), got {dofs.shape}")
    body = body_model("humanml3d")
    sk, off, ix = body.skeleton, body.rest_offsets, body.index
    n = dofs.shape[0]
    a = {name: dofs[:, i] for i, name in enumerate(DOFS)}
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    local = [eye] * sk.num_joints               # rotation of joint j's frame relative to its parent's
    pre = {}                                    # extra rotation of the bone that ends at a joint
    local[0] = ypr_matrix(np.stack([a["heading"], a["pitch"], a["roll"]], -1)) @ rot_y(a["twist"])
    spine = np.stack([a["spine_twist"], a["spine_flex"], a["spine_lat"]], -1)
    for name, share in zip(("spine1", "spine2", "spine3"), _SPINE_SHARE):
        local[ix[name]] = ypr_matrix(spine * share)
    half_neck = ypr_matrix(0.5 * np.stack([a["neck_yaw"], a["neck_pitch"], a["neck_roll"]], -1))
    pre[ix["neck"]] = half_neck                 # the neck bone takes half of the head's turn
    local[ix["neck"]] = half_neck
    phi0 = flat_pitch(body)
    for k, (s, side) in enumerate((("l", "left"), ("r", "right"))):
        g = lambda d: a[f"{s}_{d}"]             # noqa: E731
        local[ix[f"{side}_hip"]] = _side(rot_x(-g("hip_flex")) @ rot_z(g("hip_abd")) @ rot_y(g("hip_rot")), s)
        local[ix[f"{side}_knee"]] = _side(rot_x(g("knee")), s)
        local[ix[f"{side}_ankle"]] = _side(rot_x(phi0[k] + g("ankle")) @ rot_y(g("ankle_yaw")), s)
        local[ix[f"{side}_collar"]] = _side(rot_y(-g("collar_prot")) @ rot_z(g("collar_elev")), s)
        local[ix[f"{side}_shoulder"]] = _side(rot_z(g("sh_abd")) @ rot_x(-g("sh_flex")) @ rot_y(g("sh_twist")), s)
        local[ix[f"{side}_elbow"]] = _side(rot_x(-g("elbow")), s)
    out = np.zeros((n, sk.num_joints, 3))
    glob = [None] * sk.num_joints
    glob[0] = local[0]
    if root is not None:
        out[:, 0] = np.asarray(root, dtype=np.float64)
    for j in range(1, sk.num_joints):
        p = sk.parents[j]
        g_bone = glob[p] @ pre[j] if j in pre else glob[p]
        out[:, j] = out[:, p] + g_bone @ off[j]
        glob[j] = g_bone @ local[j]
    return out
