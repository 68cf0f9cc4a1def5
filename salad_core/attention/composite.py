"""Feature-space composite of an edit: what the edit keeps is taken from the source's decoded features.

Why. :class:`~salad_core.attention.mirror_take.MirrorTake` and :class:`~salad_core.attention.inpaint.Inpaint`
keep the latents of the untouched parts (or frames) exactly the source branch's, but the VAE decoder's skeletal and
temporal convolutions mix neighbouring tokens: the mirrored legs' tokens move the decoded torso and arms (2-4 cm on
the held-out kicks and spins), a regenerated span moves the decoded frames next to it, and a span that turns
differently from the source turns every kept frame after it (the features store root *velocities*).
``lab/scripts/editing/measure_mirror_real.py`` and ``measure_inpaint.py`` measure it.

What. After decoding both branches, the edited motion's features are re-assembled per frame and joint
(:func:`composite_features`) from a weight ``w (N, J)`` in ``[0, 1]`` (1: the edit's, 0: the source's):

* every feature column of joint ``j`` (its root-relative position, 6D rotation, velocity, foot contact; for the
  root its heading and linear velocity and its height) is ``(1 - w) * source + w * edit``;
* **re-joining**: a regenerated limb whose parent is kept is moved rigidly, per frame, so that it hangs from the
  source's parent joint instead of the edit's (its positions shifted by the difference, its velocities by that
  shift's change), so a mirrored leg starts at the source's pelvis height and a waving arm at the source's
  shoulder girdle;
* **root** (frame spans): with ``root="source"`` the root velocities of a regenerated span that has kept frames after
  it are corrected by a smooth (Hann-window) offset so that the span ends at the source's heading and position;
  every kept frame then keeps its global position and facing (a span that turns keeps the turn inside the span and
  turns back before the kept frames; ``root="edit"`` lets the kept frames follow the span's turn instead;
  ``root="auto"`` decides per span: the kept frames follow a span that turned on its own, more than
  :data:`TURN_FOLLOW_DEG` and that much beyond what the source turned over the same frames (a middle span asked to
  turn keeps its turn), and keep their place after any other);
* the seams of a frame span are cross-faded over ``fade`` frames inside the span (``w`` ramps
  ``d / (fade + 1)`` with the distance ``d`` to the kept frame), kept frames are exactly the source's;
* **seam smoothing** (``smooth > 0``, :func:`smooth_seam_features`): a linear cross-fade of two different motions
  still kinks where the ramp starts, and the regenerated frames next to a seam may move abruptly; per feature
  column, the regenerated frames within ``smooth_window`` frames of an inner seam are replaced by the least-squares
  compromise between the cross-faded values and a small jerk (third difference of positions and rotations, second
  of velocities), the kept frames held fixed as the boundary, so the span continues the kept motion smoothly.

Kept joints then decode to the source's own joints (up to the pipeline's skeleton fit), whatever the decoder does
with the edited tokens. :func:`composite_output` applies it to an :class:`~salad_core.pipeline.EditOutput`; the
edited latents are left as sampled (``settings["composite"]`` records what was composited).
"""
from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from salad_core.skeleton import PART_NAMES, get_skeleton

__all__ = ["ROOT_MODES", "TURN_FOLLOW_DEG", "regenerated_runs", "followed_turns", "part_joint_weights",
           "frame_weights", "seams", "smooth_columns", "smooth_seam_features",
           "frame_jerk", "seam_jerk", "seam_jerk_ratio", "composite_features", "composite_output", "composite_specs"]

#: How the root of a regenerated frame span is handled (see the module docstring).
ROOT_MODES = ("source", "edit", "auto")

#: ``root="auto"``: a regenerated run that turns by more than this (degrees; an eighth of a turn, more than a gait's
#: heading wobble) and by more than this beyond what the source turned over the same frames turned on purpose, and
#: the kept frames after it follow it; otherwise they keep the source's place and facing.
TURN_FOLLOW_DEG = 45.0


def part_joint_weights(parts: Sequence[str], skeleton="humanml3d") -> np.ndarray:
    """``(J,)`` float: 1 on the joints drawn in body ``parts`` (names of :data:`PART_NAMES`), 0 elsewhere."""
    sk = get_skeleton(skeleton)
    unknown = [p for p in parts if p not in PART_NAMES]
    if unknown:
        raise ValueError(f"unknown body parts {unknown}; the parts are {', '.join(PART_NAMES)}")
    return np.array([1.0 if PART_NAMES[p] in parts else 0.0 for p in sk.joint_to_part])


