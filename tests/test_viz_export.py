"""salad_viz.export / kinematics: BVH checked by an independent reader (PyPI ``bvh``) plus our own FK,
GLB read back by trimesh, NPY round trip, and the rotation solver's building blocks."""
from __future__ import annotations

import logging

import numpy as np
import pytest

from salad_core.skeleton import get_skeleton
from salad_viz._style import bone_colors, to_uint8
from salad_viz.export import euler_zyx, export_bvh, export_glb, export_npy
from salad_viz.kinematics import (
    axis_angle_matrix,
    children_of,
    forward_kinematics,
    kabsch,
    rest_pose,
    solve_rotations,
    swing_rotation,
)
from salad_viz.synthetic import synthetic_motion

SKEL = get_skeleton("humanml3d")


# ----------------------------------------------------------------------------- an independent BVH FK
def _axis_rot(axis: str, deg: float) -> np.ndarray:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    if axis == "X":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "Y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _bvh_positions(path, frames) -> tuple[list[str], dict[str, np.ndarray]]:
    """Parse with the PyPI ``bvh`` package and run BVH forward kinematics written here."""
    import bvh

    with open(path) as fh:
        mocap = bvh.Bvh(fh.read())
    names = mocap.get_joints_names()
    out = {n: [] for n in names}
    for t in frames:
        world, pos = {}, {}
        for name in names:
            channels = mocap.joint_channels(name)
            values = mocap.frame_joint_channels(t, name, channels)
            rot = np.eye(3)
            trans = np.zeros(3)
            for ch, v in zip(channels, values):
                if ch.endswith("rotation"):
                    rot = rot @ _axis_rot(ch[0], v)  # channels compose in the order listed
                else:
                    trans["XYZ".index(ch[0])] = v
            offset = np.asarray(mocap.joint_offset(name))
            parent = mocap.joint_parent(name)
            if parent is None:
                pos[name] = offset + trans
                world[name] = rot
            else:
                pos[name] = pos[parent.name] + world[parent.name] @ offset
                world[name] = world[parent.name] @ rot
        for name in names:
            out[name].append(pos[name])
    return names, {n: np.asarray(v) for n, v in out.items()}


def _check_bvh_reproduces(path, joints, frames, tol=0.01):
    names, pos = _bvh_positions(path, frames)
    assert sorted(names) == sorted(SKEL.joint_names)
    err = max(np.linalg.norm(pos[n] - joints[frames, SKEL.joint_names.index(n)], axis=-1).max() for n in names)
    assert err < tol, f"BVH FK misses the joints by {err * 100:.2f} cm"
    return err


def test_bvh_of_real_humanml3d_motion_reproduces_joints(tmp_path, sample_joints):
    import bvh

    path = export_bvh(sample_joints, SKEL, tmp_path / "012314.bvh")
    with open(path) as fh:
        mocap = bvh.Bvh(fh.read())
    assert mocap.nframes == len(sample_joints)
    assert mocap.frame_time == pytest.approx(0.05)
    names = mocap.get_joints_names()
    assert names[0] == "pelvis"
    assert mocap.joint_channels("pelvis") == ["Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation",
                                              "Xrotation"]
    assert mocap.joint_channels("left_knee") == ["Zrotation", "Yrotation", "Xrotation"]
    # hierarchy = the skeleton's parents
    for j, name in enumerate(SKEL.joint_names[1:], start=1):
        assert mocap.joint_parent(name).name == SKEL.joint_names[SKEL.parents[j]]
    # every leaf has an End Site (so importers draw the feet, head and hands)
    leaves = [j for j, ch in enumerate(children_of(SKEL)) if not ch]
    assert len(mocap.search("End", "Site")) == len(leaves) == 5
    err = _check_bvh_reproduces(path, sample_joints, list(range(0, len(sample_joints), 9)))
    assert err < 1e-4  # rigid HumanML3D data is reproduced to float precision


def test_bvh_with_target_lengths_and_a_turning_synthetic_walk(tmp_path, sample_joints):
    path = export_bvh(sample_joints, SKEL, tmp_path / "target.bvh", lengths="target")
    _check_bvh_reproduces(path, sample_joints, [0, 60, 169])
    walk = synthetic_motion(SKEL, 30, turn_degrees=150)
    path = export_bvh(walk, SKEL, tmp_path / "walk.bvh", fps=30)
    import bvh

    with open(path) as fh:
        assert bvh.Bvh(fh.read()).frame_time == pytest.approx(1 / 30, abs=1e-6)
    _check_bvh_reproduces(path, walk, list(range(0, 30, 3)))


def test_bvh_rest_pose_is_a_t_pose_in_metres(tmp_path, sample_joints):
    import bvh

    path = export_bvh(sample_joints, SKEL, tmp_path / "rest.bvh")
    with open(path) as fh:
        mocap = bvh.Bvh(fh.read())
    elbow = np.asarray(mocap.joint_offset("left_elbow"))
    knee = np.asarray(mocap.joint_offset("left_knee"))
    head = np.asarray(mocap.joint_offset("head"))
    assert elbow[0] > 0.25 and abs(elbow[1]) < 1e-6  # arm out sideways, ~26 cm upper arm
    assert knee[1] < -0.35  # thigh down
    assert head[1] > 0.09  # head up
    # bone lengths are the motion's (metres)
    j = SKEL.joint_names.index("left_elbow")
    assert np.linalg.norm(elbow) == pytest.approx(SKEL.bone_lengths[j], abs=1e-4)


