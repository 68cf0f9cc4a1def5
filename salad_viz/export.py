"""Exports for other tools: BVH (Blender and friends), GLB (trimesh), NPY.

BVH layout: the skeleton's hierarchy (HumanML3D: pelvis root, 22 joints), a T-pose rest skeleton,
root channels ``Xposition Yposition Zposition Zrotation Yrotation Xrotation`` and three rotation
channels ``Zrotation Yrotation Xrotation`` per joint (rotation = Rz @ Ry @ Rx, degrees), an End
Site after every leaf so that importers draw the last bones (feet, head, hands), and a frame time
of 1 / fps (0.05 s for HumanML3D's 20 fps). Rotations come from :mod:`salad_viz.kinematics`.

The file holds the motion of the joints it was written from: its OFFSETs are the motion's own
bone lengths and rigid branch geometry (pelvis -> hips and spine, chest -> neck and collars), so
for joints with constant bone lengths and rigid branches (what the pipeline's ``"fit"`` recovery
gives) any BVH reader gets the joints back to float precision (< 0.01 mm). For other joints the
file is the closest rigid skeleton; :func:`export_bvh` measures what a reader gets back and returns
it with the path (:class:`BvhFile`).
"""
from __future__ import annotations

import logging
import os
import re
from pathlib import Path

import numpy as np

from salad_core.skeleton import Skeleton, get_skeleton

from ._arrays import as_joints, as_joints_list, atomic_output, check_frame
from .kinematics import SolvedMotion, children_of, solve_rotations

log = logging.getLogger(__name__)

__all__ = ["export_bvh", "bvh_text", "bvh_errors", "BvhFile", "euler_zyx", "export_glb", "export_npy"]

#: Warn when a reader of the BVH gets joints back more than this far (metres) from the input: bones
#: that stretch (10 cm) or the raw position features (40 cm) are another motion than the file's rigid
#: skeleton can hold. Below it (a non-rigid pelvis or chest: about 2 cm before the rigid fit) the
#: figure is only returned (:attr:`BvhFile.max_error`) and logged at debug level.
_FK_WARN_M = 0.05
#: What counts as exact (metres): the 6-decimal text of the file, far below this.
EXACT_M = 1e-4


class BvhFile(type(Path())):
    """The path of a BVH file written by :func:`export_bvh`, with how closely it holds the joints.

    A :class:`pathlib.Path` in every other respect. ``max_error`` and ``mean_error`` (metres) are the
    largest and mean distances between the joints given to :func:`export_bvh` and the joints a BVH
    reader gets back from the written file (its text read by :func:`salad_core.bvh.parse_bvh`);
    ``None`` on paths derived from it.
    """

    max_error: float | None = None
    mean_error: float | None = None

    @property
    def exact(self) -> bool:
        """Whether a reader gets the joints back to within :data:`EXACT_M` (0.1 mm)."""
        return self.max_error is not None and self.max_error <= EXACT_M


def euler_zyx(rotations) -> np.ndarray:
    """Intrinsic Z-Y-X Euler angles in degrees, continuous over time.

    Parameters
    ----------
    rotations : array (N, J, 3, 3)
        Rotation matrices R = Rz(z) @ Ry(y) @ Rx(x).

    Returns
    -------
    ndarray (N, J, 3)
        ``(z, y, x)`` per frame and joint. Of the two Euler solutions of each rotation the one
        closest to the previous frame is kept, and angles are unwrapped (no 360-degree jumps),
        so that importers interpolate smoothly.
    """
    from scipy.spatial.transform import Rotation

    rot = np.asarray(rotations, dtype=np.float64)
    n, j = rot.shape[:2]
    import warnings

    with warnings.catch_warnings():  # gimbal-lock warnings: the solution is still valid
        warnings.simplefilter("ignore", UserWarning)
        ang = Rotation.from_matrix(rot.reshape(-1, 3, 3)).as_euler("ZYX", degrees=True).reshape(n, j, 3)
    alt = np.stack([ang[..., 0] + 180.0, 180.0 - ang[..., 1], ang[..., 2] + 180.0], axis=-1)
    out = np.empty_like(ang)
    out[0] = ang[0]
    for t in range(1, n):
        prev = out[t - 1]
        cands = []
        for c in (ang[t], alt[t]):
            cands.append(c + 360.0 * np.round((prev - c) / 360.0))
        d0 = np.abs(cands[0] - prev).sum(-1)
        d1 = np.abs(cands[1] - prev).sum(-1)
        out[t] = np.where((d1 < d0)[:, None], cands[1], cands[0])
    return out


def _names(skel: Skeleton) -> list[str]:
    names = [re.sub(r"\W+", "_", n).strip("_") or f"joint{i}" for i, n in enumerate(skel.joint_names)]
    seen: dict[str, int] = {}
    for i, n in enumerate(names):
        if n in seen:
            names[i] = f"{n}_{i}"
        seen[n] = i
    return names


