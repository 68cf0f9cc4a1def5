"""KeyMotion's MMAE against linear interpolation at a keyframe *ratio* (issue 22's in-filling target).

For each test window of a procedural corpus (up to the models' ``max_length`` frames), the MDO
keyframes of the ground truth are selected, either ``K = max(2, round(ratio x L))`` of them (the
paper: 10 % on HumanML3D) or a fixed ``K``; the MMAE in-fills the motion from them and linear
interpolation of the same keyframes is the baseline. Reported: the root-aligned MPJPE (cm, joints
relative to the pelvis, mean over frames and joints) of both, pooled over frames, and the MMAE's
gain ``1 - MMAE / LERP`` (the issue's target: at least 0.30 at the paper's ratio); and the foot skating of
the clips themselves, of the MMAE's in-fillings and of LERP's (m/s, mean over windows, the physics benchmark's
measure on the position joints: :func:`salad_core.eval.physics.measure_motion`), which says how far the in-filling
stage alone, given a clip's own keyframes, is from the clip's planted feet; and the skating of the MMAE's in-fillings
read through the skeleton fit (``"mmae_fit"``, :func:`salad_core.recovery.recover_joints` with ``"fit"``: fixed bones,
feet locked where the in-filled contact channels say so), which is what ``out.joints`` of the pipeline shows: whether
the contact channels the MMAE fills in let the fit plant the feet. ``--words walk run`` keeps the windows
whose caption names one of the words (the skating of gaits).

Example::

    OMP_NUM_THREADS=1 nice -n 19 .venv/bin/python lab/scripts/keymotion/keymotion_infill_ratio.py \
        --data /tmp/corpus_small --limit 150 --ratios 0.1 0.25 --fixed 20
    python lab/scripts/keymotion/keymotion_infill_ratio.py --data CORPUS --split val --words walk run jog --limit 30 \
        --ratios 0.1 0.2 0.35 0.5 --fixed                  # in-filled gaits' skating by keyframe density
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

from salad_core.eval.physics import measure_motion
from salad_core.keymotion.kf_vae import gather_keyframes
from salad_core.keymotion.mmae import keyframe_lerp, scatter_keyframes
from salad_core.keymotion.pipeline import KeyMotionPipeline
from salad_core.keymotion.selection import select_keyframes
from salad_core.motion import features_to_joints
from salad_core.recovery import recover_joints


def root_aligned_error(pred: np.ndarray, true: np.ndarray) -> np.ndarray:
    """Per-frame mean joint error (m) of joints ``(N, J, 3)`` relative to their pelvis."""
    return np.linalg.norm((pred - pred[:, :1]) - (true - true[:, :1]), axis=-1).mean(-1)


def contact_transitions(contacts: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: frames at which any of the 4 foot-contact channels ``contacts (N, 4)`` (0 / 1, denormalised)
    switches from the frame before (a foot lands or lifts); frame 0 never."""
    on = np.asarray(contacts) > 0.5
    out = np.zeros(len(on), dtype=bool)
    out[1:] = (on[1:] != on[:-1]).any(-1)
    return out


def contact_mdo_keyframes(x: np.ndarray, k: int, events: np.ndarray, weight: float = 1.0) -> np.ndarray:
    """MDO keyframes of ``x (N, D)`` that prefer foot-contact events: the exact DP of
    :func:`salad_core.keymotion.selection.mdo_keyframes` with each chosen frame in ``events (N,)`` earning ``weight``
    times the mean distance between MDO's own consecutive keyframes (so one event is worth about one average segment).
    Frames 0 and N-1 are always chosen; ``weight`` 0 is MDO."""
    from salad_core.keymotion.selection import feature_distances, optimal_keyframe_path

    dist = feature_distances(x)
    base = optimal_keyframe_path(dist, k)  # MDO
    seg = float(np.mean(dist[base[:-1], base[1:]]))
    bonus = weight * seg * np.asarray(events, dtype=np.float64)
    return optimal_keyframe_path(dist + bonus[None, :], k)


@torch.no_grad()
def infill_joints(pipe: KeyMotionPipeline, x: np.ndarray, caption: str, k: int,
                  contact_weight: float = 0.0) -> dict[str, np.ndarray]:
    """Joints ``(N, J, 3)`` (m) of a window ``x (N, D)`` (normalised features): ``"true"``, and its in-filling from
    its ``k`` MDO keyframes by the MMAE (``"mmae"``) and by linear interpolation (``"lerp"``), read from the position
    features; and the MMAE's in-filling through the skeleton fit (``"mmae_fit"``). ``contact_weight`` > 0: the
    keyframes prefer foot-contact events (:func:`contact_mdo_keyframes`)."""
    n = len(x)
    if contact_weight > 0:
        den = pipe.mmae.norm.denormalize(torch.from_numpy(x).float()).numpy()
        events = contact_transitions(den[:, pipe.skeleton.feature_slices["contacts"]])
        idx = torch.from_numpy(contact_mdo_keyframes(x, k, events, contact_weight).astype(np.int64))[None]
    else:
        idx = torch.from_numpy(select_keyframes(x, k, "mdo").astype(np.int64))[None]
    xt = torch.from_numpy(x)[None]
    kf = gather_keyframes(xt, idx)
    tb = pipe.text_encoder.encode([caption])
    out = pipe.mmae.infill(kf, idx, torch.tensor([n]), tb.features, tb.mask)
    canvas, mask = scatter_keyframes(kf, idx, n)
    lerp = keyframe_lerp(canvas, mask)
    den = pipe.mmae.norm.denormalize
    sk = pipe.skeleton
    joints = {name: features_to_joints(den(t.float())[0].numpy(), sk) for name, t in
              (("true", xt), ("mmae", out), ("lerp", lerp))}
    joints["mmae_fit"] = recover_joints(den(out.float())[0].numpy(), "fit", sk)
    return joints


