"""Triangle meshes of a posed skeleton (trimesh): capsule or cylinder bones, sphere joints, floor.

Used by the pyvista renderer and by the GLB export, so the two show the same geometry. Each
mesh carries per-face RGBA colours (``mesh.visual.face_colors``).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from salad_core.skeleton import Skeleton

from ._style import FLOOR_DARK, FLOOR_LIGHT, to_uint8

__all__ = ["BONE_SHAPES", "FLOOR_TILE", "body_mesh", "floor_tiles", "floor_mesh"]

BONE_SHAPES = ("capsule", "cylinder")
FLOOR_TILE = 0.5  # metres: side of a floor checker tile
_SECTIONS = 10  # facets around a bone: enough for small renders, cheap to rebuild every frame


@lru_cache(maxsize=512)
def _unit_bone(shape: str, length_mm: int, radius_mm: int):
    """A bone along +Z from z=0 to z=length, cached by size (bone lengths repeat every frame)."""
    import trimesh

    length = length_mm / 1000.0
    radius = radius_mm / 1000.0
    if shape == "capsule":
        mesh = trimesh.creation.capsule(height=max(length, 1e-4), radius=radius, count=[_SECTIONS, _SECTIONS])
        mesh.apply_translation((0.0, 0.0, length / 2.0))  # trimesh centres capsules on the origin
    else:
        mesh = trimesh.creation.cylinder(radius=radius, segment=[[0, 0, 0], [0, 0, max(length, 1e-4)]],
                                         sections=_SECTIONS)
    return mesh.vertices.copy(), mesh.faces.copy()


@lru_cache(maxsize=64)
def _unit_sphere(radius_mm: int):
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=1, radius=radius_mm / 1000.0)
    return mesh.vertices.copy(), mesh.faces.copy()


def _align_z(direction: np.ndarray) -> np.ndarray:
    """``(3, 3)`` rotation taking +Z onto the unit vector ``direction`` (Rodrigues)."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, direction)
    c = float(np.dot(z, direction))
    if c < -1.0 + 1e-9:  # opposite: rotate 180 degrees about X
        return np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def body_mesh(
    pose: np.ndarray,
    skeleton: Skeleton,
    bone_colors: np.ndarray,
    joint_colors: np.ndarray | None = None,
    *,
    bone_shape: str = "capsule",
    bone_radius: float = 0.022,
    joint_radius: float = 0.032,
    alpha: float = 1.0,
):
    """One pose as a single coloured triangle mesh.

    Parameters
    ----------
    pose : ndarray (J, 3)
        Joint positions in metres.
    skeleton : Skeleton
    bone_colors : ndarray (J, 3)
        RGB in [0, 1] of the bone parent->j (row j).
    joint_colors : ndarray (J, 3), optional
        RGB of each joint sphere; defaults to a darker shade of its bone colour.
    bone_shape : {"capsule", "cylinder"}
    bone_radius, joint_radius : float
        Radii in metres.
    alpha : float
        Opacity written into the face colours.

    Returns
    -------
    trimesh.Trimesh
        With per-face RGBA colours.
    """
    import trimesh

    if bone_shape not in BONE_SHAPES:
        raise ValueError(f"bone_shape must be one of {BONE_SHAPES}, got {bone_shape!r}")
    if joint_colors is None:
        joint_colors = bone_colors * 0.7
    verts, faces, cols = [], [], []
    n = 0
    r_mm = max(1, int(round(bone_radius * 1000)))
    for child, parent in enumerate(skeleton.parents):
        if parent < 0:
            continue
        a, b = pose[parent], pose[child]
        vec = b - a
        length = float(np.linalg.norm(vec))
        if length < 1e-6:
            continue
        v, f = _unit_bone(bone_shape, max(1, int(round(length * 1000))), r_mm)
        # the cached bone has the rounded length; rescale along the axis to the exact length
        v = v * np.array([1.0, 1.0, length / (max(1, int(round(length * 1000))) / 1000.0)])
        verts.append(v @ _align_z(vec / length).T + a)
        faces.append(f + n)
        cols.append(np.repeat(bone_colors[child][None], len(f), axis=0))
        n += len(v)
    sv, sf = _unit_sphere(max(1, int(round(joint_radius * 1000))))
    for j in range(skeleton.num_joints):
        verts.append(sv + pose[j])
        faces.append(sf + n)
        cols.append(np.repeat(joint_colors[j][None], len(sf), axis=0))
        n += len(sv)
    rgb = to_uint8(np.concatenate(cols))
    rgba = np.concatenate([rgb, np.full((len(rgb), 1), int(round(alpha * 255)), np.uint8)], axis=1)
    return trimesh.Trimesh(vertices=np.concatenate(verts), faces=np.concatenate(faces),
                           face_colors=rgba, process=False)


def floor_tiles(centre_xz, half_extent: float, tile: float = FLOOR_TILE) -> tuple[np.ndarray, np.ndarray]:
    """Checkerboard tiles on y = 0 around ``centre_xz``.

    Returns
    -------
    corners : ndarray (T, 4, 3)
        Tile corners (counter-clockwise seen from above), snapped to a world grid of ``tile``
        metres so that the pattern stays fixed in the world while the camera moves.
    dark : ndarray (T,) bool
        Which tiles take the darker colour.
    """
    cx, cz = float(centre_xz[0]), float(centre_xz[1])
    i0, i1 = int(np.floor((cx - half_extent) / tile)), int(np.ceil((cx + half_extent) / tile))
    k0, k1 = int(np.floor((cz - half_extent) / tile)), int(np.ceil((cz + half_extent) / tile))
    ii, kk = np.meshgrid(np.arange(i0, i1), np.arange(k0, k1), indexing="ij")
    ii, kk = ii.ravel(), kk.ravel()
    x0, z0 = ii * tile, kk * tile
    corners = np.stack([
        np.stack([x0, np.zeros_like(x0), z0], -1),
        np.stack([x0, np.zeros_like(x0), z0 + tile], -1),
        np.stack([x0 + tile, np.zeros_like(x0), z0 + tile], -1),
        np.stack([x0 + tile, np.zeros_like(x0), z0], -1),
    ], axis=1).astype(np.float64)
    dark = ((ii + kk) % 2).astype(bool)
    return corners, dark


def floor_mesh(centre_xz, half_extent: float, tile: float = FLOOR_TILE):
    """The checkerboard floor as a trimesh (two triangles per tile, per-face colours)."""
    import trimesh

    corners, dark = floor_tiles(centre_xz, half_extent, tile)
    t = len(corners)
    verts = corners.reshape(-1, 3)
    base = np.arange(t)[:, None] * 4
    # counter-clockwise seen from +Y so that the normals point up
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
    col = np.where(dark[:, None], np.asarray(FLOOR_DARK), np.asarray(FLOOR_LIGHT))
    rgb = to_uint8(np.concatenate([col, col]))
    rgba = np.concatenate([rgb, np.full((len(rgb), 1), 255, np.uint8)], axis=1)
    return trimesh.Trimesh(vertices=verts, faces=faces, face_colors=rgba, process=False)
