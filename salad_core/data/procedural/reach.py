"""Hands at world points: arm controls that put a wrist where it must touch something
(the floor, a knee), given the rest of the body's pose.

The chest frame and shoulder positions are those :func:`~.kinematics.assemble` builds from the
pose's pelvis and spine controls, so a target within the arm's reach is met exactly.
"""
from __future__ import annotations

import numpy as np

from .kinematics import BodyModel, Pose, arm_angles_for_target, assemble, trunk_frames

__all__ = ["chest_frames", "shoulders", "arm_controls_for", "wrist_reach", "nearest_controls"]


def chest_frames(pose: Pose) -> np.ndarray:
    """``(N, 3, 3)`` chest (spine3) orientation of every frame, as :func:`assemble` builds it."""
    return trunk_frames(pose)[2]


def shoulders(pose: Pose, body: BodyModel) -> np.ndarray:
    """``(N, 2, 3)`` world positions of the left and right shoulder joints."""
    j = assemble(pose, body)
    return j[:, [body.j("left_shoulder"), body.j("right_shoulder")]]


def wrist_reach(body: BodyModel, k: int) -> float:
    """Largest shoulder-to-wrist distance (m) of arm ``k`` (straight elbow)."""
    return float(body.upper_arm[k] + body.forearm[k])


def arm_controls_for(pose: Pose, body: BodyModel, k: int, wrist: np.ndarray) -> np.ndarray:
    """``(N, 3)`` (flex, abd, elbow) that put wrist ``k`` (0 left, 1 right) at ``wrist`` ``(N, 3)``.

    Targets beyond reach leave the arm straight towards them. Valid while the target is not
    behind the shoulder's frontal plane by more than the arm's length (|flex| <= 90 deg).
    """
    chest = chest_frames(pose)
    sh = shoulders(pose, body)[:, k]
    local = np.einsum("nji,nj->ni", chest, np.asarray(wrist, dtype=np.float64) - sh)   # chest^T (w - s)
    if k == 1:
        local[:, 0] *= -1.0                      # arm controls: x outwards for either arm
    return arm_angles_for_target(local, body.upper_arm[k], body.forearm[k])


def nearest_controls(controls: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``(..., 3)`` arm controls that put the wrist where ``controls`` do, written nearest to ``reference``.

    (flex, abd) and (pi - flex, abd + pi) point the arm the same way (abd counts modulo 2 pi), and
    the elbow flexion and pole do not depend on the choice. :func:`arm_controls_for` writes a
    direction with |flex| <= 90 deg, so an arm reaching past the head (or, with the trunk folded
    far forward, down to the feet) comes out with its abduction near +-180 deg; blended with
    controls written the other way it would swing through the body (2.7).
    """
    c = np.asarray(controls, dtype=np.float64)
    ref = np.broadcast_to(np.asarray(reference, dtype=np.float64), c.shape)
    best, cost = c.copy(), None
    for flex, abd in ((c[..., 0], c[..., 1]), (np.pi - c[..., 0], c[..., 1] + np.pi)):
        abd = abd + 2 * np.pi * np.round((ref[..., 1] - abd) / (2 * np.pi))
        d = np.abs(flex - ref[..., 0]) + np.abs(abd - ref[..., 1])
        if cost is None:
            best[..., 1], cost = abd, d
            continue
        take = d < cost - 1e-12
        best[..., 0] = np.where(take, flex, best[..., 0])
        best[..., 1] = np.where(take, abd, best[..., 1])
    return best
