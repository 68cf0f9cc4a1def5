"""KeyMotion's guidance against the physical-plausibility benchmark: diversity vs prompt checks (issue 22).

Runs :func:`salad_core.eval.physics_prompts.run_benchmark` (the 41 prompts of ``salad eval --physics``,
seeds 0-2 by default) for KeyMotion under several classifier-free guidance settings, and optionally
SALAD at its own default as the seed-diversity reference. Per setting it prints the seed diversity
(cm, world and root-relative), the share of per-prompt action checks passed (does the motion still
do what the prompt says?), foot skating, stride and the jump's flight acceleration. Joints are the
raw position features (``joints_reader('positions')``), as the benchmark reads them.

Example::

    OMP_NUM_THREADS=1 nice -n 19 .venv/bin/python lab/scripts/keymotion/keymotion_guidance_bench.py \
        --settings 7.5 2.5 1 "7.5@0-0.5" --salad --out /tmp/km_guidance.json
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from salad_core.eval.physics import joints_reader, seed_diversity
from salad_core.eval.physics_prompts import PROMPTS, BenchSettings, run_benchmark
from salad_core.keymotion.pipeline import KeyMotionPipeline
from salad_core.sampling import Guidance, parse_guidance_setting


def parse_setting(text: str) -> Guidance:
    """``--settings`` entry -> Guidance (:func:`salad_core.sampling.parse_guidance_setting`); a bad one exits."""
    try:
        return parse_guidance_setting(text)
    except ValueError as err:
        raise SystemExit(str(err)) from None


def root_relative_diversity(motions: dict, name: str, n_prompts: int, seeds: tuple[int, ...]) -> float:
    """Mean over prompts of the seed diversity (cm) of pelvis-relative joints (pose, not path)."""
    vals = []
    for p in range(n_prompts):
        xs = [motions[f"{name}/{p:02d}/{s}"] for s in seeds if f"{name}/{p:02d}/{s}" in motions]
        if len(xs) > 1:
            vals.append(seed_diversity([x - x[:, :1] for x in xs]))
    return float(np.mean(vals))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--weights", default=None, help="KeyMotion pipeline folder or training root (default: shipped)")
    ap.add_argument("--settings", nargs="+", default=["7.5", "2.5", "1"], help="W, W@LO-HI (interval) or W^PHI")
    ap.add_argument("--salad", action="store_true", help="add SALAD (shipped, its default guidance) as reference")
    ap.add_argument("--seeds", type=int, nargs="*", default=[0, 1, 2])
    ap.add_argument("--num-prompts", type=int, default=None)
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    km = KeyMotionPipeline.from_pretrained(args.weights)
    read = joints_reader("positions", km.skeleton)
    generators = {}
    for text in args.settings:
        g = parse_setting(text)

        def gen(texts, lengths, seed, g=g):
            return read(km(texts, lengths=lengths, seed=seed, guidance_scale=g, num_steps=args.steps))
        generators[f"KeyMotion {text}"] = gen
    if args.salad:
        from salad_core.pipeline import SaladPipeline

        pipe = SaladPipeline.from_pretrained()
        sread = joints_reader("positions", pipe.skeleton)
        generators["SALAD"] = lambda texts, lengths, seed: sread(
            pipe(texts, lengths=lengths, seed=[seed] * len(texts), num_steps=args.steps))
    settings = BenchSettings(steps=args.steps, seeds=tuple(args.seeds), num_prompts=args.num_prompts)
    motions: dict = {}
    t0 = time.time()
    report = run_benchmark(generators, settings, motions_sink=motions, log=lambda s: print(s, flush=True))
    n = args.num_prompts or len(PROMPTS)
    rows = {}
    print("| generator | seed diversity cm | root-relative cm | checks passed | foot skate m/s | stride m | "
          "flight acc m/s^2 |")
    print("|---|---|---|---|---|---|---|")
    for name, g in report["generators"].items():
        a = g["aggregate"]
        rr = root_relative_diversity(motions, name, n, settings.seeds)
        rows[name] = {"seed_diversity_cm": a.get("seed_diversity_cm"), "root_relative_cm": rr,
                      "checks": f"{g.get('checks_passed')}/{g.get('checks_total')}",
                      "skate": a.get("skate_mean_ms"), "stride": a.get("stride_m"),
                      "flight_acc": a.get("flight_accel_ms2")}
        r = rows[name]
        fmt = lambda v: "n/a" if v is None else f"{v:.3g}"  # noqa: E731
        print(f"| {name} | {fmt(r['seed_diversity_cm'])} | {rr:.2f} | {r['checks']} | {fmt(r['skate'])} | "
              f"{fmt(r['stride'])} | {fmt(r['flight_acc'])} |")
    print(f"{time.time() - t0:.0f} s")
    if args.out:
        Path(args.out).write_text(json.dumps({"rows": rows, "report": report}, indent=1, default=str) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
