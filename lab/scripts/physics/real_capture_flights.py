#!/usr/bin/env python
"""What the physics benchmark's flight measure finds in real motion capture, segment by segment.

The benchmark's real-capture row (``salad_core.eval.physics_prompts.real_capture_row``: HumanML3D 012314 and
pybullet's DeepMimic clips) reports a flight fit (the median over flight segments of the pelvis's fitted vertical
acceleration) that generators are compared against. This probe lists every flight segment of every clip: its
frames, its fitted acceleration, how high the lowest foot joint gets above the contact level during it
(``clearance_cm``: a flight whose feet never rise more than a few centimetres is a detection, not a flight) and each
foot joint's own resting height above the level (the 5th percentile of its height; a converted rig whose toe joint
rests above the benchmark's 3.5 cm toe threshold turns every heel raise into "flight"). Beside it, the same
segments found with each foot joint measured from its own resting height (``--per-joint``), a candidate repair.

    python lab/scripts/physics/real_capture_flights.py [--no-deepmimic] [--json OUT]

Needs pybullet for the DeepMimic clips (the ``deepmimic`` extra); evaluation data only: nothing is tuned on it.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from salad_core.eval import physics as ph
from salad_core.eval.physics_prompts import real_capture_clips
from salad_core.skeleton import get_skeleton


def segments(flight: np.ndarray, min_frames: int) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` of the runs of True in ``flight (N,)`` at least ``min_frames`` long."""
    f = np.concatenate([[False], np.asarray(flight, bool), [False]])
    edges = np.flatnonzero(f[1:] != f[:-1])
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2]) if b - a >= min_frames]


def per_joint_flight(joints: np.ndarray, sk, config: ph.PhysicsConfig) -> np.ndarray:
    """``(N,)`` bool: no foot joint within its threshold of *its own* resting height (the ``contact_percentile``
    percentile of that joint's height) -- the benchmark's contact rule with one level per foot joint."""
    cj = list(sk.contact_joints)
    h = joints[:, cj, 1]
    rest = np.percentile(h, config.contact_percentile, axis=0)
    limit = np.asarray(config.contact_heights * 2)
    return ~((h - rest) < limit).any(-1)


def fit_accel(joints: np.ndarray, a: int, b: int, fps: float) -> float:
    """The pelvis's fitted vertical acceleration (m/s^2) over frames ``a:b`` (as the benchmark fits it)."""
    t = np.arange(b - a) / fps
    return float(2.0 * np.polyfit(t, joints[a:b, 0, 1], 2)[0])


def clip_flights(joints: np.ndarray, sk, config: ph.PhysicsConfig = ph.PhysicsConfig()) -> dict:
    """One clip's flights under the benchmark's rule and under :func:`per_joint_flight`."""
    fps = float(sk.fps)
    level = ph.contact_level(joints, sk, config)
    cj = list(sk.contact_joints)
    low = joints[:, cj, 1].min(-1) - level
    rest = np.percentile(joints[:, cj, 1], config.contact_percentile, axis=0) - level

    def rows(flight):
        return [{"frames": [a, b], "accel_ms2": fit_accel(joints, a, b, fps),
                 "clearance_cm": float(100 * low[a:b].max())} for a, b in segments(flight, config.flight_min_frames)]

    return {"frames": len(joints), "rest_height_cm": [round(float(100 * r), 1) for r in rest],
            "benchmark": rows(ph.flight_frames(joints, sk, config)), "per_joint": rows(per_joint_flight(joints, sk, config))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--no-deepmimic", action="store_true", help="HumanML3D 012314 alone")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    sk = get_skeleton("humanml3d")
    clips, name = real_capture_clips(False if args.no_deepmimic else None)
    print(name)
    out = {}
    for clip, joints in clips.items():
        res = out[clip] = clip_flights(np.asarray(joints, np.float64), sk)
        print(f"{clip:32s} {res['frames']:4d} frames, foot joints rest at {res['rest_height_cm']} cm (L ankle, L toe, "
              "R ankle, R toe)")
        for kind in ("benchmark", "per_joint"):
            for s in res[kind]:
                print(f"    {kind:9s} frames {s['frames'][0]:3d}-{s['frames'][1]:3d}  fit {s['accel_ms2']:7.2f} m/s^2  "
                      f"lowest foot up to {s['clearance_cm']:5.1f} cm")
    clip_rows = list(out.values())
    for kind in ("benchmark", "per_joint"):
        fits = [s["accel_ms2"] for r in clip_rows for s in r[kind]]
        med = float(np.median(fits)) if fits else float("nan")
        print(f"{kind}: {len(fits)} segments, median fit {med:.2f} m/s^2")
        out[f"median_{kind}"] = med
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"clips_name": name, **out}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
