"""Place a body on the floor: root height, a root path that does not slide, ballistic flight, planted feet.

The general-motion generator produces body-relative joints (pelvis at the origin, body already
oriented); this module solves where the body is in the world:

* **height** -- on the ground the lowest joint rests on the floor: every joint centre keeps at
  least its flesh radius (:data:`~.general_body.FLESH_RADIUS`) above y = 0 and the closest one
  touches it, whatever the body's orientation (standing, kneeling, lying, on the hands);
* **horizontal path** -- the joints touching the floor do not slide: the root moves by minus the
  (softly weighted) body-relative displacement of the supporting joints, so stepping legs carry
  the body forwards, sideways or backwards and a rolling body rolls along the floor;
* **flight** -- in flight intervals (jumps, the airborne phase of a run) the root follows a
  parabola under gravity between take-off and landing heights and keeps its take-off horizontal
  velocity (plus an optional push);
* **planted feet** -- a final pass pins the heel (ankle) and the toe of each foot in xz while they
  touch the floor (a flat foot neither slides nor turns, a rolling foot pivots about the end that is
  down) and re-solves the leg with exact two-bone IK (:func:`~.kinematics.two_bone_ik`). Generator
  1.1 (pins on both ends, the body's turn no longer turning a planted foot): the set's feet skate
  0.07 m/s on :mod:`salad_core.eval.physics`'s measure instead of 1.0's 0.23 (``lab/scripts/vae/general_skating.py``).
"""
from __future__ import annotations

import numpy as np

from .curves import min_jerk
from .general_body import flesh_radii
from .kinematics import FPS, body_model, two_bone_ik

__all__ = ["GRAVITY", "intervals", "ground_heights", "solve_root", "plant_feet"]

#: Gravity (m/s^2) of the ballistic flights.
GRAVITY = 9.81
#: Softness (m) of the support weights: joints within a few of these of the floor share the load.
SUPPORT_SOFTNESS = 0.012
#: Joints further than this (m) above their rest height carry no weight.
SUPPORT_RANGE = 0.04
#: A foot closer than this (m) to its rest height on the floor is in contact (plant_feet).
CONTACT_GAP = 0.035
#: A lifted foot's pin correction fades only while both its ends are this far (m) above their
#: resting heights, so a foot skimming the floor keeps its correction instead of sliding back.
RELEASE_GAP = 0.05


