"""The BVH files salad writes, read by Blender's own importer (``bpy.ops.import_anim.bvh``).

Blender runs headless (``blender -b --factory-startup --python SCRIPT -- FILE.bvh OUT.json``): the script
imports the file with the importer's defaults that matter here (1 file unit = 1 Blender unit, forward -Z and
up Y turned into Blender's Z-up, frame 1 = the file's first frame, no frame-rate scaling) and dumps the world
position of every pose bone's head (= the BVH joint) at every frame, plus the axis conversion it applied,
which the test undoes. Skipped when ``blender`` is not on PATH (``scripts/setup.sh`` installs Debian's when
run as root).
"""
from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from salad_core.skeleton import get_skeleton
from salad_viz.export import export_bvh

SKEL = get_skeleton("humanml3d")
BLENDER = shutil.which("blender")
pytestmark = pytest.mark.skipif(BLENDER is None, reason="blender is not on PATH (scripts/setup.sh installs it as root)")

_DUMP = r'''
import builtins
import json
import sys

import bpy
from bpy_extras.io_utils import axis_conversion

bvh_path, out_path = sys.argv[sys.argv.index("--") + 1:][:2]
bpy.ops.wm.read_factory_settings(use_empty=True)
# Debian's Blender 3.4 runs on Python 3.11, where the importer's open(path, "rU") is an error ("invalid
# mode"); the importer itself is unchanged, only that mode letter is dropped
import io_anim_bvh.import_bvh as importer
importer.open = lambda file, mode="r", *a, **k: builtins.open(file, mode.replace("U", ""), *a, **k)
bpy.ops.import_anim.bvh(filepath=bvh_path, global_scale=1.0, axis_forward="-Z", axis_up="Y", rotate_mode="NATIVE",
                        frame_start=1, use_fps_scale=False, update_scene_fps=False, update_scene_duration=True)
scene = bpy.context.scene
arm = next(o for o in scene.objects if o.type == "ARMATURE")
start, end = (int(round(v)) for v in arm.animation_data.action.frame_range)
frames = []
for f in range(start, end + 1):
    scene.frame_set(f)
    ev = arm.evaluated_get(bpy.context.evaluated_depsgraph_get())
    frames.append([list(ev.matrix_world @ pb.head) for pb in ev.pose.bones])
json.dump({"names": [pb.name for pb in arm.pose.bones], "frames": frames, "first_frame": start,
           "axis_matrix": [list(r) for r in axis_conversion(from_forward="-Z", from_up="Y")],
           "version": bpy.app.version_string}, open(out_path, "w"))
'''


def blender_joints(bvh: Path, tmp_path: Path) -> tuple[np.ndarray, dict]:
    """Joints ``(N, 22, 3)`` (the file's axes and unit) as Blender's BVH importer poses them, and the dump."""
    script = tmp_path / "dump_bvh.py"
    script.write_text(_DUMP)
    out = tmp_path / f"{bvh.stem}_blender.json"
    run = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python", str(script),
                          "--", str(bvh), str(out)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0 and out.is_file(), run.stdout[-2000:] + run.stderr[-2000:]
    dump = json.loads(out.read_text())
    pos = np.asarray(dump["frames"], dtype=np.float64)                  # (N, bones, 3) Blender's axes
    conv = np.asarray(dump["axis_matrix"], dtype=np.float64)            # file axes -> Blender axes
    pos = pos @ conv                                                    # back to the file's axes (row vectors)
    order = [dump["names"].index(n) for n in SKEL.joint_names]
    return pos[:, order], dump


def _check(joints: np.ndarray, bvh: Path, tmp_path: Path, scale: float = 1.0) -> np.ndarray:
    got, dump = blender_joints(bvh, tmp_path)
    assert dump["first_frame"] == 1 and got.shape == joints.shape, (got.shape, joints.shape)
    err = np.linalg.norm(got / scale - joints, axis=-1)
    print(f"Blender {dump['version']}: {bvh.name} {100 * err.mean():.5f} cm mean, {100 * err.max():.5f} cm max")
    assert err.max() < 0.005                      # the bar: 0.5 cm; measured ~1e-6 m
    assert err.mean() < 1e-4
    return err


def test_blender_reads_the_joints_of_a_rigid_branch_motion(tmp_path):
    """Joints with the fit's properties (constant bones, rigid pelvis and chest; the root turns a full circle)."""
    from test_viz_export import rigid_branch_motion      # (tests/ is on sys.path, as for _doubles)

    joints = rigid_branch_motion(60)
    path = export_bvh(joints, SKEL, tmp_path / "rigid.bvh")
    assert path.exact
    _check(joints, path, tmp_path)
    # in centimetres (Blender reads 1 unit = 1 Blender unit): the same motion, 100 times larger
    path = export_bvh(joints, SKEL, tmp_path / "rigid_cm.bvh", scale=100.0)
    _check(joints, path, tmp_path, scale=100.0)


def test_blender_reads_the_fit_of_a_real_clip(tmp_path, sample_features):
    """HumanML3D clip 012314 recovered as the pipeline recovers joints (the fit), as ``salad export`` writes it."""
    from salad_core.recovery import DEFAULT_METHOD, recover_joints

    joints = np.asarray(recover_joints(sample_features[:120], DEFAULT_METHOD, SKEL), dtype=np.float64)
    path = export_bvh(joints, SKEL, tmp_path / "012314.bvh")
    err = _check(joints, path, tmp_path)
    # Blender and salad_core.bvh agree with what export_bvh measured
    assert err.max() <= path.max_error + 1e-5
