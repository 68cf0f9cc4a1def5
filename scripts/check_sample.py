#!/usr/bin/env python
"""Check salad's HumanML3D feature maths against a reference clip and print the figures.

Usage::

    python scripts/check_sample.py                       # tests/data/humanml3d_sample, clip 012314
    python scripts/check_sample.py /data/HumanML3D --id 000021 --repeats 50

The folder must have the HumanML3D layout (``new_joint_vecs/<id>.npy``, ``new_joints/<id>.npy``).
Prints, per feature slice, max/mean |error| for

- features -> joints: ``features_to_joints`` (recover_from_ric) and ``features_to_joints_rot``
  against ``new_joints`` (metres);
- joints -> features: ``joints_to_features(new_joints)`` against ``new_joint_vecs`` on the T-2
  overlapping rows (``new_joints`` lacks the clip's last frame, which changes the smoothed heading
  near the end), and again on the full clip with the last frame recovered from the features;
- ``mirror_features`` against ``joints_to_features(mirror_joints(.))``;

then the foot sliding of the clip (mean horizontal speed of the contact joints while the contact
label is 1) and the time per clip of ``joints_to_features``.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from salad_core.motion import (
    features_to_joints,
    features_to_joints_rot,
    joints_to_features,
    mirror_features,
    mirror_joints,
    recover_root,
)
from salad_core.quaternion import qinv, qrot
from salad_core.skeleton import get_skeleton

DEFAULT_DIR = Path(__file__).resolve().parents[1] / "tests" / "data" / "humanml3d_sample"
SLICES = ("root_rot_vel", "root_lin_vel", "root_y", "ric", "rot", "local_vel", "contacts")


def slice_errors(a: np.ndarray, b: np.ndarray, sk) -> str:
    rows = []
    for name in SLICES:
        d = np.abs(a[:, sk.feature_slices[name]].astype(np.float64) - b[:, sk.feature_slices[name]])
        rows.append(f"    {name:13s} max {d.max():.2e}  mean {d.mean():.2e}")
    return "\n".join(rows)


def full_clip(features: np.ndarray, joints: np.ndarray, sk) -> np.ndarray:
    """All T frames: ``new_joints`` plus the last frame from the final row's local velocity."""
    heading, _ = recover_root(features.astype(np.float64), sk)
    lv = features[-1, sk.feature_slices["local_vel"]].reshape(sk.num_joints, 3)
    return np.concatenate([joints, (joints[-1] + qrot(qinv(heading[-1]), lv))[None]], axis=0)


def foot_sliding(joints: np.ndarray, contacts: np.ndarray, sk) -> tuple[float, dict[str, float]]:
    """Mean horizontal speed (units/s) of each contact joint over the frames labelled in contact."""
    n = min(len(joints) - 1, len(contacts))
    per_joint = {}
    speeds = []
    for k, j in enumerate(sk.contact_joints):
        step = np.linalg.norm(joints[1:n + 1, j][:, [0, 2]] - joints[:n, j][:, [0, 2]], axis=-1) * sk.fps
        on = contacts[:n, k] > 0.5
        per_joint[sk.joint_names[j]] = float(step[on].mean()) if on.any() else float("nan")
        speeds.append(step[on])
    allv = np.concatenate(speeds)
    return (float(allv.mean()) if allv.size else float("nan")), per_joint


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("path", nargs="?", default=str(DEFAULT_DIR), help="HumanML3D-layout folder")
    ap.add_argument("--id", default=None, help="clip id (default: 012314 if present, else the first)")
    ap.add_argument("--skeleton", default="humanml3d")
    ap.add_argument("--repeats", type=int, default=20, help="timing repeats")
    args = ap.parse_args(argv)

    sk = get_skeleton(args.skeleton)
    root = Path(args.path)
    vec_dir, jnt_dir = root / "new_joint_vecs", root / "new_joints"
    if not vec_dir.is_dir() or not jnt_dir.is_dir():
        print(f"error: {root} must contain new_joint_vecs/ and new_joints/", file=sys.stderr)
        return 2
    clip = args.id
    if clip is None:
        clip = "012314" if (vec_dir / "012314.npy").exists() else sorted(vec_dir.glob("*.npy"))[0].stem
    feats = np.load(vec_dir / f"{clip}.npy")
    joints = np.load(jnt_dir / f"{clip}.npy")
    print(f"clip {clip}: features {feats.shape}, joints {joints.shape}, skeleton {sk.name}")

    print("\nfeatures -> joints (|error| in joint coordinates)")
    for name, fn in (("features_to_joints (ric)", features_to_joints), ("features_to_joints_rot", features_to_joints_rot)):
        if fn is features_to_joints_rot and sk.bone_lengths is None:
            print(f"  {name:26s} skipped: skeleton {sk.name!r} has no target bone lengths")
            continue
        d = np.abs(fn(feats, sk).astype(np.float64) - joints)
        print(f"  {name:26s} max {d.max():.2e}  mean {d.mean():.2e}")

    out = joints_to_features(joints, sk)
    print(f"\njoints -> features: joints_to_features(new_joints), {len(out)} overlapping rows")
    print(slice_errors(out, feats[:len(out)], sk))
    cut = len(out) - 40
    if cut > 0:
        print(f"  rows 0..{cut - 1} only (>= 40 frames = 2 sigma of the heading smoothing from the end)")
        print(slice_errors(out[:cut], feats[:cut], sk))
    out_full = joints_to_features(full_clip(feats, joints, sk), sk)
    print(f"\njoints -> features on the full clip (last frame recovered from the features), {len(out_full)} rows")
    print(slice_errors(out_full, feats, sk))

    print("\nmirror_features(f) vs joints_to_features(mirror_joints(j))")
    for retarget in (False, True):
        a = mirror_features(joints_to_features(joints, sk, retarget=retarget), sk)
        b = joints_to_features(mirror_joints(joints, sk), sk, retarget=retarget)
        print(f"  retarget={retarget}")
        print(slice_errors(a, b, sk))

    contacts = feats[:, sk.feature_slices["contacts"]]
    total, per_joint = foot_sliding(joints, contacts, sk)
    print(f"\nfoot sliding (mean horizontal speed while in contact, units/s at {sk.fps:g} fps): {total:.4f}")
    for name, v in per_joint.items():
        print(f"    {name:12s} {v:.4f}")
    print("  contact ratio per channel: " + ", ".join(f"{v:.3f}" for v in contacts.mean(0)))

    times = []
    for _ in range(max(1, args.repeats)):
        t0 = time.perf_counter()
        joints_to_features(joints, sk)
        times.append(time.perf_counter() - t0)
    print(f"\njoints_to_features: median {np.median(times) * 1e3:.2f} ms, best {min(times) * 1e3:.2f} ms "
          f"per {len(joints)}-frame clip ({args.repeats} runs)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
