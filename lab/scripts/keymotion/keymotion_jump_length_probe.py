#!/usr/bin/env python
"""Does KeyMotion's flight depend on the length it is asked for? (a probe; nothing is chosen from it)

The physics benchmark asks every prompt for 120 frames (6 s); the corpus's jump clips are shorter. This generates the
benchmark's four jump prompts and 12 validation jump captions (those of ``keymotion_guidance_levers.py``) at 60 and
at 120 frames, 6 seeds, for KeyMotion 0.2 and a second folder, and prints the median per-segment flight fit of the
fitted joints (gravity -9.81 m/s^2), the mean pelvis rise and the motions with a flight found.

    OMP_NUM_THREADS=1 python lab/scripts/keymotion/keymotion_jump_length_probe.py [--data CORPUS] [--other DIR]
"""
import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from keymotion_guidance_levers import flight_fit, jump_prompts, measure  # noqa: E402

BENCH = ['a person jumps', 'a man is jumping high', 'a person hops in place', 'a man jumps forward']


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument("--data", type=Path, default=Path("/tmp/fo/corpus27"), help="corpus 2.7 (validation captions)")
    ap.add_argument("--other", default=None, help="a second KeyMotion folder beside the shipped one")
    ap.add_argument("--lengths", type=int, nargs="+", default=[60, 120])
    ap.add_argument("--seeds", type=int, default=6)
    args = ap.parse_args()
    from salad_core.keymotion.pipeline import KeyMotionPipeline

    torch.set_num_threads(1)
    val = [p["caption"] for p in jump_prompts(args.data, "val", 12, 196)]
    folders = [("0.2", None)] + ([("other", args.other)] if args.other else [])
    for name, folder in folders:
        pipe = KeyMotionPipeline.from_pretrained(folder)
        for label, prompts in (("bench", BENCH), ("val", val)):
            for length in args.lengths:
                feats = []
                for seed in range(args.seeds):
                    out = pipe(prompts, lengths=length, seed=seed, recovery="positions")
                    feats += [out.features[i, :n] for i, n in enumerate(out.lengths)]
                rows = measure(feats, pipe.skeleton)["fit"]
                print(f"{name} {label:5s} {length:3d} frames: flight fit {flight_fit(rows):6.2f}  rise "
                      f"{np.mean([r['jump_rise_m'] for r in rows]):.3f}  with flight "
                      f"{sum(r['flight_segments'] > 0 for r in rows)}/{len(rows)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
