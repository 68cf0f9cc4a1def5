#!/usr/bin/env python
"""Where does KeyMotion lose the flight of a jump and the planted feet of real motion? (issue 22)

For the test clips (or ``--split val``: choosing settings on validation clips keeps the test figures
unbiased) whose caption names an action (default: jumps, not jumping jacks), the motion at every
stage of the generation path (:func:`salad_core.eval.keymotion_roundtrip.generation_chain`): the clip
itself, the MMAE's in-filling of its own MDO keyframes, the same keyframes after the keyframe VAE
(posterior mean), and a motion generated from its caption. Each stage is measured by the physics
benchmark's per-motion measures (raw position joints, :func:`salad_core.eval.physics.measure_motion`):
flight frames, the pelvis's vertical acceleration in flight (ballistic: -9.81 m/s^2), the longest flight,
the pelvis rise, foot skating and floating. ``--recovery fit`` reads the three generated stages' joints after
the skeleton fit (fixed bones, locked feet, a floor: what ``out.joints`` shows) instead of the position features.
``--kf-vae RUN`` measures another keyframe VAE (a training run, e.g. of another latent size) in place of the
weights' own, with their MMAE, before any PST has been trained on its latent: the generated stage is left out.

    python lab/scripts/keymotion/keymotion_flight_chain.py --data CORPUS [--weights DIR] [--kf-vae RUN] [--split test] [--limit 30] [--recovery fit] [--guidance W] [--out chain.json]

CORPUS is the corpus the weights were trained on (its test or validation split: never training clips).
"""
from __future__ import annotations

import argparse
import copy
import json
import sys
from pathlib import Path

import numpy as np

#: Measures reported per stage: (PhysicsReport field, label, statistic over clips).
COLUMNS = (("flight_frames", "flight frames", "mean"), ("flight_accel_ms2", "flight accel (m/s^2)", "median"),
           ("longest_flight_s", "longest flight (s)", "median"), ("jump_rise_m", "pelvis rise (m)", "median"),
           ("skate_mean_ms", "skating (m/s)", "mean"), ("float_mean_cm", "float (cm)", "mean"))
#: Decimals in the markdown table (default 2): skating is a few cm/s, where 2 decimals cannot tell stages apart.
DECIMALS = {"skate_mean_ms": 3, "jump_rise_m": 3}


def clips_with(data: Path, words: list[str], exclude: list[str], limit: int, split: str = "test"
               ) -> list[tuple[str, str]]:
    """``(clip, caption)`` of ``split`` clips with a caption holding one of ``words`` and none of ``exclude``."""
    out = []
    for name in (data / f"{split}.txt").read_text().split():
        lines = (data / "texts" / f"{name}.txt").read_text().splitlines()
        caps = [line.split("#")[0].strip() for line in lines if line.strip()]
        good = [c for c in caps if any(w in c for w in words) and not any(x in c for x in exclude)]
        if good:
            out.append((name, good[0]))
        if len(out) >= limit:
            break
    return out


def summarise(reports: dict[str, list[dict]]) -> dict[str, dict[str, float]]:
    table = {}
    for stage, rows in reports.items():
        table[stage] = {}
        for key, _, stat in COLUMNS:
            v = np.array([r[key] for r in rows], dtype=float)
            v = v[np.isfinite(v)]
            table[stage][key] = float(getattr(np, stat)(v)) if v.size else float("nan")
    return table


def markdown(table: dict[str, dict[str, float]], n: int) -> str:
    head = "| stage (%d clips) | " % n + " | ".join(f"{label} ({stat})" for _, label, stat in COLUMNS) + " |"
    lines = [head, "|---|" + "---:|" * len(COLUMNS)]
    for stage, row in table.items():
        lines.append(f"| {stage} | " + " | ".join(f"{row[k]:.{DECIMALS.get(k, 2)}f}" for k, _, _ in COLUMNS) + " |")
    return "\n".join(lines)


