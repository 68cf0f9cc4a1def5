"""salad_core.bvh: reading BVH files, mapping rigs (salad's export, SMPL, Mixamo, CMU, generic) to the
22 HumanML3D joints, converting units / up axis / frame rate, and errors for bad files.

The rigs are written here from known joint positions (a procedural corpus motion): a small writer
solves each joint's rotation (Kabsch on its children) and emits Euler angles in the rig's own
channel order, so the expected joints are known exactly. The shipped files in ``tests/data/bvh``
are small takes made the same way (``python tests/test_bvh_import.py --regenerate``).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from salad_core.bvh import (BvhError, RigError, bvh_to_features, bvh_to_joints, import_bvh, load_motion,
                            parse_bvh, read_bvh)
from salad_core.bvh.convert import TARGET_STATURE, UP_AXES, BvhImportOptions
from salad_core.bvh.rigs import HML_NAMES, normalize_name
from salad_core.motion import features_to_joints, joints_to_features
from salad_core.skeleton import get_skeleton

DATA = Path(__file__).parent / "data" / "bvh"
J = {n: i for i, n in enumerate(HML_NAMES)}


# ----------------------------------------------------------------------------- a rig writer
def corpus_joints() -> np.ndarray:
    """A procedural corpus motion (seed 0, motion 13: walk, stretch; 60 frames at 20 fps) stored in
    tests/data/bvh/corpus_motion.npy: HumanML3D joints, metres, Y up, on the floor. Stored because
    the corpus generator changes between versions; made by ``make_motion(0, 13)``."""
    return np.load(DATA / "corpus_motion.npy").astype(np.float64)


def rigid(joints: np.ndarray) -> np.ndarray:
    """The same motion with constant bone lengths and rigid branches (salad_viz's own rotation solve
    and forward kinematics), so that any rig written from it reproduces it exactly."""
    from salad_viz.kinematics import forward_kinematics, solve_rotations

    s = solve_rotations(joints, "humanml3d")
    out = forward_kinematics(s.offsets, s.parents, s.rotations, s.root_positions)
    out[..., 1] -= out[..., 1].min()
    return out


def _kabsch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotations ``(N, 3, 3)`` taking rest vectors ``a`` (K, 3) onto ``b`` (N, K, 3), least squares."""
    h = np.einsum("ka,nkb->nab", a, b)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.swapaxes(vt, -1, -2) @ np.swapaxes(u, -1, -2)))
    fix = np.broadcast_to(np.eye(3), h.shape).copy()
    fix[:, 2, 2] = d
    return np.swapaxes(vt, -1, -2) @ fix @ np.swapaxes(u, -1, -2)


def write_rig(names, parents, pos, channels, *, end_sites=None, scale=1.0, up="y", frame_time=0.05) -> str:
    """BVH text of a rig whose joints are at ``pos`` (N, P, 3) (metres, Y up), rest pose = frame 0.

    ``channels[j]`` is e.g. ``"pZYX"`` (position channels, then rotations Z, Y, X) or ``"XYZ"``;
    ``end_sites`` maps a joint index to the world positions (N, 3) of its End Site.
    """
    from scipy.spatial.transform import Rotation

    end_sites = end_sites or {}
    pos = np.asarray(pos, np.float64) @ UP_AXES[up] * scale           # row vectors: R^T p in file axes
    ends = {j: np.asarray(e, np.float64) @ UP_AXES[up] * scale for j, e in end_sites.items()}
    n, p = pos.shape[:2]
    kids = [[c for c in range(p) if parents[c] == j] for j in range(p)]
    world = np.zeros((n, p, 3, 3))
    for j in range(p):
        # the rotation is fitted to the children that need it (no position channels of their own)
        fixed = [c for c in kids[j] if not channels[c].startswith("p")] or kids[j]
        vec_now = [pos[:, c] - pos[:, j] for c in fixed] + ([ends[j] - pos[:, j]] if j in ends else [])
        vec_rest = [v[0] for v in vec_now]
        if vec_now:
            world[:, j] = _kabsch(np.stack(vec_rest), np.stack(vec_now, axis=1))
        else:
            world[:, j] = world[:, parents[j]] if parents[j] >= 0 else np.eye(3)
    lines = ["HIERARCHY"]
    columns = []

    def emit(j, depth):
        ind = "  " * depth
        off = pos[0, j] - (pos[0, parents[j]] if parents[j] >= 0 else 0.0)
        if parents[j] < 0:
            off = np.zeros(3)
        ch = channels[j]
        decl = (["Xposition", "Yposition", "Zposition"] if ch.startswith("p") else []) + \
            [f"{a}rotation" for a in ch.lstrip("p")]
        lines.append(f"{ind}{'ROOT' if parents[j] < 0 else 'JOINT'} {names[j]}")
        lines.append(f"{ind}{{")
        lines.append(f"{ind}  OFFSET {off[0]:.6f} {off[1]:.6f} {off[2]:.6f}")
        lines.append(f"{ind}  CHANNELS {len(decl)} {' '.join(decl)}")
        wp = world[:, parents[j]] if parents[j] >= 0 else np.broadcast_to(np.eye(3), (n, 3, 3))
        local_r = np.swapaxes(wp, -1, -2) @ world[:, j]
        rel = pos[:, j] - (pos[:, parents[j]] if parents[j] >= 0 else 0.0)
        local_t = np.einsum("nba,nb->na", wp, rel)                     # W_parent^T (p_j - p_parent)
        if ch.startswith("p"):
            columns.append(local_t)
        order = ch.lstrip("p")
        if order:
            columns.append(Rotation.from_matrix(local_r).as_euler(order.upper(), degrees=True))
        for c in kids[j]:
            emit(c, depth + 1)
        if j in ends:
            e = ends[j][0] - pos[0, j]
            lines.extend([f"{ind}  End Site", f"{ind}  {{", f"{ind}    OFFSET {e[0]:.6f} {e[1]:.6f} {e[2]:.6f}",
                          f"{ind}  }}"])
        lines.append(f"{ind}}}")

    emit(0, 0)
    data = np.concatenate(columns, axis=1)
    lines += ["MOTION", f"Frames: {n}", f"Frame Time: {frame_time:.6f}"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in data]
    return "\n".join(lines) + "\n"


def _rig(spec, joints):
    """``spec``: list of (name, parent name, position (N, 3) or callable of joints, channels)."""
    names = [s[0] for s in spec]
    parents = [names.index(s[1]) if s[1] else -1 for s in spec]
    pos = np.stack([s[2](joints) if callable(s[2]) else s[2] for s in spec], axis=1)
    return names, parents, pos, [s[3] for s in spec]


def _at(name):
    return lambda x: x[:, J[name]]


def _mix(a, b, w):
    return lambda x: (1 - w) * x[:, J[a]] + w * x[:, J[b]]


