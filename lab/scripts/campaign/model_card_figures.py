"""Figures for the shipped weights' model card, measured now (nothing is copied from elsewhere).

Usage: python lab/scripts/campaign/model_card_figures.py --data CORPUS [--weights DIR] [--clips 100] [--seeds 4]

Prints: the VAE's reconstruction MPJPE on test clips; for prompts with a left/right or body-part
contrast, the per-part activity of generated motions (mean part speed, m/s), the left/right
activity ratio, and how far their bone lengths stray from the corpus's (the features hold joint
positions, so nothing forces one skeleton), averaged over seeds; and the generation time per motion.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from salad_core.attention.measure import left_right_ratio
from salad_core.data.procedural import part_activity
from salad_core.eval.metrics import mpjpe
from salad_core.motion import bone_lengths, features_to_joints
from salad_core.pipeline import SaladPipeline
from salad_core.skeleton import PART_NAMES

PROMPTS = [
    "a person walks forward",
    "a man waves his left hand",
    "a man waves his right hand",
    "a person kicks with the left leg",
    "a person kicks with the right leg",
    "a man is jumping high",
    "a man sits on the ground",
    "a person nods his head",
    "a man raises his right hand high",
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, type=Path)
    ap.add_argument("--weights", default=None)
    ap.add_argument("--clips", type=int, default=100)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--length", type=int, default=100)
    args = ap.parse_args()
    pipe = SaladPipeline.from_pretrained(args.weights)

    names = (args.data / "test.txt").read_text().split()[: args.clips]
    errs, real_bones = [], []
    for n in names:
        f = np.load(args.data / "new_joint_vecs" / f"{n}.npy")
        f = f[: len(f) // 4 * 4]
        feats, _ = pipe.decode(pipe.encode_motion(f), [len(f)])
        real = features_to_joints(f)
        errs.append(mpjpe(features_to_joints(feats[0]), real))      # the raw decoded positions, not the fit
        real_bones.append(bone_lengths(real)[:, 1:])
    print(f"VAE reconstruction MPJPE (root-aligned) on {len(errs)} test clips: mean {np.mean(errs) * 100:.2f} cm, "
          f"median {np.median(errs) * 100:.2f} cm")
    # bone lengths against the corpus's per-bone median (its personas differ in size, so the corpus
    # clips themselves deviate a little: that is the reference row)
    ref = np.median(np.concatenate(real_bones), axis=0)

    def bone_stray(j: np.ndarray) -> tuple[float, float]:
        """(mean |bone - corpus median| over bones and frames, 95th pct over frames of the worst bone), cm."""
        dev = np.abs(bone_lengths(j)[:, 1:] - ref) * 100
        return float(dev.mean()), float(np.percentile(dev.max(axis=1), 95))

    corpus = np.array([bone_stray(features_to_joints(np.load(args.data / "new_joint_vecs" / f"{n}.npy")))
                       for n in names])
    recon = []
    for n in names[:20]:
        f = np.load(args.data / "new_joint_vecs" / f"{n}.npy")
        f = f[: len(f) // 4 * 4]
        recon.append(bone_stray(features_to_joints(pipe.decode(pipe.encode_motion(f), [len(f)])[0][0])))  # raw
    recon = np.array(recon)
    print(f"bone-length deviation from the corpus median, mean / worst bone (95th pct of frames): corpus clips "
          f"{corpus[:, 0].mean():.1f} / {corpus[:, 1].mean():.1f} cm, VAE reconstructions {recon[:, 0].mean():.1f} / "
          f"{recon[:, 1].mean():.1f} cm")
    g = pipe.guidance
    print(f"\ngenerated motions ({args.length} frames, 50 DDIM steps, w={g.scale:g} rescale {g.rescale:g} (the weights' "
          f"default), {args.seeds} seeds each; activity and travel of out.joints (recovery {pipe.recovery!r}), bone "
          f"deviation of the raw joints (position features), then of out.joints:")
    print(f"{'prompt':36s} " + " ".join(f"{p[:9]:>9s}" for p in PART_NAMES)
          + "  L/R legs  L/R arms  root travel  bone dev. mean / worst raw (cm)  shown")
    t0 = time.perf_counter()
    for prompt in PROMPTS:
        out = pipe([prompt] * args.seeds, lengths=args.length, seed=list(range(args.seeds)))
        act = np.mean([part_activity(j) for j in out.joints], axis=0)
        lr = [left_right_ratio(j) for j in out.joints]
        legs = np.exp(np.mean([np.log(r["legs"]) for r in lr]))
        arms = np.exp(np.mean([np.log(r["arms"]) for r in lr]))
        travel = np.mean([np.linalg.norm(j[-1, 0, [0, 2]] - j[0, 0, [0, 2]]) for j in out.joints])
        raw = np.array([bone_stray(features_to_joints(f[:n])) for f, n in zip(out.features, out.lengths)])
        shown = np.array([bone_stray(j) for j in out.joints])
        print(f"{prompt:36s} " + " ".join(f"{a:9.2f}" for a in act) + f"  {legs:8.2f}  {arms:8.2f}  {travel:8.2f} m"
              f"  {raw[:, 0].mean():8.1f} / {raw[:, 1].mean():5.1f}  {shown[:, 0].mean():5.1f} / {shown[:, 1].mean():5.1f}")
    dt = (time.perf_counter() - t0) / (len(PROMPTS) * args.seeds)
    print(f"\ngeneration time: {dt:.2f} s per motion (batch {args.seeds}, text encoder included)")


if __name__ == "__main__":
    main()
