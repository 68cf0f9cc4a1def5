"""Probe: rank a take's span candidates with the pasted prior by how much of the pasted motion they keep.

Two fidelities: the root-relative joint distance (the pose), and the heights above the floor of the pelvis and feet
(:func:`salad_core.attention.ranking.height_distance_cm`: flight and contacts, which the root-relative distance cannot see).

With ``Inpaint(prior="prompt")`` each candidate of a frame span of an inverted take passes the prompt's check far
more often than without (lab/docs/editing.md, "Paste, then harmonise"), but the T2M evaluator's distance ranks them
badly. This probe asks whether a score that does not need the evaluator, the candidate's *prior fidelity* (the
root-relative joint distance between the regenerated span and the same frames of the prompt sampled alone, which is
what was pasted), picks passing candidates: the harmonisation that changed the pasted motion least is taken. Each
candidate's check over the span, seam ratio, evaluator distance and fidelity are recorded; the rankings are computed
from them (nothing is chosen here: a rule for a default needs its own validation run).

    python lab/scripts/editing/inpaint_prior_fidelity_probe.py --tuning 24 --offset 8 --threads 1 \
        --json lab/records/editing/inpaint_prior_fidelity_probe.json

Procedural validation clips only (as ``measure_inpaint.py --tuning``: the same clips, the middle third made to jump,
"fresh g7.5 prior S | fade 8 smooth 100/8", candidates from region seeds 0 .. K-1).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from salad_core.attention import Inpaint
from salad_core.attention.composite import composite_output, seam_jerk_ratio
from salad_core.attention.grounding import ground_edit
from salad_core.attention.ranking import TextMotionScorer, choose_candidate, height_distance_cm
from salad_core.pipeline import SaladPipeline
from salad_core.skeleton import get_skeleton

from measure_inpaint import measure, tuning_takes  # lab/scripts/editing
from _measure_common import start_run  # lab/scripts

TARGET = "a person jumps"


def fidelity_cm(edited: np.ndarray, prior: np.ndarray, span: tuple[int, int], offset: int) -> float:
    """Mean root-relative joint distance (cm) between the edit's span ``edited[span]`` ``(N, J, 3)`` and the prior
    motion's frames ``prior[offset : offset + len(span)]``."""
    a = edited[span[0]:span[1]]
    b = prior[offset:offset + len(a)]
    a, b = a - a[:, :1], b - b[:, :1]
    return float(np.linalg.norm(a - b, axis=-1).mean() * 100)


def rankings(cands: list[dict], bound: float = 1.5) -> dict[str, int]:
    """The candidate each rule picks (index): by fidelity / evaluator distance among the smooth ones (seam ratio at
    most ``bound``; none: the smoothest), seed 0."""
    smooth = [i for i, c in enumerate(cands) if c["seam_ratio"] <= bound]
    pool = smooth or [min(range(len(cands)), key=lambda i: cands[i]["seam_ratio"])]
    return {"seed 0": 0,
            "most faithful among smooth": min(pool, key=lambda i: cands[i]["fidelity_cm"]),
            "least faithful among smooth": max(pool, key=lambda i: cands[i]["fidelity_cm"]),
            "evaluator's closest among smooth": min(pool, key=lambda i: cands[i]["distance"]),
            "vertically most faithful among smooth": min(pool, key=lambda i: cands[i]["vertical_cm"]),
            "vertically least faithful among smooth": max(pool, key=lambda i: cands[i]["vertical_cm"])}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tuning", type=int, default=24)
    ap.add_argument("--offset", type=int, default=8)
    ap.add_argument("--candidates", type=int, default=8)
    ap.add_argument("--strength", type=float, default=0.7)
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    start_run(args.threads)
    pipe, scorer, sk = SaladPipeline.from_pretrained(), TextMotionScorer(), get_skeleton()
    takes = tuning_takes(args.tuning + args.offset, args.frames)[args.offset:]
    cases = []
    t0 = time.perf_counter()
    for it in takes:
        inv = pipe.invert(it["features"], it["prompt"], num_steps=args.steps)
        m = len(it["features"])
        span = (4 * round(m / 12), 4 * round(m / 6))
        cands = []
        for seed in range(args.candidates):
            inp = Inpaint(frames=span, noise="fresh", guidance=7.5, resample=1, candidates=1, seam_bound=None,
                          prior="prompt", prior_strength=args.strength, seed=seed, fade=8, smooth=100.0,
                          smooth_window=8)
            raw = pipe.edit(target=TARGET, inversion=inv, edits=[dataclasses.replace(inp, composite=False)],
                            ground=False)
            out = ground_edit(pipe, composite_output(pipe, raw, [inp]))
            s, e, frames, c = inp.prior_window(m, sk.min_length)
            alone = raw.prior       # the pasted sample: TARGET alone from the region's seed, the edit's guidance
            row = measure(pipe, out, inp, TARGET, sk)
            regen = (s * 4, e * 4)
            cands.append({"seed": seed, "check_span": bool(row["check_span"]), "seam_ratio": row["seam_jerk_ratio"],
                          "fidelity_cm": fidelity_cm(out.edited.joints[0], alone.joints[0], regen, c * 4),
                          "vertical_cm": height_distance_cm(out.edited.joints[0], alone.joints[0][:frames], regen,
                                                            c * 4, sk.name),
                          "_out": out})
        best, dists, _ = choose_candidate([c.pop("_out") for c in cands], Inpaint(frames=span, candidates=len(cands)),
                                          scorer, inverted=True, skeleton=sk.name)
        for c, d in zip(cands, dists):
            c["distance"] = d
        picks = rankings(cands)
        cases.append({"case": it["id"], "span": list(span), "candidates": cands, "picks": picks})
        print(it["id"], " ".join(f"{k}: {cands[i]['check_span']}" for k, i in picks.items()),
              "| passing", sum(c["check_span"] for c in cands), flush=True)
    summary = {name: {"check": sum(cs["candidates"][cs["picks"][name]]["check_span"] for cs in cases),
                      "seams_within_1.5x": sum(cs["candidates"][cs["picks"][name]]["seam_ratio"] <= 1.5
                                               for cs in cases)}
               for name in cases[0]["picks"]}
    print(json.dumps(summary, indent=1), f"{time.perf_counter() - t0:.0f} s")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"strength": args.strength, "target": TARGET, "summary": summary,
                                         "cases": cases}, indent=1))


if __name__ == "__main__":
    main()
