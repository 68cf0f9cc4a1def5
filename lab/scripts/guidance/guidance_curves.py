#!/usr/bin/env python
"""How guidance moves the generated latents and the jump heights (issue 20, lab/docs/plausibility.md).

    python lab/scripts/guidance/guidance_curves.py --data CORPUS [--weights W] --scales 1,4.5,7.5 [--sections spread jumps]

* ``spread``: the benchmark prompts (:data:`salad_core.eval.physics_prompts.PROMPTS`, one seed, 120 frames) are
  generated at each weight and their final latents (the diffusion's space) compared with the posterior means of the
  first ``--clips`` test clips of ``--data``: the root-mean-square deviation about the clips' mean, relative to the
  clips' own (1 = the data's spread; the decoder was trained near 1).
* ``jumps``: the benchmark's jump prompts, ``--seeds`` seeds each, pelvis rise (m, :func:`measure_motion`'s
  ``jump_rise_m`` of the raw joints) at each weight, beside the corpus's reference range.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))

JUMP_PROMPTS = ("a man is jumping high", "a person does jumping jacks", "a person jumps")


def relative_spread(latents, reference) -> float:
    """RMS deviation of ``latents`` (``(M, C)``) about ``reference``'s (``(R, C)``) mean, over ``reference``'s own."""
    ref = np.asarray(reference, np.float64)
    mu = ref.mean(0)
    return float(np.sqrt(((np.asarray(latents, np.float64) - mu) ** 2).mean()) / np.sqrt(((ref - mu) ** 2).mean()))


def parse_scales(text: str) -> list[float]:
    """The ``--scales`` list; a bad one ends the script with the reason."""
    from salad_core.cli.eval import comma_floats

    try:
        return comma_floats("--scales", text)
    except ValueError as err:
        raise SystemExit(str(err)) from None


def encoded_clips(pipe, root: Path, clips: int) -> np.ndarray:
    """``(R, C)`` posterior means (diffusion space) of the first ``clips`` test clips, all frames and parts."""
    ids = (root / "test.txt").read_text().split()[:clips]
    rows = []
    for i in ids:
        f = np.load(root / "new_joint_vecs" / f"{i}.npy").astype(np.float32)
        f = f[: len(f) - len(f) % pipe.skeleton.unit_length]
        z = pipe.encode_motion(f)[0].numpy()
        rows.append(z.reshape(-1, z.shape[-1]))
    return np.concatenate(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True, type=Path, help="the procedural corpus (test clips, reference ranges)")
    ap.add_argument("--weights", default=None, help="pipeline folder (default: the shipped weights)")
    ap.add_argument("--scales", default="1,4.5,7.5", help="comma-separated guidance weights")
    ap.add_argument("--sections", nargs="+", default=["spread", "jumps"], choices=["spread", "jumps"])
    ap.add_argument("--num-prompts", type=int, default=None, help="the first N benchmark prompts (default all)")
    ap.add_argument("--clips", type=int, default=200, help="test clips for the data's spread")
    ap.add_argument("--seeds", type=int, default=3, help="seeds per jump prompt")
    ap.add_argument("--steps", type=int, default=50, help="DDIM steps")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)
    scales = parse_scales(args.scales)
    import torch

    from salad_core.eval.physics import measure_motion
    from salad_core.eval.physics_prompts import PROMPTS, corpus_reference_ranges
    from salad_core.pipeline import SaladPipeline

    torch.set_num_threads(args.threads)
    pipe = SaladPipeline.from_pretrained(args.weights)
    if "spread" in args.sections:
        ref = encoded_clips(pipe, args.data, args.clips)
        texts = [p.text for p in PROMPTS][: args.num_prompts]
        print(f"latent spread about the {args.clips} encoded test clips' mean (clips = 1), {len(texts)} prompts, seed 0")
        for w in scales:
            z = []
            for i in range(0, len(texts), 8):
                out = pipe(texts[i:i + 8], lengths=120, seed=0, guidance_scale=w, num_steps=args.steps)
                z.append(out.latents.reshape(-1, out.latents.shape[-1]).numpy())
            print(f"  w {w:g}: {relative_spread(np.concatenate(z), ref):.3f}", flush=True)
    if "jumps" in args.sections:
        ranges = corpus_reference_ranges(args.data)
        print(f"pelvis rise (m) per seed; corpus ranges {ranges}")
        for text in JUMP_PROMPTS:
            for w in scales:
                out = pipe([text] * args.seeds, lengths=120, seed=0, guidance_scale=w, num_steps=args.steps)
                rises = [measure_motion(j).jump_rise_m for j in out.raw_joints]
                print(f"  {text:<30} w {w:g}: {' '.join(f'{r:.2f}' for r in rises)}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
