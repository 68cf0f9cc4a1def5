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
* **planted feet** -- a final pass pins each foot's floor contacts in xz and re-solves the leg with
  exact two-bone IK (:func:`~.kinematics.two_bone_ik`), removing residual foot sliding.
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
CONTACT_GAP = 0.025


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


def plant_feet(joints: np.ndarray, flight: np.ndarray | None = None, blend: int = 4) -> np.ndarray:
    """Pin feet that touch the floor in xz and re-solve the legs with exact IK.

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
    exactly (a target out of reach is approached as closely as the leg allows).
    """
    body = body_model("humanml3d")
    ix = body.index
    out = joints.copy()
    n = joints.shape[0]
    radii = flesh_radii()
    flight = np.zeros(n, dtype=bool) if flight is None else np.asarray(flight, dtype=bool)
    for k, side in enumerate(("left", "right")):
        hip, knee, ankle, toe = (ix[f"{side}_{p}"] for p in ("hip", "knee", "ankle", "foot"))
        gaps = np.stack([joints[:, ankle, 1] - radii[ankle], joints[:, toe, 1] - radii[toe]], -1)
        low = (gaps.min(-1) < CONTACT_GAP) & ~flight
        low[1:] &= low[:-1] | (gaps[1:].min(-1) < 0.5 * CONTACT_GAP)
        # the contact point: ankle and toe weighted by how close each is to the floor
        w = np.exp(-np.maximum(gaps, 0.0) / SUPPORT_SOFTNESS)
        w /= w.sum(-1, keepdims=True)
        point = w[:, :1] * joints[:, ankle, :] + w[:, 1:] * joints[:, toe, :]
        corr = np.zeros((n, 3))
        for a, b in intervals(low):
            drift = point[a:b, [0, 2]] - point[a, [0, 2]]
            corr[a:b, [0, 2]] = -drift
            stop = min(b + blend, n)
            if stop > b:
                fade = 1.0 - min_jerk((np.arange(b, stop) - b + 1) / (blend + 1))
                corr[b:stop] = np.where(np.abs(corr[b:stop]).sum(-1, keepdims=True) > 0,
                                        corr[b:stop], corr[b - 1] * fade[:, None])
        moved = np.abs(corr).sum(-1) > 1e-12
        if not moved.any():
            continue
        foot_vec = joints[:, toe] - joints[:, ankle]
        pole = joints[:, knee] - 0.5 * (joints[:, hip] + joints[:, ankle])
        new_knee, new_ankle = two_bone_ik(joints[:, hip], joints[:, ankle] + corr, body.thigh[k], body.shin[k], pole)
        # a re-solved leg must not push a knee, ankle or toe into the floor: keep the original there
        moved &= ((new_knee[:, 1] >= radii[knee] - 1e-9) & (new_ankle[:, 1] >= radii[ankle] - 1e-9)
                  & (new_ankle[:, 1] + foot_vec[:, 1] >= radii[toe] - 1e-9))
        out[moved, knee] = new_knee[moved]
        out[moved, ankle] = new_ankle[moved]
        out[moved, toe] = new_ankle[moved] + foot_vec[moved]
    return out