def test_bvh_warns_when_bones_stretch(tmp_path, caplog):
    walk = synthetic_motion(SKEL, 10)
    wrist = SKEL.joint_names.index("left_wrist")
    elbow = SKEL.parents[wrist]
    stretched = walk.copy()
    stretched[5:, wrist] += 0.1 * (walk[5:, wrist] - walk[5:, elbow]) / np.linalg.norm(
        walk[5:, wrist] - walk[5:, elbow], axis=-1, keepdims=True)
    with caplog.at_level(logging.WARNING, logger="salad_viz.export"):
        export_bvh(stretched, SKEL, tmp_path / "s.bvh")
    assert any("reproduces the joints only to" in r.message for r in caplog.records)


def test_euler_angles_are_continuous():
    t = np.linspace(0, 4 * np.pi, 80)
    rot = axis_angle_matrix(np.array([0.0, 1.0, 0.0]), t)[:, None]  # two full turns about Y
    rot = np.concatenate([rot, axis_angle_matrix(np.array([0.3, 0.9, 0.3]) / np.linalg.norm([0.3, 0.9, 0.3]),
                                                 t)[:, None]], axis=1)
    ang = euler_zyx(rot)
    assert np.abs(np.diff(ang, axis=0)).max() < 30.0
    # and still the same rotations
    from scipy.spatial.transform import Rotation

    back = Rotation.from_euler("ZYX", ang.reshape(-1, 3), degrees=True).as_matrix().reshape(rot.shape)
    np.testing.assert_allclose(back, rot, atol=1e-9)


def test_rotation_helpers():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(50, 3))
    b = rng.normal(size=(50, 3))
    a /= np.linalg.norm(a, axis=-1, keepdims=True)
    b /= np.linalg.norm(b, axis=-1, keepdims=True)
    r = swing_rotation(a, b)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", r, a), b, atol=1e-9)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-9)
    flip = swing_rotation(np.array([0.0, 1.0, 0.0]), np.array([0.0, -1.0, 0.0]))
    np.testing.assert_allclose(flip @ np.array([0.0, 1.0, 0.0]), [0.0, -1.0, 0.0], atol=1e-9)
    true = axis_angle_matrix(np.array([0.0, 0.6, 0.8]), np.array([0.7, -2.0]))
    rest = rng.normal(size=(3, 3))
    obs = np.einsum("nij,kj->nki", true, rest)
    np.testing.assert_allclose(kabsch(rest, obs), true, atol=1e-9)


def test_rest_pose_and_synthetic_motion_geometry():
    pose = rest_pose(SKEL)
    assert pose[:, 1].min() == pytest.approx(0.0)
    lengths = np.linalg.norm(pose[1:] - pose[list(SKEL.parents[1:])], axis=-1)
    np.testing.assert_allclose(lengths, SKEL.bone_lengths[1:])
    walk = synthetic_motion(SKEL, 20)
    np.testing.assert_allclose(walk[..., 1].min(axis=1), 0.0, atol=1e-12)  # on the floor every frame
    seg = np.linalg.norm(walk[:, 1:] - walk[:, list(SKEL.parents[1:])], axis=-1)
    np.testing.assert_allclose(seg, np.broadcast_to(SKEL.bone_lengths[1:], seg.shape), atol=1e-9)
    assert walk[-1, 0, 2] - walk[0, 0, 2] == pytest.approx(1.1 * 19 / 20)  # forward along +Z
    rot = solve_rotations(walk, SKEL)
    rec = forward_kinematics(rot.offsets, rot.parents, rot.rotations, rot.root_positions)
    np.testing.assert_allclose(rec, walk, atol=1e-6)


def test_glb_round_trip(tmp_path, sample_joints):
    import trimesh

    path = export_glb(sample_joints, SKEL, tmp_path / "pose.glb", frame=30, floor=False)
    scene = trimesh.load(path)
    mesh = scene.to_geometry() if hasattr(scene, "to_geometry") else scene.dump(concatenate=True)
    lo, hi = mesh.bounds
    pose = sample_joints[30]
    assert np.all(lo <= pose.min(axis=0)) and np.all(hi >= pose.max(axis=0))
    assert np.all(lo >= pose.min(axis=0) - 0.05) and np.all(hi <= pose.max(axis=0) + 0.05)
    colors = {tuple(int(v) for v in c[:3]) for c in np.asarray(mesh.visual.face_colors)}
    for c in to_uint8(bone_colors(SKEL))[1:]:
        assert tuple(int(v) for v in c) in colors
    with_floor = trimesh.load(export_glb([sample_joints, sample_joints], SKEL, tmp_path / "two.glb", frame=0))
    assert len(with_floor.geometry) == 3  # two motions + floor


def test_npy_round_trip_and_validation(tmp_path, sample_joints):
    path = export_npy(sample_joints, SKEL, tmp_path / "j.npy")
    back = np.load(path)
    assert back.dtype == np.float32
    np.testing.assert_array_equal(back, sample_joints.astype(np.float32))
    with pytest.raises(ValueError, match="J = 22"):
        export_npy(sample_joints[:, :21], SKEL, tmp_path / "bad.npy")
    assert not (tmp_path / "bad.npy").exists()
