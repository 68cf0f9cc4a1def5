"""What to draw for one frame, independent of the backend that draws it.

:func:`build_scene` turns motions, colours and view options into a :class:`FrameScene` (poses,
colours, trajectories, floor patch, camera). The pyvista renderer and the 2D rasteriser both draw
a ``FrameScene``, which is why the two backends show the same view.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from salad_core.skeleton import Skeleton

from ._style import TRAJECTORY, THEME_HUES, motion_bone_colors, to_rgb
from .camera import Camera, fixed_camera, follow_camera

__all__ = ["FrameScene", "build_scene", "frame_joint_colors"]


@dataclass(frozen=True)
class FrameScene:
    """Everything a backend needs to draw one frame (arrays are private copies)."""

    poses: tuple[np.ndarray, ...]          # per motion (J, 3) joint positions
    bone_colors: tuple[np.ndarray, ...]    # per motion (J, 3) RGB of the bone ending at each joint
    joint_colors: tuple[np.ndarray, ...]   # per motion (J, 3) RGB of each joint sphere
    trajectories: tuple[np.ndarray, ...]   # per motion (T, 3) root path on the floor (may be empty)
    trajectory_colors: tuple[tuple[float, float, float], ...]  # per motion RGB of its path
    camera: Camera                         # shared camera
    floor_centre: tuple[float, float] | None  # (x, z) centre of the floor patch, None = no floor
    floor_half_extent: float               # half side of the floor patch in metres
    bone_radius: float                     # metres
    joint_radius: float                    # metres


def frame_joint_colors(joint_colors, n_motions: int, lengths: Sequence[int], J: int, frame: int) -> list:
    """Per-motion ``(J, 3)`` joint colours at ``frame`` from the user's ``joint_colors`` argument.

    ``joint_colors`` is ``None``, one array (``(J, 3)`` or ``(N, J, 3)``) for a single motion, or a
    list with one such entry (or ``None``) per motion.
    """
    if joint_colors is None:
        return [None] * n_motions
    if isinstance(joint_colors, (list, tuple)):
        if len(joint_colors) != n_motions:
            raise ValueError(f"joint_colors must have one entry per motion ({n_motions}), got {len(joint_colors)}")
        specs = list(joint_colors)
    else:
        if n_motions != 1:
            raise ValueError("with several motions, joint_colors must be a list with one entry per motion")
        specs = [joint_colors]
    out = []
    for k, spec in enumerate(specs):
        if spec is None:
            out.append(None)
            continue
        arr = np.asarray(spec, dtype=np.float64)
        if arr.ndim == 3:
            if arr.shape[1:] != (J, 3):
                raise ValueError(f"joint_colors[{k}] must be (N, J, 3) or (J, 3) with J = {J}, got {arr.shape}")
            arr = arr[min(frame, lengths[k] - 1, len(arr) - 1)]
        if arr.shape != (J, 3):
            raise ValueError(f"joint_colors[{k}] must be (N, J, 3) or (J, 3) with J = {J}, got {arr.shape}")
        out.append(np.clip(arr, 0.0, 1.0))
    return out


def build_scene(
    motions: Sequence[np.ndarray],
    skeleton: Skeleton,
    frame: int,
    *,
    camera: Camera | None = None,
    view: str | float = "three_quarter",
    elevation: float | None = None,
    follow: bool = True,
    aspect: float = 4.0 / 3.0,
    colors=None,
    joint_colors=None,
    trajectory: bool = True,
    floor: bool = True,
    bone_radius: float = 0.022,
    joint_radius: float = 0.032,
) -> FrameScene:
    """Assemble one frame of one or more validated motions.

    Parameters
    ----------
    motions : sequence of ndarray (N_k, J, 3)
        Validated motions in metres (see ``_arrays.as_joints_list``); a motion shorter than
        ``frame`` holds its last pose.
    skeleton : Skeleton
    frame : int
        Frame index (0-based).
    camera : Camera, optional
        Overrides ``view``/``elevation``/``follow``.
    view, elevation, follow, aspect
        See :func:`salad_viz.camera.follow_camera` and :func:`~salad_viz.camera.fixed_camera`.
    colors : sequence, optional
        One entry per motion: ``None``, a colour, or a ``(J, 3)`` array of bone colours.
    joint_colors : array or sequence, optional
        Per-joint colours (e.g. attention), see :func:`frame_joint_colors`. When given, the bone
        parent->j takes joint j's colour too, so the whole limb shows the value.
    trajectory, floor : bool
        Draw the root paths / the checkerboard floor.
    """
    n = len(motions)
    J = skeleton.num_joints
    lengths = [len(m) for m in motions]
    poses = tuple(m[min(frame, len(m) - 1)].copy() for m in motions)
    bones = motion_bone_colors(skeleton, n, colors)
    jcols = frame_joint_colors(joint_colors, n, lengths, J, frame)
    bone_out, joint_out = [], []
    for k in range(n):
        if jcols[k] is not None:
            bone_out.append(jcols[k].copy())
            joint_out.append(jcols[k].copy())
        else:
            bone_out.append(bones[k])
            joint_out.append(bones[k] * 0.7)
    if camera is None:
        if follow:
            camera = follow_camera(motions, frame, view=view, elevation=elevation, aspect=aspect)
        else:
            camera = fixed_camera(motions, view=view, elevation=elevation, aspect=aspect)
    trajs, tcols = [], []
    for k, m in enumerate(motions):
        trajs.append(m[:, 0, :].copy() if trajectory else np.zeros((0, 3)))
        tcols.append(TRAJECTORY if n == 1 else _theme_trajectory(k, colors))
    floor_centre = None
    half = 0.0
    if floor:
        focal = np.asarray(camera.focal_point)
        dist = float(np.linalg.norm(np.subtract(camera.position, camera.focal_point)))
        if follow:
            floor_centre = (float(focal[0]), float(focal[2]))
            half = float(np.clip(dist * 2.5, 6.0, 15.0))  # reach towards the horizon
        else:
            pts = np.concatenate([m[:, 0, :] for m in motions])
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            floor_centre = (float(0.5 * (lo[0] + hi[0])), float(0.5 * (lo[2] + hi[2])))
            half = float(np.clip(0.5 * max(hi[0] - lo[0], hi[2] - lo[2]) + 1.5, 2.0, 12.0))
    return FrameScene(
        poses=poses,
        bone_colors=tuple(bone_out),
        joint_colors=tuple(joint_out),
        trajectories=tuple(trajs),
        trajectory_colors=tuple(tcols),
        camera=camera,
        floor_centre=floor_centre,
        floor_half_extent=half,
        bone_radius=float(bone_radius),
        joint_radius=float(joint_radius),
    )


def _theme_trajectory(k: int, colors) -> tuple[float, float, float]:
    import colorsys

    if colors is not None and colors[k] is not None and not (isinstance(colors[k], np.ndarray) and colors[k].ndim == 2):
        return to_rgb(colors[k])
    hue = THEME_HUES[k % len(THEME_HUES)] / 360.0
    return tuple(colorsys.hls_to_rgb(hue, 0.45, 0.7))
