#!/usr/bin/env python
"""Which guidance weight should a KeyMotion pipeline sample at, judged on its jumps' flight and its gaits' feet?

A new PST (e.g. the side-canonical scratch PST) need not share KeyMotion 0.2's best weight (7.5). This sweeps
guidance weights for one or more KeyMotion folders on VALIDATION prompts only (the corpus's ``val`` captions of
``keymotion_guidance_levers.py``: the shortest jump captions and forward walk / run / jog captions, each at its
clip's length) and reports, per folder and weight, the fitted joints' stance sliding on the gaits and the median
per-segment flight fit of the jumps (95 % bootstrap intervals over prompts), the gaits' stride and the jumps' rise.

Rule (fixed before the run): the reference is the first folder at ``--reference-scale`` (KeyMotion 0.2 at 7.5).
For every other folder, a weight is eligible if its sliding and its flight fit each lie inside the reference's 95 %
interval or on its better side (slide lower, flight closer to -9.81), with stride and rise >= 80 % of the
reference's; among the eligible ones the lowest score slide / slide(ref) + |fit - g| / |fit(ref) - g| wins; with
none eligible the folder has no weight that keeps the reference's feet and flight.

    OMP_NUM_THREADS=1 .venv/bin/python lab/scripts/keymotion/keymotion_weight_sweep.py --data CORPUS \\
        --weights salad_core/weights/keymotion RUNS/km_v3_pst/pipe --scales 5 7.5 10 12.5 --seeds 0 1 2 3 4 5 \\
        --out lab/records/keymotion/weight_sweep.json
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from keymotion_guidance_levers import (GRAVITY, generate, gait_prompts, jump_prompts, measure,  # noqa: E402
                                        summarise)

RULE = ("reference = first folder at --reference-scale; eligible: fitted slide and flight fit each inside the "
        "reference's 95 % interval or better, stride and rise >= 80 % of the reference's; lowest score "
        "slide / slide(ref) + |fit - g| / |fit(ref) - g| wins")


def eligible(row: dict, ref: dict) -> bool:
    """``row`` / ``ref``: the fitted summaries of :func:`summarise` (``["fit"]``)."""
    slide_ok = row["slide_ms"] <= ref["slide_ci"][1]
    lo, hi = ref["flight_fit_ci"]
    fit = row["flight_fit_ms2"]
    fit_ok = lo <= fit <= hi or abs(fit - GRAVITY) <= abs(ref["flight_fit_ms2"] - GRAVITY)
    return bool(slide_ok and fit_ok and row["stride_m"] >= 0.8 * ref["stride_m"]
                and row["rise_m"] >= 0.8 * ref["rise_m"])


def score(row: dict, ref: dict) -> float:
    return row["slide_ms"] / ref["slide_ms"] + abs(row["flight_fit_ms2"] - GRAVITY) / abs(ref["flight_fit_ms2"] - GRAVITY)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, type=Path, help="the corpus the weights were trained on (2.7)")
    ap.add_argument("--weights", type=Path, nargs="+", required=True, help="KeyMotion folders; the first is the reference")
    ap.add_argument("--scales", type=float, nargs="+", default=[5.0, 7.5, 10.0, 12.5])
    ap.add_argument("--reference-scale", type=float, default=7.5)
    ap.add_argument("--jumps", type=int, default=12)
    ap.add_argument("--gaits", type=int, default=12)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4, 5])
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    import torch

    from salad_core.keymotion.pipeline import KeyMotionPipeline
    from salad_core.sampling import Guidance

    torch.set_num_threads(args.threads)
    t0 = time.perf_counter()
    rows = []
    for i, folder in enumerate(args.weights):
        pipe = KeyMotionPipeline.from_pretrained(folder)
        jumps = jump_prompts(args.data, "val", args.jumps, pipe.max_length)
        gaits = gait_prompts(args.data, "val", args.gaits, pipe.max_length)
        prompts = jumps + gaits
        scales = [args.reference_scale] if i == 0 else args.scales
        for w in scales:
            t = time.perf_counter()
            _, feats = generate(pipe, prompts, args.seeds, Guidance(w), args.steps)
            n = len(prompts)
            by_seed = [feats[s * n:(s + 1) * n] for s in range(len(args.seeds))]
            jf = [f for chunk in by_seed for f in chunk[: len(jumps)]]
            gf = [f for chunk in by_seed for f in chunk[len(jumps):]]
            phys = summarise(measure(gf, pipe.skeleton), measure(jf, pipe.skeleton), len(gaits), len(jumps))
            rows.append({"weights": str(folder), "scale": w, "physics": phys,
                         "seconds": round(time.perf_counter() - t, 1)})
            f = phys["fit"]
            print(f"{folder} w {w}: slide {f['slide_ms']:.3f} [{f['slide_ci'][0]:.3f}, {f['slide_ci'][1]:.3f}], "
                  f"flight {f['flight_fit_ms2']:.2f} [{f['flight_fit_ci'][0]:.2f}, {f['flight_fit_ci'][1]:.2f}], "
                  f"stride {f['stride_m']:.2f}, rise {f['rise_m']:.3f}, flights {f['jumps_with_flight']}/{f['jumps']}",
                  flush=True)
    ref = rows[0]["physics"]["fit"]
    chosen = {}
    for folder in args.weights[1:]:
        mine = [r for r in rows if r["weights"] == str(folder)]
        ok = [r for r in mine if eligible(r["physics"]["fit"], ref)]
        for r in mine:
            r["eligible"] = r in ok
            r["score"] = score(r["physics"]["fit"], ref)
        best = min(ok, key=lambda r: r["score"]) if ok else None
        chosen[str(folder)] = None if best is None else best["scale"]
        print(f"{folder}: chosen weight {chosen[str(folder)]}")
    result = {"question": "which guidance weight keeps the reference's feet and flight?", "rule": RULE,
              "data": str(args.data), "seeds": args.seeds, "steps": args.steps, "rows": rows, "chosen": chosen,
              "seconds": round(time.perf_counter() - t0, 1)}
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=1) + "\n")
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