def cmu_rig(joints):
    """CMU naming and layout: LHipJoint and LowerBack at the hips, Spine half-way up the back, the
    clavicles (LeftShoulder) at zero offset from Spine1, Neck at Spine1, Neck1 mid-neck."""
    spec = [("Hips", None, _at("pelvis"), "pZYX")]
    for s, S in (("left", "Left"), ("right", "Right")):
        spec += [(f"{S[0]}HipJoint", "Hips", _at("pelvis"), "ZYX"), (f"{S}UpLeg", f"{S[0]}HipJoint", _at(f"{s}_hip"), "ZYX"),
                 (f"{S}Leg", f"{S}UpLeg", _at(f"{s}_knee"), "ZYX"), (f"{S}Foot", f"{S}Leg", _at(f"{s}_ankle"), "ZYX"),
                 (f"{S}ToeBase", f"{S}Foot", _at(f"{s}_foot"), "ZYX")]
    spec += [("LowerBack", "Hips", _at("pelvis"), "ZYX"), ("Spine", "LowerBack", _mix("spine1", "spine2", 0.5), "ZYX"),
             ("Spine1", "Spine", _at("spine3"), "ZYX"), ("Neck", "Spine1", _at("spine3"), "ZYX"),
             ("Neck1", "Neck", _at("neck"), "ZYX"), ("Head", "Neck1", _at("head"), "ZYX")]
    for s, S in (("left", "Left"), ("right", "Right")):
        spec += [(f"{S}Shoulder", "Spine1", _at("spine3"), "ZYX"), (f"{S}Arm", f"{S}Shoulder", _at(f"{s}_shoulder"), "ZYX"),
                 (f"{S}ForeArm", f"{S}Arm", _at(f"{s}_elbow"), "ZYX"), (f"{S}Hand", f"{S}ForeArm", _at(f"{s}_wrist"), "ZYX")]
    return _rig(spec, joints)


def mixamo_rig(joints, prefix="mixamorig:"):
    """Mixamo naming (with its prefix), 6 channels on every joint, ZXY rotation order."""
    spec = [("Hips", None, _at("pelvis"), "pZXY"), ("Spine", "Hips", _at("spine1"), "pZXY"),
            ("Spine1", "Spine", _at("spine2"), "pZXY"), ("Spine2", "Spine1", _at("spine3"), "pZXY"),
            ("Neck", "Spine2", _at("neck"), "pZXY"), ("Head", "Neck", _at("head"), "pZXY"),
            ("HeadTop_End", "Head", lambda x: x[:, J["head"]] + [0.0, 0.12, 0.0], "pZXY")]
    for s, S in (("left", "Left"), ("right", "Right")):
        spec += [(f"{S}Shoulder", "Spine2", _at(f"{s}_collar"), "pZXY"), (f"{S}Arm", f"{S}Shoulder", _at(f"{s}_shoulder"), "pZXY"),
                 (f"{S}ForeArm", f"{S}Arm", _at(f"{s}_elbow"), "pZXY"), (f"{S}Hand", f"{S}ForeArm", _at(f"{s}_wrist"), "pZXY"),
                 (f"{S}UpLeg", "Hips", _at(f"{s}_hip"), "pZXY"), (f"{S}Leg", f"{S}UpLeg", _at(f"{s}_knee"), "pZXY"),
                 (f"{S}Foot", f"{S}Leg", _at(f"{s}_ankle"), "pZXY"), (f"{S}ToeBase", f"{S}Foot", _at(f"{s}_foot"), "pZXY")]
    names, parents, pos, ch = _rig(spec, joints)
    return [prefix + n for n in names], parents, pos, ch


def smpl_rig(joints):
    """SMPL ``Pelvis, L_Hip, ...`` names, the HumanML3D hierarchy, XYZ rotation order."""
    short = {"pelvis": "Pelvis", "spine1": "Spine1", "spine2": "Spine2", "spine3": "Spine3", "neck": "Neck",
             "head": "Head"}
    sk = get_skeleton("humanml3d")
    names = []
    for n in HML_NAMES:
        side, _, base = n.partition("_")
        names.append(short.get(n) or f"{side[0].upper()}_{base.capitalize()}")
    channels = ["pXYZ"] + ["XYZ"] * (len(names) - 1)
    return names, list(sk.parents), joints.copy(), channels


def biped_rig(joints):
    """3ds Max Biped names (``Bip01 L Thigh``...): no toe joints (End Sites below the feet), one
    spine joint, the clavicles on the neck: spine1..3 must be placed along the back."""
    # (spine and neck with position channels: the source motion bends at spine1 and spine3 between them)
    spec = [("Bip01 Pelvis", None, _at("pelvis"), "pZYX"), ("Bip01 Spine", "Bip01 Pelvis", _at("spine2"), "pZYX"),
            ("Bip01 Neck", "Bip01 Spine", _at("neck"), "pZYX"), ("Bip01 Head", "Bip01 Neck", _at("head"), "ZYX")]
    for s, S in (("left", "L"), ("right", "R")):
        # (clavicles with position channels: in the source motion they move with spine3, not the neck)
        spec += [(f"Bip01 {S} Clavicle", "Bip01 Neck", _at(f"{s}_collar"), "pZYX"),
                 (f"Bip01 {S} UpperArm", f"Bip01 {S} Clavicle", _at(f"{s}_shoulder"), "ZYX"),
                 (f"Bip01 {S} Forearm", f"Bip01 {S} UpperArm", _at(f"{s}_elbow"), "ZYX"),
                 (f"Bip01 {S} Hand", f"Bip01 {S} Forearm", _at(f"{s}_wrist"), "ZYX"),
                 (f"Bip01 {S} Thigh", "Bip01 Pelvis", _at(f"{s}_hip"), "ZYX"),
                 (f"Bip01 {S} Calf", f"Bip01 {S} Thigh", _at(f"{s}_knee"), "ZYX"),
                 (f"Bip01 {S} Foot", f"Bip01 {S} Calf", _at(f"{s}_ankle"), "ZYX")]
    names, parents, pos, ch = _rig(spec, joints)
    ends = {names.index(f"Bip01 {S} Foot"): joints[:, J[f"{s}_foot"]] for s, S in (("left", "L"), ("right", "R"))}
    return names, parents, pos, ch, ends


#: The 1/0.45-inch unit of the CMU conversion, metres.
CMU_UNIT = 0.0254 / 0.45


def rig_files(joints) -> dict[str, tuple[str, dict]]:
    """BVH text of every test rig of ``joints`` (20 fps; each rig at its own rate) and how it was written."""
    out = {}
    up = {fps: _upsampled(joints, fps) for fps in (120, 30, 40)}
    out["cmu"] = (write_rig(*cmu_rig(up[120]), scale=1 / CMU_UNIT, frame_time=1 / 120), {"up": "y", "fps": 120})
    out["mixamo"] = (write_rig(*mixamo_rig(up[30]), scale=100.0, frame_time=1 / 30), {"up": "y", "fps": 30})
    out["smpl"] = (write_rig(*smpl_rig(joints), up="z", frame_time=1 / 20), {"up": "z", "fps": 20})
    names, parents, pos, ch, ends = biped_rig(up[40])
    out["biped"] = (write_rig(names, parents, pos, ch, end_sites=ends, scale=1 / 0.0254, up="z", frame_time=1 / 40),
                    {"up": "z", "fps": 40})
    return out


def _resampled(joints, src_fps, fps):
    """Linear resampling in time (written here, independently of salad_core.bvh)."""
    duration = (len(joints) - 1) / src_fps
    t = np.arange(0, duration + 1e-9, 1.0 / fps) * src_fps
    k = np.minimum(np.floor(t + 1e-9).astype(int), len(joints) - 2)
    w = (t - k)[:, None, None]
    return joints[k] * (1 - w) + joints[k + 1] * w


def _upsampled(joints, fps):
    """The 20-fps joints at ``fps``: what a rig at ``fps`` is written from."""
    return _resampled(joints, 20.0, fps)


# ----------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def motion():
    """The stored corpus motion as it is (bone lengths vary slightly, as in generated data); 57 of its
    60 frames, so that the 30-fps copies end on a 20-fps frame."""
    return corpus_joints()[:57]


