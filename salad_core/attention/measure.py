"""Numbers that say whether attention and edits do what they claim (pure functions of arrays).

Used by ``lab/scripts/editing/measure_editing.py`` and by the tests that need trained weights:

* :func:`localisation`: the share of a phrase's attention on its annotated body parts and frames,
  against the share a uniform map would put there (chance);
* :func:`left_right_ratio`: left/right activity of the legs and arms (mirroring should flip it);
* :func:`mirror_closeness`: how close an edited motion is to the mirror image of its source;
* :func:`root_path_difference`: root trajectory and timing agreement of two motions (word swap);
* :func:`wrist_height`: how high the wrists go (re-weighting "high").

Joints are ``(N, J, 3)`` (Y up, metres, the skeleton's fps); attention maps ``(P, N')``.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from salad_core.part_activity import part_speeds
from salad_core.motion import mirror_joints
from salad_core.skeleton import PART_NAMES, Skeleton, get_skeleton

__all__ = ["localisation", "left_right_ratio", "mirror_closeness", "root_path_difference", "wrist_height",
           "part_activity_change", "spearman"]


def localisation(word_map: np.ndarray, parts: Sequence[str], frames: tuple[int, int],
                 unit_length: int | None = None) -> dict[str, float]:
    """Share of a phrase's attention on its annotated parts and frames, and chance.

    Parameters
    ----------
    word_map : array ``(P, N')``
        The phrase's summed cross-attention (:meth:`AttentionMaps.word_map`).
    parts : sequence of str
        Annotated body parts (names from :data:`salad_core.skeleton.PART_NAMES`).
    frames : (f0, f1)
        Annotated motion frames ``[f0, f1)``; latent frame ``t`` covers ``unit_length`` frames.

    Returns
    -------
    dict
        ``share`` (on parts x frames), ``chance`` (their fraction of the cells), ``lift`` = share /
        chance, and the same for parts alone (``part_share``, ``part_chance``) and frames alone.
    """
    m = np.asarray(word_map, dtype=np.float64)
    if m.ndim != 2 or m.shape[0] != len(PART_NAMES):
        raise ValueError(f"word_map must be (P={len(PART_NAMES)}, N'), got shape {m.shape}")
    unknown = [p for p in parts if p not in PART_NAMES]
    if unknown or not parts:
        raise ValueError(f"parts {list(parts)} must be a non-empty list of {PART_NAMES}")
    unit = unit_length or get_skeleton().unit_length
    n = m.shape[1]
    t0 = min(int(frames[0]) // unit, n - 1)
    t1 = min(max(int(math.ceil(int(frames[1]) / unit)), t0 + 1), n)
    rows = [PART_NAMES.index(p) for p in parts]
    total = m.sum()
    if total <= 0:
        raise ValueError("the attention map has no mass")
    share = m[rows, t0:t1].sum() / total
    chance = len(rows) * (t1 - t0) / m.size
    part_share, part_chance = m[rows].sum() / total, len(rows) / m.shape[0]
    frame_share, frame_chance = m[:, t0:t1].sum() / total, (t1 - t0) / n
    return {"share": float(share), "chance": float(chance), "lift": float(share / chance),
            "part_share": float(part_share), "part_chance": float(part_chance),
            "frame_share": float(frame_share), "frame_chance": float(frame_chance)}


def _side_pairs() -> dict[str, tuple[int, int]]:
    return {"legs": (PART_NAMES.index("left leg"), PART_NAMES.index("right leg")),
            "arms": (PART_NAMES.index("left arm"), PART_NAMES.index("right arm"))}


def left_right_ratio(joints: np.ndarray, skeleton: str | Skeleton = "humanml3d") -> dict[str, float]:
    """Mean speed of the left limb over the right one, for the legs and the arms (>1: left busier)."""
    speeds = part_speeds(np.asarray(joints, dtype=np.float64), skeleton).mean(0)
    out = {}
    for name, (left, right) in _side_pairs().items():
        out[name] = float((speeds[left] + 1e-6) / (speeds[right] + 1e-6))
    return out


def mirror_closeness(source: np.ndarray, edited: np.ndarray, parts: str = "all",
                     skeleton: str | Skeleton = "humanml3d") -> dict[str, float]:
    """Root-relative joint error of ``edited`` to the mirror image of ``source`` and to ``source``
    itself, over the joints of the mirrored parts (``legs``, ``arms`` or ``all``). A mirroring edit
    should be closer to the mirror: ``ratio = to_mirror / to_source < 1``."""
    sk = get_skeleton(skeleton)
    groups = {"legs": ("left leg", "right leg"), "arms": ("left arm", "right arm")}
    names = groups.get(parts, groups["legs"] + groups["arms"])
    ids = [j for j, p in enumerate(sk.joint_to_part) if PART_NAMES[p] in names]
    a, b = np.asarray(source, np.float64), np.asarray(edited, np.float64)
    n = min(len(a), len(b))
    a, b = a[:n] - a[:n, :1], b[:n] - b[:n, :1]
    mirrored = mirror_joints(a, sk)
    to_mirror = float(np.linalg.norm(b[:, ids] - mirrored[:, ids], axis=-1).mean())
    to_source = float(np.linalg.norm(b[:, ids] - a[:, ids], axis=-1).mean())
    return {"to_mirror": to_mirror, "to_source": to_source, "ratio": to_mirror / max(to_source, 1e-9)}


def root_path_difference(a: np.ndarray, b: np.ndarray, skeleton: str | Skeleton = "humanml3d") -> dict[str, float]:
    """Root (pelvis) XZ path RMSE in metres and the correlation of the root speed profiles
    (timing) of two motions over their common frames."""
    sk = get_skeleton(skeleton)
    n = min(len(a), len(b))
    pa, pb = np.asarray(a, np.float64)[:n, 0, [0, 2]], np.asarray(b, np.float64)[:n, 0, [0, 2]]
    rmse = float(np.sqrt(((pa - pb) ** 2).sum(-1).mean()))
    va = np.linalg.norm(np.diff(pa, axis=0), axis=-1) * sk.fps
    vb = np.linalg.norm(np.diff(pb, axis=0), axis=-1) * sk.fps
    corr = float(np.corrcoef(va, vb)[0, 1]) if va.std() > 1e-9 and vb.std() > 1e-9 else float("nan")
    return {"path_rmse": rmse, "speed_corr": corr, "distance_a": float(np.linalg.norm(pa[-1] - pa[0])),
            "distance_b": float(np.linalg.norm(pb[-1] - pb[0]))}


def part_activity_change(a: np.ndarray, b: np.ndarray, parts: Sequence[str],
                         skeleton: str | Skeleton = "humanml3d") -> float:
    """Mean absolute change (m/s) of the per-frame speeds of ``parts`` between two motions."""
    n = min(len(a), len(b))
    sa = part_speeds(np.asarray(a, np.float64)[:n], skeleton)
    sb = part_speeds(np.asarray(b, np.float64)[:n], skeleton)
    idx = [PART_NAMES.index(p) for p in parts]
    return float(np.abs(sa[:, idx] - sb[:, idx]).mean())


def wrist_height(joints: np.ndarray, side: str = "both", skeleton: str | Skeleton = "humanml3d",
                 percentile: float = 90.0) -> float:
    """The ``percentile`` of the wrist height above the clip's floor (lowest joint), metres."""
    sk = get_skeleton(skeleton)
    names = {"left": ("left_wrist",), "right": ("right_wrist",), "both": ("left_wrist", "right_wrist")}
    if side not in names:
        raise ValueError(f"side={side!r}; allowed: {sorted(names)}")
    j = np.asarray(joints, np.float64)
    floor = j[..., 1].min()
    ids = [sk.joint_names.index(n) for n in names[side]]
    return float(np.percentile(j[:, ids, 1].max(-1) - floor, percentile))


def spearman(x: Sequence[float], y: Sequence[float], min_length: int = 2) -> float:
    """Spearman rank correlation of two equal-length 1-D samples (ranks by ``scipy.stats.rankdata``,
    ties averaged); NaN when either sample is constant. A sample shorter than ``min_length`` is a
    ``ValueError`` (a correlation of two points is always +-1)."""
    from scipy.stats import rankdata

    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    if x.shape != y.shape or x.ndim != 1 or len(x) < min_length:
        raise ValueError(f"spearman needs two 1-D samples of equal length >= {min_length}, "
                         f"got {x.shape} and {y.shape}")
    rx, ry = rankdata(x), rankdata(y)
    if rx.std() == 0 or ry.std() == 0:
        return float("nan")
    return float(np.corrcoef(rx, ry)[0, 1])
