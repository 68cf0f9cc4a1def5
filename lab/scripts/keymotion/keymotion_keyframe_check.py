"""Can KeyMotion's keyframe VAE represent a step? Its reconstruction of real keyframes (issue 22's stage gate).

KeyMotion glides because its keyframes do not step: for "a person walks forward" the keyframes the
shipped 0.1 pipeline decodes keep the ankles within a few centimetres of each other front to back, and
the MMAE in-fills exactly that. This script asks whether the keyframe VAE can represent stepping at all,
before a PST is trained on its latent space: for procedural corpus windows whose caption names a gait
(default: walk / run / jog / march / step), it selects the ground truth's MDO keyframes (as training
does), encodes them (posterior mean) and decodes, and reports per window

* ``stride``: the range over the keyframes of the ankles' front-to-back separation in the body frame
  (HumanML3D's root-relative positions face +z; left minus right ankle), in metres, for the true
  keyframes and the reconstruction, and ``kept`` = reconstructed / true (a walk alternates about
  +-0.3 m, so its range is about 0.4-0.7 m; the mean pose gives 0);
* ``pose cm``: root-aligned MPJPE of the reconstructed keyframe poses, each pose alone
  (:func:`salad_core.keymotion.models.pose_joints`);
* ``index``: mean absolute error of the decoded keyframe frames.

Run it on a keyframe VAE stage as soon as it is trained (``--kf-vae RUN/kf_vae``): if the median ``kept``
is low, a PST trained on that latent space cannot make steps either.

Example::

    python lab/scripts/keymotion/keymotion_keyframe_check.py --data ~/salad-runs/v4/corpus --limit 40            # shipped 0.1
    python lab/scripts/keymotion/keymotion_keyframe_check.py --data ~/salad-runs/v4/corpus --kf-vae ~/salad-runs/v4/keymotion/kf_vae
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np
import torch

from salad_core.keymotion.models import pose_joints
from salad_core.keymotion.selection import select_keyframes

L_ANKLE, R_ANKLE = 7, 8            # HumanML3D joints; root-relative positions hold joints 1..21
GAITS = ("walk", "run", "jog", "march", "step")


def load_keyframe_vae(weights: str | None, kf_vae: str | None):
    """The keyframe VAE of a KeyMotion pipeline folder (default: the shipped one) or of a training stage."""
    if kf_vae is not None:
        from salad_core.io import load_model
        from salad_core.train.assemble import run_checkpoint

        path = Path(kf_vae)
        stem = run_checkpoint(path) if path.is_dir() else path.with_suffix("")
        model, _, _ = load_model(stem)
        return model.eval()
    from salad_core.keymotion.pipeline import KeyMotionPipeline

    return KeyMotionPipeline.from_pretrained(weights).kf_vae


def forward_separation(features: np.ndarray) -> np.ndarray:
    """Left minus right ankle along the body's facing axis (+z of the root-relative positions), metres:
    de-normalised features ``(K, D)`` -> ``(K,)``."""
    ric = features[:, 4:4 + 21 * 3].reshape(len(features), 21, 3)
    return ric[:, L_ANKLE - 1, 2] - ric[:, R_ANKLE - 1, 2]


@torch.no_grad()
def check_window(vae, x: np.ndarray) -> dict:
    """Reconstruct the MDO keyframes of one window ``x (N, D)`` (de-normalised features)."""
    k = vae.config.num_keyframes
    n = len(x)
    idx = torch.from_numpy(select_keyframes(x, k, "mdo").astype(np.int64))[None]         # (1, K)
    true = torch.from_numpy(x)[None].gather(1, idx[..., None].expand(-1, -1, x.shape[-1]))  # (1, K, D)
    lengths = torch.tensor([n])
    enc = vae.encode(vae.norm.normalize(true), vae.positions_of(idx, lengths), sample=False)
    dec = vae.decode(enc.mu)
    rec = vae.norm.denormalize(dec.keyframes)
    rec_idx = vae.indices_of(dec.positions, lengths)
    pt, pr = pose_joints(true, vae.skeleton)[0], pose_joints(rec, vae.skeleton)[0]            # (K, J, 3)
    pose = ((pr - pr[:, :1]) - (pt - pt[:, :1])).norm(dim=-1).mean().item()
    s_true, s_rec = np.ptp(forward_separation(true[0].numpy())), np.ptp(forward_separation(rec[0].numpy()))
    return {"frames": n, "stride_true_m": float(s_true), "stride_rec_m": float(s_rec),
            "kept": float(s_rec / s_true) if s_true > 1e-6 else float("nan"), "pose_cm": pose * 100,
            "index_frames": float((rec_idx - idx).abs().float().mean())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", default=None, help="KeyMotion pipeline folder or training root (default: shipped)")
    ap.add_argument("--kf-vae", default=None, help="a keyframe-VAE training stage (run folder or checkpoint stem)")
    ap.add_argument("--data", required=True, help="procedural corpus (HumanML3D layout); never the real sample")
    ap.add_argument("--split", default="test")
    ap.add_argument("--limit", type=int, default=40, help="windows at most")
    ap.add_argument("--words", nargs="+", default=list(GAITS), help="keep windows whose caption has one of these")
    ap.add_argument("--json", default=None, help="write the per-window rows and the summary here")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    from salad_core.data.dataset import MotionTextDataset

    vae = load_keyframe_vae(args.weights, args.kf_vae)
    ds = MotionTextDataset(args.data, args.split, max_length=vae.config.max_length, random_crop=False,
                           normalize=False)
    pattern = re.compile(r"\b(" + "|".join(map(re.escape, args.words)) + r")", re.IGNORECASE)
    rows = []
    for i in range(len(ds)):
        if len(rows) >= args.limit:
            break
        item = ds[i]
        if not pattern.search(item["caption"]):
            continue
        n = int(item["length"])
        if n < vae.config.num_keyframes:
            continue
        row = check_window(vae, np.asarray(item["motion"][:n], dtype=np.float32))
        row["caption"] = item["caption"]
        rows.append(row)
    if not rows:
        raise SystemExit(f"no {args.split} window of {args.data} has a caption with {args.words}")
    med = {key: float(np.nanmedian([r[key] for r in rows]))
           for key in ("stride_true_m", "stride_rec_m", "kept", "pose_cm", "index_frames")}
    steps_true = [r for r in rows if r["stride_true_m"] >= 0.4]
    summary = {"windows": len(rows), **{f"median_{k}": v for k, v in med.items()},
               "windows_stepping": len(steps_true),
               "stepping_kept_0.4m": sum(r["stride_rec_m"] >= 0.4 for r in steps_true)}
    print(f"keyframe VAE {args.kf_vae or args.weights or 'shipped KeyMotion'}, {len(rows)} {args.split} windows "
          f"naming {'/'.join(args.words)}:")
    print(f"  stride (ankle front-back range over the keyframes): true median {med['stride_true_m']:.2f} m, "
          f"reconstructed {med['stride_rec_m']:.2f} m, kept {med['kept']:.2f}")
    print(f"  windows whose true keyframes step (>= 0.4 m): {len(steps_true)}; reconstructions that still do: "
          f"{summary['stepping_kept_0.4m']}")
    print(f"  keyframe pose error (root-aligned) median {med['pose_cm']:.1f} cm, keyframe frames off by "
          f"{med['index_frames']:.1f} on average")
    if args.json:
        Path(args.json).write_text(json.dumps({"summary": summary, "windows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