@pytest.fixture(scope="module")
def walk(motion):
    """The corpus motion made rigid: the 'known joint positions' the test rigs are written from."""
    return rigid(motion)


@pytest.fixture(scope="module")
def rigs(walk, tmp_path_factory):
    folder = tmp_path_factory.mktemp("rigs")
    files = {}
    for style, (text, info) in rig_files(walk).items():
        path = folder / f"{style}.bvh"
        path.write_text(text)
        files[style] = (path, info)
    return files


# ----------------------------------------------------------------------------- reader and FK
def test_forward_kinematics_matches_scipy_for_every_channel_order():
    """Random rotations in all six Euler orders, a 6-channel child and an End Site: positions equal
    an independent FK built from scipy's intrinsic Euler rotations."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(0)
    orders = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]
    n = 5
    offsets = rng.normal(size=(6, 3))
    angles = rng.uniform(-170, 170, size=(n, 6, 3))
    trans = rng.normal(size=(n, 3))
    child_pos = rng.normal(size=(n, 3))          # joint 3 has position channels (replacing its OFFSET)
    text = ["HIERARCHY"]
    for j, order in enumerate(orders):
        kw = "ROOT" if j == 0 else "JOINT"
        pch = "Xposition Yposition Zposition " if j in (0, 3) else ""
        text += [f"{kw} j{j}", "{", "OFFSET " + " ".join(map(str, offsets[j])),
                 f"CHANNELS {6 if j in (0, 3) else 3} {pch}" + " ".join(f"{a}rotation" for a in order)]
    text += ["End Site", "{", "OFFSET 0.5 -1 2", "}"] + ["}"] * 6
    rows = []
    for t in range(n):
        row = []
        for j in range(6):
            if j == 0:
                row += list(trans[t])
            if j == 3:
                row += list(child_pos[t])
            row += list(angles[t, j])
        rows.append(" ".join(f"{v:.9f}" for v in row))
    text += ["MOTION", f"Frames: {n}", "Frame Time: 0.0083333"] + rows
    motion = parse_bvh("\n".join(text))
    got = motion.world_positions()
    assert got.shape == (n, 7, 3) and motion.point_names()[-1] == "j5/End"
    for t in range(n):
        r, p = np.eye(3), np.zeros(3)
        for j, order in enumerate(orders):
            local = trans[t] if j == 0 else (child_pos[t] if j == 3 else offsets[j])
            p = p + r @ local
            r = r @ Rotation.from_euler(order, angles[t, j], degrees=True).as_matrix()
            np.testing.assert_allclose(got[t, j], p, atol=1e-9)
        np.testing.assert_allclose(got[t, 6], p + r @ [0.5, -1, 2], atol=1e-9)
    assert motion.fps == pytest.approx(120.0, rel=1e-4)
    rest = motion.world_positions(rest=True)[0]              # offsets only, even where positions are channels
    np.testing.assert_allclose(rest[3], offsets[:4].sum(0), atol=1e-12)


def test_export_then_import_round_trip_within_a_centimetre(tmp_path, motion):
    from salad_viz import export_bvh
    from salad_viz.kinematics import fk_error, solve_rotations

    path = export_bvh(motion, "humanml3d", tmp_path / "walk.bvh")
    take = import_bvh(path)
    assert take.rig.style == "smpl" and take.units == "m" and take.up == "y"
    assert set(take.detected) == {"units", "up", "rig"}
    assert take.joints.shape == motion.shape and take.joints.dtype == np.float32
    err = np.linalg.norm(take.joints - motion, axis=-1)
    assert err.max() < 0.01, err.max()                         # measured: 0.56 cm
    # all of that error is the export's (a rigid fit of slightly non-rigid joints): the import
    # reproduces the file's own forward kinematics
    assert err.max() == pytest.approx(fk_error(solve_rotations(motion, "humanml3d"), motion), abs=2e-4)
    assert take.joints[..., 1].min() == 0.0
    # the features match too (retargeting, facing and the floor are joints_to_features' business)
    rec = features_to_joints(bvh_to_features(path))
    ref = features_to_joints(joints_to_features(motion))
    assert np.linalg.norm(rec - ref, axis=-1).max() < 0.01
    # exported in centimetres at 40 fps: the unit is detected and the take resampled to 20 fps
    path = export_bvh(_upsampled(motion, 40), "humanml3d", tmp_path / "walk_cm.bvh", fps=40, scale=100.0)
    take = import_bvh(path)
    assert take.units == "cm" and take.source_fps == pytest.approx(40.0, rel=1e-4) and take.fps == 20.0
    assert take.num_frames == len(motion)
    assert np.linalg.norm(take.joints - motion, axis=-1).max() < 0.01


@pytest.mark.parametrize("style, units", [("cmu", "fit"), ("mixamo", "cm"), ("smpl", "m"), ("biped", "inch")])
def test_each_rig_style_maps_to_the_humanml3d_joints(rigs, walk, style, units):
    path, info = rigs[style]
    take = import_bvh(path)
    assert take.rig.style == {"biped": "generic"}.get(style, style)
    assert take.up == info["up"] and take.units == units and take.source_fps == pytest.approx(info["fps"], rel=1e-4)
    expected = _resampled(_upsampled(walk, info["fps"]), info["fps"], 20.0)   # = walk where the rates divide
    assert take.num_frames == len(walk) == len(expected)
    got = take.joints.astype(np.float64)
    if style == "cmu":       # the unit is unusual: the rig is scaled to the target stature
        # (the placed spine is a little shorter than the original's polyline: 1.5 % larger scale)
        assert take.metres_per_unit == pytest.approx(TARGET_STATURE / _stature_m(walk) * CMU_UNIT, rel=0.03)
        got = got * (CMU_UNIT / take.metres_per_unit)
    got[..., 1] -= got[..., 1].min()
    err = np.linalg.norm(got - expected, axis=-1)                # (N, 22)
    placed = {"cmu": ["spine1", "spine2", "left_collar", "right_collar"], "biped": ["spine1", "spine2", "spine3"]}.get(style, [])
    direct = [i for n, i in J.items() if n not in placed]
    # CMU: 2 mm where the test rig's spine joints bend at other places than the source's
    assert err[:, direct].max() < (0.003 if style == "cmu" else 1e-3), (style, err[:, direct].max())
    # joints the rig lacks are placed along its spine / clavicle, at HumanML3D's proportions
    desc = take.rig.describe()
    for n in placed:
        assert desc[n].startswith("along "), desc[n]
    if style == "cmu":
        spine = got[:, [J["pelvis"], J["spine3"]]]
        arc = np.linalg.norm(got[:, J["spine2"]] - got[:, J["spine1"]], axis=-1)
        assert np.all(arc > 0)
        lengths = get_skeleton("humanml3d").bone_lengths
        for side in ("left", "right"):          # on the chord spine3 -> shoulder, at 0.51 / 0.54
            a, b = lengths[J[f"{side}_collar"]], lengths[J[f"{side}_shoulder"]]
            chord = got[:, J[f"{side}_shoulder"]] - got[:, J["spine3"]]
            on = got[:, J["spine3"]] + a / (a + b) * chord
            assert np.linalg.norm(got[:, J[f"{side}_collar"]] - on, axis=-1).max() < 1e-3
        # spine1, spine2 on the rig's spine polyline Hips > Spine > Spine1 (the rig's Spine is the
        # midpoint of HumanML3D's spine1 and spine2)
        mid = 0.5 * (expected[:, J["spine1"]] + expected[:, J["spine2"]])
        for n in ("spine1", "spine2"):
            d1 = _dist_to_segment(got[:, J[n]], expected[:, J["pelvis"]], mid)
            d2 = _dist_to_segment(got[:, J[n]], mid, expected[:, J["spine3"]])
            assert np.minimum(d1, d2).max() < 1e-3
        assert spine.shape == (len(walk), 2, 3)
    for n in placed:                            # and not far from where HumanML3D has them
        assert err[:, J[n]].max() < 0.08, (style, n, err[:, J[n]].max())
    # the features the models see agree with those of the original motion (up to the placed joints)
    rec = features_to_joints(take.features())
    ref = features_to_joints(joints_to_features(expected))
    assert np.linalg.norm(rec - ref, axis=-1).mean() < (0.03 if placed else 0.005)


def _dist_to_segment(p, a, b):
    ab = b - a
    t = np.clip(((p - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0, 1)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=-1)


def _stature_m(joints):
    from salad_core.bvh.convert import stature

    return stature(joints)


def _legs(joints):
    return sum(np.linalg.norm(joints[:, J[a]] - joints[:, J[b]], axis=-1)
               for a, b in (("left_hip", "left_knee"), ("left_knee", "left_ankle")))


def test_rig_mapping_details(rigs):
    desc = import_bvh(rigs["cmu"][0]).rig.describe()
    assert desc["left_hip"] == "LeftUpLeg" and desc["left_ankle"] == "LeftFoot" and desc["left_foot"] == "LeftToeBase"
    assert desc["spine3"] == "Spine1" and desc["neck"] == "Neck1" and desc["left_shoulder"] == "LeftArm"
    assert desc["spine1"] == "along Hips > LowerBack > Spine > Spine1 at 0.40"
    assert desc["left_collar"] == "along LeftShoulder > LeftArm at 0.51"
    desc = import_bvh(rigs["mixamo"][0]).rig.describe()
    assert desc["spine3"] == "mixamorig:Spine2" and desc["left_collar"] == "mixamorig:LeftShoulder"
    desc = import_bvh(rigs["biped"][0]).rig.describe()
    assert desc["left_foot"] == "Bip01 L Foot/End"               # no toe joint: the foot's End Site
    assert desc["neck"] == "Bip01 Neck" and desc["spine2"].startswith("along Bip01 Pelvis > Bip01 Spine")
    assert normalize_name("mixamorig:LeftUpLeg") == "leftupleg" and normalize_name("m_avg_L_Hip") == "lhip"


def test_a_rig_with_more_spine_joints(tmp_path, walk):
    """Hips > Spine > Spine1 > Spine2 > Spine3 > Neck, collars on Spine3: spine3 is Spine3 (where the
    collars hang), spine1 and spine2 are placed along the rig's longer spine."""
    spec = [("Hips", None, _at("pelvis"), "pZXY"), ("Spine", "Hips", _mix("pelvis", "spine1", 0.6), "pZXY"),
            ("Spine1", "Spine", _mix("spine1", "spine2", 0.5), "pZXY"), ("Spine2", "Spine1", _at("spine2"), "pZXY"),
            ("Spine3", "Spine2", _at("spine3"), "pZXY"), ("Neck", "Spine3", _at("neck"), "pZXY"),
            ("Head", "Neck", _at("head"), "pZXY")]
    for s_, S in (("left", "Left"), ("right", "Right")):
        spec += [(f"{S}Shoulder", "Spine3", _at(f"{s_}_collar"), "pZXY"),
                 (f"{S}Arm", f"{S}Shoulder", _at(f"{s_}_shoulder"), "pZXY"),
                 (f"{S}ForeArm", f"{S}Arm", _at(f"{s_}_elbow"), "pZXY"), (f"{S}Hand", f"{S}ForeArm", _at(f"{s_}_wrist"), "pZXY"),
                 (f"{S}UpLeg", "Hips", _at(f"{s_}_hip"), "pZXY"), (f"{S}Leg", f"{S}UpLeg", _at(f"{s_}_knee"), "pZXY"),
                 (f"{S}Foot", f"{S}Leg", _at(f"{s_}_ankle"), "pZXY"), (f"{S}ToeBase", f"{S}Foot", _at(f"{s_}_foot"), "pZXY")]
    path = tmp_path / "long_spine.bvh"
    path.write_text(write_rig(*_rig(spec, walk[:10]), scale=100.0))
    take = import_bvh(path)
    desc = take.rig.describe()
    assert take.rig.style == "generic" and desc["spine3"] == "Spine3" and desc["neck"] == "Neck"
    assert desc["spine1"] == "along Hips > Spine > Spine1 > Spine2 > Spine3 at 0.40"
    err = np.linalg.norm(take.joints - walk[:10], axis=-1)
    direct = [i for n, i in J.items() if n not in ("spine1", "spine2")]
    assert err[:, direct].max() < 1e-4
    assert err[:, [J["spine1"], J["spine2"]]].max() < 0.03        # near the originals, on the rig's spine