def infill_errors(pipe: KeyMotionPipeline, x: np.ndarray, caption: str, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame root-aligned errors (m) of the MMAE and of LERP from ``k`` MDO keyframes of ``x (N, D)``
    (normalised features)."""
    j = infill_joints(pipe, x, caption, k)
    return root_aligned_error(j["mmae"], j["true"]), root_aligned_error(j["lerp"], j["true"])


def skating(joints: np.ndarray, skeleton) -> float:
    """Mean foot speed (m/s) in contact frames of one motion ``(N, J, 3)``, as the physics benchmark measures it
    (nan when no foot touches the floor)."""
    return float(measure_motion(joints, skeleton).skate_mean_ms)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--weights", default=None, help="KeyMotion pipeline folder or training root (default: shipped)")
    ap.add_argument("--data", required=True, help="procedural corpus (HumanML3D layout); never the real sample")
    ap.add_argument("--split", default="test")
    ap.add_argument("--limit", type=int, default=150)
    ap.add_argument("--ratios", type=float, nargs="*", default=[0.1])
    ap.add_argument("--fixed", type=int, nargs="*", default=[20])
    ap.add_argument("--words", nargs="*", default=None,
                    help="keep only windows whose caption names one of these words (e.g. walk run jog)")
    ap.add_argument("--contact-weight", type=float, default=0.0,
                    help="keyframes that prefer foot-contact events (contact_mdo_keyframes; 0: the paper's MDO)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    from salad_core.data.dataset import MotionTextDataset

    pipe = KeyMotionPipeline.from_pretrained(args.weights)
    norm = pipe.mmae.norm
    ds = MotionTextDataset(args.data, args.split, max_length=pipe.max_length, random_crop=False,
                           mean=norm.mean.numpy(), std=norm.std.numpy())
    rng = np.random.default_rng(0)
    if args.words:
        import re

        pattern = re.compile(r"\b(" + "|".join(map(re.escape, args.words)) + r")", re.IGNORECASE)
        pick = [i for i in rng.permutation(len(ds)) if pattern.search(ds[int(i)]["caption"])][:args.limit]
        if not pick:
            raise SystemExit(f"no {args.split} window of {args.data} has a caption naming {args.words}")
    else:                                        # the windows the model card's figures were measured on
        pick = rng.choice(len(ds), size=min(args.limit, len(ds)), replace=False)
    settings = [(f"ratio {r:g}", r, None) for r in args.ratios] + [(f"K = {k}", None, k) for k in args.fixed]
    stages = ("true", "mmae", "lerp", "mmae_fit")
    errs = {name: {key: [] for key in ("mmae", "lerp", "ratio", *(f"skate_{st}" for st in stages))}
            for name, _, _ in settings}
    for i in pick:
        item = ds[int(i)]
        n = int(item["length"])
        x = np.asarray(item["motion"][:n], dtype=np.float32)
        for name, r, k in settings:
            kk = max(2, int(round(r * n))) if r is not None else k
            if kk > n:
                continue
            j, row = infill_joints(pipe, x, item["caption"], kk, args.contact_weight), errs[name]
            row["mmae"].append(root_aligned_error(j["mmae"], j["true"]))
            row["lerp"].append(root_aligned_error(j["lerp"], j["true"]))
            row["ratio"].append(kk / n)
            for st in stages:
                row[f"skate_{st}"].append(skating(j[st], pipe.skeleton))
    report = {}
    print("| keyframes | windows | mean ratio | MMAE cm | LERP cm | gain 1 - MMAE/LERP "
          "| skating m/s: clips | MMAE | LERP | MMAE, skeleton fit |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, row in errs.items():
        if not row["mmae"]:
            print(f"| {name} | 0 | | | | | | | | |")
            continue
        mm, ll = (float(np.concatenate(row[key]).mean() * 100) for key in ("mmae", "lerp"))
        sk = {st: float(np.nanmean(v)) if np.isfinite(v := np.asarray(row[f"skate_{st}"])).any() else float("nan")
              for st in stages}
        report[name] = {"windows": len(row["mmae"]), "mean_ratio": float(np.mean(row["ratio"])), "mmae_cm": mm,
                        "lerp_cm": ll, "gain": 1 - mm / ll, **{f"skate_{st}_ms": sk[st] for st in stages}}
        print(f"| {name} | {len(row['mmae'])} | {np.mean(row['ratio']):.3f} | {mm:.2f} | {ll:.2f} | {1 - mm / ll:+.3f} "
              f"| {sk['true']:.3f} | {sk['mmae']:.3f} | {sk['lerp']:.3f} | {sk['mmae_fit']:.3f} |")
    if args.out:
        Path(args.out).write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