def main(argv=None, *, pipe=None) -> int:
    """``pipe``: a KeyMotionPipeline instead of loading ``--weights`` (tests)."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, type=Path, help="corpus folder")
    ap.add_argument("--split", choices=("test", "val"), default="test", help="the corpus split whose clips are used")
    ap.add_argument("--weights", type=Path, default=None, help="KeyMotion folder (default: the shipped weights)")
    ap.add_argument("--words", nargs="+", default=["jump"], help="caption words that select the clips")
    ap.add_argument("--exclude", nargs="*", default=["jack"], help="caption words that leave a clip out")
    ap.add_argument("--limit", type=int, default=30, help="clips measured")
    ap.add_argument("--seed", type=int, default=0, help="seed of the generated stage")
    ap.add_argument("--recovery", choices=("positions", "fit"), default="positions",
                    help="joints of the generated stages: the position features as they are (default), or after the "
                         "skeleton fit (fixed bones, locked feet, a floor: what out.joints shows)")
    ap.add_argument("--guidance", type=float, default=None,
                    help="guidance weight of the generated stage (default: the pipeline's)")
    ap.add_argument("--kf-vae", type=Path, default=None,
                    help="a keyframe VAE run (folder or checkpoint) measured in place of the weights' own, with their "
                         "MMAE; the generated stage is left out (the weights' PST denoises its own VAE's latent)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None, help="write the per-clip reports and the table here (JSON)")
    args = ap.parse_args(argv)
    if args.limit < 1:
        ap.error(f"--limit {args.limit}: use an integer >= 1")
    if not (args.data / f"{args.split}.txt").is_file():
        ap.error(f"--data {args.data} has no {args.split}.txt")
    import torch

    from salad_core.eval.keymotion_roundtrip import CHAIN_STAGES, generation_chain
    from salad_core.eval.physics import measure_motion
    from salad_core.keymotion.pipeline import KeyMotionPipeline

    torch.set_num_threads(args.threads)
    pipe = pipe if pipe is not None else KeyMotionPipeline.from_pretrained(args.weights)
    if args.kf_vae is not None:
        from salad_core.keymotion.train import load_frozen_kf_vae

        vae, own = load_frozen_kf_vae(args.kf_vae, pipe.device), pipe.kf_vae.config
        if (vae.config.num_keyframes, vae.config.skeleton) != (own.num_keyframes, own.skeleton):
            ap.error(f"--kf-vae {args.kf_vae}: {vae.config.num_keyframes} keyframes of {vae.config.skeleton!r}, the "
                     f"weights' VAE {own.num_keyframes} of {own.skeleton!r}")
        pipe = copy.copy(pipe)                         # the caller's pipeline keeps its own VAE
        pipe.kf_vae = vae                              # the PST is not called (generate=False below)
    stages = [s for s in CHAIN_STAGES if args.kf_vae is None or s != "generated"]
    clips = clips_with(args.data, args.words, args.exclude, args.limit, args.split)
    if not clips:
        ap.error(f"no {args.split} clip of {args.data} has a caption with {args.words} (without {args.exclude})")
    reports: dict[str, list[dict]] = {s: [] for s in stages}
    for name, caption in clips:
        x = np.load(args.data / "new_joint_vecs" / f"{name}.npy").astype(np.float32)[: pipe.max_length]
        if len(x) < pipe.num_keyframes:
            continue
        for stage, joints in generation_chain(pipe, x, caption, seed=args.seed, recovery=args.recovery,
                                                guidance_scale=args.guidance, generate=args.kf_vae is None).items():
            reports[stage].append({"clip": name, **measure_motion(joints, pipe.skeleton).as_dict()})
    n = len(reports["true"])
    table = summarise(reports)
    print(markdown(table, n))
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"clips": [c for c, _ in clips], "words": args.words, "exclude": args.exclude,
                                        "split": args.split, "seed": args.seed, "recovery": args.recovery,
                                        "guidance": args.guidance,
                                        "weights": str(args.weights or "shipped"),
                                        "kf_vae": str(args.kf_vae) if args.kf_vae else None,
                                        "table": table, "reports": reports}, indent=2, default=float) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