def bvh_text(solved: SolvedMotion, skeleton: str | Skeleton = "humanml3d", *, fps: float = 20.0,
             scale: float = 1.0) -> str:
    """The BVH file contents of a :class:`~salad_viz.kinematics.SolvedMotion`.

    ``scale`` multiplies every length (1 = metres, 100 = centimetres).
    """
    skel = get_skeleton(skeleton)
    if fps <= 0:
        raise ValueError(f"fps must be positive, got {fps}")
    names = _names(skel)
    kids = children_of(skel)
    order: list[int] = []
    lines = ["HIERARCHY"]

    def fmt(v) -> str:
        return " ".join(f"{x * scale:.6f}" for x in v)

    def write(j: int, depth: int) -> None:
        ind = "\t" * depth
        order.append(j)
        if skel.parents[j] < 0:
            lines.append(f"{ind}ROOT {names[j]}")
            lines.append(f"{ind}{{")
            lines.append(f"{ind}\tOFFSET {fmt((0.0, 0.0, 0.0))}")
            lines.append(f"{ind}\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation")
        else:
            lines.append(f"{ind}JOINT {names[j]}")
            lines.append(f"{ind}{{")
            lines.append(f"{ind}\tOFFSET {fmt(solved.offsets[j])}")
            lines.append(f"{ind}\tCHANNELS 3 Zrotation Yrotation Xrotation")
        for c in kids[j]:
            write(c, depth + 1)
        if not kids[j]:
            lines.append(f"{ind}\tEnd Site")
            lines.append(f"{ind}\t{{")
            lines.append(f"{ind}\t\tOFFSET {fmt(solved.end_sites[j])}")
            lines.append(f"{ind}\t}}")
        lines.append(f"{ind}}}")

    roots = [j for j, p in enumerate(skel.parents) if p < 0]
    for r in roots:
        write(r, 0)
    euler = euler_zyx(solved.rotations)  # (N, J, 3) as z, y, x
    n = euler.shape[0]
    lines.append("MOTION")
    lines.append(f"Frames: {n}")
    lines.append(f"Frame Time: {1.0 / fps:.6f}")
    root_pos = solved.root_positions * scale
    for t in range(n):
        vals = list(root_pos[t])
        for j in order:
            vals.extend(euler[t, j])
        lines.append(" ".join(f"{v:.6f}" for v in vals))
    return "\n".join(lines) + "\n"


def bvh_errors(text: str, joints, skeleton: str | Skeleton, *, scale: float = 1.0) -> np.ndarray:
    """Distances ``(N, J)`` in metres between ``joints`` and what a BVH reader gets from ``text``.

    The text is parsed and its forward kinematics run by :mod:`salad_core.bvh` (joints matched by
    the names :func:`bvh_text` writes); ``scale`` is the length unit the text was written in.
    """
    from salad_core.bvh.reader import parse_bvh

    skel = get_skeleton(skeleton)
    motion = parse_bvh(text)
    pos = motion.world_positions()[:, : len(motion.joints)] / scale
    index = {n: i for i, n in enumerate(motion.joint_names)}
    order = [index[n] for n in _names(skel)]
    return np.linalg.norm(pos[:, order] - np.asarray(joints, dtype=np.float64), axis=-1)


def export_bvh(joints, skeleton: str | Skeleton, path: str | os.PathLike, fps: float | None = None, *,
               lengths: str = "motion", scale: float = 1.0) -> BvhFile:
    """Write a motion as BVH (rotations solved from joint positions).

    Parameters
    ----------
    joints : array (N, J, 3)
        Joint positions in metres, +Y up.
    skeleton : str or Skeleton
        Gives the hierarchy (HumanML3D: 22 joints rooted at the pelvis).
    path : str or PathLike
        Output ``.bvh`` file (written atomically).
    fps : float, optional
        Frame rate; default the skeleton's (20 for HumanML3D, frame time 0.05 s).
    lengths : {"motion", "target"}
        Rest bone lengths: the motion's own (its median bone lengths and its branches' rigid
        geometry: reproduces the joints exactly when bone lengths are constant and the branches
        rigid) or the skeleton's target lengths.
    scale : float
        Length unit factor (1 = metres; Blender's importer reads 1 unit = 1 m).

    Returns
    -------
    BvhFile
        The written file's path, with ``max_error`` / ``mean_error``: how far (metres) the joints
        a BVH reader gets back from the file are from ``joints``. 0 to float precision for joints
        with constant bone lengths and rigid branches (the pipeline's ``"fit"`` recovery); for
        other joints the file holds the closest rigid skeleton, and the figure says how close
        (logged as a warning only beyond 5 cm: bones that stretch, raw position features).
    """
    skel = get_skeleton(skeleton)
    motion = as_joints(joints, skel)
    if fps is not None and (isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating))
                            or not np.isfinite(fps) or fps <= 0):
        raise ValueError(f"fps must be a positive finite number of frames per second, got {fps!r}")
    if isinstance(scale, bool) or not isinstance(scale, (int, float, np.integer, np.floating)) or \
            not np.isfinite(scale) or scale <= 0:
        raise ValueError(f"scale must be a positive finite number (1 = metres), got {scale!r}")
    _check_bones(motion, skel)
    solved = solve_rotations(motion, skel, lengths=lengths)
    text = bvh_text(solved, skel, fps=skel.fps if fps is None else float(fps), scale=scale)
    err = bvh_errors(text, motion, skel, scale=float(scale))
    max_err, mean_err = float(err.max()), float(err.mean())
    if max_err > _FK_WARN_M:
        log.warning("the BVH holds these joints only to %.1f cm (mean %.1f cm): its skeleton is rigid and "
                    "these joints' bones change length (raw position features? recover joints with "
                    "salad_core.recovery.recover_joints(features, 'fit'))", max_err * 100, mean_err * 100)
    elif max_err > EXACT_M:
        log.debug("BVH %s holds the joints to %.2f cm max, %.2f cm mean (non-rigid branches or bones)",
                  path, max_err * 100, mean_err * 100)
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    out = BvhFile(path)
    out.max_error, out.mean_error = max_err, mean_err
    return out