def intervals(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open ``[start, stop)`` runs of True in a boolean ``(N,)`` mask."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    d = np.diff(m.astype(np.int8))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def ground_heights(rel: np.ndarray) -> np.ndarray:
    """``(N,)`` pelvis height that puts the lowest joint (flesh included) on the floor.

    ``rel`` are body-relative joints ``(N, J, 3)`` (pelvis at the origin).
    """
    return np.max(flesh_radii()[None, :] - rel[..., 1], axis=1)


def solve_root(rel: np.ndarray, flight: np.ndarray | None = None, push: np.ndarray | None = None,
               fps: float = FPS) -> np.ndarray:
    """World pelvis path ``(N, 3)`` for body-relative joints ``rel (N, J, 3)``.

    Parameters
    ----------
    rel : ndarray ``(N, J, 3)``
        Joints relative to the pelvis (metres), body orientation included.
    flight : bool ndarray ``(N,)``, optional
        Frames in the air. A flight touching the first or last frame is treated as ground.
    push : ndarray ``(N, 2)``, optional
        Extra horizontal velocity (m/s, world x and z) added during flight frames (a long jump).
    fps : float
        Frame rate.

    Returns
    -------
    ndarray ``(N, 3)``: pelvis x, height, z; x = z = 0 at frame 0. No joint (flesh included) goes
    below the floor in any frame.
    """
    n = rel.shape[0]
    flight = np.zeros(n, dtype=bool) if flight is None else np.asarray(flight, dtype=bool).copy()
    push = np.zeros((n, 2)) if push is None else np.asarray(push, dtype=np.float64)
    h_ground = ground_heights(rel)
    h = h_ground.copy()
    runs = [(a, b) for a, b in intervals(flight) if a > 0 and b < n]
    for a, b in intervals(flight):
        if (a, b) not in runs:
            flight[a:b] = False
    for a, b in runs:                                      # a-1 and b are on the ground
        t_total = (b - a + 1) / fps
        tau = (np.arange(a, b) - (a - 1)) / fps
        line = h_ground[a - 1] + (h_ground[b] - h_ground[a - 1]) * tau / t_total
        h[a:b] = np.maximum(line + 0.5 * GRAVITY * tau * (t_total - tau), h_ground[a:b])

    radii = flesh_radii()[None, :]
    gap = rel[..., 1] + h[:, None] - radii                 # (N, J) height above the resting height
    step = np.zeros((n, 2))
    for t in range(1, n):
        if flight[t]:
            continue
        g = np.maximum(gap[t], gap[t - 1])                 # loaded in both frames: no drag on touch-down
        w = np.where(g < SUPPORT_RANGE, np.exp(-np.maximum(g, 0.0) / SUPPORT_SOFTNESS), 0.0)
        if w.sum() <= 0:
            w = (gap[t] <= gap[t].min() + 1e-9).astype(np.float64)
        w /= w.sum()
        step[t] = -(w[:, None] * (rel[t, :, [0, 2]].T - rel[t - 1, :, [0, 2]].T)).sum(0)
    for a, b in runs:                                      # keep the take-off velocity (+ push)
        lo = max(a - 3, 1)
        v0 = step[lo:a].mean(0) if a > lo else np.zeros(2)
        step[a:b] = v0 + push[a:b] / fps
        # landing: the first ground frame keeps the flight velocity so the body does not stop dead
        step[b] = 0.5 * (step[b] + step[b - 1])
    xz = np.cumsum(step, axis=0)
    return np.stack([xz[:, 0], h, xz[:, 1]], -1)


def _yaw(v: np.ndarray) -> np.ndarray:
    """Heading angle (rad) of horizontal vectors ``(..., 3)``: atan2(x, z)."""
    return np.arctan2(v[..., 0], v[..., 2])


def _turn(v: np.ndarray, angle: float) -> np.ndarray:
    """``v (3,)`` turned by ``angle`` (rad) about +Y, in the :func:`_yaw` sense."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([c * v[0] + s * v[2], v[1], -s * v[0] + c * v[2]])


def _contact_mask(gap: np.ndarray, flight: np.ndarray) -> np.ndarray:
    """Frames in which a foot end with heights ``gap (N,)`` above its resting height touches the
    floor: closer than :data:`CONTACT_GAP`, staying in contact down to half of it after touch-down."""
    low = (gap < CONTACT_GAP) & ~flight
    low[1:] &= low[:-1] | (gap[1:] < 0.5 * CONTACT_GAP)
    return low


def plant_feet(joints: np.ndarray, flight: np.ndarray | None = None, blend: int = 4) -> np.ndarray:
    """Pin the heel (ankle) and the toe of each foot where they touch the floor, re-solving the legs
    with exact IK.

    Each end of a foot is pinned in xz from the frame it touches the floor until it lifts: a flat
    foot does not move or turn, a foot rolling onto its toe pivots about the toe, a heel strike
    lowers the toe about the heel. When the heel and the toe are both pinned the foot keeps the
    heading from heel to toe; when only one is, the foot keeps the heading offset it had (so it can
    pivot on that end with the body). After a contact, the correction fades out over ``blend``
    frames (minimum jerk).

    Parameters
    ----------
    joints : ndarray ``(N, 22, 3)``
        World joints (HumanML3D order).
    flight : bool ndarray ``(N,)``, optional
        Frames in the air (never pinned).
    blend : int
        Frames over which a pin's correction fades out after the contact ends.

    Returns
    -------
    ndarray ``(N, 22, 3)``: a copy with the knees, ankles and toes moved; bone lengths are kept
    exactly (a target out of reach is approached as closely as the leg allows), and a frame whose
    re-solved leg would go into the floor keeps its original leg.
    """
    body = body_model("humanml3d")
    ix = body.index
    out = joints.copy()
    n = joints.shape[0]
    radii = flesh_radii()
    flight = np.zeros(n, dtype=bool) if flight is None else np.asarray(flight, dtype=bool)
    for k, side in enumerate(("left", "right")):
        hip, knee, ankle, toe = (ix[f"{side}_{p}"] for p in ("hip", "knee", "ankle", "foot"))
        heel_gap = joints[:, ankle, 1] - radii[ankle]                 # (N,) heights above resting on the floor
        toe_gap = joints[:, toe, 1] - radii[toe]
        heel_low, toe_low = _contact_mask(heel_gap, flight), _contact_mask(toe_gap, flight)
        clear = (heel_gap >= RELEASE_GAP) & (toe_gap >= RELEASE_GAP)   # (N,) both ends off the floor
        foot = joints[:, toe] - joints[:, ankle]                       # (N, 3) original foot vectors
        new_ankle = joints[:, ankle].copy()
        new_foot = foot.copy()
        heel_pin = toe_pin = None                                      # (2,) xz anchors
        cur_shift, cur_turn = np.zeros(2), 0.0                         # correction applied in frame t-1
        last_shift, last_turn = np.zeros(2), 0.0                       # ... in the last frame in contact
        since = blend + 1                                              # frames since the last contact
        for t in range(n):
            if not heel_low[t]:
                heel_pin = None
            if not toe_low[t]:
                toe_pin = None
            if not (heel_low[t] or toe_low[t]):                        # free: the correction fades out
                since += int(clear[t])                                 # ... once the foot is clear of the floor
                fade = 1.0 - float(min_jerk(since / (blend + 1))) if blend > 0 else 0.0
                cur_shift, cur_turn = last_shift * fade, last_turn * fade
                new_foot[t] = _turn(foot[t], cur_turn)
                new_ankle[t, [0, 2]] = joints[t, ankle, [0, 2]] + cur_shift
                continue
            since = 0
            if heel_pin is not None and toe_pin is not None:           # flat foot: heel -> toe heading
                way = np.array([toe_pin[0] - heel_pin[0], 0.0, toe_pin[1] - heel_pin[1]])
                turn = float(np.angle(np.exp(1j * (_yaw(way) - _yaw(foot[t])))))
            else:
                turn = cur_turn
            new_foot[t] = _turn(foot[t], turn)
            if toe_pin is not None:
                new_ankle[t, [0, 2]] = toe_pin - new_foot[t, [0, 2]]
            elif heel_pin is not None:
                new_ankle[t, [0, 2]] = heel_pin
            else:                                                      # touching down now: where it is
                new_ankle[t, [0, 2]] = joints[t, ankle, [0, 2]] + cur_shift
            if heel_low[t] and heel_pin is None:
                heel_pin = new_ankle[t, [0, 2]].copy()
            if toe_low[t] and toe_pin is None:
                toe_pin = (new_ankle[t] + new_foot[t])[[0, 2]].copy()
            cur_shift, cur_turn = new_ankle[t, [0, 2]] - joints[t, ankle, [0, 2]], turn
            last_shift, last_turn = cur_shift, cur_turn
        moved = (np.abs(new_ankle - joints[:, ankle]).sum(-1) + np.abs(new_foot - foot).sum(-1)) > 1e-12
        if not moved.any():
            continue
        pole = joints[:, knee] - 0.5 * (joints[:, hip] + joints[:, ankle])
        ik_knee, ik_ankle = two_bone_ik(joints[:, hip], new_ankle, body.thigh[k], body.shin[k], pole)
        ik_toe = ik_ankle + new_foot
        # a re-solved leg must not push a knee, ankle or toe into the floor: keep the original there
        moved &= ((ik_knee[:, 1] >= radii[knee] - 1e-9) & (ik_ankle[:, 1] >= radii[ankle] - 1e-9)
                  & (ik_toe[:, 1] >= radii[toe] - 1e-9))
        out[moved, knee] = ik_knee[moved]
        out[moved, ankle] = ik_ankle[moved]
        out[moved, toe] = ik_toe[moved]
    return out
