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


# ----------------------------------------------------------------------------- joints the fit gives
def rigid_branch_motion(n: int = 60, seed: int = 0) -> np.ndarray:
    """Joints ``(n, 22, 3)`` with the properties of the pipeline's ``"fit"`` recovery, made here by forward
    kinematics (written here, independently of salad_viz) of random smooth rotations on a skeleton with SMPL's
    rest offsets: constant bone lengths, and the children of the pelvis (hips, spine1) and of spine3 (neck,
    collars) rigid per frame (at SMPL's angles, not the T-pose's). The root turns a full circle."""
    from scipy.spatial.transform import Rotation

    from salad_core.data.procedural.kinematics import body_model

    offsets = np.asarray(body_model("humanml3d").rest_offsets, dtype=np.float64)
    rng = np.random.default_rng(seed)
    j = SKEL.num_joints
    t = np.arange(n) / 20.0
    amp, freq, phase = rng.uniform(0.2, 1.0, (j, 3)), rng.uniform(0.3, 1.5, (j, 3)), rng.uniform(0, 2 * np.pi, (j, 3))
    rotvec = amp * np.sin(2 * np.pi * freq * t[:, None, None] + phase)                # (n, J, 3)
    rotvec[:, 0] = 0.0
    rotvec[:, 0, 1] = np.linspace(0.0, 2 * np.pi, n, endpoint=False)                   # the root turns around
    rot = Rotation.from_rotvec(rotvec.reshape(-1, 3)).as_matrix().reshape(n, j, 3, 3)
    world = np.empty_like(rot)
    pos = np.empty((n, j, 3))
    for k, p in enumerate(SKEL.parents):
        if p < 0:
            world[:, k] = rot[:, k]
            pos[:, k] = np.stack([0.8 * t, 0.95 + 0.05 * np.sin(3 * t), 0.3 * t], axis=1)
        else:
            world[:, k] = world[:, p] @ rot[:, k]
            pos[:, k] = pos[:, p] + world[:, p] @ offsets[k]
    return pos


def _own_reader_error(path, joints) -> np.ndarray:
    """Distances ``(N, J)`` between ``joints`` and salad_core.bvh's reading of the file."""
    from salad_core.bvh import read_bvh

    motion = read_bvh(path)
    pos = motion.world_positions()[:, : len(motion.joints)]
    order = [motion.joint_names.index(n) for n in SKEL.joint_names]
    return np.linalg.norm(pos[:, order] - joints, axis=-1)


def test_bvh_of_joints_with_rigid_branches_is_exact(tmp_path, caplog):
    """The fit's joints (constant bones, rigid pelvis and chest): any reader gets them back to float precision,
    the returned figures say so, and nothing is logged."""
    joints = rigid_branch_motion()
    ref = joints - joints[:, :1]
    angle = np.degrees(np.arccos(np.clip((ref[:, 1] * ref[:, 3]).sum(-1) / np.linalg.norm(ref[:, 1], axis=-1)
                                         / np.linalg.norm(ref[:, 3], axis=-1), -1, 1)))
    assert np.ptp(angle) < 1e-9 and abs(angle[0] - 90.0) > 5        # rigid, and not at the T-pose's angle
    with caplog.at_level(logging.DEBUG, logger="salad_viz"):
        path = export_bvh(joints, SKEL, tmp_path / "rigid.bvh")
    assert not caplog.records
    assert path.exact and path.max_error < 1e-5 and path.mean_error <= path.max_error    # measured: 1e-6 m
    assert path.name == "rigid.bvh" and path.read_text().startswith("HIERARCHY")
    assert _own_reader_error(path, joints).max() < 1e-5                         # salad_core.bvh
    assert _check_bvh_reproduces(path, joints, list(range(0, 60, 7)), tol=1e-5) < 1e-5    # PyPI bvh + FK here
    # in centimetres too
    path = export_bvh(joints, SKEL, tmp_path / "rigid_cm.bvh", scale=100.0)
    assert path.max_error < 1e-5


def test_bvh_offsets_are_the_motions_own_geometry(tmp_path):
    """Single-child bones: the T-pose direction at the motion's bone length; the children of the pelvis and of
    spine3: the motion's rigid geometry (pairwise distances of frame 0), turned as a whole."""
    import bvh

    joints = rigid_branch_motion(20, seed=3)
    path = export_bvh(joints, SKEL, tmp_path / "o.bvh")
    with open(path) as fh:
        mocap = bvh.Bvh(fh.read())
    offsets = {n: np.asarray(mocap.joint_offset(n)) for n in SKEL.joint_names[1:]}
    for j, name in enumerate(SKEL.joint_names[1:], start=1):
        length = np.linalg.norm(joints[0, j] - joints[0, SKEL.parents[j]])
        assert np.linalg.norm(offsets[name]) == pytest.approx(length, abs=2e-6), name
    kids = children_of(SKEL)
    for j in (0, SKEL.joint_names.index("spine3")):
        names = [SKEL.joint_names[c] for c in kids[j]]
        got = np.stack([offsets[n] for n in names])
        want = joints[0, list(kids[j])] - joints[0, j]
        np.testing.assert_allclose(np.linalg.norm(got[:, None] - got[None], axis=-1),
                                   np.linalg.norm(want[:, None] - want[None], axis=-1), atol=2e-6)
    np.testing.assert_allclose(offsets["left_elbow"] / np.linalg.norm(offsets["left_elbow"]), [1, 0, 0], atol=1e-6)


