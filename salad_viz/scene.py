"""What to draw for one frame, independent of the backend that draws it.

:func:`build_scene` turns motions, colours and view options into a :class:`FrameScene` (poses,
colours, trajectories, floor patch, supports, camera). The pyvista renderer and the 2D rasteriser
both draw a ``FrameScene``, which is why the two backends show the same view.

Supports: a motion that leaves the floor level (climbing stairs, stepping onto a box) plants its
feet above the floor; drawn over a flat floor it walks on air. :func:`support_boxes` finds the
plants (a foot still for several frames, its sole more than 5 cm up, lower than the rest of the
body) and puts a step under each, from the floor up to the sole. They are drawn by default only
when a motion has such plants (and also touches the floor, so a motion that floats all along is
not given a platform that hides it).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from salad_core.skeleton import Skeleton

from ._style import TRAJECTORY, THEME_HUES, motion_bone_colors, to_rgb
from .camera import Camera, fixed_camera, follow_camera

__all__ = ["FrameScene", "build_scene", "frame_joint_colors", "support_boxes", "support_faces", "STEP_DEPTH",
           "STEP_WIDTH", "STEP_TOP", "STEP_SIDE"]


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
    supports: tuple[np.ndarray, ...] = ()  # per step (4, 3) corners of its top face; it reaches down to y = 0


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


#: Size (m) of a drawn step: along the foot and across it.
STEP_DEPTH, STEP_WIDTH = 0.34, 0.56
#: Colours of a step's top and of its sides.
STEP_TOP, STEP_SIDE = (0.80, 0.71, 0.58), (0.60, 0.52, 0.42)
#: Heights (m) of a foot's joints above the surface it stands on: the sole is this far below them
#: (HumanML3D's flat foot: ankle 5.8 cm, toes 1.2 cm; a heel-up foot gives a lower ankle estimate).
_ANKLE_REST, _TOE_REST = 0.058, 0.012


def support_boxes(motion: np.ndarray, skeleton: Skeleton, *, fps: float | None = None, min_height: float = 0.05,
                  max_speed: float = 0.3, min_frames: int = 4, floor_level: float = 0.03) -> list[np.ndarray]:
    """Steps under the feet a motion plants above the floor.

    A foot is planted where its ankle and toe joints move slower than ``max_speed`` (m/s) for at
    least ``min_frames`` frames; its sole is the lower of (toe height - 1.2 cm) and (ankle height -
    5.8 cm). A plant whose sole is more than ``min_height`` up gets a step if the foot carries the
    body: it is below every joint but the feet (a lying body's raised feet are no plant), the pelvis
    is more than 0.6 m above it, and the other foot does not stand lower through most of it (a knee
    held up, a balance on one leg). The step is a box from the floor to the sole, :data:`STEP_DEPTH`
    along the foot and :data:`STEP_WIDTH` across, centred under the foot. Steps at the same height within 15 cm of one already found are not repeated. A motion
    whose soles never come within ``floor_level`` of the floor gets none.

    Parameters
    ----------
    motion : ndarray (N, J, 3)
        Joints in metres, +Y up, floor y = 0.
    skeleton : Skeleton
        Gives the foot joints (``fid_l``, ``fid_r``: ankle, toe) and the frame rate.

    Returns
    -------
    list of ndarray (4, 3): the corners of each step's top face (counter-clockwise seen from above).
    """
    m = np.asarray(motion, dtype=np.float64)
    if m.ndim != 3 or len(m) < min_frames:
        return []
    fps = float(fps or skeleton.fps or 20.0)
    feet = [tuple(skeleton.fid_l), tuple(skeleton.fid_r)]
    foot_joints = sorted({j for f in feet for j in f})
    others = [j for j in range(m.shape[1]) if j not in foot_joints]
    lowest_other = m[:, others, 1].min(axis=1)
    soles, planted = [], []
    for ankle, toe in feet:
        sole = np.minimum(m[:, toe, 1] - _TOE_REST, m[:, ankle, 1] - _ANKLE_REST)
        speed = np.zeros(len(m))
        v = np.linalg.norm(np.diff(m[:, [ankle, toe]], axis=0), axis=-1).max(axis=1) * fps
        speed[1:] = v
        speed[0] = v[0]
        soles.append(sole)
        planted.append(speed < max_speed)
    if min(float(s.min()) for s in soles) > floor_level:
        return []                                           # never on the floor: nothing to stand it on
    found: list[tuple[np.ndarray, float]] = []
    quads: list[np.ndarray] = []
    pelvis = m[:, 0, 1]
    for k, ((ankle, toe), sole, still) in enumerate(zip(feet, soles, planted)):
        other_sole, other_still = soles[1 - k], planted[1 - k]
        edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(np.int8), [0]])))
        for a, b in zip(edges[::2], edges[1::2]):
            if b - a < min_frames:
                continue
            h = float(np.median(sole[a:b]))
            if h <= min_height:
                continue
            # the foot carries the body: below every joint but the feet, the leg under the pelvis, and
            # the other foot not standing lower all the while (a knee held up, a balance on one leg)
            below = np.median(m[a:b, [ankle, toe], 1].min(axis=1) - lowest_other[a:b]) < 0.0
            under = np.median(pelvis[a:b] - sole[a:b]) > 0.6
            held_up = np.mean(other_still[a:b] & (other_sole[a:b] < sole[a:b] - min_height)) > 0.8
            if not (below and under) or held_up:
                continue
            centre = 0.5 * (m[a:b, ankle] + m[a:b, toe]).mean(axis=0)
            if any(abs(h - h2) < 0.03 and np.hypot(*(centre - c2)[[0, 2]]) < 0.15 for c2, h2 in found):
                continue
            found.append((centre, h))
            along = (m[a:b, toe] - m[a:b, ankle]).mean(axis=0) * np.array([1.0, 0.0, 1.0])
            along = along / np.linalg.norm(along) if np.linalg.norm(along) > 1e-6 else np.array([0.0, 0.0, 1.0])
            across = np.array([along[2], 0.0, -along[0]])
            c = np.array([centre[0], h, centre[2]])
            da, dc = 0.5 * STEP_DEPTH * along, 0.5 * STEP_WIDTH * across
            quad = np.stack([c - da - dc, c + da - dc, c + da + dc, c - da + dc])
            quads.append(quad if _ccw_from_above(quad) else quad[::-1].copy())
    return quads


def support_faces(quad: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The five faces of a step (its top and four sides down to y = 0) as ``(corners (4, 3), outward
    normal)``, top first; the backends draw them (the bottom lies on the floor)."""
    top = np.asarray(quad, dtype=np.float64)
    bottom = top.copy()
    bottom[:, 1] = 0.0
    centre = 0.5 * (top.mean(axis=0) + bottom.mean(axis=0))
    faces = [(top, np.array([0.0, 1.0, 0.0]))]
    for i in range(4):
        j = (i + 1) % 4
        corners = np.stack([top[i], top[j], bottom[j], bottom[i]])
        nrm = np.cross(top[j] - top[i], bottom[i] - top[i])
        nrm /= np.linalg.norm(nrm) + 1e-12
        if nrm @ (corners.mean(axis=0) - centre) < 0:
            nrm = -nrm
        faces.append((corners, nrm))
    return faces


def _ccw_from_above(quad: np.ndarray) -> bool:
    x, z = quad[:, 0], quad[:, 2]
    # counter-clockwise seen from +Y (looking down): the signed area in (z, x) is positive
    return float(np.sum(z * np.roll(x, -1) - np.roll(z, -1) * x)) > 0.0


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
    supports: bool | None = None,
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
    supports : bool, optional
        Draw steps under feet planted above the floor (:func:`support_boxes`); default: with the
        floor, wherever a motion has such plants.
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
    steps: list[np.ndarray] = []
    if supports or (supports is None and floor):
        for m in motions:
            steps += support_boxes(m, skeleton)
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
        supports=tuple(steps),
    )


def _theme_trajectory(k: int, colors) -> tuple[float, float, float]:
    import colorsys

    if colors is not None and colors[k] is not None and not (isinstance(colors[k], np.ndarray) and colors[k].ndim == 2):
        return to_rgb(colors[k])
    hue = THEME_HUES[k % len(THEME_HUES)] / 360.0
    return tuple(colorsys.hls_to_rgb(hue, 0.45, 0.7))
