#!/usr/bin/env python
"""Score shipped ablation denoisers again with a stage's protocol but another sampler setting (issue 24).

The staged study scores its denoisers with 10 DDIM steps (a CPU budget); the paper samples with 50. This probe
takes the protocol of one stage's evaluation file (split, crops, replications, seed, guidance), changes only the
sampler steps or the guidance weight, scores the named variants of the shipped ablation folder and prints each row
and the paired advantage of the first variant over each other one (the same crops, captions and noise)::

    python lab/scripts/ablations/ablation_sampler_probe.py --stage-eval salad_core/weights/ablations/evaluations/denoisers@8000.json \\
        --variants full x0 --num-steps 50 --data CORPUS_2.4 --out lab/records/ablations_v2/sampler_probe.json
    python lab/scripts/ablations/ablation_sampler_probe.py --stage-eval salad_core/weights/ablations/evaluations/denoisers@8000.json \\
        --variants full no_st x0 --guidance 1 --data CORPUS_2.4 --out lab/records/ablations_v2/sampler_probe.json
    python lab/scripts/ablations/ablation_sampler_probe.py --stage-eval salad_core/weights/ablations/evaluations/denoisers@8000.json \\
        --variants full no_st --interval 0-0.5 --data CORPUS_2.4 --out lab/records/ablations_v2/sampler_probe.json

``--interval LO-HI`` applies the guidance only at the sampler steps whose timestep ``t`` has ``LO <= t / T <= HI``
(the conditional prediction alone elsewhere; the record lists the guided timesteps), ``--rescale PHI`` rescales the
guided prediction to the conditional one's spread (:class:`salad_core.sampling.Guidance`).
The shipped models must be those of the stage (the card names the steps; checked against ``index.json``).
The record keeps the command, so the probe can be made again on a new machine.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "lab"))   # salad_lab


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--stage-eval", type=Path, required=True, help="a denoiser stage's evaluation file")
    ap.add_argument("--variants", nargs="+", required=True, help="shipped denoiser variants; the first is compared "
                    "with each other one")
    ap.add_argument("--num-steps", type=int, default=None, help="sampler steps (default: the stage's)")
    ap.add_argument("--guidance", type=float, default=None, help="classifier-free guidance weight (default: the "
                    "stage's); 1 samples with the conditional prediction alone")
    ap.add_argument("--interval", default=None, metavar="LO-HI", help="guide only the steps with LO <= t/T <= HI "
                    "(e.g. 0-0.5: the low-noise half; default: every step)")
    ap.add_argument("--rescale", type=float, default=0.0, metavar="PHI", help="guidance rescale phi in [0, 1] "
                    "(default 0: plain classifier-free guidance)")
    ap.add_argument("--data", type=Path, required=True, help="the corpus the stage was scored on")
    ap.add_argument("--ablations", type=Path, default=None, help="shipped ablation folder (default: salad's own)")
    ap.add_argument("--out", type=Path, required=True, help="JSON record (one entry per sampler setting, merged)")
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args(argv)

    import torch

    if args.threads:
        torch.set_num_threads(args.threads)
    from salad_lab import list_ablations, load_ablation_pipeline
    from salad_lab.orderings import TABLE_METRICS, paired_advantage
    from salad_lab.probes import stage_settings
    from salad_core.eval import evaluate_generator
    from salad_core.eval.guidance_sweep import FixedGuidance, guidance_label
    from salad_core.eval.length_buckets import LengthBucketed
    from salad_core.eval.train_evaluator import load_packaged_evaluator
    from salad_core.sampling import Guidance, make_scheduler
    from salad_core.text import load_text_encoder

    if args.num_steps is not None and args.num_steps < 1:
        raise SystemExit(f"--num-steps must be at least 1, got {args.num_steps}")
    if args.guidance is not None and not args.guidance >= 1.0:
        raise SystemExit(f"--guidance must be a weight >= 1 (1: no guidance), got {args.guidance}")
    interval = None
    if args.interval is not None:
        try:
            interval = tuple(float(v) for v in args.interval.split("-"))
        except ValueError:
            interval = ()
        if len(interval) != 2:
            raise SystemExit(f"--interval {args.interval!r}: give LO-HI, e.g. 0-0.5")
    stage = json.loads(args.stage_eval.read_text())
    try:
        base = stage_settings(stage, "denoiser")
    except ValueError as err:
        raise SystemExit(f"{args.stage_eval} is not a denoiser stage: {err}") from None
    args.num_steps = base.num_steps if args.num_steps is None else args.num_steps
    guidance = base.guidance_scale if args.guidance is None else args.guidance
    settings = dataclasses.replace(base, num_steps=args.num_steps, guidance_scale=guidance)
    try:
        full_guidance = Guidance(guidance, args.rescale, interval)
    except ValueError as err:
        raise SystemExit(f"--interval/--rescale: {err}") from None
    refined = full_guidance.rescale > 0 or full_guidance.interval is not None
    at_stage = f"{base.num_steps} steps, w {base.guidance_scale:g}"
    probe = f"{args.num_steps} steps, " + (guidance_label(full_guidance) if refined else f"w {guidance:g}")
    index = list_ablations(args.ablations)
    for v in args.variants:
        if v not in stage["rows"]:
            raise SystemExit(f"variant {v!r} is not a row of {args.stage_eval} (rows: {sorted(stage['rows'])})")
    for v in args.variants:
        if v not in index or index[v]["steps"] != stage["steps"]:
            got = index.get(v, {}).get("steps")
            raise SystemExit(f"shipped {v!r} has {got} steps, the stage {stage['steps']}: ship that stage first")
    evaluator = load_packaged_evaluator()[0]
    text_encoder = load_text_encoder("minilm")
    rows, guided_timesteps = {}, None
    for v in args.variants:
        t0 = time.perf_counter()
        pipe = load_ablation_pipeline(v, args.ablations, text_encoder=text_encoder)
        if guided_timesteps is None:
            sched = make_scheduler(pipe.diffusion, settings.solver or pipe.solver)
            sched.set_timesteps(args.num_steps)
            n_train = int(sched.config.num_train_timesteps)
            guided_timesteps = [int(t) for t in sched.timesteps if full_guidance.active(float(t), n_train)]
        gen = LengthBucketed(FixedGuidance(pipe, full_guidance) if refined else pipe)
        res = evaluate_generator(gen, args.data, evaluator, settings, name=index[v]["label"],
                                 weights=f"ablation {v} at {stage['steps']} steps, {probe}")
        values = {m: [float(x) for x in res.values[m]] for m in TABLE_METRICS["denoiser"]}
        summary = res.summary()
        rows[v] = {"values": values, "summary": {m: [float(x) for x in summary[m]] for m in values},
                   "at_stage": {m: stage["rows"][v]["summary"][m] for m in values}}
        print(f"{v}: {time.perf_counter() - t0:.0f} s;", ", ".join(
            f"{m} {s[0]:.3f} ± {s[1]:.3f} (at {at_stage} {rows[v]['at_stage'][m][0]:.3f})"
            for m, s in rows[v]["summary"].items()))
    first = args.variants[0]
    paired = {}
    for b in args.variants[1:]:
        for m in TABLE_METRICS["denoiser"]:
            mean, half = paired_advantage(rows[first]["values"][m], rows[b]["values"][m], m)
            at = paired_advantage(stage["rows"][first]["values"][m], stage["rows"][b]["values"][m], m)
            paired[f"{first} vs {b}, {m}"] = {"probe": [mean, half], "at_stage": list(at)}
            print(f"{first} vs {b}, {m}: paired advantage {mean:+.3f} ± {half:.3f} at {probe} "
                  f"({at[0]:+.3f} ± {at[1]:.3f} at {at_stage})")
    record = json.loads(args.out.read_text()) if args.out.is_file() else {}
    key = f"{stage['stage']}, {args.num_steps} steps"
    if refined:
        key += f", {guidance_label(full_guidance)}"
    elif guidance != base.guidance_scale:
        key += f", w {guidance:g}"
    record[key] = {
        "stage_eval": str(args.stage_eval), "num_steps": args.num_steps, "guidance_scale": guidance,
        "guidance_rescale": full_guidance.rescale,
        "guidance_interval": list(full_guidance.interval) if full_guidance.interval else None,
        "guided_timesteps": guided_timesteps,
        "stage_guidance_scale": base.guidance_scale,
        "stage_num_steps": stage["settings"]["num_steps"], "settings": dataclasses.asdict(settings),
        "rows": rows, "paired": paired,
        "command": "python lab/scripts/ablations/ablation_sampler_probe.py " + " ".join(
            shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(record, indent=1) + "\n")
    print(f"recorded in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
