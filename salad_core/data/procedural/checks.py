"""Measurements that say whether motions are physically plausible and whether the ground-truth
annotations are right: bone lengths, floor contact, foot sliding, joint angles, and how much
each of the 7 body parts moves during an annotated phrase.

All functions take joints ``(N, J, 3)`` (Y up, metres, 20 fps) as in ``new_joints/<id>.npy``.

Part activity (m/s) is the mean speed of the part's fastest joint, each part measured in its own
reference frame so that it says what the part itself does:

* root: the pelvis in the world (speed) plus its yaw rate times 0.5 m (turning on the spot);
* legs and spine: joints relative to the pelvis, in the heading frame of the hips;
* arms and head: joints relative to spine3, in the chest frame (the collars), so that bending
  the trunk does not count as arm motion.

The part speeds live in :mod:`salad_core.part_activity` (shared with the attention measures) and
are re-exported here.
"""
from __future__ import annotations

import numpy as np

from ...part_activity import YAW_LEVER, heading_frames, part_activity, part_speeds
from ...skeleton import PART_NAMES, Skeleton, get_skeleton

__all__ = ["bone_length_error", "foot_sliding", "part_speeds", "part_activity", "joint_angles",
           "phrase_activity", "YAW_LEVER", "CONTACT_HEIGHTS"]

#: Height (m) below which an (ankle, toe) joint counts as touching the floor (clip floored to 0).
CONTACT_HEIGHTS = (0.08, 0.035)


def _idx(sk: Skeleton, name: str) -> int:
    return sk.joint_names.index(name)


def bone_length_error(joints: np.ndarray, skeleton: str | Skeleton = "humanml3d") -> dict[str, float]:
    """Largest per-bone std over time and largest deviation from the target lengths (m)."""
    sk = get_skeleton(skeleton)
    par = np.asarray(sk.parents[1:])
    lengths = np.linalg.norm(joints[:, 1:] - joints[:, par], axis=-1)          # (N, J-1)
    out = {"max_std": float(lengths.std(0).max())}
    if sk.bone_lengths is not None:
        out["max_error"] = float(np.abs(lengths - np.asarray(sk.bone_lengths[1:])).max())
    return out


def foot_sliding(joints: np.ndarray, skeleton: str | Skeleton = "humanml3d",
                 heights: tuple[float, float] = CONTACT_HEIGHTS) -> dict[str, float]:
    """Horizontal speed of the feet while they touch the floor.

    A foot joint (ankle, toe of each foot) touches the floor in a frame when it is lower than
    ``heights`` (ankle, toe) above the clip's lowest joint. Returns the summed speed (m/s) and
    the number of such joint-frames (so clips can be pooled), their mean and 95th percentile.
    """
    sk = get_skeleton(skeleton)
    floor = joints[..., 1].min()
    speeds = []
    for j, h in zip(sk.contact_joints, heights * 2):
        y = joints[:-1, j, 1] - floor
        v = np.linalg.norm(np.diff(joints[:, j][:, [0, 2]], axis=0), axis=1) * sk.fps
        speeds.append(v[y < h])
    v = np.concatenate(speeds) if speeds else np.zeros(0)
    return {"sum": float(v.sum()), "count": int(v.size),
            "mean": float(v.mean()) if v.size else 0.0,
            "p95": float(np.percentile(v, 95)) if v.size else 0.0}


def joint_angles(joints: np.ndarray, skeleton: str | Skeleton = "humanml3d") -> dict[str, np.ndarray]:
    """Knee and elbow flexion (0 = straight), ankle angle (shin to foot) and knee bend sense.

    Returns arrays ``(N, 2)`` (left, right) in degrees, and ``knee_bend``: the sine of the knee
    flexion signed by its sense about the body's left axis (negative = the knee bends the wrong
    way, i.e. hyperextends).
    """
    sk = get_skeleton(skeleton)
    j = {n: _idx(sk, n) for n in sk.joint_names}

    def flex(a, b, c):
        u, v = joints[:, b] - joints[:, a], joints[:, c] - joints[:, b]
        cos = (u * v).sum(-1) / np.maximum(np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1), 1e-9)
        return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))

    heading = heading_frames(joints, sk)
    out = {"knee": [], "elbow": [], "ankle": [], "knee_bend": []}
    for side in ("left", "right"):
        hip, knee, ankle, toe = (j[f"{side}_{n}"] for n in ("hip", "knee", "ankle", "foot"))
        out["knee"].append(flex(hip, knee, ankle))
        out["elbow"].append(flex(j[f"{side}_shoulder"], j[f"{side}_elbow"], j[f"{side}_wrist"]))
        shin = joints[:, knee] - joints[:, ankle]
        foot = joints[:, toe] - joints[:, ankle]
        cos = (shin * foot).sum(-1) / np.maximum(np.linalg.norm(shin, axis=-1) * np.linalg.norm(foot, axis=-1), 1e-9)
        out["ankle"].append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
        # knee flexion turns the shin backwards about the body's left axis, never the other way
        thigh = joints[:, knee] - joints[:, hip]
        shin_dn = joints[:, ankle] - joints[:, knee]
        turn = np.cross(thigh, shin_dn) / np.maximum(
            np.linalg.norm(thigh, axis=-1, keepdims=True) * np.linalg.norm(shin_dn, axis=-1, keepdims=True), 1e-9)
        out["knee_bend"].append((turn * heading[:, 0]).sum(-1))
    return {k: np.stack(v, 1) for k, v in out.items()}


def phrase_activity(speeds: np.ndarray, phrases: list[dict], secondary: list[tuple[str, ...]]
                    ) -> list[dict[str, float]]:
    """Compare, for each phrase of one caption, the activity of its parts with the other parts.

    Parameters
    ----------
    speeds : ``(N-1, P)`` from :func:`part_speeds`
    phrases : the caption's annotated phrases (``parts``, ``frames``)
    secondary : per phrase, the parts its action moves incidentally (e.g. arm swing of walking)

    Returns
    -------
    per phrase: ``driven`` (lowest activity among its parts), ``idle`` (highest activity among
    the parts that no phrase active in the interval drives or moves) and ``others`` (highest
    among all parts not driven by an active phrase), with their ratios (inf when the other set
    is empty).
    """
    out = []
    for k, ph in enumerate(phrases):
        f0, f1 = ph["frames"]
        act = part_activity(None, (f0, f1), speeds=speeds)
        driven = [PART_NAMES.index(p) for p in ph["parts"]]
        busy_primary, busy_any = set(driven), set(driven) | {PART_NAMES.index(p) for p in secondary[k]}
        for q, other in enumerate(phrases):
            if q == k:
                continue
            g0, g1 = other["frames"]
            if min(f1, g1) - max(f0, g0) > 0:
                busy_primary |= {PART_NAMES.index(p) for p in other["parts"]}
                busy_any |= {PART_NAMES.index(p) for p in other["parts"]} | {PART_NAMES.index(p) for p in secondary[q]}
        idle = [p for p in range(len(PART_NAMES)) if p not in busy_any]
        others = [p for p in range(len(PART_NAMES)) if p not in busy_primary]
        d = float(act[driven].min()) if driven else 0.0
        i = float(act[idle].max()) if idle else 0.0
        o = float(act[others].max()) if others else 0.0
        out.append({"driven": d, "idle": i, "others": o,
                    "ratio_idle": d / i if i > 0 else float("inf"),
                    "ratio_others": d / o if o > 0 else float("inf")})
    return out