def frame_weights(num_frames: int, span: tuple[int, int] | None, fade: int) -> np.ndarray:
    """``(N,)`` float: 1 inside the motion-frame span ``[s, e)`` (None: every frame), 0 outside, ramping
    ``d / (fade + 1)`` over the ``fade`` frames of the span next to a kept frame."""
    n = int(num_frames)
    if span is None:
        return np.ones(n)
    s, e = max(0, int(span[0])), min(n, int(span[1]))
    w = np.zeros(n)
    for f in range(s, e):
        d = min(f - s + 1 if s > 0 else np.inf, e - f if e < n else np.inf)
        w[f] = min(1.0, d / (fade + 1))
    return w


def seams(regenerated: np.ndarray) -> list[int]:
    """Inner seams of a per-frame ``(N,)`` bool: the frames ``b`` (``0 < b < N``) where kept and regenerated
    frames meet (frame ``b - 1`` is one, frame ``b`` the other)."""
    r = np.asarray(regenerated, bool)
    return [int(b) for b in np.flatnonzero(r[1:] != r[:-1]) + 1]


def _difference_matrix(n: int, order: int) -> np.ndarray:
    """``(n - order, n)``: row ``r`` takes the ``order``-th forward difference of frames ``r .. r + order``."""
    d = np.eye(n)
    for _ in range(order):
        d = d[1:] - d[:-1]
    return d


def smooth_columns(y: np.ndarray, free: np.ndarray, order: int, strength: float) -> np.ndarray:
    """Least-squares smoothing of columns ``y (N, C)`` on the ``free`` frames ``(N,)`` bool, the others fixed:
    per column ``argmin_x ||x_F - y_F||^2 + strength * ||D x||^2`` over the free frames ``F``, with ``D`` the
    ``order``-th difference over every window of ``order + 1`` frames that holds a free frame. Returns
    ``(N, C)``: the fixed frames are ``y``'s exactly."""
    y = np.asarray(y, np.float64)
    free = np.asarray(free, bool)
    out = y.copy()
    if not free.any() or strength <= 0 or len(y) <= order:
        return out
    d = _difference_matrix(len(y), order)
    d = d[np.abs(d[:, free]).sum(1) > 0]                       # the differences that touch a free frame
    df, dc = d[:, free], d[:, ~free]
    a = np.eye(int(free.sum())) + strength * df.T @ df
    rhs = y[free] - strength * df.T @ (dc @ y[~free])
    out[free] = np.linalg.solve(a, rhs)
    return out


def _column_orders(sk) -> list[tuple[slice, int]]:
    """Feature columns smoothed by :func:`smooth_seam_features` and the difference order that is the jerk of
    each: the third of positions and rotations (root height, ``ric``, ``rot``), the second of velocities (root
    turn and step, ``local_vel``); the foot contacts are left alone."""
    fs = sk.feature_slices
    return [(fs["root_rot_vel"], 2), (fs["root_lin_vel"], 2), (fs["root_y"], 3), (fs["ric"], 3), (fs["rot"], 3),
            (fs["local_vel"], 2)]


def smooth_seam_features(features: np.ndarray, weights: np.ndarray, window: int, strength: float,
                         skeleton="humanml3d") -> np.ndarray:
    """The composited features with the regenerated frames next to each inner seam smoothed (jerk-penalised).

    Per feature column of each regenerated joint, the frames that joint regenerates within ``window`` frames of
    an inner seam (:func:`seams` of the frames where any joint is regenerated) are the least-squares
    :func:`smooth_columns` of the cross-faded values, penalising the column's jerk (see :func:`_column_orders`)
    with weight ``strength``; every other frame, and every kept frame, is left exactly as it is, so the
    regenerated frames continue the kept ones without a kink.

    Parameters
    ----------
    features : ndarray ``(N, D)``
        Composited (de-normalised) features.
    weights : ndarray ``(N, J)``
        The composite's weights (> 0: the joint is regenerated at that frame).
    window : int
        Regenerated frames next to a seam that may move.
    strength : float
        Weight of the jerk penalty (0: unchanged).

    Returns
    -------
    ndarray ``(N, D)`` float64.
    """
    sk = get_skeleton(skeleton)
    f = np.asarray(features, np.float64).copy()
    w = np.asarray(weights, np.float64)
    if w.shape != (len(f), sk.num_joints):
        raise ValueError(f"weights must be (N, J) = {(len(f), sk.num_joints)}, got {w.shape}")
    regen = w > 0
    cuts = seams(regen.any(1))
    if window <= 0 or strength <= 0 or not cuts:
        return f
    idx = np.arange(len(f))
    near = np.zeros(len(f), bool)
    for b in cuts:
        near |= np.abs(idx - b + 0.5) < window           # the window frames on either side of the seam b - 1 | b
    col_joint = np.zeros(sk.feature_dim, int)
    for j, cols in enumerate(sk.joint_feature_index):
        col_joint[list(cols)] = j
    for sl, order in _column_orders(sk):
        cols = np.arange(sl.start, sl.stop)
        groups: dict[bytes, list[int]] = {}
        for c in cols:
            free = near & regen[:, col_joint[c]]
            if free.any():
                groups.setdefault(free.tobytes(), []).append(int(c))
        for key, cs in groups.items():
            free = np.frombuffer(key, bool)
            f[:, cs] = smooth_columns(f[:, cs], free, order, strength)
    return f