def test_mixamo_names_without_prefix_and_forced_style(tmp_path, walk):
    path = tmp_path / "plain.bvh"
    path.write_text(write_rig(*mixamo_rig(walk[:10], prefix=""), scale=100.0))
    take = import_bvh(path, rig="mixamo", units="cm", up="y")
    assert take.rig.style == "mixamo" and take.detected == ()
    assert np.linalg.norm(take.joints - walk[:10], axis=-1).max() < 0.01
    with pytest.raises(RigError, match="as a 'smpl' rig.*missing pelvis"):
        import_bvh(path, rig="smpl")
    with pytest.raises(ValueError, match="rig style 'maya' is not known; allowed: smpl, mixamo, cmu, generic"):
        import_bvh(path, rig="maya")


def test_user_name_map_dict_json_and_reverse(tmp_path, walk):
    names, parents, pos, ch = smpl_rig(walk[:8])
    custom = [f"jnt_{i:02d}" for i in range(len(names))]
    path = tmp_path / "custom.bvh"
    path.write_text(write_rig(custom, parents, pos, ch, up="z"))
    with pytest.raises(RigError) as err:
        import_bvh(path)
    msg = str(err.value)
    assert "missing pelvis, left_hip" in msg and "jnt_00, jnt_01" in msg and "name map" in msg
    mapping = {hml: c for hml, c in zip(HML_NAMES, custom)}
    expected = walk[:8]
    for given in (mapping, {v: k for k, v in mapping.items()}):
        take = import_bvh(path, name_map=given)
        assert take.rig.style.endswith("+map")
        assert np.linalg.norm(take.joints - expected, axis=-1).max() < 1e-4
    (tmp_path / "map.json").write_text(json.dumps(mapping))
    take = import_bvh(path, name_map=tmp_path / "map.json")
    assert np.linalg.norm(take.joints - expected, axis=-1).max() < 1e-4
    # a partial map completes an auto-detected rig; wrong names are named
    smpl_path = tmp_path / "smpl.bvh"
    smpl_path.write_text(write_rig(names, parents, pos, ch, up="z"))
    take = import_bvh(smpl_path, name_map={"left_wrist": "L_Elbow", "left_elbow": "L_Wrist"})
    assert take.rig.describe()["left_wrist"] == "L_Elbow"
    with pytest.raises(RigError, match="has no joint 'L_Pinky' \\(given for left_wrist\\)"):
        import_bvh(smpl_path, name_map={"left_wrist": "L_Pinky"})
    with pytest.raises(RigError, match="'lefthand' is not a HumanML3D joint name; allowed keys: pelvis"):
        import_bvh(smpl_path, name_map={"lefthand": "L_Wrist"})
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(RigError, match="not valid JSON"):
        import_bvh(smpl_path, name_map=tmp_path / "bad.json")


