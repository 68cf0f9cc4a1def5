"""Figures for salad_core/weights/keymotion/MODEL_CARD.md (measured, nothing copied).

Usage: python lab/scripts/keymotion/keymotion_card_figures.py --data CORPUS [--weights DIR] [--clips 300] [--seeds 4] [--renders DIR]
       [--eval] [--eval-samples 128] [--eval-reps 2]

1. keyframe reconstruction on test clips (MDO keyframes of the ground truth):
   - decoded keyframes (VAE posterior mean -> decoder), root-aligned pose MPJPE (cm) and frame error;
   - MMAE in-filled full motions given the ground-truth keyframes, MPJPE (cm) root-aligned and
     global, next to plain linear interpolation of the same keyframes;
   - VAE-decoded keyframes -> MMAE (the whole reconstruction path).
2. generations: part activity, left/right ratios, travel; generation time; keyframe strips (PNG).
3. optional: the T2M protocol (quick settings) with the packaged evaluator, real row and KeyMotion.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

torch.set_num_threads(1)

from salad_core.attention.measure import left_right_ratio
from salad_core.data.dataset import read_texts
from salad_core.data.procedural import part_activity
from salad_core.eval.metrics import mpjpe

from salad_core.keymotion.mmae import keyframe_lerp, scatter_keyframes
from salad_core.keymotion.models import pose_joints
from salad_core.keymotion.pipeline import KeyMotionPipeline, decode_keyframes
from salad_core.keymotion.selection import select_keyframes
from salad_core.motion import features_to_joints
from salad_core.skeleton import PART_NAMES

from model_card_figures import PROMPTS  # the same prompts as the SALAD model card (this folder)


@torch.no_grad()
def reconstruction(pipe: KeyMotionPipeline, data: Path, clips: int, method: str) -> dict:
    names = (data / "test.txt").read_text().split()[:clips]
    k = pipe.num_keyframes
    norm = pipe.mmae.norm
    res = {m: [] for m in ("kf_pose", "kf_frames", "mmae_gt_ra", "mmae_gt_glob", "lerp_gt_ra", "lerp_gt_glob",
                           "mmae_vae_ra", "mmae_vae_glob")}
    for name in names:
        f = np.load(data / "new_joint_vecs" / f"{name}.npy")[: pipe.max_length].astype(np.float32)
        n = len(f)
        x = norm.normalize(torch.from_numpy(f))[None]                       # (1, N, D)
        idx = torch.from_numpy(select_keyframes(x[0].numpy(), k, method).astype(np.int64))[None]
        kf = torch.gather(x, 1, idx[..., None].expand(-1, -1, x.shape[-1]))
        length = torch.tensor([n])
        enc = pipe.kf_vae.encode(kf, pipe.kf_vae.positions_of(idx, length), sample=False)
        dec_kf, dec_idx = decode_keyframes(pipe.kf_vae, enc.mu, length)
        pj = pose_joints(norm.denormalize(dec_kf), pipe.skeleton)[0].numpy()
        tj = pose_joints(norm.denormalize(kf), pipe.skeleton)[0].numpy()
        res["kf_pose"].append(mpjpe(pj, tj))
        res["kf_frames"].append(float((dec_idx - idx).abs().float().mean()))
        caption = read_texts(data, name)[0].caption
        tb = pipe.text_encoder.encode([caption])
        gt_j = features_to_joints(f, pipe.skeleton)
        for tag, (kfs, ids) in {"gt": (kf, idx), "vae": (dec_kf, dec_idx)}.items():
            motion = pipe.mmae.infill(kfs, ids, length, tb.features, tb.mask)
            j = features_to_joints(norm.denormalize(motion)[0].numpy(), pipe.skeleton)
            res[f"mmae_{tag}_ra"].append(mpjpe(j, gt_j))
            res[f"mmae_{tag}_glob"].append(mpjpe(j, gt_j, root_aligned=False))
        canvas, mask = scatter_keyframes(kf, idx, n)
        lerp = keyframe_lerp(canvas, mask)
        j = features_to_joints(norm.denormalize(lerp)[0].numpy(), pipe.skeleton)
        res["lerp_gt_ra"].append(mpjpe(j, gt_j))
        res["lerp_gt_glob"].append(mpjpe(j, gt_j, root_aligned=False))
    out = {}
    for key, v in res.items():
        scale = 1.0 if key == "kf_frames" else 100.0                          # metres -> cm
        out[key] = {"mean": float(np.mean(v) * scale), "median": float(np.median(v) * scale)}
    out["clips"] = len(names)
    return out


def generations(pipe: KeyMotionPipeline, seeds: int, length: int, renders: Path | None) -> dict:
    rows = {}
    t0 = time.perf_counter()
    outs = {}
    for prompt in PROMPTS:
        joints = []
        for s in range(seeds):
            # the card's figures are of the model's own output: the position features read as they are
            # (out.joints would be the skeleton fit, the pipeline's default since session 22)
            out = pipe([prompt], lengths=[length], seed=s, recovery="positions")
            joints.append(out.joints[0])
        outs[prompt] = joints
    dt = (time.perf_counter() - t0) / (len(PROMPTS) * seeds)
    for prompt, joints in outs.items():
        act = np.mean([part_activity(j) for j in joints], axis=0)
        lr = [left_right_ratio(j) for j in joints]
        legs = float(np.exp(np.mean([np.log(r["legs"]) for r in lr])))
        arms = float(np.exp(np.mean([np.log(r["arms"]) for r in lr])))
        travel = float(np.mean([np.linalg.norm(j[-1, 0, [0, 2]] - j[0, 0, [0, 2]]) for j in joints]))
        rows[prompt] = {"parts": dict(zip(PART_NAMES, map(float, act))), "lr_legs": legs, "lr_arms": arms,
                        "travel_m": travel}
    if renders is not None:
        from PIL import Image

        from salad_viz.render import keyframe_strip

        renders.mkdir(parents=True, exist_ok=True)
        for i, (prompt, joints) in enumerate(outs.items()):
            for s in range(min(2, seeds)):
                img = keyframe_strip(joints[s], "humanml3d", 8, backend="raster", fps=20, title=f"{prompt} (seed {s})")
                Image.fromarray(img).save(renders / f"{i:02d}_{prompt.replace(' ', '_')}_seed{s}.png")
                img = keyframe_strip(joints[s], "humanml3d", 6, layout="row", view="three_quarter", backend="raster",
                                     fps=20, title=f"{prompt} (seed {s})")
                Image.fromarray(img).save(renders / f"{i:02d}_{prompt.replace(' ', '_')}_seed{s}_row.png")
    return {"rows": rows, "seconds_per_motion": dt, "length": length, "seeds": seeds}


def evaluation(pipe: KeyMotionPipeline, data: Path, samples: int, reps: int, weights: str | None = None) -> dict:
    """The quick T2M rows (real, KeyMotion); ``weights`` is the folder recorded with them (None: the shipped one)."""
    from salad_core.eval.protocol import evaluate_generator, evaluate_real
    from salad_core.eval.settings import EvalSettings
    from salad_core.eval.tables import results_frame, to_markdown
    from salad_core.eval.train_evaluator import load_packaged_evaluator

    evaluator, _ = load_packaged_evaluator(None)
    settings = EvalSettings.quick_mode(max_samples=samples, replications=reps)
    t0 = time.perf_counter()
    real = evaluate_real(data, evaluator, settings)
    t1 = time.perf_counter()
    gen = evaluate_generator(pipe, data, evaluator, settings, name="KeyMotion",
                             weights=weights or "salad_core/weights/keymotion")
    t2 = time.perf_counter()
    df = results_frame([real, gen])
    return {"settings": settings.describe(), "markdown": to_markdown(df), "real": real.summary(),
            "keymotion": gen.summary(), "seconds_real": t1 - t0, "seconds_generator": t2 - t1}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", required=True, type=Path)
    ap.add_argument("--weights", default=None)
    ap.add_argument("--clips", type=int, default=300)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--length", type=int, default=100)
    ap.add_argument("--renders", type=Path, default=None)
    ap.add_argument("--skip-rec", action="store_true")
    ap.add_argument("--skip-gen", action="store_true")
    ap.add_argument("--eval", action="store_true")
    ap.add_argument("--eval-samples", type=int, default=128)
    ap.add_argument("--eval-reps", type=int, default=2)
    ap.add_argument("--out", type=Path, default=None, help="JSON file for the figures")
    args = ap.parse_args()
    pipe = KeyMotionPipeline.from_pretrained(args.weights)
    doc = {}
    if not args.skip_rec:
        t0 = time.perf_counter()
        doc["reconstruction"] = reconstruction(pipe, args.data, args.clips, "mdo")
        print(json.dumps(doc["reconstruction"], indent=1), f"({time.perf_counter() - t0:.0f} s)", flush=True)
    if not args.skip_gen:
        doc["generations"] = generations(pipe, args.seeds, args.length, args.renders)
        g = doc["generations"]
        print(f"{'prompt':36s} " + " ".join(f"{p[:9]:>9s}" for p in PART_NAMES) + "  L/R legs  L/R arms  travel")
        for prompt, r in g["rows"].items():
            print(f"{prompt:36s} " + " ".join(f"{v:9.2f}" for v in r["parts"].values())
                  + f"  {r['lr_legs']:8.2f}  {r['lr_arms']:8.2f}  {r['travel_m']:6.2f} m")
        print(f"generation: {g['seconds_per_motion']:.2f} s per motion", flush=True)
    if args.eval:
        doc["evaluation"] = evaluation(pipe, args.data, args.eval_samples, args.eval_reps, args.weights)
        e = doc["evaluation"]
        print(e["settings"])
        print(e["markdown"])
        print(f"real {e['seconds_real']:.0f} s, generator {e['seconds_generator']:.0f} s")
    if args.out:
        args.out.write_text(json.dumps(doc, indent=2, default=str) + "\n")


if __name__ == "__main__":
    main()
