"""Hands at world points: arm controls that put a wrist where it must touch something
(the floor, a knee), given the rest of the body's pose.

The chest frame and shoulder positions are those :func:`~.kinematics.assemble` builds from the
pose's pelvis and spine controls, so a target within the arm's reach is met exactly.
"""
from __future__ import annotations

import numpy as np

from .kinematics import BodyModel, Pose, arm_angles_for_target, assemble, trunk_frames

__all__ = ["chest_frames", "shoulders", "arm_controls_for", "wrist_reach"]


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
