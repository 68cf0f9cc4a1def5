#!/usr/bin/env python
"""Does KeyMotion slow a one-action prompt down when it is asked for longer? (a probe; nothing is chosen from it)

The keyframe VAE encodes keyframe positions normalised to the motion's length, so a keyframe latent has no time
scale: if the PST gives a one-action caption the same latent at every length, the action lasts in proportion to
the length asked for. Two measures:

* ``stretch``: for a few prompts, at 40 .. 196 frames (4 seeds, the pipeline's joints), the time the action takes
  (jumps: the pelvis above half its rise; waves and kicks: the wrist or ankle faster than 0.5 m/s) and the peak speed
  of that joint (95th percentile; the pelvis's vertical speed for jumps). A time growing with the length is a slowed
  action or a repeated one; a peak speed falling with the length is a slowed one.
* ``chain``: with ``--chain FILE`` (a ``keymotion_flight_chain.py --out`` record), its stages' flight fit split by
  clip length: whether the true keyframes, the keyframe VAE's and the generated motion at the clip's own length
  and caption fly at every length.

    OMP_NUM_THREADS=1 python lab/scripts/keymotion/keymotion_time_stretch_probe.py [--other NAME=DIR] [--salad] [--chain FILE] [--json OUT]
"""
import argparse
import json
import sys
from pathlib import Path

import numpy as np

PROMPTS = ["a man jumps forward", "a person jumps", "a person waves with the right hand",
           "a person kicks with the right leg"]
LENGTHS = (40, 60, 90, 120, 160, 196)
#: HumanML3D joints: pelvis, right ankle, right wrist
PELVIS, R_ANKLE, R_WRIST = 0, 8, 21
FPS = 20.0


def action_seconds(joints: np.ndarray, prompt: str) -> float:
    """Seconds the prompt's action takes in ``joints`` ``(N, 22, 3)`` (see the module docstring)."""
    if "jump" in prompt:
        y = joints[:, PELVIS, 1] - joints[:, PELVIS, 1].min()
        return float((y > 0.5 * y.max()).sum() / FPS)
    k = R_WRIST if "wave" in prompt else R_ANKLE
    speed = np.linalg.norm(np.diff(joints[:, k], axis=0), axis=-1) * FPS
    return float((speed > 0.5).sum() / FPS)


def peak_speed(joints: np.ndarray, prompt: str) -> float:
    """95th percentile (m/s) of the speed of the prompt's joint in ``joints`` ``(N, 22, 3)``: the pelvis's vertical
    speed for a jump, the right wrist's or ankle's speed otherwise. A motion played slower moves slower; one that
    repeats its action at its pace does not."""
    if "jump" in prompt:
        return float(np.percentile(np.abs(np.diff(joints[:, PELVIS, 1])) * FPS, 95))
    k = R_WRIST if "wave" in prompt else R_ANKLE
    return float(np.percentile(np.linalg.norm(np.diff(joints[:, k], axis=0), axis=-1) * FPS, 95))


def stretch(folder, seeds: int) -> dict:
    """Action seconds per prompt and length; ``folder`` a KeyMotion folder (None: the shipped one) or ``"salad"``
    (the shipped SALAD, whose latent has one token per 4 frames: a control)."""
    if folder == "salad":
        from salad_core.pipeline import SaladPipeline

        pipe = SaladPipeline.from_pretrained()
    else:
        from salad_core.keymotion.pipeline import KeyMotionPipeline

        pipe = KeyMotionPipeline.from_pretrained(folder)
    out = {}
    for prompt in PROMPTS:
        row = {}
        for length in LENGTHS:
            motions = [np.asarray(pipe([prompt], lengths=length if folder != "salad" else length // 4 * 4, seed=s).joints[0])[:length] for s in range(seeds)]
            row[length] = {"seconds": float(np.mean([action_seconds(m, prompt) for m in motions])),
                           "peak_speed": float(np.mean([peak_speed(m, prompt) for m in motions]))}
        out[prompt] = row
    return out


def chain_by_length(path: Path, bins=((0, 90), (90, 140), (140, 400))) -> dict:
    reports = json.loads(path.read_text())["reports"]
    table = {}
    for lo, hi in bins:
        row = {}
        for stage, rows in reports.items():
            sel = [r for r in rows if lo <= r["frames"] < hi]
            fits = [r["flight_fit_accel_ms2"] for r in sel if r.get("flight_fit_accel_ms2") is not None]
            row[stage] = {"clips": len(sel), "flight_fit": float(np.median(fits)) if fits else None,
                          "with_flight": int(sum(r["flight_segments"] > 0 for r in sel))}
        table[f"{lo}-{hi}"] = row
    return table


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument("--other", action="append", default=[], help="NAME=DIR: another KeyMotion folder (repeatable)")
    ap.add_argument("--salad", action="store_true", help="also the shipped SALAD (a control)")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--chain", type=Path, default=None, help="a keymotion_flight_chain.py record to split by length")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    record = {"lengths": list(LENGTHS), "seeds": args.seeds, "stretch": {}}
    folders = [("0.2", None)] + [tuple(o.split("=", 1)) for o in args.other] + ([("salad", "salad")] if args.salad else [])
    for name, folder in folders:
        record["stretch"][name] = res = stretch(folder, args.seeds)
        for prompt, row in res.items():
            print(f"{name:7s} {prompt:36s} " + "  ".join(f"{n}f {v['seconds']:.2f}s {v['peak_speed']:.2f}m/s"
                                                         for n, v in row.items()), flush=True)
    if args.chain is not None:
        record["chain_by_length"] = chain_by_length(args.chain)
        for span, row in record["chain_by_length"].items():
            print(f"clips of {span} frames: " + " | ".join(
                f"{stage} n={v['clips']} fit={v['flight_fit'] if v['flight_fit'] is None else round(v['flight_fit'], 2)}"
                f" flying={v['with_flight']}" for stage, v in row.items()))
    if args.json is not None:
        args.json.write_text(json.dumps(record, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