#: Bones shorter than this (metres, median over the motion) have no direction to solve a rotation from.
_MIN_BONE_M = 1e-6


def _check_bones(motion: np.ndarray, skel: Skeleton) -> None:
    """Refuse motions with zero-length bones (e.g. all-zero joints), whose rotations are undefined."""
    names = _names(skel)
    short = []
    for j, p in enumerate(skel.parents):
        if p >= 0 and float(np.median(np.linalg.norm(motion[:, j] - motion[:, p], axis=-1))) < _MIN_BONE_M:
            short.append(f"{names[p]}->{names[j]}")
    if short:
        listed = ", ".join(short[:4]) + (f" and {len(short) - 4} more" if len(short) > 4 else "")
        raise ValueError(f"joints: {len(short)} bone(s) have zero length ({listed}); a BVH needs a skeleton pose "
                         "(are these joints all zero or collapsed onto one point?)")


def export_glb(joints, skeleton: str | Skeleton, path: str | os.PathLike, frame: int = 0, *, colors=None,
               joint_colors=None, floor: bool = True, bone_shape: str = "capsule",
               bone_radius: float = 0.022, joint_radius: float = 0.032) -> Path:
    """Write one frame as a GLB scene: capsule bones and sphere joints coloured by chain, a floor.

    Parameters
    ----------
    joints : array (N, J, 3) or list of arrays
        One motion, or several (each in its own colour theme, e.g. source and edited).
    skeleton : str or Skeleton
    path : str or PathLike
        Output ``.glb`` file (written atomically).
    frame : int
        Frame to export.
    colors, joint_colors
        As in :func:`salad_viz.render.render_skeleton`.
    floor : bool
        Add the checkerboard floor under the motion.
    bone_shape, bone_radius, joint_radius
        Bone geometry (metres).

    Returns
    -------
    Path
    """
    import trimesh

    from .meshes import body_mesh, floor_mesh
    from .scene import build_scene

    skel = get_skeleton(skeleton)
    motions = as_joints_list(joints, skel)
    frame = check_frame(frame, max(len(m) for m in motions))
    scene = build_scene(motions, skel, frame, follow=False, colors=colors, joint_colors=joint_colors,
                        trajectory=False, floor=floor, bone_radius=bone_radius, joint_radius=joint_radius)
    out = trimesh.Scene()
    for k, (pose, bcol, jcol) in enumerate(zip(scene.poses, scene.bone_colors, scene.joint_colors)):
        out.add_geometry(body_mesh(pose, skel, bcol, jcol, bone_shape=bone_shape, bone_radius=bone_radius,
                                   joint_radius=joint_radius), node_name=f"motion{k}", geom_name=f"motion{k}")
    if floor:
        centre = np.mean([p[0] for p in scene.poses], axis=0)
        out.add_geometry(floor_mesh((centre[0], centre[2]), 1.5), node_name="floor", geom_name="floor")
    with atomic_output(path) as tmp:
        tmp.write_bytes(out.export(file_type="glb"))
    return Path(path)


def export_npy(joints, skeleton: str | Skeleton | None, path: str | os.PathLike) -> Path:
    """Write joints ``(N, J, 3)`` as float32 ``.npy`` (the HumanML3D ``new_joints`` format), atomically.

    ``skeleton`` checks the joint count (``None`` skips the check).
    """
    if skeleton is not None:
        arr = as_joints(joints, get_skeleton(skeleton))
    else:
        from ._arrays import to_numpy

        arr = to_numpy(joints, "joints")
        if arr.ndim != 3 or arr.shape[-1] != 3:
            raise ValueError(f"joints must have shape (N, J, 3), got {arr.shape}")
    with atomic_output(path) as tmp:
        with open(tmp, "wb") as fh:
            np.save(fh, arr.astype(np.float32))
    return Path(path)
