"""A procedural walking motion for demos, docs and tests (no dataset needed).

Built by forward kinematics from the skeleton's rest pose: legs and arms swing in opposite phase,
knees and elbows bend, the root moves forward along +Z (the direction HumanML3D motions start
facing), optionally turning, and every frame is put on the floor (lowest joint at y = 0).
Joints for the swing are found from the kinematic chains (a leg chain starts at the root, an
arm chain at the chest), so no joint index is hard-coded.
"""
from __future__ import annotations

import numpy as np

from salad_core.skeleton import Skeleton, get_skeleton

from ._style import chain_sides
from .kinematics import axis_angle_matrix, forward_kinematics, rest_directions

__all__ = ["synthetic_motion"]


def synthetic_motion(skeleton: str | Skeleton = "humanml3d", n_frames: int = 40, *, speed: float = 1.1,
                     turn_degrees: float = 0.0, step_hz: float = 0.9, fps: float | None = None,
                     bone_lengths=None) -> np.ndarray:
    """Joint positions ``(N, J, 3)`` in metres of a simple walk.

    Parameters
    ----------
    skeleton : str or Skeleton
    n_frames : int
        Number of frames N.
    speed : float
        Forward speed in m/s.
    turn_degrees : float
        Total yaw turn over the clip (positive = towards +X, i.e. to the character's left).
    step_hz : float
        Gait cycles per second.
    fps : float, optional
        Frame rate (default the skeleton's).
    bone_lengths : array (J,), optional
        Needed for skeletons without target lengths (KIT).
    """
    skel = get_skeleton(skeleton)
    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    fps = skel.fps if fps is None else float(fps)
    if bone_lengths is None:
        if skel.bone_lengths is None:
            raise ValueError(f"skeleton {skel.name!r} has no target bone lengths; pass bone_lengths=")
        bone_lengths = skel.bone_lengths
    offsets = rest_directions(skel, arms="down") * np.asarray(bone_lengths, dtype=np.float64)[:, None]
    n, J = int(n_frames), skel.num_joints
    t = np.arange(n) / fps
    phase = 2 * np.pi * step_hz * t
    x_axis = np.array([1.0, 0.0, 0.0])
    rot = np.broadcast_to(np.eye(3), (n, J, 3, 3)).copy()
    sides = chain_sides(skel)
    for chain, side in zip(skel.kinematic_chains, sides):
        if side == "mid":
            continue
        sign = 1.0 if side == "left" else -1.0
        if chain[0] == 0 and len(chain) >= 3:  # leg: hip swing, knee bend on the back swing
            hip, knee = chain[1], chain[2]
            swing = np.radians(28.0) * sign * np.sin(phase)
            bend = np.radians(45.0) * np.clip(-sign * np.sin(phase + 0.6), 0, None)
            # rotating a downward bone about +X by a negative angle moves it forward (+Z)
            rot[:, hip] = axis_angle_matrix(x_axis, -swing)
            rot[:, knee] = axis_angle_matrix(x_axis, bend)
        elif chain[0] != 0 and len(chain) >= 4:  # arm: the last two bones are upper and lower arm
            shoulder, elbow = chain[-3], chain[-2]
            swing = np.radians(22.0) * -sign * np.sin(phase)
            rot[:, shoulder] = axis_angle_matrix(x_axis, -swing)
            rot[:, elbow] = axis_angle_matrix(x_axis, -np.radians(20.0) - 0.5 * np.abs(swing))
    yaw = np.radians(turn_degrees) * (t / max(t[-1], 1e-9) if n > 1 else t)
    rot[:, 0] = axis_angle_matrix(np.array([0.0, 1.0, 0.0]), yaw)
    heading = np.stack([np.sin(yaw), np.zeros_like(yaw), np.cos(yaw)], axis=-1)
    root = np.concatenate([np.zeros((1, 3)), np.cumsum(heading[1:] * speed / fps, axis=0)], axis=0)
    joints = forward_kinematics(offsets, skel.parents, rot, root)
    joints[..., 1] -= joints[..., 1].min(axis=1, keepdims=True)
    return joints
