"""Exports for other tools: BVH (Blender and friends), GLB (trimesh), NPY.

BVH layout: the skeleton's hierarchy (HumanML3D: pelvis root, 22 joints), a T-pose rest skeleton,
root channels ``Xposition Yposition Zposition Zrotation Yrotation Xrotation`` and three rotation
channels ``Zrotation Yrotation Xrotation`` per joint (rotation = Rz @ Ry @ Rx, degrees), an End
Site after every leaf so that importers draw the last bones (feet, head, hands), and a frame time
of 1 / fps (0.05 s for HumanML3D's 20 fps). Rotations come from :mod:`salad_viz.kinematics`.
"""
from __future__ import annotations

import logging
import os
import re
from pathlib import Path

import numpy as np

from salad_core.skeleton import Skeleton, get_skeleton

from ._arrays import as_joints, as_joints_list, atomic_output, check_frame
from .kinematics import SolvedMotion, children_of, fk_error, solve_rotations

log = logging.getLogger(__name__)

__all__ = ["export_bvh", "bvh_text", "euler_zyx", "export_glb", "export_npy"]

_FK_NOTE_M = 0.01  # log (info) when the BVH cannot reproduce the joints to 1 cm
# ... and warn beyond 5 cm. A BVH moves the hips and the spine with one rigid pelvis (likewise the chest
# and its three children); the shipped model's fitted joints (fixed bone lengths) miss that rigid
# triangle by about 2.4 cm (quickstart prompt), which is not worth a warning in every notebook, while
# stretching bones (10 cm) or the raw position features (40 cm) are.
_FK_WARN_M = 0.05


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


def export_bvh(joints, skeleton: str | Skeleton, path: str | os.PathLike, fps: float | None = None, *,
               lengths: str = "motion", scale: float = 1.0) -> Path:
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
        Rest bone lengths: the motion's median lengths (reproduces the joints exactly when bone
        lengths are constant) or the skeleton's target lengths.
    scale : float
        Length unit factor (1 = metres; Blender's importer reads 1 unit = 1 m).

    Returns
    -------
    Path
        The written file. When forward kinematics of the file misses the input by more than 1 cm
        (bones that change length, or a non-rigid pelvis/chest in generated data) this is logged:
        as information up to 5 cm, as a warning beyond.
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
    err = fk_error(solved, motion)
    if err > _FK_NOTE_M:
        log.log(logging.WARNING if err > _FK_WARN_M else logging.INFO,
                "BVH reproduces the joints only to %.1f cm (bone lengths vary or the pelvis/chest "
                "children are not rigid in this motion)", err * 100)
    text = bvh_text(solved, skel, fps=skel.fps if fps is None else float(fps), scale=scale)
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


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