def test_bvh_of_non_rigid_joints_returns_its_error(tmp_path, caplog):
    """Joints a rigid skeleton cannot hold (the hips and collars wobble a centimetre): the file is the closest
    rigid skeleton, the returned figure is what a reader gets back, and it is not logged as a fault."""
    joints = rigid_branch_motion(40, seed=1)
    rng = np.random.default_rng(0)
    wobble = joints.copy()
    for name in ("left_hip", "right_hip", "left_collar", "right_collar"):
        wobble[:, SKEL.joint_names.index(name)] += rng.normal(scale=0.005, size=(40, 3))
    with caplog.at_level(logging.INFO, logger="salad_viz"):
        path = export_bvh(wobble, SKEL, tmp_path / "w.bvh")
    assert not caplog.records
    err = _own_reader_error(path, wobble)
    assert path.max_error == pytest.approx(err.max(), abs=1e-6) and path.mean_error == pytest.approx(err.mean(), abs=1e-6)
    assert not path.exact and 0.002 < path.max_error < 0.05
    # the residual stays where the wobble is: each joint is aimed at from where the file puts its parent
    assert err.mean() < 0.006


def test_bvh_warns_when_bones_stretch(tmp_path, caplog):
    walk = synthetic_motion(SKEL, 10)
    wrist = SKEL.joint_names.index("left_wrist")
    elbow = SKEL.parents[wrist]
    stretched = walk.copy()
    stretched[5:, wrist] += 0.1 * (walk[5:, wrist] - walk[5:, elbow]) / np.linalg.norm(
        walk[5:, wrist] - walk[5:, elbow], axis=-1, keepdims=True)
    with caplog.at_level(logging.WARNING, logger="salad_viz.export"):
        path = export_bvh(stretched, SKEL, tmp_path / "s.bvh")
    assert any("holds these joints only to" in r.message and "bones change length" in r.message
               for r in caplog.records)
    assert path.max_error > 0.05


def test_export_of_features_gives_generates_joints_and_bvh(make_tiny_pipeline, tmp_path, capsys, single_thread):
    """``salad export X_features.npy`` (bvh and npy) writes the motion of the ``X_joints.npy`` and ``X.bvh`` that
    ``salad generate`` wrote for it: the same recovery (the pipeline's default fit), not the raw positions."""
    from salad_core import cli
    from salad_core.recovery import DEFAULT_METHOD

    weights = make_tiny_pipeline(seed=0).save_pretrained(tmp_path / "w")
    gen = tmp_path / "gen"
    assert cli.main(["-q", "generate", "a person walks", "--length", "24", "--steps", "2", "--no-render",
                     "--no-attention", "--weights", str(weights), "--out", str(gen)]) == 0
    stem = "00_a_person_walks"
    features = gen / f"{stem}_features.npy"
    for fmt in ("bvh", "npy"):
        assert cli.main(["-q", "export", str(features), "--format", fmt, "--out", str(tmp_path / "exp")]) == 0
    assert DEFAULT_METHOD == "fit"
    joints = np.load(gen / f"{stem}_joints.npy")
    np.testing.assert_allclose(np.load(tmp_path / "exp" / f"{stem}_features.npy"), joints, atol=1e-6)
    assert (tmp_path / "exp" / f"{stem}_features.bvh").read_text() == (gen / f"{stem}.bvh").read_text()
    err = _own_reader_error(gen / f"{stem}.bvh", joints.astype(np.float64))
    print(f"tiny random model: BVH vs its joints {100 * err.max():.3f} cm max")


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


def test_half_turn_swings_keep_their_twist_continuous():
    """A bone swinging through a half turn from its rest direction: the smallest swing's axis is undefined at
    180 degrees; the solver keeps the previous frame's axis there, so the joint does not spin about its bone."""
    from salad_viz.kinematics import _continuous_swing

    deg = np.array([176.0, 178.0, 180.0, 182.0, 184.0])
    a = np.broadcast_to([0.0, 1.0, 0.0], (5, 3))
    b = np.einsum("nij,j->ni", axis_angle_matrix(np.array([1.0, 0.0, 0.0]), np.radians(deg)), [0.0, 1.0, 0.0])
    rot = _continuous_swing(a, b)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", rot, a), b, atol=1e-9)
    step = [np.degrees(np.arccos(np.clip((np.trace(rot[t].T @ rot[t + 1]) - 1) / 2, -1, 1))) for t in range(4)]
    assert max(step) < 2.5, step                          # 2 degrees a frame, as the bone moves
    plain = swing_rotation(a, b)                          # the smallest swing alone turns 180 degrees at 180
    assert np.degrees(np.arccos(np.clip((np.trace(plain[1].T @ plain[2]) - 1) / 2, -1, 1))) > 90


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