def _column_weights(w: np.ndarray, sk) -> np.ndarray:
    """Per-joint weights ``(N, J)`` -> per-column weights ``(N, D)`` by the VAE's joint split."""
    cols = np.zeros((w.shape[0], sk.feature_dim))
    for j, idx in enumerate(sk.joint_feature_index):
        cols[:, list(idx)] = w[:, j:j + 1]
    return cols


def _attachment(sk, regenerated: np.ndarray) -> dict[int, int]:
    """For each regenerated joint, its nearest kept ancestor (the joint its limb hangs from); joints whose chain to
    the root is regenerated throughout are left out."""
    out = {}
    for j in range(sk.num_joints):
        if not regenerated[j]:
            continue
        a = sk.parents[j]
        while a >= 0 and regenerated[a]:
            a = sk.parents[a]
        if a >= 0:
            out[j] = a
    return out


def _ric(f: np.ndarray, sk, j: int) -> np.ndarray:
    """Root-relative (heading-frame) position ``(N, 3)`` of joint ``j``: the root's is ``(0, height, 0)``."""
    if j == 0:
        out = np.zeros((len(f), 3))
        out[:, 1] = f[:, sk.feature_slices["root_y"]][:, 0]
        return out
    r = sk.feature_slices["ric"].start + 3 * (j - 1)
    return f[:, r:r + 3]


def _rejoin(edited: np.ndarray, source: np.ndarray, w: np.ndarray, sk) -> np.ndarray:
    """The edited features with each regenerated limb shifted onto the source's attachment joint (per frame, by the
    weight of the frames where the attachment is kept)."""
    out = edited.copy()
    kept_somewhere = (w < 1).any(0)
    # joint j hangs from its nearest ancestor a that is never regenerated (a frame span regenerates every joint:
    # nothing to re-join there)
    att = _attachment(sk, (w > 0).any(0))
    ric0, vel0 = sk.feature_slices["ric"].start, sk.feature_slices["local_vel"].start
    for j, a in att.items():
        if not kept_somewhere[a]:
            continue
        delta = _ric(source, sk, a) - _ric(edited, sk, a)
        out[:, ric0 + 3 * (j - 1): ric0 + 3 * j] += delta
        if len(out) > 1:
            out[:-1, vel0 + 3 * j: vel0 + 3 * j + 3] += delta[1:] - delta[:-1]
    return out


