"""EVALUATION ONLY: why real motion capture reconstructs worse than the procedural sets (issue 21).

Usage::

    python lab/scripts/vae/diagnose_vae_real.py [--vae DIR] [--corpus CORPUS] [--general GENERAL] [--limit 60]
                                        [--bank-clips 1000] [--bank-stride 3] [--json OUT.json]

Loads the VAE and the clips as ``lab/scripts/vae/measure_vae_real.py`` does (imported, not copied) and prints:

1. **where the error sits**: root-aligned error per joint (22) and per body part (the 7 latent parts,
   ``skeleton.joint_to_part``; the root part is the pelvis, 0 after alignment), and the error split
   into local pose and root channels: root-aligned MPJPE of the reconstruction with the clip's own
   root channels put back (``pose only``) and of the clip with only the reconstructed root channels
   (``root only``), beside ``measure_vae_real``'s ``ric`` error;
2. **the rig geometry**: angles between bones that are rigid or nearly so in each source (pelvis to
   hips, the spine, collars, head), per set -- the rigid relations a converter fixes once for all;
3. **coverage**: per frame, the distance (cm, mean over the 22 joints) of the root-relative,
   heading-aligned pose (``ric`` with the root height removed) to its nearest neighbour in a
   subsample of the corpus and general *training* splits, its rank correlation with the frame's
   reconstruction error, the error binned by it, and the farthest real frames (clip, frame, joints);
   held-out procedural test frames are the control;
4. **dynamics**: per-frame error against pose speed and root speed, and whole clips replayed at half
   and double speed (joints resampled linearly, features re-extracted);
5. **other checks**: each clip encoded in 40-frame windows (the training window) and 64-frame windows
   instead of whole; mirrored clips; and the DeepMimic clips per clip.

Sets: ``hml`` (HumanML3D 012314), ``dm`` (the DeepMimic clips on the humanoid's own torso,
``measure_vae_real --deepmimic-rig deepmimic``: the conversion this diagnosis found wanting; the converter now
re-poses them on HumanML3D's torso by default, :mod:`salad_core.retarget`),
``corpus`` and ``general`` (the procedural test splits), and counterfactual re-riggings (:func:`salad_core.retarget.rerig`)
that keep every limb's bone direction per frame and swap only the rigid torso geometry (pelvis to
hips and spine, chest to collars, shoulders and neck, the head's rest direction): ``dm_smpl``
(DeepMimic on the SMPL / procedural rig), ``corpus_dm`` and ``general_dm`` (procedural clips on the
DeepMimic converter's rig), and the controls ``hml_smpl`` and ``general_smpl`` (rebuilt on their own
rig: what the rebuild alone changes).

The real clips (012314 and DeepMimic) are evaluation data: nothing here trains or tunes anything on
them. The DeepMimic rig's rest geometry is read from the converter itself
(:func:`salad_core.data.deepmimic.humanoid_rest_directions`), the SMPL rig from the procedural body model.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import measure_vae_real as mvr  # noqa: E402

from salad_core.attention.measure import spearman as _spearman  # noqa: E402
from salad_core.retarget import (SEGMENTS, _unit, bone_directions, kabsch, rerig,  # noqa: E402,F401
                                 smpl_rest_directions, swing)
from salad_core.skeleton import get_skeleton  # noqa: E402

SK = get_skeleton("humanml3d")
J = SK.num_joints
IX = {n: i for i, n in enumerate(SK.joint_names)}
RUNS = Path.home() / "salad-runs" / "v3"

# ============================================================================ pure functions
def pose_descriptor(feats: np.ndarray) -> np.ndarray:
    """``(N, 22, 3)`` root-relative, heading-aligned joint positions of features ``(N, 263)``: the
    ``ric`` block (already relative to the root's x/z and turned to the heading) with the root height
    subtracted from y, and the root itself at the origin."""
    f = np.asarray(feats, dtype=np.float32)
    ric = f[:, SK.feature_slices["ric"]].reshape(len(f), J - 1, 3).copy()
    ric[..., 1] -= f[:, 3:4]
    return np.concatenate([np.zeros((len(f), 1, 3), np.float32), ric], axis=1)


def per_joint_error(pred_joints: np.ndarray, gt_joints: np.ndarray) -> np.ndarray:
    """Root-aligned error ``(N, J)`` (same unit as the joints) of every joint of every pose."""
    p = np.asarray(pred_joints, dtype=np.float64)
    g = np.asarray(gt_joints, dtype=np.float64)
    return np.linalg.norm((p - p[..., :1, :]) - (g - g[..., :1, :]), axis=-1)


def part_means(joint_values: np.ndarray, joint_to_part=SK.joint_to_part,
               part_names=SK.part_names) -> dict[str, float]:
    """Mean of a per-joint quantity ``(..., J)`` over each body part's joints (and all leading axes)."""
    v = np.asarray(joint_values, dtype=np.float64).reshape(-1, len(joint_to_part))
    part_of = np.asarray(joint_to_part)
    return {name: float(v[:, part_of == k].mean()) for k, name in enumerate(part_names) if (part_of == k).any()}


def nearest_neighbours(query: np.ndarray, bank: np.ndarray, k: int = 32, chunk: int = 256):
    """Nearest pose of ``bank`` to every pose of ``query`` under the mean per-joint distance.

    Parameters
    ----------
    query, bank : array ``(Q, J, 3)``, ``(B, J, 3)``
    k : int
        Candidates per query taken by Euclidean distance of the flattened poses (``torch.cdist``,
        chunked); the mean joint distance then picks among them (exact when ``k >= B``; checked with
        k = 32 against all 6,000 poses of a bank for 3,549 DeepMimic and general-test frames: the same
        neighbour for 98.5 % of them, distances 0.04 % too large on average, 13 % at worst).
    chunk : int
        Queries per ``cdist`` call (memory ``chunk * B`` floats).

    Returns
    -------
    (dist ``(Q,)``, index ``(Q,)``, per_joint ``(Q, J)``)
        Mean joint distance to the neighbour, its index in ``bank``, and each joint's distance to it.
    """
    import torch

    q = torch.as_tensor(np.asarray(query, np.float32))
    b = torch.as_tensor(np.asarray(bank, np.float32))
    if q.ndim != 3 or b.ndim != 3 or q.shape[1:] != b.shape[1:]:
        raise ValueError(f"query {tuple(q.shape)} and bank {tuple(b.shape)} must be (Q, J, 3) and (B, J, 3)")
    k = min(int(k), len(b))
    flat_b = b.reshape(len(b), -1)
    dist, index, per_joint = [], [], []
    for s in range(0, len(q), chunk):
        qc = q[s:s + chunk]
        cand = torch.cdist(qc.reshape(len(qc), -1), flat_b).topk(k, largest=False).indices    # (C, k)
        pj = (b[cand] - qc[:, None]).norm(dim=-1)                                              # (C, k, J)
        best = pj.mean(-1).argmin(-1)
        rows = torch.arange(len(qc))
        dist.append(pj[rows, best].mean(-1))
        index.append(cand[rows, best])
        per_joint.append(pj[rows, best])
    return torch.cat(dist).numpy(), torch.cat(index).numpy(), torch.cat(per_joint).numpy()


def spearman(a, b) -> float:
    """Spearman rank correlation of two 1-D samples of at least 3 values (:func:`salad_core.attention.measure.spearman`)."""
    return _spearman(a, b, min_length=3)


def partial_spearman(x, y, z) -> float:
    """Rank correlation of ``x`` and ``y`` with ``z`` held fixed: the correlation of the residuals of
    their ranks after a least-squares line on ``z``'s ranks."""
    from scipy.stats import rankdata

    rx, ry, rz = (rankdata(np.asarray(v, np.float64)) for v in (x, y, z))
    a = np.stack([np.ones_like(rz), rz], 1)
    ex = rx - a @ np.linalg.lstsq(a, rx, rcond=None)[0]
    ey = ry - a @ np.linalg.lstsq(a, ry, rcond=None)[0]
    if ex.std() == 0 or ey.std() == 0:
        return float("nan")
    return float(np.corrcoef(ex, ey)[0, 1])


def binned(x, y, edges) -> list[tuple[float, float, int, float]]:
    """``(lo, hi, count, mean y)`` for every bin ``lo <= x < hi`` of consecutive ``edges`` (NaN mean if empty)."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = (x >= lo) & (x < hi)
        out.append((float(lo), float(hi), int(sel.sum()), float(y[sel].mean()) if sel.any() else float("nan")))
    return out


def frame_speed(joints: np.ndarray, fps: float = SK.fps) -> np.ndarray:
    """Mean joint speed per frame ``(N,)`` (unit of the joints per second; central differences)."""
    j = np.asarray(joints, dtype=np.float64)
    if len(j) < 2:
        return np.zeros(len(j))
    return np.linalg.norm(np.gradient(j, axis=0), axis=-1).mean(-1) * fps


def resample_joints(joints: np.ndarray, speed: float) -> np.ndarray:
    """Replay a motion ``speed`` times as fast: ``(N, J, 3)`` -> ``(floor((N-1)/speed)+1, J, 3)`` by linear
    interpolation (``speed`` 0.5 = slow motion, 2 = double speed)."""
    j = np.asarray(joints, dtype=np.float64)
    if not speed > 0:
        raise ValueError(f"speed must be positive, got {speed}")
    t = np.arange(0.0, len(j) - 1 + 1e-9, float(speed))
    k = np.minimum(np.floor(t).astype(int), len(j) - 2)
    f = (t - k)[:, None, None]
    return j[k] * (1.0 - f) + j[k + 1] * f


def swap_columns(base: np.ndarray, donor: np.ndarray, cols: slice) -> np.ndarray:
    """``base`` with the columns ``cols`` taken from ``donor``."""
    out = np.array(base, copy=True)
    out[..., cols] = np.asarray(donor)[..., cols]
    return out


def deepmimic_rest_directions() -> np.ndarray:
    """Rest bone directions ``(J, 3)`` of DeepMimic's humanoid as the converter maps it (needs pybullet)."""
    from salad_core.data import deepmimic

    with mvr._quiet_stdout():
        return deepmimic.humanoid_rest_directions()


def rig_angles(joints: np.ndarray) -> dict[str, np.ndarray]:
    """Angles (degrees, per frame) between bones that a rig holds rigid or nearly so."""
    j = np.asarray(joints, dtype=np.float64)

    def ang(a, b):
        return np.degrees(np.arccos(np.clip((_unit(a) * _unit(b)).sum(-1), -1.0, 1.0)))

    def bone(c):
        return j[:, IX[c]] - j[:, SK.parents[IX[c]]]
    across = j[:, IX["left_hip"]] - j[:, IX["right_hip"]]
    return {"hip below hip line": ang(bone("left_hip"), across),
            "hip vs pelvis-spine1": ang(bone("left_hip"), bone("spine1")),
            "spine1-spine2 bend": ang(bone("spine2"), bone("spine1")),
            "spine2-spine3 bend": ang(bone("spine3"), bone("spine2")),
            "neck vs spine3": ang(bone("neck"), bone("spine3")),
            "collar vs spine3": ang(bone("left_collar"), bone("spine3")),
            "head vs neck": ang(bone("head"), bone("neck"))}


# ============================================================================ measurements
def reconstruct(vae, mean, std, feats: np.ndarray, window: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(clip, reconstruction)`` raw features of one clip cropped as ``measure_vae_real`` crops it; with
    ``window``, encoded and decoded in consecutive windows of that many frames (the last one shorter)."""
    from salad_core.eval.reconstruction import reconstruct_features

    unit = int(vae.config.downsample)
    f = mvr._crop(np.asarray(feats, dtype=np.float32), unit)
    if window is None:
        return f, reconstruct_features(vae, mean, std, f[None], [len(f)])[0]
    rec = np.zeros_like(f)
    for s in range(0, len(f), window):
        w = f[s:s + window]
        rec[s:s + len(w)] = reconstruct_features(vae, mean, std, w[None], [len(w)])[0]
    return f, rec


def measure_set(vae, mean, std, clips: dict[str, np.ndarray]) -> dict:
    """Per clip: frame-level error arrays and the clip figures (root-aligned MPJPE in cm)."""
    from salad_core.motion import features_to_joints

    root = SK.feature_slices["root"]
    out = {}
    for name, feats in clips.items():
        f, rec = reconstruct(vae, mean, std, feats)
        gt, pr = features_to_joints(f.astype(np.float64)), features_to_joints(rec.astype(np.float64))
        pj = 100 * per_joint_error(pr, gt)
        pose_only = features_to_joints(swap_columns(rec, f, root).astype(np.float64))
        root_only = features_to_joints(swap_columns(f, rec, root).astype(np.float64))
        height_only = features_to_joints(swap_columns(f, rec, SK.feature_slices["root_y"]).astype(np.float64))
        desc = pose_descriptor(f)
        out[name] = {"feats": f, "joints": gt, "per_joint": pj, "frame_err": pj.mean(-1),
                     "mpjpe_cm": float(pj.mean()),
                     "pose_only_cm": float(100 * per_joint_error(pose_only, gt).mean()),
                     "root_only_cm": float(100 * per_joint_error(root_only, gt).mean()),
                     "height_only_cm": float(100 * per_joint_error(height_only, gt).mean()),
                     "global_cm": float(100 * np.linalg.norm(pr - gt, axis=-1).mean()),
                     "ric_cm": mvr.ric_error_cm(rec, f), "desc": desc,
                     "pose_speed": frame_speed(desc), "root_speed": frame_speed(gt[:, :1])}
    return out


def clip_mpjpe(vae, mean, std, feats: np.ndarray, window: int | None = None) -> float:
    from salad_core.motion import features_to_joints

    f, rec = reconstruct(vae, mean, std, feats, window)
    return float(100 * per_joint_error(features_to_joints(rec.astype(np.float64)),
                                       features_to_joints(f.astype(np.float64))).mean())


def rerig_features(feats: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    from salad_core.motion import features_to_joints, joints_to_features

    return joints_to_features(rerig(features_to_joints(np.asarray(feats, np.float64)), src, dst)).astype(np.float32)


def training_bank(corpus: Path, general: Path, clips: int, stride: int, seed: int = 0):
    """Pose descriptors of a subsample of both training splits: ``(poses (B, J, 3), source labels)``,
    in a seeded random order (so its first half is a random half)."""
    rng = np.random.default_rng(seed)
    poses, labels = [], []
    for tag, root in (("corpus", corpus), ("general", general)):
        ids = [x for x in (root / "train.txt").read_text().split() if x]
        for i in rng.permutation(len(ids))[:clips]:
            f = np.load(root / "new_joint_vecs" / f"{ids[i]}.npy")
            d = pose_descriptor(f)[rng.integers(stride)::stride]
            poses.append(d)
            labels += [f"{tag}:{ids[i]}:{k}" for k in range(len(d))]
    poses = np.concatenate(poses)
    order = rng.permutation(len(poses))
    return poses[order], [labels[k] for k in order]


# ============================================================================ printing
def _pool(rows: dict, key: str) -> np.ndarray:
    return np.concatenate([r[key] for r in rows.values()])


def _table(title: str, header: list[str], lines: list[list], width: int = 9, first: int = 22) -> None:
    print(f"\n== {title}")
    print(f"{header[0]:{first}s}" + "".join(f"{h:>{width}s}" for h in header[1:]))
    for ln in lines:
        cells = [f"{v:{width}.1f}" if isinstance(v, (float, np.floating)) else f"{v!s:>{width}s}" for v in ln[1:]]
        print(f"{ln[0]!s:{first}s}" + "".join(cells))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--vae", default=str(mvr.REPO / "salad_core" / "weights" / "general_vae"),
                    help="pipeline folder, exported VAE or VAE run (default: the shipped general VAE)")
    ap.add_argument("--corpus", type=Path, default=RUNS / "corpus", help="procedural corpus (train + test splits)")
    ap.add_argument("--general", type=Path, default=RUNS / "general", help="general-motion set (train + test)")
    ap.add_argument("--limit", type=int, default=60, help="clips per procedural test split (default 60)")
    ap.add_argument("--bank-clips", type=int, default=1000, help="training clips per set in the pose bank")
    ap.add_argument("--bank-stride", type=int, default=3, help="every n-th frame of a bank clip")
    ap.add_argument("--json", type=Path, default=None, help="write the figures to this JSON file")
    args = ap.parse_args(argv)
    for flag, folder in (("--corpus", args.corpus), ("--general", args.general)):
        if not (folder / "train.txt").is_file() or not (folder / "test.txt").is_file():
            ap.error(f"{flag} {folder}: no train.txt/test.txt there; give the corpus / general set the VAE trained on "
                     "(lab/scripts/campaign/train_v2.sh WORK data builds both)")

    import torch

    torch.set_grad_enabled(False)
    t0 = time.time()
    vae, mean, std, desc = mvr.load_vae(args.vae)
    print(f"VAE: {desc}; posterior mean; root-aligned errors in cm")
    real, notes = mvr.real_clips(rig="deepmimic")     # as converted before: the humanoid's own torso
    if "deepmimic" not in real:
        raise SystemExit("DeepMimic clips need pybullet; " + "; ".join(notes))
    smpl, dm = smpl_rest_directions(), deepmimic_rest_directions()
    corpus_test = mvr.split_clips(args.corpus, "test", args.limit)
    general_test = mvr.split_clips(args.general, "test", args.limit)
    # "_smpl": torso rebuilt on the SMPL / procedural rig, "_dm": on the DeepMimic converter's rig;
    # hml_smpl and general_smpl (own rig, rebuilt) are the controls that the rebuild alone changes little
    clip_sets = {
        "hml": real["humanml3d_012314"],
        "hml_smpl": {k: rerig_features(f, smpl, smpl) for k, f in real["humanml3d_012314"].items()},
        "dm": real["deepmimic"],
        "dm_smpl": {k: rerig_features(f, dm, smpl) for k, f in real["deepmimic"].items()},
        "corpus": corpus_test,
        "corpus_dm": {k: rerig_features(f, smpl, dm) for k, f in corpus_test.items()},
        "general": general_test,
        "general_smpl": {k: rerig_features(f, smpl, smpl) for k, f in general_test.items()},
        "general_dm": {k: rerig_features(f, smpl, dm) for k, f in general_test.items()},
    }
    sets = {name: measure_set(vae, mean, std, clips) for name, clips in clip_sets.items()}
    names = list(sets)
    res: dict = {"vae": desc, "args": {k: str(v) for k, v in vars(args).items()}, "notes": notes}
    print(f"[{time.time() - t0:.0f} s] reconstructed {sum(len(s) for s in sets.values())} clips")

    # ---------------------------------------------------------------- 1. where the error sits
    summary = {}
    for n, rows in sets.items():
        per_clip = lambda k: np.array([r[k] for r in rows.values()])        # noqa: E731
        summary[n] = {"clips": len(rows), "frames": int(sum(len(r["frame_err"]) for r in rows.values())),
                      **{f"{k}_median": float(np.median(per_clip(k)))
                         for k in ("mpjpe_cm", "pose_only_cm", "root_only_cm", "height_only_cm", "ric_cm",
                                   "global_cm")},
                      "mpjpe_max": float(per_clip("mpjpe_cm").max())}
    res["summary"] = summary
    _table("1a. per set (medians over clips; pose only = own root channels put back, root only = only the "
           "4 root channels reconstructed, height only = only the root height)",
           ["set", "clips", "MPJPE", "max", "pose only", "root only", "height only", "ric", "global"],
           [[n, s["clips"], s["mpjpe_cm_median"], s["mpjpe_max"], s["pose_only_cm_median"], s["root_only_cm_median"],
             s["height_only_cm_median"], s["ric_cm_median"], s["global_cm_median"]] for n, s in summary.items()],
           width=12, first=20)
    joint_err = {n: _pool(rows, "per_joint").mean(0) for n, rows in sets.items()}
    res["per_joint"] = {n: dict(zip(SK.joint_names, map(float, v))) for n, v in joint_err.items()}
    _table("1b. per joint (mean over all frames of the set)", ["joint"] + [n[:13] for n in names],
           [[SK.joint_names[j]] + [float(joint_err[n][j]) for n in names] for j in range(1, J)], width=14, first=16)
    parts = {n: part_means(_pool(rows, "per_joint")) for n, rows in sets.items()}
    res["per_part"] = parts
    _table("1c. per body part (joint_to_part; the root part is the pelvis, 0 after alignment)",
           ["part"] + [n[:13] for n in names],
           [[p] + [parts[n][p] for n in names] for p in SK.part_names[1:]], width=14, first=16)

    # ---------------------------------------------------------------- 2. rig geometry
    geo = {}
    for n, rows in sets.items():
        per_clip = [rig_angles(r["joints"]) for r in rows.values()]
        geo[n] = {k: np.concatenate([a[k] for a in per_clip]) for k in per_clip[0]}
    res["rig_angles_deg"] = {n: {k: [float(np.median(v)), float(np.percentile(v, 5)), float(np.percentile(v, 95))]
                                 for k, v in g.items()} for n, g in geo.items()}
    print("\n== 2. rig geometry: bone angles in degrees, median [p5, p95] over all frames")
    print(f"{'angle':22s}" + "".join(f"{n[:15]:>16s}" for n in names))
    for k in geo[names[0]]:
        print(f"{k:22s}" + "".join(f"{'%.0f [%.0f,%.0f]' % tuple(res['rig_angles_deg'][n][k]):>16s}" for n in names))
    print(f"[{time.time() - t0:.0f} s]")

    # ---------------------------------------------------------------- 3. coverage
    bank, labels = training_bank(args.corpus, args.general, args.bank_clips, args.bank_stride)
    half = len(bank) // 2
    print(f"\n== 3. coverage: nearest training pose (bank: {len(bank)} poses, every {args.bank_stride}th frame of "
          f"{args.bank_clips} corpus + {args.bank_clips} general training clips; distances in cm)")
    cov = {}
    edges = [0, 2, 4, 6, 8, 12, 1e9]
    for n, rows in sets.items():
        q = _pool(rows, "desc")
        d, idx, pj = nearest_neighbours(q, bank)
        d_half, _, _ = nearest_neighbours(q, bank[:half])
        d, d_half, pj = 100 * d, 100 * d_half, 100 * pj
        err = _pool(rows, "frame_err")
        cov[n] = {"nn_median": float(np.median(d)), "nn_p90": float(np.percentile(d, 90)), "nn_max": float(d.max()),
                  "nn_median_half_bank": float(np.median(d_half)), "spearman_nn_err": spearman(d, err),
                  "from_general": float(np.mean([labels[i].startswith("general") for i in idx])),
                  "err_by_nn": binned(d, err, edges), "nn_joint": dict(zip(SK.joint_names, map(float, pj.mean(0))))}
        bounds = np.cumsum([len(r["frame_err"]) for r in rows.values()])[:-1]
        for r_name, r in zip(rows, np.split(np.arange(len(d)), bounds)):
            rows[r_name]["nn"], rows[r_name]["nn_joint"], rows[r_name]["nn_idx"] = d[r], pj[r], idx[r]
    res["coverage"] = cov
    _table("3a. nearest-neighbour distance per set (rho = Spearman of per-frame NN distance and error)",
           ["set", "median", "p90", "max", "half bank", "rho", "NN general"],
           [[n, c["nn_median"], c["nn_p90"], c["nn_max"], c["nn_median_half_bank"], f"{c['spearman_nn_err']:.2f}",
             f"{c['from_general']:.2f}"] for n, c in cov.items()], width=10, first=20)
    _table("3b. mean per-frame error (cm) by NN distance bin (frames in brackets)",
           ["set"] + [f"{lo:g}-{hi:g}" if hi < 1e8 else f">{lo:g}" for lo, hi, *_ in cov[names[0]]["err_by_nn"]],
           [[n] + [f"{m:.1f} ({c})" if c else "-" for *_, c, m in cv["err_by_nn"]] for n, cv in cov.items()],
           width=13, first=20)
    _table("3c. per-joint distance to the nearest training pose (mean over frames)",
           ["joint"] + [n[:13] for n in names],
           [[SK.joint_names[j]] + [cov[n]["nn_joint"][SK.joint_names[j]] for n in names] for j in range(1, J)],
           width=14, first=16)
    res["farthest"] = {}
    for n in ("hml", "dm", "dm_smpl"):
        if n not in sets:
            continue
        cand = [(r["nn"][i], clip, i) for clip, r in sets[n].items() for i in range(len(r["nn"]))]
        best_per_clip: dict = {}
        for dist, clip, i in sorted(cand, reverse=True):
            best_per_clip.setdefault(clip, (dist, i))
        top = sorted(((v[0], c, v[1]) for c, v in best_per_clip.items()), reverse=True)[:8]
        print(f"\n== 3d. {n}: farthest frame of the 8 farthest clips (NN distance, error, worst joints to the NN)")
        res["farthest"][n] = []
        for dist, clip, i in top:
            r = sets[n][clip]
            worst = np.argsort(-r["nn_joint"][i])[:3]
            jn = ", ".join(f"{SK.joint_names[w]} {r['nn_joint'][i][w]:.0f}" for w in worst)
            print(f"  {clip:26s} frame {i:3d}: NN {dist:5.1f} cm, error {r['frame_err'][i]:5.1f} cm; {jn}; "
                  f"NN {labels[r['nn_idx'][i]]}")
            res["farthest"][n].append({"clip": clip, "frame": int(i), "nn_cm": float(dist),
                                       "err_cm": float(r["frame_err"][i]), "worst_joints": jn})
    print(f"[{time.time() - t0:.0f} s]")

    # ---------------------------------------------------------------- 4. dynamics
    sp_edges = [0, 0.25, 0.5, 1.0, 2.0, 1e9]
    dyn = {}
    for n, rows in sets.items():
        err, ps, rs = _pool(rows, "frame_err"), _pool(rows, "pose_speed"), _pool(rows, "root_speed")
        dyn[n] = {"spearman_pose_speed": spearman(ps, err), "spearman_root_speed": spearman(rs, err),
                  "partial_pose_speed_given_nn": partial_spearman(ps, err, _pool(rows, "nn")),
                  "partial_nn_given_pose_speed": partial_spearman(_pool(rows, "nn"), err, ps),
                  "pose_speed_median": float(np.median(ps)), "err_by_pose_speed": binned(ps, err, sp_edges)}
    _table("4a. per-frame error against speed (rho: Spearman; |NN: pose speed's partial rho with the NN distance "
           "held fixed, NN|v: the NN distance's with pose speed held fixed; pose speed = mean joint speed of the "
           "root-relative pose, m/s; mean error cm by pose speed bin, frames in brackets)",
           ["set", "rho pose", "rho root", "|NN", "NN|v", "median v"]
           + [f"{lo:g}-{hi:g}" if hi < 1e8 else f">{lo:g}" for lo, hi, *_ in dyn[names[0]]["err_by_pose_speed"]],
           [[n, f"{d['spearman_pose_speed']:.2f}", f"{d['spearman_root_speed']:.2f}",
             f"{d['partial_pose_speed_given_nn']:.2f}", f"{d['partial_nn_given_pose_speed']:.2f}", d["pose_speed_median"]]
            + [f"{m:.1f} ({c})" if c else "-" for *_, c, m in d["err_by_pose_speed"]] for n, d in dyn.items()],
           width=12, first=20)
    from salad_core.motion import features_to_joints, joints_to_features, mirror_features

    speeds = (0.5, 1.0, 2.0)
    for n in names:
        med, top = {}, {}
        for s in speeds:
            vals = []
            for f in clip_sets[n].values():
                # the same content at every speed: the first 4.8 s (97 joint frames), so that slow
                # motion still fits in 196 frames
                j = features_to_joints(np.asarray(f, np.float64))[:97]
                f2 = joints_to_features(resample_joints(j, s))
                if len(f2) >= 8:
                    vals.append(clip_mpjpe(vae, mean, std, f2))
            med[str(s)], top[str(s)] = float(np.median(vals)), float(np.max(vals))
        dyn[n]["replayed_median"], dyn[n]["replayed_max"] = med, top
    res["dynamics"] = dyn
    _table("4b. the first 4.8 s of every clip replayed at another speed (MPJPE median and max over clips; x1 = "
           "re-extracted unchanged)", ["set"] + [f"{w} x{s:g}" for w in ("med", "max") for s in speeds],
           [[n] + [dyn[n][k][str(s)] for k in ("replayed_median", "replayed_max") for s in speeds] for n in names],
           width=10, first=20)
    print(f"[{time.time() - t0:.0f} s]")

    # ---------------------------------------------------------------- 5. other checks
    other = {}
    for n in names:
        clips = clip_sets[n]
        other[n] = {"whole": summary[n]["mpjpe_cm_median"],
                    "windows 40": float(np.median([clip_mpjpe(vae, mean, std, f, 40) for f in clips.values()])),
                    "windows 64": float(np.median([clip_mpjpe(vae, mean, std, f, 64) for f in clips.values()])),
                    "mirrored": float(np.median([clip_mpjpe(vae, mean, std, mirror_features(np.asarray(f)))
                                                 for f in clips.values()]))}
    res["other"] = other
    cols = list(other[names[0]])
    _table("5. median MPJPE encoded whole / in 40- or 64-frame windows / mirrored", ["set"] + cols,
           [[n] + [other[n][c] for c in cols] for n in names], width=12, first=20)
    dm_rows, rig_rows = sets["dm"], sets["dm_smpl"]
    print("\n== 5b. DeepMimic per clip: as converted -> on the SMPL rig (MPJPE cm; NN = median NN distance cm; "
          "v = median pose speed m/s)")
    res["deepmimic_clips"] = {}
    for c in dm_rows:
        a, b = dm_rows[c], rig_rows[c]
        res["deepmimic_clips"][c] = {"mpjpe_cm": a["mpjpe_cm"], "smplrig_mpjpe_cm": b["mpjpe_cm"],
                                     "nn_cm": float(np.median(a["nn"])), "smplrig_nn_cm": float(np.median(b["nn"])),
                                     "pose_speed": float(np.median(a["pose_speed"]))}
        print(f"  {c:26s} {a['mpjpe_cm']:5.1f} -> {b['mpjpe_cm']:5.1f}   NN {np.median(a['nn']):5.1f} -> "
              f"{np.median(b['nn']):5.1f}   v {np.median(a['pose_speed']):4.2f}")
    rig_all = {**sets["hml"], **rig_rows}
    vals = np.array([r["mpjpe_cm"] for r in rig_all.values()])
    before = np.array([r["mpjpe_cm"] for r in {**sets["hml"], **dm_rows}.values()])
    print(f"\nreal clips with DeepMimic on the SMPL rig ({len(vals)} clips): median {np.median(vals):.1f} cm, "
          f"max {vals.max():.1f} cm (as converted: {np.median(before):.1f}, {before.max():.1f})")
    res["real_smplrig_summary"] = {"median": float(np.median(vals)), "max": float(vals.max())}
    print(f"\ntotal {time.time() - t0:.0f} s")
    for note in notes:
        print(f"note: {note}")
    if args.json:
        args.json.write_text(json.dumps(res, indent=2, default=float) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