def test_units_up_and_fps_options(rigs, walk):
    path, _ = rigs["mixamo"]
    take = import_bvh(path, units="m", fps=10)
    assert take.units == "m" and take.fps == 10 and take.num_frames == (len(walk) - 1) // 2 + 1
    assert np.median(_legs(take.joints)) == pytest.approx(100 * np.median(_legs(walk)), rel=1e-3)
    take = import_bvh(path, units=0.01)
    assert take.units == "custom" and take.metres_per_unit == 0.01
    # a wrong up axis given on purpose turns the body on its side (the spine no longer vertical)
    spine = import_bvh(rigs["smpl"][0], up="y").joints
    v = spine[:, J["head"]] - spine[:, J["pelvis"]]
    assert np.abs(v[:, 1]).mean() < 0.5 * np.abs(v[:, 2]).mean()
    for bad, msg in [({"units": "furlong"}, "units 'furlong' is not known; allowed: m, cm, mm, inch, ft"),
                     ({"units": -1.0}, "positive number of metres"), ({"up": "w"}, "up 'w' is not an axis"),
                     ({"fps": 0}, "fps must be a positive number")]:
        with pytest.raises(ValueError, match=msg):
            BvhImportOptions(**bad)


def test_up_axis_comes_from_the_standing_rest_pose(tmp_path, walk, caplog):
    """A take that falls and lies on its back from frame 1 on: the spine points along Z on average,
    but the rest pose (frame 0 here) stands along Y, and the rest pose decides."""
    lying = walk[:20].copy()
    c, s_ = 0.0, 1.0                                          # -90 degrees about X around the pelvis
    rot = np.array([[1, 0, 0], [0, c, s_], [0, -s_, c]])
    lying[1:] = (lying[1:] - lying[1:, :1]) @ rot.T + lying[1:, :1]
    path = tmp_path / "lying.bvh"
    path.write_text(write_rig(*smpl_rig(lying)))
    take = import_bvh(path)
    assert take.up == "y" and "up" in take.detected
    assert "the rest pose stands along y but the body's spine points along" in caplog.text
    # an explicit axis skips the detection (and the warning)
    caplog.clear()
    assert import_bvh(path, up="y").detected == ("units", "rig") and not caplog.text


def test_bvh_to_joints_and_load_motion(rigs, walk, tmp_path):
    path, _ = rigs["mixamo"]
    joints = bvh_to_joints(path)
    assert joints.shape == walk.shape
    loaded = load_motion(path)
    assert loaded.kind == "bvh" and loaded.features.shape == (len(walk) - 1, 263) and loaded.bvh.rig.style == "mixamo"
    np.save(tmp_path / "j.npy", walk.astype(np.float32))
    np.save(tmp_path / "f.npy", joints_to_features(walk))
    lj, lf = load_motion(tmp_path / "j.npy"), load_motion(tmp_path / "f.npy")
    assert lj.kind == "joints" and lf.kind == "features"
    np.testing.assert_allclose(lj.features, lf.features, atol=1e-5)
    assert lf.joints.shape == (len(walk) - 1, 22, 3)
    with pytest.raises(FileNotFoundError, match="motion file not found"):
        load_motion(tmp_path / "nope.bvh")
    with pytest.raises(ValueError, match="up applies to BVH files only"):
        load_motion(tmp_path / "f.npy", up="z")
    np.save(tmp_path / "w.npy", np.zeros((5, 7)))
    with pytest.raises(ValueError, match="must have shape \\(..., N, 263\\)"):
        load_motion(tmp_path / "w.npy")
    np.save(tmp_path / "w.npy", np.zeros((5, 7, 3)))
    with pytest.raises(ValueError, match="expected features \\(N, 263\\), joints \\(N, 22, 3\\) or a .bvh"):
        load_motion(tmp_path / "w.npy")