def _root_state(f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Integrated half-angle heading ``(N,)`` and root x, z ``(N, 2)`` of features (HumanML3D's recovery)."""
    half = np.concatenate([[0.0], np.cumsum(f[:-1, 0])])
    c, s = np.cos(2 * half), np.sin(2 * half)
    vx, vz = np.concatenate([[0.0], f[:-1, 1]]), np.concatenate([[0.0], f[:-1, 2]])
    # world step = inverse heading rotation of the local step (a y rotation by the full angle 2 * half)
    wx = c * vx - s * vz
    wz = s * vx + c * vz
    return half, np.stack([np.cumsum(wx), np.cumsum(wz)], -1)


def _world_to_local(half: np.ndarray, wx: np.ndarray, wz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c, s = np.cos(2 * half), np.sin(2 * half)
    return c * wx + s * wz, -s * wx + c * wz


def _turn_deg(f: np.ndarray, s: int, e: int) -> float:
    """Heading change (degrees, positive to the left) of features ``f`` from frame ``s`` to frame ``e``."""
    half, _ = _root_state(f)
    return float(np.degrees(2 * (half[e] - half[s])))


def regenerated_runs(w_root: np.ndarray) -> list[tuple[int, int]]:
    """``[(s, e), ...]``: the runs of frames with ``w_root > 0`` (``(N,)``) that have a kept frame after them."""
    regen = np.asarray(w_root) > 0
    n, runs, t = len(regen), [], 0
    while t < n:
        if regen[t]:
            s = t
            while t < n and regen[t]:
                t += 1
            if t < n:                     # a kept frame follows
                runs.append((s, t))
        else:
            t += 1
    return runs


def followed_turns(out: np.ndarray, source: np.ndarray, w_root: np.ndarray,
                   limit: float = TURN_FOLLOW_DEG) -> list[tuple[int, int]]:
    """The regenerated runs (:func:`regenerated_runs`) of the composite ``out`` ``(N, D)`` that turned on their own:
    their heading change exceeds ``limit`` degrees and differs from ``source``'s over the same frames by more than
    ``limit``: the spans ``root="auto"`` lets the kept frames after them follow. (A span that does not turn where
    the source did, a jump in place of a walk's turn, keeps the rest of the take in place.)"""
    runs = []
    for s, e in regenerated_runs(w_root):
        turn = _turn_deg(out, s, e)
        if abs(turn) > limit and abs(turn - _turn_deg(source, s, e)) > limit:
            runs.append((s, e))
    return runs


def _fix_root(out: np.ndarray, source: np.ndarray, w_root: np.ndarray,
              skip: Sequence[tuple[int, int]] = ()) -> np.ndarray:
    """Correct the root velocities of each regenerated run of frames that has kept frames after it, so that the
    first kept frame after it has the source's heading and position (a Hann-window offset over the run's rows).
    Runs in ``skip`` are left as they are, and so are the kept frames after them (they follow the run); the runs
    after a skipped one are corrected towards the source's path turned and moved with it."""
    f = out.copy()
    src_half, src_xz = _root_state(source)
    for s, e in regenerated_runs(w_root):
        if (s, e) in skip:
            # the source's path from here on, turned and moved to where the followed run ends
            half, xz = _root_state(f)
            rot = 2 * (half[e] - src_half[e])
            c, sn = np.cos(rot), np.sin(rot)
            rel = src_xz - src_xz[e]
            # _root_state's world steps turn by +2*half as (c*vx - s*vz, s*vx + c*vz)
            src_xz = xz[e] + np.stack([c * rel[:, 0] - sn * rel[:, 1], sn * rel[:, 0] + c * rel[:, 1]], -1)
            src_half = src_half + (half[e] - src_half[e])
            continue
        # rows s-1 .. e-1 move the root into frames s .. e; the offsets go on rows s .. e-1 (frame s keeps its place)
        rows = np.arange(s, e)
        if len(rows) == 0:
            continue
        win = np.sin(np.pi * (np.arange(len(rows)) + 0.5) / len(rows)) ** 2
        half, _ = _root_state(f)
        f[rows, 0] += (src_half[e] - half[e]) * win / win.sum()
        half, xz = _root_state(f)
        d = src_xz[e] - xz[e]
        # world offsets per row, turned into the heading frame of the frame each row moves into
        wx, wz = d[0] * win / win.sum(), d[1] * win / win.sum()
        lx, lz = _world_to_local(half[rows + 1], wx, wz)
        f[rows, 1] += lx
        f[rows, 2] += lz
    return f


def composite_features(source: np.ndarray, edited: np.ndarray, weights: np.ndarray, skeleton="humanml3d", *,
                       rejoin: bool = True, root: str = "source", smooth: float = 0.0,
                       smooth_window: int = 0) -> np.ndarray:
    """The edited motion re-assembled from the source's features where ``weights`` is 0.

    Parameters
    ----------
    source, edited : ndarray ``(N, D)``
        De-normalised features of the source (its decoding) and of the edit, the same length.
    weights : ndarray ``(N, J)`` or ``(J,)``
        Per frame and joint, 1 where the edit's features are used, 0 where the source's are, in between a blend.
    rejoin : bool
        Hang each regenerated limb from the source's kept parent joint (see the module docstring).
    root : ``"source"``, ``"edit"`` or ``"auto"``
        ``"source"``: a regenerated span followed by kept frames ends at the source's root heading and position;
        ``"edit"``: the kept frames follow the span; ``"auto"``: they follow a span that turned more than
        :data:`TURN_FOLLOW_DEG` beyond the source (:func:`followed_turns`), else as ``"source"``.
    smooth, smooth_window : float, int
        Jerk penalty and window (regenerated frames next to each inner seam) of :func:`smooth_seam_features`,
        applied after the cross-fade and before the root correction (0: off).

    Returns
    -------
    ndarray ``(N, D)``, the dtype of ``edited``.
    """
    return _composite_features(source, edited, weights, skeleton, rejoin=rejoin, root=root, smooth=smooth,
                               smooth_window=smooth_window)[0]


def _composite_features(source: np.ndarray, edited: np.ndarray, weights: np.ndarray, skeleton="humanml3d", *,
                        rejoin: bool = True, root: str = "source", smooth: float = 0.0,
                        smooth_window: int = 0) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """:func:`composite_features` and the regenerated runs whose turn the kept frames follow
    (:func:`followed_turns`; ``root="auto"`` only, else empty)."""
    sk = get_skeleton(skeleton)
    if root not in ROOT_MODES:
        raise ValueError(f"root={root!r}; allowed: {ROOT_MODES}")
    src, ed = np.asarray(source, np.float64), np.asarray(edited, np.float64)
    if src.shape != ed.shape or src.ndim != 2 or src.shape[1] != sk.feature_dim:
        raise ValueError(f"source and edited must both be (N, {sk.feature_dim}); got {src.shape} and {ed.shape}")
    w = np.asarray(weights, np.float64)
    if w.ndim == 1:
        w = np.broadcast_to(w, (len(src), sk.num_joints))
    if w.shape != (len(src), sk.num_joints):
        raise ValueError(f"weights must be (N, J) = {(len(src), sk.num_joints)} or (J,), got {w.shape}")
    w = np.clip(w, 0.0, 1.0)
    if rejoin:
        ed = _rejoin(ed, src, w, sk)
    cw = _column_weights(w, sk)
    out = (1.0 - cw) * src + cw * ed
    if smooth > 0 and smooth_window > 0:
        out = smooth_seam_features(out, w, smooth_window, smooth, sk)
    if root != "edit" and (w[:, 0] < 1).any() and (w[:, 0] > 0).any():
        skip = followed_turns(out, src, w[:, 0]) if root == "auto" else []
        out = _fix_root(out, src, w[:, 0], skip)
    else:
        skip = []
    return out.astype(np.asarray(edited).dtype, copy=False), skip


def composite_specs(edits) -> list:
    """The edits that ask for a composite (``composite=True`` and a :meth:`joint_weights` method)."""
    return [e for e in edits if getattr(e, "composite", False) and hasattr(e, "joint_weights")]


def _joints(joints: np.ndarray, name: str) -> np.ndarray:
    j = np.asarray(joints, np.float64)
    if j.ndim != 3 or j.shape[-1] != 3:
        raise ValueError(f"{name} must be joint positions (N, J, 3), got shape {j.shape}")
    return j


def frame_jerk(joints: np.ndarray) -> np.ndarray:
    """``(N - 3,)`` jerk of joint positions ``(N, J, 3)``: the norm of each joint's third difference, mean over
    joints (per frame^3: multiply by ``fps ** 3`` for m/s^3 when the positions are metres); entry ``i`` spans frames
    ``i .. i + 3``. Fewer than 4 frames: empty."""
    j = _joints(joints, "joints")
    if len(j) < 4:
        return np.zeros(0)
    return np.linalg.norm(j[3:] - 3 * j[2:-1] + 3 * j[1:-2] - j[:-3], axis=-1).mean(-1)


def seam_jerk(joints: np.ndarray, cuts: Sequence[int]) -> float:
    """The largest :func:`frame_jerk` of the joints ``(N, J, 3)`` (per frame^3) in the third differences that touch a
    frame within 4 of an inner seam of ``cuts`` (:func:`seams`); 0 without one."""
    d3 = frame_jerk(joints)
    if not len(d3) or not cuts:
        return 0.0
    idx = sorted({i for b in cuts for i in range(max(0, b - 5), min(len(d3), b + 3))})
    return float(d3[idx].max()) if idx else 0.0


#: Floor of the source's jerk percentile in :func:`seam_jerk_ratio` (per frame^3; a source that never moves).
_MIN_SOURCE_JERK = 1e-12


def seam_jerk_ratio(source: np.ndarray, edited: np.ndarray, cuts: Sequence[int], percentile: float = 95.0) -> float:
    """How sharp an edit's seams are against the source's own motion: the edit's :func:`seam_jerk` at the inner seams
    ``cuts`` over the ``percentile``-th percentile of the source's :func:`frame_jerk` (1: a seam as jerky as the
    source's 95th-percentile frame). ``source`` and ``edited``: joint positions ``(N, J, 3)`` (the same joints; the
    lengths may differ). No seam: 0.

    Raises
    ------
    ValueError
        Joints of the wrong shape, a source of fewer than 4 frames, a percentile outside [0, 100].
    """
    src = _joints(source, "source")
    if len(src) < 4:
        raise ValueError(f"the source has {len(src)} frames: its jerk needs at least 4")
    if not 0 <= percentile <= 100:
        raise ValueError(f"percentile={percentile!r} must lie in [0, 100]")
    ref = float(np.percentile(frame_jerk(src), percentile))
    return seam_jerk(_joints(edited, "edited"), cuts) / max(ref, _MIN_SOURCE_JERK)


def _smoothing(specs) -> tuple[float, int]:
    """The seam smoothing ``(strength, window)`` the edits ask for (the largest of each; ``(0, 0)``: none)."""
    smooth = max((float(getattr(spec, "smooth", 0.0)) for spec in specs), default=0.0)
    window = max((int(getattr(spec, "smooth_window", 0)) for spec in specs), default=0)
    return smooth, window


def composite_output(pipe, output, edits=None):
    """``output`` (an :class:`~salad_core.pipeline.EditOutput`) with each edited motion composited
    (:func:`composite_features`) by the product of the weights of the edits that ask for it (a copy; ``output`` is not
    changed). The joints are recovered again with the pipeline's recovery; the latents are left as sampled.
    ``settings["composite"]`` names the edits. No such edit, or nothing kept: ``output`` itself.

    With seam smoothing (an edit's ``smooth > 0``), the smoothed composite is kept only where the recovered joints'
    :func:`seam_jerk` is not larger than without it (the pipeline's skeleton fit turns each fixed-length bone
    towards the smoothed positions, and where a limb swings fast next to a seam the smoothing shortens its bone
    vectors so that the fitted bone can turn abruptly); ``settings["composite"]["seam_smoothing"]`` records per
    motion ``"smoothed"``, ``"plain"`` (smoothing would have raised the seam's jerk) or None (no seam or no
    smoothing)."""
    from salad_core.recovery import recover_joints

    specs = composite_specs(output.edits if edits is None else edits)
    if not specs:
        return output
    sk = pipe.skeleton
    src, ed = output.source, output.edited
    feats = np.array(ed.features, copy=True)
    joints = list(ed.joints)
    changed = False
    smooth, window = _smoothing(specs)
    smoothed: list[str | None] = []
    followed: list[list[list[int]]] = []
    for b, n in enumerate(ed.lengths):
        w = np.ones((n, sk.num_joints))
        roots = set()
        for spec in specs:
            w = w * spec.joint_weights(n, sk)
            roots.add(getattr(spec, "root", "source"))
        if (w >= 1).all():
            smoothed.append(None)
            followed.append([])
            continue
        args = (np.asarray(src.features[b, :n]), np.asarray(ed.features[b, :n]), w, sk)
        root = "edit" if "edit" in roots else "auto" if "auto" in roots else "source"
        f, turns = _composite_features(*args, root=root)
        j = recover_joints(f, pipe.recovery, sk)
        cuts = seams((w > 0).any(1))
        state = None
        if smooth > 0 and window > 0 and cuts:
            fs, turns_s = _composite_features(*args, root=root, smooth=smooth, smooth_window=window)
            js = recover_joints(fs, pipe.recovery, sk)
            state = "plain"
            if seam_jerk(js, cuts) <= seam_jerk(j, cuts):
                f, j, turns, state = fs, js, turns_s, "smoothed"
        smoothed.append(state)
        followed.append([[s, e] for s, e in turns])
        feats[b, :n] = f
        joints[b] = j.astype(np.float32)
        changed = True
    if not changed:          # every weight 1 (MirrorTake("all"), Inpaint(parts="all") ...): nothing is kept
        return output
    record = {"edits": [type(s).__name__ for s in specs]}
    if any(getattr(s, "root", "source") == "auto" for s in specs):
        record["followed_turns"] = followed      # per motion: the spans whose turn the kept frames follow
    if smooth > 0:
        record["seam_smoothing"] = smoothed
    settings = dict(ed.settings)
    settings["composite"] = record
    composited = dataclasses.replace(ed, features=feats, joints=joints, settings=settings)
    out_settings = dict(output.settings)
    out_settings["composite"] = record
    return dataclasses.replace(output, edited=composited, settings=out_settings)
