#!/usr/bin/env python
"""Does a KeyMotion pipeline generate the side its prompt names, before any sampling-time repair? (issue 66)

Generates side-naming prompts (arms, legs, turns, sidesteps; each in its left and its right form) for several
seeds with ``side_check=False`` and grades each motion with :func:`salad_core.side_check.cue_verdict` against every
side cue of its prompt: *kept* (every cue's side leads beyond its margin), *broken* (some cue has the other side
leading and none is kept: what the side check mirrors), *unclear* (the rest). A generator that ignores the side
breaks about as many as it keeps; ``same-seed pairs`` counts the seeds where the left and the right prompt give
motions with the same measured side (the side taken from the noise).

    python lab/scripts/keymotion/keymotion_side_generation.py [--weights DIR ...] [--seeds 6] [--out JSON]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[3]

#: right-side prompts; each is also generated with its side words swapped
PROMPTS_RIGHT = (
    "a man waves his right hand", "a person raises his right arm", "a man punches with his right hand",
    "a man kicks with his right leg", "a woman lifts her right knee", "a person turns right",
    "a man steps sideways to the right", "a person walks in a circle to the right",
)


def grade(pipe, prompt_sets, seeds, length, guidance=None):
    """Each set of prompts is one call per seed (row j of every set gets the same noise)."""
    from salad_core.side_check import cue_verdict, side_cues, side_measure

    rows = []
    for seed in seeds:
        for prompts in prompt_sets:
            out = pipe(list(prompts), lengths=length, seed=seed, side_check=False, guidance_scale=guidance)
            for text, joints in zip(prompts, out.joints):
                cues = side_cues(text)
                verdicts = [cue_verdict(c, joints, pipe.skeleton) for c in cues]
                kept = bool(verdicts) and min(verdicts) > 0
                broken = bool(verdicts) and min(verdicts) < 0 and max(verdicts) <= 0
                measure = float(side_measure(joints, cues[0].kind, pipe.skeleton)) if cues else float("nan")
                rows.append({"prompt": text, "seed": seed, "kept": kept, "broken": broken, "measure": measure})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", type=Path, nargs="*", default=[None], help="KeyMotion folders (default: shipped)")
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--length", type=int, default=120)
    ap.add_argument("--guidance", type=float, default=None, help="guidance weight (default: each pipeline's)")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    sys.path.insert(0, str(REPO))
    from salad_core.keymotion import KeyMotionPipeline
    from salad_core.keymotion.sides import mirror_side_words

    lefts = [mirror_side_words(r) for r in PROMPTS_RIGHT]
    prompts = list(PROMPTS_RIGHT) + lefts
    report = {"prompts": prompts, "seeds": args.seeds, "length": args.length, "guidance": args.guidance,
              "models": {}}
    for weights in args.weights:
        pipe = KeyMotionPipeline.from_pretrained(weights)
        rows = grade(pipe, (PROMPTS_RIGHT, lefts), range(args.seeds), args.length, args.guidance)
        kept = sum(r["kept"] for r in rows)
        broken = sum(r["broken"] for r in rows)
        by = {(r["prompt"], r["seed"]): r["measure"] for r in rows}
        same = sum(1 for r in PROMPTS_RIGHT for s in range(args.seeds)
                   if np.sign(by[(r, s)]) == np.sign(by[(mirror_side_words(r), s)]))
        name = str(weights or "shipped")
        report["models"][name] = {"motions": len(rows), "kept": kept, "broken": broken,
                                  "unclear": len(rows) - kept - broken,
                                  "same_side_seed_pairs": same, "pairs": len(PROMPTS_RIGHT) * args.seeds,
                                  "side_canonical": bool(pipe.pst.config.side_canonical), "rows": rows}
        print(f"{name}: kept {kept} / broken {broken} / unclear {len(rows) - kept - broken} of {len(rows)}; "
              f"left and right prompt with the same measured side in {same} of {len(PROMPTS_RIGHT) * args.seeds} "
              "seed pairs", flush=True)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