# ----------------------------------------------------------------------------- bad files
_GOOD = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    End Site
    {
      OFFSET 0 10 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.05
0 90 0 0 0 0 0 0 0
1 90 0 0 0 0 10 0 0
"""


def test_a_good_small_file_parses():
    crlf = parse_bvh(_GOOD.replace("\n", "\r\n").replace("  ", "\t"))      # Windows line ends and tabs
    m = parse_bvh(_GOOD)
    np.testing.assert_array_equal(crlf.values, m.values)
    assert m.joint_names == ("Hips", "Spine") and m.num_frames == 2 and m.values.shape == (2, 9)
    pos = m.world_positions()                                   # (2 frames, Hips + Spine + End Site, 3)
    np.testing.assert_allclose(pos[0], [[0, 90, 0], [0, 100, 0], [0, 110, 0]], atol=1e-9)
    a = np.deg2rad(10.0)                                        # frame 2: the spine turned 10 degrees about Z
    np.testing.assert_allclose(pos[1], [[1, 90, 0], [1, 100, 0], [1 - 10 * np.sin(a), 100 + 10 * np.cos(a), 0]],
                               atol=1e-9)


def test_root_motion_may_sit_on_the_hips_below_a_reference_root():
    text = _GOOD.replace("ROOT Hips\n{\n  OFFSET 0 0 0\n", "ROOT Reference\n{\n  OFFSET 0 0 0\n  CHANNELS 0\n"
                         "  JOINT Hips\n  {\n  OFFSET 0 0 0\n", 1).replace("MOTION", "}\nMOTION", 1)
    m = parse_bvh(text)
    assert m.joint_names == ("Reference", "Hips", "Spine")
    np.testing.assert_allclose(m.world_positions()[1, 1], [1.0, 90.0, 0.0])
    rotations_only = text.replace("CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation",
                                  "CHANNELS 3 Zrotation Yrotation Xrotation").replace("0 90 0 0", "0")
    with pytest.raises(BvhError, match="'Reference' has no position channels \\(no channels\\) nor do 'Hips', "
                                       "'Spine' below it: the file carries no root motion"):
        parse_bvh(rotations_only.replace("1 90 0 0", "0"))


def _variant(old: str, new: str, text: str = _GOOD) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


@pytest.mark.parametrize("text, line, message", [
    ("", None, "the file is empty"),
    (_GOOD[:_GOOD.index("    End Site")], 9, "the hierarchy is truncated: expected '}' closing joint 'Spine'"),
    (_GOOD[:_GOOD.index("1 90 0 0 0 0 10")], 19, "the file is truncated: 'Frames: 2' but it ends after 1 frame line(s)"),
    (_GOOD[:_GOOD.index("1 90 0 0 0 0 10") + 10], 20, "frame 2 has 5 values, but the hierarchy declares 9 channels (the line looks cut short"),
    (_variant("1 90 0 0 0 0 10 0 0", "1 90 0 0 0 0 10 0 0 7"), 20, "frame 2 has 10 values, but the hierarchy declares 9"),
    (_variant("1 90 0 0 0 0 10 0 0", "1 90 0 nan 0 0 10 0 0"), 20, "non-finite value nan (Hips Zrotation)"),
    (_variant("0 90 0 0 0 0 0 0 0", "0 90 0 0 0 0 inf 0 0"), 19, "non-finite value inf (Spine Zrotation)"),
    (_variant("0 90 0 0 0 0 0 0 0", "0 90 0 0 x 0 0 0 0"), 19, "value 'x' (Hips Yrotation) is not a number"),
    (_variant("CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation",
              "CHANNELS 3 Zrotation Yrotation Xrotation").replace("0 90 0 0", "0").replace("1 90 0 0", "0"),
     5, "the root joint 'Hips' has no position channels (Zrotation Yrotation Xrotation) nor does 'Spine' below it: "
        "the file carries no root motion"),
    (_variant("CHANNELS 3 Zrotation Yrotation Xrotation", "CHANNELS 3 Zrotation Yrotation"), 9,
     "CHANNELS of joint 'Spine' declares 3 channel(s) but lists 2"),
    (_variant("CHANNELS 3 Zrotation Yrotation Xrotation", "CHANNELS 3 Zrotation Yrotation Wrotation"), 9,
     "unknown channel 'Wrotation' on joint 'Spine'"),
    (_variant("Frames: 2", "Frames: 0"), 17, "the file has 0 frames; a motion needs at least one"),
    (_variant("Frame Time: 0.05", "Frame Time: 0"), 18, "the frame time must be a positive number of seconds, got 0"),
    (_variant("Frame Time: 0.05", "Frame Time: -0.1"), 18, "got -0.1"),
    (_variant("OFFSET 0 10 0", "OFFSET 0 nan 0"), 8, "OFFSET y of joint 'Spine' is nan"),
    (_variant("HIERARCHY", "HIERARCHI"), 1, "a BVH file starts with HIERARCHY, got 'HIERARCHI'"),
    (_GOOD[:_GOOD.index("MOTION")], 15, "no MOTION section"),
    (_variant("Frames: 2", "Frame: 2"), 17, "expected 'Frames: <count>'"),
])
def test_bad_files_name_the_problem_and_the_line(tmp_path, text, line, message):
    path = tmp_path / "bad.bvh"
    path.write_text(text)
    with pytest.raises(BvhError) as err:
        read_bvh(path)
    assert err.value.line == line, str(err.value)
    assert message in str(err.value)
    assert str(err.value).startswith(f"{path}, line {line}: " if line else f"{path}: ")


def test_unknown_rig_lists_missing_joints_and_the_rig(tmp_path):
    path = tmp_path / "two.bvh"
    path.write_text(_GOOD)
    with pytest.raises(RigError) as err:
        import_bvh(path)
    msg = str(err.value)
    assert "missing left_hip, right_hip" in msg and "the file's joints are Hips, Spine" in msg
    assert "--name-map" in msg


def test_shipped_test_files_import():
    """The small takes in tests/data/bvh (made by this file's writer) import to their recorded joints."""
    expected = np.load(DATA / "expected_joints.npy")
    for name in ("salad_export", "cmu", "mixamo", "smpl", "biped"):
        take = import_bvh(DATA / f"{name}.bvh")
        got = take.joints.astype(np.float64)
        if take.units == "fit":
            got = got * (np.median(_legs(expected)) / np.median(_legs(got)))
        got[..., 1] -= got[..., 1].min()
        err = np.linalg.norm(got - expected, axis=-1)
        assert np.median(err) < 0.002 and err.max() < 0.08, (name, np.median(err), err.max())


# ----------------------------------------------------------------------------- a real take (bvhtoolbox's MocapBank file)
MOCAPBANK = DATA / "mocapbank.bvh"


@pytest.fixture(scope="module")
def mocapbank():
    return read_bvh(MOCAPBANK), import_bvh(MOCAPBANK)


def test_a_real_take_keeps_its_own_skeleton_and_floor(mocapbank):
    """bvhtoolbox's MocapBank take (30 fps, cm; stands, kneels on the right knee, stands up): the import is the take
    itself, at 20 fps, frame for frame; the HumanML3D-retargeted copy is beside it, with its error."""
    motion, take = mocapbank
    assert (take.units, take.up, take.source_frames, take.num_frames) == ("cm", "y", 455, 303)
    assert take.source_fps == pytest.approx(30.0, rel=1e-4) and take.fps == 20.0
    # its own bone lengths: the thigh is the file's LeftHip -> LeftKnee offset, 0.49 m (HumanML3D's: 0.39 m)
    thigh_file = 0.01 * np.linalg.norm(motion.joints[motion.joint_names.index("LeftKnee")].offset)
    assert thigh_file == pytest.approx(0.488, abs=0.002)
    for side in ("left", "right"):
        thigh = np.linalg.norm(take.joints[:, J[f"{side}_knee"]] - take.joints[:, J[f"{side}_hip"]], axis=-1)
        assert np.abs(thigh - thigh_file).max() < 1e-3 if side == "left" else thigh.std() < 1e-4
    # frame for frame: every second 20-fps frame is every third file frame (the file's rig through the mapping),
    # only moved down by the clip's lowest joint (its floor: y = 0)
    src = take.rig.apply(motion.world_positions() * 0.01)                      # (455, 22, 3) metres, Y up
    src[..., 1] -= src[..., 1].min()
    assert np.linalg.norm(take.joints[::2] - src[::3][:152], axis=-1).max() < 1e-3
    # on its floor: the kneeling knee touches it (1.2 cm), the standing feet stand on it (0.6 cm)
    knees = take.joints[:, [J["left_knee"], J["right_knee"]], 1].min(1)
    feet = take.joints[:, [J["left_ankle"], J["right_ankle"], J["left_foot"], J["right_foot"]], 1].min(1)
    assert knees.min() < 0.02 and np.median(feet) < 0.01 and take.joints[..., 1].min() == 0.0
    # the retargeted copy (what the features hold): shorter thighs, the knee and the feet off the floor
    ret = take.retargeted
    assert ret.shape == take.joints.shape
    thigh = np.linalg.norm(ret[:, J["left_knee"]] - ret[:, J["left_hip"]], axis=-1)
    assert thigh == pytest.approx(get_skeleton("humanml3d").bone_lengths[J["left_knee"]], abs=1e-4)
    assert ret[:, [J["left_knee"], J["right_knee"]], 1].min() > 0.08            # measured 11.1 cm
    assert np.median(ret[:, [J["left_ankle"], J["right_ankle"], J["left_foot"], J["right_foot"]], 1].min(1)) > 0.04
    err = take.retarget_error                                                   # measured 9.4 cm mean, 22.9 max
    assert 8.0 < err.mean_cm < 11.0 and 20.0 < err.max_cm < 26.0, err
    rec = features_to_joints(take.features())
    assert rec.shape == (302, 22, 3) and np.abs(rec - ret[:-1]).max() < 1e-4


def test_take_in_the_features_frame(mocapbank):
    """``take_in_features_frame``: the take's own joints placed where the features put the retargeted copy, for
    errors against the take (salad invert), also for a crop starting later in the take."""
    from salad_core.bvh import take_in_features_frame
    from salad_core.eval.metrics import mpjpe

    _, take = mocapbank
    feats = take.features()
    for start, n in ((0, 120), (100, 80)):
        crop = feats[start:start + n]
        placed = take_in_features_frame(take.joints, crop, start)
        given = features_to_joints(crop).astype(np.float64)
        assert placed.shape == given.shape == (n, 22, 3)
        # the take's bones and shape, turned and moved only: pairwise joint distances per frame unchanged
        own = take.joints[start:start + n].astype(np.float64)
        d_own = np.linalg.norm(own[:, :, None] - own[:, None], axis=-1)
        np.testing.assert_allclose(np.linalg.norm(placed[:, :, None] - placed[:, None], axis=-1), d_own, atol=1e-5)
        np.testing.assert_allclose(placed[..., 1], own[..., 1], atol=1e-5)          # on its own floor
        # first roots together horizontally; the root-aligned distance is the retargeting's alone
        np.testing.assert_allclose(placed[0, 0, [0, 2]], given[0, 0, [0, 2]], atol=1e-5)
        assert mpjpe(given, placed) == pytest.approx(mpjpe(take.retargeted[start:start + n], _aligned(take.joints)
                                                           [start:start + n]), abs=2e-3)
    # on HumanML3D's own skeleton retargeting changes nothing: the take lands on the features' joints
    walk = rigid(corpus_joints()[:40])
    placed = take_in_features_frame(walk, joints_to_features(walk)[10:30], 10)
    assert np.abs(placed - features_to_joints(joints_to_features(walk)[10:30])).max() < 1e-3


def _aligned(joints):
    from salad_core.motion import process_joints

    return process_joints(joints, retarget=False).astype(np.float64)


def test_salads_own_bvh_round_trips_frame_for_frame(tmp_path, sample_features):
    """What salad writes (the pipeline's fit of clip 012314, 100 frames at 20 fps) comes back as 100 frames, each
    within a centimetre (the floor: the import puts the lowest joint on y = 0; everything else to float precision);
    also through ``salad import``, whose joints file is the take and whose messages agree on the counts."""
    from salad_core import cli
    from salad_core.recovery import recover_joints
    from salad_viz import export_bvh

    joints = np.asarray(recover_joints(sample_features[:100], "fit"), dtype=np.float64)
    path = export_bvh(joints, "humanml3d", tmp_path / "clip.bvh")
    take = import_bvh(path)
    assert take.source_frames == take.num_frames == 100 and take.rig.style == "smpl" and take.units == "m"
    floor = joints[..., 1].min()                                              # measured 0.8 cm
    err = np.linalg.norm(take.joints - joints, axis=-1)
    assert err.max() < 0.01 and floor < 0.01
    assert np.abs(take.joints - (joints - [0, floor, 0])).max() < 1e-5
    out = tmp_path / "imp"
    assert cli.main(["import", str(path), "--out", str(out), "--no-render"]) == 0
    np.testing.assert_allclose(np.load(out / "clip_joints.npy"), take.joints, atol=1e-6)
    assert np.load(out / "clip_features.npy").shape == (99, 263)


@pytest.mark.parametrize("frame_time, frames, expected", [
    ("0.050000", 100, 100), ("0.049999", 100, 100), ("0.050001", 100, 100), ("0.05", 1000, 1000),
    ("0.049999", 1000, 1000), ("0.033333", 91, 61), ("0.0333333", 91, 61), ("0.008333", 121, 21),
    ("0.025000", 81, 41), ("0.1", 11, 21),
])
def test_resampling_keeps_every_frame(frame_time, frames, expected):
    """A 20 fps file keeps its frames (also with a rounded Frame Time); other rates give every 20-fps frame
    of the take, the last one included where the rates divide."""
    rows = "\n".join(f"{t * 0.01:.4f} 90 0 0 0 {t % 7}" for t in range(frames))
    text = _GOOD.split("MOTION")[0] + f"MOTION\nFrames: {frames}\nFrame Time: {frame_time}\n" + rows + "\n"
    text = text.replace("CHANNELS 3 Zrotation Yrotation Xrotation", "CHANNELS 0")
    text = text.replace("CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation",
                        "CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation")
    from salad_core.bvh.convert import _resample

    motion = parse_bvh(text)
    pos = motion.world_positions()
    got = _resample(pos, motion.fps, 20.0)
    assert len(got) == expected
    # every output frame is the take at its time (x moves 1 cm per source frame); within the rounding of a
    # Frame Time (1e-4), a 20 fps take is a 20 fps take: its frames as they are
    ratio = 1.0 / 20.0 / float(frame_time)
    src_time = np.arange(expected) * (1.0 if abs(ratio - 1) <= 1e-4 else ratio)
    np.testing.assert_allclose(got[:, 0, 0], np.minimum(src_time, frames - 1) * 0.01, atol=2e-5)


def regenerate() -> None:
    """Write the small takes of tests/data/bvh: the first 13 frames of the stored corpus motion in
    this project's export and in each test rig (the rigid version for the rigs)."""
    from salad_viz import export_bvh

    joints = rigid(corpus_joints()[:13])
    np.save(DATA / "expected_joints.npy", joints.astype(np.float32))
    export_bvh(joints, "humanml3d", DATA / "salad_export.bvh")
    for style, (text, _) in rig_files(joints).items():
        (DATA / f"{style}.bvh").write_text(text)


if __name__ == "__main__" and "--regenerate" in sys.argv:
    regenerate()


# ----------------------------------------------------------------------------- salad invert MY_TAKE.bvh
@pytest.fixture(scope="module")
def tiny_weights(tmp_path_factory, make_tiny_pipeline):
    """A tiny randomly initialised pipeline folder (the motions are noise, the plumbing is real)."""
    return make_tiny_pipeline(seed=0).save_pretrained(tmp_path_factory.mktemp("weights"))


@pytest.fixture(scope="module")
def cmu_take(walk, tmp_path_factory):
    """A 40-frame CMU-style take at 120 fps in the CMU conversion's unit (a user's file)."""
    path = tmp_path_factory.mktemp("take") / "my_take.bvh"
    path.write_text(write_rig(*cmu_rig(_upsampled(walk[:41], 120)), scale=1 / CMU_UNIT, frame_time=1 / 120))
    return path


def test_cli_inverts_and_mirrors_a_bvh_take_with_the_shipped_weights(cmu_take, tmp_path, capsys, single_thread):
    """``salad invert my_take.bvh --mirror all`` end to end (shipped weights, 5 steps): a GIF, a BVH
    and npy files of the edited take, the reconstruction error printed and recorded."""
    from salad_core import cli

    out = tmp_path / "out"
    code = cli.main(["-q", "invert", str(cmu_take), "--prompt", "a person walks forward and stretches",
                     "--mirror", "all", "--steps", "5", "--out", str(out)])
    assert code == 0
    printed = capsys.readouterr().out
    assert "my_take.bvh: 241 frames at 120 fps -> 41 at 20 fps; units fit (detected)" in printed
    assert "rig cmu (detected)" in printed and "reconstruction MPJPE" in printed
    names = {p.name for p in out.iterdir()}
    assert names == {f"my_take_{b}{e}" for b in ("reconstruction", "edited")
                     for e in ("_features.npy", "_joints.npy", ".bvh")} | {
        "my_take_input_features.npy", "my_take_source_vs_edited.gif", "my_take_inversion.json"}
    report = json.loads((out / "my_take_inversion.json").read_text())
    assert report["input"]["kind"] == "bvh" and report["input"]["bvh"]["rig"] == "cmu"
    assert report["input"]["bvh"]["joints"]["left_hip"] == "LeftUpLeg"
    assert report["input_frames"] == 40 and report["frames"] == 40     # 41 joint frames -> 40 feature frames
    assert f"reconstruction MPJPE {report['errors']['mpjpe_cm']:.2f} cm" in printed
    assert 0 < report["errors"]["mpjpe_cm"] < 20
    # and against the take itself (its own skeleton), beside the retargeting's own share
    vs = report["errors_vs_take"]
    assert set(vs) == {"mpjpe_cm", "mpjpe_global_cm", "retargeting_mpjpe_cm", "retargeting_mpjpe_global_cm"}
    assert (f"against the take itself (its own bone lengths; the line above is against its copy retargeted to "
            f"humanml3d, which the model was given): reconstruction MPJPE {vs['mpjpe_cm']:.2f} cm root-aligned, "
            f"{vs['mpjpe_global_cm']:.2f} cm global") in printed
    assert 0 < vs["mpjpe_cm"] < 25 and 0 < vs["retargeting_mpjpe_cm"] < 5      # the take is scaled to HumanML3D's size
    print("vs take", vs, "vs retargeted", report["errors"])
    # the input features are those of the take; the edit differs from the reconstruction
    inp = np.load(out / "my_take_input_features.npy")
    np.testing.assert_allclose(inp, bvh_to_features(cmu_take), atol=1e-5)
    edited, rec = np.load(out / "my_take_edited_joints.npy"), np.load(out / "my_take_reconstruction_joints.npy")
    assert edited.shape == rec.shape == (40, 22, 3) and np.abs(edited - rec).max() > 0.05
    # the edited take's BVH reads back (this project's export) to the edited joints within a few cm
    back = bvh_to_joints(out / "my_take_edited.bvh")
    assert back.shape == edited.shape
    e = edited - edited[..., 1].min() * np.array([0, 1, 0])
    assert np.median(np.linalg.norm(back - e, axis=-1)) < 0.03
    import imageio.v3 as iio

    frames = iio.imread(out / "my_take_source_vs_edited.gif", index=None)
    assert frames.shape[0] == 20 and frames.shape[2] > frames.shape[1]    # two panels side by side
    assert frames.std() > 10


def test_cli_invert_reports_errors_against_the_take_and_its_retargeted_copy(tmp_path, capsys, single_thread):
    """``salad invert`` of the real MocapBank take (the kneel, 6-10 s; shipped weights, 5 steps): the errors against
    the retargeted copy the model was given, and against the take itself, whose thighs are 10 cm longer."""
    from salad_core import cli
    from salad_core.bvh import take_in_features_frame
    from salad_core.eval.metrics import mpjpe

    out = tmp_path / "out"
    assert cli.main(["-q", "invert", str(MOCAPBANK), "--prompt", "a person kneels down on one knee and stands up",
                     "--crop", "6:10", "--steps", "5", "--no-render", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    report = json.loads((out / "mocapbank_inversion.json").read_text())
    assert report["frames"] == report["input_frames"] == 80
    vs, errors = report["errors_vs_take"], report["errors"]
    assert f"reconstruction MPJPE {errors['mpjpe_cm']:.2f} cm root-aligned" in printed
    assert f"reconstruction MPJPE {vs['mpjpe_cm']:.2f} cm root-aligned, {vs['mpjpe_global_cm']:.2f} cm global" in printed
    # the retargeted input alone is that far from the take (the features' joints against the take's frames 120-199)
    take = import_bvh(MOCAPBANK)
    feats = np.load(out / "mocapbank_input_features.npy")
    placed = take_in_features_frame(take.joints, feats, 120)
    assert vs["retargeting_mpjpe_cm"] == pytest.approx(100 * mpjpe(features_to_joints(feats), placed), abs=1e-3)
    assert 6.0 < vs["retargeting_mpjpe_cm"] < 14.0                      # kneeling on 10 cm shorter thighs
    assert vs["mpjpe_cm"] > errors["mpjpe_cm"]
    print("mocapbank kneel: vs take", vs, "vs retargeted copy", errors)


@pytest.mark.parametrize("extra, name, message", [
    ([], "bad.bvh", "bad.bvh, line 20: frame 2 has 5 values, but the hierarchy declares 9 channels"),
    ([], "two.bvh", "missing left_hip, right_hip"),
    (["--up", "z"], "f.npy", "--up applies to .bvh files; f.npy is not one"),
    (["--crop", "3:1"], "take.bvh", "--crop takes START:STOP in seconds"),
    (["--crop", "60:"], "take.bvh", "--crop 60:: the motion lasts 2.00 s (40 frames at 20 fps)"),
    (["--units", "furlong"], "take.bvh", "units 'furlong' is not known"),
    (["--name-map", "nowhere.json"], "take.bvh", "name_map: file not found"),
])
def test_cli_bvh_errors_are_one_line(tmp_path, capsys, cmu_take, extra, name, message):
    from salad_core import cli

    (tmp_path / "bad.bvh").write_text(_GOOD[:_GOOD.index("1 90 0 0 0 0 10") + 10])
    (tmp_path / "two.bvh").write_text(_GOOD)
    (tmp_path / "take.bvh").write_text(cmu_take.read_text())
    np.save(tmp_path / "f.npy", np.zeros((40, 263), np.float32))
    code = cli.main(["-q", "invert", str(tmp_path / name), "--prompt", "a person walks", *extra,
                     "--weights", str(tmp_path / "nowhere"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and err.startswith("salad invert: error: ") and message in err, err


def test_cli_crop_and_joints_npy(tmp_path, capsys, tiny_weights, walk):
    """--crop picks seconds of a take; a joints .npy is converted like a take (tiny weights)."""
    from salad_core import cli

    np.save(tmp_path / "walk_joints.npy", walk.astype(np.float32))
    out = tmp_path / "o"
    assert cli.main(["-q", "invert", str(tmp_path / "walk_joints.npy"), "--prompt", "a person walks", "--steps", "2",
                     "--crop", "0.5:2.1", "--no-render", "--weights", str(tiny_weights), "--out", str(out)]) == 0
    report = json.loads((out / "walk_joints_inversion.json").read_text())
    assert report["input"] == {"kind": "joints", "crop": "0.5:2.1"} and report["input_frames"] == 32
    inp = np.load(out / "walk_joints_input_features.npy")
    np.testing.assert_allclose(inp, joints_to_features(walk)[10:42], atol=1e-5)


def test_cli_import_converts_a_take_for_the_other_commands(tmp_path, capsys, rigs, walk):
    from salad_core import cli

    path, _ = rigs["mixamo"]
    out = tmp_path / "takes"
    assert cli.main(["import", str(path), "--out", str(out), "--no-render"]) == 0
    printed = capsys.readouterr().out
    assert "rig mixamo (detected)" in printed and "left_collar     <- mixamorig:LeftShoulder" in printed
    feats = np.load(out / "mixamo_features.npy")
    np.testing.assert_allclose(feats, bvh_to_features(path), atol=1e-6)
    # the take's own joints first (its bone lengths, its floor), the HumanML3D-retargeted copy beside them
    take = import_bvh(path)
    np.testing.assert_allclose(np.load(out / "mixamo_joints.npy"), take.joints, atol=1e-6)
    np.testing.assert_allclose(np.load(out / "mixamo_joints.npy"), _resampled(_upsampled(walk, 30), 30, 20),
                               atol=1e-3)          # the 30 fps take back at 20 fps
    np.testing.assert_allclose(np.load(out / "mixamo_retargeted_joints.npy"), take.retargeted, atol=1e-6)
    assert feats.shape == (len(walk) - 1, 263)
    # the messages agree on the frame counts: 57 frames at 30 fps -> 57... (the summary), joints 57, features 56
    n = len(walk)
    assert f"-> {n} at 20 fps" in printed and f"\n{n} frames at 20 fps ({n / 20:.2f} s): take joints and " \
        f"retargeted joints {n} frames, features {n - 1} (one per step between frames)" in printed
    assert f"{take.retarget_error} from the take (per frame, root and heading aligned)" in printed
    # the converted features go anywhere a features .npy goes, e.g. salad export
    assert cli.main(["-q", "export", str(out / "mixamo_features.npy"), "--format", "bvh", "--out", str(out)]) == 0
    assert bvh_to_joints(out / "mixamo_features.bvh").shape == (len(walk) - 1, 22, 3)
    assert cli.main(["-q", "import", str(path), "--out", str(out), "--no-render"]) == 2     # refuses to overwrite
    assert "--force" in capsys.readouterr().err
